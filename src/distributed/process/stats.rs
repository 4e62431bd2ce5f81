//! A process's live figures: what it publishes every [`STATS_PERIOD`] ([`LiveStats`]),
//! whole for `ratelab lab --attach` and its counts alone for its launcher and `ratelab top`,
//! and the bounded batch of steps, ticks and counter samples its nodes fill between two
//! publications.

use super::{wire, DistError, GraphSpec, NodeId, Share, StepRecord, StopFlag, TopicId};
use std::sync::{Arc, Mutex};
use std::time::Duration;
use zenoh::Wait;

/// Live counters a process publishes: whole, with the batch, on `ratelab/<graph>/@stats/<p>`
/// for a watcher (`lab --attach`); its counts alone (no batch) on `…/@stats/<p>/counts` for
/// its launcher and `ratelab top`.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct LiveStats {
    /// The graph's name.
    pub graph: String,
    /// The process.
    pub process: String,
    /// Its OS process id.
    pub pid: u32,
    /// Run time of these figures, ns: every counter sample up to it is in this message or
    /// an earlier one (under the real clock, see `figures_time`).
    pub t_ns: u64,
    /// Its nodes: name, kind, rate Hz, ticks so far.
    pub nodes: Vec<(String, String, f64, u64)>,
    /// The topics whose counters it holds (it runs their subscriber, or their publisher when
    /// nobody subscribes): name and counters.
    pub topics: Vec<(String, ratelab_core::topic::TopicStats)>,
    /// Per inbound topic, its over-the-wire latency so far.
    pub wire: Vec<wire::WireLink>,
    /// The actuator's steps since the previous figures, oldest first (its process only; at
    /// most [`MAX_BATCH_STEPS`], the oldest dropped beyond): what `ratelab lab --attach`
    /// draws the plant, the latency and the topics' counters from.
    #[serde(default)]
    pub steps: Vec<StepRecord>,
    /// Real clock: each tick of its nodes since the previous figures, as (node index, run
    /// time ns, lateness ns, wall time the tick took ns), oldest first (at most
    /// [`MAX_BATCH_TICKS`]).
    #[serde(default)]
    pub ticks: Vec<(usize, u64, u64, u64)>,
    /// The counters of each topic it holds, sampled after each tick of its nodes when they
    /// differ from the previous sample: (run time ns, topic index, counters), oldest first,
    /// run times never decreasing (at most [`MAX_BATCH_COUNTERS`], the oldest dropped
    /// beyond). A watcher shows each actuator step with the counters
    /// its holder had at the step's run time, not at the figures' (under the virtual clock
    /// 100 ms of wall time is many seconds of run time).
    #[serde(default)]
    pub counters: Vec<(u64, usize, ratelab_core::topic::TopicStats)>,
    /// The process's part of the run is over: these are its last figures, and its
    /// liveliness tokens going next is a process leaving, not dying.
    #[serde(default)]
    pub done: bool,
    /// Set when this process joined a run already under way (started again mid-run, real
    /// clock): the run time its counts start from, ns. Its counters and ticks count from
    /// then; a watcher that heard the process before it carries that one's counts over
    /// ([`crate::monitor::Carried`]), one that did not says so.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub since_ns: Option<u64>,
}

/// How often each process publishes its [`LiveStats`].
pub const STATS_PERIOD: Duration = Duration::from_millis(100);

/// The most actuator steps one [`LiveStats`] carries (the virtual lockstep runs about a
/// thousand a second; a step is about 1 KB of JSON with a few topics).
pub const MAX_BATCH_STEPS: usize = 1000;

/// The most topic counters the steps of one [`LiveStats`] carry together (about 150 bytes
/// each as JSON, so 15 MB at most): a large graph's batch holds fewer steps than
/// [`MAX_BATCH_STEPS`], the newest.
pub const MAX_BATCH_STEP_COUNTERS: usize = 100_000;

/// The most node ticks one [`LiveStats`] carries.
pub const MAX_BATCH_TICKS: usize = 20_000;

/// The most counter samples one [`LiveStats`] carries (about 240 bytes each as JSON: a full
/// batch, with full steps and ticks, stays well under [`wire::MAX_CONTROL_BYTES`]).
pub const MAX_BATCH_COUNTERS: usize = 8_000;

