//! What adversarial planners can force against a grid solution's own tracker policy: an independent check of a
//! grid `V_min` by simulation.
//!
//! From states of the solution's error set `{V <= (1 + start_margin) V_min}` (grid nodes, thinned evenly to
//! `max_starts`), the relative system is rolled forward (RK4, control and planner held over a step) with the
//! tracker control of the solution's gradient (central differences of the interpolant across one cell)
//! against the worst-case planner of that gradient and against random bang-bang planners. The error a planner
//! *sustains* is the largest `l` over the second half of the horizon, after the start's own transient.
//!
//! A planner family's sustained error is at most the worst error this policy allows (the planners need not be
//! optimal), and it is not a bound on the TEB either way: the TEB is at most what the best policy allows, and
//! holding the control over a step costs a little (4% on the double integrator). What it shows is whether a
//! grid `V_min` lies above what these planners force, and whether its growth with the horizon is something
//! they can exploit.

use crate::solver::Solution;
use fastrack_valuefn::simulation::{step_relative, HeldInputs, PlannerPolicy};
use fastrack_valuefn::system::{AffineSystem, DecomposedAxis};
use rand::rngs::StdRng;
use rand::{Rng, SeedableRng};
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

/// How to roll out.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct RolloutOptions {
    /// Rollout horizon (s); the sustained error is taken over its second half.
    pub horizon: f64,
    /// RK4 step (s).
    pub step: f64,
    /// Starts are the nodes of `{V <= (1 + start_margin) V_min}`.
    pub start_margin: f64,
    /// Largest number of starts (the set's nodes are thinned evenly).
    pub max_starts: usize,
    /// Random bang-bang planners per start (besides the worst-case planner).
    pub random_planners: usize,
    /// Mean time between a random planner's switches (s).
    pub mean_dwell: f64,
    /// Random seed.
    pub seed: u64,
}

impl Default for RolloutOptions {
    fn default() -> Self {
        Self {
            horizon: 60.0,
            step: 0.01,
            start_margin: 0.02,
            max_starts: 200,
            random_planners: 4,
            mean_dwell: 1.0,
            seed: 11,
        }
    }
}

/// Options the rollout cannot use, or a solution it cannot roll out.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum RolloutError {
    /// A numeric option is out of range.
    #[error("{0}")]
    Setting(String),
    /// The solution's system is not the one given, or its grid does not match it.
    #[error("the solution is of system `{solution}` with {axes} axes; the rollout was given `{system}`")]
    System {
        /// The solution's system id.
        solution: String,
        /// Its grid axes.
        axes: usize,
        /// The system given.
        system: String,
    },
}

/// What the planners sustained.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct RolloutReport {
    /// The solution's `V_min`.
    pub v_min: f64,
    /// Starts rolled out (each against every planner).
    pub starts: usize,
    /// Largest error over the second half of the horizon against the worst-case planner, over the starts.
    pub sustained_worst_case: f64,
    /// The same against the random bang-bang planners (none when there are none).
    pub sustained_random: Option<f64>,
    /// Largest error over the whole horizon, any planner (the starts' own transients included).
    pub peak: f64,
    /// Rollouts that left the grid's domain on a non-periodic axis (values there are clamped).
    pub left_domain: usize,
}

impl RolloutReport {
    /// The larger of the sustained errors.
    pub fn sustained(&self) -> f64 {
        self.sustained_random.map_or(self.sustained_worst_case, |r| r.max(self.sustained_worst_case))
    }
}

fn check(options: &RolloutOptions) -> Result<(), RolloutError> {
    let positive = |name: &str, x: f64| {
        if x.is_finite() && x > 0.0 {
            Ok(())
        } else {
            Err(RolloutError::Setting(format!("{name} must be a positive number, got {x}")))
        }
    };
    positive("horizon", options.horizon)?;
    positive("step", options.step)?;
    positive("mean dwell", options.mean_dwell)?;
    if options.step > options.horizon / 2.0 {
        return Err(RolloutError::Setting(format!(
            "step {} s leaves no second half of the {} s horizon",
            options.step, options.horizon
        )));
    }
    if !(options.start_margin.is_finite() && options.start_margin >= 0.0) {
        return Err(RolloutError::Setting(format!("start margin must be >= 0, got {}", options.start_margin)));
    }
    if options.max_starts == 0 {
        return Err(RolloutError::Setting("max starts must be at least 1".into()));
    }
    Ok(())
}

