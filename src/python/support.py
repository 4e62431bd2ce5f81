"""ratelab's side of the embedded interpreter (src/python): loads a learner's script, calls
its brain, and says in one line what went wrong. Internal to ratelab, not an API: learners
write plain functions and classes and never import this module.

Every error a learner can cause is reported as `FILE:LINE: ExceptionType: message`, the
line being the innermost frame in the learner's own files (the folder of the script), so a
NumPy internal never hides where the learner's code went wrong.
"""

import inspect
import math
import os
import sys
import threading
import time
import traceback
import types
import unicodedata


# ---- blocking calls a stop can interrupt ------------------------------------------------
# A stop (Ctrl-C, SIGTERM, quitting the lab) raises KeyboardInterrupt inside a learner's
# callback that is still running (PyThreadState_SetAsyncExc, src/python/lib.rs), but Python
# delivers it only between bytecodes: a callback blocked in one long C call (`time.sleep(60)`,
# `threading.Event().wait()`) would not see it until the call returned. These two, the usual
# ways a learner waits, are made of slices of at most _SLICE_S seconds, so the stop lands
# within a slice; what they do and return is unchanged. Other blocking C calls (a socket,
# a lock's acquire) still block until they return.
_SLICE_S = 0.05
_real_sleep = time.sleep
_real_event_wait = threading.Event.wait


def _sleep(seconds):
    if not isinstance(seconds, (int, float)) or not math.isfinite(seconds) or seconds <= 0:
        return _real_sleep(seconds)  # its own errors (a type, NaN, inf, a negative value), 0
    end = time.monotonic() + seconds
    while True:
        left = end - time.monotonic()
        if left <= 0:
            return None
        _real_sleep(min(left, _SLICE_S))


def _event_wait(self, timeout=None):
    end = None if timeout is None else time.monotonic() + max(0.0, timeout)
    while True:
        left = _SLICE_S if end is None else min(_SLICE_S, end - time.monotonic())
        if left <= 0:
            return self.is_set()
        if _real_event_wait(self, left):
            return True


_sleep.__doc__ = _real_sleep.__doc__
_event_wait.__doc__ = _real_event_wait.__doc__
time.sleep = _sleep
threading.Event.wait = _event_wait


# ---- what learners' code writes -----------------------------------------------------------
# `print`, `sys.stderr`, Python's warnings (NumPy's RuntimeWarning): each line goes to the
# run's text log (`_log`, src/core/textlog.rs), stamped with the tick it was written in, never
# straight onto a terminal where the lab draws.


class _Lines:
    """A text stream whose lines go to the run's text log at one level. Each thread has its
    own partial line: `print` writes a line in pieces, and nodes on the real clock's threads
    print at once (one buffer for all would splice one node's pieces into another's line)."""

    encoding = "utf-8"
    errors = "replace"
    _MAX = 4096  # a line longer than this is cut into pieces of this size

    def __init__(self, level):
        self._level = level
        self._partial = {}  # thread id -> its line so far

    def write(self, s):
        s = str(s)
        key = threading.get_ident()
        buf = self._partial.pop(key, "") + s
        while "\n" in buf:
            line, buf = buf.split("\n", 1)
            _log(self._level, line)
        while len(buf) > self._MAX:
            _log(self._level, buf[: self._MAX])
            buf = buf[self._MAX :]
        if buf:
            self._partial[key] = buf
        return len(s)

    def flush(self):
        """Log this thread's partial line (a `print(..., end="")` then `flush`)."""
        buf = self._partial.pop(threading.get_ident(), "")
        if buf:
            _log(self._level, buf)

    def flush_all(self):
        """Log every thread's partial line (the run is over)."""
        for key in list(self._partial):
            buf = self._partial.pop(key, "")
            if buf:
                _log(self._level, buf)

    def writable(self):
        return True

    def isatty(self):
        return False


# Runs going at once (`ratelab.run` from several threads) share one capture: the first to
# start installs it, the last to end puts back the streams as they were before the first.
_capturing = {"runs": 0, "before": None}
_capture_lock = threading.Lock()


def _capture_output():
    """Send `sys.stdout` and `sys.stderr` to the run's text log (each line to the log of the
    run whose thread wrote it); returns a token for `_restore_output`."""
    with _capture_lock:
        if _capturing["runs"] == 0:
            _capturing["before"] = (sys.stdout, sys.stderr)
            sys.stdout = _Lines("info")
            sys.stderr = _Lines("warn")
        _capturing["runs"] += 1
        return _capturing["before"]


def _restore_output(prev):
    """Called once for each `_capture_output` (`prev`, its token): when no other run is
    going, the last partial lines are logged and the streams put back as they were."""
    with _capture_lock:
        _capturing["runs"] = max(0, _capturing["runs"] - 1)
        if _capturing["runs"] > 0:
            return
        try:
            for stream in (sys.stdout, sys.stderr):
                if isinstance(stream, _Lines):
                    stream.flush_all()
        finally:  # the streams put back whatever logging the last lines did
            sys.stdout, sys.stderr = _capturing["before"] or prev
            _capturing["before"] = None


