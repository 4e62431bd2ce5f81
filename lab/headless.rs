//! The headless run: one graph, the chapter's summary, optional metrics.json and trace.csv.

use crate::cli::{GraphArgs, RunArgs};
use crate::trace::TraceFile;
use anyhow::Context;
use indicatif::{ProgressBar, ProgressStyle};
use ratelab::config::{phase_offsets_from_ms, BREAK_CONTROL_HZ};
use ratelab::graph::GraphSpec;
use ratelab::recording::{check_output_path, default_path, RecordOptions, Recording};
use ratelab::runlog::StepRecord;
use ratelab::scheduler::{EndReason, StopFlag};
use ratelab::{run, ClockKind, Nanos, RunConfig, RunOptions, RunReport};
use std::io::{IsTerminal, Write};
use std::path::{Path, PathBuf};
use std::sync::{Arc, Mutex};
use std::time::Duration;

/// Headless runs last this long unless `--duration` says otherwise, s.
pub const DEFAULT_DURATION_S: f64 = 10.0;

/// The graph the flags name (`--graph`, default the chapter's), with `--rate` and
/// `--depth` applied.
pub fn graph_from_args(g: &GraphArgs) -> anyhow::Result<GraphSpec> {
    let mut spec = match &g.graph {
        Some(path) => GraphSpec::load(path)?,
        None => GraphSpec::chapter(),
    };
    for (node, hz) in &g.rates {
        spec.set_rate(node, *hz)
            .map_err(|e| anyhow::anyhow!("--rate {node}={hz}: {e}"))?;
    }
    for (topic, depth) in &g.depths {
        spec.set_depth(topic, *depth)
            .map_err(|e| anyhow::anyhow!("--depth {topic}={depth}: {e}"))?;
    }
    for (flag, list) in [("--qos", &g.qos), ("--link", &g.links)] {
        for (topic, pairs) in list {
            if flag == "--link" {
                if let Some((k, _)) = ratelab::qos::split_pairs(pairs)
                    .map_err(|e| anyhow::anyhow!("{flag} {topic}:{pairs}: {e}"))?
                    .into_iter()
                    .find(|(k, _)| !ratelab::qos::LINK_KEYS.contains(k))
                {
                    anyhow::bail!(
                        "--link {topic}:{pairs}: '{k}' is not a link key ({}); use --qos",
                        ratelab::qos::LINK_KEYS.join(", ")
                    );
                }
            }
            spec.set_qos(topic, pairs)
                .map_err(|e| anyhow::anyhow!("{flag} {topic}:{pairs}: {e}"))?;
        }
    }
    for (node, ms) in &g.leases {
        spec.set_lease(node, *ms)
            .map_err(|e| anyhow::anyhow!("--lease {node}={ms}: {e}"))?;
    }
    if let Some(over) = g.executor {
        spec.set_executor(over);
    }
    for (node, c) in &g.computes {
        spec.set_compute(node, *c)?;
    }
    for w in spec.qos_warnings() {
        eprintln!("[ratelab] {w}");
    }
    Ok(spec)
}

/// The faults the flags inject (`--stall`, then `--kill`).
pub fn faults_from_args(g: &GraphArgs) -> Vec<ratelab::qos::Fault> {
    g.stalls.iter().chain(&g.kills).cloned().collect()
}

