//! `fastrack teb`: the tracking error bound at a planner speed bound.

use super::print;
use fastrack_client::{model_ref, FastrackClient};
use serde_json::json;

/// Arguments of `fastrack teb`.
#[derive(clap::Args)]
pub struct Args {
    /// Model name.
    name: String,
    /// Planner speed bound.
    #[arg(long)]
    beta: f64,
    /// Boundary points of the error set to print.
    #[arg(long, default_value_t = 0)]
    boundary: u32,
    /// Version (0 = the default: the pinned version, else the latest).
    #[arg(long, default_value_t = 0)]
    version: u32,
}

/// Prints the certified set's level and extent at `beta`, the error bound (radius) that holds from inside it,
/// and boundary points if asked.
pub async fn run(client: &FastrackClient, args: Args, json_mode: bool) -> anyhow::Result<()> {
    let r = client.tracking_error_bound(model_ref(&args.name, args.version), args.beta, args.boundary).await?;
    print(
        json_mode,
        json!({"level": r.level, "radius": r.radius, "extent": r.extent, "table_beta": r.table_beta, "boundary": r.boundary, "model_version": r.model_version}),
        || {
            let mut s = format!(
                "set level = {:.4}  bound (radius) = {:.4}  extent = {:?}  (table beta {:.4})",
                r.level, r.radius, r.extent, r.table_beta
            );
            for p in r.boundary.chunks(r.extent.len().max(1)) {
                s += &format!("\n  {p:?}");
            }
            s
        },
    );
    Ok(())
}
