//! The headless run (`ratelab run`): its flags read into the library's `RunSpec`
//! (`From<&RunArgs>`, in `cli`), started and run by the library ([`RunSpec::start`]: every
//! settings rule, the checks, the trace, the recording and ROS 2 are its), and what the
//! command line prints of it: progress on a terminal, the chapter's summary, what was offered
//! to ROS 2, the files written. The graph's and the run's settings for the other commands
//! (the lab, a launch, `exercise`, `bench`) are read here too, through the same rules.

use crate::cli::{GraphArgs, RunArgs};
use indicatif::{ProgressBar, ProgressStyle};
use ratelab::graph::GraphSpec;
use ratelab::metrics::Metrics;
use ratelab::observer::RunObserver;
use ratelab::outputs::end_is_an_error;
use ratelab::run_spec::{late_fault_warnings, GraphSettings, RunSpec};
use ratelab::runlog::StepRecord;
use ratelab::scheduler::{EndReason, RunEnd, StopFlag};
use ratelab::setting::Speech;
use ratelab::start::StartOptions;
use ratelab::{ClockKind, Nanos, RunConfig, RunReport};
use std::io::{IsTerminal, Write};
use std::time::Duration;

/// The graph the flags name (`--graph`, default the chapter's), with every override
/// applied ([`GraphSettings::graph`]); its QoS warnings on stderr.
pub fn graph_from_args(g: &GraphArgs) -> anyhow::Result<GraphSpec> {
    let spec = GraphSettings::from(g).graph(Speech::Flags)?;
    warn_qos(&spec);
    Ok(spec)
}

/// A graph's QoS warnings ([`GraphSpec::qos_warnings`]), a `[ratelab]` line each on stderr.
pub fn warn_qos(spec: &GraphSpec) {
    for w in spec.qos_warnings() {
        eprintln!("[ratelab] {w}");
    }
}

/// The run settings the flags describe: [`RunSpec::config`] of `ratelab run`'s flags, in
/// their words; the graph's QoS warnings on stderr.
pub fn config_from_args(a: &RunArgs) -> anyhow::Result<RunConfig> {
    let cfg = RunSpec::from(a).config(Speech::Flags)?;
    warn_qos(&cfg.graph);
    Ok(cfg)
}

/// Refuse `--trace-every N` (N > 1) where no trace.csv is written (no `--out`): accepted, it
/// would do nothing.
///
/// # Errors
/// One line saying what to add.
pub fn check_trace_every(a: &RunArgs) -> anyhow::Result<()> {
    if a.trace_every > 1 && a.out.is_none() {
        anyhow::bail!("--trace-every thins trace.csv, which only --out writes: add --out DIR");
    }
    Ok(())
}

/// Warn on stderr of each injected fault (`--stall`, `--kill`) that starts after `cfg`'s
/// run ends, so does nothing ([`late_fault_warnings`]). Call it once the run's duration is
/// final (the lab and a launch on a terminal run until quit, with no end to be after).
pub fn warn_late_faults(cfg: &RunConfig) {
    for line in late_fault_warnings(cfg, Speech::Flags) {
        eprintln!("[ratelab] {line}");
    }
}

/// `ratelab run`: the run its flags describe, started by the library ([`RunSpec::start`]),
/// with a progress bar on a terminal; then its summary, what it offered ROS 2, its files,
/// its recording. Returns the report.
///
/// # Errors
/// A refusal before the run (one line, exit 2); after its summary and files, a recording
/// that could not be finished, a bag that is not whole, a run that failed
/// ([`end_is_an_error`]).
pub fn run_headless(a: &RunArgs, stop: StopFlag) -> anyhow::Result<RunReport> {
    let mut run = RunSpec::from(a).start(StartOptions::command_line(stop.clone()))?;
    let (clock, rt_priority) = (run.config().clock, run.config().rt_priority);
    let (bar, ticker) = real_clock_bar(run.config(), &stop);
    if let Some(bar) = virtual_clock_bar(run.config()) {
        run.observe(Box::new(ProgressObserver(bar)));
    }
    let mut done = run.wait()?;
    if let Some(bar) = bar {
        bar.finish_and_clear();
    }
    if let Some(t) = ticker {
        let _ = t.join();
    }
    print_summary(&done.report);
    if let Some(r) = &done.report.ros2 {
        print_ros2(r, a.bag.as_deref());
    }
    if rt_priority.is_some() && clock == ClockKind::Virtual {
        eprintln!("[ratelab] note: --rt-priority applies to the real clock only; ignored");
    }
    if let Some(w) = done.report.metrics.sched_warning() {
        eprintln!("[ratelab] warning: {w}");
    }
    if let Some(dir) = &a.out {
        done.write_files()?;
        print_written(dir, &done.report, a.trace_every);
    }
    // A recording that could not be finished (a full disk) fails the run after its summary
    // and the other files: it costs the file, not the run's result.
    if let Some(e) = done.unrecorded.take() {
        return Err(e.into());
    }
    if let Some(r) = &done.recording {
        println!("[ratelab] recording: {}", r.path().display());
        println!("[ratelab] {}", ratelab::recording::open_hint(r.path()));
    }
    if let Some(Err(e)) = done.report.ros2.as_ref().and_then(|r| r.bagged.as_ref()) {
        // After the summary and the other outputs: a bag that is not whole is an error.
        anyhow::bail!("--bag {e}");
    }
    end_is_an_error(&done.report)?;
    Ok(done.report)
}

