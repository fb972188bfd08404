//! `fastrack sim bench`: seeded worlds x methods, the paper's Table 1 beside ours, a record and figures.

use super::{print, world_of, Generation, Recording, Simulation};
use anyhow::Context as _;
use fastrack_client::FastrackClient;
use fastrack_lab::record::write_record;
use fastrack_lab::shard::Shard;
use fastrack_online::geometry::Point;
use fastrack_sim::bench::{
    beta_share_table, paper_comparison, summarise, summary_json, table, time_ratio, BenchPart, BenchRun, Summary,
    FIGURE_WORLD, PART_STEM,
};
use fastrack_sim::episode::{Outcome, Run, Simulated, Simulator};
use fastrack_sim::methods::Method;
use fastrack_sim::plot::{methods_on_one_world, time_to_goal, Outlined, View};
use fastrack_sim::visits::write_csv;
use fastrack_sim::world::{World, WorldObstacle};
use indicatif::{ProgressBar, ProgressStyle};
use serde::de::DeserializeOwned;
use serde::Serialize;
use serde_json::json;
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::time::Instant;
use tokio::sync::Semaphore;

/// Arguments of `fastrack sim bench`.
#[derive(clap::Args)]
pub(super) struct Args {
    /// Seeded worlds (seeds 1..=N).
    #[arg(long, default_value_t = 20)]
    worlds: u64,
    /// Methods, comma separated (pf, pf-fast, pf-planner, f-low, f-high, mf, mf-quick, mppi).
    #[arg(long, value_delimiter = ',', default_value = "f-low,f-high,mf,mf-quick,pf,pf-fast,pf-planner,mppi")]
    methods: Vec<String>,
    /// Runs at once (each its own connection's stream or calls); decision latencies then include the
    /// others' load on the machine.
    #[arg(long, default_value_t = 1)]
    jobs: usize,
    /// Only this shard of the worlds, `INDEX/COUNT` (world `w` goes to shard `(w - 1) % COUNT`), or `COUNT`
    /// with the index from `JOB_COMPLETION_INDEX` (a Kubernetes Indexed Job); writes a part (--part-dir)
    /// for `sim merge` instead of a record.
    #[arg(long)]
    shard: Option<Shard>,
    /// Folder the shard's part is written into, as `sim-bench-part-<index>-of-<count>.json`.
    #[arg(long)]
    part_dir: Option<PathBuf>,
    /// Write the relative state of every control period of PF's runs, with its branch and `beta`, into this
    /// CSV file (the operational states `fastrack-grid verify --operational-states` checks); a shard's part
    /// then keeps them for `sim merge --visits`.
    #[arg(long)]
    visits: Option<PathBuf>,
    /// Write the online loop's golden trace of every PF run into this folder, as `pf-world-<seed>.json`
    /// (what the loop was given and decided at every control period; docs/online-loop.md).
    #[arg(long)]
    traces: Option<PathBuf>,
    #[command(flatten)]
    recording: Recording,
    #[command(flatten)]
    simulation: Simulation,
    #[command(flatten)]
    generation: Generation,
}

/// Runs `fastrack sim bench`.
pub(super) async fn run(client: &FastrackClient, args: Args, json_mode: bool) -> anyhow::Result<()> {
    anyhow::ensure!(args.worlds > 0, "--worlds must be at least 1");
    anyhow::ensure!(args.jobs > 0, "--jobs must be at least 1");
    let shard = args.shard.unwrap_or(Shard::WHOLE);
    anyhow::ensure!(
        shard.is_whole() || args.part_dir.is_some(),
        "--shard {shard} writes a part: give --part-dir (merge the parts with `fastrack sim merge`)"
    );
    let simulator = args.simulation.connect(client, args.traces.is_some()).await?;
    in_dimension!(async simulator.dim(), bench_in(simulator, args, shard, json_mode))
}

