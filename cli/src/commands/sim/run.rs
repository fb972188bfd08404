//! `fastrack sim run`: one world, one method, a summary and figures; in the plane or in space, by the
//! model's planner.

use super::{print, world_of, Generation, Simulation};
use anyhow::Context as _;
use fastrack_cli::load_generator::LatencySummary;
use fastrack_client::FastrackClient;
use fastrack_sim::episode::{Outcome, Run, Simulated, Simulator};
use fastrack_sim::methods::Method;
use fastrack_sim::plot::{over_time, trajectory, Outlined, View};
use fastrack_sim::viewer::write_html;
use serde_json::json;
use std::path::PathBuf;

/// Arguments of `fastrack sim run`.
#[derive(clap::Args)]
pub(super) struct Args {
    /// A world file (TOML or JSON); without it, a world generated from --seed.
    #[arg(long)]
    world: Option<PathBuf>,
    /// Seed of the generated world (and of the method's randomness).
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// pf-planner (Parametric FaSTrack under the planner rule on the fastest raw path, the fastest on every
    /// world family), pf (the paper's rule on the shortest raw path), pf-fast, f-low, f-high, mf, mf-quick or
    /// mppi.
    #[arg(long, default_value = "pf-planner")]
    method: String,
    /// Where the trajectory figure goes (a second figure, over time, goes beside it; in space the view from
    /// above goes here, the side view beside it, and a page to turn in a browser, `.html`).
    #[arg(long, default_value = "target/sim/run.png")]
    plot: PathBuf,
    #[command(flatten)]
    simulation: Simulation,
    #[command(flatten)]
    generation: Generation,
}

fn run_line<O, const D: usize>(run: &Run<O, D>, beta_l: f64) -> String {
    let latency = LatencySummary::from_latencies(&mut run.decision_times.clone());
    let speed = run.mean_beta().map_or(String::new(), |mean| {
        format!(" mean beta {mean:.3} m/s, above beta_l {:.0}% of the time;", 100.0 * run.share_above(beta_l))
    });
    format!(
        "{}: {} after {:.2} s;{speed} min clearance {:.3} m; largest error - bound {}; replans {}, resets {}, held steps {}, server calls {}, steps out of domain {}, steps past the certificate {}, steps the bound reached an obstacle {}; decision p50 {:.3} ms, p99 {:.3} ms{}",
        run.method,
        run.outcome.label(),
        run.time,
        run.min_clearance,
        run.worst_excess.map_or("-".into(), |e| format!("{e:.3} m")),
        run.replans,
        run.resets,
        run.held_steps,
        run.round_trips,
        run.out_of_domain,
        run.uncertified_steps,
        run.exposed_steps,
        latency.p50.as_secs_f64() * 1e3,
        latency.p99.as_secs_f64() * 1e3,
        match &run.outcome {
            Outcome::Failed(why) => format!(" ({why})"),
            Outcome::BoundExceeded { error, bound } => format!(" (error {error:.3} m over the bound {bound:.3} m)"),
            _ => String::new(),
        }
    )
}

/// Runs `fastrack sim run`.
pub(super) async fn run(client: &FastrackClient, args: Args, json_mode: bool) -> anyhow::Result<()> {
    let simulator = args.simulation.connect(client, false).await?;
    in_dimension!(async simulator.dim(), run_in(&simulator, args, json_mode))
}

/// One run in a world of `D` axes, its trajectory drawn in each of the dimension's views.
async fn run_in<O: Simulated<D> + Outlined<D>, const D: usize>(
    simulator: &std::sync::Arc<Simulator>,
    args: Args,
    json_mode: bool,
) -> anyhow::Result<()> {
    let beta_l = simulator.speeds()[0].beta;
    let world = world_of::<O, D>(args.world.as_ref(), &args.generation, args.seed, simulator.steb_radius())?;
    let method = Method::parse(&args.method).map_err(anyhow::Error::msg)?;
    let run = simulator.spawn_run(world.clone(), method, args.seed).await.context("the run's thread failed")??;
    if let Some(dir) = args.plot.parent() {
        std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
    }
    let mut figures = Vec::new();
    for (extension, view) in View::all::<D>() {
        let figure = args.plot.with_extension(extension);
        trajectory(&figure, &world, &run, beta_l, 2.0, *view).map_err(anyhow::Error::msg)?;
        figures.push(figure);
    }
    let over = args.plot.with_extension("time.png");
    over_time(&over, &run).map_err(anyhow::Error::msg)?;
    figures.push(over);
    if D == 3 {
        // A run in space also gets a page to turn in a browser.
        let page = args.plot.with_extension("html");
        write_html(&page, &world, &run, beta_l, 2.0).with_context(|| format!("writing {}", page.display()))?;
        figures.push(page);
    }
    print(
        json_mode,
        json!({"method": run.method, "outcome": run.outcome.label(), "time_s": run.time, "min_clearance_m": run.min_clearance,
               "largest_error_minus_bound_m": run.worst_excess, "replans": run.replans, "resets": run.resets, "held_steps": run.held_steps,
               "server_calls": run.round_trips, "steps_out_of_domain": run.out_of_domain, "steps_past_the_certificate": run.uncertified_steps,
               "steps_the_bound_reached_an_obstacle": run.exposed_steps, "mean_beta": run.mean_beta(),
               "share_above_beta_l": run.share_above(beta_l), "figures": figures}),
        || {
            let names: Vec<String> = figures.iter().map(|f| f.display().to_string()).collect();
            format!("{}\nfigures: {}", run_line(&run, beta_l), names.join(", "))
        },
    );
    anyhow::ensure!(!run.outcome.is_unsafe(), "the run was unsafe: {}", run.outcome.label());
    Ok(())
}
