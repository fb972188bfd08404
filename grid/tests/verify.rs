//! Scenario verification on double-integrator bundles whose value function is known: a network fitted to
//! the grid solution (random sine features, least-squares output layer), written as an ONNX bundle and run
//! through ONNX Runtime like any served model.
//!
//! The first round samples under the row's level (margin 0). At the settings the shipped tables are verified
//! with (`eps` 1e-3, `delta` 1e-6: 13,809 samples per round), against the model's and the grid's worst-case
//! planners, random bang-bang planners and the search:
//!
//! - A correct table (the fitted value, level above its minimum) is verified in one round, within the slack
//!   left for the fit and for the control held over each step.
//! - A shrunk table (the same network and levels scaled down by 0.6, i.e. a model that underestimates the
//!   value) is flagged: most samples of its first round break it, and no raised level holds.
//!
//! With the `bound` correction the shrunk table is not flagged but bounded: one round rolls out every sample of
//! its set, and the bound is the largest error, close to the grid's value on that set; split into pieces (and
//! the pieces into shards) the round combines into the same counts and a bound within the sampling's spread.
//!
//! And on a model whose control is known to be weak (fitted to a value function whose gradient makes the
//! control `u = -a sign(x)`, an undamped oscillator a planner can pump), the search forces larger errors than
//! random bang-bang planners from the same samples, and the grid solution's policy as the tracker (the
//! reference run) holds the same samples within the grid's own values there.

use fastrack_grid::grid::Grid;
use fastrack_grid::solver::{solve, Solution, SolverConfig};
use fastrack_grid::verify::{
    apply_reports, combine_pieces, required_samples, verify_rows, verify_table, ControlLaw, Correction, ErrorScale,
    FalsificationOptions, Outcome, RecordedStates, RowReport, SearchOptions, Selection, VerifyError, VerifyOptions,
    FALSIFICATION, OPERATIONAL, UNIFORM, ZERO_ERROR_SLICE,
};
use fastrack_lab::shard::Shard;
use fastrack_valuefn::bundle::Bundle;
use fastrack_valuefn::manifest::{Manifest, NetworkInfo, Provenance, SystemInfo, TebRow, MIN_TEB_ROWS, SCHEMA_VERSION};
use fastrack_valuefn::network::{Dense, PeriodicEncoding, ValueNetwork};
use fastrack_valuefn::onnx_writer::write_value_graph;
use fastrack_valuefn::runtime::{runtime, Evaluator, GraphDims};
use fastrack_valuefn::system::double_integrator::system;
use fastrack_valuefn::system::AffineSystem;
use indicatif::ProgressBar;
use nalgebra::{DMatrix, DVector};
use rand::{Rng, SeedableRng};
use std::sync::OnceLock;

/// Random sine features of the fitted network.
const FEATURES: usize = 256;
/// Horizon written into the graph (the network does not depend on it).
const HORIZON: f64 = 10.0;

/// The grid solution at `beta_u` (solved once for every test).
fn ground_truth() -> &'static (AffineSystem, Solution) {
    static TRUTH: OnceLock<(AffineSystem, Solution)> = OnceLock::new();
    TRUTH.get_or_init(|| {
        let system = system();
        let beta = system.params[0].max;
        let grid = Grid::for_system(&system, &[161, 121]).unwrap();
        let config = SolverConfig { tolerance: 0.02 * beta, ..SolverConfig::default() };
        let solution = solve(&system, &[beta], &grid, &config, false).unwrap();
        (system, solution)
    })
}

/// A one-hidden-layer SIREN fitted to the grid solution: `V(r) = scale * (w . sin(W r_n + b) + c)`,
/// independent of `tau` and `beta`.
fn fitted_network(system: &AffineSystem, solution: &Solution, scale: f64) -> ValueNetwork {
    fit(system, &solution.grid, &solution.values, scale)
}

