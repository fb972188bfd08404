//! Dynamic batching: concurrent requests merged into one evaluation must each get exactly their own
//! answer (compared with the in-process evaluator), and merging must really happen.

use fastrack_client::{model_ref, pb};
use fastrack_e2e::{evaluator_for, write_test_bundle, TestServer};
use fastrack_valuefn::system::dubins4d;
use rand::{Rng, SeedableRng};

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn merged_requests_get_their_own_answers() {
    let repo = tempfile::tempdir().unwrap();
    let dir = write_test_bundle(repo.path(), &dubins4d::system(), "dubins-test", 1, 5);
    let (reference, _) = evaluator_for(&dir);
    // A 5 ms window and one compute thread make concurrent requests wait for each other.
    let args = ["--compute-threads", "1", "--max-queue-delay-us", "5000", "--max-batch-size", "64"];
    let (server, _) = TestServer::start_observed(repo.path(), &args).await;
    let mut tasks = Vec::new();
    for client_id in 0..32u64 {
        let client = server.client().await;
        tasks.push(tokio::spawn(async move {
            let mut rng = rand::rngs::StdRng::seed_from_u64(client_id);
            let mut answers = Vec::new();
            for _ in 0..10 {
                let items = rng.random_range(1..4usize);
                let states: Vec<f64> = (0..items)
                    .flat_map(|_| {
                        [
                            rng.random_range(-2.0..2.0),
                            rng.random_range(-2.0..2.0),
                            rng.random_range(-3.0..3.0),
                            rng.random_range(0.0..3.0),
                        ]
                    })
                    .collect();
                let params: Vec<f64> = (0..items * 2).map(|_| rng.random_range(0.5..1.25)).collect();
                let answer = client
                    .tracking_control(
                        model_ref("dubins-test", 0),
                        states.clone(),
                        params.clone(),
                        pb::OutOfDomainPolicy::Reject,
                    )
                    .await
                    .unwrap();
                answers.push((states, params, answer));
            }
            answers
        }));
    }
    for task in tasks {
        for (states, params, answer) in task.await.unwrap() {
            let s: Vec<f32> = states.iter().map(|&x| x as f32).collect();
            let p: Vec<f32> = params.iter().map(|&x| x as f32).collect();
            let expected = reference.evaluate(&s, &p).unwrap();
            assert_eq!(answer.values.len(), expected.value.len());
            for (got, want) in answer.values.iter().zip(&expected.value) {
                assert!((got - f64::from(*want)).abs() < 1e-5, "value {got} vs {want}");
            }
            for (got, want) in answer.controls.iter().zip(&expected.control) {
                assert!((got - f64::from(*want)).abs() < 1e-5, "control {got} vs {want}");
            }
        }
    }
    let evaluations = server.metric("fastrack_batch_items_count").await;
    let items = server.metric("fastrack_batch_items_sum").await;
    assert!(
        evaluations > 0.0 && items / evaluations > 2.0 * 2.0,
        "{items} items in {evaluations} evaluations: no merging"
    );
}
