//! Requests nobody listed, against the real server: every RPC's messages drawn at random (lengths from empty
//! to past the model's, NaN, infinities, subnormals, huge and negative numbers, unknown models and versions,
//! enum values outside the contract) and `Track` ticks alike. Each answer is either a well-formed reply or
//! one of the statuses bad input gets, with a message; the server never panics and keeps serving.
//! `FASTRACK_FUZZ_CASES` sets the cases per RPC (default 500; a long run is a matter of raising it).

use fastrack_client::{model_ref, pb};
use fastrack_e2e::fuzz::{cases, Tally};
use fastrack_e2e::{write_test_bundle, TestServer};
use fastrack_valuefn::system::dubins4d;
use pb::safety_service_client::SafetyServiceClient;
use proptest::prelude::*;
use proptest::test_runner::{Config, TestCaseError, TestRunner};
use std::cell::{Cell, RefCell};
use tonic::transport::Channel;
use tonic::Code;

/// Statuses a request's content may earn; anything else (INTERNAL, UNKNOWN, UNAVAILABLE) is a failure.
const INPUT_CODES: [Code; 3] = [Code::InvalidArgument, Code::OutOfRange, Code::NotFound];

/// Numbers a client might send: ordinary ones inside and outside the domain, and every kind of edge.
fn number() -> impl Strategy<Value = f64> {
    prop_oneof![
        4 => -4.0..4.0f64,
        1 => prop_oneof![
            Just(f64::NAN),
            Just(f64::INFINITY),
            Just(f64::NEG_INFINITY),
            Just(-0.0),
            Just(f64::MIN_POSITIVE / 4.0),
            Just(f64::MAX),
            Just(-f64::MAX),
            -1e12..1e12f64,
        ],
    ]
}

fn numbers(max_len: usize) -> impl Strategy<Value = Vec<f64>> {
    prop::collection::vec(number(), 0..=max_len)
}

/// An optional distance: mostly a plausible one, sometimes any number.
fn distance() -> impl Strategy<Value = Option<f64>> {
    prop::option::of(prop_oneof![0.0..8.0f64, number()])
}

/// The served model most of the time, otherwise names and versions that are not served.
fn model() -> impl Strategy<Value = Option<pb::ModelRef>> {
    prop_oneof![
        6 => (0u32..=1).prop_map(|version| Some(model_ref("good", version))),
        1 => Just(None),
        1 => ("[a-z\\-]{0,12}", 0u32..=3).prop_map(|(name, version)| Some(model_ref(&name, version))),
        1 => (2u32..=u32::MAX).prop_map(|version| Some(model_ref("good", version))),
    ]
}

/// A dubins4d relative state inside (mostly) the trained domain.
fn state() -> impl Strategy<Value = Vec<f64>> {
    (-3.5..3.5f64, -3.5..3.5f64, -4.0..4.0f64, -0.5..3.5f64).prop_map(|(x, y, theta, v)| vec![x, y, theta, v])
}

/// `values` with, maybe, one entry replaced by an edge number.
fn maybe_broken(values: Vec<f64>) -> impl Strategy<Value = Vec<f64>> {
    let n = values.len();
    prop_oneof![
        2 => Just(values.clone()),
        1 => (0..n.max(1), number()).prop_map(move |(i, bad)| {
            let mut broken = values.clone();
            if let Some(v) = broken.get_mut(i) {
                *v = bad;
            }
            broken
        }),
    ]
}

/// A batch request's fields: model, states, params, out-of-domain policy. Half are shaped as the contract
/// asks (1-3 items, two betas each) with at most one bad number; the rest are anything.
fn batch() -> impl Strategy<Value = (Option<pb::ModelRef>, Vec<f64>, Vec<f64>, i32)> {
    let shaped = (1usize..=3)
        .prop_flat_map(|n| (prop::collection::vec(state(), n), prop::collection::vec(0.4..1.35f64, 2 * n)))
        .prop_flat_map(|(states, params)| (maybe_broken(states.concat()), Just(params)))
        .prop_map(|(states, params)| (Some(model_ref("good", 0)), states, params));
    prop_oneof![
        1 => (shaped, -1i32..=3).prop_map(|((model, states, params), policy)| (model, states, params, policy)),
        1 => (model(), numbers(13), numbers(7), -2i32..=4),
    ]
}

