//! The **actuator**: applies the newest force (zero before the first), steps the plant once
//! and records the step. Re-applying a stale force is the zero-order hold; a non-finite
//! force is refused and the last good one held; a missed deadline gets the input topic's
//! reaction (hold, zero, stop). It alone steps the plant; a fall stops the graph.

use crate::graph::kind::{typed, Code, KindDef, Params, Plant};
use crate::plant::{lock, SharedPlant, GEAR_N};
use ratelab_core::estimate::EstimatePoint;
use ratelab_core::ids::TopicId;
use ratelab_core::msg::{AnyTopic, ForceMsg, StateMsg};
use ratelab_core::node::{Flow, NodeState};
use ratelab_core::ports::{Held, RustNode, Stamped};
use ratelab_core::qos::OnDeadlineMissed;
use ratelab_core::runlog::{RunLog, StepRecord, StepSink, TopicCounters, INLINE_TOPICS};
use ratelab_core::time::Nanos;
use ratelab_core::topic::{ChangeBoard, Subscription, TopicStats};
use std::sync::{Arc, Mutex};

/// The kind: `force` in, nothing out; steps the plant (exactly one per graph).
pub fn def() -> KindDef {
    KindDef {
        doc: "applies the newest force (zero-order hold) and steps the plant",
        plant: Plant::Steps,
        code: Code::BuiltIn,
        params: Params::Numbers(&[]),
        ..KindDef::of("actuator", |cx| {
            let run = &mut cx.run;
            Ok(Actuator {
                plant: run.plant.clone(),
                input: typed(cx.node.inputs.first())?,
                topics: TopicWatch::new(run.topics.to_vec()),
                log: run.log.clone(),
                observers: run.observers.take().unwrap_or_default(),
                held: None,
                held_stamp: None,
                policy_output: run
                    .action
                    .and_then(|t| t.subscription(0).typed::<ForceMsg>().cloned()),
                reported: None,
                estimate: run
                    .estimate
                    .as_ref()
                    .and_then(|t| t.typed::<StateMsg>().cloned()),
                flow: Flow::Continue,
            })
        })
    }
}

/// The run's log, locked (tolerating poison: each holder leaves it consistent).
fn log(l: &Mutex<RunLog>) -> std::sync::MutexGuard<'_, RunLog> {
    l.lock().unwrap_or_else(|e| e.into_inner())
}

/// Every topic of the graph, watched for the counters of each step record. A topic is read
/// again only when it changed since the last step (its queues count their changes on one
/// [`ChangeBoard`]) or when its counters move with time alone (a deadline, whose missed
/// periods count up without a message). A topic that did nothing costs one counter in a
/// contiguous pass, and the record shares the unchanged counters with the one before
/// ([`TopicCounters`]). Issue 51: an idle node costs next to nothing.
pub struct TopicWatch {
    topics: Vec<AnyTopic>,
    board: ChangeBoard,
    /// Per topic, when last read: its count and whether to read it again whatever the count
    /// (its counters move with time, or it is unwatched); `None` before its first read.
    read: Vec<Option<(u64, bool)>>,
    /// Topics whose changes are not counted on the board, read every step: all of a graph of
    /// at most [`INLINE_TOPICS`], and those whose queues another watch holds. A queue is
    /// watched once, so an actuator rebuilt over the same topics reads them all every step:
    /// the same counters, without the saving.
    unwatched: Vec<bool>,
    counters: TopicCounters,
}

impl TopicWatch {
    /// Watch `topics`, in [`ratelab_core::ids::TopicId`] order. A graph of at most
    /// [`INLINE_TOPICS`] topics (the chapter's) is read whole every step, as counting its
    /// changes would cost more than it saves.
    pub fn new(topics: Vec<AnyTopic>) -> Self {
        let board = ChangeBoard::new(topics.len());
        let watch = topics.len() > INLINE_TOPICS;
        let unwatched = (0..topics.len())
            .map(|i| {
                !(watch
                    && board
                        .slot(i)
                        .is_some_and(|slot| topics[i].watch_changes(&slot)))
            })
            .collect();
        Self {
            read: vec![None; topics.len()],
            counters: topics.iter().map(|_| TopicStats::default()).collect(),
            topics,
            board,
            unwatched,
        }
    }

