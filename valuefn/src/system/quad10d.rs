//! The paper's second example: a near-hover quadcopter (10 relative states) tracking a 3-D point planner
//! with one speed bound per axis (3 parameters, 13 inputs to the value function).
//!
//! The paper writes each horizontal axis (x shown; y is the same with `u_py`, `u_y`) as `r1' = r2 - u_px`,
//! `r2' = g tan(r3)`, `r3' = -d1 r3 + r4`, `r4' = -d0 r3 + n0 u_x`, with `r4` an internal state of the tilt's
//! filter. The system here is the same one in the coordinates a robot measures: position error `x_r = r1`,
//! velocity `v_x = r2`, tilt `theta_x = r3` and the tilt's rate `omega_x = theta_x' = r4 - d1 r3` (a gyro's
//! reading), so that `theta_x' = omega_x` and `omega_x' = -d0 theta_x - d1 omega_x + n0 u_x`. The map is an
//! exact shear that keeps the error coordinate: the value function is the paper's at `r4 = omega_x + d1
//! theta_x` and every bound the same. Vertically: `z_r' = v_z - u_pz`, `v_z' = k_T u_z - g`.
//! `|u_x|, |u_y| <= pi/9`, `u_z in [0, 1.5 g]` (thrust: a box not centred on zero), `|u_pi| <= beta_i`,
//! `beta_i in [0.5, 1.5]`.
//!
//! Why these coordinates: from rest the paper's pair `(r3, r4)` stays in a thin band along `r4 = d1 r3`, so a
//! box in it (the domain a network is trained on, the grid a solver covers) holds mostly states no tracker
//! reaches; in `(theta_x, omega_x)` the reachable states fill the box.
//!
//! The system splits exactly into the x subsystem (coordinates 0..4; `beta_1`), the identical y subsystem
//! (4..8; `beta_2`) and the z subsystem (8, 9; `beta_3`): no drift term, input or parameter couples two of
//! them ([`AffineSystem::subsystem`] checks this). [`x_axis`] and [`z_axis`] are those subsystems, which the
//! grid solver can solve as ground truth.
//!
//! No coordinate has tracker limits: the tilt pair is an overdamped filter of the bounded tilt command
//! (poles `-4 +- sqrt(6)`, positive impulse responses), so from rest `|theta_x| <= pi/9` and
//! `|omega_x| <= 0.69` under any command, and the velocities are moved by the drift, which state limits
//! cannot hold.

use super::drift::{term, Factor};
use super::{AffineSystem, DecomposedAxis, Drift, GroundMotion, InputDim, ParamDim, StateDim};
use nalgebra::DMatrix;
use std::f64::consts::PI;

/// System id.
pub const ID: &str = "quad10d";
/// Id of the x (and y) subsystem `(x_r, v_x, theta_x, omega_x; beta_1)`.
pub const X_AXIS_ID: &str = "quad10d_x";
/// Id of the z subsystem `(z_r, v_z; beta_3)`.
pub const Z_AXIS_ID: &str = "quad10d_z";

/// Gravity (m/s^2).
pub const GRAVITY: f64 = 9.81;
/// Tilt-command gain `n0`.
pub const N0: f64 = 10.0;
/// Tilt damping `d1`.
pub const D1: f64 = 8.0;
/// Tilt stiffness `d0`.
pub const D0: f64 = 10.0;
/// Thrust gain `k_T`.
pub const K_T: f64 = 0.91;
/// Largest tilt command `|u_x|, |u_y|` (rad).
pub const TILT_MAX: f64 = PI / 9.0;
/// Largest thrust command `u_z` (m/s^2 before `k_T`); the smallest is 0.
pub const THRUST_MAX: f64 = 1.5 * GRAVITY;
/// Planner speed bounds `[beta_l, beta_u]` per axis (m/s).
pub const BETA_RANGE: (f64, f64) = (0.5, 1.5);

