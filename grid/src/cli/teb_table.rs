//! `teb-table`: the grid's TEB table over `beta` (the classic FaSTrack bound at `beta_l`/`beta_u` and the Meta-FaSTrack levels),
//! across resolutions and accuracies, with convergence plots and a measurement record.

use super::common::{write_command_record, SolveOptions, StudyOutputs};
use fastrack_grid::analysis::{teb, Teb, EXTENT_REL_TOL};
use fastrack_grid::solver::Solution;
use fastrack_grid::upwind::Accuracy;
use fastrack_lab::plot::{line_chart, Chart, Series};
use fastrack_lab::record::MarkdownTable;
use fastrack_valuefn::system::AffineSystem;
use serde_json::json;

/// Arguments of `teb-table`.
#[derive(clap::Args)]
pub struct Args {
    #[command(flatten)]
    solve: SolveOptions,
    /// Planner speed bounds (default: 5 values evenly spaced over the system's range, ends included).
    #[arg(long, value_delimiter = ',')]
    betas: Vec<f64>,
    /// Uniform resolutions to solve at, comma separated (overrides --resolution); the finest is reported.
    #[arg(long, value_delimiter = ',')]
    resolutions: Vec<usize>,
    /// Accuracies to compare, comma separated (overrides --accuracy).
    #[arg(long, value_delimiter = ',')]
    accuracies: Vec<Accuracy>,
    #[command(flatten)]
    outputs: StudyOutputs,
}

/// One solve of the study.
struct Entry {
    accuracy: Accuracy,
    beta: f64,
    teb: Teb,
    solution: Solution,
}

fn fmt(x: f64) -> String {
    format!("{x:.4}")
}

/// Runs `table`.
pub fn run(args: Args) -> anyhow::Result<()> {
    let system = args.solve.system()?;
    let (beta_l, beta_u) = (system.params[0].min, system.params[0].max);
    let betas = if args.betas.is_empty() {
        (0..5).map(|i| beta_l + (beta_u - beta_l) * i as f64 / 4.0).collect()
    } else {
        args.betas.clone()
    };
    let resolutions = if args.resolutions.is_empty() {
        vec![args.solve.resolution.clone()]
    } else {
        args.resolutions.iter().map(|&n| vec![n]).collect()
    };
    let accuracies = if args.accuracies.is_empty() { vec![args.solve.accuracy] } else { args.accuracies.clone() };
    let mut entries = Vec::new();
    for &accuracy in &accuracies {
        for resolution in &resolutions {
            for &beta in &betas {
                let options = SolveOptions { accuracy, resolution: resolution.clone(), ..args.solve.clone() };
                let solution = options.solve_or_load(beta, &args.outputs.solutions_dir)?;
                let teb = teb(&solution, &system, EXTENT_REL_TOL);
                println!(
                    "{accuracy} n={:?} beta={beta}: V_min {:.4} extent {:?} horizon {:.2} s {} wall {:.1} s",
                    solution.grid.axes().iter().map(|a| a.n).collect::<Vec<_>>(),
                    teb.v_min,
                    teb.extent.iter().map(|e| (e * 1000.0).round() / 1000.0).collect::<Vec<_>>(),
                    solution.info.horizon,
                    if solution.info.converged { "converged" } else { "NOT converged" },
                    solution.info.wall_s
                );
                entries.push(Entry { accuracy, beta, teb, solution });
            }
        }
    }
    if let Some(name) = &args.outputs.record {
        write_outputs(&args, &system, &betas, &accuracies, &entries, name)?;
    }
    Ok(())
}

fn res_label(entry: &Entry) -> String {
    entry.solution.grid.axes().iter().map(|a| a.n.to_string()).collect::<Vec<_>>().join("x")
}

