//! One run of one method through one world: sense, decide, integrate the true dynamics over the control
//! period in sub-steps, and at every sub-step check the true map for a collision and the tracking error
//! against the bound in force. A collision or an error beyond the bound ends the run as a failure.
//!
//! A [`Simulator`] fetches what every run against one model shares (its dynamics, its TEB table, the control
//! period, the sensor) once; its runs are then independent of each other. A run is CPU work between server
//! calls (RK4 sub-steps, A*, MPPI's rollouts, which make no call at all): [`Simulator::spawn_run`] runs it on
//! a thread of its own, so that runs at once never starve the runtime's workers, and with them the
//! connection every run's calls travel on.

use crate::backend::Backend;
use crate::methods::{Context, Controller, Method, MethodError};
use crate::trace::LoopTrace;
use crate::tracker::{Disturbance, RangeSensor, Tracker};
use crate::visits::Visit;
use crate::world::{World, WorldObstacle};
use fastrack_client::{pb, FastrackClient};
use fastrack_online::geometry::{clearance, norm, sub, PlaneObstacle, Point, SpaceObstacle};
use fastrack_proto::planner_speed::SpeedRow;
use rand::rngs::StdRng;
use rand::SeedableRng;
use serde::{Deserialize, Serialize};
use std::future::Future;
use std::pin::Pin;
use std::sync::Arc;
use std::time::{Duration, Instant};
use tokio::task::JoinHandle;

/// A run in progress: the future [`Simulated::run_compiled_here`] returns.
pub type RunFuture<'a, O, const D: usize> = Pin<Box<dyn Future<Output = Result<Run<O, D>, MethodError>> + 'a>>;

/// The obstacle kinds of the worlds the simulator runs. Each kind's run is compiled in this crate, and so
/// optimised with it, whatever the build of the crate that calls it: a run generic over the obstacle kind
/// is compiled where it is called, and in a debug build of a tool or a test its A* replans ran 25x slower.
pub trait Simulated<const D: usize>: WorldObstacle<D> {
    /// [`Simulator::run`] through a world of this kind of obstacle.
    fn run_compiled_here<'a>(
        simulator: &'a Simulator,
        world: &'a World<Self, D>,
        method: &'a Method,
        seed: u64,
    ) -> RunFuture<'a, Self, D>;
}

/// Implements [`Simulated`] for an obstacle kind of worlds of `D` axes.
macro_rules! simulated {
    ($obstacle:ty, $dim:literal) => {
        impl Simulated<$dim> for $obstacle {
            fn run_compiled_here<'a>(
                simulator: &'a Simulator,
                world: &'a World<Self, $dim>,
                method: &'a Method,
                seed: u64,
            ) -> RunFuture<'a, Self, $dim> {
                Box::pin(simulator.run_world(world, method, seed))
            }
        }
    };
}

simulated!(PlaneObstacle, 2);
simulated!(SpaceObstacle, 3);

/// How a run is simulated.
#[derive(Debug, Clone, PartialEq)]
pub struct RunSettings {
    /// The model.
    pub model: pb::ModelRef,
    /// Control period (s); `None`: the verification step recorded in the model's manifest.
    pub control_period: Option<f64>,
    /// RK4 sub-steps per control period.
    pub substeps: usize,
    /// The run stops, not reached, after this long (s).
    pub time_limit: f64,
    /// Sensing range (m); `None`: twice the dTEB at `beta_u`, the paper's assumption.
    pub sensor_range: Option<f64>,
    /// A push on the tracker the model does not know of (none by default).
    pub disturbance: Option<Disturbance>,
    /// Record the online loop's trace of Parametric FaSTrack's runs (`Run::trace`).
    pub trace: bool,
}

impl Default for RunSettings {
    fn default() -> Self {
        Self {
            model: pb::ModelRef { name: "dubins4d".into(), version: 0 },
            control_period: None,
            substeps: 4,
            time_limit: 120.0,
            sensor_range: None,
            disturbance: None,
            trace: false,
        }
    }
}

/// How a run ended.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub enum Outcome {
    /// The tracker reached the goal.
    Reached,
    /// The tracker hit an obstacle of the true map.
    Collided,
    /// The tracking error exceeded the bound in force.
    BoundExceeded {
        /// The error (m).
        error: f64,
        /// The bound (m).
        bound: f64,
    },
    /// The time limit passed.
    TimedOut,
    /// The method gave up (no path, no reset point, the server failed).
    Failed(String),
}

