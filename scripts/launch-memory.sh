#!/usr/bin/env bash
# The resident memory of a launch's processes (issue 76 item 4): the launcher and every
# process it starts, RSS and PSS from /proc/PID/smaps_rollup, sampled once the run is under
# way (a launch's memory is flat after start-up). Run it alone: PSS splits the binary's
# shared pages among every ratelab process on the host.
#
# RSS counts the binary's pages mapped from the page cache, and how many a process maps
# depends on how those pages came into the cache: a binary just written (built, copied)
# sits there in large folios, each mapped whole, and the same binary read back from disk
# in small ones. One binary measured both ways differed by 9-10 MiB a launch (2026-11-30),
# more than most changes measured. RATELAB_DROP_CACHES=1 (as root) drops the page cache
# before the launch, so that every binary compared is read from disk alike; the columns
# anon and file split each RSS.
# Usage: scripts/launch-memory.sh [GRAPH] [CLOCK] [extra launch flags...]
set -euo pipefail
graph=${1:-graphs/cartpole.toml}; clock=${2:-real}; shift $(( $# > 2 ? 2 : $# )) || true
bin=${RATELAB_BIN:-target/release/ratelab}
if pgrep -x ratelab >/dev/null; then echo "another ratelab is running: PSS would be shared with it" >&2; fi
out=$(mktemp)
if [ "${RATELAB_DROP_CACHES:-0}" = 1 ]; then sync; echo 3 > /proc/sys/vm/drop_caches; fi
"$bin" launch "$graph" --processes --headless --clock "$clock" --duration 600 "$@" >"$out" 2>&1 &
L=$!
# Wait until every process said ready, then 3 s more (virtual clock: the run is then at
# about 400 s of run time; its 600 s end about 5 s after the start).
for _ in $(seq 1 300); do
  n=$(grep -oE "in [0-9]+ processes" "$out" | grep -oE "[0-9]+" || true)
  [ -n "$n" ] && [ "$(grep -c "' ready" "$out")" -ge "$n" ] && break; sleep 0.2
done
sleep 3
rss=0; pss=0
for p in $L $(pgrep -P $L); do
  read -r r s < <(awk '/^Rss:/{r=$2} /^Pss:/{s=$2} END{print r, s}' /proc/$p/smaps_rollup)
  read -r a f < <(awk '/^RssAnon:/{a=$2} /^RssFile:/{f=$2} END{print a, f}' /proc/$p/status)
  name=$(tr '\0' ' ' </proc/$p/cmdline | grep -oE -- '--process [^ ]+' | cut -d' ' -f2 || true)
  printf '%-10s pid %-7s RSS %6.1f MiB (anon %5.1f, file %5.1f)  PSS %6.1f MiB  threads %s  locked %s kB\n' \
    "${name:-launcher}" "$p" "$(echo "$r/1024" | bc -l)" "$(echo "$a/1024" | bc -l)" "$(echo "$f/1024" | bc -l)" \
    "$(echo "$s/1024" | bc -l)" "$(ls /proc/$p/task | wc -l)" \
    "$(awk '/^VmLck:/{print $2}' /proc/$p/status)"
  rss=$((rss + r)); pss=$((pss + s))
done
printf 'total      RSS %.1f MiB  PSS %.1f MiB (clock %s, shared memory %s, page cache %s)\n' \
  "$(echo "$rss/1024" | bc -l)" "$(echo "$pss/1024" | bc -l)" "$clock" "${RATELAB_SHARED_MEMORY:-on}" \
  "$([ "${RATELAB_DROP_CACHES:-0}" = 1 ] && echo dropped || echo "as found")"
kill -INT $L 2>/dev/null || true; wait $L || true; rm -f "$out"
