//! The chapter's exercises, as a registry: each exercise is one file (`exN.rs`) holding its
//! bands, what it measures, its checks, its outcome in the terms of the learner's
//! prediction, how that is said and whether the prediction held ([`Said`]), and what it
//! prints; [`EXERCISES`] lists them, in order.
//! A new exercise is its file plus one line there (and its TOML in `exercises/`).
//!
//! A crate of its own (`ratelab-exercises`, above the drivers and the graph across
//! processes): the facade does not hold it, so a change to an exercise rebuilds only this
//! crate and the lab. The crate root holds what they share: reading the learner's file and `bands.toml`
//! ([`ExerciseFile`], [`Bands`]), the [`Exercise`] trait, the [`Context`] an exercise runs
//! in (where it prints, its progress, what did not pass), [`run`] (one exercise from
//! prediction to reconcile, as `ratelab exercise` runs it) and the runs and table cells the
//! exercises share.
//!
//! - [`ex1`], the control-rate cliff: sweep the policy rate with sensor and plant at 50 Hz.
//! - [`ex2`], the queue-depth trap: at 5 Hz, /obs depth 1 against 100.
//! - [`ex3`], jitter and phase offsets (real clock): matched rates drop from races alone, and
//!   their latency is about 20 ms where the virtual clock gives 0; phase offsets remove the
//!   drops and fix the latency (at the sensor-to-actuator offset, 10 ms).
//! - [`ex4`], the stale queue (QoS): a slow policy behind a deep `/obs` queue, latest-wins
//!   against FIFO delivery, then FIFO with a lifespan.
//! - [`ex5`], the watchdog (QoS): the safety graph's `/cmd` across a lossy link, best effort
//!   against a deadline with `hold` or `zero`, and reliable delivery.
//! - [`ex6`], write your own node: the learner's Python safety limiter in the safety graph's
//!   place, over a ladder of clamps, beside the built-in safety node: the smallest clamp
//!   that still balances, and whether the learner's node limits as the built-in one does.
//! - [`ex7`], the slow callback: a 30 ms policy callback beside the sensor on one
//!   executor, single-threaded, on two threads in one callback group, and in two groups.
//! - [`ex8`], the noisy sensor: the estimator graph with its sensor's angle noise
//!   raised, at the estimator's cut-off and a lower one: where the pole first falls.
//! - [`ex9`], the crossing (real clock, real processes): the chapter's graph split
//!   across two processes, without and with phase offsets: what a crossing hop costs.
//! - [`ex10`], the held force: the policy of a balanced pole killed, its lease set: how
//!   long the pole stays up on the force the actuator goes on holding.
//! - [`ex11`], your own brain: the learner's Python brain and the scripted balancer, each
//!   slowed down until the pole falls: whose rate cliff is lower.
//! - [`ex12`], the restart (real clock, real processes): the policy's process killed and
//!   started again: the readings lost across its rejoin, and the held force's age.
//! - [`ex13`], what ROS 2 sees: the chapter's graph offered with `--ros2`, its policy at
//!   40 Hz: the node list, the topics' ROS 2 types, and how often `/clock` ticks.
//! - [`spec`], an exercise's run as data ([`ExerciseSpec`]): what the command line's flags
//!   and the Python package's keywords fill in.
//! - [`ex14`], incompatible QoS: four requested/offered pairs on the chapter's `/action`,
//!   which ROS 2 connects; and a node joining late under each durability: what it gets.
#![warn(missing_docs)]

/// Print one line of an exercise's report through its [`Context`]: `say!(cx, "…", args)`,
/// or `say!(cx)` for an empty line.
macro_rules! say {
    ($cx:expr) => {
        $cx.say("")
    };
    ($cx:expr, $($arg:tt)*) => {
        $cx.say(&format!($($arg)*))
    };
}

pub mod ex1;
pub mod ex10;
pub mod ex11;
pub mod ex12;
pub mod ex13;
pub mod ex14;
pub mod ex2;
pub mod ex3;
pub mod ex4;
pub mod ex5;
pub mod ex6;
pub mod ex7;
pub mod ex8;
pub mod ex9;
pub mod spec;

pub use ex1::{check_ex1, measure_ex1, Ex1Bands, Ex1Outcome};
pub use ex13::{check_ex13, measure_ex13, Ex13Bands, Ex13Outcome};
pub use ex2::{check_ex2, measure_ex2, Ex2Bands, Ex2Outcome};
pub use ex3::{check_ex3, fixed_latency_ms, measure_ex3, Ex3Bands, Ex3Outcome};
pub use ex4::{check_ex4, measure_ex4, outcome_ex4, Ex4Bands, Ex4Outcome, Ex4Run};
pub use ex5::EX5_REACTIONS;
pub use ex5::{check_ex5, measure_ex5, outcome_ex5, Ex5Bands, Ex5Case, Ex5Outcome, Ex5Run};
pub use ex6::{check_ex6, ex6_differences, measure_ex6, outcome_ex6, Ex6Bands, Ex6Outcome, Ex6Run};
pub use ex7::{check_ex7, measure_ex7, outcome_ex7, Ex7Bands, Ex7Case, Ex7Outcome, Ex7Run};
pub use ex8::{check_ex8, first_fall_rad, measure_ex8, outcome_ex8, Ex8Bands, Ex8Outcome, Ex8Run};
pub use ex9::{check_ex9, measure_ex9, outcome_ex9, Ex9Bands, Ex9Case, Ex9Outcome, Ex9Run};
pub use spec::ExerciseSpec;

use ratelab_core::metrics::Metrics;
use ratelab_drivers::sweep::SweepError;
use ratelab_runtime::config::{duration_from_secs, ClockKind, RunConfig};
use ratelab_runtime::graph::GraphSpec;
use ratelab_runtime::policy::{Policy, Scripted};
use ratelab_runtime::scheduler::StopFlag;
// One thread per core, as a sweep runs (`ratelab sweep`).
use ratelab_drivers::sweep_spec::threads;
use serde::de::DeserializeOwned;
use serde::Deserialize;
use std::path::{Path, PathBuf};

/// Every exercise, in the order the chapter gives them. A new exercise adds its line here.
pub const EXERCISES: &[&dyn Exercise] = &[
    &ex1::Ex1,
    &ex2::Ex2,
    &ex3::Ex3,
    &ex4::Ex4,
    &ex5::Ex5,
    &ex6::Ex6,
    &ex7::Ex7,
    &ex8::Ex8,
    &ex9::Ex9,
    &ex10::Ex10,
    &ex11::Ex11,
    &ex12::Ex12,
    &ex13::Ex13,
    &ex14::Ex14,
];

/// One exercise: the learner predicts, ratelab measures, the two are reconciled.
///
/// An implementation is a unit struct in its own file, listed in [`EXERCISES`]; its
/// settings are the `[exN]` table of `bands.toml` (a [`Section`]).
pub trait Exercise: Sync {
    /// Its name on the command line: `ex4`.
    fn id(&self) -> &'static str;
    /// What it is about, in a few words: `the stale queue`.
    fn title(&self) -> &'static str;
    /// The learner's file in the exercises folder: `ex4_stale_queue.toml`.
    fn file(&self) -> &'static str;
    /// The keys its prediction must have, besides `why`.
    fn required_keys(&self) -> &'static [&'static str];
    /// The graph it runs on when the command line names none, relative to the bands'
    /// folder (`None`: the chapter's).
    ///
    /// # Errors
    /// [`ExerciseError`] when its bands cannot be read.
    fn default_graph(&self, bands: &Bands) -> Result<Option<String>, ExerciseError> {
        let _ = bands;
        Ok(None)
    }
    /// Measure, then print the table, the reconcile, the checks and the explanation
    /// through `cx`.
    ///
    /// # Errors
    /// [`ExerciseError`] when it cannot run (bad bands, a run that cannot start).
    fn run(&self, cx: &mut Context<'_>) -> Result<(), ExerciseError>;
}

