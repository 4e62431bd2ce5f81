//! `ratelab launch`, `ratelab process` and `ratelab top`: the graph across processes
//! ([`ratelab::distributed`]), from the command line.

use crate::cli::{LaunchArgs, ProcessArgs, TopArgs};
use crate::headless;
use ratelab::distributed::credentials::{Credentials, Role};
use ratelab::distributed::launcher::{launch, LaunchOptions, LaunchReport};
use ratelab::distributed::monitor::{
    ask_graph, placed_processes, Carried, PlacedProcess, Signals, Watch,
};
use ratelab::distributed::process::{LiveStats, ProcessOptions};
use ratelab::distributed::zenoh::{self, Wait};
use ratelab::distributed::{check_endpoint, live_tokens, open_session, Access};
use ratelab::graph::spec::graph_file_bytes;
use ratelab::scheduler::StopFlag;
use ratelab::session::Telemetry;
use ratelab::RunReport;
use std::collections::BTreeMap;
use std::io::{IsTerminal, Write};
use std::path::Path;
use std::time::{Duration, Instant};

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
        if a.listen.is_some() || a.no_spawn || a.export_credentials.is_some() {
            anyhow::bail!("--listen, --no-spawn and --export-credentials need --processes");
        }
        return headless::run_headless(&run, stop).map(|_| ());
    }
    if run.bag.is_some() {
        anyhow::bail!("--bag writes a bag of a run in one process (run --ros2): a launch across processes does not write one yet");
    }
    if run.session.is_some() {
        anyhow::bail!("--session is not available with --processes: a launch takes no live commands to log (its lab only watches)");
    }
    let on_terminal =
        !force_headless && std::io::stdout().is_terminal() && std::io::stdin().is_terminal();
    let mut cfg = headless::config_from_args(&run)?;
    let ros2 = headless::ros2_options(&run, &cfg.graph)?;
    ratelab::ros2::external::check_placement(&cfg.graph).map_err(anyhow::Error::msg)?;
    // Across processes each process spins its own executors: `--executor` makes one per
    // process; an [executors] table must hold one process's nodes.
    if let Some(over) = run.graph.executor {
        cfg.graph.set_executor_per_process(over);
    }
    cfg.graph
        .check_executors_per_process()
        .map_err(anyhow::Error::msg)?;
    if on_terminal && run.duration.is_none() && !run.smoke {
        cfg.duration = ratelab::session::UNBOUNDED; // as the lab: until you quit
    }
    headless::warn_late_faults(&cfg);
    let brain = ratelab::checkpoint::load_policy(&run.policy)?; // a bad --policy fails before any process starts
    if let Some(dir) = &run.out {
        std::fs::create_dir_all(dir)
            .map_err(|e| anyhow::anyhow!("cannot create --out folder {}: {e}", dir.display()))?;
        ratelab::output::check_target(&dir.join("metrics.json"), run.force)?;
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
    };
    let placed = cfg.graph.placement().len();
    println!(
        "[ratelab] launch: graph '{}' in {placed} process{}: {}",
        cfg.graph.name,
        if placed == 1 { "" } else { "es" },
        placement_line(&cfg.graph)
    );
    let recording = headless::open_recording(&run, &cfg, &brain.label())?;
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
    headless::print_summary(&report);
    for w in &wire {
        println!("[ratelab] {}", wire_line(w));
    }
    if let Some(l) = lockstep {
        println!(
            "[ratelab] lockstep: {} ticks at {} instants, {:.0} µs of wall time per instant",
            l.ticks, l.instants, l.us_per_instant
        );
    }
    if let Some(dir) = &run.out {
        let json = serde_json::to_string_pretty(&report.metrics)? + "\n";
        ratelab::output::write_file(&dir.join("metrics.json"), run.force, json.as_bytes())?;
        println!("[ratelab] wrote {}", dir.join("metrics.json").display());
    }
    if let Some(r) = &recording {
        println!("[ratelab] recording: {}", r.path().display());
        println!("[ratelab] open it with: rerun {}", r.path().display());
    }
    anyhow::ensure!(
        missing.is_empty(),
        "process(es) {} did not report: their nodes' figures are missing from the summary",
        missing.join(", ")
    );
    headless::end_is_an_error(&report)
}

