#!/usr/bin/env bash
# Benchmarks, each printing tables and writing a record under bench/results/:
# - foundation: evaluator vs bare ONNX Runtime throughput, unary latency over loopback (foundation.{json,md});
# - serving: the load generator against the release server with and without dynamic batching, unary
#   TrackingControl batch 1 and 64 and Track ticks at concurrency 1-256, and the in-process ceiling
#   (serving.{json,md});
# - replicas: aggregate Track ticks/s over 1, 2 and 3 release servers, and how soon robots on a killed replica
#   are served again (replicas.{json,md}).
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup-onnxruntime.sh >/dev/null
cargo build --release -j2 --bins
cargo bench -j2 -p fastrack-e2e --bench foundation
cargo bench -j2 -p fastrack-e2e --bench serving
cargo bench -j2 -p fastrack-e2e --bench replicas
