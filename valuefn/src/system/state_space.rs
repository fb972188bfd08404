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

/// `x` wrapped into the period `[min, max)`, exactly for every finite `x` (the remainder of a division is
/// exact in floating point, so an angle of 1e300 rad wraps to its true residue, not to rounding noise).
pub fn wrap_periodic(x: f64, min: f64, max: f64) -> f64 {
    let wrapped = min + (x - min).rem_euclid(max - min);
    // The remainder of a tiny negative offset rounds up to the whole period.
    if wrapped >= max {
        min
    } else {
        wrapped
    }
}

#[cfg(test)]
mod tests {
    use super::wrap_periodic;
    use std::f64::consts::PI;

    #[test]
    fn periodic_coordinates_wrap_into_their_period_for_every_finite_number() {
        // Ordinary angles: the residue the floor formula gives.
        for x in [-7.0, -PI, -0.3, 0.0, 0.3, PI - 1e-9, 4.0, 12.5] {
            let expected = x - 2.0 * PI * ((x + PI) / (2.0 * PI)).floor();
            assert!((wrap_periodic(x, -PI, PI) - expected).abs() < 1e-12, "{x}");
        }
        // Extremes stay inside the period (the floor formula left f64::MAX far outside it).
        for x in [f64::MAX, -f64::MAX, 1e300, -1e30, f64::MIN_POSITIVE, -1e-18] {
            let w = wrap_periodic(x, -PI, PI);
            assert!((-PI..PI).contains(&w), "{x} wrapped to {w}");
        }
        // A whole number of periods of a power-of-two period is exactly the start of the period.
        assert_eq!(wrap_periodic(2f64.powi(80), 0.0, 2.0), 0.0);
        // A tiny negative offset whose remainder rounds to the whole period wraps to its start.
        assert_eq!(wrap_periodic(-1e-18, 0.0, 2.0 * PI), 0.0);
    }
}
