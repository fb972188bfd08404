//! Rollouts batched through ONNX Runtime: at every step the states of many rollouts go to the served graph in a
//! few large calls (one per worker thread, each on its own session), and each worker then steps the rollouts of
//! its chunk. Every rollout carries its own random generator, seeded before the run, so the outcome does not
//! depend on how the rollouts are split among threads.

use super::{ErrorScale, VerifyError};
use crate::solver::Solution;
use fastrack_valuefn::runtime::Evaluator;
use fastrack_valuefn::simulation::{step_relative, HeldInputs, PlannerPolicy};
use fastrack_valuefn::system::AffineSystem;
use rand::rngs::StdRng;
use rayon::prelude::*;

/// Whose value gradient a player (planner or tracker) reads.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) enum Gradient {
    /// The served graph's `grad` output (the model under test).
    Model,
    /// The grid solution given as the adversary.
    Grid,
}

/// One rollout: its relative state, its planner, and the largest tracking error reached so far.
pub(super) struct Rollout {
    /// Relative state.
    pub state: Vec<f64>,
    /// The planner pushing it.
    pub planner: PlannerPolicy,
    /// The gradient the planner reads.
    pub gradient: Gradient,
    /// The planner's own random generator.
    pub rng: StdRng,
    /// Largest tracking error so far (the start's included).
    pub max_error: f64,
    /// The served value at the start, once the first step has evaluated it.
    pub start_value: Option<f64>,
}

impl Rollout {
    /// A rollout from `state` with its error at the start as the largest so far.
    pub fn new(system: &AffineSystem, state: &[f64], planner: PlannerPolicy, gradient: Gradient, rng: StdRng) -> Self {
        Self {
            state: state.to_vec(),
            planner,
            gradient,
            rng,
            max_error: system.tracking_error(state),
            start_value: None,
        }
    }
}

/// How rollouts are fed to ONNX Runtime.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Batching {
    /// Largest number of states per graph call.
    pub chunk: usize,
    /// Chunks are evaluated and stepped on the rayon pool (one ONNX Runtime session per thread) instead of in
    /// turn on the calling thread.
    pub parallel: bool,
}

impl Default for Batching {
    fn default() -> Self {
        Self { chunk: 4096, parallel: true }
    }
}

/// What a batched rollout needs besides the rollouts.
pub(super) struct Scene<'a> {
    pub evaluator: &'a Evaluator,
    pub system: &'a AffineSystem,
    pub params: &'a [f64],
    pub grid: Option<&'a Solution>,
    /// Whose control the tracker plays: the served graph's, or (as a reference) the grid solution's policy.
    pub tracker: Gradient,
    pub horizon: f64,
    pub step: f64,
    pub mean_dwell: f64,
    pub batching: Batching,
    /// What a rollout's largest error is measured against.
    pub error_scale: ErrorScale,
}

impl Scene<'_> {
    /// A finished rollout's largest error on the scene's scale: the error itself, or less the start's value.
    pub fn score(&self, rollout: &Rollout) -> f64 {
        match self.error_scale {
            ErrorScale::Absolute => rollout.max_error,
            ErrorScale::ExcessOverStartValue => rollout.start_value.map_or(f64::INFINITY, |v| rollout.max_error - v),
        }
    }

    /// Rolls every rollout forward over the horizon: the tracker plays the served `control` (or the grid
    /// solution's optimal control, with [`Gradient::Grid`] as the tracker), the planner its input, the
    /// disturbance the worst case of the model's gradient.
    pub fn roll_out(&self, rollouts: &mut [Rollout]) -> Result<(), VerifyError> {
        if rollouts.is_empty() {
            return Ok(());
        }
        let steps = (self.horizon / self.step).round().max(1.0) as usize;
        let threads = if self.batching.parallel { rayon::current_num_threads().max(1) } else { 1 };
        let chunk = rollouts.len().div_ceil(threads).clamp(1, self.batching.chunk.max(1));
        for k in 0..steps {
            let t = k as f64 * self.step;
            if self.batching.parallel {
                rollouts.par_chunks_mut(chunk).try_for_each(|c| self.step_chunk(c, t))?;
            } else {
                rollouts.chunks_mut(chunk).try_for_each(|c| self.step_chunk(c, t))?;
            }
        }
        Ok(())
    }

    /// One step of a chunk: one graph call for its states, then each rollout's RK4 step.
    fn step_chunk(&self, chunk: &mut [Rollout], t: f64) -> Result<(), VerifyError> {
        let system = self.system;
        let (n_state, n_control) = (system.n_state(), system.n_control());
        let states: Vec<f32> = chunk.iter().flat_map(|r| r.state.iter().map(|&x| x as f32)).collect();
        let params: Vec<f32> =
            self.params.iter().map(|&p| p as f32).cycle().take(chunk.len() * self.params.len()).collect();
        let out = self.evaluator.evaluate(&states, &params)?;
        let mut grid_grad = vec![0.0; n_state];
        for (j, rollout) in chunk.iter_mut().enumerate() {
            rollout.start_value.get_or_insert(f64::from(out.value[j]));
            let grad: Vec<f64> = out.grad[j * n_state..(j + 1) * n_state].iter().map(|&g| f64::from(g)).collect();
            if let Some(grid) =
                self.grid.filter(|_| rollout.gradient == Gradient::Grid || self.tracker == Gradient::Grid)
            {
                grid.gradient(&rollout.state, &mut grid_grad);
            }
            let u: Vec<f64> = match (self.tracker, self.grid) {
                (Gradient::Grid, Some(_)) => system.optimal_control(&rollout.state, &grid_grad),
                _ => out.control[j * n_control..(j + 1) * n_control].iter().map(|&c| f64::from(c)).collect(),
            };
            let planner_grad = match (rollout.gradient, self.grid) {
                (Gradient::Grid, Some(_)) => &grid_grad,
                _ => &grad,
            };
            let u_p = rollout.planner.input(system, self.params, planner_grad, t, self.mean_dwell, &mut rollout.rng);
            let d = system.worst_disturbance(&grad);
            step_relative(
                system,
                &mut rollout.state,
                HeldInputs { control: &u, planner: &u_p, disturbance: &d },
                self.step,
            );
            rollout.max_error = rollout.max_error.max(system.tracking_error(&rollout.state));
        }
        Ok(())
    }
}
