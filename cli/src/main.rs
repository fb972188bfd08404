//! `fastrack`: command-line client of the fastrack safety service, one subcommand per RPC, human-readable
//! or `--json` output.

mod commands;

use clap::Parser;

#[tokio::main]
async fn main() -> anyhow::Result<()> {
    commands::run(commands::Cli::parse()).await
}
