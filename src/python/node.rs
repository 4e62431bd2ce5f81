//! A node written in Python, shaped like an rclpy node: a graph file's
//! `kind = "python"`, `script = "nodes/NAME.py"`, optional `class` and `params`.
//!
//! The class's constructor gets a node handle and declares, as in rclpy,
//! `create_subscription(MsgType, "/topic", callback, qos_depth)`,
//! `create_publisher(MsgType, "/topic", qos_depth)` and `create_timer(period_s, callback)`;
//! the handle also has `get_clock().now()` (the run's clock, virtual or real: `.nanoseconds`),
//! `get_logger().info/warn/error`, `get_parameter(name).value` (the graph file's `params`),
//! `get_name()`, `get_period()` (the node's tick, s: 1 / its `rate_hz` in this run) and `rng` (a NumPy `Generator` seeded from the run's seed and the node's
//! name). Message classes, from `import ratelab` (number fields are floats in SI units; a
//! text field is a `str`; a bytes field, as it arrives, a read-only `memoryview` of the
//! message's own bytes, not a copy ([`SharedBytes`]: a camera's frame that crossed processes
//! in shared memory is read where it arrived; `numpy.frombuffer` reads it in place), and
//! whatever a node sets it to when it builds a message: `bytes`, or any object that lends
//! its bytes):
//!
//! | graph file type | class | fields |
//! | --- | --- | --- |
//! | `state` | `ratelab.State` | `cart_pos_m`, `cart_vel_m_s`, `cos_theta`, `sin_theta`, `pole_angvel_rad_s` (float32 on the topic) |
//! | `position` | `ratelab.Position` | `cart_pos_m`, `pole_angle_rad` |
//! | `force` | `ratelab.Force` | `newtons` |
//! | `image` | `ratelab.Image` | `height`, `width`, `encoding` (str), `step`, `data` (bytes) |
//!
//! A node may subscribe to several topics and publish several (`subscribes = ["/obs",
//! "/reference"]` in the graph file): one `create_subscription` per input and one
//! `create_publisher` per output, each naming a topic the graph file gives it.
//!
//! **The executor's order within a tick** (the node ticks at its `rate_hz`, like every
//! node): first the subscriptions' callbacks, in the order the node created them, each
//! once for what its topic's QoS delivers at that instant (latest: the newest unread
//! message; FIFO: the oldest unread) — not called when nothing new arrived on it; then
//! every timer due at the tick, in the order created (a timer fires on the node's first
//! tick and then every `period_s`, which must be a whole number of the node's periods).
//! What the callbacks published goes out at the end of the tick, stamped with the tick's
//! time, in the order published.
//!
//! **Origin stamps** (sense→act latency): what a Python node publishes carries the
//! **oldest** origin among the newest messages its subscriptions delivered — the oldest
//! reading the output may depend on, since a node keeps its inputs' last values (a zero-order
//! hold) — or its own tick time when it subscribes to nothing (it is a source). With one
//! input that is the origin of the reading it was derived from. So an input that is slow or
//! stale (a setpoint published once a second) stretches the sense→act latency the actuator
//! measures: the command really does rest on data that old.
//!
//! Errors at load are one line ([`PythonError`]): the script missing or unreadable, a
//! syntax error, no such class, a topic or type the graph file does not give the node, a
//! timer period that is not a whole number of ticks. During the run an exception, a
//! publish of the wrong message type or a parameter that does not exist fails the node
//! at that tick, naming `FILE:LINE` of the raising frame and the exception.

use super::{describe, describe_failure, start, support, CallbackGuard, PythonError};
use pyo3::prelude::*;
use pyo3::types::{PyBytes, PyDict, PyList, PyTuple};
use ratelab_core::msg::{AnyTopic, FieldKind, Value};
use ratelab_core::publisher::Outbox;
use ratelab_core::time::Nanos;
use ratelab_runtime::graph::kind::{BuildContext, PythonCode};

/// A message's values as they cross into Python: numbers (`float`), text (`str`) and bytes
/// (`bytes`, which NumPy reads with `np.frombuffer`).
type Fields = Vec<Value>;

/// One Python node, ready to tick (see the module docs).
pub struct PythonNode {
    runtime: Py<PyAny>,
    script: String,
    /// The node's name (the lab shows a tick that does not return on its box; what its code
    /// writes is stamped with it).
    name: std::sync::Arc<str>,
    what: String,
    inputs: Vec<Input>,
    outputs: Vec<AnyTopic>,
    /// Where its publishes go (held during a tick with a compute time).
    outbox: Outbox,
}

