//! The fastrack gRPC safety service: loads a model repository (and keeps it in line with the directory),
//! serves `fastrack.v1` with health and reflection on a dedicated compute pool, guards it with TLS and
//! bearer tokens, exports Prometheus metrics, and drains gracefully on SIGINT/SIGTERM.

#![warn(missing_docs)]

pub mod auth;
pub mod convert;
pub mod deadline;
pub mod loaded_model;
pub mod metrics;
pub mod repository;
pub mod scheduler;
pub mod services;
pub mod settings;
pub mod validate;

mod health;
mod polling;
mod shutdown;

use anyhow::Context;
use auth::{Guard, Role, Tokens};
use fastrack_proto::v1::{
    model_admin_service_server::ModelAdminServiceServer, model_service_server::ModelServiceServer,
    safety_service_server::SafetyServiceServer,
};
use health::set_health;
use metrics::Metrics;
use polling::spawn_repository_tasks;
use repository::Repository;
use scheduler::Scheduler;
use settings::Settings;
use shutdown::{begin_drain, drain_deadline};
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::Arc;
use tonic::service::interceptor::InterceptedService;
use tonic::transport::{Certificate, Identity, ServerTlsConfig};
use tonic_health::ServingStatus;

/// A request id: the caller's `x-request-id` if sent, else a fresh one unique within this process.
fn request_id(request: &tonic::codegen::http::Request<()>) -> String {
    static NEXT: AtomicU64 = AtomicU64::new(1);
    match request.headers().get("x-request-id").and_then(|v| v.to_str().ok()) {
        Some(id) if !id.is_empty() && id.len() <= 128 => id.to_string(),
        _ => format!("{:x}-{:x}", std::process::id(), NEXT.fetch_add(1, Ordering::Relaxed)),
    }
}

fn tls_config(tls: &settings::TlsFiles) -> ServerTlsConfig {
    let config = ServerTlsConfig::new().identity(Identity::from_pem(&tls.cert, &tls.key));
    match &tls.client_ca {
        Some(ca) => config.client_ca_root(Certificate::from_pem(ca)),
        None => config,
    }
}

fn log_exposure(settings: &Settings, local: std::net::SocketAddr, tokens: &Tokens) {
    let (users, admins) = tokens.counts();
    let tls = match &settings.tls {
        None => "off",
        Some(t) if t.client_ca.is_some() => "mutual",
        Some(_) => "on",
    };
    if local.ip().is_loopback() {
        tracing::info!(address = %local, tls, user_tokens = users, admin_tokens = admins, "listening on loopback only");
    } else if tls == "off" || tokens.is_empty() {
        tracing::warn!(address = %local, tls, user_tokens = users, admin_tokens = admins, "listening beyond loopback without TLS or without tokens");
    } else {
        tracing::info!(address = %local, tls, user_tokens = users, admin_tokens = admins, "listening");
    }
}

