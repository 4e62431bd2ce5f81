//! ex5, the watchdog (QoS): the safety graph's `/cmd` across a lossy link, best effort
//! against a deadline with `hold` or `zero`, and reliable delivery. Virtual clock: each case
//! is exact.

use super::{check, run_virtual, seeds_header, threads, verdict, Check, Context, Exercise};
use super::{ExerciseError, Reconcile, Said, Section, Verdict};
use ratelab_core::metrics::Metrics;
use ratelab_drivers::sweep::run_pool;
use ratelab_runtime::graph::GraphSpec;
use ratelab_runtime::scheduler::StopFlag;
use serde::Deserialize;

/// ex5: the watchdog.
pub struct Ex5;

/// ex5's settings: the watchdog.
#[derive(Clone, Debug, Deserialize)]
pub struct Ex5Bands {
    /// The graph, relative to the bands file's folder.
    pub graph: String,
    /// The actuator's input, which crosses the link.
    pub topic: String,
    /// Seeds.
    pub seeds: Vec<u64>,
    /// Run length, s.
    pub duration_s: f64,
    /// The link's loss the zero-order hold rides out.
    pub low_loss: f64,
    /// The link's loss the exercise's reactions are compared at.
    pub high_loss: f64,
    /// The deadline on the actuator's input, ms.
    pub deadline_ms: f64,
}

impl Section for Ex5Bands {
    const NAME: &'static str = "ex5";
}

/// The names a learner gives the reactions at the high loss, in
/// [`Ex5Outcome::keeps_it_up`]'s order.
pub const EX5_REACTIONS: [&str; 3] = ["hold", "zero", "reliable"];

/// ex5's outcome: what kept the pole up on every seed, and reliable delivery's latency.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Ex5Outcome {
    /// Best effort at the low loss balanced on every seed.
    pub low_loss_balances: bool,
    /// Best effort at the high loss (the zero-order hold) balanced on every seed.
    pub high_loss_balances: bool,
    /// At the high loss, with the deadline: `hold`, `zero`, and reliable delivery,
    /// each true when it balanced on every seed.
    pub keeps_it_up: [bool; 3],
    /// Reliable delivery's mean sense→act latency (mean over the seeds), ms.
    pub reliable_latency_ms: f64,
    /// The lossless link's, ms.
    pub lossless_latency_ms: f64,
    /// The low and the high loss, for the words.
    pub losses: (f64, f64),
}

/// ex5's cases, in table order.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Ex5Case {
    /// The graph as it is: no link.
    Lossless,
    /// Best effort at the low loss (the actuator holds the last command).
    LowLoss,
    /// Best effort at the high loss.
    HighLoss,
    /// The high loss, with the deadline and `on_deadline_missed = "hold"`.
    DeadlineHold,
    /// The high loss, with the deadline and `on_deadline_missed = "zero"`.
    DeadlineZero,
    /// The high loss, reliable delivery.
    Reliable,
}

impl Ex5Case {
    /// Every case, in table order.
    pub const ALL: [Ex5Case; 6] = [
        Ex5Case::Lossless,
        Ex5Case::LowLoss,
        Ex5Case::HighLoss,
        Ex5Case::DeadlineHold,
        Ex5Case::DeadlineZero,
        Ex5Case::Reliable,
    ];

    /// The `--qos` pairs on the topic (`None`: the graph as it is). Every key the cases
    /// differ in is set, so a case is what its label says whatever the command line set on
    /// the topic (a link delay or jitter given there stays: a way to explore).
    pub fn pairs(self, b: &Ex5Bands) -> Option<String> {
        let (low, high, d) = (b.low_loss, b.high_loss, b.deadline_ms);
        let no_deadline = "deadline_ms=none,on_deadline_missed=hold";
        Some(match self {
            Ex5Case::Lossless => return None,
            Ex5Case::LowLoss => format!("loss={low},reliability=best_effort,{no_deadline}"),
            Ex5Case::HighLoss => format!("loss={high},reliability=best_effort,{no_deadline}"),
            Ex5Case::DeadlineHold => format!(
                "loss={high},reliability=best_effort,deadline_ms={d},on_deadline_missed=hold"
            ),
            Ex5Case::DeadlineZero => format!(
                "loss={high},reliability=best_effort,deadline_ms={d},on_deadline_missed=zero"
            ),
            Ex5Case::Reliable => format!("loss={high},reliability=reliable,{no_deadline}"),
        })
    }

