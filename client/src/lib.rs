//! Typed Rust client for the fastrack safety service (`fastrack.v1` over gRPC).
//!
//! ```no_run
//! # async fn demo() -> Result<(), fastrack_client::ClientError> {
//! use fastrack_client::{model_ref, ClientOptions, FastrackClient};
//! let client = FastrackClient::connect("http://127.0.0.1:50051", ClientOptions::default()).await?;
//! let speed = client.query_planner_control(model_ref("dubins4d", 0), Some(2.0)).await?;
//! println!("plan at beta = {} (TEB radius {})", speed.beta_query, speed.dteb_radius);
//! # Ok(()) }
//! ```

#![warn(missing_docs)]

pub use fastrack_proto::v1 as pb;

mod replicas;
mod track;

pub use track::TrackStream;

/// The README's Rust example, compiled as a doctest so that it cannot drift from this crate.
#[cfg(doctest)]
#[doc = include_str!("../../README.md")]
pub struct ReadmeExample;

use pb::model_admin_service_client::ModelAdminServiceClient;
use pb::model_service_client::ModelServiceClient;
use pb::safety_service_client::SafetyServiceClient;
use rustls_pki_types::pem::PemObject;
use rustls_pki_types::{CertificateDer, PrivateKeyDer};
use std::future::Future;
use std::sync::Arc;
use std::time::Duration;
use tonic::metadata::AsciiMetadataValue;
use tonic::transport::{Certificate, Channel, ClientTlsConfig, Endpoint, Identity};
pub use tonic_health::pb::health_check_response::ServingStatus as HealthStatus;
use tonic_health::pb::health_client::HealthClient;

/// Connection settings.
#[derive(Clone, PartialEq, Eq)]
pub struct ClientOptions {
    /// Limit on establishing the connection.
    pub connect_timeout: Duration,
    /// Deadline of each unary call (sent to the server as `grpc-timeout`), of a `Track` stream's open and of
    /// each tick's reply (a replica that misses it is passed over as gone).
    pub request_timeout: Duration,
    /// Bearer token sent as `authorization: Bearer <token>` on every call (unary and streams).
    pub bearer_token: Option<String>,
    /// TLS settings; `Some` requires an `https://` endpoint.
    pub tls: Option<ClientTls>,
}

impl Default for ClientOptions {
    fn default() -> Self {
        Self {
            connect_timeout: Duration::from_secs(5),
            request_timeout: Duration::from_secs(5),
            bearer_token: None,
            tls: None,
        }
    }
}

impl std::fmt::Debug for ClientOptions {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("ClientOptions")
            .field("connect_timeout", &self.connect_timeout)
            .field("request_timeout", &self.request_timeout)
            .field("bearer_token", &self.bearer_token.as_ref().map(|_| "<redacted>"))
            .field("tls", &self.tls)
            .finish()
    }
}

/// TLS settings of a connection: the server is verified against `ca_pem`; with `identity` the client also
/// presents a certificate (mutual TLS).
#[derive(Clone, PartialEq, Eq)]
pub struct ClientTls {
    /// PEM of the certificate authority (one or more certificates) that signed the server's certificate.
    pub ca_pem: Vec<u8>,
    /// Client certificate chain PEM and private key PEM, for mutual TLS.
    pub identity: Option<(Vec<u8>, Vec<u8>)>,
    /// Server name to verify the certificate against; default: the endpoint's host.
    pub domain: Option<String>,
}

impl std::fmt::Debug for ClientTls {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("ClientTls")
            .field("ca_pem", &format_args!("<{} bytes>", self.ca_pem.len()))
            .field("identity", &self.identity.as_ref().map(|_| "<certificate and key>"))
            .field("domain", &self.domain)
            .finish()
    }
}

