//! The terminal lab: a live dashboard of the graph, with the rate and the queue under the
//! user's fingers. `main` is init → run → always restore; the loop is generic over the
//! ratatui `Backend` so tests drive it with `TestBackend`.

pub mod app;
pub mod chart_window;
pub mod estimates;
pub mod fit;
pub mod keymap;
pub mod live;
pub mod navigate;
pub mod timeline;
pub mod view;
pub mod watch;
pub mod zoom;

use anyhow::Context;
use app::App;
use crossbeam_channel::{bounded, select, tick, unbounded, Receiver};
use crossterm::event::Event as TermEvent;
use ratatui::backend::Backend;
use ratatui::Terminal;
use ratelab::scheduler::StopFlag;
use ratelab::session::{Control, Engine, SessionSettings, Telemetry};
use std::io::Write;
use std::time::Duration;

/// Frames per second of the display.
pub const FPS: u64 = 30;
/// Pending input events kept at most: a held key or a paste burst beyond this is dropped,
/// so seconds of stale input never queue up.
pub const INPUT_QUEUE: usize = 16;

/// The most log lines waiting between two frames of the lab (more are dropped).
const LOG_QUEUE: usize = 4096;

/// Run the event loop until the user quits or `stop` is set: input, telemetry and a
/// ~30 fps tick, one `select!`. Draws on every tick and after every key.
///
/// # Errors
/// A drawing error from the backend.
pub fn run_loop<B: Backend>(
    terminal: &mut Terminal<B>,
    app: &mut App,
    input: &Receiver<TermEvent>,
    telemetry: &Receiver<Telemetry>,
    stop: &StopFlag,
) -> anyhow::Result<()>
where
    B::Error: Send + Sync + 'static,
{
    let ticker = tick(Duration::from_millis(1000 / FPS));
    let draw = |terminal: &mut Terminal<B>, app: &App| -> anyhow::Result<()> {
        let view = app.view();
        terminal
            .draw(|f| f.render_widget(&view, f.area()))
            .context("drawing")?;
        Ok(())
    };
    draw(terminal, app)?;
    while !app.quit && !stop.is_stopped() {
        select! {
            recv(input) -> ev => {
                let Ok(ev) = ev else { break };
                for ev in std::iter::once(ev).chain(input.try_iter()) {
                    if let TermEvent::Key(k) = ev {
                        if let Some(m) = keymap::map_key(k, app.typing(), app.scrubbing()) {
                            app.on_msg(m);
                        }
                    }
                }
                draw(terminal, app)?;
            }
            recv(telemetry) -> t => {
                let Ok(t) = t else { break };
                app.on_telemetry(t);
                for t in telemetry.try_iter() {
                    app.on_telemetry(t);
                }
            }
            recv(ticker) -> _ => {
                app.drain_log();
                draw(terminal, app)?
            }
        }
    }
    Ok(())
}

/// Open the lab on the real terminal: start the engine, read keys on a thread, run the
/// loop, and always restore the terminal (ratatui's panic hook restores it on a panic).
pub fn run_lab(
    mut settings: SessionSettings,
    code: watch::CodeSource,
    stop: StopFlag,
) -> anyhow::Result<()> {
    let (ctl_tx, ctl_rx) = unbounded::<Control>();
    let (tel_tx, tel_rx) = unbounded::<Telemetry>();
    settings.control = Some(ctl_tx.clone());
    let mut app = App::new(
        ctl_tx.clone(),
        settings.policy.clone(),
        settings.alt_policy.clone(),
        settings.speed,
    );
    app.show_graph(settings.cfg.graph.clone());
    app.show_clock(settings.cfg.clock);
    if let Some((_, opts)) = &settings.ros2 {
        app.set_ros2_domain(opts.domain);
    }
    // What nodes' code and ratelab's warnings write goes to the log pane while the screen
    // is up, never over it (bounded: a node printing without end drops lines, not memory).
    let (log_tx, log_rx) = crossbeam_channel::bounded::<ratelab::textlog::LogLine>(LOG_QUEUE);
    app.take_log(log_rx);
    ratelab::textlog::set_sink(Some(Box::new(move |line| {
        let _ = log_tx.try_send(line);
    })));
    // A callback's exception reaches the pane as one entry, with its traceback; its paths
    // read relative to the graph file's folder (else the lab's own).
    ratelab::python::log_failures(true);
    // (As the graph resolves its scripts: std::path::absolute, `..` kept.)
    let folder = code
        .graph_file
        .as_ref()
        .and_then(|g| std::path::absolute(g).ok())
        .and_then(|g| g.parent().map(std::path::Path::to_path_buf))
        .unwrap_or_else(|| std::env::current_dir().unwrap_or_default());
    app.set_code_folder(&folder);
    // Reload on save: a save of the graph file or a Python file it runs runs it again.
    let _watch = match watch::watch(code.files(&settings.cfg.graph), ctl_tx.clone()) {
        Ok(w) => {
            // Each run's graph gives the files watched (a reload may run scripts elsewhere).
            let w = std::sync::Arc::new(w);
            let follow = w.clone();
            app.on_graph(Box::new(move |graph| {
                follow.follow(code.files(graph)).err().map(|e| {
                    format!("reload on save: a folder of this graph cannot be watched ({e})")
                })
            }));
            Some(w)
        }
        Err(e) => {
            app.on_telemetry(Telemetry::Error(format!(
                "reload on save is off: the files cannot be watched ({e})"
            )));
            None
        }
    };
    let session_file = settings.session_file.clone();
    let engine = Engine::new(settings, ctl_rx, tel_tx).spawn();
    let result = on_terminal(&mut app, &tel_rx, &stop);
    let _ = ctl_tx.send(Control::Quit);
    // A Python callback that never returns would keep the engine from seeing the quit.
    ratelab::python::interrupt_callbacks_after(crate::PYTHON_GRACE);
    ratelab::python::log_failures(false);
    let joined = match join_engine(engine) {
        Ok(joined) => joined,
        Err(stuck) => {
            ratelab::textlog::set_sink(None);
            result?;
            anyhow::bail!(
                "the lab ended without waiting for its engine: {stuck} (a sleep or C code cannot be interrupted)"
            );
        }
    };
    ratelab::textlog::set_sink(None);
    if joined.is_err() {
        anyhow::bail!("the lab's engine stopped unexpectedly");
    }
    if let Some(p) = session_file {
        // Not `println!`: after a hang-up (SIGHUP) stdout is gone, and the log is saved.
        let _ = writeln!(
            std::io::stdout(),
            "[ratelab] session log: {} (replay: ratelab replay {})",
            p.display(),
            p.display()
        );
    }
    result?;
    // Quitting the lab after a run whose node failed is no success (a script that ran it
    // learns so): the terminal is restored, the session log saved, then one line.
    if let Some(line) = app.failed_node() {
        anyhow::bail!("the lab's last run failed: node {line}");
    }
    Ok(())
}

/// How long quitting waits for the engine while a call into learners' code that it waits
/// on has not returned (the quit's `KeyboardInterrupt` cannot end a `time.sleep` or C code)
/// before the lab ends without it ([`join_engine`]).
const ENGINE_STUCK_AFTER: Duration = Duration::from_secs(3);

/// Wait for the engine to end after the quit. `Err` (the call it is held by) when, after
/// [`ENGINE_STUCK_AFTER`], a call into learners' code of the run (not a save's trial, which
/// the engine never waits on) still has not returned: the lab then ends without waiting.
fn join_engine(
    engine: std::thread::JoinHandle<ratelab::session::SessionLog>,
) -> Result<std::thread::Result<ratelab::session::SessionLog>, String> {
    let since = std::time::Instant::now();
    while !engine.is_finished() {
        if since.elapsed() >= ENGINE_STUCK_AFTER {
            let stuck = ratelab::python::running_callbacks(ENGINE_STUCK_AFTER)
                .into_iter()
                .next();
            if let Some(call) = stuck {
                return Err(format!(
                    "{} has not returned after {:.0} s",
                    call.what,
                    call.running_for.as_secs_f64()
                ));
            }
        }
        std::thread::sleep(Duration::from_millis(20));
    }
    Ok(engine.join())
}

/// Open the lab on a graph running across processes (`ratelab lab --attach`, or the lab of
/// `ratelab launch --processes`): the same dashboard, fed with `telemetry` by a watcher
/// ([`ratelab::distributed::monitor::Watch`]) instead of an engine in this process. It only
/// watches: a key that would change the graph is answered with [`app::READ_ONLY`]. `policy`
/// is the brain's spec, `spec` the graph. What the processes' nodes write shows in the log
/// pane (`v`), stamped as in one process. Returns when the user quits (or `stop` is set).
///
/// # Errors
/// The terminal cannot be opened or drawn on.
pub fn run_attached(
    policy: String,
    spec: &ratelab::graph::GraphSpec,
    endpoint: Option<&str>,
    telemetry: &Receiver<Telemetry>,
    stop: &StopFlag,
) -> anyhow::Result<()> {
    // Nothing listens for controls: an attached lab refuses them itself.
    let (ctl_tx, _) = unbounded::<Control>();
    let mut app = App::new(ctl_tx, policy, None, ratelab::session::Speed::Times(1.0));
    app.set_attached(attached_label(spec));
    // The footer names where the launch listens (another lab or `top` connects there).
    app.set_endpoint(endpoint.map(str::to_string));
    app.show_graph(spec.clone());
    // What the processes' nodes write (passed on by the launcher, read back by the watcher)
    // and this process's own warnings go to the log pane, never over the screen.
    let (log_tx, log_rx) = crossbeam_channel::bounded::<ratelab::textlog::LogLine>(LOG_QUEUE);
    app.take_log(log_rx);
    ratelab::textlog::set_sink(Some(Box::new(move |line| {
        let _ = log_tx.try_send(line);
    })));
    let result = on_terminal(&mut app, telemetry, stop);
    ratelab::textlog::set_sink(None);
    result
}

/// The header's note on an attached graph: `2 processes`.
pub fn attached_label(spec: &ratelab::graph::GraphSpec) -> String {
    match spec.placement().len() {
        1 => "1 process".to_string(),
        n => format!("{n} processes"),
    }
}

/// Read keys on a thread, open the terminal, run the loop until the user quits, and always
/// restore the terminal.
fn on_terminal(
    app: &mut App,
    telemetry: &Receiver<Telemetry>,
    stop: &StopFlag,
) -> anyhow::Result<()> {
    let (in_tx, in_rx) = bounded::<TermEvent>(INPUT_QUEUE);
    std::thread::Builder::new()
        .name("input".into())
        .spawn(move || {
            while let Ok(ev) = crossterm::event::read() {
                // Full queue: drop the event rather than let stale input pile up.
                let _ = in_tx.try_send(ev);
            }
        })
        .context("spawning the input thread")?;
    let mut terminal = ratatui::try_init().context(
        "cannot open the terminal (the lab draws on one; `ratelab run` runs the graph headless)",
    )?;
    // ratatui's hook restores the terminal on a panic; keep that for the UI thread only.
    // A node's panic is caught by the executor and shown in the lab (NODE FAILED), so it
    // must neither restore the terminal under the running UI nor print over it.
    let restore_and_report = std::panic::take_hook();
    std::panic::set_hook(Box::new(move |info| {
        if std::thread::current().name() == Some("main") {
            restore_and_report(info);
        }
    }));
    let result = run_loop(&mut terminal, app, &in_rx, telemetry, stop);
    let gone = result.as_ref().err().is_some_and(hung_up) || terminal.show_cursor().is_err();
    if !gone {
        let _ = ratatui::try_restore();
        return result;
    }
    // The terminal hung up (its window closed: SIGHUP, or a draw failed on it first).
    // There is nothing to restore, and a print to a hung-up terminal panics: leave it
    // without ratatui's restore and drop, which print. The engine still ends the run, so
    // the recording and the session log are complete.
    std::mem::forget(terminal);
    stop.stop();
    Err(anyhow::anyhow!(
        "the terminal hung up (its window closed): the lab ended there"
    ))
}

/// Linux's `EIO` and `ENXIO` (asm-generic/errno-base.h).
const EIO: i32 = 5;
const ENXIO: i32 = 6;

/// Whether `e` is a terminal that hung up: a write to it failed with `EIO` or `ENXIO` (its
/// pseudo-terminal's other side closed).
fn hung_up(e: &anyhow::Error) -> bool {
    e.chain().any(|c| {
        c.downcast_ref::<std::io::Error>()
            .and_then(std::io::Error::raw_os_error)
            .is_some_and(|n| n == EIO || n == ENXIO)
    })
}

/// What a widget drew into `buf`, as text: its rows, one a line (the symbols of its cells).
#[cfg(test)]
pub(crate) fn buffer_text(buf: &ratatui::buffer::Buffer) -> String {
    let area = buf.area;
    (area.top()..area.bottom())
        .map(|y| {
            (area.left()..area.right())
                .map(|x| buf[(x, y)].symbol())
                .collect::<String>()
        })
        .collect::<Vec<_>>()
        .join("\n")
}

#[cfg(test)]
mod tests {
    use super::app::App;
    use super::keymap::Msg;
    use ratatui::backend::TestBackend;
    use ratatui::Terminal;
    use ratelab::policy::Scripted;
    use ratelab::scheduler::EndReason;
    use ratelab::session::{Control, Speed, Telemetry};
    use ratelab::{run, ClockKind, RunConfig, RunOptions};

    /// An app fed with a real (deterministic) virtual run's telemetry.
    fn app_after(cfg: RunConfig, ended: bool) -> (App, crossbeam_channel::Receiver<Control>) {
        ratelab::init(); // the shipped graphs include Python nodes
        App::after_virtual_run(cfg, ended).unwrap()
    }

    /// A lab told the run of `cfg` whose steps are `trace`, up to run time `upto`; and what
    /// it asked of the engine.
    fn told(
        cfg: &RunConfig,
        trace: &[ratelab::runlog::StepRecord],
        upto: ratelab::Nanos,
    ) -> (App, crossbeam_channel::Receiver<Control>) {
        let (tx, rx) = crossbeam_channel::unbounded();
        let mut app = App::new(tx, "scripted".into(), None, Speed::Times(1.0));
        app.on_telemetry(Telemetry::Started {
            cfg: cfg.clone(),
            policy: "scripted".into(),
            recording: None,
        });
        for s in trace.iter().filter(|s| s.t <= upto) {
            app.on_telemetry(Telemetry::Step(Box::new(s.clone())));
        }
        (app, rx)
    }

    /// A 120×40 screen's rows but the footer's (the message line).
    fn rows(screen: &str) -> Vec<String> {
        screen.lines().take(39).map(str::to_string).collect()
    }

    fn render(app: &App, w: u16, h: u16) -> String {
        render_view(&app.view(), w, h)
    }

    fn render_view(view: &super::view::View, w: u16, h: u16) -> String {
        let mut t = Terminal::new(TestBackend::new(w, h)).unwrap();
        t.draw(|f| f.render_widget(view, f.area())).unwrap();
        t.backend().to_string()
    }

    /// The engine's status for the chapter's graph at 1 s: every node at 50 Hz, every topic
    /// at depth 1 with `qos`, each node's liveliness `alive`.
    fn chapter_status(qos: Vec<ratelab::qos::TopicQos>, alive: Vec<Option<bool>>) -> Telemetry {
        Telemetry::Status {
            now: ratelab::Nanos::SECOND,
            paused: false,
            speed: Speed::Times(1.0),
            rates: vec![50.0; 3],
            depths: vec![1, 1],
            qos,
            alive,
            policy: "scripted".into(),
            exec: None,
            topics: None,
        }
    }

    fn virtual_cfg(control_hz: f64, secs: u64) -> RunConfig {
        let mut cfg = RunConfig {
            clock: ClockKind::Virtual,
            duration: ratelab::Nanos(secs * 1_000_000_000),
            ..RunConfig::default()
        };
        cfg.set_control_hz(control_hz).unwrap();
        cfg
    }