/// Half-width of each horizontal position-error domain (m): the x axis' error set at `beta_u` reaches about
/// 2.4 m on coarse grids (docs/grid-solver.md), and the convergence set is half as large again.
pub const POSITION_HALF_WIDTH: f64 = 5.0;
/// Half-width of each horizontal velocity domain (m/s).
pub const VELOCITY_HALF_WIDTH: f64 = 4.0;
/// Half-width of the tilt domain (rad): above [`TILT_MAX`], which bounds the tilt from rest, with room for
/// the states of the error set that are not reached from rest.
pub const TILT_HALF_WIDTH: f64 = 0.5;
/// Half-width of the tilt rate's domain (rad/s): above `2 h_max TILT_MAX` = 0.69, the largest tilt rate from
/// rest (`h_max` = 0.99 s^-1 the peak of the tilt's impulse response, whose rate changes sign once, so its
/// integral of `|h'|` is `2 h_max`).
pub const TILT_RATE_HALF_WIDTH: f64 = 1.0;
/// Half-width of the vertical position-error domain (m): 2.4 times the z axis' bound at `beta_u` (0.63 m).
pub const VERTICAL_POSITION_HALF_WIDTH: f64 = 1.5;
/// Half-width of the vertical velocity domain (m/s).
pub const VERTICAL_VELOCITY_HALF_WIDTH: f64 = 2.5;

fn symmetric(name: &'static str, unit: &'static str, half_width: f64) -> StateDim {
    StateDim { name, unit, min: -half_width, max: half_width, periodic: false, limits: None }
}

/// The four coordinates of one horizontal axis, named for `axis` (`x` or `y`).
fn horizontal_axis(axis: char) -> [StateDim; 4] {
    let (position, velocity, tilt, rate) = match axis {
        'x' => ("x_r", "v_x", "theta_x", "omega_x"),
        _ => ("y_r", "v_y", "theta_y", "omega_y"),
    };
    [
        symmetric(position, "m", POSITION_HALF_WIDTH),
        symmetric(velocity, "m/s", VELOCITY_HALF_WIDTH),
        symmetric(tilt, "rad", TILT_HALF_WIDTH),
        symmetric(rate, "rad/s", TILT_RATE_HALF_WIDTH),
    ]
}

/// The drift of one horizontal axis whose coordinates start at `first`.
fn horizontal_drift(first: usize) -> Vec<super::DriftTerm> {
    let (position, velocity, tilt, rate) = (first, first + 1, first + 2, first + 3);
    vec![
        term(position, 1.0, &[Factor::Linear(velocity)]),
        term(velocity, GRAVITY, &[Factor::Tan(tilt)]),
        term(tilt, 1.0, &[Factor::Linear(rate)]),
        term(rate, -D0, &[Factor::Linear(tilt)]),
        term(rate, -D1, &[Factor::Linear(rate)]),
    ]
}

/// The quad10d relative system (3 parameters `beta_1..3`).
pub fn system() -> AffineSystem {
    let mut state: Vec<StateDim> = horizontal_axis('x').into_iter().chain(horizontal_axis('y')).collect();
    state.push(symmetric("z_r", "m", VERTICAL_POSITION_HALF_WIDTH));
    state.push(symmetric("v_z", "m/s", VERTICAL_VELOCITY_HALF_WIDTH));
    let mut terms = horizontal_drift(0);
    terms.extend(horizontal_drift(4));
    terms.push(term(8, 1.0, &[Factor::Linear(9)]));
    terms.push(term(9, -GRAVITY, &[]));
    let drift = Drift { n_state: 10, terms };

    let mut g_control = DMatrix::zeros(10, 3);
    g_control[(3, 0)] = N0;
    g_control[(7, 1)] = N0;
    g_control[(9, 2)] = K_T;
    let mut g_planner = DMatrix::zeros(10, 3);
    let mut planner_to_state = DMatrix::zeros(10, 3);
    for (axis, row) in [0, 4, 8].into_iter().enumerate() {
        g_planner[(row, axis)] = -1.0;
        planner_to_state[(row, axis)] = 1.0;
    }
    let (beta_l, beta_u) = BETA_RANGE;
    let beta = |name| ParamDim { name, unit: "m/s", min: beta_l, max: beta_u };
    AffineSystem {
        id: ID,
        description: "near-hover quadcopter (per axis: position error, velocity, tilt, the tilt's rate; vertically: position error, velocity) tracking a 3-D point planner with per-axis speed bounds beta_1..3",
        state,
        error_coords: vec![0, 4, 8],
        params: vec![beta("beta_1"), beta("beta_2"), beta("beta_3")],
        planner_input_param: vec![0, 1, 2],
        controls: vec![
            InputDim { name: "u_x", unit: "rad", min: -TILT_MAX, max: TILT_MAX },
            InputDim { name: "u_y", unit: "rad", min: -TILT_MAX, max: TILT_MAX },
            InputDim { name: "u_z", unit: "m/s^2", min: 0.0, max: THRUST_MAX },
        ],
        disturbances: vec![],
        drift,
        g_control,
        g_planner,
        g_disturbance: DMatrix::zeros(10, 0),
        planner_to_state,
        ground_motion: GroundMotion::Velocity { x: 1, y: 5 },
    }
}

