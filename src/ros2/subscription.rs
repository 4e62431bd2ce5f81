//! How `ratelab ros2 topic echo|hz|bw` subscribe to a topic: with the QoS ros2cli chooses
//! for its subscription, made into the Zenoh subscription rmw_zenoh_cpp makes for that QoS.
//! So a transient-local ("latched") topic prints its publishers' stored messages at once,
//! as `ros2 topic echo` prints them, even when nothing is published any more.
//!
//! **The choice** ([`choose_qos`]) is ros2cli's `choose_qos` (ros2topic's `verb/echo.py` in
//! ros2cli 0.36.1, Kilted's; `ros2cli/qos.py` later, where `topic bw` uses it too). The
//! profile starts as rclpy's `sensor_data` preset (best effort, volatile, keep last
//! [`SENSOR_DATA_DEPTH`]), and:
//! - with no `--qos-*` flag it adapts to the topic's publishers: reliable when every one
//!   offers reliable, else best effort; transient local when every one offers transient
//!   local, else volatile. When some but not all offer the stronger policy, ros2cli says so
//!   in one line on stdout ([`SOME_RELIABLE`], [`SOME_TRANSIENT_LOCAL`]) and takes the
//!   weaker, which connects to all of them.
//! - with `--qos-reliability` or `--qos-durability` nothing adapts: the flags' values
//!   replace the preset's, and a policy not given keeps the preset's (so
//!   `--qos-reliability reliable` alone subscribes volatile, as ros2cli does).
//!
//! The flags take rclpy's short keys ([`RELIABILITY_KEYS`], [`DURABILITY_KEYS`]);
//! `system_default` is what rmw_zenoh_cpp makes of it (`rmw_zenoh_cpp/src/detail/qos.cpp`,
//! `QoS::best_available_qos`): reliable, volatile. rclpy's `unknown` and `best_available`
//! are not taken.
//!
//! **The subscription** ([`subscribe`]) is rmw_zenoh_cpp's (`rmw_subscription_data.cpp`,
//! `SubscriptionData::init`): a transient-local one is a Zenoh advanced subscriber
//! (`zenoh-ext`) that asks every publisher's cache for its history (at most `depth`
//! samples each), detects publishers that appear later and asks theirs too, and can itself
//! be detected; reliable as well, it also recovers missed samples through the publishers'
//! heartbeats. A volatile one is a plain subscriber (in Zenoh 1.x reliability is the
//! publisher's). The history queries time out after zenoh-ext's default, 10 s, where
//! rmw_zenoh_cpp waits without limit.

use super::rmw_zenoh::entity::EndpointEntity;
use super::rmw_zenoh::key_expr::KeyExprFormat;
pub use super::rmw_zenoh::qos::{QosDurability, QosProfile, QosReliability};
use super::{zerr, Ros2Error};
use zenoh::Wait;

/// rclpy's `sensor_data` preset's depth (`rmw_qos_profile_sensor_data`): the history a
/// transient-local subscription asks of each publisher.
pub const SENSOR_DATA_DEPTH: usize = 5;

/// `--qos-reliability`'s values: rclpy's short keys (`QoSReliabilityPolicy.short_keys()`)
/// that a subscription can be made with.
pub const RELIABILITY_KEYS: [&str; 3] = ["system_default", "reliable", "best_effort"];

/// `--qos-durability`'s values: rclpy's short keys (`QoSDurabilityPolicy.short_keys()`)
/// that a subscription can be made with.
pub const DURABILITY_KEYS: [&str; 3] = ["system_default", "transient_local", "volatile"];

/// What ros2cli prints when some, but not all, of a topic's publishers offer reliable.
pub const SOME_RELIABLE: &str = "Some, but not all, publishers are offering QoSReliabilityPolicy.RELIABLE. Falling back to QoSReliabilityPolicy.BEST_EFFORT as it will connect to all publishers";

/// What ros2cli prints when some, but not all, of a topic's publishers offer transient
/// local.
pub const SOME_TRANSIENT_LOCAL: &str = "Some, but not all, publishers are offering QoSDurabilityPolicy.TRANSIENT_LOCAL. Falling back to QoSDurabilityPolicy.VOLATILE as it will connect to all publishers";

