//! Server settings: command-line flags, environment variables and a TOML file (`--config`) with the same
//! keys (flag `--max-batch-size` is key `max_batch_size`). A flag or variable wins over the file, the file
//! over the default. [`Settings::resolve`] validates everything before the server starts.

use anyhow::{bail, Context};
use std::collections::BTreeMap;
use std::net::SocketAddr;
use std::path::PathBuf;
use std::time::Duration;

/// Every setting, each optional so that flags, environment and file can be layered.
#[derive(Debug, Clone, Default, clap::Parser, serde::Deserialize)]
#[command(
    name = "fastrack-server",
    version,
    about = "Serves learned Hamilton-Jacobi value functions (Parametric FaSTrack) over gRPC"
)]
#[serde(deny_unknown_fields)]
pub struct Options {
    /// TOML file with any of these settings (keys are the flag names with `_` for `-`).
    #[arg(long, env = "FASTRACK_CONFIG")]
    #[serde(skip)]
    pub config: Option<PathBuf>,
    /// Address to listen on [default: 127.0.0.1:50051, loopback only].
    #[arg(long, env = "FASTRACK_LISTEN")]
    pub listen: Option<SocketAddr>,
    /// Model repository: `<dir>/<name>/<version>/{model.onnx, manifest.json}` [default: models].
    #[arg(long, env = "FASTRACK_MODELS")]
    pub models: Option<PathBuf>,
    /// Seconds between scans of the repository for new, changed or removed versions; 0 = no polling
    /// [default: 5].
    #[arg(long, env = "FASTRACK_POLL_INTERVAL_S")]
    pub poll_interval_s: Option<f64>,
    /// Version served when a request names version 0, per model: `name=version` (repeatable; default:
    /// the latest loaded version).
    #[arg(long = "pin", env = "FASTRACK_PIN", value_delimiter = ',')]
    pub pin: Option<Vec<String>>,
    /// Log filter (tracing EnvFilter syntax, e.g. `info` or `fastrack_server=debug`) [default: info].
    #[arg(long, env = "FASTRACK_LOG")]
    pub log_level: Option<String>,
    /// Log format: `text` or `json` [default: text].
    #[arg(long, env = "FASTRACK_LOG_FORMAT")]
    pub log_format: Option<String>,
    /// ONNX Runtime shared library [default: the project's .cache/onnxruntime].
    #[arg(long, env = "FASTRACK_ORT_LIB")]
    pub ort_lib: Option<PathBuf>,
    /// Threads of the compute pool that evaluates batches [default: the number of cores].
    #[arg(long, env = "FASTRACK_COMPUTE_THREADS")]
    pub compute_threads: Option<usize>,
    /// Items (states) that may wait for the compute pool; beyond it calls get RESOURCE_EXHAUSTED
    /// [default: 262144].
    #[arg(long, env = "FASTRACK_QUEUE_CAPACITY")]
    pub queue_capacity: Option<usize>,
    /// Merge concurrent requests for the same model version into one evaluation [default: true].
    #[arg(long, env = "FASTRACK_DYNAMIC_BATCHING", action = clap::ArgAction::Set)]
    pub dynamic_batching: Option<bool>,
    /// Most items in one merged evaluation [default: 256].
    #[arg(long, env = "FASTRACK_MAX_BATCH_SIZE")]
    pub max_batch_size: Option<usize>,
    /// Microseconds a request may wait for others to merge with; 0 merges only what is already queued
    /// [default: 0].
    #[arg(long, env = "FASTRACK_MAX_QUEUE_DELAY_US")]
    pub max_queue_delay_us: Option<u64>,
    /// Seconds a Track stream may stay without a tick before it is closed [default: 60].
    #[arg(long, env = "FASTRACK_STREAM_IDLE_TIMEOUT_S")]
    pub stream_idle_timeout_s: Option<f64>,
    /// Seconds a Track reply may wait for its client to read before the stream is closed: a client that
    /// stops reading holds at most its stream's reply buffer, and only that long [default: 10].
    #[arg(long, env = "FASTRACK_STREAM_SEND_TIMEOUT_S")]
    pub stream_send_timeout_s: Option<f64>,
    /// Track streams open at once over all connections (those still waiting for `open` included); beyond
    /// it a new stream gets RESOURCE_EXHAUSTED [default: 10000].
    #[arg(long, env = "FASTRACK_MAX_TRACK_STREAMS")]
    pub max_track_streams: Option<usize>,
    /// Seconds to drain open calls and streams after SIGTERM/SIGINT before exiting [default: 10].
    #[arg(long, env = "FASTRACK_SHUTDOWN_GRACE_S")]
    pub shutdown_grace_s: Option<f64>,
    /// TLS certificate chain (PEM); needs `tls_key`.
    #[arg(long, env = "FASTRACK_TLS_CERT")]
    pub tls_cert: Option<PathBuf>,
    /// TLS private key (PEM).
    #[arg(long, env = "FASTRACK_TLS_KEY")]
    pub tls_key: Option<PathBuf>,
    /// CA (PEM) that client certificates must chain to: turns on mutual TLS.
    #[arg(long, env = "FASTRACK_TLS_CLIENT_CA")]
    pub tls_client_ca: Option<PathBuf>,
    /// File of bearer tokens, one `role:token` per line (`user` or `admin`; `#` comments).
    #[arg(long, env = "FASTRACK_TOKENS_FILE")]
    pub tokens_file: Option<PathBuf>,
    /// Bearer tokens inline, `role:token` separated by commas (added to `tokens_file`).
    #[arg(long, env = "FASTRACK_TOKENS", hide_env_values = true)]
    pub tokens: Option<String>,
    /// File holding one user token and nothing else (e.g. a mounted Secret key), added to the others.
    #[arg(long, env = "FASTRACK_USER_TOKEN_FILE")]
    pub user_token_file: Option<PathBuf>,
    /// File holding one admin token and nothing else, added to the others.
    #[arg(long, env = "FASTRACK_ADMIN_TOKEN_FILE")]
    pub admin_token_file: Option<PathBuf>,
    /// Largest gRPC message accepted or sent, bytes [default: 16777216].
    #[arg(long, env = "FASTRACK_MAX_MESSAGE_BYTES")]
    pub max_message_bytes: Option<usize>,
    /// Most concurrent HTTP/2 streams (calls) per client connection [default: 1024].
    #[arg(long, env = "FASTRACK_MAX_CONCURRENT_STREAMS")]
    pub max_concurrent_streams: Option<u32>,
    /// Address of the Prometheus `/metrics` endpoint (plain HTTP) [default: none, no endpoint].
    #[arg(long, env = "FASTRACK_METRICS_LISTEN")]
    pub metrics_listen: Option<SocketAddr>,
}

