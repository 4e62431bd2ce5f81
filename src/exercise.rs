//! The chapter's exercises, as a registry: each exercise is one file (`exN.rs`) holding its
//! bands, what it measures, its checks, its outcome in the terms of the learner's
//! prediction and how that is said, and what it prints; [`EXERCISES`] lists them, in order.
//! A new exercise is its file plus one line there (and its TOML in `exercises/`).
//!
//! This module holds what they share: reading the learner's file and `bands.toml`
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
//! - [`ex14`], incompatible QoS: four requested/offered pairs on the chapter's `/action`,
//!   which ROS 2 connects; and a node joining late under each durability: what it gets.

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

use crate::config::{duration_from_secs, ClockKind, RunConfig};
use crate::graph::GraphSpec;
use crate::metrics::Metrics;
use crate::policy::{Policy, Scripted};
use crate::sweep::SweepError;
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
    /// ([`crate::input::read_regular_file`]'s rules).
    #[error(transparent)]
    Input(#[from] crate::input::InputError),
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
    /// The learner's file has no prediction yet.
    #[error(
        "{path} has no prediction yet: fill in [prediction] ({keys} and why) first — predicting is the exercise"
    )]
    NoPrediction {
        /// The learner's file.
        path: String,
        /// The keys it needs, comma-separated.
        keys: String,
    },
    /// What the learner must do first, in one line (ex6's untouched template).
    #[error("{0}")]
    NotReady(String),
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
    let bytes = crate::input::read_regular_file(path, MAX_FILE_BYTES)?;
    String::from_utf8(bytes).map_err(|_| ExerciseError::Parse {
        path: path.display().to_string(),
        detail: "not UTF-8 text".into(),
    })
}

fn parse_error(path: &str, e: &impl std::fmt::Display) -> ExerciseError {
    ExerciseError::Parse {
        path: path.to_string(),
        detail: e
            .to_string()
            .lines()
            .next()
            .unwrap_or("invalid TOML")
            .to_string(),
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
        table
            .clone()
            .try_into()
            .map_err(|e| parse_error(&format!("{} [{}]", self.path, S::NAME), &e))
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

    /// The prediction beside the outcome, one sentence per predicted key, in words: "You
    /// predicted the pole first fails at 10 Hz; it first fell at 5 Hz." A key the learner
    /// left out, or gave in another type, is said so ([`says_unreadable`]).
    pub fn reconcile(&self, outcome: &impl Reconcile) -> Vec<String> {
        outcome.reconcile(&self.prediction)
    }
}

/// What an exercise measured, in the terms of its prediction's keys: each exercise's
/// outcome type says itself beside a prediction.
pub trait Reconcile {
    /// One sentence per key of `prediction` the exercise asks for.
    fn reconcile(&self, prediction: &toml::Table) -> Vec<String>;
}

/// A prediction value as a number (TOML integer or float).
fn number(v: &toml::Value) -> Option<f64> {
    v.as_float().or_else(|| v.as_integer().map(|i| i as f64))
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
    pub exe: &'a crate::distributed::launcher::Program,
    /// The learner's file.
    pub file: &'a ExerciseFile,
    /// `bands.toml`.
    pub bands: &'a Bands,
    out: &'a mut dyn FnMut(&str),
    progress: &'a dyn Progress,
    /// What it found so far: every check and reconcile line, and what did not pass.
    report: Report,
}

/// What an exercise found: its checks, the sentences setting the prediction beside the
/// outcome, and how many checks failed or predictions could not be read.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Report {
    /// Every check, in the order printed (`[ok]` / `[!!]`).
    pub checks: Vec<Check>,
    /// The prediction beside the outcome, one sentence per predicted key.
    pub reconcile: Vec<String>,
    /// Checks that failed plus predictions that could not be read (0: passed).
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

    /// Run `f` (a measurement) with its progress shown.
    pub fn measure<T>(&self, f: impl FnOnce() -> T) -> T {
        self.progress.begin(&format!("measuring {}", self.id));
        let out = f();
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
                self.report.not_passed += 1;
            }
            self.report.checks.push(c.clone());
        }
    }

    /// Print the learner's prediction beside `outcome`, and count the keys that could not
    /// be read.
    pub fn reconcile(&mut self, outcome: &impl Reconcile) {
        say!(self);
        for line in self.file.reconcile(outcome) {
            self.say(&line);
            if says_unreadable(&line) {
                self.report.not_passed += 1;
            }
            self.report.reconcile.push(line);
        }
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
    pub exe: &'a crate::distributed::launcher::Program,
    /// The prediction, in place of the one in the learner's file (`None`: the file's): the
    /// keys the exercise's file asks for, and `why`.
    pub prediction: Option<&'a toml::Table>,
}

/// Run exercise `which` as `ratelab exercise` does: refuse it without a prediction, print
/// its heading and the prediction, then let it measure and report, every line through
/// `out`.
///
/// Returns how many checks failed and predictions could not be read (0: passed).
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

