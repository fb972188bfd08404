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
//! The tick that carries `p_next` (or the candidate `p*`) returns `beta_query`, the bound's membership and
//! `u*` together, so the common branch costs one round trip; a reset asks about all its candidates in one
//! `TrackingControl` batch and then ticks the chosen one; a hold reads its control with one more
//! `TrackingControl` call under `beta_old`.
//! The server's `beta_query` is checked against the local one: a table that changed under the loop (the
//! model was reloaded) is fetched again and the step repeated once.

use crate::geometry::{clearance, norm, remember, sub, Obstacle, Point};
use crate::raw_path::{advance_along, PlanError, PlanRequest, RawPathPlanner};
use fastrack_client::{pb, ClientError, FastrackClient, TrackStream};
use fastrack_proto::planner_speed::{query_planner_control, row_for, SpeedRow};
use rand::rngs::StdRng;
use rand::{Rng, SeedableRng};
use std::collections::VecDeque;

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

/// Which branch of adjustPlannerControl a step took.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Branch {
    /// `beta_query >= beta_old`: the planner moved along the raw path.
    Advance,
    /// `beta_query < beta_old` and `s - Q p*` in the certified set of `beta_query`: the planner jumped to `p*`.
    Keep,
    /// `beta_query < beta_old` and `s - Q p*` outside that set: the planner was reset into it, a replan flagged.
    Reset,
    /// `beta_query < beta_old` and no free planner state within `dTEBmax` of the tracker puts `s - Q p` in
    /// that set: the planner waits where it is (a planner at rest obeys every speed bound), `beta_old` and its
    /// bound stay in force, and the drop is tried again at the next step.
    Hold,
}

impl Branch {
    /// Its name in records: `advance`, `keep`, `reset` or `hold`.
    pub fn name(self) -> &'static str {
        match self {
            Branch::Advance => "advance",
            Branch::Keep => "keep",
            Branch::Reset => "reset",
            Branch::Hold => "hold",
        }
    }
}

/// What one step decided.
#[derive(Debug, Clone, PartialEq)]
pub struct StepReport {
    /// Distance from the tracker to the nearest obstacle sensed so far (`None`: none sensed).
    pub d_obs: Option<f64>,
    /// The previous step's `beta_query`.
    pub beta_old: f64,
    /// This step's planner speed bound (`beta_old` on a hold).
    pub beta_query: f64,
    /// `dTEBmax`: the TEB radius at `beta_query`, the bound the tracking error must keep this step.
    pub dteb_radius: f64,
    /// The sTEB radius (at `beta_l`), by which obstacles are inflated.
    pub steb_radius: f64,
    /// True if the raw path was planned again at this step.
    pub replanned: bool,
    /// adjustPlannerControl's branch.
    pub branch: Branch,
    /// The planner state after the step, `p_next`.
    pub planner: Point,
    /// The optimal tracking control at `r_next = s - Q p_next` under `beta_query`.
    pub control: Vec<f64>,
    /// The relative state `r_next`.
    pub relative_state: Vec<f64>,
    /// `V(r_next; beta_query)`.
    pub value: f64,
    /// `r_next` lies in the certified set of `beta_query` (`V <= set level`), from which `dTEBmax` holds.
    pub in_teb: bool,
    /// `r_next` lies inside the model's trained domain.
    pub in_domain: bool,
    /// Ticks and calls sent in this step (1 on the common branch).
    pub round_trips: usize,
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

/// The online loop of one robot.
pub struct OnlineLoop {
    client: FastrackClient,
    stream: TrackStream,
    settings: LoopSettings,
    speeds: Vec<SpeedRow>,
    /// `Q`, row-major `n_state x 2`.
    planner_to_state: Vec<f64>,
    n_state: usize,
    n_params: usize,
    beta_query: f64,
    replan_flag: bool,
    planner: Point,
    raw_path: VecDeque<Point>,
    obstacles: Vec<Obstacle>,
    seq: u64,
    rng: StdRng,
}

impl OnlineLoop {
    /// Opens a `Track` stream for the model and places the planner at `start` (its initial state `p_0`).
    pub async fn start(client: &FastrackClient, settings: LoopSettings, start: Point) -> Result<Self, LoopError> {
        if !(settings.control_period.is_finite() && settings.control_period > 0.0) {
            return Err(LoopError::Setup(format!(
                "control_period = {}; must be a finite number of seconds > 0",
                settings.control_period
            )));
        }
        if settings.reset_candidates == 0 {
            return Err(LoopError::Setup("reset_candidates must be at least 1".into()));
        }
        let info = client.get_model(settings.model.clone()).await?;
        if info.planner_dim != 2 {
            return Err(LoopError::Setup(format!(
                "model {} has a {}-D planner; the online loop plans in the plane (2-D planners)",
                info.name, info.planner_dim
            )));
        }
        let stream = client.track(settings.model.clone(), 0.0).await?;
        let speeds: Vec<SpeedRow> = info.teb_table.iter().map(SpeedRow::from).collect();
        let beta_u = speeds.last().map(|row| row.beta).ok_or_else(|| LoopError::Setup("empty TEB table".into()))?;
        let rng = StdRng::seed_from_u64(settings.seed);
        Ok(Self {
            client: client.clone(),
            stream,
            speeds,
            planner_to_state: info.planner_to_state,
            n_state: info.state.len(),
            n_params: info.params.len(),
            beta_query: beta_u,
            replan_flag: true,
            planner: start,
            raw_path: VecDeque::new(),
            obstacles: Vec::new(),
            seq: 0,
            rng,
            settings,
        })
    }

