//! ex8, the noisy sensor: the estimator graph (`graphs/cartpole-estimator.toml`: a 200 Hz
//! sensor measuring positions only, an estimator differencing them into velocities through
//! a first-order low-pass filter, the policy on its estimate) with the sensor's pole-angle
//! noise raised step by step, at the estimator's shipped cut-off and at a lower one. Where
//! does the pole first fall, and does a smoother estimate (more lag, less noise) move that
//! point? Virtual clock: every run is exact, the noise seeded.

use super::{
    check, run_virtual, Check, Context, Exercise, ExerciseError, Reconcile, Said, Section,
};
use ratelab_core::metrics::Metrics;
use ratelab_runtime::graph::GraphSpec;
use ratelab_runtime::scheduler::StopFlag;
use serde::Deserialize;

/// ex8: the noisy sensor.
pub struct Ex8;

/// ex8's settings and the bands its checks assert.
#[derive(Clone, Debug, Deserialize)]
pub struct Ex8Bands {
    /// The graph, relative to the bands file's folder.
    pub graph: String,
    /// The node whose measurement noise is raised.
    pub sensor: String,
    /// Its noise parameter (a standard deviation, rad).
    pub noise_param: String,
    /// The estimator node.
    pub estimator: String,
    /// Its low-pass cut-off parameter (Hz).
    pub cutoff_param: String,
    /// The noise levels, rad, in increasing order.
    pub noise_grid_rad: Vec<f64>,
    /// The cut-offs, Hz: the graph's own first, then the lower (smoother) one.
    pub cutoffs_hz: [f64; 2],
    /// Seeds.
    pub seeds: Vec<u64>,
    /// Run length, s.
    pub duration_s: f64,
    /// At the first cut-off, the lowest noise at which a seed falls lies in this
    /// `[low, high]`, rad.
    pub first_fall_rad: [f64; 2],
}

impl Section for Ex8Bands {
    const NAME: &'static str = "ex8";
}

/// ex8's outcome: the lowest noise at which a seed fell at the estimator's shipped cut-off,
/// and whether the lower cut-off's first fall came at a higher noise.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Ex8Outcome {
    /// rad (`None`: none on the grid).
    pub fails_at_noise_rad: Option<f64>,
    /// The smoother estimate tolerated more noise.
    pub lower_cutoff_tolerates_more: bool,
}

/// One ex8 run.
#[derive(Clone, Debug)]
pub struct Ex8Run {
    /// The estimator's cut-off, Hz.
    pub cutoff_hz: f64,
    /// The sensor's pole-angle noise (standard deviation), rad.
    pub noise_rad: f64,
    /// The seed.
    pub seed: u64,
    /// What it measured.
    pub metrics: Metrics,
}

/// `graph` with the sensor's noise at `noise_rad` and the estimator's cut-off at `cutoff_hz`.
fn case_graph(
    b: &Ex8Bands,
    graph: &GraphSpec,
    noise_rad: f64,
    cutoff_hz: f64,
) -> Result<GraphSpec, ExerciseError> {
    let mut g = graph.clone();
    for (node, key, value) in [
        (&b.sensor, &b.noise_param, noise_rad),
        (&b.estimator, &b.cutoff_param, cutoff_hz),
    ] {
        let id = g
            .node_id(node)
            .ok_or_else(|| ExerciseError::NoNode(node.clone()))?;
        g.nodes[id.0]
            .params
            .insert(key.clone(), toml::Value::Float(value));
    }
    Ok(g)
}

/// ex8's measurements: every cut-off, noise level and seed (in that order, seed fastest).
///
/// # Errors
/// [`ExerciseError`] when the graph has no such sensor or estimator, or a run cannot start.
pub fn measure_ex8(
    b: &Ex8Bands,
    graph: &GraphSpec,
    stop: &StopFlag,
) -> Result<Vec<Ex8Run>, ExerciseError> {
    let mut runs = Vec::new();
    for cutoff_hz in b.cutoffs_hz {
        for &noise_rad in &b.noise_grid_rad {
            let g = case_graph(b, graph, noise_rad, cutoff_hz)?;
            for &seed in &b.seeds {
                runs.push(Ex8Run {
                    cutoff_hz,
                    noise_rad,
                    seed,
                    metrics: run_virtual(g.clone(), seed, b.duration_s, stop)?.metrics,
                });
            }
        }
    }
    Ok(runs)
}

