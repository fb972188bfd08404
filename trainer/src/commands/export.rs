//! `export`: a run's checkpoint as a model bundle (TEB table, manifest with provenance, reload check).

use fastrack_trainer::export::{self, provenance_here_and_now};
use fastrack_trainer::train::{checkpoint_network, RunDir};
use fastrack_valuefn::teb::TebOptions;
use std::collections::BTreeMap;
use std::path::PathBuf;

/// Arguments of `export`.
#[derive(clap::Args)]
pub struct Args {
    /// Run directory.
    #[arg(long)]
    run_dir: PathBuf,
    /// Repository root to write into.
    #[arg(long, default_value = "models")]
    out: PathBuf,
}

/// Runs `export`; draws the exported table into the run directory (`teb.png`).
pub fn run(args: Args) -> anyhow::Result<()> {
    let run = RunDir(args.run_dir);
    let (network, state) = checkpoint_network(&run, &burn::tensor::Device::flex())?;
    let system = state.config.system()?;
    let losses = state.last_losses.clone().unwrap_or_default();
    let loss = |i: usize| losses.get(i).copied().unwrap_or(0.0);
    let provenance = provenance_here_and_now(
        format!(
            "DeepReach ({:?} loss, {:?} parameters{}), burn",
            state.config.loss.form,
            state.config.parameter_mode,
            if state.config.supervision.is_some() { ", supervised by grid solutions" } else { "" }
        ),
        serde_json::to_value(&state.config)?,
        state.iteration,
        BTreeMap::from([
            ("total".into(), loss(0)),
            ("boundary".into(), loss(1)),
            ("residual".into(), loss(2)),
            ("supervision".into(), loss(3)),
            ("supervision_gradient".into(), loss(4)),
        ]),
        state.wall_time_s,
    );
    let request = export::ExportRequest {
        model: export::ExportedModel::Network { network: &network, horizon: state.config.sampling.tau_max },
        system: &system,
        name: &state.config.export.name,
        version: state.config.export.version,
        untrained: false,
        provenance,
        teb: TebOptions::default(),
    };
    let dir = export::export(&args.out, request)?;
    let manifest = fastrack_valuefn::bundle::Bundle::load(&dir)?.manifest;
    fastrack_trainer::report::plot_teb(&run.0.join("teb.png"), &manifest.teb_table, &[])?;
    println!("{}", dir.display());
    Ok(())
}
