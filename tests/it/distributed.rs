//! One graph, many processes (`ratelab launch --processes`, `ratelab node`, `ratelab top`):
//! the real binary, several OS processes on localhost over Zenoh.

use crate::REPO;
use std::io::{BufRead, BufReader};
use std::path::Path;
use std::process::{Child, Command, Output, Stdio};
use std::time::{Duration, Instant};

fn bin() -> Command {
    let mut c = Command::new(env!("CARGO_BIN_EXE_ratelab"));
    c.current_dir(REPO);
    c
}

fn ratelab(args: &[&str]) -> Output {
    bin().args(args).output().expect("runs")
}

fn text(b: &[u8]) -> String {
    String::from_utf8_lossy(b).into_owned()
}

/// Every process whose command line mentions `needle` (the launcher's endpoint).
fn processes_mentioning(needle: &str) -> Vec<u32> {
    let mut out = Vec::new();
    for e in std::fs::read_dir("/proc").into_iter().flatten().flatten() {
        let Ok(pid) = e.file_name().to_string_lossy().parse::<u32>() else {
            continue;
        };
        if pid == std::process::id() {
            continue;
        }
        if let Ok(cmd) = std::fs::read(e.path().join("cmdline")) {
            let cmd = text(&cmd).replace('\0', " ");
            if cmd.contains(needle) && cmd.contains(" node ") {
                out.push(pid);
            }
        }
    }
    out
}

/// A free localhost port.
fn free_port() -> u16 {
    std::net::TcpListener::bind("127.0.0.1:0")
        .unwrap()
        .local_addr()
        .unwrap()
        .port()
}

#[test]
fn virtual_lockstep_is_byte_identical_to_the_in_process_run() {
    let _m = crate::machine::shared();
    let dir = tempfile::tempdir().unwrap();
    for hz in ["50", "5"] {
        for seed in ["0", "1", "2"] {
            let one = dir.path().join(format!("one-{hz}-{seed}"));
            let many = dir.path().join(format!("many-{hz}-{seed}"));
            let common = ["--clock", "virtual", "--seed", seed, "--control-hz", hz];
            let o = ratelab(&[&["run"][..], &common, &["--out", one.to_str().unwrap()]].concat());
            assert!(o.status.success(), "{}", text(&o.stderr));
            let o = ratelab(
                &[
                    &["launch", "graphs/cartpole.toml", "--processes"][..],
                    &common,
                    &["--out", many.to_str().unwrap()],
                ]
                .concat(),
            );
            assert!(o.status.success(), "{}{}", text(&o.stdout), text(&o.stderr));
            let out = text(&o.stdout);
            assert!(
                out.contains("in 2 processes: robot [sensor, actuator], policy [policy]"),
                "{out}"
            );
            let a = std::fs::read_to_string(one.join("metrics.json")).unwrap();
            let b = std::fs::read_to_string(many.join("metrics.json")).unwrap();
            assert_eq!(a, b, "control {hz} Hz, seed {seed}: metrics differ");
        }
    }
}

#[test]
fn a_split_graph_with_qos_matches_too() {
    // Three groups (the safety node alone), a fifo queue and a deadline crossing processes.
    let _m = crate::machine::shared();
    let dir = tempfile::tempdir().unwrap();
    let common = [
        "--graph",
        "graphs/cartpole-safety.toml",
        "--clock",
        "virtual",
        "--duration",
        "5",
        "--control-hz",
        "10",
        "--qos",
        "/obs:depth=100,delivery=fifo",
        "--qos",
        "/cmd:deadline_ms=30,on_deadline_missed=zero",
    ];
    let one = dir.path().join("one");
    let many = dir.path().join("many");
    let o = ratelab(&[&["run"][..], &common, &["--out", one.to_str().unwrap()]].concat());
    assert!(o.status.success(), "{}", text(&o.stderr));
    let o = ratelab(
        &[
            &["launch", "--processes"][..],
            &common,
            &["--out", many.to_str().unwrap()],
        ]
        .concat(),
    );
    assert!(o.status.success(), "{}{}", text(&o.stdout), text(&o.stderr));
    assert!(
        text(&o.stdout).contains("in 3 processes"),
        "{}",
        text(&o.stdout)
    );
    assert_eq!(
        std::fs::read_to_string(one.join("metrics.json")).unwrap(),
        std::fs::read_to_string(many.join("metrics.json")).unwrap()
    );
}

