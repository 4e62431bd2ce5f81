//! `ratelab launch`, `ratelab process` and `ratelab lab --attach`: the graph across processes
//! ([`ratelab::distributed`]), from the command line.

use crate::cli::{LaunchArgs, ProcessArgs, RouterArgs};
use crate::headless;
use ratelab::distributed::check_endpoint;
use ratelab::distributed::credentials::{Credentials, Role};
use ratelab::distributed::launcher::{launch, LaunchOptions, LaunchReport, LISTENING};
use ratelab::distributed::monitor::{Signals, Watch};
use ratelab::distributed::process::ProcessOptions;
use ratelab::graph::spec::graph_file_bytes;
use ratelab::scheduler::StopFlag;
use ratelab::session::Telemetry;
use ratelab::RunReport;
use ratelab::{ClockKind, RunConfig};
use std::io::{IsTerminal, Write};
use std::path::Path;
use std::time::Duration;

/// `ratelab launch [GRAPH] [--processes]`. On a terminal (and without `--headless`) a launch
/// across processes opens the lab on it (as `ratelab lab --attach` would); otherwise it
/// prints progress lines and the summary.
pub fn run_launch(a: &LaunchArgs, force_headless: bool, stop: StopFlag) -> anyhow::Result<()> {
    let mut run = a.run.clone();
    match (&a.file, &run.graph.graph) {
        (Some(_), Some(_)) => anyhow::bail!("give the graph once: as GRAPH or as --graph"),
        (Some(f), None) => run.graph.graph = Some(f.clone()),
        _ => {}
    }
    if !a.processes {
        if a.listen.is_some()
            || a.no_spawn
            || a.export_credentials.is_some()
            || !a.kill_processes.is_empty()
            || a.star
        {
            anyhow::bail!(
                "--listen, --no-spawn, --export-credentials, --kill-process and --star need --processes"
            );
        }
        headless::check_trace_every(&run)?;
        return headless::run_headless(&run, stop).map(|_| ());
    }
    refuse_across_processes(&run)?;
    let on_terminal =
        !force_headless && std::io::stdout().is_terminal() && std::io::stdin().is_terminal();
    let mut cfg = headless::config_from_args(&run)?;
    let outputs = ratelab::run_spec::RunSpec::from(&run).outputs;
    let ros2 = ratelab::outputs::ros2_options(&outputs, &cfg.graph)?;
    ratelab::ros2::external::check_placement(&cfg.graph).map_err(anyhow::Error::msg)?;
    // Across processes each process spins its own executors: `--executor` makes one per
    // process; an [executors] table must hold one process's nodes.
    if let Some(over) = run.graph.executor {
        cfg.graph.set_executor_per_process(over);
    }
    cfg.graph
        .check_executors_per_process()
        .map_err(anyhow::Error::msg)?;
    // Refused before anything is said of the placement (a line naming 49,151 processes).
    ratelab::distributed::check_keys(&cfg.graph)?;
    // A malformed --listen too (a port in use is known only when the router opens).
    (a.listen.iter()).try_for_each(|ep| check_endpoint("--listen", ep, true))?;
    if on_terminal && run.duration.is_none() && !run.smoke {
        cfg.duration = ratelab::session::UNBOUNDED; // as the lab: until you quit
    }
    headless::warn_late_faults(&cfg);
    let kill_processes = kills_of(a, &cfg)?;
    let brain = ratelab::checkpoint::load_policy(&run.policy)?; // a bad --policy fails before any process starts
    if let Some(dir) = &run.out {
        std::fs::create_dir_all(dir)
            .map_err(|e| anyhow::anyhow!("cannot create --out folder {}: {e}", dir.display()))?;
        ratelab::output::check_writable(&dir.join("metrics.json"), run.force)?;
    }
    if a.no_spawn && a.export_credentials.is_none() {
        anyhow::bail!("--no-spawn waits for processes started by hand, which need the launch's credentials: give --export-credentials FILE");
    }
    // This launch's CA and identities; exported for processes started by hand.
    let names: Vec<String> = cfg.graph.placement().into_iter().map(|(p, _)| p).collect();
    let credentials = Credentials::generate(&cfg.graph.name, &names)?;
    if let Some(f) = &a.export_credentials {
        credentials.write(f, run.force)?;
        println!(
            "[ratelab] launch: wrote the launch's credentials to {} (a secret: whoever holds it can join)",
            f.display()
        );
    }
    // --ros2: checked, and the session (with the embedded router when none answers) opened
    // before any process starts, so that each finds the router and offers its own nodes.
    let ros2_domain = ros2.as_ref().map(|o| o.domain);
    let _ros2 = ros2_domain
        .map(|domain| offer_ros2(domain, &cfg.graph, &stop))
        .transpose()?;
    let graph_path = run.graph.graph.clone();
    let opts = LaunchOptions {
        graph_bytes: graph_file_bytes(graph_path.as_deref())?,
        graph_path,
        listen: a.listen.clone(),
        policy: run.policy.clone(),
        exe: if a.no_spawn {
            None
        } else {
            Some(ratelab::distributed::launcher::Program::this()?)
        },
        child_stderr: None,
        start_gate: None,
        listening: None,
        pace: None,
        credentials,
        ros2_domain,
        kill_processes,
        star: a.star,
    };
    let placed = cfg.graph.placement().len();
    println!(
        "[ratelab] launch: graph '{}' in {placed} process{}: {}",
        cfg.graph.name,
        if placed == 1 { "" } else { "es" },
        placement_line(&cfg.graph)
    );
    let recording = ratelab::outputs::open_recording(
        &outputs,
        &cfg,
        &brain.label(),
        ratelab::setting::Speech::Flags,
    )?;
    let report = if on_terminal || recording.is_some() {
        launch_watched(cfg, opts, &stop, on_terminal, recording.as_ref())?
    } else {
        launch_unwatched(&cfg, opts, &stop)?
    };
    let (wire, lockstep, missing) = (report.wire, report.lockstep, report.missing);
    let report = RunReport {
        metrics: report.metrics,
        trace: Vec::new(),
        end: report.end,
        wall: report.wall,
        ros2: None,
    };
    headless::print_figures(&report);
    for w in &wire {
        println!("[ratelab] {}", wire_line(w));
    }
    if let Some(l) = lockstep {
        println!(
            "[ratelab] lockstep: {} ticks at {} instants, {:.0} µs of wall time per instant",
            l.ticks, l.instants, l.us_per_instant
        );
    }
    headless::print_end(&report);
    if let Some(dir) = &run.out {
        let json = serde_json::to_string_pretty(&report.metrics)? + "\n";
        ratelab::output::write_file(&dir.join("metrics.json"), run.force, json.as_bytes())?;
        println!("[ratelab] wrote {}", dir.join("metrics.json").display());
    }
    if let Some(r) = &recording {
        println!("[ratelab] recording: {}", r.path().display());
        println!("[ratelab] {}", ratelab::recording::open_hint(r.path()));
    }
    anyhow::ensure!(
        missing.is_empty(),
        "process(es) {} did not report: their nodes' figures are missing from the summary",
        ratelab::text::listed(missing.iter().map(String::as_str))
    );
    ratelab::outputs::end_is_an_error(&report)
}

