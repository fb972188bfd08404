//! `fastrack-trainer`: produces model bundles.

use anyhow::Context;
use clap::{Parser, Subcommand};
use fastrack_trainer::config::TrainConfig;
use fastrack_trainer::export;
use fastrack_trainer::train::{checkpoint_network, train, RunDir, TrainOptions};
use fastrack_valuefn::composite::{AxisNetwork, Composite};
use fastrack_valuefn::manifest::Provenance;
use fastrack_valuefn::network::{FeatureLayout, NetworkShape, ValueNetwork};
use fastrack_valuefn::system::{by_id, decomposition, SYSTEM_IDS};
use fastrack_valuefn::teb::TebOptions;
use std::collections::BTreeMap;
use std::path::PathBuf;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;

#[derive(Parser)]
#[command(name = "fastrack-trainer", version, about = "Produces fastrack model bundles")]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Writes a bundle from a seeded random (untrained) SIREN, marked untrained in its manifest: a
    /// stand-in for tests and demos until a trained model exists. Its bounds mean nothing.
    RandomBundle {
        /// System id.
        #[arg(long, default_value = "dubins4d")]
        system: String,
        /// Model name (should say that it is untrained).
        #[arg(long, default_value = "untrained-dubins4d")]
        name: String,
        /// Model version.
        #[arg(long, default_value_t = 1)]
        version: u32,
        /// Hidden layer widths, comma separated.
        #[arg(long, value_delimiter = ',', default_value = "256,256,256")]
        hidden: Vec<usize>,
        /// Random seed.
        #[arg(long, default_value_t = 7)]
        seed: u64,
        /// Horizon fixed in the graph (s).
        #[arg(long, default_value_t = 1.0)]
        horizon: f64,
        /// Constant added to the network output, so that `V = l + tau (offset + NN)` stays positive like a
        /// real value function (a random SIREN alone averages zero). Still meaningless as a bound.
        #[arg(long, default_value_t = 0.5)]
        output_offset: f64,
        /// Repository root to write into.
        #[arg(long, default_value = "models")]
        out: PathBuf,
    },
    /// Trains a value function (DeepReach) from a TOML config, checkpointing into a run directory.
    Train {
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
    },
    /// Training-speed benchmark: the config's network and the paper's (3x512, 65,536 points), beside the
    /// machine's matmul rate and PyTorch; writes bench/results/trainer-speed.{json,md}.
    Bench {
        /// The configuration whose network is benchmarked (and whose system and loss are used).
        #[arg(long, default_value = "trainer/configs/dubins4d.toml")]
        config: PathBuf,
        /// Where the record goes.
        #[arg(long, default_value = "bench/results")]
        out: PathBuf,
        /// Record name (`<out>/<record>.{json,md}`).
        #[arg(long, default_value = "trainer-speed")]
        record: String,
    },
    /// Exports a run's checkpoint as a model bundle (TEB table, manifest with provenance, reload check).
    Export {
        /// Run directory.
        #[arg(long)]
        run_dir: PathBuf,
        /// Repository root to write into.
        #[arg(long, default_value = "models")]
        out: PathBuf,
    },
    /// Composes runs trained on the axes of a decomposed system (quad10d) into one bundle of the full system:
    /// `V = sqrt(sum V_a^2)` over the axes, each axis' network from the run trained on its subsystem.
    Compose {
        /// The decomposed system.
        #[arg(long, default_value = "quad10d")]
        system: String,
        /// A run directory per subsystem (repeatable); an axis takes the run of its subsystem (quad10d's x and y
        /// axes share one).
        #[arg(long = "axis-run", required = true)]
        axis_runs: Vec<PathBuf>,
        /// Model name.
        #[arg(long, default_value = "quad10d")]
        name: String,
        /// Model version.
        #[arg(long, default_value_t = 1)]
        version: u32,
        /// Repository root to write into.
        #[arg(long, default_value = "models")]
        out: PathBuf,
    },
    /// Draws a bundle's TEB table (bound, certified set level, measured `V_min`) against `beta`, with grid solutions'
    /// `V_min` beside it.
    PlotTeb {
        /// The bundle's version folder, e.g. `models/dubins4d/4`.
        #[arg(long)]
        bundle: PathBuf,
        /// Grid solution files (`.ftgrid`) whose `V_min` is drawn as the reference.
        #[arg(long = "grid-solution")]
        grid_solutions: Vec<PathBuf>,
        /// The PNG to write.
        #[arg(long)]
        out: PathBuf,
    },
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

