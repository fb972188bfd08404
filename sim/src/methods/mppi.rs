//! MPPI (Williams et al., "Information theoretic MPC for model-based reinforcement learning", ICRA 2017,
//! Alg. 2) on the tracker's own dynamics: sampled control sequences around a nominal one, rolled out,
//! weighted by `exp(-cost / temperature)`, averaged into the next nominal sequence. The sensed obstacles are
//! in the cost; there is no tracking error bound, and so no guarantee.
//!
//! Defaults, and why: 256 samples over a 3 s horizon of 0.1 s steps (pytorch_mppi's 100 samples are too few
//! for obstacle fields; Nav2's 1000 samples of 56 x 0.05 s cost 4-8x more for little gain at these speeds),
//! re-planned every 0.1 s and held in between (10 Hz, as Nav2 runs it); temperature 0.3 (Nav2's); noise
//! on dubins4d 2 rad/s on the turn rate and 0.5 m/s^2 on the acceleration (40% and 50% of their half
//! ranges), on other systems 40% of each control's half range (quad10d: 0.14 rad of tilt command, 2.9 m/s^2
//! of thrust). The first nominal sequence holds the tracker's resting control (a quadcopter's hover thrust,
//! a car's zero).

use super::{Context, Decision, MethodError};
use crate::world::WorldObstacle;
use fastrack_online::geometry::{clearance, norm, remember, sub, Point};
use rand::rngs::StdRng;
use rand::{Rng, SeedableRng};

/// MPPI's settings.
#[derive(Debug, Clone, PartialEq)]
pub struct MppiSettings {
    /// Sampled control sequences per plan.
    pub samples: usize,
    /// Steps of a sequence.
    pub horizon: usize,
    /// Length of a step (s); the plan is made again every step and its first control held meanwhile.
    pub step: f64,
    /// Temperature `lambda` of the weights.
    pub temperature: f64,
    /// Standard deviation of the sampling noise, per control (empty: the system's default, above).
    pub noise: Vec<f64>,
    /// Cost per metre from the goal, per step.
    pub goal_weight: f64,
    /// Cost of an obstacle at distance 0, falling off as `exp(-distance / obstacle_scale)`, per step.
    pub obstacle_weight: f64,
    /// Length scale of the obstacle cost (m).
    pub obstacle_scale: f64,
    /// Cost of a step inside an obstacle.
    pub collision_cost: f64,
}

impl Default for MppiSettings {
    fn default() -> Self {
        Self {
            samples: 256,
            horizon: 30,
            step: 0.1,
            temperature: 0.3,
            noise: Vec::new(),
            goal_weight: 1.0,
            obstacle_weight: 20.0,
            obstacle_scale: 0.3,
            collision_cost: 1e4,
        }
    }
}

/// MPPI, running.
pub struct Mppi<O, const D: usize> {
    context: Context<O, D>,
    settings: MppiSettings,
    /// The nominal control sequence, `horizon x n_control` (empty until the first plan).
    nominal: Vec<Vec<f64>>,
    /// Control periods left before the next plan.
    until_plan: usize,
    obstacles: Vec<O>,
    rng: StdRng,
}

impl<O: WorldObstacle<D>, const D: usize> Mppi<O, D> {
    /// MPPI with `settings`, checked.
    pub fn new(context: Context<O, D>, mut settings: MppiSettings) -> Result<Self, MethodError> {
        let system = context.tracker.system();
        let n_control = system.n_control();
        if settings.noise.is_empty() {
            settings.noise = match system.id {
                fastrack_valuefn::system::dubins4d::ID => vec![2.0, 0.5],
                _ => system.controls.iter().map(|c| 0.4 * (c.max - c.min) / 2.0).collect(),
            };
        }
        let positive = |x: f64| x.is_finite() && x > 0.0;
        if settings.samples == 0
            || settings.horizon == 0
            || !positive(settings.step)
            || !positive(settings.temperature)
            || settings.noise.len() != n_control
            || settings.noise.iter().any(|&s| !positive(s))
        {
            return Err(MethodError::Setup(format!(
                "MPPI needs samples and horizon >= 1, a positive step and temperature, and {n_control} positive noise levels; got {settings:?}"
            )));
        }
        Ok(Self {
            nominal: Vec::new(),
            until_plan: 0,
            obstacles: Vec::new(),
            rng: StdRng::seed_from_u64(context.seed),
            context,
            settings,
        })
    }

