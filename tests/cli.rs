//! The `ratelab` binary's command line: headless runs, outputs, and bad input.

use std::path::Path;
use std::process::{Command, Output};

fn ratelab(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_ratelab"))
        .args(args)
        .output()
        .expect("runs")
}

fn stderr(o: &Output) -> String {
    String::from_utf8_lossy(&o.stderr).into_owned()
}

fn assert_usage_error(args: &[&str], needle: &str) {
    let o = ratelab(args);
    assert_eq!(o.status.code(), Some(2), "{args:?}: {}", stderr(&o));
    let err = stderr(&o);
    assert_eq!(
        err.trim_end().lines().count(),
        1,
        "{args:?}: one line, got {err:?}"
    );
    assert!(err.contains(needle), "{args:?}: {err:?} lacks {needle:?}");
    assert!(!err.contains("panicked"), "{err}");
}

#[test]
fn bad_rates_are_refused() {
    for bad in ["0", "-5", "nan", "inf", "10001", "fast"] {
        assert_usage_error(&["run", "--control-hz", bad], "--control-hz");
        assert_usage_error(&["run", "--sensor-hz", bad], "--sensor-hz");
    }
}

#[test]
fn bad_depth_duration_clock_are_refused() {
    assert_usage_error(&["run", "--queue-depth", "0"], "--queue-depth");
    assert_usage_error(&["run", "--duration", "0"], "--duration");
    assert_usage_error(&["run", "--duration", "-1"], "--duration");
    assert_usage_error(&["run", "--duration", "inf"], "--duration");
    assert_usage_error(&["run", "--clock", "wall"], "--clock");
}

#[test]
fn bad_policies_are_refused() {
    assert_usage_error(
        &["run", "--smoke", "--policy", "/no/such/ppo.pt"],
        "/no/such/ppo.pt",
    );
    let dir = tempfile::tempdir().unwrap();
    let p = dir.path().join("junk.pt");
    std::fs::write(&p, b"not a zip").unwrap();
    assert_usage_error(
        &["run", "--smoke", "--policy", p.to_str().unwrap()],
        "junk.pt",
    );
}

#[test]
fn smoke_run_prints_the_summary_and_writes_metrics() {
    let dir = tempfile::tempdir().unwrap();
    let o = ratelab(&["run", "--smoke", "--out", dir.path().to_str().unwrap()]);
    assert!(o.status.success(), "{}", stderr(&o));
    let out = String::from_utf8_lossy(&o.stdout);
    assert!(out.contains("clock=virtual"), "{out}");
    assert!(out.contains("BALANCED"), "{out}");
    assert!(out.contains("/obs 50.5 msg/s (0 dropped)"), "{out}");
    let m: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.path().join("metrics.json")).unwrap())
            .unwrap();
    for key in [
        "balanced",
        "clock",
        "control_hz",
        "sensor_hz",
        "queue_depth",
        "seed",
        "steps",
        "sim_time_s",
        "final_pole_angle",
        "mean_latency_ms",
        "obs_published",
        "obs_dropped",
        "action_published",
        "action_dropped",
        "latency_p50_ms",
        "latency_p99_ms",
        "latency_max_ms",
        "fell_at_s",
        "policy",
    ] {
        assert!(m.get(key).is_some(), "metrics.json lacks {key}");
    }
    assert_eq!(m["steps"], 101);
    assert_eq!(m["balanced"], true);
    assert!(dir.path().join("trace.csv").is_file());
}

fn run_to(dir: &Path, extra: &[&str]) -> (Vec<u8>, Vec<u8>) {
    let mut args = vec![
        "run",
        "--clock",
        "virtual",
        "--seed",
        "2",
        "--out",
        dir.to_str().unwrap(),
    ];
    args.extend_from_slice(extra);
    let o = ratelab(&args);
    assert!(o.status.success(), "{}", stderr(&o));
    (
        std::fs::read(dir.join("metrics.json")).unwrap(),
        std::fs::read(dir.join("trace.csv")).unwrap(),
    )
}

#[test]
fn two_virtual_runs_write_byte_identical_files() {
    let (a, b) = (tempfile::tempdir().unwrap(), tempfile::tempdir().unwrap());
    for extra in [&[][..], &["--break"][..]] {
        let first = run_to(a.path(), extra);
        let second = run_to(b.path(), extra);
        assert_eq!(first, second, "{extra:?}");
    }
}

#[test]
fn break_flag_falls_headless_when_piped() {
    // No subcommand + piped stdout = the headless run.
    let o = ratelab(&["--clock", "virtual", "--break"]);
    assert!(o.status.success(), "{}", stderr(&o));
    let out = String::from_utf8_lossy(&o.stdout);
    assert!(
        out.contains("control 5 Hz") && out.contains("FELL at t="),
        "{out}"
    );
}
