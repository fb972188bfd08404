//! `compare` evaluates a diagonal-mode bundle (one shared `beta`) on a grid solved with `beta` for every
//! planner input: the learned values on the grid equal the network's own f64 evaluation at that `beta`, and
//! the bundle's system is the shared-parameter form of its id.

use fastrack_grid::compare::learned_on_grid;
use fastrack_grid::grid::Grid;
use fastrack_grid::solver::{solve, SolverConfig};
use fastrack_valuefn::network::{NetworkShape, ValueNetwork};
use fastrack_valuefn::onnx_writer::write_value_graph;
use fastrack_valuefn::runtime::{runtime, Evaluator, GraphDims};
use fastrack_valuefn::system::{dubins4d, for_bundle};

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
    assert_eq!(learned.len(), grid.num_points());
    let mut r = vec![0.0; 4];
    for (flat, value) in learned.iter().enumerate() {
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
