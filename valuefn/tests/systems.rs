//! The generic affine-system machinery against brute force and the closed-form Hamiltonians of dubins4d and
//! quad10d, and quad10d's exact decomposition into its axes.

use fastrack_valuefn::system::{double_integrator, dubins4d, quad10d, AffineSystem};
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
    // |dH/dp_i| <= alpha_i: check with finite differences of H in p, at the largest parameters.
    let mut rng = rand::rngs::StdRng::seed_from_u64(13);
    for id in fastrack_valuefn::system::SYSTEM_IDS {
        let system = fastrack_valuefn::system::by_id(id).unwrap();
        let n = system.n_state();
        let params: Vec<f64> = system.params.iter().map(|p| p.max).collect();
        let mut alpha = vec![0.0; n];
        for _ in 0..500 {
            let r = random_state(&system, &mut rng);
            let p: Vec<f64> = (0..n).map(|_| rng.random_range(-3.0..3.0)).collect();
            system.dissipation_bounds(&r, &params, &mut alpha);
            for i in 0..n {
                let mut q = p.clone();
                q[i] += 1e-6;
                let slope = (system.hamiltonian(&r, &q, &params) - system.hamiltonian(&r, &p, &params)) / 1e-6;
                assert!(slope.abs() <= alpha[i] + 1e-6, "{id} dim {i}: slope {slope} > alpha {}", alpha[i]);
            }
        }
    }
}

#[test]
fn quad10d_hamiltonian_and_controls_equal_brute_force_and_closed_form() {
    use quad10d::{D0, D1, GRAVITY as G, K_T, N0, THRUST_MAX, TILT_MAX};
    let system = quad10d::system();
    let mut rng = rand::rngs::StdRng::seed_from_u64(21);
    let (mut thrust_up, mut thrust_off) = (0, 0);
    for _ in 0..2000 {
        let r = random_state(&system, &mut rng);
        let p: Vec<f64> = (0..10).map(|_| rng.random_range(-3.0..3.0)).collect();
        let params: Vec<f64> = (0..3).map(|_| rng.random_range(0.5..1.5)).collect();
        let h = system.hamiltonian(&r, &p, &params);
        let brute = brute_force_hamiltonian(&system, &r, &p, &params);
        assert!((h - brute).abs() < 1e-9, "H {h} vs brute force {brute}");
        let axis = |k: usize, beta: f64| {
            p[k] * r[k + 1] + p[k + 1] * G * r[k + 2].tan() + p[k + 2] * r[k + 3]
                - p[k + 3] * (D0 * r[k + 2] + D1 * r[k + 3])
                + beta * p[k].abs()
                - N0 * TILT_MAX * p[k + 3].abs()
        };
        // The thrust box [0, 1.5 g] is not centred on 0: the minimum of p10 k_T u_z is k_T 1.5 g p10 when
        // p10 < 0 and 0 otherwise, and gravity is a drift.
        let vertical = p[8] * r[9] + params[2] * p[8].abs() - G * p[9] + (K_T * THRUST_MAX * p[9]).min(0.0);
        let closed = axis(0, params[0]) + axis(4, params[1]) + vertical;
        assert!((h - closed).abs() < 1e-9, "H {h} vs the closed form {closed}");

        let u = system.optimal_control(&r, &p);
        let thrust = if p[9] < 0.0 {
            thrust_up += 1;
            THRUST_MAX
        } else {
            thrust_off += 1;
            0.0
        };
        assert_eq!(u, vec![-TILT_MAX * p[3].signum(), -TILT_MAX * p[7].signum(), thrust]);
        let up = system.worst_planner(&p, &params);
        assert_eq!(up, vec![-params[0] * p[0].signum(), -params[1] * p[4].signum(), -params[2] * p[8].signum()]);
        let mut rdot = vec![0.0; 10];
        system.dynamics(&r, &u, &up, &[], &mut rdot);
        let attained: f64 = rdot.iter().zip(&p).map(|(a, b)| a * b).sum();
        assert!((attained - h).abs() < 1e-9, "u*, u_p* attain H");
    }
    assert!(thrust_up > 500 && thrust_off > 500, "both ends of the thrust box: {thrust_up} / {thrust_off}");
    // Where the gradient gives no direction, the control is the middle of the box: hover-ish thrust 0.75 g.
    let u = system.optimal_control(&[0.0; 10], &[0.0; 10]);
    assert_eq!(u, vec![0.0, 0.0, 0.5 * THRUST_MAX]);
}

