//! `fastrack health`: the server's `grpc.health.v1` status, optionally waiting for SERVING.

use super::{print, seconds, Server};
use serde_json::json;
use std::time::{Duration, Instant};

/// Arguments of `fastrack health`.
#[derive(clap::Args)]
pub struct Args {
    /// Wait up to this many seconds for the server to accept connections and report SERVING (exits non-zero
    /// if it does not).
    #[arg(long, value_parser = seconds)]
    wait_s: Option<Duration>,
}

/// Prints the health status; with `--wait-s`, retries connecting and polls until SERVING.
pub async fn run(server: &Server, args: Args, json_mode: bool) -> anyhow::Result<()> {
    let status = match args.wait_s {
        None => server.connect().await?.health().await?,
        Some(limit) => {
            let start = Instant::now();
            let client = loop {
                match server.connect().await {
                    Ok(client) => break client,
                    Err(e) if start.elapsed() >= limit => return Err(e.into()),
                    Err(_) => tokio::time::sleep(Duration::from_millis(100)).await,
                }
            };
            client.wait_until_serving(limit.saturating_sub(start.elapsed())).await?;
            client.health().await?
        }
    };
    print(json_mode, json!({"status": status.as_str_name()}), || status.as_str_name().to_string());
    Ok(())
}
