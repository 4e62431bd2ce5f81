//! End to end: the real `ratelab` binary in a pseudo-terminal, read through a vt100 parser.

use portable_pty::{native_pty_system, CommandBuilder, PtySize};
use std::io::{Read, Write};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

mod attached;
mod failures;
mod hangs;
mod readout;

/// A pseudo-terminal of `cols` × `rows` (the tests' screens are 100×30 unless they test
/// the two sizes the lab is made for, 80×24 and 120×40).
fn pty(cols: u16, rows: u16) -> portable_pty::PtyPair {
    native_pty_system()
        .openpty(PtySize {
            rows,
            cols,
            pixel_width: 0,
            pixel_height: 0,
        })
        .expect("a pseudo-terminal")
}

/// Wait (at most 15 s) for `child` to exit (`after`: what should have made it, for the
/// failure).
fn exit_status(
    child: &mut (dyn portable_pty::Child + Send + Sync),
    after: &str,
) -> portable_pty::ExitStatus {
    let start = Instant::now();
    loop {
        if let Some(s) = child.try_wait().unwrap() {
            return s;
        }
        assert!(
            start.elapsed() < Duration::from_secs(15),
            "ratelab did not exit after {after}"
        );
        std::thread::sleep(Duration::from_millis(50));
    }
}

struct Lab {
    parser: Arc<Mutex<vt100::Parser>>,
    writer: Box<dyn Write + Send>,
    child: Box<dyn portable_pty::Child + Send + Sync>,
}

impl Lab {
    fn start(args: &[&str]) -> Lab {
        Lab::start_with(args, &[])
    }

    /// With these environment variables set as well.
    fn start_with(args: &[&str], env: &[(&str, String)]) -> Lab {
        Lab::start_sized(args, env, 100, 30)
    }

    /// In a terminal of `cols` × `rows`.
    fn start_sized(args: &[&str], env: &[(&str, String)], cols: u16, rows: u16) -> Lab {
        Lab::start_program(
            env!("CARGO_BIN_EXE_ratelab").as_ref(),
            args,
            env,
            cols,
            rows,
        )
    }

    /// `program` (a `ratelab` binary, or a program on `ratelab_lab::main_with`) in a
    /// terminal of `cols` × `rows`.
    fn start_program(
        program: &std::path::Path,
        args: &[&str],
        env: &[(&str, String)],
        cols: u16,
        rows: u16,
    ) -> Lab {
        let pty = pty(cols, rows);
        let mut cmd = CommandBuilder::new(program);
        cmd.args(args);
        cmd.env("TERM", "xterm-256color");
        for (k, v) in env {
            cmd.env(k, v);
        }
        cmd.cwd(std::env::temp_dir());
        let child = pty.slave.spawn_command(cmd).expect("spawn ratelab");
        drop(pty.slave);
        let parser = Arc::new(Mutex::new(vt100::Parser::new(
            std::num::NonZeroU16::new(rows).unwrap(),
            std::num::NonZeroU16::new(cols).unwrap(),
            0,
        )));
        let mut reader = pty.master.try_clone_reader().unwrap();
        let p = parser.clone();
        std::thread::spawn(move || {
            let mut buf = [0u8; 8192];
            while let Ok(n) = reader.read(&mut buf) {
                if n == 0 {
                    break;
                }
                p.lock().unwrap().process(&buf[..n]);
            }
        });
        let writer = pty.master.take_writer().unwrap();
        // Keep the master alive as long as the writer is (portable-pty ties them together).
        std::mem::forget(pty.master);
        Lab {
            parser,
            writer,
            child,
        }
    }

    fn screen(&self) -> String {
        self.parser.lock().unwrap().screen().contents()
    }

    /// Wait (at most 60 s) until the run on screen steps: `BALANCED` with its run time past
    /// 0.2 s, so its nodes' code has loaded. A save before then may be read by the run's
    /// own start (whose first frames already say `BALANCED` at t 0.00 s), not as a save.
    fn wait_for_the_run(&self) -> String {
        self.wait_until("the run stepping, balanced", Duration::from_secs(60), |s| {
            s.contains("BALANCED") && shown_run_time(s).is_some_and(|t| t > 0.2)
        })
    }

    fn wait_for(&self, needle: &str, timeout: Duration) -> String {
        self.wait_until(&format!("'{needle}'"), timeout, |s| s.contains(needle))
    }

    /// Wait until the screen satisfies `ok` (described as `what` when it does not in time).
    fn wait_until(&self, what: &str, timeout: Duration, ok: impl Fn(&str) -> bool) -> String {
        let start = Instant::now();
        loop {
            let s = self.screen();
            if ok(&s) {
                return s;
            }
            assert!(
                start.elapsed() < timeout,
                "{what} not on screen after {timeout:?}:\n{s}"
            );
            std::thread::sleep(Duration::from_millis(50));
        }
    }

    fn keys(&mut self, keys: &str) {
        for k in keys.chars() {
            write!(self.writer, "{k}").unwrap();
            self.writer.flush().unwrap();
            std::thread::sleep(Duration::from_millis(40));
        }
    }

    /// Wait (at most 15 s) for the process to exit.
    fn exit_status(&mut self, after: &str) -> portable_pty::ExitStatus {
        exit_status(&mut *self.child, after)
    }

    fn quit(self) {
        self.quit_and_read();
    }

    /// As [`Lab::quit`], and what the terminal shows after: what ratelab printed once the
    /// lab gave the screen back (its summary), as far as it fits the terminal.
    fn quit_and_read(mut self) -> String {
        self.keys("q");
        let status = self.exit_status("q");
        assert!(status.success(), "exit status {status:?}");
        std::thread::sleep(Duration::from_millis(200));
        let parser = self.parser.lock().unwrap();
        assert!(
            !parser.screen().alternate_screen(),
            "still on the alternate screen"
        );
        assert!(!parser.screen().hide_cursor(), "the cursor was left hidden");
        parser.screen().contents()
    }
}

#[test]
fn virtual_lab_falls_off_the_rate_cliff_and_quits_cleanly() {
    let _machine = crate::machine::alone();
    let mut lab = Lab::start(&["--clock", "virtual"]);
    lab.wait_for("BALANCED", Duration::from_secs(60));
    lab.wait_for("virtual clock", Duration::from_secs(5));
    // Step the control rate down the ladder: 50 → … → 5 Hz (11 presses).
    lab.keys("-----------");
    lab.wait_for("5 Hz set", Duration::from_secs(30));
    let screen = lab.wait_for("FELL at t=", Duration::from_secs(60));
    assert!(screen.contains("dropped"), "{screen}");
    lab.quit();
}

