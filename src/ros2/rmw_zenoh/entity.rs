//! What a liveliness token names (rmw_zenoh's `docs/design.md`, "Graph Cache": "An
//! 'entity' is a node, publisher, subscription, service server, or service client"): a
//! node, or an endpoint of a node with its topic, its type and its QoS ([`super::qos`]).
//! The token itself is [`super::key_expr`]'s.

use super::qos::QosProfile;
use super::{bad, Error};
use zenoh::session::ZenohId;

/// A ROS 2 node, as its `NN` token names it.
#[derive(Clone, Debug, PartialEq, Eq, Hash)]
pub struct NodeEntity {
    /// Its ROS 2 domain (`ROS_DOMAIN_ID`).
    pub domain_id: usize,
    /// The Zenoh session it lives in (its ROS 2 context's).
    pub z_id: ZenohId,
    /// Its id in that session (rmw_zenoh_cpp numbers a session's nodes and endpoints from
    /// 0, with one counter).
    pub id: usize,
    /// Its name, without namespace: `talker`.
    pub name: String,
    /// Its namespace, `/demo`; empty for the root namespace, which a token writes `%`.
    pub namespace: String,
    /// Its security enclave; empty for the root enclave, which a token writes `%`.
    pub enclave: String,
}

impl NodeEntity {
    /// Node `id` of session `z_id` on domain `domain_id`, named `name` in `namespace` (empty
    /// for the root) with `enclave` (empty for the root).
    pub fn new(
        domain_id: usize,
        z_id: ZenohId,
        id: usize,
        name: String,
        namespace: String,
        enclave: String,
    ) -> NodeEntity {
        NodeEntity {
            domain_id,
            z_id,
            id,
            name,
            namespace,
            enclave,
        }
    }
}

/// What an endpoint is, with the two letters its token names it by.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum EndpointKind {
    /// A publisher, `MP`.
    Publisher,
    /// A subscription, `MS`.
    Subscription,
    /// A service server, `SS`.
    Service,
    /// A service client, `SC`.
    Client,
}

impl EndpointKind {
    /// The two letters a token names it by: `MP`, `MS`, `SS`, `SC`.
    pub const fn code(self) -> &'static str {
        match self {
            EndpointKind::Publisher => "MP",
            EndpointKind::Subscription => "MS",
            EndpointKind::Service => "SS",
            EndpointKind::Client => "SC",
        }
    }

    /// The kind two letters name; `None` for anything else (a node's `NN` included).
    pub fn from_code(code: &str) -> Option<EndpointKind> {
        [
            EndpointKind::Publisher,
            EndpointKind::Subscription,
            EndpointKind::Service,
            EndpointKind::Client,
        ]
        .into_iter()
        .find(|k| k.code() == code)
    }
}

impl std::fmt::Display for EndpointKind {
    /// [`EndpointKind::code`].
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.code())
    }
}

/// A ROS 2 type hash (REP 2011's RIHS): its version and its 32 bytes.
#[derive(Clone, Debug, PartialEq, Eq, Hash)]
pub struct TypeHash {
    /// The RIHS version: 1 (SHA-256 of the type description), or 0 for no hash (ROS 2
    /// Humble's rmw_zenoh_cpp writes `TypeHashNotSupported`).
    pub version: u8,
    /// The hash, 32 bytes (zeros when there is none).
    pub value: [u8; 32],
}

impl TypeHash {
    /// The hash ROS 2 Humble has not, written `TypeHashNotSupported`.
    pub const NOT_SUPPORTED: TypeHash = TypeHash {
        version: 0,
        value: [0; 32],
    };

    /// Version `version` (1: RIHS01) with bytes `value`.
    pub const fn new(version: u8, value: [u8; 32]) -> TypeHash {
        TypeHash { version, value }
    }

    /// As ROS 2 writes it: `RIHS01_` and 64 lowercase hex digits (the version in two
    /// decimal digits); `TypeHashNotSupported` for version 0.
    pub fn to_rihs_string(&self) -> String {
        if self.version == 0 {
            return "TypeHashNotSupported".to_string();
        }
        let hex: String = self.value.iter().map(|b| format!("{b:02x}")).collect();
        format!("RIHS{:02}_{hex}", self.version)
    }

