//! The chapter's exercises as data and checks: bands (with provenance) and learner
//! predictions are TOML files in `exercises/`; measurements are in-process virtual runs.
//!
//! - ex1, the control-rate cliff: sweep the policy rate with sensor and plant at 50 Hz.
//! - ex2, the queue-depth trap: at 5 Hz, /obs depth 1 against 100.
//! - ex3, jitter and phase offsets (real clock): matched rates drop from races alone, and
//!   their latency is about 20 ms where the virtual clock gives 0; phase offsets remove the
//!   drops and fix the latency (at the sensor-to-actuator offset, 10 ms).

use crate::config::{duration_from_secs, phase_offset_from_ms, ClockKind, RunConfig};
use crate::graph::GraphSpec;
use crate::metrics::Metrics;
use crate::policy::{Policy, Scripted};
use crate::sweep::{run_grid, Grid, SweepError};
use serde::Deserialize;
use std::path::Path;

/// Errors reading exercise files.
#[derive(Debug, thiserror::Error)]
pub enum ExerciseError {
    /// The file cannot be read.
    #[error("cannot read {path}: {detail}")]
    Read {
        /// The file.
        path: String,
        /// Why.
        detail: String,
    },
    /// The file is not valid TOML of the expected shape.
    #[error("{path}: {detail}")]
    Parse {
        /// The file.
        path: String,
        /// The parser's complaint (first line).
        detail: String,
    },
    /// A run failed.
    #[error(transparent)]
    Sweep(#[from] SweepError),
    /// A setting in the bands is invalid.
    #[error("bands: {0}")]
    Config(#[from] crate::config::ConfigError),
}

fn read_toml<T: for<'de> Deserialize<'de>>(path: &Path) -> Result<T, ExerciseError> {
    let text = std::fs::read_to_string(path).map_err(|e| ExerciseError::Read {
        path: path.display().to_string(),
        detail: e.to_string(),
    })?;
    toml::from_str(&text).map_err(|e| ExerciseError::Parse {
        path: path.display().to_string(),
        detail: e
            .to_string()
            .lines()
            .next()
            .unwrap_or("invalid TOML")
            .to_string(),
    })
}

/// Where the bands came from.
#[derive(Clone, Debug, Deserialize)]
pub struct Provenance {
    /// How they were measured.
    pub measured_with: String,
    /// When.
    pub measured_on: String,
    /// What the chapter reports.
    pub chapter: String,
    /// Anything else.
    pub notes: String,
}

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

/// ex3's settings.
#[derive(Clone, Debug, Deserialize)]
pub struct Ex3Bands {
    /// Run length, s.
    pub duration_s: f64,
    /// Every node's rate, Hz.
    pub rate_hz: f64,
    /// Offsets for sensor, policy, actuator, ms.
    pub phase_offset_ms: [f64; 3],
    /// Robust bound on /obs drops with the offsets, as a fraction of published.
    pub max_obs_drop_fraction_with_offsets: f64,
    /// With the offsets the latency is fixed: its median is the sensor-to-actuator offset
    /// (the last offset minus the first) within this, ms.
    pub fixed_latency_tolerance_ms: f64,
    /// Without offsets the mean sense→act latency is at least this, ms (the virtual clock
    /// gives 0: same-phase threads race, and the policy often reads the previous tick's
    /// reading).
    pub min_mean_latency_ms_matched: f64,
}

impl Ex3Bands {
    /// The latency the offsets fix, ms: from the sensor's tick to the actuator's (the last
    /// offset minus the first).
    pub fn fixed_latency_ms(&self) -> f64 {
        self.phase_offset_ms[2] - self.phase_offset_ms[0]
    }
}

/// `exercises/bands.toml`.
#[derive(Clone, Debug, Deserialize)]
pub struct Bands {
    /// Provenance.
    pub provenance: Provenance,
    /// ex1.
    pub ex1: Ex1Bands,
    /// ex2.
    pub ex2: Ex2Bands,
    /// ex3.
    pub ex3: Ex3Bands,
}

/// Read `exercises/bands.toml`.
///
/// # Errors
/// [`ExerciseError`] when unreadable or malformed.
pub fn load_bands(path: &Path) -> Result<Bands, ExerciseError> {
    read_toml(path)
}

/// An exercise file the learner edits.
#[derive(Clone, Debug, Deserialize)]
pub struct ExerciseFile {
    /// Title.
    pub title: String,
    /// Estimated learner time, minutes.
    pub estimated_minutes: u32,
    /// What it teaches.
    pub objective: String,
    /// What to do.
    pub instructions: String,
    /// The learner's prediction (keys per exercise; empty by default).
    #[serde(default)]
    pub prediction: toml::Table,
}

impl ExerciseFile {
    /// Read an exercise file.
    ///
    /// # Errors
    /// [`ExerciseError`] when unreadable or malformed.
    pub fn load(path: &Path) -> Result<Self, ExerciseError> {
        read_toml(path)
    }

    /// The prediction's `why`, trimmed.
    pub fn why(&self) -> &str {
        self.prediction
            .get("why")
            .and_then(|v| v.as_str())
            .map_or("", str::trim)
    }

    /// Is the prediction filled in: every `required` key present and a non-empty `why`?
    pub fn has_prediction(&self, required: &[&str]) -> bool {
        !self.why().is_empty() && required.iter().all(|k| self.prediction.contains_key(*k))
    }

    /// The prediction as `key = value` text, for display beside the outcome.
    pub fn prediction_text(&self) -> String {
        self.prediction
            .iter()
            .map(|(k, v)| format!("{k} = {v}"))
            .collect::<Vec<_>>()
            .join("\n")
    }
}

/// What an exercise measured, in the terms of its prediction's keys.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Outcome {
    /// ex1: the highest control rate on the grid at which a seed fell (`None`: none fell).
    Ex1 {
        /// Rate, Hz.
        fails_at_hz: Option<f64>,
    },
    /// ex2: the deep queue's `/obs` drops (the most over the seeds) and whether every seed
    /// balanced with it.
    Ex2 {
        /// Drops.
        deep_queue_obs_drops: u64,
        /// Every seed balanced.
        deep_queue_balances: bool,
    },
    /// ex3: `/obs` drops with matched rates and no offsets.
    Ex3 {
        /// Drops.
        matched_obs_drops: u64,
    },
}

/// A prediction value as a number (TOML integer or float).
fn number(v: &toml::Value) -> Option<f64> {
    v.as_float().or_else(|| v.as_integer().map(|i| i as f64))
}

impl ExerciseFile {
    /// The prediction beside the outcome, one sentence per predicted key, in words: "You
    /// predicted the pole first fails at 10 Hz; it first fell at 5 Hz." A key the learner
    /// left out, or gave in another type, is said so.
    pub fn reconcile(&self, outcome: &Outcome) -> Vec<String> {
        let p = |k: &str| self.prediction.get(k);
        let unreadable =
            |k: &str| format!("Your prediction `{k}` is missing or not of the expected type.");
        match *outcome {
            Outcome::Ex1 { fails_at_hz } => {
                let measured = fails_at_hz.map_or("it never fell in the range".to_string(), |hz| {
                    format!("it first fell at {hz} Hz")
                });
                vec![match p("fails_at_hz").and_then(number) {
                    Some(hz) if Some(hz) == fails_at_hz => {
                        format!("You predicted the pole first fails at {hz} Hz; {measured}: right.")
                    }
                    Some(hz) => format!("You predicted the pole first fails at {hz} Hz; {measured}."),
                    None => unreadable("fails_at_hz"),
                }]
            }
            Outcome::Ex2 {
                deep_queue_obs_drops,
                deep_queue_balances,
            } => {
                let drops = match p("deep_queue_obs_drops").and_then(number) {
                    Some(n) => format!(
                        "You predicted {n} /obs drops with the deep queue; there were {deep_queue_obs_drops}."
                    ),
                    None => unreadable("deep_queue_obs_drops"),
                };
                let measured = if deep_queue_balances {
                    "it stayed up"
                } else {
                    "it fell"
                };
                let survives = match p("deep_queue_balances").and_then(toml::Value::as_bool) {
                    Some(true) => format!("You predicted the deep queue keeps the pole up; {measured}."),
                    Some(false) => format!("You predicted the pole falls even with the deep queue; {measured}."),
                    None => unreadable("deep_queue_balances"),
                };
                vec![drops, survives]
            }
            Outcome::Ex3 { matched_obs_drops } => vec![match p("matched_obs_drops").and_then(number) {
                Some(n) => format!(
                    "You predicted {n} /obs drops with matched rates; there were {matched_obs_drops} (the real clock varies run to run)."
                ),
                None => unreadable("matched_obs_drops"),
            }],
        }
    }
}

/// The keys each exercise's prediction must have (besides `why`).
pub fn required_keys(exercise: &str) -> &'static [&'static str] {
    match exercise {
        "ex1" => &["fails_at_hz"],
        "ex2" => &["deep_queue_obs_drops", "deep_queue_balances"],
        "ex3" => &["matched_obs_drops"],
        _ => &[],
    }
}

