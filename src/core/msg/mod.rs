//! Message types: what topics carry, each **one definition** in one registry.
//!
//! A message type is a Rust type implementing [`Message`]: its name as a graph file spells
//! it (`type = "force"`), its Python class name and fields with units (what a Python node
//! sees, and how a value is shown: [`MsgData::describe`]), and, optionally, the ROS 2 type
//! it is offered as ([`ros_mapping`]). From that one definition ratelab makes its topics
//! ([`AnyTopic`]), sends it across processes (postcard, by serde: [`MsgData::to_bytes`]),
//! hands it to Python nodes ([`Message::to_fields`]) and offers it to ROS 2. The built-in
//! types are one file each — [`state`], [`position`], [`force`] — and are registered here;
//! a type of your own is one file plus one line:
//!
//! ```no_run
//! use ratelab::msg::{register, Field, Message};
//! use serde::{Deserialize, Serialize};
//!
//! /// A cart position setpoint.
//! #[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
//! struct Setpoint { cart_pos_m: f64 }
//!
//! impl Message for Setpoint {
//!     const NAME: &'static str = "setpoint";
//!     const CLASS: &'static str = "Setpoint";
//!     const DOC: &'static str = "A cart position setpoint.";
//!     const FIELDS: &'static [Field] = &[Field::new("cart_pos_m", "m", "cart position")];
//!     fn to_fields(&self) -> Vec<f64> { vec![self.cart_pos_m] }
//!     fn from_fields(f: &[f64]) -> Self { Setpoint { cart_pos_m: f[0] } }
//! }
//!
//! register::<Setpoint>().unwrap(); // before the graph file is read
//! ```
//!
//! A graph file's topics may then carry `type = "setpoint"`; a Rust node kind reads and
//! publishes it typed (`ratelab::graph::registry`), a Python node as `ratelab.Setpoint`.
//! A node kind registered with a type registers the type too.
//!
//! [`AnyTopic`] is a topic of any registered type, for the views that only count messages
//! (metrics, the lab, recordings), for changes that do not look inside (depth, QoS), and
//! for the code that moves payloads without knowing their type (the wire, the ROS 2 bridge,
//! Python nodes); a node that knows the type gets the typed [`Subscription`] back with
//! [`AnyTopic::typed`].

pub mod force;
pub mod image;
mod pieces;
pub use pieces::PiecesError;
pub mod position;
pub mod ros_mapping;
pub mod state;

pub use force::ForceMsg;
pub use image::{ImageData, ImageMsg};
pub use position::PositionMsg;
pub use ros_mapping::{RosCodec, RosMapped};
pub use state::StateMsg;

use crate::publisher::Outbox;
use crate::qos::TopicQos;
use crate::time::Nanos;
use crate::topic::{ChangeSlot, Subscription, TopicStats, ZeroDepth};
use serde::de::DeserializeOwned;
use serde::{Deserialize, Serialize};
use std::any::{Any, TypeId};
use std::fmt;
use std::sync::{Arc, LazyLock, RwLock};

pub use crate::limits::MAX_MSG_TYPES;
/// The most fields a message type may have ([`crate::limits::MAX_MSG_FIELDS`]).
pub const MAX_FIELDS: usize = crate::limits::MAX_MSG_FIELDS;
/// The most bytes a message may take on the wire (postcard): a sample between processes
/// ([`crate::limits::MAX_SAMPLE_BYTES`], 64 MiB: a camera's frame, a point cloud) less room
/// for the sample's own header; a larger payload is refused where it arrives.
pub const MAX_PAYLOAD_BYTES: usize = crate::limits::MAX_SAMPLE_BYTES - 4096;

/// One field of a message type: a name (a Python identifier, in SI units by convention:
/// `cart_pos_m`), its unit as shown (`m`, `rad/s`, `N`, `1` for a pure number), a few
/// words on what it is, and what it holds (a number, text or bytes).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Field {
    /// The name, as Python sees it.
    pub name: &'static str,
    /// The unit, as shown next to a value (of bytes: what each is, `px`).
    pub unit: &'static str,
    /// What it is.
    pub doc: &'static str,
    /// What it holds.
    pub kind: FieldKind,
}

/// What a field holds.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum FieldKind {
    /// A number (`f64`), in the field's unit.
    Number,
    /// A whole number (a count of pixels or bytes): an `f64` in Rust's values (exact below
    /// 2⁵³), an `int` in Python.
    Integer,
    /// Text (`sensor_msgs/Image`'s `encoding`).
    Text,
    /// Bytes of any length (an image's pixels), shared between subscribers, never copied
    /// per subscriber in one process.
    Bytes,
}

impl Field {
    /// A number field.
    pub const fn new(name: &'static str, unit: &'static str, doc: &'static str) -> Field {
        Field {
            name,
            unit,
            doc,
            kind: FieldKind::Number,
        }
    }
    /// A whole-number field (Python sees an `int`).
    pub const fn integer(name: &'static str, unit: &'static str, doc: &'static str) -> Field {
        Field {
            name,
            unit,
            doc,
            kind: FieldKind::Integer,
        }
    }
    /// A text field.
    pub const fn text(name: &'static str, doc: &'static str) -> Field {
        Field {
            name,
            unit: "",
            doc,
            kind: FieldKind::Text,
        }
    }
    /// A bytes field; `unit`: what each byte is.
    pub const fn bytes(name: &'static str, unit: &'static str, doc: &'static str) -> Field {
        Field {
            name,
            unit,
            doc,
            kind: FieldKind::Bytes,
        }
    }
}

/// A field's value ([`Message::to_values`]).
#[derive(Clone, Debug, PartialEq)]
pub enum Value {
    /// A number or whole-number field's.
    Number(f64),
    /// A text field's.
    Text(String),
    /// A bytes field's (shared, not copied).
    Bytes(ImageData),
}

/// A message type: the one definition of what a topic carries (module docs).
///
/// Any type meeting the bounds may be one (copper-rs's rule): a plain value that is cheap
/// to clone, sent between threads and, by serde, between processes.
pub trait Message:
    Clone + fmt::Debug + PartialEq + Send + Sync + Serialize + DeserializeOwned + 'static
{
    /// The name a graph file gives as a topic's `type`: 1 to 32 lowercase letters, digits
    /// or '_', starting with a letter.
    const NAME: &'static str;
    /// The Python class (`ratelab.<CLASS>`): an identifier starting with a capital letter.
    const CLASS: &'static str;
    /// One line on what it carries.
    const DOC: &'static str;
    /// Its fields, in order: what [`Message::to_fields`] gives and
    /// [`Message::from_fields`] takes.
    const FIELDS: &'static [Field];
    /// The number fields, in [`Message::FIELDS`] order (of a type with text or bytes
    /// fields, the numbers alone: [`Message::to_values`] gives them all).
    fn to_fields(&self) -> Vec<f64>;
    /// A message from its number fields, in [`Message::FIELDS`] order (always as many; a
    /// Python node leaves an unset field 0); a text or bytes field is left empty.
    fn from_fields(fields: &[f64]) -> Self;
    /// Every field's value, in [`Message::FIELDS`] order. A type with text or bytes fields
    /// must give them here; the default is [`Message::to_fields`] as numbers.
    fn to_values(&self) -> Vec<Value> {
        self.to_fields().into_iter().map(Value::Number).collect()
    }
    /// A message from every field's value, in [`Message::FIELDS`] order (as many; each of
    /// its field's kind, as [`MsgType::from_values`] checks). A type with text or bytes
    /// fields must take them here; the default takes the numbers to
    /// [`Message::from_fields`].
    fn from_values(values: &[Value]) -> Self {
        let mut numbers: Vec<f64> = values
            .iter()
            .filter_map(|v| match v {
                Value::Number(x) => Some(*x),
                _ => None,
            })
            .collect();
        // As many as the type has number fields, whatever was given.
        let count = Self::FIELDS
            .iter()
            .filter(|f| matches!(f.kind, FieldKind::Number | FieldKind::Integer))
            .count();
        numbers.resize(count, 0.0);
        Self::from_fields(&numbers)
    }
    /// The ROS 2 type it is offered as over `--ros2`, if any ([`RosCodec::of`] for a type
    /// that implements [`RosMapped`]). A type without one is not offered to ROS 2, and an
    /// external node cannot read or publish it.
    fn ros2() -> Option<RosCodec> {
        None
    }
    /// The type's handle (do not override).
    const TYPE: MsgType = MsgType(&MsgTypeInfo::of::<Self>());
}

