//! The grid tools on a trained diagonal-mode bundle (one shared `beta`, the dubins4d default): `fastrack-trainer`
//! trains and exports a tiny dubins4d run, then `fastrack-grid compare` and `verify` (the binaries) read it
//! against the full two-parameter system they solve and simulate.

use fastrack_e2e::{run_binary as run, tiny_training_config};
use std::path::Path;

fn path(p: &Path) -> &str {
    p.to_str().unwrap()
}

#[test]
fn compare_and_verify_read_a_diagonal_bundle() {
    let work = tempfile::tempdir().unwrap();
    let (config, run_dir, repo, results) =
        (work.path().join("tiny.toml"), work.path().join("run"), work.path().join("repo"), work.path().join("results"));
    std::fs::write(&config, tiny_training_config("dubins4d", "diagonal", 5, 0.5, "tiny-d4")).unwrap();
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
