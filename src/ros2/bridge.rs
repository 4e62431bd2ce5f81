//! A running graph offered as a ROS 2 graph (rmw_zenoh's format, ros2/rmw_zenoh
//! `docs/design.md`):
//!
//! - each ratelab process is a ROS 2 node in the root namespace: a liveliness token
//!   `@ros2_lv/<domain>/<zid>/<nid>/<nid>/NN/%/%/<name>`; one more node, `ratelab`,
//!   publishes `/clock`;
//! - each topic's publisher and subscriber hold MP/MS tokens naming the topic, its type, its
//!   RIHS01 hash and its QoS as ratelab runs it: a publisher's what it offers (history and
//!   depth, deadline, lifespan, reliability, durability, its node's liveliness lease), a
//!   subscription's its own (`requested_qos_of`: no lifespan, no lease unless requested);
//! - each message is put on `<domain>/<topic>/<dds type>/<RIHS01>` as CDR
//!   ([`super::types`]) with rmw_zenoh's attachment: sequence number (ratelab's `seq` + 1,
//!   so it starts at 1 and grows by 1), source timestamp (wall clock, ns since the Unix
//!   epoch, as rmw_zenoh takes it) and the publisher's 16-byte GID;
//! - `/clock` (`rosgraph_msgs/msg/Clock`, best effort, depth 1) carries the run time: before
//!   each virtual instant under the virtual clock, and before any message stamped later than
//!   the last clock under both clocks, so a message's header stamp is never ahead of
//!   `/clock`. With an external node under the virtual clock (the lockstep,
//!   [`super::external`]) `/clock = t` follows instead the messages published at `t` by the
//!   nodes ranked before the external node ticking at `t` (or all of instant `t`'s when none
//!   ticks then): a message is then ahead of `/clock` until the clock reaches its instant;
//! - an external node's own tokens and publishers are its program's: ratelab declares none
//!   for it, and what it publishes is not put again (only written to the bag);
//! - each node's log goes out on its `/rosout` ([`super::node_api`]), the lines its
//!   constructor wrote while the graph was built first ([`Offer::build_lines`]);
//! - with `--bag`, everything put is also written to a rosbag2 bag ([`super::bag`]): the
//!   graph's topics, `/clock`, and each node's `/rosout` and `/parameter_events` (its
//!   declared parameters first, at run time 0).
//!
//! Messages leave through a `ratelab::topic::Tap` on each topic and a channel to one bridge
//! thread: no node puts on Zenoh itself. Under the virtual clock a publisher waits when the
//! channel is full, and the bridge's Zenoh publishers wait for room in Zenoh's queue
//! (`Declarer::waiting`) (the run stays byte-identical, only slower: it keeps pace with
//! the wall clock anyway); under the real clock a full channel drops the ROS 2 copy and counts it
//! ([`BridgeReport::dropped`]), so the nodes' timing is never the bridge's.

use super::bag::{Bag, BagTopic};
use super::names::{check_node_name, check_topic_name};
use super::node_api::{self, NodeApi};
use super::parameters::NodeParameters;
use super::rmw_zenoh::entity::{EndpointKind, Entity, NodeEntity};
use super::rmw_zenoh::key_expr::KeyExprFormat;
use super::rmw_zenoh::qos::{QosDurability, QosDuration, QosHistory, QosProfile, QosReliability};
use super::ros_type_of;
use super::session::{Ros2Session, Router};
use super::types::{clock_type, encode_clock, type_info};
pub use super::wire::{attachment, gid};
use super::wire::{Declarer, Outlet};
use super::{Ros2Error, Ros2Options};
use crossbeam_channel::{Receiver, Sender, TrySendError};
use ratelab_core::msg::AnyTopic;
use ratelab_core::msg::MsgData;
use ratelab_core::qos::{History, Reliability};
use ratelab_core::textlog::LogLine;
use ratelab_core::time::Nanos;
use ratelab_runtime::config::ClockKind;
use ratelab_runtime::graph::nodes::external::{ExternalLink, ExternalStats};
use ratelab_runtime::graph::nodes::ExternalPort;
use ratelab_runtime::graph::{GraphSpec, NodeId};
use ratelab_runtime::scheduler::StopFlag;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::Arc;
use std::thread::JoinHandle;
use zenoh::Wait;

/// The ROS 2 node that publishes `/clock`.
pub const CLOCK_NODE: &str = "ratelab";

/// The topic ROS 2 nodes with `use_sim_time` read their time from.
pub const CLOCK_TOPIC: &str = "/clock";

/// Messages waiting for the bridge thread, at most.
pub const CHANNEL_CAPACITY: usize = 4096;

/// How long to ask the network for another `/clock` publisher before starting.
const CLOCK_QUERY: std::time::Duration = std::time::Duration::from_millis(500);

/// What the bridge thread is told.
enum Out {
    /// A message of topic `topic`, published at `stamp` with ratelab's `seq`.
    Msg {
        topic: usize,
        seq: u64,
        stamp: Nanos,
        data: MsgData,
    },
    /// The run's clock reached this time (before an instant).
    Clock(Nanos),
    /// An external node ticks at this time: `/clock` must say it now.
    Announce(Nanos),
    /// The run is over: put what came before, then stop.
    End,
}

/// What the bridge did, when the run is over.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct BridgeReport {
    /// Messages put on the ROS 2 keys (not counting `/clock`).
    pub offered: u64,
    /// ROS 2 copies dropped because the bridge fell behind (real clock only).
    pub dropped: u64,
    /// Log lines not put on their node's `/rosout` because the bridge fell behind.
    pub log_dropped: u64,
    /// The first failed put, if any.
    pub error: Option<String>,
    /// The bag, when there is one: the messages written to it (with `/clock`), or why it
    /// could not be written whole (it was then removed: [`super::bag::Bag::finish`]).
    pub bagged: Option<Result<u64, String>>,
    /// What each external node did, by name, in node order.
    pub external: Vec<(String, ExternalStats)>,
    /// Notes from waiting for the external nodes (malformed tokens ignored), one line each.
    pub notes: Vec<String>,
}

