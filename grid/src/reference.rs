//! Ground-truth references for a bundle's TEB rows: at each row's `beta`, the bound the project's ground
//! truth gives, so that the served bound never undercuts it ([`TebRow::bound`]).
//!
//! A system the grid solves whole (dubins4d) takes the `V_min` of its solution at the row's `beta`, or at the
//! next solved `beta` above it: `V_min` grows with `beta`, so that one is no smaller. A decomposed system
//! (quad10d: the x, y and z axes) takes each axis' bound the same way from its subsystem's solutions, or, where
//! the subsystem has a closed form, from that and a solution at the row's own `beta`, the larger of the two; it
//! combines the axes' bounds as the error's norm,
//! `sqrt(sum V_axis^2)`: every axis' error stays within its own bound, so the error vector within that norm.

use fastrack_gridfile::solution::Solution;
use fastrack_valuefn::manifest::{Reference, TebRow};
use fastrack_valuefn::system::{closed_form_teb, decomposition};

/// What a grid solution says of one system at one `beta`.
#[derive(Debug, Clone, PartialEq)]
pub struct SolvedBound {
    /// The solved system (a subsystem's id for an axis).
    pub system: String,
    /// Its planner speed bound.
    pub beta: f64,
    /// The solution's `V_min`.
    pub v_min: f64,
}

impl SolvedBound {
    /// The bound a solution gives.
    pub fn of(solution: &Solution) -> Self {
        Self { system: solution.info.system.clone(), beta: solution.info.params[0], v_min: solution.v_min() }
    }
}

/// The bound of one axis (or of a whole system) at `beta`, and where it comes from.
/// With a closed form, a grid solution counts only at the row's own `beta` (where it may lie above the
/// closed form by its numerical error); without one, the next solved `beta` at or above the row's.
fn axis_bound(system: &str, beta: f64, solved: &[SolvedBound]) -> Option<(f64, String)> {
    let tolerance = 1e-9 * beta.abs().max(1.0);
    let closed = closed_form_teb(system).map(|f| {
        let v = f(beta);
        (v, format!("{system}: closed form {v:.4}"))
    });
    let usable = |s: &&SolvedBound| {
        s.system == system
            && if closed.is_some() { (s.beta - beta).abs() <= tolerance } else { s.beta >= beta - tolerance }
    };
    let grid = solved
        .iter()
        .filter(usable)
        .min_by(|a, b| a.beta.total_cmp(&b.beta))
        .map(|s| (s.v_min, format!("{system}: grid at beta {} V_min {:.4}", s.beta, s.v_min)));
    match (grid, closed) {
        (Some(g), Some(c)) => Some(if g.0 >= c.0 { g } else { c }),
        (g, c) => g.or(c),
    }
}

/// The reference of system `id` at `beta` from the `solved` bounds and the closed forms; None where the
/// system, or one of its axes, has neither a solution at or above `beta` nor a closed form.
pub fn reference_at(id: &str, beta: f64, solved: &[SolvedBound]) -> Option<Reference> {
    let systems: Vec<&str> = match decomposition(id) {
        Some(axes) => axes.iter().map(|a| a.subsystem).collect(),
        None => vec![id],
    };
    let bounds = systems.iter().map(|system| axis_bound(system, beta, solved)).collect::<Option<Vec<_>>>()?;
    let bound = bounds.iter().map(|(v, _)| v * v).sum::<f64>().sqrt();
    let mut sources: Vec<String> = bounds.into_iter().map(|(_, source)| source).collect();
    sources.dedup();
    let source = if systems.len() > 1 {
        format!("sqrt of the sum of the axes' squares ({})", sources.join("; "))
    } else {
        sources.concat()
    };
    Some(Reference { bound, source })
}

/// Sets the reference of every row of `table` that has one (rows without keep theirs); the number of rows
/// that got one.
pub fn set_references(id: &str, table: &mut [TebRow], solved: &[SolvedBound]) -> usize {
    let mut count = 0;
    for row in table {
        if let Some(reference) = reference_at(id, row.beta, solved) {
            row.reference = Some(reference);
            count += 1;
        }
    }
    count
}

#[cfg(test)]
mod tests {
    use super::*;
    use fastrack_valuefn::system::quad10d;

    fn solved(system: &str, beta: f64, v_min: f64) -> SolvedBound {
        SolvedBound { system: system.into(), beta, v_min }
    }

    #[test]
    fn a_whole_system_takes_the_next_solved_beta_at_or_above_the_row() {
        let solved = [solved("dubins4d", 0.5, 0.63), solved("dubins4d", 0.875, 1.28), solved("dubins4d", 1.25, 1.9)];
        let at = |beta| reference_at("dubins4d", beta, &solved).map(|r| r.bound);
        assert_eq!([at(0.5), at(0.6), at(0.875), at(1.0), at(1.25)], [0.63, 1.28, 1.28, 1.9, 1.9].map(Some));
        assert_eq!(at(1.3), None, "no solution at or above 1.3");
        assert!(reference_at("dubins4d", 0.6, &solved).unwrap().source.contains("beta 0.875"));
    }

    #[test]
    fn a_decomposed_system_combines_its_axes_as_the_error_norm_with_the_closed_form_where_larger() {
        let x = quad10d::X_AXIS_ID;
        let z = quad10d::Z_AXIS_ID;
        let closed = quad10d::z_axis_closed_form_teb(1.0);
        // The x axis from its grid at the next beta above, z from its closed form (no z solution).
        let reference = reference_at(quad10d::ID, 1.0, &[solved(x, 1.1, 0.8)]).unwrap();
        assert!((reference.bound - (2.0 * 0.8f64.powi(2) + closed * closed).sqrt()).abs() < 1e-12);
        assert!(reference.source.contains("closed form"), "{}", reference.source);
        // A z solution at the row's beta above the closed form wins; one below it loses, and so does one at
        // another beta (the closed form is exact there).
        let high = reference_at(quad10d::ID, 1.0, &[solved(x, 1.0, 0.8), solved(z, 1.0, closed + 0.1)]).unwrap();
        assert!((high.bound - (2.0 * 0.64 + (closed + 0.1).powi(2)).sqrt()).abs() < 1e-12);
        let low = reference_at(quad10d::ID, 1.0, &[solved(x, 1.0, 0.8), solved(z, 1.0, closed - 0.1)]).unwrap();
        assert!((low.bound - reference.bound).abs() < 1e-12);
        let above = reference_at(quad10d::ID, 1.0, &[solved(x, 1.0, 0.8), solved(z, 1.5, closed + 1.0)]).unwrap();
        assert!((above.bound - reference.bound).abs() < 1e-12);
        // No x solution at or above the row: no reference.
        assert!(reference_at(quad10d::ID, 1.2, &[solved(x, 1.1, 0.8)]).is_none());
    }
}
