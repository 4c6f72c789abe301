#!/usr/bin/env bash
# Shows that a machine without libaravis-dev and libhidapi-dev still builds
# the simulator daemon and every offline tool, and that the daemon runs. In a
# private mount namespace the two packages' headers and pkg-config files are
# hidden (empty directories / empty files bound over them), a fresh build
# directory is configured with no options (SL_WITH_ARAVIS / SL_WITH_HIDAPI
# then default to OFF), the daemon and the tools are built, and the daemon
# runs on the simulator in a private network namespace until slctl got two
# scans from it. Needs root (unshare); slow (a fresh build): not part of the
# test suite.
#   sudo bash scripts/check-sim-only-build.sh [BUILD_DIR]   (default /tmp/sl-sim-only-build)
set -euo pipefail
root=$(cd "$(dirname "$0")/.." && pwd)
if [[ "${1:-}" != --inside ]]; then
  exec unshare --mount --net --propagation private bash "$0" --inside "$@"
fi
shift
build_dir=${1:-/tmp/sl-sim-only-build}

empty_dir=$(mktemp -d)
empty_file=$(mktemp)
for dir in /usr/include/aravis-0.8 /usr/include/hidapi; do
  if [[ -d $dir ]]; then mount --bind "$empty_dir" "$dir"; echo "hidden: $dir"; fi
done
for pc in /usr/lib/*/pkgconfig/aravis-0.8.pc /usr/lib/*/pkgconfig/hidapi-*.pc /usr/share/pkgconfig/aravis-0.8.pc; do
  if [[ -e $pc ]]; then mount --bind "$empty_file" "$pc"; echo "hidden: $pc"; fi
done
for module in aravis-0.8 hidapi-hidraw; do
  if pkg-config --exists "$module" 2>/dev/null; then echo "FAIL: pkg-config still finds $module"; exit 1; fi
  echo "pkg-config: $module not found"
done
[[ -e /usr/include/aravis-0.8/arv.h || -e /usr/include/hidapi/hidapi.h ]] && { echo "FAIL: headers visible"; exit 1; }

rm -rf "$build_dir"
cmake -S "$root" -B "$build_dir" -DCMAKE_BUILD_TYPE=Release | grep -E "SL_WITH|Aravis|hidapi|Configuring done|Generating done" || true
grep -E "^SL_WITH_(ARAVIS|HIDAPI):" "$build_dir/CMakeCache.txt"
targets=(sl_sensord slctl sl_points_listener sl_process sl_patterns sl_calibrate sl_eval sl_register)
cmake --build "$build_dir" -j"$(nproc)" --target "${targets[@]}" 2>&1 | grep -E "Built target|error|warning" || true
for t in "${targets[@]}"; do
  path=$(find "$build_dir" -type f -name "$t" -perm -u+x | head -1)
  [[ -n $path ]] || { echo "FAIL: $t not built"; exit 1; }
  echo "built: ${path#"$build_dir"/}"
done
if ldd "$build_dir/daemon/sl_sensord" | grep -Ei "aravis|hidapi"; then
  echo "FAIL: sl_sensord links Aravis or hidapi"; exit 1
fi
echo "sl_sensord links neither Aravis nor hidapi"

# The daemon on the simulator (loopback only, in this network namespace).
ip link set lo up
export CYCLONEDDS_URI=file://$root/config/cyclonedds-loopback.xml
log=$(mktemp)
"$build_dir/daemon/sl_sensord" --config "$root/config/sim.yaml" >"$log" 2>&1 &
daemon=$!
trap 'kill "$daemon" 2>/dev/null || true' EXIT
for _ in $(seq 100); do grep -q "ready:" "$log" && break; sleep 0.2; done
grep "ready:" "$log"
scans=$(mktemp -d)
"$build_dir/tools/slctl" scan --count 2 --out "$scans" --timeout 120
ls -l "$scans"
"$build_dir/tools/slctl" status --timeout 10
kill -INT "$daemon"
wait "$daemon" && echo "sl_sensord exited with 0"
trap - EXIT
cat "$log"
echo "sim-only build: OK"
