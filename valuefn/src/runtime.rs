//! ONNX Runtime through `ort` (`load-dynamic`): finding the shared library, one process-wide environment,
//! and a pooled batch [`Evaluator`] for bundle graphs (one intra-op thread per session).

use ort::session::builder::GraphOptimizationLevel;
use ort::session::Session;
use ort::value::{TensorElementType, TensorRef, ValueType};
use std::path::{Path, PathBuf};
use std::sync::{Condvar, Mutex, OnceLock};

/// Environment variable naming the library explicitly.
pub(crate) const LIBRARY_ENV: &str = "FASTRACK_ORT_LIB";
/// Project folder the set-up script installs the library into.
pub(crate) const CACHE_DIR: &str = ".cache/onnxruntime";
/// How to install the library.
pub(crate) const INSTALL_HINT: &str = "run `bash scripts/setup-onnxruntime.sh` from the project root (it installs the onnxruntime==1.31.1 wheel into .cache/onnxruntime), or set FASTRACK_ORT_LIB to a libonnxruntime.so of version >= 1.31";

/// ONNX Runtime could not be loaded, or a graph could not be used.
#[derive(Debug, Clone, thiserror::Error)]
pub enum RuntimeError {
    /// No library file was found.
    #[error("ONNX Runtime library not found; looked for {looked_for}; {INSTALL_HINT}")]
    LibraryNotFound {
        /// What was searched.
        looked_for: String,
    },
    /// The library failed to load or has the wrong version.
    #[error("cannot use ONNX Runtime library {path}: {reason}; {INSTALL_HINT}")]
    Library {
        /// The library file.
        path: PathBuf,
        /// Why (including version mismatch).
        reason: String,
    },
    /// The graph could not be turned into a session.
    #[error("invalid ONNX graph: {0}")]
    Graph(String),
    /// The graph's inputs or outputs differ from the bundle contract.
    #[error("graph signature mismatch: {0}")]
    Signature(String),
    /// Inference failed.
    #[error("ONNX Runtime inference failed: {0}")]
    Inference(String),
}

/// The process-wide ONNX Runtime environment.
pub struct Runtime {
    env: ort::environment::Environment,
    /// The library file loaded.
    pub library: PathBuf,
}

impl Runtime {
    /// The `ort` environment, for callers that build their own sessions (benchmarks).
    pub fn environment(&self) -> &ort::environment::Environment {
        &self.env
    }
}

static RUNTIME: OnceLock<Result<Runtime, RuntimeError>> = OnceLock::new();

fn find_in(dir: &Path, depth: usize) -> Option<PathBuf> {
    let mut entries: Vec<_> = std::fs::read_dir(dir).ok()?.filter_map(Result::ok).map(|e| e.path()).collect();
    entries.sort();
    for path in &entries {
        let name = path.file_name().and_then(|n| n.to_str()).unwrap_or_default();
        if path.is_file() && name.starts_with("libonnxruntime.so.") {
            return Some(path.clone());
        }
    }
    if depth == 0 {
        return None;
    }
    entries.iter().filter(|p| p.is_dir()).find_map(|p| find_in(p, depth - 1))
}

/// Candidate cache folders: `.cache/onnxruntime` in the working directory, the executable's folder and
/// their ancestors (so binaries and tests under `target/` find the project's cache).
fn cache_candidates() -> Vec<PathBuf> {
    let mut roots = Vec::new();
    if let Ok(cwd) = std::env::current_dir() {
        roots.extend(cwd.ancestors().map(Path::to_path_buf));
    }
    if let Ok(exe) = std::env::current_exe() {
        roots.extend(exe.ancestors().skip(1).map(Path::to_path_buf));
    }
    roots.dedup();
    roots.into_iter().map(|r| r.join(CACHE_DIR)).filter(|p| p.is_dir()).collect()
}

/// Locates the library: `explicit`, then `$FASTRACK_ORT_LIB`, then the project cache.
pub(crate) fn locate_library(explicit: Option<&Path>) -> Result<PathBuf, RuntimeError> {
    if let Some(path) = explicit {
        return Ok(path.into());
    }
    if let Some(path) = std::env::var_os(LIBRARY_ENV) {
        return Ok(path.into());
    }
    let candidates = cache_candidates();
    candidates.iter().find_map(|dir| find_in(dir, 4)).ok_or_else(|| RuntimeError::LibraryNotFound {
        looked_for: format!(
            "${LIBRARY_ENV} (unset) and libonnxruntime.so.* under {CACHE_DIR} in the working directory, the executable's folder and their parents{}",
            if candidates.is_empty() { " (no such folder exists)".to_string() } else { format!(" ({candidates:?} hold none)") }
        ),
    })
}

