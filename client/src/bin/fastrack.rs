//! `fastrack`: command-line client of the fastrack safety service, one subcommand per RPC, human-readable
//! or `--json` output.

use anyhow::Context;
use clap::{Parser, Subcommand, ValueEnum};
use fastrack_client::load::{run_in_process, run_load, InProcessReport, InProcessSpec, LoadReport, LoadSpec, Workload};
use fastrack_client::{model_ref, pb, ClientOptions, ClientTls, FastrackClient};
use indicatif::{ProgressBar, ProgressStyle};
use serde_json::{json, Value};
use std::path::PathBuf;
use std::time::Duration;

#[derive(Parser)]
#[command(name = "fastrack", version, about = "Client of the fastrack safety service")]
struct Cli {
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
    #[arg(long, env = "FASTRACK_TOKEN", hide_env_values = true, global = true)]
    token: Option<String>,
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
    /// Server health (grpc.health.v1).
    Health,
    /// Lists loaded models.
    Models,
    /// Describes a model: domain, parameters, controls, TEB table.
    Model {
        /// Model name.
        name: String,
        /// Version (0 = latest).
        #[arg(long, default_value_t = 0)]
        version: u32,
    },
    /// queryPlannerControl: the fastest planner speed bound for an obstacle distance.
    Query {
        /// Model name.
        name: String,
        /// Distance to the nearest sensed obstacle (omit when none is sensed).
        #[arg(long)]
        d_obs: Option<f64>,
        /// Version (0 = latest).
        #[arg(long, default_value_t = 0)]
        version: u32,
    },
    /// The tracking error bound at a planner speed bound.
    Teb {
        /// Model name.
        name: String,
        /// Planner speed bound.
        #[arg(long)]
        beta: f64,
        /// Boundary points of the error set to print.
        #[arg(long, default_value_t = 0)]
        boundary: u32,
        /// Version (0 = latest).
        #[arg(long, default_value_t = 0)]
        version: u32,
    },
    /// V, dV/dr and u* for one or more states.
    Evaluate(BatchArgs),
    /// Optimal tracking control for one or more states.
    Control(BatchArgs),
    /// Runs a short scripted robot on a Track stream: the planner drives straight past an obstacle, the
    /// tracker follows with the served control (the model's own dynamics, Euler steps).
    Track {
        /// Model name.
        name: String,
        /// Number of ticks.
        #[arg(long, default_value_t = 40)]
        ticks: u32,
        /// Control period (s).
        #[arg(long, default_value_t = 0.1)]
        dt: f64,
    },
    /// Load generator: closed-loop clients at each concurrency, unary TrackingControl batches or Track
    /// ticks; prints throughput and latency percentiles (and, with --in-process, the ratio to evaluating the
    /// same bundle in this process).
    Load(LoadArgs),
    /// Admin: loads a model from the server's repository.
    LoadModel {
        /// Model name.
        name: String,
        /// Version (0 = every version on disk).
        #[arg(long, default_value_t = 0)]
        version: u32,
    },
    /// Admin: stops serving a model.
    UnloadModel {
        /// Model name.
        name: String,
        /// Version (0 = every version).
        #[arg(long, default_value_t = 0)]
        version: u32,
    },
    /// Admin: re-reads a model (or, without a name, the whole repository) from disk.
    ReloadModel {
        /// Model name.
        name: Option<String>,
    },
}

/// What the load generator's clients send.
#[derive(Clone, Copy, ValueEnum)]
enum WorkloadArg {
    /// Unary TrackingControl calls of --batch items.
    Unary,
    /// Ticks on Track streams, one stream per client.
    Track,
}