impl BridgeReport {
    /// One line per external node that missed ticks or sent what could not be used (none
    /// when all went well).
    pub fn external_warnings(&self) -> Vec<String> {
        let mut lines = Vec::new();
        for (name, s) in &self.external {
            if s.missed > 0 {
                lines.push(format!(
                    "external node '{name}' missed {} tick(s): nothing on its output within its tick_timeout (it publishes one message per output per tick under the virtual clock; docs/ros2.md)",
                    s.missed
                ));
            }
            if s.stray > 0 {
                lines.push(format!(
                    "external node '{name}': {} message(s) came outside their tick (late after a miss, or more than one per tick) and were dropped",
                    s.stray
                ));
            }
            if s.overflow > 0 {
                lines.push(format!(
                    "external node '{name}': {} message(s) dropped (more than {} waiting)",
                    s.overflow, s.inbox
                ));
            }
            if let Some(e) = &s.first_error {
                lines.push(format!(
                    "external node '{name}': {} message(s) refused, the first: {e}",
                    s.undecodable
                ));
            }
        }
        // Notes last: the lab shows the first line, and a node's misses matter more.
        lines.extend(self.notes.iter().cloned());
        lines
    }
}

/// The graph offered to ROS 2 while it runs ([`Bridge::start`] … [`Bridge::finish`]).
pub struct Bridge {
    tx: Option<Sender<Out>>,
    thread: Option<JoinHandle<Forwarded>>,
    /// Takes the log's lines to `/rosout` while the bridge lives.
    recorder: Option<ratelab_core::textlog::Recorder>,
    /// Log lines not put on `/rosout` (the bridge fell behind).
    log_dropped: Arc<AtomicU64>,
    dropped: Arc<AtomicU64>,
    ports: Vec<Arc<ExternalPort>>,
    notes: Vec<String>,
    /// The router the session uses.
    pub router: Router,
    /// The domain.
    pub domain: u32,
}

/// What a bridge offers: a graph's topics, the external nodes it waits for, and (in a launch
/// across processes) which nodes run here.
pub struct Offer<'a> {
    /// The graph's shape.
    pub spec: &'a GraphSpec,
    /// Its topics, by topic id.
    pub topics: &'a [AnyTopic],
    /// Its external nodes' ports ([`super::external`]).
    pub external: &'a [Arc<ExternalPort>],
    /// The nodes this process runs; `None`: all (one process). A node run by another
    /// process is offered by that process's bridge: this one declares nothing for it and
    /// puts nothing of it (a topic it publishes arrives here as a copy).
    pub local: Option<&'a [NodeId]>,
    /// Publish `/clock` (one bridge of a graph does: in a launch, the plant's process).
    pub clock: bool,
    /// Each node's rate, by node id, shared with the running graph: `rate_hz` as its
    /// parameter services answer it ([`super::parameters`]).
    pub rates: &'a [ratelab_core::rate::Rate],
    /// How a node's rate is set from ROS 2 (`ros2 param set /policy rate_hz 20`): a command
    /// to the run, by node name and Hz, as the lab's keys give it; `None`: the run takes no
    /// commands, and `rate_hz` is read-only.
    pub set_rate: Option<SetNodeRate>,
    /// The lines the nodes wrote while the graph was built (their constructors'), oldest
    /// first: each node offered here puts its own on its `/rosout` before any other line
    /// ([`ratelab_runtime::graph::GraphHandles::build_lines`]).
    pub build_lines: &'a [LogLine],
}

/// Set node `name`'s rate to `hz` as a command to the run ([`Offer::set_rate`]).
pub type SetNodeRate = Arc<dyn Fn(&str, f64) -> Result<(), String> + Send + Sync>;

