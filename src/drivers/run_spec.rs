//! A run as data: [`RunSpec`], what every front end (the command line, the lab, a launch,
//! the Python package) fills in and the library turns into a [`RunConfig`] by one set of
//! rules ([`RunSpec::config`]; [`late_fault_warnings`], what it warns of), and starts
//! (`RunSpec::start`, in `crate::start`).
//!
//! Each rule refuses a bad setting in one line naming it as its front end takes it
//! ([`Speech`]: `--control-hz` on the command line, `control_hz` from Python), so no front
//! end builds another's argument list to reach a run.

use crate::outputs::Outputs;
use ratelab_core::executor::{ComputeTime, ExecutorOverride};
use ratelab_core::qos::Fault;
use ratelab_core::time::Nanos;
use ratelab_runtime::command::{Command, TimedCommand};
use ratelab_runtime::config::{check_rate, duration_from_secs, ConfigError};
use ratelab_runtime::config::{phase_offsets_from_ms, BREAK_CONTROL_HZ};
use ratelab_runtime::graph::GraphSpec;
use ratelab_runtime::setting::{Setting, Speech};
use ratelab_runtime::{ClockKind, RunConfig};
use std::path::PathBuf;

/// A run lasts this long unless its settings say otherwise, s (a headless run, a run from
/// Python; the lab runs until it is quit).
pub const DEFAULT_DURATION_S: f64 = 10.0;

/// The clock of a run whose settings name none, for every front end: the real clock, one
/// thread per node against the monotonic clock, as the chapter's `--clock real` ("the
/// authentic one"). Ask for the virtual clock for a deterministic run.
pub const DEFAULT_CLOCK: ClockKind = ClockKind::Real;

/// The brain of a run whose settings name none: the chapter's scripted balancer.
pub const DEFAULT_POLICY: &str = "scripted";

/// A warning for each injected fault (`--stall`, `--kill`) of `cfg` that starts after its
/// run ends, so does nothing: a line each, without a prefix, naming the setting in
/// `speech`'s words (`the --stall of 'policy'`, `the stall of 'policy'`). None for a run with
/// no end ([`ratelab_runtime::telemetry::UNBOUNDED`]: the lab and a launch on a terminal run
/// until quit). Ask once the run's duration is final.
pub fn late_fault_warnings(cfg: &RunConfig, speech: Speech) -> Vec<String> {
    if cfg.duration == ratelab_runtime::telemetry::UNBOUNDED {
        return Vec::new();
    }
    // One at the duration itself takes the run's last instant (which runs at it).
    (cfg.faults.iter().filter(|f| f.at > cfg.duration))
        .map(|f| {
            let setting = if f.duration.is_some() {
                Setting::Stall
            } else {
                Setting::Kill
            };
            format!(
                "warning: the {} of '{}' at {} s starts after the run ends ({} s): it does nothing",
                speech.name(setting),
                f.node,
                f.at.as_secs_f64(),
                cfg.duration.as_secs_f64()
            )
        })
        .collect()
}

/// A node killed twice is refused, naming both: it would be killed at the first, and the
/// summary would name a kill that never was.
fn check_kills(kills: &[Fault], speech: Speech) -> anyhow::Result<()> {
    for (i, k) in kills.iter().enumerate() {
        if let Some(first) = kills[..i].iter().find(|f| f.node == k.node) {
            let given = |f: &Fault| match speech {
                Speech::Flags => format!("--kill {}@{}", f.node, f.at.as_secs_f64()),
                Speech::Keywords => speech.entry(Setting::Kill, &f.node, &f.at.as_secs_f64()),
            };
            anyhow::bail!(
                "{} and {} both kill node '{}'; give one",
                given(first),
                given(k),
                k.node
            );
        }
    }
    Ok(())
}

/// A `qos` or `link` entry as it was given: `--qos /obs:depth=3` or `qos["/obs"]="depth=3"`.
fn pairs_given(setting: Setting, topic: &str, pairs: &str, speech: Speech) -> String {
    match speech {
        Speech::Flags => format!("{} {topic}:{pairs}", setting.flag()),
        Speech::Keywords => speech.entry(setting, topic, &format!("{pairs:?}")),
    }
}

