//! `verify-bench`: what a verification's rollouts cost, per state and step, fed to ONNX Runtime one state per
//! call, all states in one call on one thread (how verification ran before batching), and in chunks on every
//! core; with the wall time of a row and a table at given settings projected from the fastest rate.

use super::common::write_command_record;
use anyhow::Context;
use fastrack_grid::verify::{required_samples, rollout_rate, Batching, RateProbe};
use fastrack_lab::record::MarkdownTable;
use fastrack_valuefn::bundle::Bundle;
use fastrack_valuefn::runtime::{runtime, Evaluator, GraphDims};
use fastrack_valuefn::system::for_bundle;
use serde_json::json;
use std::path::PathBuf;

/// Arguments of `verify-bench`.
#[derive(clap::Args)]
pub struct Args {
    /// The bundle's version folder, e.g. `models/dubins4d/5`.
    #[arg(long)]
    bundle: PathBuf,
    /// Planner speed bound of the rollouts.
    #[arg(long, default_value_t = 0.5)]
    beta: f64,
    /// Rollouts per batched measurement.
    #[arg(long, default_value_t = 16384)]
    states: usize,
    /// Rollouts of the one-state-per-call measurement.
    #[arg(long, default_value_t = 256)]
    single_states: usize,
    /// Steps per rollout.
    #[arg(long, default_value_t = 50)]
    steps: usize,
    /// RK4 step (s).
    #[arg(long, default_value_t = 0.01)]
    step: f64,
    /// States per call when chunked.
    #[arg(long, default_value_t = 4096)]
    chunk: usize,
    /// Settings the projection is for: epsilon.
    #[arg(long, default_value_t = 1e-3)]
    eps: f64,
    /// Settings the projection is for: delta.
    #[arg(long, default_value_t = 1e-6)]
    delta: f64,
    /// Settings the projection is for: rollouts per sample (planner families, search excluded).
    #[arg(long, default_value_t = 4)]
    rollouts_per_sample: usize,
    /// Settings the projection is for: horizon (s).
    #[arg(long, default_value_t = 10.0)]
    horizon: f64,
    /// ONNX Runtime library (default: FASTRACK_ORT_LIB, then .cache/onnxruntime).
    #[arg(long)]
    ort_lib: Option<PathBuf>,
    /// Record name.
    #[arg(long, default_value = "verify-bench")]
    record: String,
    /// Folder of measurement records.
    #[arg(long, default_value = "bench/results")]
    results_dir: PathBuf,
}

/// Runs `verify-bench`.
pub fn run(args: Args) -> anyhow::Result<()> {
    let bundle = Bundle::load(&args.bundle)?;
    let manifest = &bundle.manifest;
    let system = for_bundle(&manifest.system.id, manifest.n_params())
        .with_context(|| format!("the bundle's system `{}` is unknown", manifest.system.id))?;
    let threads = rayon::current_num_threads();
    let evaluator = Evaluator::new(runtime(args.ort_lib.as_deref())?, &bundle.onnx, GraphDims::of(manifest), threads)?;
    let cases = [
        ("one state per call, one thread", args.single_states, Batching { chunk: 1, parallel: false }),
        ("all states in one call, one thread", args.states, Batching { chunk: usize::MAX, parallel: false }),
        ("chunks on every core", args.states, Batching { chunk: args.chunk, parallel: true }),
    ];
    let mut rates = Vec::new();
    for (name, states, batching) in cases {
        // A short warm-up run lets ONNX Runtime plan the shapes before the timed one.
        let probe = RateProbe { beta: args.beta, states, steps: args.steps, step: args.step, batching };
        rollout_rate(&evaluator, manifest, &system, &RateProbe { states: states.min(1024), steps: 2, ..probe })?;
        let rate = rollout_rate(&evaluator, manifest, &system, &probe)?;
        println!("{name}: {rate:.0} rollout steps/s");
        rates.push((name, states, batching, rate));
    }
    let baseline = rates[0].3;
    let mut table = MarkdownTable::new(&[
        "feeding",
        "rollouts",
        "states per call",
        "threads",
        "rollout steps/s",
        "vs one per call",
    ]);
    for (name, states, batching, rate) in &rates {
        table.row(vec![
            name.to_string(),
            states.to_string(),
            batching.chunk.min(*states).to_string(),
            if batching.parallel { threads.to_string() } else { "1".into() },
            format!("{rate:.0}"),
            format!("{:.1}", rate / baseline),
        ]);
    }
    let n = required_samples(args.eps, args.delta);
    let row_steps = (n * args.rollouts_per_sample) as f64 * (args.horizon / args.step).round();
    let rows = manifest.teb_table.len();
    let mut projection = MarkdownTable::new(&["feeding", "row (s)", "table (s)", "table (h)"]);
    for (name, _, _, rate) in &rates {
        let row = row_steps / rate;
        projection.row(vec![
            name.to_string(),
            format!("{row:.0}"),
            format!("{:.0}", row * rows as f64),
            format!("{:.2}", row * rows as f64 / 3600.0),
        ]);
    }
    println!(
        "a row at eps {} / delta {} (N {n}, {} rollouts each, {} s at {} s) takes {row_steps:.3e} rollout steps",
        args.eps, args.delta, args.rollouts_per_sample, args.horizon, args.step
    );
    let config = json!({ "bundle": args.bundle, "model": manifest.name, "version": manifest.version, "beta": args.beta,
        "states": args.states, "single_states": args.single_states, "steps": args.steps, "step": args.step,
        "chunk": args.chunk, "threads": threads, "eps": args.eps, "delta": args.delta,
        "rollouts_per_sample": args.rollouts_per_sample, "horizon": args.horizon });
    let results = json!({ "rates": rates.iter().map(|(name, states, b, rate)| json!({ "feeding": name,
        "rollouts": states, "chunk": b.chunk.min(*states), "parallel": b.parallel, "rollout_steps_per_s": rate }))
        .collect::<Vec<_>>(), "row_rollout_steps": row_steps, "rows": rows });
    let path = write_command_record(
        &args.results_dir,
        &args.record,
        config,
        results,
        &[("rollout steps per second", &table), ("projected wall time without search or extra rounds", &projection)],
    )?;
    println!("wrote {}", path.display());
    Ok(())
}
