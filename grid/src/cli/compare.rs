//! `compare`: a model bundle against grid solutions, per `beta`, with PNG slices and a record. A bundle of a
//! decomposed system (quad10d) is compared along each of its axes with the combined ground truth of the
//! axes' solutions (`--axis-solutions`).

use super::common::{axes_at, load_axis_solutions, write_command_record, SolveOptions, StudyOutputs};
use anyhow::{bail, Context};
use fastrack_grid::compare::{
    combined_on_axis, compare, learned_on_axis, learned_on_grid, slices, Comparison, Learned, Slices,
};
use fastrack_grid::slice_plot::slice_pair;
use fastrack_grid::solver::Solution;
use fastrack_lab::record::MarkdownTable;
use fastrack_valuefn::bundle::Bundle;
use fastrack_valuefn::manifest::Manifest;
use fastrack_valuefn::runtime::{runtime, Evaluator, GraphDims};
use fastrack_valuefn::system::{by_id, decomposition, AffineSystem, DecomposedAxis};
use serde_json::json;
use std::path::{Path, PathBuf};

/// Arguments of `compare`.
#[derive(clap::Args)]
pub struct Args {
    /// The bundle's version folder, e.g. `models/dubins4d/5`.
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
    /// For a bundle of a decomposed system (quad10d): its axes' solution files (`.ftgrid`), comma separated,
    /// one per axis subsystem and `beta`. Each axis is compared with the combined ground truth
    /// `sqrt(sum V_axis^2)` on its own grid, the other axes at their minimisers; --betas and the solve options
    /// are not used.
    #[arg(long, value_delimiter = ',')]
    axis_solutions: Vec<PathBuf>,
}

/// The table's columns after `beta` (and the axis, for a decomposed system).
const COLUMNS: [&str; 10] = [
    "grid V_min",
    "learned V_min (grid nodes)",
    "learned / grid",
    "table bound",
    "mean |dV| on set",
    "max |dV| on set",
    "control = grid's on set",
    "control loss on set: mean / max",
    "set nodes",
    "slice",
];

/// The error bound the bundle serves at `beta`: its first row at or above it.
fn table_bound(manifest: &Manifest, beta: f64) -> Option<f64> {
    manifest.teb_table.iter().find(|r| r.beta >= beta - 1e-9).map(|r| r.bound())
}

/// A table row's cells after `beta`.
fn cells(system: &AffineSystem, c: &Comparison, bound: Option<f64>, png: &Path) -> Vec<String> {
    vec![
        format!("{:.4}", c.grid_v_min),
        format!("{:.4}", c.learned_v_min),
        format!("{:.3}", c.ratio),
        bound.map_or("-".into(), |b| format!("{b:.4}")),
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
    ]
}

/// Compares `learned` with `solution` (of `system`), draws the slices into `png` under `title` and prints
/// a line; returns the comparison and its slices.
fn compare_and_draw(
    system: &AffineSystem,
    solution: &Solution,
    learned: &Learned,
    sublevel_factor: f64,
    png: &Path,
    title: &str,
) -> anyhow::Result<(Comparison, Slices)> {
    let c = compare(system, solution, learned, sublevel_factor);
    let s = slices(solution, &learned.values);
    let axes = solution.grid.axes();
    let plot_title = format!(
        "{title}: V in ({}, {}) at {:?}; white: V = {:.3}",
        axes[0].name,
        axes[1].name,
        s.cut.iter().map(|x| (x * 1000.0).round() / 1000.0).collect::<Vec<_>>(),
        c.set_level
    );
    slice_pair(png, &plot_title, [("grid", &s.grid), ("learned", &s.learned)], s.n0, s.n1, c.set_level)
        .context("drawing the slices")?;
    println!(
        "{title}: grid V_min {:.4}, learned {:.4} (ratio {:.3}), mean/max |dV| on {{V_grid <= {:.3}}} {:.4}/{:.4}",
        c.grid_v_min, c.learned_v_min, c.ratio, c.set_level, c.mean_abs_error, c.max_abs_error
    );
    Ok((c, s))
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
    if let Some(axes) = decomposition(&manifest.system.id) {
        return run_axes(&args, &bundle, &evaluator, &axes, &name);
    }
    let mut table = MarkdownTable::new(&[&["beta"][..], &COLUMNS].concat());
    let mut rows = Vec::new();
    for &beta in &args.betas {
        let solution = solve.solve_or_load(beta, &args.outputs.solutions_dir)?;
        let learned = learned_on_grid(&evaluator, &solution, &vec![beta; manifest.n_params()])?;
        let png = args.outputs.results_dir.join(format!("{name}-beta{beta}.png"));
        let title = format!("{} beta {beta}", manifest.name);
        let (c, s) = compare_and_draw(&system, &solution, &learned, args.sublevel_factor, &png, &title)?;
        let bound = table_bound(manifest, beta);
        table.row([vec![beta.to_string()], cells(&system, &c, bound, &png)].concat());
        rows.push(
            json!({ "comparison": c, "table_bound": bound, "slice_cut": s.cut, "plot": png.display().to_string(),
            "grid": solution.grid.axes(), "solver": solution.info.config, "horizon": solution.info.horizon,
            "converged": solution.info.converged }),
        );
    }
    let config = json!({ "bundle": args.bundle, "model": manifest.name, "version": manifest.version,
        "untrained": manifest.untrained, "betas": args.betas, "sublevel_factor": args.sublevel_factor, "solver": solve.config() });
    let path = write_command_record(
        &args.outputs.results_dir,
        &name,
        config,
        json!({ "rows": rows }),
        &[("learned vs grid", &table)],
    )?;
    println!("wrote {}", path.display());
    Ok(())
}