#[derive(clap::Args)]
struct LoadArgs {
    /// Model name.
    #[arg(long)]
    model: String,
    /// Version (0 = latest).
    #[arg(long, default_value_t = 0)]
    version: u32,
    /// What each client sends.
    #[arg(long, value_enum, default_value = "unary")]
    workload: WorkloadArg,
    /// Items per unary request.
    #[arg(long, default_value_t = 1, value_parser = clap::value_parser!(u32).range(1..))]
    batch: u32,
    /// Concurrent clients, one run per value, comma separated.
    #[arg(long, value_delimiter = ',', default_value = "1,8,64,256", value_parser = clap::value_parser!(u32).range(1..))]
    concurrency: Vec<u32>,
    /// Measured seconds per run.
    #[arg(long, default_value = "5", value_parser = seconds)]
    duration_s: Duration,
    /// Warm-up seconds before each run's measurement.
    #[arg(long, default_value = "1", value_parser = seconds)]
    warmup_s: Duration,
    /// Seed of the random inputs.
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// Also evaluate this bundle folder (<repository>/<name>/<version>) in-process through ONNX Runtime, as
    /// many threads as cores at the same batch size, and print the server's throughput relative to it.
    #[arg(long)]
    in_process: Option<PathBuf>,
    /// Threads of the in-process evaluation (default: the number of cores).
    #[arg(long, requires = "in_process", value_parser = clap::value_parser!(u32).range(1..))]
    in_process_threads: Option<u32>,
    /// ONNX Runtime library for --in-process (default: $FASTRACK_ORT_LIB, then .cache/onnxruntime).
    #[arg(long, requires = "in_process")]
    ort_lib: Option<PathBuf>,
}

/// A non-negative, finite number of seconds.
fn seconds(text: &str) -> Result<Duration, String> {
    let value: f64 = text.parse().map_err(|e| format!("{e}"))?;
    Duration::try_from_secs_f64(value).map_err(|_| format!("{value} is not a finite number of seconds >= 0"))
}

#[derive(clap::Args)]
struct BatchArgs {
    /// Model name.
    name: String,
    /// A relative state, comma separated; repeat for a batch.
    #[arg(long = "state", value_delimiter = ',', num_args = 1, action = clap::ArgAction::Append, required = true, allow_hyphen_values = true)]
    states: Vec<f64>,
    /// Parameters of every item, comma separated (default: every parameter = --beta).
    #[arg(long, value_delimiter = ',')]
    params: Option<Vec<f64>>,
    /// Shorthand: every parameter of every item equal to this beta.
    #[arg(long)]
    beta: Option<f64>,
    /// Evaluate states outside the trained domain, flagged, instead of rejecting them.
    #[arg(long)]
    allow_out_of_domain: bool,
    /// Version (0 = latest).
    #[arg(long, default_value_t = 0)]
    version: u32,
}

fn print(json_mode: bool, value: Value, text: impl FnOnce() -> String) {
    if json_mode {
        println!("{}", serde_json::to_string_pretty(&value).expect("JSON serialises"));
    } else {
        println!("{}", text());
    }
}

fn model_json(m: &pb::ModelInfo) -> Value {
    json!({
        "name": m.name, "version": m.version, "system": m.system, "description": m.description,
        "untrained": m.untrained, "default_version": m.is_default_version, "horizon": m.horizon,
        "state": m.state.iter().map(|d| json!({"name": d.name, "unit": d.unit,
            "min": d.bounds.map(|b| b.min), "max": d.bounds.map(|b| b.max), "periodic": d.periodic,
            "error_coordinate": d.error_coordinate,
            "limits": d.limits.map(|l| [l.min, l.max])})).collect::<Vec<_>>(),
        "params": m.params.iter().map(|p| json!({"name": p.name, "unit": p.unit,
            "min": p.range.map(|r| r.min), "max": p.range.map(|r| r.max)})).collect::<Vec<_>>(),
        "controls": m.controls.iter().map(|c| json!({"name": c.name, "unit": c.unit,
            "min": c.bounds.map(|b| b.min), "max": c.bounds.map(|b| b.max)})).collect::<Vec<_>>(),
        "teb_table": m.teb_table.iter().map(|r| json!({"beta": r.beta, "level": r.level,
            "learned_level": r.learned_level, "verified_level": r.verified_level, "extent": r.extent})).collect::<Vec<_>>(),
        "onnx_sha256": m.onnx_sha256,
    })
}

