#!/usr/bin/env bash
# Cloud delivery with the daemon in the loop (issue 13): sl_sensord on the
# simulated sensor, subscribers in other processes, per shipped Cyclone DDS
# configuration and per scenario, plus the bare DDS ceiling (sl_dds_bench
# pub/sub, 25 MB clouds, no daemon) and a Fast DDS subscriber at 5 Hz.
#
#   bash scripts/bench-delivery.sh [BUILD_DIR]        (default: build; a Release build)
#
# SL_BENCH_READER_DEPTH (default 4, the daemon's writer depth) sets the
# subscribers' keep-last history; SL_BENCH_QUEUE_DEPTH sets the daemon's
# runtime.queue_depth (default: config/sim.yaml's 2).
# SL_BENCH_KEEP_LOGS=DIR copies the run's scratch files (daemon, RouDi and
# subscriber logs) to DIR at the end (a path outside /tmp: as root the run has
# a private /tmp).
# Scenarios (SL_BENCH_SECONDS scales the windows, default 30):
#   5hz      camera 30 fps (6-frame 3+3 sequences: 5 scans/s), one subscriber
#   max      camera 180 fps (30 scans/s), one subscriber, 30 s
#   3subs    three subscribers (the figures: the worst of the three) at
#            SL_BENCH_3SUBS_FPS (default 90 fps = 15 scans/s: the rate the
#            issue asks each of three subscribers to get without loss; at
#            180 fps three full-cloud readers need more CPU than 2 cores have)
#   5hz-inplace (SL_BENCH_SCENARIOS name: inplace) as 5hz, same daemon, with
#            a subscriber that takes each cloud serialized and reads it in
#            place (sl_dds_bench listen --in-place 1, as sl_view does)
#            instead of deserializing it (loopback only)
#   5hz-sets as 5hz with dds.publish_image_sets on (loopback only): what
#            publishing the raw image sets costs the clouds
#   5hz-copy (SL_BENCH_SCENARIOS name: copy) as 5hz with
#            dds.points_zero_copy off (loopback only): clouds serialized by
#            dds_write, the comparison for the daemon's zero-copy writer
#   stalled  camera 30 fps, two subscribers, the second SIGSTOPped for 30 s
#            (SL_BENCH_SECONDS) after 5 s; the figures are the first's; the second's clouds
#            after it resumes are reported on their own line
# Configurations: loopback (config/cyclonedds-loopback.xml, the default),
# lan (config/cyclonedds-lan.xml bound to 127.0.0.1 with unicast discovery,
# as tools/sl_dds_bench/run.sh does), shm (config/cyclonedds-shm.xml, with a
# RouDi of config/iceoryx-roudi.toml started for the run).
#
# Figures per subscriber, over its window (from its first cloud):
#   clouds_per_s  clouds taken / window
#   lost          sequences missing between the first and the last cloud
#                 taken (by header.stamp on the sequence grid: 6 frames at the
#                 camera rate), whatever lost them (simulator, synchroniser,
#                 queues, DDS)
#   p50/p99/max   latency = take time (CLOCK_REALTIME after dds_take) - the
#                 trigger time of the sequence's last pattern (header.stamp
#                 + 5 image intervals): from the end of the sequence's
#                 acquisition to the subscriber holding the cloud
#   rss_mb        the daemon's peak resident set (VmHWM, reset before each
#                 scenario through /proc/PID/clear_refs)
# Ends with one line per configuration and scenario:
#   delivery: <config> <scenario> clouds_per_s=<x> lost=<n> p50_ms=<x> p99_ms=<x> max_ms=<x> rss_mb=<x>
# and writes them as CSV to SL_BENCH_CSV (default
# docs/measurements/delivery-<UTC time>.csv; docs/measurements.md says how to read them).
#
# As root it runs in a private network and mount namespace (its own
# loopback, /tmp and /dev/shm), so its DDS traffic and its RouDi never meet
# anyone else's; otherwise on the host's loopback, domain 0. Every wait is
# bounded; daemons, subscribers and RouDi are stopped on exit.
set -euo pipefail
src=$(cd "$(dirname "$0")/.." && pwd)
build=$(cd "${1:-$src/build}" && pwd)
secs=${SL_BENCH_SECONDS:-30}
# A new reader's first clouds pay for its fresh buffers (Cyclone's receive
# buffers, the deserialized sample, the kernel's socket buffers): on this
# VM first-touched memory costs several ms per MB (docs/measurements.md),
# so the first clouds take far longer than the rest. p50/p99/max are over the clouds a reader
# takes from SL_BENCH_WARMUP_S (default 1 s) after its first one; the
# warm-up's clouds are counted for loss and rate, and their latencies are
# printed on the reader's own line (first_ms, warmup_max_ms).
warmup_ns=$(awk -v s="${SL_BENCH_WARMUP_S:-1}" 'BEGIN { printf "%.0f", s * 1e9 }')
subs3_fps=${SL_BENCH_3SUBS_FPS:-90}
# SL_BENCH_DAEMON_RT=N runs the daemon (all its threads) at SCHED_FIFO
# priority N, as the unit's CPUSchedulingPolicy=fifo would; default: as an
# ordinary process.
daemon_prefix=()
if [ -n "${SL_BENCH_DAEMON_RT:-}" ]; then daemon_prefix=(chrt -f "$SL_BENCH_DAEMON_RT"); fi
# The 5 Hz windows (5hz, 5hz-inplace, 5hz-copy, 5hz-sets, fastdds-5hz): 60 s = 300 clouds, so that
# the p99 is the 4th-worst cloud; with 100 clouds (20 s) it was the
# 2nd-worst, i.e. the subscriber's second cloud, which always pays for its
# buffers' first page faults. The first cloud's latency is printed on the
# subscriber's line (first_ms) and is in max_ms.
secs_5hz=${SL_BENCH_5HZ_SECONDS:-$((secs * 2))}