/// What ratelab knows of a message type, made from its [`Message`] impl.
pub struct MsgTypeInfo {
    name: &'static str,
    class: &'static str,
    doc: &'static str,
    fields: &'static [Field],
    type_id: fn() -> TypeId,
    new_topic: fn(&str, usize, TopicQos, u64, usize) -> Result<AnyTopic, ZeroDepth>,
    from_bytes: fn(&[u8]) -> Result<MsgData, String>,
    from_pieces: fn(&[&[u8]]) -> Result<MsgData, PiecesError>,
    from_fields: fn(&[f64]) -> MsgData,
    from_values: fn(&[Value]) -> MsgData,
    ros2: fn() -> Option<RosCodec>,
}

impl MsgTypeInfo {
    const fn of<M: Message>() -> MsgTypeInfo {
        MsgTypeInfo {
            name: M::NAME,
            class: M::CLASS,
            doc: M::DOC,
            fields: M::FIELDS,
            type_id: TypeId::of::<M>,
            new_topic: new_topic::<M>,
            from_bytes: from_bytes::<M>,
            from_pieces: pieces::from_pieces::<M>,
            from_fields: from_fields::<M>,
            from_values: from_values::<M>,
            ros2: M::ros2,
        }
    }
}

fn new_topic<M: Message>(
    name: &str,
    depth: usize,
    qos: TopicQos,
    link_seed: u64,
    subscriptions: usize,
) -> Result<AnyTopic, ZeroDepth> {
    let queue = |k: usize| -> Result<Arc<Subscription<M>>, ZeroDepth> {
        // Each subscription's link draws its own fates; the first draws the topic's.
        let seed = link_seed ^ ((k as u64) << 48);
        Ok(Arc::new(Subscription::<M>::with_qos(
            name, depth, qos, seed,
        )?))
    };
    Ok(if subscriptions <= 1 {
        AnyTopic(Arc::new(queue(0)?))
    } else {
        let queues = (0..subscriptions)
            .map(queue)
            .collect::<Result<Vec<_>, _>>()?;
        AnyTopic(Arc::new(FanOut { queues }))
    })
}

fn from_fields<M: Message>(f: &[f64]) -> MsgData {
    MsgData::new(M::from_fields(f))
}

fn from_values<M: Message>(v: &[Value]) -> MsgData {
    MsgData::new(M::from_values(v))
}

fn from_bytes<M: Message>(bytes: &[u8]) -> Result<MsgData, String> {
    if bytes.len() > MAX_PAYLOAD_BYTES {
        return Err(format!(
            "a {} payload of {} bytes (at most {MAX_PAYLOAD_BYTES})",
            M::NAME,
            bytes.len()
        ));
    }
    match postcard::take_from_bytes::<M>(bytes) {
        Ok((m, [])) => Ok(MsgData::new(m)),
        Ok((_, rest)) => Err(format!("{} bytes after a {} payload", rest.len(), M::NAME)),
        Err(e) => Err(format!("not a {} payload: {e}", M::NAME)),
    }
}

/// A registered message type: a cheap handle (compare, hash, print by name).
#[derive(Clone, Copy)]
pub struct MsgType(&'static MsgTypeInfo);

impl MsgType {
    /// The name a graph file spells (`state`).
    pub fn as_str(self) -> &'static str {
        self.0.name
    }
    /// Its Python class name (`State`).
    pub fn class(self) -> &'static str {
        self.0.class
    }
    /// One line on what it carries.
    pub fn doc(self) -> &'static str {
        self.0.doc
    }
    /// Its fields, in order.
    pub fn fields(self) -> &'static [Field] {
        self.0.fields
    }
    /// Are all its fields numbers (what a Python node's tuples and a ROS 2 bridge without a
    /// mapping of their own can carry)?
    pub fn is_numeric(self) -> bool {
        self.0
            .fields
            .iter()
            .all(|f| matches!(f.kind, FieldKind::Number | FieldKind::Integer))
    }
    /// Its ROS 2 mapping, if it has one.
    pub fn ros2(self) -> Option<RosCodec> {
        (self.0.ros2)()
    }
    /// Is it `M`?
    pub fn is<M: Message>(self) -> bool {
        (self.0.type_id)() == TypeId::of::<M>()
    }
    /// A payload of this type from its wire bytes (postcard), decoded exactly.
    ///
    /// # Errors
    /// One line: too long, not this type, or bytes after its end.
    pub fn decode(self, bytes: &[u8]) -> Result<MsgData, String> {
        (self.0.from_bytes)(bytes)
    }
    /// A payload of this type from its wire bytes in pieces, read in order (a sample that
    /// crossed as a head and a shared-memory frame): as [`MsgType::decode`] of the pieces
    /// joined, with a field of bytes borrowed from the piece it lies in (a view of it inside
    /// [`crate::pixels::decode_within`]).
    ///
    /// # Errors
    /// [`PiecesError::Refused`] as [`MsgType::decode`] refuses (one line);
    /// [`PiecesError::Straddles`] when a run postcard reads whole (a field of bytes, a
    /// string, a float) lies across two pieces: the caller may decode the pieces joined.
    pub fn decode_pieces(self, pieces: &[&[u8]]) -> Result<MsgData, PiecesError> {
        (self.0.from_pieces)(pieces)
    }
    /// A payload of this type from its fields, in order (missing ones 0, extra ignored).
    pub fn from_fields(self, fields: &[f64]) -> MsgData {
        let mut f = fields.to_vec();
        f.resize(self.0.fields.len(), 0.0);
        (self.0.from_fields)(&f)
    }
    /// A payload of this type from every field's value, in order.
    ///
    /// # Errors
    /// One line naming the field: too few or too many values, or a value of another kind
    /// than its field's (a number for `encoding`).
    pub fn from_values(self, values: &[Value]) -> Result<MsgData, String> {
        let fields = self.0.fields;
        if values.len() != fields.len() {
            return Err(format!(
                "{} has {} fields, not {}",
                self.0.class,
                fields.len(),
                values.len()
            ));
        }
        for (f, v) in fields.iter().zip(values) {
            let fits = matches!(
                (f.kind, v),
                (FieldKind::Number, Value::Number(_))
                    | (FieldKind::Integer, Value::Number(_))
                    | (FieldKind::Text, Value::Text(_))
                    | (FieldKind::Bytes, Value::Bytes(_))
            );
            if !fits {
                return Err(format!(
                    "{}.{} holds {:?}, not {v:?}",
                    self.0.class, f.name, f.kind
                ));
            }
        }
        Ok((self.0.from_values)(values))
    }
    /// The registered type named `name`.
    pub fn named(name: &str) -> Option<MsgType> {
        registry()
            .read()
            .unwrap_or_else(|e| e.into_inner())
            .iter()
            .copied()
            .find(|t| t.as_str() == name)
    }
}

