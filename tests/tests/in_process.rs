//! The simulator's in-process backend answers as the server does: the same worlds run over the real server
//! (gRPC, the `Track` stream) and over the shipped bundle loaded in this process give the same runs, decision
//! for decision, for Parametric FaSTrack and the level-based baselines; bad bundles are refused with the
//! folder named; a run's golden trace of the online loop records every period and reads back.

use fastrack_e2e::TestServer;
use fastrack_online::geometry::PlaneObstacle;
use fastrack_sim::backend::Backend;
use fastrack_sim::episode::{Outcome, PlaneRun, RunSettings, Simulator};
use fastrack_sim::in_process::LocalModel;
use fastrack_sim::methods::Method;
use fastrack_sim::trace::{LoopTrace, FORMAT};
use fastrack_sim::world::{PlaneWorld, WorldSpec};
use std::path::{Path, PathBuf};

fn models() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../models")
}

/// The version the server serves by default: the highest in the model's folder.
fn shipped_bundle() -> PathBuf {
    let folder = models().join("dubins4d");
    let version = std::fs::read_dir(&folder)
        .unwrap()
        .filter_map(|e| e.ok()?.file_name().to_str()?.parse::<u32>().ok())
        .max()
        .expect("a dubins4d version");
    folder.join(version.to_string())
}

fn assert_same(service: &PlaneRun, local: &PlaneRun, what: &str) {
    assert_eq!(service.outcome, local.outcome, "{what}: outcome");
    assert_eq!(service.samples.len(), local.samples.len(), "{what}: control periods");
    for (k, (a, b)) in service.samples.iter().zip(&local.samples).enumerate() {
        assert_eq!(a, b, "{what}: first difference at period {k}");
    }
    assert_eq!(
        (service.replans, service.resets, service.held_steps, service.round_trips),
        (local.replans, local.resets, local.held_steps, local.round_trips),
        "{what}: replans, resets, held steps, calls"
    );
    assert_eq!(service.visits, local.visits, "{what}: the loop's branches and relative states");
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn runs_answered_in_process_equal_runs_over_the_server() {
    let (_server, client) = TestServer::start_serving(&models()).await;
    let service = Simulator::connect(&client, RunSettings::default()).await.unwrap();
    let local = LocalModel::load(&shipped_bundle(), None, 1).unwrap();
    let in_process = Simulator::new(Backend::InProcess(local), RunSettings::default()).await.unwrap();
    assert_eq!(service.speeds(), in_process.speeds(), "the same table");
    let mut reached = 0;
    for seed in 1..=3u64 {
        let world: PlaneWorld =
            WorldSpec { seed, inflation: service.steb_radius(), ..WorldSpec::default() }.generate().unwrap();
        for method in [Method::Parametric, Method::MetaFastrack { levels: 3, quickest: false }] {
            let what = format!("{} on world {seed}", method.label());
            let a = service.run(&world, &method, seed).await.unwrap();
            let b = in_process.run(&world, &method, seed).await.unwrap();
            assert!(!a.samples.is_empty(), "{what}: the run drove");
            assert_same(&a, &b, &what);
            reached += usize::from(a.outcome == Outcome::Reached);
        }
    }
    assert!(reached >= 5, "{reached} of 6 runs reached their goal");
}

#[test]
fn a_missing_or_broken_bundle_is_refused_with_its_folder_named() {
    let missing = Path::new("no/such/bundle/1");
    let Err(error) = LocalModel::load(missing, None, 1) else { panic!("a missing bundle loaded") };
    assert!(error.to_string().contains("no/such/bundle/1"), "{error}");
    let dir = tempfile::tempdir().unwrap();
    let broken = dir.path().join("dubins4d/5");
    std::fs::create_dir_all(&broken).unwrap();
    for file in ["manifest.json", "model.onnx"] {
        std::fs::copy(shipped_bundle().join(file), broken.join(file)).unwrap();
    }
    std::fs::write(broken.join("model.onnx"), b"not an onnx graph").unwrap();
    let Err(error) = LocalModel::load(&broken, None, 1) else { panic!("a corrupt graph loaded") };
    assert!(error.to_string().contains(&broken.display().to_string()), "{error}");
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_golden_trace_records_every_period_and_reads_back() {
    let local = LocalModel::load(&shipped_bundle(), None, 1).unwrap();
    let settings = RunSettings { trace: true, ..RunSettings::default() };
    let simulator = Simulator::new(Backend::InProcess(local), settings).await.unwrap();
    let world: PlaneWorld =
        WorldSpec { seed: 2, inflation: simulator.steb_radius(), ..WorldSpec::default() }.generate().unwrap();
    let run = simulator.run(&world, &Method::Parametric, 2).await.unwrap();
    let trace = run.trace.clone().expect("PF's run carries its trace");
    assert_eq!((trace.format.as_str(), trace.start, trace.goal), (FORMAT, world.start, world.goal));
    assert_eq!(trace.steps.len(), run.samples.len(), "one step per control period");
    let beta_u = simulator.speeds().last().unwrap().beta;
    assert_eq!(trace.steps[0].beta_old, beta_u);
    for (k, pair) in trace.steps.windows(2).enumerate() {
        assert_eq!(pair[1].beta_old, pair[0].beta_query, "period {}: the bound in force chains", k + 1);
    }
    for (step, sample) in trace.steps.iter().zip(&run.samples) {
        assert_eq!((Some(step.planner), Some(step.dteb_radius)), (sample.planner, sample.bound));
    }
    // Each obstacle is given once, when first sensed.
    let sensed: Vec<_> = trace.steps.iter().flat_map(|s| &s.sensed).collect();
    assert!(!sensed.is_empty() && sensed.iter().all(|o| world.obstacles.contains(o)));
    assert!(sensed.iter().enumerate().all(|(i, o)| !sensed[..i].contains(o)), "an obstacle given twice");
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("trace.json");
    trace.write(&path).unwrap();
    assert_eq!(LoopTrace::read(&path).unwrap(), trace);
    std::fs::write(&path, r#"{"format": "another/1"}"#).unwrap();
    let error = LoopTrace::<PlaneObstacle, 2>::read(&path).unwrap_err();
    assert!(error.contains("trace.json"), "{error}");
    // The baselines keep no trace.
    let mf = simulator.run(&world, &Method::MetaFastrack { levels: 3, quickest: false }, 2).await.unwrap();
    assert!(mf.trace.is_none());
}
