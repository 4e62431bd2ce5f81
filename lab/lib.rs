//! The ratelab command line — the terminal lab, the headless run, and the tools around them
//! (`run`, `lab`, `launch`, `node`, `sweep`, `cliff`, `exercise`, `bench`, `replay`, `top`,
//! `export`, `kinds`, `msgs`) — as a library, so that a program with node kinds and message
//! types of its own gets all of it with them: [`main_with`]. The `ratelab` binary is
//! `main_with(|| {})`.
#![warn(missing_docs)]

mod bench;
mod cli;
mod exercise;
mod headless;
mod launch;
mod rendezvous;
mod ros2;
mod sweep;
mod top;
mod tui;

use clap::error::ErrorKind;
use cli::{Cli, Command};
use ratelab::scheduler::StopFlag;
use ratelab::text::printable;
use std::io::{IsTerminal, Write};
use std::process::ExitCode;

/// Exit code for bad input (as clap uses for usage errors).
const EXIT_USAGE: u8 = 2;
/// Exit code of an exercise that ran but did not pass (a check failed, a prediction missed or
/// could not be read), for scripts: 0 passed, 1 not passed, 2 could not run.
const EXIT_NOT_PASSED: u8 = 1;
/// Exit code of a run stopped by Ctrl-C or SIGTERM (after writing its outputs).
const EXIT_INTERRUPTED: u8 = 130;

/// A headless run; its summary, outputs and recording are complete even when interrupted.
fn headless(args: &cli::RunArgs, stop: StopFlag) -> anyhow::Result<()> {
    if args.session.is_some() {
        // Accepted silently, it wrote nothing: the log is of a lab's keys.
        anyhow::bail!("--session is the lab's log of the keys pressed in it; a headless run takes none (run `ratelab lab --session FILE`, or give the changes at the start)");
    }
    headless::check_trace_every(args)?;
    headless::run_headless(args, stop).map(|_| ())
}

/// Open the terminal lab with the run flags.
fn lab(args: &cli::RunArgs, stop: StopFlag) -> anyhow::Result<()> {
    use ratelab::session::{SessionSettings, Speed, UNBOUNDED};
    // Accepted, they would write nothing: the lab keeps its runs by --record and --session.
    if args.out.is_some() {
        anyhow::bail!("--out writes one headless run's files: the lab keeps its runs with --record and --session (run `ratelab run --out DIR` for metrics.json and trace.csv)");
    }
    if args.trace_every > 1 {
        anyhow::bail!("--trace-every thins trace.csv, which the lab does not write (run `ratelab run --out DIR --trace-every N`)");
    }
    let mut cfg = headless::config_from_args(args)?;
    if args.duration.is_none() && !args.smoke {
        cfg.duration = UNBOUNDED;
    }
    headless::warn_late_faults(&cfg);
    ratelab::checkpoint::load_policy(&args.policy)?; // a bad --policy fails before the screen opens
    let record = match &args.record {
        None if !args.spawn => None,
        Some(Some(p)) => Some(p.clone()),
        _ => Some(ratelab::recording::default_lab_path(
            std::path::Path::new("recordings"),
            &cfg,
        )),
    };
    if let Some(p) = &record {
        // Checked before the screen opens; the session then replaces it only with --force.
        ratelab::recording::check_output_path(p, args.force)?;
    }
    let session_file = args
        .session
        .clone()
        .or_else(|| record.as_ref().map(|p| p.with_extension("session.json")));
    if let Some(p) = &session_file {
        // The session log is saved over and over during the session: an existing file
        // is only replaced with --force (and never through a link or into a non-file).
        ratelab::output::check_writable(p, args.force)
            .map_err(|e| anyhow::anyhow!("--session {e}"))?;
    }
    // Checked and opened before the screen opens: a bad name or setting is one line, exit 2.
    if args.bag.is_some() {
        anyhow::bail!("--bag writes one run's bag: use it with `ratelab run --ros2`, not the lab");
    }
    let ros2 = match ratelab::outputs::ros2_options(
        &ratelab::run_spec::RunSpec::from(args).outputs,
        &cfg.graph,
    )? {
        Some(opts) => Some((ratelab::outputs::open_ros2(&stop)?, opts)),
        None => None,
    };
    let alt_policy = (args.policy != "scripted").then(|| args.policy.clone());
    // Reload on save: the files the run's code comes from, and the graph read again from
    // its file with the command line's overrides.
    let code = tui::watch::CodeSource {
        graph_file: args.graph.graph.clone(),
        policy: args.policy.clone(),
    };
    let graph_source = args.graph.graph.as_ref().map(|_| {
        let flags = args.graph.clone();
        ratelab::session::GraphSource(std::sync::Arc::new(move || {
            headless::graph_from_args(&flags).map_err(|e| format!("{e:#}"))
        }))
    });
    let settings = SessionSettings {
        force: args.force,
        cfg,
        policy: args.policy.clone(),
        alt_policy,
        record,
        spawn: args.spawn,
        record_window: args.record_window,
        session_file,
        start_paused: false,
        speed: Speed::Times(1.0),
        ros2,
        graph_source,
        control: None,
    };
    tui::run_lab(settings, code, stop)
}

