//! The grid tools on a trained diagonal-mode bundle (one shared `beta`, the dubins4d default): `fastrack-trainer`
//! trains and exports a tiny dubins4d run, then `fastrack-grid compare` and `verify` (the binaries) read it
//! against the full two-parameter system they solve and simulate, and the server describes the verified
//! bundle with every figure of its verification. A training config's grid solutions are made by spec with
//! `fastrack-grid solve --config` before the trainer takes them.

use fastrack_client::model_ref;
use fastrack_e2e::{run_binary as run, tiny_training_config, TestServer};
use fastrack_valuefn::bundle::Bundle;
use std::path::Path;

fn path(p: &Path) -> &str {
    p.to_str().unwrap()
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn compare_and_verify_read_a_diagonal_bundle() {
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
        "verify --bundle {} --out {} --eps 0.2 --delta 0.2 --horizon 0.1 --random-planners 0 --level-margin 1 \
         --results-dir {} --record tiny-verify",
        path(&bundle),
        path(&verified),
        path(&results)
    );
    run("fastrack-grid", &verify.split_whitespace().collect::<Vec<_>>());
    let verified_bundle = Bundle::load(&verified.join("tiny-d4").join("1")).unwrap();
    let manifest = verified_bundle.manifest.clone();
    assert!(manifest.teb_table.iter().all(|row| row.verification.is_some()), "every row is verified");

    // `reshape` measures the shapes again at each row's set level: from zeroed shapes it restores the ones
    // verification wrote.
    let mut flattened = manifest.clone();
    for row in &mut flattened.teb_table {
        row.extent.iter_mut().chain(&mut row.boundary_radii).for_each(|x| *x = 0.0);
    }
    let flat_repo = work.path().join("flattened");
    let flat_dir = Bundle::write(&flat_repo, flattened, &verified_bundle.onnx).unwrap();
    run("fastrack-grid", &["reshape", "--bundle", path(&flat_dir), "--out", path(&flat_repo)]);
    let reshaped = Bundle::load(&flat_dir).unwrap().manifest;
    for (got, want) in reshaped.teb_table.iter().zip(&manifest.teb_table) {
        assert_eq!((&got.extent, &got.boundary_radii), (&want.extent, &want.boundary_radii), "beta {}", want.beta);
        assert!(got.extent.iter().any(|&x| x > 0.0), "beta {}: an empty certified set", want.beta);
    }

    // Only the lowest row of the unverified bundle: its verified level rises above the unverified rows over
    // it, so no bundle can be written, but the rollouts are not lost: the record is.
    let partial = work.path().join("partial");
    let lowest = verify
        .replace("--record tiny-verify", "--record tiny-lowest --betas 0.5")
        .replace(path(&verified), path(&partial));
    let refused = std::process::Command::new(fastrack_e2e::binary("fastrack-grid"))
        .args(lowest.split_whitespace())
        .output()
        .unwrap();
    let said = String::from_utf8_lossy(&refused.stderr);
    assert!(!refused.status.success(), "{said}");
    assert!(said.contains("the record is written") && said.contains("verify it as well"), "{said}");
    let record = std::fs::read_to_string(results.join("tiny-lowest.md")).unwrap();
    let header = record.lines().find(|l| l.starts_with("| beta |")).expect("the record's table header");
    let row = record.lines().find(|l| l.starts_with("| 0.5000 |")).expect("the row's result in the record");
    let column = |name: &str| header.split('|').map(str::trim).position(|c| c == name).expect(name);
    let cells: Vec<&str> = row.split('|').map(str::trim).collect();
    assert_eq!(
        (cells[column("set level")], cells[column("bound")]),
        ("-", "-"),
        "no set level or bound without a table: {row}"
    );
    assert!(!partial.exists(), "no bundle written");

    // `reference` writes the grid's ground truth into the rows at or below the solved beta 0.8 (the next
    // solved beta above theirs), none above; the bound never lies below it.
    let solution = std::fs::read_dir(&solutions)
        .unwrap()
        .map(|entry| entry.unwrap().path())
        .find(|p| p.extension().is_some_and(|e| e == "ftgrid"))
        .expect("compare's solution in the store");
    let verified_dir = verified.join("tiny-d4").join("1");
    let verification_record = results.join("tiny-verify.json");
    let reference = [
        "reference",
        "--bundle",
        path(&verified_dir),
        "--grid-solutions",
        path(&solution),
        "--out",
        path(&verified),
        "--record",
        "tiny-reference",
        "--verification-record",
        path(&verification_record),
        "--results-dir",
        path(&results),
    ];
    run("fastrack-grid", &reference);
    let manifest = Bundle::load(&verified_dir).unwrap().manifest;
    assert!(manifest.teb_table.iter().all(|row| row.verification.is_some()), "the verifications are kept");
    for row in &manifest.teb_table {
        match &row.reference {
            Some(r) => {
                assert!(row.beta <= 0.8 && r.source.contains("grid at beta 0.8"), "beta {}: {r:?}", row.beta);
                assert_eq!(row.bound(), row.verified_bound().max(r.bound));
            }
            None => assert!(row.beta > 0.8, "beta {} has no reference", row.beta),
        }
    }
    // Its record puts each row's served bound beside the reference, with the wall time of every stage: the
    // training (the bundle's provenance), the solve (the solution's own) and each row's verification (the
    // verification record's).
    let record: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(results.join("tiny-reference.json")).unwrap()).unwrap();
    let verify_rows: serde_json::Value =
        serde_json::from_str::<serde_json::Value>(&std::fs::read_to_string(&verification_record).unwrap()).unwrap()
            ["figures"]["rows"]
            .clone();
    let figures = &record["figures"];
    assert_eq!(figures["rows"].as_array().unwrap().len(), manifest.teb_table.len(), "one record row per table row");
    for (got, row) in figures["rows"].as_array().unwrap().iter().zip(&manifest.teb_table) {
        assert_eq!(got["bound"].as_f64(), Some(row.bound()), "beta {}", row.beta);
        let ratio = row.reference.as_ref().map(|r| row.bound() / r.bound);
        assert_eq!(got["served_over_reference"].as_f64(), ratio, "beta {}", row.beta);
        assert!(ratio.is_none_or(|r| r >= 1.0), "the bound never undercuts its reference: {got}");
        let wall = verify_rows.as_array().unwrap().iter().find(|v| v["beta"].as_f64() == Some(row.beta)).unwrap();
        assert_eq!(got["verification_wall_s"], wall["wall_s"], "beta {}", row.beta);
    }
    let solved = fastrack_gridfile::format::load(&solution).unwrap();
    assert_eq!(figures["solves"][0]["wall_s"].as_f64(), Some(solved.info.wall_s));
    assert_eq!(figures["stages"]["training_s"].as_f64(), Some(manifest.provenance.wall_time_s));
    assert!(manifest.provenance.wall_time_s > 0.0, "the training's wall time is recorded");
    let rows_wall: f64 = verify_rows.as_array().unwrap().iter().map(|v| v["wall_s"].as_f64().unwrap()).sum();
    assert_eq!(figures["stages"]["verification_s"].as_f64(), Some(rows_wall));

    // GetModel serves every figure of each row's verification and reference, as the manifest holds it.
    let (_server, client) = TestServer::start_serving(&verified).await;
    let info = client.get_model(model_ref("tiny-d4", 1)).await.unwrap();
    assert_eq!(info.teb_table.len(), manifest.teb_table.len());
    for (served, row) in info.teb_table.iter().zip(&manifest.teb_table) {
        assert_eq!(served.reference_bound, row.reference.as_ref().map(|r| r.bound));
        assert_eq!(served.reference_source, row.reference.as_ref().map_or("", |r| r.source.as_str()));
        assert_eq!((served.bound, served.bound_source.as_str()), (row.bound(), row.bound_source().name()));
        let (got, want) =
            (served.verification.as_ref().expect("a verification per row"), row.verification.as_ref().unwrap());
        assert_eq!(served.verified_level, Some(want.verified_level));
        assert_eq!((got.verified_level, got.eps, got.delta), (want.verified_level, 0.2, 0.2));
        assert_eq!((got.samples, got.violations), (want.samples as u64, want.violations as u64));
        assert_eq!((got.rounds as usize, got.horizon, got.step), (want.rounds, 0.1, want.step));
        assert!(got.rounds >= 1 && got.samples == 8, "N = ceil(ln 0.2 / ln 0.8): {got:?}");
        assert_eq!(got.sampled_level, want.sampled_level);
        assert!(got.sampled_level.is_some());
        assert_eq!(got.correction, "set");
        let checks: Vec<(&str, u64, u64, f64)> =
            got.checks.iter().map(|c| (c.distribution.as_str(), c.samples, c.violations, c.max_error)).collect();
        let wanted: Vec<(&str, u64, u64, f64)> = want
            .checks
            .iter()
            .map(|c| (c.distribution.as_str(), c.samples as u64, c.violations as u64, c.max_error))
            .collect();
        assert_eq!(checks, wanted);
        assert_eq!(checks[0].0, "uniform", "{checks:?}");
        let families: Vec<&str> = got.planners.iter().map(|p| p.family.as_str()).collect();
        assert_eq!(families, ["model-worst-case", "search"], "no random planners were asked for");
        for (g, w) in got.planners.iter().zip(&want.planners) {
            assert_eq!(
                (g.family.as_str(), g.rollouts, g.max_error),
                (w.family.as_str(), w.rollouts as u64, w.max_error)
            );
        }
    }
}

