//! A model bundle against a grid solution at one `beta`: learned vs grid `V_min`, their ratio, the error of
//! `V` over the grid's sublevel set, how the served control compares with the grid's optimal control there,
//! and the `(axis 0, axis 1)` slices of both value functions through the grid's minimiser. A bundle of a
//! decomposed system (quad10d) is compared axis by axis with the combined ground truth of its axes' solutions
//! ([`combined_on_axis`], [`learned_on_axis`]).

use crate::grid::Grid;
use crate::solver::Solution;
use fastrack_valuefn::runtime::{Evaluator, RuntimeError};
use fastrack_valuefn::system::{AffineSystem, DecomposedAxis};
use serde::{Deserialize, Serialize};

/// Grid nodes evaluated per ONNX batch.
const BATCH: usize = 4096;

/// The comparison at one `beta`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Comparison {
    /// Planner speed bound.
    pub beta: f64,
    /// `min V_grid` over the nodes.
    pub grid_v_min: f64,
    /// `min V_learned` over the same nodes.
    pub learned_v_min: f64,
    /// `learned_v_min / grid_v_min`.
    pub ratio: f64,
    /// Level of the sublevel set the errors are taken over: `sublevel_factor * grid_v_min`.
    pub set_level: f64,
    /// Nodes in `{V_grid <= set_level}`.
    pub set_nodes: usize,
    /// Mean `|V_learned - V_grid|` over the set.
    pub mean_abs_error: f64,
    /// Max `|V_learned - V_grid|` over the set.
    pub max_abs_error: f64,
    /// Per control, the share of the set's nodes where the served control equals the grid's optimal control
    /// (within 0.1% of the control's range): for bang-bang controls, where the learned switching function has
    /// the grid's sign.
    pub control_agreement: Vec<f64>,
    /// Mean over the set of the served control's Hamiltonian loss under the grid's gradient,
    /// `p . G_u (u_served - u_grid) >= 0` (`p` the grid's `dV/dr`): how much faster, in `V` per second, the
    /// served control lets the value grow than the grid's best control.
    pub mean_control_loss: f64,
    /// The largest such loss over the set.
    pub max_control_loss: f64,
}

/// Slices of both value functions in the plane of grid axes 0 and 1 through the grid's minimiser
/// (row-major, axis 1 fastest).
#[derive(Debug, Clone, PartialEq)]
pub struct Slices {
    /// Nodes along axis 0.
    pub n0: usize,
    /// Nodes along axis 1.
    pub n1: usize,
    /// Grid values.
    pub grid: Vec<f64>,
    /// Learned values.
    pub learned: Vec<f64>,
    /// Coordinates of the other axes where the plane was cut.
    pub cut: Vec<f64>,
}

/// The bundle's values and served controls at the nodes of a grid.
#[derive(Debug, Clone, PartialEq)]
pub struct Learned {
    /// `V` per node.
    pub values: Vec<f64>,
    /// The served control per node (row-major, `n_control` per node).
    pub controls: Vec<f64>,
}

/// The learned values and served controls at every node of `solution`'s grid, the bundle evaluated at
/// `params` (its own parameters: one shared `beta` for a diagonal-mode bundle, `beta` per planner input
/// otherwise).
pub fn learned_on_grid(evaluator: &Evaluator, solution: &Solution, params: &[f64]) -> Result<Learned, RuntimeError> {
    learned_at_nodes(evaluator, &solution.grid, params, |r, state| state.extend(r.iter().map(|&x| x as f32)))
}

/// The bundle at every node of `grid`, each node written into the bundle's state by `embed`.
fn learned_at_nodes(
    evaluator: &Evaluator,
    grid: &Grid,
    params: &[f64],
    embed: impl Fn(&[f64], &mut Vec<f32>),
) -> Result<Learned, RuntimeError> {
    let params: Vec<f32> = params.iter().map(|&p| p as f32).collect();
    let mut values = Vec::with_capacity(grid.num_points());
    let mut controls = Vec::new();
    let mut r = vec![0.0; grid.ndim()];
    for start in (0..grid.num_points()).step_by(BATCH) {
        let end = (start + BATCH).min(grid.num_points());
        let mut states = Vec::new();
        for flat in start..end {
            grid.point(flat, &mut r);
            embed(&r, &mut states);
        }
        let batch_params: Vec<f32> = params.iter().copied().cycle().take((end - start) * params.len()).collect();
        let out = evaluator.evaluate(&states, &batch_params)?;
        values.extend(out.value.iter().map(|&v| f64::from(v)));
        controls.extend(out.control.iter().map(|&u| f64::from(u)));
    }
    Ok(Learned { values, controls })
}

/// The combined ground truth of a decomposed system along one of its axes: `V_c(r) = sqrt(sum_b V_b(r_b)^2)`
/// (the bound the axes' solutions certify together) on the nodes of that axis' grid, every other axis held
/// at its own solution's minimiser.
#[derive(Debug, Clone, PartialEq)]
pub struct AxisSlice {
    /// The axis' grid with the values `sqrt(V_a^2 + sum_{b != a} V_min,b^2)`: its minimum is the combined
    /// bound `sqrt(sum_b V_min,b^2)`, and its sublevel sets are the axis' own.
    pub reference: Solution,
    /// The full relative state the axis' nodes are written into.
    pub base: Vec<f64>,
    /// The axis' coordinates in the full state.
    pub coords: Vec<usize>,
    /// The full system's controls acting on the axis, in the subsystem's order.
    pub controls: Vec<usize>,
}