/// A tracker policy read off a value gradient over the whole relative state, on grids of a domain.
trait GradientField: Sync {
    /// The value gradient at `r`, written into `out`.
    fn gradient(&self, r: &[f64], out: &mut [f64]);
    /// Whether `r` lies outside a grid on a non-periodic axis (values there are clamped).
    fn outside(&self, r: &[f64]) -> bool;
}

fn outside_grid(solution: &Solution, r: &[f64]) -> bool {
    solution.grid.axes().iter().zip(r).any(|(a, &x)| !a.periodic && (x < a.min || x > a.max))
}

impl GradientField for Solution {
    fn gradient(&self, r: &[f64], out: &mut [f64]) {
        Solution::gradient(self, r, out);
    }

    fn outside(&self, r: &[f64]) -> bool {
        outside_grid(self, r)
    }
}

/// Axis solutions side by side: each axis' solution gives the gradient on its own coordinates.
struct AxisSolutions<'a> {
    axes: &'a [(DecomposedAxis, &'a Solution)],
}

/// Largest axis a grid holds: the stack buffers of [`AxisSolutions`] (no allocation per step).
const MAX_AXIS: usize = crate::grid::MAX_DIMS;

impl AxisSolutions<'_> {
    /// Calls `f` with the axis' solution and its coordinates cut out of `r`.
    fn with_cut<T>(axis: &DecomposedAxis, r: &[f64], f: impl FnOnce(&[f64]) -> T) -> T {
        let mut cut = [0.0; MAX_AXIS];
        for (x, &i) in cut.iter_mut().zip(&axis.coords) {
            *x = r[i];
        }
        f(&cut[..axis.coords.len()])
    }
}

impl GradientField for AxisSolutions<'_> {
    fn gradient(&self, r: &[f64], out: &mut [f64]) {
        for (axis, solution) in self.axes {
            let mut p = [0.0; MAX_AXIS];
            let p = &mut p[..axis.coords.len()];
            Self::with_cut(axis, r, |cut| solution.gradient(cut, p));
            for (&i, &g) in axis.coords.iter().zip(p.iter()) {
                out[i] = g;
            }
        }
    }

    fn outside(&self, r: &[f64]) -> bool {
        self.axes.iter().any(|(axis, solution)| Self::with_cut(axis, r, |cut| outside_grid(solution, cut)))
    }
}

/// What one rollout reached.
struct Reached {
    /// Largest error over the second half of the horizon.
    sustained: f64,
    /// Largest error over the whole horizon.
    peak: f64,
    /// Per group of error coordinates (an axis' own error), the largest error over the second half.
    group_sustained: Vec<f64>,
    /// Whether the rollout left a grid's domain.
    left: bool,
}

/// What every rollout of one check shares: the system, the tracker policy, the parameters, the groups of
/// error coordinates whose own errors are tracked besides the whole error, and the options.
struct Scene<'a> {
    system: &'a AffineSystem,
    field: &'a dyn GradientField,
    params: &'a [f64],
    groups: &'a [Vec<usize>],
    options: &'a RolloutOptions,
}

