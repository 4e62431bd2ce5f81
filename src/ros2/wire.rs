//! rmw_zenoh's wire, as every endpoint ratelab offers uses it (rmw_zenoh `docs/design.md`,
//! checked against a real rmw_zenoh_cpp 0.6.7 node's captures in
//! `../shared/fixtures/ros2-real/`): declaring an endpoint (its key, its liveliness token,
//! its GID from that token), the 33-byte attachment each message and each service reply
//! carries, and putting a message stamped by its publisher's own session.
//!
//! A transient-local publisher keeps its last `depth` messages for subscriptions that join
//! later, as rmw_zenoh_cpp's does: a Zenoh advanced publisher (`zenoh-ext`) with a cache
//! of `depth` samples and publisher detection (reliable: with sample-miss detection and a
//! 500 ms sporadic heartbeat too), which a late-joining transient-local subscription (an
//! advanced subscriber asking for history, detecting late publishers) finds and queries.

use super::rmw_zenoh::entity::{EndpointEntity, EndpointKind, NodeEntity, TypeInfo};
use super::rmw_zenoh::key_expr::KeyExprFormat;
use super::rmw_zenoh::qos::{QosDurability, QosHistory, QosProfile, QosReliability};
use super::session::Ros2Session;
use super::{zerr, Ros2Error};
use zenoh::Wait;

/// The 16-byte GID of the endpoint whose token is `token`, as rmw_zenoh_cpp computes it:
/// the XXH3-128 hash of the token, its low 64 bits then its high 64 bits, little endian
/// (checked against a real rmw_zenoh_cpp 0.6.7 node's attachments, `../shared/fixtures/
/// ros2-real/`): a subscriber's `MessageInfo.publisher_gid` then matches the GID that
/// `ros2 topic info -v` shows for the publisher.
pub fn gid(token: &str) -> [u8; 16] {
    xxhash_rust::xxh3::xxh3_128(token.as_bytes()).to_le_bytes()
}

/// An endpoint's liveliness token ([`KeyExprFormat::liveliness_key_expr`]), a keep-all
/// history carrying depth `depth`, the depth ratelab keeps, as rmw_zenoh_cpp writes a
/// keep-all profile's depth (`2,10`; left out, rmw_zenoh_cpp would read its default, 42).
fn token_of(format: &KeyExprFormat, e: &EndpointEntity, depth: usize) -> Result<String, Ros2Error> {
    let mut e = e.clone();
    if let QosHistory::KeepAll(_) = e.qos.history {
        e.qos.history = QosHistory::KeepAll(depth);
    }
    format.liveliness_key_expr(&e).map_err(zerr)
}

/// rmw_zenoh's attachment: `int64` sequence number, `int64` source timestamp (ns), the
/// GID as a byte sequence (its length, 16, as one byte, then the 16 bytes): 33 bytes,
/// little endian (rmw_zenoh `attachment_helpers.cpp`, Zenoh's serializer).
pub fn attachment(seq: i64, source_ns: i64, gid: &[u8; 16]) -> [u8; 33] {
    let mut a = [0u8; 33];
    a[..8].copy_from_slice(&seq.to_le_bytes());
    a[8..16].copy_from_slice(&source_ns.to_le_bytes());
    a[16] = 16;
    a[17..].copy_from_slice(gid);
    a
}

/// What [`attachment`] wrote: the sequence number and the GID (a service request's: its
/// client's); `None` for anything not 33 bytes laid out so.
pub fn read_attachment(att: &[u8]) -> Option<(i64, [u8; 16])> {
    if att.len() != 33 || att[16] != 16 {
        return None;
    }
    let seq = i64::from_le_bytes(att[..8].try_into().ok()?);
    Some((seq, att[17..].try_into().ok()?))
}

/// The wall clock, ns since the Unix epoch (rmw_zenoh's source timestamps).
pub(crate) fn wall_ns() -> i64 {
    std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map_or(0, |d| i64::try_from(d.as_nanos()).unwrap_or(i64::MAX))
}

