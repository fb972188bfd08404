//! The oracle of a robot on the network: one `Track` stream answers the tick of each step (`beta_query`,
//! membership, `u*` in one round trip), `TrackingControl` answers the batches (reset candidates, a held
//! state), and `GetModel` gives the table.

use crate::core::{Answer, CoreError, ModelView, Query};
use crate::online_loop::LoopError;
use crate::oracle::Oracle;
use fastrack_client::{pb, FastrackClient, TrackStream};
use fastrack_proto::planner_speed::SpeedRow;

/// Out-of-domain states are answered with a flag, as on the `Track` stream.
const FLAG: pb::OutOfDomainPolicy = pb::OutOfDomainPolicy::Flag;

/// The `Track` tick numbered `seq` that asks what a [`Query::Tick`] with these fields asks.
pub fn track_tick(
    seq: u64,
    tracker: &[f64],
    planner: &[f64],
    d_obs: Option<f64>,
    planner_clearance: Option<f64>,
) -> pb::TrackTick {
    pb::TrackTick { seq, tracker_state: tracker.to_vec(), planner_state: planner.to_vec(), d_obs, planner_clearance }
}

impl From<pb::TrackReply> for Answer {
    /// The answer a tick's reply gives (its `seq`, `beta_query` and error checked by the caller).
    fn from(reply: pb::TrackReply) -> Self {
        Self {
            relative_state: reply.relative_state,
            value: reply.value,
            in_set: reply.in_teb,
            in_domain: reply.in_domain,
            control: reply.control,
        }
    }
}

/// The horizon over which the model's rows were verified: the shortest of them (`None`: no row verified).
pub fn certificate_horizon(info: &pb::ModelInfo) -> Option<f64> {
    info.teb_table.iter().filter_map(|row| row.verification.as_ref().map(|v| v.horizon)).reduce(f64::min)
}

/// The model as the core reads it, from its description (the core checks that its planner's dimension is
/// the loop's).
pub fn model_view(info: &pb::ModelInfo) -> ModelView {
    ModelView {
        speeds: info.teb_table.iter().map(SpeedRow::from).collect(),
        planner_to_state: info.planner_to_state.clone(),
        n_state: info.state.len(),
        certificate_horizon: certificate_horizon(info),
    }
}

/// One `TrackingControl` call for the relative states `states` (row-major, `n_state` each) under `beta`
/// (every parameter of every item set to it), as the core's [`Answer`]s.
pub async fn batch_answers(
    client: &FastrackClient,
    model: pb::ModelRef,
    states: &[f64],
    beta: f64,
    n_state: usize,
    n_params: usize,
) -> Result<Vec<Answer>, LoopError> {
    let count = states.len() / n_state;
    let params = vec![beta; count * n_params];
    let reply = client.tracking_control(model, states.to_vec(), params, FLAG).await?;
    let n_control = reply.controls.len() / count.max(1);
    let fits = reply.values.len() == count && reply.in_teb.len() == count && reply.in_domain.len() == count;
    if !fits || reply.controls.len() != count * n_control {
        return Err(LoopError::Core(CoreError::Answer(format!(
            "TrackingControl answered a batch of {count} with {} values",
            reply.values.len()
        ))));
    }
    Ok((0..count)
        .map(|i| Answer {
            relative_state: states[i * n_state..(i + 1) * n_state].to_vec(),
            value: reply.values[i],
            in_set: reply.in_teb[i],
            in_domain: reply.in_domain[i],
            control: reply.controls[i * n_control..(i + 1) * n_control].to_vec(),
        })
        .collect())
}

/// The fastrack service as the oracle, over one `Track` stream.
pub struct TrackOracle {
    client: FastrackClient,
    stream: TrackStream,
    model: pb::ModelRef,
    view: ModelView,
    n_params: usize,
    seq: u64,
}

impl TrackOracle {
    /// Fetches the model's description and opens a `Track` stream for it.
    pub async fn open(client: &FastrackClient, model: pb::ModelRef) -> Result<Self, LoopError> {
        let info = client.get_model(model.clone()).await?;
        let view = model_view(&info);
        let stream = client.track(model.clone(), 0.0).await?;
        Ok(Self { client: client.clone(), stream, model, view, n_params: info.params.len(), seq: 0 })
    }
}

impl Oracle for TrackOracle {
    fn view(&self) -> &ModelView {
        &self.view
    }

    /// A tick on the stream (its `beta_query` checked against the core's), or one `TrackingControl` batch.
    async fn answer<const D: usize>(&mut self, query: &Query<D>) -> Result<Vec<Answer>, LoopError> {
        match query {
            Query::Tick { tracker, planner, d_obs, planner_clearance, beta } => {
                let seq = self.seq;
                self.seq += 1;
                let tick = track_tick(seq, tracker, planner, *d_obs, *planner_clearance);
                let reply = self.stream.tick(tick).await?;
                if let Some(error) = reply.error {
                    return Err(LoopError::Tick { seq, code: error.code, message: error.message });
                }
                if reply.beta_query != *beta {
                    return Err(LoopError::TableMismatch { local: *beta, server: reply.beta_query });
                }
                Ok(vec![reply.into()])
            }
            Query::Batch { states, beta } => {
                let model = self.model.clone();
                batch_answers(&self.client, model, states, *beta, self.view.n_state, self.n_params).await
            }
        }
    }

    async fn refresh(&mut self) -> Result<Vec<SpeedRow>, LoopError> {
        let info = self.client.get_model(self.model.clone()).await?;
        self.view = model_view(&info);
        Ok(self.view.speeds.clone())
    }
}
