//! The chapter's exercises as data and checks: bands (with provenance) and learner
//! predictions are TOML files in `exercises/`; measurements are in-process virtual runs.
//!
//! - ex1, the control-rate cliff: sweep the policy rate with sensor and plant at 50 Hz.
//! - ex2, the queue-depth trap: at 5 Hz, /obs depth 1 against 100.
//! - ex3, jitter and phase offsets (real clock): matched rates drop from races alone, and
//!   their latency is about 20 ms where the virtual clock gives 0; phase offsets remove the
//!   drops and fix the latency (at the sensor-to-actuator offset, 10 ms).
//! - ex4, the stale queue ([`ex4`], QoS): a slow policy behind a deep `/obs` queue, latest-wins
//!   against FIFO delivery, then FIFO with a lifespan.
//! - ex5, the watchdog ([`ex5`], QoS): the safety graph's `/cmd` across a lossy link, best effort
//!   against a deadline with `hold` or `zero`, and reliable delivery.
//! - ex6, write your own node ([`ex6`]): the learner's Python safety limiter in the safety graph's
//!   place, over a ladder of clamps, beside the built-in safety node: the smallest clamp
//!   that still balances, and whether the learner's node limits as the built-in one does.
//! - ex7, the slow callback ([`ex7`]): a 30 ms policy callback beside the sensor on one
//!   executor, single-threaded, on two threads in one callback group, and in two groups.
//! - ex8, the noisy sensor ([`ex8`]): the estimator graph with its sensor's angle noise
//!   raised, at the estimator's cut-off and a lower one: where the pole first falls.
//! - ex9, the crossing ([`ex9`], real clock, real processes): the chapter's graph split
//!   across two processes, without and with phase offsets: what a crossing hop costs.

mod ex4;
mod ex5;
mod ex6;
mod ex7;
mod ex8;
mod ex9;

pub use ex4::{check_ex4, measure_ex4, outcome_ex4, Ex4Bands, Ex4Run};
pub use ex5::{check_ex5, measure_ex5, outcome_ex5, Ex5Bands, Ex5Case, Ex5Run};
pub use ex6::{check_ex6, ex6_differences, measure_ex6, outcome_ex6, Ex6Bands, Ex6Run};
pub use ex7::{check_ex7, measure_ex7, outcome_ex7, Ex7Bands, Ex7Case, Ex7Run};
pub use ex8::{check_ex8, first_fall_rad, measure_ex8, outcome_ex8, Ex8Bands, Ex8Run};
pub use ex9::{check_ex9, measure_ex9, outcome_ex9, Ex9Bands, Ex9Case, Ex9Run};

use crate::config::{duration_from_secs, phase_offset_from_ms, ClockKind, RunConfig};
use crate::graph::GraphSpec;
use crate::metrics::Metrics;
use crate::policy::{Policy, Scripted};
use crate::qos::Delivery;
use crate::sweep::{run_grid, run_pool, Grid, SweepError};
use serde::Deserialize;
use std::path::{Path, PathBuf};

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
    /// A QoS or rate the bands set does not fit the graph.
    #[error("bands: {0}")]
    Setting(#[from] crate::graph::spec::OverrideError),
    /// The graph lacks a node the bands name.
    #[error("bands: the graph has no node '{0}'")]
    NoNode(String),
    /// A launch across processes failed.
    #[error("launch: {0}")]
    Launch(String),
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
    /// The latency the offsets fix, ms ([`fixed_latency_ms`]).
    pub fn fixed_latency_ms(&self) -> f64 {
        fixed_latency_ms(&self.phase_offset_ms)
    }
}

/// The sense→act latency phase offsets of the chapter's chain (sensor, policy, actuator,
/// ms) fix: from the sensor's tick to the actuator's, the last offset minus the first.
pub fn fixed_latency_ms(phase_offset_ms: &[f64; 3]) -> f64 {
    phase_offset_ms[2] - phase_offset_ms[0]
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
    /// ex4.
    pub ex4: Ex4Bands,
    /// ex5.
    pub ex5: Ex5Bands,
    /// ex6.
    pub ex6: Ex6Bands,
    /// ex7.
    pub ex7: Ex7Bands,
    /// ex8.
    pub ex8: Ex8Bands,
    /// ex9.
    pub ex9: Ex9Bands,
}