    /// The planner's current state `p`.
    pub fn planner(&self) -> Point {
        self.planner
    }

    /// What is left of the raw path after the planner's state.
    pub fn raw_path(&self) -> impl Iterator<Item = &Point> {
        self.raw_path.iter()
    }

    /// The obstacles sensed so far.
    pub fn obstacles(&self) -> &[Obstacle] {
        &self.obstacles
    }

    /// The tracker's position in the planner's plane, `Q^T s`.
    pub fn tracker_position(&self, tracker: &[f64]) -> Point {
        let q = &self.planner_to_state;
        [0, 1].map(|j| (0..self.n_state).map(|i| q[2 * i + j] * tracker[i]).sum())
    }

    /// One control step of Alg. 3 for tracker state `tracker` and the obstacles sensed now.
    pub async fn step(
        &mut self,
        tracker: &[f64],
        sensed: &[Obstacle],
        planner: &mut dyn RawPathPlanner,
    ) -> Result<StepReport, LoopError> {
        if tracker.len() != self.n_state {
            return Err(LoopError::Tracker(format!(
                "{} values; the model's state has {}",
                tracker.len(),
                self.n_state
            )));
        }
        if let Some(i) = tracker.iter().position(|x| !x.is_finite()) {
            return Err(LoopError::Tracker(format!("tracker[{i}] = {}; must be finite", tracker[i])));
        }
        let newly_sensed = remember(&mut self.obstacles, sensed);
        match self.decide(tracker, newly_sensed, planner).await {
            Err(LoopError::TableMismatch { .. }) => {
                let info = self.client.get_model(self.settings.model.clone()).await?;
                self.speeds = info.teb_table.iter().map(SpeedRow::from).collect();
                // The new table's sTEB may differ: plan again with it.
                self.decide(tracker, true, planner).await
            }
            other => other,
        }
    }

    async fn decide(
        &mut self,
        tracker: &[f64],
        newly_sensed: bool,
        planner: &mut dyn RawPathPlanner,
    ) -> Result<StepReport, LoopError> {
        let position = self.tracker_position(tracker);
        let d_obs = (!self.obstacles.is_empty()).then(|| clearance(&self.obstacles, position));
        let beta_old = self.beta_query;
        let speed = query_planner_control(&self.speeds, d_obs);
        // The flag stays set until a path is planned: a step that failed to plan plans again next time.
        self.replan_flag |= newly_sensed;
        let replanned = self.replan_flag;
        if replanned {
            let path = planner.plan(&PlanRequest {
                start: self.planner,
                goal: self.settings.goal,
                obstacles: &self.obstacles,
                inflation: speed.steb_radius,
                bounds: self.settings.bounds,
            })?;
            self.raw_path = path.into_iter().skip(1).collect();
            self.replan_flag = false;
        }
        let mut round_trips = 0;
        let (branch, p_next, reply) = if speed.beta < beta_old {
            let (index, p_star) = self.closest_path_state(position);
            round_trips += 1;
            let reply = self.tick(tracker, p_star, d_obs, speed.beta).await?;
            if reply.in_teb {
                self.raw_path.drain(..index);
                (Branch::Keep, p_star, reply)
            } else {
                let (candidate, calls) = self.reset_point(tracker, position, speed).await?;
                round_trips += calls;
                let Some(candidate) = candidate else {
                    return self.hold(tracker, d_obs, beta_old, speed, replanned, round_trips).await;
                };
                round_trips += 1;
                let reply = self.tick(tracker, candidate, d_obs, speed.beta).await?;
                self.raw_path.clear();
                self.replan_flag = true;
                (Branch::Reset, candidate, reply)
            }
        } else {
            // The path is consumed only once the server has answered: a step taken again (the table changed)
            // starts from the same planner state and path.
            let mut ahead = self.raw_path.clone();
            let p_next = advance_along(self.planner, &mut ahead, speed.beta * self.settings.control_period);
            round_trips += 1;
            let reply = self.tick(tracker, p_next, d_obs, speed.beta).await?;
            self.raw_path = ahead;
            (Branch::Advance, p_next, reply)
        };
        self.beta_query = speed.beta;
        self.planner = p_next;
        Ok(StepReport {
            d_obs,
            beta_old,
            beta_query: speed.beta,
            dteb_radius: speed.dteb_radius,
            steb_radius: speed.steb_radius,
            replanned,
            branch,
            planner: p_next,
            control: reply.control,
            relative_state: reply.relative_state,
            value: reply.value,
            in_teb: reply.in_teb,
            in_domain: reply.in_domain,
            round_trips,
        })
    }

