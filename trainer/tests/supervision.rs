//! Grid supervision: solutions that do not fit the run are refused with the reason, and the drawn targets
//! are the grid's values where the network is evaluated.

use burn::tensor::Device;
use fastrack_grid::format::save;
use fastrack_grid::grid::{Axis, Grid};
use fastrack_grid::solver::{solve, Solution, SolverConfig};
use fastrack_grid::spec::{SeriesSolve, SolutionStore, SolveSeries, DEFAULT_STORE};
use fastrack_grid::store::solve_or_load;
use fastrack_trainer::config::{GradientMetric, SupervisionConfig};
use fastrack_trainer::supervision::GridSupervision;
use fastrack_valuefn::system::{double_integrator, dubins4d, AffineSystem};
use std::path::{Path, PathBuf};

/// A short solve of `system` at `params` on a coarse grid, saved under `dir`.
fn solved(dir: &Path, name: &str, system: &AffineSystem, params: &[f64], horizon: f64) -> (PathBuf, Solution) {
    let grid = Grid::for_system(system, &vec![7; system.n_state()]).unwrap();
    solved_on(dir, name, system, params, horizon, &grid)
}

/// A short solve of `system` at `params` on `grid`, saved under `dir`.
fn solved_on(
    dir: &Path,
    name: &str,
    system: &AffineSystem,
    params: &[f64],
    horizon: f64,
    grid: &Grid,
) -> (PathBuf, Solution) {
    let config = SolverConfig { horizon_cap: horizon, tolerance: 1e-12, ..SolverConfig::default() };
    let solution = solve(system, params, grid, &config, false).unwrap();
    let path = dir.join(name);
    save(&solution, &path).unwrap();
    (path, solution)
}

/// A 7x7 double-integrator grid over `x_r` in `x` and the whole velocity domain.
fn di_grid(x: (f64, f64)) -> Grid {
    Grid::new(vec![
        Axis { name: "x_r".into(), min: x.0, max: x.1, n: 7, periodic: false },
        Axis { name: "v".into(), min: -1.5, max: 1.5, n: 7, periodic: false },
    ])
    .unwrap()
}

/// A batch tensor's entries, row-major.
fn rows(t: burn::tensor::Tensor<2>) -> Vec<f32> {
    t.into_data().try_to_vec::<f32>().unwrap()
}

/// Supervision by files: the config's own solution specs are not read.
fn config() -> SupervisionConfig {
    SupervisionConfig {
        solutions: SolveSeries {
            system: "double_integrator".into(),
            resolution: vec![7],
            bounds: vec![],
            solver: SolverConfig::default(),
            solves: vec![],
        },
        store: PathBuf::from(DEFAULT_STORE),
        weight: 1.0,
        gradient_weight: 0.0,
        points: 500,
        focus_share: 0.5,
        focus_factor: 2.0,
        own_grid_share: 0.0,
        slice_share: 0.0,
        under_weight: 1.0,
        gradient_metric: GradientMetric::Euclidean,
    }
}

fn refusal(paths: &[PathBuf], system: &AffineSystem, tau_max: f64) -> String {
    match GridSupervision::from_files(&config(), paths, system, tau_max, 1) {
        Ok(_) => panic!("accepted {paths:?}"),
        Err(e) => e.to_string(),
    }
}