/// The Zenoh publisher behind an outlet: a plain one (volatile), or an advanced one that
/// keeps the last messages for late joiners (transient local; module header).
enum Publisher {
    Volatile(zenoh::pubsub::Publisher<'static>),
    TransientLocal(zenoh_ext::AdvancedPublisher<'static>),
}

/// A publisher ready to put: its key, its GID, and the session that stamps its samples.
pub(crate) struct Outlet {
    publisher: Publisher,
    gid: [u8; 16],
    session: zenoh::Session,
}

impl Outlet {
    /// `bytes` out as message `seq` (rmw_zenoh's sequence number, from 1), with rmw_zenoh's
    /// attachment and a timestamp from the publisher's own session (its clock and its ZID),
    /// as a real rmw_zenoh_cpp node stamps its samples (the captures in
    /// `../shared/fixtures/ros2-real/`), not left for the router to stamp. A
    /// transient-local publisher's cache keeps it, attachment and stamp included.
    ///
    /// # Errors
    /// Zenoh's, in one line.
    pub(crate) fn put(&self, seq: i64, bytes: &[u8]) -> Result<(), String> {
        let att = attachment(seq, wall_ns(), &self.gid).to_vec();
        let done = match &self.publisher {
            Publisher::Volatile(p) => p
                .put(bytes.to_vec())
                .attachment(att)
                .timestamp(self.session.new_timestamp())
                .wait(),
            // It stamps each sample from the session's clock itself.
            Publisher::TransientLocal(p) => p.put(bytes.to_vec()).attachment(att).wait(),
        };
        done.map_err(|e| e.to_string())
    }

    /// A subscriber matches it now.
    pub(crate) fn matched(&self) -> bool {
        let status = match &self.publisher {
            Publisher::Volatile(p) => p.matching_status().wait(),
            Publisher::TransientLocal(p) => p.matching_status().wait(),
        };
        status.is_ok_and(|m| m.matching())
    }

    /// Withdraw it (its cache with it).
    pub(crate) fn undeclare(self) {
        let _ = match self.publisher {
            Publisher::Volatile(p) => p.undeclare().wait(),
            Publisher::TransientLocal(p) => p.undeclare().wait(),
        };
    }
}

/// What a bridge declares with: the session, the ids it takes, rmw_zenoh's key format, and
/// the liveliness tokens declared so far (withdrawn when the bridge stops).
pub(crate) struct Declarer<'a> {
    session: &'a zenoh::Session,
    link: &'a Ros2Session,
    format: KeyExprFormat,
    tokens: Vec<zenoh::liveliness::LivelinessToken>,
    congestion: zenoh::qos::CongestionControl,
}

impl<'a> Declarer<'a> {
    /// A declarer on `session`, taking ids from `link`.
    pub(crate) fn new(session: &'a zenoh::Session, link: &'a Ros2Session) -> Declarer<'a> {
        Declarer {
            session,
            link,
            format: KeyExprFormat,
            tokens: Vec::new(),
            congestion: zenoh::qos::CongestionControl::Drop,
        }
    }

