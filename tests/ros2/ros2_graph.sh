#!/usr/bin/env bash
# The daemon in ROS 2's graph: /tf_static, /diagnostics and
# ros_discovery_info of sl_sensord on the simulated sensor, taken by
# ros2_graph_listener and decoded with Foxglove's ROS 2 deserializer
# (tools/sl_view/test/ros2_graph_check.mjs says what is checked).
# usage: ros2_graph.sh SOURCE_DIR BINARY_DIR
set -euo pipefail
src=$1
bin=$2
export CYCLONEDDS_URI=${CYCLONEDDS_URI:-file://$src/config/cyclonedds-loopback.xml}
[ -d "$src/tools/sl_view/node_modules/@foxglove/rosmsg2-serialization" ] || {
  echo "FAIL: npm packages missing: run scripts/install-deps.sh (npm ci in tools/sl_view)" >&2
  exit 1
}
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
node "$src/tools/sl_view/test/ros2_graph_check.mjs" "$src" "$bin/daemon/sl_sensord" \
  "$bin/tests/ros2/ros2_graph_listener" "$bin/tools/slctl" "$work"
