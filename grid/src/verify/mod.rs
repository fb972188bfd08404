//! Scenario verification of a bundle's TEB table (after Lin & Bansal's verification of DeepReach), with their
//! iterated level correction.
//!
//! For each row, a round samples `N` states uniformly from the learned sublevel set `{V <= c}` by rejection
//! ([`sampling`]) and rolls each out (RK4, fixed step, control and planner held over each step, [`batch`]) with
//! the served tracker control against every planner family: the worst-case planner of the model's own
//! gradient, the worst-case planner of a grid solution's gradient (where one is given near the row's `beta`),
//! random bang-bang planners, and a cross-entropy search over planner schedules ([`search`]) from the samples
//! of each batch the others pushed furthest. A sample *violates* the round when its error exceeds
//! `(1 + slack) c`. Once a round's uniform samples hold, the same set is checked where robots are: uniform
//! samples of its zero-error slice (error coordinates at 0, where starts and planner resets put a robot),
//! draws from the states the online loop visited in simulated runs that lie in the set ([`operational`]),
//! and a falsification search over start states ([`falsify`]) from the samples the others pushed furthest; a
//! violation in any ends the round as one in the uniform samples does. The first round samples under
//! `(1 + margin) level`, or under the level whose set holds a given share of the proposal box where that is
//! higher; a round with a violation ends there, the level is raised to the largest error seen, and the next
//! round samples afresh, until a round rolls out all `N` samples of every check without a violation. A row
//! whose rounds run out, or whose raised level would take the set past the trained domain's error coordinates,
//! is not verified: its violations stay in the report and in the manifest. That is the
//! [`Correction::Set`] correction. [`Correction::Bound`] runs one round on the first set, rolls out every
//! sample of every check whatever it reaches, and takes the largest error as the bound; its samples can be
//! split into pieces ([`pieces`]) that run apart and combine into that round.
//!
//! With `N` samples of a distribution in the final round, `(1 - eps)^N <= delta` ([`required_samples`]), the largest error
//! over them bounds the error from all but an `eps` fraction (by that distribution's measure) of `{V <= c}`,
//! with confidence `1 - delta` (scenario approach, one decision variable: the level), for these planner
//! families and this horizon; under the set correction it is at most `(1 + slack) c`. The search only adds
//! evidence: it can raise the largest error, never lower it, and the samples it starts from are chosen by the
//! other families' errors, so the guarantee is stated for them.
//!
//! A composed value (a system decomposed into axes) is verified through its axes instead ([`axes`]): each
//! axis network on its own, every error taken less the value at its start ([`ErrorScale`]), which certifies
//! every level of the composite at once.

pub mod axes;
mod batch;
mod falsify;
mod operational;
mod pieces;
mod sampling;
mod search;

pub use batch::Batching;
pub use falsify::FalsificationOptions;
pub use operational::{InForce, RecordedStates};
pub use pieces::combine_pieces;
pub use search::SearchOptions;

use crate::solver::Solution;
use batch::{Gradient, Rollout, Scene};
use fastrack_lab::shard::Shard;
use fastrack_valuefn::manifest::{CheckResult, Manifest, PlannerResult, TebRow, Verification};
use fastrack_valuefn::runtime::{Evaluator, RuntimeError};
use fastrack_valuefn::simulation::PlannerPolicy;
use fastrack_valuefn::system::AffineSystem;
use fastrack_valuefn::teb::{reshape_at_set_levels, TebOptions};
use indicatif::ProgressBar;
use operational::RecordedSampler;
use rand::rngs::StdRng;
use rand::{Rng, SeedableRng};
use sampling::{StateSource, SublevelSampler};
use serde::{Deserialize, Serialize};
use std::time::Instant;

/// Smallest raise of the level between rounds, as a share of it (so rounds make progress).
const MIN_RAISE: f64 = 0.005;

/// What the level correction raises after a round with a violation.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, clap::ValueEnum)]
#[serde(rename_all = "kebab-case")]
pub enum Correction {
    /// The sampled set and the bound together: the next round samples `{V <= c}` at the raised `c`, so the
    /// certified set must hold its own level (a set a tracker inside stays within, in error).
    Set,
    /// The bound alone: one round samples the first set, rolls out all its samples, and bounds the error from
    /// that set by the largest error reached (nothing to raise: the bound is the scenario program's solution).
    Bound,
}

impl Correction {
    /// Its name in records and manifests.
    pub fn name(self) -> &'static str {
        match self {
            Correction::Set => "set",
            Correction::Bound => "bound",
        }
    }
}

/// Whose control law the tracker plays in the rollouts.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, Deserialize, clap::ValueEnum)]
#[serde(rename_all = "kebab-case")]
pub enum ControlLaw {
    /// The bundle's served control: what verification certifies.
    #[default]
    Model,
    /// The optimal control of the row's grid solution (central differences of its interpolant), on the
    /// bundle's own sampled sets: a reference that separates what the learned control loses from what the
    /// learned sets hold. Its results are not a verification of the bundle.
    Grid,
}

