//! Raw-path planners: what the online loop asks for a path around the sensed obstacles, inflated by the
//! sTEB, in the plane or in space. Any planner fits behind [`RawPathPlanner`]; the default is A* on a grid of
//! cells (squares or cubes) with the path shortened by line of sight.

use crate::geometry::{chebyshev_norm, clearance, inside, lerp, norm, segment_is_free, sub, Obstacle, Point};
use fastrack_proto::planner_speed::{SpeedRow, SpeedRule};
use std::cell::RefCell;
use std::collections::VecDeque;

/// What a planner is asked for.
#[derive(Debug)]
pub struct PlanRequest<'a, O, const D: usize> {
    /// Where the path starts: the planner's current state.
    pub start: Point<D>,
    /// Where it ends.
    pub goal: Point<D>,
    /// The obstacles sensed so far.
    pub obstacles: &'a [O],
    /// How far the path must keep from every obstacle (the sTEB radius).
    pub inflation: f64,
    /// The workspace, `(min, max)` corners: the path stays inside.
    pub bounds: (Point<D>, Point<D>),
    /// The TEB table the speed rule reads (slowest row first), for planners that plan for speed; others
    /// ignore it.
    pub speeds: &'a [SpeedRow],
    /// The rule that picks the speed along the path, for planners that plan for speed.
    pub rule: SpeedRule,
}

/// A path that cannot be planned (its points as lists of coordinates, whatever the dimension).
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum PlanError {
    /// The goal lies within the inflation of an obstacle or outside the workspace.
    #[error("the goal {goal:?} is not free: it lies within {inflation} m of an obstacle or outside the workspace")]
    GoalBlocked {
        /// The goal.
        goal: Vec<f64>,
        /// The inflation asked for.
        inflation: f64,
    },
    /// No path keeps the inflation from every obstacle.
    #[error("no path from {start:?} to {goal:?} keeps {inflation} m from every sensed obstacle")]
    NoPath {
        /// The start.
        start: Vec<f64>,
        /// The goal.
        goal: Vec<f64>,
        /// The inflation asked for.
        inflation: f64,
    },
    /// The planner's own settings are unusable.
    #[error("planner settings: {0}")]
    Settings(String),
}

/// Plans raw paths: a list of planner states from the request's start to its goal, every segment keeping
/// more than the inflation from every obstacle (the start may lie closer: the path leaves it).
pub trait RawPathPlanner<O: Obstacle<D>, const D: usize>: Send {
    /// A path from `request.start` to `request.goal`, both included.
    fn plan(&mut self, request: &PlanRequest<'_, O, D>) -> Result<Vec<Point<D>>, PlanError>;
}

/// A* over the cells of a grid of the workspace (each cell joined to every cell it touches, 8 in the plane
/// and 26 in space, at the length of the step), then shortened by line of sight: from each kept point, the
/// farthest later point whose segment is free.
#[derive(Debug, Clone, PartialEq)]
pub struct GridAStar {
    /// Cell size (m).
    pub cell: f64,
}

impl Default for GridAStar {
    fn default() -> Self {
        Self { cell: 0.1 }
    }
}

/// Most cells a side of the grid searched: cell indices and their neighbours stay far from overflow.
const MAX_CELLS_PER_SIDE: f64 = 1_048_576.0;

/// Grid costs are integers: micrometres.
const COST_SCALE: f64 = 1e6;

impl<O: Obstacle<D>, const D: usize> RawPathPlanner<O, D> for GridAStar {
    fn plan(&mut self, request: &PlanRequest<'_, O, D>) -> Result<Vec<Point<D>>, PlanError> {
        let grid = CellGrid::new(request, self.cell)?;
        let goal = grid.cell_of(request.goal);
        let points = grid.search(|a, b| grid.octile(a, b), |a| grid.octile(a, goal))?;
        Ok(shortcut(&points, request.obstacles, request.inflation))
    }
}

/// A cell of a [`CellGrid`]: its index along each axis.
pub(crate) type Cell<const D: usize> = [i64; D];

/// The grid one request is searched on: cells of the workspace, their centres, and the steps allowed
/// between neighbours (keeping the inflation, or leaving a start within it by gaining clearance).
pub(crate) struct CellGrid<'r, O, const D: usize> {
    request: &'r PlanRequest<'r, O, D>,
    cell: f64,
    /// Cells along each axis.
    counts: [i64; D],
    /// The offsets to the cells a cell touches.
    neighbours: Vec<[i64; D]>,
    /// The goal's cell.
    goal: Cell<D>,
    /// The clearance of each cell's centre met so far (NaN: not yet measured), when the grid holds at most
    /// [`MAX_REMEMBERED_CELLS`]: a search asks about every cell from each of its neighbours.
    clearances: Option<RefCell<Vec<f64>>>,
}

