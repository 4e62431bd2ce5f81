//! A run started from its [`RunSpec`], the same way for every front end:
//! [`RunSpec::start`] turns the settings into the run ([`RunSpec::config`]: every rule,
//! once), checks what it offers to ROS 2 once, loads the brain, checks `--out`, makes the
//! trace's writer, opens the recording, and attaches it ([`crate::observer`]); the ROS 2
//! session opens when the run does, once its graph is built. It returns the run ready to go ([`StartedRun`]): the front end
//! reads its settings, adds observers of its own (a progress bar), and
//! [`StartedRun::wait`]s for it on the calling thread, which runs it to its end and
//! finishes the recording ([`FinishedRun`]; [`FinishedRun::write_files`] writes `--out`'s
//! files). `ratelab run` prints what it gives; a host program's run
//! ([`crate::held_run`]) returns it.
//!
//! The steps keep the order the command line's run has always taken, so that what is
//! refused first, and what is written or opened before a refusal, does not change.

use crate::observer::{steps, Observers, Recorded, RunObserver};
use crate::outputs::{
    check_out, finish_recording, log_text, open_recording, ros2_options, write_outputs, KeptLog,
    Outputs, RecordRefused, TraceCsv, MAX_LOG_LINES,
};
use crate::run::{RunOptions, RunReport};
use crate::run_spec::{late_fault_warnings, RunSpec};
use crate::trace_csv::{TraceFile, TraceStream};
use ratelab_recording::Recording;
use ratelab_runtime::policy::Policy;
use ratelab_runtime::scheduler::StopFlag;
use ratelab_runtime::setting::Speech;
use ratelab_runtime::RunConfig;
use std::io::Write;
use std::sync::{Arc, Mutex};

/// Where a run's `trace.csv` goes.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum TraceTo {
    /// A file in `--out`'s folder, written as the run goes (`ratelab run`: a day's step
    /// records are gigabytes, never held); none without `--out`.
    File,
    /// Memory, returned by [`FinishedRun::write_files`] (and written to `--out` too when
    /// given): a host program's run.
    Memory,
}

/// The front end's own check of a run's settings ([`StartOptions::check`]).
pub type StartCheck = Box<dyn FnOnce(&RunConfig) -> anyhow::Result<()>>;

/// How a front end starts a run ([`RunSpec::start`]): what differs between the command line
/// and a host program.
pub struct StartOptions {
    /// Whose words a refusal names settings in (`--control-hz`, `control_hz`).
    pub speech: Speech,
    /// The brain, in place of the spec's `policy` (a host program's callable); `None`: the
    /// brain `policy` names, loaded.
    pub brain: Option<Box<dyn Policy>>,
    /// The front end's own check of the settings (a host program's: the classes it gives
    /// for Python nodes, its trace's size in memory), after the library's and before the
    /// brain is loaded or anything is written or opened.
    pub check: Option<StartCheck>,
    /// Stops the run from outside (Ctrl-C); also ends a wait for a ROS 2 router.
    pub stop: StopFlag,
    /// Where `trace.csv` goes.
    pub trace: TraceTo,
    /// Say on stderr what the run says as it goes, as `ratelab run` does: a warning for each
    /// fault that starts after the run ends, and each line the nodes write, stamped. Without
    /// it the lines are only kept (`log.txt`, [`FinishedRun::log`]).
    pub echo: bool,
}

impl StartOptions {
    /// `ratelab run`'s: the flags' words, the brain `--policy` names, `trace.csv` streamed to
    /// `--out`, everything said on stderr.
    pub fn command_line(stop: StopFlag) -> Self {
        Self {
            speech: Speech::Flags,
            brain: None,
            check: None,
            stop,
            trace: TraceTo::File,
            echo: true,
        }
    }

    /// A host program's (`ratelab.run`): refusals in `speech`'s words, the trace held in
    /// memory, nothing said but the graph's QoS warnings.
    pub fn held(speech: Speech, stop: StopFlag) -> Self {
        Self {
            speech,
            brain: None,
            check: None,
            stop,
            trace: TraceTo::Memory,
            echo: false,
        }
    }
}

/// The writer of a run's `trace.csv`.
enum Trace {
    File(TraceFile),
    Memory(TraceStream<Vec<u8>>),
}

impl Trace {
    /// The observer that writes its rows.
    fn observer(&self) -> Box<dyn RunObserver> {
        steps(match self {
            Self::File(f) => f.observer(),
            Self::Memory(s) => s.observer(),
        })
    }
}

