//! ex9, the crossing: the chapter's graph under the real clock, in one process and split
//! across two (the plant's `robot` process holding sensor and actuator, the policy alone),
//! first with every node waking at the same instant, then with phase offsets. A message
//! that crosses processes takes a fraction of a millisecond on the wire, so the node that
//! ticks at the instant it was published never has it: each crossing hop costs a period.
//! Real clock, real processes over Zenoh ([`ratelab_distributed`]): the checks assert only
//! what holds on a noisy machine (medians).

use super::{check, Check, Context, Exercise, ExerciseError, Reconcile, Said, Section};
use ratelab_core::metrics::Metrics;
use ratelab_distributed::launcher::Program;
use ratelab_runtime::config::{duration_from_secs, phase_offset_from_ms, ClockKind, RunConfig};
use ratelab_runtime::graph::GraphSpec;
use ratelab_runtime::scheduler::StopFlag;
use serde::Deserialize;
use std::path::Path;

/// ex9: the crossing.
pub struct Ex9;

/// ex9's settings and the bands its checks assert.
#[derive(Clone, Debug, Deserialize)]
pub struct Ex9Bands {
    /// Run length of each run, s.
    pub duration_s: f64,
    /// Offsets for sensor, policy, actuator (tie-break order), ms.
    pub phase_offset_ms: [f64; 3],
    /// Across processes without offsets, the median sense→act latency is two policy
    /// periods: within this `[low, high]`, ms.
    pub across_p50_ms: [f64; 2],
    /// Across processes with the offsets, the median is the sensor-to-actuator offset (the
    /// last minus the first) within this, ms.
    pub offsets_p50_tolerance_ms: f64,
}

impl Ex9Bands {
    /// The latency the offsets fix, ms ([`super::fixed_latency_ms`]).
    pub fn fixed_latency_ms(&self) -> f64 {
        super::fixed_latency_ms(&self.phase_offset_ms)
    }
}

impl Section for Ex9Bands {
    const NAME: &'static str = "ex9";
}

/// ex9's outcome: the median sense→act latency across processes, without and with the
/// offsets.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Ex9Outcome {
    /// ms.
    pub p50_latency_across_ms: f64,
    /// ms.
    pub p50_latency_across_offsets_ms: f64,
}

/// The three ways ex9 runs the graph.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Ex9Case {
    /// One process (`ratelab run --clock real`).
    OneProcess,
    /// Two processes (`ratelab launch --processes --clock real`).
    Across,
    /// Two processes with the phase offsets.
    AcrossWithOffsets,
}

impl Ex9Case {
    /// Every case, in the order the exercise runs and shows them.
    pub const ALL: [Ex9Case; 3] = [
        Ex9Case::OneProcess,
        Ex9Case::Across,
        Ex9Case::AcrossWithOffsets,
    ];

    /// The case as the table names it.
    pub fn label(self) -> &'static str {
        match self {
            Ex9Case::OneProcess => "one process",
            Ex9Case::Across => "two processes",
            Ex9Case::AcrossWithOffsets => "two processes, offsets",
        }
    }
}

/// One ex9 run.
#[derive(Clone, Debug)]
pub struct Ex9Run {
    /// Which case.
    pub case: Ex9Case,
    /// What it measured (merged from the processes across processes).
    pub metrics: Metrics,
    /// Across processes: the median wire latency of each crossing topic, µs, in the graph's
    /// topic order.
    pub wire_p50_us: Vec<(String, f64)>,
}

