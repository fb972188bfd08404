//! The trainer's output served by the real server: `fastrack-trainer train` and `export` (the binaries) make a
//! bundle from a tiny double-integrator run, the server loads it, and its answers equal the manifest's TEB
//! table and the in-process evaluation of the exported graph.

use fastrack_client::{model_ref, pb};
use fastrack_e2e::{evaluator_for, run_binary, tiny_training_config, TestServer};

/// Served values and gradients equal the exported graph's in-process answers (1e-6 relative).
fn assert_served_like_the_graph(
    served: &pb::EvaluateValueResponse,
    evaluator: &fastrack_valuefn::runtime::Evaluator,
    states: &[f64],
    params: &[f64],
) {
    let s: Vec<f32> = states.iter().map(|&x| x as f32).collect();
    let p: Vec<f32> = params.iter().map(|&x| x as f32).collect();
    let local = evaluator.evaluate(&s, &p).unwrap();
    for (got, want) in served.values.iter().chain(&served.gradients).zip(local.value.iter().chain(&local.grad)) {
        assert!((got - f64::from(*want)).abs() <= 1e-6 * (1.0 + want.abs() as f64), "{got} vs {want}");
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn an_exported_bundle_is_served() {
    let work = tempfile::tempdir().unwrap();
    let config = work.path().join("tiny.toml");
    std::fs::write(&config, tiny_training_config("double_integrator", "full", 3, 2.0, "tiny-di")).unwrap();
    let run = work.path().join("run");
    let repo = work.path().join("repo");
    run_binary(
        "fastrack-trainer",
        &["train", "--config", config.to_str().unwrap(), "--run-dir", run.to_str().unwrap()],
    );
    run_binary("fastrack-trainer", &["export", "--run-dir", run.to_str().unwrap(), "--out", repo.to_str().unwrap()]);
    let bundle = repo.join("tiny-di").join("1");
    let (evaluator, manifest) = evaluator_for(&bundle);
    assert!(!manifest.untrained, "a trained bundle says so");
    assert_eq!(manifest.provenance.iterations, 20);

    let (_server, client) = TestServer::start_serving(&repo).await;
    let info = client.get_model(model_ref("tiny-di", 0)).await.unwrap();
    assert_eq!((info.name.as_str(), info.version), ("tiny-di", 1));
    // Every table row is served as written.
    for row in &manifest.teb_table {
        let teb = client.tracking_error_bound(model_ref("tiny-di", 1), row.beta, 0).await.unwrap();
        assert_eq!((teb.level, teb.radius), (row.set_level(), row.bound()));
        assert_eq!(teb.table_beta, row.beta);
    }
    // Values, gradients and controls equal the exported graph's in-process answers.
    let states = vec![0.3, -0.2, -1.0, 0.5, 0.0, 0.0];
    let params = vec![0.6, 0.8, 1.0];
    let served = client
        .evaluate_value(model_ref("tiny-di", 1), states.clone(), params.clone(), pb::OutOfDomainPolicy::Reject)
        .await
        .unwrap();
    assert_served_like_the_graph(&served, &evaluator, &states, &params);
    // queryPlannerControl with no obstacle picks the fastest row.
    let speed = client.query_planner_control(model_ref("tiny-di", 1), None).await.unwrap();
    assert_eq!(speed.beta_query, manifest.teb_table.last().unwrap().beta);
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn runs_on_quad10d_s_axes_are_composed_into_one_served_bundle() {
    let work = tempfile::tempdir().unwrap();
    let mut runs = Vec::new();
    for (system, seed) in [("quad10d_x", 4), ("quad10d_z", 5)] {
        let config = work.path().join(format!("{system}.toml"));
        std::fs::write(&config, tiny_training_config(system, "full", seed, 1.0, system)).unwrap();
        let run = work.path().join(system);
        run_binary(
            "fastrack-trainer",
            &["train", "--config", config.to_str().unwrap(), "--run-dir", run.to_str().unwrap()],
        );
        runs.push(run);
    }
    let repo = work.path().join("repo");
    let (x, z, out) = (runs[0].to_str().unwrap(), runs[1].to_str().unwrap(), repo.to_str().unwrap());
    run_binary("fastrack-trainer", &["compose", "--axis-run", x, "--axis-run", z, "--name", "quad", "--out", out]);
    let (evaluator, manifest) = evaluator_for(&repo.join("quad").join("1"));
    assert_eq!(manifest.system.id, "quad10d");
    assert_eq!(manifest.network.kind, fastrack_valuefn::manifest::COMPOSITE_KIND);
    let subsystems: Vec<&str> = manifest.network.axes.iter().map(|a| a.subsystem.as_str()).collect();
    assert_eq!(subsystems, ["quad10d_x", "quad10d_x", "quad10d_z"]);
    assert_eq!(manifest.provenance.iterations, 40, "both runs' iterations");

    // The composite bundle is served like any other: values and gradients equal the in-process graph.
    let (_server, client) = TestServer::start_serving(&repo).await;
    let states = vec![0.3, -0.2, 0.1, 0.5, -0.4, 0.3, -0.05, 0.2, 0.2, -0.3];
    let params = vec![0.6, 1.2, 1.4];
    let served = client
        .evaluate_value(model_ref("quad", 0), states.clone(), params.clone(), pb::OutOfDomainPolicy::Reject)
        .await
        .unwrap();
    assert_served_like_the_graph(&served, &evaluator, &states, &params);

    // Runs that do not cover the axes are refused with the reason.
    let failed = std::process::Command::new(fastrack_e2e::binary("fastrack-trainer"))
        .args(["compose", "--axis-run", x, "--name", "half", "--out", out])
        .output()
        .unwrap();
    assert!(!failed.status.success());
    let stderr = String::from_utf8_lossy(&failed.stderr);
    assert!(stderr.contains("no --axis-run was trained on `quad10d_z`"), "{stderr}");
}