if [ "${SL_BENCH_INSIDE:-0}" != 1 ] && [ "$(id -u)" = 0 ] && unshare -n -m true 2> /dev/null; then
  exec env SL_BENCH_INSIDE=1 unshare -n -m --propagation private bash "$0" "$build"
fi
if [ "${SL_BENCH_INSIDE:-0}" = 1 ]; then
  ip link set lo up
  mount -t tmpfs -o mode=1777 tmpfs /tmp
  mount -t tmpfs -o mode=1777 tmpfs /dev/shm
  isolation="private network and mount namespace"
else
  isolation="host loopback (not root: no private namespace)"
fi

daemon=$build/daemon/sl_sensord
slctl=$build/tools/slctl
bench=$build/tools/sl_dds_bench/sl_dds_bench
fastdds=$build/tests/interop/fastdds_points_subscriber
for b in "$daemon" "$slctl" "$bench"; do
  [ -x "$b" ] || { echo "bench-delivery: $b not built (cmake --build $build)" >&2; exit 2; }
done
grep -q 'CMAKE_BUILD_TYPE:STRING=Release' "$build/CMakeCache.txt" 2> /dev/null ||
  echo "bench-delivery: warning: $build is not a Release build" >&2

work=$(mktemp -d)
pids=()
roudi_pid=""
cleanup() {
  for p in "${pids[@]}"; do kill -CONT "$p" 2> /dev/null || true; kill -TERM "$p" 2> /dev/null || true; done
  sleep 0.5
  for p in "${pids[@]}"; do kill -KILL "$p" 2> /dev/null || true; done
  if [ -n "$roudi_pid" ]; then
    for _ in $(seq 1 20); do
      kill -TERM "$roudi_pid" 2> /dev/null || break
      sleep 0.5
      case "$(ps -o stat= -p "$roudi_pid" 2> /dev/null)" in Z* | "") break ;; esac
    done
    kill -KILL "$roudi_pid" 2> /dev/null || true
  fi
  if [ -n "${SL_BENCH_KEEP_LOGS:-}" ]; then
    mkdir -p "$SL_BENCH_KEEP_LOGS" && cp -r "$work"/. "$SL_BENCH_KEEP_LOGS"/ 2> /dev/null || true
  fi
  rm -rf "$work"
}
trap cleanup EXIT
trap 'exit 130' INT TERM

t_start=$SECONDS
results=()
notes=()
note() { echo "$*"; notes+=("$*"); }

# --- configurations ---
sed -e 's#<NetworkInterface autodetermine="true"/>#<NetworkInterface address="127.0.0.1"/>#' \
    -e 's#<AllowMulticast>spdp</AllowMulticast>#<AllowMulticast>false</AllowMulticast>#' \
    -e 's#</Discovery>#  <Peers><Peer address="127.0.0.1"/></Peers>\n    </Discovery>#' \
    "$src/config/cyclonedds-lan.xml" > "$work/lan-loopback.xml"
