#!/usr/bin/env bash
# Every command-line tool: --help prints the usage and exits 0; an unknown
# option, or one that does not belong to the command, exits 2 with the usage
# (never ignored with exit 0). No daemon needed: these are refused before any
# DDS traffic.
# usage: tools_usage.sh BINARY_DIR
set -uo pipefail
bin=$1
failed=0
check() {  # check EXPECTED_EXIT CMD...
  local want=$1 out rc
  shift
  out=$("$@" 2>&1 < /dev/null)
  rc=$?
  if [ "$rc" -ne "$want" ]; then
    echo "FAIL: '$*' exit code $rc, expected $want: $(echo "$out" | head -n 3)"; failed=1
  elif ! echo "$out" | grep -qi '^usage:'; then
    echo "FAIL: '$*' did not print its usage: $(echo "$out" | head -n 3)"; failed=1
  else
    echo "ok: '$*' -> $rc"
  fi
}
tools=("$bin/tools/slctl" "$bin/tools/sl_view/sl_view" "$bin/tools/sl_process" "$bin/tools/sl_patterns"
       "$bin/tools/sl_calibrate" "$bin/tools/sl_register" "$bin/tools/sl_eval" "$bin/tools/sl_handeye"
       "$bin/tools/sl_verify")
for t in "${tools[@]}"; do
  [ -x "$t" ] || { echo "FAIL: $t not built"; failed=1; continue; }
  check 0 "$t" --help
  check 2 "$t" --no-such-option
done
# slctl: options of another command are refused, not ignored.
check 2 "$bin/tools/slctl" --timeout 1 start --out x
check 2 "$bin/tools/slctl" --timeout 1 status --units m
check 2 "$bin/tools/slctl" --timeout 1 stop --count 3
check 2 "$bin/tools/slctl" --timeout 1 patterns --wait
check 2 "$bin/tools/slctl" --timeout 1 status extra
check 2 "$bin/tools/sl_eval" precision --no-such-option
exit "$failed"
