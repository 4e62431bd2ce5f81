//! `ratelab ros2`: any rmw_zenoh graph read from the other side, as ros2cli reads it, without
//! a ROS 2 installation. The graph is what the domain's liveliness tokens say
//! (`@ros2_lv/<domain>/…`: a node's NN, a publisher's MP, a subscription's MS, with types
//! and QoS), parsed by hiroz-protocol ([`seen`], [`Seen`]); what ros2cli prints of it is
//! written by pure functions over that data ([`node_list`], [`node_info`], [`topic_list`],
//! [`topic_info`]), and a topic's messages are heard on its data key ([`subscribe`]) and
//! written by [`super::echo`] or counted ([`Rate`], [`Bandwidth`]).
//!
//! Output follows ros2cli (Jazzy): `node list` prints `/talker`; `topic list -t` prints
//! `/cmd_vel [geometry_msgs/msg/Twist]`; `topic info -v` an endpoint block per node with its
//! QoS; `topic hz` `average rate: 20.000` then `\tmin: …s max: …s std dev: …s window: N`.
//! Names from the wire are written with their control characters escaped.

use super::{zerr, Ros2Error};
pub use hiroz_protocol::entity::{EndpointEntity, EndpointKind, Entity, NodeEntity};
use hiroz_protocol::qos::{QosDuration, QosHistory, QosLiveliness, QosProfile, QosReliability};
use hiroz_protocol::KeyExprFormat;
use std::collections::BTreeSet;
use std::time::Duration;
/// The Zenoh session a reader holds.
pub use zenoh::Session;
use zenoh::Wait;

/// The most tokens kept from one domain (a graph of thousands of nodes fits; a flood does
/// not grow memory without bound).
pub const MAX_TOKENS: usize = 1 << 20;

/// The graph as the tokens tell it.
#[derive(Debug, Default, Clone)]
pub struct Seen {
    /// Every node.
    pub nodes: Vec<NodeEntity>,
    /// Every publisher, subscription, service and client.
    pub endpoints: Vec<EndpointEntity>,
    /// Each endpoint's GID (by index in `endpoints`), as rmw_zenoh_cpp computes it from its
    /// token ([`super::bridge::gid`]): `ros2 topic info -v` shows it.
    pub gids: Vec<[u8; 16]>,
}

impl Seen {
    /// Take one liveliness token `key` (`@ros2_lv/<domain>/…`) into the graph: a node, or an
    /// endpoint with its GID. Returns whether it was a ROS 2 entity.
    pub fn take(&mut self, key: &str) -> bool {
        let Ok(k) = zenoh::key_expr::KeyExpr::try_from(key) else {
            return false;
        };
        match KeyExprFormat::default().parse_liveliness(&k) {
            Ok(Entity::Node(n)) => self.nodes.push(n),
            Ok(Entity::Endpoint(e)) => {
                self.gids.push(super::bridge::gid(key));
                self.endpoints.push(e);
            }
            Err(_) => return false,
        }
        true
    }
}

/// A node's fully qualified name, `/ns/name` (`/talker` in the root namespace).
pub fn fq_name(node: &NodeEntity) -> String {
    let ns = node.namespace.trim_end_matches('/');
    let ns = if ns.is_empty() { "" } else { ns };
    let sep = if ns.starts_with('/') || ns.is_empty() {
        ""
    } else {
        "/"
    };
    printable(&format!("{sep}{ns}/{}", node.name))
}

fn printable(s: &str) -> String {
    crate::text::printable(s).into_owned()
}

/// An endpoint's type as ROS 2 names it (`std_msgs/msg/Float64`), from its DDS name.
pub fn type_name(e: &EndpointEntity) -> String {
    e.type_info.as_ref().map_or_else(
        || "?".to_string(),
        |t| printable(&hiroz_schema::ros_from_dds(&t.name)),
    )
}

/// An endpoint's type name (ROS 2's form, as the wire has it: not escaped) and RIHS01 hash
/// (`RIHS01_…`; empty when its token names none).
pub fn type_and_hash(e: &EndpointEntity) -> (String, String) {
    e.type_info
        .as_ref()
        .map_or(("?".to_string(), String::new()), |t| {
            (hiroz_schema::ros_from_dds(&t.name), t.hash.to_rihs_string())
        })
}

