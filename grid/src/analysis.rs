//! What a solution says about tracking: `V_min` (the TEB), where it is attained, and the extent of the
//! error set `{V <= V_min + tol}` along each error coordinate.

use crate::solver::Solution;
use fastrack_valuefn::system::AffineSystem;
use serde::{Deserialize, Serialize};

/// Default relative tolerance of the error set: `{V <= V_min (1 + EXTENT_REL_TOL)}`.
pub const EXTENT_REL_TOL: f64 = 0.02;

/// The tracking error bound read off a grid solution.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Teb {
    /// `min V` over the grid nodes.
    pub v_min: f64,
    /// The node attaining it.
    pub argmin: Vec<f64>,
    /// Level used for the error set, `V_min (1 + rel_tol)`.
    pub set_level: f64,
    /// The relative tolerance of the set.
    pub rel_tol: f64,
    /// `max |e_i|` over nodes in `{V <= set_level}`, per error coordinate.
    pub extent: Vec<f64>,
    /// Nodes in the set.
    pub set_nodes: usize,
}

/// `V_min`, its argmin and the extent of `{V <= V_min (1 + rel_tol)}` (grid nodes only).
pub fn teb(solution: &Solution, system: &AffineSystem, rel_tol: f64) -> Teb {
    let grid = &solution.grid;
    let (best, v_min) =
        solution
            .values
            .iter()
            .copied()
            .enumerate()
            .fold((0, f64::INFINITY), |acc, (i, v)| if v < acc.1 { (i, v) } else { acc });
    let mut argmin = vec![0.0; grid.ndim()];
    grid.point(best, &mut argmin);
    let set_level = v_min * (1.0 + rel_tol);
    let mut extent = vec![0.0f64; system.error_coords.len()];
    let mut set_nodes = 0;
    let mut r = vec![0.0; grid.ndim()];
    for (flat, &v) in solution.values.iter().enumerate() {
        if v <= set_level {
            set_nodes += 1;
            grid.point(flat, &mut r);
            for (e, &i) in extent.iter_mut().zip(&system.error_coords) {
                *e = e.max(r[i].abs());
            }
        }
    }
    Teb { v_min, argmin, set_level, rel_tol, extent, set_nodes }
}
