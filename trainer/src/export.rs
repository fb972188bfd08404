//! Writes a value network, or a composite of axis networks, as a served bundle: ONNX graph, TEB table
//! computed from the graph itself through ONNX Runtime, manifest with provenance; then reloads it and checks
//! the served value against the f64 model before declaring success.

use anyhow::{ensure, Context};
use fastrack_lab::provenance::{machine_description, source_revision, utc_now_rfc3339};
use fastrack_valuefn::bundle::Bundle;
use fastrack_valuefn::composite::Composite;
use fastrack_valuefn::manifest::{Manifest, NetworkInfo, Provenance, SystemInfo, SCHEMA_VERSION};
use fastrack_valuefn::network::ValueNetwork;
use fastrack_valuefn::onnx_writer::{write_composite_graph, write_value_graph};
use fastrack_valuefn::runtime::{runtime, Evaluator, GraphDims};
use fastrack_valuefn::system::AffineSystem;
use fastrack_valuefn::teb::{teb_table, TebOptions};
use rand::{Rng, SeedableRng};
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

/// The value function a bundle serves.
pub enum ExportedModel<'a> {
    /// One network of the system, evaluated at `horizon` (s).
    Network {
        /// The network.
        network: &'a ValueNetwork,
        /// Horizon fixed in the graph (s).
        horizon: f64,
    },
    /// Axis networks of a decomposed system, each at its own horizon.
    Composite(&'a Composite),
}

impl ExportedModel<'_> {
    fn graph(&self, system: &AffineSystem) -> Vec<u8> {
        match self {
            Self::Network { network, horizon } => write_value_graph(network, system, *horizon),
            Self::Composite(composite) => write_composite_graph(composite),
        }
    }

    /// The manifest's horizon: the network's, or the longest of the axes'.
    fn horizon(&self) -> f64 {
        match self {
            Self::Network { horizon, .. } => *horizon,
            Self::Composite(composite) => composite.axes().iter().map(|a| a.tau).fold(0.0, f64::max),
        }
    }

    fn describe(&self) -> NetworkInfo {
        match self {
            Self::Network { network, .. } => NetworkInfo::describe(network),
            Self::Composite(composite) => NetworkInfo::describe_composite(composite),
        }
    }

    /// `(V, dV/dr, control)` in f64 at state `s` and parameters `p`; `served_grad` is what the graph answered,
    /// so that a single network's control is compared as the law of that gradient.
    fn reference(&self, system: &AffineSystem, s: &[f64], p: &[f64], served_grad: &[f64]) -> (f64, Vec<f64>, Vec<f64>) {
        match self {
            Self::Network { network, horizon } => {
                let e = network.evaluate(*horizon, s, p);
                (e.value, e.grad_state, system.optimal_control(s, served_grad))
            }
            Self::Composite(composite) => {
                let e = composite.evaluate(s, p);
                (e.value, e.grad, e.control)
            }
        }
    }
}

/// What to export.
pub struct ExportRequest<'a> {
    /// The value function.
    pub model: ExportedModel<'a>,
    /// Its system.
    pub system: &'a AffineSystem,
    /// Model name.
    pub name: &'a str,
    /// Model version.
    pub version: u32,
    /// Untrained (random) weights.
    pub untrained: bool,
    /// Training provenance.
    pub provenance: Provenance,
    /// TEB search effort.
    pub teb: TebOptions,
}

/// Largest relative difference between served and network values accepted on reload.
const RELOAD_TOLERANCE: f64 = 1e-4;

/// Largest difference between served and network `dV/dr` accepted on reload, relative to `max(|dV/dr|, 1)`.
const GRADIENT_TOLERANCE: f64 = 1e-3;

