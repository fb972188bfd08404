//! Control- and planner-affine relative systems with box-bounded inputs.
//!
//! Every system has the shape `r' = f(r) + G_u u + G_p u_p + G_d d` with constant matrices and box sets
//! (the planner's box is `[-beta_k, beta_k]` per input, from the value function's parameters). The
//! Hamiltonian, the optimal tracker control, the worst-case planner and disturbance, and the per-dimension
//! bounds on `|dH/dp_i|` used for Lax-Friedrichs dissipation all follow from that shape; a system only
//! supplies its drift, matrices, boxes, error coordinates and domain.

mod boxset;
pub mod double_integrator;
pub mod drift;
pub mod dubins4d;
mod state_space;

pub use boxset::BoxSet;
pub use drift::{Drift, DriftTerm, Factor};
pub use state_space::{wrap_periodic, Coordinate, StateSpace};

use nalgebra::DMatrix;

/// One coordinate of the relative state.
#[derive(Debug, Clone, PartialEq)]
pub struct StateDim {
    /// Name, e.g. `x_r`.
    pub name: &'static str,
    /// Physical unit.
    pub unit: &'static str,
    /// Domain `[min, max]` (for periodic coordinates: one period).
    pub min: f64,
    /// Upper end of the domain.
    pub max: f64,
    /// Angle-like coordinate, wrapped into `[min, max)`.
    pub periodic: bool,
    /// The tracker's own limits `(low, high)` on this coordinate (e.g. its speed range), inside the domain:
    /// at or past a limit the served control never pushes the coordinate further out (see
    /// [`AffineSystem::control_range`]). `None`: unlimited.
    pub limits: Option<(f64, f64)>,
}

/// One named input with box bounds (tracker control or disturbance).
#[derive(Debug, Clone, PartialEq)]
pub struct InputDim {
    /// Name, e.g. `omega`.
    pub name: &'static str,
    /// Physical unit.
    pub unit: &'static str,
    /// Lower bound.
    pub min: f64,
    /// Upper bound.
    pub max: f64,
}

/// One value-function parameter: a planner speed bound `beta_k`.
#[derive(Debug, Clone, PartialEq)]
pub struct ParamDim {
    /// Name, e.g. `beta_1`.
    pub name: &'static str,
    /// Physical unit.
    pub unit: &'static str,
    /// Lower end of the range (`beta_l`).
    pub min: f64,
    /// Upper end of the range (`beta_u`).
    pub max: f64,
}

/// A relative tracker/planner system of the control- and planner-affine shape.
#[derive(Debug, Clone)]
pub struct AffineSystem {
    /// Identifier, e.g. `dubins4d`.
    pub id: &'static str,
    /// One-line description.
    pub description: &'static str,
    /// Relative-state coordinates.
    pub state: Vec<StateDim>,
    /// Indices of the position-error coordinates (`l(r)` is their Euclidean norm).
    pub error_coords: Vec<usize>,
    /// Value-function parameters (planner speed bounds).
    pub params: Vec<ParamDim>,
    /// For each planner input, the index of the parameter bounding it: `|u_p,i| <= beta[k(i)]`.
    pub planner_input_param: Vec<usize>,
    /// Tracker controls.
    pub controls: Vec<InputDim>,
    /// Disturbances (may be empty).
    pub disturbances: Vec<InputDim>,
    /// Drift `f(r)`.
    pub drift: Drift,
    /// `G_u`, `n_state x n_control`.
    pub g_control: DMatrix<f64>,
    /// `G_p`, `n_state x n_planner_inputs`.
    pub g_planner: DMatrix<f64>,
    /// `G_d`, `n_state x n_disturbance`.
    pub g_disturbance: DMatrix<f64>,
    /// `Q`, `n_state x n_planner_state`: `r = s - Q p`.
    pub planner_to_state: DMatrix<f64>,
}

impl AffineSystem {
    /// Number of relative-state coordinates.
    pub fn n_state(&self) -> usize {
        self.state.len()
    }

    /// Number of parameters.
    pub fn n_params(&self) -> usize {
        self.params.len()
    }

    /// Number of tracker controls.
    pub fn n_control(&self) -> usize {
        self.controls.len()
    }

    /// Number of planner state coordinates (columns of `Q`).
    pub fn planner_dim(&self) -> usize {
        self.planner_to_state.ncols()
    }

    /// The tracker's control box.
    pub fn control_box(&self) -> BoxSet {
        BoxSet::new(self.controls.iter().map(|c| c.min).collect(), self.controls.iter().map(|c| c.max).collect())
    }

