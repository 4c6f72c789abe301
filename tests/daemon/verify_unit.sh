#!/usr/bin/env bash
# systemd-analyze verify on the shipped unit, with ExecStart pointed at the
# freshly built binary (the installed path does not exist on a build machine).
# usage: verify_unit.sh SOURCE_DIR BINARY_DIR
set -euo pipefail
src=$1
bin=$2
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
sed "s|^ExecStart=/usr/local/bin/sl_sensord|ExecStart=$bin/daemon/sl_sensord|" \
  "$src/systemd/sl-sensord.service" > "$work/sl-sensord.service"
grep -q "^Type=notify" "$work/sl-sensord.service"
out=$(systemd-analyze verify "$work/sl-sensord.service" 2>&1 | grep -v "^$" || true)
if [ -n "$out" ]; then
  echo "systemd-analyze verify reported:"; echo "$out"; echo "0 passed, 1 failed"; exit 1
fi
echo "1 passed, 0 failed"
