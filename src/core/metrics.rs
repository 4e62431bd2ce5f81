//! Metrics: what a run measured, per step and in total, and the chapter's summary.
//!
//! The actuator appends one `StepRecord` per tick to a `RunLog` ([`crate::runlog`]).
//! Sense→act latency of a tick is `now - origin_stamp` of the action it applied (ch2.8,
//! `ActuatorNode`); its statistics are exact ([`ExactLatency`]: every sample kept, an integer mean), with an HDR
//! histogram beside them for drawing.
//! [`Metrics`] is the run's summary and the schema of `metrics.json` (the chapter's keys,
//! plus percentiles, `fell_at_s`, `policy` and ratelab's extras).

use crate::plant::ACTUATOR_HZ;
use crate::time::Nanos;
use hdrhistogram::Histogram;
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;

/// How a node's failure begins when its callback hung (ran on without returning until
/// Ctrl-C interrupted it, `ratelab::python`): the headline then says `HUNG`, not `NODE
/// FAILED`.
pub const HUNG: &str = "hung: ";

/// Latency (or lateness) statistics over a run: an HDR histogram in nanoseconds (3
/// significant digits: percentiles are within 0.1% of the sample, rounded up) with an exact
/// integer sum for the mean. Constant memory, for counts without a bound (node lateness
/// under the real clock); sense→act latency uses [`ExactLatency`].
///
/// The histogram (1 ns to an hour at 3 digits: about 270 KB) is allocated at the first
/// sample, so statistics kept for every node or topic of a large graph cost nothing where
/// nothing is recorded (a launch's process holds one per topic it receives).
#[derive(Clone, Debug, Default)]
pub struct LatencyStats {
    hist: Option<Histogram<u64>>,
    sum_ns: u128,
}

/// 1 ns .. 1 hour at 3 significant digits.
fn new_histogram() -> Histogram<u64> {
    Histogram::new_with_bounds(1, 3_600_000_000_000, 3).expect("static bounds are valid")
}

impl LatencyStats {
    /// Record one sample (saturated at one hour).
    pub fn record(&mut self, value: Nanos) {
        self.hist
            .get_or_insert_with(new_histogram)
            .saturating_record(value.0);
        self.sum_ns += u128::from(value.0);
    }

    /// Number of samples.
    pub fn count(&self) -> u64 {
        self.hist.as_ref().map_or(0, Histogram::len)
    }

    /// Exact mean, or `None` with no samples.
    pub fn mean(&self) -> Option<f64> {
        (self.count() > 0).then(|| self.sum_ns as f64 / self.count() as f64)
    }

    /// The value at quantile `q` in [0, 1] (HDR precision), or `None` with no samples.
    pub fn quantile(&self, q: f64) -> Option<Nanos> {
        let h = self.hist.as_ref().filter(|h| !h.is_empty())?;
        Some(Nanos(h.value_at_quantile(q)))
    }

    /// The largest sample (HDR precision), or `None` with no samples.
    pub fn max(&self) -> Option<Nanos> {
        let h = self.hist.as_ref().filter(|h| !h.is_empty())?;
        Some(Nanos(h.max()))
    }

    /// The underlying histogram (for drawing buckets); an empty one before the first sample.
    pub fn histogram(&self) -> &Histogram<u64> {
        static EMPTY: std::sync::OnceLock<Histogram<u64>> = std::sync::OnceLock::new();
        self.hist
            .as_ref()
            .unwrap_or_else(|| EMPTY.get_or_init(new_histogram))
    }

    /// p50/p99/max in ms, rounded to µs; zeros with no samples.
    pub fn summary_ms(&self) -> (f64, f64, f64) {
        let ms = |n: Option<Nanos>| round_to(n.map_or(0.0, |n| n.as_millis_f64()), 3);
        (
            ms(self.quantile(0.5)),
            ms(self.quantile(0.99)),
            ms(self.max()),
        )
    }
}

/// The most sense→act samples [`ExactLatency`] keeps for exact order statistics: an hour's
/// (one per actuator tick, at the plant's fixed [`ACTUATOR_HZ`]: ticks at 0, 20 ms, …,
/// 3600 s), 180 001, 8 bytes each (about 1.4 MB). A longer run's percentiles come from the
/// streaming histogram (3 significant digits).
pub const MAX_EXACT_SAMPLES: usize = (EXACT_SECONDS * ACTUATOR_HZ) as usize + 1;

/// The run time over which sense→act percentiles are exact, seconds: an hour.
const EXACT_SECONDS: f64 = 3600.0;

/// More nodes (or topics) than this, and the summary's rates (topics) line gives the first
/// [`SUMMARY_SHOWN`] and sums up the rest (the rest's rates: the [`SUMMARY_SHOWN`] slowest
/// named, the others counted): a line of bounded length, whatever the graph's size.
pub const SUMMARY_ITEMS: usize = 12;
/// Nodes and topics the summary names one by one in a graph of more than [`SUMMARY_ITEMS`].
pub const SUMMARY_SHOWN: usize = 8;

/// Samples per block of [`ExactLatency`]'s sorted list (a block splits past twice this).
const BLOCK: usize = 512;

/// Sense→act latency with **exact** order statistics: every sample is kept, sorted, so the
/// percentiles are samples (nearest rank, as the HDR histogram ranks them) and a latency
/// the virtual clock makes exact (80 ms, 180 ms) prints exactly, where the histogram's 3
/// significant digits printed 80.019 and 180.1.
///
/// The samples live in a sorted list of blocks (each at most `2 × 512`), so one insert
/// costs a binary search and a move within one block, and a percentile a walk over the
/// blocks' lengths (at most about 350 at [`MAX_EXACT_SAMPLES`]): cheap enough to read every
/// frame in the lab. Storage is bounded: past [`MAX_EXACT_SAMPLES`] (a run longer than an
/// hour) further samples count in the histogram and the mean only, and the percentiles
/// come from the histogram (3 significant digits). The HDR histogram is kept beside the
/// samples for drawing buckets; the mean is exact (an integer sum).
///
/// A clone shares the blocks (copied on the next write to each): the run core captures a
/// run's log every second of run time for seeking (`ratelab::runcore`), and a copy per
/// capture would grow with the run.
#[derive(Clone, Debug, Default)]
pub struct ExactLatency {
    /// Sorted samples, ns: every block sorted, each block's values ≤ the next block's.
    blocks: Vec<std::sync::Arc<Vec<u64>>>,
    /// Samples in `blocks`.
    kept: usize,
    /// Every sample (histogram and exact sum).
    stats: LatencyStats,
}

impl ExactLatency {
    /// Record one sample.
    pub fn record(&mut self, value: Nanos) {
        self.stats.record(value);
        if self.kept >= MAX_EXACT_SAMPLES {
            return;
        }
        self.kept += 1;
        let v = value.0;
        // The first block whose last value is above `v` (ties go after equal values), or
        // the last block.
        let last = self.blocks.len().saturating_sub(1);
        let i = self
            .blocks
            .partition_point(|b| b.last().is_some_and(|&x| x <= v))
            .min(last);
        match self.blocks.get_mut(i) {
            None => self.blocks.push(std::sync::Arc::new(vec![v])),
            Some(b) => {
                let b = std::sync::Arc::make_mut(b);
                let j = b.partition_point(|&x| x <= v);
                b.insert(j, v);
                if b.len() > 2 * BLOCK {
                    let tail = b.split_off(BLOCK);
                    self.blocks.insert(i + 1, std::sync::Arc::new(tail));
                }
            }
        }
    }