#[test]
fn quad10d_splits_exactly_into_its_axes() {
    let full = quad10d::system();
    let (x, z) = (quad10d::x_axis(), quad10d::z_axis());
    assert_eq!((x.n_state(), x.n_params(), x.n_control(), x.planner_dim()), (4, 1, 1, 1));
    assert_eq!((z.n_state(), z.n_params(), z.n_control(), z.planner_dim()), (2, 1, 1, 1));
    assert_eq!((x.error_coords.clone(), z.error_coords.clone()), (vec![0], vec![0]));
    assert_eq!((x.params[0].name, z.params[0].name), ("beta_1", "beta_3"));
    assert_eq!((z.controls[0].min, z.controls[0].max), (0.0, quad10d::THRUST_MAX));
    // The y axis is the x axis on r5..r8 with beta_2.
    let y = full.subsystem("quad10d_y", "y", &[4, 5, 6, 7]).unwrap();
    assert_eq!(y.params[0].name, "beta_2");
    let mut rng = rand::rngs::StdRng::seed_from_u64(22);
    for _ in 0..1000 {
        let r = random_state(&full, &mut rng);
        let p: Vec<f64> = (0..10).map(|_| rng.random_range(-3.0..3.0)).collect();
        let params: Vec<f64> = (0..3).map(|_| rng.random_range(0.5..1.5)).collect();
        // H splits into the axes' Hamiltonians, the y axis solved by the x axis' system.
        let parts = x.hamiltonian(&r[0..4], &p[0..4], &params[0..1])
            + x.hamiltonian(&r[4..8], &p[4..8], &params[1..2])
            + z.hamiltonian(&r[8..10], &p[8..10], &params[2..3]);
        let h = full.hamiltonian(&r, &p, &params);
        assert!((h - parts).abs() < 1e-9, "H {h} vs the sum of its axes {parts}");
        assert!(
            (y.hamiltonian(&r[4..8], &p[4..8], &params[1..2]) - x.hamiltonian(&r[4..8], &p[4..8], &params[1..2])).abs()
                < 1e-12
        );
        // The full control is the axes' controls side by side, and so are the dynamics.
        let u = full.optimal_control(&r, &p);
        let (ux, uy, uz) = (
            x.optimal_control(&r[0..4], &p[0..4]),
            x.optimal_control(&r[4..8], &p[4..8]),
            z.optimal_control(&r[8..10], &p[8..10]),
        );
        assert_eq!(u, vec![ux[0], uy[0], uz[0]]);
        let up = full.worst_planner(&p, &params);
        let mut rdot = vec![0.0; 10];
        full.dynamics(&r, &u, &up, &[], &mut rdot);
        let mut axis_dot = vec![0.0; 4];
        x.dynamics(&r[4..8], &uy, &up[1..2], &[], &mut axis_dot);
        assert_eq!(&rdot[4..8], axis_dot.as_slice());
        let mut vertical_dot = vec![0.0; 2];
        z.dynamics(&r[8..10], &uz, &up[2..3], &[], &mut vertical_dot);
        assert_eq!(&rdot[8..10], vertical_dot.as_slice());
    }
}

#[test]
fn every_decomposition_partitions_the_state_into_its_subsystems() {
    let mut rng = rand::rngs::StdRng::seed_from_u64(23);
    let mut decomposed = 0;
    for id in fastrack_valuefn::system::SYSTEM_IDS {
        let Some(axes) = fastrack_valuefn::system::decomposition(id) else { continue };
        decomposed += 1;
        let full = fastrack_valuefn::system::by_id(id).unwrap();
        let mut covered: Vec<usize> = axes.iter().flat_map(|a| a.coords.clone()).collect();
        covered.sort_unstable();
        assert_eq!(covered, (0..full.n_state()).collect::<Vec<_>>(), "{id}: the axes partition the state");
        for _ in 0..200 {
            let r = random_state(&full, &mut rng);
            let p: Vec<f64> = (0..full.n_state()).map(|_| rng.random_range(-3.0..3.0)).collect();
            let params: Vec<f64> = full.params.iter().map(|d| rng.random_range(d.min..d.max)).collect();
            let mut sum = 0.0;
            for axis in &axes {
                let sub = fastrack_valuefn::system::by_id(axis.subsystem).unwrap();
                let cut = full.subsystem("cut", "cut", &axis.coords).unwrap();
                let (ra, pa): (Vec<f64>, Vec<f64>) = axis.coords.iter().map(|&i| (r[i], p[i])).unzip();
                let h = sub.hamiltonian(&ra, &pa, &[params[axis.param]]);
                assert!(
                    (h - cut.hamiltonian(&ra, &pa, &[params[axis.param]])).abs() < 1e-12,
                    "{id}: {}",
                    axis.subsystem
                );
                sum += h;
            }
            assert!((full.hamiltonian(&r, &p, &params) - sum).abs() < 1e-9, "{id}: H is the sum over its axes");
        }
    }
    assert_eq!(decomposed, 1, "quad10d decomposes");
}