def joining(threads, me):
    """Which of `threads` (Python thread ids, each in a call into learners' code) is inside
    `threading.Thread.join` on thread `me` with no timeout, read from its frames: that
    thread's id, or None. A blocked join is among a thread's innermost frames (3.13:
    `join` itself; before, `join` then `_wait_for_tstate_lock`); its `self` is the thread
    joined. A join with a timeout ends on its own and is let be."""
    frames = sys._current_frames()
    for tid in threads:
        f, depth = frames.get(tid), 0
        while f is not None and depth < 8:
            code = f.f_code
            if code.co_name == "join" and os.path.basename(code.co_filename) == "threading.py":
                joined, timeout = f.f_locals.get("self"), f.f_locals.get("timeout")
                if isinstance(joined, threading.Thread) and joined.ident == me and timeout is None:
                    return tid
                break
            f, depth = f.f_back, depth + 1
    return None


def _known_by(fn):
    """The name a callable brain is shown by, and the file its code says it was written in
    (`"<callable>"` when none says): a function's own (`act`); a `functools.partial`'s
    function's, said so (`partial(act)`); a callable object's class and its `__call__`
    (`Brain.__call__`), the class's own file when `__call__` is inherited (a
    `torch.nn.Module`'s is torch's, not where the brain was written)."""
    import functools

    inner, partials = fn, 0
    while isinstance(inner, functools.partial):
        inner, partials = inner.func, partials + 1
    code = getattr(inner, "__code__", None)
    name = getattr(inner, "__name__", None)
    script = code.co_filename if code else "<callable>"
    if code is None and not isinstance(inner, type):
        cls = type(inner)
        name = name or f"{cls.__qualname__}.__call__"
        own = cls.__dict__.get("__call__")
        if getattr(own, "__code__", None) is not None:
            script = own.__code__.co_filename
        else:
            try:
                script = inspect.getfile(cls)
            except (TypeError, OSError):  # a class of the interpreter's or a builtin's
                pass
    shown = name or "act"
    for _ in range(partials):
        shown = f"partial({shown})"
    return shown, script


def callable_brain(fn):
    """`brain_caller` for a function object the caller holds (`ratelab.run(policy=fn)`): the
    same conversions as for `FILE.py:FUNCTION`, so the same code gives the same run. Returns
    the caller, the file its code names (for tracebacks) and how the run names the brain."""
    import types

    name = getattr(fn, "__name__", "act")
    if not callable(fn):
        raise ContractError("policy", f"a {type(fn).__name__} is not a function")
    shown_name, script = _known_by(fn)
    # How the run names it: by its file where it has one. A function typed into a notebook
    # cell or the interpreter has none; its code's file name (a kernel's temporary name,
    # new every session, which Jupyter's debugger writes out) would make one brain's runs
    # differ by their label.
    if "ipykernel_" in script or script.startswith("<ipython-input-"):
        shown = f"{shown_name} in a notebook cell"
    elif os.path.isfile(script):
        shown = f"{script}:{shown_name}"
    else:
        shown = f"{shown_name} in {script}"
    return brain_caller(types.SimpleNamespace(**{name: fn}), name, script), script, shown


class ContractError(Exception):
    """A script broke ratelab's contract (a missing function, a wrong return value)."""

    def __init__(self, where, message):
        super().__init__(message)
        self.where = where


def _one_line(text):
    """`text` as one line a terminal shows as it is: whitespace runs (newlines too) become
    one space, and any other control character (ESC, DEL, C1) is written out as Rust's
    `char::escape_default` writes it (`\\u{1b}`), as ratelab's `text::printable` does."""
    folded = " ".join(str(text).split())
    return "".join(
        f"\\u{{{ord(c):x}}}" if unicodedata.category(c) == "Cc" else c for c in folded
    )


def _where(filename, lineno):
    """`FILE:LINE`, or for code of a notebook cell the name IPython shows it by ("Cell
    In[3], line 5") rather than the kernel's temporary file."""
    ipython = sys.modules.get("IPython")
    try:
        shell = ipython.get_ipython() if ipython is not None else None
        named = shell.compile.format_code_name(filename) if shell is not None else None
    except Exception:  # an IPython without it: the file's name
        named = None
    if named:
        return f"{named[0]} {named[1]}, line {lineno}"
    return f"{filename}:{lineno}"


