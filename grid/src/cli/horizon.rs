//! `horizon`: how `V_min` and `max |dV/dtau|` evolve with the horizon, by region (whole grid, interior away from
//! the non-periodic edges, the sublevel set near `V_min`), across resolutions and `beta`; the horizon at which
//! the sublevel-set rate first falls below a tolerance (over the solve's rate windows when it has them, else per
//! step); plots and a measurement record.

use super::common::{write_command_record, SolveOptions, StudyOutputs};
use fastrack_grid::analysis::{teb, EXTENT_REL_TOL};
use fastrack_grid::solver::{ConvergenceSet, HistoryPoint, Solution, WindowRates};
use fastrack_lab::plot::{line_chart, Chart, Series};
use fastrack_lab::record::MarkdownTable;
use serde_json::json;

/// Arguments of `horizon`.
#[derive(clap::Args)]
pub struct Args {
    #[command(flatten)]
    solve: SolveOptions,
    /// Planner speed bounds, comma separated.
    #[arg(long, value_delimiter = ',', default_value = "0.5,0.875,1.25")]
    betas: Vec<f64>,
    /// Resolutions, comma separated (overrides --resolution): each one number for every axis or one per
    /// axis joined by `x`, e.g. `21,31` or `21x21x15x15,27x27x19x19`.
    #[arg(long, value_delimiter = ',', value_parser = parse_resolution)]
    resolutions: Vec<Vec<usize>>,
    /// Horizons at which `V_min` is tabulated (s), comma separated.
    #[arg(long, value_delimiter = ',', default_value = "5,10,15,20,25,30")]
    at: Vec<f64>,
    /// The converged horizon reported is the first recorded one where max |dV/dtau| over the convergence set
    /// (--set-margin, --edge-nodes; over the rate window when --rate-window is set) is below this (m/s).
    #[arg(long, default_value_t = 0.01)]
    report_tolerance: f64,
    /// ... and stays below it over the recorded history for this long (s).
    #[arg(long, default_value_t = 0.0)]
    report_settle_time: f64,
    /// Also reported: the first horizon at which `V_min` itself grew by less than --report-tolerance per second
    /// over the preceding window of this length (s).
    #[arg(long, default_value_t = 5.0)]
    vmin_window: f64,
    /// Multiply --tolerance and --report-tolerance by each `beta`: the rate `dV/dtau` of a system whose
    /// error scales like `beta^2` and time like `beta` (a double integrator) scales like `beta`, so one
    /// relative setting serves every row.
    #[arg(long)]
    tolerance_per_beta: bool,
    #[command(flatten)]
    outputs: StudyOutputs,
}

/// One solve and what its history says.
struct Study {
    beta: f64,
    label: String,
    solution: Solution,
    /// First recorded point whose set rate stays below the report tolerance for the report settle time.
    settled: Option<HistoryPoint>,
    /// First recorded point where `V_min`'s growth over the preceding window is below the report tolerance.
    vmin_settled: Option<HistoryPoint>,
}

/// The last history point at or before `tau`.
fn at(history: &[HistoryPoint], tau: f64) -> Option<&HistoryPoint> {
    history.iter().take_while(|h| h.tau <= tau + 1e-9).last()
}

/// The rate window ending nearest `tau`, and its end.
fn window_near(history: &[HistoryPoint], tau: f64) -> Option<(f64, WindowRates)> {
    history
        .iter()
        .filter_map(|h| h.window.map(|w| (h.tau, w)))
        .min_by(|a, b| (a.0 - tau).abs().total_cmp(&(b.0 - tau).abs()))
}

fn fmt(x: Option<f64>, digits: usize) -> String {
    x.map_or("-".into(), |x| format!("{x:.digits$}"))
}

/// `(V_min(tau_1) - V_min(tau_0)) / (tau_1 - tau_0)` over the last `span` seconds of the history.
fn creep(history: &[HistoryPoint], span: f64) -> Option<f64> {
    let last = history.last()?;
    let first = at(history, last.tau - span)?;
    (last.tau > first.tau).then(|| (last.v_min - first.v_min) / (last.tau - first.tau))
}

/// The rate on the convergence set that a history point reports: over its rate window when the solve measured
/// windows, else over its step.
fn set_rate(h: &HistoryPoint, windowed: bool) -> Option<f64> {
    if windowed {
        h.window.map(|w| w.regions.set)
    } else {
        h.regions.map(|r| r.set)
    }
}

/// The first recorded point from which the set rate stays below `tolerance` for `settle` seconds of history.
fn settled(history: &[HistoryPoint], windowed: bool, tolerance: f64, settle: f64) -> Option<HistoryPoint> {
    let measured: Vec<(HistoryPoint, f64)> =
        history.iter().filter_map(|h| set_rate(h, windowed).map(|rate| (*h, rate))).collect();
    let end = measured.last()?.0.tau;
    measured
        .iter()
        .enumerate()
        .filter(|(_, (h, _))| h.tau + settle <= end + 1e-9)
        .find(|(i, (h, _))| {
            measured[*i..].iter().take_while(|(g, _)| g.tau <= h.tau + settle + 1e-9).all(|(_, r)| *r < tolerance)
        })
        .map(|(_, (h, _))| *h)
}

