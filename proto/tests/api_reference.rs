//! The API reference cannot drift from the contract: `docs/api-reference.md` must equal what the build
//! generates from the descriptors, and every service, method, message, field, enum and enum value of
//! `fastrack.v1` must carry a comment.

use fastrack_proto::reference::api_reference;
use fastrack_proto::{API_REFERENCE, FILE_DESCRIPTOR_SET};
use prost::Message;
use prost_types::FileDescriptorSet;
use std::path::PathBuf;

fn descriptors() -> FileDescriptorSet {
    FileDescriptorSet::decode(FILE_DESCRIPTOR_SET).expect("the build's descriptor set decodes")
}

#[test]
fn docs_hold_the_generated_reference() {
    let path = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../docs/api-reference.md");
    if std::env::var_os("FASTRACK_WRITE_API_REFERENCE").is_some() {
        std::fs::write(&path, API_REFERENCE).expect("docs/api-reference.md is writable");
    }
    let committed = std::fs::read_to_string(&path).unwrap_or_default();
    assert!(
        committed == API_REFERENCE,
        "docs/api-reference.md differs from the reference generated from proto/; rewrite it with \
         `FASTRACK_WRITE_API_REFERENCE=1 cargo test --workspace --test api_reference`"
    );
    // The reference in the crate is the one the descriptors give.
    assert_eq!(api_reference(&descriptors(), "fastrack.v1").0, API_REFERENCE);
}

#[test]
fn every_item_of_the_contract_is_documented() {
    let (reference, undocumented) = api_reference(&descriptors(), "fastrack.v1");
    assert!(undocumented.is_empty(), "items without a comment in proto/: {undocumented:?}");
    for item in ["Service `SafetyService`", "| `Track` | stream ", "### `TrackTick`", "OUT_OF_DOMAIN_POLICY_FLAG"] {
        assert!(reference.contains(item), "the reference lacks {item}");
    }
}

#[test]
fn a_field_without_a_comment_is_named() {
    let mut set = descriptors();
    let safety = set.file.iter_mut().find(|f| f.name() == "fastrack/v1/safety.proto").expect("safety.proto");
    let tick = safety.message_type.iter().position(|m| m.name() == "TrackTick").expect("TrackTick") as i32;
    let info = safety.source_code_info.as_mut().expect("source comments are compiled in");
    // Field 0 of message `tick` in the file: path [4, tick, 2, 0].
    info.location.retain(|l| l.path != [4, tick, 2, 0]);
    let (reference, undocumented) = api_reference(&set, "fastrack.v1");
    assert_eq!(undocumented, ["fastrack.v1.TrackTick.seq"]);
    assert!(reference.contains("| `seq` | 1 | `uint64` | (undocumented) |"), "{reference}");
}
