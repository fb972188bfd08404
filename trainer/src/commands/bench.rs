//! `bench`: the training-speed benchmark (the config's network and the paper's, beside the machine's matmul
//! rate and PyTorch).

use fastrack_lab::record::{write_record, MarkdownTable};
use fastrack_trainer::config::TrainConfig;
use fastrack_trainer::step_bench::{
    flops_per_iteration, iterations_per_second, matmul_gflops, torch_iterations_per_second, Case,
};
use fastrack_valuefn::network::FeatureLayout;
use std::path::PathBuf;

/// Arguments of `bench`.
#[derive(clap::Args)]
pub struct Args {
    /// The configuration whose network is benchmarked (and whose system and loss are used).
    #[arg(long, default_value = "trainer/configs/dubins4d.toml")]
    config: PathBuf,
    /// Where the record goes.
    #[arg(long, default_value = "bench/results")]
    out: PathBuf,
    /// Record name (`<out>/<record>.{json,md}`).
    #[arg(long, default_value = "trainer-speed")]
    record: String,
}

/// Runs `bench`.
pub fn run(args: Args) -> anyhow::Result<()> {
    run_bench(&args.config, &args.out, &args.record)
}

/// Runs the training-speed benchmark and writes its record.
fn run_bench(config_path: &std::path::Path, out: &std::path::Path, record: &str) -> anyhow::Result<()> {
    let config = &TrainConfig::load(config_path)?;
    let device = burn::tensor::Device::flex().autodiff();
    let encoding = config.network.periodic_encoding;
    let n_in = FeatureLayout::for_system(&config.system()?, encoding).n_features();
    let peak = matmul_gflops(2048, 5, &burn::tensor::Device::flex());
    eprintln!("f32 matmul 2048^3 (burn flex): {peak:.1} GFLOP/s");
    let shipped = Case {
        width: config.network.hidden[0],
        depth: config.network.hidden.len(),
        points: config.sampling.points,
        iterations: 100,
    };
    let paper = Case { width: 512, depth: 3, points: 65_536, iterations: 3 };
    let mut table = MarkdownTable::new(&[
        "network x points",
        "burn-flex it/s",
        "GFLOP/iter",
        "GFLOP/s",
        "of matmul rate",
        "PyTorch CPU it/s",
        "flex / torch",
    ]);
    let mut figures = Vec::new();
    for (label, case) in [("shipped", shipped), ("paper", paper)] {
        let rate = iterations_per_second(config, &case, &device)?;
        let gflop = flops_per_iteration(&case, n_in) / 1e9;
        let torch = torch_iterations_per_second(&case, encoding);
        let (torch_cell, ratio_cell) = match &torch {
            Ok((t, _)) => (format!("{t:.3}"), format!("{:.2}", rate / t)),
            Err(why) => (format!("n/a ({why})"), "-".into()),
        };
        eprintln!("{label}: {rate:.3} it/s, {:.1} GFLOP/s, torch {torch_cell}", rate * gflop);
        table.row(vec![
            format!("{}x{} x {}", case.depth, case.width, case.points),
            format!("{rate:.3}"),
            format!("{gflop:.1}"),
            format!("{:.1}", rate * gflop),
            format!("{:.0}%", 100.0 * rate * gflop / peak),
            torch_cell,
            ratio_cell,
        ]);
        figures.push(serde_json::json!({"case": label, "width": case.width, "depth": case.depth, "points": case.points,
            "iterations_per_s": rate, "gflop_per_iteration": gflop, "gflops": rate * gflop,
            "torch_iterations_per_s": torch.as_ref().ok().map(|t| t.0), "torch": torch.map(|t| t.1).unwrap_or_else(|e| e)}));
    }
    println!("matmul rate: {peak:.1} GFLOP/s\n\n{}", table.to_markdown());
    let command = format!(
        "cargo run --release -p fastrack-trainer -- bench --config {} --record {record}",
        config_path.display()
    );
    let path = write_record(
        out,
        record,
        &command,
        serde_json::json!({"config": config_path, "system": config.system, "loss": config.loss.form,
            "parameter_mode": config.parameter_mode, "periodic_encoding": config.network.periodic_encoding, "matmul_n": 2048}),
        serde_json::json!({"matmul_gflops": peak, "cases": figures}),
        &[("One DeepReach iteration (forward, explicit input gradient, HJI loss, backward, Adam)", &table)],
    )?;
    eprintln!("wrote {}", path.display());
    Ok(())
}
