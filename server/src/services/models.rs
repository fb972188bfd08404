//! `ModelService`: list and describe loaded models.

use super::observe;
use crate::metrics::Metrics;
use crate::repository::Repository;
use fastrack_proto::v1 as pb;
use pb::model_service_server::ModelService;
use std::sync::Arc;
use std::time::Instant;
use tonic::{Request, Response, Status};

/// Serves model descriptions from the repository.
pub struct Models {
    /// The repository.
    pub repository: Arc<Repository>,
    /// Metrics.
    pub metrics: Arc<Metrics>,
}

#[tonic::async_trait]
impl ModelService for Models {
    async fn list_models(&self, _: Request<pb::ListModelsRequest>) -> Result<Response<pb::ListModelsResponse>, Status> {
        let start = Instant::now();
        let answer = if self.repository.is_ready() {
            Ok(Response::new(pb::ListModelsResponse { models: self.repository.list() }))
        } else {
            Err(Status::unavailable("models are still loading"))
        };
        observe(&self.metrics, &self.repository, "ListModels", None, start, answer)
    }

    async fn get_model(&self, request: Request<pb::GetModelRequest>) -> Result<Response<pb::GetModelResponse>, Status> {
        let start = Instant::now();
        let model_ref = request.get_ref().model.as_ref();
        let answer = self
            .repository
            .resolve(model_ref)
            .map(|model| Response::new(pb::GetModelResponse { model: Some(self.repository.describe(&model)) }));
        observe(&self.metrics, &self.repository, "GetModel", model_ref, start, answer)
    }
}