grep -q 'address="127.0.0.1"' "$work/lan-loopback.xml" || { echo "bench-delivery: LAN config edit failed" >&2; exit 2; }
configs=("loopback:$src/config/cyclonedds-loopback.xml" "lan:$work/lan-loopback.xml")
if command -v iox-roudi > /dev/null; then
  if [ "${SL_BENCH_INSIDE:-0}" = 1 ] || ! pgrep -x iox-roudi > /dev/null; then
    # Monitoring off: with it on, RouDi declares a SIGSTOPped subscriber dead
    # after a few seconds and the subscriber aborts when it resumes (docs/operations.md
    # "DDS deployment").
    iox-roudi -c "$src/config/iceoryx-roudi.toml" -m off -l warning > "$work/roudi.log" 2>&1 &
    roudi_pid=$!
    sleep 2
    kill -0 "$roudi_pid" 2> /dev/null || { cat "$work/roudi.log" >&2; roudi_pid=""; }
    # As systemd/iceoryx-roudi.service does: every page of the segments
    # allocated before the first chunk is written.
    [ -z "$roudi_pid" ] || sh "$src/scripts/iceoryx-prefault.sh" "$roudi_pid" | sed 's/^/bench-delivery: /'
  fi
  [ -n "$roudi_pid" ] || pgrep -x iox-roudi > /dev/null && configs+=("shm:$src/config/cyclonedds-shm.xml")
else
  note "note: iox-roudi not installed: shm configuration skipped"
fi

# SL_BENCH_CONFIGS / SL_BENCH_SCENARIOS: subsets (names separated by spaces),
# for iterating on one case; the figures of record come from a full run.
if [ -n "${SL_BENCH_CONFIGS:-}" ]; then
  kept=()
  for entry in "${configs[@]}"; do
    case " $SL_BENCH_CONFIGS " in *" ${entry%%:*} "*) kept+=("$entry") ;; esac
  done
  configs=("${kept[@]}")
fi
scenarios=${SL_BENCH_SCENARIOS:-ceiling 5hz inplace copy stalled sets max 3subs fastdds}
# Subscribers deserialize each cloud (dds_take into the generated struct, as
# a ROS 2 node's subscription does) except in 5hz-inplace.
in_place=0
wanted() { case " $scenarios " in *" $1 "*) return 0 ;; esac; return 1; }

# slctl always talks over the loopback config (which the shm config extends):
# its small requests gain nothing from shared memory, and short-lived
# processes registering with RouDi one after another is what made Debian's
# iox-roudi 2.0 abort (it tried to shut down an slctl that had already exited:
# POSH__ROUDI_PROCESS_SHUTDOWN_FAILED).
ctl=(env "CYCLONEDDS_URI=file://$src/config/cyclonedds-loopback.xml" "$slctl")

