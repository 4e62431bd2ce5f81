//! The reload line's comparison ([`super::reload`]): the run before a save against the new
//! code's trial run, over the span of run time both ran — the shorter of the two, a run
//! that fell or failed ending there — so that a count never reads smaller only because its
//! run was shorter: `balanced (5.5 s) → balanced (10.0 s) · over the first 5.50 s of each:
//! latency p50 40 → 40 ms, /obs dropped 267 → 133`.
//!
//! A run's figures at an instant come from its actuator's step records, the records
//! `trace.csv` is written from (each carries every topic's counters and the applied
//! action's sense→act latency), kept as the run goes by an [`Opening`]: the run before's
//! first [`super::engine::JUDGE_FOR`] of run time (no trial runs longer, so no common span
//! is longer), and the whole of the trial's.

use ratelab_core::metrics::{ExactLatency, Metrics};
use ratelab_core::runlog::{StepRecord, TopicCounters};
use ratelab_core::time::Nanos;
use ratelab_runtime::graph::StepObserver;
use std::sync::{Arc, Mutex};

/// One actuator tick's figures, as the reload line compares runs by them.
#[derive(Clone, Debug)]
pub(super) struct Tick {
    /// Its run time.
    pub(super) t: Nanos,
    /// The sense→act latency of the action it applied (`None`: it applied no sensed one).
    pub(super) latency: Option<Nanos>,
    /// Every topic's counters at it, by topic index.
    pub(super) topics: TopicCounters,
}

impl From<&StepRecord> for Tick {
    fn from(r: &StepRecord) -> Self {
        Tick {
            t: r.t,
            latency: r.latency,
            topics: r.topics.clone(),
        }
    }
}

/// A run's actuator ticks over its opening span of run time, kept as it runs: a step
/// observer whose clones share what it keeps. A run that goes back (a seek back runs it
/// again from a capture, or from 0) replaces its ticks from where it went back.
#[derive(Clone)]
pub(super) struct Opening {
    /// The ticks kept, in run-time order.
    kept: Arc<Mutex<Vec<Tick>>>,
    /// The last run time kept: later ticks are not.
    upto: Nanos,
}

impl Opening {
    /// Keep the ticks at or before `upto` of run time.
    pub(super) fn upto(upto: Nanos) -> Opening {
        Opening {
            kept: Arc::default(),
            upto,
        }
    }

    /// A boxed clone, for a graph's observers.
    pub(super) fn observer(&self) -> Box<dyn StepObserver> {
        Box::new(self.clone())
    }

    /// The ticks kept so far, in run-time order.
    pub(super) fn ticks(&self) -> Vec<Tick> {
        self.kept.lock().unwrap_or_else(|e| e.into_inner()).clone()
    }
}

impl StepObserver for Opening {
    fn on_step(&mut self, rec: &StepRecord) {
        let mut kept = self.kept.lock().unwrap_or_else(|e| e.into_inner());
        // Ticks come in run-time order within a branch: one at or before the newest kept
        // is the run gone back, run again from there.
        let from = kept.partition_point(|k| k.t < rec.t);
        kept.truncate(from);
        if rec.t <= self.upto {
            kept.push(Tick::from(rec));
        }
    }
}

/// How a run went, as the reload line says it.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) enum Verdict {
    /// The pole was up at the end of its span.
    Balanced,
    /// The pole fell at the end of its span.
    Fell,
    /// A node failed at the end of its span.
    Failed,
}

/// One run's figures for the reload line.
#[derive(Clone, Debug)]
pub(super) struct RunFigures {
    /// How it went.
    pub(super) verdict: Verdict,
    /// The run time it covers: to its fall or its failure, else as far as it ran.
    pub(super) span: Nanos,
    /// Its topics' names, by topic index.
    pub(super) topics: Vec<String>,
    /// Its actuator ticks, in run-time order (any past `span` are not counted).
    pub(super) ticks: Vec<Tick>,
}

impl RunFigures {
    /// The run whose summary is `m` (its verdict and span), with its `topics`' names and
    /// its `ticks`.
    pub(super) fn of(m: &Metrics, topics: Vec<String>, ticks: Vec<Tick>) -> RunFigures {
        let ns = |s: f64| Nanos((s * 1e9).round() as u64);
        let (verdict, span) = match (&m.node_failed, m.fell_at_s) {
            (Some(_), _) => (Verdict::Failed, ns(m.sim_time_s)),
            (None, Some(t)) => (Verdict::Fell, ns(t)),
            (None, None) => (Verdict::Balanced, ns(m.sim_time_s)),
        };
        RunFigures {
            verdict,
            span,
            topics,
            ticks,
        }
    }

