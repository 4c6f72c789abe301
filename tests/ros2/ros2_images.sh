#!/usr/bin/env bash
# The daemon's images as image_transport / depth_image_proc take them (issue
# 31 item 6): sl_sensord on the simulated sensor (lens with distortion),
# publish_images on; one scan's /points, depth/image_rect,
# depth/camera_info, depth/image, camera_info, shading/camera_info and the
# compressed siblings (shading/image/compressed, .../compressedDepth) taken
# as raw samples (raw_topic_dump) and checked by
# tools/sl_view/test/images_check.mjs with Foxglove's ROS 2 deserializer.
# Files (issue 31 item 7): that scan's PLY (slctl's default: metres) and a
# second scan's PCD (--units mm), read back by the Point Cloud Library
# (pcl-tools), against their /points (tools/sl_view/test/files_check.mjs).
# usage: ros2_images.sh SOURCE_DIR BINARY_DIR
set -euo pipefail
# shellcheck source=../support/daemon.sh
source "$1/tests/support/daemon.sh"
sl_enter_netns "$0" "$@"
sl_init "$1" "$2"
[ -d "$src/tools/sl_view/node_modules/@foxglove/rosmsg2-serialization" ] ||
  fail "npm packages missing: run scripts/install-deps.sh (npm ci in tools/sl_view)"

ns="images_$$_$RANDOM"
sl_sim_config "$ns" "$work/sim.yaml" \
  "s/^  publish_projector_maps: false$/  publish_projector_maps: false\n  publish_images: true/"
grep -q "publish_images: true" "$work/sim.yaml" || fail "could not enable publish_images"
sl_start_daemon "$work/sim.yaml" "$work/daemon.log"
sl_wait_ready "$work/daemon.log"

mkdir -p "$work/samples"
"$bin/tests/ros2/raw_topic_dump" "$work/samples" 60 1 \
  "points=rt/$ns/points=PointCloud2" \
  "rect=rt/$ns/depth/image_rect=Image" "rect_info=rt/$ns/depth/camera_info=CameraInfo" \
  "raw=rt/$ns/depth/image=Image" "raw_info=rt/$ns/camera_info=CameraInfo" \
  "shading_info=rt/$ns/shading/camera_info=CameraInfo" "shading=rt/$ns/shading/image=Image" \
  "shading_png=rt/$ns/shading/image/compressed=CompressedImage" \
  "depth_png=rt/$ns/depth/image_rect/compressedDepth=CompressedImage" \
  > "$work/dump.log" 2>&1 &
dump_pid=$!
sl_track "$dump_pid"
for _ in $(seq 1 200); do
  grep -q '^ready' "$work/dump.log" && break
  kill -0 "$dump_pid" 2>/dev/null || fail "raw_topic_dump exited"
  sleep 0.1
done
grep -q '^ready' "$work/dump.log" || fail "raw_topic_dump did not match the daemon's writers in 20 s"
sleep 1  # the writers' side of discovery (volatile topics)
"$bin/tools/slctl" scan --count 1 --out "$work/scan" --ns "$ns" > "$work/slctl.log" 2>&1 ||
  fail "slctl scan failed"
wait "$dump_pid" || fail "raw_topic_dump did not get one sample of every topic"
node "$src/tools/sl_view/test/images_check.mjs" "$work/samples" || fail "images_check failed"

# dump_one DIR: one /points sample into DIR (in the background; dump_pid).
dump_one() {
  mkdir -p "$1"
  "$bin/tests/ros2/raw_topic_dump" "$1" 60 1 "points=rt/$ns/points=PointCloud2" > "$1/dump.log" 2>&1 &
  dump_pid=$!
  sl_track "$dump_pid"
  for _ in $(seq 1 200); do
    grep -q '^ready' "$1/dump.log" && break
    sleep 0.1
  done
  grep -q '^ready' "$1/dump.log" || fail "raw_topic_dump did not match the daemon's points writer"
  sleep 1
}
command -v pcl_ply2pcd > /dev/null && command -v pcl_convert_pcd_ascii_binary > /dev/null ||
  fail "pcl-tools missing (scripts/install-deps.sh installs it)"
ply="$work/scan/scan_0001.ply"
head -c 300 "$ply" | grep -aq "^comment units m$" || fail "$ply: not in metres by default"
pcl_ply2pcd -format 0 "$ply" "$work/ply.pcd" > "$work/pcl.log" 2>&1 || fail "PCL cannot read $ply"
pcl_convert_pcd_ascii_binary "$work/ply.pcd" "$work/ply_ascii.pcd" 0 >> "$work/pcl.log" 2>&1 ||
  fail "PCL cannot convert the PLY's PCD"
node "$src/tools/sl_view/test/files_check.mjs" ply "$work/samples/points_1.cdr" "$work/ply_ascii.pcd" ||
  fail "the PLY read by PCL is not /points in metres"

dump_one "$work/samples_pcd"
"$bin/tools/slctl" scan --count 1 --out "$work/pcd" --format pcd --units mm --ns "$ns" > "$work/slctl.log" 2>&1 ||
  fail "slctl scan --format pcd --units mm failed"
wait "$dump_pid" || fail "raw_topic_dump did not get the PCD scan's cloud"
pcl_convert_pcd_ascii_binary "$work/pcd/scan_0001.pcd" "$work/pcd_ascii.pcd" 0 >> "$work/pcl.log" 2>&1 ||
  fail "PCL cannot read the PCD"
node "$src/tools/sl_view/test/files_check.mjs" pcd-mm "$work/samples_pcd/points_1.cdr" "$work/pcd_ascii.pcd" ||
  fail "the PCD read by PCL is not /points, organized, in millimetres"
sl_stop_daemon
echo "ok: ros2_images"