#[test]
fn the_lab_offers_its_graph_to_ros_2_with_the_virtual_clock_on_clock() {
    use crate::ros2::{assert_every_one_from, clock_ns, connect_to, strs, StandIn};
    let _machine = crate::machine::alone();
    let endpoint = format!("tcp/127.0.0.1:{}", crate::distributed::free_port());
    let standin = StandIn::start("router", &endpoint, 0, &[]);
    let dir = tempfile::tempdir().unwrap();
    let session = dir.path().join("session.json");
    let lab = Lab::start_with(
        &[
            "--clock",
            "virtual",
            "--ros2",
            "--session",
            session.to_str().unwrap(),
        ],
        &[connect_to(&endpoint)],
    );
    lab.wait_for(
        &format!("ROS 2 domain 0 + /clock: via the router at {endpoint}"),
        Duration::from_secs(60),
    );
    lab.wait_for("BALANCED", Duration::from_secs(10));
    // `ros2 param set` on a node's rate is the lab's rate key: the run takes it, and
    // `param get` and /parameter_events say the new rate.
    let ros2 = |verb: &[&str]| {
        let args = [&["ros2", "--connect", endpoint.as_str()][..], verb].concat();
        crate::ros2::ratelab(&args, &[])
    };
    let (code, out, err) = ros2(&["param", "set", "/policy", "rate_hz", "25.0"]);
    assert_eq!(
        (code, out.as_str()),
        (0, "Set parameter successful\n"),
        "{err}"
    );
    let deadline = std::time::Instant::now() + Duration::from_secs(10);
    let mut got = String::new();
    while std::time::Instant::now() < deadline && got != "Double value is: 25.0\n" {
        std::thread::sleep(Duration::from_millis(200));
        got = ros2(&["param", "get", "/policy", "rate_hz"]).1;
    }
    assert_eq!(got, "Double value is: 25.0\n");
    // The graph's own rules first: the actuator's rate is the plant's step. A refused set
    // is said on stderr and exits 0, as ros2cli's `param set` (ros2param's verb/set.py).
    let (code, out, err) = ros2(&["param", "set", "/actuator", "rate_hz", "40.0"]);
    assert_eq!((code, out.as_str()), (0, ""), "{err}");
    assert!(
        err.contains("Setting parameter failed: /actuator: rate_hz: actuator rate 40 Hz refused"),
        "{err}"
    );
    let (code, out, err) = ros2(&["param", "set", "/policy", "use_sim_time", "false"]);
    assert_eq!((code, out.as_str()), (0, ""), "{err}");
    assert!(
        err.contains("Setting parameter failed: /policy: parameter 'use_sim_time' is read-only"),
        "{err}"
    );
    // Quit once the header's run time has reached 2 s (not after 2 s of wall time, which
    // a slow start on a loaded machine may eat into): the stand-in has had that much.
    lab.wait_until("run time 2 s", Duration::from_secs(60), |s| {
        s.split("│ t ")
            .nth(1)
            .and_then(|r| r.split(" s").next())
            .and_then(|t| t.trim().parse::<f64>().ok())
            .is_some_and(|t| t >= 2.0)
    });
    lab.quit();
    let r = standin.report();
    assert_eq!(r["errors"], serde_json::json!([]), "{r}");
    assert_eq!(
        strs(&r["nodes"]),
        ["actuator", "policy", "ratelab", "sensor"]
    );
    // The lab paces virtual time at 1×: about 50 messages a second, every one, from the
    // first; /clock follows the run's time.
    let obs = r["topics"]["/obs"].as_array().unwrap();
    assert!(obs.len() >= 80, "{} messages", obs.len());
    assert_every_one_from(obs, 1);
    let clock = clock_ns(&r);
    assert!(clock.windows(2).all(|w| w[0] < w[1]));
    assert!(*clock.last().unwrap() >= 1_500_000_000, "{clock:?}");
    // The set is a command of the run, in its session log as the key's would be: `replay`
    // runs it again.
    let log: serde_json::Value = serde_json::from_slice(&std::fs::read(&session).unwrap()).unwrap();
    let commands = &log["runs"][0]["commands"];
    let set = &commands[0];
    assert_eq!(
        (&set["cmd"], &set["node"], &set["hz"]),
        (&"set_node_hz".into(), &"policy".into(), &25.0.into()),
        "{commands}"
    );
    let events = r["topics"]["/parameter_events"].as_array().unwrap();
    assert!(
        events
            .iter()
            .any(|e| e["node"] == "/policy"
                && e["changed"]["rate_hz"] == serde_json::json!([3, 25.0])),
        "{events:?}"
    );
}

#[test]
fn real_clock_lab_keeps_the_pole_up_for_3_s() {
    let _machine = crate::machine::alone();
    let lab = Lab::start(&["--clock", "real"]);
    lab.wait_for("real clock", Duration::from_secs(60));
    std::thread::sleep(Duration::from_secs(3));
    let screen = lab.wait_for("BALANCED", Duration::from_secs(5));
    assert!(!screen.contains("FELL"), "{screen}");
    assert!(
        screen.contains("Hz meas"),
        "the real clock shows measured rates:\n{screen}"
    );
    assert!(
        screen.contains("µs late"),
        "the real clock shows tick lateness:\n{screen}"
    );
    assert!(
        screen.contains("tick p50 "),
        "the real clock shows what a tick takes:\n{screen}"
    );
    lab.quit();
}

#[test]
fn sigterm_restores_the_terminal() {
    let _machine = crate::machine::alone();
    let mut lab = Lab::start(&["--clock", "virtual"]);
    lab.wait_for("BALANCED", Duration::from_secs(60));
    let pid = lab.child.process_id().expect("a pid") as libc::pid_t;
    // SAFETY: signalling our own child process.
    unsafe { libc::kill(pid, libc::SIGTERM) };
    let status = lab.exit_status("SIGTERM");
    assert_eq!(status.exit_code(), 130, "{status:?}");
    std::thread::sleep(Duration::from_millis(200));
    let parser = lab.parser.lock().unwrap();
    assert!(
        !parser.screen().alternate_screen(),
        "SIGTERM left the alternate screen on"
    );
    assert!(
        !parser.screen().hide_cursor(),
        "SIGTERM left the cursor hidden"
    );
    drop(parser);
    lab.keys(""); // the pty is still writable: nothing hangs
}

/// The lab's window closed under it (the pseudo-terminal's master side gone: SIGHUP, and
/// every write to the terminal fails): it ends without a panic or a backtrace, not as a
/// success, and its recording and session log are whole.
#[test]
fn a_lab_whose_terminal_hangs_up_ends_quietly_with_its_recording_whole() {
    let _machine = crate::machine::alone();
    let dir = tempfile::tempdir().unwrap();
    let rrd = dir.path().join("hup.rrd");
    let pty = pty(100, 30);
    let mut cmd = CommandBuilder::new(env!("CARGO_BIN_EXE_ratelab"));
    cmd.args(["--clock", "virtual", "--record"]);
    cmd.arg(&rrd);
    cmd.env("TERM", "xterm-256color");
    cmd.cwd(dir.path());
    let mut child = pty.slave.spawn_command(cmd).expect("spawn ratelab");
    drop(pty.slave);
    let mut reader = pty.master.try_clone_reader().unwrap();
    let (tx, rx) = std::sync::mpsc::channel();
    std::thread::spawn(move || {
        let mut parser = vt100::Parser::new(
            std::num::NonZeroU16::new(30).unwrap(),
            std::num::NonZeroU16::new(100).unwrap(),
            0,
        );
        let mut buf = [0u8; 8192];
        while let Ok(n) = reader.read(&mut buf) {
            if n == 0 {
                break;
            }
            parser.process(&buf[..n]);
            if parser.screen().contents().contains("BALANCED") {
                // Its copy of the master side goes with it: the window can then close.
                let _ = tx.send(());
                break;
            }
        }
    });
    rx.recv_timeout(Duration::from_secs(60))
        .expect("the lab runs");
    std::thread::sleep(Duration::from_secs(1)); // a second of the run, unread
    drop(pty.master); // the window closes
    let status = exit_status(&mut *child, "its terminal hung up");
    // 2 (a write failed first) or 130 (the signal came first); a panic is 101.
    assert!([2, 130].contains(&status.exit_code()), "{status:?}");
    let events = crate::recording::events_with_times(&rrd);
    for kind in ["start:", "end:"] {
        assert!(
            events.iter().any(|(_, _, e)| e.starts_with(kind)),
            "{kind} {events:?}"
        );
    }
    assert!(dir.path().join("hup.session.json").is_file());
}