/// The run flags a launch across processes cannot honour, refused in one line each rather
/// than ignored: a bag, a session log, a thinned trace.csv (it writes none).
fn refuse_across_processes(run: &crate::cli::RunArgs) -> anyhow::Result<()> {
    if run.trace_every > 1 {
        anyhow::bail!("--trace-every thins trace.csv, which a launch across processes does not write (its --out holds metrics.json)");
    }
    if run.bag.is_some() {
        anyhow::bail!("--bag writes a bag of a run in one process (run --ros2): a launch across processes does not write one yet");
    }
    if run.session.is_some() {
        anyhow::bail!("--session is not available with --processes: a launch takes no live commands to log (its lab only watches)");
    }
    Ok(())
}

/// `--kill-process`'s kills, checked: each names a process of the graph that this launch
/// starts, under the real clock, at a time within the run.
///
/// # Errors
/// One line: the virtual clock (its lockstep cannot go on without a process, nor take one
/// back), `--no-spawn`, a time at the start or past the end, or a process the graph does
/// not have.
fn kills_of(a: &LaunchArgs, cfg: &RunConfig) -> anyhow::Result<Vec<(String, ratelab::Nanos)>> {
    if a.kill_processes.is_empty() {
        return Ok(Vec::new());
    }
    if cfg.clock != ClockKind::Real {
        anyhow::bail!("--kill-process needs --clock real: under the virtual clock the processes run in lockstep, which a killed process would stop, and none can rejoin");
    }
    if a.no_spawn {
        anyhow::bail!("--kill-process kills processes this launch starts: not with --no-spawn");
    }
    let names: Vec<String> = cfg.graph.placement().into_iter().map(|(p, _)| p).collect();
    a.kill_processes
        .iter()
        .enumerate()
        .map(|(i, k)| {
            if a.kill_processes[..i].contains(k) {
                Err(anyhow::anyhow!(
                    "--kill-process {}@{} is given twice: give it once",
                    ratelab::text::printable(&k.node),
                    k.at.as_secs_f64()
                ))
            } else if k.at == ratelab::Nanos::ZERO || k.at >= cfg.duration {
                Err(anyhow::anyhow!(
                    "--kill-process {}@{}: the time must be within the run, after its start and before its end at {} s",
                    ratelab::text::printable(&k.node),
                    k.at.as_secs_f64(),
                    cfg.duration.as_secs_f64()
                ))
            } else if names.contains(&k.node) {
                Ok((k.node.clone(), k.at))
            } else {
                Err(anyhow::anyhow!(
                    "--kill-process: graph '{}' has no process '{}' (its processes: {})",
                    cfg.graph.name,
                    ratelab::text::printable(&k.node),
                    ratelab::text::listed(names.iter().map(String::as_str))
                ))
            }
        })
        .collect()
}