def describe(exc, script, tb=None):
    """One line for `exc` raised by code of `script` (its path as the user gave it), `tb`
    its traceback (default: `exc.__traceback__`)."""
    if isinstance(exc, ContractError):
        return f"{exc.where}: {_one_line(exc)}"
    name = type(exc).__name__
    if isinstance(exc, SyntaxError) and exc.filename == script:
        return f"{script}:{exc.lineno}: {name}: {_one_line(exc.msg)}"
    frames = traceback.extract_tb(tb if tb is not None else exc.__traceback__)
    mine = _mine(frames, script)
    # Code typed at a prompt or given to `python -c` (`<stdin>`, `<string>`) is not in a
    # file beside `script`: its innermost frame, never this module's, is still the learner's.
    theirs = [f for f in frames if not _ratelab_s(f.filename)]
    frame = (mine or theirs or frames or [None])[-1]
    where = _where(frame.filename, frame.lineno) if frame is not None else script
    message = _one_line(exc)
    return f"{where}: {name}: {message}" if message else f"{where}: {name}"


def _ratelab_s(filename):
    """Whether `filename` is ratelab's own code: this module (`<ratelab>`) or the Python
    package's files (its `ratelab.run` between a learner's line and a refusal)."""
    if filename == "<ratelab>":
        return True
    package = getattr(sys.modules.get("ratelab"), "__file__", None)
    if not package:
        return False
    folder = os.path.dirname(os.path.abspath(package))
    return os.path.abspath(filename).startswith(folder + os.sep)


def _mine(frames, script):
    """The frames of `frames` in the learner's own files: those in the folder of `script`,
    never ratelab's own (this module's, whose file name starts with `<`)."""
    folder = os.path.dirname(os.path.abspath(script))
    return [
        f
        for f in frames
        if not f.filename.startswith("<")
        and os.path.dirname(os.path.abspath(f.filename)) == folder
    ]


def traceback_of(exc, script, tb=None):
    """What the lab's log pane shows of `exc`, raised in a callback of `script`, beside its
    one line (`describe`): the learner's frames (as `describe` takes them), outermost first,
    each `(file, line, function, code)`, and the whole traceback as Python prints it, line
    by line. `tb` is its traceback (default: `exc.__traceback__`)."""
    tb = tb if tb is not None else exc.__traceback__
    mine = [
        (f.filename, f.lineno or 0, f.name, (f.line or "").strip())
        for f in _mine(traceback.extract_tb(tb), script)
    ]
    whole = "".join(traceback.format_exception(type(exc), exc, tb)).splitlines()
    return mine, whole


def load_module(script, source, module_name):
    """Run `source` (the text of `script`) as a fresh module and return it. The script's
    folder goes first on sys.path, as `python script.py` does, so it can import its
    neighbours."""
    code = compile(source, script, "exec", dont_inherit=True)
    module = types.ModuleType(module_name)
    module.__file__ = script
    folder = os.path.dirname(os.path.abspath(script))
    if folder not in sys.path:
        sys.path.insert(0, folder)
    sys.modules[module_name] = module
    exec(code, module.__dict__)
    return module


def brain_caller(module, function, script):
    """The chapter's `load_policy` contract for `FILE.py:FUNCTION`: `FUNCTION(obs)` with the
    observation as a NumPy float32[5] array, returning a float or a one-element array-like,
    converted to float32. Returns a callable from a 5-tuple of floats to a Python float
    (ratelab clips it to [-1, 1])."""
    fn = getattr(module, function, None)
    if fn is None:
        defined = sorted(
            k for k, v in vars(module).items() if callable(v) and not k.startswith("_")
        )
        hint = f" (it defines {', '.join(defined)})" if defined else ""
        raise ContractError(script, f"no function '{function}'{hint}; a brain is "
                            f"`def {function}(obs): return action`")
    if not callable(fn):
        raise ContractError(script, f"'{function}' is a {type(fn).__name__}, not a function")
    code = getattr(fn, "__code__", None)
    where = f"{code.co_filename}:{code.co_firstlineno}" if code else script
    # Refused before the run when it cannot take the observation, as a callable brain is,
    # naming its own signature (not a line of ratelab's, at its first call).
    try:
        sig = inspect.signature(fn)
    except Exception:  # no signature Python can read (a builtin; an annotation it cannot
        sig = None  # resolve): judged when called
    if sig is not None:
        try:
            sig.bind(None)
        except TypeError:
            raise ContractError(where, f"a brain is called with one argument, the observation "
                                f"(`def {function}(obs): return action`); {function}{sig} "
                                "cannot take it") from None
    import numpy as np

    array, asarray, f32 = np.array, np.asarray, np.float32

    def call(obs):
        result = fn(array(obs, dtype=f32))
        a = None
        if result is not None:  # NumPy would take None for NaN: a brain that forgot to return
            try:
                a = asarray(result, dtype=f32)
            except (TypeError, ValueError):
                pass
        if a is None or a.size != 1:
            shown = repr(result)
            shown = shown if len(shown) <= 60 else shown[:57] + "..."
            raise ContractError(where, f"{function}() returned {shown}; expected a float "
                                "or a one-element array (the force command in [-1, 1])")
        return float(a.reshape(-1)[0])

    return call


# ---- Python nodes (src/python/node.rs): an rclpy-shaped handle over one ratelab process -----

