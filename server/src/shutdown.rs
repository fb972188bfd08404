//! Graceful shutdown: the signals that start it, the drain (health NOT_SERVING, no more polling, streams
//! told to end) and the deadline after which the server exits with calls still open.

use crate::health::set_health;
use std::time::Duration;
use tokio::sync::watch;
use tokio::task::AbortHandle;
use tonic_health::server::HealthReporter;
use tonic_health::ServingStatus;

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
        _ = interrupt => tracing::info!("SIGINT received, draining"),
        _ = terminate => tracing::info!("SIGTERM received, draining"),
    }
}

/// Resolves once a shutdown signal has started the drain: polling stopped (it must not turn health back to
/// SERVING), health NOT_SERVING, and `draining` set so that open `Track` streams end after their tick. The
/// server stops accepting connections when this resolves.
pub(crate) async fn begin_drain(reporter: HealthReporter, polling: AbortHandle, draining: watch::Sender<bool>) {
    shutdown_signal().await;
    polling.abort();
    set_health(&reporter, ServingStatus::NotServing).await;
    let _ = draining.send(true);
}

/// Resolves `grace` after the drain began.
pub(crate) async fn drain_deadline(mut draining: watch::Receiver<bool>, grace: Duration) {
    let _ = draining.wait_for(|d| *d).await;
    tokio::time::sleep(grace).await;
}
