#!/usr/bin/env bash
# The main job: starts the server on the shipped model repository (models/) and drives it with a short
# scripted client run through the `fastrack` CLI (every RPC, a Track stream, a short load run), shows
# the Prometheus metrics, then shuts the server down gracefully.
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/build.sh
port=${FASTRACK_DEMO_PORT:-50151}
export FASTRACK_SERVER="http://127.0.0.1:$port"
metrics_port=${FASTRACK_DEMO_METRICS_PORT:-50152}
./target/debug/fastrack-server --listen "127.0.0.1:$port" --models models --metrics-listen "127.0.0.1:$metrics_port" &
server=$!
trap 'kill $server 2>/dev/null || true' EXIT
./target/debug/fastrack health --wait-s 30 >/dev/null
fastrack() { echo; echo "\$ fastrack $*"; ./target/debug/fastrack "$@"; }
model=${FASTRACK_DEMO_MODEL:-dubins4d}   # the trained model; untrained-dubins4d is the seeded stand-in
fastrack health
fastrack models
fastrack model "$model"
fastrack query "$model"
fastrack query "$model" --d-obs 0.5
fastrack teb "$model" --beta 0.9 --boundary 8
fastrack control "$model" --state 0.2,-0.1,0.3,1.0 --state 0.5,0.5,-1.0,1.5 --beta 1.0
fastrack evaluate "$model" --state 0.2,-0.1,0.3,1.0 --beta 0.75
fastrack track "$model" --ticks 20
fastrack load --model "$model" --workload track --concurrency 8 --duration-s 2 --warmup-s 0.5
echo
echo "\$ curl http://127.0.0.1:$metrics_port/metrics  (excerpt)"
python3 -c "import urllib.request,sys; print(''.join(l for l in urllib.request.urlopen('http://127.0.0.1:$metrics_port/metrics').read().decode().splitlines(True) if l.startswith(('fastrack_requests_total', 'fastrack_track_ticks_total', 'fastrack_loaded_versions'))))"
echo
kill -TERM $server
wait $server && echo "server shut down cleanly"
trap - EXIT
