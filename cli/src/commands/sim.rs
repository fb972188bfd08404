//! `fastrack sim`: the navigation simulator against the server: `run` (one world, one method, a summary and
//! figures), `bench` (seeded worlds x methods, the paper's Table 1, a record), `fleet` (many robots on one
//! server at once) and `world` (generate or check a world file).

use super::{print, Server};
use anyhow::Context as _;
use fastrack_cli::load_generator::LatencySummary;
use fastrack_client::{model_ref, FastrackClient};
use fastrack_proto::planner_speed::SpeedRow;
use fastrack_sim::bench::{
    paper_comparison, summarise, summary_json, table, time_ratio, BenchPart, BenchRun, Summary, FIGURE_WORLD, PART_STEM,
};
use fastrack_sim::episode::{Outcome, Run, RunSettings, Simulator};
use fastrack_sim::methods::Method;
use fastrack_sim::plot::{methods_on_one_world, over_time, time_to_goal, trajectory};
use fastrack_sim::tracker::Disturbance;
use fastrack_sim::visits::write_csv;
use fastrack_sim::world::{World, WorldSpec};
use fastrack_valuefn::record::write_record;
use fastrack_valuefn::shard::Shard;
use indicatif::{ProgressBar, ProgressStyle};
use serde_json::json;
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::time::{Duration, Instant};
use tokio::sync::Semaphore;

/// Arguments of `fastrack sim`.
#[derive(clap::Args)]
pub struct Args {
    #[command(subcommand)]
    command: SimCommand,
}

#[derive(clap::Subcommand)]
enum SimCommand {
    /// One world, one method: prints the run's summary and writes its figures.
    Run(RunArgs),
    /// Seeded worlds x methods: the paper's Table 1 beside ours, a record and figures.
    Bench(BenchArgs),
    /// Merges the parts of a sharded `sim bench` into the tables and record a single run gives.
    Merge(MergeArgs),
    /// Parametric FaSTrack robots on seeded worlds, all at once on one server: ticks/s and latency.
    Fleet(FleetArgs),
    /// Generates a world from a seed, or checks a world file.
    World(WorldArgs),
}

/// Settings every simulated run shares.
#[derive(clap::Args)]
struct Simulation {
    /// Model name.
    #[arg(long, default_value = "dubins4d")]
    model: String,
    /// Control period (s); default: the verification step recorded in the model's manifest.
    #[arg(long)]
    control_period: Option<f64>,
    /// RK4 sub-steps per control period (collisions and the bound are checked at each).
    #[arg(long, default_value_t = 4)]
    substeps: usize,
    /// A run that has not reached the goal by then is stopped (s).
    #[arg(long, default_value_t = 120.0)]
    time_limit: f64,
    /// Sensing range (m); default: twice the dTEB at beta_u (the paper's assumption).
    #[arg(long)]
    sensor_range: Option<f64>,
    /// A random push on the tracker's position of at most this many m/s per axis, which the model does not
    /// know of (default none; the bounds are not guaranteed under it).
    #[arg(long)]
    disturbance: Option<f64>,
}

impl Simulation {
    fn settings(&self, trace: bool) -> RunSettings {
        RunSettings {
            model: model_ref(&self.model, 0),
            control_period: self.control_period,
            substeps: self.substeps,
            time_limit: self.time_limit,
            sensor_range: self.sensor_range,
            disturbance: self.disturbance.map(|bound| Disturbance { bound, period: 0.5 }),
            trace,
        }
    }

    /// The simulator of these settings, its model fetched from the server; `trace`: PF's runs record the
    /// online loop's trace.
    async fn connect(&self, client: &FastrackClient, trace: bool) -> anyhow::Result<Arc<Simulator>> {
        let simulator = Simulator::connect(client, self.settings(trace)).await;
        Ok(Arc::new(simulator.with_context(|| format!("preparing runs of model {}", self.model))?))
    }
}

