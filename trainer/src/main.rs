//! `fastrack-trainer`: produces model bundles.

mod export;

use anyhow::Context;
use clap::{Parser, Subcommand};
use fastrack_valuefn::manifest::Provenance;
use fastrack_valuefn::network::ValueNetwork;
use fastrack_valuefn::system::{by_id, SYSTEM_IDS};
use fastrack_valuefn::teb::TebOptions;
use std::collections::BTreeMap;
use std::path::PathBuf;

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
    RandomBundle {
        /// System id.
        #[arg(long, default_value = "dubins4d")]
        system: String,
        /// Model name (should say that it is untrained).
        #[arg(long, default_value = "untrained-dubins4d")]
        name: String,
        /// Model version.
        #[arg(long, default_value_t = 1)]
        version: u32,
        /// Hidden layer widths, comma separated.
        #[arg(long, value_delimiter = ',', default_value = "256,256,256")]
        hidden: Vec<usize>,
        /// Random seed.
        #[arg(long, default_value_t = 7)]
        seed: u64,
        /// Horizon fixed in the graph (s).
        #[arg(long, default_value_t = 1.0)]
        horizon: f64,
        /// Constant added to the network output, so that `V = l + tau (offset + NN)` stays positive like a
        /// real value function (a random SIREN alone averages zero). Still meaningless as a bound.
        #[arg(long, default_value_t = 0.5)]
        output_offset: f64,
        /// Repository root to write into.
        #[arg(long, default_value = "models")]
        out: PathBuf,
    },
}

fn main() -> anyhow::Result<()> {
    tracing_subscriber::fmt()
        .with_env_filter(tracing_subscriber::EnvFilter::new("info"))
        .with_writer(std::io::stderr)
        .init();
    match Cli::parse().command {
        Command::RandomBundle { system, name, version, hidden, seed, horizon, output_offset, out } => {
            let system = by_id(&system)
                .with_context(|| format!("unknown system {system:?}; known: {}", SYSTEM_IDS.join(", ")))?;
            anyhow::ensure!(
                !hidden.is_empty() && hidden.iter().all(|&w| w > 0),
                "--hidden needs at least one positive width"
            );
            anyhow::ensure!(horizon.is_finite() && horizon > 0.0, "--horizon must be > 0");
            let mut network = ValueNetwork::random(&system, &hidden, 30.0, horizon, true, seed);
            network.output_offset = output_offset;
            let config = serde_json::json!({
                "system": system.id, "hidden": hidden, "omega_0": 30.0, "seed": seed, "horizon": horizon,
                "exact_boundary": true, "output_offset": output_offset,
            });
            let provenance = Provenance {
                method: "random-init (SIREN initialisation, untrained)".into(),
                config,
                iterations: 0,
                final_losses: BTreeMap::new(),
                wall_time_s: 0.0,
                machine: String::new(),
                source_revision: String::new(),
                created: String::new(),
            };
            let request = export::ExportRequest {
                network: &network,
                system: &system,
                horizon,
                name: &name,
                version,
                untrained: true,
                provenance,
                teb: TebOptions::default(),
            };
            let dir = export::export(&out, request)?;
            println!("{}", dir.display());
        }
    }
    Ok(())
}