/// Writes `<root>/<name>/<version>/` and returns the folder.
pub fn export(root: &Path, request: ExportRequest<'_>) -> anyhow::Result<PathBuf> {
    let ExportRequest { ref model, system, .. } = request;
    let onnx = model.graph(system);
    let horizon = model.horizon();
    let dims = GraphDims::of_system(system);
    let rt = runtime(None)?;
    let evaluator = Evaluator::new(rt, &onnx, dims, 1).context("loading the written graph")?;
    let report = teb_table(&evaluator, system, &request.teb).map_err(anyhow::Error::msg)?;
    for (beta, measured, raised) in &report.non_monotone {
        tracing::warn!(beta, measured, raised_to = raised, "learned V_min not monotone in beta; level raised");
    }
    for (beta, level, at_rest) in &report.raised_to_rest {
        tracing::info!(beta, level, raised_to = at_rest, "level raised to hold the resting state");
    }
    let (state, planner_to_state, params, controls) = Manifest::describe_system(system);
    let manifest = Manifest {
        schema_version: SCHEMA_VERSION,
        name: request.name.into(),
        version: request.version,
        system: SystemInfo { id: system.id.into(), description: system.description.into() },
        state,
        planner_to_state,
        params,
        controls,
        horizon,
        network: model.describe(),
        teb_table: report.rows,
        untrained: request.untrained,
        provenance: request.provenance,
        onnx_sha256: String::new(),
    };
    let dir = Bundle::write(root, manifest, &onnx)?;
    check_reload(&dir, model, system, dims)?;
    Ok(dir)
}

/// Reloads the bundle through the loader and ONNX Runtime and compares served values with the model.
fn check_reload(dir: &Path, model: &ExportedModel<'_>, system: &AffineSystem, dims: GraphDims) -> anyhow::Result<()> {
    let bundle = Bundle::load(dir)?;
    let evaluator = Evaluator::new(runtime(None)?, &bundle.onnx, dims, 1)?;
    let mut rng = rand::rngs::StdRng::seed_from_u64(99);
    let n = 256;
    let states: Vec<f64> =
        (0..n).flat_map(|_| system.state.iter().map(|d| rng.random_range(d.min..d.max)).collect::<Vec<_>>()).collect();
    let params: Vec<f64> =
        (0..n).flat_map(|_| system.params.iter().map(|p| rng.random_range(p.min..p.max)).collect::<Vec<_>>()).collect();
    let to_f32 = |v: &[f64]| v.iter().map(|&x| x as f32).collect::<Vec<_>>();
    let served = evaluator.evaluate(&to_f32(&states), &to_f32(&params))?;
    let (ns, nc) = (dims.n_state, dims.n_control);
    let (mut worst, mut worst_gradient) = (0.0f64, 0.0f64);
    for i in 0..n {
        let s = &states[i * ns..(i + 1) * ns];
        let p = &params[i * dims.n_params..(i + 1) * dims.n_params];
        let grad: Vec<f64> = served.grad[i * ns..(i + 1) * ns].iter().map(|&g| f64::from(g)).collect();
        // f32 state and parameters, as the graph saw them, so the state limits compare alike.
        let s32: Vec<f64> = s.iter().map(|&x| f64::from(x as f32)).collect();
        let p32: Vec<f64> = p.iter().map(|&x| f64::from(x as f32)).collect();
        let (value, reference_grad, reference_control) = model.reference(system, &s32, &p32, &grad);
        worst = worst.max((f64::from(served.value[i]) - value).abs() / value.abs().max(1.0));
        let scale = reference_grad.iter().fold(1.0f64, |m, g| m.max(g.abs()));
        for (g, r) in grad.iter().zip(&reference_grad) {
            worst_gradient = worst_gradient.max((g - r).abs() / scale);
        }
        let control: Vec<f64> = served.control[i * nc..(i + 1) * nc].iter().map(|&u| f64::from(u)).collect();
        // The graph holds the control bounds in f32 (quad10d's pi/9 is not a float32).
        let expected: Vec<f64> = reference_control.iter().map(|&u| f64::from(u as f32)).collect();
        ensure!(
            control == expected,
            "served control {control:?} at state {s:?} is not the model's control law ({expected:?})"
        );
    }
    ensure!(worst < RELOAD_TOLERANCE, "served value differs from the model by {worst:e} (relative) after reload");
    ensure!(
        worst_gradient < GRADIENT_TOLERANCE,
        "served dV/dr differs from the model by {worst_gradient:e} (relative) after reload"
    );
    tracing::info!(
        bundle = %dir.display(),
        worst_relative_error = worst,
        worst_gradient_error = worst_gradient,
        "bundle reloaded and checked"
    );
    Ok(())
}

/// Provenance of a model made now, on this machine, from this source revision.
pub fn provenance_here_and_now(
    method: impl Into<String>,
    config: serde_json::Value,
    iterations: u64,
    final_losses: BTreeMap<String, f64>,
    wall_time_s: f64,
) -> Provenance {
    Provenance {
        method: method.into(),
        config,
        iterations,
        final_losses,
        wall_time_s,
        machine: machine_description(),
        source_revision: source_revision(),
        created: utc_now_rfc3339(),
    }
}
