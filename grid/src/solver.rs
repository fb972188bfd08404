//! The tracking value iteration: from `V(r, 0) = l(r)`, step `dV/dtau = H` with `V <- max(V, l)` until the
//! largest change per unit horizon falls below a tolerance (converged) or the horizon cap is reached.
//!
//! The change is measured per step (`rate_window` 0), or over windows of horizon: `max |V(tau) - V(tau - w)| / w`
//! at the end of each window of length `w`. A step's change also counts the scheme's step-to-step oscillation
//! (WENO5's stencil switching and the obstacle near kinks), which does not settle: on dubins4d at 30 s the
//! largest change of a step is 15-25x the largest net change over 2 s, so only the window measures whether the
//! value still drifts.
//!
//! The largest change is taken over the whole grid by default, or over a sublevel set near `V_min` away from
//! the non-periodic edges ([`ConvergenceSet`]): under optimal play trajectories never leave a sublevel set of
//! the tracking value (`V(r) = max(l(r), V(r(t)))`), so values outside it do not feed into it, and the rate
//! there measures whether the TEB and its error set have settled.

use crate::grid::Grid;
use crate::hamiltonian::Hamiltonian;
use crate::integrate::{step, RkOrder, Workspace};
use crate::scheme::{Flux, Scheme};
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
    /// Numerical Hamiltonian (files written before it was recorded used Lax-Friedrichs).
    #[serde(default)]
    pub flux: Flux,
    /// TVD Runge-Kutta order.
    pub rk: RkOrder,
    /// CFL number (`dt = cfl / max sum_i alpha_i / h_i`).
    pub cfl: f64,
    /// Largest horizon integrated (s).
    pub horizon_cap: f64,
    /// Converged once `max |dV/dtau|` over the grid (or over `converge_on`) is below this (value units per
    /// second) for `settle_time`.
    pub tolerance: f64,
    /// Horizon (s) over which the convergence rate is measured, `max |V(tau) - V(tau - rate_window)| /
    /// rate_window` at the end of each window; 0 (the default, and files written before it was recorded)
    /// measures every step on its own.
    #[serde(default, skip_serializing_if = "is_zero")]
    pub rate_window: f64,
    /// Apply the tracking obstacle `V <- max(V, l)` after every stage; `false` integrates the plain
    /// terminal-cost equation (only useful to show what the obstacle does).
    pub tracking: bool,
    /// Where the convergence test measures `max |dV/dtau|`: `None` (the default) over every node, else over
    /// this set.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub converge_on: Option<ConvergenceSet>,
    /// Horizon (s) over which the rate must stay below the tolerance; 0 (the default) stops at the first step
    /// below it.
    #[serde(default, skip_serializing_if = "is_zero")]
    pub settle_time: f64,
}

fn is_zero(x: &f64) -> bool {
    *x == 0.0
}

/// The nodes a restricted convergence test looks at: `{V <= V_min + margin |V_min|}` (values after the step)
/// at least `edge_nodes` nodes from every non-periodic edge.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct ConvergenceSet {
    /// Relative margin of the sublevel set above `V_min`.
    pub margin: f64,
    /// Nodes left out next to each non-periodic edge (where extrapolated ghost nodes feed the stencils).
    pub edge_nodes: usize,
}

impl ConvergenceSet {
    /// The set the history's diagnostics use when the test runs over the whole grid.
    pub const DIAGNOSTIC: ConvergenceSet = ConvergenceSet { margin: 0.5, edge_nodes: 3 };
}

