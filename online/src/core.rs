//! The decisions of the paper's Alg. 3, free of I/O: the planner state, the raw path, the obstacles sensed so
//! far, the `beta` in force (`beta_old` of the next step) and the branch of adjustPlannerControl, with every
//! question about the model asked of whoever drives the core.
//!
//! A step is a small exchange. [`LoopCore::begin`] takes the tracker state and the obstacles sensed now,
//! measures `d_obs`, applies queryPlannerControl, replans when needed, and returns a [`Step`] whose
//! [`Step::query`] says what it needs to know: a [`Query::Tick`] (the value, membership and control at the
//! relative state of one planner state, the one question per step on the common branch) or a
//! [`Query::Batch`] (the same for several relative states under a given `beta`: the reset candidates, the held
//! state under `beta_old`, or any state of a drop tried below the rule's row). Its [`Step::answer`] returns
//! either the next question or the step's [`StepReport`]; the core changes only when the report is returned.
//! A driver answers over the network (`online_loop::OnlineLoop`, over a `Track` stream) or in process.

use crate::geometry::{clearance, inside, lerp, norm, remember, sub, Obstacle, Point};
use crate::raw_path::{advance_along, PlanError, PlanRequest, RawPathPlanner};
use fastrack_proto::planner_speed::{planner_rule, query_planner_control, row_for, PlannerSpeed, SpeedRow, SpeedRule};
use serde::{Deserialize, Serialize};
use std::collections::VecDeque;

/// Which branch of adjustPlannerControl a step took.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Branch {
    /// `beta_query >= beta_old`: the planner moved along the raw path (at `beta_query`, whose certified set
    /// holds the new relative state whenever `beta_query > beta_old`).
    Advance,
    /// `beta_query > beta_old` but the rise was refused: the new relative state lies outside the faster row's
    /// certified set, the move would bring the planner within the faster bound of a sensed obstacle, or (under
    /// the planner rule) the raw path within that bound ahead does not keep it clear. The planner moved along
    /// the raw path at `beta_old`, whose row stays in force; the rise is tried again at the next step.
    Steady,
    /// `beta_query < beta_old` and `s - Q p*` in the certified set of `beta_query`, with `p*` farther than
    /// `dTEBmax` from every sensed obstacle: the planner jumped to `p*`.
    Keep,
    /// `beta_query < beta_old` and `p*` not kept: the planner was reset into that set, to a free state farther
    /// than `dTEBmax` from every sensed obstacle, a replan flagged.
    Reset,
    /// The planner waits where it is (a planner at rest obeys every speed bound), `beta_old` and its bound stay
    /// in force, and the step's `beta` is tried again at the next step: on a drop, when no free planner state
    /// within `dTEBmax` of the tracker puts `s - Q p` in the smaller set (a drop that has held for
    /// [`DROP_PATIENCE`] is tried one row slower at each further step); on a rise or an advance, when one
    /// period along the raw path would bring the planner within the bound of a sensed obstacle.
    Hold,
}

impl Branch {
    /// Its name in records: `advance`, `steady`, `keep`, `reset` or `hold`.
    pub fn name(self) -> &'static str {
        match self {
            Branch::Advance => "advance",
            Branch::Steady => "steady",
            Branch::Keep => "keep",
            Branch::Reset => "reset",
            Branch::Hold => "hold",
        }
    }
}

/// The model's geometry and table as the core needs them.
#[derive(Debug, Clone, PartialEq)]
pub struct ModelView {
    /// The TEB table as the planner-speed rule reads it, slowest row first.
    pub speeds: Vec<SpeedRow>,
    /// `Q`, row-major `n_state x D`: the planner's position in the state space.
    pub planner_to_state: Vec<f64>,
    /// State coordinates.
    pub n_state: usize,
    /// The horizon over which verification certified the rows (s): from a relative state in a row's
    /// certified set, the error stays within its bound for this long while the planner obeys its `beta`
    /// (`None`: an unverified table, no certificate to keep).
    pub certificate_horizon: Option<f64>,
}

/// Share of the certificate horizon after which a loop whose relative state stayed outside the certified
/// set of the row in force moves the planner back into it.
pub const REANCHOR_SHARE: f64 = 0.5;

/// How long a drop may hold (s) before it is tried one row slower at each further step: a hold waits for the
/// tracker to move into the smaller set, and a tracker that settles outside it (at rest beside a planner that
/// cannot reach it) would wait for ever. Any row below the rule's keeps its smaller bound clear, so a slower
/// drop is as safe.
pub const DROP_PATIENCE: f64 = 2.0;

/// Reset candidates a reset asks about before the planner holds, unless the settings say otherwise.
pub const DEFAULT_RESET_CANDIDATES: usize = 256;

/// How the core runs.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CoreSettings<const D: usize> {
    /// Control period `dt` (s): the planner moves at most `beta_query dt` per axis per step.
    pub control_period: f64,
    /// Where the planner goes.
    pub goal: Point<D>,
    /// The workspace, `(min, max)`, for the raw-path planner.
    pub bounds: (Point<D>, Point<D>),
    /// Reset candidates asked about per reset before the planner holds.
    pub reset_candidates: usize,
    /// The rule that picks `beta_query`: the paper's on the tracker's distance to the nearest sensed obstacle,
    /// or the planner rule on the planner's own clearance.
    pub rule: SpeedRule,
}

impl<const D: usize> CoreSettings<D> {
    /// Why these settings cannot drive a loop, if they cannot.
    pub fn check(&self) -> Result<(), CoreError> {
        if !(self.control_period.is_finite() && self.control_period > 0.0) {
            return Err(CoreError::Setup(format!(
                "control_period = {}; must be a finite number of seconds > 0",
                self.control_period
            )));
        }
        if self.reset_candidates == 0 {
            return Err(CoreError::Setup("reset_candidates must be at least 1".into()));
        }
        Ok(())
    }
}

/// What the core asks of the model.
#[derive(Debug, Clone, PartialEq)]
pub enum Query<const D: usize> {
    /// Value, membership and control at `r = s - Q p` for the tracker state and one planner state, under
    /// `beta`; `d_obs` is the step's distance to the nearest sensed obstacle (a `Track` tick carries it).
    Tick {
        /// The tracker state `s`.
        tracker: Vec<f64>,
        /// The planner state `p`.
        planner: Point<D>,
        /// `d_obs` (`None`: nothing sensed).
        d_obs: Option<f64>,
        /// The planner rule's clearance (`None`: the paper's rule on `d_obs`).
        planner_clearance: Option<f64>,
        /// The planner speed bound to answer under.
        beta: f64,
    },
    /// The same for several relative states (row-major, `n_state` each) under one `beta`.
    Batch {
        /// The relative states.
        states: Vec<f64>,
        /// The planner speed bound.
        beta: f64,
    },
}

/// The model's answer for one relative state.
#[derive(Debug, Clone, PartialEq)]
pub struct Answer {
    /// The relative state as the model read it (periodic coordinates wrapped).
    pub relative_state: Vec<f64>,
    /// `V(r; beta)`.
    pub value: f64,
    /// `r` lies in the certified set of `beta` (`V <= set level`).
    pub in_set: bool,
    /// `r` lies in the trained domain.
    pub in_domain: bool,
    /// The optimal tracking control `u*`.
    pub control: Vec<f64>,
}

