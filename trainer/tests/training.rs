//! The trainer's numerics: explicit input gradients, the exact boundary condition, and the tensor
//! Hamiltonian against the f64 one.

use burn::tensor::{Device, Tensor, TensorData};
use fastrack_trainer::config::TrainConfig;
use fastrack_trainer::features::TensorFeatures;
use fastrack_trainer::objective::Objective;
use fastrack_trainer::sampler::Sampler;
use fastrack_trainer::siren::Siren;
use fastrack_trainer::train::initial_network;
use fastrack_valuefn::network::{FeatureLayout, NetworkShape, PeriodicEncoding, ValueNetwork};
use fastrack_valuefn::system::{double_integrator, dubins4d, AffineSystem};
use rand::{Rng, SeedableRng};

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
    let network = ValueNetwork::random(&system, &NetworkShape::new(&[64, 64, 64], 30.0, false), 2.0, 3);
    let model = Siren::from_network(&network, &device);
    let mut rng = rand::rngs::StdRng::seed_from_u64(4);
    let (n, n_in) = (64, network.layers[0].n_in);
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
fn training_values_and_gradients_equal_the_f64_network() {
    // The tensor path (sampler inputs, circle features, explicit gradient, chain rule, exact boundary) and
    // the f64 network the exporter writes must be the same function: V and dV/dr at the same points.
    let device = device();
    for encoding in [PeriodicEncoding::Circle, PeriodicEncoding::Wrap] {
        let mut config = config("configs/dubins4d.toml");
        config.network.hidden = vec![32, 32];
        config.network.periodic_encoding = encoding;
        config.supervision = None;
        let system = config.system().unwrap();
        let network = initial_network(&config, &system);
        let model = Siren::from_network(&network, &device);
        let sampler = Sampler::new(&system, network.input.clone(), 256, 0.0, 21);
        let batch = sampler.batch(0, config.sampling.tau_max, &device);
        let objective = Objective::new(&config, &system, &network.input, &device);
        let terms = objective.value_terms(&model, &batch);
        let values = |t: Tensor<2>| t.into_data().try_to_vec::<f32>().unwrap();
        let (tau, state, params) = (values(batch.tau), values(batch.state), values(batch.params));
        let (value, d_state) = (values(terms.value), values(terms.d_state));
        let (ns, np) = (system.n_state(), system.n_params());
        let (mut worst_value, mut worst_gradient) = (0.0f64, 0.0f64);
        for i in 0..256 {
            let r: Vec<f64> = state[i * ns..(i + 1) * ns].iter().map(|&x| x.into()).collect();
            let p: Vec<f64> = params[i * np..(i + 1) * np].iter().map(|&x| x.into()).collect();
            let reference = network.evaluate(tau[i].into(), &r, &p);
            worst_value =
                worst_value.max((f64::from(value[i]) - reference.value).abs() / reference.value.abs().max(1.0));
            let scale = reference.grad_state.iter().fold(1.0f64, |m, g| m.max(g.abs()));
            for j in 0..ns {
                worst_gradient =
                    worst_gradient.max((f64::from(d_state[i * ns + j]) - reference.grad_state[j]).abs() / scale);
            }
        }
        assert!(
            worst_value < 1e-4 && worst_gradient < 1e-3,
            "{encoding:?}: value {worst_value:e}, dV/dr {worst_gradient:e}"
        );
    }
}

#[test]
fn circle_features_chain_rule_equals_autodiff() {
    let device = device();
    let system = dubins4d::system();
    let layout = FeatureLayout::for_system(&system, PeriodicEncoding::Circle);
    let features = TensorFeatures::new(layout.clone());
    let network = ValueNetwork::random(&system, &NetworkShape::new(&[32, 32], 30.0, false), 2.0, 8);
    let model = Siren::from_network(&network, &device);
    let mut rng = rand::rngs::StdRng::seed_from_u64(9);
    let (n, n_in) = (64, layout.n_inputs);
    let x: Vec<f32> = (0..n * n_in).map(|_| rng.random_range(-1.0f32..1.0)).collect();
    let input = Tensor::<2>::from_data(TensorData::new(x, [n, n_in]), &device).require_grad();
    let forward = model.forward(features.encode(input.clone()), 30.0);
    let chained: Vec<f32> =
        features.input_gradient(&input, forward.input_grad.clone()).into_data().try_to_vec().unwrap();
    let grads = forward.output.sum().backward();
    let autodiff: Vec<f32> = input.grad(&grads).unwrap().into_data().try_to_vec().unwrap();
    let worst = chained.iter().zip(&autodiff).map(|(a, b)| (a - b).abs() / b.abs().max(1e-2)).fold(0.0f32, f32::max);
    assert!(worst < 1e-4, "chain rule through (cos, sin) vs autodiff: {worst:e}");
}

