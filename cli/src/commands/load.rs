//! `fastrack load`: the load generator against a server (the serving bench adds the in-process ceiling).

use super::{print, seconds, Server};
use clap::ValueEnum;
use fastrack_cli::load_generator::{run_load, LoadReport, LoadSpec, Workload};
use fastrack_client::model_ref;
use indicatif::{ProgressBar, ProgressStyle};
use serde_json::json;
use std::time::Duration;

/// What the load generator's clients send.
#[derive(Clone, Copy, ValueEnum)]
enum WorkloadArg {
    /// Unary TrackingControl calls of --batch items.
    Unary,
    /// Ticks on Track streams, one stream per client.
    Track,
}

/// Arguments of `fastrack load`.
#[derive(clap::Args)]
pub struct Args {
    /// Model name.
    #[arg(long)]
    model: String,
    /// Version (0 = the default: the pinned version, else the latest).
    #[arg(long, default_value_t = 0)]
    version: u32,
    /// What each client sends.
    #[arg(long, value_enum, default_value = "unary")]
    workload: WorkloadArg,
    /// Items per unary request.
    #[arg(long, default_value_t = 1, value_parser = clap::value_parser!(u32).range(1..))]
    batch: u32,
    /// Concurrent clients, one run per value, comma separated.
    #[arg(long, value_delimiter = ',', default_value = "1,8,64,256", value_parser = clap::value_parser!(u32).range(1..))]
    concurrency: Vec<u32>,
    /// Measured seconds per run.
    #[arg(long, default_value = "5", value_parser = seconds)]
    duration_s: Duration,
    /// Warm-up seconds before each run's measurement.
    #[arg(long, default_value = "1", value_parser = seconds)]
    warmup_s: Duration,
    /// Seed of the random inputs.
    #[arg(long, default_value_t = 1)]
    seed: u64,
}

/// `fastrack load`: one run per concurrency; a table or JSON.
pub async fn run(server: &Server, args: Args, json_mode: bool) -> anyhow::Result<()> {
    let workload = match args.workload {
        WorkloadArg::Unary => Workload::Unary { batch: args.batch as usize },
        WorkloadArg::Track => Workload::Track,
    };
    let style = ProgressStyle::with_template("{prefix:>16} [{bar:30}] {msg}")?.progress_chars("=> ");
    let mut reports = Vec::with_capacity(args.concurrency.len());
    for &concurrency in &args.concurrency {
        let spec = LoadSpec {
            model: model_ref(&args.model, args.version),
            workload,
            concurrency: concurrency as usize,
            duration: args.duration_s,
            warmup: args.warmup_s,
            seed: args.seed,
        };
        let bar = ProgressBar::new(0).with_style(style.clone()).with_prefix(format!("concurrency {concurrency}"));
        reports.push(run_load(&server.address, &server.options, &spec, Some(bar)).await?);
    }
    let title = format!(
        "{} (version {}), {workload}, {:?} per run after {:?} warm-up",
        args.model,
        if args.version == 0 { "default".to_string() } else { args.version.to_string() },
        args.duration_s,
        args.warmup_s
    );
    print(
        json_mode,
        json!({
            "server": server.address, "model": args.model, "version": args.version, "workload": workload.to_string(),
            "runs": reports.iter().map(LoadReport::to_json).collect::<Vec<_>>(),
        }),
        || {
            let header = [
                "concurrency",
                "connections",
                "requests",
                "requests/s",
                "items/s",
                "p50 ms",
                "p90 ms",
                "p99 ms",
                "max ms",
                "errors",
            ];
            let ms = |d: Duration| format!("{:.2}", d.as_secs_f64() * 1e3);
            let rows: Vec<Vec<String>> = reports
                .iter()
                .map(|r| {
                    vec![
                        r.concurrency.to_string(),
                        r.connections.to_string(),
                        r.requests.to_string(),
                        format!("{:.0}", r.requests_per_s()),
                        format!("{:.0}", r.items_per_s()),
                        ms(r.latency.p50),
                        ms(r.latency.p90),
                        ms(r.latency.p99),
                        ms(r.latency.max),
                        errors_text(r),
                    ]
                })
                .collect();
            format!("{title}\n{}", aligned(&header, &rows))
        },
    );
    Ok(())
}

/// "0", or the total and the count per gRPC code.
fn errors_text(report: &LoadReport) -> String {
    if report.errors.is_empty() {
        return "0".into();
    }
    let by_code: Vec<String> = report.errors.iter().map(|(code, n)| format!("{code:?} {n}")).collect();
    format!("{} ({})", report.error_count(), by_code.join(", "))
}

/// A text table, right-aligned columns.
fn aligned(header: &[&str], rows: &[Vec<String>]) -> String {
    let mut widths: Vec<usize> = header.iter().map(|h| h.len()).collect();
    for row in rows {
        for (w, cell) in widths.iter_mut().zip(row) {
            *w = (*w).max(cell.len());
        }
    }
    let line =
        |cells: Vec<&str>| cells.iter().zip(&widths).map(|(c, w)| format!("{c:>w$}")).collect::<Vec<_>>().join("  ");
    let mut lines = vec![line(header.to_vec())];
    lines.extend(rows.iter().map(|r| line(r.iter().map(String::as_str).collect())));
    lines.join("\n")
}
