//! A raw-path planner that times its plans, for the benchmark's planning time per replan.

use fastrack_online::geometry::{Obstacle, Point};
use fastrack_online::raw_path::{PlanError, PlanRequest, RawPathPlanner};
use std::time::{Duration, Instant};

/// Wraps a raw-path planner and adds up the wall time of the plans made since [`TimedPlanner::take`].
pub struct TimedPlanner<O, const D: usize> {
    inner: Box<dyn RawPathPlanner<O, D>>,
    since_taken: Option<Duration>,
}

impl<O, const D: usize> TimedPlanner<O, D> {
    /// Times `inner`.
    pub fn new(inner: Box<dyn RawPathPlanner<O, D>>) -> Self {
        Self { inner, since_taken: None }
    }

    /// The time spent planning since the last call (`None`: no plan was made).
    pub fn take(&mut self) -> Option<Duration> {
        self.since_taken.take()
    }
}

impl<O: Obstacle<D>, const D: usize> RawPathPlanner<O, D> for TimedPlanner<O, D> {
    fn plan(&mut self, request: &PlanRequest<'_, O, D>) -> Result<Vec<Point<D>>, PlanError> {
        let started = Instant::now();
        let path = self.inner.plan(request);
        *self.since_taken.get_or_insert(Duration::ZERO) += started.elapsed();
        path
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use fastrack_online::geometry::PlaneObstacle;
    use fastrack_online::raw_path::GridAStar;
    use fastrack_proto::planner_speed::SpeedRule;

    #[test]
    fn plans_add_up_until_taken() {
        let mut planner = TimedPlanner::<PlaneObstacle, 2>::new(Box::new(GridAStar::default()));
        assert_eq!(planner.take(), None, "nothing planned yet");
        let request = PlanRequest {
            start: [0.0, 0.0],
            goal: [5.0, 0.0],
            obstacles: &[],
            inflation: 0.5,
            bounds: ([-1.0, -1.0], [6.0, 1.0]),
            speeds: &[],
            rule: SpeedRule::HalfDistance,
        };
        planner.plan(&request).unwrap();
        let one = planner.take().expect("one plan timed");
        planner.plan(&request).unwrap();
        planner.plan(&request).unwrap();
        let two = planner.take().expect("two plans timed");
        assert!(one > Duration::ZERO && two > Duration::ZERO);
        assert_eq!(planner.take(), None, "taken");
    }
}