#[test]
fn solutions_that_do_not_fit_the_run_are_refused_with_the_reason() {
    let dir = tempfile::tempdir().unwrap();
    let di = double_integrator::system();
    let car = dubins4d::system();
    let shared = car.with_shared_parameter();
    let (di_path, _) = solved(dir.path(), "di.ftgrid", &di, &[0.75], 0.2);
    let (unequal, _) = solved(dir.path(), "unequal.ftgrid", &car, &[0.6, 0.9], 0.05);

    let message = refusal(std::slice::from_ref(&di_path), &car, 1.0);
    assert!(message.contains("system `double_integrator`, training `dubins4d`"), "{message}");

    let message = refusal(std::slice::from_ref(&di_path), &di, 0.1);
    assert!(message.contains("lies past sampling.tau_max = 0.1 s"), "{message}");

    let message = refusal(std::slice::from_ref(&unequal), &shared, 1.0);
    assert!(message.contains("do not map onto the network's 1 parameter(s)"), "{message}");
    assert!(message.contains("unequal.ftgrid"), "the message names the file: {message}");

    // The same unequal solution fits a run with one input per planner bound.
    assert!(GridSupervision::from_files(&config(), &[unequal], &car, 1.0, 1).is_ok());

    let mut narrow = di.clone();
    narrow.params[0].min = 0.8;
    let message = refusal(std::slice::from_ref(&di_path), &narrow, 1.0);
    assert!(message.contains("beta = 0.75 outside the trained range [0.8, 1]"), "{message}");

    // Blending in beta needs one horizon, overlapping grids, and distinct beta.
    let (later, _) = solved(dir.path(), "later.ftgrid", &di, &[1.0], 0.3);
    let message = refusal(&[di_path.clone(), later], &di, 1.0);
    assert!(message.contains("needs one horizon for every solution"), "{message}");
    let (left, _) = solved_on(dir.path(), "left.ftgrid", &di, &[0.75], 0.2, &di_grid((-2.0, -0.5)));
    let (right, _) = solved_on(dir.path(), "right.ftgrid", &di, &[1.0], 0.2, &di_grid((0.5, 2.0)));
    let message = refusal(&[left.clone(), right], &di, 1.0);
    assert!(message.contains("axis `x_r` [0.5, 2] does not overlap `x_r` [-2, -0.5]"), "{message}");
    let (wide, _) = solved_on(dir.path(), "wide.ftgrid", &di, &[1.0], 0.2, &di_grid((-1.0, 2.0)));
    assert!(GridSupervision::from_files(&config(), &[left, wide], &di, 1.0, 1).is_ok(), "overlapping grids blend");
    let message = refusal(&[di_path.clone(), di_path.clone()], &di, 1.0);
    assert!(message.contains("a second solution at beta = 0.75"), "{message}");

    let missing = dir.path().join("missing.ftgrid");
    let message = refusal(&[missing], &di, 1.0);
    assert!(message.contains("missing.ftgrid"), "{message}");
    std::fs::write(dir.path().join("junk.ftgrid"), b"not a solution").unwrap();
    let message = refusal(&[dir.path().join("junk.ftgrid")], &di, 1.0);
    assert!(message.contains("magic FTGRID01 missing"), "{message}");
}

#[test]
fn solutions_named_by_spec_are_read_from_the_store_and_a_missing_one_is_named() {
    let dir = tempfile::tempdir().unwrap();
    let di = double_integrator::system();
    let mut config = config();
    config.store = dir.path().join("store");
    config.solutions.solver = SolverConfig { horizon_cap: 0.2, tolerance: 1e-12, ..SolverConfig::default() };
    config.solutions.solves = [0.5, 1.0].map(|beta| SeriesSolve { beta, bounds: vec![] }).to_vec();

    let message = match GridSupervision::load(&config, &di, 1.0, 1) {
        Ok(_) => panic!("supervised by solutions that were never made"),
        Err(e) => e.to_string(),
    };
    assert!(message.contains("no solution for double_integrator at beta 0.5"), "{message}");
    assert!(message.contains("fastrack-grid solve --config"), "the message says how to make them: {message}");

    // Made by the solver's store, they supervise; the batch is the one the same files give.
    let store = SolutionStore::new(&config.store);
    for spec in config.solutions.specs() {
        solve_or_load(&store, &spec, false).unwrap();
    }
    let by_spec = GridSupervision::load(&config, &di, 1.0, 7).unwrap().batch(2, &Device::flex());
    let paths: Vec<PathBuf> = config.solutions.specs().iter().map(|spec| store.path(spec)).collect();
    let by_file = GridSupervision::from_files(&config, &paths, &di, 1.0, 7).unwrap().batch(2, &Device::flex());
    assert_eq!(rows(by_spec.target), rows(by_file.target));

    // A file under a spec's name that holds another solve is refused, naming the difference.
    solved_on(dir.path(), "longer.ftgrid", &di, &[0.5], 0.3, &Grid::for_system(&di, &[7, 7]).unwrap());
    std::fs::copy(dir.path().join("longer.ftgrid"), &paths[0]).unwrap();
    let message = match GridSupervision::load(&config, &di, 1.0, 1) {
        Ok(_) => panic!("supervised by a file of another solve"),
        Err(e) => e.to_string(),
    };
    assert!(message.contains("is not the solve of its spec: solver settings"), "{message}");
}