impl Default for SolverConfig {
    fn default() -> Self {
        Self {
            accuracy: Accuracy::Weno5,
            flux: Flux::LaxFriedrichs,
            rk: RkOrder::Three,
            cfl: 0.75,
            horizon_cap: 30.0,
            tolerance: 1e-3,
            rate_window: 0.0,
            tracking: true,
            converge_on: None,
            settle_time: 0.0,
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
    /// The same rate by region (none at `tau = 0` and in files written before regions were recorded).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub regions: Option<RegionRates>,
    /// The rates over the rate window that ends here (only at window ends of a solve with a `rate_window`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub window: Option<WindowRates>,
}

/// `max |V(tau) - V(tau - span)| / span` over a window of horizon, over the whole grid and by region.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct WindowRates {
    /// The window's length (s): the solve's `rate_window`, or less for the last window before the cap.
    pub span: f64,
    /// Over every node.
    pub grid: f64,
    /// By region, as for a step.
    pub regions: RegionRates,
}

impl WindowRates {
    /// The rate a convergence test reads: on the convergence set when it has one, else over the grid.
    pub fn tested(&self, on_set: bool) -> f64 {
        if on_set {
            self.regions.set
        } else {
            self.grid
        }
    }
}

/// `max |dV/dtau|` of one step by region, and where the largest change over the grid happened.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct RegionRates {
    /// Over nodes at least the set's `edge_nodes` from every non-periodic edge.
    pub interior: f64,
    /// Over the convergence set (the solve's [`ConvergenceSet`], or [`ConvergenceSet::DIAGNOSTIC`]).
    pub set: f64,
    /// Over the nodes of the sublevel set `{V <= V_min + margin |V_min|}` that are outside the interior.
    pub set_edge: f64,
    /// Distance in nodes from the node of the largest change over the grid to the nearest non-periodic edge.
    pub worst_edge_distance: usize,
    /// `V - V_min` at that node.
    pub worst_excess: f64,
}

/// Rates by region of a step of length `dt` from `before` to `after`, the set taken at `after`'s minimum.
pub fn region_rates(grid: &Grid, before: &[f64], after: &[f64], dt: f64, set: ConvergenceSet) -> RegionRates {
    let v_min = after.par_iter().copied().reduce(|| f64::INFINITY, f64::min);
    let level = v_min + set.margin * v_min.abs();
    let edge_distance = |flat: usize| {
        grid.axes()
            .iter()
            .enumerate()
            .filter(|(_, a)| !a.periodic)
            .map(|(k, a)| {
                let i = grid.node(flat, k);
                i.min(a.n - 1 - i)
            })
            .min()
            .unwrap_or(usize::MAX)
    };
    // (interior, set, set_edge, worst change, its flat index)
    let zero = || (0.0f64, 0.0f64, 0.0f64, -1.0f64, 0usize);
    let (interior, inside, outside, _, worst) = (0..after.len())
        .into_par_iter()
        .fold(zero, |mut acc, flat| {
            let change = (after[flat] - before[flat]).abs();
            let is_interior = edge_distance(flat) >= set.edge_nodes;
            if is_interior {
                acc.0 = acc.0.max(change);
            }
            if after[flat] <= level {
                if is_interior {
                    acc.1 = acc.1.max(change);
                } else {
                    acc.2 = acc.2.max(change);
                }
            }
            if change > acc.3 {
                acc.3 = change;
                acc.4 = flat;
            }
            acc
        })
        .reduce(zero, |x, y| {
            let (c, f) = if y.3 > x.3 { (y.3, y.4) } else { (x.3, x.4) };
            (x.0.max(y.0), x.1.max(y.1), x.2.max(y.2), c, f)
        });
    RegionRates {
        interior: interior / dt,
        set: inside / dt,
        set_edge: outside / dt,
        worst_edge_distance: edge_distance(worst),
        worst_excess: after.get(worst).map_or(0.0, |v| v - v_min),
    }
}

/// Rates over a window of horizon `span` from `start` to `end`, the set taken at `end`'s minimum.
pub fn window_rates(grid: &Grid, start: &[f64], end: &[f64], span: f64, set: ConvergenceSet) -> WindowRates {
    let largest = start.par_iter().zip(end).map(|(a, b)| (b - a).abs()).reduce(|| 0.0, f64::max);
    WindowRates { span, grid: largest / span, regions: region_rates(grid, start, end, span, set) }
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
    /// Last step's `max |dV/dtau|` over the grid ([`SolveInfo::tested_rate`] is the one the test compared).
    pub final_rate: f64,
    /// Wall time (s).
    pub wall_s: f64,
    /// `(tau, V_min, rate)` about every 0.1 s of horizon.
    pub history: Vec<HistoryPoint>,
}

