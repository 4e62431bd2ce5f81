//! ex14, incompatible QoS: four pairs of what a subscription requests and what its
//! publisher offers on the chapter's `/action`, only some of which ROS 2 connects; then a
//! node that joins late, under each durability: what it gets of the past. Virtual clock:
//! exact.

use super::{check, Check, Context, Exercise, ExerciseError, Reconcile, Said, Section};
use ratelab_core::metrics::Metrics;
use ratelab_runtime::config::{duration_from_secs, ClockKind, RunConfig};
use ratelab_runtime::graph::GraphSpec;
use ratelab_runtime::scheduler::StopFlag;
use serde::Deserialize;
use std::path::Path;

/// ex14: incompatible QoS.
pub struct Ex14;

/// One requested/offered pair of ex14 (`bands.toml`'s `[[ex14.pairs]]`).
#[derive(Clone, Debug, Deserialize)]
pub struct Ex14Pair {
    /// Its prediction key: does the pair deliver? (`reliable_from_best_effort`).
    pub key: String,
    /// What the publisher offers on the topic, as `--qos` gives it (`reliability=best_effort`).
    pub offered: String,
    /// What the subscription requests, as `KEY=VALUE` pairs of a `[topic.requested.NODE]`
    /// table (`reliability=reliable`).
    pub requested: String,
    /// Whether ROS 2's compatibility table connects it (the check).
    pub delivers: bool,
}

/// ex14's runs and bands (`bands.toml`'s `[ex14]`).
#[derive(Clone, Debug, Deserialize)]
pub struct Ex14Bands {
    /// The seed of every run.
    pub seed: u64,
    /// Run length, s.
    pub duration_s: f64,
    /// The topic of the pairs (the chapter's `/action`)...
    pub topic: String,
    /// ...and the subscription that requests (its actuator's).
    pub subscriber: String,
    /// The pairs, in the order the exercise gives them.
    pub pairs: Vec<Ex14Pair>,
    /// The late joiner's graph, relative to `bands.toml` (the monitor graph)...
    pub late_graph: String,
    /// ...the node that joins late...
    pub late_node: String,
    /// ...the topic it reads...
    pub late_topic: String,
    /// ...when it joins, ms of run time...
    pub late_start_ms: f64,
    /// ...and the topic's history depth (what a transient-local topic keeps for it).
    pub late_depth: usize,
}

impl Section for Ex14Bands {
    const NAME: &'static str = "ex14";
}

/// The durabilities the late joiner meets, in order.
pub const EX14_DURABILITIES: [&str; 2] = ["volatile", "transient_local"];

/// What ex14 measured.
#[derive(Clone, Debug)]
pub struct Ex14Runs {
    /// Per pair, in the bands' order: the run.
    pub pairs: Vec<Metrics>,
    /// Per durability ([`EX14_DURABILITIES`]): the late joiner's run.
    pub late: Vec<Metrics>,
}

/// ex14's outcome.
#[derive(Clone, Debug, PartialEq)]
pub struct Ex14Outcome {
    /// Per pair (its key): did it deliver, and what the incompatible-QoS event said if not.
    pub delivers: Vec<(String, bool, Option<String>)>,
    /// Per durability: the messages from before its join the late joiner received.
    pub history: Vec<(String, u64)>,
}

/// ex14's measurements: one run of `graph` per pair (the pair's offer set on the topic, its
/// request on the subscription), then the late joiner's graph (read from `dir`) once per
/// durability.
///
/// # Errors
/// [`ExerciseError`] for a pair the graph refuses or a run that cannot start.
pub fn measure_ex14(
    b: &Ex14Bands,
    graph: &GraphSpec,
    dir: &Path,
    stop: &StopFlag,
) -> Result<Ex14Runs, ExerciseError> {
    let cfg = |graph: GraphSpec| -> Result<RunConfig, ExerciseError> {
        Ok(RunConfig {
            clock: ClockKind::Virtual,
            seed: b.seed,
            duration: duration_from_secs(b.duration_s)?,
            graph,
            ..RunConfig::default()
        })
    };
    let pairs = b
        .pairs
        .iter()
        .map(|p| {
            let mut g = graph.clone();
            g.set_qos(&b.topic, &p.offered)?;
            g.set_requested(&b.topic, &b.subscriber, &p.requested)?;
            super::run_scripted(&cfg(g)?, stop)
        })
        .collect::<Result<Vec<_>, ExerciseError>>()?;
    let file = dir.join(&b.late_graph);
    let late_graph = GraphSpec::load(&file).map_err(|e| ExerciseError::Parse {
        path: file.display().to_string(),
        detail: e.to_string(),
    })?;
    let late = EX14_DURABILITIES
        .iter()
        .map(|d| {
            let mut g = late_graph.clone();
            g.set_start(&b.late_node, b.late_start_ms)?;
            g.set_qos(
                &b.late_topic,
                &format!("depth={},durability={d}", b.late_depth),
            )?;
            super::run_scripted(&cfg(g)?, stop)
        })
        .collect::<Result<Vec<_>, ExerciseError>>()?;
    Ok(Ex14Runs { pairs, late })
}

/// ex14's outcome from its runs.
pub fn outcome_ex14(b: &Ex14Bands, runs: &Ex14Runs) -> Ex14Outcome {
    Ex14Outcome {
        delivers: b
            .pairs
            .iter()
            .zip(&runs.pairs)
            .map(|(p, m)| {
                let event = m
                    .topics
                    .get(&b.topic)
                    .and_then(|t| t.incompatible_qos.get(&b.subscriber))
                    .map(|i| i.event.clone());
                (p.key.clone(), event.is_none(), event)
            })
            .collect(),
        history: EX14_DURABILITIES
            .iter()
            .zip(&runs.late)
            .map(|(d, m)| {
                let got = m
                    .topics
                    .get(&b.late_topic)
                    .and_then(|t| t.late_joiners.get(&b.late_node))
                    .map_or(0, |j| j.history);
                ((*d).to_string(), got)
            })
            .collect(),
    }
}

