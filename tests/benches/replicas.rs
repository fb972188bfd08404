//! Replicas benchmark: aggregate `Track` ticks/s of the load generator against 1, 2 and 3 release servers on
//! this machine, one client spreading its streams round-robin over them (the replicas share the machine's
//! cores, so the figure shows the overhead of replication rather than scale: per-replica efficiency is
//! `ticks(n) / (n ticks(1))`); and the time from a replica's death (SIGKILL) until every robot that was on it
//! is served again by another, over several trials, with the robots ticking every control period and at full
//! load (each robot's next tick sent as soon as the last is answered: the machine's cores saturated). Prints
//! tables and writes `bench/results/replicas.{json,md}`.
//!
//! Run: `cargo build --release --bins && cargo bench -p fastrack-e2e --bench replicas` (or with `--profile dev`
//! against the dev build's servers, whose dependencies are optimised as well).

use fastrack_cli::load_generator::{run_load, LoadSpec, Workload};
use fastrack_client::{model_ref, ClientOptions, FastrackClient};
use fastrack_e2e::{robot_tick, TestServer};
use fastrack_lab::record::{write_record, MarkdownTable};
use serde_json::json;
use std::path::Path;
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

const MODEL: &str = "dubins4d";
const STREAMS: usize = 64;
const DURATION: Duration = Duration::from_secs(3);
const WARMUP: Duration = Duration::from_millis(500);
/// Robots of each failover trial, each ticking every control period.
const ROBOTS: u64 = 48;
const CONTROL_PERIOD: Duration = Duration::from_millis(10);
const TRIALS: usize = 5;

async fn start(count: usize) -> anyhow::Result<Vec<TestServer>> {
    let models = Path::new(env!("CARGO_MANIFEST_DIR")).join("../models");
    let mut servers = Vec::with_capacity(count);
    for _ in 0..count {
        let (server, _) = TestServer::start_serving(&models).await;
        servers.push(server);
    }
    Ok(servers)
}

fn address(servers: &[TestServer]) -> String {
    servers.iter().map(|s| s.endpoint.as_str()).collect::<Vec<_>>().join(",")
}

/// Aggregate ticks/s of `STREAMS` closed-loop streams over `count` replicas.
async fn throughput(count: usize) -> anyhow::Result<f64> {
    let servers = start(count).await?;
    let spec = LoadSpec {
        model: model_ref(MODEL, 0),
        workload: Workload::Track,
        concurrency: STREAMS,
        duration: DURATION,
        warmup: WARMUP,
        seed: 7,
    };
    let options = ClientOptions { request_timeout: Duration::from_secs(10), ..Default::default() };
    let report = run_load(&address(&servers), &options, &spec, None).await?;
    anyhow::ensure!(report.error_count() == 0, "{count} replicas: {} errors", report.error_count());
    Ok(report.items_per_s())
}

/// One trial: `ROBOTS` robots tick over 3 replicas, every `period` (none: as fast as they are answered, for
/// as long as the paced robots run); one replica is killed; returns how many robots were on it and, for
/// each, the time from the kill to its next reply.
async fn failover(period: Option<Duration>) -> anyhow::Result<(usize, Vec<Duration>)> {
    let mut servers = start(3).await?;
    let client = FastrackClient::connect(&address(&servers), ClientOptions::default()).await?;
    let killed_at: Arc<Mutex<Option<Instant>>> = Arc::default();
    let mut robots = Vec::new();
    for robot in 0..ROBOTS {
        let (client, killed_at) = (client.clone(), Arc::clone(&killed_at));
        robots.push(tokio::spawn(async move {
            let mut stream = client.track(model_ref(MODEL, 0), 0.0).await?;
            let mut ticker = tokio::time::interval(period.unwrap_or(CONTROL_PERIOD));
            let end = Instant::now() + CONTROL_PERIOD * 300;
            for seq in 0.. {
                if Instant::now() > end {
                    break;
                }
                if period.is_some() {
                    ticker.tick().await;
                }
                let moved = stream.reopened();
                let reply = stream.tick(robot_tick(seq, robot)).await?;
                anyhow::ensure!(reply.seq == seq && reply.error.is_none(), "robot {robot} tick {seq}: {reply:?}");
                if stream.reopened() > moved {
                    let killed = killed_at.lock().map_err(|_| anyhow::anyhow!("poisoned"))?;
                    return Ok(killed.map(|at| at.elapsed()));
                }
            }
            Ok(None)
        }));
    }
    tokio::time::sleep(Duration::from_millis(1000)).await;
    *killed_at.lock().map_err(|_| anyhow::anyhow!("poisoned"))? = Some(Instant::now());
    servers[0].kill();
    let mut recoveries = Vec::new();
    for robot in robots {
        if let Some(recovery) = robot.await?? {
            recoveries.push(recovery);
        }
    }
    Ok((recoveries.len(), recoveries))
}