#[test]
fn drawn_targets_blend_the_grid_values_in_beta_at_the_drawn_points() {
    let dir = tempfile::tempdir().unwrap();
    let di = double_integrator::system();
    let (low, low_solution) = solved(dir.path(), "low.ftgrid", &di, &[0.5], 0.3);
    let (high, high_solution) = solved(dir.path(), "high.ftgrid", &di, &[1.0], 0.3);
    // Given out of order: sorted by beta.
    let supervision = GridSupervision::from_files(&config(), &[high, low], &di, 1.0, 7).unwrap();
    let batch = supervision.batch(3, &Device::flex());
    let (tau, state, params, target) = (rows(batch.tau), rows(batch.state), rows(batch.params), rows(batch.target));
    assert_eq!((tau.len(), state.len(), params.len(), target.len()), (500, 1000, 500, 500));
    let (mut below, mut above) = (0, 0);
    for i in 0..500 {
        let beta = f64::from(params[i]);
        assert!((0.5..=1.0).contains(&beta) && tau[i] == 0.3, "row {i}: beta {beta}, tau {}", tau[i]);
        let x = [f64::from(state[2 * i]), f64::from(state[2 * i + 1])];
        assert!(di.state_space().in_domain(&x), "row {i}: {x:?} outside the domain");
        let w = (beta - 0.5) / 0.5;
        let value = |s: &Solution| s.grid.interpolate(&s.values, &x);
        let expected = (1.0 - w) * value(&low_solution) + w * value(&high_solution);
        assert!((f64::from(target[i]) - expected).abs() < 1e-4, "row {i}: target {} vs blend {expected}", target[i]);
        below += usize::from(beta < 0.75);
        above += usize::from(beta > 0.75);
    }
    assert!(below > 200 && above > 200, "beta drawn across the range: {below} below 0.75, {above} above");
    // Reproducible per iteration, different across iterations.
    let again = rows(supervision.batch(3, &Device::flex()).state);
    let next = rows(supervision.batch(4, &Device::flex()).state);
    assert_eq!(again, state);
    assert_ne!(next, state);
}

#[test]
fn blended_solutions_on_different_grids_give_targets_only_where_both_are_defined() {
    let dir = tempfile::tempdir().unwrap();
    let di = double_integrator::system();
    // The lower beta on a box cut to x_r <= 0.5 (as a domain scaled to a smaller error set is).
    let (low, low_solution) = solved_on(dir.path(), "low.ftgrid", &di, &[0.5], 0.3, &di_grid((-2.0, 0.5)));
    let (high, high_solution) = solved(dir.path(), "high.ftgrid", &di, &[1.0], 0.3);
    let supervision = GridSupervision::from_files(&config(), &[low, high], &di, 1.0, 7).unwrap();
    let batch = supervision.batch(5, &Device::flex());
    let (state, params, target) = (rows(batch.state), rows(batch.params), rows(batch.target));
    let mut near_the_cut = 0;
    for i in 0..500 {
        let x = [f64::from(state[2 * i]), f64::from(state[2 * i + 1])];
        // f32 storage: within rounding of the cut.
        assert!(x[0] <= 0.5 + 1e-6, "row {i}: {x:?} lies outside the lower beta's grid");
        let w = (f64::from(params[i]) - 0.5) / 0.5;
        let value = |s: &Solution| s.grid.interpolate(&s.values, &x);
        let expected = (1.0 - w) * value(&low_solution) + w * value(&high_solution);
        assert!((f64::from(target[i]) - expected).abs() < 1e-4, "row {i}: target {} vs blend {expected}", target[i]);
        near_the_cut += usize::from(w > 0.5 && x[0] > 0.0);
    }
    assert!(near_the_cut > 20, "rows drawn from the wider grid up to the cut: {near_the_cut}");
}

