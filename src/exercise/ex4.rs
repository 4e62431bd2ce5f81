//! ex4, the stale queue (QoS): a slow policy behind a deep `/obs` queue, latest-wins
//! against FIFO delivery, then FIFO with a lifespan. Virtual clock: each case is exact.

use super::*;

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
pub fn measure_ex4(b: &Ex4Bands, graph: &GraphSpec) -> Result<Vec<Ex4Run>, ExerciseError> {
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
        let r = run_virtual(g.clone(), *seed, b.duration_s)?;
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
pub fn outcome_ex4(b: &Ex4Bands, runs: &[Ex4Run]) -> Outcome {
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
    Outcome::Ex4 {
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
