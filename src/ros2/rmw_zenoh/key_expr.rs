//! rmw_zenoh's key expressions (rmw_zenoh's `docs/design.md`, "Graph Cache" and
//! "Namespaces"; the fields' order, and `/` written `%`, are rmw_zenoh_cpp's
//! `liveliness_utils.cpp`):
//! - an endpoint's data key, `<domain>/<topic>/<dds type>/<hash>`, the topic without its
//!   leading and trailing `/` (and with the ones inside it): a message's key, and a
//!   service's;
//! - a node's liveliness token,
//!   `@ros2_lv/<domain>/<zid>/<node id>/<node id>/NN/<enclave>/<namespace>/<name>`;
//! - an endpoint's,
//!   `@ros2_lv/<domain>/<zid>/<node id>/<id>/<MP|MS|SS|SC>/<enclave>/<namespace>/<node name>/<topic>/<dds type>/<hash>/<qos>`.
//!
//! In a token every name has its `/` written `%` (`/chatter` is `%chatter`), the root
//! namespace and enclave are `%` (design.md: "in the case of an empty namespace …, a
//! namespace of `%` is used"), `<zid>` is the node's Zenoh session id as Zenoh writes it
//! (lowercase hex, no leading zero), the ids and the domain are decimal, the hash is
//! [`TypeHash::to_rihs_string`]'s and `<qos>` is [`QosProfile::encode`]'s.

use super::entity::{EndpointEntity, EndpointKind, Entity, NodeEntity, TypeHash, TypeInfo};
use super::qos::QosProfile;
use super::{bad, bounded, decimal_usize, split_exact, Error, MAX_KEY_EXPR_BYTES};
use zenoh::session::ZenohId;

/// The first field of every liveliness token (rmw_zenoh's admin space).
pub const ADMIN_SPACE: &str = "@ros2_lv";

/// A node's kind in its token.
const NODE_CODE: &str = "NN";

/// The root namespace or enclave in a token.
const ROOT: &str = "%";

/// How many `/`-separated fields a node's token has.
const NODE_FIELDS: usize = 9;

/// How many an endpoint's token has.
const ENDPOINT_FIELDS: usize = 13;

/// What a token is called in errors.
const TOKEN: &str = "liveliness token";

/// rmw_zenoh's key expression format: the data keys and liveliness tokens of the module
/// header, written and read. It holds nothing (rmw_zenoh's is the only format ratelab
/// speaks); its methods are its rules.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct KeyExprFormat;

impl KeyExprFormat {
    /// Endpoint `e`'s data key, `0/chatter/std_msgs::msg::dds_::String_/RIHS01_…`: what its
    /// publisher puts on, its subscriber hears, its service answers on.
    ///
    /// # Errors
    /// [`Error::Unwritable`] when `e` has no node or no type, or the key is no Zenoh key
    /// expression (an empty topic, `//` in it, a wildcard) or is over
    /// [`MAX_KEY_EXPR_BYTES`].
    pub fn topic_key_expr(&self, e: &EndpointEntity) -> Result<String, Error> {
        let (node, ty) = node_and_type(e)?;
        let topic = e.topic.strip_prefix('/').unwrap_or(&e.topic);
        let topic = topic.strip_suffix('/').unwrap_or(topic);
        checked(format!(
            "{}/{topic}/{}/{}",
            node.domain_id,
            ty.name,
            ty.hash.to_rihs_string()
        ))
    }

    /// Node `n`'s liveliness token (`NN`), its id written twice (as its node id and its
    /// entity id, as rmw_zenoh_cpp writes a node's).
    ///
    /// # Errors
    /// [`Error::Unwritable`] for a node with no name, or a token that is no Zenoh key
    /// expression or is over [`MAX_KEY_EXPR_BYTES`].
    pub fn node_liveliness_key_expr(&self, n: &NodeEntity) -> Result<String, Error> {
        checked(node_part(n, n.id, NODE_CODE)?)
    }

    /// Endpoint `e`'s liveliness token, which names its node, topic, type and QoS.
    ///
    /// # Errors
    /// [`Error::Unwritable`] when `e` has no node, no type, an empty topic or type name, a
    /// node with no name, or when the token is no Zenoh key expression or is over
    /// [`MAX_KEY_EXPR_BYTES`].
    pub fn liveliness_key_expr(&self, e: &EndpointEntity) -> Result<String, Error> {
        let (node, ty) = node_and_type(e)?;
        if e.topic.is_empty() || ty.name.is_empty() {
            return Err(Error::Unwritable(format!(
                "an endpoint with topic {:?} and type {:?}",
                e.topic, ty.name
            )));
        }
        checked(format!(
            "{}/{}/{}/{}/{}",
            node_part(node, e.id, e.kind.code())?,
            mangle(&e.topic),
            mangle(&ty.name),
            mangle(&ty.hash.to_rihs_string()),
            e.qos.encode()
        ))
    }

