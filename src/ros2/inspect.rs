//! `ratelab ros2`: any rmw_zenoh graph read from the other side, as ros2cli reads it, without
//! a ROS 2 installation. The graph is what the domain's liveliness tokens say
//! (`@ros2_lv/<domain>/…`: a node's NN, a publisher's MP, a subscription's MS, with types
//! and QoS), parsed by [`super::rmw_zenoh`] ([`seen`], [`Seen`]); what ros2cli prints of it is
//! written by pure functions over that data ([`node_list`], [`node_info`], [`topic_list`],
//! [`topic_info`]), and a topic's messages are heard on its data key ([`subscribe`]) and
//! written by [`super::echo`] or counted ([`Rate`], [`Bandwidth`], from [`super::figures`]).
//!
//! Output follows ros2cli (0.36.1, Kilted's; checked against its captures in
//! `../shared/fixtures/ros2-real/kilted-ros2cli/`): `node list` prints `/talker`; `topic
//! list -t` prints `/cmd_vel [geometry_msgs/msg/Twist]`; `topic info` a line each, `-v` an
//! endpoint block per node with its QoS; `topic hz` `average rate: 20.000` then `\tmin: …s
//! max: …s std dev: …s window: N` (N intervals); `topic bw` `524 B/s from 20 messages` then
//! the sizes in the same unit. Its rules too: a name with a part beginning with `_` is hidden
//! unless asked for ([`super::names::is_hidden_name`], [`super::names::is_hidden_node`]);
//! nodes that share a name are listed each and warned of ([`SHARED_NAME_WARNING`]), and
//! `node info` shows one of them, never their union; a topic of two types is refused by
//! `echo`, `hz` and `bw` ([`one_type`]). Names from the wire are written with their control
//! characters escaped.

pub use super::figures::{Bandwidth, Rate};
use super::names::{is_hidden_name, is_hidden_node};
pub use super::rmw_zenoh::entity::{EndpointEntity, EndpointKind, Entity, NodeEntity};
use super::rmw_zenoh::key_expr::KeyExprFormat;
use super::rmw_zenoh::qos::{
    QosDurability, QosDuration, QosHistory, QosLiveliness, QosProfile, QosReliability,
};
use super::{zerr, Ros2Error};
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
        match KeyExprFormat.parse_liveliness(key) {
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
    ratelab_core::text::printable(s).into_owned()
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

/// ros2cli's warning on stderr, before the list, when `ros2 node list` lists a name twice
/// (ros2node's `verb/list.py`).
pub const SHARED_NAME_WARNING: &str = "WARNING: Be aware that there are nodes in the graph that share an exact name, which can have unintended side effects.";

/// ros2cli's warning on stderr, before the information, when `ros2 node info NODE` is asked
/// of a name `count` nodes share (ros2node's `INFO_NONUNIQUE_WARNING_TEMPLATE`): `There are 2
/// nodes in the graph with the exact name "/dup". You are seeing information about only one
/// of them.`
pub fn shared_name_info_warning(count: usize, node: &str) -> String {
    format!(
        "There are {count} nodes in the graph with the exact name \"{}\". You are seeing information about only one of them.",
        printable(node)
    )
}

/// The nodes ros2cli shows: every one when `all`, else those whose base name is not hidden
/// ([`is_hidden_node`]: ros2node's `get_node_names`).
fn shown_nodes(g: &Seen, all: bool) -> impl Iterator<Item = &NodeEntity> {
    g.nodes
        .iter()
        .filter(move |n| all || !is_hidden_node(&n.name))
}

/// `node` as ros2node's `get_absolute_node_name` makes it: `/` before a name without one.
fn absolute(node: &str) -> String {
    if node.starts_with('/') {
        node.to_string()
    } else {
        format!("/{node}")
    }
}

/// What `ros2 node list` prints.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct NodeList {
    /// stdout: each node's fully qualified name, sorted, one a line; a name `k` nodes share,
    /// `k` times (ros2cli lists them, it does not merge them).
    pub names: String,
    /// stderr, first: [`SHARED_NAME_WARNING`] when two listed nodes share a name.
    pub warning: Option<&'static str>,
}