#[test]
fn any_graph_in_the_lab_tab_selects_and_esc_backs_out() {
    let _machine = crate::machine::alone();
    let graph = std::path::Path::new(crate::REPO).join("graphs/cartpole-estimator.toml");
    let mut lab = Lab::start(&["--clock", "virtual", "--graph", graph.to_str().unwrap()]);
    // The first frame, before the run has started, can still show the chapter's graph.
    lab.wait_for("/meas", Duration::from_secs(60));
    let screen = lab.wait_for("BALANCED", Duration::from_secs(10));
    for name in [
        "sensor",
        "/meas",
        "estimator",
        "/state",
        "policy",
        "/action",
        "actuator",
    ] {
        assert!(screen.contains(name), "{name} not drawn:\n{screen}");
    }
    // Tab, Tab: the estimator; `-` steps its rate down the ladder (100 → 60 Hz).
    lab.keys("\t\t");
    lab.wait_for("estimator selected", Duration::from_secs(5));
    lab.keys("-");
    lab.wait_for("estimator rate → 60", Duration::from_secs(5));
    // Esc closes the help, then the selection, then asks, and only then quits.
    lab.keys("?");
    lab.wait_for("keys (? or Esc to close)", Duration::from_secs(5));
    lab.keys("\x1b");
    std::thread::sleep(Duration::from_millis(300));
    let screen = lab.wait_for("estimator selected", Duration::from_secs(5));
    assert!(
        !screen.contains("Esc to close"),
        "help still open:\n{screen}"
    );
    lab.keys("\x1b");
    std::thread::sleep(Duration::from_millis(300));
    assert!(
        lab.child.try_wait().unwrap().is_none(),
        "Esc quit with a selection open"
    );
    assert!(!lab.screen().contains("estimator selected"));
    lab.keys("\x1b");
    lab.wait_for("quit? Esc again or q quits", Duration::from_secs(5));
    assert!(lab.child.try_wait().unwrap().is_none(), "one bare Esc quit");
    lab.keys("\x1b");
    let status = lab.exit_status("Esc");
    assert!(status.success(), "{status:?}");
}

/// Keys typed as a person types them: one every 0.4 s.
/// At the two sizes the lab is made for, the real binary: a break (`b`, 5 Hz) falls, the
/// verdict and the drops read whole, `=` after the fall shows its prompt and Esc cancels it,
/// and `q` restores the terminal (#25's screen items at 80×24 and 120×40).
#[test]
fn at_80x24_and_120x40_a_fall_reads_whole_and_typing_a_rate_has_its_prompt() {
    let _machine = crate::machine::alone();
    for (cols, rows) in [(80, 24), (120, 40)] {
        let mut lab = Lab::start_sized(&["--clock", "virtual"], &[], cols, rows);
        lab.wait_for("BALANCED", Duration::from_secs(60));
        type_slowly(&mut lab, "b");
        let fell = lab.wait_for("FELL at t=", Duration::from_secs(30));
        assert!(fell.contains("5 Hz"), "{cols}x{rows}:\n{fell}");
        assert!(fell.contains("drop"), "{cols}x{rows}:\n{fell}");
        type_slowly(&mut lab, "=8");
        let typing = lab.wait_for("rate (Hz): 8", Duration::from_secs(5));
        assert!(typing.contains("Enter apply"), "{cols}x{rows}:\n{typing}");
        lab.keys("\x1b");
        lab.wait_until("the prompt gone", Duration::from_secs(5), |s| {
            !s.contains("rate (Hz):")
        });
        lab.quit();
    }
}

/// Keys that are escape sequences (`\x1b[B`, ↓), each written whole (a lone ESC is Esc),
/// one every 0.4 s.
fn press(lab: &mut Lab, sequences: &[&str]) {
    for seq in sequences {
        lab.writer.write_all(seq.as_bytes()).unwrap();
        lab.writer.flush().unwrap();
        std::thread::sleep(Duration::from_millis(400));
    }
}

fn type_slowly(lab: &mut Lab, keys: &str) {
    for k in keys.chars() {
        lab.keys(&k.to_string());
        std::thread::sleep(Duration::from_millis(400));
    }
}

#[test]
fn the_queue_trap_recipe_works_at_human_speed() {
    // exercises/README.md: `b`; after the fall `]` until depth 100, then `r`: the drops
    // vanish from /obs and the pole still falls.
    let _machine = crate::machine::alone();
    let mut lab = Lab::start(&["--clock", "virtual"]);
    lab.wait_for("BALANCED", Duration::from_secs(60));
    type_slowly(&mut lab, "b");
    lab.wait_for("FELL at t=", Duration::from_secs(30));
    type_slowly(&mut lab, "]]]]");
    lab.wait_for("(from the next run)", Duration::from_secs(5));
    type_slowly(&mut lab, "r");
    let screen = lab.wait_for("depth 100", Duration::from_secs(10));
    assert!(
        screen.contains("5 Hz set"),
        "the break survives the reset:\n{screen}"
    );
    let screen = lab.wait_for("FELL at t=", Duration::from_secs(30));
    let graph_rows: Vec<&str> = screen.lines().skip(1).take(6).collect();
    assert!(
        graph_rows.iter().any(|l| l.contains("0 dropped ✓")) && !screen.contains("dropped ⚠"),
        "a deep queue drops nothing:\n{screen}"
    );
    lab.quit();
}

/// `t` shows the executor timeline: on the executors graph (sensor and a 30 ms policy in
/// one exclusive group of a two-thread executor) every tick of both is on the executor's
/// first thread, the sensor's (S) each followed by the policy computing (Ppp); `t` again
/// gives the latency histogram back.
#[test]
fn the_executor_timeline_shows_which_tick_ran_on_which_thread() {
    let _machine = crate::machine::alone();
    let graph = crate::repo("graphs/cartpole-executors.toml");
    let mut lab = Lab::start(&["--clock", "virtual", "--graph", graph.to_str().unwrap()]);
    lab.wait_for("BALANCED", Duration::from_secs(60));
    type_slowly(&mut lab, "t");
    let screen = lab.wait_until("the timeline", Duration::from_secs(10), |s| {
        s.contains("executor timeline") && s.contains("main#1") && s.contains("Spp")
    });
    let lane = |name: &str| {
        screen
            .lines()
            .find(|l| l.trim_start_matches('│').starts_with(name))
            .map(str::to_string)
            .unwrap_or_default()
    };
    assert!(
        !lane("main#2").contains('S') && !lane("main#2").contains('P'),
        "one exclusive group: nothing on the second thread\n{screen}"
    );
    assert!(lane("actuator").contains('A'), "{screen}");
    type_slowly(&mut lab, "t");
    lab.wait_for("sense→act latency", Duration::from_secs(5));
    lab.quit();
}

