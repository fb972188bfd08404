//! Batch work split into shards (`--shard INDEX/COUNT`, as the pods of a Kubernetes Indexed Job run it) and
//! merged gives exactly what a single process gives: the navigation benchmark against the real server, and
//! the scenario verification of a bundle's TEB table.

use fastrack_e2e::{run_binary, write_test_bundle, TestServer};
use fastrack_valuefn::system::dubins4d;
use serde_json::Value;
use std::path::Path;
use std::process::Command;

/// A record's JSON.
fn record(dir: &Path, name: &str) -> Value {
    serde_json::from_slice(&std::fs::read(dir.join(format!("{name}.json"))).unwrap()).unwrap()
}

/// The figures of a benchmark record that its seeds decide: everything but wall, decision and planning times.
fn seeded_figures(record: &Value) -> Value {
    let mut summaries = record["figures"]["summaries"].clone();
    for summary in summaries.as_array_mut().unwrap() {
        let summary = summary.as_object_mut().unwrap();
        // Wall times, which no seed fixes.
        for timed in ["decision_p50_ms", "decision_p99_ms", "planning_ms_mean", "planning_ms_p99"] {
            summary.remove(timed);
        }
    }
    serde_json::json!({"summaries": summaries, "ratios": record["figures"]["pf_time_ratios"], "config": record["config"]})
}

#[test]
fn a_benchmark_in_shards_merges_into_the_single_run() {
    let models = Path::new(env!("CARGO_MANIFEST_DIR")).join("../models");
    let server = TestServer::start(&models, &[]);
    let out = tempfile::tempdir().unwrap();
    let (results, parts) = (out.path().join("results"), out.path().join("parts"));
    let common = |extra: &[&str]| {
        let mut args = vec!["--server", server.endpoint.as_str(), "sim"];
        args.extend_from_slice(extra);
        args.iter().map(|s| s.to_string()).collect::<Vec<String>>()
    };
    let run = |args: Vec<String>| run_binary("fastrack", &args.iter().map(String::as_str).collect::<Vec<_>>());
    run(vec!["--server".into(), server.endpoint.clone(), "health".into(), "--wait-s".into(), "60".into()]);
    let bench = ["bench", "--worlds", "3", "--methods", "pf,f-low,mppi", "--results-dir"];
    let results_dir = results.to_str().unwrap();
    let mut whole = bench.to_vec();
    whole.extend([results_dir, "--record", "whole"]);
    run(common(&whole));
    let part_dir = parts.to_str().unwrap();
    for shard in ["0/2", "1/2"] {
        let mut part = bench.to_vec();
        part.extend([results_dir, "--shard", shard, "--part-dir", part_dir]);
        let said = run(common(&part));
        assert!(said.contains(&format!("shard {shard}:")), "{said}");
    }
    run(common(&["merge", "--part-dir", part_dir, "--results-dir", results_dir, "--record", "merged"]));
    let (single, merged) = (record(&results, "whole"), record(&results, "merged"));
    assert_eq!(seeded_figures(&single), seeded_figures(&merged));
    assert_eq!(single["figures"]["summaries"][0]["runs"], 3, "{single}");
    assert!(results.join("merged-world1.png").is_file() && results.join("merged-time-to-goal.png").is_file());

    // A part missing, or a part of another benchmark, is refused with the reason.
    std::fs::remove_file(parts.join("sim-bench-part-1-of-2.json")).unwrap();
    let fastrack = fastrack_e2e::binary("fastrack");
    let merge = |dir: &str| Command::new(&fastrack).args(["sim", "merge", "--part-dir", dir]).output().unwrap();
    let missing = merge(part_dir);
    let said = String::from_utf8_lossy(&missing.stderr);
    assert!(!missing.status.success() && said.contains("shards 1 of 2 are missing"), "{said}");
    let mut other = bench.to_vec();
    other[2] = "2";
    other.extend([results_dir, "--shard", "1/2", "--part-dir", part_dir]);
    run(common(&other));
    let mixed = merge(part_dir);
    let said = String::from_utf8_lossy(&mixed.stderr);
    assert!(!mixed.status.success() && said.contains("shard 1/2 ran"), "{said}");
    // A shard without a folder for its part is refused before any run.
    let mut lost = bench.to_vec();
    lost.extend([results_dir, "--shard", "0/2"]);
    let refused = Command::new(&fastrack).args(common(&lost)).output().unwrap();
    assert!(String::from_utf8_lossy(&refused.stderr).contains("give --part-dir"));
}