/// How generated worlds look.
#[derive(clap::Args, serde::Deserialize)]
struct Generation {
    /// Workspace width and height (m).
    #[arg(long, value_delimiter = ',', default_value = "30,20", num_args = 1)]
    size: Vec<f64>,
    /// Obstacles per 100 m^2.
    #[arg(long, default_value_t = 2.0)]
    density: f64,
    /// Smallest and largest obstacle size (m): radius, half side, half length.
    #[arg(long, value_delimiter = ',', default_value = "0.4,1.5", num_args = 1)]
    size_range: Vec<f64>,
    /// Worlds (generated or checked) must be feasible for this sTEB (m) instead of the model's, so that
    /// models of different bounds run on the same worlds; at least the model's sTEB.
    #[arg(long)]
    #[serde(default)]
    feasible_for: Option<f64>,
}

impl Generation {
    /// The sTEB generated worlds are made feasible for: --feasible-for, or the model's `steb`.
    fn inflation(&self, steb: f64) -> anyhow::Result<f64> {
        match self.feasible_for {
            None => Ok(steb),
            Some(m) if m.is_finite() && m >= steb => Ok(m),
            Some(m) => anyhow::bail!("--feasible-for must be a finite sTEB of at least the model's, {steb} m; got {m}"),
        }
    }

    fn spec(&self, seed: u64, inflation: f64) -> anyhow::Result<WorldSpec> {
        let (&[w, h], &[lo, hi]) = (self.size.as_slice(), self.size_range.as_slice()) else {
            anyhow::bail!("--size and --size-range take two numbers each, e.g. --size 30,20 --size-range 0.4,1.5");
        };
        Ok(WorldSpec {
            seed,
            size: [w, h],
            density: self.density,
            size_range: (lo, hi),
            inflation,
            ..WorldSpec::default()
        })
    }
}

/// Where a benchmark's record goes.
#[derive(clap::Args)]
struct Recording {
    /// Record name (`<results-dir>/<record>.{json,md}`, figures beside it); none without it.
    #[arg(long)]
    record: Option<String>,
    /// Folder of measurement records and figures.
    #[arg(long, default_value = "bench/results")]
    results_dir: PathBuf,
}

#[derive(clap::Args)]
struct RunArgs {
    /// A world file (TOML or JSON); without it, a world generated from --seed.
    #[arg(long)]
    world: Option<PathBuf>,
    /// Seed of the generated world (and of the method's randomness).
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// pf, f-low, f-high, mf or mppi.
    #[arg(long, default_value = "pf")]
    method: String,
    /// Where the trajectory figure goes (a second figure, over time, goes beside it).
    #[arg(long, default_value = "target/sim/run.png")]
    plot: PathBuf,
    #[command(flatten)]
    simulation: Simulation,
    #[command(flatten)]
    generation: Generation,
}