    /// `p*`: the state of the planner and the raw path closest to the tracker, with the number of raw-path
    /// states before it (0: the planner's own state).
    fn closest_path_state(&self, position: Point) -> (usize, Point) {
        std::iter::once(self.planner)
            .chain(self.raw_path.iter().copied())
            .enumerate()
            .min_by(|a, b| norm(sub(a.1, position)).total_cmp(&norm(sub(b.1, position))))
            .unwrap_or((0, self.planner))
    }

    /// A free planner state with `s - Q p` in the certified set and the trained domain, if there is one among
    /// the candidates: the tracker's own position first, then points drawn uniformly in the disc of radius
    /// `dTEBmax` around it, the free ones asked about in one `TrackingControl` batch. Also returns the calls
    /// made.
    async fn reset_point(
        &mut self,
        tracker: &[f64],
        position: Point,
        speed: fastrack_proto::planner_speed::PlannerSpeed,
    ) -> Result<(Option<Point>, usize), LoopError> {
        let mut free = Vec::with_capacity(self.settings.reset_candidates);
        for k in 0..self.settings.reset_candidates {
            let candidate = if k == 0 {
                position
            } else {
                let (radius, angle) = (
                    speed.dteb_radius * self.rng.random::<f64>().sqrt(),
                    std::f64::consts::TAU * self.rng.random::<f64>(),
                );
                [position[0] + radius * angle.cos(), position[1] + radius * angle.sin()]
            };
            if clearance(&self.obstacles, candidate) > speed.steb_radius {
                free.push(candidate);
            }
        }
        if free.is_empty() {
            return Ok((None, 0));
        }
        let states = free.iter().flat_map(|&p| self.relative_state(tracker, p)).collect();
        let params = vec![speed.beta; free.len() * self.n_params];
        let reply = self.client.tracking_control(self.settings.model.clone(), states, params, FLAG).await?;
        // Inside the bound and the trained domain: a membership read off an extrapolated value is no reset.
        let members = reply.in_teb.iter().zip(&reply.in_domain).map(|(&teb, &domain)| teb && domain);
        let inside = free.into_iter().zip(members).find_map(|(p, inside)| inside.then_some(p));
        Ok((inside, 1))
    }

    /// The hold branch: the planner waits at its state, and `u*` is read under `beta_old` (the row answering
    /// for it in the current table), whose bound stays in force.
    async fn hold(
        &mut self,
        tracker: &[f64],
        d_obs: Option<f64>,
        beta_old: f64,
        speed: fastrack_proto::planner_speed::PlannerSpeed,
        replanned: bool,
        round_trips: usize,
    ) -> Result<StepReport, LoopError> {
        // Only a table fetched again after a reload can end below `beta_old`.
        let fetched_beta_u = self.speeds.last().map_or(f64::NAN, |row| row.beta);
        let row = row_for(&self.speeds, beta_old)
            .map(|i| self.speeds[i])
            .ok_or(LoopError::TableMismatch { local: beta_old, server: fetched_beta_u })?;
        let relative_state = self.relative_state(tracker, self.planner);
        let params = vec![row.beta; self.n_params];
        let reply =
            self.client.tracking_control(self.settings.model.clone(), relative_state.clone(), params, FLAG).await?;
        let (Some(&value), Some(&in_teb), Some(&in_domain)) =
            (reply.values.first(), reply.in_teb.first(), reply.in_domain.first())
        else {
            return Err(LoopError::Setup("TrackingControl answered no item for the held state".into()));
        };
        self.beta_query = row.beta;
        Ok(StepReport {
            d_obs,
            beta_old,
            beta_query: row.beta,
            dteb_radius: row.bound,
            steb_radius: speed.steb_radius,
            replanned,
            branch: Branch::Hold,
            planner: self.planner,
            control: reply.controls,
            relative_state,
            value,
            in_teb,
            in_domain,
            round_trips: round_trips + 1,
        })
    }

    /// `r = s - Q p`.
    fn relative_state(&self, tracker: &[f64], p: Point) -> Vec<f64> {
        let q = &self.planner_to_state;
        (0..self.n_state).map(|i| tracker[i] - q[2 * i] * p[0] - q[2 * i + 1] * p[1]).collect()
    }

    /// One tick with planner state `p`; checks the server's `beta_query` against `beta`.
    async fn tick(
        &mut self,
        tracker: &[f64],
        p: Point,
        d_obs: Option<f64>,
        beta: f64,
    ) -> Result<pb::TrackReply, LoopError> {
        let seq = self.seq;
        self.seq += 1;
        let tick = pb::TrackTick { seq, tracker_state: tracker.to_vec(), planner_state: p.to_vec(), d_obs };
        let reply = self.stream.tick(tick).await?;
        if let Some(error) = reply.error {
            return Err(LoopError::Tick { seq, code: error.code, message: error.message });
        }
        if reply.beta_query != beta {
            return Err(LoopError::TableMismatch { local: beta, server: reply.beta_query });
        }
        Ok(reply)
    }
}
