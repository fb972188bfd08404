//! The Hamiltonian of a control- and planner-affine system prepared for the grid's inner loop (no
//! allocation per point), and its numerical Hamiltonians: Lax-Friedrichs with per-point dissipation, and
//! Godunov's for systems whose every input acts on one state coordinate.

use fastrack_valuefn::system::{AffineSystem, BoxSet};
use nalgebra::DMatrix;

/// One input of a box-bounded affine term: its column of `G` (non-zero entries only) and its bounds.
#[derive(Debug, Clone)]
struct BoxInput {
    column: Vec<(usize, f64)>,
    lo: f64,
    hi: f64,
}

fn box_inputs(g: &DMatrix<f64>, bounds: &BoxSet) -> Vec<BoxInput> {
    (0..g.ncols())
        .map(|j| BoxInput {
            column: (0..g.nrows()).filter(|&i| g[(i, j)] != 0.0).map(|i| (i, g[(i, j)])).collect(),
            lo: bounds.lo()[j],
            hi: bounds.hi()[j],
        })
        .collect()
}

/// `H(r, p) = p . f(r) + min_u p . G_u u + max_{u_p} p . G_p u_p + max_d p . G_d d` for fixed parameters,
/// the same function as [`AffineSystem::hamiltonian`] without its per-call allocations.
#[derive(Debug, Clone)]
pub struct Hamiltonian {
    system: AffineSystem,
    minimised: Vec<BoxInput>,
    maximised: Vec<BoxInput>,
    /// Per state coordinate, the inputs acting on it alone (`None` if some input acts on several).
    separable: Option<Vec<Vec<AxisInput>>>,
}

/// An input acting on one state coordinate: `g * q * u` with `u` in `[lo, hi]`, minimised or maximised.
#[derive(Debug, Clone, Copy)]
struct AxisInput {
    g: f64,
    lo: f64,
    hi: f64,
    maximised: bool,
}

/// The inputs grouped by the one state coordinate each acts on, or `None` if an input acts on several.
fn separate(n_state: usize, minimised: &[BoxInput], maximised: &[BoxInput]) -> Option<Vec<Vec<AxisInput>>> {
    let mut axes = vec![Vec::new(); n_state];
    let tagged = minimised.iter().map(|i| (i, false)).chain(maximised.iter().map(|i| (i, true)));
    for (input, is_max) in tagged {
        match input.column[..] {
            [] => {}
            [(i, g)] => axes[i].push(AxisInput { g, lo: input.lo, hi: input.hi, maximised: is_max }),
            _ => return None,
        }
    }
    Some(axes)
}

/// Largest state dimension the inner loop supports (stack buffers).
pub const MAX_STATE: usize = crate::grid::MAX_DIMS;

impl Hamiltonian {
    /// Prepares `system`'s Hamiltonian at parameters `params`.
    pub fn new(system: &AffineSystem, params: &[f64]) -> Self {
        let mut maximised = box_inputs(&system.g_planner, &system.planner_box(params));
        maximised.extend(box_inputs(&system.g_disturbance, &system.disturbance_box()));
        let minimised = box_inputs(&system.g_control, &system.control_box());
        let separable = separate(system.n_state(), &minimised, &maximised);
        Self { system: system.clone(), minimised, maximised, separable }
    }

    /// Whether every input acts on one state coordinate, so that `H(r, p) = sum_i h_i(p_i)` and the Godunov
    /// numerical Hamiltonian ([`Hamiltonian::godunov`]) applies.
    pub fn is_separable(&self) -> bool {
        self.separable.is_some()
    }

    /// The drift `f(r)`, written into `out`.
    pub fn drift(&self, r: &[f64], out: &mut [f64]) {
        self.system.drift.eval(r, out);
    }

    /// `H(r, p)`.
    pub fn eval(&self, r: &[f64], p: &[f64]) -> f64 {
        let mut f = [0.0; MAX_STATE];
        let f = &mut f[..r.len()];
        self.drift(r, f);
        self.eval_with_drift(f, p)
    }