/// A run checked, its outputs opened and attached, ready to go ([`StartedRun::wait`]).
/// Dropped instead, it runs nothing: its recording keeps what it wrote (nothing), its
/// trace's temporary file goes, its ROS 2 session is dropped.
pub struct StartedRun {
    cfg: RunConfig,
    outputs: Outputs,
    brain: Box<dyn Policy>,
    stop: StopFlag,
    echo: bool,
    /// Whose words a recording that cannot be finished is refused in.
    speech: Speech,
    trace: Option<Trace>,
    recording: Option<Recording>,
    ros2: Option<ratelab_ros2::Ros2Options>,
    /// The spec's commands: those between instants, and those after the run's end.
    commands: (
        Vec<ratelab_runtime::command::TimedCommand>,
        Vec<ratelab_runtime::command::TimedCommand>,
    ),
    /// The front end's own observers ([`StartedRun::observe`]).
    observers: Vec<Box<dyn RunObserver>>,
}

impl RunSpec {
    /// Start the run these settings describe, as every front end does: the settings turned
    /// into the run ([`RunSpec::config`], in `opts.speech`'s words; the graph's QoS warnings
    /// on stderr), faults after the end warned of (with `opts.echo`), the front end's own
    /// check (`opts.check`), the brain loaded (unless given), `--out` checked
    /// ([`check_out`]), `trace.csv`'s writer made ([`StartOptions::trace`]), ROS 2 checked
    /// ([`ros2_options`], the one check: the run does not check again), the recording
    /// opened ([`open_recording`]). Nothing runs until [`StartedRun::wait`], which opens the
    /// ROS 2 session once the graph is built.
    ///
    /// # Errors
    /// The first refusal, in one line: a setting ([`RunSpec::config`]), the front end's
    /// check, a brain or graph file that cannot be read, an output that exists without
    /// `force`, ROS 2's settings, a recording that cannot be opened.
    pub fn start(self, opts: StartOptions) -> anyhow::Result<StartedRun> {
        let StartOptions {
            speech,
            brain,
            check,
            stop,
            trace,
            echo,
        } = opts;
        let cfg = self.config(speech)?;
        let commands = self.commands_at(cfg.duration);
        for w in cfg.graph.qos_warnings() {
            eprintln!("[ratelab] {w}");
        }
        if echo {
            for line in late_fault_warnings(&cfg, speech) {
                eprintln!("[ratelab] {line}");
            }
        }
        if let Some(check) = check {
            check(&cfg)?;
        }
        let brain = match brain {
            Some(b) => b,
            None => ratelab_runtime::checkpoint::load_policy(&self.policy)?,
        };
        let a = self.outputs;
        check_out(&a, &cfg.graph, speech)?;
        let trace = match (trace, &a.out) {
            // Held in memory: the caller's to return.
            (TraceTo::Memory, _) => {
                let stream = TraceStream::new(Vec::new(), &cfg.graph, a.trace_every)?;
                Some(Trace::Memory(stream))
            }
            // Written as the run goes, never held: a day's step records were 4.6 GB (issue
            // 75). Its file is checked and started before the run.
            (TraceTo::File, Some(dir)) => {
                let path = dir.join("trace.csv");
                let file = TraceFile::create(&path, a.force, &cfg.graph, a.trace_every)?;
                Some(Trace::File(file))
            }
            (TraceTo::File, None) => None,
        };
        // Refused before anything is opened.
        let ros2 = ros2_options(&a, &cfg.graph)?;
        let recording = open_recording(&a, &cfg, &brain.label(), speech)?;
        Ok(StartedRun {
            cfg,
            commands,
            outputs: a,
            brain,
            stop,
            echo,
            speech,
            trace,
            recording,
            ros2,
            observers: Vec::new(),
        })
    }
}

impl StartedRun {
    /// The run's settings, every rule applied.
    pub fn config(&self) -> &RunConfig {
        &self.cfg
    }

    /// Tell `observer` about the run too: the front end's observers are told first, in the
    /// order added, then `trace.csv`'s writer, then the recording.
    pub fn observe(&mut self, observer: Box<dyn RunObserver>) {
        self.observers.push(observer);
    }