/// The x subsystem `(x_r, v_x, theta_x, omega_x; beta_1)`, which is also the y subsystem renamed.
pub fn x_axis() -> AffineSystem {
    system()
        .subsystem(X_AXIS_ID, "quad10d's x axis (position error, velocity, tilt, the tilt's rate) tracking a 1-D point planner with speed bound beta_1", &[0, 1, 2, 3])
        .expect("quad10d's x axis decouples")
}

/// The exact decomposition: the x axis on coordinates 0..4 with `beta_1`, the same subsystem on 4..8 with
/// `beta_2`, and the z axis on 8, 9 with `beta_3`.
pub fn axes() -> Vec<DecomposedAxis> {
    vec![
        DecomposedAxis { subsystem: X_AXIS_ID, coords: vec![0, 1, 2, 3], param: 0 },
        DecomposedAxis { subsystem: X_AXIS_ID, coords: vec![4, 5, 6, 7], param: 1 },
        DecomposedAxis { subsystem: Z_AXIS_ID, coords: vec![8, 9], param: 2 },
    ]
}

/// The largest upward acceleration `k_T THRUST_MAX - g` (m/s^2); the largest downward one is `g`.
pub const CLIMB_ACCEL: f64 = K_T * THRUST_MAX - GRAVITY;

/// Closed-form converged tracking error bound of the z subsystem, `V_min(beta_3) = beta_3^2 / a_up` with
/// `a_up` = [`CLIMB_ACCEL`], the smaller of its two accelerations.
///
/// With `e = z_r`, `v = v_z` and the planner's speed `w = +-beta`: a planner that holds `w = -beta` forces
/// `v` to `-beta` (else `e` grows without end), and a reversal to `+beta` then lowers `e` by at least
/// `(2 beta)^2 / (2 a_up)` before `v` reaches `+beta`; the mirror reversal raises it by `(2 beta)^2 / (2 g)`,
/// less. So every invariant band is at least `2 beta^2 / a_up` wide. The band between the curves
/// `e = e_low + (beta - v)^2 / (2 a_up)` and `e = e_high - (v + beta)^2 / (2 g)` with exactly that width is
/// invariant (climbing at `a_up` rides the lower curve, braking at `g` the upper one, and the two meet only
/// at `v = -beta`), and centring it gives `max |e| = beta^2 / a_up`.
pub fn z_axis_closed_form_teb(beta: f64) -> f64 {
    beta * beta / CLIMB_ACCEL
}

/// The z subsystem `(z_r, v_z; beta_3)`: a double integrator whose acceleration box `[-g, (1.5 k_T - 1) g]`
/// is not symmetric.
pub fn z_axis() -> AffineSystem {
    system()
        .subsystem(
            Z_AXIS_ID,
            "quad10d's z axis (position error, velocity) tracking a 1-D point planner with speed bound beta_3",
            &[8, 9],
        )
        .expect("quad10d's z axis decouples")
}
