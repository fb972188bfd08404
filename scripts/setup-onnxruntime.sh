#!/usr/bin/env bash
# Installs the ONNX Runtime shared library the project loads (ort `load-dynamic`) into .cache/onnxruntime,
# from the PyPI wheel onnxruntime==1.31.1 (no other download host is needed). Idempotent and quiet when the
# library is already there. Prints the library path.
set -euo pipefail
root=$(cd "$(dirname "$0")/.." && pwd)
version=1.31.1
target="$root/.cache/onnxruntime"
lib=$(find "$target" -name "libonnxruntime.so.$version" 2>/dev/null | head -n 1 || true)
if [[ -z "$lib" ]]; then
  echo "installing onnxruntime==$version (PyPI wheel) into $target" >&2
  rm -rf "$target"
  python3 -m pip install --quiet --disable-pip-version-check --root-user-action=ignore --no-deps --target "$target" "onnxruntime==$version" >&2
  lib=$(find "$target" -name "libonnxruntime.so.$version" | head -n 1)
  [[ -n "$lib" ]] || { echo "the onnxruntime wheel holds no libonnxruntime.so.$version" >&2; exit 1; }
fi
echo "$lib"