/// A cell a search expands: whether it is free (or the goal) and its clearance.
struct Leaving<const D: usize> {
    cell: Cell<D>,
    free: bool,
    clearance: f64,
}

/// Most cells whose clearances a grid remembers (32 MiB of them); a larger grid measures each time.
const MAX_REMEMBERED_CELLS: i64 = 1 << 22;

impl<'r, O: Obstacle<D>, const D: usize> CellGrid<'r, O, D> {
    /// The grid of `request` with cells of `cell` metres, after checking the settings and the goal.
    pub(crate) fn new(request: &'r PlanRequest<'r, O, D>, cell: f64) -> Result<Self, PlanError> {
        if !(cell.is_finite() && cell > 0.0) {
            return Err(PlanError::Settings(format!("cell = {cell}; must be a finite size > 0")));
        }
        let (lo, hi) = request.bounds;
        let span = |axis: usize| ((hi[axis] - lo[axis]) / cell).ceil();
        if !(0..D).all(|axis| span(axis) >= 0.0 && span(axis) <= MAX_CELLS_PER_SIDE) {
            return Err(PlanError::Settings(format!(
                "the bounds {lo:?}..{hi:?} span more than {MAX_CELLS_PER_SIDE} cells of {cell} m a side (or are not finite)"
            )));
        }
        // In lexicographic order, the first axis slowest: A* breaks ties by it.
        let neighbours = (0..3i64.pow(D as u32))
            .map(|k| std::array::from_fn(|axis| (k / 3i64.pow((D - 1 - axis) as u32)) % 3 - 1))
            .filter(|offset: &[i64; D]| offset.iter().any(|&o| o != 0))
            .collect();
        let counts: [i64; D] = std::array::from_fn(|axis| span(axis) as i64 + 1);
        let total = counts.iter().try_fold(1i64, |total, &n| total.checked_mul(n)).unwrap_or(i64::MAX);
        let mut grid = Self {
            request,
            cell,
            counts,
            neighbours,
            goal: [0; D],
            clearances: (total <= MAX_REMEMBERED_CELLS).then(|| RefCell::new(vec![f64::NAN; total as usize])),
        };
        grid.goal = grid.cell_of(request.goal);
        if !grid.free(request.goal) {
            return Err(PlanError::GoalBlocked { goal: request.goal.to_vec(), inflation: request.inflation });
        }
        Ok(grid)
    }

    /// The cell's centre.
    pub(crate) fn centre(&self, cell: Cell<D>) -> Point<D> {
        let lo = self.request.bounds.0;
        std::array::from_fn(|axis| lo[axis] + cell[axis] as f64 * self.cell)
    }

    /// The cell whose centre is nearest `p`.
    pub(crate) fn cell_of(&self, p: Point<D>) -> Cell<D> {
        let lo = self.request.bounds.0;
        std::array::from_fn(|axis| ((p[axis] - lo[axis]) / self.cell).round() as i64)
    }

    /// Inside the workspace.
    fn inside(&self, p: Point<D>) -> bool {
        inside(p, self.request.bounds)
    }

    /// Inside the workspace and farther than the inflation from every obstacle.
    fn free(&self, p: Point<D>) -> bool {
        self.inside(p) && clearance(self.request.obstacles, p) > self.request.inflation
    }