/// What one step decided.
#[derive(Debug, Clone, PartialEq)]
pub struct StepReport<const D: usize> {
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
    pub planner: Point<D>,
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
    /// Questions asked of the model in this step (1 on the common branch).
    pub round_trips: usize,
    /// Seconds since the relative state last lay in the certified set of the row in force, with that row in
    /// force since (0 when it lies there now): the certificate from that state covers this step while it is
    /// below the certificate horizon.
    pub certificate_age: f64,
}

/// Why the core cannot take or finish a step.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum CoreError {
    /// The raw path could not be planned.
    #[error(transparent)]
    Plan(#[from] PlanError),
    /// The settings or the model cannot drive the loop.
    #[error("{0}")]
    Setup(String),
    /// The tracker state does not fit the model.
    #[error("tracker state: {0}")]
    Tracker(String),
    /// An answer does not fit its question.
    #[error("the model's answer does not fit the question: {0}")]
    Answer(String),
    /// `beta_old` has no row in the table (the table changed under the loop).
    #[error("beta_old = {beta_old} has no row in the table (its fastest is {beta_u})")]
    NoRow {
        /// The `beta` in force.
        beta_old: f64,
        /// The table's fastest `beta`.
        beta_u: f64,
    },
}

/// `count` reset candidates in the disc (plane) or ball (space) of radius `radius` around `position`: the
/// position itself first, then points that cover the disc or ball evenly at every count. In the plane a
/// sunflower spiral: point `k` at distance `radius sqrt((k - 1/2) / (count - 1))` and angle `k` times the
/// golden angle `pi (3 - sqrt 5)`. In space the additive sequence of the generalized golden ratio (`u_k =
/// frac(1/2 + k / phi^i)`, i = 1, 2, 3, `phi^4 = phi + 1`) mapped to the ball by volume: distance `radius u_1^(1/3)`,
/// height `1 - 2 u_2` and azimuth `2 pi u_3` on the unit sphere. Deterministic, so that every implementation
/// of the loop asks about the same points (the Python client's included).
pub fn reset_candidates<const D: usize>(position: Point<D>, radius: f64, count: usize) -> Vec<Point<D>> {
    const { assert!(D == 2 || D == 3, "reset candidates are defined in the plane and in space") };
    let golden_angle = std::f64::consts::PI * (3.0 - 5f64.sqrt());
    let rest = count.saturating_sub(1) as f64;
    let phi: f64 = 1.220_744_084_605_759_5;
    (0..count)
        .map(|k| {
            let mut p = position;
            if k == 0 {
                return p;
            }
            if D == 2 {
                let (distance, angle) = (radius * ((k as f64 - 0.5) / rest).sqrt(), k as f64 * golden_angle);
                p[0] += distance * angle.cos();
                p[1] += distance * angle.sin();
            } else {
                let u = [1, 2, 3].map(|i| (0.5 + k as f64 / phi.powi(i)).fract());
                let (distance, height, azimuth) =
                    (radius * u[0].cbrt(), 1.0 - 2.0 * u[1], std::f64::consts::TAU * u[2]);
                let across = (1.0 - height * height).sqrt();
                p[0] += distance * across * azimuth.cos();
                p[1] += distance * across * azimuth.sin();
                p[2] += distance * height;
            }
            p
        })
        .collect()
}

/// The I/O-free state of one robot's loop.
pub struct LoopCore<O, const D: usize> {
    view: ModelView,
    settings: CoreSettings<D>,
    beta_query: f64,
    certificate_age: f64,
    /// How long the drop under way has held (s): 0 unless the last steps were drops that held.
    drop_held: f64,
    replan_flag: bool,
    planner: Point<D>,
    raw_path: VecDeque<Point<D>>,
    obstacles: Vec<O>,
}

/// Where a step stands between questions.
#[derive(Debug, Clone)]
enum Stage<const D: usize> {
    /// Waiting for the tick at `p_next`, the path consumed up to it; `rising` when `beta_query > beta_old`.
    Advance { p_next: Point<D>, ahead: VecDeque<Point<D>>, rising: bool },
    /// Waiting for the batch of candidates that move the planner back into the set of `row`, in force.
    Reanchor { free: Vec<Point<D>>, row: SpeedRow },
    /// Waiting for the answer at `p_next` moved at `beta_old`, under `row` (a refused rise).
    Steady { p_next: Point<D>, ahead: VecDeque<Point<D>>, row: SpeedRow },
    /// Waiting for the tick at `p*`, the raw-path state `index` states along.
    Keep { index: usize, p_star: Point<D> },
    /// Waiting for the batch of reset candidates.
    Candidates { free: Vec<Point<D>> },
    /// Waiting for the tick at the chosen reset point.
    Reset { candidate: Point<D> },
    /// Waiting for the held state's answer under the row answering for `beta_old`.
    Hold { row: SpeedRow },
}

/// One step in progress: ask [`Step::query`], give the model's answers to [`Step::answer`].
#[derive(Debug, Clone)]
pub struct Step<const D: usize> {
    tracker: Vec<f64>,
    position: Point<D>,
    d_obs: Option<f64>,
    planner_clearance: Option<f64>,
    beta_old: f64,
    speed: PlannerSpeed,
    /// The drop is tried below the rule's row (after [`DROP_PATIENCE`]): the server's `Track` tick would
    /// choose the rule's row, so every question is a batch under the step's own `beta`.
    slower_than_rule: bool,
    replanned: bool,
    round_trips: usize,
    stage: Stage<D>,
    query: Query<D>,
}

/// What a step needs next.
#[derive(Debug)]
pub enum Progress<const D: usize> {
    /// Another question.
    Ask(Step<D>),
    /// The step is decided; the core has taken it.
    Done(StepReport<D>),
}

impl<O: Obstacle<D>, const D: usize> LoopCore<O, D> {
    /// A loop with the planner at `start` (its initial state `p_0`) and `beta_u` in force.
    pub fn new(view: ModelView, settings: CoreSettings<D>, start: Point<D>) -> Result<Self, CoreError> {
        settings.check()?;
        if view.planner_to_state.len() != D * view.n_state {
            return Err(CoreError::Setup(format!(
                "the model's planner moves {} axes of its {}-D state (Q has {} entries); this loop's planner moves {D}",
                view.planner_to_state.len() as f64 / view.n_state.max(1) as f64,
                view.n_state,
                view.planner_to_state.len()
            )));
        }
        let beta_u =
            view.speeds.last().map(|row| row.beta).ok_or_else(|| CoreError::Setup("empty TEB table".into()))?;
        Ok(Self {
            beta_query: beta_u,
            // The robot starts at rest on the planner.
            certificate_age: 0.0,
            drop_held: 0.0,
            replan_flag: true,
            planner: start,
            raw_path: VecDeque::new(),
            obstacles: Vec::new(),
            view,
            settings,
        })
    }

    /// The planner's current state `p`.
    pub fn planner(&self) -> Point<D> {
        self.planner
    }