/// One subscription: its topic and what it delivered last.
struct Input {
    topic: AnyTopic,
    /// `seq` of the newest message delivered to the subscription callback.
    last_seq: Option<u64>,
    /// Origin stamp of the newest message delivered.
    origin: Option<Nanos>,
}

/// Why a tick of a Python node failed: the one-line description the node fails with.
#[derive(Debug)]
pub struct TickError(pub String);

impl PythonNode {
    /// Load the node `cx` makes (its name, period, seed, parameters, topics in the graph
    /// file's order, outbox) from `code`, or from the class the caller gave for it
    /// ([`give_classes`]).
    ///
    /// # Errors
    /// [`PythonError`]: see the module docs.
    pub fn load(cx: &BuildContext<'_>, code: &PythonCode) -> Result<PythonNode, PythonError> {
        let node = &cx.node;
        let (name, params, period, seed) = (node.name, node.params, node.period, node.seed);
        let (inputs, outputs, outbox) = (
            node.inputs.to_vec(),
            node.outputs.to_vec(),
            cx.outbox.clone(),
        );
        let given = given_class(name);
        let script = code.script.as_str();
        // A class the caller gave needs no script: its own file names it in messages.
        let source = match &given {
            Some(_) => String::new(),
            None => super::brain::read_script(script)?,
        };
        start()?;
        let module_name = format!("ratelab_node_{name}");
        let declared = |ts: &[AnyTopic]| -> Vec<(String, &'static str)> {
            ts.iter()
                .map(|t| (t.name().to_string(), t.msg_type().as_str()))
                .collect()
        };
        Python::attach(|py| {
            let support = support(py)?;
            let script: String = match &given {
                Some(cls) => support
                    .call_method1("class_script", (cls,))
                    .and_then(|s| s.extract())
                    .unwrap_or_else(|_| script.to_string()),
                None => script.to_string(),
            };
            let script = script.as_str();
            let fail = |e: PyErr| PythonError::Script(describe(py, &e, script));
            let _running = CallbackGuard::enter_loading(
                &format!("node '{name}' ({script}) loading"),
                Some(name),
            );
            super::install_messages(py).map_err(fail)?;
            let (module, class) = match &given {
                Some(cls) => (py.None().into_bound(py), cls.bind(py).clone()),
                None => (
                    support
                        .call_method1("load_module", (script, source, module_name))
                        .map_err(fail)?,
                    match code.class.as_deref() {
                        Some(c) => pyo3::types::PyString::new(py, c).into_any(),
                        None => py.None().into_bound(py),
                    },
                ),
            };
            let py_params = PyDict::new(py);
            for (k, v) in params {
                py_params.set_item(k, to_python(py, v)).map_err(fail)?;
            }
            let runtime = support
                .call_method1(
                    "node_runtime",
                    (
                        module,
                        script,
                        class,
                        name,
                        period.0,
                        declared(&inputs),
                        declared(&outputs),
                        py_params,
                        seed,
                    ),
                )
                .map_err(fail)?;
            Ok(PythonNode {
                runtime: runtime.unbind(),
                script: script.to_string(),
                name: name.into(),
                what: format!("node '{name}' ({script})"),
                inputs: inputs
                    .into_iter()
                    .map(|topic| Input {
                        topic,
                        last_seq: None,
                        origin: None,
                    })
                    .collect(),
                outputs,
                outbox,
            })
        })
    }

