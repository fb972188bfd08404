//! `reference`: every row's ground-truth reference (grid solutions of the system or of its axes, closed forms)
//! written into a bundle, so that its served bounds never undercut the ground truth; with `--record`, a record
//! of each row's served bound against its reference and of the wall time of each stage that made the model.

use super::common::write_command_record;
use anyhow::Context;
use fastrack_grid::format::load;
use fastrack_grid::reference::{set_references, SolvedBound};
use fastrack_gridfile::solution::SolveInfo;
use fastrack_lab::record::MarkdownTable;
use fastrack_valuefn::bundle::Bundle;
use fastrack_valuefn::manifest::Manifest;
use fastrack_valuefn::system::decomposition;
use serde_json::json;
use std::path::{Path, PathBuf};

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
    /// Record name: `<results-dir>/<record>.{json,md}` with each row's served bound beside its reference
    /// and the wall time of each stage (training, every solve, verification per row). None without it.
    #[arg(long)]
    record: Option<String>,
    /// The bundle's verification record (`verify` or `verify-merge`'s JSON), for the verification's wall
    /// time per row in the record.
    #[arg(long, requires = "record")]
    verification_record: Option<PathBuf>,
    /// Folder of measurement records.
    #[arg(long, default_value = "bench/results")]
    results_dir: PathBuf,
}

/// A grid solution the references were taken from.
struct Solved {
    path: PathBuf,
    bound: SolvedBound,
    info: SolveInfo,
    nodes: Vec<usize>,
}

/// Runs `reference`.
pub fn run(args: Args) -> anyhow::Result<()> {
    let bundle = Bundle::load(&args.bundle)?;
    let id = bundle.manifest.system.id.clone();
    let systems: Vec<String> = match decomposition(&id) {
        Some(axes) => axes.iter().map(|a| a.subsystem.to_string()).collect(),
        None => vec![id.clone()],
    };
    let mut solved: Vec<Solved> = Vec::new();
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
        if let Some(other) = solved.iter().find(|s| s.bound.system == bound.system && s.bound.beta == bound.beta) {
            anyhow::bail!(
                "two solutions of `{}` at beta {} ({} and {}); give one per beta",
                bound.system,
                bound.beta,
                other.path.display(),
                path.display()
            );
        }
        let nodes = solution.grid.axes().iter().map(|a| a.n).collect();
        solved.push(Solved { path: path.clone(), bound, info: solution.info, nodes });
    }
    let bounds: Vec<SolvedBound> = solved.iter().map(|s| s.bound.clone()).collect();
    let mut manifest = bundle.manifest.clone();
    let count = set_references(&id, &mut manifest.teb_table, &bounds);
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
    if let Some(name) = &args.record {
        let walls = match &args.verification_record {
            Some(path) => verification_walls(path)?,
            None => Vec::new(),
        };
        let path = write_reference_record(&args.results_dir, name, &manifest, &solved, &walls)?;
        println!("wrote {}", path.display());
    }
    let dir = Bundle::write(&args.out, manifest, &bundle.onnx)?;
    println!("{count} of {} rows have a reference; wrote {}", bundle.manifest.teb_table.len(), dir.display());
    Ok(())
}

/// Each verified row's `(beta, wall time)` from a verification record.
fn verification_walls(path: &Path) -> anyhow::Result<Vec<(f64, f64)>> {
    let text = std::fs::read_to_string(path).with_context(|| format!("reading {}", path.display()))?;
    let record: serde_json::Value =
        serde_json::from_str(&text).with_context(|| format!("parsing {}", path.display()))?;
    let rows = record["figures"]["rows"]
        .as_array()
        .with_context(|| format!("{}: no figures.rows; a verification record has one per row", path.display()))?;
    rows.iter()
        .map(|row| match (row["beta"].as_f64(), row["wall_s"].as_f64()) {
            (Some(beta), Some(wall)) => Ok((beta, wall)),
            _ => anyhow::bail!("{}: a row without beta or wall_s: {row}", path.display()),
        })
        .collect()
}