    /// A reload keeps the run before as a ghost in the angle, force and latency panels
    /// (their titles say so); the run after it, started for another reason, drops it.
    #[test]
    fn a_reload_draws_the_run_before_as_a_ghost_until_another_run_starts() {
        let (mut app, _rx) = app_after(virtual_cfg(5.0, 10), true);
        assert!(app.view().ghost_angle.is_empty());
        let started = |cfg: RunConfig| Telemetry::Started {
            cfg,
            policy: "scripted".into(),
            recording: None,
        };
        app.on_telemetry(Telemetry::Reloaded {
            line: "reloaded brain.py: fell at 0.84 s → balanced (10.0 s)".into(),
        });
        app.on_telemetry(started(virtual_cfg(50.0, 10)));
        let v = app.view();
        assert!(v.ghost_angle.len() > 10, "{}", v.ghost_angle.len());
        assert!(!v.ghost_force.is_empty());
        assert!(v
            .message
            .as_deref()
            .unwrap_or("")
            .starts_with("reloaded brain.py:"));
        let screen = render(&app, 120, 40);
        // The angle and force panels, and the latency panel's pairs.
        assert_eq!(screen.matches("before reload").count(), 3, "{screen}");
        // One second into the new run: the latency panel pairs each bar with the run
        // before's count over its first second.
        app.on_telemetry(chapter_status(
            vec![ratelab::qos::TopicQos::default(); 2],
            vec![None; 3],
        ));
        let v = app.view();
        assert_eq!(v.latency.ghost.len(), v.latency.buckets.len());
        let before: u64 = v.latency.ghost.iter().sum();
        assert!((1..=51).contains(&before), "{:?}", v.latency.ghost);
        for (w, h) in [(120, 40), (80, 24)] {
            let screen = render(&app, w, h);
            assert!(screen.contains("dim: before reload"), "{w}×{h}\n{screen}");
        }
        app.on_telemetry(started(virtual_cfg(50.0, 10)));
        assert!(app.view().ghost_angle.is_empty());
        assert!(app.view().latency.ghost.is_empty());
    }

    #[test]
    fn the_lab_draws_its_own_graph_before_the_run_starts() {
        let (tx, _rx) = crossbeam_channel::unbounded();
        let mut app = App::new(tx, "scripted".into(), None, Speed::Times(1.0));
        app.show_graph(graph_cfg("graphs/cartpole-estimator.toml", 1).graph);
        let names: Vec<String> = app.view().nodes.iter().map(|n| n.name.clone()).collect();
        assert!(names.contains(&"estimator".to_string()), "{names:?}");
    }

    fn graph_cfg(file: &str, secs: u64) -> RunConfig {
        let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("..")
            .join(file);
        RunConfig {
            clock: ClockKind::Virtual,
            duration: ratelab::Nanos(secs * 1_000_000_000),
            graph: ratelab::graph::GraphSpec::load(&path).unwrap(),
            ..RunConfig::default()
        }
    }

    /// A node under an injected fault says so in its box (a lease, when it has one, then
    /// says NOT ALIVE), and no arrow it publishes or reads carries a green tick (#25).
    #[test]
    fn an_injected_stall_or_kill_shows_on_its_node_and_takes_the_tick_off_its_topics() {
        // The policy stalled from 1 s: the pole falls at 2.42 s, the policy still stalled.
        let mut cfg = virtual_cfg(50.0, 5);
        cfg.faults = vec![ratelab::qos::Fault::parse("policy@1+3", false).unwrap()];
        let (app, _rx) = app_after(cfg, true);
        for (w, h) in [(80, 24), (120, 40)] {
            let text = render(&app, w, h);
            assert_eq!(text.matches("✗ STALLED").count(), 1, "{w}x{h}:\n{text}");
            assert!(!text.contains("dropped ✓"), "{w}x{h}:\n{text}");
        }
        // The actuator killed at 1 s of 3: the engine's last status is at 3 s.
        let mut cfg = virtual_cfg(50.0, 3);
        cfg.faults = vec![ratelab::qos::Fault::parse("actuator@1", true).unwrap()];
        let depths: Vec<usize> = cfg.graph.topics.iter().map(|t| t.depth).collect();
        let qos = cfg.graph.topics.iter().map(|t| t.qos).collect();
        let (mut app, _rx) = app_after(cfg, false);
        app.on_telemetry(Telemetry::Status {
            now: ratelab::Nanos(3_000_000_000),
            paused: false,
            speed: Speed::Times(1.0),
            rates: vec![50.0; 3],
            depths,
            qos,
            alive: vec![None; 3],
            policy: "scripted balancer".into(),
            exec: None,
            topics: None,
        });
        let text = render(&app, 80, 24);
        assert_eq!(text.matches("✗ KILLED").count(), 1, "{text}");
        // /obs still flows (sensor to policy); /action's reader is dead.
        assert_eq!(text.matches("dropped ✓").count(), 1, "{text}");
    }

    /// The lab's `k` mid-run (a fault injected as a change, not at the start) marks its node
    /// while it lasts, as a fault given at the start does; a seek back before it drops it.
    #[test]
    fn a_stall_injected_mid_run_shows_while_it_lasts_and_goes_with_a_seek_back() {
        let cfg = virtual_cfg(50.0, 3);
        let report = run(&cfg, Box::new(Scripted), RunOptions::new()).unwrap();
        let at = ratelab::Nanos(1_000_000_000);
        let (mut app, _rx) = told(&cfg, &report.trace, at);
        let fault = ratelab::run::Command::InjectFault {
            fault: "policy@1.000+0.5".into(),
        };
        // As the engine tells it (`Engine::apply_with`).
        app.on_telemetry(Telemetry::Faulted(
            ratelab::command::parse_fault("policy@1.000+0.5").unwrap(),
        ));
        app.on_telemetry(Telemetry::Changed {
            at,
            text: ratelab::session::describe(&fault),
        });
        let feed = |app: &mut App, from: f64, to: f64| {
            for s in (report.trace.iter())
                .filter(|s| s.t.as_secs_f64() > from && s.t.as_secs_f64() <= to)
            {
                app.on_telemetry(Telemetry::Step(Box::new(s.clone())));
            }
        };
        feed(&mut app, 1.0, 1.2);
        for (w, h) in [(80, 24), (120, 40)] {
            let text = render(&app, w, h);
            assert_eq!(text.matches("✗ STALLED").count(), 1, "{w}x{h}:\n{text}");
            assert!(!text.contains("dropped ✓"), "{w}x{h}:\n{text}");
        }
        feed(&mut app, 1.2, 1.6);
        let text = render(&app, 120, 40);
        assert!(!text.contains("STALLED"), "over at 1.5 s:\n{text}");
        // Back before it: the branch has no fault.
        app.on_telemetry(Telemetry::Rewound {
            at: ratelab::Nanos(500_000_000),
        });
        feed(&mut app, 0.5, 1.2);
        let text = render(&app, 120, 40);
        assert!(!text.contains("STALLED"), "{text}");
        // Injected paused at 1.2 s, it takes effect at the next instant (1.22 s): a seek
        // back to 1.2 s, where the lab heard of it, is before it and drops it.
        app.on_telemetry(Telemetry::Faulted(
            ratelab::command::parse_fault("policy@1.22+0.48").unwrap(),
        ));
        let text = render(&app, 120, 40);
        assert!(!text.contains("STALLED"), "not yet at 1.2 s: {text}");
        app.on_telemetry(Telemetry::Rewound {
            at: ratelab::Nanos(1_200_000_000),
        });
        feed(&mut app, 1.2, 1.4);
        let text = render(&app, 120, 40);
        assert!(!text.contains("STALLED"), "the branch has no fault: {text}");
    }

    /// The verdict reads whole in the narrow cartpole panel (80 columns): the panel's name
    /// gives way first (#25).
    #[test]
    fn the_verdict_reads_whole_at_80_columns() {
        let mut cfg = virtual_cfg(50.0, 3);
        cfg.faults = vec![ratelab::qos::Fault::parse("actuator@1+0.5", false).unwrap()];
        let (app, _rx) = app_after(cfg, true);
        let text = render(&app, 80, 24);
        assert!(text.contains("┌ BALANCED while the plant ran ┐"), "{text}");
        let mut cfg = virtual_cfg(50.0, 3);
        cfg.faults = vec![ratelab::qos::Fault::parse("actuator@1", true).unwrap()];
        let (app, _rx) = app_after(cfg, true);
        let text = render(&app, 80, 24);
        assert!(text.contains("┌ ACTUATOR KILLED at t=1.00s ─"), "{text}");
        let (app, _rx) = app_after(virtual_cfg(50.0, 2), true);
        let text = render(&app, 80, 24);
        assert!(text.contains("┌ BALANCED ✓ (run complete) ─"), "{text}");
        let text = render(&app, 120, 40);
        assert!(
            text.contains("┌ cartpole  BALANCED ✓ (run complete) ─"),
            "{text}"
        );
    }

    /// While the run goes on with its actuator killed (or stalled now), the plant stands
    /// still: the badge says so, not BALANCED; before the fault, and after a stall, it is
    /// balanced again.
    #[test]
    fn a_run_going_on_with_its_actuator_killed_or_stalled_is_not_balanced() {
        for (fault, kill, at_1_2, at_2_5) in [
            (
                "actuator@1",
                true,
                "ACTUATOR KILLED at t=1.00s",
                "ACTUATOR KILLED",
            ),
            (
                "actuator@1+0.5",
                false,
                "ACTUATOR STALLED at t=1.00s",
                "BALANCED ✓",
            ),
        ] {
            let mut cfg = virtual_cfg(50.0, 3);
            cfg.faults = vec![ratelab::qos::Fault::parse(fault, kill).unwrap()];
            let report = run(&cfg, Box::new(Scripted), RunOptions::new()).unwrap();
            let trace = report.trace;
            for (upto, want) in [(0.9, "BALANCED ✓"), (1.2, at_1_2), (2.5, at_2_5)] {
                let at = ratelab::Nanos::from_secs_f64(upto).unwrap();
                let (mut app, _rx) = told(&cfg, &trace, at);
                // The engine's status tells the time on: a killed actuator steps no more.
                let mut status = chapter_status(
                    vec![ratelab::qos::TopicQos::default(); 2],
                    vec![Some(true); 3],
                );
                if let Telemetry::Status { now, .. } = &mut status {
                    *now = at;
                }
                app.on_telemetry(status);
                // Whole in the narrow panel too.
                let narrow = render(&app, 80, 24);
                assert!(narrow.contains(want), "{fault} at {upto} s: {narrow}");
                let text = render(&app, 120, 40);
                assert!(text.contains(want), "{fault} at {upto} s: {text}");
                if want != "BALANCED ✓" {
                    assert!(!text.contains("BALANCED"), "{fault} at {upto} s: {text}");
                }
            }
        }
    }

    /// A watchdog's stop is not a fall: the footer says which ended the run (#25).
    #[test]
    fn a_watchdog_stop_is_not_called_a_fall() {
        let mut cfg = virtual_cfg(50.0, 5);
        cfg.graph
            .set_qos("/action", "deadline_ms=40,on_deadline_missed=stop")
            .unwrap();
        cfg.faults = vec![ratelab::qos::Fault::parse("policy@2+0.5", false).unwrap()];
        let (app, _rx) = app_after(cfg, true);
        let text = render(&app, 80, 24);
        let footer = text.lines().last().unwrap_or_default();
        assert!(
            footer.contains("stopped by watchdog — keys set"),
            "{footer}"
        );
        assert!(!text.contains("the pole fell"), "{text}");
        assert!(text.contains("STOPPED BY WATCHDOG at t=2.04s"), "{text}");
    }

    /// A subscription its publisher does not connect (incompatible QoS) breaks its arrow in
    /// red, says why where there is room (at 120 columns the whole request and offer; at
    /// 80 what was wanted) and the pole falls with no force applied.
    #[test]
    fn an_incompatible_subscription_breaks_its_arrow_at_both_sizes() {
        let (app, _rx) = app_after(graph_cfg("graphs/cartpole-incompatible-qos.toml", 2), true);
        let small = render(&app, 80, 24);
        assert!(small.contains("incompatible"), "{small}");
        assert!(small.contains("wants RELIABLE"), "{small}");
        assert!(small.contains("FELL"), "{small}");
        let big = render(&app, 120, 40);
        assert!(big.contains("incompatible QoS"), "{big}");
        assert!(big.contains("RELIABLE, offered"), "{big}");
        assert!(big.contains("BEST_EFFORT"), "{big}");
        insta::assert_snapshot!("incompatible_80x24", small);
        insta::assert_snapshot!("incompatible_120x40", big);
        // The /obs arrow beside it stays whole and green.
        let obs = app
            .view()
            .topics
            .iter()
            .find(|t| t.name == "/obs")
            .cloned()
            .unwrap();
        assert!(obs.incompatible.is_empty() && !obs.unhealthy);
    }

    #[test]
    fn snapshot_shipped_graphs_at_80x24() {
        for (name, file) in [
            ("estimator", "graphs/cartpole-estimator.toml"),
            ("safety", "graphs/cartpole-safety.toml"),
            // A learner's Python node says so in its box.
            ("safety_python", "graphs/cartpole-safety-python.toml"),
            // Two inputs and two outputs; /error has no subscriber (a dashed arrow).
            ("setpoint", "graphs/cartpole-setpoint.toml"),
        ] {
            let (app, _rx) = app_after(graph_cfg(file, 2), false);
            let text = render(&app, 80, 24);
            for n in &app.view().nodes {
                assert!(
                    text.contains(&n.name),
                    "{name}: node {} not shown:\n{text}",
                    n.name
                );
            }
            for t in &app.view().topics {
                assert!(
                    text.contains(&t.name),
                    "{name}: topic {} not shown:\n{text}",
                    t.name
                );
            }
            // A dropping topic keeps its mark where its words do not fit.
            if name == "estimator" {
                assert!(text.contains("200 drop ⚠"), "{text}");
            }
            insta::assert_snapshot!(format!("graph_{name}_80x24"), text);
        }
    }

    /// A lab's settings with a generated graph of `nodes` nodes in one process.
    fn synthetic_cfg(nodes: usize) -> RunConfig {
        let mut cfg = graph_cfg("graphs/cartpole.toml", 2);
        cfg.graph = ratelab::graph::GraphSpec::parse(
            &ratelab::graph::synthetic::graph_toml(nodes, 1),
            "synthetic",
        )
        .unwrap();
        cfg
    }

    #[test]
    fn a_200_node_graph_shows_what_fits_and_counts_the_rest() {
        let cfg = synthetic_cfg(200);
        let (app, _rx) = app_after(cfg, false);
        for (w, h) in [(80, 24), (120, 40)] {
            let text = render(&app, w, h);
            assert!(text.contains("graph: 200 nodes, 199 topics"), "{text}");
            assert!(text.contains("sensor_0"), "{text}");
            // Every column of nodes and of topics counts what it could not show: 4 layers
            // of nodes, each with a column of the topics it publishes (the last none).
            let more: usize = text.lines().map(|l| l.matches(" more").count()).sum();
            assert_eq!(more, 8, "{text}");
            insta::assert_snapshot!(format!("graph_200_nodes_{w}x{h}"), text);
        }
    }

    /// The same graph zoomed to names and to the list, scrolled, filtered by name and by
    /// trouble, at both sizes.
    #[test]
    fn a_200_node_graph_zooms_scrolls_and_filters() {
        let cfg = synthetic_cfg(200);
        let (mut app, _rx) = app_after(cfg, false);
        // Scrolled three rows (after a frame was drawn, as on a screen: the drawing says how
        // far scrolling can go): every long column counts what is above and below.
        render(&app, 120, 40);
        for _ in 0..3 {
            app.on_msg(Msg::ScrollDown);
        }
        let text = render(&app, 120, 40);
        assert!(text.contains("↑3 ↓"), "{text}");
        app.on_msg(Msg::ScrollTop);
        // Names: a row per node and topic, each topic beside its publisher's row.
        app.on_msg(Msg::Zoom);
        for (w, h) in [(80, 24), (120, 40)] {
            let text = render(&app, w, h);
            assert!(text.contains("sensor_0 "), "{text}");
            assert!(text.contains("▶ /c_0/pos"), "{text}");
            // Each topic right under its publisher.
            let rows: Vec<&str> = text.lines().collect();
            let at = rows.iter().position(|l| l.contains("sensor_0 ")).unwrap();
            assert!(rows[at + 1].contains("▶ /c_0/pos"), "{text}");
            insta::assert_snapshot!(format!("graph_200_names_{w}x{h}"), text);
        }
        // The list: every node and topic with its figures, over the plant's rows.
        app.on_msg(Msg::Zoom);
        for (w, h) in [(80, 24), (120, 40)] {
            let text = render(&app, w, h);
            assert!(text.contains("NODES 200"), "{text}");
            assert!(!text.contains("cart "), "the plant gave its rows: {text}");
            insta::assert_snapshot!(format!("graph_200_list_{w}x{h}"), text);
        }
        // Scrolled to the end: the last topics, and what is above counted (on the screen
        // it is drawn on: how far scrolling goes depends on its size).
        render(&app, 80, 24);
        for _ in 0..1000 {
            app.on_msg(Msg::ScrollDown);
        }
        let text = render(&app, 80, 24);
        assert!(text.contains("/c_48/cmd"), "{text}");
        assert!(text.contains("↑ "), "{text}");
        // A filter by name, typed.
        app.on_msg(Msg::Filter);
        for c in "estimator_1".chars() {
            app.on_msg(Msg::Input(c));
        }
        app.on_msg(Msg::Submit);
        let text = render(&app, 80, 24);
        assert!(
            text.contains("NODES 11"),
            "estimator_1 and _10 … _19:\n{text}"
        );
        assert!(!text.contains("sensor_1 "), "{text}");
        insta::assert_snapshot!("graph_200_list_filtered_80x24", text);
        // Down the list: the topics they publish.
        for _ in 0..20 {
            app.on_msg(Msg::ScrollDown);
        }
        let text = render(&app, 80, 24);
        assert!(text.contains("/c_1/state"), "{text}");
        // Nothing in trouble in a balanced run: the boxes say so, and how to clear it.
        app.on_msg(Msg::ToggleTrouble);
        app.on_msg(Msg::Zoom);
        let text = render(&app, 80, 24);
        assert!(
            text.contains("nothing matches /estimator_1 · trouble"),
            "{text}"
        );
        // Esc clears it: the boxes whole again.
        app.on_msg(Msg::Back);
        let text = render(&app, 80, 24);
        assert!(text.contains("graph: 200 nodes, 199 topics"), "{text}");
    }