    /// A row label: `20% loss, best effort`, `80%, deadline 30 ms + zero`.
    pub fn label(self, b: &Ex5Bands) -> String {
        let pct = |p: f64| format!("{}%", p * 100.0);
        let (low, high, d) = (pct(b.low_loss), pct(b.high_loss), b.deadline_ms);
        match self {
            Ex5Case::Lossless => "no link (lossless)".into(),
            Ex5Case::LowLoss => format!("{low} loss, best effort"),
            Ex5Case::HighLoss => format!("{high} loss, best effort"),
            Ex5Case::DeadlineHold => format!("{high}, deadline {d} ms + hold"),
            Ex5Case::DeadlineZero => format!("{high}, deadline {d} ms + zero"),
            Ex5Case::Reliable => format!("{high}, reliable"),
        }
    }
}

/// One ex5 run.
#[derive(Clone, Debug)]
pub struct Ex5Run {
    /// The case.
    pub case: Ex5Case,
    /// Seed.
    pub seed: u64,
    /// The run's summary.
    pub metrics: Metrics,
    /// Actuator steps that applied no command (before the first arrived, or zeroed by the
    /// watchdog): they have no sense→act latency, so the latency figures leave them out.
    pub steps_without_command: u64,
}

impl Ex5Run {
    /// A QoS counter of the exercise's topic (0 when not reported).
    pub fn counter(&self, b: &Ex5Bands, key: &str) -> u64 {
        self.metrics
            .topics
            .get(&b.topic)
            .and_then(|t| t.qos_counters.get(key))
            .copied()
            .unwrap_or(0)
    }
}

/// ex5's measurements: every case on every seed, seed fastest, on `graph` (the safety
/// graph: see [`super::default_graph`]).
///
/// # Errors
/// [`ExerciseError`] when a setting does not fit `graph` or a run cannot start.
pub fn measure_ex5(
    b: &Ex5Bands,
    graph: &GraphSpec,
    stop: &StopFlag,
) -> Result<Vec<Ex5Run>, ExerciseError> {
    let mut jobs = Vec::new();
    for case in Ex5Case::ALL {
        let mut g = graph.clone();
        if let Some(pairs) = case.pairs(b) {
            g.set_qos(&b.topic, &pairs)?;
        }
        for &seed in &b.seeds {
            jobs.push((case, seed, g.clone()));
        }
    }
    run_pool(&jobs, threads(), |(case, seed, g)| {
        let r = run_virtual(g.clone(), *seed, b.duration_s, stop)?;
        let steps_without_command = r.trace.iter().filter(|s| s.latency.is_none()).count() as u64;
        Ok(Ex5Run {
            case: *case,
            seed: *seed,
            metrics: r.metrics,
            steps_without_command,
        })
    })
    .into_iter()
    .collect()
}

fn ex5_of(runs: &[Ex5Run], case: Ex5Case) -> Vec<&Ex5Run> {
    runs.iter().filter(|r| r.case == case).collect()
}

fn mean_latency(runs: &[&Ex5Run]) -> f64 {
    runs.iter().map(|r| r.metrics.mean_latency_ms).sum::<f64>() / runs.len().max(1) as f64
}

/// ex5's outcome in the terms of its prediction.
pub fn outcome_ex5(b: &Ex5Bands, runs: &[Ex5Run]) -> Ex5Outcome {
    let up = |c: Ex5Case| {
        let rs = ex5_of(runs, c);
        !rs.is_empty() && rs.iter().all(|r| r.metrics.balanced)
    };
    Ex5Outcome {
        low_loss_balances: up(Ex5Case::LowLoss),
        high_loss_balances: up(Ex5Case::HighLoss),
        keeps_it_up: [
            up(Ex5Case::DeadlineHold),
            up(Ex5Case::DeadlineZero),
            up(Ex5Case::Reliable),
        ],
        reliable_latency_ms: mean_latency(&ex5_of(runs, Ex5Case::Reliable)),
        lossless_latency_ms: mean_latency(&ex5_of(runs, Ex5Case::Lossless)),
        losses: (b.low_loss, b.high_loss),
    }
}

