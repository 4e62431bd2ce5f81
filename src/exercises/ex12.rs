//! ex12, the restart: the chapter's graph across processes under the real clock, its policy's
//! process killed mid-run (SIGKILL, as a crash) and started again by the launcher
//! (`restart = "on-failure"`, `graphs/cartpole-restart.toml`). How many readings are lost
//! across the rejoin, and how old does the force the actuator holds meanwhile get? Real
//! clock, real processes over Zenoh ([`ratelab_distributed`]): the checks assert what holds
//! on a loaded machine (the readings lost are those published while no policy ran).

use super::{check, Check, Context, Exercise, ExerciseError, Reconcile, Said, Section};
use ratelab_core::metrics::Metrics;
use ratelab_core::time::Nanos;
use ratelab_distributed::launcher::Program;
use ratelab_runtime::config::{duration_from_secs, ClockKind, RunConfig};
use ratelab_runtime::graph::spec::RestartPolicy;
use ratelab_runtime::graph::GraphSpec;
use ratelab_runtime::scheduler::StopFlag;
use serde::Deserialize;
use std::path::Path;

/// ex12: the restart.
pub struct Ex12;

/// ex12's settings and the bands its checks assert (`bands.toml`'s `[ex12]`).
#[derive(Clone, Debug, Deserialize)]
pub struct Ex12Bands {
    /// The graph, relative to the bands' folder (its policy's process restarts on failure).
    pub graph: String,
    /// The process killed.
    pub process: String,
    /// The topic whose readings the killed process would have read.
    pub topic: String,
    /// When it is killed, s of run time.
    pub kill_at_s: f64,
    /// Run length, s.
    pub duration_s: f64,
    /// The process rejoins within this long of the kill, s.
    pub rejoin_within_s: f64,
    /// How old the killed copy's last figures can be, ms (a process publishes its figures
    /// every [`ratelab_distributed::process::STATS_PERIOD`]): readings it counted after them
    /// are counted lost.
    pub figures_age_ms: f64,
    /// How long the new copy takes from its welcome to its subscription, at most, ms:
    /// readings published meanwhile are lost too.
    pub subscribe_within_ms: f64,
}

impl Section for Ex12Bands {
    const NAME: &'static str = "ex12";
}

/// What one ex12 run measured.
#[derive(Clone, Debug)]
pub struct Ex12Run {
    /// The merged summary.
    pub metrics: Metrics,
    /// When the process was killed, run time (`None`: it was not).
    pub killed_at: Option<Nanos>,
    /// When the process rejoined (the launcher let its new copy in), run time; `None`: it
    /// did not.
    pub rejoined_at: Option<Nanos>,
}

/// ex12's outcome in the terms of its prediction.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Ex12Outcome {
    /// Readings of the topic lost (published, never received by any copy of the process).
    pub readings_lost: u64,
    /// From the kill to the rejoin (the new copy let in), ms (`NaN`: no kill or no rejoin).
    pub gap_ms: f64,
    /// The sense→act latency's maximum, ms: the held force's age when a new one came.
    pub latency_max_ms: f64,
}

/// ex12's measurement: one launch of `graph` (read from `graph_path`, which the started
/// processes load too) under the real clock, its `process` killed at `kill_at_s`, starting
/// the processes with `exe`.
///
/// # Errors
/// [`ExerciseError`] when the graph does not restart the process, or the launch fails.
pub fn measure_ex12(
    b: &Ex12Bands,
    graph: &GraphSpec,
    graph_path: Option<&Path>,
    exe: &Program,
    stop: &StopFlag,
) -> Result<Ex12Run, ExerciseError> {
    if graph.restart.get(&b.process) != Some(&RestartPolicy::OnFailure) {
        return Err(ExerciseError::Launch(format!(
            "graph '{}' does not start process '{}' again ([processes.{}] restart = \"on-failure\")",
            graph.name, b.process, b.process
        )));
    }
    let cfg = RunConfig {
        clock: ClockKind::Real,
        duration: duration_from_secs(b.duration_s)?,
        graph: graph.clone(),
        ..RunConfig::default()
    };
    let kill_at = duration_from_secs(b.kill_at_s)?;
    let killed = vec![(b.process.clone(), kill_at)];
    let report = super::launch_across(&cfg, graph_path, exe, killed, stop)?;
    let rejoined_at = report
        .wire
        .iter()
        .filter(|w| w.process == b.process)
        .find_map(|w| w.since_ns)
        .map(Nanos);
    let killed_at = report
        .killed
        .iter()
        .find(|(p, _)| *p == b.process)
        .map(|(_, t)| *t);
    Ok(Ex12Run {
        metrics: report.metrics,
        killed_at,
        rejoined_at,
    })
}

