//! The shipped trained model `models/dubins4d/5`, served by the real server: it loads (checksum, schema,
//! graph), says it is trained and verified, serves its table as written, its values keep the property every
//! value function has, `V >= l` (the error can only be at least the current one), on random states, and its
//! served control never pushes the speed past the tracker's limits. Every row's certified set holds states
//! of a robot on its planner, and the table says how far each set lies in the next one's.

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
    let (evaluator, manifest) = evaluator_for(&repo.join("dubins4d/5"));
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

/// Uniform states of dubins4d's domain with the position error within `reach`, `count` of them.
fn proposals(rng: &mut impl Rng, reach: f64, count: usize) -> Vec<f64> {
    (0..count)
        .flat_map(|_| {
            [
                rng.random_range(-reach..reach),
                rng.random_range(-reach..reach),
                rng.random_range(-std::f64::consts::PI..std::f64::consts::PI),
                rng.random_range(0.0..3.0),
            ]
        })
        .collect()
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn every_certified_set_can_be_entered_and_the_table_says_where_they_nest() {
    let repo = Path::new(env!("CARGO_MANIFEST_DIR")).join("../models");
    let (_server, client) = TestServer::start_serving(&repo).await;
    let model = || model_ref("dubins4d", 5);
    let table = client.get_model(model()).await.unwrap().teb_table;
    let in_teb = |states: Vec<f64>, beta: f64| {
        let params = vec![beta; states.len() / 4];
        let client = &client;
        async move { client.evaluate_value(model(), states, params, pb::OutOfDomainPolicy::Flag).await.unwrap().in_teb }
    };
    let mut rng = rand::rngs::StdRng::seed_from_u64(5);

    // A robot on its planner (zero position error) at some heading and speed lies in every row's set.
    for row in &table {
        let slice: Vec<f64> = proposals(&mut rng, 1.0, 2000).chunks(4).flat_map(|s| [0.0, 0.0, s[2], s[3]]).collect();
        let inside = in_teb(slice, row.beta).await.iter().filter(|&&b| b).count();
        assert!(inside >= 20, "beta {}: {inside} of 2000 zero-error states in the certified set", row.beta);
    }

    // Every row but the last says how much of its set lies in the next one's; checked on the least and the
    // most nested rows against the server's own membership of uniform samples of the set.
    let (last, rest) = table.split_last().unwrap();
    assert_eq!(last.nested_share, None);
    let shares: Vec<f64> = rest.iter().map(|r| r.nested_share.expect("measured")).collect();
    assert!(shares.iter().all(|s| (0.0..=1.0).contains(s)), "{shares:?}");
    let least = (0..shares.len()).min_by(|&a, &b| shares[a].total_cmp(&shares[b])).unwrap();
    let most = (0..shares.len()).max_by(|&a, &b| shares[a].total_cmp(&shares[b])).unwrap();
    for i in [least, most] {
        let (row, next) = (&table[i], &table[i + 1]);
        let mut samples = Vec::new();
        while samples.len() < 4 * 600 {
            let states = proposals(&mut rng, (2.5 * row.set_level).min(3.0), 4096);
            let inside = in_teb(states.clone(), row.beta).await;
            samples.extend(states.chunks(4).zip(inside).filter(|(_, b)| *b).flat_map(|(s, _)| s.to_vec()));
        }
        let n = samples.len() / 4;
        let nested = in_teb(samples, next.beta).await.iter().filter(|&&b| b).count() as f64 / n as f64;
        let share = shares[i];
        // Two binomial estimates of one share (2,000 and ~600 samples): within about 4 standard deviations.
        assert!(
            (nested - share).abs() <= 0.08,
            "beta {}: {nested:.3} of {n} samples nested, table says {share}",
            row.beta
        );
    }
    assert!(shares[least] < 0.9, "the shipped table has rows whose sets do not nest: {shares:?}");
}