/// The first [`REPLAY_SHOWN`] of a logged run's `commands`, a line each (`indent`, then
/// `when`'s words for it, then the command described), and how many more.
fn list_commands(
    commands: &[ratelab::run::TimedCommand],
    indent: &str,
    when: impl Fn(&ratelab::run::TimedCommand) -> String,
) {
    for c in commands.iter().take(REPLAY_SHOWN) {
        // A log is a file from anywhere: its text reaches the terminal escaped.
        let said = ratelab::session::describe(&c.command);
        println!("{indent}{}{}", when(c), printable(&said));
    }
    if commands.len() > REPLAY_SHOWN {
        println!("{indent}… and {} more", commands.len() - REPLAY_SHOWN);
    }
}

/// The most commands `replay` lists per run (a session may hold thousands).
const REPLAY_SHOWN: usize = 20;

/// Re-run a session's virtual runs and compare with what the live runs measured.
fn replay(args: &cli::ReplayArgs) -> anyhow::Result<()> {
    use ratelab::session::{replay_run, SessionLog};
    let log = SessionLog::load(&args.file)?;
    if let Some(dir) = &args.out {
        std::fs::create_dir_all(dir)
            .map_err(|e| anyhow::anyhow!("cannot create --out folder {}: {e}", dir.display()))?;
        for n in 1..=log.runs.len() {
            ratelab::output::check_writable(&dir.join(format!("metrics-{n}.json")), args.force)?;
        }
    }
    if log.runs.is_empty() {
        println!(
            "[ratelab] {}: no runs to replay (the session started none)",
            args.file.display()
        );
    }
    let mut mismatches = 0;
    for (i, run) in log.runs.iter().enumerate() {
        let n = i + 1;
        if run.clock != ratelab::ClockKind::Virtual {
            println!(
                "[ratelab] run {n}: real clock — not replayable exactly (concurrency), skipped"
            );
            continue;
        }
        if let Some(&at) = run.clock_switches_ns.first() {
            println!(
                "[ratelab] run {n}: went under the real clock at t={:.3} s (c) — not replayable exactly, skipped",
                ratelab::Nanos(at).as_secs_f64()
            );
            continue;
        }
        if run.end_ns == 0 {
            println!("[ratelab] run {n}: ended before its first tick, nothing to replay");
            continue;
        }
        let metrics = replay_run(&log, i)?;
        let same = log.matches(i, &metrics);
        let applied = run.applied();
        println!(
            "[ratelab] run {n}: seed {}, {} command(s) replayed",
            metrics.seed,
            applied.len()
        );
        // Each change at its run time (the summary gives only the start and the end: a depth
        // set to 2 and back to 1 reads as 1).
        list_commands(applied, "[ratelab]   ", |c| {
            format!("at {:.2} s: ", ratelab::Nanos(c.at_ns).as_secs_f64())
        });
        // Changes made after its last instant (paused, or with the restart that ended it):
        // they set what it ended with, and ran no tick.
        let after = run.after_end();
        if !after.is_empty() {
            println!(
                "[ratelab]   after its last instant ({:.2} s), applied to the settings it ended with as in the live run:",
                ratelab::Nanos(run.end_ns).as_secs_f64()
            );
            list_commands(after, "[ratelab]     ", |_| String::new());
        }
        for line in metrics.summary_lines(None).iter().skip(1) {
            println!("[ratelab]   {line}");
        }
        let json = serde_json::to_string_pretty(&metrics)? + "\n";
        match same {
            Some(true) => println!("[ratelab]   identical to the live run's metrics ✓"),
            Some(false) => {
                mismatches += 1;
                println!("[ratelab]   DIFFERS from the live run's metrics ✗")
            }
            None => println!("[ratelab]   (the live run recorded no metrics)"),
        }
        if let Some(dir) = &args.out {
            ratelab::output::write_file(
                &dir.join(format!("metrics-{n}.json")),
                args.force,
                json.as_bytes(),
            )?;
        }
    }
    anyhow::ensure!(
        mismatches == 0,
        "{mismatches} replayed run(s) differ from the live session"
    );
    Ok(())
}