#[test]
fn pause_stops_virtual_time_and_is_refused_under_the_real_clock() {
    let _machine = crate::machine::alone();
    let mut lab = Lab::start(&["--clock", "virtual"]);
    lab.wait_for("BALANCED", Duration::from_secs(60));
    type_slowly(&mut lab, " ");
    let paused = lab.wait_for("PAUSED", Duration::from_secs(5));
    let t = |s: &str| {
        s.split("│ t ")
            .nth(1)
            .and_then(|r| r.split(' ').next())
            .map(str::to_string)
    };
    std::thread::sleep(Duration::from_secs(1));
    assert_eq!(
        t(&paused),
        t(&lab.screen()),
        "virtual time stands still while paused"
    );
    lab.quit();

    let mut lab = Lab::start(&["--clock", "real"]);
    lab.wait_for("real clock", Duration::from_secs(60));
    type_slowly(&mut lab, " ");
    let screen = lab.wait_for("pause is for the virtual clock", Duration::from_secs(5));
    assert!(!screen.contains("PAUSED"), "{screen}");
    lab.quit();
}

/// `c` in the real binary: the running graph goes on under the real clock from the run time
/// it had reached (its clock never starts again from 0), then back under the virtual one,
/// where pausing works again.
#[test]
fn c_switches_the_running_lab_s_clock_in_place() {
    let _machine = crate::machine::alone();
    let t = |s: &str| -> f64 {
        s.split("│ t ")
            .nth(1)
            .and_then(|r| r.split(' ').next())
            .and_then(|v| v.parse().ok())
            .unwrap_or(-1.0)
    };
    let mut lab = Lab::start(&["--clock", "virtual"]);
    lab.wait_until("t ≥ 1 s", Duration::from_secs(60), |s| t(s) >= 1.0);
    type_slowly(&mut lab, "c");
    let real = lab.wait_for("the same run goes on", Duration::from_secs(10));
    assert!(real.contains("real clock │"), "{real}");
    assert!(t(&real) >= 1.0, "the run time goes on: {real}");
    let switched = t(&real);
    let later = lab.wait_until("t 1 s later", Duration::from_secs(20), |s| {
        t(s) >= switched + 1.0
    });
    assert!(later.contains("BALANCED"), "{later}");
    type_slowly(&mut lab, "c");
    let back = lab.wait_for("clock → virtual", Duration::from_secs(10));
    assert!(back.contains("virtual clock"), "{back}");
    assert!(t(&back) >= switched + 1.0, "{back}");
    type_slowly(&mut lab, " ");
    lab.wait_for("PAUSED", Duration::from_secs(5));
    lab.quit();
}

/// A real-clock run that fell is reviewed in the real binary: space shows REVIEW, Shift-←
/// goes a second back (the pole BALANCED again, as it was then), space again shows the
/// fall.
#[test]
fn an_ended_real_clock_run_is_reviewed_with_space_and_the_arrows() {
    let _machine = crate::machine::alone();
    let mut lab = Lab::start(&["--clock", "real"]);
    lab.wait_for("BALANCED", Duration::from_secs(60));
    type_slowly(&mut lab, "b"); // the policy at 5 Hz: the pole falls
    lab.wait_for("FELL at", Duration::from_secs(30));
    type_slowly(&mut lab, " ");
    lab.wait_for("REVIEW", Duration::from_secs(5));
    press(&mut lab, &["\x1b[1;2D", "\x1b[1;2D"]);
    let back = lab.wait_for("as recorded", Duration::from_secs(5));
    assert!(
        back.contains("BALANCED"),
        "two seconds before the fall: {back}"
    );
    type_slowly(&mut lab, " ");
    let end = lab.wait_until("the fall again", Duration::from_secs(5), |s| {
        s.contains("FELL at") && !s.contains("REVIEW")
    });
    assert!(end.contains("real clock"), "{end}");
    lab.quit();
}

/// `ratelab launch --processes` on a terminal opens the lab on the graph it runs across
/// processes: nodes named with their process, measured rates and topic counters that cross
/// the boundary, a key that would change the graph refused; quitting stops every process.
#[test]
fn launch_across_processes_opens_the_lab_and_quitting_leaves_nothing_behind() {
    let _machine = crate::machine::alone();
    // At the two sizes the lab is made for (#25): the header says where the launch listens
    // where it fits (120 columns), the footer at 80.
    for (cols, rows) in [(80, 24), (120, 40)] {
        let port = crate::distributed::free_port();
        let ep = format!("tls/127.0.0.1:{port}");
        let args = ["launch", "--processes", "--clock", "real", "--listen", &ep];
        let mut lab = Lab::start_sized(&args, &[], cols, rows);
        lab.wait_for("2 processes", Duration::from_secs(60));
        for node in ["sensor@robot", "policy@policy", "actuator@robot"] {
            lab.wait_for(node, Duration::from_secs(10));
        }
        // Ticks of the policy's process (its measured rate) and the robot's steps arrive.
        lab.wait_for("Hz meas", Duration::from_secs(20));
        let s = lab.wait_for("BALANCED", Duration::from_secs(10));
        assert!(s.contains("real clock"), "{s}");
        // Where it listens, at once: whole at 120 columns, its port at 80.
        let header = s.lines().next().unwrap_or_default();
        let at = if cols >= 120 {
            format!("2 processes at {ep}")
        } else {
            format!("2 processes at :{port}")
        };
        assert!(header.contains(&at), "{cols}x{rows}:\n{s}");
        // The /obs counters are the policy process's copy: 50 Hz published, none dropped.
        lab.wait_for("msg/s", Duration::from_secs(10));
        assert_eq!(
            crate::distributed::processes_mentioning(&format!(":{port}")).len(),
            2,
            "two node processes while the lab runs"
        );
        lab.keys("+");
        lab.wait_for("read-only: live changes", Duration::from_secs(5));
        let after = lab.quit_and_read();
        // After the lab (where the whole of it fits, 40 rows): where it listened said once,
        // and a run of no set length stopped, not "of 315360000.00s".
        if rows >= 40 {
            assert_eq!(after.matches("listening on").count(), 1, "{after}");
            assert!(
                after.contains("STOPPED at t=") && after.contains("(no set length;"),
                "{after}"
            );
        }
        crate::distributed::assert_none_left(port, Duration::from_millis(500));
    }
}

/// What a node prints in another process of a launch shows in the lab's log pane (`v`),
/// stamped with its run time and node as in one process, never over the screen.
#[test]
fn a_launch_s_lab_shows_what_its_processes_nodes_print_in_the_log_pane() {
    let _machine = crate::machine::alone();
    let dir = tempfile::tempdir().unwrap();
    let g = crate::loud_python_graph(dir.path(), "print('zqx tick here')");
    let port = crate::distributed::free_port();
    let ep = format!("tls/127.0.0.1:{port}");
    let args = [
        "launch",
        "--processes",
        "--clock",
        "real",
        "--listen",
        &ep,
        "--graph",
        g.to_str().unwrap(),
    ];
    let mut lab = Lab::start_sized(&args, &[], 120, 40);
    lab.wait_for("BALANCED", Duration::from_secs(60));
    type_slowly(&mut lab, "v");
    // A row of the pane: `│t=7.40  policy    zqx tick here`.
    let screen = lab.wait_until(
        "a line of the policy's in the pane",
        Duration::from_secs(15),
        |s| {
            s.lines().any(|l| {
                l.starts_with("│t=") && l.contains(" policy ") && l.contains("zqx tick here")
            })
        },
    );
    assert!(
        !screen
            .lines()
            .any(|l| l.starts_with("zqx") || l.starts_with("policy: ")),
        "nothing over the screen: {screen}"
    );
    lab.quit();
    crate::distributed::assert_none_left(port, Duration::from_millis(500));
}

