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
# The library PyO3 links: LIBDIR/LDLIBRARY must be a shared object that exists (Debian's
# python3 says "shared" but ships libpython3.X.so only in libpython3.X-dev).
has_libpython() {
  python3 - <<'PY'
import os, sys, sysconfig
lib = sysconfig.get_config_var("LDLIBRARY") or ""
path = os.path.join(sysconfig.get_config_var("LIBDIR") or "", lib)
sys.exit(0 if ".so" in lib and os.path.exists(path) else 1)
PY
}
if ! has_libpython; then
  py="$(command -v python3)"
  ver="$(python3 -c 'import sys; print(f"{sys.version_info[0]}.{sys.version_info[1]}")')"
  if [ "$(readlink -f "$py")" = "/usr/bin/python$ver" ] && command -v apt-get >/dev/null && [ "$(id -u)" = 0 ]; then
    echo "ratelab: installing libpython$ver-dev (the shared libpython ratelab embeds) ..." >&2
    DEBIAN_FRONTEND=noninteractive apt-get install -y -qq "libpython$ver-dev" >&2 \
      || { apt-get update -qq >&2 && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq "libpython$ver-dev" >&2; }
  fi
fi
if ! has_libpython; then
  echo "ratelab: the python3 on PATH ($(command -v python3)) has no shared libpython, which ratelab embeds;" >&2
  echo "ratelab: install your distribution's libpython3-dev (Debian: apt-get install libpython3-dev) or use a Python built with --enable-shared" >&2
  exit 2
fi
stamp="$venv/.ratelab-numpy-$NUMPY_VERSION"
if [ ! -f "$stamp" ]; then
  echo "ratelab: making $venv with NumPy $NUMPY_VERSION ..." >&2
  python3 -m venv "$venv" >&2
  "$venv/bin/python" -m pip install --quiet --disable-pip-version-check "numpy==$NUMPY_VERSION" >&2
  touch "$stamp"
fi
echo "$venv"
