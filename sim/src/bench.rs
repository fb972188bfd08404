//! The benchmark of the paper's Table 1: every method through the same seeded worlds, summarised per
//! method (reached, collisions, bounds exceeded, time to goal, clearance, replans, resets, held steps, ticks,
//! decision latency), beside the paper's figures. A benchmark may be split into shards of worlds (`--shard`), each
//! writing a [`BenchPart`]; merged, the parts give the runs a single process gives.

use crate::episode::{add_seconds, Outcome, Run};
use fastrack_lab::record::MarkdownTable;
use fastrack_lab::shard::Part;
use serde::{Deserialize, Serialize};
use serde_json::{json, Value};
use std::time::Duration;

/// The world whose runs the benchmark's figure shows; the others keep no samples.
pub const FIGURE_WORLD: u64 = 1;

/// One run of a benchmark through worlds of obstacles `O` and `D` axes.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(bound(
    serialize = "O: Serialize, [f64; D]: Serialize",
    deserialize = "O: Deserialize<'de>, [f64; D]: Deserialize<'de>"
))]
pub struct BenchRun<O, const D: usize> {
    /// The world's seed (worlds 1..=N).
    pub world: u64,
    /// The method's position in the benchmark's list of methods.
    pub method: usize,
    /// The run; its per-period samples only on [`FIGURE_WORLD`], its visits only when kept.
    pub run: Run<O, D>,
}

impl<O, const D: usize> BenchRun<O, D> {
    /// The run of `method` on `world`, its samples dropped unless the figure shows that world and its visits
    /// unless `keep_visits`.
    pub fn new(world: u64, method: usize, mut run: Run<O, D>, keep_visits: bool) -> Self {
        if world != FIGURE_WORLD {
            run.samples = Vec::new();
        }
        if !keep_visits {
            run.visits = Vec::new();
        }
        Self { world, method, run }
    }
}

/// File-name stem of the benchmark's parts (`sim-bench-part-<index>-of-<count>.json`).
pub const PART_STEM: &str = "sim-bench";

/// What one shard of a benchmark ran.
pub type BenchPart<O, const D: usize> = Part<BenchRun<O, D>>;

/// The paper's Table 1 (20 runs): reached %, collision %, solution time (s), by method label.
pub const PAPER_TABLE: [(&str, f64, f64, f64); 4] = [
    ("F(beta_l)", 100.0, 0.0, 37.31),
    ("MF", 100.0, 0.0, 30.11),
    ("PF", 100.0, 0.0, 22.47),
    ("MPPI", 65.0, 35.0, 10.94),
];

/// One method's runs, summarised.
#[derive(Debug, Clone, PartialEq)]
pub struct Summary {
    /// The method.
    pub method: String,
    /// Runs.
    pub runs: usize,
    /// Runs that reached the goal.
    pub reached: usize,
    /// Runs that hit an obstacle.
    pub collided: usize,
    /// Runs whose tracking error exceeded the bound in force.
    pub bound_exceeded: usize,
    /// Runs that timed out or whose method gave up.
    pub other: usize,
    /// Mean and standard deviation of the time to goal over the reached runs (s).
    pub time_to_goal: Option<(f64, f64)>,
    /// Smallest clearance over every run (m).
    pub min_clearance: f64,
    /// Largest `error - bound` over every run (m), for methods with a bound.
    pub worst_excess: Option<f64>,
    /// Mean replans, resets and server calls per run.
    pub replans: f64,
    /// Mean planner resets per run.
    pub resets: f64,
    /// Mean control periods per run in which the planner held with the previous bound.
    pub held_steps: f64,
    /// Mean server calls per run.
    pub round_trips: f64,
    /// Control periods, over every run, whose control was read outside the trained domain.
    pub out_of_domain: usize,
    /// Control periods, over every run, that the certificate did not cover (see [`Run::uncertified_steps`]).
    pub uncertified_steps: usize,
    /// Control periods, over every run, whose planner lay within the bound in force of an obstacle (see
    /// [`Run::exposed_steps`]).
    pub exposed_steps: usize,
    /// Share of the time with each planner speed bound in use, `(beta, share)` by increasing `beta` (empty
    /// for a method without one).
    pub beta_shares: Vec<(f64, f64)>,
    /// Mean and 99th percentile of the wall time per replan of the raw path (ms).
    pub planning_ms: Option<(f64, f64)>,
    /// Median and 99th percentile of the decision time per control period.
    pub decision_p50: Duration,
    /// The 99th percentile.
    pub decision_p99: Duration,
}

impl Summary {
    /// The planner speed bound in use, averaged over time (`None` for a method without one).
    pub fn mean_beta(&self) -> Option<f64> {
        (!self.beta_shares.is_empty()).then(|| self.beta_shares.iter().map(|(beta, share)| beta * share).sum())
    }
}

