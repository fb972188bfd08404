//! The model repository: every loaded version of every model, the version policy that resolves requests,
//! and synchronisation with the directory (new, changed and removed version folders). A version is only
//! replaced by a bundle that loaded and warmed up; requests keep the `Arc` of the version they started on.

use crate::loaded_model::LoadedModel;
use crate::metrics::Metrics;
use fastrack_proto::v1 as pb;
use fastrack_valuefn::bundle::{scan_repository, Bundle, MANIFEST_FILE, MODEL_FILE};
use fastrack_valuefn::runtime::Runtime;
use std::collections::{BTreeMap, BTreeSet, HashMap};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex, RwLock};
use std::time::SystemTime;
use tonic::Status;

/// Size and modification time of a version's two files: a changed fingerprint means "load again".
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Fingerprint(Vec<(u64, Option<SystemTime>)>);

impl Fingerprint {
    /// Reads the fingerprint of a version folder (missing files count as empty).
    pub fn of(dir: &Path) -> Self {
        Fingerprint(
            [MANIFEST_FILE, MODEL_FILE]
                .iter()
                .map(|f| match std::fs::metadata(dir.join(f)) {
                    Ok(m) => (m.len(), m.modified().ok()),
                    Err(_) => (0, None),
                })
                .collect(),
        )
    }
}

struct Loaded {
    model: Arc<LoadedModel>,
    fingerprint: Fingerprint,
}

type Versions = BTreeMap<u32, Loaded>;

/// What loading one version folder did.
#[derive(Debug, Clone, PartialEq)]
pub struct LoadOutcome {
    /// Model name.
    pub name: String,
    /// Version.
    pub version: u32,
    /// `Err(reason)` if the bundle was rejected (a previously loaded copy keeps serving).
    pub result: Result<(), String>,
}

/// What one synchronisation with the directory changed.
#[derive(Debug, Default)]
pub struct SyncReport {
    /// Versions (re)loaded or rejected.
    pub outcomes: Vec<LoadOutcome>,
    /// Versions unloaded because their folder disappeared.
    pub removed: Vec<(String, u32)>,
}

/// Loaded models by name and version. Loading is blocking: call it from a blocking thread.
pub struct Repository {
    root: PathBuf,
    runtime: &'static Runtime,
    sessions_per_model: usize,
    pins: BTreeMap<String, u32>,
    metrics: Arc<Metrics>,
    models: RwLock<BTreeMap<String, Versions>>,
    /// Fingerprints of rejected folders, so that polling does not retry a broken bundle until it changes.
    rejected: Mutex<HashMap<(String, u32), Fingerprint>>,
    /// Versions unloaded by an admin: polling leaves them alone until an admin loads them again.
    held_back: Mutex<BTreeSet<(String, u32)>>,
    /// Serialises loads (start-up, polling, admin calls).
    loading: Mutex<()>,
    ready: AtomicBool,
}

impl Repository {
    /// An empty repository over `root`; nothing is loaded until [`Repository::load_all`].
    pub fn new(
        root: &Path,
        runtime: &'static Runtime,
        sessions_per_model: usize,
        pins: BTreeMap<String, u32>,
        metrics: Arc<Metrics>,
    ) -> Self {
        Self {
            root: root.into(),
            runtime,
            sessions_per_model,
            pins,
            metrics,
            models: RwLock::new(BTreeMap::new()),
            rejected: Mutex::new(HashMap::new()),
            held_back: Mutex::new(BTreeSet::new()),
            loading: Mutex::new(()),
            ready: AtomicBool::new(false),
        }
    }