/// A `Track` tick's fields: shaped as the contract asks with at most one bad number, or anything.
fn tick() -> impl Strategy<Value = (Vec<f64>, Vec<f64>, Option<f64>)> {
    let shaped = (state(), (-2.0..2.0f64, -2.0..2.0f64), prop::option::of(0.0..6.0f64))
        .prop_flat_map(|(s, (px, py), d_obs)| (maybe_broken(s), Just(vec![px, py]), Just(d_obs)));
    prop_oneof![2 => shaped, 1 => (numbers(6), numbers(3), prop::option::of(number()))]
}

/// An error status from a request's content: one of [`INPUT_CODES`], with a message.
fn input_error(status: &tonic::Status) -> Result<(), TestCaseError> {
    prop_assert!(INPUT_CODES.contains(&status.code()), "status {:?}: {}", status.code(), status.message());
    prop_assert!(!status.message().is_empty(), "status {:?} without a message", status.code());
    Ok(())
}

/// A well-formed batch answer: one value, in-TEB and in-domain flag per item, finite values.
fn batch_answer(n_items: usize, values: &[f64], in_teb: &[bool], in_domain: &[bool]) -> Result<(), TestCaseError> {
    prop_assert_eq!((values.len(), in_teb.len(), in_domain.len()), (n_items, n_items, n_items));
    prop_assert!(values.iter().all(|v| v.is_finite()), "values {values:?}");
    Ok(())
}

