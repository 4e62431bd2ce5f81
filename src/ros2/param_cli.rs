//! `ratelab ros2 param list [NODE]` and `ratelab ros2 param get NODE NAME`: any ROS 2
//! node's parameters (ratelab's own `--ros2` runs' and real nodes' over rmw_zenoh), asked
//! of its parameter services as ros2cli's `ros2 param` asks them, printed as it prints
//! them:
//!
//! ```text
//! $ ratelab ros2 param list            $ ratelab ros2 param get /policy rate_hz
//! /policy:                             Double value is: 50.0
//!   rate_hz
//!   use_sim_time
//! ```
//!
//! A call is a Zenoh get on the service's key (`<domain>/<node>/<service>/<type>/<hash>`)
//! with the CDR request and rmw_zenoh's attachment (sequence number, timestamp, the
//! client's GID), as rmw_zenoh_cpp's clients call; the reply is bounded before it is
//! decoded.

use super::rcl_interfaces::{
    parameter_type as pt, GetParametersResponse, ListParametersRequest, ListParametersResponse,
    NamesRequest, ParameterService, ParameterValue, ServiceType,
};
use super::wire::{attachment, wall_ns};
use super::{zerr, Ros2Error};
use ratelab_core::limits::{self, MAX_SERVICE_REPLY_BYTES};
use ratelab_core::ros_types::{cdr, from_cdr};
use std::time::Duration;
use zenoh::Wait;

/// Ask node `node` (`/policy`) on `domain` its service of type `service` with `request`,
/// waiting at most `timeout`: the response's CDR (header included).
///
/// # Errors
/// [`Ros2Error::Usage`] when no server answered within `timeout` (as ros2cli, which then
/// says the service is not available) or the answer passes [`MAX_SERVICE_REPLY_BYTES`]
/// (checked before a byte of it is copied or decoded); [`Ros2Error::Zenoh`]
/// when the get failed.
pub fn call<T: serde::Serialize>(
    session: &zenoh::Session,
    domain: u32,
    node: &str,
    service: ServiceType,
    request: &T,
    timeout: Duration,
) -> Result<Vec<u8>, Ros2Error> {
    let info = super::rcl_interfaces::type_info(service.type_name, service.hash);
    let key = format!(
        "{domain}/{}/{}/{}/{}",
        node.trim_start_matches('/'),
        service.suffix,
        info.name,
        service.hash
    );
    let mut payload = Vec::new();
    cdr(request, &mut payload);
    // The client's GID: this session's, as a real client's is its endpoint's.
    let gid = xxhash_rust::xxh3::xxh3_128(session.zid().to_string().as_bytes()).to_le_bytes();
    let replies = session
        .get(key.as_str())
        .payload(payload)
        .attachment(attachment(1, wall_ns(), &gid).to_vec())
        .timeout(timeout)
        .wait()
        .map_err(zerr)?;
    while let Ok(reply) = replies.recv() {
        let Ok(sample) = reply.result() else { continue };
        let bytes = sample.payload();
        if bytes.len() > MAX_SERVICE_REPLY_BYTES {
            return Err(Ros2Error::Usage(limits::refusal(
                format_args!(
                    "{}: its {} answered {} bytes; a reply is read up to {MAX_SERVICE_REPLY_BYTES}",
                    ratelab_core::text::printable(node),
                    service.suffix,
                    bytes.len()
                ),
                "MAX_SERVICE_REPLY_BYTES",
            )));
        }
        return Ok(bytes.to_bytes().into_owned());
    }
    Err(Ros2Error::Usage(format!(
        "node {} did not answer its {} within {:.1} s",
        ratelab_core::text::printable(node),
        service.suffix,
        timeout.as_secs_f64()
    )))
}