    /// Tab selects only what the filter shows, and the list keeps the selection in view.
    #[test]
    fn tab_selects_among_what_the_filter_shows() {
        let cfg = synthetic_cfg(200);
        let (mut app, _rx) = app_after(cfg, false);
        app.on_msg(Msg::Filter);
        for c in "@robot".chars() {
            app.on_msg(Msg::Input(c));
        }
        app.on_msg(Msg::Submit);
        // The process each node runs in under `launch --processes`: the plant's nodes in
        // `robot` (the chapter's sensor and actuator, 49 controllers' sensors, one extra).
        let shown = app.view().nodes.iter().filter(|n| n.shown).count();
        assert_eq!(shown, 52);
        app.on_msg(Msg::Filter);
        for c in "safety_48".chars() {
            app.on_msg(Msg::Input(c));
        }
        app.on_msg(Msg::Submit);
        app.on_msg(Msg::SelectNext);
        let v = app.view();
        let sel: Vec<&str> = v
            .nodes
            .iter()
            .filter(|n| n.selected)
            .map(|n| n.name.as_str())
            .collect();
        assert_eq!(sel, ["safety_48"]);
        // Next: its topic, then nothing, then it again.
        app.on_msg(Msg::SelectNext);
        assert!(app
            .view()
            .topics
            .iter()
            .any(|t| t.selected && t.name == "/c_48/cmd"));
        app.on_msg(Msg::SelectNext);
        assert!(!app.view().nodes.iter().any(|n| n.selected));
        app.on_msg(Msg::SelectPrev);
        assert!(app
            .view()
            .topics
            .iter()
            .any(|t| t.selected && t.name == "/c_48/cmd"));
        // In the list, at the end of 200 rows, the selection is in view.
        app.on_msg(Msg::Back);
        app.on_msg(Msg::Back);
        app.on_msg(Msg::Zoom);
        app.on_msg(Msg::Zoom);
        for _ in 0..=(3 + 4 * 48 + 3) {
            app.on_msg(Msg::SelectNext);
        }
        let text = render(&app, 80, 24);
        assert!(text.contains("safety_48 selected"), "{text}");
        assert!(text.lines().any(|l| l.contains("│safety_48 ")), "{text}");
    }

    /// At 80×24 the graph panel's title reads whole, for every selection of every shipped
    /// graph and for a wide graph's own title: what does not fit gives way (the topics in a
    /// title, `Tab next`), never the end of a word.
    #[test]
    fn the_graph_panel_s_title_fits_80_columns_whatever_is_selected() {
        for file in [
            "graphs/cartpole.toml",
            "graphs/cartpole-setpoint.toml",
            "graphs/cartpole-estimator.toml",
            "graphs/cartpole-safety.toml",
        ] {
            let (mut app, _rx) = app_after(graph_cfg(file, 2), false);
            let n = app.view().nodes.len() + app.view().topics.len();
            for _ in 0..=n {
                let text = render(&app, 80, 24);
                let title = text.lines().nth(1).unwrap_or("").trim_matches('"');
                // Whole: the title ends with its space, then the border runs to the corner.
                let inner = title
                    .trim_start_matches('┌')
                    .trim_end_matches('┐')
                    .trim_end_matches('─');
                assert!(inner.ends_with(' '), "{file}: the title is cut: {title}");
                app.on_msg(Msg::SelectNext);
            }
        }
    }

    /// A topic whose subscriber missed its deadline gets no green tick, though nothing was
    /// dropped (the policy stalled: no force for half a second).
    #[test]
    fn a_missed_deadline_takes_the_green_tick_off_its_topic() {
        let mut cfg = virtual_cfg(50.0, 2);
        cfg.graph.set_qos("/action", "deadline_ms=30").unwrap();
        cfg.faults = vec![ratelab::qos::Fault::parse("policy@1+0.5", false).unwrap()];
        let (app, _rx) = app_after(cfg, false);
        let view = app.view();
        let action = view.topics.iter().find(|t| t.name == "/action").unwrap();
        let obs = view.topics.iter().find(|t| t.name == "/obs").unwrap();
        assert!(
            action.unhealthy && !action.dropping,
            "{:?}",
            action.qos_counts
        );
        assert!(!obs.unhealthy, "/obs has no deadline, its nodes are alive");
        let text = render(&app, 120, 40);
        assert!(text.contains("dl miss"), "{text}");
        // The ✗ stands by the misses, not by the zero drops.
        assert!(
            text.contains("dl miss ✗") && !text.contains("dropped ✓"),
            "{text}"
        );
        assert!(!text.contains("dropped ✗"), "{text}");
        // At 80 columns too: the ✗ stays, no green tick on the topic.
        let small = render(&app, 80, 24);
        assert!(small.contains('✗'), "{small}");
        assert!(
            !small.contains("drop ✓") && !small.contains("dropped ✓"),
            "{small}"
        );
    }

    /// #25's case: a leased policy stalled at 1 s falls at 2.42 s. At the fall the lab must
    /// not show `/action` at 50 msg/s (its publisher has sent nothing for 1.42 s: 20.2 over
    /// the run's 2.4 s, with a ✗), and it shows the policy stalled, at both sizes.
    #[test]
    fn a_stalled_publisher_s_topic_reads_its_silence_at_the_fall() {
        let mut cfg = virtual_cfg(50.0, 10);
        cfg.graph.set_lease("policy", 60.0).unwrap();
        cfg.faults = vec![ratelab::qos::Fault::parse("policy@1+3", false).unwrap()];
        let (app, _rx) = app_after(cfg, true);
        assert!(matches!(app.view().verdict, super::view::Verdict::Fell(_)));
        let action = app
            .view()
            .topics
            .iter()
            .find(|t| t.name == "/action")
            .cloned()
            .unwrap();
        assert!(action.msg_per_s < 40.0, "{:?}", action.msg_per_s);
        for (w, h) in [(80, 24), (120, 40)] {
            let text = render(&app, w, h);
            // The node names its state: the injected stall (it is also not alive).
            assert!(text.contains("✗ STALLED"), "{w}x{h}: {text}");
            assert!(!text.contains("50.0 msg/s ✓"), "{w}x{h}: {text}");
            assert!(text.contains("20.2 msg/s ✗"), "{w}x{h}: {text}");
            let rates: Vec<&str> = text.matches("50.0 msg/s").collect();
            assert!(
                rates.len() <= 1,
                "only /obs keeps its rate: {w}x{h}: {text}"
            );
        }
    }

    /// `L` on a selected topic walks the link-loss ladder all the way to 80 % (exercise 5
    /// needs it; it stopped at 20 %), then back to none.
    #[test]
    fn the_loss_ladder_reaches_80_percent_and_wraps() {
        let (mut app, rx) = app_after(virtual_cfg(50.0, 1), false);
        // Tab past the three nodes to /obs.
        for _ in 0..4 {
            app.on_msg(Msg::SelectNext);
        }
        assert!(app.view().topics[0].selected);
        // The engine's side: each command applied to the graph, its QoS in the next status.
        let mut graph = ratelab::graph::GraphSpec::chapter();
        let mut sent = Vec::new();
        for _ in 0..6 {
            app.on_msg(Msg::CycleLoss);
            for c in rx.try_iter() {
                if let Control::Apply(ratelab::run::Command::SetTopicQos { topic, pairs }) = c {
                    graph.set_qos(&topic, &pairs).unwrap();
                    sent.push(format!("{topic}:{pairs}"));
                }
            }
            let qos = graph.topics.iter().map(|t| t.qos).collect();
            app.on_telemetry(chapter_status(qos, vec![None; 3]));
        }
        assert_eq!(
            sent,
            [
                "/obs:loss=0.01",
                "/obs:loss=0.05",
                "/obs:loss=0.2",
                "/obs:loss=0.5",
                "/obs:loss=0.8",
                "/obs:loss=0",
            ]
        );
    }

    /// At 80×24 an arrow keeps room for few QoS counters: the ones that counted come first
    /// (a lossy /cmd with a lifespan showed "0 expired" and hid its losses behind its ✗).
    #[test]
    fn at_80x24_the_counters_that_counted_come_first() {
        let mut cfg = graph_cfg("graphs/cartpole-safety.toml", 6);
        cfg.graph
            .set_qos("/cmd", "deadline_ms=40,lifespan_ms=60,loss=0.2")
            .unwrap();
        let (app, _rx) = app_after(cfg, false);
        let small = render(&app, 80, 24);
        assert!(small.contains(" lost ✗"), "{small}");
        assert!(!small.contains("dropped ✗"), "{small}");
        assert!(!small.contains("0 expired"), "{small}");
    }

    #[test]
    fn at_80x24_an_arrow_s_qos_rides_on_its_shaft() {
        let mut cfg = graph_cfg("graphs/cartpole.toml", 2);
        cfg.graph
            .set_qos(
                "/action",
                "deadline_ms=40,on_deadline_missed=stop,reliability=reliable",
            )
            .unwrap();
        let (app, _rx) = app_after(cfg, false);
        let text = render(&app, 80, 24);
        // The deadline and its reaction on the shaft, in short; the counters still below.
        let shaft = text
            .lines()
            .find(|l| l.contains("▶") && l.contains("dl 40"))
            .unwrap_or_else(|| panic!("no QoS on a shaft:\n{text}"));
        assert!(shaft.contains("dl 40 stop"), "{shaft}");
        assert!(text.contains("dl miss"), "{text}");
        // At 120×40 it is whole.
        let (app, _rx) = app_after(
            {
                let mut c = graph_cfg("graphs/cartpole.toml", 2);
                c.graph
                    .set_qos(
                        "/action",
                        "deadline_ms=40,on_deadline_missed=stop,reliability=reliable",
                    )
                    .unwrap();
                c
            },
            false,
        );
        let text = render(&app, 120, 40);
        assert!(text.contains("dl 40 ms stop rel"), "{text}");
    }

    #[test]
    fn qos_shows_on_the_edges_and_a_dead_node_is_drawn_so() {
        let mut cfg = graph_cfg("graphs/cartpole-safety.toml", 2);
        cfg.graph
            .set_qos(
                "/cmd",
                "loss=0.2,delay_ms=5,deadline_ms=30,on_deadline_missed=zero",
            )
            .unwrap();
        cfg.graph.set_qos("/obs", "delivery=fifo,depth=10").unwrap();
        cfg.graph.set_lease("policy", 60.0).unwrap();
        cfg.faults = vec![ratelab::qos::Fault::parse("policy@1.8", true).unwrap()];
        let depths: Vec<usize> = cfg.graph.topics.iter().map(|t| t.depth).collect();
        let qos = cfg.graph.topics.iter().map(|t| t.qos).collect();
        let (mut app, rx) = app_after(cfg, false);
        // What the engine reports at 2 s: the policy, killed at 1.8 s, is past its lease.
        app.on_telemetry(Telemetry::Status {
            now: ratelab::Nanos(2_000_000_000),
            paused: false,
            speed: Speed::Times(1.0),
            rates: vec![50.0; 4],
            depths,
            qos,
            alive: vec![None, Some(false), None, None],
            policy: "scripted balancer".into(),
            exec: None,
            topics: None,
        });
        let text = render(&app, 120, 40);
        for want in [
            "KL1 latest",
            "dl 30 ms",
            "link 20%",
            "KL10 fifo",
            "20 lost",
            "17 dl miss",
            "NOT ALIVE",
        ] {
            assert!(text.contains(want), "'{want}' not shown:\n{text}");
        }
        assert!(
            !text.contains("KL1 latest\n"),
            "the chapter's QoS is not labelled"
        );
        insta::assert_snapshot!("qos_120x40", text);
        let small = render(&app, 80, 24);
        // At 80×24 the dead node's words read whole, and /cmd's shaft carries its deadline
        // (without what a miss does: the shaft is too short for it).
        assert!(
            small.contains("20 lost") && small.contains("NOT ALIVE"),
            "{small}"
        );
        assert!(small.contains("─ dl 30 ─▶"), "{small}");
        insta::assert_snapshot!("qos_80x24", small);
        // f, d, L, l, e and o act on the selected topic only, as logged commands.
        app.on_msg(Msg::ToggleDelivery);
        assert!(
            rx.try_iter().next().is_none(),
            "nothing selected: nothing sent"
        );
        while !app.view().topics.last().unwrap().selected {
            app.on_msg(Msg::SelectNext);
        }
        app.on_msg(Msg::ToggleDelivery);
        app.on_msg(Msg::CycleDeadline);
        app.on_msg(Msg::CycleLoss);
        app.on_msg(Msg::CycleLifespan);
        app.on_msg(Msg::ToggleReliability);
        app.on_msg(Msg::CycleOnDeadlineMissed);
        // On a topic the actuator does not read, `o` says which one it reads, sending nothing.
        while !app
            .view()
            .topics
            .iter()
            .any(|t| t.selected && t.name != "/cmd")
        {
            app.on_msg(Msg::SelectNext);
        }
        app.on_msg(Msg::CycleOnDeadlineMissed);
        let said = app.view().message.unwrap_or_default();
        assert!(said.contains("select the topic it reads (/cmd)"), "{said}");
        use ratelab::run::Command::SetTopicQos;
        let sent: Vec<Control> = rx.try_iter().collect();
        let qos = |pairs: &str| {
            Control::Apply(SetTopicQos {
                topic: "/cmd".into(),
                pairs: pairs.into(),
            })
        };
        assert_eq!(
            sent,
            vec![
                qos("delivery=fifo"),
                qos("deadline_ms=50"), // 30 ms from the flags: the next one up
                qos("loss=0.5"),       // 20 % from the flags: the next one up
                qos("lifespan_ms=20"),
                qos("reliability=reliable"),
                qos("on_deadline_missed=stop"), // zero from the flags
            ]
        );
    }

    #[test]
    fn tab_selects_and_the_keys_follow_the_selection() {
        let (mut app, rx) = app_after(graph_cfg("graphs/cartpole-estimator.toml", 1), false);
        // Nothing selected: the chapter's keys (policy rate, every depth).
        app.on_msg(Msg::RateDown);
        app.on_msg(Msg::DepthUp);
        // Tab → sensor, Tab → estimator: its rate.
        app.on_msg(Msg::SelectNext);
        app.on_msg(Msg::SelectNext);
        assert!(app.view().nodes[1].selected);
        app.on_msg(Msg::RateDown);
        // Shift-Tab twice back to nothing, once more → the last topic: its depth.
        app.on_msg(Msg::SelectPrev);
        app.on_msg(Msg::SelectPrev);
        app.on_msg(Msg::SelectPrev);
        assert!(app.view().topics.last().unwrap().selected);
        app.on_msg(Msg::DepthUp);
        let text = render(&app, 80, 24);
        assert!(
            text.contains("/action selected: [/] its depth (5)"),
            "{text}"
        );
        // Esc closes the help, then clears the selection, then asks, and only then quits;
        // any other key in between cancels the question.
        app.on_msg(Msg::ToggleHelp);
        app.on_msg(Msg::Back);
        assert!(!app.view().help && !app.quit);
        app.on_msg(Msg::Back);
        assert!(app.view().topics.iter().all(|t| !t.selected) && !app.quit);
        app.on_msg(Msg::Back);
        assert!(!app.quit);
        assert!(render(&app, 80, 24).contains("quit? Esc again or q quits"));
        app.on_msg(Msg::ToggleHelp);
        app.on_msg(Msg::ToggleHelp);
        app.on_msg(Msg::Back);
        assert!(!app.quit, "a key between two Esc cancels the question");
        app.on_msg(Msg::Back);
        assert!(app.quit);
        use ratelab::run::Command::*;
        let sent: Vec<Control> = rx.try_iter().collect();
        assert_eq!(
            sent,
            vec![
                Control::Apply(SetControlHz { hz: 40.0 }),
                Control::Apply(SetQueueDepth { depth: 2 }),
                Control::Apply(SetNodeHz {
                    node: "estimator".into(),
                    hz: 60.0
                }),
                Control::Apply(SetTopicDepth {
                    topic: "/action".into(),
                    depth: 5
                }),
                Control::Quit,
            ]
        );
    }