def _is_lent(value):
    """A read-only view of bytes, as a received message's bytes field is lent to Python (a
    `memoryview` of the message's own bytes, src/python/node.rs `lend_bytes`): kept as it
    is, not copied."""
    if type(value) is not memoryview:
        return False
    try:
        return (type(value.obj).__name__ == "SharedBytes" and value.readonly
                and value.format == "B" and value.ndim == 1)
    except ValueError:  # a released view
        return False


def _as_kind(kind, value, name):
    """`value` as a field of `kind` holds it: `number` a float, `integer` an int, `text` a
    str, `bytes` bytes (from bytes, a bytearray or a contiguous NumPy array:
    `arr.astype(np.uint8)`), or a received message's bytes kept as they are (a read-only
    `memoryview` of them where they arrived, not a copy; any other view is copied)."""
    if kind == "text":
        if value is None:
            return ""
        if not isinstance(value, str):
            raise TypeError(f"field '{name}' takes a str, got {type(value).__name__}")
        return value
    if kind == "integer":
        if value is None:
            return 0
        try:
            whole = int(value)
        except (TypeError, ValueError, OverflowError):
            whole = None
        if whole is None or whole != value:
            raise TypeError(f"field '{name}' takes a whole number, got {value!r}")
        return whole
    if kind == "bytes":
        if value is None:
            return b""
        if type(value) is bytes or _is_lent(value):
            return value  # as it came in: not copied again
        try:
            return bytes(memoryview(value))
        except (TypeError, ValueError, BufferError) as e:
            raise TypeError(f"field '{name}' takes bytes (or a contiguous array), got "
                            f"{type(value).__name__}: {e}") from None
    if value is None:
        return 0.0
    # A number of any kind (int, float, NumPy's scalars, a 0-d array), never a text that
    # reads as one: float("1.5") would take it, and float("x") fail inside ratelab.
    if not isinstance(value, (str, bytes, bytearray)):
        try:
            return float(value)
        except (TypeError, ValueError, OverflowError):
            pass
    raise TypeError(f"field '{name}' takes a number, got {type(value).__name__} {value!r:.40}")


class _Msg:
    """A message with named fields in SI units; positional or keyword construction."""

    __slots__ = ()
    FIELDS = ()
    # Per field: "number", "text" or "bytes"; empty: every field a number.
    KINDS = ()

    def _kinds(self):
        return self.KINDS or ("number",) * len(self.FIELDS)

    def __init__(self, *args, **kwargs):
        if len(args) > len(self.FIELDS):
            raise TypeError(f"{type(self).__name__} has {len(self.FIELDS)} fields: "
                            f"{', '.join(self.FIELDS)}")
        values = dict(zip(self.FIELDS, args))
        for k, v in kwargs.items():
            if k not in self.FIELDS:
                raise TypeError(f"{type(self).__name__} has no field '{k}' "
                                f"(fields: {', '.join(self.FIELDS)})")
            values[k] = v
        for k, kind in zip(self.FIELDS, self._kinds()):
            object.__setattr__(self, k, _as_kind(kind, values.get(k), k))

    def __repr__(self):
        def shown(k):
            v = getattr(self, k)
            return f"<{len(v)} bytes>" if isinstance(v, (bytes, memoryview)) else repr(v)
        inner = ", ".join(f"{k}={shown(k)}" for k in self.FIELDS)
        return f"{type(self).__name__}({inner})"

    def _fields(self):
        return tuple(_as_kind(kind, getattr(self, k), k)
                     for k, kind in zip(self.FIELDS, self._kinds()))


# The ROS 2 types each class is offered as (`--ros2`, src/core/ros_types.rs; docs/ros2.md):
# `to_ros()` gives the ROS 2 message's fields as a dict (`JointState(**s.to_ros())` in
# rclpy; the header is left to the publisher), `from_ros(msg)` reads a ROS 2 message (an
# rclpy or rosbags object, or a dict) with the same conversion ratelab's bridge uses.
JOINT_NAMES = ("slider", "hinge")


def _ros_field(msg, name):
    return msg[name] if isinstance(msg, dict) else getattr(msg, name)


def _joints(msg, velocities):
    names = list(_ros_field(msg, "name"))
    if names and tuple(names) != JOINT_NAMES:
        raise ValueError(f"JointState names {names}, not {list(JOINT_NAMES)}")
    pos = [float(v) for v in _ros_field(msg, "position")]
    vel = [float(v) for v in _ros_field(msg, "velocity")] if velocities else [0.0, 0.0]
    if len(pos) != 2 or len(vel) != 2:
        raise ValueError("a JointState needs both joints' positions"
                         + (" and velocities" if velocities else ""))
    if not all(math.isfinite(v) for v in pos + vel):
        raise ValueError("a JointState with a non-finite position or velocity")
    return pos, vel