/// Scheduled commands checked: in order of time, each one the graph can take
/// ([`Command::validate`]), refused as `commands[i]: …`.
fn check_commands(commands: &[TimedCommand], graph: &GraphSpec) -> anyhow::Result<()> {
    if commands.len() > MAX_COMMANDS {
        anyhow::bail!(
            "commands: {}",
            ratelab_core::limits::refusal(
                format_args!("at most {MAX_COMMANDS} commands, got {}", commands.len()),
                "MAX_COMMANDS"
            )
        );
    }
    let mut at = 0;
    for (i, c) in commands.iter().enumerate() {
        if c.at_ns < at {
            anyhow::bail!(
                "commands[{i}]: at_ns {} is before the previous command's {at}",
                c.at_ns
            );
        }
        at = c.at_ns;
        (c.command.validate(graph)).map_err(|e| anyhow::anyhow!("commands[{i}]: {e}"))?;
        // Refused here as a run refuses it when applied (a stall already over).
        if let Command::InjectFault { fault } = &c.command {
            let f = ratelab_runtime::command::parse_fault(fault).map_err(anyhow::Error::msg)?;
            (ratelab_runtime::command::taking_effect(&f, Nanos(c.at_ns)))
                .map_err(|e| anyhow::anyhow!("commands[{i}]: {e}"))?;
        }
    }
    Ok(())
}

pub use ratelab_core::limits::MAX_COMMANDS;

/// The graph to run and the overrides of its nodes and topics, in the order given.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct GraphSettings {
    /// The graph file; `None` for `inline`'s, or else the chapter's (sensor → /obs →
    /// policy → /action → actuator).
    pub file: Option<PathBuf>,
    /// A graph file's text given whole, in place of a file: `(text, origin)`, `origin`
    /// naming it in errors (a session log's run: `run 2: graph`). Refused beside `file`.
    pub inline: Option<(String, String)>,
    /// Node rates, Hz: `(node, hz)`.
    pub rates: Vec<(String, f64)>,
    /// Topic history depths, messages: `(topic, depth)`.
    pub depths: Vec<(String, usize)>,
    /// Topic QoS with the graph file's keys: `(topic, "history=keep_all,depth=100")`.
    pub qos: Vec<(String, String)>,
    /// Lossy links: `(topic, "loss=0.2,delay_ms=10")`, only link keys
    /// ([`ratelab_core::qos::LINK_KEYS`]).
    pub links: Vec<(String, String)>,
    /// Liveliness leases, ms: `(node, ms)`.
    pub leases_ms: Vec<(String, f64)>,
    /// Injected stalls (each with a duration).
    pub stalls: Vec<Fault>,
    /// Injected kills.
    pub kills: Vec<Fault>,
    /// Compute times of nodes' ticks: `(node, time)`.
    pub computes: Vec<(String, ComputeTime)>,
    /// Every node on one executor, replacing the graph file's `[executors]`.
    pub executor: Option<ExecutorOverride>,
}

impl GraphSettings {
    /// Two settings of one thing that differ are refused, naming both, as a rate given twice
    /// on the command line (`--rate policy=10 --rate policy=20`) would have the last win
    /// unseen: a node's rate, lease; a topic's history depth (by `depth` or by `qos`'s
    /// `depth=`), each of its QoS keys and link keys (a link key by `link` or by `qos`,
    /// which takes them too). The same value twice says one thing and is taken: numbers are
    /// compared as numbers (`deadline_ms=40` is `deadline_ms=40.0`). A list of pairs that
    /// does not split is left to its own refusal.
    fn check_each_set_once(&self, speech: Speech) -> anyhow::Result<()> {
        // What each setting sets, its value (a number as its f64 says it), and how it was
        // given.
        let number = |v: &str| {
            v.parse::<f64>()
                .map_or_else(|_| v.to_string(), |x| x.to_string())
        };
        let mut sets: Vec<(String, String, String)> = Vec::new();
        for (node, hz) in &self.rates {
            let given = speech.entry(Setting::Rate, node, hz);
            sets.push((format!("the rate of node '{node}'"), hz.to_string(), given));
        }
        for (node, ms) in &self.leases_ms {
            let given = speech.entry(Setting::Lease, node, ms);
            sets.push((format!("the lease of node '{node}'"), ms.to_string(), given));
        }
        let depth_of = |topic: &str| format!("the history depth of topic '{topic}'");
        for (topic, depth) in &self.depths {
            let given = speech.entry(Setting::Depth, topic, depth);
            sets.push((depth_of(topic), depth.to_string(), given));
        }
        for (setting, list) in [(Setting::Qos, &self.qos), (Setting::Link, &self.links)] {
            for (topic, pairs) in list {
                let Ok(split) = ratelab_core::qos::split_pairs(pairs) else {
                    continue;
                };
                let given = pairs_given(setting, topic, pairs, speech);
                for (key, value) in split {
                    let what = if setting == Setting::Qos && key == "depth" {
                        depth_of(topic)
                    } else if ratelab_core::qos::LINK_KEYS.contains(&key) {
                        format!("the link's '{key}' on topic '{topic}'")
                    } else {
                        format!("the QoS '{key}' of topic '{topic}'")
                    };
                    sets.push((what, number(value), given.clone()));
                }
            }
        }
        let mut first: std::collections::HashMap<&str, (&str, &str)> = Default::default();
        for (what, value, given) in &sets {
            match first.get(what.as_str()) {
                Some((v, was)) if v != value => {
                    anyhow::bail!("{was} and {given} both set {what}; give one")
                }
                Some(_) => {}
                None => {
                    first.insert(what, (value, given));
                }
            }
        }
        Ok(())
    }