/// `--ros2` across processes: the ROS 2 session (with the embedded router when none
/// answers) opened before any process starts, so that each finds the router and offers its
/// own nodes; said in one line.
fn offer_ros2(
    domain: u32,
    spec: &ratelab::graph::GraphSpec,
    stop: &StopFlag,
) -> anyhow::Result<ratelab::ros2::session::Ros2Session> {
    let link = ratelab::outputs::open_ros2(stop)?;
    println!(
        "[ratelab] launch: offering the graph to ROS 2 on domain {domain}: each process its own nodes, {} /clock, {}",
        if spec.first_external().is_some() {
            "the external nodes' process"
        } else {
            "the plant's process"
        },
        link.router.via()
    );
    Ok(link)
}

/// A launch nobody watches (no terminal, no recording): its lines printed as they come,
/// its endpoint recorded for `lab --attach` and `top` once it listens (removed when it
/// ends).
fn launch_unwatched(
    cfg: &ratelab::RunConfig,
    mut opts: LaunchOptions,
    stop: &StopFlag,
) -> anyhow::Result<LaunchReport> {
    let (listening_tx, listening_rx) = crossbeam_channel::bounded::<String>(1);
    opts.listening = Some(listening_tx);
    let observer = opts.credentials.only(&Role::Observer)?;
    let recorder = std::thread::spawn(move || {
        let ep = listening_rx.recv().ok()?;
        crate::rendezvous::record(&ep, &observer, &mut |w| eprintln!("[ratelab] launch: {w}"))
    });
    let report = launch(cfg, &opts, stop, &|line| {
        println!("[ratelab] launch: {line}")
    });
    drop(opts);
    let _recorded = recorder.join();
    Ok(report?)
}

/// The placement as one line: `robot [sensor, actuator], policy [policy]`.
fn placement_line(spec: &ratelab::graph::GraphSpec) -> String {
    let placement = spec.placement();
    // A large graph's line stays readable: its first nodes in each process, the rest
    // counted (`ratelab top` lists them all), and past PLACED_PROCESSES processes, a count.
    let per_process = match placement.len() {
        0..=3 => ratelab::text::LISTED_NAMES,
        _ => PLACED_NAMES_MANY,
    };
    let mut line = placement
        .iter()
        .take(PLACED_PROCESSES)
        .map(|(p, ids)| {
            let names = ids.iter().map(|i| spec.node(*i).name.as_str());
            format!(
                "{p} [{}]",
                ratelab::text::listed_at_most(names, per_process)
            )
        })
        .collect::<Vec<_>>()
        .join(", ");
    if let Some(more) = placement
        .len()
        .checked_sub(PLACED_PROCESSES)
        .filter(|n| *n > 0)
    {
        line.push_str(&format!(" and {more} more processes"));
    }
    line
}

