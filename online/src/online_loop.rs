//! The paper's online loop (Alg. 3), one control step at a time, its questions answered by an [`Oracle`].
//!
//! Each [`OnlineLoop::step`] takes the tracker state and the obstacles sensed now, and
//! 1. measures `d_obs`, the distance from the tracker to the nearest obstacle sensed so far;
//! 2. keeps `beta_old` and applies queryPlannerControl to its copy of the model's TEB table (the rule the
//!    server applies, `fastrack_proto::planner_speed`), giving `beta_query` and `dTEBmax`;
//! 3. replans the raw path around the obstacles inflated by the sTEB when an obstacle is newly sensed or the
//!    replan flag is set;
//! 4. adjusts the planner (adjustPlannerControl): when `beta_query < beta_old`, keeps `p*`, the raw-path
//!    state closest to the tracker, if `s - Q p*` lies in the certified set of `beta_query` (the server's
//!    `in_teb`, `V <= set level`: where `dTEBmax` holds), else resets the planner to a free point of the
//!    inflated map with `s - Q p` in that set and flags a replan, else (no such point: the
//!    tracker's speed or heading lies outside the smaller set) holds: the planner waits where it is with
//!    `beta_old` and its bound still in force, and the drop is tried again at the next step; otherwise moves
//!    the planner along the raw path for one control period at per-axis speed at most `beta_query`;
//! 5. reads `u*` at `r_next = s - Q p_next` under `beta_query` (`beta_old` on a hold).
//!
//! The decisions are [`crate::core::LoopCore`]'s; an [`Oracle`] answers its questions. Over the network
//! ([`TrackOracle`], [`OnlineLoop::start`]) the tick that carries `p_next` (or the candidate `p*`) returns
//! `beta_query`, the bound's membership and `u*` together, so the common branch costs one round trip; a
//! reset asks about all its candidates in one `TrackingControl` batch and then ticks the chosen one; a hold
//! reads its control with one more `TrackingControl` call under `beta_old`.
//! The oracle's `beta_query` is checked against the local one: a table that changed under the loop (the
//! model was reloaded) is fetched again and the step repeated once.

use crate::core::{CoreError, CoreSettings, LoopCore, Progress, DEFAULT_RESET_CANDIDATES};
use crate::geometry::{Obstacle, Point};
use crate::oracle::Oracle;
use crate::raw_path::RawPathPlanner;
use crate::track_oracle::TrackOracle;
use fastrack_client::{pb, ClientError, FastrackClient};
pub use fastrack_proto::planner_speed::SpeedRule;

pub use crate::core::{Branch, StepReport};

/// How the loop runs, in a `D`-axis workspace.
#[derive(Debug, Clone, PartialEq)]
pub struct LoopSettings<const D: usize> {
    /// The model, by name and version (0: the server's default version).
    pub model: pb::ModelRef,
    /// Control period `dt` (s): the planner moves at most `beta_query dt` per axis per step.
    pub control_period: f64,
    /// Where the planner goes.
    pub goal: Point<D>,
    /// The workspace, `(min, max)`, for the raw-path planner.
    pub bounds: (Point<D>, Point<D>),
    /// Reset candidates asked about per reset before the planner holds.
    pub reset_candidates: usize,
    /// The rule that picks `beta_query` (the paper's by default).
    pub rule: SpeedRule,
}

/// Why a step could not be taken.
#[derive(Debug, thiserror::Error)]
pub enum LoopError {
    /// The server could not be reached or refused a call.
    #[error(transparent)]
    Client(#[from] ClientError),
    /// The server answered a tick with an error.
    #[error("the server refused tick {seq}: {message} (gRPC code {code})")]
    Tick {
        /// The tick.
        seq: u64,
        /// The status code.
        code: i32,
        /// The server's message.
        message: String,
    },
    /// A model answered in the same process refused a question.
    #[error("the model refused a question: {message} (gRPC code {code})")]
    Refused {
        /// The status code the service would have answered with.
        code: i32,
        /// Why.
        message: String,
    },
    /// The core could not take or finish the step (no raw path, unusable settings or model, a tracker
    /// state that does not fit).
    #[error(transparent)]
    Core(CoreError),
    /// The server's `beta_query` still differed from the loop's after the table was fetched again.
    #[error("the server chose beta {server} where the table gives {local}: the model changes under the loop")]
    TableMismatch {
        /// The loop's choice.
        local: f64,
        /// The server's.
        server: f64,
    },
}

impl From<CoreError> for LoopError {
    fn from(e: CoreError) -> Self {
        match e {
            CoreError::NoRow { beta_old, beta_u } => LoopError::TableMismatch { local: beta_old, server: beta_u },
            other => LoopError::Core(other),
        }
    }
}

impl<const D: usize> LoopSettings<D> {
    /// Settings for `model` at `control_period` toward `goal` in `bounds`, with
    /// [`DEFAULT_RESET_CANDIDATES`] and the paper's rule.
    pub fn new(model: pb::ModelRef, control_period: f64, goal: Point<D>, bounds: (Point<D>, Point<D>)) -> Self {
        Self {
            model,
            control_period,
            goal,
            bounds,
            reset_candidates: DEFAULT_RESET_CANDIDATES,
            rule: SpeedRule::default(),
        }
    }

