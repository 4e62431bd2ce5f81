//! End to end, the scrub cursor's readout: paused in the real `ratelab` binary, ← puts the
//! run a tick back and the pole-angle chart's title reads the run there (its run time, θ,
//! θ̇; the force band's, the force and the held command's age).

use super::{press, shown_run_time, type_slowly, Lab};
use std::time::Duration;

/// Paused, ← a tick back: the pole-angle chart's title reads the run at the cursor, its run
/// time the cursor's (the footer's `back at t=…`, the header's to its hundredth), with θ,
/// θ̇, the force applied and the held command's age; θ and the force equal `trace.csv`'s
/// there. At 80×24 and 120×40.
#[test]
fn paused_a_tick_back_the_readout_reads_the_run_at_the_cursor() {
    let _machine = crate::machine::alone();
    for (cols, rows) in [(80, 24), (120, 40)] {
        readout_a_tick_back(cols, rows);
    }
}

/// The test above at `cols`×`rows`.
fn readout_a_tick_back(cols: u16, rows: u16) {
    let mut lab = Lab::start_sized(&["--clock", "virtual"], &[], cols, rows);
    lab.wait_for("BALANCED", Duration::from_secs(60));
    std::thread::sleep(Duration::from_millis(1500));
    type_slowly(&mut lab, " ");
    let paused = lab.wait_until("the readout", Duration::from_secs(5), |s| {
        s.contains("PAUSED") && readout_run_time(s).is_some()
    });
    let t0 = readout_run_time(&paused).unwrap();
    press(&mut lab, &["\x1b[D"]);
    let back = lab.wait_until("the readout a tick back", Duration::from_secs(10), |s| {
        s.contains("back at t=") && readout_run_time(s).is_some_and(|t| t < t0 - 0.01)
    });
    let at = readout_run_time(&back).unwrap();
    // The chapter's nodes all tick on the actuator's 20 ms grid: a tick back is 20 ms back.
    assert!(
        (at - (t0 - 0.02)).abs() < 1e-9,
        "a tick back from {t0}:\n{back}"
    );
    let cursor: f64 = back
        .split("back at t=")
        .nth(1)
        .and_then(|r| r.split(' ').next())
        .and_then(|v| v.parse().ok())
        .unwrap_or_else(|| panic!("no cursor in the footer:\n{back}"));
    assert_eq!(at, cursor, "{back}");
    let header = shown_run_time(&back).unwrap();
    assert!(
        (at - header).abs() < 0.005 + 1e-9,
        "{at} against {header}:\n{back}"
    );
    assert!(
        back.contains(" rad/s") && back.contains(" N") && back.contains(" ms old"),
        "{back}"
    );
    lab.quit();
    // What it reads is the run's: θ and the applied force equal `trace.csv`'s at that
    // instant, the same run (the chapter's graph, seed 0) written headless.
    let (theta, force) = readout_theta_and_force(&back);
    let dir = tempfile::tempdir().unwrap();
    let duration = format!("{}", at.ceil() + 1.0);
    let out = crate::distributed::ratelab(&[
        "run",
        "--clock",
        "virtual",
        "--duration",
        &duration,
        "--out",
        dir.path().to_str().unwrap(),
    ]);
    assert!(out.status.success(), "{out:?}");
    let csv = std::fs::read_to_string(dir.path().join("trace.csv")).unwrap();
    let header: Vec<&str> = csv.lines().next().unwrap().split(',').collect();
    let col = |name: &str| header.iter().position(|h| *h == name).unwrap();
    let t_ns = (at * 1e9).round() as u64;
    let row: Vec<&str> = csv
        .lines()
        .skip(1)
        .map(|l| l.split(',').collect::<Vec<_>>())
        .find(|r| r[col("t_ns")].parse::<u64>().ok() == Some(t_ns))
        .unwrap_or_else(|| panic!("no step at {t_ns} ns in trace.csv"));
    let cell = |name: &str| row[col(name)].parse::<f64>().unwrap();
    // Shown to 4 decimals (θ, rad) and 2 (force, N: the command times the motor's 10 N).
    assert!(
        (theta - cell("pole_angle")).abs() <= 0.5e-4 + 1e-12,
        "θ {theta} against {}:\n{back}",
        cell("pole_angle")
    );
    assert!(
        (force - cell("action") * 10.0).abs() <= 0.5e-2 + 1e-12,
        "F {force} against {}:\n{back}",
        cell("action") * 10.0
    );
}

/// The readout's θ (`· θ -0.1959 rad`) and applied force (`F -2.35 N · cmd`).
fn readout_theta_and_force(screen: &str) -> (f64, f64) {
    let number = |s: Option<&str>| -> f64 {
        s.and_then(|v| v.split_whitespace().next())
            .and_then(|v| v.parse().ok())
            .unwrap_or_else(|| panic!("no readout value:\n{screen}"))
    };
    let theta = number(
        screen
            .lines()
            .find(|l| l.contains(" rad/s"))
            .and_then(|l| l.split("· θ ").nth(1)),
    );
    let force = number(
        screen
            .lines()
            .find(|l| l.contains(" N · cmd"))
            .and_then(|l| l.split_once(" N · cmd"))
            .and_then(|(left, _)| left.rsplit_once("F "))
            .map(|(_, v)| v),
    );
    (theta, force)
}

/// The run time the scrub cursor's readout reads (`t=2.980 s · θ …`, the pole-angle chart's
/// title), s.
fn readout_run_time(screen: &str) -> Option<f64> {
    let row = screen.lines().find(|l| l.contains(" rad/s"))?;
    row.rsplit_once("t=")?
        .1
        .split_whitespace()
        .next()?
        .parse()
        .ok()
}