impl PartialEq for MsgType {
    fn eq(&self, other: &MsgType) -> bool {
        // Names are unique in the registry; one type's handle may live at two addresses.
        self.0.name == other.0.name
    }
}
impl Eq for MsgType {}

impl std::hash::Hash for MsgType {
    fn hash<H: std::hash::Hasher>(&self, h: &mut H) {
        self.0.name.hash(h);
    }
}

impl fmt::Debug for MsgType {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "MsgType({})", self.0.name)
    }
}

impl fmt::Display for MsgType {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.0.name)
    }
}

impl Serialize for MsgType {
    fn serialize<S: serde::Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        s.serialize_str(self.0.name)
    }
}

impl<'de> Deserialize<'de> for MsgType {
    fn deserialize<D: serde::Deserializer<'de>>(d: D) -> Result<MsgType, D::Error> {
        let name = std::borrow::Cow::<'de, str>::deserialize(d)?;
        MsgType::named(&name).ok_or_else(|| {
            serde::de::Error::custom(format!(
                "unknown message type `{}`: expected one of {} (or a type a Rust program \
                 registers: ratelab::msg::register)",
                crate::text::printable(&name),
                crate::text::listed(registered().iter().map(|t| t.as_str()))
            ))
        })
    }
}

/// Why a message type cannot be registered.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum MsgRegistryError {
    /// The type's name, class or a field's name is not of the form [`Message`] asks.
    #[error("message type '{0}': {1}")]
    Bad(String, String),
    /// Another type has the name or the class already.
    #[error("message type '{0}': the name or class '{1}' is taken by another type")]
    Taken(String, String),
    /// [`MAX_MSG_TYPES`] types are registered already.
    #[error(
        "at most {MAX_MSG_TYPES} message types can be registered (ratelab::limits::MAX_MSG_TYPES)"
    )]
    Full,
}

/// Every message type: the built-in ones first, registered by the rules a program's own
/// types are ([`register_type`]).
fn registry() -> &'static RwLock<Vec<MsgType>> {
    static REGISTRY: LazyLock<RwLock<Vec<MsgType>>> = LazyLock::new(|| {
        let mut types = Vec::new();
        for t in [
            StateMsg::TYPE,
            PositionMsg::TYPE,
            ForceMsg::TYPE,
            ImageMsg::TYPE,
        ] {
            if let Err(e) = admit(&mut types, t) {
                panic!("a built-in message type breaks the registry's rules: {e}");
            }
        }
        RwLock::new(types)
    });
    &REGISTRY
}

/// Python's keywords: a field or type name must not be one (`msg.from` does not parse).
const PYTHON_KEYWORDS: [&str; 35] = [
    "False", "None", "True", "and", "as", "assert", "async", "await", "break", "class", "continue",
    "def", "del", "elif", "else", "except", "finally", "for", "from", "global", "if", "import",
    "in", "is", "lambda", "nonlocal", "not", "or", "pass", "raise", "return", "try", "while",
    "with", "yield",
];

/// What `import ratelab` gives besides the message classes (`src/python/support.py`): a
/// type's class must not take one of these names.
const PYTHON_TAKEN: [&str; 1] = ["Time"];

/// A field (or type) name: lowercase letters, digits and `_`, starting with a letter (a
/// leading `_` would hide the class's own methods), not a Python keyword.
fn valid_field(s: &str) -> bool {
    !s.is_empty()
        && s.len() <= 32
        && s.starts_with(|c: char| c.is_ascii_lowercase())
        && s.chars()
            .all(|c| c.is_ascii_lowercase() || c.is_ascii_digit() || c == '_')
        && !PYTHON_KEYWORDS.contains(&s)
}

/// Register message type `M`, so that graph files may name it (`type = "<M::NAME>"`).
/// Registering a type again is a no-op.
///
/// # Errors
/// [`MsgRegistryError`]: a name, class or field not of the form [`Message`] asks, a name or
/// class another type has, or too many types.
pub fn register<M: Message>() -> Result<(), MsgRegistryError> {
    register_type(M::TYPE)
}

/// [`register`] by handle (a node kind's types: `ratelab::graph::registry::register_kind`).
/// The built-in types (`state`, `position`, `force`) are registered by its rules too.
///
/// # Errors
/// As [`register`].
pub fn register_type(t: MsgType) -> Result<(), MsgRegistryError> {
    let mut reg = registry().write().unwrap_or_else(|e| e.into_inner());
    admit(&mut reg, t)
}

/// Add `t` to the types `reg` holds, by the registry's rules ([`register_type`]); a type
/// held already is left as it is.
fn admit(reg: &mut Vec<MsgType>, t: MsgType) -> Result<(), MsgRegistryError> {
    if !check_in(reg, t)? {
        reg.push(t);
    }
    Ok(())
}

/// Could [`register_type`] take `t`? `Ok(true)`: it is registered already.
///
/// # Errors
/// As [`register`].
pub fn check_type(t: MsgType) -> Result<bool, MsgRegistryError> {
    let reg = registry().read().unwrap_or_else(|e| e.into_inner());
    check_in(&reg, t)
}

/// [`check_type`] against the types `reg` holds.
fn check_in(reg: &[MsgType], t: MsgType) -> Result<bool, MsgRegistryError> {
    let (name, class, fields) = (t.as_str(), t.class(), t.fields());
    let bad = |why: &str| Err(MsgRegistryError::Bad(name.to_string(), why.to_string()));
    let name_ok = name.starts_with(|c: char| c.is_ascii_lowercase()) && valid_field(name);
    if !name_ok {
        return bad(
            "its name must be 1 to 32 lowercase letters, digits or '_', starting with a letter",
        );
    }
    let class_ok = class.len() <= 32
        && class.starts_with(|c: char| c.is_ascii_uppercase())
        && class.chars().all(|c| c.is_ascii_alphanumeric() || c == '_')
        && !PYTHON_KEYWORDS.contains(&class)
        && !PYTHON_TAKEN.contains(&class);
    if !class_ok {
        return bad("its class must be 1 to 32 letters, digits or '_', starting with a capital, and not a name `import ratelab` gives already (Time)");
    }
    if fields.is_empty() || fields.len() > MAX_FIELDS {
        let line = format_args!("it must have 1 to {MAX_FIELDS} fields");
        return bad(&crate::limits::refusal(line, "MAX_MSG_FIELDS"));
    }
    for (i, f) in fields.iter().enumerate() {
        if !valid_field(f.name) || fields[..i].iter().any(|g| g.name == f.name) {
            return bad(&format!(
                "field '{}' must be a unique name of 1 to 32 lowercase letters, digits or '_', starting with a letter, and not a Python keyword",
                f.name
            ));
        }
    }
    for other in reg {
        if (other.0.type_id)() == (t.0.type_id)() {
            return Ok(true);
        }
        if other.as_str() == name || other.class() == class {
            let clash = if other.as_str() == name { name } else { class };
            return Err(MsgRegistryError::Taken(name.to_string(), clash.to_string()));
        }
    }
    if reg.len() >= MAX_MSG_TYPES {
        return Err(MsgRegistryError::Full);
    }
    Ok(false)
}