    /// The planner's box for parameters `params`: `[-beta_k(i), beta_k(i)]` per planner input.
    pub fn planner_box(&self, params: &[f64]) -> BoxSet {
        let hi: Vec<f64> = self.planner_input_param.iter().map(|&k| params[k]).collect();
        BoxSet::new(hi.iter().map(|b| -b).collect(), hi)
    }

    /// The disturbance box.
    pub fn disturbance_box(&self) -> BoxSet {
        BoxSet::new(
            self.disturbances.iter().map(|d| d.min).collect(),
            self.disturbances.iter().map(|d| d.max).collect(),
        )
    }

    /// The same system with every planner input bounded by one shared parameter `beta` (diagonal mode).
    pub fn with_shared_parameter(&self) -> AffineSystem {
        let first = self.params[0].clone();
        let (min, max) =
            self.params.iter().fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), p| (lo.min(p.min), hi.max(p.max)));
        let mut shared = self.clone();
        shared.params = vec![ParamDim { name: "beta", unit: first.unit, min, max }];
        shared.planner_input_param = vec![0; self.planner_input_param.len()];
        shared
    }

    /// The relative-state space: domains, error coordinates and `Q`.
    pub fn state_space(&self) -> StateSpace {
        StateSpace {
            coordinates: self.coordinates().collect(),
            error_coords: self.error_coords.clone(),
            planner_to_state: self.planner_to_state.clone(),
        }
    }

    /// The domain of each coordinate.
    fn coordinates(&self) -> impl Iterator<Item = Coordinate> + '_ {
        self.state.iter().map(|d| Coordinate { min: d.min, max: d.max, periodic: d.periodic })
    }

    /// Tracking error `l(r)`: Euclidean norm of the error coordinates.
    pub fn tracking_error(&self, r: &[f64]) -> f64 {
        state_space::error_norm(&self.error_coords, r)
    }

    /// Wraps periodic coordinates of `r` into their period `[min, max)`.
    pub fn wrap(&self, r: &mut [f64]) {
        state_space::wrap_coordinates(self.coordinates(), r);
    }

    /// `c = M^T p` for a matrix with `n_state` rows.
    fn project(m: &DMatrix<f64>, p: &[f64]) -> Vec<f64> {
        (0..m.ncols()).map(|j| (0..m.nrows()).map(|i| m[(i, j)] * p[i]).sum()).collect()
    }

    /// Relative dynamics `r' = f(r) + G_u u + G_p u_p + G_d d`.
    pub fn dynamics(&self, r: &[f64], u: &[f64], u_p: &[f64], d: &[f64], out: &mut [f64]) {
        self.drift.eval(r, out);
        for (i, o) in out.iter_mut().enumerate() {
            *o += (0..u.len()).map(|j| self.g_control[(i, j)] * u[j]).sum::<f64>()
                + (0..u_p.len()).map(|j| self.g_planner[(i, j)] * u_p[j]).sum::<f64>()
                + (0..d.len()).map(|j| self.g_disturbance[(i, j)] * d[j]).sum::<f64>();
        }
    }

    /// Hamiltonian (horizon form) `H = min_u max_{u_p, d} p . (f + G_u u + G_p u_p + G_d d)`.
    pub fn hamiltonian(&self, r: &[f64], p: &[f64], params: &[f64]) -> f64 {
        let mut f = vec![0.0; self.n_state()];
        self.drift.eval(r, &mut f);
        let drift: f64 = f.iter().zip(p).map(|(a, b)| a * b).sum();
        drift
            + self.control_box().min_dot(&Self::project(&self.g_control, p))
            + self.planner_box(params).max_dot(&Self::project(&self.g_planner, p))
            + self.disturbance_box().max_dot(&Self::project(&self.g_disturbance, p))
    }

    /// Optimal tracker control at `r` for the value gradient `p`: minimises `p . G_u u` over the control
    /// range allowed at `r` ([`AffineSystem::control_range`]; the whole box away from the state limits).
    pub fn optimal_control(&self, r: &[f64], p: &[f64]) -> Vec<f64> {
        self.control_range(r).argmin_dot(&Self::project(&self.g_control, p))
    }

    /// The tracker controls allowed at `r`: the control box, cut at zero for each control that drives a
    /// coordinate at or past one of its [`StateDim::limits`] further out (`G_u[i][j] u_j` must not be > 0
    /// at `r_i >= high`, nor < 0 at `r_i <= low`). [`AffineSystem::check_limits`] makes sure that this
    /// holds the coordinate: nothing else moves it, and zero lies in every such control's range.
    pub fn control_range(&self, r: &[f64]) -> BoxSet {
        let (mut lo, mut hi): (Vec<f64>, Vec<f64>) = self.controls.iter().map(|c| (c.min, c.max)).unzip();
        for (i, dim) in self.state.iter().enumerate() {
            let Some((low, high)) = dim.limits else { continue };
            // +1: the coordinate must not grow; -1: it must not shrink.
            let forbidden = if r[i] >= high {
                1.0
            } else if r[i] <= low {
                -1.0
            } else {
                continue;
            };
            for j in 0..self.n_control() {
                let g = forbidden * self.g_control[(i, j)];
                if g > 0.0 {
                    hi[j] = hi[j].min(0.0);
                } else if g < 0.0 {
                    lo[j] = lo[j].max(0.0);
                }
            }
        }
        BoxSet::new(lo, hi)
    }

    /// Checks that every limited coordinate is held by [`AffineSystem::control_range`]: not periodic, limits
    /// inside the domain, no drift, planner or disturbance acting on it, at least one control driving it, and
    /// zero inside the range of each control driving it.
    pub fn check_limits(&self) -> Result<(), String> {
        for (i, dim) in self.state.iter().enumerate() {
            let Some((low, high)) = dim.limits else { continue };
            let name = dim.name;
            if dim.periodic || !(dim.min <= low && low < high && high <= dim.max) {
                return Err(format!(
                    "{name}: limits [{low}, {high}] must be increasing and inside the domain [{}, {}] of a non-periodic coordinate",
                    dim.min, dim.max
                ));
            }
            let moved_by = |m: &DMatrix<f64>| (0..m.ncols()).any(|j| m[(i, j)] != 0.0);
            if self.drift.terms.iter().any(|t| t.output == i)
                || moved_by(&self.g_planner)
                || moved_by(&self.g_disturbance)
            {
                return Err(format!("{name}: a limited coordinate may be moved by the tracker's controls only"));
            }
            let driving: Vec<&InputDim> =
                (0..self.n_control()).filter(|&j| self.g_control[(i, j)] != 0.0).map(|j| &self.controls[j]).collect();
            if driving.is_empty() {
                return Err(format!("{name}: no control drives this limited coordinate"));
            }
            if let Some(c) = driving.iter().find(|c| !(c.min <= 0.0 && 0.0 <= c.max)) {
                return Err(format!(
                    "{name}: control {} drives it but its range [{}, {}] excludes 0",
                    c.name, c.min, c.max
                ));
            }
        }
        Ok(())
    }

    /// Worst-case planner input: maximises `p . G_p u_p` over the planner box.
    pub fn worst_planner(&self, p: &[f64], params: &[f64]) -> Vec<f64> {
        self.planner_box(params).argmax_dot(&Self::project(&self.g_planner, p))
    }

    /// Worst-case disturbance: maximises `p . G_d d` over the disturbance box.
    pub fn worst_disturbance(&self, p: &[f64]) -> Vec<f64> {
        self.disturbance_box().argmax_dot(&Self::project(&self.g_disturbance, p))
    }

    /// Per-dimension bounds `alpha_i >= |dH/dp_i|` at `r` (Lax-Friedrichs dissipation coefficients).
    pub fn dissipation_bounds(&self, r: &[f64], params: &[f64], out: &mut [f64]) {
        self.drift.eval(r, out);
        let u_abs = self.control_box().abs_max();
        let up_abs = self.planner_box(params).abs_max();
        let d_abs = self.disturbance_box().abs_max();
        for (i, o) in out.iter_mut().enumerate() {
            *o = o.abs()
                + (0..u_abs.len()).map(|j| self.g_control[(i, j)].abs() * u_abs[j]).sum::<f64>()
                + (0..up_abs.len()).map(|j| self.g_planner[(i, j)].abs() * up_abs[j]).sum::<f64>()
                + (0..d_abs.len()).map(|j| self.g_disturbance[(i, j)].abs() * d_abs[j]).sum::<f64>();
        }
    }
}

/// Every system the project defines, by id.
pub fn by_id(id: &str) -> Option<AffineSystem> {
    match id {
        dubins4d::ID => Some(dubins4d::system()),
        double_integrator::ID => Some(double_integrator::system()),
        _ => None,
    }
}

/// The system of a bundle whose manifest names `id` and `n_params` parameters: the system itself, or its
/// shared-parameter form ([`AffineSystem::with_shared_parameter`]) for a diagonal-mode bundle with one
/// parameter. `None` if the id is unknown or the count fits neither.
pub fn for_bundle(id: &str, n_params: usize) -> Option<AffineSystem> {
    let system = by_id(id)?;
    if n_params == system.n_params() {
        Some(system)
    } else if n_params == 1 {
        Some(system.with_shared_parameter())
    } else {
        None
    }
}

/// Ids accepted by [`by_id`].
pub const SYSTEM_IDS: &[&str] = &[dubins4d::ID, double_integrator::ID];
