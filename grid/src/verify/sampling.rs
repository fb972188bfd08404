//! Uniform samples of a learned sublevel set `{V <= level}` by rejection from a box, or of its zero-error slice.
//!
//! The box is the manifest's state box with each error coordinate narrowed to `[-w, w]`, `w = factor level`:
//! since `V >= l` for a value function of the tracking error, the set lies within `|e| <= level` and the
//! narrowing only discards proposals that could not be accepted. A learned `V` can dip below `l`, so the
//! narrowing is checked rather than trusted: an accepted state within 5% of a narrowed edge means the set may
//! reach past it, and sampling stops with an error instead of returning a biased sample. An accepted state
//! near the trained domain's edge on an error coordinate is recorded
//! ([`SublevelSampler::reached_domain_edge`]): the set reaches past the domain there, where `V` is
//! extrapolated.

use super::VerifyError;
use fastrack_valuefn::manifest::Manifest;
use fastrack_valuefn::runtime::Evaluator;
use fastrack_valuefn::system::AffineSystem;
use rand::rngs::StdRng;
use rand::Rng;
use rayon::prelude::*;

/// Proposals per graph call.
const PROPOSAL_CHUNK: usize = 8192;
/// An accepted state this close to a narrowed edge (as a share of the half-width) stops the sampling.
const EDGE_GUARD: f64 = 0.95;

/// Where a sampled check draws its states from.
pub(super) trait StateSource {
    /// `count` more states, row-major.
    fn draw(&mut self, count: usize, rng: &mut StdRng) -> Result<Vec<f64>, VerifyError>;

    /// Share of the states considered that lay in the set.
    fn acceptance(&self) -> f64;
}

/// Draws uniform states of `{V <= level}` for one parameter vector.
pub(super) struct SublevelSampler<'a> {
    evaluator: &'a Evaluator,
    params: Vec<f32>,
    level: f64,
    lo: Vec<f64>,
    hi: Vec<f64>,
    /// Error coordinates whose range was narrowed, with their half-width.
    narrowed: Vec<(usize, f64)>,
    /// The trained domain's range of each error coordinate.
    error_domain: Vec<(usize, f64, f64)>,
    /// Whether an accepted state lay within 5% of the trained domain's edge on an error coordinate.
    pub reached_domain_edge: bool,
    names: Vec<String>,
    /// Proposals drawn so far.
    pub proposed: usize,
    /// Proposals accepted so far.
    pub accepted: usize,
    max_proposals: usize,
}

impl<'a> SublevelSampler<'a> {
    /// A sampler of `{V <= level}` at `params`, with error coordinates narrowed to `factor level` (a factor of
    /// 0 keeps the whole box).
    pub fn new(
        evaluator: &'a Evaluator,
        manifest: &Manifest,
        system: &AffineSystem,
        params: &[f64],
        level: f64,
        factor: f64,
        max_proposals: usize,
    ) -> Self {
        let (mut lo, mut hi): (Vec<f64>, Vec<f64>) = manifest.state.iter().map(|d| (d.min, d.max)).unzip();
        let mut narrowed = Vec::new();
        if factor > 0.0 {
            for &i in &system.error_coords {
                let w = factor * level;
                if -w > lo[i] || w < hi[i] {
                    lo[i] = lo[i].max(-w);
                    hi[i] = hi[i].min(w);
                    narrowed.push((i, w));
                }
            }
        }
        Self {
            evaluator,
            params: params.iter().map(|&p| p as f32).collect(),
            level,
            error_domain: system
                .error_coords
                .iter()
                .map(|&i| (i, manifest.state[i].min, manifest.state[i].max))
                .collect(),
            lo,
            hi,
            narrowed,
            reached_domain_edge: false,
            names: manifest.state.iter().map(|d| d.name.clone()).collect(),
            proposed: 0,
            accepted: 0,
            max_proposals,
        }
    }

    /// The same set's sampler on its zero-error slice: every error coordinate pinned at 0 (the tracker on the
    /// planner, where a start or a planner reset puts a robot), the others uniform over the box; its counts
    /// start afresh.
    pub fn on_zero_error_slice(mut self, system: &AffineSystem) -> Self {
        for &i in &system.error_coords {
            (self.lo[i], self.hi[i]) = (0.0, 0.0);
        }
        self.narrowed.clear();
        (self.proposed, self.accepted) = (0, 0);
        self
    }

