#!/usr/bin/env bash
# ros2/sl_msgs on the wire: Foxglove's ROS 2 serializer and deserializer with
# the package's .msg/.srv text against Cyclone DDS with the daemon's types
# (tools/sl_view/test/sl_msgs_wire.mjs says what is checked).
# usage: sl_msgs_wire.sh SOURCE_DIR ROUNDTRIP_EXE
set -euo pipefail
src=$1
exe=$2
export CYCLONEDDS_URI=${CYCLONEDDS_URI:-file://$src/config/cyclonedds-loopback.xml}
[ -d "$src/tools/sl_view/node_modules/@foxglove/rosmsg2-serialization" ] || {
  echo "FAIL: npm packages missing: run scripts/install-deps.sh (npm ci in tools/sl_view)" >&2
  exit 1
}
exec node "$src/tools/sl_view/test/sl_msgs_wire.mjs" "$exe" "$src/ros2/sl_msgs" "$src/idl/std_srvs"