    /// What liveliness token `key` names (the module header's layout): a node, or an
    /// endpoint with its node, topic, type and QoS. `key` comes from anyone on the network:
    /// it is read within bounds, and a token as rmw_zenoh_cpp writes one, written again,
    /// gives the same bytes. Not kept: a node token's entity id, which rmw_zenoh_cpp
    /// writes equal to its node id (other writers may not: it is read all the same), and
    /// how a policy or a number equal to the default was written (`1` for reliable, say,
    /// where rmw_zenoh_cpp leaves the field empty).
    ///
    /// # Errors
    /// [`Error::TooLong`] over [`MAX_KEY_EXPR_BYTES`]; [`Error::FieldCount`] when it has not
    /// the fields of its kind (9 for a node, 13 for an endpoint); [`Error::Bad`] when it is
    /// no Zenoh key expression (an empty field, a wildcard), is not in `@ros2_lv`, has a
    /// kind other than `NN`, `MP`, `MS`, `SS`, `SC`, a number or a Zenoh id not as they are
    /// written, a type hash that is not RIHS01 (or `TypeHashNotSupported`), or a QoS string
    /// [`QosProfile::decode`] refuses.
    pub fn parse_liveliness(&self, key: &str) -> Result<Entity, Error> {
        let key = bounded(TOKEN, key, MAX_KEY_EXPR_BYTES)?;
        if zenoh::key_expr::nonwild_keyexpr::new(key).is_err() {
            return Err(bad("liveliness token (no Zenoh key expression)", key));
        }
        let admin = key.split('/').next().unwrap_or_default();
        if admin != ADMIN_SPACE {
            return Err(bad("liveliness token's admin space", admin));
        }
        let Some(code) = key.split('/').nth(5) else {
            return Err(Error::FieldCount {
                what: TOKEN,
                got: key.split('/').count(),
                want: NODE_FIELDS,
            });
        };
        if code == NODE_CODE {
            let [_, domain, zid, nid, id, _, enclave, namespace, name] =
                split_exact::<NODE_FIELDS>(TOKEN, key, '/')?;
            // Checked, not kept: rmw_zenoh_cpp writes a node's id there again.
            decimal_usize("entity id", id)?;
            let node = read_node([domain, zid, nid, enclave, namespace, name])?;
            return Ok(Entity::Node(node));
        }
        let kind = EndpointKind::from_code(code).ok_or_else(|| bad("entity kind", code))?;
        let [_, domain, zid, nid, id, _, enclave, namespace, name, topic, ty, hash, qos] =
            split_exact::<ENDPOINT_FIELDS>(TOKEN, key, '/')?;
        Ok(Entity::Endpoint(EndpointEntity {
            id: decimal_usize("entity id", id)?,
            node: Some(read_node([domain, zid, nid, enclave, namespace, name])?),
            kind,
            topic: demangle(topic),
            type_info: Some(TypeInfo {
                name: demangle(ty),
                hash: TypeHash::from_rihs_string(hash)?,
            }),
            qos: QosProfile::decode(qos)?,
        }))
    }
}

/// Endpoint `e`'s node and type, which both its key and its token name.
fn node_and_type(e: &EndpointEntity) -> Result<(&NodeEntity, &TypeInfo), Error> {
    match (&e.node, &e.type_info) {
        (Some(node), Some(ty)) => Ok((node, ty)),
        _ => Err(Error::Unwritable(format!(
            "endpoint {:?} without its node or its type",
            e.topic
        ))),
    }
}

/// A token's fields up to its node's name, for entity `id` of kind `code` of node `n`.
fn node_part(n: &NodeEntity, id: usize, code: &str) -> Result<String, Error> {
    if n.name.is_empty() {
        return Err(Error::Unwritable("a node with no name".into()));
    }
    Ok(format!(
        "{ADMIN_SPACE}/{}/{}/{}/{id}/{code}/{}/{}/{}",
        n.domain_id,
        n.z_id,
        n.id,
        root_or_mangled(&n.enclave),
        root_or_mangled(&n.namespace),
        mangle(&n.name)
    ))
}

