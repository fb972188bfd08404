//! Prometheus metrics (OpenMetrics text) and their plain-HTTP `/metrics` endpoint on a port of its own.

use prometheus_client::encoding::EncodeLabelSet;
use prometheus_client::metrics::counter::Counter;
use prometheus_client::metrics::family::Family;
use prometheus_client::metrics::gauge::Gauge;
use prometheus_client::metrics::histogram::{exponential_buckets, Histogram};
use prometheus_client::registry::Registry;
use std::sync::Arc;
use std::time::Duration;

#[derive(Clone, Debug, Hash, PartialEq, Eq, EncodeLabelSet)]
struct CallLabels {
    rpc: &'static str,
    model: String,
    code: String,
}

#[derive(Clone, Debug, Hash, PartialEq, Eq, EncodeLabelSet)]
struct RpcLabels {
    rpc: &'static str,
}

#[derive(Clone, Debug, Hash, PartialEq, Eq, EncodeLabelSet)]
struct ModelLabels {
    model: String,
}

#[derive(Clone, Debug, Hash, PartialEq, Eq, EncodeLabelSet)]
struct CodeLabels {
    code: String,
}

/// The canonical gRPC name of a code (`OK`, `RESOURCE_EXHAUSTED`, ...).
pub fn code_name(code: tonic::Code) -> &'static str {
    use tonic::Code::*;
    match code {
        Ok => "OK",
        Cancelled => "CANCELLED",
        Unknown => "UNKNOWN",
        InvalidArgument => "INVALID_ARGUMENT",
        DeadlineExceeded => "DEADLINE_EXCEEDED",
        NotFound => "NOT_FOUND",
        AlreadyExists => "ALREADY_EXISTS",
        PermissionDenied => "PERMISSION_DENIED",
        ResourceExhausted => "RESOURCE_EXHAUSTED",
        FailedPrecondition => "FAILED_PRECONDITION",
        Aborted => "ABORTED",
        OutOfRange => "OUT_OF_RANGE",
        Unimplemented => "UNIMPLEMENTED",
        Internal => "INTERNAL",
        Unavailable => "UNAVAILABLE",
        DataLoss => "DATA_LOSS",
        Unauthenticated => "UNAUTHENTICATED",
    }
}

type HistogramFamily<L> = Family<L, Histogram, fn() -> Histogram>;

fn latency_histogram() -> Histogram {
    // 10 us .. ~5 s.
    Histogram::new(exponential_buckets(1e-5, 2.0, 20))
}

/// Every metric the server exports.
pub struct Metrics {
    registry: Registry,
    requests: Family<CallLabels, Counter>,
    request_seconds: HistogramFamily<RpcLabels>,
    ticks: Family<CallLabels, Counter>,
    queue_seconds: Histogram,
    compute_seconds: Histogram,
    batch_items: Histogram,
    queued_items: Gauge,
    shed: Counter,
    active_streams: Gauge,
    loaded_versions: Family<ModelLabels, Gauge>,
    load_failures: Family<ModelLabels, Counter>,
    auth_failures: Family<CodeLabels, Counter>,
}

impl Default for Metrics {
    fn default() -> Self {
        Self::new()
    }
}

impl Metrics {
    /// Creates and registers every metric under the `fastrack_` prefix.
    pub fn new() -> Self {
        let mut registry = Registry::with_prefix("fastrack");
        let requests = Family::<CallLabels, Counter>::default();
        registry.register(
            "requests",
            "Unary calls and Track streams by RPC, model and final gRPC code",
            requests.clone(),
        );
        let request_seconds =
            HistogramFamily::<RpcLabels>::new_with_constructor(latency_histogram as fn() -> Histogram);
        registry.register("request_seconds", "Time to answer a unary call, by RPC", request_seconds.clone());
        let ticks = Family::<CallLabels, Counter>::default();
        registry.register(
            "track_ticks",
            "Track ticks answered, by model and gRPC code (OK or the tick's error)",
            ticks.clone(),
        );
        let queue_seconds = latency_histogram();
        registry.register("queue_seconds", "Time a request waited for the compute pool", queue_seconds.clone());
        let compute_seconds = latency_histogram();
        registry.register("compute_seconds", "Time of one (possibly merged) evaluation", compute_seconds.clone());
        let batch_items = Histogram::new(exponential_buckets(1.0, 2.0, 17));
        registry.register("batch_items", "States per evaluation, after dynamic batching", batch_items.clone());
        let queued_items = Gauge::default();
        registry.register("queued_items", "States waiting for the compute pool", queued_items.clone());
        let shed = Counter::default();
        registry.register("shed", "Requests refused with RESOURCE_EXHAUSTED because the queue was full", shed.clone());
        let active_streams = Gauge::default();
        registry.register("active_streams", "Open Track streams", active_streams.clone());
        let loaded_versions = Family::<ModelLabels, Gauge>::default();
        registry.register("loaded_versions", "Versions loaded, by model", loaded_versions.clone());
        let load_failures = Family::<ModelLabels, Counter>::default();
        registry.register("load_failures", "Rejected bundle loads, by model", load_failures.clone());
        let auth_failures = Family::<CodeLabels, Counter>::default();
        registry.register("auth_failures", "Calls refused by authentication, by gRPC code", auth_failures.clone());
        Self {
            registry,
            requests,
            request_seconds,
            ticks,
            queue_seconds,
            compute_seconds,
            batch_items,
            queued_items,
            shed,
            active_streams,
            loaded_versions,
            load_failures,
            auth_failures,
        }
    }

