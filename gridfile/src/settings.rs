//! How a solution was computed: the numerical scheme's choices and the convergence test, as recorded in
//! every `.ftgrid` header and read back by whoever uses the file.

use serde::{Deserialize, Serialize};
use std::fmt;
use std::str::FromStr;

/// Spatial accuracy of the one-sided derivative approximations.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Accuracy {
    /// First-order upwind differences (stencil half-width 1).
    First,
    /// Second-order essentially non-oscillatory (half-width 2).
    Eno2,
    /// Fifth-order weighted ENO of Jiang and Peng (half-width 3).
    Weno5,
}

impl Accuracy {
    /// Every accuracy, coarsest first.
    pub const ALL: [Accuracy; 3] = [Accuracy::First, Accuracy::Eno2, Accuracy::Weno5];

    /// Nodes on each side of the centre a derivative reads.
    pub fn half_width(self) -> usize {
        match self {
            Accuracy::First => 1,
            Accuracy::Eno2 => 2,
            Accuracy::Weno5 => 3,
        }
    }

    /// The name used on the command line and in files.
    pub fn name(self) -> &'static str {
        match self {
            Accuracy::First => "first",
            Accuracy::Eno2 => "eno2",
            Accuracy::Weno5 => "weno5",
        }
    }
}

impl fmt::Display for Accuracy {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

/// An accuracy name that is not `first`, `eno2` or `weno5`.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("unknown accuracy `{0}`; expected first, eno2 or weno5")]
pub struct UnknownAccuracy(pub String);

impl FromStr for Accuracy {
    type Err = UnknownAccuracy;

    fn from_str(s: &str) -> Result<Self, Self::Err> {
        Accuracy::ALL.into_iter().find(|a| a.name() == s).ok_or_else(|| UnknownAccuracy(s.into()))
    }
}

/// The numerical Hamiltonian (flux) built from the one-sided derivatives.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Flux {
    /// Lax-Friedrichs with per-point dissipation from the `|dH/dp_i|` bounds: any system.
    #[default]
    LaxFriedrichs,
    /// Godunov's: systems whose every input acts on one state coordinate. The least dissipative monotone
    /// flux: closer to the double integrator's closed form than Lax-Friedrichs, but lower (the unsafe side)
    /// where a valley of `V` is only a few cells wide.
    Godunov,
}

impl Flux {
    /// Every flux.
    pub const ALL: [Flux; 2] = [Flux::LaxFriedrichs, Flux::Godunov];

    /// The name used on the command line and in files.
    pub fn name(self) -> &'static str {
        match self {
            Flux::LaxFriedrichs => "lax_friedrichs",
            Flux::Godunov => "godunov",
        }
    }
}

impl fmt::Display for Flux {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

/// A flux name that is not `lax_friedrichs` or `godunov`.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("unknown flux `{0}`; expected lax_friedrichs or godunov")]
pub struct UnknownFlux(pub String);

impl FromStr for Flux {
    type Err = UnknownFlux;

    fn from_str(s: &str) -> Result<Self, Self::Err> {
        Flux::ALL.into_iter().find(|f| f.name() == s).ok_or_else(|| UnknownFlux(s.into()))
    }
}

/// Order of the TVD Runge-Kutta scheme.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub enum RkOrder {
    /// Forward Euler.
    #[serde(rename = "1")]
    One,
    /// Two-stage TVD RK (Heun).
    #[serde(rename = "2")]
    Two,
    /// Three-stage TVD RK.
    #[serde(rename = "3")]
    Three,
}

impl RkOrder {
    /// The order as a number.
    pub fn order(self) -> u8 {
        match self {
            RkOrder::One => 1,
            RkOrder::Two => 2,
            RkOrder::Three => 3,
        }
    }
}

impl fmt::Display for RkOrder {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}", self.order())
    }
}

/// An order other than 1, 2 or 3.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("unknown Runge-Kutta order `{0}`; expected 1, 2 or 3")]
pub struct UnknownOrder(pub String);

impl FromStr for RkOrder {
    type Err = UnknownOrder;

    fn from_str(s: &str) -> Result<Self, Self::Err> {
        match s {
            "1" => Ok(RkOrder::One),
            "2" => Ok(RkOrder::Two),
            "3" => Ok(RkOrder::Three),
            _ => Err(UnknownOrder(s.into())),
        }
    }
}

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
