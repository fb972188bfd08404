//! A raw-path planner that plans for speed: the cost of a path is its travel time when the planner moves at
//! the speed the rule will allow there.
//!
//! The online loop sets `beta` by queryPlannerControl: the largest table `beta` whose bound fits half the
//! distance to the nearest sensed obstacle. The shortest path hugs the inflated obstacles, where that rule
//! allows little more than `beta_l`; a path a few metres longer through open space may be travelled at
//! `beta_u`. So a step between two cells costs its duration at the speed the rule gives at the lower
//! clearance of its two ends (the tracker sits near the planner, so its distance to the obstacles is about
//! the planner's clearance), and the planner's per-axis speed bound makes that duration the step's larger
//! axis displacement over `beta`. The sTEB inflation stays a hard constraint, as for [`GridAStar`]: only the
//! cost differs. The path is shortened by line of sight only where the shortcut is no slower.
//!
//! [`GridAStar`]: crate::raw_path::GridAStar

use crate::geometry::{chebyshev_norm, clearance, lerp, segment_is_free, sub, Obstacle, Point};
use crate::raw_path::{Cell, CellGrid, PlanError, PlanRequest, RawPathPlanner};
use fastrack_proto::planner_speed::{SpeedRow, SpeedRule};
use rustc_hash::FxHashMap;
use std::cell::RefCell;

/// A* on a grid of the workspace whose step cost is the step's duration at the speed the rule allows there;
/// needs the request's TEB table ([`PlanRequest::speeds`]).
#[derive(Debug, Clone, PartialEq)]
pub struct FastestPath {
    /// Cell size (m).
    pub cell: f64,
}

impl Default for FastestPath {
    fn default() -> Self {
        Self { cell: 0.1 }
    }
}

/// Durations are integers: microseconds.
const TIME_SCALE: f64 = 1e6;

impl<O: Obstacle<D>, const D: usize> RawPathPlanner<O, D> for FastestPath {
    fn plan(&mut self, request: &PlanRequest<'_, O, D>) -> Result<Vec<Point<D>>, PlanError> {
        let beta_u = match request.speeds.last() {
            Some(row) if request.speeds.iter().all(|row| row.beta.is_finite() && row.beta > 0.0) => row.beta,
            _ => return Err(PlanError::Settings("the fastest path needs the TEB table's rows, each beta > 0".into())),
        };
        let grid = CellGrid::new(request, self.cell)?;
        let speed = SpeedMap {
            obstacles: request.obstacles,
            speeds: request.speeds,
            rule: request.rule,
            known: RefCell::default(),
        };
        let cell_speed = |c: Cell<D>| speed.at_clearance(grid.cell_clearance(c));
        let seconds =
            |a: Cell<D>, b: Cell<D>| chebyshev(grid.centre(a), grid.centre(b)) / cell_speed(a).min(cell_speed(b));
        let goal = grid.cell_of(request.goal);
        let points = grid.search(
            |a: Cell<D>, b: Cell<D>| (seconds(a, b) * TIME_SCALE) as u64,
            |a: Cell<D>| (chebyshev(grid.centre(a), grid.centre(goal)) / beta_u * TIME_SCALE) as u64,
        )?;
        Ok(shortcut_in_time(&points, request, |a, b| segment_seconds(a, b, self.cell, &speed)))
    }
}

/// The speed the rule allows at a point, by the point's clearance, remembered per point.
struct SpeedMap<'a, O, const D: usize> {
    obstacles: &'a [O],
    speeds: &'a [SpeedRow],
    rule: SpeedRule,
    known: RefCell<FxHashMap<[u64; D], f64>>,
}

impl<O: Obstacle<D>, const D: usize> SpeedMap<'_, O, D> {
    /// The rule's `beta` at the point's clearance.
    fn at(&self, p: Point<D>) -> f64 {
        *self
            .known
            .borrow_mut()
            .entry(p.map(f64::to_bits))
            .or_insert_with(|| self.at_clearance(clearance(self.obstacles, p)))
    }

    /// The rule's `beta` at a point `gap` from the nearest obstacle (any, with none sensed: the fastest).
    fn at_clearance(&self, gap: f64) -> f64 {
        self.rule.at_clearance(self.speeds, (!self.obstacles.is_empty()).then_some(gap)).beta
    }
}

/// The larger axis displacement from `a` to `b`: a planner bounded to `beta` per axis needs this over
/// `beta` seconds.
fn chebyshev<const D: usize>(a: Point<D>, b: Point<D>) -> f64 {
    chebyshev_norm(sub(b, a))
}

