//! Golden traces of the online loop: what Parametric FaSTrack's loop was given and what it decided at every
//! control period of a run, so that another implementation of the loop (the Python client's) can be given
//! the same and checked decision for decision against the same server.
//!
//! A trace is one JSON file per run (`docs/online-loop.md` describes the format): the loop's settings and
//! start, then per control period the tracker state and the obstacles sensed for the first time at that
//! period (the loop measures `d_obs` over every obstacle sensed so far, so the new ones are all it needs),
//! with the branch, `beta_old`, `beta_query`, the bound, the planner state, the replan flag, the questions
//! asked, the certified-set membership and the certificate's age.

use fastrack_online::core::StepReport;
use fastrack_online::geometry::Point;
use fastrack_online::online_loop::Branch;
use serde::de::DeserializeOwned;
use serde::{Deserialize, Serialize};
use std::path::Path;

/// The trace format's name and version.
pub const FORMAT: &str = "fastrack-loop-trace/1";

/// One run of the online loop among obstacles `O` of a workspace of `D` axes, as given and as decided.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(bound(
    serialize = "O: Serialize, [f64; D]: Serialize",
    deserialize = "O: Deserialize<'de>, [f64; D]: Deserialize<'de>"
))]
pub struct LoopTrace<O, const D: usize> {
    /// [`FORMAT`].
    pub format: String,
    /// The model's name.
    pub model: String,
    /// The model's version.
    pub version: u32,
    /// Control period (s).
    pub control_period: f64,
    /// The goal.
    pub goal: Point<D>,
    /// The workspace, `[min, max]`.
    pub bounds: [Point<D>; 2],
    /// Reset candidates per reset.
    pub reset_candidates: usize,
    /// The planner's initial state.
    pub start: Point<D>,
    /// One entry per control period.
    pub steps: Vec<TraceStep<O, D>>,
}

/// One control period: what the loop was given and what it decided.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(bound(
    serialize = "O: Serialize, [f64; D]: Serialize",
    deserialize = "O: Deserialize<'de>, [f64; D]: Deserialize<'de>"
))]
pub struct TraceStep<O, const D: usize> {
    /// The tracker state at the period's start.
    pub tracker: Vec<f64>,
    /// Obstacles sensed for the first time at this period.
    pub sensed: Vec<O>,
    /// adjustPlannerControl's branch.
    pub branch: Branch,
    /// The `beta` in force before the step.
    pub beta_old: f64,
    /// The step's planner speed bound.
    pub beta_query: f64,
    /// The bound in force over the period.
    pub dteb_radius: f64,
    /// The planner state after the step.
    pub planner: Point<D>,
    /// The raw path was planned again.
    pub replanned: bool,
    /// Questions asked of the model.
    pub round_trips: usize,
    /// The relative state lies in the certified set of the row in force.
    pub in_teb: bool,
    /// Seconds since the relative state last lay in that set.
    pub certificate_age: f64,
}

impl<O, const D: usize> TraceStep<O, D> {
    /// The step of `report`, given `tracker` and the newly sensed `sensed`.
    pub fn new(tracker: &[f64], sensed: Vec<O>, report: &StepReport<D>) -> Self {
        Self {
            tracker: tracker.to_vec(),
            sensed,
            branch: report.branch,
            beta_old: report.beta_old,
            beta_query: report.beta_query,
            dteb_radius: report.dteb_radius,
            planner: report.planner,
            replanned: report.replanned,
            round_trips: report.round_trips,
            in_teb: report.in_teb,
            certificate_age: report.certificate_age,
        }
    }
}

impl<O: Serialize + DeserializeOwned, const D: usize> LoopTrace<O, D>
where
    [f64; D]: Serialize + DeserializeOwned,
{
    /// Writes the trace as JSON into `path`.
    pub fn write(&self, path: &Path) -> std::io::Result<()> {
        let text = serde_json::to_string(self).map_err(std::io::Error::other)?;
        std::fs::write(path, text)
    }

    /// Reads a trace written by [`LoopTrace::write`].
    pub fn read(path: &Path) -> Result<Self, String> {
        let text = std::fs::read_to_string(path).map_err(|e| format!("{}: {e}", path.display()))?;
        let trace: Self = serde_json::from_str(&text).map_err(|e| format!("{}: {e}", path.display()))?;
        if trace.format != FORMAT {
            return Err(format!("{}: format `{}`, expected `{FORMAT}`", path.display(), trace.format));
        }
        Ok(trace)
    }
}
