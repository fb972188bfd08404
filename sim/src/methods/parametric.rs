//! Parametric FaSTrack: the online loop of `fastrack-online`, answered over the server's `Track` stream (or
//! by the model in this process), with A* on a grid as its raw-path planner.

use super::{Context, Decision, MethodError};
use crate::backend::BackendOracle;
use crate::visits::Visit;
use fastrack_online::core::CoreSettings;
use fastrack_online::geometry::{Obstacle, Point};
use fastrack_online::online_loop::{Branch, OnlineLoop};
use fastrack_online::raw_path::GridAStar;

/// Parametric FaSTrack, running.
pub struct Parametric {
    online: OnlineLoop<BackendOracle>,
    planner: GridAStar,
}

impl Parametric {
    /// Opens the loop's oracle (over the service: its `Track` stream) with the planner at `start`.
    pub async fn start(context: Context, start: Point) -> Result<Self, MethodError> {
        let settings = CoreSettings {
            control_period: context.control_period,
            goal: context.world.goal,
            bounds: context.world.bounds(),
            reset_candidates: 256,
            seed: context.seed,
        };
        settings.check().map_err(|e| MethodError::Setup(e.to_string()))?;
        let oracle = context.backend.oracle().await?;
        Ok(Self { online: OnlineLoop::new(oracle, settings, start)?, planner: GridAStar::default() })
    }

    /// One step of Alg. 3.
    pub async fn step(&mut self, tracker: &[f64], sensed: &[Obstacle]) -> Result<Decision, MethodError> {
        let report = self.online.step(tracker, sensed, &mut self.planner).await?;
        Ok(Decision {
            control: report.control,
            planner: Some(report.planner),
            beta: Some(report.beta_query),
            bound: Some(report.dteb_radius),
            replanned: report.replanned,
            reset: report.branch == Branch::Reset,
            held: report.branch == Branch::Hold,
            round_trips: report.round_trips,
            out_of_domain: !report.in_domain,
            certificate_age: Some(report.certificate_age),
            visit: Some(Visit { branch: report.branch, beta: report.beta_query, state: report.relative_state }),
        })
    }

    /// The raw path ahead of the planner.
    pub fn raw_path(&self) -> Vec<Point> {
        self.online.raw_path().copied().collect()
    }
}
