//! The run under the virtual clock, as the launcher sees it: its relay follows the whole
//! graph's order of events as the processes report them and hands each process the others'
//! reports in its turn ([`super::relay`], on Zenoh's receive thread); here the main thread
//! moves the horizon on ahead of them, ends the run where a process goes, stops answering
//! or Ctrl-C stops it, and gathers the processes' reports at the end.

use super::admission::Admission;
use super::relay::{failed, Relay, Relaying};
use super::{GoneProcesses, Launch, Link, LockstepCost};
use crate::monitor::Carried;
use crate::process::LiveStats;
use crate::wire::{self, ToLauncher, ToProcess};
use crate::{DistError, REPLY_TIMEOUT};
use crossbeam_channel::Receiver;
use ratelab_core::time::Nanos;
use ratelab_runtime::graph::NodeId;
use ratelab_runtime::runcore::drive::Pacer;
use ratelab_runtime::scheduler::{EndReason, RunEnd, StopFlag};
use ratelab_runtime::summary::GraphState;
use std::collections::BTreeMap;
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};
use zenoh::Wait;

/// Where [`Launch::run_lockstep`] puts what it gathers: every process's report, the wire's
/// figures, and the newest figures of each process but the plant's ([`Carried`]).
pub(super) type Gathered<'a> = (
    &'a mut BTreeMap<String, GraphState>,
    &'a mut Vec<wire::WireLink>,
    &'a mut Carried,
);

