//! QoS compatibility: whether what a subscription *requests* is met by what its publisher
//! *offers*, as ROS 2 decides it before it connects the two ("About Quality of Service
//! settings", section "QoS compatibilities",
//! <https://docs.ros.org/en/rolling/Concepts/Intermediate/About-Quality-of-Service-Settings.html>).
//! An incompatible pair is never connected: the subscription receives nothing, and ROS 2
//! raises an *incompatible QoS* event on both ends naming the policy that failed.
//!
//! The request-versus-offer table, policy by policy (✓ compatible, ✗ not):
//!
//! | policy | offered | requested | |
//! |---|---|---|---|
//! | reliability | best effort | best effort | ✓ |
//! | | best effort | reliable | ✗ |
//! | | reliable | best effort | ✓ |
//! | | reliable | reliable | ✓ |
//! | durability | volatile | volatile | ✓ |
//! | | volatile | transient local | ✗ |
//! | | transient local | volatile | ✓ |
//! | | transient local | transient local | ✓ |
//! | deadline | any | none (infinite) | ✓ |
//! | | none (infinite) | finite | ✗ |
//! | | *o* | *r* | ✓ when *o* ≤ *r* |
//! | liveliness | automatic | automatic | ✓ |
//! | | automatic | manual by topic | ✗ |
//! | | manual by topic | automatic | ✓ |
//! | | manual by topic | manual by topic | ✓ |
//! | lease duration | any | none (infinite) | ✓ |
//! | | none (infinite) | finite | ✗ |
//! | | *o* | *r* | ✓ when *o* ≤ *r* |
//!
//! A policy a subscription does not request (a key its `[topic.requested.NODE]` table leaves
//! out) accepts any offer: a graph that requests nothing connects every pair, as the
//! chapter's graph does. What ratelab offers: a topic's reliability, durability and deadline
//! ([`crate::qos::TopicQos`]), and its publisher node's liveliness — *automatic* (a node
//! asserts it by ticking) with the node's lease.

use crate::qos::{Reliability, TopicQos};
use crate::time::Nanos;
use serde::{Deserialize, Serialize};
use std::fmt;

/// Whether a publisher keeps messages for subscriptions that join later (ROS 2
/// *durability*).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Durability {
    /// Only subscriptions present when a message is published receive it.
    #[default]
    Volatile,
    /// The publisher keeps its last *depth* messages and hands them to a subscription that
    /// joins later.
    TransientLocal,
}

impl Durability {
    /// Its name in a graph file and `metrics.json`: `volatile`, `transient_local`.
    pub fn as_str(self) -> &'static str {
        match self {
            Durability::Volatile => "volatile",
            Durability::TransientLocal => "transient_local",
        }
    }
}

/// How a publisher's liveliness is asserted (ROS 2 *liveliness* kind).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum LivelinessKind {
    /// By the node running at all (ratelab: each tick).
    #[default]
    Automatic,
    /// Only by publishing on the topic (or an explicit assertion).
    ManualByTopic,
}

/// What a subscription asks of its publisher: each policy it requests, `None` for one it
/// leaves to the publisher (accepts any offer). A graph file's `[topic.requested.NODE]`
/// table; every key optional.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct RequestedQos {
    /// The reliability it requires.
    pub reliability: Option<Reliability>,
    /// The durability it requires.
    pub durability: Option<Durability>,
    /// The longest gap between messages it accepts (the offered deadline must be at most
    /// this).
    pub deadline: Option<Nanos>,
    /// The liveliness kind it requires.
    pub liveliness: Option<LivelinessKind>,
    /// The longest liveliness lease it accepts (the offered lease must be at most this).
    pub liveliness_lease: Option<Nanos>,
}

impl RequestedQos {
    /// True when it requests nothing (every offer is compatible).
    pub fn is_empty(&self) -> bool {
        *self == RequestedQos::default()
    }