/// `ratelab graph`: the generated graph file on stdout. Asked for more processes than its
/// nodes fill (a controller of four nodes each, beside the plant's), it is refused in one
/// line rather than placed in fewer without a word.
fn generate_graph(args: &cli::GenerateArgs) -> anyhow::Result<()> {
    use ratelab::graph::synthetic::{graph_toml_at, nodes_to_fill, processes_filled};
    let (nodes, processes) = (args.nodes as usize, args.processes as usize);
    let filled = processes_filled(nodes, processes);
    anyhow::ensure!(
        filled >= processes,
        "--nodes {nodes} fills at most {filled} processes (the plant's, then a controller of 4 nodes each): --processes {processes} needs --nodes {} or more",
        nodes_to_fill(processes)
    );
    print!("{}", graph_toml_at(nodes, processes, args.controller_hz));
    Ok(())
}

/// `ratelab export`: a checkpoint's tensors as .npz ([`ratelab::checkpoint::export`]).
fn export(args: &cli::ExportArgs) -> anyhow::Result<()> {
    use ratelab::checkpoint::export::{checkpoint_tensors, to_npz};
    anyhow::ensure!(
        args.out.extension().is_some_and(|e| e == "npz"),
        "--out {}: the archive's name must end in .npz (np.load tells the format by it)",
        args.out.display()
    );
    ratelab::output::check_target(&args.out, args.force)?;
    let tensors = checkpoint_tensors(&args.checkpoint)?;
    let bytes = to_npz(&tensors).map_err(|e| anyhow::anyhow!("{}: {e}", args.out.display()))?;
    ratelab::output::write_file(&args.out, args.force, &bytes)?;
    for t in &tensors {
        // A state_dict's keys are the checkpoint's: written out.
        println!("{:<24} {:?}", printable(&t.name), t.shape);
    }
    println!(
        "[ratelab] wrote {} ({} tensors, float32)",
        args.out.display(),
        tensors.len()
    );
    Ok(())
}

/// A clap error as one line that keeps its point: clap's first line names the flag, the
/// value and the rule, except when it ends with a colon and lists its subject on the lines
/// below (missing required arguments), which are then joined onto it; clap's tip of a near
/// name follows in brackets (`error: unexpected argument '--contol-hz' found (a similar
/// argument exists: '--control-hz')`).
fn one_line(text: &str) -> String {
    let lines: Vec<&str> = (text.lines().map(str::trim))
        .filter(|l| !l.is_empty())
        .collect();
    let first = lines.first().copied().unwrap_or("error: invalid arguments");
    if !first.ends_with(':') {
        // Clap's suggestion of a near name ("tip: a similar argument exists: '--control-hz'").
        let tip = (lines.iter())
            .find_map(|l| l.strip_prefix("tip: "))
            .filter(|t| t.contains("similar"));
        return match tip {
            Some(t) => format!("{first} ({t})"),
            None => first.to_string(),
        };
    }
    let listed: Vec<&str> = (lines.iter().skip(1).copied())
        .take_while(|l| {
            !l.starts_with("Usage:") && !l.starts_with("For more") && !l.starts_with("tip:")
        })
        .collect();
    format!("{first} {}", listed.join(", "))
}

