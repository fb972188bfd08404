//! The served promise in closed loop, row by row, through the real server: a tracker integrated here (RK4 of
//! the model's system, the control held over each step) takes its control from a `Track` stream kept at one
//! row, while a planner plays against it (the worst case of the served gradient, or random bang-bang), from
//! starts spread across the row's certified set. Each row's largest tracking error, beside its bound, is what
//! the row's certificate promises, measured outside verification.
//!
//! The starts: a centre in the set (the system's resting state, or the zero-error state of smallest value)
//! and, along random rays from it (each coordinate scaled by its domain's half-width), the last state before
//! the value first passes a share of the set level: the set's far edge in that direction.

use fastrack_client::{pb, ClientError, FastrackClient};
use fastrack_valuefn::simulation::{step_relative, HeldInputs, PlannerPolicy};
use fastrack_valuefn::system::{for_bundle, AffineSystem};
use rand::rngs::StdRng;
use rand::{Rng, SeedableRng};
use serde::Serialize;
use std::sync::Arc;

/// Points tried along each ray from the centre to the domain's edge.
const RAY_POINTS: usize = 48;
/// Headings tried for a zero-error centre of a system with no resting state.
const CENTRE_HEADINGS: usize = 24;
/// Speeds tried for it, as multiples of the row's `beta`.
const CENTRE_SPEEDS: [f64; 6] = [0.5, 0.75, 1.0, 1.25, 1.5, 2.0];
/// The step of a row with no verification record (s).
const UNVERIFIED_STEP: f64 = 0.01;
/// Mean time between a random planner's switches (s).
const MEAN_DWELL: f64 = 1.0;

/// Why a check could not run.
#[derive(Debug, thiserror::Error)]
pub enum PromiseError {
    /// A call to the server failed.
    #[error(transparent)]
    Client(#[from] ClientError),
    /// The model or a row cannot be checked this way.
    #[error("{0}")]
    Setup(String),
}

/// What the check does per row.
#[derive(Debug, Clone, Serialize)]
pub struct PromiseOptions {
    /// Starts per row: the centre and `starts - 1` edges of the set.
    pub starts: usize,
    /// Random bang-bang planners per start, besides the worst case of the served gradient.
    pub random_planners: usize,
    /// Rollout horizon (s); default the row's verification horizon.
    pub horizon: Option<f64>,
    /// The edges lie where the value first passes this share of the set level.
    pub edge_share: f64,
    /// Seed of the rays and the random planners.
    pub seed: u64,
}

impl Default for PromiseOptions {
    fn default() -> Self {
        Self { starts: 16, random_planners: 2, horizon: None, edge_share: 0.98, seed: 7 }
    }
}

/// One row's result.
#[derive(Debug, Clone, Serialize)]
pub struct RowPromise {
    /// The row's planner speed bound.
    pub beta: f64,
    /// Its certified set's level.
    pub set_level: f64,
    /// Its error bound (the dTEB radius).
    pub bound: f64,
    /// Starts rolled out (those the server placed in the set at their first tick).
    pub certified_starts: usize,
    /// Starts the server did not place in the set (not rolled out).
    pub refused_starts: usize,
    /// Largest error against the served gradient's worst case.
    pub worst_case_error: f64,
    /// Largest error against the random planners (none without them).
    pub random_error: Option<f64>,
    /// The start of the largest error of either.
    pub worst_start: Vec<f64>,
    /// `Track` ticks answered.
    pub ticks: usize,
    /// Of them, ticks whose relative state lay outside the trained domain (the control extrapolated).
    pub out_of_domain_ticks: usize,
}

impl RowPromise {
    /// The largest error over every planner.
    pub fn largest_error(&self) -> f64 {
        self.worst_case_error.max(self.random_error.unwrap_or(0.0))
    }

    /// Whether the error stayed within the bound from every certified start.
    pub fn kept(&self) -> bool {
        self.largest_error() <= self.bound
    }
}

/// The check of one model on one server.
pub struct PromiseCheck {
    client: FastrackClient,
    model: pb::ModelRef,
    info: pb::ModelInfo,
    system: Arc<AffineSystem>,
}

impl PromiseCheck {
    /// Reads the model's description; its system must be one the project defines.
    pub async fn new(client: FastrackClient, model: pb::ModelRef) -> Result<Self, PromiseError> {
        let info = client.get_model(model.clone()).await?;
        let system = for_bundle(&info.system, info.params.len()).ok_or_else(|| {
            PromiseError::Setup(format!("the model's system `{}` is not one this check knows", info.system))
        })?;
        Ok(Self { client, model, info, system: Arc::new(system) })
    }

    /// The model's served rows.
    pub fn rows(&self) -> &[pb::TebRow] {
        &self.info.teb_table
    }

    /// The version of the model that answered.
    pub fn version(&self) -> u32 {
        self.info.version
    }