/// A one-hidden-layer SIREN fitted to `values` on the nodes of `grid`, scaled by `scale`.
fn fit(system: &AffineSystem, grid: &Grid, values: &[f64], scale: f64) -> ValueNetwork {
    let mut rng = rand::rngs::StdRng::seed_from_u64(5);
    let n_in = 1 + system.n_state() + system.n_params();
    let input = ValueNetwork::normalization_for(system, HORIZON);
    // Features over the normalised state only (inputs 1..=n_state).
    let mut weight = vec![0.0; FEATURES * n_in];
    for k in 0..FEATURES {
        for i in 1..=system.n_state() {
            weight[k * n_in + i] = rng.random_range(-6.0..6.0);
        }
    }
    let bias: Vec<f64> = (0..FEATURES).map(|_| rng.random_range(-std::f64::consts::PI..std::f64::consts::PI)).collect();
    let hidden = Dense { n_in, n_out: FEATURES, weight, bias };
    let v_min = values.iter().copied().fold(f64::INFINITY, f64::min);
    let mut r = vec![0.0; grid.ndim()];
    let (mut rows, mut targets, mut weights) = (Vec::new(), Vec::new(), Vec::new());
    for (flat, &v) in values.iter().enumerate() {
        grid.point(flat, &mut r);
        let mut x = vec![0.0; n_in];
        for i in 0..system.n_state() {
            x[1 + i] = (r[i] - input.center[1 + i]) / input.half_range[1 + i];
        }
        let mut features: Vec<f64> = hidden.apply(&x).iter().map(|z| z.sin()).collect();
        features.push(1.0);
        rows.push(features);
        targets.push(v);
        // The sublevel sets that matter weigh most.
        weights.push(if v < 3.0 * v_min.max(0.1) { 1.0 } else { 0.05 });
    }
    let m = FEATURES + 1;
    let a = DMatrix::from_fn(rows.len(), m, |i, j| rows[i][j] * weights[i]);
    let y = DVector::from_iterator(targets.len(), targets.iter().zip(&weights).map(|(t, w)| t * w));
    let normal = a.transpose() * &a + DMatrix::identity(m, m) * 1e-8;
    let coefficients = normal.cholesky().expect("normal equations are positive definite").solve(&(a.transpose() * y));
    let out = Dense {
        n_in: FEATURES,
        n_out: 1,
        weight: coefficients.iter().take(FEATURES).copied().collect(),
        bias: vec![coefficients[FEATURES]],
    };
    ValueNetwork {
        omega_0: 1.0,
        layers: vec![hidden, out],
        input,
        output_scale: scale,
        output_offset: 0.0,
        exact_boundary: false,
        periodic: vec![None; system.n_state()],
        error_coords: system.error_coords.clone(),
        periodic_encoding: PeriodicEncoding::Wrap,
    }
}

/// A bundle of `network` whose table has `level_at_beta_u` at `beta_u` (rows below scaled by `beta^2`).
fn write_bundle(
    root: &std::path::Path,
    system: &AffineSystem,
    network: &ValueNetwork,
    level_at_beta_u: f64,
) -> std::path::PathBuf {
    let onnx = write_value_graph(network, system, HORIZON);
    let (state, planner_to_state, params, controls) = Manifest::describe_system(system);
    let (beta_l, beta_u) = (system.params[0].min, system.params[0].max);
    let teb_table = (0..MIN_TEB_ROWS)
        .map(|i| {
            let beta = beta_l + (beta_u - beta_l) * i as f64 / (MIN_TEB_ROWS - 1) as f64;
            let level = level_at_beta_u * (beta / beta_u).powi(2);
            TebRow {
                beta,
                level,
                measured_min: level,
                extent: vec![level],
                boundary_radii: vec![],
                verification: None,
                nested_share: None,
                reference: None,
            }
        })
        .collect();
    let manifest = Manifest {
        schema_version: SCHEMA_VERSION,
        name: "di-test".into(),
        version: 1,
        system: SystemInfo { id: system.id.into(), description: system.description.into() },
        state,
        planner_to_state,
        params,
        controls,
        horizon: HORIZON,
        network: NetworkInfo {
            kind: "siren".into(),
            hidden: vec![FEATURES],
            omega_0: 1.0,
            exact_boundary: false,
            periodic_encoding: PeriodicEncoding::Wrap,
            axes: Vec::new(),
        },
        teb_table,
        untrained: false,
        provenance: Provenance::untrained("least-squares fit to the grid solution (test)", serde_json::json!({})),
        onnx_sha256: String::new(),
    };
    Bundle::write(root, manifest, &onnx).unwrap()
}

/// The settings the shipped tables are verified with, on the double integrator's time scale.
fn shipped_settings() -> VerifyOptions {
    VerifyOptions {
        eps: 1e-3,
        delta: 1e-6,
        level_margin: 0.0,
        horizon: 6.0,
        // Twice the shipped step, so twice its slack for the control held over a step.
        step: 0.02,
        slack: 0.04,
        random_planners: 1,
        search: SearchOptions::default(),
        batch: 8192,
        ..VerifyOptions::default()
    }
}

