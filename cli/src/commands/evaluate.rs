//! `fastrack evaluate` and `fastrack control`: batches of relative states through `EvaluateValue` or
//! `TrackingControl`.

use super::print;
use fastrack_client::{model_ref, pb, FastrackClient};
use serde_json::json;

/// Arguments of `evaluate` and `control`.
#[derive(clap::Args)]
pub struct Args {
    /// Model name.
    name: String,
    /// A relative state, comma separated; repeat for a batch.
    #[arg(long = "state", value_delimiter = ',', num_args = 1, action = clap::ArgAction::Append, required = true, allow_hyphen_values = true)]
    states: Vec<f64>,
    /// Parameters of every item, comma separated (default: every parameter = --beta).
    #[arg(long, value_delimiter = ',')]
    params: Option<Vec<f64>>,
    /// Shorthand: every parameter of every item equal to this beta.
    #[arg(long)]
    beta: Option<f64>,
    /// Evaluate states outside the trained domain, flagged, instead of rejecting them.
    #[arg(long)]
    allow_out_of_domain: bool,
    /// Version (0 = the default: the pinned version, else the latest).
    #[arg(long, default_value_t = 0)]
    version: u32,
}

/// What to ask for and print.
#[derive(Clone, Copy)]
pub enum Output {
    /// `EvaluateValue`: `V`, `dV/dr` and `u*`.
    Full,
    /// `TrackingControl`: `u*` and `V`.
    Control,
}

/// Evaluates the batch and prints one line per state.
pub async fn run(client: &FastrackClient, args: Args, output: Output, json_mode: bool) -> anyhow::Result<()> {
    let info = client.get_model(model_ref(&args.name, args.version)).await?;
    let (ns, np, nc) = (info.state.len(), info.params.len(), info.controls.len());
    anyhow::ensure!(args.states.len().is_multiple_of(ns), "each --state needs {ns} numbers");
    let n = args.states.len() / ns;
    let params = match (args.params, args.beta) {
        (Some(p), _) => p.iter().copied().cycle().take(n * p.len().max(1)).collect::<Vec<_>>(),
        (None, Some(beta)) => vec![beta; n * np],
        (None, None) => anyhow::bail!("give --params or --beta"),
    };
    let policy = if args.allow_out_of_domain { pb::OutOfDomainPolicy::Flag } else { pb::OutOfDomainPolicy::Reject };
    let model = model_ref(&args.name, args.version);
    let state = |i: usize| &args.states[i * ns..(i + 1) * ns];
    match output {
        Output::Control => {
            let r = client.tracking_control(model, args.states.clone(), params, policy).await?;
            print(
                json_mode,
                json!({"controls": r.controls, "values": r.values, "in_teb": r.in_teb, "in_domain": r.in_domain, "model_version": r.model_version}),
                || {
                    (0..n)
                        .map(|i| {
                            format!(
                                "state {:?}: u* = {:?}  V = {:.4}  in_teb = {}  in_domain = {}",
                                state(i),
                                &r.controls[i * nc..(i + 1) * nc],
                                r.values[i],
                                r.in_teb[i],
                                r.in_domain[i]
                            )
                        })
                        .collect::<Vec<_>>()
                        .join("\n")
                },
            );
        }
        Output::Full => {
            let r = client.evaluate_value(model, args.states.clone(), params, policy).await?;
            print(
                json_mode,
                json!({"values": r.values, "gradients": r.gradients, "controls": r.controls, "in_teb": r.in_teb, "in_domain": r.in_domain, "model_version": r.model_version}),
                || {
                    (0..n)
                        .map(|i| {
                            format!(
                                "state {:?}: V = {:.4}  dV/dr = {:?}  u* = {:?}  in_teb = {}  in_domain = {}",
                                state(i),
                                r.values[i],
                                &r.gradients[i * ns..(i + 1) * ns],
                                &r.controls[i * nc..(i + 1) * nc],
                                r.in_teb[i],
                                r.in_domain[i]
                            )
                        })
                        .collect::<Vec<_>>()
                        .join("\n")
                },
            );
        }
    }
    Ok(())
}
