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
pub mod quad10d;
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

/// Where the tracker's motion over the ground (the planner's first two axes) sits in its state: what a
/// robot that starts on its planner at a heading and a speed sets.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum GroundMotion {
    /// A heading angle (0 along +y, pi/2 along +x) and a speed: a car, which has a heading even at rest.
    HeadingAndSpeed {
        /// Index of the heading coordinate.
        heading: usize,
        /// Index of the speed coordinate.
        speed: usize,
    },
    /// Velocity components along x and y: a vehicle that hovers, at rest in the zero state.
    Velocity {
        /// Index of the x velocity.
        x: usize,
        /// Index of the y velocity.
        y: usize,
    },
    /// The state holds no motion over the ground (a single axis).
    None,
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
    /// Where the tracker's motion over the ground sits in the state.
    pub ground_motion: GroundMotion,
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

    /// The relative state of a tracker on its planner (zero position error) moving at `speed` along
    /// `heading` over the ground (0 along +y, pi/2 along +x), every other coordinate zero: where a robot
    /// starts. Errors when the system's state holds no ground motion.
    pub fn start_state(&self, heading: f64, speed: f64) -> Result<Vec<f64>, String> {
        let mut r = vec![0.0; self.n_state()];
        match self.ground_motion {
            GroundMotion::HeadingAndSpeed { heading: h, speed: v } => {
                r[h] = heading;
                r[v] = speed;
                self.wrap(&mut r);
            }
            GroundMotion::Velocity { x, y } => {
                r[x] = speed * heading.sin();
                r[y] = speed * heading.cos();
            }
            GroundMotion::None => {
                return Err(format!("system {} holds no motion over the ground to start with", self.id));
            }
        }
        Ok(r)
    }

    /// The relative state in which the tracker rests on its planner whatever its heading: the zero state of
    /// a system whose ground motion is a velocity (a hovering quadcopter). `None` for a car, whose state at
    /// rest still holds its heading (and its value depends on it), and for a system without ground motion.
    pub fn resting_state(&self) -> Option<Vec<f64>> {
        matches!(self.ground_motion, GroundMotion::Velocity { .. }).then(|| vec![0.0; self.n_state()])
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

    /// The subsystem on the state coordinates `coords` (in that order), with the inputs acting on them and
    /// the parameters bounding its planner inputs, named `id`. It must decouple exactly: the drift of each
    /// chosen coordinate depends on chosen coordinates only, and every input acting on a chosen coordinate
    /// acts on chosen coordinates only. Its Hamiltonian is then the part of this system's Hamiltonian over
    /// those coordinates, so its value function is exact ground truth for them. Errors name what couples.
    pub fn subsystem(
        &self,
        id: &'static str,
        description: &'static str,
        coords: &[usize],
    ) -> Result<AffineSystem, String> {
        let n = self.n_state();
        if let Some(&bad) = coords.iter().find(|&&i| i >= n) {
            return Err(format!("coordinate {bad} does not exist in {} ({n} coordinates)", self.id));
        }
        let new_index = |i: usize| coords.iter().position(|&c| c == i);
        let chosen = |i: usize| new_index(i).is_some();
        let mut terms = Vec::new();
        for (output, t) in self.drift.terms.iter().filter_map(|t| Some((new_index(t.output)?, t))) {
            let mut factors = Vec::with_capacity(t.factors.len());
            for f in &t.factors {
                let (j, remap): (usize, fn(usize) -> Factor) = match *f {
                    Factor::Linear(j) => (j, Factor::Linear),
                    Factor::Sin(j) => (j, Factor::Sin),
                    Factor::Cos(j) => (j, Factor::Cos),
                    Factor::Tan(j) => (j, Factor::Tan),
                };
                let k = new_index(j).ok_or_else(|| {
                    format!(
                        "the drift of {} depends on {}, which is not chosen",
                        self.state[t.output].name, self.state[j].name
                    )
                })?;
                factors.push(remap(k));
            }
            terms.push(DriftTerm { output, coefficient: t.coefficient, factors });
        }
        // The columns of `m` acting on a chosen coordinate, checked to act on no other.
        let columns = |m: &DMatrix<f64>, kind: &str, name: &dyn Fn(usize) -> String| -> Result<Vec<usize>, String> {
            let mut picked = Vec::new();
            for j in 0..m.ncols() {
                let acts: Vec<usize> = (0..n).filter(|&i| m[(i, j)] != 0.0).collect();
                if acts.iter().any(|&i| chosen(i)) {
                    if let Some(&i) = acts.iter().find(|&&i| !chosen(i)) {
                        return Err(format!(
                            "{kind} {} also acts on {}, which is not chosen",
                            name(j),
                            self.state[i].name
                        ));
                    }
                    picked.push(j);
                }
            }
            Ok(picked)
        };
        let controls = columns(&self.g_control, "control", &|j| self.controls[j].name.to_string())?;
        let planner_inputs = columns(&self.g_planner, "planner input", &|j| format!("u_p{j}"))?;
        let disturbances = columns(&self.g_disturbance, "disturbance", &|j| self.disturbances[j].name.to_string())?;
        let planner_dims = columns(&self.planner_to_state, "planner coordinate", &|j| format!("p{j}"))?;
        let mut params: Vec<usize> = planner_inputs.iter().map(|&j| self.planner_input_param[j]).collect();
        params.sort_unstable();
        params.dedup();
        let error_coords: Vec<usize> = self.error_coords.iter().filter_map(|&i| new_index(i)).collect();
        if error_coords.is_empty() {
            return Err("no error coordinate is chosen: the subsystem would have no tracking error".into());
        }
        let pick = |m: &DMatrix<f64>, cols: &[usize]| {
            DMatrix::from_fn(coords.len(), cols.len(), |i, j| m[(coords[i], cols[j])])
        };
        Ok(AffineSystem {
            id,
            description,
            state: coords.iter().map(|&i| self.state[i].clone()).collect(),
            error_coords,
            params: params.iter().map(|&k| self.params[k].clone()).collect(),
            planner_input_param: planner_inputs
                .iter()
                .map(|&j| params.iter().position(|&k| k == self.planner_input_param[j]).unwrap_or_default())
                .collect(),
            controls: controls.iter().map(|&j| self.controls[j].clone()).collect(),
            disturbances: disturbances.iter().map(|&j| self.disturbances[j].clone()).collect(),
            drift: Drift { n_state: coords.len(), terms },
            g_control: pick(&self.g_control, &controls),
            g_planner: pick(&self.g_planner, &planner_inputs),
            g_disturbance: pick(&self.g_disturbance, &disturbances),
            planner_to_state: pick(&self.planner_to_state, &planner_dims),
            ground_motion: match self.ground_motion {
                GroundMotion::HeadingAndSpeed { heading, speed } => match (new_index(heading), new_index(speed)) {
                    (Some(heading), Some(speed)) => GroundMotion::HeadingAndSpeed { heading, speed },
                    _ => GroundMotion::None,
                },
                GroundMotion::Velocity { x, y } => match (new_index(x), new_index(y)) {
                    (Some(x), Some(y)) => GroundMotion::Velocity { x, y },
                    _ => GroundMotion::None,
                },
                GroundMotion::None => GroundMotion::None,
            },
        })
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

    /// The control in the box that best holds the state `s` still: the least-squares solution of
    /// `G_u u = -f(s)`, clamped to the box (a quadcopter's hover thrust; zero for a car, whose drift only
    /// moves its position). A controller with nothing better to start from starts here.
    pub fn resting_control(&self, s: &[f64]) -> Vec<f64> {
        let mut f = vec![0.0; self.n_state()];
        self.drift.eval(s, &mut f);
        let g = &self.g_control;
        let normal = g.transpose() * g;
        let rhs = -(g.transpose() * nalgebra::DVector::from_vec(f));
        let u = normal.lu().solve(&rhs).unwrap_or_else(|| nalgebra::DVector::zeros(self.n_control()));
        self.controls.iter().zip(u.iter()).map(|(c, &u)| u.clamp(c.min, c.max)).collect()
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

/// One axis of a system's exact decomposition ([`decomposition`]).
#[derive(Debug, Clone, PartialEq)]
pub struct DecomposedAxis {
    /// Id of the subsystem solved for this axis (a system of its own in [`by_id`]).
    pub subsystem: &'static str,
    /// The axis' coordinates in the full relative state, in the subsystem's order.
    pub coords: Vec<usize>,
    /// Index of the full system's parameter that is the subsystem's one parameter.
    pub param: usize,
}

/// The exact decomposition of system `id` into subsystems small enough for a grid, if it has one: the axes
/// partition the state, and [`AffineSystem::subsystem`] on each axis' coordinates is its subsystem.
pub fn decomposition(id: &str) -> Option<Vec<DecomposedAxis>> {
    match id {
        quad10d::ID => Some(quad10d::axes()),
        _ => None,
    }
}

/// The closed-form converged tracking error bound `V_min(beta)` of system `id`, if it has one.
pub fn closed_form_teb(id: &str) -> Option<fn(f64) -> f64> {
    match id {
        double_integrator::ID => Some(double_integrator::closed_form_teb),
        quad10d::Z_AXIS_ID => Some(quad10d::z_axis_closed_form_teb),
        _ => None,
    }
}

/// Every system the project defines, by id.
pub fn by_id(id: &str) -> Option<AffineSystem> {
    match id {
        dubins4d::ID => Some(dubins4d::system()),
        double_integrator::ID => Some(double_integrator::system()),
        quad10d::ID => Some(quad10d::system()),
        quad10d::X_AXIS_ID => Some(quad10d::x_axis()),
        quad10d::Z_AXIS_ID => Some(quad10d::z_axis()),
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
pub const SYSTEM_IDS: &[&str] =
    &[dubins4d::ID, double_integrator::ID, quad10d::ID, quad10d::X_AXIS_ID, quad10d::Z_AXIS_ID];