/// The index of the node of `solution` where `V` is least.
fn argmin_node(solution: &Solution) -> usize {
    solution.values.iter().enumerate().fold(0, |b, (i, &v)| if v < solution.values[b] { i } else { b })
}

/// The node of `solution` where `V` is least, as a point.
fn minimiser(solution: &Solution) -> Vec<f64> {
    let mut point = vec![0.0; solution.grid.ndim()];
    solution.grid.point(argmin_node(solution), &mut point);
    point
}

/// The combined ground truth along axis `k` of `axes` (a decomposition of `system`, each axis with its
/// subsystem's solution at one `beta`).
pub fn combined_on_axis(system: &AffineSystem, axes: &[(DecomposedAxis, &Solution)], k: usize) -> AxisSlice {
    let mut base = vec![0.0; system.n_state()];
    let mut others = 0.0;
    for (b, (axis, solution)) in axes.iter().enumerate() {
        for (&i, x) in axis.coords.iter().zip(minimiser(solution)) {
            base[i] = x;
        }
        if b != k {
            let v_min = solution.v_min();
            others += v_min.max(0.0).powi(2);
        }
    }
    let (axis, solution) = &axes[k];
    let mut reference = (*solution).clone();
    for v in &mut reference.values {
        *v = (v.max(0.0).powi(2) + others).sqrt();
    }
    let controls =
        (0..system.n_control()).filter(|&j| axis.coords.iter().any(|&i| system.g_control[(i, j)] != 0.0)).collect();
    AxisSlice { reference, base, coords: axis.coords.clone(), controls }
}

/// The bundle of the full system at every node of `slice`'s axis grid, written into its base state: the
/// values, and the served controls of the axis' own inputs.
pub fn learned_on_axis(evaluator: &Evaluator, slice: &AxisSlice, params: &[f64]) -> Result<Learned, RuntimeError> {
    let full = learned_at_nodes(evaluator, &slice.reference.grid, params, |r, state| {
        let start = state.len();
        state.extend(slice.base.iter().map(|&x| x as f32));
        for (&i, &x) in slice.coords.iter().zip(r) {
            state[start + i] = x as f32;
        }
    })?;
    let n_control = full.controls.len() / full.values.len().max(1);
    let controls = full.controls.chunks(n_control.max(1)).flat_map(|u| slice.controls.iter().map(|&j| u[j])).collect();
    Ok(Learned { values: full.values, controls })
}

/// Compares `learned` (at the grid's nodes) with `solution` of `system` over `{V_grid <= factor V_min}`.
pub fn compare(system: &AffineSystem, solution: &Solution, learned: &Learned, sublevel_factor: f64) -> Comparison {
    let grid_v_min = solution.v_min();
    let learned_v_min = learned.values.iter().copied().fold(f64::INFINITY, f64::min);
    let set_level = sublevel_factor * grid_v_min;
    let (n_state, n_control) = (system.n_state(), system.n_control());
    let ranges: Vec<f64> = system.controls.iter().map(|c| c.max - c.min).collect();
    let (mut sum, mut max, mut count) = (0.0, 0.0f64, 0usize);
    let (mut agree, mut loss_sum, mut loss_max) = (vec![0usize; n_control], 0.0, 0.0f64);
    let (mut r, mut p) = (vec![0.0; n_state], vec![0.0; n_state]);
    for (flat, (&g, &l)) in solution.values.iter().zip(&learned.values).enumerate() {
        if g <= set_level {
            let e = (l - g).abs();
            sum += e;
            max = max.max(e);
            count += 1;
            solution.grid.point(flat, &mut r);
            solution.gradient(&r, &mut p);
            let best = system.optimal_control(&r, &p);
            let served = &learned.controls[flat * n_control..(flat + 1) * n_control];
            let mut loss = 0.0;
            for j in 0..n_control {
                agree[j] += usize::from((served[j] - best[j]).abs() <= 1e-3 * ranges[j]);
                let switching: f64 = (0..n_state).map(|i| p[i] * system.g_control[(i, j)]).sum();
                loss += switching * (served[j] - best[j]);
            }
            loss_sum += loss;
            loss_max = loss_max.max(loss);
        }
    }
    let share = |k: usize| if count > 0 { k as f64 / count as f64 } else { f64::NAN };
    Comparison {
        beta: solution.info.params.first().copied().unwrap_or(f64::NAN),
        grid_v_min,
        learned_v_min,
        ratio: learned_v_min / grid_v_min,
        set_level,
        set_nodes: count,
        mean_abs_error: if count > 0 { sum / count as f64 } else { f64::NAN },
        max_abs_error: max,
        control_agreement: agree.into_iter().map(share).collect(),
        mean_control_loss: if count > 0 { loss_sum / count as f64 } else { f64::NAN },
        max_control_loss: loss_max,
    }
}

/// The plane of axes 0 and 1 through the grid's minimiser, for both value functions.
pub fn slices(solution: &Solution, learned: &[f64]) -> Slices {
    let grid = &solution.grid;
    let best = argmin_node(solution);
    let base: usize = (2..grid.ndim()).map(|k| grid.node(best, k) * grid.strides()[k]).sum();
    let (n0, n1) = (grid.axes()[0].n, grid.axes()[1].n);
    let (s0, s1) = (grid.strides()[0], grid.strides()[1]);
    let pick = |values: &[f64]| (0..n0 * n1).map(|k| values[base + (k / n1) * s0 + (k % n1) * s1]).collect();
    let cut = (2..grid.ndim()).map(|k| grid.axes()[k].coord(grid.node(best, k))).collect();
    Slices { n0, n1, grid: pick(&solution.values), learned: pick(learned), cut }
}
