//! Serving benchmark: the load generator (`fastrack_cli::load_generator`) against the real release server on the
//! shipped model `models/untrained-dubins4d/1`, once with dynamic batching and once without, at concurrency
//! 1, 8, 64 and 256 for unary `TrackingControl` batch 1 and batch 64 and for `Track` ticks; beside it the
//! in-process ceiling (the same bundle through ONNX Runtime in this process, one thread per core) at batch 1
//! and 64. Prints one table and writes `bench/results/serving.{json,md}`.
//!
//! Run: `bash scripts/bench.sh` (builds the release binaries first; this bench does not build the server).

use anyhow::Context;
use fastrack_cli::load_generator::{run_load, LoadReport, LoadSpec, Workload};
use fastrack_client::{model_ref, ClientOptions};
use fastrack_e2e::ceiling::{run_in_process, InProcessReport, InProcessSpec};
use fastrack_e2e::TestServer;
use fastrack_lab::record::{write_record, MarkdownTable};
use serde_json::json;
use std::path::{Path, PathBuf};
use std::time::Duration;

const MODEL: &str = "untrained-dubins4d";
const CONCURRENCY: [usize; 4] = [1, 8, 64, 256];
const WORKLOADS: [Workload; 3] = [Workload::Unary { batch: 1 }, Workload::Unary { batch: 64 }, Workload::Track];
const DURATION: Duration = Duration::from_secs(2);
const WARMUP: Duration = Duration::from_millis(500);
const SEED: u64 = 7;
const COMMAND: &str = "cargo build --release --bins && cargo bench -p fastrack-e2e --bench serving";

/// `target/release/fastrack-server` beside this bench executable (`target/release/deps/serving-*`).
fn release_server() -> anyhow::Result<PathBuf> {
    let exe = std::env::current_exe().context("bench executable path")?;
    let binary = exe
        .parent()
        .and_then(Path::parent)
        .map(|dir| dir.join("fastrack-server"))
        .context("the bench executable is not under target/<profile>/deps")?;
    anyhow::ensure!(
        binary.is_file(),
        "{} is missing: this bench drives the release server but does not build it; run \
         `cargo build --release --bins` first (or `bash scripts/bench.sh`, which does)",
        binary.display()
    );
    Ok(binary)
}

/// Copies the shipped bundle into `<repo>/untrained-dubins4d/1`; returns the version folder.
fn copy_shipped_model(repo: &Path) -> anyhow::Result<PathBuf> {
    let source = Path::new(env!("CARGO_MANIFEST_DIR")).join("../models").join(MODEL).join("1");
    let target = repo.join(MODEL).join("1");
    std::fs::create_dir_all(&target)?;
    for file in ["model.onnx", "manifest.json"] {
        std::fs::copy(source.join(file), target.join(file))
            .with_context(|| format!("copying {}", source.join(file).display()))?;
    }
    Ok(target)
}

/// One measured cell.
struct Cell {
    dynamic_batching: bool,
    report: LoadReport,
}

/// Runs every workload at every concurrency against one server started with `--dynamic-batching`.
async fn measure_server(repo: &Path, dynamic_batching: bool) -> anyhow::Result<Vec<Cell>> {
    let flag = dynamic_batching.to_string();
    let server = TestServer::start(repo, &["--dynamic-batching", &flag]);
    let client = server.client().await;
    if client.wait_until_serving(Duration::from_secs(60)).await.is_err() {
        anyhow::bail!("the server (--dynamic-batching {flag}) never became SERVING; log:\n{}", server.log_text());
    }
    let options = ClientOptions { request_timeout: Duration::from_secs(10), ..Default::default() };
    let mut cells = Vec::new();
    for workload in WORKLOADS {
        for concurrency in CONCURRENCY {
            let spec = LoadSpec {
                model: model_ref(MODEL, 0),
                workload,
                concurrency,
                duration: DURATION,
                warmup: WARMUP,
                seed: SEED,
            };
            let report = run_load(&server.endpoint, &options, &spec, None).await?;
            println!(
                "dynamic batching {flag:<5} {workload:<32} concurrency {concurrency:>3}: {:>9.0} items/s, \
                 p50 {:>7.2} ms, p99 {:>7.2} ms, {} errors",
                report.items_per_s(),
                ms(report.latency.p50),
                ms(report.latency.p99),
                report.error_count()
            );
            cells.push(Cell { dynamic_batching, report });
        }
    }
    Ok(cells)
}