/// `node`'s parameter names, sorted (`list_parameters`, every level).
///
/// # Errors
/// [`call`]'s, or one line when the answer is not `ListParameters`' response.
pub fn list(
    session: &zenoh::Session,
    domain: u32,
    node: &str,
    timeout: Duration,
) -> Result<Vec<String>, Ros2Error> {
    let req = ListParametersRequest::default();
    let service = ParameterService::List.service_type();
    let bytes = call(session, domain, node, service, &req, timeout)?;
    let r: ListParametersResponse = from_cdr(&bytes, MAX_SERVICE_REPLY_BYTES)
        .map_err(|e| Ros2Error::Usage(format!("{node}: list_parameters answered {e}")))?;
    let mut names = r.result.names;
    names.sort();
    Ok(names)
}

/// `node`'s parameter `name` (`get_parameters`): `None` when the node has no such
/// parameter.
///
/// # Errors
/// [`call`]'s, or one line when the answer is not `GetParameters`' response.
pub fn get(
    session: &zenoh::Session,
    domain: u32,
    node: &str,
    name: &str,
    timeout: Duration,
) -> Result<Option<ParameterValue>, Ros2Error> {
    let req = NamesRequest {
        names: vec![name.to_string()],
    };
    let service = ParameterService::Get.service_type();
    let bytes = call(session, domain, node, service, &req, timeout)?;
    let r: GetParametersResponse = from_cdr(&bytes, MAX_SERVICE_REPLY_BYTES)
        .map_err(|e| Ros2Error::Usage(format!("{node}: get_parameters answered {e}")))?;
    Ok(r.values.into_iter().next())
}

/// YAML 1.1's boolean words, which PyYAML (ros2cli's reader) takes as booleans.
fn yaml11_bool(s: &str) -> Option<bool> {
    match s {
        "yes" | "Yes" | "YES" | "on" | "On" | "ON" | "true" | "True" | "TRUE" => Some(true),
        "no" | "No" | "NO" | "off" | "Off" | "OFF" | "false" | "False" | "FALSE" => Some(false),
        _ => None,
    }
}

/// A value as `ros2 param set` reads it from the command line (ros2cli's
/// `get_parameter_value`: PyYAML, YAML 1.1): `20` an INTEGER, `20.0` a DOUBLE (a float has a
/// point: `1e3` is text), `true` or `yes` a BOOL, a list of one kind an array of it (`[]` a
/// BOOL_ARRAY), anything else (text, a map, a mixed list) a STRING of the text as given.
///
/// # Errors
/// One line for an integer out of `int64`'s range, or a value nested deeper than
/// [`crate::yaml_depth::MAX_YAML_DEPTH`] (refused before YAML's parser reads it).
pub fn value_from_text(text: &str) -> Result<ParameterValue, String> {
    use serde_yaml::Value as Y;
    let mut v = ParameterValue {
        type_: pt::STRING,
        string_value: text.to_string(),
        ..ParameterValue::default()
    };
    crate::yaml_depth::check(text.as_bytes())?;
    let y: Y = serde_yaml::from_str(text).unwrap_or(Y::Null);
    let float_text = text.contains('.') || text.to_ascii_lowercase().contains("inf");
    match y {
        Y::Bool(b) => (v.type_, v.bool_value) = (pt::BOOL, b),
        Y::String(s) if yaml11_bool(&s).is_some() => {
            (v.type_, v.bool_value) = (pt::BOOL, yaml11_bool(&s).unwrap_or_default());
        }
        Y::Number(n) if n.is_i64() => {
            (v.type_, v.integer_value) = (pt::INTEGER, n.as_i64().unwrap_or_default());
        }
        Y::Number(n) if n.is_u64() => return Err(format!("{text}: out of int64's range")),
        Y::Number(n) if float_text => {
            (v.type_, v.double_value) = (pt::DOUBLE, n.as_f64().unwrap_or(f64::NAN));
        }
        Y::Sequence(items) => {
            let bool_of = |y: &Y| y.as_bool().or_else(|| y.as_str().and_then(yaml11_bool));
            let all = |f: &dyn Fn(&Y) -> bool| items.iter().all(f);
            if all(&|y| bool_of(y).is_some()) {
                v.type_ = pt::BOOL_ARRAY;
                v.bool_array_value = items.iter().filter_map(bool_of).collect();
            } else if all(&|y| y.is_i64()) {
                v.type_ = pt::INTEGER_ARRAY;
                v.integer_array_value = items.iter().filter_map(Y::as_i64).collect();
            } else if all(&|y| y.is_f64() && !y.is_i64() && !y.is_u64()) {
                v.type_ = pt::DOUBLE_ARRAY;
                v.double_array_value = items.iter().filter_map(Y::as_f64).collect();
            } else if all(&|y| y.is_string()) {
                v.type_ = pt::STRING_ARRAY;
                v.string_array_value = items
                    .iter()
                    .filter_map(|y| y.as_str().map(str::to_string))
                    .collect();
            }
            if v.type_ != pt::STRING {
                v.string_value.clear();
            }
        }
        _ => {}
    }
    if v.type_ != pt::STRING {
        v.string_value.clear();
    }
    Ok(v)
}