/// The most processes the launch's placement line names.
const PLACED_PROCESSES: usize = 16;
/// The most nodes of each process the placement line names in a launch of 4 processes or
/// more (of 3 or fewer, [`ratelab::text::LISTED_NAMES`]).
const PLACED_NAMES_MANY: usize = 4;

/// A crossing topic's time on the wire, as the summary says it (a process that rejoined
/// counts from its rejoin, and the line says so, at the time the launcher's line and the
/// recording give it: `rejoined at t=3.110s`).
fn wire_line(w: &ratelab::distributed::wire::WireLink) -> String {
    let since = w.since_ns.map_or(String::new(), |t| {
        format!(" since its rejoin at {:.3} s", t as f64 / 1e9)
    });
    let in_place = match (w.in_place, w.drawn_in_place) {
        (0, _) => String::new(),
        (n, 0) => format!(" | {n} read in place from shared memory"),
        (n, d) => format!(" | {n} read in place from shared memory | {d} as their node drew them"),
    };
    format!(
        "wire {} into '{}': {} samples{since}, p50 {:.1} µs | p99 {:.1} µs | max {:.1} µs{in_place}",
        w.topic, w.process, w.samples, w.p50_us, w.p99_us, w.max_us
    )
}

/// The most lines of the started processes' stderr kept while the lab is on the terminal.
const MAX_HELD_STDERR_LINES: usize = 1000;