fn ms(d: Duration) -> f64 {
    d.as_secs_f64() * 1e3
}

fn main() -> anyhow::Result<()> {
    release_server()?;
    let repo = tempfile::tempdir()?;
    let bundle_dir = copy_shipped_model(repo.path())?;
    let rt = tokio::runtime::Builder::new_multi_thread().enable_all().build()?;
    let mut cells = rt.block_on(measure_server(repo.path(), true))?;
    cells.extend(rt.block_on(measure_server(repo.path(), false))?);

    // The ceiling, with no server running: one thread (and ONNX Runtime session) per core.
    let threads = std::thread::available_parallelism().map_or(1, |n| n.get());
    let mut ceilings: Vec<InProcessReport> = Vec::new();
    for batch in [1, 64] {
        let spec = InProcessSpec {
            bundle_dir: bundle_dir.clone(),
            batch,
            threads,
            duration: DURATION,
            warmup: WARMUP,
            ort_lib: None,
            seed: SEED,
        };
        let report = run_in_process(&spec)?;
        println!("in-process batch {batch:>2}, {threads} threads: {:>9.0} items/s", report.items_per_s());
        ceilings.push(report);
    }
    let ceiling_for = |workload: Workload| {
        ceilings.iter().find(|c| c.batch == workload.items_per_request()).map(InProcessReport::items_per_s)
    };

    let mut table = MarkdownTable::new(&[
        "dynamic batching",
        "workload",
        "concurrency",
        "requests/s",
        "items/s",
        "p50 (ms)",
        "p90 (ms)",
        "p99 (ms)",
        "errors",
        "vs in-process",
    ]);
    let mut cells_json = Vec::new();
    for Cell { dynamic_batching, report } in &cells {
        let ratio = ceiling_for(report.workload).map(|c| report.items_per_s() / c);
        table.row(vec![
            if *dynamic_batching { "on" } else { "off" }.into(),
            report.workload.to_string(),
            report.concurrency.to_string(),
            format!("{:.0}", report.requests_per_s()),
            format!("{:.0}", report.items_per_s()),
            format!("{:.2}", ms(report.latency.p50)),
            format!("{:.2}", ms(report.latency.p90)),
            format!("{:.2}", ms(report.latency.p99)),
            report.error_count().to_string(),
            ratio.map_or("-".into(), |r| format!("{r:.3}")),
        ]);
        let mut cell = report.to_json();
        cell["dynamic_batching"] = json!(dynamic_batching);
        cell["vs_in_process"] = json!(ratio);
        cells_json.push(cell);
    }
    let mut ceiling_table = MarkdownTable::new(&["batch", "threads", "evaluations/s", "items/s"]);
    for c in &ceilings {
        ceiling_table.row(vec![
            c.batch.to_string(),
            c.threads.to_string(),
            format!("{:.0}", c.evaluations_per_s()),
            format!("{:.0}", c.items_per_s()),
        ]);
    }
    println!("\n{}\n{}", table.to_markdown(), ceiling_table.to_markdown());
    let out = Path::new(env!("CARGO_MANIFEST_DIR")).join("../bench/results");
    let path = write_record(
        &out,
        "serving",
        COMMAND,
        json!({
            "model": format!("models/{MODEL}/1 (SIREN, dubins4d: 4 states, 2 params; untrained)"),
            "server": "target/release/fastrack-server, defaults except --dynamic-batching true|false",
            "client": "fastrack_cli::load_generator: closed loop, one outstanding request or tick per client, \
                       min(concurrency, 64) connections, in-domain random inputs; client and server on one machine",
            "concurrency": CONCURRENCY, "workloads": WORKLOADS.iter().map(ToString::to_string).collect::<Vec<_>>(),
            "duration_s": DURATION.as_secs_f64(), "warmup_s": WARMUP.as_secs_f64(), "seed": SEED,
            "in_process_threads": threads,
        }),
        json!({"cells": cells_json, "in_process": ceilings.iter().map(InProcessReport::to_json).collect::<Vec<_>>()}),
        &[
            ("Load generator against the server", &table),
            ("In-process ceiling (ONNX Runtime, no network)", &ceiling_table),
        ],
    )
    .context("writing the record")?;
    println!("wrote {}", path.display());
    Ok(())
}
