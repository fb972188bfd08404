//! The grid tools on a trained diagonal-mode bundle (one shared `beta`, the dubins4d default): `fastrack-trainer`
//! trains and exports a tiny dubins4d run, then `fastrack-grid compare` and `verify` (the binaries) read it
//! against the full two-parameter system they solve and simulate.

use fastrack_e2e::binary;
use std::path::Path;
use std::process::Command;

const CONFIG: &str = r#"
system = "dubins4d"
parameter_mode = "diagonal"
seed = 5
checkpoint_every = 1000

[network]
hidden = [16, 16]
omega_0 = 30.0
output_scale = 1.0
output_offset = 0.5

[loss]
form = "exact_boundary"
lambda = 1.0
pretrain_iterations = 0

[sampling]
points = 256
boundary_share = 0.0
tau_max = 0.5
curriculum_iterations = 10

[optimizer]
iterations = 20
learning_rate = 1e-3
final_learning_rate = 1e-4
gradient_clip_norm = 10.0

[export]
name = "tiny-d4"
version = 1
"#;

fn run(name: &str, args: &[&str]) -> String {
    let output = Command::new(binary(name)).args(args).output().expect("run the binary");
    assert!(output.status.success(), "{name} {args:?} failed:\n{}", String::from_utf8_lossy(&output.stderr));
    String::from_utf8_lossy(&output.stdout).into_owned()
}

fn path(p: &Path) -> &str {
    p.to_str().unwrap()
}

#[test]
fn compare_and_verify_read_a_diagonal_bundle() {
    let work = tempfile::tempdir().unwrap();
    let (config, run_dir, repo, results) =
        (work.path().join("tiny.toml"), work.path().join("run"), work.path().join("repo"), work.path().join("results"));
    std::fs::write(&config, CONFIG).unwrap();
    run("fastrack-trainer", &["train", "--config", path(&config), "--run-dir", path(&run_dir)]);
    run("fastrack-trainer", &["export", "--run-dir", path(&run_dir), "--out", path(&repo)]);
    let bundle = repo.join("tiny-d4").join("1");

    let solutions = work.path().join("solutions");
    let compare = format!(
        "compare --bundle {} --resolution 5 --horizon-cap 0.05 --betas 0.8 --solutions-dir {} --results-dir {} \
         --record tiny",
        path(&bundle),
        path(&solutions),
        path(&results)
    );
    run("fastrack-grid", &compare.split_whitespace().collect::<Vec<_>>());
    let record = std::fs::read_to_string(results.join("tiny.md")).unwrap();
    let row = record.lines().find(|l| l.starts_with("| 0.8 |")).expect("a row for beta 0.8");
    let learned: f64 = row.split('|').nth(3).unwrap().trim().parse().unwrap();
    assert!(learned.is_finite(), "learned V_min {learned} in {row}");

    let verified = work.path().join("verified");
    let verify = format!(
        "verify --bundle {} --out {} --eps 0.5 --delta 0.5 --horizon 0.1 --random-planners 0 --level-margin 1 \
         --results-dir {} --record tiny-verify",
        path(&bundle),
        path(&verified),
        path(&results)
    );
    run("fastrack-grid", &verify.split_whitespace().collect::<Vec<_>>());
    let manifest = std::fs::read_to_string(verified.join("tiny-d4").join("1").join("manifest.json")).unwrap();
    assert!(manifest.contains("verified_level"), "the verified bundle carries verified levels");
}
