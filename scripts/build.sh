#!/usr/bin/env bash
# The one build the demo and the test suite share: every target of every crate (binaries, libraries, tests,
# benches) in the dev profile, linted by clippy as it compiles (warnings are errors). Whichever command runs
# first compiles; the other finds everything built. Installs the ONNX Runtime library and the docs' tools.
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup-onnxruntime.sh >/dev/null
bash scripts/setup-tools.sh >/dev/null
source scripts/cargo-env.sh
cargo build --workspace --all-targets
