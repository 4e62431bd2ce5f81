//! What `ratelab ros2 topic echo` prints: a message of any described ROS 2 type decoded from
//! its CDR bytes by its type description (the one rmw_zenoh's tokens name by RIHS01 hash),
//! written as ros2cli's `echo` writes it (YAML by `serde_yaml`, block style, `---` between
//! messages).
//!
//! The types known here: ratelab's own (`sensor_msgs/msg/JointState`, `std_msgs/msg/Float64`,
//! `rosgraph_msgs/msg/Clock`) and common ROS 2 ones (`std_msgs` String, Bool, Int32, Int64,
//! Float32, Header; `builtin_interfaces` Time, Duration; `geometry_msgs` Vector3, Point,
//! Quaternion, Pose, Twist; `sensor_msgs/msg/Imu`, `sensor_msgs/msg/Image`; every node's
//! `rcl_interfaces/msg/Log` and `ParameterEvent`). A message is
//! decoded only when its type's name **and** hash are one of these (a type of the same name but another
//! definition is not guessed at); any other is said by name, hash and byte length.
//!
//! Decoding walks the description with serde over `hiroz-cdr`'s CDR deserializer (no CDR
//! is read here by hand), bounded: a payload over [`MAX_PAYLOAD_BYTES`] is not decoded, a
//! sequence longer than the bytes left is refused, nesting is the descriptions' own (at
//! most [`MAX_DEPTH`]). `serde_yaml` escapes a string's control characters, so no payload
//! reaches the terminal raw. As ros2cli's default `--truncate-length`, a list or a string
//! longer than [`TRUNCATE_LENGTH`] is cut there and ends in `...` (an image's pixels are
//! read through, never held).

use hiroz_schema::{
    FieldDescription, FieldTypeDescription, TypeDescription, TypeDescriptionMsg, TypeHash, TypeId,
};
use serde::de::{DeserializeSeed, Deserializer, Error as _, SeqAccess, Visitor};
use std::collections::BTreeMap;
use std::fmt;
use std::sync::OnceLock;

/// The largest payload decoded (bytes): a larger one is said by its length alone.
pub const MAX_PAYLOAD_BYTES: usize = 64 * 1024 * 1024;

/// Lists and strings longer than this are cut to it, followed by `'...'` (a list's last
/// item) or `...` (a string's end): ros2cli's `topic echo` default (`--truncate-length`).
pub const TRUNCATE_LENGTH: usize = 128;

/// The deepest nesting of types walked (a described type nests at most 3).
pub const MAX_DEPTH: usize = 16;

/// A decoded value.
#[derive(Clone, Debug, PartialEq)]
pub enum Value {
    /// `bool`.
    Bool(bool),
    /// Any signed integer.
    Int(i64),
    /// Any unsigned integer.
    UInt(u64),
    /// `float64`, or `float32` widened (printed as Python prints it).
    Float(f64),
    /// `string`.
    Str(String),
    /// An array or a sequence.
    List(Vec<Value>),
    /// A message: its fields in order.
    Struct(Vec<(String, Value)>),
}

/// A described type: its full name, description (with the types it refers to) and hash.
#[derive(Debug)]
pub struct Described {
    /// `package/msg/Name`.
    pub name: String,
    /// The description as `type_description_interfaces` has it.
    pub description: TypeDescriptionMsg,
    /// Its RIHS01 hash.
    pub hash: TypeHash,
}

fn field(name: &str, field_type: FieldTypeDescription) -> FieldDescription {
    FieldDescription {
        name: name.to_string(),
        field_type,
        default_value: String::new(),
    }
}

fn prim(name: &str, id: u8) -> FieldDescription {
    field(name, FieldTypeDescription::primitive(id))
}

fn nested(name: &str, ty: &str) -> FieldDescription {
    field(name, FieldTypeDescription::nested(TypeId::NESTED_TYPE, ty))
}

fn describe(name: &str, fields: Vec<FieldDescription>) -> TypeDescription {
    TypeDescription {
        type_name: name.to_string(),
        fields,
    }
}

