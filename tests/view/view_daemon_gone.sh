#!/usr/bin/env bash
# sl_view says whether a daemon is behind its topics: "no daemon" on stderr
# and in GET /stats (dds.daemon, dds.status_age_s) when none publishes its
# status, at start and after the daemon exits; "daemon found" when one comes.
# The web page (headless Chromium) shows the same. And a port in use is one
# clear line with the system's reason, exit 1.
# usage: view_daemon_gone.sh SOURCE_DIR BINARY_DIR
set -euo pipefail
# shellcheck source=../support/daemon.sh
source "$1/tests/support/daemon.sh"
sl_enter_netns "$0" "$@"
sl_init "$1" "$2"
view=$bin/tools/sl_view/sl_view
node_dir=$src/tools/sl_view
[ -d "$node_dir/node_modules/playwright-core" ] ||
  fail "npm packages missing: run scripts/install-deps.sh (npm ci in tools/sl_view)"
page() { node "$node_dir/test/daemon_check.mjs" --url "http://127.0.0.1:$vport/" --expect "$1" || fail "the page with the daemon $1"; }
ns="gone_$$"
sl_sim_config "$ns" "$work/sim.yaml"

# 1. A port in use.
python3 -c 'import socket, sys, time
s = socket.socket(); s.bind(("127.0.0.1", 0)); s.listen(1)
print(s.getsockname()[1], flush=True); time.sleep(60)' > "$work/port.txt" &
sl_track $!
for _ in $(seq 50); do [ -s "$work/port.txt" ] && break; sleep 0.1; done
port=$(cat "$work/port.txt")
set +e
msg=$("$view" --ns "$ns" --port "$port" 2>&1 > /dev/null)
rc=$?
set -e
[ "$rc" -eq 1 ] || fail "port in use: exit code $rc, expected 1 ($msg)"
msg=$(echo "$msg" | grep -v '^sl_view: warning:')   # e.g. three.js not installed
[ "$(echo "$msg" | grep -c .)" -eq 1 ] || fail "port in use: not one line: $msg"
echo "$msg" | grep -q "^sl_view: cannot listen on 127.0.0.1:$port: Address already in use" \
  || fail "port in use: $msg"
echo "ok: port in use -> $msg"

# 2. No daemon at start.
"$view" --ns "$ns" --port 0 > "$work/view.out" 2> "$work/view.log" &
sl_track $!
wait_for() {  # wait_for PATTERN COUNT SECONDS: COUNT lines of view.log match
  local _
  for _ in $(seq $(( $3 * time_scale * 10 ))); do
    [ "$(grep -c "$1" "$work/view.log")" -ge "$2" ] && return 0
    sleep 0.1
  done
  fail "sl_view did not say '$1' ($2 times) within $(( $3 * time_scale )) s"
}
stats() {
  python3 -c 'import json, sys, urllib.request
d = json.load(urllib.request.urlopen("http://127.0.0.1:%s/stats" % sys.argv[1]))["dds"]
print("daemon=%s age=%.1f" % (str(d["daemon"]).lower(), d["status_age_s"]))' "$vport"
}
wait_for "^sl_view: no daemon: no status on rt/$ns/status" 1 15
vport=$(sed -n 's|.*http://127.0.0.1:\([0-9]*\)/.*|\1|p' "$work/view.out")
[ -n "$vport" ] || fail "sl_view did not print its port"
s=$(stats); echo "$s" | grep -q "^daemon=false age=-1" || fail "/stats without a daemon: $s"
echo "ok: no daemon at start ($s)"

# 3. A daemon comes.
sl_start_daemon "$work/sim.yaml" "$work/daemon.log"
sl_wait_ready "$work/daemon.log"
wait_for "^sl_view: daemon found" 1 10
s=$(stats); echo "$s" | grep -q "^daemon=true" || fail "/stats with a daemon: $s"
page present
echo "ok: daemon found ($s)"

# 4. It goes: sl_view says so, no stale "scanning".
sl_stop_daemon
wait_for "^sl_view: no daemon: no status on rt/$ns/status" 2 15
s=$(stats); echo "$s" | grep -Eq "^daemon=false age=([5-9]|[1-9][0-9])" || fail "/stats after the daemon exited: $s"
page gone
echo "ok: daemon gone ($s)"