fn is_topic(e: &EndpointEntity) -> bool {
    matches!(e.kind, EndpointKind::Publisher | EndpointKind::Subscription)
}

/// `ros2 node list`: every node's fully qualified name, sorted, one per line.
pub fn node_list(g: &Seen) -> String {
    let names: BTreeSet<String> = g.nodes.iter().map(fq_name).collect();
    names.into_iter().map(|n| n + "\n").collect()
}

/// Node `node` (`/talker`, or `talker` in the root namespace) by its fully qualified name,
/// when the graph has it.
pub fn known_node(g: &Seen, node: &str) -> Option<String> {
    let want = if node.starts_with('/') {
        node.to_string()
    } else {
        format!("/{node}")
    };
    g.nodes.iter().any(|n| fq_name(n) == want).then_some(want)
}

/// `ros2 node info NODE`: its publishers, subscribers, service servers and clients with
/// their types.
///
/// # Errors
/// One line when no node has that name (as ros2cli: `Unable to find node '/x'`).
pub fn node_info(g: &Seen, node: &str) -> Result<String, String> {
    let want =
        known_node(g, node).ok_or_else(|| format!("Unable to find node '{}'", printable(node)))?;
    let of = |kind: EndpointKind| -> String {
        let mut lines: BTreeSet<String> = BTreeSet::new();
        for e in &g.endpoints {
            if e.kind == kind && e.node.as_ref().is_some_and(|n| fq_name(n) == want) {
                lines.insert(format!("    {}: {}\n", printable(&e.topic), type_name(e)));
            }
        }
        // ros2cli prints an empty section as an empty line.
        if lines.is_empty() {
            "\n".to_string()
        } else {
            lines.into_iter().collect()
        }
    };
    Ok(format!(
        "{want}\n  Subscribers:\n{}  Publishers:\n{}  Service Servers:\n{}  Service Clients:\n{}  Action Servers:\n\n  Action Clients:\n\n",
        of(EndpointKind::Subscription),
        of(EndpointKind::Publisher),
        of(EndpointKind::Service),
        of(EndpointKind::Client),
    ))
}

/// `ros2 topic list [-t]`: every topic, sorted, with its types when `types`.
pub fn topic_list(g: &Seen, types: bool) -> String {
    let mut topics: std::collections::BTreeMap<String, BTreeSet<String>> = Default::default();
    for e in g.endpoints.iter().filter(|e| is_topic(e)) {
        topics
            .entry(printable(&e.topic))
            .or_default()
            .insert(type_name(e));
    }
    topics
        .into_iter()
        .map(|(t, tys)| {
            if types {
                let tys: Vec<String> = tys.into_iter().collect();
                format!("{t} [{}]\n", tys.join(", "))
            } else {
                format!("{t}\n")
            }
        })
        .collect()
}

fn duration(d: &QosDuration) -> String {
    if *d == QosDuration::INFINITE {
        "Infinite".into()
    } else {
        format!("{} nanoseconds", d.sec * 1_000_000_000 + d.nsec)
    }
}

/// A QoS profile in one short line: `BEST_EFFORT · KEEP_LAST (1)`, then what is not
/// ROS 2's default (`· deadline 40 ms`, `· lifespan 60 ms`, `· lease 100 ms`,
/// `· TRANSIENT_LOCAL`).
pub fn qos_short(q: &QosProfile) -> String {
    let mut parts = vec![reliability_word(q).to_string(), history_words(q)];
    let ms = |d: &QosDuration| d.sec as f64 * 1e3 + d.nsec as f64 / 1e6;
    for (what, d) in [
        ("deadline", &q.deadline),
        ("lifespan", &q.lifespan),
        ("lease", &q.liveliness_lease_duration),
    ] {
        if *d != QosDuration::INFINITE {
            parts.push(format!("{what} {} ms", ms(d)));
        }
    }
    if q.durability == hiroz_protocol::qos::QosDurability::TransientLocal {
        parts.push("TRANSIENT_LOCAL".into());
    }
    parts.join(" · ")
}

/// Reliability as ros2cli writes it: `RELIABLE`, `BEST_EFFORT`.
fn reliability_word(q: &QosProfile) -> &'static str {
    match q.reliability {
        QosReliability::Reliable => "RELIABLE",
        QosReliability::BestEffort => "BEST_EFFORT",
    }
}

