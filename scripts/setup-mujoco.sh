#!/usr/bin/env bash
# Fetch MuJoCo 3.17.0's shared library from the PyPI wheel into .mujoco/lib (git-ignored).
# Idempotent: once .mujoco/lib/libmujoco.so exists this does nothing and needs no network.
set -euo pipefail
MUJOCO_VERSION=3.17.0
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
lib_dir="$root/.mujoco/lib"
so="libmujoco.so.$MUJOCO_VERSION"
if [ -f "$lib_dir/$so" ] && [ -L "$lib_dir/libmujoco.so" ]; then
  exit 0
fi
mkdir -p "$lib_dir"
tmp="$(mktemp -d)"
trap 'rm -rf "$tmp"' EXIT
echo "ratelab: fetching MuJoCo $MUJOCO_VERSION (PyPI wheel) into .mujoco/lib ..." >&2
python3 -m pip download --quiet --no-deps --only-binary=:all: \
  --platform manylinux2014_x86_64 --platform manylinux_2_17_x86_64 --platform manylinux_2_28_x86_64 \
  --python-version 3.11 --dest "$tmp" "mujoco==$MUJOCO_VERSION"
wheel="$(ls "$tmp"/mujoco-*.whl | head -n 1)"
python3 - "$wheel" "$lib_dir" "$so" <<'PY'
import sys, zipfile, shutil, os
wheel, out, so = sys.argv[1:]
with zipfile.ZipFile(wheel) as z:
    with z.open(f"mujoco/{so}") as src, open(os.path.join(out, so + ".part"), "wb") as dst:
        shutil.copyfileobj(src, dst)
os.replace(os.path.join(out, so + ".part"), os.path.join(out, so))
PY
ln -sfn "$so" "$lib_dir/libmujoco.so"
echo "ratelab: MuJoCo ready at $lib_dir" >&2
