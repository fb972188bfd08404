//! `fastrack sim world`: a world generated from a seed, or a world file checked; in the plane or in space,
//! by the model's planner.

use super::{print, world_of, Generation};
use anyhow::Context as _;
use fastrack_client::{model_ref, FastrackClient};
use fastrack_proto::planner_speed::SpeedRow;
use fastrack_sim::world::WorldObstacle;
use serde_json::json;
use std::path::PathBuf;

/// Arguments of `fastrack sim world`.
#[derive(clap::Args)]
pub(super) struct Args {
    /// Check this world file (values, and a path for the model's sTEB) instead of generating one.
    #[arg(long)]
    check: Option<PathBuf>,
    /// Seed of the generated world.
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// Where the generated world goes (TOML); printed without it.
    #[arg(long)]
    out: Option<PathBuf>,
    /// Model whose sTEB the world must be feasible for.
    #[arg(long, default_value = "dubins4d")]
    model: String,
    #[command(flatten)]
    generation: Generation,
}

/// Runs `fastrack sim world`.
pub(super) async fn run(client: &FastrackClient, args: Args, json_mode: bool) -> anyhow::Result<()> {
    let info = client.get_model(model_ref(&args.model, 0)).await?;
    let steb = info.teb_table.first().map(|row| SpeedRow::from(row).bound).context("the model's TEB table is empty")?;
    let steb = args.generation.inflation(steb)?;
    in_dimension!(info.planner_dim, world_in(&args, steb, json_mode))
}

/// Generates or checks a world of `D` axes feasible for `steb`.
fn world_in<O: WorldObstacle<D>, const D: usize>(args: &Args, steb: f64, json_mode: bool) -> anyhow::Result<()> {
    let world = world_of::<O, D>(args.check.as_ref(), &args.generation, args.seed, steb)?;
    let text = world.to_toml();
    match (&args.check, &args.out) {
        (Some(path), _) => print(json_mode, json!({"world": path, "feasible_for_steb_m": steb}), || {
            format!("{}: valid, and a path keeps the sTEB ({steb:.3} m) from every obstacle", path.display())
        }),
        (None, Some(out)) => {
            if let Some(dir) = out.parent().filter(|d| !d.as_os_str().is_empty()) {
                std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
            }
            std::fs::write(out, &text).with_context(|| format!("writing {}", out.display()))?;
            print(json_mode, json!({"world": out, "obstacles": world.obstacles.len()}), || {
                format!("{}: {} obstacles, feasible for the sTEB ({steb:.3} m)", out.display(), world.obstacles.len())
            });
        }
        (None, None) => println!("{text}"),
    }
    Ok(())
}