/// Runs the server until a shutdown signal, then drains for at most the grace period.
pub async fn run(settings: Settings) -> anyhow::Result<()> {
    let runtime = fastrack_valuefn::runtime::runtime(settings.ort_lib.as_deref()).context("loading ONNX Runtime")?;
    let tokens = Arc::new(Tokens::parse(&settings.token_entries).context("bearer tokens")?);
    let metrics = Arc::new(Metrics::new());
    let scheduler =
        Arc::new(Scheduler::start(settings.compute, Arc::clone(&metrics)).context("starting the compute pool")?);
    let repository = Arc::new(Repository::new(
        &settings.models,
        runtime,
        settings.compute.threads,
        settings.pins.clone(),
        Arc::clone(&metrics),
    ));
    let (reporter, health) = tonic_health::server::health_reporter();
    set_health(&reporter, ServingStatus::NotServing).await;
    let repository_tasks = spawn_repository_tasks(&settings, Arc::clone(&repository), reporter.clone());

    let metrics_server = match settings.metrics_listen {
        Some(address) => {
            let listener = tokio::net::TcpListener::bind(address)
                .await
                .with_context(|| format!("binding the metrics endpoint {address}"))?;
            tracing::info!(address = %listener.local_addr()?, "Prometheus metrics at /metrics");
            let metrics = Arc::clone(&metrics);
            Some(tokio::spawn(async move {
                if let Err(e) = metrics::serve(listener, metrics, std::future::pending()).await {
                    tracing::error!(error = %e, "metrics endpoint failed");
                }
            }))
        }
        None => None,
    };

    // Reflection in both protocol versions: grpcurl and current tools speak v1, Python's grpcio-reflection
    // and older tools v1alpha only.
    let descriptors = || {
        tonic_reflection::server::Builder::configure()
            .register_encoded_file_descriptor_set(fastrack_proto::FILE_DESCRIPTOR_SET)
            .register_encoded_file_descriptor_set(tonic_health::pb::FILE_DESCRIPTOR_SET)
    };
    let reflection = descriptors().build_v1().context("building the reflection service")?;
    let reflection_v1alpha = descriptors().build_v1alpha().context("building the v1alpha reflection service")?;
    let (drain_tx, drain_rx) = tokio::sync::watch::channel(false);
    let limit = settings.max_message_bytes;
    let safety = SafetyServiceServer::new(services::safety::Safety {
        repository: Arc::clone(&repository),
        scheduler: Arc::clone(&scheduler),
        metrics: Arc::clone(&metrics),
        stream_idle_timeout: settings.stream_idle_timeout,
        stream_send_timeout: settings.stream_send_timeout,
        track_streams: Arc::new(tokio::sync::Semaphore::new(settings.max_track_streams)),
        draining: drain_rx.clone(),
    })
    .max_decoding_message_size(limit)
    .max_encoding_message_size(limit);
    let models = ModelServiceServer::new(services::models::Models {
        repository: Arc::clone(&repository),
        metrics: Arc::clone(&metrics),
    })
    .max_decoding_message_size(limit)
    .max_encoding_message_size(limit);
    let admin = ModelAdminServiceServer::new(services::admin::Admin {
        repository: Arc::clone(&repository),
        metrics: Arc::clone(&metrics),
        health: reporter.clone(),
    })
    .max_decoding_message_size(limit)
    .max_encoding_message_size(limit);
    let user_guard = Guard::new(Arc::clone(&tokens), Role::User, Arc::clone(&metrics));
    let admin_guard = Guard::new(Arc::clone(&tokens), Role::Admin, Arc::clone(&metrics));

    let listener =
        tokio::net::TcpListener::bind(settings.listen).await.with_context(|| format!("binding {}", settings.listen))?;
    log_exposure(&settings, listener.local_addr()?, &tokens);
    let mut builder =
        tonic::transport::Server::builder().max_concurrent_streams(settings.max_concurrent_streams).trace_fn(
            |request| tracing::info_span!("rpc", path = %request.uri().path(), request_id = %request_id(request)),
        );
    if let Some(tls) = &settings.tls {
        builder = builder.tls_config(tls_config(tls)).context("TLS configuration")?;
    }
    let stop = begin_drain(reporter.clone(), repository_tasks.abort_handle(), drain_tx);
    let serve = builder
        .add_service(health)
        .add_service(reflection)
        .add_service(reflection_v1alpha)
        .add_service(InterceptedService::new(models, user_guard.clone()))
        .add_service(InterceptedService::new(safety, user_guard))
        .add_service(InterceptedService::new(admin, admin_guard))
        .serve_with_incoming_shutdown(
            tonic::transport::server::TcpIncoming::from(listener).with_nodelay(Some(true)),
            stop,
        );
    let grace = settings.shutdown_grace;
    tokio::select! {
        result = serve => result.context("serving")?,
        _ = drain_deadline(drain_rx, grace) => tracing::warn!(
            open_streams = metrics.active_streams(),
            grace_s = grace.as_secs_f64(),
            "drain deadline passed; exiting with calls still open"
        ),
    }
    repository_tasks.abort();
    if let Some(task) = metrics_server {
        task.abort();
    }
    tokio::task::spawn_blocking(move || scheduler.shutdown()).await.context("stopping the compute pool")?;
    tracing::info!("server stopped");
    Ok(())
}