/// Run the launch on a thread and watch it ([`Watch`]): with `lab`, the lab on the
/// terminal (when the user quits, the launch is stopped: every process it started); with
/// `recording`, every merged step into it ([`ratelab::distributed::monitor::record`]),
/// finished with the merged summary. The launcher's progress lines are printed as they come
/// without the lab, and after the terminal is restored with it (the lab shows them
/// meanwhile).
///
/// The run starts once the watcher has figures from every process (the launcher's start
/// gate), so the lab and the recording miss none of it; with the lab, the processes' stderr
/// comes as lines (in the lab's log, and printed after it) rather than over its screen.
fn launch_watched(
    cfg: ratelab::RunConfig,
    mut opts: LaunchOptions,
    stop: &StopFlag,
    lab: bool,
    recording: Option<&ratelab::recording::Recording>,
) -> anyhow::Result<LaunchReport> {
    let (line_tx, line_rx) = crossbeam_channel::unbounded::<String>();
    let (gate_tx, gate_rx) = crossbeam_channel::bounded::<()>(1);
    opts.start_gate = Some(gate_rx);
    let (listening_tx, listening_rx) = crossbeam_channel::bounded::<String>(1);
    opts.listening = Some(listening_tx);
    // The lab follows a virtual-clock run at ×1, as it does in one process.
    if lab {
        opts.pace = Some(1.0);
    }
    // The processes' stderr while the lab is up: the first lines, printed after it (the
    // lab shows every line meanwhile, from the log key).
    let (err_tx, err_rx) = crossbeam_channel::bounded::<String>(MAX_HELD_STDERR_LINES);
    if lab {
        opts.child_stderr = Some(err_tx);
    } else {
        drop(err_tx);
    }
    let observer = opts.credentials.only(&Role::Observer)?;
    // Set when the launcher returns (or the user stops it): the watcher stops waiting.
    let launcher_done = StopFlag::new();
    let launcher = spawn_launcher(&cfg, opts, stop, &launcher_done, line_tx)?;
    let joined = |launcher: std::thread::JoinHandle<Result<LaunchReport, _>>| match launcher.join()
    {
        Ok(r) => Ok(r?),
        Err(_) => Err(anyhow::anyhow!("the launcher stopped unexpectedly")),
    };
    let mut held = Vec::new();
    let mut line = |l: String| match lab {
        // Where it listens is said at once, below: not again after the lab.
        true => held.extend((!l.starts_with(LISTENING)).then_some(l)),
        false => println!("[ratelab] launch: {l}"),
    };
    // The launcher tells where it listens, before anything else; the watcher connects
    // there. Its lines meanwhile (none yet, or the error that stopped it) pass on.
    let endpoint = loop {
        if let Ok(ep) = listening_rx.recv_timeout(Duration::from_millis(100)) {
            break ep;
        }
        for l in line_rx.try_iter() {
            line(l);
        }
        if launcher.is_finished() {
            for l in line_rx.try_iter() {
                line(l);
            }
            return joined(launcher);
        }
    };
    // Recorded for `lab --attach` and `top` (removed when the launch ends), and said at once:
    // a launch that got another port than 7449 is found all the same.
    let _recorded = crate::rendezvous::record(&endpoint, &observer, &mut line);
    if lab {
        eprintln!("[ratelab] launch: {LISTENING}{endpoint}");
    }
    let mut watch = match Watch::connect(
        std::slice::from_ref(&endpoint),
        &observer,
        ratelab::distributed::REPLY_TIMEOUT,
        &launcher_done,
    ) {
        Ok(w) => w,
        Err(e) => {
            // The launcher's own error, when it failed, says more than the watcher's.
            stop.stop();
            joined(launcher)?;
            return Err(e.into());
        }
    };
    watch.recording = recording.map(|r| r.path().to_path_buf());
    let policy = watch.setup.policy.clone();
    let (lab_tx, lab_rx) = crossbeam_channel::unbounded::<Telemetry>();
    let (rec_tx, rec_rx) = crossbeam_channel::unbounded::<Telemetry>();
    let mut sinks = Vec::new();
    if lab {
        sinks.push(lab_tx);
    }
    let recorder = match recording {
        Some(rec) => {
            sinks.push(rec_tx);
            Some(spawn_recorder(rec, &cfg, rec_rx)?)
        }
        None => {
            drop(rec_rx);
            None
        }
    };
    let (fin_tx, fin_rx) = crossbeam_channel::bounded::<()>(1);
    let signals = Signals {
        watching: Some(gate_tx),
        finished: Some(fin_tx),
    };
    let (watch_stop, watcher) = spawn_watch(watch, sinks, signals)?;
    let lab_result = if lab {
        let r = crate::tui::run_attached(policy, &cfg.graph, Some(&endpoint), &lab_rx, stop);
        stop.stop(); // the user quit: end the launch, if it is still running
        r
    } else {
        while !launcher.is_finished() {
            if let Ok(l) = line_rx.recv_timeout(Duration::from_millis(100)) {
                line(l);
            }
        }
        Ok(())
    };
    let report = joined(launcher);
    for l in line_rx.try_iter() {
        line(l);
    }
    // The processes' last figures (they leave before each process's report, but on
    // another link): wait for them, a little (none come from a launch that failed early).
    if report.is_ok() {
        let _ = fin_rx.recv_timeout(Duration::from_secs(2));
    }
    watch_stop.stop();
    let watched = watcher.join();
    if let Some(r) = recorder {
        r.join()
            .map_err(|_| anyhow::anyhow!("the recorder stopped unexpectedly"))??;
    }
    print_held(held, &err_rx);
    lab_result?;
    let report = report?;
    if let Some(rec) = recording {
        finish_recording(rec, &cfg, &report)?;
    }
    match watched {
        Ok(r) => r?,
        Err(_) => anyhow::bail!("the watcher stopped unexpectedly"),
    }
    Ok(report)
}

/// Run the launcher on a thread, its lines sent to `lines`; `done` is set when it returns.
fn spawn_launcher(
    cfg: &ratelab::RunConfig,
    opts: LaunchOptions,
    stop: &StopFlag,
    done: &StopFlag,
    lines: crossbeam_channel::Sender<String>,
) -> anyhow::Result<std::thread::JoinHandle<Result<LaunchReport, ratelab::distributed::DistError>>>
{
    let (stop, cfg, done) = (stop.clone(), cfg.clone(), done.clone());
    Ok(std::thread::Builder::new()
        .name("launcher".into())
        .spawn(move || {
            let r = launch(&cfg, &opts, &stop, &|line| {
                let _ = lines.send(line.to_string());
            });
            done.stop();
            r
        })?)
}