/// Every registered message type, the built-in ones first, then in registration order.
pub fn registered() -> Vec<MsgType> {
    registry().read().unwrap_or_else(|e| e.into_inner()).clone()
}

/// The registered message types as a Markdown table, in [`registered`]'s order: the name a
/// graph file gives as a topic's `type`, the Python class, the fields with their units,
/// the ROS 2 type it is offered as (`—`: not offered) and its one line of docs. What
/// `ratelab msgs` prints and `docs/graphs.md`'s table of message types is (a test keeps the two
/// equal).
pub fn types_table() -> String {
    let mut out = String::from(
        "| type | Python class | fields (unit) | ROS 2 type | what it is |\n\
         | --- | --- | --- | --- | --- |\n",
    );
    for t in registered() {
        let fields = t
            .fields()
            .iter()
            .map(|f| match f.kind {
                FieldKind::Number | FieldKind::Integer => format!("`{}` ({})", f.name, f.unit),
                FieldKind::Text => format!("`{}` (text)", f.name),
                FieldKind::Bytes => format!("`{}` (bytes: {})", f.name, f.unit),
            })
            .collect::<Vec<_>>()
            .join(", ");
        let ros = t
            .ros2()
            .map_or_else(|| "—".to_string(), |c| format!("`{}`", (c.ros_type)().name));
        out += &format!(
            "| `{}` | `{}` | {fields} | {ros} | {} |\n",
            t.as_str(),
            t.class(),
            t.doc().replace('|', "\\|")
        );
    }
    out
}

/// A message value of some registered type: what crosses a process boundary
/// (`ratelab::distributed::wire`, as [`MsgData::to_bytes`]), what is offered to ROS 2
/// (`ratelab::ros2`) and what a ROS 2 node delivers.
#[derive(Clone)]
pub struct MsgData {
    ty: MsgType,
    value: Arc<dyn DynMessage>,
}

/// A message behind `dyn`: what [`MsgData`] needs of its value.
trait DynMessage: Any + Send + Sync + fmt::Debug {
    fn as_any(&self) -> &dyn Any;
    fn fields(&self) -> Vec<f64>;
    fn values(&self) -> Vec<Value>;
    fn to_bytes(&self) -> Vec<u8>;
    fn encoded_len(&self) -> usize;
    fn encode_into(&self, out: &mut [u8]) -> Result<usize, String>;
    fn encode_pieces(&self, sink: &mut dyn FnMut(&[u8])) -> Result<(), String>;
    fn eq_dyn(&self, other: &dyn DynMessage) -> bool;
}

impl<M: Message> DynMessage for M {
    fn as_any(&self) -> &dyn Any {
        self
    }
    fn fields(&self) -> Vec<f64> {
        self.to_fields()
    }
    fn values(&self) -> Vec<Value> {
        self.to_values()
    }
    fn to_bytes(&self) -> Vec<u8> {
        // Plain values (numbers, text, bytes): serde cannot fail on them.
        postcard::to_allocvec(self).unwrap_or_default()
    }
    fn encoded_len(&self) -> usize {
        postcard::experimental::serialized_size(self).unwrap_or(0)
    }
    fn encode_into(&self, out: &mut [u8]) -> Result<usize, String> {
        postcard::to_slice(self, out)
            .map(|written| written.len())
            .map_err(|e| format!("a {} payload: {e}", M::NAME))
    }
    fn encode_pieces(&self, sink: &mut dyn FnMut(&[u8])) -> Result<(), String> {
        postcard::serialize_with_flavor(self, pieces::ToSink(sink))
            .map_err(|e| format!("a {} payload: {e}", M::NAME))
    }
    fn eq_dyn(&self, other: &dyn DynMessage) -> bool {
        other.as_any().downcast_ref::<M>() == Some(self)
    }
}

impl MsgData {
    /// `m` as a payload.
    pub fn new<M: Message>(m: M) -> MsgData {
        MsgData {
            ty: M::TYPE,
            value: Arc::new(m),
        }
    }
    /// Its type.
    pub fn msg_type(&self) -> MsgType {
        self.ty
    }
    /// The message, if it is an `M`.
    pub fn get<M: Message>(&self) -> Option<&M> {
        self.value.as_any().downcast_ref::<M>()
    }
    /// Its number fields, in its type's order ([`Message::to_fields`]).
    pub fn fields(&self) -> Vec<f64> {
        self.value.fields()
    }
    /// Every field's value, in its type's order ([`Message::to_values`]).
    pub fn values(&self) -> Vec<Value> {
        self.value.values()
    }
    /// Its wire bytes (postcard; the inverse of [`MsgType::decode`]).
    pub fn to_bytes(&self) -> Vec<u8> {
        self.value.to_bytes()
    }
    /// How many bytes [`MsgData::to_bytes`] makes, found without making them.
    pub fn encoded_len(&self) -> usize {
        self.value.encoded_len()
    }
    /// Write [`MsgData::to_bytes`]'s bytes into the start of `out` (a shared-memory buffer,
    /// say, so that a large message is written once): how many were written.
    ///
    /// # Errors
    /// `out` is shorter than [`MsgData::encoded_len`].
    pub fn encode_into(&self, out: &mut [u8]) -> Result<usize, String> {
        self.value.encode_into(out)
    }
    /// Hand [`MsgData::to_bytes`]'s bytes to `sink` in order, piece by piece as they are
    /// made: a field of bytes (an image's pixels) is one piece, its own bytes, so a sink can
    /// tell a frame that already lies where it will cross (a lent buffer,
    /// [`crate::pixels::PixelBuffer`]) by its address and pass it on without copying it.
    ///
    /// # Errors
    /// Never for ratelab's own types (plain values); a message type whose `Serialize` fails.
    pub fn encode_pieces(&self, sink: &mut dyn FnMut(&[u8])) -> Result<(), String> {
        self.value.encode_pieces(sink)
    }
    /// One line for people: `force: newtons=1.5 N`; text quoted, bytes counted
    /// (`data=<307200 bytes>`).
    pub fn describe(&self) -> String {
        let parts: Vec<String> = self
            .ty
            .fields()
            .iter()
            .zip(self.values())
            .map(|(d, v)| match (v, d.unit) {
                (Value::Number(v), "1" | "") => format!("{}={v}", d.name),
                (Value::Number(v), u) => format!("{}={v} {u}", d.name),
                (Value::Text(t), _) => format!("{}={t:?}", d.name),
                (Value::Bytes(b), _) => format!("{}=<{} bytes>", d.name, b.len()),
            })
            .collect();
        format!("{}: {}", self.ty, parts.join(", "))
    }
}

impl PartialEq for MsgData {
    fn eq(&self, other: &MsgData) -> bool {
        self.ty == other.ty && self.value.eq_dyn(&*other.value)
    }
}

impl fmt::Debug for MsgData {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{:?}", self.value)
    }
}

impl<M: Message> From<M> for MsgData {
    fn from(m: M) -> MsgData {
        MsgData::new(m)
    }
}

/// Told of every message published on a topic as a payload ([`AnyTopic::add_data_tap`]):
/// its `seq`, stamp, origin stamp (what it was derived from, for sense→act latency) and
/// value. On the publisher's thread, under the topic's lock: be quick.
pub type DataTap = Box<dyn Fn(u64, Nanos, Option<Nanos>, MsgData) + Send + Sync>;

