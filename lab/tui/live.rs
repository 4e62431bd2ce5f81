//! What the lab's live numbers count over, so that they mean what they say after the
//! settings change mid-run:
//!
//! - the **window**: the last [`WINDOW`] (5 s) of run time, "what is happening now" — msg/s,
//!   drops and stale reads per topic, and the latency percentiles. It never reaches back
//!   across a change of settings: right after one it is shorter, and says so.
//! - the **segment**: everything since the last change of rate, depth or brain (or since the
//!   run started) — per-topic totals and the latency histogram. Each change starts a new
//!   segment and leaves a mark for the angle chart.
//!
//! Both are computed from every topic's cumulative counters ([`Counts`]), which come with
//! each of the actuator's [`StepRecord`]s and with each of the engine's status messages (so
//! they stay current while the actuator is stalled or dead): a window or a segment is the
//! difference between two of them. Latency comes from the step records alone. Memory is
//! bounded: the window keeps at most one record per actuator tick and one count per status
//! over [`WINDOW`] (a 50 Hz actuator and a status every 33 ms: about 400; never more than
//! [`MAX_WINDOW_RECORDS`] of either), the segment's latency at most
//! [`ratelab::metrics::MAX_EXACT_SAMPLES`] samples, the marks at most [`MAX_MARKS`] over the
//! last [`MARK_HISTORY`].

use ratelab::graph::TopicId;
use ratelab::metrics::ExactLatency;
use ratelab::runlog::{StepRecord, TopicCounters};
use ratelab::topic::TopicStats;
use ratelab::Nanos;
use std::collections::VecDeque;

/// The window: the last 5 s of run time.
pub const WINDOW: Nanos = Nanos(5 * Nanos::SECOND.0);
/// Records (and counts) the window keeps at most, whatever arrives (the 50 Hz actuator
/// sends 251 in [`WINDOW`], the engine's status about 150).
pub const MAX_WINDOW_RECORDS: usize = 1024;
/// How far back segment marks are kept (the charts' widest window short of the whole run,
/// [`super::chart_window::FULL_RATE_S`]).
pub const MARK_HISTORY: Nanos = Nanos(60 * Nanos::SECOND.0);
/// Segment marks kept at most.
pub const MAX_MARKS: usize = 256;

/// One topic's figures over the window or the segment.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct TopicCounts {
    /// Messages published.
    pub published: u64,
    /// Messages dropped (evicted unread).
    pub dropped: u64,
    /// Reads that found nothing new.
    pub stale_reads: u64,
    /// Messages its link lost (a lossy best-effort link, or a crossing topic's sequence
    /// gaps: QoS counter `lost`).
    pub lost: u64,
    /// Unread messages that outlived the topic's lifespan (QoS counter `expired`).
    pub expired: u64,
    /// Messages per second: the messages published over the span of their publish stamps
    /// (so a 5 Hz topic reads 5.0), the span reaching to now once the publisher has been
    /// silent for more than twice its mean interval (a stalled or dead publisher's rate
    /// falls to 0 instead of holding its last value); 0 with fewer than two stamps to span.
    pub msg_per_s: f64,
}

impl TopicCounts {
    /// The counts between two snapshots of one topic: `base` (zeros when `None`: the run's
    /// start) and `last`, taken at run time `now`. The messages published between them span
    /// exactly `(base.last_stamp, last.last_stamp]`: msg/s is their count over that span,
    /// or over `(base.last_stamp, now]` when the publisher has been silent since for more
    /// than twice their mean interval.
    pub fn between(base: Option<TopicStats>, last: TopicStats, now: Nanos) -> Self {
        let base = base.unwrap_or_default();
        let published = last.published.saturating_sub(base.published);
        let mut span = last.last_stamp.saturating_sub(base.last_stamp);
        let silence = now.saturating_sub(last.last_stamp);
        if published > 0 && silence.0 > 2 * (span.0 / published) {
            span = now.saturating_sub(base.last_stamp);
        }
        Self {
            published,
            dropped: last.dropped.saturating_sub(base.dropped),
            stale_reads: last.stale_reads.saturating_sub(base.stale_reads),
            lost: last.lost.saturating_sub(base.lost),
            expired: last.expired.saturating_sub(base.expired),
            msg_per_s: if span.0 > 0 && base.published > 0 {
                // Both integers, so an exact rate divides exactly (249 in 4.98 s is 50.0).
                published as f64 * Nanos::SECOND.0 as f64 / span.0 as f64
            } else {
                0.0
            },
        }
    }
}