/// `--qos-reliability KEY` ([`RELIABILITY_KEYS`]) as the reliability rmw_zenoh_cpp
/// subscribes with (`system_default`: reliable).
///
/// # Errors
/// Any other key: the keys taken, in one line.
pub fn reliability_from_key(key: &str) -> Result<QosReliability, String> {
    match key {
        "system_default" | "reliable" => Ok(QosReliability::Reliable),
        "best_effort" => Ok(QosReliability::BestEffort),
        _ => Err(format!(
            "--qos-reliability '{}' is not one of {}",
            ratelab_core::text::printable(key),
            RELIABILITY_KEYS.join(", ")
        )),
    }
}

/// `--qos-durability KEY` ([`DURABILITY_KEYS`]) as the durability rmw_zenoh_cpp
/// subscribes with (`system_default`: volatile).
///
/// # Errors
/// Any other key: the keys taken, in one line.
pub fn durability_from_key(key: &str) -> Result<QosDurability, String> {
    match key {
        "system_default" | "volatile" => Ok(QosDurability::Volatile),
        "transient_local" => Ok(QosDurability::TransientLocal),
        _ => Err(format!(
            "--qos-durability '{}' is not one of {}",
            ratelab_core::text::printable(key),
            DURABILITY_KEYS.join(", ")
        )),
    }
}

/// The `--qos-*` flags a reader was given, read ([`reliability_from_key`],
/// [`durability_from_key`]); none: the subscription adapts to the publishers.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct QosFlags {
    /// `--qos-reliability`.
    pub reliability: Option<QosReliability>,
    /// `--qos-durability`.
    pub durability: Option<QosDurability>,
}

/// The QoS a reader subscribes with.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Requested {
    /// Reliable: a transient-local subscription also recovers missed samples.
    pub reliability: QosReliability,
    /// Transient local: the publishers' stored messages are asked for.
    pub durability: QosDurability,
    /// Keep last this many (messages asked of each publisher's history).
    pub depth: usize,
}

impl Requested {
    /// rclpy's `sensor_data` preset: best effort, volatile, keep last
    /// [`SENSOR_DATA_DEPTH`] (ros2cli's default profile for `echo`, `hz` and `bw`).
    pub const SENSOR_DATA: Requested = Requested {
        reliability: QosReliability::BestEffort,
        durability: QosDurability::Volatile,
        depth: SENSOR_DATA_DEPTH,
    };
}

/// The QoS chosen, and ros2cli's lines about the choice (printed on stdout before the
/// messages, as ros2cli prints them).
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Choice {
    /// What to subscribe with.
    pub qos: Requested,
    /// [`SOME_RELIABLE`] and [`SOME_TRANSIENT_LOCAL`], when they apply, in that order.
    pub notes: Vec<&'static str>,
}

/// ros2cli's `choose_qos` (module header): the QoS to subscribe with, given the QoS each of
/// the topic's publishers `offered` (from their tokens) and the `flags`.
pub fn choose_qos(offered: &[QosProfile], flags: QosFlags) -> Choice {
    let mut qos = Requested::SENSOR_DATA;
    let mut notes = Vec::new();
    if flags.reliability.is_some() || flags.durability.is_some() {
        qos.reliability = flags.reliability.unwrap_or(qos.reliability);
        qos.durability = flags.durability.unwrap_or(qos.durability);
        return Choice { qos, notes };
    }
    // No publisher: the preset as it is (ros2cli's `publishers_count == 0`).
    if offered.is_empty() {
        return Choice { qos, notes };
    }
    let reliable = offered
        .iter()
        .filter(|q| q.reliability == QosReliability::Reliable)
        .count();
    let lasting = offered
        .iter()
        .filter(|q| q.durability == QosDurability::TransientLocal)
        .count();
    qos.reliability = if reliable == offered.len() {
        QosReliability::Reliable
    } else {
        if reliable > 0 {
            notes.push(SOME_RELIABLE);
        }
        QosReliability::BestEffort
    };
    qos.durability = if lasting == offered.len() {
        QosDurability::TransientLocal
    } else {
        if lasting > 0 {
            notes.push(SOME_TRANSIENT_LOCAL);
        }
        QosDurability::Volatile
    };
    Choice { qos, notes }
}