#[test]
fn a_training_config_s_grid_solutions_are_solved_by_spec_into_its_store_then_trained_on() {
    let work = tempfile::tempdir().unwrap();
    let (config, store, run_dir) =
        (work.path().join("supervised.toml"), work.path().join("store"), work.path().join("run"));
    let supervision = format!(
        r#"
[supervision]
weight = 1.0
points = 64
store = "{}"

[supervision.solutions]
system = "double_integrator"
resolution = [9]
solves = [{{ beta = 0.5 }}, {{ beta = 1.0 }}]

[supervision.solutions.solver]
accuracy = "weno5"
rk = "3"
cfl = 0.75
horizon_cap = 0.5
tolerance = 1e-9
tracking = true
"#,
        path(&store)
    );
    let text = tiny_training_config("double_integrator", "full", 3, 0.5, "tiny-supervised") + &supervision;
    std::fs::write(&config, text).unwrap();
    let train = ["train", "--config", path(&config), "--run-dir", path(&run_dir)];

    // Before the solutions exist, training refuses, naming the missing solve and the command that makes it.
    let refused = std::process::Command::new(fastrack_e2e::binary("fastrack-trainer")).args(train).output().unwrap();
    let said = String::from_utf8_lossy(&refused.stderr);
    assert!(!refused.status.success(), "{said}");
    assert!(said.contains("no solution for double_integrator at beta 0.5"), "{said}");
    assert!(said.contains("fastrack-grid solve --config"), "{said}");

    // `solve --config` solves each spec once; a second call keeps them.
    let first = run("fastrack-grid", &["solve", "--config", path(&config)]);
    assert_eq!(first.lines().filter(|l| l.starts_with("solved ")).count(), 2, "{first}");
    let second = run("fastrack-grid", &["solve", "--config", path(&config)]);
    assert_eq!(second.lines().filter(|l| l.starts_with("kept ")).count(), 2, "{second}");
    assert_eq!(std::fs::read_dir(&store).unwrap().count(), 2);

    run("fastrack-trainer", &train);
}

