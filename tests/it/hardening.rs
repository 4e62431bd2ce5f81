//! Every path in and out, held to one rule per class of fault, across the commands it
//! touches: text from outside never reaches a terminal raw; a duration that rounds to 0 ns
//! where 0 means nothing is refused; a closed stdout ends any subcommand quietly; a full
//! disk fails `--out`, `--record` and `--bag` in one line, leaving no half-written file
//! under its name; a node publishing 10⁴ messages a tick runs across processes.
//! (Failed nodes in every layout, brains' odd values and stops: `python.rs`; hostile ROS 2
//! tokens: `ros2_external.rs`; credentials: `security.rs`; launch records: `distributed.rs`.)

use std::os::fd::{FromRawFd, OwnedFd};
use std::path::Path;
use std::process::{Command, Output, Stdio};

fn bin() -> Command {
    let mut c = Command::new(env!("CARGO_BIN_EXE_ratelab"));
    c.current_dir(crate::REPO);
    c
}

fn text(b: &[u8]) -> String {
    String::from_utf8_lossy(b).into_owned()
}

/// `ratelab ARGS` (in the repository) refused: exit 2, one line of stderr holding `needle`,
/// no raw control character, no panic.
fn assert_refused(args: &[&str], needle: &str) -> String {
    let o = bin().args(args).output().unwrap();
    let err = text(&o.stderr);
    assert_eq!(o.status.code(), Some(2), "{args:?}: {err}");
    assert_eq!(
        err.trim_end().lines().count(),
        1,
        "{args:?}: one line: {err:?}"
    );
    assert!(err.contains(needle), "{args:?}: {err:?} lacks {needle:?}");
    assert!(
        !err.trim_end().chars().any(char::is_control),
        "{args:?}: a raw control character: {err:?}"
    );
    assert!(!err.contains("panicked"), "{err}");
    err
}

#[test]
fn text_from_outside_never_reaches_the_terminal_raw() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    // A flag's value with a newline or an escape sequence: one line that shows it.
    for (args, shown) in [
        (
            vec!["launch", "--processes", "--listen", "tls/127.0.0.1:7449\n"],
            "tls/127.0.0.1:7449\\n",
        ),
        (
            vec!["run", "--graph", "g\u{1b}[2J.toml"],
            "g\\u{1b}[2J.toml",
        ),
        (vec!["run", "--policy", "brain\r.py"], "brain\\r.py"),
    ] {
        let err = assert_refused(&args, "holds a control character");
        assert!(err.contains(shown), "{err}");
    }
    // A graph file's name, kind, class and keys: quoted in errors, written out.
    let chapter = std::fs::read_to_string(crate::repo("graphs/cartpole.toml")).unwrap();
    let python = std::fs::read_to_string(crate::repo("graphs/cartpole-python.toml")).unwrap();
    let g = |name: &str, text: String| {
        let p = d.join(name);
        std::fs::write(&p, text).unwrap();
        p.to_string_lossy().into_owned()
    };
    let bad_name = g(
        "name.toml",
        chapter.replacen("name = \"cartpole\"", "name = \"x\\u001b[2Jy\"", 1),
    );
    assert_refused(
        &["run", "--graph", &bad_name],
        "name 'x\\u{1b}[2Jy' holds a control character",
    );
    let bad_kind = g(
        "kind.toml",
        chapter.replacen("kind = \"policy\"", "kind = \"po\\u001b[2Jlicy\"", 1),
    );
    assert_refused(&["run", "--graph", &bad_kind], "po\\u{1b}[2Jlicy");
    assert!(python.contains("[[node]]"));
    let key = g(
        "key.toml",
        chapter.replacen(
            "kind = \"policy\"",
            "kind = \"policy\"\nparams = { \"k\\u001b[31m\" = 1 }",
            1,
        ),
    );
    assert_refused(&["run", "--graph", &key], "k\\u{1b}[31m");
    // A Python node's logger: its lines reach stderr written out.
    std::fs::create_dir_all(d.join("nodes")).unwrap();
    let balancer =
        std::fs::read_to_string(crate::repo("graphs/nodes/scripted_balancer.py")).unwrap();
    let timer = "    def on_timer(self):\n";
    assert!(balancer.contains(timer));
    std::fs::write(
        d.join("nodes/loud.py"),
        balancer.replace(
            "        node.create_timer(",
            "        node.get_logger().warn('\\x1b[2J\\x1b]0;pwned\\x07 cleared')\n        node.create_timer(",
        ),
    )
    .unwrap();
    let loud = g(
        "loud.toml",
        python.replace("nodes/scripted_balancer.py", "nodes/loud.py"),
    );
    let o = bin()
        .args(["run", "--graph", &loud, "--duration", "0.2"])
        .output()
        .unwrap();
    let err = text(&o.stderr);
    assert!(o.status.success(), "{err}");
    assert!(
        err.contains("[policy] warning: \\u{1b}[2J\\u{1b}]0;pwned\\u{7} cleared"),
        "{err}"
    );
    assert!(!err.contains('\u{1b}'), "raw ESC: {err:?}");
}

