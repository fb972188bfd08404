//! The replicas a client talks to: one channel per server address, taken round-robin call by call, and the
//! count of the client's open `Track` streams on each, by which streams balance themselves over the replicas
//! that serve (a replica that comes back gets its share again).
//!
//! A server address is a list of endpoints separated by commas (`http://10.0.0.5:50051,http://10.0.0.6:50051`),
//! or one endpoint whose host name resolves to several addresses (a Kubernetes headless Service): each address
//! becomes a replica, verified under the host name when TLS is on. Names are resolved once, when connecting:
//! a client made before a scale-up does not see the new replicas until it connects again.

use crate::ClientError;
use std::collections::hash_map::RandomState;
use std::hash::{BuildHasher, Hasher};
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};
use tonic::transport::{Channel, Endpoint, Uri};

/// How long a replica that refused a stream is left out of balancing.
const REFUSED_PAUSE: Duration = Duration::from_secs(5);

/// The replicas of one client, shared by its clones.
#[derive(Debug)]
pub struct Replicas {
    replicas: Vec<Replica>,
    next: AtomicUsize,
    /// The client's open `Track` streams per replica.
    streams: Vec<AtomicUsize>,
    /// What balancing weighs besides the open streams.
    balance: Mutex<Balance>,
}

/// Per replica: when it last refused a stream (it is left out of balancing for a while), and the moves planned
/// to it and away from it and not made yet. Planned moves count where they go, so that streams looking at the
/// balance at the same moment do not all leave for the same lighter replica.
#[derive(Debug)]
struct Balance {
    refused: Vec<Option<Instant>>,
    incoming: Vec<usize>,
    outgoing: Vec<usize>,
}

/// A move planned by [`Replicas::plan_move`]: counted in the balance until it is dropped (made or given up).
#[derive(Debug)]
pub(crate) struct PlannedMove {
    replicas: Arc<Replicas>,
    /// The replica the stream leaves.
    pub from: usize,
    /// The replica it moves to.
    pub to: usize,
}

impl Drop for PlannedMove {
    fn drop(&mut self) {
        let mut balance = self.replicas.balance();
        balance.incoming[self.to] -= 1;
        balance.outgoing[self.from] -= 1;
    }
}

/// One server: where it is and the channel to it (connected lazily if it was down when the client connected).
#[derive(Debug, Clone)]
pub struct Replica {
    /// Its endpoint, `scheme://address:port`.
    pub endpoint: String,
    /// The channel to it.
    pub channel: Channel,
}

impl Replicas {
    /// The replicas, the first call going to a random one (so that many clients of one fleet spread their
    /// first calls too).
    pub fn new(replicas: Vec<Replica>) -> Self {
        let start = RandomState::new().build_hasher().finish() as usize;
        let streams = replicas.iter().map(|_| AtomicUsize::new(0)).collect();
        let count = replicas.len();
        let balance =
            Mutex::new(Balance { refused: vec![None; count], incoming: vec![0; count], outgoing: vec![0; count] });
        Self { replicas, next: AtomicUsize::new(start), streams, balance }
    }

    /// How many replicas there are.
    pub fn count(&self) -> usize {
        self.replicas.len()
    }

    /// The next replica in round-robin order.
    pub fn next(&self) -> &Replica {
        self.rotation().next().expect("a client has at least one replica")
    }

    /// Every replica once, from the next in round-robin order on: where a call goes, then where it goes again
    /// if that replica is gone.
    pub fn rotation(&self) -> impl Iterator<Item = &Replica> {
        self.indexed_rotation().map(|(_, replica)| replica)
    }

    /// [`Replicas::rotation`] with each replica's index.
    pub(crate) fn indexed_rotation(&self) -> impl Iterator<Item = (usize, &Replica)> {
        let (start, count) = (self.next.fetch_add(1, Ordering::Relaxed), self.replicas.len());
        (0..count).map(move |k| ((start + k) % count, &self.replicas[(start + k) % count]))
    }