    /// Set one key (`reliability=reliable`, `deadline_ms=20`, …: the graph file's
    /// `[topic.requested.NODE]` keys and values, as [`crate::qos::apply_key`] takes a topic's;
    /// `none` clears a key).
    ///
    /// # Errors
    /// A one-line reason for an unknown key or a bad value.
    pub fn apply_key(&mut self, key: &str, value: &str) -> Result<(), String> {
        let none = value.trim() == "none";
        let ms = || -> Result<Option<Nanos>, String> {
            let v: f64 = value
                .trim()
                .parse()
                .map_err(|_| format!("{key}: not a number: '{value}'"))?;
            super::ms_to_nanos(key, v, false).map(Some)
        };
        match key.trim() {
            "reliability" if none => self.reliability = None,
            "reliability" => self.reliability = Some(super::word(key, value)?),
            "durability" if none => self.durability = None,
            "durability" => self.durability = Some(super::word(key, value)?),
            "liveliness" if none => self.liveliness = None,
            "liveliness" => self.liveliness = Some(super::word(key, value)?),
            "deadline_ms" if none => self.deadline = None,
            "deadline_ms" => self.deadline = ms()?,
            "liveliness_lease_ms" if none => self.liveliness_lease = None,
            "liveliness_lease_ms" => self.liveliness_lease = ms()?,
            other => {
                return Err(format!(
                    "unknown requested QoS key '{}' (known: reliability, durability, deadline_ms, liveliness, liveliness_lease_ms)",
                    crate::text::printable(other)
                ))
            }
        }
        Ok(())
    }
}

/// What a publisher offers, in the policies [`check`] compares.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct OfferedQos {
    /// Its reliability.
    pub reliability: Reliability,
    /// Its durability.
    pub durability: Durability,
    /// Its deadline; `None`: infinite.
    pub deadline: Option<Nanos>,
    /// Its liveliness kind.
    pub liveliness: LivelinessKind,
    /// Its liveliness lease; `None`: infinite.
    pub liveliness_lease: Option<Nanos>,
}

impl OfferedQos {
    /// What a ratelab topic of `qos`, published by a node of liveliness lease `lease`,
    /// offers: its reliability, durability and deadline, automatic liveliness with the
    /// lease.
    pub fn of_topic(qos: &TopicQos, lease: Option<Nanos>) -> OfferedQos {
        OfferedQos {
            reliability: qos.reliability,
            durability: qos.durability,
            deadline: qos.deadline,
            liveliness: LivelinessKind::Automatic,
            liveliness_lease: lease,
        }
    }
}

/// A QoS policy, named as ROS 2's `rmw_qos_policy_kind_t` names it in the incompatible-QoS
/// event (`last_policy_kind`).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "SCREAMING_SNAKE_CASE")]
pub enum PolicyKind {
    /// Reliability.
    Reliability,
    /// Durability.
    Durability,
    /// Deadline.
    Deadline,
    /// Liveliness kind.
    Liveliness,
    /// Liveliness lease duration (ROS 2 reports it as `LIVELINESS` too; ratelab names it).
    LivelinessLeaseDuration,
}

impl PolicyKind {
    /// The name as `metrics.json` writes it (`RELIABILITY`, …).
    pub fn as_str(self) -> &'static str {
        match self {
            PolicyKind::Reliability => "RELIABILITY",
            PolicyKind::Durability => "DURABILITY",
            PolicyKind::Deadline => "DEADLINE",
            PolicyKind::Liveliness => "LIVELINESS",
            PolicyKind::LivelinessLeaseDuration => "LIVELINESS_LEASE_DURATION",
        }
    }
}

/// One policy whose request the offer does not meet: the values as ROS 2's tools print
/// them (`RELIABLE`, `BEST_EFFORT`, `deadline 20 ms`, `no deadline`).
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Mismatch {
    /// The policy.
    pub policy: PolicyKind,
    /// What the subscription requested.
    pub requested: String,
    /// What the publisher offered.
    pub offered: String,
}

