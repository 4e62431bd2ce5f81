"""ratelab's PEP 517 build backend: maturin's, after one step it cannot do itself.

mujoco-rs links MuJoCo's shared library at build time from `.mujoco/lib`
(`.cargo/config.toml`). The build environment holds the `mujoco==3.17.0` wheel (a
build requirement in pyproject.toml), so its `libmujoco.so.3.17.0` is copied there first,
with the `libmujoco.so` link the linker looks for. At run time the extension module loads
the same library from the installed `mujoco` package (its rpath, src/wheel/build.rs).
"""

import importlib.util
import os
import shutil

import maturin
from maturin import (  # noqa: F401  (the rest of the backend is maturin's)
    build_sdist,
    get_requires_for_build_sdist,
    get_requires_for_build_wheel,
    prepare_metadata_for_build_wheel,
)

MUJOCO_SO = "libmujoco.so.3.17.0"


def _mujoco_for_the_link():
    lib = os.path.join(os.getcwd(), ".mujoco", "lib")
    target = os.path.join(lib, MUJOCO_SO)
    if not os.path.isfile(target):
        spec = importlib.util.find_spec("mujoco")
        if spec is None or not spec.submodule_search_locations:
            raise RuntimeError("ratelab's build needs the mujoco==3.17.0 wheel (a build requirement)")
        source = os.path.join(spec.submodule_search_locations[0], MUJOCO_SO)
        if not os.path.isfile(source):
            raise RuntimeError(f"the mujoco wheel has no {MUJOCO_SO} (is it 3.17.0?)")
        os.makedirs(lib, exist_ok=True)
        shutil.copyfile(source, target + ".part")
        os.replace(target + ".part", target)
    link = os.path.join(lib, "libmujoco.so")
    if not os.path.islink(link):
        if os.path.lexists(link):
            os.remove(link)
        os.symlink(MUJOCO_SO, link)


def build_wheel(wheel_directory, config_settings=None, metadata_directory=None):
    _mujoco_for_the_link()
    return maturin.build_wheel(wheel_directory, config_settings, metadata_directory)


def build_editable(wheel_directory, config_settings=None, metadata_directory=None):
    _mujoco_for_the_link()
    return maturin.build_editable(wheel_directory, config_settings, metadata_directory)