macro_rules! overlay {
    ($high:expr, $low:expr, $($field:ident),* $(,)?) => {
        Options { config: $high.config, $($field: $high.$field.or($low.$field)),* }
    };
}

impl Options {
    /// `self` where set, else `file`.
    pub fn over(self, file: Options) -> Options {
        overlay!(
            self,
            file,
            listen,
            models,
            poll_interval_s,
            pin,
            log_level,
            log_format,
            ort_lib,
            compute_threads,
            queue_capacity,
            dynamic_batching,
            max_batch_size,
            max_queue_delay_us,
            stream_idle_timeout_s,
            stream_send_timeout_s,
            max_track_streams,
            shutdown_grace_s,
            tls_cert,
            tls_key,
            tls_client_ca,
            tokens_file,
            tokens,
            user_token_file,
            admin_token_file,
            max_message_bytes,
            max_concurrent_streams,
            metrics_listen,
        )
    }

    /// Reads a `--config` file.
    pub fn from_file(path: &std::path::Path) -> anyhow::Result<Options> {
        let text = std::fs::read_to_string(path).with_context(|| format!("reading config {}", path.display()))?;
        toml::from_str(&text).with_context(|| format!("config {} is not valid", path.display()))
    }
}

/// Log output format.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum LogFormat {
    /// Human-readable lines.
    Text,
    /// One JSON object per event, with span fields (request ids).
    Json,
}

/// TLS files (PEM contents).
#[derive(Debug, Clone)]
pub struct TlsFiles {
    /// Certificate chain.
    pub cert: Vec<u8>,
    /// Private key.
    pub key: Vec<u8>,
    /// CA for client certificates (mutual TLS) if set.
    pub client_ca: Option<Vec<u8>>,
}

/// Dynamic batching and queueing of the compute pool.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ComputeSettings {
    /// Pool threads.
    pub threads: usize,
    /// Items allowed to wait.
    pub queue_capacity: usize,
    /// Merge concurrent requests of one model version.
    pub dynamic_batching: bool,
    /// Most items per merged evaluation.
    pub max_batch_size: usize,
    /// How long a request may wait for others to merge with.
    pub max_queue_delay: Duration,
}

