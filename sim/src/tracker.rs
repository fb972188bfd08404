//! The tracker's true dynamics, from the shared system definition, integrated by RK4 with the control held
//! over each control period and checked at every sub-step; and the range sensor.

use fastrack_online::geometry::{Obstacle, PlaneObstacle, Point};
use fastrack_valuefn::simulation::rk4;
use fastrack_valuefn::system::{AffineSystem, Factor, StateSpace};
use rand::rngs::StdRng;
use rand::Rng;

/// A simulated tracker of one system.
///
/// Its dynamics are the system's relative dynamics with the planner at rest: with `p` constant,
/// `s' = r' = f(s) + G_u u`, which holds when the drift reads none of the coordinates the planner moves
/// (the rows of `Q`), as for dubins4d, whose drift reads only the heading and the speed.
#[derive(Debug, Clone)]
pub struct Tracker {
    system: AffineSystem,
    space: StateSpace,
}

impl Tracker {
    /// The tracker of `system`, or why it cannot be simulated this way.
    pub fn new(system: AffineSystem) -> Result<Self, String> {
        if system.planner_dim() != 2 {
            return Err(format!(
                "system {} has a {}-D planner; the simulator is planar",
                system.id,
                system.planner_dim()
            ));
        }
        let moved: Vec<usize> =
            (0..system.n_state()).filter(|&i| (0..2).any(|j| system.planner_to_state[(i, j)] != 0.0)).collect();
        let reads = |f: &Factor| match *f {
            Factor::Linear(j) | Factor::Sin(j) | Factor::Cos(j) | Factor::Tan(j) => j,
        };
        if system.drift.terms.iter().flat_map(|t| t.factors.iter()).any(|f| moved.contains(&reads(f))) {
            return Err(format!(
                "system {}: its drift reads a coordinate the planner moves, so the tracker's own dynamics are not its relative dynamics",
                system.id
            ));
        }
        let space = system.state_space();
        Ok(Self { system, space })
    }

    /// The system.
    pub fn system(&self) -> &AffineSystem {
        &self.system
    }

    /// The tracker's position in the planner's plane, `Q^T s`.
    pub fn position(&self, s: &[f64]) -> Point {
        let q = &self.space.planner_to_state;
        [0, 1].map(|j| (0..s.len()).map(|i| q[(i, j)] * s[i]).sum())
    }

    /// The relative state `s - Q p`, periodic coordinates wrapped.
    pub fn relative_state(&self, s: &[f64], p: Point) -> Vec<f64> {
        self.space.relative_state(s, &p)
    }

    /// The tracking error `l(s - Q p)`.
    pub fn tracking_error(&self, s: &[f64], p: Point) -> f64 {
        self.space.tracking_error(&self.relative_state(s, p))
    }

    /// A state at `position` with the named coordinates set (dubins4d: `theta`, `v`), the rest zero.
    pub fn initial_state(&self, position: Point, named: &[(&str, f64)]) -> Result<Vec<f64>, String> {
        let q = &self.space.planner_to_state;
        let mut s: Vec<f64> =
            (0..self.system.n_state()).map(|i| q[(i, 0)] * position[0] + q[(i, 1)] * position[1]).collect();
        for (name, value) in named {
            let i = self
                .system
                .state
                .iter()
                .position(|d| d.name == *name)
                .ok_or_else(|| format!("system {} has no state coordinate {name}", self.system.id))?;
            s[i] = *value;
        }
        Ok(s)
    }

    /// Integrates one control period `dt` in `substeps` RK4 steps with `control` held and the position
    /// pushed by `push` (m/s per axis, outside the model; zero for none), calling `check` after every
    /// sub-step; stops early (returning false) when `check` does.
    pub fn step(
        &self,
        s: &mut [f64],
        control: &[f64],
        push: Point,
        dt: f64,
        substeps: usize,
        mut check: impl FnMut(&[f64]) -> bool,
    ) -> bool {
        let h = dt / substeps.max(1) as f64;
        let at_rest = vec![0.0; self.system.g_planner.ncols()];
        let no_disturbance = vec![0.0; self.system.disturbances.len()];
        let q = &self.space.planner_to_state;
        for _ in 0..substeps.max(1) {
            rk4(s, h, |x, out| {
                self.system.dynamics(x, control, &at_rest, &no_disturbance, out);
                for (i, o) in out.iter_mut().enumerate() {
                    *o += q[(i, 0)] * push[0] + q[(i, 1)] * push[1];
                }
            });
            self.space.wrap(s);
            if !check(s) {
                return false;
            }
        }
        true
    }
}

/// A bounded push on the tracker's position that the model does not know of: a random per-axis velocity
/// of at most `bound`, redrawn every `period` seconds. The bounds are not guaranteed under it.
#[derive(Debug, Clone, PartialEq)]
pub struct Disturbance {
    /// Largest push per axis (m/s).
    pub bound: f64,
    /// How long a push lasts (s).
    pub period: f64,
}

impl Disturbance {
    /// The push for the next period.
    pub fn draw(&self, rng: &mut StdRng) -> Point {
        if self.bound <= 0.0 {
            return [0.0, 0.0];
        }
        [rng.random_range(-self.bound..=self.bound), rng.random_range(-self.bound..=self.bound)]
    }
}

/// A range sensor: it sees every obstacle within `range` of the tracker's position.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RangeSensor {
    /// Range (m).
    pub range: f64,
}

impl RangeSensor {
    /// The obstacles of `world` within range of `position`.
    pub fn sense(&self, obstacles: &[PlaneObstacle], position: Point) -> Vec<PlaneObstacle> {
        obstacles.iter().filter(|o| o.distance(position) <= self.range).cloned().collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use fastrack_valuefn::system::dubins4d;

    #[test]
    fn dubins4d_drives_straight_and_turns_as_its_equations_say() {
        let tracker = Tracker::new(dubins4d::system()).unwrap();
        let mut s = tracker.initial_state([1.0, 2.0], &[("theta", std::f64::consts::FRAC_PI_2), ("v", 1.0)]).unwrap();
        assert_eq!(tracker.position(&s), [1.0, 2.0]);
        // Heading pi/2 is along +x; 1 s at 1 m/s with no control.
        tracker.step(&mut s, &[0.0, 0.0], [0.0, 0.0], 1.0, 10, |_| true);
        assert!((s[0] - 2.0).abs() < 1e-9 && (s[1] - 2.0).abs() < 1e-9, "{s:?}");
        // A full turn at omega = 2 pi / T returns to the start (circle of radius v T / 2 pi).
        let period = 4.0;
        tracker.step(&mut s, &[std::f64::consts::TAU / period, 0.0], [0.0, 0.0], period, 400, |_| true);
        assert!((s[0] - 2.0).abs() < 1e-6 && (s[1] - 2.0).abs() < 1e-6, "{s:?}");
        // The check stops the integration.
        let mut calls = 0;
        assert!(!tracker.step(&mut s, &[0.0, 0.0], [0.0, 0.0], 1.0, 10, |_| {
            calls += 1;
            calls < 3
        }));
        assert_eq!(calls, 3);
    }

    #[test]
    fn the_sensor_sees_what_is_in_range() {
        let obstacles = [
            PlaneObstacle::Circle { center: [3.0, 0.0], radius: 1.0 },
            PlaneObstacle::Circle { center: [10.0, 0.0], radius: 1.0 },
        ];
        let sensed = RangeSensor { range: 2.5 }.sense(&obstacles, [0.0, 0.0]);
        assert_eq!(sensed, vec![obstacles[0].clone()]);
    }
}