impl LiveStats {
    /// Decode figures from the network, refusing any over the bounds a process keeps
    /// ([`MAX_BATCH_STEPS`], [`MAX_BATCH_TICKS`], a graph's most nodes and topics).
    ///
    /// # Errors
    /// One line.
    pub fn decode(bytes: &[u8]) -> Result<LiveStats, String> {
        let m: LiveStats = wire::decode_json(bytes)?;
        let bounded = m.steps.len() <= MAX_BATCH_STEPS
            && m.steps.iter().map(|s| s.topics.len()).sum::<usize>() <= MAX_BATCH_STEP_COUNTERS
            && m.ticks.len() <= MAX_BATCH_TICKS
            && m.counters.len() <= MAX_BATCH_COUNTERS
            && m.counters
                .iter()
                .all(|c| c.1 < ratelab_core::ids::MAX_TOPICS)
            && m.nodes.len() <= ratelab_core::ids::MAX_NODES
            && m.topics.len() <= ratelab_core::ids::MAX_TOPICS
            && m.wire.len() <= ratelab_core::ids::MAX_TOPICS;
        if bounded {
            Ok(m)
        } else {
            Err("figures over a process's bounds".into())
        }
    }

    /// A process's figures from a sample on its stats key ([`super::Keys::stats`], or
    /// [`super::Keys::stats_counts`]), as [`LiveStats::decode`] takes them; `None` as well
    /// when they name another process than the key's (a process's figures count only from
    /// its own key).
    pub fn from_sample(sample: &zenoh::sample::Sample) -> Option<LiveStats> {
        let from = stats_key_process(sample.key_expr().as_str());
        LiveStats::decode(&sample.payload().to_bytes())
            .ok()
            .filter(|m| m.process == from)
    }
}

/// The process a key of figures names: `…/@stats/<p>` or `…/@stats/<p>/counts` (names of
/// processes are letters, digits, `_` and `-`, so neither holds a `/` or an `@`); `""` for
/// a key of neither shape.
fn stats_key_process(key: &str) -> &str {
    let mut chunks = key.rsplit('/');
    match (chunks.next(), chunks.next(), chunks.next()) {
        (Some("counts"), Some(p), Some("@stats")) => p,
        (Some(p), Some("@stats"), _) => p,
        _ => "",
    }
}

/// What happened since the stats thread last published: steps and ticks, bounded.
#[derive(Default)]
pub(super) struct Batch {
    steps: std::collections::VecDeque<StepRecord>,
    ticks: std::collections::VecDeque<(usize, u64, u64, u64)>,
    counters: std::collections::VecDeque<(u64, usize, ratelab_core::topic::TopicStats)>,
    /// Each topic's counters as last sampled (a sample is kept only when they changed).
    last: Vec<Option<ratelab_core::topic::TopicStats>>,
    /// The run time of the newest sample, ns (samples never go back in time).
    last_t: u64,
}

impl Batch {
    fn push_step(&mut self, s: StepRecord) {
        // Steps of one graph carry as many counters each.
        let room = MAX_BATCH_STEPS.min(MAX_BATCH_STEP_COUNTERS / s.topics.len().max(1));
        while self.steps.len() >= room.max(1) {
            self.steps.pop_front();
        }
        self.steps.push_back(s);
    }
    pub(super) fn push_tick(&mut self, t: (usize, u64, u64, u64)) {
        if self.ticks.len() == MAX_BATCH_TICKS {
            self.ticks.pop_front();
        }
        self.ticks.push_back(t);
    }
    /// Keep the counters `read` of the topics this process holds at run time `t_ns` (after
    /// a tick of one of its nodes), those that changed. Node threads may come out of order:
    /// a sample is never older than the one before.
    pub(super) fn keep(&mut self, t_ns: u64, read: &[(TopicId, ratelab_core::topic::TopicStats)]) {
        self.last_t = self.last_t.max(t_ns);
        for &(t, st) in read {
            if self.last.len() <= t.0 {
                self.last.resize(t.0 + 1, None);
            }
            if self.last[t.0] == Some(st) {
                continue;
            }
            self.last[t.0] = Some(st);
            if self.counters.len() == MAX_BATCH_COUNTERS {
                self.counters.pop_front();
            }
            self.counters.push_back((self.last_t, t.0, st));
        }
    }
}

/// Read the counters of `held` (before taking the batch's lock: each read locks its topic).
pub(super) fn read_counters(
    held: &[TopicId],
    handles: &ratelab_runtime::graph::GraphHandles,
) -> Vec<(TopicId, ratelab_core::topic::TopicStats)> {
    held.iter()
        .map(|&t| (t, handles.topic(t).stats()))
        .collect()
}