/// ex14's checks on its runs.
pub fn check_ex14(b: &Ex14Bands, runs: &Ex14Runs) -> Vec<Check> {
    let outcome = outcome_ex14(b, runs);
    let mut checks: Vec<Check> = b
        .pairs
        .iter()
        .zip(&outcome.delivers)
        .zip(&runs.pairs)
        .map(|((p, (_, delivers, _)), m)| {
            check(
                format!(
                    "offered {}, requested {}: {} (and the pole {})",
                    p.offered,
                    p.requested,
                    if p.delivers {
                        "connected"
                    } else {
                        "never connected"
                    },
                    if p.delivers { "balances" } else { "falls" }
                ),
                *delivers == p.delivers && m.balanced == p.delivers,
            )
        })
        .collect();
    let history = |d: &str| {
        outcome
            .history
            .iter()
            .find(|(x, _)| x == d)
            .map(|(_, n)| *n)
    };
    checks.push(check(
        format!(
            "a late joiner gets nothing from before under volatile, the last {} under transient_local",
            b.late_depth
        ),
        history("volatile") == Some(0)
            && history("transient_local") == Some(b.late_depth as u64),
    ));
    checks.push(check(
        "the late joiner's arrival changes nothing for the policy (balanced both times)",
        runs.late.iter().all(|m| m.balanced),
    ));
    checks
}

/// Each pair: right when it agrees. The messages a late joiner gets: an exact count (none,
/// or the history depth), right when the same.
impl Reconcile for Ex14Outcome {
    fn reconcile(&self, prediction: &toml::Table) -> Vec<Said> {
        let mut lines: Vec<Said> = self
            .delivers
            .iter()
            .map(|(key, delivers, event)| {
                let measured = match event {
                    None => "it does".to_string(),
                    Some(e) => format!("it does not ({e})"),
                };
                match prediction.get(key).and_then(toml::Value::as_bool) {
                    Some(p) => {
                        let what = if p { "delivers" } else { "delivers nothing" };
                        super::graded(
                            key,
                            &format!("You predicted {key} {what}; {measured}"),
                            p == *delivers,
                            "",
                        )
                    }
                    None => super::unreadable(key),
                }
            })
            .collect();
        for (durability, got) in &self.history {
            let key = format!("late_joiner_{durability}");
            lines.push(match prediction.get(&key).and_then(super::number) {
                Some(n) => super::graded(
                    &key,
                    &format!(
                        "You predicted a late joiner gets {n} messages from before under {durability}; it got {got}"
                    ),
                    super::same(n, *got as f64),
                    "",
                ),
                None => super::unreadable(&key),
            });
        }
        lines
    }
}

impl Exercise for Ex14 {
    fn id(&self) -> &'static str {
        "ex14"
    }

    fn title(&self) -> &'static str {
        "incompatible QoS"
    }

    fn file(&self) -> &'static str {
        "ex14_incompatible_qos.toml"
    }

    fn required_keys(&self) -> &'static [&'static str] {
        &[
            "reliable_from_best_effort",
            "best_effort_from_reliable",
            "deadline_20_from_40",
            "deadline_40_from_20",
            "late_joiner_volatile",
            "late_joiner_transient_local",
        ]
    }

    fn run(&self, cx: &mut Context<'_>) -> Result<(), ExerciseError> {
        let b: Ex14Bands = cx.bands()?;
        let runs = cx.measure(|stop| measure_ex14(&b, cx.graph, cx.dir, stop))?;
        let outcome = outcome_ex14(&b, &runs);
        say!(
            cx,
            "{:<26} | {:<24} | {:<23} | {:<9} | pole",
            "pair",
            "offered",
            "requested",
            "connected"
        );
        for ((p, m), (_, delivers, _)) in b.pairs.iter().zip(&runs.pairs).zip(&outcome.delivers) {
            say!(
                cx,
                "{:<26} | {:<24} | {:<23} | {:<9} | {}",
                p.key,
                p.offered,
                p.requested,
                if *delivers { "yes" } else { "no" },
                super::verdict(m)
            );
        }
        say!(cx);
        say!(
            cx,
            "{} joins at {} s, {} of depth {}:",
            b.late_node,
            b.late_start_ms / 1e3,
            b.late_topic,
            b.late_depth
        );
        for (durability, got) in &outcome.history {
            say!(
                cx,
                "  {durability:<16} {} from before its join",
                ratelab_core::metrics::counted(*got, "message")
            );
        }
        cx.reconcile(&outcome);
        cx.checks(&check_ex14(&b, &runs));
        say!(cx);
        cx.paragraph(&format!(
            "Reconcile: a subscription's request is a floor, and the offer must reach it: \
             reliable needs reliable, a deadline of 20 ms needs a publisher that promises 20 ms \
             or less. A stronger offer than the request is fine (reliable serves best effort). \
             An incompatible pair is not a slow or lossy connection: it is no connection at all, \
             and the only signs are the incompatible-QoS event and a subscriber that never hears \
             anything (here the actuator, so the pole falls while the policy publishes at 50 Hz). \
             Durability is about time instead: a node that joins late gets nothing of the past \
             from a volatile topic, and the last {} messages (the history depth) from a \
             transient-local one. See it in the lab: ratelab --clock virtual --graph \
             graphs/cartpole-incompatible-qos.toml, then select {} and press e.",
            b.late_depth, b.topic
        ));
        Ok(())
    }
}
