//! ex10, the held force: kill the policy of a balanced pole and watch the actuator hold its
//! last command (the zero-order hold) while liveliness says the policy is gone. How long
//! does the pole stay up on a force nobody is computing any more? Virtual clock: exact.

use super::{check, Check, Context, Exercise, ExerciseError, Reconcile, Said, Section};
use ratelab_core::metrics::Metrics;
use ratelab_core::qos::Fault;
use ratelab_core::time::Nanos;
use ratelab_runtime::config::{duration_from_secs, ClockKind, RunConfig};
use ratelab_runtime::graph::GraphSpec;
use ratelab_runtime::scheduler::StopFlag;
use serde::Deserialize;

/// ex10: the held force.
pub struct Ex10;

/// ex10's runs and bands (`bands.toml`'s `[ex10]`).
#[derive(Clone, Debug, Deserialize)]
pub struct Ex10Bands {
    /// Seeds.
    pub seeds: Vec<u64>,
    /// The node killed (the chapter's policy).
    pub node: String,
    /// When it is killed, s of run time (the pole balanced until then).
    pub kill_at_s: f64,
    /// Its liveliness lease, ms: how soon the graph can know it is gone.
    pub lease_ms: f64,
    /// Run length, s.
    pub duration_s: f64,
    /// On every seed the pole stays up at least this long after the kill, s...
    pub stays_up_at_least_s: f64,
    /// ...and falls within this long of it, s.
    pub stays_up_at_most_s: f64,
}

impl Section for Ex10Bands {
    const NAME: &'static str = "ex10";
}

/// ex10's outcome: how long the pole stayed up after the kill, per seed, s (`None`: it did
/// not fall within the run).
#[derive(Clone, Debug, PartialEq)]
pub struct Ex10Outcome {
    /// Per seed, in the bands' order.
    pub stays_up_s: Vec<Option<f64>>,
}

impl Ex10Outcome {
    /// The mean over the seeds that fell, s.
    pub fn mean_s(&self) -> Option<f64> {
        let fell: Vec<f64> = self.stays_up_s.iter().flatten().copied().collect();
        (!fell.is_empty()).then(|| fell.iter().sum::<f64>() / fell.len() as f64)
    }
}

/// ex10's measurements: one run per seed of `graph` with the node killed at `kill_at_s` and
/// its lease set, in the bands' seed order.
///
/// # Errors
/// [`ExerciseError`] when the graph has no such node or a run cannot start.
pub fn measure_ex10(
    b: &Ex10Bands,
    graph: &GraphSpec,
    stop: &StopFlag,
) -> Result<Vec<Metrics>, ExerciseError> {
    let mut graph = graph.clone();
    graph.set_lease(&b.node, b.lease_ms)?;
    let kill = Fault {
        node: b.node.clone(),
        at: Nanos((b.kill_at_s * 1e9) as u64),
        duration: None,
    };
    b.seeds
        .iter()
        .map(|&seed| {
            let cfg = RunConfig {
                clock: ClockKind::Virtual,
                seed,
                duration: duration_from_secs(b.duration_s)?,
                graph: graph.clone(),
                faults: vec![kill.clone()],
                ..RunConfig::default()
            };
            super::run_scripted(&cfg, stop)
        })
        .collect()
}

/// ex10's outcome from its runs.
pub fn outcome_ex10(b: &Ex10Bands, runs: &[Metrics]) -> Ex10Outcome {
    Ex10Outcome {
        stays_up_s: runs
            .iter()
            .map(|m| m.fell_at_s.map(|t| t - b.kill_at_s))
            .collect(),
    }
}

