//! `Track` streams that survive the loss of a replica.
//!
//! A stream remembers the ticks it sent and that are not answered yet. When its server goes away (the stream
//! ends with `UNAVAILABLE`, as a draining replica's streams do; its connection breaks, as a killed replica's
//! does; it closes with ticks unanswered; or it leaves a tick unanswered past the client's request deadline,
//! as a frozen one does), it reopens on the client's next replica and sends those ticks again, so every tick
//! is answered exactly once as seen by the robot. A stream that every replica in turn takes and loses without
//! answering gives up. Nothing else needs carrying over: a reply depends on its tick
//! alone, and the bound in force (`beta_old`) is the robot's own loop's.
//!
//! For the same reason a stream can move when nothing is lost: at most once every [`BALANCE_EVERY`], a
//! stream on a replica holding at least two more of the client's streams than another opens a second stream
//! there in the background, and moves to it at its next tick with every earlier tick answered; so streams
//! spread evenly over the replicas that serve, and come back to one that returns, and the robot never waits
//! for the move (a replica that refuses or does not answer is simply not moved to).

use crate::replicas::{replica_lost, PlannedMove};
use crate::{pb, ClientError, FastrackClient};
use std::collections::VecDeque;
use std::time::{Duration, Instant};
use tokio_stream::wrappers::ReceiverStream;

/// Ticks buffered between the robot and the connection.
const SEND_BUFFER: usize = 64;
/// Least time between two looks of a stream at the balance of the replicas.
pub const BALANCE_EVERY: Duration = Duration::from_secs(1);

/// An open `Track` stream: send ticks, read replies in order.
pub struct TrackStream {
    client: FastrackClient,
    open: pb::TrackOpen,
    /// The replica serving it (an index into the client's replicas).
    replica: usize,
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
    rebalanced: usize,
    balance_checked: Instant,
    /// A stream being opened on a lighter replica, for the next move, and the move it makes.
    pending_move: Option<(PlannedMove, tokio::task::JoinHandle<Result<Opened, Refusal>>)>,
}

/// A stream on one replica.
struct Opened {
    replica: usize,
    ticks: tokio::sync::mpsc::Sender<pb::TrackRequest>,
    replies: tonic::Streaming<pb::TrackResponse>,
}

/// Why a replica did not open a stream.
enum Refusal {
    /// It is gone, full or silent: another may take the stream.
    PassOn(tonic::Status),
    /// It refused the stream itself (e.g. an unknown model): no replica will take it.
    Final(tonic::Status),
}

impl TrackStream {
    /// Opens a stream for `open` on the client's next replica that takes it within the client's deadline (each
    /// replica tried once).
    pub(crate) async fn open(client: &FastrackClient, open: pb::TrackOpen) -> Result<Self, ClientError> {
        let opened = Self::open_somewhere(client, &open).await?;
        client.replicas.stream_opened(opened.replica);
        Ok(Self {
            client: client.clone(),
            open,
            replica: opened.replica,
            ticks: opened.ticks,
            replies: opened.replies,
            unanswered: VecDeque::new(),
            lost: false,
            moves_unanswered: 0,
            reopened: 0,
            resent: 0,
            rebalanced: 0,
            balance_checked: Instant::now(),
            pending_move: None,
        })
    }

    async fn open_somewhere(client: &FastrackClient, open: &pb::TrackOpen) -> Result<Opened, ClientError> {
        let mut last = None;
        for (index, _) in client.replicas.indexed_rotation() {
            match Self::open_on(client, index, open).await {
                Ok(opened) => return Ok(opened),
                Err(Refusal::PassOn(status)) => last = Some(status),
                Err(Refusal::Final(status)) => return Err(status.into()),
            }
        }
        Err(last.unwrap_or_else(|| tonic::Status::unavailable("no replica to open a Track stream on")).into())
    }