    /// How it went, in words: `balanced (10.0 s)`, `fell at 0.84 s`, `failed at 2.00 s`.
    fn said(&self) -> String {
        let s = self.span.as_secs_f64();
        match self.verdict {
            Verdict::Balanced => format!("balanced ({s:.1} s)"),
            Verdict::Fell => format!("fell at {s:.2} s"),
            Verdict::Failed => format!("failed at {s:.2} s"),
        }
    }

    /// Its sense→act latency p50 (ms; `None` without a sample) and its topics' counters
    /// (`None` before its first tick), over its ticks at or before `at`.
    fn at(&self, at: Nanos) -> (Option<f64>, Option<&TopicCounters>) {
        let upto = self.ticks.partition_point(|k| k.t <= at);
        let mut latency = ExactLatency::default();
        for lat in self.ticks[..upto].iter().filter_map(|k| k.latency) {
            latency.record(lat);
        }
        let p50 = latency.quantile(0.5).map(|n| n.0 as f64 / 1e6);
        (p50, upto.checked_sub(1).map(|i| &self.ticks[i].topics))
    }

    /// Topic `name`'s drops in `counters` (0 for a topic this run does not have).
    fn dropped(&self, counters: Option<&TopicCounters>, name: &str) -> u64 {
        let i = self.topics.iter().position(|t| t == name);
        match (counters, i) {
            (Some(c), Some(i)) => c.get(ratelab_runtime::graph::TopicId(i)).dropped,
            _ => 0,
        }
    }
}

/// What changed from the run before a save (`old`) to the new code's (`new`), in one line:
/// how each run went, then, over the span of run time both ran (the shorter; a fall or a
/// failure ends a run's), the sense→act latency p50 and the drops of each topic that
/// dropped any in either: `fell at 0.84 s → balanced (10.0 s) · over the first 0.84 s of
/// each: latency p50 40 → 40 ms, /obs dropped 9 → 0`.
pub(super) fn changes(old: &RunFigures, new: &RunFigures) -> String {
    let outcomes = format!("{} → {}", old.said(), new.said());
    let common = old.span.min(new.span);
    if common == Nanos::ZERO {
        return format!("{outcomes} · no run time in common to compare");
    }
    let ((old_p50, old_at), (new_p50, new_at)) = (old.at(common), new.at(common));
    let ms = |p: Option<f64>| p.map_or_else(|| "–".to_string(), |p| format!("{p:.0}"));
    let mut figures = vec![format!("latency p50 {} → {} ms", ms(old_p50), ms(new_p50))];
    // The run before's topics in its order, then those only the new code's graph has.
    let names = old
        .topics
        .iter()
        .chain(new.topics.iter().filter(|t| !old.topics.contains(t)));
    for name in names {
        let (o, n) = (old.dropped(old_at, name), new.dropped(new_at, name));
        if o > 0 || n > 0 {
            figures.push(format!("{name} dropped {o} → {n}"));
        }
    }
    format!(
        "{outcomes} · over the first {:.2} s of each: {}",
        common.as_secs_f64(),
        figures.join(", ")
    )
}

#[cfg(test)]
mod tests {
    use super::*;
    use ratelab_core::topic::TopicStats;

    const MS: u64 = 1_000_000;

    /// A run of the chapter's topics (`/obs`, `/action`) that went `verdict` over `span_ms`:
    /// an actuator tick every 20 ms from 20 ms, each with a latency of `latency_ms` and
    /// `/obs` dropping `obs_drops_per_s` (counted whole per tick), `/action` none.
    fn run(verdict: Verdict, span_ms: u64, latency_ms: u64, obs_drops_per_s: u64) -> RunFigures {
        let ticks = (1..=span_ms / 20)
            .map(|k| {
                let t = Nanos(k * 20 * MS);
                let obs = TopicStats {
                    dropped: obs_drops_per_s * k * 20 / 1000,
                    depth: 1,
                    ..TopicStats::default()
                };
                let action = TopicStats {
                    depth: 1,
                    ..TopicStats::default()
                };
                Tick {
                    t,
                    latency: Some(Nanos(latency_ms * MS)),
                    topics: [obs, action].into_iter().collect(),
                }
            })
            .collect();
        RunFigures {
            verdict,
            span: Nanos(span_ms * MS),
            topics: vec!["/obs".into(), "/action".into()],
            ticks,
        }
    }

    #[test]
    fn equal_spans_compare_the_whole_of_both() {
        let old = run(Verdict::Balanced, 10_000, 80, 40);
        let new = run(Verdict::Balanced, 10_000, 40, 0);
        assert_eq!(
            changes(&old, &new),
            "balanced (10.0 s) → balanced (10.0 s) · over the first 10.00 s of each: latency p50 80 → 40 ms, /obs dropped 400 → 0"
        );
    }

