//! Operating the real server: Prometheus metrics scraped over HTTP, settings from a `--config` file, and
//! a graceful drain of open streams on SIGTERM.

use fastrack_client::{model_ref, ClientOptions};
use fastrack_e2e::{free_port, robot_tick, write_test_bundle, TestServer};
use fastrack_valuefn::system::dubins4d;
use std::time::{Duration, Instant};

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn metrics_move_with_the_calls() {
    let repo = tempfile::tempdir().unwrap();
    write_test_bundle(repo.path(), &dubins4d::system(), "dubins-test", 1, 1);
    let (server, client) = TestServer::start_observed(repo.path(), &[]).await;
    let ok = r#"fastrack_requests_total{rpc="TrackingControl",model="dubins-test",code="OK"}"#;
    let bad = r#"fastrack_requests_total{rpc="TrackingControl",model="dubins-test",code="INVALID_ARGUMENT"}"#;
    let before = (server.metric(ok).await, server.metric(bad).await, server.metric("fastrack_batch_items_count").await);
    for _ in 0..5 {
        client
            .tracking_control(model_ref("dubins-test", 0), vec![0.1, 0.2, 0.3, 1.0], vec![0.9, 0.9], Default::default())
            .await
            .unwrap();
    }
    let nan = client
        .tracking_control(
            model_ref("dubins-test", 0),
            vec![f64::NAN, 0.2, 0.3, 1.0],
            vec![0.9, 0.9],
            Default::default(),
        )
        .await;
    assert_eq!(nan.unwrap_err().code(), Some(tonic::Code::InvalidArgument));
    let page = server.scrape().await;
    assert!(page.contains(r#"fastrack_loaded_versions{model="dubins-test"} 1"#), "{page}");
    assert_eq!(server.metric(ok).await - before.0, 5.0);
    assert_eq!(server.metric(bad).await - before.1, 1.0);
    assert_eq!(server.metric("fastrack_batch_items_count").await - before.2, 5.0, "only valid calls are evaluated");
    assert!(server.metric(r#"fastrack_request_seconds_count{rpc="TrackingControl"}"#).await >= 6.0);
    assert!(server.metric("fastrack_compute_seconds_count").await >= 5.0);
    assert!(page.contains("fastrack_queue_seconds_bucket"), "{page}");
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_config_file_sets_what_the_flags_do() {
    let repo = tempfile::tempdir().unwrap();
    write_test_bundle(repo.path(), &dubins4d::system(), "dubins-test", 1, 1);
    write_test_bundle(repo.path(), &dubins4d::system(), "dubins-test", 2, 2);
    let metrics = format!("127.0.0.1:{}", free_port());
    let config = repo.path().join("server.toml");
    std::fs::write(
        &config,
        format!(
            "metrics_listen = \"{metrics}\"\npin = [\"dubins-test=1\"]\nmax_batch_size = 32\ntokens = \"user:config-user-token\"\nlog_format = \"json\"\n"
        ),
    )
    .unwrap();
    let mut server = TestServer::start(repo.path(), &["--config", config.to_str().unwrap()]);
    server.metrics = Some(metrics);
    let options = ClientOptions { bearer_token: Some("config-user-token".into()), ..Default::default() };
    let client = server.client_with(&server.endpoint.clone(), options).await;
    client.wait_until_serving(Duration::from_secs(60)).await.unwrap();
    // The pin makes version 1 the default although version 2 is loaded.
    let default = client.get_model(model_ref("dubins-test", 0)).await.unwrap();
    assert_eq!(default.version, 1);
    assert!(default.is_default_version);
    assert!(server.scrape().await.contains(r#"fastrack_loaded_versions{model="dubins-test"} 2"#));
    // The token from the file is required.
    let anonymous = server.client().await;
    let refused = anonymous.get_model(model_ref("dubins-test", 0)).await.unwrap_err();
    assert_eq!(refused.code(), Some(tonic::Code::Unauthenticated));
    // JSON logs with request ids.
    let log = server.log_text();
    let line = log.lines().find(|l| l.contains("listening on loopback only")).expect("startup line");
    let event: serde_json::Value = serde_json::from_str(line).expect("JSON log lines");
    assert_eq!(event["level"], "INFO");
    assert!(log.lines().any(|l| l.contains("\"request_id\"")), "request ids appear in the log spans:\n{log}");
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn sigterm_drains_open_streams_and_exits_zero() {
    let repo = tempfile::tempdir().unwrap();
    write_test_bundle(repo.path(), &dubins4d::system(), "dubins-test", 1, 1);
    let (mut server, client) = TestServer::start_observed(repo.path(), &["--shutdown-grace-s", "5"]).await;
    let mut stream = client.track(model_ref("dubins-test", 0), 0.0).await.unwrap();
    assert!(stream.tick(robot_tick(0, 0)).await.unwrap().error.is_none());
    let start = Instant::now();
    let status = tokio::task::spawn_blocking(move || {
        let status = server.terminate();
        (status, server)
    });
    // The open stream is told to go elsewhere rather than cut.
    let ended = tokio::time::timeout(Duration::from_secs(5), stream.recv()).await.expect("stream ends in time");
    match ended {
        Err(e) => {
            assert_eq!(e.code(), Some(tonic::Code::Unavailable), "{e}");
            assert!(e.to_string().contains("shutting down"), "{e}");
        }
        Ok(reply) => panic!("expected UNAVAILABLE, got {reply:?}"),
    }
    let (status, server) = status.await.unwrap();
    assert!(status.success(), "exit status {status:?}; log:\n{}", server.log_text());
    assert!(start.elapsed() < Duration::from_secs(5), "drained well before the grace period");
    assert!(server.log_text().contains("server stopped"));
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn messages_beyond_the_size_limit_are_refused() {
    let repo = tempfile::tempdir().unwrap();
    write_test_bundle(repo.path(), &dubins4d::system(), "dubins-test", 1, 1);
    let (_server, client) = TestServer::start_observed(repo.path(), &["--max-message-bytes", "65536"]).await;
    // 4,000 states: 128 kB of doubles, twice the limit.
    let n = 4000;
    let states: Vec<f64> = (0..n).flat_map(|_| [0.1, 0.2, 0.3, 1.0]).collect();
    let e = client
        .tracking_control(model_ref("dubins-test", 0), states, vec![0.9; 2 * n], Default::default())
        .await
        .unwrap_err();
    assert_eq!(e.code(), Some(tonic::Code::OutOfRange), "{e}");
    assert!(e.to_string().contains("65536"), "the message names the limit: {e}");
    // A request under the limit is served.
    let small = client
        .tracking_control(model_ref("dubins-test", 0), vec![0.1, 0.2, 0.3, 1.0], vec![0.9, 0.9], Default::default())
        .await
        .unwrap();
    assert_eq!(small.controls.len(), 2);
}