/// `rcl_interfaces`' messages every ROS 2 node publishes (`/rosout`'s `Log`,
/// `/parameter_events`' `ParameterEvent`) and the types they hold.
fn rcl_interfaces_descriptions() -> Vec<TypeDescription> {
    use TypeId as T;
    let seq = |id: u8| FieldTypeDescription::primitive(id + T::UNBOUNDED_SEQUENCE_OFFSET);
    let seq_of = |name: &str| {
        FieldTypeDescription::nested(T::NESTED_TYPE + T::UNBOUNDED_SEQUENCE_OFFSET, name)
    };
    let value = "rcl_interfaces/msg/ParameterValue";
    let parameter = "rcl_interfaces/msg/Parameter";
    vec![
        describe(
            "rcl_interfaces/msg/Log",
            vec![
                nested("stamp", "builtin_interfaces/msg/Time"),
                prim("level", T::UINT8),
                prim("name", T::STRING),
                prim("msg", T::STRING),
                prim("file", T::STRING),
                prim("function", T::STRING),
                prim("line", T::UINT32),
            ],
        ),
        describe(
            value,
            vec![
                prim("type", T::UINT8),
                prim("bool_value", T::BOOL),
                prim("integer_value", T::INT64),
                prim("double_value", T::FLOAT64),
                prim("string_value", T::STRING),
                field("byte_array_value", seq(T::BYTE)),
                field("bool_array_value", seq(T::BOOL)),
                field("integer_array_value", seq(T::INT64)),
                field("double_array_value", seq(T::FLOAT64)),
                field("string_array_value", seq(T::STRING)),
            ],
        ),
        describe(
            parameter,
            vec![prim("name", T::STRING), nested("value", value)],
        ),
        describe(
            "rcl_interfaces/msg/ParameterEvent",
            vec![
                nested("stamp", "builtin_interfaces/msg/Time"),
                prim("node", T::STRING),
                field("new_parameters", seq_of(parameter)),
                field("changed_parameters", seq_of(parameter)),
                field("deleted_parameters", seq_of(parameter)),
            ],
        ),
    ]
}

/// Every type's own description, by name (the ones a type refers to are found here).
fn own_descriptions() -> Vec<TypeDescription> {
    use TypeId as T;
    let xyz = |name: &str, w: bool| {
        let mut f = vec![
            prim("x", T::FLOAT64),
            prim("y", T::FLOAT64),
            prim("z", T::FLOAT64),
        ];
        if w {
            f.push(prim("w", T::FLOAT64));
        }
        describe(name, f)
    };
    let cov = || FieldTypeDescription::array(T::FLOAT64 + T::ARRAY_OFFSET, 9);
    let one = |name: &str, id: u8| describe(name, vec![prim("data", id)]);
    let mut own = vec![
        describe(
            "builtin_interfaces/msg/Time",
            vec![prim("sec", T::INT32), prim("nanosec", T::UINT32)],
        ),
        describe(
            "builtin_interfaces/msg/Duration",
            vec![prim("sec", T::INT32), prim("nanosec", T::UINT32)],
        ),
        describe(
            "std_msgs/msg/Header",
            vec![
                nested("stamp", "builtin_interfaces/msg/Time"),
                prim("frame_id", T::STRING),
            ],
        ),
        one("std_msgs/msg/String", T::STRING),
        one("std_msgs/msg/Bool", T::BOOL),
        one("std_msgs/msg/Int32", T::INT32),
        one("std_msgs/msg/Int64", T::INT64),
        one("std_msgs/msg/Float32", T::FLOAT32),
        xyz("geometry_msgs/msg/Vector3", false),
        xyz("geometry_msgs/msg/Point", false),
        xyz("geometry_msgs/msg/Quaternion", true),
        describe(
            "geometry_msgs/msg/Pose",
            vec![
                nested("position", "geometry_msgs/msg/Point"),
                nested("orientation", "geometry_msgs/msg/Quaternion"),
            ],
        ),
        describe(
            "geometry_msgs/msg/Twist",
            vec![
                nested("linear", "geometry_msgs/msg/Vector3"),
                nested("angular", "geometry_msgs/msg/Vector3"),
            ],
        ),
        describe(
            "sensor_msgs/msg/Imu",
            vec![
                nested("header", "std_msgs/msg/Header"),
                nested("orientation", "geometry_msgs/msg/Quaternion"),
                field("orientation_covariance", cov()),
                nested("angular_velocity", "geometry_msgs/msg/Vector3"),
                field("angular_velocity_covariance", cov()),
                nested("linear_acceleration", "geometry_msgs/msg/Vector3"),
                field("linear_acceleration_covariance", cov()),
            ],
        ),
    ];
    own.extend(rcl_interfaces_descriptions());
    // ratelab's own types, as their one definition describes them (`ratelab_core::ros_types`).
    use ratelab_core::ros_types::{clock_type, float64_type, image_type, joint_state_type};
    for t in [
        joint_state_type(),
        float64_type(),
        clock_type(),
        image_type(),
    ] {
        own.push(t.description.type_description.clone());
    }
    own
}

