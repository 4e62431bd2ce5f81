//! Run settings and their validation: one place decides what a usable run is.

use crate::graph::spec::{GraphSpec, OverrideError};
use crate::setting::{Setting, Speech};
use ratelab_core::rate::period_for_hz;
use ratelab_core::time::{Nanos, MAX_DURATION_S};

pub use ratelab_core::clock::ClockKind;

/// `--break` sets the control rate to this (the chapter's demonstration of the cliff).
pub const BREAK_CONTROL_HZ: f64 = 5.0;

/// The most faults one run may inject (`--stall`, `--kill`, and by command).
pub use ratelab_core::qos::MAX_FAULTS;

impl From<ratelab_core::clock::UnknownClock> for ConfigError {
    fn from(e: ratelab_core::clock::UnknownClock) -> ConfigError {
        ConfigError::Clock(e.0)
    }
}

/// A setting that cannot be used. Each message is one line, naming the setting as its
/// front end takes it ([`ConfigError::line`]); `Display` is the command line's words.
#[derive(Debug, PartialEq)]
pub enum ConfigError {
    /// A rate outside (0, 10 000] Hz or not finite.
    Rate {
        /// The flag's name without its dashes (`sensor-hz`, `control-hz`).
        flag: &'static str,
        /// The rejected value.
        hz: f64,
    },
    /// Queue depth 0.
    Depth(usize),
    /// A queue depth the graph refuses (past its bound, or its queues past theirs): the
    /// graph's reason ([`crate::graph::GraphSpec::set_all_depths`]).
    QueueDepth(OverrideError),
    /// A graph override (`--rate`, `--depth`, a chapter shorthand) that does not fit.
    Graph(OverrideError),
    /// Duration not finite, ≤ 0, or above [`MAX_DURATION_S`].
    Duration(f64),
    /// Unknown clock name.
    Clock(String),
    /// A fault names no node of the graph or takes effect past the longest run (`fault`:
    /// which), or there are too many (`fault`: `None`); `why` says what.
    Fault {
        /// The fault refused, when one is.
        fault: Option<ratelab_core::qos::Fault>,
        /// Why, one line.
        why: String,
    },
    /// A real-time priority outside 1..=99.
    RtPriority(u8),
    /// A phase offset not finite, negative, or not below one second.
    PhaseOffset(f64),
    /// Not exactly one phase offset per node.
    PhaseOffsetCount {
        /// Nodes in the graph.
        nodes: usize,
        /// Their names, comma-separated, in order.
        order: String,
        /// Values given.
        got: usize,
    },
    /// A real-clock run that would start more threads than
    /// [`ratelab_core::limits::MAX_REAL_CLOCK_THREADS`]: the line names the graph, the threads, the
    /// bound and the ways to fewer.
    Threads {
        /// The graph's name.
        graph: String,
        /// [`crate::scheduler::check_real_clock_threads`]'s line.
        line: String,
    },
    /// A spin margin that is not below every node's period (or above one second).
    SpinMargin {
        /// The margin, µs.
        margin_us: u64,
        /// The shortest node period, µs.
        period_us: u64,
    },
}

impl From<OverrideError> for ConfigError {
    fn from(e: OverrideError) -> ConfigError {
        ConfigError::Graph(e)
    }
}

