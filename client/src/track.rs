//! `Track` streams that survive the loss of a replica.
//!
//! A stream remembers the ticks it sent and that are not answered yet. When its server goes away (the stream
//! ends with `UNAVAILABLE`, as a draining replica's streams do; its connection breaks, as a killed replica's
//! does; or it closes with ticks unanswered), it reopens on the client's next replica and sends those ticks
//! again, so every tick is answered exactly once as seen by the robot. A stream that every replica in turn
//! takes and loses without answering gives up. Nothing else needs carrying over: a reply depends on its tick
//! alone, and the bound in force (`beta_old`) is the robot's own loop's.

use crate::replicas::replica_lost;
use crate::{pb, ClientError, FastrackClient};
use std::collections::VecDeque;
use tokio_stream::wrappers::ReceiverStream;

/// Ticks buffered between the robot and the connection.
const SEND_BUFFER: usize = 64;

/// An open `Track` stream: send ticks, read replies in order.
pub struct TrackStream {
    client: FastrackClient,
    open: pb::TrackOpen,
    endpoint: String,
    ticks: tokio::sync::mpsc::Sender<pb::TrackRequest>,
    replies: tonic::Streaming<pb::TrackResponse>,
    /// Sent and not answered yet, oldest first.
    unanswered: VecDeque<pb::TrackTick>,
    /// The replica went away with nothing unanswered: the next send reopens.
    lost: bool,
    /// Moves since the last reply.
    moves_unanswered: usize,
    reopened: usize,
    resent: usize,
}

/// A stream on one replica.
struct Opened {
    endpoint: String,
    ticks: tokio::sync::mpsc::Sender<pb::TrackRequest>,
    replies: tonic::Streaming<pb::TrackResponse>,
}

impl TrackStream {
    /// Opens a stream for `open` on the client's next replica that takes it within the client's deadline (each
    /// replica tried once).
    pub(crate) async fn open(client: &FastrackClient, open: pb::TrackOpen) -> Result<Self, ClientError> {
        let opened = Self::open_somewhere(client, &open).await?;
        Ok(Self {
            client: client.clone(),
            open,
            endpoint: opened.endpoint,
            ticks: opened.ticks,
            replies: opened.replies,
            unanswered: VecDeque::new(),
            lost: false,
            moves_unanswered: 0,
            reopened: 0,
            resent: 0,
        })
    }

    async fn open_somewhere(client: &FastrackClient, open: &pb::TrackOpen) -> Result<Opened, ClientError> {
        let mut last = None;
        for replica in client.replicas.rotation() {
            let (tx, rx) = tokio::sync::mpsc::channel(SEND_BUFFER);
            let message = pb::TrackRequest { msg: Some(pb::track_request::Msg::Open(open.clone())) };
            tx.send(message).await.map_err(|_| tonic::Status::internal("stream closed before its open message"))?;
            let mut service = pb::safety_service_client::SafetyServiceClient::new(replica.channel.clone());
            let call = service.track(client.authorized(ReceiverStream::new(rx)));
            // A replica that takes the connection but never answers is as good as gone.
            match tokio::time::timeout(client.request_timeout, call).await {
                Ok(Ok(response)) => {
                    return Ok(Opened { endpoint: replica.endpoint.clone(), ticks: tx, replies: response.into_inner() })
                }
                // A replica that is gone, or that holds all the streams it allows: try the next.
                Ok(Err(status)) if replica_lost(&status) || status.code() == tonic::Code::ResourceExhausted => {
                    last = Some(status)
                }
                Ok(Err(status)) => return Err(status.into()),
                Err(_) => {
                    last = Some(tonic::Status::unavailable(format!(
                        "{} did not open the stream within {:?}",
                        replica.endpoint, client.request_timeout
                    )))
                }
            }
        }
        Err(last.unwrap_or_else(|| tonic::Status::unavailable("no replica to open a Track stream on")).into())
    }

    /// Reopens on another replica, after `why` ended the stream, and sends the unanswered ticks again.
    async fn reopen(&mut self, why: &str) -> Result<(), ClientError> {
        if self.moves_unanswered >= self.client.replicas.count() {
            return Err(ClientError::Status(tonic::Status::unavailable(format!(
                "{why}; the stream moved {} times without an answer: every replica lost it",
                self.moves_unanswered
            ))));
        }
        self.moves_unanswered += 1;
        let opened = Self::open_somewhere(&self.client, &self.open).await.map_err(|e| {
            ClientError::Status(tonic::Status::unavailable(format!("{why}; no replica took the stream again: {e}")))
        })?;
        (self.endpoint, self.ticks, self.replies) = (opened.endpoint, opened.ticks, opened.replies);
        self.lost = false;
        self.reopened += 1;
        for tick in &self.unanswered {
            let request = pb::TrackRequest { msg: Some(pb::track_request::Msg::Tick(tick.clone())) };
            self.ticks.send(request).await.map_err(|_| tonic::Status::unavailable("Track stream closed"))?;
        }
        self.resent += self.unanswered.len();
        Ok(())
    }

    /// Sends one tick without waiting for its reply.
    pub async fn send(&mut self, tick: pb::TrackTick) -> Result<(), ClientError> {
        self.unanswered.push_back(tick.clone());
        if self.lost {
            return self.reopen("the stream's replica went away").await;
        }
        let request = pb::TrackRequest { msg: Some(pb::track_request::Msg::Tick(tick)) };
        if self.ticks.send(request).await.is_err() {
            // The connection dropped the stream: go on elsewhere, this tick with the others unanswered.
            self.reopen("the stream's connection closed").await?;
        }
        Ok(())
    }

    /// The next reply (`None` when the server closed the stream with every tick answered). A replica that
    /// goes away with ticks unanswered is replaced and they are answered; one that goes away with none is
    /// reported here, and the next send reopens the stream elsewhere.
    pub async fn recv(&mut self) -> Result<Option<pb::TrackReply>, ClientError> {
        loop {
            match self.replies.message().await {
                Ok(Some(response)) => {
                    self.unanswered.pop_front();
                    self.moves_unanswered = 0;
                    return Ok(response.reply);
                }
                Ok(None) if self.unanswered.is_empty() => return Ok(None),
                Ok(None) => self.reopen("the server closed the stream with ticks unanswered").await?,
                Err(status) if replica_lost(&status) && self.unanswered.is_empty() => {
                    self.lost = true;
                    return Err(status.into());
                }
                Err(status) if replica_lost(&status) => self.reopen(&crate::status_text(&status)).await?,
                Err(status) => return Err(status.into()),
            }
        }
    }

    /// Sends a tick and waits for its reply.
    pub async fn tick(&mut self, tick: pb::TrackTick) -> Result<pb::TrackReply, ClientError> {
        self.send(tick).await?;
        self.recv().await?.ok_or_else(|| tonic::Status::unavailable("Track stream closed by the server").into())
    }

    /// The endpoint of the replica serving the stream now.
    pub fn endpoint(&self) -> &str {
        &self.endpoint
    }

    /// How often the stream moved to another replica.
    pub fn reopened(&self) -> usize {
        self.reopened
    }

    /// Ticks sent again after a move, because their first replica never answered them.
    pub fn resent(&self) -> usize {
        self.resent
    }
}