    /// Checks the row at `beta`.
    pub async fn row(&self, beta: f64, options: &PromiseOptions) -> Result<RowPromise, PromiseError> {
        let row = self
            .rows()
            .iter()
            .find(|r| (r.beta - beta).abs() < 1e-9)
            .ok_or_else(|| PromiseError::Setup(format!("the model has no row at beta {beta}")))?
            .clone();
        let verification = row.verification.as_ref();
        let step = verification.map_or(UNVERIFIED_STEP, |v| v.step);
        let horizon = options.horizon.or(verification.map(|v| v.horizon)).unwrap_or(self.info.horizon);
        if !(horizon.is_finite() && horizon > 0.0 && step.is_finite() && step > 0.0) {
            return Err(PromiseError::Setup(format!(
                "the horizon must be a positive number of seconds and the step positive; got horizon {horizon}, step {step}"
            )));
        }
        let mut rng = StdRng::seed_from_u64(options.seed ^ beta.to_bits());
        let starts = self.starts(&row, options, &mut rng).await?;
        let mut result = RowPromise {
            beta,
            set_level: row.set_level,
            bound: row.bound,
            certified_starts: 0,
            refused_starts: 0,
            worst_case_error: 0.0,
            random_error: (options.random_planners > 0).then_some(0.0),
            worst_start: Vec::new(),
            ticks: 0,
            out_of_domain_ticks: 0,
        };
        let mut rollouts = tokio::task::JoinSet::new();
        for start in &starts {
            let planners = std::iter::once(PlannerPolicy::WorstCase)
                .chain((0..options.random_planners).map(|_| PlannerPolicy::bang_bang()));
            for planner in planners {
                let rollout = Rollout {
                    client: self.client.clone(),
                    model: self.model.clone(),
                    system: self.system.clone(),
                    planner_dim: self.info.planner_dim as usize,
                    row: row.clone(),
                    step,
                    horizon,
                    seed: rng.random(),
                };
                let start = start.clone();
                rollouts.spawn(async move {
                    let worst = matches!(planner, PlannerPolicy::WorstCase);
                    (worst, start.clone(), rollout.run(start, planner).await)
                });
            }
        }
        while let Some(joined) = rollouts.join_next().await {
            let (worst, start, outcome) = joined.map_err(|e| PromiseError::Setup(format!("a rollout failed: {e}")))?;
            let Some(RolledOut { error, ticks, out_of_domain }) = outcome? else {
                result.refused_starts += usize::from(worst);
                continue;
            };
            result.ticks += ticks;
            result.out_of_domain_ticks += out_of_domain;
            result.certified_starts += usize::from(worst);
            if error > result.largest_error() || result.worst_start.is_empty() {
                result.worst_start = start;
            }
            if worst {
                result.worst_case_error = result.worst_case_error.max(error);
            } else {
                result.random_error = result.random_error.map(|e| e.max(error));
            }
        }
        Ok(result)
    }

    /// The centre of the row's set and the set's edges along `options.starts - 1` random rays from it.
    async fn starts(
        &self,
        row: &pb::TebRow,
        options: &PromiseOptions,
        rng: &mut StdRng,
    ) -> Result<Vec<Vec<f64>>, PromiseError> {
        let centre = self.centre(row).await?;
        let edge = options.edge_share * row.set_level;
        let n = self.system.n_state();
        let half_widths: Vec<f64> =
            self.info.state.iter().map(|d| d.bounds.as_ref().map_or(1.0, |b| 0.5 * (b.max - b.min))).collect();
        let rays: Vec<Vec<f64>> = (1..options.starts)
            .map(|_| {
                let d: Vec<f64> = (0..n).map(|_| rng.random::<f64>() * 2.0 - 1.0).collect();
                let norm = d.iter().map(|x| x * x).sum::<f64>().sqrt().max(1e-12);
                d.iter().zip(&half_widths).map(|(x, w)| x / norm * w).collect()
            })
            .collect();
        let point = |ray: &[f64], k: usize| -> Vec<f64> {
            let s = k as f64 / RAY_POINTS as f64;
            centre.iter().zip(ray).map(|(c, d)| c + s * d).collect()
        };
        let states: Vec<f64> = rays.iter().flat_map(|ray| (1..=RAY_POINTS).flat_map(|k| point(ray, k))).collect();
        let values = self.values(&states, row.beta).await?;
        let mut starts = vec![centre.clone()];
        for (i, ray) in rays.iter().enumerate() {
            let along = &values[i * RAY_POINTS..(i + 1) * RAY_POINTS];
            let inside = along.iter().take_while(|v| v.is_some_and(|v| v <= edge)).count();
            starts.push(if inside == 0 { centre.clone() } else { point(ray, inside) });
        }
        Ok(starts)
    }