impl ConfigError {
    /// The refusal in `speech`'s words: `--queue-depth must be at least 1, got 0` on the
    /// command line, `queue_depth must be at least 1, got 0` in Python.
    pub fn line(&self, speech: Speech) -> String {
        let name = |s: Setting| speech.name(s);
        match self {
            ConfigError::Rate { flag, hz } => {
                let named = match *flag {
                    "sensor-hz" => name(Setting::SensorHz).to_string(),
                    "control-hz" => name(Setting::ControlHz).to_string(),
                    "rate" => name(Setting::Rate).to_string(),
                    "min-hz" => name(Setting::MinHz).to_string(),
                    "max-hz" => name(Setting::MaxHz).to_string(),
                    "step" => name(Setting::Step).to_string(),
                    other if speech == Speech::Keywords => other.replace('-', "_"),
                    other => format!("--{other}"),
                };
                format!("{named} {}", ratelab_core::rate::rate_rule(*hz))
            }
            ConfigError::Depth(d) => {
                format!("{} must be at least 1, got {d}", name(Setting::QueueDepth))
            }
            ConfigError::QueueDepth(e) => format!("{}: {e}", name(Setting::QueueDepth)),
            ConfigError::Graph(e) => e.to_string(),
            ConfigError::Duration(s) => format!(
                "{} must be in (0, {MAX_DURATION_S}] seconds (ten years), got {} (ratelab::limits::MAX_DURATION_S)",
                name(Setting::Duration),
                ratelab_core::text::number(*s)
            ),
            ConfigError::Clock(c) => {
                format!("{} must be 'real' or 'virtual', got '{c}'", name(Setting::Clock))
            }
            ConfigError::Fault { fault, why } => match (speech, fault) {
                (Speech::Flags, Some(f)) => format!("--stall/--kill: {f}: {why}"),
                (Speech::Flags, None) => format!("--stall/--kill: {why}"),
                // In the keyword's words: `stall["polcy"]`, not the flag's `stall polcy@…`.
                (Speech::Keywords, Some(f)) => {
                    let kind = if f.duration.is_some() { "stall" } else { "kill" };
                    format!("{kind}[{:?}]: {why}", f.node)
                }
                (Speech::Keywords, None) => format!("stall/kill: {why}"),
            },
            ConfigError::RtPriority(p) => {
                format!("{} must be in 1..=99, got {p}", name(Setting::RtPriority))
            }
            ConfigError::PhaseOffset(ms) => format!(
                "{} values must be finite and in [0, 1000) ms, got {ms}",
                name(Setting::PhaseOffset)
            ),
            ConfigError::PhaseOffsetCount { nodes, order, got } => format!(
                "{} takes exactly {nodes} values (one per node, in order {order}), got {got}",
                name(Setting::PhaseOffset)
            ),
            ConfigError::Threads { graph, line } => format!("graph '{graph}': {line}"),
            ConfigError::SpinMargin {
                margin_us,
                period_us,
            } => format!(
                "{} must be below every node's period (here {period_us} µs, the fastest) and at most 1000000, got {margin_us}",
                name(Setting::SpinMargin)
            ),
        }
    }
}

impl std::fmt::Display for ConfigError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(&self.line(Speech::Flags))
    }
}

impl std::error::Error for ConfigError {
    fn source(&self) -> Option<&(dyn std::error::Error + 'static)> {
        match self {
            // Transparent, as the line is the override's own.
            ConfigError::Graph(e) | ConfigError::QueueDepth(e) => std::error::Error::source(e),
            _ => None,
        }
    }
}

/// Everything that defines one run of the graph.
#[derive(Clone, Debug, PartialEq)]
pub struct RunConfig {
    /// Reset seed (numpy-compatible draws; also seeds sensor noise).
    pub seed: u64,
    /// How long to run (run time).
    pub duration: Nanos,
    /// The graph, with the rates and depths the run starts with.
    pub graph: GraphSpec,
    /// Which executor.
    pub clock: ClockKind,
    /// Real clock: spin this long before each deadline instead of sleeping.
    pub spin_margin: Nanos,
    /// First deadline of each node, by node index (missing = 0): phase offsets.
    pub phase_offsets: Vec<Nanos>,
    /// Real clock: run the node threads under `SCHED_FIFO` at this priority (1..=99) when
    /// the kernel allows (see [`crate::scheduler::RealOptions::rt_priority`]); `None` keeps the default policy.
    pub rt_priority: Option<u8>,
    /// Faults injected into nodes (`--stall`, `--kill`), in the order given.
    pub faults: Vec<ratelab_core::qos::Fault>,
}

