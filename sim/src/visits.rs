//! The relative states the online loop put the tracker in, one per control period, with the branch of
//! adjustPlannerControl that placed the planner and the `beta` whose row was in force: what verification's
//! operational check draws from (`fastrack-grid verify --operational-states FILE`).
//!
//! Written as CSV: a header `branch,beta,<the model's state coordinates>` and one line per visit.

use fastrack_online::online_loop::Branch;
use serde::{Deserialize, Serialize};
use std::io::Write;
use std::path::Path;

/// One control period's relative state, as the online loop handed it to the server.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Visit {
    /// The branch of adjustPlannerControl that placed the planner.
    pub branch: Branch,
    /// The `beta` whose row was in force over the period.
    pub beta: f64,
    /// The relative state the control was read at, `s - Q p`.
    pub state: Vec<f64>,
}

/// Writes `visits` as CSV into `path` (its folder made if needed), with `state_names` as the state columns;
/// returns how many were written.
pub fn write_csv<'a>(
    path: &Path,
    state_names: &[String],
    visits: impl IntoIterator<Item = &'a Visit>,
) -> std::io::Result<usize> {
    if let Some(dir) = path.parent().filter(|d| !d.as_os_str().is_empty()) {
        std::fs::create_dir_all(dir)?;
    }
    let mut out = std::io::BufWriter::new(std::fs::File::create(path)?);
    writeln!(out, "branch,beta,{}", state_names.join(","))?;
    let mut written = 0;
    for visit in visits {
        let state: Vec<String> = visit.state.iter().map(f64::to_string).collect();
        writeln!(out, "{},{},{}", visit.branch.name(), visit.beta, state.join(","))?;
        written += 1;
    }
    out.flush()?;
    Ok(written)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn visits_are_written_one_line_each_under_the_state_header() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("runs/visits.csv");
        let visits = [
            Visit { branch: Branch::Advance, beta: 1.25, state: vec![0.1, -0.2, 0.5, 1.0] },
            Visit { branch: Branch::Hold, beta: 0.5, state: vec![0.0, 0.0, 3.0, 0.25] },
        ];
        let names: Vec<String> = ["x_r", "y_r", "theta", "v"].iter().map(|s| s.to_string()).collect();
        assert_eq!(write_csv(&path, &names, &visits).unwrap(), 2);
        let text = std::fs::read_to_string(&path).unwrap();
        assert_eq!(text, "branch,beta,x_r,y_r,theta,v\nadvance,1.25,0.1,-0.2,0.5,1\nhold,0.5,0,0,3,0.25\n");
    }
}
