//! Subcommands of `fastrack`, one file each, and the global flags they share.

mod describe;
mod evaluate;
mod health_check;
mod load;
mod model_admin;
mod query;
mod scripted_track;
mod sim;
mod tracking_error_bound;

use anyhow::Context;
use clap::{Parser, Subcommand};
use fastrack_client::{ClientOptions, ClientTls, FastrackClient};
use serde_json::Value;
use std::path::PathBuf;
use std::time::Duration;

/// Command line of `fastrack`.
#[derive(Parser)]
#[command(name = "fastrack", version, about = "Client of the fastrack safety service")]
pub struct Cli {
    /// Server address.
    #[arg(long, env = "FASTRACK_SERVER", default_value = "http://127.0.0.1:50051", global = true)]
    server: String,
    /// Per-call deadline in milliseconds.
    #[arg(long, default_value_t = 5000, global = true)]
    timeout_ms: u64,
    /// Print JSON instead of text.
    #[arg(long, global = true)]
    json: bool,
    /// Bearer token sent as `authorization: Bearer <token>` on every call.
    #[arg(long, env = "FASTRACK_TOKEN", hide_env_values = true, global = true, conflicts_with = "token_file")]
    token: Option<String>,
    /// File holding the bearer token and nothing else (e.g. a mounted Secret key), instead of --token.
    #[arg(long, env = "FASTRACK_TOKEN_FILE", global = true)]
    token_file: Option<PathBuf>,
    /// PEM file of the CA that signed the server's certificate: connect with TLS (the server address must
    /// start with https://).
    #[arg(long, global = true)]
    tls_ca: Option<PathBuf>,
    /// PEM file of the client certificate, for mutual TLS (with --tls-key).
    #[arg(long, global = true, requires = "tls_key")]
    tls_cert: Option<PathBuf>,
    /// PEM file of the client certificate's private key, for mutual TLS (with --tls-cert).
    #[arg(long, global = true, requires = "tls_cert")]
    tls_key: Option<PathBuf>,
    /// Server name to verify the certificate against (default: the server address's host).
    #[arg(long, global = true)]
    tls_domain: Option<String>,
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Server health (grpc.health.v1); with --wait-s, waits for SERVING.
    Health(health_check::Args),
    /// Lists loaded models.
    Models,
    /// Describes a model: domain, parameters, controls, TEB table.
    Model(describe::ModelArgs),
    /// queryPlannerControl: the fastest planner speed bound for an obstacle distance.
    Query(query::Args),
    /// The tracking error bound at a planner speed bound.
    Teb(tracking_error_bound::Args),
    /// V, dV/dr and u* for one or more states.
    Evaluate(evaluate::Args),
    /// Optimal tracking control for one or more states.
    Control(evaluate::Args),
    /// Runs a short scripted robot on a Track stream: the planner drives straight past an obstacle, the
    /// tracker follows with the served control (the model's own dynamics, Euler steps).
    Track(scripted_track::Args),
    /// Load generator: closed-loop clients at each concurrency, unary TrackingControl batches or Track
    /// ticks; prints throughput and latency percentiles.
    Load(load::Args),
    /// The navigation simulator: a robot driven by Parametric FaSTrack (or a baseline) through a world, in
    /// the plane or in space by the model's planner, over this server: run, bench, fleet, world.
    Sim(Box<sim::Args>),
    /// Admin: loads a model from the server's repository.
    LoadModel(model_admin::VersionArgs),
    /// Admin: stops serving a model.
    UnloadModel(model_admin::VersionArgs),
    /// Admin: re-reads a model (or, without a name, the whole repository) from disk.
    ReloadModel(model_admin::ReloadArgs),
}

/// Runs the chosen subcommand.
pub async fn run(cli: Cli) -> anyhow::Result<()> {
    let server = Server { address: cli.server.clone(), options: client_options(&cli)? };
    let json = cli.json;
    match cli.command {
        Command::Health(args) => health_check::run(&server, args, json).await,
        Command::Models => describe::models(&server.connect().await?, json).await,
        Command::Model(args) => describe::model(&server.connect().await?, args, json).await,
        Command::Query(args) => query::run(&server.connect().await?, args, json).await,
        Command::Teb(args) => tracking_error_bound::run(&server.connect().await?, args, json).await,
        Command::Evaluate(args) => evaluate::run(&server.connect().await?, args, evaluate::Output::Full, json).await,
        Command::Control(args) => evaluate::run(&server.connect().await?, args, evaluate::Output::Control, json).await,
        Command::Track(args) => scripted_track::run(&server.connect().await?, args, json).await,
        Command::Load(args) => load::run(&server, args, json).await,
        Command::Sim(args) => sim::run_command(&server, *args, json).await,
        Command::LoadModel(args) => model_admin::load(&server.connect().await?, args, json).await,
        Command::UnloadModel(args) => model_admin::unload(&server.connect().await?, args, json).await,
        Command::ReloadModel(args) => model_admin::reload(&server.connect().await?, args, json).await,
    }
}

/// The server the command talks to, and how.
struct Server {
    /// Its address, e.g. `http://127.0.0.1:50051`.
    address: String,
    /// Deadlines, token and TLS.
    options: ClientOptions,
}

impl Server {
    /// One connection.
    async fn connect(&self) -> Result<FastrackClient, fastrack_client::ClientError> {
        FastrackClient::connect(&self.address, self.options.clone()).await
    }
}

/// Prints `value` as pretty JSON in `--json` mode, else the text.
fn print(json_mode: bool, value: Value, text: impl FnOnce() -> String) {
    if json_mode {
        println!("{}", serde_json::to_string_pretty(&value).expect("JSON serialises"));
    } else {
        println!("{}", text());
    }
}

/// A non-negative, finite number of seconds.
fn seconds(text: &str) -> Result<Duration, String> {
    let value: f64 = text.parse().map_err(|e| format!("{e}"))?;
    Duration::try_from_secs_f64(value).map_err(|_| format!("{value} is not a finite number of seconds >= 0"))
}

/// Connection settings from the global flags (token, TLS files).
fn client_options(cli: &Cli) -> anyhow::Result<ClientOptions> {
    let timeout = Duration::from_millis(cli.timeout_ms);
    let read = |path: &PathBuf| std::fs::read(path).with_context(|| format!("reading {}", path.display()));
    let tls = match (&cli.tls_ca, &cli.tls_cert, &cli.tls_key) {
        (Some(ca), cert, key) => Some(ClientTls {
            ca_pem: read(ca)?,
            identity: match (cert, key) {
                (Some(cert), Some(key)) => Some((read(cert)?, read(key)?)),
                _ => None,
            },
            domain: cli.tls_domain.clone(),
        }),
        (None, None, None) if cli.tls_domain.is_none() => None,
        (None, ..) => anyhow::bail!("--tls-cert, --tls-key and --tls-domain need --tls-ca"),
    };
    let bearer_token = match &cli.token_file {
        Some(path) => {
            let text = String::from_utf8(read(path)?).with_context(|| format!("{} is not UTF-8", path.display()))?;
            let token = text.trim();
            if token.is_empty() || token.contains(char::is_whitespace) {
                anyhow::bail!(
                    "token file {} must hold exactly one token (no spaces or line breaks inside it)",
                    path.display()
                );
            }
            Some(token.to_string())
        }
        None => cli.token.clone(),
    };
    Ok(ClientOptions { connect_timeout: timeout, request_timeout: timeout, bearer_token, tls })
}