/// [`run`], returning what the exercise found: its checks and reconcile sentences as well as
/// how many did not pass (what `ratelab.exercise` in Python returns).
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
        file.prediction = prediction.clone();
    }
    if !file.has_prediction(exercise.required_keys()) {
        return Err(ExerciseError::NoPrediction {
            path: path.display().to_string(),
            keys: exercise.required_keys().join(", "),
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

fn threads() -> usize {
    std::thread::available_parallelism().map_or(1, |n| n.get())
}

/// One run of `cfg` with the scripted balancer, no trace kept (the real-clock exercises:
/// ex3, ex9): its metrics.
/// `cfg`'s graph launched across its processes with the scripted balancer (ex9, ex12): the
/// processes started with `exe`, ratelab's command line, loading the graph file at
/// `graph_path` (`None`: the chapter's, compiled in) under fresh credentials; the processes
/// in `kill_processes` killed at their times.
///
/// # Errors
/// [`ExerciseError::Launch`] when the launch fails (a process that cannot be started, a
/// port that cannot be listened on); the graph file's error when it cannot be read.
fn launch_across(
    cfg: &RunConfig,
    graph_path: Option<&Path>,
    exe: &crate::distributed::launcher::Program,
    kill_processes: Vec<(String, crate::time::Nanos)>,
) -> Result<crate::distributed::launcher::LaunchReport, ExerciseError> {
    use crate::distributed::launcher::{launch, LaunchOptions};
    let names: Vec<String> = cfg.graph.placement().into_iter().map(|(p, _)| p).collect();
    let launch_error = |e: crate::distributed::DistError| ExerciseError::Launch(e.to_string());
    let opts = LaunchOptions {
        graph_path: graph_path.map(Path::to_path_buf),
        graph_bytes: crate::graph::spec::graph_file_bytes(graph_path)?,
        listen: None,
        policy: "scripted".into(),
        exe: Some(exe.clone()),
        child_stderr: None,
        start_gate: None,
        listening: None,
        pace: None,
        credentials: crate::distributed::credentials::Credentials::generate(
            &cfg.graph.name,
            &names,
        )
        .map_err(launch_error)?,
        ros2_domain: None,
        kill_processes,
    };
    let stop = crate::scheduler::StopFlag::new();
    launch(cfg, &opts, &stop, &|_| {}).map_err(launch_error)
}

fn run_scripted(cfg: &RunConfig) -> Result<Metrics, ExerciseError> {
    let opts = crate::run::RunOptions {
        keep_trace: false,
        ..Default::default()
    };
    Ok(crate::run::run(cfg, Box::new(Scripted), opts)
        .map_err(SweepError::from)?
        .metrics)
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
    use crate::policy::Scripted;

    #[test]
    fn every_exercise_is_registered_once_with_its_file() {
        let ids = ids();
        let mut unique = ids.clone();
        unique.sort_unstable();
        unique.dedup();
        assert_eq!(unique.len(), ids.len(), "{ids:?}");
        let dir = Path::new(concat!(env!("CARGO_MANIFEST_DIR"), "/exercises"));
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
                crate::input::InputError::TooLarge { .. }
            ))
        ));
        let binary = dir.path().join("binary.toml");
        std::fs::write(&binary, [0xff, 0xfe]).unwrap();
        assert!(ExerciseFile::load(&binary)
            .unwrap_err()
            .to_string()
            .ends_with("not UTF-8 text"));
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
            "/exercises/bands.toml"
        )))
        .unwrap()
        .of()
        .unwrap();
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
        let ex4 = Ex4Outcome {
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
        let never = Ex4Outcome {
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
        let ex5 = Ex5Outcome {
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
            f.reconcile(&Ex1Outcome {
                fails_at_hz: Some(5.0)
            }),
            ["You predicted the pole first fails at 10 Hz; it first fell at 5 Hz."]
        );
        let f = file("fails_at_hz = 5.0\nwhy = \"w\"");
        assert!(f.reconcile(&Ex1Outcome {
            fails_at_hz: Some(5.0)
        })[0]
            .ends_with(": right."));
        let f = file("deep_queue_obs_drops = 0\ndeep_queue_balances = true\nwhy = \"w\"");
        assert_eq!(
            f.reconcile(&Ex2Outcome {
                deep_queue_obs_drops: 0,
                deep_queue_balances: false
            }),
            [
                "You predicted 0 /obs drops with the deep queue; there were 0.",
                "You predicted the deep queue keeps the pole up; it fell."
            ]
        );
        let f = file("matched_obs_drops = \"many\"\nwhy = \"w\"");
        assert!(f.reconcile(&Ex3Outcome {
            matched_obs_drops: 7
        })[0]
            .contains("not of the expected type"));
    }
}
