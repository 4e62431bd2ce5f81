//! End to end, the scrub cursor's readout: paused in the real `ratelab` binary, ← puts the
//! run a tick back and the pole-angle chart's title reads the run there (its run time, θ,
//! θ̇; the force band's, the force and the held command's age).

use super::{press, shown_run_time, type_slowly, Lab};
use std::time::Duration;

/// Paused, ← a tick back: the pole-angle chart's title reads the run at the cursor, its run
/// time the cursor's (the footer's `back at t=…`, the header's to its hundredth), with θ,
/// θ̇, the force applied and the held command's age. At 80×24.
#[test]
fn paused_a_tick_back_the_readout_reads_the_run_at_the_cursor() {
    let _machine = crate::machine::alone();
    let mut lab = Lab::start_sized(&["--clock", "virtual"], &[], 80, 24);
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
