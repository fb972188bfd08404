//! `verify-merge`: the parts of a sharded verification merged into the verified bundle and the record a single
//! run writes; for a composite bundle verified by its axes, the axes' parts composed into its verification.

use super::verify::{finish, BundleSource, Loaded, Recording, PART_STEM};
use anyhow::Context;
use fastrack_grid::verify::axes::{self, AxisReports};
use fastrack_grid::verify::{combine_pieces, ControlLaw, RowReport, VerifyOptions};
use fastrack_lab::shard::{Merged, Part};
use fastrack_valuefn::bundle::Bundle;
use fastrack_valuefn::runtime::{runtime, Evaluator, GraphDims};
use rand::SeedableRng;
use serde_json::json;
use std::path::PathBuf;

/// States at which the axis bundles are checked against the composite.
const COMPOSITION_CHECKS: usize = 1024;

/// Arguments of `verify-merge`.
#[derive(clap::Args)]
pub struct Args {
    #[command(flatten)]
    source: BundleSource,
    /// Repository root the verified bundle is written into (`<out>/<name>/<version>/`).
    #[arg(long)]
    out: PathBuf,
    /// Folder holding every shard's part.
    #[arg(long, required_unless_present = "axes", conflicts_with = "axes")]
    part_dir: Option<PathBuf>,
    /// For a composite bundle verified by its axes (`verify --axis-of`): an axis bundle and the folder of its
    /// verification's parts, `BUNDLE=PART_DIR`, once per axis subsystem.
    #[arg(long = "axis", value_parser = parse_axis)]
    axes: Vec<(PathBuf, PathBuf)>,
    #[command(flatten)]
    recording: Recording,
}

fn parse_axis(text: &str) -> Result<(PathBuf, PathBuf), String> {
    let (bundle, parts) = text.split_once('=').ok_or_else(|| format!("`{text}` is not BUNDLE=PART_DIR"))?;
    Ok((bundle.into(), parts.into()))
}

/// Runs `verify-merge`: the shards' parts into the verified bundle and the record a single run writes.
pub fn run(args: Args) -> anyhow::Result<()> {
    let Loaded { bundle, system, evaluator } = args.source.load()?;
    let (mut reports, config) = match &args.part_dir {
        Some(dir) => {
            let merged = Part::<RowReport>::merge(dir, PART_STEM)?;
            check_graph(&merged, &bundle, "/onnx_sha256")?;
            let config = merged.config.clone();
            (combine_pieces(merged.items)?, config)
        }
        None => compose_axes(&args.axes, &bundle, &evaluator)?,
    };
    let position = |beta: f64| bundle.manifest.teb_table.iter().position(|row| row.beta == beta);
    reports.sort_by_key(|r| position(r.beta));
    let out = args.recording.outputs(Some(&args.out));
    finish(&evaluator, bundle, &system, reports, config, &out)
}

/// Checks that the parts verified `bundle`'s graph (its sha256 at the JSON `pointer` into their config), with the
/// bundle's own control law.
fn check_graph(merged: &Merged<RowReport>, bundle: &Bundle, pointer: &str) -> anyhow::Result<()> {
    let config = &merged.config;
    let verified = config.pointer(pointer).and_then(|v| v.as_str());
    let loaded = &bundle.manifest.onnx_sha256;
    anyhow::ensure!(
        verified == Some(loaded.as_str()),
        "the parts verified the graph {} but {} holds {loaded}",
        verified.unwrap_or("(none)"),
        bundle.dir.display()
    );
    anyhow::ensure!(
        config["options"]["control_law"] != json!(ControlLaw::Grid),
        "the parts played the grid's policy as the tracker (--control-law grid): they verify no bundle"
    );
    Ok(())
}

/// The composite `bundle`'s row reports from its axes' parts, and the record's config.
fn compose_axes(
    given: &[(PathBuf, PathBuf)],
    composite: &Bundle,
    evaluator: &Evaluator,
) -> anyhow::Result<(Vec<RowReport>, serde_json::Value)> {
    let mut loaded = Vec::new();
    for (path, dir) in given {
        let bundle = Bundle::load(path).with_context(|| format!("loading the axis bundle {}", path.display()))?;
        let merged = Part::<RowReport>::merge(dir, PART_STEM)?;
        check_graph(&merged, &bundle, "/onnx_sha256")?;
        check_graph(&merged, composite, "/axis_of/onnx_sha256")
            .with_context(|| format!("the parts in {} are not an axis verification of this bundle", dir.display()))?;
        let options: VerifyOptions = serde_json::from_value(merged.config["options"].clone())
            .with_context(|| format!("the options of the parts in {}", dir.display()))?;
        axes::check_scale(options.error_scale)?;
        let graph = Evaluator::new(runtime(None)?, &bundle.onnx, GraphDims::of(&bundle.manifest), 1)?;
        let reports = combine_pieces(merged.items)?;
        loaded.push((bundle, graph, options, merged.config, reports));
    }
    let margins: Vec<f64> = loaded.iter().map(|(_, _, o, _, _)| o.level_margin).collect();
    anyhow::ensure!(
        margins.windows(2).all(|w| w[0] == w[1]),
        "the axes were verified with different level margins ({margins:?}): their sets are not one composite set"
    );
    let pairs: Vec<(&Evaluator, &fastrack_valuefn::manifest::Manifest)> =
        loaded.iter().map(|(b, g, _, _, _)| (g, &b.manifest)).collect();
    let mut rng = rand::rngs::StdRng::seed_from_u64(3);
    axes::check_networks((evaluator, &composite.manifest), &pairs, COMPOSITION_CHECKS, &mut rng)?;
    let per_axis: Vec<AxisReports<'_>> =
        loaded.iter().map(|(b, _, _, _, reports)| AxisReports { manifest: &b.manifest, reports }).collect();
    let reports = axes::compose_reports(&composite.manifest, &per_axis, margins.first().copied().unwrap_or(0.0))?;
    let config = json!({ "model": composite.manifest.name, "version": composite.manifest.version,
        "onnx_sha256": composite.manifest.onnx_sha256, "by_axes": loaded.iter().map(|(b, _, _, config, _)| json!({
            "bundle": b.dir, "subsystem": b.manifest.system.id, "config": config })).collect::<Vec<_>>() });
    Ok((reports, config))
}
