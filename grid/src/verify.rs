//! Scenario verification of a bundle's TEB table (after Lin & Bansal's verification of DeepReach):
//! sample `N` states uniformly in the learned sublevel set `{V <= level}` of each row by rejection, roll the
//! relative system forward (RK4, fixed step, control and planner held over each step) with the served
//! tracker control against the worst-case planner of the model's gradient and against random bang-bang
//! planners, and record the largest tracking error reached.
//!
//! The states are drawn from `{V <= (1 + margin) level}`: a table's level is `V`'s minimum, whose sublevel set
//! has (next to) no volume, so a small relative margin (default 10%) gives a set that can be sampled and that
//! contains the learned error set. A sample *violates* the table when its rollout's error exceeds the level it
//! was sampled under, `(1 + margin) level`.
//!
//! With `N >= (2 / eps) (ln(1 / delta) + 1)` samples, the largest error over the samples bounds the error
//! from all but an `eps` fraction (by measure) of the sublevel set, with confidence `1 - delta` (scenario
//! approach, one decision variable: the level), for these planner families and this horizon.

use fastrack_valuefn::manifest::{Manifest, TebRow, Verification};
use fastrack_valuefn::runtime::{Evaluator, RuntimeError};
use fastrack_valuefn::shard::Shard;
use fastrack_valuefn::simulation::{step_relative, HeldInputs, Planner};
use fastrack_valuefn::system::AffineSystem;
use fastrack_valuefn::teb::{reshape_at_served_levels, TebOptions};
use indicatif::ProgressBar;
use rand::rngs::StdRng;
use rand::{Rng, SeedableRng};
use serde::{Deserialize, Serialize};

/// Proposals evaluated per rejection-sampling batch.
const PROPOSAL_BATCH: usize = 8192;

/// How to verify.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct VerifyOptions {
    /// Violation-probability bound epsilon.
    pub eps: f64,
    /// States are sampled in `{V <= (1 + level_margin) level}`.
    pub level_margin: f64,
    /// Confidence parameter delta.
    pub delta: f64,
    /// Rollout horizon (s).
    pub horizon: f64,
    /// RK4 step; the control and the planner are held over a step (s).
    pub step: f64,
    /// Random bang-bang planners per sample (besides the worst-case planner).
    pub random_planners: usize,
    /// Mean time between a random planner's switches (s).
    pub mean_dwell: f64,
    /// Largest number of proposals per row before giving up on rejection sampling.
    pub max_proposals: usize,
    /// Random seed.
    pub seed: u64,
}

impl Default for VerifyOptions {
    fn default() -> Self {
        Self {
            eps: 0.05,
            level_margin: 0.1,
            delta: 1e-3,
            horizon: 10.0,
            step: 0.01,
            random_planners: 3,
            mean_dwell: 1.0,
            max_proposals: 2_000_000,
            seed: 11,
        }
    }
}

/// Samples needed for `eps` and `delta`: `ceil((2 / eps) (ln(1 / delta) + 1))`.
pub fn required_samples(eps: f64, delta: f64) -> usize {
    ((2.0 / eps) * ((1.0 / delta).ln() + 1.0)).ceil() as usize
}

/// Why a verification could not run.
#[derive(Debug, thiserror::Error)]
pub enum VerifyError {
    /// A setting is out of range.
    #[error("{0}")]
    Setting(String),
    /// The error sets at the served levels could not be measured.
    #[error("measuring the error set at the served level: {0}")]
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
    /// ONNX Runtime failed.
    #[error(transparent)]
    Runtime(#[from] RuntimeError),
}

/// The result for one TEB row.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct RowReport {
    /// Planner speed bound.
    pub beta: f64,
    /// The row's learned level.
    pub level: f64,
    /// The level the states were sampled under, `(1 + margin) level`; violations are errors above it.
    pub sampled_level: f64,
    /// What was written into the row.
    pub verification: Verification,
    /// Largest error reached against the worst-case planner.
    pub worst_case_max: f64,
    /// Largest error reached against the random bang-bang planners.
    pub random_max: f64,
    /// Share of proposals accepted by rejection sampling.
    pub acceptance: f64,
}

/// A batch of rollouts: states, the planner of each, and the largest error each reached.
struct Rollouts {
    states: Vec<f64>,
    planners: Vec<Planner>,
    max_error: Vec<f64>,
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
    Ok(())
}

fn to_f32(x: &[f64]) -> Vec<f32> {
    x.iter().map(|&v| v as f32).collect()
}

