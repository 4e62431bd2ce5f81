//! The run under the real clock, as the launcher sees it: it gives the processes one start,
//! follows their figures (a process whose figures stop while its tokens live is said to be
//! silent: frozen, starved or cut off), starts again a process that failed where the graph
//! says so (`restart = "on-failure"`), lets a process started again rejoin, ends the run
//! when the plant's process goes, on Ctrl-C or at a process's own end, and gathers the
//! processes' reports.

use super::admission::Admission;
use super::processes::Children;
use super::{GoneProcesses, Launch};
use crate::monitor::{Carried, Silence};
use crate::process::LiveStats;
use crate::wire::{self, ToLauncher, ToProcess};
use crate::{DistError, REPLY_TIMEOUT};
use crossbeam_channel::Receiver;
use ratelab_core::time::Nanos;
use ratelab_runtime::graph::spec::{RestartPolicy, MAX_RESTARTS};
use ratelab_runtime::scheduler::{EndReason, RunEnd};
use ratelab_runtime::summary::GraphState;
use std::collections::BTreeMap;
use std::time::{Duration, Instant};
use zenoh::Wait;

impl Launch<'_> {
    /// Run the graph under the real clock to its end: `gone` says each process whose
    /// liveliness token went for good; `children` are the processes the launch started (started
    /// again in place on failure); `carried` keeps what a process started again had
    /// counted before. Every process's report lands in `reports` and `wires`; the processes
    /// killed on request ([`super::LaunchOptions::kill_processes`]) in `killed`, with the run
    /// time each was killed at. Returns how the run ended and, for a run the launcher
    /// stopped (a failure, a process gone, Ctrl-C), the run time each report was taken at:
    /// a process's nodes run until the stop reaches it, so under load a report counts
    /// ticks past the run's end, never past the time it came ([`super::report_time`]).
    ///
    /// # Errors
    /// [`DistError`] when the start cannot be sent or the figures cannot be subscribed to.
    pub(super) fn supervise(
        &self,
        gone: &GoneProcesses,
        children: &mut Children,
        carried: &mut Carried,
        reports: &mut BTreeMap<String, GraphState>,
        wires: &mut Vec<wire::WireLink>,
        killed: &mut Vec<(String, Nanos)>,
    ) -> Result<(RunEnd, BTreeMap<String, Nanos>), DistError> {
        // Every process's figures: when they stop, the process is silent; of the
        // processes that may be started again (all but the plant's), what one counted
        // before it was killed is carried into the summary, as the lab carries it
        // ([`Carried`]).
        let (stats_tx, stats_rx) = crossbeam_channel::bounded::<LiveStats>(1024);
        let mut _stats_subs = Vec::new();
        for p in &self.names {
            let tx = stats_tx.clone();
            // Its figures say the process is running: its outbox's bound on direct puts
            // starts again ([`super::outbox`]).
            let outbox = self.outboxes.of(p).cloned();
            _stats_subs.push(
                self.link
                    .session
                    .declare_subscriber(self.link.keys.stats_counts(p))
                    .callback(move |s| {
                        if let Some(m) = LiveStats::from_sample(&s) {
                            if let Some(outbox) = &outbox {
                                outbox.answered();
                            }
                            let _ = tx.try_send(m);
                        }
                    })
                    .wait()?,
            );
        }
        let mut run = Supervision::new(wire::mono_now_ns() + 300_000_000);
        for p in &self.names {
            self.link.tell(
                p,
                &ToProcess::Start {
                    start_mono_ns: run.start_mono,
                },
            )?;
        }
        let mut kills = self.opts.kill_processes.clone();
        loop {
            run.hear_figures(self, &stats_rx, carried);
            run.kill_due(self, children, &mut kills);
            run.restart_failed(self, children);
            run.note_gone(self, gone);
            run.stop_once_ended(self);
            self.say_refusals_due();
            run.say_waiting(self, reports);
            if let Some(m) = run.next_message(self) {
                run.handle(self, m, reports, wires)?;
            }
            if run.over(self, reports) {
                break;
            }
        }
        for m in stats_rx.try_iter().filter(|m| m.process != self.robot) {
            carried.see(self.spec, &m);
        }
        *killed = std::mem::take(&mut run.killed);
        let end = run.end.unwrap_or(RunEnd {
            at: self.cfg.duration,
            reason: EndReason::Duration,
        });
        // A run that ended at its duration needed no stop: each process ended there on its
        // own, and the end bounds every report.
        let taken_at = if run.stop_sent {
            run.taken_at
        } else {
            BTreeMap::new()
        };
        Ok((end, taken_at))
    }
}

