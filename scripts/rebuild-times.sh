#!/usr/bin/env bash
# What a change rebuilds (issue 71 item 6): for each file given (default: a file of the lab,
# the Python layer, the recording, ROS 2, the runtime and the core), the wall time of
# rebuilding the release binary after
#   touch: its modification time moved, nothing else;
#   edit:  a public function appended to it (the crate's interface changes, so every crate
#          above it must check itself again), then taken out again.
# Prints one line per file and kind: `SECONDS KIND FILE`. Files are restored on exit, even
# on Ctrl-C. A build first makes the target directory fresh, so each row is one rebuild.
#
# Usage: scripts/rebuild-times.sh [FILE...]
# Honours CARGO_TARGET_DIR and CARGO_INCREMENTAL as cargo does; the figures in BENCHMARKS.md
# are measured with CARGO_INCREMENTAL unset, as a developer builds.
set -euo pipefail
cd "$(dirname "${BASH_SOURCE[0]}")/.."

files=("$@")
if [ ${#files[@]} -eq 0 ]; then
  files=(lab/cli.rs src/python/lib.rs src/recording/lib.rs src/ros2/lib.rs
    src/runtime/lib.rs src/core/lib.rs)
fi
for f in "${files[@]}"; do
  [ -f "$f" ] || { echo "error: no such file: $f" >&2; exit 2; }
  # Restored with git: a file git does not track could not be.
  git ls-files --error-unmatch -- "$f" >/dev/null 2>&1 || { echo "error: $f is not tracked by git" >&2; exit 2; }
  git diff --quiet -- "$f" || { echo "error: $f has changes of its own; commit or stash them" >&2; exit 2; }
done

log="$(mktemp)"
# A build that fails ends the script with cargo's words: no time is given for it.
build() {
  cargo build --release --offline --locked --bin ratelab >"$log" 2>&1 || {
    tail -n 30 "$log" >&2
    echo "error: the build failed (above)" >&2
    exit 1
  }
}
seconds() {
  local start end
  start=$(date +%s%N)
  build
  end=$(date +%s%N)
  awk -v ns=$((end - start)) 'BEGIN { printf "%.1f", ns / 1e9 }'
}

edited=""
restore() {
  if [ -n "$edited" ]; then git checkout -q -- "$edited"; fi
  rm -f "$log"
}
trap restore EXIT

build
for f in "${files[@]}"; do
  touch "$f"
  t="$(seconds)" || exit 1
  echo "$t touch $f"
  edited="$f"
  printf '\n/// Appended by scripts/rebuild-times.sh; taken out when it ends.\npub fn rebuild_probe() -> u32 {\n    %d\n}\n' "$RANDOM" >>"$f"
  t="$(seconds)" || exit 1
  echo "$t edit $f"
  git checkout -q -- "$f"
  edited=""
  build
done