/// `N` states drawn uniformly from `{V <= level}` over the manifest's state box, and the acceptance rate.
fn sample_sublevel_set(
    evaluator: &Evaluator,
    manifest: &Manifest,
    params: &[f64],
    level: f64,
    n: usize,
    options: &VerifyOptions,
    rng: &mut StdRng,
) -> Result<(Vec<f64>, f64), VerifyError> {
    let n_state = manifest.state.len();
    let mut accepted = Vec::with_capacity(n * n_state);
    let (mut proposed, mut inside) = (0usize, 0usize);
    while accepted.len() < n * n_state {
        if proposed >= options.max_proposals {
            return Err(VerifyError::Sampling { beta: params[0], level, accepted: accepted.len() / n_state, proposed });
        }
        let states: Vec<f64> = (0..PROPOSAL_BATCH)
            .flat_map(|_| manifest.state.iter().map(|d| rng.random_range(d.min..=d.max)).collect::<Vec<_>>())
            .collect();
        let batch_params: Vec<f64> = params.iter().copied().cycle().take(PROPOSAL_BATCH * params.len()).collect();
        let out = evaluator.evaluate(&to_f32(&states), &to_f32(&batch_params))?;
        proposed += PROPOSAL_BATCH;
        for (state, &v) in states.chunks(n_state).zip(&out.value) {
            if f64::from(v) <= level {
                inside += 1;
                if accepted.len() < n * n_state {
                    accepted.extend_from_slice(state);
                }
            }
        }
    }
    Ok((accepted, inside as f64 / proposed as f64))
}

/// Rolls every trajectory forward over the horizon with the served control.
fn roll_out(
    evaluator: &Evaluator,
    system: &AffineSystem,
    params: &[f64],
    rollouts: &mut Rollouts,
    options: &VerifyOptions,
    rng: &mut StdRng,
) -> Result<(), VerifyError> {
    let n_state = system.n_state();
    let n_control = system.n_control();
    let count = rollouts.planners.len();
    let batch_params = to_f32(&params.iter().copied().cycle().take(count * params.len()).collect::<Vec<_>>());
    let steps = (options.horizon / options.step).round().max(1.0) as usize;
    for k in 0..steps {
        let t = k as f64 * options.step;
        let out = evaluator.evaluate(&to_f32(&rollouts.states), &batch_params)?;
        for j in 0..count {
            let grad: Vec<f64> = out.grad[j * n_state..(j + 1) * n_state].iter().map(|&g| f64::from(g)).collect();
            let u: Vec<f64> = out.control[j * n_control..(j + 1) * n_control].iter().map(|&c| f64::from(c)).collect();
            let u_p = rollouts.planners[j].input(system, params, &grad, t, options.mean_dwell, rng);
            let d = system.worst_disturbance(&grad);
            let r = &mut rollouts.states[j * n_state..(j + 1) * n_state];
            step_relative(system, r, HeldInputs { control: &u, planner: &u_p, disturbance: &d }, options.step);
            rollouts.max_error[j] = rollouts.max_error[j].max(system.tracking_error(r));
        }
    }
    Ok(())
}

/// Verifies one row: samples, rolls out, and returns the report (the row itself is not modified).
pub fn verify_row(
    evaluator: &Evaluator,
    manifest: &Manifest,
    system: &AffineSystem,
    row: &TebRow,
    options: &VerifyOptions,
) -> Result<RowReport, VerifyError> {
    check(options)?;
    if manifest.system.id != system.id {
        return Err(VerifyError::System { bundle: manifest.system.id.clone(), system: system.id.into() });
    }
    let mut rng = StdRng::seed_from_u64(options.seed ^ row.beta.to_bits());
    let params = vec![row.beta; system.n_params()];
    let n = required_samples(options.eps, options.delta);
    let sampled_level = row.level * (1.0 + options.level_margin);
    let (samples, acceptance) = sample_sublevel_set(evaluator, manifest, &params, sampled_level, n, options, &mut rng)?;
    let per_sample = 1 + options.random_planners;
    let mut rollouts = Rollouts { states: Vec::new(), planners: Vec::new(), max_error: Vec::new() };
    for state in samples.chunks(system.n_state()) {
        for p in 0..per_sample {
            rollouts.states.extend_from_slice(state);
            rollouts.max_error.push(system.tracking_error(state));
            rollouts.planners.push(if p == 0 { Planner::WorstCase } else { Planner::bang_bang() });
        }
    }
    roll_out(evaluator, system, &params, &mut rollouts, options, &mut rng)?;
    let per_state: Vec<f64> =
        rollouts.max_error.chunks(per_sample).map(|c| c.iter().copied().fold(0.0, f64::max)).collect();
    let (mut worst_case_max, mut random_max) = (0.0f64, 0.0f64);
    for (j, &e) in rollouts.max_error.iter().enumerate() {
        if j % per_sample == 0 {
            worst_case_max = worst_case_max.max(e);
        } else {
            random_max = random_max.max(e);
        }
    }
    let verified_level = per_state.iter().copied().fold(0.0, f64::max);
    let violations = per_state.iter().filter(|&&e| e > sampled_level).count();
    Ok(RowReport {
        beta: row.beta,
        level: row.level,
        sampled_level,
        verification: Verification {
            verified_level,
            eps: options.eps,
            delta: options.delta,
            samples: n,
            violations,
            horizon: options.horizon,
            step: options.step,
        },
        worst_case_max,
        random_max,
        acceptance,
    })
}