/// p50, p99 and max of `samples`, ns, by nearest rank (the sample at rank `⌈q·n⌉`), as
/// [`ExactLatency`] ranks them; `None` when empty. Sorts `samples`.
pub fn order_stats(samples: &mut [u64]) -> Option<(Nanos, Nanos, Nanos)> {
    let n = samples.len();
    if n == 0 {
        return None;
    }
    samples.sort_unstable();
    let at = |q: f64| Nanos(samples[((q * n as f64).ceil() as usize).clamp(1, n) - 1]);
    Some((at(0.5), at(0.99), Nanos(samples[n - 1])))
}

/// Every topic's cumulative counters at one run time: from an actuator's [`StepRecord`], or
/// from the engine's status (which comes while the actuator is stalled or dead too).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Counts {
    /// Run time they were read.
    pub t: Nanos,
    /// Each topic's counters, by [`TopicId`].
    pub topics: TopicCounters,
}

/// The segment since the last change of settings.
#[derive(Clone, Debug, Default)]
pub struct Segment {
    /// 1 for the run's start, then one more per change.
    pub index: u32,
    /// Run time it started.
    pub start: Nanos,
    /// What started it (`None`: the run's start).
    pub cause: Option<String>,
    /// The newest counters from before `start` (`None`: the segment starts with the run).
    baseline: Option<Counts>,
    /// Sense→act latency of the steps since `start`.
    pub latency: ExactLatency,
    /// Run time of the first step it holds (a lab attached mid-run sees none before).
    pub first_step: Option<Nanos>,
    /// Steps since `start` that applied no command after the run's first one (a deadline's
    /// `zero` reaction): they have no sense→act latency, so the histogram does not hold them.
    pub no_command: u64,
}

impl Segment {
    /// When the lab saw the run's first segment's first step over a second after its start
    /// (attached mid-run), that step's run time: the latency counts from there.
    pub fn joined(&self) -> Option<Nanos> {
        self.first_step
            .filter(|t| self.cause.is_none() && *t > self.start + Nanos::SECOND)
    }
}

/// The lab's window and segment, fed with every step record, every status's counters and
/// every change.
#[derive(Clone, Debug)]
pub struct Live {
    /// Step records over the window, oldest first (their latencies).
    window: VecDeque<StepRecord>,
    /// Counters over the window, oldest first; the oldest may be from just before the
    /// window (the window's baseline).
    counts: VecDeque<Counts>,
    segment: Segment,
    /// Run times of the changes over the last [`MARK_HISTORY`].
    marks: VecDeque<Nanos>,
    /// The newest counters, from a step or a status.
    newest: Option<Counts>,
    /// Run time of the first step that applied a command (the steps before it have no
    /// latency either, and are not "no command").
    first_command: Option<Nanos>,
}

impl Default for Live {
    fn default() -> Self {
        Self {
            window: VecDeque::new(),
            counts: VecDeque::new(),
            segment: Segment {
                index: 1,
                ..Segment::default()
            },
            marks: VecDeque::new(),
            newest: None,
            first_command: None,
        }
    }
}

/// Drop the front of `q` while its second entry is at or before `now − WINDOW` (so one
/// entry at or before the window's start stays: its baseline) or `q` holds more than
/// [`MAX_WINDOW_RECORDS`].
fn trim<T>(q: &mut VecDeque<T>, at: impl Fn(&T) -> Nanos, now: Nanos) {
    while q.len() > MAX_WINDOW_RECORDS
        || q.get(1)
            .is_some_and(|r| at(r) <= now.saturating_sub(WINDOW) && now >= WINDOW)
    {
        q.pop_front();
    }
}

impl Live {
    /// How many step records it holds (the window's).
    pub fn records(&self) -> usize {
        self.window.len()
    }

    /// Account one actuator step.
    pub fn push(&mut self, s: StepRecord) {
        if s.t >= self.segment.start {
            let first = self.segment.first_step.get_or_insert(s.t);
            *first = (*first).min(s.t);
            match s.latency {
                Some(l) => self.segment.latency.record(l),
                None if self.applied_no_command(&s) => self.segment.no_command += 1,
                None => {}
            }
        }
        if s.latency.is_some() {
            self.first_command = Some(self.first_command.map_or(s.t, |f| f.min(s.t)));
        }
        let counts = Counts {
            t: s.t,
            topics: s.topics.clone(),
        };
        self.window.push_back(s);
        self.counters(counts);
    }

