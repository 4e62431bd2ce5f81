//! Opt-in real-time priority for node threads: granted or refused exactly as the kernel's
//! rule says (sched(7): `CAP_SYS_NICE`, or `RLIMIT_RTPRIO` at least the priority), and a
//! refusal never costs the run.
//!
//! Each case computes the expected outcome from the rule for the thread or process that
//! asks, so the same tests hold on a privileged and an unprivileged machine; the refusal
//! cases take the privilege away themselves (capabilities are per thread; the child
//! process loses `CAP_SYS_NICE` from its bounding set and its rtprio limit).

use caps::{CapSet, Capability};
use ratelab::metrics::NodeTiming;
use ratelab::policy::Scripted;
use ratelab::realtime::{
    current_thread_sched, set_current_thread_fifo, RealtimeError, ThreadSched,
};
use ratelab::{run, Nanos, RunConfig, RunOptions};
use std::os::unix::process::CommandExt;
use std::process::Command;

const PRIO: u8 = 7;

/// Whether real-time group scheduling (cgroup v1, `CONFIG_RT_GROUP_SCHED`) gives this
/// process's cgroup no real-time budget, as container runtimes do by default: then every
/// request is refused, privileged or not.
fn rt_group_budget_is_zero() -> bool {
    // "4:cpu,cpuacct:/docker/abc" → the cgroup path of the cpu controller.
    let cgroups = std::fs::read_to_string("/proc/self/cgroup").unwrap_or_default();
    let Some(path) = cgroups.lines().find_map(|l| {
        let mut parts = l.splitn(3, ':');
        let (_, controllers, path) = (parts.next()?, parts.next()?, parts.next()?);
        controllers
            .split(',')
            .any(|c| c == "cpu")
            .then(|| path.to_string())
    }) else {
        return false; // cgroup v2 only: no real-time group budget
    };
    ["cpu", "cpu,cpuacct"].iter().any(|mount| {
        let file = format!("/sys/fs/cgroup/{mount}{path}/cpu.rt_runtime_us");
        std::fs::read_to_string(file).is_ok_and(|v| v.trim() == "0")
    })
}

/// The kernel's rule for the calling thread asking for `SCHED_FIFO priority`.
fn kernel_would_grant(priority: u8) -> bool {
    if rt_group_budget_is_zero() {
        return false;
    }
    let cap = caps::has_cap(None, CapSet::Effective, Capability::CAP_SYS_NICE).unwrap();
    let mut lim = libc::rlimit {
        rlim_cur: 0,
        rlim_max: 0,
    };
    // SAFETY: `lim` is a valid, writable rlimit.
    assert_eq!(unsafe { libc::getrlimit(libc::RLIMIT_RTPRIO, &mut lim) }, 0);
    cap || lim.rlim_cur >= u64::from(priority)
}

/// Drop `CAP_SYS_NICE` from the calling thread's effective set (this thread only).
fn drop_sys_nice() {
    caps::drop(None, CapSet::Effective, Capability::CAP_SYS_NICE).unwrap();
}

/// Ask on a fresh thread (the test harness's threads keep their policy) after `prepare`.
fn request_on_fresh_thread(prepare: fn()) -> (bool, Result<(), RealtimeError>) {
    std::thread::spawn(move || {
        prepare();
        let before = current_thread_sched();
        assert_eq!(before, ThreadSched::Other);
        let expect = kernel_would_grant(PRIO);
        let got = set_current_thread_fifo(PRIO);
        match &got {
            Ok(()) => assert_eq!(current_thread_sched(), ThreadSched::Fifo(PRIO)),
            Err(RealtimeError::Refused { priority, reason }) => {
                assert_eq!(*priority, PRIO);
                assert!(reason.contains("not permitted"), "{reason}");
                assert_eq!(current_thread_sched(), before, "a refusal changes nothing");
            }
            Err(e) => panic!("unexpected {e}"),
        }
        (expect, got)
    })
    .join()
    .unwrap()
}

#[test]
fn a_request_is_granted_or_refused_as_the_kernel_rule_says() {
    let (expect, got) = request_on_fresh_thread(|| {});
    assert_eq!(got.is_ok(), expect, "{got:?}");
}

#[test]
fn without_cap_sys_nice_a_request_is_refused_with_a_one_line_reason() {
    let (expect, got) = request_on_fresh_thread(drop_sys_nice);
    assert_eq!(got.is_ok(), expect, "{got:?}");
    if let Err(e) = got {
        let line = e.to_string();
        assert!(
            line.starts_with("SCHED_FIFO priority 7 refused: "),
            "{line}"
        );
        assert!(
            line.contains("CAP_SYS_NICE") && !line.contains('\n'),
            "{line}"
        );
    }
}

