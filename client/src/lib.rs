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

pub use fastrack_proto::v1 as pb;

use pb::model_admin_service_client::ModelAdminServiceClient;
use pb::model_service_client::ModelServiceClient;
use pb::safety_service_client::SafetyServiceClient;
use std::time::Duration;
use tokio_stream::wrappers::ReceiverStream;
use tonic::transport::{Channel, Endpoint};
pub use tonic_health::pb::health_check_response::ServingStatus as HealthStatus;
use tonic_health::pb::health_client::HealthClient;

/// Connection settings.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ClientOptions {
    /// Limit on establishing the connection.
    pub connect_timeout: Duration,
    /// Deadline of each unary call (sent to the server as `grpc-timeout`).
    pub request_timeout: Duration,
}

impl Default for ClientOptions {
    fn default() -> Self {
        Self { connect_timeout: Duration::from_secs(5), request_timeout: Duration::from_secs(5) }
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
    /// The server answered with an error status.
    #[error("{:?}: {}", .0.code(), .0.message())]
    Status(tonic::Status),
    /// The server did not become ready in time.
    #[error("server not SERVING after {0:?}")]
    NotReady(Duration),
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

/// `ModelRef` for `name` at `version` (0 = latest).
pub fn model_ref(name: &str, version: u32) -> pb::ModelRef {
    pb::ModelRef { name: name.into(), version }
}

/// A connection to one server; cheap to clone.
#[derive(Debug, Clone)]
pub struct FastrackClient {
    channel: Channel,
    request_timeout: Duration,
}

impl FastrackClient {
    /// Connects to `endpoint` (e.g. `http://127.0.0.1:50051`).
    pub async fn connect(endpoint: &str, options: ClientOptions) -> Result<Self, ClientError> {
        let invalid = |reason: String| ClientError::InvalidEndpoint { endpoint: endpoint.into(), reason };
        let channel = Endpoint::from_shared(endpoint.to_string())
            .map_err(|e| invalid(e.to_string()))?
            .connect_timeout(options.connect_timeout)
            .tcp_nodelay(true)
            .connect()
            .await
            .map_err(|source| ClientError::Connect { endpoint: endpoint.into(), source })?;
        Ok(Self { channel, request_timeout: options.request_timeout })
    }

    /// The same connection with another per-call deadline.
    pub fn with_deadline(&self, deadline: Duration) -> Self {
        Self { channel: self.channel.clone(), request_timeout: deadline }
    }

    fn request<T>(&self, message: T) -> tonic::Request<T> {
        let mut request = tonic::Request::new(message);
        request.set_timeout(self.request_timeout);
        request
    }

    fn safety(&self) -> SafetyServiceClient<Channel> {
        SafetyServiceClient::new(self.channel.clone())
    }

    /// Overall health (`grpc.health.v1`, service "").
    pub async fn health(&self) -> Result<HealthStatus, ClientError> {
        let request = self.request(tonic_health::pb::HealthCheckRequest { service: String::new() });
        let response = HealthClient::new(self.channel.clone()).check(request).await?;
        Ok(response.into_inner().status())
    }

    /// Polls health until SERVING or `timeout`.
    pub async fn wait_until_serving(&self, timeout: Duration) -> Result<(), ClientError> {
        let start = std::time::Instant::now();
        loop {
            if matches!(self.health().await, Ok(HealthStatus::Serving)) {
                return Ok(());
            }
            if start.elapsed() > timeout {
                return Err(ClientError::NotReady(timeout));
            }
            tokio::time::sleep(Duration::from_millis(50)).await;
        }
    }

    /// Every loaded model version.
    pub async fn list_models(&self) -> Result<Vec<pb::ModelInfo>, ClientError> {
        let response =
            ModelServiceClient::new(self.channel.clone()).list_models(self.request(pb::ListModelsRequest {})).await?;
        Ok(response.into_inner().models)
    }

    /// One model version's description.
    pub async fn get_model(&self, model: pb::ModelRef) -> Result<pb::ModelInfo, ClientError> {
        let request = self.request(pb::GetModelRequest { model: Some(model) });
        let response = ModelServiceClient::new(self.channel.clone()).get_model(request).await?;
        response.into_inner().model.ok_or_else(|| tonic::Status::internal("GetModel answered without a model").into())
    }

    /// queryPlannerControl: the fastest planner speed bound whose TEB fits `d_obs / 2`.
    pub async fn query_planner_control(
        &self,
        model: pb::ModelRef,
        d_obs: Option<f64>,
    ) -> Result<pb::QueryPlannerControlResponse, ClientError> {
        let request = self.request(pb::QueryPlannerControlRequest { model: Some(model), d_obs });
        Ok(self.safety().query_planner_control(request).await?.into_inner())
    }

    /// The TEB at `beta`, with `boundary_points` boundary points (0 for none).
    pub async fn tracking_error_bound(
        &self,
        model: pb::ModelRef,
        beta: f64,
        boundary_points: u32,
    ) -> Result<pb::GetTrackingErrorBoundResponse, ClientError> {
        let request = self.request(pb::GetTrackingErrorBoundRequest { model: Some(model), beta, boundary_points });
        Ok(self.safety().get_tracking_error_bound(request).await?.into_inner())
    }

    /// `V`, `dV/dr`, `u*` and flags for a batch (`states` `[N x n_state]`, `params` `[N x n_params]`).
    pub async fn evaluate_value(
        &self,
        model: pb::ModelRef,
        states: Vec<f64>,
        params: Vec<f64>,
        out_of_domain: pb::OutOfDomainPolicy,
    ) -> Result<pb::EvaluateValueResponse, ClientError> {
        let request = self.request(pb::EvaluateValueRequest {
            model: Some(model),
            states,
            params,
            out_of_domain: out_of_domain as i32,
        });
        Ok(self.safety().evaluate_value(request).await?.into_inner())
    }

    /// Optimal tracking control for a batch.
    pub async fn tracking_control(
        &self,
        model: pb::ModelRef,
        states: Vec<f64>,
        params: Vec<f64>,
        out_of_domain: pb::OutOfDomainPolicy,
    ) -> Result<pb::TrackingControlResponse, ClientError> {
        let request = self.request(pb::TrackingControlRequest {
            model: Some(model),
            states,
            params,
            out_of_domain: out_of_domain as i32,
        });
        Ok(self.safety().tracking_control(request).await?.into_inner())
    }

    /// Opens a `Track` stream (no deadline: it lives as long as the robot runs).
    pub async fn track(&self, model: pb::ModelRef, idle_timeout_s: f64) -> Result<TrackSession, ClientError> {
        let (tx, rx) = tokio::sync::mpsc::channel(64);
        let open = pb::TrackRequest {
            msg: Some(pb::track_request::Msg::Open(pb::TrackOpen { model: Some(model), idle_timeout_s })),
        };
        tx.send(open).await.map_err(|_| tonic::Status::internal("stream closed"))?;
        let replies = self.safety().track(ReceiverStream::new(rx)).await?.into_inner();
        Ok(TrackSession { ticks: tx, replies })
    }

    fn admin(&self) -> ModelAdminServiceClient<Channel> {
        ModelAdminServiceClient::new(self.channel.clone())
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

/// An open `Track` stream: send ticks, read replies in order.
pub struct TrackSession {
    ticks: tokio::sync::mpsc::Sender<pb::TrackRequest>,
    replies: tonic::Streaming<pb::TrackResponse>,
}

impl TrackSession {
    /// Sends one tick without waiting for its reply.
    pub async fn send(&self, tick: pb::TrackTick) -> Result<(), ClientError> {
        let request = pb::TrackRequest { msg: Some(pb::track_request::Msg::Tick(tick)) };
        self.ticks.send(request).await.map_err(|_| tonic::Status::unavailable("Track stream closed").into())
    }

    /// The next reply (`None` when the server closed the stream).
    pub async fn recv(&mut self) -> Result<Option<pb::TrackReply>, ClientError> {
        Ok(self.replies.message().await?.and_then(|r| r.reply))
    }

    /// Sends a tick and waits for its reply.
    pub async fn tick(&mut self, tick: pb::TrackTick) -> Result<pb::TrackReply, ClientError> {
        self.send(tick).await?;
        self.recv().await?.ok_or_else(|| tonic::Status::unavailable("Track stream closed by the server").into())
    }
}