    /// Account every topic's counters at a run time: a step's, or the engine's status's
    /// (which keeps the counts current while the actuator sends no step).
    pub fn counters(&mut self, c: Counts) {
        if c.t < self.segment.start {
            // Taken before the change but received after it (the real clock's threads):
            // the baseline, not the segment.
            if self.segment.baseline.as_ref().is_none_or(|b| b.t <= c.t) {
                self.segment.baseline = Some(c.clone());
            }
        }
        // A status repeats its instant while paused or frozen: the newest counters of an
        // instant stand for it.
        if self.newest.as_ref().is_none_or(|n| n.t <= c.t) {
            self.newest = Some(c.clone());
        }
        match self.counts.back_mut() {
            Some(back) if back.t == c.t => *back = c,
            _ => self.counts.push_back(c),
        }
        let now = self.now();
        trim(&mut self.counts, |c| c.t, now);
        trim(&mut self.window, |r| r.t, now);
        while self
            .marks
            .front()
            .is_some_and(|m| now.saturating_sub(*m) > MARK_HISTORY)
        {
            self.marks.pop_front();
        }
    }

    /// The newest run time accounted.
    fn now(&self) -> Nanos {
        self.newest.as_ref().map_or(Nanos::ZERO, |n| n.t)
    }

    /// A change of settings took effect at run time `at`: a new segment starts there.
    pub fn change(&mut self, at: Nanos, cause: String) {
        let baseline = self
            .counts
            .iter()
            .filter(|c| c.t < at)
            .max_by_key(|c| c.t)
            .cloned()
            .or_else(|| self.segment.baseline.clone().filter(|b| b.t < at));
        // Steps from at or after the change that arrived before it (real clock) belong here.
        let latency = self
            .window
            .iter()
            .filter(|r| r.t >= at)
            .filter_map(|r| r.latency)
            .collect();
        let first_step = self.window.iter().filter(|r| r.t >= at).map(|r| r.t).min();
        let no_command = self
            .window
            .iter()
            .filter(|r| r.t >= at && self.applied_no_command(r))
            .count() as u64;
        self.segment = Segment {
            index: self.segment.index + 1,
            start: at,
            cause: Some(cause),
            baseline,
            latency,
            first_step,
            no_command,
        };
        self.marks.push_back(at);
        while self.marks.len() > MAX_MARKS {
            self.marks.pop_front();
        }
    }

    /// The current segment.
    pub fn segment(&self) -> &Segment {
        &self.segment
    }

    /// The window's baseline, the counters the window counts from (its events are after
    /// them): the segment's baseline when the last change is within the window (so the
    /// window never mixes two settings), else the counters from just before the window;
    /// `None` when the window reaches back to the run's start (it counts from zero).
    fn window_base(&self) -> Option<&Counts> {
        let front = self.counts.front()?;
        match &self.segment.baseline {
            Some(b) if b.t >= front.t => Some(b),
            None if self.now() < WINDOW => None,
            _ => Some(front),
        }
    }

    /// The window's span, and whether it is the whole [`WINDOW`] (false right after the
    /// run's start or a change: the window is shorter then).
    pub fn window_span(&self) -> (Nanos, bool) {
        if self.newest.is_none() {
            return (Nanos::ZERO, false);
        }
        let from = self.window_base().map_or(self.segment.start, |b| b.t);
        let span = self.now().saturating_sub(from);
        (span.min(WINDOW), span >= WINDOW)
    }

    /// The latency window's span: as [`Live::window_span`], but from the first step a lab
    /// saw when it joined a run well after its start (attached mid-run: it holds no step
    /// from before; the counters it holds count from the run's start).
    pub fn latency_span(&self) -> (Nanos, bool) {
        let (span, full) = self.window_span();
        match self.segment.joined() {
            Some(j) if !full => {
                let from = self.window_base().map_or(self.segment.start, |b| b.t);
                (self.now().saturating_sub(from.max(j)), false)
            }
            _ => (span, full),
        }
    }

