//! The promise a served row makes, checked from outside the project's own simulation code: while the
//! relative state lies in the row's certified set (`in_teb`, `V <= set_level`), the tracking error stays
//! within the row's bound (`GetTrackingErrorBound.radius`), whatever the planner does.
//!
//! The check is the one a safety reviewer would run on `dubins4d/5`: the tracker starts on the planner (zero
//! position error, where every start and every planner reset puts a robot) at every heading and at speeds
//! from 0.25 to 2 m/s; a tracker integrated here (RK4 of the car's own equations, the served control held for
//! the manifest's verification step) plays against the planner that plays the worst case of the served
//! gradient, `u_p = -beta sign(dV/dx_r, dV/dy_r)`, for 8 s. From the states the server calls inside, the
//! error never passes the bound; from states between the set level and the bound, which nothing certified,
//! it does.

use fastrack_client::{model_ref, pb, FastrackClient};
use fastrack_e2e::TestServer;
use std::f64::consts::TAU;
use std::path::Path;

/// How long each start is rolled out (s).
const HORIZON: f64 = 8.0;
/// Headings of the starts (evenly spaced over the circle).
const HEADINGS: usize = 24;
/// Speeds of the starts (m/s).
const SPEEDS: [f64; 8] = [0.25, 0.5, 0.75, 1.0, 1.25, 1.5, 1.75, 2.0];

/// The relative dynamics of `dubins4d` (`x_r' = v sin theta - u_px`, `y_r' = v cos theta - u_py`,
/// `theta' = omega`, `v' = alpha`), written here from the system's equations, not taken from the project.
fn derivative(r: [f64; 4], control: [f64; 2], planner: [f64; 2]) -> [f64; 4] {
    let [_, _, theta, v] = r;
    [v * theta.sin() - planner[0], v * theta.cos() - planner[1], control[0], control[1]]
}

/// One RK4 step of `step` seconds with the tracker's and the planner's inputs held.
fn rk4(r: [f64; 4], control: [f64; 2], planner: [f64; 2], step: f64) -> [f64; 4] {
    let shifted = |k: [f64; 4], h: f64| std::array::from_fn(|i| r[i] + h * k[i]);
    let k1 = derivative(r, control, planner);
    let k2 = derivative(shifted(k1, step / 2.0), control, planner);
    let k3 = derivative(shifted(k2, step / 2.0), control, planner);
    let k4 = derivative(shifted(k3, step), control, planner);
    std::array::from_fn(|i| r[i] + step / 6.0 * (k1[i] + 2.0 * k2[i] + 2.0 * k3[i] + k4[i]))
}

/// Every zero-error start: `(0, 0, theta, v)`.
fn zero_error_starts() -> Vec<[f64; 4]> {
    (0..HEADINGS)
        .flat_map(|k| SPEEDS.map(|v| [0.0, 0.0, TAU * k as f64 / HEADINGS as f64 - std::f64::consts::PI, v]))
        .collect()
}

/// The largest tracking error each start reaches against the served gradient's worst-case planner.
async fn largest_errors(client: &FastrackClient, starts: &[[f64; 4]], beta: f64, step: f64) -> Vec<f64> {
    let mut states = starts.to_vec();
    let mut largest: Vec<f64> = states.iter().map(|r| r[0].hypot(r[1])).collect();
    for _ in 0..(HORIZON / step).round() as usize {
        let flat = states.iter().flatten().copied().collect();
        let reply = client
            .evaluate_value(model_ref("dubins4d", 5), flat, vec![beta; states.len()], pb::OutOfDomainPolicy::Flag)
            .await
            .unwrap();
        for (i, r) in states.iter_mut().enumerate() {
            let gradient = &reply.gradients[4 * i..4 * i + 2];
            let planner = [-beta * gradient[0].signum(), -beta * gradient[1].signum()];
            let control = [reply.controls[2 * i], reply.controls[2 * i + 1]];
            *r = rk4(*r, control, planner, step);
            largest[i] = largest[i].max(r[0].hypot(r[1]));
        }
    }
    largest
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn from_the_states_served_as_inside_the_error_stays_within_the_bound() {
    let repo = Path::new(env!("CARGO_MANIFEST_DIR")).join("../models");
    let (_server, client) = TestServer::start_serving(&repo).await;
    let info = client.get_model(model_ref("dubins4d", 5)).await.unwrap();
    let starts = zero_error_starts();
    let mut uncertified_breaks = 0;
    // The two rows where a worst-case planner breaks the bound from outside the certified set.
    for beta in [0.5, 0.7] {
        let row = info.teb_table.iter().find(|r| (r.beta - beta).abs() < 1e-9).unwrap();
        let step = row.verification.as_ref().expect("a verified row").step;
        let teb = client.tracking_error_bound(model_ref("dubins4d", 5), beta, 0).await.unwrap();
        assert_eq!((teb.level, teb.radius), (row.set_level, row.bound));
        assert!(row.set_level < row.bound, "beta {beta}: the bound correction left the set below the bound");

        let flat = starts.iter().flatten().copied().collect();
        let at_start = client
            .evaluate_value(model_ref("dubins4d", 5), flat, vec![beta; starts.len()], pb::OutOfDomainPolicy::Flag)
            .await
            .unwrap();
        // Membership as served is membership in the certified set.
        for (i, &value) in at_start.values.iter().enumerate() {
            assert_eq!(at_start.in_teb[i], value <= row.set_level, "beta {beta}, start {:?}", starts[i]);
        }
        // Roll out every start inside the bound's level set: the certified ones and the ones between.
        let candidates: Vec<usize> = (0..starts.len()).filter(|&i| at_start.values[i] <= row.bound).collect();
        let chosen: Vec<[f64; 4]> = candidates.iter().map(|&i| starts[i]).collect();
        let errors = largest_errors(&client, &chosen, beta, step).await;
        let (mut inside, mut worst_inside, mut between, mut broke_between) = (0, 0.0f64, 0, 0);
        for (&i, &error) in candidates.iter().zip(&errors) {
            if at_start.in_teb[i] {
                inside += 1;
                worst_inside = worst_inside.max(error);
                assert!(
                    error <= teb.radius,
                    "beta {beta}: from {:?} (V {:.4}, served as inside) the error reached {error:.4}, past the bound {:.4}",
                    starts[i],
                    at_start.values[i],
                    teb.radius
                );
            } else {
                between += 1;
                broke_between += usize::from(error > teb.radius);
            }
        }
        eprintln!(
            "beta {beta}: set level {:.4}, bound {:.4}; {inside} starts inside (largest error {worst_inside:.4}), \
             {between} between the set level and the bound, {broke_between} of them past the bound",
            row.set_level, row.bound
        );
        assert!(inside > 0, "beta {beta}: some zero-error starts are certified");
        uncertified_breaks += broke_between;
    }
    // Serving `V <= bound` as inside would have broken the promise: the check can fail.
    assert!(uncertified_breaks > 0, "no start between the set level and the bound broke the bound");
}
