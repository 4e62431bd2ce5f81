//! ex2, the queue-depth trap: at a too-slow policy rate, `/obs` with history depth 1
//! against a deep queue, every seed. Virtual clock: each run is exact.

use super::{check, dash, scripted, threads, Check, Context, Exercise, ExerciseError};
use super::{Reconcile, Said, Section};
use ratelab_core::metrics::Metrics;
use ratelab_drivers::sweep::{run_grid_until, Grid};
use ratelab_runtime::config::{duration_from_secs, ClockKind, RunConfig};
use ratelab_runtime::graph::GraphSpec;
use ratelab_runtime::scheduler::StopFlag;
use serde::Deserialize;

/// ex2: the queue-depth trap.
pub struct Ex2;

/// ex2's settings.
#[derive(Clone, Debug, Deserialize)]
pub struct Ex2Bands {
    /// Seeds.
    pub seeds: Vec<u64>,
    /// Sensor rate, Hz.
    pub sensor_hz: f64,
    /// The too-slow policy rate, Hz.
    pub control_hz: f64,
    /// Run length, s.
    pub duration_s: f64,
    /// The shallow queue.
    pub shallow_depth: usize,
    /// The deep queue.
    pub deep_depth: usize,
}

impl Section for Ex2Bands {
    const NAME: &'static str = "ex2";
}

/// ex2's outcome: the deep queue's `/obs` drops (the most over the seeds) and whether
/// every seed balanced with it.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Ex2Outcome {
    /// Drops.
    pub deep_queue_obs_drops: u64,
    /// Every seed balanced.
    pub deep_queue_balances: bool,
}

/// ex2's measurements: per seed, (shallow, deep).
///
/// # Errors
/// [`ExerciseError`] when a run cannot start.
pub fn measure_ex2(
    b: &Ex2Bands,
    graph: &GraphSpec,
    stop: &StopFlag,
) -> Result<Vec<(Metrics, Metrics)>, ExerciseError> {
    let grid = Grid {
        clocks: vec![ClockKind::Virtual],
        sensor_hz: vec![b.sensor_hz],
        control_hz: vec![b.control_hz],
        queue_depth: vec![b.shallow_depth, b.deep_depth],
        seeds: b.seeds.clone(),
        base: RunConfig {
            duration: duration_from_secs(b.duration_s)?,
            graph: graph.clone(),
            ..RunConfig::default()
        },
    };
    let rows = run_grid_until(&grid, &scripted, threads(), &|_, _| {}, stop)?;
    super::interrupted(stop)?;
    let rows: Vec<Metrics> = rows.into_iter().map(|(_, m)| m).collect();
    let n = b.seeds.len();
    Ok((0..n)
        .map(|i| (rows[i].clone(), rows[n + i].clone()))
        .collect())
}

/// ex2's outcome in the terms of its prediction.
pub fn outcome_ex2(pairs: &[(Metrics, Metrics)]) -> Ex2Outcome {
    Ex2Outcome {
        deep_queue_obs_drops: pairs
            .iter()
            .filter_map(|(_, d)| d.obs_dropped)
            .max()
            .unwrap_or(0),
        deep_queue_balances: pairs.iter().all(|(_, d)| d.balanced),
    }
}

/// ex2's checks.
pub fn check_ex2(b: &Ex2Bands, pairs: &[(Metrics, Metrics)]) -> Vec<Check> {
    vec![
        check(
            format!("depth {} drops 0 /obs on every seed", b.deep_depth),
            pairs.iter().all(|(_, d)| d.obs_dropped == Some(0)),
        ),
        check(
            format!("depth {} drops > 0 /obs on every seed", b.shallow_depth),
            pairs.iter().all(|(s, _)| s.obs_dropped > Some(0)),
        ),
        check(
            "neither depth balances",
            pairs.iter().all(|(s, d)| !s.balanced && !d.balanced),
        ),
        check(
            "both depths fall at the same step per seed",
            pairs.iter().all(|(s, d)| s.steps == d.steps),
        ),
    ]
}

/// The drops are a count on the virtual clock, exact: right when the same. The survival:
/// right when it agrees.
impl Reconcile for Ex2Outcome {
    fn reconcile(&self, prediction: &toml::Table) -> Vec<Said> {
        let p = |k: &str| prediction.get(k);
        let (key, seen) = ("deep_queue_obs_drops", self.deep_queue_obs_drops);
        let drops = match p(key).and_then(super::number) {
            Some(n) => super::graded(
                key,
                &format!("You predicted {n} /obs drops with the deep queue; there were {seen}"),
                super::same(n, seen as f64),
                "",
            ),
            None => super::unreadable(key),
        };
        let key = "deep_queue_balances";
        let up = self.deep_queue_balances;
        let measured = if up { "it stayed up" } else { "it fell" };
        let survives = match p(key).and_then(toml::Value::as_bool) {
            Some(true) => super::graded(
                key,
                &format!("You predicted the deep queue keeps the pole up; {measured}"),
                up,
                "",
            ),
            Some(false) => super::graded(
                key,
                &format!("You predicted the pole falls even with the deep queue; {measured}"),
                !up,
                "",
            ),
            None => super::unreadable(key),
        };
        vec![drops, survives]
    }
}

impl Exercise for Ex2 {
    fn id(&self) -> &'static str {
        "ex2"
    }

    fn title(&self) -> &'static str {
        "the queue-depth trap"
    }

    fn file(&self) -> &'static str {
        "ex2_queue_trap.toml"
    }

    fn required_keys(&self) -> &'static [&'static str] {
        &["deep_queue_obs_drops", "deep_queue_balances"]
    }

    fn run(&self, cx: &mut Context<'_>) -> Result<(), ExerciseError> {
        let b: Ex2Bands = cx.bands()?;
        let pairs = cx.measure(|stop| measure_ex2(&b, cx.graph, stop))?;
        say!(
            cx,
            "control {} Hz | seed | depth | /obs dropped | balanced | fell at step | mean latency",
            b.control_hz
        );
        for (seed, (s, d)) in b.seeds.iter().zip(&pairs) {
            for m in [s, d] {
                say!(
                    cx,
                    "{:>13} | {:>4} | {:>5} | {:>12} | {:>8} | {:>12} | {:>7.1} ms",
                    "",
                    seed,
                    dash(m.queue_depth),
                    dash(m.obs_dropped),
                    if m.balanced { "Y" } else { "n" },
                    m.steps,
                    m.mean_latency_ms
                );
            }
        }
        cx.reconcile(&outcome_ex2(&pairs));
        cx.checks(&check_ex2(&b, &pairs));
        say!(cx, "\nReconcile: the deep queue stops the drop counter — nothing is evicted before the next");
        say!(cx, "read — but the policy still reads only the LATEST message, every 200 ms. The backlog it");
        say!(cx, "buffers is never used, the decisions are exactly as old, and the pole falls at the same");
        say!(cx, "step. Drops were the symptom of a rate mismatch; the disease is latency. Throughput is not control.");
        Ok(())
    }
}
