//! The actuator's per-tick record and the run's log: one [`StepRecord`] per actuator tick
//! (the row of `trace.csv`), every topic's counters at that tick ([`TopicCounters`]), and
//! the [`RunLog`] that accumulates them into what [`crate::metrics`] summarizes.
//!
//! Below the graph and the executor, which write it, and beside the metrics, which read it:
//! it imports only leaves ([`crate::ids`], [`crate::time`], [`crate::topic`]'s counters) and
//! the latency statistics of [`crate::metrics`].

use crate::ids::{TopicId, MAX_TOPICS};
use crate::metrics::ExactLatency;
use crate::time::Nanos;
use crate::topic::TopicStats;
use serde::{Deserialize, Serialize};
use smallvec::SmallVec;
use std::sync::Arc;

/// Told of every actuator step, on the actuator's thread (a recorder, the lab's telemetry):
/// it must not block. It is told before the run log takes the step ([`RunLog::push`]), so
/// the record it is given is the step's whole account. `ratelab::graph::StepObserver` is
/// one that also sees the graph built.
pub trait StepSink: Send {
    /// One actuator tick happened.
    fn on_step(&mut self, rec: &StepRecord);
}

/// Topics whose counters a [`TopicCounters`] holds without allocating: the chapter's
/// graphs and every shipped one have fewer.
pub const INLINE_TOPICS: usize = 7;

/// Topics per shared block of a large graph's [`TopicCounters`]: a clone shares every block,
/// and changing one topic's counters copies only its block (64 × `TopicStats`, 8.5 KiB).
pub const COUNTER_BLOCK: usize = 64;

/// Every topic's counters at one instant, by [`TopicId`], at most [`MAX_TOPICS`] entries.
///
/// Up to [`INLINE_TOPICS`] they are inline (no allocation per actuator step for the graphs
/// of the chapter). Past them they are kept in blocks of [`COUNTER_BLOCK`] shared between
/// clones (copy on write), so that a step record of a graph of thousands of topics, of which
/// a few changed since the last step, costs a block or two and not a copy of them all: an
/// idle topic costs next to nothing (issue 51; `BENCHMARKS.md`, "Graphs of any size").
#[derive(Clone, Debug, Default)]
pub struct TopicCounters {
    repr: Repr,
}

#[derive(Clone, Debug)]
// Inline on purpose: the chapter's graphs must not allocate per actuator step.
#[allow(clippy::large_enum_variant)]
enum Repr {
    Inline(SmallVec<[TopicStats; INLINE_TOPICS]>),
    /// `len` topics in blocks of [`COUNTER_BLOCK`] (the last may be shorter).
    Blocks {
        len: usize,
        blocks: Vec<Arc<Vec<TopicStats>>>,
    },
}

impl Default for Repr {
    fn default() -> Self {
        Repr::Inline(SmallVec::new())
    }
}

impl FromIterator<TopicStats> for TopicCounters {
    /// From each topic's stats, in [`TopicId`] order (entries past [`MAX_TOPICS`] are ignored;
    /// a validated graph has no more).
    fn from_iter<I: IntoIterator<Item = TopicStats>>(stats: I) -> Self {
        let mut it = stats.into_iter().take(MAX_TOPICS);
        let head: SmallVec<[TopicStats; INLINE_TOPICS]> = it.by_ref().take(INLINE_TOPICS).collect();
        let Some(next) = it.next() else {
            return TopicCounters {
                repr: Repr::Inline(head),
            };
        };
        let all: Vec<TopicStats> = head
            .into_iter()
            .chain(std::iter::once(next))
            .chain(it)
            .collect();
        let blocks: Vec<Arc<Vec<TopicStats>>> = all
            .chunks(COUNTER_BLOCK)
            .map(|c| Arc::new(c.to_vec()))
            .collect();
        TopicCounters {
            repr: Repr::Blocks {
                len: all.len(),
                blocks,
            },
        }
    }
}

impl PartialEq for TopicCounters {
    fn eq(&self, other: &Self) -> bool {
        self.len() == other.len() && self.iter().eq(other.iter())
    }
}

impl Eq for TopicCounters {}

