//! The generic affine-system machinery against brute force and dubins4d's closed-form Hamiltonian.

use fastrack_valuefn::system::{double_integrator, dubins4d, AffineSystem};
use rand::{Rng, SeedableRng};

fn random_state(system: &AffineSystem, rng: &mut impl Rng) -> Vec<f64> {
    system.state.iter().map(|d| rng.random_range(d.min..d.max)).collect()
}

/// `min over control vertices of max over planner vertices of p . r'`.
fn brute_force_hamiltonian(system: &AffineSystem, r: &[f64], p: &[f64], params: &[f64]) -> f64 {
    let dot = |u: &[f64], up: &[f64]| {
        let mut rdot = vec![0.0; system.n_state()];
        system.dynamics(r, u, up, &[], &mut rdot);
        rdot.iter().zip(p).map(|(a, b)| a * b).sum::<f64>()
    };
    let planners = system.planner_box(params).vertices();
    system
        .control_box()
        .vertices()
        .iter()
        .map(|u| planners.iter().map(|up| dot(u, up)).fold(f64::NEG_INFINITY, f64::max))
        .fold(f64::INFINITY, f64::min)
}

#[test]
fn dubins4d_hamiltonian_and_controls_equal_brute_force_and_closed_form() {
    let system = dubins4d::system();
    let mut rng = rand::rngs::StdRng::seed_from_u64(11);
    for _ in 0..2000 {
        let r = random_state(&system, &mut rng);
        let p: Vec<f64> = (0..4).map(|_| rng.random_range(-3.0..3.0)).collect();
        let params = [rng.random_range(0.5..1.25), rng.random_range(0.5..1.25)];
        let h = system.hamiltonian(&r, &p, &params);
        let brute = brute_force_hamiltonian(&system, &r, &p, &params);
        assert!((h - brute).abs() < 1e-12, "H {h} vs brute force {brute}");
        let closed =
            p[0] * r[3] * r[2].sin() + p[1] * r[3] * r[2].cos() + params[0] * p[0].abs() + params[1] * p[1].abs()
                - 5.0 * p[2].abs()
                - p[3].abs();
        assert!((h - closed).abs() < 1e-12, "H {h} vs the closed form {closed}");

        // The optimal control attains the min over control vertices; the closed form is -5 sign(p3), -sign(p4)
        // (between the speed limits, where the whole box is allowed).
        let (low, high) = dubins4d::V_LIMITS;
        if r[3] <= low || r[3] >= high {
            continue;
        }
        let u = system.optimal_control(&r, &p);
        assert_eq!(u, vec![-5.0 * p[2].signum(), -p[3].signum()]);
        let up = system.worst_planner(&p, &params);
        assert_eq!(up, vec![-params[0] * p[0].signum(), -params[1] * p[1].signum()]);
        let mut rdot = vec![0.0; 4];
        system.dynamics(&r, &u, &up, &[], &mut rdot);
        let attained: f64 = rdot.iter().zip(&p).map(|(a, b)| a * b).sum();
        assert!((attained - h).abs() < 1e-12, "u*, u_p* attain H");
    }
}

#[test]
fn dubins4d_control_never_pushes_the_speed_past_its_limits() {
    let system = dubins4d::system();
    let (low, high) = dubins4d::V_LIMITS;
    let mut rng = rand::rngs::StdRng::seed_from_u64(14);
    let (mut at_high, mut at_low) = (0, 0);
    for _ in 0..4000 {
        let mut r = random_state(&system, &mut rng);
        // Half the states at or beyond a limit (inside or outside the domain).
        if rng.random_bool(0.5) {
            r[3] = if rng.random_bool(0.5) {
                rng.random_range(high..high + 1.0)
            } else {
                rng.random_range(low - 1.0..=low)
            };
        }
        let p: Vec<f64> = (0..4).map(|_| rng.random_range(-3.0..3.0)).collect();
        let u = system.optimal_control(&r, &p);
        // Turning is never restricted; acceleration is -sign(p4) cut at zero beyond a limit.
        assert_eq!(u[0], -5.0 * p[2].signum());
        let free = -p[3].signum();
        let expected = if r[3] >= high {
            at_high += 1;
            free.min(0.0)
        } else if r[3] <= low {
            at_low += 1;
            free.max(0.0)
        } else {
            free
        };
        assert_eq!(u[1], expected, "v = {}, p4 = {}", r[3], p[3]);
        // It minimises p . G_u u over the allowed range (brute force over that range's vertices).
        let range = system.control_range(&r);
        let best = range.vertices().iter().map(|v| p[2] * v[0] + p[3] * v[1]).fold(f64::INFINITY, f64::min);
        assert!((p[2] * u[0] + p[3] * u[1] - best).abs() < 1e-12);
    }
    assert!(at_high > 500 && at_low > 500, "both limits exercised: {at_high} / {at_low}");
}

