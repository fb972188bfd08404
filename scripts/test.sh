#!/usr/bin/env bash
# The whole test suite, as CI runs it: formatting, then the shared build (which lints every crate with
# clippy, warnings denied), then every crate's tests, the end-to-end tests against the real server binary
# and the docs' commands; then the Python client's tests (its virtual environment made from PyPI, the real
# server binary started by the tests), the deployment files' validators and the dependency policy
# (cargo-deny: licenses, bans, sources).
set -euo pipefail
cd "$(dirname "$0")/.."
cargo fmt --all -- --check
bash scripts/build.sh
source scripts/cargo-env.sh
cargo test --workspace
venv=$(bash client/python/setup-venv.sh)
"$venv/bin/python" -m pytest client/python/tests -q
bash deploy/validate.sh
bash deploy/validate.sh --self-test
bash scripts/deny.sh
bash scripts/deny.sh --self-test