    /// Number of samples.
    pub fn count(&self) -> u64 {
        self.stats.count()
    }

    /// Whether every sample is kept (the percentiles are exact): true unless more than
    /// [`MAX_EXACT_SAMPLES`] were recorded.
    pub fn is_exact(&self) -> bool {
        self.kept as u64 == self.count()
    }

    /// Exact mean, ns, or `None` with no samples.
    pub fn mean(&self) -> Option<f64> {
        self.stats.mean()
    }

    /// The sample of 0-based rank `k` in sorted order.
    fn kth(&self, mut k: usize) -> Option<u64> {
        for b in &self.blocks {
            if k < b.len() {
                return Some(b[k]);
            }
            k -= b.len();
        }
        None
    }

    /// The sample at quantile `q` in [0, 1] by nearest rank (`⌈q·n⌉`, at least the first),
    /// or `None` with no samples.
    pub fn quantile(&self, q: f64) -> Option<Nanos> {
        if !self.is_exact() {
            return self.stats.quantile(q);
        }
        let n = self.kept;
        let rank = ((q.clamp(0.0, 1.0) * n as f64).ceil() as usize).clamp(1, n.max(1));
        self.kth(rank - 1).map(Nanos)
    }

    /// The largest sample, or `None` with no samples.
    pub fn max(&self) -> Option<Nanos> {
        if !self.is_exact() {
            return self.stats.max();
        }
        self.blocks
            .last()
            .and_then(|b| b.last())
            .copied()
            .map(Nanos)
    }

    /// Samples strictly below `bound`: exact while every sample is kept, else the
    /// histogram's count up to `bound` (3 significant digits). For a histogram's bars: the
    /// bar `[a, b)` holds `count_below(b) − count_below(a)`.
    pub fn count_below(&self, bound: Nanos) -> u64 {
        if !self.is_exact() {
            let h = self.stats.histogram();
            return match bound.0.checked_sub(1) {
                None => 0,
                Some(top) => h.count_between(0, top),
            };
        }
        self.blocks
            .iter()
            .map(|b| b.partition_point(|&x| x < bound.0) as u64)
            .sum()
    }

    /// The HDR histogram of every sample (3 significant digits), for drawing buckets.
    pub fn histogram(&self) -> &Histogram<u64> {
        self.stats.histogram()
    }

    /// p50/p99/max in ms, rounded to µs; zeros with no samples.
    pub fn summary_ms(&self) -> (f64, f64, f64) {
        let ms = |n: Option<Nanos>| round_to(n.map_or(0.0, |n| n.as_millis_f64()), 3);
        (
            ms(self.quantile(0.5)),
            ms(self.quantile(0.99)),
            ms(self.max()),
        )
    }
}

impl FromIterator<Nanos> for ExactLatency {
    fn from_iter<I: IntoIterator<Item = Nanos>>(samples: I) -> Self {
        let mut s = Self::default();
        for v in samples {
            s.record(v);
        }
        s
    }
}

/// `n` and its noun, singular for one: `counted(1, "actuator step")` is "1 actuator step",
/// `counted(2, "actuator step")` "2 actuator steps".
pub fn counted(n: u64, noun: &str) -> String {
    if n == 1 {
        format!("1 {noun}")
    } else {
        format!("{n} {noun}s")
    }
}

/// Round `x` to `digits` decimals (report figures only).
pub fn round_to(x: f64, digits: i32) -> f64 {
    let p = 10f64.powi(digits);
    (x * p).round() / p
}

/// Tick-timing statistics of one node under the real clock.
#[derive(Clone, Debug, Default, Serialize, Deserialize, PartialEq)]
pub struct NodeTiming {
    /// Node name.
    pub node: String,
    /// Ticks run.
    pub ticks: u64,
    /// Deadlines skipped because a tick overran a whole period.
    pub skipped: u64,
    /// Lateness (actual − scheduled wake-up) percentiles, µs.
    pub lateness_p50_us: f64,
    /// 99th percentile lateness, µs.
    pub lateness_p99_us: f64,
    /// Largest lateness, µs.
    pub lateness_max_us: f64,
    /// Thread CPU time over the run, ms.
    pub cpu_ms: f64,
    /// Measured tick rate over the run, Hz.
    pub measured_hz: f64,
    /// The scheduling policy the node's thread ran under (`SCHED_OTHER`, `SCHED_FIFO 50`).
    #[serde(default)]
    pub sched: String,
    /// Why a requested real-time priority was not granted (the thread ran as `sched` says).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub sched_error: Option<String>,
}

/// [`Metrics::headline`] of a run whose plant stepped its whole duration with the pole up.
pub const BALANCED_WHOLE_RUN: &str = "BALANCED (pole up the whole run)";