# --- statistics ---
# stats FILE PERIOD_NS OFFSET_NS -> "clouds_per_s=.. lost=.. p50_ms=.. p99_ms=.. max_ms=.."
# from "rx STAMP TAKE" lines; latency = TAKE - (STAMP + OFFSET).
stats() {
  local file=$1 period=$2 offset=$3
  local n
  n=$(grep -c '^rx ' "$file" || true)
  if [ "$n" -lt 1 ]; then
    echo "clouds_per_s=0 lost=all p50_ms=nan p99_ms=nan max_ms=nan"
    return
  fi
  local head
  head=$(awk -v p="$period" '$1 == "rx" {
      if (!(n++)) { s0 = $2; s1 = $2; r0 = $3; r1 = $3 }
      if ($2 < s0) s0 = $2; if ($2 > s1) s1 = $2; if ($3 < r0) r0 = $3; if ($3 > r1) r1 = $3
      seen[$2] = 1 }
    END { u = 0; for (k in seen) u++
      expected = int((s1 - s0) / p + 0.5) + 1
      span = (r1 - r0) / 1e9
      printf "clouds_per_s=%.2f lost=%d", (n > 1 && span > 0 ? (n - 1) / span : 0), expected - u }' "$file")
  echo "$head $(latencies "$file" "$offset")"
}
# latencies FILE OFFSET_NS -> "p50_ms=.. p99_ms=.. max_ms=.." over the clouds
# taken after the reader's warm-up (warmup_ns from its first take); the
# warm-up's own are in first() below.
latencies() {
  awk -v o="$2" -v w="$warmup_ns" '$1 == "rx" { if (!(n++)) t0 = $3
      if ($3 - t0 >= w) printf "%.3f\n", ($3 - $2 - o) / 1e6 }' "$1" | sort -g |
    awk '{ v[NR] = $1 } END {
      i50 = int(0.50 * (NR - 1) + 0.5) + 1; i99 = int(0.99 * (NR - 1) + 0.5) + 1
      printf "p50_ms=%.1f p99_ms=%.1f max_ms=%.1f", v[i50], v[i99], v[NR] }'
}
# split FILE OFFSET_NS -> where the latency went, over the same clouds as
# latencies(): "trigger->write p50/p99" up to the daemon's dds_write (the
# sample's source timestamp: wait + processing in the daemon) and
# "write->take p50/p99" from there to the reader holding it (serialization,
# transport, the reader's wake-up and deserialization).
split() {
  local col
  for col in 1 2; do
    awk -v o="$2" -v w="$warmup_ns" -v c="$col" '$1 == "rx" && NF >= 4 { if (!(n++)) t0 = $3
        if ($3 - t0 >= w) printf "%.3f\n", (c == 1 ? ($4 - $2 - o) : ($3 - $4)) / 1e6 }' "$1" | sort -g |
      awk -v c="$col" '{ v[NR] = $1 } END { if (!NR) exit
        i50 = int(0.50 * (NR - 1) + 0.5) + 1; i99 = int(0.99 * (NR - 1) + 0.5) + 1
        printf "%s p50 %.1f p99 %.1f ms%s", (c == 1 ? "trigger->write" : "write->take"), v[i50], v[i99], (c == 1 ? ", " : "") }'
  done
}
field() { echo "$1" | tr ' ' '\n' | sed -n "s/^$2=//p"; }
# first FILE OFFSET_NS -> "first_ms=<the first two clouds' latencies>
# warmup_clouds=<n> warmup_max_ms=<the worst latency within the warm-up>"
first() { awk -v o="$2" -v w="$warmup_ns" '$1 == "rx" { l = ($3 - $2 - o) / 1e6
      if (!(n++)) t0 = $3
      if (n <= 2) v = v (v ? "," : "") sprintf("%.1f", l)
      if ($3 - t0 < w) { k++; if (l > m) m = l } }
    END { printf "first_ms=%s warmup_clouds=%d warmup_max_ms=%.1f\n", (v ? v : "nan"), k, m }' "$1"; }

# --- the daemon ---
daemon_pid=""
ns=""
# prefault_at FPS -> 1 or 0: runtime.prefault_memory for the daemon and
# --prefault-clouds for its readers (docs/formats.md, runtime.prefault_memory: recommended from ~15 scans/s),
# on for the high-rate scenarios unless SL_BENCH_PREFAULT says 0 or 1 for all.
prefault_at() {
  local p=${SL_BENCH_PREFAULT:-auto}
  [ "$p" = auto ] && p=$([ "$1" -ge 90 ] && echo 1 || echo 0)
  echo "$p"
}
start_daemon() {  # FPS [extra sed expression]
  local fps=$1 extra=${2:-}
  ns="bench_$$_$RANDOM"
  local prefault
  prefault=$([ "$(prefault_at "$fps")" = 1 ] && echo true || echo false)
  sed -e "s/^  camera_fps: 30 /  camera_fps: $fps /" -e "s/^  namespace: sl$/  namespace: $ns/" \
      -e "s/^runtime:$/runtime:\n  prefault_memory: $prefault/" \
      ${SL_BENCH_QUEUE_DEPTH:+-e "s/^  queue_depth: 2$/  queue_depth: $SL_BENCH_QUEUE_DEPTH/"} \
      ${extra:+-e "$extra"} "$src/config/sim.yaml" > "$work/sim.yaml"
  grep -q "camera_fps: $fps " "$work/sim.yaml" && grep -q "namespace: $ns" "$work/sim.yaml" &&
    { [ -z "${SL_BENCH_QUEUE_DEPTH:-}" ] || grep -q "^  queue_depth: $SL_BENCH_QUEUE_DEPTH$" "$work/sim.yaml"; } &&
    grep -q "prefault_memory: $prefault" "$work/sim.yaml" ||
    { echo "bench-delivery: could not edit config/sim.yaml" >&2; exit 2; }
  echo "  daemon: camera_fps $fps, runtime.prefault_memory $prefault"
  "${daemon_prefix[@]}" "$daemon" --config "$work/sim.yaml" > "$work/daemon.log" 2>&1 &
  daemon_pid=$!
  pids+=("$daemon_pid")
  timeout 30 "${ctl[@]}" --ns "$ns" --timeout 20 status > /dev/null 2>&1 ||
    { echo "bench-delivery: the daemon did not answer:" >&2; cat "$work/daemon.log" >&2; exit 1; }
  grep -m 3 'warning' "$work/daemon.log" | sed 's/^/  daemon: /' || true
}
stop_daemon() {
  [ -n "$daemon_pid" ] || return 0
  kill -TERM "$daemon_pid" 2> /dev/null || true
  for _ in $(seq 1 50); do kill -0 "$daemon_pid" 2> /dev/null || break; sleep 0.1; done
  kill -KILL "$daemon_pid" 2> /dev/null || true
  wait "$daemon_pid" 2> /dev/null || true
  daemon_pid=""
}
# minflt: the daemon's minor page faults so far (/proc/PID/stat field 10).
minflt() { awk '{ print $10 }' "/proc/$daemon_pid/stat" 2> /dev/null || echo 0; }
# udp_drops: UDP datagrams this namespace dropped for a full socket receive
# buffer (each costs a repair round of the cloud it belonged to).
udp_drops() { awk '$1 == "Udp:" && $2 ~ /^[0-9]+$/ { print $6 }' /proc/net/snmp; }
rss_mb() { awk '/^VmHWM/ { printf "%.0f", $2 / 1024 }' "/proc/$daemon_pid/status" 2> /dev/null || echo nan; }
reset_rss() { echo 5 > "/proc/$daemon_pid/clear_refs" 2> /dev/null || true; }