#[test]
fn own_grid_rows_supervise_each_solution_at_its_own_beta_past_the_lower_grid() {
    // The same cut grids: the first 60% of the rows are blended and stop at the cut, the last 40% lie at a
    // solution's own beta and reach its whole grid.
    let dir = tempfile::tempdir().unwrap();
    let di = double_integrator::system();
    let (low, low_solution) = solved_on(dir.path(), "low.ftgrid", &di, &[0.5], 0.3, &di_grid((-2.0, 0.5)));
    let (high, high_solution) = solved(dir.path(), "high.ftgrid", &di, &[1.0], 0.3);
    let mut own = config();
    own.own_grid_share = 0.4;
    let batch = GridSupervision::from_files(&own, &[low, high], &di, 1.0, 7).unwrap().batch(5, &Device::flex());
    let (state, params, target) = (rows(batch.state), rows(batch.params), rows(batch.target));
    let mut past_the_cut = 0;
    for i in 0..500 {
        let x = [f64::from(state[2 * i]), f64::from(state[2 * i + 1])];
        let beta = f64::from(params[i]);
        let value = |s: &Solution| s.grid.interpolate(&s.values, &x);
        if i < 300 {
            assert!(x[0] <= 0.5 + 1e-6, "blended row {i}: {x:?} lies outside the lower beta's grid");
            continue;
        }
        let expected = match beta {
            0.5 => value(&low_solution),
            1.0 => value(&high_solution),
            _ => panic!("own-grid row {i} at beta {beta}, not a solution's"),
        };
        assert!((f64::from(target[i]) - expected).abs() < 1e-4, "row {i}: target {} vs {expected}", target[i]);
        past_the_cut += usize::from(beta == 1.0 && x[0] > 0.5 + 1e-6);
    }
    assert!(past_the_cut > 10, "rows of the wider grid past the cut: {past_the_cut}");
}

#[test]
fn slice_rows_lie_at_zero_error_with_the_grids_value_there() {
    // The 20% of rows before the 30% own-grid rows have the error coordinate at 0 and the speed anywhere;
    // their targets are the blend of the two grids' values at that point, as every other row's.
    let dir = tempfile::tempdir().unwrap();
    let di = double_integrator::system();
    let (low, low_solution) = solved(dir.path(), "low.ftgrid", &di, &[0.5], 0.3);
    let (high, high_solution) = solved(dir.path(), "high.ftgrid", &di, &[1.0], 0.3);
    let mut sliced = config();
    (sliced.slice_share, sliced.own_grid_share) = (0.2, 0.3);
    let batch = GridSupervision::from_files(&sliced, &[low, high], &di, 1.0, 3).unwrap().batch(2, &Device::flex());
    let (state, params, target) = (rows(batch.state), rows(batch.params), rows(batch.target));
    let (mut speeds, mut off_slice) = (Vec::new(), 0);
    for i in 0..500 {
        let x = [f64::from(state[2 * i]), f64::from(state[2 * i + 1])];
        if !(250..350).contains(&i) {
            off_slice += usize::from(x[0] != 0.0);
            continue;
        }
        assert_eq!(x[0], 0.0, "slice row {i}: {x:?}");
        speeds.push(x[1]);
        let w = (f64::from(params[i]) - 0.5) / 0.5;
        let value = |s: &Solution| s.grid.interpolate(&s.values, &x);
        let expected = (1.0 - w) * value(&low_solution) + w * value(&high_solution);
        assert!((f64::from(target[i]) - expected).abs() < 1e-4, "row {i}: target {} vs {expected}", target[i]);
    }
    assert_eq!(off_slice, 400, "every other row is drawn off the slice");
    let spread =
        speeds.iter().copied().fold(f64::NEG_INFINITY, f64::max) - speeds.iter().copied().fold(f64::INFINITY, f64::min);
    assert!(spread > 1.0, "slice rows cover the speeds: spread {spread}");
}

