//! Where recordings go and how their files are written: the default names (the graph, the
//! clock, the settings), the first free name in a folder, the output rule
//! ([`ratelab_core::output`]: written at its name from the start, replaced only with `--force`,
//! through a temporary file moved into place), the
//! reason a full disk gives, the recording id a virtual run derives from its settings, the
//! run's name and settings in a line, and the name of its time timeline.

use super::*;

/// `<graph>-` for any graph but the chapter's (`cartpole`), which keeps the names it had.
pub(super) fn graph_prefix(cfg: &RunConfig) -> String {
    if cfg.graph.name == "cartpole" {
        String::new()
    } else {
        format!("{}-", cfg.graph.name)
    }
}

/// `recordings/[<graph>-]<clock>-control<hz>-q<depth>-seed<seed>[-<n>].rrd` under `dir`: the
/// first name not already taken (`-2`, `-3`, … are appended), so nothing is overwritten.
pub fn default_path(dir: &Path, cfg: &RunConfig) -> PathBuf {
    let chain = match (cfg.control_hz(), cfg.queue_depth()) {
        (Some(hz), Some(depth)) => format!("-control{}-q{depth}", hz_label(hz)),
        _ => String::new(),
    };
    first_free(
        dir,
        &format!("{}{}{chain}-seed{}", graph_prefix(cfg), cfg.clock, cfg.seed),
    )
}

/// A lab session's recording: `lab-[<graph>-]<clock>-seed<seed>[-<n>].rrd` under `dir`, the
/// first name not taken. No rate or depth in the name: the learner changes them during the
/// session (the recording's summary gives them at the start and at the end, its events each
/// change).
pub fn default_lab_path(dir: &Path, cfg: &RunConfig) -> PathBuf {
    first_free(
        dir,
        &format!("lab-{}{}-seed{}", graph_prefix(cfg), cfg.clock, cfg.seed),
    )
}

pub(super) fn first_free(dir: &Path, stem: &str) -> PathBuf {
    let first = dir.join(format!("{stem}.rrd"));
    if !first.exists() {
        return first;
    }
    (2..)
        .map(|n| dir.join(format!("{stem}-{n}.rrd")))
        .find(|p| !p.exists())
        .expect("unbounded")
}

/// Check that `path` can be written before a run starts: not a folder, a symbolic link or
/// another non-regular file, not an existing file (unless `force`), and in a folder where
/// files can be created (a temporary file is created there and removed; the final name is
/// never touched).
///
/// # Errors
/// [`RecordingError`] naming the problem.
pub fn check_output_path(path: &Path, force: bool) -> Result<(), RecordingError> {
    Ok(ratelab_core::output::check_writable(path, force)?)
}

/// Commits a recording's file once, when finished or dropped: moves it into place when it
/// replaces a file, else checks that its name still holds it
/// ([`ratelab_core::output::PendingFile::commit`]).
pub(super) struct Committer(pub(super) Mutex<Option<ratelab_core::output::PendingFile>>);

impl Committer {
    pub(super) fn commit(&self) -> Result<(), ratelab_core::output::OutputError> {
        match self.0.lock().unwrap_or_else(|e| e.into_inner()).take() {
            Some(mut p) => p.commit(),
            None => Ok(()),
        }
    }
}

impl Drop for Committer {
    fn drop(&mut self) {
        // Best effort: a recording dropped unfinished keeps what it wrote.
        let _ = self.commit();
    }
}

/// Why a write in folder `dir` fails now, if it does: a page written to a temporary file
/// there and synced (removed after). The reason behind a file writer that stopped.
pub(super) fn writing_beside_fails(dir: &Path) -> Option<String> {
    let dir = if dir.as_os_str().is_empty() {
        Path::new(".")
    } else {
        dir
    };
    let path = dir.join(format!(".ratelab-probe.{}", std::process::id()));
    let probe = || -> std::io::Result<()> {
        // create_new: never through anything already at that name.
        let mut f = std::fs::OpenOptions::new()
            .write(true)
            .create_new(true)
            .open(&path)?;
        std::io::Write::write_all(&mut f, &[0; 4096])?;
        f.sync_all()
    };
    let failed = probe().err().map(|e| e.to_string());
    let _ = std::fs::remove_file(&path);
    failed
}

/// The recording id of a virtual run: derived from its settings, so two runs with the same
/// settings write the same recording. `None` under the real clock (a random id).
pub(super) fn deterministic_id(cfg: &RunConfig) -> Option<String> {
    (cfg.clock == ClockKind::Virtual).then(|| {
        let chain = match (cfg.sensor_hz(), cfg.control_hz(), cfg.queue_depth()) {
            (Some(s), Some(c), Some(q)) => {
                format!("-sensor{}-control{}-q{q}", hz_label(s), hz_label(c))
            }
            _ => String::new(),
        };
        format!(
            "ratelab-{}virtual{chain}-seed{}-d{}",
            graph_prefix(cfg),
            cfg.seed,
            cfg.duration.0
        )
    })
}

/// The chapter's settings of a run (`control 50 Hz, sensor 50 Hz, depth 1`), when its
/// graph has the chapter's chain; `None` for another shape.
pub(super) fn chapter_settings(cfg: &RunConfig) -> Option<String> {
    Some(format!(
        "control {} Hz, sensor {} Hz, depth {}",
        hz_label(cfg.control_hz()?),
        hz_label(cfg.sensor_hz()?),
        cfg.queue_depth()?
    ))
}

/// The recording's name: graph, clock, the chain's control rate (`control`: `50`, or
/// `50 → 5` for a run whose rate changed) and depth, seed.
pub(super) fn run_name(cfg: &RunConfig, control: Option<String>) -> String {
    let chain = match (control, cfg.queue_depth()) {
        (Some(hz), Some(depth)) => format!(", control {hz} Hz, depth {depth}"),
        _ => String::new(),
    };
    format!(
        "{}{} clock{chain}, seed {}",
        graph_prefix(cfg),
        cfg.clock,
        cfg.seed
    )
}

/// One-line settings of a run, for the start event and the summary.
pub(super) fn settings_line(cfg: &RunConfig) -> String {
    format!(
        "{}{}seed {}, {} clock",
        graph_prefix(cfg).replace('-', ": "),
        chapter_settings(cfg).map(|c| c + ", ").unwrap_or_default(),
        cfg.seed,
        cfg.clock
    )
}

/// The name of the timeline that carries the runtime clock's time: `sim_time` for the
/// virtual clock (simulated time, as ROS 2 calls time from `/clock`), `wall_time` for the
/// real clock (time since the run's start on the machine's monotonic clock).
pub fn timeline_name(clock: ClockKind) -> &'static str {
    match clock {
        ClockKind::Virtual => "sim_time",
        ClockKind::Real => "wall_time",
    }
}