#[test]
fn durations_that_round_to_zero_are_refused_in_files_and_flags() {
    let dir = tempfile::tempdir().unwrap();
    let safety = std::fs::read_to_string(crate::repo("graphs/cartpole-safety.toml")).unwrap();
    let with = |name: &str, extra: &str| {
        let p = dir.path().join(name);
        let text = safety.replacen(
            "[[topic]]\nname = \"/cmd\"",
            &format!("[[topic]]\nname = \"/cmd\"\n{extra}"),
            1,
        );
        assert_ne!(text, safety, "the safety graph has a /cmd topic");
        std::fs::write(&p, text).unwrap();
        p.to_string_lossy().into_owned()
    };
    for key in ["deadline_ms", "lifespan_ms"] {
        let g = with(&format!("{key}.toml"), &format!("{key} = 1e-300"));
        assert_refused(
            &["run", "--graph", &g],
            &format!("{key} = 1e-300 ms rounds to 0 ns"),
        );
        let qos = format!("/cmd:{key}=1e-300");
        assert_refused(
            &[
                "run",
                "--graph",
                "graphs/cartpole-safety.toml",
                "--qos",
                &qos,
            ],
            "rounds to 0 ns",
        );
    }
    assert_refused(
        &[
            "run",
            "--graph",
            "graphs/cartpole-safety.toml",
            "--link",
            "/cmd:loss=0.1,retransmit_ms=1e-300",
        ],
        "retransmit_ms = 1e-300 ms rounds to 0 ns",
    );
    let lease = dir.path().join("lease.toml");
    std::fs::write(
        &lease,
        safety.replacen(
            "kind = \"policy\"",
            "kind = \"policy\"\nliveliness_lease_ms = 1e-300",
            1,
        ),
    )
    .unwrap();
    assert_refused(
        &["run", "--graph", lease.to_str().unwrap()],
        "liveliness_lease_ms = 1e-300 ms rounds to 0 ns",
    );
    assert_refused(&["run", "--lease", "policy=1e-300"], "rounds to 0 ns");
    // The smallest duration that is one: accepted.
    let ok = with("one_ns.toml", "deadline_ms = 0.000001");
    let o = bin()
        .args(["run", "--graph", &ok, "--duration", "0.1"])
        .output()
        .unwrap();
    assert!(o.status.code() != Some(2) || !text(&o.stderr).contains("rounds to 0"));
}

/// A pipe whose reading end is already closed: every write to it fails (EPIPE).
fn closed_pipe() -> OwnedFd {
    let mut fds = [0; 2];
    // SAFETY: pipe(2) fills two fresh descriptors that we then own.
    assert_eq!(unsafe { libc::pipe(fds.as_mut_ptr()) }, 0);
    // SAFETY: both are ours; the reading end is closed at once.
    unsafe {
        drop(OwnedFd::from_raw_fd(fds[0]));
        OwnedFd::from_raw_fd(fds[1])
    }
}

