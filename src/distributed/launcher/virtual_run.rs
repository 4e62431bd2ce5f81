//! The run under the virtual clock, as the launcher sees it: it follows the whole graph's
//! order of events as the run core draws it ([`ratelab_runtime::runcore::Follower`]), moves the
//! horizon on ahead of them, takes each event's report from its
//! node's process ([`crate::lockstep`]), ends the run where a report says so,
//! and gathers the processes' reports at the end.

use super::admission::Admission;
use super::{Launch, Link, LockstepCost};
use crate::lockstep::{check_tick_report, TickInbox, HORIZON_PERIODS};
use crate::wire::{self, Ticked, ToLauncher, ToProcess};
use crate::{DistError, REPLY_TIMEOUT};
use crossbeam_channel::Receiver;
use ratelab_core::time::Nanos;
use ratelab_runtime::graph::{NodeId, TopicId};
use ratelab_runtime::runcore::Follower;
use ratelab_runtime::scheduler::{EndReason, Event, RunEnd, StopFlag};
use ratelab_runtime::summary::GraphState;
use std::collections::BTreeMap;
use std::sync::Mutex;
use std::time::{Duration, Instant};

/// What the launcher's wait for one tick's report came to (virtual clock).
enum Awaited {
    /// The report.
    Report(Ticked),
    /// The run cannot go on: why (the node's process is silent, or out of step).
    Failed(String),
    /// A process of the graph is gone (its liveliness token withdrawn): its ticks will not
    /// come, and a tick awaited elsewhere may wait on its messages.
    Gone(String),
    /// Ctrl-C while the tick hung.
    Interrupted,
}