    /// Its publishers wait for room in Zenoh's queue (`waits`: under the virtual clock)
    /// instead of dropping a sample the link cannot take within Zenoh's
    /// `congestion_control/drop` wait (1 ms, 50 ms for a fragmented message: a camera
    /// frame), as rmw_zenoh_cpp's do for every QoS but reliable keep-all. The virtual clock
    /// keeps pace with the wall clock when offered, so a wait slows nothing a node sees;
    /// dropping would lose frames only because the link was briefly busy at start-up.
    pub(crate) fn waiting(mut self, waits: bool) -> Declarer<'a> {
        if waits {
            self.congestion = zenoh::qos::CongestionControl::Block;
        }
        self
    }

    /// The tokens declared, to be withdrawn with the offer.
    pub(crate) fn into_tokens(self) -> Vec<zenoh::liveliness::LivelinessToken> {
        self.tokens
    }

    /// Declare node `n`'s NN token.
    pub(crate) fn node(&mut self, n: &NodeEntity) -> Result<(), Ros2Error> {
        let ke = self.format.node_liveliness_key_expr(n).map_err(zerr)?;
        self.token(ke)
    }

    /// The session.
    pub(crate) fn session(&self) -> &zenoh::Session {
        self.session
    }

    /// Declare liveliness token `ke`.
    pub(crate) fn token(&mut self, ke: String) -> Result<(), Ros2Error> {
        let t = self
            .session
            .liveliness()
            .declare_token(ke)
            .wait()
            .map_err(zerr)?;
        self.tokens.push(t);
        Ok(())
    }

    /// Declare endpoint `e`'s token (a keep-all history with `depth`).
    pub(crate) fn token_of(
        &mut self,
        e: &EndpointEntity,
        depth: usize,
    ) -> Result<String, Ros2Error> {
        let token = token_of(&self.format, e, depth)?;
        self.token(token.clone())?;
        Ok(token)
    }

    /// An endpoint of `node` with a fresh id (not declared).
    pub(crate) fn endpoint(
        &self,
        node: &NodeEntity,
        kind: EndpointKind,
        topic: &str,
        ty: TypeInfo,
        qos: QosProfile,
    ) -> EndpointEntity {
        EndpointEntity {
            id: self.link.take_id(),
            node: Some(node.clone()),
            kind,
            topic: topic.to_string(),
            type_info: Some(ty),
            qos,
        }
    }

    /// Endpoint `e`'s data key (a topic's, or a service's).
    pub(crate) fn key(&self, e: &EndpointEntity) -> Result<String, Ros2Error> {
        self.format.topic_key_expr(e).map_err(zerr)
    }

    /// A publisher: its key declared, its MP token declared, its GID from that token. A
    /// transient-local one (`e`'s QoS) keeps its last `depth` messages (module header).
    pub(crate) fn publisher(
        &mut self,
        e: &EndpointEntity,
        depth: usize,
    ) -> Result<Outlet, Ros2Error> {
        use zenoh_ext::{AdvancedPublisherBuilderExt, CacheConfig, MissDetectionConfig};
        let key = self.key(e)?;
        let declared = self
            .session
            .declare_publisher(key)
            .congestion_control(self.congestion);
        let publisher = if e.qos.durability == QosDurability::TransientLocal {
            let cache = CacheConfig::default().max_samples(depth.max(1));
            let p = declared.cache(cache).publisher_detection();
            // Reliable: numbered samples and a sporadic heartbeat, as rmw_zenoh_cpp's (each
            // publisher then has its own id in its token, and its late joiners a history of
            // their own per publisher).
            let p = if e.qos.reliability == QosReliability::Reliable {
                let heartbeat = std::time::Duration::from_millis(500);
                p.sample_miss_detection(
                    MissDetectionConfig::default().sporadic_heartbeat(heartbeat),
                )
            } else {
                p
            };
            Publisher::TransientLocal(p.wait().map_err(zerr)?)
        } else {
            Publisher::Volatile(declared.wait().map_err(zerr)?)
        };
        let token = self.token_of(e, depth)?;
        Ok(Outlet {
            publisher,
            gid: gid(&token),
            session: self.session.clone(),
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_attachment_is_33_bytes_as_rmw_zenoh_lays_it_out() {
        let a = attachment(7, -2, &[9; 16]);
        assert_eq!(a.len(), 33);
        assert_eq!(a[..8], 7i64.to_le_bytes());
        assert_eq!(a[8..16], (-2i64).to_le_bytes());
        assert_eq!(a[16], 16);
        assert_eq!(a[17..], [9; 16]);
    }

    #[test]
    fn an_attachment_reads_back_from_rmw_zenoh_s_33_bytes_only() {
        let a = attachment(42, 7, &[3; 16]);
        assert_eq!(read_attachment(&a), Some((42, [3; 16])));
        assert_eq!(read_attachment(&a[..32]), None);
        let mut wrong = a;
        wrong[16] = 15;
        assert_eq!(read_attachment(&wrong), None);
    }

    #[test]
    fn a_keep_all_token_carries_its_depth_as_rmw_zenoh_cpp_writes_it() {
        let zid = "1".parse::<zenoh::session::ZenohId>().unwrap();
        let node = NodeEntity::new(0, zid, 0, "sensor".into(), String::new(), String::new());
        let hash = crate::rmw_zenoh::entity::TypeHash::new(1, [0; 32]);
        let mut e = EndpointEntity {
            id: 1,
            node: Some(node),
            kind: EndpointKind::Publisher,
            topic: "/obs".into(),
            type_info: Some(TypeInfo::new("T", hash)),
            qos: QosProfile {
                history: QosHistory::KeepAll(7),
                ..QosProfile::default()
            },
        };
        let format = KeyExprFormat;
        let t = token_of(&format, &e, 100).unwrap();
        let want = format!("/%obs/T/RIHS01_{}/::2,100:,:,:,,", "00".repeat(32));
        assert!(t.ends_with(&want), "{t}");
        e.qos.history = QosHistory::KeepLast(1);
        let last = token_of(&format, &e, 100).unwrap();
        assert!(last.ends_with("/::,1:,:,:,,"), "{last}");
    }

    #[test]
    fn gids_differ_per_endpoint() {
        assert_ne!(gid("@ros2_lv/0/a/1/2/MP"), gid("@ros2_lv/0/a/1/3/MP"));
    }
}