/// The lowest noise at which a seed fell with the cut-off `cutoff_hz` (`None`: none fell).
pub fn first_fall_rad(runs: &[Ex8Run], cutoff_hz: f64) -> Option<f64> {
    runs.iter()
        .filter(|r| r.cutoff_hz == cutoff_hz && !r.metrics.balanced)
        .map(|r| r.noise_rad)
        .fold(None, |lo: Option<f64>, n| {
            Some(lo.map_or(n, |lo| lo.min(n)))
        })
}

/// ex8's outcome in the terms of its prediction.
pub fn outcome_ex8(b: &Ex8Bands, runs: &[Ex8Run]) -> Ex8Outcome {
    let [shipped, lower] = b.cutoffs_hz;
    let (at_shipped, at_lower) = (first_fall_rad(runs, shipped), first_fall_rad(runs, lower));
    Ex8Outcome {
        fails_at_noise_rad: at_shipped,
        lower_cutoff_tolerates_more: tolerates_more(at_lower, at_shipped),
    }
}

/// Does a first fall at `a` (`None`: none on the grid) come at a higher noise than one at `b`?
fn tolerates_more(a: Option<f64>, b: Option<f64>) -> bool {
    match (a, b) {
        (None, Some(_)) => true,
        (Some(a), Some(b)) => a > b,
        _ => false,
    }
}

/// ex8's checks: at the shipped cut-off every seed balances below the band and one falls
/// within it; every seed falls at the grid's top (the noise does decide); the lower
/// cut-off's first fall is at a higher noise.
pub fn check_ex8(b: &Ex8Bands, runs: &[Ex8Run]) -> Vec<Check> {
    let [lo, hi] = b.first_fall_rad;
    let [shipped, lower] = b.cutoffs_hz;
    let top = b.noise_grid_rad.last().copied().unwrap_or(0.0);
    let at_shipped = first_fall_rad(runs, shipped);
    let at_lower = first_fall_rad(runs, lower);
    vec![
        check(
            format!(
                "with the {shipped} Hz cut-off the pole first falls at a noise of {lo}-{hi} rad, and no seed falls below it"
            ),
            at_shipped.is_some_and(|n| (lo..=hi).contains(&n)),
        ),
        check(
            format!("at {top} rad every seed falls, whatever the cut-off"),
            runs.iter().any(|r| r.noise_rad == top)
                && runs
                    .iter()
                    .filter(|r| r.noise_rad == top)
                    .all(|r| !r.metrics.balanced),
        ),
        check(
            format!(
                "a {lower} Hz cut-off (smoother, later) first falls at a higher noise than {shipped} Hz"
            ),
            tolerates_more(at_lower, at_shipped),
        ),
    ]
}

/// The learner's ex8 `prediction` beside the outcome, one sentence per key. A noise of the
/// grid: right when it is the one at which a seed first fell. The cut-off: right when it
/// agrees.
impl Reconcile for Ex8Outcome {
    fn reconcile(&self, prediction: &toml::Table) -> Vec<Said> {
        reconcile(prediction, self)
    }
}

fn reconcile(prediction: &toml::Table, outcome: &Ex8Outcome) -> Vec<Said> {
    let Ex8Outcome {
        fails_at_noise_rad,
        lower_cutoff_tolerates_more,
    } = *outcome;
    let measured = fails_at_noise_rad
        .map_or("no noise on the grid made it fall".to_string(), |n| {
            format!("it first fell at {n} rad")
        });
    let key = "fails_at_noise_rad";
    let first = match prediction.get(key).and_then(super::number) {
        Some(n) => super::graded(
            key,
            &format!("You predicted the pole first falls at a noise of {n} rad; {measured}"),
            fails_at_noise_rad.is_some_and(|f| super::same(n, f)),
            "",
        ),
        None => super::unreadable(key),
    };
    let key = "lower_cutoff_tolerates_more";
    let lower = match prediction.get(key).and_then(toml::Value::as_bool) {
        Some(p) => super::graded(
            key,
            &format!(
                "You predicted the lower cut-off {} more noise; it {}",
                if p { "tolerates" } else { "does not tolerate" },
                if lower_cutoff_tolerates_more {
                    "does"
                } else {
                    "does not"
                }
            ),
            p == lower_cutoff_tolerates_more,
            "",
        ),
        None => super::unreadable(key),
    };
    vec![first, lower]
}