/// ex10's checks on its runs.
pub fn check_ex10(b: &Ex10Bands, runs: &[Metrics]) -> Vec<Check> {
    let not_alive = |m: &Metrics| m.nodes.get(&b.node).and_then(|n| n.not_alive);
    vec![
        check(
            format!("balances on every seed until the kill at {} s", b.kill_at_s),
            runs.iter()
                .all(|m| m.fell_at_s.is_none_or(|t| t > b.kill_at_s)),
        ),
        check(
            format!(
                "stays up {}–{} s after the kill on every seed, on the held force",
                b.stays_up_at_least_s, b.stays_up_at_most_s
            ),
            runs.iter().all(|m| {
                m.fell_at_s.is_some_and(|t| {
                    let up = t - b.kill_at_s;
                    up >= b.stays_up_at_least_s && up <= b.stays_up_at_most_s
                })
            }),
        ),
        check(
            format!(
                "the {} is reported not alive once (lease {} ms) on every seed",
                b.node, b.lease_ms
            ),
            runs.iter().all(|m| not_alive(m) == Some(1)),
        ),
    ]
}

/// The seconds on the held force: right within [`super::NEAR`] of their mean over the seeds
/// (missed when the pole never fell).
impl Reconcile for Ex10Outcome {
    fn reconcile(&self, prediction: &toml::Table) -> Vec<Said> {
        let measured = match self.mean_s() {
            Some(mean) => format!(
                "it stayed up {} s ({mean:.2} s on average)",
                self.stays_up_s
                    .iter()
                    .map(|s| s.map_or("the whole run".into(), |s| format!("{s:.2}")))
                    .collect::<Vec<_>>()
                    .join(", ")
            ),
            None => "it never fell".into(),
        };
        let key = "stays_up_s";
        vec![match prediction.get(key).and_then(super::number) {
            Some(s) => super::graded(
                key,
                &format!("You predicted the pole stays up {s} s after the kill; {measured}"),
                self.mean_s().is_some_and(|mean| super::near(s, mean, 0.0)),
                &super::more_than_near(),
            ),
            None => super::unreadable(key),
        }]
    }
}

impl Exercise for Ex10 {
    fn id(&self) -> &'static str {
        "ex10"
    }

    fn title(&self) -> &'static str {
        "the held force"
    }

    fn file(&self) -> &'static str {
        "ex10_held_force.toml"
    }

    fn required_keys(&self) -> &'static [&'static str] {
        &["stays_up_s"]
    }

    fn run(&self, cx: &mut Context<'_>) -> Result<(), ExerciseError> {
        let b: Ex10Bands = cx.bands()?;
        let runs = cx.measure(|stop| measure_ex10(&b, cx.graph, stop))?;
        let outcome = outcome_ex10(&b, &runs);
        say!(
            cx,
            "{:>6} | {:>9} | {:>10} | {:>10} | not alive",
            "seed",
            "fell at",
            "stayed up",
            "ticks lost"
        );
        for ((seed, m), up) in b.seeds.iter().zip(&runs).zip(&outcome.stays_up_s) {
            let node = m.nodes.get(&b.node);
            say!(
                cx,
                "{:>6} | {:>9} | {:>10} | {:>10} | {}",
                seed,
                m.fell_at_s.map_or("-".into(), |t| format!("{t:.2} s")),
                up.map_or("-".into(), |s| format!("{s:.2} s")),
                node.and_then(|n| n.faulted_ticks)
                    .map_or("-".into(), |t| t.to_string()),
                node.and_then(|n| n.not_alive)
                    .map_or("-".into(), |k| format!("{k}×"))
            );
        }
        say!(
            cx,
            "(The {} killed at {} s, lease {} ms; the actuator goes on applying its last command.)",
            b.node,
            b.kill_at_s,
            b.lease_ms
        );
        cx.reconcile(&outcome);
        cx.checks(&check_ex10(&b, &runs));
        say!(cx);
        cx.paragraph(&format!(
            "Reconcile: the actuator never stops: it applies the last force it received at every \
             tick, the zero-order hold that kept the pole up between a slow policy's ticks. With the \
             policy dead that held force is a constant push: the balance it made decays and the pole \
             goes over in about two seconds. Liveliness knew within {} ms ({} ms of silence is a \
             lapsed lease), long before the fall: a node that watched it (a safety node, a \
             supervisor) had almost all of that time to act. Try it in the lab: ratelab --clock \
             virtual --kill {}@{} --lease {}={}.",
            b.lease_ms, b.lease_ms, b.node, b.kill_at_s, b.node, b.lease_ms
        ));
        Ok(())
    }
}