    /// A 5 Hz policy's `/action` has one message until 0.2 s: its arrow says `measuring`
    /// (as the policy's box does under the real clock), not `0.0 msg/s`, which would say
    /// nothing was published; from its second message on, its rate. A run that ended with
    /// its window full says no `measuring`.
    #[test]
    fn a_slow_topic_reads_measuring_until_its_second_message() {
        let cfg = virtual_cfg(5.0, 2);
        let report = run(&cfg, Box::new(Scripted), RunOptions::new()).unwrap();
        let (app, _rx) = told(&cfg, &report.trace, ratelab::Nanos(100_000_000));
        let v = app.view();
        let (obs, action) = (&v.topics[0], &v.topics[1]);
        assert!(action.measuring && !obs.measuring, "{action:?} {obs:?}");
        let text = render(&app, 120, 40);
        assert!(text.contains("measuring"), "{text}");
        assert!(!text.contains(" 0.0 msg/s"), "{text}");
        let (app, _rx) = told(&cfg, &report.trace, ratelab::Nanos(700_000_000));
        let action = &app.view().topics[1];
        assert!(!action.measuring, "{action:?}");
        assert_eq!(action.msg_per_s, 5.0);
        let (app, _rx) = app_after(cfg, true);
        assert!(app.view().topics.iter().all(|t| !t.measuring));
    }

    #[test]
    fn msg_per_s_comes_from_stamps_and_a_slow_sensor_shows_stale_reads() {
        // A 5 Hz policy publishes exactly 5 /action messages a second, a 50 Hz sensor 50.
        let (app, _rx) = app_after(virtual_cfg(5.0, 3), false);
        let v = app.view();
        assert_eq!((v.topics[0].msg_per_s, v.topics[1].msg_per_s), (50.0, 5.0));
        // A 5 Hz sensor under a 50 Hz policy: no drops, but the policy reads each reading
        // ten times: 9 stale reads per reading.
        let mut cfg = virtual_cfg(50.0, 2);
        cfg.set_sensor_hz(5.0).unwrap();
        let (app, _rx) = app_after(cfg, false);
        let v = app.view();
        let obs = &v.topics[0];
        assert_eq!((obs.dropped, obs.msg_per_s), (0, 5.0));
        // Up to the last step (the pole falls on the way): policy ticks every 20 ms, the
        // sensor every 200 ms, each reading read fresh once (sensor first at shared instants).
        let ms = (v.sim_time_s * 1000.0).round() as u64;
        let (ticks, readings) = (ms / 20 + 1, ms / 200 + 1);
        assert_eq!(obs.stale_reads, ticks - readings, "{obs:?} at {ms} ms");
        assert!(obs.staling);
        let text = render(&app, 80, 24);
        assert!(
            text.contains(&format!("{} stale ↺", obs.stale_reads)),
            "{text}"
        );
        insta::assert_snapshot!("slow_sensor_stale_80x24", text);
    }

    #[test]
    fn at_80x24_an_arrow_with_stale_reads_still_shows_its_wire_line() {
        // A 5 Hz sensor under a 50 Hz policy (stale reads on /obs), with wire figures as a
        // launch across processes sends them: at 80×24 the arrow has five rows, so drops and
        // stale reads share one and the wire line (p50 only: p50/p99 is wider than the
        // arrow) keeps the fifth; at 120×40 each has its own line.
        let mut cfg = virtual_cfg(50.0, 2);
        cfg.set_sensor_hz(5.0).unwrap();
        let (mut app, _rx) = app_after(cfg, false);
        app.on_telemetry(Telemetry::Wire(vec![(0, 239.4, 1058.2), (1, 230.0, 400.0)]));
        let stale = app.view().topics[0].stale_reads;
        let small = render(&app, 80, 24);
        assert!(small.contains(&format!("0 drop ✓ {stale}↺")), "{small}");
        assert!(small.contains("wire 239 µs"), "{small}");
        assert!(small.contains("wire 230 µs"), "{small}");
        let big = render(&app, 120, 40);
        assert!(big.contains(&format!("{stale} stale ↺")), "{big}");
        assert!(big.contains("wire 239/1058 µs"), "{big}");
    }

    /// A seek back (Rewound) shows the run as it was then: the screen of a lab told the run
    /// up to 5 s, every row but the footer's message.
    #[test]
    fn rewound_the_lab_shows_the_run_as_it_was_then() {
        let cfg = virtual_cfg(8.0, 8);
        let report = run(&cfg, Box::new(Scripted), RunOptions::new()).unwrap();
        let at = ratelab::Nanos(5_000_000_000);
        let (mut back, _) = told(&cfg, &report.trace, ratelab::Nanos(8_000_000_000));
        let before = render(&back, 120, 40);
        back.on_telemetry(Telemetry::Rewound { at });
        let (a, b) = (
            render(&back, 120, 40),
            render(&told(&cfg, &report.trace, at).0, 120, 40),
        );
        assert_eq!(rows(&a), rows(&b));
        assert_ne!(rows(&a), rows(&before), "8 Hz falls between 5 and 8 s");
        // The engine paused there (a seek is made paused): the notice says where.
        let status = |paused: bool| Telemetry::Status {
            now: at,
            paused,
            speed: Speed::Times(1.0),
            rates: vec![50.0, 8.0, 50.0],
            depths: vec![1, 1],
            qos: Vec::new(),
            alive: Vec::new(),
            policy: "scripted".into(),
            exec: None,
            topics: None,
        };
        back.on_telemetry(status(true));
        let paused = render(&back, 120, 40);
        assert!(paused.contains("back at t=5.000 s"), "{paused}");
        // A step from there: the notice names where the run is now, not where it was said.
        let next = report.trace.iter().find(|s| s.t > at).unwrap();
        back.on_telemetry(Telemetry::Step(Box::new(next.clone())));
        let stepped = render(&back, 120, 40);
        let now = format!("back at t={:.3} s", next.t.as_secs_f64());
        assert!(
            stepped.contains(&now) && !stepped.contains("t=5.000 s"),
            "{stepped}"
        );
        // Resumed (space), the run goes on: the notice is not said of every instant after.
        back.on_telemetry(status(false));
        let resumed = render(&back, 120, 40);
        assert!(!resumed.contains("back at t="), "{resumed}");
    }

    /// Space on a real-clock run that has ended reviews it: ← and → show the run as it was
    /// then (the same screen as a lab told the run up to then, in the header REVIEW and the
    /// real clock), what the engine sends meanwhile waits, and space again shows the run as
    /// it ended. The engine is never asked (it cannot run the run again).
    #[test]
    fn an_ended_real_clock_run_is_reviewed_without_the_engine() {
        // 8 Hz falls at 22.5 s of a 30 s run (seed 0), as the chapter's cliff says.
        let mut cfg = virtual_cfg(8.0, 30);
        let report = run(&cfg, Box::new(Scripted), RunOptions::new()).unwrap();
        cfg.clock = ClockKind::Real;
        let (mut app, rx) = told(&cfg, &report.trace, report.end.at);
        app.on_telemetry(Telemetry::Ended {
            metrics: Box::new(report.metrics.clone()),
            reason: report.end.reason.clone(),
        });
        let ended = render(&app, 120, 40);
        assert!(ended.contains("FELL"), "{ended}");
        app.on_msg(Msg::TogglePause);
        assert!(app.scrubbing());
        let end = report.end.at;
        app.on_msg(Msg::SeekBack { second: true });
        app.on_msg(Msg::SeekBack { second: true });
        let back = end.saturating_sub(ratelab::Nanos(2_000_000_000));
        // The charts' titles read the run at the cursor; the rest is the screen as it was.
        let mut view = app.view();
        let readout = view
            .readout
            .take()
            .expect("reviewing: the readout at the cursor");
        assert_eq!(readout.cursor_s, back.as_secs_f64());
        let shown = render_view(&view, 120, 40);
        assert!(shown.contains("real clock REVIEW"), "{shown}");
        let (then, _) = told(&cfg, &report.trace, back);
        assert_eq!(
            rows(&shown)[1..],
            rows(&render(&then, 120, 40))[1..],
            "the screen as it was at {back}"
        );
        // The engine's repeated status waits; forward stops at the end.
        app.on_telemetry(chapter_status(vec![Default::default(); 2], vec![None; 3]));
        for _ in 0..5 {
            app.on_msg(Msg::SeekForward { second: true });
        }
        app.on_msg(Msg::TogglePause);
        assert!(!app.scrubbing());
        assert_eq!(rows(&render(&app, 120, 40))[1..], rows(&ended)[1..]);
        assert!(rx.try_recv().is_err(), "the engine was never asked");
    }

    /// With an estimator in the graph the pole-angle chart draws its estimate θ̂ beside the
    /// truth θ, in every window, and its title keys it; without one, nothing of it.
    #[test]
    fn the_angle_chart_shows_an_estimator_s_estimate_beside_the_truth() {
        let mut cfg = virtual_cfg(50.0, 12);
        cfg.graph = ratelab::graph::GraphSpec::load(
            &std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
                .join("../graphs/cartpole-estimator.toml"),
        )
        .unwrap();
        let report = run(&cfg, Box::new(Scripted), RunOptions::new()).unwrap();
        let (mut app, _) = told(&cfg, &report.trace, cfg.duration);
        let v = app.view();
        // Each step's estimate, drawn where the θ line shows the state it estimates: the
        // angle the step before reached is the truth a step's estimate is of.
        let trace = &report.trace;
        for w in trace.windows(2) {
            let truth = w[1].estimate.as_ref().unwrap().truth[2];
            assert_eq!(truth, w[0].pole_angle, "at {}", w[1].t);
        }
        let want: Vec<(f64, f64)> = trace
            .windows(2)
            .filter_map(|w| {
                let e = w[1].estimate.as_ref()?.estimate?;
                Some((w[0].t.as_secs_f64(), e[2]))
            })
            .filter(|(t, _)| *t >= 2.0)
            .collect();
        assert_eq!(v.angle_estimate, want);
        for (w, h, key) in [
            (
                120,
                40,
                "pole angle (rad) · ── ±0.21 fall · θ̂ estimate · last 10 s",
            ),
            (80, 24, "θ (rad) · ── ±0.21 fall · θ̂ est · last 10 s"),
        ] {
            let text = render(&app, w, h);
            assert!(text.contains(key), "{w}×{h}:\n{text}");
        }
        for _ in 0..3 {
            app.on_msg(Msg::ChartsWider); // the whole run, thinned as the truth is
        }
        let v = app.view();
        assert_eq!(v.chart_label, "whole run");
        assert_eq!(
            v.angle_estimate.len(),
            report.trace.len() - 1,
            "all but t = 0"
        );
        let chapter = virtual_cfg(50.0, 2);
        let report = run(&chapter, Box::new(Scripted), RunOptions::new()).unwrap();
        let (app, _) = told(&chapter, &report.trace, chapter.duration);
        assert!(app.view().angle_estimate.is_empty());
        assert!(!render(&app, 120, 40).contains("θ̂"));
    }

    /// Tab to the estimator swaps the pole-angle chart for the estimator's: θ̇ and its
    /// estimate over the window (each where the θ line shows the state it is of), the
    /// estimate drawn over the truth in dashes, and its RMS error and lag the run's
    /// summary's (the same fold of the same points); its topic shows it too, Esc gives the
    /// pole angle back. Without it selected, the angle chart's bottom border gives θ̂'s
    /// figures and where the estimator's chart is.
    #[test]
    fn tab_to_the_estimator_shows_its_velocity_estimate_and_the_summary_s_figures() {
        use ratelab::estimate::{POLE_ANGLE, POLE_ANGVEL};
        let cfg = graph_cfg("graphs/cartpole-estimator.toml", 4);
        let report = run(&cfg, Box::new(Scripted), RunOptions::new()).unwrap();
        let summary = report.metrics.estimate.clone().expect("an estimator");
        let rms = summary.figures.rms.expect("estimates reached the policy");
        let (mut app, _) = told(&cfg, &report.trace, cfg.duration);
        let e = app.view().estimator.expect("the graph has an estimator");
        assert!(!e.shown && e.angvel.is_empty());
        assert_eq!((e.node.as_str(), e.topic.as_str()), ("estimator", "/state"));
        assert_eq!(e.figures.as_ref(), Some(&summary.figures));
        let angle = render(&app, 120, 40);
        let theta = format!("θ̂ RMS error {:.2} mrad", rms[POLE_ANGLE] * 1e3);
        assert!(angle.contains(&theta), "{angle}");
        assert!(angle.contains("Tab to estimator"), "{angle}");
        insta::assert_snapshot!("estimator_angle_120x40", angle);
        // Tab → sensor, Tab → estimator.
        app.on_msg(Msg::SelectNext);
        app.on_msg(Msg::SelectNext);
        let e = app.view().estimator.unwrap();
        assert!(e.shown);
        let points = |pick: fn(&ratelab::estimate::EstimatePoint) -> Option<f64>| {
            report
                .trace
                .windows(2)
                .filter_map(|w| Some((w[0].t.as_secs_f64(), pick(w[1].estimate.as_ref()?)?)))
                .collect::<Vec<(f64, f64)>>()
        };
        assert_eq!(e.angvel, points(|p| Some(p.truth[POLE_ANGVEL])));
        assert_eq!(
            e.angvel_estimate,
            points(|p| p.estimate.map(|x| x[POLE_ANGVEL]))
        );
        // The truth a point is of is the θ̇ the step before reached.
        for w in report.trace.windows(2) {
            let truth = w[1].estimate.as_ref().unwrap().truth[POLE_ANGVEL];
            assert_eq!(truth, w[0].pole_angvel, "at {}", w[1].t);
        }
        assert_eq!(e.angvel_estimate.len(), report.trace.len() - 1);
        let small = render(&app, 80, 24);
        let big = render(&app, 120, 40);
        let w = rms[POLE_ANGVEL] * 1e3;
        let lag = summary
            .figures
            .pole_angvel_lag_ms
            .expect("a lag under 250 ms");
        for text in [&small, &big] {
            assert!(text.contains(&format!("RMS {w:.1} mrad/s")), "{text}");
            assert!(text.contains(&format!("lag {lag:.0} ms")), "{text}");
            assert!(
                !text.contains("pole angle") && !text.contains("θ (rad)"),
                "{text}"
            );
        }
        assert!(small.contains("θ̇ vs est rad/s"), "{small}");
        assert!(big.contains("θ̇ (rad/s): true · estimate"), "{big}");
        // 120×40 has the bottom border: the error of θ and θ̇ and their lags.
        let both = format!(
            "RMS error θ {:.2} mrad · θ̇ {w:.1} mrad/s",
            rms[POLE_ANGLE] * 1e3
        );
        assert!(big.contains(&both), "{big}");
        insta::assert_snapshot!("estimator_80x24", small);
        insta::assert_snapshot!("estimator_120x40", big);
        // Paused, the title reads the tick at the cursor: θ̇ beside its estimate.
        app.on_telemetry(Telemetry::Status {
            now: cfg.duration,
            paused: true,
            speed: Speed::Times(1.0),
            rates: vec![200.0, 100.0, 50.0, 50.0],
            depths: vec![1; 3],
            qos: vec![Default::default(); 3],
            alive: vec![None; 4],
            policy: "scripted".into(),
            exec: None,
            topics: None,
        });
        let rec = report
            .trace
            .iter()
            .rev()
            .find(|s| s.t <= cfg.duration)
            .unwrap();
        let p = rec.estimate.as_ref().unwrap();
        let pair = format!(
            "θ̇ {} · est {} rad/s",
            ratelab::text::signed(p.truth[POLE_ANGVEL], 3),
            ratelab::text::signed(p.estimate.unwrap()[POLE_ANGVEL], 3)
        );
        let text = render(&app, 120, 40);
        assert!(text.contains(&pair), "{text}");
        // Its topic shows it too (policy, actuator, /meas, /state); Esc gives the angle back.
        for _ in 0..4 {
            app.on_msg(Msg::SelectNext);
        }
        assert!(app.view().estimator.unwrap().shown);
        app.on_msg(Msg::Back);
        assert!(!app.view().estimator.unwrap().shown);
        // The angle chart again (paused, its title reads the plant at the cursor).
        let text = render(&app, 80, 24);
        assert!(text.contains("-0.3") && !text.contains("· est "), "{text}");
    }

