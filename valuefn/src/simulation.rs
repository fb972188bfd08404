//! Simulation pieces every rollout shares: a fixed-step RK4 integrator with the inputs held over the step,
//! and the planner models that push a tracker (the worst case of a value gradient, random bang-bang).
//! Scenario verification, the rollouts of grid solutions and the online simulator all step through here.

use crate::system::AffineSystem;
use rand::rngs::StdRng;
use rand::Rng;

/// One classic RK4 step of `x' = f(x)` over `h`, in place (`f` writes the derivative into its second
/// argument).
pub fn rk4(x: &mut [f64], h: f64, mut f: impl FnMut(&[f64], &mut [f64])) {
    let n = x.len();
    let (mut k1, mut k2, mut k3, mut k4, mut y) =
        (vec![0.0; n], vec![0.0; n], vec![0.0; n], vec![0.0; n], vec![0.0; n]);
    f(x, &mut k1);
    y.iter_mut().enumerate().for_each(|(i, yi)| *yi = x[i] + 0.5 * h * k1[i]);
    f(&y, &mut k2);
    y.iter_mut().enumerate().for_each(|(i, yi)| *yi = x[i] + 0.5 * h * k2[i]);
    f(&y, &mut k3);
    y.iter_mut().enumerate().for_each(|(i, yi)| *yi = x[i] + h * k3[i]);
    f(&y, &mut k4);
    for i in 0..n {
        x[i] += h / 6.0 * (k1[i] + 2.0 * k2[i] + 2.0 * k3[i] + k4[i]);
    }
}

/// The inputs held over one step of the relative dynamics.
#[derive(Debug, Clone, Copy)]
pub struct HeldInputs<'a> {
    /// Tracker control `u`.
    pub control: &'a [f64],
    /// Planner input `u_p`.
    pub planner: &'a [f64],
    /// Disturbance `d` (empty for a system without one).
    pub disturbance: &'a [f64],
}

/// One RK4 step of the relative dynamics `r' = f(r) + G_u u + G_p u_p + G_d d` with the inputs held, the
/// periodic coordinates wrapped afterwards.
pub fn step_relative(system: &AffineSystem, r: &mut [f64], inputs: HeldInputs<'_>, h: f64) {
    rk4(r, h, |x, out| system.dynamics(x, inputs.control, inputs.planner, inputs.disturbance, out));
    system.wrap(r);
}

/// How a simulated planner picks its input.
#[derive(Debug, Clone, PartialEq)]
pub enum PlannerPolicy {
    /// The maximiser of `grad . G_p u_p` over the planner's box, from the value's gradient.
    WorstCase,
    /// A random vertex of the planner's box, switched at exponentially distributed times.
    BangBang {
        /// The vertex held now (empty before the first step).
        input: Vec<f64>,
        /// When the next switch is due (s).
        next_switch: f64,
    },
    /// A fixed sequence of inputs, each held for `segment` seconds (the last one past the end).
    Schedule {
        /// The inputs in turn.
        inputs: Vec<Vec<f64>>,
        /// How long each is held (s).
        segment: f64,
    },
}

impl PlannerPolicy {
    /// A bang-bang planner that draws its first vertex at the first step.
    pub fn bang_bang() -> Self {
        PlannerPolicy::BangBang { input: Vec::new(), next_switch: 0.0 }
    }

    /// The input at time `t` for the value gradient `grad` at parameters `params`; a bang-bang planner
    /// switches with mean dwell `mean_dwell` (s), drawing from `rng`.
    pub fn input(
        &mut self,
        system: &AffineSystem,
        params: &[f64],
        grad: &[f64],
        t: f64,
        mean_dwell: f64,
        rng: &mut StdRng,
    ) -> Vec<f64> {
        match self {
            PlannerPolicy::WorstCase => system.worst_planner(grad, params),
            PlannerPolicy::BangBang { input, next_switch } => {
                if t >= *next_switch {
                    *input = random_vertex(system, params, rng);
                    *next_switch = t + exponential(mean_dwell, rng);
                }
                input.clone()
            }
            PlannerPolicy::Schedule { inputs, segment } => {
                let k = ((t / *segment).floor().max(0.0) as usize).min(inputs.len().saturating_sub(1));
                inputs.get(k).cloned().unwrap_or_else(|| vec![0.0; system.planner_input_param.len()])
            }
        }
    }
}

