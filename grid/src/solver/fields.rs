//! What a solve precomputes on its grid before stepping: `l(r)`, the dissipation bounds and the drift.

use crate::grid::Grid;
use crate::hamiltonian::Hamiltonian;
use crate::scheme::{Flux, Scheme};
use crate::upwind::Accuracy;
use fastrack_valuefn::system::AffineSystem;
use rayon::prelude::*;

/// `l(r)` at every grid point.
fn tracking_error_field(system: &AffineSystem, grid: &Grid) -> Vec<f64> {
    let n = grid.ndim();
    (0..grid.num_points())
        .into_par_iter()
        .map_init(
            || vec![0.0; n],
            |r, flat| {
                grid.point(flat, r);
                system.tracking_error(r)
            },
        )
        .collect()
}

/// `alpha_i(r) >= |dH/dp_i|` at every grid point, point-major, from [`AffineSystem::dissipation_bounds`].
fn dissipation_field(system: &AffineSystem, params: &[f64], grid: &Grid) -> Vec<f64> {
    let n = grid.ndim();
    let mut alpha = vec![0.0; grid.num_points() * n];
    alpha.par_chunks_mut(n).enumerate().for_each_init(
        || vec![0.0; n],
        |r, (flat, out)| {
            grid.point(flat, r);
            system.dissipation_bounds(r, params, out);
        },
    );
    alpha
}

/// The drift `f(r)` at every grid point, point-major.
fn drift_field(hamiltonian: &Hamiltonian, grid: &Grid) -> Vec<f64> {
    let n = grid.ndim();
    let mut drift = vec![0.0; grid.num_points() * n];
    drift.par_chunks_mut(n).enumerate().for_each_init(
        || vec![0.0; n],
        |r, (flat, out)| {
            grid.point(flat, r);
            hamiltonian.drift(r, out);
        },
    );
    drift
}

/// What a solve precomputes on its grid: the Hamiltonian at the parameters and the fields of `l(r)`, the
/// dissipation bounds and the drift.
pub struct SolveFields {
    /// The Hamiltonian at the solve's parameters.
    pub hamiltonian: Hamiltonian,
    /// `l(r)` at every point (the obstacle of the tracking value, and its initial condition).
    pub l: Vec<f64>,
    alpha: Vec<f64>,
    drift: Vec<f64>,
}

impl SolveFields {
    /// Computes the fields of `system` at `params` on `grid`.
    pub fn new(system: &AffineSystem, params: &[f64], grid: &Grid) -> Self {
        let hamiltonian = Hamiltonian::new(system, params);
        let l = tracking_error_field(system, grid);
        let alpha = dissipation_field(system, params, grid);
        let drift = drift_field(&hamiltonian, grid);
        Self { hamiltonian, l, alpha, drift }
    }

    /// The spatial scheme on `grid` (the one the fields were computed on); `tracking` adds the obstacle `l`.
    pub fn scheme<'a>(&'a self, grid: &'a Grid, accuracy: Accuracy, flux: Flux, tracking: bool) -> Scheme<'a> {
        Scheme {
            flux,
            grid,
            hamiltonian: &self.hamiltonian,
            alpha: &self.alpha,
            drift: &self.drift,
            accuracy,
            obstacle: tracking.then_some(&self.l[..]),
        }
    }
}
