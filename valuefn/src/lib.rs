//! Value-function models shared by every fastrack crate.
//!
//! - [`system`]: control- and planner-affine relative systems (`dubins4d`, the double integrator, `quad10d` and its axes).
//! - [`network`]: the SIREN value network and its f64 reference evaluation.
//! - [`composite`]: axis networks of a decomposed system (quad10d) combined into one value function.
//! - [`manifest`], [`bundle`]: the model bundle format and repository layout.
//! - [`teb`]: TEB tables from a value function (`V_min` per `beta`, extent, boundary).
//! - [`simulation`]: RK4 with held inputs and the planner models every rollout shares.
//! - `onnx_writer` (feature `writer`): the network plus control law as an ONNX graph.
//! - `runtime` (feature `runtime`): ONNX Runtime loading and a pooled batch evaluator.

#![warn(missing_docs)]

pub mod bundle;
pub mod composite;
pub mod manifest;
pub mod network;
pub mod simulation;
pub mod system;
pub mod teb;

#[cfg(feature = "writer")]
pub mod onnx_writer;
#[cfg(feature = "runtime")]
pub mod runtime;