/// `ros2 node list [-a]` (ros2node's `verb/list.py`): every node's fully qualified name,
/// sorted, one a line, duplicates kept and warned of; a node whose base name begins with `_`
/// only when `all` (`-a`, `--all`), as [`is_hidden_node`] says.
pub fn node_list(g: &Seen, all: bool) -> NodeList {
    let mut names: Vec<String> = shown_nodes(g, all).map(fq_name).collect();
    names.sort();
    let shared = names.windows(2).any(|w| w[0] == w[1]);
    NodeList {
        names: names.into_iter().map(|n| n + "\n").collect(),
        warning: shared.then_some(SHARED_NAME_WARNING),
    }
}

/// `ros2 node list -c [-a]`: how many nodes `node list` lists (a shared name once per node).
pub fn node_count(g: &Seen, all: bool) -> usize {
    shown_nodes(g, all).count()
}

/// Node `node` (`/talker`, or `talker` in the root namespace) by its fully qualified name,
/// when the graph has it and ros2cli shows it (`all`: a hidden one too, as ros2cli's
/// `--include-hidden-nodes`; else ros2cli says `Node not found`).
pub fn known_node(g: &Seen, node: &str, all: bool) -> Option<String> {
    let want = absolute(node);
    shown_nodes(g, all)
        .any(|n| fq_name(n) == want)
        .then_some(want)
}

/// What `ros2 node info` prints.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct NodeInfo {
    /// stdout: the name, then each section.
    pub text: String,
    /// stderr, first: [`shared_name_info_warning`] when nodes share the name.
    pub warning: Option<String>,
}

/// Whether `a` and `b` are one node: one session's node id, and its name.
fn same_node(a: &NodeEntity, b: &NodeEntity) -> bool {
    a.z_id == b.z_id && a.id == b.id && a.name == b.name && a.namespace == b.namespace
}

/// `ros2 node info NODE [--include-hidden]` (ros2node's `verb/info.py`): its subscribers,
/// publishers, service servers and clients, each name with its types (`/mixed: a, b` when
/// the node has it under two), sorted; an endpoint with a hidden name ([`is_hidden_name`])
/// only when `include_hidden`, and a hidden node is found only then. When nodes share the
/// name, ros2cli warns and shows one of them, never their union: rmw_zenoh_cpp's graph
/// cache keeps them in a multimap and answers for the first it discovered, which depends
/// on discovery order; ratelab shows the same one every time, the first by Zenoh session
/// id, then node id.
///
/// # Errors
/// One line when no shown node has that name (ros2cli's `Unable to find node '/x'`).
pub fn node_info(g: &Seen, node: &str, include_hidden: bool) -> Result<NodeInfo, String> {
    let want = absolute(node);
    let mut named: Vec<&NodeEntity> = shown_nodes(g, include_hidden)
        .filter(|n| fq_name(n) == want)
        .collect();
    named.sort_by_key(|n| (n.z_id, n.id));
    let Some(&one) = named.first() else {
        return Err(format!("Unable to find node '{}'", printable(node)));
    };
    let shared = named.len() > 1;
    // A name one node has: its endpoints by name, as ever; a shared one: the chosen node's.
    let mine = |n: &NodeEntity| {
        if shared {
            same_node(n, one)
        } else {
            fq_name(n) == want
        }
    };
    let of = |kind: EndpointKind| -> String {
        let mut topics: std::collections::BTreeMap<String, BTreeSet<String>> = Default::default();
        for e in &g.endpoints {
            let shown = include_hidden || !is_hidden_name(&e.topic);
            if e.kind == kind && shown && e.node.as_ref().is_some_and(mine) {
                topics
                    .entry(printable(&e.topic))
                    .or_default()
                    .insert(type_name(e));
            }
        }
        // ros2cli prints an empty section as an empty line.
        if topics.is_empty() {
            return "\n".to_string();
        }
        topics
            .into_iter()
            .map(|(t, tys)| {
                format!(
                    "    {t}: {}\n",
                    tys.into_iter().collect::<Vec<_>>().join(", ")
                )
            })
            .collect()
    };
    let text = format!(
        "{want}\n  Subscribers:\n{}  Publishers:\n{}  Service Servers:\n{}  Service Clients:\n{}  Action Servers:\n\n  Action Clients:\n\n",
        of(EndpointKind::Subscription),
        of(EndpointKind::Publisher),
        of(EndpointKind::Service),
        of(EndpointKind::Client),
    );
    let warning = shared.then(|| shared_name_info_warning(named.len(), &want));
    Ok(NodeInfo { text, warning })
}

