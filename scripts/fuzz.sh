#!/usr/bin/env bash
# libFuzzer runs of the fuzz/ targets (docs/testing.md, "Sanitizers and fuzzing"). Builds them with
# clang into build-fuzz/ (SL_BUILD_FUZZERS=ON: ASan + UBSan + coverage) and
# runs each for SECONDS (default 600) on a copy of its seed corpus in
# build-fuzz/corpus/<name> (new inputs accumulate there, fuzz/corpus/ stays as
# committed). Findings (crash-*, timeout-*, oom-*) land in
# build-fuzz/findings/<name>/; the log with -print_final_stats=1 in
# build-fuzz/logs/<name>.log.
#
#   bash scripts/fuzz.sh                       # all targets, one after another
#   SECONDS_PER_TARGET=60 bash scripts/fuzz.sh fuzz_ply fuzz_config
#   PARALLEL=2 nice -n 19 bash scripts/fuzz.sh # two at a time
# Exit status: non-zero if a target reported a finding.
set -uo pipefail
root=$(cd "$(dirname "$0")/.." && pwd)
dir=${BUILD_DIR:-$root/build-fuzz}
seconds=${SECONDS_PER_TARGET:-600}
parallel=${PARALLEL:-1}
all=(fuzz_config fuzz_pattern fuzz_calibration fuzz_ply fuzz_recording fuzz_request)
targets=("$@")
[ ${#targets[@]} -eq 0 ] && targets=("${all[@]}")

export CCACHE_DIR=${CCACHE_DIR:-/work/.ccache} CCACHE_BASEDIR=${CCACHE_BASEDIR:-$(dirname "$root")}
launcher=()
command -v ccache >/dev/null && launcher=(-DCMAKE_CXX_COMPILER_LAUNCHER=ccache -DCMAKE_C_COMPILER_LAUNCHER=ccache)
if [ -z "${NO_BUILD:-}" ]; then
  CC=${CC:-clang-14} CXX=${CXX:-clang++-14} cmake -S "$root" -B "$dir" -DCMAKE_BUILD_TYPE=RelWithDebInfo \
    -DSL_BUILD_FUZZERS=ON -DSL_BUILD_TESTS=OFF -DSL_BUILD_BENCHMARKS=OFF "${launcher[@]}" >/dev/null || exit 1
  cmake --build "$dir" -j"${JOBS:-2}" --target "${targets[@]}" || exit 1
fi

run_one() {
  local name=$1 corpus=$dir/corpus/$1 findings=$dir/findings/$1
  mkdir -p "$corpus" "$findings" "$dir/logs"
  cp -n "$root/fuzz/corpus/${name#fuzz_}"/* "$corpus"/ 2>/dev/null
  export ASAN_OPTIONS=${ASAN_OPTIONS:-detect_leaks=1:allocator_may_return_null=1}
  export UBSAN_OPTIONS=${UBSAN_OPTIONS:-print_stacktrace=1:halt_on_error=1}
  # -rss_limit_mb: a reader must not need GBs for a small input; -timeout:
  # nor seconds. -max_len: config-sized inputs.
  local wrap=() max_len=${MAX_LEN:-8192}
  if [ "$name" = fuzz_request ]; then
    # DDS: the loopback config in a private network namespace when possible.
    export CYCLONEDDS_URI=file://$root/config/cyclonedds-loopback.xml
    unshare -rn true 2>/dev/null && wrap=(unshare -rn sh -c 'ip link set lo up && exec "$0" "$@"')
    max_len=${MAX_LEN:-4096}
  fi
  "${wrap[@]}" "$dir/fuzz/$name" -max_total_time="$seconds" -print_final_stats=1 -rss_limit_mb=2048 \
    -timeout=10 -max_len="$max_len" -artifact_prefix="$findings/" \
    -dict="$root/fuzz/yaml.dict" "$corpus" >"$dir/logs/$name.log" 2>&1
  local rc=$?
  echo "$name: exit $rc; $(grep -E '^stat::(number_of_executed_units|average_exec_per_sec|new_units_added|peak_rss_mb)' "$dir/logs/$name.log" | tr '\n' ' ') $(grep -E '#[0-9]+.*(DONE|cov:)' "$dir/logs/$name.log" | tail -1)"
  return $rc
}

status=0
pids=()
for name in "${targets[@]}"; do
  run_one "$name" &
  pids+=($!)
  if [ ${#pids[@]} -ge "$parallel" ]; then
    wait "${pids[0]}" || status=1
    pids=("${pids[@]:1}")
  fi
done
for pid in "${pids[@]}"; do wait "$pid" || status=1; done
exit $status
