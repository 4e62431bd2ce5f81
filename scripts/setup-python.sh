#!/usr/bin/env bash
# Python for ratelab's Python brains and nodes (src/python), idempotent, offline once done:
# 1. checks that the `python3` on PATH has the shared libpython the build embeds (PyO3);
# 2. makes .venv/ (git-ignored) with the packages the shipped Python examples and the tests
#    import (NumPy, pinned), unless it is already there.
# Prints the environment's folder on stdout (the caller exports VIRTUAL_ENV=<it>).
set -euo pipefail
NUMPY_VERSION=2.4.6
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
venv="$root/.venv"
shared="$(python3 -c 'import sysconfig; print(sysconfig.get_config_var("Py_ENABLE_SHARED") or 0)')"
if [ "$shared" != "1" ]; then
  libdir="$(python3 -c 'import sysconfig; print(sysconfig.get_config_var("LIBDIR"))')"
  if ! ls "$libdir"/libpython3*.so >/dev/null 2>&1; then
    echo "ratelab: the python3 on PATH ($(command -v python3)) has no shared libpython, which ratelab embeds;" >&2
    echo "ratelab: install your distribution's libpython3-dev (Debian: apt-get install libpython3-dev) or use a Python built with --enable-shared" >&2
    exit 2
  fi
fi
stamp="$venv/.ratelab-numpy-$NUMPY_VERSION"
if [ ! -f "$stamp" ]; then
  echo "ratelab: making $venv with NumPy $NUMPY_VERSION ..." >&2
  python3 -m venv "$venv" >&2
  "$venv/bin/python" -m pip install --quiet --disable-pip-version-check "numpy==$NUMPY_VERSION" >&2
  touch "$stamp"
fi
echo "$venv"
