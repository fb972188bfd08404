//! `compose`: runs trained on the axes of a decomposed system (quad10d) as one bundle of the full system.

use anyhow::Context;
use fastrack_trainer::export::{self, provenance_here_and_now};
use fastrack_trainer::train::{checkpoint_network, RunDir};
use fastrack_valuefn::composite::{AxisNetwork, Composite};
use fastrack_valuefn::system::{by_id, decomposition, SYSTEM_IDS};
use fastrack_valuefn::teb::TebOptions;
use std::collections::BTreeMap;
use std::path::PathBuf;

/// Arguments of `compose`.
#[derive(clap::Args)]
pub struct Args {
    /// The decomposed system.
    #[arg(long, default_value = "quad10d")]
    system: String,
    /// A run directory per subsystem (repeatable); an axis takes the run of its subsystem (quad10d's x and y
    /// axes share one).
    #[arg(long = "axis-run", required = true)]
    axis_runs: Vec<PathBuf>,
    /// Model name.
    #[arg(long, default_value = "quad10d")]
    name: String,
    /// Model version.
    #[arg(long, default_value_t = 1)]
    version: u32,
    /// Repository root to write into.
    #[arg(long, default_value = "models")]
    out: PathBuf,
}

/// Runs `compose`.
pub fn run(args: Args) -> anyhow::Result<()> {
    let dir = compose(&args.system, &args.axis_runs, &args.name, args.version, &args.out)?;
    println!("{}", dir.display());
    Ok(())
}

/// `compose`: the axes' runs of a decomposed system exported as one composite bundle.
fn compose(
    id: &str,
    axis_runs: &[PathBuf],
    name: &str,
    version: u32,
    out: &std::path::Path,
) -> anyhow::Result<PathBuf> {
    let system = by_id(id).with_context(|| format!("unknown system {id:?}; known: {}", SYSTEM_IDS.join(", ")))?;
    let axes = decomposition(id).with_context(|| format!("system {id:?} has no decomposition into axes"))?;
    let device = burn::tensor::Device::flex();
    let mut runs = Vec::new();
    for dir in axis_runs {
        let run = RunDir(dir.clone());
        let (network, state) = checkpoint_network(&run, &device)?;
        runs.push((dir.clone(), network, state));
    }
    let mut networks = Vec::new();
    for axis in &axes {
        let mut matching = runs.iter().filter(|(_, _, s)| s.config.system == axis.subsystem);
        let (_, network, state) = matching
            .next()
            .with_context(|| format!("no --axis-run was trained on `{}` (an axis of {id})", axis.subsystem))?;
        if let Some((other, _, _)) = matching.next() {
            anyhow::bail!("two runs were trained on `{}`; give one ({})", axis.subsystem, other.display());
        }
        let subsystem = state.config.system()?;
        networks.push(AxisNetwork {
            axis: axis.clone(),
            subsystem,
            network: network.clone(),
            tau: state.config.sampling.tau_max,
        });
    }
    if let Some((dir, _, state)) = runs.iter().find(|(_, _, s)| !axes.iter().any(|a| a.subsystem == s.config.system)) {
        anyhow::bail!("{} was trained on `{}`, which is not an axis of {id}", dir.display(), state.config.system);
    }
    let composite = Composite::new(system.clone(), networks)?;
    let configs: Vec<serde_json::Value> =
        runs.iter().map(|(_, _, s)| serde_json::to_value(&s.config)).collect::<Result<_, _>>()?;
    let provenance = provenance_here_and_now(
        format!(
            "DeepReach per axis of {id} ({} runs, supervised by grid solutions where configured), burn",
            runs.len()
        ),
        serde_json::json!({ "axes": configs }),
        runs.iter().map(|(_, _, s)| s.iteration).sum(),
        BTreeMap::new(),
        runs.iter().map(|(_, _, s)| s.wall_time_s).sum(),
    );
    let request = export::ExportRequest {
        model: export::ExportedModel::Composite(&composite),
        system: &system,
        name,
        version,
        untrained: false,
        provenance,
        teb: TebOptions::default(),
    };
    export::export(out, request)
}
