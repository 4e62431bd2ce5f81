//! The node kinds at run time: what each does on a tick (ch2.8's node classes, generalized).
//!
//! - **sensor**: reads the plant under its lock and publishes the full state (the chapter's
//!   observation) or a position measurement, with optional seeded Gaussian noise on the
//!   positions. Its message's origin stamp is its own stamp: the reading.
//! - **estimator**: reads the newest position measurement, updates the
//!   [`VelocityFilter`], publishes the state estimate. Before its first measurement it
//!   publishes nothing.
//! - **policy**: runs the brain on the newest state (nothing before the first) and publishes
//!   the force, `command × GEAR_N` newtons.
//! - **safety**: clamps the newest force to ±`max_force_n` and republishes it.
//! - **python**: the learner's node ([`crate::python::node`]): its subscription callback for
//!   what arrived, then its timers; what they published goes out with the input's origin.
//! - a **registered** kind ([`super::registry`]): the node's `tick` for what arrived; what
//!   it returned goes out with the input's origin.
//! - **actuator**: applies the newest force (zero before the first), steps the plant once and
//!   records the step. Re-applying a stale force is the zero-order hold; a non-finite force
//!   is refused and the last good one held. It alone steps the plant; a fall stops the graph.
//!
//! Every node that publishes passes on the origin stamp of the message it derived its output
//! from, so the actuator measures sense→act latency (`now − origin`) across any chain. Every
//! kind has one input; a kind that combined several would pass on the oldest origin.

use super::estimator::VelocityFilter;
use super::spec::NodeId;
use super::{lock, SharedPlant, StepObserver};
use crate::msg::{AnyTopic, ForceMsg, PositionMsg, StateMsg};
use crate::node::{Flow, Node};
use crate::plant::GEAR_N;
use crate::policy::BrainSlot;
use crate::qos::{Fault, Liveliness, OnDeadlineMissed};
use crate::rate::Rate;
use crate::runlog::{RunLog, StepRecord};
use crate::time::Nanos;
use crate::topic::Topic;
use rand_distr::{Distribution, Normal};
use std::sync::{Arc, Mutex};

/// What every node carries: its identity, tie-break rank and rate.
pub struct NodeCore {
    /// Its name (from the graph file).
    pub name: String,
    /// Its index in the graph (the tie-break rank).
    pub id: NodeId,
    /// Its rate (shared with the graph's handles).
    pub rate: Rate,
    /// Its liveliness, asserted by every tick (shared with the graph's handles).
    pub liveliness: Arc<Liveliness>,
    /// Faults injected into it (`--stall`, `--kill`).
    pub faults: Vec<Fault>,
}

/// A node of some kind around its [`NodeCore`].
pub struct GraphNode {
    core: NodeCore,
    work: Work,
}

/// The kind-specific state.
pub enum Work {
    /// See the module docs.
    Sensor(Sensor),
    /// See the module docs.
    Estimator {
        /// Input.
        input: Arc<Topic<PositionMsg>>,
        /// Output.
        output: Arc<Topic<StateMsg>>,
        /// The filter.
        filter: VelocityFilter,
        /// `seq` of the last measurement fed to the filter.
        last_seq: Option<u64>,
        /// Origin of the newest measurement used.
        origin: Option<Nanos>,
    },
    /// See the module docs.
    Policy {
        /// The brain.
        brain: BrainSlot,
        /// Input.
        input: Arc<Topic<StateMsg>>,
        /// Output.
        output: Arc<Topic<ForceMsg>>,
    },
    /// See the module docs.
    Safety {
        /// Input.
        input: Arc<Topic<ForceMsg>>,
        /// Output.
        output: Arc<Topic<ForceMsg>>,
        /// Largest magnitude passed on, N.
        max_force_n: f64,
    },
    /// See the module docs.
    Actuator(Box<Actuator>),
    /// A learner's node in Python ([`crate::python::node`]).
    Python(Box<crate::python::node::PythonNode>),
    /// A node of a kind registered in Rust ([`super::registry`]), bound to its topics.
    Registered(Box<dyn super::registry::Tick>),
}

