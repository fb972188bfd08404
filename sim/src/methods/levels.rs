//! FaSTrack at fixed planner speeds: one level (classic FaSTrack, obstacles inflated by that row's bound), or
//! several (Meta-FaSTrack, after Fridovich-Keil et al., ICRA 2018): at every replan the fastest level whose
//! inflated map admits a path is chosen (or, choosing the quickest, the level whose path takes the least time
//! at its speed, a shorter path at a slower level beating a detour at a faster one); a faster level is taken at once (its bound contains the slower
//! one's), a slower one only once the relative state lies inside that level's bound, the planner holding
//! still until then. The control comes from the backend (`TrackingControl`) at the level's `beta`; checking
//! a pending switch and reading the control share one call.

use super::{Context, Decision, MethodError, TimedPlanner};
use crate::world::{feasibility_cell, WorldObstacle};
use fastrack_online::core::Answer;
use fastrack_online::geometry::{chebyshev_norm, clearance, remember, sub, Point};
use fastrack_online::raw_path::{advance_along, GridAStar, PlanError, PlanRequest, RawPathPlanner};
use fastrack_proto::planner_speed::{SpeedRow, SpeedRule};
use std::collections::VecDeque;

/// FaSTrack over fixed levels, running.
pub struct LevelPlanner<O, const D: usize> {
    context: Context<O, D>,
    /// The levels, slowest first: table rows.
    levels: Vec<SpeedRow>,
    /// The level in use.
    current: usize,
    /// A slower level waiting for the tracker to enter its bound, with its path.
    pending: Option<(usize, VecDeque<Point<D>>)>,
    planner: Point<D>,
    path: VecDeque<Point<D>>,
    obstacles: Vec<O>,
    replan: bool,
    path_planner: TimedPlanner<O, D>,
    /// Choose the level by its path's travel time, not by its speed.
    quickest: bool,
}

impl<O: WorldObstacle<D>, const D: usize> LevelPlanner<O, D> {
    /// The levels `rows` (indices into the model's table, slowest first) with the planner at `start`; the
    /// fastest level first; `quickest` chooses each replan's level by its path's travel time. A* runs on
    /// cells of the world's feasibility grid (0.1 m squares, 0.25 m cubes).
    pub fn new(context: Context<O, D>, rows: Vec<usize>, start: Point<D>, quickest: bool) -> Self {
        let levels: Vec<SpeedRow> = rows.iter().map(|&i| context.speeds[i]).collect();
        Self {
            current: levels.len() - 1,
            levels,
            context,
            pending: None,
            planner: start,
            path: VecDeque::new(),
            obstacles: Vec::new(),
            replan: true,
            path_planner: TimedPlanner::new(Box::new(GridAStar { cell: feasibility_cell::<D>() })),
            quickest,
        }
    }

    /// The raw path ahead of the planner.
    pub fn raw_path(&self) -> Vec<Point<D>> {
        self.path.iter().copied().collect()
    }

    /// A path at `level`'s inflation from the planner's state. FaSTrack's guarantee needs the planner itself
    /// farther than the level's bound from every obstacle (the tracker may lie anywhere within the bound of
    /// it); a planner closer than that (at a start in clutter, or beside an obstacle sensed late) has no
    /// path at this level, though the path planner could lead it out.
    fn plan(&mut self, level: usize) -> Result<VecDeque<Point<D>>, PlanError> {
        let inflation = self.levels[level].bound;
        if clearance(&self.obstacles, self.planner) <= inflation {
            return Err(PlanError::NoPath {
                start: self.planner.to_vec(),
                goal: self.context.world.goal.to_vec(),
                inflation,
            });
        }
        let request = PlanRequest {
            start: self.planner,
            goal: self.context.world.goal,
            obstacles: &self.obstacles,
            inflation,
            bounds: self.context.world.bounds(),
            speeds: &[],
            rule: SpeedRule::HalfDistance,
        };
        Ok(self.path_planner.plan(&request)?.into_iter().skip(1).collect())
    }

    /// The level to plan with and its path: the fastest level with a path, or with `quickest` the level whose
    /// path takes the least time at its speed (each axis at most `beta` per second).
    fn choose(&mut self) -> Result<(usize, VecDeque<Point<D>>), MethodError> {
        let mut chosen: Option<(usize, VecDeque<Point<D>>, f64)> = None;
        for level in (0..self.levels.len()).rev() {
            match self.plan(level) {
                Ok(path) => {
                    if !self.quickest {
                        return Ok((level, path));
                    }
                    let seconds = self.chebyshev_length(&path) / self.levels[level].beta;
                    if chosen.as_ref().is_none_or(|(_, _, best)| seconds < *best) {
                        chosen = Some((level, path, seconds));
                    }
                }
                Err(PlanError::NoPath { .. } | PlanError::GoalBlocked { .. }) if level > 0 || chosen.is_some() => {}
                Err(e) => return Err(e.into()),
            }
        }
        chosen.map(|(level, path, _)| (level, path)).ok_or_else(|| MethodError::Setup("no levels to plan with".into()))
    }

    /// The path's length from the planner on, each segment counted by its larger axis displacement (what a
    /// per-axis speed bound makes it cost).
    fn chebyshev_length(&self, path: &VecDeque<Point<D>>) -> f64 {
        std::iter::once(&self.planner).chain(path).zip(path).map(|(a, b)| chebyshev_norm(sub(*b, *a))).sum()
    }

    /// Value, membership and control at relative state `r` under level `level`'s `beta`.
    async fn answer(&self, r: &[f64], level: usize) -> Result<Answer, MethodError> {
        let (beta, n_params) = (self.levels[level].beta, self.context.n_params);
        let mut answers = self.context.backend.batch(r, beta, r.len(), n_params).await?;
        answers.pop().ok_or_else(|| MethodError::Setup("the model answered no state".into()))
    }

    /// One control period.
    pub async fn step(&mut self, tracker: &[f64], sensed: &[O]) -> Result<Decision<D>, MethodError> {
        let replanned = remember(&mut self.obstacles, sensed) || self.replan;
        if replanned {
            self.replan = false;
            let (level, path) = self.choose()?;
            if level >= self.current {
                (self.current, self.path, self.pending) = (level, path, None);
            } else {
                self.pending = Some((level, path));
            }
        }
        let (p_next, control, in_domain) = match self.pending.take() {
            // Hold the planner and steer with the pending level's control, which drives the relative state
            // towards that level's set; the current level's bound stays in force until the state is inside.
            // Under the current level's own control a Dubins car circles a still planner outside the
            // smaller set and the switch never happens.
            Some((level, path)) => {
                let r = self.context.tracker.relative_state(tracker, &self.planner);
                let answer = self.answer(&r, level).await?;
                if answer.in_set {
                    (self.current, self.path) = (level, path);
                } else {
                    self.pending = Some((level, path));
                }
                (self.planner, answer.control, answer.in_domain)
            }
            None => {
                let budget = self.levels[self.current].beta * self.context.control_period;
                let p_next = advance_along(self.planner, &mut self.path, budget);
                let r = self.context.tracker.relative_state(tracker, &p_next);
                let answer = self.answer(&r, self.current).await?;
                (p_next, answer.control, answer.in_domain)
            }
        };
        self.planner = p_next;
        Ok(Decision {
            control,
            planner: Some(p_next),
            beta: Some(self.levels[self.current].beta),
            bound: Some(self.levels[self.current].bound),
            replanned,
            planning: self.path_planner.take(),
            reset: false,
            held: false,
            visit: None,
            certificate_age: None,
            round_trips: 1,
            out_of_domain: !in_domain,
        })
    }
}