/// ex5's checks.
pub fn check_ex5(b: &Ex5Bands, runs: &[Ex5Run]) -> Vec<Check> {
    let all = |c: Ex5Case, f: &dyn Fn(&Ex5Run) -> bool| {
        let rs = ex5_of(runs, c);
        !rs.is_empty() && rs.iter().all(|r| f(r))
    };
    let label = |c: Ex5Case| c.label(b);
    let best_effort = ex5_of(runs, Ex5Case::HighLoss);
    vec![
        check(
            format!("{}: balances on every seed", label(Ex5Case::Lossless)),
            all(Ex5Case::Lossless, &|r| r.metrics.balanced),
        ),
        check(
            format!("{}: balances on every seed, with commands lost", label(Ex5Case::LowLoss)),
            all(Ex5Case::LowLoss, &|r| r.metrics.balanced && r.counter(b, "lost") > 0),
        ),
        check(
            format!("{}: falls on every seed", label(Ex5Case::HighLoss)),
            all(Ex5Case::HighLoss, &|r| !r.metrics.balanced && r.metrics.fell_at_s.is_some()),
        ),
        check(
            format!(
                "{}: counts deadline misses, and falls at the same step as without a deadline, per seed",
                label(Ex5Case::DeadlineHold)
            ),
            all(Ex5Case::DeadlineHold, &|r| {
                r.counter(b, "requested_deadline_missed") > 0
                    && best_effort.iter().any(|e| {
                        e.seed == r.seed
                            && !e.metrics.balanced
                            && e.metrics.steps == r.metrics.steps
                            && e.metrics.fell_at_s == r.metrics.fell_at_s
                    })
            }),
        ),
        check(
            format!("{}: balances on every seed", label(Ex5Case::DeadlineZero)),
            all(Ex5Case::DeadlineZero, &|r| r.metrics.balanced),
        ),
        check(
            format!(
                "{}: applies no command older than the deadline (latency max <= {} ms), and zeroes some steps",
                label(Ex5Case::DeadlineZero),
                b.deadline_ms
            ),
            all(Ex5Case::DeadlineZero, &|r| {
                r.metrics.latency_max_ms <= b.deadline_ms && r.steps_without_command > 0
            }),
        ),
        check(
            format!(
                "{}: balances on every seed, with commands retransmitted",
                label(Ex5Case::Reliable)
            ),
            all(Ex5Case::Reliable, &|r| {
                r.metrics.balanced && r.counter(b, "retransmitted") > 0
            }),
        ),
        check(
            format!(
                "{}: loses under a tenth of the share of commands best effort loses (it gives up only after {} sends)",
                label(Ex5Case::Reliable),
                ratelab_core::qos::MAX_ATTEMPTS
            ),
            {
                let share = |c: Ex5Case| {
                    let rs = ex5_of(runs, c);
                    let lost: u64 = rs.iter().map(|r| r.counter(b, "lost")).sum();
                    let sent: u64 = rs
                        .iter()
                        .filter_map(|r| r.metrics.topics.get(&b.topic))
                        .map(|t| t.published)
                        .sum();
                    lost as f64 / sent.max(1) as f64
                };
                share(Ex5Case::Reliable) < share(Ex5Case::HighLoss) / 10.0
            },
        ),
        check(
            format!(
                "{}: mean latency above the lossless link's (the price of retransmitting)",
                label(Ex5Case::Reliable)
            ),
            mean_latency(&ex5_of(runs, Ex5Case::Reliable))
                > mean_latency(&ex5_of(runs, Ex5Case::Lossless)),
        ),
    ]
}

