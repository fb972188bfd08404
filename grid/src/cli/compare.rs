//! `compare`: a model bundle against grid solutions, per `beta`, with PNG slices and a record.

use super::common::{command_line, SolveOptions, StudyOutputs};
use super::table::solve_or_load;
use anyhow::{bail, Context};
use fastrack_grid::compare::{compare, learned_on_grid, slices};
use fastrack_grid::slice_plot::slice_pair;
use fastrack_valuefn::bundle::Bundle;
use fastrack_valuefn::record::{write_record, Table};
use fastrack_valuefn::runtime::{runtime, Evaluator, GraphDims};
use serde_json::json;
use std::path::PathBuf;

/// Arguments of `compare`.
#[derive(clap::Args)]
pub struct Args {
    /// The bundle's version folder, e.g. `models/dubins4d/4`.
    #[arg(long)]
    bundle: PathBuf,
    #[command(flatten)]
    solve: SolveOptions,
    /// Planner speed bounds to compare at (grid solutions are loaded from --solutions-dir or solved).
    #[arg(long, value_delimiter = ',', default_value = "0.5,0.875,1.25")]
    betas: Vec<f64>,
    #[command(flatten)]
    outputs: StudyOutputs,
    /// Errors of V are taken over `{V_grid <= factor * V_min_grid}`.
    #[arg(long, default_value_t = 1.5)]
    sublevel_factor: f64,
    /// ONNX Runtime library (default: FASTRACK_ORT_LIB, then .cache/onnxruntime).
    #[arg(long)]
    ort_lib: Option<PathBuf>,
}

/// Runs `compare`.
pub fn run(args: Args) -> anyhow::Result<()> {
    let bundle = Bundle::load(&args.bundle)?;
    let manifest = &bundle.manifest;
    let solve = SolveOptions { system: manifest.system.id.clone(), ..args.solve.clone() };
    let system = solve.system()?;
    if !(args.sublevel_factor.is_finite() && args.sublevel_factor >= 1.0) {
        bail!("--sublevel-factor = {} must be at least 1", args.sublevel_factor);
    }
    let dims = GraphDims::of(manifest);
    let evaluator = Evaluator::new(runtime(args.ort_lib.as_deref())?, &bundle.onnx, dims, 1)?;
    let name = args.outputs.record.clone().unwrap_or_else(|| format!("grid-compare-{}", manifest.name));
    std::fs::create_dir_all(&args.outputs.results_dir)?;
    let mut table = Table::new(&[
        "beta",
        "grid V_min",
        "learned V_min (grid nodes)",
        "learned / grid",
        "table level",
        "mean |dV| on set",
        "max |dV| on set",
        "control = grid's on set",
        "control loss on set: mean / max",
        "set nodes",
        "slice",
    ]);
    let mut rows = Vec::new();
    for &beta in &args.betas {
        let solution = solve_or_load(&system, &solve, beta, &args.outputs.solutions_dir)?;
        let learned = learned_on_grid(&evaluator, &solution, &vec![beta; manifest.n_params()])?;
        let c = compare(&system, &solution, &learned, args.sublevel_factor);
        let s = slices(&solution, &learned.values);
        let png = args.outputs.results_dir.join(format!("{name}-beta{beta}.png"));
        let axes = solution.grid.axes();
        let title = format!(
            "{} beta {beta}: V in ({}, {}) at {:?}; white: V = {:.3}",
            manifest.name,
            axes[0].name,
            axes[1].name,
            s.cut.iter().map(|x| (x * 1000.0).round() / 1000.0).collect::<Vec<_>>(),
            c.set_level
        );
        slice_pair(&png, &title, [("grid", &s.grid), ("learned", &s.learned)], s.n0, s.n1, c.set_level)
            .context("drawing the slices")?;
        let level = manifest.teb_table.iter().find(|r| r.beta >= beta - 1e-9).map(|r| r.served_level());
        println!(
            "beta {beta}: grid V_min {:.4}, learned {:.4} (ratio {:.3}), mean/max |dV| on {{V_grid <= {:.3}}} {:.4}/{:.4}",
            c.grid_v_min, c.learned_v_min, c.ratio, c.set_level, c.mean_abs_error, c.max_abs_error
        );
        table.row(vec![
            beta.to_string(),
            format!("{:.4}", c.grid_v_min),
            format!("{:.4}", c.learned_v_min),
            format!("{:.3}", c.ratio),
            level.map_or("-".into(), |l| format!("{l:.4}")),
            format!("{:.4}", c.mean_abs_error),
            format!("{:.4}", c.max_abs_error),
            system
                .controls
                .iter()
                .zip(&c.control_agreement)
                .map(|(u, a)| format!("{} {:.1}%", u.name, 100.0 * a))
                .collect::<Vec<_>>()
                .join(", "),
            format!("{:.4} / {:.4}", c.mean_control_loss, c.max_control_loss),
            c.set_nodes.to_string(),
            png.file_name().map(|f| f.to_string_lossy().into_owned()).unwrap_or_default(),
        ]);
        rows.push(
            json!({ "comparison": c, "table_level": level, "slice_cut": s.cut, "plot": png.display().to_string(),
            "grid": solution.grid.axes(), "solver": solution.info.config, "horizon": solution.info.horizon,
            "converged": solution.info.converged }),
        );
    }
    let config = json!({ "bundle": args.bundle, "model": manifest.name, "version": manifest.version,
        "untrained": manifest.untrained, "betas": args.betas, "sublevel_factor": args.sublevel_factor, "solver": solve.config() });
    let path = write_record(
        &args.outputs.results_dir,
        &name,
        &command_line(),
        config,
        json!({ "rows": rows }),
        &[("learned vs grid", &table)],
    )?;
    println!("wrote {}", path.display());
    Ok(())
}