/// What a node answered `ros2 param set` (ros2param's `verb/set.py`).
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum SetAnswer {
    /// Set: `Set parameter successful` (`: REASON` when the node gave one), for stdout.
    Set(String),
    /// Refused by the node: `Setting parameter failed` (`: REASON` when it gave one), for
    /// stderr. Not an error of the command: ros2cli prints it and exits 0.
    Refused(String),
}

/// `node`'s parameter `name` set to `value` (`set_parameters`), and what `ros2 param set`
/// prints of the node's answer ([`SetAnswer`]).
///
/// # Errors
/// [`call`]'s; an answer that is not `set_parameters`' CDR, or holds no result.
pub fn set(
    session: &zenoh::Session,
    domain: u32,
    (node, name): (&str, &str),
    value: ParameterValue,
    timeout: Duration,
) -> Result<SetAnswer, Ros2Error> {
    use super::rcl_interfaces::{Parameter, SetParametersResponse, SetRequest};
    let req = SetRequest {
        parameters: vec![Parameter {
            name: name.to_string(),
            value,
        }],
    };
    let service = ParameterService::Set.service_type();
    let bytes = call(session, domain, node, service, &req, timeout)?;
    let r: SetParametersResponse = from_cdr(&bytes, MAX_SERVICE_REPLY_BYTES)
        .map_err(|e| Ros2Error::Usage(format!("{node}: set_parameters answered {e}")))?;
    let with = |what: &str, reason: &str| {
        if reason.is_empty() {
            what.to_string()
        } else {
            format!("{what}: {}", ratelab_core::text::printable(reason))
        }
    };
    match r.results.first() {
        Some(res) if res.successful => Ok(SetAnswer::Set(with(
            "Set parameter successful",
            &res.reason,
        ))),
        Some(res) => Ok(SetAnswer::Refused(with(
            "Setting parameter failed",
            &res.reason,
        ))),
        None => Err(Ros2Error::Usage(format!(
            "{}: set_parameters answered no result",
            ratelab_core::text::printable(node)
        ))),
    }
}

/// `x` as Python's `repr` writes it (`50.0`, `1e-05`, `nan`), which `ros2 param get`
/// prints.
fn python_float(x: f64) -> String {
    match super::echo::python_yaml_float(x).as_str() {
        ".nan" => "nan".into(),
        ".inf" => "inf".into(),
        "-.inf" => "-inf".into(),
        // PyYAML writes `1.0e-05` where repr writes `1e-05`.
        s => s.replacen(".0e", "e", 1),
    }
}

fn python_bool(b: bool) -> &'static str {
    if b {
        "True"
    } else {
        "False"
    }
}

/// A Python string literal as `repr` writes it (single quotes unless the text has one and
/// no double quote; backslashes doubled), control characters written out.
pub(crate) fn python_str(s: &str) -> String {
    let text = ratelab_core::text::printable(s).replace('\\', "\\\\");
    if text.contains('\'') && !text.contains('"') {
        format!("\"{text}\"")
    } else {
        format!("'{}'", text.replace('\'', "\\'"))
    }
}

