//! Verification of a composed value by its axes. A composite `V(r) = sqrt(sum_a V_a(r_a)^2)` over decoupled
//! axes (quad10d: x, y, z) is certified without sampling its own sets, which fill too small a share of any box
//! around them to sample: each axis subsystem's network is verified on its own, with every rollout's error
//! taken less the value at its start ([`ErrorScale::ExcessOverStartValue`]). An axis is sampled where the
//! composite's set can put it: a state of `{V <= S}` has `V_a^2 <= S^2 - sum_{b != a} V_b^2 <= S_a^2 =
//! S^2 - (L^2 - m_a^2)`, with `L` the composite's measured minimum (the axes' minima combined) and `m_a` the
//! axis' own measured minimum at that `beta` ([`axis_sampled_level`]). If every axis keeps
//! `|e_a(t)| <= V_a(r_a(0)) + delta_a` (`delta_a >= 0`), the whole error from a start in `{V <= S}` keeps
//! `|e(t)|^2 = sum_a e_a(t)^2 <= sum_a (V_a + delta_a)^2 = V^2 + 2 sum_a delta_a V_a + sum_a delta_a^2`, at most
//! `S^2 + 2 sum_a delta_a S_a + sum_a delta_a^2`; and by the triangle inequality in the axes also at most
//! `(S + sqrt(sum_a delta_a^2))^2`. The smaller of the two is the composite's bound ([`composed_bound`]; an
//! axis subsystem that serves several axes, quad10d's x for x and y, counts once per axis). What `eps` bounds changes with it: the share of each axis' sampled set whose
//! excess may pass its bound, not the share of the composite's set.

use super::{Correction, ErrorScale, Outcome, RecordedStates, RoundReport, RowReport, VerifyError};
use fastrack_valuefn::manifest::{CheckResult, Manifest, PlannerResult, TebRow, Verification};
use fastrack_valuefn::runtime::Evaluator;
use fastrack_valuefn::system::decomposition;
use rand::Rng;

/// The `correction` a composite row verified by its axes carries in its manifest.
pub const BY_AXES: &str = "by-axes";

/// The level of an axis' sampled set at one composite row: every axis state of the composite's set
/// `{V <= sampled}` lies in `{V_a <= axis_sampled_level}` (module docs).
pub fn axis_sampled_level(sampled: f64, composite_min: f64, axis_min: f64) -> f64 {
    (sampled * sampled - composite_min * composite_min + axis_min * axis_min).max(axis_min * axis_min).sqrt()
}

/// The row of `table` at `beta` (rows are matched exactly: the tables are built at the same betas).
fn row_at(table: &[TebRow], beta: f64) -> Option<&TebRow> {
    table.iter().find(|row| (row.beta - beta).abs() < 1e-9)
}

/// An axis' report at `beta`, if it verified that row.
fn report_at<'r>(axis: &'r AxisReports<'_>, beta: f64) -> Option<&'r RowReport> {
    axis.reports.iter().find(|r| (r.beta - beta).abs() < 1e-9)
}

/// Checks that `axis` is the bundle of one of `composite`'s axis subsystems.
fn check_axis(composite: &Manifest, axis: &Manifest) -> Result<(), VerifyError> {
    let axes = decomposition(&composite.system.id).ok_or_else(|| {
        VerifyError::Setting(format!("system `{}` has no decomposition into axes", composite.system.id))
    })?;
    if axes.iter().any(|a| a.subsystem == axis.system.id) {
        Ok(())
    } else {
        let known: Vec<&str> = axes.iter().map(|a| a.subsystem).collect();
        Err(VerifyError::Setting(format!(
            "the bundle is for `{}`, which is not an axis of `{}` (its axes: {})",
            axis.system.id,
            composite.system.id,
            known.join(", ")
        )))
    }
}

/// The composite's recorded states (`fastrack sim bench --visits`) as states of the axis bundle's subsystem:
/// each state's projection on every axis that subsystem serves (quad10d's x network: the x and the y axis),
/// so that the axis' operational check draws from every place the online loop put one of its axes.
pub fn axis_states(
    composite: &Manifest,
    axis: &Manifest,
    recorded: &RecordedStates,
) -> Result<RecordedStates, VerifyError> {
    check_axis(composite, axis)?;
    let groups: Vec<Vec<usize>> = decomposition(&composite.system.id)
        .unwrap_or_default()
        .into_iter()
        .filter(|a| a.subsystem == axis.system.id)
        .map(|a| a.coords)
        .collect();
    recorded.projected(&groups).map_err(VerifyError::Operational)
}

