//! Load generator: closed-loop clients driving a server with unary `TrackingControl` batches or `Track`
//! ticks.
//!
//! Every concurrent client keeps one request (or one tick) outstanding: it sends, awaits the answer and
//! sends again. Clients share `min(concurrency, 64)` connections round-robin (one HTTP/2 connection
//! serialises a lot). Inputs are random states inside the model's trained domain and parameters inside its
//! range, taken from `GetModel`. Errors are counted by gRPC code and never end a run.
//!
//! ```no_run
//! # async fn demo() -> Result<(), fastrack_cli::load_generator::LoadError> {
//! use fastrack_cli::load_generator::{run_load, LoadSpec, Workload};
//! use fastrack_client::{model_ref, ClientOptions};
//! use std::time::Duration;
//! let spec = LoadSpec {
//!     model: model_ref("dubins4d", 0),
//!     workload: Workload::Unary { batch: 64 },
//!     concurrency: 8,
//!     duration: Duration::from_secs(5),
//!     warmup: Duration::from_secs(1),
//!     seed: 1,
//! };
//! let report = run_load("http://127.0.0.1:50051", &ClientOptions::default(), &spec, None).await?;
//! println!("{:.0} items/s, p99 {:?}", report.items_per_s(), report.latency.p99);
//! # Ok(()) }
//! ```

use fastrack_client::{pb, ClientError, ClientOptions, FastrackClient};
use indicatif::ProgressBar;
use rand::rngs::StdRng;
use rand::{Rng, SeedableRng};
use serde_json::{json, Value};
use std::collections::HashMap;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::Arc;
use std::time::{Duration, Instant};

/// Why a load run cannot run.
#[derive(Debug, thiserror::Error)]
pub enum LoadError {
    /// Connecting to the server or describing the model failed.
    #[error(transparent)]
    Client(#[from] ClientError),
    /// A bad spec, or a model description the run cannot draw inputs from.
    #[error("load run: {0}")]
    InvalidLoad(String),
}

/// Most connections a run opens; more concurrent clients share them round-robin.
pub const MAX_CONNECTIONS: usize = 64;

/// Distinct request payloads each unary client cycles through (generated before the clock starts).
pub const PAYLOADS_PER_CLIENT: usize = 8;

/// Fraction of each non-periodic state interval kept clear at both ends, so that rounding never puts a
/// sampled state outside the domain.
const DOMAIN_MARGIN: f64 = 0.01;

/// Half-width of the box planner states are drawn from (planner units), for `Track` ticks.
const PLANNER_SPREAD: f64 = 5.0;

/// What each concurrent client sends.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Workload {
    /// Unary `TrackingControl` calls of `batch` items each.
    Unary {
        /// Items per request (at least 1).
        batch: usize,
    },
    /// Ticks on `Track` streams, one stream per concurrent client, one outstanding tick per stream.
    Track,
}

impl Workload {
    /// Items one request evaluates: the batch, or 1 for a tick.
    pub fn items_per_request(self) -> usize {
        match self {
            Workload::Unary { batch } => batch,
            Workload::Track => 1,
        }
    }
}

impl std::fmt::Display for Workload {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Workload::Unary { batch } => write!(f, "unary TrackingControl batch {batch}"),
            Workload::Track => write!(f, "Track ticks"),
        }
    }
}

/// One load run.
#[derive(Debug, Clone, PartialEq)]
pub struct LoadSpec {
    /// The model to drive (version 0: the default version).
    pub model: pb::ModelRef,
    /// What each client sends.
    pub workload: Workload,
    /// Concurrent clients (at least 1).
    pub concurrency: usize,
    /// Measured time, after the warm-up.
    pub duration: Duration,
    /// Time the clients run before measuring starts (requests started in it are not counted).
    pub warmup: Duration,
    /// Seed of the random inputs.
    pub seed: u64,
}

/// Latency percentiles of the successful requests (nearest rank); zero when there were none.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct LatencySummary {
    /// Median.
    pub p50: Duration,
    /// 90th percentile.
    pub p90: Duration,
    /// 99th percentile.
    pub p99: Duration,
    /// Slowest request.
    pub max: Duration,
    /// Mean.
    pub mean: Duration,
}