/// Verifies the `beta_u` row of a bundle of the fitted network scaled by `scale`, level `level`, with the grid
/// solution's worst-case planner playing.
fn verify(scale: f64, level: f64) -> RowReport {
    verify_and_check_shapes(scale, level, ground_truth().0.params[0].max, false, None)
}

/// The evaluator and manifest of a bundle of `network` written with `level` at `beta_u`.
fn load(system: &AffineSystem, network: &ValueNetwork, level: f64) -> (Evaluator, Bundle) {
    let root = tempfile::tempdir().unwrap();
    let dir = write_bundle(root.path(), system, network, level);
    let bundle = Bundle::load(&dir).unwrap();
    let dims = GraphDims { n_state: 2, n_params: 1, n_control: 1 };
    let evaluator = Evaluator::new(runtime(None).unwrap(), &bundle.onnx, dims, rayon_threads()).unwrap();
    (evaluator, bundle)
}

/// The row at `beta` alone, with no grid adversary and no operational check.
fn bare_selection(beta: &f64) -> Selection<'_> {
    Selection { betas: Some(std::slice::from_ref(beta)), ..Selection::default() }
}

/// The row at `beta` of a double-integrator bundle verified alone, whole, with `options`.
fn verify_alone(
    evaluator: &Evaluator,
    manifest: &Manifest,
    beta: f64,
    options: &VerifyOptions,
) -> Result<Vec<RowReport>, VerifyError> {
    let system = &ground_truth().0;
    verify_rows(evaluator, manifest, system, &bare_selection(&beta), Shard::WHOLE, options, &ProgressBar::hidden())
}

fn rayon_threads() -> usize {
    std::thread::available_parallelism().map_or(1, |n| n.get())
}

/// [`verify`] of the row at `row_beta` (the grid solution nearest it plays it, its inputs scaled to the row's
/// bound), with the operational check of `operational` if given, optionally checking every row's extent
/// against a dense scan (meaningful for a network that keeps `V >= |x|`, which the error-set measurement
/// relies on; a shrunk one does not).
fn verify_and_check_shapes(
    scale: f64,
    level: f64,
    row_beta: f64,
    check_shapes: bool,
    operational: Option<&RecordedStates>,
) -> RowReport {
    let (system, solution) = ground_truth();
    let network = fitted_network(system, solution, scale);
    let (evaluator, bundle) = load(system, &network, level);
    let mut manifest = bundle.manifest.clone();
    let options = shipped_settings();
    let adversaries = std::slice::from_ref(solution);
    let selection = Selection { betas: Some(&[row_beta]), adversaries, grid_tolerance: 0.1, operational };
    let reports =
        verify_table(&evaluator, &mut manifest, system, &selection, &options, &ProgressBar::hidden()).unwrap();
    // The verification lands in the manifest and survives a rewrite of the bundle.
    let out = tempfile::tempdir().unwrap();
    let written = Bundle::load(&Bundle::write(out.path(), manifest, &bundle.onnx).unwrap()).unwrap();
    let row = written.manifest.teb_table.iter().find(|row| (row.beta - row_beta).abs() < 1e-9).unwrap();
    assert_eq!(row.verification.as_ref(), Some(&reports[0].verification));
    let families: Vec<&str> = reports[0].verification.planners.iter().map(|p| p.family.as_str()).collect();
    assert!(
        ["model-worst-case", "grid-worst-case", "random-bang-bang"].iter().all(|f| families.contains(f)),
        "planner families {families:?}"
    );
    if check_shapes {
        check_extents_at_set_levels(system, &evaluator, &written.manifest);
    }
    reports[0].clone()
}