impl Outcome {
    /// A failure of safety: a collision or a bound exceeded.
    pub fn is_unsafe(&self) -> bool {
        matches!(self, Outcome::Collided | Outcome::BoundExceeded { .. })
    }

    /// A short word for tables.
    pub fn label(&self) -> &'static str {
        match self {
            Outcome::Reached => "reached",
            Outcome::Collided => "collided",
            Outcome::BoundExceeded { .. } => "bound exceeded",
            Outcome::TimedOut => "timed out",
            Outcome::Failed(_) => "failed",
        }
    }
}

/// The state of the run after one control period, positions of `D` axes.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(bound(serialize = "[f64; D]: Serialize", deserialize = "[f64; D]: Deserialize<'de>"))]
pub struct Sample<const D: usize> {
    /// Time at the end of the period (s).
    pub t: f64,
    /// Tracker position.
    pub position: Point<D>,
    /// Planner position, if the method has a planner.
    pub planner: Option<Point<D>>,
    /// Planner speed bound.
    pub beta: Option<f64>,
    /// Bound in force.
    pub bound: Option<f64>,
    /// Largest tracking error over the period's sub-steps.
    pub error: Option<f64>,
    /// Smallest distance to the true map over the period's sub-steps.
    pub clearance: f64,
    /// Obstacles sensed at the period's start.
    pub sensed: usize,
}

/// A run through a world of obstacles `O` and `D` axes, finished.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(bound(
    serialize = "O: Serialize, [f64; D]: Serialize",
    deserialize = "O: Deserialize<'de>, [f64; D]: Deserialize<'de>"
))]
pub struct Run<O, const D: usize> {
    /// The method's label.
    pub method: String,
    /// How it ended.
    pub outcome: Outcome,
    /// Time when it ended (s): the time to goal when reached.
    pub time: f64,
    /// One sample per control period.
    pub samples: Vec<Sample<D>>,
    /// Smallest distance to an obstacle of the true map over the run (m).
    pub min_clearance: f64,
    /// Largest `error - bound` over the run (m; negative when the error stayed inside).
    pub worst_excess: Option<f64>,
    /// Raw paths planned.
    pub replans: usize,
    /// Planner resets.
    pub resets: usize,
    /// Control periods in which the planner held its state with the previous bound in force.
    #[serde(default)]
    pub held_steps: usize,
    /// Calls to the server (ticks or unary calls).
    pub round_trips: usize,
    /// Control periods whose control was read outside the model's trained domain (extrapolated).
    pub out_of_domain: usize,
    /// Control periods the certificate did not cover: the relative state had stayed outside the certified
    /// set of the row in force for the verification horizon or longer.
    #[serde(default)]
    pub uncertified_steps: usize,
    /// Control periods whose planner lay no farther from an obstacle of the true map than the bound in force:
    /// the tracker, anywhere within the bound of the planner, then had no proof of clearance (what a hold
    /// under a larger old bound can lead to; a collision-free run may still have some).
    #[serde(default)]
    pub exposed_steps: usize,
    /// The method's decision time per control period, server calls included.
    #[serde(with = "nanoseconds")]
    pub decision_times: Vec<Duration>,
    /// Wall time of each replan of the raw path (Meta-FaSTrack's tries at each level added up).
    #[serde(default, with = "nanoseconds")]
    pub planning_times: Vec<Duration>,
    /// Seconds with each planner speed bound in use, `(beta, seconds)` by increasing `beta`.
    #[serde(default)]
    pub beta_seconds: Vec<(f64, f64)>,
    /// The sensing range used (m).
    pub sensor_range: f64,
    /// The sTEB radius (m).
    pub steb_radius: f64,
    /// The control period used (s).
    pub control_period: f64,
    /// The planner's raw path at the end.
    pub final_path: Vec<Point<D>>,
    /// The relative state of every control period of the online loop, with its branch (Parametric FaSTrack).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub visits: Vec<Visit>,
    /// The online loop's trace (Parametric FaSTrack, when the settings ask for it).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub trace: Option<LoopTrace<O, D>>,
}

/// A run through a world in the plane.
pub type PlaneRun = Run<PlaneObstacle, 2>;