/// What a rollout's largest error is measured against.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum ErrorScale {
    /// The error itself (m): a bound on the error from one set `{V <= c}`.
    #[default]
    Absolute,
    /// The error less the value at its start, `max_t |e(t)| - V(r(0))`: a bound `delta` on it gives
    /// `|e(t)| <= V(r(0)) + delta` from every start of the sampled set, so it bounds every level below the
    /// sampled one at once (`L + delta` from `{V <= L}`). How the axes of a composed value are verified
    /// ([`axes`]). A correct value keeps it at most 0, up to the fit and the held control.
    ExcessOverStartValue,
}

impl ErrorScale {
    /// Its name in records and manifests.
    pub fn name(self) -> &'static str {
        match self {
            ErrorScale::Absolute => "absolute",
            ErrorScale::ExcessOverStartValue => "excess-over-start-value",
        }
    }
}

/// How to verify.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct VerifyOptions {
    /// Violation-probability bound epsilon.
    pub eps: f64,
    /// The first round samples `{V <= (1 + level_margin) level}`.
    pub level_margin: f64,
    /// Confidence parameter delta.
    pub delta: f64,
    /// Largest number of rounds of the `set` correction (the `bound` correction has one).
    pub max_rounds: usize,
    /// What the correction raises.
    pub correction: Correction,
    /// A sample violates a round when its error exceeds `(1 + slack)` times the round's level: room for a
    /// control held over each step, which lets the error creep slightly past a continuous-time bound.
    pub slack: f64,
    /// Rollout horizon (s).
    pub horizon: f64,
    /// RK4 step; the control and the planner are held over a step (s).
    pub step: f64,
    /// Random bang-bang planners per sample (besides the worst-case planners).
    pub random_planners: usize,
    /// Mean time between a random planner's switches (s).
    pub mean_dwell: f64,
    /// The cross-entropy search over planner schedules.
    pub search: SearchOptions,
    /// Also sample the zero-error slice of each round's set (as many samples as the uniform check).
    #[serde(default = "yes")]
    pub zero_error_slice: bool,
    /// The falsification search over start states.
    #[serde(default)]
    pub falsification: FalsificationOptions,
    /// Samples rolled out together (each round checks for violations after every such batch).
    pub batch: usize,
    /// How the rollouts are fed to ONNX Runtime.
    pub batching: Batching,
    /// Error coordinates of the proposals are drawn within `proposal_box` times the sampled level (0: the
    /// whole state box).
    pub proposal_box: f64,
    /// Largest number of proposals per round before giving up on rejection sampling.
    pub max_proposals: usize,
    /// The first round samples under at least the level whose sublevel set holds this share of the proposal
    /// box (measured on a pilot of proposals), so that a narrow minimum can be sampled; 0 keeps
    /// `(1 + level_margin) level`.
    pub min_acceptance: f64,
    /// Whose control law the tracker plays.
    #[serde(default)]
    pub control_law: ControlLaw,
    /// Each row's samples are split into this many pieces, each rolled out on its own (and, sharded, in its
    /// own process) with its own random stream, and combined into the row's one round (the `bound` correction
    /// only: a `set` round's outcome decides the next round's level, so its samples cannot be split).
    #[serde(default = "one")]
    pub pieces: usize,
    /// What a rollout's largest error is measured against (levels, bounds and checks are on this scale).
    #[serde(default)]
    pub error_scale: ErrorScale,
    /// Random seed.
    pub seed: u64,
}

impl Default for VerifyOptions {
    fn default() -> Self {
        Self {
            eps: 1e-3,
            level_margin: 0.05,
            delta: 1e-6,
            max_rounds: 8,
            correction: Correction::Set,
            slack: 0.02,
            horizon: 10.0,
            step: 0.01,
            random_planners: 2,
            mean_dwell: 1.0,
            search: SearchOptions::default(),
            zero_error_slice: true,
            falsification: FalsificationOptions::default(),
            batch: 4096,
            batching: Batching::default(),
            proposal_box: 2.5,
            max_proposals: 20_000_000,
            min_acceptance: 5e-3,
            control_law: ControlLaw::Model,
            pieces: 1,
            error_scale: ErrorScale::Absolute,
            seed: 11,
        }
    }
}

/// Samples needed for `eps` and `delta`: the least `N` with `(1 - eps)^N <= delta`, i.e.
/// `ceil(ln delta / ln(1 - eps))` (13,809 at `eps` 1e-3, `delta` 1e-6).
///
/// A round decides one number from its samples (the bound, their largest error, or the pass of a fixed
/// level), a scenario program with one decision variable, for which Campi and Garatti's bound is exact:
/// the probability that more than an `eps` fraction of the set exceeds it is at most `(1 - eps)^N`. The
/// sufficient `(2 / eps)(ln(1 / delta) + 1)` (29,632) that covers any number of decision variables
/// certifies the same `eps` and `delta` with twice the samples.
pub fn required_samples(eps: f64, delta: f64) -> usize {
    (delta.ln() / (-eps).ln_1p()).ceil() as usize
}

