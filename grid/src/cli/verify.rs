//! `verify`: scenario verification of a bundle's TEB table, written back into a copy of the bundle.

use super::common::command_line;
use anyhow::Context;
use fastrack_grid::verify::{required_samples, verify_table, VerifyOptions};
use fastrack_valuefn::bundle::Bundle;
use fastrack_valuefn::record::{write_record, Table};
use fastrack_valuefn::runtime::{runtime, Evaluator, GraphDims};
use fastrack_valuefn::system::for_bundle;
use indicatif::{ProgressBar, ProgressStyle};
use serde_json::json;
use std::path::PathBuf;

/// Arguments of `verify`.
#[derive(clap::Args)]
pub struct Args {
    /// The bundle's version folder, e.g. `models/dubins4d/3`.
    #[arg(long)]
    bundle: PathBuf,
    /// Repository root the verified bundle is written into (`<out>/<name>/<version>/`); may be the
    /// bundle's own repository to update it in place.
    #[arg(long)]
    out: PathBuf,
    /// Violation-probability bound epsilon.
    #[arg(long, default_value_t = 0.05)]
    eps: f64,
    /// States are sampled in {V <= (1 + margin) level} (the level is V's minimum: its own sublevel set has
    /// next to no volume).
    #[arg(long, default_value_t = 0.1)]
    level_margin: f64,
    /// Largest number of uniform proposals per row for rejection sampling.
    #[arg(long, default_value_t = 2_000_000)]
    max_proposals: usize,
    /// Confidence parameter delta.
    #[arg(long, default_value_t = 1e-3)]
    delta: f64,
    /// Rollout horizon (s).
    #[arg(long, default_value_t = 10.0)]
    horizon: f64,
    /// RK4 step (s); control and planner are held over a step.
    #[arg(long, default_value_t = 0.01)]
    step: f64,
    /// Random bang-bang planners per sample, besides the worst-case planner.
    #[arg(long, default_value_t = 3)]
    random_planners: usize,
    /// Mean time between a random planner's switches (s).
    #[arg(long, default_value_t = 1.0)]
    mean_dwell: f64,
    /// Only the rows with these betas (default: every row).
    #[arg(long, value_delimiter = ',')]
    betas: Vec<f64>,
    /// Random seed.
    #[arg(long, default_value_t = 11)]
    seed: u64,
    /// ONNX Runtime library (default: FASTRACK_ORT_LIB, then .cache/onnxruntime).
    #[arg(long)]
    ort_lib: Option<PathBuf>,
    /// Record name (default `grid-verify-<model>`).
    #[arg(long)]
    record: Option<String>,
    /// Folder of measurement records.
    #[arg(long, default_value = "bench/results")]
    results_dir: PathBuf,
}

/// Runs `verify`.
pub fn run(args: Args) -> anyhow::Result<()> {
    let bundle = Bundle::load(&args.bundle)?;
    let mut manifest = bundle.manifest.clone();
    let system = for_bundle(&manifest.system.id, manifest.n_params()).with_context(|| {
        format!("the bundle's system `{}` with {} parameters is unknown", manifest.system.id, manifest.n_params())
    })?;
    let dims = GraphDims::of(&manifest);
    let evaluator = Evaluator::new(runtime(args.ort_lib.as_deref())?, &bundle.onnx, dims, 1)?;
    let options = VerifyOptions {
        eps: args.eps,
        level_margin: args.level_margin,
        max_proposals: args.max_proposals,
        delta: args.delta,
        horizon: args.horizon,
        step: args.step,
        random_planners: args.random_planners,
        mean_dwell: args.mean_dwell,
        seed: args.seed,
    };
    println!(
        "N = ceil((2 / {}) (ln(1 / {}) + 1)) = {} samples per row",
        args.eps,
        args.delta,
        required_samples(args.eps, args.delta)
    );
    let bar = ProgressBar::new(0);
    bar.set_style(
        ProgressStyle::with_template("{elapsed_precise} [{bar:30}] {pos}/{len} rows")
            .unwrap_or_else(|_| ProgressStyle::default_bar()),
    );
    let betas = (!args.betas.is_empty()).then_some(&args.betas[..]);
    let reports = verify_table(&evaluator, &mut manifest, &system, betas, &options, &bar)?;
    bar.finish_and_clear();
    let mut table = Table::new(&[
        "beta",
        "learned level",
        "sampled level",
        "verified level",
        "served level",
        "violations / N",
        "worst-case planner max l",
        "random planners max l",
        "acceptance",
    ]);
    for r in &reports {
        let v = &r.verification;
        let served =
            manifest.teb_table.iter().find(|row| row.beta == r.beta).map_or(f64::NAN, |row| row.served_level());
        println!(
            "beta {:.4}: level {:.4} (sampled under {:.4}) -> verified {:.4} ({} of {} samples broke it)",
            r.beta, r.level, r.sampled_level, v.verified_level, v.violations, v.samples
        );
        table.row(vec![
            format!("{:.4}", r.beta),
            format!("{:.4}", r.level),
            format!("{:.4}", r.sampled_level),
            format!("{:.4}", v.verified_level),
            format!("{served:.4}"),
            format!("{} / {}", v.violations, v.samples),
            format!("{:.4}", r.worst_case_max),
            format!("{:.4}", r.random_max),
            format!("{:.4}", r.acceptance),
        ]);
    }
    let broken = reports.iter().filter(|r| r.verification.violations > 0).count();
    println!("{broken} of {} rows had violations", reports.len());
    let name = args.record.clone().unwrap_or_else(|| format!("grid-verify-{}", manifest.name));
    let config = json!({ "bundle": args.bundle, "out": args.out, "model": manifest.name, "version": manifest.version,
        "untrained": manifest.untrained, "options": options });
    let path = write_record(
        &args.results_dir,
        &name,
        &command_line(),
        config,
        json!({ "rows": reports, "rows_with_violations": broken }),
        &[("verification", &table)],
    )?;
    println!("wrote {}", path.display());
    let dir = Bundle::write(&args.out, manifest, &bundle.onnx)?;
    println!("wrote the verified bundle {}", dir.display());
    Ok(())
}
