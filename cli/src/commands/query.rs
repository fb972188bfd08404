//! `fastrack query`: the paper's queryPlannerControl, or the planner rule.

use super::print;
use fastrack_client::{model_ref, FastrackClient};
use serde_json::json;

/// Arguments of `fastrack query`.
#[derive(clap::Args)]
pub struct Args {
    /// Model name.
    name: String,
    /// Distance to the nearest sensed obstacle (omit when none is sensed).
    #[arg(long, conflicts_with = "planner_clearance")]
    d_obs: Option<f64>,
    /// The planner rule instead: the planner's distance to the nearest sensed obstacle, less the farthest one
    /// control period can move it.
    #[arg(long)]
    planner_clearance: Option<f64>,
    /// Version (0 = the default: the pinned version, else the latest).
    #[arg(long, default_value_t = 0)]
    version: u32,
}

/// Prints the fastest planner speed bound for the obstacle distance, with the dTEB and sTEB radii.
pub async fn run(client: &FastrackClient, args: Args, json_mode: bool) -> anyhow::Result<()> {
    let model = model_ref(&args.name, args.version);
    let r = match args.planner_clearance {
        Some(c) => client.query_planner_rule(model, c).await?,
        None => client.query_planner_control(model, args.d_obs).await?,
    };
    print(
        json_mode,
        json!({"beta_query": r.beta_query, "dteb_radius": r.dteb_radius, "steb_radius": r.steb_radius,
               "steb_exceeds_half_distance": r.steb_exceeds_half_distance, "model_version": r.model_version}),
        || {
            format!(
                "beta_query = {:.4}  dTEB radius = {:.4}  sTEB radius = {:.4}{}",
                r.beta_query,
                r.dteb_radius,
                r.steb_radius,
                if r.steb_exceeds_half_distance { "  (the sTEB does not fit: slowest speed)" } else { "" }
            )
        },
    );
    Ok(())
}
