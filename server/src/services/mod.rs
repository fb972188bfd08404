//! gRPC service implementations.

pub mod admin;
pub mod models;
pub mod safety;
pub mod track;
