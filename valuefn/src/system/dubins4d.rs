//! The paper's 6-D example: a Dubins car with speed control tracking a 2-D point planner.
//!
//! `r = (x_r, y_r, theta, v)`, `x_r' = v sin(theta) - u_px`, `y_r' = v cos(theta) - u_py`,
//! `theta' = omega`, `v' = alpha`; `omega in [-5, 5]`, `alpha in [-1, 1]`, `|u_pi| <= beta_i`,
//! `beta_1, beta_2 in [0.5, 1.25]`.

use super::drift::{term, Factor};
use super::{AffineSystem, Drift, GroundMotion, InputDim, ParamDim, StateDim};
use nalgebra::DMatrix;
use std::f64::consts::PI;

/// System id.
pub const ID: &str = "dubins4d";

/// Half-width of the position-error domain (m). Chosen to hold the converged TEB at `beta_u` with margin.
pub const POSITION_HALF_WIDTH: f64 = 3.0;
/// Speed domain `[V_MIN, V_MAX]` (m/s).
pub const V_MIN: f64 = 0.0;
/// Upper end of the speed domain (m/s): above the planner's top diagonal speed `sqrt(2) * 1.25`.
pub const V_MAX: f64 = 3.0;
/// The tracker's speed limits (m/s), 0.1 m/s inside the domain: the served control never accelerates past
/// `V_LIMITS.1` nor brakes below `V_LIMITS.0`, so a tracker applying it for up to 0.1 s per control step stays
/// inside the trained domain (without them, rollouts left it where the value is flat in `v`: README).
pub const V_LIMITS: (f64, f64) = (0.1, 2.9);

fn position(name: &'static str) -> StateDim {
    StateDim { name, unit: "m", min: -POSITION_HALF_WIDTH, max: POSITION_HALF_WIDTH, periodic: false, limits: None }
}

/// The dubins4d relative system.
pub fn system() -> AffineSystem {
    let state = vec![
        position("x_r"),
        position("y_r"),
        StateDim { name: "theta", unit: "rad", min: -PI, max: PI, periodic: true, limits: None },
        StateDim { name: "v", unit: "m/s", min: V_MIN, max: V_MAX, periodic: false, limits: Some(V_LIMITS) },
    ];
    let drift = Drift {
        n_state: 4,
        terms: vec![
            term(0, 1.0, &[Factor::Linear(3), Factor::Sin(2)]),
            term(1, 1.0, &[Factor::Linear(3), Factor::Cos(2)]),
        ],
    };
    let mut g_control = DMatrix::zeros(4, 2);
    g_control[(2, 0)] = 1.0;
    g_control[(3, 1)] = 1.0;
    let mut g_planner = DMatrix::zeros(4, 2);
    g_planner[(0, 0)] = -1.0;
    g_planner[(1, 1)] = -1.0;
    let mut planner_to_state = DMatrix::zeros(4, 2);
    planner_to_state[(0, 0)] = 1.0;
    planner_to_state[(1, 1)] = 1.0;
    AffineSystem {
        id: ID,
        description: "Dubins car with speed control (x_r, y_r, theta, v) tracking a 2-D point planner with per-axis speed bounds beta_1, beta_2",
        state,
        error_coords: vec![0, 1],
        params: vec![
            ParamDim { name: "beta_1", unit: "m/s", min: 0.5, max: 1.25 },
            ParamDim { name: "beta_2", unit: "m/s", min: 0.5, max: 1.25 },
        ],
        planner_input_param: vec![0, 1],
        controls: vec![
            InputDim { name: "omega", unit: "rad/s", min: -5.0, max: 5.0 },
            InputDim { name: "alpha", unit: "m/s^2", min: -1.0, max: 1.0 },
        ],
        disturbances: vec![],
        drift,
        g_control,
        g_planner,
        g_disturbance: DMatrix::zeros(4, 0),
        planner_to_state,
        ground_motion: GroundMotion::HeadingAndSpeed { heading: 2, speed: 3 },
    }
}
