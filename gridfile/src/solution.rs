//! A value function on a grid and the record of how it was solved.

use crate::grid::Grid;
use crate::settings::SolverConfig;
use serde::{Deserialize, Serialize};

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
    /// Over the convergence set (the solve's [`ConvergenceSet`](crate::settings::ConvergenceSet), or
    /// [`ConvergenceSet::DIAGNOSTIC`](crate::settings::ConvergenceSet::DIAGNOSTIC)).
    pub set: f64,
    /// Over the nodes of the sublevel set `{V <= V_min + margin |V_min|}` that are outside the interior.
    pub set_edge: f64,
    /// Distance in nodes from the node of the largest change over the grid to the nearest non-periodic edge.
    pub worst_edge_distance: usize,
    /// `V - V_min` at that node.
    pub worst_excess: f64,
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

impl Solution {
    /// `V_min`: the smallest value over the grid.
    pub fn v_min(&self) -> f64 {
        self.values.iter().copied().fold(f64::INFINITY, f64::min)
    }

    /// `dV/dr` of the interpolant at `r` by central differences across one cell, into `out`.
    pub fn gradient(&self, r: &[f64], out: &mut [f64]) {
        let mut shifted = r.to_vec();
        for (i, axis) in self.grid.axes().iter().enumerate() {
            let h = axis.spacing();
            shifted[i] = r[i] + 0.5 * h;
            let up = self.grid.interpolate(&self.values, &shifted);
            shifted[i] = r[i] - 0.5 * h;
            let down = self.grid.interpolate(&self.values, &shifted);
            shifted[i] = r[i];
            out[i] = (up - down) / h;
        }
    }
}