/// Verifies the rows of `manifest` whose `beta` is in `betas` (all rows when `None`), writing each
/// result into its row's `verification` (raised where needed to keep served levels monotone in `beta`) and
/// every row's extent and boundary radii at its served level; returns the reports (raw maxima) in row order.
pub fn verify_table(
    evaluator: &Evaluator,
    manifest: &mut Manifest,
    system: &AffineSystem,
    betas: Option<&[f64]>,
    options: &VerifyOptions,
    progress: &ProgressBar,
) -> Result<Vec<RowReport>, VerifyError> {
    let reports = verify_rows(evaluator, manifest, system, betas, Shard::WHOLE, options, progress)?;
    apply_reports(evaluator, manifest, system, &reports)?;
    Ok(reports)
}

/// Verifies this shard's share of the rows of `manifest` whose `beta` is in `betas` (all rows when `None`),
/// without changing the manifest: the `i`-th selected row belongs to shard `i % count`. Each row's samples
/// are seeded by the options' seed and the row's `beta` alone, so shards give the reports a single run gives.
pub fn verify_rows(
    evaluator: &Evaluator,
    manifest: &Manifest,
    system: &AffineSystem,
    betas: Option<&[f64]>,
    shard: Shard,
    options: &VerifyOptions,
    progress: &ProgressBar,
) -> Result<Vec<RowReport>, VerifyError> {
    let selected: Vec<usize> = (0..manifest.teb_table.len())
        .filter(|&i| betas.is_none_or(|b| b.iter().any(|&x| (x - manifest.teb_table[i].beta).abs() < 1e-9)))
        .collect();
    if selected.is_empty() {
        return Err(VerifyError::Setting(format!("no TEB row has a beta in {betas:?}")));
    }
    let mine: Vec<usize> =
        selected.iter().enumerate().filter(|(position, _)| shard.takes(*position)).map(|(_, &i)| i).collect();
    progress.set_length(mine.len() as u64);
    let mut reports = Vec::with_capacity(mine.len());
    for i in mine {
        let report = verify_row(evaluator, manifest, system, &manifest.teb_table[i], options)?;
        tracing::info!(
            beta = report.beta,
            level = report.level,
            verified = report.verification.verified_level,
            violations = report.verification.violations,
            "row verified"
        );
        reports.push(report);
        progress.inc(1);
    }
    Ok(reports)
}

/// Writes `reports` into their rows of `manifest` (matched by `beta`), keeps the served levels monotone in
/// `beta`, and reshapes every row's extent and boundary radii at its served level.
pub fn apply_reports(
    evaluator: &Evaluator,
    manifest: &mut Manifest,
    system: &AffineSystem,
    reports: &[RowReport],
) -> Result<(), VerifyError> {
    for report in reports {
        let row =
            manifest.teb_table.iter_mut().find(|row| row.beta == report.beta).ok_or_else(|| {
                VerifyError::Setting(format!("the table has no row with beta {} to verify", report.beta))
            })?;
        row.verification = Some(report.verification.clone());
    }
    monotone_envelope(manifest)?;
    reshape_at_served_levels(evaluator, system, &mut manifest.teb_table, &TebOptions::default())
        .map_err(VerifyError::Shape)
}

/// Keeps served levels monotone in `beta` (the manifest's invariant): a verified row serves at least what
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
        floor = floor.max(row.served_level());
    }
    Ok(())
}