    /// Topic `id` over the window. msg/s is the count over the span between the first and
    /// the last publish stamp in the window: from the first counters that hold a message
    /// published in the window (its newest stamp), so a gap before the window (a change from
    /// a slower rate) does not dilute it. A topic with one message in a whole window (slower
    /// than one per [`WINDOW`] / 2, 0.4 Hz) has no span: its rate is that message over the
    /// window (0.2/s), not a 0.0 that says nothing was published.
    pub fn window_topic(&self, id: TopicId) -> TopicCounts {
        let Some(newest) = &self.newest else {
            return TopicCounts::default();
        };
        let last = newest.topics.get(id);
        let base = self.window_base();
        let counts = TopicCounts::between(base.map(|b| b.topics.get(id)), last, newest.t);
        let before = base.map_or(0, |b| b.topics.get(id).published);
        let first = self
            .counts
            .iter()
            .filter(|c| base.is_none_or(|b| c.t > b.t))
            .map(|c| c.topics.get(id))
            .find(|s| s.published > before);
        let mut msg_per_s = first.map_or(0.0, |f| {
            TopicCounts::between(Some(f), last, newest.t).msg_per_s
        });
        if msg_per_s == 0.0 && counts.published > 0 && self.window_span().1 {
            msg_per_s = counts.published as f64 / WINDOW.as_secs_f64();
        }
        TopicCounts {
            msg_per_s,
            ..counts
        }
    }

    /// Topic `id`'s QoS counter `c` over the window (what it counted since the window's
    /// baseline), as its drops and stale reads are.
    pub fn window_counter(&self, id: TopicId, c: ratelab::qos::QosCounter) -> u64 {
        let Some(newest) = &self.newest else { return 0 };
        let base = self
            .window_base()
            .map_or(0, |b| b.topics.get(id).counter(c));
        newest.topics.get(id).counter(c).saturating_sub(base)
    }

    /// Topic `id` since the segment started.
    pub fn segment_topic(&self, id: TopicId) -> TopicCounts {
        match &self.newest {
            Some(n) => TopicCounts::between(
                self.segment.baseline.as_ref().map(|b| b.topics.get(id)),
                n.topics.get(id),
                n.t,
            ),
            None => TopicCounts::default(),
        }
    }

    /// Steps over the window that applied no command after the run's first one (as
    /// [`Segment::no_command`] counts them): beside the window's latency samples.
    pub fn window_no_command(&self) -> u64 {
        let after = self.window_base().map(|b| b.t);
        self.window
            .iter()
            .filter(|r| after.is_none_or(|a| r.t > a) && r.t >= self.segment.start)
            .filter(|r| self.applied_no_command(r))
            .count() as u64
    }

    /// Step `r` applied no command after the run's first one (a deadline's `zero`
    /// reaction): it has no sense→act latency (the steps before the first command have none
    /// either, and are not counted).
    fn applied_no_command(&self, r: &StepRecord) -> bool {
        r.latency.is_none() && self.first_command.is_some_and(|f| f < r.t)
    }

    /// Sense→act latency over the window: (samples, p50/p99/max).
    pub fn window_latency(&self) -> (usize, Option<(Nanos, Nanos, Nanos)>) {
        let after = self.window_base().map(|b| b.t);
        let mut samples: Vec<u64> = self
            .window
            .iter()
            .filter(|r| after.is_none_or(|a| r.t > a))
            .filter_map(|r| r.latency.map(|l| l.0))
            .collect();
        (samples.len(), order_stats(&mut samples))
    }

    /// Run times of the changes over the last [`MARK_HISTORY`], oldest first.
    pub fn marks(&self) -> impl Iterator<Item = Nanos> + '_ {
        self.marks.iter().copied()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use ratelab::runlog::TopicCounters;

    const MS: u64 = 1_000_000;

