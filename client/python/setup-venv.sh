#!/usr/bin/env bash
# Creates or updates the Python client's virtual environment at .cache/python/venv: an editable install of
# client/python with its test and ROS 2 extras (PyPI only). The stubs of fastrack.v1 are generated from
# proto/ by the install (setup.py). Idempotent and quiet when nothing changed. Prints the venv path.
set -euo pipefail
root=$(cd "$(dirname "$0")/../.." && pwd)
here="$root/client/python"
venv="$root/.cache/python/venv"
stamp="$venv/.fastrack-client-stamp"
want=$(cat "$here/pyproject.toml" "$here/setup.py" "$here/setup-venv.sh" "$root"/proto/fastrack/v1/*.proto | sha256sum | cut -d' ' -f1)
generated=("$here"/src/fastrack/v1/{models,safety}_pb2{,_grpc}.py)
up_to_date=true
[[ -x "$venv/bin/python" && -f "$stamp" && "$(cat "$stamp")" == "$want" ]] || up_to_date=false
for file in "${generated[@]}"; do [[ -f "$file" ]] || up_to_date=false; done
if [[ "$up_to_date" == false ]]; then
  echo "installing the Python client (fastrack-client, editable, extras test and ros) into $venv" >&2
  [[ -x "$venv/bin/python" ]] || python3 -m venv "$venv"
  rm -f "$stamp"
  "$venv/bin/python" -m pip install --quiet --disable-pip-version-check --root-user-action=ignore \
    -e "$here[test,ros]" >&2
  echo "$want" > "$stamp"
fi
echo "$venv"