/// Writes the record: each row's bounds, the solves and the stages' wall times.
fn write_reference_record(
    dir: &Path,
    name: &str,
    manifest: &Manifest,
    solved: &[Solved],
    walls: &[(f64, f64)],
) -> anyhow::Result<PathBuf> {
    let wall_at = |beta: f64| walls.iter().find(|(b, _)| *b == beta).map(|(_, w)| *w);
    let mut rows = MarkdownTable::new(&[
        "beta",
        "verified bound",
        "reference",
        "served bound",
        "set by",
        "served / reference",
        "verification wall (s)",
        "reference from",
    ]);
    let mut row_figures = Vec::new();
    for row in &manifest.teb_table {
        let reference = row.reference.as_ref();
        let ratio = reference.map(|r| row.bound() / r.bound);
        let wall = wall_at(row.beta);
        let cell = |x: Option<f64>, digits: usize| x.map_or_else(|| "-".to_string(), |x| format!("{x:.digits$}"));
        rows.row(vec![
            format!("{:.4}", row.beta),
            format!("{:.4}", row.verified_bound()),
            cell(reference.map(|r| r.bound), 4),
            format!("{:.4}", row.bound()),
            row.bound_source().name().to_string(),
            cell(ratio, 3),
            cell(wall, 0),
            reference.map_or_else(String::new, |r| r.source.clone()),
        ]);
        row_figures.push(json!({
            "beta": row.beta, "verified_bound": row.verified_bound(), "reference": reference.map(|r| r.bound),
            "bound": row.bound(), "set_by": row.bound_source().name(), "served_over_reference": ratio,
            "verification_wall_s": wall, "reference_source": reference.map(|r| &r.source),
        }));
    }
    let mut solves = MarkdownTable::new(&["system", "beta", "nodes", "horizon (s)", "converged", "V_min", "wall (s)"]);
    let mut solve_figures = Vec::new();
    let mut in_order: Vec<&Solved> = solved.iter().collect();
    in_order.sort_by(|a, b| a.bound.system.cmp(&b.bound.system).then(a.bound.beta.total_cmp(&b.bound.beta)));
    for s in in_order {
        let nodes = s.nodes.iter().map(usize::to_string).collect::<Vec<_>>().join(" x ");
        solves.row(vec![
            s.bound.system.clone(),
            format!("{:.4}", s.bound.beta),
            nodes,
            format!("{:.1}", s.info.horizon),
            if s.info.converged { "yes" } else { "no" }.to_string(),
            format!("{:.4}", s.bound.v_min),
            format!("{:.0}", s.info.wall_s),
        ]);
        solve_figures.push(json!({
            "file": s.path, "system": s.bound.system, "beta": s.bound.beta, "nodes": s.nodes,
            "horizon": s.info.horizon, "converged": s.info.converged, "v_min": s.bound.v_min, "wall_s": s.info.wall_s,
        }));
    }
    let solve_wall: f64 = solved.iter().map(|s| s.info.wall_s).sum();
    let verification_wall: f64 = walls.iter().map(|(_, w)| w).sum();
    let provenance = &manifest.provenance;
    let mut stages = MarkdownTable::new(&["stage", "wall (s)"]);
    stages.row(vec![
        format!("training ({}, {} iterations, on {})", provenance.method, provenance.iterations, provenance.machine),
        format!("{:.0}", provenance.wall_time_s),
    ]);
    stages.row(vec![format!("ground-truth solves ({})", solved.len()), format!("{solve_wall:.0}")]);
    if !walls.is_empty() {
        stages.row(vec![format!("verification ({} rows)", walls.len()), format!("{verification_wall:.0}")]);
    }
    let figures = json!({
        "rows": row_figures, "solves": solve_figures,
        "stages": { "training_s": provenance.wall_time_s, "solves_s": solve_wall,
                    "verification_s": (!walls.is_empty()).then_some(verification_wall) },
    });
    let config = json!({ "model": manifest.name, "version": manifest.version, "onnx_sha256": manifest.onnx_sha256 });
    Ok(write_command_record(
        dir,
        name,
        config,
        figures,
        &[("served bound against the ground truth", &rows), ("ground-truth solves", &solves), ("stages", &stages)],
    )?)
}
