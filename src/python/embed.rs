//! How ratelab starts its embedded interpreter: by its own rules, never by whatever `python3`
//! or virtual environment comes first on `PATH`.
//!
//! Left to itself, an embedded CPython takes the first `python3` on `PATH` for its own
//! executable and computes its home from it: a virtual environment's (its `pyvenv.cfg`, and
//! its `.pth` files run at start-up: PyPI's ROS 2 wheels' bootstrapper re-executes the
//! process and, embedded, dies as "Fatal Python error: init_import_site"), or another
//! installation's (Debian's `python3`, whose standard library lacks the modules Debian builds
//! into its own libpython: "No module named 'math'"). So:
//!
//! - **The interpreter** is the `libpython` the process runs on (the one ratelab was built
//!   against, found through an rpath), and its **home** the installation that library belongs
//!   to: the nearest folder above the library (the root aside) that holds its version's
//!   standard library (`lib/pythonX.Y/os.py`); else `PYTHONHOME`, if that holds it. With
//!   neither, the interpreter is not started: one line names the library found and why it
//!   cannot be used (exit 2). `sys.executable` is that home's `bin/pythonX.Y`.
//! - **Start-up** runs `site` only once the interpreter is up, from `startup.py`, with each
//!   `.pth` file's code kept from re-executing or ending the process.
//! - **Packages** of one environment are added: `VIRTUAL_ENV`'s site-packages, else
//!   `CONDA_PREFIX`'s, when it has a folder for the embedded Python's version (a warning says
//!   when it has not). `PYTHONPATH` counts, as for `python3`.
//!
//! An interpreter that runs already (a host's: `import ratelab`) is left as it is.

use pyo3::ffi;
use pyo3::prelude::*;
use pyo3::types::PyModule;
use std::ffi::{CStr, CString, OsStr};
use std::os::unix::ffi::OsStrExt;
use std::path::{Path, PathBuf};

const STARTUP_SOURCE: &CStr = {
    const BYTES: &[u8] = concat!(include_str!("startup.py"), "\0").as_bytes();
    match CStr::from_bytes_with_nul(BYTES) {
        Ok(s) => s,
        Err(_) => panic!("startup.py holds no NUL byte"),
    }
};

/// The environment variables that name the environment whose packages are added, in order:
/// the first one set is taken.
pub const ENVIRONMENTS: [&str; 2] = ["VIRTUAL_ENV", "CONDA_PREFIX"];

/// Start the interpreter by ratelab's rules (the module docs), unless one runs already.
/// Returns whether this call started it.
///
/// # Errors
/// One line naming the interpreter found and why it cannot be used.
pub fn initialize() -> Result<bool, String> {
    // SAFETY: Py_IsInitialized may be called at any time.
    if unsafe { ffi::Py_IsInitialized() } != 0 {
        return Ok(false);
    }
    let (major, minor) = version();
    let library = libpython()?;
    let home = home(&library, major, minor)?;
    let executable = executable(&home, major, minor);
    // SAFETY: the interpreter is not initialised (checked above); `start` runs once per
    // process (`SUPPORT`'s OnceLock), so nothing else initialises it meanwhile.
    unsafe { start_interpreter(&home, &executable) }.map_err(|e| {
        format!(
            "Python {major}.{minor} ({}, home {}) cannot start: {}",
            ratelab_core::text::printable(&library.to_string_lossy()),
            ratelab_core::text::printable(&home.to_string_lossy()),
            ratelab_core::text::printable(&e)
        )
    })?;
    Ok(true)
}

/// Run `startup.py` in the interpreter: `site` when `run_site` (an interpreter this process
/// started, without it), and the environment's packages ([`ENVIRONMENTS`]). Its warnings
/// go to stderr, one line each.
///
/// # Errors
/// The start-up's error, in one line.
pub fn run_startup(py: Python<'_>, run_site: bool) -> Result<(), String> {
    let version = py.version_info();
    let dirs = environment_packages(version.major, version.minor);
    let warnings: Vec<String> = PyModule::from_code(
        py,
        STARTUP_SOURCE,
        c"<ratelab startup>",
        c"_ratelab_startup",
    )
    .and_then(|m| m.call_method1("start", (dirs, run_site)))
    .and_then(|w| w.extract::<Vec<String>>())
    .map_err(|e| format!("Python's start-up failed: {e}"))?;
    for w in warnings {
        eprintln!("[ratelab] warning: {}", ratelab_core::text::printable(&w));
    }
    Ok(())
}

/// The embedded Python's version, `(major, minor)`.
fn version() -> (u32, u32) {
    // SAFETY: Py_GetVersion returns a static NUL-terminated string, before initialisation too.
    let text = unsafe { CStr::from_ptr(ffi::Py_GetVersion()) }.to_string_lossy();
    parse_version(&text).unwrap_or((3, 0))
}