/// A run's summary: the schema of `metrics.json`. Keys follow the chapter's report, then
/// ratelab's additions. Under the virtual clock every field is a pure function of the
/// settings (no wall-clock figure), so two runs serialize byte for byte the same.
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
pub struct Metrics {
    /// The pole stayed up for the whole run.
    pub balanced: bool,
    /// `virtual` or `real`.
    pub clock: String,
    /// Policy rate at the start of the run, Hz (this and every key of the chapter's chain
    /// below — `sensor_hz`, `queue_depth`, `policy_ticks`, `control_hz_end`, `obs_*`,
    /// `action_*` — only for a graph with the chain: [`Metrics::without_chain`]).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub control_hz: Option<f64>,
    /// Sensor rate at the start of the run, Hz.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub sensor_hz: Option<f64>,
    /// Actuator (plant) rate, Hz.
    pub actuator_hz: f64,
    /// History depth of the policy's input topic at the start of the run.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub queue_depth: Option<usize>,
    /// Reset seed.
    pub seed: u64,
    /// Requested duration, s.
    pub duration_s: f64,
    /// Actuator steps run (each applies the held force and steps the plant 20 ms): the
    /// chapter's name, which its summary called "control steps"; the same as
    /// [`Metrics::actuator_steps`].
    pub steps: u64,
    /// Actuator (plant) steps run: the same figure as `steps`, named for what it counts.
    #[serde(default)]
    pub actuator_steps: u64,
    /// Ticks of the chain's policy node that ran its brain (at 5 Hz a tenth of the actuator
    /// steps); ticks an injected fault (`--stall`, `--kill`) swallowed are not counted.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub policy_ticks: Option<u64>,
    /// The policy's rate in force when the run ended, Hz (`control_hz` is the rate it
    /// started with; live changes in the lab and replayed sessions move it).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub control_hz_end: Option<f64>,
    /// Run time when the graph stopped (the fall, or the duration), s.
    pub sim_time_s: f64,
    /// Pole angle after the last step, rad.
    pub final_pole_angle: f64,
    /// Mean sense→act latency, ms (0 when no action was applied).
    pub mean_latency_ms: f64,
    /// Median sense→act latency, ms.
    pub latency_p50_ms: f64,
    /// 99th-percentile sense→act latency, ms.
    pub latency_p99_ms: f64,
    /// Largest sense→act latency, ms.
    pub latency_max_ms: f64,
    /// Messages published on `/obs` (the policy's input topic).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub obs_published: Option<u64>,
    /// `/obs` messages evicted unread.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub obs_dropped: Option<u64>,
    /// `/obs` messages per second of run time.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub obs_msg_per_s: Option<f64>,
    /// Messages published on `/action` (the policy's output topic).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub action_published: Option<u64>,
    /// `/action` messages evicted unread.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub action_dropped: Option<u64>,
    /// `/action` messages per second of run time.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub action_msg_per_s: Option<f64>,
    /// Run time of the fall, s, or `null` when balanced.
    pub fell_at_s: Option<f64>,
    /// Brain label.
    pub policy: String,
    /// Actuator ticks whose newest action was non-finite (held the last good action).
    pub nonfinite_actions: u64,
    /// Real clock only: per-node tick timing.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub node_timing: Option<Vec<NodeTiming>>,
    /// The node that failed (panicked) and ended the run, with its message; absent when
    /// none did. A failed run is not `balanced`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub node_failed: Option<String>,
    /// The graph's name (`cartpole` for the chapter's).
    #[serde(default)]
    pub graph: String,
    /// Per node, by name: kind, rate, ticks (and lateness under the real clock).
    #[serde(default)]
    pub nodes: BTreeMap<String, NodeMetrics>,
    /// Per topic, by name: type, depth, published, dropped, msg/s.
    #[serde(default)]
    pub topics: BTreeMap<String, TopicMetrics>,
    /// When the actuator's deadline watchdog ended the run (`on_deadline_missed = "stop"`):
    /// `stopped by watchdog at T s: no message on TOPIC for more than D`. Absent otherwise.
    /// Such a run is not `balanced`, and did not fall.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub stopped_by_watchdog: Option<String>,
    /// `launch --processes` only: the processes that never reported (gone for good, not
    /// started again). Their nodes' figures, and the counters of the topics they held, are
    /// not measured: they read 0 here. Absent when every process reported.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub missing_processes: Vec<String>,
    /// The executors that share threads (not `per_node`), with their utilization
    /// ([`crate::executor`]). Absent when every node has a thread of its own.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub executors: Vec<crate::executor::ExecutorFigures>,
    /// For a graph without the chapter's chain (sensor → policy → actuator), why the
    /// chain's keys are left out; absent for a graph with it.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub without_chain: Option<String>,
    /// With an estimator in the graph, its error and lag against the plant's truth
    /// ([`crate::estimate`]). Not in `metrics.json`, whose bytes the reference runs fix
    /// (`../shared/fixtures/reference-runs/`): the summary prints it and `--out` writes it
    /// to `estimator.json`.
    #[serde(skip)]
    pub estimate: Option<crate::estimate::EstimateReport>,
}

/// A fault injected into a node (`--stall NODE@T+D`, `--kill NODE@T`), in `metrics.json`.
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
pub struct FaultMetrics {
    /// When it started, s of run time.
    pub at_s: f64,
    /// How long it lasted, s; `None` for a kill (to the end of the run).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub duration_s: Option<f64>,
}

impl FaultMetrics {
    /// A kill that took effect by run time `t_s` (a kill set after a run's end does nothing).
    pub fn kills_by(&self, t_s: f64) -> bool {
        self.duration_s.is_none() && self.at_s <= t_s
    }

    /// The fault in words, as the summary says it: `stalled at 2.00 s for 0.50 s`,
    /// `killed at 3.00 s`.
    pub fn describe(&self) -> String {
        match self.duration_s {
            Some(d) => format!("stalled at {:.2} s for {d:.2} s", self.at_s),
            None => format!("killed at {:.2} s", self.at_s),
        }
    }
}

impl From<&crate::qos::Fault> for FaultMetrics {
    fn from(f: &crate::qos::Fault) -> Self {
        Self {
            at_s: f.at.as_secs_f64(),
            duration_s: f.duration.map(Nanos::as_secs_f64),
        }
    }
}

/// One node's figures in `metrics.json`.
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
pub struct NodeMetrics {
    /// The node's kind, as the graph file names it (`sensor`, `policy`, … or a registered
    /// kind's name: `ratelab kinds` lists them).
    pub kind: String,
    /// Tie-break rank: at a shared instant, lower ticks first.
    pub rank: usize,
    /// Rate at the start of the run, Hz.
    pub rate_hz: f64,
    /// Rate at the end of the run, Hz, when a live change (the lab's keys, a replayed
    /// command) moved it; absent when it ran at `rate_hz` to the end.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub rate_hz_end: Option<f64>,
    /// Ticks run.
    pub ticks: u64,
    /// Real clock only: lateness p99, µs.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub lateness_p99_us: Option<f64>,
    /// Real clock only: largest lateness, µs.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub lateness_max_us: Option<f64>,
    /// Its liveliness lease, ms, when one is set (QoS).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub liveliness_lease_ms: Option<f64>,
    /// Times it went from alive to not alive (with a lease).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub not_alive: Option<u64>,
    /// Ticks a fault (`--stall`, `--kill`) swallowed, when one was injected.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub faulted_ticks: Option<u64>,
    /// The faults injected into it (`--stall`, `--kill`); empty (and left out of
    /// `metrics.json`) without one.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub faults: Vec<FaultMetrics>,
    /// Its declared mean compute time, ms, when it has one ([`crate::executor`]).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub compute_ms: Option<f64>,
    /// The half-width of its compute time's uniform spread, ms, when it has one
    /// (`compute_ms = { mean, jitter }`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub compute_jitter_ms: Option<f64>,
    /// When the graph has executors or compute times: its response times
    /// (`response_time_p50_ms`, `…_p99_ms`, `…_max_ms`), `skipped_ticks` and `busy_ms`.
    #[serde(default, flatten, skip_serializing_if = "Option::is_none")]
    pub exec: Option<crate::executor::NodeExecFigures>,
}

