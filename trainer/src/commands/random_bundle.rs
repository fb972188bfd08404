//! `random-bundle`: a bundle from a seeded random (untrained) SIREN.

use anyhow::Context;
use fastrack_trainer::export::{self, provenance_here_and_now};
use fastrack_valuefn::network::{NetworkShape, ValueNetwork};
use fastrack_valuefn::system::{by_id, SYSTEM_IDS};
use fastrack_valuefn::teb::TebOptions;
use std::collections::BTreeMap;
use std::path::PathBuf;

/// Arguments of `random-bundle`.
#[derive(clap::Args)]
pub struct Args {
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
}

/// Runs `random-bundle`.
pub fn run(args: Args) -> anyhow::Result<()> {
    let Args { system, name, version, hidden, seed, horizon, output_offset, out } = args;
    let system =
        by_id(&system).with_context(|| format!("unknown system {system:?}; known: {}", SYSTEM_IDS.join(", ")))?;
    anyhow::ensure!(!hidden.is_empty() && hidden.iter().all(|&w| w > 0), "--hidden needs at least one positive width");
    anyhow::ensure!(horizon.is_finite() && horizon > 0.0, "--horizon must be > 0");
    let mut network = ValueNetwork::random(&system, &NetworkShape::new(&hidden, 30.0, true), horizon, seed);
    network.output_offset = output_offset;
    let config = serde_json::json!({
        "system": system.id, "hidden": hidden, "omega_0": 30.0, "seed": seed, "horizon": horizon,
        "exact_boundary": true, "output_offset": output_offset,
    });
    let provenance =
        provenance_here_and_now("random-init (SIREN initialisation, untrained)", config, 0, BTreeMap::new(), 0.0);
    let request = export::ExportRequest {
        model: export::ExportedModel::Network { network: &network, horizon },
        system: &system,
        name: &name,
        version,
        untrained: true,
        provenance,
        teb: TebOptions::default(),
    };
    let dir = export::export(&out, request)?;
    println!("{}", dir.display());
    Ok(())
}