    /// A 50 Hz actuator's record at `t_ms` for one topic published at `hz` from t = 0 (so
    /// `published` and `last_stamp` are what a 5 Hz publisher leaves), with `dropped` and
    /// `stale` so far and a latency of `lat_ms`.
    fn rec(t_ms: u64, hz: u64, dropped: u64, stale: u64, lat_ms: u64) -> StepRecord {
        let period = 1000 / hz;
        let topic = TopicStats {
            published: t_ms / period + 1,
            dropped,
            stale_reads: stale,
            last_stamp: Nanos(t_ms / period * period * MS),
            depth: 1,
            ..TopicStats::default()
        };
        StepRecord {
            step: t_ms / 20 + 1,
            t: Nanos(t_ms * MS),
            pole_angle: 0.0,
            pole_angvel: 0.0,
            cart_pos: 0.0,
            action: 0.0,
            latency: Some(Nanos(lat_ms * MS)),
            held_stamp: None,
            nonfinite: false,
            topics: TopicCounters::from_iter([topic]),
            published: None,
            fell: false,
            estimate: None,
        }
    }

    const T: TopicId = TopicId(0);

    #[test]
    fn steps_that_applied_no_command_are_counted_beside_the_latency() {
        let mut live = Live::default();
        let at = |live: &mut Live, t: u64, latency: Option<u64>| {
            let mut r = rec(t, 50, 0, 0, 0);
            r.latency = latency.map(|l| Nanos(l * MS));
            live.push(r);
        };
        // Before the first command: no latency, and not "no command" either.
        at(&mut live, 0, None);
        at(&mut live, 20, Some(0));
        // A deadline's zero reaction: two steps with no command.
        at(&mut live, 40, None);
        at(&mut live, 60, None);
        at(&mut live, 80, Some(0));
        assert_eq!(live.segment().latency.count(), 2);
        assert_eq!(live.segment().no_command, 2);
        assert_eq!((live.window_latency().0, live.window_no_command()), (2, 2));
        // A change starts a segment: it counts its own (one, at 100 ms).
        live.change(Nanos(90 * MS), "x".into());
        at(&mut live, 100, None);
        assert_eq!(live.segment().no_command, 1);
    }

    #[test]
    fn a_publisher_that_stops_reads_less_and_then_0_msg_per_s() {
        let mut live = Live::default();
        // 50 Hz until 1 s, then silent (a stalled or killed publisher).
        for t in (0..=8_000).step_by(20) {
            let mut r = rec(t.min(1_000), 50, 0, 0, 0);
            r.t = Nanos(t * MS);
            r.step = t / 20 + 1;
            live.push(r);
            let hz = live.window_topic(T).msg_per_s;
            match t {
                // Publishing: exact, even between its stamps.
                1_000 => assert_eq!(hz, 50.0),
                // Silent for 1 s of a 2 s window: about half, never the old 50.
                2_000 => assert!((20.0..30.0).contains(&hz), "{hz}"),
                // The window no longer holds a message.
                7_000.. => assert_eq!(hz, 0.0),
                _ => {}
            }
        }
    }

    #[test]
    fn a_topic_with_one_message_in_a_whole_window_reads_it_over_the_window() {
        let mut live = Live::default();
        // One message every 4 s (0.25 Hz), from t = 0.
        for t in (0..=12_000).step_by(20) {
            let mut r = rec(t, 50, 0, 0, 0);
            r.topics = TopicCounters::from_iter([TopicStats {
                published: t / 4_000 + 1,
                last_stamp: Nanos(t / 4_000 * 4_000 * MS),
                depth: 1,
                ..TopicStats::default()
            }]);
            live.push(r);
            let w = live.window_topic(T);
            match t {
                // Two in the window (8 s and 12 s): the span between them, 0.25/s.
                12_000 => assert_eq!((w.published, w.msg_per_s), (2, 0.25)),
                // Only the message at 4 s since 2.98 s, a whole window: 1 in 5 s.
                7_980 => assert_eq!((w.published, w.msg_per_s), (1, 0.2)),
                // Younger than the window, one message: not known yet (the lab's
                // `measuring`), not 0.2.
                3_000 => assert_eq!((w.published, w.msg_per_s), (1, 0.0)),
                _ => {}
            }
        }
    }

    #[test]
    fn a_5_hz_topic_reads_5_msg_per_s_over_the_window() {
        let mut live = Live::default();
        for t in (0..=12_000).step_by(20) {
            live.push(rec(t, 5, 0, 0, 0));
            if t == 2_000 {
                // Younger than the window: from the start, and labelled with its span.
                assert_eq!(live.window_span(), (Nanos(2_000 * MS), false));
                assert_eq!(live.window_topic(T).msg_per_s, 5.0);
            }
        }
        let w = live.window_topic(T);
        assert_eq!((w.msg_per_s, w.published), (5.0, 25));
        assert_eq!(live.window_span(), (WINDOW, true));
        // One record per actuator tick over 5 s, and the one before: bounded.
        assert_eq!(live.window.len(), 251);
        // The segment (no change yet) is the whole run: 61 messages at t = 0, 0.2, …, 12 s.
        assert_eq!(live.segment_topic(T).published, 61);
    }