impl<O, const D: usize> Run<O, D> {
    /// A run of `method` not yet under way: timed out at 0 s until it ends otherwise, nothing counted, with
    /// the sensor range, sTEB radius and control period it runs with.
    pub fn starting(method: &str, sensor_range: f64, steb_radius: f64, control_period: f64) -> Self {
        Self {
            method: method.to_string(),
            outcome: Outcome::TimedOut,
            time: 0.0,
            samples: Vec::new(),
            min_clearance: f64::INFINITY,
            worst_excess: None,
            replans: 0,
            resets: 0,
            held_steps: 0,
            round_trips: 0,
            out_of_domain: 0,
            uncertified_steps: 0,
            exposed_steps: 0,
            decision_times: Vec::new(),
            planning_times: Vec::new(),
            beta_seconds: Vec::new(),
            sensor_range,
            steb_radius,
            control_period,
            final_path: Vec::new(),
            visits: Vec::new(),
            trace: None,
        }
    }

    /// The planner speed bound in use, averaged over the run's time (`None` for a method without one).
    pub fn mean_beta(&self) -> Option<f64> {
        let seconds: f64 = self.beta_seconds.iter().map(|(_, s)| s).sum();
        (seconds > 0.0).then(|| self.beta_seconds.iter().map(|(beta, s)| beta * s).sum::<f64>() / seconds)
    }

    /// The share of the run's time with a planner speed bound above `beta` in use.
    pub fn share_above(&self, beta: f64) -> f64 {
        let seconds: f64 = self.beta_seconds.iter().map(|(_, s)| s).sum();
        // Folded from +0: an empty sum of floats is -0, which prints as "-0%".
        let above: f64 = self.beta_seconds.iter().filter(|(b, _)| *b > beta).fold(0.0, |sum, (_, s)| sum + s);
        if seconds > 0.0 {
            above / seconds
        } else {
            0.0
        }
    }
}

/// What every run against one model shares, fetched from the server (or the model in this process) once.
pub struct Simulator {
    backend: Backend,
    settings: RunSettings,
    tracker: Arc<Tracker>,
    speeds: Vec<SpeedRow>,
    n_params: usize,
    model_name: String,
    model_version: u32,
    control_period: f64,
    sensor: RangeSensor,
    certificate_horizon: Option<f64>,
}

impl Simulator {
    /// Fetches the model of `settings` from the server and checks that runs can be simulated with it.
    pub async fn connect(client: &FastrackClient, settings: RunSettings) -> Result<Self, MethodError> {
        let backend = Backend::Service { client: client.clone(), model: settings.model.clone() };
        Self::new(backend, settings).await
    }

    /// Reads the model's description from `backend` and checks that runs can be simulated with it (the
    /// model of `settings` names the server's model; a model in this process is the backend's own).
    pub async fn new(backend: Backend, settings: RunSettings) -> Result<Self, MethodError> {
        let info = backend.model_info().await?;
        let system = fastrack_valuefn::system::for_bundle(&info.system, info.params.len())
            .ok_or_else(|| MethodError::Setup(format!("the simulator has no dynamics for system `{}`", info.system)))?;
        let tracker = Arc::new(Tracker::new(system).map_err(MethodError::Setup)?);
        let speeds: Vec<SpeedRow> = info.teb_table.iter().map(SpeedRow::from).collect();
        let Some(fastest) = speeds.last().map(|row| row.bound) else {
            return Err(MethodError::Setup("the model's TEB table is empty".into()));
        };
        let control_period = match settings.control_period {
            Some(dt) => dt,
            None => verification_step(&info)?,
        };
        if !(control_period.is_finite() && control_period > 0.0 && settings.substeps > 0) {
            return Err(MethodError::Setup(format!(
                "control period {control_period} s and {} sub-steps",
                settings.substeps
            )));
        }
        let sensor = RangeSensor { range: settings.sensor_range.unwrap_or(2.0 * fastest) };
        if !(sensor.range.is_finite() && sensor.range > 0.0) {
            return Err(MethodError::Setup(format!("sensor range {} m; must be finite and > 0", sensor.range)));
        }
        Ok(Self {
            backend,
            settings,
            tracker,
            speeds,
            n_params: info.params.len(),
            model_name: info.name.clone(),
            model_version: info.version,
            control_period,
            sensor,
            certificate_horizon: fastrack_online::track_oracle::certificate_horizon(&info),
        })
    }

    /// The model's TEB table as the planner-speed rules read it, slowest row first.
    pub fn speeds(&self) -> &[SpeedRow] {
        &self.speeds
    }

