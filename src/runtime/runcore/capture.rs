//! Capture and restore, and seeking by them: the run's complete state at an instant
//! ([`Capture`]), put back whole ([`RunCore::restore`]) so that running on is the run's own
//! continuation, byte for byte; the captures a run core keeps as it goes, and a seek to any
//! instant from the nearest of them ([`RunCore::seek`]). See [`super`]'s module docs.

use super::*;

/// Why [`RunCore::restore`] could not restore a capture. The run is unchanged.
#[derive(Debug, thiserror::Error)]
pub enum RestoreError {
    /// The capture was taken of another graph: another run core's, or this one's before a
    /// restore that replayed (a capture restores into the graph it was taken of, whose
    /// topics a held publish refers to).
    #[error("this capture is of another graph")]
    OtherGraph,
    /// The capture is a replay and no brain factory was given.
    #[error(
        "this capture must be replayed from t = 0, and the run core cannot make its brain again"
    )]
    CannotReplay,
    /// Seeking back with no capture kept at or before the instant
    /// ([`CoreOptions::history_every`]).
    #[error("no capture kept to seek back to {0}")]
    NoHistory(Nanos),
    /// Seeking back into, or across to a time after, a part of the run the real clock ran
    /// ([`RunCore::run_real`]) from a capture before it: that part cannot be run again.
    #[error("the real clock ran {from} to {to} of this run: that part cannot run again")]
    RealPart {
        /// Where the part began, run time.
        from: Nanos,
        /// Where it ended.
        to: Nanos,
    },
    /// Replaying the run to the captured instant failed.
    #[error("replaying the run to {at}: {reason}")]
    Replay {
        /// The captured instant.
        at: Nanos,
        /// Why.
        reason: String,
    },
}

/// A run's state at an instant ([`RunCore::capture`]).
pub struct Capture {
    /// The graph it was taken of ([`RunCore::graph_id`]).
    graph_id: u64,
    at: Nanos,
    /// The commands applied up to the capture, each at the instant before which it took
    /// effect.
    applied: Vec<TimedCommand>,
    /// Those of them applied by hand ([`RunCore::apply`]).
    by_hand: Vec<TimedCommand>,
    next_scheduled: usize,
    end: Option<RunEnd>,
    /// The parts of the run the real clock ran by then, `(from, to)` run times.
    real_parts: Vec<(Nanos, Nanos)>,
    state: Option<Box<Saved>>,
}

impl Capture {
    /// The run time captured: the newest instant that had run (0 before any).
    pub fn at(&self) -> Nanos {
        self.at
    }

    /// True when restoring this capture replays the run from t = 0 (some part of the graph
    /// could not be captured; module docs).
    pub fn is_replay(&self) -> bool {
        self.state.is_none()
    }
}

/// The parts of a captured state (module docs).
pub(super) struct Saved {
    plant: PlantState,
    nodes: Vec<NodeState>,
    topics: Vec<TopicSnapshot>,
    liveliness: Vec<LivelinessState>,
    rates_hz: Vec<f64>,
    /// The faults injected by command so far, with their nodes.
    faults: Vec<(ratelab_core::ids::NodeId, ratelab_core::qos::Fault)>,
    brain: Box<dyn Policy>,
    log: RunLog,
    executor: Option<ExecutorOverride>,
    plan_request: Option<ExecutionPlan>,
    phase_request: Vec<(ratelab_core::ids::NodeId, Nanos)>,
    sched: VirtualScheduler,
}

impl RunCore {
    /// Keep a capture for seeking when one is due (module docs: [`CoreOptions::history_every`],
    /// [`max_history`]).
    pub(super) fn keep_history(&mut self) {
        let Some(every) = self.history_every else {
            return;
        };
        let now = self.sched.now();
        if now < self.next_history && !self.history.is_empty() {
            return;
        }
        let capture = self.capture();
        if capture.is_replay() && !self.real_parts.is_empty() {
            // It could not be restored (a replay cannot give the real clock's part): none
            // is kept, and none tried again before the next is due.
            self.next_history = now.saturating_add(self.history_every.unwrap_or(every));
            return;
        }
        self.history.push(capture);
        if self.history.len() > self.max_history {
            // Keep the first (t = 0) and every other one after it.
            let mut k = 0;
            self.history.retain(|_| {
                k += 1;
                k % 2 == 1
            });
            self.history_every = Some(Nanos(every.0.saturating_mul(2)));
        }
        let every = self.history_every.unwrap_or(every);
        self.next_history = now.saturating_add(every);
    }