impl fmt::Display for Mismatch {
    /// `requested RELIABLE, offered BEST_EFFORT`.
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "requested {}, offered {}", self.requested, self.offered)
    }
}

fn reliability_name(r: Reliability) -> &'static str {
    match r {
        Reliability::BestEffort => "BEST_EFFORT",
        Reliability::Reliable => "RELIABLE",
    }
}

fn durability_name(d: Durability) -> &'static str {
    match d {
        Durability::Volatile => "VOLATILE",
        Durability::TransientLocal => "TRANSIENT_LOCAL",
    }
}

fn liveliness_name(l: LivelinessKind) -> &'static str {
    match l {
        LivelinessKind::Automatic => "AUTOMATIC",
        LivelinessKind::ManualByTopic => "MANUAL_BY_TOPIC",
    }
}

/// `what 20 ms`, or `no what` for infinite.
fn duration_text(what: &str, d: Option<Nanos>) -> String {
    d.map_or_else(|| format!("no {what}"), |d| format!("{what} {d}"))
}

/// A requested duration (deadline, lease) against the offered one: compatible when the
/// request is infinite or the offer is finite and no longer.
fn duration_ok(requested: Option<Nanos>, offered: Option<Nanos>) -> bool {
    match (requested, offered) {
        (None, _) => true,
        (Some(_), None) => false,
        (Some(r), Some(o)) => o <= r,
    }
}

/// Every policy whose request `offered` does not meet, in the table's order (module docs);
/// empty when the pair is compatible. ROS 2's event names one of them (`last_policy_kind`);
/// ratelab says them all, and `metrics.json`'s `policy` names the first.
pub fn check(requested: &RequestedQos, offered: &OfferedQos) -> Vec<Mismatch> {
    let mut out = Vec::new();
    if requested.reliability == Some(Reliability::Reliable)
        && offered.reliability == Reliability::BestEffort
    {
        out.push(Mismatch {
            policy: PolicyKind::Reliability,
            requested: reliability_name(Reliability::Reliable).into(),
            offered: reliability_name(offered.reliability).into(),
        });
    }
    if requested.durability == Some(Durability::TransientLocal)
        && offered.durability == Durability::Volatile
    {
        out.push(Mismatch {
            policy: PolicyKind::Durability,
            requested: durability_name(Durability::TransientLocal).into(),
            offered: durability_name(offered.durability).into(),
        });
    }
    if !duration_ok(requested.deadline, offered.deadline) {
        out.push(Mismatch {
            policy: PolicyKind::Deadline,
            requested: duration_text("deadline", requested.deadline),
            offered: duration_text("deadline", offered.deadline),
        });
    }
    if requested.liveliness == Some(LivelinessKind::ManualByTopic)
        && offered.liveliness == LivelinessKind::Automatic
    {
        out.push(Mismatch {
            policy: PolicyKind::Liveliness,
            requested: liveliness_name(LivelinessKind::ManualByTopic).into(),
            offered: liveliness_name(offered.liveliness).into(),
        });
    }
    if !duration_ok(requested.liveliness_lease, offered.liveliness_lease) {
        out.push(Mismatch {
            policy: PolicyKind::LivelinessLeaseDuration,
            requested: duration_text("lease", requested.liveliness_lease),
            offered: duration_text("lease", offered.liveliness_lease),
        });
    }
    out
}