/// The rows an axis bundle is verified at for `composite`: the composite's betas, each with the level whose
/// first sampled set (`(1 + level_margin)` times it, as every verification samples) is the axis' share of the
/// composite's sampled set `{V <= (1 + level_margin) level}`. The axis' minimum at each `beta` is its own
/// table's measured minimum there.
pub fn axis_rows(composite: &Manifest, axis: &Manifest, level_margin: f64) -> Result<Vec<TebRow>, VerifyError> {
    check_axis(composite, axis)?;
    composite
        .teb_table
        .iter()
        .map(|row| {
            let own = row_at(&axis.teb_table, row.beta).ok_or_else(|| {
                VerifyError::Setting(format!(
                    "the axis bundle `{}` has no row at beta {}, a row of `{}`",
                    axis.name, row.beta, composite.name
                ))
            })?;
            let sampled = (1.0 + level_margin) * row.level;
            let level = axis_sampled_level(sampled, row.measured_min, own.measured_min) / (1.0 + level_margin);
            Ok(TebRow { level, verification: None, reference: None, nested_share: None, ..own.clone() })
        })
        .collect()
}

/// The bound on the error from the composite's set `{V <= sampled}` given each of its axes' largest excess
/// of the error over the start's value and its reach there, `(delta_a, S_a)` (module docs): the smaller of
/// `sqrt(S^2 + 2 sum_a delta_a S_a + sum_a delta_a^2)` and `S + sqrt(sum_a delta_a^2)`, with each excess
/// taken at least 0.
pub fn composed_bound(sampled: f64, axes: &[(f64, f64)]) -> f64 {
    let excess_squared: f64 = axes.iter().map(|&(delta, _)| delta.max(0.0).powi(2)).sum();
    let reached: f64 = axes.iter().map(|&(delta, reach)| delta.max(0.0) * reach).sum();
    let by_reach = (sampled * sampled + 2.0 * reached + excess_squared).sqrt();
    by_reach.min(sampled + excess_squared.sqrt())
}

/// One axis subsystem's verification: its bundle's manifest and its rows' reports (pieces combined).
pub struct AxisReports<'a> {
    /// The axis bundle's manifest.
    pub manifest: &'a Manifest,
    /// Its reports, verified with [`ErrorScale::ExcessOverStartValue`] and the bound correction at
    /// [`axis_rows`]' levels.
    pub reports: &'a [RowReport],
}

