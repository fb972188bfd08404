//! The value network: a SIREN (sine MLP) over normalised `(tau, state, params)`, with an f64 reference
//! evaluation of `V` and `dV/dr`. The ONNX writer compiles the same network into a graph; the trainer
//! produces its weights.

use crate::system::AffineSystem;
use rand::{Rng, SeedableRng};
use serde::{Deserialize, Serialize};
use std::f64::consts::PI;

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

/// How periodic state coordinates enter the network.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum PeriodicEncoding {
    /// The coordinate wrapped into its period and normalised onto `[-1, 1)`, like any other input: the two
    /// ends of the period are far-apart inputs, so the network is continuous across the seam only as far as
    /// training made it.
    Wrap,
    /// `(cos(pi x), sin(pi x))` of the normalised coordinate `x`: the network is periodic by construction.
    #[default]
    Circle,
}

/// Which first-layer features the normalised inputs `x = (tau, state, params)` become: the `passthrough`
/// inputs as they are, in order, then `(cos(pi x_i), sin(pi x_i))` for each input `i` of `circles`.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct FeatureLayout {
    /// Number of normalised inputs.
    pub n_inputs: usize,
    /// Inputs fed to the first layer unchanged.
    pub passthrough: Vec<usize>,
    /// Inputs fed as a `(cos, sin)` pair, after the passthrough features.
    pub circles: Vec<usize>,
}

impl FeatureLayout {
    /// The layout for `n_inputs` inputs of which `periodic` (input indices) are periodic.
    pub fn new(n_inputs: usize, periodic: &[usize], encoding: PeriodicEncoding) -> Self {
        let circles: Vec<usize> = match encoding {
            PeriodicEncoding::Wrap => Vec::new(),
            PeriodicEncoding::Circle => periodic.to_vec(),
        };
        let passthrough = (0..n_inputs).filter(|i| !circles.contains(i)).collect();
        Self { n_inputs, passthrough, circles }
    }

    /// The layout of a network over `system`'s inputs `(tau, state, params)`.
    pub fn for_system(system: &AffineSystem, encoding: PeriodicEncoding) -> Self {
        let periodic: Vec<usize> = (0..system.n_state()).filter(|&j| system.state[j].periodic).map(|j| 1 + j).collect();
        Self::new(1 + system.n_state() + system.n_params(), &periodic, encoding)
    }

    /// Number of first-layer features.
    pub fn n_features(&self) -> usize {
        self.passthrough.len() + 2 * self.circles.len()
    }

    /// Feature index of the `(cos, sin)` pair of the `k`-th circle input.
    pub fn circle_features(&self, k: usize) -> (usize, usize) {
        let first = self.passthrough.len() + 2 * k;
        (first, first + 1)
    }

    /// The features of normalised inputs `x`.
    pub fn encode(&self, x: &[f64]) -> Vec<f64> {
        let mut features: Vec<f64> = self.passthrough.iter().map(|&i| x[i]).collect();
        for &i in &self.circles {
            features.push((PI * x[i]).cos());
            features.push((PI * x[i]).sin());
        }
        features
    }

    /// `dy/dx` from `dy/dfeatures` at normalised inputs `x` (the chain rule through [`Self::encode`]).
    pub fn input_gradient(&self, x: &[f64], feature_gradient: &[f64]) -> Vec<f64> {
        let mut g = vec![0.0; self.n_inputs];
        for (f, &i) in self.passthrough.iter().enumerate() {
            g[i] = feature_gradient[f];
        }
        for (k, &i) in self.circles.iter().enumerate() {
            let (c, s) = self.circle_features(k);
            g[i] = PI * (-(PI * x[i]).sin() * feature_gradient[c] + (PI * x[i]).cos() * feature_gradient[s]);
        }
        g
    }
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
    /// How the periodic coordinates enter the first layer.
    pub periodic_encoding: PeriodicEncoding,
}

/// The architecture of a network: what [`ValueNetwork::random`] initialises.
#[derive(Debug, Clone, PartialEq)]
pub struct NetworkShape {
    /// Hidden layer widths.
    pub hidden: Vec<usize>,
    /// Sine frequency `omega_0`.
    pub omega_0: f64,
    /// `V = l(r) + tau * NN` instead of `V = NN`.
    pub exact_boundary: bool,
    /// How periodic coordinates enter the first layer.
    pub periodic_encoding: PeriodicEncoding,
}

impl NetworkShape {
    /// `hidden` sine layers at `omega_0`, periodic coordinates on the circle.
    pub fn new(hidden: &[usize], omega_0: f64, exact_boundary: bool) -> Self {
        Self { hidden: hidden.to_vec(), omega_0, exact_boundary, periodic_encoding: PeriodicEncoding::Circle }
    }
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
    /// `[0, tau_max]`, periodic coordinates encoded as `periodic_encoding` says.
    pub fn random(system: &AffineSystem, shape: &NetworkShape, tau_max: f64, seed: u64) -> Self {
        let mut rng = rand::rngs::StdRng::seed_from_u64(seed);
        let NetworkShape { hidden, omega_0, exact_boundary, periodic_encoding } = shape.clone();
        let n_in = FeatureLayout::for_system(system, periodic_encoding).n_features();
        let mut widths = vec![n_in];
        widths.extend_from_slice(&hidden);
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
            periodic_encoding,
        }
    }

    /// How the normalised inputs become the first layer's features.
    pub(crate) fn feature_layout(&self) -> FeatureLayout {
        let periodic: Vec<usize> =
            self.periodic.iter().enumerate().filter(|(_, p)| p.is_some()).map(|(j, _)| 1 + j).collect();
        FeatureLayout::new(self.input.center.len(), &periodic, self.periodic_encoding)
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
        let x: Vec<f64> =
            raw.iter().zip(&self.input.center).zip(&self.input.half_range).map(|((x, c), s)| (x - c) / s).collect();
        let layout = self.feature_layout();
        let mut h = layout.encode(&x);
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
        let d_raw: Vec<f64> =
            layout.input_gradient(&x, &g).iter().zip(&self.input.half_range).map(|(g, s)| g / s).collect();
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