/// One byte as Python's `repr` of a one-byte `bytes` writes it: `b'A'`, `b'\x00'`, `b'\n'`,
/// `b"'"` (rclpy gives a `byte[]` parameter as a list of them).
fn python_byte(b: u8) -> String {
    match b {
        b'\'' => "b\"'\"".into(),
        b'\\' => "b'\\\\'".into(),
        b'\t' => "b'\\t'".into(),
        b'\n' => "b'\\n'".into(),
        b'\r' => "b'\\r'".into(),
        0x20..=0x7e => format!("b'{}'", b as char),
        _ => format!("b'\\x{b:02x}'"),
    }
}

/// What `ros2 param get` prints of `value` (Jazzy and later): `Double value is: 50.0`,
/// `Integer values are: [1, 2]`, `Parameter not set.` for a value of no type.
///
/// # Errors
/// `Parameter not set` when the node has no such parameter (`value` is `None`), as
/// ros2cli says it.
pub fn get_text(value: Option<&ParameterValue>) -> Result<String, String> {
    let Some(v) = value else {
        return Err("Parameter not set".into());
    };
    let join = |items: Vec<String>| items.join(", ");
    let (label, shown) = match v.type_ {
        pt::BOOL => ("Boolean value is:", python_bool(v.bool_value).to_string()),
        pt::INTEGER => ("Integer value is:", v.integer_value.to_string()),
        pt::DOUBLE => ("Double value is:", python_float(v.double_value)),
        pt::STRING => (
            "String value is:",
            ratelab_core::text::printable(&v.string_value).into(),
        ),
        pt::BYTE_ARRAY => (
            "Byte values are:",
            format!(
                "[{}]",
                join(v.byte_array_value.iter().map(|b| python_byte(*b)).collect())
            ),
        ),
        pt::BOOL_ARRAY => (
            "Boolean values are:",
            format!(
                "[{}]",
                join(
                    v.bool_array_value
                        .iter()
                        .map(|b| python_bool(*b).into())
                        .collect()
                )
            ),
        ),
        pt::INTEGER_ARRAY => (
            "Integer values are:",
            format!(
                "[{}]",
                join(v.integer_array_value.iter().map(i64::to_string).collect())
            ),
        ),
        pt::DOUBLE_ARRAY => (
            "Double values are:",
            format!(
                "[{}]",
                join(
                    v.double_array_value
                        .iter()
                        .map(|x| python_float(*x))
                        .collect()
                )
            ),
        ),
        pt::STRING_ARRAY => (
            "String values are:",
            format!(
                "[{}]",
                join(v.string_array_value.iter().map(|s| python_str(s)).collect())
            ),
        ),
        pt::NOT_SET => return Ok("Parameter not set.\n".into()),
        other => return Err(format!("Unknown parameter type '{other}'")),
    };
    Ok(format!("{label} {shown}\n"))
}

