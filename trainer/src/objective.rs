//! The training loss: the HJI variational inequality in horizon form,
//! `0 = min{V - l, dV/dtau - H(r, dV/dr; beta)}`, in the paper's form or with the exact boundary condition,
//! as a differential or a semi-Lagrangian residual, plus the optional grid-supervision terms
//! (`crate::supervision`).

use crate::causal::causal_weights;
use crate::config::{LossForm, Residual, ResidualNorm, TrainConfig};
use crate::dynamics::TensorDynamics;
use crate::features::TensorFeatures;
use crate::sampler::Batch;
use crate::siren::Siren;
use crate::supervision::GridSupervision;
use burn::tensor::{Device, Tensor, TensorData};
use fastrack_valuefn::network::{FeatureLayout, InputNormalization};
use fastrack_valuefn::system::AffineSystem;

/// Loss terms of one iteration, for logs.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LossTerms {
    /// What was minimised.
    pub total: f64,
    /// Mean `|V - l|` at `tau = 0` (0 for the exact-boundary form).
    pub boundary: f64,
    /// Mean absolute (or, with the `l2` norm, squared) residual: `min(V - l, dV/dtau - H)` or the
    /// semi-Lagrangian one.
    pub residual: f64,
    /// Mean squared error to the grid values (0 without supervision).
    pub supervision: f64,
    /// Mean squared error of `dV/dr` to the grid's (summed over the state axes; 0 unless supervised).
    pub supervision_gradient: f64,
}