/// The node that a token's fields `[domain, zid, node id, enclave, namespace, name]` name.
fn read_node(fields: [&str; 6]) -> Result<NodeEntity, Error> {
    let [domain, zid, nid, enclave, namespace, name] = fields;
    Ok(NodeEntity {
        domain_id: decimal_usize("domain id", domain)?,
        z_id: read_zid(zid)?,
        id: decimal_usize("node id", nid)?,
        name: demangle(name),
        namespace: root_or_demangled(namespace),
        enclave: root_or_demangled(enclave),
    })
}

/// The Zenoh id `s` writes as Zenoh writes one: 1 to 32 lowercase hex digits, the first
/// not `0`.
fn read_zid(s: &str) -> Result<ZenohId, Error> {
    let written = (1..=32).contains(&s.len())
        && s.bytes().all(|b| matches!(b, b'0'..=b'9' | b'a'..=b'f'))
        && !s.starts_with('0');
    if !written {
        return Err(bad("Zenoh id", s));
    }
    s.parse::<ZenohId>().map_err(|_| bad("Zenoh id", s))
}

/// `key` if it is a Zenoh key expression without wildcards, within [`MAX_KEY_EXPR_BYTES`]
/// (what is written can be read).
fn checked(key: String) -> Result<String, Error> {
    if key.len() > MAX_KEY_EXPR_BYTES {
        return Err(Error::Unwritable(format!(
            "a key expression of {} bytes (over {MAX_KEY_EXPR_BYTES})",
            key.len()
        )));
    }
    if zenoh::key_expr::nonwild_keyexpr::new(key.as_str()).is_err() {
        return Err(Error::Unwritable(format!(
            "{key:?}, not a Zenoh key expression without wildcards"
        )));
    }
    Ok(key)
}

/// `name` with each `/` written `%`.
fn mangle(name: &str) -> String {
    name.replace('/', "%")
}

/// `name` with each `%` read `/`.
fn demangle(name: &str) -> String {
    name.replace('%', "/")
}

/// A namespace or enclave as a token writes it: `%` for the root (empty, or `/`).
fn root_or_mangled(name: &str) -> String {
    if name.is_empty() {
        ROOT.to_string()
    } else {
        mangle(name)
    }
}

/// A namespace or enclave a token's field names: empty for the root (`%`).
fn root_or_demangled(field: &str) -> String {
    if field == ROOT {
        String::new()
    } else {
        demangle(field)
    }
}

#[cfg(test)]
mod tests {
    use super::super::qos::{QosDuration, QosHistory, QosReliability};
    use super::*;

    const F: KeyExprFormat = KeyExprFormat;

    /// The captures of real rmw_zenoh_cpp 0.6.7 nodes (and of ratelab beside them) that hold
    /// liveliness tokens and data keys.
    const CAPTURES: [&str; 4] = [
        "real-rclpy-talker.json",
        "real-probe-and-ratelab-real-clock.json",
        "ratelab-default.json",
        "ratelab-qos.json",
    ];

    /// A capture of `../shared/fixtures/ros2-real/`, beside the checkout. A missing one
    /// fails the test (never skips).
    fn capture(file: &str) -> serde_json::Value {
        let p = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("../../../shared/fixtures/ros2-real")
            .join(file);
        assert!(
            p.is_file(),
            "fixture missing: {} (CI puts ../shared beside the checkout)",
            p.display()
        );
        serde_json::from_slice(&std::fs::read(&p).unwrap()).unwrap()
    }

    /// The token of what `entity` is.
    fn write(entity: &Entity) -> Result<String, Error> {
        match entity {
            Entity::Node(n) => F.node_liveliness_key_expr(n),
            Entity::Endpoint(e) => F.liveliness_key_expr(e),
        }
    }

    fn zid() -> ZenohId {
        "d72c72ef6733404b97a5010f7d8620d".parse().unwrap()
    }

    fn node(name: &str, namespace: &str) -> NodeEntity {
        NodeEntity::new(0, zid(), 3, name.into(), namespace.into(), String::new())
    }

    fn endpoint(kind: EndpointKind, topic: &str) -> EndpointEntity {
        EndpointEntity {
            id: 7,
            node: Some(node("talker", "")),
            kind,
            topic: topic.into(),
            type_info: Some(TypeInfo::new(
                "std_msgs::msg::dds_::String_",
                TypeHash::new(1, [0xab; 32]),
            )),
            qos: QosProfile::default(),
        }
    }