impl<'a> Offer<'a> {
    /// The whole graph behind `h`, in one process, with `/clock`.
    pub fn whole(h: &'a ratelab_runtime::graph::GraphHandles) -> Offer<'a> {
        Offer {
            spec: &h.spec,
            topics: &h.topics,
            external: &h.external,
            local: None,
            clock: true,
            rates: &h.rates,
            set_rate: None,
            build_lines: &h.build_lines,
        }
    }

    /// Node `n` is run by another program (an external node, or another process).
    fn elsewhere(&self, n: NodeId) -> bool {
        self.external.iter().any(|p| p.node == n) || self.local.is_some_and(|l| !l.contains(&n))
    }
}

/// Check, before any session opens, everything [`Bridge::start`] would refuse that does
/// not need the network: the graph ([`check_graph`]) and the bag's folder.
///
/// # Errors
/// The first problem, in one line.
pub fn check(spec: &GraphSpec, opts: &Ros2Options) -> Result<(), String> {
    check_graph(spec)?;
    if let Some(dir) = &opts.bag {
        Bag::check(dir, opts.force).map_err(|e| e.to_string())?;
    }
    Ok(())
}

/// Check that `spec` can be offered to ROS 2: valid ROS 2 names, no topic of its own on
/// `/clock` (ratelab publishes the run's clock there: two `/clock` publishers would give
/// ROS 2 nodes two times), no node named [`CLOCK_NODE`].
///
/// # Errors
/// The first rule broken, in one line.
pub fn check_graph(spec: &GraphSpec) -> Result<(), String> {
    for n in &spec.nodes {
        check_node_name(&n.name).map_err(|e| format!("--ros2: node {e}"))?;
        if n.name == CLOCK_NODE {
            return Err(format!(
                "--ros2: a node named '{CLOCK_NODE}' would share its ROS 2 name with ratelab's /clock publisher; rename it"
            ));
        }
    }
    for t in &spec.topics {
        check_topic_name(&t.name).map_err(|e| format!("--ros2: topic {e}"))?;
        if t.msg.ros2().is_none() {
            return Err(format!(
                "--ros2: topic '{}' carries '{}', a message type with no ROS 2 type (give it one: ratelab::msg::RosMapped)",
                t.name, t.msg
            ));
        }
        if t.name == CLOCK_TOPIC {
            return Err(format!(
                "--ros2: the graph's topic {CLOCK_TOPIC} would be a second /clock publisher (ratelab publishes the run's clock there); rename it"
            ));
        }
    }
    Ok(())
}

/// A duration as a QoS token carries it.
fn ros_duration(d: Nanos) -> QosDuration {
    QosDuration {
        sec: d.0 / 1_000_000_000,
        nsec: d.0 % 1_000_000_000,
    }
}

/// ratelab's reliability as ROS 2's.
fn ros_reliability(r: Reliability) -> QosReliability {
    match r {
        Reliability::BestEffort => QosReliability::BestEffort,
        Reliability::Reliable => QosReliability::Reliable,
    }
}

/// ratelab's durability as ROS 2's.
fn ros_durability(d: ratelab_core::qos::compat::Durability) -> QosDurability {
    match d {
        ratelab_core::qos::compat::Durability::Volatile => QosDurability::Volatile,
        ratelab_core::qos::compat::Durability::TransientLocal => QosDurability::TransientLocal,
    }
}

/// The QoS topic `t` of `spec` is offered with (its publisher's token's), durability
/// included: a transient-local topic's publisher keeps its last `depth` messages for ROS 2's
/// late joiners too ([`super::wire`]), as it keeps them for the graph's own.
pub(crate) fn qos_of(spec: &GraphSpec, t: usize) -> QosProfile {
    let topic = &spec.topics[t];
    let q = &topic.qos;
    let dur = |d: Option<Nanos>| d.map_or(QosDuration::INFINITE, ros_duration);
    QosProfile {
        reliability: ros_reliability(q.reliability),
        history: match q.history {
            History::KeepLast => QosHistory::KeepLast(topic.depth),
            History::KeepAll => QosHistory::KeepAll(topic.depth),
        },
        durability: ros_durability(q.durability),
        deadline: dur(q.deadline),
        lifespan: dur(q.lifespan),
        liveliness_lease_duration: dur(spec.node(topic.publisher).liveliness_lease),
        ..QosProfile::default()
    }
}

/// The QoS subscriber `sub`'s subscription to topic `t` of `spec` announces (its token's):
/// its own profile, as a ROS 2 subscription announces the one it was made with (a real
/// rclpy subscription's token carries its own lifespan and lease, `Infinite` when it sets
/// none: `../shared/fixtures/ros2-real/real-rclpy-graph-view-qos.json`), so `ros2 topic
/// info -v` lists both ends. What the subscriber has of the topic in ratelab's graph: its
/// queue's history and depth, the reliability and durability it is delivered with, and the
/// deadline it watches (ratelab counts requested deadline misses on it); each replaced by
/// what it requests (`[topic.requested.NODE]`, `ratelab::qos::compat`). Not the publisher's
/// lifespan (a publisher's policy) nor its node's liveliness lease ([`qos_of`]): a
/// subscription's lease is the longest it accepts, infinite unless it requests one.
pub(crate) fn requested_qos_of(spec: &GraphSpec, t: usize, sub: NodeId) -> QosProfile {
    use super::rmw_zenoh::qos::QosLiveliness;
    use ratelab_core::qos::compat::LivelinessKind;
    let mut q = QosProfile {
        lifespan: QosDuration::INFINITE,
        liveliness_lease_duration: QosDuration::INFINITE,
        ..qos_of(spec, t)
    };
    let topic = &spec.topics[t];
    let Some(r) = topic.requested.get(&spec.node(sub).name) else {
        return q;
    };
    if let Some(rel) = r.reliability {
        q.reliability = ros_reliability(rel);
    }
    if let Some(d) = r.durability {
        q.durability = ros_durability(d);
    }
    if let Some(d) = r.deadline {
        q.deadline = ros_duration(d);
    }
    if let Some(l) = r.liveliness {
        q.liveliness = match l {
            LivelinessKind::Automatic => QosLiveliness::Automatic,
            LivelinessKind::ManualByTopic => QosLiveliness::ManualByTopic,
        };
    }
    if let Some(d) = r.liveliness_lease {
        q.liveliness_lease_duration = ros_duration(d);
    }
    q
}

/// The types each node of `spec` uses, described, by node id (and one more, last, for a
/// node of no topic: the `/clock` node): its topics' (published or read), and every node's
/// `/rosout` and `/parameter_events` types. One pass over the topics; hashes as computed once.
fn node_types(spec: &GraphSpec) -> Vec<super::type_description::Descriptions> {
    let mut types = vec![super::type_description::Descriptions::default(); spec.nodes.len() + 1];
    let known = super::echo::known();
    for d in [
        "rcl_interfaces/msg/Log",
        "rcl_interfaces/msg/ParameterEvent",
    ]
    .iter()
    .filter_map(|name| known.get(*name))
    {
        let hash = d.hash.to_rihs_string();
        types.iter_mut().for_each(|t| t.add(&d.description, &hash));
    }
    for t in &spec.topics {
        let ty = ros_type_of(t.msg);
        let hash = ty.hash.to_rihs_string();
        for n in std::iter::once(&t.publisher).chain(&t.subscribers) {
            types[n.0].add(&ty.description, &hash);
        }
    }
    types
}

/// Declare the `/rosout`, `/parameter_events`, parameter services and type descriptions
/// ([`super::node_api`]) of `own` (by node id) and, when this bridge offers it, of the
/// `/clock` node; what a node's `params` hold that ROS 2 has no type for goes to `notes`.
fn declare_node_apis(
    d: &mut Declarer<'_>,
    offer: &Offer<'_>,
    (own, clock_node): (&[(usize, &NodeEntity)], Option<&NodeEntity>),
    notes: &mut Vec<String>,
) -> Result<Vec<NodeApi>, Ros2Error> {
    let spec = offer.spec;
    let mut apis = Vec::new();
    let rules = Arc::new(spec.clone());
    let mut described = node_types(spec);
    for &(i, n) in own {
        // Checked by the graph's own rules first (the actuator's rate is the plant's step),
        // so that ROS 2 is told "successful" only for what the run will take.
        let set_rate = offer.set_rate.clone().map(|set| {
            let (name, rules) = (spec.nodes[i].name.clone(), rules.clone());
            Arc::new(move |hz| {
                let node = name.clone();
                ratelab_runtime::command::Command::SetNodeHz { node, hz }.validate(&rules)?;
                set(&name, hz)
            }) as super::parameters::SetRate
        });
        let params = NodeParameters::of(&spec.nodes[i], offer.rates.get(i), set_rate);
        let name = &spec.nodes[i].name;
        for why in &params.left_out {
            notes.push(format!(
                "node '{name}': parameter {why}: not offered to ROS 2"
            ));
        }
        let types = std::mem::take(&mut described[i]);
        apis.push(NodeApi::declare(d, n, (params, types), Nanos(0))?);
    }
    if let Some(clock_node) = clock_node {
        let params = NodeParameters::clock_node(CLOCK_NODE);
        let mut types = described.pop().unwrap_or_default();
        let clock = clock_type();
        types.add(&clock.description, &clock.hash.to_rihs_string());
        apis.push(NodeApi::declare(d, clock_node, (params, types), Nanos(0))?);
    }
    Ok(apis)
}

/// `/clock`'s QoS: best effort, keep last 1.
pub(crate) fn clock_qos() -> QosProfile {
    QosProfile {
        reliability: QosReliability::BestEffort,
        history: QosHistory::KeepLast(1),
        ..QosProfile::default()
    }
}

/// The `/clock` publishers already on the network but not of this session (their nodes'
/// names), asked of the liveliness tokens for `CLOCK_QUERY`.
fn clock_publishers(session: &zenoh::Session, domain: u32) -> Vec<String> {
    let Ok(replies) = session
        .liveliness()
        .get(format!("@ros2_lv/{domain}/**"))
        .timeout(CLOCK_QUERY)
        .wait()
    else {
        return Vec::new();
    };
    let format = KeyExprFormat;
    let mut found = Vec::new();
    while let Ok(r) = replies.recv() {
        let Ok(sample) = r.result() else { continue };
        if let Ok(Entity::Endpoint(e)) = format.parse_liveliness(sample.key_expr().as_str()) {
            let ours = e.node.as_ref().is_some_and(|n| n.z_id == session.zid());
            if e.kind == EndpointKind::Publisher && e.topic == CLOCK_TOPIC && !ours {
                found.push(e.node.map_or_else(|| "?".to_string(), |n| n.name));
            }
        }
    }
    found
}

/// Wait until `o` has a matching subscriber, for at most `within` (or until `stop`).
fn wait_matched(o: &Outlet, within: std::time::Duration, stop: &StopFlag) -> Result<(), ()> {
    let start = std::time::Instant::now();
    loop {
        if o.matched() {
            return Ok(());
        }
        if start.elapsed() >= within || stop.is_stopped() {
            return Err(());
        }
        std::thread::sleep(std::time::Duration::from_millis(10));
    }
}

/// Log lines waiting for the bridge thread, at most.
pub const LOG_CAPACITY: usize = 1024;

/// Give every line of the log (from now until the returned guard is dropped) to the
/// bridge for its node's `/rosout`, on a channel of their own ([`LOG_CAPACITY`]); a line
/// that does not fit is dropped and counted in `dropped` (the log never waits for ROS 2).
fn log_to_rosout(dropped: Arc<AtomicU64>) -> (ratelab_core::textlog::Recorder, Receiver<LogLine>) {
    let (tx, rx) = crossbeam_channel::bounded(LOG_CAPACITY);
    let recorder = ratelab_core::textlog::add_recorder(Box::new(move |line| {
        if let Err(TrySendError::Full(_)) = tx.try_send(line) {
            dropped.fetch_add(1, Ordering::Relaxed);
        }
    }));
    (recorder, rx)
}

impl Bridge {
    /// Offer `spec`'s graph, whose topics are `topics` (by topic id), to ROS 2 on
    /// `opts.domain`, through `link` ([`super::session::open`]; it outlives the bridge, so that a
    /// lab's successive runs keep one session and one router). The graph's external nodes
    /// are waited for first ([`super::external::wait_for`], `stop` ends the wait), then
    /// connected.
    ///
    /// # Errors
    /// [`Ros2Error::Usage`]: what [`check`] refuses, another `/clock` publisher on the
    /// domain, an external node that did not appear or has another type. [`Ros2Error::Zenoh`]:
    /// a declaration failed.
    pub fn start(
        link: &Ros2Session,
        offer: &Offer<'_>,
        opts: &Ros2Options,
        clock: ClockKind,
        stop: &StopFlag,
    ) -> Result<Bridge, Ros2Error> {
        let (spec, topics, ports) = (offer.spec, offer.topics, offer.external);
        check(spec, opts).map_err(Ros2Error::Usage)?;
        let domain = opts.domain;
        let session = link.session.clone();
        let router = link.router.clone();
        let waits = clock == ClockKind::Virtual;
        refuse_clock_clash(&session, offer, domain, waits)?;
        let mut notes = super::external::wait_for(&session, domain, spec, ports, stop)?;
        let elsewhere = |n: NodeId| offer.elsewhere(n);
        let zid = session.zid();
        let dom = usize::try_from(domain).unwrap_or(0);
        let node = |id: usize, name: &str| {
            NodeEntity::new(dom, zid, id, name.to_string(), String::new(), String::new())
        };
        let mut d = Declarer::new(&session, link).waiting(waits);
        let nodes: Vec<NodeEntity> = spec
            .nodes
            .iter()
            .map(|n| node(link.take_id(), &n.name))
            .collect();
        let clock_node = node(link.take_id(), CLOCK_NODE);
        let own: Vec<(usize, &NodeEntity)> = nodes
            .iter()
            .enumerate()
            .filter(|(i, _)| !elsewhere(NodeId(*i)))
            .collect();
        for n in own
            .iter()
            .map(|(_, n)| *n)
            .chain(offer.clock.then_some(&clock_node))
        {
            d.node(n)?;
        }
        let mut outlets = Vec::new();
        let mut subscriptions = Vec::new();
        for (t, topic) in spec.topics.iter().enumerate() {
            let ty = type_info(ros_type_of(topic.msg));
            let qos = qos_of(spec, t);
            let publisher = &nodes[topic.publisher.0];
            if elsewhere(topic.publisher) {
                outlets.push(None); // its own program or process publishes it
            } else {
                let mp = d.endpoint(
                    publisher,
                    EndpointKind::Publisher,
                    &topic.name,
                    ty.clone(),
                    qos,
                );
                outlets.push(Some(d.publisher(&mp, topic.depth)?));
            }
            // An external node's topic reaches the graph through a plain subscriber, which
            // asks for no history: its subscriptions announce no more than they get.
            let from_ros = offer.external.iter().any(|p| p.node == topic.publisher);
            for &sub in topic.subscribers.iter().filter(|s| !elsewhere(**s)) {
                let kind = EndpointKind::Subscription;
                let mut own = requested_qos_of(spec, t, sub);
                if from_ros {
                    own.durability = QosDurability::Volatile;
                }
                let ms = d.endpoint(&nodes[sub.0], kind, &topic.name, ty.clone(), own);
                subscriptions.push((ms, topic.depth));
            }
        }
        // Its id is taken whether or not it is offered, as every endpoint's is.
        let (ty, qos) = (type_info(clock_type()), clock_qos());
        let clock_ep = d.endpoint(&clock_node, EndpointKind::Publisher, CLOCK_TOPIC, ty, qos);
        let clock_outlet = offer.clock.then(|| d.publisher(&clock_ep, 1)).transpose()?;
        for (ms, depth) in &subscriptions {
            d.token_of(ms, *depth)?;
        }
        // What every ROS 2 node declares besides its topics (`super::node_api`).
        let clock_api = offer.clock.then_some(&clock_node);
        let apis = declare_node_apis(&mut d, offer, (&own, clock_api), &mut notes)?;
        let tokens = d.into_tokens();

        let bag = opts
            .bag
            .as_ref()
            .map(|dir| bag_for(spec, dir, opts.force, apis.len()))
            .transpose()?;
        let inbound = super::external::listen(&session, domain, spec, ports)?;
        wait_feeds_matched(
            spec,
            ports,
            &outlets,
            clock_outlet.as_ref().filter(|_| waits),
            stop,
        )?;
        let lockstep = waits && !ports.is_empty();
        let (tx, rx, dropped) = connect_graph(offer, topics, lockstep, waits);
        let log_dropped = Arc::new(AtomicU64::new(0));
        let (recorder, logs) = log_to_rosout(log_dropped.clone());
        let thread = spawn_forwarder(
            (rx, logs, offer.build_lines.to_vec()),
            (outlets, clock_outlet, apis),
            bag,
            lockstep,
            (inbound, tokens),
        )?;
        Ok(Bridge {
            tx: Some(tx),
            thread: Some(thread),
            recorder: Some(recorder),
            dropped,
            log_dropped,
            ports: ports.to_vec(),
            notes,
            router,
            domain,
        })
    }