/// Why a verification could not run.
#[derive(Debug, thiserror::Error)]
pub enum VerifyError {
    /// A setting is out of range.
    #[error("{0}")]
    Setting(String),
    /// The certified sets could not be measured.
    #[error("measuring the certified set at its level: {0}")]
    Shape(String),
    /// The bundle's system is not the one given.
    #[error("the bundle is for system `{bundle}`, not `{system}`")]
    System {
        /// In the manifest.
        bundle: String,
        /// Given.
        system: String,
    },
    /// Rejection sampling found too few states in the sublevel set.
    #[error(
        "beta {beta}: only {accepted} of {proposed} uniform states satisfy V <= {level}; the sublevel set is too small to sample (raise --level-margin or --max-proposals, or check the table)"
    )]
    Sampling {
        /// Row.
        beta: f64,
        /// Its level.
        level: f64,
        /// Accepted states.
        accepted: usize,
        /// Proposals drawn.
        proposed: usize,
    },
    /// A row's sampled set reached the trained domain's edge: it cannot be served as verified.
    #[error(
        "row beta {beta}: the set {{V <= {level}}} reaches the trained domain's edge, where the model is extrapolated; the row is not verified (a smaller --level-margin or a model trained on a wider domain)"
    )]
    LeftDomain {
        /// Row.
        beta: f64,
        /// The level of the set sampled.
        level: f64,
    },
    /// The recorded operational states cannot be read or sampled.
    #[error("operational states: {0}")]
    Operational(String),
    /// ONNX Runtime failed.
    #[error(transparent)]
    Runtime(#[from] RuntimeError),
}

/// A planner family of the verification.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Family {
    /// The worst case of the model's own gradient.
    ModelWorstCase,
    /// The worst case of a grid solution's gradient.
    GridWorstCase,
    /// Random bang-bang planners.
    RandomBangBang,
    /// The cross-entropy search over planner schedules.
    Search,
}

impl Family {
    /// Every family, in report order.
    pub const ALL: [Family; 4] =
        [Family::ModelWorstCase, Family::GridWorstCase, Family::RandomBangBang, Family::Search];

    /// Its name in records and manifests.
    pub fn name(self) -> &'static str {
        match self {
            Family::ModelWorstCase => "model-worst-case",
            Family::GridWorstCase => "grid-worst-case",
            Family::RandomBangBang => "random-bang-bang",
            Family::Search => "search",
        }
    }
}

/// One round of the level correction.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct RoundReport {
    /// The level errors were checked against.
    pub level: f64,
    /// The level the round sampled under (the same as `level` when the correction raises the set).
    pub sampled_level: f64,
    /// Samples rolled out before the round ended.
    pub samples: usize,
    /// Those whose error exceeded `(1 + slack)` times the level.
    pub violations: usize,
    /// The largest error reached.
    pub max_error: f64,
    /// Share of the proposals accepted by rejection sampling.
    pub acceptance: f64,
    /// Each check of the round in the order it ran (a check after one with a violation does not run).
    #[serde(default)]
    pub checks: Vec<CheckResult>,
    /// With the operational check: the recorded states taken while this row was in force, and how many lie
    /// outside the round's set.
    #[serde(default)]
    pub in_force: Option<InForce>,
}

/// The check of uniform samples of the round's set.
pub const UNIFORM: &str = "uniform";
/// The check of uniform samples of the set's zero-error slice.
pub const ZERO_ERROR_SLICE: &str = "zero-error-slice";
/// The check of draws from the recorded states of the online loop that lie in the round's set.
pub const OPERATIONAL: &str = "operational";
/// The falsification search over start states.
pub const FALSIFICATION: &str = "falsification";

/// How the level correction of a row ended.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Outcome {
    /// A round rolled out every sample without a violation: the row is verified.
    Verified,
    /// Every round had a violation.
    RoundsExhausted,
    /// A round's sampled set reached the trained domain's edge on an error coordinate (an accepted state within
    /// 5% of it): past it the model is extrapolated, so the row cannot be verified at that level or above.
    LeftDomain,
}

/// The result for one TEB row.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct RowReport {
    /// Planner speed bound.
    pub beta: f64,
    /// The row's learned level.
    pub level: f64,
    /// Every round, the last one the certificate.
    pub rounds: Vec<RoundReport>,
    /// How the correction ended.
    pub outcome: Outcome,
    /// What was written into the row.
    pub verification: Verification,
    /// The `beta` of the grid solution whose worst-case planner played, if one did.
    pub grid_beta: Option<f64>,
    /// Samples of the final round the search ran on.
    pub searched: usize,
    /// Rollout steps taken over all rounds (states times steps, the search's included).
    pub rollout_steps: u64,
    /// Wall time of the row (s): the sum of its pieces' when it was split.
    pub wall_s: f64,
    /// Which piece of the row's samples this report covers (none: all of them).
    #[serde(default)]
    pub piece: Option<Shard>,
}

impl RowReport {
    /// The level the final round sampled under.
    pub fn sampled_level(&self) -> f64 {
        self.rounds.last().map_or(f64::NAN, |r| r.sampled_level)
    }
}