/// The graph an exercise runs on when none is given: ex5's and ex6's (resolved against the
/// folder of the bands file, `dir`); `None` for the chapter's.
///
/// # Errors
/// [`ExerciseError`] when the bands cannot be read.
pub fn default_graph(exercise: &str, dir: &Path) -> Result<Option<PathBuf>, ExerciseError> {
    let graph = |b: Bands| match exercise {
        "ex5" => Some(b.ex5.graph),
        "ex7" => Some(b.ex7.graph),
        "ex8" => Some(b.ex8.graph),
        _ => Some(b.ex6.graph),
    };
    if !matches!(exercise, "ex5" | "ex6" | "ex7" | "ex8") {
        return Ok(None);
    }
    Ok(graph(load_bands(&dir.join("bands.toml"))?).map(|g| dir.join(g)))
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
            .map(|(k, v)| format!("{} = {v}", crate::text::printable(k)))
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
    /// ex4: which deliveries kept the pole up on every seed, and FIFO's latency at the fall.
    Ex4 {
        /// Latest-wins balanced on every seed.
        latest_balances: bool,
        /// FIFO balanced on every seed.
        fifo_balances: bool,
        /// The smallest and largest sense→act latency at the fall over the seeds where FIFO
        /// fell, ms (`None`: it never fell).
        fifo_latency_at_fall_ms: Option<(f64, f64)>,
        /// FIFO with the shortest lifespan balanced on every seed.
        lifespan_balances: bool,
        /// That lifespan, ms.
        lifespan_ms: f64,
    },
    /// ex5: what kept the pole up on every seed, and reliable delivery's latency.
    Ex5 {
        /// Best effort at the low loss balanced on every seed.
        low_loss_balances: bool,
        /// Best effort at the high loss (the zero-order hold) balanced on every seed.
        high_loss_balances: bool,
        /// At the high loss, with the deadline: `hold`, `zero`, and reliable delivery,
        /// each true when it balanced on every seed.
        keeps_it_up: [bool; 3],
        /// Reliable delivery's mean sense→act latency (mean over the seeds), ms.
        reliable_latency_ms: f64,
        /// The lossless link's, ms.
        lossless_latency_ms: f64,
        /// The low and the high loss, for the words.
        losses: (f64, f64),
    },
    /// ex6: the smallest clamp at which the learner's node kept the pole up on every seed
    /// (`None`: at none), and whether it gave the built-in node's verdicts at every clamp.
    Ex6 {
        /// Clamp, N.
        smallest_clamp_n: Option<f64>,
        /// Same balanced/fell, at the same step, as the built-in safety node, everywhere.
        matches_builtin: bool,
    },
    /// ex7: the sensor's achieved rate in each case (the lowest over the seeds), its skipped
    /// ticks single-threaded (the most over the seeds), and the single-threaded verdict.
    Ex7 {
        /// Single-threaded, Hz.
        sensor_hz_single_threaded: f64,
        /// Single-threaded.
        skipped_ticks_single_threaded: u64,
        /// Single-threaded, on every seed.
        balances_single_threaded: bool,
        /// Two threads, one mutually exclusive group, Hz.
        sensor_hz_shared_group: f64,
        /// Two threads, the sensor in its own group, Hz.
        sensor_hz_own_group: f64,
    },
    /// ex8: the lowest noise at which a seed fell at the estimator's shipped cut-off
    /// (`None`: none on the grid), and whether the lower cut-off's first fall came at a
    /// higher noise.
    Ex8 {
        /// rad.
        fails_at_noise_rad: Option<f64>,
        /// The smoother estimate tolerated more noise.
        lower_cutoff_tolerates_more: bool,
    },
    /// ex9: the median sense→act latency across processes, without and with the offsets.
    Ex9 {
        /// ms.
        p50_latency_across_ms: f64,
        /// ms.
        p50_latency_across_offsets_ms: f64,
    },
}

