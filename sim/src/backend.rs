//! Where the simulator's methods get their answers about the model: the fastrack service over gRPC (what a
//! robot does), or, with the `in-process` feature, a bundle loaded in this process and answered by the
//! server's own code with no network ([`crate::in_process`]), for tests and fast benchmarks.

use crate::methods::MethodError;
use fastrack_client::{pb, FastrackClient};
use fastrack_online::core::{Answer, ModelView, Query};
use fastrack_online::online_loop::LoopError;
use fastrack_online::oracle::Oracle;
use fastrack_online::track_oracle::{batch_answers, TrackOracle};
use fastrack_proto::planner_speed::SpeedRow;

/// The source of answers about one model.
#[derive(Clone)]
pub enum Backend {
    /// The fastrack service.
    Service {
        /// A connection to it.
        client: FastrackClient,
        /// The model.
        model: pb::ModelRef,
    },
    /// A model loaded in this process.
    #[cfg(feature = "in-process")]
    InProcess(crate::in_process::LocalModel),
}

impl Backend {
    /// The model's description, as `GetModel` gives it.
    pub async fn model_info(&self) -> Result<pb::ModelInfo, MethodError> {
        match self {
            Backend::Service { client, model } => Ok(client.get_model(model.clone()).await?),
            #[cfg(feature = "in-process")]
            Backend::InProcess(local) => Ok(local.info().clone()),
        }
    }

    /// An oracle for one robot's online loop (over the service: a `Track` stream of its own).
    pub async fn oracle(&self) -> Result<BackendOracle, MethodError> {
        match self {
            Backend::Service { client, model } => {
                Ok(BackendOracle::Track(Box::new(TrackOracle::open(client, model.clone()).await?)))
            }
            #[cfg(feature = "in-process")]
            Backend::InProcess(local) => Ok(BackendOracle::InProcess(local.oracle()?)),
        }
    }

    /// Value, membership, domain and control of the relative states `states` (row-major, `n_state` each)
    /// under `beta`, every parameter of an item set to it: one `TrackingControl` call over the service.
    pub async fn batch(
        &self,
        states: &[f64],
        beta: f64,
        n_state: usize,
        n_params: usize,
    ) -> Result<Vec<Answer>, MethodError> {
        match self {
            Backend::Service { client, model } => {
                Ok(batch_answers(client, model.clone(), states, beta, n_state, n_params).await?)
            }
            #[cfg(feature = "in-process")]
            Backend::InProcess(local) => Ok(local.batch(states, beta)?),
        }
    }
}

/// The oracle of one robot's online loop, from a [`Backend`].
pub enum BackendOracle {
    /// The service, over a `Track` stream.
    Track(Box<TrackOracle>),
    /// The model in this process.
    #[cfg(feature = "in-process")]
    InProcess(crate::in_process::LocalOracle),
}

impl Oracle for BackendOracle {
    fn view(&self) -> &ModelView {
        match self {
            BackendOracle::Track(oracle) => oracle.view(),
            #[cfg(feature = "in-process")]
            BackendOracle::InProcess(oracle) => oracle.view(),
        }
    }

    async fn answer<const D: usize>(&mut self, query: &Query<D>) -> Result<Vec<Answer>, LoopError> {
        match self {
            BackendOracle::Track(oracle) => oracle.answer(query).await,
            #[cfg(feature = "in-process")]
            BackendOracle::InProcess(oracle) => oracle.answer(query).await,
        }
    }

    async fn refresh(&mut self) -> Result<Vec<SpeedRow>, LoopError> {
        match self {
            BackendOracle::Track(oracle) => oracle.refresh().await,
            #[cfg(feature = "in-process")]
            BackendOracle::InProcess(oracle) => oracle.refresh().await,
        }
    }
}
