//! The graph: sensor → `/obs` → policy → `/action` → actuator, around one cartpole.
//!
//! Semantics are the chapter's (ch2.8, `build_graph` and the three node classes):
//! - **sensor** (priority 0) reads the observation under the plant's lock and publishes it;
//! - **policy** (priority 1) runs the brain on `latest()` of `/obs` (does nothing before
//!   the first reading) and publishes the action with `origin_stamp` = the reading's stamp;
//! - **actuator** (priority 2, the plant's 50 Hz) applies `latest()` of `/action` (zero
//!   before the first) and steps the plant once. Re-applying a stale action is the
//!   zero-order hold. It alone steps the plant; a fall stops the graph.

use crate::metrics::{RunLog, StepRecord};
use crate::node::{Flow, Node};
use crate::plant::{Action, CartPole, Observation};
use crate::policy::BrainSlot;
use crate::rate::{InvalidRate, Rate};
use crate::time::Nanos;
use crate::topic::{Topic, ZeroDepth};
use std::sync::{Arc, Mutex, MutexGuard};

/// The plant shared by the sensor (reads) and the actuator (steps).
pub type SharedPlant = Arc<Mutex<CartPole>>;

/// Lock a shared value, tolerating poison (each holder leaves it consistent).
pub fn lock<T>(m: &Mutex<T>) -> MutexGuard<'_, T> {
    m.lock().unwrap_or_else(|e| e.into_inner())
}

/// Something told about every actuator tick (a recorder, the lab's telemetry).
/// Called on the actuator's thread: it must not block.
pub trait StepObserver: Send {
    /// The graph was built: a chance to keep handles (rates, topics) for later ticks.
    fn attach(&mut self, _handles: &GraphHandles) {}
    /// One actuator tick happened.
    fn on_step(&mut self, rec: &StepRecord);
}

/// Samples the plant and publishes on `/obs`.
pub struct SensorNode {
    plant: SharedPlant,
    obs: Arc<Topic<Observation>>,
    rate: Rate,
}

impl Node for SensorNode {
    fn name(&self) -> &str {
        "sensor"
    }
    fn priority(&self) -> u8 {
        0
    }
    fn rate(&self) -> &Rate {
        &self.rate
    }
    fn tick(&mut self, now: Nanos) -> Flow {
        let obs = lock(&self.plant).observe();
        self.obs.publish(obs, now, None);
        Flow::Continue
    }
}

/// Runs the brain on the newest `/obs` and publishes on `/action`.
pub struct PolicyNode {
    brain: BrainSlot,
    obs: Arc<Topic<Observation>>,
    action: Arc<Topic<Action>>,
    rate: Rate,
}

impl Node for PolicyNode {
    fn name(&self) -> &str {
        "policy"
    }
    fn priority(&self) -> u8 {
        1
    }
    fn rate(&self) -> &Rate {
        &self.rate
    }
    fn tick(&mut self, now: Nanos) -> Flow {
        let Some(msg) = self.obs.latest() else {
            return Flow::Continue; // nothing sensed yet
        };
        let action = self.brain.lock().act(&msg.data);
        self.action.publish(action, now, Some(msg.stamp));
        Flow::Continue
    }
}

/// Applies the newest `/action` (zero-order hold) and steps the plant.
pub struct ActuatorNode {
    plant: SharedPlant,
    obs: Arc<Topic<Observation>>,
    action: Arc<Topic<Action>>,
    rate: Rate,
    log: Arc<Mutex<RunLog>>,
    observers: Vec<Box<dyn StepObserver>>,
    /// The last finite action applied, with the origin stamp it carried.
    held: Option<(f32, Option<Nanos>)>,
}

impl Node for ActuatorNode {
    fn name(&self) -> &str {
        "actuator"
    }
    fn priority(&self) -> u8 {
        2
    }
    fn rate(&self) -> &Rate {
        &self.rate
    }
    fn tick(&mut self, now: Nanos) -> Flow {
        let newest = self.action.latest();
        let mut nonfinite = false;
        if let Some(msg) = newest {
            if msg.data[0].is_finite() {
                self.held = Some((msg.data[0], msg.origin_stamp));
            } else {
                nonfinite = true; // hold the last good action instead
            }
        }
        let (u, origin) = self.held.unwrap_or((0.0, None));
        let (outcome, step) = {
            let mut plant = lock(&self.plant);
            let outcome = plant.step(u);
            (outcome, plant.steps())
        };
        let rec = StepRecord {
            step,
            t: now,
            pole_angle: outcome.state.theta,
            cart_pos: outcome.state.cart_pos,
            action: outcome.applied,
            latency: origin.map(|o| now.saturating_sub(o)),
            nonfinite,
            obs: self.obs.stats(),
            action_topic: self.action.stats(),
            fell: outcome.terminated,
        };
        lock(&self.log).push(rec);
        for obs in &mut self.observers {
            obs.on_step(&rec);
        }
        if outcome.terminated {
            Flow::Stop
        } else {
            Flow::Continue
        }
    }
}