/// The run settings the flags describe (`--smoke` and `--break` applied).
pub fn config_from_args(a: &RunArgs) -> anyhow::Result<RunConfig> {
    let mut cfg = RunConfig {
        seed: a.seed,
        duration: ratelab::config::duration_from_secs(a.duration.unwrap_or(DEFAULT_DURATION_S))?,
        graph: graph_from_args(&a.graph)?,
        clock: a.clock,
        spin_margin: Nanos(a.spin_margin_us.unwrap_or(0).saturating_mul(1_000)),
        rt_priority: a.rt_priority,
        faults: faults_from_args(&a.graph),
        ..RunConfig::default()
    };
    let policy = cfg.graph.chain.map(|c| cfg.graph.node(c.policy));
    if let (Some(python), false) = (
        policy.and_then(|p| p.python.as_ref()),
        a.policy == "scripted",
    ) {
        let policy = policy.expect("a Python policy node");
        // A brain is what a built-in policy node runs; a Python node is its own brain.
        anyhow::bail!(
            "--policy {}: graph '{}' has a Python node as its policy ('{}', {}), which computes its own actions; --policy is for a graph whose policy is kind = \"policy\"",
            a.policy,
            cfg.graph.name,
            policy.name,
            python.script
        );
    }
    if a.policy != "scripted" && !cfg.graph.nodes.iter().any(|n| n.kind.def().uses_brain) {
        anyhow::bail!(
            "--policy {}: graph '{}' has no node that runs a brain (kind = \"policy\"); its nodes compute their own actions",
            a.policy,
            cfg.graph.name
        );
    }
    // Two shorthands for the policy's rate would leave one of them ignored.
    if let (true, Some(hz)) = (a.break_, a.control_hz.filter(|hz| *hz != BREAK_CONTROL_HZ)) {
        anyhow::bail!(
            "--break sets the policy to {BREAK_CONTROL_HZ} Hz and --control-hz to {hz} Hz; give one"
        );
    }
    // A chain shorthand and a `--rate` for the same node would leave one of them ignored.
    let control_hz = if a.break_ {
        Some(BREAK_CONTROL_HZ)
    } else {
        a.control_hz
    };
    let chain = cfg.graph.chain;
    for (flag, hz, node) in [
        ("--sensor-hz", a.sensor_hz, chain.map(|c| c.sensor)),
        (
            if a.break_ { "--break" } else { "--control-hz" },
            control_hz,
            chain.map(|c| c.policy),
        ),
    ] {
        let Some(node) = node else { continue }; // refused below, naming the flag
        let name = &cfg.graph.node(node).name;
        if let (Some(hz), Some((_, rate))) = (hz, a.graph.rates.iter().find(|(n, _)| n == name)) {
            if hz != *rate {
                anyhow::bail!(
                    "--rate {name}={rate} and {flag} ({hz} Hz) both set the rate of node '{name}'; give one"
                );
            }
        }
    }
    // Each shorthand of the chain refuses a graph without it, by its own name.
    for (flag, given) in [
        ("--sensor-hz", a.sensor_hz.is_some()),
        ("--break", a.break_),
        ("--control-hz", a.control_hz.is_some()),
    ] {
        if given {
            cfg.graph.chain_for(flag)?;
        }
    }
    if let Some(hz) = a.sensor_hz {
        cfg.set_sensor_hz(hz)?;
    }
    match (a.break_, a.control_hz) {
        (true, _) => cfg.set_control_hz(BREAK_CONTROL_HZ)?,
        (false, Some(hz)) => cfg.set_control_hz(hz)?,
        (false, None) => {}
    }
    if let Some(depth) = a.queue_depth {
        cfg.set_queue_depth(depth)?;
    }
    cfg.phase_offsets = phase_offsets_from_ms(&a.phase_offset_ms, &cfg.graph.node_names())?;
    if a.smoke {
        cfg.clock = ClockKind::Virtual;
        cfg.duration = Nanos(2 * Nanos::SECOND.0);
    }
    if a.spin_margin_us.is_none() {
        cfg.spin_margin = cfg.default_spin_margin();
    }
    cfg.validate()?;
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

/// Run headless and print the summary. Returns the report.
/// `--ros2` as `a` gives it (the domain from the flag or `ROS_DOMAIN_ID`, the bag), checked
/// against `graph` before anything opens: ROS 2's names, `/clock`, the bag's folder. Without
/// `--ros2` the graph must have no external node (nothing else could fill it). Used by
/// `run`, the lab and a launch.
///
/// # Errors
/// The first problem, in one line (exit 2).
pub fn ros2_options(
    a: &RunArgs,
    graph: &GraphSpec,
) -> anyhow::Result<Option<ratelab::ros2::Ros2Options>> {
    let opts =
        a.ros2_domain()
            .map_err(anyhow::Error::msg)?
            .map(|domain| ratelab::ros2::Ros2Options {
                domain,
                bag: a.bag.clone(),
                force: a.force,
            });
    match &opts {
        Some(o) => ratelab::ros2::bridge::check(graph, o),
        None => ratelab::ros2::external::check_offered(graph),
    }
    .map_err(anyhow::Error::msg)?;
    Ok(opts)
}

/// The ROS 2 session, opened as rmw_zenoh's nodes open theirs (with an embedded router when
/// none answers), from the process's `ZENOH_*` variables; `stop` ends a wait for a router.
///
/// # Errors
/// A bad variable or a failed session, in one line.
pub fn open_ros2(stop: &StopFlag) -> anyhow::Result<ratelab::ros2::session::Ros2Session> {
    let env = ratelab::ros2::session::SessionEnv::from_process();
    Ok(ratelab::ros2::session::open(&env, stop)?)
}

pub fn run_headless(a: &RunArgs, stop: StopFlag) -> anyhow::Result<RunReport> {
    let cfg = config_from_args(a)?;
    warn_late_faults(&cfg);
    let brain = ratelab::checkpoint::load_policy(&a.policy)?;
    check_out(a, &cfg.graph)?;
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
    let (report, kept, recording) = execute(a, &cfg, brain, stop, observers, true)?;
    if let Some(bar) = virtual_bar {
        bar.finish_and_clear();
    }
    // A recording that could not be finished (a full disk) fails the run after its summary
    // and the other files: it costs the file, not the run's result.
    let unrecorded = finish_recording(a, recording.as_ref(), &report);
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

/// `--out`'s folder made, and its files checked before the run, not after it (refused when
/// they will not be writable).
///
/// # Errors
/// The folder cannot be made, or a file is there without `--force`.
pub fn check_out(a: &RunArgs, graph: &GraphSpec) -> anyhow::Result<()> {
    if let Some(dir) = &a.out {
        std::fs::create_dir_all(dir)
            .with_context(|| format!("cannot create --out folder {}", dir.display()))?;
        // Refuse before the run, not after it: the outputs will not be writable.
        let estimator = graph.estimate_topic().map(|_| ESTIMATOR_JSON);
        for name in ["metrics.json", "trace.csv"].into_iter().chain(estimator) {
            ratelab::output::check_target(&dir.join(name), a.force)?;
        }
    }
    Ok(())
}

/// With an estimator in the graph, `--out`'s file of its error and lag against the truth
/// ([`ratelab::estimate::EstimateReport`]; not in `metrics.json`, whose bytes the reference
/// runs fix).
pub const ESTIMATOR_JSON: &str = "estimator.json";

/// The lines nodes wrote, as `log.txt` holds them (one per line, a newline after each).
pub fn log_text(kept: &Mutex<Vec<String>>) -> String {
    let log = kept.lock().unwrap_or_else(|e| e.into_inner()).join("\n");
    if log.is_empty() {
        log
    } else {
        log + "\n"
    }
}

/// What a run kept of the lines its nodes wrote (`log.txt`'s, the first [`MAX_LOG_LINES`]).
pub type KeptLog = Arc<Mutex<Vec<String>>>;

/// Run `cfg` (made from `a`) with `brain`, as `ratelab run` does: the recording `a` asks for
/// opened, ROS 2 offered when asked, `observers` told of every step (trace.csv's writer,
/// [`crate::trace`], is one); every line the nodes write kept (and written to stderr,
/// stamped, when `echo`); no step record kept in the report. Returns the report, the lines
/// kept and the recording (not yet finished: [`finish_recording`]).
///
/// # Errors
/// What keeps the run from starting: bad ROS 2 or recording settings, a graph that cannot be
/// built.
pub fn execute(
    a: &RunArgs,
    cfg: &RunConfig,
    brain: Box<dyn ratelab::policy::Policy>,
    stop: StopFlag,
    observers: Vec<Box<dyn ratelab::graph::StepObserver>>,
    echo: bool,
) -> anyhow::Result<(RunReport, KeptLog, Option<Recording>)> {
    // Refused before anything is written or opened.
    let ros2 = ros2_options(a, &cfg.graph)?;
    let recording = open_recording(a, cfg, &brain.label())?;
    let mut opts = RunOptions {
        stop,
        ros2,
        observers,
        // trace.csv's rows are written by an observer as the run goes (`crate::trace`).
        keep_trace: false,
        trace_every: a.trace_every,
        ..RunOptions::new()
    };
    if let Some(r) = &recording {
        opts.observers.push(r.observer());
        let r = r.clone();
        opts.on_span = r.span_hook();
        opts.on_node_tick = Some(Arc::new(move |t: &ratelab::scheduler::TickReport<'_>| {
            r.real_tick(t)
        }));
    }
    // What nodes' code writes (ratelab::textlog): each line on stderr, stamped, as it comes
    // (when `echo`); kept for log.txt (the first MAX_LOG_LINES); with --record, in the
    // recording (`log/<node>`).
    let kept = log_sink(echo, recording.clone());
    let report = run(cfg, brain, opts);
    ratelab::textlog::set_sink(None);
    Ok((report?, kept, recording))
}

/// Finish the run's recording: `Some(error)` when it could not be finished (a full disk),
/// which fails the run after its summary and other files. With `--spawn` a live viewer
/// that could not start or went away costs neither the file nor the summary.
pub fn finish_recording(
    a: &RunArgs,
    recording: Option<&Recording>,
    report: &RunReport,
) -> Option<ratelab::recording::RecordingError> {
    match recording?.finish(&report.metrics, &report.end) {
        Err(e) if a.spawn => {
            eprintln!("[ratelab] warning: live viewer: {e} (the file is written)");
            None
        }
        Err(e) => Some(e),
        Ok(()) => None,
    }
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

/// Where the lines nodes' code writes go ([`ratelab::textlog`]): each on stderr, stamped,
/// as it comes; with `keep` (`--out`) also kept for log.txt (the first [`MAX_LOG_LINES`],
/// returned); with a recording (`recorded`), in it (`log/<node>`).
fn log_sink(echo: bool, recorded: Option<Recording>) -> KeptLog {
    let kept = Arc::new(Mutex::new(Vec::<String>::new()));
    let keep = kept.clone();
    ratelab::textlog::set_sink(Some(Box::new(move |line| {
        if let Some(r) = &recorded {
            r.log_line(&line);
        }
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

/// A run that reached its summary and files but did not succeed is, after them, an error
/// (exit 2, one line), in every command and process layout (`run`, `launch` in one process
/// or across processes, under either clock): a node that failed (a panic, a Python
/// exception, `sys.exit`), whatever the pole did meanwhile, or [`no_success_is_an_error`]'s
/// cases.
///
/// # Errors
/// One line naming the failed node and its error's first line, or `no_success`'s.
pub fn end_is_an_error(report: &RunReport) -> anyhow::Result<()> {
    if let EndReason::NodeFailed { node, message } = &report.end.reason {
        anyhow::bail!(
            "node '{node}' failed at t={:.2}s: {}",
            report.end.at.as_secs_f64(),
            message.lines().next().unwrap_or("panic")
        );
    }
    no_success_is_an_error(&report.metrics)
}

/// The most lines of the run's text log `--out` keeps in `log.txt` (each is on stderr as
/// well).
pub const MAX_LOG_LINES: usize = 100_000;

/// A run that reached its summary but is no success (`Metrics::no_success`: a deadline
/// watchdog's stop, as a ROS 2 node's deadline-missed handler may stop the system, or an
/// actuator killed within the run) is, after its summary and files, an error (exit 2),
/// never a success that a script could take for a balanced run.
///
/// # Errors
/// One line, `Metrics::no_success`'s.
pub fn no_success_is_an_error(metrics: &ratelab::metrics::Metrics) -> anyhow::Result<()> {
    match metrics.no_success() {
        Some(why) => anyhow::bail!("{why}"),
        None => Ok(()),
    }
}

/// Moves a progress bar to each actuator step's run time, in ms.
struct ProgressObserver(ProgressBar);

impl ratelab::graph::StepObserver for ProgressObserver {
    fn on_step(&mut self, rec: &StepRecord) {
        self.0.set_position(rec.t.0 / 1_000_000);
    }
}

/// The `--record`/`--spawn` recording, checked and opened before the run starts.
pub fn open_recording(
    a: &RunArgs,
    cfg: &RunConfig,
    policy: &str,
) -> anyhow::Result<Option<Recording>> {
    if a.record.is_none() && !a.spawn {
        return Ok(None);
    }
    let path: PathBuf = match a.record.clone().flatten() {
        Some(p) => p,
        None => default_path(Path::new("recordings"), cfg),
    };
    check_output_path(&path, a.force)?;
    let (recording, notice) = Recording::create_with(
        &path,
        cfg,
        policy,
        &RecordOptions {
            spawn: a.spawn,
            window: a.record_window,
        },
        a.force,
    )?;
    if let Some(n) = notice {
        eprintln!("[ratelab] {n}");
    }
    Ok(Some(recording))
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

/// `trace.csv` as [`write_outputs`] puts it in place.
pub enum TraceCsv<'a> {
    /// Written to a temporary file beside its name as the run went (`ratelab run --out`):
    /// moved into place.
    Streamed(TraceFile),
    /// Held whole (`ratelab.run`, which returns it): written.
    Held(&'a [u8]),
}

/// `metrics.json` (pretty, stable key order), `trace.csv` (one row per actuator tick kept:
/// `trace`) and `log.txt` (the lines nodes wrote, `log`), each through [`ratelab::output`]
/// (never over an existing file unless `force`).
pub fn write_outputs(
    dir: &Path,
    report: &RunReport,
    log: &str,
    force: bool,
    trace: TraceCsv<'_>,
) -> anyhow::Result<()> {
    // Every name is checked before any is written, so a refusal writes nothing.
    let (metrics, trace_csv) = (dir.join("metrics.json"), dir.join("trace.csv"));
    ratelab::output::check_target(&metrics, force)?;
    ratelab::output::check_target(&trace_csv, force)?;
    ratelab::output::check_target(&dir.join("log.txt"), force)?;
    let estimator = report
        .metrics
        .estimate
        .as_ref()
        .map(|e| (dir.join(ESTIMATOR_JSON), e));
    if let Some((path, _)) = &estimator {
        ratelab::output::check_target(path, force)?;
    } else if force {
        // Replacing a run's files: another run's estimator figures do not stay beside them.
        match std::fs::remove_file(dir.join(ESTIMATOR_JSON)) {
            Err(e) if e.kind() != std::io::ErrorKind::NotFound => {
                anyhow::bail!("cannot remove {}: {e}", dir.join(ESTIMATOR_JSON).display())
            }
            _ => {}
        }
    }
    let json = serde_json::to_string_pretty(&report.metrics)? + "\n";
    ratelab::output::write_file(&metrics, force, json.as_bytes())?;
    if let Some((path, e)) = &estimator {
        let json = serde_json::to_string_pretty(e)? + "\n";
        ratelab::output::write_file(path, force, json.as_bytes())?;
    }
    match trace {
        TraceCsv::Streamed(file) => file.commit()?,
        TraceCsv::Held(bytes) => ratelab::output::write_file(&trace_csv, force, bytes)?,
    }
    ratelab::output::write_file(&dir.join("log.txt"), force, log.as_bytes())?;
    Ok(())
}