class State(_Msg):
    """The full state, the chapter's observation (float32 on the wire): cart position m,
    cart velocity m/s, cos θ, sin θ, pole angular velocity rad/s. ROS 2:
    `sensor_msgs/msg/JointState` (joints slider, hinge; the pole's position is
    atan2(sin θ, cos θ))."""

    __slots__ = ("cart_pos_m", "cart_vel_m_s", "cos_theta", "sin_theta", "pole_angvel_rad_s")
    FIELDS = __slots__
    ROS_TYPE = "sensor_msgs/msg/JointState"

    def to_ros(self):
        theta = math.atan2(self.sin_theta, self.cos_theta)
        return {"name": list(JOINT_NAMES), "position": [self.cart_pos_m, theta],
                "velocity": [self.cart_vel_m_s, self.pole_angvel_rad_s], "effort": []}

    @classmethod
    def from_ros(cls, msg):
        (x, theta), (x_dot, theta_dot) = _joints(msg, True)
        return cls(x, x_dot, math.cos(theta), math.sin(theta), theta_dot)


class Position(_Msg):
    """A position measurement: cart position m, pole angle from upright rad. ROS 2:
    `sensor_msgs/msg/JointState` without velocities."""

    __slots__ = ("cart_pos_m", "pole_angle_rad")
    FIELDS = __slots__
    ROS_TYPE = "sensor_msgs/msg/JointState"

    def to_ros(self):
        return {"name": list(JOINT_NAMES), "position": [self.cart_pos_m, self.pole_angle_rad],
                "velocity": [], "effort": []}

    @classmethod
    def from_ros(cls, msg):
        (x, theta), _ = _joints(msg, False)
        return cls(x, theta)


class Force(_Msg):
    """A force on the cart, N (the motor's range is ±10 N; the plant clips beyond it).
    ROS 2: `std_msgs/msg/Float64`."""

    __slots__ = ("newtons",)
    FIELDS = __slots__
    ROS_TYPE = "std_msgs/msg/Float64"

    def to_ros(self):
        return {"data": self.newtons}

    @classmethod
    def from_ros(cls, msg):
        return cls(float(_ros_field(msg, "data")))


class Image(_Msg):
    """A camera's frame: height and width px, encoding (`mono8`: a byte of brightness a
    pixel), step (bytes per row), data (the pixels, row after row: bytes, or as a received
    frame arrives, a read-only `memoryview` of the frame where it arrived, not a copy;
    `np.frombuffer(img.data, np.uint8).reshape(img.height, img.step)` reads either in
    place). ROS 2:
    `sensor_msgs/msg/Image` (multi-byte pixels little-endian)."""

    __slots__ = ("height", "width", "encoding", "step", "data")
    FIELDS = __slots__
    KINDS = ("integer", "integer", "text", "integer", "bytes")
    ROS_TYPE = "sensor_msgs/msg/Image"

    def to_ros(self):
        return {"height": self.height, "width": self.width, "encoding": self.encoding,
                "is_bigendian": 0, "step": self.step, "data": bytes(self.data)}

    @classmethod
    def from_ros(cls, msg):
        img = cls(int(_ros_field(msg, "height")), int(_ros_field(msg, "width")),
                  str(_ros_field(msg, "encoding")), int(_ros_field(msg, "step")),
                  _ros_field(msg, "data"))
        # Byte order matters only for pixels of more than a byte (mono16, 32FC1).
        if (int(_ros_field(msg, "is_bigendian")) != 0
                and any(bits in img.encoding for bits in ("16", "32", "64"))):
            raise ValueError(f"an Image of {img.encoding} with big-endian pixels "
                             "(is_bigendian 1): ratelab reads little-endian ones")
        if img.step < img.width:
            raise ValueError(f"an Image whose step ({img.step} bytes a row) is less than its "
                             f"width ({img.width} px)")
        if len(img.data) != img.step * img.height:
            raise ValueError(f"an Image of {len(img.data)} bytes, not step × height = "
                             f"{img.step} × {img.height}")
        return img


MESSAGE_TYPES = {"state": State, "position": Position, "force": Force, "image": Image}


class Time:
    """A run time, as rclpy's `Time`: `.nanoseconds` (int) and `.seconds` (float)."""

    __slots__ = ("nanoseconds",)

    def __init__(self, nanoseconds):
        self.nanoseconds = nanoseconds

    @property
    def seconds(self):
        return self.nanoseconds / 1e9

    def __repr__(self):
        return f"Time(nanoseconds={self.nanoseconds})"


class Clock:
    """The run's clock (virtual or real): `now()` is the current tick's run time."""

    def __init__(self, runtime):
        self._runtime = runtime

    def now(self):
        return Time(self._runtime.now_ns)