    /// `(` and `)` zoom the charts' window: 0.2 s of a 20 s run shows its last tenths (the
    /// axis in tenths), 30 s shows it from 0, the whole run of a long run spans it from 0
    /// with its points thinned; the title names the window.
    #[test]
    fn the_charts_zoom_from_0_2_s_to_the_whole_run() {
        let cfg = virtual_cfg(50.0, 20);
        let report = run(&cfg, Box::new(Scripted), RunOptions::new()).unwrap();
        let (mut app, _) = told(&cfg, &report.trace, cfg.duration);
        let v = app.view();
        assert_eq!(
            (v.chart_s, v.chart_label.as_str()),
            ((10.0, 20.0), "last 10 s")
        );
        let n = v.angle_history.len();
        assert!((500..=501).contains(&n), "10 s at 50 Hz: {n}");
        for _ in 0..5 {
            app.on_msg(Msg::ChartsNarrower);
        }
        let v = app.view();
        assert_eq!(v.chart_label, "last 0.2 s");
        let n = v.angle_history.len();
        assert!((10..=11).contains(&n), "0.2 s at 50 Hz: {n}");
        let text = render(&app, 120, 40);
        assert!(text.contains("last 0.2 s"), "{text}");
        assert!(text.contains("19.8s") && text.contains("20.0s"), "{text}");
        app.on_msg(Msg::ChartsNarrower); // stays at 0.2 s
        assert_eq!(app.view().chart_label, "last 0.2 s");
        for _ in 0..6 {
            app.on_msg(Msg::ChartsWider);
        }
        let v = app.view();
        assert_eq!(
            (v.chart_s, v.chart_label.as_str()),
            ((0.0, 30.0), "last 30 s")
        );
        assert_eq!(v.angle_history.len(), report.trace.len());
        for _ in 0..3 {
            app.on_msg(Msg::ChartsWider); // 60 s, the whole run, and it stays there
        }
        let v = app.view();
        assert_eq!(
            (v.chart_s, v.chart_label.as_str()),
            ((0.0, 20.0), "whole run")
        );
        assert!(v.published_force.is_empty(), "no dots over the whole run");
        let text = render(&app, 80, 24);
        assert!(text.contains("whole run"), "{text}");
    }

    /// `c` on a running lab: the header names the clock the run goes on under, the footer
    /// says the same run goes on, and the totals count from the switch; scrubbed back to
    /// where the real clock's part began, the lab is under the virtual clock as it was.
    #[test]
    fn a_clock_switch_in_place_shows_and_a_rewind_to_it_is_virtual_again() {
        let cfg = virtual_cfg(50.0, 4);
        let report = run(&cfg, Box::new(Scripted), RunOptions::new()).unwrap();
        let at = ratelab::Nanos(2_000_000_000);
        let (mut app, _) = told(&cfg, &report.trace, at);
        let before = render(&app, 120, 40);
        app.on_telemetry(Telemetry::ClockSwitched {
            at,
            clock: ClockKind::Real,
        });
        for s in report.trace.iter().filter(|s| s.t > at) {
            app.on_telemetry(Telemetry::Step(Box::new(s.clone())));
        }
        for (w, h) in [(80, 24), (120, 40)] {
            let text = render(&app, w, h);
            assert!(text.contains("real clock │ t 4.00 s"), "{w}x{h}:\n{text}");
            assert!(text.contains("since 2.00 s"), "{w}x{h}:\n{text}");
            assert!(
                text.contains("clock → real at t=2.00 s: the same run goes on"),
                "{w}x{h}:\n{text}"
            );
        }
        app.on_telemetry(Telemetry::Rewound { at });
        let back = render(&app, 120, 40);
        assert_eq!(rows(&back), rows(&before), "as it was before the switch");
    }

    #[test]
    fn a_lab_attached_mid_run_says_its_latency_counts_from_when_it_joined() {
        // The steps of a run from 6 s on, as a lab attached then sees them.
        let cfg = virtual_cfg(50.0, 8);
        let report = run(&cfg, Box::new(Scripted), RunOptions::new()).unwrap();
        let (tx, _rx) = crossbeam_channel::unbounded();
        let mut app = App::new(tx, "scripted".into(), None, Speed::Times(1.0));
        app.set_attached(super::attached_label(&cfg.graph));
        app.on_telemetry(Telemetry::Started {
            cfg,
            policy: "scripted".into(),
            recording: None,
        });
        let late = report
            .trace
            .iter()
            .filter(|s| s.t >= ratelab::Nanos(6_000_000_000));
        for s in late {
            app.on_telemetry(Telemetry::Step(Box::new(s.clone())));
        }
        let text = render(&app, 120, 40);
        assert!(text.contains("latency since 6.00 s (joined): n="), "{text}");
        // From the start, as in one process, it says so.
        let (app, _rx) = app_after(virtual_cfg(50.0, 2), false);
        assert!(render(&app, 120, 40).contains("latency since the start: n="));
    }

    #[test]
    fn a_narrow_node_box_keeps_late_by_dropping_spaces_and_digits_first() {
        // Real-clock nodes whose tick lateness p99 is 5, 124 and 1064 µs: at 80 columns a
        // box is 14 wide inside, where "p99 124 µs late" and "p99 1064 µs late" do not fit.
        // Each keeps what the figure is, never cut mid-word, so the three read alike.
        let (app, _rx) = app_after(virtual_cfg(50.0, 1), false);
        let mut view = app.view();
        for (n, late_us) in [(0, 5.0), (1, 124.0), (2, 1064.0)] {
            view.nodes[n].measured_hz = Some(50.0);
            view.nodes[n].lateness_p99_us = Some(late_us);
        }
        let text = |w, h| {
            let mut t = Terminal::new(TestBackend::new(w, h)).unwrap();
            t.draw(|f| f.render_widget(&view, f.area())).unwrap();
            t.backend().to_string()
        };
        let small = text(80, 24);
        for form in ["p99 5 µs late", "p99 124µs late", "p99 1.1ms late"] {
            assert!(small.contains(form), "{form}:\n{small}");
        }
        assert!(
            !small.contains("la\u{2502}"),
            "a word cut at the box's edge:\n{small}"
        );
        let large = text(120, 40);
        for form in ["p99 5 µs late", "p99 124 µs late", "p99 1064 µs late"] {
            assert!(large.contains(form), "{form}:\n{large}");
        }
    }

    /// After a change, the real clock's measured rate is the new setting's, not a mix with
    /// the one before (which read 20.6 Hz just after a change from 50 Hz to 5 Hz).
    #[test]
    fn a_real_clock_measured_rate_counts_from_the_last_change() {
        let cfg = RunConfig {
            clock: ClockKind::Real,
            ..virtual_cfg(50.0, 2)
        };
        let (mut app, _rx) = told(&cfg, &[], ratelab::Nanos::ZERO);
        let tick = |app: &mut App, ms: u64| {
            app.on_telemetry(Telemetry::NodeTick {
                node: 1,
                now: ratelab::Nanos(ms * 1_000_000),
                lateness: ratelab::Nanos(5_000),
                took: ratelab::Nanos(30_000),
            })
        };
        for k in 0..50 {
            tick(&mut app, k * 20);
        }
        app.on_telemetry(Telemetry::Changed {
            at: ratelab::Nanos(1_000_000_000),
            text: "control rate → 5 Hz".into(),
        });
        for k in 0..3 {
            tick(&mut app, 1_000 + k * 200);
        }
        let hz = app.view().nodes[1]
            .measured_hz
            .expect("two ticks since the change");
        assert!((hz - 5.0).abs() < 1e-9, "{hz}");
    }

    #[test]
    fn a_real_clock_node_box_shows_the_median_time_of_its_ticks() {
        let cfg = RunConfig {
            clock: ClockKind::Real,
            ..virtual_cfg(50.0, 1)
        };
        let (mut app, _rx) = told(&cfg, &[], ratelab::Nanos::ZERO);
        // Ticks of the policy (node 1) every 20 ms taking 30, 40 … 130 µs: the median of the
        // last second's is 80 µs.
        for k in 0..11u64 {
            app.on_telemetry(Telemetry::NodeTick {
                node: 1,
                now: ratelab::Nanos(k * 20_000_000),
                lateness: ratelab::Nanos(5_000),
                took: ratelab::Nanos(30_000 + k * 10_000),
            });
        }
        let view = app.view();
        assert_eq!(view.nodes[1].tick_p50_us, Some(80.0));
        assert_eq!(view.nodes[0].tick_p50_us, None, "no ticks heard of");
        let text = |w, h| {
            let mut t = Terminal::new(TestBackend::new(w, h)).unwrap();
            t.draw(|f| f.render_widget(&view, f.area())).unwrap();
            t.backend().to_string()
        };
        assert!(
            text(120, 40).contains("tick p50 80 µs"),
            "{}",
            text(120, 40)
        );
        // At 80×24 the box has no row left for it: the rate and lateness stay whole.
        let small = text(80, 24);
        assert!(
            small.contains("p99 5 µs late") && !small.contains("tick"),
            "{small}"
        );
    }

    /// A tick time past 999 µs reads whole in a narrow box: in ms where µs would not fit.
    #[test]
    fn a_long_tick_time_reads_whole_in_a_narrow_box() {
        let cfg = RunConfig {
            clock: ClockKind::Real,
            ..graph_cfg("graphs/cartpole-estimator.toml", 1)
        };
        let (mut app, _rx) = told(&cfg, &[], ratelab::Nanos::ZERO);
        // The policy (node 2) computes 2 ms a tick.
        for k in 0..11u64 {
            app.on_telemetry(Telemetry::NodeTick {
                node: 2,
                now: ratelab::Nanos(k * 20_000_000),
                lateness: ratelab::Nanos(5_000),
                took: ratelab::Nanos(2_024_000),
            });
        }
        let text = render(&app, 120, 40);
        assert!(text.contains("tick p50 2.0 ms"), "{text}");
        assert!(!text.contains("2024 µ"), "{text}");
    }

    #[test]
    fn after_50_5_50_hz_the_window_and_the_segment_see_only_the_matched_rates() {
        // The issue's sequence: 50 Hz, a dip to 5 Hz (4.0 s to 4.6 s: /obs drops), back to
        // 50 Hz until 12 s. The run's totals mix the three settings; the window (last 5 s)
        // and the segment (since the change at 4.6 s) see matched rates only.
        use ratelab::run::{Command, TimedCommand};
        let at = |ms: u64, hz: f64| TimedCommand {
            at_ns: ms * 1_000_000,
            command: Command::SetControlHz { hz },
        };
        let commands = vec![at(4_000, 5.0), at(4_600, 50.0)];
        let (app, _rx) =
            App::after_virtual_session(virtual_cfg(50.0, 12), commands.clone(), false).unwrap();
        let run_total = run(
            &virtual_cfg(50.0, 12),
            Box::new(Scripted),
            RunOptions {
                commands,
                ..RunOptions::new()
            },
        )
        .unwrap()
        .metrics;
        assert!(run_total.balanced, "the dip is short enough to survive");
        assert!(
            run_total.obs_dropped > Some(0),
            "the dip dropped /obs messages"
        );
        let v = app.view();
        let obs = &v.topics[0];
        // One drop in the segment, at its first instant: the sensor's tick at 4.60 s runs
        // before the policy's first 50 Hz tick and evicts the 4.58 s reading, which the 5 Hz
        // policy never read. None since (the window's 0), against the run's total.
        assert_eq!((obs.dropped, obs.segment_dropped), (0, 1), "{obs:?}");
        assert!(
            run_total.obs_dropped > Some(10),
            "{:?}",
            run_total.obs_dropped
        );
        assert!(!obs.dropping);
        assert_eq!((obs.msg_per_s, v.topics[1].msg_per_s), (50.0, 50.0));
        assert_eq!(v.segment.index, 3);
        assert_eq!(v.segment.start_s, 4.6);
        assert_eq!(v.segment.marks_s, [4.0, 4.6]);
        assert!(v.segment.window_full);
        // Matched rates act on the reading of the same instant: the segment's latency is 0,
        // where the run's p99 includes the dip's 180 ms.
        assert_eq!((v.latency.p99_ms, v.latency.window.p99_ms), (0.0, 0.0));
        assert!(
            run_total.latency_max_ms >= 100.0,
            "{}",
            run_total.latency_max_ms
        );
        assert_eq!(v.latency.count, 371, "steps from 4.60 s to 12 s");
        assert_eq!(v.latency.window.count, 250, "steps in (7 s, 12 s]");
        let small = render(&app, 80, 24);
        assert!(small.contains("last 5 s"), "{small}");
        assert!(
            small.contains("totals since 4.60 s: /obs 1 dropped"),
            "{small}"
        );
        assert!(small.contains("latency since 4.60 s: n=371"), "{small}");
        insta::assert_snapshot!("segments_80x24", small);
        let big = render(&app, 120, 40);
        assert!(
            big.contains(
                "arrows: last 5 s │ totals since the change at 4.60 s (control rate → 50 Hz)"
            ),
            "{big}"
        );
        insta::assert_snapshot!("segments_120x40", big);
        // In the middle of the dip: the window and the segment see the dip only.
        let (app, _rx) = App::after_virtual_session(
            virtual_cfg(50.0, 0).with_duration_ms(4_500),
            vec![at(4_000, 5.0)],
            false,
        )
        .unwrap();
        let v = app.view();
        let obs = &v.topics[0];
        assert!(obs.dropping && obs.dropped == obs.segment_dropped && obs.dropped > 0);
        assert_eq!(v.topics[1].msg_per_s, 5.0);
        let text = render(&app, 120, 40);
        assert!(
            text.contains(
                "arrows: last 0.5 s │ totals since the change at 4.00 s: /obs 22 dropped"
            ),
            "{text}"
        );
        insta::assert_snapshot!("segment_in_the_dip_120x40", text);
    }

    #[test]
    fn snapshot_the_hold_at_a_slow_policy() {
        // 8 Hz policy, 50 Hz actuator: each published force (a dot, every 125 ms) is applied
        // for six or seven actuator steps (the staircase).
        let (app, _rx) = app_after(virtual_cfg(8.0, 3), false);
        let v = app.view();
        assert_eq!(v.published_force.len(), 25, "8 Hz for 3 s, inclusive");
        let held = v
            .applied_force
            .chunks(2)
            .zip(v.applied_force.chunks(2).skip(1))
            .filter(|(a, b)| a[0].1 == b[0].1)
            .count();
        assert!(held > 100, "most steps re-apply the held force: {held}");
        let text = render(&app, 120, 40);
        assert!(text.contains("the hold"), "{text}");
        insta::assert_snapshot!("hold_80x24", render(&app, 80, 24));
        insta::assert_snapshot!("hold_120x40", text);
    }