    /// One line for the user: the domain, the router, what ROS 2's tools will see.
    pub fn describe(&self) -> String {
        let (d, via) = (self.domain, self.router.via());
        format!("offering the graph to ROS 2 on domain {d} with /clock, {via}")
    }

    /// The same in a few words, for the lab's status line (fits 80 columns with a
    /// `tcp/localhost:7447` endpoint): `ROS 2 domain 0 + /clock: ratelab's router on …`.
    pub fn status(&self) -> String {
        let via = match &self.router {
            Router::Found(e) => format!("via the router at {e}"),
            Router::Embedded(e) => format!("ratelab's own router on {e}"),
            Router::Unchecked => "router not checked".into(),
        };
        format!("ROS 2 domain {} + /clock: {via}", self.domain)
    }

    /// The run's clock reached `t` (the virtual clock, before each instant).
    pub fn clock(&self, t: Nanos) {
        if let Some(tx) = &self.tx {
            let _ = tx.send(Out::Clock(t));
        }
    }

    /// Stop offering: every message already handed over is put first (and the bag
    /// finished), then the tokens and publishers are withdrawn; the session stays open.
    pub fn finish(mut self) -> BridgeReport {
        drop(self.recorder.take());
        // The taps hold senders too (they end with the graph's topics): the thread is told.
        if let Some(tx) = self.tx.take() {
            let _ = tx.send(Out::End);
        }
        let f = self
            .thread
            .take()
            .and_then(|t| t.join().ok())
            .unwrap_or(Forwarded {
                offered: 0,
                error: Some("the ROS 2 bridge thread panicked".into()),
                bagged: None,
            });
        BridgeReport {
            offered: f.offered,
            dropped: self.dropped.load(Ordering::Relaxed),
            log_dropped: self.log_dropped.load(Ordering::Relaxed),
            error: f.error,
            bagged: f.bagged,
            external: self
                .ports
                .iter()
                .map(|p| (p.name.clone(), p.stats()))
                .collect(),
            notes: std::mem::take(&mut self.notes),
        }
    }
}

/// Tap `topic` (number `i`) into the bridge's channel.
fn tap(topic: &AnyTopic, i: usize, tx: Sender<Out>, waits: bool, dropped: Arc<AtomicU64>) {
    topic.add_data_tap(Box::new(
        move |seq: u64, stamp: Nanos, _origin, data: MsgData| {
            let out = Out::Msg {
                topic: i,
                seq,
                stamp,
                data,
            };
            if waits {
                let _ = tx.send(out);
            } else if let Err(TrySendError::Full(_)) = tx.try_send(out) {
                dropped.fetch_add(1, Ordering::Relaxed);
            }
        },
    ));
}

/// What the bridge thread did.
struct Forwarded {
    offered: u64,
    error: Option<String>,
    bagged: Option<Result<u64, String>>,
}

/// The bridge thread's state: where messages go and what happened.
struct Forwarder<'a> {
    /// By topic: `None` for an external node's topic (bag only).
    outlets: &'a [Option<Outlet>],
    /// `None`: another process's bridge publishes `/clock`.
    clock: Option<&'a Outlet>,
    /// The lockstep's `/clock` (module header): an instant's time waits for an external
    /// node's tick or the next instant.
    deferred: bool,
    /// The instant whose `/clock` waits, in that mode.
    pending: Option<Nanos>,
    bag: Option<Bag>,
    /// The nodes' `/rosout`, `/parameter_events` and services, the `/clock` node's last.
    apis: Vec<NodeApi>,
    /// When the nodes' rates were last looked at ([`node_api::RATE_POLL`]).
    polled: std::time::Instant,
    buf: Vec<u8>,
    clock_seq: i64,
    last_clock: Option<Nanos>,
    /// The latest run time seen (a message's stamp, an instant): a parameter event's stamp.
    latest: Nanos,
    offered: u64,
    error: Option<String>,
}