fn model_text(m: &pb::ModelInfo) -> String {
    let mut out = format!(
        "{}/{}{} — system {}{}\n  {}\n  horizon {} s\n  state:",
        m.name,
        m.version,
        if m.is_default_version { " (default)" } else { "" },
        m.system,
        if m.untrained { " — UNTRAINED (random weights, bounds meaningless)" } else { "" },
        m.description,
        m.horizon
    );
    for d in &m.state {
        let b = d.bounds.unwrap_or_default();
        out += &format!(
            "\n    {:<8} [{}, {}] {}{}{}",
            d.name,
            b.min,
            b.max,
            d.unit,
            if d.periodic { " periodic" } else { "" },
            d.limits.map_or(String::new(), |l| format!(", control held within [{}, {}]", l.min, l.max))
        );
    }
    out += "\n  params:";
    for p in &m.params {
        let r = p.range.unwrap_or_default();
        out += &format!("\n    {:<8} [{}, {}] {}", p.name, r.min, r.max, p.unit);
    }
    out += "\n  TEB table:\n    beta      level    learned  verified";
    for r in &m.teb_table {
        let verified = r.verified_level.map_or("-".to_string(), |v| format!("{v:.4}"));
        out += &format!("\n    {:<8.4}  {:<7.4}  {:<7.4}  {verified}", r.beta, r.level, r.learned_level);
    }
    out
}

async fn batch(client: &FastrackClient, args: BatchArgs, control_only: bool, json_mode: bool) -> anyhow::Result<()> {
    let info = client.get_model(model_ref(&args.name, args.version)).await?;
    let (ns, np, nc) = (info.state.len(), info.params.len(), info.controls.len());
    anyhow::ensure!(args.states.len().is_multiple_of(ns), "each --state needs {ns} numbers");
    let n = args.states.len() / ns;
    let params = match (args.params, args.beta) {
        (Some(p), _) => p.iter().copied().cycle().take(n * p.len().max(1)).collect::<Vec<_>>(),
        (None, Some(beta)) => vec![beta; n * np],
        (None, None) => anyhow::bail!("give --params or --beta"),
    };
    let policy = if args.allow_out_of_domain { pb::OutOfDomainPolicy::Flag } else { pb::OutOfDomainPolicy::Reject };
    let model = model_ref(&args.name, args.version);
    if control_only {
        let r = client.tracking_control(model, args.states.clone(), params, policy).await?;
        print(
            json_mode,
            json!({"controls": r.controls, "values": r.values, "in_teb": r.in_teb, "in_domain": r.in_domain, "model_version": r.model_version}),
            || {
                (0..n)
                    .map(|i| {
                        format!(
                            "state {:?}: u* = {:?}  V = {:.4}  in_teb = {}  in_domain = {}",
                            &args.states[i * ns..(i + 1) * ns],
                            &r.controls[i * nc..(i + 1) * nc],
                            r.values[i],
                            r.in_teb[i],
                            r.in_domain[i]
                        )
                    })
                    .collect::<Vec<_>>()
                    .join("\n")
            },
        );
    } else {
        let r = client.evaluate_value(model, args.states.clone(), params, policy).await?;
        print(
            json_mode,
            json!({"values": r.values, "gradients": r.gradients, "controls": r.controls, "in_teb": r.in_teb, "in_domain": r.in_domain, "model_version": r.model_version}),
            || {
                (0..n)
                    .map(|i| {
                        format!(
                            "state {:?}: V = {:.4}  dV/dr = {:?}  u* = {:?}  in_teb = {}  in_domain = {}",
                            &args.states[i * ns..(i + 1) * ns],
                            r.values[i],
                            &r.gradients[i * ns..(i + 1) * ns],
                            &r.controls[i * nc..(i + 1) * nc],
                            r.in_teb[i],
                            r.in_domain[i]
                        )
                    })
                    .collect::<Vec<_>>()
                    .join("\n")
            },
        );
    }
    Ok(())
}