impl TopicCounters {
    /// Topic `id`'s counters (zeros for an id past the end).
    pub fn get(&self, id: TopicId) -> TopicStats {
        match &self.repr {
            Repr::Inline(v) => v.get(id.0).copied(),
            Repr::Blocks { blocks, .. } => blocks
                .get(id.0 / COUNTER_BLOCK)
                .and_then(|b| b.get(id.0 % COUNTER_BLOCK))
                .copied(),
        }
        .unwrap_or_default()
    }

    /// How many topics it holds.
    pub fn len(&self) -> usize {
        match &self.repr {
            Repr::Inline(v) => v.len(),
            Repr::Blocks { len, .. } => *len,
        }
    }

    /// True for a graph of no topics.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// Every topic's counters, by [`TopicId`].
    pub fn iter(&self) -> impl Iterator<Item = &TopicStats> + '_ {
        let (inline, blocks): (&[TopicStats], &[Arc<Vec<TopicStats>>]) = match &self.repr {
            Repr::Inline(v) => (v, &[]),
            Repr::Blocks { blocks, .. } => (&[], blocks),
        };
        inline.iter().chain(blocks.iter().flat_map(|b| b.iter()))
    }

    /// Bytes of counters on the heap, counted as if no block were shared with another
    /// clone (0 up to [`INLINE_TOPICS`]): an upper bound, what a front end that keeps step
    /// records counts against its budget (`ratelab::telemetry`).
    pub fn heap_bytes(&self) -> usize {
        match &self.repr {
            Repr::Inline(_) => 0,
            Repr::Blocks { len, blocks } => {
                // Each block: its pointer here, and its Arc's counts and Vec's header there.
                let block = std::mem::size_of::<Arc<Vec<TopicStats>>>()
                    + 2 * std::mem::size_of::<usize>()
                    + std::mem::size_of::<Vec<TopicStats>>();
                blocks.len() * block + len * std::mem::size_of::<TopicStats>()
            }
        }
    }

    /// Replace topic `id`'s counters (an id past the end is ignored). In a large graph this
    /// copies the topic's block first when a clone still shares it.
    pub fn set(&mut self, id: TopicId, stats: TopicStats) {
        let slot = match &mut self.repr {
            Repr::Inline(v) => v.get_mut(id.0),
            Repr::Blocks { blocks, .. } => blocks
                .get_mut(id.0 / COUNTER_BLOCK)
                .and_then(|b| Arc::make_mut(b).get_mut(id.0 % COUNTER_BLOCK)),
        };
        if let Some(s) = slot {
            *s = stats;
        }
    }
}

impl Serialize for TopicCounters {
    /// A list of every topic's counters, by [`TopicId`] (the same bytes whatever the layout).
    fn serialize<S: serde::Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        use serde::ser::SerializeSeq;
        let mut seq = s.serialize_seq(Some(self.len()))?;
        for stats in self.iter() {
            seq.serialize_element(stats)?;
        }
        seq.end()
    }
}

impl<'de> Deserialize<'de> for TopicCounters {
    /// A list of at most [`MAX_TOPICS`] counters (more is an error: the bytes may come from
    /// the network, `ratelab::distributed`).
    fn deserialize<D: serde::Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        struct Bounded;
        impl<'de> serde::de::Visitor<'de> for Bounded {
            type Value = TopicCounters;
            fn expecting(&self, f: &mut std::fmt::Formatter) -> std::fmt::Result {
                write!(f, "a list of at most {MAX_TOPICS} topic counters")
            }
            fn visit_seq<A: serde::de::SeqAccess<'de>>(
                self,
                mut seq: A,
            ) -> Result<TopicCounters, A::Error> {
                let mut all: Vec<TopicStats> = Vec::new();
                while let Some(s) = seq.next_element::<TopicStats>()? {
                    if all.len() == MAX_TOPICS {
                        return Err(serde::de::Error::invalid_length(MAX_TOPICS + 1, &self));
                    }
                    all.push(s);
                }
                Ok(all.into_iter().collect())
            }
        }
        d.deserialize_seq(Bounded)
    }
}