/// The first recorded point where `(V_min(tau) - V_min(tau - window)) / window < tolerance`.
fn vmin_settled(history: &[HistoryPoint], tolerance: f64, window: f64) -> Option<HistoryPoint> {
    history
        .iter()
        .filter(|h| h.tau >= window)
        .find(|h| at(history, h.tau - window).is_some_and(|g| (h.v_min - g.v_min) / (h.tau - g.tau) < tolerance))
        .copied()
}

/// One resolution: `31` or `31x31x21x21`.
fn parse_resolution(text: &str) -> Result<Vec<usize>, String> {
    text.split('x')
        .map(|n| {
            n.trim().parse::<usize>().map_err(|_| format!("`{text}`: expected nodes per axis like 31 or 31x31x21x21"))
        })
        .collect()
}

/// Runs `horizon`.
pub fn run(args: Args) -> anyhow::Result<()> {
    let set = args.solve.config().converge_on.unwrap_or(ConvergenceSet::DIAGNOSTIC);
    let resolutions: Vec<Vec<usize>> =
        if args.resolutions.is_empty() { vec![args.solve.resolution.clone()] } else { args.resolutions.clone() };
    let mut studies = Vec::new();
    for resolution in &resolutions {
        for &beta in &args.betas {
            let scale = if args.tolerance_per_beta { beta } else { 1.0 };
            let options = SolveOptions {
                resolution: resolution.clone(),
                tolerance: args.solve.tolerance * scale,
                ..args.solve.clone()
            };
            let solution = options.solve_or_load(beta, &args.outputs.solutions_dir)?;
            let label = solution.grid.axes().iter().map(|a| a.n.to_string()).collect::<Vec<_>>().join("x");
            let windowed = solution.info.config.rate_window > 0.0;
            let report_tolerance = args.report_tolerance * scale;
            let settled = settled(&solution.info.history, windowed, report_tolerance, args.report_settle_time);
            let vmin_settled = vmin_settled(&solution.info.history, report_tolerance, args.vmin_window);
            let last = solution.info.history.last();
            println!(
                "{label} beta={beta}: V_min {:.4} at {:.1} s, set rate {} (grid {}){}, settled {}, wall {:.1} s",
                last.map_or(f64::NAN, |h| h.v_min),
                solution.info.horizon,
                fmt(last.and_then(|h| h.regions).map(|r| r.set), 4),
                fmt(last.and_then(|h| h.rate), 4),
                last.and_then(|h| h.window).map_or(String::new(), |w| format!(
                    ", over the last {:.1} s: set {:.4} grid {:.4}",
                    w.span, w.regions.set, w.grid
                )),
                settled.map_or("never".into(), |h| format!("at {:.1} s, V_min {:.4}", h.tau, h.v_min)),
                solution.info.wall_s
            );
            studies.push(Study { beta, label, solution, settled, vmin_settled });
        }
    }
    if let Some(name) = &args.outputs.record {
        write_outputs(&args, set, &studies, name)?;
    }
    Ok(())
}