    /// Every topic's counters at run time `now`: each one what [`AnyTopic::stats_at`] gives.
    pub fn at(&mut self, now: Nanos) -> TopicCounters {
        // The count first: a change after it is seen next time, one before it now.
        for (i, (read, count)) in self.read.iter_mut().zip(self.board.counts()).enumerate() {
            if matches!(*read, Some((c, false)) if c == count) {
                continue;
            }
            let (stats, timed) = self.topics[i].stats_and_timing_at(now);
            *read = Some((count, timed || self.unwatched[i]));
            if self.counters.get(TopicId(i)) != stats {
                self.counters.set(TopicId(i), stats);
            }
        }
        self.counters.clone()
    }
}

/// The actuator's state.
pub struct Actuator {
    /// The plant it steps.
    pub plant: SharedPlant,
    /// Its input topic, for its QoS (the deadline reaction); its messages come through
    /// its tick.
    pub input: Arc<Subscription<ForceMsg>>,
    /// Every topic of the graph, for the per-step counters.
    pub topics: TopicWatch,
    /// Where steps are accounted.
    pub log: Arc<Mutex<RunLog>>,
    /// Told about every step.
    pub observers: Vec<Box<dyn StepSink>>,
    /// The last finite command applied (in [-1, 1] units of the motor), with its origin.
    pub held: Option<(f32, Option<Nanos>)>,
    /// When the held command was published (its message's stamp), for its age in each
    /// step record ([`StepRecord::held_stamp`]).
    pub held_stamp: Option<Nanos>,
    /// The policy's output topic, watched (never read) for what it published.
    pub policy_output: Option<Arc<Subscription<ForceMsg>>>,
    /// `seq` of the newest policy message already reported.
    pub reported: Option<u64>,
    /// The chain's state estimate, when the graph has an estimator: the policy's queue of
    /// it, watched (never read) beside the plant's state ([`ratelab_core::estimate`]).
    pub estimate: Option<Arc<Subscription<StateMsg>>>,
    /// What the last tick said: stop when the pole fell or the deadline's reaction stopped.
    pub flow: Flow,
}

impl RustNode for Actuator {
    type Input = Held<ForceMsg>;
    type Output = ();

    fn flow(&self) -> Flow {
        self.flow
    }
    fn save(&self) -> Option<NodeState> {
        // The force it holds (zero-order hold), when it was published, and the newest
        // policy message it reported.
        Some(Box::new((self.held, self.reported, self.held_stamp)))
    }
    fn load(&mut self, state: &NodeState) -> bool {
        type Kept = (Option<(f32, Option<Nanos>)>, Option<u64>, Option<Nanos>);
        let Some(&(held, reported, held_stamp)) = state.downcast_ref::<Kept>() else {
            return false;
        };
        (self.held, self.reported, self.held_stamp) = (held, reported, held_stamp);
        true
    }
    /// One tick at `now`: apply, step, record.
    fn tick(&mut self, now: Nanos, force: Option<&Stamped<ForceMsg>>) {
        self.flow = self.step(now, force);
    }
}

