//! Harness for end-to-end tests: writes model bundles into a temporary repository, starts the real
//! `fastrack-server` binary on a free loopback port, connects the client library, and stops the server
//! (checking that it never panicked) at the end.

pub mod ceiling;
pub mod fuzz;

use fastrack_client::{ClientOptions, FastrackClient};
use fastrack_valuefn::bundle::Bundle;
use fastrack_valuefn::manifest::{Manifest, NetworkInfo, Provenance, SystemInfo, TebRow, SCHEMA_VERSION};
use fastrack_valuefn::network::{NetworkShape, ValueNetwork};
use fastrack_valuefn::onnx_writer::write_value_graph;
use fastrack_valuefn::runtime::{runtime, Evaluator, GraphDims};
use fastrack_valuefn::system::AffineSystem;
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

/// Asserts that a call failed with gRPC status `code` and a message containing every fragment.
pub fn expect_error<T: std::fmt::Debug>(
    result: Result<T, fastrack_client::ClientError>,
    code: tonic::Code,
    fragments: &[&str],
) {
    match result {
        Err(fastrack_client::ClientError::Status(status)) => {
            assert_eq!(status.code(), code, "wrong code for {:?}", status.message());
            for fragment in fragments {
                assert!(status.message().contains(fragment), "message {:?} lacks {fragment:?}", status.message());
            }
        }
        other => panic!("expected {code:?}, got {other:?}"),
    }
}

/// Horizon fixed in test bundles.
pub const TEST_HORIZON: f64 = 1.0;

/// The hand-made TEB table of test bundles: 16 rows over the system's beta range, level `0.2 + 0.1 k`.
pub fn hand_made_table(system: &AffineSystem) -> Vec<TebRow> {
    let (lo, hi) = (system.params[0].min, system.params[0].max);
    (0..16)
        .map(|k| {
            let level = 0.2 + 0.1 * k as f64;
            TebRow {
                beta: if k == 15 { hi } else { lo + (hi - lo) * k as f64 / 15.0 },
                level,
                measured_min: level,
                extent: vec![0.5 * level; system.error_coords.len()],
                // Radii per direction of `boundary_directions`: 2 for 1-D error sets, 16 for 2-D, none above.
                boundary_radii: vec![0.8 * level; [0, 2, 16].get(system.error_coords.len()).copied().unwrap_or(0)],
                nested_share: None,
                reference: None,
                verification: None,
            }
        })
        .collect()
}

/// A test bundle's network (small, seeded).
pub fn test_network(system: &AffineSystem, seed: u64) -> ValueNetwork {
    let mut network = ValueNetwork::random(system, &NetworkShape::new(&[32, 32], 30.0, true), TEST_HORIZON, seed);
    network.output_offset = 0.5;
    network
}

/// Writes `<root>/<name>/<version>/` from a seeded test network with the hand-made table.
pub fn write_test_bundle(root: &Path, system: &AffineSystem, name: &str, version: u32, seed: u64) -> PathBuf {
    write_network_bundle(root, system, name, version, &test_network(system, seed))
}

/// Writes `<root>/<name>/<version>/` from `network` with the hand-made table; returns the folder.
pub fn write_network_bundle(
    root: &Path,
    system: &AffineSystem,
    name: &str,
    version: u32,
    network: &ValueNetwork,
) -> PathBuf {
    let onnx = write_value_graph(network, system, TEST_HORIZON);
    let (state, planner_to_state, params, controls) = Manifest::describe_system(system);
    let manifest = Manifest {
        schema_version: SCHEMA_VERSION,
        name: name.into(),
        version,
        system: SystemInfo { id: system.id.into(), description: system.description.into() },
        state,
        planner_to_state,
        params,
        controls,
        horizon: TEST_HORIZON,
        network: NetworkInfo::describe(network),
        teb_table: hand_made_table(system),
        untrained: true,
        provenance: Provenance {
            machine: "test".into(),
            source_revision: "test".into(),
            created: "2026-01-01T00:00:00Z".into(),
            ..Provenance::untrained("test fixture", serde_json::json!({ "hidden": network.hidden_widths() }))
        },
        onnx_sha256: String::new(),
    };
    Bundle::write(root, manifest, &onnx).expect("write test bundle")
}