    /// What is left of the raw path after the planner's state.
    pub fn raw_path(&self) -> impl Iterator<Item = &Point<D>> {
        self.raw_path.iter()
    }

    /// The obstacles sensed so far.
    pub fn obstacles(&self) -> &[O] {
        &self.obstacles
    }

    /// The `beta` in force: the last step's `beta_query` (`beta_u` before the first step).
    pub fn beta_in_force(&self) -> f64 {
        self.beta_query
    }

    /// The model's table as the core reads it.
    pub fn view(&self) -> &ModelView {
        &self.view
    }

    /// Takes a new table (the model was reloaded) and plans again at the next step, whose sTEB may differ.
    pub fn replace_table(&mut self, speeds: Vec<SpeedRow>) -> Result<(), CoreError> {
        if speeds.is_empty() {
            return Err(CoreError::Setup("empty TEB table".into()));
        }
        self.view.speeds = speeds;
        self.replan_flag = true;
        Ok(())
    }

    /// The tracker's position in the planner's position space, `Q^T s`.
    pub fn tracker_position(&self, tracker: &[f64]) -> Point<D> {
        let q = &self.view.planner_to_state;
        std::array::from_fn(|j| (0..self.view.n_state).map(|i| q[D * i + j] * tracker[i]).sum())
    }

    /// `r = s - Q p`.
    pub fn relative_state(&self, tracker: &[f64], p: Point<D>) -> Vec<f64> {
        let q = &self.view.planner_to_state;
        (0..self.view.n_state).map(|i| (0..D).fold(tracker[i], |r, j| r - q[D * i + j] * p[j])).collect()
    }

