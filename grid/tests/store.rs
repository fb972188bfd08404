//! Solutions by spec: the file a spec names, the store's check that a file is its spec's solve, solving
//! what is missing, and the specs of the training configs.

use fastrack_grid::grid::Grid;
use fastrack_grid::solver::{solve, SolverConfig};
use fastrack_grid::spec::{AxisBounds, SeriesSolve, SolutionStore, SolveSeries, SolveSpec, StoreError};
use fastrack_grid::store::{solve_or_load, SolutionSource};
use std::path::Path;

fn quick_spec(beta: f64) -> SolveSpec {
    SolveSpec {
        system: "double_integrator".into(),
        beta,
        resolution: vec![9],
        bounds: vec![],
        solver: SolverConfig { horizon_cap: 0.2, tolerance: 1e-12, ..SolverConfig::default() },
    }
}

/// The `[supervision.solutions]` of a training config.
fn config_series(name: &str) -> SolveSeries {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../trainer/configs").join(name);
    let config: toml::Table = std::fs::read_to_string(&path).unwrap().parse().unwrap();
    config["supervision"]["solutions"].clone().try_into().unwrap()
}

#[test]
fn a_store_solves_a_missing_spec_once_and_replaces_a_file_of_another_solve() {
    let dir = tempfile::tempdir().unwrap();
    let store = SolutionStore::new(dir.path().join("store"));
    let spec = quick_spec(0.75);
    assert!(matches!(store.load(&spec), Err(StoreError::Missing { .. })));

    let (solved, source) = solve_or_load(&store, &spec, false).unwrap();
    assert_eq!(source, SolutionSource::Solver);
    let (system, grid) = (spec.system().unwrap(), spec.grid().unwrap());
    let direct = solve(&system, &[0.75], &grid, &spec.solver, false).unwrap();
    assert_eq!(
        (&solved.grid, &solved.values, &solved.info.config),
        (&direct.grid, &direct.values, &direct.info.config)
    );
    let (kept, source) = solve_or_load(&store, &spec, false).unwrap();
    assert_eq!((source, &kept), (SolutionSource::Store, &solved));

    // Another horizon is another solve: the file under this spec's name is refused, then replaced.
    let longer = SolveSpec { solver: SolverConfig { horizon_cap: 0.3, ..spec.solver.clone() }, ..spec.clone() };
    let (other, _) = solve_or_load(&SolutionStore::new(dir.path().join("other")), &longer, false).unwrap();
    fastrack_grid::format::save(&other, &store.path(&spec)).unwrap();
    match store.load(&spec) {
        Err(StoreError::Mismatch { problem, .. }) => assert!(problem.starts_with("solver settings"), "{problem}"),
        other => panic!("a file of another solve was handed out: {other:?}"),
    }
    let (again, source) = solve_or_load(&store, &spec, false).unwrap();
    assert_eq!(source, SolutionSource::Solver);
    assert_eq!(again.info.config, spec.solver);
    assert_eq!(store.load(&spec).unwrap().values, again.values);
}

#[test]
fn specs_that_name_no_grid_are_refused_naming_what_is_allowed() {
    let refusal = |spec: SolveSpec| spec.grid().unwrap_err().to_string();
    let message = refusal(SolveSpec { system: "boat".into(), ..quick_spec(1.0) });
    assert!(message.contains("unknown system `boat`; known: dubins4d"), "{message}");
    let message = refusal(SolveSpec { resolution: vec![9, 9, 9], ..quick_spec(1.0) });
    assert!(message.contains("resolution has 3 entries; give 1 or 2"), "{message}");
    let bounds = vec![AxisBounds { axis: "theta".into(), min: -1.0, max: 1.0 }];
    let message = refusal(SolveSpec { bounds, ..quick_spec(1.0) });
    assert!(message.contains("bounds of `theta`: no such axis; axes: x_r, v"), "{message}");
    let bounds = vec![AxisBounds { axis: "v".into(), min: 1.0, max: -1.0 }];
    assert!(refusal(SolveSpec { bounds, ..quick_spec(1.0) }).contains("axis 1"));
    let message = quick_spec(f64::NAN).params().unwrap_err().to_string();
    assert!(message.contains("beta = NaN must be a positive number"), "{message}");
}

#[test]
fn a_series_solve_s_own_bounds_replace_the_shared_ones_of_the_same_axis() {
    let series = SolveSeries {
        system: "double_integrator".into(),
        resolution: vec![9],
        bounds: vec![AxisBounds { axis: "x_r".into(), min: -1.0, max: 1.0 }],
        solver: SolverConfig::default(),
        solves: vec![
            SeriesSolve { beta: 0.5, bounds: vec![] },
            SeriesSolve { beta: 1.0, bounds: vec![AxisBounds { axis: "x_r".into(), min: -2.0, max: 2.0 }] },
        ],
    };
    let grids: Vec<Grid> = series.specs().iter().map(|s| s.grid().unwrap()).collect();
    assert_eq!((grids[0].axes()[0].min, grids[1].axes()[0].min), (-1.0, -2.0));
    assert_eq!(grids[0].axes()[1], grids[1].axes()[1], "the axis no solve names keeps the domain's bounds");
}

#[test]
fn the_training_configs_name_the_files_their_solutions_were_always_kept_in() {
    let names =
        |config: &str| -> Vec<String> { config_series(config).specs().iter().map(SolveSpec::file_name).collect() };
    assert_eq!(
        names("dubins4d.toml"),
        ["0.5", "0.6875", "0.875", "1.0625", "1.25"]
            .map(|b| format!("dubins4d-beta{b}-n31x31x31x31-weno5-rk3-tol0.000001-cap30-set0.5e3.ftgrid"))
    );
    assert_eq!(
        names("quad10d_x.toml"),
        [("0.5", "-2.02.0", "-2.52.5"), ("1", "-3.253.25", "-3.03.0"), ("1.5", "-5.05.0", "-4.04.0")].map(
            |(b, x, v)| format!(
                "quad10d_x-beta{b}-n21x21x15x15-weno5-rk3-tol0.000000001-cap120-set0.5e3-win2-godunov-theta_x-0.50.5_x_r{x}_v_x{v}.ftgrid"
            )
        )
    );
    assert_eq!(
        names("quad10d_z.toml"),
        ["0.5", "1", "1.5"]
            .map(|b| format!("quad10d_z-beta{b}-n301x301-weno5-rk3-tol0.000000001-cap10-set0.5e3-win2-godunov.ftgrid"))
    );
    for spec in config_series("experiments/double_integrator_supervised.toml").specs() {
        spec.grid().unwrap();
    }
}