fn real_run_with_priority() -> (bool, Vec<NodeTiming>, Option<String>, bool) {
    let expect = kernel_would_grant(PRIO);
    let cfg = RunConfig {
        duration: Nanos(Nanos::SECOND.0),
        rt_priority: Some(PRIO),
        ..RunConfig::default()
    };
    let r = run(&cfg, Box::new(Scripted), RunOptions::new()).unwrap();
    let warning = r.metrics.sched_warning();
    (
        expect,
        r.metrics.node_timing.unwrap(),
        warning,
        r.metrics.balanced,
    )
}

fn assert_node_policies(expect: bool, timing: &[NodeTiming], warning: Option<&str>) {
    assert_eq!(timing.len(), 3);
    for t in timing {
        if expect {
            assert_eq!(t.sched, format!("SCHED_FIFO {PRIO}"), "{t:?}");
            assert_eq!(t.sched_error, None);
        } else {
            assert_eq!(t.sched, "SCHED_OTHER", "{t:?}");
            assert!(t.sched_error.as_deref().unwrap().contains("refused"));
        }
        assert!(t.ticks >= 10, "{t:?}");
    }
    match warning {
        None => assert!(expect),
        Some(w) => {
            assert!(!expect);
            assert!(
                w.starts_with(
                    "sensor, policy, actuator ran under SCHED_OTHER: SCHED_FIFO priority 7 refused"
                ),
                "{w}"
            );
        }
    }
}

#[test]
fn node_threads_run_under_the_policy_they_were_granted() {
    let _machine = crate::machine::alone();
    // Node threads are created by this thread and inherit its capabilities.
    let (expect, timing, warning, balanced) =
        std::thread::spawn(real_run_with_priority).join().unwrap();
    assert_node_policies(expect, &timing, warning.as_deref());
    assert!(balanced);
}

#[test]
fn a_refused_priority_leaves_the_nodes_running_and_says_so() {
    let _machine = crate::machine::alone();
    let (expect, timing, warning, balanced) = std::thread::spawn(|| {
        drop_sys_nice();
        real_run_with_priority()
    })
    .join()
    .unwrap();
    assert_node_policies(expect, &timing, warning.as_deref());
    assert!(balanced, "a refusal must not cost the run");
}

#[test]
fn the_binary_warns_in_one_line_when_refused_and_still_balances() {
    let _machine = crate::machine::alone();
    let mut cmd = Command::new(env!("CARGO_BIN_EXE_ratelab"));
    cmd.args(["run", "--duration", "1", "--rt-priority", "7"]);
    // Only a process that could pass CAP_SYS_NICE on needs to (and can) drop it.
    let privileged = caps::has_cap(None, CapSet::Permitted, Capability::CAP_SYS_NICE).unwrap();
    let sys_nice = libc::c_ulong::from(Capability::CAP_SYS_NICE.index());
    // SAFETY: runs in the forked child before exec and makes only async-signal-safe
    // syscalls (prctl, setrlimit) with no allocation.
    unsafe {
        cmd.pre_exec(move || {
            // Out of the bounding set → not regained at exec, even by root.
            if privileged && libc::prctl(libc::PR_CAPBSET_DROP, sys_nice, 0, 0, 0) != 0 {
                return Err(std::io::Error::last_os_error());
            }
            let zero = libc::rlimit {
                rlim_cur: 0,
                rlim_max: 0,
            };
            if libc::setrlimit(libc::RLIMIT_RTPRIO, &zero) != 0 {
                return Err(std::io::Error::last_os_error());
            }
            Ok(())
        });
    }
    let out = cmd.output().unwrap();
    let stdout = String::from_utf8_lossy(&out.stdout);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(0), "{stderr}");
    assert!(stdout.contains("BALANCED"), "{stdout}");
    let warnings: Vec<&str> = stderr.lines().filter(|l| l.contains("warning")).collect();
    assert_eq!(
        warnings,
        ["[ratelab] warning: sensor, policy, actuator ran under SCHED_OTHER: SCHED_FIFO priority 7 refused: Operation not permitted (needs CAP_SYS_NICE or `ulimit -r` >= 7, and a real-time budget in a container)"],
        "{stderr}"
    );
    assert!(stdout.contains("| SCHED_OTHER"), "{stdout}");
}

