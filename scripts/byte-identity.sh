#!/usr/bin/env bash
# Byte identity across a change: build the commit BASE (default HEAD~1) and this checkout,
# run the same configurations with both binaries from this checkout's root, and compare.
#
#   scripts/byte-identity.sh [BASE]
#
# Compared, byte for byte:
#   - metrics.json and trace.csv of every configuration in
#     ../shared/fixtures/reference-runs/commands.txt (the default; 5 Hz; 10 Hz, depth 100,
#     seed 2; the estimator, safety, python, setpoint, executors, position-python,
#     estimator-python and safety-python graphs; a watchdog stall; a lossy link; a lockstep
#     across processes; …);
#   - what every virtual-clock exercise prints, and its exit code (ex1, ex2, ex4 to ex8; ex3
#     and ex9 measure the real clock, which no two runs repeat).
# The reference recording's content is checked by the test suite against the committed
# recordings/reference-virtual-control50-seed0.rrd (tests/it/recording.rs), not here: a
# recording's bytes hold its own id and wall-clock times.
#
# With BYTE_IDENTITY_KEEP=DIR the two binaries are kept there (ratelab-base, ratelab-head),
# for an A/B of their timings after.
#
# Run it once per change of the run core. Exit 0: identical; 1: something differs (named);
# 2: a build failed. Both builds share cargo's target directory (only ratelab's own crates
# are rebuilt for each).
set -euo pipefail
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
base="${1:-HEAD~1}"
target="${CARGO_TARGET_DIR:-$HOME/.cache/ratelab/target}"
commands="$root/../shared/fixtures/reference-runs/commands.txt"
[ -f "$commands" ] || { echo "byte-identity: $commands not found (../shared beside the checkout)" >&2; exit 2; }

"$root/scripts/setup-mujoco.sh"
VIRTUAL_ENV="$("$root/scripts/setup-python.sh")"
export VIRTUAL_ENV

work="$(mktemp -d)"
cleanup() {
    git -C "$root" worktree remove --force "$work/base" >/dev/null 2>&1 || true
    rm -rf "$work"
}
trap cleanup EXIT

git -C "$root" worktree add -q --detach "$work/base" "$base" ||
    { echo "byte-identity: no commit '$base'" >&2; exit 2; }
ln -s "$root/.mujoco" "$work/base/.mujoco"
# The same MuJoCo path for both builds, so mujoco-rs is not rebuilt between them.
export MUJOCO_DYNAMIC_LINK_DIR="$root/.mujoco/lib"
build() { # DIR OUT
    # Cargo names a path crate's artifacts and fingerprints by its path within the
    # workspace, so the two checkouts' crates share them: touching this checkout's sources
    # makes cargo rebuild them instead of taking the other build's as fresh.
    find "$1/src" "$1/lab" "$1/build.rs" -name '*.rs' -print0 | xargs -0 -r touch
    (cd "$1" && CARGO_TARGET_DIR="$target" cargo build --release --locked -p ratelab-lab --bin ratelab) ||
        { echo "byte-identity: the build of $1 failed" >&2; exit 2; }
    cp "$target/release/ratelab" "$2"
}
build "$work/base" "$work/ratelab-base"
build "$root" "$work/ratelab-head"
if [ -n "${BYTE_IDENTITY_KEEP:-}" ]; then
    mkdir -p "$BYTE_IDENTITY_KEEP"
    cp "$work/ratelab-base" "$work/ratelab-head" "$BYTE_IDENTITY_KEEP/"
fi

differ=0
say_differs() { echo "DIFFERS: $*"; differ=1; }
cd "$root"
while IFS='|' read -r name args; do
    [ -n "$name" ] || continue
    for side in base head; do
        # shellcheck disable=SC2086 # the arguments are words
        "$work/ratelab-$side" $args --out "$work/out-$side/$name" >"$work/$side-$name.log" 2>&1 || true
    done
    for file in metrics.json trace.csv; do
        a="$work/out-base/$name/$file" b="$work/out-head/$name/$file"
        if [ -f "$a" ] || [ -f "$b" ]; then
            cmp -s "$a" "$b" || say_differs "$name/$file"
        elif [ "$file" = metrics.json ]; then
            say_differs "$name: neither binary wrote metrics.json ($(tail -1 "$work/head-$name.log"))"
        fi
    done
done <"$commands"

# The exercises with a prediction filled in (the examples their files give), so each runs
# its measurement and reconciles.
cp -r "$root/exercises" "$work/exercises"
ln -s "$root/graphs" "$work/graphs" # the exercises name graphs as ../graphs/…
predict() { # KEY VALUE
    sed -i -E "s|^# $1 =\$|$1 = $2|" "$work"/exercises/ex*.toml
}
predict fails_at_hz 12.5
predict deep_queue_obs_drops 40
predict deep_queue_balances true
predict latest_balances true
predict fifo_balances false
predict fifo_latency_at_fall_ms 100
predict lifespan_balances true
predict survives_low_loss true
predict survives_high_loss false
predict keeps_it_up '["hold"]'
predict reliable_latency_ms 5
predict smallest_clamp_n 4
predict sensor_hz_single_threaded 50
predict skipped_ticks_single_threaded 0
predict balances_single_threaded true
predict sensor_hz_shared_group 50
predict sensor_hz_own_group 50
predict fails_at_noise_rad 0.03
predict lower_cutoff_tolerates_more true
sed -i -E 's|^why = ""$|why = "byte identity"|' "$work"/exercises/ex*.toml
for ex in ex1 ex2 ex4 ex5 ex6 ex7 ex8; do
    for side in base head; do
        set +e
        "$work/ratelab-$side" exercise "$ex" --headless --dir "$work/exercises" >"$work/$side-$ex.out" 2>&1
        echo "exit $?" >>"$work/$side-$ex.out"
        set -e
    done
    # Each measured and reconciled (ex6 refuses its untouched template, by design).
    grep -q "exit [01]$" "$work/head-$ex.out" || [ "$ex" = ex6 ] ||
        say_differs "exercise $ex did not run: $(head -1 "$work/head-$ex.out")"
    cmp -s "$work/base-$ex.out" "$work/head-$ex.out" || {
        say_differs "exercise $ex"
        diff "$work/base-$ex.out" "$work/head-$ex.out" | head -20 || true
    }
done

runs="$(grep -c '|' "$commands")"
if [ "$differ" = 0 ]; then
    echo "byte-identity: $base and this checkout agree on $runs runs and 7 exercises"
fi
exit "$differ"
