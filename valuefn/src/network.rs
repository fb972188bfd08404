//! The value network: a SIREN (sine MLP) over normalised `(tau, state, params)`, with an f64 reference
//! evaluation of `V` and `dV/dr`. The ONNX writer compiles the same network into a graph; the trainer
//! produces its weights.

use crate::system::AffineSystem;
use rand::{Rng, SeedableRng};

/// A dense layer `z = W x + b`, `W` row-major `[n_out x n_in]`.
#[derive(Debug, Clone, PartialEq)]
pub struct Dense {
    /// Inputs.
    pub n_in: usize,
    /// Outputs.
    pub n_out: usize,
    /// Weights, row-major `[n_out x n_in]`.
    pub weight: Vec<f64>,
    /// Biases `[n_out]`.
    pub bias: Vec<f64>,
}

impl Dense {
    /// `W x + b`.
    pub fn apply(&self, x: &[f64]) -> Vec<f64> {
        (0..self.n_out)
            .map(|o| {
                self.bias[o]
                    + self.weight[o * self.n_in..(o + 1) * self.n_in].iter().zip(x).map(|(w, v)| w * v).sum::<f64>()
            })
            .collect()
    }

    /// `g W` for a row vector `g` of length `n_out` (back-propagation through the layer).
    pub fn back(&self, g: &[f64]) -> Vec<f64> {
        let mut out = vec![0.0; self.n_in];
        for (o, go) in g.iter().enumerate() {
            for (i, x) in out.iter_mut().enumerate() {
                *x += go * self.weight[o * self.n_in + i];
            }
        }
        out
    }
}

/// Affine map of the raw inputs `(tau, state, params)` onto `[-1, 1]`: `x_n = (x - center) / half_range`.
#[derive(Debug, Clone, PartialEq)]
pub struct InputNormalization {
    /// Centre per input.
    pub center: Vec<f64>,
    /// Half range per input.
    pub half_range: Vec<f64>,
}

/// A SIREN value network `V(tau, r; params)` in physical units.
///
/// Hidden layers compute `h = sin(omega_0 (W h + b))`; the last layer is linear, `y = W h + b`. The value is
/// `V = scale * y + offset`, or with the exact boundary condition `V = l(r) + tau * (scale * y + offset)`.
#[derive(Debug, Clone, PartialEq)]
pub struct ValueNetwork {
    /// Sine frequency `omega_0`.
    pub omega_0: f64,
    /// Hidden layers followed by the linear output layer (`n_out = 1`).
    pub layers: Vec<Dense>,
    /// Input normalisation of `(tau, state, params)`.
    pub input: InputNormalization,
    /// Output scale.
    pub output_scale: f64,
    /// Output offset.
    pub output_offset: f64,
    /// `V = l(r) + tau * NN` instead of `V = NN`.
    pub exact_boundary: bool,
    /// Per state coordinate: `Some((min, period))` if periodic.
    pub periodic: Vec<Option<(f64, f64)>>,
    /// Indices of the error coordinates.
    pub error_coords: Vec<usize>,
}

/// Value and gradient of the network at one point.
#[derive(Debug, Clone, PartialEq)]
pub struct ValueAndGradient {
    /// `V`.
    pub value: f64,
    /// `dV/dr` (physical units).
    pub grad_state: Vec<f64>,
    /// `dV/dtau`.
    pub grad_tau: f64,
}