/// Rates of the three nodes, in Hz.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct GraphRates {
    /// Sensor rate.
    pub sensor_hz: f64,
    /// Policy (control) rate.
    pub control_hz: f64,
    /// Actuator rate (the plant's control rate, 50 Hz in the chapter).
    pub actuator_hz: f64,
}

/// Handles to change a running graph: rates, depths, the brain. Cheap to clone and
/// `Send`, so the lab's thread can hold one while the graph runs elsewhere.
#[derive(Clone)]
pub struct GraphHandles {
    /// The sensor's rate.
    pub sensor_rate: Rate,
    /// The policy's rate.
    pub control_rate: Rate,
    /// The actuator's rate.
    pub actuator_rate: Rate,
    /// `/obs`.
    pub obs: Arc<Topic<Observation>>,
    /// `/action`.
    pub action: Arc<Topic<Action>>,
    /// The policy node's brain.
    pub brain: BrainSlot,
    /// The plant.
    pub plant: SharedPlant,
    /// What the actuator measured.
    pub log: Arc<Mutex<RunLog>>,
}

impl GraphHandles {
    /// Set both topics' history depth.
    ///
    /// # Errors
    /// [`ZeroDepth`] for 0 (nothing changes).
    pub fn set_queue_depth(&self, depth: usize) -> Result<(), ZeroDepth> {
        self.obs.set_depth(depth)?;
        self.action.set_depth(depth)
    }
}

/// A built graph: the nodes (in priority order) plus the handles.
pub struct Graph {
    /// sensor, policy, actuator.
    pub nodes: Vec<Box<dyn Node>>,
    /// Handles into the running graph.
    pub handles: GraphHandles,
}

/// Why a graph cannot be built.
#[derive(Debug, thiserror::Error)]
pub enum GraphError {
    /// A rate out of range.
    #[error(transparent)]
    Rate(#[from] InvalidRate),
    /// Queue depth 0.
    #[error(transparent)]
    Depth(#[from] ZeroDepth),
}

impl Graph {
    /// Wire the three nodes around `plant` (already reset) with topics of `queue_depth`.
    /// `observers` are told about every actuator tick; `keep_trace` keeps every step record.
    ///
    /// # Errors
    /// [`GraphError`] for a bad rate or a zero depth.
    pub fn build(
        plant: CartPole,
        brain: BrainSlot,
        rates: GraphRates,
        queue_depth: usize,
        keep_trace: bool,
        mut observers: Vec<Box<dyn StepObserver>>,
    ) -> Result<Graph, GraphError> {
        let plant = Arc::new(Mutex::new(plant));
        let obs = Arc::new(Topic::new("/obs", queue_depth)?);
        let action = Arc::new(Topic::new("/action", queue_depth)?);
        let log = Arc::new(Mutex::new(RunLog::new(keep_trace)));
        let handles = GraphHandles {
            sensor_rate: Rate::new(rates.sensor_hz)?,
            control_rate: Rate::new(rates.control_hz)?,
            actuator_rate: Rate::new(rates.actuator_hz)?,
            obs: obs.clone(),
            action: action.clone(),
            brain: brain.clone(),
            plant: plant.clone(),
            log: log.clone(),
        };
        for o in &mut observers {
            o.attach(&handles);
        }
        let nodes: Vec<Box<dyn Node>> = vec![
            Box::new(SensorNode {
                plant: plant.clone(),
                obs: obs.clone(),
                rate: handles.sensor_rate.clone(),
            }),
            Box::new(PolicyNode {
                brain,
                obs: obs.clone(),
                action: action.clone(),
                rate: handles.control_rate.clone(),
            }),
            Box::new(ActuatorNode {
                plant,
                obs,
                action,
                rate: handles.actuator_rate.clone(),
                log,
                observers,
                held: None,
            }),
        ];
        Ok(Graph { nodes, handles })
    }
}
