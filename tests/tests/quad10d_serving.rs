//! One real server serving dubins4d and quad10d from one repository. The server knows neither system: the
//! quad's ten coordinates, its three per-axis speed bounds, its thrust box that is not centred on zero and
//! the shape of its bad input all come from the bundle's manifest and graph.

use fastrack_client::{model_ref, pb};
use fastrack_e2e::{evaluator_for, expect_error, write_test_bundle, TestServer};
use fastrack_valuefn::system::{dubins4d, quad10d};
use rand::{Rng, SeedableRng};
use tonic::Code;

fn close(a: f64, b: f32) -> bool {
    (a - f64::from(b)).abs() <= 1e-6 * (1.0 + a.abs())
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn one_server_serves_dubins4d_and_quad10d_and_refuses_bad_quad_input() {
    let repo = tempfile::tempdir().unwrap();
    write_test_bundle(repo.path(), &dubins4d::system(), "car", 1, 1);
    let quad_dir = write_test_bundle(repo.path(), &quad10d::system(), "quad", 1, 2);
    let (mut server, client) = TestServer::start_serving(repo.path()).await;
    let quad = || model_ref("quad", 0);

    let systems: Vec<(String, String)> =
        client.list_models().await.unwrap().into_iter().map(|m| (m.name, m.system)).collect();
    assert_eq!(systems, vec![("car".into(), "dubins4d".into()), ("quad".into(), "quad10d".into())]);
    let info = client.get_model(quad()).await.unwrap();
    assert_eq!((info.state.len(), info.params.len(), info.controls.len(), info.planner_dim), (10, 3, 3, 3));
    let errors: Vec<&str> = info.state.iter().filter(|d| d.error_coordinate).map(|d| d.name.as_str()).collect();
    assert_eq!(errors, ["x_r", "y_r", "z_r"]);
    let params: Vec<(&str, f64, f64)> = info
        .params
        .iter()
        .map(|p| {
            let range = p.range.unwrap_or_default();
            (p.name.as_str(), range.min, range.max)
        })
        .collect();
    assert_eq!(params, [("beta_1", 0.5, 1.5), ("beta_2", 0.5, 1.5), ("beta_3", 0.5, 1.5)]);
    let thrust = &info.controls[2];
    let bounds = thrust.bounds.unwrap_or_default();
    assert_eq!((thrust.name.as_str(), bounds.min, bounds.max), ("u_z", 0.0, quad10d::THRUST_MAX));

    // Per-axis speed bounds, each item its own: the served answers are the graph's, evaluated in-process.
    let system = quad10d::system();
    let mut rng = rand::rngs::StdRng::seed_from_u64(3);
    let n = 32;
    let states: Vec<f64> =
        (0..n).flat_map(|_| system.state.iter().map(|d| rng.random_range(d.min..d.max)).collect::<Vec<_>>()).collect();
    let betas: Vec<f64> = (0..3 * n).map(|_| rng.random_range(0.5..1.5)).collect();
    let served = client.evaluate_value(quad(), states.clone(), betas.clone(), pb::OutOfDomainPolicy::Unspecified).await;
    let served = served.unwrap();
    let (reference, manifest) = evaluator_for(&quad_dir);
    let f32s = |v: &[f64]| v.iter().map(|&x| x as f32).collect::<Vec<_>>();
    let local = reference.evaluate(&f32s(&states), &f32s(&betas)).unwrap();
    assert_eq!((served.values.len(), served.gradients.len(), served.controls.len()), (n, 10 * n, 3 * n));
    assert!(served.values.iter().zip(&local.value).all(|(a, b)| close(*a, *b)), "values differ");
    assert!(served.gradients.iter().zip(&local.grad).all(|(a, b)| close(*a, *b)), "gradients differ");
    assert!(served.controls.iter().zip(&local.control).all(|(a, b)| close(*a, *b)), "controls differ");
    for i in 0..n {
        // The thrust is an end of its box [0, 1.5 g] (the gradient is never exactly 0 here).
        let u_z = served.controls[3 * i + 2];
        assert!([0.0, quad10d::THRUST_MAX].iter().any(|e| (u_z - e).abs() < 1e-5), "u_z {u_z}");
        // in_teb is judged at the slowest axis' table row at or above the largest beta.
        let beta = betas[3 * i..3 * i + 3].iter().copied().fold(f64::NEG_INFINITY, f64::max);
        let row = manifest.teb_table.iter().find(|r| r.beta >= beta - 1e-12).unwrap();
        assert_eq!(served.in_teb[i], served.values[i] <= row.set_level(), "in_teb of item {i}");
    }
    // The parameters reach the graph: the same state at other per-axis bounds has another value.
    let one = &states[..10];
    let at = |b: [f64; 3]| {
        let client = client.clone();
        let one = one.to_vec();
        async move {
            client.evaluate_value(quad(), one, b.to_vec(), pb::OutOfDomainPolicy::Unspecified).await.unwrap().values[0]
        }
    };
    assert_ne!(at([0.5, 0.5, 0.5]).await, at([0.5, 0.5, 1.5]).await);
    let q = client.query_planner_control(quad(), Some(0.0)).await.unwrap();
    assert_eq!((q.beta_query, q.steb_exceeds_half_distance), (0.5, true));

    // A Track stream on the quad: 10-D tracker state, 3-D planner position.
    let mut stream = client.track(quad(), 0.0).await.unwrap();
    let tracker = vec![1.0, 0.5, 0.1, 0.2, -1.0, 0.0, 0.0, 0.0, 2.0, -0.5];
    let reply = stream
        .tick(pb::TrackTick {
            seq: 1,
            tracker_state: tracker,
            planner_state: vec![0.25, -1.5, 1.0],
            d_obs: Some(5.0),
            planner_clearance: None,
        })
        .await
        .unwrap();
    assert_eq!(reply.relative_state, vec![0.75, 0.5, 0.1, 0.2, 0.5, 0.0, 0.0, 0.0, 1.0, -0.5]);
    assert_eq!(reply.control.len(), 3);

    // Bad input of the quad's shape.
    let ok_state = vec![0.0; 10];
    let evaluate = |states: Vec<f64>, params: Vec<f64>| {
        let client = client.clone();
        async move { client.evaluate_value(quad(), states, params, pb::OutOfDomainPolicy::Unspecified).await }
    };
    expect_error(
        evaluate(vec![0.0; 13], vec![1.0; 3]).await,
        Code::InvalidArgument,
        &["states has 13 values", "n_state = 10"],
    );
    expect_error(
        evaluate(ok_state.clone(), vec![1.0, 1.0, 1.6]).await,
        Code::InvalidArgument,
        &["params[2]", "beta_3", "= 1.6", "[0.5, 1.5]"],
    );
    expect_error(
        evaluate(ok_state.clone(), vec![1.0, 1.0]).await,
        Code::InvalidArgument,
        &["params has 2 values", "1 x 3 = 3", "beta_1, beta_2, beta_3"],
    );
    let mut nan = ok_state.clone();
    nan[9] = f64::NAN;
    expect_error(evaluate(nan, vec![1.0; 3]).await, Code::InvalidArgument, &["states[9]", "v_z", "NaN"]);
    let mut high = ok_state.clone();
    high[8] = 3.0;
    expect_error(evaluate(high, vec![1.0; 3]).await, Code::OutOfRange, &["states[8]", "z_r", "[-1.5, 1.5]"]);
    // Its 3-D error set has a radius and an extent per axis but no boundary curve to draw.
    let teb = client.tracking_error_bound(quad(), 1.0, 0).await.unwrap();
    assert_eq!(teb.extent.len(), 3);
    expect_error(
        client.tracking_error_bound(quad(), 1.0, 8).await,
        Code::InvalidArgument,
        &["boundary points exist for 1-D and 2-D error spaces", "has 3 dimensions", "boundary_points = 0"],
    );
    expect_error(
        client.tracking_error_bound(quad(), 1.6, 0).await,
        Code::InvalidArgument,
        &["beta = 1.6", "[0.5, 1.5]"],
    );

    // The car is served beside it, unchanged.
    let car = client
        .evaluate_value(
            model_ref("car", 0),
            vec![0.1, 0.2, 0.3, 1.0],
            vec![1.0, 1.0],
            pb::OutOfDomainPolicy::Unspecified,
        )
        .await
        .unwrap();
    assert_eq!(car.values.len(), 1);
    drop(stream);
    assert!(server.terminate().success());
}
