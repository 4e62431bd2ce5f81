"""The start-up of ratelab's embedded interpreter (`src/python/embed.rs` runs it once, first).

The interpreter starts without `site` (ratelab's own rules choose its home, never a
`python3` or virtual environment first on PATH); `start` then runs `site` (the interpreter's
own site-packages, the user's, `sitecustomize`) and adds the site-packages of the
environment ratelab takes packages from. Every `.pth` file's code runs guarded: ratelab is
the process, and a `.pth` may neither replace it (`os.exec*`) nor end it (`sys.exit`,
`os._exit`). What it tried is said in a warning; a `.pth` that exits has the rest of its
lines skipped.
"""

import io
import os
import site
import sys

# PyPI's ROS 2 wheels install `ros_wheels_bootstrapper.pth`, which re-executes the
# interpreter (`os.execve(sys.executable, sys.orig_argv, env)`) to put the wheels'
# libraries on LD_LIBRARY_PATH, unless this variable says that was done. ratelab cannot be
# re-executed, and a running process's library path cannot change: told it is done, the
# bootstrapper does nothing (the wheels' Python modules are importable; rclpy's libraries
# load only if LD_LIBRARY_PATH already names them).
ROS_BOOTSTRAP_DONE = "_ROS_WHEELS_BOOTSTRAP_COMPLETE"

# What a `.pth` file's code may not call.
_REFUSED = (
    "execl",
    "execle",
    "execlp",
    "execlpe",
    "execv",
    "execve",
    "execvp",
    "execvpe",
    "_exit",
)


def start(dirs, run_site):
    """Run `site` (when `run_site`: the interpreter started without it), then add each
    folder of `dirs` (site-packages) as a site directory, unless it is on `sys.path`
    already. Returns the warnings, one line each."""
    warnings = []
    original = site.addpackage
    site.addpackage = _guarded(original, warnings)
    try:
        try:
            if run_site:
                site.main()
        except SystemExit as e:
            warnings.append(
                f"Python's site start-up tried to end the process (exit {e.code!r});"
                " the rest of it was skipped"
            )
        on_path = {os.path.realpath(p) for p in sys.path}
        for d in dirs:
            if os.path.realpath(d) not in on_path:
                site.addsitedir(d)
    finally:
        site.addpackage = original
    return warnings


def _guarded(addpackage, warnings):
    """`site.addpackage` with each `.pth` file run under `_Guard`."""

    def guarded(sitedir, name, known_paths):
        guard = _Guard(os.path.join(sitedir, name), warnings)
        with guard:
            return addpackage(sitedir, name, known_paths)
        # A `.pth` that ended the process: `_Guard` kept it from doing so.
        return known_paths

    return guarded


class _Guard:
    """While it lasts, `os.exec*` and `os._exit` refuse, `sys.exit` is caught, `os.environ`
    is a copy that says the ROS 2 wheels' bootstrap is done (what the `.pth` changes in it is
    copied back, that variable aside), and what goes to `sys.stderr` (`site`'s report of a
    line that raised, a traceback of many lines) becomes one warning."""

    def __init__(self, path, warnings):
        self.path = path
        self.warnings = warnings
        self.tried = False

    def __enter__(self):
        self.saved = {n: getattr(os, n) for n in _REFUSED if hasattr(os, n)}
        for name in self.saved:
            setattr(os, name, self._refuse(name))
        self.environ = os.environ
        self.added = ROS_BOOTSTRAP_DONE not in self.environ
        os.environ = dict(self.environ)
        os.environ[ROS_BOOTSTRAP_DONE] = "1"
        self.captured = io.StringIO()
        self.stderr, sys.stderr = sys.stderr, self.captured

    def __exit__(self, kind, value, tb):
        said, sys.stderr = self.captured.getvalue(), self.stderr
        copy, os.environ = os.environ, self.environ
        for name, f in self.saved.items():
            setattr(os, name, f)
        if self.added:
            copy.pop(ROS_BOOTSTRAP_DONE, None)
        for key in [k for k in self.environ if k not in copy]:
            del self.environ[key]
        for key, val in copy.items():
            if self.environ.get(key) != val:
                try:
                    self.environ[key] = val
                except (TypeError, ValueError):
                    pass  # not a string, or a NUL in it: the process's environment cannot hold it
        if kind is not None and issubclass(kind, SystemExit):
            if not self.tried:
                self.warnings.append(
                    f"{self.path} tried to end the process (exit {value.code!r});"
                    " the rest of it was skipped"
                )
            return True
        lines = [l.strip() for l in said.splitlines() if l.strip()]
        if lines and not self.tried:
            # `site` ends its report with "Remainder of file ignored"; the error is above it.
            skipped = lines[-1] == "Remainder of file ignored"
            error = lines[-2] if skipped and len(lines) > 1 else lines[-1]
            rest = "; the rest of it was skipped" if skipped else ""
            self.warnings.append(f"{self.path}: {error}{rest}")
        return False

    def _refuse(self, name):
        def refused(*args, **kwargs):
            if not self.tried:
                self.tried = True
                self.warnings.append(
                    f"{self.path} tried to replace or end the process (os.{name});"
                    " ratelab refused"
                )
            if name == "_exit":
                raise SystemExit(args[0] if args else None)
            raise OSError(f"ratelab embeds Python: a .pth file may not call os.{name}")

        return refused
