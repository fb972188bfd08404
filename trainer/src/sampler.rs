//! Collocation points: uniform over the state domain, the parameter ranges and the (curriculum) horizon,
//! a share at `tau = 0`; reproducible per iteration from the seed, so a resumed run draws the same points.

use burn::tensor::{Device, Tensor, TensorData};
use fastrack_valuefn::network::InputNormalization;
use fastrack_valuefn::system::AffineSystem;
use rand::{Rng, SeedableRng};

/// One iteration's points.
pub struct Batch {
    /// Horizon `[N, 1]`.
    pub tau: Tensor<2>,
    /// Relative states `[N, n_state]`.
    pub state: Tensor<2>,
    /// Parameters `[N, n_params]`.
    pub params: Tensor<2>,
    /// Normalised network input `(tau, state, params)` `[N, 1 + n_state + n_params]`.
    pub input: Tensor<2>,
    /// The first `n_boundary` rows have `tau = 0`.
    pub n_boundary: usize,
    /// Largest horizon the batch was drawn with.
    pub tau_limit: f64,
}

/// Draws batches for a system.
pub struct Sampler {
    system: AffineSystem,
    normalization: InputNormalization,
    points: usize,
    n_boundary: usize,
    seed: u64,
    focus_share: f64,
    focus_scale: f64,
    tau_exponent: f64,
}

impl Sampler {
    /// A sampler of `points` points per batch, `boundary_share` of them at `tau = 0`.
    pub fn new(
        system: &AffineSystem,
        normalization: InputNormalization,
        points: usize,
        boundary_share: f64,
        seed: u64,
    ) -> Self {
        let n_boundary = (boundary_share * points as f64).round() as usize;
        Self {
            system: system.clone(),
            normalization,
            points,
            n_boundary,
            seed,
            focus_share: 0.0,
            focus_scale: 1.0,
            tau_exponent: 1.0,
        }
    }

    /// Draws horizons as `tau_limit * u^exponent` (`u` uniform), crowding them at short horizons when
    /// `exponent > 1`.
    pub fn with_tau_exponent(self, exponent: f64) -> Self {
        Self { tau_exponent: exponent, ..self }
    }

    /// Draws `share` of the points (after the `tau = 0` ones) from the state domain shrunk by `scale` about
    /// its centre; periodic coordinates keep their full period.
    pub fn with_focus(self, share: f64, scale: f64) -> Self {
        Self { focus_share: share, focus_scale: scale, ..self }
    }

    /// The batch of `iteration`, with horizons drawn from `[0, tau_limit]`.
    pub fn batch(&self, iteration: u64, tau_limit: f64, device: &Device) -> Batch {
        let mut rng = rand::rngs::StdRng::seed_from_u64(self.seed ^ iteration.wrapping_mul(0x9E37_79B9_7F4A_7C15));
        let (ns, np) = (self.system.n_state(), self.system.n_params());
        let n = self.points;
        let mut tau = Vec::with_capacity(n);
        let mut state = Vec::with_capacity(n * ns);
        let mut params = Vec::with_capacity(n * np);
        let mut input = Vec::with_capacity(n * (1 + ns + np));
        let (c, s) = (&self.normalization.center, &self.normalization.half_range);
        let n_focus = (self.focus_share * (n - self.n_boundary) as f64).round() as usize;
        for i in 0..n {
            let t = if i < self.n_boundary || tau_limit <= 0.0 {
                0.0
            } else {
                tau_limit * rng.random_range(0.0..1.0f64).powf(self.tau_exponent)
            };
            let scale = if i >= n - n_focus { self.focus_scale } else { 1.0 };
            let r: Vec<f64> = self
                .system
                .state
                .iter()
                .map(|d| {
                    let (mid, half) = (0.5 * (d.min + d.max), 0.5 * (d.max - d.min));
                    let half = if d.periodic { half } else { half * scale };
                    rng.random_range(mid - half..mid + half)
                })
                .collect();
            let p: Vec<f64> = self.system.params.iter().map(|d| rng.random_range(d.min..=d.max)).collect();
            tau.push(t as f32);
            input.push(((t - c[0]) / s[0]) as f32);
            for (j, &x) in r.iter().enumerate() {
                state.push(x as f32);
                input.push(((x - c[1 + j]) / s[1 + j]) as f32);
            }
            for (k, &x) in p.iter().enumerate() {
                params.push(x as f32);
                input.push(((x - c[1 + ns + k]) / s[1 + ns + k]) as f32);
            }
        }
        let t2 = |v: Vec<f32>, cols: usize| Tensor::from_data(TensorData::new(v, [n, cols]), device);
        Batch {
            tau: t2(tau, 1),
            state: t2(state, ns),
            params: t2(params, np),
            input: t2(input, 1 + ns + np),
            n_boundary: self.n_boundary,
            tau_limit,
        }
    }
}