/// The names a learner gives the reactions at the high loss (ex5's `keeps_it_up`), in
/// [`Outcome::Ex5`]'s `keeps_it_up` order.
pub const EX5_REACTIONS: [&str; 3] = ["hold", "zero", "reliable"];

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
        let survives = |key: &str, what: &str, measured: bool| {
            predicted_survival(&self.prediction, key, what, measured)
        };
        match *outcome {
            Outcome::Ex7 { .. } => ex7::reconcile(&self.prediction, outcome),
            Outcome::Ex8 { .. } => ex8::reconcile(&self.prediction, outcome),
            Outcome::Ex9 { .. } => ex9::reconcile(&self.prediction, outcome),
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
            Outcome::Ex4 {
                latest_balances,
                fifo_balances,
                fifo_latency_at_fall_ms,
                lifespan_balances,
                lifespan_ms,
            } => {
                let latency = match (p("fifo_latency_at_fall_ms").and_then(number), fifo_latency_at_fall_ms) {
                    (None, _) => unreadable("fifo_latency_at_fall_ms"),
                    (Some(n), None) => format!(
                        "You predicted {n} ms of sense->act latency at the FIFO fall; FIFO never fell."
                    ),
                    (Some(n), Some((lo, hi))) => format!(
                        "You predicted {n} ms of sense->act latency at the FIFO fall; it was {}.",
                        if lo == hi { format!("{lo:.0} ms") } else { format!("{lo:.0} to {hi:.0} ms over the seeds") }
                    ),
                };
                vec![
                    survives("latest_balances", "with latest", latest_balances),
                    survives("fifo_balances", "with fifo", fifo_balances),
                    latency,
                    survives(
                        "lifespan_balances",
                        &format!("with fifo and a {lifespan_ms} ms lifespan"),
                        lifespan_balances,
                    ),
                ]
            }
            Outcome::Ex6 {
                smallest_clamp_n,
                matches_builtin,
            } => {
                let measured = smallest_clamp_n.map_or_else(
                    || "your node kept it up at none of the clamps".to_string(),
                    |c| format!("with your node it was {c} N"),
                );
                let clamp = match p("smallest_clamp_n").and_then(number) {
                    Some(n) if Some(n) == smallest_clamp_n => format!(
                        "You predicted the smallest clamp that keeps the pole up is {n} N; {measured}: right."
                    ),
                    Some(n) => format!(
                        "You predicted the smallest clamp that keeps the pole up is {n} N; {measured}."
                    ),
                    None => unreadable("smallest_clamp_n"),
                };
                let node = if matches_builtin {
                    "Your node limits as the built-in safety node does: the same verdict, at the same step, at every clamp and seed."
                } else {
                    "Your node does not limit as the built-in safety node does: see the table for where they differ."
                };
                vec![clamp, node.to_string()]
            }
            Outcome::Ex5 {
                low_loss_balances,
                high_loss_balances,
                keeps_it_up,
                reliable_latency_ms,
                lossless_latency_ms,
                losses: (low, high),
            } => {
                let pct = |p: f64| format!("{}%", p * 100.0);
                let named = |set: &[bool; 3]| -> String {
                    let v: Vec<&str> = EX5_REACTIONS
                        .iter()
                        .zip(set)
                        .filter_map(|(n, &up)| up.then_some(*n))
                        .collect();
                    if v.is_empty() { "none".into() } else { v.join(", ") }
                };
                let kept = match p("keeps_it_up").and_then(toml::Value::as_array) {
                    Some(list) => {
                        let names: Option<Vec<&str>> = list.iter().map(toml::Value::as_str).collect();
                        match names {
                            Some(names) if names.iter().all(|n| EX5_REACTIONS.contains(n)) => {
                                let mut said = [false; 3];
                                for (i, r) in EX5_REACTIONS.iter().enumerate() {
                                    said[i] = names.contains(r);
                                }
                                format!(
                                    "You predicted these keep the pole up at {} loss: {}; what did: {}{}",
                                    pct(high),
                                    named(&said),
                                    named(&keeps_it_up),
                                    if said == keeps_it_up { ": right." } else { "." }
                                )
                            }
                            _ => format!(
                                "Your prediction `keeps_it_up` lists names other than {}.",
                                EX5_REACTIONS.join(", ")
                            ),
                        }
                    }
                    None => unreadable("keeps_it_up"),
                };
                let latency = match p("reliable_latency_ms").and_then(number) {
                    Some(n) => format!(
                        "You predicted {n} ms of mean sense->act latency with reliable delivery; it was {reliable_latency_ms:.1} ms (the lossless link: {lossless_latency_ms:.1} ms)."
                    ),
                    None => unreadable("reliable_latency_ms"),
                };
                vec![
                    survives(
                        "survives_low_loss",
                        &format!("at {} loss, best effort", pct(low)),
                        low_loss_balances,
                    ),
                    survives(
                        "survives_high_loss",
                        &format!("at {} loss, best effort", pct(high)),
                        high_loss_balances,
                    ),
                    kept,
                    latency,
                ]
            }
        }
    }
}

