//! Metrics: what a run measured, per step and in total, and the chapter's summary.
//!
//! The actuator appends one [`StepRecord`] per tick to a [`RunLog`]. Sense→act latency of
//! a tick is `now - origin_stamp` of the action it applied (ch2.8, `ActuatorNode`); its
//! statistics use an HDR histogram (3 significant digits) plus an exact integer mean.
//! [`Metrics`] is the run's summary and the schema of `metrics.json` (the chapter's keys,
//! plus percentiles, `fell_at_s`, `policy` and ratelab's extras).

use crate::graph::spec::MAX_TOPICS;
use crate::graph::TopicId;
use crate::time::Nanos;
use crate::topic::TopicStats;
use hdrhistogram::Histogram;
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;

/// Every topic's counters at one instant, by [`TopicId`]: a fixed-size copy (no allocation
/// per actuator step), at most [`MAX_TOPICS`] entries.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct TopicCounters {
    len: u8,
    stats: [TopicStats; MAX_TOPICS],
}

impl FromIterator<TopicStats> for TopicCounters {
    /// From each topic's stats, in [`TopicId`] order (entries past [`MAX_TOPICS`] are ignored;
    /// a validated graph has no more).
    fn from_iter<I: IntoIterator<Item = TopicStats>>(stats: I) -> Self {
        let mut c = TopicCounters::default();
        for s in stats.into_iter().take(MAX_TOPICS) {
            c.stats[c.len as usize] = s;
            c.len += 1;
        }
        c
    }
}

impl TopicCounters {
    /// Topic `id`'s counters (zeros for an id past the end).
    pub fn get(&self, id: TopicId) -> TopicStats {
        self.as_slice().get(id.0).copied().unwrap_or_default()
    }
    /// All of them, by [`TopicId`].
    pub fn as_slice(&self) -> &[TopicStats] {
        &self.stats[..self.len as usize]
    }
}

impl Serialize for TopicCounters {
    fn serialize<S: serde::Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        self.as_slice().serialize(s)
    }
}

/// One actuator tick.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct StepRecord {
    /// Control step number, from 1.
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
}

/// Latency (or lateness) statistics over a run: an HDR histogram in nanoseconds with an
/// exact integer sum for the mean.
#[derive(Clone, Debug)]
pub struct LatencyStats {
    hist: Histogram<u64>,
    sum_ns: u128,
}

impl Default for LatencyStats {
    fn default() -> Self {
        Self {
            // 1 ns .. 1 hour at 3 significant digits.
            hist: Histogram::new_with_bounds(1, 3_600_000_000_000, 3)
                .expect("static bounds are valid"),
            sum_ns: 0,
        }
    }
}

impl LatencyStats {
    /// Record one sample (saturated at one hour).
    pub fn record(&mut self, value: Nanos) {
        self.hist.saturating_record(value.0);
        self.sum_ns += u128::from(value.0);
    }

    /// Number of samples.
    pub fn count(&self) -> u64 {
        self.hist.len()
    }

    /// Exact mean, or `None` with no samples.
    pub fn mean(&self) -> Option<f64> {
        (self.count() > 0).then(|| self.sum_ns as f64 / self.count() as f64)
    }

    /// The value at quantile `q` in [0, 1] (HDR precision), or `None` with no samples.
    pub fn quantile(&self, q: f64) -> Option<Nanos> {
        (self.count() > 0).then(|| Nanos(self.hist.value_at_quantile(q)))
    }

    /// The largest sample (HDR precision), or `None` with no samples.
    pub fn max(&self) -> Option<Nanos> {
        (self.count() > 0).then(|| Nanos(self.hist.max()))
    }