/// Validated settings of one server process.
#[derive(Debug, Clone)]
pub struct Settings {
    /// gRPC address.
    pub listen: SocketAddr,
    /// Model repository root.
    pub models: PathBuf,
    /// Repository polling period (`None`: no polling).
    pub poll_interval: Option<Duration>,
    /// Pinned default versions by model name.
    pub pins: BTreeMap<String, u32>,
    /// Log filter.
    pub log_level: String,
    /// Log format.
    pub log_format: LogFormat,
    /// ONNX Runtime library.
    pub ort_lib: Option<PathBuf>,
    /// Compute pool.
    pub compute: ComputeSettings,
    /// Default idle timeout of Track streams.
    pub stream_idle_timeout: Duration,
    /// How long a Track reply may wait for its client to read.
    pub stream_send_timeout: Duration,
    /// Track streams open at once.
    pub max_track_streams: usize,
    /// Drain deadline at shutdown.
    pub shutdown_grace: Duration,
    /// TLS, if configured.
    pub tls: Option<TlsFiles>,
    /// Bearer tokens (`role:token` entries, unparsed); empty = no authentication.
    pub token_entries: Vec<String>,
    /// Message size limit.
    pub max_message_bytes: usize,
    /// HTTP/2 streams per connection.
    pub max_concurrent_streams: u32,
    /// Prometheus endpoint.
    pub metrics_listen: Option<SocketAddr>,
}

fn positive_seconds(name: &str, value: f64) -> anyhow::Result<Duration> {
    match Duration::try_from_secs_f64(value) {
        Ok(duration) if value > 0.0 && value <= 1e9 => Ok(duration),
        _ => bail!("{name} = {value}; must be a positive number of seconds, at most 1e9"),
    }
}

fn at_least<T: PartialOrd + std::fmt::Display>(name: &str, value: T, min: T) -> anyhow::Result<T> {
    if value < min {
        bail!("{name} = {value}; must be at least {min}");
    }
    Ok(value)
}

fn parse_pins(entries: &[String]) -> anyhow::Result<BTreeMap<String, u32>> {
    let mut pins = BTreeMap::new();
    for entry in entries {
        let parsed = entry.split_once('=').and_then(|(name, v)| Some((name.trim(), v.trim().parse::<u32>().ok()?)));
        match parsed {
            Some((name, version)) if !name.is_empty() && version > 0 => {
                pins.insert(name.to_string(), version);
            }
            _ => bail!("pin {entry:?} must be `name=version` with a version >= 1"),
        }
    }
    Ok(pins)
}

fn read(path: &std::path::Path, what: &str) -> anyhow::Result<Vec<u8>> {
    std::fs::read(path).with_context(|| format!("reading {what} {}", path.display()))
}

/// The one token of a token file, without surrounding whitespace (a trailing newline is common).
fn read_token_file(path: &std::path::Path, role: &str) -> anyhow::Result<String> {
    let what = format!("{role} token file");
    let text =
        String::from_utf8(read(path, &what)?).with_context(|| format!("{what} {} is not UTF-8", path.display()))?;
    let token = text.trim();
    if token.is_empty() || token.contains(char::is_whitespace) {
        bail!("{what} {} must hold exactly one token (no spaces or line breaks inside it)", path.display());
    }
    Ok(token.to_string())
}

