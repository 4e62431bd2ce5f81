//! A `ros2msg` schema — the message definition a rosbag2 bag carries for each channel: the
//! type's `.msg` text, then each type it uses after a line of `=` and `MSG: pkg/Type` — read
//! as the type description [`super::echo`] decodes by ([`describe`]), so that `ratelab ros2
//! bag echo` decodes a type it has no description of from the bag's own definition, with
//! the one bounded decoder (`echo::decode_with`: its payload bound, value allowance and
//! depth limit).
//!
//! The text is parsed by rerun's `re_ros_msg` (`MessageSchema::parse`); what it gives is
//! mapped as rosidl maps a `.msg` file (`rosidl_adapter`): `char` is `uint8`, `byte` is
//! `byte` (IDL's `octet`), `string<=N` a bounded string, `T[N]` an array, `T[<=N]` a bounded
//! sequence, `T[]` a sequence; a type name without a package is the containing type's
//! package's; `pkg/Type` and `pkg/msg/Type` name the same type; a type of no fields gets
//! rosidl's one `uint8 structure_needs_at_least_one_member` (its one byte on the wire).
//! Constants and default values are not part of a description (nor of its RIHS01 hash).
//!
//! The text comes from a file, so it is untrusted: at most [`MAX_SCHEMA_BYTES`], UTF-8, a
//! panic of the parser caught and said; then every type name must be a ROS 2 message type's
//! (`pkg/msg/Type`, letters, digits and `_`), every type used defined once, no type may
//! contain itself, nesting at most [`super::echo::MAX_DEPTH`] deep, at most
//! [`MAX_DESCRIBED_TYPES`] types. A field ratelab does not decode (`wstring`) refuses the
//! schema. Every refusal is one line.

use hiroz_schema::{
    FieldDescription, FieldTypeDescription, TypeDescription, TypeDescriptionMsg, TypeId,
};
use ratelab_core::limits::{self, MAX_DESCRIBED_TYPES};
use re_ros_msg::message_spec::{ArraySize, BuiltInType, ComplexType, MessageSpecification, Type};
use std::collections::{BTreeMap, HashMap};

/// The longest `ros2msg` schema read (bytes): 1 MiB. rosbag2 writes a few KiB for a type
/// (`sensor_msgs/msg/PointCloud2` with every type it uses is under 4 KiB, comments and
/// all); a longer one is refused before it is parsed.
pub const MAX_SCHEMA_BYTES: usize = 1 << 20;

/// The member rosidl gives a type of no fields, so that it has one byte on the wire.
pub const PLACEHOLDER_FIELD: &str = "structure_needs_at_least_one_member";

/// The longest name written in a refusal (characters); a longer one is cut with `…`.
const SHOWN_NAME_CHARS: usize = 80;

/// Why a schema of `len` bytes is not read: over [`MAX_SCHEMA_BYTES`].
pub fn too_long(len: usize) -> String {
    format!(
        "the ros2msg schema is {len} bytes, more than ratelab reads (at most {MAX_SCHEMA_BYTES}, ratelab::ros2::msg_schema::MAX_SCHEMA_BYTES)"
    )
}