/// Summarises the runs of one method.
pub fn summarise<O, const D: usize>(method: &str, runs: &[&Run<O, D>]) -> Summary {
    let count = |f: &dyn Fn(&Outcome) -> bool| runs.iter().filter(|r| f(&r.outcome)).count();
    let times: Vec<f64> = runs.iter().filter(|r| r.outcome == Outcome::Reached).map(|r| r.time).collect();
    let time_to_goal = (!times.is_empty()).then(|| {
        let mean = times.iter().sum::<f64>() / times.len() as f64;
        let var = times.iter().map(|t| (t - mean) * (t - mean)).sum::<f64>() / times.len() as f64;
        (mean, var.sqrt())
    });
    let mut decisions: Vec<Duration> = runs.iter().flat_map(|r| r.decision_times.iter().copied()).collect();
    decisions.sort();
    let rank = |q: f64| {
        decisions.get(((q * decisions.len() as f64).ceil() as usize).clamp(1, decisions.len().max(1)) - 1).copied()
    };
    let mean =
        |f: &dyn Fn(&Run<O, D>) -> usize| runs.iter().map(|r| f(r) as f64).sum::<f64>() / runs.len().max(1) as f64;
    let mut beta_shares: Vec<(f64, f64)> = Vec::new();
    for &(beta, seconds) in runs.iter().flat_map(|r| &r.beta_seconds) {
        add_seconds(&mut beta_shares, beta, seconds);
    }
    let total: f64 = beta_shares.iter().map(|(_, s)| s).sum();
    beta_shares.iter_mut().for_each(|(_, s)| *s /= total);
    let mut plans: Vec<f64> = runs.iter().flat_map(|r| &r.planning_times).map(|t| t.as_secs_f64() * 1e3).collect();
    plans.sort_by(f64::total_cmp);
    let planning_ms = (!plans.is_empty()).then(|| {
        let p99 = plans[((0.99 * plans.len() as f64).ceil() as usize).clamp(1, plans.len()) - 1];
        (plans.iter().sum::<f64>() / plans.len() as f64, p99)
    });
    Summary {
        method: method.to_string(),
        runs: runs.len(),
        reached: count(&|o| *o == Outcome::Reached),
        collided: count(&|o| *o == Outcome::Collided),
        bound_exceeded: count(&|o| matches!(o, Outcome::BoundExceeded { .. })),
        other: count(&|o| matches!(o, Outcome::TimedOut | Outcome::Failed(_))),
        time_to_goal,
        min_clearance: runs.iter().map(|r| r.min_clearance).fold(f64::INFINITY, f64::min),
        worst_excess: runs.iter().filter_map(|r| r.worst_excess).reduce(f64::max),
        replans: mean(&|r| r.replans),
        resets: mean(&|r| r.resets),
        held_steps: mean(&|r| r.held_steps),
        round_trips: mean(&|r| r.round_trips),
        out_of_domain: runs.iter().map(|r| r.out_of_domain).sum(),
        uncertified_steps: runs.iter().map(|r| r.uncertified_steps).sum(),
        exposed_steps: runs.iter().map(|r| r.exposed_steps).sum(),
        beta_shares,
        planning_ms,
        decision_p50: rank(0.5).unwrap_or_default(),
        decision_p99: rank(0.99).unwrap_or_default(),
    }
}

fn percent(part: usize, whole: usize) -> f64 {
    100.0 * part as f64 / whole.max(1) as f64
}

/// The summaries as a markdown table.
pub fn table(summaries: &[Summary]) -> MarkdownTable {
    let mut table = MarkdownTable::new(&[
        "method",
        "runs",
        "reached %",
        "collision %",
        "bound exceeded %",
        "timed out / gave up %",
        "time to goal (s, mean ± sd)",
        "min clearance (m)",
        "largest error - bound (m)",
        "replans",
        "resets",
        "held steps",
        "server calls",
        "steps out of domain",
        "steps past the certificate",
        "steps the bound reached an obstacle",
        "mean beta (m/s)",
        "planning per replan, mean / p99 (ms)",
        "decision p50 / p99 (ms)",
    ]);
    for s in summaries {
        table.row(vec![
            s.method.clone(),
            s.runs.to_string(),
            format!("{:.0}", percent(s.reached, s.runs)),
            format!("{:.0}", percent(s.collided, s.runs)),
            format!("{:.0}", percent(s.bound_exceeded, s.runs)),
            format!("{:.0}", percent(s.other, s.runs)),
            s.time_to_goal.map_or("-".into(), |(m, sd)| format!("{m:.2} ± {sd:.2}")),
            format!("{:.3}", s.min_clearance),
            s.worst_excess.map_or("-".into(), |e| format!("{e:.3}")),
            format!("{:.1}", s.replans),
            format!("{:.1}", s.resets),
            format!("{:.1}", s.held_steps),
            format!("{:.0}", s.round_trips),
            s.out_of_domain.to_string(),
            s.uncertified_steps.to_string(),
            s.exposed_steps.to_string(),
            s.mean_beta().map_or("-".into(), |b| format!("{b:.3}")),
            s.planning_ms.map_or("-".into(), |(mean, p99)| format!("{mean:.2} / {p99:.2}")),
            format!("{:.3} / {:.3}", s.decision_p50.as_secs_f64() * 1e3, s.decision_p99.as_secs_f64() * 1e3),
        ]);
    }
    table
}