class Logger:
    """`info`, `warn`/`warning`, `error`: one line of the run's text log, naming the node,
    shown as `info: text`; on /rosout the text alone, with the file, function and line
    that called the logger (as rclpy's logger gives rcl)."""

    def __init__(self, name):
        self._name = name

    def _say(self, level, text):
        # To the run's text log (src/core/textlog.rs), stamped with this node and the run
        # time, with the frame that called info/warn/error (two above this one), as
        # rclpy/impl/rcutils_logger.py takes it: co_filename, co_name, f_lineno.
        try:
            frame = sys._getframe(2)
            caller = (frame.f_code.co_filename, frame.f_code.co_name, frame.f_lineno or 0)
        except ValueError:  # called from the bottom of a stack: where is not known
            caller = ("", "", 0)
        _log("warn" if level == "warning" else level, _one_line(text), self._name, caller)

    def info(self, text):
        self._say("info", text)

    def warn(self, text):
        self._say("warning", text)

    warning = warn

    def error(self, text):
        self._say("error", text)


class Parameter:
    """A node's parameter, as rclpy's: `.name`, `.value`."""

    __slots__ = ("name", "value")

    def __init__(self, name, value):
        self.name, self.value = name, value

    def __repr__(self):
        return f"Parameter({self.name!r}, {self.value!r})"


class ParameterAlreadyDeclaredException(ContractError):
    """`declare_parameter` of a name this node already declared (rclpy's exception of the
    same name)."""


class ParameterNotDeclaredException(ContractError):
    """`get_parameter` of a name neither declared nor given in the graph file's `params`
    (rclpy's exception of the same name)."""


class Publisher:
    """What `create_publisher` returns: `publish(msg)` sends `msg` on its topic at the end
    of the tick that published it, stamped with the tick's time."""

    def __init__(self, runtime, msg_type, topic, index):
        self._runtime, self.msg_type, self.topic_name = runtime, msg_type, topic
        self._index = index

    def publish(self, msg):
        if type(msg) is not self.msg_type:
            raise TypeError(f"publish on '{self.topic_name}' takes a {self.msg_type.__name__}, "
                            f"got {type(msg).__name__}")
        self._runtime.outbox.append((self._index, msg._fields()))


def _qos_depth(qos):
    return qos if isinstance(qos, int) else getattr(qos, "depth", qos)