/// What the launcher knows of a run under the real clock while it supervises it.
struct Supervision {
    /// The common start, on the host's monotonic clock, ns.
    start_mono: u64,
    /// How the run ended, once it has.
    end: Option<RunEnd>,
    /// Processes that said they ended.
    ended: Vec<String>,
    /// Whether every process was told to stop.
    stop_sent: bool,
    /// Processes whose liveliness token went (and that have not rejoined).
    gone: Vec<String>,
    /// Processes let in again, not yet started.
    rejoining: Vec<String>,
    /// When each process that rejoined did (its last time): its wire figures count from
    /// then.
    rejoined_at: BTreeMap<String, Nanos>,
    /// Joins told to wait (their process's last run still had its token), taken again the
    /// moment that run is seen gone rather than at the joiner's next ask (100 ms later),
    /// when the joiner still asks: it asked within the last 300 ms and its process still
    /// runs (a rejoin under the real clock is on this host).
    waiting_join: BTreeMap<String, (Instant, ToLauncher)>,
    /// The OS process each rejoining process was let in as: its ask that crossed the
    /// welcome is not another copy's.
    welcomed_pid: BTreeMap<String, u32>,
    /// Restarts per process ([`RestartPolicy::OnFailure`]).
    restarts: BTreeMap<String, u32>,
    /// Processes no longer started again.
    given_up: Vec<String>,
    /// The processes killed on request, with the run time of each kill.
    killed: Vec<(String, Nanos)>,
    /// The run time each process's report was taken at (its last, for one started again).
    taken_at: BTreeMap<String, Nanos>,
    /// When each process's figures last came.
    silence: Silence,
    /// Processes said to be silent.
    silent: Vec<String>,
    /// Whether the wait for the last reports after the run's end was said.
    said_waiting: bool,
}

impl Supervision {
    fn new(start_mono: u64) -> Self {
        Supervision {
            start_mono,
            end: None,
            ended: Vec::new(),
            stop_sent: false,
            gone: Vec::new(),
            rejoining: Vec::new(),
            rejoined_at: BTreeMap::new(),
            waiting_join: BTreeMap::new(),
            welcomed_pid: BTreeMap::new(),
            restarts: BTreeMap::new(),
            given_up: Vec::new(),
            killed: Vec::new(),
            taken_at: BTreeMap::new(),
            silence: Silence::default(),
            silent: Vec::new(),
            said_waiting: false,
        }
    }

    /// When the run ended (its duration, or how it ended: a fall, a failure, Ctrl-C), once
    /// it has: the reports are due from then.
    fn over_at(&self, l: &Launch) -> Option<Nanos> {
        match &self.end {
            Some(end) => Some(end.at),
            None => (self.run_time() >= l.cfg.duration).then_some(l.cfg.duration),
        }
    }

    /// A second after the run's end, the processes whose reports have not come, said once
    /// with how long the launcher waits for them ([`REPLY_TIMEOUT`] from the end): a
    /// frozen process keeps its tokens until Zenoh's lease runs out, and the wait would
    /// otherwise pass without a word.
    fn say_waiting(&mut self, l: &Launch, reports: &BTreeMap<String, GraphState>) {
        let Some(at) = self.over_at(l) else { return };
        if self.said_waiting || self.run_time() < at + Nanos::SECOND {
            return;
        }
        let waiting: Vec<&str> = (l.names.iter())
            .filter(|p| !reports.contains_key(*p) && !self.gone.contains(*p))
            .map(String::as_str)
            .collect();
        if waiting.is_empty() {
            return;
        }
        self.said_waiting = true;
        let left = (at + Nanos::from(REPLY_TIMEOUT)).saturating_sub(self.run_time());
        l.say(&format!(
            "the run is over; waiting for the report of process(es) {} (at most {:.0} s more)",
            ratelab_core::text::listed(waiting),
            left.as_secs_f64()
        ));
    }

