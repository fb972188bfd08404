//! An adversary that searches for the largest error instead of reading a value function: the cross-entropy
//! method over bang-bang planner schedules. A schedule holds one vertex of the planner's box per segment of the
//! horizon; each axis of each segment is `+beta` with a probability the search learns. Every iteration draws a
//! population of schedules per start, rolls them all out in one batch, and moves the probabilities towards the
//! elite schedules (those that forced the largest errors). The result per start is the largest error any
//! schedule forced.

use super::batch::{Gradient, Rollout, Scene};
use super::VerifyError;
use fastrack_valuefn::simulation::PlannerPolicy;
use rand::rngs::StdRng;
use rand::{Rng, SeedableRng};
use serde::{Deserialize, Serialize};

/// How the search runs.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SearchOptions {
    /// Schedules per start and iteration (0 turns the search off).
    pub population: usize,
    /// Iterations of the cross-entropy method.
    pub iterations: usize,
    /// Schedules per start that update the probabilities.
    pub elites: usize,
    /// How long each vertex of a schedule is held (s).
    pub segment: f64,
    /// Weight of the elites' frequencies in each update (the rest keeps the old probability).
    pub smoothing: f64,
    /// Samples searched per batch: those the other planner families pushed to the largest errors.
    pub per_batch: usize,
}

impl Default for SearchOptions {
    fn default() -> Self {
        Self { population: 16, iterations: 3, elites: 4, segment: 0.5, smoothing: 0.7, per_batch: 64 }
    }
}

impl SearchOptions {
    /// Whether the search runs at all.
    pub fn enabled(&self) -> bool {
        self.population > 0 && self.iterations > 0 && self.per_batch > 0
    }

    /// Why these options cannot run, if they cannot.
    pub fn check(&self) -> Result<(), VerifyError> {
        if !self.enabled() {
            return Ok(());
        }
        let fine = self.elites >= 1
            && self.elites <= self.population
            && self.segment.is_finite()
            && self.segment > 0.0
            && (0.0..=1.0).contains(&self.smoothing);
        if fine {
            Ok(())
        } else {
            Err(VerifyError::Setting(format!(
                "search: population {} needs 1 <= elites ({}) <= population, a positive segment ({}) and smoothing in [0, 1] ({})",
                self.population, self.elites, self.segment, self.smoothing
            )))
        }
    }
}

/// The largest error the search forced from each of `starts` (row-major states).
pub(super) fn search(
    scene: &Scene<'_>,
    starts: &[f64],
    options: &SearchOptions,
    rng: &mut StdRng,
) -> Result<Vec<f64>, VerifyError> {
    let system = scene.system;
    let n_state = system.n_state();
    let count = starts.len() / n_state;
    let axes = system.planner_input_param.len();
    let segments = (scene.horizon / options.segment).ceil().max(1.0) as usize;
    let bounds: Vec<f64> = system.planner_input_param.iter().map(|&k| scene.params[k]).collect();
    // Probability of `+beta` per start, segment and axis.
    let mut up: Vec<f64> = vec![0.5; count * segments * axes];
    let mut best = vec![0.0f64; count];
    for _ in 0..options.iterations {
        let mut signs = Vec::with_capacity(count * options.population);
        let mut rollouts = Vec::with_capacity(count * options.population);
        for (i, start) in starts.chunks(n_state).enumerate() {
            let p = &up[i * segments * axes..(i + 1) * segments * axes];
            for _ in 0..options.population {
                let s: Vec<bool> = p.iter().map(|&q| rng.random_bool(q.clamp(0.0, 1.0))).collect();
                let inputs = s
                    .chunks(axes)
                    .map(|seg| seg.iter().zip(&bounds).map(|(&plus, &b)| if plus { b } else { -b }).collect())
                    .collect();
                let planner = PlannerPolicy::Schedule { inputs, segment: options.segment };
                rollouts.push(Rollout::new(system, start, planner, Gradient::Model, StdRng::seed_from_u64(0)));
                signs.push(s);
            }
        }
        scene.roll_out(&mut rollouts)?;
        for i in 0..count {
            let members = i * options.population..(i + 1) * options.population;
            let mut order: Vec<usize> = members.collect();
            order.sort_by(|&a, &b| scene.score(&rollouts[b]).total_cmp(&scene.score(&rollouts[a])));
            best[i] = best[i].max(scene.score(&rollouts[order[0]]));
            let p = &mut up[i * segments * axes..(i + 1) * segments * axes];
            for (k, q) in p.iter_mut().enumerate() {
                let frequency =
                    order[..options.elites].iter().filter(|&&m| signs[m][k]).count() as f64 / options.elites as f64;
                *q = (1.0 - options.smoothing) * *q + options.smoothing * frequency;
            }
        }
    }
    Ok(best)
}
