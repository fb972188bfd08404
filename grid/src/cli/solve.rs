//! `solve`: one tracking value function, saved, with its TEB printed; or every grid solution a training
//! config is supervised by, the missing ones solved into its store.

use super::common::{command_line, params_for, SolveOptions};
use anyhow::Context;
use fastrack_grid::analysis::{teb, EXTENT_REL_TOL};
use fastrack_grid::format::save;
use fastrack_grid::solver::{solve, Solution};
use fastrack_grid::spec::{SolutionStore, SolveSeries, DEFAULT_STORE};
use fastrack_grid::store::{solve_or_load, SolutionSource};
use fastrack_valuefn::system::AffineSystem;
use std::path::{Path, PathBuf};

/// Arguments of `solve`.
#[derive(clap::Args)]
pub struct Args {
    #[command(flatten)]
    solve: SolveOptions,
    /// Planner speed bound (every parameter set to it).
    #[arg(long, required_unless_present = "config")]
    beta: Option<f64>,
    /// Solution file to write (`.ftgrid`, see README).
    #[arg(long, conflicts_with = "config")]
    output: Option<PathBuf>,
    /// A training config (TOML): solve every grid solution its `[supervision.solutions]` names that its
    /// store (`supervision.store`, default `target/grid-solutions`) lacks; the solve options are its.
    #[arg(long, conflicts_with = "beta")]
    config: Option<PathBuf>,
}

/// Runs `solve`.
pub fn run(args: Args) -> anyhow::Result<()> {
    if let Some(config) = &args.config {
        return solve_config(config);
    }
    let beta = args.beta.context("--beta is required without --config")?;
    let spec = args.solve.spec(beta)?;
    let (system, grid) = (spec.system()?, spec.grid()?);
    let params = params_for(&system, beta)?;
    tracing::info!(system = system.id, beta, points = grid.num_points(), command = %command_line(), "solving");
    let solution = solve(&system, &params, &grid, &spec.solver, true)?;
    print_teb(&system, &solution);
    if let Some(path) = &args.output {
        save(&solution, path)?;
        println!("wrote {}", path.display());
    }
    Ok(())
}

/// Solves what a training config's store lacks of its supervision's solutions.
fn solve_config(path: &Path) -> anyhow::Result<()> {
    let text = std::fs::read_to_string(path).with_context(|| format!("reading {}", path.display()))?;
    let config: toml::Value = toml::from_str(&text).with_context(|| format!("parsing {}", path.display()))?;
    let supervision = config
        .get("supervision")
        .with_context(|| format!("{}: no [supervision]: the run is supervised by no grid solution", path.display()))?;
    let series: SolveSeries = supervision
        .get("solutions")
        .with_context(|| format!("{}: no [supervision.solutions]", path.display()))?
        .clone()
        .try_into()
        .with_context(|| format!("{}: [supervision.solutions]", path.display()))?;
    let dir = match supervision.get("store") {
        Some(dir) => PathBuf::from(dir.as_str().with_context(|| format!("{}: supervision.store", path.display()))?),
        None => PathBuf::from(DEFAULT_STORE),
    };
    let store = SolutionStore::new(dir);
    for spec in series.specs() {
        let system = spec.system()?;
        let (solution, source) = solve_or_load(&store, &spec, true)?;
        let verb = match source {
            SolutionSource::Store => "kept",
            SolutionSource::Solver => "solved",
        };
        println!("{verb} {}", store.path(&spec).display());
        print_teb(&system, &solution);
    }
    Ok(())
}

/// Prints a solution's TEB and how its solve went.
fn print_teb(system: &AffineSystem, solution: &Solution) {
    let teb = teb(solution, system, EXTENT_REL_TOL);
    let info = &solution.info;
    println!(
        "system {}  beta {:?}  grid {:?}  {} {}-RK",
        system.id,
        info.params,
        solution.grid.axes().iter().map(|a| a.n).collect::<Vec<_>>(),
        info.config.accuracy,
        info.config.rk
    );
    println!("V_min {:.5}  at {:?}", teb.v_min, teb.argmin.iter().map(|x| (x * 1e4).round() / 1e4).collect::<Vec<_>>());
    println!("extent of {{V <= V_min (1 + {})}}: {:?} ({} nodes)", teb.rel_tol, teb.extent, teb.set_nodes);
    println!(
        "horizon {:.3} s ({}, last tested max|dV/dtau| {:.2e}{}, tolerance {:.1e}), {} steps of {:.5} s, wall {:.1} s",
        info.horizon,
        if info.converged { "converged" } else { "NOT converged: horizon cap reached" },
        info.tested_rate().unwrap_or(f64::NAN),
        if info.config.rate_window > 0.0 { format!(" over {} s", info.config.rate_window) } else { String::new() },
        info.config.tolerance,
        info.steps,
        info.dt,
        info.wall_s
    );
}