/// The files `--out` got (in `dir`), and how thin its trace is (one step in `every`).
fn print_written(dir: &std::path::Path, report: &RunReport, every: u64) {
    let files = if report.metrics.estimate.is_some() {
        "metrics.json, trace.csv, log.txt and estimator.json"
    } else {
        "metrics.json, trace.csv and log.txt"
    };
    println!(
        "[ratelab] wrote {}/{files} (what each key and column means: docs/metrics.md)",
        dir.display()
    );
    if every > 1 {
        println!(
            "[ratelab] trace.csv keeps one actuator step in {every} (--trace-every {every}: steps 1, {}, … and the last); the metrics count every step",
            1 + every
        );
    }
}

/// A long virtual run's progress bar on a terminal (up to an hour of run time, seconds to
/// minutes of wall time): its run time going by. Its observer only reads step times, so
/// results do not change.
fn virtual_clock_bar(cfg: &RunConfig) -> Option<ProgressBar> {
    (cfg.clock == ClockKind::Virtual
        && cfg.duration >= Nanos(60 * Nanos::SECOND.0)
        && std::io::stdout().is_terminal())
    .then(|| {
        let bar = ProgressBar::new(cfg.duration.0 / 1_000_000);
        bar.set_style(
            ProgressStyle::with_template(
                "{spinner} virtual clock [{bar:40}] {pos}/{len} ms run time ({elapsed})",
            )
            .expect("static template")
            .progress_chars("=> "),
        );
        bar
    })
}

/// A real-clock run's progress bar on a terminal (run time against the duration) and the
/// thread that moves it, until `stop` or the bar is finished.
fn real_clock_bar(
    cfg: &RunConfig,
    stop: &StopFlag,
) -> (Option<ProgressBar>, Option<std::thread::JoinHandle<()>>) {
    let bar = (cfg.clock == ClockKind::Real && std::io::stdout().is_terminal()).then(|| {
        let bar = ProgressBar::new(cfg.duration.0 / 1_000_000);
        bar.set_style(
            ProgressStyle::with_template("{spinner} real clock [{bar:40}] {pos}/{len} ms run time")
                .expect("static template")
                .progress_chars("=> "),
        );
        bar.enable_steady_tick(Duration::from_millis(100));
        bar
    });
    let ticker = bar.clone().map(|bar| {
        let stop = stop.clone();
        std::thread::spawn(move || {
            let start = std::time::Instant::now();
            while !stop.is_stopped() && !bar.is_finished() {
                bar.set_position(start.elapsed().as_millis() as u64);
                std::thread::sleep(Duration::from_millis(50));
            }
        })
    });
    (bar, ticker)
}

/// What the run offered ROS 2 (and how many messages it could not), the bag written to
/// `bag`, and the bridge's warnings.
fn print_ros2(r: &ratelab::ros2::BridgeReport, bag: Option<&std::path::Path>) {
    println!(
        "[ratelab] ROS 2: {} messages offered{}",
        r.offered,
        if r.dropped > 0 {
            format!(", {} not (the bridge fell behind)", r.dropped)
        } else {
            String::new()
        }
    );
    if r.log_dropped > 0 {
        println!(
            "[ratelab] ROS 2: {} log lines not put on /rosout (the bridge fell behind)",
            r.log_dropped
        );
    }
    if let (Some(Ok(n)), Some(dir)) = (&r.bagged, bag) {
        println!(
            "[ratelab] bag: {} (rosbag2, MCAP): {n} messages with /clock",
            dir.display()
        );
    }
    if let Some(e) = &r.error {
        eprintln!("[ratelab] warning: ROS 2: {e}");
    }
    for w in r.external_warnings() {
        eprintln!("[ratelab] warning: {w}");
    }
}

/// Moves a progress bar to each actuator step's run time, in ms; clears it at the end.
struct ProgressObserver(ProgressBar);

impl RunObserver for ProgressObserver {
    fn on_step_record(&mut self, rec: &StepRecord) {
        self.0.set_position(rec.t.0 / 1_000_000);
    }

    fn on_end(&mut self, _metrics: &Metrics, _end: &RunEnd) {
        self.0.finish_and_clear();
    }
}

/// The chapter's summary, one `[ratelab]` line each, on stdout: its figures
/// ([`print_figures`]), then how the run ended where it did not run its course
/// ([`print_end`]).
pub fn print_summary(report: &RunReport) {
    print_figures(report);
    print_end(report);
}

/// The summary's figures, one `[ratelab]` line each, on stdout.
pub fn print_figures(report: &RunReport) {
    let mut out = std::io::stdout().lock();
    for line in report
        .metrics
        .summary_lines(Some(report.wall.as_secs_f64()))
    {
        let _ = writeln!(out, "[ratelab] {line}");
    }
}

/// The summary's last line where the run did not run its course: `interrupted at t=…`, or
/// the node that failed. Said after every figure (a launch's wire and lockstep lines too).
pub fn print_end(report: &RunReport) {
    let mut out = std::io::stdout().lock();
    match &report.end.reason {
        EndReason::Interrupted => {
            let _ = writeln!(
                out,
                "[ratelab] interrupted at t={:.2}s",
                report.end.at.as_secs_f64()
            );
        }
        reason @ EndReason::NodeFailed { .. } => {
            let _ = writeln!(out, "[ratelab] {reason}");
        }
        _ => {}
    }
}