impl Launch<'_> {
    /// Follow the run in lockstep from `start` (every process ready) to its end: each
    /// event's report from `ticked` (every process's tick reports), a process of the graph
    /// going (`gone_now`) ending it. Then stop every process and gather its report
    /// (`reports`, `wires`). Returns how the run ended and, unpaced, its cost.
    ///
    /// # Errors
    /// [`DistError`] when a horizon cannot be sent.
    pub(super) fn run_lockstep(
        &self,
        ticked_rx: &Receiver<Ticked>,
        gone_now: &Mutex<Vec<String>>,
        start: Instant,
        reports: &mut BTreeMap<String, GraphState>,
        wires: &mut Vec<wire::WireLink>,
    ) -> Result<(RunEnd, Option<LockstepCost>), DistError> {
        let (spec, cfg, opts, stop) = (self.spec, self.cfg, self.opts, self.stop);
        let (names, placement, link) = (&self.names, &self.placement, &self.link);
        // The run's order of events, as the run core draws it: each is a tick (or its
        // outputs going out) in its node's process, which reports it.
        let mut order = Follower::new(cfg).map_err(|e| DistError::Usage(e.to_string()))?;
        let lookahead = order.shortest_period().0.saturating_mul(HORIZON_PERIODS);
        let mut inbox = TickInbox::new();
        // No process ticks before the first horizon: anything already here is not a report.
        while ticked_rx.try_recv().is_ok() {}
        let mut published: Vec<Option<u64>> = vec![None; spec.topics.len()];
        let mut horizon: Option<u64> = None;
        // Events (ticks' starts, and their outputs going out after a compute time), the
        // ticks among them, and the instants they fell on.
        let (mut index, mut started, mut instants) = (0u64, 0u64, 0u64);
        let mut last_t = None;
        let failed = |i: usize, at: Nanos, message: String| RunEnd {
            at,
            reason: EndReason::NodeFailed {
                node: spec.nodes[i].name.clone(),
                message,
            },
        };
        let paced_from = Instant::now();
        let end = loop {
            let Some(event) = order.next_event() else {
                break RunEnd {
                    at: cfg.duration,
                    reason: EndReason::Duration,
                };
            };
            let (i, t) = event.node_at();
            // Paced: no instant before its wall time (the horizon follows).
            if let Some(speed) = opts.pace.filter(|s| *s > 0.0 && s.is_finite()) {
                wait_for_wall_time(paced_from, t, speed, stop);
            }
            self.say_refusals_due();
            // Move the horizon on before the processes reach it; an interrupt stops it.
            let want = t.0.saturating_add(lookahead).min(cfg.duration.0);
            let low = horizon.is_none_or(|h| h < t.0.saturating_add(lookahead / 2));
            if !stop.is_stopped() && low && horizon.is_none_or(|h| want > h) {
                for p in names {
                    link.tell(p, &ToProcess::Horizon { until_ns: want })?;
                }
                horizon = Some(want);
            }
            if horizon.is_none_or(|h| t.0 > h) {
                // Only after an interrupt: every tick up to the horizon was seen.
                break RunEnd {
                    at: order.now(),
                    reason: EndReason::Interrupted,
                };
            }
            // The tick's report, from its node's process.
            let report = self.await_report(ticked_rx, gone_now, &mut inbox, index, i);
            let m = match report {
                Awaited::Report(m) => m,
                Awaited::Interrupted => {
                    break RunEnd {
                        at: order.now(),
                        reason: EndReason::Interrupted,
                    }
                }
                Awaited::Failed(message) => break failed(i, t, message),
                Awaited::Gone(p) => {
                    // The failed node is the gone process's (its first), not the awaited one.
                    let node = placement
                        .iter()
                        .find(|(name, _)| *name == p)
                        .and_then(|(_, ids)| ids.first().map(|n| n.0))
                        .unwrap_or(i);
                    break failed(node, t, format!("process '{p}' is gone"));
                }
            };
            let compute = match check_tick_report(&m, index, event, spec) {
                Ok(c) => c,
                Err(message) => break failed(i, t, message),
            };
            if let Event::Start { .. } = event {
                started += 1;
            }
            order.ran_elsewhere(event, compute);
            index += 1;
            if last_t != Some(t) {
                instants += 1;
                last_t = Some(t);
            }
            for &(topic, seq) in &m.published {
                // Only a topic the node publishes (a report is untrusted input).
                if spec.nodes[i].publishes.contains(&TopicId(topic)) {
                    published[topic] = Some(seq);
                }
            }
            if let Some(message) = m.failed {
                break failed(i, t, message);
            }
            if m.stop {
                break RunEnd {
                    at: t,
                    reason: EndReason::NodeStopped,
                };
            }
        };
        // Paced, the wall time is the pace's, not the lockstep's cost.
        let lockstep = opts.pace.is_none().then(|| LockstepCost {
            ticks: started,
            instants,
            us_per_instant: start.elapsed().as_secs_f64() * 1e6 / instants.max(1) as f64,
        });
        // Every message sent is delivered before the reports: the last ones too, but those
        // of a process that is gone, which may have died with them still to send (its
        // report reached us, its sample not the subscriber).
        let gone = ratelab_runtime::graph::lock(gone_now).clone();
        let need: Vec<(usize, u64)> = published
            .iter()
            .enumerate()
            .filter_map(|(t, s)| s.map(|s| (t, s)))
            .filter(|&(t, _)| !gone.contains(&spec.process_of(spec.topics[t].publisher)))
            .collect();
        collect_reports((link, stop), names, gone_now, &end, need, reports, wires);
        Ok((end, lockstep))
    }

    /// Wait for the report of event `index`, a tick of node `i` (from `ticked_rx` through
    /// `inbox`, which keeps reports that came early): it, a process of the graph gone
    /// (`gone_now`), no answer within twice [`REPLY_TIMEOUT`], or Ctrl-C with the tick still
    /// hung after a second's grace. A join meanwhile is refused (nobody joins a lockstep).
    fn await_report(
        &self,
        ticked_rx: &Receiver<Ticked>,
        gone_now: &Mutex<Vec<String>>,
        inbox: &mut TickInbox,
        index: u64,
        i: usize,
    ) -> Awaited {
        let (spec, names, stop, link) = (self.spec, &self.names, self.stop, &self.link);
        let process = spec.process_of(NodeId(i));
        // Longer than a process waits for an input message itself, so that its
        // own, more precise error comes first.
        let patience = 2 * REPLY_TIMEOUT;
        let deadline = Instant::now() + patience;
        let mut interrupted_at: Option<Instant> = None;
        loop {
            // Reports already here count before a process's going (it may have
            // reported, then died).
            let mut overflow = None;
            while let Ok(m) = ticked_rx.try_recv() {
                if let Err(e) = inbox.accept(m, spec) {
                    overflow = Some(e.to_string());
                    break;
                }
            }
            if let Some(e) = overflow {
                return Awaited::Failed(e);
            }
            if let Some(m) = inbox.take(index) {
                return Awaited::Report(m);
            }
            // Any of the graph's processes, not only this tick's: a tick of another
            // process may be waiting for the gone one's message, and would only
            // time out (REPLY_TIMEOUT) before saying so.
            let gone = ratelab_runtime::graph::lock(gone_now)
                .iter()
                .find(|p| names.contains(p))
                .cloned();
            if let Some(p) = gone {
                return Awaited::Gone(p);
            }
            if Instant::now() >= deadline {
                return Awaited::Failed(format!(
                    "process '{process}' did not answer within {} s",
                    patience.as_secs()
                ));
            }
            // Ctrl-C while a tick hangs: a second's grace, then the run ends here.
            if stop.is_stopped() {
                let since = *interrupted_at.get_or_insert_with(Instant::now);
                if since.elapsed() >= Duration::from_secs(1) {
                    return Awaited::Interrupted;
                }
            }
            crossbeam_channel::select! {
                recv(ticked_rx) -> m => if let Ok(m) = m {
                    if let Err(e) = inbox.accept(m, spec) {
                        return Awaited::Failed(e.to_string());
                    }
                },
                recv(link.up) -> m => match m {
                    // Nobody joins a run in lockstep: say so to whoever tries.
                    Ok(m @ ToLauncher::Join { .. }) => match self.admit(&m, true, &[], &[]) {
                        Admission::Refused(r)
                        | Admission::OtherGraph(r)
                        | Admission::Busy(r) => self.say_refused(&r),
                        Admission::Welcomed | Admission::Ignored => {}
                    },
                    Ok(_) => {}
                    Err(_) => return Awaited::Failed("the launcher's channel closed".into()),
                },
                default(Duration::from_millis(50)) => {}
            }
        }
    }
}