/// A sensor's state.
pub struct Sensor {
    /// The plant it reads.
    pub plant: SharedPlant,
    /// Where it publishes.
    pub output: SensorOutput,
    /// Noise on (cart position, pole angle), with its generator; `None` when noiseless.
    pub noise: Option<SensorNoise>,
}

/// A sensor's topic: full state or positions.
pub enum SensorOutput {
    /// Publishes the full state.
    State(Arc<Topic<StateMsg>>),
    /// Publishes positions.
    Position(Arc<Topic<PositionMsg>>),
}

/// Seeded Gaussian measurement noise.
pub struct SensorNoise {
    /// The generator (PCG64, seeded from the run's seed and the node's rank).
    pub rng: rand_pcg::Pcg64,
    /// Cart-position noise, m (standard deviation).
    pub pos: Normal<f64>,
    /// Pole-angle noise, rad (standard deviation).
    pub angle: Normal<f64>,
}

impl SensorNoise {
    /// Noise with these standard deviations, seeded by `(seed, node)`: same seed, same draws.
    ///
    /// # Panics
    /// Never for the finite, non-negative deviations a validated graph holds.
    pub fn new(seed: u64, node: NodeId, pos_m: f64, angle_rad: f64) -> SensorNoise {
        SensorNoise {
            rng: rand_pcg::Pcg64::new(u128::from(seed), 0xda3e_39cb_94b9_5bdb ^ node.0 as u128),
            pos: Normal::new(0.0, pos_m).expect("validated deviation"),
            angle: Normal::new(0.0, angle_rad).expect("validated deviation"),
        }
    }
}

/// The actuator's state.
pub struct Actuator {
    /// The plant it steps.
    pub plant: SharedPlant,
    /// Its input.
    pub input: Arc<Topic<ForceMsg>>,
    /// Every topic of the graph, for the per-step counters.
    pub topics: Vec<AnyTopic>,
    /// Where steps are accounted.
    pub log: Arc<Mutex<RunLog>>,
    /// Told about every step.
    pub observers: Vec<Box<dyn StepObserver>>,
    /// The last finite command applied (in [-1, 1] units of the motor), with its origin.
    pub held: Option<(f32, Option<Nanos>)>,
    /// The policy's output topic, watched (never read) for what it published.
    pub policy_output: Option<Arc<Topic<ForceMsg>>>,
    /// `seq` of the newest policy message already reported.
    pub reported: Option<u64>,
}

impl GraphNode {
    /// A node of `work`'s kind.
    pub fn new(core: NodeCore, work: Work) -> GraphNode {
        GraphNode { core, work }
    }
}

