//! Compiles `fastrack/v1/*.proto` with protox (no system protoc), writes the descriptor set that the
//! server's reflection service publishes, and the API reference generated from it.
use prost::Message;
use std::path::PathBuf;

#[path = "src/reference.rs"]
mod reference;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let files = ["fastrack/v1/models.proto", "fastrack/v1/safety.proto"];
    for file in files {
        println!("cargo:rerun-if-changed={file}");
    }
    println!("cargo:rerun-if-changed=src/reference.rs");
    let fds = protox::compile(files, ["."])?;
    let out_dir = PathBuf::from(std::env::var("OUT_DIR")?);
    std::fs::write(out_dir.join("fastrack_descriptor.bin"), fds.encode_to_vec())?;
    let (markdown, _) = reference::api_reference(&fds, "fastrack.v1");
    std::fs::write(out_dir.join("api-reference.md"), markdown)?;
    tonic_prost_build::configure().compile_fds(fds)?;
    Ok(())
}
