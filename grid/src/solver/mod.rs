//! The tracking value iteration: from `V(r, 0) = l(r)`, step `dV/dtau = H` with `V <- max(V, l)` until the
//! largest change per unit horizon falls below a tolerance (converged) or the horizon cap is reached.
//!
//! The change is measured per step (`rate_window` 0), or over windows of horizon: `max |V(tau) - V(tau - w)| / w`
//! at the end of each window of length `w`. A step's change also counts the scheme's step-to-step oscillation
//! (WENO5's stencil switching and the obstacle near kinks), which does not settle: on dubins4d (31^4, 25 to
//! 30 s, record `grid-dubins4d-horizon-31-windows`) the largest change of a step is 4-14x the largest net change
//! over 2 s, so only the window measures whether the value still drifts.
//!
//! The largest change is taken over the whole grid by default, or over a sublevel set near `V_min` away from
//! the non-periodic edges ([`ConvergenceSet`]): under optimal play trajectories never leave a sublevel set of
//! the tracking value (`V(r) = max(l(r), V(r(t)))`), so values outside it do not feed into it, and the rate
//! there measures whether the TEB and its error set have settled.

mod convergence;
mod fields;
mod progress;

pub use convergence::{region_rates, window_rates};
pub use fastrack_gridfile::settings::{ConvergenceSet, SolverConfig};
pub use fastrack_gridfile::solution::{HistoryPoint, RegionRates, Solution, SolveInfo, WindowRates};
pub use fields::SolveFields;

use crate::grid::Grid;
use crate::hamiltonian::Hamiltonian;
use crate::integrate::{step, Workspace};
use crate::scheme::Flux;
use fastrack_valuefn::system::AffineSystem;
use progress::progress_bar;
use std::time::Instant;

/// A configuration or system the solver cannot use.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum SolveError {
    /// The parameters do not match the system.
    #[error("system `{system}` takes {expected} parameters, {given} given")]
    Params {
        /// System id.
        system: String,
        /// Parameters the system has.
        expected: usize,
        /// Parameters supplied.
        given: usize,
    },
    /// The grid does not match the system.
    #[error("the grid has {grid} axes, system `{system}` has {state} state coordinates")]
    Grid {
        /// System id.
        system: String,
        /// Grid axes.
        grid: usize,
        /// State coordinates.
        state: usize,
    },
    /// A numeric setting is out of range.
    #[error("{0}")]
    Setting(String),
}

fn check(system: &AffineSystem, params: &[f64], grid: &Grid, config: &SolverConfig) -> Result<(), SolveError> {
    if params.len() != system.n_params() {
        return Err(SolveError::Params { system: system.id.into(), expected: system.n_params(), given: params.len() });
    }
    if grid.ndim() != system.n_state() {
        return Err(SolveError::Grid { system: system.id.into(), grid: grid.ndim(), state: system.n_state() });
    }
    let positive = |name: &str, x: f64| {
        if x.is_finite() && x > 0.0 {
            Ok(())
        } else {
            Err(SolveError::Setting(format!("{name} must be a positive number, got {x}")))
        }
    };
    if config.flux == Flux::Godunov && !Hamiltonian::new(system, params).is_separable() {
        return Err(SolveError::Setting(format!(
            "the godunov flux needs every input of `{}` to act on one state coordinate; use lax_friedrichs",
            system.id
        )));
    }
    positive("cfl", config.cfl)?;
    positive("horizon cap", config.horizon_cap)?;
    positive("tolerance", config.tolerance)?;
    if !(config.rate_window.is_finite() && config.rate_window >= 0.0) {
        return Err(SolveError::Setting(format!("rate window must be >= 0 s, got {}", config.rate_window)));
    }
    if !(config.settle_time.is_finite() && config.settle_time >= 0.0) {
        return Err(SolveError::Setting(format!("settle time must be >= 0, got {}", config.settle_time)));
    }
    if let Some(set) = config.converge_on {
        if !(set.margin.is_finite() && set.margin >= 0.0) {
            return Err(SolveError::Setting(format!("convergence set margin must be >= 0, got {}", set.margin)));
        }
    }
    if params.iter().any(|p| !p.is_finite()) {
        return Err(SolveError::Setting(format!("parameters must be finite, got {params:?}")));
    }
    Ok(())
}

