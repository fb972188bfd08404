//! `verify-merge`: the parts of a sharded verification merged into the verified bundle and the record a single
//! run writes.

use super::verify::{finish, BundleSource, Loaded, Recording, PART_STEM};
use fastrack_grid::verify::{combine_pieces, ControlLaw, RowReport};
use fastrack_lab::shard::Part;
use serde_json::json;
use std::path::PathBuf;

/// Arguments of `verify-merge`.
#[derive(clap::Args)]
pub struct Args {
    #[command(flatten)]
    source: BundleSource,
    /// Repository root the verified bundle is written into (`<out>/<name>/<version>/`).
    #[arg(long)]
    out: PathBuf,
    /// Folder holding every shard's part.
    #[arg(long)]
    part_dir: PathBuf,
    #[command(flatten)]
    recording: Recording,
}

/// Runs `verify-merge`: the shards' parts into the verified bundle and the record a single run writes.
pub fn run(args: Args) -> anyhow::Result<()> {
    let Loaded { bundle, system, evaluator } = args.source.load()?;
    let merged = Part::<RowReport>::merge(&args.part_dir, PART_STEM)?;
    let (verified, loaded) = (merged.config["onnx_sha256"].as_str(), &bundle.manifest.onnx_sha256);
    anyhow::ensure!(
        verified == Some(loaded.as_str()),
        "the parts verified the graph {} but {} holds {loaded}",
        verified.unwrap_or("(none)"),
        args.source.bundle.display()
    );
    anyhow::ensure!(
        merged.config["options"]["control_law"] != json!(ControlLaw::Grid),
        "the parts played the grid's policy as the tracker (--control-law grid): they verify no bundle"
    );
    let mut reports = combine_pieces(merged.items)?;
    let position = |beta: f64| bundle.manifest.teb_table.iter().position(|row| row.beta == beta);
    reports.sort_by_key(|r| position(r.beta));
    let out = args.recording.outputs(Some(&args.out));
    finish(&evaluator, bundle, &system, reports, merged.config, &out)
}