/// An in-process evaluator of a bundle folder (the reference for served answers).
pub fn evaluator_for(dir: &Path) -> (Evaluator, Manifest) {
    let bundle = Bundle::load(dir).expect("bundle loads");
    let m = bundle.manifest.clone();
    let dims = GraphDims::of(&m);
    let rt = runtime(None).expect("ONNX Runtime (run scripts/setup-onnxruntime.sh)");
    (Evaluator::new(rt, &bundle.onnx, dims, 1).expect("evaluator"), m)
}

/// Tick `seq` of a dubins4d robot drifting around its plan (relative state inside the domain).
pub fn robot_tick(seq: u64, robot: u64) -> fastrack_client::pb::TrackTick {
    let phase = seq as f64 * 0.01 + robot as f64;
    fastrack_client::pb::TrackTick {
        seq,
        tracker_state: vec![0.3 * phase.sin(), 0.2 * phase.cos(), phase % 3.0, 1.0 + 0.5 * phase.sin()],
        planner_state: vec![0.0, 0.0],
        d_obs: Some(1.0 + (seq % 7) as f64),
        planner_clearance: None,
    }
}

/// Path of the `fastrack-server` binary built beside this test executable (`target/<profile>/`).
pub fn server_binary() -> PathBuf {
    binary("fastrack-server")
}

/// Path of a workspace binary built beside this test executable (`target/<profile>/`).
pub fn binary(name: &str) -> PathBuf {
    let exe = std::env::current_exe().expect("test executable path");
    let profile_dir = exe.parent().and_then(Path::parent).expect("target/<profile>/deps/<test>");
    let binary = profile_dir.join(name);
    assert!(
        binary.is_file(),
        "{} is missing: build it first (`cargo build --workspace --bins`, which scripts/test.sh does)",
        binary.display()
    );
    binary
}

/// Runs one of the workspace's binaries to success (its stderr in the panic otherwise); returns its stdout.
pub fn run_binary(name: &str, args: &[&str]) -> String {
    let output = Command::new(binary(name)).args(args).output().expect("run the binary");
    assert!(output.status.success(), "{name} {args:?} failed:\n{}", String::from_utf8_lossy(&output.stderr));
    String::from_utf8_lossy(&output.stdout).into_owned()
}

/// A tiny training run (16x16 network, 256 points, 20 iterations: seconds) of `system` in `parameter_mode`,
/// exported as `name` version 1.
pub fn tiny_training_config(system: &str, parameter_mode: &str, seed: u64, tau_max: f64, name: &str) -> String {
    format!(
        r#"
system = "{system}"
parameter_mode = "{parameter_mode}"
seed = {seed}
checkpoint_every = 1000

[network]
hidden = [16, 16]
omega_0 = 30.0
output_scale = 1.0
output_offset = 0.5

[loss]
form = "exact_boundary"
lambda = 1.0
pretrain_iterations = 0

[sampling]
points = 256
boundary_share = 0.0
tau_max = {tau_max:?}
curriculum_iterations = 10

[optimizer]
iterations = 20
learning_rate = 1e-3
final_learning_rate = 1e-4
gradient_clip_norm = 10.0

[export]
name = "{name}"
version = 1
"#
    )
}

/// A free loopback port (bound and released).
pub fn free_port() -> u16 {
    std::net::TcpListener::bind("127.0.0.1:0").expect("bind").local_addr().expect("addr").port()
}

/// A running server process; killed (and its log checked for panics) on drop.
pub struct TestServer {
    child: Child,
    /// `http://127.0.0.1:<port>`.
    pub endpoint: String,
    /// `127.0.0.1:<port>` of the Prometheus endpoint, if started with one.
    pub metrics: Option<String>,
    log: PathBuf,
    _log_dir: tempfile::TempDir,
}