/// ex12's outcome from its run.
pub fn outcome_ex12(b: &Ex12Bands, run: &Ex12Run) -> Ex12Outcome {
    let lost = run
        .metrics
        .topics
        .get(&b.topic)
        .and_then(|t| t.qos_counters.get("lost").copied())
        .unwrap_or(0);
    Ex12Outcome {
        readings_lost: lost,
        gap_ms: match (run.killed_at, run.rejoined_at) {
            (Some(k), Some(r)) => (r.as_secs_f64() - k.as_secs_f64()) * 1e3,
            _ => f64::NAN,
        },
        latency_max_ms: run.metrics.latency_max_ms,
    }
}

/// The topic's publisher's rate, Hz: how many readings a gap holds.
fn reading_hz(graph: &GraphSpec, topic: &str) -> Option<f64> {
    let t = graph.topics.iter().find(|t| t.name == topic)?;
    Some(graph.nodes[t.publisher.0].rate_hz)
}

/// The readings an ex12 run must count lost, `(at least, at most)`: every reading published
/// from the kill to the rejoin (none can have reached a copy), and at most those plus the
/// readings of the killed copy's last figures' age and of the new copy's way from its
/// welcome to its subscription. `None` without a kill and a rejoin.
pub fn lost_bounds(b: &Ex12Bands, hz: f64, gap_ms: f64) -> Option<(u64, u64)> {
    if !(gap_ms.is_finite() && gap_ms >= 0.0 && hz > 0.0) {
        return None;
    }
    let readings = |ms: f64| ms / 1e3 * hz;
    let least = (readings(gap_ms).floor() as u64).saturating_sub(1);
    let most = readings(gap_ms + b.figures_age_ms + b.subscribe_within_ms).ceil() as u64 + 1;
    Some((least, most))
}

/// ex12's checks: the pole stays up across the restart; the process rejoins in time; the
/// readings counted lost cover the gap ([`lost_bounds`]; a restart faster than the sensor's
/// period may lose none); the held force aged by the gap.
pub fn check_ex12(b: &Ex12Bands, graph: &GraphSpec, run: &Ex12Run) -> Vec<Check> {
    let o = outcome_ex12(b, run);
    let hz = reading_hz(graph, &b.topic).unwrap_or(0.0);
    let bounds = lost_bounds(b, hz, o.gap_ms);
    vec![
        check(
            "the pole stays up across the restart",
            run.metrics.balanced,
        ),
        check(
            format!(
                "process '{}' is started again and rejoins within {} s of the kill",
                b.process, b.rejoin_within_s
            ),
            o.gap_ms.is_finite() && o.gap_ms >= 0.0 && o.gap_ms <= b.rejoin_within_s * 1e3,
        ),
        check(
            format!(
                "the {} readings counted lost cover the gap: those published in it ({hz} Hz), and at most {} ms more (the killed copy's last figures, the new copy's subscription)",
                b.topic,
                b.figures_age_ms + b.subscribe_within_ms
            ),
            bounds.is_some_and(|(least, most)| (least..=most).contains(&o.readings_lost)),
        ),
        check(
            "the force the actuator held aged by the whole gap (max sense→act latency ≥ the gap)",
            o.gap_ms.is_finite() && o.latency_max_ms >= o.gap_ms,
        ),
    ]
}