/// How long after a process is seen gone, once the run is stopped, its report may still
/// come. A process keeps its tokens until the launcher has its report
/// ([`ToProcess::ReportTaken`]); this is for one that sent its report and then died, or
/// whose wait for the receipt ran out (its tokens' withdrawal can overtake the report:
/// by 0.36 s, seen with 64 processes on 2 cores before the receipt).
const GONE_REPORT_GRACE: Duration = Duration::from_secs(2);

/// Stop every process at `end` and gather its report: every process's, or until 5 s past
/// [`REPLY_TIMEOUT`] (2 s after Ctrl-C, before or during the wait); a process gone before
/// the stop is not waited for, one seen gone after it [`GONE_REPORT_GRACE`] more.
fn collect_reports(
    (link, stop): (&Link, &StopFlag),
    names: &[String],
    gone: &Mutex<Vec<String>>,
    end: &RunEnd,
    need: Vec<(usize, u64)>,
    reports: &mut BTreeMap<String, GraphState>,
    wires: &mut Vec<wire::WireLink>,
) {
    // Gone before the stop: no report will come (a virtual-clock process reports once
    // told to stop).
    let mut gone_since: BTreeMap<String, Option<Instant>> = ratelab_runtime::graph::lock(gone)
        .iter()
        .map(|p| (p.clone(), None))
        .collect();
    for p in names {
        let _ = link.tell(
            p,
            &ToProcess::Stop {
                at_ns: end.at.0,
                need: need.clone(),
            },
        );
    }
    // After Ctrl-C (maybe with a tick hung) the reports get a short while only; else
    // longer than a process waits for its last input messages (REPLY_TIMEOUT), so that
    // its own error, on its stderr, comes first.
    let interrupted = Duration::from_secs(2);
    let patience = if end.reason == EndReason::Interrupted {
        interrupted
    } else {
        REPLY_TIMEOUT + Duration::from_secs(5)
    };
    let mut deadline = Instant::now() + patience;
    loop {
        let now = Instant::now();
        // Ctrl-C meanwhile: 2 s from the first time it is seen (later, `now + 2 s` is
        // never the earlier).
        if stop.is_stopped() {
            deadline = deadline.min(now + interrupted);
        }
        for p in ratelab_runtime::graph::lock(gone).iter() {
            gone_since.entry(p.clone()).or_insert(Some(now));
        }
        if !awaits_a_report(names, reports, &gone_since, now) || now >= deadline {
            break;
        }
        if let Some(ToLauncher::Report {
            process,
            state,
            wire,
        }) = link.recv(Duration::from_millis(50))
        {
            // Its tokens go after this receipt, not before the report is in.
            let _ = link.tell(&process, &ToProcess::ReportTaken);
            wires.extend(wire);
            reports.insert(process, *state);
        }
    }
}