impl Actuator {
    /// Apply the force, step the plant, record the step: [`Flow::Stop`] when the pole fell
    /// or the deadline's reaction is to stop.
    fn step(&mut self, now: Nanos, force: Option<&Stamped<ForceMsg>>) -> Flow {
        let mut nonfinite = false;
        if let Some(msg) = force {
            if msg.data.newtons.is_finite() {
                // Exact: a brain's f32 command × 10 is exact in f64, and so is ÷ 10.
                let command = (msg.data.newtons / GEAR_N) as f32;
                self.held = Some((command, msg.origin_stamp));
                self.held_stamp = Some(msg.stamp);
            } else {
                nonfinite = true; // hold the last good force instead
            }
        }
        let (mut u, mut origin) = self.held.unwrap_or((0.0, None));
        let mut held_stamp = self.held_stamp;
        // The deadline reaction (QoS): no message within the deadline.
        let qos = self.input.qos();
        if let Some(deadline) = qos.deadline {
            if now.saturating_sub(self.input.last_arrival()) > deadline {
                match qos.on_deadline_missed {
                    OnDeadlineMissed::Hold => {}
                    OnDeadlineMissed::Zero => (u, origin, held_stamp) = (0.0, None, None),
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
            pole_angvel: outcome.state.pole_angvel,
            cart_pos: outcome.state.cart_pos,
            action: outcome.applied,
            latency: origin.map(|o| now.saturating_sub(o)),
            held_stamp,
            nonfinite,
            topics: self.topics.at(now),
            fell: outcome.terminated,
            estimate,
        };
        // The observers first, then the log takes the record itself: no copy of it (its
        // counters) each step ([`ratelab_core::runlog::StepSink`]).
        for obs in &mut self.observers {
            obs.on_step(&rec);
        }
        log(&self.log).push(rec);
        if outcome.terminated {
            Flow::Stop
        } else {
            Flow::Continue
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use ratelab_core::msg::{Message, MsgData};
    use ratelab_core::qos::{History, Link, TopicQos};

    /// Topics of every QoS that changes how counters move: the chapter's, a deadline (its
    /// counters move with time alone), a lifespan over a lossy, delayed link, keep-all, and
    /// a topic of three subscriptions.
    fn topics() -> Vec<AnyTopic> {
        let ms = Nanos::from_millis;
        let deadline = TopicQos {
            deadline: Some(ms(30)),
            ..TopicQos::default()
        };
        let linked = TopicQos {
            lifespan: Some(ms(45)),
            link: Some(Link {
                loss: 0.3,
                delay: ms(15),
                jitter: ms(10),
                retransmit: ms(5),
            }),
            ..TopicQos::default()
        };
        let keep_all = TopicQos {
            history: History::KeepAll,
            ..TopicQos::default()
        };
        let t = ForceMsg::TYPE;
        vec![
            AnyTopic::new("/plain", t, 1).unwrap(),
            AnyTopic::with_qos("/deadline", t, 2, deadline, 1).unwrap(),
            AnyTopic::with_qos("/linked", t, 3, linked, 2).unwrap(),
            AnyTopic::with_qos("/all", t, 4, keep_all, 3).unwrap(),
            AnyTopic::with_subscriptions("/fan", t, 2, TopicQos::default(), 4, 3).unwrap(),
        ]
        .into_iter()
        .chain((0..INLINE_TOPICS).map(|i| AnyTopic::new(&format!("/more_{i}"), t, 1).unwrap()))
        .collect()
    }

    #[test]
    fn the_watch_gives_every_topic_s_counters_at_every_step_however_they_changed() {
        let topics = topics();
        let mut watch = TopicWatch::new(topics.clone());
        // A fixed sequence of operations, the same on every machine.
        let mut rng = rand_pcg::Pcg64::new(0x2545_f491_4f6c_dd1d, 0);
        let mut next = move |n: u64| rand_pcg::rand_core::Rng::next_u64(&mut rng) % n;
        let (mut blocks_changed, mut toggles) = (0, 0);
        for step in 1..=2000u64 {
            let now = Nanos::from_millis(step * 5);
            // Most steps leave most topics alone; some publish, read, or change the QoS.
            if step % 151 == 0 {
                // The deadline on /plain switched on or off: whether its counters move with
                // time alone changes with it.
                let mut q = topics[0].qos();
                q.deadline = q.deadline.xor(Some(Nanos::from_millis(20)));
                topics[0].set_qos(q);
                toggles += 1;
            }
            for t in &topics {
                match next(12) {
                    0 | 1 => {
                        let data = MsgData::new(ForceMsg {
                            newtons: step as f64,
                        });
                        t.publish(None, &data, now, Some(now)).unwrap();
                    }
                    2 => {
                        let _ = t.subscription(next(3) as usize).read(now);
                    }
                    3 if step % 97 == 0 => t.set_depth(1 + next(4) as usize).unwrap(),
                    _ => {}
                }
            }
            let before = watch.counters.clone();
            let got = watch.at(now);
            let want: TopicCounters = topics.iter().map(|t| t.stats_at(now)).collect();
            assert_eq!(got, want, "step {step}");
            blocks_changed += usize::from(before != got);
        }
        assert!(
            blocks_changed > 100,
            "the topics did change: {blocks_changed}"
        );
        assert_eq!(toggles, 13, "the deadline switched on and off");
    }

    #[test]
    fn a_topic_watched_by_another_is_read_every_step() {
        let topics = topics();
        let first = TopicWatch::new(topics.clone());
        let mut second = TopicWatch::new(topics.clone());
        assert!(first.unwatched.iter().all(|&u| !u));
        // Topics no watch holds, but too few to count.
        let few = TopicWatch::new(self::topics()[..INLINE_TOPICS].to_vec());
        assert!(
            few.unwatched.iter().all(|&u| u),
            "a small graph is read whole"
        );
        assert!(
            second.unwatched.iter().all(|&u| u),
            "the first watch holds every queue"
        );
        let data = MsgData::new(ForceMsg { newtons: 1.0 });
        for step in 1..=3u64 {
            let now = Nanos::from_millis(step * 20);
            topics[0].publish(None, &data, now, None).unwrap();
            let want: TopicCounters = topics.iter().map(|t| t.stats_at(now)).collect();
            assert_eq!(second.at(now), want);
        }
        drop(first);
    }
}
