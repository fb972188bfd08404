//! The `Track` bidirectional stream: one per robot, answering every tick in order. A reply depends on its
//! tick alone: the stream keeps no state between ticks (the bound in force, `beta_old`, is the robot's), so a
//! stream that moves to another replica is answered exactly as before.
//!
//! What a stream may hold is bounded: the server keeps at most `max_track_streams` streams open at once (a
//! permit taken before `open` is read), a stream's replies wait in a buffer of [`REPLY_BUFFER`] and at most
//! the send timeout for a client that stopped reading, after which the stream is closed, and a stream with no
//! tick for its idle timeout is closed with `DEADLINE_EXCEEDED`.

use crate::loaded_model::{BatchResult, LoadedModel};
use crate::metrics::{code_name, Metrics};
use crate::repository::Repository;
use crate::scheduler::Scheduler;
use crate::validate::{self, ValidBatch};
use fastrack_proto::planner_speed::PlannerSpeed;
use fastrack_proto::v1 as pb;
use pb::track_request::Msg;
use std::sync::Arc;
use std::time::Duration;
use tokio::sync::{OwnedSemaphorePermit, Semaphore};
use tokio_stream::wrappers::ReceiverStream;
use tokio_stream::StreamExt;
use tonic::{Code, Status, Streaming};
use tracing::Instrument;

/// Longest idle timeout a stream may ask for (one day).
pub const MAX_IDLE_TIMEOUT_S: f64 = 86_400.0;

/// Replies a stream buffers for its client.
pub const REPLY_BUFFER: usize = 64;

/// What a stream needs from the server.
pub struct StreamContext {
    /// Model lookup at `open`, and the current copy of the stream's version after a reload.
    pub repository: Arc<Repository>,
    /// The compute pool.
    pub scheduler: Arc<Scheduler>,
    /// Metrics.
    pub metrics: Arc<Metrics>,
    /// Idle timeout when `open` asks for none.
    pub default_idle: Duration,
    /// How long a reply may wait for the client to read it before the stream is closed.
    pub send_timeout: Duration,
    /// Permits for the streams open at once.
    pub streams: Arc<Semaphore>,
    /// Turns true when the server drains: the stream ends with `UNAVAILABLE` after its current tick.
    pub draining: tokio::sync::watch::Receiver<bool>,
}

/// Counts an open stream in the active-streams gauge and holds its permit until dropped, and the stream's
/// final code.
struct StreamGuard {
    metrics: Arc<Metrics>,
    model: String,
    code: Code,
    _permit: OwnedSemaphorePermit,
}

impl Drop for StreamGuard {
    fn drop(&mut self) {
        self.metrics.stream_delta(-1);
        self.metrics.call("Track", &self.model, self.code, None);
        tracing::debug!(model = %self.model, code = code_name(self.code), "track stream closed");
    }
}

/// Reads the opening message, resolves the model (the stream keeps that version for its lifetime, taking up
/// a reloaded copy of it at its next tick) and spawns the tick loop. Errors before the first tick end the
/// call with their status.
pub async fn open(
    context: StreamContext,
    mut inbound: Streaming<pb::TrackRequest>,
) -> Result<ReceiverStream<Result<pb::TrackResponse, Status>>, Status> {
    let default_idle = context.default_idle;
    let Ok(permit) = Arc::clone(&context.streams).try_acquire_owned() else {
        let status = Status::resource_exhausted(
            "the server holds as many Track streams as it allows (max_track_streams); retry later or on another replica",
        );
        context.metrics.call("Track", "-", status.code(), None);
        return Err(status);
    };
    let opened = async {
        let first = tokio::time::timeout(default_idle, inbound.next())
            .await
            .map_err(|_| Status::deadline_exceeded(format!("no open message within {default_idle:?}")))?;
        let open = match first {
            Some(Ok(pb::TrackRequest { msg: Some(Msg::Open(open)) })) => open,
            Some(Ok(_)) => {
                return Err(Status::invalid_argument(
                    "the first message of a Track stream must be `open` (model and options)",
                ))
            }
            Some(Err(status)) => return Err(status),
            None => return Err(Status::cancelled("stream closed before `open`")),
        };
        let model = context.repository.resolve(open.model.as_ref())?;
        if !(open.idle_timeout_s.is_finite() && (0.0..=MAX_IDLE_TIMEOUT_S).contains(&open.idle_timeout_s)) {
            return Err(Status::invalid_argument(format!(
                "idle_timeout_s = {}; must be between 0 (the server's default) and {MAX_IDLE_TIMEOUT_S} seconds",
                open.idle_timeout_s
            )));
        }
        let idle = if open.idle_timeout_s > 0.0 { Duration::from_secs_f64(open.idle_timeout_s) } else { default_idle };
        Ok((model, idle))
    }
    .await;
    let (model, idle) = opened.inspect_err(|status| context.metrics.call("Track", "-", status.code(), None))?;
    context.metrics.stream_delta(1);
    let guard = StreamGuard {
        metrics: Arc::clone(&context.metrics),
        model: model.manifest.name.clone(),
        code: Code::Ok,
        _permit: permit,
    };
    tracing::debug!(model = %model.label(), "track stream opened");
    // One slot more than the replies, reserved for the status that closes the stream: a client that stopped
    // reading still finds why, after its buffered replies.
    let (tx, rx) = tokio::sync::mpsc::channel(REPLY_BUFFER + 1);
    let last = tx.clone().try_reserve_owned().map_err(|_| Status::internal("a new reply channel has no room"))?;
    tokio::spawn(
        async move {
            let mut guard = guard;
            if let Err(status) = tick_loop(context, model, inbound, tx, idle, &mut guard).await {
                guard.code = status.code();
                last.send(Err(status));
            }
        }
        .in_current_span(),
    );
    Ok(ReceiverStream::new(rx))
}

