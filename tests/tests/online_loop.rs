//! The online loop (Alg. 3) against the real server on the shipped `dubins4d` model: the planner advances at
//! per-axis speed at most `beta_query`; when `beta` drops next to an obstacle, adjustPlannerControl keeps `p*`
//! if the relative state is inside the smaller row's certified set, otherwise resets the planner to a free
//! point inside it and replans, and holds the planner under the old bound when no point is; bad tracker states and a server that
//! goes away are errors, never panics.

use fastrack_client::{model_ref, pb, FastrackClient};
use fastrack_e2e::TestServer;
use fastrack_online::core::CoreError;
use fastrack_online::geometry::{clearance, PlaneObstacle};
use fastrack_online::online_loop::{Branch, LoopError, LoopSettings, OnlineLoop};
use fastrack_online::raw_path::{GridAStar, PlanError, PlanRequest, RawPathPlanner};
use std::f64::consts::FRAC_PI_2;
use std::path::Path;

/// dubins4d heading along +x (`x' = v sin theta`).
const ALONG_X: f64 = FRAC_PI_2;

fn settings() -> LoopSettings<2> {
    let field = ([-2.0, -6.0], [12.0, 6.0]);
    LoopSettings { reset_candidates: 64, ..LoopSettings::new(model_ref("dubins4d", 0), 0.1, [10.0, 0.0], field) }
}

