//! ROS 2's `~/get_type_description` service (`type_description_interfaces/srv/
//! GetTypeDescription`, REP 2011: a node describes the types it uses), both sides:
//!
//! - **served**: each node ratelab offers answers it for the types of its endpoints (its
//!   topics', `/rosout`'s `Log`, `/parameter_events`' `ParameterEvent`; `/ratelab`'s
//!   `Clock`), so that a ROS 2 tool that does not know ratelab's types can decode them,
//!   with their `.msg` sources when the request asks for them ([`sources`]);
//! - **asked**: `ratelab ros2 topic echo` of a type it carries no description of asks the
//!   publisher's node ([`fetch`]), checks that the description is of the type named and
//!   hashes (RIHS01) to the hash in the topic's key, and decodes by it.
//!
//! What comes from the network is bounded: the reply's bytes before it is decoded
//! ([`MAX_SERVICE_REPLY_BYTES`]), the types it holds ([`MAX_DESCRIBED_TYPES`]); the decode
//! walks it with `echo`'s own bounds (depth, sequence lengths).

use super::rcl_interfaces::GET_TYPE_DESCRIPTION;
use super::{param_cli, Ros2Error};
pub use hiroz_schema::TypeDescriptionMsg;
use ratelab_core::limits::{
    self, MAX_DESCRIBED_TYPES, MAX_SERVICE_REPLY_BYTES, MAX_SERVICE_REQUEST_BYTES,
};
use ratelab_core::ros_types::{cdr, from_cdr};
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;
use std::time::Duration;

/// `type_description_interfaces/srv/GetTypeDescription` request.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct Request {
    /// `package/msg/Name`.
    pub type_name: String,
    /// Its RIHS01 hash (`RIHS01_…`).
    pub type_hash: String,
    /// Also the types' sources (their `.msg` text, [`sources`]).
    pub include_type_sources: bool,
}

/// `type_description_interfaces/msg/TypeSource`.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct TypeSource {
    /// The type.
    pub type_name: String,
    /// `msg`, `idl`, …
    pub encoding: String,
    /// The file's text.
    pub raw_file_contents: String,
}

/// `type_description_interfaces/msg/KeyValue`.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct KeyValue {
    /// The key.
    pub key: String,
    /// The value.
    pub value: String,
}

/// `type_description_interfaces/srv/GetTypeDescription` response (its
/// `type_description` is `hiroz-schema`'s, laid out as `type_description_interfaces`').
#[derive(Clone, Debug, Default, Serialize, Deserialize)]
pub struct Response {
    /// The type was described.
    pub successful: bool,
    /// Why not, when not.
    pub failure_reason: String,
    /// The type and every type it refers to.
    pub type_description: TypeDescriptionMsg,
    /// The sources of the type and of each type it refers to, when the request asked for
    /// them ([`sources`]); else none.
    pub type_sources: Vec<TypeSource>,
    /// More, as key and value (none from ratelab).
    pub extra_information: Vec<KeyValue>,
}

/// The types a node describes, by RIHS01 hash (as rcl's type registry looks them up).
#[derive(Clone, Debug, Default)]
pub struct Descriptions {
    by_hash: BTreeMap<String, TypeDescriptionMsg>,
}

impl Descriptions {
    /// Describe `d`, whose RIHS01 hash is `hash` (computed from it by the caller, once per
    /// type: `hiroz_schema::calculate_hash`).
    pub fn add(&mut self, d: &TypeDescriptionMsg, hash: &str) {
        self.by_hash.insert(hash.to_string(), d.clone());
    }

    /// The answer to `request` (CDR with its header): the response's CDR. As rcl answers
    /// (`rcl/src/rcl/node_type_cache.c`, `type_description_service`): the type is looked up
    /// by its hash alone; a hash that does not parse, or of no type this node uses, is
    /// answered unsuccessful with rcl's reason; `include_type_sources` adds the types'
    /// sources ([`sources`]).
    ///
    /// # Errors
    /// One line when the request is too long or not the service's CDR (not answered).
    pub fn answer(&self, request: &[u8]) -> Result<Vec<u8>, String> {
        if request.len() > MAX_SERVICE_REQUEST_BYTES {
            return Err(limits::refusal(
                format_args!("a request of {} bytes", request.len()),
                "MAX_SERVICE_REQUEST_BYTES",
            ));
        }
        let req: Request = from_cdr(request, MAX_SERVICE_REQUEST_BYTES)?;
        let mut r = Response::default();
        if hiroz_schema::TypeHash::from_rihs_string(&req.type_hash).is_err() {
            r.failure_reason = "Failed to parse type hash".into();
        } else if let Some(d) = self.by_hash.get(&req.type_hash) {
            r.successful = true;
            r.type_description = d.clone();
            if req.include_type_sources {
                r.type_sources = sources(d);
            }
        } else {
            r.failure_reason = "Type not currently in use by this node".into();
        }
        let mut out = Vec::new();
        cdr(&r, &mut out);
        Ok(out)
    }
}