/// Exit code when the reader of stdout went away (`ratelab cliff | head -1`): 128 + SIGPIPE,
/// what a shell reports for a program the closed pipe ended.
const EXIT_CLOSED_PIPE: i32 = 141;

/// A closed stdout (or stderr) ends the process quietly, whatever subcommand was printing:
/// Rust ignores SIGPIPE (sockets and child pipes must not kill a launcher), so `println!` to
/// a pipe whose reader has gone panics; this hook turns exactly that panic into a silent
/// exit 141, as a shell tool killed by SIGPIPE ends (never 0: what was to be said was not).
/// Any other panic goes on to the hook before it.
fn quiet_on_a_closed_stdout() {
    static INSTALLED: std::sync::Once = std::sync::Once::new();
    INSTALLED.call_once(quiet_hook);
}

/// The hook [`quiet_on_a_closed_stdout`] installs.
fn quiet_hook() {
    let before = std::panic::take_hook();
    std::panic::set_hook(Box::new(move |info| {
        let message = ratelab::scheduler::panic_message(info.payload());
        let printing = message.starts_with("failed printing to stdout")
            || message.starts_with("failed printing to stderr");
        if printing && message.contains("Broken pipe") {
            std::process::exit(EXIT_CLOSED_PIPE);
        }
        before(info)
    }));
}

/// How long a Python callback may still run after Ctrl-C (or `q` in the lab) before it is
/// interrupted: the Python layer's, for every front end.
pub use ratelab::python::PYTHON_GRACE;

/// Run ratelab's whole command line (the process's arguments) in a program that first
/// registers its own node kinds and message types in `register`
/// ([`ratelab::graph::registry::register`], [`ratelab::msg::register`]): every front end —
/// the lab, `run`, `launch` (whose processes are this program started again, so each
/// registers them too), `sweep`, `cliff`, `exercise`, `bench`, `replay`, `kinds`, `msgs` —
/// then knows them. Returns the exit code: 0 done, 1 an exercise not passed or what ros2cli
/// refuses with exit 1 (`ratelab ros2`: `Node not found`, …), 2 bad input or a failed run,
/// 130 interrupted (Ctrl-C, SIGTERM; `ratelab ros2 topic echo|hz|bw`: ros2cli's code, 2, or
/// 0 for `hz` once subscribed), 141 a closed stdout.
///
/// ```no_run
/// fn main() -> std::process::ExitCode {
///     ratelab_lab::main_with(|| {
///         // ratelab::graph::registry::register("pd", …);
///     })
/// }
/// ```
pub fn main_with(register: impl FnOnce()) -> ExitCode {
    // This program is ratelab's command line on its own arguments: a camera may start it
    // again as its renderer (`render-camera`). Not in `run_command_line`, whose arguments
    // may be another program's.
    if let Ok(exe) = std::env::current_exe() {
        ratelab::distributed::launcher::Program::set_this(exe.into());
    }
    ExitCode::from(run_command_line(std::env::args_os().collect(), register))
}

/// A graph file's error as the command line prints it: `FILE:LINE:COL: error: reason`, as
/// gcc and clang print theirs, or `error: FILE: reason` for what concerns the whole file
/// (not found, too large; a file that is not UTF-8 is placed at its first byte that is
/// not). One line: [`SpecError`](ratelab::graph::spec::SpecError)'s parts have their
/// control characters written out.
fn spec_error_line(spec: &ratelab::graph::spec::SpecError) -> String {
    let origin = printable(&spec.origin);
    let reason = printable(&spec.reason);
    match spec.line {
        0 => format!("error: {origin}: {reason}"),
        line => format!("{origin}:{line}:{}: error: {reason}", spec.col),
    }
}

