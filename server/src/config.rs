//! Server settings, by flag or environment variable.

use std::net::SocketAddr;
use std::path::PathBuf;

/// Settings of one server process.
#[derive(Debug, Clone, clap::Parser)]
#[command(
    name = "fastrack-server",
    version,
    about = "Serves learned Hamilton-Jacobi value functions (Parametric FaSTrack) over gRPC"
)]
pub struct ServerConfig {
    /// Address to listen on (loopback by default).
    #[arg(long, env = "FASTRACK_LISTEN", default_value = "127.0.0.1:50051")]
    pub listen: SocketAddr,
    /// Model repository: `<dir>/<name>/<version>/{model.onnx, manifest.json}`.
    #[arg(long, env = "FASTRACK_MODELS", default_value = "models")]
    pub models: PathBuf,
    /// Log filter (tracing EnvFilter syntax, e.g. `info` or `fastrack_server=debug`).
    #[arg(long, env = "FASTRACK_LOG", default_value = "info")]
    pub log_level: String,
    /// ONNX Runtime shared library (default: the project's .cache/onnxruntime).
    #[arg(long, env = "FASTRACK_ORT_LIB")]
    pub ort_lib: Option<PathBuf>,
    /// ONNX Runtime sessions per model version (concurrent evaluations), one intra-op thread each.
    #[arg(long, env = "FASTRACK_SESSIONS", default_value_t = 2)]
    pub sessions_per_model: usize,
    /// Seconds a Track stream may stay without a tick before it is closed.
    #[arg(long, env = "FASTRACK_STREAM_IDLE_TIMEOUT_S", default_value_t = 60.0)]
    pub stream_idle_timeout_s: f64,
}