fn ms(d: Duration) -> f64 {
    d.as_secs_f64() * 1e3
}

fn main() -> anyhow::Result<()> {
    let binary = fastrack_e2e::server_binary();
    let profile = binary.parent().and_then(Path::file_name).map_or("?".into(), |p| p.to_string_lossy().into_owned());
    let rt = tokio::runtime::Builder::new_multi_thread().enable_all().build()?;
    let mut rates = Vec::new();
    for count in 1..=3 {
        let rate = rt.block_on(throughput(count))?;
        println!("{count} replica(s): {rate:.0} ticks/s");
        rates.push(rate);
    }
    let mut table = MarkdownTable::new(&["replicas", "ticks/s", "ticks/s per replica", "per-replica efficiency"]);
    for (i, rate) in rates.iter().enumerate() {
        let n = (i + 1) as f64;
        table.row(vec![
            (i + 1).to_string(),
            format!("{rate:.0}"),
            format!("{:.0}", rate / n),
            format!("{:.3}", rate / (n * rates[0])),
        ]);
    }
    let mut trials = Vec::new();
    let mut failover_table = MarkdownTable::new(&[
        "load",
        "trial",
        "robots on the killed replica",
        "served again: median (ms)",
        "p99 (ms)",
        "max (ms)",
    ]);
    for (load, period) in [("every 10 ms", Some(CONTROL_PERIOD)), ("full (closed loop)", None)] {
        for trial in 1..=TRIALS {
            let (moved, mut recoveries) = rt.block_on(failover(period))?;
            recoveries.sort();
            let at = |q: f64| recoveries.get(((recoveries.len() as f64 * q) as usize).min(recoveries.len().max(1) - 1));
            let (median, p99, max) = (at(0.5), at(0.99), recoveries.last());
            let [median, p99, max] = [median, p99, max].map(|d| ms(d.copied().unwrap_or_default()));
            println!(
                "{load}, trial {trial}: {moved} robots moved; median {median:.1} ms, p99 {p99:.1} ms, max {max:.1} ms"
            );
            failover_table.row(vec![
                load.to_string(),
                trial.to_string(),
                moved.to_string(),
                format!("{median:.1}"),
                format!("{p99:.1}"),
                format!("{max:.1}"),
            ]);
            trials
                .push(json!({"load": load, "robots_moved": moved, "median_ms": median, "p99_ms": p99, "max_ms": max}));
        }
    }
    println!("\n{}\n{}", table.to_markdown(), failover_table.to_markdown());
    let out = Path::new(env!("CARGO_MANIFEST_DIR")).join("../bench/results");
    let command = match profile.as_str() {
        "release" => "cargo build --release --bins && cargo bench -p fastrack-e2e --bench replicas".to_string(),
        other => format!("cargo bench --profile dev -p fastrack-e2e --bench replicas (servers from target/{other})"),
    };
    let path = write_record(
        &out,
        "replicas",
        &command,
        json!({
            "model": MODEL, "server": format!("target/{profile}/fastrack-server, defaults; every replica on this machine"),
            "throughput": {"streams": STREAMS, "duration_s": DURATION.as_secs_f64(), "warmup_s": WARMUP.as_secs_f64(),
                           "client": "fastrack_cli::load_generator, Track closed loop, one client of every replica"},
            "failover": {"replicas": 3, "robots": ROBOTS, "control_period_ms": ms(CONTROL_PERIOD), "trials": TRIALS,
                         "loads": ["every control period", "full: closed loop, no pause between ticks"],
                         "kill": "SIGKILL of one replica after 1 s"},
        }),
        json!({"ticks_per_s": rates, "failover": trials}),
        &[("Aggregate Track ticks/s", &table), ("Failover: a replica killed under 48 robots", &failover_table)],
    )?;
    println!("wrote {}", path.display());
    Ok(())
}
