//! The double integrator's converged `V_min` against its closed form `beta^2 / a`.
//!
//! `beta_u` is solved on the system's domain. The problem is scale invariant (`x ~ beta^2 / a`, `v ~ beta`,
//! `tau ~ beta / a`, so `dV/dtau ~ beta`), so `beta_l` is solved on the domain scaled by `(beta / beta_u)^2`
//! in `x_r` and `beta / beta_u` in `v`, with the tolerance scaled by `beta / beta_u`: the same relative
//! resolution of the error set, and (as the test checks) the same relative error.

use fastrack_grid::grid::{Axis, Grid};
use fastrack_grid::scheme::Flux;
use fastrack_grid::solver::{solve, SolverConfig};
use fastrack_valuefn::system::double_integrator::{closed_form_teb, system};

/// Tolerance on `max |dV/dtau|` at `beta = 1` (scaled by `beta`).
const TOLERANCE_PER_BETA: f64 = 0.02;

/// `(beta, half-width of x_r, half-width of v, tolerance)` for `beta_u` and `beta_l`.
fn cases() -> Vec<(f64, f64, f64, f64)> {
    let system = system();
    let (beta_l, beta_u) = (system.params[0].min, system.params[0].max);
    let (half_x, half_v) = (system.state[0].max, system.state[1].max);
    [beta_u, beta_l]
        .into_iter()
        .map(|beta| {
            let s = beta / beta_u;
            (beta, half_x * s * s, half_v * s, TOLERANCE_PER_BETA * beta)
        })
        .collect()
}

fn grid(half_x: f64, half_v: f64, n_x: usize, n_v: usize) -> Grid {
    Grid::new(vec![
        Axis { name: "x_r".into(), min: -half_x, max: half_x, n: n_x, periodic: false },
        Axis { name: "v".into(), min: -half_v, max: half_v, n: n_v, periodic: false },
    ])
    .unwrap()
}

/// `V_min / closed form` and whether the solve converged.
fn ratio(beta: f64, grid: &Grid, config: &SolverConfig) -> (f64, bool) {
    let solution = solve(&system(), &[beta], grid, config, false).unwrap();
    let v_min = solution.v_min();
    (v_min / closed_form_teb(beta), solution.info.converged)
}

#[test]
fn v_min_within_3_percent_of_closed_form_and_error_shrinks_under_refinement() {
    for (beta, half_x, half_v, tolerance) in cases() {
        let config = SolverConfig { tolerance, ..SolverConfig::default() };
        let mut errors = Vec::new();
        for (n_x, n_v) in [(201, 101), (241, 121)] {
            let (ratio, converged) = ratio(beta, &grid(half_x, half_v, n_x, n_v), &config);
            let error = (ratio - 1.0).abs();
            eprintln!("beta {beta}, {n_x}x{n_v}: V_min / closed form = {ratio:.4}, converged {converged}");
            assert!(converged, "beta {beta}, {n_x}x{n_v}: not converged by the horizon cap");
            assert!(error < 0.03, "beta {beta}, {n_x}x{n_v}: V_min is {:.2}% from the closed form", 100.0 * error);
            errors.push(error);
        }
        assert!(errors[1] < errors[0], "beta {beta}: the error did not shrink under refinement: {errors:?}");
    }
}

#[test]
fn godunov_flux_is_closer_to_the_closed_form_than_lax_friedrichs_at_a_tighter_tolerance() {
    // Half the tolerance above runs the solve further into the horizon, where Lax-Friedrichs' dissipation on
    // the kinked valley of `V` has pushed `V_min` above the closed form; Godunov's flux adds less of it.
    for (beta, half_x, half_v, tolerance) in cases() {
        let config = |flux| SolverConfig { tolerance: tolerance / 2.0, flux, ..SolverConfig::default() };
        let mut errors = Vec::new();
        for (n_x, n_v) in [(201, 101), (241, 121)] {
            let grid = grid(half_x, half_v, n_x, n_v);
            let (godunov, converged) = ratio(beta, &grid, &config(Flux::Godunov));
            let (lax_friedrichs, _) = ratio(beta, &grid, &config(Flux::LaxFriedrichs));
            eprintln!("beta {beta}, {n_x}x{n_v}: V_min / closed form: godunov {godunov:.4}, lax-friedrichs {lax_friedrichs:.4}");
            assert!(converged, "beta {beta}, {n_x}x{n_v}: godunov not converged by the horizon cap");
            let error = (godunov - 1.0).abs();
            assert!(error < 0.03, "beta {beta}, {n_x}x{n_v}: godunov V_min is {:.2}% off", 100.0 * error);
            assert!(
                error < (lax_friedrichs - 1.0).abs(),
                "beta {beta}, {n_x}x{n_v}: godunov {godunov:.4} no closer than lax-friedrichs {lax_friedrichs:.4}"
            );
            errors.push(error);
        }
        assert!(errors[1] < errors[0], "beta {beta}: the godunov error did not shrink under refinement: {errors:?}");
    }
}

#[test]
fn without_the_tracking_obstacle_the_closed_form_is_missed() {
    // Dropping `V <- max(V, l)` solves the terminal-cost equation instead; its minimum is far from the TEB.
    let (beta, half_x, half_v, tolerance) = cases()[0];
    let config = SolverConfig { tolerance, tracking: false, ..SolverConfig::default() };
    let (ratio, _) = ratio(beta, &grid(half_x, half_v, 121, 61), &config);
    eprintln!("without the obstacle: V_min / closed form = {ratio:.4}");
    assert!((ratio - 1.0).abs() > 0.2, "the obstacle-free value should miss the closed form, got ratio {ratio}");
}