/// One check's outcome.
#[derive(Clone, Debug, PartialEq)]
pub struct Check {
    /// What was checked.
    pub name: String,
    /// Did it hold?
    pub passed: bool,
}

fn check(name: impl Into<String>, passed: bool) -> Check {
    Check {
        name: name.into(),
        passed,
    }
}

fn scripted() -> Result<Box<dyn Policy>, String> {
    Ok(Box::new(Scripted))
}

fn threads() -> usize {
    std::thread::available_parallelism().map_or(1, |n| n.get())
}

/// ex1's measurements: one [`Metrics`] per (rate, seed), rates in band order, seed fastest.
///
/// # Errors
/// [`ExerciseError`] when a run cannot start.
pub fn measure_ex1(b: &Ex1Bands, graph: &GraphSpec) -> Result<Vec<Metrics>, ExerciseError> {
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
    Ok(run_grid(&grid, &scripted, threads(), &|_, _| {})?
        .into_iter()
        .map(|(_, m)| m)
        .collect())
}

/// ex1's checks on its measurements.
pub fn check_ex1(b: &Ex1Bands, runs: &[Metrics]) -> Vec<Check> {
    let at = |hz: f64| runs.iter().filter(move |m| m.control_hz == hz);
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

/// ex2's measurements: per seed, (shallow, deep).
///
/// # Errors
/// [`ExerciseError`] when a run cannot start.
pub fn measure_ex2(
    b: &Ex2Bands,
    graph: &GraphSpec,
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
    let rows: Vec<Metrics> = run_grid(&grid, &scripted, threads(), &|_, _| {})?
        .into_iter()
        .map(|(_, m)| m)
        .collect();
    let n = b.seeds.len();
    Ok((0..n)
        .map(|i| (rows[i].clone(), rows[n + i].clone()))
        .collect())
}

/// ex2's checks.
pub fn check_ex2(b: &Ex2Bands, pairs: &[(Metrics, Metrics)]) -> Vec<Check> {
    vec![
        check(
            format!("depth {} drops 0 /obs on every seed", b.deep_depth),
            pairs.iter().all(|(_, d)| d.obs_dropped == 0),
        ),
        check(
            format!("depth {} drops > 0 /obs on every seed", b.shallow_depth),
            pairs.iter().all(|(s, _)| s.obs_dropped > 0),
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

/// ex3's two real-clock runs: (matched, with phase offsets).
///
/// # Errors
/// [`ExerciseError`] when a run cannot start.
pub fn measure_ex3(b: &Ex3Bands, graph: &GraphSpec) -> Result<(Metrics, Metrics), ExerciseError> {
    let mut base = RunConfig {
        clock: ClockKind::Real,
        duration: duration_from_secs(b.duration_s)?,
        graph: graph.clone(),
        ..RunConfig::default()
    };
    base.set_sensor_hz(b.rate_hz)?;
    base.set_control_hz(b.rate_hz)?;
    let offsets = b
        .phase_offset_ms
        .iter()
        .map(|&ms| phase_offset_from_ms(ms))
        .collect::<Result<Vec<_>, _>>()?;
    let run = |cfg: &RunConfig| -> Result<Metrics, ExerciseError> {
        let opts = crate::run::RunOptions {
            keep_trace: false,
            ..Default::default()
        };
        Ok(crate::run::run(cfg, Box::new(Scripted), opts)
            .map_err(SweepError::from)?
            .metrics)
    };
    let matched = run(&base)?;
    let offset = run(&RunConfig {
        phase_offsets: offsets,
        ..base
    })?;
    Ok((matched, offset))
}

/// ex3's checks: only what is robust on a noisy machine (see the bands' provenance).
pub fn check_ex3(b: &Ex3Bands, matched: &Metrics, offset: &Metrics) -> Vec<Check> {
    let fixed = b.fixed_latency_ms();
    vec![
        check("the pole stays up with matched rates", matched.balanced),
        check("the pole stays up with phase offsets", offset.balanced),
        check(
            "the offsets remove drops: fewer /obs drops than with matched phases",
            offset.obs_dropped < matched.obs_dropped,
        ),
        check(
            format!(
                "with offsets, /obs drops <= {:.0}% of published",
                b.max_obs_drop_fraction_with_offsets * 100.0
            ),
            offset.obs_dropped as f64
                <= b.max_obs_drop_fraction_with_offsets * offset.obs_published as f64,
        ),
        check(
            format!(
                "the offsets fix the latency: median {fixed} ms ± {} ms",
                b.fixed_latency_tolerance_ms
            ),
            (offset.latency_p50_ms - fixed).abs() <= b.fixed_latency_tolerance_ms,
        ),
        check(
            format!(
                "with matched phases, mean sense->act latency >= {} ms (the virtual clock: 0)",
                b.min_mean_latency_ms_matched
            ),
            matched.mean_latency_ms >= b.min_mean_latency_ms_matched,
        ),
    ]
}

#[cfg(test)]
mod tests {
    use super::*;

    fn file(prediction: &str) -> ExerciseFile {
        toml::from_str(&format!(
            "title = \"t\"\nestimated_minutes = 1\nobjective = \"o\"\ninstructions = \"i\"\n[prediction]\n{prediction}"
        ))
        .unwrap()
    }

    #[test]
    fn ex3_checks_pass_on_the_measured_shape_and_fail_off_it() {
        let b: Bands = toml::from_str(
            &std::fs::read_to_string(concat!(env!("CARGO_MANIFEST_DIR"), "/exercises/bands.toml"))
                .unwrap(),
        )
        .unwrap();
        let b = b.ex3;
        assert_eq!(b.fixed_latency_ms(), 10.0);
        // Any run's metrics, given the figures of one real-clock pair (matched: 40 drops,
        // mean 21.5 ms; offsets 0/5/10: no drop, median 10.0 ms).
        let cfg = RunConfig {
            clock: ClockKind::Virtual,
            duration: crate::time::Nanos::from_millis(100),
            ..RunConfig::default()
        };
        let base = crate::run::run(&cfg, Box::new(Scripted), crate::run::RunOptions::new())
            .unwrap()
            .metrics;
        let matched = Metrics {
            obs_published: 250,
            obs_dropped: 40,
            mean_latency_ms: 21.5,
            ..base.clone()
        };
        let offset = Metrics {
            obs_published: 250,
            obs_dropped: 0,
            mean_latency_ms: 9.9,
            latency_p50_ms: 10.0,
            ..base
        };
        assert!(check_ex3(&b, &matched, &offset).iter().all(|c| c.passed));
        let failed = |m: &Metrics, o: &Metrics| -> Vec<String> {
            check_ex3(&b, m, o)
                .into_iter()
                .filter(|c| !c.passed)
                .map(|c| c.name)
                .collect()
        };
        // A latency that is not the offsets' 10 ms, drops that stay, a matched run at 0 ms.
        let off = Metrics {
            latency_p50_ms: 12.0,
            obs_dropped: 40,
            ..offset.clone()
        };
        assert_eq!(
            failed(&matched, &off).len(),
            3,
            "{:?}",
            failed(&matched, &off)
        );
        let zero = Metrics {
            mean_latency_ms: 0.0,
            ..matched.clone()
        };
        assert_eq!(failed(&zero, &offset).len(), 1);
    }

    #[test]
    fn predictions_are_reconciled_in_words() {
        let f = file("fails_at_hz = 10\nwhy = \"w\"");
        assert_eq!(
            f.reconcile(&Outcome::Ex1 {
                fails_at_hz: Some(5.0)
            }),
            ["You predicted the pole first fails at 10 Hz; it first fell at 5 Hz."]
        );
        let f = file("fails_at_hz = 5.0\nwhy = \"w\"");
        assert!(f.reconcile(&Outcome::Ex1 {
            fails_at_hz: Some(5.0)
        })[0]
            .ends_with(": right."));
        let f = file("deep_queue_obs_drops = 0\ndeep_queue_balances = true\nwhy = \"w\"");
        assert_eq!(
            f.reconcile(&Outcome::Ex2 {
                deep_queue_obs_drops: 0,
                deep_queue_balances: false
            }),
            [
                "You predicted 0 /obs drops with the deep queue; there were 0.",
                "You predicted the deep queue keeps the pole up; it fell."
            ]
        );
        let f = file("matched_obs_drops = \"many\"\nwhy = \"w\"");
        assert!(f.reconcile(&Outcome::Ex3 {
            matched_obs_drops: 7
        })[0]
            .contains("not of the expected type"));
    }
}
