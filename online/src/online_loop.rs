//! The paper's online loop (Alg. 3), one control step at a time, over a `Track` stream.
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
//! The decisions are [`crate::core::LoopCore`]'s; this loop answers its questions over the network. The tick
//! that carries `p_next` (or the candidate `p*`) returns `beta_query`, the bound's membership and `u*`
//! together, so the common branch costs one round trip; a reset asks about all its candidates in one
//! `TrackingControl` batch and then ticks the chosen one; a hold reads its control with one more
//! `TrackingControl` call under `beta_old`.
//! The server's `beta_query` is checked against the local one: a table that changed under the loop (the
//! model was reloaded) is fetched again and the step repeated once.

use crate::core::{Answer, CoreError, CoreSettings, LoopCore, ModelView, Progress, Query};
use crate::geometry::{Obstacle, Point};
use crate::raw_path::{PlanError, RawPathPlanner};
use fastrack_client::{pb, ClientError, FastrackClient, TrackStream};
use fastrack_proto::planner_speed::SpeedRow;

pub use crate::core::{Branch, StepReport};

/// Out-of-domain states are answered with a flag, as on the `Track` stream.
const FLAG: pb::OutOfDomainPolicy = pb::OutOfDomainPolicy::Flag;

/// How the loop runs.
#[derive(Debug, Clone, PartialEq)]
pub struct LoopSettings {
    /// The model, by name and version (0: the server's default version).
    pub model: pb::ModelRef,
    /// Control period `dt` (s): the planner moves at most `beta_query dt` per axis per step.
    pub control_period: f64,
    /// Where the planner goes.
    pub goal: Point,
    /// The workspace, `(min, max)`, for the raw-path planner.
    pub bounds: (Point, Point),
    /// Reset candidates asked about per reset before the planner holds.
    pub reset_candidates: usize,
    /// Seed of the reset candidates.
    pub seed: u64,
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
    /// The raw path could not be planned.
    #[error(transparent)]
    Plan(#[from] PlanError),
    /// The model cannot drive this loop, or the loop's settings are unusable.
    #[error("{0}")]
    Setup(String),
    /// The tracker state does not fit the model.
    #[error("tracker state: {0}")]
    Tracker(String),
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
            CoreError::Plan(e) => LoopError::Plan(e),
            CoreError::Tracker(why) => LoopError::Tracker(why),
            CoreError::NoRow { beta_old, beta_u } => LoopError::TableMismatch { local: beta_old, server: beta_u },
            other => LoopError::Setup(other.to_string()),
        }
    }
}

/// The horizon over which the model's rows were verified: the shortest of them (`None`: no row verified).
pub fn certificate_horizon(info: &pb::ModelInfo) -> Option<f64> {
    info.teb_table.iter().filter_map(|row| row.verification.as_ref().map(|v| v.horizon)).reduce(f64::min)
}

/// The online loop of one robot: [`LoopCore`]'s decisions, answered by the server over one `Track` stream.
pub struct OnlineLoop {
    client: FastrackClient,
    stream: TrackStream,
    model: pb::ModelRef,
    core: LoopCore,
    n_params: usize,
    seq: u64,
}

impl OnlineLoop {
    /// Opens a `Track` stream for the model and places the planner at `start` (its initial state `p_0`).
    pub async fn start(client: &FastrackClient, settings: LoopSettings, start: Point) -> Result<Self, LoopError> {
        let core_settings = CoreSettings {
            control_period: settings.control_period,
            goal: settings.goal,
            bounds: settings.bounds,
            reset_candidates: settings.reset_candidates,
            seed: settings.seed,
        };
        // Settings are checked before the server is asked anything.
        core_settings.check()?;
        let info = client.get_model(settings.model.clone()).await?;
        if info.planner_dim != 2 {
            return Err(LoopError::Setup(format!(
                "model {} has a {}-D planner; the online loop plans in the plane (2-D planners)",
                info.name, info.planner_dim
            )));
        }
        let view = ModelView {
            speeds: info.teb_table.iter().map(SpeedRow::from).collect(),
            planner_to_state: info.planner_to_state.clone(),
            n_state: info.state.len(),
            certificate_horizon: certificate_horizon(&info),
        };
        let core = LoopCore::new(view, core_settings, start)?;
        let stream = client.track(settings.model.clone(), 0.0).await?;
        Ok(Self { client: client.clone(), stream, model: settings.model, core, n_params: info.params.len(), seq: 0 })
    }