/// The benchmark through worlds of `D` axes.
async fn bench_in<O: Simulated<D> + Outlined<D>, const D: usize>(
    simulator: Arc<Simulator>,
    args: Args,
    shard: Shard,
    json_mode: bool,
) -> anyhow::Result<()>
where
    Point<D>: Serialize + DeserializeOwned,
{
    if let Some(dir) = &args.traces {
        std::fs::create_dir_all(dir).with_context(|| format!("creating the traces folder {}", dir.display()))?;
    }
    let methods: Vec<Method> =
        args.methods.iter().map(|m| Method::parse(m)).collect::<Result<_, _>>().map_err(anyhow::Error::msg)?;
    let seeds: Vec<u64> = (1..=args.worlds).filter(|&seed| shard.takes(seed as usize - 1)).collect();
    let worlds: Vec<(u64, World<O, D>)> = seeds
        .iter()
        .map(|&seed| Ok((seed, world_of::<O, D>(None, &args.generation, seed, simulator.steb_radius())?)))
        .collect::<anyhow::Result<_>>()?;
    let bar = ProgressBar::new((worlds.len() * methods.len()) as u64).with_style(
        ProgressStyle::with_template("{elapsed_precise} [{bar:30}] {pos}/{len} runs {msg}")?.progress_chars("=> "),
    );
    let started = Instant::now();
    let keep_visits = args.visits.is_some();
    let slots = Arc::new(Semaphore::new(args.jobs));
    let mut tasks = Vec::new();
    for (seed, world) in &worlds {
        for (m, method) in methods.iter().enumerate() {
            let (simulator, world, method, bar) = (Arc::clone(&simulator), world.clone(), method.clone(), bar.clone());
            let (slots, seed, traces) = (Arc::clone(&slots), *seed, args.traces.clone());
            tasks.push(tokio::spawn(async move {
                let _slot = slots.acquire_owned().await?;
                let label = method.label();
                let mut done = simulator.spawn_run(world, method, seed).await.context("a run's thread failed")?;
                if let (Ok(run), Some(dir)) = (&mut done, &traces) {
                    if let Some(trace) = run.trace.take() {
                        let path = dir.join(format!("pf-world-{seed}.json"));
                        trace.write(&path).with_context(|| format!("writing the trace {}", path.display()))?;
                    }
                }
                bar.set_message(format!("world {seed} {label}"));
                bar.inc(1);
                anyhow::Ok(BenchRun::new(seed, m, done?, keep_visits))
            }));
        }
    }
    let mut runs = Vec::with_capacity(tasks.len());
    for task in tasks {
        runs.push(task.await.context("a run's task failed")??);
    }
    bar.finish_and_clear();
    let config = json!({"model": args.simulation.model, "dim": D, "worlds": args.worlds, "methods": args.methods,
        "control_period_s": simulator.control_period(), "substeps": args.simulation.substeps,
        "sensor_range_m": simulator.sensor_range(), "time_limit_s": args.simulation.time_limit,
        "disturbance_m_s": args.simulation.disturbance, "state": simulator.state_names(),
        "world": args.generation.recorded::<D>()?});
    let wall_s = started.elapsed().as_secs_f64();
    if let Some(path) = &args.visits {
        write_visits(path, &config, &runs, json_mode)?;
    }
    if let Some(dir) = &args.part_dir {
        let part = BenchPart { config, shard, wall_s, items: runs };
        let path = part.write(dir, PART_STEM).with_context(|| format!("writing the part into {}", dir.display()))?;
        print(json_mode, json!({"part": path, "shard": shard.to_string(), "runs": part.items.len()}), || {
            format!(
                "shard {shard}: {} runs of {} worlds in {wall_s:.0} s; part {}",
                part.items.len(),
                seeds.len(),
                path.display()
            )
        });
        return ensure_pf_safe(&methods, &part.items);
    }
    let command = format!(
        "fastrack sim bench --worlds {} --methods {} --jobs {}{}",
        args.worlds,
        args.methods.join(","),
        args.jobs,
        args.recording.record.as_ref().map_or(String::new(), |name| format!(" --record {name}"))
    );
    report(&config, &runs, wall_s, &command, &args.recording, json_mode)
}

/// Writes the visits of `runs` (world by world) into `path` as CSV, the state columns named by the
/// benchmark's configuration.
pub(super) fn write_visits<O, const D: usize>(
    path: &Path,
    config: &serde_json::Value,
    runs: &[BenchRun<O, D>],
    json_mode: bool,
) -> anyhow::Result<()> {
    let names: Vec<String> =
        serde_json::from_value(config["state"].clone()).context("the configuration names no state coordinates")?;
    let written = write_csv(path, &names, runs.iter().flat_map(|r| &r.run.visits))
        .with_context(|| format!("writing the visits into {}", path.display()))?;
    let mut by_branch = std::collections::BTreeMap::<&str, usize>::new();
    for visit in runs.iter().flat_map(|r| &r.run.visits) {
        *by_branch.entry(visit.branch.name()).or_default() += 1;
    }
    let by_branch: Vec<String> = by_branch.iter().map(|(name, count)| format!("{name} {count}")).collect();
    if !json_mode {
        eprintln!("visits: {written} ({}) in {}", by_branch.join(", "), path.display());
    }
    Ok(())
}

/// PF, on either raw path, must never collide nor exceed its bound.
fn ensure_pf_safe<O, const D: usize>(methods: &[Method], runs: &[BenchRun<O, D>]) -> anyhow::Result<()> {
    let unsafe_runs: Vec<String> = runs
        .iter()
        .filter(|r| methods[r.method].is_parametric() && r.run.outcome.is_unsafe())
        .map(|r| format!("{} on world {}: {}", methods[r.method].label(), r.world, r.run.outcome.label()))
        .collect();
    anyhow::ensure!(unsafe_runs.is_empty(), "PF was unsafe: {}", unsafe_runs.join("; "));
    Ok(())
}