    /// Run time now.
    fn run_time(&self) -> Nanos {
        Nanos(wire::mono_now_ns().saturating_sub(self.start_mono))
    }

    /// Take the figures that came: a silent process heard again is said so; what a process
    /// other than the plant's counted is carried. A process whose figures stopped while its
    /// tokens live (frozen by SIGSTOP, starved or cut off) is said to be silent, long
    /// before Zenoh's lease declares it gone.
    fn hear_figures(&mut self, l: &Launch, stats_rx: &Receiver<LiveStats>, carried: &mut Carried) {
        for m in stats_rx.try_iter() {
            self.silence.heard(&m);
            if let Some(i) = self.silent.iter().position(|p| *p == m.process) {
                self.silent.remove(i);
                l.say(&format!(
                    "process '{}' is heard again at t={:.3}s",
                    m.process,
                    self.run_time().as_secs_f64()
                ));
            }
            if m.process != l.robot {
                carried.see(l.spec, &m);
            }
        }
        for (p, quiet) in self.silence.silent() {
            if self.end.is_none() && !self.gone.contains(&p) && !self.silent.contains(&p) {
                l.say(&format!(
                    "process '{p}' is silent at t={:.3}s: no figures for {:.1} s while its tokens live (stopped, starved or cut off?); it is gone if Zenoh's lease ({} s) runs out",
                    self.run_time().as_secs_f64(),
                    quiet.as_secs_f64(),
                    crate::LinkTimings::for_processes(l.names.len())
                        .lease
                        .as_secs()
                ));
                self.silent.push(p);
            }
        }
    }

    /// The kills asked for ([`super::LaunchOptions::kill_processes`]) whose time has come:
    /// each process killed (SIGKILL, as a crash), said, noted in `killed` and taken off
    /// `kills`. None once the run is over (its duration reached, its end, Ctrl-C), nor of a
    /// process that has ended or already exited.
    fn kill_due(&mut self, l: &Launch, children: &mut Children, kills: &mut Vec<(String, Nanos)>) {
        let now = self.run_time();
        if self.end.is_some() || l.stop.is_stopped() || now >= l.cfg.duration || kills.is_empty() {
            return;
        }
        kills.retain(|(p, at)| {
            if now < *at {
                return true;
            }
            let child = children.0.iter_mut().find(|(name, _)| name == p);
            // Still running (a child that exited, reaped or not, is not killed again).
            let child = child.map(|(_, c)| {
                let running = matches!(c.try_wait(), Ok(None));
                (c, running && !self.ended.contains(p))
            });
            match child {
                Some((_, false)) => {
                    l.say(&format!("process '{p}' had already exited: not killed"));
                }
                Some((c, true)) => match c.kill() {
                    Ok(()) => {
                        l.say(&format!(
                            "process '{p}' killed at t={:.3}s (--kill-process)",
                            now.as_secs_f64()
                        ));
                        self.killed.push((p.clone(), now));
                    }
                    Err(e) => l.say(&format!("process '{p}' could not be killed: {e}")),
                },
                None => l.say(&format!(
                    "process '{p}' was not started by this launch: not killed"
                )),
            }
            false
        });
    }

