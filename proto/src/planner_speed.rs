//! The rules both sides of the contract apply to a TEB table: the paper's queryPlannerControl, the planner
//! rule beside it, and the row that answers for a `beta`. The server answers with them; an online loop
//! applies them to its copy of the table (from `GetModel`) to plan a step before it asks, so that a step
//! costs one round trip, and checks the server's answer against its own. No rule ever interpolates towards
//! a less safe answer.

use crate::v1 as pb;

/// One row of a TEB table as the rules read it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SpeedRow {
    /// Planner speed bound `beta`.
    pub beta: f64,
    /// The row's tracking error bound: the TEB radius at `beta`.
    pub bound: f64,
}

impl From<&pb::TebRow> for SpeedRow {
    fn from(row: &pb::TebRow) -> Self {
        Self { beta: row.beta, bound: row.bound }
    }
}

/// What queryPlannerControl chose.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PlannerSpeed {
    /// The planner speed bound to use, `beta_query`.
    pub beta: f64,
    /// Index of its row in the table.
    pub row: usize,
    /// TEB radius at `beta` (the dTEB, `dTEBmax` in the paper's Alg. 3).
    pub dteb_radius: f64,
    /// TEB radius at `beta_l` (the sTEB).
    pub steb_radius: f64,
    /// The sTEB does not fit in the ball of radius `d_obs / 2` (under [`planner_rule`]: in the planner's
    /// clearance).
    pub steb_exceeds_half_distance: bool,
}

/// queryPlannerControl: with no obstacle sensed (`d_obs = None`) the fastest row; otherwise, if the sTEB
/// radius exceeds `d_obs / 2`, the slowest row (`beta_l`), else the largest `beta` whose radius is at most
/// `d_obs / 2`. `rows` must be non-empty, sorted by `beta`, with monotone bounds (as a validated manifest
/// and `GetModel` give them).
#[inline]
pub fn query_planner_control(rows: &[SpeedRow], d_obs: Option<f64>) -> PlannerSpeed {
    let steb_radius = rows[0].bound;
    let row = match d_obs {
        None => rows.len() - 1,
        Some(d) => rows.iter().rposition(|row| row.bound <= d / 2.0).unwrap_or(0),
    };
    PlannerSpeed {
        beta: rows[row].beta,
        row,
        dteb_radius: rows[row].bound,
        steb_radius,
        steb_exceeds_half_distance: d_obs.is_some_and(|d| steb_radius > d / 2.0),
    }
}

/// Which clearance picks a step's planner speed.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum SpeedRule {
    /// The paper's queryPlannerControl on the tracker's distance `d_obs` to the nearest sensed obstacle:
    /// bounds up to `d_obs / 2`.
    #[default]
    HalfDistance,
    /// [`planner_rule`] on the planner's own clearance: bounds below it.
    Planner,
}

impl SpeedRule {
    /// The rule's speed at a point `clearance` from the nearest sensed obstacle (`None`: nothing sensed), as a
    /// planner that plans for speed estimates it along a path (the tracker on the planner).
    #[inline]
    pub fn at_clearance(self, rows: &[SpeedRow], clearance: Option<f64>) -> PlannerSpeed {
        match (self, clearance) {
            (SpeedRule::Planner, Some(c)) => planner_rule(rows, c),
            (_, d_obs) => query_planner_control(rows, d_obs),
        }
    }
}

/// The planner rule: the largest `beta` whose radius is less than `planner_clearance`, the planner's distance
/// to the nearest sensed obstacle less the farthest one control period can move it, or `beta_l` when none
/// is. A tracker within the bound of a planner farther than the bound from every obstacle touches none of
/// them, which is the condition the paper's rule reaches by asking for half the tracker's distance.
#[inline]
pub fn planner_rule(rows: &[SpeedRow], planner_clearance: f64) -> PlannerSpeed {
    let steb_radius = rows[0].bound;
    let row = rows.iter().rposition(|row| row.bound < planner_clearance).unwrap_or(0);
    PlannerSpeed {
        beta: rows[row].beta,
        row,
        dteb_radius: rows[row].bound,
        steb_radius,
        steb_exceeds_half_distance: steb_radius >= planner_clearance,
    }
}