fn check(options: &VerifyOptions) -> Result<(), VerifyError> {
    let ok = |x: f64| x.is_finite() && x > 0.0;
    if !(ok(options.eps) && options.eps < 1.0 && ok(options.delta) && options.delta < 1.0) {
        return Err(VerifyError::Setting(format!(
            "eps = {} and delta = {} must lie in (0, 1)",
            options.eps, options.delta
        )));
    }
    if !(options.level_margin.is_finite() && options.level_margin >= 0.0) {
        return Err(VerifyError::Setting(format!("level margin = {} must be >= 0", options.level_margin)));
    }
    if !(ok(options.horizon) && ok(options.step) && options.step <= options.horizon && ok(options.mean_dwell)) {
        return Err(VerifyError::Setting(format!(
            "horizon = {}, step = {} and mean dwell = {} must be positive with step <= horizon",
            options.horizon, options.step, options.mean_dwell
        )));
    }
    if !(options.slack.is_finite() && options.slack >= 0.0) {
        return Err(VerifyError::Setting(format!("slack = {} must be >= 0", options.slack)));
    }
    if options.max_rounds == 0 || options.batch == 0 || options.pieces == 0 {
        return Err(VerifyError::Setting(format!(
            "max rounds = {}, batch = {} and pieces = {} must be at least 1",
            options.max_rounds, options.batch, options.pieces
        )));
    }
    if options.pieces > 1 && options.correction != Correction::Bound {
        return Err(VerifyError::Setting(format!(
            "pieces = {}: only the bound correction's one round can be split into pieces",
            options.pieces
        )));
    }
    if options.error_scale == ErrorScale::ExcessOverStartValue && options.correction != Correction::Bound {
        return Err(VerifyError::Setting(
            "an excess over the start's value is bounded by the bound correction's one round: it is no level to sample under"
                .into(),
        ));
    }
    if !(0.0..1.0).contains(&options.min_acceptance) {
        return Err(VerifyError::Setting(format!("min acceptance = {} must lie in [0, 1)", options.min_acceptance)));
    }
    if !(options.proposal_box.is_finite() && (options.proposal_box == 0.0 || options.proposal_box >= 1.0)) {
        return Err(VerifyError::Setting(format!(
            "proposal box = {} must be 0 (the whole box) or at least 1",
            options.proposal_box
        )));
    }
    options.search.check()?;
    options.falsification.check()
}

fn yes() -> bool {
    true
}

fn one() -> usize {
    1
}

/// The grid solution among `adversaries` nearest the row's `beta`, if one lies within `tolerance` of it.
pub fn nearest_adversary(adversaries: &[Solution], beta: f64, tolerance: f64) -> Option<&Solution> {
    adversaries
        .iter()
        .filter(|s| s.info.params.iter().all(|&p| (p - beta).abs() <= tolerance))
        .min_by(|a, b| (a.info.params[0] - beta).abs().total_cmp(&(b.info.params[0] - beta).abs()))
}

/// The largest error per family and the rollouts each played, accumulated over a round.
#[derive(Default)]
struct FamilyTally {
    max_error: [f64; 4],
    rollouts: [usize; 4],
}

impl FamilyTally {
    fn add(&mut self, family: Family, error: f64) {
        let i = family as usize;
        self.max_error[i] = self.max_error[i].max(error);
        self.rollouts[i] += 1;
    }

    fn results(&self) -> Vec<PlannerResult> {
        Family::ALL
            .iter()
            .filter(|&&f| self.rollouts[f as usize] > 0)
            .map(|&f| PlannerResult {
                family: f.name().into(),
                rollouts: self.rollouts[f as usize],
                max_error: self.max_error[f as usize],
            })
            .collect()
    }
}

/// What a round found.
struct Round {
    report: RoundReport,
    /// Whether a sampled state lay at the trained domain's edge on an error coordinate.
    reached_domain_edge: bool,
    tally: FamilyTally,
    searched: usize,
    rollout_steps: u64,
}

/// What the samples of one sampled check reached.
struct Sampled {
    check: CheckResult,
    acceptance: f64,
    /// The starts whose errors were largest, row-major, with those errors (largest first).
    worst: (Vec<f64>, Vec<f64>),
}

