//! ex4, the stale queue (QoS): a slow policy behind a deep `/obs` queue, latest-wins
//! against FIFO delivery, then FIFO with a lifespan. Virtual clock: each case is exact.

use super::{check, run_virtual, threads, verdict, Check, Context, Exercise, ExerciseError};
use super::{Reconcile, Said, Section};
use ratelab_core::metrics::Metrics;
use ratelab_core::qos::Delivery;
use ratelab_drivers::sweep::run_pool;
use ratelab_runtime::config::RunConfig;
use ratelab_runtime::graph::GraphSpec;
use ratelab_runtime::scheduler::StopFlag;
use serde::Deserialize;

/// ex4: the stale queue.
pub struct Ex4;

/// ex4's settings: the stale queue.
#[derive(Clone, Debug, Deserialize)]
pub struct Ex4Bands {
    /// Seeds.
    pub seeds: Vec<u64>,
    /// Sensor rate, Hz.
    pub sensor_hz: f64,
    /// The slow policy's rate, Hz.
    pub control_hz: f64,
    /// Run length, s.
    pub duration_s: f64,
    /// The sensor's topic, whose QoS the exercise sets.
    pub topic: String,
    /// Its history depth (keep last).
    pub depth: usize,
    /// Lifespans tried on the FIFO queue, ms, shortest first.
    pub lifespan_ms: Vec<f64>,
    /// A run that balances has at least this many actuator steps.
    pub min_steps: u64,
}

impl Section for Ex4Bands {
    const NAME: &'static str = "ex4";
}

/// ex4's outcome: which deliveries kept the pole up on every seed, and FIFO's latency at
/// the fall.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Ex4Outcome {
    /// Latest-wins balanced on every seed.
    pub latest_balances: bool,
    /// FIFO balanced on every seed.
    pub fifo_balances: bool,
    /// The smallest and largest sense→act latency at the fall over the seeds where FIFO
    /// fell, ms (`None`: it never fell).
    pub fifo_latency_at_fall_ms: Option<(f64, f64)>,
    /// FIFO with the shortest lifespan balanced on every seed.
    pub lifespan_balances: bool,
    /// That lifespan, ms.
    pub lifespan_ms: f64,
}

/// One ex4 run: a delivery (and lifespan) on the sensor's topic, one seed.
#[derive(Clone, Debug)]
pub struct Ex4Run {
    /// `latest` or `fifo`.
    pub delivery: Delivery,
    /// The lifespan, ms, if any.
    pub lifespan_ms: Option<f64>,
    /// Seed.
    pub seed: u64,
    /// The run's summary.
    pub metrics: Metrics,
    /// Sense→act latency at the step of the fall, ms (`None`: it did not fall).
    pub latency_at_fall_ms: Option<f64>,
}

impl Ex4Run {
    /// `latest`, `fifo`, `fifo, lifespan 20 ms`.
    pub fn label(&self) -> String {
        let d = match self.delivery {
            Delivery::Latest => "latest",
            Delivery::Fifo => "fifo",
        };
        match self.lifespan_ms {
            Some(l) => format!("{d}, lifespan {l} ms"),
            None => d.to_string(),
        }
    }

    /// Messages the lifespan expired on `topic` (the exercise's).
    pub fn expired(&self, topic: &str) -> u64 {
        self.metrics
            .topics
            .get(topic)
            .and_then(|t| t.qos_counters.get("expired"))
            .copied()
            .unwrap_or(0)
    }
}

/// ex4's configurations, in table order: latest, FIFO, then FIFO with each lifespan.
fn seed_of<'a>(rs: &[&'a Ex4Run], seed: u64) -> Option<&'a Ex4Run> {
    rs.iter().find(|r| r.seed == seed).copied()
}

fn ex4_configs(b: &Ex4Bands) -> Vec<(Delivery, Option<f64>)> {
    let mut c = vec![(Delivery::Latest, None), (Delivery::Fifo, None)];
    c.extend(b.lifespan_ms.iter().map(|&l| (Delivery::Fifo, Some(l))));
    c
}