impl Forwarder<'_> {
    /// `self.buf` out as message `seq` of outlet number `index` (the clock's: the number
    /// after the topics'), at run time `t`: put on its key and written to the bag. False
    /// when the put failed.
    fn send(&mut self, index: usize, seq: i64, t: Nanos) -> bool {
        if let Some(b) = self.bag.as_mut() {
            b.write(index, t.0, &self.buf);
        }
        let outlet = match (self.outlets.get(index), self.clock) {
            (Some(Some(o)), _) | (None, Some(o)) => o,
            // An external node's (its program put it), or /clock of another process.
            _ => return false,
        };
        match outlet.put(seq, &self.buf) {
            Ok(()) => true,
            Err(e) => {
                self.error.get_or_insert(e);
                false
            }
        }
    }

    /// `self.buf` into the bag (if any) as a message of `extra` at run time `t`.
    fn bag_extra(&mut self, extra: BagExtra, t: Nanos) {
        if let Some(b) = self.bag.as_mut() {
            b.write(self.outlets.len() + extra as usize, t.0, &self.buf);
        }
    }

    /// `line` on its node's `/rosout` (and in the bag, at the run time it was written, else
    /// the latest seen): the node that wrote it, or (a line of no node's, or of a node
    /// offered elsewhere) the `/clock` node's, when this bridge offers it.
    fn log(&mut self, line: &LogLine) {
        let by_name = line
            .node
            .as_deref()
            .and_then(|n| self.apis.iter().position(|a| a.name == n));
        let clock_node = self.apis.iter().position(|a| a.name == CLOCK_NODE);
        if let Some(i) = by_name.or(clock_node) {
            match self.apis[i].log(line, &mut self.buf) {
                Ok(()) => self.bag_extra(BagExtra::Rosout, line.t.unwrap_or(self.latest)),
                Err(e) => {
                    self.error.get_or_insert(e);
                }
            }
        }
    }

    /// The lines the nodes wrote while the graph was built, each on its own node's
    /// `/rosout` (and in the bag at run time 0), before any other line: those of a node
    /// offered here (another process offers its own).
    fn log_built(&mut self, lines: &[LogLine]) {
        for line in lines {
            let ours = line
                .node
                .as_deref()
                .is_some_and(|n| self.apis.iter().any(|a| a.name == n));
            if ours {
                self.log(line);
            }
        }
    }

    /// Each node's declaration of its parameters (put when declared) into the bag, at run
    /// time 0.
    fn bag_declared(&mut self) {
        let index = self.outlets.len() + BagExtra::Events as usize;
        for a in &mut self.apis {
            let cdr = a.take_declared();
            if let Some(b) = self.bag.as_mut().filter(|_| !cdr.is_empty()) {
                b.write(index, 0, &cdr);
            }
        }
    }

    /// Say on `/parameter_events` (and in the bag) what rates changed, at most every
    /// [`node_api::RATE_POLL`].
    fn poll_rates(&mut self) {
        if self.polled.elapsed() < node_api::RATE_POLL {
            return;
        }
        self.polled = std::time::Instant::now();
        let t = self.latest;
        let index = self.outlets.len() + BagExtra::Events as usize;
        for a in &mut self.apis {
            match a.poll_rate(t, &mut self.buf) {
                Ok(true) => {
                    if let Some(b) = self.bag.as_mut() {
                        b.write(index, t.0, &self.buf);
                    }
                }
                Ok(false) => {}
                Err(e) => {
                    self.error.get_or_insert(e);
                }
            }
        }
    }

    /// What the graph sent (not [`Out::End`]).
    fn handle(&mut self, out: Out) {
        match out {
            Out::End => {}
            Out::Clock(t) if self.deferred => {
                self.latest = self.latest.max(t);
                // The instant before is over: its time goes out now, this one's waits.
                if let Some(p) = self.pending.replace(t) {
                    self.tick(p);
                }
            }
            Out::Clock(t) | Out::Announce(t) => {
                self.latest = self.latest.max(t);
                self.pending = self.pending.filter(|p| *p > t);
                self.tick(t);
            }
            Out::Msg {
                topic,
                seq,
                stamp,
                data,
            } => {
                self.latest = self.latest.max(stamp);
                if !self.deferred {
                    self.tick(stamp);
                }
                // check_graph refused a type without a ROS 2 mapping; nothing to send else.
                let Some(codec) = data.msg_type().ros2() else {
                    return;
                };
                if !(codec.encode)(&data, stamp, &mut self.buf) {
                    return;
                }
                let seq = i64::try_from(seq).unwrap_or(i64::MAX - 1) + 1;
                if self.send(topic, seq, stamp) {
                    self.offered += 1;
                }
            }
        }
    }

    /// `/clock` at `t`, if the run's time moved on (and this bridge publishes it).
    fn tick(&mut self, t: Nanos) {
        if self.clock.is_some() && self.last_clock.is_none_or(|l| t > l) {
            self.last_clock = Some(t);
            self.clock_seq += 1;
            encode_clock(t, &mut self.buf);
            let index = self.outlets.len() + BagExtra::Clock as usize;
            self.send(index, self.clock_seq, t);
        }
    }
}

