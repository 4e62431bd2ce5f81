//! A graph across processes, recorded as a watcher sees it: the merged telemetry of a launch
//! (`ratelab::distributed::monitor` folds the processes' reports into it) written into a
//! [`Recording`], for `ratelab launch --record`.

use crate::{GraphShape, Recording, RecordingError, RunConfig};
use ratelab_core::msg::ForceMsg;
use ratelab_core::time::Nanos;
use ratelab_core::topic::{Subscription, TopicStats};
use ratelab_runtime::telemetry::Telemetry;
use std::sync::{Arc, Mutex};

/// The level a launcher's line is recorded at: a warning for what went wrong (a process
/// killed, gone, failed, silent; a join or a report refused), information for the rest
/// (listening, ready, rejoined, heard again).
fn launcher_line_level(line: &str) -> &'static str {
    const TROUBLE: [&str; 6] = [
        " killed at t=",
        " is gone",
        " failed",
        " is silent",
        "refused ",
        "does not apply",
    ];
    if TROUBLE.iter().any(|t| line.contains(t)) {
        "WARN"
    } else {
        "INFO"
    }
}

/// Record what a watcher sees of a run across processes into `rec`, until `telemetry` is
/// closed: each merged step (the plant, the latency, every topic's counters as its holder
/// reported them; the force the policy published, from the step), each node tick's
/// lateness (real clock), the launcher's lines as events, and each node's liveliness token
/// going and coming back as events. Every event is on the launcher's run clock: a
/// launcher's line at the run time it states (`… rejoined at t=3.110s`, the time its
/// summary gives too), and the rest at the newest run time known, any process's
/// ([`Telemetry::Status`]'s `now`) or a line's stated one, so an event is never stamped
/// before one the launcher said before it. The caller finishes the recording with the
/// merged summary ([`Recording::finish`]).
///
/// What differs from an in-process recording: a topic held by another process shows its
/// counters as that process sampled them after its newest tick no later than the step (not
/// at the step itself); the published force is the newest per actuator step; leases are
/// not recorded (liveliness is the tokens'). So it is not byte-identical to the in-process recording, even under the
/// virtual clock (`metrics.json` is).
///
/// # Errors
/// [`RecordingError::Graph`] when the graph's topics cannot be made for the view (a
/// validated config has none that cannot).
pub fn record(
    rec: &Recording,
    cfg: &RunConfig,
    telemetry: &crossbeam_channel::Receiver<Telemetry>,
) -> Result<(), RecordingError> {
    let spec = &cfg.graph;
    let counters: Arc<Mutex<Vec<TopicStats>>> =
        Arc::new(Mutex::new(vec![TopicStats::default(); spec.topics.len()]));
    // The policy's published forces, when the graph has the chapter's chain.
    let commands = spec
        .chain
        .map(|c| Subscription::new(spec.topic(c.action).name.clone(), 1).map(Arc::new))
        .transpose()
        .map_err(|e| RecordingError::Graph(e.to_string()))?;
    let shape = GraphShape::from_spec(spec, counters.clone(), commands.clone())
        .map_err(|e| RecordingError::Graph(e.to_string()))?;
    let mut observer = rec.observer_for(shape);
    let mut alive: Vec<Option<bool>> = vec![None; spec.nodes.len()];
    // Per node: said not alive, and not yet alive again (a node whose token has not come
    // yet at the start is not alive to the watcher, but its coming is no return).
    let mut said_gone = vec![false; spec.nodes.len()];
    let mut now = Nanos::ZERO;
    for t in telemetry {
        match t {
            Telemetry::Step(s) => {
                now = now.max(s.t);
                *ratelab_runtime::graph::lock(&counters) = s.topics.iter().copied().collect();
                if let (Some((at, newtons)), Some(c)) = (s.published, &commands) {
                    c.publish(ForceMsg { newtons }, at, None);
                }
                observer.on_step(&s);
            }
            Telemetry::NodeTick {
                node,
                now: at,
                lateness,
                ..
            } => {
                if let Some(n) = spec.nodes.get(node) {
                    rec.node_tick(&n.name, at, lateness);
                }
            }
            Telemetry::Wire(links) => {
                for (i, p50_us, p99_us) in links {
                    if let Some(t) = spec.topics.get(i) {
                        rec.wire(now, &t.name, p50_us, p99_us);
                    }
                }
            }
            // A launcher's line says when it happened (`at t=5.570s`, its run clock): placed
            // there, and the events after it are not stamped before it.
            Telemetry::Applied(line) => {
                let at = super::events::stated_time(&line).unwrap_or(now);
                now = now.max(at);
                rec.event(at, &line, launcher_line_level(&line));
            }
            Telemetry::Error(line) => rec.event(now, &line, "WARN"),
            Telemetry::NotStarted(line) => rec.event(now, &line, "ERROR"),
            Telemetry::Status {
                now: seen,
                alive: next,
                ..
            } => {
                // The newest run time any process reported: events are stamped by it, not
                // by the newest step shown, which waits for every holder's figures (a
                // process gone and its rejoin were both stamped at the step before).
                now = now.max(seen);
                for (i, (was, is)) in alive.iter_mut().zip(next).enumerate() {
                    let name = &spec.nodes[i].name;
                    match (*was, is) {
                        (Some(true), Some(false)) => {
                            said_gone[i] = true;
                            rec.event(
                                now,
                                &format!("node {name} not alive (its process's liveliness token was withdrawn, or its process is silent)"),
                                "WARN",
                            );
                        }
                        (Some(false), Some(true)) if said_gone[i] => {
                            said_gone[i] = false;
                            rec.event(now, &format!("node {name} alive again"), "INFO");
                        }
                        _ => {}
                    }
                    *was = is;
                }
            }
            _ => {}
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_launchers_trouble_is_recorded_as_a_warning() {
        for (line, level) in [
            ("launch: process 'policy' is gone at t=3.21s (its liveliness token was withdrawn); the others run on", "WARN"),
            ("launch: process 'policy' failed (signal: 9) at t=2.31s: starting it again", "WARN"),
            ("launch: process 'policy' killed at t=3.027s (--kill-process)", "WARN"),
            ("launch: process 'policy' had already exited: not killed", "INFO"),
            ("launch: process 'robot' is silent at t=4.00s: no figures for 1.0 s", "WARN"),
            ("launch: refused a join: process 'policy' is already running", "WARN"),
            ("launch: process 'policy' rejoined at t=3.110s", "INFO"),
            ("launch: process 'robot' is heard again", "INFO"),
            ("launch: listening on tls/127.0.0.1:7449", "INFO"),
        ] {
            assert_eq!(launcher_line_level(line), level, "{line}");
        }
    }
}