/// History and depth as ros2cli writes them: `KEEP_LAST (7)`, and `KEEP_ALL` with no depth
/// (rclpy's `TopicEndpointInfo.__str__`, Jazzy and later: a keep-all depth is not shown).
fn history_words(q: &QosProfile) -> String {
    match q.history {
        QosHistory::KeepLast(n) => format!("KEEP_LAST ({n})"),
        QosHistory::KeepAll => "KEEP_ALL".into(),
    }
}

fn qos_block(q: &QosProfile) -> String {
    let (history, reliability) = (history_words(q), reliability_word(q));
    let durability = match q.durability {
        hiroz_protocol::qos::QosDurability::Volatile => "VOLATILE",
        hiroz_protocol::qos::QosDurability::TransientLocal => "TRANSIENT_LOCAL",
    };
    let liveliness = match q.liveliness {
        QosLiveliness::Automatic => "AUTOMATIC",
        QosLiveliness::ManualByNode => "MANUAL_BY_NODE",
        QosLiveliness::ManualByTopic => "MANUAL_BY_TOPIC",
    };
    format!(
        "QoS profile:\n  Reliability: {reliability}\n  History (Depth): {history}\n  Durability: {durability}\n  Lifespan: {}\n  Deadline: {}\n  Liveliness: {liveliness}\n  Liveliness lease duration: {}\n",
        duration(&q.lifespan),
        duration(&q.deadline),
        duration(&q.liveliness_lease_duration)
    )
}

/// `ros2 topic info TOPIC [-v]`: its type, publisher and subscription counts and, verbose,
/// each endpoint with its node, type hash and QoS.
///
/// # Errors
/// One line when no endpoint has that topic (as ros2cli: `Unknown topic '/x'`).
pub fn topic_info(g: &Seen, topic: &str, verbose: bool) -> Result<String, String> {
    let ends: Vec<(usize, &EndpointEntity)> = g
        .endpoints
        .iter()
        .enumerate()
        .filter(|(_, e)| is_topic(e) && e.topic == topic)
        .collect();
    if ends.is_empty() {
        return Err(format!("Unknown topic '{}'", printable(topic)));
    }
    let types: BTreeSet<String> = ends.iter().map(|(_, e)| type_name(e)).collect();
    let count = |k: EndpointKind| ends.iter().filter(|(_, e)| e.kind == k).count();
    let mut out = format!(
        "Type: {}\n\nPublisher count: {}\n\n",
        types.into_iter().collect::<Vec<_>>().join(", "),
        count(EndpointKind::Publisher)
    );
    let block = |kind: EndpointKind, what: &str| -> String {
        let mut text = String::new();
        for (i, e) in ends.iter().filter(|(_, e)| e.kind == kind) {
            let (name, ns) = e.node.as_ref().map_or(("?".into(), "?".into()), |n| {
                let ns = if n.namespace.is_empty() {
                    "/".to_string()
                } else {
                    printable(&n.namespace)
                };
                (printable(&n.name), ns)
            });
            let hash = e
                .type_info
                .as_ref()
                .map_or("?".into(), |t| t.hash.to_rihs_string());
            // ros2cli's GID: its bytes in hex, dot-separated.
            let gid = g.gids.get(*i).map_or(String::new(), |b| {
                let hex: Vec<String> = b.iter().map(|b| format!("{b:02x}")).collect();
                format!("GID: {}\n", hex.join("."))
            });
            text.push_str(&format!(
                "Node name: {name}\nNode namespace: {ns}\nTopic type: {}\nTopic type hash: {hash}\nEndpoint type: {what}\n{gid}{}\n",
                type_name(e),
                qos_block(&e.qos)
            ));
        }
        text
    };
    if verbose {
        out.push_str(&block(EndpointKind::Publisher, "PUBLISHER"));
    }
    out.push_str(&format!(
        "Subscription count: {}\n\n",
        count(EndpointKind::Subscription)
    ));
    if verbose {
        out.push_str(&block(EndpointKind::Subscription, "SUBSCRIPTION"));
    }
    Ok(out.trim_end().to_string() + "\n")
}