impl Default for RunConfig {
    /// The chapter's graph at its rates, seed 0, 10 s, real clock.
    fn default() -> Self {
        Self {
            seed: 0,
            duration: Nanos(10 * Nanos::SECOND.0),
            graph: GraphSpec::chapter(),
            clock: ClockKind::Real,
            spin_margin: ratelab_core::rate::DEFAULT_SPIN_MARGIN,
            phase_offsets: Vec::new(),
            rt_priority: None,
            faults: Vec::new(),
        }
    }
}

/// Check a rate flag.
///
/// # Errors
/// [`ConfigError::Rate`] naming `flag`.
pub fn check_rate(flag: &'static str, hz: f64) -> Result<f64, ConfigError> {
    period_for_hz(hz)
        .map(|_| hz)
        .map_err(|_| ConfigError::Rate { flag, hz })
}

/// Parse a duration in seconds.
///
/// # Errors
/// [`ConfigError::Duration`] when not finite, ≤ 0, or above [`MAX_DURATION_S`].
pub fn duration_from_secs(secs: f64) -> Result<Nanos, ConfigError> {
    match Nanos::from_secs_f64(secs) {
        Some(d) if secs > 0.0 && d.0 > 0 && secs <= MAX_DURATION_S => Ok(d),
        _ => Err(ConfigError::Duration(secs)),
    }
}

/// The phase offsets of a graph's nodes from `--phase-offset-ms` values: none given →
/// all 0; otherwise exactly one value per node (`names`, in node order).
///
/// # Errors
/// [`ConfigError::PhaseOffsetCount`] for another number of values,
/// [`ConfigError::PhaseOffset`] for a value out of range.
pub fn phase_offsets_from_ms(ms: &[f64], names: &[&str]) -> Result<Vec<Nanos>, ConfigError> {
    if ms.is_empty() {
        return Ok(vec![Nanos::ZERO; names.len()]);
    }
    if ms.len() != names.len() {
        return Err(ConfigError::PhaseOffsetCount {
            nodes: names.len(),
            order: names.join(","),
            got: ms.len(),
        });
    }
    ms.iter().map(|&m| phase_offset_from_ms(m)).collect()
}

/// Parse a phase offset in milliseconds.
///
/// # Errors
/// [`ConfigError::PhaseOffset`] when not finite, negative, or ≥ 1000 ms.
pub fn phase_offset_from_ms(ms: f64) -> Result<Nanos, ConfigError> {
    if ms.is_finite() && (0.0..1000.0).contains(&ms) {
        Ok(Nanos((ms * 1e6).round() as u64))
    } else {
        Err(ConfigError::PhaseOffset(ms))
    }
}

impl RunConfig {
    /// Each node's first deadline, by node index: its phase offset, or when it joins the
    /// graph (`start_ms`, [`crate::graph::spec::NodeSpec::start`]) if later. What every
    /// scheduler starts a node's timer from.
    pub fn first_deadlines(&self) -> Vec<Nanos> {
        self.graph
            .nodes
            .iter()
            .enumerate()
            .map(|(i, n)| {
                let phase = self.phase_offsets.get(i).copied().unwrap_or(Nanos::ZERO);
                n.start.map_or(phase, |s| s.max(phase))
            })
            .collect()
    }

    /// The chain sensor's rate at the start, Hz (the chapter's `sensor_hz`); `None` for a
    /// graph without the chapter's chain.
    pub fn sensor_hz(&self) -> Option<f64> {
        self.graph.sensor_hz()
    }

    /// The chain policy's rate at the start, Hz (the chapter's control rate); `None` for a
    /// graph without the chapter's chain.
    pub fn control_hz(&self) -> Option<f64> {
        self.graph.control_hz()
    }