/// Every row's extent is that of its certified set `{V <= set level}`: against a dense scan of the `(x, v)` plane.
fn check_extents_at_set_levels(system: &AffineSystem, evaluator: &Evaluator, manifest: &Manifest) {
    let (x_dim, v_dim) = (&system.state[0], &system.state[1]);
    let scan: Vec<(f64, f64)> = (0..=200)
        .flat_map(|i| (0..=200).map(move |j| (i as f64 / 200.0, j as f64 / 200.0)))
        .map(|(a, b)| (x_dim.min + a * (x_dim.max - x_dim.min), v_dim.min + b * (v_dim.max - v_dim.min)))
        .collect();
    let states: Vec<f32> = scan.iter().flat_map(|&(x, v)| [x as f32, v as f32]).collect();
    let mut inside_domain = 0;
    for row in &manifest.teb_table {
        let set_level = row.set_level();
        let values = evaluator.evaluate(&states, &vec![row.beta as f32; scan.len()]).unwrap().value;
        let dense = scan
            .iter()
            .zip(&values)
            .filter(|(_, &v)| f64::from(v) <= set_level)
            .map(|((x, _), _)| x.abs())
            .fold(0.0, f64::max);
        assert!(
            (row.extent[0] - dense).abs() <= 0.05 * set_level,
            "beta {}: extent {:?} vs {dense}",
            row.beta,
            row.extent
        );
        assert!(row.boundary_radii.iter().all(|&r| r <= set_level), "no boundary radius beyond the level (V >= |x|)");
        inside_domain += usize::from(dense < 0.9 * x_dim.max);
    }
    assert!(inside_domain >= 4, "only {inside_domain} rows' sets end inside the domain: the check needs some");
}

/// Level of the correct table, as a multiple of the grid's `V_min`.
const LEVEL_FACTOR: f64 = 1.5;
/// Scale of the shrunk model and table.
const SHRINK: f64 = 0.6;

fn grid_v_min() -> f64 {
    ground_truth().1.values.iter().copied().fold(f64::INFINITY, f64::min)
}

/// The sample count is the least `N` whose all-pass probability `(1 - eps)^N` under a violation share of
/// `eps` is at most `delta`, computed independently by counting up.
#[test]
fn the_sample_count_is_the_least_whose_all_pass_chance_is_at_most_delta() {
    for (eps, delta) in [(1e-3, 1e-6), (1e-2, 1e-6), (2e-2, 1e-3), (0.1, 0.05)] {
        let n = required_samples(eps, delta);
        let mut least = 0usize;
        let mut all_pass = 1.0f64;
        while all_pass > delta {
            all_pass *= 1.0 - eps;
            least += 1;
        }
        assert_eq!(n, least, "eps {eps}, delta {delta}");
    }
    assert_eq!(required_samples(1e-3, 1e-6), 13_809);
}

#[test]
fn a_correct_table_passes_at_the_shipped_settings() {
    let level = LEVEL_FACTOR * grid_v_min();
    // States a loop might have visited: a lattice over the domain, some of them in the set, most not.
    let system = &ground_truth().0;
    let lattice: Vec<String> = (0..=40)
        .flat_map(|i| (0..=40).map(move |j| (i as f64 / 40.0, j as f64 / 40.0)))
        .map(|(a, b)| {
            let (x, v) = (&system.state[0], &system.state[1]);
            format!("advance,1,{},{}", x.min + a * (x.max - x.min), v.min + b * (v.max - v.min))
        })
        .collect();
    let names: Vec<String> = system.state.iter().map(|d| d.name.to_string()).collect();
    let text = format!("branch,beta,{}\n{}\n", names.join(","), lattice.join("\n"));
    let recorded = RecordedStates::parse(&text, &names).unwrap();
    let report = verify_and_check_shapes(1.0, level, ground_truth().0.params[0].max, true, Some(&recorded));
    let v = &report.verification;
    eprintln!("correct table: level {level:.4}, {report:?}");
    assert_eq!(v.samples, required_samples(1e-3, 1e-6));
    assert_eq!(v.samples, 13_809);
    assert_eq!(report.outcome, Outcome::Verified);
    assert_eq!(v.violations, 0);
    assert_eq!(report.rounds.len(), 1, "a correct table needs no correction: {:?}", report.rounds);
    // Within the slack: the fit is not exact, and the control is held over each step.
    assert!(v.verified_level <= 1.04 * level, "verified level {} vs {level}", v.verified_level);
    // The rollouts did push the error out towards the level: the check has teeth.
    assert!(v.verified_level > 0.9 * level, "rollouts reached only {} of level {level}", v.verified_level);
    // Where robots are: the zero-error slice and the recorded states inside the set, each with its own N,
    // then the falsification over start states from the starts they pushed furthest, which climbs from their
    // errors and never reports less.
    let names: Vec<&str> = v.checks.iter().map(|c| c.distribution.as_str()).collect();
    assert_eq!(names, [UNIFORM, ZERO_ERROR_SLICE, OPERATIONAL, FALSIFICATION]);
    let [uniform, slice, operational, falsification] = [&v.checks[0], &v.checks[1], &v.checks[2], &v.checks[3]];
    assert_eq!((uniform.samples, slice.samples, operational.samples), (13_809, 13_809, 13_809));
    assert!(v.checks.iter().all(|c| c.violations == 0), "{:?}", v.checks);
    // The draws are lattice states inside the set: their errors start at their own |x| <= the level.
    assert!(operational.max_error > 0.0 && operational.max_error <= 1.04 * level, "{operational:?}");
    let sampled = [uniform, slice, operational].map(|c| c.max_error).into_iter().fold(0.0, f64::max);
    assert!(falsification.samples > 0 && falsification.max_error >= sampled);
    assert_eq!(v.verified_level, v.checks.iter().map(|c| c.max_error).fold(0.0, f64::max));
}