    /// One control period: plan again when due, apply the nominal sequence's first control.
    pub fn step(&mut self, tracker: &[f64], sensed: &[O]) -> Result<Decision<D>, MethodError> {
        let replanned = remember(&mut self.obstacles, sensed);
        if self.until_plan == 0 {
            self.plan(tracker);
            self.until_plan = ((self.settings.step / self.context.control_period).round() as usize).max(1);
        }
        self.until_plan -= 1;
        let control = self.nominal[0].clone();
        if self.until_plan == 0 {
            self.nominal.rotate_left(1);
            let last = self.nominal.len() - 1;
            self.nominal[last] = self.nominal[last.saturating_sub(1)].clone();
        }
        Ok(Decision {
            control,
            planner: None,
            beta: None,
            bound: None,
            replanned,
            planning: None,
            reset: false,
            held: false,
            visit: None,
            certificate_age: None,
            round_trips: 0,
            out_of_domain: false,
        })
    }

    /// One MPPI update of the nominal sequence from tracker state `tracker`.
    fn plan(&mut self, tracker: &[f64]) {
        let system = self.context.tracker.system();
        if self.nominal.is_empty() {
            self.nominal = vec![system.resting_control(tracker); self.settings.horizon];
        }
        let (lo, hi): (Vec<f64>, Vec<f64>) = system.controls.iter().map(|c| (c.min, c.max)).unzip();
        let (horizon, n_control) = (self.settings.horizon, lo.len());
        let mut noises = Vec::with_capacity(self.settings.samples);
        let mut costs = Vec::with_capacity(self.settings.samples);
        for _ in 0..self.settings.samples {
            let noise: Vec<Vec<f64>> = (0..horizon)
                .map(|_| self.settings.noise.iter().map(|&sigma| sigma * standard_normal(&mut self.rng)).collect())
                .collect();
            costs.push(self.rollout_cost(tracker, &noise, &lo, &hi));
            noises.push(noise);
        }
        let best = costs.iter().copied().fold(f64::INFINITY, f64::min);
        let weights: Vec<f64> = costs.iter().map(|c| (-(c - best) / self.settings.temperature).exp()).collect();
        let total: f64 = weights.iter().sum();
        for t in 0..horizon {
            for j in 0..n_control {
                let shift: f64 = weights.iter().zip(&noises).map(|(w, n)| w * n[t][j]).sum::<f64>() / total;
                self.nominal[t][j] = (self.nominal[t][j] + shift).clamp(lo[j], hi[j]);
            }
        }
    }

    /// The cost of the nominal sequence plus `noise`, rolled out from `tracker`, with Williams et al.'s
    /// control term `lambda u^T Sigma^-1 noise`.
    fn rollout_cost(&self, tracker: &[f64], noise: &[Vec<f64>], lo: &[f64], hi: &[f64]) -> f64 {
        let settings = &self.settings;
        let model = &self.context.tracker;
        let goal = self.context.world.goal;
        let mut x = tracker.to_vec();
        let mut cost = 0.0;
        for (t, eps) in noise.iter().enumerate() {
            let u: Vec<f64> = (0..lo.len()).map(|j| (self.nominal[t][j] + eps[j]).clamp(lo[j], hi[j])).collect();
            model.step(&mut x, &u, &[0.0; D], settings.step, 1, |_| true);
            let position: Point<D> = model.position(&x);
            let gap = clearance(&self.obstacles, position);
            cost += settings.goal_weight * norm(sub(position, goal));
            cost += if gap <= 0.0 {
                settings.collision_cost
            } else {
                settings.obstacle_weight * (-gap / settings.obstacle_scale).exp()
            };
            cost += settings.temperature
                * (0..lo.len())
                    .map(|j| self.nominal[t][j] * eps[j] / (settings.noise[j] * settings.noise[j]))
                    .sum::<f64>();
        }
        cost
    }
}

/// A standard normal draw (Box-Muller).
fn standard_normal(rng: &mut StdRng) -> f64 {
    let (u1, u2): (f64, f64) = (1.0 - rng.random::<f64>(), rng.random::<f64>());
    (-2.0 * u1.ln()).sqrt() * (std::f64::consts::TAU * u2).cos()
}
