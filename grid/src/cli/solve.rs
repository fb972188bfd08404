//! `solve`: one tracking value function, saved, with its TEB printed.

use super::common::{command_line, params_for, SolveOptions};
use fastrack_grid::analysis::{teb, EXTENT_REL_TOL};
use fastrack_grid::format::save;
use fastrack_grid::solver::solve;
use std::path::PathBuf;

/// Arguments of `solve`.
#[derive(clap::Args)]
pub struct Args {
    #[command(flatten)]
    solve: SolveOptions,
    /// Planner speed bound (every parameter set to it).
    #[arg(long)]
    beta: f64,
    /// Solution file to write (`.ftgrid`, see README).
    #[arg(long)]
    output: Option<PathBuf>,
}

/// Runs `solve`.
pub fn run(args: Args) -> anyhow::Result<()> {
    let system = args.solve.system()?;
    let grid = args.solve.grid(&system)?;
    let params = params_for(&system, args.beta)?;
    tracing::info!(system = system.id, beta = args.beta, points = grid.num_points(), command = %command_line(), "solving");
    let solution = solve(&system, &params, &grid, &args.solve.config(), true)?;
    let teb = teb(&solution, &system, EXTENT_REL_TOL);
    let info = &solution.info;
    println!(
        "system {}  beta {}  grid {:?}  {} {}-RK",
        system.id,
        args.beta,
        grid.axes().iter().map(|a| a.n).collect::<Vec<_>>(),
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
    if let Some(path) = &args.output {
        save(&solution, path)?;
        println!("wrote {}", path.display());
    }
    Ok(())
}
