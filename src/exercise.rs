//! The chapter's exercises as data and checks: bands (with provenance) and learner
//! predictions are TOML files in `exercises/`; measurements are in-process virtual runs.
//!
//! - ex1, the control-rate cliff: sweep the policy rate with sensor and plant at 50 Hz.
//! - ex2, the queue-depth trap: at 5 Hz, /obs depth 1 against 100.
//! - ex3, jitter and phase offsets (real clock): matched rates drop from races alone, and
//!   their latency is about 20 ms where the virtual clock gives 0; phase offsets remove the
//!   drops and fix the latency (at the sensor-to-actuator offset, 10 ms).
//! - ex4, the stale queue (QoS): a slow policy behind a deep `/obs` queue, latest-wins
//!   against FIFO delivery, then FIFO with a lifespan.
//! - ex5, the watchdog (QoS): the safety graph's `/cmd` across a lossy link, best effort
//!   against a deadline with `hold` or `zero`, and reliable delivery.
//! - ex6, write your own node: the learner's Python safety limiter in the safety graph's
//!   place, over a ladder of clamps, beside the built-in safety node: the smallest clamp
//!   that still balances, and whether the learner's node limits as the built-in one does.
//! - ex7, the slow callback ([`ex7`]): a 30 ms policy callback beside the sensor on one
//!   executor, single-threaded, on two threads in one callback group, and in two groups.
//! - ex8, the noisy sensor ([`ex8`]): the estimator graph with its sensor's angle noise
//!   raised, at the estimator's cut-off and a lower one: where the pole first falls.
//! - ex9, the crossing ([`ex9`], real clock, real processes): the chapter's graph split
//!   across two processes, without and with phase offsets: what a crossing hop costs.

mod ex7;
mod ex8;
mod ex9;

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