/// A vertex of the planner's box at `params`, each input's sign drawn fairly.
pub(crate) fn random_vertex(system: &AffineSystem, params: &[f64], rng: &mut StdRng) -> Vec<f64> {
    system.planner_input_param.iter().map(|&k| if rng.random_bool(0.5) { params[k] } else { -params[k] }).collect()
}

/// An exponentially distributed time of mean `mean`.
fn exponential(mean: f64, rng: &mut StdRng) -> f64 {
    -mean * (1.0 - rng.random::<f64>()).ln()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::system::double_integrator;
    use rand::SeedableRng;

    #[test]
    fn rk4_is_exact_on_a_cubic_and_fourth_order_on_an_exponential() {
        // x' = 3 t^2 as the autonomous pair (x, t): RK4 integrates polynomials of degree <= 3 exactly.
        let mut x = [0.0, 0.0];
        for _ in 0..10 {
            rk4(&mut x, 0.1, |y, out| {
                out[0] = 3.0 * y[1] * y[1];
                out[1] = 1.0;
            });
        }
        assert!((x[0] - 1.0).abs() < 1e-12, "x(1) = {}", x[0]);
        // x' = x: the error at t = 1 falls 16x when the step halves.
        let error = |steps: usize| {
            let mut x = [1.0];
            for _ in 0..steps {
                rk4(&mut x, 1.0 / steps as f64, |y, out| out[0] = y[0]);
            }
            (x[0] - std::f64::consts::E).abs()
        };
        let ratio = error(10) / error(20);
        assert!((ratio - 16.0).abs() < 1.0, "error ratio {ratio}");
    }

    #[test]
    fn planners_stay_on_the_box_and_the_worst_case_maximises() {
        let system = double_integrator::system();
        let mut rng = StdRng::seed_from_u64(3);
        let grad = [0.7, -0.2];
        let worst = PlannerPolicy::WorstCase.input(&system, &[0.8], &grad, 0.0, 1.0, &mut rng);
        let g = &system.g_planner;
        let dot = |u: &[f64]| -> f64 {
            (0..g.nrows()).map(|i| grad[i] * (0..g.ncols()).map(|j| g[(i, j)] * u[j]).sum::<f64>()).sum()
        };
        for vertex in [[0.8], [-0.8]] {
            assert!(dot(&worst) >= dot(&vertex) - 1e-12, "{worst:?} does not maximise over {vertex:?}");
        }
        let mut bang = PlannerPolicy::bang_bang();
        let mut switches = 0;
        let mut last = Vec::new();
        for k in 0..1000 {
            let u = bang.input(&system, &[0.8], &grad, k as f64 * 0.01, 0.5, &mut rng);
            assert!(u.iter().all(|x| x.abs() == 0.8), "{u:?} is not a vertex");
            switches += usize::from(!last.is_empty() && u != last);
            last = u;
        }
        // 10 s at a mean dwell of 0.5 s: about 20 draws, half of them a change of sign.
        assert!((3..=20).contains(&switches), "{switches} switches");
    }

    #[test]
    fn a_schedule_holds_each_input_for_its_segment_and_the_last_past_the_end() {
        let system = double_integrator::system();
        let mut rng = StdRng::seed_from_u64(3);
        let mut schedule = PlannerPolicy::Schedule { inputs: vec![vec![0.8], vec![-0.8], vec![0.3]], segment: 0.5 };
        let mut at = |t: f64| schedule.input(&system, &[0.8], &[0.0, 0.0], t, 1.0, &mut rng)[0];
        assert_eq!([at(0.0), at(0.49), at(0.5), at(0.99), at(1.0), at(7.0)], [0.8, 0.8, -0.8, -0.8, 0.3, 0.3]);
    }
}
