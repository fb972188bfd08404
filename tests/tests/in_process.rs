//! The simulator's in-process backend answers as the server does: the same worlds run over the real server
//! (gRPC, the `Track` stream) and over the shipped bundle loaded in this process give the same runs, decision
//! for decision, for Parametric FaSTrack and the level-based baselines; bad bundles are refused with the
//! folder named.

use fastrack_e2e::TestServer;
use fastrack_sim::backend::Backend;
use fastrack_sim::episode::{Outcome, Run, RunSettings, Simulator};
use fastrack_sim::in_process::LocalModel;
use fastrack_sim::methods::Method;
use fastrack_sim::world::WorldSpec;
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

fn assert_same(service: &Run, local: &Run, what: &str) {
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
        let world = WorldSpec { seed, inflation: service.steb_radius(), ..WorldSpec::default() }.generate().unwrap();
        for method in [Method::Parametric, Method::MetaFastrack { levels: 3 }] {
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
    let broken = dir.path().join("dubins4d/4");
    std::fs::create_dir_all(&broken).unwrap();
    for file in ["manifest.json", "model.onnx"] {
        std::fs::copy(shipped_bundle().join(file), broken.join(file)).unwrap();
    }
    std::fs::write(broken.join("model.onnx"), b"not an onnx graph").unwrap();
    let Err(error) = LocalModel::load(&broken, None, 1) else { panic!("a corrupt graph loaded") };
    assert!(error.to_string().contains(&broken.display().to_string()), "{error}");
}