    /// One tick at run time `now` of a node whose period is now `period` (see the module
    /// docs for the order of callbacks; a tick running [`super::OVERRUN_PERIODS`] periods
    /// is reported).
    ///
    /// # Errors
    /// [`TickError`] with the one-line description when a callback raised or published
    /// something that is not a message of its topic's type.
    pub fn tick(&mut self, now: Nanos, period: Nanos) -> Result<(), TickError> {
        // What the node's code writes meanwhile is stamped with this tick.
        let _stamp = ratelab_core::textlog::enter(&self.name, now);
        // What each input delivers now (by its QoS), if new: (input index, fields).
        let delivered: Vec<(usize, Fields)> = self
            .inputs
            .iter_mut()
            .enumerate()
            .filter_map(|(i, input)| {
                let (seq, origin, fields) = read(&input.topic, now)?;
                (input.last_seq != Some(seq)).then(|| {
                    input.last_seq = Some(seq);
                    input.origin = Some(origin);
                    (i, fields)
                })
            })
            .collect();
        let outputs = &self.outputs;
        let published: Vec<(usize, ratelab_core::msg::MsgData)> = Python::attach(|py| {
            let _running = CallbackGuard::enter_tick(&self.what, &self.name, period);
            let delivered: Vec<(usize, Bound<'_, PyTuple>)> = delivered
                .iter()
                .map(|(i, values)| {
                    let kinds = self.inputs[*i].topic.msg_type().fields();
                    Ok((*i, to_python_values(py, kinds, values)?))
                })
                .collect::<PyResult<_>>()
                .map_err(|e| TickError(describe_failure(py, &e, &self.script)))?;
            self.runtime
                .call_method1(py, "tick", (now.0, delivered))
                .and_then(|out| {
                    let out = out.bind(py).cast::<PyList>().map_err(PyErr::from)?;
                    out.iter()
                        .map(|m| {
                            let (index, values) = m.extract::<(usize, Bound<'_, PyTuple>)>()?;
                            // The Python side checked the index against the graph file's
                            // outputs.
                            let topic = outputs.get(index).ok_or_else(|| {
                                pyo3::exceptions::PyIndexError::new_err("no such output")
                            })?;
                            Ok((index, from_python_values(topic, &values)?))
                        })
                        .collect()
                })
                .map_err(|e| TickError(describe_failure(py, &e, &self.script)))
        })?;
        let origin = self.origin(now);
        for (output, data) in published {
            // Of the topic's own type: it cannot be refused.
            let _ = self.outputs[output].publish(Some(&self.outbox), &data, now, origin);
        }
        Ok(())
    }

    /// The origin stamp what it publishes at `now` carries: the oldest origin among the
    /// newest messages its subscriptions delivered (its inputs' last values, which its
    /// callbacks used), or `now` when it subscribes to nothing (it is a source). `None`
    /// before any subscription delivered.
    fn origin(&self, now: Nanos) -> Option<Nanos> {
        if self.inputs.is_empty() {
            return Some(now);
        }
        self.inputs.iter().filter_map(|i| i.origin).min()
    }
}

/// Read `t` at `now` by its QoS: the message's seq, origin (its own stamp when it has
/// none) and values.
fn read(t: &AnyTopic, now: Nanos) -> Option<(u64, Nanos, Fields)> {
    let m = t.read(now)?;
    Some((m.seq, m.origin, m.data.values()))
}

/// A message's bytes lent to Python without a copy: they are exposed read-only through the
/// buffer protocol (a `memoryview` of this object, which `numpy.frombuffer` reads in place)
/// and kept alive while Python holds a view: a frame that arrived in another process's
/// shared memory stays mapped as long (issue 76).
#[pyclass(frozen, module = "ratelab")]
pub struct SharedBytes(ratelab_core::msg::ImageData);

#[pymethods]
impl SharedBytes {
    /// The buffer protocol: the bytes, read-only (a writable view is refused with
    /// `BufferError`), one byte an item (`B`).
    unsafe fn __getbuffer__(
        slf: Bound<'_, Self>,
        view: *mut pyo3::ffi::Py_buffer,
        flags: std::ffi::c_int,
    ) -> PyResult<()> {
        let bytes = slf.get().0.as_slice();
        let len = pyo3::ffi::Py_ssize_t::try_from(bytes.len())
            .map_err(|_| pyo3::exceptions::PyBufferError::new_err("too many bytes"))?;
        // SAFETY: `view` is the buffer CPython asks to fill; `PyBuffer_FillInfo` refuses a
        // writable request, takes a new reference to `slf` (which owns the bytes, never
        // moved or changed while it lives) into `view.obj`, and sets the format to `B` when
        // asked; nothing is allocated that `__releasebuffer__` would free.
        let rc = unsafe {
            pyo3::ffi::PyBuffer_FillInfo(
                view,
                slf.as_ptr(),
                bytes.as_ptr().cast_mut().cast(),
                len,
                1,
                flags,
            )
        };
        if rc == -1 {
            // SAFETY: `view` is CPython's to fill; on failure it must not name an exporter.
            unsafe { (*view).obj = std::ptr::null_mut() };
            return Err(PyErr::fetch(slf.py()));
        }
        Ok(())
    }
}

/// `bytes` as Python reads a message's bytes field: a read-only `memoryview` of them, not a
/// copy ([`SharedBytes`]).
pub fn lend_bytes<'py>(
    py: Python<'py>,
    bytes: &ratelab_core::msg::ImageData,
) -> PyResult<Bound<'py, PyAny>> {
    let owner = Bound::new(py, SharedBytes(bytes.clone()))?;
    Ok(pyo3::types::PyMemoryView::from(&owner)?.into_any())
}