    /// A started process that failed mid-run starts again where the graph says so
    /// (`restart = "on-failure"`, at most [`MAX_RESTARTS`] times; not the plant's: the
    /// plant went with it).
    fn restart_failed(&mut self, l: &Launch, children: &mut Children) {
        if self.end.is_some() || l.stop.is_stopped() {
            return;
        }
        for (p, child) in &mut children.0 {
            let Ok(Some(status)) = child.try_wait() else {
                continue;
            };
            if status.success()
                || *p == l.robot
                || l.spec.restart.get(p.as_str()) != Some(&RestartPolicy::OnFailure)
                || self.given_up.contains(p)
            {
                continue;
            }
            let n = self.restarts.entry(p.clone()).or_insert(0);
            if *n >= MAX_RESTARTS {
                l.say(&format!(
                    "process '{p}' failed again ({status}): not started again (restarted {MAX_RESTARTS} times already)"
                ));
                self.given_up.push(p.clone());
                continue;
            }
            *n += 1;
            let n = *n;
            match l.start_process(p, false) {
                Ok(Some(c)) => {
                    l.say(&format!(
                        "process '{p}' failed ({status}) at t={:.3}s: starting it again (restart = \"on-failure\", {n} of {MAX_RESTARTS})",
                        self.run_time().as_secs_f64(),
                    ));
                    *child = c;
                }
                Ok(None) => {}
                Err(e) => {
                    l.say(&format!(
                        "process '{p}' failed ({status}); cannot start it again: {e}"
                    ));
                    self.given_up.push(p.clone());
                }
            }
        }
    }

    /// Processes whose liveliness token went: said, and the plant's ends the run.
    fn note_gone(&mut self, l: &Launch, gone: &GoneProcesses) {
        while let Some(p) = gone.next() {
            // A process that said it ended goes once its report is taken: not news.
            if !l.names.contains(&p) || self.ended.contains(&p) || self.gone.contains(&p) {
                continue;
            }
            self.silence.forget(&p);
            self.silent.retain(|s| *s != p);
            self.gone.push(p.clone());
            // After the run's end (frozen or dead before its report): not waited for more.
            if let Some(at) = self.over_at(l) {
                l.say(&format!(
                    "process '{p}' is gone {:.1} s after the run's end (its liveliness token was withdrawn): its report will not come",
                    self.run_time().saturating_sub(at).as_secs_f64()
                ));
                continue;
            }
            let plant = p == l.robot;
            if plant {
                // The plant died with it: the run cannot go on.
                self.end = Some(RunEnd {
                    at: self.run_time().min(l.cfg.duration),
                    reason: EndReason::NodeFailed {
                        node: l.spec.node(l.spec.actuator).name.clone(),
                        message: format!("process '{p}' (the plant's) is gone"),
                    },
                });
            }
            l.say(&format!(
                "process '{p}' is gone at t={:.3}s (its liveliness token was withdrawn); {}",
                self.run_time().as_secs_f64(),
                match plant {
                    true => "the run ends with it (the plant's)",
                    false => "the others run on",
                }
            ));
        }
    }

    /// Ctrl-C ends the run; once it has ended, every process is told to stop (once).
    fn stop_once_ended(&mut self, l: &Launch) {
        if l.stop.is_stopped() && self.end.is_none() {
            self.end = Some(RunEnd {
                at: self.run_time().min(l.cfg.duration),
                reason: EndReason::Interrupted,
            });
        }
        if let (Some(e), false) = (&self.end, self.stop_sent) {
            for p in &l.names {
                let _ = l.link.tell(
                    p,
                    &ToProcess::Stop {
                        at_ns: e.at.0,
                        need: Vec::new(),
                    },
                );
            }
            self.stop_sent = true;
        }
    }

    /// The next message to handle: a join told to wait whose process's last run is now
    /// gone, else what comes within 50 ms.
    fn next_message(&mut self, l: &Launch) -> Option<ToLauncher> {
        self.waiting_join.retain(|_, (asked, m)| {
            let pid = match m {
                ToLauncher::Join { pid, .. } => *pid,
                _ => 0,
            };
            asked.elapsed() < Duration::from_millis(300) && ratelab_core::procs::process_alive(pid)
        });
        let gone = &self.gone;
        let last_run_gone = self
            .waiting_join
            .keys()
            .find(|p| gone.contains(*p))
            .cloned();
        match last_run_gone.and_then(|p| self.waiting_join.remove(&p)) {
            Some((_, join)) => Some(join),
            None => l.link.recv(Duration::from_millis(50)),
        }
    }

