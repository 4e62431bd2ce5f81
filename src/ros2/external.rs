//! External nodes: a graph node of `kind = "external"` that ratelab does not run. Any
//! process speaking rmw_zenoh fills it (an rclpy or rclcpp node on a ROS 2 machine, or a
//! plain Zenoh program): it subscribes to the node's input and publishes its output as
//! ROS 2 topics, and ratelab's proxy ([`ratelab_runtime::graph::nodes::external`]) delivers what it
//! publishes into the graph.
//!
//! Before the run starts, ratelab waits (up to the node's `appear_timeout_s`) for the node's
//! liveliness tokens on the domain: its node (NN, by name, any namespace), a publisher (MP)
//! on each output and a subscription (MS) on each input. A token for one of those topics
//! with another type (name or RIHS01 hash) is refused at once, in one line naming both:
//! the silent failure ROS 2 users otherwise meet (a subscriber that hears nothing). Then
//! ratelab subscribes to the output's data key and decodes each message (the decoder of its
//! message type's ROS 2 mapping, `ros2().decode`).
//!
//! The time contract under the virtual clock (the lockstep): `/clock` reaches `t` at the
//! external node's tick at `t`, after every message the nodes ranked before it published at
//! `t` (the bridge holds `/clock = t` back until then, or until the next instant when no
//! external node ticks at `t`); the node then publishes **one message per output per
//! tick**, from the newest inputs it has. A node that ticks on `/clock` (a timer with
//! `use_sim_time`, or a `/clock` subscription) and publishes from the newest input
//! therefore computes on what ratelab's own node of its rank would read, and a
//! deterministic node gives byte-identical runs. Zenoh delivers one session's samples to a
//! subscriber in order; an rclpy executor may still run a timer before a subscription
//! callback that arrived first (docs/ros2.md).

use super::rmw_zenoh::entity::{EndpointEntity, EndpointKind, Entity, NodeEntity, TypeHash};
use super::rmw_zenoh::key_expr::KeyExprFormat;
use super::rmw_zenoh::qos::QosProfile;
use super::ros_type_of;
use super::types::{type_info, RosType};
use super::{zerr, Ros2Error};
use ratelab_runtime::graph::nodes::ExternalPort;
use ratelab_runtime::graph::GraphSpec;
use ratelab_runtime::scheduler::StopFlag;
use std::collections::BTreeSet;
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};
use zenoh::Wait;

/// A node's token, in [`Seen`]'s first place (an endpoint's is [`kind_key`]'s number).
const NODE: u8 = u8::MAX;

fn kind_key(k: EndpointKind) -> u8 {
    match k {
        EndpointKind::Publisher => 0,
        EndpointKind::Subscription => 1,
        _ => 2,
    }
}

/// One token seen on the domain: (what it is, its node's name, its topic, its type's DDS
/// name and hash).
type Seen = (u8, String, String, Option<(String, [u8; 32])>);

/// What one external node must have declared: its name, and per topic the endpoint kind
/// with the type ratelab expects.
struct Wanted<'a> {
    port: &'a ExternalPort,
    endpoints: Vec<(EndpointKind, &'a str, &'static super::types::RosType)>,
}

fn short_hash(h: &[u8; 32]) -> String {
    TypeHash::new(1, *h).to_rihs_string()
}

/// The tokens of domain `domain` seen so far, kept by a liveliness subscriber (with the
/// tokens already declared).
struct Tokens {
    seen: Arc<Mutex<BTreeSet<Seen>>>,
    /// Tokens ignored because a name in them holds a control character: how many, and the
    /// first's key, written out ([`ratelab_core::text::printable`]).
    ignored: Arc<Mutex<(u64, Option<String>)>>,
    _sub: zenoh::pubsub::Subscriber<()>,
}

impl Tokens {
    /// The note for the tokens ignored so far, if any (one line).
    fn note(&self, domain: u32) -> Option<String> {
        let (n, first) = &*self.ignored.lock().unwrap_or_else(|e| e.into_inner());
        (*n > 0).then(|| {
            format!(
                "ignored {n} malformed ROS 2 liveliness token(s) on domain {domain} (a name holding control characters), the first: {}",
                first.as_deref().unwrap_or("?")
            )
        })
    }
}

/// Check that `spec` may run without `--ros2`: it has no external node (only ROS 2 can fill
/// one).
///
/// # Errors
/// One line naming the first external node.
pub fn check_offered(spec: &GraphSpec) -> Result<(), String> {
    match spec.first_external() {
        Some(n) => Err(format!(
            "node '{}' is external (kind = \"external\"): a ROS 2 node fills it, so the graph runs with --ros2 (docs/ros2.md)",
            n.name
        )),
        None => Ok(()),
    }
}

