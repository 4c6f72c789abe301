#!/bin/bash
# Issue 36 probes of sl_sensord, for the table in docs/operations.md
# ("Hardening"): run it with two daemon binaries to compare them in one run.
#   scripts/hardening-probes.sh [ROUNDS] BIN [BIN...]
# Needs CYCLONEDDS_URI (e.g. file://$PWD/config/cyclonedds-loopback.xml) and
# build/tools/slctl. Each daemon runs under `ulimit -v 4 GiB` and is killed
# (SIGKILL) when a probe's bound passes; prints one line per probe and binary.
set -u
src=$(cd "$(dirname "$0")/.." && pwd)
rounds=20
case "${1:-}" in [0-9]*) rounds=$1; shift ;; esac
[ $# -ge 1 ] || { echo "usage: $0 [ROUNDS] BIN [BIN...]" >&2; exit 2; }
slctl=$src/build/tools/slctl
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
now() { date +%s.%N; }
since() { echo "$(now) - $1" | bc | sed 's/^\./0./'; }

# run BIN CONFIG BOUND_S: exit code (or "killed after BOUND_S s") and time.
run() {
  local bin=$1 config=$2 bound=$3 t0 pid rc
  t0=$(now)
  (ulimit -v 4194304; exec "$bin" --config "$config") > "$work/run.log" 2>&1 &
  pid=$!
  for _ in $(seq 1 $((bound * 20))); do kill -0 "$pid" 2> /dev/null || break; sleep 0.05; done
  if kill -0 "$pid" 2> /dev/null; then
    kill -KILL "$pid"; wait "$pid" 2> /dev/null
    echo "still running after ${bound} s (killed)"
  else
    wait "$pid"; rc=$?
    echo "exit $rc in $(since "$t0") s: $(grep -E 'error|fatal|killed' "$work/run.log" | tail -1 | cut -c1-160)"
  fi
}

sim_config() {  # sim_config NS > file
  sed "s/^  namespace: sl$/  namespace: $1/" "$src/config/sim.yaml"
}

index=0
for bin in "$@"; do
  index=$((index + 1))
  echo "=== $bin"
  # --- start-up inputs (item 1) ---
  mkfifo "$work/fifo.yaml"
  echo "config is a FIFO:          $(run "$bin" "$work/fifo.yaml" 10)"
  rm -f "$work/fifo.yaml"
  echo "config is /dev/zero:       $(run "$bin" /dev/zero 10)"
  echo "config is a directory:     $(run "$bin" "$work" 10)"
  { echo "a: &a [x, x, x, x, x, x, x, x, x]"
    for c in b c d e f g h i j k l m n o p q r s t u v w x y z; do
      p=$(echo "$c" | tr 'b-z' 'a-y'); echo "$c: &$c [*$p, *$p, *$p, *$p]"; done
    sim_config probe_bomb; } > "$work/bomb.yaml"
  echo "YAML alias bomb:           $(run "$bin" "$work/bomb.yaml" 10)"
  { sim_config probe_two; echo "---"; echo "sensor: hardware"; } > "$work/two.yaml"
  echo "two YAML documents:        $(run "$bin" "$work/two.yaml" 10)"

  # --- config checks before devices (item 2) ---
  cp "$src/config/hardware-paper-calibration.yaml" "$work/"
  sed -e 's/{name: 3+3_both, family/{name: 3+3_both, cameras: [nope], family/' \
    "$src/config/hardware-paper.yaml" > "$work/hw_camera.yaml"
  echo "pattern names no camera:   $(run "$bin" "$work/hw_camera.yaml" 30)"
  sed -e '0,/width: 1440, height: 1080/s//width: 100000000, height: 100000000/' \
    "$src/config/hardware-paper.yaml" > "$work/hw_roi.yaml"
  echo "huge roi:                  $(run "$bin" "$work/hw_roi.yaml" 30)"

  # --- two daemons at once (item 5) ---
  both=0 one=0
  for r in $(seq 1 "$rounds"); do
    sim_config "probe_two_$$_$r" > "$work/two_$r.yaml"
    "$bin" --config "$work/two_$r.yaml" > "$work/a.log" 2>&1 & a=$!
    "$bin" --config "$work/two_$r.yaml" > "$work/b.log" 2>&1 & b=$!
    for _ in $(seq 1 150); do
      grep -q ready "$work/a.log" && grep -q ready "$work/b.log" && break
      { ! kill -0 $a || ! kill -0 $b; } 2> /dev/null && grep -q ready "$work/a.log" "$work/b.log" && break
      sleep 0.1
    done
    sleep 1
    n=0; kill -0 $a 2> /dev/null && n=$((n + 1)); kill -0 $b 2> /dev/null && n=$((n + 1))
    [ $n = 2 ] && both=$((both + 1)); [ $n = 1 ] && one=$((one + 1))
    kill -TERM $a $b 2> /dev/null; wait $a $b 2> /dev/null
  done
  echo "two daemons at once:       both ran in $both of $rounds rounds, exactly one in $one"

  # --- reloads (item 5): a FIFO texture, a FIFO MCAP recording, then SIGTERM ---
  for kind in texture mcap config; do
    d=$work/reload_${index}_$kind; mkdir -p "$d"; ns=probe_reload_${index}_${kind}_$$
    sim_config "$ns" > "$d/good.yaml"
    ln -s good.yaml "$d/sl.yaml"
    "$bin" --config "$d/sl.yaml" > "$d/daemon.log" 2>&1 & pid=$!
    for _ in $(seq 1 200); do grep -q ready "$d/daemon.log" && break; sleep 0.1; done
    case $kind in
      texture)
        mkfifo "$d/albedo.png"
        sed 's|albedo: 0.8}|albedo: 0.8, texture: {file: albedo.png, width_mm: 200}}|' "$d/good.yaml" > "$d/new.yaml" ;;
      mcap)
        mkfifo "$d/rec.mcap"
        { echo "sensor: replay"; echo "calibration: $src/config/hardware-paper-calibration.yaml"
          echo "replay: {file: rec.mcap}"; grep -v '^sensor:\|^calibration:' "$d/good.yaml"; } > "$d/new.yaml" ;;
      config)
        mkfifo "$d/new.yaml" ;;
    esac
    ln -sfn new.yaml "$d/sl.yaml"
    kill -HUP $pid
    sleep 6  # past the 5 s reload deadline
    err=$("$slctl" --ns "$ns" --timeout 3 status 2>&1 | grep '^last error' | cut -c1-150)
    t0=$(now); kill -TERM $pid
    for _ in $(seq 1 100); do kill -0 $pid 2> /dev/null || break; sleep 0.05; done
    if kill -0 $pid 2> /dev/null; then
      kill -KILL $pid; wait $pid 2> /dev/null; end="alive 5 s after SIGTERM (SIGKILL)"
    else
      wait $pid; end="exit $? $(since "$t0") s after SIGTERM"
    fi
    printf "reload, %-8s FIFO:    %s; status: %s\n" "$kind" "$end" "${err:-none}"
  done
done
