#!/usr/bin/env bash
# The cost of a router per host (issue 76 item 2): the chapter's launch across two network
# namespaces joined by a veth pair (two hosts on one link), virtual clock, its processes on
# the second host linked to the launcher on the first directly ("direct") or through
# `ratelab router` on their own host ("router"), alternated ROUNDS times. Prints the
# launcher's lockstep line (µs of wall time per instant) and the wire latency of /obs.
# Needs root (ip netns). Usage: scripts/bench-host-router.sh [ROUNDS] [DURATION_S]
set -euo pipefail
rounds=${1:-2}; dur=${2:-60}
bin=$(realpath "${RATELAB_BIN:-target/release/ratelab}")
a=rl-bench-a-$$; b=rl-bench-b-$$
cleanup() { ip netns del "$a" 2>/dev/null || true; ip netns del "$b" 2>/dev/null || true; }
trap cleanup EXIT
ip netns add "$a"; ip netns add "$b"
ip link add "rlba$$" netns "$a" type veth peer name "rlbb$$" netns "$b"
ip -n "$a" addr add 10.79.0.1/24 dev "rlba$$"; ip -n "$b" addr add 10.79.0.2/24 dev "rlbb$$"
for n in "$a" "$b"; do ip -n "$n" link set lo up; done
ip -n "$a" link set "rlba$$" up; ip -n "$b" link set "rlbb$$" up

one() {
  local mode=$1 d ep L R=
  d=$(mktemp -d); chmod 700 "$d"
  ep=tls/10.79.0.1:7449
  ip netns exec "$a" "$bin" launch --processes --no-spawn --listen "$ep" --clock virtual \
    --duration "$dur" --seed 7 --export-credentials "$d/creds.toml" --out "$d/out" >"$d/launcher.log" 2>&1 &
  L=$!
  for _ in $(seq 100); do grep -q "listening on" "$d/launcher.log" 2>/dev/null && break; sleep 0.1; done
  if [ "$mode" = router ]; then
    ip netns exec "$b" "$bin" router --connect "$ep" --listen tls/127.0.0.1:7450 \
      --credentials "$d/creds.toml" >"$d/router.log" 2>&1 &
    R=$!
    for _ in $(seq 100); do grep -q "linked" "$d/router.log" 2>/dev/null && break; sleep 0.1; done
    ep=tls/127.0.0.1:7450
  fi
  for p in robot policy; do
    ip netns exec "$b" "$bin" process --process "$p" --connect "$ep" --credentials "$d/creds.toml" >/dev/null 2>&1 &
  done
  wait "$L"
  echo "$mode: $(grep -o 'lockstep: .*' "$d/launcher.log") | $(grep -o 'wire /obs.*' "$d/launcher.log")"
  if [ -n "$R" ]; then wait "$R"; fi
  wait
  rm -rf "$d"
}
for _ in $(seq "$rounds"); do one direct; one router; done
