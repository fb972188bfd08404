//! `bench`: grid points updated per second (per core) for a 4-D dubins4d solve at WENO5 + RK3, beside
//! hj_reachability on the same grid, system and scheme when a Python with it is given.

use super::common::{params_for, write_command_record};
use anyhow::{bail, Context};
use fastrack_grid::grid::Grid;
use fastrack_grid::integrate::{step, RkOrder, Workspace};
use fastrack_grid::scheme::Flux;
use fastrack_grid::solver::SolveFields;
use fastrack_grid::upwind::Accuracy;
use fastrack_lab::record::MarkdownTable;
use fastrack_valuefn::system::dubins4d;
use serde_json::{json, Value};
use std::path::PathBuf;
use std::time::Instant;

/// The hj_reachability reference script.
const HJ_SCRIPT: &str = include_str!("hj_bench.py");

/// Arguments of `bench`.
#[derive(clap::Args)]
pub struct Args {
    /// Nodes per axis of the 4-D grid.
    #[arg(long, default_value_t = 31)]
    resolution: usize,
    /// Timed RK3 steps (after one warm-up step).
    #[arg(long, default_value_t = 20)]
    steps: usize,
    /// Planner speed bound.
    #[arg(long, default_value_t = 1.25)]
    beta: f64,
    /// Timed rounds of each solver, interleaved; the median is reported.
    #[arg(long, default_value_t = 3)]
    rounds: usize,
    /// A Python interpreter with hj_reachability and jax installed (omit to skip the reference).
    #[arg(long)]
    hj_python: Option<PathBuf>,
    /// Record name.
    #[arg(long, default_value = "grid-bench")]
    record: String,
    /// Folder of measurement records.
    #[arg(long, default_value = "bench/results")]
    results_dir: PathBuf,
}

/// Point updates (one full RK3 step of one node) per second of ours.
fn ours(grid: &Grid, params: &[f64], steps: usize) -> f64 {
    let system = dubins4d::system();
    let fields = SolveFields::new(&system, params, grid);
    let scheme = fields.scheme(grid, Accuracy::Weno5, Flux::LaxFriedrichs, true);
    let dt = scheme.cfl_step(0.75);
    let mut values = fields.l.clone();
    let mut work = Workspace::new(grid.num_points());
    step(&scheme, RkOrder::Three, dt, &mut values, &mut work);
    let start = Instant::now();
    for _ in 0..steps {
        step(&scheme, RkOrder::Three, dt, &mut values, &mut work);
    }
    (grid.num_points() * steps) as f64 / start.elapsed().as_secs_f64()
}

/// Point updates per second of hj_reachability, from its script's JSON line.
fn reference(python: &PathBuf, args: &Args, half_width: f64, v_max: f64) -> anyhow::Result<Value> {
    let script = std::env::temp_dir().join(format!("fastrack-hj-bench-{}.py", std::process::id()));
    std::fs::write(&script, HJ_SCRIPT)?;
    let output = std::process::Command::new(python)
        .arg(&script)
        .args([args.resolution.to_string(), args.steps.to_string(), args.beta.to_string()])
        .args([half_width.to_string(), v_max.to_string()])
        .output()
        .with_context(|| format!("running {}", python.display()))?;
    let _ = std::fs::remove_file(&script);
    if !output.status.success() {
        bail!("hj_reachability bench failed: {}", String::from_utf8_lossy(&output.stderr));
    }
    let stdout = String::from_utf8_lossy(&output.stdout);
    let line = stdout.lines().last().context("hj_reachability bench printed nothing")?;
    Ok(serde_json::from_str(line)?)
}

fn median(mut xs: Vec<f64>) -> f64 {
    xs.sort_by(f64::total_cmp);
    xs[xs.len() / 2]
}

/// Runs `bench`.
pub fn run(args: Args) -> anyhow::Result<()> {
    if args.steps == 0 || args.rounds == 0 {
        bail!("--steps and --rounds must be positive");
    }
    let system = dubins4d::system();
    let grid = Grid::for_system(&system, &[args.resolution; 4])?;
    let params = params_for(&system, args.beta)?;
    let threads = rayon::current_num_threads();
    let (half_width, v_max) = (system.state[0].max, system.state[3].max);
    let (mut ours_rates, mut hj_rates, mut hj_info) = (Vec::new(), Vec::new(), Value::Null);
    for round in 0..args.rounds {
        let rate = ours(&grid, &params, args.steps);
        println!("round {round}: fastrack-grid {:.3e} point updates/s ({threads} threads)", rate);
        ours_rates.push(rate);
        if let Some(python) = &args.hj_python {
            let info = reference(python, &args, half_width, v_max)?;
            let rate = info["point_updates_per_s"].as_f64().context("no point_updates_per_s in the hj output")?;
            println!("round {round}: hj_reachability {rate:.3e} point updates/s");
            hj_rates.push(rate);
            hj_info = info;
        }
    }
    let cores = std::thread::available_parallelism().map_or(1, |n| n.get());
    let ours_rate = median(ours_rates.clone());
    let mut table = MarkdownTable::new(&["solver", "grid", "point updates/s", "per core", "ratio to hj_reachability"]);
    let grid_label = format!("{0}x{0}x{0}x{0}", args.resolution);
    let hj_rate = (!hj_rates.is_empty()).then(|| median(hj_rates.clone()));
    let ratio = hj_rate.map(|h| ours_rate / h);
    table.row(vec![
        "fastrack-grid (Rust, rayon, f64)".into(),
        grid_label.clone(),
        format!("{ours_rate:.3e}"),
        format!("{:.3e}", ours_rate / cores as f64),
        ratio.map_or("-".into(), |r| format!("{r:.2}")),
    ]);
    if let Some(h) = hj_rate {
        table.row(vec![
            "hj_reachability (JAX CPU, x64)".into(),
            grid_label,
            format!("{h:.3e}"),
            format!("{:.3e}", h / cores as f64),
            "1.00".into(),
        ]);
    }
    println!("{}", table.to_markdown());
    let config = json!({ "system": system.id, "beta": args.beta, "resolution": args.resolution, "steps": args.steps,
        "rounds": args.rounds, "scheme": "WENO5 + TVD-RK3, CFL 0.75, V <- max(V, l)", "threads": threads, "cores": cores,
        "update": "one full RK3 step (three stages) of one grid node" });
    let figures = json!({ "ours_point_updates_per_s": ours_rates, "ours_median": ours_rate,
        "ours_per_core": ours_rate / cores as f64, "hj_point_updates_per_s": hj_rates, "hj_median": hj_rate,
        "hj_per_core": hj_rate.map(|h| h / cores as f64), "ratio_ours_over_hj": ratio, "hj_run": hj_info });
    let path = write_command_record(&args.results_dir, &args.record, config, figures, &[("throughput", &table)])?;
    println!("wrote {}", path.display());
    Ok(())
}