impl Scene<'_> {
    /// One rollout from `start` against `planner`.
    fn roll_out(&self, start: &[f64], mut planner: PlannerPolicy, rng: &mut StdRng) -> Reached {
        let (system, options) = (self.system, self.options);
        let (mut r, mut p) = (start.to_vec(), vec![0.0; start.len()]);
        let steps = (options.horizon / options.step).round() as usize;
        let mut reached = Reached {
            sustained: 0.0,
            peak: system.tracking_error(&r),
            group_sustained: vec![0.0; self.groups.len()],
            left: false,
        };
        let d = vec![0.0; system.disturbances.len()];
        for k in 0..steps {
            let t = k as f64 * options.step;
            self.field.gradient(&r, &mut p);
            let u = system.optimal_control(&r, &p);
            let u_p = planner.input(system, self.params, &p, t, options.mean_dwell, rng);
            step_relative(system, &mut r, HeldInputs { control: &u, planner: &u_p, disturbance: &d }, options.step);
            let error = system.tracking_error(&r);
            reached.peak = reached.peak.max(error);
            if 2 * (k + 1) > steps {
                reached.sustained = reached.sustained.max(error);
                for (held, group) in reached.group_sustained.iter_mut().zip(self.groups) {
                    *held = held.max(group.iter().map(|&i| r[i] * r[i]).sum::<f64>().sqrt());
                }
            }
            reached.left |= self.field.outside(&r);
        }
        reached
    }

    /// Every start rolled out against the worst-case planner and `options.random_planners` random ones, on
    /// the cores: `(planner is worst-case, what it reached)` per rollout.
    fn roll_out_starts(&self, starts: &[Vec<f64>]) -> Vec<(bool, Reached)> {
        let random = self.options.random_planners;
        starts
            .par_iter()
            .enumerate()
            .flat_map_iter(|(i, start)| {
                (0..=random).map(move |j| {
                    let planner = if j == 0 { PlannerPolicy::WorstCase } else { PlannerPolicy::bang_bang() };
                    let seed = self.options.seed ^ ((i * (random + 1) + j) as u64).wrapping_mul(0x9E37_79B9);
                    let mut rng = StdRng::seed_from_u64(seed);
                    (j == 0, self.roll_out(start, planner, &mut rng))
                })
            })
            .collect()
    }
}

/// The largest sustained error of the worst-case (`true`) or random planners, if any rolled out.
fn largest_sustained(results: &[(bool, Reached)], worst_case: bool) -> Option<f64> {
    results.iter().filter(|x| x.0 == worst_case).map(|x| x.1.sustained).reduce(f64::max)
}

/// The nodes of `{V <= (1 + margin) V_min}` of `solution`, thinned evenly to at most `max` points, and `V_min`.
fn sublevel_nodes(solution: &Solution, margin: f64, max: usize) -> (Vec<Vec<f64>>, f64) {
    let v_min = solution.v_min();
    let level = v_min + margin * v_min.abs();
    let nodes: Vec<usize> = (0..solution.values.len()).filter(|&f| solution.values[f] <= level).collect();
    let stride = nodes.len().div_ceil(max).max(1);
    let points = nodes
        .iter()
        .step_by(stride)
        .map(|&f| {
            let mut r = vec![0.0; solution.grid.ndim()];
            solution.grid.point(f, &mut r);
            r
        })
        .collect();
    (points, v_min)
}

/// Rolls out `solution`'s tracker policy of `system` against the planners of `options`.
pub fn roll_out_solution(
    system: &AffineSystem,
    solution: &Solution,
    options: &RolloutOptions,
) -> Result<RolloutReport, RolloutError> {
    check(options)?;
    if solution.info.system != system.id || solution.grid.ndim() != system.n_state() {
        return Err(RolloutError::System {
            solution: solution.info.system.clone(),
            axes: solution.grid.ndim(),
            system: system.id.into(),
        });
    }
    let (starts, v_min) = sublevel_nodes(solution, options.start_margin, options.max_starts);
    let scene = Scene { system, field: solution, params: &solution.info.params, groups: &[], options };
    let results = scene.roll_out_starts(&starts);
    Ok(RolloutReport {
        v_min,
        starts: starts.len(),
        // Every start has its worst-case rollout, and there is at least one start (the minimum's node).
        sustained_worst_case: largest_sustained(&results, true).unwrap_or(f64::NAN),
        sustained_random: largest_sustained(&results, false),
        peak: results.iter().map(|x| x.1.peak).fold(f64::NEG_INFINITY, f64::max),
        left_domain: results.iter().filter(|x| x.1.left).count(),
    })
}