    #[test]
    fn counts_stay_current_while_the_actuator_sends_no_step() {
        let mut live = Live::default();
        // The actuator steps until 1 s, then stalls; the engine's status keeps counting:
        // the topic published on at 50 Hz, and every message from 1 s on was dropped.
        for t in (0..=1_000).step_by(20) {
            live.push(rec(t, 50, 0, 0, 0));
        }
        for t in (1_020..=3_000).step_by(33) {
            let r = rec(t, 50, (t - 1_000) / 20, 0, 0);
            live.counters(Counts {
                t: r.t,
                topics: r.topics,
            });
        }
        let w = live.window_topic(T);
        assert_eq!((w.dropped, w.published), (100, 151), "{w:?}");
        assert_eq!(w.msg_per_s, 50.0);
        assert_eq!(live.window_span(), (Nanos(3_000 * MS), false));
        // The latency window holds the steps only: 51 of them.
        assert_eq!(live.window_latency().0, 51);
        // A frozen run repeats its last status: the window stays as it was.
        let (t, topics) = (Nanos(3_000 * MS), live.newest.clone().unwrap().topics);
        for _ in 0..5_000 {
            live.counters(Counts {
                t,
                topics: topics.clone(),
            });
        }
        assert_eq!(live.window_topic(T), w);
        assert!(live.counts.len() < 200, "{}", live.counts.len());
    }

    #[test]
    fn a_lab_that_joined_mid_run_spans_its_latency_from_its_first_step() {
        // Attached at 1.6 s: the counters count from the run's start, the latency from 1.6 s.
        let mut live = Live::default();
        for t in (1_600..=3_600).step_by(20) {
            live.push(rec(t, 50, 0, 0, 0));
        }
        assert_eq!(live.window_span(), (Nanos(3_600 * MS), false));
        assert_eq!(live.latency_span(), (Nanos(2_000 * MS), false));
        assert_eq!(live.window_latency().0, 101);
        // Once the window is whole, both are its 5 s.
        for t in (3_620..=9_000).step_by(20) {
            live.push(rec(t, 50, 0, 0, 0));
        }
        assert_eq!(live.latency_span(), (WINDOW, true));
        // A run the lab saw from its start: the same span for both.
        let mut live = Live::default();
        for t in (0..=2_000).step_by(20) {
            live.push(rec(t, 50, 0, 0, 0));
        }
        assert_eq!(live.latency_span(), live.window_span());
    }

    #[test]
    fn drops_count_within_the_window_only() {
        let mut live = Live::default();
        let mut dropped = 0;
        for t in (0..=12_000).step_by(20) {
            if (1_000..2_000).contains(&t) && t % 100 == 0 {
                dropped += 1; // ten drops between 1 s and 2 s
            }
            live.push(rec(t, 50, dropped, 0, 0));
            if t == 4_000 {
                assert_eq!(live.window_topic(T).dropped, 10, "within the last 5 s");
            }
            if t == 6_900 {
                // The window is (1.9 s, 6.9 s]: none of the drops is in it.
                assert_eq!(live.window_topic(T).dropped, 0);
            }
        }
        assert_eq!(
            live.window_topic(T).dropped,
            0,
            "nothing dropped in the last 5 s"
        );
        assert_eq!(live.segment_topic(T).dropped, 10, "the totals keep them");
    }

    #[test]
    fn a_links_losses_total_over_the_segment() {
        let mut live = Live::default();
        let mut lost = 0;
        for t in (0..=8_000).step_by(20) {
            if t % 1_000 == 0 && t > 0 {
                lost += 1; // one lost a second
            }
            let mut r = rec(t, 50, 0, 0, 0);
            r.topics = TopicCounters::from_iter([TopicStats {
                lost,
                ..r.topics.get(T)
            }]);
            live.push(r);
        }
        assert_eq!(live.segment_topic(T).lost, 8);
        assert_eq!(live.window_counter(T, ratelab::qos::QosCounter::Lost), 5);
    }

