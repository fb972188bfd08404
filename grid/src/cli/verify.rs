//! `verify`: scenario verification of a bundle's TEB table, written back into a copy of the bundle; with
//! `--shard`, one shard's rows written as a part, which `verify-merge` combines into what a single run writes.

use super::common::write_command_record;
use anyhow::Context;
use fastrack_grid::format;
use fastrack_grid::solver::Solution;
use fastrack_grid::verify::{
    apply_reports, axes, combine_pieces, required_samples, verify_rows, Batching, ControlLaw, Correction, ErrorScale,
    FalsificationOptions, RecordedStates, RowReport, SearchOptions, Selection, VerifyOptions,
};
use fastrack_lab::record::MarkdownTable;
use fastrack_lab::shard::{Part, Shard};
use fastrack_valuefn::bundle::Bundle;
use fastrack_valuefn::manifest::{Manifest, TebRow};
use fastrack_valuefn::runtime::{runtime, Evaluator, GraphDims};
use fastrack_valuefn::system::{for_bundle, AffineSystem};
use indicatif::{ProgressBar, ProgressStyle};
use serde_json::json;
use std::path::{Path, PathBuf};
use std::time::Instant;

/// File-name stem of verification parts (`grid-verify-part-<index>-of-<count>.json`).
pub(super) const PART_STEM: &str = "grid-verify";

