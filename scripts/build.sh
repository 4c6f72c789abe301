#!/usr/bin/env bash
# Installs the dependencies (if missing) and builds sl-sensor in Release into
# build/ (override with BUILD_DIR). Extra arguments are passed to
# `cmake --build` (e.g. --target sl_sensord).
set -euo pipefail
root=$(cd "$(dirname "$0")/.." && pwd)
build_dir=${BUILD_DIR:-$root/build}

bash "$root/scripts/install-deps.sh"
cmake -S "$root" -B "$build_dir" -DCMAKE_BUILD_TYPE=Release >/dev/null
cmake --build "$build_dir" -j"$(nproc)" "$@"