/// Whether a report of `names` may still come at `now`: one not in `reports` whose process
/// is not gone (`gone_since`: `None` for those gone before the stop, else when each was
/// first seen gone after it) or went less than [`GONE_REPORT_GRACE`] ago.
fn awaits_a_report<T>(
    names: &[String],
    reports: &BTreeMap<String, T>,
    gone_since: &BTreeMap<String, Option<Instant>>,
    now: Instant,
) -> bool {
    names.iter().any(|p| {
        !reports.contains_key(p)
            && match gone_since.get(p) {
                None => true,
                Some(None) => false,
                Some(&Some(at)) => now.duration_since(at) < GONE_REPORT_GRACE,
            }
    })
}

/// Paced at `speed` × wall time from `from`: wait until run time `t` is due (or `stop`).
fn wait_for_wall_time(
    from: Instant,
    t: Nanos,
    speed: f64,
    stop: &ratelab_runtime::scheduler::StopFlag,
) {
    let due = from + Duration::from_secs_f64(t.as_secs_f64() / speed);
    while !stop.is_stopped() && Instant::now() < due {
        let left = due.saturating_duration_since(Instant::now());
        std::thread::sleep(left.min(Duration::from_millis(50)));
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_gone_process_s_report_is_awaited_for_the_grace_only() {
        let names: Vec<String> = ["robot", "policy", "ctl_0"].map(String::from).to_vec();
        let t0 = Instant::now();
        let mut reports = BTreeMap::new();
        let mut gone = BTreeMap::new();
        assert!(awaits_a_report(&names, &reports, &gone, t0));
        reports.insert("robot".to_string(), ());
        reports.insert("policy".to_string(), ());
        assert!(awaits_a_report(&names, &reports, &gone, t0), "ctl_0 runs");
        // ctl_0 seen gone: its report, sent before it exited, may still be on its way.
        gone.insert("ctl_0".to_string(), Some(t0));
        assert!(awaits_a_report(&names, &reports, &gone, t0));
        let later = t0 + GONE_REPORT_GRACE;
        assert!(!awaits_a_report(&names, &reports, &gone, later));
        // A report that came after its process was seen gone counts like any other.
        reports.insert("ctl_0".to_string(), ());
        assert!(!awaits_a_report(&names, &reports, &gone, t0));
        // A gone process that had reported is not waited for; one that runs is.
        reports.remove("policy");
        gone.insert("robot".to_string(), Some(t0));
        assert!(awaits_a_report(&names, &reports, &gone, later));
        // A process gone before the stop will not report: no grace for it.
        reports.insert("policy".to_string(), ());
        reports.remove("ctl_0");
        gone.insert("ctl_0".to_string(), None);
        assert!(!awaits_a_report(&names, &reports, &gone, t0));
    }
}