/// Answers the stream's ticks in order until the client ends it (`Ok`) or the stream must close with a
/// status: the server drains, no tick came for `idle`, the client went away or stopped reading.
async fn tick_loop(
    mut context: StreamContext,
    mut model: Arc<LoadedModel>,
    mut inbound: Streaming<pb::TrackRequest>,
    tx: tokio::sync::mpsc::Sender<Result<pb::TrackResponse, Status>>,
    idle: Duration,
    guard: &mut StreamGuard,
) -> Result<(), Status> {
    let draining = || Status::unavailable("the server is shutting down; reconnect to continue");
    loop {
        if *context.draining.borrow() {
            return Err(draining());
        }
        let next = tokio::select! {
            next = tokio::time::timeout(idle, inbound.next()) => next,
            changed = context.draining.changed() => {
                if changed.is_err() {
                    return Err(draining());
                }
                continue;
            }
        };
        let reply = match next {
            Err(_) => return Err(Status::deadline_exceeded(format!("no tick for {idle:?}; stream closed"))),
            Ok(None) => return Ok(()),
            Ok(Some(Err(status))) => {
                tracing::debug!(%status, "track stream ended by client");
                return Err(Status::cancelled("the client ended the stream"));
            }
            Ok(Some(Ok(pb::TrackRequest { msg: Some(Msg::Tick(tick)) }))) => {
                // The stream keeps its version; a reload of that version is taken up at the next tick.
                if let Some(current) = context.repository.reloaded(&model) {
                    model = current;
                }
                answer(&context.scheduler, &model, tick).await
            }
            Ok(Some(Ok(_))) => pb::TrackReply {
                error: Some(pb::TickError {
                    code: Code::InvalidArgument as i32,
                    message: "only one `open` is allowed, at the start; send `tick` messages".into(),
                }),
                ..Default::default()
            },
        };
        let code = reply.error.as_ref().map_or(Code::Ok, |e| Code::from(e.code));
        context.metrics.tick(&guard.model, code);
        let sent = tokio::time::timeout(context.send_timeout, tx.send(Ok(pb::TrackResponse { reply: Some(reply) })));
        match sent.await {
            Ok(Ok(())) => {}
            Ok(Err(_)) => return Err(Status::cancelled("the client went away")),
            Err(_) => {
                // The client stopped reading: its buffer is full and stays so. Close rather than hold it.
                let waited = context.send_timeout;
                tracing::warn!(model = %guard.model, waited_s = waited.as_secs_f64(), "track stream closed: its client read no reply");
                return Err(Status::resource_exhausted(format!(
                    "the client read none of its {REPLY_BUFFER} buffered replies for {waited:?}; stream closed"
                )));
            }
        }
    }
}

/// Answers one tick; a rejected tick gets an error reply.
async fn answer(scheduler: &Scheduler, model: &Arc<LoadedModel>, tick: pb::TrackTick) -> pb::TrackReply {
    let seq = tick.seq;
    evaluate_tick(scheduler, model, tick).await.unwrap_or_else(|status| pb::TrackReply {
        seq,
        error: Some(pb::TickError { code: status.code() as i32, message: status.message().into() }),
        ..Default::default()
    })
}

async fn evaluate_tick(
    scheduler: &Scheduler,
    model: &Arc<LoadedModel>,
    tick: pb::TrackTick,
) -> Result<pb::TrackReply, Status> {
    let (question, batch) = TickQuestion::new(model, &tick)?;
    let (result, batch) = scheduler.evaluate(model, batch, None).await?;
    Ok(question.reply(result, &batch))
}

/// A validated tick: the planner speed its rule gives (the planner rule on `planner_clearance`, else the
/// paper's on `d_obs`) and its relative state.
pub struct TickQuestion {
    seq: u64,
    /// The rule's answer for the tick.
    pub speed: PlannerSpeed,
    relative: Vec<f64>,
}

impl TickQuestion {
    /// Checks the tick's vectors, `d_obs` and `planner_clearance` and forms its relative state, with the batch of one to evaluate
    /// (`r = s - Q p` under `beta_query`, `in_domain` flagged) on the compute pool or, in the caller's
    /// process, with [`LoadedModel::answer`].
    pub fn new(model: &LoadedModel, tick: &pb::TrackTick) -> Result<(Self, ValidBatch), Status> {
        validate::tick(model, &tick.tracker_state, &tick.planner_state)?;
        let speed = validate::planner_speed(model, tick.d_obs, tick.planner_clearance)?;
        let relative = model.space.relative_state(&tick.tracker_state, &tick.planner_state);
        let params = vec![speed.beta; model.manifest.n_params()];
        let batch = validate::batch(model, &relative, &params, pb::OutOfDomainPolicy::Flag)?;
        Ok((Self { seq: tick.seq, speed, relative }, batch))
    }

    /// The reply, from the evaluation of its batch.
    pub fn reply(self, result: BatchResult, batch: &ValidBatch) -> pb::TrackReply {
        pb::TrackReply {
            seq: self.seq,
            beta_query: self.speed.beta,
            dteb_radius: self.speed.dteb_radius,
            steb_radius: self.speed.steb_radius,
            relative_state: self.relative,
            value: f64::from(result.outputs.value[0]),
            in_teb: result.in_teb[0],
            in_domain: batch.in_domain[0],
            control: result.outputs.control.iter().map(|&x| f64::from(x)).collect(),
            error: None,
        }
    }
}
