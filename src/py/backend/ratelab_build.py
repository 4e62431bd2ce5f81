"""ratelab's PEP 517 build backend: maturin's, after one step it cannot do itself.

mujoco-rs links MuJoCo's shared library at build time from `.mujoco/lib`
(`.cargo/config.toml`). The build environment holds the `mujoco==3.17.0` wheel (a
build requirement in pyproject.toml), so its `libmujoco.so.3.17.0` is copied there first,
with the `libmujoco.so` link the linker looks for. At run time the extension module loads
the same library from the installed `mujoco` package (its rpath, src/wheel/build.rs).

The wheel also carries the exercises and the graphs they run on (`ratelab/_lab/`), for
`ratelab.copy_exercises()` outside a clone: copied into the package's source folder for
the build and removed after (maturin packs what is there, but neither a symlink nor a
gitignored folder).
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
# The folders of the repository the wheel carries under ratelab/_lab.
LAB_FOLDERS = ("exercises", "graphs")


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


def _lab_copied():
    """Copy LAB_FOLDERS into the package's source folder, as ratelab/_lab; the folder made,
    or None when the tree has not got them (a build from an sdist)."""
    root = os.getcwd()
    if not all(os.path.isdir(os.path.join(root, d)) for d in LAB_FOLDERS):
        return None
    lab = os.path.join(root, "src", "py", "python", "ratelab", "_lab")
    if os.path.lexists(lab):
        shutil.rmtree(lab)
    skip = shutil.ignore_patterns("__pycache__", "*.pyc", ".*")
    for d in LAB_FOLDERS:
        shutil.copytree(os.path.join(root, d), os.path.join(lab, d), ignore=skip)
    return lab


def build_wheel(wheel_directory, config_settings=None, metadata_directory=None):
    _mujoco_for_the_link()
    lab = _lab_copied()
    try:
        return maturin.build_wheel(wheel_directory, config_settings, metadata_directory)
    finally:
        if lab is not None:
            shutil.rmtree(lab, ignore_errors=True)


def build_editable(wheel_directory, config_settings=None, metadata_directory=None):
    _mujoco_for_the_link()
    return maturin.build_editable(wheel_directory, config_settings, metadata_directory)