#[test]
fn a_shrunk_table_is_flagged_at_the_shipped_settings() {
    let correct_level = LEVEL_FACTOR * grid_v_min();
    let level = SHRINK * correct_level;
    let report = verify(SHRINK, level);
    let v = &report.verification;
    eprintln!("shrunk table: level {level:.4}, {:?}, {:?}", report.outcome, report.rounds);
    let first = &report.rounds[0];
    assert!(
        first.violations > first.samples / 2,
        "only {} of {} samples broke a table shrunk by {SHRINK}",
        first.violations,
        first.samples
    );
    // A check after a broken one does not run.
    assert_eq!(first.checks.len(), 1, "{:?}", first.checks);
    assert_eq!((first.checks[0].distribution.as_str(), first.checks[0].violations), (UNIFORM, first.violations));
    // A value scaled down everywhere has no self-consistent level: every round's set reaches errors 1 / SHRINK
    // times its level, until the set leaves the trained domain. The row is flagged, never verified.
    assert_ne!(report.outcome, Outcome::Verified, "{:?}", report.rounds);
    assert!(v.violations > 0, "the flag reaches the manifest");
    assert_eq!(v.rounds, report.rounds.len());
    assert!(
        v.verified_level > 1.3 * level,
        "verified level {} barely above the shrunk level {level}",
        v.verified_level
    );
}

/// `V(x, v) = sqrt(x^2 + 0.01) + 0.3 x v`: its gradient in `v` has the sign of `x`, so the served control is
/// `u = -a sign(x)`, a restoring force with no damping.
fn weak_value(x: f64, v: f64) -> f64 {
    (x * x + 0.01).sqrt() + 0.3 * x * v
}

/// The grid of the weak model's fit.
fn weak_grid(system: &AffineSystem) -> Grid {
    Grid::for_system(system, &[81, 61]).unwrap()
}

/// A bundle of a network fitted to [`weak_value`], its table at `WEAK_LEVEL`.
fn weak_model(system: &AffineSystem) -> (Evaluator, Bundle) {
    let grid = weak_grid(system);
    let mut r = [0.0; 2];
    let values: Vec<f64> = (0..grid.num_points())
        .map(|flat| {
            grid.point(flat, &mut r);
            weak_value(r[0], r[1])
        })
        .collect();
    let network = fit(system, &grid, &values, 1.0);
    let (evaluator, bundle) = load(system, &network, WEAK_LEVEL);
    // The served control is the weak one where it matters.
    let probe: Vec<f32> = [0.2f32, 0.0, -0.2, 0.0].to_vec();
    let control = evaluator.evaluate(&probe, &[1.0, 1.0]).unwrap().control;
    assert!(control[0] < -0.9 && control[1] > 0.9, "control {control:?} is not -sign(x)");
    (evaluator, bundle)
}

/// The weak model's level at `beta_u`.
const WEAK_LEVEL: f64 = 0.3;