    /// Every token a real rclpy node over real rmw_zenoh_cpp declared (and ratelab's beside
    /// it) is read and written again byte for byte; what is read is what an independent
    /// split of each token (the capture's `tokens_parsed`) says; and every data key a
    /// publisher put on is its token's endpoint's key.
    #[test]
    fn real_tokens_and_keys_read_and_write_back_byte_for_byte() {
        let mut tokens = 0;
        for file in CAPTURES {
            let c = capture(file);
            let mut publishers = Vec::new();
            for ev in c["token_events"].as_array().unwrap() {
                let key = ev["key"].as_str().unwrap();
                let entity = F
                    .parse_liveliness(key)
                    .unwrap_or_else(|e| panic!("{file}: {key}: {e}"));
                assert_eq!(write(&entity).as_deref(), Ok(key), "{file}");
                if let Entity::Endpoint(e) = entity {
                    if e.kind == EndpointKind::Publisher {
                        publishers.push(e);
                    }
                }
                tokens += 1;
            }
            for t in c["tokens_parsed"].as_array().unwrap() {
                check_fields(t);
            }
            let keys = c["samples"].as_object().unwrap().keys();
            for key in keys {
                assert!(
                    publishers
                        .iter()
                        .any(|e| F.topic_key_expr(e).as_deref() == Ok(key.as_str())),
                    "{file}: no publisher's key is {key}"
                );
            }
        }
        assert!(tokens > 60, "{tokens} tokens");
    }

    /// The token a capture's `tokens_parsed` entry `t` splits, joined again, reads as what
    /// its fields say.
    fn check_fields(t: &serde_json::Value) {
        let field = |k: &str| t[k].as_str().unwrap_or_else(|| panic!("{k} in {t}"));
        let mut parts = vec![
            field("prefix"),
            field("domain"),
            field("zid"),
            field("nid"),
            field("eid"),
            field("kind"),
            field("enclave"),
            field("namespace"),
            field("node"),
        ];
        let endpoint = field("kind") != "NN";
        if endpoint {
            parts.extend([
                field("topic"),
                field("type"),
                field("type_hash"),
                field("qos"),
            ]);
        }
        let key = parts.join("/");
        let entity = F.parse_liveliness(&key).unwrap();
        let n = match &entity {
            Entity::Node(n) => n,
            Entity::Endpoint(e) => e.node.as_ref().unwrap(),
        };
        assert_eq!(n.domain_id.to_string(), field("domain"));
        assert_eq!(n.z_id.to_string(), field("zid"));
        assert_eq!(n.id.to_string(), field("nid"));
        assert_eq!(n.name, field("node"));
        assert_eq!(field("namespace"), "%");
        assert_eq!((n.namespace.as_str(), n.enclave.as_str()), ("", ""));
        match entity {
            Entity::Node(n) => {
                assert!(!endpoint);
                assert_eq!(n.id.to_string(), field("eid"));
            }
            Entity::Endpoint(e) => {
                assert!(endpoint);
                assert_eq!(e.id.to_string(), field("eid"));
                assert_eq!(e.kind.code(), field("kind"));
                assert_eq!(e.topic, field("topic").replace('%', "/"));
                assert!(e.topic.starts_with('/'), "{}", e.topic);
                let ty = e.type_info.unwrap();
                assert_eq!(ty.name, field("type"));
                assert_eq!(ty.hash.to_rihs_string(), field("type_hash"));
                assert_eq!(e.qos.encode(), field("qos"));
            }
        }
    }