impl LatencySummary {
    /// Summarises `latencies` (sorted in place).
    pub fn from_latencies(latencies: &mut [Duration]) -> Self {
        if latencies.is_empty() {
            return Self::default();
        }
        latencies.sort_unstable();
        let rank = |q: f64| latencies[((latencies.len() - 1) as f64 * q).round() as usize];
        let total: f64 = latencies.iter().map(Duration::as_secs_f64).sum();
        Self {
            p50: rank(0.5),
            p90: rank(0.9),
            p99: rank(0.99),
            max: latencies[latencies.len() - 1],
            mean: Duration::from_secs_f64(total / latencies.len() as f64),
        }
    }

    /// Milliseconds as JSON (`p50_ms`, `p90_ms`, `p99_ms`, `max_ms`, `mean_ms`).
    pub fn to_json(&self) -> Value {
        let ms = |d: Duration| d.as_secs_f64() * 1e3;
        json!({"p50_ms": ms(self.p50), "p90_ms": ms(self.p90), "p99_ms": ms(self.p99), "max_ms": ms(self.max),
               "mean_ms": ms(self.mean)})
    }
}

/// What one load run measured (requests started after the warm-up).
#[derive(Debug, Clone, PartialEq)]
pub struct LoadReport {
    /// What was sent.
    pub workload: Workload,
    /// Concurrent clients.
    pub concurrency: usize,
    /// Connections the clients shared.
    pub connections: usize,
    /// Successful requests (or ticks).
    pub requests: u64,
    /// Items the successful requests evaluated (`requests x batch`, or ticks).
    pub items: u64,
    /// Failed requests (and rejected ticks) per gRPC code, most frequent first.
    pub errors: Vec<(tonic::Code, u64)>,
    /// Measured wall time: from the end of the warm-up until the last counted request finished.
    pub elapsed: Duration,
    /// Latency of the successful requests (for `Track`: tick sent to its reply received).
    pub latency: LatencySummary,
}

impl LoadReport {
    /// Successful requests (or ticks) per second.
    pub fn requests_per_s(&self) -> f64 {
        per_second(self.requests, self.elapsed)
    }

    /// Evaluated items (or ticks) per second.
    pub fn items_per_s(&self) -> f64 {
        per_second(self.items, self.elapsed)
    }

    /// Failed requests of every code.
    pub fn error_count(&self) -> u64 {
        self.errors.iter().map(|(_, n)| n).sum()
    }

    /// The report as JSON (rates per second, latencies in milliseconds, errors by code name).
    pub fn to_json(&self) -> Value {
        let errors: serde_json::Map<String, Value> =
            self.errors.iter().map(|(code, n)| (format!("{code:?}"), json!(n))).collect();
        json!({
            "workload": self.workload.to_string(), "batch": self.workload.items_per_request(),
            "concurrency": self.concurrency, "connections": self.connections, "requests": self.requests,
            "items": self.items, "elapsed_s": self.elapsed.as_secs_f64(), "requests_per_s": self.requests_per_s(),
            "items_per_s": self.items_per_s(), "latency": self.latency.to_json(), "errors": errors,
        })
    }
}

/// `count` per second of `elapsed` (0 for no time).
pub fn per_second(count: u64, elapsed: Duration) -> f64 {
    if elapsed.is_zero() {
        0.0
    } else {
        count as f64 / elapsed.as_secs_f64()
    }
}

/// Where random inputs are drawn from: the state box (margins kept clear, periodic axes whole) and the
/// parameter ranges.
#[derive(Debug, Clone)]
pub struct InputDomain {
    /// Per state coordinate: `(min, max)` to draw from.
    state: Vec<(f64, f64)>,
    /// Per parameter: `[beta_l, beta_u]`.
    params: Vec<(f64, f64)>,
}

