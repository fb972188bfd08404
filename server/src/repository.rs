//! The model repository: every loaded version of every model, resolved per request.

use crate::model::LoadedModel;
use fastrack_proto::v1 as pb;
use fastrack_valuefn::bundle::{scan_repository, Bundle};
use fastrack_valuefn::runtime::Runtime;
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, RwLock};
use tonic::Status;

type Versions = BTreeMap<u32, Arc<LoadedModel>>;

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

/// Loaded models by name and version. Loading is blocking: call it from a blocking thread.
pub struct Repository {
    root: PathBuf,
    runtime: &'static Runtime,
    sessions_per_model: usize,
    models: RwLock<BTreeMap<String, Versions>>,
    ready: AtomicBool,
}

impl Repository {
    /// An empty repository over `root`; nothing is loaded until [`Repository::load_all`].
    pub fn new(root: &Path, runtime: &'static Runtime, sessions_per_model: usize) -> Self {
        Self {
            root: root.into(),
            runtime,
            sessions_per_model,
            models: RwLock::new(BTreeMap::new()),
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

    fn load_dir(&self, name: &str, version: u32, dir: &Path) -> LoadOutcome {
        let result = Bundle::load(dir).map_err(|e| e.to_string()).and_then(|bundle| {
            LoadedModel::new(bundle, self.runtime, self.sessions_per_model)
                .map_err(|e| format!("{}: {e}", dir.display()))
        });
        let result = match result {
            Ok(model) => {
                tracing::info!(model = %model.label(), untrained = model.manifest.untrained, "model loaded");
                self.write().entry(name.to_string()).or_default().insert(version, Arc::new(model));
                Ok(())
            }
            Err(reason) => {
                tracing::error!(model = %format!("{name}/{version}"), %reason, "model rejected");
                Err(reason)
            }
        };
        LoadOutcome { name: name.into(), version, result }
    }

    /// Loads every version folder of the repository (or of one model, or one version of it).
    pub fn load(&self, only_name: Option<&str>, only_version: Option<u32>) -> Result<Vec<LoadOutcome>, String> {
        let (found, skipped) = scan_repository(&self.root)
            .map_err(|e| format!("cannot read model repository {}: {e}", self.root.display()))?;
        for (path, why) in skipped {
            tracing::warn!(path = %path.display(), why, "skipped");
        }
        Ok(found
            .iter()
            .filter(|v| only_name.is_none_or(|n| n == v.name) && only_version.is_none_or(|x| x == v.version))
            .map(|v| self.load_dir(&v.name, v.version, &v.path))
            .collect())
    }

    /// The initial load at start-up; marks the repository ready afterwards, whatever the outcome.
    pub fn load_all(&self) -> Result<Vec<LoadOutcome>, String> {
        let outcome = self.load(None, None);
        self.ready.store(true, Ordering::Release);
        outcome
    }

    /// Stops serving one version (or every version) of a model; returns the versions removed.
    pub fn unload(&self, name: &str, version: Option<u32>) -> Vec<u32> {
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

    /// Versions currently loaded for `name`.
    pub fn versions(&self, name: &str) -> Vec<u32> {
        self.read().get(name).map(|v| v.keys().copied().collect()).unwrap_or_default()
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
        let Some(model) = model.filter(|m| !m.name.is_empty()) else {
            return Err(Status::invalid_argument(format!(
                "model.name is required; loaded models: {}",
                models.keys().cloned().collect::<Vec<_>>().join(", ")
            )));
        };
        let Some(versions) = models.get(&model.name) else {
            return Err(Status::not_found(format!(
                "model {:?} is not loaded; loaded models: {}",
                model.name,
                models.keys().cloned().collect::<Vec<_>>().join(", ")
            )));
        };
        let found = if model.version == 0 { versions.values().next_back() } else { versions.get(&model.version) };
        found.cloned().ok_or_else(|| {
            Status::not_found(format!(
                "model {:?} has no loaded version {}; loaded versions: {:?} (0 = latest)",
                model.name,
                model.version,
                versions.keys().collect::<Vec<_>>()
            ))
        })
    }

    /// Every loaded version, with the default (latest) of each model marked.
    pub fn list(&self) -> Vec<pb::ModelInfo> {
        self.read()
            .values()
            .flat_map(|versions| {
                let latest = versions.keys().next_back().copied();
                versions
                    .iter()
                    .map(move |(v, m)| pb::ModelInfo { is_default_version: Some(*v) == latest, ..m.info.clone() })
            })
            .collect()
    }

    /// The description of one resolved model, with its default flag.
    pub fn describe(&self, model: &LoadedModel) -> pb::ModelInfo {
        let latest = self.versions(&model.manifest.name).last().copied();
        pb::ModelInfo { is_default_version: Some(model.manifest.version) == latest, ..model.info.clone() }
    }
}
