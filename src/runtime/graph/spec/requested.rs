//! A subscription's own requested QoS: the graph file's `[topic.requested.NODE]` table,
//! under the `[[topic]]` it belongs to, and the check of each request against what the
//! topic offers ([`ratelab_core::qos::compat`]: ROS 2's compatibility rules).
//!
//! ```toml
//! [[topic]]
//! name = "/action"
//! type = "force"
//! depth = 1                      # offered: best effort, no deadline
//!
//! [topic.requested.actuator]     # what the actuator's subscription requests
//! reliability = "reliable"       # best_effort | reliable
//! durability = "volatile"        # volatile | transient_local
//! deadline_ms = 40               # the longest offered deadline it accepts
//! liveliness = "automatic"       # automatic | manual_by_topic
//! liveliness_lease_ms = 100      # the longest offered lease it accepts
//! ```
//!
//! Every key is optional; a key left out accepts any offer. Rules (a [`SpecError`] at the
//! culprit): the table's name is a node that subscribes to the topic; durations as
//! `deadline_ms` (> 0, at most [`ratelab_core::qos::MAX_QOS_MS`]). An incompatible request is not
//! an error: it is the lesson. The run connects the pair never, and says so.

use super::{Ctx, GraphSpec, SpecError, TopicSpec};
use ratelab_core::qos::compat::{
    self, Durability, LivelinessKind, Mismatch, OfferedQos, RequestedQos,
};
use ratelab_core::qos::{self, Reliability, TopicQos};
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;
use toml::Spanned;

#[derive(Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub(super) struct RawRequested {
    #[serde(default, skip_serializing_if = "Option::is_none")]
    reliability: Option<Spanned<Reliability>>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    durability: Option<Spanned<Durability>>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    deadline_ms: Option<Spanned<f64>>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    liveliness: Option<Spanned<LivelinessKind>>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    liveliness_lease_ms: Option<Spanned<f64>>,
}

/// A topic's `requested` tables, as serde reads them: by subscriber name.
pub(super) type RawRequests = BTreeMap<String, Spanned<RawRequested>>;

/// Each request of topic `t` (its `requested` tables, `raw`), by node name, checked: the
/// node subscribes to `t` and each duration is a QoS duration. `names` gives node names.
pub(super) fn requested(
    cx: &Ctx<'_>,
    raw: &RawRequests,
    t: &TopicSpec,
    node_name: impl Fn(crate::graph::NodeId) -> String,
) -> Result<BTreeMap<String, RequestedQos>, SpecError> {
    let subscribers: Vec<String> = t.subscribers.iter().map(|&n| node_name(n)).collect();
    // Hashed: a topic may have tens of thousands of subscribers.
    let known: std::collections::HashSet<&str> = subscribers.iter().map(String::as_str).collect();
    let mut out = BTreeMap::new();
    for (node, r) in raw {
        if !known.contains(node.as_str()) {
            return Err(cx.err(
                r.span(),
                format!(
                    "[topic.requested.{node:?}]: '{}' does not subscribe to {} (its subscribers: {})",
                    ratelab_core::text::printable(node),
                    t.name,
                    if subscribers.is_empty() {
                        "none".to_string()
                    } else {
                        subscribers.join(", ")
                    }
                ),
            ));
        }
        let r = r.get_ref();
        let ms = |key: &str, v: &Option<Spanned<f64>>| {
            v.as_ref()
                .map(|v| {
                    qos::ms_to_nanos(key, *v.get_ref(), false).map_err(|e| cx.err(v.span(), e))
                })
                .transpose()
        };
        out.insert(
            node.clone(),
            RequestedQos {
                reliability: r.reliability.as_ref().map(|v| *v.get_ref()),
                durability: r.durability.as_ref().map(|v| *v.get_ref()),
                deadline: ms("deadline_ms", &r.deadline_ms)?,
                liveliness: r.liveliness.as_ref().map(|v| *v.get_ref()),
                liveliness_lease: ms("liveliness_lease_ms", &r.liveliness_lease_ms)?,
            },
        );
    }
    Ok(out)
}

