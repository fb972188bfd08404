//! `fastrack query`: the paper's queryPlannerControl.

use super::print;
use fastrack_client::{model_ref, FastrackClient};
use serde_json::json;

/// Arguments of `fastrack query`.
#[derive(clap::Args)]
pub struct Args {
    /// Model name.
    name: String,
    /// Distance to the nearest sensed obstacle (omit when none is sensed).
    #[arg(long)]
    d_obs: Option<f64>,
    /// Version (0 = the default: the pinned version, else the latest).
    #[arg(long, default_value_t = 0)]
    version: u32,
}

/// Prints the fastest planner speed bound for the obstacle distance, with the dTEB and sTEB radii.
pub async fn run(client: &FastrackClient, args: Args, json_mode: bool) -> anyhow::Result<()> {
    let r = client.query_planner_control(model_ref(&args.name, args.version), args.d_obs).await?;
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
                if r.steb_exceeds_half_distance { "  (sTEB exceeds d_obs/2: slowest speed)" } else { "" }
            )
        },
    );
    Ok(())
}