/// The share of the time (%) each method spent at each planner speed bound, a column per `beta` any of them
/// used.
pub fn beta_share_table(summaries: &[Summary]) -> MarkdownTable {
    let mut betas: Vec<f64> = summaries.iter().flat_map(|s| s.beta_shares.iter().map(|(b, _)| *b)).collect();
    betas.sort_by(f64::total_cmp);
    betas.dedup();
    let headers: Vec<String> =
        std::iter::once("method".to_string()).chain(betas.iter().map(|b| format!("beta {b}"))).collect();
    let mut table = MarkdownTable::new(&headers.iter().map(String::as_str).collect::<Vec<_>>());
    for s in summaries.iter().filter(|s| !s.beta_shares.is_empty()) {
        let share = |beta: f64| s.beta_shares.iter().find(|(b, _)| *b == beta).map(|(_, share)| *share);
        let cells = betas.iter().map(|&b| share(b).map_or("-".into(), |x| format!("{:.1}", 100.0 * x)));
        table.row(std::iter::once(s.method.clone()).chain(cells).collect());
    }
    table
}

/// The paper's Table 1 beside ours: reached %, collision % and time to goal per method.
pub fn paper_comparison(summaries: &[Summary]) -> MarkdownTable {
    let mut table = MarkdownTable::new(&[
        "method",
        "paper: reached %",
        "ours",
        "paper: collision %",
        "ours",
        "paper: time (s)",
        "ours",
    ]);
    for s in summaries {
        let paper = PAPER_TABLE.iter().find(|p| p.0 == s.method);
        let cell = |f: fn(&(&str, f64, f64, f64)) -> f64, digits: usize| {
            paper.map_or("-".into(), |p| format!("{:.*}", digits, f(p)))
        };
        table.row(vec![
            s.method.clone(),
            cell(|p| p.1, 0),
            format!("{:.0}", percent(s.reached, s.runs)),
            cell(|p| p.2, 0),
            format!("{:.0}", percent(s.collided, s.runs)),
            cell(|p| p.3, 2),
            s.time_to_goal.map_or("-".into(), |(m, _)| format!("{m:.2}")),
        ]);
    }
    table
}

/// PF's mean time to goal over another method's, on the worlds both reached (the paper: 22.47 / 37.31 = 0.60
/// against FaSTrack).
pub fn time_ratio<O, const D: usize>(pf: &[&Run<O, D>], other: &[&Run<O, D>]) -> Option<(f64, usize)> {
    let pairs: Vec<(f64, f64)> = pf
        .iter()
        .zip(other)
        .filter(|(a, b)| a.outcome == Outcome::Reached && b.outcome == Outcome::Reached)
        .map(|(a, b)| (a.time, b.time))
        .collect();
    (!pairs.is_empty()).then(|| {
        let (a, b) = pairs.iter().fold((0.0, 0.0), |(x, y), (a, b)| (x + a, y + b));
        (a / b, pairs.len())
    })
}

/// A summary's figures as JSON.
pub fn summary_json(s: &Summary) -> Value {
    json!({
        "method": s.method, "runs": s.runs, "reached": s.reached, "collided": s.collided,
        "bound_exceeded": s.bound_exceeded, "timed_out_or_gave_up": s.other,
        "time_to_goal_mean_s": s.time_to_goal.map(|t| t.0), "time_to_goal_sd_s": s.time_to_goal.map(|t| t.1),
        "min_clearance_m": s.min_clearance, "largest_error_minus_bound_m": s.worst_excess,
        "replans_mean": s.replans, "resets_mean": s.resets, "held_steps_mean": s.held_steps, "server_calls_mean": s.round_trips, "steps_out_of_domain": s.out_of_domain, "steps_past_the_certificate": s.uncertified_steps,
        "steps_the_bound_reached_an_obstacle": s.exposed_steps,
        "mean_beta": s.mean_beta(),
        "beta_shares": s.beta_shares.iter().map(|(beta, share)| json!({"beta": beta, "share": share})).collect::<Vec<_>>(),
        "planning_ms_mean": s.planning_ms.map(|p| p.0), "planning_ms_p99": s.planning_ms.map(|p| p.1),
        "decision_p50_ms": s.decision_p50.as_secs_f64() * 1e3, "decision_p99_ms": s.decision_p99.as_secs_f64() * 1e3,
    })
}
