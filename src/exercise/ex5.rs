//! ex5, the watchdog (QoS): the safety graph's `/cmd` across a lossy link, best effort
//! against a deadline with `hold` or `zero`, and reliable delivery. Virtual clock: each case
//! is exact.

use super::*;

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
/// graph: see [`default_graph`]).
///
/// # Errors
/// [`ExerciseError`] when a setting does not fit `graph` or a run cannot start.
pub fn measure_ex5(b: &Ex5Bands, graph: &GraphSpec) -> Result<Vec<Ex5Run>, ExerciseError> {
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
        let r = run_virtual(g.clone(), *seed, b.duration_s)?;
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
pub fn outcome_ex5(b: &Ex5Bands, runs: &[Ex5Run]) -> Outcome {
    let up = |c: Ex5Case| {
        let rs = ex5_of(runs, c);
        !rs.is_empty() && rs.iter().all(|r| r.metrics.balanced)
    };
    Outcome::Ex5 {
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
                crate::qos::MAX_ATTEMPTS
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
