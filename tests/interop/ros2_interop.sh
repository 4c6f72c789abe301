#!/usr/bin/env bash
# ROS 2 interoperability without ROS: sl_sensord on the simulated sensor
# publishes on rt/<ns>/points through Cyclone DDS; an eProsima Fast DDS
# subscriber (types from ros2_idl/ via fastddsgen) and a Cyclone DDS
# subscriber (the daemon's types) both receive the clouds of
# `slctl scan --count 3`, and every field of every cloud must be equal:
# header stamp and frame_id, height, width, fields, is_bigendian, point_step,
# row_step, the data bytes (length + FNV-1a hash), is_dense.
# All traffic stays on 127.0.0.1, unicast only. Every wait is bounded.
# usage: ros2_interop.sh SOURCE_DIR BINARY_DIR
set -euo pipefail
# shellcheck source=../support/daemon.sh
source "$1/tests/support/daemon.sh"
sl_enter_netns "$0" "$@"
sl_init "$1" "$2"
export FASTRTPS_DEFAULT_PROFILES_FILE=$src/config/fastdds-loopback.xml
start=$SECONDS
clouds=3

# 0. ros2_idl/ against the message definitions in Debian's ros-sensor-msgs /
# ros-std-msgs (ROS 1 .msg files; the ROS 2 definitions of these messages
# have the same fields except that ROS 2's Header has no seq and its stamp is
# builtin_interfaces/Time). Each field, in order, with its type mapped as
# ROS 2 maps it to IDL.
msg_fields() {  # FILE -> "type name" per field, constants and comments left out
  sed 's/#.*//' "$1" | awk 'NF >= 2 && $0 !~ /=/ { print $1, $2 }'
}
idl_fields() {  # FILE STRUCT -> "type name" per member, ROS type names
  awk -v s="$2" '$1 == "struct" && $2 == s { on = 1; next } on && /};/ { on = 0 }
    on { sub(/\/\/.*/, ""); sub(/;/, ""); if (NF >= 2) { name = $NF; $NF = ""; print $0 "|" name } }' "$1" |
    sed -e 's/ *|/ /' \
      -e 's/^unsigned long /uint32 /; s/^long /int32 /; s/^octet /uint8 /; s/^boolean /bool /' \
      -e 's/^sequence<octet> /uint8[] /' \
      -e 's/^sequence<sensor_msgs::msg::dds_::\([A-Za-z]*\)_> /\1[] /' \
      -e 's/^std_msgs::msg::dds_::Header_ /Header /; s/^builtin_interfaces::msg::dds_::Time_ /time /'
}
if [ -d /usr/share/sensor_msgs/msg ] && [ -d /usr/share/std_msgs/msg ]; then
  for m in sensor_msgs/PointCloud2 sensor_msgs/PointField sensor_msgs/Image std_msgs/Header; do
    name=${m#*/}
    want=$(msg_fields "/usr/share/${m%/*}/msg/$name.msg")
    [ "$name" = Header ] && want=$(echo "$want" | grep -v '^uint32 seq$')
    got=$(idl_fields "$src/tests/interop/ros2_idl/$name.idl" "${name}_")
    [ -n "$want" ] && [ "$want" = "$got" ] ||
      fail "ros2_idl/$name.idl does not match $m.msg: $(diff <(echo "$want") <(echo "$got") | tr '\n' ' ')"
  done
  echo "ok: ros2_idl/ matches the .msg definitions of PointCloud2, PointField, Image, Header"
else
  echo "note: ros-sensor-msgs not installed, IDL vs .msg check skipped"
fi

ns="interop_$$_$RANDOM"
sl_sim_config "$ns" "$work/sim.yaml"
topic="rt/$ns/points"

sl_start_daemon "$work/sim.yaml" "$work/daemon.log"
"$bin/tests/interop/fastdds_points_subscriber" --topic "$topic" --count $clouds --timeout 45 \
  > "$work/fastdds.log" 2> "$work/fastdds.err" &
pids+=($!)
fastdds_pid=$!
"$bin/tests/interop/cyclone_points_subscriber" --topic "$topic" --count $clouds --timeout 45 \
  > "$work/cyclone.log" 2> "$work/cyclone.err" &
pids+=($!)
cyclone_pid=$!

# Both subscribers must have matched the daemon's cloud writer before the
# scan is requested (volatile topic: a reader that joins late misses clouds).
for _ in $(seq 1 200); do
  grep -q '^ready' "$work/fastdds.log" && grep -q '^ready' "$work/cyclone.log" && break
  kill -0 "$daemon_pid" 2>/dev/null || fail "sl_sensord exited"
  sleep 0.1
done
grep -q '^ready' "$work/cyclone.log" || fail "Cyclone subscriber did not match the daemon in 20 s"
grep -q '^ready' "$work/fastdds.log" ||
  fail "Fast DDS subscriber did not discover the daemon's writer on $topic in 20 s"
echo "ok: both subscribers matched the daemon's writer after $((SECONDS - start)) s"
# The readers have matched the writer; give the writer's side of discovery
# (it must learn the readers' locators) time to complete before the first
# volatile sample is written.
sleep 5

# Fast DDS must use 127.0.0.1 only (no multicast, no other interface): every
# UDP socket it opened is bound to 127.0.0.1.
if command -v ss > /dev/null; then
  ss -uanp | grep "pid=$fastdds_pid," | awk '{ print $4 }' > "$work/fastdds.sockets" || true
  [ -s "$work/fastdds.sockets" ] || fail "no UDP sockets of the Fast DDS subscriber found"
  if grep -v '^127\.0\.0\.1:' "$work/fastdds.sockets"; then
    fail "Fast DDS bound sockets outside 127.0.0.1"
  fi
  echo "ok: Fast DDS sockets all on 127.0.0.1: $(tr '\n' ' ' < "$work/fastdds.sockets")"
fi

# One scan at a time, each once both subscribers hold the previous cloud: a
# Fast DDS reader on a loaded machine may otherwise still be reassembling a
# 25 MB sample when the next replaces it in its keep-last history (seen in CI
# under load: 1 of 3 clouds); the comparison below stays strict.
for i in $(seq 1 $clouds); do
  "$bin/tools/slctl" --ns "$ns" --timeout 20 scan --count 1 --out "$work/scans_$i" \
    >> "$work/slctl.log" 2>&1 || fail "slctl scan $i failed"
  for _ in $(seq 1 150); do
    [ "$(grep -c '^cloud ' "$work/cyclone.log")" -ge "$i" ] && break
    sleep 0.1
  done
  for _ in $(seq 1 30); do
    [ "$(grep -c '^cloud ' "$work/fastdds.log")" -ge "$i" ] && break
    sleep 0.1
  done
done
cat "$work/slctl.log"

wait "$cyclone_pid" || fail "Cyclone subscriber did not receive $clouds clouds"
# Clouds written before the daemon's writer has matched the Fast DDS reader
# are not sent to it (volatile durability): without the wait above, 1-2 of 3
# were missed. With it, every cloud must arrive.
for _ in $(seq 1 50); do kill -0 "$fastdds_pid" 2>/dev/null || break; sleep 0.1; done
kill "$fastdds_pid" 2>/dev/null || true
wait "$fastdds_pid" 2>/dev/null || true

grep '^cloud ' "$work/cyclone.log" | sort > "$work/cyclone.clouds"
grep '^cloud ' "$work/fastdds.log" | sort > "$work/fastdds.clouds"
[ "$(wc -l < "$work/cyclone.clouds")" -eq $clouds ] || fail "Cyclone: not $clouds cloud lines"
fastdds_count=$(wc -l < "$work/fastdds.clouds")
[ "$fastdds_count" -eq $clouds ] || fail "Fast DDS received $fastdds_count of $clouds clouds"
[ "$(sort -u "$work/cyclone.clouds" | cut -d' ' -f2 | sort -u | wc -l)" -eq $clouds ] ||
  fail "the $clouds clouds do not have distinct stamps"

# What the daemon publishes (README "Topics"): an organized 1440 x 1080
# cloud of float32 x, y, z, intensity, 16-byte little-endian points, with
# NaN for invalid pixels.
expected=" height=1080 width=1440 fields=x:0:7:1,y:4:7:1,z:8:7:1,intensity:12:7:1"
expected+=" is_bigendian=0 point_step=16 row_step=23040 data_bytes=24883200 "
while read -r line; do
  case "$line" in
    *"$expected"*is_dense=0) ;;
    *) fail "unexpected cloud from the daemon: $line" ;;
  esac
done < "$work/cyclone.clouds"
grep -q "frame_id=sl_camera_optical_frame " "$work/cyclone.clouds" || fail "unexpected frame_id"

while read -r line; do
  grep -qxF "$line" "$work/cyclone.clouds" || fail "Fast DDS received a cloud Cyclone did not: $line"
done < "$work/fastdds.clouds"
echo "Fast DDS received all $fastdds_count clouds, each identical to the Cyclone copy:"
cat "$work/fastdds.clouds"

sl_stop_daemon
echo "ok: finished in $((SECONDS - start)) s"
echo "1 passed, 0 failed"
