//! The training run: Adam with an exponential learning-rate schedule and optional clipping, seeded and
//! reproducible, checkpoints every N iterations with `--resume`, a progress bar, a JSONL loss log, and a
//! checkpoint on Ctrl-C.

use crate::config::TrainConfig;
use crate::objective::{LossTerms, Objective};
use crate::sampler::Sampler;
use crate::siren::Siren;
use crate::supervision::GridSupervision;
use anyhow::{ensure, Context};
use burn::grad_clipping::GradientClippingConfig;
use burn::module::Module;
use burn::optim::{AdamConfig, GradientsParams};
use burn::tensor::Device;
use fastrack_valuefn::network::{NetworkShape, ValueNetwork};
use fastrack_valuefn::system::AffineSystem;
use serde::{Deserialize, Serialize};
use std::io::Write;
use std::path::PathBuf;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::time::Instant;

/// Progress of a run, saved with each checkpoint.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct RunState {
    /// The configuration of the run.
    pub config: TrainConfig,
    /// Iterations completed.
    pub iteration: u64,
    /// Training wall time so far (s), over every call that trained the run (resumed ones too).
    pub wall_time_s: f64,
    /// Loss terms of the last iteration: total, boundary, residual, grid supervision of `V` and of `dV/dr`
    /// (checkpoints written before supervision existed hold the first three).
    pub last_losses: Option<Vec<f64>>,
}

/// Files of a run directory.
pub struct RunDir(pub PathBuf);

impl RunDir {
    fn checkpoint(&self) -> PathBuf {
        self.0.join("checkpoint")
    }
    fn model(&self) -> PathBuf {
        self.checkpoint().join("model.bpk")
    }
    fn optimizer(&self) -> PathBuf {
        self.checkpoint().join("optimizer.bpk")
    }
    fn state(&self) -> PathBuf {
        self.checkpoint().join("state.json")
    }
    /// The JSONL loss log.
    pub fn losses(&self) -> PathBuf {
        self.0.join("losses.jsonl")
    }

    /// Reads the saved run state.
    pub fn load_state(&self) -> anyhow::Result<RunState> {
        let text =
            std::fs::read_to_string(self.state()).with_context(|| format!("no checkpoint in {}", self.0.display()))?;
        Ok(serde_json::from_str(&text)?)
    }
}

/// The untrained network of a configuration (seeded SIREN initialisation).
pub fn initial_network(config: &TrainConfig, system: &AffineSystem) -> ValueNetwork {
    let exact = config.loss.form == crate::config::LossForm::ExactBoundary;
    let shape = NetworkShape {
        hidden: config.network.hidden.clone(),
        omega_0: config.network.omega_0,
        exact_boundary: exact,
        periodic_encoding: config.network.periodic_encoding,
    };
    let mut network = ValueNetwork::random(system, &shape, config.sampling.tau_max, config.seed);
    network.output_scale = config.network.output_scale;
    network.output_offset = config.network.output_offset;
    network.layers[0].weight.iter_mut().for_each(|w| *w *= config.network.first_layer_scale);
    network
}

/// The network stored in a run's checkpoint.
pub fn checkpoint_network(run: &RunDir, device: &Device) -> anyhow::Result<(ValueNetwork, RunState)> {
    let state = run.load_state()?;
    let system = state.config.system()?;
    let mut network = initial_network(&state.config, &system);
    let model = Siren::from_network(&network, device)
        .try_load_file(run.model())
        .map_err(|e| anyhow::anyhow!("loading {}: {e:?}", run.model().display()))?;
    model.write_into(&mut network);
    Ok((network, state))
}

/// How one call of [`train`] runs: where, from where, how far, and whether to show progress.
pub struct TrainOptions<'a> {
    /// Run directory (checkpoints, logs).
    pub run: &'a RunDir,
    /// Continue from the run's checkpoint.
    pub resume: bool,
    /// Stop after this many iterations in this call (the run continues with `--resume`).
    pub max_iterations: Option<u64>,
    /// Show a progress bar.
    pub progress: bool,
    /// Set to stop early (Ctrl-C); a checkpoint is written first.
    pub stop: Arc<AtomicBool>,
    /// Multiplies the Hamiltonian (1 except in tests showing a wrong sign fails).
    pub hamiltonian_sign: f64,
}

impl<'a> TrainOptions<'a> {
    /// A fresh run in `run`, to the config's last iteration, quietly, with nothing to stop it early.
    pub fn new(run: &'a RunDir) -> Self {
        Self {
            run,
            resume: false,
            max_iterations: None,
            progress: false,
            stop: Arc::new(AtomicBool::new(false)),
            hamiltonian_sign: 1.0,
        }
    }
}