#[test]
fn the_grid_policy_as_the_tracker_holds_the_weak_models_samples_within_the_grid_values() {
    let (system, solution) = ground_truth();
    let (evaluator, bundle) = weak_model(system);
    let beta_u = system.params[0].max;
    let options = |control_law| VerifyOptions {
        eps: 0.1,
        delta: 0.01,
        level_margin: 0.0,
        max_rounds: 1,
        horizon: 4.0,
        step: 0.02,
        random_planners: 2,
        control_law,
        ..VerifyOptions::default()
    };
    let selection =
        Selection { adversaries: std::slice::from_ref(solution), grid_tolerance: 0.1, ..bare_selection(&beta_u) };
    let run = |control_law| {
        verify_rows(
            &evaluator,
            &bundle.manifest,
            system,
            &selection,
            Shard::WHOLE,
            &options(control_law),
            &ProgressBar::hidden(),
        )
        .unwrap()
        .remove(0)
    };
    let (weak, reference) = (run(ControlLaw::Model), run(ControlLaw::Grid));
    // The independent reference: the largest grid value over the weak model's set {V <= level}, scanned on
    // its fit's nodes. From any state the grid's policy keeps the error within about the grid's value there.
    let grid = weak_grid(system);
    let mut r = [0.0; 2];
    let ceiling = (0..grid.num_points())
        .filter_map(|flat| {
            grid.point(flat, &mut r);
            (weak_value(r[0], r[1]) <= WEAK_LEVEL).then(|| solution.grid.interpolate(&solution.values, &r))
        })
        .fold(0.0, f64::max);
    let (weak_error, reference_error) = (weak.verification.verified_level, reference.verification.verified_level);
    eprintln!("weak control {weak_error:.4}, grid policy {reference_error:.4}, grid values up to {ceiling:.4}");
    assert!(reference_error <= 1.1 * ceiling, "the grid policy reached {reference_error}, its values {ceiling}");
    assert!(weak_error > 1.3 * reference_error, "weak control {weak_error} against the grid policy {reference_error}");
    // Without a grid solution near the row there is no policy to play.
    let bare = bare_selection(&beta_u);
    let refused = verify_rows(
        &evaluator,
        &bundle.manifest,
        system,
        &bare,
        Shard::WHOLE,
        &options(ControlLaw::Grid),
        &ProgressBar::hidden(),
    );
    assert!(
        matches!(&refused, Err(VerifyError::Setting(m)) if m.contains("grid control law")),
        "{:?}",
        refused.map(|r| r.len())
    );
}

#[test]
fn the_search_forces_larger_errors_than_random_planners_on_a_weak_control() {
    let system = system();
    let (evaluator, bundle) = weak_model(&system);
    let options = VerifyOptions {
        eps: 0.04,
        delta: 0.01,
        level_margin: 0.0,
        max_rounds: 1,
        horizon: 4.0,
        step: 0.02,
        random_planners: 4,
        search: SearchOptions { per_batch: 1000, ..SearchOptions::default() },
        ..VerifyOptions::default()
    };
    let mut manifest = bundle.manifest.clone();
    let beta_u = system.params[0].max;
    let selection = bare_selection(&beta_u);
    let report = verify_table(&evaluator, &mut manifest, &system, &selection, &options, &ProgressBar::hidden())
        .unwrap()
        .remove(0);
    let max =
        |family: &str| report.verification.planners.iter().find(|p| p.family == family).map(|p| p.max_error).unwrap();
    let (search, random) = (max("search"), max("random-bang-bang"));
    eprintln!("weak control: {:?}", report.verification.planners);
    assert_eq!(report.searched, report.verification.samples, "every sample was searched");
    assert!(search > 1.2 * random, "the search forced {search}, random planners {random}");
}

#[test]
fn a_set_that_reaches_the_domains_edge_is_not_verified() {
    // At a level past the position's half-width the set holds states at the edge of the trained domain, where
    // the model is extrapolated: flagged on the first round, whatever the rollouts find.
    let (system, solution) = ground_truth();
    let reach = system.state[0].max;
    let network = fitted_network(system, solution, 1.0);
    let (evaluator, bundle) = load(system, &network, 1.2 * reach);
    let mut manifest = bundle.manifest.clone();
    let beta = system.params[0].max;
    for correction in [Correction::Set, Correction::Bound] {
        let options = VerifyOptions { eps: 2e-2, delta: 1e-3, correction, ..shipped_settings() };
        let reports = verify_alone(&evaluator, &bundle.manifest, beta, &options).unwrap();
        assert_eq!(reports[0].outcome, Outcome::LeftDomain, "{correction:?}: {:?}", reports[0].rounds);
        assert_eq!(reports[0].rounds.len(), 1);
        // Under the bound correction nothing is a violation, so only the refusal can flag the row.
        if correction == Correction::Bound {
            assert_eq!(reports[0].verification.violations, 0);
        }
        // Without a violation the manifest entry would look verified: the table refuses it, naming the row.
        if reports[0].verification.violations == 0 {
            let refused = apply_reports(&evaluator, &mut manifest, system, &reports);
            assert!(
                matches!(&refused, Err(e @ VerifyError::LeftDomain { .. }) if e.to_string().contains("domain's edge")),
                "{correction:?}: {refused:?}"
            );
            assert!(manifest.teb_table.iter().all(|row| row.verification.is_none()), "nothing was written");
        }
    }
}