class NodeHandle:
    """The handle a learner's class gets in its constructor, shaped like an rclpy Node:
    create_subscription, create_publisher, create_timer, get_clock, get_logger,
    declare_parameter(s), get_parameter, has_parameter, get_name, and `rng` (a NumPy
    Generator seeded from the run's seed and the node's name). Topics and types must be the
    ones the graph file gives the node.

    Parameters are rclpy's, the graph file's `params` playing the part of a launch file's
    overrides: `declare_parameter(name, value)` returns the Parameter, whose value is the
    graph file's when it gives the name (unless `ignore_override=True`), else `value`;
    declaring a name twice raises ParameterAlreadyDeclaredException. `get_parameter(name)`
    returns a declared parameter, or one the graph file gives (declared or not, as ratelab's
    nodes always read them); any other name raises ParameterNotDeclaredException."""

    def __init__(self, runtime):
        self._rt = runtime

    def get_name(self):
        return self._rt.name

    def get_period(self):
        """The node's period, s: 1 / its rate_hz as this run set it (flags, lab keys)."""
        return self._rt.period_ns / 1e9

    def _check(self, kind, msg_type, topic, declared):
        """The index of `topic` among the graph file's `kind` topics for this node, after
        checking that it is one of them and carries `msg_type`."""
        names = [name for name, _ in declared]
        if topic not in names:
            given = (f"{kind} = " + (f"\"{names[0]}\"" if len(names) == 1 else
                                      "[" + ", ".join(f"\"{n}\"" for n in names) + "]")
                     if names else f"no `{kind} = ...`")
            raise ContractError(self._rt.where(), f"node '{self._rt.name}' {kind} '{topic}', but "
                                f"the graph file gives it {given}")
        index = names.index(topic)
        type_name = declared[index][1]
        want = MESSAGE_TYPES[type_name]
        if msg_type is not want:
            got = getattr(msg_type, "__name__", repr(msg_type))
            raise ContractError(self._rt.where(), f"'{topic}' carries {want.__name__} "
                                f"(type = \"{type_name}\"), not {got}")
        return index

    def create_subscription(self, msg_type, topic, callback, qos_profile=1, **_kw):
        index = self._check("subscribes", msg_type, topic, self._rt.inputs)
        if any(i == index for i, _, _ in self._rt.subscriptions):
            raise ContractError(self._rt.where(), f"a second subscription to '{topic}' (one "
                                "per topic)")
        if not callable(callback):
            raise ContractError(self._rt.where(), "create_subscription's callback is not callable")
        self._rt.subscriptions.append((index, msg_type, callback))
        self._rt.qos_depths.append(_qos_depth(qos_profile))
        return topic

    def create_publisher(self, msg_type, topic, qos_profile=1, **_kw):
        index = self._check("publishes", msg_type, topic, self._rt.outputs)
        self._rt.declared_outputs.add(index)
        self._rt.qos_depths.append(_qos_depth(qos_profile))
        return Publisher(self._rt, msg_type, topic, index)

    def create_timer(self, timer_period_sec, callback, **_kw):
        period_ns = self._rt.period_ns
        try:
            if isinstance(timer_period_sec, (str, bytes, bytearray, bool)):
                raise TypeError
            seconds = float(timer_period_sec)
            if not math.isfinite(seconds):
                raise ValueError
        except (TypeError, ValueError, OverflowError):
            raise ContractError(self._rt.where(), f"create_timer's period must be a number "
                                f"of seconds, got {type(timer_period_sec).__name__} "
                                f"{timer_period_sec!r:.40}") from None
        ticks = seconds * 1e9 / period_ns
        every = round(ticks)
        if every < 1 or abs(ticks - every) > 1e-6 * max(1.0, ticks):
            raise ContractError(self._rt.where(), f"create_timer({timer_period_sec}): node "
                                f"'{self._rt.name}' ticks every {period_ns / 1e6:g} ms (its "
                                "rate_hz); a timer's period must be a whole number of ticks")
        if not callable(callback):
            raise ContractError(self._rt.where(), "create_timer's callback is not callable")
        self._rt.timers.append((every, callback))

    def get_clock(self):
        return self._rt.clock

    def get_logger(self):
        return self._rt.logger

    def declare_parameter(self, name, value=None, descriptor=None, ignore_override=False):
        """Declare parameter `name` with default `value` and return it (a Parameter): its
        value is the graph file's `params` entry when there is one (an override, as a launch
        file's in ROS 2) unless `ignore_override`, else `value`."""
        if not isinstance(name, str) or not name:
            raise ContractError(self._rt.where(), f"declare_parameter's name must be a "
                                f"non-empty str, got {name!r}")
        if name in self._rt.declared:
            raise ParameterAlreadyDeclaredException(
                self._rt.where(), f"node '{self._rt.name}' declares parameter '{name}' twice "
                "(ParameterAlreadyDeclaredException)")
        if name in self._rt.params and not ignore_override:
            value = self._rt.params[name]
        parameter = Parameter(name, value)
        self._rt.declared[name] = parameter
        return parameter

    def declare_parameters(self, namespace, parameters, ignore_override=False):
        """Declare several: `parameters` a list of `(name, value)` (or `(name,)`) tuples,
        each named `namespace.name` (just `name` when `namespace` is empty); returns the
        Parameters in order."""
        declared = []
        for entry in parameters:
            name, value = entry[0], (entry[1] if len(entry) > 1 else None)
            full = f"{namespace}.{name}" if namespace else name
            declared.append(self.declare_parameter(full, value, ignore_override=ignore_override))
        return declared

    def has_parameter(self, name):
        """Whether `get_parameter(name)` finds it: declared, or in the graph file's params."""
        return name in self._rt.declared or name in self._rt.params

    def get_parameter(self, name):
        declared = self._rt.declared.get(name)
        if declared is not None:
            return declared
        if name not in self._rt.params:
            known = ", ".join(sorted(self._rt.params)) or "none"
            mine = ", ".join(sorted(self._rt.declared)) or "none"
            raise ParameterNotDeclaredException(
                self._rt.where(), f"node '{self._rt.name}' has no parameter '{name}' "
                f"(ParameterNotDeclaredException; declared: {mine}; the graph file's params: "
                f"{known})")
        return Parameter(name, self._rt.params[name])

    @property
    def rng(self):
        if self._rt.rng is None:
            import zlib

            import numpy as np

            self._rt.rng = np.random.default_rng([self._rt.seed, zlib.crc32(self._rt.name.encode())])
        return self._rt.rng


