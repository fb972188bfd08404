//! Foundation benchmark: in-process evaluator throughput (value + grad + control) at batch 1, 64 and 4096
//! for a 3x256 SIREN beside a bare `ort` session on the same graph (the ceiling), and unary
//! `TrackingControl` latency over loopback at batch 1 and 64 against the real (release) server binary.
//! Prints tables and writes `bench/results/foundation.{json,md}`.
//!
//! Run: `bash scripts/bench.sh` (builds the release binaries first).

use anyhow::Context;
use fastrack_client::{model_ref, pb};
use fastrack_e2e::{write_network_bundle, TestServer, TEST_HORIZON};
use fastrack_lab::record::{write_record, MarkdownTable};
use fastrack_valuefn::network::{NetworkShape, ValueNetwork};
use fastrack_valuefn::onnx_writer::write_value_graph;
use fastrack_valuefn::runtime::{runtime, Evaluator, GraphDims};
use fastrack_valuefn::system::dubins4d;
use ort::session::builder::GraphOptimizationLevel;
use ort::session::Session;
use ort::value::TensorRef;
use rand::{Rng, SeedableRng};
use serde_json::json;
use std::time::{Duration, Instant};

const BATCHES: [usize; 3] = [1, 64, 4096];
const ROUNDS: usize = 5;
const ROUND_TIME: Duration = Duration::from_millis(400);

fn inputs(n: usize) -> (Vec<f32>, Vec<f32>) {
    let system = dubins4d::system();
    let mut rng = rand::rngs::StdRng::seed_from_u64(n as u64);
    let mut s = Vec::new();
    let mut p = Vec::new();
    for _ in 0..n {
        s.extend(system.state.iter().map(|d| rng.random_range(d.min..d.max) as f32));
        p.extend(system.params.iter().map(|d| rng.random_range(d.min..d.max) as f32));
    }
    (s, p)
}

/// Evaluations per second of `f` (one call = `n` evaluations), over one timed round.
fn rate(n: usize, mut f: impl FnMut()) -> f64 {
    let start = Instant::now();
    let mut calls = 0usize;
    while start.elapsed() < ROUND_TIME {
        f();
        calls += 1;
    }
    (calls * n) as f64 / start.elapsed().as_secs_f64()
}

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

fn percentile(sorted: &[f64], q: f64) -> f64 {
    sorted[((sorted.len() - 1) as f64 * q).round() as usize]
}