/// One topic's figures in `metrics.json`.
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
pub struct TopicMetrics {
    /// `state`, `position` or `force`.
    #[serde(rename = "type")]
    pub msg: String,
    /// The publishing node.
    pub publisher: String,
    /// The subscribing node, if any (the first, in tie-break order, of several).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub subscriber: Option<String>,
    /// With several subscribers, each one's own queue's figures, by node (the topic's
    /// `dropped`, `stale_reads` and reader-side counters are their sums; each subscription
    /// has a queue of its own, as in ROS 2). Absent for at most one subscriber.
    #[serde(default, skip_serializing_if = "BTreeMap::is_empty")]
    pub subscriptions: BTreeMap<String, SubscriptionMetrics>,
    /// History depth at the end of the run.
    pub depth: usize,
    /// Messages published.
    pub published: u64,
    /// Messages evicted unread (the chapter's drop rule).
    pub dropped: u64,
    /// Reads that found nothing new (the subscriber read a message it had already read).
    pub stale_reads: u64,
    /// Messages per second of run time.
    pub msg_per_s: f64,
    /// Its QoS in short (`KA100 fifo dl 40 ms`), when not the chapter's.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub qos: Option<String>,
    /// The QoS counters it reports ([`crate::topic::TopicStats::reported`]): `expired`,
    /// `refused`, `lost`, `retransmitted`, `offered_deadline_missed`,
    /// `requested_deadline_missed`.
    #[serde(flatten)]
    pub qos_counters: BTreeMap<String, u64>,
    /// The subscriptions its publisher never connected because what they requested was
    /// not offered (`[topic.requested.NODE]`, ROS 2's incompatible-QoS event), by node.
    /// Absent when every subscription was connected.
    #[serde(default, skip_serializing_if = "BTreeMap::is_empty")]
    pub incompatible_qos: BTreeMap<String, IncompatibleQos>,
    /// The subscriptions of nodes that joined late (`start_ms`), by node: when, and what
    /// they found kept for them. Absent when none did.
    #[serde(default, skip_serializing_if = "BTreeMap::is_empty")]
    pub late_joiners: BTreeMap<String, LateJoiner>,
}

/// A subscription whose node joined the graph late ([`TopicMetrics::late_joiners`]).
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
pub struct LateJoiner {
    /// When it joined, s of run time.
    pub start_s: f64,
    /// Messages published before it joined that it received as it joined: a
    /// transient-local topic's last `depth` (0 from a volatile topic, or when the run ended
    /// before it joined).
    pub history: u64,
    /// The topic's durability: `volatile` or `transient_local`.
    pub durability: String,
    /// Messages published before it joined that it never received.
    pub missed: u64,
}

/// One subscription left unconnected by incompatible QoS ([`TopicMetrics::incompatible_qos`]).
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
pub struct IncompatibleQos {
    /// The policy that failed, as ROS 2's event names it (`RELIABILITY`, `DURABILITY`,
    /// `DEADLINE`, `LIVELINESS`, `LIVELINESS_LEASE_DURATION`; the first of several).
    pub policy: String,
    /// The event in one line: `incompatible QoS: requested RELIABLE, offered BEST_EFFORT`.
    pub event: String,
    /// Messages published that never reached it.
    pub not_delivered: u64,
}

/// One subscription's figures on a topic of several subscribers ([`TopicMetrics::subscriptions`]).
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
pub struct SubscriptionMetrics {
    /// Messages evicted from its queue before it read them (the chapter's drop rule).
    pub dropped: u64,
    /// Its reads that found nothing new.
    pub stale_reads: u64,
    /// Messages its queue never got (a lossy link, or the wire).
    pub lost: u64,
}

impl Metrics {
    /// One line naming the node threads whose requested real-time priority was refused, the
    /// policy they ran under instead and the kernel's reason; `None` when nothing was refused.
    pub fn sched_warning(&self) -> Option<String> {
        let refused: Vec<&NodeTiming> = self
            .node_timing
            .iter()
            .flatten()
            .filter(|t| t.sched_error.is_some())
            .collect();
        let first = refused.first()?;
        let names: Vec<&str> = refused.iter().map(|t| t.node.as_str()).collect();
        Some(format!(
            "{} ran under {}: {}",
            names.join(", "),
            first.sched,
            first.sched_error.as_deref().unwrap_or_default()
        ))
    }

    /// `sensor 50 Hz | control 50 Hz | actuator 50 Hz | queue_depth 1`: every node by
    /// tie-break rank (a graph's one policy is the chapter's "control"), then the depth (one
    /// figure when every topic shares it, else per topic).
    fn rates_line(&self) -> String {
        let mut nodes: Vec<(&String, &NodeMetrics)> = self.nodes.iter().collect();
        nodes.sort_by_key(|(_, n)| n.rank);
        let mut parts = self.node_rates(&nodes);
        if nodes.len() > SUMMARY_ITEMS {
            // A large graph: the first nodes, then the rest counted by rate (rates are
            // positive, so their bits order as they do), the most common few named.
            let mut by_rate: BTreeMap<u64, usize> = BTreeMap::new();
            for (_, n) in &nodes[SUMMARY_SHOWN..] {
                *by_rate
                    .entry(n.rate_hz_end.unwrap_or(n.rate_hz).to_bits())
                    .or_default() += 1;
            }
            let mut groups: Vec<String> = by_rate
                .iter()
                .take(SUMMARY_SHOWN)
                .map(|(hz, count)| format!("{} Hz ×{count}", f64::from_bits(*hz)))
                .collect();
            if by_rate.len() > SUMMARY_SHOWN {
                let rest: usize = by_rate.values().skip(SUMMARY_SHOWN).sum();
                groups.push(format!(
                    "{rest} at {} other rates",
                    by_rate.len() - SUMMARY_SHOWN
                ));
            }
            parts.truncate(SUMMARY_SHOWN);
            parts.push(format!(
                "{} more nodes: {}",
                nodes.len() - SUMMARY_SHOWN,
                groups.join(", ")
            ));
        }
        parts.push(self.depths_text());
        parts.join(" | ")
    }

    /// Each node's rate as the rates line says it, `nodes` in rank order: `sensor 50 Hz`,
    /// the chain's one policy as `control`, a rate a live change moved with its start.
    fn node_rates(&self, nodes: &[(&String, &NodeMetrics)]) -> Vec<String> {
        let one_policy = nodes.iter().filter(|(_, n)| n.kind == "policy").count() == 1;
        nodes
            .iter()
            .map(|(name, n)| {
                let label = if one_policy && n.kind == "policy" {
                    "control"
                } else {
                    name.as_str()
                };
                match n.rate_hz_end {
                    Some(end) => format!("{label} {end} Hz ({} Hz at the start)", n.rate_hz),
                    None => format!("{label} {} Hz", n.rate_hz),
                }
            })
            .collect()
    }

    /// The topics' history depth: `queue_depth 1` when they share one (with the start's
    /// when a live change moved it), else each topic's (the first few of a large graph's).
    fn depths_text(&self) -> String {
        let topics = self.topics_by_publisher();
        let depth0 = topics
            .first()
            .map_or(self.queue_depth.unwrap_or(0), |(_, t)| t.depth);
        let shared = topics.iter().all(|(_, t)| t.depth == depth0);
        match self.queue_depth {
            // A live change moved it: the depth at the end, as the topics report it.
            Some(start) if shared && start != depth0 => {
                format!("queue_depth {depth0} at the end, {start} at the start")
            }
            _ if shared => format!("queue_depth {depth0}"),
            _ => {
                let mut depths: Vec<String> = topics
                    .iter()
                    .take(SUMMARY_ITEMS)
                    .map(|(name, t)| format!("{name} {}", t.depth))
                    .collect();
                if topics.len() > SUMMARY_ITEMS {
                    depths.truncate(SUMMARY_SHOWN);
                    depths.push(format!("and {} more", topics.len() - SUMMARY_SHOWN));
                }
                format!("depths {}", depths.join(", "))
            }
        }
    }

