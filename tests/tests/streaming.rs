//! `Track` at scale against the real server: a long stream in order, hundreds of concurrent streams, and
//! streams whose client vanishes (the active-stream gauge must come back to zero).

use fastrack_client::{model_ref, pb};
use fastrack_e2e::{binary, write_test_bundle, TestServer};
use fastrack_proto::planner_speed::{planner_rule, query_planner_control, SpeedRow};
use fastrack_valuefn::system::dubins4d;

use fastrack_e2e::robot_tick;

/// Robot 0's tick `seq`; every third asks for the planner rule, with a clearance of a third of its `d_obs`.
fn tick(seq: u64, robot: u64) -> pb::TrackTick {
    let mut tick = robot_tick(seq, robot);
    if seq.is_multiple_of(3) {
        tick.planner_clearance = Some(tick.d_obs.unwrap_or(3.0) / 3.0);
    }
    tick
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn ten_thousand_ticks_are_answered_in_order() {
    let repo = tempfile::tempdir().unwrap();
    write_test_bundle(repo.path(), &dubins4d::system(), "dubins-test", 1, 4);
    let (server, client) = TestServer::start_observed(repo.path(), &[]).await;
    let mut stream = client.track(model_ref("dubins-test", 0), 0.0).await.unwrap();
    const TICKS: u64 = 10_000;
    let (tx, mut rx) = tokio::sync::mpsc::channel::<pb::TrackTick>(128);
    let sender = tokio::spawn(async move {
        for seq in 0..TICKS {
            tx.send(tick(seq, 0)).await.unwrap();
        }
    });
    let speeds: Vec<SpeedRow> =
        client.get_model(model_ref("dubins-test", 0)).await.unwrap().teb_table.iter().map(SpeedRow::from).collect();
    // Keep up to 32 ticks in flight: the server must still answer strictly in order, each from its own tick.
    let mut sent = 0u64;
    for expected in 0..TICKS {
        while sent < TICKS && sent < expected + 32 {
            stream.send(rx.recv().await.unwrap()).await.unwrap();
            sent += 1;
        }
        let reply = stream.recv().await.unwrap().expect("a reply for every tick");
        assert_eq!(reply.seq, expected, "replies out of order");
        assert!(reply.error.is_none(), "tick {expected}: {:?}", reply.error);
        assert!(reply.value.is_finite() && reply.control.iter().all(|u| u.is_finite()));
        let sent = tick(expected, 0);
        let chosen = match sent.planner_clearance {
            Some(c) => planner_rule(&speeds, c),
            None => query_planner_control(&speeds, sent.d_obs),
        };
        assert_eq!(reply.beta_query, chosen.beta, "tick {expected}: beta_query must be its own rule's row");
    }
    sender.await.unwrap();
    let answered = server.metric(r#"fastrack_track_ticks_total{rpc="Track",model="dubins-test",code="OK"}"#).await;
    assert_eq!(answered, TICKS as f64);
    drop(stream);
    assert_eq!(server.wait_for_metric("fastrack_active_streams", 0.0).await, 0.0);
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn five_hundred_concurrent_streams_get_every_tick() {
    let repo = tempfile::tempdir().unwrap();
    write_test_bundle(repo.path(), &dubins4d::system(), "dubins-test", 1, 4);
    let (server, _) = TestServer::start_observed(repo.path(), &[]).await;
    const STREAMS: u64 = 500;
    const TICKS: u64 = 20;
    // Ten connections, fifty streams each.
    let mut clients = Vec::new();
    for _ in 0..10 {
        clients.push(server.client().await);
    }
    let mut streams = Vec::new();
    for robot in 0..STREAMS {
        streams.push(clients[robot as usize % 10].track(model_ref("dubins-test", 0), 30.0).await.unwrap());
    }
    assert_eq!(server.metric("fastrack_active_streams").await, STREAMS as f64, "every stream open at once");
    let tasks: Vec<_> = streams
        .into_iter()
        .enumerate()
        .map(|(robot, mut stream)| {
            tokio::spawn(async move {
                for seq in 0..TICKS {
                    let reply = stream.tick(tick(seq, robot as u64)).await.expect("tick answered");
                    assert_eq!(reply.seq, seq);
                    assert!(reply.error.is_none(), "robot {robot} tick {seq}: {:?}", reply.error);
                }
            })
        })
        .collect();
    for task in tasks {
        task.await.expect("stream task");
    }
    let answered = server.metric(r#"fastrack_track_ticks_total{rpc="Track",model="dubins-test",code="OK"}"#).await;
    assert_eq!(answered, (STREAMS * TICKS) as f64);
    assert_eq!(server.wait_for_metric("fastrack_active_streams", 0.0).await, 0.0);
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_vanished_client_frees_its_stream() {
    let repo = tempfile::tempdir().unwrap();
    write_test_bundle(repo.path(), &dubins4d::system(), "dubins-test", 1, 4);
    let (server, _) = TestServer::start_observed(repo.path(), &[]).await;
    // A robot process that streams ticks and is then killed without closing anything.
    let mut child = std::process::Command::new(binary("streaming-robot"))
        .args([server.endpoint.as_str(), "dubins-test", "8"])
        .spawn()
        .unwrap();
    assert_eq!(server.wait_for_metric("fastrack_active_streams", 8.0).await, 8.0, "the robot opened 8 streams");
    child.kill().unwrap();
    child.wait().unwrap();
    assert_eq!(server.wait_for_metric("fastrack_active_streams", 0.0).await, 0.0, "streams freed after the kill");
    // The server still serves new streams.
    let client = server.client().await;
    let mut stream = client.track(model_ref("dubins-test", 0), 0.0).await.unwrap();
    assert!(stream.tick(tick(0, 0)).await.unwrap().error.is_none());
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn bad_idle_timeouts_are_refused_at_open() {
    let repo = tempfile::tempdir().unwrap();
    write_test_bundle(repo.path(), &dubins4d::system(), "dubins-test", 1, 4);
    let (server, client) = TestServer::start_observed(repo.path(), &[]).await;
    for bad in [f64::NAN, f64::INFINITY, -1.0, 1e300] {
        let e = client.track(model_ref("dubins-test", 0), bad).await.err().expect("refused");
        assert_eq!(e.code(), Some(tonic::Code::InvalidArgument), "{bad}: {e}");
        assert!(e.to_string().contains("idle_timeout_s"), "{e}");
    }
    assert_eq!(server.metric("fastrack_active_streams").await, 0.0);
}
