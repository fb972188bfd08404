//! `rollout`: what adversarial planners sustain against grid solutions' own tracker policies, beside each
//! solution's `V_min`; a table, a plot against `beta` and a record. With `--system` naming a decomposed
//! system, the solutions are its axes' and are rolled out side by side in the full system, per `beta`.

use super::common::{axes_at, load_axis_solutions, write_command_record};
use anyhow::Context;
use fastrack_grid::format::load;
use fastrack_grid::rollout::{roll_out_axes, roll_out_solution, AxesRolloutReport, RolloutOptions, RolloutReport};
use fastrack_grid::solver::Solution;
use fastrack_lab::plot::{line_chart, Chart, Series};
use fastrack_lab::record::MarkdownTable;
use fastrack_valuefn::system::{by_id, decomposition};
use serde_json::json;
use std::path::PathBuf;

/// Arguments of `rollout`.
#[derive(clap::Args)]
pub struct Args {
    /// Solution files (`.ftgrid`), comma separated.
    #[arg(long, value_delimiter = ',', required = true)]
    solutions: Vec<PathBuf>,
    /// A system with an exact decomposition (quad10d): the solutions are its axes' subsystems, one per
    /// subsystem and `beta`, rolled out side by side in the full system with every `beta_i` equal.
    #[arg(long)]
    system: Option<String>,
    /// Rollout horizon (s); the sustained error is the largest over its second half.
    #[arg(long, default_value_t = 60.0)]
    horizon: f64,
    /// RK4 step (s); control and planner are held over a step.
    #[arg(long, default_value_t = 0.01)]
    step: f64,
    /// Starts are the nodes of {V <= (1 + margin) V_min}.
    #[arg(long, default_value_t = 0.02)]
    start_margin: f64,
    /// Largest number of starts per solution (the set's nodes thinned evenly).
    #[arg(long, default_value_t = 200)]
    max_starts: usize,
    /// Random bang-bang planners per start, besides the worst-case planner.
    #[arg(long, default_value_t = 4)]
    random_planners: usize,
    /// Mean time between a random planner's switches (s).
    #[arg(long, default_value_t = 1.0)]
    mean_dwell: f64,
    /// Random seed.
    #[arg(long, default_value_t = 11)]
    seed: u64,
    /// Record name (`<results-dir>/<record>.{json,md}` and a PNG beside it); none without it.
    #[arg(long)]
    record: Option<String>,
    /// Folder of measurement records and plots.
    #[arg(long, default_value = "bench/results")]
    results_dir: PathBuf,
}

/// The solutions of one system and resolution, as `(beta, value)` points.
struct Group {
    key: String,
    v_min: Vec<(f64, f64)>,
    sustained: Vec<(f64, f64)>,
}

/// A solution as the records describe it: file, system, parameters, resolution and horizon solved to.
fn solution_figure(path: &std::path::Path, solution: &Solution) -> serde_json::Value {
    json!({
        "path": path, "system": solution.info.system, "params": solution.info.params,
        "resolution": solution.grid.axes().iter().map(|a| a.n).collect::<Vec<_>>(),
        "solved_to": solution.info.horizon,
    })
}

fn label(solution: &Solution) -> String {
    let grid = solution.grid.axes().iter().map(|a| a.n.to_string()).collect::<Vec<_>>().join("x");
    format!("beta {:?} ({grid})", solution.info.params)
}

/// Runs `rollout`.
pub fn run(args: Args) -> anyhow::Result<()> {
    let options = RolloutOptions {
        horizon: args.horizon,
        step: args.step,
        start_margin: args.start_margin,
        max_starts: args.max_starts,
        random_planners: args.random_planners,
        mean_dwell: args.mean_dwell,
        seed: args.seed,
    };
    if let Some(id) = &args.system {
        return run_axes(&args, &options, id);
    }
    let mut results: Vec<(PathBuf, Solution, RolloutReport)> = Vec::new();
    for path in &args.solutions {
        let solution = load(path).with_context(|| format!("loading {}", path.display()))?;
        let system = by_id(&solution.info.system)
            .with_context(|| format!("{}: unknown system `{}`", path.display(), solution.info.system))?;
        let report = roll_out_solution(&system, &solution, &options)?;
        println!(
            "{} at {:.1} s: V_min {:.4}; sustained over the last {:.0} s: worst-case planner {:.4}, random {} ({:.2} V_min); {} starts, {} rollouts left the domain",
            label(&solution),
            solution.info.horizon,
            report.v_min,
            options.horizon / 2.0,
            report.sustained_worst_case,
            report.sustained_random.map_or("-".into(), |r| format!("{r:.4}")),
            report.sustained() / report.v_min,
            report.starts,
            report.left_domain
        );
        results.push((path.clone(), solution, report));
    }
    if let Some(name) = &args.record {
        write_outputs(&args, &options, &results, name)?;
    }
    Ok(())
}