/// The described types, by name.
pub fn known() -> &'static BTreeMap<String, Described> {
    static KNOWN: OnceLock<BTreeMap<String, Described>> = OnceLock::new();
    KNOWN.get_or_init(|| {
        let own: BTreeMap<String, TypeDescription> = own_descriptions()
            .into_iter()
            .map(|d| (d.type_name.clone(), d))
            .collect();
        own.values()
            .map(|d| {
                // The types it refers to, transitively, sorted by name (as RIHS01 hashes them).
                let mut referenced: BTreeMap<String, TypeDescription> = BTreeMap::new();
                let mut todo: Vec<&TypeDescription> = vec![d];
                while let Some(t) = todo.pop() {
                    for f in &t.fields {
                        let n = &f.field_type.nested_type_name;
                        if let Some(r) = own.get(n).filter(|_| !referenced.contains_key(n)) {
                            referenced.insert(n.clone(), r.clone());
                            todo.push(r);
                        }
                    }
                }
                let description = TypeDescriptionMsg {
                    type_description: d.clone(),
                    referenced_type_descriptions: referenced.into_values().collect(),
                };
                let hash = hiroz_schema::calculate_hash(&description);
                (
                    d.type_name.clone(),
                    Described {
                        name: d.type_name.clone(),
                        description,
                        hash,
                    },
                )
            })
            .collect()
    })
}

/// Decode `payload` (CDR with its 4-byte encapsulation header) as the described type
/// `name` whose hash is `hash` (`RIHS01_…`).
///
/// # Errors
/// One line: the type is not known here (or known with another hash), the payload is too
/// large, its header is not plain CDR, or its bytes do not decode as the type.
pub fn decode(name: &str, hash: &str, payload: &[u8]) -> Result<Value, String> {
    let d = known()
        .get(name)
        .filter(|d| d.hash.to_rihs_string() == hash)
        .ok_or_else(|| NOT_DESCRIBED.to_string())?;
    decode_with(&d.description, payload)
}

/// Why [`decode`] could not: the type is not one described here (or of another hash).
pub const NOT_DESCRIBED: &str = "a type not described here";

/// Decode `payload` (CDR with its 4-byte encapsulation header) by `description` (a type
/// and the types it refers to), with [`decode`]'s bounds: the caller has checked that it
/// is the message's type (its hash).
///
/// # Errors
/// One line: the payload is too large, its header is not plain CDR, or its bytes do not
/// decode as the type.
pub fn decode_with(description: &TypeDescriptionMsg, payload: &[u8]) -> Result<Value, String> {
    let d = description;
    if payload.len() > MAX_PAYLOAD_BYTES {
        return Err(format!("over {MAX_PAYLOAD_BYTES} bytes"));
    }
    let (head, body) = payload
        .split_at_checked(4)
        .ok_or("shorter than its CDR header")?;
    let types: BTreeMap<&str, &TypeDescription> = std::iter::once(&d.type_description)
        .chain(&d.referenced_type_descriptions)
        .map(|t| (t.type_name.as_str(), t))
        .collect();
    // Every value decoded costs one of these: at most one per byte per level of nesting,
    // so a description of empty or deeply repeated types cannot make a few bytes into
    // millions of values.
    let values = std::cell::Cell::new(body.len().saturating_mul(MAX_DEPTH + 1) + 1024);
    let seed = TypeSeed {
        types: &types,
        ty: &d.type_description,
        depth: 0,
        budget: body.len(),
        values: &values,
    };
    let out = match (head[0], head[1]) {
        (0, 1) => hiroz_cdr::from_bytes_with::<_, hiroz_cdr::LittleEndian>(body, seed),
        (0, 0) => hiroz_cdr::from_bytes_with::<_, hiroz_cdr::BigEndian>(body, seed),
        _ => return Err(format!("not plain CDR (header {:02x?})", &head[..2])),
    };
    out.map(|(v, _)| v).map_err(|e| {
        let text = e.to_string();
        ratelab_core::text::printable(text.lines().next().unwrap_or_default()).into_owned()
    })
}

