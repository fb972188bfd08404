//! The in-process ceiling of the serving bench: a bundle evaluated through ONNX Runtime in this process, no
//! network, on random in-domain inputs like the load generator's. What the server's throughput is compared
//! with; the `fastrack` CLI links no ONNX Runtime, so the ceiling lives with the benches.

use fastrack_cli::load_generator::{per_second, InputDomain, PAYLOADS_PER_CLIENT};
use fastrack_valuefn::bundle::Bundle;
use fastrack_valuefn::runtime::{runtime, Evaluator, GraphDims};
use rand::rngs::StdRng;
use rand::SeedableRng;
use serde_json::{json, Value};
use std::path::PathBuf;
use std::time::{Duration, Instant};

/// The in-process ceiling: a bundle evaluated through ONNX Runtime in this process, no network.
#[derive(Debug, Clone, PartialEq)]
pub struct InProcessSpec {
    /// The bundle's version folder, `<repository>/<name>/<version>`.
    pub bundle_dir: PathBuf,
    /// Items per evaluation (at least 1).
    pub batch: usize,
    /// Threads evaluating at once, one ONNX Runtime session each (at least 1).
    pub threads: usize,
    /// Measured time, after the warm-up.
    pub duration: Duration,
    /// Time the threads run before measuring starts.
    pub warmup: Duration,
    /// The ONNX Runtime library; `None`: `$FASTRACK_ORT_LIB`, then the project's `.cache/onnxruntime`.
    pub ort_lib: Option<PathBuf>,
    /// Seed of the random inputs.
    pub seed: u64,
}

/// What the in-process run measured.
#[derive(Debug, Clone, PartialEq)]
pub struct InProcessReport {
    /// Items per evaluation.
    pub batch: usize,
    /// Threads (and ONNX Runtime sessions).
    pub threads: usize,
    /// Evaluations started after the warm-up.
    pub evaluations: u64,
    /// Items those evaluations covered.
    pub items: u64,
    /// Measured wall time.
    pub elapsed: Duration,
}

impl InProcessReport {
    /// Evaluated items per second.
    pub fn items_per_s(&self) -> f64 {
        per_second(self.items, self.elapsed)
    }

    /// Evaluations (calls) per second.
    pub fn evaluations_per_s(&self) -> f64 {
        per_second(self.evaluations, self.elapsed)
    }

    /// The report as JSON.
    pub fn to_json(&self) -> Value {
        json!({"batch": self.batch, "threads": self.threads, "evaluations": self.evaluations, "items": self.items,
               "elapsed_s": self.elapsed.as_secs_f64(), "items_per_s": self.items_per_s(),
               "evaluations_per_s": self.evaluations_per_s()})
    }
}

/// Evaluates the bundle at `spec.bundle_dir` on `spec.threads` threads, `spec.batch` random in-domain items
/// per call, for the warm-up and then the measured time. Blocks the calling thread: from async code, call
/// it through `tokio::task::spawn_blocking`.
pub fn run_in_process(spec: &InProcessSpec) -> anyhow::Result<InProcessReport> {
    let fail = |reason: String| anyhow::anyhow!("in-process evaluation of {}: {reason}", spec.bundle_dir.display());
    if spec.batch == 0 || spec.threads == 0 {
        return Err(fail("batch and threads must be at least 1".into()));
    }
    let bundle = Bundle::load(&spec.bundle_dir).map_err(|e| fail(e.to_string()))?;
    let m = &bundle.manifest;
    let domain = InputDomain::new(
        m.state.iter().map(|d| (d.min, d.max, d.periodic)),
        m.params.iter().map(|p| (p.min, p.max)),
        &format!("bundle {}", spec.bundle_dir.display()),
    )
    .map_err(|e| fail(e.to_string()))?;
    let dims = GraphDims::of(m);
    let rt = runtime(spec.ort_lib.as_deref()).map_err(|e| fail(e.to_string()))?;
    let evaluator = Evaluator::new(rt, &bundle.onnx, dims, spec.threads).map_err(|e| fail(e.to_string()))?;
    let start = Instant::now();
    let (measure_from, end) = (start + spec.warmup, start + spec.warmup + spec.duration);
    let per_thread = std::thread::scope(|scope| {
        let handles: Vec<_> = (0..spec.threads)
            .map(|t| {
                let mut rng = StdRng::seed_from_u64(spec.seed.wrapping_add(t as u64));
                let payloads: Vec<(Vec<f32>, Vec<f32>)> = (0..PAYLOADS_PER_CLIENT)
                    .map(|_| {
                        let (s, p) = domain.batch(&mut rng, spec.batch);
                        (s.iter().map(|&x| x as f32).collect(), p.iter().map(|&x| x as f32).collect())
                    })
                    .collect();
                let evaluator = &evaluator;
                scope.spawn(move || -> Result<(u64, Instant), String> {
                    let (mut count, mut last) = (0u64, measure_from);
                    for (s, p) in payloads.iter().cycle() {
                        let started = Instant::now();
                        if started >= end {
                            break;
                        }
                        std::hint::black_box(evaluator.evaluate(s, p).map_err(|e| e.to_string())?);
                        if started >= measure_from {
                            count += 1;
                            last = Instant::now();
                        }
                    }
                    Ok((count, last))
                })
            })
            .collect();
        handles
            .into_iter()
            .map(|h| h.join().unwrap_or_else(|_| Err("an evaluation thread panicked".into())))
            .collect::<Vec<_>>()
    });
    let (mut evaluations, mut last) = (0u64, measure_from);
    for result in per_thread {
        let (count, finished) = result.map_err(fail)?;
        evaluations += count;
        last = last.max(finished);
    }
    Ok(InProcessReport {
        batch: spec.batch,
        threads: spec.threads,
        evaluations,
        items: evaluations * spec.batch as u64,
        elapsed: last - measure_from,
    })
}
