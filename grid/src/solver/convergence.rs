//! How fast a solution still changes, by region: per step and over windows of horizon. The solver's
//! convergence test reads these rates, and every history point records them.

use crate::grid::Grid;
use fastrack_gridfile::settings::ConvergenceSet;
use fastrack_gridfile::solution::{RegionRates, WindowRates};
use rayon::prelude::*;

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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::grid::Axis;

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
}
