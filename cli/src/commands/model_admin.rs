//! `fastrack load-model`, `unload-model` and `reload-model`: the admin surface (`ModelAdminService`).

use super::print;
use fastrack_client::FastrackClient;
use serde_json::{json, Value};

/// Arguments of `load-model` and `unload-model`.
#[derive(clap::Args)]
pub struct VersionArgs {
    /// Model name.
    name: String,
    /// Version (0 = every version: on disk for load-model, loaded for unload-model).
    #[arg(long, default_value_t = 0)]
    version: u32,
}

/// Arguments of `reload-model`.
#[derive(clap::Args)]
pub struct ReloadArgs {
    /// Model name (omit to re-read the whole repository).
    name: Option<String>,
}

/// Loads a model (or one version of it) from the server's repository.
pub async fn load(client: &FastrackClient, args: VersionArgs, json_mode: bool) -> anyhow::Result<()> {
    let v = client.load_model(&args.name, args.version).await?;
    print(json_mode, json!({"loaded_versions": v}), || format!("{}: loaded versions {v:?}", args.name));
    Ok(())
}

/// Stops serving a model (or one version of it).
pub async fn unload(client: &FastrackClient, args: VersionArgs, json_mode: bool) -> anyhow::Result<()> {
    let v = client.unload_model(&args.name, args.version).await?;
    print(json_mode, json!({"unloaded_versions": v}), || format!("{}: unloaded versions {v:?}", args.name));
    Ok(())
}

/// Re-reads a model, or the whole repository, from disk; prints each version's outcome.
pub async fn reload(client: &FastrackClient, args: ReloadArgs, json_mode: bool) -> anyhow::Result<()> {
    let outcomes = client.reload_model(args.name.as_deref().unwrap_or_default()).await?;
    print(
        json_mode,
        Value::Array(
            outcomes
                .iter()
                .map(|o| json!({"name": o.name, "version": o.version, "loaded": o.loaded, "error": o.error}))
                .collect(),
        ),
        || {
            outcomes
                .iter()
                .map(|o| {
                    format!(
                        "{}/{}: {}",
                        o.name,
                        o.version,
                        if o.loaded { "loaded".to_string() } else { format!("rejected: {}", o.error) }
                    )
                })
                .collect::<Vec<_>>()
                .join("\n")
        },
    );
    Ok(())
}