#[test]
fn a_closed_stdout_ends_every_subcommand_quietly() {
    let _m = crate::machine::shared();
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let exercises = Path::new(crate::REPO).join("exercises");
    for f in ["bands.toml", "ex2_queue_trap.toml"] {
        std::fs::copy(exercises.join(f), d.join(f)).unwrap();
    }
    let ex2 = d.join("ex2_queue_trap.toml");
    let predicted = std::fs::read_to_string(&ex2)
        .unwrap()
        .replace("# deep_queue_obs_drops =\n", "deep_queue_obs_drops = 0\n")
        .replace("# deep_queue_balances =\n", "deep_queue_balances = false\n")
        .replace("why = \"\"", "why = \"newest only\"");
    std::fs::write(&ex2, predicted).unwrap();
    let npz = d.join("w.npz");
    let pt = crate::brains::fixture("ppo_ch2.1_seed0.pt");
    let (ds, npz, pt) = (
        d.to_str().unwrap(),
        npz.to_str().unwrap(),
        pt.to_str().unwrap(),
    );
    // A lab session's log, for `replay`.
    let session = d.join("s.json");
    let mut script = crate::session::steps(30);
    script.push(ratelab::session::Control::Quit);
    crate::session::drive(&script, &session);
    let session = session.to_str().unwrap();
    for args in [
        vec!["run", "--smoke"],
        vec!["run", "--duration", "1", "--out", &format!("{ds}/out")],
        vec![
            "sweep",
            "--control-hz",
            "50,5",
            "--seeds",
            "0",
            "--duration",
            "1",
        ],
        vec!["cliff", "--seeds", "0"],
        vec!["exercise", "ex2", "--dir", ds],
        vec!["launch", "--duration", "1"],
        vec!["bench", "--hz", "200", "--duration", "0.2"],
        vec!["export", pt, "--out", npz],
        vec!["replay", session],
        vec!["--help"],
    ] {
        let o: Output = bin()
            .args(&args)
            .stdout(Stdio::from(closed_pipe()))
            .stderr(Stdio::piped())
            .output()
            .unwrap();
        let err = text(&o.stderr);
        assert!(
            matches!(o.status.code(), Some(0 | 141)),
            "{args:?}: exit {:?}: {err}",
            o.status.code()
        );
        assert!(
            !err.contains("panicked") && !err.contains("RUST_BACKTRACE"),
            "{args:?}: {err}"
        );
    }
    // What a run writes besides stdout is still written.
    assert!(d.join("out/metrics.json").exists() && d.join("out/trace.csv").exists());
}

/// Run `ratelab ARGS` in a private mount namespace where `full` is a 16 KiB tmpfs (a full
/// disk); returns its output, whose last line of stderr lists what was left in `full`
/// (`LEFT: …`). `None` where the machine allows no such namespace (not root).
fn on_a_full_disk(full: &Path, args: &[&str]) -> Option<Output> {
    // As root a mount namespace; otherwise one inside a user namespace, where allowed.
    let works = |flags: &[&str]| {
        Command::new("unshare")
            .args(flags)
            .args(["--propagation", "private", "true"])
            .output()
            .is_ok_and(|o| o.status.success())
    };
    let flags: &[&str] = if works(&["-m"]) {
        &["-m"]
    } else if works(&["-r", "-m"]) {
        &["-r", "-m"]
    } else {
        return None;
    };
    std::fs::create_dir_all(full).unwrap();
    let script = "mount -t tmpfs -o size=16k tmpfs \"$0\" || exit 97; \"$@\"; code=$?; \
                  echo \"LEFT: $(cd \"$0\" && find . -mindepth 1 | sort | tr '\\n' ' ')\" >&2; \
                  exit $code";
    let o = Command::new("unshare")
        .args(flags)
        .args(["--propagation", "private", "sh", "-c", script])
        .arg(full)
        .arg(env!("CARGO_BIN_EXE_ratelab"))
        .args(args)
        .current_dir(crate::REPO)
        // `--ros2` without a router (a bag needs none): connect nowhere, check for none.
        .env("ZENOH_ROUTER_CHECK_ATTEMPTS", "-1")
        .env(
            "ZENOH_CONFIG_OVERRIDE",
            format!(
                "connect/endpoints=[\"tcp/127.0.0.1:{}\"]",
                crate::distributed::free_port()
            ),
        )
        .env_remove("ROS_DOMAIN_ID")
        .output()
        .unwrap();
    assert_ne!(o.status.code(), Some(97), "tmpfs: {}", text(&o.stderr));
    Some(o)
}

