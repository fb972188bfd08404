//! Build time of the server and of the client library alone, each from a clean target folder with the
//! dependencies' sources already downloaded, at this revision and at the revision before lab tooling (records,
//! provenance, shards, plots) left `fastrack-valuefn`, measured in one run: wall time and crates compiled.
//! Plain `cargo build -j2` of the dev profile (no clippy wrapper). Prints a table and writes
//! `bench/results/build-times.{json,md}`.
//!
//! Run: `cargo bench --profile dev -p fastrack-e2e --bench build_times` (about half an hour on 2 cores: four
//! clean builds).

use anyhow::{ensure, Context};
use fastrack_lab::record::{write_record, MarkdownTable};
use indicatif::{ProgressBar, ProgressStyle};
use serde_json::json;
use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::{Duration, Instant};

/// The revision before lab tooling moved from `fastrack-valuefn` into `fastrack-lab`.
const BEFORE: &str = "55b1188^";
/// The packages a robot's stack builds: the server and the client library.
const PACKAGES: [&str; 2] = ["fastrack-server", "fastrack-client"];

/// One clean build: its wall time and how many crates it compiled.
struct Build {
    wall: Duration,
    compiled: usize,
}

/// The source tree of `revision`, exported (no `.git`) into `into`.
fn export(root: &Path, revision: &str, into: &Path) -> anyhow::Result<PathBuf> {
    std::fs::create_dir_all(into)?;
    let archive = Command::new("git").args(["archive", "--format=tar", revision]).current_dir(root).output()?;
    ensure!(archive.status.success(), "git archive {revision}: {}", String::from_utf8_lossy(&archive.stderr));
    let tar = into.join("source.tar");
    std::fs::write(&tar, &archive.stdout)?;
    let unpacked = Command::new("tar").arg("-xf").arg(&tar).current_dir(into).status()?;
    ensure!(unpacked.success(), "tar -xf {}", tar.display());
    std::fs::remove_file(&tar)?;
    Ok(into.to_path_buf())
}

/// `cargo build -j2 -p package` in `tree` with an empty target folder, without the workspace's clippy wrapper.
fn clean_build(tree: &Path, package: &str, target: &Path) -> anyhow::Result<Build> {
    let cargo = std::env::var("CARGO").unwrap_or_else(|_| "cargo".into());
    let started = Instant::now();
    let output = Command::new(cargo)
        .args(["build", "-j2", "-p", package])
        .current_dir(tree)
        .env("CARGO_TARGET_DIR", target)
        .env_remove("RUSTC_WRAPPER")
        .env_remove("RUSTC_WORKSPACE_WRAPPER")
        .env_remove("CLIPPY_ARGS")
        .output()
        .with_context(|| format!("cargo build -p {package} in {}", tree.display()))?;
    let wall = started.elapsed();
    let log = String::from_utf8_lossy(&output.stderr);
    ensure!(output.status.success(), "cargo build -p {package} in {} failed:\n{log}", tree.display());
    let compiled = log.lines().filter(|line| line.trim_start().starts_with("Compiling ")).count();
    std::fs::remove_dir_all(target)?;
    Ok(Build { wall, compiled })
}

fn main() -> anyhow::Result<()> {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("..").canonicalize()?;
    let scratch = tempfile::tempdir()?;
    let before = export(&root, BEFORE, &scratch.path().join("before"))?;
    let trees = [("this revision", root.clone()), (BEFORE, before)];
    let progress = ProgressBar::new((PACKAGES.len() * trees.len()) as u64);
    progress.set_style(ProgressStyle::with_template("{bar:30} {pos}/{len} clean builds, {elapsed}: {msg}")?);
    let mut table =
        MarkdownTable::new(&["package", "revision", "crates compiled", "wall (s)", "this revision / before"]);
    let mut figures = Vec::new();
    for package in PACKAGES {
        let mut builds = Vec::new();
        for (label, tree) in &trees {
            progress.set_message(format!("{package} at {label}"));
            builds.push(clean_build(tree, package, &scratch.path().join("target"))?);
            progress.inc(1);
        }
        let ratio = builds[0].wall.as_secs_f64() / builds[1].wall.as_secs_f64();
        for ((label, _), build) in trees.iter().zip(&builds) {
            let wall = build.wall.as_secs_f64();
            table.row(vec![
                package.into(),
                (*label).into(),
                build.compiled.to_string(),
                format!("{wall:.0}"),
                format!("{ratio:.2}"),
            ]);
            figures.push(json!({"package": package, "revision": label, "compiled": build.compiled, "wall_s": wall}));
        }
    }
    progress.finish_and_clear();
    println!("{}", table.to_markdown());
    let out = root.join("bench/results");
    let path = write_record(
        &out,
        "build-times",
        "cargo bench --profile dev -p fastrack-e2e --bench build_times",
        json!({"packages": PACKAGES, "before": BEFORE, "profile": "dev", "jobs": 2,
               "build": "cargo build -j2 -p <package>, empty target folder, registry already downloaded, no clippy"}),
        json!({"builds": figures}),
        &[("Clean builds of the server and the client alone", &table)],
    )?;
    println!("wrote {}", path.display());
    Ok(())
}