    /// The graph these settings describe: the file (or the chapter's) with every override
    /// applied, in order. Its QoS warnings are the caller's to show
    /// ([`GraphSpec::qos_warnings`]).
    ///
    /// # Errors
    /// A graph file that cannot be read, or the first override that does not fit, in one
    /// line naming it in `speech`'s words.
    pub fn graph(&self, speech: Speech) -> anyhow::Result<GraphSpec> {
        let mut spec = match (&self.file, &self.inline) {
            (Some(path), None) => GraphSpec::load(path)?,
            (None, Some((text, origin))) => GraphSpec::parse(text, origin)?,
            (None, None) => GraphSpec::chapter(),
            (Some(path), Some((_, origin))) => {
                anyhow::bail!(
                    "two graphs given: {} and {origin}; give one",
                    path.display()
                )
            }
        };
        let entry =
            |s: Setting, key: &str, value: &dyn std::fmt::Display| speech.entry(s, key, value);
        for (node, hz) in &self.rates {
            check_rate("rate", *hz).map_err(|e| {
                anyhow::anyhow!("{}: {}", entry(Setting::Rate, node, hz), e.line(speech))
            })?;
            spec.set_rate(node, *hz)
                .map_err(|e| anyhow::anyhow!("{}: {e}", entry(Setting::Rate, node, hz)))?;
        }
        for (topic, depth) in &self.depths {
            if *depth == 0 {
                anyhow::bail!(
                    "{}: a history depth is at least 1",
                    entry(Setting::Depth, topic, depth)
                );
            }
            spec.set_depth(topic, *depth)
                .map_err(|e| anyhow::anyhow!("{}: {e}", entry(Setting::Depth, topic, depth)))?;
        }
        for (setting, list) in [(Setting::Qos, &self.qos), (Setting::Link, &self.links)] {
            for (topic, pairs) in list {
                let given = pairs_given(setting, topic, pairs, speech);
                if setting == Setting::Link {
                    if let Some((k, _)) = ratelab_core::qos::split_pairs(pairs)
                        .map_err(|e| anyhow::anyhow!("{given}: {e}"))?
                        .into_iter()
                        .find(|(k, _)| !ratelab_core::qos::LINK_KEYS.contains(k))
                    {
                        anyhow::bail!(
                            "{given}: '{k}' is not a link key ({}); use {}",
                            ratelab_core::qos::LINK_KEYS.join(", "),
                            speech.name(Setting::Qos)
                        );
                    }
                }
                spec.set_qos(topic, pairs)
                    .map_err(|e| anyhow::anyhow!("{given}: {e}"))?;
            }
        }
        for (node, ms) in &self.leases_ms {
            let given = entry(Setting::Lease, node, ms);
            ratelab_core::qos::ms_to_nanos("lease", *ms, false)
                .map_err(|e| anyhow::anyhow!("{given}: {e}"))?;
            spec.set_lease(node, *ms)
                .map_err(|e| anyhow::anyhow!("{given}: {e}"))?;
        }
        // After each entry's own checks (an unknown node, a depth of 0 said as such).
        self.check_each_set_once(speech)?;
        if let Some(over) = self.executor {
            spec.set_executor(over);
        }
        for (node, c) in &self.computes {
            spec.set_compute(node, *c).map_err(|e| {
                let why = e.0.strip_prefix("--compute: ").unwrap_or(&e.0);
                match speech {
                    Speech::Flags => anyhow::anyhow!("--compute: {why}"),
                    Speech::Keywords => {
                        anyhow::anyhow!(
                            "{}: {why}",
                            entry(Setting::Compute, node, &(c.mean.0 as f64 / 1e6))
                        )
                    }
                }
            })?;
        }
        Ok(spec)
    }

    /// The faults these settings inject: the stalls, then the kills.
    pub fn faults(&self) -> Vec<Fault> {
        self.stalls.iter().chain(&self.kills).cloned().collect()
    }
}

