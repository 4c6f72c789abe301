#!/usr/bin/env bash
# DDS Security end to end (README "DDS Security"): material from
# scripts/dds-security.sh, sl_sensord as `sensor`, clients as `operator`
# (permitted), `viewer` (authenticated, not permitted to write requests), an
# operator certified by another CA, a participant without security that
# forges clouds, and an operator of namespace N against a sensor in N/b
# (shared CAs).
# usage: security.sh SOURCE_DIR BINARY_DIR
set -euo pipefail
# shellcheck source=../support/daemon.sh
source "$1/tests/support/daemon.sh"
sl_enter_netns "$0" "$@"
sl_init "$1" "$2"

ns="sec_$$"
bash "$src/scripts/dds-security.sh" "$work/sec" --ns "$ns" >/dev/null
bash "$src/scripts/dds-security.sh" "$work/rogue" --ns "$ns" >/dev/null
bash "$src/scripts/dds-security.sh" "$work/nested" --ns "$ns/b" --ca-from "$work/sec" >/dev/null
sl_sim_config "$ns" "$work/sim.yaml"
sl_sim_config "$ns/b" "$work/sim_nested.yaml"

plain=file://$src/config/cyclonedds-loopback.xml
secure=$plain,file://$src/config/cyclonedds-security.xml
# as ROLE [DIR] -- command: runs with the role's identity
as() {
  local role=$1 dir=$work/sec
  shift
  if [ "$1" != "--" ]; then dir=$1; shift; fi
  shift
  SL_DDS_SECURITY_DIR=$dir SL_DDS_IDENTITY=$role CYCLONEDDS_URI=$secure "$@"
}
unsecured() { CYCLONEDDS_URI=$plain "$@"; }

start_daemon() {  # governance [material config]
  export SL_DDS_GOVERNANCE=$1
  # Not through as(): $! must be the daemon itself, not a subshell.
  SL_DDS_SECURITY_DIR=${2:-$work/sec} SL_DDS_IDENTITY=sensor CYCLONEDDS_URI=$secure \
    sl_start_daemon "${3:-$work/sim.yaml}" "$work/daemon.log"
}
expect() {  # rc-expected message-pattern what -- command...
  local want=$1 pattern=$2 what=$3 rc=0 msg
  shift 4
  msg=$("$@" 2>&1) || rc=$?
  [ "$rc" -eq "$want" ] || fail "$what: exit $rc, expected $want: $msg"
  echo "$msg" | grep -qi -- "$pattern" || fail "$what: message '$msg' lacks '$pattern'"
  echo "ok: $what -> exit $rc: $(echo "$msg" | grep -v "dq.builtin" | head -2 | tr '\n' ' ')"
}

# How the points writer sends clouds under security (README "Clouds written
# from their own memory"): the daemon must say it, whichever way it is.
say_how() {  # governance
  local how
  how=$(grep 'points: clouds are' "$work/daemon.log" | tail -n 1 || true)
  [ -n "$how" ] || fail "the daemon's log does not say how it writes clouds: $(head -5 "$work/daemon.log")"
  echo "ok: $1: $how"
}

# --- governance_control: requests, replies and status protected, data open ---
start_daemon governance_control
expect 0 "3+3_horizontal" "operator lists patterns" -- \
  as operator -- "$bin/tools/slctl" --ns "$ns" --timeout 20 patterns
expect 1 "not allowed by security" "viewer cannot even create a request writer" -- \
  as viewer -- "$bin/tools/slctl" --ns "$ns" --timeout 3 patterns
expect 3 "no sl_sensord answered" "participant without security gets no request through" -- \
  unsecured "$bin/tools/slctl" --ns "$ns" --timeout 3 start
expect 3 "no sl_sensord answered" "operator certified by another CA is not admitted" -- \
  as operator "$work/rogue" -- "$bin/tools/slctl" --ns "$ns" --timeout 3 start
# Nothing of the above started a scan.
expect 0 "idle" "status still idle (through security)" -- \
  as operator -- "$bin/tools/slctl" --ns "$ns" --timeout 10 status
# Data topics are signed under governance_control: only the `sensor` identity
# publishes them. A participant without security forges clouds while the
# daemon is idle; a viewer takes none of them.
wait_s=$((10 * time_scale))
as viewer -- "$bin/tools/c_listener/sl_points_listener" --topic "rt/$ns/points" --count 1 \
  --timeout $((wait_s + 2)) > "$work/forged_viewer.log" 2>&1 &
viewer=$!
sl_track "$viewer"
sleep 2
unsecured "$bin/tests/forged_points" "rt/$ns/points" $((wait_s * 5)) 200 > "$work/forged.log" 2>&1 \
  || fail "forged_points: $(cat "$work/forged.log")"
if wait "$viewer"; then
  fail "governance_control: the viewer took a forged cloud: $(cat "$work/forged_viewer.log")"
fi
grep -q "forged" "$work/forged_viewer.log" && fail "the viewer printed a forged cloud"
echo "ok: governance_control: a viewer takes none of the clouds a plain participant forged ($(cat "$work/forged.log"))"
expect 1 "not allowed by security" "a viewer cannot create a points writer" -- \
  as viewer -- "$bin/tests/forged_points" "rt/$ns/points" 1 0
