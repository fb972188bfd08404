//! A* over the cells of a bounded grid, each cell known by its number `0..cells`. The best cost found to
//! each cell and the cell it came from are kept in arrays when the grid is small enough (a search on a grid
//! touches a large share of its cells, so hashing each one costs more than the arrays), else in a hash map.
//!
//! The open cells wait in a binary heap, lowest estimate first and, among equal estimates, the higher cost
//! first; a cell reached again at a lower cost is pushed again and its older entry skipped when popped.

use rustc_hash::FxHashMap;
use std::cmp::Ordering;
use std::collections::BinaryHeap;

/// Grids of at most this many cells keep their costs and parents in arrays (12 bytes a cell: 48 MiB here).
const MAX_ARRAY_CELLS: u64 = 1 << 22;

/// The cells' numbers along the cheapest path from `start` to `goal`, both included, or `None` if no
/// path joins them. `successors(cell, out)` pushes each cell one step from `cell` with the step's cost;
/// `heuristic(cell)` never exceeds the cost from `cell` to `goal`.
pub(crate) fn astar(
    cells: u64,
    start: u64,
    goal: u64,
    mut successors: impl FnMut(u64, &mut Vec<(u64, u64)>),
    mut heuristic: impl FnMut(u64) -> u64,
) -> Option<Vec<u64>> {
    let mut reached = Reached::new(cells);
    reached.set(start, 0, start);
    let mut open = BinaryHeap::from([Open { estimate: 0, cost: 0, cell: start }]);
    let mut next = Vec::new();
    while let Some(Open { cost, cell, .. }) = open.pop() {
        if cell == goal {
            return Some(reached.path(start, goal));
        }
        if cost > reached.cost(cell) {
            continue;
        }
        next.clear();
        successors(cell, &mut next);
        for &(successor, step) in &next {
            let cost = cost + step;
            if reached.cost(successor) > cost {
                reached.set(successor, cost, cell);
                open.push(Open { estimate: cost + heuristic(successor), cost, cell: successor });
            }
        }
    }
    None
}

/// A cell waiting in the open heap: its cost so far and that plus the heuristic.
struct Open {
    estimate: u64,
    cost: u64,
    cell: u64,
}

impl Ord for Open {
    /// The heap's greatest is the lowest estimate, and among equal estimates the higher cost (the deeper
    /// cell); the cell's number takes no part.
    fn cmp(&self, other: &Self) -> Ordering {
        other.estimate.cmp(&self.estimate).then(self.cost.cmp(&other.cost))
    }
}

impl PartialOrd for Open {
    fn partial_cmp(&self, other: &Self) -> Option<Ordering> {
        Some(self.cmp(other))
    }
}

impl PartialEq for Open {
    fn eq(&self, other: &Self) -> bool {
        self.cmp(other) == Ordering::Equal
    }
}

impl Eq for Open {}

/// The best cost found to each cell and the cell it came from.
enum Reached {
    /// By cell number; `u64::MAX` where not reached.
    Arrays { cost: Vec<u64>, parent: Vec<u32> },
    /// Cell number -> (cost, parent).
    Map(FxHashMap<u64, (u64, u64)>),
}

impl Reached {
    fn new(cells: u64) -> Self {
        if cells <= MAX_ARRAY_CELLS {
            Self::Arrays { cost: vec![u64::MAX; cells as usize], parent: vec![0; cells as usize] }
        } else {
            Self::Map(FxHashMap::default())
        }
    }

    /// The best cost found to `cell` (`u64::MAX` if none).
    fn cost(&self, cell: u64) -> u64 {
        match self {
            Self::Arrays { cost, .. } => cost[cell as usize],
            Self::Map(map) => map.get(&cell).map_or(u64::MAX, |&(cost, _)| cost),
        }
    }

    fn set(&mut self, cell: u64, to: u64, from: u64) {
        match self {
            Self::Arrays { cost, parent } => {
                cost[cell as usize] = to;
                // Within MAX_ARRAY_CELLS, so a cell's number fits.
                parent[cell as usize] = from as u32;
            }
            Self::Map(map) => {
                map.insert(cell, (to, from));
            }
        }
    }

    fn parent(&self, cell: u64) -> u64 {
        match self {
            Self::Arrays { parent, .. } => u64::from(parent[cell as usize]),
            Self::Map(map) => map[&cell].1,
        }
    }

    /// The cells from `start` to `goal` by their parents.
    fn path(&self, start: u64, goal: u64) -> Vec<u64> {
        let mut path = vec![goal];
        while let Some(&cell) = path.last().filter(|&&cell| cell != start) {
            path.push(self.parent(cell));
        }
        path.reverse();
        path
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A line of `n` cells, each joined to its neighbours at cost 10, with a shortcut 0 -> `n - 1` of `long`.
    fn line(n: u64, long: u64) -> impl FnMut(u64, &mut Vec<(u64, u64)>) {
        move |cell, out| {
            if cell > 0 {
                out.push((cell - 1, 10));
            }
            if cell + 1 < n {
                out.push((cell + 1, 10));
            }
            if cell == 0 {
                out.push((n - 1, long));
            }
        }
    }

    #[test]
    fn the_cheaper_of_two_routes_is_taken_in_arrays_and_in_the_map() {
        for cells in [6, MAX_ARRAY_CELLS + 1] {
            // Along the line: 5 steps of 10. The shortcut costs 60 in one case and 40 in the other.
            let (n, goal) = (6, 5);
            let walked = astar(cells, 0, goal, line(n, 60), |_| 0).unwrap();
            assert_eq!(walked, vec![0, 1, 2, 3, 4, 5], "{cells} cells");
            let jumped = astar(cells, 0, goal, line(n, 40), |cell| (goal - cell) * 5).unwrap();
            assert_eq!(jumped, vec![0, 5], "{cells} cells");
        }
    }

    #[test]
    fn a_goal_no_step_reaches_gives_none_and_the_start_its_own_path() {
        let cut = |cell: u64, out: &mut Vec<(u64, u64)>| {
            if cell < 2 {
                out.push((cell + 1, 1));
            }
        };
        assert_eq!(astar(5, 0, 4, cut, |_| 0), None);
        assert_eq!(astar(5, 3, 3, cut, |_| 0), Some(vec![3]));
    }

    #[test]
    fn a_cell_reached_again_more_cheaply_takes_the_cheaper_parent() {
        // 0 -> 2 directly costs 10; 0 -> 1 -> 2 costs 2 + 2, but 1 is opened after 2 (its estimate is higher).
        let steps = |cell: u64, out: &mut Vec<(u64, u64)>| match cell {
            0 => out.extend([(2, 10), (1, 2)]),
            1 => out.push((2, 2)),
            2 => out.push((3, 1)),
            _ => {}
        };
        assert_eq!(astar(4, 0, 3, steps, |_| 0), Some(vec![0, 1, 2, 3]));
    }
}
