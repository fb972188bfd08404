//! Falsification over the start state: where the sampled checks look at random states of the certified set,
//! this search climbs towards its worst one. From the samples the other checks pushed furthest, each
//! iteration proposes `population` states in a box around each start's best state so far (half-width
//! `scale` times each coordinate's width, halved every iteration), keeps those inside the certified set
//! `{V <= level}`, rolls them out against the worst-case planners, and moves each start to its proposal that
//! reached the largest error (on the verification's [`ErrorScale`](super::ErrorScale)).

use super::batch::{Gradient, Rollout, Scene};
use super::VerifyError;
use fastrack_valuefn::simulation::PlannerPolicy;
use rand::rngs::StdRng;
use rand::{Rng, SeedableRng};
use serde::{Deserialize, Serialize};

/// How the falsification runs.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct FalsificationOptions {
    /// Starts searched per round: the samples the other checks pushed to the largest errors (0 turns the
    /// search off).
    pub starts: usize,
    /// Proposals per start and iteration.
    pub population: usize,
    /// Iterations.
    pub iterations: usize,
    /// Half-width of the first iteration's proposal box around a start, as a share of each coordinate's
    /// width in the trained domain.
    pub scale: f64,
}

impl Default for FalsificationOptions {
    fn default() -> Self {
        Self { starts: 64, population: 16, iterations: 4, scale: 0.05 }
    }
}

impl FalsificationOptions {
    /// Whether the search runs at all.
    pub fn enabled(&self) -> bool {
        self.starts > 0 && self.population > 0 && self.iterations > 0
    }

    /// Why these options cannot run, if they cannot.
    pub fn check(&self) -> Result<(), VerifyError> {
        if !self.enabled() || (self.scale.is_finite() && self.scale > 0.0 && self.scale <= 1.0) {
            Ok(())
        } else {
            Err(VerifyError::Setting(format!("falsification: scale = {} must lie in (0, 1]", self.scale)))
        }
    }
}

/// What the falsification found.
pub(super) struct Falsified {
    /// The largest error reached from each start (its own error at the start included).
    pub errors: Vec<f64>,
    /// Rollouts played.
    pub rollouts: usize,
}

/// Climbs from `starts` (row-major states, with the largest error each already reached) towards the states
/// of `{V <= level}` whose rollouts reach the largest errors. `box_lo`, `box_hi`: the trained domain.
pub(super) fn falsify(
    scene: &Scene<'_>,
    starts: &[f64],
    reached: &[f64],
    level: f64,
    (box_lo, box_hi): (&[f64], &[f64]),
    options: &FalsificationOptions,
    rng: &mut StdRng,
) -> Result<Falsified, VerifyError> {
    let system = scene.system;
    let n_state = system.n_state();
    let mut best: Vec<Vec<f64>> = starts.chunks(n_state).map(<[f64]>::to_vec).collect();
    let mut errors = reached.to_vec();
    let mut families = vec![Gradient::Model];
    if scene.grid.is_some() {
        families.push(Gradient::Grid);
    }
    let mut rollouts_played = 0;
    for iteration in 0..options.iterations {
        let half = options.scale * 0.5f64.powi(iteration as i32);
        let proposals: Vec<(usize, Vec<f64>)> = best
            .iter()
            .enumerate()
            .flat_map(|(i, centre)| (0..options.population).map(move |_| (i, centre.clone())))
            .map(|(i, mut state)| {
                for (k, x) in state.iter_mut().enumerate() {
                    let width = box_hi[k] - box_lo[k];
                    *x = (*x + half * width * rng.random_range(-1.0..=1.0)).clamp(box_lo[k], box_hi[k]);
                }
                (i, state)
            })
            .collect();
        let flat: Vec<f32> = proposals.iter().flat_map(|(_, s)| s.iter().map(|&x| x as f32)).collect();
        let params: Vec<f32> =
            scene.params.iter().map(|&p| p as f32).cycle().take(proposals.len() * scene.params.len()).collect();
        let values = scene.evaluator.evaluate(&flat, &params)?.value;
        let inside: Vec<&(usize, Vec<f64>)> =
            proposals.iter().zip(&values).filter(|(_, &v)| f64::from(v) <= level).map(|(p, _)| p).collect();
        let mut rollouts = Vec::with_capacity(inside.len() * families.len());
        for (_, state) in &inside {
            for &gradient in &families {
                let seed = StdRng::seed_from_u64(rng.random());
                rollouts.push(Rollout::new(system, state, PlannerPolicy::WorstCase, gradient, seed));
            }
        }
        scene.roll_out(&mut rollouts)?;
        rollouts_played += rollouts.len();
        for ((i, state), per_family) in inside.iter().zip(rollouts.chunks(families.len())) {
            let error = per_family.iter().map(|r| scene.score(r)).fold(0.0, f64::max);
            if error > errors[*i] {
                errors[*i] = error;
                best[*i].clone_from(state);
            }
        }
    }
    Ok(Falsified { errors, rollouts: rollouts_played })
}