impl Exercise for Ex8 {
    fn id(&self) -> &'static str {
        "ex8"
    }

    fn title(&self) -> &'static str {
        "the noisy sensor"
    }

    fn file(&self) -> &'static str {
        "ex8_noisy_sensor.toml"
    }

    fn required_keys(&self) -> &'static [&'static str] {
        &["fails_at_noise_rad", "lower_cutoff_tolerates_more"]
    }

    fn default_graph(&self, bands: &super::Bands) -> Result<Option<String>, ExerciseError> {
        Ok(Some(bands.of::<Ex8Bands>()?.graph))
    }

    /// The table (per cut-off and noise: each seed's verdict and the mean sense→act
    /// latency), the reconcile and the checks.
    fn run(&self, cx: &mut Context<'_>) -> Result<(), ExerciseError> {
        let b: Ex8Bands = cx.bands()?;
        let runs = cx.measure(|stop| measure_ex8(&b, cx.graph, stop))?;
        say!(
            cx,
            "cut-off | angle noise | seeds: balanced (n@t: fell at t s) | latency mean"
        );
        for cutoff in b.cutoffs_hz {
            for &noise in &b.noise_grid_rad {
                let row: Vec<&Ex8Run> = runs
                    .iter()
                    .filter(|r| r.cutoff_hz == cutoff && r.noise_rad == noise)
                    .collect();
                let verdicts: Vec<String> =
                    row.iter().map(|r| super::fell_cell(&r.metrics)).collect();
                let mean = row.iter().map(|r| r.metrics.mean_latency_ms).sum::<f64>()
                    / row.len().max(1) as f64;
                say!(
                    cx,
                    "{:>4} Hz | {:>7.3} rad | {:<34} | {:>7.1} ms",
                    cutoff,
                    noise,
                    verdicts.join(" "),
                    mean
                );
            }
        }
        cx.reconcile(&outcome_ex8(&b, &runs));
        cx.checks(&check_ex8(&b, &runs));
        say!(cx);
        cx.paragraph(
            "Reconcile: the estimator ticks at 100 Hz and reads the newest of the two measurements \
             the 200 Hz sensor published since its last tick, so its velocity is the difference of \
             two noisy angles 10 ms apart: its noise is about 141 times the angle's \
             (sqrt(2) / 0.010 s) before the filter. A pole-angle noise of a hundredth of a radian, \
             half a degree, is a velocity noise of about 1.4 rad/s, and the policy pushes on it. The low-pass filter trades that noise for \
             lag (about 1 / (2 pi cut-off): 8 ms at 20 Hz, 16 ms at 10 Hz); here the noise is the \
             larger harm, so the smoother estimate holds on to a higher noise. How far does the \
             trade go? Copy the graph, lower cutoff_hz to 5 and 2 Hz, raise noise_angle_rad, and \
             look. The latency column stays at the estimator's and the policy's compute times \
             plus the waits for the next tick: noise does not delay messages, it corrupts them.",
        );
        say!(
            cx,
            "  ./scripts/lab.sh run --clock virtual --graph graphs/cartpole-estimator.toml"
        );
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_first_fall_higher_or_none_tolerates_more() {
        assert!(tolerates_more(Some(0.018), Some(0.014)));
        assert!(!tolerates_more(Some(0.014), Some(0.014)));
        assert!(!tolerates_more(Some(0.012), Some(0.014)));
        assert!(tolerates_more(None, Some(0.014)));
        assert!(!tolerates_more(Some(0.02), None));
        assert!(!tolerates_more(None, None));
    }
}
