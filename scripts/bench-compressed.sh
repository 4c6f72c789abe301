#!/bin/bash
# What a reader of the compressed image topics costs the daemon: sl_sensord
# on config/sim.yaml with dds.publish_images, continuous 3+3_horizontal scans
# for SECONDS, with one reader of shading/image/compressed and
# depth/image_rect/compressedDepth (tests/ros2/raw_topic_dump, counting
# only), then `slctl status` (medians of the last 64 scans) and the samples
# the reader got. Each build directory given is run in turn, ROUNDS times
# alternated, so that two builds (e.g. before / after a change) are compared
# in one run.
# Usage: scripts/bench-compressed.sh SECONDS ROUNDS BUILD_DIR...   (each with
#        daemon/sl_sensord, tools/slctl; tests/ros2/raw_topic_dump from the first)
set -euo pipefail
cd "$(dirname "$0")/.."
seconds=$1 rounds=$2
shift 2
dump="$1/tests/ros2/raw_topic_dump"
export CYCLONEDDS_URI=file://$PWD/config/cyclonedds-loopback.xml
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT
echo "load average at start: $(cut -d' ' -f1-3 /proc/loadavg)"
for round in $(seq 1 "$rounds"); do
  for build in "$@"; do
    ns=cbench_${round}_$$_$RANDOM
    sed "s/^  namespace: sl$/  namespace: $ns/" config/sim.yaml > "$tmp/$ns.yaml"
    sed -i 's/^  publish_projector_maps: false$/  publish_projector_maps: false\n  publish_images: true/' "$tmp/$ns.yaml"
    grep -q "publish_images: true" "$tmp/$ns.yaml" || { echo "could not enable publish_images" >&2; exit 1; }
    "$build/daemon/sl_sensord" --config "$tmp/$ns.yaml" > "$tmp/$ns.log" 2>&1 &
    pid=$!
    sleep 4
    "$dump" - $((seconds + 6)) 1000000 \
      shading=rt/$ns/shading/image/compressed=CompressedImage \
      depth=rt/$ns/depth/image_rect/compressedDepth=CompressedImage > /dev/null 2> "$tmp/$ns.dump" &
    dump_pid=$!
    sleep 1
    "$build/tools/slctl" --ns "$ns" start --pattern 3+3_horizontal > /dev/null
    sleep "$seconds"
    echo "== $build, round $round (load $(cut -d' ' -f1 /proc/loadavg))"
    "$build/tools/slctl" --ns "$ns" status | grep -E "^(scans|latency|sets dropped|images)" || true
    "$build/tools/slctl" --ns "$ns" stop > /dev/null
    wait "$dump_pid" || true
    sed 's/^raw_topic_dump: /compressed reader: /' "$tmp/$ns.dump" | grep -E "samples" || true
    kill "$pid"
    wait "$pid" || true
  done
done
