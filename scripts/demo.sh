#!/usr/bin/env bash
# The main job: starts the server on the shipped model repository (models/), drives a simulated robot
# through one seeded world with Parametric FaSTrack (the planner rule, on the fastest raw path) over the
# server's Track stream (`fastrack sim run`), prints the run's summary and the paths of its figures, then
# shuts the server down gracefully.
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/build.sh
port=${FASTRACK_DEMO_PORT:-50151}
export FASTRACK_SERVER="http://127.0.0.1:$port"
./target/debug/fastrack-server --listen "127.0.0.1:$port" --models models &
server=$!
trap 'kill $server 2>/dev/null || true' EXIT
./target/debug/fastrack health --wait-s 30 >/dev/null
seed=${FASTRACK_DEMO_SEED:-1}
echo "\$ fastrack sim run --seed $seed --method pf-planner --plot target/sim/demo.png"
./target/debug/fastrack sim run --seed "$seed" --method pf-planner --plot target/sim/demo.png
kill -TERM $server
wait $server && echo "server shut down cleanly"
trap - EXIT
