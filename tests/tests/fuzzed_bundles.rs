//! Bundles nobody meant to write, loaded by the real server: damaged manifests (a node replaced or removed,
//! the text cut or a bit flipped), cut or bit-flipped graphs with and without a matching checksum, files and
//! version folders that are links out of the repository, to a device or to nowhere, and files past the
//! size limit. Each load either serves a model that answers, or is refused with FAILED_PRECONDITION naming
//! the folder; the server never panics and the model beside keeps serving. `FASTRACK_FUZZ_CASES` sets the
//! cases (default 300).

use fastrack_client::{model_ref, pb, ClientError, FastrackClient};
use fastrack_e2e::fuzz::{cases, damage, json_text, Damage, Tally};
use fastrack_e2e::{write_test_bundle, TestServer};
use fastrack_valuefn::bundle::{sha256_hex, MANIFEST_FILE, MAX_MODEL_BYTES, MODEL_FILE};
use fastrack_valuefn::system::dubins4d;
use proptest::prelude::*;
use proptest::test_runner::{Config, TestCaseError, TestRunner};
use std::cell::{Cell, RefCell};
use std::os::unix::fs::symlink;
use std::path::Path;
use tonic::Code;

/// Which file a damage touches.
#[derive(Debug, Clone, Copy)]
enum File {
    Manifest,
    Graph,
}

impl File {
    fn name(self) -> &'static str {
        match self {
            File::Manifest => MANIFEST_FILE,
            File::Graph => MODEL_FILE,
        }
    }
}

/// Where a link leads.
#[derive(Debug, Clone, Copy)]
enum Target {
    /// A copy of the same file outside the repository.
    Outside,
    /// A device that never ends.
    DevZero,
    /// A path that does not exist.
    Nowhere,
}

/// One broken bundle.
#[derive(Debug, Clone)]
enum Broken {
    /// The manifest damaged (its checksum of the graph kept).
    Manifest(Damage),
    /// The graph cut to a share of its bytes; the manifest's checksum updated or not.
    GraphCut { share: f64, checksum_updated: bool },
    /// One bit of the graph flipped; the manifest's checksum updated or not.
    GraphFlip { share: f64, bit: u8, checksum_updated: bool },
    /// A file replaced by a link.
    FileLink(File, Target),
    /// The whole version folder a link to a good bundle outside the repository.
    FolderLink,
    /// A (sparse) file one byte past the size limit.
    Huge(File),
}

impl Broken {
    fn kind(&self) -> String {
        match self {
            Broken::Manifest(d) => format!("manifest {}", d.kind()),
            Broken::GraphCut { .. } | Broken::GraphFlip { .. } => "graph".into(),
            Broken::FileLink(..) | Broken::FolderLink => "link".into(),
            Broken::Huge(_) => "huge".into(),
        }
    }

    /// The fragment a refusal must hold, where the damage allows only one reason.
    fn certain_reason(&self) -> Option<&'static str> {
        match self {
            Broken::GraphCut { checksum_updated: false, .. } | Broken::GraphFlip { checksum_updated: false, .. } => {
                Some("sha256")
            }
            Broken::FileLink(_, Target::Outside | Target::DevZero) | Broken::FolderLink => {
                Some("outside the model repository")
            }
            Broken::FileLink(_, Target::Nowhere) => Some("No such file"),
            Broken::Huge(_) => Some("a bundle's"),
            _ => None,
        }
    }
}

fn file() -> impl Strategy<Value = File> {
    prop_oneof![Just(File::Manifest), Just(File::Graph)]
}

fn broken() -> impl Strategy<Value = Broken> {
    let target = prop_oneof![Just(Target::Outside), Just(Target::DevZero), Just(Target::Nowhere)];
    prop_oneof![
        8 => damage().prop_map(Broken::Manifest),
        2 => (0.0..1.0f64, any::<bool>())
            .prop_map(|(share, checksum_updated)| Broken::GraphCut { share, checksum_updated }),
        3 => (0.0..1.0f64, 0u8..8, any::<bool>())
            .prop_map(|(share, bit, checksum_updated)| Broken::GraphFlip { share, bit, checksum_updated }),
        1 => (file(), target).prop_map(|(f, t)| Broken::FileLink(f, t)),
        1 => Just(Broken::FolderLink),
        1 => file().prop_map(Broken::Huge),
    ]
}

/// Replaces the graph of the bundle in `dir` by `onnx`, updating the manifest's checksum or not.
fn replace_graph(dir: &Path, onnx: &[u8], checksum_updated: bool) {
    let old = std::fs::read(dir.join(MODEL_FILE)).unwrap();
    if checksum_updated {
        let manifest = std::fs::read_to_string(dir.join(MANIFEST_FILE)).unwrap();
        std::fs::write(dir.join(MANIFEST_FILE), manifest.replace(&sha256_hex(&old), &sha256_hex(onnx))).unwrap();
    }
    std::fs::write(dir.join(MODEL_FILE), onnx).unwrap();
}