/// The scripted robot of `fastrack track`: planner from the origin along +y at `beta_query` per axis, an
/// obstacle disc at (1.2, 2.5) of radius 0.3, the tracker stepped with the model system's dynamics.
async fn scripted_track(
    client: &FastrackClient,
    name: &str,
    ticks: u32,
    dt: f64,
    json_mode: bool,
) -> anyhow::Result<()> {
    let info = client.get_model(model_ref(name, 0)).await?;
    let system = fastrack_valuefn::system::by_id(&info.system)
        .with_context(|| format!("no dynamics known for system {:?}", info.system))?;
    anyhow::ensure!(
        system.planner_dim() == 2 && system.n_state() == 4,
        "the scripted robot drives 2-D planners with 4-D trackers (dubins4d)"
    );
    let (obstacle, obstacle_radius): ([f64; 2], f64) = ([1.2, 2.5], 0.3);
    let mut tracker: Vec<f64> = vec![0.0, 0.0, 0.0, 1.0];
    let mut planner = vec![0.0, 0.0];
    let mut session = client.track(model_ref(name, 0), 10.0).await?;
    let mut rows = Vec::new();
    if !json_mode {
        println!("  t      beta   dTEB    |e|     V       in_teb  in_domain  omega   alpha");
    }
    for seq in 0..u64::from(ticks) {
        let d_obs = ((tracker[0] - obstacle[0]).hypot(tracker[1] - obstacle[1]) - obstacle_radius).max(0.0);
        let reply = session
            .tick(pb::TrackTick {
                seq,
                tracker_state: tracker.clone(),
                planner_state: planner.clone(),
                d_obs: Some(d_obs),
            })
            .await?;
        if let Some(error) = &reply.error {
            anyhow::bail!("tick {seq} rejected ({}): {}", error.code, error.message);
        }
        let error = reply.relative_state[0].hypot(reply.relative_state[1]);
        let t = seq as f64 * dt;
        if json_mode {
            rows.push(json!({"t": t, "beta_query": reply.beta_query, "dteb_radius": reply.dteb_radius, "error": error,
                "value": reply.value, "in_teb": reply.in_teb, "in_domain": reply.in_domain, "control": reply.control}));
        } else {
            println!(
                "  {t:<5.2}  {:<5.3}  {:<6.3}  {error:<6.3}  {:<6.3}  {:<6}  {:<9}  {:<6.2}  {:.2}",
                reply.beta_query,
                reply.dteb_radius,
                reply.value,
                reply.in_teb,
                reply.in_domain,
                reply.control[0],
                reply.control[1]
            );
        }
        let mut rate = vec![0.0; 4];
        system.dynamics(&tracker, &reply.control, &[0.0, 0.0], &[], &mut rate);
        // The tracker's own motion is the relative dynamics with a resting planner.
        for (s, r) in tracker.iter_mut().zip(&rate) {
            *s += dt * r;
        }
        planner[1] += dt * reply.beta_query;
    }
    if json_mode {
        println!("{}", serde_json::to_string_pretty(&rows)?);
    }
    Ok(())
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
    Ok(ClientOptions { connect_timeout: timeout, request_timeout: timeout, bearer_token: cli.token.clone(), tls })
}