/// What [`AnyTopic`] needs of a typed topic.
trait ErasedTopic: Send + Sync + fmt::Debug {
    fn msg_type(&self) -> MsgType;
    fn any(&self) -> &dyn Any;
    fn name(&self) -> &str;
    fn stats(&self) -> TopicStats;
    fn stats_at(&self, now: Nanos) -> TopicStats;
    fn stats_and_timing_at(&self, now: Nanos) -> (TopicStats, bool);
    fn watch_changes(&self, slot: &ChangeSlot) -> bool;
    fn qos(&self) -> TopicQos;
    fn set_qos(&self, qos: TopicQos);
    fn set_matched(&self, matched: bool);
    fn matched(&self) -> bool;
    fn set_joins_at(&self, at: Nanos);
    fn set_publisher_start(&self, at: Nanos);
    fn set_depth(&self, depth: usize) -> Result<(), ZeroDepth>;
    fn buffered(&self) -> usize;
    fn unseen_buffered(&self) -> usize;
    fn next_seq(&self) -> u64;
    fn count_lost(&self, n: u64);
    fn read(&self, now: Nanos) -> Option<Received>;
    fn publish(
        &self,
        outbox: Option<&Outbox>,
        data: &MsgData,
        stamp: Nanos,
        origin: Option<Nanos>,
    ) -> bool;
    fn add_data_tap(&self, tap: DataTap);
    fn set_lender(&self, lender: Arc<dyn crate::pixels::Lender>) -> bool;
    fn lender(&self) -> Option<Arc<dyn crate::pixels::Lender>>;
    fn subscriptions(&self) -> Vec<AnyTopic>;
    fn subscription_stats(&self, now: Option<Nanos>) -> Vec<TopicStats>;
    fn save(&self) -> TopicSnapshot;
    fn load(&self, state: &TopicSnapshot) -> bool;
}

/// A topic's state at an instant, every subscription's queue ([`AnyTopic::save`]).
pub struct TopicSnapshot(Box<dyn Any + Send + Sync>);

/// A message read from a topic of any type ([`AnyTopic::read`]).
#[derive(Clone, Debug, PartialEq)]
pub struct Received {
    /// Its sequence number.
    pub seq: u64,
    /// Its origin stamp, or its own stamp when it has none (a reading).
    pub origin: Nanos,
    /// The value.
    pub data: MsgData,
}

impl<M: Message> ErasedTopic for Arc<Subscription<M>> {
    fn msg_type(&self) -> MsgType {
        M::TYPE
    }
    fn any(&self) -> &dyn Any {
        self
    }
    fn name(&self) -> &str {
        Subscription::name(self)
    }
    fn stats(&self) -> TopicStats {
        Subscription::stats(self)
    }
    fn stats_at(&self, now: Nanos) -> TopicStats {
        Subscription::stats_at(self, now)
    }
    fn stats_and_timing_at(&self, now: Nanos) -> (TopicStats, bool) {
        Subscription::stats_and_timing_at(self, now)
    }
    fn watch_changes(&self, slot: &ChangeSlot) -> bool {
        Subscription::watch_changes(self, slot.clone())
    }
    fn qos(&self) -> TopicQos {
        Subscription::qos(self)
    }
    fn set_qos(&self, qos: TopicQos) {
        Subscription::set_qos(self, qos);
    }
    fn set_matched(&self, matched: bool) {
        Subscription::set_matched(self, matched);
    }
    fn matched(&self) -> bool {
        Subscription::matched(self)
    }
    fn set_joins_at(&self, at: Nanos) {
        Subscription::set_joins_at(self, at);
    }
    fn set_publisher_start(&self, at: Nanos) {
        Subscription::set_publisher_start(self, at);
    }
    fn set_depth(&self, depth: usize) -> Result<(), ZeroDepth> {
        Subscription::set_depth(self, depth)
    }
    fn buffered(&self) -> usize {
        Subscription::buffered(self)
    }
    fn unseen_buffered(&self) -> usize {
        Subscription::unseen_buffered(self)
    }
    fn next_seq(&self) -> u64 {
        Subscription::next_seq(self)
    }
    fn count_lost(&self, n: u64) {
        Subscription::count_lost(self, n);
    }
    fn read(&self, now: Nanos) -> Option<Received> {
        let m = Subscription::read(self, now)?;
        Some(Received {
            seq: m.seq,
            origin: m.origin_stamp.unwrap_or(m.stamp),
            data: MsgData::new(m.data),
        })
    }
    fn publish(
        &self,
        outbox: Option<&Outbox>,
        data: &MsgData,
        stamp: Nanos,
        origin: Option<Nanos>,
    ) -> bool {
        let Some(m) = data.get::<M>() else {
            return false;
        };
        match outbox {
            Some(o) => o.publish(self, m.clone(), stamp, origin),
            None => {
                Subscription::publish(self, m.clone(), stamp, origin);
            }
        }
        true
    }
    fn add_data_tap(&self, tap: DataTap) {
        self.add_tap(Box::new(move |m: &crate::topic::Message<M>| {
            tap(m.seq, m.stamp, m.origin_stamp, MsgData::new(m.data.clone()))
        }));
    }
    fn set_lender(&self, lender: Arc<dyn crate::pixels::Lender>) -> bool {
        Subscription::set_lender(self, lender)
    }
    fn lender(&self) -> Option<Arc<dyn crate::pixels::Lender>> {
        Subscription::lender(self).cloned()
    }
    fn subscriptions(&self) -> Vec<AnyTopic> {
        vec![AnyTopic(Arc::new(self.clone()))]
    }
    fn subscription_stats(&self, now: Option<Nanos>) -> Vec<TopicStats> {
        vec![now.map_or_else(
            || Subscription::stats(self),
            |n| Subscription::stats_at(self, n),
        )]
    }
    fn save(&self) -> TopicSnapshot {
        TopicSnapshot(Box::new(Subscription::save(self)))
    }
    fn load(&self, state: &TopicSnapshot) -> bool {
        match state.0.downcast_ref::<crate::topic::TopicState<M>>() {
            Some(s) => {
                Subscription::load(self, s);
                true
            }
            None => false,
        }
    }
}

/// A topic of several subscribers: a queue per subscription, as ROS 2 gives each
/// subscription its own history. A publish goes into every queue; each subscriber reads its
/// own, with its own drop rule, link fates and counters. Its counters as one
/// ([`AnyTopic::stats`]) are the first queue's for what the publisher did (`published`,
/// `last_stamp`, `depth`, `offered_deadline_missed`) and the sum over the subscriptions for
/// what each reader met (`dropped`, `seen`, `stale_reads`, `expired`, `refused`, `lost`,
/// `retransmitted`, `in_flight`, `requested_deadline_missed`).
#[derive(Debug)]
struct FanOut<M> {
    queues: Vec<Arc<Subscription<M>>>,
}

/// Several subscriptions' counters as one (see [`FanOut`]).
fn combined(all: Vec<TopicStats>) -> TopicStats {
    let mut it = all.into_iter();
    let mut out = it.next().unwrap_or_default();
    for s in it {
        out.dropped += s.dropped;
        out.seen += s.seen;
        out.stale_reads += s.stale_reads;
        out.expired += s.expired;
        out.refused += s.refused;
        out.lost += s.lost;
        out.retransmitted += s.retransmitted;
        out.in_flight += s.in_flight;
        out.requested_deadline_missed += s.requested_deadline_missed;
        out.unmatched += s.unmatched;
        out.before_join += s.before_join;
    }
    out
}