/// Record what a watcher of the launch follows (`rx`) into `rec`, on a thread.
fn spawn_recorder(
    rec: &ratelab::recording::Recording,
    cfg: &ratelab::RunConfig,
    rx: crossbeam_channel::Receiver<Telemetry>,
) -> anyhow::Result<std::thread::JoinHandle<Result<(), ratelab::recording::RecordingError>>> {
    let (rec, cfg) = (rec.clone(), cfg.clone());
    Ok(std::thread::Builder::new()
        .name("recorder".into())
        .spawn(move || ratelab::recording::watched::record(&rec, &cfg, &rx))?)
}

/// After the lab: the launcher's lines it held, then the processes' stderr lines it held
/// (the first [`MAX_HELD_STDERR_LINES`], and a line saying so when there were more).
fn print_held(held: Vec<String>, err_rx: &crossbeam_channel::Receiver<String>) {
    for l in held {
        println!("[ratelab] launch: {l}");
    }
    let cut = err_rx.is_full();
    for l in err_rx.try_iter() {
        eprintln!("[ratelab] {l}");
    }
    if cut {
        eprintln!("[ratelab] (the processes' stderr lines after the first {MAX_HELD_STDERR_LINES} are not kept)");
    }
}

/// End a launch's recording: its processes and each crossing topic's wire latency in the
/// summary, then the run's figures.
fn finish_recording(
    rec: &ratelab::recording::Recording,
    cfg: &ratelab::RunConfig,
    report: &LaunchReport,
) -> anyhow::Result<()> {
    rec.summary_line(format!("processes: {}", placement_line(&cfg.graph)));
    for w in &report.wire {
        rec.summary_line(wire_line(w));
    }
    rec.finish(&report.metrics, &report.end)?;
    Ok(())
}

/// Start `watch` on a thread, its telemetry copied to every sink; returns its stop flag and
/// the thread.
fn spawn_watch(
    watch: Watch,
    sinks: Vec<crossbeam_channel::Sender<Telemetry>>,
    signals: Signals,
) -> anyhow::Result<(
    StopFlag,
    std::thread::JoinHandle<Result<(), ratelab::distributed::DistError>>,
)> {
    let stop = StopFlag::new();
    let watch_stop = stop.clone();
    let handle = std::thread::Builder::new()
        .name("watch".into())
        .spawn(move || {
            let (tx, rx) = crossbeam_channel::unbounded::<Telemetry>();
            let tee = std::thread::spawn(move || {
                for t in rx {
                    for s in &sinks {
                        let _ = s.send(t.clone());
                    }
                }
            });
            let r = watch.run(&tx, &watch_stop, signals);
            drop(tx);
            let _ = tee.join();
            r
        })?;
    Ok((stop, handle))
}

/// `ratelab lab --attach [--connect EP]`: the lab on a graph running across processes
/// (without `--connect`: this user's recorded launch, [`crate::rendezvous`]).
pub fn run_attach(
    connect: &[String],
    credentials: Option<&Path>,
    stop: StopFlag,
) -> anyhow::Result<()> {
    for ep in connect {
        check_endpoint("--connect", ep, false)?;
    }
    if !(std::io::stdout().is_terminal() && std::io::stdin().is_terminal()) {
        // `top` finds this user's launch as the lab does: name an endpoint only if given.
        let top = std::iter::once("ratelab top".to_string())
            .chain(connect.iter().map(|ep| format!("--connect {ep}")))
            .collect::<Vec<_>>()
            .join(" ");
        anyhow::bail!(
            "--attach opens the lab on a terminal; without one, `{top}` prints the same figures as text"
        );
    }
    let crate::rendezvous::Target {
        connect,
        hint,
        credentials,
    } = crate::rendezvous::target(connect, credentials, &crate::rendezvous::launches())?;
    let watch = Watch::connect(&connect, &credentials, Duration::from_secs(5), &stop)
        .map_err(|e| anyhow::anyhow!("{e}: {hint}"))?;
    let (policy, spec) = (watch.setup.policy.clone(), watch.cfg.graph.clone());
    let (tx, rx) = crossbeam_channel::unbounded::<Telemetry>();
    let (watch_stop, watcher) = spawn_watch(watch, vec![tx], Signals::default())?;
    let lab = crate::tui::run_attached(
        policy,
        &spec,
        connect.first().map(String::as_str),
        &rx,
        &stop,
    );
    watch_stop.stop();
    match watcher.join() {
        Ok(r) => r?,
        Err(_) => anyhow::bail!("the watcher stopped unexpectedly"),
    }
    lab
}