#[test]
fn exact_boundary_model_satisfies_the_boundary_condition() {
    let device = device();
    let config = config("configs/experiments/double_integrator.toml");
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

/// `n` random states in the domain, costates in `[-2, 2]` and parameters in their ranges, row-major.
fn random_arguments(system: &AffineSystem, n: usize, seed: u64) -> (Vec<f64>, Vec<f64>, Vec<f64>) {
    let mut rng = rand::rngs::StdRng::seed_from_u64(seed);
    let mut draw = |dims: Vec<(f64, f64)>| -> Vec<f64> {
        (0..n).flat_map(|_| dims.iter().map(|&(lo, hi)| rng.random_range(lo..hi)).collect::<Vec<_>>()).collect()
    };
    let r = draw(system.state.iter().map(|d| (d.min, d.max)).collect());
    let p = draw(vec![(-2.0, 2.0); system.n_state()]);
    let b = draw(system.params.iter().map(|d| (d.min, d.max)).collect());
    (r, p, b)
}

#[test]
fn tensor_hamiltonian_equals_the_f64_hamiltonian() {
    use fastrack_trainer::dynamics::TensorDynamics;
    let device = Device::flex();
    for system in [dubins4d::system(), dubins4d::system().with_shared_parameter(), double_integrator::system()] {
        let dynamics = TensorDynamics::new(&system, &device);
        let n = 256;
        let (ns, np) = (system.n_state(), system.n_params());
        let (r, p, b) = random_arguments(&system, n, 21);
        let t = |v: &[f64], cols: usize| {
            Tensor::<2>::from_data(TensorData::new(v.iter().map(|&x| x as f32).collect::<Vec<_>>(), [n, cols]), &device)
        };
        let h: Vec<f32> = dynamics.hamiltonian(&t(&r, ns), &t(&p, ns), &t(&b, np)).into_data().try_to_vec().unwrap();
        for i in 0..n {
            let expected =
                system.hamiltonian(&r[i * ns..(i + 1) * ns], &p[i * ns..(i + 1) * ns], &b[i * np..(i + 1) * np]);
            assert!(
                (f64::from(h[i]) - expected).abs() < 1e-4 * (1.0 + expected.abs()),
                "{}: H {} vs {expected}",
                system.id,
                h[i]
            );
        }
    }
}

#[test]
fn vertex_velocities_give_the_hamiltonian() {
    use fastrack_trainer::dynamics::TensorDynamics;
    let device = Device::flex();
    for system in [dubins4d::system(), dubins4d::system().with_shared_parameter(), double_integrator::system()] {
        let dynamics = TensorDynamics::new(&system, &device);
        let n = 128;
        let (ns, np) = (system.n_state(), system.n_params());
        let (r, p, b) = random_arguments(&system, n, 22);
        let t = |v: &[f64], cols: usize| {
            Tensor::<2>::from_data(TensorData::new(v.iter().map(|&x| x as f32).collect::<Vec<_>>(), [n, cols]), &device)
        };
        let (r, p, b) = (t(&r, ns), t(&p, ns), t(&b, np));
        // min over control vertices of max over opponent vertices of p . r' is H for an affine system.
        let h_vertices = dynamics
            .vertex_velocities(&r, &b)
            .into_iter()
            .map(|group| group.into_iter().map(|v| p.clone().mul(v).sum_dim(1)).reduce(|x, y| x.max_pair(y)).unwrap())
            .reduce(|x, y| x.min_pair(y))
            .unwrap();
        let gap: f32 = (h_vertices - dynamics.hamiltonian(&r, &p, &b)).abs().max().into_scalar();
        assert!(gap < 1e-4, "{}: vertex Hamiltonian differs by {gap:e}", system.id);
    }
}

#[test]
fn semi_lagrangian_residual_tends_to_the_differential_one() {
    use fastrack_trainer::config::{LossForm, Residual};
    let device = device();
    let mut config = config("configs/experiments/double_integrator.toml");
    // A smooth network whose value stays well above l, so that both residuals are dV/dtau - H.
    config.loss.form = LossForm::Paper;
    config.network.omega_0 = 3.0;
    config.network.output_offset = 10.0;
    config.loss.time_step = 1e-3;
    let system = config.system().unwrap();
    let network = initial_network(&config, &system);
    let model = Siren::from_network(&network, &device);
    let batch = Sampler::new(&system, network.input.clone(), 2048, 1e-3, 5).batch(0, 2.0, &device);
    let mut residual = |kind| {
        config.loss.residual = kind;
        Objective::new(&config, &system, &network.input, &device).loss(&model, &batch, 0).1.residual
    };
    let (differential, semi_lagrangian) = (residual(Residual::Differential), residual(Residual::SemiLagrangian));
    assert!(
        (semi_lagrangian - differential).abs() < 0.02 * differential,
        "semi-Lagrangian {semi_lagrangian} vs differential {differential}"
    );
}