/// What adversarial planners sustain against axis solutions' policies side by side in the full system.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct AxesRolloutReport {
    /// Each axis' `V_min` (the bound on its own error), in the decomposition's order.
    pub axis_v_min: Vec<f64>,
    /// The bound they combine into: `sqrt(sum V_min_i^2)`, since each axis' error stays inside its own bound.
    pub combined_bound: f64,
    /// The full system's parameters the axes were solved at.
    pub params: Vec<f64>,
    /// The rollouts as for one solution, with `v_min` the combined bound.
    pub rollout: RolloutReport,
    /// Per axis, the largest error of its own over the second half of the horizon, any planner.
    pub axis_sustained: Vec<f64>,
}

/// Rolls out the axes' policies side by side (each axis' control from its own solution's gradient) in the full
/// `system`, from starts whose every axis lies in its solution's set `{V <= (1 + start_margin) V_min}`
/// (each axis' nodes drawn at random), against the planners of `options`.
pub fn roll_out_axes(
    system: &AffineSystem,
    axes: &[(DecomposedAxis, &Solution)],
    options: &RolloutOptions,
) -> Result<AxesRolloutReport, RolloutError> {
    check(options)?;
    let mut params = vec![f64::NAN; system.n_params()];
    for (axis, solution) in axes {
        if solution.info.system != axis.subsystem || solution.grid.ndim() != axis.coords.len() {
            return Err(RolloutError::System {
                solution: solution.info.system.clone(),
                axes: solution.grid.ndim(),
                system: axis.subsystem.into(),
            });
        }
        let beta = solution.info.params[0];
        let slot = &mut params[axis.param];
        if !slot.is_nan() && *slot != beta {
            return Err(RolloutError::Setting(format!(
                "parameter {} of {} is {} on one axis and {beta} on another",
                axis.param, system.id, *slot
            )));
        }
        *slot = beta;
    }
    if let Some(k) = params.iter().position(|p| p.is_nan()) {
        return Err(RolloutError::Setting(format!("no axis solution gives parameter {k} of {}", system.id)));
    }
    let sets: Vec<(Vec<Vec<f64>>, f64)> =
        axes.iter().map(|(_, s)| sublevel_nodes(s, options.start_margin, options.max_starts)).collect();
    let mut rng = StdRng::seed_from_u64(options.seed);
    let starts: Vec<Vec<f64>> = (0..options.max_starts)
        .map(|_| {
            let mut r = vec![0.0; system.n_state()];
            for ((axis, _), (nodes, _)) in axes.iter().zip(&sets) {
                let node = &nodes[rng.random_range(0..nodes.len())];
                for (&i, &x) in axis.coords.iter().zip(node) {
                    r[i] = x;
                }
            }
            r
        })
        .collect();
    let groups: Vec<Vec<usize>> = axes
        .iter()
        .map(|(axis, _)| axis.coords.iter().copied().filter(|i| system.error_coords.contains(i)).collect())
        .collect();
    let field = AxisSolutions { axes };
    let scene = Scene { system, field: &field, params: &params, groups: &groups, options };
    let results = scene.roll_out_starts(&starts);
    let axis_v_min: Vec<f64> = sets.iter().map(|(_, v)| *v).collect();
    let combined_bound = axis_v_min.iter().map(|v| v * v).sum::<f64>().sqrt();
    Ok(AxesRolloutReport {
        combined_bound,
        params,
        rollout: RolloutReport {
            v_min: combined_bound,
            starts: starts.len(),
            sustained_worst_case: largest_sustained(&results, true).unwrap_or(f64::NAN),
            sustained_random: largest_sustained(&results, false),
            peak: results.iter().map(|x| x.1.peak).fold(f64::NEG_INFINITY, f64::max),
            left_domain: results.iter().filter(|x| x.1.left).count(),
        },
        axis_sustained: (0..axes.len())
            .map(|a| results.iter().map(|x| x.1.group_sustained[a]).fold(0.0, f64::max))
            .collect(),
        axis_v_min,
    })
}
