//! `SafetyService`: planner speed, tracking error bounds, value and tracking control (unary), plus the
//! `Track` stream (see [`super::track`]).

use super::observe;
use crate::loaded_model::BatchResult;
use crate::metrics::Metrics;
use crate::repository::Repository;
use crate::scheduler::Scheduler;
use crate::validate::{self, ValidBatch, MAX_BOUNDARY_POINTS};
use fastrack_proto::v1 as pb;
use fastrack_valuefn::manifest::{boundary_directions, TebRow};
use pb::safety_service_server::SafetyService;
use std::pin::Pin;
use std::sync::Arc;
use std::time::{Duration, Instant};
use tokio_stream::Stream;
use tonic::{Request, Response, Status, Streaming};

/// Answers safety queries from the repository's models.
pub struct Safety {
    /// The repository.
    pub repository: Arc<Repository>,
    /// The compute pool.
    pub scheduler: Arc<Scheduler>,
    /// Metrics.
    pub metrics: Arc<Metrics>,
    /// Default idle timeout of `Track` streams.
    pub stream_idle_timeout: Duration,
    /// How long a `Track` reply may wait for its client to read.
    pub stream_send_timeout: Duration,
    /// Permits for `Track` streams open at once, one taken per stream.
    pub track_streams: Arc<tokio::sync::Semaphore>,
    /// Turns true when the server starts draining.
    pub draining: tokio::sync::watch::Receiver<bool>,
}

/// `count` points on the boundary of a 2-D certified set, radii interpolated linearly in angle between the
/// stored directions, counter-clockwise from angle 0.
fn boundary_points(row: &TebRow, n_error: usize, count: usize) -> Result<Vec<f64>, Status> {
    let radii = &row.boundary_radii;
    if radii.is_empty() {
        return Err(Status::failed_precondition(
            "this model's TEB table holds no boundary data (error sets of more than 2 dimensions)",
        ));
    }
    Ok(match n_error {
        1 => vec![radii[0], -radii[1]],
        _ => {
            let m = radii.len();
            (0..count)
                .flat_map(|k| {
                    let angle = 2.0 * std::f64::consts::PI * k as f64 / count as f64;
                    let position = angle / (2.0 * std::f64::consts::PI) * m as f64;
                    let (i, frac) = (position.floor() as usize % m, position.fract());
                    let r = radii[i] * (1.0 - frac) + radii[(i + 1) % m] * frac;
                    [r * angle.cos(), r * angle.sin()]
                })
                .collect()
        }
    })
}

impl Safety {
    fn tracking_error_bound(
        &self,
        req: &pb::GetTrackingErrorBoundRequest,
    ) -> Result<Response<pb::GetTrackingErrorBoundResponse>, Status> {
        let model = self.repository.resolve(req.model.as_ref())?;
        let beta = validate::beta(&model, req.beta)?;
        if req.boundary_points > MAX_BOUNDARY_POINTS {
            return Err(Status::invalid_argument(format!(
                "boundary_points = {}; must be at most {MAX_BOUNDARY_POINTS}",
                req.boundary_points
            )));
        }
        let row = model.row_for(beta).ok_or_else(|| Status::internal("validated beta has no table row"))?;
        let n_error = model.manifest.error_coords().len();
        let boundary = if req.boundary_points == 0 {
            Vec::new()
        } else if boundary_directions(n_error, 1).is_empty() {
            return Err(Status::invalid_argument(format!(
                "boundary points exist for 1-D and 2-D error spaces; this model's has {n_error} dimensions (ask for boundary_points = 0)"
            )));
        } else {
            boundary_points(row, n_error, req.boundary_points as usize)?
        };
        Ok(Response::new(pb::GetTrackingErrorBoundResponse {
            level: row.set_level(),
            radius: row.bound(),
            extent: row.extent.clone(),
            table_beta: row.beta,
            boundary,
            model_version: model.manifest.version,
        }))
    }

    /// Resolves the model, validates the batch, evaluates it on the compute pool and records the call: the
    /// shared path of EvaluateValue and TrackingControl (`respond` builds the reply).
    async fn evaluate<R>(
        &self,
        rpc: &'static str,
        request: Request<BatchRequest>,
        respond: impl FnOnce(u32, BatchResult, ValidBatch) -> R,
    ) -> Result<Response<R>, Status> {
        let start = Instant::now();
        let deadline = crate::deadline::from_metadata(request.metadata(), start);
        let req = request.into_inner();
        let answer = async {
            let model = self.repository.resolve(req.model.as_ref())?;
            let batch = validate::batch(&model, &req.states, &req.params, req.policy)?;
            let (result, batch) = self.scheduler.evaluate(&model, batch, deadline).await?;
            Ok(Response::new(respond(model.manifest.version, result, batch)))
        }
        .await;
        observe(&self.metrics, &self.repository, rpc, req.model.as_ref(), start, answer)
    }
}