impl ClientTls {
    /// Checks that every PEM holds what it must (a certificate, a private key) and builds tonic's config.
    fn config(&self) -> Result<ClientTlsConfig, ClientError> {
        let bad = |what: &'static str, reason: String| ClientError::Tls { what, reason };
        let certificates = |what: &'static str, pem: &[u8]| -> Result<(), ClientError> {
            let mut count = 0usize;
            for certificate in CertificateDer::pem_slice_iter(pem) {
                certificate.map_err(|e| bad(what, e.to_string()))?;
                count += 1;
            }
            if count == 0 {
                return Err(bad(what, "no PEM certificate (-----BEGIN CERTIFICATE-----) found".into()));
            }
            Ok(())
        };
        certificates("CA certificate", &self.ca_pem)?;
        let mut config = ClientTlsConfig::new().ca_certificate(Certificate::from_pem(&self.ca_pem));
        if let Some((cert, key)) = &self.identity {
            certificates("client certificate", cert)?;
            PrivateKeyDer::from_pem_slice(key)
                .map_err(|e| bad("client key", format!("no usable PEM private key (PKCS#8, PKCS#1 or SEC1): {e}")))?;
            config = config.identity(Identity::from_pem(cert, key));
        }
        if let Some(domain) = &self.domain {
            config = config.domain_name(domain.clone());
        }
        Ok(config)
    }
}

/// Why a call failed.
#[derive(Debug, thiserror::Error)]
pub enum ClientError {
    /// The endpoint string is not a valid URI.
    #[error("invalid server address {endpoint:?}: {reason}")]
    InvalidEndpoint {
        /// The address given.
        endpoint: String,
        /// Why it is invalid.
        reason: String,
    },
    /// No connection could be made.
    #[error("cannot connect to {endpoint}: {source}")]
    Connect {
        /// The address.
        endpoint: String,
        /// The transport error.
        source: tonic::transport::Error,
    },
    /// The server answered with an error status (or the transport failed during the call).
    #[error("{}", status_text(.0))]
    Status(tonic::Status),
    /// Fewer replicas than asked for became ready in time.
    #[error("{serving} of {replicas} replicas SERVING after {timeout:?}, {quorum} wanted")]
    NotReady {
        /// Replicas SERVING at the deadline.
        serving: usize,
        /// Replicas of the client.
        replicas: usize,
        /// Replicas that had to be SERVING.
        quorum: usize,
        /// How long the client waited.
        timeout: Duration,
    },
    /// A TLS setting is unusable (e.g. a PEM file without a certificate or key).
    #[error("TLS {what}: {reason}")]
    Tls {
        /// Which setting: "CA certificate", "client certificate", "client key" or "configuration".
        what: &'static str,
        /// What is wrong with it.
        reason: String,
    },
    /// The bearer token cannot be sent as gRPC metadata.
    #[error("bearer token is not a valid header value (printable ASCII only, no line breaks)")]
    InvalidToken,
}

impl From<tonic::Status> for ClientError {
    fn from(status: tonic::Status) -> Self {
        ClientError::Status(status)
    }
}

impl ClientError {
    /// The gRPC status code, if the server answered with one.
    pub fn code(&self) -> Option<tonic::Code> {
        match self {
            ClientError::Status(status) => Some(status.code()),
            _ => None,
        }
    }
}

/// `Code: message`, with the causes of transport failures (e.g. a refused client certificate) appended.
pub(crate) fn status_text(status: &tonic::Status) -> String {
    let mut text = format!("{:?}: {}", status.code(), status.message());
    if let Some(source) = std::error::Error::source(status) {
        text += &format!(" ({})", error_chain(source));
    }
    text
}

/// An error and its sources, `: `-separated (tonic's transport errors hide the useful part in the sources).
fn error_chain(error: &dyn std::error::Error) -> String {
    let mut text = error.to_string();
    let mut source = error.source();
    while let Some(cause) = source {
        text += &format!(": {cause}");
        source = cause.source();
    }
    text
}

/// The settings of one replica's connection; `server_name`: the host name its certificate is verified
/// against, when the endpoint is an address resolved from it.
fn endpoint_builder(
    endpoint: &str,
    server_name: Option<String>,
    options: &ClientOptions,
) -> Result<Endpoint, ClientError> {
    let invalid = |reason: String| ClientError::InvalidEndpoint { endpoint: endpoint.into(), reason };
    let mut builder = Endpoint::from_shared(endpoint.to_string())
        .map_err(|e| invalid(e.to_string()))?
        .connect_timeout(options.connect_timeout)
        .tcp_nodelay(true);
    let https = builder.uri().scheme_str() == Some("https");
    match &options.tls {
        Some(tls) => {
            if !https {
                return Err(invalid("TLS is configured: the address must start with https://".into()));
            }
            let mut config = tls.config()?;
            if let (None, Some(name)) = (&tls.domain, server_name) {
                config = config.domain_name(name);
            }
            builder = builder
                .tls_config(config)
                .map_err(|e| ClientError::Tls { what: "configuration", reason: error_chain(&e) })?;
        }
        None if https => return Err(invalid("an https:// address needs TLS settings (a CA certificate)".into())),
        None => {}
    }
    Ok(builder)
}