/// Open a Zenoh session for reading a domain: a client of the router at `connect`
/// (`tcp/localhost:7447` by default, where rmw_zenoh's nodes find theirs), `ZENOH_CONFIG_OVERRIDE`
/// applied as rmw_zenoh applies it ([`super::session::parse_override`]).
///
/// # Errors
/// [`Ros2Error::Usage`] for a bad override; [`Ros2Error::Zenoh`] when no router answers
/// (named, with how to start one).
pub fn open(
    connect: Option<&str>,
    env: &super::session::SessionEnv,
) -> Result<zenoh::Session, Ros2Error> {
    let endpoint = connect
        .unwrap_or(super::session::DEFAULT_ROUTER)
        .to_string();
    let mut config = zenoh::Config::default();
    let set = |c: &mut zenoh::Config, k: &str, v: &str| {
        c.insert_json5(k, v)
            .map_err(|e| Ros2Error::Usage(format!("Zenoh config {k}={v}: {e}")))
    };
    set(&mut config, "mode", "\"client\"")?;
    set(&mut config, "scouting/multicast/enabled", "false")?;
    let quoted = serde_json::to_string(&endpoint).map_err(zerr)?;
    set(&mut config, "connect/endpoints", &format!("[{quoted}]"))?;
    if let Some(o) = env.config_override.as_deref() {
        for (k, v) in super::session::parse_override(o).map_err(Ros2Error::Usage)? {
            // A reader stays a client of the router, whatever the nodes' override says.
            if k != "mode" && k != "listen/endpoints" {
                set(&mut config, &k, &v)?;
            }
        }
    }
    zenoh::open(config).wait().map_err(|e| {
        Ros2Error::Zenoh(format!(
            "no Zenoh router answered at {} ({}): start one (`ros2 run rmw_zenoh_cpp rmw_zenohd`, `zenohd`, or a `ratelab run --ros2`, which runs one), or name it with --connect",
            printable(&endpoint),
            // Zenoh's message names its own source file after " at ": left out.
            e.to_string()
                .lines()
                .next()
                .unwrap_or_default()
                .split(" at /")
                .next()
                .unwrap_or_default()
                .trim_end_matches(['!', ' '])
        ))
    })
}

/// The graph of `domain` as its liveliness tokens say now: a liveliness query answered by
/// the router within `wait`. Tokens that are not ROS 2's, or whose names hold control
/// characters, are skipped.
///
/// # Errors
/// [`Ros2Error::Zenoh`]: the query failed.
pub fn seen(session: &zenoh::Session, domain: u32, wait: Duration) -> Result<Seen, Ros2Error> {
    let replies = session
        .liveliness()
        .get(format!("@ros2_lv/{domain}/**"))
        .timeout(wait)
        .wait()
        .map_err(zerr)?;
    let mut g = Seen::default();
    let mut seen_keys = BTreeSet::new();
    while let Ok(reply) = replies.recv() {
        let Ok(sample) = reply.result() else { continue };
        let key = sample.key_expr().as_str().to_string();
        if seen_keys.len() >= MAX_TOKENS || !seen_keys.insert(key.clone()) {
            continue;
        }
        g.take(&key);
    }
    Ok(g)
}

/// The publishers of `topic` in `g` (whose type and key a subscriber takes).
pub fn publishers<'a>(g: &'a Seen, topic: &str) -> Vec<&'a EndpointEntity> {
    g.endpoints
        .iter()
        .filter(|e| e.kind == EndpointKind::Publisher && e.topic == topic)
        .collect()
}

/// Subscribe to `publisher`'s topic on its data key (its domain, topic, type and hash):
/// `on` gets each message's payload.
///
/// # Errors
/// [`Ros2Error::Zenoh`]: the key could not be made or the declaration failed.
pub fn subscribe(
    session: &zenoh::Session,
    publisher: &EndpointEntity,
    on: impl Fn(Vec<u8>) + Send + Sync + 'static,
) -> Result<zenoh::pubsub::Subscriber<()>, Ros2Error> {
    let key = KeyExprFormat::default()
        .topic_key_expr(publisher)
        .map_err(zerr)?;
    session
        .declare_subscriber(key.to_string())
        .callback(move |s| on(s.payload().to_bytes().into_owned()))
        .wait()
        .map_err(zerr)
}

