//! One loaded model version: its manifest, its evaluator and the answers derived from them.

use crate::teb::row_for;
use crate::validate::ValidBatch;
use fastrack_proto::v1 as pb;
use fastrack_valuefn::bundle::Bundle;
use fastrack_valuefn::manifest::{Manifest, TebRow};
use fastrack_valuefn::runtime::{Evaluation, Evaluator, GraphDims, Runtime, RuntimeError};
use std::sync::Arc;
use tonic::Status;

/// A model version ready to answer.
pub struct LoadedModel {
    /// Validated manifest.
    pub manifest: Manifest,
    /// The description sent by ListModels/GetModel.
    pub info: pb::ModelInfo,
    evaluator: Evaluator,
}

/// What a batch evaluation returns, beside the raw graph outputs.
pub struct BatchResult {
    /// Graph outputs.
    pub outputs: Evaluation,
    /// Per item: `V <= TEB level` of its largest parameter.
    pub in_teb: Vec<bool>,
}

impl LoadedModel {
    /// Builds sessions for a checked bundle.
    pub fn new(bundle: Bundle, runtime: &Runtime, sessions: usize) -> Result<Self, RuntimeError> {
        let m = &bundle.manifest;
        let dims = GraphDims { n_state: m.n_state(), n_params: m.n_params(), n_control: m.n_control() };
        let evaluator = Evaluator::new(runtime, &bundle.onnx, dims, sessions)?;
        let info = crate::convert::model_info(&bundle.manifest);
        Ok(Self { manifest: bundle.manifest, info, evaluator })
    }

    /// Name and version, for logs and messages.
    pub fn label(&self) -> String {
        format!("{}/{}", self.manifest.name, self.manifest.version)
    }

    /// The TEB row answering for `beta` (see [`row_for`]).
    pub fn row_for(&self, beta: f64) -> Option<&TebRow> {
        row_for(&self.manifest.teb_table, beta)
    }

    /// Evaluates a validated batch on a blocking-pool thread.
    pub async fn evaluate(self: &Arc<Self>, batch: ValidBatch) -> Result<(BatchResult, ValidBatch), Status> {
        let model = Arc::clone(self);
        tokio::task::spawn_blocking(move || {
            let outputs = model.evaluator.evaluate(&batch.states, &batch.params).map_err(|e| {
                tracing::error!(model = %model.label(), error = %e, "evaluation failed");
                Status::internal(format!("evaluation of model {} failed: {e}", model.label()))
            })?;
            let in_teb = outputs
                .value
                .iter()
                .zip(&batch.max_beta)
                .map(|(&v, &beta)| model.row_for(beta).is_some_and(|row| f64::from(v) <= row.served_level()))
                .collect();
            Ok((BatchResult { outputs, in_teb }, batch))
        })
        .await
        .map_err(|e| Status::internal(format!("evaluation task failed: {e}")))?
    }
}
