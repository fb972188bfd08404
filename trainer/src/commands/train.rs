//! `train`: DeepReach training from a TOML config, checkpointed into a run directory.

use anyhow::Context;
use fastrack_trainer::config::TrainConfig;
use fastrack_trainer::train::{train, RunDir, TrainOptions};
use std::path::PathBuf;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;

/// Arguments of `train`.
#[derive(clap::Args)]
pub struct Args {
    /// The configuration (every hyperparameter).
    #[arg(long)]
    config: PathBuf,
    /// Run directory: checkpoint/, losses.jsonl.
    #[arg(long)]
    run_dir: PathBuf,
    /// Continue from the run directory's checkpoint.
    #[arg(long)]
    resume: bool,
    /// Stop after this many iterations in this call (continue later with --resume).
    #[arg(long)]
    max_iterations: Option<u64>,
    /// Compute device: flex (CPU), cuda, wgpu (the last two need the cargo features of that name).
    #[arg(long, default_value = "flex")]
    device: String,
}

/// The burn device for a name.
fn device(name: &str) -> anyhow::Result<burn::tensor::Device> {
    Ok(match name {
        "flex" => burn::tensor::Device::flex().autodiff(),
        #[cfg(feature = "cuda")]
        "cuda" => burn::tensor::Device::cuda(0).autodiff(),
        #[cfg(feature = "wgpu")]
        "wgpu" => burn::tensor::Device::wgpu(Default::default()).autodiff(),
        other => anyhow::bail!("device {other:?} is not available in this build (flex always; cuda, wgpu with the cargo features of that name)"),
    })
}

/// Runs `train`; Ctrl-C stops at the next checkpoint.
pub fn run(args: Args) -> anyhow::Result<()> {
    let config = TrainConfig::load(&args.config)?;
    let device = device(&args.device)?;
    let stop = Arc::new(AtomicBool::new(false));
    let flag = Arc::clone(&stop);
    ctrlc::set_handler(move || flag.store(true, Ordering::Relaxed)).context("installing the Ctrl-C handler")?;
    let run = RunDir(args.run_dir);
    let options = TrainOptions {
        resume: args.resume,
        max_iterations: args.max_iterations,
        progress: true,
        stop: Arc::clone(&stop),
        ..TrainOptions::new(&run)
    };
    let (_, state) = train(&config, &device, options)?;
    let figure = fastrack_trainer::report::plot_losses(&run)?;
    eprintln!("loss curves: {}", figure.display());
    if stop.load(Ordering::Relaxed) {
        eprintln!("interrupted: checkpoint saved at iteration {} (continue with --resume)", state.iteration);
    }
    println!(
        "iteration {} of {}, {:.0} s, last losses {:?}",
        state.iteration, config.optimizer.iterations, state.wall_time_s, state.last_losses
    );
    Ok(())
}
