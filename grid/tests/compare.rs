//! `compare` evaluates a diagonal-mode bundle (one shared `beta`) on a grid solved with `beta` for every
//! planner input: the learned values on the grid equal the network's own f64 evaluation at that `beta`, and
//! the bundle's system is the shared-parameter form of its id. Its control figures are 100% agreement and no
//! loss for the grid's own control, and the closed-form loss of the opposite vertex for a flipped one. A
//! bundle of a decomposed system is evaluated along each axis in the full state, against the combined bound.

use fastrack_grid::compare::{combined_on_axis, compare, learned_on_axis, learned_on_grid, Learned};
use fastrack_grid::grid::Grid;
use fastrack_grid::solver::{solve, Solution, SolverConfig};
use fastrack_valuefn::composite::{AxisNetwork, Composite};
use fastrack_valuefn::network::{NetworkShape, ValueNetwork};
use fastrack_valuefn::onnx_writer::{write_composite_graph, write_value_graph};
use fastrack_valuefn::runtime::{runtime, Evaluator, GraphDims};
use fastrack_valuefn::system::{by_id, decomposition, dubins4d, for_bundle, quad10d, DecomposedAxis};

#[test]
fn a_diagonal_bundle_is_evaluated_at_the_solutions_beta() {
    let (beta, horizon) = (0.8, 1.0);
    let system = dubins4d::system();
    let grid = Grid::for_system(&system, &[5, 5, 5, 5]).unwrap();
    let config = SolverConfig { horizon_cap: 0.05, ..SolverConfig::default() };
    let solution = solve(&system, &[beta, beta], &grid, &config, false).unwrap();

    let shared = for_bundle(dubins4d::ID, 1).unwrap();
    assert_eq!((shared.n_params(), shared.planner_input_param.clone()), (1, vec![0, 0]));
    let network = ValueNetwork::random(&shared, &NetworkShape::new(&[16, 16], 30.0, true), horizon, 9);
    let onnx = write_value_graph(&network, &shared, horizon);
    let dims = GraphDims { n_state: 4, n_params: 1, n_control: 2 };
    let evaluator = Evaluator::new(runtime(None).unwrap(), &onnx, dims, 1).unwrap();

    let learned = learned_on_grid(&evaluator, &solution, &[beta]).unwrap();
    assert_eq!(learned.values.len(), grid.num_points());
    assert_eq!(learned.controls.len(), 2 * grid.num_points());
    let mut r = vec![0.0; 4];
    for (flat, value) in learned.values.iter().enumerate() {
        grid.point(flat, &mut r);
        let reference = network.evaluate(horizon, &r, &[beta]).value;
        assert!((value - reference).abs() < 1e-4 * reference.abs().max(1.0), "node {flat}: {value} vs {reference}");
    }
}

#[test]
fn a_bundle_system_is_the_system_or_its_shared_parameter_form() {
    assert_eq!(for_bundle(dubins4d::ID, 2).unwrap().n_params(), 2);
    assert_eq!(for_bundle(dubins4d::ID, 1).unwrap().params[0].name, "beta");
    assert!(for_bundle(dubins4d::ID, 3).is_none());
    assert!(for_bundle("quadcopter13d", 1).is_none());
}

#[test]
fn the_control_figures_are_nil_for_the_grids_control_and_the_vertex_gap_for_a_flipped_one() {
    let system = dubins4d::system();
    let grid = Grid::for_system(&system, &[9, 9, 9, 9]).unwrap();
    let config = SolverConfig { horizon_cap: 0.5, ..SolverConfig::default() };
    let solution = solve(&system, &[0.8, 0.8], &grid, &config, false).unwrap();
    let (mut r, mut p) = (vec![0.0; 4], vec![0.0; 4]);
    let (mut best, mut flipped) = (Vec::new(), Vec::new());
    // On the set {V <= 3 V_min}: the control mirrored within its range, lo + hi - u*, loses
    // sum_j |s_j| (hi_j - lo_j) (s = G_u^T p), and equals u* only where u* is the midpoint (s_j = 0).
    let v_min = solution.v_min();
    let (mut expected_loss, mut set_nodes, mut ties) = (0.0, 0usize, [0usize; 2]);
    for flat in 0..grid.num_points() {
        grid.point(flat, &mut r);
        solution.gradient(&r, &mut p);
        let range = system.control_range(&r);
        let u = system.optimal_control(&r, &p);
        let switching = [p[2], p[3]];
        let in_set = solution.values[flat] <= 3.0 * v_min;
        for j in 0..2 {
            let (lo, hi) = (range.lo()[j], range.hi()[j]);
            assert!(
                u[j] == if switching[j] > 0.0 {
                    lo
                } else if switching[j] < 0.0 {
                    hi
                } else {
                    0.5 * (lo + hi)
                }
            );
            let mirrored = lo + hi - u[j];
            if in_set {
                expected_loss += switching[j].abs() * (hi - lo);
                ties[j] += usize::from((mirrored - u[j]).abs() <= 1e-3 * (hi - lo).max(1e-12));
            }
            flipped.push(mirrored);
        }
        set_nodes += usize::from(in_set);
        best.extend(u);
    }
    let values = solution.values.clone();
    let exact = compare(&system, &solution, &Learned { values: values.clone(), controls: best }, 3.0);
    assert_eq!(exact.set_nodes, set_nodes);
    assert_eq!(exact.control_agreement, vec![1.0, 1.0]);
    assert_eq!((exact.mean_control_loss, exact.max_control_loss), (0.0, 0.0));
    let wrong = compare(&system, &solution, &Learned { values, controls: flipped }, 3.0);
    for (j, (&agreement, &tied)) in wrong.control_agreement.iter().zip(&ties).enumerate() {
        assert_eq!(agreement, tied as f64 / set_nodes as f64, "control {j}");
    }
    assert!(wrong.control_agreement.iter().all(|&a| a < 0.5), "agreement {:?}", wrong.control_agreement);
    let mean = expected_loss / set_nodes as f64;
    assert!((wrong.mean_control_loss - mean).abs() < 1e-9 * mean.max(1.0), "{} vs {mean}", wrong.mean_control_loss);
    assert!(wrong.max_control_loss >= mean && mean > 0.0);
}