/// Loads ONNX Runtime once per process (later calls return the same result, whatever `explicit` says).
pub fn runtime(explicit: Option<&Path>) -> Result<&'static Runtime, RuntimeError> {
    RUNTIME
        .get_or_init(|| {
            let library = locate_library(explicit)?;
            if !library.is_file() {
                return Err(RuntimeError::Library { path: library, reason: "no such file".into() });
            }
            let fail = |reason: String| RuntimeError::Library { path: library.clone(), reason };
            let builder = ort::init_from(&library).map_err(|e| fail(e.to_string()))?;
            let env = builder.with_name("fastrack").build().map_err(|e| fail(e.to_string()))?;
            tracing::info!(library = %library.display(), "ONNX Runtime loaded");
            Ok(Runtime { env, library })
        })
        .as_ref()
        .map_err(Clone::clone)
}

/// Dimensions a bundle graph must have.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct GraphDims {
    /// Relative-state coordinates.
    pub n_state: usize,
    /// Parameters.
    pub n_params: usize,
    /// Controls.
    pub n_control: usize,
}

impl GraphDims {
    /// The dimensions a bundle's manifest declares for its graph.
    pub fn of(manifest: &crate::manifest::Manifest) -> Self {
        Self { n_state: manifest.state.len(), n_params: manifest.n_params(), n_control: manifest.n_control() }
    }

    /// The dimensions of a graph written for `system`.
    pub fn of_system(system: &crate::system::AffineSystem) -> Self {
        Self { n_state: system.n_state(), n_params: system.n_params(), n_control: system.n_control() }
    }
}

/// Outputs of one batch, row-major, f32 as the graph computes them.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Evaluation {
    /// `V` `[N]`.
    pub value: Vec<f32>,
    /// `dV/dr` `[N x n_state]`.
    pub grad: Vec<f32>,
    /// `u*` `[N x n_control]`.
    pub control: Vec<f32>,
}

/// A pool of ONNX Runtime sessions of one graph; `evaluate` blocks the calling thread (call it from a
/// blocking pool, never from an async runtime's worker).
pub struct Evaluator {
    dims: GraphDims,
    idle: Mutex<Vec<Session>>,
    returned: Condvar,
}

fn check_outlet(kind: &str, outlet: &ort::value::Outlet, expected: &[i64]) -> Result<(), RuntimeError> {
    match outlet.dtype() {
        ValueType::Tensor { ty: TensorElementType::Float32, shape, .. } if shape.iter().as_slice() == expected => {
            Ok(())
        }
        other => Err(RuntimeError::Signature(format!(
            "{kind} `{}` must be a float32 tensor of shape {expected:?} (-1 = batch), found {other:?}",
            outlet.name()
        ))),
    }
}

impl Evaluator {
    /// Creates `sessions` sessions of `onnx` (at least one) and checks the graph's signature against `dims`.
    pub fn new(runtime: &Runtime, onnx: &[u8], dims: GraphDims, sessions: usize) -> Result<Self, RuntimeError> {
        let mut pool = Vec::with_capacity(sessions.max(1));
        for _ in 0..sessions.max(1) {
            let session = Session::builder(&runtime.env)
                .and_then(|b| {
                    Ok(b.with_intra_threads(1)?
                        .with_inter_threads(1)?
                        .with_optimization_level(GraphOptimizationLevel::Level3)?)
                })
                .map_err(|e| RuntimeError::Graph(e.to_string()))?
                .commit_from_memory(onnx)
                .map_err(|e| RuntimeError::Graph(e.to_string()))?;
            pool.push(session);
        }
        let session = &pool[0];
        let names = |outlets: &[ort::value::Outlet]| outlets.iter().map(|o| o.name().to_string()).collect::<Vec<_>>();
        if names(session.inputs()) != ["state", "params"] {
            return Err(RuntimeError::Signature(format!(
                "inputs must be [state, params], found {:?}",
                names(session.inputs())
            )));
        }
        if names(session.outputs()) != ["value", "grad", "control"] {
            return Err(RuntimeError::Signature(format!(
                "outputs must be [value, grad, control], found {:?}",
                names(session.outputs())
            )));
        }
        let (ns, np, nc) = (dims.n_state as i64, dims.n_params as i64, dims.n_control as i64);
        check_outlet("input", &session.inputs()[0], &[-1, ns])?;
        check_outlet("input", &session.inputs()[1], &[-1, np])?;
        check_outlet("output", &session.outputs()[0], &[-1])?;
        check_outlet("output", &session.outputs()[1], &[-1, ns])?;
        check_outlet("output", &session.outputs()[2], &[-1, nc])?;
        Ok(Self { dims, idle: Mutex::new(pool), returned: Condvar::new() })
    }

