#!/usr/bin/env bash
# The whole test suite, as CI runs it: formatting, then the shared build (which lints every crate with
# clippy, warnings denied), then every crate's tests, the end-to-end tests against the real server binary
# and the docs' commands.
set -euo pipefail
cd "$(dirname "$0")/.."
cargo fmt --all -- --check
bash scripts/build.sh
source scripts/cargo-env.sh
cargo test --workspace