    /// Records a finished unary call (`elapsed`) or a finished stream (`None`).
    pub fn call(&self, rpc: &'static str, model: &str, code: tonic::Code, elapsed: Option<Duration>) {
        let labels = CallLabels { rpc, model: model.to_string(), code: code_name(code).into() };
        self.requests.get_or_create(&labels).inc();
        if let Some(elapsed) = elapsed {
            self.request_seconds.get_or_create(&RpcLabels { rpc }).observe(elapsed.as_secs_f64());
        }
    }

    /// Records one answered Track tick.
    pub fn tick(&self, model: &str, code: tonic::Code) {
        let labels = CallLabels { rpc: "Track", model: model.to_string(), code: code_name(code).into() };
        self.ticks.get_or_create(&labels).inc();
    }

    /// Records an evaluation of `items` states by the compute pool.
    pub fn evaluation(&self, items: usize, compute: Duration) {
        self.batch_items.observe(items as f64);
        self.compute_seconds.observe(compute.as_secs_f64());
    }

    /// Records how long a request waited in the queue.
    pub fn queued(&self, wait: Duration) {
        self.queue_seconds.observe(wait.as_secs_f64());
    }

    /// Sets the number of queued states.
    pub fn set_queued_items(&self, items: usize) {
        self.queued_items.set(items as i64);
    }

    /// Counts a request refused because the queue was full.
    pub fn shed(&self) {
        self.shed.inc();
    }

    /// A Track stream opened (+1) or closed (-1).
    pub fn stream_delta(&self, delta: i64) {
        self.active_streams.inc_by(delta);
    }

    /// Open Track streams.
    pub fn active_streams(&self) -> i64 {
        self.active_streams.get()
    }

    /// Sets the loaded version count of every model (models absent from `counts` are set to 0).
    pub fn set_loaded(&self, counts: &[(String, usize)]) {
        self.loaded_versions.clear();
        for (model, n) in counts {
            self.loaded_versions.get_or_create(&ModelLabels { model: model.clone() }).set(*n as i64);
        }
    }

    /// Counts a rejected bundle.
    pub fn load_failure(&self, model: &str) {
        self.load_failures.get_or_create(&ModelLabels { model: model.to_string() }).inc();
    }

    /// Counts a call refused by authentication.
    pub fn auth_failure(&self, code: tonic::Code) {
        self.auth_failures.get_or_create(&CodeLabels { code: code_name(code).into() }).inc();
    }

    /// The OpenMetrics text exposition.
    pub fn encode(&self) -> String {
        let mut text = String::new();
        // Writing into a String cannot fail.
        let _ = prometheus_client::encoding::text::encode(&mut text, &self.registry);
        text
    }
}

/// Serves `GET /metrics` on `listener` until `shutdown` resolves.
pub async fn serve(
    listener: tokio::net::TcpListener,
    metrics: Arc<Metrics>,
    shutdown: impl std::future::Future<Output = ()> + Send + 'static,
) -> std::io::Result<()> {
    use axum::http::header::CONTENT_TYPE;
    let app =
        axum::Router::new().route(
            "/metrics",
            axum::routing::get(move || {
                let metrics = Arc::clone(&metrics);
                async move {
                    ([(CONTENT_TYPE, "application/openmetrics-text; version=1.0.0; charset=utf-8")], metrics.encode())
                }
            }),
        );
    axum::serve(listener, app).with_graceful_shutdown(shutdown).await
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn exposition_names_and_labels() {
        let m = Metrics::new();
        m.call("TrackingControl", "dubins4d", tonic::Code::Ok, Some(Duration::from_micros(300)));
        m.call("TrackingControl", "dubins4d", tonic::Code::Ok, Some(Duration::from_micros(300)));
        m.stream_delta(1);
        m.set_loaded(&[("dubins4d".into(), 2)]);
        let text = m.encode();
        assert!(
            text.contains(r#"fastrack_requests_total{rpc="TrackingControl",model="dubins4d",code="OK"} 2"#),
            "{text}"
        );
        assert!(text.contains("fastrack_active_streams 1"), "{text}");
        assert!(text.contains(r#"fastrack_loaded_versions{model="dubins4d"} 2"#), "{text}");
        assert!(text.contains(r#"fastrack_request_seconds_count{rpc="TrackingControl"} 2"#), "{text}");
        assert!(text.ends_with("# EOF\n"));
    }
}