impl Launch<'_> {
    /// Follow the run in lockstep from `start` (every process ready) to its end, through
    /// `relaying` (every process's tick reports, followed and handed on), a process of the
    /// graph going (`gone_now`) ending it. Then hand every process the reports it has not
    /// had, stop every process and gather its report (`reports`, `wires`). Returns how the
    /// run ended and, unpaced, its cost.
    ///
    /// # Errors
    /// [`DistError`] when a horizon cannot be sent, or the run's order cannot be followed.
    pub(super) fn run_lockstep(
        &self,
        relaying: &Relaying,
        gone_now: &GoneProcesses,
        start: Instant,
        (reports, wires, carried): Gathered<'_>,
    ) -> Result<(RunEnd, Option<LockstepCost>), DistError> {
        let (spec, names, link) = (self.spec, &self.names, &self.link);
        let relay = &relaying.relay;
        // Each process's newest counts (its figures without their batch, `Keys::stats_counts`,
        // every `STATS_PERIOD`): a process that dies mid-run
        // never reports, and its topics read what it had counted by then ([`Carried`]), as
        // under the real clock, not nothing received. Kept as they came (a sample holds its
        // bytes by reference) and decoded once, after the run: the callback runs on the
        // launcher's one Zenoh thread, which the lockstep's reports cross too.
        let newest: Arc<Mutex<BTreeMap<String, zenoh::sample::Sample>>> = Arc::default();
        let mut _figures = Vec::new();
        for p in names.iter().filter(|p| **p != self.robot) {
            let (newest, p2) = (newest.clone(), p.to_string());
            _figures.push(
                link.session
                    .declare_subscriber(link.keys.stats_counts(p))
                    .callback(move |s| {
                        ratelab_runtime::graph::lock(&newest).insert(p2.clone(), s);
                    })
                    .wait()?,
            );
        }
        let lookahead = relay.begin(self.cfg, self.opts.pace.is_some())?;
        let end = self.follow(relay, &relaying.nudged, gone_now, lookahead)?;
        let tally = relay.tally();
        // Paced, the wall time is the pace's, not the lockstep's cost.
        let lockstep = self.opts.pace.is_none().then(|| LockstepCost {
            ticks: tally.started,
            instants: tally.instants,
            us_per_instant: start.elapsed().as_secs_f64() * 1e6 / tally.instants.max(1) as f64,
        });
        // Every message sent is delivered before the reports: the last ones too, but those
        // of a process that is gone, which may have died with them still to send (its
        // report reached us, its sample not the subscriber).
        let gone = gone_now.all();
        let need: Vec<(usize, u64)> = (tally.published.iter().enumerate())
            .filter_map(|(t, s)| s.map(|s| (t, s)))
            .filter(|&(t, _)| !gone.contains(&spec.process_of(spec.topics[t].publisher)))
            .collect();
        // Every process takes every event of the run before it reports: the order it
        // replayed (its executors' figures) is then the whole run's.
        relay.hand_over_all();
        for p in names {
            let _ = link.tell(
                p,
                &ToProcess::Events {
                    count: tally.events,
                },
            );
        }
        collect_reports(
            (link, self.stop),
            names,
            gone_now,
            &end,
            need,
            reports,
            wires,
        );
        drop(_figures);
        // Taken out first: a late callback never waits while they are decoded.
        let newest = std::mem::take(&mut *ratelab_runtime::graph::lock(&newest));
        for s in newest.values() {
            if let Some(m) = LiveStats::from_sample(s) {
                carried.see(spec, &m);
            }
        }
        Ok((end, lockstep))
    }

    /// Follow the run to its end as the relay takes the reports: move the horizon on
    /// [`crate::lockstep::horizon_periods`] periods of the fastest node (`lookahead`, ns)
    /// ahead of the next event (paced: of the wall time, too), and end the run when the
    /// relay does, when a process of the graph is gone, when the next
    /// event's process does not answer within twice [`REPLY_TIMEOUT`], or on Ctrl-C (at
    /// the horizon, or after a second's grace for a tick that hangs). A join meanwhile is
    /// refused (nobody joins a lockstep).
    ///
    /// # Errors
    /// [`DistError`] when a horizon cannot be sent.
    fn follow(
        &self,
        relay: &Relay,
        nudged: &Receiver<()>,
        gone_now: &GoneProcesses,
        lookahead: u64,
    ) -> Result<RunEnd, DistError> {
        let (spec, cfg, stop, link) = (self.spec, self.cfg, self.stop, &self.link);
        // Longer than a process waits for an input message itself, so that its own, more
        // precise error comes first.
        let patience = 2 * REPLY_TIMEOUT;
        // Paced: run time runs at `pace` × the wall's from now (the drive loop's pacer).
        let pacer = Pacer::new(Nanos::ZERO, self.opts.pace);
        let mut horizon: Option<u64> = None;
        let (mut seen, mut waiting_since) = (u64::MAX, Instant::now());
        let mut interrupted_at: Option<Instant> = None;
        // Since a process went: the launcher's view's index, when it last moved, and since.
        let mut settling: Option<(u64, Instant, Instant)> = None;
        loop {
            self.say_refusals_due();
            let now = relay.progress();
            if let Some(end) = now.end {
                return Ok(end);
            }
            let Some((i, t)) = now.next else {
                // (Never: the relay draws the next event until the run ends.)
                return Ok(relay.finish(RunEnd {
                    at: cfg.duration,
                    reason: EndReason::Duration,
                }));
            };
            // Paced: no instant more than the lookahead ahead of its wall time.
            let base = pacer.run_time_now().map_or(t.0, |due| t.0.min(due.0));
            let want = base.saturating_add(lookahead).min(cfg.duration.0);
            let low = horizon.is_none_or(|h| crate::lockstep::horizon_low(h, base, lookahead));
            if !stop.is_stopped() && low && horizon.is_none_or(|h| want > h) {
                // Linked directly, the processes send the launcher their reports once their
                // run passes where it moves the horizon on next.
                let follow_at_ns = (relay.follows_in_batches())
                    .then(|| crate::lockstep::follow_at(want, lookahead));
                let horizon_at = ToProcess::Horizon {
                    until_ns: want,
                    follow_at_ns,
                };
                for p in &self.names {
                    link.tell(p, &horizon_at)?;
                }
                horizon = Some(want);
                relay.set_horizon(want);
            }
            // The next event lies past the horizon: nobody may run it yet.
            let beyond = horizon.is_none_or(|h| t.0 > h);
            if stop.is_stopped() {
                // Ctrl-C: every event up to the horizon, or a second's grace for one that
                // hangs; then the run ends here.
                let since = *interrupted_at.get_or_insert_with(Instant::now);
                if beyond || since.elapsed() >= Duration::from_secs(1) {
                    return Ok(relay.interrupt());
                }
            }
            // Any of the graph's processes, not only the next event's: a tick of another
            // process may be waiting for the gone one's message, and would only time out
            // (REPLY_TIMEOUT) before saying so.
            let gone = gone_now.all().into_iter().find(|p| self.names.contains(p));
            // Linked directly, the launcher hears the others' reports in batches: it ends
            // the run once they stop coming, where the furthest process got.
            let settled = !relay.follows_in_batches()
                || gone.is_some() && {
                    let accepted = relay.accepted();
                    let (seen, changed, since) =
                        settling.get_or_insert((accepted, Instant::now(), Instant::now()));
                    if *seen != accepted {
                        (*seen, *changed) = (accepted, Instant::now());
                    }
                    changed.elapsed() >= FOLLOWED_SETTLE || since.elapsed() >= FOLLOWED_SETTLE_MAX
                };
            if let Some(p) = gone.filter(|_| settled) {
                // The failed node is the gone process's (its first), not the awaited one.
                let node = (self.placement.iter())
                    .find(|(name, _)| *name == p)
                    .and_then(|(_, ids)| ids.first().map(|n| n.0))
                    .unwrap_or(i);
                let message = format!("process '{p}' is gone");
                // Linked directly, the others may have run on past the launcher's view, on
                // reports of the gone process's that only they had: the run ends where the
                // furthest of them got.
                let at = relay.at_least_reported(t);
                return Ok(relay.finish(failed(spec, node, at, message)));
            }
            if now.index != seen || beyond {
                (seen, waiting_since) = (now.index, Instant::now());
            }
            if waiting_since.elapsed() >= patience {
                let process = spec.process_of(NodeId(i));
                let message = format!(
                    "process '{process}' did not answer within {} s",
                    patience.as_secs()
                );
                let at = relay.at_least_reported(t);
                return Ok(relay.finish(failed(spec, i, at, message)));
            }
            crossbeam_channel::select! {
                recv(nudged) -> _ => {},
                recv(link.up) -> m => match m {
                    // Nobody joins a run in lockstep: say so to whoever tries.
                    Ok(m @ ToLauncher::Join { .. }) => match self.admit(&m, true, &[], &[]) {
                        Admission::Refused(r)
                        | Admission::OtherGraph(r)
                        | Admission::Busy(r) => self.say_refused(&r),
                        Admission::Welcomed | Admission::Ignored => {}
                    },
                    Ok(_) => {}
                    Err(_) => {
                        let message = "the launcher's channel closed".to_string();
                        return Ok(relay.finish(failed(spec, i, t, message)));
                    }
                },
                default(Duration::from_millis(20)) => {}
            }
        }
    }
}

/// Linked directly, once a process is gone: how long no report may come in (from any
/// process, in turn or ahead of it, [`Relay::accepted`]) before the run ends, and how long
/// the launcher waits for that at most. A stalled process sends what it has kept within
/// [`crate::lockstep::FOLLOWED_MAX_AGE`] of
/// making it, once its main thread looks again (every 100 ms when nothing comes).
const FOLLOWED_SETTLE: Duration = Duration::from_millis(300);
const FOLLOWED_SETTLE_MAX: Duration = Duration::from_secs(2);

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
    gone: &GoneProcesses,
    end: &RunEnd,
    need: Vec<(usize, u64)>,
    reports: &mut BTreeMap<String, GraphState>,
    wires: &mut Vec<wire::WireLink>,
) {
    // Gone before the stop: no report will come (a virtual-clock process reports once
    // told to stop).
    let mut gone_since: BTreeMap<String, Option<Instant>> =
        gone.all().iter().map(|p| (p.clone(), None)).collect();
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
        for p in gone.all() {
            gone_since.entry(p).or_insert(Some(now));
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