/// `ros2 topic hz`'s figures over a window of arrival times (s): messages a second, and the
/// periods' min, max and standard deviation, as ros2cli computes them.
#[derive(Debug, Default)]
pub struct Rate {
    /// Arrival times (s), the newest last, at most `window`.
    times: std::collections::VecDeque<f64>,
    window: usize,
}

impl Rate {
    /// A window of `window` arrivals (ros2cli's default: 10000).
    pub fn new(window: usize) -> Rate {
        Rate {
            times: Default::default(),
            window: window.max(2),
        }
    }

    /// A message arrived at `t_s`.
    pub fn arrived(&mut self, t_s: f64) {
        if self.times.len() == self.window {
            self.times.pop_front();
        }
        self.times.push_back(t_s);
    }

    /// ros2cli's two lines, or `None` before two messages:
    /// `average rate: 20.000\n\tmin: 0.050s max: 0.050s std dev: 0.00010s window: 21\n`.
    pub fn report(&self) -> Option<String> {
        let n = self.times.len();
        if n < 2 {
            return None;
        }
        let periods: Vec<f64> = self
            .times
            .iter()
            .zip(self.times.iter().skip(1))
            .map(|(a, b)| b - a)
            .collect();
        let mean = periods.iter().sum::<f64>() / periods.len() as f64;
        if mean <= 0.0 {
            return None;
        }
        let var = periods.iter().map(|p| (p - mean).powi(2)).sum::<f64>() / periods.len() as f64;
        let min = periods.iter().copied().fold(f64::INFINITY, f64::min);
        let max = periods.iter().copied().fold(0.0, f64::max);
        Some(format!(
            "average rate: {:.3}\n\tmin: {min:.3}s max: {max:.3}s std dev: {:.5}s window: {n}\n",
            1.0 / mean,
            var.sqrt()
        ))
    }
}

/// `ratelab ros2 graph`: the graph as the tokens tell it, a line per topic from its
/// publishers through the topic (its type and, where measured, its msg/s) to its
/// subscribers, as the lab draws node → topic → node:
/// `/sensor ──▶ /obs [sensor_msgs/msg/JointState] 50.0 msg/s ──▶ /policy`. `rates`: msg/s
/// per topic (absent: not measured). Nodes with no topic follow, one line. Every node's
/// `/rosout` and `/parameter_events` are left out, as rqt_graph's "Hide Debug" leaves them
/// out, and said so in a last line when there are any.
pub fn graph_lines(g: &Seen, rates: &std::collections::BTreeMap<String, f64>) -> String {
    /// A topic's publishers, subscribers and types, by node name.
    #[derive(Default)]
    struct Ends {
        pubs: BTreeSet<String>,
        subs: BTreeSet<String>,
        types: BTreeSet<String>,
    }
    let mut topics: std::collections::BTreeMap<String, Ends> = Default::default();
    let mut linked: BTreeSet<String> = BTreeSet::new();
    let hidden = [super::node_api::ROSOUT, super::node_api::PARAMETER_EVENTS];
    let mut hid = BTreeSet::new();
    for e in g.endpoints.iter().filter(|e| is_topic(e)) {
        if hidden.contains(&e.topic.as_str()) {
            hid.insert(e.topic.as_str());
            continue;
        }
        let node = e.node.as_ref().map_or_else(|| "?".to_string(), fq_name);
        linked.insert(node.clone());
        let entry = topics.entry(e.topic.clone()).or_default();
        entry.types.insert(type_name(e));
        match e.kind {
            EndpointKind::Publisher => entry.pubs.insert(node),
            _ => entry.subs.insert(node),
        };
    }
    let join = |s: &BTreeSet<String>| s.iter().cloned().collect::<Vec<_>>().join(", ");
    let mut out = String::new();
    for (topic, Ends { pubs, subs, types }) in &topics {
        let rate = rates
            .get(topic)
            .map_or_else(String::new, |r| format!(" {r:.1} msg/s"));
        let left = if pubs.is_empty() {
            "(no publisher)".to_string()
        } else {
            join(pubs)
        };
        let right = if subs.is_empty() {
            String::new()
        } else {
            format!(" ──▶ {}", join(subs))
        };
        out.push_str(&format!(
            "{left} ──▶ {} [{}]{rate}{right}\n",
            printable(topic),
            join(types)
        ));
    }
    let alone: BTreeSet<String> = g
        .nodes
        .iter()
        .map(fq_name)
        .filter(|n| !linked.contains(n))
        .collect();
    if !alone.is_empty() {
        out.push_str(&format!("nodes with no topic: {}\n", join(&alone)));
    }
    if !hid.is_empty() {
        let hid: Vec<&str> = hid.into_iter().collect();
        out.push_str(&format!("(not drawn: {}, every node's)\n", hid.join(", ")));
    }
    out
}