/// `ModelRef` for `name` at `version` (0 = latest).
pub fn model_ref(name: &str, version: u32) -> pb::ModelRef {
    pb::ModelRef { name: name.into(), version }
}

/// A connection to a server, or to the replicas of one (round-robin, call by call); cheap to clone.
///
/// Idempotent calls that find a replica gone (`UNAVAILABLE`) are made again on the next one, each replica at
/// most once; admin calls go to one replica and are not repeated; `Track` streams move to another replica
/// when theirs goes away ([`TrackStream`]).
#[derive(Debug, Clone)]
pub struct FastrackClient {
    replicas: Arc<replicas::Replicas>,
    request_timeout: Duration,
    /// `Bearer <token>`, sent as `authorization` on every call.
    authorization: Option<AsciiMetadataValue>,
}

impl FastrackClient {
    /// Connects to `address`: one endpoint (e.g. `http://127.0.0.1:50051`, or `https://...` with
    /// `options.tls`), several separated by commas, or one whose host name resolves to several addresses
    /// (e.g. a Kubernetes headless Service); each address is a replica. Succeeds when at least one replica
    /// answers; the others are connected when they come up.
    pub async fn connect(address: &str, options: ClientOptions) -> Result<Self, ClientError> {
        let authorization = options
            .bearer_token
            .as_ref()
            .map(|token| format!("Bearer {token}").parse::<AsciiMetadataValue>().map_err(|_| ClientError::InvalidToken))
            .transpose()?;
        let mut builders = Vec::new();
        for (endpoint, server_name) in replicas::resolve(address).await? {
            let builder = endpoint_builder(&endpoint, server_name, &options)?;
            builders.push((endpoint, builder));
        }
        let replicas = replicas::connect_all(builders).await?;
        Ok(Self { replicas: Arc::new(replicas), request_timeout: options.request_timeout, authorization })
    }

    /// The endpoints of the replicas, in round-robin order.
    pub fn endpoints(&self) -> Vec<&str> {
        self.replicas.endpoints()
    }

    /// The same connection with another per-call deadline.
    pub fn with_deadline(&self, deadline: Duration) -> Self {
        Self {
            replicas: Arc::clone(&self.replicas),
            request_timeout: deadline,
            authorization: self.authorization.clone(),
        }
    }

    /// A request carrying the bearer token, without deadline.
    pub(crate) fn authorized<T>(&self, message: T) -> tonic::Request<T> {
        let mut request = tonic::Request::new(message);
        if let Some(value) = &self.authorization {
            request.metadata_mut().insert("authorization", value.clone());
        }
        request
    }

    /// A unary request: bearer token and deadline.
    fn request<T>(&self, message: T) -> tonic::Request<T> {
        let mut request = self.authorized(message);
        request.set_timeout(self.request_timeout);
        request
    }

    /// An idempotent unary call: on the next replica, and again on the following ones while they are gone
    /// (`UNAVAILABLE`, a failed connection, or no answer within the deadline; each replica at most once).
    async fn idempotent<M, R, F, Fut>(&self, message: M, call: F) -> Result<R, ClientError>
    where
        M: Clone,
        F: Fn(Channel, tonic::Request<M>) -> Fut,
        Fut: Future<Output = Result<tonic::Response<R>, tonic::Status>>,
    {
        let (mut last, mut message, count) = (None, Some(message), self.replicas.count());
        for (k, replica) in self.replicas.rotation().enumerate() {
            // Every replica but the last gets a copy (the batch may be needed again); with one, none is made.
            let Some(attempt) = (if k + 1 < count { message.clone() } else { message.take() }) else { break };
            match call(replica.channel.clone(), self.request(attempt)).await {
                Ok(response) => return Ok(response.into_inner()),
                Err(status) if replicas::replica_lost(&status) => last = Some(status),
                Err(status) => return Err(status.into()),
            }
        }
        Err(last.unwrap_or_else(|| tonic::Status::unavailable("no replica")).into())
    }

    /// Overall health (`grpc.health.v1`, service "") of the next replica.
    pub async fn health(&self) -> Result<HealthStatus, ClientError> {
        let request = self.request(tonic_health::pb::HealthCheckRequest { service: String::new() });
        let response = HealthClient::new(self.replicas.next().channel.clone()).check(request).await?;
        Ok(response.into_inner().status())
    }

