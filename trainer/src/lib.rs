//! The offline half of Parametric FaSTrack: DeepReach training of parametric value functions (burn) and
//! their export as served, validated model bundles.

#![warn(missing_docs)]

pub mod allocator;
pub mod causal;
pub mod config;
pub mod dynamics;
pub mod export;
pub mod features;
pub mod objective;
pub mod report;
pub mod sampler;
pub mod sincos;
pub mod siren;
pub mod step_bench;
pub mod supervision;
pub mod train;
