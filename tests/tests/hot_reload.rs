//! Hot reload under load: versions appear, are replaced in place and are corrupted while 50 clients call
//! the real server; no call may fail, a corrupt replacement must be rejected and the old version keep
//! answering.

use fastrack_client::{model_ref, pb, FastrackClient};
use fastrack_e2e::{evaluator_for, robot_tick, write_test_bundle, TestServer};
use fastrack_valuefn::system::dubins4d;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::Arc;
use std::time::{Duration, Instant};

const PROBE: [f64; 4] = [0.2, -0.1, 0.3, 1.0];
const PROBE_BETA: [f64; 2] = [0.9, 0.9];

/// The served value at the probe state for `version`.
async fn served_value(client: &FastrackClient, version: u32) -> Option<f64> {
    let answer = client
        .evaluate_value(model_ref("dubins-test", version), PROBE.to_vec(), PROBE_BETA.to_vec(), Default::default())
        .await
        .ok()?;
    Some(answer.values[0])
}

/// The in-process value at the probe state of the bundle now in `dir`.
fn reference_value(dir: &std::path::Path) -> f64 {
    let (evaluator, _) = evaluator_for(dir);
    let p: Vec<f32> = PROBE.iter().map(|&x| x as f32).collect();
    let b: Vec<f32> = PROBE_BETA.iter().map(|&x| x as f32).collect();
    f64::from(evaluator.evaluate(&p, &b).unwrap().value[0])
}

async fn eventually(what: &str, mut check: impl AsyncFnMut() -> bool) {
    let start = Instant::now();
    while !check().await {
        assert!(start.elapsed() < Duration::from_secs(30), "timed out waiting until {what}");
        tokio::time::sleep(Duration::from_millis(100)).await;
    }
}

