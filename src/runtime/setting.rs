//! A run's settings by name, in the words of the front end that was given them.
//!
//! One rule refuses a bad setting for every front end (`ratelab_drivers::run_spec`), and its
//! line names the setting as the person typed it: the command line as a flag
//! (`--control-hz`), the Python package as a keyword (`control_hz`). A rule writes
//! [`Speech::name`] where it names a setting, never a flag by hand.

/// One setting of a run (the fields of `ratelab_drivers::run_spec::RunSpec`), or of a sweep or
/// cliff search (`ratelab_drivers::sweep_spec::{SweepSpec, CliffSpec}`).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Setting {
    /// The graph file.
    Graph,
    /// The reset seed.
    Seed,
    /// The run's length, s.
    Duration,
    /// The clock (real or virtual).
    Clock,
    /// The chain sensor's rate, Hz.
    SensorHz,
    /// The chain policy's (control) rate, Hz.
    ControlHz,
    /// `--break`: the control rate set to the chapter's cliff.
    Break,
    /// The history depth of every topic, messages.
    QueueDepth,
    /// A node's rate, Hz.
    Rate,
    /// A topic's history depth, messages.
    Depth,
    /// A topic's QoS.
    Qos,
    /// A topic's lossy link.
    Link,
    /// A node's liveliness lease, ms.
    Lease,
    /// A node's injected stall.
    Stall,
    /// A node's injected kill.
    Kill,
    /// A node's compute time, ms.
    Compute,
    /// Every node on one executor.
    Executor,
    /// The nodes' first-tick offsets, ms.
    PhaseOffset,
    /// The real clock's spin margin, µs.
    SpinMargin,
    /// The real clock's `SCHED_FIFO` priority.
    RtPriority,
    /// The brain.
    Policy,
    /// The folder of `metrics.json`, `trace.csv`, `log.txt`.
    Out,
    /// One actuator step in this many kept in the trace.
    TraceEvery,
    /// The rerun recording.
    Record,
    /// Replace existing outputs.
    Force,
    /// A sweep's or cliff search's seeds.
    Seeds,
    /// A cliff search's lowest control rate, Hz.
    MinHz,
    /// A cliff search's highest control rate, Hz.
    MaxHz,
    /// A cliff search's resolution, Hz.
    Step,
}

/// Whose words a refusal uses for a [`Setting`].
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub enum Speech {
    /// The command line's: `--control-hz`, `--rate policy=10`.
    #[default]
    Flags,
    /// The Python package's (`ratelab.run`'s keywords): `control_hz`, `rate['policy']=10`.
    Keywords,
}

impl Setting {
    /// The command line's flag: `--control-hz`.
    pub fn flag(self) -> &'static str {
        match self {
            Setting::Graph => "--graph",
            Setting::Seed => "--seed",
            Setting::Duration => "--duration",
            Setting::Clock => "--clock",
            Setting::SensorHz => "--sensor-hz",
            Setting::ControlHz => "--control-hz",
            Setting::Break => "--break",
            Setting::QueueDepth => "--queue-depth",
            Setting::Rate => "--rate",
            Setting::Depth => "--depth",
            Setting::Qos => "--qos",
            Setting::Link => "--link",
            Setting::Lease => "--lease",
            Setting::Stall => "--stall",
            Setting::Kill => "--kill",
            Setting::Compute => "--compute",
            Setting::Executor => "--executor",
            Setting::PhaseOffset => "--phase-offset-ms",
            Setting::SpinMargin => "--spin-margin-us",
            Setting::RtPriority => "--rt-priority",
            Setting::Policy => "--policy",
            Setting::Out => "--out",
            Setting::TraceEvery => "--trace-every",
            Setting::Record => "--record",
            Setting::Force => "--force",
            Setting::Seeds => "--seeds",
            Setting::MinHz => "--min-hz",
            Setting::MaxHz => "--max-hz",
            Setting::Step => "--step",
        }
    }

    /// `ratelab.run`'s keyword (or `ratelab.sweep`'s, `ratelab.cliff`'s), units in the name
    /// where the flag leaves them to its help: `control_hz`, `duration_s`, `lease_ms`,
    /// `step_hz`.
    pub fn keyword(self) -> &'static str {
        match self {
            Setting::Graph => "graph",
            Setting::Seed => "seed",
            Setting::Duration => "duration_s",
            Setting::Clock => "clock",
            Setting::SensorHz => "sensor_hz",
            Setting::ControlHz => "control_hz",
            Setting::Break => "break_",
            Setting::QueueDepth => "queue_depth",
            Setting::Rate => "rate",
            Setting::Depth => "depth",
            Setting::Qos => "qos",
            Setting::Link => "link",
            Setting::Lease => "lease_ms",
            Setting::Stall => "stall",
            Setting::Kill => "kill",
            Setting::Compute => "compute_ms",
            Setting::Executor => "executor",
            Setting::PhaseOffset => "phase_offset_ms",
            Setting::SpinMargin => "spin_margin_us",
            Setting::RtPriority => "rt_priority",
            Setting::Policy => "policy",
            Setting::Out => "out",
            Setting::TraceEvery => "trace_every",
            Setting::Record => "record",
            Setting::Force => "force",
            Setting::Seeds => "seeds",
            Setting::MinHz => "min_hz",
            Setting::MaxHz => "max_hz",
            Setting::Step => "step_hz",
        }
    }
}

