//! A value function composed of axis networks, for a system with an exact decomposition
//! ([`decomposition`]): one network per axis subsystem, evaluated on the axis' coordinates and parameter, and
//! combined into `V(r) = sqrt(sum_a max(V_a(r_a), 0)^2)`.
//!
//! Each axis' value bounds its own future error from its state under its optimal control, and does not grow
//! along those trajectories, so `V` bounds the Euclidean error of the whole and does not grow either: the
//! sublevel set `{V <= L}` is invariant and its error is at most `L`. Its minimum is `sqrt(sum_a V_min,a^2)`,
//! the bound the axes combine into. The gradient is the chain rule's,
//! `dV/dr_a = (max(V_a, 0) / V) dV_a/dr_a`; the control is each axis' own control law on its own gradient
//! (the same as the system's law on `dV/dr` wherever every `V_a > 0`, and still defined where one is not).

use crate::network::ValueNetwork;
use crate::system::{by_id, decomposition, AffineSystem, DecomposedAxis};

/// One axis: its place in the decomposition, its subsystem and the network trained on it.
#[derive(Debug, Clone)]
pub struct AxisNetwork {
    /// The axis' coordinates and parameter in the full system.
    pub axis: DecomposedAxis,
    /// The subsystem the network was trained on.
    pub subsystem: AffineSystem,
    /// The axis' value network.
    pub network: ValueNetwork,
    /// The horizon the network is evaluated at (s).
    pub tau: f64,
}

/// Axis networks that do not fit the system's decomposition.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum CompositeError {
    /// The system has no decomposition.
    #[error("system `{0}` has no decomposition into axes")]
    NotDecomposed(String),
    /// The axes given are not the system's decomposition, in order.
    #[error("axis {index}: {reason}")]
    Axis {
        /// Position of the axis in the decomposition.
        index: usize,
        /// What does not fit.
        reason: String,
    },
}

/// The composed value function of a decomposed system ([`Composite::new`] checks its axes).
#[derive(Debug, Clone)]
pub struct Composite {
    system: AffineSystem,
    axes: Vec<AxisNetwork>,
}

/// `V`, `dV/dr` and the control at one state.
#[derive(Debug, Clone, PartialEq)]
pub struct CompositeEvaluation {
    /// `V(r)`.
    pub value: f64,
    /// `dV/dr`.
    pub grad: Vec<f64>,
    /// The tracker control.
    pub control: Vec<f64>,
}

/// Floor of `V` in the chain rule's division (where every axis' value is 0, the gradient is 0).
pub const VALUE_FLOOR: f64 = 1e-12;

impl Composite {
    /// Composes `axes` for `system`: they must be its decomposition's axes in order, each network of its
    /// axis' subsystem.
    pub fn new(system: AffineSystem, axes: Vec<AxisNetwork>) -> Result<Self, CompositeError> {
        let expected = decomposition(system.id).ok_or_else(|| CompositeError::NotDecomposed(system.id.into()))?;
        if axes.len() != expected.len() {
            return Err(CompositeError::Axis {
                index: axes.len().min(expected.len()),
                reason: format!("{} axes given; {} has {}", axes.len(), system.id, expected.len()),
            });
        }
        for (index, (given, want)) in axes.iter().zip(&expected).enumerate() {
            let fail = |reason: String| Err(CompositeError::Axis { index, reason });
            if given.axis != *want {
                return fail(format!("{:?} given where {} has {:?}", given.axis, system.id, want));
            }
            let known = by_id(want.subsystem).map(|s| s.id);
            if given.subsystem.id != want.subsystem || known.is_none() {
                return fail(format!("subsystem `{}` given where `{}` is", given.subsystem.id, want.subsystem));
            }
            if given.network.n_state() != want.coords.len() || given.network.input.center.len() != 2 + want.coords.len()
            {
                return fail(format!(
                    "the network takes {} state coordinates and {} parameters; the axis has {} and 1",
                    given.network.n_state(),
                    given.network.input.center.len().saturating_sub(1 + given.network.n_state()),
                    want.coords.len()
                ));
            }
        }
        Ok(Self { system, axes })
    }

    /// The full system.
    pub fn system(&self) -> &AffineSystem {
        &self.system
    }

    /// The axes, in the decomposition's order.
    pub fn axes(&self) -> &[AxisNetwork] {
        &self.axes
    }

    /// `V`, `dV/dr` and the control at state `r` and the full system's parameters `params`.
    pub fn evaluate(&self, r: &[f64], params: &[f64]) -> CompositeEvaluation {
        let n = self.system.n_state();
        let mut wrapped = r.to_vec();
        self.system.wrap(&mut wrapped);
        let parts: Vec<(f64, Vec<f64>)> = self
            .axes
            .iter()
            .map(|a| {
                let sub: Vec<f64> = a.axis.coords.iter().map(|&i| wrapped[i]).collect();
                let e = a.network.evaluate(a.tau, &sub, &[params[a.axis.param]]);
                (e.value.max(0.0), e.grad_state)
            })
            .collect();
        let value = parts.iter().map(|(v, _)| v * v).sum::<f64>().sqrt();
        let (mut grad, mut axis_grad) = (vec![0.0; n], vec![0.0; n]);
        for (a, (v, g)) in self.axes.iter().zip(&parts) {
            for (&i, &gi) in a.axis.coords.iter().zip(g) {
                grad[i] = v / value.max(VALUE_FLOOR) * gi;
                axis_grad[i] = gi;
            }
        }
        let control = self.system.optimal_control(&wrapped, &axis_grad);
        CompositeEvaluation { value, grad, control }
    }
}