fn write_outputs(
    args: &Args,
    options: &RolloutOptions,
    results: &[(PathBuf, Solution, RolloutReport)],
    name: &str,
) -> anyhow::Result<()> {
    let mut table = MarkdownTable::new(&[
        "solution",
        "solved to (s)",
        "V_min",
        "sustained: worst-case planner",
        "random planners",
        "sustained / V_min",
        "starts",
        "left the domain",
    ]);
    for (_, solution, report) in results {
        table.row(vec![
            label(solution),
            format!("{:.1}", solution.info.horizon),
            format!("{:.4}", report.v_min),
            format!("{:.4}", report.sustained_worst_case),
            report.sustained_random.map_or("-".into(), |r| format!("{r:.4}")),
            format!("{:.3}", report.sustained() / report.v_min),
            report.starts.to_string(),
            report.left_domain.to_string(),
        ]);
    }
    // Per system and resolution: the solutions' V_min and the sustained errors against the first parameter.
    let mut groups: Vec<Group> = Vec::new();
    for (_, solution, report) in results {
        let grid = solution.grid.axes().iter().map(|a| a.n.to_string()).collect::<Vec<_>>().join("x");
        let key = format!("{} {grid}", solution.info.system);
        let beta = solution.info.params.first().copied().unwrap_or(f64::NAN);
        let index = groups.iter().position(|g| g.key == key).unwrap_or_else(|| {
            groups.push(Group { key, v_min: Vec::new(), sustained: Vec::new() });
            groups.len() - 1
        });
        groups[index].v_min.push((beta, report.v_min));
        groups[index].sustained.push((beta, report.sustained()));
    }
    let series: Vec<Series> = groups
        .into_iter()
        .flat_map(|g| {
            [
                Series { label: format!("{}: grid V_min at its horizon", g.key), points: g.v_min, markers: true },
                Series { label: format!("{}: error planners sustain", g.key), points: g.sustained, markers: true },
            ]
        })
        .collect();
    std::fs::create_dir_all(&args.results_dir)?;
    let png = args.results_dir.join(format!("{name}-vmin-vs-sustained.png"));
    let chart = Chart {
        title: "grid V_min and the error planners sustain against its policy",
        x_label: "beta (m/s)",
        y_label: "m",
        log_y: false,
    };
    line_chart(&png, &chart, &series).map_err(anyhow::Error::msg)?;
    let figures = json!({
        "solutions": results.iter().map(|(path, s, r)| {
            let mut figure = solution_figure(path, s);
            figure["report"] = json!(r);
            figure
        }).collect::<Vec<_>>(),
        "plot": png,
    });
    let path = write_command_record(
        &args.results_dir,
        name,
        json!({ "rollout": options }),
        figures,
        &[("sustained error against each solution's policy", &table)],
    )?;
    println!("wrote {} and {}", path.display(), png.display());
    Ok(())
}

/// `rollout --system`: the axes of a decomposed system side by side, per `beta`.
fn run_axes(args: &Args, options: &RolloutOptions, id: &str) -> anyhow::Result<()> {
    let system = by_id(id).with_context(|| format!("unknown system `{id}`"))?;
    let axes = decomposition(id).with_context(|| format!("`{id}` has no decomposition into axes"))?;
    let (solutions, betas) = load_axis_solutions(id, &axes, &args.solutions)?;
    let mut table = MarkdownTable::new(&[
        "beta",
        "axis V_min",
        "combined bound",
        "sustained: worst-case planner",
        "random planners",
        "sustained / bound",
        "axis sustained / own V_min",
        "peak",
        "starts",
        "left the domain",
    ]);
    let mut reports: Vec<AxesRolloutReport> = Vec::new();
    for beta in betas {
        let pairs = axes_at(id, &axes, &solutions, beta)?;
        let report = roll_out_axes(&system, &pairs, options)?;
        let r = &report.rollout;
        let own: Vec<String> =
            report.axis_sustained.iter().zip(&report.axis_v_min).map(|(s, v)| format!("{:.3}", s / v)).collect();
        println!(
            "{id} at beta {beta}: axis V_min {:?}, combined bound {:.4}; sustained: worst-case {:.4}, random {} ({:.3} of the bound); each axis against its own V_min: {}; {} rollouts left the domain",
            report.axis_v_min,
            report.combined_bound,
            r.sustained_worst_case,
            r.sustained_random.map_or("-".into(), |x| format!("{x:.4}")),
            r.sustained() / report.combined_bound,
            own.join(", "),
            r.left_domain
        );
        table.row(vec![
            format!("{beta}"),
            report.axis_v_min.iter().map(|v| format!("{v:.4}")).collect::<Vec<_>>().join(", "),
            format!("{:.4}", report.combined_bound),
            format!("{:.4}", r.sustained_worst_case),
            r.sustained_random.map_or("-".into(), |x| format!("{x:.4}")),
            format!("{:.3}", r.sustained() / report.combined_bound),
            own.join(", "),
            format!("{:.4}", r.peak),
            r.starts.to_string(),
            r.left_domain.to_string(),
        ]);
        reports.push(report);
    }
    if let Some(name) = &args.record {
        let figures = json!({
            "system": id,
            "solutions": solutions.iter().map(|(path, s)| solution_figure(path, s)).collect::<Vec<_>>(),
            "reports": reports,
        });
        let path = write_command_record(
            &args.results_dir,
            name,
            json!({ "rollout": options }),
            figures,
            &[("the axes' policies side by side in the full system", &table)],
        )?;
        println!("wrote {}", path.display());
    }
    Ok(())
}
