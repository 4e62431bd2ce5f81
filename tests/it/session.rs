//! Determinism survives interaction: a lab session driven by commands at virtual instants
//! replays headless to the same metrics, byte for byte.

use crossbeam_channel::unbounded;
use ratelab::run::Command;
use ratelab::session::{
    replay_run, Control, Engine, SessionLog, SessionSettings, Speed, Telemetry, UNBOUNDED,
};
use ratelab::{ClockKind, RunConfig};

/// An open-ended session with the scripted brain, logged to `file`.
fn settings(
    clock: ClockKind,
    seed: u64,
    start_paused: bool,
    speed: Speed,
    file: &std::path::Path,
) -> SessionSettings {
    SessionSettings {
        cfg: RunConfig {
            clock,
            seed,
            duration: UNBOUNDED,
            ..RunConfig::default()
        },
        policy: "scripted".into(),
        alt_policy: None,
        record: None,
        spawn: false,
        record_window: None,
        session_file: Some(file.to_path_buf()),
        start_paused,
        ros2: None,
        graph_source: None,
        control: None,
        speed,
        force: false,
    }
}

pub(crate) fn drive(script: &[Control], file: &std::path::Path) -> SessionLog {
    let settings = settings(ClockKind::Virtual, 1, true, Speed::Max, file);
    driven(settings, script).0
}

/// An engine with `settings` driven by `script` (sent at once, taken in order) to its end:
/// its session log and everything it told.
fn driven(settings: SessionSettings, script: &[Control]) -> (SessionLog, Vec<Telemetry>) {
    let (ctl_tx, ctl_rx) = unbounded();
    let (tel_tx, tel_rx) = unbounded::<Telemetry>();
    let engine = Engine::new(settings, ctl_rx, tel_tx).spawn();
    for c in script {
        ctl_tx.send(c.clone()).unwrap();
    }
    let log = engine.join().unwrap();
    (log, tel_rx.try_iter().collect())
}

/// The errors among what an engine told.
fn errors(told: impl IntoIterator<Item = Telemetry>) -> Vec<String> {
    told.into_iter()
        .filter_map(|t| match t {
            Telemetry::Error(e) => Some(e),
            _ => None,
        })
        .collect()
}

pub(crate) fn steps(n: usize) -> Vec<Control> {
    vec![Control::Step; n]
}

#[test]
fn scripted_session_replays_byte_for_byte() {
    let dir = tempfile::tempdir().unwrap();
    let file = dir.path().join("session.json");
    let mut script = steps(40);
    script.push(Control::Apply(Command::SetControlHz { hz: 20.0 }));
    script.extend(steps(25));
    script.push(Control::Apply(Command::SetQueueDepth { depth: 5 }));
    script.push(Control::Apply(Command::SetSensorHz { hz: 25.0 }));
    script.extend(steps(30));
    script.push(Control::Apply(Command::SetControlHz { hz: 7.0 }));
    script.push(Control::Apply(Command::SetQueueDepth { depth: 1 }));
    script.extend(steps(60));
    script.push(Control::Reset { next_seed: true });
    script.extend(steps(10));
    script.push(Control::Apply(Command::SetControlHz { hz: 5.0 }));
    script.extend(steps(120)); // falls on the way; later steps are ignored while frozen
    script.push(Control::Quit);
    let log = drive(&script, &file);

    assert_eq!(log.runs.len(), 2);
    let first = &log.runs[0];
    assert_eq!(first.commands.len(), 5);
    assert!(first.commands.windows(2).all(|w| w[0].at_ns <= w[1].at_ns));
    // Controls were applied at virtual instants on the 20 ms actuator grid or between.
    assert!(first.commands[0].at_ns > 0);
    // The second run kept the settings as the user left them, with the next seed.
    let second = log.runs[1].config("run 2").unwrap();
    assert_eq!(
        (second.seed, second.control_hz(), second.queue_depth()),
        (2, Some(7.0), Some(1))
    );
    assert!(
        !log.runs[1].metrics.as_ref().unwrap().balanced,
        "5 Hz falls"
    );

    // The log on disk is the log returned.
    assert_eq!(SessionLog::load(&file).unwrap(), log);

    for i in 0..log.runs.len() {
        let a = serde_json::to_string_pretty(&replay_run(&log, i).unwrap()).unwrap();
        let b = serde_json::to_string_pretty(&replay_run(&log, i).unwrap()).unwrap();
        let live = serde_json::to_string_pretty(log.runs[i].metrics.as_ref().unwrap()).unwrap();
        assert_eq!(a, b, "run {i}: two replays differ");
        assert_eq!(a, live, "run {i}: replay differs from the live run");
    }
}

#[test]
fn replay_cli_reproduces_and_refuses_garbage() {
    let dir = tempfile::tempdir().unwrap();
    let file = dir.path().join("s.json");
    let mut script = steps(30);
    script.push(Control::Apply(Command::SetControlHz { hz: 10.0 }));
    script.extend(steps(30));
    script.push(Control::Quit);
    drive(&script, &file);
    let out = dir.path().join("out");
    let o = std::process::Command::new(env!("CARGO_BIN_EXE_ratelab"))
        .args([
            "replay",
            file.to_str().unwrap(),
            "--out",
            out.to_str().unwrap(),
        ])
        .output()
        .unwrap();
    let stdout = String::from_utf8_lossy(&o.stdout);
    assert!(
        o.status.success(),
        "{stdout}{}",
        String::from_utf8_lossy(&o.stderr)
    );
    assert!(stdout.contains("identical to the live run"), "{stdout}");
    // Each change is listed at its run time (the summary gives only the start and the end).
    assert!(stdout.contains("seed 1, 1 command(s) replayed"), "{stdout}");
    assert_eq!(
        stdout
            .lines()
            .filter(|l| l.contains("s: control rate → 10 Hz"))
            .count(),
        1,
        "{stdout}"
    );
    // The period reported is the one in force when the run ended (10 Hz), beside the one
    // it started with; the steps are named for what they are.
    assert!(
        stdout.contains("policy period 100 ms at the end, 20 ms at the start)"),
        "{stdout}"
    );
    assert!(
        stdout.contains("actuator steps, ") && !stdout.contains("control steps"),
        "{stdout}"
    );
    assert!(out.join("metrics-1.json").is_file());
    let m: serde_json::Value =
        serde_json::from_slice(&std::fs::read(out.join("metrics-1.json")).unwrap()).unwrap();
    assert_eq!(
        (m["control_hz"].as_f64(), m["control_hz_end"].as_f64()),
        (Some(50.0), Some(10.0))
    );
    assert_eq!(m["actuator_steps"], m["steps"]);
    // Each node's rate says where it ended when a change moved it, and only then.
    assert_eq!(m["nodes"]["policy"]["rate_hz"], 50.0);
    assert_eq!(m["nodes"]["policy"]["rate_hz_end"], 10.0);
    assert!(m["nodes"]["sensor"].get("rate_hz_end").is_none(), "{m}");
    assert!(
        stdout.contains("control 10 Hz (50 Hz at the start)") && stdout.contains("sensor 50 Hz |"),
        "{stdout}"
    );

    let junk = dir.path().join("junk.json");
    std::fs::write(&junk, "{not json").unwrap();
    let o = std::process::Command::new(env!("CARGO_BIN_EXE_ratelab"))
        .args(["replay", junk.to_str().unwrap()])
        .output()
        .unwrap();
    assert_eq!(o.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&o.stderr).contains("not a ratelab session log"));
}

#[test]
fn brain_swaps_are_logged_and_replayed() {
    let ppo = std::path::Path::new(crate::REPO).join("../shared/fixtures/ppo_ch2.1_seed0.pt");
    assert!(ppo.is_file(), "fixture missing: {}", ppo.display());
    let dir = tempfile::tempdir().unwrap();
    let mut script = steps(20);
    script.push(Control::Apply(Command::SetPolicy {
        spec: ppo.to_str().unwrap().into(),
    }));
    script.extend(steps(20));
    script.push(Control::Apply(Command::SetPolicy {
        spec: "/no/such/brain.pt".into(),
    })); // refused
    script.extend(steps(20));
    script.push(Control::Apply(Command::SetPolicy {
        spec: "scripted".into(),
    }));
    script.extend(steps(20));
    script.push(Control::Quit);
    let log = drive(&script, &dir.path().join("s.json"));
    let run = &log.runs[0];
    let swaps: Vec<&Command> = run.commands.iter().map(|c| &c.command).collect();
    assert_eq!(swaps.len(), 2, "the refused swap is not logged: {swaps:?}");
    let replayed = serde_json::to_string(&replay_run(&log, 0).unwrap()).unwrap();
    assert_eq!(
        replayed,
        serde_json::to_string(run.metrics.as_ref().unwrap()).unwrap()
    );
}