/// ex4's measurements: every configuration ([`Ex4Run::label`]) on every seed, seed fastest.
///
/// # Errors
/// [`ExerciseError`] when a setting does not fit `graph` or a run cannot start.
pub fn measure_ex4(
    b: &Ex4Bands,
    graph: &GraphSpec,
    stop: &StopFlag,
) -> Result<Vec<Ex4Run>, ExerciseError> {
    let mut base = RunConfig {
        graph: graph.clone(),
        ..RunConfig::default()
    };
    base.set_sensor_hz(b.sensor_hz)?;
    base.set_control_hz(b.control_hz)?;
    let mut jobs = Vec::new();
    for (delivery, lifespan) in ex4_configs(b) {
        let mut g = base.graph.clone();
        let delivery_word = match delivery {
            Delivery::Latest => "latest",
            Delivery::Fifo => "fifo",
        };
        // Every key the rows differ in is set, so a row is what its label says whatever
        // the command line set on the topic.
        let lifespan_word = lifespan.map_or("none".to_string(), |l| l.to_string());
        let pairs = format!(
            "history=keep_last,depth={},delivery={delivery_word},lifespan_ms={lifespan_word}",
            b.depth
        );
        g.set_qos(&b.topic, &pairs)?;
        for &seed in &b.seeds {
            jobs.push((delivery, lifespan, seed, g.clone()));
        }
    }
    run_pool(&jobs, threads(), |(delivery, lifespan, seed, g)| {
        let r = run_virtual(g.clone(), *seed, b.duration_s, stop)?;
        let latency_at_fall_ms = r
            .metrics
            .fell_at_s
            .and(r.trace.last())
            .and_then(|s| s.latency)
            .map(|l| l.as_millis_f64());
        Ok(Ex4Run {
            delivery: *delivery,
            lifespan_ms: *lifespan,
            seed: *seed,
            metrics: r.metrics,
            latency_at_fall_ms,
        })
    })
    .into_iter()
    .collect()
}

/// ex4's outcome in the terms of its prediction.
pub fn outcome_ex4(b: &Ex4Bands, runs: &[Ex4Run]) -> Ex4Outcome {
    let all_up = |d: Delivery, l: Option<f64>| {
        runs.iter()
            .filter(|r| r.delivery == d && r.lifespan_ms == l)
            .all(|r| r.metrics.balanced)
    };
    let falls: Vec<f64> = runs
        .iter()
        .filter(|r| r.delivery == Delivery::Fifo && r.lifespan_ms.is_none())
        .filter_map(|r| r.latency_at_fall_ms)
        .collect();
    let shortest = b.lifespan_ms.first().copied();
    Ex4Outcome {
        latest_balances: all_up(Delivery::Latest, None),
        fifo_balances: all_up(Delivery::Fifo, None),
        fifo_latency_at_fall_ms: (!falls.is_empty()).then(|| {
            (
                falls.iter().copied().fold(f64::INFINITY, f64::min),
                falls.iter().copied().fold(f64::NEG_INFINITY, f64::max),
            )
        }),
        lifespan_balances: shortest.is_some() && all_up(Delivery::Fifo, shortest),
        lifespan_ms: shortest.unwrap_or(0.0),
    }
}

