#!/usr/bin/env bash
# How many clouds one viewer gets through sl_view (issue 18: the live view's
# reader default): sl_sensord on the simulated sensor scanning continuously
# for SECONDS with depth/shading images on, sl_view (extra arguments are its
# options, e.g. --best-effort) and one viewer (bench_viewer.mjs) of
# /<ns>/points or /<ns>/points/preview. Prints one line: the daemon's scans,
# the messages the viewer got, DDS writes timed out, sl_view's own count of
# clouds missed (GET /stats) and the load average.
#   bash tools/sl_view/bench/delivery_view.sh build preview 10 [--best-effort]
set -uo pipefail
root=$(cd "$(dirname "$0")/../../.." && pwd)
bin=${1:-$root/build}
case ${2:-preview} in preview) suffix=/preview ;; full) suffix= ;; *) echo "TOPIC: preview or full" >&2; exit 2 ;; esac
seconds=${3:-10}
shift 3 2>/dev/null || shift $#
export CYCLONEDDS_URI=${CYCLONEDDS_URI:-file://$root/config/cyclonedds-loopback.xml}
work=$(mktemp -d)
pids=()
trap 'for p in "${pids[@]}"; do kill $p 2>/dev/null; done; sleep 0.3; rm -rf "$work"' EXIT
ns="delivery_view_$$"
sed -e "s/^  namespace: sl$/  namespace: $ns/" \
    -e "s/^  publish_projector_maps: false$/  publish_projector_maps: false\n  publish_images: true/" \
    "$root/config/sim.yaml" > "$work/sim.yaml"
"$bin/daemon/sl_sensord" --config "$work/sim.yaml" > "$work/daemon.log" 2>&1 &
pids+=($!)
"$bin/tools/sl_view/sl_view" --ns "$ns" --port 0 "$@" > "$work/view.log" 2>&1 &
pids+=($!)
for _ in $(seq 150); do grep -q ready "$work/daemon.log" && grep -q "live view at" "$work/view.log" && break; sleep 0.1; done
port=$(grep -o "http://127.0.0.1:[0-9]*" "$work/view.log" | grep -o "[0-9]*$") || { echo "sl_view did not start" >&2; exit 1; }
node "$root/tools/sl_view/bench/bench_viewer.mjs" "ws://127.0.0.1:$port" "/$ns/points$suffix" $((seconds + 3)) \
  > "$work/viewer.log" 2>&1 &
viewer=$!
sleep 2
"$bin/tools/slctl" --ns "$ns" start > /dev/null
sleep "$seconds"
status=$("$bin/tools/slctl" --ns "$ns" status)
"$bin/tools/slctl" --ns "$ns" stop > /dev/null
wait $viewer
scans=$(echo "$status" | awk '/^scans:/ { print $2 }')
timed_out=$(echo "$status" | sed -n 's/.*write timed out \([0-9]*\).*/\1/p')
got=$(grep -o "^[^:]*: [0-9]* messages" "$work/viewer.log" | grep -o "[0-9]* messages$")
missed=$(node -e 'fetch(process.argv[1]).then((r) => r.json()).then(({ dds: d }) =>
  console.log(`${d.clouds_missed} of ${d.clouds_published_while_read}`))' "http://127.0.0.1:$port/stats")
echo "delivery: points$suffix sl_view '${*:-(defaults)}': daemon scans $scans in ${seconds} s," \
  "viewer got ${got:-0 messages}, writes timed out $timed_out, sl_view counted missed $missed," \
  "load average $(cut -d' ' -f1-3 /proc/loadavg)"