    /// `/obs 50.0 msg/s (0 dropped) | /action …`, topics in their publishers' rank order; a
    /// topic nobody subscribes to says so instead of its drops (every message it evicts
    /// counts as dropped, read by no one).
    fn topics_line(&self) -> String {
        let topics = self.topics_by_publisher();
        let shown = if topics.len() > SUMMARY_ITEMS {
            SUMMARY_SHOWN
        } else {
            topics.len()
        };
        let mut parts: Vec<String> = topics[..shown]
            .iter()
            .map(|(name, t)| {
                let rate = self.rate_text(t);
                match t.subscriber {
                    // Several subscribers: each one's drops (a queue each).
                    Some(_) if !t.subscriptions.is_empty() => {
                        let each: Vec<String> = t
                            .subscriptions
                            .iter()
                            .map(|(node, s)| format!("{node} {} dropped", s.dropped))
                            .collect();
                        format!("{name} {rate} ({})", each.join(", "))
                    }
                    Some(_) => format!("{name} {rate} ({} dropped)", t.dropped),
                    None => format!("{name} {rate} (no subscriber)"),
                }
            })
            .collect();
        let rest = &topics[shown..];
        if !rest.is_empty() {
            // A large graph: the first topics, then the rest summed.
            let published: u64 = rest.iter().map(|(_, t)| t.published).sum();
            let dropped: u64 = rest
                .iter()
                .filter(|(_, t)| t.subscriber.is_some())
                .map(|(_, t)| t.dropped)
                .sum();
            let unread = rest.iter().filter(|(_, t)| t.subscriber.is_none()).count();
            parts.push(format!(
                "{} more topics: {published} msgs, {dropped} dropped, {unread} with no subscriber",
                rest.len()
            ));
        }
        parts.join(" | ")
    }

    /// A topic's traffic as the summary says it: `50.1 msg/s` (`msg_per_s`, the chapter's
    /// published / run time), or under a second of run time the count, `18 msgs in 0.34 s`:
    /// over a few periods the message at t = 0 weighs enough to read above the set rate
    /// (52.9 msg/s for a 50 Hz sensor), which a learner would take for a faster sensor.
    fn rate_text(&self, t: &TopicMetrics) -> String {
        if self.sim_time_s < 1.0 {
            format!(
                "{} msg{} in {:.2} s",
                t.published,
                if t.published == 1 { "" } else { "s" },
                self.sim_time_s
            )
        } else {
            format!("{:.1} msg/s", t.msg_per_s)
        }
    }

    /// True when the actuator requested a QoS its input's publisher never offered, so
    /// nothing published reached it ([`TopicMetrics::incompatible_qos`]).
    fn actuator_unconnected(&self) -> bool {
        self.topics.values().any(|t| {
            t.incompatible_qos.iter().any(|(node, i)| {
                self.nodes.get(node).is_some_and(|n| n.kind == "actuator")
                    && t.published > 0
                    && i.not_delivered == t.published
            })
        })
    }

    /// Why no command reached the actuator, when none did though the chain above it ran: each
    /// topic it reads was never published (`/cmd was never published`: a publisher killed,
    /// stalled or silent from the start) or lost every message on its link (`every /cmd
    /// message was lost on its link`). `None` when one reached it, or the graph names no
    /// actuator or none of its inputs. Read from the topics' counters alone, so it says the
    /// same of a `metrics.json` read back.
    fn no_command_reached(&self) -> Option<String> {
        let (actuator, _) = self.nodes.iter().find(|(_, n)| n.kind == "actuator")?;
        let reads = |t: &TopicMetrics| {
            t.subscriber.as_ref() == Some(actuator) || t.subscriptions.contains_key(actuator)
        };
        let lost = |t: &TopicMetrics| match t.subscriptions.get(actuator) {
            Some(s) => s.lost,
            None => t
                .qos_counters
                .get(crate::qos::QosCounter::Lost.key())
                .copied()
                .unwrap_or(0),
        };
        let mut why = Vec::new();
        for (name, t) in self.topics.iter().filter(|(_, t)| reads(t)) {
            if t.published == 0 {
                why.push(format!("{name} was never published"));
            } else if lost(t) >= t.published {
                why.push(format!("every {name} message was lost on its link"));
            } else {
                return None;
            }
        }
        (!why.is_empty()).then(|| why.join(", "))
    }

    /// QoS lines, only when something is set: `qos: /cmd KL1 latest dl 40 ms link 20%: 41
    /// lost, 12 offered deadline missed …`, `liveliness: policy not alive 1×`, and the
    /// watchdog's verdict.
    fn qos_lines(&self) -> Vec<String> {
        let mut lines = Vec::new();
        let topics: Vec<String> = self
            .topics_by_publisher()
            .iter()
            .filter(|(_, t)| t.qos.is_some() || !t.qos_counters.is_empty())
            .map(|(name, t)| {
                let counts: Vec<String> = t
                    .qos_counters
                    .iter()
                    .map(|(k, v)| format!("{v} {}", k.replace('_', " ")))
                    .collect();
                // The default QoS, named at the topic's depth (`KL1 latest`).
                let default = crate::qos::TopicQos::default().short(t.depth);
                format!(
                    "{name} {}{}{}",
                    t.qos.as_deref().unwrap_or(&default),
                    if counts.is_empty() { "" } else { ": " },
                    counts.join(", ")
                )
            })
            .collect();
        if !topics.is_empty() {
            lines.push(format!("qos: {}", topics.join(" | ")));
        }
        // A fault set after the run's end did nothing (its warning said so at the start): not
        // listed as if it had happened. One at the end itself took that last instant.
        let end_s = self.sim_time_s;
        let took_effect = |f: &&FaultMetrics| f.at_s <= end_s;
        let mut nodes: Vec<(&String, &NodeMetrics)> = self
            .nodes
            .iter()
            .filter(|(_, n)| {
                n.not_alive.is_some()
                    || n.faulted_ticks.is_some_and(|f| f > 0)
                    || n.faults.iter().any(|f| took_effect(&f))
            })
            .collect();
        nodes.sort_by_key(|(_, n)| n.rank);
        if !nodes.is_empty() {
            let parts: Vec<String> = nodes
                .iter()
                .map(|(name, n)| {
                    let mut p = name.to_string();
                    if let (Some(lease), Some(k)) = (n.liveliness_lease_ms, n.not_alive) {
                        p.push_str(&format!(" not alive {k}× (lease {lease} ms)"));
                    }
                    let faults: Vec<&FaultMetrics> = n.faults.iter().filter(took_effect).collect();
                    if !faults.is_empty() {
                        let sep = if n.not_alive.is_some() { ", " } else { " " };
                        let said: Vec<String> = faults.iter().map(|f| f.describe()).collect();
                        p.push_str(&format!("{sep}{}", said.join(", ")));
                    }
                    match (n.faulted_ticks, faults.is_empty()) {
                        (Some(f), true) if f > 0 => {
                            p.push_str(&format!(" {f} ticks lost to faults"))
                        }
                        (Some(f), false) => p.push_str(&format!(": {f} ticks lost")),
                        _ => {}
                    }
                    p
                })
                .collect();
            lines.push(format!("liveliness: {}", parts.join(" | ")));
        }
        for (name, t) in self.topics_by_publisher() {
            for (node, j) in &t.late_joiners {
                lines.push(format!(
                    "{name} → {node} joined at {:.2} s and received {} from before ({})",
                    j.start_s,
                    counted(j.history, "message"),
                    j.durability.replace('_', "-")
                ));
            }
            for (node, i) in &t.incompatible_qos {
                lines.push(format!(
                    "{name} → {node}: {} ({} not delivered)",
                    i.event,
                    counted(i.not_delivered, "message")
                ));
            }
        }
        if let Some(w) = &self.stopped_by_watchdog {
            lines.push(format!("STOPPED BY WATCHDOG: {w}"));
        }
        lines
    }