/// Solves the tracking value of `system` at `params` on `grid`; `progress` shows an indicatif bar.
pub fn solve(
    system: &AffineSystem,
    params: &[f64],
    grid: &Grid,
    config: &SolverConfig,
    progress: bool,
) -> Result<Solution, SolveError> {
    check(system, params, grid, config)?;
    let start = Instant::now();
    let fields = SolveFields::new(system, params, grid);
    let l = &fields.l;
    let scheme = fields.scheme(grid, config.accuracy, config.flux, config.tracking);
    let dt = scheme.cfl_step(config.cfl);
    let mut values = l.clone();
    let mut work = Workspace::new(grid.num_points());
    let mut before = vec![0.0; grid.num_points()];
    let set = config.converge_on.unwrap_or(ConvergenceSet::DIAGNOSTIC);
    let bar = progress_bar(progress, config.horizon_cap);
    let (mut tau, mut steps, mut rate, mut converged) = (0.0, 0usize, f64::INFINITY, false);
    let mut below_since: Option<f64> = None;
    let mut history = vec![HistoryPoint {
        tau: 0.0,
        v_min: values.iter().copied().fold(f64::INFINITY, f64::min),
        rate: None,
        regions: None,
        window: None,
    }];
    let record_every = (0.1 / dt).ceil().max(1.0) as usize;
    let windowed = config.rate_window > 0.0;
    // The values and horizon at the start of the current rate window.
    let (mut window_start, mut window_tau) = (if windowed { values.clone() } else { Vec::new() }, 0.0);
    while tau < config.horizon_cap {
        let h = dt.min(config.horizon_cap - tau);
        // Rates by region need the values before the step: every step for a restricted per-step test, else
        // when the history records this step.
        let by_region = (config.converge_on.is_some() && !windowed) || (steps + 1) % record_every == 0;
        if by_region {
            before.copy_from_slice(&values);
        }
        let summary = step(&scheme, config.rk, h, &mut values, &mut work);
        tau += h;
        steps += 1;
        rate = summary.max_change / h;
        let regions = by_region.then(|| region_rates(grid, &before, &values, h, set));
        let window_ends = windowed && (tau - window_tau >= config.rate_window - 1e-9 || tau >= config.horizon_cap);
        let window = window_ends.then(|| {
            let rates = window_rates(grid, &window_start, &values, tau - window_tau, set);
            window_start.copy_from_slice(&values);
            rates
        });
        // The rate tested, and the horizon from which it holds: a window's rate holds from the window's start.
        let tested = if windowed {
            window.map(|w| (w.tested(config.converge_on.is_some()), window_tau))
        } else {
            let tested = match (config.converge_on, regions) {
                (Some(_), Some(r)) => r.set,
                _ => rate,
            };
            Some((tested, tau - h))
        };
        if window_ends {
            window_tau = tau;
        }
        if let Some((tested, from)) = tested {
            // Horizon from which the rate has stayed below the tolerance.
            below_since = if tested < config.tolerance { below_since.or(Some(from)) } else { None };
            converged = below_since.is_some_and(|t0| tau - t0 >= config.settle_time);
        }
        if steps % record_every == 0 || window.is_some() || converged || tau >= config.horizon_cap {
            history.push(HistoryPoint { tau, v_min: summary.min_value, rate: Some(rate), regions, window });
            bar.set_position((tau * 1000.0) as u64);
            let window_rate = history.iter().rev().find_map(|h| h.window).map_or(String::new(), |w| {
                format!("  over {:.1} s: {:.2e}", w.span, w.tested(config.converge_on.is_some()))
            });
            bar.set_message(format!(
                "{tau:.2} s  V_min {:.4}  max|dV/dtau| {rate:.2e}{window_rate}",
                summary.min_value
            ));
            tracing::debug!(tau, v_min = summary.min_value, rate, "step");
        }
        if converged {
            break;
        }
    }
    bar.finish_and_clear();
    let info = SolveInfo {
        system: system.id.into(),
        params: params.to_vec(),
        config: config.clone(),
        horizon: tau,
        converged,
        steps,
        dt,
        final_rate: rate,
        wall_s: start.elapsed().as_secs_f64(),
        history,
    };
    Ok(Solution { grid: grid.clone(), values, info })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::grid::Axis;

    #[test]
    fn the_godunov_flux_is_refused_for_a_system_with_an_input_on_two_coordinates() {
        let mut system = fastrack_valuefn::system::by_id("dubins4d").unwrap();
        system.g_control[(0, 0)] = 0.5;
        let axes = system
            .state
            .iter()
            .map(|d| Axis { name: d.name.into(), min: d.min, max: d.max, n: 5, periodic: d.periodic })
            .collect();
        let grid = Grid::new(axes).unwrap();
        let config = SolverConfig { flux: Flux::Godunov, horizon_cap: 0.01, ..SolverConfig::default() };
        match solve(&system, &[1.0, 1.0], &grid, &config, false) {
            Err(SolveError::Setting(message)) => assert!(message.contains("lax_friedrichs"), "{message}"),
            other => panic!("expected a settings error, got {:?}", other.map(|s| s.info.horizon)),
        }
        let config = SolverConfig { flux: Flux::LaxFriedrichs, ..config };
        assert!(solve(&system, &[1.0, 1.0], &grid, &config, false).is_ok());
    }

    #[test]
    fn windowed_solves_test_the_rate_at_window_ends_and_refuse_a_negative_window() {
        let system = fastrack_valuefn::system::by_id("double_integrator").unwrap();
        let grid = Grid::for_system(&system, &[41, 21]).unwrap();
        let window = 0.5;
        let config =
            SolverConfig { tolerance: 0.05, rate_window: window, horizon_cap: 20.0, ..SolverConfig::default() };
        let solution = solve(&system, &[1.0], &grid, &config, false).unwrap();
        let windows: Vec<(f64, WindowRates)> =
            solution.info.history.iter().filter_map(|h| h.window.map(|w| (h.tau, w))).collect();
        assert!(solution.info.converged, "not converged by {} s", solution.info.horizon);
        // Windows tile the horizon, each at least the window long and less than a step more.
        let mut previous_end = 0.0;
        for (tau, w) in &windows {
            assert!((tau - previous_end - w.span).abs() < 1e-9, "a window of {} s ends at {tau} s", w.span);
            assert!(w.span >= window - 1e-9 && w.span < window + solution.info.dt, "a window spans {} s", w.span);
            previous_end = *tau;
        }
        // It stops at the end of the first window whose rate is under the tolerance, not before.
        let (last_tau, last) = windows.last().unwrap();
        assert_eq!(*last_tau, solution.info.horizon);
        assert!(last.grid < config.tolerance);
        assert!(windows[..windows.len() - 1].iter().all(|(_, w)| w.grid >= config.tolerance));
        let config = SolverConfig { rate_window: -1.0, ..config };
        assert!(matches!(solve(&system, &[1.0], &grid, &config, false), Err(SolveError::Setting(_))));
    }
}
