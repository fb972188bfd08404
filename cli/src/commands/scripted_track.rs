//! `fastrack track`: a short scripted robot on a `Track` stream.

use anyhow::Context;
use fastrack_client::{model_ref, pb, FastrackClient};
use serde_json::json;

/// Arguments of `fastrack track`.
#[derive(clap::Args)]
pub struct Args {
    /// Model name.
    name: String,
    /// Number of ticks.
    #[arg(long, default_value_t = 40)]
    ticks: u32,
    /// Control period (s).
    #[arg(long, default_value_t = 0.1)]
    dt: f64,
}

/// The scripted robot: planner from the origin along +y at `beta_query` per axis, an obstacle disc at
/// (1.2, 2.5) of radius 0.3, the tracker stepped with the model system's dynamics (Euler steps).
pub async fn run(client: &FastrackClient, args: Args, json_mode: bool) -> anyhow::Result<()> {
    let info = client.get_model(model_ref(&args.name, 0)).await?;
    let system = fastrack_valuefn::system::by_id(&info.system)
        .with_context(|| format!("no dynamics known for system {:?}", info.system))?;
    anyhow::ensure!(
        system.planner_dim() == 2 && system.n_state() == 4,
        "the scripted robot drives 2-D planners with 4-D trackers (dubins4d)"
    );
    let (obstacle, obstacle_radius): ([f64; 2], f64) = ([1.2, 2.5], 0.3);
    let mut tracker: Vec<f64> = vec![0.0, 0.0, 0.0, 1.0];
    let mut planner = vec![0.0, 0.0];
    let mut stream = client.track(model_ref(&args.name, 0), 10.0).await?;
    let mut rows = Vec::new();
    if !json_mode {
        println!("  t      beta   dTEB    |e|     V       in_teb  in_domain  omega   alpha");
    }
    for seq in 0..u64::from(args.ticks) {
        let d_obs = ((tracker[0] - obstacle[0]).hypot(tracker[1] - obstacle[1]) - obstacle_radius).max(0.0);
        let reply = stream
            .tick(pb::TrackTick {
                seq,
                tracker_state: tracker.clone(),
                planner_state: planner.clone(),
                d_obs: Some(d_obs),
                planner_clearance: None,
            })
            .await?;
        if let Some(error) = &reply.error {
            anyhow::bail!("tick {seq} rejected ({}): {}", error.code, error.message);
        }
        let error = reply.relative_state[0].hypot(reply.relative_state[1]);
        let t = seq as f64 * args.dt;
        if json_mode {
            rows.push(json!({"t": t, "beta_query": reply.beta_query, "dteb_radius": reply.dteb_radius, "error": error,
                "value": reply.value, "in_teb": reply.in_teb, "in_domain": reply.in_domain, "control": reply.control}));
        } else {
            println!(
                "  {t:<5.2}  {:<5.3}  {:<6.3}  {error:<6.3}  {:<6.3}  {:<6}  {:<9}  {:<6.2}  {:.2}",
                reply.beta_query,
                reply.dteb_radius,
                reply.value,
                reply.in_teb,
                reply.in_domain,
                reply.control[0],
                reply.control[1]
            );
        }
        let mut rate = vec![0.0; 4];
        system.dynamics(&tracker, &reply.control, &[0.0, 0.0], &[], &mut rate);
        // The tracker's own motion is the relative dynamics with a resting planner.
        for (s, r) in tracker.iter_mut().zip(&rate) {
            *s += args.dt * r;
        }
        planner[1] += args.dt * reply.beta_query;
    }
    if json_mode {
        println!("{}", serde_json::to_string_pretty(&rows)?);
    }
    Ok(())
}