/// The failure output of a binary run that must fail.
fn refused(binary: &str, args: &[&str]) -> String {
    let output = std::process::Command::new(fastrack_e2e::binary(binary)).args(args).output().unwrap();
    assert!(!output.status.success(), "{binary} {args:?} succeeded");
    String::from_utf8_lossy(&output.stderr).into_owned()
}

/// The largest excess one axis' parts found at `beta` (the verification's `verified_level` there).
fn excess_at(parts: &Path, beta: f64) -> f64 {
    let part: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(parts.join("grid-verify-part-0-of-1.json")).unwrap()).unwrap();
    let item = part["items"].as_array().unwrap().iter().find(|i| i["beta"].as_f64() == Some(beta)).unwrap();
    assert_eq!(part["config"]["options"]["error_scale"], "excess-over-start-value");
    item["verification"]["verified_level"].as_f64().unwrap()
}

#[test]
fn a_composite_quadcopter_is_verified_by_its_axes() {
    // Tiny runs on quad10d's x and z axes, exported as bundles of their own and composed into one.
    let work = tempfile::tempdir().unwrap();
    let repo = work.path().join("repo");
    let mut runs = Vec::new();
    for (system, seed) in [("quad10d_x", 4), ("quad10d_z", 5)] {
        let config = work.path().join(format!("{system}.toml"));
        std::fs::write(&config, tiny_training_config(system, "full", seed, 1.0, system)).unwrap();
        let run_dir = work.path().join(system);
        run("fastrack-trainer", &["train", "--config", path(&config), "--run-dir", path(&run_dir)]);
        run("fastrack-trainer", &["export", "--run-dir", path(&run_dir), "--out", path(&repo)]);
        runs.push(run_dir);
    }
    let compose = ["compose", "--axis-run", path(&runs[0]), "--axis-run", path(&runs[1]), "--name", "quad"];
    run("fastrack-trainer", &[&compose[..], &["--out", path(&repo)]].concat());
    let (composite, x, z) = (repo.join("quad/1"), repo.join("quad10d_x/1"), repo.join("quad10d_z/1"));

    // Each axis verified at the composite's top row, its error taken less its start's value.
    let top = Bundle::load(&composite).unwrap().manifest.teb_table.last().unwrap().beta;
    let settings = format!("--correction bound --eps 0.1 --horizon 1 --step 0.05 --betas {top} --level-margin 0.05");
    let verify_axis = |axis: &Path, parts: &Path| {
        let args = format!(
            "verify --bundle {} --axis-of {} --part-dir {} {settings}",
            path(axis),
            path(&composite),
            path(parts)
        );
        run("fastrack-grid", &args.split_whitespace().collect::<Vec<_>>());
    };
    let (x_parts, z_parts) = (work.path().join("x-parts"), work.path().join("z-parts"));
    verify_axis(&x, &x_parts);
    verify_axis(&z, &z_parts);

    // The merge composes them: the set {V <= S = 1.05 level} with the smaller of sqrt(S^2 + 2 sum_a d_a S_a +
    // sum_a d_a^2) and S + sqrt(sum_a d_a^2), over the axes x, y (both the x network) and z.
    let verified = work.path().join("verified");
    let axis = |bundle: &Path, parts: &Path| format!("{}={}", path(bundle), path(parts));
    let (x_axis, z_axis) = (axis(&x, &x_parts), axis(&z, &z_parts));
    let merge = ["verify-merge", "--bundle", path(&composite), "--out", path(&verified), "--results-dir"];
    let results = work.path().join("results");
    run("fastrack-grid", &[&merge[..], &[path(&results), "--axis", &x_axis, "--axis", &z_axis]].concat());
    let manifest = Bundle::load(&verified.join("quad/1")).unwrap().manifest;
    let row = manifest.teb_table.last().unwrap();
    let v = row.verification.as_ref().expect("the top row verified");
    let sampled = 1.05 * row.level;
    let (dx, dz) = (excess_at(&x_parts, top).max(0.0), excess_at(&z_parts, top).max(0.0));
    assert_eq!(v.correction.as_deref(), Some("by-axes"));
    assert!((row.set_level() - sampled).abs() < 1e-9 * sampled, "{} vs {sampled}", row.set_level());
    // Each axis reaches S_a = sqrt(S^2 - L^2 + m_a^2) in the set (L, m_a: the composite's and the axis' minima).
    let reach = |axis: &Path| {
        let own = Bundle::load(axis).unwrap().manifest.teb_table.last().unwrap().measured_min;
        (sampled * sampled - row.measured_min * row.measured_min + own * own).sqrt()
    };
    let (sx, sz) = (reach(&x), reach(&z));
    let by_reach = (sampled * sampled + 2.0 * (2.0 * dx * sx + dz * sz) + 2.0 * dx * dx + dz * dz).sqrt();
    let bound = by_reach.min(sampled + (2.0 * dx * dx + dz * dz).sqrt());
    assert!((v.verified_level - bound).abs() < 1e-9 * bound, "{} vs {bound}", v.verified_level);
    let checks: Vec<&str> = v.checks.iter().map(|c| c.distribution.as_str()).collect();
    assert!(checks.contains(&"quad10d_x: uniform") && checks.contains(&"quad10d_z: zero-error-slice"), "{checks:?}");
    assert!(manifest.teb_table[..manifest.teb_table.len() - 1].iter().all(|r| r.verification.is_none()));

    // Refused: an axis missing, parts given with the other axis' bundle, and an axis bundle not of this system.
    let said = refused("fastrack-grid", &[&merge[..], &[path(&results), "--axis", &x_axis]].concat());
    assert!(said.contains("no bundle of axis `quad10d_z` was given"), "{said}");
    let swapped = axis(&z, &x_parts);
    let said =
        refused("fastrack-grid", &[&merge[..], &[path(&results), "--axis", &swapped, "--axis", &z_axis]].concat());
    assert!(said.contains("the parts verified the graph"), "{said}");
    let args = format!(
        "verify --bundle {} --axis-of {} --part-dir {} {settings}",
        path(&composite),
        path(&composite),
        path(&x_parts)
    );
    let said = refused("fastrack-grid", &args.split_whitespace().collect::<Vec<_>>());
    assert!(said.contains("not an axis of `quad10d`"), "{said}");
}