    #[test]
    fn snapshot_a_starved_sensor_on_a_single_threaded_executor() {
        // graphs/cartpole-executors.toml single-threaded, 3 s: the sensor and the policy tick
        // once per 30 ms (100 ticks, 50 periods skipped), the actuator on its own thread.
        let mut cfg = graph_cfg("graphs/cartpole-executors.toml", 3);
        cfg.graph
            .set_executor(ratelab::executor::ExecutorOverride::parse("single_threaded").unwrap());
        let (mut app, _rx) = app_after(cfg, false);
        // The engine's status at `ms` of run time with each node's (ticks, skipped ticks).
        let status = |ms: u64, exec: Vec<(u64, u64)>| Telemetry::Status {
            now: ratelab::Nanos(ms * 1_000_000),
            paused: false,
            speed: Speed::Times(1.0),
            rates: vec![50.0; 3],
            depths: vec![1; 2],
            qos: vec![ratelab::qos::TopicQos::default(); 2],
            alive: vec![None; 3],
            policy: "scripted balancer".into(),
            exec: Some(exec),
            topics: None,
        };
        app.on_telemetry(status(3_000, vec![(101, 50), (101, 50), (151, 0)]));
        let v = app.view();
        assert_eq!(v.nodes[0].ran, Some((100.0 / 3.0, 50)));
        assert_eq!(v.nodes[1].compute.as_deref(), Some("30 ms"));
        let wide = render(&app, 120, 40);
        assert!(
            wide.contains("33.3 Hz · 50 skip")
                && wide.contains("30 ms compute")
                && wide.contains("50.0 Hz ran"),
            "{wide}"
        );
        let narrow = render(&app, 80, 24);
        assert!(narrow.contains("33 Hz·50 skip"), "{narrow}");
        insta::assert_snapshot!("executors_80x24", narrow);
        insta::assert_snapshot!("executors_120x40", wide);
        // Later, on threads of their own (as after a change): the box shows the window's
        // rate and skips, not the run's.
        app.on_telemetry(status(9_000, vec![(401, 50), (401, 50), (451, 0)]));
        assert_eq!(app.view().nodes[0].ran, Some((50.0, 0)));
        // A node that skipped no period ran at its rate, wherever between its ticks the
        // status falls: the actuator's 99 ticks from 1.001 s to 2.999 s are 49.5 over that
        // span, and every one of its periods.
        let (mut other, _rx) = app_after(graph_cfg("graphs/cartpole-executors.toml", 3), false);
        for (ms, ticks) in [(1_001, 51), (2_999, 150)] {
            other.on_telemetry(status(ms, vec![(ticks, 0); 3]));
        }
        assert_eq!(other.view().nodes[2].ran, Some((50.0, 0)));
        // A change of executors: the counts start again from it, never averaging the two
        // (one count is nothing to rate yet).
        app.on_telemetry(Telemetry::Changed {
            at: ratelab::Nanos(9_500_000_000),
            text: "executor → single_threaded".into(),
        });
        assert_eq!(app.view().nodes[0].ran, None);
        app.on_telemetry(status(10_000, vec![(416, 65), (416, 65), (476, 0)]));
        assert_eq!(app.view().nodes[0].ran, None);
        app.on_telemetry(status(11_000, vec![(449, 82), (449, 82), (526, 0)]));
        assert_eq!(app.view().nodes[0].ran, Some((33.0, 17)));
    }

    #[test]
    fn a_known_brain_shows_its_caption() {
        let (mut app, _rx) = app_after(virtual_cfg(50.0, 1), false);
        assert!(
            app.view().brain_caption.is_none(),
            "the scripted brain needs none"
        );
        app.on_telemetry(Telemetry::Status {
            now: ratelab::Nanos(0),
            paused: false,
            speed: Speed::Times(1.0),
            rates: vec![50.0; 3],
            depths: vec![1; 2],
            qos: vec![ratelab::qos::TopicQos::default(); 2],
            alive: vec![None; 3],
            policy: "ch2.1 PPO checkpoint (x.pt, hidden 64) — an imperfect learner".into(),
            exec: None,
            topics: None,
        });
        let text = render(&app, 120, 40);
        assert!(text.contains("brain: an imperfect learner"), "{text}");
    }

    #[test]
    fn a_long_recording_path_is_shortened_from_the_left() {
        assert_eq!(
            super::view::shorten_left("recordings/abc.rrd", 40),
            "recordings/abc.rrd"
        );
        assert_eq!(
            super::view::shorten_left("recordings/abcdef.rrd", 10),
            "…bcdef.rrd"
        );
    }

    /// Paused, ← puts the run a tick back and the charts' titles read it there: the cursor's
    /// run time, θ and θ̇, the force applied and its command's age, and the selected topic's
    /// counters, all the actuator's record at that tick (its `trace.csv` row's).
    #[test]
    fn paused_the_charts_read_the_run_at_the_scrub_cursor() {
        let cfg = virtual_cfg(8.0, 3);
        let report = run(&cfg, Box::new(Scripted), RunOptions::new()).unwrap();
        let end = ratelab::Nanos(3_000_000_000);
        let (mut app, rx) = told(&cfg, &report.trace, end);
        assert!(app.view().readout.is_none(), "running: no readout");
        let paused = |now| Telemetry::Status {
            now,
            paused: true,
            speed: Speed::Times(1.0),
            rates: vec![50.0, 8.0, 50.0],
            depths: vec![1, 1],
            qos: vec![Default::default(); 2],
            alive: vec![None; 3],
            policy: "scripted".into(),
            exec: None,
            topics: None,
        };
        app.on_telemetry(paused(end));
        assert!(app.view().readout.is_some(), "paused: the readout at once");
        // Tab to /obs (sensor, policy, actuator, /obs), then ← a tick of the actuator back.
        for _ in 0..4 {
            app.on_msg(Msg::SelectNext);
        }
        app.on_msg(Msg::SeekBack { second: false });
        let Ok(Control::Seek(at)) = rx.try_recv() else {
            panic!("← asks the engine for the run a tick back");
        };
        assert_eq!(at, ratelab::Nanos(2_980_000_000));
        // The engine ran the run again to there, and says so.
        app.on_telemetry(Telemetry::Rewound { at });
        // Paused through the rewind, before the engine's status comes: a second ← pressed
        // now is a seek, not the rate down it is while the run goes (which would branch it).
        assert!(app.scrubbing(), "still paused after the rewind");
        assert_eq!(
            super::keymap::map_key(
                crossterm::event::KeyEvent::from(crossterm::event::KeyCode::Left),
                app.typing(),
                app.scrubbing()
            ),
            Some(Msg::SeekBack { second: false })
        );
        app.on_telemetry(paused(at));
        app.on_telemetry(Telemetry::Sought { at });
        let rec = report.trace.iter().rev().find(|s| s.t <= at).unwrap();
        let obs = rec.topics.get(ratelab::graph::TopicId(0));
        let r = app.view().readout.expect("paused: the readout");
        assert_eq!(r.cursor_s, at.as_secs_f64());
        assert_eq!(
            (r.step_s, r.theta_rad, r.theta_dot_rad_s, r.force_n),
            (
                rec.t.as_secs_f64(),
                rec.pole_angle,
                rec.pole_angvel,
                rec.action * ratelab::plant::GEAR_N
            )
        );
        assert_eq!(
            r.counters
                .as_ref()
                .map(|c| (c.topic.as_str(), c.msgs, c.dropped)),
            Some(("/obs", obs.published, obs.dropped))
        );
        assert!(obs.dropped > 0, "8 Hz drops /obs");
        let text = render(&app, 80, 24);
        assert!(text.contains("t=2.980 s · θ "), "{text}");
        let counts = format!("{} msg {} drop", obs.published, obs.dropped);
        assert!(text.contains(&counts), "{text}");
        insta::assert_snapshot!("readout_paused_80x24", text);
        let wide = render(&app, 120, 40);
        let counts = format!("/obs {} msgs, {} dropped", obs.published, obs.dropped);
        assert!(
            wide.contains("t=2.980 s · θ ") && wide.contains(&counts),
            "{wide}"
        );
        // A burst of ← before the engine answers: a tick per key, each from the one before
        // (not three asks for the same tick).
        for _ in 0..3 {
            app.on_msg(Msg::SeekBack { second: false });
        }
        let ms = |ms: u64| Control::Seek(ratelab::Nanos(ms * 1_000_000));
        let asked: Vec<Control> = rx.try_iter().collect();
        assert_eq!(asked, vec![ms(2960), ms(2940), ms(2920)]);
        // The engine answers each (its status and `Sought`); while one is out, a ← goes on
        // from the last asked.
        let answer = |app: &mut App, at_ms: u64| {
            let at = ratelab::Nanos(at_ms * 1_000_000);
            app.on_telemetry(Telemetry::Rewound { at });
            app.on_telemetry(paused(at));
            app.on_telemetry(Telemetry::Sought { at });
        };
        answer(&mut app, 2960);
        answer(&mut app, 2940);
        app.on_msg(Msg::SeekBack { second: false });
        assert_eq!(rx.try_recv().ok(), Some(ms(2900)), "one still out");
        answer(&mut app, 2920);
        // A seek that lands short of its target (the last instant at or before it): once
        // every seek is answered, the next ← is from where the run is.
        answer(&mut app, 2880);
        app.on_msg(Msg::SeekBack { second: false });
        assert_eq!(rx.try_recv().ok(), Some(ms(2860)));
    }

    #[test]
    fn snapshot_start() {
        let (app, _rx) = app_after(virtual_cfg(50.0, 2), false);
        insta::assert_snapshot!("start_80x24", render(&app, 80, 24));
        insta::assert_snapshot!("start_120x40", render(&app, 120, 40));
    }

    #[test]
    fn snapshot_dropping_obs_at_5_hz() {
        let (app, _rx) = app_after(virtual_cfg(5.0, 0).with_duration_ms(800), false);
        let v = app.view();
        assert!(
            v.topics[0].dropping && v.topics[0].dropped > 0,
            "{:?}",
            v.topics[0]
        );
        let text = render(&app, 80, 24);
        assert!(
            text.contains('⚠') && text.contains('═'),
            "dropping arrow needs a symbol and a style:\n{text}"
        );
        insta::assert_snapshot!("dropping_80x24", text);
        insta::assert_snapshot!("dropping_120x40", render(&app, 120, 40));
    }

    #[test]
    fn snapshot_fall() {
        let (app, _rx) = app_after(virtual_cfg(5.0, 10), true);
        let text = render(&app, 80, 24);
        assert!(text.contains("FELL at t="), "{text}");
        insta::assert_snapshot!("fell_80x24", text);
        insta::assert_snapshot!("fell_120x40", render(&app, 120, 40));
    }

    #[test]
    fn snapshot_help_overlay() {
        let (mut app, _rx) = app_after(virtual_cfg(50.0, 1), false);
        app.on_msg(Msg::ToggleHelp);
        insta::assert_snapshot!("help_80x24", render(&app, 80, 24));
        insta::assert_snapshot!("help_120x40", render(&app, 120, 40));
    }

    #[test]
    fn snapshot_too_small() {
        let (app, _rx) = app_after(virtual_cfg(50.0, 1), false);
        let text = render(&app, 60, 20);
        assert!(text.contains("resize to at least 80×24"));
        insta::assert_snapshot!("too_small_60x20", text);
        // Re-layout after a resize: the same app renders fully at 80×24.
        assert!(render(&app, 80, 24).contains("cartpole"));
    }

    /// `>` at max and `<` at ×0.25 say so (a user pressed them and saw nothing happen), and
    /// send nothing more.
    #[test]
    fn the_speed_keys_say_when_the_ladder_ends() {
        let (mut app, rx) = app_after(virtual_cfg(50.0, 1), false);
        for _ in 0..ratelab::session::SPEEDS.len() {
            app.on_msg(Msg::Faster);
        }
        let sent: Vec<Control> = rx.try_iter().collect();
        assert_eq!(
            sent.last(),
            Some(&Control::SetSpeed(Speed::Max)),
            "{sent:?}"
        );
        let said = app.view().message.unwrap_or_default();
        assert_eq!(said, "already the fastest speed (max): < slows down");
        assert_eq!(
            sent.len(),
            ratelab::session::SPEEDS.len() - 3,
            "×1 to max: {sent:?}"
        );
        for _ in 0..ratelab::session::SPEEDS.len() {
            app.on_msg(Msg::Slower);
        }
        let sent: Vec<Control> = rx.try_iter().collect();
        assert_eq!(sent.last(), Some(&Control::SetSpeed(Speed::Times(0.25))));
        assert_eq!(
            sent.len(),
            ratelab::session::SPEEDS.len() - 1,
            "max to ×0.25: {sent:?}"
        );
        let said = app.view().message.unwrap_or_default();
        assert_eq!(said, "already the slowest speed (×0.25): > speeds up");
    }

    #[test]
    fn keys_become_engine_controls() {
        let (mut app, rx) = app_after(virtual_cfg(50.0, 1), false);
        app.on_msg(Msg::RateDown);
        app.on_msg(Msg::DepthUp);
        app.on_msg(Msg::Break);
        app.on_msg(Msg::TypeRate);
        for c in "12.5".chars() {
            app.on_msg(Msg::Input(c));
        }
        app.on_msg(Msg::Submit);
        app.on_msg(Msg::TypeRate);
        app.on_msg(Msg::Input('0'));
        app.on_msg(Msg::Submit); // 0 Hz: refused, nothing sent
        app.on_msg(Msg::TypeRate);
        for c in "-5".chars() {
            app.on_msg(Msg::Input(c));
        }
        app.on_msg(Msg::Submit); // refused whole, never read as 5 Hz
        assert!(
            (app.view().message.unwrap()).contains("not a rate in (0, 10000] Hz: '-5'"),
            "{:?}",
            app.view().message
        );
        app.on_msg(Msg::SwapBrain); // no --policy file: refused with a message
        app.on_msg(Msg::Faster);
        // `k` on the selected node (the first: the sensor): a stall from the run's next
        // instant, which only the engine knows.
        app.on_msg(Msg::SelectNext);
        app.on_msg(Msg::Stall);
        app.on_msg(Msg::Quit);
        use ratelab::run::Command::*;
        let mut sent: Vec<Control> = rx.try_iter().collect();
        let stall = sent.remove(sent.len() - 2);
        assert_eq!(
            stall,
            Control::Stall {
                node: "sensor".into(),
                duration: ratelab::Nanos(500_000_000)
            }
        );
        assert_eq!(
            sent,
            vec![
                Control::Apply(SetControlHz { hz: 40.0 }),
                Control::Apply(SetQueueDepth { depth: 2 }),
                Control::Apply(SetControlHz { hz: 5.0 }),
                Control::Apply(SetControlHz { hz: 12.5 }),
                Control::SetSpeed(Speed::Times(2.0)),
                Control::Quit,
            ]
        );
        assert!(app.view().message.unwrap().contains("--policy"));
        assert!(app.quit);
    }

    /// The log pane: the newest lines that fit, the selected node's only, PgUp back to older
    /// ones and PgDn forward; `v` again gives the latency panel back.
    #[test]
    fn the_log_pane_shows_the_newest_lines_filters_by_node_and_scrolls() {
        use ratelab::textlog::{Level, LogLine};
        let (mut app, _rx) = app_after(virtual_cfg(50.0, 1), false);
        let (tx, rx) = crossbeam_channel::unbounded();
        app.take_log(rx);
        for i in 0..40u64 {
            tx.send(LogLine {
                t: Some(ratelab::Nanos(i * 20_000_000)),
                node: Some(if i % 2 == 0 { "policy" } else { "sensor" }.into()),
                level: if i == 39 { Level::Warn } else { Level::Info },
                text: format!("line {i}"),
                logged: None,
                traceback: None,
            })
            .unwrap();
        }
        app.drain_log();
        app.on_msg(Msg::ToggleLog);
        let text = render(&app, 80, 24);
        assert!(
            text.contains("log: all nodes (40 lines) · v hides"),
            "{text}"
        );
        assert!(text.contains("t=0.78  sensor    line 39"), "{text}");
        assert!(
            text.contains("line 37") && !text.contains("line 36 "),
            "{text}"
        );
        app.on_msg(Msg::LogOlder);
        let text = render(&app, 80, 24);
        assert!(text.contains("40 lines, 3 back) · PgDn newer"), "{text}");
        assert!(
            text.contains("line 36") && !text.contains("line 39"),
            "{text}"
        );
        app.on_msg(Msg::LogNewer);
        assert!(render(&app, 80, 24).contains("line 39"));
        // Tab selects the first node: its lines only.
        app.on_msg(Msg::SelectNext);
        let text = render(&app, 120, 40);
        assert!(text.contains("log: sensor (20 lines)"), "{text}");
        assert!(!text.contains("policy    line"), "{text}");
        app.on_msg(Msg::ToggleLog);
        assert!(
            render(&app, 80, 24).contains("latency"),
            "the latency panel is back"
        );
    }