/// The topics whose counters process `mine` holds (their [`TopicSpec::holder`] runs in
/// it): those it subscribes to, and those it publishes that nobody subscribes to (as
/// [`LiveStats::topics`]).
///
/// [`TopicSpec::holder`]: ratelab_runtime::graph::spec::TopicSpec::holder
pub(super) fn held_topics(spec: &GraphSpec, mine: &[NodeId]) -> Vec<TopicId> {
    (0..spec.topics.len())
        .map(TopicId)
        .filter(|&t| mine.contains(&spec.topic(t).holder()))
        .collect()
}

/// Hands every actuator step to the stats thread.
pub(super) struct StepTap(pub(super) Arc<Mutex<Batch>>);

impl ratelab_runtime::graph::StepObserver for StepTap {
    fn on_step(&mut self, rec: &StepRecord) {
        ratelab_runtime::graph::lock(&self.0).push_step(rec.clone());
    }
}

/// A process's two publishers of its figures ([`super::stats_publishers`]).
pub(super) struct Figures {
    /// Whole, batch included ([`super::Keys::stats`]): for watchers.
    pub(super) whole: zenoh::pubsub::Publisher<'static>,
    /// Its counts alone ([`super::Keys::stats_counts`]): for the launcher and `ratelab top`.
    pub(super) counts: zenoh::pubsub::Publisher<'static>,
}

/// Whether anyone subscribes to what `publisher` puts (Zenoh's matching status, from the
/// subscriptions declared to this session: a put is routed by the same). When the status
/// cannot be had, yes: figures are sent rather than lost.
fn heard(publisher: &zenoh::pubsub::Publisher<'_>) -> bool {
    publisher
        .matching_status()
        .wait()
        .map_or(true, |m| m.matching())
}

/// Start the thread that puts this process's figures ([`LiveStats`]) every
/// [`STATS_PERIOD`], and once more after `done` (the run's last steps): whole on
/// `figures.whole` while a watcher listens (`ratelab lab --attach`, the launch's own lab or
/// recording), its counts alone on `figures.counts` while its launcher or `ratelab top`
/// does. The batch is taken every period either way (it is bounded), but only encoded for
/// a watcher: under the virtual clock a period's batch is a thousand steps or counter
/// samples, hundreds of KB of JSON, whose encoding cost the chapter's launch nobody
/// watched about 2% of its CPU (BENCHMARKS.md, issue 76 item 4).
///
/// # Errors
/// [`DistError::Peer`] when the thread cannot start.
pub(super) fn spawn_figures(
    share: Arc<Share>,
    figures: Figures,
    done: StopFlag,
) -> Result<std::thread::JoinHandle<()>, DistError> {
    std::thread::Builder::new()
        .name("stats".into())
        .spawn(move || loop {
            let last = done.is_stopped();
            let mut msg = share.live_stats();
            msg.done = last;
            let (steps, ticks, counters) = {
                let mut b = ratelab_runtime::graph::lock(&share.batch);
                let b = &mut *b;
                (
                    std::mem::take(&mut b.steps),
                    std::mem::take(&mut b.ticks),
                    std::mem::take(&mut b.counters),
                )
            };
            if heard(&figures.counts) {
                let _ = figures.counts.put(wire::encode_json(&msg)).wait();
            }
            if heard(&figures.whole) {
                msg.steps = steps.into();
                msg.ticks = ticks.into();
                msg.counters = counters.into();
                let _ = figures.whole.put(wire::encode_json(&msg)).wait();
            }
            if last {
                break;
            }
            std::thread::sleep(STATS_PERIOD);
        })
        .map_err(|e| DistError::Peer(format!("cannot start a thread: {e}")))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_key_of_figures_names_its_process_whole_or_counts_alone() {
        let keys = super::super::Keys::new("cartpole");
        for p in ["robot", "policy", "counts", "a-b_2"] {
            assert_eq!(stats_key_process(&keys.stats(p)), p);
            assert_eq!(stats_key_process(&keys.stats_counts(p)), p);
        }
        for other in [
            "",
            "counts",
            "ratelab/cartpole/@ticked/robot",
            "x/robot/counts",
        ] {
            assert_eq!(stats_key_process(other), "", "{other}");
        }
    }
}
