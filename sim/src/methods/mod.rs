//! The navigation methods the simulator compares, on the same worlds, sensor, dynamics and control period:
//! Parametric FaSTrack over the `Track` stream, FaSTrack at a fixed `beta`, Meta-FaSTrack over a few fixed
//! levels, and MPPI on the tracker's dynamics with no bound.

mod levels;
mod mppi;
mod parametric;
mod timed_planner;

pub use levels::LevelPlanner;
pub use mppi::{Mppi, MppiSettings};
pub use parametric::Parametric;
pub use timed_planner::TimedPlanner;

use crate::backend::Backend;
use crate::trace::LoopTrace;
use crate::tracker::Tracker;
use crate::visits::Visit;
use crate::world::{World, WorldObstacle};
use fastrack_online::geometry::Point;
use fastrack_proto::planner_speed::{SpeedRow, SpeedRule};
use std::sync::Arc;
use std::time::Duration;

/// Which method drives the robot.
#[derive(Debug, Clone, PartialEq)]
pub enum Method {
    /// Parametric FaSTrack (the paper's Alg. 3) on the shortest raw path, `PF`.
    Parametric,
    /// Parametric FaSTrack on the fastest raw path at the speeds the rule allows along it, `PF-fast`.
    ParametricFastestPath,
    /// Parametric FaSTrack under the planner rule (`beta` by the planner's own clearance, not half the
    /// tracker's distance) on the fastest raw path for that rule, `PF-planner`.
    ParametricPlannerRule,
    /// FaSTrack at the slowest table `beta` (obstacles inflated by its bound), `F(beta_l)`.
    FastrackSlowest,
    /// FaSTrack at the fastest table `beta`, `F(beta_u)`.
    FastrackFastest,
    /// Meta-FaSTrack over `levels` table rows spread evenly from `beta_l` to `beta_u`: `MF`, or `MF-quick`
    /// when each replan takes the level whose path is quickest rather than the fastest level with a path.
    MetaFastrack {
        /// How many levels (at least 2).
        levels: usize,
        /// Choose the level by its path's travel time.
        quickest: bool,
    },
    /// MPPI on the tracker's dynamics with the sensed obstacles in its cost and no bound.
    Mppi(MppiSettings),
}

impl Method {
    /// Every method, with its default settings.
    pub fn all() -> Vec<Method> {
        vec![
            Method::FastrackSlowest,
            Method::FastrackFastest,
            Method::MetaFastrack { levels: 3, quickest: false },
            Method::MetaFastrack { levels: 3, quickest: true },
            Method::Parametric,
            Method::ParametricFastestPath,
            Method::ParametricPlannerRule,
            Method::Mppi(MppiSettings::default()),
        ]
    }

    /// Parametric FaSTrack, on either raw path and under either rule: the methods that must never be unsafe.
    pub fn is_parametric(&self) -> bool {
        matches!(self, Method::Parametric | Method::ParametricFastestPath | Method::ParametricPlannerRule)
    }

    /// Short name, as in the paper's Table 1.
    pub fn label(&self) -> &'static str {
        match self {
            Method::Parametric => "PF",
            Method::ParametricFastestPath => "PF-fast",
            Method::ParametricPlannerRule => "PF-planner",
            Method::FastrackSlowest => "F(beta_l)",
            Method::FastrackFastest => "F(beta_u)",
            Method::MetaFastrack { quickest: false, .. } => "MF",
            Method::MetaFastrack { quickest: true, .. } => "MF-quick",
            Method::Mppi(_) => "MPPI",
        }
    }

    /// The method for a name given on the command line: `pf`, `pf-fast`, `f-low`, `f-high`, `mf`, `mppi`.
    pub fn parse(name: &str) -> Result<Method, String> {
        match name {
            "pf" => Ok(Method::Parametric),
            "pf-fast" => Ok(Method::ParametricFastestPath),
            "pf-planner" => Ok(Method::ParametricPlannerRule),
            "f-low" => Ok(Method::FastrackSlowest),
            "f-high" => Ok(Method::FastrackFastest),
            "mf" => Ok(Method::MetaFastrack { levels: 3, quickest: false }),
            "mf-quick" => Ok(Method::MetaFastrack { levels: 3, quickest: true }),
            "mppi" => Ok(Method::Mppi(MppiSettings::default())),
            other => Err(format!(
                "unknown method `{other}`; expected pf, pf-fast, pf-planner, f-low, f-high, mf, mf-quick or mppi"
            )),
        }
    }
}

/// What a method decided for one control period, in a workspace of `D` axes.
#[derive(Debug, Clone, PartialEq)]
pub struct Decision<const D: usize> {
    /// The control held over the period.
    pub control: Vec<f64>,
    /// The planner state the tracker follows (`None`: no planner, MPPI).
    pub planner: Option<Point<D>>,
    /// The planner speed bound in use.
    pub beta: Option<f64>,
    /// The tracking error bound in force over the period (`None`: none, MPPI).
    pub bound: Option<f64>,
    /// The raw path was planned again.
    pub replanned: bool,
    /// Wall time spent planning raw paths this period (`None`: none planned; Meta-FaSTrack's tries at each
    /// level add up).
    pub planning: Option<Duration>,
    /// The planner was reset (Parametric FaSTrack's adjustPlannerControl).
    pub reset: bool,
    /// The planner held its state with the previous, larger bound in force (adjustPlannerControl found no
    /// planner state inside the smaller one).
    pub held: bool,
    /// Calls to the server this period.
    pub round_trips: usize,
    /// The control was read at a relative state outside the model's trained domain (extrapolated).
    pub out_of_domain: bool,
    /// The relative state the online loop's control was read at, with its branch (Parametric FaSTrack).
    pub visit: Option<Visit>,
    /// Seconds since the relative state last lay in the certified set of the row in force (Parametric
    /// FaSTrack).
    pub certificate_age: Option<f64>,
}

