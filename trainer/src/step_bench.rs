//! Training-speed benchmark: iterations/s and achieved GFLOP/s of one DeepReach iteration for given
//! network widths and point counts, beside this machine's measured f32 matmul rate (burn flex, large
//! square matrices) and a PyTorch CPU reference of the same iteration when `torch` is importable.

use crate::config::TrainConfig;
use crate::objective::Objective;
use crate::sampler::Sampler;
use crate::train::initial_network;
use anyhow::Context;
use burn::optim::{AdamConfig, GradientsParams};
use burn::tensor::{Device, Distribution, Tensor};
use fastrack_valuefn::network::PeriodicEncoding;
use std::time::Instant;

/// One benchmark case.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Case {
    /// Hidden width (every layer).
    pub width: usize,
    /// Hidden layers.
    pub depth: usize,
    /// Points per iteration.
    pub points: usize,
    /// Timed iterations.
    pub iterations: u64,
}

/// Floating-point operations of one iteration: forward matmuls `F` (multiply-adds), the explicit input
/// gradient (about `F` again), and autodiff's backward of both (two matmuls per matmul): `6 F` MACs.
/// `n_in` is the number of first-layer features.
pub fn flops_per_iteration(case: &Case, n_in: usize) -> f64 {
    let macs_forward =
        case.points as f64 * (n_in * case.width + (case.depth - 1) * case.width * case.width + case.width) as f64;
    12.0 * macs_forward
}

/// Iterations per second of `case` on `device`, with `base` as the rest of the configuration.
pub fn iterations_per_second(base: &TrainConfig, case: &Case, device: &Device) -> anyhow::Result<f64> {
    crate::allocator::tune_for_training();
    let mut config = base.clone();
    config.network.hidden = vec![case.width; case.depth];
    config.sampling.points = case.points;
    let system = config.system()?;
    let network = initial_network(&config, &system);
    let mut model = crate::siren::Siren::from_network(&network, device);
    let mut optimizer = AdamConfig::new().init();
    let objective = Objective::new(&config, &system, &network.input, device);
    let sampler =
        Sampler::new(&system, network.input.clone(), case.points, config.sampling.boundary_share, config.seed);
    let mut run = |it: u64| {
        let batch = sampler.batch(it, config.sampling.tau_max, device);
        let (loss, _) = objective.loss(&model, &batch, it);
        let grads = GradientsParams::from_grads(loss.backward(), &model);
        model = optimizer.step(1e-5, model.clone(), grads);
    };
    run(0);
    let start = Instant::now();
    for it in 1..=case.iterations {
        run(it);
    }
    Ok(case.iterations as f64 / start.elapsed().as_secs_f64())
}

/// f32 GFLOP/s of `n x n` matmuls on `device` (burn flex: the engine training uses).
pub fn matmul_gflops(n: usize, repeats: usize, device: &Device) -> f64 {
    let a: Tensor<2> = Tensor::random([n, n], Distribution::Uniform(-1.0, 1.0), device);
    let b: Tensor<2> = Tensor::random([n, n], Distribution::Uniform(-1.0, 1.0), device);
    let _: f32 = a.clone().matmul(b.clone()).sum().into_scalar();
    let start = Instant::now();
    for _ in 0..repeats {
        let _: f32 = a.clone().matmul(b.clone()).sum().into_scalar();
    }
    2.0 * (n as f64).powi(3) * repeats as f64 / start.elapsed().as_secs_f64() / 1e9
}

/// PyTorch's iterations/s for `case` through `bench/torch_step.py` (the heading encoded as `encoding`), or
/// why it could not run.
pub fn torch_iterations_per_second(case: &Case, encoding: PeriodicEncoding) -> Result<(f64, String), String> {
    let script = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("bench/torch_step.py");
    let encoding = match encoding {
        PeriodicEncoding::Circle => "circle",
        PeriodicEncoding::Wrap => "wrap",
    };
    let output = std::process::Command::new("python3")
        .arg(&script)
        .args([case.width, case.depth, case.points].map(|x| x.to_string()))
        .arg(case.iterations.to_string())
        .arg(encoding)
        .output()
        .map_err(|e| format!("python3: {e}"))?;
    if !output.status.success() {
        let stderr = String::from_utf8_lossy(&output.stderr);
        return Err(stderr.lines().last().unwrap_or("torch reference failed").to_string());
    }
    let value: serde_json::Value = serde_json::from_slice(&output.stdout).map_err(|e| e.to_string())?;
    let rate = value["iterations_per_s"].as_f64().context("no rate").map_err(|e| e.to_string())?;
    Ok((rate, format!("torch {} ({} threads)", value["torch"].as_str().unwrap_or("?"), value["threads"])))
}