#[test]
fn a_full_disk_fails_out_record_and_bag_in_one_line_leaving_nothing_half_written() {
    let dir = tempfile::tempdir().unwrap();
    let full = dir.path().join("full");
    let f = full.to_str().unwrap();
    for (args, needle, left) in [
        (
            vec!["run", "--clock", "virtual", "--out", &format!("{f}/out")],
            "No space left on device",
            "./out ./out/metrics.json",
        ),
        (
            // A recording cut short is kept (it opens as one), and said to be.
            vec![
                "run",
                "--clock",
                "virtual",
                "--record",
                &format!("{f}/r.rrd"),
            ],
            "(No space left on device (os error 28)): cut short",
            "./r.rrd",
        ),
        (
            vec![
                "run",
                "--clock",
                "virtual",
                "--ros2",
                "--bag",
                &format!("{f}/bag"),
            ],
            "--bag ",
            "./bag",
        ),
    ] {
        let Some(o) = on_a_full_disk(&full, &args) else {
            eprintln!("skipped: no private mount namespace here (not root)");
            return;
        };
        let err = text(&o.stderr);
        let lines: Vec<&str> = err.trim_end().lines().collect();
        let (last, ratelab_err) = (lines[lines.len() - 1], lines[lines.len() - 2]);
        assert_eq!(o.status.code(), Some(2), "{args:?}: {err}");
        assert!(
            ratelab_err.starts_with("error: ") && ratelab_err.contains(needle),
            "{args:?}: {err}"
        );
        assert_eq!(
            last.trim_end(),
            format!("LEFT: {left}").trim_end(),
            "{args:?}: {err}"
        );
        // The summary came first: a full disk costs the files, not the run's result.
        assert!(text(&o.stdout).contains("BALANCED"), "{args:?}");
    }
}

/// A node that publishes 10⁴ messages a tick: in one process every one is delivered;
/// across processes the launch accepts the true counts (256 a tick cross, the rest are
/// counted lost on the wire), where it refused the report before.
#[test]
fn a_node_publishing_ten_thousand_messages_a_tick_runs_across_processes() {
    let _m = crate::machine::shared();
    let dir = tempfile::tempdir().unwrap();
    std::fs::create_dir(dir.path().join("nodes")).unwrap();
    let script = std::fs::read_to_string(crate::repo("graphs/nodes/scripted_balancer.py")).unwrap();
    let last = "        self.pub.publish(Force(newtons=float(command) * MOTOR_N))";
    assert!(script.contains(last));
    let burst = script.replace(
        last,
        &format!("        zero = Force(newtons=0.0)\n        for _ in range(9999):\n            self.pub.publish(zero)\n{last}"),
    );
    std::fs::write(dir.path().join("nodes/burst.py"), burst).unwrap();
    let graph = std::fs::read_to_string(crate::repo("graphs/cartpole-python.toml"))
        .unwrap()
        .replace("nodes/scripted_balancer.py", "nodes/burst.py");
    let file = dir.path().join("burst.toml");
    std::fs::write(&file, graph).unwrap();
    let out = dir.path().join("out");
    let o = bin()
        .args(["launch", file.to_str().unwrap(), "--processes"])
        .args(["--clock", "virtual", "--duration", "0.2", "--out"])
        .arg(&out)
        .output()
        .unwrap();
    assert!(o.status.success(), "{}{}", text(&o.stdout), text(&o.stderr));
    let m: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("metrics.json")).unwrap()).unwrap();
    let ticks = m["nodes"]["policy"]["ticks"].as_u64().unwrap();
    assert_eq!(
        m["topics"]["/action"]["published"].as_u64(),
        Some(10_000 * ticks),
        "{m}"
    );
}

/// A sweep whose runs fail a node exits 2 after its table, and a cliff search that meets a
/// failed node says so and exits 2: a run that did not balance because its brain raised is
/// no fall (it was counted as the cliff).
#[test]
fn a_sweep_or_a_cliff_whose_runs_fail_a_node_exits_2() {
    let dir = tempfile::tempdir().unwrap();
    let brain = dir.path().join("raises.py");
    std::fs::write(&brain, "def act(obs):\n    raise RuntimeError('gave up')\n").unwrap();
    let b = brain.to_str().unwrap();
    let o = bin()
        .args([
            "sweep",
            "--control-hz",
            "50,25",
            "--seeds",
            "0",
            "--duration",
            "1",
        ])
        .args(["--policy", b])
        .output()
        .unwrap();
    let err = text(&o.stderr);
    assert_eq!(o.status.code(), Some(2), "{err}");
    assert!(
        err.trim_end().lines().last().is_some_and(|l| l
            .starts_with("error: 2 of 2 runs failed a node (the first, control ")
            && l.contains("RuntimeError: gave up")),
        "{err}"
    );
    assert!(text(&o.stdout).contains("node failed"), "the table first");
    let o = bin()
        .args(["cliff", "--seeds", "0", "--duration", "1", "--policy", b])
        .output()
        .unwrap();
    let err = text(&o.stderr);
    assert_eq!(o.status.code(), Some(2), "{err}");
    assert!(
        err.contains("error: seed 0 at control ")
            && err.contains("the cliff cannot be found past a failed node"),
        "{err}"
    );
    assert!(
        !text(&o.stdout).contains("Hz (falls there"),
        "no cliff claimed"
    );
}
