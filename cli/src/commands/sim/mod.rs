//! `fastrack sim`: the navigation simulator against the server: `run` (one world, one method, a summary and
//! figures), `bench` (seeded worlds x methods, the paper's Table 1, a record), `fleet` (many robots on one
//! server at once), `world` (generate or check a world file) and `promise` (each served row's promise in
//! closed loop).

/// `$f::<O, D>(...)` (awaited after `async`) for the obstacle kind `O` of a world of `$dim` axes: the plane
/// (2) or space (3).
macro_rules! in_dimension {
    (async $dim:expr, $f:ident($($arg:expr),* $(,)?)) => {
        match $dim {
            2 => $f::<fastrack_online::geometry::PlaneObstacle, 2>($($arg),*).await,
            3 => $f::<fastrack_online::geometry::SpaceObstacle, 3>($($arg),*).await,
            other => Err(in_dimension!(@refused other)),
        }
    };
    ($dim:expr, $f:ident($($arg:expr),* $(,)?)) => {
        match $dim {
            2 => $f::<fastrack_online::geometry::PlaneObstacle, 2>($($arg),*),
            3 => $f::<fastrack_online::geometry::SpaceObstacle, 3>($($arg),*),
            other => Err(in_dimension!(@refused other)),
        }
    };
    (@refused $other:expr) => {
        anyhow::anyhow!("a planner of {} axes: the simulator flies in the plane (2) or in space (3)", $other)
    };
}

mod bench;
mod fleet;
mod merge;
mod promise;
mod run;
mod world;

use super::{print, Server};
use anyhow::Context as _;
use fastrack_client::{model_ref, FastrackClient};
use fastrack_sim::episode::{RunSettings, Simulator};
use fastrack_sim::tracker::Disturbance;
use fastrack_sim::world::{World, WorldFamily, WorldObstacle, WorldSpec};
use std::path::PathBuf;
use std::sync::Arc;

/// Arguments of `fastrack sim`.
#[derive(clap::Args)]
pub struct Args {
    #[command(subcommand)]
    command: SimCommand,
}

#[derive(clap::Subcommand)]
enum SimCommand {
    /// One world, one method: prints the run's summary and writes its figures.
    Run(run::Args),
    /// Seeded worlds x methods: the paper's Table 1 beside ours, a record and figures.
    Bench(bench::Args),
    /// Merges the parts of a sharded `sim bench` into the tables and record a single run gives.
    Merge(merge::Args),
    /// Parametric FaSTrack robots on seeded worlds, all at once on one server: ticks/s and latency.
    Fleet(fleet::Args),
    /// Generates a world from a seed, or checks a world file.
    World(world::Args),
    /// Each served row's promise in closed loop through `Track`: the largest error from starts across its
    /// certified set, against the worst case of the served gradient and random planners, beside its bound.
    Promise(promise::Args),
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
#[derive(clap::Args, serde::Serialize, serde::Deserialize)]
struct Generation {
    /// Workspace width and depth, and height for a model flying in space (m); default 30,20 (30,20,10).
    #[arg(long, value_delimiter = ',', num_args = 1)]
    #[serde(default)]
    size: Vec<f64>,
    /// Obstacles per 100 m^2 of ground.
    #[arg(long, default_value_t = 2.0)]
    density: f64,
    /// Smallest and largest obstacle size (m): radius, half side (geometric mean), quarter of a wall's length.
    #[arg(long, value_delimiter = ',', default_value = "0.4,1.5", num_args = 1)]
    size_range: Vec<f64>,
    /// The kind of world: scattered (obstacles of random kinds, --density and --size-range), dense (three
    /// times as many, half the size), narrow (walls across with one narrow gap each), open (a few large
    /// obstacles) or pop-up (obstacles on the shortest path beyond --popup-beyond, sensed late).
    #[arg(long, default_value = "scattered")]
    #[serde(default)]
    family: WorldFamily,
    /// Pop-up obstacles lie farther than this from the start (m), beyond the sensor's reach at the start.
    #[arg(long, default_value_t = 6.0)]
    #[serde(default = "default_popup_beyond")]
    popup_beyond: f64,
    /// Worlds (generated or checked) must be feasible for this sTEB (m) instead of the model's, so that
    /// models of different bounds run on the same worlds; at least the model's sTEB.
    #[arg(long)]
    #[serde(default)]
    feasible_for: Option<f64>,
}

fn default_popup_beyond() -> f64 {
    WorldSpec::<2>::default().popup_beyond
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

    /// The settings as a record states them, from which the same worlds are generated again: every one,
    /// the size resolved to the default's where none was given.
    fn recorded<const D: usize>(&self) -> anyhow::Result<serde_json::Value> {
        let mut value = serde_json::to_value(self)?;
        if self.size.is_empty() {
            value["size"] = serde_json::json!(WorldSpec::<D>::default().size.to_vec());
        }
        Ok(value)
    }

    fn spec<const D: usize>(&self, seed: u64, inflation: f64) -> anyhow::Result<WorldSpec<D>> {
        let &[lo, hi] = self.size_range.as_slice() else {
            anyhow::bail!("--size-range takes two numbers, e.g. --size-range 0.4,1.5");
        };
        let size = match self.size.as_slice() {
            [] => WorldSpec::<D>::default().size,
            given => given.try_into().map_err(|_| {
                anyhow::anyhow!(
                    "--size takes {D} numbers for this model, e.g. {}; got {given:?}",
                    ["30,20", "30,20,6"][D - 2]
                )
            })?,
        };
        Ok(WorldSpec {
            seed,
            family: self.family,
            popup_beyond: self.popup_beyond,
            size,
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
/// Runs `fastrack sim ...`.
pub async fn run_command(server: &Server, args: Args, json_mode: bool) -> anyhow::Result<()> {
    match args.command {
        SimCommand::Run(args) => run::run(&server.connect().await?, args, json_mode).await,
        SimCommand::Bench(args) => bench::run(&server.connect().await?, args, json_mode).await,
        SimCommand::Merge(args) => merge::run(args, json_mode),
        SimCommand::Fleet(args) => fleet::run(&server.connect().await?, args, json_mode).await,
        SimCommand::World(args) => world::run(&server.connect().await?, args, json_mode).await,
        SimCommand::Promise(args) => promise::run(&server.connect().await?, args, json_mode).await,
    }
}

/// The world of a run in `D` axes: the file, or the seed's generated world.
fn world_of<O: WorldObstacle<D>, const D: usize>(
    file: Option<&PathBuf>,
    generation: &Generation,
    seed: u64,
    steb: f64,
) -> anyhow::Result<World<O, D>> {
    let inflation = generation.inflation(steb)?;
    let world = match file {
        Some(path) => World::load(path)?,
        None => generation.spec(seed, inflation)?.generate()?,
    };
    world.check_feasible(inflation).context("the world is not feasible for the sTEB")?;
    Ok(world)
}
