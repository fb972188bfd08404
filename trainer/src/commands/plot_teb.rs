//! `plot-teb`: a bundle's TEB table against `beta`, with grid solutions' `V_min` beside it.

use anyhow::Context;
use std::path::PathBuf;

/// Arguments of `plot-teb`.
#[derive(clap::Args)]
pub struct Args {
    /// The bundle's version folder, e.g. `models/dubins4d/5`.
    #[arg(long)]
    bundle: PathBuf,
    /// Grid solution files (`.ftgrid`) whose `V_min` is drawn as the reference.
    #[arg(long = "grid-solution")]
    grid_solutions: Vec<PathBuf>,
    /// The PNG to write.
    #[arg(long)]
    out: PathBuf,
}

/// Runs `plot-teb`.
pub fn run(args: Args) -> anyhow::Result<()> {
    let manifest = fastrack_valuefn::bundle::Bundle::load(&args.bundle)?.manifest;
    let mut grid = args
        .grid_solutions
        .iter()
        .map(|path| {
            let solution = fastrack_gridfile::format::load(path)?;
            let beta = solution.info.params.first().copied().context("a solution without parameters")?;
            Ok((beta, solution.v_min()))
        })
        .collect::<anyhow::Result<Vec<_>>>()?;
    grid.sort_by(|a, b| a.0.total_cmp(&b.0));
    fastrack_trainer::report::plot_teb(&args.out, &manifest.teb_table, &[("grid V_min", grid)])?;
    println!("{}", args.out.display());
    Ok(())
}