    #[test]
    fn unequal_spans_compare_over_the_shorter() {
        // The run before reached 5.5 s; the new code's was judged over 10 s: its /obs
        // dropped 243 in all, but 133 over the first 5.5 s, which is what compares.
        let old = run(Verdict::Balanced, 5_500, 60, 48);
        let new = run(Verdict::Balanced, 10_000, 60, 24);
        assert_eq!(new.dropped(new.at(new.span).1, "/obs"), 240);
        let line = changes(&old, &new);
        assert_eq!(
            line,
            "balanced (5.5 s) → balanced (10.0 s) · over the first 5.50 s of each: latency p50 60 → 60 ms, /obs dropped 264 → 132"
        );
        // Either way round.
        assert_eq!(
            changes(&new, &old),
            "balanced (10.0 s) → balanced (5.5 s) · over the first 5.50 s of each: latency p50 60 → 60 ms, /obs dropped 132 → 264"
        );
    }

    #[test]
    fn a_run_that_fell_is_compared_up_to_its_fall() {
        // The new code fell at 0.84 s: the run before's counts are taken there, not at the
        // 10 s it reached.
        let old = run(Verdict::Balanced, 10_000, 40, 50);
        let new = run(Verdict::Fell, 840, 80, 100);
        assert_eq!(
            changes(&old, &new),
            "balanced (10.0 s) → fell at 0.84 s · over the first 0.84 s of each: latency p50 40 → 80 ms, /obs dropped 42 → 84"
        );
        // And the other way: the run before fell, the new code balances.
        let fell = run(Verdict::Fell, 840, 80, 100);
        let up = run(Verdict::Balanced, 10_000, 40, 0);
        assert_eq!(
            changes(&fell, &up),
            "fell at 0.84 s → balanced (10.0 s) · over the first 0.84 s of each: latency p50 80 → 40 ms, /obs dropped 84 → 0"
        );
        // A failed node ends its run's span likewise.
        let failed = run(Verdict::Failed, 2_000, 40, 0);
        assert_eq!(
            changes(&old, &failed),
            "balanced (10.0 s) → failed at 2.00 s · over the first 2.00 s of each: latency p50 40 → 40 ms, /obs dropped 100 → 0"
        );
    }

    #[test]
    fn a_save_before_the_run_moved_has_nothing_to_compare() {
        let old = run(Verdict::Balanced, 0, 40, 0);
        let new = run(Verdict::Balanced, 10_000, 40, 0);
        assert_eq!(
            changes(&old, &new),
            "balanced (0.0 s) → balanced (10.0 s) · no run time in common to compare"
        );
    }

    #[test]
    fn a_topic_only_one_graph_has_counts_zero_in_the_other() {
        let old = run(Verdict::Balanced, 1_000, 40, 0);
        let mut new = run(Verdict::Balanced, 1_000, 40, 0);
        new.topics[1] = "/cmd".into();
        for k in &mut new.ticks {
            let mut cmd = k.topics.get(ratelab_runtime::graph::TopicId(1));
            cmd.dropped = 7;
            k.topics.set(ratelab_runtime::graph::TopicId(1), cmd);
        }
        assert!(
            changes(&old, &new).ends_with("latency p50 40 → 40 ms, /cmd dropped 0 → 7"),
            "{}",
            changes(&old, &new)
        );
    }

    #[test]
    fn the_opening_keeps_the_branch_a_run_went_back_to() {
        let mut opening = Opening::upto(Nanos::SECOND);
        let rec = |ms: u64, dropped: u64| StepRecord {
            step: ms / 20,
            t: Nanos(ms * MS),
            pole_angle: 0.0,
            pole_angvel: 0.0,
            cart_pos: 0.0,
            action: 0.0,
            latency: None,
            held_stamp: None,
            nonfinite: false,
            topics: [TopicStats {
                dropped,
                depth: 1,
                ..TopicStats::default()
            }]
            .into_iter()
            .collect(),
            published: None,
            fell: false,
            estimate: None,
        };
        for ms in [20, 40, 60, 80] {
            opening.on_step(&rec(ms, 1));
        }
        // Back to 40 ms: run again from there, another branch.
        for ms in [40, 60] {
            opening.on_step(&rec(ms, 2));
        }
        let kept: Vec<(u64, u64)> = opening
            .ticks()
            .iter()
            .map(|k| {
                (
                    k.t.0 / MS,
                    k.topics.get(ratelab_runtime::graph::TopicId(0)).dropped,
                )
            })
            .collect();
        assert_eq!(kept, [(20, 1), (40, 2), (60, 2)]);
        // Past its span nothing more is kept.
        opening.on_step(&rec(1_020, 3));
        assert_eq!(opening.ticks().len(), 3);
    }
}
