//! Dense n-dimensional Cartesian grids: axes, row-major indexing (last axis fastest), point coordinates
//! and multilinear interpolation.

use fastrack_valuefn::system::AffineSystem;
use serde::{Deserialize, Serialize};

/// A grid that cannot be built.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum GridError {
    /// The number of resolutions differs from the number of axes.
    #[error("{given} resolutions given for a {expected}-dimensional state")]
    Dimension {
        /// Axes of the state.
        expected: usize,
        /// Resolutions supplied.
        given: usize,
    },
    /// An axis is too coarse or its bounds are not a finite, non-empty interval.
    #[error("axis {axis}: {problem}")]
    Axis {
        /// Axis index.
        axis: usize,
        /// What is wrong.
        problem: String,
    },
    /// No axes, or more than [`MAX_DIMS`].
    #[error("{0} axes; a grid has 1 to {MAX_DIMS}")]
    Rank(usize),
    /// The grid would not fit in memory.
    #[error("{points} grid points are more than the supported {max}")]
    TooLarge {
        /// Requested points.
        points: u128,
        /// Largest supported grid.
        max: usize,
    },
}

/// Largest supported number of grid points (a few copies of `f64` values must fit in memory).
pub const MAX_POINTS: usize = 400_000_000;
/// Most axes a grid may have.
pub const MAX_DIMS: usize = 8;
/// Fewest nodes per axis (the WENO5 stencil spans 7 nodes).
pub const MIN_NODES: usize = 4;

/// One grid axis.
///
/// A non-periodic axis has `n` nodes from `min` to `max` inclusive (spacing `(max - min) / (n - 1)`); a
/// periodic axis has `n` nodes covering `[min, max)` (spacing `(max - min) / n`, node `n` is node `0`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Axis {
    /// Coordinate name.
    pub name: String,
    /// Lower end.
    pub min: f64,
    /// Upper end (one period past `min` when periodic).
    pub max: f64,
    /// Number of nodes.
    pub n: usize,
    /// Wrap-around axis.
    pub periodic: bool,
}

impl Axis {
    /// Node spacing.
    pub fn spacing(&self) -> f64 {
        (self.max - self.min) / if self.periodic { self.n as f64 } else { (self.n - 1) as f64 }
    }

    /// Coordinate of node `i`.
    pub fn coord(&self, i: usize) -> f64 {
        self.min + i as f64 * self.spacing()
    }

    fn check(&self, axis: usize) -> Result<(), GridError> {
        let problem = if self.n < MIN_NODES {
            format!("{} nodes, at least {MIN_NODES} are needed", self.n)
        } else if !(self.min.is_finite() && self.max.is_finite() && self.min < self.max) {
            format!("bounds [{}, {}] are not a finite interval with min < max", self.min, self.max)
        } else {
            return Ok(());
        };
        Err(GridError::Axis { axis, problem })
    }
}

/// A dense grid over a box.
#[derive(Debug, Clone, PartialEq)]
pub struct Grid {
    axes: Vec<Axis>,
    strides: Vec<usize>,
    len: usize,
}

impl Grid {
    /// A grid with these axes (row-major, the last axis varies fastest).
    pub fn new(axes: Vec<Axis>) -> Result<Self, GridError> {
        if axes.is_empty() || axes.len() > MAX_DIMS {
            return Err(GridError::Rank(axes.len()));
        }
        for (k, axis) in axes.iter().enumerate() {
            axis.check(k)?;
        }
        let points: u128 = axes.iter().map(|a| a.n as u128).product();
        if points > MAX_POINTS as u128 {
            return Err(GridError::TooLarge { points, max: MAX_POINTS });
        }
        let mut strides = vec![1; axes.len()];
        for k in (0..axes.len().saturating_sub(1)).rev() {
            strides[k] = strides[k + 1] * axes[k + 1].n;
        }
        Ok(Self { axes, strides, len: points as usize })
    }

    /// The grid over a system's state domain with `resolution[k]` nodes on axis `k`.
    pub fn for_system(system: &AffineSystem, resolution: &[usize]) -> Result<Self, GridError> {
        if resolution.len() != system.n_state() {
            return Err(GridError::Dimension { expected: system.n_state(), given: resolution.len() });
        }
        Self::new(
            system
                .state
                .iter()
                .zip(resolution)
                .map(|(d, &n)| Axis { name: d.name.into(), min: d.min, max: d.max, n, periodic: d.periodic })
                .collect(),
        )
    }

    /// The axes.
    pub fn axes(&self) -> &[Axis] {
        &self.axes
    }

    /// Number of dimensions.
    pub fn ndim(&self) -> usize {
        self.axes.len()
    }

    /// Number of points.
    pub fn num_points(&self) -> usize {
        self.len
    }

    /// Flat-index step of each axis.
    pub fn strides(&self) -> &[usize] {
        &self.strides
    }

    /// Node index along `axis` of the point with flat index `flat`.
    pub fn node(&self, flat: usize, axis: usize) -> usize {
        flat / self.strides[axis] % self.axes[axis].n
    }

    /// Coordinates of the point with flat index `flat`, written into `out`.
    pub fn point(&self, flat: usize, out: &mut [f64]) {
        for (k, (o, axis)) in out.iter_mut().zip(&self.axes).enumerate() {
            *o = axis.coord(self.node(flat, k));
        }
    }

    /// Multilinear interpolation of grid `values` at `x`: periodic axes wrap, others clamp to the box.
    pub fn interpolate(&self, values: &[f64], x: &[f64]) -> f64 {
        let d = self.ndim();
        let mut base = [0usize; MAX_DIMS];
        let mut next = [0usize; MAX_DIMS];
        let mut frac = [0f64; MAX_DIMS];
        for (k, axis) in self.axes.iter().enumerate() {
            let h = axis.spacing();
            let mut t = (x[k] - axis.min) / h;
            if axis.periodic {
                t = t.rem_euclid(axis.n as f64);
                let i = (t.floor() as usize).min(axis.n - 1);
                base[k] = i;
                next[k] = (i + 1) % axis.n;
                frac[k] = t - i as f64;
            } else {
                t = t.clamp(0.0, (axis.n - 1) as f64);
                let i = (t.floor() as usize).min(axis.n - 2);
                base[k] = i;
                next[k] = i + 1;
                frac[k] = t - i as f64;
            }
        }
        (0..1usize << d)
            .map(|corner| {
                let mut weight = 1.0;
                let mut flat = 0;
                for k in 0..d {
                    let upper = corner >> k & 1 == 1;
                    weight *= if upper { frac[k] } else { 1.0 - frac[k] };
                    flat += self.strides[k] * if upper { next[k] } else { base[k] };
                }
                weight * values[flat]
            })
            .sum()
    }
}
