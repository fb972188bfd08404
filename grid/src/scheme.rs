//! The semi-discrete right-hand side `dV/dtau = H_num(r, D-V, D+V)` on a grid, fused with one TVD
//! Runge-Kutta stage combination and the tracking obstacle `V <- max(V, l)`; parallel over the grid.

use crate::grid::Grid;
use crate::hamiltonian::{Hamiltonian, MAX_STATE};
use crate::upwind::{gather_rows, one_sided_rows, Accuracy, Row};
pub use fastrack_gridfile::settings::{Flux, UnknownFlux};
use rayon::prelude::*;

/// Everything the right-hand side needs besides the values.
pub struct Scheme<'a> {
    /// The grid.
    pub grid: &'a Grid,
    /// The Hamiltonian at the solve's parameters.
    pub hamiltonian: &'a Hamiltonian,
    /// Dissipation coefficients, point-major: `alpha[flat * ndim + i] >= |dH/dp_i|` at that point.
    pub alpha: &'a [f64],
    /// The drift `f(r)` at every point, point-major like `alpha`.
    pub drift: &'a [f64],
    /// Derivative approximation.
    pub accuracy: Accuracy,
    /// Numerical Hamiltonian. [`Flux::Godunov`] needs a separable Hamiltonian ([`Hamiltonian::is_separable`]);
    /// on any other it falls back to Lax-Friedrichs, and [`crate::solver::solve`] refuses that combination.
    pub flux: Flux,
    /// `l(r)` at every point, or `None` to skip the obstacle (the plain terminal-cost value).
    pub obstacle: Option<&'a [f64]>,
}

/// One stage `out = a * base + b * (v + dt * L(v))`, then `out <- max(out, l)`.
#[derive(Debug, Clone, Copy)]
pub struct Stage {
    /// Weight of the step's starting values.
    pub a: f64,
    /// Weight of the Euler step from `v`.
    pub b: f64,
    /// Time step.
    pub dt: f64,
}

/// What a stage measured while writing its output.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct StageSummary {
    /// `max |out - base|` over the grid.
    pub max_change: f64,
    /// `min out` over the grid.
    pub min_value: f64,
}

impl Scheme<'_> {
    /// Time step for a CFL number: `cfl / max_r sum_i alpha_i(r) / h_i`.
    pub fn cfl_step(&self, cfl: f64) -> f64 {
        let inv_h: Vec<f64> = self.grid.axes().iter().map(|a| 1.0 / a.spacing()).collect();
        let rate = self
            .alpha
            .par_chunks(self.grid.ndim())
            .map(|a| a.iter().zip(&inv_h).map(|(x, y)| x * y).sum::<f64>())
            .reduce(|| 0.0, f64::max);
        cfl / rate.max(f64::MIN_POSITIVE)
    }

    /// Runs one stage from `v` into `out` (`base` and `v` may be the same slice), one row of the last axis
    /// at a time.
    pub fn stage(&self, v: &[f64], base: &[f64], stage: Stage, out: &mut [f64]) -> StageSummary {
        let n = self.grid.ndim();
        let len = self.grid.axes()[n - 1].n;
        let half = self.accuracy.half_width();
        out.par_chunks_mut(len)
            .enumerate()
            .map_init(
                || RowBuffers::new(n, len),
                |buffers, (row, out_row)| {
                    let start = row * len;
                    for (k, axis) in self.grid.axes().iter().enumerate() {
                        let line = Row {
                            start,
                            len,
                            node: self.grid.node(start, k),
                            n: axis.n,
                            stride: self.grid.strides()[k],
                            periodic: axis.periodic,
                        };
                        gather_rows(v, line, half, &mut buffers.stencil);
                        let (left, right) = (&mut buffers.left[k * len..][..len], &mut buffers.right[k * len..][..len]);
                        one_sided_rows(self.accuracy, &buffers.stencil, axis.spacing(), left, right);
                    }
                    let mut summary = StageSummary { max_change: 0.0, min_value: f64::INFINITY };
                    let (mut p_left, mut p_right) = ([0.0; MAX_STATE], [0.0; MAX_STATE]);
                    for (i, slot) in out_row.iter_mut().enumerate() {
                        let flat = start + i;
                        for k in 0..n {
                            p_left[k] = buffers.left[k * len + i];
                            p_right[k] = buffers.right[k * len + i];
                        }
                        let point = flat * n..(flat + 1) * n;
                        let (f, left, right) = (&self.drift[point.clone()], &p_left[..n], &p_right[..n]);
                        let rate = match self.flux {
                            Flux::Godunov => self.hamiltonian.godunov(f, left, right),
                            Flux::LaxFriedrichs => None,
                        }
                        .unwrap_or_else(|| self.hamiltonian.lax_friedrichs(f, left, right, &self.alpha[point]));
                        let mut value = stage.a * base[flat] + stage.b * (v[flat] + stage.dt * rate);
                        if let Some(l) = self.obstacle {
                            value = value.max(l[flat]);
                        }
                        *slot = value;
                        summary.max_change = summary.max_change.max((value - base[flat]).abs());
                        summary.min_value = summary.min_value.min(value);
                    }
                    summary
                },
            )
            .reduce(
                || StageSummary { max_change: 0.0, min_value: f64::INFINITY },
                |x, y| StageSummary {
                    max_change: x.max_change.max(y.max_change),
                    min_value: x.min_value.min(y.min_value),
                },
            )
    }
}

/// Per-thread scratch for one row: the stencil rows and the one-sided derivatives along every axis.
struct RowBuffers {
    stencil: [Vec<f64>; 7],
    left: Vec<f64>,
    right: Vec<f64>,
}

impl RowBuffers {
    fn new(ndim: usize, len: usize) -> Self {
        Self {
            stencil: std::array::from_fn(|_| vec![0.0; len]),
            left: vec![0.0; ndim * len],
            right: vec![0.0; ndim * len],
        }
    }
}