/// ex6's settings: write your own node (a Python safety limiter).
#[derive(Clone, Debug, Deserialize)]
pub struct Ex6Bands {
    /// The graph (the safety graph), relative to the bands file's folder.
    pub graph: String,
    /// Its safety node, which the learner's Python node replaces.
    pub node: String,
    /// The learner's script, relative to the bands file's folder.
    pub script: String,
    /// A correct limiter, relative to the bands file's folder: the measurement checks run
    /// it in the learner's place, so that they test the runtime, not the learner.
    pub reference_script: String,
    /// Seeds.
    pub seeds: Vec<u64>,
    /// Run length, s.
    pub duration_s: f64,
    /// The clamps tried (`max_force_n`), N, largest first.
    pub clamps_n: Vec<f64>,
    /// The smallest clamp of `clamps_n` at which the built-in safety node keeps the pole up
    /// on every seed, N.
    pub smallest_balancing_clamp_n: f64,
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

/// One ex6 run: a clamp and a seed, with the built-in safety node or the Python one.
#[derive(Clone, Debug)]
pub struct Ex6Run {
    /// The clamp (`max_force_n`), N.
    pub clamp_n: f64,
    /// The seed.
    pub seed: u64,
    /// The Python node ran (else the built-in safety node).
    pub python: bool,
    /// What the run measured.
    pub metrics: Metrics,
}

/// ex6's graph with node `b.node` clamping at `clamp_n`: the built-in safety node, or, with
/// `script`, a Python node running it with `params = { max_force_n = clamp_n }`.
fn ex6_graph(
    b: &Ex6Bands,
    graph: &GraphSpec,
    clamp_n: f64,
    script: Option<&Path>,
) -> Result<GraphSpec, ExerciseError> {
    let mut g = graph.clone();
    let node = g
        .nodes
        .iter_mut()
        .find(|n| n.name == b.node)
        .ok_or_else(|| ExerciseError::NoNode(b.node.clone()))?;
    node.params
        .insert("max_force_n".into(), toml::Value::Float(clamp_n));
    if let Some(script) = script {
        let absolute = std::path::absolute(script).unwrap_or_else(|_| script.to_path_buf());
        node.kind = crate::graph::registry::kind("python").expect("a built-in kind");
        node.python = Some(crate::graph::kind::PythonCode {
            script: absolute.to_string_lossy().into_owned(),
            class: None,
        });
    }
    Ok(g)
}

/// ex6's measurements: every clamp on every seed, the built-in safety node and the Python
/// node `script` in its place (clamp order, seed fastest, built-in first). The Python
/// runs go one at a time (they share the interpreter).
///
/// # Errors
/// [`ExerciseError`] when the graph has no such node, or a run cannot start (the script
/// cannot be loaded: its one-line reason).
pub fn measure_ex6(
    b: &Ex6Bands,
    graph: &GraphSpec,
    script: &Path,
) -> Result<Vec<Ex6Run>, ExerciseError> {
    let mut jobs = Vec::new();
    for &clamp_n in &b.clamps_n {
        for python in [false, true] {
            let g = ex6_graph(b, graph, clamp_n, python.then_some(script))?;
            for &seed in &b.seeds {
                jobs.push((clamp_n, seed, python, g.clone()));
            }
        }
    }
    let run = |(clamp_n, seed, python, g): &(f64, u64, bool, GraphSpec)| {
        Ok(Ex6Run {
            clamp_n: *clamp_n,
            seed: *seed,
            python: *python,
            metrics: run_virtual(g.clone(), *seed, b.duration_s)?.metrics,
        })
    };
    let (builtin, python): (Vec<_>, Vec<_>) = jobs.into_iter().partition(|j| !j.2);
    let mut runs: Vec<Ex6Run> = run_pool(&builtin, threads(), run)
        .into_iter()
        .collect::<Result<_, ExerciseError>>()?;
    for j in &python {
        runs.push(run(j)?);
    }
    Ok(runs)
}

/// The smallest clamp at which every run of `python` (or the built-in node) balanced.
fn ex6_smallest(runs: &[Ex6Run], python: bool) -> Option<f64> {
    let mut clamps: Vec<f64> = runs.iter().map(|r| r.clamp_n).collect();
    clamps.sort_by(f64::total_cmp);
    clamps.dedup();
    clamps.into_iter().find(|&c| {
        let rs: Vec<&Ex6Run> = runs
            .iter()
            .filter(|r| r.python == python && r.clamp_n == c)
            .collect();
        !rs.is_empty() && rs.iter().all(|r| r.metrics.balanced)
    })
}

/// The (clamp, seed) pairs where the Python node's verdict or fall differs from the
/// built-in node's.
pub fn ex6_differences(runs: &[Ex6Run]) -> Vec<(f64, u64)> {
    runs.iter()
        .filter(|p| p.python)
        .filter(|p| {
            !runs.iter().any(|b| {
                !b.python
                    && b.clamp_n == p.clamp_n
                    && b.seed == p.seed
                    && b.metrics.balanced == p.metrics.balanced
                    && b.metrics.fell_at_s == p.metrics.fell_at_s
            })
        })
        .map(|p| (p.clamp_n, p.seed))
        .collect()
}

/// ex6's outcome in the terms of its prediction.
pub fn outcome_ex6(runs: &[Ex6Run]) -> Outcome {
    Outcome::Ex6 {
        smallest_clamp_n: ex6_smallest(runs, true),
        matches_builtin: ex6_differences(runs).is_empty(),
    }
}

/// ex6's checks: the built-in safety node's smallest balancing clamp is the bands', and the
/// Python node (the reference limiter in the tests, the learner's in the exercise) limits
/// as it does.
pub fn check_ex6(b: &Ex6Bands, runs: &[Ex6Run]) -> Vec<Check> {
    let builtin = ex6_smallest(runs, false);
    let above = b
        .clamps_n
        .iter()
        .copied()
        .filter(|&c| c > b.smallest_balancing_clamp_n)
        .all(|c| {
            runs.iter()
                .filter(|r| !r.python && r.clamp_n == c)
                .all(|r| r.metrics.balanced)
        });
    vec![
        check(
            format!(
                "the built-in safety node keeps the pole up on every seed down to {} N, not below",
                b.smallest_balancing_clamp_n
            ),
            builtin == Some(b.smallest_balancing_clamp_n) && above,
        ),
        check(
            "the Python node gives the built-in node's verdict, at the same step, at every clamp and seed",
            runs.iter().any(|r| r.python) && ex6_differences(runs).is_empty(),
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