/// [`decode`] for a message whose hash may be unknown (`hash` empty: a bag that names
/// none): then the type's name alone picks the description.
///
/// # Errors
/// As [`decode`].
pub fn decode_named(name: &str, hash: &str, payload: &[u8]) -> Result<Value, String> {
    if hash.is_empty() {
        let d = known().get(name).ok_or_else(|| NOT_DESCRIBED.to_string())?;
        decode(name, &d.hash.to_rihs_string(), payload)
    } else {
        decode(name, hash, payload)
    }
}

struct TypeSeed<'a> {
    types: &'a BTreeMap<&'a str, &'a TypeDescription>,
    ty: &'a TypeDescription,
    depth: usize,
    /// The payload's length: no sequence can hold more elements.
    budget: usize,
    /// The values the whole decode may still make.
    values: &'a std::cell::Cell<usize>,
}

/// Take one value of the decode's allowance `values`.
fn spend<E: serde::de::Error>(values: &std::cell::Cell<usize>) -> Result<(), E> {
    match values.get().checked_sub(1) {
        Some(left) => {
            values.set(left);
            Ok(())
        }
        None => Err(E::custom("more values than its bytes can hold")),
    }
}

impl<'de> DeserializeSeed<'de> for TypeSeed<'_> {
    type Value = Value;
    fn deserialize<D: Deserializer<'de>>(self, d: D) -> Result<Value, D::Error> {
        if self.depth > MAX_DEPTH {
            return Err(D::Error::custom("nested too deep"));
        }
        spend::<D::Error>(self.values)?;
        let n = self.ty.fields.len();
        d.deserialize_tuple(n, StructVisitor(self))
    }
}

struct StructVisitor<'a>(TypeSeed<'a>);

impl<'de> Visitor<'de> for StructVisitor<'_> {
    type Value = Value;
    fn expecting(&self, f: &mut fmt::Formatter) -> fmt::Result {
        write!(f, "a {}", self.0.ty.type_name)
    }
    fn visit_seq<A: SeqAccess<'de>>(self, mut seq: A) -> Result<Value, A::Error> {
        let s = &self.0;
        let mut out = Vec::with_capacity(s.ty.fields.len());
        for f in &s.ty.fields {
            let seed = FieldSeed {
                types: s.types,
                ft: &f.field_type,
                depth: s.depth,
                budget: s.budget,
                values: s.values,
            };
            let v = seq
                .next_element_seed(seed)?
                .ok_or_else(|| A::Error::custom(format!("no field {}", f.name)))?;
            out.push((f.name.clone(), v));
        }
        Ok(Value::Struct(out))
    }
}

/// One field: its type id says single, fixed array (capacity) or sequence.
#[derive(Clone, Copy)]
struct FieldSeed<'a> {
    types: &'a BTreeMap<&'a str, &'a TypeDescription>,
    ft: &'a FieldTypeDescription,
    depth: usize,
    budget: usize,
    values: &'a std::cell::Cell<usize>,
}

impl FieldSeed<'_> {
    /// The element's own type id (1–22) and how it repeats.
    fn shape(&self) -> (u8, Repeat) {
        let id = self.ft.type_id;
        match id {
            0..=48 => (id, Repeat::Once),
            49..=96 => (id - TypeId::ARRAY_OFFSET, Repeat::Fixed(self.ft.capacity)),
            97..=144 => (id - TypeId::BOUNDED_SEQUENCE_OFFSET, Repeat::Seq),
            _ => (id - TypeId::UNBOUNDED_SEQUENCE_OFFSET, Repeat::Seq),
        }
    }
}

#[derive(Clone, Copy)]
enum Repeat {
    Once,
    Fixed(u64),
    Seq,
}

impl<'de> DeserializeSeed<'de> for FieldSeed<'_> {
    type Value = Value;
    fn deserialize<D: Deserializer<'de>>(self, d: D) -> Result<Value, D::Error> {
        let (base, repeat) = self.shape();
        let one = One { seed: self, base };
        match repeat {
            Repeat::Once => one.deserialize(d),
            Repeat::Fixed(n) => {
                let n = usize::try_from(n)
                    .ok()
                    .filter(|n| *n <= self.budget)
                    .ok_or_else(|| D::Error::custom("an array longer than the message"))?;
                d.deserialize_tuple(n, ListVisitor(one, Some(n)))
            }
            Repeat::Seq => d.deserialize_seq(ListVisitor(one, None)),
        }
    }
}

