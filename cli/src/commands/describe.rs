//! `fastrack models` and `fastrack model`: what the server has loaded, and one model's description.

use super::print;
use fastrack_client::{model_ref, pb, FastrackClient};
use serde_json::{json, Value};

/// Arguments of `fastrack model`.
#[derive(clap::Args)]
pub struct ModelArgs {
    /// Model name.
    name: String,
    /// Version (0 = the default: the pinned version, else the latest).
    #[arg(long, default_value_t = 0)]
    version: u32,
}

/// Lists the loaded model versions (`*` marks each model's default version).
pub async fn models(client: &FastrackClient, json_mode: bool) -> anyhow::Result<()> {
    let models = client.list_models().await?;
    print(json_mode, Value::Array(models.iter().map(model_json).collect()), || {
        models
            .iter()
            .map(|m| {
                format!(
                    "{}/{}{}  {}{}",
                    m.name,
                    m.version,
                    if m.is_default_version { "*" } else { " " },
                    m.system,
                    if m.untrained { "  UNTRAINED" } else { "" }
                )
            })
            .collect::<Vec<_>>()
            .join("\n")
    });
    Ok(())
}

/// Describes one model version: domain, parameters, controls, TEB table.
pub async fn model(client: &FastrackClient, args: ModelArgs, json_mode: bool) -> anyhow::Result<()> {
    let m = client.get_model(model_ref(&args.name, args.version)).await?;
    print(json_mode, model_json(&m), || model_text(&m));
    Ok(())
}

fn model_json(m: &pb::ModelInfo) -> Value {
    json!({
        "name": m.name, "version": m.version, "system": m.system, "description": m.description,
        "untrained": m.untrained, "default_version": m.is_default_version, "horizon": m.horizon,
        "state": m.state.iter().map(|d| json!({"name": d.name, "unit": d.unit,
            "min": d.bounds.map(|b| b.min), "max": d.bounds.map(|b| b.max), "periodic": d.periodic,
            "error_coordinate": d.error_coordinate,
            "limits": d.limits.map(|l| [l.min, l.max])})).collect::<Vec<_>>(),
        "params": m.params.iter().map(|p| json!({"name": p.name, "unit": p.unit,
            "min": p.range.map(|r| r.min), "max": p.range.map(|r| r.max)})).collect::<Vec<_>>(),
        "controls": m.controls.iter().map(|c| json!({"name": c.name, "unit": c.unit,
            "min": c.bounds.map(|b| b.min), "max": c.bounds.map(|b| b.max)})).collect::<Vec<_>>(),
        "teb_table": m.teb_table.iter().map(|r| json!({"beta": r.beta, "set_level": r.set_level, "bound": r.bound,
            "learned_level": r.learned_level, "verified_level": r.verified_level, "extent": r.extent,
            "nested_share": r.nested_share, "reference_bound": r.reference_bound,
            "reference_source": r.reference_source, "bound_source": r.bound_source,
            "verification": r.verification.as_ref().map(verification_json)})).collect::<Vec<_>>(),
        "onnx_sha256": m.onnx_sha256,
    })
}

fn model_text(m: &pb::ModelInfo) -> String {
    let mut out = format!(
        "{}/{}{} — system {}{}\n  {}\n  horizon {} s\n  state:",
        m.name,
        m.version,
        if m.is_default_version { " (default)" } else { "" },
        m.system,
        if m.untrained { " — UNTRAINED (random weights, bounds meaningless)" } else { "" },
        m.description,
        m.horizon
    );
    for d in &m.state {
        let b = d.bounds.unwrap_or_default();
        out += &format!(
            "\n    {:<8} [{}, {}] {}{}{}",
            d.name,
            b.min,
            b.max,
            d.unit,
            if d.periodic { " periodic" } else { "" },
            d.limits.map_or(String::new(), |l| format!(", control held within [{}, {}]", l.min, l.max))
        );
    }
    out += "\n  params:";
    for p in &m.params {
        let r = p.range.unwrap_or_default();
        out += &format!("\n    {:<8} [{}, {}] {}", p.name, r.min, r.max, p.unit);
    }
    out += "\n  TEB table (set level: membership, V <= it; bound: the error from inside that set):";
    out += "\n  (in next: share of the set inside the next row's, 1 where they nest; reference: the ground truth,";
    out += "\n  set by: what the bound is)";
    out += "\n    beta      set lvl  bound    learned  verified  reference  set by        in next  evidence";
    for r in &m.teb_table {
        let verified = r.verified_level.map_or("-".to_string(), |v| format!("{v:.4}"));
        let reference = r.reference_bound.map_or("-".to_string(), |v| format!("{v:.4}"));
        let nested = r.nested_share.map_or("-".to_string(), |s| format!("{s:.3}"));
        let evidence = r.verification.as_ref().map_or(String::new(), verification_text);
        out += &format!(
            "\n    {:<8.4}  {:<7.4}  {:<7.4}  {:<7.4}  {verified:<8}  {reference:<9}  {:<12}  {nested:<7}  {evidence}",
            r.beta, r.set_level, r.bound, r.learned_level, r.bound_source
        );
    }
    let sources: Vec<String> = m
        .teb_table
        .iter()
        .filter(|r| !r.reference_source.is_empty())
        .map(|r| format!("\n    beta {:.4}: {}", r.beta, r.reference_source))
        .collect();
    if !sources.is_empty() {
        out += "\n  references:";
        out += &sources.concat();
    }
    out
}

fn verification_json(v: &pb::Verification) -> Value {
    json!({"eps": v.eps, "delta": v.delta, "samples": v.samples, "violations": v.violations, "rounds": v.rounds,
        "sampled_level": v.sampled_level, "correction": v.correction, "horizon": v.horizon, "step": v.step,
        "planners": v.planners.iter().map(|p| json!({"family": p.family, "rollouts": p.rollouts,
            "max_error": p.max_error})).collect::<Vec<_>>(),
        "checks": v.checks.iter().map(|c| json!({"distribution": c.distribution, "samples": c.samples,
            "violations": c.violations, "max_error": c.max_error})).collect::<Vec<_>>()})
}

/// `eps 0.001, delta 1e-6, N 13809, 0 violations, 2 rounds (set), 10 s; hardest model-worst-case`, then where
/// they were recorded `; checks <distribution> <samples>/<violations>/<largest error>, ...`.
fn verification_text(v: &pb::Verification) -> String {
    let hardest = v.planners.iter().max_by(|a, b| a.max_error.total_cmp(&b.max_error));
    let checks: Vec<String> = v
        .checks
        .iter()
        .map(|c| format!("{} {}/{}/{:.4}", c.distribution, c.samples, c.violations, c.max_error))
        .collect();
    format!(
        "eps {}, delta {}, N {}, {} violations, {} rounds{}, {} s{}{}",
        v.eps,
        v.delta,
        v.samples,
        v.violations,
        v.rounds,
        if v.correction.is_empty() { String::new() } else { format!(" ({})", v.correction) },
        v.horizon,
        hardest.map_or(String::new(), |p| format!("; hardest {}", p.family)),
        if checks.is_empty() { String::new() } else { format!("; checks {}", checks.join(", ")) }
    )
}