# scenario NAME CONFIG FPS SUBS DURATION [STALL]: subscribers 1..SUBS, each
# "sl_dds_bench listen"; STALL=1: subscriber 2 stopped from 5 s for 30 s.
scenario() {
  local name=$1 cfg=$2 fps=$3 subs=$4 duration=$5 stall=${6:-0}
  local period offset i
  period=$(awk -v f="$fps" 'BEGIN { printf "%.0f", 6e9 / f }')
  offset=$(awk -v f="$fps" 'BEGIN { printf "%.0f", 5e9 / f }')
  local sub_pids=()
  # The subscribers prefault their heaps as the daemon does (same rule).
  local prefault
  prefault=$(prefault_at "$fps")
  for i in $(seq 1 "$subs"); do
    timeout $((duration + 90)) "$bench" listen --topic "rt/$ns/points" --duration "$duration" \
      --timeout 30 --prefault-clouds $((prefault * 8)) --depth "${SL_BENCH_READER_DEPTH:-4}" --in-place "$in_place" > "$work/sub$i.log" 2> "$work/sub$i.err" &
    sub_pids+=($!)
    pids+=($!)
  done
  sleep 3  # discovery: the volatile cloud topic only reaches matched readers
  reset_rss
  local load faults0
  load=$(cut -d' ' -f1-3 /proc/loadavg)
  faults0=$(minflt)
  local drops0
  drops0=$(udp_drops)
  timeout 20 "${ctl[@]}" --ns "$ns" start > /dev/null || { echo "bench-delivery: slctl start failed" >&2; cat "$work/daemon.log" >&2; exit 1; }
  if [ "$stall" = 1 ]; then
    sleep 5
    # The subscriber itself, not only the timeout(1) that runs it.
    local stalled=("${sub_pids[1]}" $(pgrep -P "${sub_pids[1]}" || true))
    kill -STOP "${stalled[@]}"
    sleep "$secs"
    kill -CONT "${stalled[@]}"
  fi
  for p in "${sub_pids[@]}"; do wait "$p" || true; done
  local rss faults
  rss=$(rss_mb)
  faults=$(( $(minflt) - faults0 ))
  local drops
  drops=$(( $(udp_drops) - drops0 ))
  local status
  status=$(timeout 20 "${ctl[@]}" --ns "$ns" status 2>&1 | tr '\n' ' ' | tr -s ' ')
  timeout 20 "${ctl[@]}" --ns "$ns" stop > /dev/null 2>&1 || true
  sleep 1
  # The figures: subscriber 1 (stalled), else the worst of the subscribers
  # (lowest rate, most lost, highest latencies).
  local lines=() line f
  local measured=("$work/sub1.log")
  [ "$stall" = 1 ] || measured=($(for i in $(seq 1 "$subs"); do echo "$work/sub$i.log"; done))
  for f in "${measured[@]}"; do
    line=$(stats "$f" "$period" "$offset")
    echo "  $name/$cfg $(basename "$f" .log): $line $(first "$f" "$offset")"
    local where
    where=$(split "$f" "$offset")
    [ -z "$where" ] || echo "  $name/$cfg $(basename "$f" .log) split: $where"
    lines+=("$line")
  done
  local worst
  worst=$(printf '%s\n' "${lines[@]}" | tr '=' ' ' | awk '
    { if (NR == 1) l = -1
      if (NR == 1 || $2 < r) r = $2; if ($4 == "all" || l == "all") l = "all"; else if ($4 + 0 > l + 0) l = $4
      for (k = 6; k <= 10; k += 2) if ($k == "nan" || v[k] == "nan") v[k] = "nan"; else if (NR == 1 || $k > v[k]) v[k] = $k }
    END { printf "clouds_per_s=%s lost=%s p50_ms=%s p99_ms=%s max_ms=%s", r, l, v[6], v[8], v[10] }')
  if [ "$stall" = 1 ]; then
    # The stalled subscriber: clouds taken after it resumed, and how old the
    # first of them was (the writer's and its own history hold the newest).
    awk -v o="$offset" '$1 == "rx" { if (prev && $3 - prev > 5e9) { gap = ($3 - prev) / 1e9; age = ($3 - $2 - o) / 1e6; after = 0 }
                         if (gap) after++; prev = $3 }
      END { if (gap) printf "  stalled/%s sub2: resumed after %.1f s, first cloud %.0f ms old, %d clouds after resuming\n", cfg, gap, age, after
            else printf "  stalled/%s sub2: no gap of more than 5 s between its takes: it took no cloud after resuming (%s)\n", cfg, (prev ? "or never stopped" : "nor before") }' cfg="$cfg" "$work/sub2.log"
  fi
  echo "  $name/$cfg: load average $load; daemon status: ${status:0:400}"
  # Minor page faults per cloud: fresh memory for 25 MB buffers (docs/operations.md).
  local scans
  scans=$(echo "$status" | grep -o 'scans: [0-9]*' | head -n 1 | cut -d' ' -f2)
  echo "  $name/$cfg: page faults per scan: daemon $(awk -v f="$faults" -v n="${scans:-0}" 'BEGIN { printf "%.0f", (n > 0 ? f / n : 0) }')$(for i in $(seq 1 "$subs"); do
    sed -n 's/^listen: done \([0-9]*\), minor page faults \([0-9]*\).*/\1 \2/p' "$work/sub$i.log" |
      awk -v i="$i" '$1 > 0 { printf ", sub%d %.0f", i, $2 / $1 }'; done); UDP datagrams dropped (receive buffer full): $drops"
  for i in $(seq 1 "$subs"); do
    local bad
    bad=$(sed -n 's/^listen: done .*, malformed \([0-9]*\)$/\1/p' "$work/sub$i.log")
    [ "${bad:-0}" = 0 ] || echo "  $name/$cfg: sub$i took $bad malformed clouds (see its stderr)"
  done
  # Where the time went inside the daemon (its status: last 64 scans).
  echo "  $name/$cfg: daemon $(echo "$status" | grep -o 'latency: [^)]*)' || echo 'latency: not reported')"
  results+=("delivery: $cfg $name $worst rss_mb=$rss")
}