    #[test]
    fn a_change_starts_a_segment_and_the_window_never_crosses_it() {
        let mut live = Live::default();
        let mut stale = 0;
        for t in (0..=6_000).step_by(20) {
            stale += 1;
            live.push(rec(t, 50, t / 100, stale, 40));
        }
        assert_eq!(live.segment_topic(T).dropped, 60);
        assert_eq!(live.segment().latency.count(), 301);
        // The change takes effect before the tick at 6.02 s.
        live.change(Nanos(6_020 * MS), "control rate → 5 Hz".into());
        assert_eq!(live.segment().index, 2);
        assert_eq!(
            live.segment_topic(T),
            TopicCounts::default(),
            "totals restart"
        );
        assert_eq!(live.segment().latency.count(), 0);
        for t in (6_020..=7_000).step_by(20) {
            stale += 1;
            live.push(rec(t, 50, 60, stale, 180));
        }
        let seg = live.segment_topic(T);
        assert_eq!((seg.dropped, seg.stale_reads, seg.published), (0, 50, 50));
        // The window counts from the last step before the change (6.00 s), not over the
        // last 5 s across it.
        assert_eq!(live.window_span(), (Nanos(1_000 * MS), false));
        let w = live.window_topic(T);
        assert_eq!((w.dropped, w.stale_reads, w.msg_per_s), (0, 50, 50.0));
        // Latency since the change only: exactly 180 ms.
        assert_eq!(live.window_latency().0, 50);
        assert_eq!(
            live.window_latency().1,
            Some((Nanos(180 * MS), Nanos(180 * MS), Nanos(180 * MS)))
        );
        assert_eq!(live.segment().latency.summary_ms(), (180.0, 180.0, 180.0));
        assert_eq!(live.marks().collect::<Vec<_>>(), [Nanos(6_020 * MS)]);
        // 5 s after the change the window is whole again, and still after the change.
        for t in (7_020..=12_000).step_by(20) {
            live.push(rec(t, 50, 60, stale, 180));
        }
        assert_eq!(live.window_span(), (WINDOW, true));
        assert_eq!(live.window_topic(T).stale_reads, 0);
        // Marks older than the charts' widest window short of the whole run (60 s) go.
        for t in (12_020..=66_100).step_by(20) {
            live.push(rec(t, 50, 60, stale, 180));
        }
        assert_eq!(live.marks().count(), 0);
    }

    #[test]
    fn a_step_from_before_a_change_arriving_after_it_is_the_baseline() {
        // Real clock: the engine applies the change at 1.01 s; the actuator's step of 1.00 s
        // is still on its way. It belongs to the old segment.
        let mut live = Live::default();
        for t in (0..=980).step_by(20) {
            live.push(rec(t, 50, t / 200, 0, 0));
        }
        live.change(Nanos(1_010 * MS), "queue depth → 5".into());
        live.push(rec(1_000, 50, 5, 0, 0));
        live.push(rec(1_020, 50, 5, 0, 20));
        let seg = live.segment_topic(T);
        assert_eq!((seg.published, seg.dropped), (1, 0));
        assert_eq!(live.segment().latency.count(), 1);
    }

    #[test]
    fn window_order_statistics_rank_as_the_exact_latency_does() {
        let mut samples: Vec<u64> = (0..43).map(|i| 20 * MS * (i % 10)).collect();
        let exact: ExactLatency = samples.iter().map(|&v| Nanos(v)).collect();
        assert_eq!(
            order_stats(&mut samples),
            Some((
                exact.quantile(0.5).unwrap(),
                exact.quantile(0.99).unwrap(),
                exact.max().unwrap()
            ))
        );
        assert_eq!(order_stats(&mut []), None);
    }

    #[test]
    fn memory_is_bounded_over_an_hour_of_changes() {
        let mut live = Live::default();
        for t in (0..=3_600_000).step_by(20) {
            live.push(rec(t, 50, 0, 0, 0));
            if t % 20_000 == 0 {
                live.change(Nanos((t + 10) * MS), "sensor rate → 50 Hz".into());
            }
        }
        assert!(live.window.len() <= 252, "{}", live.window.len());
        assert!(live.marks.len() <= MAX_MARKS);
        assert_eq!(live.segment().index, 181 + 1);
    }
}