#[test]
fn a_real_clock_run_is_logged_with_node_timing_and_not_replayed() {
    let _machine = crate::machine::alone();
    let dir = tempfile::tempdir().unwrap();
    let (ctl_tx, ctl_rx) = unbounded();
    let (tel_tx, tel_rx) = unbounded::<Telemetry>();
    let settings = settings(
        ClockKind::Real,
        0,
        false,
        Speed::Times(1.0),
        &dir.path().join("real.json"),
    );
    let engine = Engine::new(settings, ctl_rx, tel_tx).spawn();
    // Quit after 11 actuator steps have been told, not after a fixed time a loaded machine
    // may not fill; the deadline only bounds a hang.
    let deadline = std::time::Instant::now() + std::time::Duration::from_secs(20);
    let mut stepped = 0;
    while stepped < 11 {
        let left = deadline.saturating_duration_since(std::time::Instant::now());
        if let Telemetry::Step(_) = tel_rx.recv_timeout(left).expect("11 steps within 20 s") {
            stepped += 1;
        }
    }
    ctl_tx.send(Control::Quit).unwrap();
    let log = engine.join().unwrap();
    let m = log.runs[0].metrics.as_ref().unwrap();
    let timing = m
        .node_timing
        .as_ref()
        .expect("real-clock runs keep their node timing");
    assert_eq!(timing.len(), 3);
    assert!(m.steps > 10, "{m:?}");
    assert!(matches!(
        replay_run(&log, 0),
        Err(ratelab::session::ReplayError::RealClock(1))
    ));
}

/// A session log with one virtual run that changed rate and depth, as JSON to edit.
fn valid_log(dir: &std::path::Path) -> serde_json::Value {
    let file = dir.join("valid.json");
    let mut script = steps(10);
    script.push(Control::Apply(Command::SetControlHz { hz: 20.0 }));
    script.extend(steps(10));
    script.push(Control::Apply(Command::SetQueueDepth { depth: 5 }));
    script.extend(steps(10));
    script.push(Control::Quit);
    drive(&script, &file);
    serde_json::from_str(&std::fs::read_to_string(&file).unwrap()).unwrap()
}

/// `ratelab replay` on `text`: (exit code, stderr).
fn replay_text(dir: &std::path::Path, text: &str) -> (Option<i32>, String) {
    let file = dir.join("edited.json");
    std::fs::write(&file, text).unwrap();
    replay_path(&file)
}

fn replay_path(file: &std::path::Path) -> (Option<i32>, String) {
    let start = std::time::Instant::now();
    let o = std::process::Command::new(env!("CARGO_BIN_EXE_ratelab"))
        .args(["replay"])
        .arg(file)
        .output()
        .unwrap();
    assert!(
        start.elapsed() < std::time::Duration::from_secs(10),
        "replay took {:?}",
        start.elapsed()
    );
    (
        o.status.code(),
        String::from_utf8_lossy(&o.stderr).into_owned(),
    )
}