impl<M: Message> ErasedTopic for FanOut<M> {
    fn msg_type(&self) -> MsgType {
        M::TYPE
    }
    fn any(&self) -> &dyn Any {
        self
    }
    fn name(&self) -> &str {
        self.queues[0].name()
    }
    fn stats(&self) -> TopicStats {
        combined(self.queues.iter().map(|q| q.stats()).collect())
    }
    fn stats_at(&self, now: Nanos) -> TopicStats {
        combined(self.queues.iter().map(|q| q.stats_at(now)).collect())
    }
    fn stats_and_timing_at(&self, now: Nanos) -> (TopicStats, bool) {
        let mut timed = false;
        let all = (self.queues.iter())
            .map(|q| {
                let (stats, t) = q.stats_and_timing_at(now);
                timed |= t;
                stats
            })
            .collect();
        (combined(all), timed)
    }
    fn watch_changes(&self, slot: &ChangeSlot) -> bool {
        // Every queue counts in the one slot: any of them changing moves it. Each is
        // asked, even after one refuses.
        let watched = (self.queues.iter())
            .filter(|q| Subscription::watch_changes(q, slot.clone()))
            .count();
        watched == self.queues.len()
    }
    fn qos(&self) -> TopicQos {
        self.queues[0].qos()
    }
    fn set_qos(&self, qos: TopicQos) {
        for q in &self.queues {
            q.set_qos(qos);
        }
    }
    fn set_matched(&self, matched: bool) {
        for q in &self.queues {
            q.set_matched(matched);
        }
    }
    fn matched(&self) -> bool {
        self.queues.iter().all(|q| q.matched())
    }
    fn set_joins_at(&self, at: Nanos) {
        for q in &self.queues {
            q.set_joins_at(at);
        }
    }
    fn set_publisher_start(&self, at: Nanos) {
        for q in &self.queues {
            q.set_publisher_start(at);
        }
    }
    fn set_depth(&self, depth: usize) -> Result<(), ZeroDepth> {
        self.queues.iter().try_for_each(|q| q.set_depth(depth))
    }
    fn buffered(&self) -> usize {
        self.queues.iter().map(|q| q.buffered()).max().unwrap_or(0)
    }
    fn unseen_buffered(&self) -> usize {
        self.queues
            .iter()
            .map(|q| q.unseen_buffered())
            .max()
            .unwrap_or(0)
    }
    fn next_seq(&self) -> u64 {
        self.queues[0].next_seq()
    }
    fn count_lost(&self, n: u64) {
        for q in &self.queues {
            q.count_lost(n);
        }
    }
    fn read(&self, now: Nanos) -> Option<Received> {
        // Each subscriber reads its own queue ([`AnyTopic::subscription`]).
        ErasedTopic::read(&self.queues[0], now)
    }
    fn publish(
        &self,
        outbox: Option<&Outbox>,
        data: &MsgData,
        stamp: Nanos,
        origin: Option<Nanos>,
    ) -> bool {
        self.queues
            .iter()
            .all(|q| ErasedTopic::publish(q, outbox, data, stamp, origin))
    }
    fn add_data_tap(&self, tap: DataTap) {
        // Every publish reaches every queue: the first sees each message once.
        self.queues[0].add_data_tap(tap);
    }
    fn set_lender(&self, lender: Arc<dyn crate::pixels::Lender>) -> bool {
        // One publisher lends for every queue: the first keeps the lender.
        Subscription::set_lender(&self.queues[0], lender)
    }
    fn lender(&self) -> Option<Arc<dyn crate::pixels::Lender>> {
        Subscription::lender(&self.queues[0]).cloned()
    }
    fn subscriptions(&self) -> Vec<AnyTopic> {
        self.queues
            .iter()
            .map(|q| AnyTopic(Arc::new(q.clone())))
            .collect()
    }
    fn subscription_stats(&self, now: Option<Nanos>) -> Vec<TopicStats> {
        self.queues
            .iter()
            .map(|q| now.map_or_else(|| q.stats(), |n| q.stats_at(n)))
            .collect()
    }
    fn save(&self) -> TopicSnapshot {
        let queues: Vec<crate::topic::TopicState<M>> =
            self.queues.iter().map(|q| Subscription::save(q)).collect();
        TopicSnapshot(Box::new(queues))
    }
    fn load(&self, state: &TopicSnapshot) -> bool {
        match state.0.downcast_ref::<Vec<crate::topic::TopicState<M>>>() {
            Some(s) if s.len() == self.queues.len() => {
                for (q, s) in self.queues.iter().zip(s) {
                    Subscription::load(q, s);
                }
                true
            }
            _ => false,
        }
    }
}

/// A topic of any registered message type (module docs). Cheap to clone: the clones are
/// the one topic.
#[derive(Clone, Debug)]
pub struct AnyTopic(Arc<dyn ErasedTopic>);

impl AnyTopic {
    /// Every subscription's queue as it is now (its messages, QoS, link generator,
    /// counters): for a capture of the run (`ratelab::runcore`).
    pub fn save(&self) -> TopicSnapshot {
        self.0.save()
    }

    /// Put back what [`AnyTopic::save`] gave this topic. False (nothing changed) when
    /// `state` is another topic's type or shape.
    pub fn load(&self, state: &TopicSnapshot) -> bool {
        self.0.load(state)
    }

    /// A new topic of type `msg` with the chapter's QoS.
    ///
    /// # Errors
    /// [`ZeroDepth`] for depth 0.
    pub fn new(name: &str, msg: MsgType, depth: usize) -> Result<AnyTopic, ZeroDepth> {
        Self::with_qos(name, msg, depth, TopicQos::default(), 0)
    }

    /// A new topic of type `msg` with `qos`, its link seeded by `link_seed`.
    ///
    /// # Errors
    /// [`ZeroDepth`] for depth 0.
    pub fn with_qos(
        name: &str,
        msg: MsgType,
        depth: usize,
        qos: TopicQos,
        link_seed: u64,
    ) -> Result<AnyTopic, ZeroDepth> {
        (msg.0.new_topic)(name, depth, qos, link_seed, 1)
    }

    /// A new topic of type `msg` with `qos` read by `subscriptions` subscribers, each with
    /// a queue of its own (its depth, drop rule, link fates — seeded from `link_seed` and
    /// its index — and counters); at most one subscriber gives the one queue
    /// [`AnyTopic::with_qos`] makes.
    ///
    /// # Errors
    /// [`ZeroDepth`] for depth 0.
    pub fn with_subscriptions(
        name: &str,
        msg: MsgType,
        depth: usize,
        qos: TopicQos,
        link_seed: u64,
        subscriptions: usize,
    ) -> Result<AnyTopic, ZeroDepth> {
        (msg.0.new_topic)(name, depth, qos, link_seed, subscriptions)
    }

    /// The typed queue, if it carries `M` and has one queue (for several subscribers: a
    /// subscriber's own, [`AnyTopic::subscription`]).
    pub fn typed<M: Message>(&self) -> Option<&Arc<Subscription<M>>> {
        self.0.any().downcast_ref::<Arc<Subscription<M>>>()
    }