/// The description of type `type_name` (`pkg/msg/Type`, the name the bag gives the schema)
/// that the `ros2msg` schema `text` defines: the type, then every type it uses, once each,
/// sorted by name (as RIHS01 hashes them), ready for [`super::echo::decode_with`]. Types
/// the text defines and the type does not use are left out.
///
/// # Errors
/// One line, beginning "the ros2msg schema": it is over [`MAX_SCHEMA_BYTES`] or not UTF-8,
/// does not parse, names a type that is not a ROS 2 message type or that it does not define,
/// defines one twice or more than [`MAX_DESCRIBED_TYPES`], has a type that contains itself
/// or nests more than [`super::echo::MAX_DEPTH`] deep, or a field of a type ratelab does not
/// decode (`wstring`).
pub fn describe(type_name: &str, text: &[u8]) -> Result<TypeDescriptionMsg, String> {
    if text.len() > MAX_SCHEMA_BYTES {
        return Err(too_long(text.len()));
    }
    let text = std::str::from_utf8(text)
        .map_err(|e| format!("the ros2msg schema is not UTF-8 text ({e})"))?;
    let top = full_name(type_name, None).ok_or_else(|| not_a_type(type_name))?;
    let parsed = super::catching_panics(|| re_ros_msg::MessageSchema::parse(&top, text))
        .map_err(|why| {
            format!(
                "the ros2msg schema does not parse (its parser failed: {})",
                one_line(&why)
            )
        })?
        .map_err(|e| {
            format!(
                "the ros2msg schema does not parse: {}",
                one_line(&format!("{e:#}"))
            )
        })?;
    if parsed.dependencies.len() > MAX_DESCRIBED_TYPES {
        return Err(limits::refusal(
            format_args!(
                "the ros2msg schema defines {} types besides its own, more than ratelab reads",
                parsed.dependencies.len()
            ),
            "MAX_DESCRIBED_TYPES",
        ));
    }
    let mut defined: HashMap<String, &MessageSpecification> = HashMap::new();
    defined.insert(top.clone(), &parsed.spec);
    for dep in &parsed.dependencies {
        let name = full_name(&dep.name, None).ok_or_else(|| not_a_type(&dep.name))?;
        if defined.insert(name.clone(), dep).is_some() {
            return Err(format!(
                "the ros2msg schema defines '{}' twice",
                shown(&name)
            ));
        }
    }
    let mut used = used_types(&top, &defined)?;
    let mut heights = HashMap::new();
    nesting(&top, &used, &mut heights, &mut Vec::new())?;
    let type_description = used
        .remove(&top)
        .ok_or_else(|| format!("the ros2msg schema has no definition of '{}'", shown(&top)))?;
    Ok(TypeDescriptionMsg {
        type_description,
        referenced_type_descriptions: used.into_values().collect(),
    })
}

/// Every type `top` uses, itself included, described, by name: each must be in `defined`.
fn used_types(
    top: &str,
    defined: &HashMap<String, &MessageSpecification>,
) -> Result<BTreeMap<String, TypeDescription>, String> {
    let mut used: BTreeMap<String, TypeDescription> = BTreeMap::new();
    // (type, and who uses it: field and type, for a refusal's words)
    let mut todo: Vec<(String, Option<(String, String)>)> = vec![(top.to_string(), None)];
    while let Some((name, by)) = todo.pop() {
        if used.contains_key(&name) {
            continue;
        }
        let spec = defined.get(&name).ok_or_else(|| match &by {
            Some((field, of)) => format!(
                "the ros2msg schema has no definition of '{}' (field '{}' of '{}')",
                shown(&name),
                shown(field),
                shown(of)
            ),
            None => format!("the ros2msg schema has no definition of '{}'", shown(&name)),
        })?;
        let d = type_description(spec, &name)?;
        for f in &d.fields {
            let nested = &f.field_type.nested_type_name;
            if !nested.is_empty() && !used.contains_key(nested) {
                todo.push((nested.clone(), Some((f.name.clone(), name.clone()))));
            }
        }
        used.insert(name, d);
    }
    Ok(used)
}

/// How many levels of types `name` nests (itself 1), each type's found once (`heights`);
/// `path` the types that contain it, outermost first.
///
/// # Errors
/// A type that contains itself, or nesting deeper than the decoder walks.
fn nesting(
    name: &str,
    types: &BTreeMap<String, TypeDescription>,
    heights: &mut HashMap<String, usize>,
    path: &mut Vec<String>,
) -> Result<usize, String> {
    use super::echo::MAX_DEPTH;
    if let Some(h) = heights.get(name) {
        return Ok(*h);
    }
    if let Some(at) = path.iter().position(|p| p == name) {
        let cycle: Vec<String> = path[at..].iter().map(|p| shown(p)).collect();
        let name = shown(name);
        return Err(format!(
            "the ros2msg schema's type '{name}' contains itself ({} → {name}), which no ROS 2 type may",
            cycle.join(" → ")
        ));
    }
    if path.len() > MAX_DEPTH {
        return Err(format!(
            "the ros2msg schema nests types more than {MAX_DEPTH} deep (ratelab::ros2::echo::MAX_DEPTH)"
        ));
    }
    let Some(t) = types.get(name) else {
        return Ok(0);
    };
    path.push(name.to_string());
    let mut inner = 0;
    for f in &t.fields {
        let nested = &f.field_type.nested_type_name;
        if !nested.is_empty() {
            inner = inner.max(nesting(nested, types, heights, path)?);
        }
    }
    path.pop();
    heights.insert(name.to_string(), inner + 1);
    Ok(inner + 1)
}