    /// The planner's current state `p`.
    pub fn planner(&self) -> Point {
        self.core.planner()
    }

    /// What is left of the raw path after the planner's state.
    pub fn raw_path(&self) -> impl Iterator<Item = &Point> {
        self.core.raw_path()
    }

    /// The obstacles sensed so far.
    pub fn obstacles(&self) -> &[Obstacle] {
        self.core.obstacles()
    }

    /// The tracker's position in the planner's plane, `Q^T s`.
    pub fn tracker_position(&self, tracker: &[f64]) -> Point {
        self.core.tracker_position(tracker)
    }

    /// One control step of Alg. 3 for tracker state `tracker` and the obstacles sensed now. A table that
    /// changed under the loop (the model was reloaded) is fetched again and the step taken again once.
    pub async fn step(
        &mut self,
        tracker: &[f64],
        sensed: &[Obstacle],
        planner: &mut dyn RawPathPlanner,
    ) -> Result<StepReport, LoopError> {
        match self.decide(tracker, sensed, planner).await {
            Err(LoopError::TableMismatch { .. }) => {
                let info = self.client.get_model(self.model.clone()).await?;
                self.core.replace_table(info.teb_table.iter().map(SpeedRow::from).collect())?;
                self.decide(tracker, &[], planner).await
            }
            other => other,
        }
    }

    async fn decide(
        &mut self,
        tracker: &[f64],
        sensed: &[Obstacle],
        planner: &mut dyn RawPathPlanner,
    ) -> Result<StepReport, LoopError> {
        let mut step = self.core.begin(tracker, sensed, planner)?;
        loop {
            let answers = self.ask(step.query()).await?;
            match step.answer(&mut self.core, answers)? {
                Progress::Ask(next) => step = next,
                Progress::Done(report) => return Ok(report),
            }
        }
    }

    /// Answers one of the core's questions: a tick on the stream (its `beta_query` checked against the
    /// core's), or one `TrackingControl` batch.
    async fn ask(&mut self, query: &Query) -> Result<Vec<Answer>, LoopError> {
        match query {
            Query::Tick { tracker, planner, d_obs, beta } => {
                let seq = self.seq;
                self.seq += 1;
                let tick = pb::TrackTick {
                    seq,
                    tracker_state: tracker.clone(),
                    planner_state: planner.to_vec(),
                    d_obs: *d_obs,
                };
                let reply = self.stream.tick(tick).await?;
                if let Some(error) = reply.error {
                    return Err(LoopError::Tick { seq, code: error.code, message: error.message });
                }
                if reply.beta_query != *beta {
                    return Err(LoopError::TableMismatch { local: *beta, server: reply.beta_query });
                }
                Ok(vec![Answer {
                    relative_state: reply.relative_state,
                    value: reply.value,
                    in_set: reply.in_teb,
                    in_domain: reply.in_domain,
                    control: reply.control,
                }])
            }
            Query::Batch { states, beta } => {
                let n_state = self.core.view().n_state;
                let count = states.len() / n_state;
                let params = vec![*beta; count * self.n_params];
                let reply = self.client.tracking_control(self.model.clone(), states.clone(), params, FLAG).await?;
                let n_control = reply.controls.len() / count.max(1);
                let fits = reply.values.len() == count && reply.in_teb.len() == count && reply.in_domain.len() == count;
                if !fits || reply.controls.len() != count * n_control {
                    return Err(LoopError::Setup(format!(
                        "TrackingControl answered a batch of {count} with {} values",
                        reply.values.len()
                    )));
                }
                Ok((0..count)
                    .map(|i| Answer {
                        relative_state: states[i * n_state..(i + 1) * n_state].to_vec(),
                        value: reply.values[i],
                        in_set: reply.in_teb[i],
                        in_domain: reply.in_domain[i],
                        control: reply.controls[i * n_control..(i + 1) * n_control].to_vec(),
                    })
                    .collect())
            }
        }
    }
}