/// Under the virtual clock the lab paces the lockstep at ×1, as in one process; the arrows
/// read each topic's rate (the policy's copy of /obs sampled per tick, not per batch of
/// figures), and the lockstep's processes stop with the lab.
#[test]
fn a_launch_in_lockstep_shows_every_topic_s_rate_in_the_lab() {
    let _machine = crate::machine::alone();
    let port = crate::distributed::free_port();
    let ep = format!("tls/127.0.0.1:{port}");
    let dir = tempfile::tempdir().unwrap();
    let rrd = dir.path().join("run.rrd");
    let lab = Lab::start(&[
        "launch",
        "--processes",
        "--clock",
        "virtual",
        "--listen",
        &ep,
        "--record",
        rrd.to_str().unwrap(),
    ]);
    let screen = lab.wait_for("virtual clock · 2 processes", Duration::from_secs(60));
    let shown = Instant::now();
    // The header says the launch is recorded, and where.
    assert!(
        screen
            .lines()
            .next()
            .is_some_and(|h| h.contains("rec ●") && h.contains("run.rrd")),
        "{screen}"
    );
    // Both arrows at the chapter's 50 Hz (run time), once a 5 s window has passed.
    let screen = lab.wait_until("both arrows at 50.0 msg/s", Duration::from_secs(20), |s| {
        s.matches("50.0 msg/s").count() >= 2
    });
    // Paced at ×1: the run time in the header is about the wall time since (as fast as
    // it goes, it was hundreds of seconds by then).
    let t_s: f64 = screen
        .split("│ t ")
        .nth(1)
        .and_then(|r| r.split(" s").next())
        .and_then(|t| t.trim().parse().ok())
        .unwrap_or_else(|| panic!("no run time in the header:\n{screen}"));
    let wall_s = shown.elapsed().as_secs_f64();
    assert!(
        t_s <= wall_s + 2.0,
        "run time {t_s} s after {wall_s:.1} s of wall time:\n{screen}"
    );
    lab.quit();
    assert!(rrd.is_file(), "the recording was written");
    crate::distributed::assert_none_left(port, Duration::from_millis(500));
}

/// `ratelab lab --attach` on a running launch: a node process killed with SIGKILL is drawn
/// NOT ALIVE (its liveliness token went with it), and one started again is drawn alive.
#[test]
fn the_attached_lab_marks_a_killed_node_not_alive_and_sees_it_rejoin() {
    let _machine = crate::machine::alone();
    let port = crate::distributed::free_port();
    let ep = format!("tls/127.0.0.1:{port}");
    let dir = tempfile::tempdir().unwrap();
    let creds = dir.path().join("creds.toml");
    let mut launcher = crate::distributed::bin()
        .args([
            "launch",
            "--processes",
            "--clock",
            "real",
            "--duration",
            "40",
            "--listen",
            &ep,
            "--export-credentials",
            creds.to_str().unwrap(),
        ])
        .stdout(std::process::Stdio::null())
        .stderr(std::process::Stdio::null())
        .spawn()
        .unwrap();
    // Written before the launch listens.
    let until = Instant::now() + Duration::from_secs(30);
    while !creds.exists() && Instant::now() < until {
        std::thread::sleep(Duration::from_millis(50));
    }
    let lab = Lab::start(&[
        "lab",
        "--attach",
        "--connect",
        &ep,
        "--credentials",
        creds.to_str().unwrap(),
    ]);
    lab.wait_for("policy@policy", Duration::from_secs(60));
    lab.wait_for("Hz meas", Duration::from_secs(20));
    // Let the policy steady the pole first: the robot then holds its last force for a
    // second or so without it (killed at the very start, the pole falls at once).
    std::thread::sleep(Duration::from_secs(2));
    assert!(!lab.screen().contains("NOT ALIVE"), "{}", lab.screen());
    let policy = crate::distributed::node_processes(port, "policy");
    assert_eq!(policy.len(), 1, "one policy process: {policy:?}");
    // SAFETY: plain kill(2) on a process this test's launcher started.
    unsafe { libc::kill(policy[0] as i32, libc::SIGKILL) };
    lab.wait_for("NOT ALIVE", Duration::from_secs(10));
    // The launcher's line too (it comes on its own key: maybe a moment after the token).
    lab.wait_for("is gone", Duration::from_secs(5));
    // Its ticks stopped: its measured rate falls to 0 once a second has passed.
    lab.wait_for("0.0 Hz meas", Duration::from_secs(5));
    let mut again = crate::distributed::bin()
        .args(["process", "--process", "policy", "--connect", &ep])
        .arg("--credentials")
        .arg(&creds)
        .stdout(std::process::Stdio::null())
        .stderr(std::process::Stdio::null())
        .spawn()
        .unwrap();
    let start = Instant::now();
    while lab.screen().contains("NOT ALIVE") {
        assert!(
            start.elapsed() < Duration::from_secs(20),
            "the restarted policy is not drawn alive:\n{}",
            lab.screen()
        );
        std::thread::sleep(Duration::from_millis(100));
    }
    lab.quit();
    // SAFETY: plain kill(2) on our child: SIGTERM ends the launch cleanly.
    unsafe { libc::kill(launcher.id() as i32, libc::SIGTERM) };
    let status = launcher.wait().unwrap();
    // Interrupted (130), or over already (0) when the pole fell while the policy was down
    // (the robot held the last force for a second or so).
    assert!(
        matches!(status.code(), Some(130) | Some(0)),
        "the launch ended with {status:?}"
    );
    let _ = again.wait();
    crate::distributed::assert_none_left(port, Duration::ZERO);
}

/// Nothing to attach to: one line, exit 2, the terminal restored.
#[test]
fn attaching_where_no_graph_runs_says_so() {
    let port = crate::distributed::free_port();
    let ep = format!("tls/127.0.0.1:{port}");
    let dir = tempfile::tempdir().unwrap();
    let creds = crate::distributed::chapter_credentials(dir.path());
    let mut lab = Lab::start(&[
        "lab",
        "--attach",
        "--connect",
        &ep,
        "--credentials",
        creds.to_str().unwrap(),
    ]);
    let status = lab.exit_status("no graph to attach to");
    assert_eq!(status.exit_code(), 2);
    let s = lab.screen();
    assert!(
        s.contains("cannot open a Zenoh session") || s.contains("no running ratelab graph"),
        "{s}"
    );
}

/// `q` ends the lab even while a Python brain's call never returns: the call is interrupted
/// after a short grace (src/python), and the terminal is restored.
#[test]
fn quitting_the_lab_interrupts_a_python_brain_that_never_returns() {
    let _machine = crate::machine::alone();
    let dir = tempfile::tempdir().unwrap();
    let hang = dir.path().join("hang.py");
    std::fs::write(&hang, "def act(obs):\n    while True:\n        pass\n").unwrap();
    let mut lab = Lab::start(&["--clock", "virtual", "--policy", hang.to_str().unwrap()]);
    lab.wait_for("virtual clock", Duration::from_secs(60));
    std::thread::sleep(Duration::from_millis(500));
    let sent = Instant::now();
    lab.keys("q");
    let status = lab.exit_status("q with a hung brain");
    let took = sent.elapsed();
    // Loose for a loaded machine: the bug is never ending (exit_status gives up at 15 s).
    assert!(took < Duration::from_secs(10), "took {took:?}");
    assert!(status.success(), "exit status {status:?}");
    std::thread::sleep(Duration::from_millis(200));
    assert!(!lab.parser.lock().unwrap().screen().alternate_screen());
}

