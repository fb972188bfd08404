//! Bad input against the real server: each gets its status code and a message naming the field and what
//! is allowed; broken bundles are rejected with the reason while the other models keep serving.

use fastrack_client::{model_ref, pb, ClientError, FastrackClient};
use fastrack_e2e::{expect_error, write_test_bundle, TestServer};
use fastrack_valuefn::system::dubins4d;
use std::time::Duration;
use tonic::Code;

fn good() -> pb::ModelRef {
    model_ref("good", 0)
}

async fn evaluate(
    client: &FastrackClient,
    states: Vec<f64>,
    params: Vec<f64>,
) -> Result<pb::EvaluateValueResponse, ClientError> {
    client.evaluate_value(good(), states, params, pb::OutOfDomainPolicy::Unspecified).await
}

/// Writes the repository: one good bundle and one of each kind of broken bundle.
fn broken_repository() -> tempfile::TempDir {
    let repo = tempfile::tempdir().unwrap();
    let system = dubins4d::system();
    write_test_bundle(repo.path(), &system, "good", 1, 1);

    // Checksum mismatch: one byte of the graph changed after writing.
    let dir = write_test_bundle(repo.path(), &system, "bad-checksum", 1, 2);
    let mut onnx = std::fs::read(dir.join("model.onnx")).unwrap();
    let last = onnx.len() - 1;
    onnx[last] ^= 0xff;
    std::fs::write(dir.join("model.onnx"), onnx).unwrap();

    // Corrupt graph whose checksum matches (so the graph itself is what fails).
    let dir = write_test_bundle(repo.path(), &system, "corrupt-onnx", 1, 3);
    let garbage = b"this is not an ONNX model".to_vec();
    let manifest = std::fs::read_to_string(dir.join("manifest.json")).unwrap();
    let old_sha = fastrack_valuefn::bundle::sha256_hex(&std::fs::read(dir.join("model.onnx")).unwrap());
    std::fs::write(
        dir.join("manifest.json"),
        manifest.replace(&old_sha, &fastrack_valuefn::bundle::sha256_hex(&garbage)),
    )
    .unwrap();
    std::fs::write(dir.join("model.onnx"), garbage).unwrap();

    // Manifest failing the schema (an unknown field).
    let dir = write_test_bundle(repo.path(), &system, "bad-schema", 1, 4);
    let manifest = std::fs::read_to_string(dir.join("manifest.json")).unwrap();
    std::fs::write(
        dir.join("manifest.json"),
        manifest.replacen("\"horizon\"", "\"colour\": \"blue\",\n  \"horizon\"", 1),
    )
    .unwrap();

    // Manifest failing validation (a horizon of zero).
    let dir = write_test_bundle(repo.path(), &system, "bad-horizon", 1, 5);
    let manifest = std::fs::read_to_string(dir.join("manifest.json")).unwrap();
    std::fs::write(dir.join("manifest.json"), manifest.replacen("\"horizon\": 1.0", "\"horizon\": 0.0", 1)).unwrap();
    repo
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn broken_bundles_are_rejected_with_reasons_and_the_rest_serves() {
    let repo = broken_repository();
    let (mut server, client) = TestServer::start_serving(repo.path()).await;
    let models = client.list_models().await.unwrap();
    assert_eq!(models.iter().map(|m| m.name.as_str()).collect::<Vec<_>>(), ["good"]);
    let log = server.log_text();
    assert!(log.contains("bad-checksum/1/model.onnx: sha256 is"), "{log}");
    assert!(log.contains("invalid ONNX graph"), "{log}");
    assert!(log.contains("does not match schema version 1") && log.contains("unknown field `colour`"), "{log}");
    assert!(log.contains("manifest field `horizon`: must be finite and > 0, got 0"), "{log}");

    // The admin surface reports the same reasons.
    expect_error(client.load_model("bad-checksum", 1).await, Code::FailedPrecondition, &["sha256", "manifest says"]);
    expect_error(client.load_model("corrupt-onnx", 0).await, Code::FailedPrecondition, &["invalid ONNX graph"]);
    expect_error(client.load_model("no-such-model", 0).await, Code::NotFound, &["no folder no-such-model"]);
    let outcomes = client.reload_model("").await.unwrap();
    assert_eq!(outcomes.iter().filter(|o| o.loaded).count(), 1);
    assert_eq!(outcomes.iter().filter(|o| !o.loaded && !o.error.is_empty()).count(), 4);

    assert!(server.is_running());
    assert!(evaluate(&client, vec![0.0, 0.0, 0.0, 1.0], vec![1.0, 1.0]).await.is_ok(), "good model still serves");
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn bad_requests_get_their_status_and_a_precise_message() {
    let repo = tempfile::tempdir().unwrap();
    write_test_bundle(repo.path(), &dubins4d::system(), "good", 1, 1);
    let (mut server, client) = TestServer::start_serving(repo.path()).await;
    let ok_state = vec![0.1, 0.2, 0.3, 1.0];

    // Non-finite numbers.
    expect_error(
        evaluate(&client, vec![0.1, 0.2, f64::NAN, 1.0], vec![1.0, 1.0]).await,
        Code::InvalidArgument,
        &["states[2]", "theta", "NaN", "finite"],
    );
    expect_error(
        evaluate(&client, vec![0.1, f64::INFINITY, 0.0, 1.0], vec![1.0, 1.0]).await,
        Code::InvalidArgument,
        &["states[1]", "y_r", "inf"],
    );
    expect_error(
        evaluate(&client, ok_state.clone(), vec![1.0, f64::NEG_INFINITY]).await,
        Code::InvalidArgument,
        &["params[1]", "beta_2", "-inf"],
    );
    // Wrong lengths.
    expect_error(
        evaluate(&client, vec![0.0; 5], vec![1.0, 1.0]).await,
        Code::InvalidArgument,
        &["states has 5 values", "n_state = 4", "x_r, y_r, theta, v"],
    );
    expect_error(evaluate(&client, vec![], vec![]).await, Code::InvalidArgument, &["states has 0 values"]);
    expect_error(
        evaluate(&client, ok_state.clone(), vec![1.0]).await,
        Code::InvalidArgument,
        &["params has 1 values", "1 x 2 = 2", "beta_1, beta_2"],
    );
    // beta outside the range.
    expect_error(
        evaluate(&client, ok_state.clone(), vec![1.0, 2.0]).await,
        Code::InvalidArgument,
        &["params[1]", "beta_2", "= 2", "[0.5, 1.25]"],
    );
    expect_error(
        evaluate(&client, ok_state.clone(), vec![0.1, 1.0]).await,
        Code::InvalidArgument,
        &["beta_1", "= 0.1"],
    );
    expect_error(
        client.tracking_error_bound(good(), 1.3, 0).await,
        Code::InvalidArgument,
        &["beta = 1.3", "[0.5, 1.25]"],
    );
    expect_error(client.tracking_error_bound(good(), f64::NAN, 0).await, Code::InvalidArgument, &["beta = NaN"]);
    expect_error(
        client.tracking_error_bound(good(), 1.0, 5000).await,
        Code::InvalidArgument,
        &["boundary_points = 5000", "at most 4096"],
    );
    expect_error(
        client.query_planner_control(good(), Some(-1.0)).await,
        Code::InvalidArgument,
        &["d_obs = -1", ">= 0"],
    );
    expect_error(client.query_planner_control(good(), Some(f64::NAN)).await, Code::InvalidArgument, &["d_obs = NaN"]);
    for bad in [-0.5, f64::INFINITY] {
        expect_error(
            client.query_planner_rule(good(), bad).await,
            Code::InvalidArgument,
            &["planner_clearance = ", "finite distance >= 0"],
        );
    }

    // Outside the domain: one item is rejected, a batch is flagged, REJECT names the item.
    expect_error(
        evaluate(&client, vec![3.5, 0.0, 0.0, 1.0], vec![1.0, 1.0]).await,
        Code::OutOfRange,
        &["states[0]", "x_r", "3.5", "[-3, 3]"],
    );
    let flagged = evaluate(&client, vec![0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 3.2], vec![1.0; 4]).await.unwrap();
    assert_eq!(flagged.in_domain, vec![true, false]);
    expect_error(
        client
            .tracking_control(
                good(),
                vec![0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 3.2],
                vec![1.0; 4],
                pb::OutOfDomainPolicy::Reject,
            )
            .await,
        Code::OutOfRange,
        &["states[7]", "item 1", "v", "[0, 3]"],
    );
    // Angles are periodic, never out of domain.
    assert_eq!(evaluate(&client, vec![0.0, 0.0, 40.0, 1.0], vec![1.0, 1.0]).await.unwrap().in_domain, vec![true]);

    // Unknown models and versions, missing names.
    expect_error(
        client.get_model(model_ref("nope", 0)).await,
        Code::NotFound,
        &["\"nope\" is not loaded", "loaded models: good"],
    );
    expect_error(client.get_model(model_ref("good", 9)).await, Code::NotFound, &["no loaded version 9", "[1]"]);
    expect_error(
        client.query_planner_control(model_ref("", 0), None).await,
        Code::InvalidArgument,
        &["model.name is required"],
    );
    expect_error(client.unload_model("nope", 0).await, Code::NotFound, &["\"nope\""]);

    // Track: the first message must open the stream; an unknown model ends it with NOT_FOUND.
    match client.track(model_ref("nope", 0), 1.0).await {
        Err(e) => assert_eq!(e.code(), Some(Code::NotFound)),
        Ok(mut stream) => expect_error(stream.recv().await, Code::NotFound, &["nope"]),
    }

    // A finite state so far outside the domain that the model's 32-bit graph overflows: flagged batches and
    // Track ticks alike are refused for it, never answered with a value or a control that is not a number.
    let far = |x: f64| vec![x, 0.0, 0.0, 1.0, 0.1, 0.2, 0.3, 1.0];
    for x in [1e300, -1e30] {
        expect_error(
            client.evaluate_value(good(), far(x), vec![1.0; 4], pb::OutOfDomainPolicy::Flag).await,
            Code::OutOfRange,
            &["item 0", "x_r", "not a finite number", "[-3, 3]"],
        );
    }
    let mut stream = client.track(good(), 5.0).await.unwrap();
    let tick = pb::TrackTick {
        seq: 1,
        tracker_state: vec![1e300, 0.0, 0.0, 1.0],
        planner_state: vec![0.0, 0.0],
        d_obs: None,
        planner_clearance: None,
    };
    let reply = stream.tick(tick).await.unwrap();
    let error = reply.error.expect("the far tick is refused");
    assert_eq!(Code::from_i32(error.code), Code::OutOfRange, "{}", error.message);
    assert!(error.message.contains("not a finite number"), "{}", error.message);

    // A heading of any finite size is an angle: wrapped exactly (its residue, in double precision) before
    // the 32-bit graph sees it, so f64::MAX is answered with the value at its residue, not refused or NaN.
    let heading = f64::MAX;
    let residue = fastrack_valuefn::system::wrap_periodic(heading, -std::f64::consts::PI, std::f64::consts::PI);
    let far = evaluate(&client, vec![0.1, 0.2, heading, 1.0], vec![1.0, 1.0]).await.unwrap().values[0];
    let near = evaluate(&client, vec![0.1, 0.2, residue, 1.0], vec![1.0, 1.0]).await.unwrap().values[0];
    assert!(far.is_finite() && (far - near).abs() <= 1e-6, "V at theta = f64::MAX: {far}, at its residue {near}");

    assert!(server.is_running(), "the server survived every bad request");
    assert!(evaluate(&client, ok_state, vec![1.0, 1.0]).await.is_ok());
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn empty_repository_is_unavailable_and_not_serving() {
    let repo = tempfile::tempdir().unwrap();
    let server = TestServer::start(repo.path(), &[]);
    let client = server.client().await;
    // Wait for the loader to finish (it logs that nothing loaded).
    for _ in 0..200 {
        if server.log_text().contains("no model loaded") {
            break;
        }
        tokio::time::sleep(Duration::from_millis(25)).await;
    }
    assert!(server.log_text().contains("no model loaded"), "{}", server.log_text());
    assert_eq!(client.health().await.unwrap(), fastrack_client::HealthStatus::NotServing);
    expect_error(
        client.query_planner_control(model_ref("any", 0), None).await,
        Code::Unavailable,
        &["no model is loaded"],
    );
    assert!(client.list_models().await.unwrap().is_empty());
}

#[test]
fn missing_or_broken_onnx_runtime_library_fails_with_a_fix_not_a_panic() {
    let repo = tempfile::tempdir().unwrap();
    write_test_bundle(repo.path(), &dubins4d::system(), "good", 1, 1);
    let run = |library: &std::path::Path| {
        std::process::Command::new(fastrack_e2e::server_binary())
            .args(["--listen", "127.0.0.1:0", "--models"])
            .arg(repo.path())
            .arg("--ort-lib")
            .arg(library)
            .output()
            .unwrap()
    };
    let missing = run(std::path::Path::new("/nonexistent/libonnxruntime.so.1.31.1"));
    let stderr = String::from_utf8_lossy(&missing.stderr);
    assert!(!missing.status.success());
    assert!(stderr.contains("/nonexistent/libonnxruntime.so.1.31.1") && stderr.contains("no such file"), "{stderr}");
    assert!(stderr.contains("scripts/setup-onnxruntime.sh"), "names the fix: {stderr}");
    assert!(!stderr.contains("panicked"), "{stderr}");

    let not_a_library = repo.path().join("libonnxruntime.so.1.31.1");
    std::fs::write(&not_a_library, b"not a shared object").unwrap();
    let broken = run(&not_a_library);
    let stderr = String::from_utf8_lossy(&broken.stderr);
    assert!(!broken.status.success());
    assert!(
        stderr.contains("cannot use ONNX Runtime library") && stderr.contains("scripts/setup-onnxruntime.sh"),
        "{stderr}"
    );
    assert!(!stderr.contains("panicked"), "{stderr}");
}
