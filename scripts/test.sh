#!/usr/bin/env bash
# The whole test suite, as CI runs it: formatting, lints, every crate's tests and the end-to-end tests
# against the real server binary. Installs the ONNX Runtime library into .cache/ first if needed.
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup-onnxruntime.sh >/dev/null
cargo fmt --all -- --check
cargo clippy -j2 --workspace --all-targets -- -D warnings
# The end-to-end tests start target/debug/fastrack-server: build every binary first.
cargo build -j2 --workspace --bins
cargo test -j2 --workspace
