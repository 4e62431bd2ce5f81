//! The Python environment a user works in never breaks ratelab's embedded interpreter
//! (src/python/embed.rs, issue 74 item 2): with a ROS 2 user's virtual environment (PyPI's
//! ROS 2 wheels, whose `.pth` re-executes Python at start-up), Debian's `python3`, or a
//! virtual environment of Debian's `python3` first on `PATH`, a Python-node graph runs and
//! balances; a libpython whose installation has no standard library is refused in one line.
//!
//! The ROS 2 environment is the one `scripts/test.sh` makes (`scripts/setup-ros2-wheels.sh`,
//! `RATELAB_ROS2_VENV`); without it, and on a machine without `/usr/bin/python3`, the test
//! concerned says it is not run. NumPy comes, as for every Python test, from the virtual
//! environment the tests run in (`VIRTUAL_ENV`, scripts/test.sh's `.venv/`) unless a test
//! activates another.

use crate::{ratelab_in_repo_with, repo};
use std::ffi::OsString;
use std::path::{Path, PathBuf};
use std::process::Command;

fn ratelab() -> Command {
    Command::new(env!("CARGO_BIN_EXE_ratelab"))
}

/// `PATH` with `dir` first.
fn path_with_first(dir: &Path) -> OsString {
    let rest = std::env::var_os("PATH").unwrap_or_default();
    let dirs = std::iter::once(dir.to_path_buf()).chain(std::env::split_paths(&rest));
    std::env::join_paths(dirs).unwrap()
}

/// Run `graph` for 2 s of virtual time with `cmd` (the binary, its environment set); it must
/// balance with no sign of interpreter trouble. `what` names the environment in failures.
fn runs_and_balances(graph: &Path, cmd: &mut Command, what: &str) {
    let graph = graph.to_str().unwrap();
    let args = [
        "run",
        "--graph",
        graph,
        "--clock",
        "virtual",
        "--duration",
        "2",
    ];
    let (code, out, err) = ratelab_in_repo_with(&args, cmd);
    assert_eq!(code, 0, "{what}: {err}");
    assert!(out.contains("BALANCED"), "{what}: {out}{err}");
    for trouble in [
        "Fatal Python error",
        "Failed to bootstrap",
        "No module named",
        "[ratelab] warning",
    ] {
        assert!(!err.contains(trouble), "{what}: {err}");
    }
}

/// The ROS 2 user's environment (`RATELAB_ROS2_VENV`), checked to hold PyPI's ROS 2 wheels'
/// bootstrapper (what makes it the case this covers); `None` when the variable is not set.
fn ros2_venv() -> Option<PathBuf> {
    let Some(venv) = std::env::var_os("RATELAB_ROS2_VENV").map(PathBuf::from) else {
        eprintln!(
            "not run: RATELAB_ROS2_VENV is not set (scripts/test.sh makes the environment of PyPI's ROS 2 wheels and sets it)"
        );
        return None;
    };
    let bootstrapper = std::fs::read_dir(venv.join("lib"))
        .map(|dirs| {
            dirs.flatten().any(|d| {
                d.path()
                    .join("site-packages/ros_wheels_bootstrapper.pth")
                    .is_file()
            })
        })
        .unwrap_or(false);
    assert!(
        bootstrapper,
        "RATELAB_ROS2_VENV={} holds no ros_wheels_bootstrapper.pth: not PyPI's ROS 2 wheels (scripts/setup-ros2-wheels.sh)",
        venv.display()
    );
    Some(venv)
}

/// A ROS 2 user's environment, active (first on `PATH` and `VIRTUAL_ENV`): its `.pth`
/// bootstrapper is kept from re-executing ratelab, its packages are importable (the node
/// imports one of the wheels' modules, and NumPy comes from there); and only first on `PATH`
/// (NumPy from the tests' environment).
#[test]
fn a_python_node_graph_runs_with_a_ros2_venv_first_on_path() {
    // Processes of its own beside the suite: never beside a timing test.
    let _m = crate::machine::shared();
    let Some(venv) = ros2_venv() else { return };
    let dir = tempfile::tempdir().unwrap();
    let graph = crate::loud_python_graph(dir.path(), "import ament_index_python");
    let path = path_with_first(&venv.join("bin"));
    runs_and_balances(
        &graph,
        ratelab().env("PATH", &path).env("VIRTUAL_ENV", &venv),
        "the ROS 2 wheels' environment active",
    );
    runs_and_balances(
        &repo("graphs/cartpole-python.toml"),
        ratelab().env("PATH", &path),
        "the ROS 2 wheels' environment first on PATH",
    );
}

