//! Lab tooling of fastrack's offline work, kept out of the crates the server and a robot's client link.
//!
//! - [`record`]: measurement records under `bench/results/` and research notes.
//! - [`provenance`]: machine, revision and time stamps for bundles and records.
//! - [`shard`]: `--shard INDEX/COUNT` for batch work split among processes (Kubernetes Indexed Jobs).
//! - [`plot`]: PNG line charts.

#![warn(missing_docs)]

pub mod plot;
pub mod provenance;
pub mod record;
pub mod shard;
