//! The relative-state space of a system: each coordinate's domain, which coordinates are the position
//! error, and the map `Q` from planner states. Everything needed to form and check a relative state
//! `r = s - Q p`, and nothing of the dynamics. A system definition gives one
//! ([`AffineSystem::state_space`](super::AffineSystem::state_space)) and so does a bundle's manifest
//! ([`Manifest::state_space`](crate::manifest::Manifest::state_space)): the server, which knows no robot,
//! builds its system from the manifest.

use nalgebra::DMatrix;

/// The domain of one relative-state coordinate.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Coordinate {
    /// Lower end (for a periodic coordinate: the start of its period).
    pub min: f64,
    /// Upper end.
    pub max: f64,
    /// Angle-like: wrapped into `[min, max)` instead of leaving the domain.
    pub periodic: bool,
}

impl Coordinate {
    /// `x` wrapped into the period if the coordinate is periodic, else unchanged.
    pub fn wrapped(&self, x: f64) -> f64 {
        if self.periodic {
            wrap_periodic(x, self.min, self.max)
        } else {
            x
        }
    }

    /// True if `x` lies in the domain (always, for a periodic coordinate).
    pub fn contains(&self, x: f64) -> bool {
        self.periodic || (x >= self.min && x <= self.max)
    }
}

/// A system's relative-state space.
#[derive(Debug, Clone, PartialEq)]
pub struct StateSpace {
    /// The coordinates, in state order.
    pub coordinates: Vec<Coordinate>,
    /// Indices of the position-error coordinates (`l(r)` is their Euclidean norm).
    pub error_coords: Vec<usize>,
    /// `Q`, `n_state x planner_dim`: `r = s - Q p`.
    pub planner_to_state: DMatrix<f64>,
}

impl StateSpace {
    /// Number of relative-state (and tracker-state) coordinates.
    pub fn n_state(&self) -> usize {
        self.coordinates.len()
    }

    /// Number of planner state coordinates (columns of `Q`).
    pub fn planner_dim(&self) -> usize {
        self.planner_to_state.ncols()
    }

    /// Relative state `r = s - Q p` of tracker state `s` and planner state `p`, periodic coordinates wrapped.
    pub fn relative_state(&self, tracker: &[f64], planner: &[f64]) -> Vec<f64> {
        let q = &self.planner_to_state;
        self.coordinates
            .iter()
            .enumerate()
            .map(|(i, c)| c.wrapped(tracker[i] - (0..q.ncols()).map(|j| q[(i, j)] * planner[j]).sum::<f64>()))
            .collect()
    }

    /// Wraps the periodic coordinates of `r` into their period.
    pub fn wrap(&self, r: &mut [f64]) {
        wrap_coordinates(self.coordinates.iter().copied(), r);
    }

    /// The first coordinate of `r` outside the domain, if any (periodic coordinates never are).
    pub fn first_outside(&self, r: &[f64]) -> Option<usize> {
        self.coordinates.iter().zip(r).position(|(c, &x)| !c.contains(x))
    }

    /// True if every coordinate of `r` lies in the domain.
    pub fn in_domain(&self, r: &[f64]) -> bool {
        self.first_outside(r).is_none()
    }

    /// Tracking error `l(r)`: the Euclidean norm of the error coordinates.
    pub fn tracking_error(&self, r: &[f64]) -> f64 {
        error_norm(&self.error_coords, r)
    }
}

/// Wraps each periodic coordinate of `r` into its period (shared by [`StateSpace`] and the system
/// definitions, whose hot loops wrap without building a space).
pub(crate) fn wrap_coordinates(coordinates: impl IntoIterator<Item = Coordinate>, r: &mut [f64]) {
    for (x, c) in r.iter_mut().zip(coordinates) {
        *x = c.wrapped(*x);
    }
}

/// The Euclidean norm of `r`'s error coordinates.
pub(crate) fn error_norm(error_coords: &[usize], r: &[f64]) -> f64 {
    error_coords.iter().map(|&i| r[i] * r[i]).sum::<f64>().sqrt()
}

/// `x` wrapped into the period `[min, max)`.
pub fn wrap_periodic(x: f64, min: f64, max: f64) -> f64 {
    let period = max - min;
    x - period * ((x - min) / period).floor()
}