/// One element of type `base`.
#[derive(Clone, Copy)]
struct One<'a> {
    seed: FieldSeed<'a>,
    base: u8,
}

impl<'de> DeserializeSeed<'de> for One<'_> {
    type Value = Value;
    fn deserialize<D: Deserializer<'de>>(self, d: D) -> Result<Value, D::Error> {
        use serde::Deserialize;
        use TypeId as T;
        if self.base != T::NESTED_TYPE {
            spend::<D::Error>(self.seed.values)?;
        }
        Ok(match self.base {
            T::NESTED_TYPE => {
                let name = self.seed.ft.nested_type_name.as_str();
                let ty = self
                    .seed
                    .types
                    .get(name)
                    .ok_or_else(|| D::Error::custom(format!("no description of {name}")))?;
                return TypeSeed {
                    types: self.seed.types,
                    ty,
                    depth: self.seed.depth + 1,
                    budget: self.seed.budget,
                    values: self.seed.values,
                }
                .deserialize(d);
            }
            T::INT8 => Value::Int(i8::deserialize(d)?.into()),
            T::UINT8 | T::BYTE => Value::UInt(u8::deserialize(d)?.into()),
            T::INT16 => Value::Int(i16::deserialize(d)?.into()),
            T::UINT16 => Value::UInt(u16::deserialize(d)?.into()),
            T::INT32 => Value::Int(i32::deserialize(d)?.into()),
            T::UINT32 => Value::UInt(u32::deserialize(d)?.into()),
            T::INT64 => Value::Int(i64::deserialize(d)?),
            T::UINT64 => Value::UInt(u64::deserialize(d)?),
            T::FLOAT32 => Value::Float(f32::deserialize(d)?.into()),
            T::FLOAT64 => Value::Float(f64::deserialize(d)?),
            T::BOOL => Value::Bool(bool::deserialize(d)?),
            T::STRING | T::BOUNDED_STRING => Value::Str(truncated(String::deserialize(d)?)),
            other => return Err(D::Error::custom(format!("type id {other} not decoded"))),
        })
    }
}

struct ListVisitor<'a>(One<'a>, Option<usize>);

impl<'de> Visitor<'de> for ListVisitor<'_> {
    type Value = Value;
    fn expecting(&self, f: &mut fmt::Formatter) -> fmt::Result {
        f.write_str("a list")
    }
    fn visit_seq<A: SeqAccess<'de>>(self, mut seq: A) -> Result<Value, A::Error> {
        let budget = self.0.seed.budget;
        let n = self.1.or(seq.size_hint()).unwrap_or(0);
        if n > budget {
            return Err(A::Error::custom("a sequence longer than the message"));
        }
        let mut out = Vec::with_capacity(n.min(TRUNCATE_LENGTH + 1));
        let mut seen = 0;
        while seen < budget {
            match seq.next_element_seed(self.0)? {
                // Past the truncation, elements are read (the bytes must be valid) but not kept.
                Some(v) if seen < TRUNCATE_LENGTH => out.push(v),
                Some(_) => {}
                None => break,
            }
            seen += 1;
            if self.1.is_some_and(|n| seen == n) {
                break;
            }
        }
        if seen > TRUNCATE_LENGTH {
            out.push(Value::Str("...".into()));
        }
        Ok(Value::List(out))
    }
}

/// `s` cut to [`TRUNCATE_LENGTH`] characters and `...`, when longer.
fn truncated(s: String) -> String {
    match s.char_indices().nth(TRUNCATE_LENGTH) {
        Some((at, _)) => format!("{}...", &s[..at]),
        None => s,
    }
}

impl serde::Serialize for Value {
    fn serialize<S: serde::Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        use serde::ser::{SerializeMap, SerializeSeq};
        match self {
            Value::Bool(b) => s.serialize_bool(*b),
            Value::Int(i) => s.serialize_i64(*i),
            Value::UInt(u) => s.serialize_u64(*u),
            Value::Float(f) => s.serialize_f64(*f),
            Value::Str(t) => s.serialize_str(t),
            Value::List(items) => {
                let mut seq = s.serialize_seq(Some(items.len()))?;
                for i in items {
                    seq.serialize_element(i)?;
                }
                seq.end()
            }
            Value::Struct(fields) => {
                let mut map = s.serialize_map(Some(fields.len()))?;
                for (k, v) in fields {
                    map.serialize_entry(k, v)?;
                }
                map.end()
            }
        }
    }
}

