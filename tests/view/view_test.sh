#!/usr/bin/env bash
# Live view, MCAP and ROS 2 wire format (issue 18), against sl_sensord on the
# simulated sensor (unique namespace, depth/shading images on):
#   wire     the bridge's and an MCAP file's samples decoded by Foxglove's
#            ROS 2 deserializer == what Cyclone delivered to view_reference
#   browser  the web page in headless Chromium starts a scan and shows a
#            cloud of the expected size (screenshot kept as an artefact)
#   stalled  a viewer that stops reading does not slow the sensor
#   sets     image sets recorded as MCAP, decoded by Foxglove's deserializer
#            with the file's sl_msgs/msg/ImageSet schema
#   starved  sl_view itself stopped does not slow the sensor (its default
#            reliable readers), and the clouds it missed meanwhile are counted
# usage: view_test.sh MODE SOURCE_DIR BINARY_DIR
set -euo pipefail
mode=$1
src=$2
bin=$3
export CYCLONEDDS_URI=${CYCLONEDDS_URI:-file://$src/config/cyclonedds-loopback.xml}
node_dir=$src/tools/sl_view
artefacts=$bin/tests/view/artefacts
mkdir -p "$artefacts"
work=$(mktemp -d)
pids=()
cleanup() {
  for p in "${pids[@]}"; do kill "$p" 2>/dev/null || true; done
  sleep 0.2
  for p in "${pids[@]}"; do kill -9 "$p" 2>/dev/null || true; done
  rm -rf "$work"
}
trap cleanup EXIT
fail() {
  echo "FAIL: $*" >&2
  for f in "$work"/*.log; do [ -f "$f" ] && { echo "--- $(basename "$f")"; tail -n 20 "$f"; } >&2; done
  exit 1
}
[ -d "$node_dir/node_modules/@foxglove/rosmsg2-serialization" ] ||
  fail "npm packages missing: run scripts/install-deps.sh (npm ci in tools/sl_view)"

ns="view_${mode}_$$_$RANDOM"
sed -e "s/^  namespace: sl$/  namespace: $ns/" \
    -e "s/^  publish_projector_maps: false$/  publish_projector_maps: false\n  publish_images: true/" \
    "$src/config/sim.yaml" > "$work/sim.yaml"
grep -q "namespace: $ns" "$work/sim.yaml" && grep -q "publish_images: true" "$work/sim.yaml" ||
  fail "could not set the namespace / publish_images in a copy of config/sim.yaml"
# The wire check needs every sample sl_view got in its keep-all reference
# reader too, which writes each to disk: in that mode the writers keep 16
# samples (not 4 clouds / 2 images) so that its first, slowest seconds lose
# none (it lost some in 2 of 3 runs).
if [ "$mode" = wire ]; then
  sed -i "s/^  publish_images: true$/  publish_images: true\n  qos:\n    points: {depth: 16}\n    images: {depth: 16}/" "$work/sim.yaml"
  grep -q "images: {depth: 16}" "$work/sim.yaml" || fail "could not set dds.qos in a copy of config/sim.yaml"
fi
if [ "$mode" = sets ]; then
  sed -i "s/^  publish_images: true$/  publish_images: true\n  publish_image_sets: true/" "$work/sim.yaml"
  grep -q "publish_image_sets: true" "$work/sim.yaml" || fail "could not set publish_image_sets"
fi

"$bin/daemon/sl_sensord" --config "$work/sim.yaml" > "$work/daemon.log" 2>&1 &
pids+=($!)
# VIEW_ARGS: options for sl_view (default: none, i.e. its default reliable
# keep-last-1 readers; the live view used best-effort ones until a whole
# 25 MB cloud was seen never to arrive in 30 s, README).
"$bin/tools/sl_view/sl_view" --ns "$ns" --port 0 ${VIEW_ARGS:-} > "$work/view.log" 2>&1 &
pids+=($!)
view_pid=$!
for _ in $(seq 100); do grep -q "live view at" "$work/view.log" && break; sleep 0.1; done
port=$(grep -o "http://127.0.0.1:[0-9]*" "$work/view.log" | grep -o "[0-9]*$") || fail "sl_view did not start"
for _ in $(seq 150); do grep -q "ready" "$work/daemon.log" && break; sleep 0.1; done
grep -q "ready" "$work/daemon.log" || fail "the daemon did not get ready"

start_reference() {  # COUNT DIR
  mkdir -p "$2"
  "$bin/tests/view/view_reference" --ns "$ns" --out "$2" --count "$1" --timeout 100 \
    > "$work/reference.log" 2>&1 &
  ref_pid=$!
  pids+=($ref_pid)
  for _ in $(seq 200); do grep -q "ready" "$work/reference.log" && return; sleep 0.05; done
  fail "view_reference did not match the daemon's writers"
}

case $mode in
wire)
  # One reference subscriber for the whole test: its files are named by stamp.
  start_reference 0 "$work/ref"
  # 1. From the bridge: the check starts a continuous scan through the
  # bridge's command service, compares 2 of each, and stops it.
  node "$node_dir/test/wire_check.mjs" --ref "$work/ref" --ws "ws://127.0.0.1:$port" \
    --ns "$ns" --count 2 || fail "wire check (bridge)"
  # 2. From MCAP files (zstd, lz4 and uncompressed chunks) by sl_view record.
  for compression in zstd lz4 none; do
    n=2; [ $compression = zstd ] || n=1
    "$bin/tools/sl_view/sl_view" record "$work/rec_$compression.mcap" --ns "$ns" --scan 0 \
      --count $n --compression $compression > "$work/record.log" 2>&1 || fail "sl_view record"
    cat "$work/record.log"
    node "$node_dir/test/wire_check.mjs" --ref "$work/ref" \
      --mcap "$work/rec_$compression.mcap" --ns "$ns" --count $n || fail "wire check (mcap $compression)"
  done
  cp "$work/rec_zstd.mcap" "$artefacts/sl_view_record.mcap"
  ;;
browser)
  # sim.yaml's camera is 1440 x 1080; sl_view decimates by 4 for the page.
  node "$node_dir/test/browser_check.mjs" --url "http://127.0.0.1:$port/" --width 360 --height 270 \
    --screenshot "$artefacts/sl_view_page.png" || fail "browser check"
  echo "screenshot: $artefacts/sl_view_page.png"
  ;;
stalled)
  node "$node_dir/test/stalled_check.mjs" --ws "ws://127.0.0.1:$port" \
    --stats "http://127.0.0.1:$port/stats" --ns "$ns" --scans 8 --queue 2 || fail "stalled viewer check"
  ;;
sets)
  "$bin/tools/sl_view/sl_view" record "$work/sets.mcap" --ns "$ns" --scan 2 \
    --topics "/$ns/points,/$ns/image_sets" > "$work/record.log" 2>&1 || fail "sl_view record"
  cat "$work/record.log"
  # sim.yaml: camera sim_top, 1440 x 1080, 8 bits, 3+3 pattern (6 frames).
  node "$node_dir/test/image_sets_check.mjs" --mcap "$work/sets.mcap" --ns "$ns" --camera sim_top \
    --frames 6 --width 1440 --height 1080 --count 2 || fail "image sets check"
  ;;
starved)
  # sl_view itself stopped (a process starved of CPU) while a viewer
  # subscribes to the clouds and images: the daemon keeps scanning and no
  # DDS write times out (its keep-last writers drop the oldest cloud for the
  # stopped reader only). sl_view then counts the clouds it missed: every
  # cloud published while it was stopped but those the writer's history (4)
  # and its own (1) kept, give or take the one in flight.
  node -e '
    const WebSocket = require(process.argv[1] + "/node_modules/ws");
    const ws = new WebSocket(process.argv[2], ["foxglove.websocket.v1"]);
    ws.on("message", (data, binary) => {
      if (binary) return;
      const m = JSON.parse(data.toString());
      if (m.op !== "advertise") return;
      const subscriptions = m.channels.filter((c) => /points$|image$|camera_info$/.test(c.topic))
        .map((c, i) => ({ id: i, channelId: c.id }));
      ws.send(JSON.stringify({ op: "subscribe", subscriptions }));
      console.log(`subscribed to ${subscriptions.length} channels`);
    });' "$node_dir" "ws://127.0.0.1:$port" > "$work/viewer.log" 2>&1 &
  pids+=($!)
  for _ in $(seq 100); do grep -q "subscribed to 4" "$work/viewer.log" && break; sleep 0.1; done
  grep -q "subscribed to 4" "$work/viewer.log" || fail "the viewer did not subscribe"
  sleep 1  # sl_view creates the readers; discovery
  before=$("$bin/tools/slctl" --ns "$ns" status | sed -n 's/.*write timed out \([0-9]*\).*/\1/p')
  kill -STOP "$view_pid"
  "$bin/tools/slctl" --ns "$ns" start > "$work/scan.log" 2>&1 || { kill -CONT "$view_pid"; fail "slctl start"; }
  sleep 4
  status=$("$bin/tools/slctl" --ns "$ns" status)
  "$bin/tools/slctl" --ns "$ns" stop >> "$work/scan.log" 2>&1 || true
  kill -CONT "$view_pid"
  after=$(echo "$status" | sed -n 's/.*write timed out \([0-9]*\).*/\1/p')
  scans=$(echo "$status" | awk '/^scans:/ { print $2 }')
  echo "$status" | grep -E "^scans|sets dropped"
  [ -n "$before" ] && [ -n "$after" ] || fail "no 'write timed out' count in slctl status"
  [ "$after" -eq "$before" ] || fail "$((after - before)) DDS writes timed out while sl_view was stopped"
  [ "${scans:-0}" -ge 1 ] || fail "no scan published while sl_view was stopped"
  sleep 0.5
  kill -0 "$view_pid" 2>/dev/null || fail "sl_view did not survive"
  sleep 2  # the status after the stop reaches sl_view
  node -e '
    (async () => {
    const d = (await (await fetch(process.argv[1])).json()).dds, during = Number(process.argv[2]);
    console.log(`sl_view: ${d.reliable ? "reliable" : "best-effort"} readers; clouds missed ${d.clouds_missed} of ${d.clouds_published_while_read} published while read; ${during} scans while stopped`);
    if (!d.topics.some((t) => /points$/.test(t.topic) && t.taken >= 0)) { console.error("no points topic in /stats dds"); process.exit(1); }
    if (d.clouds_published_while_read < during) { console.error("fewer clouds published while read than scans while stopped"); process.exit(1); }
    if (d.clouds_missed < during - 6) { console.error(`only ${d.clouds_missed} clouds counted missed, ${during} published while sl_view was stopped`); process.exit(1); }
    })().catch((e) => { console.error(e); process.exit(1); });
  ' "http://127.0.0.1:$port/stats" "$scans" || fail "the clouds missed while sl_view was stopped are not counted"
  ;;
*) fail "unknown mode $mode" ;;
esac
echo "ok: $mode"
