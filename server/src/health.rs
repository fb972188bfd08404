//! `grpc.health.v1` for the server and each of its services: NOT_SERVING until a model version is loaded,
//! and again while none is or while the server drains.

use crate::repository::Repository;
use tonic_health::server::HealthReporter;
use tonic_health::ServingStatus;

/// Services whose health is reported (plus the server as a whole, "").
const HEALTH_SERVICES: [&str; 4] =
    ["", "fastrack.v1.SafetyService", "fastrack.v1.ModelService", "fastrack.v1.ModelAdminService"];

/// Reports `status` for the server as a whole and for each of its services.
pub(crate) async fn set_health(reporter: &HealthReporter, status: ServingStatus) {
    for service in HEALTH_SERVICES {
        reporter.set_service_status(service, status).await;
    }
}

/// SERVING while at least one model version is loaded.
pub(crate) async fn refresh_health(reporter: &HealthReporter, repository: &Repository) {
    let serving = repository.loaded_count() > 0;
    set_health(reporter, if serving { ServingStatus::Serving } else { ServingStatus::NotServing }).await;
}