/// The benchmark's tables, ratios, record and figures, from its configuration and runs (a single run's or
/// merged parts').
pub(super) fn report<O: WorldObstacle<D> + Outlined<D>, const D: usize>(
    config: &serde_json::Value,
    runs: &[BenchRun<O, D>],
    wall_s: f64,
    command: &str,
    recording: &Recording,
    json_mode: bool,
) -> anyhow::Result<()> {
    let names: Vec<String> =
        serde_json::from_value(config["methods"].clone()).context("the configuration's methods")?;
    let methods: Vec<Method> =
        names.iter().map(|m| Method::parse(m)).collect::<Result<_, _>>().map_err(anyhow::Error::msg)?;
    let by_method = |m: usize| runs.iter().filter(|r| r.method == m).map(|r| &r.run).collect::<Vec<&Run<O, D>>>();
    let summaries: Vec<Summary> =
        methods.iter().enumerate().map(|(m, method)| summarise(method.label(), &by_method(m))).collect();
    let pf = methods.iter().position(|m| *m == Method::Parametric);
    let ratios: Vec<(String, Option<(f64, usize)>)> = match pf {
        Some(pf) => methods
            .iter()
            .enumerate()
            .filter(|(m, _)| *m != pf)
            .map(|(m, method)| (method.label().to_string(), time_ratio(&by_method(pf), &by_method(m))))
            .collect(),
        None => Vec::new(),
    };
    let ratio_text = ratios
        .iter()
        .map(|(label, r)| match r {
            Some((ratio, n)) => format!("PF / {label} time to goal: {ratio:.3} over the {n} worlds both reached"),
            None => format!("PF / {label}: no world both reached"),
        })
        .collect::<Vec<_>>()
        .join("\n");
    let ours = table(&summaries);
    // The paper's Table 1 is of its car, in the plane.
    let paper = (D == 2).then(|| paper_comparison(&summaries));
    let shares = beta_share_table(&summaries);
    let mut sections = vec![("Ours", &ours)];
    sections.extend(paper.as_ref().map(|paper| ("The paper's Table 1 beside ours", paper)));
    sections.push(("Share of the time at each beta (%)", &shares));
    if let Some(name) = &recording.record {
        let shown: Vec<&Run<O, D>> = runs.iter().filter(|r| r.world == FIGURE_WORLD).map(|r| &r.run).collect();
        let steb = shown.first().map(|r| r.steb_radius).context("the runs hold no run of the figure's world")?;
        let generation: Generation = serde_json::from_value(config["world"].clone()).context("the world settings")?;
        let world = world_of::<O, D>(None, &generation, FIGURE_WORLD, steb)?;
        let figure = recording.results_dir.join(format!("{name}-world{FIGURE_WORLD}.png"));
        std::fs::create_dir_all(&recording.results_dir)?;
        for (extension, view) in View::all::<D>() {
            let drawn = figure.with_extension(extension);
            methods_on_one_world(&drawn, &world, &shown, *view).map_err(anyhow::Error::msg)?;
        }
        // Drawn when some run reached its goal: there is no time to goal to draw otherwise.
        let times_figure = runs
            .iter()
            .any(|r| r.run.outcome == Outcome::Reached)
            .then(|| recording.results_dir.join(format!("{name}-time-to-goal.png")));
        if let Some(times_figure) = &times_figure {
            let labels: Vec<&str> = methods.iter().map(Method::label).collect();
            let by_method_runs: Vec<Vec<&Run<O, D>>> = (0..methods.len()).map(by_method).collect();
            time_to_goal(times_figure, &labels, &by_method_runs).map_err(anyhow::Error::msg)?;
        }
        let path = write_record(
            &recording.results_dir,
            name,
            command,
            config.clone(),
            json!({"summaries": summaries.iter().map(summary_json).collect::<Vec<_>>(),
                   "pf_time_ratios": ratios.iter().map(|(l, r)| json!({"against": l, "ratio": r.map(|x| x.0), "worlds": r.map(|x| x.1)})).collect::<Vec<_>>(),
                   "paper_pf_over_f_ratio": (D == 2).then_some(22.47 / 37.31), "wall_s": wall_s, "figure": figure,
                   "time_to_goal_figure": times_figure}),
            &sections,
        )?;
        eprintln!("record: {}", path.display());
    }
    print(json_mode, json!({"summaries": summaries.iter().map(summary_json).collect::<Vec<_>>()}), || {
        let tables: Vec<String> = sections.iter().map(|(_, table)| table.to_markdown()).collect();
        format!("{}\n{ratio_text}", tables.join("\n"))
    });
    ensure_pf_safe(&methods, runs)
}
