//! A graph written by the ONNX writer, run by ONNX Runtime through the evaluator, against an independent
//! f64 evaluation of the same network, finite differences, and the system's control law.

use fastrack_valuefn::composite::{AxisNetwork, Composite, CompositeError};
use fastrack_valuefn::network::{NetworkShape, PeriodicEncoding, ValueNetwork};
use fastrack_valuefn::onnx_writer::{write_composite_graph, write_value_graph};
use fastrack_valuefn::runtime::{runtime, Evaluator, GraphDims};
use fastrack_valuefn::system::{by_id, decomposition, double_integrator, dubins4d, quad10d, AffineSystem};
use rand::{Rng, SeedableRng};

const N: usize = 1000;

fn random_batch(system: &AffineSystem, n: usize, seed: u64) -> (Vec<f32>, Vec<f32>) {
    let mut rng = rand::rngs::StdRng::seed_from_u64(seed);
    let mut states = Vec::new();
    let mut params = Vec::new();
    for _ in 0..n {
        // Periodic coordinates stay 0.01 off the wrap seam so central differences do not straddle it.
        states.extend(system.state.iter().map(|d| {
            let margin = if d.periodic { 0.01 } else { 0.0 };
            rng.random_range(d.min + margin..d.max - margin) as f32
        }));
        params.extend(system.params.iter().map(|p| rng.random_range(p.min..p.max) as f32));
    }
    (states, params)
}

fn check_roundtrip(system: &AffineSystem, exact_boundary: bool, seed: u64) {
    let network = ValueNetwork::random(system, &NetworkShape::new(&[256, 256, 256], 30.0, exact_boundary), 2.0, seed);
    check_network_roundtrip(system, &network, exact_boundary, seed);
}

fn check_network_roundtrip(system: &AffineSystem, network: &ValueNetwork, exact_boundary: bool, seed: u64) {
    let tau = 1.7;
    let onnx = write_value_graph(network, system, tau);
    let dims = GraphDims::of_system(system);
    let evaluator =
        Evaluator::new(runtime(None).expect("ONNX Runtime (scripts/setup-onnxruntime.sh)"), &onnx, dims, 1).unwrap();
    let (states, params) = random_batch(system, N, seed + 1);
    let out = evaluator.evaluate(&states, &params).unwrap();
    let (ns, np, nc) = (dims.n_state, dims.n_params, dims.n_control);
    assert_eq!((out.value.len(), out.grad.len(), out.control.len()), (N, N * ns, N * nc));

    // value vs the f64 reference, 1e-5 relative (relative to max(|V|, 1): the network's output scale).
    let mut worst_value = 0.0f64;
    for i in 0..N {
        let s: Vec<f64> = states[i * ns..(i + 1) * ns].iter().map(|&x| x.into()).collect();
        let p: Vec<f64> = params[i * np..(i + 1) * np].iter().map(|&x| x.into()).collect();
        let reference = network.evaluate(tau, &s, &p);
        let err = (f64::from(out.value[i]) - reference.value).abs() / reference.value.abs().max(1.0);
        worst_value = worst_value.max(err);
    }
    assert!(worst_value < 1e-5, "value vs f64 reference: worst relative error {worst_value:e}");

    // grad vs central finite differences of the value. The graph's value equals the f64 network to 1e-5
    // (above), so the differences are taken on the f64 network (h = 1e-5): differencing the f32 output
    // itself is rounding-limited at about 1e-3 here, too coarse to test a 1e-3 tolerance.
    let h = 1e-5;
    let mut worst_grad = 0.0f64;
    for i in 0..N {
        let s: Vec<f64> = states[i * ns..(i + 1) * ns].iter().map(|&x| x.into()).collect();
        let p: Vec<f64> = params[i * np..(i + 1) * np].iter().map(|&x| x.into()).collect();
        // With the exact boundary condition V contains |e|, with a kink at e = 0: skip items within 1e-3.
        if exact_boundary && system.tracking_error(&s) < 1e-3 {
            continue;
        }
        let g = &out.grad[i * ns..(i + 1) * ns];
        worst_grad = worst_grad.max(gradient_error(g, &s, h, |x| network.evaluate(tau, x, &p).value));
    }
    assert!(worst_grad < 1e-3, "grad vs central differences: worst relative error {worst_grad:e}");

    // control = the system's control law at the item's state applied to the graph's grad.
    let mut at_limits = 0;
    for i in 0..N {
        let s: Vec<f64> = states[i * ns..(i + 1) * ns].iter().map(|&x| x.into()).collect();
        let g: Vec<f64> = out.grad[i * ns..(i + 1) * ns].iter().map(|&x| x.into()).collect();
        let expected = system.optimal_control(&s, &g);
        let got: Vec<f64> = out.control[i * nc..(i + 1) * nc].iter().map(|&x| x.into()).collect();
        assert_eq!(got, expected, "control of item {i}");
        at_limits += usize::from(system.control_range(&s) != system.control_box());
    }
    // Uniform states reach dubins4d's speed limits (0.1 of the 3 m/s speed domain at each end).
    let limited = system.state.iter().any(|d| d.limits.is_some());
    assert!(!limited || at_limits > N / 40, "{at_limits} of {N} items at a limit");
    eprintln!("{} exact_bc={exact_boundary}: value err {worst_value:.2e}, grad err {worst_grad:.2e}", system.id);
}