/// An exercise's table in `bands.toml`: its settings and the bands its checks assert.
pub trait Section: DeserializeOwned {
    /// The table's name, the exercise's id: `ex4`.
    const NAME: &'static str;
}

/// The exercise named `id` (`ex4`), if registered.
pub fn find(id: &str) -> Option<&'static dyn Exercise> {
    EXERCISES.iter().copied().find(|e| e.id() == id)
}

/// The registered exercises' ids, in order: `ex1, ex2, …`.
pub fn ids() -> Vec<&'static str> {
    EXERCISES.iter().map(|e| e.id()).collect()
}

/// The registered exercises for a command line's help: `ex1 (the rate cliff), ex2 (…), …`.
pub fn menu() -> String {
    EXERCISES
        .iter()
        .map(|e| format!("{} ({})", e.id(), e.title()))
        .collect::<Vec<_>>()
        .join(", ")
}

/// Errors reading exercise files, or running an exercise.
#[derive(Debug, thiserror::Error)]
pub enum ExerciseError {
    /// The file cannot be read: missing, not a regular file, too large, unreadable
    /// ([`ratelab_core::input::read_regular_file`]'s rules).
    #[error(transparent)]
    Input(#[from] ratelab_core::input::InputError),
    /// The file is not valid TOML of the expected shape.
    #[error("{path}: {detail}")]
    Parse {
        /// The file.
        path: String,
        /// The parser's complaint (first line).
        detail: String,
    },
    /// `bands.toml` could not be read or lacks what the exercise needs.
    #[error("reading the bands: {0}")]
    Bands(Box<ExerciseError>),
    /// No exercise has this name.
    #[error("unknown exercise '{0}' (expected {list})", list = expected())]
    Unknown(String),
    /// The learner's file has no prediction yet, or lacks part of it (`missing`: a key, or
    /// a `why` that says something).
    #[error("{}", no_prediction(path, keys, missing, *none))]
    NoPrediction {
        /// The learner's file.
        path: String,
        /// The keys it needs, comma-separated.
        keys: String,
        /// Those it lacks, `why` among them when it is missing or blank.
        missing: Vec<String>,
        /// It lacks all of them: the prediction is not begun.
        none: bool,
    },
    /// A prediction given in place of the learner's file's (Python's `prediction=`) that
    /// lacks a key the exercise asks for, or holds one it does not.
    #[error("prediction: {0}")]
    GivenPrediction(String),
    /// What the learner must do first, in one line (ex6's untouched template).
    #[error("{0}")]
    NotReady(String),
    /// A run failed.
    #[error(transparent)]
    Sweep(#[from] SweepError),
    /// A setting in the bands is invalid.
    #[error("bands: {0}")]
    Config(#[from] ratelab_runtime::config::ConfigError),
    /// A QoS or rate the bands set does not fit the graph.
    #[error("bands: {0}")]
    Setting(#[from] ratelab_runtime::graph::spec::OverrideError),
    /// The graph lacks a node the bands name.
    #[error("bands: the graph has no node '{0}'")]
    NoNode(String),
    /// A launch across processes failed.
    #[error("launch: {0}")]
    Launch(String),
    /// Stopped (Ctrl-C) before its runs ended: nothing is graded.
    #[error("interrupted before its runs ended: nothing graded")]
    Interrupted,
}

/// [`ExerciseError::Interrupted`] once `stop` (Ctrl-C) is set: asked before and after each
/// run, so no run starts after it and a run it cut short is never graded. Each run is given
/// its own flag made from it ([`StopFlag::child`]), so what a run sets itself (a fall under
/// the real clock) is never taken for Ctrl-C.
///
/// # Errors
/// [`ExerciseError::Interrupted`].
pub fn interrupted(stop: &StopFlag) -> Result<(), ExerciseError> {
    if stop.is_stopped() {
        Err(ExerciseError::Interrupted)
    } else {
        Ok(())
    }
}

/// `ex1, ex2, …, ex13 or ex14`.
fn expected() -> String {
    match ids().split_last() {
        Some((last, rest)) if !rest.is_empty() => format!("{} or {last}", rest.join(", ")),
        Some((last, _)) => (*last).to_string(),
        None => "none".to_string(),
    }
}

/// The file's text, bounded: exercise files and bands are a few KiB.
const MAX_FILE_BYTES: u64 = 1 << 20;

fn read_text(path: &Path) -> Result<String, ExerciseError> {
    let bytes = ratelab_core::input::read_regular_file(path, MAX_FILE_BYTES)?;
    ratelab_core::input::utf8_text(bytes).map_err(|e| ExerciseError::Parse {
        path: path.display().to_string(),
        detail: e.to_string(),
    })
}

/// `e` in one line: its first (the TOML parser's "TOML parse error at line L, column C"), then
/// the lines that give the reason ("invalid string; expected `\"`, `'`"), without those
/// that quote the file (`22 | x = = 1`, `|     ^`).
fn parse_error(path: &str, e: &impl std::fmt::Display) -> ExerciseError {
    let text = e.to_string();
    let mut lines = text.lines().map(str::trim).filter(|l| !l.is_empty());
    let first = lines.next().unwrap_or("invalid TOML");
    let quotes = |l: &str| {
        l.trim_start_matches(|c: char| c.is_ascii_digit())
            .trim_start()
            .starts_with('|')
    };
    let reason: Vec<&str> = lines.filter(|l| !quotes(l)).collect();
    let detail = if reason.is_empty() {
        first.to_string()
    } else {
        format!("{first}: {}", reason.join("; "))
    };
    ExerciseError::Parse {
        path: path.to_string(),
        detail: ratelab_core::text::printable(&detail).into_owned(),
    }
}

fn read_toml<T: for<'de> Deserialize<'de>>(path: &Path) -> Result<T, ExerciseError> {
    let text = read_text(path)?;
    toml::from_str(&text).map_err(|e| parse_error(&path.display().to_string(), &e))
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

/// `exercises/bands.toml`: its provenance, and one table per exercise, read when the
/// exercise asks for it ([`Bands::of`]).
#[derive(Clone, Debug)]
pub struct Bands {
    /// Provenance.
    pub provenance: Provenance,
    /// The file, for errors.
    path: String,
    /// Every table.
    tables: toml::Table,
}

impl Bands {
    /// Exercise `S::NAME`'s table.
    ///
    /// # Errors
    /// [`ExerciseError::Parse`] naming the table when it is missing or not of its shape.
    pub fn of<S: Section>(&self) -> Result<S, ExerciseError> {
        let table = self
            .tables
            .get(S::NAME)
            .ok_or_else(|| ExerciseError::Parse {
                path: self.path.clone(),
                detail: format!("no [{}] table", S::NAME),
            })?;
        if let Some(key) = empty_list(table, "") {
            return Err(ExerciseError::Parse {
                path: format!("{} [{}]", self.path, S::NAME),
                detail: format!(
                    "`{key}` is an empty list: it would run nothing, and every check over it would pass without a run (give at least one value)"
                ),
            });
        }
        table
            .clone()
            .try_into()
            .map_err(|e| parse_error(&format!("{} [{}]", self.path, S::NAME), &e))
    }
}

/// The dotted key of the first empty list in `v` (a table's, at any depth), with `prefix`
/// before it: every list in the bands drives runs or checks (seeds, rates, depths), and an
/// empty one makes "on every seed" true of no seed.
fn empty_list(v: &toml::Value, prefix: &str) -> Option<String> {
    match v {
        toml::Value::Array(a) if a.is_empty() => Some(prefix.to_string()),
        toml::Value::Array(a) => a.iter().find_map(|x| empty_list(x, prefix)),
        toml::Value::Table(t) => t.iter().find_map(|(k, x)| {
            let key = if prefix.is_empty() {
                k.clone()
            } else {
                format!("{prefix}.{k}")
            };
            empty_list(x, &key)
        }),
        _ => None,
    }
}

/// Read `exercises/bands.toml`.
///
/// # Errors
/// [`ExerciseError`] when unreadable or malformed.
pub fn load_bands(path: &Path) -> Result<Bands, ExerciseError> {
    let mut tables: toml::Table = read_toml(path)?;
    let provenance = tables
        .remove("provenance")
        .ok_or_else(|| ExerciseError::Parse {
            path: path.display().to_string(),
            detail: "no [provenance] table".into(),
        })?
        .try_into()
        .map_err(|e| parse_error(&format!("{} [provenance]", path.display()), &e))?;
    Ok(Bands {
        provenance,
        path: path.display().to_string(),
        tables,
    })
}

/// The graph an exercise runs on when none is given, resolved against the folder of the
/// bands file, `dir` (ex5 to ex8 name theirs); `None` for the chapter's, or for an
/// exercise not registered.
///
/// # Errors
/// [`ExerciseError::Bands`] when the bands cannot be read.
pub fn default_graph(exercise: &str, dir: &Path) -> Result<Option<PathBuf>, ExerciseError> {
    let Some(e) = find(exercise) else {
        return Ok(None);
    };
    let in_bands = |e: ExerciseError| ExerciseError::Bands(Box::new(e));
    let bands = load_bands(&dir.join("bands.toml")).map_err(in_bands)?;
    Ok(e.default_graph(&bands)
        .map_err(in_bands)?
        .map(|g| dir.join(g)))
}

/// The keys exercise `id`'s prediction must have, besides `why` (none for an unknown id).
pub fn required_keys(id: &str) -> &'static [&'static str] {
    find(id).map_or(&[], |e| e.required_keys())
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
        missing_from(required, &self.prediction).is_empty()
    }

    /// The prediction as `key = value` text, for display beside the outcome.
    pub fn prediction_text(&self) -> String {
        self.prediction
            .iter()
            .map(|(k, v)| format!("{} = {v}", ratelab_core::text::printable(k)))
            .collect::<Vec<_>>()
            .join("\n")
    }

    /// The prediction beside the outcome, one sentence per predicted key, in words, each
    /// graded: "You predicted the pole first fails at 10 Hz; it first fell at 5 Hz." (missed),
    /// "…; it first fell at 5 Hz: right.". A key given in another type is said so
    /// ([`Verdict::Unreadable`]); one left out is too, though [`run_report`] refuses such a
    /// prediction before any run ([`ExerciseError::NoPrediction`]).
    pub fn reconcile(&self, outcome: &impl Reconcile) -> Vec<Said> {
        outcome.reconcile(&self.prediction)
    }
}

/// What an exercise measured, in the terms of its prediction's keys: each exercise's
/// outcome type says itself beside a prediction, and grades it.
pub trait Reconcile {
    /// One graded sentence per key of `prediction` the exercise asks for, in the order of
    /// its file.
    fn reconcile(&self, prediction: &toml::Table) -> Vec<Said>;
}

/// How a prediction fared beside the outcome.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Verdict {
    /// It held: the same value (a yes or no, a name, a value picked from the exercise's own
    /// list, an exact count), or an amount within the tolerance its sentence names on a miss
    /// ([`NEAR`] unless the exercise says otherwise).
    Right,
    /// It did not: the exercise is not passed (`ratelab exercise` exits 1).
    Missed,
    /// It could not be read (missing, or not of its type): not passed either.
    Unreadable,
    /// Not graded: the outcome leaves the key moot (a latency at a fall that never came).
    Open,
}

impl Verdict {
    /// Does it keep the exercise from passing (missed, or unreadable)?
    pub fn fails(self) -> bool {
        matches!(self, Verdict::Missed | Verdict::Unreadable)
    }

    /// Its name, as Python's `ratelab.Prediction.verdict` gives it: `right`, `missed`,
    /// `unreadable` or `open`.
    pub fn name(self) -> &'static str {
        match self {
            Verdict::Right => "right",
            Verdict::Missed => "missed",
            Verdict::Unreadable => "unreadable",
            Verdict::Open => "open",
        }
    }
}

/// One predicted key beside the outcome: the sentence `ratelab exercise` prints, and its
/// verdict.
#[derive(Clone, Debug, PartialEq)]
pub struct Said {
    /// The prediction's key: `fails_at_hz`.
    pub key: String,
    /// The sentence, the prediction beside the outcome: "You predicted the pole first fails
    /// at 10 Hz; it first fell at 5 Hz."
    pub line: String,
    /// Whether the prediction held.
    pub verdict: Verdict,
}

/// How far a predicted amount (a latency, a rate, a duration, a count of many) may lie from
/// the measured one and still be right, as a fraction of the measured: a fifth. A value
/// picked from the exercise's own list (a rate of the sweep, a clamp), a yes or no, a name
/// or an exact count must be the same.
pub const NEAR: f64 = 0.2;

/// Is the predicted amount within [`NEAR`] of the measured one (or within `floor`, for small
/// counts)?
fn near(predicted: f64, measured: f64, floor: f64) -> bool {
    (predicted - measured).abs() <= (NEAR * measured.abs()).max(floor)
}

/// What a sentence says of an amount more than [`NEAR`] off: `: more than 20% off`.
fn more_than_near() -> String {
    format!(": more than {:.0}% off", NEAR * 100.0)
}

/// Is the predicted value the measured one (a value of the exercise's list: a rate of the
/// sweep, a clamp, a noise of the grid), to the rounding of a decimal written in TOML?
fn same(predicted: f64, measured: f64) -> bool {
    (predicted - measured).abs() <= 1e-9 * predicted.abs().max(measured.abs()).max(1.0)
}

/// The sentence for `key`, `body` without its last period, graded: `body: right.` when
/// `right`, else `body` then `miss` (how far off counts as a miss, [`more_than_near`]; `""`
/// for values compared exactly) and a period.
fn graded(key: &str, body: &str, right: bool, miss: &str) -> Said {
    let (line, verdict) = if right {
        (format!("{body}: right."), Verdict::Right)
    } else {
        (format!("{body}{miss}."), Verdict::Missed)
    };
    Said {
        key: key.to_string(),
        line,
        verdict,
    }
}

/// The sentence for `key` when the outcome leaves it moot: `line`, not graded.
fn open(key: &str, line: String) -> Said {
    Said {
        key: key.to_string(),
        line,
        verdict: Verdict::Open,
    }
}

/// A prediction value as a number (TOML integer or float). TOML's `inf` and `nan` are not
/// a prediction (infinity would be "the same" as any rate, [`same`]): `None`, as a value of
/// the wrong type is.
fn number(v: &toml::Value) -> Option<f64> {
    (v.as_float().or_else(|| v.as_integer().map(|i| i as f64))).filter(|x| x.is_finite())
}

/// The sentence for a prediction key that is not of the type the exercise reads (one left
/// out is refused before the runs, [`ExerciseError::NoPrediction`]).
fn unreadable(key: &str) -> Said {
    Said {
        key: key.to_string(),
        line: format!(
            "Your prediction `{key}` is not of the type this exercise reads (the comment above it in the file gives an example)."
        ),
        verdict: Verdict::Unreadable,
    }
}

/// ex4, ex5 and ex7: the survival `prediction` gives under `key` (true or false) beside the
/// `measured` one (on every seed), `what` naming the case; right when they agree.
fn predicted_survival(prediction: &toml::Table, key: &str, what: &str, measured: bool) -> Said {
    let said = if measured {
        "it stayed up on every seed"
    } else {
        "it fell"
    };
    match prediction.get(key).and_then(toml::Value::as_bool) {
        Some(true) => graded(
            key,
            &format!("You predicted the pole stays up {what}; {said}"),
            measured,
            "",
        ),
        Some(false) => graded(
            key,
            &format!("You predicted the pole falls {what}; {said}"),
            !measured,
            "",
        ),
        None => unreadable(key),
    }
}

/// The line after the sentences: how many of the graded predictions were right, and the
/// keys of those that missed or could not be read.
fn tally(said: &[Said]) -> String {
    let keys = |v: Verdict| -> Vec<&str> {
        said.iter()
            .filter(|s| s.verdict == v)
            .map(|s| s.key.as_str())
            .collect()
    };
    let graded = said.iter().filter(|s| s.verdict != Verdict::Open).count();
    let mut line = format!(
        "Your prediction: {} of {graded} right",
        keys(Verdict::Right).len()
    );
    for (v, what) in [
        (Verdict::Missed, "missed"),
        (Verdict::Unreadable, "not read"),
    ] {
        let k = keys(v);
        if !k.is_empty() {
            line.push_str(&format!("; {what}: {}", k.join(", ")));
        }
    }
    line.push('.');
    line
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

/// Shows that a measurement is under way (the measurements take from seconds to a minute):
/// `ratelab exercise` draws a spinner with the elapsed time on a terminal.
pub trait Progress {
    /// A measurement starts: `measuring ex4`.
    fn begin(&self, what: &str);
    /// It ended.
    fn end(&self);
}

/// No progress shown.
impl Progress for () {
    fn begin(&self, _: &str) {}
    fn end(&self) {}
}

/// Where an exercise runs: its inputs, where its report goes, and what did not pass.
pub struct Context<'a> {
    /// The exercise's id.
    pub id: &'static str,
    /// The exercises folder (the bands' and the learner's files).
    pub dir: &'a Path,
    /// The graph it runs on.
    pub graph: &'a GraphSpec,
    /// The file `graph` was read from (`None`: the chapter's); ex9's processes load it too.
    pub graph_path: Option<&'a Path>,
    /// This program, for an exercise that launches processes (ex9).
    pub exe: &'a ratelab_distributed::launcher::Program,
    /// The learner's file.
    pub file: &'a ExerciseFile,
    /// Set on Ctrl-C: no run starts after it, the run in progress ends (a cliff search,
    /// ex11, finishes the seed it is on), and the exercise returns
    /// [`ExerciseError::Interrupted`].
    pub stop: &'a StopFlag,
    /// `bands.toml`.
    pub bands: &'a Bands,
    out: &'a mut dyn FnMut(&str),
    progress: &'a dyn Progress,
    /// What it found so far: every check and graded reconcile sentence, and what did not
    /// pass.
    report: Report,
}

/// What an exercise found: its checks, the sentences setting the prediction beside the
/// outcome (each graded), and how many checks failed and predictions missed.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Report {
    /// Every check, in the order printed (`[ok]` / `[!!]`).
    pub checks: Vec<Check>,
    /// The prediction beside the outcome, one graded sentence per predicted key.
    pub reconcile: Vec<Said>,
    /// Checks that failed.
    pub checks_failed: usize,
    /// Predictions that missed or could not be read ([`Verdict::fails`]).
    pub predictions_missed: usize,
    /// Both together (0: passed; `ratelab exercise` exits 1 otherwise).
    pub not_passed: usize,
}