/// `ratelab process --process NAME --connect EP`.
pub fn run_process(a: &ProcessArgs, stop: StopFlag) -> anyhow::Result<()> {
    for ep in &a.connect {
        check_endpoint("--connect", ep, false)?;
    }
    for ep in &a.listen {
        check_endpoint("--listen", ep, true)?;
    }
    let credentials = a.credentials.as_deref().ok_or_else(|| {
        anyhow::anyhow!("--credentials FILE is required: a graph admits only processes holding its launch's credentials (`ratelab launch --processes --export-credentials FILE` writes them)")
    })?;
    let opts = ProcessOptions {
        graph_bytes: graph_file_bytes(a.graph.as_deref())?,
        graph_origin: graph_origin(a.graph.as_deref()),
        process: a.process.clone(),
        connect: a.connect.clone(),
        listen: a.listen.clone(),
        credentials: Credentials::load(credentials)?,
        // On stdout: a process started by hand says what happens to it; a launcher's own
        // children have no stdout (their launcher says it).
        say: Some(say_on_stdout),
    };
    ratelab::distributed::process::run_process(&opts, &stop)
        .map_err(|e| said_as(e, &format!("process '{}'", a.process)))
}

/// `ratelab router --connect EP --credentials FILE`: this host's router of a launch
/// ([`ratelab::distributed::host_router`]) until the launch ends or Ctrl-C.
pub fn run_router(a: &RouterArgs, stop: StopFlag) -> anyhow::Result<()> {
    use ratelab::distributed::host_router::{self, HostRouterOptions};
    let opts = HostRouterOptions {
        graph_bytes: graph_file_bytes(a.graph.as_deref())?,
        graph_origin: graph_origin(a.graph.as_deref()),
        connect: a.connect.clone(),
        listen: a.listen.clone(),
        credentials: Credentials::load(&a.credentials)?,
        say: Some(say_on_stdout),
    };
    host_router::serve(&opts, &stop).map_err(|e| said_as(e, "router"))?;
    Ok(())
}

/// `e` as `who` says it (`process 'robot': …`), but a graph file's error as itself, so it
/// prints as `FILE:LINE:COL: error: reason` as every other command prints one.
fn said_as(e: ratelab::distributed::DistError, who: &str) -> anyhow::Error {
    match e {
        ratelab::distributed::DistError::Graph(spec) => spec.into(),
        // A line that names it already (the launcher's refusal) is not named twice.
        e if e.to_string().starts_with(&format!("{who} ")) => anyhow::anyhow!("{e}"),
        e => anyhow::anyhow!("{who}: {e}"),
    }
}

/// How messages name the graph file of `ratelab process` or `ratelab router`: its path, or
/// the chapter's graph file when none was given.
fn graph_origin(graph: Option<&std::path::Path>) -> String {
    graph.map_or_else(
        || "graphs/cartpole.toml".to_string(),
        |p| p.display().to_string(),
    )
}

/// A line a process or router started by hand says on stdout (`[ratelab] …`). Never fatal:
/// one whose stdout was closed runs on, unheard.
fn say_on_stdout(line: &str) {
    let _ = writeln!(std::io::stdout(), "[ratelab] {line}");
}

#[cfg(test)]
mod tests {
    use ratelab::distributed::DistError;

    #[test]
    fn a_hand_started_process_s_error_names_it_once() {
        let said = |e: DistError| super::said_as(e, "process 'robot'").to_string();
        assert_eq!(
            said(DistError::Usage("the launcher went away".into())),
            "process 'robot': the launcher went away"
        );
        // The launcher's refusal names it already.
        assert_eq!(
            said(DistError::Usage(
                "process 'robot' was given a different graph file than the launcher".into()
            )),
            "process 'robot' was given a different graph file than the launcher"
        );
    }
}
