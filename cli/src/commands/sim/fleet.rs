//! `fastrack sim fleet`: Parametric FaSTrack robots on seeded worlds, all at once on one server.

use super::{print, world_of, Generation, Recording, Simulation};
use anyhow::Context as _;
use fastrack_cli::load_generator::LatencySummary;
use fastrack_client::FastrackClient;
use fastrack_lab::record::write_record;
use fastrack_sim::episode::{Simulated, Simulator};
use fastrack_sim::methods::Method;
use fastrack_sim::world::World;
use serde_json::json;
use std::sync::Arc;
use std::time::{Duration, Instant};

/// Arguments of `fastrack sim fleet`.
#[derive(clap::Args)]
pub(super) struct Args {
    /// Robots at once, each on its own seeded world and Track stream.
    #[arg(long, value_delimiter = ',', default_value = "1,100")]
    robots: Vec<usize>,
    #[command(flatten)]
    recording: Recording,
    #[command(flatten)]
    simulation: Simulation,
    #[command(flatten)]
    generation: Generation,
}

/// Runs `fastrack sim fleet`.
pub(super) async fn run(client: &FastrackClient, args: Args, json_mode: bool) -> anyhow::Result<()> {
    let simulator = args.simulation.connect(client, false).await?;
    in_dimension!(async simulator.dim(), fleet_in(simulator, args, json_mode))
}

/// The fleet through worlds of `D` axes.
async fn fleet_in<O: Simulated<D>, const D: usize>(
    simulator: Arc<Simulator>,
    args: Args,
    json_mode: bool,
) -> anyhow::Result<()> {
    let mut lines = Vec::new();
    let mut figures = Vec::new();
    for &robots in &args.robots {
        anyhow::ensure!(robots > 0, "--robots takes counts of at least 1");
        let worlds: Vec<World<O, D>> = (1..=robots as u64)
            .map(|seed| world_of::<O, D>(None, &args.generation, seed, simulator.steb_radius()))
            .collect::<anyhow::Result<_>>()?;
        let started = Instant::now();
        let tasks: Vec<_> = worlds
            .into_iter()
            .enumerate()
            .map(|(i, world)| simulator.spawn_run(world, Method::Parametric, i as u64 + 1))
            .collect();
        let mut done = Vec::new();
        for task in tasks {
            done.push(task.await.context("a robot's task failed")??);
        }
        let wall = started.elapsed();
        let ticks: usize = done.iter().map(|r| r.round_trips).sum();
        let mut decisions: Vec<Duration> = done.iter().flat_map(|r| r.decision_times.iter().copied()).collect();
        let p99 = LatencySummary::from_latencies(&mut decisions).p99;
        let period = done.first().map_or(0.0, |r| r.control_period);
        let slowest_rate = done
            .iter()
            .map(|r| r.decision_times.len() as f64 / r.decision_times.iter().sum::<Duration>().as_secs_f64().max(1e-9))
            .fold(f64::INFINITY, f64::min);
        let unsafe_runs = done.iter().filter(|r| r.outcome.is_unsafe()).count();
        let real_time = slowest_rate >= 1.0 / period;
        lines.push(format!(
            "{robots} robots: {ticks} ticks in {:.2} s = {:.0} ticks/s; decision p99 {:.3} ms; the slowest robot decides {:.0} steps/s of its own time against {:.0} needed: {}; unsafe runs {unsafe_runs}",
            wall.as_secs_f64(),
            ticks as f64 / wall.as_secs_f64(),
            p99.as_secs_f64() * 1e3,
            slowest_rate,
            1.0 / period,
            if real_time { "holds its control period" } else { "misses its control period" }
        ));
        figures.push(json!({"robots": robots, "ticks": ticks, "wall_s": wall.as_secs_f64(), "ticks_per_s": ticks as f64 / wall.as_secs_f64(),
            "decision_p99_ms": p99.as_secs_f64() * 1e3, "slowest_robot_steps_per_s": slowest_rate, "needed_steps_per_s": 1.0 / period,
            "holds_control_period": real_time, "unsafe_runs": unsafe_runs}));
        anyhow::ensure!(unsafe_runs == 0, "{unsafe_runs} of {robots} runs were unsafe");
    }
    if let Some(name) = &args.recording.record {
        let command = format!(
            "fastrack sim fleet --robots {} --record {name}",
            args.robots.iter().map(ToString::to_string).collect::<Vec<_>>().join(",")
        );
        let mut rows = fastrack_lab::record::MarkdownTable::new(&[
            "robots",
            "ticks/s",
            "decision p99 (ms)",
            "slowest robot's steps/s",
            "steps/s its control period needs",
            "holds its control period",
            "unsafe runs",
        ]);
        for f in &figures {
            rows.row(vec![
                f["robots"].to_string(),
                format!("{:.0}", f["ticks_per_s"].as_f64().unwrap_or_default()),
                format!("{:.3}", f["decision_p99_ms"].as_f64().unwrap_or_default()),
                format!("{:.0}", f["slowest_robot_steps_per_s"].as_f64().unwrap_or_default()),
                format!("{:.0}", f["needed_steps_per_s"].as_f64().unwrap_or_default()),
                f["holds_control_period"].to_string(),
                f["unsafe_runs"].to_string(),
            ]);
        }
        let path = write_record(
            &args.recording.results_dir,
            name,
            &command,
            json!({"model": args.simulation.model}),
            json!(figures),
            &[("Fleet", &rows)],
        )?;
        eprintln!("record: {}", path.display());
    }
    print(json_mode, json!(figures), || lines.join("\n"));
    Ok(())
}