impl InputDomain {
    /// From bounds `(min, max, periodic)` and parameter ranges; `what` names the source in errors.
    pub fn new(
        state: impl IntoIterator<Item = (f64, f64, bool)>,
        params: impl IntoIterator<Item = (f64, f64)>,
        what: &str,
    ) -> Result<Self, LoadError> {
        let check = |kind: &str, i: usize, (lo, hi): (f64, f64)| {
            if lo.is_finite() && hi.is_finite() && lo <= hi {
                Ok((lo, hi))
            } else {
                Err(LoadError::InvalidLoad(format!("{what}: {kind}[{i}] has no finite interval ([{lo}, {hi}])")))
            }
        };
        let state = state
            .into_iter()
            .enumerate()
            .map(|(i, (lo, hi, periodic))| {
                let (lo, hi) = check("state", i, (lo, hi))?;
                let margin = if periodic { 0.0 } else { DOMAIN_MARGIN * (hi - lo) };
                Ok((lo + margin, hi - margin))
            })
            .collect::<Result<Vec<_>, LoadError>>()?;
        let params =
            params.into_iter().enumerate().map(|(i, range)| check("params", i, range)).collect::<Result<_, _>>()?;
        if state.is_empty() {
            return Err(LoadError::InvalidLoad(format!("{what}: the model has no state coordinates")));
        }
        Ok(Self { state, params })
    }

    fn from_model(info: &pb::ModelInfo) -> Result<Self, LoadError> {
        let what = format!("model {}/{}", info.name, info.version);
        let missing = |kind: &str, i: usize| LoadError::InvalidLoad(format!("{what}: {kind}[{i}] has no bounds"));
        let state = info
            .state
            .iter()
            .enumerate()
            .map(|(i, d)| d.bounds.map(|b| (b.min, b.max, d.periodic)).ok_or_else(|| missing("state", i)))
            .collect::<Result<Vec<_>, _>>()?;
        let params = info
            .params
            .iter()
            .enumerate()
            .map(|(i, p)| p.range.map(|r| (r.min, r.max)).ok_or_else(|| missing("params", i)))
            .collect::<Result<Vec<_>, _>>()?;
        Self::new(state, params, &what)
    }

    /// Appends one random relative state.
    fn push_state(&self, rng: &mut StdRng, out: &mut Vec<f64>) {
        out.extend(self.state.iter().map(|&(lo, hi)| rng.random_range(lo..=hi)));
    }

    /// Appends one random parameter vector.
    fn push_params(&self, rng: &mut StdRng, out: &mut Vec<f64>) {
        out.extend(self.params.iter().map(|&(lo, hi)| rng.random_range(lo..=hi)));
    }

    /// `batch` random items: `(states, params)`, row-major.
    pub fn batch(&self, rng: &mut StdRng, batch: usize) -> (Vec<f64>, Vec<f64>) {
        let mut states = Vec::with_capacity(batch * self.state.len());
        let mut params = Vec::with_capacity(batch * self.params.len());
        for _ in 0..batch {
            self.push_state(rng, &mut states);
            self.push_params(rng, &mut params);
        }
        (states, params)
    }
}

/// Builds `Track` ticks whose relative state `r = s - Q p` lies in the domain: draw `r` and a planner state
/// `p`, send `s = r + Q p`.
#[derive(Debug, Clone)]
struct TickSampler {
    domain: InputDomain,
    /// `Q`, row-major `[n_state x planner_dim]`.
    planner_to_state: Vec<f64>,
    planner_dim: usize,
    /// PlaneObstacle distances are drawn from `[0, d_obs_max]`.
    d_obs_max: f64,
}

impl TickSampler {
    fn from_model(info: &pb::ModelInfo, domain: InputDomain) -> Result<Self, LoadError> {
        let planner_dim = info.planner_dim as usize;
        if info.planner_to_state.len() != domain.state.len() * planner_dim {
            return Err(LoadError::InvalidLoad(format!(
                "model {}/{}: planner_to_state holds {} numbers, expected {} x {planner_dim}",
                info.name,
                info.version,
                info.planner_to_state.len(),
                domain.state.len()
            )));
        }
        // Up to twice the largest TEB diameter: both branches of queryPlannerControl get exercised.
        let largest = info.teb_table.iter().map(|row| row.bound).filter(|l| l.is_finite()).fold(0.0, f64::max);
        let d_obs_max = if largest > 0.0 { 4.0 * largest } else { 1.0 };
        Ok(Self { domain, planner_to_state: info.planner_to_state.clone(), planner_dim, d_obs_max })
    }