/// What `ros2 param list` prints: each node's names, two spaces in, under its name and a
/// colon when more than the one node asked for is listed (`header`) and it has names.
pub fn list_text(node: &str, names: &[String], header: bool) -> String {
    let mut out = if header && !names.is_empty() {
        format!("{}:\n", ratelab_core::text::printable(node))
    } else {
        String::new()
    };
    for n in names {
        out.push_str(&format!("  {}\n", ratelab_core::text::printable(n)));
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    fn value(type_: u8, f: impl FnOnce(&mut ParameterValue)) -> ParameterValue {
        let mut v = ParameterValue {
            type_,
            ..ParameterValue::default()
        };
        f(&mut v);
        v
    }

    #[test]
    fn get_prints_as_ros2_param_get() {
        let cases = [
            (
                value(pt::DOUBLE, |v| v.double_value = 50.0),
                "Double value is: 50.0\n",
            ),
            (
                value(pt::DOUBLE, |v| v.double_value = 1e-5),
                "Double value is: 1e-05\n",
            ),
            (
                value(pt::BOOL, |v| v.bool_value = true),
                "Boolean value is: True\n",
            ),
            (
                value(pt::INTEGER, |v| v.integer_value = -7),
                "Integer value is: -7\n",
            ),
            (
                value(pt::STRING, |v| v.string_value = "calm".into()),
                "String value is: calm\n",
            ),
            (
                value(pt::INTEGER_ARRAY, |v| v.integer_array_value = vec![1, 2]),
                "Integer values are: [1, 2]\n",
            ),
            (
                value(pt::DOUBLE_ARRAY, |v| v.double_array_value = vec![1.0, 2.5]),
                "Double values are: [1.0, 2.5]\n",
            ),
            (
                value(pt::STRING_ARRAY, |v| {
                    v.string_array_value = vec!["a".into(), "it's".into()]
                }),
                "String values are: ['a', \"it's\"]\n",
            ),
            (
                value(pt::BOOL_ARRAY, |v| v.bool_array_value = vec![true, false]),
                "Boolean values are: [True, False]\n",
            ),
            (value(pt::NOT_SET, |_| {}), "Parameter not set.\n"),
            (
                value(pt::BYTE_ARRAY, |v| {
                    v.byte_array_value = vec![b'A', 0, b'\'', b'\\']
                }),
                "Byte values are: [b'A', b'\\x00', b\"'\", b'\\\\']\n",
            ),
            (
                value(pt::STRING_ARRAY, |v| {
                    v.string_array_value = vec!["a\\b".into()]
                }),
                "String values are: ['a\\\\b']\n",
            ),
        ];
        for (v, want) in cases {
            assert_eq!(get_text(Some(&v)).as_deref(), Ok(want));
        }
        assert_eq!(get_text(None), Err("Parameter not set".into()));
        let odd = value(42, |_| {});
        assert_eq!(
            get_text(Some(&odd)),
            Err("Unknown parameter type '42'".into())
        );
    }

    #[test]
    fn a_value_is_read_as_ros2_param_set_reads_it() {
        let ty = |t: &str| value_from_text(t).map(|v| v.type_);
        assert_eq!(ty("20"), Ok(pt::INTEGER));
        assert_eq!(ty("20.0"), Ok(pt::DOUBLE));
        assert_eq!(ty("true"), Ok(pt::BOOL));
        assert_eq!(ty("yes"), Ok(pt::BOOL), "YAML 1.1, as PyYAML");
        assert_eq!(ty("calm"), Ok(pt::STRING));
        assert_eq!(ty("1e3"), Ok(pt::STRING), "PyYAML's floats have a point");
        assert_eq!(ty("[1, 2]"), Ok(pt::INTEGER_ARRAY));
        assert_eq!(ty("[1.5, 2.5]"), Ok(pt::DOUBLE_ARRAY));
        assert_eq!(ty("[a, b]"), Ok(pt::STRING_ARRAY));
        assert_eq!(
            ty("[]"),
            Ok(pt::BOOL_ARRAY),
            "ros2cli tests for booleans first"
        );
        // A mixed list, a map: the text as a STRING, as ros2cli gives it.
        for text in ["[1.5, 2]", "{a: 1}", "[1, [2]]"] {
            let v = value_from_text(text).unwrap();
            assert_eq!((v.type_, v.string_value.as_str()), (pt::STRING, text));
        }
        assert!(value_from_text("18446744073709551615").is_err());
        assert_eq!(value_from_text("20.5").unwrap().double_value, 20.5);
    }

    #[test]
    fn list_prints_as_ros2_param_list_and_nothing_raw() {
        let names = vec!["rate_hz".to_string(), "use_sim_time".to_string()];
        assert_eq!(
            list_text("/policy", &names, false),
            "  rate_hz\n  use_sim_time\n"
        );
        assert_eq!(
            list_text("/policy", &names, true),
            "/policy:\n  rate_hz\n  use_sim_time\n"
        );
        let hostile = vec!["a\x1b[2Jb\nc".to_string()];
        assert!(!list_text("/x", &hostile, true).contains('\x1b'));
        let v = value(pt::STRING, |v| v.string_value = "\x1b]0;x\x07".into());
        assert!(!get_text(Some(&v)).unwrap().contains('\x1b'));
        assert_eq!(
            list_text("/x", &[], true),
            "",
            "no header for a node with no names"
        );
    }
}