    /// The distance from the cell's centre to the nearest obstacle, measured once for a cell of the grid.
    pub(crate) fn cell_clearance(&self, c: Cell<D>) -> f64 {
        let measure = || clearance(self.request.obstacles, self.centre(c));
        let (Some(known), Some(index)) = (self.clearances.as_ref(), self.number(c)) else {
            return measure();
        };
        let index = index as usize;
        let mut known = known.borrow_mut();
        if known[index].is_nan() {
            known[index] = measure();
        }
        known[index]
    }

    /// The cell's number, the first axis slowest, if it lies on the grid.
    fn number(&self, c: Cell<D>) -> Option<u64> {
        self.on_grid(c).then(|| (0..D).fold(0, |number, axis| number * self.counts[axis] + c[axis]) as u64)
    }

    /// The cell numbered `number`.
    fn cell_numbered(&self, number: u64) -> Cell<D> {
        let mut rest = number as i64;
        let mut cell = [0; D];
        for axis in (0..D).rev() {
            cell[axis] = rest % self.counts[axis];
            rest /= self.counts[axis];
        }
        cell
    }

    /// The number of cells on the grid.
    fn cell_count(&self) -> u64 {
        self.counts.iter().map(|&n| n as u64).product()
    }

    /// Within the grid's cells.
    fn on_grid(&self, c: Cell<D>) -> bool {
        (0..D).all(|axis| c[axis] >= 0 && c[axis] < self.counts[axis])
    }

    /// The cell's centre is [`CellGrid::free`].
    fn cell_free(&self, c: Cell<D>) -> bool {
        self.inside(self.centre(c)) && self.cell_clearance(c) > self.request.inflation
    }

    /// What a search needs to know of the cell it expands, measured once for all the cell's neighbours.
    fn leaving(&self, a: Cell<D>) -> Leaving<D> {
        Leaving { cell: a, free: self.cell_free(a) || a == self.goal, clearance: self.cell_clearance(a) }
    }

    /// Whether the segment between the centres of the touching cells `from` and `b` (`b` at `b_clearance`)
    /// keeps more than `inflation` from every obstacle: at once when their clearances exceed it by half the
    /// segment (every point of it lies within that of an end, and a distance changes no faster than the
    /// point), else measured.
    fn step_keeps(&self, from: &Leaving<D>, b: Cell<D>, b_clearance: f64, inflation: f64) -> bool {
        let (from_centre, to) = (self.centre(from.cell), self.centre(b));
        from.clearance.min(b_clearance) - norm(sub(to, from_centre)) / 2.0 > inflation
            || segment_is_free(self.request.obstacles, from_centre, to, inflation)
    }

    /// Whether the step from cell `from` to its neighbour `b` is allowed: between free cells (or onto the
    /// goal) along a segment that keeps the inflation; from a cell within the inflation (the planner's cell
    /// rounded towards an obstacle, or a planner the map grew around), only a step that strictly gains
    /// clearance.
    fn step_free(&self, from: &Leaving<D>, b: Cell<D>) -> bool {
        if !self.on_grid(b) {
            return false;
        }
        let b_clearance = self.cell_clearance(b);
        let b_inside = self.inside(self.centre(b));
        let inflation = self.request.inflation;
        if from.free {
            (b_inside && b_clearance > inflation || b == self.goal) && self.step_keeps(from, b, b_clearance, inflation)
        } else {
            b_inside && b_clearance > from.clearance && self.step_keeps(from, b, b_clearance, from.clearance - 1e-9)
        }
    }

