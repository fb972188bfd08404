//! `fastrack-server`: the gRPC safety service binary.

use anyhow::Context;
use clap::Parser;
use fastrack_server::settings::{LogFormat, Options, Settings};

#[tokio::main]
async fn main() -> anyhow::Result<()> {
    let cli = Options::parse();
    let options = match &cli.config {
        Some(path) => {
            let file = Options::from_file(path)?;
            cli.over(file)
        }
        None => cli,
    };
    let settings = Settings::resolve(options).context("invalid settings")?;
    let filter = tracing_subscriber::EnvFilter::try_new(&settings.log_level)
        .map_err(|e| anyhow::anyhow!("log_level {:?} is not a valid filter: {e}", settings.log_level))?;
    let ansi = std::io::IsTerminal::is_terminal(&std::io::stderr());
    let logs = tracing_subscriber::fmt().with_env_filter(filter).with_writer(std::io::stderr).with_ansi(ansi);
    match settings.log_format {
        LogFormat::Text => logs.init(),
        LogFormat::Json => logs.json().with_current_span(true).with_span_list(false).init(),
    }
    fastrack_server::run(settings).await
}