    /// The sTEB radius (m): the bound at `beta_l`, by which worlds must be feasible.
    pub fn steb_radius(&self) -> f64 {
        self.speeds[0].bound
    }

    /// The control period of every run (s).
    pub fn control_period(&self) -> f64 {
        self.control_period
    }

    /// The sensing range of every run (m).
    pub fn sensor_range(&self) -> f64 {
        self.sensor.range
    }

    /// The names of the model's state coordinates, in order (the columns of a visits file).
    pub fn state_names(&self) -> Vec<String> {
        self.tracker.system().state.iter().map(|d| d.name.to_string()).collect()
    }

    /// Axes of the model's planner, and of the worlds its runs go through: 2 or 3.
    pub fn dim(&self) -> usize {
        self.tracker.dim()
    }

    /// Runs `method` through `world` on a thread of its own (see the module's doc), its randomness seeded
    /// by `seed`.
    pub fn spawn_run<O: Simulated<D>, const D: usize>(
        self: &Arc<Self>,
        world: World<O, D>,
        method: Method,
        seed: u64,
    ) -> JoinHandle<Result<Run<O, D>, MethodError>> {
        let (simulator, runtime) = (Arc::clone(self), tokio::runtime::Handle::current());
        tokio::task::spawn_blocking(move || runtime.block_on(simulator.run(&world, &method, seed)))
    }

    /// Runs `method` through `world`, its randomness seeded by `seed`. Whatever the server does, the run
    /// ends with an [`Outcome`]; an error means only that the method cannot run on this model (a world of
    /// another dimension than the model's planner among them).
    pub async fn run<O: Simulated<D>, const D: usize>(
        &self,
        world: &World<O, D>,
        method: &Method,
        seed: u64,
    ) -> Result<Run<O, D>, MethodError> {
        O::run_compiled_here(self, world, method, seed).await
    }

