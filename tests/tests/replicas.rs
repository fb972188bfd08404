//! A client of several replicas: calls go round-robin, and when a replica dies mid-run every robot's `Track`
//! stream moves to another one and goes on, each tick answered exactly once, in order, and an online loop
//! keeps its bound in force across the move; streams spread evenly over the replicas that serve and come
//! back to one that returns; a client waits for all its replicas, or a quorum.

use fastrack_client::{model_ref, pb, ClientOptions, FastrackClient};
use fastrack_e2e::{robot_tick, TestServer};
use fastrack_online::geometry::PlaneObstacle;
use fastrack_online::online_loop::{LoopSettings, OnlineLoop};
use fastrack_online::raw_path::GridAStar;
use std::collections::BTreeMap;
use std::path::Path;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::time::{Duration, Instant};

const ROBOTS: u64 = 50;
const TICKS: u64 = 400;
/// Every robot must be served again this soon after its replica dies.
const RECOVERY: Duration = Duration::from_secs(5);

async fn replicas(count: usize) -> (Vec<TestServer>, FastrackClient) {
    let models = Path::new(env!("CARGO_MANIFEST_DIR")).join("../models");
    let mut servers = Vec::new();
    for _ in 0..count {
        let (server, client) = TestServer::start_serving(&models).await;
        drop(client);
        servers.push(server);
    }
    let address = servers.iter().map(|s| s.endpoint.as_str()).collect::<Vec<_>>().join(",");
    let options = ClientOptions { request_timeout: Duration::from_secs(10), ..ClientOptions::default() };
    (servers, FastrackClient::connect(&address, options).await.unwrap())
}