    /// The underlying histogram (for drawing buckets).
    pub fn histogram(&self) -> &Histogram<u64> {
        &self.hist
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

/// Round `x` to `digits` decimals (report figures only).
pub fn round_to(x: f64, digits: i32) -> f64 {
    let p = 10f64.powi(digits);
    (x * p).round() / p
}

/// Everything the actuator measured during a run.
#[derive(Clone, Debug, Default)]
pub struct RunLog {
    /// One record per actuator tick, in order (empty when the trace is not kept).
    pub trace: Vec<StepRecord>,
    /// Whether to keep every [`StepRecord`] (headless runs do; long lab runs may not).
    pub keep_trace: bool,
    /// The newest record.
    pub last: Option<StepRecord>,
    /// Actuator ticks so far.
    pub steps: u64,
    /// Sense→act latency over every tick that applied a sensed action.
    pub latency: LatencyStats,
    /// Ticks whose newest action was non-finite (the last good action was held).
    pub nonfinite_actions: u64,
    /// Run time of the fall, if the pole fell.
    pub fell_at: Option<Nanos>,
    /// When the actuator's deadline watchdog stopped the run (`on_deadline_missed =
    /// "stop"`), with the topic and its deadline: a verdict distinct from a fall.
    pub watchdog: Option<Watchdog>,
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
        if rec.fell && self.fell_at.is_none() {
            self.fell_at = Some(rec.t);
        }
        if self.keep_trace {
            self.trace.push(rec);
        }
        self.last = Some(rec);
    }
}

/// Tick-timing statistics of one node under the real clock.
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
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

/// A run's summary: the schema of `metrics.json`. Keys follow the chapter's report, then
/// ratelab's additions. Under the virtual clock every field is a pure function of the
/// settings (no wall-clock figure), so two runs serialize byte for byte the same.
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
pub struct Metrics {
    /// The pole stayed up for the whole run.
    pub balanced: bool,
    /// `virtual` or `real`.
    pub clock: String,
    /// Policy rate at the start of the run, Hz.
    pub control_hz: f64,
    /// Sensor rate at the start of the run, Hz.
    pub sensor_hz: f64,
    /// Actuator (plant) rate, Hz.
    pub actuator_hz: f64,
    /// History depth of both topics at the start of the run.
    pub queue_depth: usize,
    /// Reset seed.
    pub seed: u64,
    /// Requested duration, s.
    pub duration_s: f64,
    /// Actuator steps run.
    pub steps: u64,
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
    /// Messages published on `/obs`.
    pub obs_published: u64,
    /// `/obs` messages evicted unread.
    pub obs_dropped: u64,
    /// `/obs` messages per second of run time.
    pub obs_msg_per_s: f64,
    /// Messages published on `/action`.
    pub action_published: u64,
    /// `/action` messages evicted unread.
    pub action_dropped: u64,
    /// `/action` messages per second of run time.
    pub action_msg_per_s: f64,
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
}

/// One node's figures in `metrics.json`.
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
pub struct NodeMetrics {
    /// `sensor`, `estimator`, `policy`, `safety` or `actuator`.
    pub kind: String,
    /// Tie-break rank: at a shared instant, lower ticks first.
    pub rank: usize,
    /// Rate at the start of the run, Hz.
    pub rate_hz: f64,
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
}

/// One topic's figures in `metrics.json`.
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
pub struct TopicMetrics {
    /// `state`, `position` or `force`.
    #[serde(rename = "type")]
    pub msg: String,
    /// The publishing node.
    pub publisher: String,
    /// The subscribing node, if any.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub subscriber: Option<String>,
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
    /// The QoS counters it reports ([`crate::qos::QosCounter::reported`]): `expired`,
    /// `refused`, `lost`, `retransmitted`, `offered_deadline_missed`,
    /// `requested_deadline_missed`.
    #[serde(flatten)]
    pub qos_counters: BTreeMap<String, u64>,
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
        let one_policy = nodes.iter().filter(|(_, n)| n.kind == "policy").count() == 1;
        let mut parts: Vec<String> = nodes
            .iter()
            .map(|(name, n)| {
                let label = if one_policy && n.kind == "policy" {
                    "control"
                } else {
                    name.as_str()
                };
                format!("{label} {} Hz", n.rate_hz)
            })
            .collect();
        let topics = self.topics_by_publisher();
        let depth0 = topics.first().map_or(self.queue_depth, |(_, t)| t.depth);
        if topics.iter().all(|(_, t)| t.depth == depth0) {
            parts.push(format!("queue_depth {depth0}"));
        } else {
            let depths: Vec<String> = topics
                .iter()
                .map(|(name, t)| format!("{name} {}", t.depth))
                .collect();
            parts.push(format!("depths {}", depths.join(", ")));
        }
        parts.join(" | ")
    }