/// The description of type `name` (full) that `spec` defines.
fn type_description(spec: &MessageSpecification, name: &str) -> Result<TypeDescription, String> {
    let package = name.split('/').next().unwrap_or_default();
    let mut fields = Vec::with_capacity(spec.fields.len().max(1));
    for f in &spec.fields {
        let field_type = field_type(&f.ty, package).map_err(|why| {
            format!(
                "the ros2msg schema's field '{}' of '{}' {why}",
                shown(&f.name),
                shown(name)
            )
        })?;
        fields.push(FieldDescription {
            name: f.name.clone(),
            field_type,
            default_value: String::new(),
        });
    }
    // rosidl's member of a type of no fields (constants only, or nothing at all).
    if fields.is_empty() {
        fields.push(FieldDescription {
            name: PLACEHOLDER_FIELD.to_string(),
            field_type: FieldTypeDescription::primitive(TypeId::UINT8),
            default_value: String::new(),
        });
    }
    Ok(TypeDescription {
        type_name: name.to_string(),
        fields,
    })
}

/// A field's type as `type_description_interfaces/msg/FieldType` has it; a nested type's
/// name relative to `package` made full. `Err`: why not, as a phrase after the field's name.
fn field_type(ty: &Type, package: &str) -> Result<FieldTypeDescription, String> {
    let (element, size) = match ty {
        Type::Array { ty, size } => (&**ty, Some(size)),
        other => (other, None),
    };
    let (id, string_capacity, nested_type_name) = match element {
        Type::BuiltIn(b) => {
            let (id, capacity) = built_in(b)?;
            (id, capacity, String::new())
        }
        Type::Complex(c) => (TypeId::NESTED_TYPE, 0, complex_name(c, package)?),
        Type::Array { .. } => return Err("is an array of arrays, which ROS 2 has not".into()),
    };
    let wide = |n: &usize| u64::try_from(*n).unwrap_or(u64::MAX);
    let (offset, capacity) = match size {
        None => (0, 0),
        Some(ArraySize::Fixed(n)) => (TypeId::ARRAY_OFFSET, wide(n)),
        Some(ArraySize::Bounded(n)) => (TypeId::BOUNDED_SEQUENCE_OFFSET, wide(n)),
        Some(ArraySize::Unbounded) => (TypeId::UNBOUNDED_SEQUENCE_OFFSET, 0),
    };
    Ok(FieldTypeDescription {
        type_id: id + offset,
        capacity,
        string_capacity,
        nested_type_name,
    })
}

/// A built-in type's id, and its string capacity (a bounded string's bound, else 0), as
/// rosidl describes a `.msg` field (`char` is `uint8`, `byte` IDL's `octet`).
fn built_in(b: &BuiltInType) -> Result<(u8, u64), String> {
    use TypeId as T;
    Ok(match b {
        BuiltInType::Bool => (T::BOOL, 0),
        BuiltInType::Byte => (T::BYTE, 0),
        BuiltInType::Char | BuiltInType::UInt8 => (T::UINT8, 0),
        BuiltInType::Int8 => (T::INT8, 0),
        BuiltInType::Int16 => (T::INT16, 0),
        BuiltInType::UInt16 => (T::UINT16, 0),
        BuiltInType::Int32 => (T::INT32, 0),
        BuiltInType::UInt32 => (T::UINT32, 0),
        BuiltInType::Int64 => (T::INT64, 0),
        BuiltInType::UInt64 => (T::UINT64, 0),
        BuiltInType::Float32 => (T::FLOAT32, 0),
        BuiltInType::Float64 => (T::FLOAT64, 0),
        BuiltInType::String(None) => (T::STRING, 0),
        BuiltInType::String(Some(n)) => (T::BOUNDED_STRING, u64::try_from(*n).unwrap_or(u64::MAX)),
        BuiltInType::WString(_) => return Err("is a wstring, which ratelab does not decode".into()),
    })
}

