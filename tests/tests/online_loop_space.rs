//! The online loop in space over a real server: a loop of three axes steps on a quad10d bundle (a 10-D
//! tracker, a 3-D planner) among a pillar and the floor, its raw path keeping the sTEB from both and its
//! planner moving at most `beta dt` per axis; a loop whose dimension is not the model's planner's is refused.

use fastrack_client::model_ref;
use fastrack_e2e::{write_test_bundle, TestServer};
use fastrack_online::core::CoreError;
use fastrack_online::geometry::{segment_is_free, PlaneObstacle, SpaceObstacle};
use fastrack_online::online_loop::{Branch, LoopError, LoopSettings, OnlineLoop};
use fastrack_online::raw_path::GridAStar;
use fastrack_valuefn::system::{dubins4d, quad10d};

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_loop_in_space_steps_around_a_pillar_on_a_quad_and_refuses_a_planar_model() {
    let repo = tempfile::tempdir().unwrap();
    write_test_bundle(repo.path(), &quad10d::system(), "quad", 1, 2);
    write_test_bundle(repo.path(), &dubins4d::system(), "car", 1, 1);
    let (_server, client) = TestServer::start_serving(repo.path()).await;
    let field = ([-2.0, -3.0, 0.0], [12.0, 3.0, 4.0]);
    let settings =
        LoopSettings { reset_candidates: 32, ..LoopSettings::new(model_ref("quad", 0), 0.1, [10.0, 0.0, 1.0], field) };

    let mut online = OnlineLoop::start(&client, settings.clone(), [0.0, 0.0, 1.0]).await.unwrap();
    // A pillar across the straight line to the goal, the floor 1 m below the hovering tracker.
    let sensed = [
        SpaceObstacle::Pillar { center: [5.0, 0.0], radius: 0.5, bottom: 0.0, top: 4.0 },
        SpaceObstacle::Floor { height: 0.0 },
    ];
    let hover = [0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0];
    let mut planner = GridAStar { cell: 0.25 };
    let first = online.step(&hover, &sensed, &mut planner).await.unwrap();
    assert!(first.replanned && first.control.len() == 3, "{first:?}");
    assert_eq!(first.d_obs, Some(1.0), "the floor is the nearest obstacle");
    // The table's rows have bounds 0.2, 0.3, ...: half of d_obs fits the row of bound 0.5, beta 0.7, a drop
    // from beta_u; the planner's own state is the closest to the tracker.
    assert!((first.beta_query - 0.7).abs() < 1e-12 && (first.dteb_radius - 0.5).abs() < 1e-12, "{first:?}");
    assert_eq!((first.branch, first.planner), (Branch::Keep, [0.0, 0.0, 1.0]), "{first:?}");
    // At the same beta the planner advances along the plan, at most beta dt per axis.
    let step = online.step(&hover, &sensed, &mut planner).await.unwrap();
    assert_eq!((step.branch, step.beta_query), (Branch::Advance, 0.7), "{step:?}");
    let moved: Vec<f64> = (0..3).map(|axis| (step.planner[axis] - first.planner[axis]).abs()).collect();
    assert!(moved.iter().all(|&m| m <= step.beta_query * 0.1 + 1e-12), "moved {moved:?} in one period");
    assert!(step.planner[0] > first.planner[0], "the planner did not move toward the goal: {step:?}");
    // r = s - Q p on the quad's position coordinates (x, y, z at 0, 4, 8).
    let r = &step.relative_state;
    assert!((r[0] + step.planner[0]).abs() < 1e-9 && (r[4] + step.planner[1]).abs() < 1e-9, "{r:?}");
    assert!((r[8] - (1.0 - step.planner[2])).abs() < 1e-9, "{r:?}");
    // The plan bends around the pillar and keeps the sTEB from it and the floor.
    let plan: Vec<[f64; 3]> = std::iter::once(online.planner()).chain(online.raw_path().copied()).collect();
    assert!(plan.len() > 2, "a straight plan through the pillar: {plan:?}");
    for segment in plan.windows(2) {
        assert!(segment_is_free(&sensed, segment[0], segment[1], step.steb_radius), "{segment:?} cuts the sTEB");
    }

    // A loop of the other dimension is refused at its start, naming the model's planner axes and its own.
    let planar = LoopSettings::new(model_ref("quad", 0), 0.1, [10.0, 0.0], ([-2.0, -3.0], [12.0, 3.0]));
    let refused = OnlineLoop::<PlaneObstacle, 2>::start(&client, planar, [0.0, 0.0]).await.err();
    assert!(
        matches!(&refused, Some(LoopError::Core(CoreError::Setup(why))) if why.contains("moves 3 axes of its 10-D state") && why.ends_with("moves 2")),
        "{refused:?}"
    );
    let spatial = LoopSettings { model: model_ref("car", 0), ..settings };
    let refused = OnlineLoop::<SpaceObstacle, 3>::start(&client, spatial, [0.0, 0.0, 1.0]).await.err();
    assert!(
        matches!(&refused, Some(LoopError::Core(CoreError::Setup(why))) if why.contains("moves 2 axes of its 4-D state") && why.ends_with("moves 3")),
        "{refused:?}"
    );
}
