#!/usr/bin/env bash
# Installs the Debian 12 packages sl-sensor needs to build, run and test.
# Idempotent: packages already present are skipped, and `apt-get update` runs
# only when something is missing. Must run as root (or with sudo available).
set -euo pipefail

packages=(
  build-essential cmake pkg-config git
  cyclonedds-dev cyclonedds-tools
  libeigen3-dev
  libopencv-dev
  libyaml-cpp-dev
  libexpat1-dev   # well-formedness check of XML calibration files before OpenCV parses them
  catch2
  libbenchmark-dev
  libaravis-dev
  libusb-1.0-0-dev   # aravis-0.8.pc requires it (Requires.private), Debian does not pull it in
  libhidapi-dev
  pcl-tools
  libopen3d-dev   # sl_register: ICP, normals, kd-trees, pose-graph optimisation
  systemd
  iproute2   # ss: the interop test checks Fast DDS binds only 127.0.0.1
  # Fast DDS: the daemon's ROS 2 services for rmw_fastrtps clients
  # (dds/, sl_dds_fastdds; optional at build time) and the ROS 2 interop
  # test (tests/interop) with Fast DDS's IDL code generator
  # (Java: pulls default-jre-headless) and the sensor_msgs/std_msgs .msg
  # definitions the test checks its IDL against.
  libfastrtps-dev fastddsgen ros-sensor-msgs
  # ROS 2 interfaces (ros2/sl_msgs, idl/): ament_cmake and rosidl build the
  # interface package in CI; rosidl_adapter/rosidl_parser (python3-rosidl)
  # turn its .msg/.srv into the daemon's DDS IDL at build time.
  ament-cmake rosidl-core rosidl-cmake rosidl-generator-c-cpp python3-rosidl
  librosidl-typesupport-introspection-c-cpp-dev
  # Cyclone DDS shared memory (config/cyclonedds-shm.xml): the RouDi daemon.
  iceoryx
  # sl_view (tools/sl_view): WebSockets (websocketpp over Boost.Asio), JSON,
  # MCAP chunk compression; Node.js + npm for the web page's three.js and the
  # wire-format / browser tests; Chromium for the headless page test.
  libwebsocketpp-dev libboost-dev libboost-system-dev libjsoncpp-dev libzstd-dev liblz4-dev
  zlib1g-dev   # CRC-32 of MCAP records (sl_view record, MCAP replay)
  nodejs chromium
  # DDS Security material (scripts/dds-security.sh, test dds_security); the
  # plugins themselves come with libddsc0debian (cyclonedds-dev's dependency).
  openssl
  # libFuzzer targets (scripts/fuzz.sh, SL_BUILD_FUZZERS=ON): clang with libFuzzer.
  clang-14 libfuzzer-14-dev
)
# Debian's npm package; a Node.js that brings its own npm (e.g. NodeSource's
# nodejs) conflicts with it, so it is asked for only when npm is missing.
command -v npm >/dev/null 2>&1 || packages+=(npm)

missing=()
for p in "${packages[@]}"; do
  if ! dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed"; then
    missing+=("$p")
  fi
done

if [ ${#missing[@]} -eq 0 ]; then
  echo "install-deps: all ${#packages[@]} packages present"
else
  SUDO=""
  if [ "$(id -u)" -ne 0 ]; then SUDO="sudo"; fi
  echo "install-deps: installing ${missing[*]}"
  export DEBIAN_FRONTEND=noninteractive
  $SUDO apt-get update -qq
  $SUDO apt-get install -y -qq --no-install-recommends "${missing[@]}"
fi

# npm packages of sl_view (three.js for the web page; Foxglove's ROS 2
# deserializer, @mcap/core and playwright-core for the tests), exactly as
# tools/sl_view/package-lock.json pins them, from the npm registry. Skipped
# when node_modules already matches the lock file.
view_dir=$(cd "$(dirname "$0")/.." && pwd)/tools/sl_view
if ! cmp -s "$view_dir/package-lock.json" "$view_dir/node_modules/.package-lock.json.installed" 2>/dev/null; then
  echo "install-deps: npm ci in tools/sl_view"
  (cd "$view_dir" && npm ci --no-audit --no-fund --loglevel=error)
  cp "$view_dir/package-lock.json" "$view_dir/node_modules/.package-lock.json.installed"
fi