impl Context<'_> {
    /// Print one line of the report.
    pub fn say(&mut self, line: &str) {
        (self.out)(line);
    }

    /// This exercise's table of the bands.
    ///
    /// # Errors
    /// [`ExerciseError::Bands`] when it is missing or not of its shape.
    pub fn bands<S: Section>(&self) -> Result<S, ExerciseError> {
        self.bands
            .of()
            .map_err(|e| ExerciseError::Bands(Box::new(e)))
    }

    /// Run `f` (a measurement, given the exercise's stop flag) with its progress shown.
    pub fn measure<T>(&self, f: impl FnOnce(&StopFlag) -> T) -> T {
        self.progress.begin(&format!("measuring {}", self.id));
        let out = f(self.stop);
        self.progress.end();
        out
    }

    /// Print the checks, `[ok]` or `[!!]` each, and count those that failed.
    pub fn checks(&mut self, checks: &[Check]) {
        for c in checks {
            say!(
                self,
                "  [{}] {}",
                if c.passed { "ok" } else { "!!" },
                c.name
            );
            if !c.passed {
                self.report.checks_failed += 1;
                self.report.not_passed += 1;
            }
            self.report.checks.push(c.clone());
        }
    }

    /// Print the learner's prediction beside `outcome`, a graded sentence per key, then how
    /// many were right; count those that missed or could not be read.
    pub fn reconcile(&mut self, outcome: &impl Reconcile) {
        say!(self);
        let said = self.file.reconcile(outcome);
        for s in &said {
            self.say(&s.line);
        }
        self.say(&tally(&said));
        let missed = said.iter().filter(|s| s.verdict.fails()).count();
        self.report.predictions_missed += missed;
        self.report.not_passed += missed;
        self.report.reconcile.extend(said);
    }

    /// Print `text` wrapped at 96 columns.
    pub fn paragraph(&mut self, text: &str) {
        let mut line = String::new();
        for word in text.split_whitespace() {
            if !line.is_empty() && line.len() + 1 + word.len() > 96 {
                self.say(&line);
                line.clear();
            }
            if !line.is_empty() {
                line.push(' ');
            }
            line.push_str(word);
        }
        if !line.is_empty() {
            self.say(&line);
        }
    }
}