/// What Ctrl-C and SIGTERM stop: the command running now (its stop flag, the flag set only
/// by a signal, and whether a second signal is said), one at a time per process.
static SIGNALLED: std::sync::Mutex<Option<(StopFlag, StopFlag, bool)>> =
    std::sync::Mutex::new(None);

/// Ctrl-C / SIGTERM stop the command running ([`SIGNALLED`]) cleanly (summaries and files
/// still written); a second one exits at once. Installed once per process.
fn handle_signals() {
    static INSTALLED: std::sync::Once = std::sync::Once::new();
    INSTALLED.call_once(|| {
        let _ = ctrlc::set_handler(|| {
            let current = SIGNALLED.lock().unwrap_or_else(|e| e.into_inner()).clone();
            let Some((stop, interrupted, say)) = current else {
                std::process::exit(i32::from(EXIT_INTERRUPTED));
            };
            if interrupted.is_stopped() {
                // A terminal left in raw mode (`top`'s keys) is given back first.
                let _ = crossterm::terminal::disable_raw_mode();
                if say {
                    eprintln!(
                        "ratelab: interrupted again: exiting at once, without a summary or files (a new recording keeps what it had written)"
                    );
                }
                std::process::exit(i32::from(EXIT_INTERRUPTED));
            }
            interrupted.stop();
            stop.stop();
            // A Python callback that never returns would hold its node's tick forever:
            // one still running after a short grace is interrupted (src/python).
            ratelab::python::interrupt_callbacks_after(PYTHON_GRACE);
        });
    });
}