/// `--ros2` across processes: the ROS 2 session (with the embedded router when none
/// answers) opened before any process starts, so that each finds the router and offers its
/// own nodes; said in one line.
fn offer_ros2(
    domain: u32,
    spec: &ratelab::graph::GraphSpec,
    stop: &StopFlag,
) -> anyhow::Result<ratelab::ros2::session::Ros2Session> {
    let link = headless::open_ros2(stop)?;
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
    spec.placement()
        .iter()
        .map(|(p, ids)| {
            let names: Vec<&str> = ids.iter().map(|i| spec.node(*i).name.as_str()).collect();
            format!("{p} [{}]", names.join(", "))
        })
        .collect::<Vec<_>>()
        .join(", ")
}

/// A crossing topic's time on the wire, as the summary says it (a process that rejoined
/// counts from its rejoin, and the line says so).
fn wire_line(w: &ratelab::distributed::wire::WireLink) -> String {
    let since = w.since_ns.map_or(String::new(), |t| {
        format!(" since its rejoin at {:.2} s", t as f64 / 1e9)
    });
    format!(
        "wire {} into '{}': {} samples{since}, p50 {} µs | p99 {} µs | max {} µs",
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
    let mut line = |l: String| {
        if lab {
            held.push(l);
        } else {
            println!("[ratelab] launch: {l}");
        }
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
        eprintln!("[ratelab] launch: listening on {endpoint}");
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
    let origin = a.graph.as_ref().map_or_else(
        || "graphs/cartpole.toml".to_string(),
        |p| p.display().to_string(),
    );
    let opts = ProcessOptions {
        graph_bytes: graph_file_bytes(a.graph.as_deref())?,
        graph_origin: origin,
        process: a.process.clone(),
        connect: a.connect.clone(),
        listen: a.listen.clone(),
        credentials: Credentials::load(credentials)?,
        // On stdout: a process started by hand says what happens to it; a launcher's own
        // children have no stdout (their launcher says it).
        say: Some(|line| {
            // Never fatal: a node whose stdout was closed runs on, unheard.
            let _ = writeln!(std::io::stdout(), "[ratelab] {line}");
        }),
    };
    ratelab::distributed::process::run_process(&opts, &stop)
        .map_err(|e| anyhow::anyhow!("process '{}': {e}", a.process))
}

/// `ratelab top`: refresh a table of every graph reachable from `--connect`.
pub fn run_top(a: &TopArgs, stop: StopFlag) -> anyhow::Result<()> {
    for ep in &a.connect {
        check_endpoint("--connect", ep, false)?;
    }
    let crate::rendezvous::Target {
        connect,
        hint,
        credentials,
    } = crate::rendezvous::target(
        &a.connect,
        a.credentials.as_deref(),
        &crate::rendezvous::launches(),
    )?;
    let access = Access {
        credentials: &credentials,
        role: &Role::Observer,
        spec: None,
    };
    let session = open_session(
        &[ratelab::distributed::LOOPBACK_ANY.to_string()],
        &connect,
        access,
    )
    .map_err(|e| anyhow::anyhow!("cannot reach {}: {e}: {hint}", connect.join(", ")))?;
    let (tx, rx) = crossbeam_channel::bounded::<LiveStats>(1024);
    let _sub = session
        .declare_subscriber("ratelab/*/@stats/*")
        .callback(move |s| {
            if let Some(mut m) = LiveStats::from_sample(&s) {
                // `top` shows counters: the steps and ticks for the lab are not kept.
                m.steps = Vec::new();
                m.ticks = Vec::new();
                let _ = tx.try_send(m);
            }
        })
        .wait()
        .map_err(|e| anyhow::anyhow!("zenoh: {e}"))?;
    // A launch's end (its summary on `@ended`): its graph leaves the table, and a refreshing
    // `top` with nothing left to show ends too.
    let (ended_tx, ended_rx) = crossbeam_channel::bounded::<String>(64);
    let _ended_sub = session
        .declare_subscriber("ratelab/*/@ended")
        .callback(move |s| {
            if let Some(g) = s.key_expr().as_str().split('/').nth(1) {
                let _ = ended_tx.try_send(g.to_string());
            }
        })
        .wait()
        .map_err(|e| anyhow::anyhow!("zenoh: {e}"))?;
    let mut ended: std::collections::BTreeSet<String> = std::collections::BTreeSet::new();
    // Per process: the newest figures and the ones before, for rates.
    let mut seen: BTreeMap<String, (LiveStats, Option<LiveStats>)> = BTreeMap::new();
    // Per graph: its shape (asked of its launcher once), so that a process gone before
    // `top` heard from it is listed too and a restarted one's counts go on.
    let mut graphs: BTreeMap<String, Known> = BTreeMap::new();
    let started = Instant::now();
    let mut last_print = Instant::now();
    loop {
        for g in ended_rx.try_iter() {
            if !a.once {
                seen.retain(|_, (m, _)| ratelab::distributed::Keys::new(&m.graph).graph() != g);
            }
            ended.insert(g);
        }
        if !a.once && !ended.is_empty() && seen.is_empty() {
            let graphs: Vec<&str> = ended.iter().map(String::as_str).collect();
            println!(
                "ratelab top: the launch of graph '{}' ended",
                graphs.join("', '")
            );
            return Ok(());
        }
        while let Ok(m) = rx.try_recv() {
            if !a.once && ended.contains(ratelab::distributed::Keys::new(&m.graph).graph()) {
                continue; // a last figure after its launch's end
            }
            let key = format!("{}/{}", m.graph, m.process);
            // Rates over about a second: the figures before stay until the new ones are a
            // second newer (processes publish every 100 ms); none across a restart.
            let prev = match seen.remove(&key) {
                Some((_, Some(p))) if m.t_ns.saturating_sub(p.t_ns) < 1_000_000_000 => Some(p),
                Some((cur, _)) => Some(cur),
                None => None,
            }
            .filter(|p| p.pid == m.pid);
            graphs
                .entry(m.graph.clone())
                .or_insert_with(|| Known::new(ask_graph(&session, &m.graph)))
                .see(&m);
            seen.insert(key, (m, prev));
        }
        let alive = alive_nodes(&session);
        if a.once {
            // Rates over half a second at least (a process gone sends no more figures).
            let have_rates = seen.values().all(|(m, p)| {
                !alive.iter().any(|(ap, _)| *ap == m.process)
                    || p.as_ref()
                        .is_some_and(|p| m.t_ns.saturating_sub(p.t_ns) >= 500_000_000)
            });
            if (!seen.is_empty() && have_rates) || started.elapsed() > Duration::from_secs(3) {
                if seen.is_empty() {
                    anyhow::bail!(
                        "no running ratelab graph answered at {} within 3 s: {hint}",
                        connect.join(", ")
                    );
                }
                print!("{}", table(&seen, &alive, &graphs));
                return Ok(());
            }
        } else if last_print.elapsed() >= Duration::from_secs(1) {
            last_print = Instant::now();
            // Clear the screen and home the cursor (a plain refreshing table, like `top`); a
            // pipe gets one table after another.
            if std::io::IsTerminal::is_terminal(&std::io::stdout()) {
                print!("\x1b[2J\x1b[H");
            }
            print!("{}", table(&seen, &alive, &graphs));
            if seen.is_empty() {
                println!("(waiting for a graph at {})", a.connect.join(", "));
            }
        }
        if stop.is_stopped() {
            return Ok(());
        }
        std::thread::sleep(Duration::from_millis(100));
    }
}

/// The nodes whose liveliness tokens are alive now: `(process, node)`.
fn alive_nodes(session: &zenoh::Session) -> Vec<(String, String)> {
    // At most every node of 4 graphs of the largest size (a few hundred MB of names at
    // most from whatever answers).
    let max = 4 * ratelab::ids::MAX_NODES;
    live_tokens(
        session,
        "ratelab/*/@node/*/*",
        Duration::from_millis(300),
        max,
    )
    .iter()
    .filter_map(|key| match key.split('/').collect::<Vec<_>>().as_slice() {
        [_, _, _, p, n] => Some(((*p).to_string(), (*n).to_string())),
        _ => None,
    })
    .collect()
}

/// What `top` knows of a running graph beyond its processes' figures: its shape, as its
/// launcher answered (none when it did not), and the counts of its restarted processes.
struct Known {
    /// Its processes as placed.
    placed: Vec<PlacedProcess>,
    /// The graph, with the counts its restarted processes carry over.
    carried: Option<(ratelab::graph::spec::GraphSpec, Carried)>,
}

impl Known {
    fn new(spec: Option<ratelab::graph::spec::GraphSpec>) -> Known {
        match spec {
            Some(spec) => Known {
                placed: placed_processes(&spec),
                carried: Some((spec.clone(), Carried::new(&spec))),
            },
            None => Known {
                placed: Vec::new(),
                carried: None,
            },
        }
    }

    /// Take in a process's figures.
    fn see(&mut self, m: &LiveStats) {
        if let Some((spec, carried)) = &mut self.carried {
            carried.see(spec, m);
        }
    }

    /// Node `name`'s ticks `now` (its process's count), continued from the processes
    /// before it that `top` heard.
    fn ticks(&self, name: &str, now: u64) -> u64 {
        self.carried
            .as_ref()
            .and_then(|(spec, c)| {
                let i = spec.nodes.iter().position(|n| n.name == name)?;
                Some(c.node_ticks(i, now))
            })
            .unwrap_or(now)
    }

    /// Topic `name`'s counters `now` (its holder's), continued likewise.
    fn counters(&self, name: &str, now: &ratelab::topic::TopicStats) -> ratelab::topic::TopicStats {
        self.carried
            .as_ref()
            .and_then(|(spec, c)| {
                let i = spec.topics.iter().position(|t| t.name == name)?;
                Some(c.continued(i, now))
            })
            .unwrap_or(*now)
    }

    /// What the counts of process `m.process` leave out, said after them: its runs before
    /// a rejoin that `top` did not hear (empty when they cover the whole run).
    fn since(&self, m: &LiveStats) -> String {
        let carried = self
            .carried
            .as_ref()
            .is_some_and(|(_, c)| c.saw_restart(&m.process));
        match m.since_ns {
            Some(t) if !carried => format!("since it rejoined at {:.2} s", t as f64 / 1e9),
            _ => String::new(),
        }
    }
}

/// The table `top` prints: every process's nodes, then every topic with its counters
/// (continued across a restart `top` heard; a note where they leave something out).
fn table(
    seen: &BTreeMap<String, (LiveStats, Option<LiveStats>)>,
    alive: &[(String, String)],
    graphs: &BTreeMap<String, Known>,
) -> String {
    use std::fmt::Write;
    let mut s = String::new();
    let t = seen.values().map(|(m, _)| m.t_ns).max().unwrap_or(0);
    // The placed processes `top` has no figures from (gone before it heard them, or not
    // yet started).
    let unheard: Vec<(&String, &PlacedProcess)> = graphs
        .iter()
        .flat_map(|(g, k)| k.placed.iter().map(move |p| (g, p)))
        .filter(|(g, p)| !seen.contains_key(&format!("{g}/{}", p.name)))
        .collect();
    let unknown = Known::new(None);
    let _ = writeln!(
        s,
        "ratelab top: {} process(es), run time {:.2} s",
        seen.len() + unheard.len(),
        t as f64 / 1e9
    );
    let _ = writeln!(
        s,
        "{:<10} {:>7} {:<10} {:<9} {:>8} {:>8} {:>10} {:<6}",
        "PROCESS", "PID", "NODE", "KIND", "RATE_HZ", "TICKS", "MEAS_HZ", "ALIVE"
    );
    unheard_node_rows(&mut s, &unheard, alive);
    let mut wire: BTreeMap<String, (f64, f64)> = BTreeMap::new();
    let mut topics: Vec<TopicRow> = Vec::new();
    for (m, prev) in seen.values() {
        let p = &m.process;
        let known = graphs.get(&m.graph).unwrap_or(&unknown);
        let since = known.since(m);
        let dt = prev
            .as_ref()
            .map(|q| m.t_ns.saturating_sub(q.t_ns) as f64 / 1e9)
            .filter(|d| *d > 0.0);
        for (name, kind, hz, ticks) in &m.nodes {
            let before = prev
                .as_ref()
                .and_then(|q| q.nodes.iter().find(|n| n.0 == *name))
                .map(|n| n.3);
            let is_alive = alive.iter().any(|(ap, an)| ap == p && an == name);
            // A node gone has no rate now (its last figures would show its old one).
            let meas = match (dt, before, is_alive) {
                (Some(dt), Some(b), true) => {
                    format!("{:.1}", ticks.saturating_sub(b) as f64 / dt)
                }
                _ => "-".into(),
            };
            let line = format!(
                "{:<10} {:>7} {:<10} {:<9} {:>8.1} {:>8} {:>10} {:<6} {since}",
                p,
                m.pid,
                name,
                kind,
                hz,
                known.ticks(name, *ticks),
                meas,
                if is_alive { "yes" } else { "GONE" }
            );
            let _ = writeln!(s, "{}", line.trim_end());
        }
        let process_alive = alive.iter().any(|(ap, _)| ap == p);
        // A holder gone took its counting with it: its last counts stand, and say so.
        let why = if !process_alive && !m.done {
            format!("counted by '{p}' until it went")
        } else if since.is_empty() {
            String::new()
        } else {
            format!("counted by '{p}' {since}")
        };
        for (name, st) in &m.topics {
            let before = prev
                .as_ref()
                .and_then(|q| q.topics.iter().find(|x| x.0 == *name))
                .map(|x| x.1.published)
                .filter(|_| process_alive);
            let rate = match (dt, before) {
                (Some(dt), Some(b)) => format!("{:.1}", st.published.saturating_sub(b) as f64 / dt),
                _ => "-".into(),
            };
            let st = known.counters(name, st);
            topics.push((
                name.clone(),
                rate,
                [st.published, st.dropped, st.lost].map(|n| n.to_string()),
                why.clone(),
            ));
        }
        for w in &m.wire {
            wire.insert(w.topic.clone(), (w.p50_us, w.p99_us));
        }
    }
    let _ = writeln!(
        s,
        "\n{:<10} {:>8} {:>10} {:>8} {:>6} {:>9} {:>9}",
        "TOPIC", "MSG/S", "PUBLISHED", "DROPPED", "LOST", "WIRE_P50", "WIRE_P99"
    );
    unheard_topic_rows(&mut topics, &unheard, alive);
    topics.sort_by(|a, b| a.0.cmp(&b.0));
    for (name, rate, [published, dropped, lost], why) in topics {
        let (p50, p99) = match wire.get(&name) {
            // No figures from its counting process: nothing to show of its wire either.
            _ if published == "-" => ("-".to_string(), "-".to_string()),
            Some((a, b)) => (format!("{a:.0} µs"), format!("{b:.0} µs")),
            None => ("in-proc".to_string(), "-".to_string()),
        };
        let line = format!(
            "{name:<10} {rate:>8} {published:>10} {dropped:>8} {lost:>6} {p50:>9} {p99:>9}  {why}"
        );
        let _ = writeln!(s, "{}", line.trim_end());
    }
    s
}

/// A row of `top`'s topic table: name, msg/s, (published, dropped, lost), and who counted.
type TopicRow = (String, String, [String; 3], String);

/// `top`'s node rows of the placed processes it has no figures from: alive or gone, no
/// counts.
fn unheard_node_rows(
    s: &mut String,
    unheard: &[(&String, &PlacedProcess)],
    alive: &[(String, String)],
) {
    use std::fmt::Write;
    for (_, placed) in unheard {
        let p = &placed.name;
        for (name, kind, hz) in &placed.nodes {
            let is_alive = alive.iter().any(|(ap, an)| ap == p && an == name);
            let _ = writeln!(
                s,
                "{:<10} {:>7} {:<10} {:<9} {:>8.1} {:>8} {:>10} {:<6}",
                p,
                "-",
                name,
                kind,
                hz,
                "-",
                "-",
                if is_alive { "yes" } else { "GONE" }
            );
        }
    }
}

/// A topic held by a process with no figures here still has its row: its counters live
/// there, so none can be shown, and the row says why.
fn unheard_topic_rows(
    topics: &mut Vec<TopicRow>,
    unheard: &[(&String, &PlacedProcess)],
    alive: &[(String, String)],
) {
    for (_, placed) in unheard {
        let gone = !alive.iter().any(|(ap, _)| *ap == placed.name);
        for name in &placed.holds {
            if topics.iter().any(|t| t.0 == *name) {
                continue;
            }
            let why = if gone {
                format!("counted by '{}', which is gone", placed.name)
            } else {
                format!("counted by '{}': no figures yet", placed.name)
            };
            topics.push((
                name.clone(),
                "-".into(),
                ["-", "-", "-"].map(String::from),
                why,
            ));
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn stats(process: &str, t_ns: u64, sensor_ticks: u64) -> LiveStats {
        LiveStats {
            graph: "cartpole".into(),
            process: process.into(),
            pid: 42,
            t_ns,
            nodes: vec![("sensor".into(), "sensor".into(), 50.0, sensor_ticks)],
            topics: vec![(
                "/action".into(),
                ratelab::topic::TopicStats {
                    published: 40,
                    ..Default::default()
                },
            )],
            wire: Vec::new(),
            steps: Vec::new(),
            ticks: Vec::new(),
            counters: Vec::new(),
            done: false,
            since_ns: None,
        }
    }

    /// The policy's process's figures: its pid, the counts of `/obs` (which it holds) and
    /// of its node's ticks, and the run time it joined at when it rejoined.
    fn policy_stats(pid: u32, counted: u64, since_ns: Option<u64>) -> LiveStats {
        LiveStats {
            process: "policy".into(),
            pid,
            t_ns: 3_000_000_000,
            nodes: vec![("policy".into(), "policy".into(), 50.0, counted)],
            topics: vec![(
                "/obs".into(),
                ratelab::topic::TopicStats {
                    published: counted,
                    dropped: 2,
                    ..Default::default()
                },
            )],
            since_ns,
            ..stats("policy", 0, 0)
        }
    }

    fn row<'a>(t: &'a str, starts: &str) -> &'a str {
        t.lines()
            .find(|l| l.starts_with(starts))
            .unwrap_or_else(|| panic!("no row {starts}: {t}"))
    }

    #[test]
    fn a_restarted_process_counts_on_or_says_what_its_counts_leave_out() {
        let spec = ratelab::graph::GraphSpec::chapter();
        let alive = vec![
            ("robot".to_string(), "sensor".to_string()),
            ("policy".to_string(), "policy".to_string()),
        ];
        let (first, again) = (
            policy_stats(7, 100, None),
            policy_stats(8, 30, Some(2_000_000_000)),
        );
        let seen = BTreeMap::from([("cartpole/policy".to_string(), (again.clone(), None))]);
        // Heard before and after its restart: the counts go on.
        let mut known = Known::new(Some(spec.clone()));
        known.see(&first);
        known.see(&again);
        let graphs = BTreeMap::from([("cartpole".to_string(), known)]);
        let t = table(&seen, &alive, &graphs);
        let obs = row(&t, "/obs");
        let cols: Vec<&str> = obs.split_whitespace().collect();
        assert_eq!(
            cols[2..4],
            ["130", "4"],
            "published and dropped carried over: {t}"
        );
        assert!(!obs.contains("since") && !obs.contains("counted by"), "{t}");
        let node = row(&t, "policy ");
        assert!(node.contains(" 130 ") && node.ends_with("yes"), "{t}");
        // Heard only after it: its own counts, and what they leave out.
        let mut known = Known::new(Some(spec.clone()));
        known.see(&again);
        let graphs = BTreeMap::from([("cartpole".to_string(), known)]);
        let t = table(&seen, &alive, &graphs);
        let obs = row(&t, "/obs");
        assert!(obs.contains(" 30 "), "{t}");
        assert!(
            obs.ends_with("counted by 'policy' since it rejoined at 2.00 s"),
            "{t}"
        );
        assert!(
            row(&t, "policy ").ends_with("yes    since it rejoined at 2.00 s"),
            "{t}"
        );
        // Gone: its last counts stand, and say so.
        let robot_only = vec![("robot".to_string(), "sensor".to_string())];
        let t = table(&seen, &robot_only, &graphs);
        let obs = row(&t, "/obs");
        assert!(
            obs.contains(" 30 ") && obs.contains(" - "),
            "no rate for a gone holder: {t}"
        );
        assert!(obs.ends_with("counted by 'policy' until it went"), "{t}");
        assert!(row(&t, "policy ").contains("GONE"), "{t}");
    }

    #[test]
    fn a_topic_counted_by_a_process_gone_keeps_its_row_and_says_why() {
        let spec = ratelab::graph::GraphSpec::chapter();
        let placed = placed_processes(&spec);
        assert_eq!(placed[0].name, "robot");
        assert_eq!(placed[0].holds, vec!["/action"]);
        assert_eq!(
            placed[1].holds,
            vec!["/obs"],
            "the policy subscribes to /obs"
        );
        let mut seen = BTreeMap::new();
        seen.insert(
            "cartpole/robot".to_string(),
            (
                stats("robot", 2_000_000_000, 100),
                Some(stats("robot", 1_000_000_000, 50)),
            ),
        );
        let graphs = BTreeMap::from([("cartpole".to_string(), Known::new(Some(spec.clone())))]);
        let alive = vec![("robot".to_string(), "sensor".to_string())];
        let t = table(&seen, &alive, &graphs);
        let obs = t
            .lines()
            .find(|l| l.starts_with("/obs"))
            .unwrap_or_else(|| panic!("{t}"));
        assert!(obs.contains("counted by 'policy', which is gone"), "{t}");
        assert!(!obs.contains(" 0 "), "no counts made up: {t}");
        let policy = t.lines().find(|l| l.contains(" policy ")).unwrap();
        assert!(policy.trim_end().ends_with("GONE"), "{t}");
        let sensor = t.lines().find(|l| l.contains(" sensor ")).unwrap();
        assert!(sensor.contains("50.0") && sensor.contains("yes"), "{t}");
        // Still starting: no figures yet, not gone.
        let alive = vec![
            ("robot".to_string(), "sensor".to_string()),
            ("policy".to_string(), "policy".to_string()),
        ];
        let t = table(&seen, &alive, &graphs);
        assert!(t.contains("counted by 'policy': no figures yet"), "{t}");
    }
}