#[test]
fn a_subsystem_must_decouple() {
    let dubins = dubins4d::system();
    let coupled = dubins.subsystem("d", "d", &[0, 1]).unwrap_err();
    assert!(coupled.contains("the drift of x_r depends on v, which is not chosen"), "{coupled}");
    let no_error = dubins.subsystem("d", "d", &[2, 3]).unwrap_err();
    assert!(no_error.contains("no error coordinate"), "{no_error}");
    let quad = quad10d::system();
    // The tilt alone: its drift is the tilt's rate.
    assert!(quad.subsystem("q", "q", &[0, 1, 2]).unwrap_err().contains("omega_x"));
    assert!(quad.subsystem("q", "q", &[0, 11]).unwrap_err().contains("does not exist"));
    // An input acting on two axes couples them.
    let mut shared = quad10d::system();
    shared.g_control[(7, 0)] = 1.0;
    let err = shared.subsystem("q", "q", &[0, 1, 2, 3]).unwrap_err();
    assert!(err.contains("control u_x also acts on omega_y"), "{err}");
}

#[test]
fn quad10d_relative_state_subtracts_the_planner_position_per_axis() {
    let space = quad10d::system().state_space();
    let tracker = [1.0, 0.5, 0.1, 0.2, -1.0, 0.0, 0.0, 0.0, 2.0, -0.5];
    let r = space.relative_state(&tracker, &[0.25, -1.5, 1.0]);
    assert_eq!(r, vec![0.75, 0.5, 0.1, 0.2, 0.5, 0.0, 0.0, 0.0, 1.0, -0.5]);
    assert!((space.tracking_error(&r) - (0.75f64 * 0.75 + 0.25 + 1.0).sqrt()).abs() < 1e-12);
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

/// The paper's form of one horizontal axis, `r = (r1, r2, r3, r4)` with `r4` the tilt filter's internal
/// state: `r1' = r2 - u_p`, `r2' = g tan r3`, `r3' = -d1 r3 + r4`, `r4' = -d0 r3 + n0 u`.
fn paper_horizontal_axis(r: &[f64], u: f64, up: f64) -> [f64; 4] {
    use quad10d::{D0, D1, GRAVITY, N0};
    [r[1] - up, GRAVITY * r[2].tan(), -D1 * r[2] + r[3], -D0 * r[2] + N0 * u]
}

#[test]
fn quad10d_s_horizontal_axis_is_the_paper_s_under_the_tilt_rate_shear() {
    use quad10d::{D1, TILT_MAX, TILT_RATE_HALF_WIDTH};
    let x = quad10d::x_axis();
    assert_eq!((x.state[3].name, x.state[3].max), ("omega_x", TILT_RATE_HALF_WIDTH));
    // z = T r: (x_r, v_x, theta_x, omega_x) = (r1, r2, r3, r4 - d1 r3).
    let to_ours = |r: &[f64]| [r[0], r[1], r[2], r[3] - D1 * r[2]];
    let mut rng = rand::rngs::StdRng::seed_from_u64(23);
    for _ in 0..1000 {
        let r: Vec<f64> = [5.0, 4.0, 0.5, 4.5].iter().map(|&h: &f64| rng.random_range(-h..h)).collect();
        let z = to_ours(&r);
        // T is linear, so z' = T r' for every input: one system.
        let (u, up) = (rng.random_range(-TILT_MAX..TILT_MAX), rng.random_range(-1.5..1.5));
        let mut z_dot = vec![0.0; 4];
        x.dynamics(&z, &[u], &[up], &[], &mut z_dot);
        let mapped = to_ours(&paper_horizontal_axis(&r, u, up));
        assert!(mapped.iter().zip(&z_dot).all(|(a, b)| (a - b).abs() < 1e-9), "{mapped:?} vs {z_dot:?}");
        // V_paper(r) = V(T r), so dV_paper/dr = T^T dV/dz and the paper's Hamiltonian at (r, T^T p) is ours
        // at (T r, p): the same game, the same bound. The paper's H by brute force over u and u_p.
        let p: Vec<f64> = (0..4).map(|_| rng.random_range(-3.0..3.0)).collect();
        let pulled = [p[0], p[1], p[2] - D1 * p[3], p[3]];
        let beta = rng.random_range(0.5..1.5);
        let paper_h = [-TILT_MAX, TILT_MAX]
            .iter()
            .map(|&u| {
                [-beta, beta]
                    .iter()
                    .map(|&up| paper_horizontal_axis(&r, u, up).iter().zip(&pulled).map(|(a, b)| a * b).sum::<f64>())
                    .fold(f64::NEG_INFINITY, f64::max)
            })
            .fold(f64::INFINITY, f64::min);
        let h = x.hamiltonian(&z, &p, &[beta]);
        assert!((h - paper_h).abs() < 1e-9, "H {h} vs the paper's {paper_h}");
    }
    // The tilt rate's domain holds what the tilt reaches from rest: its impulse response's rate integrates to
    // 2 h_max, and TILT_MAX times that is the largest |omega| any command can force.
    let (dt, mut theta, mut omega, mut integral) = (1e-5, 0.0f64, quad10d::N0, 0.0);
    for _ in 0..(10.0 / dt) as usize {
        integral += omega.abs() * dt;
        let accel = -quad10d::D0 * theta - D1 * omega;
        theta += omega * dt;
        omega += accel * dt;
    }
    let largest = TILT_MAX * integral;
    assert!((largest - 0.69).abs() < 0.005 && largest < TILT_RATE_HALF_WIDTH, "largest tilt rate {largest}");
}

#[test]
fn the_resting_control_holds_a_quadcopter_and_leaves_a_car_coasting() {
    // Level, moving at 0.5 m/s along x: the thrust that cancels gravity, no tilt command.
    let quad = quad10d::system();
    let mut s = vec![0.0; 10];
    s[1] = 0.5;
    let u = quad.resting_control(&s);
    assert!(u[0].abs() < 1e-12 && u[1].abs() < 1e-12, "{u:?}");
    assert!((quad10d::K_T * u[2] - quad10d::GRAVITY).abs() < 1e-9, "hover thrust {}", u[2]);
    let mut rate = vec![0.0; 10];
    quad.dynamics(&s, &u, &[0.0; 3], &[], &mut rate);
    assert!(rate[9].abs() < 1e-9, "the vertical speed changes at {}", rate[9]);
    // Tilted: the filter's drift is cancelled as far as the tilt command's box allows.
    s[2] = 0.3;
    let tilted = quad.resting_control(&s);
    assert!(tilted[0] > 0.0 && tilted[0] <= std::f64::consts::PI / 9.0, "{tilted:?}");
    // A car's drift moves only its position: nothing to cancel.
    let car = dubins4d::system();
    assert_eq!(car.resting_control(&[1.0, 2.0, 0.7, 1.5]), vec![0.0, 0.0]);
}

#[test]
fn a_robot_starts_on_its_planner_with_its_heading_and_speed_where_its_system_keeps_them() {
    let right = std::f64::consts::FRAC_PI_2;
    // A car keeps them as they are (the heading wrapped into its period).
    let car = dubins4d::system();
    assert_eq!(car.start_state(right, 0.5).unwrap(), vec![0.0, 0.0, right, 0.5]);
    let wrapped = car.start_state(right + std::f64::consts::TAU, 0.5).unwrap();
    assert!((wrapped[2] - right).abs() < 1e-12, "{wrapped:?}");
    assert_eq!(car.resting_state(), None, "a car at rest still has a heading");
    // A quadcopter keeps its velocity's components (heading pi/2 is along +x), level and vertically still.
    let quad = quad10d::system();
    let moving = quad.start_state(right, 2.0).unwrap();
    for (i, x) in moving.iter().enumerate() {
        let expected = if i == 1 { 2.0 } else { 0.0 };
        assert!((x - expected).abs() < 1e-12, "coordinate {i}: {moving:?}");
    }
    let along_y = quad.start_state(0.0, 1.0).unwrap();
    assert_eq!((along_y[1], along_y[5]), (0.0, 1.0));
    assert_eq!(quad.resting_state(), Some(vec![0.0; 10]));
    assert_eq!(quad.start_state(1.0, 0.0).unwrap(), vec![0.0; 10], "at rest the heading does not show");
    // A single axis has nowhere to put them, and its subsystems say so.
    let err = double_integrator::system().start_state(0.0, 1.0).unwrap_err();
    assert!(err.contains("no motion over the ground"), "{err}");
    assert!(quad10d::x_axis().start_state(0.0, 1.0).is_err() && quad10d::x_axis().resting_state().is_none());
    let planar = quad.subsystem("horizontal", "both horizontal axes", &[0, 1, 2, 3, 4, 5, 6, 7]).unwrap();
    assert_eq!(planar.start_state(right, 2.0).unwrap()[1], 2.0);
}