/// Why a method cannot go on.
#[derive(Debug, thiserror::Error)]
pub enum MethodError {
    /// The online loop failed (server, planner, no reset point).
    #[error(transparent)]
    Loop(#[from] fastrack_online::online_loop::LoopError),
    /// A call to the server failed.
    #[error(transparent)]
    Client(#[from] fastrack_client::ClientError),
    /// No raw path exists at the method's inflation.
    #[error(transparent)]
    Plan(#[from] fastrack_online::raw_path::PlanError),
    /// The method cannot run on this model.
    #[error("{0}")]
    Setup(String),
}

/// What every method knows of the model and the run through a world of obstacles `O` and `D` axes.
pub struct Context<O, const D: usize> {
    /// Where the answers about the model come from.
    pub backend: Backend,
    /// The model's name.
    pub model_name: String,
    /// The model's version.
    pub model_version: u32,
    /// Record the online loop's trace (Parametric FaSTrack).
    pub trace: bool,
    /// Its TEB table as the planner-speed rules read it.
    pub speeds: Vec<SpeedRow>,
    /// How many parameters an item carries (every one set to `beta`).
    pub n_params: usize,
    /// The simulated tracker (dynamics, relative states).
    pub tracker: Arc<Tracker>,
    /// The world's goal and workspace.
    pub world: Arc<World<O, D>>,
    /// Control period (s).
    pub control_period: f64,
    /// Seed of the method's own randomness.
    pub seed: u64,
}

/// A running method.
pub enum Controller<O, const D: usize> {
    /// Parametric FaSTrack.
    Parametric(Box<Parametric<O, D>>),
    /// FaSTrack or Meta-FaSTrack.
    Levels(Box<LevelPlanner<O, D>>),
    /// MPPI.
    Mppi(Box<Mppi<O, D>>),
}

impl<O: WorldObstacle<D>, const D: usize> Controller<O, D> {
    /// Starts `method` with the tracker at `tracker` (the planner starts at the tracker's position).
    pub async fn start(method: &Method, context: Context<O, D>, tracker: &[f64]) -> Result<Self, MethodError> {
        let start = context.tracker.position(tracker);
        let last = context.speeds.len() - 1;
        Ok(match method {
            Method::Parametric => Controller::Parametric(Box::new(
                Parametric::start(context, start, false, SpeedRule::HalfDistance).await?,
            )),
            Method::ParametricFastestPath => Controller::Parametric(Box::new(
                Parametric::start(context, start, true, SpeedRule::HalfDistance).await?,
            )),
            Method::ParametricPlannerRule => {
                Controller::Parametric(Box::new(Parametric::start(context, start, true, SpeedRule::Planner).await?))
            }
            Method::FastrackSlowest => Controller::Levels(Box::new(LevelPlanner::new(context, vec![0], start, false))),
            Method::FastrackFastest => {
                Controller::Levels(Box::new(LevelPlanner::new(context, vec![last], start, false)))
            }
            Method::MetaFastrack { levels, quickest } => {
                if *levels < 2 {
                    return Err(MethodError::Setup(format!("Meta-FaSTrack needs at least 2 levels, got {levels}")));
                }
                let rows = (0..*levels).map(|k| (k * last + (levels - 1) / 2) / (levels - 1)).collect();
                Controller::Levels(Box::new(LevelPlanner::new(context, rows, start, *quickest)))
            }
            Method::Mppi(settings) => Controller::Mppi(Box::new(Mppi::new(context, settings.clone())?)),
        })
    }

    /// The decision for the control period starting at tracker state `tracker`, with `sensed` obstacles.
    pub async fn step(&mut self, tracker: &[f64], sensed: &[O]) -> Result<Decision<D>, MethodError> {
        match self {
            Controller::Parametric(method) => method.step(tracker, sensed).await,
            Controller::Levels(method) => method.step(tracker, sensed).await,
            Controller::Mppi(method) => method.step(tracker, sensed),
        }
    }

    /// The online loop's trace of the run so far, if one was recorded (Parametric FaSTrack).
    pub fn take_trace(&mut self) -> Option<LoopTrace<O, D>> {
        match self {
            Controller::Parametric(method) => method.take_trace(),
            Controller::Levels(_) | Controller::Mppi(_) => None,
        }
    }

    /// The raw path still ahead of the planner (empty for MPPI).
    pub fn raw_path(&self) -> Vec<Point<D>> {
        match self {
            Controller::Parametric(method) => method.raw_path(),
            Controller::Levels(method) => method.raw_path(),
            Controller::Mppi(_) => Vec::new(),
        }
    }
}
