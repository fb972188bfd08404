//! `reshape`: a bundle's error-set shapes measured again at each row's set level.

use super::verify::{BundleSource, Loaded};
use fastrack_valuefn::bundle::Bundle;
use fastrack_valuefn::teb::{reshape_at_set_levels, TebOptions};
use std::path::PathBuf;

/// Arguments of `reshape`.
#[derive(clap::Args)]
pub struct Args {
    #[command(flatten)]
    source: BundleSource,
    /// Repository root the reshaped bundle is written into (`<out>/<name>/<version>/`; the bundle's own
    /// repository rewrites it in place).
    #[arg(long)]
    out: PathBuf,
}

/// Runs `reshape`: every row's extent, boundary radii and nested share measured again at its set level, as
/// verification leaves them, for a bundle whose shapes were measured at another level.
pub fn run(args: Args) -> anyhow::Result<()> {
    let Loaded { bundle, system, evaluator } = args.source.load()?;
    let mut manifest = bundle.manifest.clone();
    reshape_at_set_levels(&evaluator, &system, &mut manifest.teb_table, &TebOptions::default())
        .map_err(anyhow::Error::msg)?;
    for (before, after) in bundle.manifest.teb_table.iter().zip(&manifest.teb_table) {
        println!(
            "beta {:.4}: set level {:.4}, bound {:.4}; extent {:?} -> {:?}; in the next row's set {}",
            after.beta,
            after.set_level(),
            after.bound(),
            before.extent.iter().map(|x| format!("{x:.3}")).collect::<Vec<_>>(),
            after.extent.iter().map(|x| format!("{x:.3}")).collect::<Vec<_>>(),
            after.nested_share.map_or("-".into(), |s| format!("{s:.3}"))
        );
    }
    let dir = Bundle::write(&args.out, manifest, &bundle.onnx)?;
    println!("wrote the reshaped bundle {}", dir.display());
    Ok(())
}