/// One round with errors checked against `level`: the uniform samples of the round's set, then (each only if
/// every check before it held) the samples of its zero-error slice, the draws from the recorded operational
/// states inside it, and the falsification search from the starts the sampled checks pushed furthest. Each
/// sampled check rolls out batches until its samples are done or a batch has a violation.
#[allow(clippy::too_many_arguments)]
fn run_round(
    scene: &Scene<'_>,
    mut sampler: SublevelSampler<'_>,
    operational: Option<&RecordedStates>,
    domain: (&[f64], &[f64]),
    level: f64,
    n: usize,
    options: &VerifyOptions,
    rng: &mut StdRng,
) -> Result<Round, VerifyError> {
    let mut tally = FamilyTally::default();
    let sampled_level = sampler.level();
    let limit = (1.0 + options.slack) * level;
    let SampledRun { sampled, mut searched, mut rollout_steps } =
        run_samples(scene, &mut sampler, UNIFORM, level, n, options, rng, &mut tally)?;
    let acceptance = sampled.acceptance;
    let mut reached_domain_edge = sampler.reached_domain_edge;
    let mut checks = vec![sampled.check];
    let mut worst = vec![sampled.worst];
    // A check whose set holds (almost) none of its distribution's states rolls nothing out, and says so.
    let empty = |distribution: &str| CheckResult {
        distribution: distribution.into(),
        samples: 0,
        violations: 0,
        max_error: 0.0,
    };
    let mut add = |run: SampledRun, checks: &mut Vec<CheckResult>| {
        searched += run.searched;
        rollout_steps += run.rollout_steps;
        checks.push(run.sampled.check);
        worst.push(run.sampled.worst);
    };
    if options.zero_error_slice && checks[0].violations == 0 {
        let mut slice_sampler = sampler.on_zero_error_slice(scene.system);
        match run_samples(scene, &mut slice_sampler, ZERO_ERROR_SLICE, level, n, options, rng, &mut tally) {
            Ok(run) => add(run, &mut checks),
            Err(VerifyError::Sampling { .. }) => checks.push(empty(ZERO_ERROR_SLICE)),
            Err(e) => return Err(e),
        }
        reached_domain_edge |= slice_sampler.reached_domain_edge;
    }
    let mut in_force = None;
    if let Some(recorded) = operational.filter(|_| checks.iter().all(|c| c.violations == 0)) {
        let mut recorded_sampler =
            RecordedSampler::new(scene.evaluator, scene.params, sampled_level, recorded, domain)?;
        in_force = Some(recorded_sampler.in_force);
        if recorded_sampler.inside() == 0 {
            checks.push(empty(OPERATIONAL));
        } else {
            let run = run_samples(scene, &mut recorded_sampler, OPERATIONAL, level, n, options, rng, &mut tally)?;
            add(run, &mut checks);
        }
    }
    if options.falsification.enabled() && checks.iter().all(|c| c.violations == 0) {
        let (starts, reached) = worst_starts(&worst, scene.system.n_state(), options.falsification.starts);
        let found = falsify::falsify(scene, &starts, &reached, sampled_level, domain, &options.falsification, rng)?;
        let steps_per_rollout = (options.horizon / options.step).round().max(1.0) as u64;
        rollout_steps += found.rollouts as u64 * steps_per_rollout;
        checks.push(CheckResult {
            distribution: FALSIFICATION.into(),
            samples: found.rollouts,
            violations: found.errors.iter().filter(|&&e| e > limit).count(),
            max_error: found.errors.iter().copied().fold(0.0, f64::max),
        });
    }
    Ok(Round {
        report: RoundReport {
            level,
            sampled_level,
            samples: checks[0].samples,
            violations: checks.iter().map(|c| c.violations).sum(),
            max_error: checks.iter().map(|c| c.max_error).fold(0.0, f64::max),
            acceptance,
            checks,
            in_force,
        },
        reached_domain_edge,
        tally,
        searched,
        rollout_steps,
    })
}

/// The `count` starts with the largest errors among the checks' worst starts, row-major, with their errors.
fn worst_starts(worst: &[(Vec<f64>, Vec<f64>)], n_state: usize, count: usize) -> (Vec<f64>, Vec<f64>) {
    let mut all: Vec<(f64, &[f64])> =
        worst.iter().flat_map(|(states, errors)| errors.iter().copied().zip(states.chunks(n_state))).collect();
    all.sort_by(|a, b| b.0.total_cmp(&a.0));
    all.truncate(count);
    (all.iter().flat_map(|(_, s)| s.to_vec()).collect(), all.iter().map(|(e, _)| *e).collect())
}

/// A sampled check's result and what it cost.
struct SampledRun {
    sampled: Sampled,
    searched: usize,
    rollout_steps: u64,
}

