//! `ModelService`: list and describe loaded models.

use crate::repository::Repository;
use fastrack_proto::v1 as pb;
use pb::model_service_server::ModelService;
use std::sync::Arc;
use tonic::{Request, Response, Status};

/// Serves model descriptions from the repository.
pub struct Models {
    /// The repository.
    pub repository: Arc<Repository>,
}

#[tonic::async_trait]
impl ModelService for Models {
    async fn list_models(&self, _: Request<pb::ListModelsRequest>) -> Result<Response<pb::ListModelsResponse>, Status> {
        if !self.repository.is_ready() {
            return Err(Status::unavailable("models are still loading"));
        }
        Ok(Response::new(pb::ListModelsResponse { models: self.repository.list() }))
    }

    async fn get_model(&self, request: Request<pb::GetModelRequest>) -> Result<Response<pb::GetModelResponse>, Status> {
        let model = self.repository.resolve(request.get_ref().model.as_ref())?;
        Ok(Response::new(pb::GetModelResponse { model: Some(self.repository.describe(&model)) }))
    }
}