/// A bytes field's value from Python, for a message published on `topic`: `bytes`, or any
/// object that lends its bytes through the buffer protocol (a `bytearray`, a `memoryview`, a
/// NumPy array of bytes), copied once, into a buffer `topic` lends
/// ([`AnyTopic::loan_pixels`]: in a launch whose frames cross to another process, a buffer
/// of the process's shared-memory pool, so the frame is not copied again on its way).
fn bytes_from_python(
    v: &Bound<'_, PyAny>,
    topic: &AnyTopic,
) -> PyResult<ratelab_core::msg::ImageData> {
    if let Ok(b) = v.cast::<PyBytes>() {
        let b = b.as_bytes();
        let mut px = topic.loan_pixels(b.len());
        px.copy_from_slice(b);
        return Ok(px.into());
    }
    let buffer = pyo3::buffer::PyBuffer::<u8>::get(v)?;
    let mut px = topic.loan_pixels(buffer.len_bytes());
    buffer.copy_to_slice(v.py(), &mut px)?;
    Ok(px.into())
}

/// A message's values (of fields `fields`) as a Python tuple: a whole-number field an
/// `int`, a bytes field a read-only view of the message's bytes ([`lend_bytes`]).
fn to_python_values<'py>(
    py: Python<'py>,
    fields: &[ratelab_core::msg::Field],
    values: &[Value],
) -> PyResult<Bound<'py, PyTuple>> {
    use pyo3::IntoPyObjectExt;
    let items: Vec<Bound<'py, PyAny>> = fields
        .iter()
        .zip(values)
        .map(|(f, v)| match v {
            Value::Number(x) if f.kind == FieldKind::Integer => (*x as i64).into_bound_py_any(py),
            Value::Number(x) => x.into_bound_py_any(py),
            Value::Text(t) => t.into_bound_py_any(py),
            Value::Bytes(b) => lend_bytes(py, b),
        })
        .collect::<PyResult<_>>()?;
    PyTuple::new(py, items)
}

/// A message of `topic`'s type from the values tuple a Python node published (the Python
/// side made each of its field's kind: a float, a str, bytes).
fn from_python_values(
    topic: &AnyTopic,
    values: &Bound<'_, PyTuple>,
) -> PyResult<ratelab_core::msg::MsgData> {
    let ty = topic.msg_type();
    let values: Vec<Value> = ty
        .fields()
        .iter()
        .zip(values.iter())
        .map(|(f, v)| {
            Ok(match f.kind {
                FieldKind::Number | FieldKind::Integer => Value::Number(v.extract()?),
                FieldKind::Text => Value::Text(v.extract()?),
                FieldKind::Bytes => Value::Bytes(bytes_from_python(&v, topic)?),
            })
        })
        .collect::<PyResult<_>>()?;
    ty.from_values(&values)
        .map_err(pyo3::exceptions::PyTypeError::new_err)
}

/// A graph file's parameter as a Python value.
fn to_python<'py>(py: Python<'py>, v: &toml::Value) -> Bound<'py, PyAny> {
    use pyo3::IntoPyObjectExt;
    let any = match v {
        toml::Value::Integer(i) => i.into_bound_py_any(py),
        toml::Value::Float(f) => f.into_bound_py_any(py),
        toml::Value::Boolean(b) => b.into_bound_py_any(py),
        toml::Value::String(s) => s.into_bound_py_any(py),
        toml::Value::Array(a) => a
            .iter()
            .map(|x| to_python(py, x))
            .collect::<Vec<_>>()
            .into_bound_py_any(py),
        // Refused by the graph file's rules (src/runtime/graph/spec.rs).
        other => other.to_string().into_bound_py_any(py),
    };
    any.unwrap_or_else(|_| py.None().into_bound(py))
}

/// Classes the caller gave for Python nodes, by node name ([`give_classes`]).
static GIVEN: std::sync::Mutex<Vec<(String, Py<PyAny>)>> = std::sync::Mutex::new(Vec::new());

/// While the returned guard lives, a Python node named as a key of `classes` is made from
/// the class given (an object of the caller's interpreter: a notebook cell's class) instead
/// of its graph file's `script` and `class`; it is driven exactly as one from a file
/// (`ratelab.run(nodes={"policy": MyNode})`). Dropping the guard forgets them.
pub fn give_classes(classes: Vec<(String, Py<PyAny>)>) -> GivenClasses {
    *GIVEN.lock().unwrap_or_else(|e| e.into_inner()) = classes;
    GivenClasses(())
}

/// Forgets the classes [`give_classes`] gave when dropped.
pub struct GivenClasses(());

impl Drop for GivenClasses {
    fn drop(&mut self) {
        let taken = std::mem::take(&mut *GIVEN.lock().unwrap_or_else(|e| e.into_inner()));
        Python::attach(|_| drop(taken));
    }
}

fn given_class(node: &str) -> Option<Py<PyAny>> {
    let given = GIVEN.lock().unwrap_or_else(|e| e.into_inner());
    let found = given.iter().find(|(n, _)| n == node)?;
    Some(Python::attach(|py| found.1.clone_ref(py)))
}