/// A nested type's full name: `pkg/msg/Type` of `pkg/Type` or `pkg/msg/Type`, or of `Type`
/// in `package`.
fn complex_name(c: &ComplexType, package: &str) -> Result<String, String> {
    let (written, relative_to) = match c {
        ComplexType::Absolute { package, name } => (format!("{package}/{name}"), None),
        ComplexType::Relative { name } => (name.clone(), Some(package)),
    };
    full_name(&written, relative_to).ok_or_else(|| {
        format!(
            "names a type that is not a ROS 2 message type ('{}')",
            shown(&written)
        )
    })
}

/// Why a type named `name` is refused: not a ROS 2 message type's name.
fn not_a_type(name: &str) -> String {
    format!(
        "the ros2msg schema names a type that is not a ROS 2 message type ('{}')",
        shown(name)
    )
}

/// `pkg/msg/Type` of a name written `pkg/msg/Type` or `pkg/Type`, or `Type` in `package`;
/// `None` for a name that is not a ROS 2 message type's (parts of letters, digits and `_`,
/// each beginning with a letter).
fn full_name(name: &str, package: Option<&str>) -> Option<String> {
    let part = |s: &str| {
        s.chars().next().is_some_and(|c| c.is_ascii_alphabetic())
            && s.chars().all(|c| c.is_ascii_alphanumeric() || c == '_')
    };
    let parts: Vec<&str> = name.splitn(4, '/').collect();
    let (pkg, ty) = match (parts.as_slice(), package) {
        ([pkg, "msg", ty], _) | ([pkg, ty], _) => (*pkg, *ty),
        ([ty], Some(pkg)) => (pkg, *ty),
        _ => ("", ""),
    };
    (part(pkg) && part(ty)).then(|| format!("{pkg}/msg/{ty}"))
}

/// `name` as a refusal writes it: control characters written out, at most
/// [`SHOWN_NAME_CHARS`] characters.
fn shown(name: &str) -> String {
    let cut: String = name.chars().take(SHOWN_NAME_CHARS).collect();
    let more = if cut.len() < name.len() { "…" } else { "" };
    format!("{}{more}", ratelab_core::text::printable(&cut))
}

/// The first line of `text`, its control characters written out, at most 300 characters.
fn one_line(text: &str) -> String {
    let line = text.lines().next().unwrap_or_default();
    let cut: String = line.chars().take(300).collect();
    let more = if cut.len() < line.len() { "…" } else { "" };
    format!("{}{more}", ratelab_core::text::printable(&cut))
}

#[cfg(test)]
mod tests {
    use super::*;
    use hiroz_schema::TypeId as T;

    /// rosbag2's schema of a made-up type: comments, a constant, a relative and an absolute
    /// nested type, arrays of each kind, a bounded string and a `char`.
    const READING: &str = "# A reading.\nuint8 KIND_A=1 # a constant: not a field\n\nfloat64 x\nstring label\nint32[] counts\ngeometry_msgs/Vector3 v\nPart[<=4] parts\nbool[2] flags\nstring<=8 tag \"none\"\nchar c\nbyte b\n================================================================================\nMSG: geometry_msgs/Vector3\n# This represents a vector in free space.\nfloat64 x\nfloat64 y\nfloat64 z\n================================================================================\nMSG: my_pkg/msg/Part\nstring name\nfloat32 w\n";

    fn kinds(t: &TypeDescription) -> Vec<(&str, u8, u64, u64, &str)> {
        t.fields
            .iter()
            .map(|f| {
                let ft = &f.field_type;
                (
                    f.name.as_str(),
                    ft.type_id,
                    ft.capacity,
                    ft.string_capacity,
                    ft.nested_type_name.as_str(),
                )
            })
            .collect()
    }

