//! Total-variation-diminishing Runge-Kutta time integration (Shu & Osher) of order 1, 2 and 3.

use crate::scheme::{Scheme, Stage, StageSummary};
use serde::{Deserialize, Serialize};
use std::fmt;
use std::str::FromStr;

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

    /// Stage weights `(a, b)` of `out = a * u_n + b * (v + dt L(v))`, `v` the previous stage.
    fn stages(self) -> &'static [(f64, f64)] {
        match self {
            RkOrder::One => &[(0.0, 1.0)],
            RkOrder::Two => &[(0.0, 1.0), (0.5, 0.5)],
            RkOrder::Three => &[(0.0, 1.0), (0.75, 0.25), (1.0 / 3.0, 2.0 / 3.0)],
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

/// Two scratch grids for the intermediate stages.
pub struct Workspace {
    stage: Vec<f64>,
    next: Vec<f64>,
}

impl Workspace {
    /// Scratch space for a grid of `len` points.
    pub fn new(len: usize) -> Self {
        Self { stage: vec![0.0; len], next: vec![0.0; len] }
    }
}

/// Advances `values` by one step `dt` in place; returns the last stage's summary (its `max_change` is
/// `max |V(tau + dt) - V(tau)|`).
pub fn step(scheme: &Scheme<'_>, order: RkOrder, dt: f64, values: &mut Vec<f64>, work: &mut Workspace) -> StageSummary {
    let mut summary = StageSummary { max_change: 0.0, min_value: f64::INFINITY };
    for (k, &(a, b)) in order.stages().iter().enumerate() {
        let input: &[f64] = if k == 0 { values } else { &work.stage };
        summary = scheme.stage(input, values, Stage { a, b, dt }, &mut work.next);
        std::mem::swap(&mut work.stage, &mut work.next);
    }
    std::mem::swap(values, &mut work.stage);
    summary
}
