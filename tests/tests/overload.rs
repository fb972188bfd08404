//! Load shedding: a flood beyond the compute queue's bound is refused with RESOURCE_EXHAUSTED at once,
//! while admitted calls are answered within their deadlines and the server's memory stays bounded.

use fastrack_client::{model_ref, pb, ClientError};
use fastrack_e2e::{write_network_bundle, TestServer, TEST_HORIZON};
use fastrack_valuefn::network::{NetworkShape, ValueNetwork};
use fastrack_valuefn::system::dubins4d;
use std::time::{Duration, Instant};

/// States per request: with a 3x256 network one evaluation takes tens of milliseconds.
const ITEMS: usize = 4096;

fn big_request() -> (Vec<f64>, Vec<f64>) {
    let states = (0..ITEMS).flat_map(|i| [0.001 * i as f64, -0.5, 0.3, 1.0]).collect();
    (states, vec![0.9; ITEMS * 2])
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_flood_is_shed_quickly_and_admitted_calls_meet_their_deadlines() {
    let repo = tempfile::tempdir().unwrap();
    let system = dubins4d::system();
    let network = ValueNetwork::random(&system, &NetworkShape::new(&[256, 256, 256], 30.0, true), TEST_HORIZON, 7);
    write_network_bundle(repo.path(), &system, "dubins-big", 1, &network);
    // One compute thread and room for two queued requests.
    let capacity = (2 * ITEMS).to_string();
    let args = ["--compute-threads", "1", "--queue-capacity", capacity.as_str(), "--dynamic-batching", "false"];
    let (server, client) = TestServer::start_observed(repo.path(), &args).await;
    let baseline_rss = server.rss_kib();
    let deadline = Duration::from_secs(20);

    let mut flood = Vec::new();
    for _ in 0..8 {
        let client = server.client().await.with_deadline(deadline);
        flood.push(tokio::spawn(async move {
            let mut outcomes = Vec::new();
            let until = Instant::now() + Duration::from_secs(4);
            while Instant::now() < until {
                let (states, params) = big_request();
                let start = Instant::now();
                let answer = client
                    .tracking_control(model_ref("dubins-big", 0), states, params, pb::OutOfDomainPolicy::Flag)
                    .await;
                outcomes.push((answer.map(|a| a.controls.len()), start.elapsed()));
            }
            outcomes
        }));
    }
    let mut peak_rss = baseline_rss;
    while flood.iter().any(|t| !t.is_finished()) {
        peak_rss = peak_rss.max(server.rss_kib());
        tokio::time::sleep(Duration::from_millis(50)).await;
    }
    let mut admitted = Vec::new();
    let mut shed = Vec::new();
    for task in flood {
        for (answer, elapsed) in task.await.unwrap() {
            match answer {
                Ok(controls) => {
                    assert_eq!(controls, ITEMS * 2);
                    admitted.push(elapsed);
                }
                Err(ClientError::Status(s)) if s.code() == tonic::Code::ResourceExhausted => {
                    assert!(s.message().contains("queue capacity"), "{}", s.message());
                    shed.push(elapsed);
                }
                Err(e) => panic!("an admitted call failed: {e}"),
            }
        }
    }
    assert!(!admitted.is_empty() && !shed.is_empty(), "admitted {}, shed {}", admitted.len(), shed.len());
    shed.sort();
    admitted.sort();
    let shed_p50 = shed[shed.len() / 2];
    let admitted_p50 = admitted[admitted.len() / 2];
    assert!(admitted.last().unwrap() < &deadline, "every admitted call met its deadline");
    assert!(
        shed_p50 < admitted_p50,
        "refusals must be quicker than service: shed p50 {shed_p50:?}, admitted p50 {admitted_p50:?}"
    );
    let shed_metric = server.metric("fastrack_shed_total").await;
    assert_eq!(shed_metric, shed.len() as f64);
    let growth_mib = peak_rss.saturating_sub(baseline_rss) as f64 / 1024.0;
    assert!(growth_mib < 256.0, "server memory grew by {growth_mib:.0} MiB under the flood");
    eprintln!(
        "admitted {} (p50 {admitted_p50:?}), shed {} (p50 {shed_p50:?}), RSS {baseline_rss} -> peak {peak_rss} KiB",
        admitted.len(),
        shed.len()
    );

    // A call whose deadline passes while it waits is not evaluated after the fact.
    let quick = client.with_deadline(Duration::from_millis(1));
    let (states, params) = big_request();
    let answer = quick.tracking_control(model_ref("dubins-big", 0), states, params, pb::OutOfDomainPolicy::Flag).await;
    let code = answer.err().and_then(|e| e.code());
    assert!(matches!(code, Some(tonic::Code::DeadlineExceeded | tonic::Code::Cancelled)), "{code:?}");
}