/// One run's settings, as data: the graph and its overrides, the clock, the chain's
/// shorthands, the seed and duration, the brain, and where its results go. Fill in the
/// fields (each `None` or empty takes the graph's or the library's default) and call
/// [`RunSpec::start`] to run it (`crate::start`), or [`RunSpec::config`] for the settings
/// alone.
#[derive(Clone, Debug, PartialEq)]
pub struct RunSpec {
    /// The graph and its overrides.
    pub graph: GraphSettings,
    /// The reset seed (the course env's NumPy draws; also seeds sensor noise).
    pub seed: u64,
    /// Run time, s, in (0, [`ratelab_core::time::MAX_DURATION_S`]]; `None` is
    /// [`DEFAULT_DURATION_S`].
    pub duration_s: Option<f64>,
    /// Run time to the ns, in place of `duration_s` (a session log's run replayed for as
    /// long as it ran: a time no `f64` of seconds holds exactly past 2^51 ns). Refused
    /// beside `duration_s`; in (0, [`ratelab_core::time::MAX_DURATION`]].
    pub duration_ns: Option<u64>,
    /// The clock ([`DEFAULT_CLOCK`] unless asked).
    pub clock: ClockKind,
    /// The chain sensor's rate, Hz.
    pub sensor_hz: Option<f64>,
    /// The chain policy's (control) rate, Hz.
    pub control_hz: Option<f64>,
    /// Break the controller: control rate [`BREAK_CONTROL_HZ`] (the chapter's cliff demo).
    pub break_: bool,
    /// Every topic's history depth, messages (≥ 1).
    pub queue_depth: Option<usize>,
    /// First-tick offsets, ms, one per node in tie-break order (empty: all 0), each in
    /// [0, 1000).
    pub phase_offset_ms: Vec<f64>,
    /// A quick deterministic check: virtual clock, 2 s.
    pub smoke: bool,
    /// Real clock: spin this many µs before each deadline instead of sleeping (`None`: the
    /// default, [`RunConfig::default_spin_margin`]).
    pub spin_margin_us: Option<u64>,
    /// Real clock: `SCHED_FIFO` priority, 1..=99.
    pub rt_priority: Option<u8>,
    /// The brain: `scripted`, `FILE.py[:FUNCTION]` or a checkpoint path. A front end may
    /// supply a brain object instead (a Python callable); this then only names the default.
    pub policy: String,
    /// Changes scheduled at run times, in order of `at_ns` (ns): each applied between
    /// instants, before the first instant at or after its time, as the lab's keys apply
    /// them and its session log keeps them ([`TimedCommand`]). One after the run's end
    /// changes the settings the run ends with (its summary's end rates), not a tick: as a
    /// change made in the lab after a run's last instant, which a replay applies once the
    /// run has ended.
    pub commands: Vec<TimedCommand>,
    /// Where the results go.
    pub outputs: Outputs,
}

impl Default for RunSpec {
    /// The chapter's graph at its rates, seed 0, [`DEFAULT_DURATION_S`], [`DEFAULT_CLOCK`],
    /// the scripted balancer, nothing written.
    fn default() -> Self {
        Self {
            graph: GraphSettings::default(),
            seed: 0,
            duration_s: None,
            duration_ns: None,
            clock: DEFAULT_CLOCK,
            sensor_hz: None,
            control_hz: None,
            break_: false,
            queue_depth: None,
            phase_offset_ms: Vec::new(),
            smoke: false,
            spin_margin_us: None,
            rt_priority: None,
            policy: DEFAULT_POLICY.to_string(),
            commands: Vec::new(),
            outputs: Outputs::default(),
        }
    }
}