impl Node for GraphNode {
    fn name(&self) -> &str {
        &self.core.name
    }
    fn priority(&self) -> u32 {
        self.core.id.0 as u32
    }
    fn rate(&self) -> &Rate {
        &self.core.rate
    }
    fn tick(&mut self, now: Nanos) -> Flow {
        if self.core.faults.iter().any(|f| f.covers(now)) {
            self.core.liveliness.fault_tick();
            return Flow::Continue; // stalled or killed: no work, no liveliness
        }
        self.core.liveliness.assert_at(now);
        match &mut self.work {
            Work::Sensor(s) => {
                let state = lock(&s.plant).state();
                match &s.output {
                    SensorOutput::State(t) => {
                        let mut obs = state.observation();
                        if let Some(n) = &mut s.noise {
                            obs[0] = (state.cart_pos + n.pos.sample(&mut n.rng)) as f32;
                            let th = state.theta + n.angle.sample(&mut n.rng);
                            obs[2] = th.cos() as f32;
                            obs[3] = th.sin() as f32;
                        }
                        t.publish(obs, now, Some(now));
                    }
                    SensorOutput::Position(t) => {
                        let (mut x, mut th) = (state.cart_pos, state.theta);
                        if let Some(n) = &mut s.noise {
                            x += n.pos.sample(&mut n.rng);
                            th += n.angle.sample(&mut n.rng);
                        }
                        let m = PositionMsg {
                            cart_pos_m: x,
                            pole_angle_rad: th,
                        };
                        t.publish(m, now, Some(now));
                    }
                }
                Flow::Continue
            }
            Work::Estimator {
                input,
                output,
                filter,
                last_seq,
                origin,
            } => {
                if let Some(msg) = input.read(now) {
                    if *last_seq != Some(msg.seq) {
                        *last_seq = Some(msg.seq);
                        *origin = msg.origin_stamp.or(Some(msg.stamp));
                        filter.update(msg.stamp, msg.data);
                    }
                    output.publish(filter.estimate(), now, *origin);
                }
                Flow::Continue
            }
            Work::Policy {
                brain,
                input,
                output,
            } => {
                let Some(msg) = input.read(now) else {
                    return Flow::Continue; // nothing sensed yet
                };
                let action = brain.lock().act(&msg.data);
                let force = ForceMsg {
                    newtons: f64::from(action[0]) * GEAR_N,
                };
                output.publish(force, now, msg.origin_stamp.or(Some(msg.stamp)));
                Flow::Continue
            }
            Work::Safety {
                input,
                output,
                max_force_n,
            } => {
                if let Some(msg) = input.read(now) {
                    let newtons = msg.data.newtons.clamp(-*max_force_n, *max_force_n);
                    output.publish(ForceMsg { newtons }, now, msg.origin_stamp);
                }
                Flow::Continue
            }
            Work::Actuator(a) => a.tick(now),
            Work::Registered(r) => {
                r.tick(now);
                Flow::Continue
            }
            Work::Python(p) => match p.tick(now, self.core.rate.period()) {
                Ok(()) => Flow::Continue,
                // The scheduler catches it and fails the node with this line.
                Err(e) => panic!("{}", e.0),
            },
        }
    }
}

impl Actuator {
    fn tick(&mut self, now: Nanos) -> Flow {
        let mut nonfinite = false;
        if let Some(msg) = self.input.read(now) {
            if msg.data.newtons.is_finite() {
                // Exact: a brain's f32 command × 10 is exact in f64, and so is ÷ 10.
                let command = (msg.data.newtons / GEAR_N) as f32;
                self.held = Some((command, msg.origin_stamp));
            } else {
                nonfinite = true; // hold the last good force instead
            }
        }
        let (mut u, mut origin) = self.held.unwrap_or((0.0, None));
        // The deadline reaction (QoS): no message within the deadline.
        let qos = self.input.qos();
        if let Some(deadline) = qos.deadline {
            if now.saturating_sub(self.input.last_arrival()) > deadline {
                match qos.on_deadline_missed {
                    OnDeadlineMissed::Hold => {}
                    OnDeadlineMissed::Zero => (u, origin) = (0.0, None),
                    OnDeadlineMissed::Stop => {
                        lock(&self.log).watchdog(now, self.input.name(), deadline);
                        return Flow::Stop;
                    }
                }
            }
        }
        let (outcome, step) = {
            let mut plant = lock(&self.plant);
            let outcome = plant.step(u);
            (outcome, plant.steps())
        };
        let published = self.policy_output.as_ref().and_then(|t| {
            let m = t.peek_newest()?;
            (self.reported != Some(m.seq)).then(|| {
                self.reported = Some(m.seq);
                (m.stamp, m.data.newtons)
            })
        });
        let rec = StepRecord {
            published,
            step,
            t: now,
            pole_angle: outcome.state.theta,
            cart_pos: outcome.state.cart_pos,
            action: outcome.applied,
            latency: origin.map(|o| now.saturating_sub(o)),
            nonfinite,
            topics: self.topics.iter().map(|t| t.stats_at(now)).collect(),
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