#[test]
fn a_verification_in_shards_merges_into_the_single_run() {
    // A small seeded dubins4d network: the same work whole or in shards, and seconds to measure the verified
    // sets' shapes (the shipped network takes a minute a bundle).
    let repo = tempfile::tempdir().unwrap();
    let bundle = write_test_bundle(repo.path(), &dubins4d::system(), "dubins4d", 5, 1);
    let out = tempfile::tempdir().unwrap();
    let at = |name: &str| out.path().join(name).to_str().unwrap().to_string();
    let (results, parts) = (at("results"), at("parts"));
    // Few samples over a short horizon: the same work either way, in seconds.
    let verify = |extra: &[&str]| {
        let mut args = vec!["verify", "--bundle", bundle.to_str().unwrap(), "--eps", "0.2", "--delta", "0.2"];
        args.extend(["--horizon", "0.5", "--step", "0.05", "--results-dir", &results]);
        args.extend_from_slice(extra);
        run_binary("fastrack-grid", &args)
    };
    verify(&["--out", &at("whole"), "--record", "whole"]);
    for shard in ["0/3", "1/3", "2/3"] {
        let said = verify(&["--out", &at("unused"), "--shard", shard, "--part-dir", &parts]);
        assert!(said.contains(&format!("shard {shard}:")), "{said}");
    }
    assert!(!out.path().join("unused").exists(), "a shard writes no bundle");
    run_binary(
        "fastrack-grid",
        &["verify-merge", "--bundle", bundle.to_str().unwrap(), "--out", &at("merged"), "--part-dir", &parts]
            .into_iter()
            .chain(["--results-dir", &results, "--record", "merged"])
            .collect::<Vec<_>>(),
    );
    let manifest = |root: &str| -> Value {
        let text = std::fs::read(out.path().join(root).join("dubins4d/5/manifest.json")).unwrap();
        serde_json::from_slice::<Value>(&text).unwrap()["teb_table"].clone()
    };
    assert_eq!(manifest("whole"), manifest("merged"));
    assert!(manifest("whole")[0]["verification"]["samples"].as_u64() == Some(8), "{}", manifest("whole")[0]);
    let (single, merged) = (record(Path::new(&results), "whole"), record(Path::new(&results), "merged"));
    assert_eq!(
        (&single["config"], without_wall_times(&single["figures"])),
        (&merged["config"], without_wall_times(&merged["figures"]))
    );
    assert!(single["figures"]["rows"][0]["wall_s"].as_f64().is_some_and(|s| s > 0.0), "rows keep their wall times");

    // With the bound correction, each row's samples in 2 pieces: 32 items in 3 shards, whose parts merge into
    // the single run's table, every row with the samples of both its pieces.
    let pieces = ["--correction", "bound", "--pieces", "2"];
    verify(&[&pieces[..], &["--out", &at("whole-pieces")]].concat());
    let piece_parts = at("piece-parts");
    for shard in ["0/3", "1/3", "2/3"] {
        let said = verify(&[&pieces[..], &["--shard", shard, "--part-dir", &piece_parts]].concat());
        assert!(said.contains(&format!("shard {shard}:")), "{said}");
    }
    run_binary(
        "fastrack-grid",
        &["verify-merge", "--bundle", bundle.to_str().unwrap(), "--out", &at("merged-pieces")]
            .into_iter()
            .chain(["--part-dir", &piece_parts, "--results-dir", &results, "--record", "merged-pieces"])
            .collect::<Vec<_>>(),
    );
    assert_eq!(manifest("whole-pieces"), manifest("merged-pieces"));
    let row = &manifest("merged-pieces")[0]["verification"];
    assert_eq!((row["samples"].as_u64(), row["rounds"].as_u64()), (Some(8), Some(1)), "{row}");

    // Parts of another bundle's graph are refused.
    let other = write_test_bundle(repo.path(), &dubins4d::system(), "dubins4d", 6, 2);
    let refused = Command::new(fastrack_e2e::binary("fastrack-grid"))
        .args(["verify-merge", "--bundle", other.to_str().unwrap(), "--out", &at("other"), "--part-dir", &parts])
        .output()
        .unwrap();
    let said = String::from_utf8_lossy(&refused.stderr);
    assert!(!refused.status.success() && said.contains("the parts verified the graph"), "{said}");
}

/// `value` without its `wall_s` fields, at any depth: the results of a run, not how long it took.
fn without_wall_times(value: &Value) -> Value {
    match value {
        Value::Object(map) => Value::Object(
            map.iter().filter(|(k, _)| *k != "wall_s").map(|(k, v)| (k.clone(), without_wall_times(v))).collect(),
        ),
        Value::Array(items) => Value::Array(items.iter().map(without_wall_times).collect()),
        other => other.clone(),
    }
}
