//! `fastrack sim merge`: the parts of a sharded benchmark merged into the record a single run writes.

use super::bench::{report, write_visits};
use super::Recording;
use anyhow::Context as _;
use fastrack_lab::shard::Merged;
use fastrack_online::geometry::Point;
use fastrack_sim::bench::{BenchRun, PART_STEM};
use fastrack_sim::plot::Outlined;
use fastrack_sim::world::WorldObstacle;
use serde::de::DeserializeOwned;
use std::path::PathBuf;

/// Arguments of `fastrack sim merge`.
#[derive(clap::Args)]
pub(super) struct Args {
    /// Folder holding every shard's part.
    #[arg(long)]
    part_dir: PathBuf,
    /// Write the visits the parts kept (shards run with `--visits`) into this CSV file.
    #[arg(long)]
    visits: Option<PathBuf>,
    #[command(flatten)]
    recording: Recording,
}

/// `fastrack sim merge`: the parts of a sharded benchmark, merged into the record a single run writes.
pub(super) fn run(args: Args, json_mode: bool) -> anyhow::Result<()> {
    let merged = fastrack_lab::shard::Part::<serde_json::Value>::merge(&args.part_dir, PART_STEM)?;
    // Parts written before worlds in space hold worlds in the plane.
    let dim = merged.config["dim"].as_u64().unwrap_or(2) as usize;
    in_dimension!(dim, merge_in(args, merged, json_mode))
}

/// The merged runs through worlds of `D` axes, read from the parts' items.
fn merge_in<O: WorldObstacle<D> + Outlined<D>, const D: usize>(
    args: Args,
    merged: Merged<serde_json::Value>,
    json_mode: bool,
) -> anyhow::Result<()>
where
    Point<D>: DeserializeOwned,
{
    let mut runs: Vec<BenchRun<O, D>> = merged
        .items
        .into_iter()
        .map(serde_json::from_value)
        .collect::<Result<_, _>>()
        .with_context(|| format!("the parts in {} hold runs of another kind", args.part_dir.display()))?;
    runs.sort_by_key(|r| (r.world, r.method));
    if let Some(path) = &args.visits {
        anyhow::ensure!(
            runs.iter().any(|r| !r.run.visits.is_empty()),
            "the parts in {} kept no visits: run the shards with --visits",
            args.part_dir.display()
        );
        write_visits(path, &merged.config, &runs, json_mode)?;
    }
    let command = format!(
        "fastrack sim merge --part-dir {}{}",
        args.part_dir.display(),
        args.recording.record.as_ref().map_or(String::new(), |name| format!(" --record {name}"))
    );
    report(&merged.config, &runs, merged.wall_s, &command, &args.recording, json_mode)
}