impl TestServer {
    /// Starts the server on `models` with extra arguments; does not wait for health.
    pub fn start(models: &Path, extra_args: &[&str]) -> Self {
        Self::start_on(free_port(), models, extra_args)
    }

    /// [`TestServer::start`] on a given loopback port (e.g. a replica coming back where it was).
    pub fn start_on(port: u16, models: &Path, extra_args: &[&str]) -> Self {
        let log_dir = tempfile::tempdir().expect("tempdir");
        let log = log_dir.path().join("server.log");
        let log_file = std::fs::File::create(&log).expect("log file");
        let child = Command::new(server_binary())
            .arg("--listen")
            .arg(format!("127.0.0.1:{port}"))
            .arg("--models")
            .arg(models)
            .args(extra_args)
            .env("FASTRACK_LOG", "info")
            .stdout(Stdio::null())
            .stderr(log_file)
            .spawn()
            .expect("spawn fastrack-server");
        let metrics = extra_args.iter().position(|a| *a == "--metrics-listen").map(|i| extra_args[i + 1].to_string());
        Self { child, endpoint: format!("http://127.0.0.1:{port}"), metrics, log, _log_dir: log_dir }
    }

    /// Starts the server with a Prometheus endpoint on a free port, plus `extra_args`, and waits for SERVING.
    pub async fn start_observed(models: &Path, extra_args: &[&str]) -> (Self, FastrackClient) {
        let metrics = format!("127.0.0.1:{}", free_port());
        let mut args = vec!["--metrics-listen", metrics.as_str()];
        args.extend_from_slice(extra_args);
        let server = Self::start(models, &args);
        let client = server.client().await;
        if client.wait_until_serving(Duration::from_secs(60)).await.is_err() {
            panic!("server never became SERVING; log:\n{}", server.log_text());
        }
        (server, client)
    }

    /// The `/metrics` page (OpenMetrics text), fetched over plain HTTP.
    pub async fn scrape(&self) -> String {
        use tokio::io::{AsyncReadExt, AsyncWriteExt};
        let address = self.metrics.as_deref().expect("server started without --metrics-listen");
        let mut stream = tokio::net::TcpStream::connect(address).await.expect("connect to the metrics endpoint");
        let request = format!("GET /metrics HTTP/1.1\r\nHost: {address}\r\nConnection: close\r\n\r\n");
        stream.write_all(request.as_bytes()).await.expect("send the scrape");
        let mut response = String::new();
        stream.read_to_string(&mut response).await.expect("read the scrape");
        assert!(response.starts_with("HTTP/1.1 200"), "scrape failed: {response}");
        response.split_once("\r\n\r\n").map(|(_, body)| body.to_string()).unwrap_or_default()
    }

    /// The sample's value once it equals `want`, or its last value after 20 s of polling.
    pub async fn wait_for_metric(&self, sample: &str, want: f64) -> f64 {
        let start = std::time::Instant::now();
        loop {
            let value = self.metric(sample).await;
            if value == want || start.elapsed() > Duration::from_secs(20) {
                return value;
            }
            tokio::time::sleep(Duration::from_millis(100)).await;
        }
    }

    /// The value of one sample of a scrape (`name{labels}` exactly as exposed), 0 if absent.
    pub async fn metric(&self, sample: &str) -> f64 {
        let page = self.scrape().await;
        page.lines()
            .find_map(|line| line.strip_prefix(sample).and_then(|rest| rest.strip_prefix(' ')))
            .map(|v| v.trim().parse().expect("numeric sample"))
            .unwrap_or(0.0)
    }

    /// The process id.
    pub fn pid(&self) -> u32 {
        self.child.id()
    }

