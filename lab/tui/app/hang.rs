//! A learner's callback that does not return, as the lab's state sees it: which node it
//! holds (the verdict `HUNG`, its box's `in callback`), and Ctrl-C, which interrupts it as
//! Ctrl-C does in a headless run before it quits the lab.

use super::*;
use crate::tui::view::HeldIn;

/// A call into the code of the run on screen that has not returned for [`HUNG_AFTER`] or
/// longer ([`App::hung_callback`]).
#[derive(Clone, Debug, PartialEq)]
pub(super) struct HungCall {
    /// The node whose call it is.
    pub node: String,
    /// A tick's callback (or the brain's call), or the node's script loading.
    pub held_in: HeldIn,
    /// How long it has run, s (wall time).
    pub running_s: f64,
}

impl App {
    /// A learner's callback in this process (a Python node's tick, the brain's call) that
    /// (or its script's loading) that has not returned for [`HUNG_AFTER`] or longer. `None`
    /// in an attached lab (the graph's code runs in other processes). A save's trial is not
    /// the run on screen: its calls are never this ([`ratelab::python::enter_trial`]).
    pub(super) fn hung_callback(&self) -> Option<HungCall> {
        if self.attached.is_some() {
            return None;
        }
        let call = ratelab::python::running_callbacks(HUNG_AFTER)
            .into_iter()
            .next()?;
        // A brain's call is its node's: the one whose kind runs the brain.
        let node = call.node.or_else(|| {
            self.graph
                .nodes
                .iter()
                .find(|n| n.kind.def().uses_brain)
                .map(|n| n.name.clone())
        })?;
        Some(HungCall {
            node,
            held_in: if call.loading {
                HeldIn::Loading
            } else {
                HeldIn::Callback
            },
            running_s: call.running_for.as_secs_f64(),
        })
    }

    /// Ctrl-C: a callback of the run on screen hung ([`App::hung_callback`]) is interrupted
    /// (Python's `KeyboardInterrupt`, as Ctrl-C does in a headless run: its node fails,
    /// saying where it was, and the run ends there, so a save starts the next); a second
    /// Ctrl-C while that call still has not returned (a sleep in C code) quits. With only a
    /// save's trial hung (not the run on screen), the first says so; the second quits. With
    /// nothing hung, it quits.
    pub(super) fn interrupt(&mut self) {
        let since = self.interrupted_at.map(|at| at.elapsed().as_secs_f64());
        match self.hung_callback() {
            // The call hung now began before the last Ctrl-C: that one did not end it.
            Some(h) if since.is_some_and(|e| e <= h.running_s) => self.on_msg(Msg::Quit),
            Some(HungCall {
                node,
                held_in,
                running_s: s,
            }) => {
                if ratelab::python::interrupt_hung_callbacks(HUNG_AFTER).is_empty() {
                    // It returned meanwhile: nothing to interrupt.
                    return self.on_msg(Msg::Quit);
                }
                self.interrupted_at = Some(std::time::Instant::now());
                let what = match held_in {
                    HeldIn::Callback => "callback",
                    HeldIn::Loading => "script's loading",
                };
                self.say(format!(
                    "Ctrl-C: {node}'s {what}, {s:.1} s without returning, interrupted (KeyboardInterrupt) · Ctrl-C again quits"
                ));
            }
            None if since.is_none_or(|e| e > CTRL_C_AGAIN_S)
                && ratelab::python::trial_hung(HUNG_AFTER) =>
            {
                self.interrupted_at = Some(std::time::Instant::now());
                self.say(
                    "Ctrl-C: the run on screen is not hung, a reload's trial is (save again to cancel it, r drops it) · Ctrl-C again quits"
                        .into(),
                );
            }
            None => self.on_msg(Msg::Quit),
        }
    }
}

/// A Ctrl-C within this long (s) of one that said a reload's trial is hung quits.
const CTRL_C_AGAIN_S: f64 = 10.0;