/// `incompatible QoS: requested RELIABLE, offered BEST_EFFORT` (several mismatches joined by
/// `; `): ROS 2's incompatible-QoS event in one line. Empty `mismatches`: empty text.
pub fn event_text(mismatches: &[Mismatch]) -> String {
    if mismatches.is_empty() {
        return String::new();
    }
    let each: Vec<String> = mismatches.iter().map(ToString::to_string).collect();
    format!("incompatible QoS: {}", each.join("; "))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn ms(v: u64) -> Option<Nanos> {
        Some(Nanos(v * 1_000_000))
    }

    /// Each row of ROS 2's compatibility table (module docs), policy by policy.
    #[test]
    fn every_row_of_ros_2s_table() {
        use Durability::*;
        use LivelinessKind::*;
        use Reliability::*;
        let offer = OfferedQos::default();
        let req = RequestedQos::default();
        for (o, r, ok) in [
            (BestEffort, BestEffort, true),
            (BestEffort, Reliable, false),
            (Reliable, BestEffort, true),
            (Reliable, Reliable, true),
        ] {
            let m = check(
                &RequestedQos {
                    reliability: Some(r),
                    ..req
                },
                &OfferedQos {
                    reliability: o,
                    ..offer
                },
            );
            assert_eq!(
                m.is_empty(),
                ok,
                "reliability {o:?} offered, {r:?} requested"
            );
        }
        for (o, r, ok) in [
            (Volatile, Volatile, true),
            (Volatile, TransientLocal, false),
            (TransientLocal, Volatile, true),
            (TransientLocal, TransientLocal, true),
        ] {
            let m = check(
                &RequestedQos {
                    durability: Some(r),
                    ..req
                },
                &OfferedQos {
                    durability: o,
                    ..offer
                },
            );
            assert_eq!(
                m.is_empty(),
                ok,
                "durability {o:?} offered, {r:?} requested"
            );
        }
        for (o, r, ok) in [
            (Automatic, Automatic, true),
            (Automatic, ManualByTopic, false),
            (ManualByTopic, Automatic, true),
            (ManualByTopic, ManualByTopic, true),
        ] {
            let m = check(
                &RequestedQos {
                    liveliness: Some(r),
                    ..req
                },
                &OfferedQos {
                    liveliness: o,
                    ..offer
                },
            );
            assert_eq!(
                m.is_empty(),
                ok,
                "liveliness {o:?} offered, {r:?} requested"
            );
        }
        // Deadline and lease: infinite requests accept anything; a finite one needs an offer
        // no longer than itself.
        for (o, r, ok) in [
            (None, None, true),
            (ms(40), None, true),
            (None, ms(40), false),
            (ms(40), ms(40), true),
            (ms(20), ms(40), true),
            (ms(50), ms(40), false),
        ] {
            let dl = check(
                &RequestedQos { deadline: r, ..req },
                &OfferedQos {
                    deadline: o,
                    ..offer
                },
            );
            assert_eq!(dl.is_empty(), ok, "deadline {o:?} offered, {r:?} requested");
            let lease = check(
                &RequestedQos {
                    liveliness_lease: r,
                    ..req
                },
                &OfferedQos {
                    liveliness_lease: o,
                    ..offer
                },
            );
            assert_eq!(lease.is_empty(), ok, "lease {o:?} offered, {r:?} requested");
        }
    }

    #[test]
    fn the_event_says_each_policy_that_failed_as_ros_2_names_the_values() {
        let req = RequestedQos {
            reliability: Some(Reliability::Reliable),
            deadline: ms(20),
            ..RequestedQos::default()
        };
        let offer = OfferedQos::of_topic(&TopicQos::default(), None);
        let m = check(&req, &offer);
        assert_eq!(
            m.iter().map(|m| m.policy).collect::<Vec<_>>(),
            [PolicyKind::Reliability, PolicyKind::Deadline]
        );
        assert_eq!(
            event_text(&m[..1]),
            "incompatible QoS: requested RELIABLE, offered BEST_EFFORT"
        );
        assert_eq!(
            event_text(&m),
            "incompatible QoS: requested RELIABLE, offered BEST_EFFORT; requested deadline 20 ms, offered no deadline"
        );
        assert_eq!(event_text(&[]), "");
        // A request of nothing meets any offer.
        assert!(RequestedQos::default().is_empty());
        assert!(check(&RequestedQos::default(), &offer).is_empty());
    }
}