impl RunSpec {
    /// The run these settings describe, every rule checked once: the graph and its
    /// overrides, the chain's shorthands (each refusing a graph without the chain by its own
    /// name, and two settings of one rate refused), `smoke`, the spin margin's default, then
    /// [`RunConfig::validate`]. The QoS warnings of the graph are the caller's to show.
    ///
    /// # Errors
    /// The first setting that cannot be used, in one line naming it in `speech`'s words.
    pub fn config(&self, speech: Speech) -> anyhow::Result<RunConfig> {
        let said = |e: ConfigError| anyhow::anyhow!(e.line(speech));
        let name = |s: Setting| speech.name(s);
        if self.outputs.trace_every == 0 {
            anyhow::bail!("{} must be at least 1, got 0", name(Setting::TraceEvery));
        }
        let duration = match (self.duration_s, self.duration_ns) {
            (s, None) => duration_from_secs(s.unwrap_or(DEFAULT_DURATION_S)).map_err(said)?,
            (None, Some(ns)) if ns > 0 && ns <= ratelab_core::time::MAX_DURATION.0 => Nanos(ns),
            (None, Some(ns)) => anyhow::bail!(
                "duration_ns must be in (0, {}], got {ns}",
                ratelab_core::time::MAX_DURATION.0
            ),
            (Some(_), Some(_)) => anyhow::bail!(
                "{} and duration_ns both set the run's duration; give one",
                name(Setting::Duration)
            ),
        };
        let mut cfg = RunConfig {
            seed: self.seed,
            duration,
            graph: self.graph.graph(speech)?,
            clock: self.clock,
            spin_margin: Nanos(self.spin_margin_us.unwrap_or(0).saturating_mul(1_000)),
            rt_priority: self.rt_priority,
            faults: self.graph.faults(),
            ..RunConfig::default()
        };
        self.check_brain(&cfg.graph, speech)?;
        let control_hz = self.check_chain_rates(&cfg.graph, speech)?;
        if let Some(hz) = self.sensor_hz {
            cfg.set_sensor_hz(hz).map_err(said)?;
        }
        if let Some(hz) = control_hz {
            cfg.set_control_hz(hz).map_err(said)?;
        }
        if let Some(depth) = self.queue_depth {
            self.check_one_depth(depth, speech)?;
            cfg.set_queue_depth(depth).map_err(said)?;
        }
        cfg.phase_offsets =
            phase_offsets_from_ms(&self.phase_offset_ms, &cfg.graph.node_names()).map_err(said)?;
        if self.smoke {
            cfg.clock = ClockKind::Virtual;
            cfg.duration = Nanos(2 * Nanos::SECOND.0);
        }
        if self.spin_margin_us.is_none() {
            cfg.spin_margin = cfg.default_spin_margin();
        }
        cfg.validate().map_err(said)?;
        check_kills(&self.graph.kills, speech)?;
        check_commands(&self.commands, &cfg.graph)?;
        Ok(cfg)
    }

    /// Its commands split at the run's end `duration`: those applied between its instants,
    /// and those made after its last one (applied once it has ended).
    pub fn commands_at(&self, duration: Nanos) -> (Vec<TimedCommand>, Vec<TimedCommand>) {
        (self.commands.iter().cloned()).partition(|c| c.at_ns <= duration.0)
    }

    /// A brain is what a built-in policy node runs: refused by name for a graph whose
    /// policy is a Python node, or with no node that runs a brain.
    fn check_brain(&self, graph: &GraphSpec, speech: Speech) -> anyhow::Result<()> {
        if self.policy == DEFAULT_POLICY {
            return Ok(());
        }
        let given = speech.value(Setting::Policy, &self.policy);
        let policy = graph.chain.map(|c| graph.node(c.policy));
        if let Some((policy, python)) = policy.and_then(|p| p.python.as_ref().map(|py| (p, py))) {
            // A Python node is its own brain.
            anyhow::bail!(
                "{given}: graph '{}' has a Python node as its policy ('{}', {}), which computes its own actions; {} is for a graph whose policy is kind = \"policy\"",
                graph.name,
                policy.name,
                python.script,
                speech.name(Setting::Policy)
            );
        }
        if !graph.nodes.iter().any(|n| n.kind.def().uses_brain) {
            anyhow::bail!(
                "{given}: graph '{}' has no node that runs a brain (kind = \"policy\"); its nodes compute their own actions",
                graph.name
            );
        }
        Ok(())
    }

    /// `queue_depth` (every topic's history depth) against a depth of one topic given beside
    /// it (`depth`, or `qos`'s `depth=`): two settings of one topic's depth that differ would
    /// leave one of them ignored, and are refused, as two settings of one node's rate are.
    fn check_one_depth(&self, depth: usize, speech: Speech) -> anyhow::Result<()> {
        let qos_depths = self.graph.qos.iter().filter_map(|(topic, pairs)| {
            let split = ratelab_core::qos::split_pairs(pairs).ok()?;
            let (_, v) = split.into_iter().find(|(k, _)| *k == "depth")?;
            let given = pairs_given(Setting::Qos, topic, pairs, speech);
            Some((topic, v.parse::<usize>().ok(), given))
        });
        let depths = (self.graph.depths.iter())
            .map(|(topic, d)| (topic, Some(*d), speech.entry(Setting::Depth, topic, d)));
        for (topic, d, given) in depths.chain(qos_depths) {
            if d != Some(depth) {
                anyhow::bail!(
                    "{given} and {} ({depth}) both set the history depth of topic '{topic}'; give one",
                    speech.name(Setting::QueueDepth)
                );
            }
        }
        Ok(())
    }