/// `ros2 topic bw`'s figures over a window of messages: bytes a second, and the messages'
/// mean, min and max size, in ros2cli's units (B, KB, MB: powers of 1000).
#[derive(Debug, Default)]
pub struct Bandwidth {
    /// (arrival time s, size bytes), the newest last, at most `window`.
    seen: std::collections::VecDeque<(f64, usize)>,
    window: usize,
}

/// `n` bytes in ros2cli's units: `512.00 B`, `1.20 KB`, `3.40 MB`.
fn bytes_text(n: f64) -> String {
    if n < 1000.0 {
        format!("{n:.2} B")
    } else if n < 1_000_000.0 {
        format!("{:.2} KB", n / 1000.0)
    } else {
        format!("{:.2} MB", n / 1_000_000.0)
    }
}

impl Bandwidth {
    /// A window of `window` messages (ros2cli's default: 100).
    pub fn new(window: usize) -> Bandwidth {
        Bandwidth {
            seen: Default::default(),
            window: window.max(2),
        }
    }

    /// A message of `bytes` arrived at `t_s`.
    pub fn arrived(&mut self, t_s: f64, bytes: usize) {
        if self.seen.len() == self.window {
            self.seen.pop_front();
        }
        self.seen.push_back((t_s, bytes));
    }

