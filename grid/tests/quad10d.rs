//! quad10d's z axis against its closed form `beta^2 / a_up`: a double integrator whose acceleration box is
//! not centred on zero, solved by the grid solver as the ground truth of that axis.
//!
//! As for the symmetric double integrator, the problem is scale invariant (`z ~ beta^2 / a_up`, `v ~ beta`,
//! `dV/dtau ~ beta`): on a domain scaled to its error set, with a tolerance scaled by `beta`, every `beta`
//! gives the same relative error (the double integrator's test checks that invariance), so `beta_u` alone
//! is solved.

use fastrack_grid::grid::{Axis, Grid};
use fastrack_grid::scheme::Flux;
use fastrack_grid::solver::{solve, SolverConfig};
use fastrack_valuefn::system::quad10d::{z_axis, z_axis_closed_form_teb, BETA_RANGE};

/// Half-widths of the domain in units of the closed-form bound (position) and of `beta` (velocity).
const HALF_WIDTH: (f64, f64) = (2.4, 1.5);

fn grid(beta: f64, n_z: usize, n_v: usize) -> Grid {
    let (half_z, half_v) = (HALF_WIDTH.0 * z_axis_closed_form_teb(beta), HALF_WIDTH.1 * beta);
    Grid::new(vec![
        Axis { name: "z_r".into(), min: -half_z, max: half_z, n: n_z, periodic: false },
        Axis { name: "v_z".into(), min: -half_v, max: half_v, n: n_v, periodic: false },
    ])
    .unwrap()
}

#[test]
fn z_axis_v_min_within_3_percent_of_closed_form_and_error_shrinks_under_refinement() {
    let system = z_axis();
    let beta = BETA_RANGE.1;
    let config = SolverConfig { tolerance: 0.01 * beta, flux: Flux::Godunov, ..SolverConfig::default() };
    let mut errors = Vec::new();
    for (n_z, n_v) in [(201, 101), (241, 121)] {
        let solution = solve(&system, &[beta], &grid(beta, n_z, n_v), &config, false).unwrap();
        let v_min = solution.values.iter().copied().fold(f64::INFINITY, f64::min);
        let ratio = v_min / z_axis_closed_form_teb(beta);
        eprintln!("beta {beta}, {n_z}x{n_v}: V_min / closed form = {ratio:.4}, converged {}", solution.info.converged);
        assert!(solution.info.converged, "{n_z}x{n_v}: not converged by the horizon cap");
        let error = (ratio - 1.0).abs();
        assert!(error < 0.03, "{n_z}x{n_v}: V_min is {:.2}% from the closed form", 100.0 * error);
        errors.push(error);
    }
    assert!(errors[1] < errors[0], "the error did not shrink under refinement: {errors:?}");
}