/// One actuator tick.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct StepRecord {
    /// Actuator step number, from 1 (each steps the plant 20 ms).
    pub step: u64,
    /// Run time of the tick.
    pub t: Nanos,
    /// Pole angle after the step, rad.
    pub pole_angle: f64,
    /// Pole angular velocity after the step, rad/s (the plant's state beside
    /// [`StepRecord::pole_angle`]; not a column of `trace.csv`).
    #[serde(default)]
    pub pole_angvel: f64,
    /// Cart position after the step, m.
    pub cart_pos: f64,
    /// The control applied (clipped to [-1, 1]).
    pub action: f64,
    /// Sense→act latency of the applied action; `None` before the first action arrives.
    pub latency: Option<Nanos>,
    /// When the command the actuator applied at this tick was published (its message's
    /// stamp): the zero-order hold re-applies it until a newer one arrives, so `t −
    /// held_stamp` is the age of the command it holds. `None` when it applied none (before
    /// the first arrived, or zero after a missed deadline). Not a column of `trace.csv`.
    #[serde(default)]
    pub held_stamp: Option<Nanos>,
    /// True when the brain's newest action was non-finite and the last good one was held.
    pub nonfinite: bool,
    /// Every topic's counters at this tick, by [`TopicId`].
    pub topics: TopicCounters,
    /// The force the policy published since the previous actuator tick, if it did: (publish
    /// stamp, N), the newest one. Beside [`StepRecord::action`] (what was applied) it shows
    /// the zero-order hold.
    pub published: Option<(Nanos, f64)>,
    /// True on the tick the pole fell.
    pub fell: bool,
    /// With an estimator in the graph: the plant's state at this tick, before the step,
    /// beside the newest estimate, if any ([`crate::estimate`]; boxed: most graphs have
    /// none, and every record is kept).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub estimate: Option<Box<crate::estimate::EstimatePoint>>,
}

/// Everything the actuator measured during a run.
#[derive(Clone, Debug, Default)]
pub struct RunLog {
    /// One record per actuator tick, in order (empty when the trace is not kept).
    pub trace: Vec<StepRecord>,
    /// Whether to keep every [`StepRecord`] (headless runs do; long lab runs may not).
    pub keep_trace: bool,
    /// Keep only every this many steps' records (steps 1, 1 + n, 1 + 2n, …; 0 and 1: every
    /// one): what `--trace-every` asks of a long run's trace. The metrics count every step.
    pub trace_every: u64,
    /// The newest record.
    pub last: Option<StepRecord>,
    /// Actuator ticks so far.
    pub steps: u64,
    /// Sense→act latency over every tick that applied a sensed action (exact percentiles).
    pub latency: ExactLatency,
    /// Ticks whose newest action was non-finite (the last good action was held).
    pub nonfinite_actions: u64,
    /// Run time of the fall, if the pole fell.
    pub fell_at: Option<Nanos>,
    /// When the actuator's deadline watchdog stopped the run (`on_deadline_missed =
    /// "stop"`), with the topic and its deadline: a verdict distinct from a fall.
    pub watchdog: Option<Watchdog>,
    /// The estimator's error against the truth, folded tick by tick (empty without an
    /// estimator in the graph).
    pub estimate: crate::estimate::EstimateError,
}

/// The actuator's watchdog fired: no message on `topic` for longer than `deadline`.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Watchdog {
    /// Run time it fired.
    pub at: Nanos,
    /// The actuator's input topic.
    pub topic: String,
    /// Its deadline.
    pub deadline: Nanos,
}

impl std::fmt::Display for Watchdog {
    /// `stopped by watchdog at 1.24 s: no message on /cmd for more than 40 ms`.
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "stopped by watchdog at {:.2} s: no message on {} for more than {}",
            self.at.as_secs_f64(),
            self.topic,
            self.deadline
        )
    }
}

impl RunLog {
    /// An empty log; `keep_trace` keeps every step record.
    pub fn new(keep_trace: bool) -> Self {
        Self {
            keep_trace,
            ..Self::default()
        }
    }

    /// The actuator's watchdog stopped the run at `at` (the first firing counts).
    pub fn watchdog(&mut self, at: Nanos, topic: &str, deadline: Nanos) {
        if self.watchdog.is_none() {
            self.watchdog = Some(Watchdog {
                at,
                topic: topic.to_string(),
                deadline,
            });
        }
    }

