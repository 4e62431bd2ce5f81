//! ex1, the control-rate cliff: sweep the policy's rate with the sensor and the plant at
//! 50 Hz, every seed, and find where the pole first falls. Virtual clock: each run is exact.

use super::{check, scripted, threads, Check, Context, Exercise, ExerciseError};
use super::{Reconcile, Said, Section};
use ratelab_core::metrics::Metrics;
use ratelab_drivers::sweep::{run_grid_until, Grid};
use ratelab_runtime::config::{duration_from_secs, ClockKind, RunConfig};
use ratelab_runtime::graph::GraphSpec;
use ratelab_runtime::scheduler::StopFlag;
use serde::Deserialize;

/// ex1: the control-rate cliff.
pub struct Ex1;

/// ex1's sweep and bands.
#[derive(Clone, Debug, Deserialize)]
pub struct Ex1Bands {
    /// Seeds.
    pub seeds: Vec<u64>,
    /// Sensor rate, Hz.
    pub sensor_hz: f64,
    /// Policy rates swept, Hz.
    pub control_hz: Vec<f64>,
    /// Run length, s.
    pub duration_s: f64,
    /// Balances on every seed at and above this rate.
    pub balances_at_or_above_hz: f64,
    /// With at least this many steps.
    pub min_steps: u64,
    /// Falls on every seed at this rate.
    pub falls_at_hz: f64,
}

impl Section for Ex1Bands {
    const NAME: &'static str = "ex1";
}

/// ex1's outcome: the highest control rate on the grid at which a seed fell.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Ex1Outcome {
    /// Rate, Hz (`None`: none fell).
    pub fails_at_hz: Option<f64>,
}

/// ex1's measurements: one [`Metrics`] per (rate, seed), rates in band order, seed fastest.
///
/// # Errors
/// [`ExerciseError`] when a run cannot start.
pub fn measure_ex1(
    b: &Ex1Bands,
    graph: &GraphSpec,
    stop: &StopFlag,
) -> Result<Vec<Metrics>, ExerciseError> {
    let grid = Grid {
        clocks: vec![ClockKind::Virtual],
        sensor_hz: vec![b.sensor_hz],
        control_hz: b.control_hz.clone(),
        queue_depth: vec![1],
        seeds: b.seeds.clone(),
        base: RunConfig {
            duration: duration_from_secs(b.duration_s)?,
            graph: graph.clone(),
            ..RunConfig::default()
        },
    };
    let rows = run_grid_until(&grid, &scripted, threads(), &|_, _| {}, stop)?;
    super::interrupted(stop)?;
    Ok(rows.into_iter().map(|(_, m)| m).collect())
}

/// The runs of rate number `i` of the grid, one per seed.
fn row<'a>(b: &Ex1Bands, runs: &'a [Metrics], i: usize) -> &'a [Metrics] {
    &runs[i * b.seeds.len()..(i + 1) * b.seeds.len()]
}

/// ex1's outcome: the first rate of the grid (in band order, fastest first) at which a
/// seed fell.
pub fn outcome_ex1(b: &Ex1Bands, runs: &[Metrics]) -> Ex1Outcome {
    Ex1Outcome {
        fails_at_hz: b
            .control_hz
            .iter()
            .enumerate()
            .find(|(i, _)| row(b, runs, *i).iter().any(|m| !m.balanced))
            .map(|(_, hz)| *hz),
    }
}

/// ex1's checks on its measurements.
pub fn check_ex1(b: &Ex1Bands, runs: &[Metrics]) -> Vec<Check> {
    let at = |hz: f64| runs.iter().filter(move |m| m.control_hz == Some(hz));
    let mut checks = Vec::new();
    for &hz in b
        .control_hz
        .iter()
        .filter(|&&hz| hz >= b.balances_at_or_above_hz)
    {
        checks.push(check(
            format!(
                "balances on every seed at {hz} Hz with >= {} steps",
                b.min_steps
            ),
            at(hz).all(|m| m.balanced && m.steps >= b.min_steps),
        ));
    }
    checks.push(check(
        format!("falls on every seed at {} Hz", b.falls_at_hz),
        at(b.falls_at_hz).all(|m| !m.balanced),
    ));
    let mean = |hz: f64| {
        let v: Vec<f64> = at(hz).map(|m| m.mean_latency_ms).collect();
        v.iter().sum::<f64>() / v.len().max(1) as f64
    };
    let top = b.control_hz.iter().copied().fold(f64::MIN, f64::max);
    checks.push(check(
        format!(
            "mean latency at {} Hz above {top} Hz's",
            b.balances_at_or_above_hz
        ),
        mean(b.balances_at_or_above_hz) > mean(top),
    ));
    checks
}