#[derive(Default)]
struct Tally {
    calls: AtomicU64,
    failures: AtomicU64,
    saw_v2: AtomicU64,
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn versions_are_swapped_under_load_without_a_failed_call() {
    let repo = tempfile::tempdir().unwrap();
    let v1 = write_test_bundle(repo.path(), &dubins4d::system(), "dubins-test", 1, 1);
    let (server, client) = TestServer::start_observed(repo.path(), &["--poll-interval-s", "0.2"]).await;
    let stop = Arc::new(AtomicBool::new(false));
    let tally = Arc::new(Tally::default());
    let mut tasks = Vec::new();
    for worker in 0..50u64 {
        let client = server.client().await;
        let (stop, tally) = (Arc::clone(&stop), Arc::clone(&tally));
        tasks.push(tokio::spawn(async move {
            if worker < 10 {
                // Ten robots on Track streams (each keeps the version it opened on).
                let mut stream = client.track(model_ref("dubins-test", 0), 0.0).await.unwrap();
                let mut seq = 0;
                while !stop.load(Ordering::Relaxed) {
                    let ok = matches!(stream.tick(robot_tick(seq, worker)).await, Ok(r) if r.error.is_none());
                    tally.calls.fetch_add(1, Ordering::Relaxed);
                    tally.failures.fetch_add(u64::from(!ok), Ordering::Relaxed);
                    seq += 1;
                }
            } else {
                // Forty planners on unary calls for the default version.
                while !stop.load(Ordering::Relaxed) {
                    let answer = client
                        .tracking_control(
                            model_ref("dubins-test", 0),
                            PROBE.to_vec(),
                            PROBE_BETA.to_vec(),
                            pb::OutOfDomainPolicy::Reject,
                        )
                        .await;
                    tally.calls.fetch_add(1, Ordering::Relaxed);
                    match answer {
                        Ok(a) => {
                            tally.saw_v2.fetch_add(u64::from(a.model_version == 2), Ordering::Relaxed);
                        }
                        Err(e) => {
                            eprintln!("call failed: {e}");
                            tally.failures.fetch_add(1, Ordering::Relaxed);
                        }
                    }
                }
            }
        }));
    }
    let v1_value = reference_value(&v1);
    assert!((served_value(&client, 1).await.unwrap() - v1_value).abs() < 1e-5);

    // A new version appears: polling loads it and it becomes the default.
    let v2 = write_test_bundle(repo.path(), &dubins4d::system(), "dubins-test", 2, 2);
    let v2_value = reference_value(&v2);
    eventually("version 2 is served as the default", async || {
        client.get_model(model_ref("dubins-test", 0)).await.is_ok_and(|m| m.version == 2)
    })
    .await;
    assert!((served_value(&client, 2).await.unwrap() - v2_value).abs() < 1e-5);

    // Version 2 is replaced in place by another network.
    write_test_bundle(repo.path(), &dubins4d::system(), "dubins-test", 2, 3);
    let replaced_value = reference_value(&v2);
    assert!((replaced_value - v2_value).abs() > 1e-3, "the replacement must differ to be observable");
    eventually("the replaced version 2 answers", async || {
        served_value(&client, 2).await.is_some_and(|v| (v - replaced_value).abs() < 1e-5)
    })
    .await;

    // A corrupt replacement is rejected; the previous version 2 keeps answering.
    let failures_before = server.metric(r#"fastrack_load_failures_total{model="dubins-test"}"#).await;
    std::fs::write(v2.join("model.onnx"), b"not an onnx graph").unwrap();
    eventually("the corrupt bundle is rejected", async || {
        server.metric(r#"fastrack_load_failures_total{model="dubins-test"}"#).await > failures_before
    })
    .await;
    tokio::time::sleep(Duration::from_millis(500)).await;
    assert!((served_value(&client, 2).await.unwrap() - replaced_value).abs() < 1e-5, "old version 2 still serves");
    let outcomes = client.reload_model("dubins-test").await.unwrap();
    let v2_outcome = outcomes.iter().find(|o| o.version == 2).expect("reload reports version 2");
    assert!(!v2_outcome.loaded && v2_outcome.error.contains("sha256"), "{v2_outcome:?}");
    assert!((served_value(&client, 2).await.unwrap() - replaced_value).abs() < 1e-5);

    stop.store(true, Ordering::Relaxed);
    for task in tasks {
        task.await.unwrap();
    }
    let (calls, failures) = (tally.calls.load(Ordering::Relaxed), tally.failures.load(Ordering::Relaxed));
    assert!(calls > 500, "the clients made {calls} calls");
    assert_eq!(failures, 0, "{failures} of {calls} calls failed during the swaps; log:\n{}", server.log_text());
    assert!(tally.saw_v2.load(Ordering::Relaxed) > 0, "unary clients moved to version 2");
    assert!(server.log_text().contains("bundle rejected"));
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_stream_takes_up_a_reloaded_copy_of_its_version_at_its_next_tick() {
    let repo = tempfile::tempdir().unwrap();
    write_test_bundle(repo.path(), &dubins4d::system(), "dubins-test", 1, 1);
    let (_server, client) = TestServer::start_observed(repo.path(), &["--poll-interval-s", "0"]).await;
    let mut old = client.track(model_ref("dubins-test", 1), 0.0).await.unwrap();
    let before = old.tick(robot_tick(0, 7)).await.unwrap();

    // The version is replaced in place by another network and reloaded while the stream stays open.
    write_test_bundle(repo.path(), &dubins4d::system(), "dubins-test", 1, 9);
    assert!(client.reload_model("dubins-test").await.unwrap().iter().all(|o| o.loaded));
    let after = old.tick(robot_tick(0, 7)).await.unwrap();
    let mut fresh = client.track(model_ref("dubins-test", 1), 0.0).await.unwrap();
    let reference = fresh.tick(robot_tick(0, 7)).await.unwrap();
    assert!((before.value - after.value).abs() > 1e-4, "the old stream still answers from the replaced copy");
    assert_eq!(after.value, reference.value, "the old stream answers as a stream opened after the reload");
    assert_eq!(after.control, reference.control);
}
