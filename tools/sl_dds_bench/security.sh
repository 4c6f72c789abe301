#!/usr/bin/env bash
# The cost of DDS Security per cloud (docs/operations.md, "DDS Security"): sl_dds_bench
# sub/pub, full-resolution clouds (1440 x 1080 x 16 B) at the sensor's 5 Hz on
# the loopback config, without security, with governance_control (clouds
# open: only discovery and the control topics are protected) and with
# governance_all (clouds signed and encrypted, AES-GCM), the publisher as
# `sensor`, the subscriber as `viewer`. Prints per configuration the
# latency and the CPU time (user + system) of each process per cloud.
#
#   tools/sl_dds_bench/security.sh [BUILD_DIR] [COUNT] [RATE_HZ]   (defaults: build, 50, 5)
set -euo pipefail
src=$(cd "$(dirname "$0")/../.." && pwd)
build=${1:-$src/build}
count=${2:-50}
rate=${3:-5}
bench=$build/tools/sl_dds_bench/sl_dds_bench
[ -x "$bench" ] || { echo "security.sh: $bench not built" >&2; exit 2; }
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
bash "$src/scripts/dds-security.sh" "$work/sec" --ns "bench" >/dev/null
plain=file://$src/config/cyclonedds-loopback.xml
secure=$plain,file://$src/config/cyclonedds-security.xml
export SL_DDS_SECURITY_DIR=$work/sec

echo "| security | rate | clouds received | latency median | p99 | publisher CPU / cloud sent | subscriber CPU / cloud received |"
echo "|---|---|---|---|---|---|---|"
for mode in none governance_control governance_all; do
  uri=$plain
  [ "$mode" != none ] && uri=$secure
  export SL_DDS_GOVERNANCE=$mode
  topic="rt/bench/points"
  CYCLONEDDS_URI=$uri SL_DDS_IDENTITY=viewer /usr/bin/time -f "%U %S" -o "$work/sub.time" \
    timeout 300 "$bench" sub --topic "$topic" --count "$count" --timeout 250 > "$work/sub.log" 2>&1 &
  sub=$!
  sleep 1
  CYCLONEDDS_URI=$uri SL_DDS_IDENTITY=sensor /usr/bin/time -f "%U %S" -o "$work/pub.time" \
    timeout 300 "$bench" pub --topic "$topic" --count "$count" --rate "$rate" > "$work/pub.log" 2>&1 \
    || cat "$work/pub.log" >&2
  wait "$sub" || true
  line=$(grep '^sub: received' "$work/sub.log" || echo "sub: no result: $(cat "$work/sub.log")")
  pub_cpu=$(awk -v n="$count" '{ printf "%.1f ms", ($1 + $2) * 1000 / n }' "$work/pub.time")
  received=$(echo "$line" | awk '{ print $3 }')
  sub_cpu=$(awk -v n="$received" '{ if (n > 0) printf "%.1f ms", ($1 + $2) * 1000 / n; else print "-" }' "$work/sub.time")
  # sub: received R of N clouds (lost L = P %, malformed M), D clouds/s delivered,
  #      latency median A ms p99 B ms max C ms
  echo "$line" | awk -v m="$mode" -v r="$rate Hz" -v p="$pub_cpu" -v s="$sub_cpu" '{
    printf "| %s | %s | %s/%s | %s ms | %s ms | %s | %s |\n", m, r, $3, $5, $19, $22, p, s }'
done
