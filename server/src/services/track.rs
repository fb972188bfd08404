//! The `Track` bidirectional stream: one per robot, answering every tick in order and keeping `beta_old`.

use crate::model::LoadedModel;
use crate::repository::Repository;
use crate::teb::query_planner_control;
use crate::validate;
use fastrack_proto::v1 as pb;
use pb::track_request::Msg;
use std::sync::Arc;
use std::time::Duration;
use tokio_stream::wrappers::ReceiverStream;
use tokio_stream::StreamExt;
use tonic::{Status, Streaming};

/// Reads the opening message, resolves the model (the stream keeps that version for its lifetime) and
/// spawns the tick loop. Errors before the first tick end the call with their status.
pub async fn open(
    repository: Arc<Repository>,
    mut inbound: Streaming<pb::TrackRequest>,
    default_idle: Duration,
) -> Result<ReceiverStream<Result<pb::TrackResponse, Status>>, Status> {
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
    let model = repository.resolve(open.model.as_ref())?;
    if !(open.idle_timeout_s.is_finite() && open.idle_timeout_s >= 0.0) {
        return Err(Status::invalid_argument(format!(
            "idle_timeout_s = {}; must be finite and >= 0",
            open.idle_timeout_s
        )));
    }
    let idle = if open.idle_timeout_s > 0.0 { Duration::from_secs_f64(open.idle_timeout_s) } else { default_idle };
    let (tx, rx) = tokio::sync::mpsc::channel(64);
    tokio::spawn(tick_loop(model, inbound, tx, idle));
    Ok(ReceiverStream::new(rx))
}

async fn tick_loop(
    model: Arc<LoadedModel>,
    mut inbound: Streaming<pb::TrackRequest>,
    tx: tokio::sync::mpsc::Sender<Result<pb::TrackResponse, Status>>,
    idle: Duration,
) {
    let mut beta_old = model.manifest.beta_range().1;
    loop {
        let next = match tokio::time::timeout(idle, inbound.next()).await {
            Ok(next) => next,
            Err(_) => {
                let _ = tx.send(Err(Status::deadline_exceeded(format!("no tick for {idle:?}; stream closed")))).await;
                return;
            }
        };
        let reply = match next {
            None => return,
            Some(Err(status)) => {
                tracing::debug!(%status, "track stream ended by client");
                return;
            }
            Some(Ok(pb::TrackRequest { msg: Some(Msg::Tick(tick)) })) => answer(&model, tick, &mut beta_old).await,
            Some(Ok(_)) => pb::TrackReply {
                error: Some(pb::TickError {
                    code: tonic::Code::InvalidArgument as i32,
                    message: "only one `open` is allowed, at the start; send `tick` messages".into(),
                }),
                ..Default::default()
            },
        };
        if tx.send(Ok(pb::TrackResponse { reply: Some(reply) })).await.is_err() {
            return;
        }
    }
}

/// Answers one tick; a rejected tick gets an error reply and leaves `beta_old` unchanged.
async fn answer(model: &Arc<LoadedModel>, tick: pb::TrackTick, beta_old: &mut f64) -> pb::TrackReply {
    let seq = tick.seq;
    match evaluate_tick(model, tick, *beta_old).await {
        Ok(reply) => {
            *beta_old = reply.beta_query;
            reply
        }
        Err(status) => pb::TrackReply {
            seq,
            error: Some(pb::TickError { code: status.code() as i32, message: status.message().into() }),
            ..Default::default()
        },
    }
}

async fn evaluate_tick(model: &Arc<LoadedModel>, tick: pb::TrackTick, beta_old: f64) -> Result<pb::TrackReply, Status> {
    validate::tick(model, &tick.tracker_state, &tick.planner_state)?;
    let d_obs = validate::d_obs(tick.d_obs)?;
    let speed = query_planner_control(&model.manifest.teb_table, d_obs);
    let relative = model.manifest.relative_state(&tick.tracker_state, &tick.planner_state);
    let params = vec![speed.beta; model.manifest.n_params()];
    let batch = validate::batch(model, &relative, &params, pb::OutOfDomainPolicy::Flag)?;
    let (result, batch) = model.evaluate(batch).await?;
    Ok(pb::TrackReply {
        seq: tick.seq,
        beta_query: speed.beta,
        beta_old,
        dteb_radius: speed.dteb_radius,
        steb_radius: speed.steb_radius,
        relative_state: relative,
        value: f64::from(result.outputs.value[0]),
        in_teb: result.in_teb[0],
        in_domain: batch.in_domain[0],
        control: result.outputs.control.iter().map(|&x| f64::from(x)).collect(),
        error: None,
    })
}
