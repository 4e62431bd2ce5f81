//! Message types: what topics carry. Few, and named for what they carry (a graph file names
//! them `state`, `position`, `force`; [`MsgType`]).
//!
//! [`AnyTopic`] is a topic of any of them, for the views that only count messages (metrics,
//! the lab, recordings) and for changes that do not look inside (depth).

use crate::plant::Observation;
use crate::qos::TopicQos;
use crate::time::Nanos;
use crate::topic::{Topic, TopicStats, ZeroDepth};
use serde::{Deserialize, Serialize};
use std::sync::Arc;

/// What a topic carries.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum MsgType {
    /// The full state as the chapter's observation: `float32[5]` = cart position m, cart
    /// velocity m/s, cos θ, sin θ, pole angular velocity rad/s.
    State,
    /// A position measurement: cart position m and pole angle rad (no velocities).
    Position,
    /// A force command on the cart, newtons (the motor's range is ±[`crate::plant::GEAR_N`]).
    Force,
}

impl MsgType {
    /// The type's name as the file spells it.
    pub fn as_str(self) -> &'static str {
        match self {
            MsgType::State => "state",
            MsgType::Position => "position",
            MsgType::Force => "force",
        }
    }

    /// It alone, as a list of the types a node may publish.
    pub(crate) fn one(self) -> &'static [MsgType] {
        match self {
            MsgType::State => &[MsgType::State],
            MsgType::Position => &[MsgType::Position],
            MsgType::Force => &[MsgType::Force],
        }
    }
}

/// The full state, as the chapter's observation: `float32[5]` = cart position m, cart
/// velocity m/s, cos θ, sin θ, pole angular velocity rad/s.
pub type StateMsg = Observation;

/// A position measurement: what a sensor without velocity sensing reports.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PositionMsg {
    /// Cart position, m.
    pub cart_pos_m: f64,
    /// Pole angle from upright, rad, in [-π, π).
    pub pole_angle_rad: f64,
}

/// A force command on the cart, newtons. The motor's range is ±[`crate::plant::GEAR_N`]
/// (gear 10 on a control in [-1, 1]); the plant clips beyond it.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ForceMsg {
    /// Force, N (may be non-finite if a brain misbehaves; the actuator refuses those).
    pub newtons: f64,
}

/// A message's payload, by message type: what crosses a process boundary
/// ([`crate::distributed::wire`], postcard) and what is offered to ROS 2 ([`crate::ros2`]).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub enum MsgData {
    /// [`StateMsg`].
    State([f32; crate::plant::OBS_DIM]),
    /// [`PositionMsg`]: cart position m, pole angle rad.
    Position(f64, f64),
    /// [`ForceMsg`]: newtons.
    Force(f64),
}

impl From<StateMsg> for MsgData {
    fn from(m: StateMsg) -> MsgData {
        MsgData::State(m)
    }
}

impl From<PositionMsg> for MsgData {
    fn from(m: PositionMsg) -> MsgData {
        MsgData::Position(m.cart_pos_m, m.pole_angle_rad)
    }
}

impl From<ForceMsg> for MsgData {
    fn from(m: ForceMsg) -> MsgData {
        MsgData::Force(m.newtons)
    }
}

/// A topic of any message type.
#[derive(Clone, Debug)]
pub enum AnyTopic {
    /// Carries [`StateMsg`].
    State(Arc<Topic<StateMsg>>),
    /// Carries [`PositionMsg`].
    Position(Arc<Topic<PositionMsg>>),
    /// Carries [`ForceMsg`].
    Force(Arc<Topic<ForceMsg>>),
}

impl AnyTopic {
    /// A new topic of type `msg` with the chapter's QoS.
    ///
    /// # Errors
    /// [`ZeroDepth`] for depth 0.
    pub fn new(name: &str, msg: MsgType, depth: usize) -> Result<AnyTopic, ZeroDepth> {
        Self::with_qos(name, msg, depth, TopicQos::default(), 0)
    }

    /// A new topic of type `msg` with `qos`, its link seeded by `link_seed`.
    ///
    /// # Errors
    /// [`ZeroDepth`] for depth 0.
    pub fn with_qos(
        name: &str,
        msg: MsgType,
        depth: usize,
        qos: TopicQos,
        link_seed: u64,
    ) -> Result<AnyTopic, ZeroDepth> {
        Ok(match msg {
            MsgType::State => {
                AnyTopic::State(Arc::new(Topic::with_qos(name, depth, qos, link_seed)?))
            }
            MsgType::Position => {
                AnyTopic::Position(Arc::new(Topic::with_qos(name, depth, qos, link_seed)?))
            }
            MsgType::Force => {
                AnyTopic::Force(Arc::new(Topic::with_qos(name, depth, qos, link_seed)?))
            }
        })
    }

    /// The type of message it carries (the `msg` it was made with).
    pub fn msg_type(&self) -> MsgType {
        match self {
            AnyTopic::State(_) => MsgType::State,
            AnyTopic::Position(_) => MsgType::Position,
            AnyTopic::Force(_) => MsgType::Force,
        }
    }

    /// Counters and depth as of the topic's latest operation.
    pub fn stats(&self) -> TopicStats {
        match self {
            AnyTopic::State(t) => t.stats(),
            AnyTopic::Position(t) => t.stats(),
            AnyTopic::Force(t) => t.stats(),
        }
    }

    /// Counters and depth at run time `now` (see [`Topic::stats_at`]).
    pub fn stats_at(&self, now: Nanos) -> TopicStats {
        match self {
            AnyTopic::State(t) => t.stats_at(now),
            AnyTopic::Position(t) => t.stats_at(now),
            AnyTopic::Force(t) => t.stats_at(now),
        }
    }

    /// The QoS in force.
    pub fn qos(&self) -> TopicQos {
        match self {
            AnyTopic::State(t) => t.qos(),
            AnyTopic::Position(t) => t.qos(),
            AnyTopic::Force(t) => t.qos(),
        }
    }

    /// Change the QoS while running (see [`Topic::set_qos`]).
    pub fn set_qos(&self, qos: TopicQos) {
        match self {
            AnyTopic::State(t) => t.set_qos(qos),
            AnyTopic::Position(t) => t.set_qos(qos),
            AnyTopic::Force(t) => t.set_qos(qos),
        }
    }

    /// Change the history depth (see [`Topic::set_depth`]).
    ///
    /// # Errors
    /// [`ZeroDepth`] for 0.
    pub fn set_depth(&self, depth: usize) -> Result<(), ZeroDepth> {
        match self {
            AnyTopic::State(t) => t.set_depth(depth),
            AnyTopic::Position(t) => t.set_depth(depth),
            AnyTopic::Force(t) => t.set_depth(depth),
        }
    }

    /// Messages buffered now.
    pub fn buffered(&self) -> usize {
        match self {
            AnyTopic::State(t) => t.buffered(),
            AnyTopic::Position(t) => t.buffered(),
            AnyTopic::Force(t) => t.buffered(),
        }
    }

    /// Buffered messages no subscriber has seen yet (see [`Topic::unseen_buffered`]).
    pub fn unseen_buffered(&self) -> usize {
        match self {
            AnyTopic::State(t) => t.unseen_buffered(),
            AnyTopic::Position(t) => t.unseen_buffered(),
            AnyTopic::Force(t) => t.unseen_buffered(),
        }
    }

    /// The topic's name.
    pub fn name(&self) -> &str {
        match self {
            AnyTopic::State(t) => t.name(),
            AnyTopic::Position(t) => t.name(),
            AnyTopic::Force(t) => t.name(),
        }
    }
}