/// Writes `fuzz/<version>` of the repository `root` as a good bundle, then breaks it.
fn write_broken(root: &Path, outside: &Path, version: u32, broken: &Broken) {
    let dir = write_test_bundle(root, &dubins4d::system(), "fuzz", version, u64::from(version));
    match broken {
        Broken::Manifest(damage) => {
            let tree: serde_json::Value =
                serde_json::from_str(&std::fs::read_to_string(dir.join(MANIFEST_FILE)).unwrap()).unwrap();
            std::fs::write(dir.join(MANIFEST_FILE), damage.apply(&tree, json_text)).unwrap();
        }
        Broken::GraphCut { share, checksum_updated } => {
            let onnx = std::fs::read(dir.join(MODEL_FILE)).unwrap();
            replace_graph(&dir, &onnx[..(share * onnx.len() as f64) as usize], *checksum_updated);
        }
        Broken::GraphFlip { share, bit, checksum_updated } => {
            let mut onnx = std::fs::read(dir.join(MODEL_FILE)).unwrap();
            let at = ((share * onnx.len() as f64) as usize).min(onnx.len() - 1);
            onnx[at] ^= 1 << bit;
            replace_graph(&dir, &onnx, *checksum_updated);
        }
        Broken::FileLink(file, target) => {
            let path = dir.join(file.name());
            let to = match target {
                Target::Outside => {
                    let copy = outside.join(format!("{version}-{}", file.name()));
                    std::fs::copy(&path, &copy).unwrap();
                    copy
                }
                Target::DevZero => "/dev/zero".into(),
                Target::Nowhere => outside.join("nothing-here"),
            };
            std::fs::remove_file(&path).unwrap();
            symlink(to, path).unwrap();
        }
        Broken::FolderLink => {
            let good = write_test_bundle(outside, &dubins4d::system(), "fuzz", version, u64::from(version));
            std::fs::remove_dir_all(&dir).unwrap();
            symlink(good, dir).unwrap();
        }
        Broken::Huge(file) => {
            std::fs::File::create(dir.join(file.name())).unwrap().set_len(MAX_MODEL_BYTES + 1).unwrap();
        }
    }
}

/// A loaded version must describe itself and answer at the centre of its domain (or refuse the centre as
/// input, if the damage moved the domain); its answers are finite.
async fn answers(client: &FastrackClient, version: u32) -> Result<(), TestCaseError> {
    let info = client.get_model(model_ref("fuzz", version)).await;
    let info = info.map_err(|e| TestCaseError::fail(format!("a loaded version is not described: {e}")))?;
    let centre = |r: Option<pb::Interval>| r.map_or(0.0, |r| 0.5 * (r.min + r.max));
    let state: Vec<f64> = info.state.iter().map(|d| centre(d.bounds)).collect();
    let params: Vec<f64> = info.params.iter().map(|p| centre(p.range)).collect();
    let answer =
        client.evaluate_value(model_ref("fuzz", version), state, params, pb::OutOfDomainPolicy::Unspecified).await;
    match answer {
        Ok(reply) => prop_assert!(reply.values.iter().all(|v| v.is_finite()), "values {:?}", reply.values),
        Err(ClientError::Status(s)) => {
            prop_assert!(
                [Code::InvalidArgument, Code::OutOfRange].contains(&s.code()),
                "{:?}: {}",
                s.code(),
                s.message()
            )
        }
        Err(e) => return Err(TestCaseError::fail(format!("{e}"))),
    }
    Ok(())
}

#[test]
fn broken_bundles_are_served_correctly_or_refused_with_the_folder_and_the_server_keeps_serving() {
    let runtime = tokio::runtime::Builder::new_multi_thread().worker_threads(2).enable_all().build().unwrap();
    let repo = tempfile::tempdir().unwrap();
    let outside = tempfile::tempdir().unwrap();
    write_test_bundle(repo.path(), &dubins4d::system(), "good", 1, 1);
    let (mut server, client) =
        runtime.block_on(TestServer::start_serving_with(repo.path(), &["--poll-interval-s", "0"]));
    let config = Config { cases: cases(300), failure_persistence: None, ..Config::default() };
    let version = Cell::new(0u32);
    // Loaded and refused per kind of damage: the draws must reach both where both are possible.
    let tally = RefCell::new(Tally::new("bundles", config.cases));

    TestRunner::new(config)
        .run(&broken(), |broken| {
            version.set(version.get() + 1);
            let v = version.get();
            write_broken(repo.path(), outside.path(), v, &broken);
            let loaded = runtime.block_on(client.load_model("fuzz", v));
            tally.borrow_mut().count(broken.kind(), loaded.is_ok());
            match loaded {
                Ok(_) => {
                    prop_assert!(broken.certain_reason().is_none(), "{broken:?} was loaded");
                    runtime.block_on(answers(&client, v))?;
                    runtime.block_on(client.unload_model("fuzz", v)).unwrap();
                }
                Err(ClientError::Status(s)) => {
                    prop_assert_eq!(s.code(), Code::FailedPrecondition, "{}", s.message());
                    prop_assert!(
                        s.message().contains(&format!("fuzz/{v}")),
                        "the folder is not named: {}",
                        s.message()
                    );
                    if let Some(reason) = broken.certain_reason() {
                        prop_assert!(s.message().contains(reason), "{broken:?}: {}", s.message());
                    }
                }
                Err(e) => return Err(TestCaseError::fail(format!("{broken:?}: {e}"))),
            }
            // The folder goes (a long run writes tens of thousands); a link goes as itself.
            let dir = repo.path().join("fuzz").join(v.to_string());
            let _ = std::fs::remove_dir_all(&dir).or_else(|_| std::fs::remove_file(&dir));
            let good = runtime.block_on(client.tracking_error_bound(model_ref("good", 0), 1.0, 0));
            prop_assert!(good.is_ok(), "the good model stopped answering after {broken:?}");
            Ok(())
        })
        .unwrap();

    let tally = tally.into_inner();
    tally.assert_both("manifest");
    tally.assert_both("graph");
    assert!(server.is_running(), "the server died");
    tally.report();
}