/// A brain that never returns holds the virtual clock: within seconds the lab says so, at
/// both sizes it is made for: the verdict reads `HUNG in policy's callback since t=…` (never
/// BALANCED while the clock is held) and the policy's box how long it has been in its
/// callback. Quitting still ends it at once.
#[test]
fn a_brain_that_never_returns_shows_hung_not_balanced() {
    let _machine = crate::machine::alone();
    let dir = tempfile::tempdir().unwrap();
    let hang = dir.path().join("hang.py");
    std::fs::write(
        &hang,
        "calls = 0\ndef act(obs):\n    global calls\n    calls += 1\n    while calls > 25:\n        pass\n    return 0.0\n",
    )
    .unwrap();
    for (cols, rows, verdict, in_box) in [
        (80, 24, "HUNG: policy since t=0.48s", "in callback "),
        (
            120,
            40,
            "HUNG in policy's callback since t=0.48s",
            "in callback ",
        ),
    ] {
        let mut lab = Lab::start_sized(
            &["--clock", "virtual", "--policy", hang.to_str().unwrap()],
            &[],
            cols,
            rows,
        );
        lab.wait_for("virtual clock", Duration::from_secs(60));
        // Within seconds; 10 s leaves a loaded machine room (the bug is never saying it).
        let screen = lab.wait_for(verdict, Duration::from_secs(10));
        assert!(!screen.contains("BALANCED"), "{screen}");
        assert!(
            screen.contains(in_box),
            "the policy's box at {cols}x{rows}:\n{screen}"
        );
        let sent = Instant::now();
        lab.keys("q");
        let status = lab.exit_status("q with a hung brain");
        // Loose for a loaded machine: the bug is never ending (exit_status gives up at 15 s).
        assert!(
            sent.elapsed() < Duration::from_secs(10),
            "{:?}",
            sent.elapsed()
        );
        assert!(status.success(), "{status:?}");
    }
}

/// A Python node that prints every tick and logs: nothing it writes lands on the lab's
/// screen (no row shows its text) until the log pane (`v`) is opened, where its lines are,
/// stamped with run time and node; at both sizes the lab is made for.
#[test]
fn what_a_python_node_prints_goes_to_the_log_pane_never_over_the_screen() {
    let _machine = crate::machine::alone();
    let dir = tempfile::tempdir().unwrap();
    let g = crate::loud_python_graph(
        dir.path(),
        "print('printed-by-policy', 42)\nimport sys; print('on-stderr', file=sys.stderr)",
    );
    for (cols, rows) in [(80, 24), (120, 40)] {
        let mut lab = Lab::start_sized(
            &["--clock", "virtual", "--graph", g.to_str().unwrap()],
            &[],
            cols,
            rows,
        );
        lab.wait_for("t 2.", Duration::from_secs(60));
        let screen = lab.screen();
        assert!(
            !screen.contains("printed-by") && !screen.contains("on-stderr"),
            "written over the screen at {cols}x{rows}:\n{screen}"
        );
        lab.keys("v");
        let screen = lab.wait_for("log: all nodes", Duration::from_secs(5));
        assert!(
            screen.contains("policy    printed-by-policy 42")
                || screen.contains("policy    on-stderr"),
            "{cols}x{rows}:\n{screen}"
        );
        assert!(
            !screen
                .lines()
                .any(|l| l.starts_with("printed-by") || l.starts_with("on-stderr")),
            "{screen}"
        );
        lab.keys("v");
        lab.quit();
    }
}

/// A program with a node kind of its own (`examples/custom_node_processes.rs`, on
/// `ratelab_lab::main_with`) opens the lab on a graph that uses it, which the `ratelab`
/// binary refuses: the pd node is drawn, the pole balances, `q` restores the terminal.
#[test]
fn a_program_s_own_kind_runs_in_its_lab() {
    let _machine = crate::machine::alone();
    let exe = std::env::current_exe().unwrap();
    let program = exe
        .parent()
        .and_then(|deps| deps.parent())
        .unwrap()
        .join("examples/custom_node_processes");
    let graph = std::path::Path::new(crate::REPO).join("examples/cartpole-pd.toml");
    let lab = Lab::start_program(
        &program,
        &[
            "lab",
            "--clock",
            "virtual",
            "--graph",
            graph.to_str().unwrap(),
        ],
        &[],
        100,
        30,
    );
    let screen = lab.wait_for("BALANCED", Duration::from_secs(60));
    for name in ["sensor", "/obs", "policy", "/action", "actuator", "pd node"] {
        assert!(screen.contains(name), "{name} not drawn:\n{screen}");
    }
    lab.quit();
}

/// Paused, Shift-← twice puts the run 2 s back: the clock reads 2.00 s less, the latency
/// histogram holds exactly the actuator's ticks up to then (as a headless run that long),
/// → moves on a tick, and a change there branches the run: the session log keeps only the
/// branch's command. At 80×24 and 120×40.
#[test]
fn paused_the_arrows_move_through_the_run_and_a_change_branches_it() {
    let _machine = crate::machine::alone();
    for (cols, rows) in [(80, 24), (120, 40)] {
        scrub_at(cols, rows);
    }
}

/// [`paused_the_arrows_move_through_the_run_and_a_change_branches_it`] at one size.
fn scrub_at(cols: u16, rows: u16) {
    let dir = tempfile::tempdir().unwrap();
    let session = dir.path().join("s.session.json");
    let mut lab = Lab::start_sized(
        &["--clock", "virtual", "--session", session.to_str().unwrap()],
        &[],
        cols,
        rows,
    );
    lab.wait_for("BALANCED", Duration::from_secs(60));
    std::thread::sleep(Duration::from_millis(3500));
    type_slowly(&mut lab, "-"); // 40 Hz from about 3.5 s: a command in the run's future
    std::thread::sleep(Duration::from_millis(500));
    type_slowly(&mut lab, " ");
    let paused = lab.wait_for("PAUSED", Duration::from_secs(5));
    let t = |s: &str| -> f64 {
        s.split("│ t ")
            .nth(1)
            .and_then(|r| r.split(' ').next())
            .and_then(|v| v.parse().ok())
            .unwrap_or_else(|| panic!("no run time on screen:\n{s}"))
    };
    let n = |s: &str| -> u64 {
        s.split("latency since the start: n=")
            .nth(1)
            .and_then(|r| r.split(' ').next())
            .and_then(|v| v.parse().ok())
            .unwrap_or_else(|| panic!("no latency count on screen:\n{s}"))
    };
    let t0 = t(&paused);
    assert!(t0 > 3.5, "{paused}");
    // Shift-← (xterm's CSI 1;2 D), twice: 2 s back, before the rate change. Each goes a
    // second back from the instant on screen, so the second waits for the first to show.
    let mut back = paused;
    for _ in 0..2 {
        let from = t(&back);
        write!(lab.writer, "\x1b[1;2D").unwrap();
        lab.writer.flush().unwrap();
        back = lab.wait_until("a second back", Duration::from_secs(10), |s| {
            s.contains("back at t=") && t(s) < from - 0.5
        });
    }
    let t1 = t(&back);
    // A seek lands on the run's last instant at or before its target. The pause may land
    // on any node's instant (the policy's 40 Hz grid among them); before the rate change
    // every node ticks on the 20 ms grid, so two seconds back is that grid's instant at or
    // before t0 - 2 s.
    let want = ((t0 - 2.0) / 0.02 + 1e-6).floor() * 0.02;
    assert!((t1 - want).abs() < 1e-9, "{t0} → {t1}, not {want}:\n{back}");
    // The actuator ticks at 0, 20 ms, …, t1: each one a latency sample.
    assert_eq!(n(&back), (t1 / 0.02).round() as u64 + 1, "{back}");
    assert!(
        back.contains("50 Hz set"),
        "the 40 Hz change is in the future:\n{back}"
    );
    // → one actuator tick on.
    write!(lab.writer, "\x1b[C").unwrap();
    lab.writer.flush().unwrap();
    let on = lab.wait_until("a tick on", Duration::from_secs(5), |s| {
        (t(s) - (t1 + 0.02)).abs() < 1e-9
    });
    assert_eq!(n(&on), n(&back) + 1);
    // A change here branches the run: the log keeps it alone.
    type_slowly(&mut lab, "b");
    lab.wait_for("control rate → 5 Hz", Duration::from_secs(5));
    lab.quit();
    let log: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&session).unwrap()).unwrap();
    let commands = log["runs"][0]["commands"].as_array().unwrap();
    assert_eq!(commands.len(), 1, "{commands:?}");
    assert_eq!(commands[0]["cmd"], "set_control_hz", "{commands:?}");
    assert_eq!(commands[0]["hz"], 5.0, "{commands:?}");
    let at_s = commands[0]["at_ns"].as_u64().unwrap() as f64 / 1e9;
    assert!((at_s - (t1 + 0.04)).abs() < 1e-9, "{at_s}");
}