    /// The actuator's rate, Hz.
    pub fn actuator_hz(&self) -> f64 {
        self.graph.actuator_hz()
    }

    /// The policy input's depth at the start (the chapter's one queue depth); `None` for a
    /// graph without the chapter's chain.
    pub fn queue_depth(&self) -> Option<usize> {
        self.graph.queue_depth()
    }

    /// Set the chain sensor's rate (`--sensor-hz`).
    ///
    /// # Errors
    /// [`ConfigError::Rate`] naming the flag.
    pub fn set_sensor_hz(&mut self, hz: f64) -> Result<(), ConfigError> {
        check_rate("sensor-hz", hz)?;
        let id = self.graph.chain_for("--sensor-hz", Speech::Flags)?.sensor;
        Ok(self.graph.set_rate_of(id, hz)?)
    }

    /// Set the chain policy's rate (`--control-hz`).
    ///
    /// # Errors
    /// [`ConfigError::Rate`] naming the flag.
    pub fn set_control_hz(&mut self, hz: f64) -> Result<(), ConfigError> {
        check_rate("control-hz", hz)?;
        let id = self.graph.chain_for("--control-hz", Speech::Flags)?.policy;
        Ok(self.graph.set_rate_of(id, hz)?)
    }

    /// Set every topic's depth (`--queue-depth`).
    ///
    /// # Errors
    /// [`ConfigError::Depth`] for 0, or a depth past the graph's bound.
    pub fn set_queue_depth(&mut self, depth: usize) -> Result<(), ConfigError> {
        if depth == 0 {
            return Err(ConfigError::Depth(0));
        }
        (self.graph.set_all_depths(depth)).map_err(ConfigError::QueueDepth)
    }

    /// These settings with the chapter's rates and depth (builder style, for tests and
    /// sweeps): `sensor_hz`, `control_hz`, `queue_depth`.
    ///
    /// # Errors
    /// As [`RunConfig::set_sensor_hz`], [`RunConfig::set_control_hz`], [`RunConfig::set_queue_depth`].
    pub fn with_chapter(
        mut self,
        sensor_hz: f64,
        control_hz: f64,
        queue_depth: usize,
    ) -> Result<Self, ConfigError> {
        // A sweep or a cliff search varies the chain's rates: say so by name.
        self.graph.chain_for(
            "a sweep or cliff search (it varies the chain's sensor and control rates)",
            Speech::Flags,
        )?;
        self.set_sensor_hz(sensor_hz)?;
        self.set_control_hz(control_hz)?;
        self.set_queue_depth(queue_depth)?;
        Ok(self)
    }

    /// The same settings with another duration, in milliseconds.
    pub fn with_duration_ms(self, ms: u64) -> Self {
        Self {
            duration: Nanos::from_millis(ms),
            ..self
        }
    }