impl Settings {
    /// Applies defaults and checks every value; errors name the setting and what is allowed.
    pub fn resolve(o: Options) -> anyhow::Result<Settings> {
        let cores = std::thread::available_parallelism().map(|n| n.get()).unwrap_or(1);
        let poll = o.poll_interval_s.unwrap_or(5.0);
        if !(poll.is_finite() && (0.0..=1e9).contains(&poll)) {
            bail!("poll_interval_s = {poll}; must be between 0 (no polling) and 1e9 seconds");
        }
        let log_format = match o.log_format.as_deref().unwrap_or("text") {
            "text" => LogFormat::Text,
            "json" => LogFormat::Json,
            other => bail!("log_format = {other:?}; must be `text` or `json`"),
        };
        let tls = match (&o.tls_cert, &o.tls_key) {
            (Some(cert), Some(key)) => Some(TlsFiles {
                cert: read(cert, "TLS certificate")?,
                key: read(key, "TLS key")?,
                client_ca: o.tls_client_ca.as_deref().map(|p| read(p, "client CA")).transpose()?,
            }),
            (None, None) if o.tls_client_ca.is_some() => bail!("tls_client_ca needs tls_cert and tls_key"),
            (None, None) => None,
            _ => bail!("tls_cert and tls_key must be given together"),
        };
        let mut token_entries = Vec::new();
        if let Some(path) = &o.tokens_file {
            let text = String::from_utf8(read(path, "tokens file")?)
                .with_context(|| format!("tokens file {} is not UTF-8", path.display()))?;
            token_entries.extend(text.lines().map(str::to_string));
        }
        if let Some(inline) = &o.tokens {
            token_entries.extend(inline.split(',').map(str::to_string));
        }
        for (role, path) in [("user", &o.user_token_file), ("admin", &o.admin_token_file)] {
            if let Some(path) = path {
                token_entries.push(format!("{role}:{}", read_token_file(path, role)?));
            }
        }
        Ok(Settings {
            listen: o.listen.unwrap_or_else(|| SocketAddr::from(([127, 0, 0, 1], 50051))),
            models: o.models.unwrap_or_else(|| "models".into()),
            poll_interval: (poll > 0.0).then(|| Duration::from_secs_f64(poll)),
            pins: parse_pins(o.pin.as_deref().unwrap_or_default())?,
            log_level: o.log_level.unwrap_or_else(|| "info".into()),
            log_format,
            ort_lib: o.ort_lib,
            compute: ComputeSettings {
                threads: at_least("compute_threads", o.compute_threads.unwrap_or(cores), 1)?,
                queue_capacity: at_least("queue_capacity", o.queue_capacity.unwrap_or(262_144), 1)?,
                dynamic_batching: o.dynamic_batching.unwrap_or(true),
                max_batch_size: at_least("max_batch_size", o.max_batch_size.unwrap_or(256), 1)?,
                max_queue_delay: Duration::from_micros(o.max_queue_delay_us.unwrap_or(0)),
            },
            stream_idle_timeout: positive_seconds("stream_idle_timeout_s", o.stream_idle_timeout_s.unwrap_or(60.0))?,
            stream_send_timeout: positive_seconds("stream_send_timeout_s", o.stream_send_timeout_s.unwrap_or(10.0))?,
            max_track_streams: at_least("max_track_streams", o.max_track_streams.unwrap_or(10_000), 1)?,
            shutdown_grace: positive_seconds("shutdown_grace_s", o.shutdown_grace_s.unwrap_or(10.0))?,
            tls,
            token_entries,
            max_message_bytes: at_least("max_message_bytes", o.max_message_bytes.unwrap_or(16 << 20), 1024)?,
            max_concurrent_streams: at_least("max_concurrent_streams", o.max_concurrent_streams.unwrap_or(1024), 1)?,
            metrics_listen: o.metrics_listen,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use clap::Parser;

    #[test]
    fn flags_win_over_the_file_and_the_file_over_defaults() {
        let file: Options = toml::from_str("max_batch_size = 64\nqueue_capacity = 10\npin = [\"a=2\"]").unwrap();
        let cli = Options::try_parse_from(["fastrack-server", "--max-batch-size", "8"]).unwrap();
        let s = Settings::resolve(cli.over(file)).unwrap();
        assert_eq!(s.compute.max_batch_size, 8);
        assert_eq!(s.compute.queue_capacity, 10);
        assert_eq!(s.pins.get("a"), Some(&2));
        assert_eq!(s.listen.port(), 50051);
        assert!(s.listen.ip().is_loopback());
    }

    #[test]
    fn bad_values_are_named() {
        let err = |toml: &str| {
            let o: Result<Options, _> = toml::from_str(toml);
            match o {
                Err(e) => e.to_string(),
                Ok(o) => Settings::resolve(o).unwrap_err().to_string(),
            }
        };
        assert!(err("compute_threads = 0").contains("compute_threads = 0; must be at least 1"));
        assert!(err("poll_interval_s = -1.0").contains("poll_interval_s"));
        assert!(err("log_format = \"xml\"").contains("`text` or `json`"));
        assert!(err("pin = [\"a\"]").contains("name=version"));
        assert!(err("tls_cert = \"x.pem\"").contains("given together"));
        assert!(err("no_such_key = 1").contains("unknown field"));
        assert!(err("shutdown_grace_s = 0.0").contains("positive"));
        assert!(err("stream_idle_timeout_s = 1e300").contains("at most 1e9"));
        assert!(err("stream_send_timeout_s = 0.0").contains("stream_send_timeout_s = 0; must be a positive"));
        assert!(err("max_track_streams = 0").contains("max_track_streams = 0; must be at least 1"));
        assert!(err("poll_interval_s = 1e300").contains("poll_interval_s"));
    }

    #[test]
    fn token_files_hold_one_token_each_as_a_mounted_secret_key_does() {
        let dir = tempfile::tempdir().unwrap();
        let (user, admin, broken) =
            (dir.path().join("user-token"), dir.path().join("admin-token"), dir.path().join("two"));
        std::fs::write(&user, "u-123456\n").unwrap();
        std::fs::write(&admin, "a-654321").unwrap();
        std::fs::write(&broken, "first\nsecond\n").unwrap();
        let options = |user: &std::path::Path, admin: &std::path::Path| {
            let toml = format!("user_token_file = {:?}\nadmin_token_file = {:?}\ntokens = \"user:x-1\"", user, admin);
            Settings::resolve(toml::from_str(&toml).unwrap())
        };
        let s = options(&user, &admin).unwrap();
        assert_eq!(s.token_entries, ["user:x-1", "user:u-123456", "admin:a-654321"]);
        let e = options(&user, &broken).unwrap_err().to_string();
        assert!(e.contains("admin token file") && e.contains("exactly one token"), "{e}");
        let e = format!("{:#}", options(&dir.path().join("missing"), &admin).unwrap_err());
        assert!(e.contains("user token file") && e.contains("missing"), "{e}");
    }
}
