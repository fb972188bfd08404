//! Clients that misbehave on `Track` against the real server: one that stops reading its replies, and a
//! flood of streams that send nothing. Neither may hold the server's memory without bound or starve the other
//! robots; each stream that is closed says why.

use fastrack_client::{model_ref, pb};
use fastrack_e2e::{robot_tick as tick, write_test_bundle, TestServer};
use fastrack_valuefn::system::dubins4d;
use pb::safety_service_client::SafetyServiceClient;
use std::time::Duration;
use tokio::sync::mpsc;
use tokio_stream::wrappers::ReceiverStream;

/// A `Track` stream opened by hand on a connection of its own, with nothing between the test and the wire:
/// the sender of its requests and its replies.
async fn raw_stream(
    endpoint: &str,
    idle_timeout_s: f64,
) -> Result<(mpsc::Sender<pb::TrackRequest>, tonic::Streaming<pb::TrackResponse>), tonic::Status> {
    let channel = tonic::transport::Channel::from_shared(endpoint.to_string()).unwrap().connect().await.unwrap();
    raw_stream_on(channel, idle_timeout_s).await
}

/// The same on an existing connection.
async fn raw_stream_on(
    channel: tonic::transport::Channel,
    idle_timeout_s: f64,
) -> Result<(mpsc::Sender<pb::TrackRequest>, tonic::Streaming<pb::TrackResponse>), tonic::Status> {
    let (tx, rx) = mpsc::channel(16);
    let open = pb::TrackOpen { model: Some(model_ref("dubins-test", 0)), idle_timeout_s };
    tx.send(pb::TrackRequest { msg: Some(pb::track_request::Msg::Open(open)) }).await.unwrap();
    let replies = SafetyServiceClient::new(channel).track(ReceiverStream::new(rx)).await?.into_inner();
    Ok((tx, replies))
}

fn test_repository() -> tempfile::TempDir {
    let repo = tempfile::tempdir().unwrap();
    write_test_bundle(repo.path(), &dubins4d::system(), "dubins-test", 1, 4);
    repo
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_client_that_stops_reading_is_closed_with_a_reason_and_starves_no_one() {
    let repo = test_repository();
    let (server, client) = TestServer::start_observed(repo.path(), &["--stream-send-timeout-s", "1"]).await;
    let (ticks, mut stuck) = raw_stream(&server.endpoint, 0.0).await.unwrap();
    // Ticks sent, none of their replies read: the transport's windows fill, then the server's reply buffer,
    // then the server stops reading ticks and the sends block.
    let mut sent = 0u64;
    while sent < 100_000 {
        let request = pb::TrackRequest { msg: Some(pb::track_request::Msg::Tick(tick(sent, 1))) };
        match tokio::time::timeout(Duration::from_millis(500), ticks.send(request)).await {
            Ok(Ok(())) => sent += 1,
            _ => break,
        }
    }
    assert!(sent < 100_000, "the server kept reading ticks whose replies nobody read");
    // Meanwhile another robot is answered on every tick.
    let mut other = client.track(model_ref("dubins-test", 0), 0.0).await.unwrap();
    for seq in 0..50 {
        let reply = other.tick(tick(seq, 2)).await.unwrap();
        assert!(reply.error.is_none(), "{:?}", reply.error);
    }
    // Past the send timeout the stuck stream is closed: only the other robot's stays open.
    assert_eq!(server.wait_for_metric("fastrack_active_streams", 1.0).await, 1.0);
    // Read now, it gives the replies the server had sent, then the status that says why it ended.
    let mut replies = 0u64;
    let ending = loop {
        match tokio::time::timeout(Duration::from_secs(10), stuck.message()).await.expect("the stream ends") {
            Ok(Some(_)) => replies += 1,
            Ok(None) => panic!("the stream ended without a status after {replies} replies"),
            Err(status) => break status,
        }
    };
    assert!(replies < sent, "{replies} replies for {sent} ticks");
    // Either the server's send timeout closed it (its status says why, and so does its log), or the client's
    // own h2 gave up first on the unread burst of small DATA frames (GOAWAY ENHANCE_YOUR_CALM, which tonic
    // also reports as RESOURCE_EXHAUSTED); which comes first depends on timing, and both free the server.
    assert_eq!(ending.code(), tonic::Code::ResourceExhausted, "{ending}");
    if server.log_text().contains("its client read no reply") {
        assert!(ending.message().contains("read none of its 64 buffered replies"), "{ending}");
    }
    assert!(other.tick(tick(50, 2)).await.unwrap().error.is_none());
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_flood_of_silent_streams_is_capped_and_closed_when_idle() {
    let repo = test_repository();
    let (server, client) = TestServer::start_observed(repo.path(), &["--max-track-streams", "200"]).await;
    let rss_before = server.rss_kib();
    // 200 streams over 4 connections that open and then send nothing, each asking for a 3 s idle timeout.
    let mut connections = Vec::new();
    for _ in 0..4 {
        let endpoint = tonic::transport::Channel::from_shared(server.endpoint.clone()).unwrap();
        connections.push(endpoint.connect().await.unwrap());
    }
    let mut silent = Vec::new();
    for k in 0..200 {
        silent.push(raw_stream_on(connections[k % 4].clone(), 3.0).await.expect("within the cap"));
    }
    assert_eq!(server.metric("fastrack_active_streams").await, 200.0);
    // The next is refused by name, on any connection; unary calls are still served.
    let refused = raw_stream(&server.endpoint, 3.0).await.expect_err("over the cap");
    assert_eq!(refused.code(), tonic::Code::ResourceExhausted, "{refused}");
    assert!(refused.message().contains("max_track_streams"), "{refused}");
    assert!(client.get_model(model_ref("dubins-test", 0)).await.is_ok());
    let grown_kib = server.rss_kib().saturating_sub(rss_before);
    assert!(grown_kib < 64 * 1024, "200 silent streams grew the server by {grown_kib} KiB");
    // Each is closed after its idle timeout, saying so, and the cap frees up.
    let (_ticks, mut one) = silent.pop().unwrap();
    let ended = tokio::time::timeout(Duration::from_secs(10), one.message()).await.expect("closed when idle");
    let status = ended.expect_err("a status");
    assert_eq!(status.code(), tonic::Code::DeadlineExceeded, "{status}");
    assert!(status.message().contains("no tick for 3s"), "{status}");
    assert_eq!(server.wait_for_metric("fastrack_active_streams", 0.0).await, 0.0);
    let mut robot = client.track(model_ref("dubins-test", 0), 0.0).await.unwrap();
    assert!(robot.tick(tick(0, 3)).await.unwrap().error.is_none());
}