    #[test]
    fn a_schema_becomes_the_description_rosidl_gives_its_msg_file() {
        let d = describe("my_pkg/msg/Reading", READING.as_bytes()).unwrap();
        assert_eq!(d.type_description.type_name, "my_pkg/msg/Reading");
        assert_eq!(
            kinds(&d.type_description),
            [
                ("x", T::FLOAT64, 0, 0, ""),
                ("label", T::STRING, 0, 0, ""),
                ("counts", T::INT32 + T::UNBOUNDED_SEQUENCE_OFFSET, 0, 0, ""),
                ("v", T::NESTED_TYPE, 0, 0, "geometry_msgs/msg/Vector3"),
                (
                    "parts",
                    T::NESTED_TYPE + T::BOUNDED_SEQUENCE_OFFSET,
                    4,
                    0,
                    "my_pkg/msg/Part"
                ),
                ("flags", T::BOOL + T::ARRAY_OFFSET, 2, 0, ""),
                ("tag", T::BOUNDED_STRING, 0, 8, ""),
                ("c", T::UINT8, 0, 0, ""),
                ("b", T::BYTE, 0, 0, ""),
            ]
        );
        let names: Vec<&str> = d
            .referenced_type_descriptions
            .iter()
            .map(|t| t.type_name.as_str())
            .collect();
        assert_eq!(names, ["geometry_msgs/msg/Vector3", "my_pkg/msg/Part"]);
        // A known type's schema (as rosbags writes it) gives the very description, and so
        // the hash, ratelab has of it.
        let js = ratelab_core::ros_types::joint_state_type();
        let text = "std_msgs/Header header\nstring[] name\nfloat64[] position\nfloat64[] velocity\nfloat64[] effort\n================================================================================\nMSG: std_msgs/Header\nbuiltin_interfaces/Time stamp\nstring frame_id\n================================================================================\nMSG: builtin_interfaces/Time\nint32 sec\nuint32 nanosec\n";
        let d = describe(js.name, text.as_bytes()).unwrap();
        assert_eq!(hiroz_schema::calculate_hash(&d), js.hash);
        // A type of constants only, or of nothing, has rosidl's one member.
        let d = describe("my_pkg/Mode", b"uint8 IDLE=0\nuint8 RUN=1\n").unwrap();
        assert_eq!(d.type_description.type_name, "my_pkg/msg/Mode");
        assert_eq!(
            kinds(&d.type_description),
            [(PLACEHOLDER_FIELD, T::UINT8, 0, 0, "")]
        );
        let d = describe("my_pkg/msg/Empty", b"# nothing\n").unwrap();
        assert_eq!(d.type_description.fields.len(), 1);
    }

    /// A message decodes by what a schema describes, as the one decoder decodes any.
    #[test]
    fn a_message_decodes_by_its_schema() {
        let d = describe("my_pkg/msg/Small", b"float64 x\nint32[] counts\nstring s\n").unwrap();
        let mut b = vec![0, 1, 0, 0];
        b.extend_from_slice(&1.5f64.to_le_bytes());
        b.extend_from_slice(&2u32.to_le_bytes());
        b.extend_from_slice(&7i32.to_le_bytes());
        b.extend_from_slice(&(-1i32).to_le_bytes());
        b.extend_from_slice(&3u32.to_le_bytes());
        b.extend_from_slice(b"hi\0");
        let v = crate::echo::decode_with(&d, &b).unwrap();
        assert_eq!(crate::echo::yaml(&v), "x: 1.5\ncounts:\n- 7\n- -1\ns: hi\n");
    }