    /// [`Simulator::run`] for any kind of obstacle; called only by the [`Simulated`] kinds.
    async fn run_world<O: WorldObstacle<D>, const D: usize>(
        &self,
        world: &World<O, D>,
        method: &Method,
        seed: u64,
    ) -> Result<Run<O, D>, MethodError> {
        let (tracker, settings, control_period) = (&self.tracker, &self.settings, self.control_period);
        if tracker.dim() != D {
            return Err(MethodError::Setup(format!(
                "a world of {D} axes for a model whose planner has {}",
                tracker.dim()
            )));
        }
        let context = Context {
            backend: self.backend.clone(),
            speeds: self.speeds.clone(),
            n_params: self.n_params,
            model_name: self.model_name.clone(),
            model_version: self.model_version,
            trace: settings.trace,
            tracker: Arc::clone(tracker),
            world: Arc::new(world.clone()),
            control_period,
            seed,
        };
        let mut s =
            tracker.initial_state(&world.start, world.start_heading, world.start_speed).map_err(MethodError::Setup)?;
        let started = Controller::start(method, context, &s).await;
        let mut rng = StdRng::seed_from_u64(seed ^ 0xD15_7A6B);
        let mut run = Run::starting(method.label(), self.sensor.range, self.steb_radius(), control_period);
        run.min_clearance = clearance(&world.obstacles, world.start);
        // A method that cannot start on the server (its stream refused, a call timed out) is a failed run,
        // not a failed benchmark; a method that cannot run on this model at all is an error.
        let mut controller = match started {
            Ok(controller) => controller,
            Err(MethodError::Setup(why)) => return Err(MethodError::Setup(why)),
            Err(e) => {
                run.outcome = Outcome::Failed(e.to_string());
                return Ok(run);
            }
        };
        let steps = (settings.time_limit / control_period).ceil() as usize;
        let mut push = [0.0; D];
        for k in 0..steps {
            let t = k as f64 * control_period;
            let position = tracker.position(&s);
            if norm(sub(position, world.goal)) <= world.goal_radius {
                run.outcome = Outcome::Reached;
                run.time = t;
                break;
            }
            let sensed = self.sensor.sense(&world.obstacles, position);
            let started = Instant::now();
            let mut decision = match controller.step(&s, &sensed).await {
                Ok(decision) => decision,
                Err(e) => {
                    run.outcome = Outcome::Failed(e.to_string());
                    run.time = t;
                    break;
                }
            };
            run.decision_times.push(started.elapsed());
            run.planning_times.extend(decision.planning);
            if let Some(beta) = decision.beta {
                add_seconds(&mut run.beta_seconds, beta, control_period);
            }
            run.replans += usize::from(decision.replanned);
            run.resets += usize::from(decision.reset);
            run.held_steps += usize::from(decision.held);
            run.round_trips += decision.round_trips;
            run.out_of_domain += usize::from(decision.out_of_domain);
            if let (Some(age), Some(horizon)) = (decision.certificate_age, self.certificate_horizon) {
                run.uncertified_steps += usize::from(age >= horizon);
            }
            run.visits.extend(decision.visit.take());
            if let Some(disturbance) = &settings.disturbance {
                if (t / disturbance.period).floor() != ((t - control_period) / disturbance.period).floor() || k == 0 {
                    push = disturbance.draw(&mut rng);
                }
            }
            if let (Some(planner), Some(bound)) = (decision.planner, decision.bound) {
                run.exposed_steps += usize::from(clearance(&world.obstacles, planner) <= bound);
            }
            let (mut period_clearance, mut period_error) = (f64::INFINITY, None::<f64>);
            let mut failure = None;
            tracker.step(&mut s, &decision.control, &push, control_period, settings.substeps, |x| {
                let p = tracker.position(x);
                let gap = clearance(&world.obstacles, p);
                period_clearance = period_clearance.min(gap);
                if gap <= 0.0 {
                    failure = Some(Outcome::Collided);
                    return false;
                }
                if let (Some(planner), Some(bound)) = (decision.planner, decision.bound) {
                    let error = tracker.tracking_error(x, &planner);
                    period_error = Some(period_error.map_or(error, |e| e.max(error)));
                    let excess = error - bound;
                    run.worst_excess = Some(run.worst_excess.map_or(excess, |w| w.max(excess)));
                    if excess > 1e-9 {
                        failure = Some(Outcome::BoundExceeded { error, bound });
                        return false;
                    }
                }
                true
            });
            run.min_clearance = run.min_clearance.min(period_clearance);
            run.samples.push(Sample {
                t: t + control_period,
                position: tracker.position(&s),
                planner: decision.planner,
                beta: decision.beta,
                bound: decision.bound,
                error: period_error,
                clearance: period_clearance,
                sensed: sensed.len(),
            });
            if let Some(outcome) = failure {
                run.outcome = outcome;
                run.time = t + control_period;
                break;
            }
            run.time = t + control_period;
        }
        run.final_path = controller.raw_path();
        run.trace = controller.take_trace();
        Ok(run)
    }
}

/// The integration step the model's verification used (every verified row records it).
fn verification_step(info: &pb::ModelInfo) -> Result<f64, MethodError> {
    let manifest: serde_json::Value = serde_json::from_str(&info.manifest_json)
        .map_err(|e| MethodError::Setup(format!("the model's manifest does not parse: {e}")))?;
    manifest["teb_table"]
        .as_array()
        .and_then(|rows| rows.iter().find_map(|row| row["verification"]["step"].as_f64()))
        .ok_or_else(|| MethodError::Setup("the model is not verified: give the control period".into()))
}

/// Adds `seconds` to `beta`'s entry of `(beta, seconds)` pairs kept by increasing `beta`.
pub(crate) fn add_seconds(pairs: &mut Vec<(f64, f64)>, beta: f64, seconds: f64) {
    match pairs.binary_search_by(|(b, _)| b.total_cmp(&beta)) {
        Ok(i) => pairs[i].1 += seconds,
        Err(i) => pairs.insert(i, (beta, seconds)),
    }
}

/// Durations as whole nanoseconds, for records of runs.
mod nanoseconds {
    use serde::{Deserialize, Deserializer, Serialize, Serializer};
    use std::time::Duration;

    pub fn serialize<S: Serializer>(times: &[Duration], serializer: S) -> Result<S::Ok, S::Error> {
        times
            .iter()
            .map(|t| u64::try_from(t.as_nanos()).unwrap_or(u64::MAX))
            .collect::<Vec<u64>>()
            .serialize(serializer)
    }

    pub fn deserialize<'de, D: Deserializer<'de>>(deserializer: D) -> Result<Vec<Duration>, D::Error> {
        Ok(Vec::<u64>::deserialize(deserializer)?.into_iter().map(Duration::from_nanos).collect())
    }
}