#[test]
fn three_processes_balance_under_the_real_clock_and_leave_nothing_behind() {
    let _m = crate::machine::alone();
    let dir = tempfile::tempdir().unwrap();
    let port = free_port();
    let ep = format!("tcp/127.0.0.1:{port}");
    let o = ratelab(&[
        "launch",
        "graphs/cartpole.toml",
        "--processes",
        "--clock",
        "real",
        "--duration",
        "4",
        "--listen",
        &ep,
        "--phase-offset-ms",
        "0,5,10",
        "--out",
        dir.path().to_str().unwrap(),
    ]);
    let out = text(&o.stdout);
    assert!(o.status.success(), "{out}{}", text(&o.stderr));
    assert!(out.contains(&format!("listening on {ep}")), "{out}");
    let m: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.path().join("metrics.json")).unwrap())
            .unwrap();
    assert_eq!(m["balanced"], true, "{out}");
    // Counters add up across the boundary: what the sensor published (one per tick) is what
    // the policy's process received plus what the wire lost.
    let sensor_ticks = m["nodes"]["sensor"]["ticks"].as_u64().unwrap();
    let obs = &m["topics"]["/obs"];
    let lost = obs["lost"].as_u64().unwrap_or(0);
    assert_eq!(obs["published"].as_u64().unwrap(), sensor_ticks, "{obs}");
    assert_eq!(lost, 0, "no losses on localhost: {obs}");
    assert!(
        sensor_ticks >= 190,
        "about 200 ticks in 4 s at 50 Hz: {sensor_ticks}"
    );
    let policy_ticks = m["nodes"]["policy"]["ticks"].as_u64().unwrap();
    assert!(policy_ticks >= 190, "{policy_ticks}");
    // Offsets 0/5/10 ms leave the wire (about 0.1 ms here) room: the policy reads the reading
    // taken 5 ms before, the actuator the force sent 5 ms before: 10 ms, as in one process.
    let p50 = m["latency_p50_ms"].as_f64().unwrap();
    assert!((9.9..=10.5).contains(&p50), "p50 {p50} ms: {m}");
    assert!(
        processes_mentioning(&format!(":{port}")).is_empty(),
        "node processes left running"
    );
}

#[test]
fn a_killed_node_is_noticed_and_a_restarted_one_rejoins() {
    let _m = crate::machine::alone();
    let port = free_port();
    let ep = format!("tcp/127.0.0.1:{port}");
    let mut launcher: Child = bin()
        .args([
            "launch",
            "--processes",
            "--clock",
            "real",
            "--duration",
            "6",
            "--listen",
            &ep,
        ])
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let stdout = launcher.stdout.take().unwrap();
    let (tx, rx) = std::sync::mpsc::channel::<String>();
    std::thread::spawn(move || {
        for line in BufReader::new(stdout).lines().map_while(Result::ok) {
            let _ = tx.send(line);
        }
    });
    let mut lines = Vec::new();
    let wait_for = |lines: &mut Vec<String>, needle: &str, secs: u64| {
        let until = Instant::now() + Duration::from_secs(secs);
        while Instant::now() < until {
            if let Ok(l) = rx.recv_timeout(Duration::from_millis(100)) {
                let hit = l.contains(needle);
                lines.push(l);
                if hit {
                    return true;
                }
            }
        }
        false
    };
    assert!(
        wait_for(&mut lines, "process 'policy' ready", 30),
        "{lines:?}"
    );
    assert!(
        wait_for(&mut lines, "process 'robot' ready", 30)
            || lines.iter().any(|l| l.contains("'robot' ready")),
        "{lines:?}"
    );
    std::thread::sleep(Duration::from_millis(1500));
    let policy: Vec<u32> = processes_mentioning(&format!(":{port}"))
        .into_iter()
        .filter(|pid| {
            std::fs::read(format!("/proc/{pid}/cmdline"))
                .map(|c| text(&c).contains("policy"))
                .unwrap_or(false)
        })
        .collect();
    assert_eq!(policy.len(), 1, "one policy process: {policy:?}");
    // SAFETY: plain kill(2) on a child of our child.
    unsafe { libc::kill(policy[0] as i32, libc::SIGKILL) };
    assert!(
        wait_for(&mut lines, "process 'policy' is gone", 10),
        "{lines:?}"
    );
    let mut again = bin()
        .args(["node", "--process", "policy", "--connect", &ep])
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    assert!(
        wait_for(&mut lines, "process 'policy' rejoined", 20),
        "{lines:?}"
    );
    let status = launcher.wait().unwrap();
    for l in rx.try_iter() {
        lines.push(l);
    }
    assert!(status.success(), "{lines:?}");
    assert!(
        lines
            .iter()
            .any(|l| l.contains("sim_time") || l.contains("steps")),
        "{lines:?}"
    );
    let restarted = again.wait().unwrap();
    assert!(restarted.success(), "the restarted node ends with the run");
    assert!(processes_mentioning(&format!(":{port}")).is_empty());
}

