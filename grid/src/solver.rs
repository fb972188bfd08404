//! The tracking value iteration: from `V(r, 0) = l(r)`, step `dV/dtau = H` with `V <- max(V, l)` until the
//! largest change per unit horizon falls below a tolerance (converged) or the horizon cap is reached.

use crate::grid::Grid;
use crate::hamiltonian::Hamiltonian;
use crate::integrate::{step, RkOrder, Workspace};
use crate::scheme::Scheme;
use crate::upwind::Accuracy;
use fastrack_valuefn::system::AffineSystem;
use indicatif::{ProgressBar, ProgressStyle};
use rayon::prelude::*;
use serde::{Deserialize, Serialize};
use std::time::Instant;

/// How to solve.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SolverConfig {
    /// Derivative approximation.
    pub accuracy: Accuracy,
    /// TVD Runge-Kutta order.
    pub rk: RkOrder,
    /// CFL number (`dt = cfl / max sum_i alpha_i / h_i`).
    pub cfl: f64,
    /// Largest horizon integrated (s).
    pub horizon_cap: f64,
    /// Converged once `max |dV/dtau|` over the grid is below this (value units per second).
    pub tolerance: f64,
    /// Apply the tracking obstacle `V <- max(V, l)` after every stage; `false` integrates the plain
    /// terminal-cost equation (only useful to show what the obstacle does).
    pub tracking: bool,
}

impl Default for SolverConfig {
    fn default() -> Self {
        Self {
            accuracy: Accuracy::Weno5,
            rk: RkOrder::Three,
            cfl: 0.75,
            horizon_cap: 30.0,
            tolerance: 1e-3,
            tracking: true,
        }
    }
}

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

/// One entry of the convergence history.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct HistoryPoint {
    /// Horizon reached (s).
    pub tau: f64,
    /// `min V` over the grid.
    pub v_min: f64,
    /// `max |dV/dtau|` over the grid in the last step (none at `tau = 0`).
    pub rate: Option<f64>,
}

/// How a solve went.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SolveInfo {
    /// System id.
    pub system: String,
    /// Parameters (planner speed bounds).
    pub params: Vec<f64>,
    /// The configuration.
    pub config: SolverConfig,
    /// Horizon integrated (s); the converged horizon when `converged`.
    pub horizon: f64,
    /// True when the rate fell below the tolerance before the cap.
    pub converged: bool,
    /// Time steps taken.
    pub steps: usize,
    /// Time step (s).
    pub dt: f64,
    /// Last `max |dV/dtau|`.
    pub final_rate: f64,
    /// Wall time (s).
    pub wall_s: f64,
    /// `(tau, V_min, rate)` about every 0.1 s of horizon.
    pub history: Vec<HistoryPoint>,
}

/// A value function on a grid.
#[derive(Debug, Clone, PartialEq)]
pub struct Solution {
    /// The grid.
    pub grid: Grid,
    /// Values, row-major (last axis fastest).
    pub values: Vec<f64>,
    /// How it was computed.
    pub info: SolveInfo,
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
    positive("cfl", config.cfl)?;
    positive("horizon cap", config.horizon_cap)?;
    positive("tolerance", config.tolerance)?;
    if params.iter().any(|p| !p.is_finite()) {
        return Err(SolveError::Setting(format!("parameters must be finite, got {params:?}")));
    }
    Ok(())
}

/// `l(r)` at every grid point.
pub fn tracking_error_field(system: &AffineSystem, grid: &Grid) -> Vec<f64> {
    let n = grid.ndim();
    (0..grid.num_points())
        .into_par_iter()
        .map_init(
            || vec![0.0; n],
            |r, flat| {
                grid.point(flat, r);
                system.tracking_error(r)
            },
        )
        .collect()
}

/// `alpha_i(r) >= |dH/dp_i|` at every grid point, point-major, from [`AffineSystem::dissipation_bounds`].
pub fn dissipation_field(system: &AffineSystem, params: &[f64], grid: &Grid) -> Vec<f64> {
    let n = grid.ndim();
    let mut alpha = vec![0.0; grid.num_points() * n];
    alpha.par_chunks_mut(n).enumerate().for_each_init(
        || vec![0.0; n],
        |r, (flat, out)| {
            grid.point(flat, r);
            system.dissipation_bounds(r, params, out);
        },
    );
    alpha
}

/// The drift `f(r)` at every grid point, point-major.
pub fn drift_field(hamiltonian: &Hamiltonian, grid: &Grid) -> Vec<f64> {
    let n = grid.ndim();
    let mut drift = vec![0.0; grid.num_points() * n];
    drift.par_chunks_mut(n).enumerate().for_each_init(
        || vec![0.0; n],
        |r, (flat, out)| {
            grid.point(flat, r);
            hamiltonian.drift(r, out);
        },
    );
    drift
}

fn progress_bar(show: bool, cap: f64) -> ProgressBar {
    if !show {
        return ProgressBar::hidden();
    }
    let bar = ProgressBar::new((cap * 1000.0).ceil() as u64);
    let style = ProgressStyle::with_template("{elapsed_precise} [{bar:30}] tau {msg}")
        .unwrap_or_else(|_| ProgressStyle::default_bar())
        .progress_chars("=> ");
    bar.set_style(style);
    bar
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
    let hamiltonian = Hamiltonian::new(system, params);
    let l = tracking_error_field(system, grid);
    let alpha = dissipation_field(system, params, grid);
    let drift = drift_field(&hamiltonian, grid);
    let scheme = Scheme {
        grid,
        hamiltonian: &hamiltonian,
        alpha: &alpha,
        drift: &drift,
        accuracy: config.accuracy,
        obstacle: config.tracking.then_some(&l[..]),
    };
    let dt = scheme.cfl_step(config.cfl);
    let mut values = l.clone();
    let mut work = Workspace::new(grid.num_points());
    let bar = progress_bar(progress, config.horizon_cap);
    let (mut tau, mut steps, mut rate, mut converged) = (0.0, 0usize, f64::INFINITY, false);
    let mut history =
        vec![HistoryPoint { tau: 0.0, v_min: values.iter().copied().fold(f64::INFINITY, f64::min), rate: None }];
    let record_every = (0.1 / dt).ceil().max(1.0) as usize;
    while tau < config.horizon_cap {
        let h = dt.min(config.horizon_cap - tau);
        let summary = step(&scheme, config.rk, h, &mut values, &mut work);
        tau += h;
        steps += 1;
        rate = summary.max_change / h;
        converged = rate < config.tolerance;
        if steps % record_every == 0 || converged {
            history.push(HistoryPoint { tau, v_min: summary.min_value, rate: Some(rate) });
            bar.set_position((tau * 1000.0) as u64);
            bar.set_message(format!("{tau:.2} s  V_min {:.4}  max|dV/dtau| {rate:.2e}", summary.min_value));
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