/// Arguments of `verify`.
#[derive(clap::Args)]
pub struct Args {
    #[command(flatten)]
    source: BundleSource,
    /// Repository root the verified bundle is written into (`<out>/<name>/<version>/`); may be the
    /// bundle's own repository to update it in place. Not with `--control-law grid`, which writes only a record.
    #[arg(long, required_unless_present_any = ["part_dir", "control_law"])]
    out: Option<PathBuf>,
    /// Whose control law the tracker plays: `model` (the bundle's served control, what is verified) or `grid`
    /// (the policy of the row's grid solution from --grid-solutions, on the bundle's own sampled sets: a
    /// reference for what the learned control loses; writes a record, never a bundle).
    #[arg(long, value_enum)]
    control_law: Option<ControlLaw>,
    /// Violation-probability bound epsilon.
    #[arg(long, default_value_t = 1e-3)]
    eps: f64,
    /// The first round samples states in {V <= (1 + margin) level} (the level is V's minimum: its own sublevel
    /// set has next to no volume); later rounds sample under the largest error the previous one found.
    #[arg(long, default_value_t = 0.05)]
    level_margin: f64,
    /// Largest number of rounds of the `set` correction (the `bound` correction has one).
    #[arg(long, default_value_t = 8)]
    max_rounds: usize,
    /// What a round with a violation raises: `set` (the next round samples {V <= c} at the raised c: the set
    /// must hold its own level) or `bound` (every round samples the first round's set; only the bound rises).
    #[arg(long, value_enum, default_value_t = Correction::Set)]
    correction: Correction,
    /// A sample violates a round when its error exceeds (1 + slack) times the round's level (room for the
    /// control held over each step).
    #[arg(long, default_value_t = 0.02)]
    slack: f64,
    /// Largest number of uniform proposals per round for rejection sampling.
    #[arg(long, default_value_t = 20_000_000)]
    max_proposals: usize,
    /// The first round samples under at least the level whose sublevel set holds this share of the proposal
    /// box (from a pilot of proposals), so that a narrow learned minimum can be sampled (0: off).
    #[arg(long, default_value_t = 5e-3)]
    min_acceptance: f64,
    /// Error coordinates of the proposals are drawn within this factor times the sampled level (0: the whole
    /// state box); sampling stops with an error if the set reaches the narrowed edge.
    #[arg(long, default_value_t = 2.5)]
    proposal_box: f64,
    /// Confidence parameter delta.
    #[arg(long, default_value_t = 1e-6)]
    delta: f64,
    /// Rollout horizon (s).
    #[arg(long, default_value_t = 10.0)]
    horizon: f64,
    /// RK4 step (s); control and planner are held over a step.
    #[arg(long, default_value_t = 0.01)]
    step: f64,
    /// Random bang-bang planners per sample, besides the worst-case planners.
    #[arg(long, default_value_t = 2)]
    random_planners: usize,
    /// Mean time between a random planner's switches (s).
    #[arg(long, default_value_t = 1.0)]
    mean_dwell: f64,
    /// Grid solutions (.ftgrid, comma-separated) whose worst-case planners play the rows near their beta.
    #[arg(long, value_delimiter = ',')]
    grid_solutions: Vec<PathBuf>,
    /// Largest distance in beta between a row and the grid solution that plays it.
    #[arg(long, default_value_t = 0.05)]
    grid_tolerance: f64,
    /// Schedules per start and iteration of the cross-entropy search over planner schedules (0: no search).
    #[arg(long, default_value_t = 16)]
    search_population: usize,
    /// Iterations of the search.
    #[arg(long, default_value_t = 3)]
    search_iterations: usize,
    /// Elite schedules per start and iteration.
    #[arg(long, default_value_t = 4)]
    search_elites: usize,
    /// How long each vertex of a searched schedule is held (s).
    #[arg(long, default_value_t = 0.5)]
    search_segment: f64,
    /// Weight of the elites in each update of the search's probabilities.
    #[arg(long, default_value_t = 0.7)]
    search_smoothing: f64,
    /// Samples searched per batch: those the other planner families pushed furthest.
    #[arg(long, default_value_t = 64)]
    search_per_batch: usize,
    /// Skip the zero-error slice check (uniform states of each round's set with every error coordinate at 0,
    /// as many as the uniform check).
    #[arg(long)]
    no_zero_error_slice: bool,
    /// Relative states the online loop visited in simulated runs (`fastrack sim bench --visits FILE`): each
    /// round also rolls out as many draws from those of them inside its set as the uniform check (none: no
    /// operational check). With --axis-of, the composite's states, projected on the axes this bundle serves.
    #[arg(long)]
    operational_states: Option<PathBuf>,
    /// Starts of the falsification search over start states: the samples the other checks pushed furthest
    /// (0: no falsification).
    #[arg(long, default_value_t = 64)]
    falsification_starts: usize,
    /// Proposals per start and iteration of the falsification.
    #[arg(long, default_value_t = 16)]
    falsification_population: usize,
    /// Iterations of the falsification.
    #[arg(long, default_value_t = 4)]
    falsification_iterations: usize,
    /// Half-width of the falsification's first proposal box around a start, as a share of each coordinate's
    /// width in the trained domain (halved every iteration).
    #[arg(long, default_value_t = 0.05)]
    falsification_scale: f64,
    /// Samples rolled out together; a round ends after the first batch with a violation.
    #[arg(long, default_value_t = 4096)]
    batch: usize,
    /// Largest number of states per ONNX Runtime call.
    #[arg(long, default_value_t = 4096)]
    chunk: usize,
    /// Evaluate and step the chunks in turn on one thread (one session) instead of on every core.
    #[arg(long)]
    sequential: bool,
    /// Split each row's samples into this many pieces, each on a random stream of its own (with `--correction
    /// bound`); with `--shard`, each piece of each row is an item of its own, so that a long row runs as short
    /// jobs. The pieces combine into the row's one round.
    #[arg(long, default_value_t = 1)]
    pieces: usize,
    /// Verify this bundle as an axis of the composite bundle at this path (`quad10d`'s x or z network): at the
    /// composite's rows, on the axis' share of each row's sampled set, with each rollout's error less its
    /// start's value (needs `--correction bound` and `--part-dir`; `verify-merge --axis` composes the axes'
    /// parts into the composite's verification).
    #[arg(long, requires = "part_dir", conflicts_with = "out")]
    axis_of: Option<PathBuf>,
    /// Only the rows with these betas (default: every row).
    #[arg(long, value_delimiter = ',')]
    betas: Vec<f64>,
    /// Random seed.
    #[arg(long, default_value_t = 11)]
    seed: u64,
    #[command(flatten)]
    recording: Recording,
    /// Only this shard of the rows, `INDEX/COUNT` (the `i`-th row verified goes to shard `i % COUNT`), or
    /// `COUNT` with the index from `JOB_COMPLETION_INDEX` (a Kubernetes Indexed Job); writes a part
    /// (--part-dir) for `verify-merge` instead of a bundle and a record.
    #[arg(long)]
    shard: Option<Shard>,
    /// Folder the shard's part is written into, as `grid-verify-part-<index>-of-<count>.json`.
    #[arg(long)]
    part_dir: Option<PathBuf>,
}

