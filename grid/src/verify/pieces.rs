//! A row's samples split into pieces: each piece rolls out its share of every check on a random stream of its
//! own (and, sharded, in a process of its own), and the pieces combine into the one round of the `bound`
//! correction that a single run would roll out: the counts add up, and every largest error is the largest of
//! the pieces'. The bound is decided by the samples alone, so splitting them changes nothing in what is
//! certified.

use super::{Outcome, RoundReport, RowReport, VerifyError};
use fastrack_lab::shard::Shard;
use fastrack_valuefn::manifest::{CheckResult, PlannerResult};

/// Combines the reports of rows split into pieces, in the order given, into one report per row; reports of
/// whole rows pass unchanged. Every piece of a split row must be there exactly once.
pub fn combine_pieces(reports: Vec<RowReport>) -> Result<Vec<RowReport>, VerifyError> {
    let mut rows: Vec<Vec<RowReport>> = Vec::new();
    for report in reports {
        match rows.iter_mut().find(|pieces| pieces[0].beta == report.beta) {
            Some(pieces) => pieces.push(report),
            None => rows.push(vec![report]),
        }
    }
    rows.into_iter().map(combine_row).collect()
}

/// The pieces of one row as one report.
fn combine_row(mut pieces: Vec<RowReport>) -> Result<RowReport, VerifyError> {
    let beta = pieces[0].beta;
    let shards: Vec<Shard> = pieces.iter().map(|p| p.piece.unwrap_or(Shard::WHOLE)).collect();
    Shard::check_complete(&shards).map_err(|why| VerifyError::Setting(format!("row beta {beta}: pieces: {why}")))?;
    if pieces.len() == 1 {
        return Ok(pieces.remove(0));
    }
    let first = &pieces[0];
    let rounds: Vec<&RoundReport> = pieces.iter().filter_map(|p| p.rounds.last()).collect();
    if rounds.len() != pieces.len()
        || pieces.iter().any(|p| p.rounds.len() != 1 || p.level != first.level)
        || rounds.iter().any(|r| r.sampled_level != rounds[0].sampled_level)
    {
        return Err(VerifyError::Setting(format!(
            "row beta {beta}: its pieces did not each roll out one round of the same set"
        )));
    }
    let samples: usize = rounds.iter().map(|r| r.samples).sum();
    let max_error = rounds.iter().map(|r| r.max_error).fold(0.0, f64::max);
    let acceptance = rounds.iter().map(|r| r.acceptance * r.samples as f64).sum::<f64>() / samples.max(1) as f64;
    let checks = combine_checks(rounds.iter().map(|r| &r.checks[..]));
    let round = RoundReport {
        level: max_error,
        sampled_level: rounds[0].sampled_level,
        samples,
        violations: rounds.iter().map(|r| r.violations).sum(),
        max_error,
        acceptance,
        checks: checks.clone(),
        in_force: rounds[0].in_force,
    };
    let mut verification = first.verification.clone();
    verification.verified_level = max_error;
    verification.samples = samples;
    verification.violations = round.violations;
    verification.planners = combine_planners(pieces.iter().map(|p| &p.verification.planners[..]));
    verification.checks = checks;
    let outcome = if pieces.iter().any(|p| p.outcome == Outcome::LeftDomain) {
        Outcome::LeftDomain
    } else if pieces.iter().all(|p| p.outcome == Outcome::Verified) {
        Outcome::Verified
    } else {
        Outcome::RoundsExhausted
    };
    Ok(RowReport {
        beta,
        level: first.level,
        rounds: vec![round],
        outcome,
        verification,
        grid_beta: first.grid_beta,
        searched: pieces.iter().map(|p| p.searched).sum(),
        rollout_steps: pieces.iter().map(|p| p.rollout_steps).sum(),
        wall_s: pieces.iter().map(|p| p.wall_s).sum(),
        piece: None,
    })
}

/// Each check's counts added up over the pieces, its largest error the largest; in the order checks first
/// appear.
fn combine_checks<'a>(pieces: impl Iterator<Item = &'a [CheckResult]>) -> Vec<CheckResult> {
    let mut combined: Vec<CheckResult> = Vec::new();
    for check in pieces.flatten() {
        match combined.iter_mut().find(|c| c.distribution == check.distribution) {
            Some(c) => {
                c.samples += check.samples;
                c.violations += check.violations;
                c.max_error = c.max_error.max(check.max_error);
            }
            None => combined.push(check.clone()),
        }
    }
    combined
}

/// Each planner family's rollouts added up over the pieces, its largest error the largest.
fn combine_planners<'a>(pieces: impl Iterator<Item = &'a [PlannerResult]>) -> Vec<PlannerResult> {
    let mut combined: Vec<PlannerResult> = Vec::new();
    for planner in pieces.flatten() {
        match combined.iter_mut().find(|p| p.family == planner.family) {
            Some(p) => {
                p.rollouts += planner.rollouts;
                p.max_error = p.max_error.max(planner.max_error);
            }
            None => combined.push(planner.clone()),
        }
    }
    combined
}