class NodeRuntime:
    """One learner's node as ratelab drives it: `tick(now_ns, delivered)` runs the
    subscriptions' callbacks, in the order created, for what their inputs delivered
    (`delivered`: (input index, field tuple) pairs), then the timers due at this tick, and
    returns what was published: (output index, field tuple) pairs, in order."""

    def __init__(self, module, script, class_name, name, period_ns, inputs, outputs, params,
                 seed):
        self.script, self.name, self.period_ns = script, name, period_ns
        self.inputs, self.outputs, self.params, self.seed = inputs, outputs, dict(params), seed
        self.declared = {}  # name -> Parameter, as declare_parameter declared them
        self.now_ns, self.ticks, self.outbox = 0, 0, []
        self.subscriptions, self.timers, self.qos_depths, self.rng = [], [], [], None
        self.clock, self.logger = Clock(self), Logger(name)
        self.declared_outputs = set()
        cls = self._find_class(module, class_name)
        self.instance = cls(NodeHandle(self))
        # A topic the graph file gives the node that its constructor never declared: nothing
        # will come of it, which is easy to miss (a typo'd method, a forgotten line).
        for index, (topic, _) in enumerate(self.outputs):
            if index not in self.declared_outputs:
                _log("warn", f"[ratelab] warning: node '{name}' declares no publisher for "
                     f"'{topic}', which its graph file gives it: nothing is published there",
                     name)
        subscribed = {i for i, _, _ in self.subscriptions}
        for index, (topic, _) in enumerate(self.inputs):
            if index not in subscribed:
                _log("warn", f"[ratelab] warning: node '{name}' declares no subscription to "
                     f"'{topic}', which its graph file gives it: what arrives there is unread",
                     name)

    def where(self):
        """`script:line` of the innermost frame in the learner's script (the call that
        broke the contract), else the script."""
        frame = sys._getframe(1)
        theirs = None  # the innermost frame that is not ratelab's own
        while frame is not None:
            filename = frame.f_code.co_filename
            if filename == self.script:
                return f"{self.script}:{frame.f_lineno}"
            if theirs is None and not _ratelab_s(filename):
                theirs = frame
            frame = frame.f_back
        # A class given from a prompt or `python -c` has no file: its own line still is.
        if theirs is not None and self.script.startswith("<"):
            return _where(theirs.f_code.co_filename, theirs.f_lineno)
        return self.script

    def _find_class(self, module, class_name):
        if isinstance(class_name, type):
            return class_name  # a class the caller gave (`ratelab.run(nodes=...)`)
        if class_name is not None:
            cls = getattr(module, class_name, None)
            if not isinstance(cls, type):
                raise ContractError(self.script, f"no class '{class_name}'")
            return cls
        mine = [v for v in vars(module).values()
                if isinstance(v, type) and v.__module__ == module.__name__]
        if len(mine) != 1:
            names = ", ".join(c.__name__ for c in mine) or "none"
            raise ContractError(self.script, f"name the node's class with `class = \"...\"` "
                                f"(the script defines {len(mine)} classes: {names})")
        return mine[0]

    def tick(self, now_ns, delivered):
        self.now_ns, self.outbox = now_ns, []
        if delivered:
            fields = dict(delivered)
            for index, msg_type, callback in self.subscriptions:
                if index in fields:
                    callback(msg_type(*fields[index]))
        for every, callback in self.timers:
            if self.ticks % every == 0:
                callback()
        self.ticks += 1
        return self.outbox


def class_script(cls):
    """The file a class given by the caller was defined in (for messages), or `<NAME>`."""
    module = sys.modules.get(getattr(cls, "__module__", ""), None)
    return getattr(module, "__file__", None) or f"<{getattr(cls, '__qualname__', 'class')}>"


def node_runtime(module, script, class_name, name, period_ns, inputs, outputs, params, seed):
    return NodeRuntime(module, script, class_name, name, period_ns, inputs, outputs, params,
                       seed)


def install_message_module(registry):
    """`import ratelab` in a learner's script gives the message classes and Time.

    `registry` is ratelab's message registry (src/core/msg/mod.rs), the one definition of every
    message type: [(name, class, doc, [(field, unit, doc, kind), ...], ros_type or None),
    ...], each field's kind `number`, `integer`, `text` or `bytes`. The built-in types'
    classes are written above (with their ROS 2 conversions) and must match it; a type a Rust
    program registered gets a class made from its fields."""
    for name, class_name, doc, fields, ros_type in registry:
        names = tuple(f for f, _, _, _ in fields)
        kinds = tuple(k for _, _, _, k in fields)
        cls = MESSAGE_TYPES.get(name)
        if cls is None:
            described = "; ".join(
                f"{f} ({u if k in ('number', 'integer') else k}): {d}" for f, u, d, k in fields)
            cls = type(class_name, (_Msg,), {
                "__slots__": names, "FIELDS": names, "ROS_TYPE": ros_type,
                "KINDS": () if set(kinds) <= {"number"} else kinds,
                "__doc__": f"{doc} Fields: {described}.", "__module__": "ratelab"})
            MESSAGE_TYPES[name] = cls
        elif (cls.__name__, cls.FIELDS, cls.ROS_TYPE) != (class_name, names, ros_type):
            raise RuntimeError(f"ratelab's Python class {cls.__name__} does not match message "
                               f"type '{name}' as Rust defines it ({class_name}: "
                               f"{', '.join(names)}; ROS 2 {ros_type})")
    package = sys.modules.get("ratelab")
    if package is not None and hasattr(package, "_native"):
        # ratelab runs inside the caller's interpreter (`import ratelab`, the Python
        # package): the classes join the package itself, which scripts then import.
        mod = package
    else:
        mod = types.ModuleType("ratelab")
        mod.__doc__ = ("ratelab's message types for Python nodes ("
                       + ", ".join(c.__name__ for c in MESSAGE_TYPES.values()) + ") and Time.")
        sys.modules["ratelab"] = mod
    for cls in list(MESSAGE_TYPES.values()) + [Time]:
        setattr(mod, cls.__name__, cls)