/// The bundle a command reads, and the ONNX Runtime that evaluates it.
#[derive(clap::Args)]
pub(super) struct BundleSource {
    /// The bundle's version folder, e.g. `models/dubins4d/5`.
    #[arg(long)]
    pub(super) bundle: PathBuf,
    /// ONNX Runtime library (default: FASTRACK_ORT_LIB, then .cache/onnxruntime).
    #[arg(long)]
    ort_lib: Option<PathBuf>,
}

impl BundleSource {
    /// The bundle, its system and an evaluator of its network (one session per worker thread).
    pub(super) fn load(&self) -> anyhow::Result<Loaded> {
        let bundle = Bundle::load(&self.bundle)?;
        let manifest = &bundle.manifest;
        let system = for_bundle(&manifest.system.id, manifest.n_params()).with_context(|| {
            format!("the bundle's system `{}` with {} parameters is unknown", manifest.system.id, manifest.n_params())
        })?;
        let sessions = rayon::current_num_threads();
        let evaluator =
            Evaluator::new(runtime(self.ort_lib.as_deref())?, &bundle.onnx, GraphDims::of(manifest), sessions)?;
        Ok(Loaded { bundle, system, evaluator })
    }
}

/// Where a verification's record goes.
#[derive(clap::Args)]
pub(super) struct Recording {
    /// Record name (default `grid-verify-<model>`).
    #[arg(long)]
    record: Option<String>,
    /// Folder of measurement records.
    #[arg(long, default_value = "bench/results")]
    results_dir: PathBuf,
}

impl Recording {
    /// The outputs of a verification writing its bundle into `out` (none: a record only).
    pub(super) fn outputs<'a>(&'a self, out: Option<&'a Path>) -> Outputs<'a> {
        Outputs { out, record: self.record.as_deref(), results_dir: &self.results_dir }
    }
}

/// A bundle with what verifying it needs.
pub(super) struct Loaded {
    pub(super) bundle: Bundle,
    pub(super) system: AffineSystem,
    pub(super) evaluator: Evaluator,
}