#[derive(clap::Args)]
struct BenchArgs {
    /// Seeded worlds (seeds 1..=N).
    #[arg(long, default_value_t = 20)]
    worlds: u64,
    /// Methods, comma separated (pf, f-low, f-high, mf, mppi).
    #[arg(long, value_delimiter = ',', default_value = "f-low,f-high,mf,pf,mppi")]
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

#[derive(clap::Args)]
struct MergeArgs {
    /// Folder holding every shard's part.
    #[arg(long)]
    part_dir: PathBuf,
    /// Write the visits the parts kept (shards run with `--visits`) into this CSV file.
    #[arg(long)]
    visits: Option<PathBuf>,
    #[command(flatten)]
    recording: Recording,
}

#[derive(clap::Args)]
struct FleetArgs {
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

#[derive(clap::Args)]
struct WorldArgs {
    /// Check this world file (values, and a path for the model's sTEB) instead of generating one.
    #[arg(long)]
    check: Option<PathBuf>,
    /// Seed of the generated world.
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// Where the generated world goes (TOML); printed without it.
    #[arg(long)]
    out: Option<PathBuf>,
    /// Model whose sTEB the world must be feasible for.
    #[arg(long, default_value = "dubins4d")]
    model: String,
    #[command(flatten)]
    generation: Generation,
}

/// Runs `fastrack sim ...`.
pub async fn run_command(server: &Server, args: Args, json_mode: bool) -> anyhow::Result<()> {
    match args.command {
        SimCommand::Run(args) => run_one(&server.connect().await?, args, json_mode).await,
        SimCommand::Bench(args) => bench(&server.connect().await?, args, json_mode).await,
        SimCommand::Merge(args) => merge(args, json_mode),
        SimCommand::Fleet(args) => fleet(&server.connect().await?, args, json_mode).await,
        SimCommand::World(args) => world(&server.connect().await?, args, json_mode).await,
    }
}

/// The model's table as the planner-speed rules read it.
async fn speeds(client: &FastrackClient, model: &str) -> anyhow::Result<Vec<SpeedRow>> {
    let info = client.get_model(model_ref(model, 0)).await?;
    let rows: Vec<SpeedRow> = info.teb_table.iter().map(SpeedRow::from).collect();
    anyhow::ensure!(!rows.is_empty(), "model {model} has an empty TEB table");
    Ok(rows)
}

/// The world of a run: the file, or the seed's generated world.
fn world_of(file: Option<&PathBuf>, generation: &Generation, seed: u64, steb: f64) -> anyhow::Result<World> {
    let inflation = generation.inflation(steb)?;
    let world = match file {
        Some(path) => World::load(path)?,
        None => generation.spec(seed, inflation)?.generate()?,
    };
    world.check_feasible(inflation).context("the world is not feasible for the sTEB")?;
    Ok(world)
}

fn run_line(run: &Run) -> String {
    let latency = LatencySummary::from_latencies(&mut run.decision_times.clone());
    format!(
        "{}: {} after {:.2} s; min clearance {:.3} m; largest error - bound {}; replans {}, resets {}, held steps {}, server calls {}, steps out of domain {}, steps past the certificate {}; decision p50 {:.3} ms, p99 {:.3} ms{}",
        run.method,
        run.outcome.label(),
        run.time,
        run.min_clearance,
        run.worst_excess.map_or("-".into(), |e| format!("{e:.3} m")),
        run.replans,
        run.resets,
        run.held_steps,
        run.round_trips,
        run.out_of_domain,
        run.uncertified_steps,
        latency.p50.as_secs_f64() * 1e3,
        latency.p99.as_secs_f64() * 1e3,
        match &run.outcome {
            Outcome::Failed(why) => format!(" ({why})"),
            Outcome::BoundExceeded { error, bound } => format!(" (error {error:.3} m over the bound {bound:.3} m)"),
            _ => String::new(),
        }
    )
}

async fn run_one(client: &FastrackClient, args: RunArgs, json_mode: bool) -> anyhow::Result<()> {
    let simulator = args.simulation.connect(client, false).await?;
    let beta_l = simulator.speeds()[0].beta;
    let world = world_of(args.world.as_ref(), &args.generation, args.seed, simulator.steb_radius())?;
    let method = Method::parse(&args.method).map_err(anyhow::Error::msg)?;
    let run = simulator.spawn_run(world.clone(), method, args.seed).await.context("the run's thread failed")??;
    if let Some(dir) = args.plot.parent() {
        std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
    }
    trajectory(&args.plot, &world, &run, beta_l, 2.0).map_err(anyhow::Error::msg)?;
    let over = args.plot.with_extension("time.png");
    over_time(&over, &run).map_err(anyhow::Error::msg)?;
    print(
        json_mode,
        json!({"method": run.method, "outcome": run.outcome.label(), "time_s": run.time, "min_clearance_m": run.min_clearance,
               "largest_error_minus_bound_m": run.worst_excess, "replans": run.replans, "resets": run.resets, "held_steps": run.held_steps,
               "server_calls": run.round_trips, "steps_out_of_domain": run.out_of_domain, "steps_past_the_certificate": run.uncertified_steps, "plot": args.plot, "plot_over_time": over}),
        || format!("{}\nfigures: {} and {}", run_line(&run), args.plot.display(), over.display()),
    );
    anyhow::ensure!(!run.outcome.is_unsafe(), "the run was unsafe: {}", run.outcome.label());
    Ok(())
}

async fn bench(client: &FastrackClient, args: BenchArgs, json_mode: bool) -> anyhow::Result<()> {
    anyhow::ensure!(args.worlds > 0, "--worlds must be at least 1");
    anyhow::ensure!(args.jobs > 0, "--jobs must be at least 1");
    let shard = args.shard.unwrap_or(Shard::WHOLE);
    anyhow::ensure!(
        shard.is_whole() || args.part_dir.is_some(),
        "--shard {shard} writes a part: give --part-dir (merge the parts with `fastrack sim merge`)"
    );
    let simulator = args.simulation.connect(client, args.traces.is_some()).await?;
    if let Some(dir) = &args.traces {
        std::fs::create_dir_all(dir).with_context(|| format!("creating the traces folder {}", dir.display()))?;
    }
    let methods: Vec<Method> =
        args.methods.iter().map(|m| Method::parse(m)).collect::<Result<_, _>>().map_err(anyhow::Error::msg)?;
    let seeds: Vec<u64> = (1..=args.worlds).filter(|&seed| shard.takes(seed as usize - 1)).collect();
    let worlds: Vec<(u64, World)> = seeds
        .iter()
        .map(|&seed| Ok((seed, world_of(None, &args.generation, seed, simulator.steb_radius())?)))
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
    let config = json!({"model": args.simulation.model, "worlds": args.worlds, "methods": args.methods,
        "control_period_s": simulator.control_period(), "substeps": args.simulation.substeps,
        "sensor_range_m": simulator.sensor_range(), "time_limit_s": args.simulation.time_limit,
        "disturbance_m_s": args.simulation.disturbance, "state": simulator.state_names(),
        "world": {"size": args.generation.size, "density": args.generation.density, "size_range": args.generation.size_range,
            "feasible_for": args.generation.feasible_for}});
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

/// `fastrack sim merge`: the parts of a sharded benchmark, merged into the record a single run writes.
fn merge(args: MergeArgs, json_mode: bool) -> anyhow::Result<()> {
    let merged = BenchPart::merge(&args.part_dir, PART_STEM)?;
    let mut runs = merged.items;
    runs.sort_by_key(|r| (r.world, r.method));
    if let Some(path) = &args.visits {
        anyhow::ensure!(
            runs.iter().any(|r| !r.run.visits.is_empty()),
            "the parts in {} kept no visits: run the shards with --visits",
            args.part_dir.display()
        );
        write_visits(path, &merged.config, &runs, json_mode)?;
    }
    let command = format!(
        "fastrack sim merge --part-dir {}{}",
        args.part_dir.display(),
        args.recording.record.as_ref().map_or(String::new(), |name| format!(" --record {name}"))
    );
    report(&merged.config, &runs, merged.wall_s, &command, &args.recording, json_mode)
}

/// Writes the visits of `runs` (world by world) into `path` as CSV, the state columns named by the
/// benchmark's configuration.
fn write_visits(path: &Path, config: &serde_json::Value, runs: &[BenchRun], json_mode: bool) -> anyhow::Result<()> {
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

/// PF must never collide nor exceed its bound.
fn ensure_pf_safe(methods: &[Method], runs: &[BenchRun]) -> anyhow::Result<()> {
    let pf = methods.iter().position(|m| *m == Method::Parametric);
    let unsafe_runs: Vec<String> = runs
        .iter()
        .filter(|r| Some(r.method) == pf && r.run.outcome.is_unsafe())
        .map(|r| format!("world {}: {}", r.world, r.run.outcome.label()))
        .collect();
    anyhow::ensure!(unsafe_runs.is_empty(), "PF was unsafe: {}", unsafe_runs.join("; "));
    Ok(())
}

/// The benchmark's tables, ratios, record and figures, from its configuration and runs (a single run's or
/// merged parts').
fn report(
    config: &serde_json::Value,
    runs: &[BenchRun],
    wall_s: f64,
    command: &str,
    recording: &Recording,
    json_mode: bool,
) -> anyhow::Result<()> {
    let names: Vec<String> =
        serde_json::from_value(config["methods"].clone()).context("the configuration's methods")?;
    let methods: Vec<Method> =
        names.iter().map(|m| Method::parse(m)).collect::<Result<_, _>>().map_err(anyhow::Error::msg)?;
    let by_method = |m: usize| runs.iter().filter(|r| r.method == m).map(|r| &r.run).collect::<Vec<&Run>>();
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
    let paper = paper_comparison(&summaries);
    if let Some(name) = &recording.record {
        let shown: Vec<&Run> = runs.iter().filter(|r| r.world == FIGURE_WORLD).map(|r| &r.run).collect();
        let steb = shown.first().map(|r| r.steb_radius).context("the runs hold no run of the figure's world")?;
        let generation: Generation = serde_json::from_value(config["world"].clone()).context("the world settings")?;
        let world = world_of(None, &generation, FIGURE_WORLD, steb)?;
        let figure = recording.results_dir.join(format!("{name}-world{FIGURE_WORLD}.png"));
        std::fs::create_dir_all(&recording.results_dir)?;
        methods_on_one_world(&figure, &world, &shown).map_err(anyhow::Error::msg)?;
        let times_figure = recording.results_dir.join(format!("{name}-time-to-goal.png"));
        let labels: Vec<&str> = methods.iter().map(Method::label).collect();
        let by_method_runs: Vec<Vec<&Run>> = (0..methods.len()).map(by_method).collect();
        time_to_goal(&times_figure, &labels, &by_method_runs).map_err(anyhow::Error::msg)?;
        let path = write_record(
            &recording.results_dir,
            name,
            command,
            config.clone(),
            json!({"summaries": summaries.iter().map(summary_json).collect::<Vec<_>>(),
                   "pf_time_ratios": ratios.iter().map(|(l, r)| json!({"against": l, "ratio": r.map(|x| x.0), "worlds": r.map(|x| x.1)})).collect::<Vec<_>>(),
                   "paper_pf_over_f_ratio": 22.47 / 37.31, "wall_s": wall_s, "figure": figure,
                   "time_to_goal_figure": times_figure}),
            &[("Ours", &ours), ("The paper's Table 1 beside ours", &paper)],
        )?;
        eprintln!("record: {}", path.display());
    }
    print(json_mode, json!({"summaries": summaries.iter().map(summary_json).collect::<Vec<_>>()}), || {
        format!("{}\n{}\n{ratio_text}", ours.to_markdown(), paper.to_markdown())
    });
    ensure_pf_safe(&methods, runs)
}

async fn fleet(client: &FastrackClient, args: FleetArgs, json_mode: bool) -> anyhow::Result<()> {
    let simulator = args.simulation.connect(client, false).await?;
    let mut lines = Vec::new();
    let mut figures = Vec::new();
    for &robots in &args.robots {
        anyhow::ensure!(robots > 0, "--robots takes counts of at least 1");
        let worlds: Vec<World> = (1..=robots as u64)
            .map(|seed| world_of(None, &args.generation, seed, simulator.steb_radius()))
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
        let mut rows = fastrack_valuefn::record::MarkdownTable::new(&[
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

async fn world(client: &FastrackClient, args: WorldArgs, json_mode: bool) -> anyhow::Result<()> {
    let steb = args.generation.inflation(speeds(client, &args.model).await?[0].bound)?;
    let world = world_of(args.check.as_ref(), &args.generation, args.seed, steb)?;
    let text = world.to_toml();
    match (&args.check, &args.out) {
        (Some(path), _) => print(json_mode, json!({"world": path, "feasible_for_steb_m": steb}), || {
            format!("{}: valid, and a path keeps the sTEB ({steb:.3} m) from every obstacle", path.display())
        }),
        (None, Some(out)) => {
            if let Some(dir) = out.parent().filter(|d| !d.as_os_str().is_empty()) {
                std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
            }
            std::fs::write(out, &text).with_context(|| format!("writing {}", out.display()))?;
            print(json_mode, json!({"world": out, "obstacles": world.obstacles.len()}), || {
                format!("{}: {} obstacles, feasible for the sTEB ({steb:.3} m)", out.display(), world.obstacles.len())
            });
        }
        (None, None) => println!("{text}"),
    }
    Ok(())
}