/// Where `ratelab exercise` runs one: the exercises folder, the graph (and its file), and
/// this program (ex9 launches it).
#[derive(Clone, Copy, Debug)]
pub struct Setup<'a> {
    /// The exercises folder.
    pub dir: &'a Path,
    /// The graph.
    pub graph: &'a GraphSpec,
    /// Its file (`None`: the chapter's).
    pub graph_path: Option<&'a Path>,
    /// This program.
    pub exe: &'a ratelab_distributed::launcher::Program,
    /// The prediction, in place of the one in the learner's file (`None`: the file's): the
    /// keys the exercise's file asks for, and `why`.
    pub prediction: Option<&'a toml::Table>,
    /// Set on Ctrl-C: no run starts after it, the run in progress ends (a cliff search,
    /// ex11, finishes the seed it is on), and the exercise returns
    /// [`ExerciseError::Interrupted`].
    pub stop: &'a StopFlag,
}

/// Run exercise `which` as `ratelab exercise` does: refuse it without a prediction, print
/// its heading and the prediction, then let it measure and report, every line through
/// `out`.
///
/// Returns how many checks failed and predictions missed or could not be read (0: passed).
///
/// # Errors
/// [`ExerciseError`] for what kept it from running: an unknown exercise, no prediction,
/// unreadable files or bands, a run that cannot start.
pub fn run(
    which: &str,
    setup: Setup<'_>,
    out: &mut dyn FnMut(&str),
    progress: &dyn Progress,
) -> Result<usize, ExerciseError> {
    run_report(which, setup, out, progress).map(|r| r.not_passed)
}

/// [`ExerciseError::NoPrediction`]'s line: the whole prediction asked for when the file has
/// none of it (`none`); else the part it lacks, by name.
fn no_prediction(path: &str, keys: &str, missing: &[String], none: bool) -> String {
    if none {
        return format!(
            "{path} has no prediction yet: fill in [prediction] ({keys} and why) first — predicting is the exercise"
        );
    }
    let named: Vec<String> = (missing.iter())
        .map(|k| {
            if k == "why" {
                "why (a sentence: what you expect and why)".to_string()
            } else {
                k.clone()
            }
        })
        .collect();
    format!(
        "{path}: [prediction] lacks {}: fill it in first — predicting is the exercise",
        ratelab_core::text::listed(named.iter().map(String::as_str))
    )
}