/// A session that started no run replays to a line saying so, not to silence; a node
/// killed twice, and a stall over before the instant it was injected at, are refused.
#[test]
fn an_empty_session_says_so_and_a_double_kill_or_a_stall_already_over_is_refused() {
    let dir = tempfile::tempdir().unwrap();
    let file = dir.path().join("empty.json");
    std::fs::write(&file, r#"{"version": 2, "runs": []}"#).unwrap();
    let o = std::process::Command::new(env!("CARGO_BIN_EXE_ratelab"))
        .arg("replay")
        .arg(&file)
        .output()
        .unwrap();
    assert_eq!(o.status.code(), Some(0));
    let out = String::from_utf8_lossy(&o.stdout);
    assert!(out.contains("no runs to replay"), "{out}");

    let log = valid_log(dir.path());
    let mut v = log.clone();
    v["runs"][0]["faults"] = serde_json::json!([
        {"node": "actuator", "at": 3_000_000_000u64, "duration": null},
        {"node": "actuator", "at": 2_000_000_000u64, "duration": null},
    ]);
    let (code, err) = replay_text(dir.path(), &v.to_string());
    assert_eq!(code, Some(2), "{err}");
    assert!(
        err.contains(
            r#"kill["actuator"]=3 and kill["actuator"]=2 both kill node 'actuator'; give one"#
        ),
        "{err}"
    );
    // A stall over before the instant it was logged for.
    let mut v = log.clone();
    v["runs"][0]["commands"][0] = serde_json::json!(
        {"at_ns": 3_000_000_000u64, "cmd": "inject_fault", "fault": "sensor@0.5+0.2"}
    );
    let (code, err) = replay_text(dir.path(), &v.to_string());
    assert_eq!(code, Some(2), "{err}");
    assert!(err.contains("commands[0]: stall sensor@"), "{err}");
    assert!(
        err.contains("over at 0.7 s, before the instant it would take effect (3 s)"),
        "{err}"
    );
}

#[test]
fn hand_edited_session_logs_are_checked_like_the_command_line() {
    let dir = tempfile::tempdir().unwrap();
    let log = valid_log(dir.path());
    assert_eq!(log["version"], 3);
    let (code, err) = replay_text(dir.path(), &log.to_string());
    assert_eq!(code, Some(0), "the unedited log replays: {err}");
    type Edit = fn(&mut serde_json::Value);
    let cases: [(&str, Edit, &str); 12] = [
        (
            "unknown version",
            |v| v["version"] = 99.into(),
            "version 99",
        ),
        (
            "rate 0",
            |v| v["runs"][0]["commands"][0]["hz"] = 0.0.into(),
            "commands[0]: --control-hz",
        ),
        (
            "negative rate",
            |v| v["runs"][0]["commands"][0]["hz"] = (-5.0).into(),
            "commands[0]: --control-hz",
        ),
        (
            "depth 0",
            |v| v["runs"][0]["commands"][1]["depth"] = 0.into(),
            "commands[1]",
        ),
        (
            "depth 2^64",
            |v| {
                v["runs"][0]["commands"][1]["depth"] = serde_json::Value::Number(
                    serde_json::Number::from_f64(1.8446744073709552e19).unwrap(),
                )
            },
            "not a ratelab session log",
        ),
        (
            "out of order",
            |v| v["runs"][0]["commands"][1]["at_ns"] = 0.into(),
            "before the previous",
        ),
        (
            "end after the longest run",
            |v| v["runs"][0]["end_ns"] = 400_000_000_000_000_000u64.into(),
            "end_ns",
        ),
        (
            "end at u64::MAX",
            |v| v["runs"][0]["end_ns"] = u64::MAX.into(),
            "end_ns",
        ),
        (
            "a tiny actuator rate in the graph",
            |v| {
                let g = v["runs"][0]["graph"].as_str().unwrap().replacen(
                    "rate_hz = 50.0\nsubscribes = \"/action\"",
                    "rate_hz = 1e-9\nsubscribes = \"/action\"",
                    1,
                );
                v["runs"][0]["graph"] = g.into();
            },
            "graph:",
        ),
        (
            "a missing brain",
            |v| v["runs"][0]["policy"] = "/no/such/brain.pt".into(),
            "brain.pt",
        ),
        (
            "a swap to a missing brain",
            |v| {
                v["runs"][0]["commands"][0] = serde_json::json!({"at_ns": 200000000u64, "cmd": "set_policy", "spec": "/no/such.onnx"});
            },
            "commands[0]",
        ),
        (
            "an unknown field",
            |v| v["runs"][0]["speed"] = 3.into(),
            "unknown field",
        ),
    ];
    for (name, edit, want) in cases {
        let mut v = log.clone();
        edit(&mut v);
        let (code, err) = replay_text(dir.path(), &v.to_string());
        assert_eq!(code, Some(2), "{name}: {err}");
        assert_eq!(err.lines().count(), 1, "{name}: one line: {err}");
        assert!(err.contains(want), "{name}: want '{want}' in: {err}");
        assert!(!err.contains("panicked"), "{name}: {err}");
    }
}

/// `ratelab replay FILE`: (exit code, stdout, stderr).
fn replay_out(file: &std::path::Path) -> (Option<i32>, String, String) {
    let o = std::process::Command::new(env!("CARGO_BIN_EXE_ratelab"))
        .arg("replay")
        .arg(file)
        .output()
        .unwrap();
    (
        o.status.code(),
        String::from_utf8_lossy(&o.stdout).into_owned(),
        String::from_utf8_lossy(&o.stderr).into_owned(),
    )
}

#[test]
fn a_change_made_paused_after_the_last_instant_then_a_restart_replays_identical() {
    // Paused after a few instants, changes, then a restart: they came after the run's last
    // instant, so they set what the run ended with (its end rate, its executors) and no
    // tick. The log keeps them for the instant after, which never ran; the replay applies
    // them at the end, as the live run did, and matches.
    let live = LiveEngine::start(ClockKind::Virtual, Speed::Max);
    let deadline = std::time::Instant::now() + std::time::Duration::from_secs(20);
    let next = |what: &str| -> Telemetry {
        let left = deadline.saturating_duration_since(std::time::Instant::now());
        live.tel
            .recv_timeout(left)
            .unwrap_or_else(|_| panic!("no {what}"))
    };
    // One step at a time, each answered before the next is asked (steps asked at once may
    // run as one), until one is past the start.
    loop {
        live.ctl.send(Control::Step).unwrap();
        let t = loop {
            if let Telemetry::Step(s) = next("step") {
                break s.t;
            }
        };
        if t.0 > 0 {
            break;
        }
    }
    for cmd in [
        Command::SetControlHz { hz: 20.0 },
        Command::SetExecutor {
            executor: "single_threaded".into(),
        },
    ] {
        live.ctl.send(Control::Apply(cmd)).unwrap();
        while !matches!(next("change"), Telemetry::Changed { .. }) {}
    }
    live.ctl.send(Control::Reset { next_seed: false }).unwrap();
    while !matches!(next("next run"), Telemetry::Started { .. }) {}
    live.ctl.send(Control::Quit).unwrap();
    let log = live.engine.join().unwrap();
    let run = &log.runs[0];
    assert_eq!(run.applied().len(), 0, "{:?}", run.commands);
    assert_eq!(
        run.after_end().len(),
        2,
        "{:?} end {}",
        run.commands,
        run.end_ns
    );
    let file = live._dir.path().join("replayed.json");
    log.save(&file).unwrap();
    let (code, out, err) = replay_out(&file);
    assert_eq!(code, Some(0), "{out}{err}");
    assert!(
        out.contains("run 1: seed 0, 0 command(s) replayed"),
        "{out}"
    );
    assert!(
        out.contains("after its last instant (0.")
            && out.contains("control rate → 20 Hz")
            && out.contains("executor → single_threaded"),
        "{out}"
    );
    assert!(out.contains("identical to the live run"), "{out}");
}

#[test]
fn replay_refuses_what_is_not_a_regular_file_and_caps_the_size() {
    let dir = tempfile::tempdir().unwrap();
    for special in ["/dev/zero", "/dev/urandom"] {
        let (code, err) = replay_path(std::path::Path::new(special));
        assert_eq!(code, Some(2), "{special}: {err}");
        assert!(err.contains("not a regular file"), "{special}: {err}");
    }
    let fifo = dir.path().join("fifo");
    let c = std::ffi::CString::new(fifo.to_str().unwrap()).unwrap();
    // SAFETY: a valid, NUL-terminated path.
    assert_eq!(unsafe { libc::mkfifo(c.as_ptr(), 0o600) }, 0);
    let (code, err) = replay_path(&fifo);
    assert_eq!(code, Some(2), "{err}");
    assert!(err.contains("not a regular file"), "{err}");
    let big = dir.path().join("big.json");
    std::fs::write(&big, vec![b' '; 5 * 1024 * 1024]).unwrap();
    let (code, err) = replay_path(&big);
    assert_eq!(code, Some(2), "{err}");
    assert!(err.contains("at most"), "{err}");
}

#[test]
fn a_version_1_log_still_replays() {
    // The format before graphs were data: the chapter's rates and depth per run.
    let dir = tempfile::tempdir().unwrap();
    let mut v = valid_log(dir.path());
    let run = v["runs"][0].as_object_mut().unwrap();
    run.remove("graph");
    run.insert("sensor_hz".into(), 50.0.into());
    run.insert("control_hz".into(), 50.0.into());
    run.insert("actuator_hz".into(), 50.0.into());
    run.insert("queue_depth".into(), 1.into());
    let metrics = run["metrics"].as_object_mut().unwrap();
    for key in ["graph", "nodes", "topics"] {
        metrics.remove(key);
    }
    v["version"] = 1.into();
    let file = dir.path().join("v1.json");
    std::fs::write(&file, v.to_string()).unwrap();
    let o = std::process::Command::new(env!("CARGO_BIN_EXE_ratelab"))
        .args(["replay"])
        .arg(&file)
        .output()
        .unwrap();
    let out = String::from_utf8_lossy(&o.stdout);
    assert!(
        o.status.success(),
        "{out}{}",
        String::from_utf8_lossy(&o.stderr)
    );
    assert!(out.contains("identical to the live run"), "{out}");
}

#[test]
fn the_labs_later_recordings_never_replace_a_file_without_force() {
    let dir = tempfile::tempdir().unwrap();
    let canary = dir.path().join("rec-2.rrd");
    std::fs::write(&canary, b"keep me").unwrap();
    for force in [false, true] {
        let (ctl_tx, ctl_rx) = unbounded();
        let (tel_tx, tel_rx) = unbounded::<Telemetry>();
        let mut s = settings(
            ClockKind::Virtual,
            0,
            true,
            Speed::Max,
            &dir.path().join(format!("s-{force}.json")),
        );
        s.record = Some(dir.path().join("rec.rrd"));
        s.force = force;
        let engine = Engine::new(s, ctl_rx, tel_tx).spawn();
        for c in steps(5) {
            ctl_tx.send(c).unwrap();
        }
        ctl_tx.send(Control::Reset { next_seed: false }).unwrap(); // run 2 → rec-2.rrd
        ctl_tx.send(Control::Quit).unwrap();
        engine.join().unwrap();
        let errors: Vec<String> = tel_rx
            .try_iter()
            .filter_map(|t| match t {
                Telemetry::Error(e) => Some(e),
                // The run could not start: said so, not as a plain error.
                Telemetry::NotStarted(e) => Some(format!("not started: {e}")),
                _ => None,
            })
            .collect();
        if force {
            assert!(errors.is_empty(), "{errors:?}");
            assert_ne!(std::fs::read(&canary).unwrap(), b"keep me");
        } else {
            assert!(
                errors
                    .iter()
                    .any(|e| e.starts_with("not started: ") && e.contains("rec-2.rrd")),
                "the second run is refused, naming the file: {errors:?}"
            );
            assert_eq!(std::fs::read(&canary).unwrap(), b"keep me");
            std::fs::remove_file(dir.path().join("rec.rrd")).unwrap();
        }
    }
}

#[test]
fn keys_pressed_after_a_fall_set_the_next_run() {
    let dir = tempfile::tempdir().unwrap();
    let file = dir.path().join("frozen.json");
    let mut script = vec![Control::Apply(Command::SetControlHz { hz: 5.0 })];
    script.extend(steps(80)); // falls at 0.84 s; later steps are ignored while frozen
    script.push(Control::Apply(Command::SetQueueDepth { depth: 100 }));
    script.push(Control::Apply(Command::SetControlHz { hz: 0.0 })); // refused, even frozen
    script.push(Control::Reset { next_seed: false });
    script.extend(steps(5));
    script.push(Control::Quit);
    let log = drive(&script, &file);
    assert_eq!(log.runs.len(), 2);
    assert!(!log.runs[0].metrics.as_ref().unwrap().balanced);
    let second = log.runs[1].config("run 2").unwrap();
    assert_eq!(
        (second.control_hz(), second.queue_depth()),
        (Some(5.0), Some(100))
    );
    // The deferred change is part of the second run's starting graph, not a logged
    // command of the first (which replays as it ran).
    assert_eq!(log.runs[0].commands.len(), 1);
    assert_eq!(
        serde_json::to_string(&replay_run(&log, 0).unwrap()).unwrap(),
        serde_json::to_string(log.runs[0].metrics.as_ref().unwrap()).unwrap()
    );
}

#[test]
fn qos_changes_and_faults_are_logged_and_replay_byte_for_byte() {
    use ratelab::qos::Fault;
    let dir = tempfile::tempdir().unwrap();
    let file = dir.path().join("session.json");
    let (ctl_tx, ctl_rx) = unbounded();
    let (tel_tx, tel_rx) = unbounded::<Telemetry>();
    let mut s = settings(ClockKind::Virtual, 3, true, Speed::Max, &file);
    s.cfg.graph = ratelab::graph::GraphSpec::load(
        &std::path::Path::new(crate::REPO).join("graphs/cartpole-safety.toml"),
    )
    .unwrap();
    s.cfg.graph.set_lease("policy", 60.0).unwrap();
    s.cfg.faults = vec![
        Fault::parse("policy@0.5+0.1", false).unwrap(),
        Fault::parse("policy@1.2", true).unwrap(),
    ];
    let engine = Engine::new(s, ctl_rx, tel_tx).spawn();
    let mut script = steps(20);
    script.push(Control::Apply(Command::SetTopicQos {
        topic: "/cmd".into(),
        pairs: "loss=0.2,delay_ms=5".into(),
    }));
    script.extend(steps(20));
    script.push(Control::Apply(Command::SetTopicQos {
        topic: "/obs".into(),
        pairs: "delivery=fifo,depth=10".into(),
    }));
    script.push(Control::Apply(Command::SetTopicQos {
        topic: "/cmd".into(),
        pairs: "deadline_ms=30".into(),
    }));
    script.extend(steps(40));
    for c in script {
        ctl_tx.send(c).unwrap();
    }
    // Paused after 80 steps (1.58 s), the engine reports its status every 33 ms of wall time.
    std::thread::sleep(std::time::Duration::from_millis(300));
    ctl_tx.send(Control::Quit).unwrap();
    let log = engine.join().unwrap();
    // The engine told the front end the policy was not alive once killed, and the
    // QoS as the commands left it.
    let statuses: Vec<Telemetry> = tel_rx
        .try_iter()
        .filter(|t| matches!(t, Telemetry::Status { .. }))
        .collect();
    assert!(
        statuses
            .iter()
            .any(|t| matches!(t, Telemetry::Status { alive, .. } if alive[1] == Some(false))),
        "no status showed the killed policy not alive"
    );
    assert!(statuses
        .iter()
        .any(|t| matches!(t, Telemetry::Status { qos, .. } if qos[2].deadline.is_some())));
    let run = &log.runs[0];
    assert_eq!(run.commands.len(), 3, "{:?}", run.commands);
    assert_eq!(run.faults.len(), 2);
    let live = run.metrics.as_ref().unwrap();
    assert!(
        live.topics["/cmd"].qos_counters.contains_key("lost"),
        "{live:?}"
    );
    assert_eq!(live.topics["/obs"].qos.as_deref(), Some("KL10 fifo"));
    assert_eq!(
        live.nodes["policy"].faulted_ticks,
        Some(5 + 20),
        "stalled 0.5–0.6 s (5 ticks), killed from 1.2 s to the last instant run, 1.58 s (20)"
    );
    let on_disk = SessionLog::load(&file).unwrap();
    assert_eq!(on_disk, log);
    let a = serde_json::to_string_pretty(&replay_run(&on_disk, 0).unwrap()).unwrap();
    assert_eq!(a, serde_json::to_string_pretty(live).unwrap());
    // A bad QoS value in a hand-edited log is refused like the flag.
    let mut v: serde_json::Value = serde_json::from_slice(&std::fs::read(&file).unwrap()).unwrap();
    v["runs"][0]["commands"][0]["pairs"] = "loss=7".into();
    let bad = dir.path().join("bad.json");
    std::fs::write(&bad, v.to_string()).unwrap();
    let e = SessionLog::load(&bad)
        .map_err(|e| e.to_string())
        .and_then(|l| replay_run(&l, 0).map(|_| ()).map_err(|e| e.to_string()))
        .unwrap_err();
    assert!(e.contains("loss must be a probability"), "{e}");
}

/// The `Applied` notes of a paused virtual session driven by `script`.
fn notes(script: &[Control]) -> Vec<String> {
    let dir = tempfile::tempdir().unwrap();
    let settings = settings(
        ClockKind::Virtual,
        0,
        true,
        Speed::Max,
        &dir.path().join("s.json"),
    );
    let (_, told) = driven(settings, script);
    told.into_iter()
        .filter_map(|t| match t {
            Telemetry::Applied(text) => Some(text),
            _ => None,
        })
        .collect()
}

/// A live rate change keeps the phase the old rate left: the lab says so, with the offset
/// from where a run started at the new rate ticks (so `ratelab run` at that rate can differ)
/// and where its ticks fall against the sensor's, and says nothing when the phases agree.
#[test]
fn a_live_rate_change_says_when_it_keeps_an_old_phase() {
    let hz = |hz: f64| Control::Apply(Command::SetControlHz { hz });
    // 50 → 12 → 10 Hz, as `-` walks the ladder: the 10 Hz ticks are off a fresh run's.
    let mut script = steps(5);
    script.push(hz(12.0));
    script.extend(steps(7));
    script.push(hz(10.0));
    script.push(Control::Quit);
    let said = notes(&script);
    assert!(
        said.iter().any(|n| n.starts_with("control rate → 10 Hz · ")
            && n.contains(" off a fresh run's phase · ticks ")
            && n.ends_with(" ms after the sensor's (r realigns)")),
        "{said:?}"
    );
    // 50 → 25 Hz after the ticks at 0 and 20 ms: the next is at 40 ms, where a fresh 25 Hz
    // run ticks too, so no note; one step earlier it is at 20 ms, 20 ms off.
    let mut script = steps(1);
    script.push(hz(25.0));
    script.push(Control::Quit);
    let said = notes(&script);
    assert!(
        said.iter()
            .any(|n| n == "control rate → 25 Hz · 20 ms off a fresh run's phase · ticks on the sensor's (r realigns)"),
        "{said:?}"
    );
    let mut script = steps(2);
    script.push(hz(25.0));
    script.push(Control::Quit);
    let said = notes(&script);
    // (The judge's verdict on a fresh run may come too: not a phase note.)
    assert!(
        said.iter().all(|n| !n.contains("off a fresh run's phase")),
        "{said:?}"
    );
}

/// A live engine for a test of its notices (held: its session file's directory).
struct LiveEngine {
    ctl: crossbeam_channel::Sender<Control>,
    tel: crossbeam_channel::Receiver<Telemetry>,
    engine: std::thread::JoinHandle<SessionLog>,
    _dir: tempfile::TempDir,
}

impl LiveEngine {
    /// An engine on the chapter's graph, started paused, under `clock`.
    fn start(clock: ClockKind, speed: Speed) -> LiveEngine {
        LiveEngine::spawn(clock, true, speed, |_| {})
    }

    /// An engine running from the start under `clock`, its run's settings changed by `edit`
    /// (the chapter's graph, run open-ended, unless `edit` says otherwise).
    fn running(clock: ClockKind, speed: Speed, edit: impl FnOnce(&mut RunConfig)) -> LiveEngine {
        LiveEngine::spawn(clock, false, speed, edit)
    }

    fn spawn(
        clock: ClockKind,
        paused: bool,
        speed: Speed,
        edit: impl FnOnce(&mut RunConfig),
    ) -> LiveEngine {
        let dir = tempfile::tempdir().unwrap();
        let mut settings = settings(clock, 0, paused, speed, &dir.path().join("session.json"));
        edit(&mut settings.cfg);
        LiveEngine::with(settings, dir)
    }

    /// An engine on `settings`, whose files are in `dir` (held while it runs).
    fn with(settings: SessionSettings, dir: tempfile::TempDir) -> LiveEngine {
        let (ctl, ctl_rx) = unbounded();
        let (tel_tx, tel) = unbounded::<Telemetry>();
        let engine = Engine::new(settings, ctl_rx, tel_tx).spawn();
        LiveEngine {
            ctl,
            tel,
            engine,
            _dir: dir,
        }
    }

    /// Apply `cmd`, then wait (at most 20 s) for the notice that contains `wanted`: the
    /// notice, and every message the engine sent before it.
    fn notice_after(&self, cmd: Command, wanted: &str) -> (String, Vec<Telemetry>) {
        self.ctl.send(Control::Apply(cmd)).unwrap();
        let deadline = std::time::Instant::now() + std::time::Duration::from_secs(20);
        let mut before = Vec::new();
        loop {
            let left = deadline.saturating_duration_since(std::time::Instant::now());
            match self.tel.recv_timeout(left) {
                Ok(Telemetry::Applied(t)) if t.contains(wanted) => return (t, before),
                Ok(other) => before.push(other),
                Err(_) => panic!("no notice with '{wanted}'"),
            }
        }
    }

    fn quit(self) {
        self.ctl.send(Control::Quit).unwrap();
        self.engine.join().unwrap();
    }
}

/// A live rate change is judged by a fresh run at the new settings (the headless result `r`
/// gives), said as a notice: at 7 Hz the chapter's graph falls at 4.06 s from a fresh start
/// (seed 0), at 25 Hz it balances, so a learner knows how long to wait before judging.
#[test]
fn a_live_rate_change_says_how_a_fresh_run_at_that_rate_goes() {
    let live = LiveEngine::start(ClockKind::Virtual, Speed::Max);
    let (t, _) = live.notice_after(Command::SetControlHz { hz: 7.0 }, "a fresh run");
    assert!(
        t.contains("control rate → 7 Hz") && t.contains("a fresh run falls at 4.06 s"),
        "{t}"
    );
    let (t, _) = live.notice_after(Command::SetControlHz { hz: 25.0 }, "a fresh run");
    assert!(t.contains("a fresh run stays up all of its 30 s"), "{t}");
    live.quit();
}

/// Under the real clock the fresh run that judges a rate is still a virtual-clock run, and
/// the notice says so (a real run at 8 Hz fell at 7.56 s once and balanced once, where the
/// virtual clock's falls at 22.50 s).
#[test]
fn under_the_real_clock_the_fresh_run_says_it_is_the_virtual_clocks() {
    let live = LiveEngine::start(ClockKind::Real, Speed::Times(1.0));
    let (t, _) = live.notice_after(Command::SetControlHz { hz: 7.0 }, "virtual-clock run");
    assert!(
        t.contains("a virtual-clock run falls at 4.06 s (real runs vary)"),
        "{t}"
    );
    live.quit();
}

/// Under the real clock a change of executors takes effect from the next run (its threads
/// are made at the start): said so, and not announced as a change of this run (no new
/// segment, no mark on the pole-angle chart, the timeline keeps the threads that run).
#[test]
fn under_the_real_clock_an_executor_change_waits_for_the_next_run() {
    let live = LiveEngine::start(ClockKind::Real, Speed::Times(1.0));
    let cmd = Command::SetExecutor {
        executor: "single_threaded".into(),
    };
    let (t, before) = live.notice_after(cmd, "executor");
    assert!(t.contains("(from the next run: r;"), "{t}");
    for m in before {
        if let Telemetry::Changed { text, .. } = m {
            panic!("announced as a change of this run: {text}");
        }
    }
    live.quit();
}

/// A fault injected while the run goes (the lab's `k`) is told as the fault itself, just
/// before the change's words, so the lab marks its node while it lasts.
#[test]
fn an_injected_fault_is_told_as_a_fault_before_its_change() {
    let live = LiveEngine::start(ClockKind::Virtual, Speed::Max);
    let cmd = Command::InjectFault {
        fault: "policy@0.5+0.25".into(),
    };
    live.ctl.send(Control::Apply(cmd)).unwrap();
    let deadline = std::time::Instant::now() + std::time::Duration::from_secs(20);
    let mut faulted = None;
    loop {
        let left = deadline.saturating_duration_since(std::time::Instant::now());
        match live.tel.recv_timeout(left) {
            Ok(Telemetry::Faulted(f)) => faulted = Some(f),
            Ok(Telemetry::Changed { text, .. }) => {
                assert!(text.starts_with("fault → stall policy@"), "{text}");
                // The words name the fault as it took effect, the one told just before.
                let told = faulted.as_ref().expect("told before its change");
                assert_eq!(text, format!("fault → {told}"));
                break;
            }
            Ok(_) => {}
            Err(_) => panic!("no change told"),
        }
    }
    let f = faulted.expect("told before its change");
    assert_eq!(
        (f.node.as_str(), f.at, f.duration),
        (
            "policy",
            ratelab::Nanos(500_000_000),
            Some(ratelab::Nanos(250_000_000))
        )
    );
    live.quit();
}

/// The engine's status carries every topic's counters, so the lab's counts stay current
/// while the actuator (whose steps carry them too) is stalled or dead: with the actuator
/// killed at 1 s of a 3 s run, no step comes after 1 s, yet the last status before the end
/// counts the 100 messages on /action nobody read, as the headless summary does (#25).
#[test]
fn the_status_keeps_counting_while_the_actuator_is_dead() {
    let live = LiveEngine::running(ClockKind::Virtual, Speed::Max, |cfg| {
        cfg.duration = ratelab::Nanos(3_000_000_000);
        cfg.faults = vec![ratelab::qos::Fault::parse("actuator@1", true).unwrap()];
    });
    let action = ratelab::graph::TopicId(1);
    let (mut last_step, mut last_counts) = (None, None);
    let deadline = std::time::Instant::now() + std::time::Duration::from_secs(20);
    let metrics = loop {
        let left = deadline.saturating_duration_since(std::time::Instant::now());
        match live
            .tel
            .recv_timeout(left)
            .expect("the run ends within 20 s")
        {
            Telemetry::Step(r) => last_step = Some(r.t),
            Telemetry::Status {
                now,
                topics: Some(t),
                ..
            } => last_counts = Some((now, t.get(action))),
            Telemetry::Ended { metrics, .. } => break metrics,
            _ => {}
        }
    };
    live.quit();
    assert_eq!(last_step, Some(ratelab::Nanos(980_000_000)));
    let (now, a) = last_counts.expect("a status with counters");
    assert_eq!(now, ratelab::Nanos(3_000_000_000));
    assert_eq!(a.dropped, metrics.topics["/action"].dropped);
    assert_eq!(a.dropped, 100);
}

/// Under the real clock a run that fell stops its clock where it fell: the engine's status
/// after the fall shows that instant, not wall time running on (#25: the lab's charts
/// scrolled the fall away within 10 s).
#[test]
fn under_the_real_clock_the_clock_stops_at_the_fall() {
    let _m = crate::machine::shared();
    // 5 Hz falls within about a second (0.84 s under the virtual clock).
    let live = LiveEngine::running(ClockKind::Real, Speed::Times(1.0), |cfg| {
        cfg.set_control_hz(5.0).unwrap()
    });
    let tel = &live.tel;
    let deadline = std::time::Instant::now() + std::time::Duration::from_secs(20);
    let metrics = loop {
        let left = deadline.saturating_duration_since(std::time::Instant::now());
        if let Telemetry::Ended { metrics, .. } =
            tel.recv_timeout(left).expect("the run falls within 20 s")
        {
            break metrics;
        }
    };
    let fell_s = metrics.fell_at_s.expect("a 5 Hz policy falls");
    // A second of statuses after the fall (one every 33 ms): every one at the run's end.
    let until = std::time::Instant::now() + std::time::Duration::from_secs(1);
    let mut shown = Vec::new();
    while let Ok(m) = tel.recv_timeout(until.saturating_duration_since(std::time::Instant::now())) {
        if let Telemetry::Status { now, .. } = m {
            shown.push(now.as_secs_f64());
        }
    }
    live.quit();
    assert!(
        shown.len() >= 10,
        "statuses go on after the fall: {shown:?}"
    );
    assert!(
        shown.iter().all(|t| (t - metrics.sim_time_s).abs() < 0.03),
        "fell at {fell_s} s (run time {} s), yet the clock showed {shown:?}",
        metrics.sim_time_s
    );
}

/// Restarting (`r`) after reaching a rate through another gives what that rate gives from a
/// fresh start, as headless: 10 Hz reached through 12 Hz kept 12 Hz's phase in the live run
/// (latency p50 60 / max 100 ms, #25), a fresh 10 Hz run has 40 / 80.
#[test]
fn restarting_at_a_rate_reached_through_another_gives_the_headless_result() {
    let dir = tempfile::tempdir().unwrap();
    let file = dir.path().join("session.json");
    let mut script = vec![Control::Apply(Command::SetControlHz { hz: 12.0 })];
    script.extend(steps(13));
    script.push(Control::Apply(Command::SetControlHz { hz: 10.0 }));
    script.extend(steps(100));
    script.push(Control::Reset { next_seed: false });
    script.extend(steps(100));
    script.push(Control::Quit);
    let log = drive(&script, &file);
    assert_eq!(log.runs.len(), 2);
    let live = log.runs[1]
        .metrics
        .clone()
        .expect("the second run's metrics");
    let mut cfg = log.runs[1].config("run 2").unwrap();
    assert_eq!(cfg.control_hz(), Some(10.0));
    // The same run, headless, for as long as the live one ran.
    cfg.duration = ratelab::Nanos((live.sim_time_s * 1e9).round() as u64);
    let mut fresh = RunConfig {
        clock: ClockKind::Virtual,
        seed: cfg.seed,
        duration: cfg.duration,
        ..RunConfig::default()
    };
    fresh.set_control_hz(10.0).unwrap();
    assert_eq!(
        cfg.graph, fresh.graph,
        "the restart starts the graph afresh"
    );
    assert_eq!(
        cfg.first_deadlines(),
        fresh.first_deadlines(),
        "no phase carried over"
    );
    let headless = ratelab::run(
        &fresh,
        Box::new(ratelab::policy::Scripted),
        ratelab::RunOptions::new(),
    )
    .unwrap()
    .metrics;
    assert_eq!(
        (live.latency_p50_ms, live.latency_max_ms, live.steps),
        (
            headless.latency_p50_ms,
            headless.latency_max_ms,
            headless.steps
        ),
        "live {live:?}\nheadless {headless:?}"
    );
    assert_eq!((live.latency_p50_ms, live.latency_max_ms), (40.0, 80.0));
}

/// A lab session's recording (the engine's, with a rate and a depth changed mid-run, as keys
/// change them) reads at a glance as a headless run's does, its changes marked and listed
/// at their times, and its name says the rate it ended at (`control 50 → 10 Hz`).
#[test]
fn a_lab_session_s_recording_reads_at_a_glance_and_is_named_for_its_rates() {
    let dir = tempfile::tempdir().unwrap();
    let rrd = dir.path().join("lab.rrd");
    let mut s = settings(
        ClockKind::Virtual,
        0,
        true,
        Speed::Max,
        &dir.path().join("s.json"),
    );
    s.record = Some(rrd.clone());
    let mut script = steps(50);
    script.push(Control::Apply(Command::SetQueueDepth { depth: 5 }));
    script.extend(steps(50));
    script.push(Control::Apply(Command::SetControlHz { hz: 10.0 }));
    // As the lab's stall key (`k`) injects one: a fault, from 2.5 s for 0.2 s.
    script.push(Control::Apply(Command::InjectFault {
        fault: "policy@2.5+0.2".into(),
    }));
    script.extend(steps(50));
    script.push(Control::Quit);
    driven(s, &script);
    crate::recording::check_views(&rrd);
    let all = crate::recording::chunks(&rrd);
    let marks = |entity: &str| -> usize {
        all.iter()
            .filter(|c| !c.is_static() && c.entity_path().to_string() == entity)
            .map(|c| c.num_rows())
            .sum()
    };
    assert_eq!(marks("/marks/change"), 2, "the depth and the rate");
    // The stall is trouble where it took effect, its end a recovery (#73), as a headless
    // `--stall` is.
    assert_eq!(marks("/marks/trouble"), 1, "the stall");
    assert_eq!(marks("/marks/recovery"), 1, "its end");
    let events = crate::recording::events_with_times(&rrd);
    let stall = events
        .iter()
        .find(|(_, _, e)| e.starts_with("injected stall (live): node policy"))
        .unwrap_or_else(|| panic!("{events:#?}"));
    assert_eq!(stall.0, 2_500_000_000, "{stall:?}");
    assert!(
        events
            .iter()
            .any(|(t, _, e)| *t == 2_700_000_000 && e == "node policy resumes after its stall"),
        "{events:#?}"
    );
    let names: Vec<String> = all
        .iter()
        .filter(|c| c.entity_path() == &rerun::EntityPath::properties())
        .flat_map(|c| {
            c.iter_slices::<String>(rerun::RecordingInfo::descriptor_name().component)
                .flatten()
                .map(|s| s.as_str().to_string())
                .collect::<Vec<_>>()
        })
        .collect();
    assert!(
        names
            .last()
            .is_some_and(|n| n.contains("control 50 → 10 Hz")),
        "{names:?}"
    );
}

/// Reload on save, the engine's side: a graph file with a Python node, saved with a node that
/// pushes nothing, then with the policy's rate changed in the graph file, then with a syntax
/// error. Each loadable save is judged and said (`reloaded …: balanced … → fell …`) and starts
/// a run of the new code; the broken one is said with its file and line, and the run goes on.
#[test]
fn a_saved_graph_or_node_runs_again_and_a_broken_one_is_said() {
    use ratelab::session::GraphSource;
    ratelab::init(); // Python nodes
    let dir = tempfile::tempdir().unwrap();
    std::fs::create_dir(dir.path().join("nodes")).unwrap();
    let graph_file = dir.path().join("g.toml");
    let node_file = dir.path().join("nodes/scripted_balancer.py");
    let graph_text = std::fs::read_to_string(crate::repo("graphs/cartpole-python.toml")).unwrap();
    std::fs::write(&graph_file, &graph_text).unwrap();
    std::fs::copy(crate::repo("graphs/nodes/scripted_balancer.py"), &node_file).unwrap();
    let file = dir.path().join("session.json");
    let mut s = settings(ClockKind::Virtual, 1, true, Speed::Max, &file);
    s.cfg.graph = ratelab::graph::GraphSpec::load(&graph_file).unwrap();
    let source = graph_file.clone();
    s.graph_source = Some(GraphSource(std::sync::Arc::new(move || {
        ratelab::graph::GraphSpec::load(&source).map_err(|e| e.to_string())
    })));
    let (ctl_tx, ctl_rx) = unbounded();
    let (tel_tx, tel_rx) = unbounded::<Telemetry>();
    let engine = Engine::new(s, ctl_rx, tel_tx).spawn();
    let said = |what: &dyn Fn(&Telemetry) -> bool| loop {
        let t = tel_rx
            .recv_timeout(std::time::Duration::from_secs(30))
            .expect("telemetry");
        if what(&t) {
            return t;
        }
    };
    for c in steps(50) {
        ctl_tx.send(c).unwrap();
    }
    // The first run loaded its node and ran a second: then the node is saved.
    let stepped = std::cell::Cell::new(0);
    said(&|t| {
        stepped.set(stepped.get() + usize::from(matches!(t, Telemetry::Step(_))));
        stepped.get() == 50
    });
    // The node saved as one that pushes nothing: the pole falls.
    let original = std::fs::read_to_string(&node_file).unwrap();
    std::fs::write(
        &node_file,
        original.replace(
            "self.pub.publish(Force(newtons=float(command) * MOTOR_N))",
            "self.pub.publish(Force(newtons=0.0))",
        ),
    )
    .unwrap();
    ctl_tx
        .send(Control::Reload {
            file: node_file.clone(),
        })
        .unwrap();
    let Telemetry::Reloaded { line } = said(&|t| matches!(t, Telemetry::Reloaded { .. })) else {
        unreachable!()
    };
    assert!(line.starts_with("reloaded "), "{line}");
    assert!(
        line.contains("balanced (") && line.contains("→ fell at"),
        "{line}"
    );
    let Telemetry::Started { cfg, .. } = said(&|t| matches!(t, Telemetry::Started { .. })) else {
        unreachable!()
    };
    assert_eq!(cfg.graph.nodes[1].rate_hz, 50.0);
    // The graph file saved with the policy at 25 Hz: the next run has it.
    std::fs::write(&node_file, &original).unwrap();
    std::fs::write(
        &graph_file,
        graph_text.replacen(
            "rate_hz = 50\nsubscribes = \"/obs\"",
            "rate_hz = 25\nsubscribes = \"/obs\"",
            1,
        ),
    )
    .unwrap();
    ctl_tx
        .send(Control::Reload {
            file: graph_file.clone(),
        })
        .unwrap();
    let Telemetry::Started { cfg, .. } = said(&|t| matches!(t, Telemetry::Started { .. })) else {
        unreachable!()
    };
    assert_eq!(cfg.graph.nodes[1].rate_hz, 25.0);
    // A syntax error: said with the file and its line; no new run.
    std::fs::write(&node_file, "class Broken:\n    def __init__(self, node)\n").unwrap();
    ctl_tx
        .send(Control::Reload {
            file: node_file.clone(),
        })
        .unwrap();
    let Telemetry::Error(e) = said(&|t| matches!(t, Telemetry::Error(_))) else {
        unreachable!()
    };
    assert!(e.starts_with("not reloaded: "), "{e}");
    assert!(e.contains("scripted_balancer.py:2"), "{e}");
    for c in steps(5) {
        ctl_tx.send(c).unwrap();
    }
    ctl_tx.send(Control::Quit).unwrap();
    let log = engine.join().unwrap();
    assert_eq!(log.runs.len(), 3, "the first run and two reloads");
}

/// A step's run time, for [`LiveEngine::wait_for`].
fn step_at(t: &Telemetry) -> Option<ratelab::Nanos> {
    match t {
        Telemetry::Step(s) => Some(s.t),
        _ => None,
    }
}

impl LiveEngine {
    /// Ask the engine to reload `file` (as the lab's watcher does on a save).
    fn reload(&self, file: &std::path::Path) {
        let file = file.to_path_buf();
        self.ctl.send(Control::Reload { file }).unwrap();
    }

    /// Wait (at most 20 s) for the first message `pick` takes.
    fn wait_for<T>(&self, what: &str, mut pick: impl FnMut(&Telemetry) -> Option<T>) -> T {
        let deadline = std::time::Instant::now() + std::time::Duration::from_secs(20);
        loop {
            let left = deadline.saturating_duration_since(std::time::Instant::now());
            match self.tel.recv_timeout(left) {
                Ok(t) => {
                    if let Some(x) = pick(&t) {
                        return x;
                    }
                }
                Err(_) => panic!("no {what} within 20 s"),
            }
        }
    }

    fn quit_with_log(self) -> SessionLog {
        self.ctl.send(Control::Quit).unwrap();
        self.engine.join().unwrap()
    }
}

/// `c` on a running lab switches its clock in place: one run goes on, virtual → real →
/// virtual, its step count growing through both switches and its run time never starting
/// again; the session log notes the switches in that one run, and `replay` refuses it
/// (its real part cannot be run again).
#[test]
fn c_switches_the_running_graph_s_clock_in_place() {
    let _machine = crate::machine::alone();
    let live = LiveEngine::running(ClockKind::Virtual, Speed::Times(1.0), |_| {});
    // A second of the virtual clock at ×1.
    while live.wait_for("a step", step_at) < ratelab::Nanos::SECOND {}
    live.ctl.send(Control::SwitchClock).unwrap();
    let (at, clock) = live.wait_for("the switch", |t| match t {
        Telemetry::Started { .. } => panic!("a new run started: the switch was not in place"),
        Telemetry::ClockSwitched { at, clock } => Some((*at, *clock)),
        _ => None,
    });
    assert_eq!(clock, ClockKind::Real);
    assert!(at >= ratelab::Nanos::SECOND, "{at}");
    // The real clock's ticks go on from there.
    let tick = live.wait_for("a real-clock tick", |t| match t {
        Telemetry::NodeTick { now, .. } => Some(*now),
        _ => None,
    });
    assert!(tick >= at, "a tick at {tick}, the switch at {at}");
    let mut last = ratelab::Nanos::ZERO;
    while last < at + ratelab::Nanos(500 * ratelab::Nanos::MILLISECOND.0) {
        last = live.wait_for("a real-clock step", step_at);
    }
    live.ctl.send(Control::SwitchClock).unwrap();
    let (back, clock) = live.wait_for("the switch back", |t| match t {
        Telemetry::Started { .. } => panic!("a new run started"),
        Telemetry::ClockSwitched { at, clock } => Some((*at, *clock)),
        _ => None,
    });
    assert_eq!(clock, ClockKind::Virtual);
    assert!(back > at);
    let next = live.wait_for("a virtual step", step_at);
    assert!(next >= back, "{next} after {back}");
    let log = live.quit_with_log();
    assert_eq!(log.runs.len(), 1, "one run");
    let run = &log.runs[0];
    assert_eq!(run.clock, ClockKind::Virtual);
    assert_eq!(run.clock_switches_ns, vec![at.0, back.0]);
    let m = run.metrics.as_ref().unwrap();
    assert_eq!(m.clock, "virtual", "it ended under the virtual clock");
    // 50 steps a second, less what a loaded machine's real clock skipped.
    assert!(
        m.steps as f64 >= 40.0 * last.as_secs_f64(),
        "{} steps by t={last}",
        m.steps
    );
    assert!(matches!(
        replay_run(&log, 0),
        Err(ratelab::session::ReplayError::SwitchedClock { run: 1, .. })
    ));
}

/// Under the real clock a saved Python node restarts in place: the run goes on (no new run,
/// its time never back to 0), the node now runs the saved code (a policy that pushes
/// nothing: the pole falls), and the line says so; a save that breaks the node is said
/// and the run goes on with the code before; a save that changes a rate starts the run
/// again.
#[test]
fn under_the_real_clock_a_saved_node_restarts_in_place() {
    use ratelab::session::GraphSource;
    ratelab::init(); // Python nodes
    let _machine = crate::machine::alone();
    let dir = tempfile::tempdir().unwrap();
    std::fs::create_dir(dir.path().join("nodes")).unwrap();
    let graph_file = dir.path().join("g.toml");
    let node_file = dir.path().join("nodes/scripted_balancer.py");
    let graph_text = std::fs::read_to_string(crate::repo("graphs/cartpole-python.toml")).unwrap();
    std::fs::write(&graph_file, &graph_text).unwrap();
    std::fs::copy(crate::repo("graphs/nodes/scripted_balancer.py"), &node_file).unwrap();
    let mut s = settings(
        ClockKind::Real,
        1,
        false,
        Speed::Times(1.0),
        &dir.path().join("session.json"),
    );
    s.cfg.graph = ratelab::graph::GraphSpec::load(&graph_file).unwrap();
    let source = graph_file.clone();
    s.graph_source = Some(GraphSource(std::sync::Arc::new(move || {
        ratelab::graph::GraphSpec::load(&source).map_err(|e| e.to_string())
    })));
    let live = LiveEngine::with(s, dir);
    while live.wait_for("a step", step_at) < ratelab::Nanos::SECOND {}
    // A live change first: the run's graph is then not the file's, and a save of code
    // still restarts only the node.
    live.ctl
        .send(Control::Apply(ratelab::run::Command::SetQueueDepth {
            depth: 2,
        }))
        .unwrap();
    let original = std::fs::read_to_string(&node_file).unwrap();
    // A save that does not load: said, and the run goes on.
    std::fs::write(&node_file, "def broken(:\n").unwrap();
    live.reload(&node_file);
    let said = live.wait_for("not reloaded", |t| match t {
        Telemetry::Started { .. } => panic!("a new run started"),
        Telemetry::Error(e) if e.starts_with("not reloaded") => Some(e.clone()),
        _ => None,
    });
    assert!(said.contains("scripted_balancer.py"), "{said}");
    let before = live.wait_for("a step", step_at);
    // The node saved as one that pushes nothing.
    std::fs::write(
        &node_file,
        original.replace(
            "self.pub.publish(Force(newtons=float(command) * MOTOR_N))",
            "self.pub.publish(Force(newtons=0.0))",
        ),
    )
    .unwrap();
    live.reload(&node_file);
    let line = live.wait_for("the restart", |t| match t {
        Telemetry::Started { .. } => panic!("a new run started: not in place"),
        Telemetry::Applied(l) if l.starts_with("reloaded ") => Some(l.clone()),
        _ => None,
    });
    assert!(line.contains("'policy' restarted in place at t="), "{line}");
    let after = live.wait_for("a step", step_at);
    assert!(after >= before, "{after} after {before}: the run went on");
    // Pushing nothing, the pole falls.
    let reason = live.wait_for("the fall", |t| match t {
        Telemetry::Started { .. } => panic!("a new run started"),
        Telemetry::Ended { reason, .. } => Some(reason.clone()),
        _ => None,
    });
    assert_eq!(reason, ratelab::scheduler::EndReason::NodeStopped);
    // A save after the run ended starts the next run with the code.
    std::fs::write(&node_file, &original).unwrap();
    live.reload(&node_file);
    live.wait_for("a new run", |t| {
        matches!(t, Telemetry::Started { .. }).then_some(())
    });
    // A save that changes a rate (more than code) starts the run again too.
    while live.wait_for("a step", step_at) < ratelab::Nanos(500 * ratelab::Nanos::MILLISECOND.0) {}
    std::fs::write(
        &graph_file,
        graph_text.replacen(
            "rate_hz = 50\nsubscribes = \"/obs\"",
            "rate_hz = 25\nsubscribes = \"/obs\"",
            1,
        ),
    )
    .unwrap();
    live.reload(&graph_file);
    let Some(cfg) = live.wait_for("the run again", |t| match t {
        Telemetry::Started { cfg, .. } => Some(Some(cfg.clone())),
        _ => None,
    }) else {
        unreachable!()
    };
    assert_eq!(cfg.graph.nodes[1].rate_hz, 25.0);
    let log = live.quit_with_log();
    assert_eq!(log.runs.len(), 3);
}

/// A lab session's recording carries what a Python node prints, one text log per node
/// (`log/<node>`), as a headless run's does: 50 steps of a node printing once a tick.
#[test]
fn a_lab_session_s_recording_carries_what_its_nodes_print() {
    ratelab::init(); // Python nodes
    let dir = tempfile::tempdir().unwrap();
    let g = crate::loud_python_graph(dir.path(), "print('tick here')");
    let rrd = dir.path().join("lab.rrd");
    let mut s = settings(
        ClockKind::Virtual,
        0,
        true,
        Speed::Max,
        &dir.path().join("s.json"),
    );
    s.cfg.graph = ratelab::graph::GraphSpec::load(&g).unwrap();
    s.record = Some(rrd.clone());
    let mut script = steps(50);
    script.push(Control::Quit);
    driven(s, &script);
    let lines: Vec<String> = crate::recording::chunks(&rrd)
        .iter()
        .filter(|c| c.entity_path().to_string() == "/log/policy")
        .flat_map(|c| c.iter_slices::<String>(rerun::TextLog::descriptor_text().component))
        .flat_map(|s| s.into_iter().map(|x| x.to_string()).collect::<Vec<_>>())
        .collect();
    // The policy ticks with the actuator: once at t = 0 and once per step after. (A
    // recorder takes every line of the process: a test running beside this one may add
    // its own.)
    let ours = lines.iter().filter(|l| *l == "tick here").count();
    assert!((50..=51).contains(&ours), "{lines:?}");
}

/// Under the real clock a saved Python brain (`--policy FILE.py`) is loaded again and
/// swapped in, the run going on: the line says so and the change is logged as a brain
/// change.
#[test]
fn under_the_real_clock_a_saved_brain_is_swapped_in_place() {
    ratelab::init(); // Python brains
    let _machine = crate::machine::alone();
    let dir = tempfile::tempdir().unwrap();
    let brain = dir.path().join("brain.py");
    let balancer = "import math\n\ndef act(obs):\n    theta = math.atan2(float(obs[3]), float(obs[2]))\n    u = 10.0 * theta + 2.0 * float(obs[4]) + 0.4 * float(obs[0]) + 0.8 * float(obs[1])\n    return max(-1.0, min(1.0, u))\n";
    std::fs::write(&brain, balancer).unwrap();
    let mut s = settings(
        ClockKind::Real,
        1,
        false,
        Speed::Times(1.0),
        &dir.path().join("session.json"),
    );
    // Named with its function: the file saved is the spec's file part.
    s.policy = format!("{}:act", brain.display());
    let live = LiveEngine::with(s, dir);
    while live.wait_for("a step", step_at) < ratelab::Nanos(500 * ratelab::Nanos::MILLISECOND.0) {}
    std::fs::write(&brain, format!("{balancer}# saved again\n")).unwrap();
    live.reload(&brain);
    let line = live.wait_for("the swap", |t| match t {
        Telemetry::Started { .. } => panic!("a new run started: not in place"),
        Telemetry::Applied(l) if l.starts_with("reloaded ") => Some(l.clone()),
        _ => None,
    });
    assert!(line.contains("the brain swapped in place"), "{line}");
    let log = live.quit_with_log();
    assert_eq!(log.runs.len(), 1);
    assert!(
        log.runs[0]
            .commands
            .iter()
            .any(|c| matches!(&c.command, ratelab::run::Command::SetPolicy { .. })),
        "{:?}",
        log.runs[0].commands
    );
}

/// A live engine at ×1 on a copy of the chapter's graph with its Python policy
/// ([`crate::python_graph_copy`]), which reads the graph file again on a save as the lab
/// does; and the node's file, to save over.
fn python_graph_engine() -> (LiveEngine, std::path::PathBuf) {
    use ratelab::session::GraphSource;
    ratelab::init(); // Python nodes
    let dir = tempfile::tempdir().unwrap();
    let (graph_file, node_file, _) = crate::python_graph_copy(dir.path());
    let mut s = settings(
        ClockKind::Virtual,
        1,
        false,
        Speed::Times(1.0),
        &dir.path().join("session.json"),
    );
    s.cfg.graph = ratelab::graph::GraphSpec::load(&graph_file).unwrap();
    s.graph_source = Some(GraphSource(std::sync::Arc::new(move || {
        ratelab::graph::GraphSpec::load(&graph_file).map_err(|e| e.to_string())
    })));
    (LiveEngine::with(s, dir), node_file)
}

/// A save whose trial never returns (issue 72: the reloaded node's callback loops forever)
/// is said, never waited for, and not blamed on the run on screen: that run goes on with
/// the code before (its steps keep coming, no new run starts), the line names the file and
/// where the trial is stuck, and a newer save supersedes it (the stuck callback interrupted)
/// and is taken up.
#[test]
fn a_reload_whose_trial_never_returns_is_said_and_the_run_goes_on() {
    use ratelab::Nanos;
    let _machine = crate::machine::alone();
    let (live, node_file) = python_graph_engine();
    while live.wait_for("a step", step_at) < Nanos(500 * Nanos::MILLISECOND.0) {}
    // The node saved with a timer callback that never returns: its trial is stuck at t = 0.
    let original = std::fs::read_to_string(&node_file).unwrap();
    let timer = "    def on_timer(self):\n";
    assert!(original.contains(timer));
    std::fs::write(
        &node_file,
        original.replace(
            timer,
            &format!("{timer}        while True:\n            pass\n"),
        ),
    )
    .unwrap();
    live.reload(&node_file);
    let saved_at = live.wait_for("a step", step_at);
    let said = live.wait_for("the stuck trial said", |t| match t {
        Telemetry::Started { .. } => panic!("a new run started"),
        Telemetry::Reloaded { line } => panic!("taken up: {line}"),
        Telemetry::Error(e) if e.contains("has not returned") => Some(e.clone()),
        _ => None,
    });
    assert!(
        said.starts_with("reload of ")
            && said.contains(
                "scripted_balancer.py: its callback has not returned after 2 s of the trial run (t=0.00 s); the run on screen is the code before"
            ),
        "{said}"
    );
    // The footer's count goes up while it still has not returned (the log keeps the first
    // line only).
    let recount = live.wait_for("the count going up", |t| match t {
        Telemetry::Recount(e) => Some(e.clone()),
        Telemetry::Error(e) if e.contains("has not returned") => panic!("said again: {e}"),
        _ => None,
    });
    assert!(
        recount.contains("its callback has not returned after 3 s of the trial run (t=0.00 s)"),
        "{recount}"
    );
    // The run on screen went on meanwhile (2 s of it at ×1, less what a loaded machine
    // could not keep up with).
    let now = live.wait_for("a step", step_at);
    assert!(now >= saved_at + Nanos::SECOND, "{now} after {saved_at}");
    // A newer save supersedes it, and is taken up: the run starts again with its code.
    std::fs::write(&node_file, &original).unwrap();
    live.reload(&node_file);
    let line = live.wait_for("the reload", |t| match t {
        Telemetry::Reloaded { line } => Some(line.clone()),
        Telemetry::Error(e) if e.starts_with("not reloaded") => panic!("{e}"),
        _ => None,
    });
    assert!(line.contains("balanced ("), "{line}");
    live.wait_for("the new run", |t| {
        matches!(t, Telemetry::Started { .. }).then_some(())
    });
    let log = live.quit_with_log();
    assert_eq!(log.runs.len(), 2, "the first run and the reload");
}

/// The code before is what runs after a save that was not taken up (issue 72): with a
/// save's trial stuck, `r` drops the trial and starts the run again with the code the run
/// on screen had (not the saved code, which hangs), and so does `r` after a save that did
/// not load (a syntax error); a later save that loads is taken up as ever.
#[test]
fn after_a_save_not_taken_up_the_next_run_has_the_code_before() {
    use ratelab::Nanos;
    let _machine = crate::machine::alone();
    let (live, node_file) = python_graph_engine();
    while live.wait_for("a step", step_at) < Nanos(300 * Nanos::MILLISECOND.0) {}
    let original = std::fs::read_to_string(&node_file).unwrap();
    let timer = "    def on_timer(self):\n";
    assert!(original.contains(timer));
    // A new run that gets past 0.5 s of run time: its code is not the hanging one.
    let runs_past_half_a_second = |what: &str| {
        live.wait_for(what, |t| {
            matches!(t, Telemetry::Started { .. }).then_some(())
        });
        while live.wait_for(what, step_at) < Nanos(500 * Nanos::MILLISECOND.0) {}
    };
    // 1. The saved callback never returns: its trial is stuck; `r` drops it.
    std::fs::write(
        &node_file,
        original.replace(
            timer,
            &format!("{timer}        while True:\n            pass\n"),
        ),
    )
    .unwrap();
    live.reload(&node_file);
    live.wait_for("the stuck trial said", |t| match t {
        Telemetry::Error(e) if e.contains("has not returned") => Some(()),
        Telemetry::Reloaded { line } => panic!("taken up: {line}"),
        _ => None,
    });
    live.ctl.send(Control::Reset { next_seed: false }).unwrap();
    runs_past_half_a_second("the run after the dropped trial");
    // And again (the code before stays until a save is taken up).
    live.ctl.send(Control::Reset { next_seed: false }).unwrap();
    runs_past_half_a_second("a second run after the dropped trial");
    // 2. A save that does not load: the run goes on, and `r` starts it with the code before.
    std::fs::write(&node_file, format!("{original}\ndef broken(:\n")).unwrap();
    live.reload(&node_file);
    live.wait_for("the save refused", |t| match t {
        Telemetry::Error(e) if e.starts_with("not reloaded") => Some(()),
        Telemetry::Reloaded { line } => panic!("taken up: {line}"),
        _ => None,
    });
    live.ctl.send(Control::Reset { next_seed: false }).unwrap();
    runs_past_half_a_second("the run after the refused save");
    // 3. A save that loads is taken up, and the files are read again from then on.
    let quiet = original.replace(
        "self.pub.publish(Force(newtons=float(command) * MOTOR_N))",
        "self.pub.publish(Force(newtons=0.0))",
    );
    assert_ne!(quiet, original);
    std::fs::write(&node_file, &quiet).unwrap();
    live.reload(&node_file);
    let line = live.wait_for("the reload", |t| match t {
        Telemetry::Reloaded { line } => Some(line.clone()),
        Telemetry::Error(e) if e.starts_with("not reloaded") => panic!("{e}"),
        _ => None,
    });
    assert!(
        line.contains("fell at"),
        "the saved code pushes nothing: {line}"
    );
    let log = live.quit_with_log();
    assert_eq!(
        log.runs.len(),
        5,
        "the first run, three with `r`, the reload"
    );
}

/// The lab's `k` (`Control::Stall`) stalls a node from the instant the run takes up next,
/// whatever the lab has drawn: booked as the fault it became there (`NODE@T+D`, T that
/// instant, to the nanosecond), which a replay runs as it ran; and never refused as over at
/// max speed, where the run is far ahead of what the lab draws.
#[test]
fn the_stall_key_stalls_from_the_runs_next_instant_at_any_speed() {
    let stall = || Control::Stall {
        node: "policy".into(),
        duration: ratelab::Nanos(200_000_000),
    };
    // Paused and stepped: the instant is known.
    let dir = tempfile::tempdir().unwrap();
    let file = dir.path().join("session.json");
    let mut script = steps(50);
    script.push(stall());
    script.extend(steps(20));
    script.push(Control::Quit);
    let log = drive(&script, &file);
    let run = &log.runs[0];
    assert_eq!(run.commands.len(), 1, "{:?}", run.commands);
    let Command::InjectFault { fault } = &run.commands[0].command else {
        panic!("{:?}", run.commands[0]);
    };
    let at = ratelab::Nanos(run.commands[0].at_ns);
    assert!(
        at.0 > 0 && at.0 % 20_000_000 == 0,
        "an instant of the grid: {at:?}"
    );
    assert_eq!(
        fault,
        &format!(
            "policy@{}.{:09}+0.200000000",
            at.0 / 1_000_000_000,
            at.0 % 1_000_000_000
        )
    );
    let replayed = serde_json::to_string(&replay_run(&log, 0).unwrap()).unwrap();
    assert_eq!(
        replayed,
        serde_json::to_string(run.metrics.as_ref().unwrap()).unwrap()
    );

    // Running at max speed, never paused: the run is ahead of anything a lab would draw.
    let (ctl_tx, ctl_rx) = unbounded();
    let (tel_tx, tel_rx) = unbounded::<Telemetry>();
    let s = settings(
        ClockKind::Virtual,
        0,
        false,
        Speed::Max,
        &dir.path().join("max.json"),
    );
    let engine = Engine::new(s, ctl_rx, tel_tx).spawn();
    std::thread::sleep(std::time::Duration::from_millis(300));
    ctl_tx.send(stall()).unwrap();
    std::thread::sleep(std::time::Duration::from_millis(100));
    ctl_tx.send(Control::Quit).unwrap();
    let log = engine.join().unwrap();
    let errors = errors(tel_rx.try_iter());
    assert!(errors.is_empty(), "{errors:?}");
    let c = &log.runs[0].commands;
    assert_eq!(c.len(), 1, "{c:?}");
    let Command::InjectFault { fault } = &c[0].command else {
        panic!("{c:?}");
    };
    let f = ratelab::command::parse_fault(fault).unwrap();
    assert_eq!(
        (f.at.0, f.duration),
        (c[0].at_ns, Some(ratelab::Nanos(200_000_000)))
    );
}

/// `k` once the run has ended (it fell) stalls nothing: said so, naming the node, and
/// nothing is booked.
#[test]
fn the_stall_key_after_the_run_has_ended_says_so() {
    let dir = tempfile::tempdir().unwrap();
    let s = settings(
        ClockKind::Virtual,
        1,
        true,
        Speed::Max,
        &dir.path().join("s.json"),
    );
    let mut script = steps(10);
    script.push(Control::Apply(Command::SetControlHz { hz: 5.0 }));
    script.extend(steps(200)); // falls on the way; later steps are ignored while frozen
    script.push(Control::Stall {
        node: "policy".into(),
        duration: ratelab::Nanos(500_000_000),
    });
    script.push(Control::Quit);
    let (log, told) = driven(s, &script);
    assert!(
        !log.runs[0].metrics.as_ref().unwrap().balanced,
        "5 Hz falls"
    );
    assert_eq!(
        errors(told),
        vec!["stall policy: the run has ended (r starts the next)".to_string()]
    );
    assert!(
        log.runs[0]
            .commands
            .iter()
            .all(|c| !matches!(c.command, Command::InjectFault { .. })),
        "{:?}",
        log.runs[0].commands
    );
}