    /// The system's resting state, or else the zero-error state of smallest value at the row.
    async fn centre(&self, row: &pb::TebRow) -> Result<Vec<f64>, PromiseError> {
        if let Some(rest) = self.system.resting_state() {
            return Ok(rest);
        }
        let candidates: Vec<Vec<f64>> = (0..CENTRE_HEADINGS)
            .flat_map(|k| {
                let heading = std::f64::consts::TAU * k as f64 / CENTRE_HEADINGS as f64 - std::f64::consts::PI;
                CENTRE_SPEEDS.iter().filter_map(move |&m| self.system.start_state(heading, m * row.beta).ok())
            })
            .collect();
        let flat: Vec<f64> = candidates.iter().flatten().copied().collect();
        let values = self.values(&flat, row.beta).await?;
        candidates
            .into_iter()
            .zip(values)
            .filter_map(|(c, v)| v.map(|v| (c, v)))
            .min_by(|a, b| a.1.total_cmp(&b.1))
            .map(|(c, _)| c)
            .ok_or_else(|| PromiseError::Setup(format!("no zero-error state lies in the domain at beta {}", row.beta)))
    }

    /// `V` of each state at `beta` (every parameter), or none outside the trained domain.
    async fn values(&self, states: &[f64], beta: f64) -> Result<Vec<Option<f64>>, PromiseError> {
        let count = states.len() / self.system.n_state();
        let params = vec![beta; count * self.info.params.len()];
        let reply = self
            .client
            .evaluate_value(self.model.clone(), states.to_vec(), params, pb::OutOfDomainPolicy::Flag)
            .await?;
        Ok(reply.values.iter().zip(&reply.in_domain).map(|(&v, &inside)| inside.then_some(v)).collect())
    }
}

/// What one rollout found.
struct RolledOut {
    /// The largest tracking error.
    error: f64,
    /// Ticks answered.
    ticks: usize,
    /// Of them, outside the trained domain.
    out_of_domain: usize,
}

/// One start against one planner.
struct Rollout {
    client: FastrackClient,
    model: pb::ModelRef,
    system: Arc<AffineSystem>,
    planner_dim: usize,
    row: pb::TebRow,
    step: f64,
    horizon: f64,
    seed: u64,
}

impl Rollout {
    /// What the rollout found, or none when the server does not place the start in the row's set. The stream
    /// is kept at the row by a sensed obstacle at twice its bound; the planner's own state stays at the
    /// origin, so the tracker's state is the relative state.
    async fn run(self, start: Vec<f64>, mut planner: PlannerPolicy) -> Result<Option<RolledOut>, PromiseError> {
        let (system, beta) = (&self.system, self.row.beta);
        let params = vec![beta; system.params.len()];
        let planner_state = vec![0.0; self.planner_dim];
        let d_obs = 2.0 * self.row.bound * (1.0 + 1e-9);
        let mut rng = StdRng::seed_from_u64(self.seed);
        let mut stream = self.client.track(self.model.clone(), 0.0).await?;
        let mut r = start;
        let (mut largest, mut out_of_domain) = (system.tracking_error(&r), 0);
        let steps = (self.horizon / self.step).round() as usize;
        for k in 0..steps {
            let tick = pb::TrackTick {
                seq: k as u64,
                tracker_state: r.clone(),
                planner_state: planner_state.clone(),
                d_obs: Some(d_obs),
                planner_clearance: None,
            };
            let reply = stream.tick(tick).await?;
            if let Some(error) = reply.error {
                return Err(PromiseError::Setup(format!("tick {k} from {r:?} was refused: {}", error.message)));
            }
            if (reply.beta_query - beta).abs() > 1e-9 {
                return Err(PromiseError::Setup(format!(
                    "an obstacle at twice the bound of row {beta} gave beta_query {}: the bounds do not grow with beta",
                    reply.beta_query
                )));
            }
            if k == 0 && !reply.in_teb {
                return Ok(None);
            }
            out_of_domain += usize::from(!reply.in_domain);
            let gradient = if matches!(planner, PlannerPolicy::WorstCase) || !system.disturbances.is_empty() {
                let answer = self
                    .client
                    .evaluate_value(self.model.clone(), r.clone(), params.clone(), pb::OutOfDomainPolicy::Flag)
                    .await?;
                answer.gradients
            } else {
                vec![0.0; r.len()]
            };
            let u_p = planner.input(system, &params, &gradient, k as f64 * self.step, MEAN_DWELL, &mut rng);
            let d = system.worst_disturbance(&gradient);
            let inputs = HeldInputs { control: &reply.control, planner: &u_p, disturbance: &d };
            step_relative(system, &mut r, inputs, self.step);
            largest = largest.max(system.tracking_error(&r));
        }
        Ok(Some(RolledOut { error: largest, ticks: steps, out_of_domain }))
    }
}
