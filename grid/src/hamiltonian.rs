//! The Hamiltonian of a control- and planner-affine system prepared for the grid's inner loop (no
//! allocation per point), and the Lax-Friedrichs numerical Hamiltonian with per-point dissipation.

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
}

/// Largest state dimension the inner loop supports (stack buffers).
pub const MAX_STATE: usize = crate::grid::MAX_DIMS;

impl Hamiltonian {
    /// Prepares `system`'s Hamiltonian at parameters `params`.
    pub fn new(system: &AffineSystem, params: &[f64]) -> Self {
        let mut maximised = box_inputs(&system.g_planner, &system.planner_box(params));
        maximised.extend(box_inputs(&system.g_disturbance, &system.disturbance_box()));
        Self { system: system.clone(), minimised: box_inputs(&system.g_control, &system.control_box()), maximised }
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
}

#[cfg(test)]
mod tests {
    use super::*;
    use fastrack_valuefn::system::{by_id, SYSTEM_IDS};
    use rand::{Rng, SeedableRng};

    #[test]
    fn matches_the_systems_own_hamiltonian() {
        let mut rng = rand::rngs::StdRng::seed_from_u64(3);
        for id in SYSTEM_IDS {
            let system = by_id(id).unwrap();
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
}