    async fn open_on(client: &FastrackClient, index: usize, open: &pb::TrackOpen) -> Result<Opened, Refusal> {
        let replica = client.replicas.get(index);
        let (tx, rx) = tokio::sync::mpsc::channel(SEND_BUFFER);
        let message = pb::TrackRequest { msg: Some(pb::track_request::Msg::Open(open.clone())) };
        if tx.send(message).await.is_err() {
            return Err(Refusal::Final(tonic::Status::internal("stream closed before its open message")));
        }
        let mut service = pb::safety_service_client::SafetyServiceClient::new(replica.channel.clone());
        let call = service.track(client.authorized(ReceiverStream::new(rx)));
        // A replica that takes the connection but never answers is as good as gone.
        match tokio::time::timeout(client.request_timeout, call).await {
            Ok(Ok(response)) => Ok(Opened { replica: index, ticks: tx, replies: response.into_inner() }),
            // A replica that is gone, or that holds all the streams it allows: try the next.
            Ok(Err(status)) if replica_lost(&status) || status.code() == tonic::Code::ResourceExhausted => {
                client.replicas.refused(index);
                Err(Refusal::PassOn(status))
            }
            Ok(Err(status)) => Err(Refusal::Final(status)),
            Err(_) => {
                client.replicas.refused(index);
                Err(Refusal::PassOn(tonic::Status::unavailable(format!(
                    "{} did not open the stream within {:?}",
                    replica.endpoint, client.request_timeout
                ))))
            }
        }
    }

    /// Serves the stream from `opened` from now on, counting the move in the client's balance.
    fn move_to(&mut self, opened: Opened) {
        self.client.replicas.stream_closed(self.replica);
        self.client.replicas.stream_opened(opened.replica);
        (self.replica, self.ticks, self.replies) = (opened.replica, opened.ticks, opened.replies);
    }

    /// With every tick answered: moves to the stream opened in the background, if it is open; else, at most
    /// once every [`BALANCE_EVERY`], starts opening one on a replica with at least two fewer of the client's
    /// streams.
    async fn balance(&mut self) {
        if !self.unanswered.is_empty() {
            return;
        }
        if let Some((_planned, pending)) = self.pending_move.take_if(|(_, task)| task.is_finished()) {
            // Finished: awaiting it does not wait. The plan leaves the balance after the move is counted.
            if let Ok(Ok(opened)) = pending.await {
                self.move_to(opened);
                self.rebalanced += 1;
            }
            return;
        }
        if self.pending_move.is_some() || self.balance_checked.elapsed() < BALANCE_EVERY {
            return;
        }
        self.balance_checked = Instant::now();
        if let Some(planned) = self.client.replicas.plan_move(self.replica) {
            let (client, open, lighter) = (self.client.clone(), self.open.clone(), planned.to);
            let task = tokio::spawn(async move { Self::open_on(&client, lighter, &open).await });
            self.pending_move = Some((planned, task));
        }
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
        self.move_to(opened);
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
        if !self.lost {
            self.balance().await;
        }
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
            // A replica that leaves a tick unanswered past the client's deadline is as good as gone.
            let deadline = self.client.request_timeout;
            let next = if self.unanswered.is_empty() {
                Ok(self.replies.message().await)
            } else {
                tokio::time::timeout(deadline, self.replies.message()).await
            };
            let Ok(next) = next else {
                self.reopen(&format!("no reply within {deadline:?}")).await?;
                continue;
            };
            match next {
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
        &self.client.replicas.get(self.replica).endpoint
    }

    /// How often the stream moved to another replica.
    pub fn reopened(&self) -> usize {
        self.reopened
    }

    /// Ticks sent again after a move, because their first replica never answered them.
    pub fn resent(&self) -> usize {
        self.resent
    }

    /// How often the stream moved, with nothing lost, to even the load over the replicas.
    pub fn rebalanced(&self) -> usize {
        self.rebalanced
    }
}

impl Drop for TrackStream {
    fn drop(&mut self) {
        self.client.replicas.stream_closed(self.replica);
        if let Some((_planned, pending)) = self.pending_move.take() {
            pending.abort();
        }
    }
}