    /// When the graph has executors or compute times ([`crate::executor`]): one line per
    /// executor that shares threads (`executor main: single_threaded, 1 thread, 87% busy`),
    /// then per node `compute 30 ms | response p50 … p99 … max … ms | 12 skipped ticks`.
    fn executor_lines(&self) -> Vec<String> {
        let mut lines: Vec<String> = self
            .executors
            .iter()
            .map(|e| {
                format!(
                    "executor {}: {}, {} thread{}, {:.0}% busy",
                    e.name,
                    e.kind.name(),
                    e.threads,
                    if e.threads == 1 { "" } else { "s" },
                    e.utilization * 100.0
                )
            })
            .collect();
        let mut nodes: Vec<(&String, &NodeMetrics)> = self
            .nodes
            .iter()
            .filter(|(_, n)| n.exec.is_some())
            .collect();
        nodes.sort_by_key(|(_, n)| n.rank);
        for (name, n) in nodes {
            let Some(x) = &n.exec else { continue };
            let compute = match (n.compute_ms, n.compute_jitter_ms) {
                (Some(c), Some(j)) => format!("compute {c}±{j} ms"),
                (Some(c), None) => format!("compute {c} ms"),
                (None, _) => "compute 0 ms".to_string(),
            };
            // A tick that computes publishes no sooner than its compute time after its
            // release: a response of 0 with a compute time is no tick finished, not a fast one.
            let response = if n.compute_ms.is_some_and(|c| c > 0.0) && x.response_time_max_ms == 0.0
            {
                "no tick finished its compute time".to_string()
            } else {
                format!(
                    "response p50 {:.1} | p99 {:.1} | max {:.1} ms",
                    x.response_time_p50_ms, x.response_time_p99_ms, x.response_time_max_ms
                )
            };
            lines.push(format!(
                "node {name:<8} {compute} | {response} | {} skipped ticks",
                x.skipped_ticks
            ));
        }
        lines
    }

    /// When an injected `--kill` of the actuator took effect, s of run time; `None` when no
    /// actuator was killed within the run (a kill set after its end does nothing).
    pub fn actuator_killed_at_s(&self) -> Option<f64> {
        self.nodes
            .values()
            .filter(|n| n.kind == "actuator")
            .flat_map(|n| &n.faults)
            .find(|f| f.kills_by(self.sim_time_s))
            .map(|f| f.at_s)
    }

    /// Why a run that reached its summary is still no success, in one line, or `None` for a
    /// run that ran its duration or fell (issue 27: "a lying report can never read as
    /// success"). A deadline watchdog's stop (`the run ended early: …`) and an actuator
    /// killed within the run (the plant stood still from then) are no success; the binary
    /// prints this line after the summary and files and exits 2.
    pub fn no_success(&self) -> Option<String> {
        if let Some(w) = &self.stopped_by_watchdog {
            Some(format!("the run ended early: {w}"))
        } else {
            self.actuator_killed_at_s().map(|t| {
                format!(
                    "the actuator was killed at t={t:.2}s (--kill): the plant stood still from then, so the run balanced nothing after"
                )
            })
        }
    }

    /// The summary's headline: how the run really ended, first match wins: `HUNG in
    /// policy's callback (…)` (a call into a learner's code that never returned, stopped by
    /// Ctrl-C: its failure starts with [`HUNG`]), `NODE FAILED`,
    /// `FELL at t=…`, `STOPPED BY WATCHDOG at t=…` (QoS `on_deadline_missed=stop`), `PLANT
    /// NEVER STEPPED` (the actuator ran no step), `STOPPED EARLY at t=… of …` (interrupted
    /// before its duration; `STOPPED at t=… (no set length …)` for a run of no set length,
    /// [`crate::limits::MAX_DURATION_S`], which only stopping ends), `BALANCED while the plant ran` (the actuator lost ticks to an
    /// injected fault, the plant standing still meanwhile), else `BALANCED (pole up the
    /// whole run)`. "The whole run" is said only when the plant stepped the whole run.
    pub fn headline(&self) -> String {
        let actuator_faults: u64 = self
            .nodes
            .values()
            .filter(|n| n.kind == "actuator")
            .filter_map(|n| n.faulted_ticks)
            .sum();
        if let Some(failed) = &self.node_failed {
            match failed.split_once(": ") {
                Some((node, why)) if why.starts_with(HUNG) => {
                    let why = &why[HUNG.len()..];
                    format!(
                        "HUNG in {node}'s callback at t={:.2}s ({why})",
                        self.sim_time_s
                    )
                }
                _ => format!("NODE FAILED ({failed})"),
            }
        } else if let Some(t) = self.fell_at_s {
            format!("FELL at t={t:.2}s")
        } else if self.stopped_by_watchdog.is_some() {
            format!(
                "STOPPED BY WATCHDOG at t={:.2}s (pole up until then; not balanced)",
                self.sim_time_s
            )
        } else if self.steps == 0 {
            let why = if actuator_faults > 0 {
                format!("the actuator lost all {actuator_faults} of its ticks to a fault")
            } else {
                "the actuator ran no step".to_string()
            };
            format!("PLANT NEVER STEPPED ({why}; nothing was balanced)")
        } else if self.sim_time_s + 1e-9 < self.duration_s {
            if self.duration_s >= crate::limits::MAX_DURATION_S {
                // No length was set (the lab, a launch on a terminal): it ran until stopped.
                format!(
                    "STOPPED at t={:.2}s (no set length; pole up until then)",
                    self.sim_time_s
                )
            } else {
                format!(
                    "STOPPED EARLY at t={:.2}s of {:.2}s (pole up until then)",
                    self.sim_time_s, self.duration_s
                )
            }
        } else if let Some(at_s) = self.actuator_killed_at_s() {
            // The plant stood still from the kill to the end: it balanced nothing after.
            format!(
                "ACTUATOR KILLED at t={at_s:.2}s (pole up until then; the plant stood still after)"
            )
        } else if actuator_faults > 0 {
            format!(
                "BALANCED while the plant ran (the actuator lost {actuator_faults} ticks to a fault; the plant stood still meanwhile)"
            )
        } else {
            BALANCED_WHOLE_RUN.to_string()
        }
    }

    fn topics_by_publisher(&self) -> Vec<(&String, &TopicMetrics)> {
        let rank = |node: &str| self.nodes.get(node).map_or(usize::MAX, |n| n.rank);
        let mut topics: Vec<(&String, &TopicMetrics)> = self.topics.iter().collect();
        topics.sort_by_key(|(name, t)| (rank(&t.publisher), name.as_str()));
        topics
    }

