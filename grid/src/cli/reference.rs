//! `reference`: every row's ground-truth reference (grid solutions of the system or of its axes, closed forms)
//! written into a bundle, so that its served bounds never undercut the ground truth.

use anyhow::Context;
use fastrack_grid::format::load;
use fastrack_grid::reference::{set_references, SolvedBound};
use fastrack_valuefn::bundle::Bundle;
use fastrack_valuefn::system::decomposition;
use std::path::PathBuf;

/// Arguments of `reference`.
#[derive(clap::Args)]
pub struct Args {
    /// The bundle's version folder, e.g. `models/quad10d/1`.
    #[arg(long)]
    bundle: PathBuf,
    /// Grid solutions (`.ftgrid`, comma-separated) of the bundle's system, or of its axes' subsystems.
    #[arg(long, value_delimiter = ',')]
    grid_solutions: Vec<PathBuf>,
    /// Repository root the bundle is written into (`<out>/<name>/<version>/`; the bundle's own repository
    /// updates it in place).
    #[arg(long)]
    out: PathBuf,
}

/// Runs `reference`.
pub fn run(args: Args) -> anyhow::Result<()> {
    let bundle = Bundle::load(&args.bundle)?;
    let id = bundle.manifest.system.id.clone();
    let systems: Vec<String> = match decomposition(&id) {
        Some(axes) => axes.iter().map(|a| a.subsystem.to_string()).collect(),
        None => vec![id.clone()],
    };
    let mut solved = Vec::new();
    for path in &args.grid_solutions {
        let solution = load(path).with_context(|| format!("loading {}", path.display()))?;
        anyhow::ensure!(
            systems.contains(&solution.info.system),
            "{}: a solution of `{}`; {id}'s references come from {}",
            path.display(),
            solution.info.system,
            systems.join(", ")
        );
        let bound = SolvedBound::of(&solution);
        if let Some((other, _)) =
            solved.iter().find(|(_, b): &&(PathBuf, SolvedBound)| b.system == bound.system && b.beta == bound.beta)
        {
            anyhow::bail!(
                "two solutions of `{}` at beta {} ({} and {}); give one per beta",
                bound.system,
                bound.beta,
                other.display(),
                path.display()
            );
        }
        solved.push((path.clone(), bound));
    }
    let solved: Vec<SolvedBound> = solved.into_iter().map(|(_, bound)| bound).collect();
    let mut manifest = bundle.manifest.clone();
    let count = set_references(&id, &mut manifest.teb_table, &solved);
    println!("beta      verified  reference  bound    set by        reference from");
    for row in &manifest.teb_table {
        let reference = row.reference.as_ref();
        println!(
            "{:<8.4}  {:<8.4}  {:<9}  {:<7.4}  {:<12}  {}",
            row.beta,
            row.verified_bound(),
            reference.map_or("-".into(), |r| format!("{:.4}", r.bound)),
            row.bound(),
            row.bound_source().name(),
            reference.map_or("", |r| r.source.as_str())
        );
    }
    let dir = Bundle::write(&args.out, manifest, &bundle.onnx)?;
    println!("{count} of {} rows have a reference; wrote {}", bundle.manifest.teb_table.len(), dir.display());
    Ok(())
}
