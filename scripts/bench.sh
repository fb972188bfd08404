#!/usr/bin/env bash
# Benchmarks, each printing tables and writing a record under bench/results/:
# - foundation: evaluator vs bare ONNX Runtime throughput, unary latency over loopback (foundation.{json,md});
# - serving: the load generator against the release server with and without dynamic batching, unary
#   TrackingControl batch 1 and 64 and Track ticks at concurrency 1-256, and the in-process ceiling
#   (serving.{json,md});
# - replicas: aggregate Track ticks/s over 1, 2 and 3 release servers, and how soon robots on a killed replica
#   are served again (replicas.{json,md});
# - soak: 30 minutes of 100 Track streams and unary load with a reload a minute and robots killed every 5 s:
#   memory, open streams, p99 and errors per minute (soak.{json,md}, soak-memory.png, soak-latency.png);
# - the fuzz targets' long run: 100,000 requests per RPC, 20,000 bundles, 50,000 world files and training
#   configs (fuzz-long.{json,md}, a section per target written once its cases passed).
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup-onnxruntime.sh >/dev/null
cargo build --release -j2 --bins
cargo bench -j2 -p fastrack-e2e --bench foundation
cargo bench -j2 -p fastrack-e2e --bench serving
cargo bench -j2 -p fastrack-e2e --bench replicas
cargo bench -j2 -p fastrack-e2e --bench soak
FASTRACK_FUZZ_RECORD=fuzz-long FASTRACK_FUZZ_CASES=100000 cargo test -j2 -p fastrack-e2e --test fuzzed_requests
FASTRACK_FUZZ_RECORD=fuzz-long FASTRACK_FUZZ_CASES=20000 cargo test -j2 -p fastrack-e2e --test fuzzed_bundles
FASTRACK_FUZZ_RECORD=fuzz-long FASTRACK_FUZZ_CASES=50000 cargo test -j2 -p fastrack-e2e --test fuzzed_files