/// The chapter's scripted balancer as a Python brain (graphs/brains/scripted.py's arithmetic).
const BALANCER: &str = "import math\n\ndef act(obs):\n    theta = math.atan2(float(obs[3]), float(obs[2]))\n    u = 10.0 * theta + 2.0 * float(obs[4]) + 0.4 * float(obs[0]) + 0.8 * float(obs[1])\n    return max(-1.0, min(1.0, u))\n";

/// Reload on save: a Python brain that pushes nothing (the pole falls), saved as one that
/// balances: the lab runs the graph again from t = 0 with the new code, says `reloaded
/// FILE:` and what changed, and draws the run before as a ghost beside the new one; a save
/// with a syntax error keeps the run going and says FILE:LINE, at both sizes the lab is
/// made for.
#[test]
fn saving_a_brain_reloads_it_beside_the_run_before() {
    let _machine = crate::machine::alone();
    for (cols, rows) in [(120, 40), (80, 24)] {
        let dir = tempfile::tempdir().unwrap();
        let brain = dir.path().join("brain.py");
        std::fs::write(&brain, "def act(obs):\n    return 0.0\n").unwrap();
        let lab = Lab::start_sized(
            &["--clock", "virtual", "--policy", brain.to_str().unwrap()],
            &[],
            cols,
            rows,
        );
        lab.wait_for("FELL", Duration::from_secs(60));
        std::fs::write(&brain, BALANCER).unwrap();
        // Taken up within the wait's 10 s (a loaded machine may take a few).
        let screen = lab.wait_for("reloaded", Duration::from_secs(10));
        assert!(screen.contains("fell at"), "{cols}x{rows}:\n{screen}");
        // The new run is up, its clock going from 0, and the run before is drawn beside it.
        let screen = lab.wait_until("the new run balancing", Duration::from_secs(10), |s| {
            s.contains("BALANCED") && !s.contains("FELL")
        });
        if cols >= 100 {
            assert!(screen.contains("before reload"), "{cols}x{rows}:\n{screen}");
            assert!(screen.contains("→ balanced"), "{cols}x{rows}:\n{screen}");
        }
        // Code that no longer loads: the run goes on, and the error names the line.
        std::fs::write(&brain, "def act(obs):\n    return (\n").unwrap();
        let screen = lab.wait_for("not reloaded", Duration::from_secs(10));
        assert!(screen.contains("brain.py:"), "{cols}x{rows}:\n{screen}");
        std::thread::sleep(Duration::from_millis(500));
        let screen = lab.screen();
        assert!(screen.contains("BALANCED"), "{cols}x{rows}:\n{screen}");
        lab.quit();
    }
}

/// The file watch follows the graph: a reload whose graph runs a node from a folder not
/// watched before (`other/`) watches it, and a save there reloads the lab (the node then
/// pushes nothing: the pole falls).
#[test]
fn a_reloaded_graph_s_new_folder_is_watched() {
    let _machine = crate::machine::alone();
    let dir = tempfile::tempdir().unwrap();
    std::fs::create_dir(dir.path().join("nodes")).unwrap();
    std::fs::create_dir(dir.path().join("other")).unwrap();
    let graph = dir.path().join("g.toml");
    let text = std::fs::read_to_string(crate::repo("graphs/cartpole-python.toml")).unwrap();
    std::fs::write(&graph, &text).unwrap();
    let script = std::fs::read_to_string(crate::repo("graphs/nodes/scripted_balancer.py")).unwrap();
    std::fs::write(dir.path().join("nodes/scripted_balancer.py"), &script).unwrap();
    let moved = dir.path().join("other/policy.py");
    std::fs::write(&moved, &script).unwrap();
    let lab = Lab::start(&["--clock", "virtual", "--graph", graph.to_str().unwrap()]);
    lab.wait_for_the_run();
    std::fs::write(
        &graph,
        text.replace("nodes/scripted_balancer.py", "other/policy.py"),
    )
    .unwrap();
    // Named as relative to the lab's folder: `reloaded .tmpXXXX/g.toml: …`.
    lab.wait_until("the graph's reload", Duration::from_secs(15), |s| {
        s.contains("reloaded") && s.contains("g.toml:")
    });
    // The new run has started (its graph's files are watched from its start).
    std::thread::sleep(Duration::from_millis(1500));
    std::fs::write(
        &moved,
        script.replace(
            "self.pub.publish(Force(newtons=float(command) * MOTOR_N))",
            "self.pub.publish(Force(newtons=0.0))",
        ),
    )
    .unwrap();
    let screen = lab.wait_until("the node's reload", Duration::from_secs(15), |s| {
        s.contains("reloaded") && s.contains("other/policy.py:")
    });
    assert!(screen.contains("→ fell at"), "{screen}");
    lab.quit();
}