fn main() -> anyhow::Result<()> {
    let system = dubins4d::system();
    let network = ValueNetwork::random(&system, &NetworkShape::new(&[256, 256, 256], 30.0, true), TEST_HORIZON, 1);
    let onnx = write_value_graph(&network, &system, TEST_HORIZON);
    let rt = runtime(None)?;
    let dims = GraphDims { n_state: 4, n_params: 2, n_control: 2 };
    let evaluator = Evaluator::new(rt, &onnx, dims, 1)?;
    let mut bare = bare_session(rt.environment(), &onnx).map_err(anyhow::Error::msg)?;

    // Throughput: interleaved rounds, median of each.
    let mut throughput =
        MarkdownTable::new(&["batch", "evaluator (evals/s)", "bare ort session (evals/s)", "evaluator / bare"]);
    let mut throughput_json = Vec::new();
    for n in BATCHES {
        let (s, p) = inputs(n);
        let (mut ours, mut theirs) = (Vec::new(), Vec::new());
        for _ in 0..ROUNDS {
            ours.push(rate(n, || {
                evaluator.evaluate(&s, &p).expect("evaluate");
            }));
            theirs.push(rate(n, || {
                let state = TensorRef::from_array_view(([n, 4], s.as_slice())).unwrap();
                let params = TensorRef::from_array_view(([n, 2], p.as_slice())).unwrap();
                let out = bare.run(ort::inputs![state, params]).unwrap();
                for i in 0..3 {
                    std::hint::black_box(out[i].try_extract_tensor::<f32>().unwrap().1);
                }
            }));
        }
        let (ours, theirs) = (median(ours), median(theirs));
        println!(
            "batch {n:>5}: evaluator {ours:>12.0} evals/s, bare {theirs:>12.0} evals/s, ratio {:.3}",
            ours / theirs
        );
        throughput.row(vec![
            n.to_string(),
            format!("{ours:.0}"),
            format!("{theirs:.0}"),
            format!("{:.3}", ours / theirs),
        ]);
        throughput_json.push(
            json!({"batch": n, "evaluator_evals_per_s": ours, "bare_evals_per_s": theirs, "ratio": ours / theirs}),
        );
    }

    // Unary TrackingControl latency over loopback against the real server.
    let repo = tempfile::tempdir()?;
    write_network_bundle(repo.path(), &system, "bench", 1, &network);
    let latency_rows =
        tokio::runtime::Builder::new_multi_thread().worker_threads(1).enable_all().build()?.block_on(async {
            let (_server, client) = TestServer::start_serving(repo.path()).await;
            let mut rows = Vec::new();
            for (n, calls) in [(1usize, 3000usize), (64, 1500)] {
                let (s, p) = inputs(n);
                let states: Vec<f64> = s.iter().map(|&x| x.into()).collect();
                let params: Vec<f64> = p.iter().map(|&x| x.into()).collect();
                let call = || {
                    let flag = pb::OutOfDomainPolicy::Flag;
                    client.tracking_control(model_ref("bench", 0), states.clone(), params.clone(), flag)
                };
                for _ in 0..200 {
                    call().await?;
                }
                let mut micros = Vec::with_capacity(calls);
                for _ in 0..calls {
                    let start = Instant::now();
                    call().await?;
                    micros.push(start.elapsed().as_secs_f64() * 1e6);
                }
                micros.sort_by(f64::total_cmp);
                rows.push((n, calls, percentile(&micros, 0.5), percentile(&micros, 0.99)));
            }
            anyhow::Ok(rows)
        })?;
    let mut latency = MarkdownTable::new(&["batch", "calls", "p50 (us)", "p99 (us)"]);
    let mut latency_json = Vec::new();
    for (n, calls, p50, p99) in &latency_rows {
        println!("TrackingControl batch {n:>3}: p50 {p50:.0} us, p99 {p99:.0} us ({calls} calls, concurrency 1)");
        latency.row(vec![n.to_string(), calls.to_string(), format!("{p50:.0}"), format!("{p99:.0}")]);
        latency_json.push(json!({"batch": n, "calls": calls, "p50_us": p50, "p99_us": p99}));
    }
    println!("\n{}\n{}", throughput.to_markdown(), latency.to_markdown());
    let out = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../bench/results");
    let path = write_record(
        &out,
        "foundation",
        "bash scripts/bench.sh",
        json!({"network": "SIREN 3x256, omega_0 30, dubins4d (4 states, 2 params)", "sessions": 1, "intra_op_threads": 1,
               "rounds": ROUNDS, "round_ms": ROUND_TIME.as_millis(), "latency": "unary TrackingControl over loopback, concurrency 1, release server"}),
        json!({"throughput": throughput_json, "latency": latency_json}),
        &[("Evaluator throughput (value + grad + control)", &throughput), ("Unary TrackingControl latency over loopback", &latency)],
    )
    .context("writing the record")?;
    println!("wrote {}", path.display());
    Ok(())
}

/// A plain `ort` session on the graph, configured like the evaluator's (one intra-op thread, level 3).
fn bare_session(env: &ort::environment::Environment, onnx: &[u8]) -> Result<Session, String> {
    Session::builder(env)
        .and_then(|b| {
            Ok(b.with_intra_threads(1)?
                .with_inter_threads(1)?
                .with_optimization_level(GraphOptimizationLevel::Level3)?)
        })
        .map_err(|e| e.to_string())?
        .commit_from_memory(onnx)
        .map_err(|e| e.to_string())
}