/// The bridge thread: put each message (and write it to the bag), and `/clock` whenever
/// the run's time moved on (`deferred`: as the lockstep wants it), each log line on its
/// node's `/rosout` (`built` first, the lines of the graph's building, then `logs`), and
/// the nodes' rate changes on `/parameter_events`, until told the run ended (then the log
/// lines already written go out too). The bag takes all of it, and each node's
/// declaration of its parameters first.
fn forward(
    (rx, logs, built): (&Receiver<Out>, Receiver<LogLine>, &[LogLine]),
    (outlets, clock, apis): (&[Option<Outlet>], Option<&Outlet>, Vec<NodeApi>),
    bag: Option<Bag>,
    deferred: bool,
) -> (Forwarded, Vec<NodeApi>) {
    let mut f = Forwarder {
        outlets,
        clock,
        deferred,
        pending: None,
        bag,
        apis,
        polled: std::time::Instant::now(),
        buf: Vec::with_capacity(256),
        clock_seq: 0,
        last_clock: None,
        latest: Nanos(0),
        offered: 0,
        error: None,
    };
    f.bag_declared();
    f.log_built(built);
    let mut log_rx = logs.clone();
    loop {
        f.poll_rates();
        // A run that stalls still puts what its bag holds in the file within a second.
        if let Some(b) = f.bag.as_mut() {
            b.flush_if_due();
        }
        crossbeam_channel::select! {
            recv(rx) -> out => match out {
                Ok(Out::End) | Err(_) => break,
                Ok(out) => f.handle(out),
            },
            recv(log_rx) -> line => match line {
                Ok(line) => f.log(&line),
                // The recorder is gone (the run is ending): wait for the rest alone.
                Err(_) => log_rx = crossbeam_channel::never(),
            },
            default(node_api::RATE_POLL) => {}
        }
    }
    for line in logs.try_iter() {
        f.log(&line);
    }
    if let Some(p) = f.pending.take() {
        f.tick(p);
    }
    let forwarded = Forwarded {
        offered: f.offered,
        error: f.error,
        bagged: f.bag.map(Bag::finish),
    };
    (forwarded, f.apis)
}