    /// The core's share of the settings.
    pub fn core(&self) -> CoreSettings<D> {
        CoreSettings {
            control_period: self.control_period,
            goal: self.goal,
            bounds: self.bounds,
            reset_candidates: self.reset_candidates,
            rule: self.rule,
        }
    }
}

/// The online loop of one robot among obstacles `O` of a `D`-axis workspace: [`LoopCore`]'s decisions,
/// answered by an [`Oracle`] `A` (by default the server, over one `Track` stream).
pub struct OnlineLoop<O, const D: usize, A = TrackOracle> {
    oracle: A,
    core: LoopCore<O, D>,
}

impl<O: Obstacle<D>, const D: usize> OnlineLoop<O, D, TrackOracle> {
    /// Opens a `Track` stream for the model and places the planner at `start` (its initial state `p_0`).
    pub async fn start(client: &FastrackClient, settings: LoopSettings<D>, start: Point<D>) -> Result<Self, LoopError> {
        // Settings are checked before the server is asked anything.
        let core = settings.core();
        core.check()?;
        let oracle = TrackOracle::open(client, settings.model).await?;
        Self::new(oracle, core, start)
    }
}

impl<O: Obstacle<D>, const D: usize, A: Oracle> OnlineLoop<O, D, A> {
    /// A loop whose questions `oracle` answers, with the planner at `start` (its initial state `p_0`).
    pub fn new(oracle: A, settings: CoreSettings<D>, start: Point<D>) -> Result<Self, LoopError> {
        let core = LoopCore::new(oracle.view().clone(), settings, start)?;
        Ok(Self { oracle, core })
    }

    /// The planner's current state `p`.
    pub fn planner(&self) -> Point<D> {
        self.core.planner()
    }

    /// What is left of the raw path after the planner's state.
    pub fn raw_path(&self) -> impl Iterator<Item = &Point<D>> {
        self.core.raw_path()
    }

    /// The obstacles sensed so far.
    pub fn obstacles(&self) -> &[O] {
        self.core.obstacles()
    }

    /// The tracker's position in the planner's position space, `Q^T s`.
    pub fn tracker_position(&self, tracker: &[f64]) -> Point<D> {
        self.core.tracker_position(tracker)
    }

    /// One control step of Alg. 3 for tracker state `tracker` and the obstacles sensed now. A table that
    /// changed under the loop (the model was reloaded) is fetched again and the step taken again once.
    pub async fn step(
        &mut self,
        tracker: &[f64],
        sensed: &[O],
        planner: &mut dyn RawPathPlanner<O, D>,
    ) -> Result<StepReport<D>, LoopError> {
        match self.decide(tracker, sensed, planner).await {
            Err(LoopError::TableMismatch { .. }) => {
                let speeds = self.oracle.refresh().await?;
                self.core.replace_table(speeds)?;
                self.decide(tracker, &[], planner).await
            }
            other => other,
        }
    }

    async fn decide(
        &mut self,
        tracker: &[f64],
        sensed: &[O],
        planner: &mut dyn RawPathPlanner<O, D>,
    ) -> Result<StepReport<D>, LoopError> {
        let mut step = self.core.begin(tracker, sensed, planner)?;
        loop {
            let answers = self.oracle.answer(step.query()).await?;
            match step.answer(&mut self.core, answers)? {
                Progress::Ask(next) => step = next,
                Progress::Done(report) => return Ok(report),
            }
        }
    }
}
