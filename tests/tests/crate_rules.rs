//! The workspace's dependency rules (docs/architecture.md), checked against `Cargo.lock` and the crates'
//! manifests: a robot's client links no ONNX Runtime, `clap` or `indicatif`; the server no trainer, solver
//! or solution-file code; neither links the lab tooling (records, shards, plots); the `fastrack` CLI no ONNX
//! Runtime; the shared crate no gRPC and no lab tooling; the trainer the solution file, not the solver.

use std::collections::{BTreeSet, HashMap};
use std::path::PathBuf;

fn repository() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).parent().expect("the workspace root").to_path_buf()
}

/// Every package of `Cargo.lock` with the names of its dependencies (all kinds).
fn lock() -> HashMap<String, Vec<String>> {
    let text = std::fs::read_to_string(repository().join("Cargo.lock")).expect("Cargo.lock");
    let lock: toml::Table = text.parse().expect("Cargo.lock is TOML");
    let packages = lock["package"].as_array().expect("[[package]] entries");
    packages
        .iter()
        .map(|p| {
            let name = p["name"].as_str().expect("a name").to_string();
            let deps = p.get("dependencies").and_then(|d| d.as_array()).map_or(Vec::new(), |d| {
                d.iter().filter_map(|x| x.as_str()?.split(' ').next().map(String::from)).collect()
            });
            (name, deps)
        })
        .collect()
}

/// `package` and everything it depends on, transitively (dev-dependencies of workspace members included).
fn closure(lock: &HashMap<String, Vec<String>>, package: &str) -> BTreeSet<String> {
    let mut seen = BTreeSet::new();
    let mut stack = vec![package.to_string()];
    while let Some(name) = stack.pop() {
        if seen.insert(name.clone()) {
            stack.extend(lock.get(&name).into_iter().flatten().cloned());
        }
    }
    seen
}

/// The `[dependencies]` of a workspace crate's manifest.
fn normal_dependencies(folder: &str) -> BTreeSet<String> {
    let text = std::fs::read_to_string(repository().join(folder).join("Cargo.toml")).expect("a crate manifest");
    let manifest: toml::Table = text.parse().expect("Cargo.toml is TOML");
    manifest.get("dependencies").and_then(|d| d.as_table()).map_or(BTreeSet::new(), |d| d.keys().cloned().collect())
}

fn assert_excludes(lock: &HashMap<String, Vec<String>>, package: &str, forbidden: &[&str]) {
    let all = closure(lock, package);
    assert!(all.len() > 1, "{package} is not in Cargo.lock");
    let found: Vec<&&str> = forbidden.iter().filter(|f| all.contains(**f)).collect();
    assert!(found.is_empty(), "{package} depends on {found:?} (transitively)");
}

#[test]
fn the_client_library_links_only_what_a_robot_needs() {
    let lock = lock();
    assert_excludes(&lock, "fastrack-client", &["ort", "clap", "indicatif", "fastrack-valuefn", "burn"]);
    assert!(closure(&lock, "fastrack-client").contains("tonic"));
}

#[test]
fn the_server_knows_no_trainer_or_solver() {
    assert_excludes(&lock(), "fastrack-server", &["fastrack-trainer", "fastrack-grid", "fastrack-gridfile", "burn"]);
}

#[test]
fn neither_the_server_nor_the_client_links_the_lab_tooling() {
    let lock = lock();
    for package in ["fastrack-server", "fastrack-client", "fastrack-online"] {
        assert_excludes(&lock, package, &["fastrack-lab", "plotters"]);
    }
    assert_excludes(&lock, "fastrack-valuefn", &["fastrack-lab", "plotters"]);
    assert!(closure(&lock, "fastrack-grid").contains("fastrack-lab"), "the rule names the crate the tools use");
}

/// What `package` links as built on its own (its normal dependencies with the features it enables), from
/// `cargo tree`: `Cargo.lock` also lists optional dependencies that only another member's features turn on.
fn linked(package: &str) -> BTreeSet<String> {
    let out = std::process::Command::new(env!("CARGO"))
        .args(["tree", "--offline", "-p", package, "-e", "normal", "--prefix", "none", "-f", "{p}"])
        .current_dir(repository())
        .output()
        .expect("cargo tree runs");
    assert!(out.status.success(), "cargo tree: {}", String::from_utf8_lossy(&out.stderr));
    String::from_utf8_lossy(&out.stdout).lines().filter_map(|l| l.split_whitespace().next().map(String::from)).collect()
}

#[test]
fn the_command_line_links_no_onnx_runtime() {
    let linked = linked("fastrack-cli");
    let found: Vec<&str> = ["ort", "ort-sys", "libloading"].into_iter().filter(|f| linked.contains(*f)).collect();
    assert!(found.is_empty(), "fastrack-cli links {found:?}");
    assert!(linked.contains("fastrack-client") && linked.contains("fastrack-sim"), "{linked:?}");
}

#[test]
fn the_shared_crate_speaks_no_grpc() {
    assert_excludes(&lock(), "fastrack-valuefn", &["tonic", "fastrack-proto", "fastrack-client"]);
}

#[test]
fn the_trainer_reads_solution_files_not_the_solver() {
    let deps = normal_dependencies("trainer");
    assert!(deps.contains("fastrack-gridfile"), "{deps:?}");
    assert!(!deps.contains("fastrack-grid"), "the trainer depends on the grid solver: {deps:?}");
    assert_excludes(&lock(), "fastrack-gridfile", &["fastrack-grid", "indicatif", "clap"]);
}

#[test]
fn the_online_loop_links_only_what_a_robot_needs() {
    let lock = lock();
    assert_excludes(
        &lock,
        "fastrack-online",
        &["ort", "clap", "indicatif", "fastrack-valuefn", "fastrack-sim", "plotters"],
    );
    assert!(closure(&lock, "fastrack-online").contains("fastrack-client"));
}