/// The fields EvaluateValue and TrackingControl requests share.
struct BatchRequest {
    model: Option<pb::ModelRef>,
    states: Vec<f64>,
    params: Vec<f64>,
    policy: pb::OutOfDomainPolicy,
}

impl BatchRequest {
    fn new(policy: pb::OutOfDomainPolicy, model: Option<pb::ModelRef>, states: Vec<f64>, params: Vec<f64>) -> Self {
        Self { model, states, params, policy }
    }
}

fn widen(v: &[f32]) -> Vec<f64> {
    v.iter().map(|&x| f64::from(x)).collect()
}

#[tonic::async_trait]
impl SafetyService for Safety {
    async fn query_planner_control(
        &self,
        request: Request<pb::QueryPlannerControlRequest>,
    ) -> Result<Response<pb::QueryPlannerControlResponse>, Status> {
        let start = Instant::now();
        let req = request.into_inner();
        let answer = (|| {
            let model = self.repository.resolve(req.model.as_ref())?;
            let q = validate::planner_speed(&model, req.d_obs, req.planner_clearance)?;
            Ok(Response::new(pb::QueryPlannerControlResponse {
                beta_query: q.beta,
                dteb_radius: q.dteb_radius,
                steb_radius: q.steb_radius,
                steb_exceeds_half_distance: q.steb_exceeds_half_distance,
                model_version: model.manifest.version,
            }))
        })();
        observe(&self.metrics, &self.repository, "QueryPlannerControl", req.model.as_ref(), start, answer)
    }

    async fn get_tracking_error_bound(
        &self,
        request: Request<pb::GetTrackingErrorBoundRequest>,
    ) -> Result<Response<pb::GetTrackingErrorBoundResponse>, Status> {
        let start = Instant::now();
        let req = request.into_inner();
        let answer = self.tracking_error_bound(&req);
        observe(&self.metrics, &self.repository, "GetTrackingErrorBound", req.model.as_ref(), start, answer)
    }

    async fn evaluate_value(
        &self,
        request: Request<pb::EvaluateValueRequest>,
    ) -> Result<Response<pb::EvaluateValueResponse>, Status> {
        let request = request.map(|r| BatchRequest::new(r.out_of_domain(), r.model, r.states, r.params));
        self.evaluate("EvaluateValue", request, |model_version, result, batch| pb::EvaluateValueResponse {
            values: widen(&result.outputs.value),
            gradients: widen(&result.outputs.grad),
            controls: widen(&result.outputs.control),
            in_teb: result.in_teb,
            in_domain: batch.in_domain,
            model_version,
        })
        .await
    }

    async fn tracking_control(
        &self,
        request: Request<pb::TrackingControlRequest>,
    ) -> Result<Response<pb::TrackingControlResponse>, Status> {
        let request = request.map(|r| BatchRequest::new(r.out_of_domain(), r.model, r.states, r.params));
        self.evaluate("TrackingControl", request, |model_version, result, batch| pb::TrackingControlResponse {
            controls: widen(&result.outputs.control),
            values: widen(&result.outputs.value),
            in_teb: result.in_teb,
            in_domain: batch.in_domain,
            model_version,
        })
        .await
    }

    type TrackStream = Pin<Box<dyn Stream<Item = Result<pb::TrackResponse, Status>> + Send + 'static>>;

    async fn track(
        &self,
        request: Request<Streaming<pb::TrackRequest>>,
    ) -> Result<Response<Self::TrackStream>, Status> {
        let context = super::track::StreamContext {
            repository: Arc::clone(&self.repository),
            scheduler: Arc::clone(&self.scheduler),
            metrics: Arc::clone(&self.metrics),
            default_idle: self.stream_idle_timeout,
            send_timeout: self.stream_send_timeout,
            streams: Arc::clone(&self.track_streams),
            draining: self.draining.clone(),
        };
        let stream = super::track::open(context, request.into_inner()).await?;
        Ok(Response::new(Box::pin(stream)))
    }
}