    /// The graph's dimensions.
    pub fn dims(&self) -> GraphDims {
        self.dims
    }

    fn checkout(&self) -> Session {
        let mut idle = self.idle.lock().unwrap_or_else(|e| e.into_inner());
        loop {
            if let Some(session) = idle.pop() {
                return session;
            }
            idle = self.returned.wait(idle).unwrap_or_else(|e| e.into_inner());
        }
    }

    fn checkin(&self, session: Session) {
        self.idle.lock().unwrap_or_else(|e| e.into_inner()).push(session);
        self.returned.notify_one();
    }

    /// Evaluates a batch: `state` `[N x n_state]`, `params` `[N x n_params]`, row-major.
    pub fn evaluate(&self, state: &[f32], params: &[f32]) -> Result<Evaluation, RuntimeError> {
        let GraphDims { n_state, n_params, .. } = self.dims;
        let n = state.len() / n_state;
        if state.len() != n * n_state || params.len() != n * n_params || n == 0 {
            return Err(RuntimeError::Inference(format!(
                "batch shapes disagree: {} state values for n_state {n_state}, {} params for n_params {n_params}",
                state.len(),
                params.len()
            )));
        }
        let mut session = self.checkout();
        let result = Self::run(&mut session, state, params, n, self.dims);
        self.checkin(session);
        result
    }

    /// Runs every session of the pool once on the batch (ONNX Runtime allocates and plans on the first
    /// run), returning the last evaluation. Meant for load time, before the evaluator is shared.
    pub fn warm_up(&self, state: &[f32], params: &[f32]) -> Result<Evaluation, RuntimeError> {
        let mut sessions = std::mem::take(&mut *self.idle.lock().unwrap_or_else(|e| e.into_inner()));
        let n = state.len() / self.dims.n_state.max(1);
        let mut last = Err(RuntimeError::Inference("the evaluator has no session".into()));
        for session in &mut sessions {
            last = Self::run(session, state, params, n, self.dims);
            if last.is_err() {
                break;
            }
        }
        self.idle.lock().unwrap_or_else(|e| e.into_inner()).extend(sessions);
        self.returned.notify_all();
        last
    }

    fn run(
        session: &mut Session,
        state: &[f32],
        params: &[f32],
        n: usize,
        dims: GraphDims,
    ) -> Result<Evaluation, RuntimeError> {
        let err = |e: ort::Error| RuntimeError::Inference(e.to_string());
        let state = TensorRef::from_array_view(([n, dims.n_state], state)).map_err(err)?;
        let params = TensorRef::from_array_view(([n, dims.n_params], params)).map_err(err)?;
        let outputs = session.run(ort::inputs![state, params]).map_err(err)?;
        let extract = |i: usize| -> Result<Vec<f32>, RuntimeError> {
            Ok(outputs[i].try_extract_tensor::<f32>().map_err(err)?.1.to_vec())
        };
        Ok(Evaluation { value: extract(0)?, grad: extract(1)?, control: extract(2)? })
    }
}

impl crate::teb::ValueOracle for Evaluator {
    fn values_and_grads(&self, states: &[f64], params: &[f64]) -> Result<(Vec<f64>, Vec<f64>), String> {
        let mut values = Vec::with_capacity(states.len() / self.dims.n_state);
        let mut grads = Vec::with_capacity(states.len());
        const CHUNK: usize = 4096;
        for (s, p) in states.chunks(CHUNK * self.dims.n_state).zip(params.chunks(CHUNK * self.dims.n_params)) {
            let s: Vec<f32> = s.iter().map(|&x| x as f32).collect();
            let p: Vec<f32> = p.iter().map(|&x| x as f32).collect();
            let out = self.evaluate(&s, &p).map_err(|e| e.to_string())?;
            values.extend(out.value.iter().map(|&x| f64::from(x)));
            grads.extend(out.grad.iter().map(|&x| f64::from(x)));
        }
        Ok((values, grads))
    }
}
