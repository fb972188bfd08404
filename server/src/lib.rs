//! The fastrack gRPC safety service: loads a model repository, serves `fastrack.v1` with health and
//! reflection, and shuts down gracefully on SIGINT/SIGTERM.

pub mod config;
pub mod convert;
pub mod model;
pub mod repository;
pub mod services;
pub mod teb;
pub mod validate;

use anyhow::Context;
use config::ServerConfig;
use fastrack_proto::v1::{
    model_admin_service_server::ModelAdminServiceServer, model_service_server::ModelServiceServer,
    safety_service_server::SafetyServiceServer,
};
use repository::Repository;
use std::sync::Arc;
use std::time::Duration;
use tonic_health::ServingStatus;

/// Services whose health is reported (plus the server as a whole, "").
const HEALTH_SERVICES: [&str; 4] =
    ["", "fastrack.v1.SafetyService", "fastrack.v1.ModelService", "fastrack.v1.ModelAdminService"];

async fn set_health(reporter: &tonic_health::server::HealthReporter, status: ServingStatus) {
    for service in HEALTH_SERVICES {
        reporter.set_service_status(service, status).await;
    }
}

/// Resolves on SIGINT or SIGTERM.
async fn shutdown_signal() {
    let interrupt = tokio::signal::ctrl_c();
    #[cfg(unix)]
    let terminate = async {
        match tokio::signal::unix::signal(tokio::signal::unix::SignalKind::terminate()) {
            Ok(mut signal) => {
                signal.recv().await;
            }
            Err(e) => {
                tracing::warn!(error = %e, "cannot listen for SIGTERM");
                std::future::pending::<()>().await
            }
        }
    };
    #[cfg(not(unix))]
    let terminate = std::future::pending::<()>();
    tokio::select! {
        _ = interrupt => tracing::info!("SIGINT received, shutting down"),
        _ = terminate => tracing::info!("SIGTERM received, shutting down"),
    }
}

/// Runs the server until a shutdown signal.
pub async fn run(config: ServerConfig) -> anyhow::Result<()> {
    let runtime = fastrack_valuefn::runtime::runtime(config.ort_lib.as_deref()).context("loading ONNX Runtime")?;
    let repository = Arc::new(Repository::new(&config.models, runtime, config.sessions_per_model));
    let (reporter, health) = tonic_health::server::health_reporter();
    set_health(&reporter, ServingStatus::NotServing).await;

    let loader = {
        let repository = Arc::clone(&repository);
        let reporter = reporter.clone();
        tokio::spawn(async move {
            let repo = Arc::clone(&repository);
            let outcome = tokio::task::spawn_blocking(move || repo.load_all()).await;
            match outcome {
                Ok(Ok(outcomes)) => {
                    let failed = outcomes.iter().filter(|o| o.result.is_err()).count();
                    let loaded = repository.loaded_count();
                    if loaded == 0 {
                        tracing::error!(failed, "no model loaded; health stays NOT_SERVING");
                    } else {
                        tracing::info!(loaded, failed, "models ready; health SERVING");
                        set_health(&reporter, ServingStatus::Serving).await;
                    }
                }
                Ok(Err(e)) => tracing::error!(error = %e, "model repository unreadable; health stays NOT_SERVING"),
                Err(e) => tracing::error!(error = %e, "model loading task failed"),
            }
        })
    };

    let reflection = tonic_reflection::server::Builder::configure()
        .register_encoded_file_descriptor_set(fastrack_proto::FILE_DESCRIPTOR_SET)
        .register_encoded_file_descriptor_set(tonic_health::pb::FILE_DESCRIPTOR_SET)
        .build_v1()
        .context("building the reflection service")?;
    let safety = services::safety::Safety {
        repository: Arc::clone(&repository),
        stream_idle_timeout: Duration::from_secs_f64(config.stream_idle_timeout_s),
    };
    let listener =
        tokio::net::TcpListener::bind(config.listen).await.with_context(|| format!("binding {}", config.listen))?;
    let local = listener.local_addr()?;
    if local.ip().is_loopback() {
        tracing::info!(address = %local, "listening on loopback only");
    } else {
        tracing::warn!(address = %local, "listening beyond loopback");
    }
    tonic::transport::Server::builder()
        .add_service(health)
        .add_service(reflection)
        .add_service(ModelServiceServer::new(services::models::Models { repository: Arc::clone(&repository) }))
        .add_service(ModelAdminServiceServer::new(services::admin::Admin { repository: Arc::clone(&repository) }))
        .add_service(SafetyServiceServer::new(safety))
        .serve_with_incoming_shutdown(
            tonic::transport::server::TcpIncoming::from(listener).with_nodelay(Some(true)),
            shutdown_signal(),
        )
        .await
        .context("serving")?;
    loader.abort();
    tracing::info!("server stopped");
    Ok(())
}
