#!/usr/bin/env bash
# Sanitizer suites: builds the tree with AddressSanitizer + UndefinedBehavior-
# Sanitizer (build-asan/) and with ThreadSanitizer (build-tsan/) and runs the
# test executables that exercise our threads and parsers under each, in a
# private network namespace when possible (DDS traffic stays local).
#
#   bash scripts/sanitize.sh            # both, ASan/UBSan first
#   bash scripts/sanitize.sh asan       # or: tsan
#   TESTS='test_engine|test_pipeline' bash scripts/sanitize.sh tsan
#
# Each suite ends with a summary (date, wall time of the build and of the
# tests, one line per test), also kept in build-<suite>/sanitize-summary.txt
# with the whole ctest output in build-<suite>/sanitize-ctest.log; the
# summaries are what docs/testing.md records.
#
# Not part of scripts/test.sh: the two builds take ~2x a release build each,
# and the tests run 2-15x slower. Timing bounds in the tests are scaled in
# these builds (tests/support/time_scale.h), so a failure here is a finding.
# Exit status: non-zero if any build or test failed.
set -uo pipefail
root=$(cd "$(dirname "$0")/.." && pwd)
which=${1:-all}
jobs=${JOBS:-2}
# Daemon/DDS tests are included: Cyclone itself is not instrumented, which
# ASan does not mind; under TSan races inside Cyclone's own threads are not
# seen (only the accesses of our code), see tests/tsan.supp.
# test_engine under TSan runs its simulated rig at a quarter of the pixels
# (kRigDownscale in tests/daemon/test_engine.cpp) besides the 10x slower
# camera of every sanitizer build.
asan_tests=${TESTS:-test_pipeline|test_engine|test_codecs|test_config|test_replay|test_sim|test_dds|test_drivers_hw|test_messages|test_hardening|test_e2e|e2e_cli|recording_faults}
tsan_tests=${TESTS:-test_pipeline|test_engine|test_replay|test_dds|test_drivers_hw|test_e2e}
targets_for() {
  echo "$1" | tr '|' ' ' | sed -e 's/\be2e_cli\b/sl_sensord slctl sl_points_listener/' \
    -e 's/\brecording_faults\b/sl_sensord slctl recording_check/'
}

export CCACHE_DIR=${CCACHE_DIR:-/work/.ccache} CCACHE_BASEDIR=${CCACHE_BASEDIR:-$(dirname "$root")}
launcher=()
command -v ccache >/dev/null && launcher=(-DCMAKE_CXX_COMPILER_LAUNCHER=ccache -DCMAKE_C_COMPILER_LAUNCHER=ccache)

run_suite() {  # name sanitizers tests
  local name=$1 sanitize=$2 tests=$3 dir=$root/build-$1
  echo "=== $name: -fsanitize=$sanitize, build in $dir"
  local t0 t1 t2 rc
  t0=$(date +%s)
  cmake -S "$root" -B "$dir" -DCMAKE_BUILD_TYPE=RelWithDebInfo -DSL_SANITIZE="$sanitize" \
    -DSL_BUILD_BENCHMARKS=OFF "${launcher[@]}" >/dev/null || return 1
  # shellcheck disable=SC2046
  cmake --build "$dir" -j"$jobs" --target $(targets_for "$tests") || return 1
  t1=$(date +%s)
  # Each test's TIMEOUT property is already x10 in these builds
  # (SL_TEST_TIMEOUT_SCALE); --timeout bounds only the tests without one.
  local ctest_cmd="cd '$dir' && ctest --output-on-failure --timeout 1800 -R '^($tests)\$'"
  local started
  started=$(date -u '+%Y-%m-%d %H:%M')
  export CYCLONEDDS_URI=file://$root/config/cyclonedds-loopback.xml
  # new_delete_type_mismatch=0: Debian's libfastrtps 2.9 (the daemon's Fast DDS
  # participant, not instrumented) deletes an RTPSReader with a smaller size
  # than it allocated when its participant's entities are deleted
  # (~RTPSReader <- DomainParticipantImpl::delete_contained_entities); every
  # daemon exit aborted on it (docs/testing.md).
  export ASAN_OPTIONS=${ASAN_OPTIONS:-detect_leaks=1:abort_on_error=0:detect_stack_use_after_return=0:new_delete_type_mismatch=0}
  export UBSAN_OPTIONS=${UBSAN_OPTIONS:-print_stacktrace=1:halt_on_error=1}
  export LSAN_OPTIONS=${LSAN_OPTIONS:-suppressions=$root/tests/lsan.supp}
  export TSAN_OPTIONS=${TSAN_OPTIONS:-halt_on_error=0:second_deadlock_stack=1:suppressions=$root/tests/tsan.supp}
  local log=$dir/sanitize-ctest.log
  if unshare -rn true 2>/dev/null; then
    unshare -rn sh -c "ip link set lo up && $ctest_cmd" 2>&1 | tee "$log"
  elif unshare -n true 2>/dev/null; then
    unshare -n sh -c "ip link set lo up && $ctest_cmd" 2>&1 | tee "$log"
  else
    sh -c "$ctest_cmd" 2>&1 | tee "$log"
  fi
  rc=${PIPESTATUS[0]}
  t2=$(date +%s)
  {
    echo "=== $name summary: tree $(git -C "$root" rev-parse --short HEAD 2>/dev/null)$(
      git -C "$root" diff --quiet HEAD 2>/dev/null || echo '+changes'), tests from $started to" \
      "$(date -u '+%H:%M') UTC, build $((t1 - t0)) s, tests $((t2 - t1)) s, load $(cut -d' ' -f1-3 /proc/loadavg)"
    grep -E '^ *[0-9]+/[0-9]+ Test +#' "$log" || true
    grep -E 'tests passed|Total Test time' "$log" || true
    grep -cE '^(==[0-9]+==ERROR|WARNING: ThreadSanitizer|SUMMARY: (Address|Leak|Thread|UndefinedBehavior)Sanitizer)|runtime error:' "$log" |
      sed 's/^/sanitizer reports in the output: /'
  } | tee "$dir/sanitize-summary.txt"
  return "$rc"
}

status=0
case $which in
  asan|all) run_suite asan address,undefined "$asan_tests" || status=1 ;;&
  tsan|all) run_suite tsan thread "$tsan_tests" || status=1 ;;
  asan) ;;
  *) echo "usage: $0 [asan|tsan|all]" >&2; exit 2 ;;
esac
exit $status