    /// The replica at `index`.
    pub(crate) fn get(&self, index: usize) -> &Replica {
        &self.replicas[index]
    }

    /// The client's open `Track` streams on each replica, in the order of [`Replicas::endpoints`].
    pub fn stream_counts(&self) -> Vec<usize> {
        self.streams.iter().map(|n| n.load(Ordering::Relaxed)).collect()
    }

    /// Counts a stream opened on `index`.
    pub(crate) fn stream_opened(&self, index: usize) {
        self.streams[index].fetch_add(1, Ordering::Relaxed);
    }

    /// Counts a stream closed (or moved away) on `index`.
    pub(crate) fn stream_closed(&self, index: usize) {
        self.streams[index].fetch_sub(1, Ordering::Relaxed);
    }

    fn balance(&self) -> std::sync::MutexGuard<'_, Balance> {
        self.balance.lock().unwrap_or_else(|e| e.into_inner())
    }

    /// Remembers that `index` refused a stream: balancing leaves it alone for a while.
    pub(crate) fn refused(&self, index: usize) {
        self.balance().refused[index] = Some(Instant::now());
    }

    /// Plans a move that evens the load for a stream on `from`: to the replica with the fewest of the client's
    /// streams, if it has at least two fewer than `from` (one move then narrows the gap) and has not refused
    /// a stream lately. Streams count where their planned moves go, until the plan is dropped.
    pub(crate) fn plan_move(self: &Arc<Self>, from: usize) -> Option<PlannedMove> {
        let mut balance = self.balance();
        let counts = self.stream_counts();
        let load = |i: usize| (counts[i] + balance.incoming[i]).saturating_sub(balance.outgoing[i]);
        let to = (0..self.replicas.len())
            .filter(|&i| i != from && balance.refused[i].is_none_or(|at| at.elapsed() >= REFUSED_PAUSE))
            .min_by_key(|&i| load(i))
            .filter(|&i| load(i) + 2 <= load(from))?;
        balance.incoming[to] += 1;
        balance.outgoing[from] += 1;
        Some(PlannedMove { replicas: Arc::clone(self), from, to })
    }

    /// Every replica's endpoint.
    pub fn endpoints(&self) -> Vec<&str> {
        self.replicas.iter().map(|r| r.endpoint.as_str()).collect()
    }
}

/// True when `status` means the replica is gone rather than the call refused, so the call or stream may go on
/// elsewhere: `UNAVAILABLE` (unreachable, or draining), or any status the transport made from a failed
/// connection (a killed replica's streams end `UNKNOWN` with a reset connection, calls on its closed
/// connection `CANCELLED`); a status a server sent carries no transport error.
pub fn replica_lost(status: &tonic::Status) -> bool {
    status.code() == tonic::Code::Unavailable || std::error::Error::source(status).is_some()
}

/// The endpoints a server address names: its comma-separated parts, each host name resolved to every address
/// it has. Returns `(endpoint, TLS server name)` pairs; the name is the host as written.
pub async fn resolve(address: &str) -> Result<Vec<(String, Option<String>)>, ClientError> {
    let invalid = |endpoint: &str, reason: String| ClientError::InvalidEndpoint { endpoint: endpoint.into(), reason };
    let parts: Vec<&str> = address.split(',').map(str::trim).collect();
    if parts.iter().any(|part| part.is_empty()) {
        return Err(invalid(address, "an empty endpoint in the comma-separated list".into()));
    }
    let mut endpoints = Vec::new();
    for part in parts {
        let uri: Uri = part.parse().map_err(|e: tonic::codegen::http::uri::InvalidUri| invalid(part, e.to_string()))?;
        let (Some(scheme), Some(host)) = (uri.scheme_str(), uri.host()) else {
            return Err(invalid(part, "expected scheme://host:port, e.g. http://127.0.0.1:50051".into()));
        };
        let port = uri.port_u16().unwrap_or(if scheme == "https" { 443 } else { 80 });
        let bare_host = host.trim_start_matches('[').trim_end_matches(']');
        if bare_host.parse::<std::net::IpAddr>().is_ok() {
            endpoints.push((part.to_string(), None));
            continue;
        }
        let addresses = tokio::net::lookup_host((bare_host, port))
            .await
            .map_err(|e| invalid(part, format!("cannot resolve {host}: {e}")))?;
        let mut found: Vec<std::net::SocketAddr> = addresses.collect();
        found.sort();
        found.dedup();
        if found.is_empty() {
            return Err(invalid(part, format!("{host} resolves to no address")));
        }
        for socket in found {
            endpoints.push((format!("{scheme}://{socket}"), Some(host.to_string())));
        }
    }
    Ok(endpoints)
}