/// The survivals: right when they agree. What keeps the pole up: right when the set is
/// the same. Reliable delivery's latency: right within [`super::NEAR`].
impl Reconcile for Ex5Outcome {
    fn reconcile(&self, prediction: &toml::Table) -> Vec<Said> {
        let p = |k: &str| prediction.get(k);
        let (low, high) = self.losses;
        let pct = |p: f64| format!("{}%", p * 100.0);
        let named = |set: &[bool; 3]| -> String {
            let v: Vec<&str> = EX5_REACTIONS
                .iter()
                .zip(set)
                .filter_map(|(n, &up)| up.then_some(*n))
                .collect();
            if v.is_empty() {
                "none".into()
            } else {
                v.join(", ")
            }
        };
        let key = "keeps_it_up";
        let kept = match p(key).and_then(toml::Value::as_array) {
            Some(list) => {
                let names: Option<Vec<&str>> = list.iter().map(toml::Value::as_str).collect();
                match names {
                    Some(names) if names.iter().all(|n| EX5_REACTIONS.contains(n)) => {
                        let mut said = [false; 3];
                        for (i, r) in EX5_REACTIONS.iter().enumerate() {
                            said[i] = names.contains(r);
                        }
                        super::graded(
                            key,
                            &format!(
                                "You predicted these keep the pole up at {} loss: {}; what did: {}",
                                pct(high),
                                named(&said),
                                named(&self.keeps_it_up),
                            ),
                            said == self.keeps_it_up,
                            "",
                        )
                    }
                    _ => Said {
                        key: key.to_string(),
                        line: format!(
                            "Your prediction `keeps_it_up` lists names other than {}.",
                            EX5_REACTIONS.join(", ")
                        ),
                        verdict: Verdict::Unreadable,
                    },
                }
            }
            None => super::unreadable(key),
        };
        let key = "reliable_latency_ms";
        let latency = match p(key).and_then(super::number) {
            Some(n) => super::graded(
                key,
                &format!(
                    "You predicted {n} ms of mean sense->act latency with reliable delivery; it was {:.1} ms (the lossless link: {:.1} ms)",
                    self.reliable_latency_ms, self.lossless_latency_ms
                ),
                super::near(n, self.reliable_latency_ms, 0.0),
                &super::more_than_near(),
            ),
            None => super::unreadable(key),
        };
        vec![
            super::predicted_survival(
                prediction,
                "survives_low_loss",
                &format!("at {} loss, best effort", pct(low)),
                self.low_loss_balances,
            ),
            super::predicted_survival(
                prediction,
                "survives_high_loss",
                &format!("at {} loss, best effort", pct(high)),
                self.high_loss_balances,
            ),
            kept,
            latency,
        ]
    }
}

impl Exercise for Ex5 {
    fn id(&self) -> &'static str {
        "ex5"
    }

    fn title(&self) -> &'static str {
        "the watchdog"
    }

    fn file(&self) -> &'static str {
        "ex5_watchdog.toml"
    }

    fn required_keys(&self) -> &'static [&'static str] {
        &[
            "survives_low_loss",
            "survives_high_loss",
            "keeps_it_up",
            "reliable_latency_ms",
        ]
    }

    fn default_graph(&self, bands: &super::Bands) -> Result<Option<String>, ExerciseError> {
        Ok(Some(bands.of::<Ex5Bands>()?.graph))
    }

    fn run(&self, cx: &mut Context<'_>) -> Result<(), ExerciseError> {
        let b: Ex5Bands = cx.bands()?;
        let runs = cx.measure(|stop| measure_ex5(&b, cx.graph, stop))?;
        table(cx, &b, &runs);
        let outcome = outcome_ex5(&b, &runs);
        cx.reconcile(&outcome);
        cx.checks(&check_ex5(&b, &runs));
        say!(cx);
        cx.paragraph(&explain(&b, &runs, &outcome));
        say!(
            cx,
            "  ratelab run --clock virtual --graph graphs/cartpole-safety.toml --link {}:loss={},delay_ms=30,jitter_ms=10",
            b.topic,
            b.low_loss
        );
        say!(
            cx,
            "and the same with --qos {}:reliability=reliable.",
            b.topic
        );
        Ok(())
    }
}