/// Refuse to offer a `/clock` where another node on `domain` already publishes one (ROS 2
/// nodes would get two times), and, under the virtual clock (`waits`), more than one
/// external node (they would share each `/clock` tick).
fn refuse_clock_clash(
    session: &zenoh::Session,
    offer: &Offer<'_>,
    domain: u32,
    waits: bool,
) -> Result<(), Ros2Error> {
    let (spec, ports) = (offer.spec, offer.external);
    let others = if offer.clock {
        clock_publishers(session, domain)
    } else {
        Vec::new()
    };
    if let Some(other) = others.first() {
        return Err(Ros2Error::Usage(format!(
            "--ros2: node '{}' already publishes /clock on domain {domain}; two /clock publishers would give ROS 2 nodes two times (stop it, or use another ROS_DOMAIN_ID)",
            ratelab_core::text::printable(other)
        )));
    }
    if waits && ports.len() > 1 {
        // They would share each /clock tick: the second would answer at the first's.
        return Err(Ros2Error::Usage(format!(
            "graph '{}' has {} external nodes: under the virtual clock the lockstep takes one (they would share each /clock tick); use the real clock, or make one of them a ratelab process",
            spec.name,
            ports.len()
        )));
    }
    Ok(())
}

/// The bag's topics after the graph's own (numbered as their topic ids), in this order
/// ([`bag_for`]): number `spec.topics.len() + extra as usize`.
#[derive(Clone, Copy)]
enum BagExtra {
    /// `/clock`.
    Clock = 0,
    /// `/rosout`, every node's offered here.
    Rosout = 1,
    /// `/parameter_events`, every node's offered here.
    Events = 2,
}

/// A bag in `dir` (`force`: over one there) of every topic of `spec`, `/clock`, and the
/// `/rosout` and `/parameter_events` of the `nodes` ROS 2 nodes offered here (each one a
/// publisher of both, as `ros2 bag record -a` takes them), with their ROS 2 types and QoS.
fn bag_for(
    spec: &GraphSpec,
    dir: &std::path::Path,
    force: bool,
    nodes: usize,
) -> Result<Bag, Ros2Error> {
    let mut topics: Vec<BagTopic<'_>> = spec
        .topics
        .iter()
        .enumerate()
        .map(|(i, t)| BagTopic::of(&t.name, ros_type_of(t.msg), qos_of(spec, i)))
        .collect();
    topics.push(BagTopic::of(CLOCK_TOPIC, clock_type(), clock_qos()));
    let known = super::echo::known();
    for (name, ty, qos) in [
        (
            node_api::ROSOUT,
            "rcl_interfaces/msg/Log",
            node_api::rosout_qos(),
        ),
        (
            node_api::PARAMETER_EVENTS,
            "rcl_interfaces/msg/ParameterEvent",
            node_api::parameters_qos(),
        ),
    ] {
        let d = known.get(ty).ok_or_else(|| {
            Ros2Error::Usage(format!("--bag: no description of {ty} (a ratelab bug)"))
        })?;
        topics.push(BagTopic {
            name,
            description: &d.description,
            hash: d.hash.to_rihs_string(),
            qos: vec![qos; nodes],
        });
    }
    debug_assert_eq!(
        topics.len(),
        spec.topics.len() + BagExtra::Events as usize + 1
    );
    Bag::create(dir, force, &topics)
}

/// What an external node reads must reach it from the first message: wait until Zenoh has
/// matched its subscriptions to ratelab's publishers (`outlets`; the tokens came first),
/// and, under the virtual clock, `/clock`'s (`clock`: the lockstep runs on it), each
/// within the node's `appear_timeout_s`.
fn wait_feeds_matched(
    spec: &GraphSpec,
    ports: &[Arc<ExternalPort>],
    outlets: &[Option<Outlet>],
    clock: Option<&Outlet>,
    stop: &StopFlag,
) -> Result<(), Ros2Error> {
    for p in ports {
        let mut feeds: Vec<(&str, &Outlet)> = clock.map(|o| (CLOCK_TOPIC, o)).into_iter().collect();
        if let Some(t) = p.input {
            if let Some(o) = &outlets[t.0] {
                feeds.push((spec.topics[t.0].name.as_str(), o));
            }
        }
        for (topic, o) in feeds {
            wait_matched(o, p.settings.appear_timeout.to_duration(), stop).map_err(|()| {
                Ros2Error::Usage(format!(
                    "external node '{}': no subscriber of {topic} matched ratelab's publisher within {:.1} s (under the virtual clock it must subscribe to its input and to /clock)",
                    p.name,
                    p.settings.appear_timeout.as_secs_f64()
                ))
            })?;
        }
    }
    Ok(())
}

/// The bridge's thread: forward what the graph publishes (`rx`) to ROS 2 through `outlets`
/// and `/clock`, into the bag if any (`deferred`: under the lockstep, see [`forward`]);
/// then withdraw everything it declared (the inbound subscriptions, the liveliness tokens,
/// the publishers), so that ROS 2's graph no longer shows the run's nodes.
fn spawn_forwarder(
    (rx, logs, built): (Receiver<Out>, Receiver<LogLine>, Vec<LogLine>),
    (outlets, clock_outlet, apis): (Vec<Option<Outlet>>, Option<Outlet>, Vec<NodeApi>),
    bag: Option<Bag>,
    deferred: bool,
    (inbound, tokens): (
        Vec<zenoh::pubsub::Subscriber<()>>,
        Vec<zenoh::liveliness::LivelinessToken>,
    ),
) -> Result<JoinHandle<Forwarded>, Ros2Error> {
    std::thread::Builder::new()
        .name("ros2-bridge".into())
        .spawn(move || {
            let (r, apis) = forward(
                (&rx, logs, &built),
                (&outlets, clock_outlet.as_ref(), apis),
                bag,
                deferred,
            );
            // The tokens first: nothing is announced that is already gone.
            for t in tokens {
                let _ = t.undeclare().wait();
            }
            for a in apis {
                a.undeclare();
            }
            for s in inbound {
                let _ = s.undeclare().wait();
            }
            for o in outlets.into_iter().flatten() {
                o.undeclare();
            }
            if let Some(o) = clock_outlet {
                o.undeclare();
            }
            r
        })
        .map_err(|e| Ros2Error::Zenoh(format!("cannot start the ROS 2 bridge: {e}")))
}

