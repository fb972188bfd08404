//! The `fastrack.v1` gRPC contract, generated from `proto/fastrack/v1/*.proto`, the planner-speed rules both
//! of its sides apply to a TEB table, and the contract's API reference.

#![warn(missing_docs)]

pub mod planner_speed;
pub mod reference;

/// Generated messages and stubs of package `fastrack.v1`.
pub mod v1 {
    #![allow(missing_docs, clippy::doc_lazy_continuation, clippy::large_enum_variant)]
    tonic::include_proto!("fastrack.v1");
}

/// Encoded `FileDescriptorSet` of the contract, for server reflection.
pub const FILE_DESCRIPTOR_SET: &[u8] = include_bytes!(concat!(env!("OUT_DIR"), "/fastrack_descriptor.bin"));

/// The API reference (markdown) the build generated from the contract; `docs/api-reference.md` holds a copy.
pub const API_REFERENCE: &str = include_str!(concat!(env!("OUT_DIR"), "/api-reference.md"));