    /// The chain's shorthands checked against the graph and against `rates`: two settings
    /// of one node's rate refused, a graph without the chain refused by the shorthand's own
    /// name. Returns the control rate to set (`break_`'s or `control_hz`).
    fn check_chain_rates(&self, graph: &GraphSpec, speech: Speech) -> anyhow::Result<Option<f64>> {
        let name = |s: Setting| speech.name(s);
        // Two shorthands for the policy's rate would leave one of them ignored.
        if let (true, Some(hz)) = (
            self.break_,
            self.control_hz.filter(|hz| *hz != BREAK_CONTROL_HZ),
        ) {
            anyhow::bail!(
                "{} sets the policy to {BREAK_CONTROL_HZ} Hz and {} to {hz} Hz; give one",
                name(Setting::Break),
                name(Setting::ControlHz)
            );
        }
        let control_hz = if self.break_ {
            Some(BREAK_CONTROL_HZ)
        } else {
            self.control_hz
        };
        // A chain shorthand and a rate of the same node would leave one of them ignored.
        let chain = graph.chain;
        let control = if self.break_ {
            Setting::Break
        } else {
            Setting::ControlHz
        };
        for (setting, hz, node) in [
            (Setting::SensorHz, self.sensor_hz, chain.map(|c| c.sensor)),
            (control, control_hz, chain.map(|c| c.policy)),
        ] {
            let Some(node) = node else { continue }; // refused below, by name
            let node = &graph.node(node).name;
            if let (Some(hz), Some((_, rate))) =
                (hz, self.graph.rates.iter().find(|(n, _)| n == node))
            {
                if hz != *rate {
                    anyhow::bail!(
                        "{} and {} ({hz} Hz) both set the rate of node '{node}'; give one",
                        speech.entry(Setting::Rate, node, rate),
                        name(setting)
                    );
                }
            }
        }
        // Each shorthand of the chain refuses a graph without it, by its own name.
        for (setting, given) in [
            (Setting::SensorHz, self.sensor_hz.is_some()),
            (Setting::Break, self.break_),
            (Setting::ControlHz, self.control_hz.is_some()),
        ] {
            if given {
                graph.chain_for(name(setting), speech)?;
            }
        }
        Ok(control_hz)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn spec() -> RunSpec {
        RunSpec {
            clock: ClockKind::Virtual,
            ..RunSpec::default()
        }
    }

    #[test]
    fn the_default_spec_is_the_chapter_s_run_on_the_default_clock() {
        let cfg = RunSpec::default().config(Speech::Flags).unwrap();
        assert_eq!(cfg.clock, DEFAULT_CLOCK);
        assert_eq!(cfg.duration, Nanos(10 * Nanos::SECOND.0));
        assert_eq!(cfg.graph, GraphSpec::chapter());
        assert_eq!(cfg.spin_margin, cfg.default_spin_margin());
    }

    #[test]
    fn a_refusal_names_the_setting_in_its_front_end_s_words() {
        let bad = RunSpec {
            control_hz: Some(0.0),
            ..spec()
        };
        let flags = bad.config(Speech::Flags).unwrap_err().to_string();
        assert_eq!(
            flags,
            "--control-hz must be a finite rate in (0, 10000] Hz, got 0"
        );
        let words = bad.config(Speech::Keywords).unwrap_err().to_string();
        assert_eq!(
            words,
            "control_hz must be a finite rate in (0, 10000] Hz, got 0"
        );
        let depth = RunSpec {
            queue_depth: Some(0),
            ..spec()
        };
        let line = depth.config(Speech::Keywords).unwrap_err().to_string();
        assert_eq!(line, "queue_depth must be at least 1, got 0");
        let long = RunSpec {
            duration_s: Some(-1.0),
            ..spec()
        };
        let line = long.config(Speech::Keywords).unwrap_err().to_string();
        assert!(line.starts_with("duration_s must be in (0, "), "{line}");
    }

    #[test]
    fn queue_depth_and_a_topic_s_depth_that_differ_are_refused_as_two_settings_of_one() {
        let mut s = RunSpec {
            queue_depth: Some(2),
            ..spec()
        };
        s.graph.depths.push(("/obs".into(), 7));
        assert_eq!(
            s.config(Speech::Flags).unwrap_err().to_string(),
            "--depth /obs=7 and --queue-depth (2) both set the history depth of topic '/obs'; give one"
        );
        assert_eq!(
            s.config(Speech::Keywords).unwrap_err().to_string(),
            "depth[\"/obs\"]=7 and queue_depth (2) both set the history depth of topic '/obs'; give one"
        );
        // The same depth twice says one thing: taken.
        s.graph.depths[0].1 = 2;
        assert_eq!(s.config(Speech::Flags).unwrap().queue_depth(), Some(2));
        // A QoS depth too.
        s.graph.depths.clear();
        s.graph
            .qos
            .push(("/action".into(), "history=keep_last,depth=5".into()));
        // The QoS entry as it was given, whole, as the check of one setting given twice
        // quotes it.
        assert_eq!(
            s.config(Speech::Flags).unwrap_err().to_string(),
            "--qos /action:history=keep_last,depth=5 and --queue-depth (2) both set the history depth of topic '/action'; give one"
        );
        assert_eq!(
            s.config(Speech::Keywords).unwrap_err().to_string(),
            "qos[\"/action\"]=\"history=keep_last,depth=5\" and queue_depth (2) both set the history depth of topic '/action'; give one"
        );
    }

    #[test]
    fn one_thing_set_twice_with_two_values_is_refused_naming_both() {
        let refused = |edit: &dyn Fn(&mut GraphSettings), speech| {
            let mut s = spec();
            edit(&mut s.graph);
            s.config(speech).map(|_| ()).map_err(|e| e.to_string())
        };
        let rates = |g: &mut GraphSettings| {
            g.rates.push(("policy".into(), 10.0));
            g.rates.push(("policy".into(), 20.0));
        };
        assert_eq!(
            refused(&rates, Speech::Flags).unwrap_err(),
            "--rate policy=10 and --rate policy=20 both set the rate of node 'policy'; give one"
        );
        // The same value twice is one setting; two nodes are two.
        let same = |g: &mut GraphSettings| {
            g.rates.push(("policy".into(), 10.0));
            g.rates.push(("policy".into(), 10.0));
            g.rates.push(("sensor".into(), 20.0));
        };
        assert_eq!(refused(&same, Speech::Flags), Ok(()));
        // A depth given by --depth and by a QoS's depth=, in Python's words.
        let depths = |g: &mut GraphSettings| {
            g.depths.push(("/obs".into(), 3));
            g.qos
                .push(("/obs".into(), "history=keep_last,depth=5".into()));
        };
        assert_eq!(
            refused(&depths, Speech::Keywords).unwrap_err(),
            "depth[\"/obs\"]=3 and qos[\"/obs\"]=\"history=keep_last,depth=5\" both set the history depth of topic '/obs'; give one"
        );
        // One QoS key in two --qos flags; other keys of one topic are apart.
        let qos = |g: &mut GraphSettings| {
            g.qos.push(("/action".into(), "deadline_ms=40".into()));
            g.qos.push(("/action".into(), "lifespan_ms=60".into()));
            g.qos.push(("/action".into(), "deadline_ms=50".into()));
        };
        assert_eq!(
            refused(&qos, Speech::Flags).unwrap_err(),
            "--qos /action:deadline_ms=40 and --qos /action:deadline_ms=50 both set the QoS 'deadline_ms' of topic '/action'; give one"
        );
        let links = |g: &mut GraphSettings| {
            g.links.push(("/obs".into(), "loss=0.1".into()));
            g.links.push(("/obs".into(), "loss=0.2,delay_ms=5".into()));
        };
        assert!(refused(&links, Speech::Flags)
            .unwrap_err()
            .ends_with("both set the link's 'loss' on topic '/obs'; give one"));
        // A link key by --qos (which takes link keys) and by --link is one setting.
        let both = |g: &mut GraphSettings| {
            g.qos.push(("/obs".into(), "loss=0.1".into()));
            g.links.push(("/obs".into(), "loss=0.2".into()));
        };
        assert_eq!(
            refused(&both, Speech::Flags).unwrap_err(),
            "--qos /obs:loss=0.1 and --link /obs:loss=0.2 both set the link's 'loss' on topic '/obs'; give one"
        );
        // Numbers are compared as numbers.
        let same = |g: &mut GraphSettings| {
            g.qos.push(("/action".into(), "deadline_ms=40".into()));
            g.qos
                .push(("/action".into(), "deadline_ms=40.0,lifespan_ms=60".into()));
            g.links.push(("/obs".into(), "loss=0.1".into()));
            g.links.push(("/obs".into(), "loss=0.10".into()));
        };
        assert_eq!(refused(&same, Speech::Flags), Ok(()));
        // An entry's own refusal comes first: an unknown node, not "both set".
        let unknown = |g: &mut GraphSettings| {
            g.rates.push(("nobody".into(), 5.0));
            g.rates.push(("nobody".into(), 6.0));
        };
        assert!(refused(&unknown, Speech::Flags)
            .unwrap_err()
            .starts_with("--rate nobody=5: "));
        let leases = |g: &mut GraphSettings| {
            g.leases_ms.push(("policy".into(), 100.0));
            g.leases_ms.push(("policy".into(), 200.0));
        };
        assert_eq!(
            refused(&leases, Speech::Flags).unwrap_err(),
            "--lease policy=100 and --lease policy=200 both set the lease of node 'policy'; give one"
        );
    }

    #[test]
    fn keyed_settings_are_named_by_key() {
        let mut s = spec();
        s.graph.rates.push(("polcy".into(), 10.0));
        let line = s.config(Speech::Keywords).unwrap_err().to_string();
        assert!(line.starts_with("rate[\"polcy\"]=10: "), "{line}");
        assert!(line.contains("policy"), "{line}");
        let line = s.config(Speech::Flags).unwrap_err().to_string();
        assert!(line.starts_with("--rate polcy=10: "), "{line}");
        let mut s = spec();
        s.graph.depths.push(("/obs".into(), 0));
        let line = s.config(Speech::Keywords).unwrap_err().to_string();
        assert_eq!(line, "depth[\"/obs\"]=0: a history depth is at least 1");
        let mut s = spec();
        s.graph.links.push(("/obs".into(), "depth=3".into()));
        let line = s.config(Speech::Keywords).unwrap_err().to_string();
        assert!(line.ends_with("; use qos"), "{line}");
    }

    #[test]
    fn two_settings_of_one_rate_are_refused_naming_both() {
        let mut s = spec();
        s.control_hz = Some(10.0);
        s.graph.rates.push(("policy".into(), 20.0));
        assert_eq!(
            s.config(Speech::Flags).unwrap_err().to_string(),
            "--rate policy=20 and --control-hz (10 Hz) both set the rate of node 'policy'; give one"
        );
        assert_eq!(
            s.config(Speech::Keywords).unwrap_err().to_string(),
            "rate[\"policy\"]=20 and control_hz (10 Hz) both set the rate of node 'policy'; give one"
        );
        let s = RunSpec {
            break_: true,
            control_hz: Some(10.0),
            ..spec()
        };
        assert_eq!(
            s.config(Speech::Flags).unwrap_err().to_string(),
            "--break sets the policy to 5 Hz and --control-hz to 10 Hz; give one"
        );
    }

    #[test]
    fn the_shorthands_and_smoke_set_the_run() {
        let s = RunSpec {
            control_hz: Some(20.0),
            sensor_hz: Some(40.0),
            queue_depth: Some(3),
            smoke: true,
            clock: ClockKind::Real,
            ..RunSpec::default()
        };
        let cfg = s.config(Speech::Keywords).unwrap();
        assert_eq!(cfg.control_hz(), Some(20.0));
        assert_eq!(cfg.sensor_hz(), Some(40.0));
        assert_eq!(cfg.queue_depth(), Some(3));
        assert_eq!(cfg.clock, ClockKind::Virtual);
        assert_eq!(cfg.duration, Nanos(2 * Nanos::SECOND.0));
        let zero = RunSpec {
            outputs: Outputs {
                trace_every: 0,
                ..Outputs::default()
            },
            ..spec()
        };
        assert_eq!(
            zero.config(Speech::Keywords).unwrap_err().to_string(),
            "trace_every must be at least 1, got 0"
        );
    }

    #[test]
    fn a_duration_to_the_ns_is_exact_and_refused_beside_one_in_seconds() {
        let exact = RunSpec {
            duration_ns: Some((1 << 53) + 1),
            ..spec()
        };
        assert_eq!(
            exact.config(Speech::Keywords).unwrap().duration,
            Nanos((1 << 53) + 1)
        );
        let both = RunSpec {
            duration_s: Some(1.0),
            ..exact.clone()
        };
        assert_eq!(
            both.config(Speech::Keywords).unwrap_err().to_string(),
            "duration_s and duration_ns both set the run's duration; give one"
        );
        let zero = RunSpec {
            duration_ns: Some(0),
            ..spec()
        };
        let line = zero.config(Speech::Flags).unwrap_err().to_string();
        assert!(line.starts_with("duration_ns must be in (0, "), "{line}");
    }

    #[test]
    fn a_node_killed_twice_is_refused_naming_both() {
        let mut s = spec();
        for at in [3, 2] {
            s.graph.kills.push(Fault {
                node: "actuator".into(),
                at: Nanos(at * Nanos::SECOND.0),
                duration: None,
            });
        }
        assert_eq!(
            s.config(Speech::Flags).unwrap_err().to_string(),
            "--kill actuator@3 and --kill actuator@2 both kill node 'actuator'; give one"
        );
        s.graph.kills[1].node = "sensor".into();
        assert!(s.config(Speech::Flags).is_ok());
    }
}