/// [`main_with`] on the arguments `args` (the program's name first, as `argv`), returning
/// the exit code instead of ending the process: how ratelab's command line runs inside
/// another program (the Python wheel's `ratelab` command runs it in the interpreter).
/// `register` runs before the arguments are read; Ctrl-C and SIGTERM are ratelab's from the
/// first call on.
pub fn run_command_line(args: Vec<std::ffi::OsString>, register: impl FnOnce()) -> u8 {
    // Before any thread starts (it sets an environment variable that Zenoh reads).
    if let Err(e) = ratelab::distributed::set_zenoh_runtime() {
        eprintln!("error: {e}");
        return EXIT_USAGE;
    }
    ratelab::init();
    register();
    quiet_on_a_closed_stdout();
    // No flag, name or path of ratelab holds a control character: one in a value (a
    // newline pasted into `--listen`) is refused here, in one line that shows it.
    if let Some(arg) = args
        .iter()
        .skip(1)
        .map(|a| a.to_string_lossy().into_owned())
        .find(|a| ratelab::text::has_control(a))
    {
        eprintln!(
            "error: the argument '{}' holds a control character; no flag, name or path of ratelab takes one",
            printable(&arg)
        );
        return EXIT_USAGE;
    }
    let cli = match Cli::parse_argv(&args) {
        Ok(cli) => cli,
        Err(e) => {
            if matches!(e.kind(), ErrorKind::DisplayHelp | ErrorKind::DisplayVersion) {
                let _ = e.print();
                return 0;
            }
            eprintln!("{}", one_line(&e.render().to_string()));
            return EXIT_USAGE;
        }
    };
    if let Some(Command::RenderCamera(args)) = &cli.command {
        // A camera's renderer ends with its pipe, or on SIGTERM as any process does: not
        // ratelab's signal handling, which would keep it serving until its camera goes.
        return match ratelab::graph::nodes::camera_render::serve_stdio(args.width, args.height) {
            Ok(()) => 0,
            Err(e) => {
                eprintln!("error: {}", printable(&e));
                EXIT_USAGE
            }
        };
    }
    let stop = StopFlag::new();
    // Set only by a signal (a fall also sets `stop`, under the real clock).
    let interrupted = StopFlag::new();
    // A node process started by a launcher gets a second signal when the launcher exits
    // (PR_SET_PDEATHSIG): it goes quietly.
    let say = !matches!(cli.command, Some(Command::Process(_)));
    *SIGNALLED.lock().unwrap_or_else(|e| e.into_inner()) =
        Some((stop.clone(), interrupted.clone(), say));
    handle_signals();
    let result = match &cli.command {
        Some(Command::Run(args)) => headless(args, stop),
        Some(Command::Lab(_)) if cli.headless => Err(anyhow::anyhow!(
            "`lab` is the terminal lab and cannot run --headless: `ratelab run` runs the graph headless"
        )),
        Some(Command::Lab(args)) if args.attach => {
            launch::run_attach(&args.connect, args.credentials.as_deref(), stop)
        }
        Some(Command::Lab(args)) => lab(&args.run, stop),
        Some(Command::Replay(args)) => replay(args),
        Some(Command::Bench(args)) => bench::run_bench(args, stop),
        Some(Command::Exercise(args)) => exercise::run_from_args(args, &stop),
        Some(Command::Sweep(args)) => sweep::run_sweep(args, &stop),
        Some(Command::Cliff(args)) => sweep::run_cliff(args, &stop),
        Some(Command::Launch(args)) => launch::run_launch(args, cli.headless, stop),
        Some(Command::Process(args)) => launch::run_process(args, stop),
        Some(Command::Router(args)) => launch::run_router(args, stop),
        Some(Command::Top(args)) => top::run_top(args, stop),
        Some(Command::Export(args)) => export(args),
        Some(Command::Kinds) => {
            print!("{}", ratelab::graph::registry::kinds_table());
            Ok(())
        }
        Some(Command::Msgs) => {
            print!("{}", ratelab::msg::types_table());
            Ok(())
        }
        Some(Command::Ros2(args)) => ros2::run(args, cli.headless, stop),
        Some(Command::Graph(args)) => generate_graph(args),
        // Served above, before ratelab's signal handling.
        Some(Command::RenderCamera(_)) => Ok(()),
        None => {
            if !cli.headless && std::io::stdout().is_terminal() && std::io::stdin().is_terminal() {
                lab(&cli.run, stop)
            } else {
                headless(&cli.run, stop)
            }
        }
    };
    *SIGNALLED.lock().unwrap_or_else(|e| e.into_inner()) = None;
    match result {
        Ok(()) if interrupted.is_stopped() => EXIT_INTERRUPTED,
        Ok(()) => 0,
        // `ratelab ros2 topic echo|hz|bw` stopped by Ctrl-C: ros2cli's exit code, nothing said.
        Err(e) if e.downcast_ref::<ros2::Interrupted>().is_some() => e
            .downcast_ref::<ros2::Interrupted>()
            .map_or(EXIT_INTERRUPTED, |i| i.0),
        Err(e) => {
            // A graph file's error is `FILE:LINE:COL: error: reason`, as compilers print them.
            // Not `eprintln!`: stderr may be a terminal that hung up (SIGHUP).
            let mut err = std::io::stderr();
            // What ros2cli refuses with its message alone and exit 1 (`ratelab ros2`).
            if let Some(refused) = e.downcast_ref::<ros2::Refused>() {
                let _ = writeln!(err, "{}", printable(&refused.0));
                return if interrupted.is_stopped() {
                    EXIT_INTERRUPTED
                } else {
                    ros2::EXIT_REFUSED
                };
            }
            // One line whatever the error quotes (a flag's value, a file's text, a peer's
            // name, a learner's exception): its control characters are written out.
            let _ = match e.downcast_ref::<ratelab::graph::spec::SpecError>() {
                Some(spec) => writeln!(err, "{}", spec_error_line(spec)),
                None => writeln!(err, "error: {}", printable(&format!("{e:#}"))),
            };
            // Whatever failed after a Ctrl-C failed because of it.
            if interrupted.is_stopped() {
                EXIT_INTERRUPTED
            } else if e.downcast_ref::<exercise::NotPassed>().is_some() {
                EXIT_NOT_PASSED
            } else {
                EXIT_USAGE
            }
        }
    }
}
