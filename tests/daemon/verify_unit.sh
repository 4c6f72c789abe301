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
# systemd-analyze security: every remaining finding is justified in the unit
# by a "# security: NAME reason" line, and the overall exposure stays low.
if systemd-analyze security --help 2>&1 | grep -q -- "--offline"; then
  report=$(systemd-analyze security --offline=yes "$work/sl-sensord.service" 2>&1)
  unjustified=""
  while IFS= read -r name; do
    grep -qF "# security: $name " "$src/systemd/sl-sensord.service" || unjustified="$unjustified $name"
  done < <(echo "$report" | sed -n 's/^✗ \([^ ]*\) .*/\1/p')
  if [ -n "$unjustified" ]; then
    echo "systemd-analyze security findings without a '# security:' line in the unit:$unjustified"
    echo "0 passed, 1 failed"; exit 1
  fi
  exposure=$(echo "$report" | sed -n 's/.*Overall exposure level for [^:]*: \([0-9.]*\).*/\1/p')
  echo "systemd-analyze security: exposure $exposure, every finding justified in the unit"
  awk -v e="$exposure" 'BEGIN { exit !(e != "" && e <= 1.5) }' || {
    echo "exposure $exposure above 1.5"; echo "0 passed, 1 failed"; exit 1; }
fi
echo "1 passed, 0 failed"