/// ex4's checks.
pub fn check_ex4(b: &Ex4Bands, runs: &[Ex4Run]) -> Vec<Check> {
    let of = |d: Delivery, l: Option<f64>| -> Vec<&Ex4Run> {
        runs.iter()
            .filter(|r| r.delivery == d && r.lifespan_ms == l)
            .collect()
    };
    let (latest, fifo) = (of(Delivery::Latest, None), of(Delivery::Fifo, None));
    let period_ms = 1e3 / b.control_hz;
    let mut checks =
        vec![
        check(
            format!("latest: balances on every seed with >= {} steps", b.min_steps),
            !latest.is_empty()
                && latest
                    .iter()
                    .all(|r| r.metrics.balanced && r.metrics.steps >= b.min_steps),
        ),
        check(
            "fifo: falls on every seed",
            !fifo.is_empty() && fifo.iter().all(|r| !r.metrics.balanced),
        ),
        check(
            format!(
                "depth {}: 0 {} drops with latest and with fifo, every seed",
                b.depth, b.topic
            ),
            latest
                .iter()
                .chain(&fifo)
                .all(|r| r.metrics.topics.get(&b.topic).is_some_and(|t| t.dropped == 0)),
        ),
        check(
            "fifo: the latency at the fall exceeds the largest latency latest ever had, per seed",
            fifo.iter().all(|f| {
                seed_of(&latest, f.seed).is_some_and(|l| {
                    f.latency_at_fall_ms
                        .is_some_and(|at| at > l.metrics.latency_max_ms)
                })
            }),
        ),
    ];
    for (i, &l) in b.lifespan_ms.iter().enumerate() {
        let rs = of(Delivery::Fifo, Some(l));
        checks.push(check(
            format!(
                "fifo + lifespan {l} ms: readings expire, and no action is older than the lifespan plus a policy period ({} ms)",
                l + period_ms
            ),
            !rs.is_empty()
                && rs
                    .iter()
                    .all(|r| r.expired(&b.topic) > 0 && r.metrics.latency_max_ms <= l + period_ms),
        ));
        if i == 0 {
            checks.push(check(
                format!(
                    "fifo + lifespan {l} ms: balances on every seed with >= {} steps",
                    b.min_steps
                ),
                rs.iter()
                    .all(|r| r.metrics.balanced && r.metrics.steps >= b.min_steps),
            ));
        } else {
            checks.push(check(
                format!("fifo + lifespan {l} ms: falls on every seed, later than fifo without one"),
                rs.iter().all(|r| {
                    !r.metrics.balanced
                        && seed_of(&fifo, r.seed).is_some_and(|f| r.metrics.steps > f.metrics.steps)
                }),
            ));
        }
    }
    checks
}

/// The survivals: right when they agree. The latency at the fall: right within
/// [`super::NEAR`] of the range over the seeds; not graded when FIFO never fell.
impl Reconcile for Ex4Outcome {
    fn reconcile(&self, prediction: &toml::Table) -> Vec<Said> {
        let survives = |key: &str, what: &str, measured: bool| {
            super::predicted_survival(prediction, key, what, measured)
        };
        let key = "fifo_latency_at_fall_ms";
        let latency = match (
            prediction.get(key).and_then(super::number),
            self.fifo_latency_at_fall_ms,
        ) {
            (None, _) => super::unreadable(key),
            (Some(n), None) => super::open(
                key,
                format!(
                    "You predicted {n} ms of sense->act latency at the FIFO fall; FIFO never fell."
                ),
            ),
            (Some(n), Some((lo, hi))) => super::graded(
                key,
                &format!(
                    "You predicted {n} ms of sense->act latency at the FIFO fall; it was {}",
                    if lo == hi {
                        format!("{lo:.0} ms")
                    } else {
                        format!("{lo:.0} to {hi:.0} ms over the seeds")
                    }
                ),
                (lo..=hi).contains(&n) || super::near(n, lo, 0.0) || super::near(n, hi, 0.0),
                &super::more_than_near(),
            ),
        };
        vec![
            survives("latest_balances", "with latest", self.latest_balances),
            survives("fifo_balances", "with fifo", self.fifo_balances),
            latency,
            survives(
                "lifespan_balances",
                &format!("with fifo and a {} ms lifespan", self.lifespan_ms),
                self.lifespan_balances,
            ),
        ]
    }
}

impl Exercise for Ex4 {
    fn id(&self) -> &'static str {
        "ex4"
    }

    fn title(&self) -> &'static str {
        "the stale queue"
    }

    fn file(&self) -> &'static str {
        "ex4_stale_queue.toml"
    }

    fn required_keys(&self) -> &'static [&'static str] {
        &[
            "latest_balances",
            "fifo_balances",
            "fifo_latency_at_fall_ms",
            "lifespan_balances",
        ]
    }

    fn run(&self, cx: &mut Context<'_>) -> Result<(), ExerciseError> {
        let b: Ex4Bands = cx.bands()?;
        let runs = cx.measure(|stop| measure_ex4(&b, cx.graph, stop))?;
        table(cx, &b, &runs);
        let outcome = outcome_ex4(&b, &runs);
        cx.reconcile(&outcome);
        cx.checks(&check_ex4(&b, &runs));
        say!(cx);
        cx.paragraph(&explain(&b, &runs, &outcome));
        Ok(())
    }
}

