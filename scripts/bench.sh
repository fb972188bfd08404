#!/usr/bin/env bash
# Foundation benchmark: evaluator vs bare ONNX Runtime throughput, unary latency over loopback.
# Prints tables and writes bench/results/foundation.{json,md}.
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup-onnxruntime.sh >/dev/null
cargo build --release -j2 --bins
cargo bench -j2 -p fastrack-e2e --bench foundation