    /// `g`: with `--ros2`, the graph panel shows the graph as ROS 2 sees it (node names,
    /// each topic's ROS 2 type, endpoint counts and QoS, `/clock`), at 80x24; `g` again gives
    /// the node graph back. Without `--ros2` the key says why it shows nothing.
    #[test]
    fn g_shows_the_graph_as_ros_2_sees_it_with_ros2_only() {
        let (mut app, _rx) = app_after(virtual_cfg(50.0, 1), false);
        app.on_msg(Msg::ToggleRos2);
        let text = render(&app, 80, 24);
        assert!(
            text.contains("not offered to ROS 2: start the lab with --ros2"),
            "{text}"
        );
        assert!(!text.contains("as ROS 2 sees it"), "{text}");
        app.set_ros2_domain(7);
        app.on_msg(Msg::ToggleRos2);
        let text = render(&app, 80, 24);
        for row in [
            "as ROS 2 sees it · domain 7 · g: back",
            "nodes  /sensor  /policy  /actuator  /ratelab",
            "/obs     sensor_msgs/msg/JointState  1 pub 1 sub  BEST_EFFORT · KEEP_LAST (1)",
            "/action  std_msgs/msg/Float64        1 pub 1 sub  BEST_EFFORT · KEEP_LAST (1)",
            "/clock   rosgraph_msgs/msg/Clock     1 pub 0 sub  BEST_EFFORT · KEEP_LAST (1)",
        ] {
            assert!(text.contains(row), "{row:?} in\n{text}");
        }
        app.on_msg(Msg::ToggleRos2);
        let text = render(&app, 80, 24);
        assert!(
            !text.contains("as ROS 2 sees it") && text.contains("policy"),
            "{text}"
        );
    }

    #[test]
    fn frozen_after_a_fall_and_node_failures_are_named() {
        let (mut app, _rx) = app_after(virtual_cfg(5.0, 10), true);
        assert!(matches!(app.view().verdict, super::view::Verdict::Fell(_)));
        let metrics = run(&virtual_cfg(50.0, 1), Box::new(Scripted), RunOptions::new())
            .unwrap()
            .metrics;
        app.on_telemetry(Telemetry::Ended {
            metrics: Box::new(metrics),
            reason: EndReason::NodeFailed {
                node: "policy".into(),
                message: "boom".into(),
            },
        });
        let text = render(&app, 80, 24);
        assert!(text.contains("NODE FAILED"), "{text}");
        assert!(text.contains("node 'policy' failed: boom"), "{text}");
        // Quitting now exits 2 with this line (run_lab); a fall alone would not.
        assert_eq!(app.failed_node(), Some("policy: boom"));
        let (fell, _rx) = app_after(virtual_cfg(5.0, 10), true);
        assert_eq!(fell.failed_node(), None);
    }

    /// A run that could not start (a node's script fails to load) reads NOT STARTED, not the
    /// BALANCED of a run that never stepped nor the verdict of the run before, its reason in
    /// the footer at both sizes; the run a save starts is balanced again.
    #[test]
    fn a_run_that_could_not_start_is_not_called_balanced() {
        let (tx, _rx) = crossbeam_channel::unbounded();
        let mut app = App::new(tx, "scripted".into(), None, Speed::Times(1.0));
        let why =
            "policy: nodes/scripted_balancer.py:1: ModuleNotFoundError: No module named 'nump'";
        app.on_telemetry(Telemetry::NotStarted(why.into()));
        for (w, h) in [(80, 24), (120, 40)] {
            let text = render(&app, w, h);
            assert!(
                text.contains("NOT STARTED") && !text.contains("BALANCED"),
                "{text}"
            );
            assert!(text.contains("nodes/scripted_balancer.py:1"), "{text}");
        }
        let (mut fell, _rx) = app_after(virtual_cfg(5.0, 10), true);
        fell.on_telemetry(Telemetry::NotStarted(why.into()));
        assert_eq!(fell.view().verdict, super::view::Verdict::NotStarted);
        app.on_telemetry(Telemetry::Started {
            cfg: virtual_cfg(50.0, 10),
            policy: "scripted".into(),
            recording: None,
        });
        let text = render(&app, 120, 40);
        assert!(
            text.contains("BALANCED") && !text.contains("NOT STARTED"),
            "{text}"
        );
    }

    /// A live rate change's notice, as the engine says it, in the footer's two rows when it
    /// does not fit one: where the policy's ticks now fall against the sensor's stays beside
    /// the fresh run's verdict at both sizes (#25; at 80 columns one row dropped it, #72),
    /// whole at 120; the latency panel gives the row.
    #[test]
    fn a_rate_changes_notice_keeps_the_phase_against_the_sensor_where_it_fits() {
        let notice = "control rate → 7 Hz · 142.857 ms off a fresh run's phase · ticks 2.857 ms after the sensor's (r realigns) · a fresh run falls at 4.06 s: judge no sooner";
        for (w, h) in [(80, 24), (120, 40)] {
            let (mut app, _rx) = app_after(virtual_cfg(50.0, 1), false);
            app.on_telemetry(Telemetry::Applied(notice.into()));
            let text = render(&app, w, h);
            let lines: Vec<&str> = text.lines().collect();
            let footer = lines[lines.len() - 2..].join("\n");
            for part in [
                "● control rate → 7 Hz",
                "ticks 2.857 ms after the sensor's (r realigns)",
                "a fresh run falls at 4.06 s: judge no sooner",
            ] {
                assert!(footer.contains(part), "{w}x{h}: {part}:\n{footer}");
            }
            assert_eq!(
                footer.contains("142.857 ms off a fresh run's phase"),
                w >= 120,
                "{footer}"
            );
            // Above it, the latency panel's foot (a row shorter while the notice leads).
            assert!(lines[lines.len() - 3].contains("└ last"), "{text}");
        }
        // A notice that fits keeps the footer at one row.
        let (mut app, _rx) = app_after(virtual_cfg(50.0, 1), false);
        app.on_telemetry(Telemetry::Applied("control rate → 7 Hz".into()));
        let text = render(&app, 80, 24);
        let lines: Vec<&str> = text.lines().collect();
        assert!(lines[23].contains("● control rate → 7 Hz"), "{text}");
        assert!(lines[22].contains("└ last"), "{text}");
    }

    /// At 80×24 the force band has three rows of plot, labelled 10, 0 and -10 N (its two
    /// rows told only the force's sign, ≥0 and <0: #72), and the angle chart keeps its three
    /// (-0.3, 0, 0.3 rad), the band's top border serving as the chart's bottom one.
    #[test]
    fn at_80x24_the_force_band_reads_in_newtons() {
        let (app, _rx) = app_after(virtual_cfg(50.0, 1), false);
        let text = render(&app, 80, 24);
        assert!(
            text.contains("├ force (N): published · applied — the hold"),
            "{text}"
        );
        for label in ["│10 │", "│0  │", "│-10│", "│0.3 │", "│0   │", "│-0.3│"]
        {
            assert_eq!(text.matches(label).count(), 1, "{label}:\n{text}");
        }
        assert!(!text.contains("│≥0│") && !text.contains("│<0│"), "{text}");
        cart_sits_on_the_rail(&text, 80, 24);
    }

    /// `P` steps the selected node's phase offset (else the policy's) through 0, 5, 10 and
    /// 15 ms from the run's `--phase-offset-ms`, as logged `set_phase` commands (exercise
    /// ex3's offsets: sensor 0, policy 5, actuator 10); the engine's word for a change (what
    /// a seek back folds again) sets the lab's figure; the node's title says it at 120
    /// columns. Under the real clock, which keeps its grid, the lab does not step its figure
    /// (the engine refuses, saying why).
    #[test]
    fn shift_p_steps_a_node_s_phase_offset_as_logged_commands() {
        use ratelab::run::Command::SetPhase;
        let phase = |node: &str, phase_ms: f64| {
            Control::Apply(SetPhase {
                node: node.into(),
                phase_ms,
            })
        };
        let mut cfg = virtual_cfg(50.0, 1);
        cfg.phase_offsets = vec![
            ratelab::Nanos::ZERO,
            ratelab::Nanos(5_000_000),
            ratelab::Nanos::ZERO,
        ];
        let (mut app, rx) = app_after(cfg.clone(), false);
        // Nothing selected: the policy's, from its 5 ms.
        app.on_msg(Msg::CyclePhase);
        // The actuator: twice.
        while app
            .view()
            .nodes
            .iter()
            .all(|n| !(n.selected && n.name == "actuator"))
        {
            app.on_msg(Msg::SelectNext);
        }
        app.on_msg(Msg::CyclePhase);
        app.on_msg(Msg::CyclePhase);
        let text = render(&app, 120, 40);
        assert!(
            text.contains("actuator selected: -/+ its rate · P its phase (10 ms)"),
            "{text}"
        );
        // The engine's word: the policy at 15 ms; Esc, then `P` wraps it to 0.
        app.on_telemetry(Telemetry::Changed {
            at: ratelab::Nanos::SECOND,
            text: ratelab::session::describe(&SetPhase {
                node: "policy".into(),
                phase_ms: 15.0,
            }),
        });
        app.on_msg(Msg::Back);
        app.on_msg(Msg::CyclePhase);
        let sent: Vec<Control> = rx.try_iter().collect();
        assert_eq!(
            sent,
            vec![
                phase("policy", 10.0),
                phase("actuator", 5.0),
                phase("actuator", 10.0),
                phase("policy", 0.0),
            ]
        );
        // Real clock: the same command each time (refused by the engine), the figure kept.
        cfg.clock = ClockKind::Real;
        let (mut real, rx) = told(&cfg, &[], ratelab::Nanos::ZERO);
        real.on_msg(Msg::CyclePhase);
        real.on_msg(Msg::CyclePhase);
        let sent: Vec<Control> = rx.try_iter().collect();
        assert_eq!(sent, vec![phase("policy", 10.0), phase("policy", 10.0)]);
    }

    /// The footer offers a pause under the virtual clock only: real time does not stop
    /// (space there reviews a run that ended, as the help says).
    #[test]
    fn the_footer_offers_a_pause_only_under_the_virtual_clock() {
        let footer = |app: &App| {
            render(app, 120, 40)
                .lines()
                .last()
                .unwrap_or("")
                .to_string()
        };
        let (mut app, _rx) = app_after(virtual_cfg(50.0, 1), false);
        assert!(footer(&app).contains("␣ pause"), "{}", footer(&app));
        // Paused, space resumes.
        let mut paused = chapter_status(Vec::new(), Vec::new());
        if let Telemetry::Status { paused: p, .. } = &mut paused {
            *p = true;
        }
        app.on_telemetry(paused);
        assert!(footer(&app).contains("␣ resume"), "{}", footer(&app));
        let mut cfg = virtual_cfg(50.0, 1);
        cfg.clock = ClockKind::Real;
        let (app, _rx) = app_after(cfg, false);
        let real = footer(&app);
        assert!(
            !real.contains("pause") && real.contains("c clock"),
            "{real}"
        );
    }

    /// `d` on the selected topic (/action, the actuator's input, as in exercise ex5) steps
    /// its deadline through none, 25, 30 (ex5's), 50, 100 and 200 ms, then off again.
    #[test]
    fn the_deadline_key_has_ex5_s_30_ms() {
        let (mut app, rx) = app_after(virtual_cfg(50.0, 1), false);
        while !app.view().topics.last().unwrap().selected {
            app.on_msg(Msg::SelectNext);
        }
        let mut graph = ratelab::graph::GraphSpec::chapter();
        let mut sent = Vec::new();
        for _ in 0..6 {
            app.on_msg(Msg::CycleDeadline);
            for c in rx.try_iter() {
                if let Control::Apply(ratelab::run::Command::SetTopicQos { topic, pairs }) = c {
                    graph.set_qos(&topic, &pairs).unwrap();
                    sent.push(pairs);
                }
            }
            let qos = graph.topics.iter().map(|t| t.qos).collect();
            app.on_telemetry(chapter_status(qos, vec![None; 3]));
        }
        assert_eq!(
            sent,
            [
                "deadline_ms=25",
                "deadline_ms=30",
                "deadline_ms=50",
                "deadline_ms=100",
                "deadline_ms=200",
                "deadline_ms=none,on_deadline_missed=hold",
            ]
        );
    }

    /// The totals line under the graph counts lifespan's `expired` beside drops, stale reads
    /// and losses (#72: it left them out), at both sizes.
    #[test]
    fn the_totals_line_counts_expired_messages() {
        let mut cfg = virtual_cfg(10.0, 2);
        cfg.graph
            .set_qos(
                "/obs",
                "history=keep_last,depth=100,delivery=fifo,lifespan_ms=20",
            )
            .unwrap();
        let (app, _rx) = app_after(cfg, false);
        let expired = app.view().topics[0].segment_expired;
        assert!(expired > 10, "{expired}");
        for (w, h) in [(80, 24), (120, 40)] {
            let text = render(&app, w, h);
            let totals = text
                .lines()
                .find(|l| l.contains("since the start:") || l.contains(" totals: "))
                .unwrap_or_else(|| panic!("no totals line:\n{text}"));
            assert!(
                totals.contains("/obs 0 drop") && totals.contains(&format!("{expired} expired")),
                "{w}x{h}: {totals}"
            );
        }
    }

    /// A reliable topic that still counts lost messages has it explained once, in the
    /// footer, the first time it counts one (#72: "6 lost" under reliable delivery was not
    /// explained); a best-effort link's losses need no word.
    #[test]
    fn a_reliable_topic_s_first_loss_is_explained() {
        let mut cfg = virtual_cfg(50.0, 2);
        cfg.graph
            .set_qos("/action", "reliability=reliable,loss=0.9")
            .unwrap();
        let (app, _rx) = app_after(cfg, false);
        assert!(app.view().topics[1].segment_lost > 0);
        let said = app.view().message.unwrap_or_default();
        assert_eq!(
            said,
            "/action: lost though reliable · a message counts lost once all 16 of its sends are lost (retx: the resends)"
        );
        // At 80×24 it leads the footer whole, in two rows.
        let text = render(&app, 80, 24);
        let lines: Vec<&str> = text.lines().collect();
        assert!(
            lines[22].contains("● /action: lost though reliable ·"),
            "{text}"
        );
        assert!(
            lines[23].contains(
                "a message counts lost once all 16 of its sends are lost (retx: the resends)"
            ),
            "{text}"
        );
        let mut cfg = virtual_cfg(50.0, 2);
        cfg.graph.set_qos("/action", "loss=0.9").unwrap();
        let (app, _rx) = app_after(cfg, false);
        assert!(app.view().topics[1].segment_lost > 0);
        assert_eq!(app.view().message, None);
    }

    /// Losses counted while a topic was best effort are not explained as reliable
    /// delivery's once `R` makes it reliable: only a loss counted after the switch is.
    #[test]
    fn losses_from_before_a_topic_was_made_reliable_are_not_explained() {
        ratelab::init();
        let mut cfg = virtual_cfg(50.0, 2);
        cfg.graph.set_qos("/action", "loss=0.9").unwrap();
        let report = run(&cfg, Box::new(Scripted), RunOptions::new()).unwrap();
        // Switched at 0.3 s (at 90% loss the pole falls within the second).
        let second = ratelab::Nanos(300 * ratelab::Nanos::MILLISECOND.0);
        let (mut app, _rx) = told(&cfg, &report.trace, second);
        let lost_at =
            |s: &ratelab::runlog::StepRecord| s.topics.get(ratelab::graph::TopicId(1)).lost;
        let last = report.trace.iter().rfind(|s| s.t <= second).unwrap();
        assert!(lost_at(last) > 0, "best effort lost some");
        assert_eq!(app.view().message, None);
        // `R`: /action made reliable (the engine's status says so).
        let mut qos: Vec<_> = cfg.graph.topics.iter().map(|t| t.qos).collect();
        qos[1].reliability = ratelab::qos::Reliability::Reliable;
        app.on_telemetry(chapter_status(qos, vec![None; 3]));
        // A step with no loss since: nothing to explain.
        app.on_telemetry(Telemetry::Step(Box::new(last.clone())));
        assert_eq!(app.view().message, None);
        // The next loss is reliable delivery's.
        let next = report
            .trace
            .iter()
            .find(|s| s.t > second && lost_at(s) > lost_at(last))
            .unwrap_or_else(|| {
                let lost: Vec<_> = report.trace.iter().map(|s| (s.t.0, lost_at(s))).collect();
                panic!("no loss after 0.3 s: {lost:?}")
            });
        app.on_telemetry(Telemetry::Step(Box::new(next.clone())));
        assert!(
            app.view()
                .message
                .unwrap_or_default()
                .starts_with("/action: lost though reliable"),
            "{:?}",
            app.view().message
        );
    }

