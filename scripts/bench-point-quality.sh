#!/bin/bash
# The daemon's latency with and without the per-point quality fields
# (dds.points_normals + dds.points_confidence), alternated in one run:
# sl_sensord on config/sim.yaml, 20 s of continuous 3+3_horizontal scans
# each, then `slctl status` (medians of the last 64 scans).
# Usage: scripts/bench-point-quality.sh [ROUNDS]   (needs build/ with sl_sensord and slctl)
set -euo pipefail
cd "$(dirname "$0")/.."
export CYCLONEDDS_URI=file://$PWD/config/cyclonedds-loopback.xml
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT
for round in $(seq 1 "${1:-2}"); do
  for kind in default quality; do
    ns=qbench_${kind}_${round}_$$
    sed "s/^  namespace: sl$/  namespace: $ns/" config/sim.yaml > "$tmp/$ns.yaml"
    if [ "$kind" = quality ]; then
      sed -i 's/^  publish_projector_maps: false$/  publish_projector_maps: false\n  points_normals: true\n  points_confidence: true/' "$tmp/$ns.yaml"
    fi
    ./build/daemon/sl_sensord --config "$tmp/$ns.yaml" > "$tmp/$ns.log" 2>&1 &
    pid=$!
    sleep 4
    ./build/tools/slctl --ns "$ns" start --pattern 3+3_horizontal > /dev/null
    sleep 20
    echo "== $kind, round $round"
    ./build/tools/slctl --ns "$ns" status | grep -E "^(scans|latency|sets dropped)"
    ./build/tools/slctl --ns "$ns" stop > /dev/null
    kill "$pid"
    wait "$pid" || true
  done
done