/// What one robot saw.
struct Robot {
    first_endpoint: String,
    reopened: usize,
    resent: usize,
    /// From the replica's death to this robot's next reply, if it was on that replica.
    recovery: Option<Duration>,
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn robots_on_a_dead_replica_move_to_another_and_every_tick_is_answered_once() {
    let (mut servers, client) = replicas(3).await;
    assert_eq!(client.endpoints().len(), 3);
    let killed_at: Arc<std::sync::Mutex<Option<Instant>>> = Arc::default();
    let started = Arc::new(AtomicBool::new(false));
    let mut robots = Vec::new();
    for robot in 0..ROBOTS {
        let (client, killed_at, started) = (client.clone(), Arc::clone(&killed_at), Arc::clone(&started));
        robots.push(tokio::spawn(async move {
            let mut stream = client.track(model_ref("dubins4d", 0), 0.0).await.unwrap();
            let first_endpoint = stream.endpoint().to_string();
            let mut recovery = None;
            for seq in 0..TICKS {
                if seq == 50 {
                    started.store(true, Ordering::SeqCst);
                }
                let before = stream.reopened();
                let reply = stream
                    .tick(robot_tick(seq, robot))
                    .await
                    .unwrap_or_else(|e| panic!("robot {robot} tick {seq}: {e}"));
                assert_eq!(reply.seq, seq, "robot {robot}: replies in order, each once");
                assert!(reply.error.is_none(), "robot {robot} tick {seq}: {:?}", reply.error);
                if stream.reopened() > before {
                    let killed = killed_at.lock().unwrap().expect("a move only after the kill");
                    recovery = Some(killed.elapsed());
                }
                tokio::time::sleep(Duration::from_millis(2)).await;
            }
            Robot { first_endpoint, reopened: stream.reopened(), resent: stream.resent(), recovery }
        }));
    }
    while !started.load(Ordering::SeqCst) {
        tokio::time::sleep(Duration::from_millis(10)).await;
    }
    let victim = servers[1].endpoint.clone();
    *killed_at.lock().unwrap() = Some(Instant::now());
    servers[1].kill();
    let mut seen = Vec::new();
    for robot in robots {
        seen.push(robot.await.unwrap());
    }
    let mut per_replica: BTreeMap<&str, usize> = BTreeMap::new();
    for robot in &seen {
        *per_replica.entry(robot.first_endpoint.as_str()).or_default() += 1;
    }
    // Round-robin: the 50 streams opened spread over the 3 replicas.
    assert_eq!(per_replica.len(), 3, "{per_replica:?}");
    assert!(per_replica.values().all(|&n| (16..=17).contains(&n)), "{per_replica:?}");
    for (i, robot) in seen.iter().enumerate() {
        let on_victim = robot.first_endpoint == victim;
        assert_eq!(robot.reopened, usize::from(on_victim), "robot {i} on {}", robot.first_endpoint);
        assert_eq!(robot.recovery.is_some(), on_victim, "robot {i}");
        assert!(robot.resent <= 1, "robot {i}: one tick in flight at a time, {} resent", robot.resent);
    }
    let slowest = seen.iter().filter_map(|r| r.recovery).max().expect("robots were on the killed replica");
    let resent: usize = seen.iter().map(|r| r.resent).sum();
    println!(
        "{} robots moved off the killed replica, {resent} ticks resent; every robot served again within {slowest:?}",
        per_replica[victim.as_str()]
    );
    assert!(slowest < RECOVERY, "a robot waited {slowest:?} after the kill");

    // Unary calls skip the dead replica: every one succeeds.
    for _ in 0..9 {
        let speed = client.query_planner_control(model_ref("dubins4d", 0), Some(3.0)).await.unwrap();
        assert!(speed.beta_query > 0.0);
    }
    let states = vec![0.1, 0.0, 1.5, 1.0];
    let reply = client.tracking_control(model_ref("dubins4d", 0), states, vec![0.6], pb::OutOfDomainPolicy::Flag);
    assert_eq!(reply.await.unwrap().controls.len(), 2);
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_client_connects_while_a_replica_is_down_and_a_dead_address_alone_is_an_error() {
    let (servers, _) = replicas(1).await;
    let dead = format!("http://127.0.0.1:{}", fastrack_e2e::free_port());
    let address = format!("{dead},{}", servers[0].endpoint);
    let client = FastrackClient::connect(&address, ClientOptions::default()).await.unwrap();
    for _ in 0..4 {
        client.get_model(model_ref("dubins4d", 0)).await.unwrap();
    }
    let mut stream = client.track(model_ref("dubins4d", 0), 0.0).await.unwrap();
    assert_eq!(stream.endpoint(), servers[0].endpoint);
    assert_eq!(stream.tick(robot_tick(0, 0)).await.unwrap().seq, 0);
    let error = FastrackClient::connect(&dead, ClientOptions::default()).await.unwrap_err().to_string();
    assert!(error.contains("cannot connect"), "{error}");
    let error = FastrackClient::connect("http://a:1,,http://b:2", ClientOptions::default()).await.unwrap_err();
    assert!(error.to_string().contains("empty endpoint"), "{error}");
    // A host name stands for every address it resolves to.
    let port = servers[0].endpoint.rsplit(':').next().unwrap();
    let named = FastrackClient::connect(&format!("http://localhost:{port}"), ClientOptions::default()).await;
    let named = named.unwrap();
    assert!(named.endpoints().iter().all(|e| e.ends_with(&format!(":{port}"))), "{:?}", named.endpoints());
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_replica_that_never_answers_is_passed_over_by_calls_and_stream_opens() {
    let (servers, _) = replicas(1).await;
    // It takes connections and says nothing.
    let silent = tokio::net::TcpListener::bind("127.0.0.1:0").await.unwrap();
    let address = format!("http://{},{}", silent.local_addr().unwrap(), servers[0].endpoint);
    let held = tokio::spawn(async move {
        let mut connections = Vec::new();
        while let Ok((connection, _)) = silent.accept().await {
            connections.push(connection);
        }
    });
    let options = ClientOptions { request_timeout: Duration::from_millis(500), ..ClientOptions::default() };
    let client = FastrackClient::connect(&address, options).await.unwrap();
    // An idempotent unary call that meets it goes on to the next replica once its deadline passes.
    for call in 0..2 {
        let started = Instant::now();
        let model = client.get_model(model_ref("dubins4d", 0)).await.unwrap();
        assert_eq!(model.name, "dubins4d");
        assert!(started.elapsed() < Duration::from_secs(2), "call {call}: {:?}", started.elapsed());
    }
    let started = Instant::now();
    for robot in 0..4 {
        let mut stream = client.track(model_ref("dubins4d", 0), 0.0).await.unwrap();
        assert_eq!(stream.endpoint(), servers[0].endpoint, "robot {robot}");
        assert_eq!(stream.tick(robot_tick(0, robot)).await.unwrap().seq, 0);
    }
    // Round-robin sent two of the four opens to the silent replica first: each waited out its deadline.
    assert!(started.elapsed() >= Duration::from_millis(1000), "{:?}", started.elapsed());
    held.abort();
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_stream_whose_replica_freezes_moves_once_a_tick_goes_unanswered_past_the_deadline() {
    let (servers, _) = replicas(2).await;
    let address = servers.iter().map(|s| s.endpoint.as_str()).collect::<Vec<_>>().join(",");
    let options = ClientOptions { request_timeout: Duration::from_millis(500), ..ClientOptions::default() };
    let client = FastrackClient::connect(&address, options).await.unwrap();
    let mut stream = client.track(model_ref("dubins4d", 0), 0.0).await.unwrap();
    for seq in 0..3 {
        assert_eq!(stream.tick(robot_tick(seq, 0)).await.unwrap().seq, seq);
    }
    let frozen = servers.iter().position(|s| s.endpoint == stream.endpoint()).unwrap();
    servers[frozen].freeze();
    // The tick sent to the frozen replica is answered by the other, once the deadline has passed.
    let started = Instant::now();
    let reply = stream.tick(robot_tick(3, 0)).await.unwrap();
    let waited = started.elapsed();
    servers[frozen].thaw();
    assert_eq!((reply.seq, reply.error), (3, None));
    assert_eq!(stream.endpoint(), servers[1 - frozen].endpoint);
    assert_eq!((stream.reopened(), stream.resent()), (1, 1));
    assert!(waited >= Duration::from_millis(500) && waited < Duration::from_secs(3), "{waited:?}");
    assert_eq!(stream.tick(robot_tick(4, 0)).await.unwrap().seq, 4, "the stream goes on where it moved");
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_replica_at_its_stream_limit_passes_new_streams_to_another() {
    let models = Path::new(env!("CARGO_MANIFEST_DIR")).join("../models");
    let (full, _) = TestServer::start_serving_with(&models, &["--max-track-streams", "1"]).await;
    let (roomy, _) = TestServer::start_serving(&models).await;
    let address = format!("{},{}", full.endpoint, roomy.endpoint);
    let client = FastrackClient::connect(&address, ClientOptions::default()).await.unwrap();
    let mut streams = Vec::new();
    for robot in 0..4 {
        let mut stream = client.track(model_ref("dubins4d", 0), 0.0).await.unwrap();
        assert_eq!(stream.tick(robot_tick(0, robot)).await.unwrap().seq, 0, "robot {robot}");
        streams.push(stream);
    }
    let on = |endpoint: &str| streams.iter().filter(|s| s.endpoint() == endpoint).count();
    assert_eq!((on(&full.endpoint), on(&roomy.endpoint)), (1, 3), "the full replica took one stream");
    // With every replica full, the open fails with the limit's status.
    let (alone, _) = TestServer::start_serving_with(&models, &["--max-track-streams", "1"]).await;
    let client = FastrackClient::connect(&alone.endpoint, ClientOptions::default()).await.unwrap();
    let _first = client.track(model_ref("dubins4d", 0), 0.0).await.unwrap();
    let refused = client.track(model_ref("dubins4d", 0), 0.0).await.err().expect("no replica has room");
    assert_eq!(refused.code(), Some(tonic::Code::ResourceExhausted), "{refused}");
}

/// The bound in force is the robot's: an online loop whose `Track` stream moves to another replica goes on
/// under the row it had (the stream itself keeps nothing), and the step after the move starts from it.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn an_online_loop_keeps_its_bound_in_force_across_a_failover() {
    let models = Path::new(env!("CARGO_MANIFEST_DIR")).join("../models");
    let mut servers = Vec::new();
    for _ in 0..2 {
        servers.push(TestServer::start_observed(&models, &[]).await.0);
    }
    let address = servers.iter().map(|s| s.endpoint.as_str()).collect::<Vec<_>>().join(",");
    let options = ClientOptions { request_timeout: Duration::from_secs(10), ..ClientOptions::default() };
    let client = FastrackClient::connect(&address, options).await.unwrap();
    let field = ([-2.0, -6.0], [12.0, 6.0]);
    let settings =
        LoopSettings { reset_candidates: 64, ..LoopSettings::new(model_ref("dubins4d", 0), 0.1, [10.0, 0.0], field) };
    let mut online = OnlineLoop::start(&client, settings, [0.0, 0.0]).await.unwrap();
    let mut planner = GridAStar::default();
    let tracker = [0.0, 0.0, std::f64::consts::FRAC_PI_2, 1.0];
    let obstacle = PlaneObstacle::Circle { center: [3.6, 0.0], radius: 0.5 };
    let first = online.step(&tracker, &[], &mut planner).await.unwrap();
    let dropped = online.step(&tracker, std::slice::from_ref(&obstacle), &mut planner).await.unwrap();
    assert!(dropped.beta_query < first.beta_query, "the obstacle lowers the row in force: {dropped:?}");
    // Kill the replica that holds the loop's stream.
    let mut on_stream = None;
    for (i, server) in servers.iter().enumerate() {
        if server.metric("fastrack_active_streams").await == 1.0 {
            on_stream = Some(i);
        }
    }
    let victim = on_stream.expect("one replica holds the loop's stream");
    servers[victim].kill();
    let mut previous = dropped;
    for step in 0..3 {
        let position = [previous.planner[0], previous.planner[1], tracker[2], tracker[3]];
        let report = online.step(&position, std::slice::from_ref(&obstacle), &mut planner).await.unwrap();
        assert_eq!(report.beta_old, previous.beta_query, "step {step} after the failover: {report:?}");
        assert!(report.beta_query < first.beta_query, "step {step}: {report:?}");
        previous = report;
    }
    let survivor = &servers[1 - victim];
    assert_eq!(survivor.metric("fastrack_active_streams").await, 1.0, "the stream moved to the other replica");
}

/// Polls `done` every 50 ms until it holds; fails after `limit`, saying `what` and the client's streams per
/// replica.
async fn within(limit: Duration, what: &str, client: &FastrackClient, done: impl Fn(&[usize]) -> bool) {
    let start = Instant::now();
    while !done(&client.stream_counts()) {
        assert!(start.elapsed() < limit, "{what} not within {limit:?}: streams {:?}", client.stream_counts());
        tokio::time::sleep(Duration::from_millis(50)).await;
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn streams_spread_over_the_replicas_that_serve_and_come_back_to_one_that_returns() {
    let models = Path::new(env!("CARGO_MANIFEST_DIR")).join("../models");
    let (mut servers, client) = replicas(3).await;
    client.wait_until_serving(Duration::from_secs(30)).await.unwrap();

    // Waiting for all replicas, or for a quorum, of a client with one address that nothing serves.
    let dead = format!("http://127.0.0.1:{}", fastrack_e2e::free_port());
    let address = format!("{},{dead}", client.endpoints().join(","));
    let with_dead = FastrackClient::connect(&address, ClientOptions::default()).await.unwrap();
    let e = with_dead.wait_until_serving(Duration::from_millis(300)).await.unwrap_err();
    assert!(e.to_string().starts_with("3 of 4 replicas SERVING"), "{e}");
    with_dead.wait_until_quorum(3, Duration::from_secs(10)).await.unwrap();
    assert_eq!(with_dead.serving_replicas().await.len(), 3);

    // Twelve robots tick every 10 ms until told to stop; every tick is answered once, in order.
    let stop = Arc::new(AtomicBool::new(false));
    let mut robots = Vec::new();
    for robot in 0..12 {
        let (client, stop) = (client.clone(), Arc::clone(&stop));
        robots.push(tokio::spawn(async move {
            let mut stream = client.track(model_ref("dubins4d", 0), 0.0).await.unwrap();
            let mut seq = 0;
            while !stop.load(Ordering::SeqCst) {
                let reply = stream.tick(robot_tick(seq, robot)).await.unwrap();
                assert_eq!((reply.seq, reply.error), (seq, None), "robot {robot}");
                seq += 1;
                tokio::time::sleep(Duration::from_millis(10)).await;
            }
            (stream.reopened(), stream.rebalanced())
        }));
    }
    within(Duration::from_secs(30), "twelve streams spread evenly", &client, |n| n == [4, 4, 4]).await;

    // A replica dies: its robots go on on the others.
    let port: u16 = servers[0].endpoint.rsplit(':').next().unwrap().parse().unwrap();
    servers[0].kill();
    within(Duration::from_secs(30), "the dead replica's streams moved", &client, |n| n[0] == 0).await;
    assert_eq!(client.stream_counts()[1] + client.stream_counts()[2], 12);

    // It comes back where it was: streams move to it, with nothing lost, until the load is even again.
    servers[0] = TestServer::start_on(port, &models, &[]);
    within(Duration::from_secs(60), "the load even again", &client, |n| n == [4, 4, 4]).await;
    stop.store(true, Ordering::SeqCst);
    let (mut reopened, mut rebalanced) = (0, 0);
    for robot in robots {
        let (r, b) = robot.await.unwrap();
        (reopened, rebalanced) = (reopened + r, rebalanced + b);
    }
    assert_eq!(reopened, 4, "the four robots of the dead replica moved once each");
    assert!(rebalanced >= 4, "at least four streams moved back to the returned replica: {rebalanced}");
}