/// The row answering for `beta`: the first whose `beta` is at least the requested one (its level bounds
/// every smaller `beta`, the table being monotone). `None` if `beta` exceeds the last row.
pub fn row_for(rows: &[SpeedRow], beta: f64) -> Option<usize> {
    rows.iter().position(|row| row.beta >= beta - 1e-12 * row.beta.abs().max(1.0))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A hand-made table: beta = 0.5 + 0.05 k, bound = 0.2 + 0.1 k (k = 0..15).
    fn table() -> Vec<SpeedRow> {
        (0..16).map(|k| SpeedRow { beta: 0.5 + 0.05 * k as f64, bound: 0.2 + 0.1 * k as f64 }).collect()
    }

    #[test]
    fn no_obstacle_gives_fastest_beta() {
        let q = query_planner_control(&table(), None);
        assert_eq!((q.beta, q.row), (0.5 + 0.05 * 15.0, 15));
        assert!((q.dteb_radius - 1.7).abs() < 1e-12);
        assert!((q.steb_radius - 0.2).abs() < 1e-12);
        assert!(!q.steb_exceeds_half_distance);
    }

    #[test]
    fn zero_distance_and_distance_below_steb_give_slowest_beta() {
        for d in [0.0, 0.1, 0.399] {
            let q = query_planner_control(&table(), Some(d));
            assert_eq!((q.beta, q.row), (0.5, 0), "d_obs {d}");
            assert!((q.dteb_radius - 0.2).abs() < 1e-12);
            assert!(q.steb_exceeds_half_distance);
        }
    }

    #[test]
    fn largest_fitting_beta_is_chosen_never_a_larger_one() {
        // d/2 = 0.75: bounds 0.2..0.7 fit (k = 0..5), 0.8 does not.
        let q = query_planner_control(&table(), Some(1.5));
        assert!((q.beta - 0.75).abs() < 1e-12 && (q.dteb_radius - 0.7).abs() < 1e-9, "{q:?}");
        // Exactly on a bound: that row fits.
        let q = query_planner_control(&table(), Some(1.6));
        assert!((q.beta - 0.8).abs() < 1e-12, "{q:?}");
        assert!(!q.steb_exceeds_half_distance);
    }

    #[test]
    fn a_raised_bound_raises_the_radius() {
        let mut rows = table();
        rows[0].bound = 0.3;
        let q = query_planner_control(&rows, Some(0.5));
        assert!(q.steb_exceeds_half_distance && (q.steb_radius - 0.3).abs() < 1e-12);
    }

    #[test]
    fn the_planner_rule_takes_the_largest_bound_below_the_planners_clearance() {
        // Bounds 0.2..1.7: below 0.75 are 0.2..0.7 (k = 0..5); a bound equal to the clearance does not fit.
        let q = planner_rule(&table(), 0.75);
        assert!((q.beta - 0.75).abs() < 1e-12 && (q.dteb_radius - 0.7).abs() < 1e-9, "{q:?}");
        let q = planner_rule(&table(), 0.7);
        assert!((q.beta - 0.7).abs() < 1e-12, "{q:?}");
        // Twice the reach of the paper's rule at the same distance: a bound of 0.7 fits a planner 0.75 m clear,
        // a tracker 1.5 m from the obstacle under the paper's.
        assert_eq!(planner_rule(&table(), 0.75).beta, query_planner_control(&table(), Some(1.5)).beta);
        let q = planner_rule(&table(), 0.1);
        assert_eq!((q.row, q.steb_exceeds_half_distance), (0, true));
        assert_eq!(planner_rule(&table(), 10.0).row, 15);
    }

    #[test]
    fn row_for_rounds_up_to_the_next_table_beta() {
        let rows = table();
        assert_eq!(row_for(&rows, 0.5), Some(0));
        assert_eq!(row_for(&rows, 0.51), Some(1));
        assert_eq!(row_for(&rows, 1.3), None);
    }
}