async fn shipped_server() -> (TestServer, FastrackClient) {
    TestServer::start_serving(&Path::new(env!("CARGO_MANIFEST_DIR")).join("../models")).await
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn the_planner_advances_at_most_beta_dt_per_axis() {
    let (_server, client) = shipped_server().await;
    let mut online = OnlineLoop::<PlaneObstacle, 2>::start(&client, settings(), [0.0, 0.0]).await.unwrap();
    let mut planner = GridAStar::default();
    let first = online.step(&[0.0, 0.0, ALONG_X, 1.0], &[], &mut planner).await.unwrap();
    assert_eq!((first.branch, first.replanned, first.round_trips), (Branch::Advance, true, 1));
    assert_eq!(first.beta_query, 1.25, "no obstacle: beta_u");
    assert!((first.planner[0] - 0.125).abs() < 1e-12 && first.planner[1] == 0.0, "{:?}", first.planner);
    // A goal off the axis: the straight path moves both axes, the larger one at exactly beta dt.
    let mut diagonal =
        OnlineLoop::<PlaneObstacle, 2>::start(&client, LoopSettings { goal: [6.0, 3.0], ..settings() }, [0.0, 0.0])
            .await
            .unwrap();
    let step = diagonal.step(&[0.0, 0.0, ALONG_X, 1.0], &[], &mut planner).await.unwrap();
    assert!((step.planner[0] - 0.125).abs() < 1e-12 && (step.planner[1] - 0.0625).abs() < 1e-12, "{:?}", step.planner);
    assert_eq!(step.control.len(), 2);
    // A planner 0.14 m ahead after one 0.1 s period leaves the tracker on the edge of the tight set at beta_u:
    // the reply says where it is, inside the trained domain.
    assert!(step.in_domain && step.value.is_finite(), "{step:?}");
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_drop_in_beta_keeps_p_star_when_the_tracker_is_inside_the_smaller_bound() {
    let (_server, client) = shipped_server().await;
    let mut online = OnlineLoop::<PlaneObstacle, 2>::start(&client, settings(), [0.0, 0.0]).await.unwrap();
    let mut planner = GridAStar::default();
    let tracker = [0.0, 0.0, ALONG_X, 1.0];
    online.step(&tracker, &[], &mut planner).await.unwrap();
    // An obstacle 2.6 m ahead: beta drops to the largest row whose bound fits 1.3 m.
    let obstacle = PlaneObstacle::Circle { center: [3.1, 0.0], radius: 0.5 };
    let step = online.step(&tracker, std::slice::from_ref(&obstacle), &mut planner).await.unwrap();
    assert_eq!(step.d_obs, Some(2.6));
    assert!(step.beta_query < step.beta_old && step.dteb_radius <= 1.3, "{step:?}");
    assert!(step.replanned, "a newly sensed obstacle is planned around");
    assert_eq!(step.branch, Branch::Keep, "{step:?}");
    assert!(step.in_teb && step.value <= step.dteb_radius, "{step:?}");
    // p* is the raw-path state closest to the tracker: the planner's own state, 0.125 m ahead.
    assert!((step.planner[0] - 0.125).abs() < 1e-12 && step.planner[1].abs() < 1e-12, "{:?}", step.planner);
    // The path now keeps the sTEB from the obstacle.
    for point in online.raw_path() {
        assert!(clearance(std::slice::from_ref(&obstacle), *point) > step.steb_radius, "{point:?}");
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_drop_in_beta_far_from_the_plan_resets_the_planner_inside_the_bound_and_replans() {
    let (_server, client) = shipped_server().await;
    let mut online = OnlineLoop::<PlaneObstacle, 2>::start(&client, settings(), [0.0, 0.0]).await.unwrap();
    let mut planner = GridAStar::default();
    online.step(&[0.0, 0.0, ALONG_X, 1.0], &[], &mut planner).await.unwrap();
    // The tracker 2.5 m off the plan, an obstacle 2.5 m beyond it: the smaller bound cannot hold p*.
    let tracker = [0.0, 2.5, ALONG_X, 1.0];
    let obstacle = PlaneObstacle::Circle { center: [0.0, 5.5], radius: 0.5 };
    let step = online.step(&tracker, std::slice::from_ref(&obstacle), &mut planner).await.unwrap();
    assert!(step.beta_query < step.beta_old, "{step:?}");
    assert_eq!(step.branch, Branch::Reset, "{step:?}");
    assert!(step.round_trips >= 2, "p* and at least one reset candidate were asked");
    assert!(step.in_teb && step.value <= step.dteb_radius, "the reset planner state is inside dTEBmax: {step:?}");
    let offset = (step.planner[0] - tracker[0]).hypot(step.planner[1] - tracker[1]);
    assert!(offset <= step.dteb_radius, "the reset point lies within dTEBmax of the tracker: {offset}");
    assert!(
        clearance(std::slice::from_ref(&obstacle), step.planner) > step.steb_radius,
        "and outside the inflated obstacle"
    );
    let next = online.step(&tracker, std::slice::from_ref(&obstacle), &mut planner).await.unwrap();
    assert!(next.replanned, "the reset flags a replan");
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_drop_in_beta_with_no_planner_state_inside_the_smaller_bound_holds_under_the_old_one() {
    let (_server, client) = shipped_server().await;
    let mut online = OnlineLoop::<PlaneObstacle, 2>::start(&client, settings(), [0.0, 0.0]).await.unwrap();
    let mut planner = GridAStar::default();
    // A tracker at 2.5 m/s, twice the planner's speed: no position within the smaller bound puts its relative
    // state inside that bound's set, so neither p* nor any reset candidate does.
    let fast = [0.0, 0.0, ALONG_X, 2.5];
    let first = online.step(&fast, &[], &mut planner).await.unwrap();
    let obstacle = PlaneObstacle::Circle { center: [3.6, 0.0], radius: 0.5 };
    let mut step = online.step(&fast, std::slice::from_ref(&obstacle), &mut planner).await.unwrap();
    // Held step after step, the bound in force stays the old row's: the loop owns `beta_old`.
    for held in 0..3 {
        assert_eq!(step.branch, Branch::Hold, "held step {held}: {step:?}");
        assert_eq!(
            (step.beta_old, step.beta_query, step.dteb_radius),
            (first.beta_query, first.beta_query, first.dteb_radius),
            "held step {held}"
        );
        if held < 2 {
            step = online.step(&fast, std::slice::from_ref(&obstacle), &mut planner).await.unwrap();
        }
    }
    assert!(step.dteb_radius > step.d_obs.unwrap() / 2.0, "the old bound stays in force: {step:?}");
    assert_eq!(step.planner, first.planner, "the planner waits where it is");
    assert_eq!(step.round_trips, 3, "p*, one batch of reset candidates, the held control");
    let expected: Vec<f64> = (0..4).map(|i| fast[i] - if i < 2 { step.planner[i] } else { 0.0 }).collect();
    assert_eq!(step.relative_state, expected);
    let info = client.get_model(model_ref("dubins4d", 0)).await.unwrap();
    let params = vec![step.beta_query; info.params.len()];
    let unary = client
        .tracking_control(model_ref("dubins4d", 0), step.relative_state.clone(), params, pb::OutOfDomainPolicy::Flag)
        .await
        .unwrap();
    assert_eq!(step.control, unary.controls, "u* under the held beta");
    // Slowed down onto the planner, the tracker is inside the smaller bound: the drop goes through.
    let slow = [step.planner[0], step.planner[1], ALONG_X, 1.0];
    let next = online.step(&slow, std::slice::from_ref(&obstacle), &mut planner).await.unwrap();
    assert!(next.beta_query < next.beta_old && next.branch == Branch::Keep, "{next:?}");
    assert_eq!(next.beta_old, first.beta_query, "the drop is taken from the held row");
    assert!(next.in_teb && next.dteb_radius <= next.d_obs.unwrap() / 2.0, "{next:?}");
    let after = online.step(&slow, std::slice::from_ref(&obstacle), &mut planner).await.unwrap();
    assert_eq!(after.beta_old, next.beta_query, "then the dropped row is in force");
}

/// Keep and reset take the planner only where the server's membership says the relative state is
/// certified: `V <= set level` of the new row, never the larger `V <= bound`. A drop to `beta_l` on the first
/// step with the tracker on the planner puts `p*` at zero position error; at headings and speeds where `V`
/// lies between the 0.5 row's set level (0.652) and its bound (0.769) a loop that took the bound's level set
/// for the certified one would keep there.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn the_loop_never_keeps_or_resets_outside_the_certified_set() {
    let (_server, client) = shipped_server().await;
    let info = client.get_model(model_ref("dubins4d", 0)).await.unwrap();
    let row_for = |beta: f64| info.teb_table.iter().find(|r| r.beta >= beta - 1e-12).unwrap();
    // 1.5 m from the tracker: only the slowest row's bound fits half of it.
    let obstacle = PlaneObstacle::Circle { center: [0.0, -2.0], radius: 0.5 };
    let trackers: Vec<[f64; 4]> = (0..16)
        .flat_map(|k| [0.5, 1.0, 1.5].map(|v| [0.0, 0.0, -3.0 + 0.4 * k as f64, v]))
        .chain([[0.0, 0.0, 0.074, 1.0]])
        .collect();
    let flat = trackers.iter().flatten().copied().collect();
    let slowest = &info.teb_table[0];
    let at_start = client
        .evaluate_value(model_ref("dubins4d", 0), flat, vec![slowest.beta; trackers.len()], pb::OutOfDomainPolicy::Flag)
        .await
        .unwrap();
    let mut planner = GridAStar::default();
    let (mut uncertified, mut branches) = (0, Vec::new());
    for (tracker, &value) in trackers.iter().zip(&at_start.values) {
        let mut online = OnlineLoop::<PlaneObstacle, 2>::start(&client, settings(), [0.0, 0.0]).await.unwrap();
        let step = online.step(tracker, std::slice::from_ref(&obstacle), &mut planner).await.unwrap();
        assert!(step.beta_query < step.beta_old || step.branch == Branch::Hold, "{step:?}");
        let uncertified_start = value > slowest.set_level && value <= slowest.bound;
        uncertified += usize::from(uncertified_start);
        match step.branch {
            Branch::Keep | Branch::Reset => {
                let row = row_for(step.beta_query);
                assert!(step.in_teb && step.value <= row.set_level, "{tracker:?}: {step:?} outside {}", row.set_level);
                if step.branch == Branch::Keep {
                    assert!(value <= slowest.set_level, "kept at zero error with V {value} > {}", slowest.set_level);
                }
            }
            Branch::Hold => assert_eq!(step.beta_query, step.beta_old),
            Branch::Advance | Branch::Steady => panic!("a drop in beta is never an advance: {step:?}"),
        }
        branches.push(step.branch);
    }
    let count = |b: Branch| branches.iter().filter(|&&x| x == b).count();
    eprintln!(
        "{} starts, {uncertified} between the set level and the bound: keep {}, reset {}, hold {}",
        trackers.len(),
        count(Branch::Keep),
        count(Branch::Reset),
        count(Branch::Hold)
    );
    assert!(uncertified > 0, "the starts include states only the bound's level set would cover");
    assert!(count(Branch::Keep) > 0 && count(Branch::Reset) + count(Branch::Hold) > 0, "{branches:?}");
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn bad_tracker_states_and_a_vanished_server_are_errors() {
    let (mut server, client) = shipped_server().await;
    let mut online = OnlineLoop::<PlaneObstacle, 2>::start(&client, settings(), [0.0, 0.0]).await.unwrap();
    let mut planner = GridAStar::default();
    let short = online.step(&[0.0, 0.0, 1.0], &[], &mut planner).await.unwrap_err();
    assert!(matches!(short, LoopError::Core(CoreError::Tracker(_))), "{short}");
    let nan = online.step(&[0.0, f64::NAN, 1.0, 1.0], &[], &mut planner).await.unwrap_err();
    assert!(nan.to_string().contains("tracker[1]"), "{nan}");
    let bad_period =
        OnlineLoop::<PlaneObstacle, 2>::start(&client, LoopSettings { control_period: 0.0, ..settings() }, [0.0, 0.0])
            .await;
    assert!(matches!(bad_period, Err(LoopError::Core(CoreError::Setup(_)))));
    server.terminate();
    let gone = online.step(&[0.0, 0.0, ALONG_X, 1.0], &[], &mut planner).await.unwrap_err();
    assert!(matches!(gone, LoopError::Client(_)), "{gone}");
}

/// A raw-path planner that fails its first `failures` requests, then plans with A*.
struct FailingFirst {
    failures: usize,
    requests: usize,
}

impl RawPathPlanner<PlaneObstacle, 2> for FailingFirst {
    fn plan(&mut self, request: &PlanRequest<'_, PlaneObstacle, 2>) -> Result<Vec<[f64; 2]>, PlanError> {
        self.requests += 1;
        if self.requests <= self.failures {
            return Err(PlanError::Settings("planner not ready".into()));
        }
        GridAStar::default().plan(request)
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_step_whose_plan_failed_plans_again_next_time() {
    let (_server, client) = shipped_server().await;
    let mut online = OnlineLoop::<PlaneObstacle, 2>::start(&client, settings(), [0.0, 0.0]).await.unwrap();
    let mut planner = FailingFirst { failures: 0, requests: 0 };
    let tracker = [0.0, 0.0, ALONG_X, 1.0];
    online.step(&tracker, &[], &mut planner).await.unwrap();
    // The obstacle is sensed while the planner fails: the step is an error ...
    let obstacle = PlaneObstacle::Circle { center: [5.0, 0.0], radius: 0.5 };
    planner.failures = planner.requests + 1;
    let failed = online.step(&tracker, std::slice::from_ref(&obstacle), &mut planner).await;
    assert!(matches!(failed, Err(LoopError::Core(CoreError::Plan(_)))), "{:?}", failed.map(|r| r.branch));
    // ... and the next step, the obstacle no longer new, plans around it rather than follow the old path.
    let step = online.step(&tracker, std::slice::from_ref(&obstacle), &mut planner).await.unwrap();
    assert!(step.replanned, "{step:?}");
    for point in online.raw_path() {
        assert!(clearance(std::slice::from_ref(&obstacle), *point) > step.steb_radius, "{point:?}");
    }
}
