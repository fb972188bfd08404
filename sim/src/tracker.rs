//! The tracker's true dynamics, from the shared system definition, integrated by RK4 with the control held
//! over each control period and checked at every sub-step; and the range sensor.

use fastrack_online::geometry::{Obstacle, Point};
use fastrack_valuefn::simulation::rk4;
use fastrack_valuefn::system::{AffineSystem, Factor, StateSpace};
use rand::rngs::StdRng;
use rand::Rng;

/// A simulated tracker of one system.
///
/// Its dynamics are the system's relative dynamics with the planner at rest: with `p` constant,
/// `s' = r' = f(s) + G_u u`, which holds when the drift reads none of the coordinates the planner moves
/// (the rows of `Q`), as for dubins4d, whose drift reads only the heading and the speed, and quad10d, whose
/// drift reads velocities and tilts. Positions have as many axes as the system's planner (2 or 3).
#[derive(Debug, Clone)]
pub struct Tracker {
    system: AffineSystem,
    space: StateSpace,
}

impl Tracker {
    /// The tracker of `system`, or why it cannot be simulated this way.
    pub fn new(system: AffineSystem) -> Result<Self, String> {
        let dim = system.planner_dim();
        if !(dim == 2 || dim == 3) {
            return Err(format!(
                "system {} has a {dim}-D planner; the simulator flies in the plane or in space",
                system.id
            ));
        }
        let moved: Vec<usize> =
            (0..system.n_state()).filter(|&i| (0..dim).any(|j| system.planner_to_state[(i, j)] != 0.0)).collect();
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

    /// Axes of the planner's position space: 2 or 3.
    pub fn dim(&self) -> usize {
        self.system.planner_dim()
    }

    /// The tracker's position in the planner's position space, `Q^T s` (`D` must be [`Tracker::dim`]).
    pub fn position<const D: usize>(&self, s: &[f64]) -> Point<D> {
        let q = &self.space.planner_to_state;
        std::array::from_fn(|j| (0..s.len()).map(|i| q[(i, j)] * s[i]).sum())
    }

    /// The relative state `s - Q p`, periodic coordinates wrapped.
    pub fn relative_state(&self, s: &[f64], p: &[f64]) -> Vec<f64> {
        self.space.relative_state(s, p)
    }

    /// The tracking error `l(s - Q p)`.
    pub fn tracking_error(&self, s: &[f64], p: &[f64]) -> f64 {
        self.space.tracking_error(&self.relative_state(s, p))
    }

    /// A state at `position` on the planner, moving at `speed` along `heading` in the ground plane (0 along
    /// +y, pi/2 along +x), the rest zero: the system's start state ([`AffineSystem::start_state`]) moved to
    /// `position`.
    pub fn initial_state(&self, position: &[f64], heading: f64, speed: f64) -> Result<Vec<f64>, String> {
        let q = &self.space.planner_to_state;
        let mut s = self.system.start_state(heading, speed)?;
        for (i, x) in s.iter_mut().enumerate() {
            *x += (0..position.len()).map(|j| q[(i, j)] * position[j]).sum::<f64>();
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
        push: &[f64],
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
                    *o += (0..push.len()).map(|j| q[(i, j)] * push[j]).sum::<f64>();
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
    pub fn draw<const D: usize>(&self, rng: &mut StdRng) -> Point<D> {
        if self.bound <= 0.0 {
            return [0.0; D];
        }
        std::array::from_fn(|_| rng.random_range(-self.bound..=self.bound))
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
    pub fn sense<O: Obstacle<D>, const D: usize>(&self, obstacles: &[O], position: Point<D>) -> Vec<O> {
        obstacles.iter().filter(|o| o.distance(position) <= self.range).cloned().collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use fastrack_online::geometry::PlaneObstacle;
    use fastrack_valuefn::system::{dubins4d, quad10d};

    #[test]
    fn dubins4d_drives_straight_and_turns_as_its_equations_say() {
        let tracker = Tracker::new(dubins4d::system()).unwrap();
        let mut s = tracker.initial_state(&[1.0, 2.0], std::f64::consts::FRAC_PI_2, 1.0).unwrap();
        assert_eq!(tracker.position(&s), [1.0, 2.0]);
        // Heading pi/2 is along +x; 1 s at 1 m/s with no control.
        tracker.step(&mut s, &[0.0, 0.0], &[0.0, 0.0], 1.0, 10, |_| true);
        assert!((s[0] - 2.0).abs() < 1e-9 && (s[1] - 2.0).abs() < 1e-9, "{s:?}");
        // A full turn at omega = 2 pi / T returns to the start (circle of radius v T / 2 pi).
        let period = 4.0;
        tracker.step(&mut s, &[std::f64::consts::TAU / period, 0.0], &[0.0, 0.0], period, 400, |_| true);
        assert!((s[0] - 2.0).abs() < 1e-6 && (s[1] - 2.0).abs() < 1e-6, "{s:?}");
        // The check stops the integration.
        let mut calls = 0;
        assert!(!tracker.step(&mut s, &[0.0, 0.0], &[0.0, 0.0], 1.0, 10, |_| {
            calls += 1;
            calls < 3
        }));
        assert_eq!(calls, 3);
    }

    #[test]
    fn quad10d_hovers_coasts_and_falls_as_its_equations_say() {
        let tracker = Tracker::new(quad10d::system()).unwrap();
        assert_eq!(tracker.dim(), 3);
        // Heading pi/2 is along +x: v_x = 1, v_y = 0 (to rounding), level, at rest vertically.
        let mut s = tracker.initial_state(&[1.0, 2.0, 3.0], std::f64::consts::FRAC_PI_2, 1.0).unwrap();
        assert_eq!(tracker.position(&s), [1.0, 2.0, 3.0]);
        assert!((s[1] - 1.0).abs() < 1e-12 && s[5].abs() < 1e-12, "{s:?}");
        // Hover thrust (k_T u_z = g) and no tilt command: 1 s coasting along x, the height held.
        let hover = quad10d::GRAVITY / quad10d::K_T;
        tracker.step(&mut s, &[0.0, 0.0, hover], &[0.0; 3], 1.0, 20, |_| true);
        let p: [f64; 3] = tracker.position(&s);
        assert!((p[0] - 2.0).abs() < 1e-9 && (p[1] - 2.0).abs() < 1e-9 && (p[2] - 3.0).abs() < 1e-9, "{p:?}");
        // No thrust: free fall, g t^2 / 2 in 0.5 s (RK4 is exact on a quadratic).
        tracker.step(&mut s, &[0.0, 0.0, 0.0], &[0.0; 3], 0.5, 10, |_| true);
        let fallen = 3.0 - tracker.position::<3>(&s)[2];
        assert!((fallen - quad10d::GRAVITY * 0.125).abs() < 1e-9, "fell {fallen} m");
        // A push moves every axis of the position.
        let before: [f64; 3] = tracker.position(&s);
        let mut pushed = s.clone();
        tracker.step(&mut pushed, &[0.0, 0.0, 0.0], &[0.0, 0.0, 1.0], 0.5, 10, |_| true);
        let extra = tracker.position::<3>(&pushed)[2]
            - tracker.position::<3>(&{
                let mut free = s.clone();
                tracker.step(&mut free, &[0.0, 0.0, 0.0], &[0.0; 3], 0.5, 10, |_| true);
                free
            })[2];
        assert!((extra - 0.5).abs() < 1e-9 && before[2] < 3.0, "pushed {extra} m up");
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