fn write_outputs(
    args: &Args,
    system: &AffineSystem,
    betas: &[f64],
    accuracies: &[Accuracy],
    entries: &[Entry],
    name: &str,
) -> anyhow::Result<()> {
    let mut all = MarkdownTable::new(&[
        "accuracy",
        "grid",
        "beta",
        "V_min",
        "extent (error coords)",
        "argmin",
        "horizon (s)",
        "converged",
        "steps",
        "wall (s)",
    ]);
    for e in entries {
        all.row(vec![
            e.accuracy.to_string(),
            res_label(e),
            e.beta.to_string(),
            fmt(e.teb.v_min),
            format!("{:?}", e.teb.extent.iter().map(|x| (x * 1000.0).round() / 1000.0).collect::<Vec<_>>()),
            format!("{:?}", e.teb.argmin.iter().map(|x| (x * 1000.0).round() / 1000.0).collect::<Vec<_>>()),
            format!("{:.2}", e.solution.info.horizon),
            e.solution.info.converged.to_string(),
            e.solution.info.steps.to_string(),
            format!("{:.1}", e.solution.info.wall_s),
        ]);
    }
    // The finest resolution of the most accurate scheme gives the table; the previous one the change.
    let best_accuracy = *accuracies.iter().max_by_key(|a| a.half_width()).unwrap_or(&args.solve.accuracy);
    let finest: Vec<&Entry> = {
        let mut by_res: Vec<&Entry> = entries.iter().filter(|e| e.accuracy == best_accuracy).collect();
        by_res.sort_by_key(|e| e.solution.grid.num_points());
        let top = by_res.last().map(|e| e.solution.grid.num_points()).unwrap_or(0);
        by_res.into_iter().filter(|e| e.solution.grid.num_points() == top).collect()
    };
    let mut teb_table = MarkdownTable::new(&[
        "beta",
        "V_min (Meta-FaSTrack level)",
        "classic FaSTrack bound (V_min at beta_u)",
        "change vs next-coarser grid",
    ]);
    let classic = finest.iter().find(|e| (e.beta - system.params[0].max).abs() < 1e-9).map(|e| e.teb.v_min);
    for e in &finest {
        let coarser = entries
            .iter()
            .filter(|c| {
                c.accuracy == e.accuracy
                    && c.beta == e.beta
                    && c.solution.grid.num_points() < e.solution.grid.num_points()
            })
            .max_by_key(|c| c.solution.grid.num_points());
        teb_table.row(vec![
            e.beta.to_string(),
            fmt(e.teb.v_min),
            classic.map_or("(beta_u not solved)".into(), fmt),
            coarser.map_or("-".into(), |c| {
                format!("{:+.2}% ({} -> {})", 100.0 * (e.teb.v_min / c.teb.v_min - 1.0), res_label(c), res_label(e))
            }),
        ]);
    }
    let dir = &args.outputs.results_dir;
    std::fs::create_dir_all(dir)?;
    // V_min against horizon at the finest grid, one line per beta.
    let horizon_series: Vec<Series> = finest
        .iter()
        .map(|e| Series {
            label: format!("beta {} ({})", e.beta, res_label(e)),
            points: e.solution.info.history.iter().map(|h| (h.tau, h.v_min)).collect(),
            markers: false,
        })
        .collect();
    let horizon_png = dir.join(format!("{name}-vmin-vs-horizon.png"));
    let title = format!("{}: V_min vs horizon", system.id);
    let chart = Chart { title: &title, x_label: "horizon tau (s)", y_label: "V_min (m)", log_y: false };
    line_chart(&horizon_png, &chart, &horizon_series).map_err(anyhow::Error::msg)?;
    // V_min against resolution, one line per (accuracy, beta).
    let mut resolution_series = Vec::new();
    for &accuracy in accuracies {
        for &beta in betas {
            let mut points: Vec<(f64, f64)> = entries
                .iter()
                .filter(|e| e.accuracy == accuracy && e.beta == beta)
                .map(|e| (e.solution.grid.axes()[0].n as f64, e.teb.v_min))
                .collect();
            points.sort_by(|a, b| a.0.total_cmp(&b.0));
            if points.len() > 1 {
                resolution_series.push(Series { label: format!("{accuracy} beta {beta}"), points, markers: false });
            }
        }
    }
    let mut plots = vec![horizon_png.display().to_string()];
    if !resolution_series.is_empty() {
        let png = dir.join(format!("{name}-vmin-vs-resolution.png"));
        let title = format!("{}: V_min vs nodes per axis", system.id);
        let chart = Chart { title: &title, x_label: "nodes per axis", y_label: "V_min (m)", log_y: false };
        line_chart(&png, &chart, &resolution_series).map_err(anyhow::Error::msg)?;
        plots.push(png.display().to_string());
    }
    let figures = json!({
        "solves": entries.iter().map(|e| json!({
            "accuracy": e.accuracy, "resolution": e.solution.grid.axes().iter().map(|a| a.n).collect::<Vec<_>>(),
            "bounds": e.solution.grid.axes().iter().map(|a| [a.min, a.max]).collect::<Vec<_>>(),
            "beta": e.beta, "teb": e.teb, "horizon": e.solution.info.horizon, "converged": e.solution.info.converged,
            "final_rate": e.solution.info.final_rate, "tested_rate": e.solution.info.tested_rate(), "steps": e.solution.info.steps, "dt": e.solution.info.dt,
            "wall_s": e.solution.info.wall_s,
            "history": e.solution.info.history.iter().step_by(5).collect::<Vec<_>>(),
        })).collect::<Vec<_>>(),
        "classic_fastrack_bound": classic,
        "plots": plots,
    });
    let config = json!({
        "system": system.id, "betas": betas, "accuracies": accuracies, "resolutions": args.resolutions,
        "solver": args.solve.config(), "bounds": args.solve.bounds, "extent_rel_tol": EXTENT_REL_TOL,
    });
    let path = write_command_record(
        dir,
        name,
        config,
        figures,
        &[("TEB table (finest grid)", &teb_table), ("every solve", &all)],
    )?;
    println!("wrote {} and {}", path.display(), plots.join(", "));
    Ok(())
}
