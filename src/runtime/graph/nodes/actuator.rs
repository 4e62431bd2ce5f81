//! The **actuator**: applies the newest force (zero before the first), steps the plant once
//! and records the step. Re-applying a stale force is the zero-order hold; a non-finite
//! force is refused and the last good one held; a missed deadline gets the input topic's
//! reaction (hold, zero, stop). It alone steps the plant; a fall stops the graph.

use crate::estimate::EstimatePoint;
use crate::graph::kind::{typed, BuildContext, Code, KindDef, Params, Plant, Ports, Work};
use crate::msg::{AnyTopic, ForceMsg, Message, StateMsg};
use crate::node::Flow;
use crate::plant::{lock, SharedPlant, GEAR_N};
use crate::qos::OnDeadlineMissed;
use crate::runlog::{RunLog, StepRecord, StepSink};
use crate::time::Nanos;
use crate::topic::Subscription;
use std::sync::{Arc, Mutex};

/// The kind: `force` in, nothing out; steps the plant (exactly one per graph).
pub fn def() -> KindDef {
    KindDef {
        name: "actuator",
        doc: "applies the newest force (zero-order hold) and steps the plant",
        ports: Ports::Fixed {
            inputs: vec![&[ForceMsg::TYPE]],
            outputs: vec![],
        },
        plant: Plant::Steps,
        code: Code::BuiltIn,
        params: Params::Numbers(&[]),
        uses_brain: false,
        make: Box::new(|cx: &mut BuildContext<'_>| {
            Ok(Box::new(Actuator {
                plant: cx.plant.clone(),
                input: typed(cx.inputs.first())?,
                topics: cx.topics.to_vec(),
                log: cx.log.clone(),
                observers: cx.observers.take().unwrap_or_default(),
                held: None,
                policy_output: cx
                    .action
                    .and_then(|t| t.subscription(0).typed::<ForceMsg>().cloned()),
                reported: None,
                estimate: cx
                    .estimate
                    .as_ref()
                    .and_then(|t| t.typed::<StateMsg>().cloned()),
            }) as Box<dyn Work>)
        }),
    }
}

/// The run's log, locked (tolerating poison: each holder leaves it consistent).
fn log(l: &Mutex<RunLog>) -> std::sync::MutexGuard<'_, RunLog> {
    l.lock().unwrap_or_else(|e| e.into_inner())
}

/// The actuator's state.
pub struct Actuator {
    /// The plant it steps.
    pub plant: SharedPlant,
    /// Its input.
    pub input: Arc<Subscription<ForceMsg>>,
    /// Every topic of the graph, for the per-step counters.
    pub topics: Vec<AnyTopic>,
    /// Where steps are accounted.
    pub log: Arc<Mutex<RunLog>>,
    /// Told about every step.
    pub observers: Vec<Box<dyn StepSink>>,
    /// The last finite command applied (in [-1, 1] units of the motor), with its origin.
    pub held: Option<(f32, Option<Nanos>)>,
    /// The policy's output topic, watched (never read) for what it published.
    pub policy_output: Option<Arc<Subscription<ForceMsg>>>,
    /// `seq` of the newest policy message already reported.
    pub reported: Option<u64>,
    /// The chain's state estimate, when the graph has an estimator: the policy's queue of
    /// it, watched (never read) beside the plant's state ([`crate::estimate`]).
    pub estimate: Option<Arc<Subscription<StateMsg>>>,
}

impl Work for Actuator {
    fn save(&self) -> Option<crate::node::NodeState> {
        // The force it holds (zero-order hold) and the newest policy message it reported.
        Some(Box::new((self.held, self.reported)))
    }
    fn load(&mut self, state: &crate::node::NodeState) -> bool {
        type Kept = (Option<(f32, Option<Nanos>)>, Option<u64>);
        let Some(&(held, reported)) = state.downcast_ref::<Kept>() else {
            return false;
        };
        (self.held, self.reported) = (held, reported);
        true
    }
    /// One tick at `now`: apply, step, record.
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
                        log(&self.log).watchdog(now, self.input.name(), deadline);
                        return Flow::Stop;
                    }
                }
            }
        }
        let (outcome, step, estimate) = {
            let mut plant = lock(&self.plant);
            // The newest estimate by now beside the state the sensors read now.
            let estimate = self.estimate.as_ref().map(|t| {
                let m = t.peek_newest();
                let point =
                    EstimatePoint::new(plant.state().as_array(), m.as_ref().map(|m| &m.data));
                Box::new(point)
            });
            let outcome = plant.step(u);
            (outcome, plant.steps(), estimate)
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
            estimate,
        };
        log(&self.log).push(rec.clone());
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
