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

/// Told of every actuator step, on the actuator's thread (a recorder, the lab's telemetry):
/// it must not block. `ratelab::graph::StepObserver` is one that also sees the graph built.
pub trait StepSink: Send {
    /// One actuator tick happened.
    fn on_step(&mut self, rec: &StepRecord);
}

/// Topics whose counters a [`TopicCounters`] holds without allocating: the chapter's
/// graphs and every shipped one have fewer.
pub const INLINE_TOPICS: usize = 7;

/// Every topic's counters at one instant, by [`TopicId`], at most [`MAX_TOPICS`] entries:
/// inline up to [`INLINE_TOPICS`] (no allocation per actuator step for the graphs of the
/// chapter), on the heap past them.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct TopicCounters {
    stats: SmallVec<[TopicStats; INLINE_TOPICS]>,
}

impl FromIterator<TopicStats> for TopicCounters {
    /// From each topic's stats, in [`TopicId`] order (entries past [`MAX_TOPICS`] are ignored;
    /// a validated graph has no more).
    fn from_iter<I: IntoIterator<Item = TopicStats>>(stats: I) -> Self {
        TopicCounters {
            stats: stats.into_iter().take(MAX_TOPICS).collect(),
        }
    }
}

impl TopicCounters {
    /// Topic `id`'s counters (zeros for an id past the end).
    pub fn get(&self, id: TopicId) -> TopicStats {
        self.as_slice().get(id.0).copied().unwrap_or_default()
    }
    /// All of them, by [`TopicId`].
    pub fn as_slice(&self) -> &[TopicStats] {
        &self.stats
    }
    /// Replace topic `id`'s counters (an id past the end is ignored).
    pub fn set(&mut self, id: TopicId, stats: TopicStats) {
        if let Some(s) = self.stats.get_mut(id.0) {
            *s = stats;
        }
    }
}

impl Serialize for TopicCounters {
    fn serialize<S: serde::Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        self.as_slice().serialize(s)
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
                let mut c = TopicCounters::default();
                while let Some(s) = seq.next_element::<TopicStats>()? {
                    if c.stats.len() == MAX_TOPICS {
                        return Err(serde::de::Error::invalid_length(MAX_TOPICS + 1, &self));
                    }
                    c.stats.push(s);
                }
                Ok(c)
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
    /// Cart position after the step, m.
    pub cart_pos: f64,
    /// The control applied (clipped to [-1, 1]).
    pub action: f64,
    /// Sense→act latency of the applied action; `None` before the first action arrives.
    pub latency: Option<Nanos>,
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

    #[test]
    fn run_log_accounts_falls_once() {
        let mut log = RunLog::new(true);
        let base = StepRecord {
            step: 1,
            t: Nanos(0),
            pole_angle: 0.0,
            cart_pos: 0.0,
            action: 0.0,
            latency: None,
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
