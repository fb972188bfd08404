//! The TEB-table rules the server answers with (never interpolated towards a less safe answer).

use fastrack_valuefn::manifest::TebRow;

/// The row answering for `beta`: the first row whose `beta` is at least the requested one (its level
/// bounds every smaller `beta`, the table being monotone). `None` if `beta` exceeds the last row.
pub fn row_for(rows: &[TebRow], beta: f64) -> Option<&TebRow> {
    rows.iter().find(|row| row.beta >= beta - 1e-12 * row.beta.abs().max(1.0))
}

/// The paper's queryPlannerControl on a TEB table.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PlannerSpeed {
    /// Chosen planner speed bound.
    pub beta: f64,
    /// TEB radius at `beta` (the dTEB).
    pub dteb_radius: f64,
    /// TEB radius at `beta_l` (the sTEB).
    pub steb_radius: f64,
    /// The sTEB does not fit in the ball of radius `d_obs / 2`.
    pub steb_exceeds_half_distance: bool,
}

/// `d_obs = None` (no obstacle sensed): the fastest row. Otherwise, if the sTEB radius exceeds `d_obs / 2`
/// the slowest row (`beta_l`), else the largest `beta` whose radius is at most `d_obs / 2`.
/// `rows` must be non-empty, sorted by `beta`, with monotone levels (as manifest validation ensures).
pub fn query_planner_control(rows: &[TebRow], d_obs: Option<f64>) -> PlannerSpeed {
    let slowest = &rows[0];
    let steb_radius = slowest.served_level();
    let chosen = match d_obs {
        None => &rows[rows.len() - 1],
        Some(d) => rows.iter().rev().find(|row| row.served_level() <= d / 2.0).unwrap_or(slowest),
    };
    PlannerSpeed {
        beta: chosen.beta,
        dteb_radius: chosen.served_level(),
        steb_radius,
        steb_exceeds_half_distance: d_obs.is_some_and(|d| steb_radius > d / 2.0),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A hand-made table: beta = 0.5 + 0.05 k, level = 0.2 + 0.1 k (k = 0..15).
    fn table() -> Vec<TebRow> {
        (0..16)
            .map(|k| TebRow {
                beta: 0.5 + 0.05 * k as f64,
                level: 0.2 + 0.1 * k as f64,
                measured_min: 0.2 + 0.1 * k as f64,
                extent: vec![0.0, 0.0],
                boundary_radii: vec![],
                verification: None,
            })
            .collect()
    }

    #[test]
    fn no_obstacle_gives_fastest_beta() {
        let q = query_planner_control(&table(), None);
        assert_eq!(q.beta, 0.5 + 0.05 * 15.0);
        assert!((q.dteb_radius - 1.7).abs() < 1e-12);
        assert!((q.steb_radius - 0.2).abs() < 1e-12);
        assert!(!q.steb_exceeds_half_distance);
    }

    #[test]
    fn zero_distance_and_distance_below_steb_give_slowest_beta() {
        for d in [0.0, 0.1, 0.399] {
            let q = query_planner_control(&table(), Some(d));
            assert_eq!(q.beta, 0.5, "d_obs {d}");
            assert!((q.dteb_radius - 0.2).abs() < 1e-12);
            assert!(q.steb_exceeds_half_distance);
        }
    }

    #[test]
    fn largest_fitting_beta_is_chosen_never_a_larger_one() {
        // d/2 = 0.75: levels 0.2..0.7 fit (k = 0..5), 0.8 does not.
        let q = query_planner_control(&table(), Some(1.5));
        assert!((q.beta - 0.75).abs() < 1e-12 && (q.dteb_radius - 0.7).abs() < 1e-9, "{q:?}");
        // Exactly on a level: that row fits.
        let q = query_planner_control(&table(), Some(1.6));
        assert!((q.beta - 0.8).abs() < 1e-12, "{q:?}");
        assert!(!q.steb_exceeds_half_distance);
    }

    #[test]
    fn verified_level_raises_the_radius() {
        let mut rows = table();
        rows[0].verification = Some(fastrack_valuefn::manifest::Verification {
            verified_level: 0.3,
            eps: 0.01,
            delta: 1e-6,
            samples: 3000,
            violations: 2,
            horizon: 10.0,
            step: 0.01,
        });
        let q = query_planner_control(&rows, Some(0.5));
        assert!(q.steb_exceeds_half_distance && (q.steb_radius - 0.3).abs() < 1e-12);
    }

    #[test]
    fn row_for_rounds_up_to_the_next_table_beta() {
        let rows = table();
        assert_eq!(row_for(&rows, 0.5).unwrap().beta, 0.5);
        assert!((row_for(&rows, 0.51).unwrap().beta - 0.55).abs() < 1e-12);
        assert!(row_for(&rows, 1.3).is_none());
    }
}