/// `compare` of a decomposed system's bundle: per `beta` of the axis solutions and per axis, the bundle on
/// the axis' grid (the other axes at their minimisers) against the combined ground truth there.
fn run_axes(
    args: &Args,
    bundle: &Bundle,
    evaluator: &Evaluator,
    axes: &[DecomposedAxis],
    name: &str,
) -> anyhow::Result<()> {
    let manifest = &bundle.manifest;
    let id = manifest.system.id.as_str();
    if args.axis_solutions.is_empty() {
        bail!("{id} is compared with its axes' solutions: give them with --axis-solutions");
    }
    let system = by_id(id).with_context(|| format!("unknown system `{id}`"))?;
    let (solutions, betas) = load_axis_solutions(id, axes, &args.axis_solutions)?;
    let mut table = MarkdownTable::new(&[&["beta", "axis"][..], &COLUMNS].concat());
    let mut rows = Vec::new();
    for beta in betas {
        let pairs = axes_at(id, axes, &solutions, beta)?;
        let bound = table_bound(manifest, beta);
        for (k, (axis, _)) in pairs.iter().enumerate() {
            let slice = combined_on_axis(&system, &pairs, k);
            let subsystem = by_id(axis.subsystem).with_context(|| format!("unknown system `{}`", axis.subsystem))?;
            let learned = learned_on_axis(evaluator, &slice, &vec![beta; manifest.n_params()])?;
            let axis_name = system.state[axis.coords[0]].name;
            let png = args.outputs.results_dir.join(format!("{name}-beta{beta}-{axis_name}.png"));
            let title = format!("{} beta {beta}, along {axis_name}", manifest.name);
            let (c, s) = compare_and_draw(&subsystem, &slice.reference, &learned, args.sublevel_factor, &png, &title)?;
            table.row([vec![beta.to_string(), axis_name.to_string()], cells(&subsystem, &c, bound, &png)].concat());
            rows.push(json!({ "axis": axis_name, "comparison": c, "table_bound": bound, "base_state": slice.base,
                "slice_cut": s.cut, "plot": png.display().to_string(), "grid": slice.reference.grid.axes(),
                "solver": slice.reference.info.config, "horizon": slice.reference.info.horizon,
                "converged": slice.reference.info.converged }));
        }
    }
    let config = json!({ "bundle": args.bundle, "model": manifest.name, "version": manifest.version,
        "untrained": manifest.untrained, "axis_solutions": args.axis_solutions,
        "sublevel_factor": args.sublevel_factor });
    let path = write_command_record(
        &args.outputs.results_dir,
        name,
        config,
        json!({ "rows": rows }),
        &[("learned vs the combined ground truth, along each axis", &table)],
    )?;
    println!("wrote {}", path.display());
    Ok(())
}
