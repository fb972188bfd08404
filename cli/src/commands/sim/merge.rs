//! `fastrack sim merge`: the parts of a sharded benchmark merged into the record a single run writes.

use super::bench::{report, write_visits};
use super::Recording;
use fastrack_online::geometry::PlaneObstacle;
use fastrack_sim::bench::{BenchPart, PART_STEM};
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
    let merged = BenchPart::<PlaneObstacle, 2>::merge(&args.part_dir, PART_STEM)?;
    let mut runs = merged.items;
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