/// The composite's row reports from its axes': for every composite row the axes verified, the set
/// `{V <= S}` it would sample (`S = (1 + level_margin) level`) with the [`composed_bound`] of the axes'
/// largest excesses (module docs). Every axis subsystem of the decomposition must be there; a row
/// one of them verified must have been verified by all, on sampled sets that cover its share of `{V <= S}`.
/// Each check and planner family keeps its axis' largest excess, named after the axis.
pub fn compose_reports(
    composite: &Manifest,
    axes: &[AxisReports<'_>],
    level_margin: f64,
) -> Result<Vec<RowReport>, VerifyError> {
    let decomposition = decomposition(&composite.system.id).ok_or_else(|| {
        VerifyError::Setting(format!("system `{}` has no decomposition into axes", composite.system.id))
    })?;
    for axis in axes {
        check_axis(composite, axis.manifest)?;
    }
    for wanted in &decomposition {
        let given = axes.iter().filter(|a| a.manifest.system.id == wanted.subsystem).count();
        if given != 1 {
            return Err(VerifyError::Setting(format!(
                "axis `{}` of `{}`: {given} verifications given, one needed",
                wanted.subsystem, composite.system.id
            )));
        }
    }
    let decomposed: Vec<&str> = decomposition.iter().map(|a| a.subsystem).collect();
    composite.teb_table.iter().filter_map(|row| compose_row(row, axes, &decomposed, level_margin).transpose()).collect()
}

/// One composite row from every axis' report at its `beta` (none where no axis verified it). `decomposed`:
/// the subsystem of each axis of the composite, in order.
fn compose_row(
    row: &TebRow,
    axes: &[AxisReports<'_>],
    decomposed: &[&str],
    level_margin: f64,
) -> Result<Option<RowReport>, VerifyError> {
    let at_row = |axis| report_at(axis, row.beta);
    if axes.iter().all(|axis| at_row(axis).is_none()) {
        return Ok(None);
    }
    let sampled = (1.0 + level_margin) * row.level;
    let mut found = Vec::with_capacity(axes.len());
    for axis in axes {
        let fail = |why: String| {
            VerifyError::Setting(format!("row beta {}, axis `{}`: {why}", row.beta, axis.manifest.system.id))
        };
        let report = at_row(axis).ok_or_else(|| fail("not verified, though other axes were".into()))?;
        let v = &report.verification;
        if v.correction.as_deref() != Some(Correction::Bound.name()) || report.rounds.len() != 1 {
            return Err(fail("not verified by the bound correction's one round".into()));
        }
        let own =
            row_at(&axis.manifest.teb_table, row.beta).ok_or_else(|| fail("the axis table has no such row".into()))?;
        let needed = axis_sampled_level(sampled, row.measured_min, own.measured_min);
        if report.sampled_level() < needed * (1.0 - 1e-9) {
            return Err(fail(format!(
                "it sampled {{V <= {}}}, short of the {needed} the composite's set {{V <= {sampled}}} reaches",
                report.sampled_level()
            )));
        }
        found.push((axis.manifest.system.id.as_str(), report, needed));
    }
    // Each axis of the composite with its subsystem's excess and reach.
    let per_axis: Vec<(f64, f64)> = decomposed
        .iter()
        .filter_map(|&subsystem| found.iter().find(|(axis, _, _)| *axis == subsystem))
        .map(|(_, report, reach)| (report.verification.verified_level, *reach))
        .collect();
    let bound = composed_bound(sampled, &per_axis);
    let named = |axis: &str, name: &str| format!("{axis}: {name}");
    let checks: Vec<CheckResult> = found
        .iter()
        .flat_map(|(axis, r, _)| {
            r.verification
                .checks
                .iter()
                .map(move |c| CheckResult { distribution: named(axis, &c.distribution), ..c.clone() })
        })
        .collect();
    let planners: Vec<PlannerResult> = found
        .iter()
        .flat_map(|(axis, r, _)| {
            r.verification.planners.iter().map(move |p| PlannerResult { family: named(axis, &p.family), ..p.clone() })
        })
        .collect();
    let reports = found.iter().map(|(_, r, _)| *r);
    let samples = reports.clone().map(|r| r.verification.samples).min().unwrap_or(0);
    let violations = reports.clone().map(|r| r.verification.violations).sum();
    let outcome = if reports.clone().any(|r| r.outcome == Outcome::LeftDomain) {
        Outcome::LeftDomain
    } else if violations > 0 {
        Outcome::RoundsExhausted
    } else {
        Outcome::Verified
    };
    let first = &found[0].1.verification;
    let round = RoundReport {
        level: bound,
        sampled_level: sampled,
        samples,
        violations,
        max_error: bound,
        acceptance: reports.clone().map(|r| r.rounds[0].acceptance).fold(1.0, f64::min),
        checks: checks.clone(),
        in_force: None,
    };
    Ok(Some(RowReport {
        beta: row.beta,
        level: row.level,
        rounds: vec![round],
        outcome,
        verification: Verification {
            verified_level: bound,
            eps: first.eps,
            delta: first.delta,
            samples,
            violations,
            horizon: first.horizon,
            step: first.step,
            sampled_level: Some(sampled),
            correction: Some(BY_AXES.into()),
            rounds: 1,
            planners,
            checks,
        },
        grid_beta: reports.clone().find_map(|r| r.grid_beta),
        searched: reports.clone().map(|r| r.searched).sum(),
        rollout_steps: reports.clone().map(|r| r.rollout_steps).sum(),
        wall_s: reports.map(|r| r.wall_s).sum(),
        piece: None,
    }))
}

/// Checks that the reports were verified as excesses over the start's value (the only scale that composes).
pub fn check_scale(scale: ErrorScale) -> Result<(), VerifyError> {
    if scale == ErrorScale::ExcessOverStartValue {
        Ok(())
    } else {
        Err(VerifyError::Setting(format!(
            "an axis verification measured its errors as `{}`; composing needs `{}`",
            scale.name(),
            ErrorScale::ExcessOverStartValue.name()
        )))
    }
}

/// Largest difference allowed between the composite's served value and its axes' values combined (the graphs
/// compute in f32).
const COMPOSITION_TOLERANCE: f64 = 1e-4;

/// Checks that the axis networks are the composite's: at `count` states drawn uniformly over the composite's
/// domain (every parameter at one random `beta`), its served `V` equals `sqrt(sum_a V_a(r_a)^2)` of the axis
/// bundles' graphs within [`COMPOSITION_TOLERANCE`].
pub fn check_networks(
    composite: (&Evaluator, &Manifest),
    axes: &[(&Evaluator, &Manifest)],
    count: usize,
    rng: &mut impl Rng,
) -> Result<(), VerifyError> {
    let (evaluator, manifest) = composite;
    let decomposition = decomposition(&manifest.system.id).ok_or_else(|| {
        VerifyError::Setting(format!("system `{}` has no decomposition into axes", manifest.system.id))
    })?;
    let (lo, hi) = manifest.beta_range();
    let beta = rng.random_range(lo..=hi);
    let states: Vec<f64> = (0..count)
        .flat_map(|_| manifest.state.iter().map(|d| rng.random_range(d.min..=d.max)).collect::<Vec<_>>())
        .collect();
    let as_f32 = |xs: &[f64]| xs.iter().map(|&x| x as f32).collect::<Vec<f32>>();
    let served = evaluator.evaluate(&as_f32(&states), &vec![beta as f32; count * manifest.n_params()])?.value;
    let mut combined = vec![0.0f64; count];
    for axis in &decomposition {
        let (axis_evaluator, _) = axes
            .iter()
            .find(|(_, m)| m.system.id == axis.subsystem)
            .ok_or_else(|| VerifyError::Setting(format!("no bundle of axis `{}` was given", axis.subsystem)))?;
        let n = manifest.state.len();
        let sub: Vec<f64> =
            states.chunks(n).flat_map(|s| axis.coords.iter().map(|&i| s[i]).collect::<Vec<_>>()).collect();
        let values = axis_evaluator.evaluate(&as_f32(&sub), &vec![beta as f32; count])?.value;
        for (c, v) in combined.iter_mut().zip(values) {
            *c += f64::from(v).max(0.0).powi(2);
        }
    }
    let worst = served.iter().zip(&combined).map(|(&v, &c)| (f64::from(v) - c.sqrt()).abs()).fold(0.0, f64::max);
    if worst > COMPOSITION_TOLERANCE * (1.0 + served.iter().map(|&v| f64::from(v).abs()).fold(0.0, f64::max)) {
        return Err(VerifyError::Setting(format!(
            "the axis bundles are not `{}`'s axes: its value differs from theirs combined by up to {worst:.3e}",
            manifest.name
        )));
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::{axis_sampled_level, composed_bound};

    #[test]
    fn an_axis_is_sampled_as_far_as_the_composite_set_reaches_with_the_other_axes_at_their_minima() {
        // Axes with minima 0.6, 0.6 and 0.3 compose to the minimum 0.9.
        let minima = [0.6f64, 0.6, 0.3];
        let composite_min = minima.iter().map(|m| m * m).sum::<f64>().sqrt();
        let sampled = 1.0;
        for (a, &m) in minima.iter().enumerate() {
            let others: f64 = minima.iter().enumerate().filter(|&(b, _)| b != a).map(|(_, m)| m * m).sum();
            let reach = (sampled * sampled - others).sqrt();
            assert!((axis_sampled_level(sampled, composite_min, m) - reach).abs() < 1e-12, "axis {a}");
        }
        // A set below the composite's minimum holds no state; the axis keeps at least its own minimum.
        assert_eq!(axis_sampled_level(0.5, composite_min, 0.3), 0.3);
    }

    #[test]
    fn the_composed_bound_is_the_largest_error_the_axes_excesses_allow_at_their_reach() {
        // One axis with an excess: the worst start puts that axis at its reach and the others at the rest.
        let (sampled, reach, delta) = (1.0f64, 0.3f64, 0.5f64);
        let worst = (sampled * sampled - reach * reach + (reach + delta).powi(2)).sqrt();
        assert!((composed_bound(sampled, &[(0.0, 0.7), (0.0, 0.7), (delta, reach)]) - worst).abs() < 1e-12);
        // Where every axis reaches the whole set, the triangle inequality is the smaller.
        let spread = composed_bound(sampled, &[(0.1, 1.0), (0.1, 1.0), (0.1, 1.0)]);
        assert!((spread - (sampled + (3.0f64 * 0.01).sqrt())).abs() < 1e-12);
        // Negative excesses count as none: the set's own level.
        assert_eq!(composed_bound(sampled, &[(-0.2, 0.7), (-0.1, 0.5)]), sampled);
    }
}
