#!/usr/bin/env bash
# The supply-chain check of the Rust dependency graph: cargo-deny's licenses, bans and sources checks
# against deny.toml (advisories need the RustSec database from GitHub, which these machines cannot reach).
# Installs cargo-deny 0.20.2 from crates.io into .cache/cargo-deny when missing (a few minutes, once).
#   bash scripts/deny.sh              check the workspace
#   bash scripts/deny.sh --self-test  check that the policy refuses a crate under a license it does not allow
set -euo pipefail
root=$(cd "$(dirname "$0")/.." && pwd)
version=0.20.2
tool="$root/.cache/cargo-deny/bin/cargo-deny"
if [[ ! -x "$tool" || "$("$tool" --version)" != "cargo-deny $version" ]]; then
  echo "installing cargo-deny $version into $root/.cache/cargo-deny" >&2
  cargo install --quiet --locked --version "$version" --root "$root/.cache/cargo-deny" -j2 cargo-deny >&2
fi
case "${1:-}" in
  "")
    "$tool" --manifest-path "$root/Cargo.toml" --config "$root/deny.toml" check licenses bans sources
    ;;
  --self-test)
    scratch=$(mktemp -d)
    trap 'rm -rf "$scratch"' EXIT
    mkdir -p "$scratch/app/src" "$scratch/copyleft/src"
    printf '[package]\nname = "copyleft"\nversion = "0.1.0"\nedition = "2021"\nlicense = "GPL-3.0-only"\n' \
      >"$scratch/copyleft/Cargo.toml"
    printf '[package]\nname = "app"\nversion = "0.1.0"\nedition = "2021"\nlicense = "MIT"\npublish = false\n\n[dependencies]\ncopyleft = { path = "../copyleft", version = "0.1.0" }\n' \
      >"$scratch/app/Cargo.toml"
    touch "$scratch/app/src/lib.rs" "$scratch/copyleft/src/lib.rs"
    if "$tool" --manifest-path "$scratch/app/Cargo.toml" --config "$root/deny.toml" check licenses \
      >"$scratch/out" 2>&1; then
      echo "deny.sh --self-test: a GPL-3.0-only dependency was accepted" >&2
      exit 1
    elif ! grep -q "GPL-3.0-only" "$scratch/out"; then
      echo "deny.sh --self-test: the refusal does not name GPL-3.0-only:" >&2
      cat "$scratch/out" >&2
      exit 1
    fi
    echo "deny.sh --self-test: a GPL-3.0-only dependency is refused"
    ;;
  *)
    echo "usage: bash scripts/deny.sh [--self-test]" >&2
    exit 2
    ;;
esac
