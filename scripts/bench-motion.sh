#!/usr/bin/env bash
# Scanning while moving, in real time (issue 33): sl_sensord on
# config/sim-motion.yaml (60 mm/s, vertical 3+3, motion compensation on, two
# cameras), SECONDS of continuous scanning, one cloud subscriber.
#
#   bash scripts/bench-motion.sh [BUILD_DIR] [SECONDS]     (defaults: build, 20; a Release build
#                                                          with sl_sensord, slctl, sl_dds_bench)
#
# SL_BENCH_CACHE_MIB="0 256" runs the daemon once per value of
# sim.signal_cache_mib, one after the other (default: one run with the
# config's own value, "config"); SL_BENCH_LABEL (default: none) is printed at
# the start of each result line, e.g. the commit or the machine.
#
# Figures per run:
#   scans_per_s   clouds the subscriber took / SECONDS (0 when fewer than 2 came;
#                 includes the start: the simulator's first sequences, the
#                 subscriber's first clouds)
#   daemon_scan_hz the daemon's scan rate at the end (slctl status: its recent window)
#   lost          sequences missing between the subscriber's first and last
#                 cloud (by header.stamp on the sequence grid: 6 frames at
#                 the camera rate), whatever lost them
#   incomplete    the daemon's sets incomplete (slctl status)
#   sets_dropped  the daemon's sets dropped (queue full, ...)
#   frames_dropped the daemon's frames dropped (queue full or unmatched)
#   camera_fps    frames per second PER CAMERA: the daemon's frame rate of all
#                 cameras divided by the number of cameras (both expose on
#                 the one projector schedule), over the status's window
#   p50_ms/p99_ms latency at the subscriber: take time - the trigger time of
#                 the sequence's last pattern (header.stamp, the time of
#                 motion_compensation.reference_frame, + 5 - that frame image
#                 intervals), over the clouds taken from SL_BENCH_WARMUP_S
#                 (default 2) after the first one (the first sequences pay for
#                 the simulator's first renders of each pose and the reader's
#                 fresh buffers); "nan" when none came
#   first_max_ms  the largest latency of the warm-up's clouds
#   daemon_median_ms the daemon's own median (last trigger -> published)
#   load          the 1-minute load average at the end of the run
# Ends with one line per run:
#   motion: [<label>] cache_mib=<v> scans_per_s=<x> daemon_scan_hz=<x> lost=<n> incomplete=<n> sets_dropped=<n>
#     frames_dropped=<n> camera_fps=<x> p50_ms=<x> p99_ms=<x> first_max_ms=<x> daemon_median_ms=<x> load=<x>
#
# Runs on the host's loopback (config/cyclonedds-loopback.xml) in a topic
# namespace of its own; every wait is bounded; the daemon and the subscriber
# are stopped on exit.
set -euo pipefail
src=$(cd "$(dirname "$0")/.." && pwd)
build=$(cd "${1:-$src/build}" && pwd)
secs=${2:-20}
label=${SL_BENCH_LABEL:-}
caches=${SL_BENCH_CACHE_MIB:-config}
export CYCLONEDDS_URI=file://$src/config/cyclonedds-loopback.xml

sensord=$build/daemon/sl_sensord
slctl=$build/tools/slctl
listen=$build/tools/sl_dds_bench/sl_dds_bench
for b in "$sensord" "$slctl" "$listen"; do
  [ -x "$b" ] || { echo "bench-motion: $b not built" >&2; exit 1; }
done
config=$src/config/sim-motion.yaml
fps=$(awk '$1 == "camera_fps:" { print $2; exit }' "$config")
cameras=$(( $(grep -c '^  second_camera:' "$config") + 1 ))
period=$(awk -v f="$fps" 'BEGIN { printf "%.0f", 6e9 / f }')   # one 6-frame sequence, ns
# With compensation on, a cloud is stamped with its reference frame's time.
ref=$(awk '$1 == "reference_frame:" { print $2; exit }' "$config")
offset=$(awk -v f="$fps" -v r="${ref:-0}" 'BEGIN { printf "%.0f", (5 - r) * 1e9 / f }')   # stamp -> last trigger, ns
warmup_ns=$(awk -v s="${SL_BENCH_WARMUP_S:-2}" 'BEGIN { printf "%.0f", s * 1e9 }')

work=$(mktemp -d)
pids=()
cleanup() {
  for p in "${pids[@]}"; do kill "$p" 2> /dev/null || true; done
  for p in "${pids[@]}"; do wait "$p" 2> /dev/null || true; done
  rm -rf "$work"
}
trap cleanup EXIT