/// ex9's measurements: the three cases, each once, on `graph` (the file at `graph_path`,
/// `None` for the chapter's compiled-in graph, which the started processes load too),
/// starting the processes with `exe`, ratelab's command line.
///
/// # Errors
/// [`ExerciseError`] when a run cannot start, or a launch fails (a process that cannot be
/// started, a port that cannot be listened on).
pub fn measure_ex9(
    b: &Ex9Bands,
    graph: &GraphSpec,
    graph_path: Option<&Path>,
    exe: &Program,
    stop: &StopFlag,
) -> Result<Vec<Ex9Run>, ExerciseError> {
    let base = RunConfig {
        clock: ClockKind::Real,
        duration: duration_from_secs(b.duration_s)?,
        graph: graph.clone(),
        ..RunConfig::default()
    };
    let offsets = b
        .phase_offset_ms
        .iter()
        .map(|&ms| phase_offset_from_ms(ms))
        .collect::<Result<Vec<_>, _>>()?;
    let across = |cfg: &RunConfig| -> Result<(Metrics, Vec<(String, f64)>), ExerciseError> {
        let report = super::launch_across(cfg, graph_path, exe, Vec::new(), stop)?;
        if !report.missing.is_empty() {
            return Err(ExerciseError::Launch(format!(
                "process(es) {} did not report",
                report.missing.join(", ")
            )));
        }
        // In the graph's topic order (the reports arrive in any order).
        let mut wire: Vec<(String, f64)> = report
            .wire
            .iter()
            .map(|w| (w.topic.clone(), w.p50_us))
            .collect();
        wire.sort_by_key(|(t, _)| cfg.graph.topics.iter().position(|x| &x.name == t));
        Ok((report.metrics, wire))
    };
    let mut runs = Vec::new();
    for case in Ex9Case::ALL {
        let (metrics, wire_p50_us) = match case {
            Ex9Case::OneProcess => (super::run_scripted(&base, stop)?, Vec::new()),
            Ex9Case::Across => across(&base)?,
            Ex9Case::AcrossWithOffsets => across(&RunConfig {
                phase_offsets: offsets.clone(),
                ..base.clone()
            })?,
        };
        runs.push(Ex9Run {
            case,
            metrics,
            wire_p50_us,
        });
    }
    Ok(runs)
}

fn of(runs: &[Ex9Run], case: Ex9Case) -> Option<&Ex9Run> {
    runs.iter().find(|r| r.case == case)
}

/// ex9's outcome in the terms of its prediction.
pub fn outcome_ex9(runs: &[Ex9Run]) -> Ex9Outcome {
    let p50 = |case| of(runs, case).map_or(f64::NAN, |r| r.metrics.latency_p50_ms);
    Ex9Outcome {
        p50_latency_across_ms: p50(Ex9Case::Across),
        p50_latency_across_offsets_ms: p50(Ex9Case::AcrossWithOffsets),
    }
}

/// ex9's checks: the pole stays up in every case; across processes the median latency is
/// two periods (each crossing hop misses the tick at its instant); the offsets bring it to
/// the sensor-to-actuator offset.
pub fn check_ex9(b: &Ex9Bands, runs: &[Ex9Run]) -> Vec<Check> {
    let [lo, hi] = b.across_p50_ms;
    let fixed = b.fixed_latency_ms();
    let tol = b.offsets_p50_tolerance_ms;
    let p50 = |case| of(runs, case).map(|r| r.metrics.latency_p50_ms);
    vec![
        check(
            "the pole stays up in every case",
            runs.len() == Ex9Case::ALL.len() && runs.iter().all(|r| r.metrics.balanced),
        ),
        check(
            format!("across processes, all nodes waking together: median sense→act {lo}-{hi} ms"),
            p50(Ex9Case::Across).is_some_and(|m| (lo..=hi).contains(&m)),
        ),
        check(
            format!(
                "across processes with offsets {:?} ms: median sense→act {fixed} ms (within {tol} ms)",
                b.phase_offset_ms
            ),
            p50(Ex9Case::AcrossWithOffsets).is_some_and(|m| (m - fixed).abs() <= tol),
        ),
    ]
}

/// The learner's ex9 `prediction` beside the outcome, one sentence per key. The medians: right
/// within [`super::NEAR`] (the real clock moves the tails, not the medians: bands.toml).
impl Reconcile for Ex9Outcome {
    fn reconcile(&self, prediction: &toml::Table) -> Vec<Said> {
        reconcile(prediction, self)
    }
}