/// A topic's requests as the graph file writes them back ([`GraphSpec::to_toml`]).
pub(super) fn to_raw(t: &TopicSpec) -> Option<RawRequests> {
    let f = |n: ratelab_core::time::Nanos| Spanned::new(0..0, n.0 as f64 / 1e6);
    (!t.requested.is_empty()).then(|| {
        t.requested
            .iter()
            .map(|(node, r)| {
                let raw = RawRequested {
                    reliability: r.reliability.map(|v| Spanned::new(0..0, v)),
                    durability: r.durability.map(|v| Spanned::new(0..0, v)),
                    deadline_ms: r.deadline.map(f),
                    liveliness: r.liveliness.map(|v| Spanned::new(0..0, v)),
                    liveliness_lease_ms: r.liveliness_lease.map(f),
                };
                (node.clone(), Spanned::new(0..0, raw))
            })
            .collect()
    })
}

/// A node's `start_ms` as run time: a QoS duration ([`qos::ms_to_nanos`]'s rules), and
/// never the actuator's, which steps the plant from t = 0.
///
/// # Errors
/// A one-line reason.
pub(super) fn start_at(ms: f64, actuator: bool) -> Result<ratelab_core::time::Nanos, String> {
    let at = qos::ms_to_nanos("start_ms", ms, false)?;
    if actuator {
        return Err(
            "the actuator steps the plant from t = 0: it cannot join late (start_ms)".into(),
        );
    }
    Ok(at)
}

impl GraphSpec {
    /// Set what node `node`'s subscription to `topic` requests, `KEY=VALUE[,KEY=VALUE…]`
    /// over what it requested before ([`RequestedQos::apply_key`]'s keys): what a
    /// `[topic.requested.NODE]` table says, from code (an exercise's pairs).
    ///
    /// # Errors
    /// [`crate::graph::spec::OverrideError`] for an unknown topic, a node that does not
    /// subscribe to it, or a bad key or value (the spec is unchanged).
    pub fn set_requested(
        &mut self,
        topic: &str,
        node: &str,
        pairs: &str,
    ) -> Result<(), super::OverrideError> {
        let err = |e: String| super::OverrideError(format!("{topic} requested by {node}: {e}"));
        let t = self.known_topic(topic)?;
        let subscribes = self
            .topic(t)
            .subscribers
            .iter()
            .any(|&n| self.node(n).name == node);
        if !subscribes {
            return Err(err(format!("'{node}' does not subscribe to {topic}")));
        }
        let mut r = self
            .topic(t)
            .requested
            .get(node)
            .copied()
            .unwrap_or_default();
        for (k, v) in qos::split_pairs(pairs).map_err(err)? {
            r.apply_key(k, v).map_err(err)?;
        }
        let requested = &mut self.topics[t.0].requested;
        if r.is_empty() {
            requested.remove(node);
        } else {
            requested.insert(node.to_string(), r);
        }
        Ok(())
    }

    /// Make node `name` join the graph at `ms` of run time ([`super::NodeSpec::start`]'s rules).
    ///
    /// # Errors
    /// [`crate::graph::spec::OverrideError`] for an unknown node, the actuator, or a time
    /// not in (0, [`qos::MAX_QOS_MS`]].
    pub fn set_start(&mut self, name: &str, ms: f64) -> Result<(), super::OverrideError> {
        let id = self.known_node(name)?;
        let at = start_at(ms, self.node(id).kind.is_actuator())
            .map_err(|e| super::OverrideError(format!("node '{name}': {e}")))?;
        self.nodes[id.0].start = Some(at);
        Ok(())
    }

    /// The subscriptions of topic `t` whose requested QoS the topic does not meet when it
    /// offers `offered_qos` (its QoS now; its publisher's liveliness lease is the spec's):
    /// each as (its index among the topic's subscribers, in tie-break order, its node's
    /// name, what failed). Empty when every request is met (always, for a graph that
    /// requests nothing).
    pub fn incompatible(
        &self,
        t: crate::graph::TopicId,
        offered_qos: &TopicQos,
    ) -> Vec<(usize, String, Vec<Mismatch>)> {
        let topic = self.topic(t);
        if topic.requested.is_empty() {
            return Vec::new();
        }
        let offered =
            OfferedQos::of_topic(offered_qos, self.node(topic.publisher).liveliness_lease);
        topic
            .subscribers
            .iter()
            .enumerate()
            .filter_map(|(k, &n)| {
                let name = &self.node(n).name;
                let m = compat::check(topic.requested.get(name)?, &offered);
                (!m.is_empty()).then(|| (k, name.clone(), m))
            })
            .collect()
    }
}