    /// What a real rclpy node's tokens say, read as ros2cli shows it.
    #[test]
    fn a_real_node_s_tokens_say_what_it_declared() {
        let c = capture("real-rclpy-talker.json");
        let endpoints: Vec<EndpointEntity> = c["token_events"]
            .as_array()
            .unwrap()
            .iter()
            .filter_map(|ev| match F.parse_liveliness(ev["key"].as_str().unwrap()) {
                Ok(Entity::Endpoint(e)) => Some(e),
                _ => None,
            })
            .collect();
        let qos = |topic: &str| {
            endpoints
                .iter()
                .find(|e| e.topic == topic)
                .unwrap_or_else(|| panic!("{topic}"))
                .qos
        };
        assert_eq!(qos("/chatter"), QosProfile::default());
        assert_eq!(qos("/qos_keep_all").history, QosHistory::KeepAll(10));
        assert_eq!(qos("/rosout").lifespan, QosDuration { sec: 10, nsec: 0 });
        let sensor = qos("/js_in");
        assert_eq!(
            (sensor.reliability, sensor.history),
            (QosReliability::BestEffort, QosHistory::KeepLast(5))
        );
        let service = endpoints
            .iter()
            .find(|e| e.topic == "/talker/get_parameters")
            .unwrap();
        assert_eq!(service.kind, EndpointKind::Service);
        assert_eq!(
            F.topic_key_expr(service).unwrap(),
            "0/talker/get_parameters/rcl_interfaces::srv::dds_::GetParameters_/\
             RIHS01_bf9803d5c74cf989a5de3e0c2e99444599a627c7ff75f97b8c05b01003675cbc"
        );
    }

    #[test]
    fn entities_read_back_from_their_tokens() {
        let mut nodes = vec![node("talker", ""), node("listener", "/demo/deep")];
        nodes[1].enclave = "/secure".into();
        nodes[1].domain_id = 232;
        nodes[1].id = usize::MAX;
        for n in nodes {
            let token = F.node_liveliness_key_expr(&n).unwrap();
            assert_eq!(F.parse_liveliness(&token), Ok(Entity::Node(n)), "{token}");
        }
        for kind in [
            EndpointKind::Publisher,
            EndpointKind::Subscription,
            EndpointKind::Service,
            EndpointKind::Client,
        ] {
            let mut e = endpoint(kind, "/ns/chatter");
            e.qos.history = QosHistory::KeepAll(3);
            let token = F.liveliness_key_expr(&e).unwrap();
            assert_eq!(
                F.parse_liveliness(&token),
                Ok(Entity::Endpoint(e)),
                "{token}"
            );
        }
        let mut humble = endpoint(EndpointKind::Publisher, "/chatter");
        humble.type_info.as_mut().unwrap().hash = TypeHash::NOT_SUPPORTED;
        let token = F.liveliness_key_expr(&humble).unwrap();
        assert!(token.contains("/TypeHashNotSupported/"), "{token}");
        assert_eq!(F.parse_liveliness(&token), Ok(Entity::Endpoint(humble)));
    }

    /// The layout of the module header, field by field.
    #[test]
    fn tokens_and_keys_are_laid_out_as_rmw_zenoh_s() {
        let mut n = node("talker", "");
        assert_eq!(
            F.node_liveliness_key_expr(&n).unwrap(),
            "@ros2_lv/0/d72c72ef6733404b97a5010f7d8620d/3/3/NN/%/%/talker"
        );
        // The root namespace as rcl names it, `/`, is `%` too.
        n.namespace = "/".into();
        assert!(F
            .node_liveliness_key_expr(&n)
            .unwrap()
            .ends_with("/NN/%/%/talker"));
        let e = endpoint(EndpointKind::Subscription, "/a/b");
        let hash = format!("RIHS01_{}", "ab".repeat(32));
        assert_eq!(
            F.liveliness_key_expr(&e).unwrap(),
            format!(
                "@ros2_lv/0/d72c72ef6733404b97a5010f7d8620d/3/7/MS/%/%/talker/%a%b/\
                 std_msgs::msg::dds_::String_/{hash}/::,10:,:,:,,"
            )
        );
        assert_eq!(
            F.topic_key_expr(&e).unwrap(),
            format!("0/a/b/std_msgs::msg::dds_::String_/{hash}")
        );
        // One leading and one trailing slash go.
        let e = endpoint(EndpointKind::Publisher, "/a/");
        assert!(F.topic_key_expr(&e).unwrap().starts_with("0/a/std_msgs"));
    }

    #[test]
    fn what_makes_no_key_is_not_written() {
        for topic in ["", "/", "//", "/a//b", "/*", "/a/**", "/$*", "/a#", "/a?b"] {
            let e = endpoint(EndpointKind::Publisher, topic);
            assert!(F.topic_key_expr(&e).is_err(), "{topic:?}");
        }
        let mut e = endpoint(EndpointKind::Publisher, "/chatter");
        e.node = None;
        assert!(F.topic_key_expr(&e).is_err());
        assert!(F.liveliness_key_expr(&e).is_err());
        let mut e = endpoint(EndpointKind::Publisher, "/chatter");
        e.type_info = None;
        assert!(F.topic_key_expr(&e).is_err());
        assert!(F.liveliness_key_expr(&e).is_err());
        assert!(F.node_liveliness_key_expr(&node("", "")).is_err());
        assert!(F.node_liveliness_key_expr(&node("*", "")).is_err());
        let long = endpoint(EndpointKind::Publisher, &format!("/{}", "a".repeat(5000)));
        assert!(matches!(
            F.liveliness_key_expr(&long),
            Err(Error::Unwritable(_))
        ));
    }