    /// `/obs 50.0 msg/s (0 dropped) | /action …`, topics in their publishers' rank order.
    fn topics_line(&self) -> String {
        self.topics_by_publisher()
            .iter()
            .map(|(name, t)| format!("{name} {:.1} msg/s ({} dropped)", t.msg_per_s, t.dropped))
            .collect::<Vec<_>>()
            .join(" | ")
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
                format!(
                    "{name} {}{}{}",
                    t.qos.as_deref().unwrap_or("KL latest"),
                    if counts.is_empty() { "" } else { ": " },
                    counts.join(", ")
                )
            })
            .collect();
        if !topics.is_empty() {
            lines.push(format!("qos: {}", topics.join(" | ")));
        }
        let mut nodes: Vec<(&String, &NodeMetrics)> = self
            .nodes
            .iter()
            .filter(|(_, n)| n.not_alive.is_some() || n.faulted_ticks.is_some())
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
                    if let Some(f) = n.faulted_ticks {
                        p.push_str(&format!(" {f} ticks lost to faults"));
                    }
                    p
                })
                .collect();
            lines.push(format!("liveliness: {}", parts.join(" | ")));
        }
        if let Some(w) = &self.stopped_by_watchdog {
            lines.push(format!("STOPPED BY WATCHDOG: {w}"));
        }
        lines
    }

    fn topics_by_publisher(&self) -> Vec<(&String, &TopicMetrics)> {
        let rank = |node: &str| self.nodes.get(node).map_or(usize::MAX, |n| n.rank);
        let mut topics: Vec<(&String, &TopicMetrics)> = self.topics.iter().collect();
        topics.sort_by_key(|(name, t)| (rank(&t.publisher), name.as_str()));
        topics
    }

    /// The chapter's human summary (five lines, no terminal codes). `wall_s` is the
    /// wall time the run took, when known (not part of the metrics: it varies run to run).
    pub fn summary_lines(&self, wall_s: Option<f64>) -> Vec<String> {
        let wall = wall_s.map_or_else(String::new, |w| format!(" ({w:.2}s wall)"));
        let verdict = match (&self.node_failed, self.fell_at_s) {
            (Some(failed), _) => format!(
                "NODE FAILED ({failed}) — {} control steps in {:.2}s sim{wall}",
                self.steps, self.sim_time_s
            ),
            (None, None) => format!(
                "BALANCED (pole up the whole run) — {} control steps in {:.2}s sim{wall}",
                self.steps, self.sim_time_s
            ),
            (None, Some(t)) => format!(
                "FELL at t={t:.2}s — {} control steps in {:.2}s sim{wall}",
                self.steps, self.sim_time_s
            ),
        };
        let mut lines = vec![
            format!("clock={}  policy={}", self.clock, self.policy),
            format!("rates: {}", self.rates_line()),
            verdict,
            format!("topics: {}", self.topics_line()),
            format!(
                "mean sense->act latency: {:.1} ms  (p50 {:.1} | p99 {:.1} | max {:.1} ms; control period {})",
                self.mean_latency_ms,
                self.latency_p50_ms,
                self.latency_p99_ms,
                self.latency_max_ms,
                crate::rate::period_for_hz(self.control_hz).map_or_else(|_| "?".into(), |p| p.to_string())
            ),
        ];
        lines.extend(self.qos_lines());
        if self.nonfinite_actions > 0 {
            lines.push(format!(
                "non-finite actions held over: {} (the actuator kept the last good action)",
                self.nonfinite_actions
            ));
        }
        if let Some(timing) = &self.node_timing {
            for t in timing {
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
        };
        log.push(base);
        log.push(StepRecord {
            step: 2,
            t: Nanos(20),
            fell: true,
            nonfinite: true,
            latency: Some(Nanos(5)),
            ..base
        });
        assert_eq!(log.steps, 2);
        assert_eq!(log.fell_at, Some(Nanos(20)));
        assert_eq!(log.nonfinite_actions, 1);
        assert_eq!(log.latency.count(), 1);
        assert_eq!(log.trace.len(), 2);
    }
}
