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
        session_file: Some(file.to_path_buf()),
        start_paused,
        speed,
    }
}

fn drive(script: &[Control], file: &std::path::Path) -> SessionLog {
    let (ctl_tx, ctl_rx) = unbounded();
    let (tel_tx, tel_rx) = unbounded::<Telemetry>();
    let settings = settings(ClockKind::Virtual, 1, true, Speed::Max, file);
    let engine = Engine::new(settings, ctl_rx, tel_tx).spawn();
    for c in script {
        ctl_tx.send(c.clone()).unwrap();
    }
    let log = engine.join().unwrap();
    drop(tel_rx);
    log
}

fn steps(n: usize) -> Vec<Control> {
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
        (2, 7.0, 1)
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
    assert!(out.join("metrics-1.json").is_file());

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
    let (tel_tx, _tel_rx) = unbounded::<Telemetry>();
    let settings = settings(
        ClockKind::Real,
        0,
        false,
        Speed::Times(1.0),
        &dir.path().join("real.json"),
    );
    let engine = Engine::new(settings, ctl_rx, tel_tx).spawn();
    std::thread::sleep(std::time::Duration::from_millis(600));
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