#[test]
fn dubins4d_graph_matches_reference() {
    check_roundtrip(&dubins4d::system(), false, 1);
}

#[test]
fn dubins4d_exact_boundary_graph_matches_reference() {
    check_roundtrip(&dubins4d::system(), true, 2);
}

#[test]
fn double_integrator_graph_matches_reference() {
    check_roundtrip(&double_integrator::system(), false, 3);
}

#[test]
fn dubins4d_wrapped_heading_graph_matches_reference() {
    let system = dubins4d::system();
    let network = ValueNetwork::random(
        &system,
        &NetworkShape { periodic_encoding: PeriodicEncoding::Wrap, ..NetworkShape::new(&[64, 64], 30.0, true) },
        2.0,
        4,
    );
    assert_eq!(network.layers[0].n_in, 1 + 4 + 2, "tau, the four coordinates and two parameters");
    check_network_roundtrip(&system, &network, true, 4);
}

#[test]
fn circle_encoded_network_is_periodic_and_has_two_heading_features() {
    let system = dubins4d::system();
    let network = ValueNetwork::random(&system, &NetworkShape::new(&[32, 32], 30.0, true), 2.0, 6);
    assert_eq!(network.layers[0].n_in, 1 + 3 + 2 + 2, "tau, x, y, v, two parameters, cos and sin of theta");
    // Across the seam at -pi / pi the f64 network is continuous in value and gradient.
    let just_below = network.evaluate(1.0, &[0.3, -0.2, std::f64::consts::PI - 1e-7, 1.0], &[0.9, 0.9]);
    let just_above = network.evaluate(1.0, &[0.3, -0.2, -std::f64::consts::PI + 1e-7, 1.0], &[0.9, 0.9]);
    assert!((just_below.value - just_above.value).abs() < 1e-5);
    for (a, b) in just_below.grad_state.iter().zip(&just_above.grad_state) {
        assert!((a - b).abs() < 1e-4, "{:?} vs {:?}", just_below.grad_state, just_above.grad_state);
    }
}

#[test]
fn exact_boundary_graph_wraps_periodic_state() {
    // theta and theta + 2 pi give the same value and gradient.
    let system = dubins4d::system();
    let network = ValueNetwork::random(&system, &NetworkShape::new(&[32, 32], 30.0, true), 2.0, 5);
    let onnx = write_value_graph(&network, &system, 1.0);
    let dims = GraphDims { n_state: 4, n_params: 2, n_control: 2 };
    let evaluator = Evaluator::new(runtime(None).unwrap(), &onnx, dims, 1).unwrap();
    let a = evaluator.evaluate(&[0.5, -0.3, 1.0, 1.2], &[0.8, 0.9]).unwrap();
    let b = evaluator.evaluate(&[0.5, -0.3, 1.0 + 2.0 * std::f32::consts::PI, 1.2], &[0.8, 0.9]).unwrap();
    assert!((a.value[0] - b.value[0]).abs() < 1e-5, "{} vs {}", a.value[0], b.value[0]);
}

/// quad10d's axes, each with a random network of its subsystem.
fn random_axes(seed: u64) -> Vec<AxisNetwork> {
    decomposition(quad10d::ID)
        .unwrap()
        .into_iter()
        .zip(seed..)
        .map(|(axis, seed)| {
            let subsystem = by_id(axis.subsystem).unwrap();
            let network = ValueNetwork::random(&subsystem, &NetworkShape::new(&[64, 64], 30.0, true), 2.0, seed);
            AxisNetwork { axis, subsystem, network, tau: 1.3 }
        })
        .collect()
}