/// What `prediction` lacks of what an exercise asks for: each `required` key not there, then
/// `why` when it is not a string that says something. Empty: the prediction is filled in.
fn missing_from<'a>(required: &[&'a str], prediction: &toml::Table) -> Vec<&'a str> {
    let said_why =
        (prediction.get("why").and_then(toml::Value::as_str)).is_some_and(|w| !w.trim().is_empty());
    (required.iter().copied())
        .filter(|k| !prediction.contains_key(*k))
        .chain((!said_why).then_some("why"))
        .collect()
}

/// A prediction given in place of the file's: every key exercise `id` asks for (`required`)
/// and a `why` that says something, and no other key (a misspelt key would otherwise be
/// graded as left out).
///
/// # Errors
/// [`ExerciseError::GivenPrediction`] naming the first key missing or not the exercise's.
fn check_given_prediction(
    id: &str,
    required: &[&str],
    given: &toml::Table,
) -> Result<(), ExerciseError> {
    let keys = || format!("{} and why", required.join(", "));
    if let Some(k) = given
        .keys()
        .find(|k| *k != "why" && !required.contains(&k.as_str()))
    {
        return Err(ExerciseError::GivenPrediction(format!(
            "'{}' is not a key of {id}'s prediction ({})",
            ratelab_core::text::printable(k),
            keys()
        )));
    }
    let missing = missing_from(required, given);
    if !missing.is_empty() {
        return Err(ExerciseError::GivenPrediction(format!(
            "missing {} ({id} asks for {})",
            missing.join(", "),
            keys()
        )));
    }
    Ok(())
}

/// [`run`], returning what the exercise found: its checks and graded reconcile sentences as
/// well as how many did not pass (what `ratelab.exercise` in Python returns).
///
/// # Errors
/// As [`run`].
pub fn run_report(
    which: &str,
    setup: Setup<'_>,
    out: &mut dyn FnMut(&str),
    progress: &dyn Progress,
) -> Result<Report, ExerciseError> {
    let exercise = find(which).ok_or_else(|| ExerciseError::Unknown(which.to_string()))?;
    let path = setup.dir.join(exercise.file());
    let mut file = ExerciseFile::load(&path)?;
    if let Some(prediction) = setup.prediction {
        check_given_prediction(exercise.id(), exercise.required_keys(), prediction)?;
        file.prediction = prediction.clone();
    }
    let missing = missing_from(exercise.required_keys(), &file.prediction);
    if !missing.is_empty() {
        return Err(ExerciseError::NoPrediction {
            path: path.display().to_string(),
            keys: exercise.required_keys().join(", "),
            // Every key and the why.
            none: missing.len() > exercise.required_keys().len(),
            missing: missing.into_iter().map(str::to_string).collect(),
        });
    }
    let bands =
        load_bands(&setup.dir.join("bands.toml")).map_err(|e| ExerciseError::Bands(Box::new(e)))?;
    let mut cx = Context {
        id: exercise.id(),
        dir: setup.dir,
        graph: setup.graph,
        graph_path: setup.graph_path,
        exe: setup.exe,
        file: &file,
        stop: setup.stop,
        bands: &bands,
        out,
        progress,
        report: Report::default(),
    };
    say!(
        cx,
        "== {}: {} (about {} min)\n{}\n",
        exercise.id(),
        file.title,
        file.estimated_minutes,
        file.objective.trim()
    );
    say!(
        cx,
        "Your prediction:\n{}\n",
        indent(&file.prediction_text())
    );
    exercise.run(&mut cx)?;
    Ok(cx.report)
}

fn indent(s: &str) -> String {
    s.lines()
        .map(|l| format!("  {l}"))
        .collect::<Vec<_>>()
        .join("\n")
}

fn scripted() -> Result<Box<dyn Policy>, String> {
    Ok(Box::new(Scripted))
}

/// `cfg`'s graph launched across its processes with the scripted balancer (ex9, ex12): the
/// processes started with `exe`, ratelab's command line, loading the graph file at
/// `graph_path` (`None`: the chapter's, compiled in) under fresh credentials; the processes
/// in `kill_processes` killed at their times.
///
/// # Errors
/// [`ExerciseError::Launch`] when the launch fails (a process that cannot be started, a
/// port that cannot be listened on); the graph file's error when it cannot be read;
/// [`ExerciseError::Interrupted`] when `stop` ended it.
fn launch_across(
    cfg: &RunConfig,
    graph_path: Option<&Path>,
    exe: &ratelab_distributed::launcher::Program,
    kill_processes: Vec<(String, ratelab_core::time::Nanos)>,
    stop: &StopFlag,
) -> Result<ratelab_distributed::launcher::LaunchReport, ExerciseError> {
    use ratelab_distributed::launcher::{launch, LaunchOptions};
    let names: Vec<String> = cfg.graph.placement().into_iter().map(|(p, _)| p).collect();
    let launch_error = |e: ratelab_distributed::DistError| ExerciseError::Launch(e.to_string());
    let opts = LaunchOptions {
        graph_path: graph_path.map(Path::to_path_buf),
        graph_bytes: ratelab_runtime::graph::spec::graph_file_bytes(graph_path)?,
        listen: None,
        policy: "scripted".into(),
        exe: Some(exe.clone()),
        child_stderr: None,
        start_gate: None,
        listening: None,
        pace: None,
        credentials: ratelab_distributed::credentials::Credentials::generate(
            &cfg.graph.name,
            &names,
        )
        .map_err(launch_error)?,
        ros2_domain: None,
        kill_processes,
        star: false,
    };
    interrupted(stop)?;
    // Its own flag: what stops the launch from inside (a failed process) leaves the
    // exercise's runs after it alone; Ctrl-C (`stop`) reaches it.
    let report = launch(cfg, &opts, &stop.child(), &|_| {});
    // A launch Ctrl-C cut short says so in its own words: the exercise's are the ones said.
    interrupted(stop)?;
    report.map_err(launch_error)
}

/// One run of `cfg` with the scripted balancer, no trace kept (the real-clock exercises:
/// ex3, ex9): its metrics. `stop` ends it at once, as [`ExerciseError::Interrupted`].
fn run_scripted(cfg: &RunConfig, stop: &StopFlag) -> Result<Metrics, ExerciseError> {
    interrupted(stop)?;
    // The run's own flag: a fall under the real clock sets it to stop the run's threads,
    // and must not end the exercise's runs after it; Ctrl-C (`stop`) reaches it.
    let opts = ratelab_drivers::run::RunOptions {
        keep_trace: false,
        stop: stop.child(),
        ..Default::default()
    };
    let metrics = ratelab_drivers::run::run(cfg, Box::new(Scripted), opts)
        .map_err(SweepError::from)?
        .metrics;
    interrupted(stop)?;
    Ok(metrics)
}

/// One virtual run of an exercise on `graph` with `seed`, keeping its trace (the latency at
/// the fall and the steps without a command are read from it). `stop` ends it at once, as
/// [`ExerciseError::Interrupted`].
fn run_virtual(
    graph: GraphSpec,
    seed: u64,
    duration_s: f64,
    stop: &StopFlag,
) -> Result<ratelab_drivers::run::RunReport, ExerciseError> {
    let cfg = RunConfig {
        clock: ClockKind::Virtual,
        duration: duration_from_secs(duration_s)?,
        graph,
        seed,
        ..RunConfig::default()
    };
    interrupted(stop)?;
    let opts = ratelab_drivers::run::RunOptions {
        stop: stop.child(),
        ..ratelab_drivers::run::RunOptions::new()
    };
    let report =
        ratelab_drivers::run::run(&cfg, Box::new(Scripted), opts).map_err(SweepError::from)?;
    interrupted(stop)?;
    Ok(report)
}

/// A run's verdict in a table cell: `Y`, `n@0.34s` (fell at run time 0.34 s), or
/// `W@0.34s` (stopped by the watchdog).
fn verdict(m: &Metrics) -> String {
    match (m.balanced, m.fell_at_s) {
        (true, _) => "Y".into(),
        (false, Some(t)) => format!("n@{t:.2}s"),
        (false, None) if m.stopped_by_watchdog.is_some() => format!("W@{:.2}s", m.sim_time_s),
        (false, None) => "n".into(),
    }
}