/// One sampled check: batches of samples rolled out against every planner family until `n` are done or a
/// batch has a violation of `level`.
#[allow(clippy::too_many_arguments)]
fn run_samples(
    scene: &Scene<'_>,
    sampler: &mut dyn StateSource,
    distribution: &str,
    level: f64,
    n: usize,
    options: &VerifyOptions,
    rng: &mut StdRng,
    tally: &mut FamilyTally,
) -> Result<SampledRun, VerifyError> {
    let system = scene.system;
    let n_state = system.n_state();
    let steps_per_rollout = (options.horizon / options.step).round().max(1.0) as u64;
    let mut families = vec![Family::ModelWorstCase];
    if scene.grid.is_some() {
        families.push(Family::GridWorstCase);
    }
    families.extend(std::iter::repeat_n(Family::RandomBangBang, options.random_planners));
    let (mut done, mut violations, mut max_error, mut searched, mut rollout_steps) = (0, 0, 0.0f64, 0, 0u64);
    let keep = options.falsification.starts;
    let mut worst: Vec<(f64, Vec<f64>)> = Vec::new();
    while done < n && violations == 0 {
        let count = options.batch.min(n - done);
        let samples = sampler.draw(count, rng)?;
        let mut rollouts = Vec::with_capacity(count * families.len());
        for state in samples.chunks(n_state) {
            for &family in &families {
                let (planner, gradient) = match family {
                    Family::GridWorstCase => (PlannerPolicy::WorstCase, Gradient::Grid),
                    Family::RandomBangBang => (PlannerPolicy::bang_bang(), Gradient::Model),
                    _ => (PlannerPolicy::WorstCase, Gradient::Model),
                };
                rollouts.push(Rollout::new(system, state, planner, gradient, StdRng::seed_from_u64(rng.random())));
            }
        }
        scene.roll_out(&mut rollouts)?;
        rollout_steps += rollouts.len() as u64 * steps_per_rollout;
        let mut errors: Vec<f64> = rollouts
            .chunks(families.len())
            .map(|per_sample| {
                for (r, &family) in per_sample.iter().zip(&families) {
                    tally.add(family, scene.score(r));
                }
                per_sample.iter().map(|r| scene.score(r)).fold(0.0, f64::max)
            })
            .collect();
        if options.search.enabled() {
            let mut chosen: Vec<usize> = (0..count).collect();
            chosen.sort_by(|&a, &b| errors[b].total_cmp(&errors[a]));
            chosen.truncate(options.search.per_batch);
            let starts: Vec<f64> =
                chosen.iter().flat_map(|&j| samples[j * n_state..(j + 1) * n_state].to_vec()).collect();
            let found = search::search(scene, &starts, &options.search, rng)?;
            for (&j, &e) in chosen.iter().zip(&found) {
                tally.add(Family::Search, e);
                errors[j] = errors[j].max(e);
            }
            searched += chosen.len();
            rollout_steps +=
                (chosen.len() * options.search.population * options.search.iterations) as u64 * steps_per_rollout;
        }
        violations += errors.iter().filter(|&&e| e > (1.0 + options.slack) * level).count();
        max_error = errors.iter().copied().fold(max_error, f64::max);
        worst.extend(errors.iter().zip(samples.chunks(n_state)).map(|(&e, s)| (e, s.to_vec())));
        worst.sort_by(|a, b| b.0.total_cmp(&a.0));
        worst.truncate(keep);
        done += count;
    }
    let (errors, states): (Vec<f64>, Vec<Vec<f64>>) = worst.into_iter().unzip();
    Ok(SampledRun {
        sampled: Sampled {
            check: CheckResult { distribution: distribution.into(), samples: done, violations, max_error },
            acceptance: sampler.acceptance(),
            worst: (states.concat(), errors),
        },
        searched,
        rollout_steps,
    })
}