#[test]
fn every_rpc_answers_random_requests_with_a_reply_or_a_precise_status() {
    let runtime = tokio::runtime::Builder::new_multi_thread().worker_threads(2).enable_all().build().unwrap();
    let repo = tempfile::tempdir().unwrap();
    write_test_bundle(repo.path(), &dubins4d::system(), "good", 1, 1);
    let (mut server, client) = runtime.block_on(TestServer::start_serving(repo.path()));
    let channel: Channel = runtime.block_on(Channel::from_shared(server.endpoint.clone()).unwrap().connect()).unwrap();
    let service = SafetyServiceClient::new(channel);
    // A runner per RPC: one runner counts its cases across runs.
    let config = Config { cases: cases(500), failure_persistence: None, ..Config::default() };
    let runner = || TestRunner::new(config.clone());
    // Answers and refusals per RPC: the draws must reach both, or the properties check little.
    let tally = RefCell::new(Tally::new("requests", config.cases));
    let count = |rpc: &'static str, answered: bool| tally.borrow_mut().count(rpc, answered);

    runner()
        .run(&batch(), |(model, states, params, out_of_domain)| {
            let request = pb::EvaluateValueRequest { model, states: states.clone(), params, out_of_domain };
            let answer = runtime.block_on(service.clone().evaluate_value(request));
            count("EvaluateValue", answer.is_ok());
            match answer {
                Ok(reply) => {
                    let r = reply.into_inner();
                    batch_answer(states.len() / 4, &r.values, &r.in_teb, &r.in_domain)?;
                    prop_assert_eq!(r.gradients.len(), states.len());
                }
                Err(status) => input_error(&status)?,
            }
            Ok(())
        })
        .unwrap();

    runner()
        .run(&batch(), |(model, states, params, out_of_domain)| {
            let request = pb::TrackingControlRequest { model, states: states.clone(), params, out_of_domain };
            let answer = runtime.block_on(service.clone().tracking_control(request));
            count("TrackingControl", answer.is_ok());
            match answer {
                Ok(reply) => {
                    let r = reply.into_inner();
                    batch_answer(states.len() / 4, &r.values, &r.in_teb, &r.in_domain)?;
                    prop_assert_eq!(r.controls.len(), 2 * (states.len() / 4));
                    prop_assert!(r.controls.iter().all(|u| u.is_finite()), "controls {:?}", r.controls);
                }
                Err(status) => input_error(&status)?,
            }
            Ok(())
        })
        .unwrap();

    runner()
        .run(&(model(), distance(), distance()), |(model, d_obs, planner_clearance)| {
            let request = pb::QueryPlannerControlRequest { model, d_obs, planner_clearance };
            let answer = runtime.block_on(service.clone().query_planner_control(request));
            count("QueryPlannerControl", answer.is_ok());
            match answer {
                Ok(reply) => {
                    let r = reply.into_inner();
                    let valid = |x: Option<f64>| x.is_none_or(|d| d.is_finite() && d >= 0.0);
                    prop_assert!(valid(d_obs), "answered d_obs {d_obs:?}");
                    prop_assert!(valid(planner_clearance), "answered planner_clearance {planner_clearance:?}");
                    prop_assert!((0.5..=1.25).contains(&r.beta_query), "beta_query {}", r.beta_query);
                    prop_assert!(r.dteb_radius > 0.0 && r.steb_radius > 0.0);
                }
                Err(status) => input_error(&status)?,
            }
            Ok(())
        })
        .unwrap();

    runner()
        .run(
            &(model(), prop_oneof![0.4..1.35f64, number()], prop_oneof![0u32..=256, any::<u32>()]),
            |(model, beta, boundary_points)| {
                let request = pb::GetTrackingErrorBoundRequest { model, beta, boundary_points };
                let answer = runtime.block_on(service.clone().get_tracking_error_bound(request));
                count("GetTrackingErrorBound", answer.is_ok());
                match answer {
                    Ok(reply) => {
                        let r = reply.into_inner();
                        prop_assert!((0.5..=1.25).contains(&beta), "answered beta {beta}");
                        prop_assert!(r.radius > 0.0 && r.table_beta >= beta, "radius {} at {}", r.radius, r.table_beta);
                    }
                    Err(status) => input_error(&status)?,
                }
                Ok(())
            },
        )
        .unwrap();

    // One stream takes every tick: a bad one is answered with its error and the stream goes on.
    let stream = RefCell::new(runtime.block_on(client.track(model_ref("good", 0), 30.0)).unwrap());
    let last_seq = Cell::new(0u64);
    runner()
        .run(&tick(), |(tracker_state, planner_state, d_obs)| {
            let seq = last_seq.get() + 1;
            last_seq.set(seq);
            let tick = pb::TrackTick { seq, tracker_state, planner_state, d_obs, planner_clearance: None };
            let reply = runtime
                .block_on(stream.borrow_mut().tick(tick))
                .map_err(|e| TestCaseError::fail(format!("the stream failed: {e}")))?;
            prop_assert_eq!(reply.seq, seq);
            count("Track", reply.error.is_none());
            match reply.error {
                Some(error) => {
                    let code = Code::from_i32(error.code);
                    prop_assert!(INPUT_CODES.contains(&code), "tick error {code:?}: {}", error.message);
                    prop_assert!(!error.message.is_empty());
                }
                None => {
                    prop_assert_eq!(reply.relative_state.len(), 4);
                    prop_assert_eq!(reply.control.len(), 2);
                    prop_assert!(reply.value.is_finite() && reply.control.iter().all(|u| u.is_finite()));
                }
            }
            Ok(())
        })
        .unwrap();

    let tally = tally.into_inner();
    for rpc in ["EvaluateValue", "TrackingControl", "QueryPlannerControl", "GetTrackingErrorBound", "Track"] {
        tally.assert_both(rpc);
    }
    assert!(server.is_running(), "the server exited:\n{}", server.log_text());
    runtime.block_on(client.wait_until_serving(std::time::Duration::from_secs(5))).unwrap();
    assert!(!server.log_text().contains("panicked"), "a panic in the log:\n{}", server.log_text());
    tally.report();
}