/// A run's verdict in a narrow cell: `Y`, `n@0.34` (fell at run time 0.34 s), or `n`.
fn fell_cell(m: &Metrics) -> String {
    if m.balanced {
        "Y".to_string()
    } else {
        m.fell_at_s.map_or("n".into(), |t| format!("n@{t:.2}"))
    }
}

/// A table's seed columns: `seed 0  seed 1 …`.
fn seeds_header(seeds: &[u64]) -> String {
    seeds
        .iter()
        .map(|s| format!("seed {s:<2}"))
        .collect::<Vec<_>>()
        .join(" ")
}

/// A figure of the chapter's chain, or `-` for a graph without it (the exercises' graphs
/// all have it).
fn dash<T: std::fmt::Display>(x: Option<T>) -> String {
    x.map_or_else(|| "-".to_string(), |v| v.to_string())
}

#[cfg(test)]
mod tests {
    use super::*;
    use ratelab_runtime::policy::Scripted;

    #[test]
    fn every_exercise_is_registered_once_with_its_file() {
        let ids = ids();
        let mut unique = ids.clone();
        unique.sort_unstable();
        unique.dedup();
        assert_eq!(unique.len(), ids.len(), "{ids:?}");
        let dir = Path::new(concat!(env!("CARGO_MANIFEST_DIR"), "/../../exercises"));
        let bands = load_bands(&dir.join("bands.toml")).unwrap();
        for e in EXERCISES {
            assert!(e.file().starts_with(e.id()), "{}: {}", e.id(), e.file());
            assert!(dir.join(e.file()).is_file(), "{}", e.file());
            assert!(!e.required_keys().is_empty(), "{}", e.id());
            if let Some(g) = e.default_graph(&bands).unwrap() {
                assert!(dir.join(g).is_file(), "{}", e.id());
            }
        }
        assert_eq!(
            expected(),
            "ex1, ex2, ex3, ex4, ex5, ex6, ex7, ex8, ex9, ex10, ex11, ex12, ex13 or ex14"
        );
    }

    #[test]
    fn exercise_files_are_read_by_the_rules_for_files_the_user_names() {
        let dir = tempfile::tempdir().unwrap();
        let missing = load_bands(&dir.path().join("bands.toml")).unwrap_err();
        assert!(
            missing.to_string().ends_with("bands.toml: not found"),
            "{missing}"
        );
        let folder = ExerciseFile::load(dir.path()).unwrap_err();
        assert!(
            folder.to_string().contains("not a regular file"),
            "{folder}"
        );
        let big = dir.path().join("big.toml");
        std::fs::write(&big, vec![b'#'; (MAX_FILE_BYTES + 1) as usize]).unwrap();
        assert!(matches!(
            ExerciseFile::load(&big),
            Err(ExerciseError::Input(
                ratelab_core::input::InputError::TooLarge { .. }
            ))
        ));
        let binary = dir.path().join("binary.toml");
        std::fs::write(&binary, [0xff, 0xfe]).unwrap();
        assert!(ExerciseFile::load(&binary)
            .unwrap_err()
            .to_string()
            .ends_with("not UTF-8 text (byte 0xff at line 1, column 1)"));
    }

