//! Parametric FaSTrack: the online loop of `fastrack-online`, answered over the server's `Track` stream (or
//! by the model in this process), with A* on a grid as its raw-path planner: the shortest path, or the
//! fastest at the speeds the rule allows along it.

use super::{Context, Decision, MethodError, TimedPlanner};
use crate::backend::BackendOracle;
use crate::trace::{LoopTrace, TraceStep, FORMAT};
use crate::visits::Visit;
use crate::world::{feasibility_cell, WorldObstacle};
use fastrack_online::core::{CoreSettings, DEFAULT_RESET_CANDIDATES};
use fastrack_online::fastest_path::FastestPath;
use fastrack_online::geometry::Point;
use fastrack_online::online_loop::{Branch, OnlineLoop};
use fastrack_online::raw_path::{GridAStar, RawPathPlanner};
use fastrack_proto::planner_speed::SpeedRule;

/// Parametric FaSTrack, running.
pub struct Parametric<O, const D: usize> {
    online: OnlineLoop<O, D, BackendOracle>,
    planner: TimedPlanner<O, D>,
    /// The run's trace, when the context asks for one.
    trace: Option<LoopTrace<O, D>>,
}

impl<O: WorldObstacle<D>, const D: usize> Parametric<O, D> {
    /// Opens the loop's oracle (over the service: its `Track` stream) with the planner at `start`, planning
    /// the fastest raw path when `fastest` (else the shortest), `beta` picked by `rule`; A* on cells of the
    /// world's feasibility grid (0.1 m squares, 0.25 m cubes).
    pub async fn start(
        context: Context<O, D>,
        start: Point<D>,
        fastest: bool,
        rule: SpeedRule,
    ) -> Result<Self, MethodError> {
        if (fastest || rule != SpeedRule::HalfDistance) && context.trace {
            return Err(MethodError::Setup(
                "a loop trace is recorded with the shortest-path planner and the paper's rule (the Python port \
                 replays it)"
                    .into(),
            ));
        }
        let settings = CoreSettings {
            control_period: context.control_period,
            goal: context.world.goal,
            bounds: context.world.bounds(),
            reset_candidates: DEFAULT_RESET_CANDIDATES,
            rule,
        };
        settings.check().map_err(|e| MethodError::Setup(e.to_string()))?;
        let oracle = context.backend.oracle().await?;
        let trace = context.trace.then(|| LoopTrace {
            format: FORMAT.into(),
            model: context.model_name.clone(),
            version: context.model_version,
            control_period: settings.control_period,
            goal: settings.goal,
            bounds: [settings.bounds.0, settings.bounds.1],
            reset_candidates: settings.reset_candidates,
            start,
            steps: Vec::new(),
        });
        let cell = feasibility_cell::<D>();
        let planner: Box<dyn RawPathPlanner<O, D>> =
            if fastest { Box::new(FastestPath { cell }) } else { Box::new(GridAStar { cell }) };
        let planner = TimedPlanner::new(planner);
        Ok(Self { online: OnlineLoop::new(oracle, settings, start)?, planner, trace })
    }

    /// The run's trace so far (`None` unless the context asked for one).
    pub fn take_trace(&mut self) -> Option<LoopTrace<O, D>> {
        self.trace.take()
    }

    /// One step of Alg. 3.
    pub async fn step(&mut self, tracker: &[f64], sensed: &[O]) -> Result<Decision<D>, MethodError> {
        let mut new = Vec::new();
        if self.trace.is_some() {
            for obstacle in sensed {
                if !self.online.obstacles().contains(obstacle) && !new.contains(obstacle) {
                    new.push(obstacle.clone());
                }
            }
        }
        let report = self.online.step(tracker, sensed, &mut self.planner).await?;
        if let Some(trace) = &mut self.trace {
            trace.steps.push(TraceStep::new(tracker, new, &report));
        }
        Ok(Decision {
            control: report.control,
            planner: Some(report.planner),
            beta: Some(report.beta_query),
            bound: Some(report.dteb_radius),
            replanned: report.replanned,
            planning: self.planner.take(),
            reset: report.branch == Branch::Reset,
            held: report.branch == Branch::Hold,
            round_trips: report.round_trips,
            out_of_domain: !report.in_domain,
            certificate_age: Some(report.certificate_age),
            visit: Some(Visit { branch: report.branch, beta: report.beta_query, state: report.relative_state }),
        })
    }

    /// The raw path ahead of the planner.
    pub fn raw_path(&self) -> Vec<Point<D>> {
        self.online.raw_path().copied().collect()
    }
}