/// Check that a launch across processes can run `spec`'s external nodes: all of their
/// proxies in one process (it publishes `/clock` at their ticks), each beside its input's
/// publisher (so that process offers the input to ROS 2 before `/clock` reaches the tick,
/// in one ordered stream).
///
/// # Errors
/// One line naming the node and where it would have to run.
pub fn check_placement(spec: &GraphSpec) -> Result<(), String> {
    let mut host: Option<(String, &str)> = None;
    for (i, n) in spec.nodes.iter().enumerate() {
        if n.kind.code() != ratelab_runtime::graph::kind::Code::Ros2 {
            continue;
        }
        let p = spec.process_of(ratelab_runtime::graph::NodeId(i));
        if let Some(&t) = n.subscribes.first() {
            let feeder = spec.process_of(spec.topic(t).publisher);
            if feeder != p {
                return Err(format!(
                    "external node '{}' is placed in process '{p}', but its input {} comes from process '{feeder}': place it there (or leave out its `process`), so that /clock follows its input in one stream",
                    n.name,
                    spec.topic(t).name
                ));
            }
        }
        match &host {
            Some((h, other)) if *h != p => {
                return Err(format!(
                    "external nodes '{other}' and '{}' run in processes '{h}' and '{p}': a launch across processes takes its external nodes in one process (which publishes /clock)",
                    n.name
                ))
            }
            Some(_) => {}
            None => host = Some((p, &n.name)),
        }
    }
    Ok(())
}

/// Wait until every external node of `spec` (their `ports`) has declared its tokens on
/// `domain`, each within its own `appear_timeout` from now.
///
/// # Errors
/// [`Ros2Error::Usage`], one line: a node that did not appear in time (what is missing), a
/// node whose endpoint has another type, or Ctrl-C while waiting. [`Ros2Error::Zenoh`]: the
/// liveliness subscriber could not be declared.
pub fn wait_for(
    session: &zenoh::Session,
    domain: u32,
    spec: &GraphSpec,
    ports: &[Arc<ExternalPort>],
    stop: &StopFlag,
) -> Result<Vec<String>, Ros2Error> {
    if ports.is_empty() {
        return Ok(Vec::new());
    }
    let tokens = watch(session, domain)?;
    let wanted: Vec<Wanted<'_>> = ports
        .iter()
        .map(|p| {
            let mut endpoints = Vec::new();
            let topic = |t: ratelab_runtime::graph::TopicId| &spec.topics[t.0];
            let out = topic(p.output);
            endpoints.push((
                EndpointKind::Publisher,
                out.name.as_str(),
                ros_type_of(out.msg),
            ));
            if let Some(i) = p.input {
                let t = topic(i);
                endpoints.push((
                    EndpointKind::Subscription,
                    t.name.as_str(),
                    ros_type_of(t.msg),
                ));
            }
            Wanted { port: p, endpoints }
        })
        .collect();
    let start = Instant::now();
    loop {
        let seen = tokens
            .seen
            .lock()
            .unwrap_or_else(|e| e.into_inner())
            .clone();
        let mut all = true;
        for w in &wanted {
            let name = &w.port.name;
            let mut missing = Vec::new();
            // Of another type: said only if the right one never comes (any peer on the domain
            // may declare a token under this node's name, before or beside the node's own).
            let mut other_type = None;
            if !seen.iter().any(|(k, n, _, _)| *k == NODE && n == name) {
                missing.push(format!("its node (an NN token named '{name}')"));
            }
            for (kind, topic, ty) in &w.endpoints {
                let want = (ty.dds_name(), ty.hash.0);
                let mine = seen
                    .iter()
                    .filter(|(k, n, t, _)| *k == kind_key(*kind) && n == name && t == topic);
                if mine
                    .clone()
                    .any(|(_, _, _, got)| *got == Some(want.clone()))
                {
                    continue;
                }
                missing.push(format!("{} {topic} ({})", endpoint_word(*kind), ty.name));
                let theirs = mine.filter_map(|(_, _, _, got)| got.as_ref()).next();
                if let (Some((gname, ghash)), None) = (theirs, &other_type) {
                    let what = endpoint_word(*kind);
                    let shown =
                        ratelab_core::text::printable(&hiroz_schema::ros_from_dds_strict(gname))
                            .into_owned();
                    let differs = if *gname == want.0 {
                        format!(
                            "{shown} with type hash {}, ratelab's is {} (another ROS 2 distribution's definition?)",
                            short_hash(ghash),
                            short_hash(&want.1)
                        )
                    } else {
                        format!("{shown}, but the graph's {topic} is {}", ty.name)
                    };
                    other_type = Some(format!(
                        "external node '{name}' {what} {topic} as {differs}: a ROS 2 endpoint of another type hears nothing (fix its type or the graph's)"
                    ));
                }
            }
            if !missing.is_empty() {
                all = false;
                if start.elapsed() >= w.port.settings.appear_timeout.to_duration() {
                    return Err(Ros2Error::Usage(other_type.unwrap_or_else(|| format!(
                        "external node '{name}' did not appear on ROS 2 domain {domain} within {:.1} s: no liveliness token for {} (start it, with RMW_IMPLEMENTATION=rmw_zenoh_cpp and the same ROS_DOMAIN_ID and router; or raise params.appear_timeout_s)",
                        w.port.settings.appear_timeout.as_secs_f64(),
                        missing.join(", ")
                    ))));
                }
            }
        }
        if all {
            return Ok(tokens.note(domain).into_iter().collect());
        }
        if stop.is_stopped() {
            return Err(Ros2Error::Usage(
                "stopped while waiting for the graph's external nodes".into(),
            ));
        }
        std::thread::sleep(Duration::from_millis(20));
    }
}