    /// ros2cli's two lines at `now_s`, or `None` before a message:
    /// `1.20 KB/s from 100 messages\n\tMessage size mean: 12.00 B min: 12.00 B max: 12.00 B\n`.
    pub fn report(&self, now_s: f64) -> Option<String> {
        let (first, _) = *self.seen.front()?;
        let n = self.seen.len();
        let total: usize = self.seen.iter().map(|(_, b)| b).sum();
        let span = (now_s - first).max(1e-9);
        let min = self.seen.iter().map(|(_, b)| *b).min().unwrap_or(0);
        let max = self.seen.iter().map(|(_, b)| *b).max().unwrap_or(0);
        Some(format!(
            "{}/s from {n} messages\n\tMessage size mean: {} min: {} max: {}\n",
            bytes_text(total as f64 / span),
            bytes_text(total as f64 / n as f64),
            bytes_text(min as f64),
            bytes_text(max as f64)
        ))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use hiroz_protocol::entity::{TypeHash, TypeInfo};

    fn node(name: &str, ns: &str) -> NodeEntity {
        NodeEntity::new(
            0,
            zenoh::session::ZenohId::default(),
            0,
            name.into(),
            ns.into(),
            String::new(),
        )
    }

    fn endpoint(n: &NodeEntity, kind: EndpointKind, topic: &str, dds: &str) -> EndpointEntity {
        EndpointEntity {
            id: 1,
            node: Some(n.clone()),
            kind,
            topic: topic.into(),
            type_info: Some(TypeInfo::new(dds, TypeHash::new(1, [7; 32]))),
            qos: QosProfile::default(),
        }
    }

    fn talker() -> Seen {
        let t = node("talker", "/");
        let l = node("listener", "/demo");
        Seen {
            nodes: vec![t.clone(), l.clone()],
            endpoints: vec![
                endpoint(
                    &t,
                    EndpointKind::Publisher,
                    "/chatter",
                    "std_msgs::msg::dds_::String_",
                ),
                endpoint(
                    &l,
                    EndpointKind::Subscription,
                    "/chatter",
                    "std_msgs::msg::dds_::String_",
                ),
                endpoint(
                    &t,
                    EndpointKind::Publisher,
                    "/cmd_vel",
                    "geometry_msgs::msg::dds_::Twist_",
                ),
            ],
            ..Seen::default()
        }
    }

    #[test]
    fn lists_read_as_ros2cli_s() {
        let g = talker();
        assert_eq!(node_list(&g), "/demo/listener\n/talker\n");
        assert_eq!(topic_list(&g, false), "/chatter\n/cmd_vel\n");
        assert_eq!(
            topic_list(&g, true),
            "/chatter [std_msgs/msg/String]\n/cmd_vel [geometry_msgs/msg/Twist]\n"
        );
    }

    #[test]
    fn info_names_endpoints_types_and_qos() {
        let g = talker();
        let info = node_info(&g, "/talker").unwrap();
        assert!(info.starts_with("/talker\n  Subscribers:\n\n  Publishers:\n    /chatter: std_msgs/msg/String\n    /cmd_vel: geometry_msgs/msg/Twist\n  Service Servers:\n\n"), "{info}");
        assert_eq!(
            node_info(&g, "/nobody").unwrap_err(),
            "Unable to find node '/nobody'"
        );
        let t = topic_info(&g, "/chatter", false).unwrap();
        assert_eq!(
            t,
            "Type: std_msgs/msg/String\n\nPublisher count: 1\n\nSubscription count: 1\n"
        );
        let v = topic_info(&g, "/chatter", true).unwrap();
        for needle in [
            "Node name: talker\nNode namespace: /\nTopic type: std_msgs/msg/String\n",
            "Endpoint type: PUBLISHER\nQoS profile:\n  Reliability: RELIABLE\n  History (Depth): KEEP_LAST (10)\n",
            "Node name: listener\nNode namespace: /demo\n",
            "  Deadline: Infinite\n",
        ] {
            assert!(v.contains(needle), "{needle:?} in {v}");
        }
        assert_eq!(
            topic_info(&g, "/x", false).unwrap_err(),
            "Unknown topic '/x'"
        );
    }

    #[test]
    fn a_keep_all_endpoint_shows_no_depth_as_ros2cli_does() {
        let mut g = talker();
        g.endpoints[0].qos.history = QosHistory::KeepAll;
        let v = topic_info(&g, "/chatter", true).unwrap();
        assert!(v.contains("  History (Depth): KEEP_ALL\n"), "{v}");
    }

    #[test]
    fn a_name_from_the_wire_never_reaches_the_terminal_raw() {
        let mut g = talker();
        g.nodes.push(node("evil\x1b[2J", "/"));
        assert!(!node_list(&g).contains('\x1b'));
    }

    #[test]
    fn the_graph_reads_publisher_topic_subscriber() {
        let mut g = talker();
        let idle = node("idle", "/");
        g.nodes.push(idle.clone());
        // Its log alone: not drawn, the node then has no topic.
        let log = "rcl_interfaces::msg::dds_::Log_";
        g.endpoints
            .push(endpoint(&idle, EndpointKind::Publisher, "/rosout", log));
        let rates = std::collections::BTreeMap::from([("/chatter".to_string(), 10.0)]);
        assert_eq!(
            graph_lines(&g, &rates),
            "/talker ──▶ /chatter [std_msgs/msg/String] 10.0 msg/s ──▶ /demo/listener\n\
             /talker ──▶ /cmd_vel [geometry_msgs/msg/Twist]\n\
             nodes with no topic: /idle\n\
             (not drawn: /rosout, every node's)\n"
        );
    }

    #[test]
    fn bw_reports_as_ros2cli_does() {
        let mut b = Bandwidth::new(100);
        assert!(b.report(0.0).is_none());
        for i in 0..10 {
            b.arrived(f64::from(i) * 0.1, 120);
        }
        assert_eq!(
            b.report(1.0).unwrap(),
            "1.20 KB/s from 10 messages\n\tMessage size mean: 120.00 B min: 120.00 B max: 120.00 B\n"
        );
    }

    #[test]
    fn hz_reports_as_ros2cli_does() {
        let mut r = Rate::new(10_000);
        assert!(r.report().is_none());
        for i in 0..21 {
            r.arrived(f64::from(i) * 0.05);
        }
        let text = r.report().unwrap();
        assert!(
            text.starts_with(
                "average rate: 20.000\n\tmin: 0.050s max: 0.050s std dev: 0.00000s window: 21\n"
            ),
            "{text}"
        );
        let mut small = Rate::new(3);
        for i in 0..10 {
            small.arrived(f64::from(i));
        }
        assert!(small.report().unwrap().ends_with("window: 3\n"));
    }
}