#[tokio::main]
async fn main() -> anyhow::Result<()> {
    let cli = Cli::parse();
    let options = client_options(&cli)?;
    let j = cli.json;
    let client = FastrackClient::connect(&cli.server, options.clone()).await?;
    match cli.command {
        Command::Health => {
            let status = client.health().await?;
            print(j, json!({"status": status.as_str_name()}), || status.as_str_name().to_string());
        }
        Command::Models => {
            let models = client.list_models().await?;
            print(j, Value::Array(models.iter().map(model_json).collect()), || {
                models
                    .iter()
                    .map(|m| {
                        format!(
                            "{}/{}{}  {}{}",
                            m.name,
                            m.version,
                            if m.is_default_version { "*" } else { " " },
                            m.system,
                            if m.untrained { "  UNTRAINED" } else { "" }
                        )
                    })
                    .collect::<Vec<_>>()
                    .join("\n")
            });
        }
        Command::Model { name, version } => {
            let m = client.get_model(model_ref(&name, version)).await?;
            print(j, model_json(&m), || model_text(&m));
        }
        Command::Query { name, d_obs, version } => {
            let r = client.query_planner_control(model_ref(&name, version), d_obs).await?;
            print(
                j,
                json!({"beta_query": r.beta_query, "dteb_radius": r.dteb_radius, "steb_radius": r.steb_radius,
                       "steb_exceeds_half_distance": r.steb_exceeds_half_distance, "model_version": r.model_version}),
                || {
                    format!(
                        "beta_query = {:.4}  dTEB radius = {:.4}  sTEB radius = {:.4}{}",
                        r.beta_query,
                        r.dteb_radius,
                        r.steb_radius,
                        if r.steb_exceeds_half_distance { "  (sTEB exceeds d_obs/2: slowest speed)" } else { "" }
                    )
                },
            );
        }
        Command::Teb { name, beta, boundary, version } => {
            let r = client.tracking_error_bound(model_ref(&name, version), beta, boundary).await?;
            print(
                j,
                json!({"level": r.level, "radius": r.radius, "extent": r.extent, "table_beta": r.table_beta, "boundary": r.boundary, "model_version": r.model_version}),
                || {
                    let mut s = format!(
                        "level = {:.4}  radius = {:.4}  extent = {:?}  (table beta {:.4})",
                        r.level, r.radius, r.extent, r.table_beta
                    );
                    for p in r.boundary.chunks(r.extent.len().max(1)) {
                        s += &format!("\n  {p:?}");
                    }
                    s
                },
            );
        }
        Command::Evaluate(args) => batch(&client, args, false, j).await?,
        Command::Control(args) => batch(&client, args, true, j).await?,
        Command::Track { name, ticks, dt } => scripted_track(&client, &name, ticks, dt, j).await?,
        Command::Load(args) => load(&cli.server, &options, args, j).await?,
        Command::LoadModel { name, version } => {
            let v = client.load_model(&name, version).await?;
            print(j, json!({"loaded_versions": v}), || format!("{name}: loaded versions {v:?}"));
        }
        Command::UnloadModel { name, version } => {
            let v = client.unload_model(&name, version).await?;
            print(j, json!({"unloaded_versions": v}), || format!("{name}: unloaded versions {v:?}"));
        }
        Command::ReloadModel { name } => {
            let outcomes = client.reload_model(name.as_deref().unwrap_or_default()).await?;
            print(
                j,
                Value::Array(
                    outcomes
                        .iter()
                        .map(|o| json!({"name": o.name, "version": o.version, "loaded": o.loaded, "error": o.error}))
                        .collect(),
                ),
                || {
                    outcomes
                        .iter()
                        .map(|o| {
                            format!(
                                "{}/{}: {}",
                                o.name,
                                o.version,
                                if o.loaded { "loaded".to_string() } else { format!("rejected: {}", o.error) }
                            )
                        })
                        .collect::<Vec<_>>()
                        .join("\n")
                },
            );
        }
    }
    Ok(())
}