/// Seconds to cross the segment `a`-`b` in pieces of about `cell`, each at the rule's speed at its slower
/// end.
fn segment_seconds<O: Obstacle<D>, const D: usize>(
    a: Point<D>,
    b: Point<D>,
    cell: f64,
    speed: &SpeedMap<'_, O, D>,
) -> f64 {
    let pieces = (chebyshev(a, b) / cell).ceil().max(1.0) as usize;
    let at = |k: usize| lerp(a, b, k as f64 / pieces as f64);
    (0..pieces).map(|k| chebyshev(at(k), at(k + 1)) / speed.at(at(k)).min(speed.at(at(k + 1)))).sum()
}

/// The path shortened by line of sight where it is no slower: from each kept point, the farthest later
/// point whose segment keeps the inflation and takes no longer than the path between them.
fn shortcut_in_time<O: Obstacle<D>, const D: usize>(
    points: &[Point<D>],
    request: &PlanRequest<'_, O, D>,
    seconds: impl Fn(Point<D>, Point<D>) -> f64,
) -> Vec<Point<D>> {
    // Seconds from the first point to each point along the path.
    let elapsed: Vec<f64> = std::iter::once(0.0)
        .chain(points.windows(2).scan(0.0, |total, w| {
            *total += seconds(w[0], w[1]);
            Some(*total)
        }))
        .collect();
    let mut kept = vec![points[0]];
    let mut i = 0;
    while i + 1 < points.len() {
        let j = (i + 2..points.len())
            .rev()
            .find(|&j| {
                segment_is_free(request.obstacles, points[i], points[j], request.inflation)
                    && seconds(points[i], points[j]) <= elapsed[j] - elapsed[i] + 1e-9
            })
            .unwrap_or(i + 1);
        kept.push(points[j]);
        i = j;
    }
    kept
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::PlaneObstacle;
    use crate::raw_path::{path_length, GridAStar};

    /// beta 0.5 / 1.0 / 1.5 with bounds 0.3 / 1.0 / 2.0: full speed needs 4 m of clearance.
    fn table() -> Vec<SpeedRow> {
        [(0.5, 0.3), (1.0, 1.0), (1.5, 2.0)].map(|(beta, bound)| SpeedRow { beta, bound }).to_vec()
    }

    fn request<'a>(obstacles: &'a [PlaneObstacle], speeds: &'a [SpeedRow]) -> PlanRequest<'a, PlaneObstacle, 2> {
        PlanRequest {
            start: [0.0, 0.0],
            goal: [20.0, 0.0],
            obstacles,
            inflation: 0.3,
            bounds: ([-1.0, -12.0], [21.0, 12.0]),
            speeds,
            rule: SpeedRule::HalfDistance,
        }
    }

    /// Seconds along `path` at the rule's speed, finely sampled.
    fn travel_seconds(path: &[Point], request: &PlanRequest<'_, PlaneObstacle, 2>) -> f64 {
        let speed = SpeedMap {
            obstacles: request.obstacles,
            speeds: request.speeds,
            rule: request.rule,
            known: RefCell::default(),
        };
        path.windows(2).map(|w| segment_seconds(w[0], w[1], 0.01, &speed)).sum()
    }

    #[test]
    fn with_nothing_sensed_the_path_is_the_straight_line() {
        let speeds = table();
        let path = FastestPath::default().plan(&request(&[], &speeds)).unwrap();
        assert_eq!(path, vec![[0.0, 0.0], [20.0, 0.0]]);
    }

    #[test]
    fn a_corridor_between_walls_is_left_for_open_space_when_that_is_faster() {
        // Two long walls 1.6 m apart along the straight line: inside, the clearance is at most 0.8 m and the
        // rule allows beta_l; a detour 3-4 m around their ends is crossed at beta_u.
        let walls = [
            PlaneObstacle::Rectangle { min: [4.0, 0.8], max: [16.0, 1.0] },
            PlaneObstacle::Rectangle { min: [4.0, -1.0], max: [16.0, -0.8] },
        ];
        let speeds = table();
        let request = request(&walls, &speeds);
        let shortest = GridAStar::default().plan(&request).unwrap();
        let fastest = FastestPath::default().plan(&request).unwrap();
        let (t_shortest, t_fastest) = (travel_seconds(&shortest, &request), travel_seconds(&fastest, &request));
        assert!(path_length(&fastest) > path_length(&shortest) + 1.0, "no detour: {fastest:?}");
        assert!(t_fastest < 0.8 * t_shortest, "fastest {t_fastest:.2} s against shortest {t_shortest:.2} s");
        for segment in fastest.windows(2) {
            assert!(segment_is_free(&walls, segment[0], segment[1], 0.3), "{segment:?} cuts the inflation");
        }
    }

    #[test]
    fn the_planner_rule_prices_a_corridor_at_the_bounds_that_fit_its_clearance() {
        // Walls 4.4 m apart: 2.2 m of clearance on the centre line. The paper's rule fits bounds up to 1.1 m
        // there (beta 1.0), the planner rule bounds below 2.2 m (beta 1.5).
        let walls = [
            PlaneObstacle::Rectangle { min: [-2.0, 2.2], max: [22.0, 2.4] },
            PlaneObstacle::Rectangle { min: [-2.0, -2.4], max: [22.0, -2.2] },
        ];
        let speeds = table();
        let half = request(&walls, &speeds);
        let planner = PlanRequest { rule: SpeedRule::Planner, ..request(&walls, &speeds) };
        let straight = [[0.0, 0.0], [20.0, 0.0]];
        assert!((travel_seconds(&straight, &half) - 20.0).abs() < 1e-6);
        assert!((travel_seconds(&straight, &planner) - 20.0 / 1.5).abs() < 1e-6);
        assert_eq!(FastestPath::default().plan(&planner).unwrap(), straight.to_vec());
    }

    #[test]
    fn where_the_detour_costs_more_than_it_gains_the_path_goes_through() {
        // A short gap (2 m of walls) costs less at beta_l than a detour around walls 20 m long.
        let walls = [
            PlaneObstacle::Rectangle { min: [9.0, 0.8], max: [11.0, 11.0] },
            PlaneObstacle::Rectangle { min: [9.0, -11.0], max: [11.0, -0.8] },
        ];
        let speeds = table();
        let request = request(&walls, &speeds);
        let fastest = FastestPath::default().plan(&request).unwrap();
        assert!(fastest.iter().all(|p| p[1].abs() < 1.0), "the path left the gap: {fastest:?}");
        let shortest = GridAStar::default().plan(&request).unwrap();
        assert!(travel_seconds(&fastest, &request) <= travel_seconds(&shortest, &request) + 1e-6);
    }

    #[test]
    fn in_space_it_climbs_away_from_the_floor_where_that_is_faster() {
        // 1 m above the floor the rule allows beta_l (bound 0.3 fits half of 1 m); 4 m up, between the floor
        // and a ceiling at 8 m, beta_u. The shortest path stays low; the fastest climbs.
        use crate::geometry::SpaceObstacle;
        let solids = [SpaceObstacle::Floor { height: 0.0 }, SpaceObstacle::Ceiling { height: 8.0 }];
        let speeds = table();
        let request = PlanRequest {
            start: [0.0, 0.0, 1.0],
            goal: [20.0, 0.0, 1.0],
            obstacles: &solids,
            inflation: 0.3,
            bounds: ([-1.0, -3.0, 0.0], [21.0, 3.0, 8.0]),
            speeds: &speeds,
            rule: SpeedRule::HalfDistance,
        };
        let seconds = |path: &[Point<3>]| {
            let speed =
                SpeedMap { obstacles: &solids[..], speeds: &speeds, rule: request.rule, known: RefCell::default() };
            path.windows(2).map(|w| segment_seconds(w[0], w[1], 0.01, &speed)).sum::<f64>()
        };
        let shortest = GridAStar { cell: 0.25 }.plan(&request).unwrap();
        let fastest = FastestPath { cell: 0.25 }.plan(&request).unwrap();
        assert!(shortest.iter().all(|p| (p[2] - 1.0).abs() < 1e-9), "the shortest path stays low: {shortest:?}");
        assert!(fastest.iter().any(|p| p[2] > 3.0), "the fastest path did not climb: {fastest:?}");
        assert!(
            seconds(&fastest) < 0.6 * seconds(&shortest),
            "{} s against {} s",
            seconds(&fastest),
            seconds(&shortest)
        );
        for segment in fastest.windows(2) {
            assert!(segment_is_free(&solids, segment[0], segment[1], 0.3), "{segment:?} cuts the inflation");
        }
    }

    #[test]
    fn without_a_table_or_with_a_blocked_goal_it_says_why() {
        assert!(matches!(FastestPath::default().plan(&request(&[], &[])), Err(PlanError::Settings(_))));
        let on_goal = [PlaneObstacle::Circle { center: [20.0, 0.1], radius: 0.5 }];
        let speeds = table();
        assert!(matches!(FastestPath::default().plan(&request(&on_goal, &speeds)), Err(PlanError::GoalBlocked { .. })));
    }
}
