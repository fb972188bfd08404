//! Compiles the vendored ONNX schema (`proto/onnx/onnx.proto`, Apache-2.0, from the onnx project) into
//! Rust message types with protox, when the `writer` feature is on.

fn main() -> Result<(), Box<dyn std::error::Error>> {
    println!("cargo:rerun-if-changed=proto/onnx/onnx.proto");
    #[cfg(feature = "writer")]
    {
        let fds = protox::compile(["onnx/onnx.proto"], ["proto"])?;
        prost_build::Config::new().compile_fds(fds)?;
    }
    Ok(())
}
