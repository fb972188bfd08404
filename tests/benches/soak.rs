//! Soak benchmark: one server under hours-like churn. `ROBOTS` robots tick their `Track` streams every control
//! period while unary clients send `TrackingControl` batches; every minute an admin reloads the model, and
//! every few seconds a robot is killed (its task aborted mid-stream, the connection's stream reset) and a new
//! one takes its place. Per minute: the server's resident memory, its open streams, ticks answered, the p99
//! tick latency and every error that was not injected. Memory must stay flat after the warm-up (the first
//! third of the run: growth under 5 %) and no error may occur; the record (`bench/results/soak.{json,md}` and two figures) is written
//! either way, and the bench fails afterwards if either holds not.
//!
//! Run: `cargo build --release --bins && cargo bench -p fastrack-e2e --bench soak` (30 minutes;
//! `FASTRACK_SOAK_MINUTES` sets another length, e.g. 2 for a try).

use fastrack_client::{model_ref, ClientOptions, FastrackClient};
use fastrack_e2e::{robot_tick, TestServer};
use fastrack_lab::plot::{line_chart, Chart, Series};
use fastrack_lab::record::{write_record, MarkdownTable};
use rand::{Rng, SeedableRng};
use serde_json::json;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

const MODEL: &str = "dubins4d";
const ROBOTS: usize = 100;
const CONTROL_PERIOD: Duration = Duration::from_millis(20);
const UNARY_CLIENTS: usize = 4;
const UNARY_BATCH: usize = 64;
const UNARY_PERIOD: Duration = Duration::from_millis(50);
const RELOAD_EVERY: Duration = Duration::from_secs(60);
const KILL_EVERY: Duration = Duration::from_secs(5);
/// The warm-up is the first third of the run, at least this long: memory settles over the first reloads
/// and the largest merged batches (the allocator's and ONNX Runtime's arenas grow to their peak and keep
/// it); a 30-minute run settled by its twelfth minute (60.7-63.2 MiB from then on).
const MIN_WARMUP_MINUTES: usize = 2;
/// Memory growth allowed from the end of the warm-up to the end of the run.
const MAX_GROWTH: f64 = 0.05;

/// What the load did during the current minute; taken and reset once a minute.
#[derive(Default)]
struct Minute {
    tick_latencies_us: Vec<u64>,
    unary_calls: u64,
    errors: Vec<String>,
}

#[derive(Default)]
struct Shared {
    minute: Mutex<Minute>,
    kills: AtomicU64,
    reloads: AtomicU64,
}

impl Shared {
    fn with<T>(&self, f: impl FnOnce(&mut Minute) -> T) -> T {
        f(&mut self.minute.lock().unwrap_or_else(|e| e.into_inner()))
    }

    fn error(&self, what: String) {
        self.with(|m| m.errors.push(what));
    }
}

/// A robot ticking its stream every control period until its task is aborted (a kill) or an error ends it.
async fn robot(client: FastrackClient, robot: u64, shared: Arc<Shared>) {
    let mut stream = match client.track(model_ref(MODEL, 0), 0.0).await {
        Ok(stream) => stream,
        Err(e) => return shared.error(format!("robot {robot}: opening its stream: {e}")),
    };
    let mut ticker = tokio::time::interval(CONTROL_PERIOD);
    for seq in 0.. {
        ticker.tick().await;
        let sent = Instant::now();
        match stream.tick(robot_tick(seq, robot)).await {
            Ok(reply) if reply.error.is_none() && reply.seq == seq => {
                let us = sent.elapsed().as_micros() as u64;
                shared.with(|m| m.tick_latencies_us.push(us));
            }
            Ok(reply) => return shared.error(format!("robot {robot} tick {seq}: {reply:?}")),
            Err(e) => return shared.error(format!("robot {robot} tick {seq}: {e}")),
        }
    }
}

/// A unary client sending `TrackingControl` batches every `UNARY_PERIOD`.
async fn unary(client: FastrackClient, id: u64, shared: Arc<Shared>) {
    let mut ticker = tokio::time::interval(UNARY_PERIOD);
    for call in 0u64.. {
        ticker.tick().await;
        let states: Vec<f64> = (0..UNARY_BATCH as u64).flat_map(|k| robot_tick(call + k, id).tracker_state).collect();
        let params = vec![1.0; UNARY_BATCH];
        let answer = client.tracking_control(model_ref(MODEL, 0), states, params, Default::default()).await;
        match answer {
            Ok(_) => shared.with(|m| m.unary_calls += 1),
            Err(e) => shared.error(format!("unary client {id} call {call}: {e}")),
        }
    }
}

