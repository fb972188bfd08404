//! The real server binary over loopback: every implemented RPC, checked against the same bundle evaluated
//! in-process through ONNX Runtime, and against the paper's queryPlannerControl rule on a hand-made table.

use fastrack_client::{model_ref, pb};
use fastrack_e2e::{evaluator_for, write_test_bundle, TestServer};
use fastrack_valuefn::system::{double_integrator, dubins4d};
use rand::{Rng, SeedableRng};

fn random_batch(n: usize, seed: u64) -> (Vec<f64>, Vec<f64>) {
    let system = dubins4d::system();
    let mut rng = rand::rngs::StdRng::seed_from_u64(seed);
    let mut states = Vec::new();
    let mut params = Vec::new();
    for _ in 0..n {
        states.extend(system.state.iter().map(|d| rng.random_range(d.min..d.max)));
        params.extend(system.params.iter().map(|p| rng.random_range(p.min..p.max)));
    }
    (states, params)
}

fn f32s(v: &[f64]) -> Vec<f32> {
    v.iter().map(|&x| x as f32).collect()
}

fn close(a: f64, b: f32) -> bool {
    (a - f64::from(b)).abs() <= 1e-6 * (1.0 + a.abs())
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn every_rpc_answers_like_the_in_process_evaluator() {
    let repo = tempfile::tempdir().unwrap();
    let v1 = write_test_bundle(repo.path(), &dubins4d::system(), "dubins-test", 1, 1);
    let v2 = write_test_bundle(repo.path(), &dubins4d::system(), "dubins-test", 2, 2);
    write_test_bundle(repo.path(), &double_integrator::system(), "di-test", 1, 3);
    let (mut server, client) = TestServer::start_serving(repo.path()).await;

    // ListModels / GetModel.
    let models = client.list_models().await.unwrap();
    let labels: Vec<(String, u32, bool)> =
        models.iter().map(|m| (m.name.clone(), m.version, m.is_default_version)).collect();
    assert_eq!(
        labels,
        vec![("di-test".into(), 1, true), ("dubins-test".into(), 1, false), ("dubins-test".into(), 2, true)]
    );
    let latest = client.get_model(model_ref("dubins-test", 0)).await.unwrap();
    assert_eq!((latest.version, latest.system.as_str(), latest.untrained), (2, "dubins4d", true));
    let (reference, manifest) = evaluator_for(&v2);
    assert_eq!(latest.onnx_sha256, manifest.onnx_sha256);
    assert_eq!(latest.state.iter().map(|d| d.name.as_str()).collect::<Vec<_>>(), ["x_r", "y_r", "theta", "v"]);
    assert_eq!(latest.teb_table.len(), 16);
    for (row, expected) in latest.teb_table.iter().zip(&manifest.teb_table) {
        assert_eq!((row.beta, row.bound, row.set_level), (expected.beta, expected.bound(), expected.set_level()));
    }
    assert_eq!(client.get_model(model_ref("dubins-test", 1)).await.unwrap().version, 1);

    // EvaluateValue and TrackingControl against the in-process evaluator.
    let (states, params) = random_batch(64, 5);
    let served = client
        .evaluate_value(model_ref("dubins-test", 0), states.clone(), params.clone(), pb::OutOfDomainPolicy::Unspecified)
        .await
        .unwrap();
    let local = reference.evaluate(&f32s(&states), &f32s(&params)).unwrap();
    assert_eq!(served.model_version, 2);
    assert_eq!((served.values.len(), served.gradients.len(), served.controls.len()), (64, 256, 128));
    assert!(served.values.iter().zip(&local.value).all(|(a, b)| close(*a, *b)), "values differ");
    assert!(served.gradients.iter().zip(&local.grad).all(|(a, b)| close(*a, *b)), "gradients differ");
    assert!(served.controls.iter().zip(&local.control).all(|(a, b)| close(*a, *b)), "controls differ");
    assert!(served.in_domain.iter().all(|&x| x));
    for i in 0..64 {
        let beta = params[2 * i].max(params[2 * i + 1]);
        let row = manifest.teb_table.iter().find(|r| r.beta >= beta - 1e-12).unwrap();
        assert_eq!(served.in_teb[i], served.values[i] <= row.set_level(), "in_teb of item {i}");
    }
    let control = client
        .tracking_control(
            model_ref("dubins-test", 0),
            states.clone(),
            params.clone(),
            pb::OutOfDomainPolicy::Unspecified,
        )
        .await
        .unwrap();
    assert_eq!(control.controls, served.controls);
    assert_eq!(control.values, served.values);
    assert_eq!(control.in_teb, served.in_teb);

    // A pinned version answers with its own network.
    let (reference_v1, _) = evaluator_for(&v1);
    let pinned = client
        .evaluate_value(
            model_ref("dubins-test", 1),
            states[..4].to_vec(),
            params[..2].to_vec(),
            pb::OutOfDomainPolicy::Unspecified,
        )
        .await
        .unwrap();
    let local_v1 = reference_v1.evaluate(&f32s(&states[..4]), &f32s(&params[..2])).unwrap();
    assert_eq!(pinned.model_version, 1);
    assert!(close(pinned.values[0], local_v1.value[0]));

    // GetTrackingErrorBound: the next table row at or above beta, never interpolated.
    let teb = client.tracking_error_bound(model_ref("dubins-test", 0), 0.81, 8).await.unwrap();
    let row = manifest.teb_table.iter().find(|r| r.beta >= 0.81).unwrap();
    assert_eq!((teb.table_beta, teb.level, teb.radius), (row.beta, row.set_level(), row.bound()));
    assert_eq!(teb.extent, row.extent);
    assert_eq!(teb.boundary.len(), 16);
    for p in teb.boundary.chunks(2) {
        assert!((p[0].hypot(p[1]) - row.boundary_radii[0]).abs() < 1e-9);
    }

    // QueryPlannerControl: levels are 0.2 + 0.1 k at beta = 0.5 + 0.05 k.
    let q = |d: Option<f64>| {
        let client = client.clone();
        async move { client.query_planner_control(model_ref("dubins-test", 0), d).await.unwrap() }
    };
    let none = q(None).await;
    assert_eq!((none.beta_query, none.steb_exceeds_half_distance), (1.25, false));
    assert!((none.dteb_radius - 1.7).abs() < 1e-9 && (none.steb_radius - 0.2).abs() < 1e-9);
    let zero = q(Some(0.0)).await;
    assert_eq!((zero.beta_query, zero.steb_exceeds_half_distance), (0.5, true));
    let below_steb = q(Some(0.3)).await;
    assert_eq!(
        (below_steb.beta_query, below_steb.dteb_radius, below_steb.steb_exceeds_half_distance),
        (0.5, 0.2, true)
    );
    let mid = q(Some(1.0)).await;
    assert!((mid.beta_query - 0.65).abs() < 1e-9 && (mid.dteb_radius - 0.5).abs() < 1e-9, "{mid:?}");

    // Admin: unload the latest version, the previous one becomes the default; load it back.
    assert_eq!(client.unload_model("dubins-test", 2).await.unwrap(), vec![2]);
    assert_eq!(client.get_model(model_ref("dubins-test", 0)).await.unwrap().version, 1);
    assert_eq!(client.load_model("dubins-test", 2).await.unwrap(), vec![1, 2]);
    let outcomes = client.reload_model("").await.unwrap();
    assert_eq!(outcomes.len(), 3);
    assert!(outcomes.iter().all(|o| o.loaded && o.error.is_empty()));
    // With every version unloaded health turns NOT_SERVING; loading one back makes it SERVING again.
    assert_eq!(client.unload_model("dubins-test", 0).await.unwrap(), vec![1, 2]);
    assert_eq!(client.unload_model("di-test", 0).await.unwrap(), vec![1]);
    assert_eq!(client.health().await.unwrap(), fastrack_client::HealthStatus::NotServing);
    assert_eq!(client.load_model("di-test", 0).await.unwrap(), vec![1]);
    assert_eq!(client.health().await.unwrap(), fastrack_client::HealthStatus::Serving);

    let status = server.terminate();
    assert!(status.success(), "graceful shutdown exits 0, got {status:?}");
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn track_stream_answers_every_tick_in_order_from_the_tick_alone() {
    let repo = tempfile::tempdir().unwrap();
    let dir = write_test_bundle(repo.path(), &dubins4d::system(), "dubins-test", 1, 4);
    let (reference, manifest) = evaluator_for(&dir);
    let (_server, client) = TestServer::start_serving(repo.path()).await;
    let mut stream = client.track(model_ref("dubins-test", 0), 5.0).await.unwrap();

    let ticks = [(None, 1.25), (Some(1.0), 0.65), (Some(0.0), 0.5), (Some(10.0), 1.25)];
    let mut replies = Vec::new();
    for (seq, (d_obs, expected_beta)) in ticks.iter().enumerate() {
        let tracker = vec![0.3 + 0.1 * seq as f64, -0.2, 7.0, 1.1];
        let planner = vec![0.1, 0.4];
        let reply = stream
            .tick(pb::TrackTick {
                seq: seq as u64,
                tracker_state: tracker.clone(),
                planner_state: planner.clone(),
                d_obs: *d_obs,
                planner_clearance: None,
            })
            .await
            .unwrap();
        assert!(reply.error.is_none(), "{:?}", reply.error);
        assert_eq!(reply.seq, seq as u64);
        assert!((reply.beta_query - expected_beta).abs() < 1e-9, "tick {seq}: {reply:?}");
        // r = s - Q p with theta wrapped into [-pi, pi).
        let r = [tracker[0] - 0.1, -0.6, 7.0 - 2.0 * std::f64::consts::PI, 1.1];
        for (a, b) in reply.relative_state.iter().zip(r) {
            assert!((a - b).abs() < 1e-12, "relative state {:?} vs {r:?}", reply.relative_state);
        }
        let local = reference.evaluate(&f32s(&r), &[reply.beta_query as f32; 2]).unwrap();
        assert!(close(reply.value, local.value[0]));
        assert_eq!(reply.control, local.control.iter().map(|&x| f64::from(x)).collect::<Vec<_>>());
        let row = manifest.teb_table.iter().find(|row| row.beta >= reply.beta_query - 1e-12).unwrap();
        assert_eq!(reply.in_teb, reply.value <= row.set_level());
        assert!(reply.in_domain);
        replies.push(reply);
    }
    // The stream keeps no state: the ticks sent again, in another order, get the same answers.
    for (seq, (d_obs, _)) in ticks.iter().enumerate().rev() {
        let tick = pb::TrackTick {
            seq: 10 + seq as u64,
            tracker_state: vec![0.3 + 0.1 * seq as f64, -0.2, 7.0, 1.1],
            planner_state: vec![0.1, 0.4],
            d_obs: *d_obs,
            planner_clearance: None,
        };
        let again = stream.tick(tick).await.unwrap();
        assert_eq!(pb::TrackReply { seq: seq as u64, ..again }, replies[seq], "tick {seq} answered again");
    }

    // A bad tick gets an error reply and the stream stays open.
    let bad = stream
        .tick(pb::TrackTick {
            seq: 99,
            tracker_state: vec![0.0; 3],
            planner_state: vec![0.0; 2],
            d_obs: None,
            planner_clearance: None,
        })
        .await
        .unwrap();
    let error = bad.error.expect("error reply");
    assert_eq!(error.code, tonic::Code::InvalidArgument as i32);
    assert!(error.message.contains("tracker_state has 3 values"), "{}", error.message);
    let nan = stream
        .tick(pb::TrackTick {
            seq: 100,
            tracker_state: vec![0.0, f64::NAN, 0.0, 1.0],
            planner_state: vec![0.0; 2],
            d_obs: None,
            planner_clearance: None,
        })
        .await
        .unwrap();
    assert!(nan.error.unwrap().message.contains("tracker_state[1] is NaN"));
    let good = stream
        .tick(pb::TrackTick {
            seq: 101,
            tracker_state: vec![0.0, 0.0, 0.0, 1.0],
            planner_state: vec![0.0; 2],
            d_obs: Some(-1.0),
            planner_clearance: None,
        })
        .await
        .unwrap();
    assert!(good.error.unwrap().message.contains("d_obs = -1"));
    let good = stream
        .tick(pb::TrackTick {
            seq: 102,
            tracker_state: vec![0.0, 0.0, 0.0, 1.0],
            planner_state: vec![0.0; 2],
            d_obs: None,
            planner_clearance: None,
        })
        .await
        .unwrap();
    assert_eq!((good.seq, good.beta_query, good.error), (102, 1.25, None));

    // Many ticks pipelined: every one answered, in order.
    for seq in 0..200u64 {
        stream
            .send(pb::TrackTick {
                seq,
                tracker_state: vec![0.0, 0.0, 0.0, 1.0],
                planner_state: vec![0.0; 2],
                d_obs: Some(1.0 + seq as f64 * 0.01),
                planner_clearance: None,
            })
            .await
            .unwrap();
    }
    for seq in 0..200u64 {
        assert_eq!(stream.recv().await.unwrap().unwrap().seq, seq);
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn reflection_lists_and_describes_every_service() {
    use tonic_reflection::pb::v1::server_reflection_client::ServerReflectionClient;
    use tonic_reflection::pb::v1::server_reflection_request::MessageRequest;
    use tonic_reflection::pb::v1::server_reflection_response::MessageResponse;
    use tonic_reflection::pb::v1::ServerReflectionRequest;

    let repo = tempfile::tempdir().unwrap();
    write_test_bundle(repo.path(), &dubins4d::system(), "dubins-test", 1, 1);
    let (server, _client) = TestServer::start_serving(repo.path()).await;
    let channel = tonic::transport::Endpoint::from_shared(server.endpoint.clone()).unwrap().connect().await.unwrap();
    let mut reflection = ServerReflectionClient::new(channel);
    let ask = |request: MessageRequest| {
        tokio_stream::iter([ServerReflectionRequest { host: String::new(), message_request: Some(request) }])
    };

    // `grpcurl list`
    let mut replies =
        reflection.server_reflection_info(ask(MessageRequest::ListServices(String::new()))).await.unwrap().into_inner();
    let Some(MessageResponse::ListServicesResponse(list)) = replies.message().await.unwrap().unwrap().message_response
    else {
        panic!("expected a service list");
    };
    let mut names: Vec<String> = list.service.into_iter().map(|s| s.name).collect();
    names.sort();
    for expected in [
        "fastrack.v1.ModelAdminService",
        "fastrack.v1.ModelService",
        "fastrack.v1.SafetyService",
        "grpc.health.v1.Health",
    ] {
        assert!(names.iter().any(|n| n == expected), "{expected} missing from {names:?}");
    }

    // `grpcurl describe fastrack.v1.SafetyService`: the file defining it, with its RPCs.
    let request = MessageRequest::FileContainingSymbol("fastrack.v1.SafetyService".into());
    let mut replies = reflection.server_reflection_info(ask(request)).await.unwrap().into_inner();
    let Some(MessageResponse::FileDescriptorResponse(files)) =
        replies.message().await.unwrap().unwrap().message_response
    else {
        panic!("expected file descriptors");
    };
    let bytes: Vec<u8> = files.file_descriptor_proto.concat();
    let text = String::from_utf8_lossy(&bytes);
    for rpc in ["QueryPlannerControl", "GetTrackingErrorBound", "EvaluateValue", "TrackingControl", "Track"] {
        assert!(text.contains(rpc), "descriptor lacks {rpc}");
    }
}