fn write_outputs(args: &Args, set: ConvergenceSet, studies: &[Study], name: &str) -> anyhow::Result<()> {
    let system = args.solve.system()?;
    let mut header: Vec<String> = vec!["grid".into(), "beta".into()];
    header.extend(args.at.iter().map(|t| format!("V_min({t} s)")));
    header.extend(["dV_min/dtau, last 5 s".into(), "wall (s)".into()]);
    let mut vmin_table = MarkdownTable::new(&header.iter().map(String::as_str).collect::<Vec<_>>());
    let mut rate_table = MarkdownTable::new(&[
        "grid",
        "beta",
        "tau (s)",
        "max rate: grid",
        "interior",
        "set",
        "set near edges",
        "worst node: nodes from edge",
        "worst node: V - V_min",
        "window ending nearest (s)",
        "over it: grid",
        "set",
    ]);
    let mut settled_table = MarkdownTable::new(&[
        "grid",
        "beta",
        "set rate settled (s)",
        "V_min there",
        "V_min rate settled (s)",
        "V_min there",
        "V_min at cap",
        "extent at cap",
    ]);
    for s in studies {
        let history = &s.solution.info.history;
        let mut row = vec![s.label.clone(), s.beta.to_string()];
        row.extend(args.at.iter().map(|&t| fmt(at(history, t).filter(|h| h.tau > t - 0.2).map(|h| h.v_min), 4)));
        row.extend([fmt(creep(history, 5.0), 4), format!("{:.1}", s.solution.info.wall_s)]);
        vmin_table.row(row);
        for &t in &args.at {
            let Some(h) = at(history, t).filter(|h| h.tau > t - 0.2) else { continue };
            let Some(r) = h.regions else { continue };
            rate_table.row(vec![
                s.label.clone(),
                s.beta.to_string(),
                format!("{:.1}", h.tau),
                fmt(h.rate, 4),
                format!("{:.4}", r.interior),
                format!("{:.4}", r.set),
                format!("{:.4}", r.set_edge),
                r.worst_edge_distance.to_string(),
                format!("{:.3}", r.worst_excess),
                fmt(window_near(history, h.tau).map(|(end, _)| end), 1),
                fmt(window_near(history, h.tau).map(|(_, w)| w.grid), 4),
                fmt(window_near(history, h.tau).map(|(_, w)| w.regions.set), 4),
            ]);
        }
        let teb = teb(&s.solution, &system, EXTENT_REL_TOL);
        let never = format!("not before {:.1}", s.solution.info.horizon);
        settled_table.row(vec![
            s.label.clone(),
            s.beta.to_string(),
            s.settled.map_or(never.clone(), |h| format!("{:.1}", h.tau)),
            fmt(s.settled.map(|h| h.v_min), 4),
            s.vmin_settled.map_or(never, |h| format!("{:.1}", h.tau)),
            fmt(s.vmin_settled.map(|h| h.v_min), 4),
            format!("{:.4}", teb.v_min),
            format!("{:?}", teb.extent.iter().map(|x| (x * 1000.0).round() / 1000.0).collect::<Vec<_>>()),
        ]);
    }
    let dir = &args.outputs.results_dir;
    std::fs::create_dir_all(dir)?;
    let series = |f: &dyn Fn(&HistoryPoint) -> Option<f64>, suffix: &str| -> Vec<Series> {
        studies
            .iter()
            .map(|s| Series {
                label: format!("beta {} ({}){suffix}", s.beta, s.label),
                points: s.solution.info.history.iter().filter_map(|h| f(h).map(|y| (h.tau, y))).collect(),
                markers: false,
            })
            .collect()
    };
    let vmin_png = dir.join(format!("{name}-vmin-vs-horizon.png"));
    let title = format!("{}: V_min vs horizon", system.id);
    let chart = Chart { title: &title, x_label: "horizon tau (s)", y_label: "V_min (m)", log_y: false };
    line_chart(&vmin_png, &chart, &series(&|h| Some(h.v_min), "")).map_err(anyhow::Error::msg)?;
    let set_png = dir.join(format!("{name}-set-rate-vs-horizon.png"));
    let title = format!("{}: max |dV/dtau| on {{V <= {} V_min}}, interior", system.id, 1.0 + set.margin);
    let chart = Chart { title: &title, x_label: "horizon tau (s)", y_label: "max |dV/dtau| (m/s)", log_y: true };
    let mut set_series = series(&|h| h.regions.map(|r| r.set), ", per step");
    set_series.extend(series(&|h| h.window.map(|w| w.regions.set), ", over the rate window"));
    set_series.retain(|s| !s.points.is_empty());
    line_chart(&set_png, &chart, &set_series).map_err(anyhow::Error::msg)?;
    let grid_png = dir.join(format!("{name}-grid-rate-vs-horizon.png"));
    let title = format!("{}: max |dV/dtau| over the whole grid", system.id);
    let chart = Chart { title: &title, x_label: "horizon tau (s)", y_label: "max |dV/dtau| (m/s)", log_y: true };
    line_chart(&grid_png, &chart, &series(&|h| h.rate, "")).map_err(anyhow::Error::msg)?;
    let plots: Vec<String> = [vmin_png, set_png, grid_png].iter().map(|p| p.display().to_string()).collect();
    let figures = json!({
        "solves": studies.iter().map(|s| json!({
            "resolution": s.solution.grid.axes().iter().map(|a| a.n).collect::<Vec<_>>(),
            "beta": s.beta, "horizon": s.solution.info.horizon, "converged": s.solution.info.converged,
            "steps": s.solution.info.steps, "dt": s.solution.info.dt, "wall_s": s.solution.info.wall_s,
            "settled": s.settled, "vmin_settled": s.vmin_settled,
            "history": s.solution.info.history.iter().enumerate()
                .filter(|(i, h)| i % 5 == 0 || h.window.is_some()).map(|(_, h)| h).collect::<Vec<_>>(),
        })).collect::<Vec<_>>(),
        "plots": plots,
    });
    let config = json!({
        "system": system.id, "betas": args.betas, "resolutions": args.resolutions, "solver": args.solve.config(),
        "convergence_set": set, "report_tolerance": args.report_tolerance,
        "tolerance_per_beta": args.tolerance_per_beta,
        "report_settle_time": args.report_settle_time, "vmin_window": args.vmin_window, "bounds": args.solve.bounds,
    });
    let path = write_command_record(
        dir,
        name,
        config,
        figures,
        &[
            ("V_min against horizon", &vmin_table),
            ("max |dV/dtau| by region", &rate_table),
            ("settled horizons (rates below the report tolerance)", &settled_table),
        ],
    )?;
    println!("wrote {} and {}", path.display(), plots.join(", "));
    Ok(())
}
