//! A 1-D double integrator tracking a point planner, whose tracking error bound has a closed form.
//!
//! `r = (x_r, v)`, `x_r' = v - u_p`, `v' = u`, `|u| <= a`, `|u_p| <= beta`. Whatever the tracker does,
//! it must match the planner's speed (`v = -beta` say) to stop the error drifting, and from there a
//! planner reversal moves the error by `(2 beta)^2 / (2a)` before the speeds match again; centring that
//! swing gives the smallest invariant band, `V_min(beta) = beta^2 / a`. The value converges in the horizon
//! on the time scale `beta / a` (about `5.5 beta / a` to within a few percent, measured with the grid solver),
//! so `a = 1` keeps the training horizon short.

use super::drift::{term, Factor};
use super::{AffineSystem, Drift, GroundMotion, InputDim, ParamDim, StateDim};
use nalgebra::DMatrix;

/// System id.
pub const ID: &str = "double_integrator";

/// Tracker acceleration bound `a` (m/s^2).
pub const ACCEL: f64 = 1.0;

/// Closed-form converged tracking error bound `V_min(beta) = beta^2 / a`.
pub fn closed_form_teb(beta: f64) -> f64 {
    beta * beta / ACCEL
}

/// The double-integrator relative system.
pub fn system() -> AffineSystem {
    let drift = Drift { n_state: 2, terms: vec![term(0, 1.0, &[Factor::Linear(1)])] };
    AffineSystem {
        id: ID,
        description: "1-D double integrator (x_r, v), |u| <= 1, tracking a point planner with |u_p| <= beta",
        state: vec![
            StateDim { name: "x_r", unit: "m", min: -2.0, max: 2.0, periodic: false, limits: None },
            StateDim { name: "v", unit: "m/s", min: -1.5, max: 1.5, periodic: false, limits: None },
        ],
        error_coords: vec![0],
        params: vec![ParamDim { name: "beta", unit: "m/s", min: 0.5, max: 1.0 }],
        planner_input_param: vec![0],
        controls: vec![InputDim { name: "u", unit: "m/s^2", min: -ACCEL, max: ACCEL }],
        disturbances: vec![],
        drift,
        g_control: DMatrix::from_column_slice(2, 1, &[0.0, 1.0]),
        g_planner: DMatrix::from_column_slice(2, 1, &[-1.0, 0.0]),
        g_disturbance: DMatrix::zeros(2, 0),
        planner_to_state: DMatrix::from_column_slice(2, 1, &[1.0, 0.0]),
        ground_motion: GroundMotion::None,
    }
}
