//! `fastrack-trainer`: produces model bundles.

mod commands;

use clap::{Parser, Subcommand};
use commands::{bench, compose, export, plot_teb, random_bundle, train};

#[derive(Parser)]
#[command(name = "fastrack-trainer", version, about = "Produces fastrack model bundles")]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Writes a bundle from a seeded random (untrained) SIREN, marked untrained in its manifest: a
    /// stand-in for tests and demos until a trained model exists. Its bounds mean nothing.
    RandomBundle(random_bundle::Args),
    /// Trains a value function (DeepReach) from a TOML config, checkpointing into a run directory.
    Train(train::Args),
    /// Training-speed benchmark: the config's network and the paper's (3x512, 65,536 points), beside the
    /// machine's matmul rate and PyTorch; writes bench/results/trainer-speed.{json,md}.
    Bench(bench::Args),
    /// Exports a run's checkpoint as a model bundle (TEB table, manifest with provenance, reload check).
    Export(export::Args),
    /// Composes runs trained on the axes of a decomposed system (quad10d) into one bundle of the full system:
    /// `V = sqrt(sum V_a^2)` over the axes, each axis' network from the run trained on its subsystem.
    Compose(compose::Args),
    /// Draws a bundle's TEB table (bound, certified set level, measured `V_min`) against `beta`, with grid solutions'
    /// `V_min` beside it.
    PlotTeb(plot_teb::Args),
}

fn main() -> anyhow::Result<()> {
    tracing_subscriber::fmt()
        .with_env_filter(tracing_subscriber::EnvFilter::new("info"))
        .with_writer(std::io::stderr)
        .init();
    match Cli::parse().command {
        Command::RandomBundle(args) => random_bundle::run(args),
        Command::Train(args) => train::run(args),
        Command::Bench(args) => bench::run(args),
        Command::Export(args) => export::run(args),
        Command::Compose(args) => compose::run(args),
        Command::PlotTeb(args) => plot_teb::run(args),
    }
}