    #[test]
    fn a_missing_table_is_named() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("bands.toml");
        std::fs::write(
            &p,
            "[provenance]\nmeasured_with = \"\"\nmeasured_on = \"\"\nchapter = \"\"\nnotes = \"\"\n",
        )
        .unwrap();
        let e = load_bands(&p).unwrap().of::<Ex4Bands>().unwrap_err();
        assert!(e.to_string().ends_with("no [ex4] table"), "{e}");
        std::fs::write(&p, "x = 1\n").unwrap();
        assert!(load_bands(&p)
            .unwrap_err()
            .to_string()
            .ends_with("no [provenance] table"));
    }

    fn file(prediction: &str) -> ExerciseFile {
        toml::from_str(&format!(
            "title = \"t\"\nestimated_minutes = 1\nobjective = \"o\"\ninstructions = \"i\"\n[prediction]\n{prediction}"
        ))
        .unwrap()
    }

    #[test]
    fn ex3_checks_pass_on_the_measured_shape_and_fail_off_it() {
        let b: Ex3Bands = load_bands(Path::new(concat!(
            env!("CARGO_MANIFEST_DIR"),
            "/../../exercises/bands.toml"
        )))
        .unwrap()
        .of()
        .unwrap();
        assert_eq!(b.fixed_latency_ms(), 10.0);
        // Any run's metrics, given the figures of one real-clock pair (matched: 40 drops,
        // mean 21.5 ms; offsets 0/5/10: no drop, median 10.0 ms).
        let cfg = RunConfig {
            clock: ClockKind::Virtual,
            duration: ratelab_core::time::Nanos::from_millis(100),
            ..RunConfig::default()
        };
        let base = ratelab_drivers::run::run(
            &cfg,
            Box::new(Scripted),
            ratelab_drivers::run::RunOptions::new(),
        )
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

    /// The sentences alone.
    fn lines(said: &[Said]) -> Vec<&str> {
        said.iter().map(|s| s.line.as_str()).collect()
    }

    /// The verdicts alone.
    fn verdicts(said: &[Said]) -> Vec<Verdict> {
        said.iter().map(|s| s.verdict).collect()
    }

    #[test]
    fn ex4_and_ex5_predictions_are_reconciled_in_words() {
        use super::Verdict::{Missed, Open, Right, Unreadable};
        let f = file(
            "latest_balances = true\nfifo_balances = true\nfifo_latency_at_fall_ms = 100\nlifespan_balances = false\nwhy = \"w\"",
        );
        let ex4 = Ex4Outcome {
            latest_balances: true,
            fifo_balances: false,
            fifo_latency_at_fall_ms: Some((240.0, 340.0)),
            lifespan_balances: true,
            lifespan_ms: 20.0,
        };
        let said = f.reconcile(&ex4);
        assert_eq!(
            lines(&said),
            [
                "You predicted the pole stays up with latest; it stayed up on every seed: right.",
                "You predicted the pole stays up with fifo; it fell.",
                "You predicted 100 ms of sense->act latency at the FIFO fall; it was 240 to 340 ms over the seeds: more than 20% off.",
                "You predicted the pole falls with fifo and a 20 ms lifespan; it stayed up on every seed."
            ]
        );
        assert_eq!(verdicts(&said), [Right, Missed, Missed, Missed]);
        // Within a fifth of the range over the seeds is right; a fall that never came is not
        // graded.
        for (ms, right) in [(200.0, true), (300.0, true), (400.0, true), (180.0, false)] {
            let f = file(&format!("fifo_latency_at_fall_ms = {ms}\nwhy = \"w\""));
            assert_eq!(f.reconcile(&ex4)[2].verdict == Right, right, "{ms}");
        }
        let never = Ex4Outcome {
            latest_balances: true,
            fifo_balances: true,
            fifo_latency_at_fall_ms: None,
            lifespan_balances: true,
            lifespan_ms: 20.0,
        };
        let said = f.reconcile(&never);
        assert!(said[2].line.ends_with("FIFO never fell."));
        assert_eq!(said[2].verdict, Open);
        let f = file(
            "survives_low_loss = true\nsurvives_high_loss = false\nkeeps_it_up = [\"reliable\", \"zero\"]\nreliable_latency_ms = 5\nwhy = \"w\"",
        );
        let ex5 = Ex5Outcome {
            low_loss_balances: true,
            high_loss_balances: false,
            keeps_it_up: [false, true, true],
            reliable_latency_ms: 16.5,
            lossless_latency_ms: 0.0,
            losses: (0.2, 0.8),
        };
        let said = f.reconcile(&ex5);
        assert_eq!(
            lines(&said),
            [
                "You predicted the pole stays up at 20% loss, best effort; it stayed up on every seed: right.",
                "You predicted the pole falls at 80% loss, best effort; it fell: right.",
                "You predicted these keep the pole up at 80% loss: zero, reliable; what did: zero, reliable: right.",
                "You predicted 5 ms of mean sense->act latency with reliable delivery; it was 16.5 ms (the lossless link: 0.0 ms): more than 20% off."
            ]
        );
        assert_eq!(verdicts(&said), [Right, Right, Right, Missed]);
        for bad in ["[\"stop\"]", "[1]", "\"zero\""] {
            let f = file(&format!(
                "survives_low_loss = true\nsurvives_high_loss = false\nkeeps_it_up = {bad}\nreliable_latency_ms = 5\nwhy = \"w\""
            ));
            let said = &f.reconcile(&ex5)[2];
            assert!(
                said.line.contains("other than hold, zero, reliable")
                    || said.line.contains("not of the type this exercise reads"),
                "{bad}: {}",
                said.line
            );
            assert_eq!(said.verdict, Unreadable, "{bad}");
        }
        let f = file("keeps_it_up = []\nwhy = \"w\"");
        let said = &f.reconcile(&ex5)[2];
        assert!(said.line.contains("up at 80% loss: none; what did"));
        assert_eq!(said.verdict, Missed);
    }

    #[test]
    fn a_toml_error_is_one_line_with_its_place_and_its_reason() {
        let e = toml::from_str::<toml::Table>("[prediction]\nx = = 1\n").unwrap_err();
        let ExerciseError::Parse { detail, .. } = parse_error("f.toml", &e) else {
            panic!()
        };
        assert!(
            detail.starts_with("TOML parse error at line 2, column 5: "),
            "{detail}"
        );
        assert!(
            !detail.contains('\n') && !detail.contains('|') && !detail.contains("x = = 1"),
            "{detail}"
        );
        assert!(
            detail.len() > "TOML parse error at line 2, column 5: ".len() + 3,
            "{detail}"
        );
    }

    #[test]
    fn predictions_are_reconciled_in_words() {
        let f = file("fails_at_hz = 10\nwhy = \"w\"");
        let said = f.reconcile(&Ex1Outcome {
            fails_at_hz: Some(5.0),
        });
        assert_eq!(
            lines(&said),
            ["You predicted the pole first fails at 10 Hz; it first fell at 5 Hz."]
        );
        assert_eq!(said[0].verdict, Verdict::Missed);
        assert_eq!(said[0].key, "fails_at_hz");
        let f = file("fails_at_hz = 5.0\nwhy = \"w\"");
        let said = f.reconcile(&Ex1Outcome {
            fails_at_hz: Some(5.0),
        });
        assert!(said[0].line.ends_with(": right."));
        assert_eq!(said[0].verdict, Verdict::Right);
        // Infinity is no rate (it was "right" of any), nor is nan: unreadable, not graded.
        for bad in ["inf", "-inf", "nan"] {
            let f = file(&format!("fails_at_hz = {bad}\nwhy = \"w\""));
            let said = f.reconcile(&Ex1Outcome {
                fails_at_hz: Some(5.0),
            });
            assert_eq!(said[0].verdict, Verdict::Unreadable, "{bad}: {said:?}");
        }
        let f = file("deep_queue_obs_drops = 0\ndeep_queue_balances = true\nwhy = \"w\"");
        let said = f.reconcile(&Ex2Outcome {
            deep_queue_obs_drops: 0,
            deep_queue_balances: false,
        });
        assert_eq!(
            lines(&said),
            [
                "You predicted 0 /obs drops with the deep queue; there were 0: right.",
                "You predicted the deep queue keeps the pole up; it fell."
            ]
        );
        assert_eq!(verdicts(&said), [Verdict::Right, Verdict::Missed]);
        let f = file("matched_obs_drops = \"many\"\nwhy = \"w\"");
        let said = f.reconcile(&Ex3Outcome {
            matched_obs_drops: 7,
        });
        assert!(said[0].line.contains("not of the type this exercise reads"));
        assert_eq!(said[0].verdict, Verdict::Unreadable);
    }

    /// `prediction` (TOML) read as a table.
    fn table(prediction: &str) -> toml::Table {
        toml::from_str(prediction).unwrap()
    }

    /// Exercise `id`'s outcome `outcome` beside a prediction it bears out (`right`) and one
    /// it does not (`wrong`, every key wrong): one sentence per key the exercise asks for, in
    /// its order, graded right (ending `: right.`) or missed; and beside no prediction, every
    /// key unreadable.
    fn graded_both_ways(id: &str, outcome: &dyn Reconcile, right: &str, wrong: &str) {
        let keys = find(id).unwrap().required_keys();
        for (prediction, want) in [(right, Verdict::Right), (wrong, Verdict::Missed)] {
            let said = outcome.reconcile(&table(prediction));
            let said_keys: Vec<&str> = said.iter().map(|s| s.key.as_str()).collect();
            assert_eq!(said_keys, keys, "{id}: every key, once, in order");
            for s in &said {
                assert_eq!(s.verdict, want, "{id}: {}", s.line);
                assert_eq!(
                    s.line.ends_with(": right."),
                    want == Verdict::Right,
                    "{id}: {}",
                    s.line
                );
                assert!(s.line.starts_with("You predicted"), "{id}: {}", s.line);
            }
        }
        let said = outcome.reconcile(&toml::Table::new());
        assert_eq!(said.len(), keys.len(), "{id}");
        assert!(
            said.iter().all(|s| s.verdict == Verdict::Unreadable),
            "{id}: {said:?}"
        );
    }

    /// Every exercise grades its prediction: made-up outcomes (the bands' answers) beside a
    /// right prediction and a wrong one. The exercises' runs are measured elsewhere
    /// (tests/it/exercises.rs); this is the grading alone, for all of them.
    #[test]
    fn every_exercise_grades_its_prediction_right_or_missed() {
        graded_both_ways(
            "ex1",
            &Ex1Outcome {
                fails_at_hz: Some(5.0),
            },
            "fails_at_hz = 5",
            "fails_at_hz = 50",
        );
        graded_both_ways(
            "ex2",
            &Ex2Outcome {
                deep_queue_obs_drops: 0,
                deep_queue_balances: false,
            },
            "deep_queue_obs_drops = 0\ndeep_queue_balances = false",
            "deep_queue_obs_drops = 40\ndeep_queue_balances = true",
        );
        let ex3 = Ex3Outcome {
            matched_obs_drops: 40,
        };
        graded_both_ways(
            "ex3",
            &ex3,
            "matched_obs_drops = 100",
            "matched_obs_drops = 0",
        );
        graded_both_ways(
            "ex3",
            &ex3,
            "matched_obs_drops = 14",
            "matched_obs_drops = 121",
        );
        graded_both_ways(
            "ex4",
            &Ex4Outcome {
                latest_balances: true,
                fifo_balances: false,
                fifo_latency_at_fall_ms: Some((240.0, 340.0)),
                lifespan_balances: true,
                lifespan_ms: 20.0,
            },
            "latest_balances = true\nfifo_balances = false\nfifo_latency_at_fall_ms = 300\nlifespan_balances = true",
            "latest_balances = false\nfifo_balances = true\nfifo_latency_at_fall_ms = 100\nlifespan_balances = false",
        );
        graded_both_ways(
            "ex5",
            &Ex5Outcome {
                low_loss_balances: true,
                high_loss_balances: false,
                keeps_it_up: [false, true, true],
                reliable_latency_ms: 16.5,
                lossless_latency_ms: 0.0,
                losses: (0.2, 0.8),
            },
            "survives_low_loss = true\nsurvives_high_loss = false\nkeeps_it_up = [\"reliable\", \"zero\"]\nreliable_latency_ms = 18",
            "survives_low_loss = false\nsurvives_high_loss = true\nkeeps_it_up = [\"hold\"]\nreliable_latency_ms = 5",
        );
        graded_both_ways(
            "ex6",
            &Ex6Outcome {
                smallest_clamp_n: Some(0.75),
                matches_builtin: true,
            },
            "smallest_clamp_n = 0.75",
            "smallest_clamp_n = 2",
        );
        graded_both_ways(
            "ex7",
            &Ex7Outcome {
                sensor_hz_single_threaded: 33.3,
                skipped_ticks_single_threaded: 166,
                balances_single_threaded: true,
                sensor_hz_shared_group: 33.3,
                sensor_hz_own_group: 50.0,
            },
            "sensor_hz_single_threaded = 33\nskipped_ticks_single_threaded = 167\nbalances_single_threaded = true\nsensor_hz_shared_group = 33\nsensor_hz_own_group = 50",
            "sensor_hz_single_threaded = 50\nskipped_ticks_single_threaded = 0\nbalances_single_threaded = false\nsensor_hz_shared_group = 50\nsensor_hz_own_group = 25",
        );
        graded_both_ways(
            "ex8",
            &Ex8Outcome {
                fails_at_noise_rad: Some(0.014),
                lower_cutoff_tolerates_more: true,
            },
            "fails_at_noise_rad = 0.014\nlower_cutoff_tolerates_more = true",
            "fails_at_noise_rad = 0.03\nlower_cutoff_tolerates_more = false",
        );
        graded_both_ways(
            "ex9",
            &ex9::Ex9Outcome {
                p50_latency_across_ms: 40.0,
                p50_latency_across_offsets_ms: 10.0,
            },
            "p50_latency_across_ms = 40\np50_latency_across_offsets_ms = 10",
            "p50_latency_across_ms = 20\np50_latency_across_offsets_ms = 0",
        );
        graded_both_ways(
            "ex10",
            &ex10::Ex10Outcome {
                stays_up_s: vec![Some(1.74), Some(1.86), Some(2.06)],
            },
            "stays_up_s = 2",
            "stays_up_s = 0.5",
        );
        graded_both_ways(
            "ex11",
            &ex11::Ex11Outcome {
                mine_hz: Some(5.5),
                scripted_hz: Some(7.5),
            },
            "my_cliff_hz = 5.5\nlower_than_scripted = true",
            "my_cliff_hz = 12.5\nlower_than_scripted = false",
        );
        graded_both_ways(
            "ex12",
            &ex12::Ex12Outcome {
                readings_lost: 3,
                gap_ms: 65.0,
                latency_max_ms: 120.0,
            },
            "readings_lost = 4\nlatency_max_ms = 110",
            "readings_lost = 10\nlatency_max_ms = 60",
        );
        let ex13 = Ex13Outcome {
            nodes: ["/sensor", "/policy", "/actuator", "/ratelab"]
                .map(String::from)
                .to_vec(),
            obs_type: "sensor_msgs/msg/JointState".into(),
            action_type: "std_msgs/msg/Float64".into(),
            clock_hz: 80.0,
        };
        graded_both_ways(
            "ex13",
            &ex13,
            "nodes = [\"/ratelab\", \"/actuator\", \"/sensor\", \"/policy\"]\nobs_type = \"sensor_msgs/msg/JointState\"\naction_type = \"std_msgs/msg/Float64\"\nclock_hz = 80",
            "nodes = [\"/sensor\", \"/policy\", \"/actuator\"]\nobs_type = \"sensor_msgs/JointState\"\naction_type = \"std_msgs/msg/Float32\"\nclock_hz = 90",
        );
        let event = |e: &str| Some(format!("incompatible QoS: {e}"));
        graded_both_ways(
            "ex14",
            &ex14::Ex14Outcome {
                delivers: vec![
                    ("reliable_from_best_effort".into(), false, event("reliability")),
                    ("best_effort_from_reliable".into(), true, None),
                    ("deadline_20_from_40".into(), false, event("deadline")),
                    ("deadline_40_from_20".into(), true, None),
                ],
                history: vec![("volatile".into(), 0), ("transient_local".into(), 5)],
            },
            "reliable_from_best_effort = false\nbest_effort_from_reliable = true\ndeadline_20_from_40 = false\ndeadline_40_from_20 = true\nlate_joiner_volatile = 0\nlate_joiner_transient_local = 5",
            "reliable_from_best_effort = true\nbest_effort_from_reliable = false\ndeadline_20_from_40 = true\ndeadline_40_from_20 = false\nlate_joiner_volatile = 3\nlate_joiner_transient_local = 1",
        );
    }

    /// ex13's node list is a set: any order, each name with or without the root
    /// namespace's `/`; a node missing, or one more, is a miss. What it prints is what `ros2
    /// node list` prints: sorted.
    #[test]
    fn ex13_compares_the_node_list_as_a_set() {
        let o = Ex13Outcome {
            nodes: ["/sensor", "/policy", "/actuator", "/ratelab"]
                .map(String::from)
                .to_vec(),
            obs_type: "sensor_msgs/msg/JointState".into(),
            action_type: "std_msgs/msg/Float64".into(),
            clock_hz: 80.0,
        };
        let nodes = |list: &str| o.reconcile(&table(&format!("nodes = {list}"))).remove(0);
        for right in [
            "[\"/sensor\", \"/policy\", \"/actuator\", \"/ratelab\"]",
            "[\"/actuator\", \"/policy\", \"/ratelab\", \"/sensor\"]",
            "[\"ratelab\", \"sensor\", \"actuator\", \"policy\"]",
            "[\"/ratelab\", \"sensor\", \"/actuator\", \"policy\", \"/sensor\"]",
        ] {
            let said = nodes(right);
            assert_eq!(said.verdict, Verdict::Right, "{right}: {}", said.line);
            assert_eq!(
                said.line,
                "You predicted the node list /actuator /policy /ratelab /sensor; ros2 node list prints /actuator /policy /ratelab /sensor: right."
            );
        }
        for wrong in [
            "[\"/sensor\", \"/policy\", \"/actuator\"]",
            "[\"/sensor\", \"/policy\", \"/actuator\", \"/ratelab\", \"/clock\"]",
            "[\"/robot/sensor\", \"/policy\", \"/actuator\", \"/ratelab\"]",
            "[]",
        ] {
            let said = nodes(wrong);
            assert_eq!(said.verdict, Verdict::Missed, "{wrong}: {}", said.line);
            assert!(
                said.line.contains(
                    "; ros2 node list prints /actuator /policy /ratelab /sensor (ROS 2 sees"
                ),
                "{}",
                said.line
            );
        }
        assert!(nodes("[]")
            .line
            .starts_with("You predicted the node list none;"));
        for unreadable in ["[\"/sensor\", 1]", "\"/sensor\""] {
            assert_eq!(
                nodes(unreadable).verdict,
                Verdict::Unreadable,
                "{unreadable}"
            );
        }
        assert_eq!(
            ex13::node_set(["sensor", "/policy", "actuator", "/ratelab"]),
            ["/actuator", "/policy", "/ratelab", "/sensor"]
                .map(String::from)
                .into_iter()
                .collect::<std::collections::BTreeSet<String>>()
        );
    }

    /// The line after the sentences counts what was right, and names what was not.
    #[test]
    fn the_tally_names_the_keys_that_missed() {
        let s = |key: &str, verdict| Said {
            key: key.into(),
            line: String::new(),
            verdict,
        };
        assert_eq!(
            tally(&[s("a", Verdict::Right), s("b", Verdict::Right)]),
            "Your prediction: 2 of 2 right."
        );
        assert_eq!(
            tally(&[
                s("a", Verdict::Missed),
                s("b", Verdict::Open),
                s("c", Verdict::Unreadable),
                s("d", Verdict::Right),
                s("e", Verdict::Missed),
            ]),
            "Your prediction: 1 of 4 right; missed: a, e; not read: c."
        );
    }
}
