//! Commands to a running graph — a rate, a depth, a QoS, a brain, the executors, a phase
//! offset, a fault — as the lab's keys, a session log and `replay` give them ([`Command`]), and stamped with the run
//! time they take effect at ([`TimedCommand`]).

use crate::graph::GraphHandles;

/// A change to a running graph. Under the virtual clock each is applied at a virtual
/// instant, so a logged session replays exactly.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(tag = "cmd", rename_all = "snake_case")]
pub enum Command {
    /// Set the policy rate, Hz.
    SetControlHz {
        /// New rate.
        hz: f64,
    },
    /// Set the sensor rate, Hz.
    SetSensorHz {
        /// New rate.
        hz: f64,
    },
    /// Set every topic's history depth.
    SetQueueDepth {
        /// New depth (≥ 1).
        depth: usize,
    },
    /// Set one node's rate, Hz.
    SetNodeHz {
        /// The node's name.
        node: String,
        /// New rate.
        hz: f64,
    },
    /// Set one topic's history depth.
    SetTopicDepth {
        /// The topic's name.
        topic: String,
        /// New depth (≥ 1).
        depth: usize,
    },
    /// Set one topic's QoS keys (`KEY=VALUE[,KEY=VALUE…]`, the graph file's keys; see
    /// [`ratelab_core::qos`]): the lab's `f` (delivery), `d` (deadline) and `L` (link loss).
    SetTopicQos {
        /// The topic's name.
        topic: String,
        /// The keys and values.
        pairs: String,
    },
    /// Swap the policy node's brain (`scripted` or a checkpoint path).
    SetPolicy {
        /// The brain spec, as `--policy` takes it.
        spec: String,
    },
    /// Run the graph on other executors, as `--executor` takes them (`per_node`,
    /// `single_threaded`, `multi_threaded:N`): the lab's `x`. Under the virtual clock it
    /// takes effect at the instant it is applied (ticks running keep their threads); under
    /// the real clock, whose threads are made when a run starts, from the next run.
    SetExecutor {
        /// The executors, as `--executor` takes them.
        executor: String,
    },
    /// Put a node's ticks on a new grid, `phase + k·period`, from the next instant on: its
    /// phase offset (as `--phase-offset-ms` gives it at the start, in [0, 1000) ms), its rate
    /// unchanged. Under the virtual clock only (the real clock's threads keep the grid they
    /// started on). A new run starts at its settings' phase offsets.
    SetPhase {
        /// The node's name.
        node: String,
        /// Its new phase offset, ms.
        phase_ms: f64,
    },
    /// Inject a fault into a node while the run goes on, as `--stall` and `--kill` give one
    /// at the start: `NODE@T+D` stalls it from run time T for D, `NODE@T` kills it from T
    /// (seconds, or with an `s` or `ms` suffix). A faulted tick does no work and asserts no
    /// liveliness; a time already past covers the ticks from now on. The summary lists it
    /// with the node's faults. A fault is an event of the run it is injected into: a new run
    /// does not keep it.
    InjectFault {
        /// The fault, `NODE@T+D` or `NODE@T`.
        fault: String,
    },
    /// [`Command::InjectFault`] as a session log of version 2 or before holds it: booked at
    /// the time it was given, not from the instant it took effect, as those runs booked it
    /// (their summaries list that time, which a replay compares). Read from such a log
    /// only (`ratelab::session::LoggedRun::spec`); never written.
    InjectFaultAsGiven {
        /// The fault, `NODE@T+D` or `NODE@T`.
        fault: String,
    },
}

/// Fault `f` injected before the instant at `at` (run time), as it takes effect
/// ([`ratelab_core::qos::Fault::from_instant`]): what a run's fault book holds, its summary
/// and its telemetry give.
///
/// # Errors
/// One line for a stall over before `at`: it would name a stall that never was.
pub fn taking_effect(
    f: &ratelab_core::qos::Fault,
    at: ratelab_core::time::Nanos,
) -> Result<ratelab_core::qos::Fault, String> {
    let from = f.from_instant(at);
    if from.duration == Some(ratelab_core::time::Nanos::ZERO) {
        return Err(format!(
            "{f}: over at {} s, before the instant it would take effect ({} s)",
            f.at.saturating_add(f.duration.unwrap_or_default())
                .as_secs_f64(),
            at.as_secs_f64()
        ));
    }
    Ok(from)
}

/// A stall of `node` for `duration` from run time `at`, as the command that injects it:
/// `NODE@T+D`, both times in seconds to the nanosecond (`policy@9.380000000+0.500000000`),
/// which [`parse_fault`] reads back exactly.
pub fn stall_from(
    node: &str,
    at: ratelab_core::time::Nanos,
    duration: ratelab_core::time::Nanos,
) -> Command {
    Command::InjectFault {
        fault: format!("{node}@{}+{}", at.secs_exact(), duration.secs_exact()),
    }
}

