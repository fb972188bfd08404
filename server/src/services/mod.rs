//! gRPC service implementations.

pub mod admin;
pub mod models;
pub mod safety;
pub mod track;

use crate::metrics::Metrics;
use crate::repository::Repository;
use fastrack_proto::v1 as pb;
use std::time::Instant;
use tonic::Status;

/// The model label of a metric: the requested name if such a model is loaded, else `-` (names sent by
/// clients must not grow the label set without bound).
pub(crate) fn model_label<'a>(repository: &Repository, model: Option<&'a pb::ModelRef>) -> &'a str {
    match model {
        Some(m) if !repository.versions(&m.name).is_empty() => &m.name,
        _ => "-",
    }
}

/// Records a finished unary call and passes its result through.
pub(crate) fn observe<T>(
    metrics: &Metrics,
    repository: &Repository,
    rpc: &'static str,
    model: Option<&pb::ModelRef>,
    start: Instant,
    result: Result<T, Status>,
) -> Result<T, Status> {
    let code = result.as_ref().map_or_else(Status::code, |_| tonic::Code::Ok);
    metrics.call(rpc, model_label(repository, model), code, Some(start.elapsed()));
    if let Err(status) = &result {
        tracing::debug!(rpc, code = ?status.code(), message = status.message(), "call failed");
    }
    result
}