#[test]
fn a_composite_bundle_is_compared_along_each_axis_with_the_combined_bound() {
    let beta = 0.8;
    let system = quad10d::system();
    let config = SolverConfig { horizon_cap: 0.1, ..SolverConfig::default() };
    let mut solved: Vec<(DecomposedAxis, Solution)> = Vec::new();
    let mut networks = Vec::new();
    for (seed, axis) in decomposition(quad10d::ID).unwrap().into_iter().enumerate() {
        let subsystem = by_id(axis.subsystem).unwrap();
        let n = if axis.coords.len() == 2 { vec![21, 21] } else { vec![7; 4] };
        let grid = Grid::for_system(&subsystem, &n).unwrap();
        solved.push((axis.clone(), solve(&subsystem, &[beta], &grid, &config, false).unwrap()));
        let network = ValueNetwork::random(&subsystem, &NetworkShape::new(&[16, 16], 30.0, true), 2.0, seed as u64);
        networks.push(AxisNetwork { axis, subsystem, network, tau: 1.0 });
    }
    let composite = Composite::new(system.clone(), networks).unwrap();
    let dims = GraphDims::of_system(&system);
    let evaluator = Evaluator::new(runtime(None).unwrap(), &write_composite_graph(&composite), dims, 1).unwrap();
    let pairs: Vec<(DecomposedAxis, &Solution)> = solved.iter().map(|(a, s)| (a.clone(), s)).collect();
    let v_min = |s: &Solution| s.values.iter().copied().fold(f64::INFINITY, f64::min);
    let bound = (2.0 * v_min(&solved[0].1).powi(2) + v_min(&solved[2].1).powi(2)).sqrt();

    for (k, (axis, solution)) in solved.iter().enumerate() {
        let slice = combined_on_axis(&system, &pairs, k);
        // The reference is the combined bound on the axis' own nodes: its minimum is the bound.
        assert!((v_min(&slice.reference) - bound).abs() < 1e-12, "axis {k}: {} vs {bound}", v_min(&slice.reference));
        assert_eq!(slice.controls, vec![k], "axis {k} is driven by control {k}");
        let learned = learned_on_axis(&evaluator, &slice, &[beta; 3]).unwrap();
        let grid = &solution.grid;
        assert_eq!((learned.values.len(), learned.controls.len()), (grid.num_points(), grid.num_points()));
        let mut node = vec![0.0; grid.ndim()];
        for flat in (0..grid.num_points()).step_by(37) {
            grid.point(flat, &mut node);
            let mut state = slice.base.clone();
            for (&i, &x) in axis.coords.iter().zip(&node) {
                state[i] = x;
            }
            let state: Vec<f64> = state.iter().map(|&x| f64::from(x as f32)).collect();
            let reference = composite.evaluate(&state, &[beta; 3]);
            let value = learned.values[flat];
            assert!((value - reference.value).abs() < 1e-4 * reference.value.max(1.0), "{value} vs {reference:?}");
            assert_eq!(learned.controls[flat], f64::from(reference.control[k] as f32), "axis {k} node {flat}");
        }
        // Every other axis sits at its own solution's minimiser.
        for (b, (other, other_solution)) in solved.iter().enumerate().filter(|(b, _)| *b != k) {
            let at: Vec<f64> = other.coords.iter().map(|&i| slice.base[i]).collect();
            let value = other_solution.grid.interpolate(&other_solution.values, &at);
            assert!((value - v_min(other_solution)).abs() < 1e-9, "axis {b} in the base state of axis {k}");
        }
    }
}
