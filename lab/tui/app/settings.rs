//! The keys that change a setting of the running graph beyond its rates: the selected
//! topic's QoS (`f d L l e o`) and depth (`[ ]`), a node's phase offset (`P`); and the line
//! that explains a reliable topic's losses the first time the run counts one.

use super::*;

/// What the footer says the first time a reliable topic counts a loss in a run (`/action:
/// lost though reliable · …`): a reliable link resends a lost message, and counts it lost
/// only once all [`ratelab::qos::MAX_ATTEMPTS`] of its sends were lost.
fn reliable_loss_line(topic: &str) -> String {
    format!(
        "{topic}: lost though reliable · a message counts lost once all {} of its sends are lost (retx: the resends)",
        ratelab::qos::MAX_ATTEMPTS
    )
}

impl App {
    /// The selected topic's QoS, one key at a time: `f` latest ↔ fifo, `d` the next
    /// deadline of [`DEADLINES_MS`], `L` the next link loss of [`LOSSES`], `l` the next
    /// lifespan of [`LIFESPANS_MS`], `e` best effort ↔ reliable, `o` the actuator's
    /// reaction to a missed deadline (hold → zero → stop). Each change is a logged command,
    /// so it replays; one the graph refuses (e.g. `o` on a topic without a deadline) is
    /// refused with the reason on the status line.
    pub(super) fn change_qos(&mut self, m: Msg) {
        let Some(Selected::Topic(t)) = self.selected else {
            self.say(
                "select a topic with Tab first: f d L l e o change the selected topic's QoS".into(),
            );
            return;
        };
        let q = self
            .qos
            .get(t.0)
            .copied()
            .unwrap_or(self.graph.topic(t).qos);
        let pairs = match m {
            Msg::ToggleDelivery => match q.delivery {
                Delivery::Latest => "delivery=fifo".to_string(),
                Delivery::Fifo => "delivery=latest".to_string(),
            },
            Msg::CycleDeadline => {
                let now_ms = q.deadline.map(|d| d.as_millis_f64());
                let next = next_in_cycle(&DEADLINES_MS, now_ms.unwrap_or(0.0));
                if next == 0.0 {
                    // Off again: without a deadline there is no reaction either.
                    "deadline_ms=none,on_deadline_missed=hold".to_string()
                } else {
                    format!("deadline_ms={next}")
                }
            }
            Msg::CycleLoss => {
                let loss = q.link.map_or(0.0, |l| l.loss);
                format!("loss={}", next_in_cycle(&LOSSES, loss))
            }
            Msg::CycleLifespan => {
                let now_ms = q.lifespan.map_or(0.0, |d| d.as_millis_f64());
                let next = next_in_cycle(&LIFESPANS_MS, now_ms);
                if next == 0.0 {
                    "lifespan_ms=none".to_string()
                } else {
                    format!("lifespan_ms={next}")
                }
            }
            Msg::ToggleReliability => match q.reliability {
                Reliability::BestEffort => "reliability=reliable".to_string(),
                Reliability::Reliable => "reliability=best_effort".to_string(),
            },
            Msg::CycleOnDeadlineMissed => {
                // Said here in a line that fits 80 columns (the graph would refuse it too).
                let actuator = self.graph.actuator;
                if !self.graph.topic(t).subscribers.contains(&actuator) {
                    let read = self
                        .graph
                        .topics
                        .iter()
                        .find(|x| x.subscribers.contains(&actuator))
                        .map_or_else(String::new, |x| format!(" ({})", x.name));
                    self.say(format!(
                        "o: the actuator's reaction: select the topic it reads{read}"
                    ));
                    return;
                }
                if q.deadline.is_none() && q.on_deadline_missed == OnDeadlineMissed::Hold {
                    self.say("o: reacts to a missed deadline: set one first with d".into());
                    return;
                }
                let next = match q.on_deadline_missed {
                    OnDeadlineMissed::Hold => "zero",
                    OnDeadlineMissed::Zero => "stop",
                    OnDeadlineMissed::Stop => "hold",
                };
                format!("on_deadline_missed={next}")
            }
            _ => return,
        };
        let topic = self.graph.topic(t).name.clone();
        self.apply(Command::SetTopicQos { topic, pairs });
    }