    fn tick(&self, rng: &mut StdRng, seq: u64) -> pb::TrackTick {
        let mut relative = Vec::with_capacity(self.domain.state.len());
        self.domain.push_state(rng, &mut relative);
        let planner: Vec<f64> =
            (0..self.planner_dim).map(|_| rng.random_range(-PLANNER_SPREAD..=PLANNER_SPREAD)).collect();
        let tracker = relative
            .iter()
            .enumerate()
            .map(|(i, r)| {
                let row = &self.planner_to_state[i * self.planner_dim..(i + 1) * self.planner_dim];
                r + row.iter().zip(&planner).map(|(q, p)| q * p).sum::<f64>()
            })
            .collect();
        pb::TrackTick {
            seq,
            tracker_state: tracker,
            planner_state: planner,
            d_obs: Some(rng.random_range(0.0..=self.d_obs_max)),
            planner_clearance: None,
        }
    }
}

/// What one client measured.
#[derive(Debug, Default)]
struct ClientStats {
    latencies: Vec<Duration>,
    errors: HashMap<tonic::Code, u64>,
    last_finish: Option<Instant>,
}

impl ClientStats {
    /// Records the outcome of a request started at `started`, if it started in the measured window.
    fn record(&mut self, started: Instant, measure_from: Instant, outcome: Result<(), tonic::Code>) {
        if started < measure_from {
            return;
        }
        let now = Instant::now();
        match outcome {
            Ok(()) => self.latencies.push(now - started),
            Err(code) => *self.errors.entry(code).or_default() += 1,
        }
        self.last_finish = Some(now);
    }
}

/// Live counters for the progress bar.
#[derive(Debug, Default)]
struct Counters {
    done: AtomicU64,
    failed: AtomicU64,
}

impl Counters {
    fn count(&self, ok: bool) {
        if ok { &self.done } else { &self.failed }.fetch_add(1, Ordering::Relaxed);
    }
}

/// The clock of one run: warm-up until `measure_from`, no new requests from `end`.
#[derive(Debug, Clone, Copy)]
struct Window {
    measure_from: Instant,
    end: Instant,
}

fn code_of(error: &ClientError) -> tonic::Code {
    error.code().unwrap_or(tonic::Code::Unknown)
}

async fn unary_client(
    client: FastrackClient,
    model: pb::ModelRef,
    payloads: Vec<(Vec<f64>, Vec<f64>)>,
    window: Window,
    counters: Arc<Counters>,
) -> ClientStats {
    let mut stats = ClientStats::default();
    for (states, params) in payloads.iter().cycle() {
        let started = Instant::now();
        if started >= window.end {
            break;
        }
        let result = client
            .tracking_control(model.clone(), states.clone(), params.clone(), pb::OutOfDomainPolicy::Flag)
            .await
            .map(drop)
            .map_err(|e| code_of(&e));
        counters.count(result.is_ok());
        stats.record(started, window.measure_from, result);
    }
    stats
}

/// Pause before reopening a stream the server refused or broke, so a refusing server is not hammered.
const REOPEN_BACKOFF: Duration = Duration::from_millis(10);

async fn track_client(
    client: FastrackClient,
    model: pb::ModelRef,
    sampler: Arc<TickSampler>,
    seed: u64,
    window: Window,
    counters: Arc<Counters>,
) -> ClientStats {
    let mut stats = ClientStats::default();
    let mut rng = StdRng::seed_from_u64(seed);
    let mut open_stream = None;
    let mut seq = 0u64;
    while Instant::now() < window.end {
        let stream = match &mut open_stream {
            Some(stream) => stream,
            None => {
                let started = Instant::now();
                match client.track(model.clone(), 0.0).await {
                    Ok(opened) => open_stream.insert(opened),
                    Err(e) => {
                        counters.count(false);
                        stats.record(started, window.measure_from, Err(code_of(&e)));
                        tokio::time::sleep(REOPEN_BACKOFF).await;
                        continue;
                    }
                }
            }
        };
        let tick = sampler.tick(&mut rng, seq);
        seq += 1;
        let started = Instant::now();
        let result = match stream.tick(tick).await {
            Ok(reply) => match reply.error {
                None => Ok(()),
                Some(error) => Err(tonic::Code::from_i32(error.code)),
            },
            Err(e) => {
                // The stream is gone: reopen it on the next round.
                open_stream = None;
                Err(code_of(&e))
            }
        };
        counters.count(result.is_ok());
        stats.record(started, window.measure_from, result);
    }
    stats
}