/// Trains (or continues) a run; returns the network and the final state.
pub fn train(
    config: &TrainConfig,
    device: &Device,
    options: TrainOptions<'_>,
) -> anyhow::Result<(ValueNetwork, RunState)> {
    crate::allocator::tune_for_training();
    let system = config.system()?;
    let mut network = initial_network(config, &system);
    let mut model = Siren::from_network(&network, device);
    let mut adam = AdamConfig::new();
    if let Some(norm) = config.optimizer.gradient_clip_norm {
        adam = adam.with_grad_clipping(Some(GradientClippingConfig::Norm(norm as f32)));
    }
    let mut optimizer = adam.init();
    let run = options.run;
    let mut state = RunState { config: config.clone(), iteration: 0, wall_time_s: 0.0, last_losses: None };
    if options.resume {
        state = run.load_state()?;
        ensure!(
            state.config == *config,
            "the config differs from the one the checkpoint in {} was trained with",
            run.0.display()
        );
        model = model
            .try_load_file(run.model())
            .map_err(|e| anyhow::anyhow!("loading {}: {e:?}", run.model().display()))?;
        optimizer = optimizer
            .load(run.optimizer())
            .map_err(|e| anyhow::anyhow!("loading {}: {e:?}", run.optimizer().display()))?;
        tracing::info!(iteration = state.iteration, "resumed");
    } else {
        std::fs::create_dir_all(run.checkpoint())?;
        std::fs::write(run.losses(), "")?;
    }
    let objective = {
        let mut o = Objective::new(config, &system, &network.input, device);
        o.hamiltonian_sign = options.hamiltonian_sign;
        match &config.supervision {
            Some(s) => o.with_supervision(GridSupervision::load(s, &system, config.sampling.tau_max, config.seed)?),
            None => o,
        }
    };
    let sampler = Sampler::new(
        &system,
        network.input.clone(),
        config.sampling.points,
        config.sampling.boundary_share,
        config.seed,
    )
    .with_focus(config.sampling.focus_share, config.sampling.focus_scale)
    .with_tau_exponent(config.sampling.tau_exponent);
    let total = config.optimizer.iterations;
    let end = options.max_iterations.map_or(total, |m| (state.iteration + m).min(total));
    let bar = if options.progress { indicatif::ProgressBar::new(total) } else { indicatif::ProgressBar::hidden() };
    bar.set_style(
        indicatif::ProgressStyle::with_template("{elapsed_precise} [{bar:30}] {pos}/{len} {per_sec} eta {eta} {msg}")
            .expect("progress template")
            .progress_chars("=> "),
    );
    bar.set_position(state.iteration);
    let mut log = std::fs::OpenOptions::new().append(true).open(run.losses())?;
    let call_start = Instant::now();
    let wall_before = state.wall_time_s;
    while state.iteration < end && !options.stop.load(Ordering::Relaxed) {
        let it = state.iteration;
        let batch = sampler.batch(it, config.tau_limit(it), device);
        let (loss, terms) = objective.loss(&model, &batch, it);
        ensure!(terms.total.is_finite(), "loss became {} at iteration {it}", terms.total);
        let grads = GradientsParams::from_grads(loss.backward(), &model);
        model = optimizer.step(config.learning_rate(it), model, grads);
        state.iteration += 1;
        state.last_losses =
            Some(vec![terms.total, terms.boundary, terms.residual, terms.supervision, terms.supervision_gradient]);
        state.wall_time_s = wall_before + call_start.elapsed().as_secs_f64();
        if it.is_multiple_of(10) || state.iteration == end {
            write_log_line(&mut log, it, &terms, config.tau_limit(it), config.learning_rate(it), state.wall_time_s)?;
            bar.set_message(format!(
                "loss {:.3e} (bc {:.2e}, hji {:.2e}, grid {:.2e}, grid dV/dr {:.2e})",
                terms.total, terms.boundary, terms.residual, terms.supervision, terms.supervision_gradient
            ));
        }
        bar.set_position(state.iteration);
        if state.iteration.is_multiple_of(config.checkpoint_every) {
            save_checkpoint(run, &model, &optimizer, &state)?;
        }
    }
    bar.finish();
    save_checkpoint(run, &model, &optimizer, &state)?;
    model.write_into(&mut network);
    Ok((network, state))
}

fn write_log_line(
    log: &mut std::fs::File,
    it: u64,
    terms: &LossTerms,
    tau: f64,
    lr: f64,
    wall: f64,
) -> anyhow::Result<()> {
    let line = serde_json::json!({
        "iteration": it, "loss": terms.total, "boundary": terms.boundary, "residual": terms.residual,
        "supervision": terms.supervision, "supervision_gradient": terms.supervision_gradient,
        "tau_limit": tau, "learning_rate": lr, "wall_time_s": wall,
    });
    writeln!(log, "{line}")?;
    Ok(())
}

fn save_checkpoint(
    run: &RunDir,
    model: &Siren,
    optimizer: &burn::optim::ModuleOptimizer,
    state: &RunState,
) -> anyhow::Result<()> {
    std::fs::create_dir_all(run.checkpoint())?;
    model.clone().save_file(run.model()).map_err(|e| anyhow::anyhow!("saving the model: {e:?}"))?;
    optimizer.save(run.optimizer()).map_err(|e| anyhow::anyhow!("saving the optimizer: {e:?}"))?;
    let tmp = run.state().with_extension("json.tmp");
    std::fs::write(&tmp, serde_json::to_string_pretty(state)?)?;
    std::fs::rename(tmp, run.state())?;
    Ok(())
}