    /// Begins the step for tracker state `tracker` and the obstacles sensed now: remembers them, applies
    /// queryPlannerControl, replans when an obstacle is new or the replan flag is set, and asks the first
    /// question.
    pub fn begin(
        &mut self,
        tracker: &[f64],
        sensed: &[O],
        planner: &mut dyn RawPathPlanner<O, D>,
    ) -> Result<Step<D>, CoreError> {
        if tracker.len() != self.view.n_state {
            return Err(CoreError::Tracker(format!(
                "{} values; the model's state has {}",
                tracker.len(),
                self.view.n_state
            )));
        }
        if let Some(i) = tracker.iter().position(|x| !x.is_finite()) {
            return Err(CoreError::Tracker(format!("tracker[{i}] = {}; must be finite", tracker[i])));
        }
        let newly_sensed = remember(&mut self.obstacles, sensed);
        let position = self.tracker_position(tracker);
        let d_obs = (!self.obstacles.is_empty()).then(|| clearance(&self.obstacles, position));
        let beta_old = self.beta_query;
        let planner_clearance = match self.settings.rule {
            // Less the farthest a period's move takes the planner (`beta_u dt` on every axis), so that the move
            // keeps the bound clear.
            SpeedRule::Planner => {
                (!self.obstacles.is_empty()).then(|| (clearance(&self.obstacles, self.planner) - self.reach()).max(0.0))
            }
            SpeedRule::HalfDistance => None,
        };
        let speed = match planner_clearance {
            Some(c) => planner_rule(&self.view.speeds, c),
            None => query_planner_control(&self.view.speeds, d_obs),
        };
        let rule_row = speed.row;
        let speed = if speed.beta < beta_old { self.slower_after_patience(speed) } else { speed };
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
                speeds: &self.view.speeds,
                rule: self.settings.rule,
            })?;
            self.raw_path = path.into_iter().skip(1).collect();
            self.replan_flag = false;
        }
        let mut step = Step {
            tracker: tracker.to_vec(),
            position,
            d_obs,
            planner_clearance,
            beta_old,
            speed,
            slower_than_rule: speed.row < rule_row,
            replanned,
            round_trips: 1,
            stage: Stage::Candidates { free: Vec::new() },
            query: Query::Batch { states: Vec::new(), beta: speed.beta },
        };
        let stale = self.view.certificate_horizon.is_some_and(|t| self.certificate_age >= REANCHOR_SHARE * t);
        if speed.beta >= beta_old && stale {
            // The relative state has stayed outside the certified set of the row in force for half the
            // horizon: move the planner back into that row's set (a reset under the same row, answered by the
            // batch that found it), or hold if no free point is in it. A rise waits for the next step.
            let row = self.row_in_force(beta_old)?;
            let free = self.free_candidates(position, row.bound, speed.steb_radius);
            if free.is_empty() {
                step.round_trips = 0;
                return self.hold(step);
            }
            step.query = Query::Batch {
                states: free.iter().flat_map(|&p| self.relative_state(tracker, p)).collect(),
                beta: row.beta,
            };
            step.stage = Stage::Reanchor { free, row };
            return Ok(step);
        }
        let p = if speed.beta < beta_old {
            let (index, p_star) = self.closest_path_state(position);
            if !self.clears(p_star, speed.dteb_radius) {
                // A planner at p* would not keep the smaller bound clear of the sensed obstacles: reset.
                step.round_trips = 0;
                return self.ask_candidates(step);
            }
            step.stage = Stage::Keep { index, p_star };
            p_star
        } else {
            // The path is consumed only once the step is done: a step begun again (the table changed)
            // starts from the same planner state and path.
            let mut ahead = self.raw_path.clone();
            let p_next = advance_along(self.planner, &mut ahead, speed.beta * self.settings.control_period);
            if !self.clears(p_next, speed.dteb_radius) {
                // One period along the path would bring the planner within the bound of a sensed obstacle: on
                // a rise it moves at beta_old instead, otherwise it waits where it is.
                step.round_trips = 0;
                return if speed.beta > beta_old { self.steady(step) } else { self.hold(step) };
            }
            if speed.beta > beta_old && !self.path_allows(speed) {
                // The path ahead would take the faster row away again within its bound: a rise refused, the
                // planner moves at beta_old.
                step.round_trips = 0;
                return self.steady(step);
            }
            step.stage = Stage::Advance { p_next, ahead, rising: speed.beta > beta_old };
            p_next
        };
        step.query = if step.slower_than_rule {
            Query::Batch { states: self.relative_state(tracker, p), beta: speed.beta }
        } else {
            Query::Tick { tracker: tracker.to_vec(), planner: p, d_obs, planner_clearance, beta: speed.beta }
        };
        Ok(step)
    }

    /// Asks about the free reset candidates around the tracker under the step's `beta_query`, or holds if
    /// none is free.
    fn ask_candidates(&mut self, mut step: Step<D>) -> Result<Step<D>, CoreError> {
        let free = self.free_candidates(step.position, step.speed.dteb_radius, step.speed.steb_radius);
        if free.is_empty() {
            return self.hold(step);
        }
        let states = free.iter().flat_map(|&p| self.relative_state(&step.tracker, p)).collect();
        step.query = Query::Batch { states, beta: step.speed.beta };
        step.stage = Stage::Candidates { free };
        step.round_trips += 1;
        Ok(step)
    }

    /// `p*`: the state of the planner and the raw path closest to the tracker, with the number of raw-path
    /// states before it (0: the planner's own state).
    fn closest_path_state(&self, position: Point<D>) -> (usize, Point<D>) {
        std::iter::once(self.planner)
            .chain(self.raw_path.iter().copied())
            .enumerate()
            .min_by(|a, b| norm(sub(a.1, position)).total_cmp(&norm(sub(b.1, position))))
            .unwrap_or((0, self.planner))
    }

    /// Free reset candidates for a row of bound `bound`: [`reset_candidates`] in the disc or ball of that
    /// radius around the tracker's position, those inside the workspace (a planner reset outside it, where a tracker
    /// may overshoot its edge, could plan no path back) and farther than the sTEB and the row's bound from
    /// every sensed obstacle.
    fn free_candidates(&self, position: Point<D>, bound: f64, steb_radius: f64) -> Vec<Point<D>> {
        reset_candidates(position, bound, self.settings.reset_candidates)
            .into_iter()
            .filter(|&candidate| {
                inside(candidate, self.settings.bounds) && self.clears(candidate, bound.max(steb_radius))
            })
            .collect()
    }

    /// True when `p` lies farther than `bound` from every sensed obstacle: a tracker within `bound` of a
    /// planner at `p` touches none of them.
    fn clears(&self, p: Point<D>, bound: f64) -> bool {
        clearance(&self.obstacles, p) > bound
    }

    /// Whether a rise to `speed` may be taken as far as the path ahead goes: under the planner rule, the raw
    /// path within that row's bound ahead of the planner must keep the bound clear by one period's reach, as
    /// the rule asks of the planner's own state (so a rise is not undone a bound's length later); under the
    /// paper's rule, always.
    fn path_allows(&self, speed: PlannerSpeed) -> bool {
        self.settings.rule != SpeedRule::Planner
            || self.path_clearance(speed.dteb_radius) - self.reach() > speed.dteb_radius
    }

    /// The farthest one control period can move the planner: `beta_u dt` on every axis.
    fn reach(&self) -> f64 {
        (D as f64).sqrt() * self.beta_u() * self.settings.control_period
    }

    /// The least clearance of the planner's state and its raw path within `ahead` metres along it.
    fn path_clearance(&self, ahead: f64) -> f64 {
        let mut least = clearance(&self.obstacles, self.planner);
        let (mut from, mut left) = (self.planner, ahead);
        for &to in &self.raw_path {
            if left <= 0.0 {
                break;
            }
            let length = norm(sub(to, from));
            let end = if length > left { lerp(from, to, left / length) } else { to };
            least = self.obstacles.iter().map(|o| o.segment_distance(from, end)).fold(least, f64::min);
            (from, left) = (to, left - length);
        }
        least
    }

    /// The drop's row: the rule's own, or, once the drop has held for [`DROP_PATIENCE`], one row slower for
    /// each further step it has held (down to `beta_l`).
    fn slower_after_patience(&self, speed: PlannerSpeed) -> PlannerSpeed {
        let past = self.drop_held - DROP_PATIENCE;
        if past < -1e-9 {
            return speed;
        }
        let rows_down = 1 + (past / self.settings.control_period + 1e-9).floor() as usize;
        let row = speed.row.saturating_sub(rows_down);
        let chosen = self.view.speeds[row];
        PlannerSpeed { beta: chosen.beta, row, dteb_radius: chosen.bound, ..speed }
    }

    /// The table's fastest `beta`.
    fn beta_u(&self) -> f64 {
        self.view.speeds.last().map_or(0.0, |row| row.beta)
    }

    /// The row answering for `beta_old` in the current table (only a table replaced under the loop can end
    /// below it).
    fn row_in_force(&self, beta_old: f64) -> Result<SpeedRow, CoreError> {
        let beta_u = self.beta_u();
        row_for(&self.view.speeds, beta_old).map(|i| self.view.speeds[i]).ok_or(CoreError::NoRow { beta_old, beta_u })
    }

    /// A refused rise: the planner moves along the raw path at `beta_old`, under its row, whose certificate
    /// still runs, or waits where it is if that would bring it within the row's bound of a sensed obstacle.
    fn steady(&self, mut step: Step<D>) -> Result<Step<D>, CoreError> {
        let row = self.row_in_force(step.beta_old)?;
        let mut ahead = self.raw_path.clone();
        let p_next = advance_along(self.planner, &mut ahead, row.beta * self.settings.control_period);
        if !self.clears(p_next, row.bound) {
            return self.hold(step);
        }
        step.query = Query::Batch { states: self.relative_state(&step.tracker, p_next), beta: row.beta };
        step.stage = Stage::Steady { p_next, ahead, row };
        step.round_trips += 1;
        Ok(step)
    }

    /// The hold's question: the held planner state's relative state under the row answering for `beta_old`.
    fn hold(&self, mut step: Step<D>) -> Result<Step<D>, CoreError> {
        let row = self.row_in_force(step.beta_old)?;
        step.query = Query::Batch { states: self.relative_state(&step.tracker, self.planner), beta: row.beta };
        step.stage = Stage::Hold { row };
        step.round_trips += 1;
        Ok(step)
    }

    /// Finishes a step on `branch` with the planner at `p_next`, `answer` the model's at it, under `held`'s
    /// row on a hold and the step's `beta_query` otherwise.
    fn done(
        &mut self,
        step: Step<D>,
        branch: Branch,
        p_next: Point<D>,
        answer: Answer,
        held: Option<SpeedRow>,
    ) -> Progress<D> {
        let (beta_query, dteb_radius) = match held {
            Some(row) => (row.beta, row.bound),
            None => (step.speed.beta, step.speed.dteb_radius),
        };
        self.beta_query = beta_query;
        self.planner = p_next;
        // Every branch that changes the row in force puts the relative state in the new row's set, so the age
        // counts from there; on the others the row stays.
        self.certificate_age = if answer.in_set { 0.0 } else { self.certificate_age + self.settings.control_period };
        let drop_holds = branch == Branch::Hold && step.speed.beta < step.beta_old;
        self.drop_held = if drop_holds { self.drop_held + self.settings.control_period } else { 0.0 };
        Progress::Done(StepReport {
            d_obs: step.d_obs,
            beta_old: step.beta_old,
            beta_query,
            dteb_radius,
            steb_radius: step.speed.steb_radius,
            replanned: step.replanned,
            branch,
            planner: p_next,
            control: answer.control,
            relative_state: answer.relative_state,
            value: answer.value,
            in_teb: answer.in_set,
            in_domain: answer.in_domain,
            round_trips: step.round_trips,
            certificate_age: self.certificate_age,
        })
    }
}

impl<const D: usize> Step<D> {
    /// What the step needs to know next.
    pub fn query(&self) -> &Query<D> {
        &self.query
    }