    /// Polls every replica's health until all of them are SERVING, or `timeout` (a fleet that starts once
    /// this returns spreads its streams over every replica).
    pub async fn wait_until_serving(&self, timeout: Duration) -> Result<(), ClientError> {
        self.wait_until_quorum(self.replicas.count(), timeout).await
    }

    /// Polls every replica's health until at least `quorum` of them (clamped to 1 ..= the number of
    /// replicas) are SERVING, or `timeout`.
    pub async fn wait_until_quorum(&self, quorum: usize, timeout: Duration) -> Result<(), ClientError> {
        let replicas = self.replicas.count();
        let quorum = quorum.clamp(1, replicas);
        let start = std::time::Instant::now();
        loop {
            let serving = self.serving_replicas().await.len();
            if serving >= quorum {
                return Ok(());
            }
            if start.elapsed() > timeout {
                return Err(ClientError::NotReady { serving, replicas, quorum, timeout });
            }
            tokio::time::sleep(Duration::from_millis(50)).await;
        }
    }

    /// The endpoints of the replicas whose health is SERVING now (each asked once, within the request
    /// timeout).
    pub async fn serving_replicas(&self) -> Vec<String> {
        let mut serving = Vec::new();
        for replica in self.replicas.rotation() {
            let request = self.request(tonic_health::pb::HealthCheckRequest { service: String::new() });
            let mut health = HealthClient::new(replica.channel.clone());
            if let Ok(Ok(reply)) = tokio::time::timeout(self.request_timeout, health.check(request)).await {
                if reply.into_inner().status() == HealthStatus::Serving {
                    serving.push(replica.endpoint.clone());
                }
            }
        }
        serving
    }

    /// The client's open `Track` streams on each replica, in the order of [`FastrackClient::endpoints`].
    pub fn stream_counts(&self) -> Vec<usize> {
        self.replicas.stream_counts()
    }

    /// Every loaded model version.
    pub async fn list_models(&self) -> Result<Vec<pb::ModelInfo>, ClientError> {
        let call = |channel, request| async move { ModelServiceClient::new(channel).list_models(request).await };
        Ok(self.idempotent(pb::ListModelsRequest {}, call).await?.models)
    }

    /// One model version's description.
    pub async fn get_model(&self, model: pb::ModelRef) -> Result<pb::ModelInfo, ClientError> {
        let call = |channel, request| async move { ModelServiceClient::new(channel).get_model(request).await };
        let response = self.idempotent(pb::GetModelRequest { model: Some(model) }, call).await?;
        response.model.ok_or_else(|| tonic::Status::internal("GetModel answered without a model").into())
    }

    /// queryPlannerControl: the fastest planner speed bound whose TEB fits `d_obs / 2`.
    pub async fn query_planner_control(
        &self,
        model: pb::ModelRef,
        d_obs: Option<f64>,
    ) -> Result<pb::QueryPlannerControlResponse, ClientError> {
        self.planner_speed(pb::QueryPlannerControlRequest { model: Some(model), d_obs, planner_clearance: None }).await
    }

    /// The planner rule: the fastest planner speed bound whose TEB is less than `planner_clearance`, the
    /// planner's distance to the nearest sensed obstacle less the farthest one control period can move it.
    pub async fn query_planner_rule(
        &self,
        model: pb::ModelRef,
        planner_clearance: f64,
    ) -> Result<pb::QueryPlannerControlResponse, ClientError> {
        let planner_clearance = Some(planner_clearance);
        self.planner_speed(pb::QueryPlannerControlRequest { model: Some(model), d_obs: None, planner_clearance }).await
    }

    async fn planner_speed(
        &self,
        request: pb::QueryPlannerControlRequest,
    ) -> Result<pb::QueryPlannerControlResponse, ClientError> {
        let call =
            |channel, request| async move { SafetyServiceClient::new(channel).query_planner_control(request).await };
        self.idempotent(request, call).await
    }

    /// The TEB at `beta`, with `boundary_points` boundary points (0 for none).
    pub async fn tracking_error_bound(
        &self,
        model: pb::ModelRef,
        beta: f64,
        boundary_points: u32,
    ) -> Result<pb::GetTrackingErrorBoundResponse, ClientError> {
        let message = pb::GetTrackingErrorBoundRequest { model: Some(model), beta, boundary_points };
        let call =
            |channel, request| async move { SafetyServiceClient::new(channel).get_tracking_error_bound(request).await };
        self.idempotent(message, call).await
    }