/// ex5's table: per case, each seed's verdict, the latency and the link's counters.
fn table(cx: &mut Context<'_>, b: &Ex5Bands, runs: &[Ex5Run]) {
    let w = Ex5Case::ALL
        .iter()
        .map(|c| c.label(b).len())
        .max()
        .unwrap_or(0)
        .max(b.topic.len() + 20);
    say!(
        cx,
        "{:<w$} | {} | latency mean |   max | lost |  retx | dl missed | no cmd",
        format!("{} (safety -> actuator)", b.topic),
        seeds_header(&b.seeds)
    );
    for case in Ex5Case::ALL {
        let rs: Vec<&Ex5Run> = runs.iter().filter(|r| r.case == case).collect();
        let cells: Vec<String> = rs
            .iter()
            .map(|r| format!("{:^7}", verdict(&r.metrics)))
            .collect();
        let max = rs
            .iter()
            .map(|r| r.metrics.latency_max_ms)
            .fold(0.0, f64::max);
        let sum = |key: &str| rs.iter().map(|r| r.counter(b, key)).sum::<u64>();
        say!(
            cx,
            "{:<w$} | {} | {:>9.1} ms | {:>5.1} | {:>4} | {:>5} | {:>9} | {:>6}",
            case.label(b),
            cells.join(" "),
            mean_latency(&rs),
            max,
            sum("lost"),
            sum("retransmitted"),
            if matches!(case, Ex5Case::DeadlineHold | Ex5Case::DeadlineZero) {
                sum("requested_deadline_missed").to_string()
            } else {
                "-".into()
            },
            rs.iter().map(|r| r.steps_without_command).sum::<u64>(),
        );
    }
    say!(cx, "(latency: sense->act, ms, the mean of the seeds' means and the largest; lost, retx (retransmitted),");
    say!(cx, " dl missed (deadline periods with no command arriving; -: no deadline) and no cmd (actuator steps");
    say!(cx, " that applied no command: no latency) are summed over the seeds; Y: balanced; n@T: fell at T s)");
}

/// The explanation, with its numbers from the bands and the runs, and each claim about a
/// verdict said only when the runs bear it out.
fn explain(b: &Ex5Bands, runs: &[Ex5Run], outcome: &Ex5Outcome) -> String {
    let max_of = |c: Ex5Case| {
        ex5_of(runs, c)
            .iter()
            .map(|r| r.metrics.latency_max_ms)
            .fold(0.0, f64::max)
    };
    let up = |c: Ex5Case| ex5_of(runs, c).iter().all(|r| r.metrics.balanced);
    let pct = |p: f64| format!("{}%", p * 100.0);
    let (low, high) = (pct(b.low_loss), pct(b.high_loss));
    let mut text = format!(
        "Reconcile: a lost command is a held command. At {low} loss the actuator re-applies the \
         previous command for a tick or a few (the oldest command applied was {:.0} ms old)",
        max_of(Ex5Case::LowLoss)
    );
    text += if up(Ex5Case::LowLoss) {
        ", within what ex1's rate cliff allows, and the pole stays up: the zero-order hold already \
         is a loss strategy."
    } else {
        "."
    };
    text += &format!(
        " At {high} the holds run to {:.0} ms{}",
        max_of(Ex5Case::HighLoss),
        if up(Ex5Case::HighLoss) {
            "."
        } else {
            " and the pole falls."
        }
    );
    text += &format!(
        " A deadline alone changes only the counters: hold is the default reaction. With zero the \
         actuator stops pushing once its command is older than the deadline ({} ms: a command lost \
         once is held, the next tick still without one applies no force).",
        b.deadline_ms
    );
    if up(Ex5Case::DeadlineZero) && !up(Ex5Case::HighLoss) {
        text += " Here a stale push is worse than none, and the pole stays up.";
    }
    text +=
        " Motor drivers do the same with a command timeout (ROS 2's diff_drive_controller stops \
             the wheels after cmd_vel_timeout).";
    let timeout = ratelab_core::qos::Link::default_retransmit(
        ratelab_core::Nanos::ZERO,
        ratelab_core::Nanos::ZERO,
    );
    let attempts = ratelab_core::qos::MAX_ATTEMPTS;
    text += &format!(
        " Reliable delivery sends a lost command again, up to {attempts} times (at {high} loss all \
         {attempts} sends fail for {:.1}% of commands), and a retransmission comes a timeout later \
         ({timeout} here: the link has no delay), too late for its tick, which applies an older \
         command.",
        b.high_loss.powi(i32::try_from(attempts).unwrap_or(i32::MAX)) * 100.0
    );
    text += &format!(
        " That is its latency cost: {:.1} ms on average, against {:.1} ms without the link.",
        outcome.reliable_latency_ms, outcome.lossless_latency_ms
    );
    text += " On a slow link the timeout is a round trip, and a reliable link keeps order, so one \
             loss delays every command behind it. Try it:";
    text
}