# $1: slctl status output, $2: line prefix; the first number after it.
status_number() { sed -n "s/^$2 *\([0-9.]*\).*/\1/p" "$1" | head -n 1; }

results=()
for cache in $caches; do
  ns=motion_$$_${cache}
  cfg=$work/$ns.yaml
  sed "s/^  namespace: sl$/  namespace: $ns/" "$config" > "$cfg"
  # The config names files relative to itself: none in sim-motion.yaml.
  if [ "$cache" != config ]; then
    sed -i "s/^sim:$/sim:\n  signal_cache_mib: $cache/" "$cfg"
  fi
  "$sensord" --config "$cfg" > "$work/$ns.daemon.log" 2>&1 &
  daemon=$!
  pids+=("$daemon")
  if ! "$slctl" --ns "$ns" --timeout 30 status > /dev/null; then
    echo "bench-motion: the daemon did not answer; its log:" >&2
    cat "$work/$ns.daemon.log" >&2
    exit 1
  fi
  timeout $((secs + 60)) "$listen" listen --topic "rt/$ns/points" --duration "$secs" --timeout 30 \
    --in-place 1 > "$work/$ns.listen.log" 2>&1 &
  sub=$!
  pids+=("$sub")
  sleep 2   # the subscriber matched before the first scan
  "$slctl" --ns "$ns" start > /dev/null
  sleep "$secs"
  "$slctl" --ns "$ns" status > "$work/$ns.status" || true
  load=$(cut -d ' ' -f 1 /proc/loadavg)
  "$slctl" --ns "$ns" stop > /dev/null || true
  wait "$sub" || true   # ends after its window (or without clouds: exit 1)
  kill "$daemon" 2> /dev/null || true
  wait "$daemon" || true

  clouds=$(grep -c '^rx ' "$work/$ns.listen.log" || true)
  rate=$(awk -v n="$clouds" -v s="$secs" 'BEGIN { printf "%.2f", (n >= 2 ? n / s : 0) }')
  lost=$(awk -v p="$period" '$1 == "rx" { if (n++) { k = int(($2 - prev) / p + 0.5); if (k > 1) lost += k - 1 } prev = $2 }
    END { print lost + 0 }' "$work/$ns.listen.log")
  first_max=$(awk -v o="$offset" -v w="$warmup_ns" '$1 == "rx" { if (!(n++)) t0 = $3
      if ($3 - t0 < w) { l = ($3 - $2 - o) / 1e6; if (l > m) m = l; seen = 1 } }
    END { if (seen) printf "%.1f", m; else print "nan" }' "$work/$ns.listen.log")
  percentiles=$(awk -v o="$offset" -v w="$warmup_ns" '$1 == "rx" { if (!(n++)) t0 = $3
      if ($3 - t0 >= w) print ($3 - $2 - o) / 1e6 }' "$work/$ns.listen.log" |
    sort -g | awk '{ v[NR] = $1 } END {
      if (!NR) { print "nan nan"; exit }
      i50 = int(0.50 * NR + 0.999); i99 = int(0.99 * NR + 0.999)
      printf "%.1f %.1f\n", v[i50 < 1 ? 1 : i50], v[i99 < 1 ? 1 : i99] }')
  st=$work/$ns.status
  frame_rate=$(status_number "$st" 'frame rate:')
  camera_fps=$(awk -v f="${frame_rate:-0}" -v c="$cameras" 'BEGIN { printf "%.1f", f / c }')
  line="motion:${label:+ $label} cache_mib=$cache scans_per_s=$rate"
  line+=" daemon_scan_hz=$(status_number "$st" 'scan rate:') lost=$lost"
  line+=" incomplete=$(status_number "$st" 'sets incomplete:')"
  line+=" sets_dropped=$(status_number "$st" 'sets dropped:')"
  line+=" frames_dropped=$(status_number "$st" 'frames dropped:')"
  line+=" camera_fps=$camera_fps p50_ms=${percentiles% *} p99_ms=${percentiles#* } first_max_ms=$first_max"
  line+=" daemon_median_ms=$(status_number "$st" 'latency:' | sed 's/^$/nan/') load=$load"
  echo "== cache_mib=$cache: $clouds clouds in $secs s; daemon status:"
  grep -E '^(scans|scan rate|frame rate|latency|frames dropped|sets dropped|sets incomplete):' "$st" || true
  results+=("$line")
done
printf '%s\n' "${results[@]}"