    /// Step the selected topic's depth, or every topic's (as one command) when none is.
    pub(super) fn change_depth(&mut self, step: fn(usize) -> usize) {
        match self.selected {
            Some(Selected::Topic(t)) => {
                let depth = step(self.depths.get(t.0).copied().unwrap_or(1));
                if let Some(d) = self.depths.get_mut(t.0) {
                    *d = depth;
                }
                let topic = self.graph.topic(t).name.clone();
                self.apply(Command::SetTopicDepth { topic, depth });
            }
            _ => {
                let depth = step(self.depths.first().copied().unwrap_or(1));
                self.depths.iter_mut().for_each(|d| *d = depth);
                self.apply(Command::SetQueueDepth { depth });
            }
        }
    }

    /// `P`: the selected node's (else the policy's) phase offset, the next of [`PHASES_MS`]
    /// after its own, from the next instant on: its ticks then fall on `phase + k·period`
    /// (`Command::SetPhase`, logged, so a session replays it). The engine takes it under the
    /// virtual clock only, and not after the run ended (it says why): the lab steps its own
    /// figure only where the engine takes it, and again from the engine's word
    /// ([`App::note_phase`]).
    pub(super) fn cycle_phase(&mut self) {
        let n = self.rate_target();
        let now = self.phases.get(n.0).copied().unwrap_or(0.0);
        let phase_ms = next_in_cycle(&PHASES_MS, now);
        if self.clock == "virtual" && self.ended_with.is_none() {
            if let Some(p) = self.phases.get_mut(n.0) {
                *p = phase_ms;
            }
        }
        let node = self.graph.node(n).name.clone();
        self.apply(Command::SetPhase { node, phase_ms });
    }

    /// The engine's word for a phase change it made (`phase policy → 5 ms`, as
    /// [`ratelab::session::describe`] says it): the node's phase offset from then on. A seek
    /// back folds the run's words again, so the phase shown and stepped is the run's then.
    pub(super) fn note_phase(&mut self, text: &str) {
        let Some((node, ms)) = text
            .strip_prefix("phase ")
            .and_then(|t| t.rsplit_once(" → "))
        else {
            return;
        };
        let Some(ms) = ms.strip_suffix(" ms").and_then(|m| m.parse::<f64>().ok()) else {
            return;
        };
        if let Some(i) = self.graph.nodes.iter().position(|n| n.name == node) {
            if let Some(p) = self.phases.get_mut(i) {
                *p = ms;
            }
        }
    }

    /// After step `s`: a reliable topic that counts its first loss of the run under reliable
    /// delivery has it explained in the footer ([`reliable_loss_line`]), once a topic and run
    /// (a seek back, folding the run again, does not say it again). Losses counted while
    /// the topic was best effort (before `R` made it reliable) are not reliable delivery's.
    pub(super) fn explain_reliable_losses(&mut self, s: &StepRecord) {
        let n = self.qos.len().min(self.graph.topics.len());
        self.lost_before_reliable.resize(n, None);
        self.lost_at_last_step.resize(n, 0);
        let mut fresh = Vec::new();
        for i in 0..n {
            let lost = s.topics.get(TopicId(i)).lost;
            let before = &mut self.lost_before_reliable[i];
            if self.qos[i].reliability == Reliability::Reliable {
                // Made reliable since the last step (or reliable from the start: 0). A
                // step before it (the run folded again after a seek back) is not judged.
                let (from, since) = *before.get_or_insert((s.t, self.lost_at_last_step[i]));
                if s.t >= from && lost > since && !self.explained_losses.contains(&TopicId(i)) {
                    fresh.push(TopicId(i));
                }
            } else {
                *before = None;
            }
            self.lost_at_last_step[i] = lost;
        }
        for id in fresh {
            self.explained_losses.push(id);
            if !self.rewinding {
                let line = reliable_loss_line(&self.graph.topic(id).name);
                self.say(line);
            }
        }
    }
}