/// Runs `verify`.
pub fn run(args: Args) -> anyhow::Result<()> {
    let shard = args.shard.unwrap_or(Shard::WHOLE);
    anyhow::ensure!(
        shard.is_whole() || args.part_dir.is_some(),
        "--shard {shard} writes a part: give --part-dir (merge the parts with `fastrack-grid verify-merge`)"
    );
    let control_law = args.control_law.unwrap_or_default();
    anyhow::ensure!(
        control_law == ControlLaw::Model || args.out.is_none(),
        "--control-law grid verifies no bundle: it writes only a record, so --out does not apply"
    );
    anyhow::ensure!(
        control_law == ControlLaw::Grid || args.out.is_some() || args.part_dir.is_some(),
        "give --out, the repository the verified bundle is written into"
    );
    let Loaded { mut bundle, system, evaluator } = args.source.load()?;
    let composite = args.axis_of.as_deref().map(Bundle::load).transpose()?;
    if let Some(composite) = &composite {
        anyhow::ensure!(
            args.correction == Correction::Bound,
            "--axis-of bounds each rollout's error less its start's value: give --correction bound"
        );
        bundle.manifest.teb_table = axes::axis_rows(&composite.manifest, &bundle.manifest, args.level_margin)?;
    }
    let error_scale = if composite.is_some() { ErrorScale::ExcessOverStartValue } else { ErrorScale::Absolute };
    let options = VerifyOptions {
        eps: args.eps,
        level_margin: args.level_margin,
        max_rounds: args.max_rounds,
        correction: args.correction,
        slack: args.slack,
        max_proposals: args.max_proposals,
        proposal_box: args.proposal_box,
        min_acceptance: args.min_acceptance,
        delta: args.delta,
        horizon: args.horizon,
        step: args.step,
        random_planners: args.random_planners,
        mean_dwell: args.mean_dwell,
        search: SearchOptions {
            population: args.search_population,
            iterations: args.search_iterations,
            elites: args.search_elites,
            segment: args.search_segment,
            smoothing: args.search_smoothing,
            per_batch: args.search_per_batch,
        },
        zero_error_slice: !args.no_zero_error_slice,
        falsification: FalsificationOptions {
            starts: args.falsification_starts,
            population: args.falsification_population,
            iterations: args.falsification_iterations,
            scale: args.falsification_scale,
        },
        batch: args.batch,
        batching: Batching { chunk: args.chunk, parallel: !args.sequential },
        control_law,
        pieces: args.pieces,
        error_scale,
        seed: args.seed,
    };
    let adversaries: Vec<Solution> = args
        .grid_solutions
        .iter()
        .map(|p| format::load(p).with_context(|| format!("loading the grid solution {}", p.display())))
        .collect::<anyhow::Result<_>>()?;
    println!(
        "N = ceil(ln({1}) / ln(1 - {0})) = {2} samples per check and row",
        args.eps,
        args.delta,
        required_samples(args.eps, args.delta)
    );
    let bar = ProgressBar::new(0);
    bar.set_style(
        ProgressStyle::with_template("{elapsed_precise} [{bar:30}] {pos}/{len} rows")
            .unwrap_or_else(|_| ProgressStyle::default_bar()),
    );
    let betas = (!args.betas.is_empty()).then_some(&args.betas[..]);
    let started = Instant::now();
    let operational = match (args.operational_states.as_deref(), &composite) {
        (None, _) => None,
        (Some(path), None) => Some(RecordedStates::read(path, &state_names(&bundle.manifest))?),
        (Some(path), Some(composite)) => {
            let recorded = RecordedStates::read(path, &state_names(&composite.manifest))?;
            Some(axes::axis_states(&composite.manifest, &bundle.manifest, &recorded)?)
        }
    };
    if let Some(recorded) = &operational {
        println!("operational states: {} recorded, by branch {:?}", recorded.len(), recorded.branches);
    }
    let selection = Selection {
        betas,
        adversaries: &adversaries,
        grid_tolerance: args.grid_tolerance,
        operational: operational.as_ref(),
    };
    let reports = verify_rows(&evaluator, &bundle.manifest, &system, &selection, shard, &options, &bar)?;
    bar.finish_and_clear();
    let config = json!({ "bundle": args.source.bundle, "model": bundle.manifest.name, "version": bundle.manifest.version,
        "onnx_sha256": bundle.manifest.onnx_sha256, "untrained": bundle.manifest.untrained, "options": options,
        "betas": args.betas, "grid_solutions": args.grid_solutions, "grid_tolerance": args.grid_tolerance,
        "operational_states": args.operational_states,
        "operational_recorded": operational.as_ref().map(|r| json!({"states": r.len(), "by_branch": r.branches})),
        "threads": rayon::current_num_threads(),
        "axis_of": composite.as_ref().map(|c| json!({ "bundle": args.axis_of, "model": c.manifest.name,
            "version": c.manifest.version, "onnx_sha256": c.manifest.onnx_sha256 })) });
    if let Some(dir) = &args.part_dir {
        let part = Part { config, shard, wall_s: started.elapsed().as_secs_f64(), items: reports };
        let path = part.write(dir, PART_STEM).with_context(|| format!("writing the part into {}", dir.display()))?;
        println!("shard {shard}: {} rows or pieces verified; part {}", part.items.len(), path.display());
        return Ok(());
    }
    let reports = combine_pieces(reports)?;
    let out = args.recording.outputs(args.out.as_deref());
    finish(&evaluator, bundle, &system, reports, config, &out)
}

/// A bundle's state coordinates by name, in order.
fn state_names(manifest: &Manifest) -> Vec<String> {
    manifest.state.iter().map(|d| d.name.clone()).collect()
}

/// Where a verification's results go.
pub(super) struct Outputs<'a> {
    /// Where the verified bundle goes (none: a reference run, record only).
    pub(super) out: Option<&'a Path>,
    pub(super) record: Option<&'a str>,
    pub(super) results_dir: &'a Path,
}