    /// Check every setting.
    ///
    /// # Errors
    /// The first [`ConfigError`] found.
    pub fn validate(&self) -> Result<(), ConfigError> {
        for n in &self.graph.nodes {
            check_rate("rate", n.rate_hz)?;
        }
        if self.graph.topics.iter().any(|t| t.depth == 0) {
            return Err(ConfigError::Depth(0));
        }
        // What the queues may hold at worst (a graph file's and every override's are
        // checked as they are made; a graph changed in place by a program, here).
        self.graph.check_queue_bytes()?;
        if self.duration.0 == 0 {
            return Err(ConfigError::Duration(0.0));
        }
        if let Some(p) = self.rt_priority {
            ratelab_core::realtime::check_priority(p).map_err(|_| ConfigError::RtPriority(p))?;
        }
        if self.faults.len() > MAX_FAULTS {
            let got = self.faults.len();
            let line = format_args!("at most {MAX_FAULTS} faults, got {got}");
            return Err(ConfigError::Fault {
                fault: None,
                why: ratelab_core::limits::refusal(line, "MAX_FAULTS"),
            });
        }
        for f in &self.faults {
            // The bound `--stall`'s text is read with, for a fault given as data (a session
            // log's): a fault from past the longest run could never take effect, and a
            // stall longer than it is refused as `--stall` refuses it.
            let max = ratelab_core::time::MAX_DURATION;
            if f.at > max || f.duration.is_some_and(|d| d > max) {
                return Err(ConfigError::Fault {
                    fault: Some(f.clone()),
                    why: ratelab_core::limits::refusal(
                        format_args!(
                            "its times must be in [0, {}] s",
                            ratelab_core::limits::MAX_DURATION_S
                        ),
                        "MAX_DURATION_S",
                    ),
                });
            }
            if self.graph.node_id(&f.node).is_none() {
                let names = self.graph.node_names();
                return Err(ConfigError::Fault {
                    fault: Some(f.clone()),
                    why: format!(
                        "unknown node '{}' (nodes: {})",
                        ratelab_core::text::printable(&f.node),
                        ratelab_core::text::listed(names.iter().map(|n| n.as_ref()))
                    ),
                });
            }
        }
        // The real clock starts a thread per node on a thread of its own, and each shared
        // executor's: refused here, before the graph is built, past the bound (a launch's
        // processes counted together: they share the machine).
        if self.clock == ClockKind::Real {
            crate::scheduler::check_real_clock_threads(&self.graph.execution_plan()).map_err(
                |line| ConfigError::Threads {
                    graph: self.graph.name.clone(),
                    line,
                },
            )?;
        }
        // The spin margin matters to the real clock only (the virtual one never waits).
        let fastest = self.fastest_period();
        if self.clock == ClockKind::Real
            && (self.spin_margin >= fastest
                || self.spin_margin > ratelab_core::rate::MAX_SPIN_MARGIN)
        {
            return Err(ConfigError::SpinMargin {
                margin_us: self.spin_margin.0 / 1_000,
                period_us: fastest.0 / 1_000,
            });
        }
        Ok(())
    }

    /// The shortest period among the nodes' rates (`u64::MAX` ns if none is valid).
    pub fn fastest_period(&self) -> Nanos {
        self.graph
            .nodes
            .iter()
            .filter_map(|n| period_for_hz(n.rate_hz).ok())
            .min()
            .unwrap_or(Nanos(u64::MAX))
    }