    /// The chapter's human summary (five lines, no terminal codes). `wall_s` is the
    /// wall time the run took, when known (not part of the metrics: it varies run to run).
    /// The chapter's "control steps" are named for what they count, actuator steps (the
    /// plant's 20 ms steps), beside the policy's ticks; the policy period is the one in
    /// force at the end (with the starting one when a live change moved it).
    pub fn summary_lines(&self, wall_s: Option<f64>) -> Vec<String> {
        let wall = wall_s.map_or_else(String::new, |w| format!(" ({w:.2}s wall)"));
        let ticks = self
            .policy_ticks
            .map_or_else(String::new, |t| format!(", {}", counted(t, "policy tick")));
        // Under the real clock run time is wall time from the start: not simulated time.
        let time = if self.clock == crate::clock::ClockKind::Real.as_str() {
            "run time"
        } else {
            "sim"
        };
        let counted = format!(
            "{}{ticks} in {:.2}s {time}{wall}",
            counted(self.steps, "actuator step"),
            self.sim_time_s
        );
        let verdict = format!("{} — {counted}", self.headline());
        let period =
            |hz: f64| crate::rate::period_for_hz(hz).map_or_else(|_| "?".into(), |p| p.to_string());
        let policy_period = match (self.control_hz, self.control_hz_end) {
            (Some(start), Some(end)) if start == end => format!("; policy period {}", period(end)),
            (Some(start), Some(end)) => format!(
                "; policy period {} at the end, {} at the start",
                period(end),
                period(start)
            ),
            _ => String::new(),
        };
        let mut lines = vec![
            format!("clock={}  policy={}", self.clock, self.policy),
            format!("rates: {}", self.rates_line()),
            verdict,
            format!("topics: {}", self.topics_line()),
            if self.action_published == Some(0) {
                // Nothing reached the actuator: there is no latency to give, not one of 0 ms.
                "sense->act latency: none (no command was published to the actuator)".to_string()
            } else if self.steps > 0 && self.nonfinite_actions >= self.steps {
                // Every command was NaN or ±inf: none was applied, none has a latency.
                "sense->act latency: none (no finite command was applied)".to_string()
            } else if self.actuator_unconnected() {
                // Published, and never delivered: no latency either.
                "sense->act latency: none (the actuator's subscription was never connected: incompatible QoS)".to_string()
            } else if self.steps == 0 {
                // Nothing was applied: the same, from the other end of the chain.
                "sense->act latency: none (the actuator applied no command)".to_string()
            } else if let Some(why) = self.no_command_reached() {
                // Its input's publisher never published (or its link lost everything): the
                // mean of no samples is no latency, not 0.0 ms.
                format!("sense->act latency: none (no command reached the actuator: {why})")
            } else {
                format!(
                    "mean sense->act latency: {:.1} ms  (p50 {:.1} | p99 {:.1} | max {:.1} ms{policy_period})",
                    self.mean_latency_ms,
                    self.latency_p50_ms,
                    self.latency_p99_ms,
                    self.latency_max_ms,
                )
            },
        ];
        lines.extend(self.qos_lines());
        if let Some(why) = &self.without_chain {
            lines.push(why.clone());
        }
        if let Some(e) = &self.estimate {
            lines.push(e.figures.line(&e.topic));
        }
        lines.extend(self.executor_lines());
        if self.nonfinite_actions > 0 {
            let kept = if self.nonfinite_actions >= self.steps {
                "no good action came, so no force was applied"
            } else {
                "the actuator kept the last good action"
            };
            lines.push(format!(
                "non-finite actions held over: {} ({kept})",
                self.nonfinite_actions
            ));
        }
        if !self.missing_processes.is_empty() {
            lines.push(format!(
                "not measured: process(es) {} did not report; their nodes' figures read 0, the topics they hold their last figures (what was sent after those counted lost)",
                self.missing_processes.join(", ")
            ));
        }
        if let Some(timing) = &self.node_timing {
            for t in timing {
                if t.sched.is_empty() && t.ticks == 0 {
                    lines.push(format!(
                        "node {:<8} no figures (its process did not report)",
                        t.node
                    ));
                    continue;
                }
                lines.push(format!(
                    "node {:<8} {:>7.2} Hz measured | lateness p50 {:.0} µs, p99 {:.0} µs, max {:.0} µs | cpu {:.0} ms | {}",
                    t.node, t.measured_hz, t.lateness_p50_us, t.lateness_p99_us, t.lateness_max_us, t.cpu_ms, t.sched
                ));
            }
        }
        lines
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The safety graph's `metrics.json` of a run whose `/cmd` (safety → actuator) was
    /// published `cmd` times, `lost` of them on its link, and whose mean latency reads 0.0 ms
    /// (a mean of no samples, or of samples at matched rates under the virtual clock).
    fn safety_run(cmd: u64, lost: u64) -> Metrics {
        let lost = if lost > 0 {
            format!(r#", "lost": {lost}"#)
        } else {
            String::new()
        };
        let json = format!(
            r#"{{
  "balanced": false, "clock": "virtual", "control_hz": 50.0, "actuator_hz": 50.0, "seed": 0,
  "duration_s": 2.0, "steps": 32, "sim_time_s": 0.62, "final_pole_angle": 0.21,
  "mean_latency_ms": 0.0, "latency_p50_ms": 0.0, "latency_p99_ms": 0.0, "latency_max_ms": 0.0,
  "action_published": 32, "fell_at_s": 0.62, "policy": "scripted", "nonfinite_actions": 0,
  "nodes": {{
    "actuator": {{"kind": "actuator", "rank": 3, "rate_hz": 50.0, "ticks": 32}},
    "safety": {{"kind": "safety", "rank": 2, "rate_hz": 50.0, "ticks": 32}}
  }},
  "topics": {{
    "/cmd": {{"type": "force", "publisher": "safety", "subscriber": "actuator", "depth": 1,
      "published": {cmd}, "dropped": 0, "stale_reads": 0, "msg_per_s": 0.0{lost}}}
  }}
}}"#
        );
        serde_json::from_str(&json).unwrap()
    }

    /// No command reached the actuator (its input's publisher never published, as a safety
    /// node killed at t = 0): no latency, said "none" as the non-finite case says it, not a
    /// mean of 0.0 ms; and the figures of `metrics.json` stay as they were (#72).
    #[test]
    fn no_command_reaching_the_actuator_is_no_latency_not_0_ms() {
        let silent = safety_run(0, 0);
        assert_eq!(
            silent.summary_lines(None)[4],
            "sense->act latency: none (no command reached the actuator: /cmd was never published)"
        );
        assert_eq!(silent.mean_latency_ms, 0.0);
        let lost = safety_run(20, 20);
        assert_eq!(
            lost.summary_lines(None)[4],
            "sense->act latency: none (no command reached the actuator: every /cmd message was lost on its link)"
        );
        // Commands that arrived at matched rates under the virtual clock: 0 ms is a latency.
        for m in [safety_run(32, 0), safety_run(32, 5)] {
            assert!(
                m.summary_lines(None)[4].starts_with("mean sense->act latency: 0.0 ms"),
                "{:?}",
                m.summary_lines(None)
            );
        }
    }