    /// A refused rate reads whole enough to act on at both sizes: the value tried and the
    /// rule (#25: at 80×24 "must be 50 Hz, got 4" when 40 was tried).
    #[test]
    fn a_refused_actuator_rate_names_the_rate_tried_at_both_sizes() {
        // The engine's words: its command goes through the graph's own check.
        let refused = ratelab::graph::GraphSpec::chapter()
            .set_rate("actuator", 40.0)
            .unwrap_err()
            .to_string();
        for (w, h) in [(80, 24), (120, 40)] {
            let (mut app, _rx) = app_after(virtual_cfg(50.0, 1), false);
            app.on_telemetry(Telemetry::Error(refused.clone()));
            let text = render(&app, w, h);
            assert!(
                text.contains("actuator rate 40 Hz refused"),
                "{w}x{h}: {text}"
            );
            if w >= 120 {
                assert!(text.contains("it must be 50 Hz"), "{w}x{h}: {text}");
            }
        }
    }

    /// After a fall `=` still shows what it takes (#25: it took input with no prompt), and
    /// what was said of the next run goes when that run starts (#25: "… (from the next
    /// run)" stayed on it). At both sizes.
    #[test]
    fn after_a_fall_typing_a_rate_has_its_prompt_and_a_new_run_clears_the_last_word() {
        for (w, h) in [(80, 24), (120, 40)] {
            let (mut app, _rx) = app_after(virtual_cfg(5.0, 10), true);
            assert!(matches!(app.view().verdict, super::view::Verdict::Fell(_)));
            app.on_msg(Msg::TypeRate);
            app.on_msg(Msg::Input('8'));
            let typing = render(&app, w, h);
            // The footer: the screen's last line.
            let footer = typing.lines().last().unwrap_or_default();
            assert!(footer.contains("rate (Hz): 8"), "{w}x{h}: {typing}");
            assert!(footer.contains("Enter apply"), "{w}x{h}: {typing}");
            app.on_msg(Msg::Submit);
            let said = app.view().message.expect("the change is said");
            assert!(said.contains("next run"), "{said}");
            assert!(render(&app, w, h).contains("next run"), "{w}x{h}");
            // The next run starts: what was said of it belongs to the run before.
            app.on_telemetry(Telemetry::Started {
                cfg: virtual_cfg(8.0, 10),
                policy: "scripted balancer".into(),
                recording: None,
            });
            let fresh = render(&app, w, h);
            assert!(app.view().message.is_none(), "{w}x{h}: {fresh}");
            assert!(!fresh.contains("next run"), "{w}x{h}: {fresh}");
        }
    }

    /// After a fall the keys set the next run: the frozen figures stay beside the rate and
    /// depth they were measured under, and the next run's show as next.
    #[test]
    fn after_a_fall_the_next_runs_settings_show_as_next() {
        let (mut app, _rx) = app_after(virtual_cfg(5.0, 10), true);
        assert!(matches!(app.view().verdict, super::view::Verdict::Fell(_)));
        // The engine's status after `+` on the policy and `]`: the next run's settings.
        app.on_telemetry(Telemetry::Status {
            now: ratelab::Nanos(840_000_000),
            paused: false,
            speed: Speed::Times(1.0),
            rates: vec![50.0, 6.0, 50.0],
            depths: vec![2, 2],
            qos: vec![ratelab::qos::TopicQos::default(); 2],
            alive: vec![None; 3],
            policy: "scripted balancer".into(),
            exec: None,
            topics: None,
        });
        let v = app.view();
        let policy = v.nodes.iter().find(|n| n.name == "policy").unwrap();
        assert_eq!((policy.set_hz, policy.next_hz), (5.0, Some(6.0)));
        assert!(v
            .topics
            .iter()
            .all(|t| t.depth == 1 && t.next_depth == Some(2)));
        let wide = render(&app, 120, 40);
        assert!(wide.contains("5→6 Hz next"), "{wide}");
        assert!(wide.contains("depth 1→2 next"), "{wide}");
        let small = render(&app, 80, 24);
        assert!(small.contains("5→6 Hz"), "{small}");
        // The header keeps the brain's label whole, cut at a word's end or left out.
        let header = small.lines().next().unwrap();
        assert!(header.contains("depth 1→2 next"), "{header}");
        assert!(
            !header.contains("balanc") || header.contains("balancer"),
            "{header}"
        );
    }

    /// The cartpole panel of a rendered screen: the rail is its lowest drawing (the cart
    /// on it, never under it: #25 saw an attached lab's cart hang under the rail), the
    /// cart and pole above or on the rail's row.
    fn cart_sits_on_the_rail(text: &str, w: u16, h: u16) {
        let braille = |c: char| ('\u{2801}'..='\u{28ff}').contains(&c);
        // (The test backend quotes each line.)
        let lines: Vec<&str> = text.lines().map(|l| l.trim_matches('"')).collect();
        let top = lines
            .iter()
            .position(|l| l.contains("┌ cartpole"))
            .unwrap_or_else(|| panic!("{w}x{h}: no cartpole panel:\n{text}"));
        // The panel's inside: from its title to its bottom border, up to its right border.
        let inside: Vec<String> = lines[top + 1..]
            .iter()
            .take_while(|l| !l.starts_with('└'))
            .map(|l| l.chars().skip(1).take_while(|c| *c != '│').collect())
            .collect();
        let rail = inside
            .iter()
            .rposition(|l| l.chars().filter(|c| braille(*c)).count() >= l.chars().count() / 2)
            .unwrap_or_else(|| panic!("{w}x{h}: no rail in\n{}", inside.join("\n")));
        assert!(
            inside[rail + 1..].iter().all(|l| !l.chars().any(braille)),
            "{w}x{h}: something drawn under the rail:\n{}",
            inside.join("\n")
        );
        assert!(
            inside[..rail].iter().any(|l| l.chars().any(braille)),
            "{w}x{h}: the cart and pole are above the rail:\n{}",
            inside.join("\n")
        );
    }

    #[test]
    fn an_attached_lab_names_each_nodes_process_and_draws_a_gone_one() {
        let (mut app, rx) = app_after(virtual_cfg(50.0, 2), false);
        let spec = ratelab::graph::GraphSpec::chapter();
        app.set_attached(super::attached_label(&spec));
        app.on_telemetry(chapter_status(
            vec![ratelab::qos::TopicQos::default(); 2],
            vec![Some(true), Some(false), Some(true)],
        ));
        app.on_telemetry(Telemetry::Wire(vec![(0, 214.4, 402.7)]));
        app.set_endpoint(Some("tls/127.0.0.1:7451".into()));
        for (w, h) in [(80, 24), (120, 40)] {
            let text = render(&app, w, h);
            // Where the launch listens shows at once (it may not be 7449): in the header
            // where it fits, and in the footer.
            let header = text.lines().next().unwrap_or_default();
            let at = if w >= 120 {
                "2 processes at tls/127.0.0.1:7451"
            } else {
                "2 processes at :7451"
            };
            assert!(header.contains(at), "{w}x{h}: {header}");
            assert!(header.contains("t 2.00 s"), "{w}x{h}: {header}");
            let footer = text.lines().last().unwrap_or_default();
            assert!(footer.contains("tls/127.0.0.1:7451"), "{w}x{h}: {footer}");
            for needle in [
                "2 processes",
                "sensor@robot",
                "policy@policy",
                "actuator@robot",
                "NOT ALIVE",
            ] {
                assert!(text.contains(needle), "{needle} at {w}x{h}:\n{text}");
            }
            assert_eq!(text.matches("NOT ALIVE").count(), 1, "{text}");
            // /obs is counted by the policy's process, gone: its rate is not known (not a
            // 0.0 that says nothing was published), and no arrow has a green tick.
            assert_eq!(text.matches("? msg/s").count(), 1, "{text}");
            assert!(
                !text.contains("dropped ✓") && !text.contains("drop ✓"),
                "{text}"
            );
            // At 80 columns an arrow is 14 wide: p50 only.
            let wire = if w == 80 {
                "wire 214 µs"
            } else {
                "wire 214/403 µs"
            };
            assert_eq!(text.matches(wire).count(), 1, "{text}");
            // The footer offers only the keys that act: no rate or depth keys.
            let footer = text.lines().last().unwrap_or_default();
            assert!(footer.contains("read-only"), "{footer}");
            assert!(
                !footer.contains("rate") && !footer.contains("depth"),
                "{footer}"
            );
            cart_sits_on_the_rail(&text, w, h);
        }
        // Tab selects to look, and says the keys do nothing to it; the help lists only the
        // keys that act here.
        app.on_msg(Msg::SelectNext);
        let text = render(&app, 120, 40);
        assert!(text.contains("sensor selected (read-only)"), "{text}");
        assert!(!text.contains("its rate"), "{text}");
        app.on_msg(Msg::Back);
        app.on_msg(Msg::ToggleHelp);
        let text = render(&app, 120, 40);
        assert!(text.contains("this lab only watches"), "{text}");
        assert!(
            text.contains("quit") && text.contains("wire p50/p99"),
            "{text}"
        );
        for refused in ["pause", "rate ladder", "reset"] {
            assert!(!text.contains(refused), "{refused} in:\n{text}");
        }
        app.on_msg(Msg::ToggleHelp);
        // A key that would change the graph is refused in words, and sends nothing.
        app.on_msg(Msg::RateUp);
        let msg = app.view().message.unwrap_or_default();
        assert!(msg.contains("read-only"), "{msg}");
        assert!(rx.try_recv().is_err(), "an attached lab sent a control");
        // The run's end in an attached lab offers no next run.
        let mut report = run(&virtual_cfg(50.0, 1), Box::new(Scripted), RunOptions::new()).unwrap();
        // Its totals are the summary's, where the launcher counted what the gone policy's
        // copy of /obs no longer could.
        if let Some(obs) = report.metrics.topics.get_mut("/obs") {
            (obs.dropped, obs.stale_reads) = (93, 4);
            obs.qos_counters.insert("lost".into(), 7);
        }
        app.on_telemetry(Telemetry::Ended {
            metrics: Box::new(report.metrics),
            reason: EndReason::Duration,
        });
        let msg = app.view().message.unwrap_or_default();
        assert!(msg.contains("the launch is over"), "{msg}");
        assert!(!msg.contains("r/R reset"), "{msg}");
        let obs = &app.view().topics[0];
        assert_eq!(
            (
                obs.segment_dropped,
                obs.segment_stale_reads,
                obs.segment_lost
            ),
            (93, 4, 7)
        );
        let text = render(&app, 120, 40);
        assert!(text.contains("/obs 93 dropped, 4 stale, 7 lost"), "{text}");
        // At 80 columns the totals shorten, and still say the loss.
        let text = render(&app, 80, 24);
        assert!(text.contains("/obs 93 drop, 4 stale, 7 lost"), "{text}");
    }
    /// A run of code just saved that falls keeps its reload line in the footer (two rows at
    /// 80×24, where it is said last how the trial stalled) and says the fall in the status
    /// bar: both read, neither replaces the other. A run not reloaded says its fall in the
    /// footer, as before.
    #[test]
    fn a_reload_line_and_the_fall_after_it_both_read_at_80x24() {
        let (mut app, _rx) = app_after(virtual_cfg(50.0, 1), true);
        let line = "reloaded nodes/policy.py: balanced (5.5 s) → fell at 0.84 s · over the first 0.84 s of each: latency p50 40 → 80 ms, /obs dropped 0 → 37 · the trial's callback stalled 5.0 s at t=0.50 s";
        app.on_telemetry(Telemetry::Reloaded { line: line.into() });
        app.on_telemetry(Telemetry::Started {
            cfg: virtual_cfg(5.0, 10),
            policy: "scripted".into(),
            recording: None,
        });
        let fell = run(&virtual_cfg(5.0, 10), Box::new(Scripted), RunOptions::new()).unwrap();
        assert!(fell.metrics.fell_at_s.is_some());
        let ended = Telemetry::Ended {
            metrics: Box::new(fell.metrics.clone()),
            reason: EndReason::NodeStopped,
        };
        app.on_telemetry(ended.clone());
        let text = render(&app, 80, 24);
        let rows: Vec<&str> = text.lines().collect();
        assert!(rows[0].contains("the pole fell"), "{text}");
        let footer = rows[rows.len() - 2..].join("\n");
        assert!(
            footer.contains("reloaded nodes/policy.py: balanced (5.5 s) → fell at 0.84 s"),
            "{text}"
        );
        assert!(
            footer.contains("the trial's callback stalled 5.0 s at t=0.50 s"),
            "{text}"
        );
        // The next run, not a reload's, says its fall in the footer again.
        app.on_telemetry(Telemetry::Started {
            cfg: virtual_cfg(5.0, 10),
            policy: "scripted".into(),
            recording: None,
        });
        app.on_telemetry(ended);
        let text = render(&app, 80, 24);
        let last = text.lines().last().unwrap_or_default();
        assert!(last.contains("the pole fell — keys set"), "{text}");
        assert!(
            !text.lines().next().unwrap_or_default().contains("fell"),
            "{text}"
        );
    }

    /// A callback's exception is one entry of the log pane: its message whole, wrapped, its
    /// paths relative to the graph file's folder, the learner's frames under it; Enter shows
    /// it whole over the lab with its traceback, and Esc closes it.
    #[test]
    fn a_callback_s_failure_reads_whole_in_the_log_pane_and_enter_shows_its_traceback() {
        use ratelab::textlog::{Frame, Level, LogLine, Traceback};
        let (mut app, _rx) = app_after(virtual_cfg(50.0, 1), false);
        app.set_code_folder(std::path::Path::new("/home/me/lab"));
        let (tx, rx) = crossbeam_channel::unbounded();
        app.take_log(rx);
        let frame = |line: u32, function: &str, code: &str| Frame {
            file: "/home/me/lab/nodes/policy.py".into(),
            line,
            function: function.into(),
            code: code.into(),
        };
        tx.send(LogLine {
            t: Some(ratelab::Nanos(1_200_000_000)),
            node: Some("policy".into()),
            level: Level::Error,
            text: "/home/me/lab/nodes/policy.py:12: ValueError: the gain schedule has no entry for a pole angle of 0.2137 rad (the table ends at 0.2)".into(),
            logged: None,
            traceback: Some(Box::new(Traceback {
                frames: vec![
                    frame(9, "on_timer", "u = self.gain(theta) * theta"),
                    frame(12, "gain", "raise ValueError(...)"),
                ],
                lines: vec![
                    "Traceback (most recent call last):".into(),
                    "  File \"/home/me/lab/nodes/policy.py\", line 9, in on_timer".into(),
                    "  File \"/home/me/lab/nodes/policy.py\", line 12, in gain".into(),
                    "ValueError: the gain schedule has no entry".into(),
                ],
            })),
        })
        .unwrap();
        app.drain_log();
        app.on_msg(Msg::ToggleLog);
        let text = render(&app, 120, 40);
        assert!(!text.contains("/home/me/lab"), "{text}");
        assert!(
            text.contains("t=1.20  policy    nodes/policy.py:12: ValueError: the gain schedule"),
            "{text}"
        );
        // Wrapped, never cut: the message's end is on the next row.
        assert!(
            text.contains("│                  table ends at 0.2)"),
            "{text}"
        );
        assert!(
            text.contains("↳ nodes/policy.py:9 in on_timer: u = self.gain(theta) * theta"),
            "{text}"
        );
        assert!(text.contains("↵ traceback"), "{text}");
        app.on_msg(Msg::LogEntry);
        for (w, h) in [(80, 24), (120, 40)] {
            let text = render(&app, w, h);
            assert!(
                text.contains("log entry · ↵ or Esc closes"),
                "{w}x{h}:\n{text}"
            );
            assert!(
                text.contains("Traceback (most recent call last):"),
                "{text}"
            );
            assert!(
                text.contains("File \"nodes/policy.py\", line 12, in gain"),
                "{text}"
            );
        }
        app.on_msg(Msg::Back);
        assert!(!render(&app, 80, 24).contains("Traceback (most recent"));
        // Enter with the pane closed says how to open it.
        app.on_msg(Msg::ToggleLog);
        app.on_msg(Msg::LogEntry);
        assert!(app
            .view()
            .message
            .unwrap_or_default()
            .contains("v opens the pane"));
    }

    /// Ctrl-C with no callback hung quits the lab, as `q` does.
    #[test]
    fn ctrl_c_with_nothing_hung_quits() {
        let (mut app, rx) = app_after(virtual_cfg(50.0, 1), true);
        app.on_msg(Msg::Interrupt);
        assert!(app.quit);
        assert!(rx.try_iter().any(|c| matches!(c, Control::Quit)));
    }
}