/// A reader's subscription: it listens until dropped.
pub enum Subscription {
    /// A plain Zenoh subscriber (volatile).
    Volatile(zenoh::pubsub::Subscriber<()>),
    /// An advanced subscriber asking for history (transient local).
    TransientLocal(Box<zenoh_ext::AdvancedSubscriber<()>>),
}

impl std::fmt::Debug for Subscription {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            Subscription::Volatile(_) => "Subscription::Volatile",
            Subscription::TransientLocal(_) => "Subscription::TransientLocal",
        })
    }
}

/// Subscribe to `publisher`'s topic on its data key (its domain, topic, type and hash) with
/// `qos`, as rmw_zenoh_cpp subscribes (module header): `on` gets each message's payload, a
/// transient-local subscription's history first, oldest first per publisher.
///
/// # Errors
/// [`Ros2Error::Zenoh`]: the key could not be made or the declaration failed.
pub fn subscribe(
    session: &zenoh::Session,
    publisher: &EndpointEntity,
    qos: &Requested,
    on: impl Fn(Vec<u8>) + Send + Sync + 'static,
) -> Result<Subscription, Ros2Error> {
    use zenoh_ext::{AdvancedSubscriberBuilderExt, HistoryConfig, RecoveryConfig};
    let key = KeyExprFormat.topic_key_expr(publisher).map_err(zerr)?;
    let deliver = move |s: zenoh::sample::Sample| on(s.payload().to_bytes().into_owned());
    if qos.durability == QosDurability::Volatile {
        let sub = session
            .declare_subscriber(key)
            .callback(deliver)
            .wait()
            .map_err(zerr)?;
        return Ok(Subscription::Volatile(sub));
    }
    // rmw_zenoh_cpp: history of at most `depth` samples per publisher, late publishers
    // detected and asked, the subscriber detectable (zenoh-ext refuses a depth of 0).
    let history = HistoryConfig::default()
        .detect_late_publishers()
        .max_samples(qos.depth.max(1));
    let builder = session
        .declare_subscriber(key)
        .callback(deliver)
        .history(history)
        .subscriber_detection();
    let builder = if qos.reliability == QosReliability::Reliable {
        builder.recovery(RecoveryConfig::default().heartbeat())
    } else {
        builder
    };
    let sub = builder.wait().map_err(zerr)?;
    Ok(Subscription::TransientLocal(Box::new(sub)))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn offer(reliability: QosReliability, durability: QosDurability) -> QosProfile {
        QosProfile {
            reliability,
            durability,
            ..QosProfile::default()
        }
    }

    const RELIABLE: QosReliability = QosReliability::Reliable;
    const BEST_EFFORT: QosReliability = QosReliability::BestEffort;
    const LASTING: QosDurability = QosDurability::TransientLocal;
    const VOLATILE: QosDurability = QosDurability::Volatile;

    fn chosen(offered: &[QosProfile]) -> (QosReliability, QosDurability, Vec<&'static str>) {
        let c = choose_qos(offered, QosFlags::default());
        assert_eq!(c.qos.depth, SENSOR_DATA_DEPTH);
        (c.qos.reliability, c.qos.durability, c.notes)
    }

    /// A latched topic (every publisher reliable and transient local, as a real latcher's
    /// and every node's /rosout) is subscribed to reliable and transient local.
    #[test]
    fn every_publisher_transient_local_and_reliable_is_followed() {
        let latched = offer(RELIABLE, LASTING);
        assert_eq!(chosen(&[latched]), (RELIABLE, LASTING, vec![]));
        assert_eq!(chosen(&[latched, latched]), (RELIABLE, LASTING, vec![]));
        // ratelab's own transient-local topics are best effort by default.
        let beat = offer(BEST_EFFORT, LASTING);
        assert_eq!(chosen(&[beat]), (BEST_EFFORT, LASTING, vec![]));
        assert_eq!(
            chosen(&[offer(RELIABLE, VOLATILE)]),
            (RELIABLE, VOLATILE, vec![])
        );
    }

    /// Some but not all: the weaker policy, said in ros2cli's words; none: no words.
    #[test]
    fn a_mixed_topic_falls_back_to_the_weaker_policy_and_says_so() {
        let mixed = [offer(RELIABLE, LASTING), offer(BEST_EFFORT, VOLATILE)];
        assert_eq!(
            chosen(&mixed),
            (
                BEST_EFFORT,
                VOLATILE,
                vec![SOME_RELIABLE, SOME_TRANSIENT_LOCAL]
            )
        );
        let durability_only = [offer(RELIABLE, LASTING), offer(RELIABLE, VOLATILE)];
        assert_eq!(
            chosen(&durability_only),
            (RELIABLE, VOLATILE, vec![SOME_TRANSIENT_LOCAL])
        );
        assert_eq!(
            chosen(&[offer(BEST_EFFORT, VOLATILE)]),
            (BEST_EFFORT, VOLATILE, vec![])
        );
        assert!(SOME_TRANSIENT_LOCAL.starts_with(
            "Some, but not all, publishers are offering QoSDurabilityPolicy.TRANSIENT_LOCAL."
        ));
    }

    /// No publisher: ros2cli's preset as it is.
    #[test]
    fn no_publisher_leaves_sensor_data() {
        let c = choose_qos(&[], QosFlags::default());
        assert_eq!(c.qos, Requested::SENSOR_DATA);
        assert!(c.notes.is_empty());
    }

    /// A flag turns the adaptation off: the policy it does not give is the preset's.
    #[test]
    fn a_flag_replaces_the_preset_and_nothing_adapts() {
        let latched = [offer(RELIABLE, LASTING)];
        let only_reliability = QosFlags {
            reliability: Some(RELIABLE),
            durability: None,
        };
        let c = choose_qos(&latched, only_reliability);
        assert_eq!((c.qos.reliability, c.qos.durability), (RELIABLE, VOLATILE));
        let volatile = QosFlags {
            reliability: None,
            durability: Some(VOLATILE),
        };
        let c = choose_qos(&latched, volatile);
        assert_eq!(
            (c.qos.reliability, c.qos.durability),
            (BEST_EFFORT, VOLATILE)
        );
        // And a mixed topic is not spoken of: nothing was adapted.
        let mixed = [offer(RELIABLE, LASTING), offer(BEST_EFFORT, VOLATILE)];
        let lasting = QosFlags {
            reliability: None,
            durability: Some(LASTING),
        };
        let c = choose_qos(&mixed, lasting);
        assert_eq!(
            (c.qos.reliability, c.qos.durability),
            (BEST_EFFORT, LASTING)
        );
        assert!(c.notes.is_empty());
    }

    #[test]
    fn the_short_keys_read_as_rmw_zenoh_cpp_makes_them() {
        assert_eq!(reliability_from_key("reliable"), Ok(RELIABLE));
        assert_eq!(reliability_from_key("best_effort"), Ok(BEST_EFFORT));
        assert_eq!(reliability_from_key("system_default"), Ok(RELIABLE));
        assert_eq!(durability_from_key("transient_local"), Ok(LASTING));
        assert_eq!(durability_from_key("volatile"), Ok(VOLATILE));
        assert_eq!(durability_from_key("system_default"), Ok(VOLATILE));
        for key in RELIABILITY_KEYS {
            assert!(reliability_from_key(key).is_ok(), "{key}");
        }
        for key in DURABILITY_KEYS {
            assert!(durability_from_key(key).is_ok(), "{key}");
        }
        let e = durability_from_key("best_available").unwrap_err();
        assert_eq!(
            e,
            "--qos-durability 'best_available' is not one of system_default, transient_local, volatile"
        );
        assert!(!reliability_from_key("x\n").unwrap_err().contains('\n'));
    }
}
