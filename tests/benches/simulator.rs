//! Simulator throughput: the same seeded worlds run with each method's questions answered over the real
//! server (gRPC: the `Track` stream, `TrackingControl`) and by the shipped bundle loaded in this process (the
//! server's own answer code, no network). Runs go one at a time, so the figure is one robot's simulated
//! control periods per second of wall time. Prints a table and writes `bench/results/sim-throughput.{json,md}`.
//!
//! Run: `cargo bench --profile dev -p fastrack-e2e --bench simulator` (the dev build's dependencies and
//! simulator are optimised).

use fastrack_e2e::TestServer;
use fastrack_lab::record::{write_record, MarkdownTable};
use fastrack_sim::backend::Backend;
use fastrack_sim::episode::{PlaneRun, RunSettings, Simulator};
use fastrack_sim::in_process::LocalModel;
use fastrack_sim::methods::Method;
use fastrack_sim::world::{PlaneWorld, WorldSpec};
use serde_json::json;
use std::path::Path;
use std::time::Instant;

const WORLDS: u64 = 10;
const BUNDLE: &str = "dubins4d/5";

/// Control periods per second over every run of `method` on `worlds`, and the runs.
async fn rate(simulator: &Simulator, worlds: &[PlaneWorld], method: &Method) -> anyhow::Result<(f64, Vec<PlaneRun>)> {
    let started = Instant::now();
    let mut runs = Vec::with_capacity(worlds.len());
    for (i, world) in worlds.iter().enumerate() {
        runs.push(simulator.run(world, method, i as u64 + 1).await?);
    }
    let periods: usize = runs.iter().map(|r| r.samples.len()).sum();
    Ok((periods as f64 / started.elapsed().as_secs_f64(), runs))
}

fn main() -> anyhow::Result<()> {
    let rt = tokio::runtime::Builder::new_multi_thread().worker_threads(2).enable_all().build()?;
    let models = Path::new(env!("CARGO_MANIFEST_DIR")).join("../models");
    let (rows, figures) = rt.block_on(async {
        let (_server, client) = TestServer::start_serving(&models).await;
        let service = Simulator::connect(&client, RunSettings::default()).await?;
        let local = LocalModel::load(&models.join(BUNDLE), None, 1)?;
        let in_process = Simulator::new(Backend::InProcess(local), RunSettings::default()).await?;
        let worlds: Vec<PlaneWorld> = (1..=WORLDS)
            .map(|seed| WorldSpec { seed, inflation: service.steb_radius(), ..WorldSpec::default() }.generate())
            .collect::<Result<_, _>>()?;
        let mut rows = Vec::new();
        let mut figures = Vec::new();
        for method in [Method::Parametric, Method::MetaFastrack { levels: 3, quickest: false }, Method::FastrackSlowest]
        {
            let (over_grpc, a) = rate(&service, &worlds, &method).await?;
            let (local_rate, b) = rate(&in_process, &worlds, &method).await?;
            let differing = a.iter().zip(&b).filter(|(a, b)| a.samples != b.samples).count();
            let periods: usize = a.iter().map(|r| r.samples.len()).sum();
            println!("{}: {over_grpc:.0} periods/s over gRPC, {local_rate:.0} in process", method.label());
            rows.push(vec![
                method.label().to_string(),
                periods.to_string(),
                format!("{over_grpc:.0}"),
                format!("{local_rate:.0}"),
                format!("{:.2}", local_rate / over_grpc),
                format!("{differing} of {WORLDS}"),
            ]);
            figures.push(json!({"method": method.label(), "periods": periods, "grpc_periods_per_s": over_grpc,
                                "in_process_periods_per_s": local_rate, "runs_differing": differing}));
        }
        anyhow::Ok((rows, figures))
    })?;
    let mut table = MarkdownTable::new(&[
        "method",
        "control periods",
        "periods/s over gRPC",
        "periods/s in process",
        "in process / gRPC",
        "runs that differ",
    ]);
    for row in rows {
        table.row(row);
    }
    println!("\n{}", table.to_markdown());
    let out = Path::new(env!("CARGO_MANIFEST_DIR")).join("../bench/results");
    let path = write_record(
        &out,
        "sim-throughput",
        "cargo bench --profile dev -p fastrack-e2e --bench simulator",
        json!({"bundle": BUNDLE, "worlds": WORLDS, "generator": "WorldSpec::default(), seeds 1..=10",
               "runs": "one at a time; the server is the dev build with its defaults, on this machine"}),
        json!(figures),
        &[("Simulated control periods per second, one run at a time", &table)],
    )?;
    println!("wrote {}", path.display());
    Ok(())
}