    /// `V`, `dV/dr`, `u*` and flags for a batch (`states` `[N x n_state]`, `params` `[N x n_params]`).
    pub async fn evaluate_value(
        &self,
        model: pb::ModelRef,
        states: Vec<f64>,
        params: Vec<f64>,
        out_of_domain: pb::OutOfDomainPolicy,
    ) -> Result<pb::EvaluateValueResponse, ClientError> {
        let message =
            pb::EvaluateValueRequest { model: Some(model), states, params, out_of_domain: out_of_domain as i32 };
        let call = |channel, request| async move { SafetyServiceClient::new(channel).evaluate_value(request).await };
        self.idempotent(message, call).await
    }

    /// Optimal tracking control for a batch.
    pub async fn tracking_control(
        &self,
        model: pb::ModelRef,
        states: Vec<f64>,
        params: Vec<f64>,
        out_of_domain: pb::OutOfDomainPolicy,
    ) -> Result<pb::TrackingControlResponse, ClientError> {
        let message =
            pb::TrackingControlRequest { model: Some(model), states, params, out_of_domain: out_of_domain as i32 };
        let call = |channel, request| async move { SafetyServiceClient::new(channel).tracking_control(request).await };
        self.idempotent(message, call).await
    }

    /// Opens a `Track` stream on the next replica (no deadline: it lives as long as the robot runs).
    pub async fn track(&self, model: pb::ModelRef, idle_timeout_s: f64) -> Result<TrackStream, ClientError> {
        TrackStream::open(self, pb::TrackOpen { model: Some(model), idle_timeout_s }).await
    }

    /// The admin service of the next replica: admin calls change one replica's repository.
    fn admin(&self) -> ModelAdminServiceClient<Channel> {
        ModelAdminServiceClient::new(self.replicas.next().channel.clone())
    }

    /// Loads a model (version 0: every version on disk).
    pub async fn load_model(&self, name: &str, version: u32) -> Result<Vec<u32>, ClientError> {
        let request = self.request(pb::LoadModelRequest { name: name.into(), version });
        Ok(self.admin().load_model(request).await?.into_inner().loaded_versions)
    }

    /// Unloads a model (version 0: every version).
    pub async fn unload_model(&self, name: &str, version: u32) -> Result<Vec<u32>, ClientError> {
        let request = self.request(pb::UnloadModelRequest { name: name.into(), version });
        Ok(self.admin().unload_model(request).await?.into_inner().unloaded_versions)
    }