/// `NODE@T+D` (a stall) or `NODE@T` (a kill), as [`Command::InjectFault`] gives it.
///
/// # Errors
/// One line saying what is wrong ([`ratelab_core::qos::Fault::parse`]).
pub fn parse_fault(text: &str) -> Result<ratelab_core::qos::Fault, String> {
    // A stall has a duration after its time (`@T+D`); a node's name has no `@`.
    let stall = text
        .split_once('@')
        .is_some_and(|(_, when)| when.contains('+'));
    ratelab_core::qos::Fault::parse(text, !stall)
}

impl Command {
    /// Apply to the settings a run starts with: `graph`'s rates and depths, the brain
    /// spec `policy`. The checks are the command line's: rates in (0, 10 000] Hz (the
    /// actuator at 50), depths in 1..=[`ratelab_core::qos::MAX_DEPTH`], names that exist.
    /// A brain is not loaded here (see [`Command::validate`]).
    ///
    /// # Errors
    /// One line saying what is wrong; nothing changes.
    pub fn apply_to_settings(
        &self,
        graph: &mut crate::graph::GraphSpec,
        policy: &mut String,
    ) -> Result<(), String> {
        match self {
            Command::SetControlHz { hz } => crate::config::check_rate("control-hz", *hz)
                .and_then(|_| {
                    let id = graph
                        .chain_for("the control rate", crate::setting::Speech::Flags)?
                        .policy;
                    Ok(graph.set_rate_of(id, *hz)?)
                })
                .map_err(|e| e.to_string()),
            Command::SetSensorHz { hz } => crate::config::check_rate("sensor-hz", *hz)
                .and_then(|_| {
                    let id = graph
                        .chain_for("the sensor rate", crate::setting::Speech::Flags)?
                        .sensor;
                    Ok(graph.set_rate_of(id, *hz)?)
                })
                .map_err(|e| e.to_string()),
            Command::SetQueueDepth { depth } => {
                graph.set_all_depths(*depth).map_err(|e| e.to_string())
            }
            Command::SetNodeHz { node, hz } => graph.set_rate(node, *hz).map_err(|e| e.to_string()),
            Command::SetTopicDepth { topic, depth } => {
                graph.set_depth(topic, *depth).map_err(|e| e.to_string())
            }
            Command::SetTopicQos { topic, pairs } => {
                graph.set_qos(topic, pairs).map_err(|e| e.to_string())
            }
            Command::SetPolicy { spec } => {
                policy.clone_from(spec);
                Ok(())
            }
            Command::SetExecutor { executor } => {
                graph.set_executor(ratelab_core::executor::ExecutorOverride::parse(executor)?);
                Ok(())
            }
            // Checked, not kept: the next run starts at its settings' phase offsets.
            Command::SetPhase { node, phase_ms } => phase_node(graph, node, *phase_ms).map(|_| ()),
            // Checked, not kept: a fault is an event of its run.
            Command::InjectFault { fault } | Command::InjectFaultAsGiven { fault } => {
                fault_node(graph, fault).map(|_| ())
            }
        }
    }

    /// Check the command against `graph` as the command line checks the same values
    /// ([`Command::apply_to_settings`] on a copy), and that a brain it names loads.
    ///
    /// # Errors
    /// One line saying what is wrong.
    pub fn validate(&self, graph: &crate::graph::GraphSpec) -> Result<(), String> {
        self.apply_to_settings(&mut graph.clone(), &mut String::new())?;
        if let Command::SetPolicy { spec } = self {
            crate::checkpoint::load_policy(spec).map_err(|e| e.to_string())?;
        }
        Ok(())
    }

