//! Manifest to wire types.

use fastrack_proto::v1 as pb;
use fastrack_valuefn::manifest::Manifest;
use fastrack_valuefn::system::StateSpace;

/// The `ModelInfo` describing a manifest and the state space built from it (`is_default_version` is filled
/// in by the repository).
pub fn model_info(m: &Manifest, space: &StateSpace) -> pb::ModelInfo {
    let interval = |min: f64, max: f64| Some(pb::Interval { min, max });
    pb::ModelInfo {
        name: m.name.clone(),
        version: m.version,
        system: m.system.id.clone(),
        description: m.system.description.clone(),
        state: m
            .state
            .iter()
            .map(|d| pb::StateDimension {
                name: d.name.clone(),
                unit: d.unit.clone(),
                bounds: interval(d.min, d.max),
                periodic: d.periodic,
                error_coordinate: d.error_coordinate,
                limits: d.limits.map(|[low, high]| pb::Interval { min: low, max: high }),
            })
            .collect(),
        params: m
            .params
            .iter()
            .map(|p| pb::ParameterDimension {
                name: p.name.clone(),
                unit: p.unit.clone(),
                range: interval(p.min, p.max),
            })
            .collect(),
        controls: m
            .controls
            .iter()
            .map(|c| pb::ControlDimension {
                name: c.name.clone(),
                unit: c.unit.clone(),
                bounds: interval(c.min, c.max),
            })
            .collect(),
        planner_to_state: m.planner_to_state.iter().flatten().copied().collect(),
        planner_dim: space.planner_dim() as u32,
        horizon: m.horizon,
        teb_table: m
            .teb_table
            .iter()
            .map(|row| pb::TebRow {
                beta: row.beta,
                bound: row.bound(),
                set_level: row.set_level(),
                learned_level: row.level,
                verified_level: row.verification.as_ref().map(|v| v.verified_level),
                extent: row.extent.clone(),
                verification: row.verification.as_ref().map(verification),
                nested_share: row.nested_share,
                reference_bound: row.reference.as_ref().map(|r| r.bound),
                reference_source: row.reference.as_ref().map_or_else(String::new, |r| r.source.clone()),
                bound_source: row.bound_source().name().into(),
            })
            .collect(),
        untrained: m.untrained,
        onnx_sha256: m.onnx_sha256.clone(),
        manifest_json: m.to_json(),
        is_default_version: false,
    }
}

fn verification(v: &fastrack_valuefn::manifest::Verification) -> pb::Verification {
    pb::Verification {
        verified_level: v.verified_level,
        eps: v.eps,
        delta: v.delta,
        samples: v.samples as u64,
        violations: v.violations as u64,
        rounds: v.rounds as u32,
        sampled_level: v.sampled_level,
        correction: v.correction.clone().unwrap_or_default(),
        horizon: v.horizon,
        step: v.step,
        planners: v
            .planners
            .iter()
            .map(|p| pb::PlannerResult {
                family: p.family.clone(),
                rollouts: p.rollouts as u64,
                max_error: p.max_error,
            })
            .collect(),
        checks: v
            .checks
            .iter()
            .map(|c| pb::VerificationCheck {
                distribution: c.distribution.clone(),
                samples: c.samples as u64,
                violations: c.violations as u64,
                max_error: c.max_error,
            })
            .collect(),
    }
}