/// `v` as ros2cli's `topic echo` writes a message: YAML in block style (by `serde_yaml`,
/// which quotes a string that would read back as another value and escapes control
/// characters), ending in a newline, its floats as ros2cli writes them
/// ([`python_yaml_float`]: `1.0e-05`, where serde_yaml alone writes `1e-5`).
///
/// Each float goes to serde_yaml as a plain placeholder that no string or field name of
/// `v` contains, and each placeholder in its output is then replaced by the float as Python
/// and PyYAML write it.
pub fn yaml(v: &Value) -> String {
    let mut mark = String::from("ratelabfloat");
    while mentions(v, &mark) {
        mark.push('z');
    }
    let mut floats = Vec::new();
    let marked = with_marks(v, &mark, &mut floats);
    let out = match serde_yaml::to_string(&marked) {
        Ok(out) => out,
        Err(e) => return format!("<not written: {e}>\n"),
    };
    // `MARK<i>x`: the i-th float (the `x` ends the number).
    let mut written = String::with_capacity(out.len());
    let mut rest = out.as_str();
    while let Some(at) = rest.find(mark.as_str()) {
        written.push_str(&rest[..at]);
        let after = &rest[at + mark.len()..];
        let digits = after.find('x').unwrap_or(0);
        match after[..digits]
            .parse::<usize>()
            .ok()
            .and_then(|i| floats.get(i))
        {
            Some(&f) => {
                written.push_str(&python_yaml_float(f));
                rest = &after[digits + 1..];
            }
            None => {
                written.push_str(&mark);
                rest = after;
            }
        }
    }
    written.push_str(rest);
    written
}

/// Whether a string or field name of `v` contains `mark`.
fn mentions(v: &Value, mark: &str) -> bool {
    match v {
        Value::Str(t) => t.contains(mark),
        Value::List(items) => items.iter().any(|i| mentions(i, mark)),
        Value::Struct(fields) => fields
            .iter()
            .any(|(k, v)| k.contains(mark) || mentions(v, mark)),
        Value::Bool(_) | Value::Int(_) | Value::UInt(_) | Value::Float(_) => false,
    }
}

/// `v` with each float replaced by the string `MARK<i>x`, `i` its place in `floats`.
fn with_marks(v: &Value, mark: &str, floats: &mut Vec<f64>) -> Value {
    match v {
        Value::Float(f) => {
            floats.push(*f);
            Value::Str(format!("{mark}{}x", floats.len() - 1))
        }
        Value::List(items) => {
            Value::List(items.iter().map(|i| with_marks(i, mark, floats)).collect())
        }
        Value::Struct(fields) => Value::Struct(
            fields
                .iter()
                .map(|(k, v)| (k.clone(), with_marks(v, mark, floats)))
                .collect(),
        ),
        other => other.clone(),
    }
}

