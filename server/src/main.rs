//! `fastrack-server`: the gRPC safety service binary.

use clap::Parser;
use fastrack_server::config::ServerConfig;

#[tokio::main]
async fn main() -> anyhow::Result<()> {
    let config = ServerConfig::parse();
    let filter = tracing_subscriber::EnvFilter::try_new(&config.log_level)
        .map_err(|e| anyhow::anyhow!("--log-level {:?} is not a valid filter: {e}", config.log_level))?;
    tracing_subscriber::fmt().with_env_filter(filter).with_writer(std::io::stderr).init();
    if !(config.stream_idle_timeout_s.is_finite() && config.stream_idle_timeout_s > 0.0) {
        anyhow::bail!("--stream-idle-timeout-s must be a positive number of seconds");
    }
    if config.sessions_per_model == 0 {
        anyhow::bail!("--sessions must be at least 1");
    }
    fastrack_server::run(config).await
}