#[cfg(test)]
mod tests {
    use super::super::{GraphSpec, TopicId};
    use ratelab_core::qos::compat::{Durability, PolicyKind};

    const GRAPH: &str = r#"
[[node]]
name = "sensor"
kind = "sensor"
rate_hz = 50
publishes = "/obs"
[[node]]
name = "policy"
kind = "policy"
rate_hz = 50
subscribes = "/obs"
publishes = "/action"
liveliness_lease_ms = 100
[[node]]
name = "actuator"
kind = "actuator"
rate_hz = 50
subscribes = "/action"
[[topic]]
name = "/obs"
type = "state"
depth = 1
[[topic]]
name = "/action"
type = "force"
depth = 1
deadline_ms = 40
"#;

    fn with(tail: &str) -> Result<GraphSpec, String> {
        GraphSpec::parse(&format!("{GRAPH}{tail}\n"), "g.toml").map_err(|e| e.to_string())
    }

    #[test]
    fn a_request_is_read_checked_against_the_offer_and_written_back() {
        let spec = with(
            "[topic.requested.actuator]\nreliability = \"reliable\"\ndurability = \"volatile\"\ndeadline_ms = 20\nliveliness_lease_ms = 50",
        )
        .unwrap();
        let action = spec.topic_id("/action").unwrap();
        let r = spec.topic(action).requested["actuator"];
        assert_eq!(r.durability, Some(Durability::Volatile));
        let bad = spec.incompatible(action, &spec.topic(action).qos);
        assert_eq!(bad.len(), 1);
        let (k, node, m) = &bad[0];
        assert_eq!((*k, node.as_str()), (0, "actuator"));
        assert_eq!(
            m.iter().map(|m| m.policy).collect::<Vec<_>>(),
            [
                PolicyKind::Reliability,
                PolicyKind::Deadline,
                PolicyKind::LivelinessLeaseDuration
            ]
        );
        assert_eq!(
            m[1].to_string(),
            "requested deadline 20 ms, offered deadline 40 ms"
        );
        assert_eq!(
            m[2].to_string(),
            "requested lease 50 ms, offered lease 100 ms"
        );
        // Offered what it asks, the pair connects.
        let mut q = spec.topic(action).qos;
        q.reliability = ratelab_core::qos::Reliability::Reliable;
        q.deadline = Some(ratelab_core::time::Nanos::from_millis(20));
        assert_eq!(
            spec.incompatible(action, &q)[0].2.len(),
            1,
            "the lease still fails"
        );
        // Written back and read again alike (a launch sends the graph to its processes so).
        let again = GraphSpec::parse(&spec.to_toml(), "again").unwrap();
        assert_eq!(again.topic(action).requested, spec.topic(action).requested);
        // Nothing requested: nothing incompatible.
        let plain = with("").unwrap();
        assert!(plain
            .incompatible(TopicId(1), &plain.topics[1].qos)
            .is_empty());
    }

    #[test]
    fn requests_by_a_node_that_does_not_subscribe_or_with_bad_values_are_refused() {
        let e = with("[topic.requested.policy]\nreliability = \"reliable\"").unwrap_err();
        assert!(e.starts_with("g.toml:"), "{e}");
        assert!(
            e.contains("'policy' does not subscribe to /action (its subscribers: actuator)"),
            "{e}"
        );
        let e = with("[topic.requested.actuator]\nreliability = \"sometimes\"").unwrap_err();
        assert!(e.contains("unknown variant `sometimes`"), "{e}");
        let e = with("[topic.requested.actuator]\nhistory = \"keep_all\"").unwrap_err();
        assert!(e.contains("unknown field `history`"), "{e}");
        let e = with("[topic.requested.actuator]\ndeadline_ms = -1").unwrap_err();
        assert!(e.contains("deadline_ms must be > 0"), "{e}");
        let e = with("[topic.requested.actuator]\nliveliness_lease_ms = inf").unwrap_err();
        assert!(e.contains("liveliness_lease_ms must be > 0"), "{e}");
    }
}
