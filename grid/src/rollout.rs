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
use fastrack_valuefn::simulation::{step_relative, HeldInputs, Planner};
use fastrack_valuefn::system::AffineSystem;
use rand::rngs::StdRng;
use rand::SeedableRng;
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

/// `(sustained error, peak error, left the domain)` of one rollout from `start`.
fn roll_out(
    system: &AffineSystem,
    solution: &Solution,
    start: &[f64],
    mut planner: Planner,
    rng: &mut StdRng,
    options: &RolloutOptions,
) -> (f64, f64, bool) {
    let params = &solution.info.params;
    let n = start.len();
    let (mut r, mut p) = (start.to_vec(), vec![0.0; n]);
    let steps = (options.horizon / options.step).round() as usize;
    let (mut sustained, mut peak, mut left) = (0.0f64, system.tracking_error(&r), false);
    let d = vec![0.0; system.disturbances.len()];
    for k in 0..steps {
        let t = k as f64 * options.step;
        solution.gradient(&r, &mut p);
        let u = system.optimal_control(&r, &p);
        let u_p = planner.input(system, params, &p, t, options.mean_dwell, rng);
        step_relative(system, &mut r, HeldInputs { control: &u, planner: &u_p, disturbance: &d }, options.step);
        let error = system.tracking_error(&r);
        peak = peak.max(error);
        if 2 * (k + 1) > steps {
            sustained = sustained.max(error);
        }
        left |= solution.grid.axes().iter().zip(&r).any(|(a, &x)| !a.periodic && (x < a.min || x > a.max));
    }
    (sustained, peak, left)
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
    let v_min = solution.values.iter().copied().fold(f64::INFINITY, f64::min);
    let level = v_min + options.start_margin * v_min.abs();
    let nodes: Vec<usize> = (0..solution.values.len()).filter(|&f| solution.values[f] <= level).collect();
    let stride = nodes.len().div_ceil(options.max_starts).max(1);
    let starts: Vec<Vec<f64>> = nodes
        .iter()
        .step_by(stride)
        .map(|&f| {
            let mut r = vec![0.0; system.n_state()];
            solution.grid.point(f, &mut r);
            r
        })
        .collect();
    // (planner is worst-case, sustained, peak, left the domain) per rollout.
    let results: Vec<(bool, f64, f64, bool)> = starts
        .par_iter()
        .enumerate()
        .flat_map_iter(|(i, start)| {
            (0..=options.random_planners).map(move |j| {
                let planner = if j == 0 { Planner::WorstCase } else { Planner::bang_bang() };
                let seed = options.seed ^ ((i * (options.random_planners + 1) + j) as u64).wrapping_mul(0x9E37_79B9);
                let mut rng = StdRng::seed_from_u64(seed);
                let (sustained, peak, left) = roll_out(system, solution, start, planner, &mut rng, options);
                (j == 0, sustained, peak, left)
            })
        })
        .collect();
    let largest = |worst_case: bool| results.iter().filter(|x| x.0 == worst_case).map(|x| x.1).reduce(f64::max);
    Ok(RolloutReport {
        v_min,
        starts: starts.len(),
        // Every start has its worst-case rollout, and there is at least one start (the minimum's node).
        sustained_worst_case: largest(true).unwrap_or(f64::NAN),
        sustained_random: largest(false),
        peak: results.iter().map(|x| x.2).fold(f64::NEG_INFINITY, f64::max),
        left_domain: results.iter().filter(|x| x.3).count(),
    })
}
