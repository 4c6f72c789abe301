#!/usr/bin/env bash
# The README's first-scan block, run as a user pastes it: the lines between
# <!-- first-scan --> and <!-- /first-scan --> in README.md, against sl_sensord
# on the simulated sensor, from a folder that holds `config` and `build` as
# the source folder does. Only the daemon's namespace is added to each slctl
# call; every command must succeed (set -e), the scans and the recording must
# be where the README says, and the recording outside the source tree.
# usage: readme_first_scan.sh SOURCE_DIR BINARY_DIR
set -euo pipefail
# shellcheck source=../support/daemon.sh
source "$1/tests/support/daemon.sh"
sl_enter_netns "$0" "$@"
sl_init "$1" "$2"

ns="readme_$$"
sl_sim_config "$ns" "$work/sim.yaml"
export XDG_DATA_HOME="$work/data"   # where the recordings must go (not the source tree)
unset STATE_DIRECTORY
sl_start_daemon "$work/sim.yaml" "$work/daemon.log"
sl_wait_ready "$work/daemon.log"

block=$(sed -n '/^<!-- first-scan -->$/,/^<!-- \/first-scan -->$/p' "$src/README.md" | sed '/^<!--/d; /^```/d')
[ "$(echo "$block" | grep -c 'build/tools/slctl')" -ge 5 ] || fail "no first-scan block between the markers in README.md"
# The user's shell: the source folder's layout, this test's daemon.
mkdir -p "$work/user"
ln -s "$src/config" "$work/user/config"
ln -s "$bin" "$work/user/build"
extra="--ns $ns"
[ "$time_scale" -eq 1 ] || extra="$extra --timeout $(( 10 * time_scale ))"   # scans 10x slower there
script=$(echo "$block" | sed "s|build/tools/slctl |build/tools/slctl $extra |")
echo "$script" > "$work/block.sh"
( cd "$work/user" && bash -e "$work/block.sh" ) > "$work/block.log" 2>&1 \
  || fail "the README's first-scan block failed: $(tail -n 5 "$work/block.log")"
cat "$work/block.log"

for f in scans/scan_0001.ply scans/scan_0003.ply sw/scan_0003.ply; do
  [ -s "$work/user/$f" ] || fail "the block did not write $f"
done
rec="$XDG_DATA_HOME/sl-sensor/recordings/rec1"
grep -q "recording 'rec1' to $rec " "$work/block.log" || fail "slctl record did not name $rec"
# --wait returns once the recording has ended, with the sets it holds (on a
# loaded machine the daemon may drop sets; it counts them, see docs/interface.md).
recorded=$(sed -n 's/^recorded \([0-9]*\) image sets$/\1/p' "$work/block.log")
[ -n "$recorded" ] || fail "slctl record --wait did not report the sets recorded"
sets=$(find "$rec" -name meta.yml | wc -l)
[ "$recorded" -ge 1 ] && [ "$sets" -eq "$recorded" ] \
  || fail "slctl record --wait returned with $recorded sets reported, $sets in $rec"
[ ! -e "$work/recordings" ] \
  || fail "a recording landed beside the config file (the source tree for config/sim.yaml)"
sl_stop_daemon
echo "ok: the README's first-scan block runs as pasted"