    /// `H` from the drift `f(r)` at the point and the costate `p`.
    pub fn eval_with_drift(&self, f: &[f64], p: &[f64]) -> f64 {
        let mut h: f64 = f.iter().zip(p).map(|(a, b)| a * b).sum();
        let dot = |input: &BoxInput| input.column.iter().map(|&(i, g)| g * p[i]).sum::<f64>();
        for input in &self.minimised {
            let c = dot(input);
            h += (c * input.lo).min(c * input.hi);
        }
        for input in &self.maximised {
            let c = dot(input);
            h += (c * input.lo).max(c * input.hi);
        }
        h
    }

    /// Lax-Friedrichs numerical Hamiltonian for the horizon form `dV/dtau = H`:
    /// `H((p- + p+) / 2) + sum_i alpha_i (p+_i - p-_i) / 2`, with `alpha_i >= |dH/dp_i|` at the point whose
    /// drift is `f`.
    pub fn lax_friedrichs(&self, f: &[f64], left: &[f64], right: &[f64], alpha: &[f64]) -> f64 {
        let mut mean = [0.0; MAX_STATE];
        let mean = &mut mean[..f.len()];
        let mut dissipation = 0.0;
        for i in 0..f.len() {
            mean[i] = 0.5 * (left[i] + right[i]);
            dissipation += 0.5 * alpha[i] * (right[i] - left[i]);
        }
        self.eval_with_drift(f, mean) + dissipation
    }