/// A rate of the sweep: right when it is the rate at which the pole first fell.
impl Reconcile for Ex1Outcome {
    fn reconcile(&self, prediction: &toml::Table) -> Vec<Said> {
        let key = "fails_at_hz";
        let measured = self
            .fails_at_hz
            .map_or("it never fell in the range".to_string(), |hz| {
                format!("it first fell at {hz} Hz")
            });
        vec![match prediction.get(key).and_then(super::number) {
            Some(hz) => super::graded(
                key,
                &format!("You predicted the pole first fails at {hz} Hz; {measured}"),
                self.fails_at_hz.is_some_and(|f| super::same(hz, f)),
                "",
            ),
            None => super::unreadable(key),
        }]
    }
}

impl Exercise for Ex1 {
    fn id(&self) -> &'static str {
        "ex1"
    }

    fn title(&self) -> &'static str {
        "the rate cliff"
    }

    fn file(&self) -> &'static str {
        "ex1_rate_cliff.toml"
    }

    fn required_keys(&self) -> &'static [&'static str] {
        &["fails_at_hz"]
    }

    fn run(&self, cx: &mut Context<'_>) -> Result<(), ExerciseError> {
        let b: Ex1Bands = cx.bands()?;
        let runs = cx.measure(|stop| measure_ex1(&b, cx.graph, stop))?;
        say!(
            cx,
            "{:>9} | {} | mean sense->act latency",
            "control",
            super::seeds_header(&b.seeds)
        );
        for (i, hz) in b.control_hz.iter().enumerate() {
            let row = row(&b, &runs, i);
            let cells: Vec<String> = row
                .iter()
                .map(|m| {
                    if m.balanced {
                        "   Y   ".into()
                    } else {
                        format!("n@{:>4.2}s", m.fell_at_s.unwrap_or(0.0))
                    }
                })
                .collect();
            let lat = row.iter().map(|m| m.mean_latency_ms).sum::<f64>() / row.len() as f64;
            say!(cx, "{:>6} Hz | {} | {:>6.1} ms", hz, cells.join(" "), lat);
        }
        let outcome = outcome_ex1(&b, &runs);
        say!(
            cx,
            "(Y: balanced the whole {} s run, which a longer run may not; n@T: fell at run time T s; one cell per seed, as in the header.)",
            b.duration_s
        );
        say!(
            cx,
            "\nOutcome: the pole first fails at {} Hz.",
            outcome
                .fails_at_hz
                .map_or("no rate".into(), |hz| hz.to_string())
        );
        cx.reconcile(&outcome);
        cx.checks(&check_ex1(&b, &runs));
        say!(cx, "\nReconcile: latency grows as the rate drops (the actuator holds each action longer), but");
        say!(cx, "not strictly: a 15 Hz policy ticks between sensor readings and acts on readings up to 20 ms");
        say!(cx, "older than a 10 Hz policy, whose ticks coincide with the sensor's. Phase matters, not only");
        say!(cx, "rate. The pole survives until the held action is so old that the correction arrives after");
        say!(
            cx,
            "the pole is past saving. A good controller is robust until, suddenly, it is not."
        );
        say!(cx, "Near the edge a seed can fall at one rate and balance just below it: the cliff is ragged.");
        let seeds: Vec<String> = b.seeds.iter().map(u64::to_string).collect();
        say!(
            cx,
            "Find it to 0.1 Hz, with the balanced fraction per rate around it: ratelab cliff --seeds {}",
            seeds.join(",")
        );
        Ok(())
    }
}
