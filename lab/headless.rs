//! The headless run: one graph, the chapter's summary, optional metrics.json and trace.csv.

use crate::cli::{GraphArgs, RunArgs};
use indicatif::{ProgressBar, ProgressStyle};
use ratelab::graph::GraphSpec;
use ratelab::outputs::{
    check_out, end_is_an_error, execute, finish_recording, log_text, write_outputs, TraceCsv,
};
use ratelab::run_spec::{GraphSettings, RunSpec};
use ratelab::runlog::StepRecord;
use ratelab::scheduler::{EndReason, StopFlag};
use ratelab::setting::Speech;
use ratelab::trace_csv::TraceFile;
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

/// The faults the flags inject (`--stall`, then `--kill`).
pub fn faults_from_args(g: &GraphArgs) -> Vec<ratelab::qos::Fault> {
    GraphSettings::from(g).faults()
}

/// The run settings the flags describe: [`RunSpec::config`] of `ratelab run`'s flags, in
/// their words; the graph's QoS warnings on stderr.
pub fn config_from_args(a: &RunArgs) -> anyhow::Result<RunConfig> {
    let cfg = RunSpec::from(a).config(Speech::Flags)?;
    warn_qos(&cfg.graph);
    Ok(cfg)
}

/// Warn on stderr of each injected fault (`--stall`, `--kill`) that starts after `cfg`'s
/// run ends, so does nothing. Call it once the run's duration is final (the lab and a
/// launch on a terminal run until quit, with no end to be after).
pub fn warn_late_faults(cfg: &RunConfig) {
    if cfg.duration == ratelab::session::UNBOUNDED {
        return;
    }
    for f in cfg.faults.iter().filter(|f| f.at >= cfg.duration) {
        eprintln!(
            "[ratelab] warning: the {} of '{}' at {} s starts after the run ends ({} s): it does nothing",
            if f.duration.is_some() { "--stall" } else { "--kill" },
            f.node,
            f.at.as_secs_f64(),
            cfg.duration.as_secs_f64()
        );
    }
}

pub fn run_headless(a: &RunArgs, stop: StopFlag) -> anyhow::Result<RunReport> {
    let cfg = config_from_args(a)?;
    warn_late_faults(&cfg);
    let brain = ratelab::checkpoint::load_policy(&a.policy)?;
    let outputs = RunSpec::from(a).outputs;
    check_out(&outputs, &cfg.graph)?;
    // trace.csv is written as the run goes, never held: a day's step records were 4.6 GB
    // (issue 75). Its file is checked and started before the run.
    let trace = match &a.out {
        Some(dir) => Some(TraceFile::create(
            &dir.join("trace.csv"),
            a.force,
            &cfg.graph,
            a.trace_every,
        )?),
        None => None,
    };
    let (bar, ticker) = real_clock_bar(&cfg, &stop);
    // A long virtual run (up to an hour of run time, seconds to minutes of wall time) shows
    // its run time going by; the observer only reads step times, so results do not change.
    let virtual_bar = (cfg.clock == ClockKind::Virtual
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
    });
    let mut observers: Vec<Box<dyn ratelab::graph::StepObserver>> = match &virtual_bar {
        Some(bar) => vec![Box::new(ProgressObserver(bar.clone()))],
        None => Vec::new(),
    };
    observers.extend(trace.as_ref().map(TraceFile::observer));
    let (report, kept, recording) = execute(&outputs, &cfg, brain, stop, observers, true)?;
    if let Some(bar) = virtual_bar {
        bar.finish_and_clear();
    }
    // A recording that could not be finished (a full disk) fails the run after its summary
    // and the other files: it costs the file, not the run's result.
    let unrecorded = finish_recording(&outputs, recording.as_ref(), &report);
    if let Some(bar) = bar {
        bar.finish_and_clear();
    }
    if let Some(t) = ticker {
        let _ = t.join();
    }
    print_summary(&report);
    if let Some(r) = &report.ros2 {
        print_ros2(r, a.bag.as_deref());
    }
    if cfg.rt_priority.is_some() && cfg.clock == ClockKind::Virtual {
        eprintln!("[ratelab] note: --rt-priority applies to the real clock only; ignored");
    }
    if let Some(w) = report.metrics.sched_warning() {
        eprintln!("[ratelab] warning: {w}");
    }
    if let (Some(dir), Some(trace)) = (&a.out, trace) {
        write_outputs(
            dir,
            &report,
            &log_text(&kept),
            a.force,
            TraceCsv::Streamed(trace),
        )?;
        let files = if report.metrics.estimate.is_some() {
            "metrics.json, trace.csv, log.txt and estimator.json"
        } else {
            "metrics.json, trace.csv and log.txt"
        };
        println!(
            "[ratelab] wrote {}/{files} (what each key and column means: docs/metrics.md)",
            dir.display()
        );
        if a.trace_every > 1 {
            let n = a.trace_every;
            println!(
                "[ratelab] trace.csv keeps one actuator step in {n} (--trace-every {n}: steps 1, {}, … and the last); the metrics count every step",
                1 + n
            );
        }
    }
    if let Some(e) = unrecorded {
        return Err(e.into());
    }
    if let Some(r) = &recording {
        println!("[ratelab] recording: {}", r.path().display());
        println!("[ratelab] open it with: rerun {}", r.path().display());
    }
    if let Some(Err(e)) = report.ros2.as_ref().and_then(|r| r.bagged.as_ref()) {
        // After the summary and the other outputs: a bag that is not whole is an error.
        anyhow::bail!("--bag {e}");
    }
    end_is_an_error(&report)?;
    Ok(report)
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

/// Moves a progress bar to each actuator step's run time, in ms.
struct ProgressObserver(ProgressBar);

impl ratelab::graph::StepObserver for ProgressObserver {
    fn on_step(&mut self, rec: &StepRecord) {
        self.0.set_position(rec.t.0 / 1_000_000);
    }
}

/// The chapter's summary, one `[ratelab]` line each, on stdout.
pub fn print_summary(report: &RunReport) {
    let mut out = std::io::stdout().lock();
    for line in report
        .metrics
        .summary_lines(Some(report.wall.as_secs_f64()))
    {
        let _ = writeln!(out, "[ratelab] {line}");
    }
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
