#!/usr/bin/env bash
# The live view: install, build, run sl_sensord on the simulated sensor (with
# depth / shading images and camera_info on) and sl_view next to it, then open
#   http://127.0.0.1:8765/      in a browser (3D cloud, depth, status, controls)
#   ws://127.0.0.1:8765         in Foxglove ("Open connection" > Foxglove WebSocket)
# Ctrl-C stops both. Extra arguments go to sl_view (e.g. --port 9000,
# --host 0.0.0.0 to let other machines connect).
set -euo pipefail
root=$(cd "$(dirname "$0")/.." && pwd)
build_dir=${BUILD_DIR:-$root/build}

bash "$root/scripts/build.sh" --target sl_sensord slctl sl_view
export CYCLONEDDS_URI=${CYCLONEDDS_URI:-file://$root/config/cyclonedds-loopback.xml}
config=$(mktemp --suffix=.yaml)
sed "s/^  publish_projector_maps: false$/  publish_projector_maps: false\n  publish_images: true/" \
  "$root/config/sim.yaml" > "$config"
grep -q "publish_images: true" "$config" || { echo "run-view: cannot enable publish_images" >&2; exit 1; }
"$build_dir/daemon/sl_sensord" --config "$config" &
daemon=$!
trap 'kill $daemon 2>/dev/null; wait $daemon 2>/dev/null; rm -f "$config"' EXIT
"$build_dir/tools/sl_view/sl_view" "$@"
