//! The repository's background work: the initial load, then a scan of the directory every poll interval,
//! with health following what is loaded.

use crate::health::refresh_health;
use crate::repository::Repository;
use crate::settings::Settings;
use std::sync::Arc;
use tonic_health::server::HealthReporter;

/// The initial load, then (if configured) a scan of the directory every poll interval.
pub(crate) fn spawn_repository_tasks(
    settings: &Settings,
    repository: Arc<Repository>,
    reporter: HealthReporter,
) -> tokio::task::JoinHandle<()> {
    let poll = settings.poll_interval;
    tokio::spawn(async move {
        let repo = Arc::clone(&repository);
        match tokio::task::spawn_blocking(move || repo.load_all()).await {
            Ok(Ok(outcomes)) => {
                let failed = outcomes.iter().filter(|o| o.result.is_err()).count();
                let loaded = repository.loaded_count();
                if loaded == 0 {
                    tracing::error!(failed, "no model loaded; health stays NOT_SERVING");
                } else {
                    tracing::info!(loaded, failed, "models ready; health SERVING");
                }
            }
            Ok(Err(e)) => tracing::error!(error = %e, "model repository unreadable; health stays NOT_SERVING"),
            Err(e) => tracing::error!(error = %e, "model loading task failed"),
        }
        refresh_health(&reporter, &repository).await;
        let Some(poll) = poll else { return };
        let mut ticker = tokio::time::interval(poll);
        ticker.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Delay);
        ticker.tick().await;
        loop {
            ticker.tick().await;
            let repo = Arc::clone(&repository);
            match tokio::task::spawn_blocking(move || repo.sync()).await {
                Ok(Ok(report)) if !report.outcomes.is_empty() || !report.removed.is_empty() => {
                    tracing::info!(
                        loaded = report.outcomes.iter().filter(|o| o.result.is_ok()).count(),
                        rejected = report.outcomes.iter().filter(|o| o.result.is_err()).count(),
                        removed = report.removed.len(),
                        "repository changed"
                    );
                    refresh_health(&reporter, &repository).await;
                }
                Ok(Ok(_)) => {}
                Ok(Err(e)) => tracing::warn!(error = %e, "repository scan failed; serving what is loaded"),
                Err(e) => tracing::error!(error = %e, "repository scan task failed"),
            }
        }
    })
}