/// ex4's table: per configuration and seed, drops, expiries, the verdict and the latency.
fn table(cx: &mut Context<'_>, b: &Ex4Bands, runs: &[Ex4Run]) {
    let head = format!(
        "{} keep-last {}, policy {} Hz",
        b.topic, b.depth, b.control_hz
    );
    let w = head.len().max(22);
    say!(
        cx,
        "{head:<w$} | seed | {:>7} | expired | balanced | latency mean |   max | at the fall",
        "dropped"
    );
    let mut last = String::new();
    for r in runs {
        let label = r.label();
        let shown = if label == last {
            String::new()
        } else {
            label.clone()
        };
        last = label;
        let m = &r.metrics;
        say!(
            cx,
            "{shown:<w$} | {:>4} | {:>7} | {:>7} | {:>8} | {:>9.1} ms | {:>5.1} | {:>11}",
            r.seed,
            m.topics.get(&b.topic).map_or(0, |t| t.dropped),
            if r.lifespan_ms.is_some() {
                r.expired(&b.topic).to_string()
            } else {
                "-".into()
            },
            verdict(m),
            m.mean_latency_ms,
            m.latency_max_ms,
            r.latency_at_fall_ms
                .map_or("-".into(), |l| format!("{l:.1} ms")),
        );
    }
    say!(cx, "(latency: sense->act, ms; at the fall: the latency of the action applied at the step the pole fell;");
    say!(cx, " dropped: readings evicted unread; expired: readings the lifespan discarded unread; n@T: fell at T s)");
}

/// The explanation, with its numbers from the bands and the runs, and each claim about a
/// verdict said only when the runs bear it out.
fn explain(b: &Ex4Bands, runs: &[Ex4Run], outcome: &Ex4Outcome) -> String {
    let per_tick = b.sensor_hz / b.control_hz;
    let aging_ms = (per_tick - 1.0) * 1e3 / b.sensor_hz;
    let of = |label: &str| -> Vec<&Ex4Run> { runs.iter().filter(|r| r.label() == label).collect() };
    let latest_max = of("latest")
        .iter()
        .map(|r| r.metrics.latency_max_ms)
        .fold(0.0, f64::max);
    let mut text = format!(
        "Reconcile: under latest the policy reads the newest reading and reads past the rest; the deep \
         queue holds them, nothing is dropped, and no action is older than {latest_max:.0} ms. Under fifo \
         the policy takes the OLDEST unread reading, one per tick, while {per_tick} arrive: the backlog \
         grows by {} a tick, and each reading acted on is {aging_ms:.0} ms older than the one before. \
         Nothing is dropped, so the drop counter says all is well",
        per_tick - 1.0
    );
    let fifo_falls: Vec<f64> = of("fifo")
        .iter()
        .filter_map(|r| r.metrics.fell_at_s)
        .collect();
    match outcome.fifo_latency_at_fall_ms {
        Some((lo, hi)) if fifo_falls.len() == of("fifo").len() => {
            let t = fifo_falls.iter().copied().fold(0.0, f64::max);
            text += &format!(
                ", while the pole is down by {t:.2} s on every seed, acting on readings {lo:.0} to {hi:.0} ms old."
            );
        }
        _ => text += ", while the decisions age.",
    }
    if let Some((&first, longer)) = b.lifespan_ms.split_first() {
        text += &format!(
            " A lifespan discards a reading older than it before a read can return it: at {first} ms \
             fifo acts at worst on a reading {first} ms old when read"
        );
        text += if of(&format!("fifo, lifespan {first} ms"))
            .iter()
            .all(|r| r.metrics.balanced)
        {
            ", and the pole stays up."
        } else {
            "."
        };
        text += " The readings latest reads past are discarded again, and counted as expired: the drops \
                 are back, under another name.";
        for &l in longer {
            let rs = of(&format!("fifo, lifespan {l} ms"));
            if rs.iter().all(|r| !r.metrics.balanced) {
                text += &format!(
                    " At {l} ms the bound is too loose: the pole falls later ({}), but it falls.",
                    rs.iter()
                        .filter_map(|r| r.metrics.fell_at_s)
                        .map(|t| format!("{t:.2} s"))
                        .collect::<Vec<_>>()
                        .join(", ")
                );
            }
        }
    }
    text += " A slow subscriber of a fast sensor wants the newest reading, not a queue of old ones: \
             ROS 2's sensor-data QoS profile keeps only the last few, best effort, for this reason.";
    text
}