/// The sentence for a prediction key that is missing or not of the expected type.
fn unreadable(key: &str) -> String {
    format!("Your prediction `{key}` is missing or not of the expected type.")
}

/// Does a reconcile line say a prediction could not be read (missing, or not of its type)?
/// Such an exercise is not passed (`ratelab exercise` exits 1).
pub fn says_unreadable(line: &str) -> bool {
    line.starts_with("Your prediction `")
        && line.ends_with("is missing or not of the expected type.")
}

/// ex4, ex5 and ex7: the survival `prediction` gives under `key` (true or false) beside the
/// `measured` one (on every seed), `what` naming the case.
fn predicted_survival(prediction: &toml::Table, key: &str, what: &str, measured: bool) -> String {
    let measured = if measured {
        "it stayed up on every seed"
    } else {
        "it fell"
    };
    match prediction.get(key).and_then(toml::Value::as_bool) {
        Some(true) => format!("You predicted the pole stays up {what}; {measured}."),
        Some(false) => format!("You predicted the pole falls {what}; {measured}."),
        None => unreadable(key),
    }
}

/// The keys each exercise's prediction must have (besides `why`).
pub fn required_keys(exercise: &str) -> &'static [&'static str] {
    match exercise {
        "ex1" => &["fails_at_hz"],
        "ex2" => &["deep_queue_obs_drops", "deep_queue_balances"],
        "ex3" => &["matched_obs_drops"],
        "ex4" => &[
            "latest_balances",
            "fifo_balances",
            "fifo_latency_at_fall_ms",
            "lifespan_balances",
        ],
        "ex5" => &[
            "survives_low_loss",
            "survives_high_loss",
            "keeps_it_up",
            "reliable_latency_ms",
        ],
        "ex6" => &["smallest_clamp_n"],
        "ex7" => &[
            "sensor_hz_single_threaded",
            "skipped_ticks_single_threaded",
            "balances_single_threaded",
            "sensor_hz_shared_group",
            "sensor_hz_own_group",
        ],
        "ex8" => &["fails_at_noise_rad", "lower_cutoff_tolerates_more"],
        "ex9" => &["p50_latency_across_ms", "p50_latency_across_offsets_ms"],
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
    let matched = run_scripted(&base)?;
    let offset = run_scripted(&RunConfig {
        phase_offsets: offsets,
        ..base
    })?;
    Ok((matched, offset))
}

/// One run of `cfg` with the scripted balancer, no trace kept (the real-clock exercises:
/// ex3, ex9): its metrics.
fn run_scripted(cfg: &RunConfig) -> Result<Metrics, ExerciseError> {
    let opts = crate::run::RunOptions {
        keep_trace: false,
        ..Default::default()
    };
    Ok(crate::run::run(cfg, Box::new(Scripted), opts)
        .map_err(SweepError::from)?
        .metrics)
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
            offset.obs_dropped.unwrap_or(0) as f64
                <= b.max_obs_drop_fraction_with_offsets * offset.obs_published.unwrap_or(0) as f64,
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

/// One virtual run of an exercise on `graph` with `seed`, keeping its trace (the latency at
/// the fall and the steps without a command are read from it).
fn run_virtual(
    graph: GraphSpec,
    seed: u64,
    duration_s: f64,
) -> Result<crate::run::RunReport, ExerciseError> {
    let cfg = RunConfig {
        clock: ClockKind::Virtual,
        duration: duration_from_secs(duration_s)?,
        graph,
        seed,
        ..RunConfig::default()
    };
    Ok(
        crate::run::run(&cfg, Box::new(Scripted), crate::run::RunOptions::new())
            .map_err(SweepError::from)?,
    )
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
            obs_published: Some(250),
            obs_dropped: Some(40),
            mean_latency_ms: 21.5,
            ..base.clone()
        };
        let offset = Metrics {
            obs_published: Some(250),
            obs_dropped: Some(0),
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
            obs_dropped: Some(40),
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
    fn ex4_and_ex5_predictions_are_reconciled_in_words() {
        let f = file(
            "latest_balances = true\nfifo_balances = true\nfifo_latency_at_fall_ms = 100\nlifespan_balances = false\nwhy = \"w\"",
        );
        let ex4 = Outcome::Ex4 {
            latest_balances: true,
            fifo_balances: false,
            fifo_latency_at_fall_ms: Some((240.0, 340.0)),
            lifespan_balances: true,
            lifespan_ms: 20.0,
        };
        assert_eq!(
            f.reconcile(&ex4),
            [
                "You predicted the pole stays up with latest; it stayed up on every seed.",
                "You predicted the pole stays up with fifo; it fell.",
                "You predicted 100 ms of sense->act latency at the FIFO fall; it was 240 to 340 ms over the seeds.",
                "You predicted the pole falls with fifo and a 20 ms lifespan; it stayed up on every seed."
            ]
        );
        let never = Outcome::Ex4 {
            latest_balances: true,
            fifo_balances: true,
            fifo_latency_at_fall_ms: None,
            lifespan_balances: true,
            lifespan_ms: 20.0,
        };
        assert!(f.reconcile(&never)[2].ends_with("FIFO never fell."));
        let f = file(
            "survives_low_loss = true\nsurvives_high_loss = false\nkeeps_it_up = [\"reliable\", \"zero\"]\nreliable_latency_ms = 5\nwhy = \"w\"",
        );
        let ex5 = Outcome::Ex5 {
            low_loss_balances: true,
            high_loss_balances: false,
            keeps_it_up: [false, true, true],
            reliable_latency_ms: 16.5,
            lossless_latency_ms: 0.0,
            losses: (0.2, 0.8),
        };
        assert_eq!(
            f.reconcile(&ex5),
            [
                "You predicted the pole stays up at 20% loss, best effort; it stayed up on every seed.",
                "You predicted the pole falls at 80% loss, best effort; it fell.",
                "You predicted these keep the pole up at 80% loss: zero, reliable; what did: zero, reliable: right.",
                "You predicted 5 ms of mean sense->act latency with reliable delivery; it was 16.5 ms (the lossless link: 0.0 ms)."
            ]
        );
        for bad in ["[\"stop\"]", "[1]", "\"zero\""] {
            let f = file(&format!(
                "survives_low_loss = true\nsurvives_high_loss = false\nkeeps_it_up = {bad}\nreliable_latency_ms = 5\nwhy = \"w\""
            ));
            let said = &f.reconcile(&ex5)[2];
            assert!(
                said.contains("other than hold, zero, reliable")
                    || said.contains("not of the expected type"),
                "{bad}: {said}"
            );
        }
        let f = file("keeps_it_up = []\nwhy = \"w\"");
        assert!(f.reconcile(&ex5)[2].contains("up at 80% loss: none; what did"));
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