#[test]
fn quad10d_composite_graph_matches_its_reference_finite_differences_and_the_axes_controls() {
    let system = quad10d::system();
    let composite = Composite::new(system.clone(), random_axes(40)).unwrap();
    let onnx = write_composite_graph(&composite);
    let dims = GraphDims::of_system(&system);
    let evaluator =
        Evaluator::new(runtime(None).expect("ONNX Runtime (scripts/setup-onnxruntime.sh)"), &onnx, dims, 1).unwrap();
    let (states, params) = random_batch(&system, N, 41);
    let out = evaluator.evaluate(&states, &params).unwrap();
    let (ns, np, nc) = (dims.n_state, dims.n_params, dims.n_control);
    let (mut worst_value, mut worst_grad, mut compared) = (0.0f64, 0.0f64, 0);
    let h = 1e-5;
    for i in 0..N {
        let s: Vec<f64> = states[i * ns..(i + 1) * ns].iter().map(|&x| x.into()).collect();
        let p: Vec<f64> = params[i * np..(i + 1) * np].iter().map(|&x| x.into()).collect();
        let reference = composite.evaluate(&s, &p);
        // The value from the axis networks themselves: sqrt of the sum of their clamped squares.
        let by_axes = composite
            .axes()
            .iter()
            .map(|a| {
                let sub: Vec<f64> = a.axis.coords.iter().map(|&j| s[j]).collect();
                a.network.evaluate(a.tau, &sub, &[p[a.axis.param]]).value.max(0.0).powi(2)
            })
            .sum::<f64>()
            .sqrt();
        assert!((reference.value - by_axes).abs() < 1e-12);
        worst_value = worst_value.max((f64::from(out.value[i]) - by_axes).abs() / by_axes.max(1.0));
        let got: Vec<f64> = out.control[i * nc..(i + 1) * nc].iter().map(|&x| x.into()).collect();
        // grad vs central differences of the f64 composite, away from kinks: each axis' |e| at 0 and the clamp
        // of a value at 0.
        let clear = composite.axes().iter().all(|a| {
            let sub: Vec<f64> = a.axis.coords.iter().map(|&j| s[j]).collect();
            a.subsystem.tracking_error(&sub) > 1e-3 && a.network.evaluate(a.tau, &sub, &[p[a.axis.param]]).value > 1e-3
        });
        if !clear {
            // Where an axis' value is clamped at 0 its share of the composite's grad is 0, and the control is
            // still that axis' law on its own gradient (in f32, as the graph computes the bounds).
            let reference_f32: Vec<f64> = reference.control.iter().map(|&u| f64::from(u as f32)).collect();
            assert_eq!(got, reference_f32, "control of item {i}");
            continue;
        }
        compared += 1;
        let g = &out.grad[i * ns..(i + 1) * ns];
        worst_grad = worst_grad.max(gradient_error(g, &s, h, |x| composite.evaluate(x, &p).value));
        // Where every axis' value is positive, the control is the system's law on the composite's grad.
        let grad: Vec<f64> = g.iter().map(|&x| x.into()).collect();
        let expected: Vec<f64> = system.optimal_control(&s, &grad).iter().map(|&u| f64::from(u as f32)).collect();
        assert_eq!(got, expected, "control of item {i}");
    }
    eprintln!("quad10d composite: value err {worst_value:.2e}, grad err {worst_grad:.2e} over {compared} items");
    assert!(worst_value < 1e-5, "value vs the axes: worst relative error {worst_value:e}");
    assert!(compared > N / 4, "only {compared} items away from the kinks");
    assert!(worst_grad < 1e-3, "grad vs central differences: worst relative error {worst_grad:e}");
}

#[test]
fn a_composite_takes_the_decomposition_s_axes_in_order_and_nothing_else() {
    let system = quad10d::system();
    let mut swapped = random_axes(50);
    swapped.swap(0, 2);
    assert!(matches!(Composite::new(system.clone(), swapped), Err(CompositeError::Axis { index: 0, .. })));
    let mut short = random_axes(50);
    short.pop();
    let error = Composite::new(system.clone(), short).unwrap_err();
    assert!(error.to_string().contains("2 axes given; quad10d has 3"), "{error}");
    let mut wrong_network = random_axes(50);
    let dubins = dubins4d::system();
    wrong_network[2].network = ValueNetwork::random(&dubins, &NetworkShape::new(&[8], 30.0, true), 2.0, 1);
    let error = Composite::new(system, wrong_network).unwrap_err();
    assert!(error.to_string().contains("the network takes 4 state coordinates and 2 parameters"), "{error}");
    let error = Composite::new(dubins, random_axes(50)).unwrap_err();
    assert_eq!(error, CompositeError::NotDecomposed("dubins4d".into()));
}

/// The largest difference between the graph's gradient `g` at `s` and central differences of `value` (step
/// `h`), relative to the gradient's largest component (at least 1e-2).
fn gradient_error(g: &[f32], s: &[f64], h: f64, value: impl Fn(&[f64]) -> f64) -> f64 {
    let scale = g.iter().map(|x| f64::from(*x).abs()).fold(0.0, f64::max).max(1e-2);
    let mut worst = 0.0f64;
    for (j, &gj) in g.iter().enumerate() {
        let (mut a, mut b) = (s.to_vec(), s.to_vec());
        a[j] += h;
        b[j] -= h;
        worst = worst.max(((value(&a) - value(&b)) / (2.0 * h) - f64::from(gj)).abs() / scale);
    }
    worst
}