    /// A run stopped before its end says of how long; one of no set length (the lab's, a
    /// launch's on a terminal: the longest run there is) says it had none, not "of
    /// 315360000.00s".
    #[test]
    fn a_run_stopped_says_of_how_long_only_when_it_had_a_length() {
        let stopped = |duration_s: f64| {
            let mut m = safety_run(32, 0);
            (m.fell_at_s, m.sim_time_s, m.duration_s) = (None, 20.42, duration_s);
            m.headline()
        };
        assert_eq!(
            stopped(60.0),
            "STOPPED EARLY at t=20.42s of 60.00s (pole up until then)"
        );
        assert_eq!(
            stopped(crate::limits::MAX_DURATION_S),
            "STOPPED at t=20.42s (no set length; pole up until then)"
        );
    }

    #[test]
    fn latency_stats_mean_is_exact_and_quantiles_close() {
        let mut s = LatencyStats::default();
        assert_eq!(s.mean(), None);
        for ms in [0u64, 20, 40] {
            s.record(Nanos::from_millis(ms));
        }
        assert_eq!(s.mean(), Some(20_000_000.0));
        let p50 = s.quantile(0.5).unwrap().as_millis_f64();
        assert!((p50 - 20.0).abs() < 0.05, "{p50}");
        assert!((s.max().unwrap().as_millis_f64() - 40.0).abs() < 0.05);
    }

    #[test]
    fn latency_stats_allocate_their_histogram_at_the_first_sample() {
        let s = LatencyStats::default();
        assert!(s.hist.is_none(), "no histogram before a sample");
        assert_eq!((s.count(), s.quantile(0.5), s.max()), (0, None, None));
        assert!(s.histogram().is_empty());
        assert_eq!(s.summary_ms(), (0.0, 0.0, 0.0));
        let mut s = s.clone();
        s.record(Nanos::from_millis(3));
        assert!(s.hist.is_some());
        assert_eq!(s.count(), 1);
        assert_eq!(s.histogram().len(), 1);
    }

    #[test]
    fn exact_latencies_print_exactly() {
        // A 5 Hz policy over a 50 Hz actuator: 0, 20, …, 180 ms, again and again. The HDR
        // histogram printed p50 80.019 and p99 180.1 ms here.
        let s: ExactLatency = (0..43u64)
            .map(|i| Nanos::from_millis(20 * (i % 10)))
            .collect();
        assert!(s.is_exact());
        assert_eq!(s.quantile(0.5), Some(Nanos::from_millis(80)));
        assert_eq!(s.quantile(0.99), Some(Nanos::from_millis(180)));
        assert_eq!(s.max(), Some(Nanos::from_millis(180)));
        assert_eq!(s.summary_ms(), (80.0, 180.0, 180.0));
        assert_eq!(
            format!("p50 {:.1} | p99 {:.1}", s.summary_ms().0, s.summary_ms().1),
            "p50 80.0 | p99 180.0"
        );
        // A period that is not a whole number of µs: exact to the ns, rounded to µs for print.
        let t: ExactLatency = [142_857_142u64, 9_900_001].map(Nanos).into_iter().collect();
        assert_eq!(t.max(), Some(Nanos(142_857_142)));
        assert_eq!(t.summary_ms().2, 142.857);
        let empty = ExactLatency::default();
        assert_eq!((empty.quantile(0.5), empty.max()), (None, None));
        assert_eq!(empty.summary_ms(), (0.0, 0.0, 0.0));
    }

    #[test]
    fn exact_order_statistics_match_a_sort_across_blocks() {
        // Many blocks (splits), duplicates, and values arriving out of order.
        let mut x = 12345u64;
        let mut values = Vec::new();
        let mut s = ExactLatency::default();
        for i in 0..20_000u64 {
            x = x
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            let v = if i % 3 == 0 {
                20_000_000
            } else {
                (x >> 33) % 300_000_000
            };
            values.push(v);
            s.record(Nanos(v));
        }
        values.sort_unstable();
        let n = values.len();
        for q in [0.0, 0.001, 0.25, 0.5, 0.9, 0.99, 0.999, 1.0] {
            let rank = ((q * n as f64).ceil() as usize).max(1);
            assert_eq!(s.quantile(q), Some(Nanos(values[rank - 1])), "q {q}");
        }
        assert_eq!(s.max(), Some(Nanos(*values.last().unwrap())));
        let mean = values.iter().map(|&v| v as f64).sum::<f64>() / n as f64;
        assert!((s.mean().unwrap() - mean).abs() < 1e-3);
        // The same ranking as the histogram's, to its precision.
        let h = s.histogram().value_at_quantile(0.5) as f64;
        assert!((h - s.quantile(0.5).unwrap().0 as f64).abs() <= h * 1e-3);
    }

    #[test]
    fn count_below_is_exact_at_the_bounds() {
        let s: ExactLatency = [0u64, 10_000_000, 19_990_000, 20_000_000, 200_000_000]
            .map(Nanos)
            .into_iter()
            .collect();
        assert_eq!(s.count_below(Nanos(0)), 0);
        assert_eq!(
            s.count_below(Nanos::from_millis(20)),
            3,
            "19.99 ms is below 20"
        );
        assert_eq!(
            s.count_below(Nanos::from_millis(200)),
            4,
            "200 ms is not below 200"
        );
        assert_eq!(s.count_below(Nanos(u64::MAX)), 5);
    }

    #[test]
    fn a_clone_shares_its_blocks_and_keeps_its_samples_when_the_original_goes_on() {
        let mut a: ExactLatency = (0..5_000u64).map(|i| Nanos(i * 7 % 1_000)).collect();
        let b = a.clone();
        assert!(a
            .blocks
            .iter()
            .zip(&b.blocks)
            .all(|(x, y)| std::sync::Arc::ptr_eq(x, y)));
        for i in 0..5_000u64 {
            a.record(Nanos(2_000 + i));
        }
        assert_eq!(b.count(), 5_000);
        assert_eq!(b.max(), Some(Nanos(999)));
        assert_eq!(b.count_below(Nanos(1_000)), 5_000);
        assert_eq!(a.count(), 10_000);
        assert_eq!(a.max(), Some(Nanos(6_999)));
        assert_eq!(a.count_below(Nanos(1_000)), 5_000);
        assert_eq!(a.quantile(0.5), Some(Nanos(999)));
    }

    #[test]
    fn exact_storage_is_bounded_by_the_longest_run() {
        assert_eq!(
            MAX_EXACT_SAMPLES, 180_001,
            "3600 s of 50 Hz ticks, inclusive"
        );
        let mut s: ExactLatency = (0..MAX_EXACT_SAMPLES as u64).map(|_| Nanos(7)).collect();
        assert!(s.is_exact());
        s.record(Nanos::from_millis(500));
        // Past the bound: counted (mean, histogram) but not kept; percentiles from the
        // histogram, still sound.
        assert!(!s.is_exact());
        assert_eq!(s.count(), MAX_EXACT_SAMPLES as u64 + 1);
        assert_eq!(s.kept, MAX_EXACT_SAMPLES);
        assert_eq!(s.quantile(0.5), Some(Nanos(7)));
        let max = s.max().unwrap().as_millis_f64();
        assert!((max - 500.0).abs() < 0.5, "{max}");
    }
}