/// Mean of `error^2`, times `under_weight` where `error < 0` (the weights are constants of the gradient).
fn weighted_square_error(error: Tensor<2>, under_weight: f64) -> Tensor<1> {
    let squared = error.clone().powi_scalar(2);
    if under_weight == 1.0 {
        return squared.mean();
    }
    let under = error.detach().lower_elem(0.0).float();
    squared.mul(under.mul_scalar(under_weight - 1.0).add_scalar(1.0)).mean()
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
    residual: Residual,
    norm: ResidualNorm,
    time_step: f64,
    causal_bins: usize,
    causal_epsilon: f64,
    lambda: f64,
    pretrain_iterations: u64,
    omega_0: f64,
    features: TensorFeatures,
    output_scale: f64,
    output_offset: f64,
    n_state: usize,
    tau_half_range: f64,
    state_inv_half_range: Tensor<2>,
    input_center: Tensor<2>,
    input_inv_half_range: Tensor<2>,
    /// `(column, min, period)` of each periodic state coordinate.
    periodic: Vec<(usize, f64, f64)>,
    /// Multiplies the Hamiltonian: 1 always, except in tests showing that a wrong sign fails.
    pub hamiltonian_sign: f64,
    /// Grid supervision, if configured.
    supervision: Option<GridSupervision>,
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
        let input_row = |values: Vec<f32>| {
            let n = values.len();
            Tensor::from_data(TensorData::new(values, [1, n]), device)
        };
        Self {
            dynamics: TensorDynamics::new(system, device),
            form: config.loss.form,
            residual: config.loss.residual,
            norm: config.loss.norm,
            time_step: config.loss.time_step,
            causal_bins: config.loss.causal_bins,
            causal_epsilon: config.loss.causal_epsilon,
            lambda: config.loss.lambda,
            pretrain_iterations: config.loss.pretrain_iterations,
            omega_0: config.network.omega_0,
            features: TensorFeatures::new(FeatureLayout::for_system(system, config.network.periodic_encoding)),
            output_scale: config.network.output_scale,
            output_offset: config.network.output_offset,
            n_state: ns,
            tau_half_range: normalization.half_range[0],
            state_inv_half_range: Tensor::from_data(TensorData::new(inv, [1, ns]), device),
            input_center: input_row(normalization.center.iter().map(|&c| c as f32).collect()),
            input_inv_half_range: input_row(normalization.half_range.iter().map(|&s| (1.0 / s) as f32).collect()),
            periodic: system
                .state
                .iter()
                .enumerate()
                .filter(|(_, d)| d.periodic)
                .map(|(j, d)| (j, d.min, d.max - d.min))
                .collect(),
            hamiltonian_sign: 1.0,
            supervision: None,
        }
    }

    /// Adds the grid-supervision terms.
    pub fn with_supervision(self, supervision: GridSupervision) -> Self {
        Self { supervision: Some(supervision), ..self }
    }

    /// Mean squared errors of `V` and (when its weight is positive) of `dV/dr` to the grid targets drawn at
    /// `iteration`.
    fn supervision_errors(
        &self,
        supervision: &GridSupervision,
        model: &Siren,
        iteration: u64,
        device: &Device,
    ) -> (Tensor<1>, Option<Tensor<1>>) {
        let batch = supervision.batch(iteration, device);
        if supervision.gradient_weight <= 0.0 {
            let value = self.value_at(model, batch.tau, batch.state, batch.params);
            return (weighted_square_error(value - batch.target, supervision.under_weight), None);
        }
        let input = (Tensor::cat(vec![batch.tau.clone(), batch.state.clone(), batch.params.clone()], 1)
            - self.input_center.clone())
        .mul(self.input_inv_half_range.clone());
        let points =
            Batch { tau: batch.tau, state: batch.state, params: batch.params, input, n_boundary: 0, tau_limit: 0.0 };
        let v = self.value_terms(model, &points);
        let gradient_error =
            (v.d_state - batch.target_gradient).powi_scalar(2).mul(batch.gradient_weights).sum_dim(1).mean();
        (weighted_square_error(v.value - batch.target, supervision.under_weight), Some(gradient_error))
    }

    /// `V`, `dV/dtau`, `dV/dr` and `l` in physical units.
    pub fn value_terms(&self, model: &Siren, batch: &Batch) -> ValueTerms {
        let forward = model.forward(self.features.encode(batch.input.clone()), self.omega_0);
        let nn = forward.output.mul_scalar(self.output_scale).add_scalar(self.output_offset);
        let input_grad = self.features.input_gradient(&batch.input, forward.input_grad);
        let d_tau_nn = input_grad.clone().narrow(1, 0, 1).mul_scalar(self.output_scale / self.tau_half_range);
        let d_state_nn =
            input_grad.narrow(1, 1, self.n_state).mul(self.state_inv_half_range.clone()).mul_scalar(self.output_scale);
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

    /// `V` `[N, 1]` at physical `tau` `[N, 1]`, `state` `[N, n_state]`, `params` `[N, n_params]` (values only).
    fn value_at(&self, model: &Siren, tau: Tensor<2>, state: Tensor<2>, params: Tensor<2>) -> Tensor<2> {
        let input = (Tensor::cat(vec![tau.clone(), state.clone(), params], 1) - self.input_center.clone())
            .mul(self.input_inv_half_range.clone());
        let nn = model
            .output(self.features.encode(input), self.omega_0)
            .mul_scalar(self.output_scale)
            .add_scalar(self.output_offset);
        match self.form {
            LossForm::Paper => nn,
            LossForm::ExactBoundary => self.dynamics.tracking_error(&state).0 + tau.mul(nn),
        }
    }

    /// Wraps the periodic coordinates of `state` into their period.
    fn wrap(&self, state: Tensor<2>) -> Tensor<2> {
        if self.periodic.is_empty() {
            return state;
        }
        let columns = (0..self.n_state)
            .map(|j| {
                let x = state.clone().narrow(1, j, 1);
                match self.periodic.iter().find(|p| p.0 == j) {
                    Some(&(_, min, period)) => {
                        x.clone() - x.sub_scalar(min).div_scalar(period).floor().mul_scalar(period)
                    }
                    None => x,
                }
            })
            .collect();
        Tensor::cat(columns, 1)
    }

    /// The semi-Lagrangian residual `(V - max{l, min_u max_{u_p, d} V(r + h s r', tau - h)}) / dt` `[N, 1]`
    /// (`h = min(dt, tau)`, `s` the Hamiltonian sign; a negative sign swaps the min and the max, which
    /// multiplies the step's Hamiltonian by `s`) and `V - l` `[N, 1]`.
    fn semi_lagrangian(&self, model: &Siren, batch: &Batch) -> (Tensor<2>, Tensor<2>) {
        let n = batch.tau.dims()[0];
        let value = self.value_at(model, batch.tau.clone(), batch.state.clone(), batch.params.clone());
        let error = self.dynamics.tracking_error(&batch.state).0;
        let earlier = batch.tau.clone().sub_scalar(self.time_step).clamp_min(0.0);
        let step = (batch.tau.clone() - earlier.clone()).mul_scalar(self.hamiltonian_sign);
        let groups = self.dynamics.vertex_velocities(&batch.state, &batch.params);
        let shifted: Vec<Tensor<2>> = groups
            .iter()
            .flatten()
            .map(|velocity| self.wrap(batch.state.clone() + velocity.clone().mul(step.clone())))
            .collect();
        let k = shifted.len();
        let values = self.value_at(
            model,
            earlier.repeat_dim(0, k),
            Tensor::cat(shifted, 0),
            batch.params.clone().repeat_dim(0, k),
        );
        let opponent_maximises = self.hamiltonian_sign >= 0.0;
        let pick = |a: Tensor<2>, b: Tensor<2>, maximise: bool| if maximise { a.max_pair(b) } else { a.min_pair(b) };
        let per_group = k / groups.len();
        let target = (0..groups.len())
            .map(|c| {
                (0..per_group)
                    .map(|o| values.clone().narrow(0, (c * per_group + o) * n, n))
                    .reduce(|a, b| pick(a, b, opponent_maximises))
                    .expect("at least one opponent vertex")
            })
            .reduce(|a, b| pick(a, b, !opponent_maximises))
            .expect("at least one control vertex");
        let gap = value.clone() - error.clone();
        ((value - target.max_pair(error)).div_scalar(self.time_step), gap)
    }

    /// Causal weights `[N, 1]` (constants) for the pointwise losses `[N, 1]`; `None` when causal training
    /// is off.
    fn causal_weights(&self, batch: &Batch, pointwise: &Tensor<2>) -> Option<Tensor<2>> {
        if self.causal_bins == 0 || batch.tau_limit <= 0.0 {
            return None;
        }
        let values = |t: &Tensor<2>| t.clone().into_data().try_to_vec::<f32>().expect("f32 tensor");
        let weights = causal_weights(
            &values(&batch.tau),
            &values(pointwise),
            batch.tau_limit,
            self.causal_bins,
            self.causal_epsilon,
        );
        let n = weights.len();
        Some(Tensor::from_data(TensorData::new(weights, [n, 1]), &pointwise.device()))
    }

    /// The loss at `iteration` and its terms.
    pub fn loss(&self, model: &Siren, batch: &Batch, iteration: u64) -> (Tensor<1>, LossTerms) {
        let (pointwise, gap) = match self.residual {
            Residual::Differential => {
                let v = self.value_terms(model, batch);
                let hamiltonian = self
                    .dynamics
                    .hamiltonian(&batch.state, &v.d_state, &batch.params)
                    .mul_scalar(self.hamiltonian_sign);
                let gap = v.value - v.error;
                (gap.clone().min_pair(v.d_tau - hamiltonian), gap)
            }
            Residual::SemiLagrangian => self.semi_lagrangian(model, batch),
        };
        let pointwise = match self.norm {
            ResidualNorm::L1 => pointwise.abs(),
            ResidualNorm::L2 => pointwise.powi_scalar(2),
        };
        let residual = match self.causal_weights(batch, &pointwise) {
            Some(weights) => pointwise.mul(weights).mean(),
            None => pointwise.mean(),
        };
        let (total, boundary) = match self.form {
            LossForm::ExactBoundary => (residual.clone(), None),
            LossForm::Paper => {
                let boundary = gap.narrow(0, 0, batch.n_boundary).abs().mean();
                let total = if iteration < self.pretrain_iterations {
                    boundary.clone()
                } else {
                    boundary.clone() + residual.clone().mul_scalar(self.lambda)
                };
                (total, Some(boundary))
            }
        };
        let scalar = |t: Tensor<1>| f64::from(t.into_scalar::<f32>());
        let (total, supervision, supervision_gradient) = match &self.supervision {
            Some(grid) => {
                let (value, gradient) = self.supervision_errors(grid, model, iteration, &batch.tau.device());
                let total = total + value.clone().mul_scalar(grid.weight);
                match gradient {
                    Some(g) => (total + g.clone().mul_scalar(grid.gradient_weight), Some(value), Some(g)),
                    None => (total, Some(value), None),
                }
            }
            None => (total, None, None),
        };
        let terms = LossTerms {
            total: scalar(total.clone()),
            boundary: boundary.map_or(0.0, scalar),
            residual: scalar(residual),
            supervision: supervision.map_or(0.0, scalar),
            supervision_gradient: supervision_gradient.map_or(0.0, scalar),
        };
        (total, terms)
    }
}

#[cfg(test)]
mod tests {
    use super::weighted_square_error;
    use burn::tensor::{Device, Tensor, TensorData};

    #[test]
    fn errors_below_the_target_weigh_more() {
        let device = Device::flex().autodiff();
        let error =
            Tensor::<2>::from_data(TensorData::new(vec![-1.0f32, 2.0, -0.5, 0.0], [4, 1]), &device).require_grad();
        let loss = weighted_square_error(error.clone(), 4.0);
        // (4 * 1 + 4 + 4 * 0.25 + 0) / 4 = 2.25
        assert!((loss.clone().into_scalar::<f32>() - 2.25).abs() < 1e-6);
        let gradient: Vec<f32> = error.grad(&loss.backward()).unwrap().into_data().try_to_vec().unwrap();
        // d/de of w e^2 / 4 = w e / 2: the weight is a constant of the gradient.
        assert_eq!(gradient, vec![-2.0, 1.0, -1.0, 0.0]);
        let symmetric = weighted_square_error(error.detach(), 1.0).into_scalar::<f32>();
        assert!((symmetric - 1.3125).abs() < 1e-6);
    }
}