/// Connect the graph to the bridge: each topic published in this program (`offer.local`)
/// is tapped (a copy of each message goes to the bridge; `waits`: under the virtual clock),
/// and each external node announces its ticks (`lockstep`: the lockstep waits for them).
/// Returns the channel's two ends and the count of what did not fit in it.
fn connect_graph(
    offer: &Offer<'_>,
    topics: &[AnyTopic],
    lockstep: bool,
    waits: bool,
) -> (Sender<Out>, Receiver<Out>, Arc<AtomicU64>) {
    let (spec, ports) = (offer.spec, offer.external);
    let (tx, rx) = crossbeam_channel::bounded(CHANNEL_CAPACITY);
    let dropped = Arc::new(AtomicU64::new(0));
    for (i, topic) in topics.iter().enumerate() {
        // What another process publishes arrives here as a copy: its own bridge offers it.
        if offer
            .local
            .is_none_or(|l| l.contains(&spec.topics[i].publisher))
        {
            tap(topic, i, tx.clone(), waits, dropped.clone());
        }
    }
    for p in ports {
        let tx = tx.clone();
        p.connect(ExternalLink {
            lockstep,
            announce: Box::new(move |t| {
                let _ = tx.send(Out::Announce(t));
            }),
        });
    }
    (tx, rx, dropped)
}

/// `/clock` for a run driven instant by instant ([`ratelab_runtime::runcore::drive`]).
impl ratelab_runtime::runcore::drive::ClockOut for Bridge {
    fn clock(&self, t: Nanos) {
        Bridge::clock(self, t);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_chapters_graph_can_be_offered_and_clock_is_refused() {
        let spec = GraphSpec::chapter();
        assert_eq!(check_graph(&spec), Ok(()));
        let mut s = spec.clone();
        s.topics[0].name = "/clock".into();
        assert!(check_graph(&s)
            .unwrap_err()
            .contains("second /clock publisher"));
        let mut s = spec.clone();
        s.topics[0].name = "/2obs".into();
        assert!(check_graph(&s)
            .unwrap_err()
            .contains("must not start with a digit"));
        let mut s = spec;
        s.nodes[0].name = "ratelab".into();
        assert!(check_graph(&s)
            .unwrap_err()
            .contains("ratelab's /clock publisher"));
    }

    #[test]
    fn the_qos_token_says_what_ratelab_runs() {
        let mut spec = GraphSpec::chapter();
        spec.set_qos("/action", "deadline_ms=40").unwrap();
        let q = qos_of(&spec, spec.topic_id("/action").unwrap().0);
        assert_eq!(q.history, QosHistory::KeepLast(spec.queue_depth().unwrap()));
        assert_eq!(
            q.deadline,
            QosDuration {
                sec: 0,
                nsec: 40_000_000
            }
        );
        assert_eq!(q.lifespan, QosDuration::INFINITE);
        assert_eq!(q.reliability, QosReliability::BestEffort);
    }

    /// A subscription announces what it requests where it requests something, the offer
    /// elsewhere: both ends as ROS 2's tools list them.
    #[test]
    fn a_subscriptions_token_carries_its_own_requested_qos() {
        use crate::rmw_zenoh::qos::{QosDurability, QosLiveliness};
        let text = std::fs::read_to_string(concat!(
            env!("CARGO_MANIFEST_DIR"),
            "/../../graphs/cartpole-incompatible-qos.toml"
        ))
        .unwrap()
        .replace(
            "reliability = \"reliable\"",
            "reliability = \"reliable\"\ndurability = \"transient_local\"\ndeadline_ms = 25\nliveliness = \"manual_by_topic\"",
        );
        let spec = GraphSpec::parse(&text, "g.toml").unwrap();
        let action = spec.topic_id("/action").unwrap();
        let offered = qos_of(&spec, action.0);
        let actuator = spec.node_id("actuator").unwrap();
        let own = requested_qos_of(&spec, action.0, actuator);
        assert_eq!(offered.reliability, QosReliability::BestEffort);
        assert_eq!(own.reliability, QosReliability::Reliable);
        assert_eq!(own.durability, QosDurability::TransientLocal);
        assert_eq!(own.liveliness, QosLiveliness::ManualByTopic);
        assert_eq!(
            own.deadline,
            QosDuration {
                sec: 0,
                nsec: 25_000_000
            }
        );
        assert_eq!(
            (own.history, own.lifespan),
            (offered.history, offered.lifespan)
        );
        // Where nothing is requested, and the topic has no lifespan and its publisher no
        // lease, the subscription announces what the topic runs with, as the offer does.
        let obs = spec.topic_id("/obs").unwrap();
        let policy = spec.node_id("policy").unwrap();
        assert_eq!(requested_qos_of(&spec, obs.0, policy), qos_of(&spec, obs.0));
    }

    /// The captured run (`ratelab-qos.json`: `--qos /action:deadline_ms=40,lifespan_ms=60
    /// --lease policy=100`) announced the actuator's subscription with the policy's
    /// lifespan and lease, where a real rclpy subscription announces its own (`Infinite`
    /// when it sets none: the probe's in `real-rclpy-graph-view-qos.json`). The
    /// subscription's token now carries the actuator's: the topic's history, reliability,
    /// durability and the deadline it watches, no lifespan and no lease; a lease it
    /// requests is its own.
    #[test]
    fn a_subscription_announces_its_own_lifespan_and_lease_not_its_publisher_s() {
        let mut spec = GraphSpec::chapter();
        spec.set_qos("/action", "deadline_ms=40,lifespan_ms=60")
            .unwrap();
        spec.set_lease("policy", 100.0).unwrap();
        let action = spec.topic_id("/action").unwrap().0;
        let actuator = spec.node_id("actuator").unwrap();
        let ms = |n: u64| QosDuration {
            sec: 0,
            nsec: n * 1_000_000,
        };
        let offered = qos_of(&spec, action);
        assert_eq!(
            (
                offered.deadline,
                offered.lifespan,
                offered.liveliness_lease_duration
            ),
            (ms(40), ms(60), ms(100))
        );
        let own = requested_qos_of(&spec, action, actuator);
        assert_eq!(
            (own.deadline, own.lifespan, own.liveliness_lease_duration),
            (ms(40), QosDuration::INFINITE, QosDuration::INFINITE)
        );
        assert_eq!(
            (own.history, own.reliability, own.durability, own.liveliness),
            (
                offered.history,
                offered.reliability,
                offered.durability,
                offered.liveliness
            )
        );
        // A lease the actuator requests is what its token says.
        spec.topics[action]
            .requested
            .entry("actuator".into())
            .or_default()
            .liveliness_lease = Some(Nanos(250_000_000));
        let own = requested_qos_of(&spec, action, actuator);
        assert_eq!(own.liveliness_lease_duration, ms(250));
        assert_eq!(own.lifespan, QosDuration::INFINITE);
    }
}
