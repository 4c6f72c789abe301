#!/usr/bin/env bash
# The cost of DDS Security per cloud (docs/operations.md, "DDS Security"): sl_dds_bench
# sub/pub, full-resolution clouds (1440 x 1080 x 16 B) at the sensor's 5 Hz on
# the loopback config, the publisher as `sensor`, the subscriber as `viewer`:
#   none                 no security
#   control_only         requests, replies and status protected, clouds open
#                        (governance_control before issue 36; made here from
#                        governance_control, not shipped)
#   governance_control   clouds signed (SIGN, AES-GMAC) with write access control
#   governance_origin    clouds signed as above, plus one MAC per matched
#                        reader (origin authentication)
#   governance_all       clouds encrypted (AES-GCM)
# SL_BENCH_MODES="..." runs a subset, in its order.
# Each round runs every mode once, in that order; prints per run the clouds
# received (the subscriber waits up to 30 s for a late cloud), those the
# publisher did not send (a write blocked > 200 ms), the latency and the CPU
# time (user + system) of each process per cloud.
#
#   tools/sl_dds_bench/security.sh [BUILD_DIR] [COUNT] [RATE_HZ]   (defaults: build, 50, 5)
#   SL_BENCH_ROUNDS=N (default 1)
set -euo pipefail
src=$(cd "$(dirname "$0")/../.." && pwd)
build=${1:-$src/build}
count=${2:-50}
rate=${3:-5}
bench=$build/tools/sl_dds_bench/sl_dds_bench
[ -x "$bench" ] || { echo "security.sh: $bench not built" >&2; exit 2; }
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
rounds=${SL_BENCH_ROUNDS:-1}
bash "$src/scripts/dds-security.sh" "$work/sec" --ns "bench" >/dev/null
# control_only: governance_control with the SIGN rules (the data topics)
# unprotected, signed with the same permissions CA.
awk '/<topic_rule>/ { in_rule = 1; rule = "" }
     in_rule { rule = rule $0 "\n"
               if (/<\/topic_rule>/) {
                 if (rule ~ /SIGN/) {
                   gsub(/SIGN/, "NONE", rule)
                   gsub(/write_access_control>true/, "write_access_control>false", rule)
                 }
                 printf "%s", rule
                 in_rule = 0
               }
               next }
     { print }' \
  "$work/sec/governance_control.xml" > "$work/sec/control_only.xml"
grep -q SIGN "$work/sec/control_only.xml" && { echo "security.sh: control_only still signs" >&2; exit 2; }
openssl smime -sign -in "$work/sec/control_only.xml" -text -out "$work/sec/control_only.p7s" \
  -signer "$work/sec/permissions_ca.pem" -inkey "$work/sec/permissions_ca_key.pem" 2>/dev/null
plain=file://$src/config/cyclonedds-loopback.xml
secure=$plain,file://$src/config/cyclonedds-security.xml
export SL_DDS_SECURITY_DIR=$work/sec

echo "| security | rate | clouds received | not sent | latency median | p99 | publisher CPU / cloud | subscriber CPU / cloud received |"
echo "|---|---|---|---|---|---|---|---|"
for round in $(seq "$rounds"); do
for mode in ${SL_BENCH_MODES:-none control_only governance_control governance_origin governance_all}; do
  uri=$plain
  [ "$mode" != none ] && uri=$secure
  export SL_DDS_GOVERNANCE=$mode
  topic="rt/bench/points"
  CYCLONEDDS_URI=$uri SL_DDS_IDENTITY=viewer /usr/bin/time -f "%U %S" -o "$work/sub.time" \
    timeout 300 "$bench" sub --topic "$topic" --count "$count" --timeout 250 --quiet 30 \
    > "$work/sub.log" 2>&1 &
  sub=$!
  sleep 1
  CYCLONEDDS_URI=$uri SL_DDS_IDENTITY=sensor /usr/bin/time -f "%U %S" -o "$work/pub.time" \
    timeout 300 "$bench" pub --topic "$topic" --count "$count" --rate "$rate" > "$work/pub.log" 2>&1 \
    || cat "$work/pub.log" >&2
  wait "$sub" || true
  line=$(grep '^sub: received' "$work/sub.log" || echo "sub: no result: $(cat "$work/sub.log")")
  pub_cpu=$(awk -v n="$count" '{ printf "%.1f ms", ($1 + $2) * 1000 / n }' "$work/pub.time")
  received=$(echo "$line" | awk '{ print $3 }')
  # pub: N clouds of ... , K not sent (write blocked > 200 ms)
  not_sent=$(sed -n 's/^pub: .*, \([0-9]*\) not sent.*/\1/p' "$work/pub.log")
  sub_cpu=$(awk -v n="$received" '{ if (n > 0) printf "%.1f ms", ($1 + $2) * 1000 / n; else print "-" }' "$work/sub.time")
  # sub: received R of N clouds (lost L = P %, malformed M), D clouds/s delivered,
  #      latency median A ms p99 B ms max C ms
  echo "$line" | awk -v m="$mode" -v r="$rate Hz" -v p="$pub_cpu" -v s="$sub_cpu" -v u="${not_sent:-?}" '{
    printf "| %s | %s | %s/%s | %s | %s ms | %s ms | %s | %s |\n", m, r, $3, $5, u, $19, $22, p, s }'
done
done