    /// The length of the shortest path of steps between touching cells from `a` to `b` (the octile distance
    /// in the plane), in integer cost units. With the axis gaps `g_0 >= g_1 >= ...`, it takes `g_k - g_(k+1)`
    /// steps along `k + 1` axes at once, of `sqrt(k + 1)` cells each: `g_0 + sum_k (sqrt(k + 1) - sqrt(k)) g_k`.
    pub(crate) fn octile(&self, a: Cell<D>, b: Cell<D>) -> u64 {
        let mut gaps: [f64; D] = std::array::from_fn(|axis| (a[axis] - b[axis]).abs() as f64);
        gaps.sort_by(|x, y| y.total_cmp(x));
        let diagonal: f64 = (1..D).map(|k| (((k + 1) as f64).sqrt() - (k as f64).sqrt()) * gaps[k]).sum();
        ((gaps[0] + diagonal) * self.cell * COST_SCALE) as u64
    }

    /// A* over the allowed steps, each costing `step_cost(a, b)`, with the admissible `heuristic`: the path
    /// of cell centres, its first point the request's start and its last the goal.
    pub(crate) fn search(
        &self,
        step_cost: impl Fn(Cell<D>, Cell<D>) -> u64,
        heuristic: impl Fn(Cell<D>) -> u64,
    ) -> Result<Vec<Point<D>>, PlanError> {
        let request = self.request;
        let (start, goal) = (self.cell_of(request.start), self.goal);
        // A start off the grid (a planner just outside the workspace) takes the number after the grid's.
        let off_grid = self.cell_count();
        let number = |c: Cell<D>| self.number(c).unwrap_or(off_grid);
        let cell = |number: u64| if number == off_grid { start } else { self.cell_numbered(number) };
        let successors = |from: u64, next: &mut Vec<(u64, u64)>| {
            let a = cell(from);
            let leaving = self.leaving(a);
            for offset in &self.neighbours {
                let b = std::array::from_fn(|axis| a[axis] + offset[axis]);
                if self.step_free(&leaving, b) {
                    next.push((number(b), step_cost(a, b)));
                }
            }
        };
        let no_path = || PlanError::NoPath {
            start: request.start.to_vec(),
            goal: request.goal.to_vec(),
            inflation: request.inflation,
        };
        let numbers =
            crate::cell_astar::astar(off_grid + 1, number(start), number(goal), successors, |n| heuristic(cell(n)))
                .ok_or_else(no_path)?;
        let cells: Vec<Cell<D>> = numbers.into_iter().map(cell).collect();
        let mut points: Vec<Point<D>> = cells.iter().map(|&c| self.centre(c)).collect();
        points[0] = request.start;
        *points.last_mut().expect("a path holds its goal") = request.goal;
        Ok(points)
    }
}

/// The path shortened by line of sight: from each kept point, the farthest later point whose segment keeps
/// the inflation from every obstacle (the next point always qualifies, as the path's segments do).
pub fn shortcut<O: Obstacle<D>, const D: usize>(points: &[Point<D>], obstacles: &[O], inflation: f64) -> Vec<Point<D>> {
    let mut kept = vec![points[0]];
    let mut i = 0;
    while i + 1 < points.len() {
        let j = (i + 1..points.len())
            .rev()
            .find(|&j| j == i + 1 || segment_is_free(obstacles, points[i], points[j], inflation))
            .unwrap_or(i + 1);
        kept.push(points[j]);
        i = j;
    }
    kept
}

/// Moves a planner at `p` along `path` (the states ahead of it, consumed as they are reached) for one
/// control period at per-axis speed at most `beta`, where `budget = beta dt`: a segment of direction `d` is
/// crossed at speed `beta / max_i |d_i|`, so no axis moves more than `budget`. Returns the new state (the
/// last one when the path runs out).
pub fn advance_along<const D: usize>(p: Point<D>, path: &mut VecDeque<Point<D>>, budget: f64) -> Point<D> {
    let (mut p, mut remaining) = (p, budget);
    while let Some(&next) = path.front() {
        let per_axis = chebyshev_norm(sub(next, p));
        if per_axis <= remaining {
            remaining -= per_axis;
            p = next;
            path.pop_front();
        } else {
            return lerp(p, next, remaining / per_axis);
        }
    }
    p
}