#[test]
fn the_binary_reports_the_granted_policy_per_node() {
    let _machine = crate::machine::alone();
    let expect = kernel_would_grant(PRIO);
    let out = Command::new(env!("CARGO_BIN_EXE_ratelab"))
        .args(["run", "--duration", "1", "--rt-priority", "7"])
        .output()
        .unwrap();
    let stdout = String::from_utf8_lossy(&out.stdout);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(0), "{stderr}");
    let node_lines: Vec<&str> = stdout.lines().filter(|l| l.contains(" node ")).collect();
    assert_eq!(node_lines.len(), 3, "{stdout}");
    let want = if expect {
        "| SCHED_FIFO 7"
    } else {
        "| SCHED_OTHER"
    };
    assert!(node_lines.iter().all(|l| l.ends_with(want)), "{stdout}");
    assert_eq!(stderr.contains("refused"), !expect, "{stderr}");
}

#[test]
fn the_probe_predicts_what_node_threads_get() {
    let (expect, got) = std::thread::spawn(|| {
        (
            kernel_would_grant(PRIO),
            ratelab::realtime::probe_fifo(PRIO),
        )
    })
    .join()
    .unwrap();
    assert_eq!(got.is_ok(), expect, "{got:?}");
    let (expect, got) = std::thread::spawn(|| {
        drop_sys_nice();
        (
            kernel_would_grant(PRIO),
            ratelab::realtime::probe_fifo(PRIO),
        )
    })
    .join()
    .unwrap();
    assert_eq!(got.is_ok(), expect, "{got:?}");
}

#[test]
fn the_lab_engine_warns_when_the_run_starts_not_when_it_ends() {
    let _machine = crate::machine::alone();
    use crossbeam_channel::unbounded;
    use ratelab::session::{Control, Engine, SessionSettings, Speed, Telemetry, UNBOUNDED};
    std::thread::spawn(|| {
        drop_sys_nice();
        let expect = kernel_would_grant(PRIO);
        let settings = SessionSettings {
            cfg: RunConfig {
                duration: UNBOUNDED,
                rt_priority: Some(PRIO),
                ..RunConfig::default()
            },
            policy: "scripted".into(),
            alt_policy: None,
            record: None,
            spawn: false,
            record_window: None,
            session_file: None,
            start_paused: false,
            speed: Speed::Times(1.0),
            force: false,
            ros2: None,
            graph_source: None,
            control: None,
        };
        let (ctl_tx, ctl_rx) = unbounded();
        let (tel_tx, tel_rx) = unbounded::<Telemetry>();
        let engine = Engine::new(settings, ctl_rx, tel_tx).spawn();
        // Everything told while the run is still going: wait for 15 actuator ticks (each
        // node then has the 10 ticks assert_node_policies asks for) rather than a fixed
        // time, which a loaded machine may not fill; the deadline only bounds a hang.
        let deadline = std::time::Instant::now() + std::time::Duration::from_secs(20);
        let mut told: Vec<Telemetry> = Vec::new();
        while told
            .iter()
            .filter(|t| matches!(t, Telemetry::Step(_)))
            .count()
            < 15
        {
            let left = deadline.saturating_duration_since(std::time::Instant::now());
            match tel_rx.recv_timeout(left) {
                Ok(t) => told.push(t),
                Err(_) => panic!("15 steps within 20 s; told: {told:?}"),
            }
        }
        ctl_tx.send(Control::Quit).unwrap();
        let log = engine.join().unwrap();
        assert!(
            !told.iter().any(|t| matches!(t, Telemetry::Ended { .. })),
            "the run was still going"
        );
        let warning = told.iter().position(|t| {
            matches!(t, Telemetry::Applied(text) if text.starts_with(
                "warning: node threads keep their default policy: SCHED_FIFO priority 7 refused"))
        });
        assert_eq!(warning.is_some(), !expect);
        // Told when the run starts: before its first step, not only by the end.
        if let Some(w) = warning {
            let first_step = told
                .iter()
                .position(|t| matches!(t, Telemetry::Step(_)))
                .expect("counted above");
            assert!(w < first_step, "warning after the first step: {told:?}");
        }
        let m = log.runs[0].metrics.as_ref().unwrap();
        assert_node_policies(
            expect,
            m.node_timing.as_ref().unwrap(),
            m.sched_warning().as_deref(),
        );
    })
    .join()
    .unwrap();
}