    /// A publisher of `M` on it, into every subscription's queue, through `outbox`; `None`
    /// when it carries another type.
    pub fn publisher<M: Message>(&self, outbox: &Outbox) -> Option<crate::publisher::Publisher<M>> {
        let any = self.0.any();
        if let Some(t) = any.downcast_ref::<Arc<Subscription<M>>>() {
            return Some(crate::publisher::Publisher::new(t.clone(), outbox.clone()));
        }
        let fan = any.downcast_ref::<FanOut<M>>()?;
        Some(crate::publisher::Publisher::fan_out(
            fan.queues.clone(),
            outbox.clone(),
        ))
    }

    /// Subscription `k`'s queue, as a topic of its own (what subscriber number `k`, in
    /// tie-break order, reads); the topic itself when it has one queue.
    pub fn subscription(&self, k: usize) -> AnyTopic {
        let mut all = self.0.subscriptions();
        if k < all.len() {
            all.swap_remove(k)
        } else {
            self.clone()
        }
    }

    /// Every subscription's counters, in subscriber order (one entry for a topic of one
    /// queue), as of their latest operations or at run time `now`.
    pub fn subscription_stats(&self, now: Option<Nanos>) -> Vec<TopicStats> {
        self.0.subscription_stats(now)
    }

    /// The type of message it carries (the `msg` it was made with).
    pub fn msg_type(&self) -> MsgType {
        self.0.msg_type()
    }

    /// Counters and depth as of the topic's latest operation.
    pub fn stats(&self) -> TopicStats {
        self.0.stats()
    }

    /// Counters and depth at run time `now` (see [`Subscription::stats_at`]).
    pub fn stats_at(&self, now: Nanos) -> TopicStats {
        self.0.stats_at(now)
    }

    /// [`AnyTopic::stats_at`], and whether the counters move with `now` alone (see
    /// [`Subscription::stats_and_timing_at`]).
    pub fn stats_and_timing_at(&self, now: Nanos) -> (TopicStats, bool) {
        self.0.stats_and_timing_at(now)
    }

    /// Count every change of any of its queues in `slot` from now on (see
    /// [`Subscription::watch_changes`]); false when a queue was already watched, whose
    /// changes then do not reach `slot`.
    pub fn watch_changes(&self, slot: &ChangeSlot) -> bool {
        self.0.watch_changes(slot)
    }

    /// The QoS in force.
    pub fn qos(&self) -> TopicQos {
        self.0.qos()
    }

    /// Change the QoS while running (see [`Subscription::set_qos`]).
    pub fn set_qos(&self, qos: TopicQos) {
        self.0.set_qos(qos);
    }

    /// Connect every subscription of this topic (or of the one queue
    /// [`AnyTopic::subscription`] gave) to the publisher, or leave them unconnected (see
    /// [`Subscription::set_matched`]).
    pub fn set_matched(&self, matched: bool) {
        self.0.set_matched(matched);
    }

    /// Whether every subscription of it is connected to the publisher
    /// ([`AnyTopic::set_matched`]).
    pub fn matched(&self) -> bool {
        self.0.matched()
    }

    /// Make every subscription of it (or the one queue [`AnyTopic::subscription`] gave)
    /// come into being at `at` (see [`Subscription::set_joins_at`]).
    pub fn set_joins_at(&self, at: Nanos) {
        self.0.set_joins_at(at);
    }

    /// Its publisher comes into being at `at` (see [`Subscription::set_publisher_start`]).
    pub fn set_publisher_start(&self, at: Nanos) {
        self.0.set_publisher_start(at);
    }

    /// Change the history depth (see [`Subscription::set_depth`]).
    ///
    /// # Errors
    /// [`ZeroDepth`] for 0.
    pub fn set_depth(&self, depth: usize) -> Result<(), ZeroDepth> {
        self.0.set_depth(depth)
    }

    /// Messages buffered now.
    pub fn buffered(&self) -> usize {
        self.0.buffered()
    }

    /// Buffered messages no subscriber has seen yet (see [`Subscription::unseen_buffered`]).
    pub fn unseen_buffered(&self) -> usize {
        self.0.unseen_buffered()
    }

    /// The topic's name.
    pub fn name(&self) -> &str {
        self.0.name()
    }

    /// The `seq` the next publish takes (see [`Subscription::next_seq`]).
    pub fn next_seq(&self) -> u64 {
        self.0.next_seq()
    }

    /// Account `n` messages lost on the wire (see [`Subscription::count_lost`]).
    pub fn count_lost(&self, n: u64) {
        self.0.count_lost(n);
    }

    /// Read at `now` by the topic's QoS, as a subscriber does ([`Subscription::read`]).
    pub fn read(&self, now: Nanos) -> Option<Received> {
        self.0.read(now)
    }

    /// Publish `data` stamped `stamp`, through `outbox` (held during a tick with a compute
    /// time) or straight onto the topic (`None`).
    ///
    /// # Errors
    /// `data` is not of the topic's type (nothing is published).
    pub fn publish(
        &self,
        outbox: Option<&Outbox>,
        data: &MsgData,
        stamp: Nanos,
        origin: Option<Nanos>,
    ) -> Result<(), String> {
        if self.0.publish(outbox, data, stamp, origin) {
            Ok(())
        } else {
            Err(format!(
                "a {} message on {}, which carries {}",
                data.msg_type(),
                self.name(),
                self.msg_type()
            ))
        }
    }

    /// Tell `tap` of every message published from now on, after the taps added before it
    /// (see [`Subscription::add_tap`]).
    pub fn add_data_tap(&self, tap: DataTap) {
        self.0.add_data_tap(tap);
    }

    /// Lend its publisher's frames from `lender` from now on (a launch's process lends
    /// buffers of its shared-memory pool for a topic that crosses to another process): false,
    /// and nothing changed, when a lender was set before.
    pub fn set_lender(&self, lender: Arc<dyn crate::pixels::Lender>) -> bool {
        self.0.set_lender(lender)
    }