#[test]
fn the_bound_correction_bounds_a_shrunk_table_in_one_round_whole_or_in_pieces() {
    let (system, solution) = ground_truth();
    let correct_level = LEVEL_FACTOR * grid_v_min();
    let level = SHRINK * correct_level;
    let network = fitted_network(system, solution, SHRINK);
    let (evaluator, bundle) = load(system, &network, level);
    let beta = system.params[0].max;
    let adversaries = std::slice::from_ref(solution);
    let selection = Selection { adversaries, grid_tolerance: 0.1, ..bare_selection(&beta) };
    let options =
        |pieces| VerifyOptions { eps: 2e-2, delta: 1e-3, correction: Correction::Bound, pieces, ..shipped_settings() };
    let n = required_samples(2e-2, 1e-3);
    let whole = |pieces| {
        let mut manifest = bundle.manifest.clone();
        verify_table(&evaluator, &mut manifest, system, &selection, &options(pieces), &ProgressBar::hidden())
            .unwrap()
            .remove(0)
    };

    // Whole: one round of every sample, none a violation, and the bound the largest error reached. The shrunk
    // set is the correct table's set {V_true <= correct level}, so the independent reference for its bound
    // is the correct level (within the slack the correct table's own test allows).
    let one = whole(1);
    let v = &one.verification;
    eprintln!("shrunk table, bound correction: {one:?}");
    assert_eq!((one.outcome, one.rounds.len(), v.rounds, v.violations), (Outcome::Verified, 1, 1, 0));
    assert_eq!(v.samples, n);
    assert!(v.checks.iter().take(2).all(|c| c.samples == n), "{:?}", v.checks);
    assert_eq!(v.verified_level, v.checks.iter().map(|c| c.max_error).fold(0.0, f64::max));
    assert_eq!(one.rounds[0].level, v.verified_level, "the round's bound is its largest error");
    assert!((one.sampled_level() - level).abs() < 1e-12, "the set sampled is the row's: {}", one.sampled_level());
    assert!(
        (0.9 * correct_level..=1.04 * correct_level).contains(&v.verified_level),
        "bound {} against the grid's {correct_level}",
        v.verified_level
    );

    // In three pieces: the counts add up to at least N, and the bound lies within the sampling's spread.
    let split = whole(3);
    let w = &split.verification;
    assert_eq!((split.outcome, split.rounds.len(), split.piece), (Outcome::Verified, 1, None));
    assert_eq!(w.samples, 3 * n.div_ceil(3));
    let families: usize = w.planners.iter().filter(|p| p.family == "model-worst-case").map(|p| p.rollouts).sum();
    assert_eq!(families, 2 * w.samples, "the model's worst case played every uniform and slice sample");
    assert!((w.verified_level / v.verified_level - 1.0).abs() < 0.03, "{} vs {}", w.verified_level, v.verified_level);

    // The pieces in two shards (three items: the shards take 0, 2 and 1) combine into what one process gives.
    let run_shard = |index| {
        let shard = Shard { index, count: 2 };
        verify_rows(&evaluator, &bundle.manifest, system, &selection, shard, &options(3), &ProgressBar::hidden())
            .unwrap()
    };
    let (first, second) = (run_shard(0), run_shard(1));
    assert_eq!((first.len(), second.len()), (2, 1));
    let combined = combine_pieces([first.clone(), second].concat()).unwrap().remove(0);
    assert_eq!(combined.verification, split.verification);
    assert_eq!(combined.rounds, split.rounds);
    // A piece missing is refused with the reason.
    let missing = combine_pieces(first);
    assert!(
        matches!(&missing, Err(VerifyError::Setting(m)) if m.contains("shards 1 of 3 are missing")),
        "{:?}",
        missing.map(|r| r.len())
    );
    // The set correction's rounds depend on each other: its samples cannot be split.
    let mut manifest = bundle.manifest.clone();
    let set = VerifyOptions { correction: Correction::Set, ..options(3) };
    let refused = verify_table(&evaluator, &mut manifest, system, &selection, &set, &ProgressBar::hidden());
    assert!(matches!(&refused, Err(VerifyError::Setting(m)) if m.contains("pieces")), "{:?}", refused.map(|r| r.len()));
}