#[test]
fn top_lists_a_running_graph() {
    let _m = crate::machine::alone();
    let port = free_port();
    let ep = format!("tcp/127.0.0.1:{port}");
    let mut launcher = bin()
        .args([
            "launch",
            "--processes",
            "--clock",
            "real",
            "--duration",
            "5",
            "--listen",
            &ep,
        ])
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .spawn()
        .unwrap();
    std::thread::sleep(Duration::from_secs(3));
    let o = ratelab(&["top", "--connect", &ep, "--once"]);
    let out = text(&o.stdout);
    assert!(o.status.success(), "{out}{}", text(&o.stderr));
    for needle in [
        "robot", "policy", "sensor", "actuator", "/obs", "/action", "µs", "yes",
    ] {
        assert!(out.contains(needle), "{needle} missing in:\n{out}");
    }
    assert!(launcher.wait().unwrap().success());
}

fn assert_one_line_exit_2(o: &Output, needle: &str) {
    let err = text(&o.stderr);
    assert_eq!(o.status.code(), Some(2), "{err}");
    assert_eq!(err.trim_end().lines().count(), 1, "one line: {err:?}");
    assert!(err.contains(needle), "{err:?} lacks {needle:?}");
    assert!(!err.contains("panicked"), "{err}");
}

#[test]
fn bad_endpoints_busy_ports_and_unknown_processes_exit_2() {
    let _m = crate::machine::shared();
    for bad in [
        "nope",
        "udp/127.0.0.1:7447",
        "tcp/127.0.0.1",
        "tcp/127.0.0.1:99999",
        "tcp/no.such.host.invalid:7447",
    ] {
        let o = ratelab(&["node", "--process", "policy", "--connect", bad]);
        assert_one_line_exit_2(&o, "--connect");
        let o = ratelab(&[
            "launch",
            "--processes",
            "--clock",
            "virtual",
            "--listen",
            bad,
        ]);
        assert_one_line_exit_2(&o, "--listen");
    }
    let o = ratelab(&[
        "node",
        "--process",
        "nobody",
        "--connect",
        "tcp/127.0.0.1:9",
    ]);
    assert_one_line_exit_2(&o, "has no process 'nobody'");
    // A port in use.
    let busy = std::net::TcpListener::bind("127.0.0.1:0").unwrap();
    let ep = format!("tcp/127.0.0.1:{}", busy.local_addr().unwrap().port());
    let o = ratelab(&[
        "launch",
        "--processes",
        "--clock",
        "virtual",
        "--listen",
        &ep,
    ]);
    assert_one_line_exit_2(&o, "cannot open a Zenoh session");
    // Nobody listening.
    let o = ratelab(&[
        "node",
        "--process",
        "policy",
        "--connect",
        &format!("tcp/127.0.0.1:{}", free_port()),
    ]);
    assert_eq!(o.status.code(), Some(2), "{}", text(&o.stderr));
    assert!(!text(&o.stderr).contains("panicked"));
}

#[test]
fn a_graph_file_that_differs_between_processes_is_refused_at_join() {
    let _m = crate::machine::shared();
    let dir = tempfile::tempdir().unwrap();
    let changed = dir.path().join("cartpole.toml");
    let original = std::fs::read_to_string(Path::new(REPO).join("graphs/cartpole.toml")).unwrap();
    std::fs::write(
        &changed,
        original.replace(
            "rate_hz = 50\nsubscribes = \"/obs\"",
            "rate_hz = 25\nsubscribes = \"/obs\"",
        ),
    )
    .unwrap();
    assert_ne!(std::fs::read_to_string(&changed).unwrap(), original);
    let port = free_port();
    let ep = format!("tcp/127.0.0.1:{port}");
    let launcher = bin()
        .args([
            "launch",
            "graphs/cartpole.toml",
            "--processes",
            "--no-spawn",
            "--clock",
            "virtual",
            "--listen",
            &ep,
        ])
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    std::thread::sleep(Duration::from_millis(800));
    let node = ratelab(&[
        "node",
        "--graph",
        changed.to_str().unwrap(),
        "--process",
        "policy",
        "--connect",
        &ep,
    ]);
    assert_one_line_exit_2(&node, "different graph file");
    let o = launcher.wait_with_output().unwrap();
    assert_one_line_exit_2(&o, "different graph file");
}