impl SolveInfo {
    /// The last rate the convergence test compared with the tolerance: over the last rate window, or the
    /// last step's, on the grid or on the convergence set as configured (`None` before any was measured).
    pub fn tested_rate(&self) -> Option<f64> {
        let on_set = self.config.converge_on.is_some();
        let last = |f: &dyn Fn(&HistoryPoint) -> Option<f64>| self.history.iter().rev().find_map(f);
        match (self.config.rate_window > 0.0, on_set) {
            (true, _) => last(&|h| h.window.map(|w| w.tested(on_set))),
            (false, true) => last(&|h| h.regions.map(|r| r.set)),
            (false, false) => Some(self.final_rate),
        }
    }
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

/// `l(r)` at every grid point.
fn tracking_error_field(system: &AffineSystem, grid: &Grid) -> Vec<f64> {
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
fn dissipation_field(system: &AffineSystem, params: &[f64], grid: &Grid) -> Vec<f64> {
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
fn drift_field(hamiltonian: &Hamiltonian, grid: &Grid) -> Vec<f64> {
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

/// What a solve precomputes on its grid: the Hamiltonian at the parameters and the fields of `l(r)`, the
/// dissipation bounds and the drift.
pub struct SolveFields {
    /// The Hamiltonian at the solve's parameters.
    pub hamiltonian: Hamiltonian,
    /// `l(r)` at every point (the obstacle of the tracking value, and its initial condition).
    pub l: Vec<f64>,
    alpha: Vec<f64>,
    drift: Vec<f64>,
}

impl SolveFields {
    /// Computes the fields of `system` at `params` on `grid`.
    pub fn new(system: &AffineSystem, params: &[f64], grid: &Grid) -> Self {
        let hamiltonian = Hamiltonian::new(system, params);
        let l = tracking_error_field(system, grid);
        let alpha = dissipation_field(system, params, grid);
        let drift = drift_field(&hamiltonian, grid);
        Self { hamiltonian, l, alpha, drift }
    }

    /// The spatial scheme on `grid` (the one the fields were computed on); `tracking` adds the obstacle `l`.
    pub fn scheme<'a>(&'a self, grid: &'a Grid, accuracy: Accuracy, flux: Flux, tracking: bool) -> Scheme<'a> {
        Scheme {
            flux,
            grid,
            hamiltonian: &self.hamiltonian,
            alpha: &self.alpha,
            drift: &self.drift,
            accuracy,
            obstacle: tracking.then_some(&self.l[..]),
        }
    }
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
    fn region_rates_split_the_change_by_edge_distance_and_sublevel_set() {
        let axis = |periodic| Axis { name: "x".into(), min: 0.0, max: 1.0, n: 8, periodic };
        let grid = Grid::new(vec![axis(false), axis(true)]).unwrap();
        let before = vec![1.0; 64];
        let mut after = vec![2.0; 64];
        // V_min 1 at node (4, 0); the set {V <= 1.5} holds it and node (0, 3) on the non-periodic edge.
        after[4 * 8] = 1.0;
        after[3] = 1.5;
        // The largest change: node (3, 5), 3 nodes from the edge, outside the set.
        after[3 * 8 + 5] = 5.0;
        let set = ConvergenceSet { margin: 0.5, edge_nodes: 2 };
        let r = region_rates(&grid, &before, &after, 0.5, set);
        assert_eq!(r.interior, 8.0);
        assert_eq!(r.set, 0.0);
        assert_eq!(r.set_edge, 1.0);
        assert_eq!(r.worst_edge_distance, 3);
        assert_eq!(r.worst_excess, 4.0);
    }

    #[test]
    fn window_rates_divide_the_net_change_by_the_span() {
        let axis = Axis { name: "x".into(), min: 0.0, max: 1.0, n: 6, periodic: false };
        let grid = Grid::new(vec![axis]).unwrap();
        let start = vec![1.0, 1.0, 1.0, 1.0, 1.0, 1.0];
        // The largest net change is on the edge node 5 (outside the interior), falling: |-3| over 2 s.
        let end = vec![1.2, 1.0, 1.1, 1.0, 1.4, -2.0];
        let set = ConvergenceSet { margin: 0.5, edge_nodes: 1 };
        let w = window_rates(&grid, &start, &end, 2.0, set);
        assert_eq!(w.span, 2.0);
        assert_eq!(w.grid, 1.5);
        assert_eq!(w.regions, region_rates(&grid, &start, &end, 2.0, set));
        assert!((w.regions.interior - 0.2).abs() < 1e-12, "{:?}", w.regions);
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