/// Keeps `progress` showing the phase and the counts until aborted.
async fn show_progress(progress: ProgressBar, start: Instant, window: Window, counters: Arc<Counters>) {
    let total = window.end - start;
    progress.set_length(total.as_millis() as u64);
    loop {
        let now = Instant::now();
        let phase = if now < window.measure_from { "warm-up" } else { "measuring" };
        progress.set_position((now - start).min(total).as_millis() as u64);
        progress.set_message(format!(
            "{phase}: {} ok, {} errors",
            counters.done.load(Ordering::Relaxed),
            counters.failed.load(Ordering::Relaxed)
        ));
        tokio::time::sleep(Duration::from_millis(100)).await;
    }
}

/// Runs `spec` against the server at `endpoint`: describes the model, opens `min(concurrency, 64)`
/// connections with `options`, runs the clients through the warm-up and the measured time, and merges what
/// they measured. `progress`, if given, shows the phase and counts, and is cleared at the end.
///
/// Fails only before the clients start (bad spec, no connection, unknown model, unusable model
/// description); errors during the run are counted in the report.
pub async fn run_load(
    endpoint: &str,
    options: &ClientOptions,
    spec: &LoadSpec,
    progress: Option<ProgressBar>,
) -> Result<LoadReport, LoadError> {
    if spec.concurrency == 0 {
        return Err(LoadError::InvalidLoad("concurrency must be at least 1".into()));
    }
    if spec.workload.items_per_request() == 0 {
        return Err(LoadError::InvalidLoad("batch must be at least 1".into()));
    }
    let connections = spec.concurrency.min(MAX_CONNECTIONS);
    let mut clients = Vec::with_capacity(connections);
    for _ in 0..connections {
        clients.push(FastrackClient::connect(endpoint, options.clone()).await?);
    }
    let info = clients[0].get_model(spec.model.clone()).await?;
    let domain = InputDomain::from_model(&info)?;
    // Pin the version that answered, so that every request measures the same model.
    let model = pb::ModelRef { name: info.name.clone(), version: info.version };
    let counters = Arc::new(Counters::default());
    let start = Instant::now();
    let measure_from = start + spec.warmup;
    let window = Window { measure_from, end: measure_from + spec.duration };
    let mut tasks = tokio::task::JoinSet::new();
    match spec.workload {
        Workload::Unary { batch } => {
            for i in 0..spec.concurrency {
                let mut rng = StdRng::seed_from_u64(spec.seed.wrapping_add(i as u64));
                let payloads = (0..PAYLOADS_PER_CLIENT).map(|_| domain.batch(&mut rng, batch)).collect();
                let client = clients[i % connections].clone();
                tasks.spawn(unary_client(client, model.clone(), payloads, window, counters.clone()));
            }
        }
        Workload::Track => {
            let sampler = Arc::new(TickSampler::from_model(&info, domain)?);
            for i in 0..spec.concurrency {
                let client = clients[i % connections].clone();
                let seed = spec.seed.wrapping_add(i as u64);
                tasks.spawn(track_client(client, model.clone(), sampler.clone(), seed, window, counters.clone()));
            }
        }
    }
    let ticker = progress.clone().map(|bar| tokio::spawn(show_progress(bar, start, window, counters.clone())));
    let mut latencies = Vec::new();
    let mut errors: HashMap<tonic::Code, u64> = HashMap::new();
    let mut last_finish = measure_from;
    while let Some(joined) = tasks.join_next().await {
        // A client task only ends by returning; a panic in one would be a bug worth surfacing.
        let stats = joined.map_err(|e| LoadError::InvalidLoad(format!("a load client failed: {e}")))?;
        latencies.extend(stats.latencies);
        for (code, n) in stats.errors {
            *errors.entry(code).or_default() += n;
        }
        last_finish = last_finish.max(stats.last_finish.unwrap_or(measure_from));
    }
    if let Some(ticker) = ticker {
        ticker.abort();
    }
    if let Some(bar) = progress {
        bar.finish_and_clear();
    }
    let requests = latencies.len() as u64;
    let mut errors: Vec<(tonic::Code, u64)> = errors.into_iter().collect();
    errors.sort_by_key(|&(code, n)| (std::cmp::Reverse(n), code as i32));
    Ok(LoadReport {
        workload: spec.workload,
        concurrency: spec.concurrency,
        connections,
        requests,
        items: requests * spec.workload.items_per_request() as u64,
        errors,
        elapsed: last_finish - measure_from,
        latency: LatencySummary::from_latencies(&mut latencies),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn info() -> pb::ModelInfo {
        let dim = |min: f64, max: f64, periodic: bool| pb::StateDimension {
            bounds: Some(pb::Interval { min, max }),
            periodic,
            ..Default::default()
        };
        pb::ModelInfo {
            name: "m".into(),
            version: 1,
            state: vec![dim(-3.0, 3.0, false), dim(-3.0, 3.0, false), dim(-3.2, 3.2, true), dim(0.0, 3.0, false)],
            params: vec![pb::ParameterDimension {
                range: Some(pb::Interval { min: 0.5, max: 1.25 }),
                ..Default::default()
            }],
            planner_to_state: vec![1.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0],
            planner_dim: 2,
            teb_table: vec![pb::TebRow { beta: 1.0, bound: 0.5, ..Default::default() }],
            ..Default::default()
        }
    }

    #[test]
    fn ticks_have_relative_states_inside_the_domain() {
        let info = info();
        let sampler = TickSampler::from_model(&info, InputDomain::from_model(&info).unwrap()).unwrap();
        let mut rng = StdRng::seed_from_u64(3);
        for seq in 0..1000 {
            let tick = sampler.tick(&mut rng, seq);
            assert_eq!((tick.tracker_state.len(), tick.planner_state.len()), (4, 2));
            let r = [
                tick.tracker_state[0] - tick.planner_state[0],
                tick.tracker_state[1] - tick.planner_state[1],
                tick.tracker_state[2],
                tick.tracker_state[3],
            ];
            for (x, d) in r.iter().zip(&info.state) {
                let b = d.bounds.unwrap();
                assert!((b.min..=b.max).contains(x), "{x} outside [{}, {}]", b.min, b.max);
            }
            let d_obs = tick.d_obs.unwrap();
            assert!((0.0..=2.0).contains(&d_obs));
        }
    }

    #[test]
    fn batches_are_inside_domain_and_range() {
        let domain = InputDomain::from_model(&info()).unwrap();
        let (states, params) = domain.batch(&mut StdRng::seed_from_u64(1), 64);
        assert_eq!((states.len(), params.len()), (256, 64));
        assert!(states.chunks(4).all(|s| s[3] >= 0.0 && s[3] <= 3.0 && s[0].abs() <= 3.0));
        assert!(params.iter().all(|p| (0.5..=1.25).contains(p)));
    }

    #[test]
    fn unusable_model_descriptions_are_errors() {
        let mut bad = info();
        bad.params[0].range = Some(pb::Interval { min: 2.0, max: 1.0 });
        assert!(matches!(InputDomain::from_model(&bad), Err(LoadError::InvalidLoad(_))));
        bad = info();
        bad.state[0].bounds = None;
        assert!(matches!(InputDomain::from_model(&bad), Err(LoadError::InvalidLoad(_))));
        bad = info();
        bad.planner_to_state.pop();
        let domain = InputDomain::from_model(&bad).unwrap();
        assert!(matches!(TickSampler::from_model(&bad, domain), Err(LoadError::InvalidLoad(_))));
    }

    #[test]
    fn latency_summary_uses_nearest_rank() {
        let mut latencies: Vec<Duration> = (1..=100).rev().map(Duration::from_millis).collect();
        let s = LatencySummary::from_latencies(&mut latencies);
        assert_eq!(s.p50, Duration::from_millis(51));
        assert_eq!(s.p99, Duration::from_millis(99));
        assert_eq!(s.max, Duration::from_millis(100));
        assert_eq!(LatencySummary::from_latencies(&mut []), LatencySummary::default());
    }
}
