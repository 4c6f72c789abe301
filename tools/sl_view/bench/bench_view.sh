#!/usr/bin/env bash
# The bridge's cost (issue 18): sl_sensord on the simulated sensor scanning
# continuously (5 clouds/s), sl_view next to it and one viewer
# (bench_viewer.mjs) subscribed to the full cloud (as Foxglove) or to the web
# page's decimated cloud. Measures, over SECONDS each: the daemon's CPU per
# cloud without sl_view and with it, sl_view's CPU per cloud, and the latency
# the bridge adds (sl_view's DDS receive -> the viewer's receive).
# VIEW_ARGS="--best-effort" passes options to sl_view (default: its
# reliable keep-last-1 readers).
#
# Ends with a summary: one "bench_view:" line per case and the load average
# at the start and at the end (the figures mean little on a loaded machine).
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
load_start=$(cut -d' ' -f1-3 /proc/loadavg)
summary=()

"$bin/daemon/sl_sensord" --config "$work/sim.yaml" > "$work/daemon.log" 2>&1 &
daemon=$!; pids+=($daemon)
sleep 3
"$bin/tools/slctl" --ns "$ns" start > /dev/null
sleep 3
# measure VIEW_PID: sets clouds, rate, daemon_ms (daemon CPU per cloud) and
# view_ms (sl_view CPU per cloud, if VIEW_PID) over $seconds.
measure() {
  local d0 v0=0 s0 d1 v1=0 s1
  d0=$(cpu $daemon); s0=$(scans); [ -n "$1" ] && v0=$(cpu $1)
  sleep "$seconds"
  d1=$(cpu $daemon); s1=$(scans); [ -n "$1" ] && v1=$(cpu $1)
  clouds=$((s1 - s0))
  [ "$clouds" -gt 0 ] || { echo "bench_view: no cloud published in $seconds s" >&2; exit 1; }
  rate=$(echo "scale=2; $clouds / $seconds" | bc)
  daemon_ms=$(echo "scale=1; ($d1 - $d0) * 1000 / $hz / $clouds" | bc)
  view_ms=$(echo "scale=1; ($v1 - $v0) * 1000 / $hz / $clouds" | bc)
}
measure ""
base_ms=$daemon_ms
summary+=("bench_view: no sl_view: $rate clouds/s, daemon $daemon_ms ms CPU per cloud")
echo "${summary[-1]}"
for topic in "/$ns/points" "/$ns/points/preview"; do
  "$bin/tools/sl_view/sl_view" --ns "$ns" --port 0 ${VIEW_ARGS:-} > "$work/view.log" 2>&1 &
  view=$!; pids+=($view)
  sleep 2
  port=$(grep -o "http://127.0.0.1:[0-9]*" "$work/view.log" | grep -o "[0-9]*$")
  node "$root/tools/sl_view/bench/bench_viewer.mjs" "ws://127.0.0.1:$port" "$topic" $((seconds + 2)) > "$work/viewer.log" &
  viewer=$!
  sleep 1
  measure $view
  wait $viewer
  cat "$work/viewer.log"
  got=$(sed -n 's/^[^:]*: \([0-9]*\) messages.*/\1/p' "$work/viewer.log")
  added=$(sed -n 's/^  added by the bridge + WS: *median \([0-9.]*\) ms, p95 \([0-9.]*\) ms/\1 \/ \2/p' "$work/viewer.log")
  name=$([ "$topic" = "/$ns/points" ] && echo "full cloud (25 MB)" || echo "preview (1.6 MB)")
  line="bench_view: viewer of the $name, sl_view '${VIEW_ARGS:-reliable (default)}': $rate clouds/s,"
  line+=" daemon $daemon_ms ms CPU per cloud ($(echo "$daemon_ms - $base_ms" | bc) ms more), sl_view $view_ms ms CPU per cloud,"
  line+=" latency added by the bridge median / p95 ${added:-n/a} ms, viewer got ${got:-0} messages in $((seconds + 2)) s"
  summary+=("$line")
  echo "${summary[-1]}"
  kill $view; wait $view 2>/dev/null || true
done
"$bin/tools/slctl" --ns "$ns" stop > /dev/null
echo
echo "=== bench_view summary ($seconds s per case, $(nproc) cores) ==="
printf '%s\n' "${summary[@]}"
echo "bench_view: load average at start $load_start, at end $(cut -d' ' -f1-3 /proc/loadavg)"
