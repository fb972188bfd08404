//! A model answered in this process (feature `in-process`): a bundle loaded through ONNX Runtime as the
//! server loads it, its questions answered by the server's own validation, planner-speed rule and
//! membership test on the calling thread, with no network. Runs come out as over the service, only faster.

use crate::methods::MethodError;
use fastrack_client::pb;
use fastrack_online::core::{Answer, ModelView, Query};
use fastrack_online::online_loop::LoopError;
use fastrack_online::oracle::Oracle;
use fastrack_online::track_oracle::{model_view, track_tick};
use fastrack_proto::planner_speed::SpeedRow;
use fastrack_server::loaded_model::LoadedModel;
use fastrack_server::services::track::TickQuestion;
use fastrack_server::validate;
use fastrack_valuefn::bundle::Bundle;
use std::path::Path;
use std::sync::Arc;

/// A model loaded in this process, shared by every run.
#[derive(Clone)]
pub struct LocalModel {
    model: Arc<LoadedModel>,
}

fn refused(status: tonic::Status) -> LoopError {
    LoopError::Refused { code: status.code() as i32, message: status.message().to_string() }
}

impl LocalModel {
    /// Loads the bundle in the version folder `dir` (e.g. `models/dubins4d/5`) through the ONNX Runtime
    /// library `library` (`None`: where the project installs it), with `sessions` sessions for runs at once.
    pub fn load(dir: &Path, library: Option<&Path>, sessions: usize) -> Result<Self, MethodError> {
        let fail = |e: &dyn std::fmt::Display| MethodError::Setup(format!("loading the bundle {}: {e}", dir.display()));
        let runtime = fastrack_valuefn::runtime::runtime(library).map_err(|e| fail(&e))?;
        let bundle = Bundle::load(dir).map_err(|e| fail(&e))?;
        let model = LoadedModel::new(bundle, runtime, sessions).map_err(|e| fail(&e))?;
        Ok(Self { model: Arc::new(model) })
    }

    /// The model's description, as `GetModel` gives it.
    pub fn info(&self) -> &pb::ModelInfo {
        &self.model.info
    }

    /// An oracle for one robot.
    pub fn oracle(&self) -> Result<LocalOracle, LoopError> {
        Ok(LocalOracle { view: model_view(&self.model.info), local: self.clone() })
    }

    /// Value, membership, domain and control of the relative states `states` (row-major) under `beta`, as
    /// `TrackingControl` answers them (out-of-domain states flagged).
    pub fn batch(&self, states: &[f64], beta: f64) -> Result<Vec<Answer>, LoopError> {
        let model = &self.model;
        let (n_state, n_params) = (model.space.n_state(), model.manifest.n_params());
        let params = vec![beta; states.len() / n_state.max(1) * n_params];
        let batch = validate::batch(model, states, &params, pb::OutOfDomainPolicy::Flag).map_err(refused)?;
        let result = model.answer(&batch).map_err(refused)?;
        let n_control = result.outputs.control.len() / batch.n;
        Ok((0..batch.n)
            .map(|i| Answer {
                relative_state: states[i * n_state..(i + 1) * n_state].to_vec(),
                value: f64::from(result.outputs.value[i]),
                in_set: result.in_teb[i],
                in_domain: batch.in_domain[i],
                control: result.outputs.control[i * n_control..(i + 1) * n_control]
                    .iter()
                    .map(|&x| f64::from(x))
                    .collect(),
            })
            .collect())
    }
}

/// The oracle of one robot over a [`LocalModel`]: a tick is answered as the `Track` stream answers it.
pub struct LocalOracle {
    local: LocalModel,
    view: ModelView,
}

impl Oracle for LocalOracle {
    fn view(&self) -> &ModelView {
        &self.view
    }

    async fn answer<const D: usize>(&mut self, query: &Query<D>) -> Result<Vec<Answer>, LoopError> {
        match query {
            Query::Tick { tracker, planner, d_obs, planner_clearance, beta } => {
                let tick = track_tick(0, tracker, planner, *d_obs, *planner_clearance);
                let model = &self.local.model;
                let (question, batch) = TickQuestion::new(model, &tick).map_err(refused)?;
                if question.speed.beta != *beta {
                    return Err(LoopError::TableMismatch { local: *beta, server: question.speed.beta });
                }
                let result = model.answer(&batch).map_err(refused)?;
                Ok(vec![question.reply(result, &batch).into()])
            }
            Query::Batch { states, beta } => self.local.batch(states, *beta),
        }
    }

    async fn refresh(&mut self) -> Result<Vec<SpeedRow>, LoopError> {
        Ok(self.view.speeds.clone())
    }
}