    /// Run it to its end on the calling thread (the real clock's nodes on threads of their
    /// own), every line the nodes write kept (and said on stderr, stamped, with
    /// [`StartOptions::echo`]) and in the recording, then finish the recording. No step
    /// record is kept in the report: `trace.csv`'s rows are written as the run goes.
    ///
    /// # Errors
    /// What keeps the run from starting: a graph that cannot be built, a ROS 2 session that
    /// cannot be opened, ROS 2 refusing the offer. A recording that cannot be finished is not an error here
    /// ([`FinishedRun::unrecorded`]).
    pub fn wait(self) -> anyhow::Result<FinishedRun> {
        let StartedRun {
            cfg,
            outputs,
            brain,
            stop,
            echo,
            speech,
            trace,
            recording,
            ros2,
            commands: (commands, after_end),
            mut observers,
        } = self;
        observers.extend(trace.as_ref().map(Trace::observer));
        if let Some(r) = &recording {
            observers.push(Box::new(Recorded::new(r)));
        }
        let observers = Observers::new(observers);
        let opts = RunOptions {
            stop,
            ros2,
            keep_trace: false,
            trace_every: outputs.trace_every,
            commands,
            after_end,
            ..RunOptions::new()
        };
        // What nodes' code writes (ratelab_core::textlog): told to the observers (the
        // recording's `log/<node>`), each line on stderr, stamped, as it comes (with `echo`),
        // kept for log.txt (the first MAX_LOG_LINES).
        let kept = log_sink(echo, observers.clone());
        let report = crate::run::run_checked(&cfg, brain, opts, &observers);
        ratelab_core::textlog::set_sink(None);
        // The observers' handles on the recording go before it is finished.
        drop(observers);
        let report = report?;
        let unrecorded =
            finish_recording(&outputs, recording.as_ref(), &report).map(|cause| RecordRefused {
                line: cause.said(speech),
                cause,
            });
        Ok(FinishedRun {
            report,
            log: log_text(&kept),
            recording,
            unrecorded,
            trace,
            outputs,
        })
    }
}

/// A run that has ended: its report, the lines its nodes wrote, its recording; its files
/// not yet written ([`FinishedRun::write_files`]).
pub struct FinishedRun {
    /// The report (no step records: see [`FinishedRun::write_files`] for `trace.csv`).
    pub report: RunReport,
    /// `log.txt`'s text: the lines the nodes wrote, stamped, a newline after each (the
    /// first [`MAX_LOG_LINES`]).
    pub log: String,
    /// The recording written, finished, when one was asked for.
    pub recording: Option<Recording>,
    /// Why the recording could not be finished (a full disk), in the front end's words,
    /// which fails the run once its summary and other files are out ([`finish_recording`]).
    pub unrecorded: Option<RecordRefused>,
    trace: Option<Trace>,
    outputs: Outputs,
}

impl FinishedRun {
    /// Finish `trace.csv` and write `--out`'s files when it was given ([`write_outputs`]:
    /// `metrics.json`, `trace.csv`, `log.txt`, `estimator.json` with an estimator). Returns
    /// `trace.csv`'s bytes when they were held in memory ([`TraceTo::Memory`]). Call it once:
    /// the trace is finished then.
    ///
    /// # Errors
    /// A write of the trace failed (during the run or now), or an output file could not be
    /// written (or exists without `force`).
    pub fn write_files(&mut self) -> anyhow::Result<Option<Vec<u8>>> {
        let out = self.outputs.out.as_deref();
        match self.trace.take() {
            Some(Trace::Memory(stream)) => {
                let bytes = stream.finish()?;
                if let Some(dir) = out {
                    let held = TraceCsv::Held(&bytes);
                    write_outputs(dir, &self.report, &self.log, self.outputs.force, held)?;
                }
                Ok(Some(bytes))
            }
            Some(Trace::File(file)) => {
                if let Some(dir) = out {
                    let streamed = TraceCsv::Streamed(file);
                    write_outputs(dir, &self.report, &self.log, self.outputs.force, streamed)?;
                }
                Ok(None)
            }
            None => Ok(None),
        }
    }
}

/// Where the lines nodes' code writes go ([`ratelab_core::textlog`]) while the run goes: to
/// `observers` ([`RunObserver::on_line`]); on stderr, stamped, as they come (with `echo`);
/// kept for log.txt (the first [`MAX_LOG_LINES`], returned).
fn log_sink(echo: bool, observers: Observers) -> KeptLog {
    let kept = Arc::new(Mutex::new(Vec::<String>::new()));
    let keep = kept.clone();
    ratelab_core::textlog::set_sink(Some(Box::new(move |line| {
        observers.line(&line);
        let text = line.prefixed();
        if echo {
            let _ = writeln!(std::io::stderr(), "{text}");
        }
        let mut k = keep.lock().unwrap_or_else(|e| e.into_inner());
        if k.len() < MAX_LOG_LINES {
            k.push(text);
        }
    })));
    kept
}
