//! The training loss: the HJI variational inequality in horizon form,
//! `0 = min{V - l, dV/dtau - H(r, dV/dr; beta)}`, in the paper's form or with the exact boundary condition.

use crate::config::{LossForm, TrainConfig};
use crate::dynamics::TensorDynamics;
use crate::model::Siren;
use crate::sampler::Batch;
use burn::tensor::{Device, Tensor, TensorData};
use fastrack_valuefn::network::InputNormalization;
use fastrack_valuefn::system::AffineSystem;

/// Loss terms of one iteration, for logs.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LossTerms {
    /// What was minimised.
    pub total: f64,
    /// Mean `|V - l|` at `tau = 0` (0 for the exact-boundary form).
    pub boundary: f64,
    /// Mean `|min(V - l, dV/dtau - H)|`.
    pub residual: f64,
}

/// `V`, its derivatives and `l` on a batch.
pub struct ValueTerms {
    /// `V` `[N, 1]`.
    pub value: Tensor<2>,
    /// `dV/dtau` `[N, 1]`.
    pub d_tau: Tensor<2>,
    /// `dV/dr` `[N, n_state]`.
    pub d_state: Tensor<2>,
    /// `l(r)` `[N, 1]`.
    pub error: Tensor<2>,
}

/// Builds the loss of a configuration.
pub struct Objective {
    dynamics: TensorDynamics,
    form: LossForm,
    lambda: f64,
    pretrain_iterations: u64,
    omega_0: f64,
    output_scale: f64,
    output_offset: f64,
    n_state: usize,
    tau_half_range: f64,
    state_inv_half_range: Tensor<2>,
    /// Multiplies the Hamiltonian: 1 always, except in tests showing that a wrong sign fails.
    pub hamiltonian_sign: f64,
}

impl Objective {
    /// The objective of `config` for `system` on `device`.
    pub fn new(
        config: &TrainConfig,
        system: &AffineSystem,
        normalization: &InputNormalization,
        device: &Device,
    ) -> Self {
        let ns = system.n_state();
        let inv: Vec<f32> = (0..ns).map(|j| (1.0 / normalization.half_range[1 + j]) as f32).collect();
        Self {
            dynamics: TensorDynamics::new(system, device),
            form: config.loss.form,
            lambda: config.loss.lambda,
            pretrain_iterations: config.loss.pretrain_iterations,
            omega_0: config.network.omega_0,
            output_scale: config.network.output_scale,
            output_offset: config.network.output_offset,
            n_state: ns,
            tau_half_range: normalization.half_range[0],
            state_inv_half_range: Tensor::from_data(TensorData::new(inv, [1, ns]), device),
            hamiltonian_sign: 1.0,
        }
    }

    /// `V`, `dV/dtau`, `dV/dr` and `l` in physical units.
    pub fn value_terms(&self, model: &Siren, batch: &Batch) -> ValueTerms {
        let forward = model.forward(batch.input.clone(), self.omega_0);
        let nn = forward.output.mul_scalar(self.output_scale).add_scalar(self.output_offset);
        let d_tau_nn = forward.input_grad.clone().narrow(1, 0, 1).mul_scalar(self.output_scale / self.tau_half_range);
        let d_state_nn = forward
            .input_grad
            .narrow(1, 1, self.n_state)
            .mul(self.state_inv_half_range.clone())
            .mul_scalar(self.output_scale);
        let (error, d_error) = self.dynamics.tracking_error(&batch.state);
        match self.form {
            LossForm::Paper => ValueTerms { value: nn, d_tau: d_tau_nn, d_state: d_state_nn, error },
            LossForm::ExactBoundary => ValueTerms {
                value: error.clone() + batch.tau.clone().mul(nn.clone()),
                d_tau: nn + batch.tau.clone().mul(d_tau_nn),
                d_state: d_error + batch.tau.clone().mul(d_state_nn),
                error,
            },
        }
    }

    /// The loss at `iteration` and its terms.
    pub fn loss(&self, model: &Siren, batch: &Batch, iteration: u64) -> (Tensor<1>, LossTerms) {
        let v = self.value_terms(model, batch);
        let hamiltonian =
            self.dynamics.hamiltonian(&batch.state, &v.d_state, &batch.params).mul_scalar(self.hamiltonian_sign);
        let residual = (v.value.clone() - v.error.clone()).min_pair(v.d_tau - hamiltonian).abs().mean();
        let (total, boundary) = match self.form {
            LossForm::ExactBoundary => (residual.clone(), None),
            LossForm::Paper => {
                let boundary =
                    (v.value.narrow(0, 0, batch.n_boundary) - v.error.narrow(0, 0, batch.n_boundary)).abs().mean();
                let total = if iteration < self.pretrain_iterations {
                    boundary.clone()
                } else {
                    boundary.clone() + residual.clone().mul_scalar(self.lambda)
                };
                (total, Some(boundary))
            }
        };
        let scalar = |t: Tensor<1>| f64::from(t.into_scalar::<f32>());
        let terms = LossTerms {
            total: scalar(total.clone()),
            boundary: boundary.map_or(0.0, scalar),
            residual: scalar(residual),
        };
        (total, terms)
    }
}