/// The sources of the type `d` describes and of each type it refers to, in the
/// description's order (the type first), as rcl gives them when asked: the type's name,
/// encoding `msg` and the `.msg` file's text. ratelab's texts are the ones its bags carry
/// as `ros2msg` schemas ([`super::bag`]): ROS 2's interface files' declarations (constants
/// and fields, in order), their comments dropped. A type with no text here is left out.
pub fn sources(d: &TypeDescriptionMsg) -> Vec<TypeSource> {
    std::iter::once(&d.type_description)
        .chain(&d.referenced_type_descriptions)
        .filter_map(|t| {
            let text = super::bag::msg_text(&t.type_name);
            (!text.is_empty()).then(|| TypeSource {
                type_name: t.type_name.clone(),
                encoding: "msg".into(),
                raw_file_contents: text.into(),
            })
        })
        .collect()
}

/// Ask node `node` (`/talker`) on `domain` for the description of type `type_name` whose
/// hash is `hash` (the one in its topic's key), within `timeout`; check it.
///
/// # Errors
/// One line: the node did not answer, said it could not, or answered a description that is
/// too large, of another type, or that does not hash to `hash`.
pub fn fetch(
    session: &zenoh::Session,
    domain: u32,
    node: &str,
    (type_name, hash): (&str, &str),
    timeout: Duration,
) -> Result<TypeDescriptionMsg, String> {
    let request = Request {
        type_name: type_name.to_string(),
        type_hash: hash.to_string(),
        include_type_sources: false,
    };
    let bytes = param_cli::call(
        session,
        domain,
        node,
        GET_TYPE_DESCRIPTION,
        &request,
        timeout,
    )
    .map_err(|e: Ros2Error| e.to_string())?;
    let r: Response = from_cdr(&bytes, MAX_SERVICE_REPLY_BYTES)
        .map_err(|e| format!("its node's description is not readable: {e}"))?;
    if !r.successful {
        return Err(format!(
            "its node could not describe it: {}",
            ratelab_core::text::printable(&r.failure_reason)
        ));
    }
    let d = r.type_description;
    if d.referenced_type_descriptions.len() > MAX_DESCRIBED_TYPES {
        return Err(limits::refusal(
            format_args!(
                "its description refers to {} types",
                d.referenced_type_descriptions.len()
            ),
            "MAX_DESCRIBED_TYPES",
        ));
    }
    // A real type has at least one member (ROS 2 gives an empty one a placeholder field); a
    // type of none decodes from no bytes at all.
    let all = std::iter::once(&d.type_description).chain(&d.referenced_type_descriptions);
    if let Some(empty) = all.clone().find(|t| t.fields.is_empty()) {
        return Err(format!(
            "its node's description has a type of no fields ('{}')",
            ratelab_core::text::printable(&empty.type_name)
        ));
    }
    if d.type_description.type_name != type_name {
        return Err(format!(
            "its node described '{}' instead",
            ratelab_core::text::printable(&d.type_description.type_name)
        ));
    }
    let got = hiroz_schema::calculate_hash(&d).to_rihs_string();
    if got != hash {
        return Err(format!(
            "its node's description hashes to {got}, not to the topic's {}",
            ratelab_core::text::printable(hash)
        ));
    }
    Ok(d)
}

#[cfg(test)]
mod tests {
    use super::*;
    use ratelab_core::ros_types::joint_state_type;

    fn ask(d: &Descriptions, type_name: &str, type_hash: &str) -> Response {
        ask_for(d, type_name, type_hash, true)
    }

    fn ask_for(d: &Descriptions, type_name: &str, type_hash: &str, sources: bool) -> Response {
        let mut req = Vec::new();
        cdr(
            &Request {
                type_name: type_name.into(),
                type_hash: type_hash.into(),
                include_type_sources: sources,
            },
            &mut req,
        );
        from_cdr(&d.answer(&req).unwrap(), usize::MAX).unwrap()
    }

