//! `ModelAdminService`: load, unload and reload model versions at run time.

use super::observe;
use crate::metrics::Metrics;
use crate::repository::{LoadOutcome, Repository};
use fastrack_proto::v1 as pb;
use pb::model_admin_service_server::ModelAdminService;
use std::sync::Arc;
use std::time::Instant;
use tonic::{Request, Response, Status};

/// Changes what the repository serves.
pub struct Admin {
    /// The repository.
    pub repository: Arc<Repository>,
    /// Metrics.
    pub metrics: Arc<Metrics>,
    /// Health, refreshed after every change (NOT_SERVING once nothing is loaded).
    pub health: tonic_health::server::HealthReporter,
}

fn version_filter(version: u32) -> Option<u32> {
    (version != 0).then_some(version)
}

impl Admin {
    async fn load(&self, name: Option<String>, version: Option<u32>) -> Result<Vec<LoadOutcome>, Status> {
        let repository = Arc::clone(&self.repository);
        tokio::task::spawn_blocking(move || repository.load(name.as_deref(), version))
            .await
            .map_err(|e| Status::internal(format!("load task failed: {e}")))?
            .map_err(Status::internal)
    }

    async fn load_one(&self, req: pb::LoadModelRequest) -> Result<Response<pb::LoadModelResponse>, Status> {
        if req.name.is_empty() {
            return Err(Status::invalid_argument("name is required: a model folder of the repository"));
        }
        let outcomes = self.load(Some(req.name.clone()), version_filter(req.version)).await?;
        if outcomes.is_empty() {
            return Err(Status::not_found(format!(
                "the repository has no folder {}{}",
                req.name,
                version_filter(req.version).map(|v| format!("/{v}")).unwrap_or_default()
            )));
        }
        let failures: Vec<String> =
            outcomes.iter().filter_map(|o| o.result.as_ref().err().map(|e| format!("{}: {e}", o.version))).collect();
        if failures.len() == outcomes.len() {
            return Err(Status::failed_precondition(format!(
                "no version of {} could be loaded: {}",
                req.name,
                failures.join("; ")
            )));
        }
        Ok(Response::new(pb::LoadModelResponse { loaded_versions: self.repository.versions(&req.name) }))
    }

    fn unload_one(&self, req: &pb::UnloadModelRequest) -> Result<Response<pb::UnloadModelResponse>, Status> {
        let unloaded = self.repository.unload(&req.name, version_filter(req.version));
        if unloaded.is_empty() {
            return Err(Status::not_found(format!(
                "model {:?} version {} is not loaded (0 = every version)",
                req.name, req.version
            )));
        }
        tracing::info!(model = %req.name, versions = ?unloaded, "unloaded");
        Ok(Response::new(pb::UnloadModelResponse { unloaded_versions: unloaded }))
    }

    async fn reload(&self, name: String) -> Result<Response<pb::ReloadModelResponse>, Status> {
        let outcomes = self.load((!name.is_empty()).then_some(name), None).await?;
        Ok(Response::new(pb::ReloadModelResponse {
            outcomes: outcomes
                .into_iter()
                .map(|o| pb::ReloadOutcome {
                    loaded: o.result.is_ok(),
                    error: o.result.err().unwrap_or_default(),
                    name: o.name,
                    version: o.version,
                })
                .collect(),
        }))
    }
}

#[tonic::async_trait]
impl ModelAdminService for Admin {
    async fn load_model(
        &self,
        request: Request<pb::LoadModelRequest>,
    ) -> Result<Response<pb::LoadModelResponse>, Status> {
        let start = Instant::now();
        let req = request.into_inner();
        let model = pb::ModelRef { name: req.name.clone(), version: req.version };
        let answer = self.load_one(req).await;
        crate::health::refresh_health(&self.health, &self.repository).await;
        observe(&self.metrics, &self.repository, "LoadModel", Some(&model), start, answer)
    }

    async fn unload_model(
        &self,
        request: Request<pb::UnloadModelRequest>,
    ) -> Result<Response<pb::UnloadModelResponse>, Status> {
        let start = Instant::now();
        let req = request.into_inner();
        let answer = self.unload_one(&req);
        let model = pb::ModelRef { name: req.name, version: req.version };
        crate::health::refresh_health(&self.health, &self.repository).await;
        observe(&self.metrics, &self.repository, "UnloadModel", Some(&model), start, answer)
    }

    async fn reload_model(
        &self,
        request: Request<pb::ReloadModelRequest>,
    ) -> Result<Response<pb::ReloadModelResponse>, Status> {
        let start = Instant::now();
        let name = request.into_inner().name;
        let model = pb::ModelRef { name: name.clone(), version: 0 };
        let answer = self.reload(name).await;
        crate::health::refresh_health(&self.health, &self.repository).await;
        observe(&self.metrics, &self.repository, "ReloadModel", Some(&model), start, answer)
    }
}