/// Verifies one row (or, with `piece`, one piece of its samples) and returns the report (the row itself is
/// not modified). `grid` is the grid solution whose worst-case planner plays, if any; `operational`, the
/// recorded states of the online loop the operational check draws from, if any. With the `set` correction the
/// level is corrected round by round; with the `bound` correction one round rolls out every sample of the
/// first set and the bound is the largest error reached.
#[allow(clippy::too_many_arguments)]
pub fn verify_row(
    evaluator: &Evaluator,
    manifest: &Manifest,
    system: &AffineSystem,
    row: &TebRow,
    grid: Option<&Solution>,
    operational: Option<&RecordedStates>,
    options: &VerifyOptions,
    piece: Shard,
) -> Result<RowReport, VerifyError> {
    check(options)?;
    if piece.count != options.pieces {
        return Err(VerifyError::Setting(format!(
            "piece {piece} is not one of the {} pieces of a row",
            options.pieces
        )));
    }
    if manifest.system.id != system.id {
        return Err(VerifyError::System { bundle: manifest.system.id.clone(), system: system.id.into() });
    }
    if let Some(g) = grid {
        if g.info.system != system.id || g.grid.ndim() != system.n_state() {
            return Err(VerifyError::System { bundle: g.info.system.clone(), system: system.id.into() });
        }
    }
    if options.control_law == ControlLaw::Grid && grid.is_none() {
        return Err(VerifyError::Setting(format!(
            "row beta {}: the grid control law is a grid solution's policy, and none lies within the grid tolerance of this beta",
            row.beta
        )));
    }
    let started = Instant::now();
    let mut rng = StdRng::seed_from_u64(options.seed ^ row.beta.to_bits());
    let params = vec![row.beta; system.n_params()];
    let scene = Scene {
        evaluator,
        system,
        params: &params,
        grid,
        tracker: match options.control_law {
            ControlLaw::Model => Gradient::Model,
            ControlLaw::Grid => Gradient::Grid,
        },
        horizon: options.horizon,
        step: options.step,
        mean_dwell: options.mean_dwell,
        batching: options.batching,
        error_scale: options.error_scale,
    };
    let mut level = row.level * (1.0 + options.level_margin);
    if options.min_acceptance > 0.0 {
        let sampler = SublevelSampler::new(evaluator, manifest, system, &params, level, options.proposal_box, 0);
        level = level.max(sampler.quantile_level(options.min_acceptance, &mut rng)?);
    }
    // Every piece shares the row's level; its samples come from a stream of its own.
    let mut piece_options = options.clone();
    if !piece.is_whole() {
        rng = StdRng::seed_from_u64(rng.random::<u64>() ^ (piece.index as u64 + 1).wrapping_mul(0x9E37_79B9_7F4A_7C15));
        piece_options.falsification.starts = options.falsification.starts.div_ceil(piece.count);
    }
    let n = required_samples(options.eps, options.delta).div_ceil(piece.count);
    let (domain_lo, domain_hi): (Vec<f64>, Vec<f64>) = manifest.state.iter().map(|d| (d.min, d.max)).unzip();
    let domain = (&domain_lo[..], &domain_hi[..]);
    let sampler = |sampled_level: f64| {
        SublevelSampler::new(
            evaluator,
            manifest,
            system,
            &params,
            sampled_level,
            options.proposal_box,
            options.max_proposals,
        )
    };
    let (mut rounds, mut rollout_steps) = (Vec::new(), 0u64);
    let (last, outcome) = match options.correction {
        Correction::Bound => {
            // No level to break: every sample is rolled out, and the bound is the largest error (the scenario
            // program's solution for its one decision variable).
            let mut round =
                run_round(&scene, sampler(level), operational, domain, f64::INFINITY, n, &piece_options, &mut rng)?;
            round.report.level = round.report.max_error;
            rollout_steps += round.rollout_steps;
            rounds.push(round.report.clone());
            let outcome = if round.reached_domain_edge { Outcome::LeftDomain } else { Outcome::Verified };
            (round, outcome)
        }
        Correction::Set => loop {
            let round = run_round(&scene, sampler(level), operational, domain, level, n, options, &mut rng)?;
            tracing::info!(
                beta = row.beta,
                level,
                violations = round.report.violations,
                max_error = round.report.max_error,
                "round"
            );
            rollout_steps += round.rollout_steps;
            rounds.push(round.report.clone());
            if round.reached_domain_edge {
                break (round, Outcome::LeftDomain);
            }
            if round.report.violations == 0 {
                break (round, Outcome::Verified);
            }
            if rounds.len() >= options.max_rounds {
                break (round, Outcome::RoundsExhausted);
            }
            level = round.report.max_error.max(level * (1.0 + MIN_RAISE));
        },
    };
    Ok(RowReport {
        beta: row.beta,
        level: row.level,
        verification: Verification {
            verified_level: last.report.max_error,
            eps: options.eps,
            delta: options.delta,
            samples: last.report.samples,
            violations: last.report.violations,
            horizon: options.horizon,
            step: options.step,
            sampled_level: Some(last.report.sampled_level),
            correction: Some(options.correction.name().into()),
            rounds: rounds.len(),
            planners: last.tally.results(),
            checks: last.report.checks.clone(),
        },
        rounds,
        outcome,
        grid_beta: grid.map(|g| g.info.params[0]),
        searched: last.searched,
        rollout_steps,
        wall_s: started.elapsed().as_secs_f64(),
        piece: (!piece.is_whole()).then_some(piece),
    })
}

/// Which rows to verify and the grid solutions whose worst-case planners play.
#[derive(Debug, Clone, Copy, Default)]
pub struct Selection<'a> {
    /// Only the rows with these `beta` (every row when `None`).
    pub betas: Option<&'a [f64]>,
    /// Grid solutions; each row is played by the one nearest its `beta` within `grid_tolerance`.
    pub adversaries: &'a [Solution],
    /// Largest distance in `beta` between a row and the grid solution that plays it.
    pub grid_tolerance: f64,
    /// Recorded states of the online loop, for the operational check of every row (none: no such check).
    pub operational: Option<&'a RecordedStates>,
}

/// Verifies the rows of `manifest` the selection names, writing each
/// result into its row's `verification` (raised where needed to keep the bounds monotone in `beta`) and
/// every row's extent and boundary radii at its set level; returns the reports (raw maxima) in row order.
pub fn verify_table(
    evaluator: &Evaluator,
    manifest: &mut Manifest,
    system: &AffineSystem,
    selection: &Selection<'_>,
    options: &VerifyOptions,
    progress: &ProgressBar,
) -> Result<Vec<RowReport>, VerifyError> {
    let reports =
        combine_pieces(verify_rows(evaluator, manifest, system, selection, Shard::WHOLE, options, progress)?)?;
    apply_reports(evaluator, manifest, system, &reports)?;
    Ok(reports)
}

