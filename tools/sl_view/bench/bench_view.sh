#!/usr/bin/env bash
# The bridge's cost (issue 18): sl_sensord on the simulated sensor scanning
# continuously (5 clouds/s), sl_view next to it and one viewer
# (bench_viewer.mjs) subscribed to the full cloud (as Foxglove) or to the web
# page's decimated cloud. Prints sl_view's CPU per cloud, the daemon's CPU
# per cloud with and without the bridge, and the latency the bridge adds.
# VIEW_ARGS="--best-effort" passes options to sl_view.
# Run it in a private network namespace, on an otherwise idle machine:
#   unshare -n sh -c 'ip link set lo up && bash tools/sl_view/bench/bench_view.sh build 20'
set -euo pipefail
root=$(cd "$(dirname "$0")/../../.." && pwd)
bin=${1:-$root/build}
seconds=${2:-20}
export CYCLONEDDS_URI=${CYCLONEDDS_URI:-file://$root/config/cyclonedds-loopback.xml}
work=$(mktemp -d)
pids=()
trap 'for p in "${pids[@]}"; do kill $p 2>/dev/null || true; done; rm -rf "$work"' EXIT
ns="bench_view_$$"
sed -e "s/^  namespace: sl$/  namespace: $ns/" \
    -e "s/^  publish_projector_maps: false$/  publish_projector_maps: false\n  publish_images: true/" \
    "$root/config/sim.yaml" > "$work/sim.yaml"
cpu() { awk '{ print $14 + $15 }' "/proc/$1/stat"; }  # utime + stime, clock ticks
hz=$(getconf CLK_TCK)
scans() { "$bin/tools/slctl" --ns "$ns" status | awk '/^scans:/ { print $2 }'; }

"$bin/daemon/sl_sensord" --config "$work/sim.yaml" > "$work/daemon.log" 2>&1 &
daemon=$!; pids+=($daemon)
sleep 3
"$bin/tools/slctl" --ns "$ns" start > /dev/null
sleep 3
measure() {  # LABEL VIEW_PID: daemon (and sl_view) CPU per cloud over $seconds
  local d0 v0 s0 d1 v1 s1
  d0=$(cpu $daemon); s0=$(scans); [ -n "$2" ] && v0=$(cpu $2)
  sleep "$seconds"
  d1=$(cpu $daemon); s1=$(scans); [ -n "$2" ] && v1=$(cpu $2)
  local n=$((s1 - s0))
  echo "$1: $n clouds in $seconds s ($(echo "scale=2; $n / $seconds" | bc) /s);" \
    "daemon $(echo "scale=1; ($d1 - $d0) * 1000 / $hz / $n" | bc) ms CPU per cloud" \
    "${2:+; sl_view $(echo "scale=1; ($v1 - $v0) * 1000 / $hz / $n" | bc) ms CPU per cloud}"
}
measure "no bridge" ""
for topic in "/$ns/points" "/$ns/points/preview"; do
  "$bin/tools/sl_view/sl_view" --ns "$ns" --port 0 ${VIEW_ARGS:-} > "$work/view.log" 2>&1 &
  view=$!; pids+=($view)
  sleep 2
  port=$(grep -o "http://127.0.0.1:[0-9]*" "$work/view.log" | grep -o "[0-9]*$")
  node "$root/tools/sl_view/bench/bench_viewer.mjs" "ws://127.0.0.1:$port" "$topic" $((seconds + 2)) > "$work/viewer.log" &
  viewer=$!
  sleep 1
  measure "bridge + 1 viewer of $topic" $view
  wait $viewer
  cat "$work/viewer.log"
  kill $view; wait $view 2>/dev/null || true
done
"$bin/tools/slctl" --ns "$ns" stop > /dev/null
echo "load average: $(cut -d' ' -f1-3 /proc/loadavg)"