    /// Godunov's numerical Hamiltonian for the horizon form `dV/dtau = H` of a separable Hamiltonian
    /// `H = sum_i h_i(p_i)`: `sum_i` of the largest `h_i` over `[p-_i, p+_i]` where `p-_i <= p+_i` (a valley
    /// of `V` along the axis) and the smallest over `[p+_i, p-_i]` otherwise. Each `h_i` is linear on either
    /// side of 0, so the extremes lie at the ends or at 0. It adds no more dissipation than the upwind
    /// structure needs, where Lax-Friedrichs adds `alpha_i (p+_i - p-_i) / 2` on every kink. `None` when the
    /// Hamiltonian is not separable.
    pub fn godunov(&self, f: &[f64], left: &[f64], right: &[f64]) -> Option<f64> {
        let axes = self.separable.as_ref()?;
        let mut h = 0.0;
        for (i, inputs) in axes.iter().enumerate() {
            let term = |q: f64| {
                let mut t = f[i] * q;
                for input in inputs {
                    let (a, b) = (input.g * q * input.lo, input.g * q * input.hi);
                    t += if input.maximised { a.max(b) } else { a.min(b) };
                }
                t
            };
            let (lo, hi) = (left[i].min(right[i]), left[i].max(right[i]));
            let (at_lo, at_hi) = (term(lo), term(hi));
            let crosses_zero = lo < 0.0 && hi > 0.0;
            h += if left[i] <= right[i] {
                let ends = at_lo.max(at_hi);
                if crosses_zero {
                    ends.max(term(0.0))
                } else {
                    ends
                }
            } else {
                let ends = at_lo.min(at_hi);
                if crosses_zero {
                    ends.min(term(0.0))
                } else {
                    ends
                }
            };
        }
        Some(h)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use fastrack_valuefn::system::{by_id, SYSTEM_IDS};
    use rand::{Rng, SeedableRng};

    /// The systems a grid can hold (quad10d's 10 coordinates cannot; its axes can).
    fn grid_systems() -> impl Iterator<Item = (&'static str, AffineSystem)> {
        SYSTEM_IDS.iter().map(|&id| (id, by_id(id).unwrap())).filter(|(_, s)| s.n_state() <= MAX_STATE)
    }

    #[test]
    fn matches_the_systems_own_hamiltonian() {
        let mut rng = rand::rngs::StdRng::seed_from_u64(3);
        for (id, system) in grid_systems() {
            let params: Vec<f64> = system.params.iter().map(|p| rng.random_range(p.min..p.max)).collect();
            let h = Hamiltonian::new(&system, &params);
            for _ in 0..200 {
                let r: Vec<f64> = system.state.iter().map(|d| rng.random_range(d.min..d.max)).collect();
                let p: Vec<f64> = (0..system.n_state()).map(|_| rng.random_range(-2.0..2.0)).collect();
                let (got, want) = (h.eval(&r, &p), system.hamiltonian(&r, &p, &params));
                assert!((got - want).abs() < 1e-12, "{id}: {got} vs {want} at r {r:?}, p {p:?}");
            }
        }
    }

    /// The largest (`maximise`) or smallest value of `h` over `[a, b]`, by dense sampling (and at 0, where an
    /// input's term `max_u p . G u` has its kink, so that steep axes are not under-sampled there).
    fn sampled_extreme(h: impl Fn(f64) -> f64, a: f64, b: f64, maximise: bool) -> f64 {
        let (lo, hi) = (a.min(b), a.max(b));
        let kink = (lo <= 0.0 && 0.0 <= hi).then_some(0.0);
        let samples = (0..=2_000).map(|k| lo + (hi - lo) * k as f64 / 2_000.0).chain(kink).map(h);
        if maximise {
            samples.fold(f64::NEG_INFINITY, f64::max)
        } else {
            samples.fold(f64::INFINITY, f64::min)
        }
    }

    #[test]
    fn godunov_is_the_axis_wise_extreme_of_the_hamiltonian_and_consistent() {
        let mut rng = rand::rngs::StdRng::seed_from_u64(5);
        for (id, system) in grid_systems() {
            let params: Vec<f64> = system.params.iter().map(|p| rng.random_range(p.min..p.max)).collect();
            let h = Hamiltonian::new(&system, &params);
            assert!(h.is_separable(), "{id}");
            let n = system.n_state();
            for _ in 0..200 {
                let r: Vec<f64> = system.state.iter().map(|d| rng.random_range(d.min..d.max)).collect();
                let mut f = vec![0.0; n];
                h.drift(&r, &mut f);
                let left: Vec<f64> = (0..n).map(|_| rng.random_range(-2.0..2.0)).collect();
                let right: Vec<f64> = (0..n).map(|_| rng.random_range(-2.0..2.0)).collect();
                // H(r, p) = sum_i h_i(p_i) with h_i(0) = 0, so h_i(q) = H(r, q e_i).
                let want: f64 = (0..n)
                    .map(|i| {
                        let axis = |q: f64| {
                            let mut p = vec![0.0; n];
                            p[i] = q;
                            system.hamiltonian(&r, &p, &params)
                        };
                        sampled_extreme(axis, left[i], right[i], left[i] <= right[i])
                    })
                    .sum();
                let got = h.godunov(&f, &left, &right).unwrap();
                assert!((got - want).abs() < 1e-3, "{id}: {got} vs sampled {want}");
                let same = h.godunov(&f, &left, &left).unwrap();
                assert!((same - h.eval(&r, &left)).abs() < 1e-12, "{id}: not consistent");
                // Godunov stays within Lax-Friedrichs' dissipation of the Lax-Friedrichs flux.
                let mut alpha = vec![0.0; n];
                system.dissipation_bounds(&r, &params, &mut alpha);
                let lf = h.lax_friedrichs(&f, &left, &right, &alpha);
                let spread: f64 = (0..n).map(|i| alpha[i] * (right[i] - left[i]).abs()).sum();
                assert!((got - lf).abs() <= spread + 1e-9, "{id}: godunov {got}, lax-friedrichs {lf}");
            }
        }
    }

    #[test]
    fn a_hamiltonian_with_an_input_on_two_coordinates_has_no_godunov_flux() {
        let mut system = by_id("dubins4d").unwrap();
        system.g_control[(0, 0)] = 0.5;
        let h = Hamiltonian::new(&system, &[1.0, 1.0]);
        assert!(!h.is_separable());
        assert_eq!(h.godunov(&[0.0; 4], &[1.0; 4], &[2.0; 4]), None);
    }
}