/// Every topic (a publisher's or a subscription's name) with its types, sorted; one with a
/// hidden name ([`is_hidden_name`]) only when `include_hidden`.
fn topics(g: &Seen, include_hidden: bool) -> std::collections::BTreeMap<String, BTreeSet<String>> {
    let mut topics: std::collections::BTreeMap<String, BTreeSet<String>> = Default::default();
    for e in g.endpoints.iter().filter(|e| is_topic(e)) {
        if include_hidden || !is_hidden_name(&e.topic) {
            topics
                .entry(printable(&e.topic))
                .or_default()
                .insert(type_name(e));
        }
    }
    topics
}

/// `ros2 topic list [-t] [--include-hidden-topics]` (ros2topic's `verb/list.py`): every
/// topic, sorted, with its types when `types` (`/mixed [a, b]`: sorted, where ros2cli takes
/// rmw_zenoh_cpp's order, which is no fixed one); a hidden one ([`is_hidden_name`]) only
/// when `include_hidden`.
pub fn topic_list(g: &Seen, types: bool, include_hidden: bool) -> String {
    topics(g, include_hidden)
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

/// `ros2 topic list -v [--include-hidden-topics]` (ros2topic's `verb/list.py`,
/// `show_topic_info`, each section printed by `print`, so an empty line after it): a
/// `Published topics:` section with a line ` * /chatter [std_msgs/msg/String] 1 publisher`
/// (`2 publishers`) per topic some node publishes, then `Subscribed topics:` with ` * … 1
/// subscriber` per topic some node subscribes to, the topics as [`topic_list`] lists them
/// (sorted, hidden ones only when `include_hidden`), every endpoint of the topic counted, a
/// hidden node's too (rclpy's `count_publishers`). Nothing at all when there is no topic.
/// ros2cli's own node (`/_ros2cli_…`) adds its `/rosout` and `/parameter_events` publishers
/// to their counts; ratelab reads the graph without being a node, so it adds none.
pub fn topic_list_verbose(g: &Seen, include_hidden: bool) -> String {
    let types = topics(g, include_hidden);
    if types.is_empty() {
        return String::new();
    }
    // (publishers, subscriptions) by topic, in one pass.
    let mut counts: std::collections::BTreeMap<String, (usize, usize)> = Default::default();
    for e in g.endpoints.iter().filter(|e| is_topic(e)) {
        let c = counts.entry(printable(&e.topic)).or_default();
        match e.kind {
            EndpointKind::Publisher => c.0 += 1,
            _ => c.1 += 1,
        }
    }
    let section = |published: bool| {
        let (head, what) = if published {
            ("Published", "publisher")
        } else {
            ("Subscribed", "subscriber")
        };
        let mut text = format!("{head} topics:\n");
        for (topic, tys) in &types {
            let n = counts
                .get(topic)
                .map_or(0, |&(p, s)| if published { p } else { s });
            if n > 0 {
                let tys: Vec<&str> = tys.iter().map(String::as_str).collect();
                let plural = if n > 1 { "s" } else { "" };
                text.push_str(&format!(
                    " * {topic} [{}] {n} {what}{plural}\n",
                    tys.join(", ")
                ));
            }
        }
        text + "\n"
    };
    section(true) + &section(false)
}

/// `ros2 topic list -c`: how many topics `topic list` lists.
pub fn topic_count(g: &Seen, include_hidden: bool) -> usize {
    topics(g, include_hidden).len()
}

/// The one type `echo`, `hz` and `bw` take `topic` to have, over its publishers and
/// subscriptions (hidden or not), as ros2topic's `api._get_msg_class` requires; `None` when
/// no endpoint has the topic.
///
/// # Errors
/// ros2cli's words, whichever of the three verbs asked, when the topic has more than one:
/// `Cannot echo topic '/mixed', as it contains more than one type: [std_msgs/msg/Int32,
/// std_msgs/msg/String]` (the types sorted).
pub fn one_type(g: &Seen, topic: &str) -> Result<Option<String>, String> {
    one_type_as(g, topic, topic)
}

/// [`one_type`] of `topic` (the name expanded, `/chatter`) for a command given it as `said`
/// (`chatter`): ros2cli's refusal quotes the name as it was given.
///
/// # Errors
/// [`one_type`]'s, naming `said`.
pub fn one_type_as(g: &Seen, topic: &str, said: &str) -> Result<Option<String>, String> {
    let types: BTreeSet<String> = g
        .endpoints
        .iter()
        .filter(|e| is_topic(e) && e.topic == topic)
        .map(type_name)
        .collect();
    if types.len() > 1 {
        return Err(format!(
            "Cannot echo topic '{}', as it contains more than one type: [{}]",
            printable(said),
            types.into_iter().collect::<Vec<_>>().join(", ")
        ));
    }
    Ok(types.into_iter().next())
}

fn duration(d: &QosDuration) -> String {
    if *d == QosDuration::INFINITE {
        "Infinite".into()
    } else {
        // Saturating: a token's numbers are anyone's (up to u64::MAX each).
        let ns = d.sec.saturating_mul(1_000_000_000).saturating_add(d.nsec);
        format!("{ns} nanoseconds")
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
    if q.durability == QosDurability::TransientLocal {
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
        QosHistory::KeepAll(_) => "KEEP_ALL".into(),
    }
}

fn qos_block(q: &QosProfile) -> String {
    let (history, reliability) = (history_words(q), reliability_word(q));
    let durability = match q.durability {
        QosDurability::Volatile => "VOLATILE",
        QosDurability::TransientLocal => "TRANSIENT_LOCAL",
    };
    let liveliness = match q.liveliness {
        QosLiveliness::Automatic => "AUTOMATIC",
        QosLiveliness::ManualByTopic => "MANUAL_BY_TOPIC",
    };
    format!(
        "QoS profile:\n  Reliability: {reliability}\n  History (Depth): {history}\n  Durability: {durability}\n  Lifespan: {}\n  Deadline: {}\n  Liveliness: {liveliness}\n  Liveliness lease duration: {}\n",
        duration(&q.lifespan),
        duration(&q.deadline),
        duration(&q.liveliness_lease_duration)
    )
}

/// `ros2 topic info TOPIC [-v]` (ros2topic's `verb/info.py`): its type, publisher and
/// subscription counts, a line each (`-v`: an empty line after each, and each endpoint with
/// its node, type hash and QoS). A topic of two types shows them as Python prints a list,
/// `Type: ['std_msgs/msg/Int32', 'std_msgs/msg/String']` (sorted). A hidden topic is found
/// too, as ros2cli's.
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
    let types: Vec<String> = ends
        .iter()
        .map(|(_, e)| type_name(e))
        .collect::<BTreeSet<String>>()
        .into_iter()
        .collect();
    // ros2cli: `'Type: %s' % (types[0] if len(types) == 1 else types)`.
    let type_text = match types.as_slice() {
        [one] => one.clone(),
        many => {
            let quoted: Vec<String> = many
                .iter()
                .map(|t| super::param_cli::python_str(t))
                .collect();
            format!("[{}]", quoted.join(", "))
        }
    };
    let count = |k: EndpointKind| ends.iter().filter(|(_, e)| e.kind == k).count();
    let end = if verbose { "\n\n" } else { "\n" };
    let mut out = format!(
        "Type: {type_text}{end}Publisher count: {}{end}",
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
        "Subscription count: {}{end}",
        count(EndpointKind::Subscription)
    ));
    if verbose {
        out.push_str(&block(EndpointKind::Subscription, "SUBSCRIPTION"));
    }
    // `-v` ends on the empty line after its last endpoint (or its last count), as ros2cli's.
    Ok(out)
}