echo "bench-delivery: $(date -u +%FT%TZ), $(nproc) cores, $isolation, load average $(cut -d' ' -f1-3 /proc/loadavg)"
echo "bench-delivery: net.core.rmem_max=$(cat /proc/sys/net/core/rmem_max) wmem_max=$(cat /proc/sys/net/core/wmem_max)"
echo "bench-delivery: daemon scheduling: ${daemon_prefix[*]:-ordinary (SCHED_OTHER, nice 0)}"
echo "bench-delivery: allocator: $([ "${SL_DEFAULT_MALLOC:-0}" = 1 ] && echo "glibc's defaults (SL_DEFAULT_MALLOC=1)" || echo "large samples retained (sl::dds::retainLargeSampleMemory)")"

# --- bare DDS ceiling: sl_dds_bench pub -> sub, no daemon ---
# At 5 Hz: pub -> listen over the 5 Hz scenarios' window, latency = take -
# write time (header.stamp), the same warm-up rule as the daemon's readers:
# what the transport alone gives a subscriber, to hold the 5hz lines against.
declare -A ceiling_rate ceiling_p50 ceiling_p99
for entry in "${configs[@]}"; do
  wanted ceiling || break
  cfg=${entry%%:*}
  export CYCLONEDDS_URI=file://${entry#*:}
  topic="rt/ceiling_$$_${cfg}_listen/points"
  timeout $((secs_5hz + 90)) "$bench" listen --topic "$topic" --duration "$((secs_5hz + 5))" --timeout 30 \
    > "$work/clisten.log" 2>&1 &
  clisten=$!
  pids+=("$clisten")
  sleep 2
  timeout $((secs_5hz + 60)) "$bench" pub --topic "$topic" --count $((secs_5hz * 5)) --rate 5 > "$work/cpub.log" 2>&1 || true
  wait "$clisten" || true
  line=$(latencies "$work/clisten.log" 0)
  echo "  ceiling/$cfg 5 Hz, $(grep -c '^rx ' "$work/clisten.log") of $((secs_5hz * 5)) clouds: $line $(first "$work/clisten.log" 0)"
  grep '^pub: retransmitted' "$work/cpub.log" | sed "s|^pub: |  ceiling/$cfg writer: |" || true
  ceiling_p50[$cfg]=$(field "$line" p50_ms)
  ceiling_p99[$cfg]=$(field "$line" p99_ms)
  # Back to back: sl_dds_bench pub -> sub, 120 clouds as fast as they go.
  topic="rt/ceiling_$$_${cfg}_b2b/points"
  timeout 90 "$bench" sub --topic "$topic" --count 120 --timeout 60 > "$work/csub.log" 2>&1 &
  csub=$!
  pids+=("$csub")
  sleep 1
  timeout 90 "$bench" pub --topic "$topic" --count 120 --rate 0 > "$work/cpub.log" 2>&1 || true
  wait "$csub" || true
  line=$(grep '^sub: received' "$work/csub.log" || echo "sub: no result")
  echo "  ceiling/$cfg back to back: $line"
  # The writer's repair traffic (Cyclone's writer statistics).
  grep '^pub: retransmitted' "$work/cpub.log" | sed "s|^pub: |  ceiling/$cfg writer: |" || true
  ceiling_rate[$cfg]=$(echo "$line" | sed -n 's/.* \([0-9.]*\) clouds\/s delivered.*/\1/p')