    /// Gives the model's answers to [`Step::query`] (one per state asked about, in order) and returns the
    /// next question or the decided step.
    pub fn answer<O: Obstacle<D>>(
        mut self,
        core: &mut LoopCore<O, D>,
        answers: Vec<Answer>,
    ) -> Result<Progress<D>, CoreError> {
        let asked = match &self.query {
            Query::Tick { .. } => 1,
            Query::Batch { states, .. } => states.len() / core.view.n_state,
        };
        if answers.len() != asked {
            return Err(CoreError::Answer(format!("{} answers for {asked} states", answers.len())));
        }
        let mut answers = answers.into_iter();
        let mut single = || answers.next().ok_or_else(|| CoreError::Answer("no answer".into()));
        match std::mem::replace(&mut self.stage, Stage::Candidates { free: Vec::new() }) {
            Stage::Advance { p_next, ahead, rising } => {
                let answer = single()?;
                if rising && !answer.in_set {
                    // The faster row's certificate does not cover the new state.
                    return core.steady(self).map(Progress::Ask);
                }
                core.raw_path = ahead;
                Ok(core.done(self, Branch::Advance, p_next, answer, None))
            }
            Stage::Steady { p_next, ahead, row } => {
                let answer = single()?;
                core.raw_path = ahead;
                Ok(core.done(self, Branch::Steady, p_next, answer, Some(row)))
            }
            Stage::Keep { index, p_star } => {
                let answer = single()?;
                if answer.in_set {
                    core.raw_path.drain(..index);
                    return Ok(core.done(self, Branch::Keep, p_star, answer, None));
                }
                core.ask_candidates(self).map(Progress::Ask)
            }
            Stage::Candidates { free } => {
                // Inside the set and the trained domain: a membership read off an extrapolated value is no
                // reset.
                let chosen = free.into_iter().zip(answers).find(|(_, a)| a.in_set && a.in_domain);
                let Some((candidate, answer)) = chosen else {
                    return core.hold(self).map(Progress::Ask);
                };
                if self.slower_than_rule {
                    // Below the rule's row the batch that found the candidate answers for it.
                    core.raw_path.clear();
                    core.replan_flag = true;
                    return Ok(core.done(self, Branch::Reset, candidate, answer, None));
                }
                self.query = Query::Tick {
                    tracker: self.tracker.clone(),
                    planner: candidate,
                    d_obs: self.d_obs,
                    planner_clearance: self.planner_clearance,
                    beta: self.speed.beta,
                };
                self.stage = Stage::Reset { candidate };
                self.round_trips += 1;
                Ok(Progress::Ask(self))
            }
            Stage::Reanchor { free, row } => {
                let chosen = free.into_iter().zip(answers).find(|(_, a)| a.in_set && a.in_domain);
                let Some((candidate, answer)) = chosen else {
                    return core.hold(self).map(Progress::Ask);
                };
                core.raw_path.clear();
                core.replan_flag = true;
                Ok(core.done(self, Branch::Reset, candidate, answer, Some(row)))
            }
            Stage::Reset { candidate } => {
                let answer = single()?;
                core.raw_path.clear();
                core.replan_flag = true;
                Ok(core.done(self, Branch::Reset, candidate, answer, None))
            }
            Stage::Hold { row } => {
                let answer = single()?;
                let planner = core.planner;
                Ok(core.done(self, Branch::Hold, planner, answer, Some(row)))
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::PlaneObstacle;

    /// A planner that goes straight to the goal.
    struct Straight;

    impl<O: Obstacle<D>, const D: usize> RawPathPlanner<O, D> for Straight {
        fn plan(&mut self, request: &PlanRequest<'_, O, D>) -> Result<Vec<Point<D>>, PlanError> {
            Ok(vec![request.start, request.goal])
        }
    }

    /// A table of `beta` 0.5 / 1.0 / 1.5 with bounds 0.5 / 1.0 / 1.5, the double integrator's `Q` in 2-D
    /// (`s = (x, y, vx, vy)`).
    fn core() -> LoopCore<PlaneObstacle, 2> {
        let speeds = [0.5, 1.0, 1.5].map(|b| SpeedRow { beta: b, bound: b }).to_vec();
        let view = ModelView {
            speeds,
            planner_to_state: vec![1.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0],
            n_state: 4,
            certificate_horizon: Some(1.0),
        };
        let settings = CoreSettings {
            control_period: 0.1,
            goal: [10.0, 0.0],
            bounds: ([-20.0; 2], [20.0; 2]),
            reset_candidates: 8,
            rule: SpeedRule::HalfDistance,
        };
        LoopCore::new(view, settings, [0.0, 0.0]).unwrap()
    }

    #[test]
    fn reset_candidates_start_at_the_position_and_cover_the_disc_evenly() {
        let (centre, radius) = ([1.0, -2.0], 2.0);
        let points = reset_candidates(centre, radius, 64);
        assert_eq!((points.len(), points[0]), (64, centre));
        assert!(points.iter().all(|&p| norm(sub(p, centre)) <= radius + 1e-12));
        // Every point of a fine lattice in the disc lies near a candidate: no part of the disc is left out.
        let mut worst: f64 = 0.0;
        for i in -20..=20 {
            for j in -20..=20 {
                let q = [centre[0] + radius * i as f64 / 20.0, centre[1] + radius * j as f64 / 20.0];
                if norm(sub(q, centre)) <= radius {
                    let nearest = points.iter().map(|&p| norm(sub(p, q))).fold(f64::INFINITY, f64::min);
                    worst = worst.max(nearest);
                }
            }
        }
        assert!(worst < 0.2 * radius, "a lattice point {worst} m from every candidate");
        assert_eq!(reset_candidates(centre, radius, 1), vec![centre]);
        assert!(reset_candidates(centre, radius, 0).is_empty());
    }

    #[test]
    fn reset_candidates_in_space_start_at_the_position_and_fill_the_ball_evenly() {
        let (centre, radius) = ([1.0, -2.0, 3.0], 2.0);
        let points = reset_candidates(centre, radius, 256);
        assert_eq!((points.len(), points[0]), (256, centre));
        assert!(points.iter().all(|&p| norm(sub(p, centre)) <= radius + 1e-12));
        // Every point of a lattice in the ball lies near a candidate, and each octant holds about an eighth.
        let mut worst: f64 = 0.0;
        for i in -8..=8 {
            for j in -8..=8 {
                for k in -8..=8 {
                    let q = [i, j, k].map(|n| n as f64 * radius / 8.0);
                    if norm(q) <= radius {
                        let q = [centre[0] + q[0], centre[1] + q[1], centre[2] + q[2]];
                        let nearest = points.iter().map(|&p| norm(sub(p, q))).fold(f64::INFINITY, f64::min);
                        worst = worst.max(nearest);
                    }
                }
            }
        }
        assert!(worst < 0.4 * radius, "a lattice point {worst} m from every candidate");
        for octant in 0..8 {
            let sign = |axis: usize| if octant >> axis & 1 == 1 { 1.0 } else { -1.0 };
            let count = points[1..].iter().filter(|p| (0..3).all(|a| (p[a] - centre[a]) * sign(a) > 0.0)).count();
            assert!((20..=44).contains(&count), "octant {octant} holds {count} of 255");
        }
    }

    /// An answer for the relative state of `query`'s first state (or `r`), with membership `in_set`.
    fn answer(r: Vec<f64>, in_set: bool) -> Answer {
        Answer { relative_state: r, value: 0.1, in_set, in_domain: true, control: vec![0.0, 0.0] }
    }

    /// Runs a step to its end, answering ticks with `tick_in_set` and each batch item with `batch_in_set`.
    fn run(
        core: &mut LoopCore<PlaneObstacle, 2>,
        tracker: &[f64],
        sensed: &[PlaneObstacle],
        tick_in_set: bool,
        batch_in_set: bool,
    ) -> (StepReport<2>, Vec<Query<2>>) {
        run_with(core, tracker, sensed, |query| match query {
            Query::Tick { .. } => tick_in_set,
            Query::Batch { .. } => batch_in_set,
        })
    }

    /// Runs a step to its end, every state of a question in the set when `in_set` says so of the question.
    fn run_with(
        core: &mut LoopCore<PlaneObstacle, 2>,
        tracker: &[f64],
        sensed: &[PlaneObstacle],
        in_set: impl Fn(&Query<2>) -> bool,
    ) -> (StepReport<2>, Vec<Query<2>>) {
        let mut step = core.begin(tracker, sensed, &mut Straight).unwrap();
        let mut asked = Vec::new();
        loop {
            let query = step.query().clone();
            let inside = in_set(&query);
            let answers = match &query {
                Query::Tick { tracker, planner, .. } => {
                    vec![answer(core.relative_state(tracker, *planner), inside)]
                }
                Query::Batch { states, .. } => states.chunks(4).map(|r| answer(r.to_vec(), inside)).collect(),
            };
            asked.push(query);
            match step.answer(core, answers).unwrap() {
                Progress::Ask(next) => step = next,
                Progress::Done(report) => return (report, asked),
            }
        }
    }

    const OBSTACLE: PlaneObstacle = PlaneObstacle::Circle { center: [2.0, 0.0], radius: 0.5 };

    #[test]
    fn with_nothing_sensed_the_planner_advances_at_beta_u_with_one_question() {
        let mut core = core();
        let (report, asked) = run(&mut core, &[0.0; 4], &[], true, true);
        assert_eq!((report.branch, report.beta_query, report.round_trips), (Branch::Advance, 1.5, 1));
        assert!(report.replanned, "the first step plans");
        assert!((report.planner[0] - 0.15).abs() < 1e-12 && report.planner[1] == 0.0, "{:?}", report.planner);
        assert!(matches!(asked[..], [Query::Tick { beta, d_obs: None, .. }] if beta == 1.5));
        assert_eq!(core.beta_in_force(), 1.5);
    }

    #[test]
    fn a_drop_keeps_the_closest_path_state_when_the_set_holds_it() {
        let mut core = core();
        run(&mut core, &[0.0; 4], &[], true, true);
        // 1.5 m from the obstacle's edge: half of it fits beta 0.5's bound only.
        let (report, asked) = run(&mut core, &[0.1, 0.0, 0.0, 0.0], &[OBSTACLE], true, true);
        assert_eq!(
            (report.branch, report.beta_old, report.beta_query, report.dteb_radius),
            (Branch::Keep, 1.5, 0.5, 0.5)
        );
        assert_eq!(asked.len(), 1);
        assert_eq!(core.beta_in_force(), 0.5);
    }

    #[test]
    fn an_advance_that_would_bring_the_planner_within_the_bound_of_an_obstacle_holds() {
        let mut core = core();
        run(&mut core, &[0.0; 4], &[], true, true);
        // The tracker 3.5 m behind, 4.5 m from the obstacle: the rule keeps beta 1.5, but one period along the
        // path would put the planner 1.2 m from the obstacle's edge, inside the bound of 1.5.
        let (report, asked) = run(&mut core, &[-3.0, 0.0, 0.0, 0.0], &[OBSTACLE], true, true);
        assert_eq!((report.branch, report.beta_query, report.dteb_radius), (Branch::Hold, 1.5, 1.5));
        assert!((report.planner[0] - 0.15).abs() < 1e-12 && report.round_trips == 1, "{report:?}");
        assert!(matches!(asked[..], [Query::Batch { beta, .. }] if beta == 1.5), "{asked:?}");
        assert!(clearance(core.obstacles(), core.planner()) > 0.0);
    }

    #[test]
    fn a_rise_that_would_bring_the_planner_within_the_faster_bound_of_an_obstacle_moves_at_beta_old() {
        let mut core = core();
        run(&mut core, &[0.0; 4], &[], true, true);
        run(&mut core, &[0.1, 0.0, 0.0, 0.0], &[OBSTACLE], true, true);
        assert_eq!(core.beta_in_force(), 0.5);
        // The tracker far behind allows 1.5, but the planner, 1.35 m from the obstacle's edge, would not keep
        // 1.5 clear of it: it moves on at 0.5 without asking about the faster row.
        let (report, asked) = run(&mut core, &[-20.0, 0.0, 0.0, 0.0], &[], true, true);
        assert_eq!((report.branch, report.beta_query, report.round_trips), (Branch::Steady, 0.5, 1));
        assert!(matches!(asked[..], [Query::Batch { beta: 0.5, .. }]), "{asked:?}");
        assert!((report.planner[0] - 0.2).abs() < 1e-12, "{:?}", report.planner);
    }

    #[test]
    fn the_planner_rule_reads_the_planners_clearance_less_one_periods_reach() {
        let mut core = core();
        core.settings.rule = SpeedRule::Planner;
        let (first, asked) = run(&mut core, &[0.0; 4], &[], true, true);
        assert!(matches!(asked[..], [Query::Tick { planner_clearance: None, beta, .. }] if beta == 1.5));
        assert_eq!(first.branch, Branch::Advance);
        // The planner 1.35 m from the obstacle's edge, less sqrt(2) 1.5 m/s 0.1 s: 1.138 m, which bound 1.0 fits
        // and 1.5 does not, though the tracker 4.5 m away would allow 1.5 under the paper's rule.
        let reach = std::f64::consts::SQRT_2 * 1.5 * 0.1;
        let (drop, asked) = run(&mut core, &[-3.0, 0.0, 0.0, 0.0], &[OBSTACLE], true, true);
        let Query::Tick { planner_clearance: Some(c), beta, .. } = asked[0] else { panic!("{asked:?}") };
        assert!((c - (1.35 - reach)).abs() < 1e-9 && beta == 1.0, "{c} {beta}");
        assert_eq!((drop.branch, drop.beta_query), (Branch::Keep, 1.0));
        // Under the row it chose, a period's move keeps the bound clear: the planner advances.
        let (next, _) = run(&mut core, &[-3.0, 0.0, 0.0, 0.0], &[OBSTACLE], true, true);
        assert_eq!((next.branch, next.beta_query), (Branch::Advance, 1.0));
        assert!(clearance(core.obstacles(), next.planner) > 1.0 && next.planner[0] > drop.planner[0]);
    }

    #[test]
    fn under_the_planner_rule_a_rise_the_path_ahead_would_undo_moves_at_beta_old() {
        // beta 0.5 in force, the planner at the origin on a straight path along +x. An obstacle 2.27 m from
        // the planner (less the reach 0.21 m: beta_u's bound 1.5 fits) but 1.06 m from the path's point 1.5 m
        // ahead, within beta_u's bound: the rise is refused, the planner moves at 0.5 under its row.
        let near = PlaneObstacle::Circle { center: [2.5, 1.2], radius: 0.5 };
        let mut slow = core();
        (slow.settings.rule, slow.beta_query) = (SpeedRule::Planner, 0.5);
        let (report, asked) = run(&mut slow, &[0.0; 4], std::slice::from_ref(&near), true, true);
        assert_eq!((report.branch, report.beta_query, report.round_trips), (Branch::Steady, 0.5, 1));
        assert!(matches!(asked[..], [Query::Batch { beta: 0.5, .. }]), "{asked:?}");
        assert!((report.planner[0] - 0.05).abs() < 1e-12, "{:?}", report.planner);
        // One metre farther along, the path within 1.5 m keeps 1.62 m (less the reach) from it: the rise is taken.
        let far = PlaneObstacle::Circle { center: [3.5, 1.2], radius: 0.5 };
        let mut slow = core();
        (slow.settings.rule, slow.beta_query) = (SpeedRule::Planner, 0.5);
        let (report, _) = run(&mut slow, &[0.0; 4], &[far], true, true);
        assert_eq!((report.branch, report.beta_query), (Branch::Advance, 1.5));
        // The paper's rule reads the tracker's distance and takes the rise past the near obstacle.
        let mut slow = core();
        slow.beta_query = 0.5;
        let (report, _) = run(&mut slow, &[0.0; 4], std::slice::from_ref(&near), true, true);
        assert_eq!((report.branch, report.beta_query), (Branch::Advance, 1.0));
    }

    #[test]
    fn a_drop_whose_closest_path_state_lies_within_the_smaller_bound_of_an_obstacle_resets() {
        let mut core = core();
        run(&mut core, &[0.0; 4], &[], true, true);
        // The planner at (0.15, 0), 0.4 m from the obstacle's edge; the tracker 1.04 m from it: beta 0.5, whose
        // bound 0.5 a planner kept at p* would not keep clear.
        let obstacle = PlaneObstacle::Circle { center: [0.15, 0.8], radius: 0.4 };
        let (report, asked) = run(&mut core, &[-1.05, 0.0, 0.0, 0.0], &[obstacle], true, true);
        assert_eq!((report.branch, report.beta_query, report.round_trips), (Branch::Reset, 0.5, 2));
        assert!(matches!(asked[..], [Query::Batch { .. }, Query::Tick { .. }]), "no keep asked: {asked:?}");
        assert!(clearance(core.obstacles(), report.planner) > 0.5, "{:?}", report.planner);
    }

    #[test]
    fn reset_candidates_keep_the_rows_bound_clear_of_sensed_obstacles() {
        let mut core = core();
        run(&mut core, &[0.0; 4], &[OBSTACLE], true, true);
        let (position, bound, steb) = ([0.6, 0.0], 1.0, 0.5);
        let free = core.free_candidates(position, bound, steb);
        assert!(!free.is_empty());
        assert!(free.iter().all(|&p| clearance(core.obstacles(), p) > bound), "{free:?}");
        let between = reset_candidates(position, bound, core.settings.reset_candidates)
            .into_iter()
            .filter(|&p| (steb..=bound).contains(&clearance(core.obstacles(), p)))
            .count();
        assert!(between > 0, "some candidate clears the sTEB but not the bound, and is left out");
    }

    #[test]
    fn a_drop_outside_the_set_resets_into_it_and_plans_again() {
        let mut core = core();
        run(&mut core, &[0.0; 4], &[], true, true);
        let (report, asked) = run(&mut core, &[0.1, 0.0, 0.0, 0.0], &[OBSTACLE], false, true);
        assert_eq!((report.branch, report.beta_query, report.round_trips), (Branch::Reset, 0.5, 3));
        assert!(matches!(asked[1], Query::Batch { beta, .. } if beta == 0.5));
        // The tracker's own position is the first candidate, and it was free.
        assert_eq!(report.planner, [0.1, 0.0]);
        assert_eq!(core.raw_path().count(), 0);
        let (next, _) = run(&mut core, &[0.1, 0.0, 0.0, 0.0], &[OBSTACLE], true, true);
        assert!(next.replanned, "a reset flags a replan");
    }

    #[test]
    fn a_tracker_past_the_workspace_edge_is_reset_inside_it() {
        let mut core = core();
        core.settings.bounds = ([-20.0, -0.3], [20.0, 20.0]);
        core.settings.reset_candidates = 64;
        run(&mut core, &[0.0; 4], &[], true, true);
        // The tracker 0.4 m below the workspace's lower edge: its own position is no reset point, the first
        // candidate inside is.
        let (report, asked) = run(&mut core, &[0.1, -0.7, 0.0, 0.0], &[OBSTACLE], false, true);
        assert_eq!(report.branch, Branch::Reset);
        assert!(report.planner[1] >= -0.3, "reset outside the workspace: {:?}", report.planner);
        let Query::Batch { states, .. } = &asked[1] else { panic!("no batch of candidates: {asked:?}") };
        // Every candidate asked about lies inside: r_y = s_y - p_y, so p_y = -0.7 - r_y.
        assert!(states.chunks(4).all(|r| -0.7 - r[1] >= -0.3 - 1e-12), "{states:?}");
    }

    #[test]
    fn a_drop_with_no_state_in_the_set_holds_under_beta_old() {
        let mut core = core();
        run(&mut core, &[0.0; 4], &[], true, true);
        let planner = core.planner();
        let (report, asked) = run(&mut core, &[0.1, 0.0, 2.0, 0.0], &[OBSTACLE], false, false);
        assert_eq!((report.branch, report.beta_query, report.dteb_radius), (Branch::Hold, 1.5, 1.5));
        assert_eq!(report.planner, planner, "the planner waits");
        assert!(matches!(asked.last(), Some(Query::Batch { beta, .. }) if *beta == 1.5));
        assert_eq!(core.beta_in_force(), 1.5, "beta_old stays in force");
    }

    /// 2.5 m from the tracker at `NEAR_AHEAD`: the rule drops from 1.5 to 1.0.
    const AHEAD: PlaneObstacle = PlaneObstacle::Circle { center: [3.1, 0.0], radius: 0.5 };
    const NEAR_AHEAD: [f64; 4] = [0.1, 0.0, 0.0, 0.0];

    /// Steps at `NEAR_AHEAD` for [`DROP_PATIENCE`] (control period 0.1 s), each a hold under 1.5 that asks
    /// the rule's row (1.0) first.
    fn hold_for_the_patience(core: &mut LoopCore<PlaneObstacle, 2>, in_set: impl Fn(&Query<2>) -> bool + Copy) {
        let planner = core.planner();
        for _ in 0..(DROP_PATIENCE / 0.1).round() as usize {
            let (report, asked) = run_with(core, &NEAR_AHEAD, &[AHEAD], in_set);
            assert_eq!((report.branch, report.beta_query, report.planner), (Branch::Hold, 1.5, planner));
            assert!(matches!(asked[0], Query::Tick { beta: 1.0, .. }), "the rule's row first: {asked:?}");
        }
    }

    #[test]
    fn a_drop_that_held_for_the_patience_is_tried_one_row_slower_at_each_step() {
        let mut core = core();
        run(&mut core, &[0.0; 4], &[], true, true);
        // 1.0's set holds no state; 0.5's holds all.
        let slowest_holds = |query: &Query<2>| match query {
            Query::Tick { beta, .. } | Query::Batch { beta, .. } => *beta <= 0.5,
        };
        hold_for_the_patience(&mut core, slowest_holds);
        let (report, asked) = run_with(&mut core, &NEAR_AHEAD, &[AHEAD], slowest_holds);
        assert_eq!((report.branch, report.beta_old, report.beta_query), (Branch::Keep, 1.5, 0.5));
        // The server's tick would choose the rule's row: below it, the step asks in a batch.
        assert!(matches!(asked[..], [Query::Batch { beta: 0.5, .. }]), "{asked:?}");
        assert_eq!(core.beta_in_force(), 0.5);
        // The patience counts afresh: far from the obstacle the loop rises to 1.5, and the next drop holds
        // under the rule's own row again.
        let (report, _) = run(&mut core, &[-20.0, 0.0, 0.0, 0.0], &[], true, true);
        assert_eq!((report.branch, report.beta_query), (Branch::Advance, 1.5));
        hold_for_the_patience(&mut core, slowest_holds);
    }

    #[test]
    fn a_drop_below_the_rules_row_resets_on_the_batch_that_found_the_candidate() {
        let mut core = core();
        run(&mut core, &[0.0; 4], &[], true, true);
        // p* lies in no set; of the reset candidates, only 0.5's set holds some.
        let candidates_under_slowest = |query: &Query<2>| match query {
            Query::Tick { .. } => false,
            Query::Batch { states, beta } => states.len() > 4 && *beta <= 0.5,
        };
        hold_for_the_patience(&mut core, candidates_under_slowest);
        let (report, asked) = run_with(&mut core, &NEAR_AHEAD, &[AHEAD], candidates_under_slowest);
        assert_eq!((report.branch, report.beta_query, report.in_teb), (Branch::Reset, 0.5, true));
        assert!(matches!(asked[..], [Query::Batch { beta: 0.5, .. }, Query::Batch { beta: 0.5, .. }]), "{asked:?}");
        assert_eq!(report.round_trips, 2, "p*, then the candidates: no tick");
        assert!(core.replan_flag, "a reset plans again");
    }

    #[test]
    fn a_rise_whose_state_the_faster_set_does_not_hold_moves_at_beta_old() {
        let mut core = core();
        run(&mut core, &[0.0; 4], &[], true, true);
        // Beside the path, 1.6 m from the planner: far enough for the planner to move on under beta 1.5.
        let beside = PlaneObstacle::Circle { center: [0.1, -2.1], radius: 0.5 };
        run(&mut core, &[0.1, 0.0, 0.0, 0.0], &[beside], true, true);
        assert_eq!(core.beta_in_force(), 0.5);
        // Far from the obstacle: the rule allows 1.5 again, but the state lies outside that row's set.
        let planner = core.planner();
        let far = [-20.0, 0.0, 0.0, 0.0];
        let (report, asked) = run(&mut core, &far, &[], false, true);
        assert_eq!(
            (report.branch, report.beta_old, report.beta_query, report.dteb_radius),
            (Branch::Steady, 0.5, 0.5, 0.5)
        );
        assert!(matches!(asked[..], [Query::Tick { beta: 1.5, .. }, Query::Batch { beta: 0.5, .. }]), "{asked:?}");
        let moved = norm(sub(report.planner, planner));
        assert!(moved > 0.0 && moved <= 0.5 * 0.1 * 2f64.sqrt() + 1e-12, "moved {moved} at beta_old");
        assert_eq!(core.beta_in_force(), 0.5);
        // Once the faster set holds it, the rise is taken.
        let (report, _) = run(&mut core, &far, &[], true, true);
        assert_eq!((report.branch, report.beta_query), (Branch::Advance, 1.5));
    }

    #[test]
    fn a_state_outside_the_set_for_half_the_horizon_is_moved_back_into_it() {
        let mut core = core();
        // Horizon 1 s, control period 0.1 s: five steps outside the set age the certificate to 0.5 s.
        let ages: Vec<f64> = (0..5).map(|_| run(&mut core, &[0.0; 4], &[], false, true).0.certificate_age).collect();
        assert!(ages.iter().zip(1..).all(|(a, k)| (a - 0.1 * f64::from(k)).abs() < 1e-9), "{ages:?}");
        let (report, asked) = run(&mut core, &[0.0; 4], &[], true, true);
        assert_eq!((report.branch, report.beta_query, report.certificate_age), (Branch::Reset, 1.5, 0.0));
        assert!(matches!(asked[..], [Query::Batch { beta: 1.5, .. }]), "the batch that found it answers: {asked:?}");
        assert_eq!(report.round_trips, 1);
        // With no candidate in the set, the planner holds instead (and the age goes on).
        for _ in 0..5 {
            run(&mut core, &[0.0; 4], &[], false, true);
        }
        let planner = core.planner();
        let (report, _) = run(&mut core, &[0.0; 4], &[], false, false);
        assert_eq!((report.branch, report.planner), (Branch::Hold, planner));
        assert!((report.certificate_age - 0.6).abs() < 1e-9, "{}", report.certificate_age);
    }

    #[test]
    fn refused_rises_outside_the_set_for_half_the_horizon_move_back_into_the_slower_set() {
        let mut core = core();
        run(&mut core, &[0.0; 4], &[], true, true);
        run(&mut core, &[0.1, 0.0, 0.0, 0.0], &[OBSTACLE], true, true);
        let far = [-20.0, 0.0, 0.0, 0.0];
        for _ in 0..5 {
            let (report, _) = run(&mut core, &far, &[], false, false);
            assert_eq!((report.branch, report.beta_query), (Branch::Steady, 0.5));
        }
        // The rise is still refused, and the certificate of 0.5's row is 0.5 s old: back into that row's set.
        let (report, asked) = run(&mut core, &far, &[], false, true);
        assert_eq!((report.branch, report.beta_query, report.certificate_age), (Branch::Reset, 0.5, 0.0));
        assert!(matches!(asked[..], [Query::Batch { beta: 0.5, .. }]), "{asked:?}");
    }

    #[test]
    fn wrong_answers_and_trackers_are_errors_not_panics() {
        let mut core = core();
        let step = core.begin(&[0.0; 4], &[], &mut Straight).unwrap();
        assert!(matches!(step.clone().answer(&mut core, Vec::new()), Err(CoreError::Answer(_))));
        assert!(matches!(step.answer(&mut core, vec![answer(vec![0.0; 4], true); 2]), Err(CoreError::Answer(_))));
        assert!(matches!(core.begin(&[0.0; 3], &[], &mut Straight), Err(CoreError::Tracker(_))));
        assert!(matches!(core.begin(&[f64::NAN; 4], &[], &mut Straight), Err(CoreError::Tracker(_))));
        assert_eq!(core.planner(), [0.0, 0.0], "an unfinished step leaves the planner where it was");
    }
}