/// Open a Zenoh session for reading a domain: a client of the router at `connect`
/// (`tcp/localhost:7447` by default, where rmw_zenoh's nodes find theirs), `ZENOH_CONFIG_OVERRIDE`
/// applied as rmw_zenoh applies it ([`super::session::parse_override`]), and the router
/// looked for as `ZENOH_ROUTER_CHECK_ATTEMPTS` says ([`super::session::router_check`], read
/// as the nodes' session reads it): N attempts one second apart (unset: one), `0` until one
/// answers; after a first attempt fails it says on stderr that it waits, and `stop`
/// (Ctrl-C) ends the wait. The endpoints it names are those it connects to
/// (`ZENOH_CONFIG_OVERRIDE`'s `connect/endpoints` when set). A negative value, which lets
/// rmw_zenoh's nodes go on without a router, gives a reader one attempt: a reader is the
/// router's client and has nothing to read without one.
///
/// # Errors
/// [`Ros2Error::Usage`] for a bad override, a bad `ZENOH_ROUTER_CHECK_ATTEMPTS`, an endpoint
/// whose port is not one ([`check_router_endpoint`]) or a wait stopped; [`Ros2Error::Zenoh`]
/// when no router answers (named, with how to start one).
pub fn open(
    connect: Option<&str>,
    env: &super::session::SessionEnv,
    stop: &ratelab_runtime::scheduler::StopFlag,
) -> Result<zenoh::Session, Ros2Error> {
    use super::session::set;
    let given = connect
        .unwrap_or(super::session::DEFAULT_ROUTER)
        .to_string();
    let check = super::session::router_check(env.router_check_attempts.as_deref())
        .map_err(Ros2Error::Usage)?;
    let mut config = zenoh::Config::default();
    set(&mut config, "mode", "\"client\"")?;
    set(&mut config, "scouting/multicast/enabled", "false")?;
    let quoted = serde_json::to_string(&given).map_err(zerr)?;
    set(&mut config, "connect/endpoints", &format!("[{quoted}]"))?;
    if let Some(o) = env.config_override.as_deref() {
        for (k, v) in super::session::parse_override(o).map_err(Ros2Error::Usage)? {
            // A reader stays a client of the router, whatever the nodes' override says.
            if k != "mode" && k != "listen/endpoints" {
                set(&mut config, &k, &v)?;
            }
        }
    }
    // Where it looks, as the override may have said it (rmw_zenoh's usual way).
    let mut endpoints = super::session::connect_endpoints(&config);
    if endpoints.is_empty() {
        endpoints.push(given);
    }
    for e in &endpoints {
        check_router_endpoint(e)?;
    }
    let endpoint = printable(&endpoints.join(", "));
    // Each attempt is one session opened (a client opens only with its router there).
    let probe = || zenoh::open(config.clone()).wait();
    let every = Duration::from_secs(1);
    match super::session::look_for_router(check, &endpoint, stop, every, probe)? {
        Ok(session) => Ok(session),
        Err(failed) => Err(no_router(&endpoint, &failed.to_string())),
    }
}