fn main() -> anyhow::Result<()> {
    tracing_subscriber::fmt()
        .with_env_filter(tracing_subscriber::EnvFilter::new("info"))
        .with_writer(std::io::stderr)
        .init();
    match Cli::parse().command {
        Command::RandomBundle { system, name, version, hidden, seed, horizon, output_offset, out } => {
            let system = by_id(&system)
                .with_context(|| format!("unknown system {system:?}; known: {}", SYSTEM_IDS.join(", ")))?;
            anyhow::ensure!(
                !hidden.is_empty() && hidden.iter().all(|&w| w > 0),
                "--hidden needs at least one positive width"
            );
            anyhow::ensure!(horizon.is_finite() && horizon > 0.0, "--horizon must be > 0");
            let mut network = ValueNetwork::random(&system, &NetworkShape::new(&hidden, 30.0, true), horizon, seed);
            network.output_offset = output_offset;
            let config = serde_json::json!({
                "system": system.id, "hidden": hidden, "omega_0": 30.0, "seed": seed, "horizon": horizon,
                "exact_boundary": true, "output_offset": output_offset,
            });
            let provenance = Provenance::here_and_now(
                "random-init (SIREN initialisation, untrained)",
                config,
                0,
                BTreeMap::new(),
                0.0,
            );
            let request = export::ExportRequest {
                model: export::ExportedModel::Network { network: &network, horizon },
                system: &system,
                name: &name,
                version,
                untrained: true,
                provenance,
                teb: TebOptions::default(),
            };
            let dir = export::export(&out, request)?;
            println!("{}", dir.display());
        }
        Command::Train { config, run_dir, resume, max_iterations, device: device_name } => {
            let config = TrainConfig::load(&config)?;
            let device = device(&device_name)?;
            let stop = Arc::new(AtomicBool::new(false));
            let flag = Arc::clone(&stop);
            ctrlc::set_handler(move || flag.store(true, Ordering::Relaxed)).context("installing the Ctrl-C handler")?;
            let run = RunDir(run_dir);
            let options = TrainOptions {
                run: &run,
                resume,
                max_iterations,
                progress: true,
                stop: Arc::clone(&stop),
                hamiltonian_sign: 1.0,
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
        }
        Command::Bench { config, out, record } => run_bench(&config, &out, &record)?,
        Command::PlotTeb { bundle, grid_solutions, out } => {
            let manifest = fastrack_valuefn::bundle::Bundle::load(&bundle)?.manifest;
            let mut grid = grid_solutions
                .iter()
                .map(|path| {
                    let solution = fastrack_gridfile::format::load(path)?;
                    let beta = solution.info.params.first().copied().context("a solution without parameters")?;
                    Ok((beta, solution.values.iter().copied().fold(f64::INFINITY, f64::min)))
                })
                .collect::<anyhow::Result<Vec<_>>>()?;
            grid.sort_by(|a, b| a.0.total_cmp(&b.0));
            fastrack_trainer::report::plot_teb(&out, &manifest.teb_table, &[("grid V_min", grid)])?;
            println!("{}", out.display());
        }
        Command::Compose { system, axis_runs, name, version, out } => {
            let dir = compose(&system, &axis_runs, &name, version, &out)?;
            println!("{}", dir.display());
        }
        Command::Export { run_dir, out } => {
            let run = RunDir(run_dir);
            let (network, state) = checkpoint_network(&run, &burn::tensor::Device::flex())?;
            let system = state.config.system()?;
            let losses = state.last_losses.clone().unwrap_or_default();
            let loss = |i: usize| losses.get(i).copied().unwrap_or(0.0);
            let provenance = Provenance::here_and_now(
                format!(
                    "DeepReach ({:?} loss, {:?} parameters{}), burn",
                    state.config.loss.form,
                    state.config.parameter_mode,
                    if state.config.supervision.is_some() { ", supervised by grid solutions" } else { "" }
                ),
                serde_json::to_value(&state.config)?,
                state.iteration,
                BTreeMap::from([
                    ("total".into(), loss(0)),
                    ("boundary".into(), loss(1)),
                    ("residual".into(), loss(2)),
                    ("supervision".into(), loss(3)),
                    ("supervision_gradient".into(), loss(4)),
                ]),
                state.wall_time_s,
            );
            let request = export::ExportRequest {
                model: export::ExportedModel::Network { network: &network, horizon: state.config.sampling.tau_max },
                system: &system,
                name: &state.config.export.name,
                version: state.config.export.version,
                untrained: false,
                provenance,
                teb: TebOptions::default(),
            };
            let dir = export::export(&out, request)?;
            let manifest = fastrack_valuefn::bundle::Bundle::load(&dir)?.manifest;
            fastrack_trainer::report::plot_teb(&run.0.join("teb.png"), &manifest.teb_table, &[])?;
            println!("{}", dir.display());
        }
    }
    Ok(())
}

/// `compose`: the axes' runs of a decomposed system exported as one composite bundle.
fn compose(
    id: &str,
    axis_runs: &[PathBuf],
    name: &str,
    version: u32,
    out: &std::path::Path,
) -> anyhow::Result<PathBuf> {
    let system = by_id(id).with_context(|| format!("unknown system {id:?}; known: {}", SYSTEM_IDS.join(", ")))?;
    let axes = decomposition(id).with_context(|| format!("system {id:?} has no decomposition into axes"))?;
    let device = burn::tensor::Device::flex();
    let mut runs = Vec::new();
    for dir in axis_runs {
        let run = RunDir(dir.clone());
        let (network, state) = checkpoint_network(&run, &device)?;
        runs.push((dir.clone(), network, state));
    }
    let mut networks = Vec::new();
    for axis in &axes {
        let mut matching = runs.iter().filter(|(_, _, s)| s.config.system == axis.subsystem);
        let (_, network, state) = matching
            .next()
            .with_context(|| format!("no --axis-run was trained on `{}` (an axis of {id})", axis.subsystem))?;
        if let Some((other, _, _)) = matching.next() {
            anyhow::bail!("two runs were trained on `{}`; give one ({})", axis.subsystem, other.display());
        }
        let subsystem = state.config.system()?;
        networks.push(AxisNetwork {
            axis: axis.clone(),
            subsystem,
            network: network.clone(),
            tau: state.config.sampling.tau_max,
        });
    }
    if let Some((dir, _, state)) = runs.iter().find(|(_, _, s)| !axes.iter().any(|a| a.subsystem == s.config.system)) {
        anyhow::bail!("{} was trained on `{}`, which is not an axis of {id}", dir.display(), state.config.system);
    }
    let composite = Composite::new(system.clone(), networks)?;
    let configs: Vec<serde_json::Value> =
        runs.iter().map(|(_, _, s)| serde_json::to_value(&s.config)).collect::<Result<_, _>>()?;
    let provenance = Provenance::here_and_now(
        format!(
            "DeepReach per axis of {id} ({} runs, supervised by grid solutions where configured), burn",
            runs.len()
        ),
        serde_json::json!({ "axes": configs }),
        runs.iter().map(|(_, _, s)| s.iteration).sum(),
        BTreeMap::new(),
        runs.iter().map(|(_, _, s)| s.wall_time_s).sum(),
    );
    let request = export::ExportRequest {
        model: export::ExportedModel::Composite(&composite),
        system: &system,
        name,
        version,
        untrained: false,
        provenance,
        teb: TebOptions::default(),
    };
    export::export(out, request)
}

/// Runs the training-speed benchmark and writes its record.
fn run_bench(config_path: &std::path::Path, out: &std::path::Path, record: &str) -> anyhow::Result<()> {
    let config = &TrainConfig::load(config_path)?;
    use fastrack_trainer::step_bench::{
        flops_per_iteration, iterations_per_second, matmul_gflops, torch_iterations_per_second, Case,
    };
    use fastrack_valuefn::record::{write_record, MarkdownTable};
    let device = burn::tensor::Device::flex().autodiff();
    let encoding = config.network.periodic_encoding;
    let n_in = FeatureLayout::for_system(&config.system()?, encoding).n_features();
    let peak = matmul_gflops(2048, 5, &burn::tensor::Device::flex());
    eprintln!("f32 matmul 2048^3 (burn flex): {peak:.1} GFLOP/s");
    let shipped = Case {
        width: config.network.hidden[0],
        depth: config.network.hidden.len(),
        points: config.sampling.points,
        iterations: 100,
    };
    let paper = Case { width: 512, depth: 3, points: 65_536, iterations: 3 };
    let mut table = MarkdownTable::new(&[
        "network x points",
        "burn-flex it/s",
        "GFLOP/iter",
        "GFLOP/s",
        "of matmul rate",
        "PyTorch CPU it/s",
        "flex / torch",
    ]);
    let mut figures = Vec::new();
    for (label, case) in [("shipped", shipped), ("paper", paper)] {
        let rate = iterations_per_second(config, &case, &device)?;
        let gflop = flops_per_iteration(&case, n_in) / 1e9;
        let torch = torch_iterations_per_second(&case, encoding);
        let (torch_cell, ratio_cell) = match &torch {
            Ok((t, _)) => (format!("{t:.3}"), format!("{:.2}", rate / t)),
            Err(why) => (format!("n/a ({why})"), "-".into()),
        };
        eprintln!("{label}: {rate:.3} it/s, {:.1} GFLOP/s, torch {torch_cell}", rate * gflop);
        table.row(vec![
            format!("{}x{} x {}", case.depth, case.width, case.points),
            format!("{rate:.3}"),
            format!("{gflop:.1}"),
            format!("{:.1}", rate * gflop),
            format!("{:.0}%", 100.0 * rate * gflop / peak),
            torch_cell,
            ratio_cell,
        ]);
        figures.push(serde_json::json!({"case": label, "width": case.width, "depth": case.depth, "points": case.points,
            "iterations_per_s": rate, "gflop_per_iteration": gflop, "gflops": rate * gflop,
            "torch_iterations_per_s": torch.as_ref().ok().map(|t| t.0), "torch": torch.map(|t| t.1).unwrap_or_else(|e| e)}));
    }
    println!("matmul rate: {peak:.1} GFLOP/s\n\n{}", table.to_markdown());
    let command = format!(
        "cargo run --release -p fastrack-trainer -- bench --config {} --record {record}",
        config_path.display()
    );
    let path = write_record(
        out,
        record,
        &command,
        serde_json::json!({"config": config_path, "system": config.system, "loss": config.loss.form,
            "parameter_mode": config.parameter_mode, "periodic_encoding": config.network.periodic_encoding, "matmul_n": 2048}),
        serde_json::json!({"matmul_gflops": peak, "cases": figures}),
        &[("One DeepReach iteration (forward, explicit input gradient, HJI loss, backward, Adam)", &table)],
    )?;
    eprintln!("wrote {}", path.display());
    Ok(())
}
