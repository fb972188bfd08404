//! `streaming-robot ENDPOINT MODEL STREAMS`: opens STREAMS Track streams and ticks on each every 20 ms
//! until killed. The end-to-end tests kill it to play a robot that vanishes mid-stream.

use anyhow::Context;
use fastrack_client::{model_ref, ClientOptions, FastrackClient};
use fastrack_e2e::robot_tick;
use std::time::Duration;

#[tokio::main(flavor = "multi_thread", worker_threads = 1)]
async fn main() -> anyhow::Result<()> {
    let args: Vec<String> = std::env::args().collect();
    let [_, endpoint, model, streams] = args.as_slice() else {
        anyhow::bail!("usage: streaming-robot ENDPOINT MODEL STREAMS");
    };
    let streams: u64 = streams.parse().context("STREAMS must be a count")?;
    let client = FastrackClient::connect(endpoint, ClientOptions::default()).await?;
    let mut tasks = Vec::new();
    for robot in 0..streams {
        let mut stream = client.track(model_ref(model, 0), 0.0).await?;
        tasks.push(tokio::spawn(async move {
            for seq in 0.. {
                stream.tick(robot_tick(seq, robot)).await?;
                tokio::time::sleep(Duration::from_millis(20)).await;
            }
            Ok::<(), fastrack_client::ClientError>(())
        }));
    }
    for task in tasks {
        task.await??;
    }
    Ok(())
}