/// Debian's `python3` first on `PATH` (a folder holding `python3` → `/usr/bin/python3`),
/// then a virtual environment of it (as a ROS 2 user on Debian or Ubuntu makes one): its
/// standard library, which lacks the modules Debian builds into its own libpython (`math`),
/// is never taken for the embedded interpreter's.
#[test]
fn a_python_node_graph_runs_with_debian_s_python3_first_on_path() {
    // Processes of its own beside the suite: never beside a timing test.
    let _m = crate::machine::shared();
    let debian = Path::new("/usr/bin/python3");
    if !debian.is_file() {
        eprintln!("not run: this machine has no /usr/bin/python3 (Debian's)");
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    let bin = dir.path().join("bin");
    std::fs::create_dir(&bin).unwrap();
    std::os::unix::fs::symlink(debian, bin.join("python3")).unwrap();
    let graph = repo("graphs/cartpole-python.toml");
    runs_and_balances(
        &graph,
        ratelab().env("PATH", path_with_first(&bin)),
        "Debian's python3 first on PATH",
    );
    let venv = dir.path().join("venv");
    let made = Command::new(debian)
        .args(["-m", "venv", "--without-pip"])
        .arg(&venv)
        .output()
        .unwrap();
    assert!(
        made.status.success(),
        "{}",
        String::from_utf8_lossy(&made.stderr)
    );
    runs_and_balances(
        &graph,
        ratelab().env("PATH", path_with_first(&venv.join("bin"))),
        "a virtual environment of Debian's python3 first on PATH",
    );
}

/// The libpython ratelab links, as the loader resolves it (`ldd`): its file name and path.
fn linked_libpython() -> (String, PathBuf) {
    let ldd = Command::new("ldd")
        .arg(env!("CARGO_BIN_EXE_ratelab"))
        .output()
        .expect("ldd runs");
    String::from_utf8_lossy(&ldd.stdout)
        .lines()
        .find_map(|l| {
            let (name, rest) = l.trim().split_once(" => ")?;
            let path = rest.split(" (").next()?;
            name.starts_with("libpython")
                .then(|| (name.into(), path.into()))
        })
        .expect("ratelab links a shared libpython")
}

/// The libpython ratelab links, copied into a folder with no standard library above it and
/// loaded first (`LD_PRELOAD`, which the loader honours before any rpath): the run is refused
/// in one line that names the library and what is missing, exit 2 (never "Fatal Python
/// error").
#[test]
fn a_libpython_without_its_standard_library_is_refused_in_one_line() {
    // Processes of its own beside the suite: never beside a timing test.
    let _m = crate::machine::shared();
    let (name, path) = linked_libpython();
    let dir = tempfile::tempdir().unwrap();
    let lib = dir.path().join("lib");
    std::fs::create_dir(&lib).unwrap();
    let copy = lib.join(&name);
    std::fs::copy(&path, &copy).unwrap();
    let graph = repo("graphs/cartpole-python.toml");
    let (code, _, err) = ratelab_in_repo_with(
        &[
            "run",
            "--graph",
            graph.to_str().unwrap(),
            "--clock",
            "virtual",
        ],
        ratelab().env("LD_PRELOAD", &copy).env_remove("PYTHONHOME"),
    );
    assert_eq!(code, 2, "{err}");
    assert_eq!(err.trim().lines().count(), 1, "{err}");
    let named = std::fs::canonicalize(&copy).unwrap();
    assert!(err.contains(&*named.to_string_lossy()), "{err}");
    assert!(err.contains("standard library"), "{err}");
    assert!(!err.contains("Fatal"), "{err}");
}