    fn read(&self) -> std::sync::RwLockReadGuard<'_, BTreeMap<String, Versions>> {
        self.models.read().unwrap_or_else(|e| e.into_inner())
    }

    fn write(&self) -> std::sync::RwLockWriteGuard<'_, BTreeMap<String, Versions>> {
        self.models.write().unwrap_or_else(|e| e.into_inner())
    }

    /// True once the initial load has finished.
    pub fn is_ready(&self) -> bool {
        self.ready.load(Ordering::Acquire)
    }

    /// Number of loaded versions over all models.
    pub fn loaded_count(&self) -> usize {
        self.read().values().map(BTreeMap::len).sum()
    }

    fn publish_counts(&self) {
        let counts: Vec<(String, usize)> = self.read().iter().map(|(n, v)| (n.clone(), v.len())).collect();
        self.metrics.set_loaded(&counts);
    }

    fn load_dir(&self, name: &str, version: u32, dir: &Path) -> LoadOutcome {
        let fingerprint = Fingerprint::of(dir);
        let result = Bundle::load_within(&self.root, dir).map_err(|e| e.to_string()).and_then(|bundle| {
            if bundle.manifest.name != name || bundle.manifest.version != version {
                return Err(format!(
                    "{}: the manifest says {}/{}, the folder {name}/{version}",
                    dir.display(),
                    bundle.manifest.name,
                    bundle.manifest.version
                ));
            }
            LoadedModel::new(bundle, self.runtime, self.sessions_per_model)
                .map_err(|e| format!("{}: {e}", dir.display()))
        });
        let key = (name.to_string(), version);
        let result = match result {
            Ok(model) => {
                tracing::info!(model = %model.label(), untrained = model.manifest.untrained, "model loaded and warmed up");
                let loaded = Loaded { model: Arc::new(model), fingerprint };
                self.write().entry(name.to_string()).or_default().insert(version, loaded);
                self.rejected.lock().unwrap_or_else(|e| e.into_inner()).remove(&key);
                Ok(())
            }
            Err(reason) => {
                let serving = self.read().get(name).is_some_and(|v| v.contains_key(&version));
                tracing::error!(model = %format!("{name}/{version}"), %reason, previous_keeps_serving = serving, "bundle rejected");
                self.metrics.load_failure(name);
                self.rejected.lock().unwrap_or_else(|e| e.into_inner()).insert(key, fingerprint);
                Err(reason)
            }
        };
        LoadOutcome { name: name.into(), version, result }
    }

    /// Loads every version folder of the repository (or of one model, or one version of it), whether or
    /// not it changed; an admin's explicit load also lifts an earlier admin unload.
    pub fn load(&self, only_name: Option<&str>, only_version: Option<u32>) -> Result<Vec<LoadOutcome>, String> {
        let _guard = self.loading.lock().unwrap_or_else(|e| e.into_inner());
        let found = self.scan()?;
        let outcomes: Vec<LoadOutcome> = found
            .iter()
            .filter(|v| only_name.is_none_or(|n| n == v.name) && only_version.is_none_or(|x| x == v.version))
            .map(|v| {
                self.held_back.lock().unwrap_or_else(|e| e.into_inner()).remove(&(v.name.clone(), v.version));
                self.load_dir(&v.name, v.version, &v.path)
            })
            .collect();
        self.publish_counts();
        Ok(outcomes)
    }

    fn scan(&self) -> Result<Vec<fastrack_valuefn::bundle::VersionDir>, String> {
        let (found, skipped) = scan_repository(&self.root)
            .map_err(|e| format!("cannot read model repository {}: {e}", self.root.display()))?;
        for (path, why) in skipped {
            tracing::debug!(path = %path.display(), why, "skipped");
        }
        Ok(found)
    }

    /// The initial load at start-up; marks the repository ready afterwards, whatever the outcome.
    pub fn load_all(&self) -> Result<Vec<LoadOutcome>, String> {
        let outcome = self.load(None, None);
        self.ready.store(true, Ordering::Release);
        outcome
    }

    /// Brings the repository in line with the directory: loads new and changed folders (a rejected folder
    /// is retried only once it changes), unloads versions whose folder is gone. Admin-unloaded versions
    /// are left alone.
    pub fn sync(&self) -> Result<SyncReport, String> {
        let _guard = self.loading.lock().unwrap_or_else(|e| e.into_inner());
        let found = self.scan()?;
        let mut report = SyncReport::default();
        let on_disk: BTreeSet<(String, u32)> = found.iter().map(|v| (v.name.clone(), v.version)).collect();
        for v in &found {
            let key = (v.name.clone(), v.version);
            if self.held_back.lock().unwrap_or_else(|e| e.into_inner()).contains(&key) {
                continue;
            }
            let fingerprint = Fingerprint::of(&v.path);
            let current = self.read().get(&v.name).and_then(|m| m.get(&v.version)).map(|l| l.fingerprint.clone());
            let rejected = self.rejected.lock().unwrap_or_else(|e| e.into_inner()).get(&key).cloned();
            if current.as_ref() == Some(&fingerprint) || rejected.as_ref() == Some(&fingerprint) {
                continue;
            }
            report.outcomes.push(self.load_dir(&v.name, v.version, &v.path));
        }
        let gone: Vec<(String, u32)> = self
            .read()
            .iter()
            .flat_map(|(name, versions)| versions.keys().map(move |v| (name.clone(), *v)))
            .filter(|key| !on_disk.contains(key))
            .collect();
        for (name, version) in gone {
            self.remove(&name, Some(version));
            tracing::info!(model = %format!("{name}/{version}"), "folder removed; version unloaded");
            report.removed.push((name, version));
        }
        self.publish_counts();
        Ok(report)
    }

    fn remove(&self, name: &str, version: Option<u32>) -> Vec<u32> {
        let mut models = self.write();
        let Some(versions) = models.get_mut(name) else { return Vec::new() };
        let removed: Vec<u32> = match version {
            Some(v) => versions.remove(&v).map(|_| v).into_iter().collect(),
            None => std::mem::take(versions).into_keys().collect(),
        };
        if versions.is_empty() {
            models.remove(name);
        }
        removed
    }

    /// Stops serving one version (or every version) of a model, and keeps polling from loading it back;
    /// returns the versions removed.
    pub fn unload(&self, name: &str, version: Option<u32>) -> Vec<u32> {
        let removed = self.remove(name, version);
        self.held_back.lock().unwrap_or_else(|e| e.into_inner()).extend(removed.iter().map(|v| (name.to_string(), *v)));
        self.publish_counts();
        removed
    }

    /// Versions currently loaded for `name`.
    pub fn versions(&self, name: &str) -> Vec<u32> {
        self.read().get(name).map(|v| v.keys().copied().collect()).unwrap_or_default()
    }

    /// The version answering requests for version 0: the pinned one if the model is pinned, else the latest.
    fn default_version(&self, name: &str, versions: &Versions) -> Option<u32> {
        match self.pins.get(name) {
            Some(pinned) => Some(*pinned),
            None => versions.keys().next_back().copied(),
        }
    }

    /// Finds the model a request names: `UNAVAILABLE` while loading or when nothing is loaded,
    /// `INVALID_ARGUMENT` without a name, `NOT_FOUND` for an unknown model or version.
    pub fn resolve(&self, model: Option<&pb::ModelRef>) -> Result<Arc<LoadedModel>, Status> {
        if !self.is_ready() {
            return Err(Status::unavailable(
                "models are still loading; retry shortly (grpc.health.v1 turns SERVING when ready)",
            ));
        }
        let models = self.read();
        if models.is_empty() {
            return Err(Status::unavailable(format!(
                "no model is loaded (repository {} is empty or every bundle in it was rejected; see the server log)",
                self.root.display()
            )));
        }
        let names = || models.keys().cloned().collect::<Vec<_>>().join(", ");
        let Some(model) = model.filter(|m| !m.name.is_empty()) else {
            return Err(Status::invalid_argument(format!("model.name is required; loaded models: {}", names())));
        };
        let Some(versions) = models.get(&model.name) else {
            return Err(Status::not_found(format!("model {:?} is not loaded; loaded models: {}", model.name, names())));
        };
        let wanted = if model.version == 0 { self.default_version(&model.name, versions) } else { Some(model.version) };
        let pinned = if model.version == 0 && self.pins.contains_key(&model.name) { " (pinned)" } else { "" };
        wanted.and_then(|v| versions.get(&v)).map(|l| Arc::clone(&l.model)).ok_or_else(|| {
            Status::not_found(format!(
                "model {:?} has no loaded version {}{pinned}; loaded versions: {:?} (0 = default)",
                model.name,
                wanted.unwrap_or(model.version),
                versions.keys().collect::<Vec<_>>()
            ))
        })
    }

    /// The copy of `model`'s name and version loaded now, if it is another than `model` (the version was
    /// reloaded since): a long-lived stream moves to it, so that a replaced copy is freed once its calls end
    /// rather than kept for as long as the oldest stream lives. None while `model` is current, or when its
    /// version is no longer loaded (the stream keeps what it has).
    pub fn reloaded(&self, model: &Arc<LoadedModel>) -> Option<Arc<LoadedModel>> {
        let models = self.read();
        let current = &models.get(&model.manifest.name)?.get(&model.manifest.version)?.model;
        (!Arc::ptr_eq(current, model)).then(|| Arc::clone(current))
    }

    /// Every loaded version, with the default version of each model marked.
    pub fn list(&self) -> Vec<pb::ModelInfo> {
        let models = self.read();
        models
            .iter()
            .flat_map(|(name, versions)| {
                let default = self.default_version(name, versions);
                versions.iter().map(move |(v, l)| pb::ModelInfo {
                    is_default_version: Some(*v) == default,
                    ..l.model.info.clone()
                })
            })
            .collect()
    }

    /// The description of one resolved model, with its default flag.
    pub fn describe(&self, model: &LoadedModel) -> pb::ModelInfo {
        let models = self.read();
        let default = models.get(&model.manifest.name).and_then(|v| self.default_version(&model.manifest.name, v));
        pb::ModelInfo { is_default_version: Some(model.manifest.version) == default, ..model.info.clone() }
    }
}
