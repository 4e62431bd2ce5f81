//! Recordings: decode fresh `.rrd` files in Rust, check their content, their determinism,
//! the shipped reference recording, and the refusals before a run starts.

use ratelab::policy::Scripted;
use ratelab::recording::{RecordOptions, Recording};
use ratelab::scheduler::StopFlag;
use ratelab::{run, ClockKind, RunConfig, RunOptions};
use re_chunk::Chunk;
use re_log_types::{LogMsg, StoreKind};
use std::collections::BTreeSet;
use std::path::{Path, PathBuf};

fn record(path: &Path, cfg: &RunConfig, stop: Option<StopFlag>) -> ratelab::metrics::Metrics {
    let (rec, _) = Recording::create(
        path,
        cfg,
        "scripted balancer (built-in, checkpoint-free)",
        &RecordOptions::default(),
    )
    .unwrap();
    let mut opts = RunOptions {
        observers: vec![rec.observer()],
        ..RunOptions::new()
    };
    if let Some(s) = stop {
        opts.stop = s;
    }
    let r = run(cfg, Box::new(Scripted), opts).unwrap();
    rec.finish(&r.metrics, &r.end).unwrap();
    r.metrics
}

/// The recording store's chunks, in file order.
fn chunks(path: &Path) -> Vec<Chunk> {
    let file = std::io::BufReader::new(std::fs::File::open(path).unwrap());
    let mut out = Vec::new();
    for msg in re_log_encoding::DecoderApp::decode_lazy(file) {
        if let LogMsg::ArrowMsg(store, arrow) = msg.expect("decodes") {
            if store.kind() == StoreKind::Recording {
                out.push(Chunk::from_arrow_msg(&arrow).unwrap());
            }
        }
    }
    out
}

fn virtual_cfg() -> RunConfig {
    RunConfig {
        clock: ClockKind::Virtual,
        ..RunConfig::default()
    }
}

fn same_chunks(a: &[Chunk], b: &[Chunk]) -> Result<(), String> {
    if a.len() != b.len() {
        return Err(format!("{} chunks vs {}", a.len(), b.len()));
    }
    for (x, y) in a.iter().zip(b) {
        Chunk::ensure_similar_ignoring_timelines(x, y, &[])
            .map_err(|e| format!("{}: {e}", x.entity_path()))?;
    }
    Ok(())
}

#[test]
fn fresh_recording_has_the_entities_timelines_and_one_angle_row_per_step() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("r.rrd");
    let m = record(&path, &virtual_cfg(), None);
    let chunks = chunks(&path);
    let entities: BTreeSet<String> = chunks.iter().map(|c| c.entity_path().to_string()).collect();
    for e in [
        "/world/rail",
        "/world/cart",
        "/world/cart/pole",
        "/plant/pole_angle_rad",
        "/plant/fall_limit/upper",
        "/plant/cart_pos_m",
        "/policy/action",
        "/latency/sense_to_act_ms",
        "/bus/obs/dropped",
        "/bus/obs/msg_per_s",
        "/bus/action/published",
        "/graph",
        "/events",
    ] {
        assert!(entities.contains(e), "missing {e} in {entities:?}");
    }
    let timelines: BTreeSet<String> = chunks
        .iter()
        .flat_map(|c| {
            c.timelines()
                .keys()
                .map(|t| t.to_string())
                .collect::<Vec<_>>()
        })
        .collect();
    assert!(
        timelines.contains("sim_time") && timelines.contains("control_step"),
        "{timelines:?}"
    );
    assert!(
        !timelines.contains("log_time"),
        "virtual recordings carry no wall-clock timeline"
    );
    let angle_rows: usize = chunks
        .iter()
        .filter(|c| c.entity_path().to_string() == "/plant/pole_angle_rad")
        .map(|c| c.num_rows())
        .sum();
    assert_eq!(angle_rows as u64, m.steps);
    let size = std::fs::metadata(&path).unwrap().len();
    assert!(size < 2 * 1024 * 1024, "a 10 s recording is {size} bytes");
}

#[test]
fn two_virtual_recordings_are_identical() {
    let dir = tempfile::tempdir().unwrap();
    let (a, b) = (dir.path().join("a.rrd"), dir.path().join("b.rrd"));
    let mut cfg = virtual_cfg();
    cfg.set_control_hz(7.0).unwrap();
    record(&a, &cfg, None);
    record(&b, &cfg, None);
    same_chunks(&chunks(&a), &chunks(&b)).unwrap();
    // …and a different run is different.
    let c = dir.path().join("c.rrd");
    record(&c, &RunConfig { seed: 1, ..cfg }, None);
    assert!(same_chunks(&chunks(&a), &chunks(&c)).is_err());
}

fn reference() -> PathBuf {
    PathBuf::from(crate::REPO).join("recordings/reference-virtual-control50-seed0.rrd")
}

#[test]
fn reference_recording_is_what_the_code_produces() {
    let dir = tempfile::tempdir().unwrap();
    let fresh = dir.path().join("fresh.rrd");
    // Same as: ratelab run --clock virtual --record <reference> --force
    record(&fresh, &virtual_cfg(), None);
    if let Err(e) = same_chunks(&chunks(&reference()), &chunks(&fresh)) {
        panic!(
            "recordings/reference-virtual-control50-seed0.rrd is stale ({e}); regenerate it on purpose with \
             `ratelab run --clock virtual --record recordings/reference-virtual-control50-seed0.rrd --force`"
        );
    }
}