/// `"3.11.7 (main, …)"` → `(3, 11)`.
fn parse_version(text: &str) -> Option<(u32, u32)> {
    let number = text.split_whitespace().next()?;
    let mut parts = number.split('.');
    let major = parts.next()?.parse().ok()?;
    let minor: String = parts
        .next()?
        .chars()
        .take_while(char::is_ascii_digit)
        .collect();
    Some((major, minor.parse().ok()?))
}

/// The file of the `libpython` this process runs on.
fn libpython() -> Result<PathBuf, String> {
    // SAFETY: zeroed is a valid Dl_info (null pointers); dlsym with RTLD_DEFAULT and a
    // NUL-terminated name only looks the symbol up; dladdr only fills `info`.
    let name = unsafe {
        let mut info: libc::Dl_info = std::mem::zeroed();
        let symbol = libc::dlsym(libc::RTLD_DEFAULT, c"Py_GetVersion".as_ptr());
        if symbol.is_null() || libc::dladdr(symbol, &mut info) == 0 || info.dli_fname.is_null() {
            None
        } else {
            Some(CStr::from_ptr(info.dli_fname).to_bytes().to_vec())
        }
    };
    let path = PathBuf::from(OsStr::from_bytes(
        &name.ok_or("cannot find the libpython this process runs on (dladdr)")?,
    ));
    Ok(std::fs::canonicalize(&path).unwrap_or(path))
}

/// Does `home` hold Python `major.minor`'s standard library?
fn has_stdlib(home: &Path, major: u32, minor: u32) -> bool {
    ["lib", "lib64"].iter().any(|lib| {
        let dir = home.join(lib).join(format!("python{major}.{minor}"));
        dir.join("os.py").is_file() || dir.join("os.pyc").is_file()
    })
}

/// The interpreter's home (the module docs): the nearest folder above `library` (the root
/// aside) that holds the standard library, else `PYTHONHOME` when it holds it.
fn home(library: &Path, major: u32, minor: u32) -> Result<PathBuf, String> {
    // Never the root: a Python installed there is none, and on a merged-/usr system `/lib`
    // is `/usr/lib`, the distribution's Python, which is not this library's.
    if let Some(home) = library
        .ancestors()
        .skip(1)
        .filter(|d| d.parent().is_some())
        .find(|d| has_stdlib(d, major, minor))
    {
        return Ok(home.to_path_buf());
    }
    let set = std::env::var_os("PYTHONHOME").filter(|h| !h.is_empty());
    if let Some(h) = &set {
        // `PYTHONHOME` may be `prefix:exec_prefix`: the standard library is under the prefix.
        let prefix = h
            .as_bytes()
            .split(|b| *b == b':')
            .next()
            .unwrap_or_default();
        if has_stdlib(Path::new(OsStr::from_bytes(prefix)), major, minor) {
            return Ok(PathBuf::from(h));
        }
    }
    let pythonhome = set.map_or_else(String::new, |h| {
        format!(
            ", nor does PYTHONHOME={}",
            ratelab_core::text::printable(&h.to_string_lossy())
        )
    });
    Err(format!(
        "ratelab embeds Python {major}.{minor} from {}, but no folder above it holds that Python's standard library (lib/python{major}.{minor}/os.py){pythonhome}: reinstall that Python, or rebuild ratelab with a complete one (scripts/setup-python.sh)",
        ratelab_core::text::printable(&library.to_string_lossy()),
    ))
}

/// The interpreter's `sys.executable`: `home`'s `bin/pythonX.Y` (or `python3`, `python`),
/// never a `python3` looked up on `PATH`.
fn executable(home: &Path, major: u32, minor: u32) -> PathBuf {
    let bin = home.join("bin");
    let names = [
        format!("python{major}.{minor}"),
        format!("python{major}"),
        "python".to_string(),
    ];
    names
        .iter()
        .map(|n| bin.join(n))
        .find(|p| p.is_file())
        .unwrap_or_else(|| bin.join(&names[0]))
}

/// The site-packages of the environment named by the first of [`ENVIRONMENTS`] that is set,
/// if it has a folder for Python `major.minor`; a warning otherwise.
fn environment_packages(major: u8, minor: u8) -> Vec<String> {
    let Some((var, env)) = ENVIRONMENTS.iter().find_map(|var| {
        std::env::var_os(var)
            .filter(|v| !v.is_empty())
            .map(|v| (*var, v))
    }) else {
        return Vec::new();
    };
    let dir = Path::new(&env).join(format!("lib/python{major}.{minor}/site-packages"));
    if !dir.is_dir() {
        // An environment of another Python version: say so rather than guess.
        eprintln!(
            "[ratelab] warning: {var}={} has no {} (ratelab embeds Python {major}.{minor}); its packages are not importable",
            ratelab_core::text::printable(&env.to_string_lossy()),
            ratelab_core::text::printable(&dir.to_string_lossy()),
        );
        return Vec::new();
    }
    vec![dir.to_string_lossy().into_owned()]
}