fn reconcile(prediction: &toml::Table, outcome: &Ex9Outcome) -> Vec<Said> {
    let Ex9Outcome {
        p50_latency_across_ms,
        p50_latency_across_offsets_ms,
    } = *outcome;
    let say = |key: &str, what: &str, measured: f64| {
        match prediction.get(key).and_then(super::number) {
            Some(n) => super::graded(
                key,
                &format!(
                    "You predicted a median sense→act latency of {n} ms {what}; it was {measured:.1} ms"
                ),
                super::near(n, measured, 0.0),
                &super::more_than_near(),
            ),
            None => super::unreadable(key),
        }
    };
    vec![
        say(
            "p50_latency_across_ms",
            "across processes",
            p50_latency_across_ms,
        ),
        say(
            "p50_latency_across_offsets_ms",
            "across processes with the offsets",
            p50_latency_across_offsets_ms,
        ),
    ]
}

impl Exercise for Ex9 {
    fn id(&self) -> &'static str {
        "ex9"
    }

    fn title(&self) -> &'static str {
        "the crossing: real processes"
    }

    fn file(&self) -> &'static str {
        "ex9_crossing.toml"
    }

    fn required_keys(&self) -> &'static [&'static str] {
        &["p50_latency_across_ms", "p50_latency_across_offsets_ms"]
    }

    /// The table (per case: the latency's mean, median and 99th percentile, the drops, the
    /// wire's median per crossing topic), the reconcile and the checks.
    fn run(&self, cx: &mut Context<'_>) -> Result<(), ExerciseError> {
        let b: Ex9Bands = cx.bands()?;
        say!(
            cx,
            "Running {} s on the real clock three times, twice across two processes (this takes real time)...",
            b.duration_s
        );
        let runs = cx.measure(|stop| measure_ex9(&b, cx.graph, cx.graph_path, cx.exe, stop))?;
        say!(cx, "case                   | latency mean |    p50 |    p99 | /obs dropped | /action dropped | wire p50");
        for case in Ex9Case::ALL {
            for r in runs.iter().filter(|r| r.case == case) {
                let m = &r.metrics;
                let wire: Vec<String> = r
                    .wire_p50_us
                    .iter()
                    .map(|(t, us)| format!("{t} {us:.0} µs"))
                    .collect();
                say!(
                    cx,
                    "{:<22} | {:>9.1} ms | {:>6.1} | {:>6.1} | {:>12} | {:>15} | {}",
                    case.label(),
                    m.mean_latency_ms,
                    m.latency_p50_ms,
                    m.latency_p99_ms,
                    m.obs_dropped.unwrap_or(0),
                    m.action_dropped.unwrap_or(0),
                    if wire.is_empty() {
                        "-".to_string()
                    } else {
                        wire.join(", ")
                    }
                );
            }
        }
        cx.reconcile(&outcome_ex9(&runs));
        cx.checks(&check_ex9(&b, &runs));
        say!(cx);
        cx.paragraph(
            "Reconcile: in one process, the policy waking at the sensor's instant races the \
             sensor's thread for the fresh reading, and wins it sometimes (ex3). Across \
             processes it never does: the reading is still on the wire (a fraction of a \
             millisecond), so the policy acts on the one before, a period older (+20 ms); the \
             force crosses back the same way and the actuator, waking at the policy's instant, \
             applies the force before (+20 ms). Each crossing hop at a shared instant costs a \
             full period. Offsets give each hop time to arrive: the sensor at 0, the policy 5 ms \
             later, the actuator 5 ms after that, and the latency is the 10 ms between sensor and \
             actuator. An offset of 1 ms is longer than the wire but not than every stall of a \
             busy machine: then misses come back, some of the time.",
        );
        say!(
            cx,
            "  ./scripts/lab.sh launch --processes --clock real --duration 5 --phase-offset-ms 0,1,2"
        );
        Ok(())
    }
}