    /// A token cut anywhere, grown, or with any field made wrong is refused, or (cut inside
    /// its last name or number) read as the shorter token it then is: never a panic, and
    /// never read as what it does not write.
    #[test]
    fn hostile_tokens_are_refused_never_a_panic() {
        let real = "@ros2_lv/0/d72c72ef6733404b97a5010f7d8620d/0/14/MP/%/%/talker/%qos_deadline/\
                    std_msgs::msg::dds_::Float64_/\
                    RIHS01_705ba9c3d1a09df43737eb67095534de36fd426c0587779bda2bc51fe790182a/\
                    2::,1:0,40000000:0,60000000:,0,100000000";
        let node = "@ros2_lv/0/d72c72ef6733404b97a5010f7d8620d/0/0/NN/%/%/talker";
        for token in [real, node] {
            assert!(F.parse_liveliness(token).is_ok());
            for (cut, _) in token.char_indices() {
                let short = &token[..cut];
                if let Ok(e) = F.parse_liveliness(short) {
                    assert_eq!(write(&e).as_deref(), Ok(short));
                }
            }
            // Cut at a field: refused.
            for (cut, _) in token.match_indices('/') {
                assert!(
                    F.parse_liveliness(&token[..cut]).is_err(),
                    "{}",
                    &token[..cut]
                );
                assert!(F.parse_liveliness(&token[..=cut]).is_err());
            }
            // One field too many.
            assert!(matches!(
                F.parse_liveliness(&format!("{token}/x")),
                Err(Error::FieldCount { .. })
            ));
        }
        let replace = |i: usize, with: &str| {
            let mut f: Vec<&str> = real.split('/').collect();
            f[i] = with;
            f.join("/")
        };
        let bad_fields: [(usize, &[&str]); 8] = [
            (0, &["@ros2", "ros2_lv", "@ROS2_LV"]),
            (
                1,
                &[
                    "+0",
                    "-1",
                    "00",
                    "x",
                    "0x1",
                    "99999999999999999999999",
                    " 0",
                ],
            ),
            (
                2,
                &[
                    "D72C72EF6733404B97A5010F7D8620D",
                    "0d72c72ef6733404b97a5010f7d8620d",
                    "0",
                    "d72c72ef6733404b97a5010f7d8620d00",
                    "g",
                    "d72c.72ef",
                ],
            ),
            (3, &["01", "n", "-0", "18446744073709551616"]),
            (4, &["1.0", "1e2", "٣"]),
            (5, &["XX", "mp", "NNN", "M"]),
            (11, &["RIHS01_00", "RIHS02_x", "TypeHash", "%"]),
            (
                12,
                &["2::,1", "9::,1:,:,:,,", "2::,1:,:,:,,:", "2::,1:,:,:2,,"],
            ),
        ];
        for (i, values) in bad_fields {
            for v in values {
                let token = replace(i, v);
                assert!(F.parse_liveliness(&token).is_err(), "{token}");
            }
        }
        // Wildcards and what is no key expression.
        for name in ["*", "**", "$*", "a$*", "a#", "a?"] {
            assert!(F.parse_liveliness(&replace(8, name)).is_err(), "{name}");
        }
        // A node token whose entity id is not its node id (some writers' own): read, the
        // node id kept.
        let other = "@ros2_lv/0/d72c72ef6733404b97a5010f7d8620d/2/5/NN/%/%/talker";
        let Ok(Entity::Node(n)) = F.parse_liveliness(other) else {
            panic!("{other}")
        };
        assert_eq!(n.id, 2);
        // Over the bound, at once.
        let long = replace(9, "%a".repeat(MAX_KEY_EXPR_BYTES).as_str());
        assert!(matches!(
            F.parse_liveliness(&long),
            Err(Error::TooLong { .. })
        ));
        assert!(F.parse_liveliness("").is_err());
        assert!(F.parse_liveliness("@ros2_lv").is_err());
        assert!(F.parse_liveliness("@ros2_lv/0/1/0/0").is_err());
    }
}
