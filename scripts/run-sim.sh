#!/usr/bin/env bash
# README command (a): install, build and run sl_sensord in the foreground on
# the simulated sensor (config/sim.yaml). Stop it with Ctrl-C.
# DDS stays on this machine (config/cyclonedds-loopback.xml) unless
# CYCLONEDDS_URI is already set.
set -euo pipefail
root=$(cd "$(dirname "$0")/.." && pwd)
build_dir=${BUILD_DIR:-$root/build}

bash "$root/scripts/build.sh" --target sl_sensord slctl
export CYCLONEDDS_URI=${CYCLONEDDS_URI:-file://$root/config/cyclonedds-loopback.xml}
echo "run-sim: CYCLONEDDS_URI=$CYCLONEDDS_URI"
exec "$build_dir/daemon/sl_sensord" --config "$root/config/sim.yaml" "$@"