/// A graph of 200 nodes in the lab at the two sizes it is made for (issue 51): at first
/// its columns show what fits and count the rest; ↓ scrolls them; `z` zooms to names and
/// then to a list of every node and topic with its figures; `/` filters by name as it is
/// typed; Tab selects among what the filter shows; Esc clears the selection, then the
/// filter.
#[test]
fn a_200_node_graph_in_the_lab_scrolls_zooms_filters_and_selects() {
    let _machine = crate::machine::alone();
    let dir = tempfile::tempdir().unwrap();
    let graph = crate::large_graphs::generated(dir.path(), "big.toml", 200, 1);
    for (cols, rows) in [(80, 24), (120, 40)] {
        let mut lab = Lab::start_sized(&["--clock", "virtual", "--graph", &graph], &[], cols, rows);
        let at = format!("{cols}x{rows}");
        let screen = lab.wait_for("BALANCED", Duration::from_secs(90));
        // Boxes: the first of each column, and how many more below.
        assert!(screen.contains("more ↓"), "{at}:\n{screen}");
        // ↓ scrolls every column: the rows above are counted too.
        press(&mut lab, &["\x1b[B"; 3]);
        lab.wait_for("↑3 ↓", Duration::from_secs(5));
        // z: names, a row each.
        type_slowly(&mut lab, "z");
        lab.wait_for("graph: names", Duration::from_secs(5));
        // z: the list, every node and topic with its figures.
        type_slowly(&mut lab, "z");
        let list = lab.wait_for("NODES 200", Duration::from_secs(5));
        assert!(list.contains("graph as a list"), "{at}:\n{list}");
        assert!(list.contains("Hz"), "{at}: a node's rate:\n{list}");
        // ↓ scrolls the list; Home goes back to its top.
        press(&mut lab, &["\x1b[B"; 2]);
        lab.wait_for("↑2 ↓", Duration::from_secs(5));
        press(&mut lab, &["\x1b[H"]);
        lab.wait_for("NODES 200", Duration::from_secs(5));
        // `/safety_4`: the safety nodes 4 and 40–48 (49 controllers), and what they
        // publish.
        type_slowly(&mut lab, "/safety_4");
        let typed = lab.wait_for("filter: safety_4", Duration::from_secs(5));
        assert!(typed.contains("NODES 10"), "{at}:\n{typed}");
        assert!(typed.contains("TOPICS 10"), "{at}:\n{typed}");
        type_slowly(&mut lab, "\r");
        let filtered = lab.wait_for("/safety_4 · z boxes", Duration::from_secs(5));
        for name in ["safety_4 ", "safety_48", "/c_4/cmd"] {
            assert!(filtered.contains(name), "{at}: {name} missing:\n{filtered}");
        }
        assert!(!filtered.contains("sensor_4 "), "{at}:\n{filtered}");
        // Tab selects the first node the filter shows; its rate keys act on it.
        type_slowly(&mut lab, "\t");
        lab.wait_for("safety_4 selected", Duration::from_secs(5));
        type_slowly(&mut lab, "\t");
        lab.wait_for("safety_40 selected", Duration::from_secs(5));
        // Esc: the selection, then the filter; the list is whole again.
        type_slowly(&mut lab, "\x1b");
        type_slowly(&mut lab, "\x1b");
        lab.wait_for("NODES 200", Duration::from_secs(5));
        // z: the boxes again, the chapter's nodes first.
        type_slowly(&mut lab, "z");
        lab.wait_until("the boxes again", Duration::from_secs(5), |s| {
            !s.contains("NODES 200") && s.contains("more ↓")
        });
        lab.quit();
    }
}

/// `ratelab top` on a terminal shows a 200-node launch a page at a time: PgDn turns the
/// page, `s` sorts by the next column, `q` quits and gives the terminal back.
#[test]
fn top_pages_and_sorts_a_large_graph_on_a_terminal() {
    let _machine = crate::machine::alone();
    let dir = tempfile::tempdir().unwrap();
    let graph = crate::large_graphs::generated(dir.path(), "big.toml", 200, 2);
    let port = crate::distributed::free_port();
    let (mut launcher, _rx, _lines) = crate::distributed::ready_launch_of(
        Some(std::path::Path::new(&graph)),
        "real",
        "60",
        port,
        dir.path(),
    );
    let ep = format!("tls/127.0.0.1:{port}");
    let creds = dir.path().join("creds.toml");
    let mut top = Lab::start_program(
        env!("CARGO_BIN_EXE_ratelab").as_ref(),
        &[
            "top",
            "--connect",
            &ep,
            "--credentials",
            creds.to_str().unwrap(),
        ],
        &[],
        80,
        24,
    );
    let first = top.wait_for("page 1/", Duration::from_secs(20));
    assert!(first.contains("sorted by name"), "{first}");
    let pages: usize = first
        .split("page 1/")
        .nth(1)
        .and_then(|s| s.split(' ').next())
        .and_then(|n| n.parse().ok())
        .unwrap_or_else(|| panic!("{first}"));
    assert!(pages > 10, "200 nodes in pages of 24 rows: {first}");
    press(&mut top, &["\x1b[6~"]);
    top.wait_for("page 2/", Duration::from_secs(5));
    type_slowly(&mut top, "s");
    let sorted = top.wait_for("sorted by rate", Duration::from_secs(5));
    assert!(
        sorted.contains("page 1/"),
        "a new sort starts at the first page:\n{sorted}"
    );
    press(&mut top, &["\x1b[F"]);
    top.wait_for(&format!("page {pages}/{pages}"), Duration::from_secs(5));
    top.keys("q");
    let status = top.exit_status("q");
    assert!(status.success(), "{status:?}");
    let _ = launcher.kill();
    let _ = launcher.wait();
}

/// The run time the lab's header shows (`│ t 12.34 s │`), s.
fn shown_run_time(screen: &str) -> Option<f64> {
    screen
        .split_once("│ t ")?
        .1
        .split_whitespace()
        .next()?
        .parse()
        .ok()
}

/// Saving a node whose import never returns (issue 75: a sleep or a busy loop at module
/// level) never holds the lab, under either clock: the run on screen goes on (its time
/// advances), the footer says `loading FILE has not returned after 2 s; the run on screen
/// is the code before` (no node is shown hung: the stuck code is not the run's), a newer
/// save supersedes it and is taken up, and `q` quits at once with exit 0.
#[test]
fn saving_a_node_whose_import_never_returns_never_holds_the_lab() {
    let _machine = crate::machine::alone();
    let sleep = "import time\ntime.sleep(10**6)\n";
    let busy = "while True:\n    pass\n";
    for (clock, hang, supersede) in [
        ("virtual", sleep, false),
        ("virtual", busy, true),
        ("real", sleep, true),
        ("real", busy, false),
    ] {
        let case = format!("{clock} clock, {hang:?}");
        let dir = tempfile::tempdir().unwrap();
        let (graph, node, script) = crate::python_graph_copy(dir.path());
        let mut lab = Lab::start_sized(
            &["--clock", clock, "--graph", graph.to_str().unwrap()],
            &[],
            120,
            40,
        );
        lab.wait_for_the_run();
        std::fs::write(&node, format!("{hang}{script}")).unwrap();
        // Said once the import has run 2 s (the wait leaves a loaded machine room).
        let screen = lab.wait_for(
            "has not returned after 2 s; the run on screen is the code before",
            Duration::from_secs(15),
        );
        assert!(
            screen.contains("loading ") && screen.contains("scripted_balancer.py has not returned"),
            "{case}:\n{screen}"
        );
        assert!(
            !screen.contains("HUNG"),
            "{case}: the stuck import is not the run's:\n{screen}"
        );
        // The run on screen goes on.
        let t0 = shown_run_time(&screen).unwrap_or_else(|| panic!("{case}:\n{screen}"));
        lab.wait_until("the run time advancing", Duration::from_secs(10), |s| {
            shown_run_time(s).is_some_and(|t| t >= t0 + 0.5)
        });
        if supersede {
            // A newer save supersedes the stuck one, and is taken up.
            std::fs::write(&node, &script).unwrap();
            let screen = lab.wait_until("the newer save taken up", Duration::from_secs(15), |s| {
                s.contains("reloaded ") && s.contains("scripted_balancer.py:")
            });
            assert!(!screen.contains("not reloaded"), "{case}:\n{screen}");
        }
        let sent = Instant::now();
        lab.keys("q");
        let status = lab.exit_status(&format!("q ({case})"));
        // Loose for a loaded machine: the bug is never ending (exit_status gives up at 15 s).
        assert!(
            sent.elapsed() < Duration::from_secs(5),
            "{case}: {:?}",
            sent.elapsed()
        );
        assert!(status.success(), "{case}: {status:?}");
    }
}