# The sensor's signed clouds: the viewer reads them, a plain subscriber does not.
as viewer -- "$bin/tools/c_listener/sl_points_listener" --topic "rt/$ns/points" --count 1 --timeout 30 \
  > "$work/viewer_listener.log" 2>&1 &
viewer=$!
sl_track "$viewer"
unsecured "$bin/tools/c_listener/sl_points_listener" --topic "rt/$ns/points" --count 1 --timeout 15 \
  > "$work/open_listener.log" 2>&1 &
plain_listener=$!
sl_track "$plain_listener"
expect 0 "scan 1/1" "operator scans" -- \
  as operator -- "$bin/tools/slctl" --ns "$ns" --timeout 20 scan --count 1 --out "$work/scan1"
wait "$viewer" || fail "governance_control: the viewer got no signed cloud: $(cat "$work/viewer_listener.log")"
echo "ok: governance_control: the viewer reads the sensor's signed clouds"
if wait "$plain_listener"; then fail "governance_control: a plain subscriber received a signed cloud"; fi
echo "ok: governance_control: a plain subscriber receives no cloud"
sl_stop_daemon "" 10
say_how governance_control

# --- governance_origin: data signed with one MAC per matched reader ---
# Two viewers: each checks the MAC made for it (a sample that fails its own
# receiver-specific MAC is dropped), so both must get the clouds.
start_daemon governance_origin
for v in 1 2; do
  as viewer -- "$bin/tools/c_listener/sl_points_listener" --topic "rt/$ns/points" --count 1 \
    --timeout 30 > "$work/origin_viewer$v.log" 2>&1 &
  eval "origin_viewer$v=\$!"
  sl_track "$!"
done
sleep 1
unsecured "$bin/tests/forged_points" "rt/$ns/points" 10 200 > "$work/forged_origin.log" 2>&1 \
  || fail "forged_points: $(cat "$work/forged_origin.log")"
expect 0 "scan 1/1" "governance_origin: operator scans" -- \
  as operator -- "$bin/tools/slctl" --ns "$ns" --timeout 30 scan --count 1 --out "$work/scan_origin"
for v in 1 2; do
  eval "pid=\$origin_viewer$v"
  wait "$pid" || fail "governance_origin: viewer $v got no cloud: $(cat "$work/origin_viewer$v.log")"
  grep -q "forged" "$work/origin_viewer$v.log" && fail "governance_origin: viewer $v took a forged cloud"
done
echo "ok: governance_origin: two viewers read the sensor's clouds, each through its own MAC; no forged cloud taken"
sl_stop_daemon "" 10
say_how governance_origin

# --- governance_all: every topic protected ---
start_daemon governance_all
unsecured "$bin/tools/c_listener/sl_points_listener" --topic "rt/$ns/points" --count 1 --timeout 8 \
  > "$work/closed_listener.log" 2>&1 &
closed=$!
sl_track "$closed"
as viewer -- "$bin/tools/c_listener/sl_points_listener" --topic "rt/$ns/points" --count 1 --timeout 30 \
  > "$work/viewer_listener.log" 2>&1 &
viewer=$!
sl_track "$viewer"
expect 0 "scan 1/1" "operator scans with data encrypted" -- \
  as operator -- "$bin/tools/slctl" --ns "$ns" --timeout 30 scan --count 1 --out "$work/scan2"
wait "$viewer" || fail "viewer got no cloud: $(cat "$work/viewer_listener.log")"
echo "ok: governance_all: the viewer reads clouds"
if wait "$closed"; then fail "governance_all: a plain subscriber received a cloud"; fi
echo "ok: governance_all: a plain subscriber receives nothing"
expect 3 "no sl_sensord answered" "governance_all: participant without security" -- \
  unsecured "$bin/tools/slctl" --ns "$ns" --timeout 3 status
sl_stop_daemon "" 10
say_how governance_all

# --- nested namespaces: a sensor in $ns/b, its material under the same CAs ---
# Every permission names exact topics: `rq/$ns/*` would match rq/$ns/b/...
start_daemon governance_control "$work/nested" "$work/sim_nested.yaml"
expect 0 "3+3_horizontal" "the nested namespace's operator lists its patterns" -- \
  as operator "$work/nested" -- "$bin/tools/slctl" --ns "$ns/b" --timeout 20 patterns
# Its own governance has no rule for $ns/b's topics: its request writer is
# unprotected and matches no reader of the sensor's protected request topic.
expect 3 "no sl_sensord answered" "an operator of $ns cannot start the sensor in $ns/b" -- \
  as operator -- "$bin/tools/slctl" --ns "$ns/b" --timeout 3 start
expect 0 "idle" "the sensor in $ns/b is still idle" -- \
  as operator "$work/nested" -- "$bin/tools/slctl" --ns "$ns/b" --timeout 10 status
sl_stop_daemon "" 10
echo "security: all checks passed"