/// `x` as ros2cli's `topic echo` writes a float: Python's `repr` (the shortest digits
/// that read back to `x`; positional when its decimal point falls 4 places left of the
/// first digit or nearer, up to 16 digits left of the point; else scientific with a signed
/// exponent of at least two digits), then PyYAML's float representer (`.0` before the `e`
/// of a repr with no point; `.nan`, `.inf`, `-.inf`). So `1e-05` is `1.0e-05`, `1e16` is
/// `1.0e+16`, `0.0001` stays `0.0001` and `100.0` stays `100.0`.
pub fn python_yaml_float(x: f64) -> String {
    if x.is_nan() {
        return ".nan".into();
    }
    if x.is_infinite() {
        return if x > 0.0 { ".inf" } else { "-.inf" }.into();
    }
    // Rust's `{:e}` writes the shortest digits that read back, as Python's repr does.
    let sci = format!("{x:e}");
    let (mantissa, exponent) = sci.split_once('e').unwrap_or((&sci, "0"));
    let exponent: i32 = exponent.parse().unwrap_or(0);
    let (negative, mantissa) = match mantissa.strip_prefix('-') {
        Some(m) => (true, m),
        None => (false, mantissa),
    };
    let digits: String = mantissa.chars().filter(char::is_ascii_digit).collect();
    // The decimal point's place after the first digit, as CPython's `decpt` counts it.
    let point = exponent + 1;
    let body = if x == 0.0 {
        "0.0".to_string()
    } else if point <= -4 || point > 16 {
        let (first, rest) = digits.split_at(1);
        let sign = if exponent < 0 { '-' } else { '+' };
        // PyYAML: a repr with no point gets `.0` before its exponent.
        let rest = if rest.is_empty() { "0" } else { rest };
        format!("{first}.{rest}e{sign}{:02}", exponent.unsigned_abs())
    } else if point <= 0 {
        format!("0.{}{digits}", "0".repeat(point.unsigned_abs() as usize))
    } else if point as usize >= digits.len() {
        format!("{digits}{}.0", "0".repeat(point as usize - digits.len()))
    } else {
        let (whole, fraction) = digits.split_at(point as usize);
        format!("{whole}.{fraction}")
    };
    if negative {
        format!("-{body}")
    } else {
        body
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A description that would make a few bytes into millions of values (types of many
    /// fields of types of many fields, down to an empty one) is stopped by the allowance.
    #[test]
    fn a_description_cannot_multiply_a_few_bytes_into_millions_of_values() {
        let name = |k: usize| format!("evil/msg/T{k}");
        let mut types: Vec<TypeDescription> = (0..MAX_DEPTH)
            .map(|k| {
                let fields = (0..8)
                    .map(|f| nested(&format!("f{f}"), &name(k + 1)))
                    .collect();
                describe(&name(k), fields)
            })
            .collect();
        types.push(describe(&name(MAX_DEPTH), vec![]));
        let top = types.remove(0);
        let d = TypeDescriptionMsg {
            type_description: top,
            referenced_type_descriptions: types,
        };
        // Without the allowance this would make 8^16 values (and not return).
        let e = decode_with(&d, &[0, 1, 0, 0]).unwrap_err();
        assert!(e.contains("more values than its bytes can hold"), "{e}");
    }
    use ratelab_core::ros_types::{cdr, JointState};

    #[test]
    fn ratelab_s_own_types_are_described_as_the_core_describes_them() {
        for t in [
            ratelab_core::ros_types::joint_state_type(),
            ratelab_core::ros_types::float64_type(),
            ratelab_core::ros_types::clock_type(),
            ratelab_core::ros_types::image_type(),
        ] {
            assert_eq!(known()[t.name].hash, t.hash, "{}", t.name);
        }
    }

    #[test]
    fn a_joint_state_echoes_as_ros2cli_prints_it() {
        let js = JointState::of(
            ratelab_core::time::Nanos(1_500_000_000),
            vec![0.25, -0.5],
            vec![1.0, 0.0],
        );
        let mut bytes = Vec::new();
        cdr(&js, &mut bytes);
        let t = ratelab_core::ros_types::joint_state_type();
        let v = decode(t.name, &t.hash.to_rihs_string(), &bytes).unwrap();
        assert_eq!(
            yaml(&v),
            "header:\n  stamp:\n    sec: 1\n    nanosec: 500000000\n  frame_id: ''\nname:\n- slider\n- hinge\nposition:\n- 0.25\n- -0.5\nvelocity:\n- 1.0\n- 0.0\neffort: []\n"
        );
    }

    #[test]
    fn an_image_echoes_with_its_pixels_and_long_strings_cut_as_ros2cli_cuts_them() {
        use ratelab_core::ros_types::{Header, Image, Time};
        let img = Image {
            header: Header {
                stamp: Time { sec: 2, nanosec: 0 },
                frame_id: "é".repeat(130),
            },
            height: 2,
            width: 100,
            encoding: "mono8".into(),
            is_bigendian: 0,
            step: 100,
            data: (0..200u8).collect::<Vec<u8>>().into(),
        };
        let mut bytes = Vec::new();
        cdr(&img, &mut bytes);
        let t = ratelab_core::ros_types::image_type();
        let text = yaml(&decode(t.name, &t.hash.to_rihs_string(), &bytes).unwrap());
        let pixels: String = (0..128).map(|i| format!("- {i}\n")).collect();
        assert_eq!(
            text,
            format!(
                "header:\n  stamp:\n    sec: 2\n    nanosec: 0\n  frame_id: {}...\nheight: 2\nwidth: 100\nencoding: mono8\nis_bigendian: 0\nstep: 100\ndata:\n{pixels}- '...'\n",
                "é".repeat(128)
            )
        );
        // A list of exactly the length is whole.
        let img = Image {
            data: vec![7; 128].into(),
            ..img
        };
        cdr(&img, &mut bytes);
        let text = yaml(&decode(t.name, &t.hash.to_rihs_string(), &bytes).unwrap());
        assert!(text.ends_with("- 7\n") && !text.contains("'...'"), "{text}");
    }

    #[test]
    fn another_definition_a_short_payload_or_a_huge_sequence_is_refused_in_one_line() {
        let t = ratelab_core::ros_types::joint_state_type();
        let hash = t.hash.to_rihs_string();
        assert!(decode(t.name, "RIHS01_00", &[0, 1, 0, 0]).is_err());
        assert!(decode("pkg/msg/Unknown", &hash, &[0, 1, 0, 0]).is_err());
        assert!(decode(t.name, &hash, &[0, 1]).is_err());
        // A header, then a sequence (the frame id's length) claiming 4 GiB.
        let mut hostile = vec![0, 1, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0];
        hostile.extend_from_slice(&[0xff, 0xff, 0xff, 0xff]);
        let e = decode(t.name, &hash, &hostile).unwrap_err();
        assert!(!e.contains('\n'), "{e}");
        let names = {
            // A header, an empty frame id, then `name` claiming 2^31 strings.
            let mut b = vec![0, 1, 0, 0];
            b.extend_from_slice(&[0; 8]); // stamp
            b.extend_from_slice(&1u32.to_le_bytes()); // frame_id: "" (1 byte, the NUL)
            b.extend_from_slice(&[0, 0, 0, 0]); // NUL + padding
            b.extend_from_slice(&0x8000_0000u32.to_le_bytes());
            b
        };
        assert!(decode(t.name, &hash, &names).is_err());
    }

    #[test]
    fn strings_are_quoted_as_yaml_needs_and_never_raw() {
        let s = |x: &str| yaml(&Value::Struct(vec![("s".into(), Value::Str(x.into()))]));
        assert_eq!(s("base_link"), "s: base_link\n");
        assert_eq!(s(""), "s: ''\n");
        assert_eq!(s("1.5"), "s: '1.5'\n");
        assert_eq!(s("true"), "s: 'true'\n");
        assert!(!s("\x1b[2Jhi").contains('\x1b'), "{}", s("\x1b[2Jhi"));
        let f = |x: f64| yaml(&Value::Struct(vec![("f".into(), Value::Float(x))]));
        assert_eq!(f(1.0), "f: 1.0\n");
        assert_eq!(f(f64::from(0.1f32)), "f: 0.10000000149011612\n");
        assert_eq!(f(1e-5), "f: 1.0e-05\n");
    }

    /// Python 3's `yaml.dump` (PyYAML 6) of each value, as ros2cli's echo writes a float:
    /// the expected strings were printed by `python3 -c 'import yaml; print(yaml.dump(x))'`.
    #[test]
    fn floats_are_written_as_python_and_pyyaml_write_them() {
        let cases: &[(f64, &str)] = &[
            (0.0, "0.0"),
            (-0.0, "-0.0"),
            (1.0, "1.0"),
            (-0.5, "-0.5"),
            (100.0, "100.0"),
            (0.0001, "0.0001"),
            (0.00012345, "0.00012345"),
            (1e-5, "1.0e-05"),
            (-2.5e-7, "-2.5e-07"),
            (1.5e-300, "1.5e-300"),
            (1e15, "1000000000000000.0"),
            (1e16, "1.0e+16"),
            (1.2345678901234566e17, "1.2345678901234566e+17"),
            (123456.789, "123456.789"),
            (f64::from(0.1f32), "0.10000000149011612"),
            (f64::MAX, "1.7976931348623157e+308"),
            (f64::MIN_POSITIVE, "2.2250738585072014e-308"),
            (5e-324, "5.0e-324"),
            (f64::NAN, ".nan"),
            (f64::INFINITY, ".inf"),
            (f64::NEG_INFINITY, "-.inf"),
        ];
        for &(x, want) in cases {
            assert_eq!(python_yaml_float(x), want, "{x:e}");
        }
    }

    /// A string that looks like the floats' placeholder stays a string.
    #[test]
    fn a_string_like_the_float_placeholder_is_left_as_it_is() {
        let v = Value::Struct(vec![
            ("s".into(), Value::Str("ratelabfloat0x".into())),
            ("f".into(), Value::Float(1e-5)),
        ]);
        assert_eq!(yaml(&v), "s: ratelabfloat0x\nf: 1.0e-05\n");
    }
}