/// The readings lost: right within [`super::NEAR`] or one reading. The longest latency:
/// right within [`super::NEAR`].
impl Reconcile for Ex12Outcome {
    fn reconcile(&self, prediction: &toml::Table) -> Vec<Said> {
        let key = "readings_lost";
        let lost = match prediction.get(key).and_then(super::number) {
            Some(n) => super::graded(
                key,
                &format!(
                    "You predicted {n} readings lost across the restart; {} were",
                    self.readings_lost
                ),
                super::near(n, self.readings_lost as f64, 1.0),
                &format!(
                    ": off by more than 1 and by more than {:.0}%",
                    super::NEAR * 100.0
                ),
            ),
            None => super::unreadable(key),
        };
        let key = "latency_max_ms";
        let latency = match prediction.get(key).and_then(super::number) {
            Some(n) => super::graded(
                key,
                &format!(
                    "You predicted a longest sense→act latency of {n} ms; it was {:.1} ms",
                    self.latency_max_ms
                ),
                super::near(n, self.latency_max_ms, 0.0),
                &super::more_than_near(),
            ),
            None => super::unreadable(key),
        };
        vec![lost, latency]
    }
}

impl Exercise for Ex12 {
    fn id(&self) -> &'static str {
        "ex12"
    }

    fn title(&self) -> &'static str {
        "the restart: a process's rejoin"
    }

    fn file(&self) -> &'static str {
        "ex12_restart.toml"
    }

    fn required_keys(&self) -> &'static [&'static str] {
        &["readings_lost", "latency_max_ms"]
    }

    fn default_graph(&self, bands: &super::Bands) -> Result<Option<String>, ExerciseError> {
        Ok(Some(bands.of::<Ex12Bands>()?.graph))
    }

    /// The run's figures (the gap, the readings lost, the policy's ticks, the latency), the
    /// reconcile, the checks and the explanation.
    fn run(&self, cx: &mut Context<'_>) -> Result<(), ExerciseError> {
        let b: Ex12Bands = cx.bands()?;
        say!(
            cx,
            "Running {} s on the real clock across processes, '{}' killed at t = {} s (this takes real time)...",
            b.duration_s,
            b.process,
            b.kill_at_s
        );
        let run = cx.measure(|stop| measure_ex12(&b, cx.graph, cx.graph_path, cx.exe, stop))?;
        let o = outcome_ex12(&b, &run);
        let hz = reading_hz(cx.graph, &b.topic).unwrap_or(0.0);
        let m = &run.metrics;
        let ticks = |node: &str| m.nodes.get(node).map_or(0, |n| n.ticks);
        let expected = (b.duration_s * hz).round() as u64 + 1;
        say!(
            cx,
            "killed at | rejoined at |     gap | {} published | lost | policy ticks | latency p50 | max",
            b.topic
        );
        say!(
            cx,
            "{:>9} | {:>11} | {:>7} | {:>14} | {:>4} | {:>5} of {:<4} | {:>8.1} ms | {:.1} ms",
            run.killed_at
                .map_or("-".into(), |t| format!("{:.3} s", t.as_secs_f64())),
            run.rejoined_at
                .map_or("-".into(), |t| format!("{:.3} s", t.as_secs_f64())),
            if o.gap_ms.is_finite() {
                format!("{:.0} ms", o.gap_ms)
            } else {
                "-".into()
            },
            m.topics.get(&b.topic).map_or(0, |t| t.published),
            o.readings_lost,
            ticks("policy"),
            expected,
            m.latency_p50_ms,
            m.latency_max_ms
        );
        cx.reconcile(&o);
        cx.checks(&check_ex12(&b, cx.graph, &run));
        say!(cx);
        cx.paragraph(&format!(
            "Reconcile: the kill ends the policy's process at once, and its liveliness token \
             goes with it. The launcher sees it fail, starts a new copy, which opens its session \
             and proves who it is (its own certificate), and lets it in: {:.0} ms here, part of \
             it the launcher's own polling (every 50 ms). The new copy then builds its graph, \
             subscribes and is started on the run's clock. Meanwhile the sensor went on \
             publishing {} at {hz} Hz to no subscriber: those readings are lost, and a new \
             process has no history to catch up from. The count of lost readings also takes in \
             what the killed copy read after its last figures (published every 100 ms: a \
             SIGKILL leaves no last word). The actuator never stopped: it held the last force it \
             had, older at every tick, until the new policy's first force came; the longest \
             sense→act latency is that force's age. A restart is fast, but it is a gap in the \
             control loop as long as a process takes to start and join.",
            o.gap_ms, b.topic
        ));
        say!(
            cx,
            "  ./scripts/lab.sh launch --processes --clock real --duration 8 graphs/cartpole-restart.toml --kill-process policy@3"
        );
        Ok(())
    }
}
