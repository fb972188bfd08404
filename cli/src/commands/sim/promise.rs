//! `fastrack sim promise`: each served row's promise in closed loop through the server's `Track` stream, from
//! starts across the row's certified set against the served gradient's worst case and random planners; the
//! largest error per row beside its bound, as a table and a record.

use super::{print, Recording};
use anyhow::Context as _;
use fastrack_client::{model_ref, FastrackClient};
use fastrack_lab::record::{write_record, MarkdownTable};
use fastrack_sim::promise::{PromiseCheck, PromiseOptions, RowPromise};
use indicatif::{ProgressBar, ProgressStyle};
use serde_json::json;

/// Arguments of `fastrack sim promise`.
#[derive(clap::Args)]
pub(super) struct Args {
    /// Model name.
    #[arg(long, default_value = "dubins4d")]
    model: String,
    /// Model version (0: the server's default).
    #[arg(long, default_value_t = 0)]
    version: u32,
    /// Only the rows with these betas (default: every row).
    #[arg(long, value_delimiter = ',')]
    betas: Vec<f64>,
    /// Starts per row: the set's centre and its edges along random rays.
    #[arg(long, default_value_t = 16)]
    starts: usize,
    /// Random bang-bang planners per start, besides the worst case of the served gradient.
    #[arg(long, default_value_t = 2)]
    random_planners: usize,
    /// Rollout horizon (s); default each row's verification horizon.
    #[arg(long)]
    horizon: Option<f64>,
    /// Seed of the rays and the random planners.
    #[arg(long, default_value_t = 7)]
    seed: u64,
    #[command(flatten)]
    recording: Recording,
}

/// Runs `fastrack sim promise`; fails when a row's error passed its bound.
pub(super) async fn run(client: &FastrackClient, args: Args, json_mode: bool) -> anyhow::Result<()> {
    let model = model_ref(&args.model, args.version);
    let check = PromiseCheck::new(client.clone(), model).await.context("reading the model")?;
    let options = PromiseOptions {
        starts: args.starts,
        random_planners: args.random_planners,
        horizon: args.horizon,
        seed: args.seed,
        ..PromiseOptions::default()
    };
    anyhow::ensure!(options.starts >= 1, "--starts must be at least 1 (the set's centre)");
    let betas: Vec<f64> =
        if args.betas.is_empty() { check.rows().iter().map(|r| r.beta).collect() } else { args.betas.clone() };
    let bar = ProgressBar::new(betas.len() as u64);
    bar.set_style(
        ProgressStyle::with_template("{elapsed_precise} [{bar:30}] {pos}/{len} rows")
            .unwrap_or_else(|_| ProgressStyle::default_bar()),
    );
    let mut rows = Vec::new();
    for &beta in &betas {
        rows.push(check.row(beta, &options).await.with_context(|| format!("the row at beta {beta}"))?);
        bar.inc(1);
    }
    bar.finish_and_clear();
    let table = promise_table(&rows);
    if let Some(name) = &args.recording.record {
        let command = format!(
            "fastrack sim promise --model {} --version {} --starts {} --random-planners {} --seed {} --record {name}",
            args.model, args.version, args.starts, args.random_planners, args.seed
        );
        let config = json!({ "model": args.model, "version": args.version, "options": options,
            "model_version_served": check.version() });
        let path = write_record(&args.recording.results_dir, name, &command, config, json!(rows), &[("Rows", &table)])?;
        eprintln!("record: {}", path.display());
    }
    print(json_mode, json!(rows), || table.to_markdown());
    let broken: Vec<String> = rows.iter().filter(|r| !r.kept()).map(|r| r.beta.to_string()).collect();
    anyhow::ensure!(broken.is_empty(), "the error passed the bound at beta {}", broken.join(", "));
    Ok(())
}

/// The rows as a table.
fn promise_table(rows: &[RowPromise]) -> MarkdownTable {
    let mut table = MarkdownTable::new(&[
        "beta",
        "set level",
        "bound (m)",
        "starts in the set",
        "starts refused",
        "largest error, worst case (m)",
        "largest error, random (m)",
        "largest / bound",
        "ticks out of domain",
    ]);
    for r in rows {
        table.row(vec![
            format!("{:.4}", r.beta),
            format!("{:.4}", r.set_level),
            format!("{:.4}", r.bound),
            r.certified_starts.to_string(),
            r.refused_starts.to_string(),
            format!("{:.4}", r.worst_case_error),
            r.random_error.map_or("-".into(), |e| format!("{e:.4}")),
            format!("{:.3}", r.largest_error() / r.bound),
            r.out_of_domain_ticks.to_string(),
        ]);
    }
    table
}