/// The excess of the error over the start's value, `max_t |e(t)| - V(r(0))`, on the fitted network scaled
/// by `scale`: the bound correction's one round from the set at the correct level (scaled with the network, so
/// the same set), at `eps` 1e-2, with `options` over the shipped settings'.
fn excess_of(scale: f64, options: VerifyOptions) -> (RowReport, f64) {
    let (system, solution) = ground_truth();
    let network = fitted_network(system, solution, scale);
    let level = LEVEL_FACTOR * grid_v_min() * scale;
    let (evaluator, bundle) = load(system, &network, level);
    let options = VerifyOptions {
        eps: 1e-2,
        correction: Correction::Bound,
        error_scale: ErrorScale::ExcessOverStartValue,
        level_margin: 0.0,
        min_acceptance: 0.0,
        ..options
    };
    let beta = system.params[0].max;
    let selection =
        Selection { adversaries: std::slice::from_ref(solution), grid_tolerance: 0.1, ..bare_selection(&beta) };
    let reports =
        verify_rows(&evaluator, &bundle.manifest, system, &selection, Shard::WHOLE, &options, &ProgressBar::hidden())
            .unwrap();
    (reports[0].clone(), level)
}

#[test]
fn the_excess_over_the_start_value_is_small_for_a_correct_value_and_grows_with_a_shrunk_one() {
    let (correct, level) = excess_of(1.0, shipped_settings());
    let excess = correct.verification.verified_level;
    eprintln!("correct value: level {level:.4}, excess {excess:.4}, checks {:?}", correct.verification.checks);
    assert_eq!(correct.outcome, Outcome::Verified);
    assert_eq!(correct.sampled_level(), level);
    let names: Vec<&str> = correct.verification.checks.iter().map(|c| c.distribution.as_str()).collect();
    assert_eq!(names, [UNIFORM, ZERO_ERROR_SLICE, FALSIFICATION]);
    // The falsification climbs the excess, not the error: it never reports less than the samples it starts from.
    let sampled = correct.verification.checks[..2].iter().map(|c| c.max_error).fold(0.0, f64::max);
    assert!(correct.verification.checks[2].max_error >= sampled);
    assert!(excess < 0.25 * level, "excess {excess} of a correct value at level {level}");

    // Scaling the value by SHRINK keeps its control (the gradient's signs) and its set (the level scales too),
    // so the same starts take the same paths and each excess grows by (1 - SHRINK) V(r(0)), with V(r(0)) between
    // the minimum and the level: an exact check of what is measured (the search, whose starts depend on the
    // measure, is off; the proposals are drawn over the whole box, which does not scale with the level).
    let plain = VerifyOptions {
        search: SearchOptions { population: 0, ..SearchOptions::default() },
        zero_error_slice: false,
        falsification: FalsificationOptions { starts: 0, ..FalsificationOptions::default() },
        proposal_box: 0.0,
        ..shipped_settings()
    };
    let (base, _) = excess_of(1.0, plain.clone());
    let (shrunk, _) = excess_of(SHRINK, plain);
    let (before, after) = (base.verification.verified_level, shrunk.verification.verified_level);
    eprintln!("uniform excess {before:.4}, shrunk by {SHRINK}: {after:.4}");
    // The fit's minimum lies within 3% of the grid's.
    let (low, high) = (before + (1.0 - SHRINK) * 0.97 * grid_v_min(), before + (1.0 - SHRINK) * level);
    assert!((low..=1.01 * high).contains(&after), "shrunk excess {after} outside [{low}, {high}]");

    // An excess is no level to sample under: the set correction refuses it.
    let options = VerifyOptions { error_scale: ErrorScale::ExcessOverStartValue, ..shipped_settings() };
    let (system, solution) = ground_truth();
    let (evaluator, bundle) = load(system, &fitted_network(system, solution, 1.0), 1.0);
    let beta = system.params[0].max;
    let refused = verify_alone(&evaluator, &bundle.manifest, beta, &options);
    assert!(matches!(refused, Err(VerifyError::Setting(ref why)) if why.contains("bound correction")), "{refused:?}");
}