    /// Hostile or broken schemas are refused in one line, never a panic nor a hang.
    #[test]
    fn a_hostile_schema_is_refused_in_one_line() {
        let refused = |name: &str, text: &[u8], why: &str| {
            let e = describe(name, text).unwrap_err();
            assert!(e.contains(why), "{e}");
            assert!(e.starts_with("the ros2msg schema"), "{e}");
            assert!(!e.contains('\n') && e.len() < 600, "{e}");
        };
        let t = "my_pkg/msg/T";
        // Too long: refused before it is parsed.
        refused(t, &vec![b'#'; MAX_SCHEMA_BYTES + 1], "MAX_SCHEMA_BYTES");
        refused(t, b"float64 x\n\xff\xfe", "not UTF-8");
        // Garbage, and a default the parser itself panics on (`"` alone).
        refused(t, b"\x1b[2J garbage ( ) [ ]\n", "does not parse");
        refused(t, b"int32[][] x\n", "does not parse");
        // (re_ros_msg 0.36 slices `&s[1..0]` there; a later one may read it as a string.)
        if let Err(e) = describe(t, b"string s \"\n") {
            assert!(
                e.starts_with("the ros2msg schema does not parse") && !e.contains('\n'),
                "{e}"
            );
        }
        refused(
            "not a type name",
            b"float64 x\n",
            "not a ROS 2 message type",
        );
        refused(t, b"../../etc/passwd x\n", "not a ROS 2 message type");
        // A type used and not defined; one defined twice.
        refused(
            t,
            b"other_pkg/Thing v\n",
            "no definition of 'other_pkg/msg/Thing' (field 'v' of 'my_pkg/msg/T')",
        );
        let twice = format!(
            "Part p\n{sep}\nMSG: my_pkg/Part\nint8 a\n{sep}\nMSG: my_pkg/msg/Part\nint8 b\n",
            sep = "=".repeat(80)
        );
        refused(t, twice.as_bytes(), "defines 'my_pkg/msg/Part' twice");
        // A type naming itself, directly or through another.
        refused(
            t,
            b"T inner\n",
            "contains itself (my_pkg/msg/T → my_pkg/msg/T)",
        );
        refused(t, b"T[] children\n", "contains itself");
        let cycle = format!(
            "A a\n{sep}\nMSG: my_pkg/A\nB b\n{sep}\nMSG: my_pkg/B\nA a\n",
            sep = "=".repeat(80)
        );
        refused(t, cycle.as_bytes(), "contains itself");
        // Deeper than the decoder walks (it walks `t` at depth 0 and L<k> at k + 1, at most
        // MAX_DEPTH): a chain to L<MAX_DEPTH> is refused, one to L<MAX_DEPTH - 1> is not.
        let chain = |last: usize| {
            let types: String = (0..=last)
                .map(|k| {
                    let body = if k == last {
                        "int8 end".to_string()
                    } else {
                        format!("L{} next", k + 1)
                    };
                    format!("{}\nMSG: my_pkg/L{k}\n{body}\n", "=".repeat(80))
                })
                .collect();
            format!("L0 top\n{types}")
        };
        let max = crate::echo::MAX_DEPTH;
        refused(t, chain(max).as_bytes(), "nests types more than 16 deep");
        let d = describe(t, chain(max - 1).as_bytes()).unwrap();
        assert_eq!(d.referenced_type_descriptions.len(), max);
        let v = crate::echo::decode_with(&d, &[0, 1, 0, 0, 5]).unwrap();
        assert!(crate::echo::yaml(&v).contains("end: 5"), "{v:?}");
        // Too many types, and a field ratelab does not decode.
        let many: String = (0..=MAX_DESCRIBED_TYPES)
            .map(|k| format!("{}\nMSG: my_pkg/M{k}\nint8 a\n", "=".repeat(80)))
            .collect();
        refused(
            t,
            format!("int8 a\n{many}").as_bytes(),
            "MAX_DESCRIBED_TYPES",
        );
        refused(
            t,
            b"wstring w\n",
            "field 'w' of 'my_pkg/msg/T' is a wstring",
        );
    }

    /// Many types each using the next twice over (a diamond chain) are walked once each.
    #[test]
    fn shared_types_are_walked_once() {
        let chain: String = (0..crate::echo::MAX_DEPTH - 1)
            .map(|k| {
                format!(
                    "{}\nMSG: my_pkg/D{k}\n{}",
                    "=".repeat(80),
                    (0..64)
                        .map(|f| format!("D{} f{f}\n", k + 1))
                        .collect::<String>()
                )
            })
            .collect();
        let text = format!(
            "D0 a\nD0 b\n{chain}{}\nMSG: my_pkg/D{}\nint8 end\n",
            "=".repeat(80),
            crate::echo::MAX_DEPTH - 1
        );
        let d = describe("my_pkg/msg/Top", text.as_bytes()).unwrap();
        assert_eq!(d.referenced_type_descriptions.len(), crate::echo::MAX_DEPTH);
    }
}
