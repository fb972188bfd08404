//! Subcommands of `fastrack-grid`.

mod bench;
mod common;
mod compare;
mod horizon;
mod reference;
mod reshape;
mod rollout;
mod solve;
mod teb_table;
mod verify;
mod verify_bench;
mod verify_merge;

use clap::{Parser, Subcommand};

/// Command line of `fastrack-grid`.
#[derive(Parser)]
#[command(
    name = "fastrack-grid",
    version,
    about = "Grid Hamilton-Jacobi solver: ground truth, TEB tables, model comparison and verification"
)]
pub struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Solves one tracking value function and prints its TEB (V_min, extent, converged horizon, wall time).
    Solve(solve::Args),
    /// TEB table over beta (classic FaSTrack bound at beta_u, Meta-FaSTrack levels) across resolutions and
    /// accuracies, with V_min-vs-horizon and V_min-vs-resolution plots and a record under bench/results/.
    TebTable(teb_table::Args),
    /// V_min and max |dV/dtau| by region (grid, interior, sublevel set) against the horizon, across resolutions
    /// and beta, with the horizon at which the sublevel-set rate settles; plots and a record.
    Horizon(horizon::Args),
    /// A model bundle against grid solutions: learned vs grid V_min per beta, errors of V over the grid's
    /// sublevel set, PNG slices of both value functions through the grid's minimiser.
    Compare(compare::Args),
    /// Scenario verification of a bundle's TEB table (rollouts of the served control from its sublevel sets);
    /// writes verified levels into a copy of the bundle.
    Verify(verify::Args),
    /// Merges the parts of a sharded `verify` into the verified bundle and the record a single run writes.
    VerifyMerge(verify_merge::Args),
    /// Every row's ground-truth reference (grid solutions of the system or its axes, closed forms), written
    /// into the bundle: its served bounds never undercut it.
    Reference(reference::Args),
    /// Measures a bundle's error-set shapes (extent, boundary radii) again at each row's set level.
    Reshape(reshape::Args),
    /// What a verification's rollouts cost per state and step, one state per call against batched on every
    /// core, with the projected wall time of a row and a table; a record.
    VerifyBench(verify_bench::Args),
    /// What adversarial planners sustain against grid solutions' own tracker policies (an independent check of
    /// their V_min by simulation), with a plot against beta and a record.
    Rollout(rollout::Args),
    /// Throughput of a 4-D WENO5 + RK3 solve (points updated per second per core), beside hj_reachability.
    Bench(bench::Args),
}

/// Runs the chosen subcommand.
pub fn run(cli: Cli) -> anyhow::Result<()> {
    match cli.command {
        Command::Solve(args) => solve::run(args),
        Command::TebTable(args) => teb_table::run(args),
        Command::Horizon(args) => horizon::run(args),
        Command::Compare(args) => compare::run(args),
        Command::Verify(args) => verify::run(args),
        Command::VerifyMerge(args) => verify_merge::run(args),
        Command::Reference(args) => reference::run(args),
        Command::Reshape(args) => reshape::run(args),
        Command::VerifyBench(args) => verify_bench::run(args),
        Command::Rollout(args) => rollout::run(args),
        Command::Bench(args) => bench::run(args),
    }
}
