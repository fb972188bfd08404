//! The trainer's numerics: explicit input gradients, the exact boundary condition, and a short DeepReach
//! run on the double integrator against its closed-form tracking error bound.

use burn::tensor::{Device, Tensor, TensorData};
use fastrack_trainer::config::TrainConfig;
use fastrack_trainer::model::Siren;
use fastrack_trainer::objective::Objective;
use fastrack_trainer::sampler::Sampler;
use fastrack_trainer::train::{initial_network, train, RunDir, Session};
use fastrack_valuefn::network::ValueNetwork;
use fastrack_valuefn::system::{double_integrator, dubins4d};
use fastrack_valuefn::teb::{minimise, AtHorizon, TebOptions};
use rand::{Rng, SeedableRng};
use std::sync::atomic::AtomicBool;
use std::sync::Arc;

fn device() -> Device {
    Device::flex().autodiff()
}

fn config(path: &str) -> TrainConfig {
    TrainConfig::load(&std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join(path)).unwrap()
}

#[test]
fn explicit_input_gradient_equals_finite_differences_and_autodiff() {
    let device = device();
    let system = dubins4d::system();
    let network = ValueNetwork::random(&system, &[64, 64, 64], 30.0, 2.0, false, 3);
    let model = Siren::from_network(&network, &device);
    let mut rng = rand::rngs::StdRng::seed_from_u64(4);
    let (n, n_in) = (64, 7);
    let x: Vec<f32> = (0..n * n_in).map(|_| rng.random_range(-1.0f32..1.0)).collect();
    let input = Tensor::<2>::from_data(TensorData::new(x.clone(), [n, n_in]), &device).require_grad();
    let forward = model.forward(input.clone(), 30.0);
    let explicit: Vec<f32> = forward.input_grad.clone().into_data().try_to_vec().unwrap();
    let output: Vec<f32> = forward.output.clone().into_data().try_to_vec().unwrap();

    // burn's own first-order gradient of sum(y) with respect to the input.
    let grads = forward.output.sum().backward();
    let autodiff: Vec<f32> = input.grad(&grads).unwrap().into_data().try_to_vec().unwrap();
    let worst_autodiff =
        explicit.iter().zip(&autodiff).map(|(a, b)| (a - b).abs() / b.abs().max(1e-2)).fold(0.0f32, f32::max);
    assert!(worst_autodiff < 1e-4, "explicit vs autodiff: {worst_autodiff:e}");

    // Central differences (f32 network, h = 1e-3 in normalised units; error scaled by max(|g|, |y|)).
    let h = 1e-3f32;
    let mut worst_fd = 0.0f32;
    for j in 0..n_in {
        let shifted = |sign: f32| {
            let mut v = x.clone();
            for i in 0..n {
                v[i * n_in + j] += sign * h;
            }
            let t = Tensor::<2>::from_data(TensorData::new(v, [n, n_in]), &device);
            model.forward(t, 30.0).output.into_data().try_to_vec::<f32>().unwrap()
        };
        let (plus, minus) = (shifted(1.0), shifted(-1.0));
        for i in 0..n {
            let fd = (plus[i] - minus[i]) / (2.0 * h);
            let g = &explicit[i * n_in..(i + 1) * n_in];
            let scale = g.iter().fold(output[i].abs(), |m, x| m.max(x.abs()));
            worst_fd = worst_fd.max((fd - g[j]).abs() / scale);
        }
    }
    assert!(worst_fd < 1e-3, "explicit vs central differences: {worst_fd:e}");
}

#[test]
fn exact_boundary_model_satisfies_the_boundary_condition() {
    let device = device();
    let config = config("configs/double_integrator.toml");
    let system = config.system().unwrap();
    let network = initial_network(&config, &system);
    let model = Siren::from_network(&network, &device);
    let sampler = Sampler::new(&system, network.input.clone(), 512, 0.0, 9);
    let batch = sampler.batch(0, 0.0, &device);
    let objective = Objective::new(&config, &system, &network.input, &device);
    let terms = objective.value_terms(&model, &batch);
    let gap: f32 = (terms.value - terms.error).abs().max().into_scalar();
    assert!(gap < 1e-6, "V(r, 0) - l(r) = {gap:e}");
}

/// Trains the double-integrator config and returns `(beta, learned V_min, closed form)` at two betas.
fn train_double_integrator(hamiltonian_sign: f64) -> Vec<(f64, f64, f64)> {
    let config = config("configs/double_integrator.toml");
    let run_dir = tempfile::tempdir().unwrap();
    let run = RunDir(run_dir.path().into());
    let session = Session {
        run: &run,
        resume: false,
        max_iterations: None,
        progress: false,
        stop: Arc::new(AtomicBool::new(false)),
        hamiltonian_sign,
    };
    let (network, _) = train(&config, &device(), session).unwrap();
    let system = double_integrator::system();
    let oracle = AtHorizon { network: &network, tau: config.sampling.tau_max };
    let mut rng = rand::rngs::StdRng::seed_from_u64(5);
    [0.6, 0.9]
        .iter()
        .map(|&beta| {
            let (v_min, _) = minimise(&oracle, &system, &[beta], &TebOptions::default(), &mut rng).unwrap();
            (beta, v_min, double_integrator::closed_form_teb(beta))
        })
        .collect()
}

#[test]
fn double_integrator_training_reaches_the_closed_form_bound() {
    for (beta, learned, exact) in train_double_integrator(1.0) {
        let error = (learned - exact).abs() / exact;
        eprintln!("beta {beta}: learned V_min {learned:.4}, closed form {exact:.4}, error {:.1}%", 100.0 * error);
        assert!(error < 0.10, "beta {beta}: learned {learned} vs closed form {exact} ({:.1}%)", 100.0 * error);
    }
}

#[test]
fn a_wrong_hamiltonian_sign_misses_the_closed_form_bound() {
    let results = train_double_integrator(-1.0);
    assert!(
        results.iter().any(|(_, learned, exact)| (learned - exact).abs() / exact >= 0.10),
        "a negated Hamiltonian must not reach the bound: {results:?}"
    );
}
