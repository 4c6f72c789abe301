#!/bin/sh
# Allocates every page of a running iceoryx RouDi's shared-memory segments
# (/dev/shm), so that no process pays for them when it first writes a chunk.
#
#   iceoryx-prefault.sh ROUDI_PID
#
# RouDi maps its segments but writes only part of them at start (~470 of
# ~820 MB with config/iceoryx-roudi.toml). A page of /dev/shm is allocated
# at its first write; on a VM that hands free memory back to the host that
# costs ~5 ms per MB, so each 25 MB cloud chunk used for the first time cost
# the daemon's output thread ~125 ms (docs/measurements.md).
# fallocate(1) allocates the missing pages of each segment file and leaves
# what is written untouched, so it is safe while RouDi and its clients run.
# Waits up to 20 s for RouDi to map its segments; a failure is reported and
# does not fail the caller (shared memory works without it, only slower at
# first). Used by systemd/iceoryx-roudi.service (ExecStartPost) and
# scripts/bench-delivery.sh.
pid=${1:?usage: iceoryx-prefault.sh ROUDI_PID}
i=0
segments=""
while [ $i -lt 200 ]; do
  # The management segment and at least one data segment.
  segments=$(awk '$6 ~ /^\/dev\/shm\// { print $6 }' "/proc/$pid/maps" 2> /dev/null | sort -u)
  [ "$(echo "$segments" | grep -c .)" -ge 2 ] && break
  i=$((i + 1))
  sleep 0.1
done
if [ "$(echo "$segments" | grep -c .)" -lt 2 ]; then
  echo "iceoryx-prefault: RouDi (pid $pid) mapped no segments in 20 s; nothing allocated" >&2
  exit 0
fi
status=0
for f in $segments; do
  fallocate -l "$(stat -c %s "$f")" "$f" || { echo "iceoryx-prefault: could not allocate $f" >&2; status=1; }
done
[ $status = 0 ] && echo "iceoryx-prefault: allocated $(du -ck $segments | tail -n 1 | cut -f1) KiB in $(echo $segments | wc -w) segments"
exit 0