    /// Resident memory of the process in KiB (Linux `/proc`).
    pub fn rss_kib(&self) -> u64 {
        let status = std::fs::read_to_string(format!("/proc/{}/status", self.child.id())).unwrap_or_default();
        status
            .lines()
            .find_map(|l| l.strip_prefix("VmRSS:"))
            .and_then(|v| v.trim().trim_end_matches("kB").trim().parse().ok())
            .unwrap_or(0)
    }

    /// Connects a client, retrying while the server binds its port.
    pub async fn client(&self) -> FastrackClient {
        self.client_with(
            &self.endpoint,
            ClientOptions {
                connect_timeout: Duration::from_secs(2),
                request_timeout: Duration::from_secs(10),
                ..Default::default()
            },
        )
        .await
    }

    /// Connects a client with `options` to `endpoint` (this server's, e.g. with `https://localhost:<port>`),
    /// retrying while the server binds its port.
    pub async fn client_with(&self, endpoint: &str, options: ClientOptions) -> FastrackClient {
        for _ in 0..200 {
            if let Ok(client) = FastrackClient::connect(endpoint, options.clone()).await {
                return client;
            }
            tokio::time::sleep(Duration::from_millis(50)).await;
        }
        panic!("server at {endpoint} never accepted a connection; log:\n{}", self.log_text());
    }

    /// Starts the server and waits until health is SERVING.
    pub async fn start_serving(models: &Path) -> (Self, FastrackClient) {
        Self::start_serving_with(models, &[]).await
    }

    /// [`TestServer::start_serving`] with extra server arguments.
    pub async fn start_serving_with(models: &Path, extra_args: &[&str]) -> (Self, FastrackClient) {
        let server = Self::start(models, extra_args);
        let client = server.client().await;
        if client.wait_until_serving(Duration::from_secs(60)).await.is_err() {
            panic!("server never became SERVING; log:\n{}", server.log_text());
        }
        (server, client)
    }

    /// The server's log so far.
    pub fn log_text(&self) -> String {
        std::fs::read_to_string(&self.log).unwrap_or_default()
    }

    /// True while the process runs.
    pub fn is_running(&mut self) -> bool {
        matches!(self.child.try_wait(), Ok(None))
    }

    /// Sends SIGKILL (a crash: no drain, connections reset) and waits for the process to end.
    pub fn kill(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }

    /// Sends SIGSTOP and waits until every thread has stopped (a stop is delivered, not immediate): the
    /// process keeps its connections and answers nothing (a frozen server).
    pub fn freeze(&self) {
        let _ = Command::new("kill").arg("-STOP").arg(self.child.id().to_string()).status();
        let tasks = PathBuf::from(format!("/proc/{}/task", self.child.id()));
        let stopped = |stat: String| stat.rsplit_once(')').is_some_and(|(_, rest)| rest.trim_start().starts_with('T'));
        let started = Instant::now();
        while !std::fs::read_dir(&tasks)
            .into_iter()
            .flatten()
            .flatten()
            .all(|task| std::fs::read_to_string(task.path().join("stat")).is_ok_and(stopped))
        {
            assert!(started.elapsed() < Duration::from_secs(5), "the server did not stop within 5 s");
            std::thread::sleep(Duration::from_millis(1));
        }
    }

    /// Sends SIGCONT after [`TestServer::freeze`].
    pub fn thaw(&self) {
        let _ = Command::new("kill").arg("-CONT").arg(self.child.id().to_string()).status();
    }

    /// Sends SIGTERM and waits for the exit status (graceful shutdown).
    pub fn terminate(&mut self) -> std::process::ExitStatus {
        let _ = Command::new("kill").arg("-TERM").arg(self.child.id().to_string()).status();
        for _ in 0..200 {
            if let Ok(Some(status)) = self.child.try_wait() {
                return status;
            }
            std::thread::sleep(Duration::from_millis(25));
        }
        let _ = self.child.kill();
        self.child.wait().expect("wait")
    }
}

impl Drop for TestServer {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
        let log = self.log_text();
        if !std::thread::panicking() {
            assert!(!log.contains("panicked"), "the server panicked:\n{log}");
        }
    }
}
