//! The shipped trained model `models/dubins4d/4`, served by the real server: it loads (checksum, schema,
//! graph), says it is trained and verified, serves its table as written, its values keep the property every
//! value function has, `V >= l` (the error can only be at least the current one), on random states, and its
//! served control never pushes the speed past the tracker's limits.

use fastrack_client::{model_ref, pb};
use fastrack_e2e::{evaluator_for, TestServer};
use fastrack_valuefn::network::PeriodicEncoding;
use rand::{Rng, SeedableRng};
use std::path::Path;

/// Largest amount by which the learned `V` may fall below `l` (the fit's error; measured -0.011 on these states).
const BELOW_L_TOLERANCE: f64 = 0.1;

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn the_shipped_dubins4d_model_is_trained_verified_and_served() {
    let repo = Path::new(env!("CARGO_MANIFEST_DIR")).join("../models");
    let (evaluator, manifest) = evaluator_for(&repo.join("dubins4d/4"));
    assert!(!manifest.untrained);
    assert_eq!(manifest.network.periodic_encoding, PeriodicEncoding::Circle);
    assert_eq!(manifest.state[3].limits, Some([0.1, 2.9]), "the speed limits");
    assert!(manifest.provenance.method.contains("supervised by grid solutions"), "{}", manifest.provenance.method);
    assert!(manifest.teb_table.len() >= 16);
    for row in &manifest.teb_table {
        let verification = row.verification.as_ref().expect("every row verified");
        assert!(row.bound() >= row.level && row.bound() >= verification.verified_level);
        // The certified set is the one verification sampled from, never the larger set of the bound.
        assert_eq!(Some(row.set_level()), verification.sampled_level);
    }

    let (_server, client) = TestServer::start_serving(&repo).await;
    for row in &manifest.teb_table {
        let teb = client.tracking_error_bound(model_ref("dubins4d", 0), row.beta, 0).await.unwrap();
        assert_eq!((teb.level, teb.radius, teb.table_beta), (row.set_level(), row.bound(), row.beta));
    }
    let slow = &manifest.teb_table[0];
    let speed = client.query_planner_control(model_ref("dubins4d", 0), Some(2.0 * slow.bound())).await.unwrap();
    let expected = manifest.teb_table.iter().rev().find(|r| r.bound() <= slow.bound()).unwrap();
    assert_eq!((speed.beta_query, speed.dteb_radius), (expected.beta, expected.bound()));

    let mut rng = rand::rngs::StdRng::seed_from_u64(3);
    let (n, mut states, mut params) = (2000, Vec::new(), Vec::new());
    for _ in 0..n {
        states.extend([
            rng.random_range(-3.0..3.0),
            rng.random_range(-3.0..3.0),
            rng.random_range(-std::f64::consts::PI..std::f64::consts::PI),
            rng.random_range(0.0..3.0),
        ]);
        params.push(rng.random_range(0.5..1.25));
    }
    let served = client
        .evaluate_value(model_ref("dubins4d", 0), states.clone(), params.clone(), pb::OutOfDomainPolicy::Reject)
        .await
        .unwrap();
    let s: Vec<f32> = states.iter().map(|&x| x as f32).collect();
    let p: Vec<f32> = params.iter().map(|&x| x as f32).collect();
    let local = evaluator.evaluate(&s, &p).unwrap();
    let mut lowest = f64::INFINITY;
    for i in 0..n {
        assert!((served.values[i] - f64::from(local.value[i])).abs() <= 1e-6 * (1.0 + served.values[i].abs()));
        let l = states[4 * i].hypot(states[4 * i + 1]);
        lowest = lowest.min(served.values[i] - l);
    }
    eprintln!("min V - l over {n} random states: {lowest:.4}");
    assert!(lowest > -BELOW_L_TOLERANCE, "V falls {:.3} below l", -lowest);

    // The served model says where the speed is held, and its control holds it there: at or above 2.9 m/s
    // it never accelerates, at or below 0.1 m/s it never brakes, whatever the learned gradient says.
    let info = client.get_model(model_ref("dubins4d", 0)).await.unwrap();
    assert_eq!(info.state[3].limits, Some(pb::Interval { min: 0.1, max: 2.9 }));
    for i in 0..n {
        states[4 * i + 3] = if i % 2 == 0 { rng.random_range(2.9..3.0) } else { rng.random_range(0.0..=0.1) };
    }
    let at_limits = client
        .tracking_control(model_ref("dubins4d", 0), states.clone(), params, pb::OutOfDomainPolicy::Reject)
        .await
        .unwrap();
    let (mut braking, mut accelerating) = (0, 0);
    for i in 0..n {
        let alpha = at_limits.controls[2 * i + 1];
        if i % 2 == 0 {
            assert!(alpha <= 0.0, "v = {}: alpha {alpha}", states[4 * i + 3]);
            braking += usize::from(alpha < 0.0);
        } else {
            assert!(alpha >= 0.0, "v = {}: alpha {alpha}", states[4 * i + 3]);
            accelerating += usize::from(alpha > 0.0);
        }
    }
    // Not a control stuck at zero: at each limit the learned gradient still decides between holding and
    // moving inwards.
    eprintln!("at the upper limit {braking} of {} brake; at the lower {accelerating} accelerate", n / 2);
    assert!(braking > 0 && accelerating > 0);
}
