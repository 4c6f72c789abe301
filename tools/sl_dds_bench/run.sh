#!/usr/bin/env bash
# Measures full-resolution cloud delivery (1440 x 1080 x 16 B) between two
# processes on this machine for each shipped Cyclone DDS configuration, with
# sl_dds_bench (see sl_dds_bench.cpp): at the sensor's rate (5 Hz) and back
# to back. Prints one Markdown table row per run.
#
#   tools/sl_dds_bench/run.sh [BUILD_DIR] [COUNT]      (defaults: build, 100)
#
# Configurations: loopback (config/cyclonedds-loopback.xml); lan, i.e.
# config/cyclonedds-lan.xml with its interface bound to 127.0.0.1 and
# unicast discovery (its message, fragment, buffer and watermark sizes
# unchanged); shm (config/cyclonedds-shm.xml) when iox-roudi is installed:
# a RouDi with config/iceoryx-roudi.toml is started for the run unless one
# is already running. Traffic stays on 127.0.0.1.
set -euo pipefail
src=$(cd "$(dirname "$0")/../.." && pwd)
build=${1:-$src/build}
count=${2:-100}
bench=$build/tools/sl_dds_bench/sl_dds_bench
[ -x "$bench" ] || { echo "run.sh: $bench not built" >&2; exit 2; }
work=$(mktemp -d)
roudi_pid=""
cleanup() {
  if [ -n "$roudi_pid" ]; then
    # RouDi removes its segments on SIGTERM; it may miss one sent right after
    # start-up, so repeat it for up to 10 s before SIGKILL.
    for _ in $(seq 1 20); do
      kill -TERM "$roudi_pid" 2>/dev/null || break
      sleep 0.5
      case "$(ps -o stat= -p "$roudi_pid" 2>/dev/null)" in Z* | "") break ;; esac
    done
    kill -KILL "$roudi_pid" 2>/dev/null || true
    wait "$roudi_pid" 2>/dev/null || true
  fi
  rm -rf "$work"
}
trap cleanup EXIT

# The LAN config on loopback: only the interface and discovery change.
sed -e 's#<NetworkInterface autodetermine="true"/>#<NetworkInterface address="127.0.0.1"/>#' \
    -e 's#<AllowMulticast>spdp</AllowMulticast>#<AllowMulticast>false</AllowMulticast>#' \
    -e 's#</Discovery>#  <Peers><Peer address="127.0.0.1"/></Peers>\n    </Discovery>#' \
    "$src/config/cyclonedds-lan.xml" > "$work/lan-loopback.xml"
grep -q 'address="127.0.0.1"' "$work/lan-loopback.xml" || { echo "run.sh: LAN config edit failed" >&2; exit 2; }

configs=("loopback:$src/config/cyclonedds-loopback.xml" "lan:$work/lan-loopback.xml")
if command -v iox-roudi > /dev/null; then
  if ! pgrep -r R,S,D -x iox-roudi > /dev/null; then
    iox-roudi -c "$src/config/iceoryx-roudi.toml" -l warning > "$work/roudi.log" 2>&1 &
    roudi_pid=$!
    sleep 1
  fi
  configs+=("shm:$src/config/cyclonedds-shm.xml")
fi

echo "| config | rate | clouds | delivered/s | latency median | p99 | max | lost |"
echo "|---|---|---|---|---|---|---|---|"
for entry in "${configs[@]}"; do
  name=${entry%%:*}
  export CYCLONEDDS_URI=file://${entry#*:}
  for rate in 5 0; do
    topic="rt/bench_$$_${name}_$rate/points"
    timeout 180 "$bench" sub --topic "$topic" --count "$count" --timeout 150 \
      > "$work/sub.log" 2>&1 &
    sub=$!
    sleep 0.5
    timeout 180 "$bench" pub --topic "$topic" --count "$count" --rate "$rate" \
      > "$work/pub.log" 2>&1 || { cat "$work/pub.log" >&2; }
    wait "$sub" || true
    line=$(grep '^sub: received' "$work/sub.log" || echo "sub: no result: $(cat "$work/sub.log")")
    label=$([ "$rate" = 0 ] && echo "back to back" || echo "$rate Hz")
    # sub: received R of N clouds (lost L = P %, malformed M), D clouds/s delivered,
    #      latency median A ms p99 B ms max C ms
    echo "$line" | awk -v cfg="$name" -v label="$label" '{
      printf "| %s | %s | %s/%s | %s | %s ms | %s ms | %s ms | %s (%s %%) |\n",
        cfg, label, $3, $5, $14, $19, $22, $25, $8, $10 }'
  done
done