done

# --- the daemon in the loop ---
for entry in "${configs[@]}"; do
  cfg=${entry%%:*}
  export CYCLONEDDS_URI=file://${entry#*:}
  if wanted 5hz || wanted stalled; then
    start_daemon 30
    ! wanted 5hz || scenario 5hz "$cfg" 30 1 "$secs_5hz"
    if wanted inplace && [ "$cfg" = loopback ]; then
      in_place=1
      scenario 5hz-inplace "$cfg" 30 1 "$secs_5hz"
      in_place=0
    fi
    ! wanted stalled || scenario stalled "$cfg" 30 2 "$((secs + 12))" 1
    stop_daemon
  fi
  if wanted copy && [ "$cfg" = loopback ]; then
    # The clouds serialized by dds_write (one more 25 MB copy per cloud)
    # instead of sent from their own memory: compare with 5hz.
    start_daemon 30 's/^  publish_projector_maps: false$/  publish_projector_maps: false\n  points_zero_copy: false/'
    grep -q 'points_zero_copy: false' "$work/sim.yaml" || { echo "bench-delivery: could not turn zero copy off" >&2; exit 2; }
    scenario 5hz-copy "$cfg" 30 1 "$secs_5hz"
    stop_daemon
  fi
  if wanted sets && [ "$cfg" = loopback ]; then
    # What publishing the image sets (dds.publish_image_sets, 9.3 MB per 3+3
    # scan, written after the cloud) costs the clouds: compare with 5hz.
    start_daemon 30 's/^  publish_projector_maps: false$/  publish_projector_maps: false\n  publish_image_sets: true/'
    grep -q 'publish_image_sets: true' "$work/sim.yaml" || { echo "bench-delivery: could not enable image sets" >&2; exit 2; }
    scenario 5hz-sets "$cfg" 30 1 "$secs_5hz"
    stop_daemon
  fi
  if wanted max; then
    start_daemon 180
    scenario max "$cfg" 180 1 "$secs"
    stop_daemon
  fi
  if wanted 3subs; then
    start_daemon "$subs3_fps"
    scenario 3subs "$cfg" "$subs3_fps" 3 "$((secs * 2 / 3))"
    stop_daemon
  fi
done

# --- a Fast DDS subscriber (ROS 2's default middleware) at 5 Hz, default config ---
if ! wanted fastdds; then
  :