    /// The spin margin to use when none was asked for: [`ratelab_core::rate::DEFAULT_SPIN_MARGIN`],
    /// or half the fastest node's period if that is shorter (a node never spins a whole
    /// period).
    pub fn default_spin_margin(&self) -> Nanos {
        ratelab_core::rate::DEFAULT_SPIN_MARGIN.min(Nanos(self.fastest_period().0 / 2))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn validation_names_the_flag() {
        let mut cfg = RunConfig::default();
        assert_eq!(
            cfg.set_control_hz(0.0),
            Err(ConfigError::Rate {
                flag: "control-hz",
                hz: 0.0
            })
        );
        assert!(cfg
            .set_queue_depth(0)
            .unwrap_err()
            .to_string()
            .contains("--queue-depth"));
        // Past the bound: the setting named in each front end's words, once.
        let past = cfg
            .set_queue_depth(ratelab_core::qos::MAX_DEPTH + 1)
            .unwrap_err();
        let max = ratelab_core::qos::MAX_DEPTH;
        assert_eq!(
            past.line(Speech::Flags),
            format!("--queue-depth: depth must be in 1..={max}, got {}", max + 1)
        );
        assert_eq!(
            past.line(Speech::Keywords),
            format!("queue_depth: depth must be in 1..={max}, got {}", max + 1)
        );
        cfg.set_control_hz(5.0).unwrap();
        assert_eq!(cfg.control_hz(), Some(5.0));
        assert!(RunConfig::default().validate().is_ok());
        assert!(duration_from_secs(-1.0).is_err());
        assert!(duration_from_secs(f64::NAN).is_err());
        assert!(duration_from_secs(MAX_DURATION_S).is_ok());
        assert!(duration_from_secs(MAX_DURATION_S + 1.0)
            .unwrap_err()
            .to_string()
            .contains("(0, 315360000]"));
        let names = ["sensor", "policy", "actuator"];
        assert_eq!(phase_offsets_from_ms(&[], &names), Ok(vec![Nanos::ZERO; 3]));
        assert_eq!(
            phase_offsets_from_ms(&[0.0, 5.0, 10.0], &names).unwrap()[2],
            Nanos(10_000_000)
        );
        for n in [1, 2, 4, 5] {
            let e = phase_offsets_from_ms(&vec![1.0; n], &names).unwrap_err();
            assert!(e.to_string().contains("exactly 3 values"), "{e}");
        }
        let four = ["a", "b", "c", "d"];
        assert!(phase_offsets_from_ms(&[0.0; 4], &four).is_ok());
        let spin = |us: u64| {
            let mut cfg = RunConfig {
                spin_margin: Nanos(us * 1_000),
                clock: ClockKind::Real,
                ..RunConfig::default()
            };
            cfg.set_sensor_hz(1000.0).unwrap();
            cfg
        };
        // The virtual clock never spins: any margin is fine there.
        let virtual_spin = RunConfig {
            clock: ClockKind::Virtual,
            ..spin(5_000)
        };
        assert!(virtual_spin.validate().is_ok());
        assert_eq!(spin(0).default_spin_margin(), Nanos(300_000));
        let mut fast = spin(0);
        fast.set_control_hz(10_000.0).unwrap();
        assert_eq!(fast.default_spin_margin(), Nanos(50_000));
        assert!(spin(999).validate().is_ok());
        assert!(matches!(
            spin(1_000).validate(),
            Err(ConfigError::SpinMargin {
                margin_us: 1_000,
                period_us: 1_000
            })
        ));
        assert_eq!(duration_from_secs(2.0), Ok(Nanos(2_000_000_000)));
        assert_eq!("virtual".parse::<ClockKind>(), Ok(ClockKind::Virtual));
        assert!("wall".parse::<ClockKind>().is_err());
    }

    #[test]
    fn a_real_clock_run_of_more_threads_than_the_bound_is_refused_before_it_is_built() {
        let nodes = ratelab_core::limits::MAX_REAL_CLOCK_THREADS + 1;
        let graph =
            GraphSpec::parse(&crate::graph::synthetic::graph_toml(nodes, 1), "big").unwrap();
        let real = RunConfig {
            graph,
            clock: ClockKind::Real,
            ..RunConfig::default()
        };
        let e = real.validate().unwrap_err();
        assert!(matches!(e, ConfigError::Threads { .. }), "{e:?}");
        let line = e.to_string();
        assert_eq!(line.lines().count(), 1, "{line}");
        assert!(
            line.starts_with(&format!(
                "graph 'synthetic-{nodes}': the real clock would start {nodes} threads"
            )),
            "{line}"
        );
        assert!(line.contains("--executor single_threaded"), "{line}");
        assert!(
            line.ends_with("(ratelab::limits::MAX_REAL_CLOCK_THREADS)"),
            "{line}"
        );
        // Under the virtual clock (no threads), or on one shared thread, it runs.
        let virtual_clock = RunConfig {
            clock: ClockKind::Virtual,
            ..real.clone()
        };
        assert_eq!(virtual_clock.validate(), Ok(()));
        let mut shared = real;
        shared.graph.set_executor(
            ratelab_core::executor::ExecutorOverride::parse("single_threaded").unwrap(),
        );
        assert_eq!(
            crate::scheduler::plan_threads(&shared.graph.execution_plan()),
            2
        );
        assert_eq!(shared.validate(), Ok(()));
    }
}