#[test]
fn a_run_cut_short_leaves_a_complete_file() {
    struct StopAfter(u64, StopFlag);
    impl ratelab::graph::StepObserver for StopAfter {
        fn on_step(&mut self, r: &ratelab::metrics::StepRecord) {
            if r.step >= self.0 {
                self.1.stop();
            }
        }
    }
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("cut.rrd");
    let cfg = virtual_cfg();
    let stop = StopFlag::new();
    let (rec, _) = Recording::create(&path, &cfg, "scripted", &RecordOptions::default()).unwrap();
    let opts = RunOptions {
        observers: vec![rec.observer(), Box::new(StopAfter(100, stop.clone()))],
        stop,
        ..RunOptions::new()
    };
    let r = run(&cfg, Box::new(Scripted), opts).unwrap();
    assert_eq!(r.end.reason, ratelab::scheduler::EndReason::Interrupted);
    rec.finish(&r.metrics, &r.end).unwrap();
    drop(rec);
    let rows: usize = chunks(&path)
        .iter()
        .filter(|c| c.entity_path().to_string() == "/plant/pole_angle_rad")
        .map(|c| c.num_rows())
        .sum();
    assert_eq!(rows as u64, r.metrics.steps);
    assert_eq!(r.metrics.steps, 100);
}

fn ratelab(args: &[&str], cwd: &Path) -> std::process::Output {
    std::process::Command::new(env!("CARGO_BIN_EXE_ratelab"))
        .args(args)
        .current_dir(cwd)
        .output()
        .unwrap()
}

#[test]
fn headless_record_prints_where_and_how_to_open() {
    let dir = tempfile::tempdir().unwrap();
    let o = ratelab(&["run", "--smoke", "--record"], dir.path());
    let out = String::from_utf8_lossy(&o.stdout);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let expected = "recordings/virtual-control50-q1-seed0.rrd";
    assert!(out.contains(&format!("recording: {expected}")), "{out}");
    assert!(out.contains(&format!("rerun {expected}")), "{out}");
    assert!(dir.path().join(expected).is_file());
    // The default path never overwrites: the next run gets -2.
    let o = ratelab(&["run", "--smoke", "--record"], dir.path());
    assert!(String::from_utf8_lossy(&o.stdout).contains("seed0-2.rrd"));
    // --spawn without a viewer on PATH: one line saying so, and the file is still written.
    let o = std::process::Command::new(env!("CARGO_BIN_EXE_ratelab"))
        .args(["run", "--smoke", "--spawn"])
        .current_dir(dir.path())
        .env("PATH", "/nonexistent")
        .output()
        .unwrap();
    assert!(o.status.success());
    assert!(String::from_utf8_lossy(&o.stderr).contains("no rerun viewer on PATH"));
    assert!(dir
        .path()
        .join("recordings/virtual-control50-q1-seed0-3.rrd")
        .is_file());
}

#[test]
fn bad_record_paths_fail_before_the_run() {
    let dir = tempfile::tempdir().unwrap();
    let existing = dir.path().join("x.rrd");
    std::fs::write(&existing, b"keep me").unwrap();
    for (path, needle) in [
        (dir.path().to_str().unwrap().to_string(), "is a directory"),
        (existing.to_str().unwrap().to_string(), "--force"),
        (
            "/proc/ratelab-denied/x.rrd".to_string(),
            "cannot write recording",
        ),
    ] {
        let o = ratelab(&["run", "--smoke", "--record", &path], dir.path());
        assert_eq!(o.status.code(), Some(2), "{path}");
        let err = String::from_utf8_lossy(&o.stderr);
        assert!(err.contains(needle), "{path}: {err}");
        assert_eq!(err.trim_end().lines().count(), 1, "{err}");
        assert!(
            o.stdout.is_empty(),
            "the run must not start: {}",
            String::from_utf8_lossy(&o.stdout)
        );
    }
    assert_eq!(std::fs::read(&existing).unwrap(), b"keep me");
}

#[test]
fn ctrl_c_during_a_recorded_real_run_leaves_a_complete_file() {
    let _machine = crate::machine::alone();
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("cut.rrd");
    let child = std::process::Command::new(env!("CARGO_BIN_EXE_ratelab"))
        .args([
            "run",
            "--clock",
            "real",
            "--duration",
            "20",
            "--record",
            path.to_str().unwrap(),
        ])
        .stdout(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    std::thread::sleep(std::time::Duration::from_millis(2500));
    // SAFETY: sending SIGINT to our own child process.
    unsafe { libc::kill(child.id() as libc::pid_t, libc::SIGINT) };
    let out = child.wait_with_output().unwrap();
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert_eq!(out.status.code(), Some(130), "{stdout}");
    assert!(stdout.contains("interrupted at t="), "{stdout}");
    let rows: usize = chunks(&path)
        .iter()
        .filter(|c| c.entity_path().to_string() == "/plant/pole_angle_rad")
        .map(|c| c.num_rows())
        .sum();
    assert!(rows > 50, "about 2.5 s of 50 Hz steps recorded, got {rows}");
    let events: Vec<Chunk> = chunks(&path)
        .into_iter()
        .filter(|c| c.entity_path().to_string() == "/events")
        .collect();
    assert!(!events.is_empty());
}