/// `fastrack load`: one run per concurrency, then the in-process ceiling if asked; a table or JSON.
async fn load(server: &str, options: &ClientOptions, args: LoadArgs, json_mode: bool) -> anyhow::Result<()> {
    let workload = match args.workload {
        WorkloadArg::Unary => Workload::Unary { batch: args.batch as usize },
        WorkloadArg::Track => Workload::Track,
    };
    let style = ProgressStyle::with_template("{prefix:>16} [{bar:30}] {msg}")?.progress_chars("=> ");
    let mut reports = Vec::with_capacity(args.concurrency.len());
    for &concurrency in &args.concurrency {
        let spec = LoadSpec {
            model: model_ref(&args.model, args.version),
            workload,
            concurrency: concurrency as usize,
            duration: args.duration_s,
            warmup: args.warmup_s,
            seed: args.seed,
        };
        let bar = ProgressBar::new(0).with_style(style.clone()).with_prefix(format!("concurrency {concurrency}"));
        reports.push(run_load(server, options, &spec, Some(bar)).await?);
    }
    let ceiling = match args.in_process {
        Some(bundle_dir) => {
            let threads = match args.in_process_threads {
                Some(t) => t as usize,
                None => std::thread::available_parallelism().map_or(1, |n| n.get()),
            };
            let spec = InProcessSpec {
                bundle_dir,
                batch: workload.items_per_request(),
                threads,
                duration: args.duration_s,
                warmup: args.warmup_s,
                ort_lib: args.ort_lib,
                seed: args.seed,
            };
            let spinner =
                ProgressBar::new_spinner().with_message(format!("in-process: {threads} threads, batch {}", spec.batch));
            spinner.enable_steady_tick(Duration::from_millis(100));
            let report = tokio::task::spawn_blocking(move || run_in_process(&spec))
                .await
                .context("the in-process evaluation thread failed")??;
            spinner.finish_and_clear();
            Some(report)
        }
        None => None,
    };
    let ratio = |r: &LoadReport| ceiling.as_ref().map(|c| r.items_per_s() / c.items_per_s());
    let title = format!(
        "{} (version {}), {workload}, {:?} per run after {:?} warm-up",
        args.model,
        if args.version == 0 { "default".to_string() } else { args.version.to_string() },
        args.duration_s,
        args.warmup_s
    );
    print(
        json_mode,
        json!({
            "server": server, "model": args.model, "version": args.version, "workload": workload.to_string(),
            "runs": reports.iter().map(|r| {
                let mut row = r.to_json();
                row["vs_in_process"] = json!(ratio(r));
                row
            }).collect::<Vec<_>>(),
            "in_process": ceiling.as_ref().map(InProcessReport::to_json),
        }),
        || {
            let mut header = vec![
                "concurrency",
                "connections",
                "requests",
                "requests/s",
                "items/s",
                "p50 ms",
                "p90 ms",
                "p99 ms",
                "max ms",
                "errors",
            ];
            if ceiling.is_some() {
                header.push("vs in-process");
            }
            let ms = |d: Duration| format!("{:.2}", d.as_secs_f64() * 1e3);
            let rows: Vec<Vec<String>> = reports
                .iter()
                .map(|r| {
                    let mut row = vec![
                        r.concurrency.to_string(),
                        r.connections.to_string(),
                        r.requests.to_string(),
                        format!("{:.0}", r.requests_per_s()),
                        format!("{:.0}", r.items_per_s()),
                        ms(r.latency.p50),
                        ms(r.latency.p90),
                        ms(r.latency.p99),
                        ms(r.latency.max),
                        errors_text(r),
                    ];
                    if let Some(x) = ratio(r) {
                        row.push(format!("{x:.3}"));
                    }
                    row
                })
                .collect();
            let mut text = format!("{title}\n{}", aligned(&header, &rows));
            if let Some(c) = &ceiling {
                text += &format!(
                    "\nin-process ceiling: {:.0} items/s ({} threads, batch {}, {} evaluations)",
                    c.items_per_s(),
                    c.threads,
                    c.batch,
                    c.evaluations
                );
            }
            text
        },
    );
    Ok(())
}

/// "0", or the total and the count per gRPC code.
fn errors_text(report: &LoadReport) -> String {
    if report.errors.is_empty() {
        return "0".into();
    }
    let by_code: Vec<String> = report.errors.iter().map(|(code, n)| format!("{code:?} {n}")).collect();
    format!("{} ({})", report.error_count(), by_code.join(", "))
}

/// A text table, right-aligned columns.
fn aligned(header: &[&str], rows: &[Vec<String>]) -> String {
    let mut widths: Vec<usize> = header.iter().map(|h| h.len()).collect();
    for row in rows {
        for (w, cell) in widths.iter_mut().zip(row) {
            *w = (*w).max(cell.len());
        }
    }
    let line =
        |cells: Vec<&str>| cells.iter().zip(&widths).map(|(c, w)| format!("{c:>w$}")).collect::<Vec<_>>().join("  ");
    let mut lines = vec![line(header.to_vec())];
    lines.extend(rows.iter().map(|r| line(r.iter().map(String::as_str).collect())));
    lines.join("\n")
}