    /// Account one actuator tick.
    pub fn push(&mut self, rec: StepRecord) {
        self.steps = rec.step;
        if let Some(lat) = rec.latency {
            self.latency.record(lat);
        }
        if rec.nonfinite {
            self.nonfinite_actions += 1;
        }
        if let Some(p) = &rec.estimate {
            self.estimate.push(rec.t, p);
        }
        if rec.fell && self.fell_at.is_none() {
            self.fell_at = Some(rec.t);
        }
        if self.keep_trace && (rec.step.saturating_sub(1)) % self.trace_every.max(1) == 0 {
            self.trace.push(rec.clone());
        }
        self.last = Some(rec);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn stats(published: u64) -> TopicStats {
        TopicStats {
            published,
            depth: 1,
            ..TopicStats::default()
        }
    }

    #[test]
    fn counters_of_a_large_graph_share_their_blocks_and_copy_only_the_one_that_changes() {
        let n = 3 * COUNTER_BLOCK + 5;
        let mut a: TopicCounters = (0..n as u64).map(stats).collect();
        let b = a.clone();
        a.set(TopicId(COUNTER_BLOCK + 1), stats(999));
        let (Repr::Blocks { blocks: ab, .. }, Repr::Blocks { blocks: bb, .. }) = (&a.repr, &b.repr)
        else {
            panic!("past INLINE_TOPICS the counters are in blocks");
        };
        let shared: Vec<bool> = ab.iter().zip(bb).map(|(x, y)| Arc::ptr_eq(x, y)).collect();
        assert_eq!(shared, [true, false, true, true]);
        assert_eq!(a.get(TopicId(COUNTER_BLOCK + 1)), stats(999));
        assert_eq!(
            b.get(TopicId(COUNTER_BLOCK + 1)),
            stats(COUNTER_BLOCK as u64 + 1)
        );
        assert_eq!(a.len(), n);
        assert_eq!(a.iter().count(), n);
        assert_eq!(a.get(TopicId(n)), TopicStats::default(), "past the end");
        assert_ne!(a, b);
        a.set(TopicId(COUNTER_BLOCK + 1), stats(COUNTER_BLOCK as u64 + 1));
        assert_eq!(a, b);
        assert!(a.heap_bytes() >= n * std::mem::size_of::<TopicStats>());
    }

    #[test]
    fn counters_read_and_write_as_the_list_they_always_were() {
        for n in [0, 3, INLINE_TOPICS, INLINE_TOPICS + 1, 200] {
            let list: Vec<TopicStats> = (0..n as u64).map(stats).collect();
            let counters: TopicCounters = list.iter().copied().collect();
            assert_eq!(counters.iter().copied().collect::<Vec<_>>(), list);
            assert_eq!(
                postcard::to_allocvec(&counters).unwrap(),
                postcard::to_allocvec(&list).unwrap()
            );
            let json = serde_json::to_string(&counters).unwrap();
            assert_eq!(json, serde_json::to_string(&list).unwrap());
            let back: TopicCounters = serde_json::from_str(&json).unwrap();
            assert_eq!(back, counters);
        }
        let too_many: Vec<TopicStats> = vec![TopicStats::default(); MAX_TOPICS + 1];
        let bytes = postcard::to_allocvec(&too_many).unwrap();
        assert!(postcard::from_bytes::<TopicCounters>(&bytes).is_err());
    }

    #[test]
    fn run_log_accounts_falls_once() {
        let mut log = RunLog::new(true);
        let base = StepRecord {
            step: 1,
            t: Nanos(0),
            pole_angle: 0.0,
            pole_angvel: 0.0,
            cart_pos: 0.0,
            action: 0.0,
            latency: None,
            held_stamp: None,
            nonfinite: false,
            topics: TopicCounters::default(),
            published: None,
            fell: false,
            estimate: None,
        };
        log.push(base.clone());
        log.push(StepRecord {
            step: 2,
            t: Nanos(20),
            fell: true,
            nonfinite: true,
            latency: Some(Nanos(5)),
            ..base.clone()
        });
        assert_eq!(log.steps, 2);
        assert_eq!(log.fell_at, Some(Nanos(20)));
        assert_eq!(log.nonfinite_actions, 1);
        assert_eq!(log.latency.count(), 1);
        assert_eq!(log.trace.len(), 2);
        // Every third step's record, from the first.
        let mut thin = RunLog::new(true);
        thin.trace_every = 3;
        for step in 1..=7 {
            thin.push(StepRecord {
                step,
                ..base.clone()
            });
        }
        let kept: Vec<u64> = thin.trace.iter().map(|r| r.step).collect();
        assert_eq!(kept, [1, 4, 7]);
        assert_eq!(thin.steps, 7);
    }
}