fn p99_ms(latencies: &mut [u64]) -> f64 {
    latencies.sort_unstable();
    latencies.get(latencies.len() * 99 / 100).map_or(f64::NAN, |&us| us as f64 / 1e3)
}

/// A fresh copy of the shipped model's repository, so that reloads read real files.
fn repository() -> anyhow::Result<tempfile::TempDir> {
    let repo = tempfile::tempdir()?;
    let shipped = Path::new(env!("CARGO_MANIFEST_DIR")).join("../models").join(MODEL);
    let version = std::fs::read_dir(&shipped)?.filter_map(|e| e.ok()).map(|e| e.path()).max().expect("a version");
    let target = repo.path().join(MODEL).join(version.file_name().expect("a version folder"));
    std::fs::create_dir_all(&target)?;
    for file in ["manifest.json", "model.onnx"] {
        std::fs::copy(version.join(file), target.join(file))?;
    }
    Ok(repo)
}

struct Row {
    minute: usize,
    rss_mib: f64,
    open_streams: f64,
    ticks: usize,
    unary_calls: u64,
    p99_ms: f64,
    errors: usize,
}

async fn soak(minutes: usize) -> anyhow::Result<(Vec<Row>, Vec<String>, u64, u64)> {
    let repo = repository()?;
    let (server, admin) = TestServer::start_observed(repo.path(), &["--poll-interval-s", "0"]).await;
    let options = ClientOptions { request_timeout: Duration::from_secs(5), ..Default::default() };
    let client = FastrackClient::connect(&server.endpoint, options).await?;
    let shared = Arc::new(Shared::default());
    let mut robots: Vec<tokio::task::JoinHandle<()>> =
        (0..ROBOTS).map(|r| tokio::spawn(robot(client.clone(), r as u64, Arc::clone(&shared)))).collect();
    let unaries: Vec<_> =
        (0..UNARY_CLIENTS).map(|u| tokio::spawn(unary(client.clone(), 1000 + u as u64, Arc::clone(&shared)))).collect();

    let mut rng = rand::rngs::StdRng::seed_from_u64(17);
    let (start, mut next_robot) = (Instant::now(), ROBOTS as u64);
    let (mut last_kill, mut last_reload) = (start, start);
    let (mut rows, mut errors) = (Vec::new(), Vec::new());
    let progress = indicatif::ProgressBar::new(minutes as u64);
    for minute in 1..=minutes {
        while start.elapsed() < Duration::from_secs(60 * minute as u64) {
            tokio::time::sleep(Duration::from_millis(250)).await;
            if last_kill.elapsed() >= KILL_EVERY {
                last_kill = Instant::now();
                let victim = rng.random_range(0..robots.len());
                robots[victim].abort();
                robots[victim] = tokio::spawn(robot(client.clone(), next_robot, Arc::clone(&shared)));
                next_robot += 1;
                shared.kills.fetch_add(1, Ordering::Relaxed);
            }
            if last_reload.elapsed() >= RELOAD_EVERY {
                last_reload = Instant::now();
                match admin.reload_model(MODEL).await {
                    Ok(outcomes) if outcomes.iter().all(|o| o.loaded) => {
                        shared.reloads.fetch_add(1, Ordering::Relaxed);
                    }
                    other => shared.error(format!("reload at {:?}: {other:?}", start.elapsed())),
                }
            }
        }
        let mut done = shared.with(std::mem::take);
        let row = Row {
            minute,
            rss_mib: server.rss_kib() as f64 / 1024.0,
            open_streams: server.metric("fastrack_active_streams").await,
            ticks: done.tick_latencies_us.len(),
            unary_calls: done.unary_calls,
            p99_ms: p99_ms(&mut done.tick_latencies_us),
            errors: done.errors.len(),
        };
        // Printed beside the bar, and also where there is no terminal to draw it on.
        progress.suspend(|| {
            println!(
                "minute {minute}: RSS {:.1} MiB, {} streams open, {} ticks (p99 {:.2} ms), {} unary calls, {} errors",
                row.rss_mib, row.open_streams, row.ticks, row.p99_ms, row.unary_calls, row.errors
            )
        });
        progress.inc(1);
        errors.extend(done.errors);
        rows.push(row);
    }
    progress.finish_and_clear();
    for task in robots.iter().chain(&unaries) {
        task.abort();
    }
    Ok((rows, errors, shared.kills.load(Ordering::Relaxed), shared.reloads.load(Ordering::Relaxed)))
}

