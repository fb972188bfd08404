//! Supervision by grid solutions (optional): beside the HJI residual, the network's value (and optionally
//! `dV/dr`) at each solution's horizon is pulled towards the grid solution's interpolant, at points drawn
//! within its cells and, with one network parameter, at any `beta` between two solutions.
//!
//! The residual alone does not hold the kink at the value's minimum (README, "Where training stands"), so
//! the learned bound drifts; ground truth where a grid solver can compute it (dubins4d whole, the 13-D
//! quadcopter through its exact 4-D/4-D/2-D split) anchors it. The residual still shapes the shorter
//! horizons, which the served graph (fixed at `tau_max`) does not use.

use crate::config::{GradientMetric, SupervisionConfig};
use burn::tensor::{Device, Tensor, TensorData};
use fastrack_gridfile::format::{load, FormatError};
use fastrack_gridfile::solution::Solution;
use fastrack_gridfile::spec::{SolutionStore, StoreError};
use fastrack_valuefn::system::AffineSystem;
use rand::{Rng, SeedableRng};
use std::path::PathBuf;

/// A grid solution that cannot supervise this training run.
#[derive(Debug, thiserror::Error)]
pub enum SupervisionError {
    /// The file cannot be read or is not a solution.
    #[error(transparent)]
    Format(#[from] FormatError),
    /// A solution the config names is not in its store, or its file holds another solve.
    #[error("{0}; make the config's grid solutions with `fastrack-grid solve --config <the training config>`")]
    Store(#[from] StoreError),
    /// The solution does not fit the system, its domain, its parameters or the trained horizon.
    #[error("{path}: {problem}")]
    Mismatch {
        /// The solution file.
        path: PathBuf,
        /// What does not fit, and what is allowed.
        problem: String,
    },
}

/// One solution and how it enters the network.
struct Supervised {
    solution: Solution,
    /// The network's parameter inputs for it (one shared `beta` in diagonal mode).
    params: Vec<f32>,
    /// Nodes of `{V <= focus_factor * V_min}`, where the tracking error bound lies.
    near_minimum: Vec<usize>,
}

/// Target values drawn for one iteration.
pub struct SupervisionBatch {
    /// Horizon `[M, 1]` (each solution's own).
    pub tau: Tensor<2>,
    /// Relative states `[M, n_state]` (within the grid's cells).
    pub state: Tensor<2>,
    /// Parameters `[M, n_params]`.
    pub params: Tensor<2>,
    /// Grid values `[M, 1]`.
    pub target: Tensor<2>,
    /// The grid's `dV/dr` `[M, n_state]`: central differences of the interpolated values over one cell.
    pub target_gradient: Tensor<2>,
    /// Weights `[M, n_state]` of each axis' squared `dV/dr` error (all 1 with the Euclidean metric).
    pub gradient_weights: Tensor<2>,
}

/// Grid solutions and how many points each iteration draws.
pub struct GridSupervision {
    /// Sorted by parameter when `blend_in_beta`.
    solutions: Vec<Supervised>,
    /// One network parameter and several solutions: targets at any `beta` between two solutions.
    blend_in_beta: bool,
    points: usize,
    focus_share: f64,
    /// Share of the rows drawn at a solution's own parameters, anywhere in its grid.
    own_grid_share: f64,
    /// Share of the rows drawn on the zero-error slice.
    slice_share: f64,
    /// The system's error coordinates (0 on the slice).
    error_coords: Vec<usize>,
    seed: u64,
    /// Weight of the value error.
    pub weight: f64,
    /// Weight of the `dV/dr` error (0: values only).
    pub gradient_weight: f64,
    /// Multiplies the squared value error where the network is below the target.
    pub under_weight: f64,
    /// How the `dV/dr` error is weighted across the axes.
    gradient_metric: GradientMetric,
    /// The trained system (for the Hamiltonian metric's dissipation bounds).
    system: AffineSystem,
}

impl GridSupervision {
    /// Loads the solutions `config` names from its store (each checked to be its spec's solve) and checks
    /// them as [`GridSupervision::from_files`] does.
    pub fn load(
        config: &SupervisionConfig,
        system: &AffineSystem,
        tau_max: f64,
        seed: u64,
    ) -> Result<Self, SupervisionError> {
        let store = SolutionStore::new(&config.store);
        let solutions = config
            .solutions
            .specs()
            .iter()
            .map(|spec| Ok((store.path(spec), store.load(spec)?)))
            .collect::<Result<Vec<_>, SupervisionError>>()?;
        Self::from_solutions(config, solutions, system, tau_max, seed)
    }

    /// Loads and checks the solution files `paths` against the trained `system` (in its parameter mode) and
    /// the largest trained horizon `tau_max`, to supervise as `config` says. With one network parameter and
    /// several solutions, they must share one horizon and have distinct `beta`; their grids may differ (a
    /// domain scaled to each `beta`'s error set) but each must overlap the next.
    pub fn from_files(
        config: &SupervisionConfig,
        paths: &[PathBuf],
        system: &AffineSystem,
        tau_max: f64,
        seed: u64,
    ) -> Result<Self, SupervisionError> {
        let solutions =
            paths.iter().map(|path| Ok((path.clone(), load(path)?))).collect::<Result<_, SupervisionError>>()?;
        Self::from_solutions(config, solutions, system, tau_max, seed)
    }

    /// Checks `solutions` (each with its file) as [`GridSupervision::from_files`] says.
    fn from_solutions(
        config: &SupervisionConfig,
        solutions: Vec<(PathBuf, Solution)>,
        system: &AffineSystem,
        tau_max: f64,
        seed: u64,
    ) -> Result<Self, SupervisionError> {
        let mut solutions = solutions
            .into_iter()
            .map(|(path, solution)| {
                let mismatch = |problem: String| SupervisionError::Mismatch { path: path.clone(), problem };
                check_fits(&solution, system, tau_max).map_err(mismatch)?;
                let params = network_params(&solution.info.params, system).map_err(mismatch)?;
                let v_min = solution.v_min();
                let near_minimum =
                    (0..solution.values.len()).filter(|&i| solution.values[i] <= config.focus_factor * v_min).collect();
                Ok((path, Supervised { solution, params, near_minimum }))
            })
            .collect::<Result<Vec<_>, SupervisionError>>()?;
        let blend_in_beta = system.n_params() == 1 && solutions.len() > 1;
        if blend_in_beta {
            solutions.sort_by(|a, b| a.1.params[0].total_cmp(&b.1.params[0]));
            let (first_path, first) = &solutions[0];
            for (path, s) in &solutions[1..] {
                let mismatch = |problem: String| SupervisionError::Mismatch { path: path.clone(), problem };
                if s.solution.info.horizon != first.solution.info.horizon {
                    return Err(mismatch(format!(
                        "blending in beta needs one horizon for every solution; {} is at {} s, this one at {} s",
                        first_path.display(),
                        first.solution.info.horizon,
                        s.solution.info.horizon
                    )));
                }
            }
            for pair in solutions.windows(2) {
                let (a, b) = (&pair[0].1.solution.grid, &pair[1].1.solution.grid);
                let mismatch = |problem: String| SupervisionError::Mismatch { path: pair[1].0.clone(), problem };
                for (x, y) in a.axes().iter().zip(b.axes()) {
                    if x.name != y.name || x.periodic != y.periodic || x.max.min(y.max) <= x.min.max(y.min) {
                        return Err(mismatch(format!(
                            "axis `{}` [{}, {}] does not overlap `{}` [{}, {}] of {}, the solution at the next lower beta",
                            y.name,
                            y.min,
                            y.max,
                            x.name,
                            x.min,
                            x.max,
                            pair[0].0.display()
                        )));
                    }
                }
            }
            if let Some(w) = solutions.windows(2).find(|w| w[0].1.params == w[1].1.params) {
                return Err(SupervisionError::Mismatch {
                    path: w[1].0.clone(),
                    problem: format!("a second solution at beta = {}", w[1].1.params[0]),
                });
            }
        }
        for (path, s) in &solutions {
            if s.solution.info.horizon != tau_max {
                tracing::warn!(
                    file = %path.display(),
                    horizon = s.solution.info.horizon,
                    tau_max,
                    "a solution supervises a horizon other than sampling.tau_max, the one the exported graph serves"
                );
            }
            tracing::info!(
                file = %path.display(),
                params = ?s.params,
                horizon = s.solution.info.horizon,
                nodes = s.solution.values.len(),
                near_minimum = s.near_minimum.len(),
                "grid supervision"
            );
        }
        let solutions = solutions.into_iter().map(|(_, s)| s).collect();
        Ok(Self {
            solutions,
            blend_in_beta,
            points: config.points,
            focus_share: config.focus_share,
            own_grid_share: config.own_grid_share,
            slice_share: config.slice_share,
            error_coords: system.error_coords.clone(),
            seed,
            weight: config.weight,
            gradient_weight: config.gradient_weight,
            under_weight: config.under_weight,
            gradient_metric: config.gradient_metric,
            system: system.clone(),
        })
    }

    /// The targets drawn at `iteration` (reproducible from the seed).
    ///
    /// Each row takes a pair of solutions `(a, b)` and a blend weight `w`: with `blend_in_beta`, `beta` is
    /// drawn uniformly between the first and last solution's, `a` and `b` are the solutions on either side and
    /// the target is `(1 - w) V_a + w V_b` (`V` is nondecreasing in `beta`, since a faster planner only helps
    /// the adversary, so the blend lies between the two); otherwise, and for the last `own_grid_share` of the
    /// rows, the solutions are taken in turn with `w = 0`, so such a point may lie anywhere in its grid. The
    /// point is a node of the nearer solution (a `focus_share` of them from near its minimum), moved uniformly
    /// within its cell and drawn again until it also lies in the other solution's grid, and the values there
    /// are each grid's multilinear interpolation: points between the nodes keep the sine network from fitting
    /// the nodes while it oscillates between them.
    pub fn batch(&self, iteration: u64, device: &Device) -> SupervisionBatch {
        let mut rng = rand::rngs::StdRng::seed_from_u64(self.seed ^ iteration.wrapping_mul(0xD1B5_4A32_D192_ED03));
        let m = self.points;
        let n_state = self.solutions[0].solution.grid.ndim();
        let n_params = self.solutions[0].params.len();
        let n_focus = (self.focus_share * m as f64).round() as usize;
        let first_own = m - (self.own_grid_share * m as f64).round() as usize;
        let first_slice = first_own.saturating_sub((self.slice_share * m as f64).round() as usize);
        let (mut tau, mut state, mut params, mut target) = (
            Vec::with_capacity(m),
            Vec::with_capacity(m * n_state),
            Vec::with_capacity(m * n_params),
            Vec::with_capacity(m),
        );
        let mut target_gradient = Vec::with_capacity(m * n_state);
        let mut gradient_weights = Vec::with_capacity(m * n_state);
        let (mut x, mut alpha) = (vec![0.0; n_state], vec![0.0; n_state]);
        for i in 0..m {
            let (a, b, w) = if self.blend_in_beta && i < first_own {
                let (lo, hi) = (self.solutions[0].params[0], self.solutions[self.solutions.len() - 1].params[0]);
                let beta = rng.random_range(lo..=hi);
                let k = self.solutions.partition_point(|s| s.params[0] <= beta).clamp(1, self.solutions.len() - 1);
                let (a, b) = (&self.solutions[k - 1], &self.solutions[k]);
                (a, b, f64::from((beta - a.params[0]) / (b.params[0] - a.params[0])))
            } else {
                let s = &self.solutions[i % self.solutions.len()];
                (s, s, 0.0)
            };
            let (nearer, other) = if w < 0.5 { (a, b) } else { (b, a) };
            let focus = i < n_focus && !nearer.near_minimum.is_empty();
            let on_slice = (first_slice..first_own).contains(&i);
            for draw in 1.. {
                draw_in_cell(nearer, focus, &mut rng, &mut x);
                if on_slice {
                    self.error_coords.iter().for_each(|&k| x[k] = 0.0);
                }
                if inside(&other.solution, &x) {
                    break;
                }
                if draw == MAX_DRAWS {
                    clamp_into(&other.solution, &mut x);
                    break;
                }
            }
            let value = |s: &Supervised| s.solution.grid.interpolate(&s.solution.values, &x);
            tau.push(a.solution.info.horizon as f32);
            state.extend(x.iter().map(|&v| v as f32));
            let row_params: Vec<f32> =
                a.params.iter().zip(&b.params).map(|(&pa, &pb)| pa + (w as f32) * (pb - pa)).collect();
            match self.gradient_metric {
                GradientMetric::Euclidean => gradient_weights.extend(std::iter::repeat_n(1.0f32, n_state)),
                GradientMetric::Hamiltonian => {
                    let p: Vec<f64> = row_params.iter().map(|&v| f64::from(v)).collect();
                    self.system.dissipation_bounds(&x, &p, &mut alpha);
                    gradient_weights.extend(hamiltonian_weights(&alpha).map(|w| w as f32));
                }
            }
            params.extend(row_params);
            target.push(((1.0 - w) * value(a) + w * value(b)) as f32);
            for k in 0..n_state {
                let gradient = |s: &Supervised| central_difference(&s.solution, &x, k);
                target_gradient.push(((1.0 - w) * gradient(a) + w * gradient(b)) as f32);
            }
        }
        let t2 = |v: Vec<f32>, cols: usize| Tensor::from_data(TensorData::new(v, [m, cols]), device);
        SupervisionBatch {
            tau: t2(tau, 1),
            state: t2(state, n_state),
            params: t2(params, n_params),
            target: t2(target, 1),
            target_gradient: t2(target_gradient, n_state),
            gradient_weights: t2(gradient_weights, n_state),
        }
    }
}

/// Draws of a point inside both solutions of a blend before it is clamped into the other one's box.
const MAX_DRAWS: usize = 1000;

/// A node of `s` (with `focus`, one near its minimum) moved uniformly within its cell, into `x`.
fn draw_in_cell(s: &Supervised, focus: bool, rng: &mut impl Rng, x: &mut [f64]) {
    let grid = &s.solution.grid;
    let flat = if focus {
        s.near_minimum[rng.random_range(0..s.near_minimum.len())]
    } else {
        rng.random_range(0..s.solution.values.len())
    };
    grid.point(flat, x);
    for (xk, axis) in x.iter_mut().zip(grid.axes()) {
        let moved = *xk + axis.spacing() * rng.random_range(-0.5..0.5);
        *xk = if axis.periodic {
            axis.min + (moved - axis.min).rem_euclid(axis.max - axis.min)
        } else {
            moved.clamp(axis.min, axis.max)
        };
    }
}

/// Whether `x` lies in the box of `solution`'s grid (periodic axes always do).
fn inside(solution: &Solution, x: &[f64]) -> bool {
    solution.grid.axes().iter().zip(x).all(|(a, &v)| a.periodic || (a.min..=a.max).contains(&v))
}

/// `x` clamped into the box of `solution`'s grid.
fn clamp_into(solution: &Solution, x: &mut [f64]) {
    for (v, a) in x.iter_mut().zip(solution.grid.axes()) {
        if !a.periodic {
            *v = v.clamp(a.min, a.max);
        }
    }
}

/// The Hamiltonian metric's weights `n alpha_j^2 / sum_k alpha_k^2` (all 1 where every `alpha` is 0).
fn hamiltonian_weights(alpha: &[f64]) -> impl Iterator<Item = f64> + '_ {
    let total: f64 = alpha.iter().map(|a| a * a).sum();
    let n = alpha.len() as f64;
    alpha.iter().map(move |a| if total > 0.0 { n * a * a / total } else { 1.0 })
}

/// `dV/dr_k` of `solution`'s interpolant at `x`: the difference over one cell centred on `x` (one-sided where
/// a non-periodic edge cuts the cell).
fn central_difference(solution: &Solution, x: &[f64], k: usize) -> f64 {
    let axis = &solution.grid.axes()[k];
    let half = 0.5 * axis.spacing();
    let (mut plus, mut minus) = (x.to_vec(), x.to_vec());
    plus[k] += half;
    minus[k] -= half;
    if !axis.periodic {
        plus[k] = plus[k].min(axis.max);
        minus[k] = minus[k].max(axis.min);
    }
    let grid = &solution.grid;
    (grid.interpolate(&solution.values, &plus) - grid.interpolate(&solution.values, &minus)) / (plus[k] - minus[k])
}

/// Checks that `solution` is of `system`, on (part of) its domain, within the trained horizon.
fn check_fits(solution: &Solution, system: &AffineSystem, tau_max: f64) -> Result<(), String> {
    let info = &solution.info;
    if info.system != system.id {
        return Err(format!("a solution of system `{}`, training `{}`", info.system, system.id));
    }
    if info.horizon > tau_max * (1.0 + 1e-9) {
        return Err(format!(
            "horizon {} s lies past sampling.tau_max = {tau_max} s (supervise only inside the trained horizon)",
            info.horizon
        ));
    }
    let axes = solution.grid.axes();
    if axes.len() != system.n_state() {
        return Err(format!("{} grid axes for {} states", axes.len(), system.n_state()));
    }
    for (axis, dim) in axes.iter().zip(&system.state) {
        let slack = 1e-9 * (dim.max - dim.min);
        if axis.name != dim.name || axis.periodic != dim.periodic {
            return Err(format!("axis `{}` does not match state `{}`", axis.name, dim.name));
        }
        if axis.min < dim.min - slack || axis.max > dim.max + slack {
            return Err(format!(
                "axis `{}` spans [{}, {}], outside the domain [{}, {}]",
                axis.name, axis.min, axis.max, dim.min, dim.max
            ));
        }
    }
    Ok(())
}

/// The network's parameters for a solution solved at `solved` (one value per planner bound): the same in
/// full mode, the shared `beta` in diagonal mode (which needs every bound equal). Each must lie in range.
fn network_params(solved: &[f64], system: &AffineSystem) -> Result<Vec<f32>, String> {
    let params: Vec<f64> = if solved.len() == system.n_params() {
        solved.to_vec()
    } else if system.n_params() == 1 && solved.windows(2).all(|w| w[0] == w[1]) && !solved.is_empty() {
        vec![solved[0]]
    } else {
        return Err(format!("parameters {solved:?} do not map onto the network's {} parameter(s)", system.n_params()));
    };
    for (p, dim) in params.iter().zip(&system.params) {
        if !(dim.min..=dim.max).contains(p) {
            return Err(format!("{} = {p} outside the trained range [{}, {}]", dim.name, dim.min, dim.max));
        }
    }
    Ok(params.iter().map(|&p| p as f32).collect())
}
