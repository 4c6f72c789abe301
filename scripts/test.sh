#!/usr/bin/env bash
# README command (b): install, build and run the whole test suite (ctest).
set -euo pipefail
root=$(cd "$(dirname "$0")/.." && pwd)
build_dir=${BUILD_DIR:-$root/build}

bash "$root/scripts/build.sh"
export CYCLONEDDS_URI=file://$root/config/cyclonedds-loopback.xml
cd "$build_dir"
ctest --output-on-failure --timeout 900 "$@"