/// Writes `reports` into the bundle's table, prints and records them, and writes the verified bundle. A table
/// the reports cannot be written into (a subset of rows that breaks the monotone bounds) still gets its record,
/// without the rows' set levels and bounds, before the error.
pub(super) fn finish(
    evaluator: &Evaluator,
    bundle: Bundle,
    system: &AffineSystem,
    reports: Vec<RowReport>,
    config: serde_json::Value,
    outputs: &Outputs<'_>,
) -> anyhow::Result<()> {
    let mut manifest: Manifest = bundle.manifest.clone();
    let applied = apply_reports(evaluator, &mut manifest, system, &reports);
    let mut table = MarkdownTable::new(&[
        "beta",
        "learned level",
        "outcome",
        "rounds",
        "sampled level",
        "verified level",
        "set level",
        "bound",
        "violations / N",
        "checks: N / violations / max l",
        "recorded in force / outside the set",
        "hardest planner",
        "max l per planner",
        "searched",
        "acceptance",
        "wall (s)",
        "rollout steps/s",
    ]);
    for r in &reports {
        let v = &r.verification;
        let applied_row = applied.as_ref().ok().and_then(|()| manifest.teb_table.iter().find(|row| row.beta == r.beta));
        let [set_level, bound] = [TebRow::set_level, TebRow::bound]
            .map(|number| applied_row.map_or_else(|| "-".to_string(), |row| format!("{:.4}", number(row))));
        let levels: Vec<String> = r.rounds.iter().map(|round| format!("{:.4}", round.level)).collect();
        println!(
            "beta {:.4}: level {:.4}, rounds at {} -> verified {:.4} ({} of {} samples broke the last), {:.0} s",
            r.beta,
            r.level,
            levels.join(", "),
            v.verified_level,
            v.violations,
            v.samples,
            r.wall_s
        );
        let per_planner: Vec<String> = v.planners.iter().map(|p| format!("{} {:.4}", p.family, p.max_error)).collect();
        table.row(vec![
            format!("{:.4}", r.beta),
            format!("{:.4}", r.level),
            serde_json::to_value(r.outcome).ok().and_then(|o| o.as_str().map(String::from)).unwrap_or_default(),
            format!("{}", r.rounds.len()),
            format!("{:.4}", r.sampled_level()),
            format!("{:.4}", v.verified_level),
            set_level,
            bound,
            format!("{} / {}", v.violations, v.samples),
            v.checks
                .iter()
                .map(|c| format!("{} {} / {} / {:.4}", c.distribution, c.samples, c.violations, c.max_error))
                .collect::<Vec<_>>()
                .join("; "),
            r.rounds
                .last()
                .and_then(|round| round.in_force)
                .map_or_else(|| "-".to_string(), |f| format!("{} / {}", f.recorded, f.outside)),
            v.hardest_planner().map_or_else(String::new, |p| p.family.clone()),
            per_planner.join("; "),
            format!("{}", r.searched),
            format!("{:.4}", r.rounds.last().map_or(f64::NAN, |round| round.acceptance)),
            format!("{:.1}", r.wall_s),
            format!("{:.0}", r.rollout_steps as f64 / r.wall_s.max(1e-9)),
        ]);
    }
    let wall: f64 = reports.iter().map(|r| r.wall_s).sum();
    println!("{} rows in {wall:.0} s", reports.len());
    let broken = reports.iter().filter(|r| r.verification.violations > 0).count();
    println!("{broken} of {} rows had violations", reports.len());
    let name = outputs.record.map_or_else(|| format!("grid-verify-{}", manifest.name), str::to_string);
    let path = write_command_record(
        outputs.results_dir,
        &name,
        config,
        json!({ "rows": reports, "rows_with_violations": broken, "wall_s": wall }),
        &[("verification", &table)],
    )?;
    println!("wrote {}", path.display());
    applied.context("the record is written; the reports do not fit the bundle's table, so no bundle is")?;
    if let Some(out) = outputs.out {
        let dir = Bundle::write(out, manifest, &bundle.onnx)?;
        println!("wrote the verified bundle {}", dir.display());
    }
    Ok(())
}