/// The length of a path.
pub fn path_length<const D: usize>(points: &[Point<D>]) -> f64 {
    points.windows(2).map(|w| norm(sub(w[1], w[0]))).sum()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::{clearance, segment_is_free, PlaneObstacle, SpaceObstacle};

    fn request<'a>(obstacles: &'a [PlaneObstacle], inflation: f64) -> PlanRequest<'a, PlaneObstacle, 2> {
        PlanRequest {
            start: [0.0, 0.0],
            goal: [10.0, 0.0],
            obstacles,
            inflation,
            bounds: ([-1.0, -6.0], [11.0, 6.0]),
            speeds: &[],
            rule: SpeedRule::HalfDistance,
        }
    }

    #[test]
    fn an_open_plane_gives_the_straight_line() {
        let path = GridAStar::default().plan(&request(&[], 0.5)).unwrap();
        assert_eq!(path, vec![[0.0, 0.0], [10.0, 0.0]]);
    }

    #[test]
    fn a_grid_too_large_to_remember_its_clearances_plans_the_same_path() {
        // The same lattice (same lower corner and cell) in a workspace of 5.2 million cells and in one of
        // 14,400: the large grid measures every clearance afresh, the small one remembers them.
        let obstacles = [PlaneObstacle::Circle { center: [5.0, 0.3], radius: 1.0 }];
        let small = GridAStar::default().plan(&request(&obstacles, 0.5)).unwrap();
        let wide = PlanRequest { bounds: ([-1.0, -6.0], [250.0, 200.0]), ..request(&obstacles, 0.5) };
        assert!(CellGrid::new(&wide, 0.1).unwrap().clearances.is_none());
        assert!(CellGrid::new(&request(&obstacles, 0.5), 0.1).unwrap().clearances.is_some());
        assert_eq!(GridAStar::default().plan(&wide).unwrap(), small);
    }

    #[test]
    fn the_path_goes_around_an_obstacle_keeping_the_inflation() {
        let obstacles = [PlaneObstacle::Circle { center: [5.0, 0.0], radius: 1.0 }];
        let path = GridAStar::default().plan(&request(&obstacles, 0.5)).unwrap();
        for segment in path.windows(2) {
            assert!(segment_is_free(&obstacles, segment[0], segment[1], 0.5), "{segment:?} cuts the inflated disc");
        }
        // Longer than the straight line, shorter than a wide detour (half a circle of radius 2: 6.3 + 6).
        let length = path_length(&path);
        assert!(length > 10.0 && length < 12.3, "length {length}: {path:?}");
    }

    #[test]
    fn advancing_moves_no_axis_more_than_the_budget() {
        let mut path: VecDeque<Point> = [[1.0, 0.0], [1.0, 2.0]].into();
        // 0.5 along x first.
        assert_eq!(advance_along([0.0, 0.0], &mut path, 0.5), [0.5, 0.0]);
        // Across the corner: 0.5 to reach it, 0.25 up the next segment.
        let p = advance_along([0.5, 0.0], &mut path, 0.75);
        assert_eq!((p, path.len()), ([1.0, 0.25], 1));
        // A diagonal segment: both axes at the budget.
        let mut diagonal: VecDeque<Point> = [[2.0, 2.0]].into();
        assert_eq!(advance_along([0.0, 0.0], &mut diagonal, 0.5), [0.5, 0.5]);
        // The end of the path is where the planner stops.
        let mut short: VecDeque<Point> = [[0.1, 0.0]].into();
        assert_eq!((advance_along([0.0, 0.0], &mut short, 1.0), short.len()), ([0.1, 0.0], 0));
    }

    #[test]
    fn a_start_within_the_inflation_is_left_by_gaining_clearance() {
        // The start lies 0.3 m from the disc, inside the 0.5 m inflation: the path leaves it, never closing in.
        let obstacles = [PlaneObstacle::Circle { center: [0.0, -1.3], radius: 1.0 }];
        let path = GridAStar::default().plan(&request(&obstacles, 0.5)).unwrap();
        assert_eq!(path[0], [0.0, 0.0]);
        let closest = path.windows(2).map(|w| obstacles[0].segment_distance(w[0], w[1])).fold(f64::INFINITY, f64::min);
        assert!(closest >= 0.3 - 1e-9, "the path closes in on the obstacle: {closest} ({path:?})");
        let escaped = path.iter().position(|&p| clearance(&obstacles, p) > 0.5).expect("the path leaves the inflation");
        for segment in path[escaped..].windows(2) {
            assert!(segment_is_free(&obstacles, segment[0], segment[1], 0.5), "{segment:?} after the escape");
        }
    }

    #[test]
    fn a_start_just_outside_the_workspace_steps_in_away_from_an_obstacle() {
        // The start's cell lies one cell left of the grid; a disc beyond it makes the step in a gain in
        // clearance, so the path enters the grid and goes on to the goal.
        let obstacles = [PlaneObstacle::Circle { center: [-5.0, 0.0], radius: 1.0 }];
        let outside = PlanRequest { start: [-1.1, 0.0], ..request(&obstacles, 0.5) };
        let path = GridAStar::default().plan(&outside).unwrap();
        assert_eq!((path[0], *path.last().unwrap()), ([-1.1, 0.0], [10.0, 0.0]));
        assert!(path[1..].iter().all(|&p| inside(p, outside.bounds)), "{path:?}");
    }

    #[test]
    fn a_wall_across_the_workspace_or_a_blocked_goal_is_reported() {
        let wall = [PlaneObstacle::Wall { from: [5.0, -7.0], to: [5.0, 7.0], thickness: 0.2 }];
        assert!(matches!(GridAStar::default().plan(&request(&wall, 0.3)), Err(PlanError::NoPath { .. })));
        let on_goal = [PlaneObstacle::Circle { center: [10.0, 0.2], radius: 0.5 }];
        assert!(matches!(GridAStar::default().plan(&request(&on_goal, 0.3)), Err(PlanError::GoalBlocked { .. })));
        assert!(matches!(GridAStar { cell: 0.0 }.plan(&request(&[], 0.3)), Err(PlanError::Settings(_))));
    }

    #[test]
    fn in_space_the_path_climbs_over_a_low_block_keeping_the_inflation() {
        // A block 6 m wide and 1.5 m high across the straight line: over it is shorter than around it.
        let obstacles = [
            SpaceObstacle::Box { min: [4.0, -3.0, -1.0], max: [6.0, 3.0, 1.5] },
            SpaceObstacle::Floor { height: -1.0 },
        ];
        let request = PlanRequest {
            start: [0.0, 0.0, 0.5],
            goal: [10.0, 0.0, 0.5],
            obstacles: &obstacles,
            inflation: 0.3,
            bounds: ([-1.0, -4.0, -0.5], [11.0, 4.0, 3.0]),
            speeds: &[],
            rule: SpeedRule::HalfDistance,
        };
        let path = GridAStar { cell: 0.25 }.plan(&request).unwrap();
        assert_eq!((path[0], *path.last().unwrap()), (request.start, request.goal));
        for segment in path.windows(2) {
            assert!(segment_is_free(&obstacles, segment[0], segment[1], 0.3), "{segment:?} cuts the inflated block");
        }
        let top = path.iter().map(|p| p[2]).fold(f64::NEG_INFINITY, f64::max);
        assert!(top > 1.8, "the path does not go over the block: {path:?}");
        // Over the top: at least 10 m plus the climb of 1.3 m each way; around a side: more than 14 m.
        let length = path_length(&path);
        assert!(length > 10.3 && length < 13.0, "length {length}: {path:?}");
    }

    #[test]
    fn bounds_past_the_grid_s_reach_are_refused_not_overflowed() {
        for hi in [[1e300, 6.0], [f64::INFINITY, 6.0], [11.0, 2e5]] {
            let far = PlanRequest { bounds: ([-1.0, -6.0], hi), ..request(&[], 0.3) };
            let Err(PlanError::Settings(why)) = GridAStar::default().plan(&far) else { panic!("{hi:?} was planned") };
            assert!(why.contains("cells of 0.1 m a side"), "{why}");
        }
    }
}