elif [ -x "$fastdds" ]; then
  export CYCLONEDDS_URI=file://$src/config/cyclonedds-loopback.xml
  export FASTRTPS_DEFAULT_PROFILES_FILE=$src/config/fastdds-loopback.xml
  start_daemon 30
  n=$((secs_5hz * 5))
  # The Fast DDS subscriber stands for a ROS 2 node: it runs with the
  # allocator settings docs/operations.md recommends for subscribers of full clouds
  # (docs/operations.md, "Memory of large samples": the values retainLargeSampleMemory
  # sets with mallopt), unless SL_DEFAULT_MALLOC=1.
  tunables=glibc.malloc.mmap_threshold=33554432:glibc.malloc.trim_threshold=2147483647:glibc.malloc.top_pad=67108864
  [ "${SL_DEFAULT_MALLOC:-0}" = 1 ] && tunables=${GLIBC_TUNABLES:-}
  timeout $((secs + 60)) env GLIBC_TUNABLES="$tunables" "$fastdds" --topic "rt/$ns/points" --count "$n" --timeout $((secs + 50)) --rx-times \
    > "$work/fastdds.log" 2> "$work/fastdds.err" &
  fpid=$!
  pids+=("$fpid")
  for _ in $(seq 1 100); do grep -q '^ready' "$work/fastdds.log" && break; sleep 0.1; done
  sleep 1
  reset_rss
  timeout 20 "${ctl[@]}" --ns "$ns" start > /dev/null
  wait "$fpid" || echo "  fastdds: $(tail -n 2 "$work/fastdds.err")"
  rss=$(rss_mb)
  timeout 20 "${ctl[@]}" --ns "$ns" stop > /dev/null 2>&1 || true
  stop_daemon
  line=$(stats "$work/fastdds.log" 200000000 166666667)
  echo "  fastdds-5hz/loopback: $line $(first "$work/fastdds.log" 166666667)"
  results+=("delivery: loopback fastdds-5hz $line rss_mb=$rss")
else
  note "note: $fastdds not built (Fast DDS missing): Fast DDS subscriber skipped"
fi

echo
for entry in "${configs[@]}"; do
  cfg=${entry%%:*}
  echo "bench-delivery: bare DDS ceiling ($cfg, sl_dds_bench, 25 MB clouds): ${ceiling_rate[$cfg]:-?} clouds/s back to back; at 5 Hz p50 ${ceiling_p50[$cfg]:-?} ms, p99 ${ceiling_p99[$cfg]:-?} ms"
  for r in "${results[@]}"; do
    case "$r" in
      "delivery: $cfg max "*)
        awk -v got="$(field "$r" clouds_per_s)" -v bare="${ceiling_rate[$cfg]:-0}" -v c="$cfg" \
          'BEGIN { if (bare > 0) printf "bench-delivery: %s max / bare ceiling = %.2f\n", c, got / bare }' ;;
      "delivery: $cfg 5hz "*)
        # What the daemon adds to the transport's own latency at 5 Hz (the
        # bare figure is from the write, the daemon's from the last trigger).
        awk -v p50="$(field "$r" p50_ms)" -v p99="$(field "$r" p99_ms)" -v b50="${ceiling_p50[$cfg]:-nan}" \
          -v b99="${ceiling_p99[$cfg]:-nan}" -v c="$cfg" 'BEGIN { if (b50 != "nan" && b50 != "")
            printf "bench-delivery: %s 5hz over the bare ceiling: p50 +%.1f ms, p99 +%.1f ms\n", c, p50 - b50, p99 - b99 }' ;;
    esac
  done
done
echo "bench-delivery: load average at the end $(cut -d' ' -f1-3 /proc/loadavg); total $((SECONDS - t_start)) s"
for r in "${results[@]}"; do echo "$r"; done
# The same lines as data, in the columns of docs/measurements/delivery-history.csv.
csv=${SL_BENCH_CSV:-$src/docs/measurements/delivery-$(date -u +%Y%m%dT%H%MZ).csv}
tree=$(git -C "$src" rev-parse --short HEAD 2>/dev/null || echo unknown)
{
  echo "date_utc,tree,config,scenario,clouds_per_s,lost,p50_ms,p99_ms,max_ms,rss_mb"
  for r in "${results[@]}"; do
    set -- $r
    echo "$(date -u +%FT%H:%MZ),$tree,$2,$3,$(field "$r" clouds_per_s),$(field "$r" lost),$(field "$r" p50_ms),$(field "$r" p99_ms),$(field "$r" max_ms),$(field "$r" rss_mb)"
  done
} > "$csv"
echo "bench-delivery: results written to $csv"