    /// `len` bytes for a frame its publisher is about to draw, every one 0 (ROS 2's loaned
    /// message, rclcpp's `Publisher::borrow_loaned_message`): lent by the topic's lender when
    /// it has one and a buffer to lend ([`AnyTopic::set_lender`]; a frame drawn there crosses
    /// to another process without a copy), else memory of their own. Publish the frame as
    /// an [`crate::pixels::ImageData`] made `from` it.
    pub fn loan_pixels(&self, len: usize) -> crate::pixels::PixelBuffer {
        crate::pixels::PixelBuffer::lent(self.0.lender().as_deref(), len)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
    struct Setpoint {
        cart_pos_m: f64,
    }

    impl Message for Setpoint {
        const NAME: &'static str = "setpoint_unit";
        const CLASS: &'static str = "SetpointUnit";
        const DOC: &'static str = "A setpoint.";
        const FIELDS: &'static [Field] = &[Field::new("cart_pos_m", "m", "cart position")];
        fn to_fields(&self) -> Vec<f64> {
            vec![self.cart_pos_m]
        }
        fn from_fields(f: &[f64]) -> Self {
            Setpoint { cart_pos_m: f[0] }
        }
    }

    #[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
    struct Impostor(f64);

    impl Message for Impostor {
        const NAME: &'static str = "force";
        const CLASS: &'static str = "Impostor";
        const DOC: &'static str = "Not a force.";
        const FIELDS: &'static [Field] = &[Field::new("x", "1", "x")];
        fn to_fields(&self) -> Vec<f64> {
            vec![self.0]
        }
        fn from_fields(f: &[f64]) -> Self {
            Impostor(f[0])
        }
    }

    #[test]
    fn a_registered_type_is_usable_by_name_once() {
        assert_eq!(MsgType::named("setpoint_unit"), None);
        register::<Setpoint>().unwrap();
        register::<Setpoint>().unwrap(); // again: a no-op
        let t = MsgType::named("setpoint_unit").unwrap();
        assert!(t.is::<Setpoint>() && !t.is::<ForceMsg>());
        assert_eq!((t.class(), t.fields().len()), ("SetpointUnit", 1));
        assert_eq!(
            registered().iter().filter(|x| **x == t).count(),
            1,
            "registered once"
        );
        assert!(matches!(
            register::<Impostor>(),
            Err(MsgRegistryError::Taken(_, _))
        ));
        // A topic of it, typed and erased.
        let topic = AnyTopic::new("/sp", t, 1).unwrap();
        assert!(topic.typed::<Setpoint>().is_some() && topic.typed::<ForceMsg>().is_none());
        let data = t.from_fields(&[0.25]);
        topic.publish(None, &data, Nanos(5), None).unwrap();
        assert!(topic
            .publish(
                None,
                &MsgData::new(ForceMsg { newtons: 1.0 }),
                Nanos(6),
                None
            )
            .is_err());
        let got = topic.read(Nanos(7)).unwrap();
        assert_eq!(
            (got.seq, got.origin, got.data.fields()),
            (0, Nanos(5), vec![0.25])
        );
        assert_eq!(got.data.describe(), "setpoint_unit: cart_pos_m=0.25 m");
    }

    #[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
    struct Keyword(f64);

    impl Message for Keyword {
        const NAME: &'static str = "keyword_unit";
        const CLASS: &'static str = "KeywordUnit";
        const DOC: &'static str = "A field Python cannot name.";
        const FIELDS: &'static [Field] = &[Field::new("from", "1", "a keyword")];
        fn to_fields(&self) -> Vec<f64> {
            vec![self.0]
        }
        fn from_fields(f: &[f64]) -> Self {
            Keyword(f[0])
        }
    }

    /// A program's own type with a bytes field (a laser scan's ranges, packed) and a text
    /// field, as a point cloud or a map would be written.
    #[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
    struct Scan {
        frame_id: String,
        angle_increment_rad: f64,
        ranges: ImageData,
    }

    impl Message for Scan {
        const NAME: &'static str = "scan_unit";
        const CLASS: &'static str = "ScanUnit";
        const DOC: &'static str = "Ranges, packed as little-endian f32.";
        const FIELDS: &'static [Field] = &[
            Field::text("frame_id", "the sensor's frame"),
            Field::new("angle_increment_rad", "rad", "between two ranges"),
            Field::bytes("ranges", "f32 LE", "the ranges, m"),
        ];
        fn to_fields(&self) -> Vec<f64> {
            vec![self.angle_increment_rad]
        }
        fn from_fields(f: &[f64]) -> Self {
            Scan {
                frame_id: String::new(),
                angle_increment_rad: f[0],
                ranges: ImageData::default(),
            }
        }
        fn to_values(&self) -> Vec<Value> {
            vec![
                Value::Text(self.frame_id.clone()),
                Value::Number(self.angle_increment_rad),
                Value::Bytes(self.ranges.clone()),
            ]
        }
        fn from_values(v: &[Value]) -> Self {
            match v {
                [Value::Text(frame_id), Value::Number(inc), Value::Bytes(ranges)] => Scan {
                    frame_id: frame_id.clone(),
                    angle_increment_rad: *inc,
                    ranges: ranges.clone(),
                },
                _ => Scan::from_fields(&[0.0]),
            }
        }
    }

    #[test]
    fn a_program_s_own_type_carries_bytes_shared_in_one_process_and_whole_across() {
        register::<Scan>().unwrap();
        let t = MsgType::named("scan_unit").unwrap();
        let ranges: Vec<u8> = (0..360)
            .flat_map(|i| (1.0f32 + i as f32).to_le_bytes())
            .collect();
        let scan = Scan {
            frame_id: "laser".into(),
            angle_increment_rad: 0.0175,
            ranges: ranges.clone().into(),
        };
        // In one process: every subscriber's copy is the publisher's bytes, not a copy.
        let topic = AnyTopic::new("/scan", t, 1).unwrap();
        let data = MsgData::new(scan.clone());
        topic.publish(None, &data, Nanos(5), None).unwrap();
        let got = topic.read(Nanos(6)).unwrap();
        let got = got.data.get::<Scan>().unwrap();
        assert!(got.ranges.shares(&scan.ranges));
        // Across processes: encoded and decoded whole, its text and bytes included.
        let decoded = t.decode(&data.to_bytes()).unwrap();
        assert_eq!(decoded.get::<Scan>(), Some(&scan));
        assert_eq!(
            decoded.get::<Scan>().unwrap().ranges.as_slice(),
            &ranges[..]
        );
        // By field values (Python's way in) and described by size.
        let values = scan.to_values();
        assert_eq!(
            t.from_values(&values).map(|d| d.get::<Scan>().cloned()),
            Ok(Some(scan))
        );
        assert!(
            data.describe().contains("ranges=<1440 bytes>"),
            "{}",
            data.describe()
        );
    }

    #[test]
    fn a_full_registry_refuses_naming_the_bound() {
        let full = vec![StateMsg::TYPE; MAX_MSG_TYPES];
        let e = check_in(&full, Setpoint::TYPE).unwrap_err();
        assert_eq!(
            e.to_string(),
            "at most 1024 message types can be registered (ratelab::limits::MAX_MSG_TYPES)"
        );
        assert_eq!(check_in(&full[1..], Setpoint::TYPE), Ok(false));
    }

    #[test]
    fn names_python_cannot_use_are_refused() {
        let e = register::<Keyword>().unwrap_err().to_string();
        assert!(
            e.contains("field 'from'") && e.contains("Python keyword"),
            "{e}"
        );
        assert!(!valid_field("_fields") && !valid_field("lambda") && valid_field("cart_pos_m"));
        assert_eq!(MsgType::named("keyword_unit"), None);
    }

    #[test]
    fn payloads_cross_as_bytes_exactly() {
        let d = MsgData::new(ForceMsg { newtons: -2.5 });
        let bytes = d.to_bytes();
        assert_eq!(ForceMsg::TYPE.decode(&bytes), Ok(d.clone()));
        let mut longer = bytes.clone();
        longer.push(0);
        assert!(ForceMsg::TYPE
            .decode(&longer)
            .unwrap_err()
            .contains("after"));
        assert!(
            StateMsg::TYPE.decode(&bytes).is_err(),
            "too short for a state"
        );
        assert!(ForceMsg::TYPE
            .decode(&vec![0; MAX_PAYLOAD_BYTES + 1])
            .is_err());
        let s = MsgData::new([0.5f32, 1.0, 0.0, 1.0, -2.0]);
        assert_eq!(StateMsg::TYPE.decode(&s.to_bytes()), Ok(s));
    }

    #[test]
    fn types_serialize_by_name_and_unknown_names_are_refused() {
        let j = serde_json::to_string(&PositionMsg::TYPE).unwrap();
        assert_eq!(j, "\"position\"");
        assert_eq!(
            serde_json::from_str::<MsgType>(&j).unwrap(),
            PositionMsg::TYPE
        );
        let e = serde_json::from_str::<MsgType>("\"imu\"")
            .unwrap_err()
            .to_string();
        assert!(e.contains("unknown message type `imu`") && e.contains("state, position, force"));
    }
}
