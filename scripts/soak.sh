#!/bin/bash
# Soak: sl_sensord on config/sim.yaml scanning continuously (3+3_horizontal,
# 5 Hz) for MINUTES with one subscriber of rt/<ns>/points (sl_dds_bench
# listen, in place); prints the daemon's RSS every minute and, at the end,
# the clouds the daemon published (status scans_done) against those the
# subscriber received, and the daemon's loss counters.
# Usage: scripts/soak.sh BUILD_DIR MINUTES
set -euo pipefail
cd "$(dirname "$0")/.."
build=$1 minutes=$2
export CYCLONEDDS_URI=file://$PWD/config/cyclonedds-loopback.xml
tmp=$(mktemp -d)
ns=soak_$$
cleanup() {
  [ -n "${listen_pid:-}" ] && kill "$listen_pid" 2>/dev/null || true
  [ -n "${pid:-}" ] && kill "$pid" 2>/dev/null || true
  wait 2>/dev/null || true
  rm -rf "$tmp"
}
trap cleanup EXIT
sed "s/^  namespace: sl$/  namespace: $ns/" config/sim.yaml > "$tmp/sim.yaml"
"$build/daemon/sl_sensord" --config "$tmp/sim.yaml" > "$tmp/daemon.log" 2>&1 &
pid=$!
sleep 4
secs=$((minutes * 60))
"$build/tools/sl_dds_bench/sl_dds_bench" listen --topic "rt/$ns/points" --duration $((secs + 5)) \
  --timeout 60 --in-place 1 > "$tmp/listen.log" 2>&1 &
listen_pid=$!
sleep 2
"$build/tools/slctl" --ns "$ns" start --pattern 3+3_horizontal > /dev/null
rss() { awk '/^VmRSS/ { print $2 / 1024 }' "/proc/$pid/status"; }
echo "start: $(date -u +%H:%M:%S), load $(cut -d' ' -f1 /proc/loadavg), daemon RSS $(rss) MiB"
for m in $(seq 1 "$minutes"); do
  sleep 60
  echo "minute $m: RSS $(rss) MiB, load $(cut -d' ' -f1 /proc/loadavg), $("$build/tools/slctl" --ns "$ns" status | grep -E '^scans:')"
done
"$build/tools/slctl" --ns "$ns" stop > /dev/null
wait "$listen_pid" || true
listen_pid=
status=$("$build/tools/slctl" --ns "$ns" status)
echo "$status" | grep -E "^(scans|scan rate|frames dropped|sets dropped|sets incomplete|clouds lost)"
echo "end: $(date -u +%H:%M:%S), daemon RSS $(rss) MiB"
echo "clouds published (scans_done): $(echo "$status" | awk '/^scans:/ { print $2 }'), received by the subscriber: $(awk '/^listen: done/ { print $3 }' "$tmp/listen.log" | tr -d ,)"