impl ValueNetwork {
    /// A SIREN-initialised random network for `system` (Sitzmann et al.: first layer `U(-1/n, 1/n)`, later
    /// layers `U(-sqrt(6/n)/omega_0, sqrt(6/n)/omega_0)`), inputs normalised over the domain, `tau` over
    /// `[0, tau_max]`.
    pub fn random(
        system: &AffineSystem,
        hidden: &[usize],
        omega_0: f64,
        tau_max: f64,
        exact_boundary: bool,
        seed: u64,
    ) -> Self {
        let mut rng = rand::rngs::StdRng::seed_from_u64(seed);
        let n_in = 1 + system.n_state() + system.n_params();
        let mut widths = vec![n_in];
        widths.extend_from_slice(hidden);
        widths.push(1);
        let layers = widths
            .windows(2)
            .enumerate()
            .map(|(k, w)| {
                let (n_in, n_out) = (w[0], w[1]);
                let bound = if k == 0 { 1.0 / n_in as f64 } else { (6.0 / n_in as f64).sqrt() / omega_0 };
                Dense {
                    n_in,
                    n_out,
                    weight: (0..n_in * n_out).map(|_| rng.random_range(-bound..bound)).collect(),
                    bias: (0..n_out).map(|_| rng.random_range(-bound..bound)).collect(),
                }
            })
            .collect();
        Self {
            omega_0,
            layers,
            input: Self::normalization_for(system, tau_max),
            output_scale: 1.0,
            output_offset: 0.0,
            exact_boundary,
            periodic: system.state.iter().map(|d| d.periodic.then_some((d.min, d.max - d.min))).collect(),
            error_coords: system.error_coords.clone(),
        }
    }

    /// Normalisation mapping `tau in [0, tau_max]`, the state domain and the parameter ranges onto `[-1, 1]`.
    pub fn normalization_for(system: &AffineSystem, tau_max: f64) -> InputNormalization {
        let mut center = vec![0.5 * tau_max];
        let mut half_range = vec![0.5 * tau_max];
        for d in &system.state {
            center.push(0.5 * (d.min + d.max));
            half_range.push(0.5 * (d.max - d.min));
        }
        for p in &system.params {
            center.push(0.5 * (p.min + p.max));
            half_range.push(0.5 * (p.max - p.min));
        }
        InputNormalization { center, half_range }
    }

    /// Hidden layer widths.
    pub fn hidden_widths(&self) -> Vec<usize> {
        self.layers[..self.layers.len() - 1].iter().map(|l| l.n_out).collect()
    }

    /// Number of state inputs.
    pub fn n_state(&self) -> usize {
        self.periodic.len()
    }

    /// `V` and its gradients at `(tau, r, params)`, in f64.
    pub fn evaluate(&self, tau: f64, state: &[f64], params: &[f64]) -> ValueAndGradient {
        let mut raw = Vec::with_capacity(1 + state.len() + params.len());
        raw.push(tau);
        raw.extend(state.iter().zip(&self.periodic).map(|(&x, p)| match p {
            Some((min, period)) => crate::system::wrap_periodic(x, *min, min + period),
            None => x,
        }));
        raw.extend_from_slice(params);
        let mut h: Vec<f64> =
            raw.iter().zip(&self.input.center).zip(&self.input.half_range).map(|((x, c), s)| (x - c) / s).collect();
        let hidden = &self.layers[..self.layers.len() - 1];
        let mut pre_activations = Vec::with_capacity(hidden.len());
        for layer in hidden {
            let z: Vec<f64> = layer.apply(&h).iter().map(|z| self.omega_0 * z).collect();
            h = z.iter().map(|z| z.sin()).collect();
            pre_activations.push(z);
        }
        let last = &self.layers[self.layers.len() - 1];
        let nn = self.output_scale * last.apply(&h)[0] + self.output_offset;
        // Backward pass: d(nn)/d(normalised inputs).
        let mut g: Vec<f64> = last.weight.iter().map(|w| w * self.output_scale).collect();
        for (layer, z) in hidden.iter().zip(&pre_activations).rev() {
            let gz: Vec<f64> = g.iter().zip(z).map(|(g, z)| g * self.omega_0 * z.cos()).collect();
            g = layer.back(&gz);
        }
        let d_raw: Vec<f64> = g.iter().zip(&self.input.half_range).map(|(g, s)| g / s).collect();
        let n = state.len();
        if self.exact_boundary {
            let l = self.error_coords.iter().map(|&i| state[i] * state[i]).sum::<f64>().sqrt();
            let mut grad_state: Vec<f64> = d_raw[1..1 + n].iter().map(|g| tau * g).collect();
            if l > 0.0 {
                for &i in &self.error_coords {
                    grad_state[i] += state[i] / l;
                }
            }
            ValueAndGradient { value: l + tau * nn, grad_state, grad_tau: nn + tau * d_raw[0] }
        } else {
            ValueAndGradient { value: nn, grad_state: d_raw[1..1 + n].to_vec(), grad_tau: d_raw[0] }
        }
    }
}