    /// The run times of the captures kept for seeking, oldest first.
    pub fn history(&self) -> impl Iterator<Item = Nanos> + '_ {
        self.history.iter().map(Capture::at)
    }

    /// Put the run at run time `t`: as it was right after its last instant at or before
    /// `t`. Forward it runs on. Back it restores the newest capture kept at or before `t`
    /// and runs on from there to `t`, applying again, at the instants they took effect, the
    /// commands applied by hand in between ([`RunCore::apply`]; scheduled ones come again
    /// from their schedule), and forgets what came after `t`: the run branches there, and
    /// what is applied next is a new future (what `replay` of [`RunCore::applied`] then
    /// gives). Step observers see the instants run again.
    ///
    /// # Errors
    /// [`RestoreError::NoHistory`] when no capture is kept at or before `t`;
    /// [`RestoreError::RealPart`] when the real clock ran part of the run between that
    /// capture and `t`; or what the restore met. The run is then unchanged.
    pub fn seek(&mut self, t: Nanos) -> Result<(), RestoreError> {
        if t >= self.sched.now() {
            self.run_until(t);
            return Ok(());
        }
        let k = self
            .history
            .iter()
            .rposition(|c| c.at <= t)
            .ok_or(RestoreError::NoHistory(t))?;
        let from_capture = self.history[k].at;
        if let Some(&(from, to)) = self
            .real_parts
            .iter()
            .find(|&&(from, to)| from < t && to > from_capture)
        {
            return Err(RestoreError::RealPart { from, to });
        }
        let by_hand = self.by_hand.clone();
        let mut kept = self.history.split_off(k);
        let from = kept.swap_remove(0);
        if let Err(e) = self.restore_keeping_history(&from) {
            self.history.push(from);
            self.history.append(&mut kept);
            return Err(e);
        }
        let mut again = by_hand
            .into_iter()
            .skip(from.by_hand.len())
            .filter(|c| c.at_ns <= t.0)
            .peekable();
        self.next_history = from
            .at
            .saturating_add(self.history_every.unwrap_or_default());
        self.history.push(from);
        while let Some(due) = self.next_instant().filter(|&due| due <= t) {
            while let Some(c) = again.next_if(|c| c.at_ns <= due.0) {
                // It was applied once; the graph is as it was then.
                let _ = c.command.apply(&self.handles, Nanos(c.at_ns));
                self.applied.push(c.clone());
                self.by_hand.push(c);
            }
            self.take_plan();
            if !self.step_within(t) {
                break;
            }
        }
        Ok(())
    }

    /// The run's complete state now, between instants (module docs): restoring it and
    /// running on gives this run's continuation, byte for byte.
    pub fn capture(&self) -> Capture {
        Capture {
            graph_id: self.graph_id,
            at: self.sched.now(),
            applied: self.applied.clone(),
            by_hand: self.by_hand.clone(),
            next_scheduled: self.next_scheduled,
            end: self.end.clone(),
            real_parts: self.real_parts.clone(),
            state: self.save().map(Box::new),
        }
    }

    pub(super) fn save(&self) -> Option<Saved> {
        let h = &self.handles;
        let nodes = self
            .nodes
            .iter()
            .map(|n| n.save())
            .collect::<Option<Vec<_>>>()?;
        Some(Saved {
            brain: h.brain.save()?,
            plant: lock(&h.plant).save(),
            nodes,
            topics: h
                .topics
                .iter()
                .map(ratelab_core::msg::AnyTopic::save)
                .collect(),
            liveliness: h.liveliness.iter().map(|l| l.save()).collect(),
            rates_hz: h.rates.iter().map(ratelab_core::rate::Rate::hz).collect(),
            faults: h.faults.save(),
            log: lock(&h.log).clone(),
            executor: *lock(&h.executor),
            plan_request: lock(&h.plan_request).clone(),
            phase_request: h.phase_request.save(),
            sched: self.sched.clone(),
        })
    }

    /// Put the run back as `capture` found it (module docs), whatever ran or was applied
    /// since: in place, or by replaying the run from t = 0 when the capture is a replay.
    /// The captures kept for seeking are forgotten (they may be of another branch of the
    /// run); new ones are kept from here.
    ///
    /// # Errors
    /// [`RestoreError`]; the run is then unchanged.
    pub fn restore(&mut self, capture: &Capture) -> Result<(), RestoreError> {
        self.restore_keeping_history(capture)?;
        self.history.clear();
        self.next_history = capture.at;
        self.keep_history();
        Ok(())
    }

    pub(super) fn restore_keeping_history(
        &mut self,
        capture: &Capture,
    ) -> Result<(), RestoreError> {
        match &capture.state {
            Some(_) if capture.graph_id != self.graph_id => return Err(RestoreError::OtherGraph),
            Some(saved) => self.load(saved)?,
            None => self.replay(capture)?,
        }
        self.applied.clone_from(&capture.applied);
        self.by_hand.clone_from(&capture.by_hand);
        self.next_scheduled = capture.next_scheduled;
        self.end.clone_from(&capture.end);
        self.real_parts.clone_from(&capture.real_parts);
        Ok(())
    }

    pub(super) fn load(&mut self, s: &Saved) -> Result<(), RestoreError> {
        let h = &self.handles;
        if s.nodes.len() != self.nodes.len()
            || s.topics.len() != h.topics.len()
            || s.liveliness.len() != h.liveliness.len()
            || s.rates_hz.len() != h.rates.len()
        {
            return Err(RestoreError::OtherGraph);
        }
        // The plant first: the one part that can refuse without a change elsewhere.
        lock(&h.plant)
            .load(&s.plant)
            .map_err(|_| RestoreError::OtherGraph)?;
        for (node, state) in self.nodes.iter_mut().zip(&s.nodes) {
            if !node.load(state) {
                return Err(RestoreError::OtherGraph);
            }
        }
        for (topic, state) in h.topics.iter().zip(&s.topics) {
            if !topic.load(state) {
                return Err(RestoreError::OtherGraph);
            }
        }
        for (l, state) in h.liveliness.iter().zip(&s.liveliness) {
            l.load(*state);
        }
        for (rate, &hz) in h.rates.iter().zip(&s.rates_hz) {
            // The rate was valid when captured.
            let _ = rate.set_hz(hz);
        }
        h.faults.load(&s.faults);
        h.brain.load(s.brain.as_ref());
        lock(&h.log).clone_from(&s.log);
        *lock(&h.executor) = s.executor;
        lock(&h.plan_request).clone_from(&s.plan_request);
        h.phase_request.load(&s.phase_request);
        self.sched.load(&s.sched);
        Ok(())
    }

    pub(super) fn replay(&mut self, capture: &Capture) -> Result<(), RestoreError> {
        let remake = self
            .remake_brain
            .as_ref()
            .ok_or(RestoreError::CannotReplay)?;
        let failed = |reason: String| RestoreError::Replay {
            at: capture.at,
            reason,
        };
        if let Some(&(from, to)) = capture.real_parts.first() {
            let what = if from == to {
                "restarted a node in place"
            } else {
                "went under the real clock"
            };
            return Err(failed(format!(
                "the run {what} at {from}, which a replay cannot give"
            )));
        }
        let brain = remake().map_err(failed)?;
        let mut fresh = RunCore::new(
            &self.cfg,
            brain,
            CoreOptions {
                keep_trace: self.keep_trace,
                observers: self
                    .remake_observers
                    .as_ref()
                    .map(|f| f())
                    .unwrap_or_default(),
                commands: capture.applied.clone(),
                on_span: self.on_span.clone(),
                remake_brain: None,
                remake_observers: None,
                history_every: None,
            },
        )
        .map_err(|e| failed(e.to_string()))?;
        fresh.run_until(capture.at);
        // Commands applied after the captured instant ran (logged at the next one).
        while let Some(c) = fresh.scheduled.get(fresh.next_scheduled) {
            c.command
                .apply(&fresh.handles, Nanos(c.at_ns))
                .map_err(|e| failed(e.clone()))?;
            fresh.next_scheduled += 1;
        }
        fresh.take_plan();
        if fresh.sched.now() != capture.at && capture.at != Nanos::ZERO {
            return Err(failed(format!("the replay reached {}", fresh.sched.now())));
        }
        self.graph_id = fresh.graph_id;
        self.nodes = fresh.nodes;
        self.handles = fresh.handles;
        self.sched = fresh.sched;
        Ok(())
    }
}