#[test]
fn limits_are_checked_against_what_can_hold_them() {
    for id in fastrack_valuefn::system::SYSTEM_IDS {
        let system = fastrack_valuefn::system::by_id(id).unwrap();
        assert_eq!(system.check_limits(), Ok(()), "{id}");
    }
    let with = |i: usize, limits: (f64, f64), edit: &dyn Fn(&mut AffineSystem)| {
        let mut system = dubins4d::system();
        system.state[i].limits = Some(limits);
        edit(&mut system);
        system.check_limits().unwrap_err()
    };
    let none = |_: &mut AffineSystem| {};
    assert!(with(2, (-1.0, 1.0), &none).contains("non-periodic"), "a periodic coordinate");
    assert!(with(3, (0.1, 3.5), &none).contains("inside the domain"), "beyond the domain");
    assert!(with(3, (2.0, 1.0), &none).contains("increasing"), "reversed");
    assert!(with(0, (-1.0, 1.0), &none).contains("tracker's controls only"), "x_r moves with the drift and planner");
    let no_reverse = |s: &mut AffineSystem| s.controls[1].min = 0.5;
    assert!(with(3, (0.1, 2.9), &no_reverse).contains("excludes 0"), "alpha in [0.5, 1] cannot hold the speed");
    let undriven = |s: &mut AffineSystem| s.g_control[(3, 1)] = 0.0;
    assert!(with(3, (0.1, 2.9), &undriven).contains("no control drives"), "nothing moves v");
}

#[test]
fn double_integrator_hamiltonian_equals_brute_force() {
    let system = double_integrator::system();
    let mut rng = rand::rngs::StdRng::seed_from_u64(12);
    for _ in 0..500 {
        let r = random_state(&system, &mut rng);
        let p: Vec<f64> = (0..2).map(|_| rng.random_range(-2.0..2.0)).collect();
        let params = [rng.random_range(0.5..1.0)];
        let brute = brute_force_hamiltonian(&system, &r, &p, &params);
        assert!((system.hamiltonian(&r, &p, &params) - brute).abs() < 1e-12);
    }
}

#[test]
fn dissipation_bounds_dominate_hamiltonian_slopes() {
    // |dH/dp_i| <= alpha_i: check with finite differences of H in p.
    let system = dubins4d::system();
    let mut rng = rand::rngs::StdRng::seed_from_u64(13);
    let mut alpha = vec![0.0; 4];
    for _ in 0..500 {
        let r = random_state(&system, &mut rng);
        let p: Vec<f64> = (0..4).map(|_| rng.random_range(-3.0..3.0)).collect();
        let params = [1.25, 1.25];
        system.dissipation_bounds(&r, &params, &mut alpha);
        for i in 0..4 {
            let mut q = p.clone();
            q[i] += 1e-6;
            let slope = (system.hamiltonian(&r, &q, &params) - system.hamiltonian(&r, &p, &params)) / 1e-6;
            assert!(slope.abs() <= alpha[i] + 1e-6, "dim {i}: slope {slope} > alpha {}", alpha[i]);
        }
    }
}

#[test]
fn relative_state_subtracts_planner_and_wraps_angles() {
    let system = dubins4d::system();
    let space = system.state_space();
    let r = space.relative_state(&[1.0, 2.0, 3.0 * std::f64::consts::PI, 1.5], &[0.25, 0.5]);
    assert!((r[0] - 0.75).abs() < 1e-12 && (r[1] - 1.5).abs() < 1e-12);
    assert!((r[2] - (-std::f64::consts::PI)).abs() < 1e-9, "3 pi wraps to -pi, got {}", r[2]);
    assert_eq!(r[3], 1.5);
    assert!((system.tracking_error(&r) - (0.75f64.hypot(1.5))).abs() < 1e-12);
    assert!((space.tracking_error(&r) - system.tracking_error(&r)).abs() < 1e-15);
    assert!(space.in_domain(&r));
    assert!(!space.in_domain(&[3.5, 0.0, 0.0, 1.0]));
}