    /// Re-reads a model (empty name: the whole repository) from disk.
    pub async fn reload_model(&self, name: &str) -> Result<Vec<pb::ReloadOutcome>, ClientError> {
        let request = self.request(pb::ReloadModelRequest { name: name.into() });
        Ok(self.admin().reload_model(request).await?.into_inner().outcomes)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rcgen::{BasicConstraints, CertificateParams, CertifiedIssuer, IsCa, KeyPair};
    use tonic::service::interceptor::InterceptedService;
    use tonic::transport::server::TcpIncoming;
    use tonic::transport::{Server, ServerTlsConfig};

    /// A CA, a server certificate for "localhost" and a client certificate, all PEM.
    struct Pki {
        ca: String,
        server: (String, String),
        client: (String, String),
    }

    fn pki() -> Pki {
        let mut ca_params = CertificateParams::new(Vec::<String>::new()).unwrap();
        ca_params.is_ca = IsCa::Ca(BasicConstraints::Unconstrained);
        let ca = CertifiedIssuer::self_signed(ca_params, KeyPair::generate().unwrap()).unwrap();
        let leaf = |name: &str| {
            let key = KeyPair::generate().unwrap();
            let cert = CertificateParams::new(vec![name.to_string()]).unwrap().signed_by(&key, &*ca).unwrap();
            (cert.pem(), key.serialize_pem())
        };
        Pki { ca: ca.pem(), server: leaf("localhost"), client: leaf("robot") }
    }

    /// A health server with TLS (mutual if `client_ca`) that requires `authorization: Bearer secret`;
    /// returns its `https://127.0.0.1:<port>` address.
    async fn tls_server(pki: &Pki, client_ca: bool) -> String {
        let listener = tokio::net::TcpListener::bind("127.0.0.1:0").await.unwrap();
        let port = listener.local_addr().unwrap().port();
        let mut tls = ServerTlsConfig::new().identity(Identity::from_pem(&pki.server.0, &pki.server.1));
        if client_ca {
            tls = tls.client_ca_root(Certificate::from_pem(&pki.ca));
        }
        let (_, health) = tonic_health::server::health_reporter();
        let check = |request: tonic::Request<()>| match request.metadata().get("authorization") {
            Some(value) if value == "Bearer secret" => Ok(request),
            _ => Err(tonic::Status::unauthenticated("missing or wrong bearer token")),
        };
        let router = Server::builder().tls_config(tls).unwrap().add_service(InterceptedService::new(health, check));
        tokio::spawn(router.serve_with_incoming(TcpIncoming::from(listener)));
        format!("https://127.0.0.1:{port}")
    }

    fn options(pki: &Pki, token: Option<&str>, identity: bool) -> ClientOptions {
        ClientOptions {
            bearer_token: token.map(Into::into),
            tls: Some(ClientTls {
                ca_pem: pki.ca.clone().into_bytes(),
                identity: identity.then(|| (pki.client.0.clone().into_bytes(), pki.client.1.clone().into_bytes())),
                domain: Some("localhost".into()),
            }),
            ..Default::default()
        }
    }

    /// Connects and checks health; any failure (connection or status) as an error.
    async fn health(endpoint: &str, options: ClientOptions) -> Result<HealthStatus, ClientError> {
        FastrackClient::connect(endpoint, options).await?.health().await
    }

    #[tokio::test]
    async fn tls_with_bearer_token() {
        let pki = pki();
        let endpoint = tls_server(&pki, false).await;
        assert_eq!(health(&endpoint, options(&pki, Some("secret"), false)).await.unwrap(), HealthStatus::Serving);
        let missing = health(&endpoint, options(&pki, None, false)).await.unwrap_err();
        assert_eq!(missing.code(), Some(tonic::Code::Unauthenticated), "{missing}");
        let wrong = health(&endpoint, options(&pki, Some("guess"), false)).await.unwrap_err();
        assert_eq!(wrong.code(), Some(tonic::Code::Unauthenticated), "{wrong}");
        // A server certificate from another CA is refused.
        let mut other = options(&pki, Some("secret"), false);
        other.tls.as_mut().unwrap().ca_pem = self::pki().ca.into_bytes();
        assert!(health(&endpoint, other).await.is_err());
    }

    #[tokio::test]
    async fn mutual_tls_needs_the_client_certificate() {
        let pki = pki();
        let endpoint = tls_server(&pki, true).await;
        assert_eq!(health(&endpoint, options(&pki, Some("secret"), true)).await.unwrap(), HealthStatus::Serving);
        assert!(health(&endpoint, options(&pki, Some("secret"), false)).await.is_err());
    }

    #[tokio::test]
    async fn unusable_settings_are_named() {
        let pki = pki();
        let endpoint = "https://127.0.0.1:9";
        let mut bad_ca = options(&pki, None, true);
        bad_ca.tls.as_mut().unwrap().ca_pem = b"not a certificate".to_vec();
        let error = FastrackClient::connect(endpoint, bad_ca).await.unwrap_err();
        assert!(matches!(error, ClientError::Tls { what: "CA certificate", .. }), "{error}");
        let mut bad_key = options(&pki, None, true);
        bad_key.tls.as_mut().unwrap().identity.as_mut().unwrap().1 = pki.client.0.clone().into_bytes();
        let error = FastrackClient::connect(endpoint, bad_key).await.unwrap_err();
        assert!(matches!(error, ClientError::Tls { what: "client key", .. }), "{error}");
        let error = FastrackClient::connect("http://127.0.0.1:9", options(&pki, None, false)).await.unwrap_err();
        assert!(matches!(error, ClientError::InvalidEndpoint { .. }), "{error}");
        let error = FastrackClient::connect(endpoint, ClientOptions::default()).await.unwrap_err();
        assert!(matches!(error, ClientError::InvalidEndpoint { .. }), "{error}");
        let token = ClientOptions { bearer_token: Some("a\nb".into()), ..Default::default() };
        let error = FastrackClient::connect("http://127.0.0.1:9", token).await.unwrap_err();
        assert!(matches!(error, ClientError::InvalidToken), "{error}");
        assert!(!format!("{:?}", options(&pki, Some("secret"), true)).contains("secret"));
    }
}
