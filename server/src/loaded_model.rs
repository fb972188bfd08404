//! One loaded model version: its manifest, its evaluator and the answers derived from them.

use crate::validate::ValidBatch;
use fastrack_proto::planner_speed::{self, SpeedRow};
use fastrack_proto::v1 as pb;
use fastrack_valuefn::bundle::Bundle;
use fastrack_valuefn::manifest::{Manifest, TebRow};
use fastrack_valuefn::runtime::{Evaluation, Evaluator, GraphDims, Runtime, RuntimeError};
use fastrack_valuefn::system::StateSpace;
use tonic::Status;

/// What an evaluation returns for one batch, beside the batch.
pub struct BatchResult {
    /// Graph outputs for the batch's items.
    pub outputs: Evaluation,
    /// Per item: `V <= set level` of the row for its largest parameter.
    pub in_teb: Vec<bool>,
}

/// A model version ready to answer.
pub struct LoadedModel {
    /// Validated manifest.
    pub manifest: Manifest,
    /// The relative-state space the manifest describes: what the server knows of the system.
    pub space: StateSpace,
    /// The description sent by ListModels/GetModel.
    pub info: pb::ModelInfo,
    /// The TEB table as the planner-speed rules read it: each row's `beta` and bound.
    pub speeds: Vec<SpeedRow>,
    evaluator: Evaluator,
}

/// Why a bundle could not be made ready.
#[derive(Debug, thiserror::Error)]
pub enum ModelError {
    /// ONNX Runtime refused the graph or failed to run it.
    #[error(transparent)]
    Runtime(#[from] RuntimeError),
    /// The warm-up evaluation gave NaN or infinite outputs.
    #[error("warm-up at the centre of the domain gave non-finite outputs (value {0}); the graph is broken")]
    NonFinite(f32),
}

impl LoadedModel {
    /// Builds `sessions` ONNX Runtime sessions for a checked bundle and warms each of them up on the centre of the domain
    /// (rejecting a graph whose outputs there are not finite).
    pub fn new(bundle: Bundle, runtime: &Runtime, sessions: usize) -> Result<Self, ModelError> {
        let m = &bundle.manifest;
        let dims = GraphDims::of(m);
        let evaluator = Evaluator::new(runtime, &bundle.onnx, dims, sessions)?;
        let centre = |min: f64, max: f64| (0.5 * (min + max)) as f32;
        let state: Vec<f32> = m.state.iter().map(|d| centre(d.min, d.max)).collect();
        let params: Vec<f32> = m.params.iter().map(|d| centre(d.min, d.max)).collect();
        let warm = evaluator.warm_up(&state, &params)?;
        if let Some(bad) = warm.value.iter().chain(&warm.grad).chain(&warm.control).find(|x| !x.is_finite()) {
            return Err(ModelError::NonFinite(*bad));
        }
        let space = m.state_space();
        let info = crate::convert::model_info(&bundle.manifest, &space);
        let speeds = info.teb_table.iter().map(SpeedRow::from).collect();
        Ok(Self { manifest: bundle.manifest, space, info, speeds, evaluator })
    }

    /// Name and version, for logs and messages.
    pub fn label(&self) -> String {
        format!("{}/{}", self.manifest.name, self.manifest.version)
    }

    /// The TEB row answering for `beta` ([`planner_speed::row_for`]).
    pub fn row_for(&self, beta: f64) -> Option<&TebRow> {
        planner_speed::row_for(&self.speeds, beta).map(|i| &self.manifest.teb_table[i])
    }

    /// `V <= set level` of the row for `beta`: the relative state lies in the row's certified set, from which
    /// its bound holds.
    pub fn in_teb(&self, value: f32, beta: f64) -> bool {
        self.row_for(beta).is_some_and(|row| f64::from(value) <= row.set_level())
    }

    /// The result of `batch` from its graph outputs: each item's membership in the certified set of its row.
    /// An item whose value, gradient or control is not finite (a state so far outside the trained domain that
    /// the graph overflows) fails the batch with OUT_OF_RANGE naming it: no number that is not one is sent.
    pub fn result(&self, outputs: Evaluation, batch: &ValidBatch) -> Result<BatchResult, Status> {
        let (ns, nc) = (self.space.n_state(), self.manifest.n_control());
        let finite = |i: usize| {
            outputs.value[i].is_finite()
                && outputs.grad[i * ns..(i + 1) * ns].iter().all(|g| g.is_finite())
                && outputs.control[i * nc..(i + 1) * nc].iter().all(|u| u.is_finite())
        };
        if let Some(i) = (0..batch.n).find(|&i| !finite(i)) {
            return Err(self.not_finite(i, &batch.states[i * ns..(i + 1) * ns]));
        }
        let in_teb = outputs.value.iter().zip(&batch.max_beta).map(|(&v, &b)| self.in_teb(v, b)).collect();
        Ok(BatchResult { outputs, in_teb })
    }

    /// The error for item `i` (state `state`) whose outputs are not finite.
    fn not_finite(&self, i: usize, state: &[f32]) -> Status {
        let state: Vec<f64> = state.iter().map(|&x| f64::from(x)).collect();
        match self.space.first_outside(&state) {
            Some(j) => {
                let d = &self.manifest.state[j];
                Status::out_of_range(format!(
                    "item {i} lies so far outside the trained domain ({} = {:e} in the model's 32-bit inputs, domain [{}, {}] {}) that its value is not a finite number; nothing is returned for it",
                    d.name, state[j], d.min, d.max, d.unit
                ))
            }
            None => {
                tracing::error!(model = %self.label(), item = i, ?state, "a non-finite output inside the domain");
                Status::internal(format!(
                    "model {} gave a non-finite output for item {i} inside its domain",
                    self.label()
                ))
            }
        }
    }

    /// Evaluates a validated batch on the calling thread (blocks): what the compute pool answers, for a
    /// caller that holds the model in its own process.
    pub fn answer(&self, batch: &ValidBatch) -> Result<BatchResult, Status> {
        let outputs = self.compute(&batch.states, &batch.params)?;
        self.result(outputs, batch)
    }

    /// Evaluates `[N x n_state]` states with `[N x n_params]` params; blocks (compute-pool threads only).
    pub fn compute(&self, states: &[f32], params: &[f32]) -> Result<Evaluation, Status> {
        self.evaluator.evaluate(states, params).map_err(|e| {
            tracing::error!(model = %self.label(), error = %e, "evaluation failed");
            Status::internal(format!("evaluation of model {} failed: {e}", self.label()))
        })
    }
}