    /// A process's message: a rejoin (welcomed, refused or told to wait), a rejoined
    /// process ready (started on the run's clock), a process's end, or its report.
    ///
    /// # Errors
    /// [`DistError`] when a rejoined process cannot be told to start.
    fn handle(
        &mut self,
        l: &Launch,
        m: ToLauncher,
        reports: &mut BTreeMap<String, GraphState>,
        wires: &mut Vec<wire::WireLink>,
    ) -> Result<(), DistError> {
        match m {
            // The ask of one just let in that crossed its welcome: already answered.
            ToLauncher::Join { process, pid, .. }
                if self.rejoining.contains(&process)
                    && self.welcomed_pid.get(&process) == Some(&pid) => {}
            // A process restarted mid-run rejoins on the same clock.
            m @ ToLauncher::Join { .. } if self.end.is_none() => {
                match l.admit(&m, true, &self.gone, &[]) {
                    Admission::Welcomed => {
                        let process = m.process().to_string();
                        if let ToLauncher::Join { pid, .. } = &m {
                            self.welcomed_pid.insert(process.clone(), *pid);
                        }
                        self.gone.retain(|g| *g != process);
                        // The process before it fell silent, not this one: no "silent" (then
                        // "heard again") about a process that has just rejoined.
                        self.silence.forget(&process);
                        self.silent.retain(|p| *p != process);
                        // Said at the run time the summary's wire line counts from, so that
                        // the log, the recording and the summary give the rejoin one time.
                        let at = self.run_time();
                        self.rejoined_at.insert(process.clone(), at);
                        l.say(&format!(
                            "process '{process}' rejoined at t={:.3}s",
                            at.as_secs_f64()
                        ));
                        self.rejoining.push(process);
                    }
                    Admission::Refused(r) | Admission::OtherGraph(r) => l.say_refused(&r),
                    // Started again before its last run's token went: it asks again.
                    Admission::Busy(_) => {
                        l.say_once(format!(
                            "process '{}' asks to rejoin before its last run's liveliness token went: it is let in once that goes (a second copy gives up)",
                            m.process()
                        ));
                        self.waiting_join
                            .insert(m.process().to_string(), (Instant::now(), m));
                    }
                    Admission::Ignored => {}
                }
            }
            ToLauncher::Ready { process }
                if self.end.is_none() && self.rejoining.contains(&process) =>
            {
                self.rejoining.retain(|p| *p != process);
                l.link.tell(
                    &process,
                    &ToProcess::Start {
                        start_mono_ns: self.start_mono,
                    },
                )?;
            }
            ToLauncher::Ended { process, end: e } => {
                self.ended.push(process);
                if e.reason != EndReason::Duration && self.end.is_none() {
                    self.end = Some(e);
                }
            }
            ToLauncher::Report {
                process,
                state,
                wire,
            } => {
                // Its tokens go after this receipt, not before the report is in.
                let _ = l.link.tell(&process, &ToProcess::ReportTaken);
                wires.retain(|w| w.process != process);
                let since = self.rejoined_at.get(&process).map(|t| t.0);
                wires.extend(wire.into_iter().map(|w| wire::WireLink {
                    since_ns: since,
                    ..w
                }));
                self.taken_at.insert(process.clone(), self.run_time());
                reports.insert(process, *state);
            }
            _ => {}
        }
        Ok(())
    }

    /// Whether supervision is over: every process has reported or is gone for good, or
    /// the run is [`REPLY_TIMEOUT`] past its duration or its end.
    fn over(&self, l: &Launch, reports: &BTreeMap<String, GraphState>) -> bool {
        let settled = |p: &String| {
            reports.contains_key(p) || (self.gone.contains(p) && !self.rejoining.contains(p))
        };
        if l.names.iter().all(settled) {
            return true;
        }
        let grace = Nanos::from(REPLY_TIMEOUT);
        self.run_time() > l.cfg.duration + grace
            || self.stop_sent
                && self.run_time() > self.end.as_ref().map_or(Nanos::ZERO, |e| e.at) + grace
    }
}