impl Speech {
    /// `setting` in these words: `--control-hz` or `control_hz`.
    pub fn name(self, setting: Setting) -> &'static str {
        match self {
            Speech::Flags => setting.flag(),
            Speech::Keywords => setting.keyword(),
        }
    }

    /// One entry of a keyed setting as it was given: `--rate policy=10` or
    /// `rate['policy']=10`.
    pub fn entry(self, setting: Setting, key: &str, value: &dyn std::fmt::Display) -> String {
        match self {
            Speech::Flags => format!("{} {key}={value}", setting.flag()),
            Speech::Keywords => format!("{}[{key:?}]={value}", setting.keyword()),
        }
    }

    /// One value of a setting as it was given: `--control-hz 0` or `control_hz=0`.
    pub fn value(self, setting: Setting, value: &dyn std::fmt::Display) -> String {
        match self {
            Speech::Flags => format!("{} {value}", setting.flag()),
            Speech::Keywords => format!("{}={value}", setting.keyword()),
        }
    }

    /// The words for "pass `--force`" (or `force=True`).
    pub fn force(self) -> &'static str {
        match self {
            Speech::Flags => "--force",
            Speech::Keywords => "force=True",
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_setting_is_named_as_its_front_end_takes_it() {
        assert_eq!(Speech::Flags.name(Setting::ControlHz), "--control-hz");
        assert_eq!(Speech::Keywords.name(Setting::ControlHz), "control_hz");
        assert_eq!(Speech::Keywords.name(Setting::Duration), "duration_s");
        assert_eq!(
            Speech::Flags.entry(Setting::Rate, "policy", &10),
            "--rate policy=10"
        );
        assert_eq!(
            Speech::Keywords.entry(Setting::Rate, "policy", &10),
            "rate[\"policy\"]=10"
        );
        assert_eq!(Speech::Keywords.value(Setting::Seed, &3), "seed=3");
        assert_eq!(Speech::Flags.name(Setting::Step), "--step");
        assert_eq!(Speech::Keywords.name(Setting::Step), "step_hz");
        assert_eq!(Speech::Keywords.name(Setting::Seeds), "seeds");
    }

    #[test]
    fn every_keyword_is_a_python_identifier_and_every_flag_a_long_flag() {
        use Setting::*;
        for s in [
            Graph,
            Seed,
            Duration,
            Clock,
            SensorHz,
            ControlHz,
            Break,
            QueueDepth,
            Rate,
            Depth,
            Qos,
            Link,
            Lease,
            Stall,
            Kill,
            Compute,
            Executor,
            PhaseOffset,
            SpinMargin,
            RtPriority,
            Policy,
            Out,
            TraceEvery,
            Record,
            Force,
            Seeds,
            MinHz,
            MaxHz,
            Step,
        ] {
            let k = s.keyword();
            assert!(k.chars().all(|c| c.is_ascii_lowercase() || c == '_'), "{k}");
            assert!(s.flag().starts_with("--"), "{}", s.flag());
        }
    }
}
