//! Total-variation-diminishing Runge-Kutta time integration (Shu & Osher) of order 1, 2 and 3.

use crate::scheme::{Scheme, Stage, StageSummary};
pub use fastrack_gridfile::settings::{RkOrder, UnknownOrder};

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

/// Stage weights `(a, b)` of `out = a * u_n + b * (v + dt L(v))`, `v` the previous stage.
fn stages(order: RkOrder) -> &'static [(f64, f64)] {
    match order {
        RkOrder::One => &[(0.0, 1.0)],
        RkOrder::Two => &[(0.0, 1.0), (0.5, 0.5)],
        RkOrder::Three => &[(0.0, 1.0), (0.75, 0.25), (1.0 / 3.0, 2.0 / 3.0)],
    }
}

/// Advances `values` by one step `dt` in place; returns the last stage's summary (its `max_change` is
/// `max |V(tau + dt) - V(tau)|`).
pub fn step(scheme: &Scheme<'_>, order: RkOrder, dt: f64, values: &mut Vec<f64>, work: &mut Workspace) -> StageSummary {
    let mut summary = StageSummary { max_change: 0.0, min_value: f64::INFINITY };
    for (k, &(a, b)) in stages(order).iter().enumerate() {
        let input: &[f64] = if k == 0 { values } else { &work.stage };
        summary = scheme.stage(input, values, Stage { a, b, dt }, &mut work.next);
        std::mem::swap(&mut work.stage, &mut work.next);
    }
    std::mem::swap(values, &mut work.stage);
    summary
}
