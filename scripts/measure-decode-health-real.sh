#!/bin/bash
# Decode health of the real SLStudio captures (../shared/data/slstudio-skull:
# the six calibration sequences, 3+3 on both axes at 16 periods, and the
# skull, 3+3 on the columns) described rightly and wrongly; prints one line
# per run: capture, description, exit code, fail-unwrapping %, residual
# median, epipolar median and p90 (px). docs/decode-health.md has the table.
#   [PROJECTOR_ITERATIONS=N] scripts/measure-decode-health-real.sh [BUILD_DIR] [DATA_DIR]
# (N = 0 by default: projector distortion ignored, as SLStudio triangulates)
set -u
build=${1:-build}
data=${2:-$(dirname "$0")/../../shared/data/slstudio-skull}
out=$(mktemp -d)
trap 'rm -rf "$out"' EXIT
pattern() {  # name direction frequencies
  cat > "$out/$1.yaml" <<YAML
name: $1
family: phase_shift
direction: $2
projector: {width: 1824, height: 1140}
steps: 3
frequencies: $3
unwrapping: unit_cue
YAML
  echo "$out/$1.yaml"
}
run() {  # capture-name images pattern-file label
  local log="$out/log.txt"
  "$build/tools/sl_process" --pattern "$3" --images "$2" --calibration "$data/calibration.xml" \
    --projector-iterations "${PROJECTOR_ITERATIONS:-0}" --undistort-images --out "$out/o" > "$log" 2>&1
  local rc=$?
  local fail median epi
  fail=$(sed -n 's/.*of those \([0-9.]*\) % unwrap consistently.*/\1/p' "$log")
  median=$(sed -n 's/.*unwrapping residual median \([0-9.]*\), p90.*/\1/p' "$log")
  epi=$(sed -n 's/.*epipolar distance.*median \([0-9.]*\) px, p90 \([0-9.]*\) px/\1 \2/p' "$log")
  printf '%-6s %-28s exit %s  fail %6s %%  residual %-6s  epipolar median/p90 %s\n' "$1" "$4" "$rc" \
    "$(awk -v c="${fail:-0}" 'BEGIN{printf "%.1f", 100 - c}')" "${median:--}" "${epi:--}"
}
both_right=$(pattern both_right both "[16, 1]")
for f in "[1, 16]" "[12, 1]" "[20, 1]" "[15, 0.9375]" "[17, 1]" "[8, 0.5]"; do
  name=$(echo "both_$f" | tr -dc 'a-z0-9_.')
  pattern "$name" both "$f" > /dev/null
done
for s in 1 2 3 4 5 6; do
  run "seq$s" "$data/calibration/seq$s" "$both_right" "[16, 1] (right)"
  for f in "[1, 16]" "[12, 1]" "[20, 1]" "[15, 0.9375]" "[17, 1]" "[8, 0.5]"; do
    run "seq$s" "$data/calibration/seq$s" "$out/$(echo "both_$f" | tr -dc 'a-z0-9_.').yaml" "$f"
  done
done
run skull "$data/skull_2x3" "$(pattern skull_right horizontal "[16, 1]")" "[16, 1] (right)"
for f in "[1, 16]" "[12, 1]" "[20, 1]" "[15, 0.9375]"; do
  run skull "$data/skull_2x3" "$(pattern "skull_$(echo "$f" | tr -dc '0-9')" horizontal "$f")" "$f"
done
