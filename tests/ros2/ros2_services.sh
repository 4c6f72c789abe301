#!/usr/bin/env bash
# The daemon's ROS 2 services against two rmw_cyclonedds-framed clients
# (tools/sl_view/test/ros2_services_check.mjs says what is checked), with
# sl_sensord on the simulated sensor in a unique namespace.
# usage: ros2_services.sh SOURCE_DIR BINARY_DIR [FASTDDS_CLIENT_EXE]
set -euo pipefail
src=$1
bin=$2
fastdds_client=${3:-}
export CYCLONEDDS_URI=${CYCLONEDDS_URI:-file://$src/config/cyclonedds-loopback.xml}
export FASTRTPS_DEFAULT_PROFILES_FILE=$src/config/fastdds-loopback.xml
work=$(mktemp -d)
daemon_pid=
cleanup() {
  [ -n "$daemon_pid" ] && kill "$daemon_pid" 2>/dev/null || true
  rm -rf "$work"
}
trap cleanup EXIT
fail() {
  echo "FAIL: $*" >&2
  [ -f "$work/daemon.log" ] && { echo "--- daemon.log"; tail -n 30 "$work/daemon.log"; } >&2
  exit 1
}
[ -d "$src/tools/sl_view/node_modules/@foxglove/rosmsg2-serialization" ] ||
  fail "npm packages missing: run scripts/install-deps.sh (npm ci in tools/sl_view)"
ns="services_$$_$RANDOM"
sed -e "s/^  namespace: sl$/  namespace: $ns/" "$src/config/sim.yaml" > "$work/sim.yaml"
grep -q "namespace: $ns" "$work/sim.yaml" || fail "could not set the namespace in a copy of config/sim.yaml"
"$bin/daemon/sl_sensord" --config "$work/sim.yaml" > "$work/daemon.log" 2>&1 &
daemon_pid=$!
for _ in $(seq 1 300); do
  grep -q "ready:" "$work/daemon.log" && break
  kill -0 "$daemon_pid" 2>/dev/null || fail "sl_sensord exited"
  sleep 0.1
done
grep -q "ready:" "$work/daemon.log" || fail "sl_sensord not ready within 30 s"
node "$src/tools/sl_view/test/ros2_services_check.mjs" "$src" "$bin/tests/ros2/ros2_service_client" "$ns" \
  $fastdds_client ||
  fail "ros2_services_check"