fn figures(dir: &Path, rows: &[Row]) -> Vec<PathBuf> {
    let series = |label: &str, y: &dyn Fn(&Row) -> f64| Series {
        label: label.into(),
        points: rows.iter().map(|r| (r.minute as f64, y(r))).collect(),
        markers: false,
    };
    let mut written = Vec::new();
    for (file, title, y_label, s) in [
        ("soak-memory.png", "Server memory under churn", "resident memory (MiB)", series("RSS", &|r| r.rss_mib)),
        ("soak-latency.png", "Track tick latency under churn", "p99 per minute (ms)", series("p99", &|r| r.p99_ms)),
    ] {
        let path = dir.join(file);
        let chart = Chart { title, x_label: "minute", y_label, log_y: false };
        match line_chart(&path, &chart, &[s]) {
            Ok(()) => written.push(path),
            Err(e) => eprintln!("{file}: {e}"),
        }
    }
    written
}

fn main() -> anyhow::Result<()> {
    let minutes: usize = std::env::var("FASTRACK_SOAK_MINUTES").ok().and_then(|v| v.parse().ok()).unwrap_or(30);
    let warmup = (minutes / 3).max(MIN_WARMUP_MINUTES);
    anyhow::ensure!(minutes > warmup, "FASTRACK_SOAK_MINUTES must be more than {MIN_WARMUP_MINUTES} (the warm-up)");
    let binary = fastrack_e2e::server_binary();
    let profile = binary.parent().and_then(Path::file_name).map_or("?".into(), |p| p.to_string_lossy().into_owned());
    let rt = tokio::runtime::Builder::new_multi_thread().enable_all().build()?;
    let (rows, errors, kills, reloads) = rt.block_on(soak(minutes))?;

    let warm = rows[warmup - 1].rss_mib;
    let last = rows.last().expect("more minutes than the warm-up").rss_mib;
    let growth = last / warm - 1.0;
    let mut table = MarkdownTable::new(&[
        "minute",
        "RSS (MiB)",
        "open streams",
        "ticks",
        "tick p99 (ms)",
        "unary calls",
        "errors (not injected)",
    ]);
    for r in &rows {
        table.row(vec![
            r.minute.to_string(),
            format!("{:.1}", r.rss_mib),
            format!("{:.0}", r.open_streams),
            r.ticks.to_string(),
            format!("{:.2}", r.p99_ms),
            r.unary_calls.to_string(),
            r.errors.to_string(),
        ]);
    }
    let out = Path::new(env!("CARGO_MANIFEST_DIR")).join("../bench/results");
    std::fs::create_dir_all(&out)?;
    let out = out.canonicalize()?;
    let plots = figures(&out, &rows);
    let command = match profile.as_str() {
        "release" => format!("cargo bench -p fastrack-e2e --bench soak (FASTRACK_SOAK_MINUTES={minutes})"),
        other => format!("cargo bench --profile dev -p fastrack-e2e --bench soak (FASTRACK_SOAK_MINUTES={minutes}, server from target/{other})"),
    };
    let path = write_record(
        &out,
        "soak",
        &command,
        json!({
            "model": MODEL, "minutes": minutes, "robots": ROBOTS, "control_period_ms": CONTROL_PERIOD.as_millis(),
            "unary_clients": UNARY_CLIENTS, "unary_batch": UNARY_BATCH, "unary_period_ms": UNARY_PERIOD.as_millis(),
            "reload_every_s": RELOAD_EVERY.as_secs(), "kill_every_s": KILL_EVERY.as_secs(),
            "server": format!("target/{profile}/fastrack-server, defaults, polling off; the load on this machine"),
        }),
        json!({
            "warmup_minutes": warmup, "rss_mib_after_warmup": warm, "rss_mib_at_end": last, "growth": growth, "max_growth": MAX_GROWTH,
            "kills": kills, "reloads": reloads, "unexpected_errors": errors.len(), "first_errors": errors.iter().take(10).collect::<Vec<_>>(),
            "ticks": rows.iter().map(|r| r.ticks).sum::<usize>(),
            "figures": plots.iter().filter_map(|p| p.file_name()).map(|f| f.to_string_lossy().into_owned()).collect::<Vec<_>>(),
        }),
        &[("per minute", &table)],
    )?;
    println!(
        "{}\nRSS {warm:.1} -> {last:.1} MiB ({:+.1} %), {kills} robots killed, {reloads} reloads, {} unexpected errors; record {}",
        table.to_markdown(),
        100.0 * growth,
        errors.len(),
        path.display()
    );
    anyhow::ensure!(errors.is_empty(), "{} errors that were not injected, first: {}", errors.len(), errors[0]);
    anyhow::ensure!(growth < MAX_GROWTH, "memory grew {:.1} % after the warm-up", 100.0 * growth);
    Ok(())
}