    /// Whether `state` lies within 5% of the trained domain's edge on an error coordinate.
    fn at_domain_edge(&self, state: &[f64]) -> bool {
        self.error_domain.iter().any(|&(i, lo, hi)| (state[i] - 0.5 * (hi + lo)).abs() > EDGE_GUARD * 0.5 * (hi - lo))
    }

    /// The level sampled under.
    pub fn level(&self) -> f64 {
        self.level
    }

    /// The level whose sublevel set holds the share `acceptance` of this sampler's proposal box, estimated from
    /// a pilot of proposals: the value quantile at that share. Where it lies above this sampler's level, a
    /// sampler at it draws from a wider box, in which its set holds a smaller share.
    pub fn quantile_level(&self, acceptance: f64, rng: &mut StdRng) -> Result<f64, VerifyError> {
        let n_state = self.lo.len();
        // Enough proposals that the quantile holds about 100 of them.
        let pilot = ((100.0 / acceptance).ceil() as usize).clamp(PROPOSAL_CHUNK, 50 * PROPOSAL_CHUNK);
        let states: Vec<f32> = (0..pilot * n_state)
            .map(|k| rng.random_range(self.lo[k % n_state]..=self.hi[k % n_state]) as f32)
            .collect();
        let params: Vec<f32> = self.params.iter().copied().cycle().take(pilot * self.params.len()).collect();
        let chunk = PROPOSAL_CHUNK;
        let values: Vec<Vec<f32>> = states
            .par_chunks(chunk * n_state)
            .zip(params.par_chunks(chunk * self.params.len()))
            .map(|(s, p)| self.evaluator.evaluate(s, p).map(|e| e.value))
            .collect::<Result<_, _>>()?;
        let mut values: Vec<f64> = values.into_iter().flatten().map(f64::from).collect();
        values.sort_by(f64::total_cmp);
        let k = ((acceptance * pilot as f64).ceil() as usize).clamp(1, pilot) - 1;
        Ok(values[k])
    }
}

impl StateSource for SublevelSampler<'_> {
    /// Share of the proposals accepted so far.
    fn acceptance(&self) -> f64 {
        if self.proposed == 0 {
            0.0
        } else {
            self.accepted as f64 / self.proposed as f64
        }
    }

    fn draw(&mut self, count: usize, rng: &mut StdRng) -> Result<Vec<f64>, VerifyError> {
        let n_state = self.lo.len();
        let mut out = Vec::with_capacity(count * n_state);
        while out.len() < count * n_state {
            if self.proposed >= self.max_proposals {
                return Err(VerifyError::Sampling {
                    beta: f64::from(self.params[0]),
                    level: self.level,
                    accepted: self.accepted,
                    proposed: self.proposed,
                });
            }
            let threads = rayon::current_num_threads().max(1);
            let proposals: Vec<Vec<f64>> = (0..threads)
                .map(|_| {
                    (0..PROPOSAL_CHUNK)
                        .flat_map(|_| {
                            (0..n_state).map(|i| rng.random_range(self.lo[i]..=self.hi[i])).collect::<Vec<_>>()
                        })
                        .collect()
                })
                .collect();
            let values: Vec<Vec<f32>> = proposals
                .par_iter()
                .map(|states| {
                    let s: Vec<f32> = states.iter().map(|&x| x as f32).collect();
                    let p: Vec<f32> =
                        self.params.iter().copied().cycle().take(PROPOSAL_CHUNK * self.params.len()).collect();
                    self.evaluator.evaluate(&s, &p).map(|e| e.value)
                })
                .collect::<Result<_, _>>()?;
            for (states, values) in proposals.iter().zip(&values) {
                self.proposed += PROPOSAL_CHUNK;
                for (state, &v) in states.chunks(n_state).zip(values) {
                    if f64::from(v) > self.level {
                        continue;
                    }
                    self.accepted += 1;
                    self.reached_domain_edge |= self.at_domain_edge(state);
                    if let Some(&(i, w)) = self.narrowed.iter().find(|&&(i, w)| state[i].abs() > EDGE_GUARD * w) {
                        return Err(VerifyError::Setting(format!(
                            "a state of {{V <= {}}} lies at {} on `{}`, at the edge of the proposal box (+-{w}): the learned value dips below the tracking error there; raise the proposal box factor",
                            self.level, state[i], self.names[i]
                        )));
                    }
                    if out.len() < count * n_state {
                        out.extend_from_slice(state);
                    }
                }
            }
        }
        Ok(out)
    }
}