/// The refusal when no router answered at `endpoint`, Zenoh's reason `why` in its first
/// line (Zenoh's message names its own source file after " at ": left out).
fn no_router(endpoint: &str, why: &str) -> Ros2Error {
    Ros2Error::Zenoh(format!(
        "no Zenoh router answered at {endpoint} ({}): start one (`ros2 run rmw_zenoh_cpp rmw_zenohd`, `zenohd`, or a `ratelab run --ros2`, which runs one), or name it with --connect",
        why.lines()
            .next()
            .unwrap_or_default()
            .split(" at /")
            .next()
            .unwrap_or_default()
            .trim_end_matches(['!', ' '])
    ))
}

/// Check a router's endpoint before any session opens: for the protocols over IP (`tcp`,
/// `udp`, `tls`, `quic`, `ws`), `PROTO/HOST:PORT` with PORT in 1..=65535 (after it, Zenoh's
/// `?metadata` and `#config` may follow). Other protocols (`unixsock-stream/PATH`, …) are
/// left to Zenoh, which names what it refuses.
///
/// # Errors
/// [`Ros2Error::Usage`]: `--connect ENDPOINT: why`.
pub fn check_router_endpoint(endpoint: &str) -> Result<(), Ros2Error> {
    let bad = |why: &str| Ros2Error::Usage(format!("--connect {}: {why}", printable(endpoint)));
    let Some((proto, rest)) = endpoint.split_once('/') else {
        return Ok(());
    };
    if !["tcp", "udp", "tls", "quic", "ws"].contains(&proto) {
        return Ok(());
    }
    let address = rest.split(['?', '#']).next().unwrap_or_default();
    let Some((host, port)) = address.rsplit_once(':').filter(|_| !address.ends_with(']')) else {
        return Err(bad(&format!("expected {proto}/HOST:PORT")));
    };
    if host
        .trim_start_matches('[')
        .trim_end_matches(']')
        .is_empty()
    {
        return Err(bad(&format!("no host: expected {proto}/HOST:PORT")));
    }
    match port.parse::<u16>() {
        Ok(0) => Err(bad("port 0 means any port: connect to the router's")),
        Ok(_) => Ok(()),
        Err(_) => Err(bad("the port must be a number in 1..=65535")),
    }
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

/// Subscribe to `publisher`'s topic on its data key (its domain, topic, type and hash), a
/// plain (volatile) subscriber, as `ratelab ros2 graph` counts messages: `on` gets each
/// message's payload. `echo`, `hz` and `bw` subscribe with the QoS ros2cli chooses instead
/// ([`super::subscription::subscribe`]).
///
/// # Errors
/// [`Ros2Error::Zenoh`]: the key could not be made or the declaration failed.
pub fn subscribe(
    session: &zenoh::Session,
    publisher: &EndpointEntity,
    on: impl Fn(Vec<u8>) + Send + Sync + 'static,
) -> Result<zenoh::pubsub::Subscriber<()>, Ros2Error> {
    let key = KeyExprFormat.topic_key_expr(publisher).map_err(zerr)?;
    session
        .declare_subscriber(key)
        .callback(move |s| on(s.payload().to_bytes().into_owned()))
        .wait()
        .map_err(zerr)
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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::rmw_zenoh::entity::{TypeHash, TypeInfo};

    fn node(name: &str, ns: &str) -> NodeEntity {
        NodeEntity::new(
            0,
            // One fixed session (`ZenohId::default()` is a random one).
            "1".parse::<zenoh::session::ZenohId>().expect("a Zenoh id"),
            0,
            name.into(),
            ns.into(),
            String::new(),
        )
    }

    #[test]
    fn a_router_endpoint_over_ip_needs_a_host_and_a_port() {
        for ok in [
            "tcp/localhost:7447",
            "tls/[::1]:7447",
            "udp/10.0.0.1:7447#iface=eth0",
            "tcp/h:1?prio=1",
            "unixsock-stream/tmp/z.sock",
            "garbage",
        ] {
            assert!(check_router_endpoint(ok).is_ok(), "{ok}");
        }
        for (bad, why) in [
            ("tcp/h:99999", "1..=65535"),
            ("tcp/h:x", "1..=65535"),
            ("tcp/h:0", "port 0"),
            ("quic/h", "expected quic/HOST:PORT"),
            ("ws/:80", "no host"),
            ("tcp/[::1]", "expected tcp/HOST:PORT"),
        ] {
            let Err(Ros2Error::Usage(said)) = check_router_endpoint(bad) else {
                panic!("{bad} taken")
            };
            assert!(
                said.starts_with(&format!("--connect {bad}: ")) && said.contains(why),
                "{said}"
            );
        }
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
        let list = node_list(&g, false);
        assert_eq!(list.names, "/demo/listener\n/talker\n");
        assert_eq!(list.warning, None);
        assert_eq!(topic_list(&g, false, false), "/chatter\n/cmd_vel\n");
        assert_eq!(
            topic_list(&g, true, false),
            "/chatter [std_msgs/msg/String]\n/cmd_vel [geometry_msgs/msg/Twist]\n"
        );
        assert_eq!((node_count(&g, false), topic_count(&g, false)), (2, 2));
    }

    /// `topic list -v` as ros2topic's `verb/list.py` prints it: two sections, each followed
    /// by an empty line, a count per topic with `s` after more than one, a topic in a
    /// section only when it has such endpoints; nothing for an empty graph.
    #[test]
    fn the_verbose_list_reads_as_ros2cli_s() {
        let mut g = talker();
        let other = node("other", "/");
        g.endpoints.push(endpoint(
            &other,
            EndpointKind::Publisher,
            "/chatter",
            "std_msgs::msg::dds_::String_",
        ));
        assert_eq!(
            topic_list_verbose(&g, false),
            "Published topics:\n * /chatter [std_msgs/msg/String] 2 publishers\n * /cmd_vel [geometry_msgs/msg/Twist] 1 publisher\n\nSubscribed topics:\n * /chatter [std_msgs/msg/String] 1 subscriber\n\n"
        );
        assert_eq!(topic_list_verbose(&Seen::default(), false), "");
    }

    #[test]
    fn info_names_endpoints_types_and_qos() {
        let g = talker();
        let info = node_info(&g, "/talker", false).unwrap();
        assert_eq!(info.warning, None);
        let info = info.text;
        assert!(info.starts_with("/talker\n  Subscribers:\n\n  Publishers:\n    /chatter: std_msgs/msg/String\n    /cmd_vel: geometry_msgs/msg/Twist\n  Service Servers:\n\n"), "{info}");
        assert_eq!(
            node_info(&g, "/nobody", false).unwrap_err(),
            "Unable to find node '/nobody'"
        );
        // Plain: a line each (real ros2cli's `topic info /chatter`, kilted-ros2cli/step2).
        let t = topic_info(&g, "/chatter", false).unwrap();
        assert_eq!(
            t,
            "Type: std_msgs/msg/String\nPublisher count: 1\nSubscription count: 1\n"
        );
        // Verbose: an empty line after each.
        let v = topic_info(&g, "/chatter", true).unwrap();
        assert!(
            v.starts_with("Type: std_msgs/msg/String\n\nPublisher count: 1\n\nNode name: talker\n"),
            "{v}"
        );
        // To the empty line after the last endpoint, as ros2cli ends it.
        assert!(v.ends_with("Infinite\n\n"), "{v}");
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
        g.endpoints[0].qos.history = QosHistory::KeepAll(10);
        let v = topic_info(&g, "/chatter", true).unwrap();
        assert!(v.contains("  History (Depth): KEEP_ALL\n"), "{v}");
    }

    #[test]
    fn a_name_from_the_wire_never_reaches_the_terminal_raw() {
        let mut g = talker();
        g.nodes.push(node("evil\x1b[2J", "/"));
        assert!(!node_list(&g, true).names.contains('\x1b'));
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

    /// A node `name` in `ns` with node id `id` of session 0.
    fn node_id(name: &str, ns: &str, id: usize) -> NodeEntity {
        NodeEntity {
            id,
            ..node(name, ns)
        }
    }

    const STRING: &str = "std_msgs::msg::dds_::String_";
    const INT32: &str = "std_msgs::msg::dds_::Int32_";

    /// The real graph of `kilted-ros2cli/step2/edge` (real rclpy over rmw_zenoh_cpp), in
    /// part: a hidden node publishing a hidden topic, two nodes named `/dup` (the first, by
    /// node id, publishing `/dup/private` and serving a service; the second `/mixed` as
    /// Int32), and `/talker` publishing `/mixed` as String.
    fn edges() -> Seen {
        let hidden = node_id("_hidden_node", "", 0);
        let (dup1, dup2) = (node_id("dup", "", 1), node_id("dup", "", 2));
        let talker = node_id("talker", "", 3);
        let private = endpoint(&dup1, EndpointKind::Publisher, "/dup/private", STRING);
        let srv = "rcl_interfaces::srv::dds_::ListParameters_";
        Seen {
            // Listed as a liveliness query may answer: not in node id order.
            nodes: vec![talker.clone(), dup2.clone(), hidden.clone(), dup1.clone()],
            endpoints: vec![
                endpoint(&hidden, EndpointKind::Publisher, "/_secret", STRING),
                endpoint(&dup1, EndpointKind::Service, "/dup/list_parameters", srv),
                private,
                endpoint(&dup2, EndpointKind::Publisher, "/mixed", INT32),
                endpoint(&talker, EndpointKind::Publisher, "/mixed", STRING),
                endpoint(&talker, EndpointKind::Service, "/talker/_hidden_srv", srv),
            ],
            ..Seen::default()
        }
    }

    #[test]
    fn hidden_nodes_and_topics_are_listed_only_when_asked() {
        let g = edges();
        // Real ros2cli's `node list` (edge/ros2-node-list.txt): /_hidden_node left out...
        assert_eq!(node_list(&g, false).names, "/dup\n/dup\n/talker\n");
        // ...and listed with -a (ros2-node-list-a.txt, less ros2cli's own /_ros2cli_ node).
        assert_eq!(
            node_list(&g, true).names,
            "/_hidden_node\n/dup\n/dup\n/talker\n"
        );
        assert_eq!((node_count(&g, false), node_count(&g, true)), (3, 4));
        // ros2-topic-list-t.txt and ros2-topic-list-t-hidden.txt.
        assert_eq!(
            topic_list(&g, true, false),
            "/dup/private [std_msgs/msg/String]\n/mixed [std_msgs/msg/Int32, std_msgs/msg/String]\n"
        );
        assert_eq!(
            topic_list(&g, false, true),
            "/_secret\n/dup/private\n/mixed\n"
        );
        assert_eq!((topic_count(&g, false), topic_count(&g, true)), (2, 3));
        // A hidden node is not found unless asked for; a hidden topic's info is given.
        assert_eq!(known_node(&g, "/_hidden_node", false), None);
        assert_eq!(
            known_node(&g, "_hidden_node", true).as_deref(),
            Some("/_hidden_node")
        );
        assert_eq!(
            node_info(&g, "/_hidden_node", false).unwrap_err(),
            "Unable to find node '/_hidden_node'"
        );
        let info = node_info(&g, "/_hidden_node", true).unwrap().text;
        assert!(
            info.contains("  Publishers:\n    /_secret: std_msgs/msg/String\n"),
            "{info}"
        );
        assert!(topic_info(&g, "/_secret", false).is_ok());
        // A node's hidden service, only with --include-hidden.
        let shown = node_info(&g, "/talker", false).unwrap().text;
        assert!(shown.contains("  Service Servers:\n\n"), "{shown}");
        let all = node_info(&g, "/talker", true).unwrap().text;
        assert!(
            all.contains(
                "  Service Servers:\n    /talker/_hidden_srv: rcl_interfaces/srv/ListParameters\n"
            ),
            "{all}"
        );
    }

    #[test]
    fn a_shared_node_name_is_listed_twice_warned_of_and_never_merged() {
        let g = edges();
        assert_eq!(node_list(&g, false).warning, Some(SHARED_NAME_WARNING));
        // ros2node's words, as real ros2cli printed them (edge/ros2-node-list.txt).
        assert_eq!(
            SHARED_NAME_WARNING,
            "WARNING: Be aware that there are nodes in the graph that share an exact name, which can have unintended side effects."
        );
        // A name shared only by hidden nodes warns only when they are listed.
        let mut quiet = edges();
        quiet.nodes.retain(|n| n.name != "dup");
        quiet.nodes.push(node_id("_twin", "", 7));
        quiet.nodes.push(node_id("_twin", "", 8));
        assert_eq!(node_list(&quiet, false).warning, None);
        assert_eq!(node_list(&quiet, true).warning, Some(SHARED_NAME_WARNING));
        // node info: the warning (edge/ros2-node-info-dup.txt), then one node's endpoints,
        // the first by node id, whatever order the graph was heard in; not the other's.
        let info = node_info(&g, "/dup", false).unwrap();
        assert_eq!(
            info.warning.as_deref(),
            Some("There are 2 nodes in the graph with the exact name \"/dup\". You are seeing information about only one of them.")
        );
        assert_eq!(
            info.text,
            "/dup\n  Subscribers:\n\n  Publishers:\n    /dup/private: std_msgs/msg/String\n  Service Servers:\n    /dup/list_parameters: rcl_interfaces/srv/ListParameters\n  Service Clients:\n\n  Action Servers:\n\n  Action Clients:\n\n"
        );
        let mut reversed = g.clone();
        reversed.nodes.reverse();
        reversed.endpoints.reverse();
        assert_eq!(node_info(&reversed, "dup", false).unwrap(), info);
    }

    #[test]
    fn a_topic_of_two_types_is_shown_as_ros2cli_shows_it_and_refused_to_echo() {
        let g = edges();
        // edge/ros2-topic-info-mixed.txt, line for line.
        assert_eq!(
            topic_info(&g, "/mixed", false).unwrap(),
            "Type: ['std_msgs/msg/Int32', 'std_msgs/msg/String']\nPublisher count: 2\nSubscription count: 0\n"
        );
        assert!(topic_info(&g, "/mixed", true).unwrap().starts_with(
            "Type: ['std_msgs/msg/Int32', 'std_msgs/msg/String']\n\nPublisher count: 2\n\n"
        ));
        // edge/ros2-echo-mixed.txt.
        assert_eq!(
            one_type(&g, "/mixed").unwrap_err(),
            "Cannot echo topic '/mixed', as it contains more than one type: [std_msgs/msg/Int32, std_msgs/msg/String]"
        );
        assert_eq!(
            one_type(&g, "/dup/private"),
            Ok(Some("std_msgs/msg/String".to_string()))
        );
        assert_eq!(one_type(&g, "/nothing"), Ok(None));
        // A node holding a topic under two types says both on one line, as ros2cli joins them.
        let mut both = g.clone();
        let talker = node_id("talker", "", 3);
        both.endpoints
            .push(endpoint(&talker, EndpointKind::Publisher, "/mixed", INT32));
        let info = node_info(&both, "/talker", false).unwrap().text;
        assert!(
            info.contains("  Publishers:\n    /mixed: std_msgs/msg/Int32, std_msgs/msg/String\n"),
            "{info}"
        );
    }
}