/// Initialise CPython with `home` and `executable` (`site` left for [`run_startup`]), then
/// release the interpreter's lock, as PyO3's own initialisation does.
///
/// # Safety
/// The interpreter is not initialised, and nothing else initialises it meanwhile.
unsafe fn start_interpreter(home: &Path, executable: &Path) -> Result<(), String> {
    let text = |p: &Path| {
        CString::new(p.as_os_str().as_bytes())
            .map_err(|_| format!("{} holds a NUL byte", p.display()))
    };
    let (home, executable) = (text(home)?, text(executable)?);
    // SAFETY (whole block): each PyConfig/PyPreConfig is initialised by its Init function
    // before use and cleared after; the strings outlive the calls that copy them.
    unsafe {
        // The locale as `Py_InitializeEx` leaves it: no C-locale coercion (which would set
        // LC_CTYPE in the environment of a process that runs threads already).
        let mut pre_config = std::mem::MaybeUninit::<ffi::PyPreConfig>::uninit();
        let pre = pre_config.as_mut_ptr();
        ffi::PyPreConfig_InitPythonConfig(pre);
        (*pre).coerce_c_locale = 0;
        (*pre).coerce_c_locale_warn = 0;
        status(ffi::Py_PreInitialize(pre))?;
        let mut config = std::mem::MaybeUninit::<ffi::PyConfig>::uninit();
        let c = config.as_mut_ptr();
        ffi::PyConfig_InitPythonConfig(c);
        (*c).parse_argv = 0;
        // Signals stay ratelab's (Ctrl-C is handled by the binary), stdio as it is.
        (*c).install_signal_handlers = 0;
        (*c).configure_c_stdio = 0;
        // `site` runs from `startup.py`, guarded, once the interpreter is up.
        (*c).site_import = 0;
        let started = status(ffi::PyConfig_SetBytesString(
            c,
            std::ptr::addr_of_mut!((*c).program_name),
            executable.as_ptr(),
        ))
        .and_then(|()| {
            status(ffi::PyConfig_SetBytesString(
                c,
                std::ptr::addr_of_mut!((*c).home),
                home.as_ptr(),
            ))
        })
        .and_then(|()| status(ffi::Py_InitializeFromConfig(c)));
        ffi::PyConfig_Clear(c);
        started?;
        ffi::PyEval_SaveThread();
    }
    Ok(())
}

/// A `PyStatus` as a result: its function and message when it is an error or an exit.
fn status(s: ffi::PyStatus) -> Result<(), String> {
    // SAFETY: PyStatus_Exception only reads the status; its strings are static or null.
    unsafe {
        if ffi::PyStatus_Exception(s) == 0 {
            return Ok(());
        }
        let text = |p: *const std::ffi::c_char| {
            (!p.is_null()).then(|| CStr::from_ptr(p).to_string_lossy().into_owned())
        };
        Err(match (text(s.func), text(s.err_msg)) {
            (Some(f), Some(m)) => format!("{f}: {m}"),
            (None, Some(m)) => m,
            _ => format!("it exited with status {}", s.exitcode),
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_version_is_read_from_python_s_own_string() {
        assert_eq!(
            parse_version("3.11.7 (main, May  9 2026, 07:35:25) [GCC 12.2.0]"),
            Some((3, 11))
        );
        assert_eq!(parse_version("3.13.0rc1 (main)"), Some((3, 13)));
        assert_eq!(parse_version("not a version"), None);
        assert_eq!(parse_version(""), None);
    }

    /// The running test links libpython: its home is found above it, and holds the
    /// standard library of its version; `sys.executable` is under that home.
    #[test]
    fn the_home_is_the_installation_of_the_libpython_linked() {
        let (major, minor) = version();
        let library = libpython().expect("the test binary links libpython");
        let home = home(&library, major, minor).expect("its installation is complete");
        assert!(
            library.starts_with(&home),
            "{} not under {}",
            library.display(),
            home.display()
        );
        assert!(has_stdlib(&home, major, minor));
        assert!(executable(&home, major, minor).starts_with(&home));
    }

    /// A library with no standard library above it (a Python version no folder up to `/`
    /// has) is refused in one line that names it and what is missing.
    #[test]
    fn a_library_without_a_standard_library_is_refused_in_one_line() {
        let dir = std::env::temp_dir().join(format!("ratelab-embed-{}", std::process::id()));
        let lib = dir.join("lib/libpython3.99.so.1.0");
        std::fs::create_dir_all(lib.parent().unwrap()).unwrap();
        let err = home(&lib, 3, 99).expect_err("no lib/python3.99/os.py above it");
        assert!(err.contains("libpython3.99.so.1.0"), "{err}");
        assert!(err.contains("lib/python3.99/os.py"), "{err}");
        assert!(!err.contains('\n'), "{err}");
        std::fs::create_dir_all(dir.join("lib/python3.99")).unwrap();
        std::fs::write(dir.join("lib/python3.99/os.py"), "").unwrap();
        assert_eq!(home(&lib, 3, 99).unwrap(), dir);
        let _ = std::fs::remove_dir_all(&dir);
    }
}