#[test]
fn targets_of_a_linear_field_are_its_values_and_its_slope_up_to_the_edges() {
    // Multilinear interpolation and differences over a cell are exact on a linear field, edges included.
    let dir = tempfile::tempdir().unwrap();
    let di = double_integrator::system();
    let slope = [0.7, -1.3];
    let (_, mut solution) = solved(dir.path(), "field.ftgrid", &di, &[0.8], 0.2);
    let mut r = [0.0; 2];
    for flat in 0..solution.values.len() {
        solution.grid.point(flat, &mut r);
        solution.values[flat] = 2.0 + slope[0] * r[0] + slope[1] * r[1];
    }
    let path = dir.path().join("linear.ftgrid");
    save(&solution, &path).unwrap();
    let supervision = GridSupervision::from_files(&config(), &[path], &di, 1.0, 5).unwrap();
    let batch = supervision.batch(0, &Device::flex());
    let (state, target, gradient) = (rows(batch.state), rows(batch.target), rows(batch.target_gradient));
    let mut at_edge = 0;
    for i in 0..500 {
        let x = [f64::from(state[2 * i]), f64::from(state[2 * i + 1])];
        let expected = 2.0 + slope[0] * x[0] + slope[1] * x[1];
        assert!((f64::from(target[i]) - expected).abs() < 1e-4, "row {i}: value {} vs {expected}", target[i]);
        for k in 0..2 {
            let g = f64::from(gradient[2 * i + k]);
            assert!((g - slope[k]).abs() < 1e-4, "row {i}, axis {k}: slope {g} vs {}", slope[k]);
        }
        at_edge +=
            usize::from(x.iter().zip(&di.state).any(|(x, d)| (x - d.min).abs() < 0.33 || (d.max - x).abs() < 0.33));
    }
    assert!(at_edge > 50, "only {at_edge} rows within half a cell of an edge");
}

#[test]
fn the_hamiltonian_metric_weighs_each_axis_by_its_squared_dissipation_bound() {
    // dubins4d: alpha = (|v sin theta| + beta, |v cos theta| + beta, 5, 1) at beta (the shared parameter);
    // the weights are 4 alpha_j^2 / sum alpha_k^2, so the heading, which the 5 rad/s turn rate drives,
    // weighs most; the Euclidean metric weighs every axis 1.
    let dir = tempfile::tempdir().unwrap();
    let car = dubins4d::system().with_shared_parameter();
    let (low, _) = solved(dir.path(), "low.ftgrid", &dubins4d::system(), &[0.5, 0.5], 0.05);
    let (high, _) = solved(dir.path(), "high.ftgrid", &dubins4d::system(), &[1.25, 1.25], 0.05);
    let mut hamiltonian = config();
    hamiltonian.gradient_metric = GradientMetric::Hamiltonian;
    let batch = GridSupervision::from_files(&hamiltonian, &[low.clone(), high.clone()], &car, 1.0, 3)
        .unwrap()
        .batch(0, &Device::flex());
    let (state, params, weights) = (rows(batch.state), rows(batch.params), rows(batch.gradient_weights));
    for i in 0..500 {
        let (theta, v, beta) = (f64::from(state[4 * i + 2]), f64::from(state[4 * i + 3]), f64::from(params[i]));
        let alpha = [(v * theta.sin()).abs() + beta, (v * theta.cos()).abs() + beta, 5.0, 1.0];
        let total: f64 = alpha.iter().map(|a| a * a).sum();
        for k in 0..4 {
            let expected = 4.0 * alpha[k] * alpha[k] / total;
            let w = f64::from(weights[4 * i + k]);
            assert!((w - expected).abs() < 1e-5, "row {i}, axis {k}: weight {w} vs {expected}");
        }
        assert!(weights[4 * i + 2] > 2.0, "row {i}: the heading weighs {}", weights[4 * i + 2]);
    }
    let euclidean =
        GridSupervision::from_files(&config(), &[low, high], &car, 1.0, 3).unwrap().batch(0, &Device::flex());
    assert!(rows(euclidean.gradient_weights).iter().all(|&w| w == 1.0));
}