    /// Apply to a running graph, before its instant at `at` (run time): the instant it takes
    /// effect at, and is logged at. An injected fault given an earlier time is booked from
    /// `at` ([`ratelab_core::qos::Fault::from_instant`]); a stall over before `at` is refused.
    ///
    /// # Errors
    /// A one-line description when the value is invalid or the brain cannot be loaded
    /// (the graph is unchanged).
    pub fn apply(&self, h: &GraphHandles, at: ratelab_core::time::Nanos) -> Result<(), String> {
        match self {
            Command::SetControlHz { hz } => h
                .control_rate()
                .ok_or("the graph has no chapter chain: no control rate")?
                .set_hz(*hz)
                .map_err(|e| e.to_string()),
            Command::SetSensorHz { hz } => h
                .sensor_rate()
                .ok_or("the graph has no chapter chain: no sensor rate")?
                .set_hz(*hz)
                .map_err(|e| e.to_string()),
            Command::SetQueueDepth { depth } => {
                h.set_queue_depth(*depth).map_err(|e| e.to_string())
            }
            Command::SetNodeHz { node, hz } => {
                // The file's rules (the actuator's fixed rate) hold for live changes too.
                let mut spec = h.spec.as_ref().clone();
                spec.set_rate(node, *hz).map_err(|e| e.to_string())?;
                let id = spec.node_id(node).expect("set_rate found it");
                h.rate(id).set_hz(*hz).map_err(|e| e.to_string())
            }
            Command::SetTopicDepth { topic, depth } => {
                let id = h
                    .spec
                    .topic_id(topic)
                    .ok_or_else(|| format!("no topic '{topic}' in graph '{}'", h.spec.name))?;
                h.topic(id).set_depth(*depth).map_err(|e| e.to_string())
            }
            Command::SetTopicQos { topic, pairs } => {
                // The file's rules hold for live changes: check on the graph as it is now.
                let mut spec = h.current_spec();
                spec.set_qos(topic, pairs).map_err(|e| e.to_string())?;
                let id = spec.topic_id(topic).expect("set_qos found it");
                let t = spec.topic(id);
                h.topic(id).set_depth(t.depth).map_err(|e| e.to_string())?;
                h.topic(id).set_qos(t.qos);
                // A subscription's request may now be met, or no longer.
                crate::graph::connect_subscriptions(&h.spec, &h.topics);
                Ok(())
            }
            Command::SetPolicy { spec } => {
                let brain = crate::checkpoint::load_policy(spec).map_err(|e| e.to_string())?;
                h.brain.swap(brain);
                Ok(())
            }
            Command::SetExecutor { executor } => {
                let over = ratelab_core::executor::ExecutorOverride::parse(executor)?;
                let mut spec = h.current_spec();
                spec.set_executor(over);
                *crate::graph::lock(&h.executor) = Some(over);
                *crate::graph::lock(&h.plan_request) = Some(spec.execution_plan());
                Ok(())
            }
            Command::InjectFault { fault } => {
                let (id, f) = fault_node(&h.spec, fault)?;
                h.faults.inject(id, taking_effect(&f, at)?)
            }
            Command::InjectFaultAsGiven { fault } => {
                let (id, f) = fault_node(&h.spec, fault)?;
                h.faults.inject(id, f)
            }
            Command::SetPhase { node, phase_ms } => {
                let (id, phase) = phase_node(&h.spec, node, *phase_ms)?;
                h.phase_request.push(id, phase);
                Ok(())
            }
        }
    }
}

/// Node `node`'s id in `graph` and the phase offset `phase_ms` as a run time.
fn phase_node(
    graph: &crate::graph::GraphSpec,
    node: &str,
    phase_ms: f64,
) -> Result<(crate::graph::NodeId, ratelab_core::time::Nanos), String> {
    let id = graph.known_node(node).map_err(|e| e.to_string())?;
    let phase = crate::config::phase_offset_from_ms(phase_ms).map_err(|e| e.to_string())?;
    Ok((id, phase))
}

/// The fault `text` ([`parse_fault`]) and its node's id in `graph`.
fn fault_node(
    graph: &crate::graph::GraphSpec,
    text: &str,
) -> Result<(crate::graph::NodeId, ratelab_core::qos::Fault), String> {
    let f = parse_fault(text)?;
    let id = graph.node_id(&f.node).ok_or_else(|| {
        format!(
            "{f}: unknown node '{}' (nodes: {})",
            f.node,
            graph.node_names().join(", ")
        )
    })?;
    Ok((id, f))
}

/// A command stamped with the run time at which it takes effect.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct TimedCommand {
    /// Run time, ns: applied just before the first tick due at or after it.
    pub at_ns: u64,
    /// The change.
    #[serde(flatten)]
    pub command: Command,
}

#[cfg(test)]
mod tests {
    use super::*;
    use ratelab_core::time::Nanos;

    #[test]
    fn a_stall_from_an_instant_reads_back_to_the_nanosecond() {
        let d = Nanos(500_000_000);
        // Instants of a 50 Hz grid, odd nanoseconds, one 48.5 days in that an `f64` would
        // read 1 ns late, a run of 100 days, the longest run.
        for at in [
            0,
            20_000_000,
            9_380_000_000,
            123_456_789_123,
            4_194_304_280_000_000,
            (1u64 << 53) - 1,
            8_640_000_000_000_000,
            ratelab_core::time::MAX_DURATION.0,
        ] {
            let Command::InjectFault { fault } = stall_from("policy", Nanos(at), d) else {
                panic!("not a fault");
            };
            let f = parse_fault(&fault).unwrap();
            assert_eq!(
                (f.node.as_str(), f.at, f.duration),
                ("policy", Nanos(at), Some(d)),
                "{fault}"
            );
        }
        let Command::InjectFault { fault } = stall_from("sensor", Nanos(9_380_000_000), d) else {
            panic!("not a fault");
        };
        assert_eq!(fault, "sensor@9.380000000+0.500000000");
    }
}