/// Verifies this shard's share of the rows of `manifest` the selection names, without changing the
/// manifest. The work is a list of items, each selected row's pieces in turn (one item per row unless
/// `options.pieces` splits its samples), and the `i`-th item belongs to shard `i % count`. Each item's samples
/// are seeded by the options' seed, the row's `beta` and the piece alone, so shards give the reports a single
/// run gives; [`combine_pieces`] makes one report per row of them.
pub fn verify_rows(
    evaluator: &Evaluator,
    manifest: &Manifest,
    system: &AffineSystem,
    selection: &Selection<'_>,
    shard: Shard,
    options: &VerifyOptions,
    progress: &ProgressBar,
) -> Result<Vec<RowReport>, VerifyError> {
    let selected: Vec<usize> = (0..manifest.teb_table.len())
        .filter(|&i| selection.betas.is_none_or(|b| b.iter().any(|&x| (x - manifest.teb_table[i].beta).abs() < 1e-9)))
        .collect();
    if selected.is_empty() {
        return Err(VerifyError::Setting(format!("no TEB row has a beta in {:?}", selection.betas)));
    }
    let pieces = options.pieces.max(1);
    let items = selected.iter().flat_map(|&i| (0..pieces).map(move |index| (i, Shard { index, count: pieces })));
    let mine: Vec<(usize, Shard)> =
        items.enumerate().filter(|(position, _)| shard.takes(*position)).map(|(_, item)| item).collect();
    progress.set_length(mine.len() as u64);
    let mut reports = Vec::with_capacity(mine.len());
    for (i, piece) in mine {
        let row = &manifest.teb_table[i];
        let grid = nearest_adversary(selection.adversaries, row.beta, selection.grid_tolerance);
        let report = verify_row(evaluator, manifest, system, row, grid, selection.operational, options, piece)?;
        tracing::info!(
            beta = report.beta,
            piece = %piece,
            level = report.level,
            verified = report.verification.verified_level,
            violations = report.verification.violations,
            rounds = report.rounds.len(),
            "row verified"
        );
        reports.push(report);
        progress.inc(1);
    }
    Ok(reports)
}

/// Writes `reports` into their rows of `manifest` (matched by `beta`), keeps the bounds monotone in `beta`,
/// and reshapes every row's extent and boundary radii at its set level. A row whose set reached the trained
/// domain's edge without a violation (always so under the `bound` correction) is refused: its manifest entry
/// would look verified, though its rollouts ran on an extrapolated model.
pub fn apply_reports(
    evaluator: &Evaluator,
    manifest: &mut Manifest,
    system: &AffineSystem,
    reports: &[RowReport],
) -> Result<(), VerifyError> {
    if let Some(report) = reports.iter().find(|r| r.outcome == Outcome::LeftDomain && r.verification.violations == 0) {
        return Err(VerifyError::LeftDomain { beta: report.beta, level: report.sampled_level() });
    }
    for report in reports {
        let row =
            manifest.teb_table.iter_mut().find(|row| row.beta == report.beta).ok_or_else(|| {
                VerifyError::Setting(format!("the table has no row with beta {} to verify", report.beta))
            })?;
        row.verification = Some(report.verification.clone());
    }
    monotone_envelope(manifest)?;
    reshape_at_set_levels(evaluator, system, &mut manifest.teb_table, &TebOptions::default())
        .map_err(VerifyError::Shape)
}

/// Keeps the bounds monotone in `beta` (the manifest's invariant): a verified row bounds at least what
/// every row below it serves. An unverified row that would then serve less than a row below it is an error:
/// verify the rows above a raised one too.
fn monotone_envelope(manifest: &mut Manifest) -> Result<(), VerifyError> {
    let mut floor = 0.0f64;
    for row in &mut manifest.teb_table {
        if let Some(v) = &mut row.verification {
            v.verified_level = v.verified_level.max(floor);
        } else if row.level < floor {
            return Err(VerifyError::Setting(format!(
                "row beta {} (level {}) is below the verified level {floor} of a smaller beta: verify it as well",
                row.beta, row.level
            )));
        }
        floor = floor.max(row.bound());
    }
    Ok(())
}

/// A measurement of rollout speed: `states` rollouts of `steps` steps of `step` seconds at `beta`, fed to ONNX
/// Runtime as `batching` says.
#[derive(Debug, Clone, Copy)]
pub struct RateProbe {
    /// Planner speed bound.
    pub beta: f64,
    /// Rollouts.
    pub states: usize,
    /// Steps per rollout.
    pub steps: usize,
    /// RK4 step (s).
    pub step: f64,
    /// How the states are fed.
    pub batching: Batching,
}

/// Rollout steps per second (states times steps over wall time) of the probe's rollouts, from states drawn
/// uniformly over the manifest's box, against the model's worst-case planner: what a verification's rollouts
/// cost per state and step.
pub fn rollout_rate(
    evaluator: &Evaluator,
    manifest: &Manifest,
    system: &AffineSystem,
    probe: &RateProbe,
) -> Result<f64, VerifyError> {
    let mut rng = StdRng::seed_from_u64(7);
    let params = vec![probe.beta; system.n_params()];
    let mut rollouts: Vec<Rollout> = (0..probe.states)
        .map(|_| {
            let state: Vec<f64> = manifest.state.iter().map(|d| rng.random_range(d.min..=d.max)).collect();
            Rollout::new(system, &state, PlannerPolicy::WorstCase, Gradient::Model, StdRng::seed_from_u64(0))
        })
        .collect();
    let scene = Scene {
        evaluator,
        system,
        params: &params,
        grid: None,
        tracker: Gradient::Model,
        horizon: probe.steps as f64 * probe.step,
        step: probe.step,
        mean_dwell: 1.0,
        batching: probe.batching,
        error_scale: ErrorScale::Absolute,
    };
    let started = Instant::now();
    scene.roll_out(&mut rollouts)?;
    Ok((probe.states * probe.steps) as f64 / started.elapsed().as_secs_f64())
}
