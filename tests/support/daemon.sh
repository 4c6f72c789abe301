# Shared pieces of the shell tests (sourced, bash): a scratch folder and
# cleanup trap, failure reporting with the logs, a config with its own
# namespace, starting sl_sensord, waiting for it and stopping it, and an
# optional private network namespace. Every wait is bounded.
#
#   source "$src/tests/support/daemon.sh"
#   sl_init "$src" "$bin"            # work=, pids=(), trap, CYCLONEDDS_URI
#   sl_sim_config "$ns" "$work/sim.yaml" [sed expressions...]
#   sl_start_daemon "$work/sim.yaml" "$work/daemon.log"   # sets daemon_pid
#   sl_wait_ready "$work/daemon.log"
#   sl_stop_daemon                   # SIGTERM, exit within 2 s, exit code 0
#
# In a sanitizer build (SL_SANITIZE in the build's CMakeCache.txt) sl_init
# sets time_scale=10 (else 1), and the waits above are multiplied by it, as
# tests/support/time_scale.h does for the C++ tests.
#
# SL_TEST_NETNS=1 makes sl_enter_netns re-run the script in a private
# network namespace (unshare -rn, else -n) with only loopback, so that its
# DDS traffic meets no other process's.

# sl_enter_netns "$0" "$@": re-executes the script in a private network
# namespace when SL_TEST_NETNS=1 and it is not already in one; else returns.
sl_enter_netns() {
  [ "${SL_TEST_NETNS:-0}" = 1 ] && [ -z "${SL_IN_NETNS:-}" ] || return 0
  local script=$1
  shift
  export SL_IN_NETNS=1
  if unshare -rn true 2>/dev/null; then
    exec unshare -rn sh -c 'ip link set lo up && exec bash "$0" "$@"' "$script" "$@"
  elif unshare -n true 2>/dev/null; then
    exec unshare -n sh -c 'ip link set lo up && exec bash "$0" "$@"' "$script" "$@"
  fi
  echo "note: no private network namespace available; running in the current one" >&2
}

# sl_init SOURCE_DIR BINARY_DIR: sets src, bin, work (a fresh scratch folder),
# pids (processes killed on exit) and time_scale, installs the cleanup trap
# and points Cyclone at the loopback config unless CYCLONEDDS_URI is set (in
# a sanitizer build with the participants' lease x time_scale).
sl_init() {
  src=$1
  bin=$2
  time_scale=1
  if grep -Eq '^SL_SANITIZE:STRING=.+' "$bin/CMakeCache.txt" 2> /dev/null; then time_scale=10; fi
  export CYCLONEDDS_URI=${CYCLONEDDS_URI:-file://$src/config/cyclonedds-loopback.xml}
  # The participants' lease (Cyclone's 10 s) x time_scale, as the C++ tests
  # do (scaledDdsLeaseXml in tests/support/time_scale.h).
  if [ "$time_scale" -ne 1 ]; then
    CYCLONEDDS_URI="$CYCLONEDDS_URI,<Discovery><LeaseDuration>$((10 * time_scale))s</LeaseDuration></Discovery>"
  fi
  work=$(mktemp -d)
  pids=()
  daemon_pid=""
  trap sl_cleanup EXIT
}

# Kills what is left (SIGTERM, then SIGKILL after 0.2 s) and removes $work.
sl_cleanup() {
  local p
  for p in "${pids[@]}"; do kill "$p" 2>/dev/null || true; done
  if [ ${#pids[@]} -gt 0 ]; then
    sleep 0.2
    for p in "${pids[@]}"; do kill -9 "$p" 2>/dev/null || true; done
  fi
  rm -rf "$work"
}

# sl_track PID...: kill these on exit.
sl_track() { pids+=("$@"); }

# fail MESSAGE: prints it and the tail of every log in $work, exits 1.
fail() {
  echo "FAIL: $*" >&2
  local f
  for f in "$work"/*.log; do [ -f "$f" ] && { echo "--- $(basename "$f")"; tail -n 20 "$f"; } >&2; done
  exit 1
}

# sl_sim_config NAMESPACE OUT [SED_EXPRESSION...]: config/sim.yaml with
# dds.namespace set (and the further sed expressions applied) written to OUT;
# fails unless the namespace took. In a sanitizer build (time_scale 10) the
# simulated camera runs at camera_fps / time_scale and synchroniser.max_age_s
# is x time_scale, as simConfig() in tests/daemon/daemon_process.h does: at
# 30 Hz the renderer falls behind there and whole sequences arrive too late
# to be grouped (counted as incomplete sets), which measures the machine.
sl_sim_config() {
  local ns=$1 out=$2
  shift 2
  local args=(-e "s|^  namespace: sl$|  namespace: $ns|")
  if [ "${time_scale:-1}" -ne 1 ]; then
    local fps age
    fps=$(sed -n 's/^  camera_fps: *\([0-9.]*\).*/\1/p' "$src/config/sim.yaml")
    age=$(sed -n 's/^  max_age_s: *\([0-9.]*\).*/\1/p' "$src/config/sim.yaml")
    fps=$(awk -v v="$fps" -v s="$time_scale" 'BEGIN { print v / s }')
    age=$(awk -v v="$age" -v s="$time_scale" 'BEGIN { print v * s }')
    args+=(-e "s/^\(  camera_fps: *\)[0-9.]*/\1$fps/" -e "s/^\(  max_age_s: *\)[0-9.]*/\1$age/")
  fi
  local e
  for e in "$@"; do args+=(-e "$e"); done
  sed "${args[@]}" "$src/config/sim.yaml" > "$out"
  grep -q "namespace: $ns$" "$out" || fail "could not set the namespace in a copy of config/sim.yaml"
}

# sl_start_daemon CONFIG LOG: starts sl_sensord in the background with the
# caller's environment; daemon_pid is the daemon itself.
sl_start_daemon() {
  "$bin/daemon/sl_sensord" --config "$1" > "$2" 2>&1 &
  daemon_pid=$!
  sl_track "$daemon_pid"
}

# sl_wait_ready LOG [SECONDS=15]: until the daemon logged that it is ready
# (SECONDS x time_scale).
sl_wait_ready() {
  local log=$1 tenths=$(( ${2:-15} * ${time_scale:-1} * 10 ))
  local _
  for _ in $(seq "$tenths"); do
    grep -q "ready" "$log" && return 0
    kill -0 "$daemon_pid" 2>/dev/null || fail "the daemon exited during start-up"
    sleep 0.1
  done
  fail "the daemon did not get ready within $(( tenths / 10 )) s"
}

# sl_stop_daemon [PID=daemon_pid] [SECONDS=2]: SIGTERM; it must be gone
# within SECONDS (x time_scale) and exit 0.
sl_stop_daemon() {
  local pid=${1:-$daemon_pid} steps=$(( ${2:-2} * ${time_scale:-1} * 20 )) _ rc=0
  kill -TERM "$pid"
  for _ in $(seq 1 "$steps"); do kill -0 "$pid" 2>/dev/null || break; sleep 0.05; done
  kill -0 "$pid" 2>/dev/null && fail "daemon $pid still running $(( steps / 20 )) s after SIGTERM"
  wait "$pid" || rc=$?
  [ "$rc" -eq 0 ] || fail "daemon $pid exit code $rc"
  [ "$pid" = "$daemon_pid" ] && daemon_pid=""
  return 0
}