/// Connects to every endpoint; one that cannot be reached now is kept, connected lazily (it may come back),
/// as long as one can be reached.
pub async fn connect_all(builders: Vec<(String, Endpoint)>) -> Result<Replicas, ClientError> {
    if builders.is_empty() {
        return Err(ClientError::InvalidEndpoint { endpoint: String::new(), reason: "no endpoint given".into() });
    }
    let mut replicas = Vec::with_capacity(builders.len());
    let (mut reached, mut first_error) = (0, None);
    for (endpoint, builder) in builders {
        let channel = match builder.connect().await {
            Ok(channel) => {
                reached += 1;
                channel
            }
            Err(source) => {
                first_error.get_or_insert(ClientError::Connect { endpoint: endpoint.clone(), source });
                builder.connect_lazy()
            }
        };
        replicas.push(Replica { endpoint, channel });
    }
    match first_error {
        Some(error) if reached == 0 => Err(error),
        _ => Ok(Replicas::new(replicas)),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// `count` replicas nothing serves (their channels connect lazily, never here).
    fn unserved(count: usize) -> Arc<Replicas> {
        let replicas = (0..count)
            .map(|i| {
                let endpoint = format!("http://127.0.0.1:{}", 1 + i);
                let channel = Endpoint::from_shared(endpoint.clone()).unwrap().connect_lazy();
                Replica { endpoint, channel }
            })
            .collect();
        Arc::new(Replicas::new(replicas))
    }

    fn open(replicas: &Replicas, counts: &[usize]) {
        for (index, &count) in counts.iter().enumerate() {
            (0..count).for_each(|_| replicas.stream_opened(index));
        }
    }

    #[tokio::test]
    async fn streams_looking_at_once_plan_only_the_moves_that_even_the_load() {
        // Six streams on replica 1 look at [0, 6, 3] at the same moment: three moves to replica 0 even it.
        let replicas = unserved(3);
        open(&replicas, &[0, 6, 3]);
        let plans: Vec<PlannedMove> = (0..6).filter_map(|_| replicas.plan_move(1)).collect();
        assert_eq!(plans.iter().map(|p| (p.from, p.to)).collect::<Vec<_>>(), [(1, 0); 3]);
        assert!(replicas.plan_move(2).is_none(), "replica 2 holds its share once the plans count");
        // Plans given up leave the balance: the same look plans the same moves again.
        drop(plans);
        assert_eq!(replicas.plan_move(1).map(|p| p.to), Some(0));
    }

    #[tokio::test]
    async fn a_replica_that_refused_is_left_out_and_one_move_narrows_the_gap() {
        let replicas = unserved(3);
        open(&replicas, &[0, 6, 3]);
        replicas.refused(0);
        let plans: Vec<PlannedMove> = (0..6).filter_map(|_| replicas.plan_move(1)).collect();
        assert_eq!(plans.iter().map(|p| (p.from, p.to)).collect::<Vec<_>>(), [(1, 2)], "[0, 5, 4] after one");
        let even = unserved(2);
        open(&even, &[2, 1]);
        assert!(even.plan_move(0).is_none(), "a gap of one is as even as it gets");
    }
}