    /// Asked for them, a node gives its types' sources: each type's `.msg` text (the type
    /// first, then those it refers to, by name), as ROS 2's interface files declare it; not
    /// asked, none.
    #[test]
    fn a_node_gives_its_types_sources_when_asked() {
        let mut d = Descriptions::default();
        let js = joint_state_type();
        let hash = js.hash.to_rihs_string();
        d.add(&js.description, &hash);
        let r = ask_for(&d, js.name, &hash, true);
        assert!(r.successful, "{}", r.failure_reason);
        let got: Vec<(&str, &str, &str)> = r
            .type_sources
            .iter()
            .map(|s| {
                (
                    s.type_name.as_str(),
                    s.encoding.as_str(),
                    s.raw_file_contents.as_str(),
                )
            })
            .collect();
        assert_eq!(
            got,
            [
                (
                    "sensor_msgs/msg/JointState",
                    "msg",
                    "std_msgs/Header header\nstring[] name\nfloat64[] position\nfloat64[] velocity\nfloat64[] effort\n"
                ),
                (
                    "builtin_interfaces/msg/Time",
                    "msg",
                    "int32 sec\nuint32 nanosec\n"
                ),
                (
                    "std_msgs/msg/Header",
                    "msg",
                    "builtin_interfaces/Time stamp\nstring frame_id\n"
                ),
            ]
        );
        // What it answers still hashes to the type's hash: the sources are beside it.
        assert_eq!(
            hiroz_schema::calculate_hash(&r.type_description).to_rihs_string(),
            hash
        );
        let r = ask_for(&d, js.name, &hash, false);
        assert!(r.successful && r.type_sources.is_empty(), "{r:?}");
        // Not described: no sources either.
        let r = ask_for(&d, js.name, "", true);
        assert!(!r.successful && r.type_sources.is_empty(), "{r:?}");
    }

    /// Every type a ratelab node describes (its topics', `/rosout`'s, `/parameter_events'`,
    /// `/clock`'s) has a source for itself and each type it refers to; where ROS 2's own
    /// interface files are at hand (the ROS 2 Kilted wheels' environment the tests make,
    /// scripts/setup-ros2-wheels.sh: `builtin_interfaces`, `std_msgs`, `rcl_interfaces`,
    /// `rosgraph_msgs`), each text is their file's declarations, line for line.
    #[test]
    fn every_served_type_has_the_source_ros_2_s_interface_file_declares() {
        let known = crate::echo::known();
        let node_types = [
            "rcl_interfaces/msg/Log",
            "rcl_interfaces/msg/ParameterEvent",
        ]
        .map(|n| &known[n].description);
        let own = [
            joint_state_type(),
            crate::types::float64_type(),
            crate::types::clock_type(),
            crate::types::image_type(),
        ]
        .map(|t| &t.description);
        let share = std::env::var_os("RATELAB_ROS2_VENV")
            .map(std::path::PathBuf::from)
            .unwrap_or_else(|| {
                std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../../.venv-ros2")
            })
            .join("share");
        let mut compared = 0;
        for d in own.into_iter().chain(node_types) {
            let s = sources(d);
            assert_eq!(s.len(), 1 + d.referenced_type_descriptions.len());
            for source in s {
                assert_eq!(source.encoding, "msg");
                let file = share.join(format!("{}.msg", source.type_name));
                let Ok(text) = std::fs::read_to_string(&file) else {
                    continue;
                };
                let declared: String = text
                    .lines()
                    .map(|l| l.split('#').next().unwrap_or_default().trim())
                    .filter(|l| !l.is_empty())
                    .map(|l| format!("{l}\n"))
                    .collect();
                assert_eq!(source.raw_file_contents, declared, "{}", file.display());
                compared += 1;
            }
        }
        if compared == 0 {
            eprintln!(
                "note: no ROS 2 interface files under {}: sources not compared with them",
                share.display()
            );
        }
    }

    #[test]
    fn a_node_describes_the_types_it_uses_and_no_other() {
        let mut d = Descriptions::default();
        let js = joint_state_type();
        let hash = js.hash.to_rihs_string();
        d.add(&js.description, &hash);
        let r = ask(&d, js.name, &hash);
        assert!(r.successful, "{}", r.failure_reason);
        // What it answers hashes back to the type's hash: a client can check it.
        assert_eq!(
            hiroz_schema::calculate_hash(&r.type_description).to_rihs_string(),
            hash
        );
        assert_eq!(r.type_description.referenced_type_descriptions.len(), 2);
        // rcl's answers: a hash that does not parse, a type of no endpoint of the node.
        let r = ask(&d, js.name, "");
        assert_eq!(
            (r.successful, r.failure_reason.as_str()),
            (false, "Failed to parse type hash")
        );
        let other = crate::types::float64_type().hash.to_rihs_string();
        let r = ask(&d, "std_msgs/msg/Float64", &other);
        assert_eq!(
            (r.successful, r.failure_reason.as_str()),
            (false, "Type not currently in use by this node")
        );
    }

    #[test]
    fn a_bad_request_is_one_line_and_no_answer() {
        let d = Descriptions::default();
        for bad in [&b""[..], &[0, 1, 0, 0, 0xff, 0xff, 0xff, 0xff][..]] {
            let e = d.answer(bad).unwrap_err();
            assert!(!e.contains('\n'), "{e}");
        }
    }
}