    /// The hash `s` writes: `RIHS01_` and 64 hex digits, or `TypeHashNotSupported`.
    ///
    /// # Errors
    /// [`Error::Bad`] for anything else (another version, another length, a non-hex digit).
    pub fn from_rihs_string(s: &str) -> Result<TypeHash, Error> {
        if s == "TypeHashNotSupported" {
            return Ok(TypeHash::NOT_SUPPORTED);
        }
        let hex = s
            .strip_prefix("RIHS01_")
            .filter(|h| h.len() == 64 && h.bytes().all(|b| b.is_ascii_hexdigit()))
            .ok_or_else(|| bad("type hash", s))?;
        let mut value = [0u8; 32];
        for (byte, pair) in value.iter_mut().zip(hex.as_bytes().chunks_exact(2)) {
            let pair = std::str::from_utf8(pair).map_err(|_| bad("type hash", s))?;
            *byte = u8::from_str_radix(pair, 16).map_err(|_| bad("type hash", s))?;
        }
        Ok(TypeHash::new(1, value))
    }
}

/// An endpoint's type: its DDS name (`std_msgs::msg::dds_::String_`) and its hash.
#[derive(Clone, Debug, PartialEq, Eq, Hash)]
pub struct TypeInfo {
    /// The DDS name, as rmw_zenoh names types: `std_msgs::msg::dds_::String_`.
    pub name: String,
    /// The type's hash.
    pub hash: TypeHash,
}

impl TypeInfo {
    /// The type named `name` (its DDS name) with hash `hash`.
    pub fn new(name: &str, hash: TypeHash) -> TypeInfo {
        TypeInfo {
            name: name.to_string(),
            hash,
        }
    }
}

/// A publisher, subscription, service server or client of a node, as its token names it.
#[derive(Clone, Debug, PartialEq, Eq, Hash)]
pub struct EndpointEntity {
    /// Its id in its node's session (the node's counter, [`NodeEntity::id`]).
    pub id: usize,
    /// Its node: always there in a token read; one to write is refused without it.
    pub node: Option<NodeEntity>,
    /// What it is.
    pub kind: EndpointKind,
    /// Its topic's (or service's) full name: `/chatter`, `/talker/get_parameters`.
    pub topic: String,
    /// Its type: always there in a token read; one to write is refused without it.
    pub type_info: Option<TypeInfo>,
    /// Its QoS profile (a subscription's: the one it requests).
    pub qos: QosProfile,
}

/// What one token names: a node or an endpoint.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum Entity {
    /// A node (`NN`).
    Node(NodeEntity),
    /// A publisher, subscription, service server or client.
    Endpoint(EndpointEntity),
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn kinds_read_back_from_their_letters_and_nothing_else() {
        for k in [
            EndpointKind::Publisher,
            EndpointKind::Subscription,
            EndpointKind::Service,
            EndpointKind::Client,
        ] {
            assert_eq!(EndpointKind::from_code(k.code()), Some(k));
            assert_eq!(k.to_string(), k.code());
        }
        for no in ["NN", "mp", "M", "MPX", ""] {
            assert_eq!(EndpointKind::from_code(no), None, "{no}");
        }
    }

    #[test]
    fn a_type_hash_reads_back_from_what_it_writes() {
        let real = "RIHS01_df668c740482bbd48fb39d76a70dfd4bd59db1288021743503259e948f6b1a18";
        let h = TypeHash::from_rihs_string(real).unwrap();
        assert_eq!(h.version, 1);
        assert_eq!(h.value[0], 0xdf);
        assert_eq!(h.value[31], 0x18);
        assert_eq!(h.to_rihs_string(), real);
        let mut every = [0u8; 32];
        for (i, b) in every.iter_mut().enumerate() {
            *b = (i * 8 + 7) as u8;
        }
        let h = TypeHash::new(1, every);
        assert_eq!(TypeHash::from_rihs_string(&h.to_rihs_string()), Ok(h));
        let none = TypeHash::NOT_SUPPORTED;
        assert_eq!(none.to_rihs_string(), "TypeHashNotSupported");
        assert_eq!(TypeHash::from_rihs_string("TypeHashNotSupported"), Ok(none));
    }

    #[test]
    fn what_is_not_a_type_hash_is_refused() {
        let ok = "df668c740482bbd48fb39d76a70dfd4bd59db1288021743503259e948f6b1a18";
        for no in [
            String::new(),
            ok.to_string(),
            format!("RIHS02_{ok}"),
            format!("rihs01_{ok}"),
            format!("RIHS01_{}", &ok[..62]),
            format!("RIHS01_{ok}00"),
            format!("RIHS01_{}g", &ok[..63]),
            format!("RIHS01_{}+f", &ok[..62]),
            format!("RIHS01_{}é", &ok[..62]),
            "TypeHashNotSupported ".to_string(),
        ] {
            assert!(TypeHash::from_rihs_string(&no).is_err(), "{no:?}");
        }
    }
}