fn endpoint_word(k: EndpointKind) -> &'static str {
    match k {
        EndpointKind::Publisher => "publishes",
        _ => "subscribes to",
    }
}

/// A liveliness subscriber on `@ros2_lv/<domain>/**` (with the tokens already there)
/// keeping what each token says.
fn watch(session: &zenoh::Session, domain: u32) -> Result<Tokens, Ros2Error> {
    let seen = Arc::new(Mutex::new(BTreeSet::new()));
    let kept = seen.clone();
    let ignored = Arc::new(Mutex::new((0u64, None)));
    let noted = ignored.clone();
    let format = KeyExprFormat;
    let sub = session
        .liveliness()
        .declare_subscriber(format!("@ros2_lv/{domain}/**"))
        .history(true)
        .callback(move |sample| {
            let Ok(entity) = format.parse_liveliness(sample.key_expr().as_str()) else {
                return; // not a ROS 2 token: ignored
            };
            let entry = match entity {
                Entity::Node(n) => (NODE, n.name, String::new(), None),
                Entity::Endpoint(e) => (
                    kind_key(e.kind),
                    e.node.map(|n| n.name).unwrap_or_default(),
                    e.topic,
                    e.type_info.map(|t| (t.name, t.hash.value)),
                ),
            };
            // A peer's names reach the user's terminal in errors: a token whose names hold
            // control characters is not one ROS 2 makes (its names are checked), so it is
            // ignored, with a note, never fatal.
            if [&entry.1, &entry.2]
                .iter()
                .any(|t| ratelab_core::text::has_control(t))
                || entry
                    .3
                    .as_ref()
                    .is_some_and(|t| ratelab_core::text::has_control(&t.0))
            {
                let mut n = noted.lock().unwrap_or_else(|e| e.into_inner());
                n.0 += 1;
                n.1.get_or_insert_with(|| {
                    ratelab_core::text::printable(sample.key_expr().as_ref()).into_owned()
                });
                return;
            }
            let mut s = kept.lock().unwrap_or_else(|e| e.into_inner());
            match sample.kind() {
                zenoh::sample::SampleKind::Put => {
                    // Bounded: a domain with more than this many tokens is not waited on
                    // token by token (the first ones are kept).
                    if s.len() < 65_536 {
                        s.insert(entry);
                    }
                }
                zenoh::sample::SampleKind::Delete => {
                    s.remove(&entry);
                }
            }
        })
        .wait()
        .map_err(zerr)?;
    Ok(Tokens {
        seen,
        ignored,
        _sub: sub,
    })
}

/// The data key of `topic` of type `ty` on `domain` (`<domain>/<topic>/<dds type>/<hash>`).
///
/// # Errors
/// [`Ros2Error::Zenoh`] when the format refuses it (a validated name never is).
fn data_key(
    format: &KeyExprFormat,
    zid: zenoh::session::ZenohId,
    domain: u32,
    topic: &str,
    ty: &RosType,
) -> Result<String, Ros2Error> {
    let dom = usize::try_from(domain).unwrap_or(0);
    // Any node gives the same key: it names the domain, topic and type alone.
    let node = NodeEntity::new(dom, zid, 0, "key".into(), String::new(), String::new());
    let e = EndpointEntity {
        id: 0,
        node: Some(node),
        kind: EndpointKind::Subscription,
        topic: topic.to_string(),
        type_info: Some(type_info(ty)),
        qos: QosProfile::default(),
    };
    format.topic_key_expr(&e).map_err(zerr)
}

/// Subscribe to what each external node publishes, on its output's data key, delivering
/// each decoded message to its port (undecodable ones are counted there). The subscribers
/// live as long as the returned handles.
///
/// # Errors
/// [`Ros2Error::Zenoh`]: a declaration failed.
pub fn listen(
    session: &zenoh::Session,
    domain: u32,
    spec: &GraphSpec,
    ports: &[Arc<ExternalPort>],
) -> Result<Vec<zenoh::pubsub::Subscriber<()>>, Ros2Error> {
    let format = KeyExprFormat;
    ports
        .iter()
        .map(|p| {
            let topic = &spec.topics[p.output.0];
            let key = data_key(
                &format,
                session.zid(),
                domain,
                &topic.name,
                ros_type_of(topic.msg),
            )?;
            let port = p.clone();
            let decode = topic
                .msg
                .ros2()
                .expect("a graph offered to ROS 2 has only mapped types")
                .decode;
            session
                .declare_subscriber(key)
                .callback(move |sample| {
                    let bytes = sample.payload().to_bytes();
                    match decode(&bytes) {
                        Ok(data) => port.push(data),
                        Err(e) => port.refuse(e),
                    }
                })
                .wait()
                .map_err(zerr)
        })
        .collect()
}
