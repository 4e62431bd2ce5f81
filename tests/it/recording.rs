//! Recordings: decode fresh `.rrd` files in Rust, check their content, their determinism,
//! the shipped reference recording, and the refusals before a run starts.

use ratelab::observer::Recorded;
use ratelab::policy::Scripted;
use ratelab::recording::{RecordOptions, Recording};
use ratelab::run::{Command, TimedCommand};
use ratelab::scheduler::StopFlag;
use ratelab::{run, ClockKind, RunConfig, RunOptions};
use re_chunk::Chunk;
use re_log_types::{
    EntityPath, EntityPathFilter, EntityPathSubs, LogMsg, ResolvedEntityPathRule, RuleEffect,
    StoreKind,
};
use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};

pub(crate) fn record(
    path: &Path,
    cfg: &RunConfig,
    stop: Option<StopFlag>,
) -> ratelab::metrics::Metrics {
    record_with(path, cfg, stop, Vec::new())
}

/// [`record`] with commands applied at virtual instants, as a lab session logs them.
fn record_with(
    path: &Path,
    cfg: &RunConfig,
    stop: Option<StopFlag>,
    commands: Vec<TimedCommand>,
) -> ratelab::metrics::Metrics {
    record_with_options(path, cfg, stop, commands, &RecordOptions::default())
}

/// [`record_with`] with these options (a window).
fn record_with_options(
    path: &Path,
    cfg: &RunConfig,
    stop: Option<StopFlag>,
    commands: Vec<TimedCommand>,
    options: &RecordOptions,
) -> ratelab::metrics::Metrics {
    let (rec, _) = Recording::create(
        path,
        cfg,
        "scripted balancer (built-in, checkpoint-free)",
        options,
    )
    .unwrap();
    let mut opts = RunOptions {
        // As `ratelab run` attaches it: every step, per-node lateness (logged by the real
        // clock only) and, with executors or compute times, every tick's span for the
        // executor timeline.
        observers: vec![Box::new(Recorded::new(&rec))],
        commands,
        ..RunOptions::new()
    };
    if let Some(s) = stop {
        opts.stop = s;
    }
    let r = run(cfg, Box::new(Scripted), opts).unwrap();
    rec.finish(&r.metrics, &r.end).unwrap();
    r.metrics
}

/// Every label the node graph (`/graph`) was logged with, in the order logged.
fn graph_labels(chunks: &[Chunk]) -> Vec<String> {
    chunks
        .iter()
        .filter(|c| c.entity_path().to_string() == "/graph")
        .flat_map(|c| c.iter_slices::<String>(rerun::GraphNodes::descriptor_labels().component))
        .flatten()
        .map(|s| s.as_str().to_string())
        .collect()
}

/// The recording store's chunks, in file order.
pub(crate) fn chunks(path: &Path) -> Vec<Chunk> {
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

/// The names of every timeline the chunks are on.
fn timeline_names(chunks: &[Chunk]) -> BTreeSet<String> {
    chunks
        .iter()
        .flat_map(|c| {
            c.timelines()
                .keys()
                .map(|t| t.to_string())
                .collect::<Vec<_>>()
        })
        .collect()
}

/// A chunk's rows' times on `timeline` (none when it is not on it).
fn times_on(c: &Chunk, timeline: &str) -> Vec<i64> {
    c.timelines()
        .iter()
        .find(|(n, _)| n.as_str() == timeline)
        .map(|(_, col)| col.times_raw().to_vec())
        .unwrap_or_default()
}

/// Pole-angle rows on the timelines (the static row naming the series is not a sample).
/// Every sample of scalar series `entity` on the `sim_time` timeline, by run time: (ns, value).
fn sim_series(chunks: &[Chunk], entity: &str) -> Vec<(i64, f64)> {
    let mut samples: Vec<(i64, f64)> = chunks
        .iter()
        .filter(|c| !c.is_static() && c.entity_path().to_string() == entity)
        .flat_map(|c| {
            let values: Vec<f64> = c
                .iter_slices::<f64>(rerun::Scalars::descriptor_scalars().component)
                .flat_map(|b| b.to_vec())
                .collect();
            times_on(c, "sim_time").into_iter().zip(values)
        })
        .collect();
    samples.sort_by_key(|(t, _)| *t);
    samples
}

fn angle_rows(chunks: &[Chunk]) -> u64 {
    chunks
        .iter()
        .filter(|c| !c.is_static() && c.entity_path().to_string() == "/plant/pole_angle_rad")
        .map(|c| c.num_rows() as u64)
        .sum()
}

pub(crate) fn virtual_cfg() -> RunConfig {
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
        "/when",
        "/action/published_N",
        "/action/applied_N",
        "/latency/control_period_ms",
        "/world/cart/force",
        "/world/cart/fall_limits",
        "/summary",
        "/latency/sense_to_act_ms",
        "/bus/obs/dropped",
        "/bus/obs/msg_per_s",
        "/bus/action/published",
        "/graph",
        "/events",
    ] {
        assert!(entities.contains(e), "missing {e} in {entities:?}");
    }
    let timelines = timeline_names(&chunks);
    assert!(
        timelines.contains("sim_time") && timelines.contains("control_step"),
        "{timelines:?}"
    );
    assert!(
        !timelines.contains("log_time"),
        "virtual recordings carry no wall-clock timeline"
    );
    assert_eq!(angle_rows(&chunks), m.steps);
    let size = std::fs::metadata(&path).unwrap().len();
    assert!(size < 2 * 1024 * 1024, "a 10 s recording is {size} bytes");
}

/// The bus's msg/s starts at the second step, at the sensor's rate: the first step spans no
/// time, and logging 0 there drew a 50 Hz topic rising from 0 msg/s at the run's start (#25).
#[test]
fn the_msg_per_s_plot_starts_at_the_rate_not_at_zero() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("r.rrd");
    let mut cfg = virtual_cfg();
    cfg.duration = ratelab::Nanos(1_000_000_000);
    record(&path, &cfg, None);
    let samples = sim_series(&chunks(&path), "/bus/obs/msg_per_s");
    assert_eq!(samples.first(), Some(&(20_000_000, 50.0)), "{samples:?}");
    assert!(samples.iter().all(|(_, r)| *r > 0.0), "{samples:?}");
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
        fn on_step(&mut self, r: &ratelab::runlog::StepRecord) {
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
        observers: vec![
            Box::new(Recorded::new(&rec)),
            Box::new(StopAfter(100, stop.clone())),
        ],
        stop,
        ..RunOptions::new()
    };
    let r = run(&cfg, Box::new(Scripted), opts).unwrap();
    assert_eq!(r.end.reason, ratelab::scheduler::EndReason::Interrupted);
    rec.finish(&r.metrics, &r.end).unwrap();
    drop(rec);
    assert_eq!(angle_rows(&chunks(&path)), r.metrics.steps);
    assert_eq!(r.metrics.steps, 100);
}

/// The chunks of a recording that may stop midway (its writer killed, or still writing):
/// every whole message, in file order, up to the first that does not read.
fn chunks_so_far(path: &Path) -> Vec<Chunk> {
    let file = std::io::BufReader::new(std::fs::File::open(path).unwrap());
    let mut read = Vec::new();
    for msg in re_log_encoding::DecoderApp::decode_lazy(file) {
        let Ok(msg) = msg else { break };
        if let LogMsg::ArrowMsg(store, arrow) = msg {
            if store.kind() == StoreKind::Recording {
                read.push(Chunk::from_arrow_msg(&arrow).unwrap());
            }
        }
    }
    read
}

/// A run killed outright (`SIGKILL`: nothing of ratelab runs after it, as under the
/// out-of-memory killer) leaves what it recorded under the name asked for, nothing hidden
/// beside it, and the file reads back up to where it stopped (and reads while written).
#[test]
fn a_recording_killed_midway_is_at_its_name_and_reads_back() {
    use std::time::{Duration, Instant};
    /// The run, killed however the test ends.
    struct Killed(std::process::Child);
    impl Drop for Killed {
        fn drop(&mut self) {
            let _ = self.0.kill();
            let _ = self.0.wait();
        }
    }
    let _machine = crate::machine::shared();
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("killed.rrd");
    let mut child = Killed(
        std::process::Command::new(env!("CARGO_BIN_EXE_ratelab"))
            .args(["run", "--clock", "real", "--duration", "120", "--record"])
            .arg(&path)
            .current_dir(dir.path())
            .stdout(std::process::Stdio::null())
            .stderr(std::process::Stdio::null())
            .spawn()
            .unwrap(),
    );
    // Until the pole's angle has reached the file (sent every FLUSH_EVERY_STEPS actuator
    // steps: 5 s at 50 Hz), at most 60 s.
    let deadline = Instant::now() + Duration::from_secs(60);
    let seen = loop {
        assert!(
            child.0.try_wait().unwrap().is_none(),
            "the run ended before it was killed"
        );
        let rows = if path.exists() {
            angle_rows(&chunks_so_far(&path))
        } else {
            0
        };
        if rows >= 50 {
            break rows;
        }
        assert!(
            Instant::now() < deadline,
            "{rows} angle rows at {} after 60 s",
            path.display()
        );
        std::thread::sleep(Duration::from_millis(250));
    };
    child.0.kill().unwrap(); // SIGKILL
    child.0.wait().unwrap();
    let names: Vec<String> = std::fs::read_dir(dir.path())
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    assert_eq!(names, ["killed.rrd"], "nothing beside it");
    let rows = angle_rows(&chunks_so_far(&path));
    assert!(
        rows >= seen,
        "{rows} angle rows after the kill, {seen} before"
    );
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
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(err.contains("no rerun viewer on PATH"), "{err}");
    // Both lines name the viewer a user gets today, not an older one.
    let install = "pip install rerun-sdk==0.41.0";
    assert!(err.contains(install), "{err}");
    let out = String::from_utf8_lossy(&o.stdout);
    let hint = format!("open it with: rerun recordings/virtual-control50-q1-seed0-3.rrd (no rerun on PATH: {install}");
    assert!(out.contains(&hint), "{out}");
    assert!(dir
        .path()
        .join("recordings/virtual-control50-q1-seed0-3.rrd")
        .is_file());
    // With a `rerun` on PATH, the line is the command alone.
    let bin = dir.path().join("bin");
    std::fs::create_dir(&bin).unwrap();
    std::fs::write(bin.join("rerun"), "").unwrap();
    let o = std::process::Command::new(env!("CARGO_BIN_EXE_ratelab"))
        .args(["run", "--smoke", "--record", "r.rrd"])
        .current_dir(dir.path())
        .env("PATH", &bin)
        .output()
        .unwrap();
    let out = String::from_utf8_lossy(&o.stdout);
    assert!(
        out.contains("[ratelab] open it with: rerun r.rrd\n"),
        "{out}"
    );
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
    // The headline names the run's end, never "the whole run" (issue 25).
    assert!(stdout.contains("STOPPED EARLY at t="), "{stdout}");
    assert!(
        stdout.contains("s of 20.00s (pole up until then)"),
        "{stdout}"
    );
    assert!(!stdout.contains("whole run"), "{stdout}");
    let rows = angle_rows(&chunks(&path));
    assert!(rows > 50, "about 2.5 s of 50 Hz steps recorded, got {rows}");
    let events: Vec<Chunk> = chunks(&path)
        .into_iter()
        .filter(|c| c.entity_path().to_string() == "/events")
        .collect();
    assert!(!events.is_empty());
}

/// One view of a recording's blueprint, as decoded from the file.
#[derive(Debug, Default)]
pub(crate) struct BlueprintView {
    class: String,
    name: String,
    origin: String,
    queries: Vec<String>,
    /// The y range (`ScalarAxis`) of a time series view, when it has one.
    y_range: Option<[f64; 2]>,
    /// How its time axis is linked (`TimeAxis`'s link), when set.
    time_link: Option<String>,
    /// The corner of its legend (`PlotLegend`), when set.
    legend: Option<String>,
}

/// The last value of `component` (of type `C`) in `chunk`, if any.
fn last<C: rerun::Component + Clone>(
    chunk: &Chunk,
    component: re_chunk::ComponentIdentifier,
) -> Option<C> {
    chunk
        .iter_component::<C>(component)
        .flat_map(|batch| batch.to_vec())
        .last()
}

/// The chunks of the blueprint the `.rrd` at `path` activates last.
pub(crate) fn active_blueprint(path: &Path) -> Vec<Chunk> {
    let file = std::io::BufReader::new(std::fs::File::open(path).unwrap());
    let mut stores: BTreeMap<String, Vec<Chunk>> = BTreeMap::new();
    let mut active = None;
    for msg in re_log_encoding::DecoderApp::decode_lazy(file) {
        match msg.expect("decodes") {
            LogMsg::ArrowMsg(store, arrow) if store.kind() == StoreKind::Blueprint => {
                stores
                    .entry(format!("{store:?}"))
                    .or_default()
                    .push(Chunk::from_arrow_msg(&arrow).unwrap());
            }
            LogMsg::BlueprintActivationCommand(cmd) if cmd.make_active => {
                active = Some(format!("{:?}", cmd.blueprint_id));
            }
            _ => {}
        }
    }
    let active = active.expect("the file activates a blueprint");
    stores
        .remove(&active)
        .expect("the active blueprint is in the file")
}

/// The time range every linked time axis shows (the `TimeAxis` view range that no view of
/// its own carries: the viewer's global one), ns: `(start, end)`.
fn linked_time_range(path: &Path) -> Option<(i64, i64)> {
    use rerun::external::re_sdk_types::blueprint::archetypes::TimeAxis;
    use rerun::external::re_sdk_types::blueprint::components::TimeRange;
    use rerun::external::re_sdk_types::datatypes::TimeRangeBoundary;
    let at = |b: &TimeRangeBoundary| match b {
        TimeRangeBoundary::Absolute(t) => Some(t.0),
        _ => None,
    };
    active_blueprint(path)
        .iter()
        .filter(|c| c.entity_path().to_string().ends_with("/TimeAxis"))
        .flat_map(|c| c.iter_component::<TimeRange>(TimeAxis::descriptor_view_range().component))
        .flat_map(|batch| batch.to_vec())
        .filter_map(|r| Some((at(&r.0.start)?, at(&r.0.end)?)))
        .last()
}

/// The views of the blueprint the `.rrd` at `path` activates last (`view/<id>` and
/// `view/<id>/ViewContents` of that blueprint store).
fn blueprint_views(path: &Path) -> Vec<BlueprintView> {
    use rerun::external::re_sdk_types::blueprint::archetypes::{
        PlotLegend, ScalarAxis, TimeAxis, ViewBlueprint, ViewContents,
    };
    use rerun::external::re_sdk_types::blueprint::components::{Corner2D, LinkAxis};
    let text = |chunk: &Chunk, component| -> Vec<String> {
        chunk
            .iter_slices::<String>(component)
            .flatten()
            .map(|s| s.as_str().to_string())
            .collect()
    };
    let mut views: BTreeMap<String, BlueprintView> = BTreeMap::new();
    for chunk in active_blueprint(path) {
        let path = chunk.entity_path().to_string();
        let parts: Vec<&str> = path.trim_start_matches('/').split('/').collect();
        match parts.as_slice() {
            ["view", id] => {
                let v = views.entry(id.to_string()).or_default();
                let class = ViewBlueprint::descriptor_class_identifier().component;
                let origin = ViewBlueprint::descriptor_space_origin().component;
                let name = ViewBlueprint::descriptor_display_name().component;
                if let Some(c) = text(&chunk, class).pop() {
                    v.class = c;
                }
                if let Some(o) = text(&chunk, origin).pop() {
                    v.origin = o;
                }
                if let Some(n) = text(&chunk, name).pop() {
                    v.name = n;
                }
            }
            ["view", id, "ViewContents"] => {
                let query = ViewContents::descriptor_query().component;
                views.entry(id.to_string()).or_default().queries = text(&chunk, query);
            }
            ["view", id, "ScalarAxis"] => {
                let range = ScalarAxis::descriptor_range().component;
                if let Some(r) = last::<rerun::components::Range1D>(&chunk, range) {
                    views.entry(id.to_string()).or_default().y_range = Some(r.0 .0);
                }
            }
            ["view", id, "TimeAxis"] => {
                // The global range's own entity carries no link: no view is made for it.
                let link = TimeAxis::descriptor_link().component;
                if let Some(l) = last::<LinkAxis>(&chunk, link) {
                    views.entry(id.to_string()).or_default().time_link = Some(format!("{l:?}"));
                }
            }
            ["view", id, "PlotLegend"] => {
                let corner = PlotLegend::descriptor_corner().component;
                if let Some(c) = last::<Corner2D>(&chunk, corner) {
                    views.entry(id.to_string()).or_default().legend = Some(format!("{c:?}"));
                }
            }
            _ => {}
        }
    }
    views.into_values().collect()
}

/// Every entity of the recording store with the components it carries data for.
fn entity_components(path: &Path) -> BTreeMap<EntityPath, BTreeSet<String>> {
    let mut out: BTreeMap<EntityPath, BTreeSet<String>> = BTreeMap::new();
    for c in chunks(path) {
        out.entry(c.entity_path().clone())
            .or_default()
            .extend(c.component_descriptors().map(|d| d.component.to_string()));
    }
    out
}

/// The component a view of `class` needs at least one matched entity to carry.
fn data_component(class: &str) -> Option<&'static str> {
    match class {
        "TimeSeries" => Some("Scalars:scalars"),
        "TextLog" => Some("TextLog:text"),
        "TextDocument" => Some("TextDocument:text"),
        "Graph" => Some("GraphNodes:node_ids"),
        _ => None,
    }
}

/// What in `views` matches nothing in `entities`, one line per problem: a view whose origin
/// has no entity under it, or an inclusion expression (after `$origin` substitution, with
/// rerun's own rule semantics) that matches no entity carrying the view's data component.
fn unmatched(
    views: &[BlueprintView],
    entities: &BTreeMap<EntityPath, BTreeSet<String>>,
) -> Vec<String> {
    let mut problems = Vec::new();
    for v in views {
        let origin = EntityPath::parse_forgiving(&v.origin);
        if !entities.keys().any(|e| e.starts_with(&origin)) {
            problems.push(format!("{:?}: origin {} has no entity", v.name, v.origin));
        }
        let subs = EntityPathSubs::new_with_origin(&origin);
        let filter = EntityPathFilter::from_query_expressions(v.queries.iter().map(String::as_str));
        for (rule, effect) in filter.rules() {
            if *effect != RuleEffect::Include {
                continue;
            }
            let hit = ResolvedEntityPathRule::parse_strict(rule, &subs).is_ok_and(|r| {
                entities.iter().any(|(e, comps)| {
                    r.matches(e) && data_component(&v.class).is_none_or(|c| comps.contains(c))
                })
            });
            if !hit {
                problems.push(format!("{:?}: {} matches nothing", v.name, &**rule));
            }
        }
    }
    problems
}

pub(crate) fn check_views(path: &Path) -> Vec<BlueprintView> {
    let views = blueprint_views(path);
    let problems = unmatched(&views, &entity_components(path));
    assert!(problems.is_empty(), "{problems:#?}");
    let queries: Vec<String> = views.iter().flat_map(|v| v.queries.clone()).collect();
    crate::glance::check_at_a_glance(path, &queries);
    let all = chunks(path);
    // Every plot's time axis is linked to the one range, which shows the whole run with room
    // at both ends, so the last label reads whole ("+10s", not "+1").
    let (start, end) = linked_time_range(path).expect("a range for the linked time axes");
    let ends = all
        .iter()
        .flat_map(|c| {
            c.timelines()
                .iter()
                .filter(|(name, _)| ["sim_time", "wall_time"].contains(&name.as_str()))
                .flat_map(|(_, t)| t.times_raw().to_vec())
                .collect::<Vec<_>>()
        })
        .fold((i64::MAX, i64::MIN), |(a, b), t| (a.min(t), b.max(t)));
    assert!(
        start < ends.0.min(0) && end > ends.1,
        "the linked range {start}..{end} leaves no room around the run's {ends:?}"
    );
    for v in views.iter().filter(|v| v.class == "TimeSeries") {
        assert_eq!(v.time_link.as_deref(), Some("LinkToGlobal"), "{v:?}");
        assert!(
            v.legend.is_some(),
            "{:?}: its legend's corner is chosen",
            v.name
        );
        let [lo, hi] = v
            .y_range
            .unwrap_or_else(|| panic!("{:?} has no y range in the final layout", v.name));
        // A range the stock viewer labels above "0" alone: a step of a power of ten that
        // fits in it, at most 7 of them across. In the pictures (1600x900) a plot of the
        // four-plot column labels the cart's 6.96 steps (±3.48 m), one of the five-plot
        // column 5.2 but not 6.96 (`recording::label_top` keeps those at 5.5 and under); a
        // latency fitted to 0–80 ms (9.65 steps of 10) showed "0" alone.
        let labelled = (-12..=12).any(|k| {
            let step = 10f64.powi(k);
            step <= hi.max(-lo) && (hi - lo) / step <= 7.0
        });
        assert!(labelled, "{:?}: no labelled step in {lo}..{hi}", v.name);
        let values: Vec<f64> = all
            .iter()
            .filter(|c| v.queries.contains(&c.entity_path().to_string()))
            .flat_map(|c| c.iter_slices::<f64>(rerun::Scalars::descriptor_scalars().component))
            .flat_map(|batch| batch.to_vec())
            .collect();
        assert!(!values.is_empty(), "{:?} shows no samples", v.name);
        let (min, max) = values
            .iter()
            .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), x| {
                (a.min(*x), b.max(*x))
            });
        assert!(
            lo < min && max < hi,
            "{:?}: data {min}..{max} touches the edge of {lo}..{hi}",
            v.name
        );
    }
    views
}

fn classes(views: &[BlueprintView]) -> BTreeSet<&str> {
    views.iter().map(|v| v.class.as_str()).collect()
}

#[test]
fn every_view_matches_data_in_a_virtual_run_and_a_fall() {
    let dir = tempfile::tempdir().unwrap();
    let balanced = dir.path().join("balanced.rrd");
    record(&balanced, &virtual_cfg(), None);
    let views = check_views(&balanced);
    for class in ["3D", "Graph", "TextDocument", "TextLog", "TimeSeries"] {
        assert!(
            classes(&views).contains(class),
            "no {class} view: {views:#?}"
        );
    }
    assert_eq!(views.len(), 12, "{views:#?}");
    assert!(
        !views.iter().any(|v| v.name.contains("lateness")),
        "no lateness under the virtual clock"
    );
    let fall = dir.path().join("fall.rrd");
    let mut five = virtual_cfg();
    five.set_control_hz(5.0).unwrap();
    let m = record(&fall, &five, None);
    assert!(m.fell_at_s.is_some(), "5 Hz falls");
    let views = check_views(&fall);
    // The fall is marked on the pole-angle plot (a balanced run has no such series).
    let angle = views
        .iter()
        .find(|v| v.name.starts_with("pole angle"))
        .expect("an angle view");
    assert!(
        angle.queries.contains(&"/plant/fall".to_string()),
        "{angle:?}"
    );
    let balanced_angle = blueprint_views(&balanced)
        .into_iter()
        .find(|v| v.name.starts_with("pole angle"))
        .unwrap();
    assert!(!balanced_angle.queries.contains(&"/plant/fall".to_string()));
    // …and in 3D, from the fall on: the pole drawn red over the orange one, labelled.
    let fallen: Vec<Chunk> = chunks(&fall)
        .into_iter()
        .filter(|c| {
            c.entity_path()
                .to_string()
                .starts_with("/world/cart/pole/fallen")
        })
        .collect();
    assert_eq!(
        fallen.iter().map(|c| c.num_rows()).sum::<usize>(),
        2,
        "the red pole and its label"
    );
    let at_ns = *times_on(&fallen[0], "sim_time")
        .first()
        .expect("the fall's time");
    let fell_at_s = m.fell_at_s.unwrap();
    assert!(
        (at_ns as f64 / 1e9 - fell_at_s).abs() < 1e-9,
        "{at_ns} ns vs {fell_at_s} s"
    );
    assert!(
        !chunks(&balanced).iter().any(|c| c
            .entity_path()
            .to_string()
            .starts_with("/world/cart/pole/fallen")),
        "a balanced run has no fallen pole"
    );
}

/// A run with executors and compute times records the executor timeline (a lane per node,
/// raised while its tick holds a thread), each tick's response time and the skipped ticks,
/// each a view of the stock viewer; the chapter's run has none of them.
#[test]
fn an_executors_run_records_its_timeline_response_times_and_skipped_ticks() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("exec.rrd");
    let mut g =
        ratelab::graph::GraphSpec::load(&crate::repo("graphs/cartpole-executors.toml")).unwrap();
    g.set_executor(ratelab::executor::ExecutorOverride::parse("single_threaded").unwrap());
    let cfg = RunConfig {
        graph: g,
        ..virtual_cfg().with_duration_ms(3000)
    };
    let m = record(&path, &cfg, None);
    let views = check_views(&path);
    assert_eq!(views.len(), 15, "the chapter's 12 and three: {views:#?}");
    for (title, series) in [
        ("executor timeline", "executor_lane"),
        ("response time", "response_ms"),
        ("skipped ticks", "skipped_ticks"),
    ] {
        let v = views
            .iter()
            .find(|v| v.name.starts_with(title))
            .unwrap_or_else(|| panic!("no {title} view: {views:#?}"));
        let want: Vec<String> = ["sensor", "policy", "actuator"]
            .iter()
            .map(|n| format!("/nodes/{n}/{series}"))
            .collect();
        assert_eq!(v.queries, want, "{title}");
    }
    // The policy's lane: raised 30 ms each tick (its compute time), at rank 1.
    let all = chunks(&path);
    let lane: Vec<f64> = all
        .iter()
        .filter(|c| c.entity_path().to_string() == "/nodes/policy/executor_lane")
        .flat_map(|c| c.iter_slices::<f64>(rerun::Scalars::descriptor_scalars().component))
        .flat_map(|b| b.to_vec())
        .collect();
    assert!(lane.contains(&1.0) && lane.contains(&1.8), "{lane:?}");
    // The skipped ticks end where metrics.json ends them.
    let skipped: Vec<f64> = all
        .iter()
        .filter(|c| c.entity_path().to_string() == "/nodes/sensor/skipped_ticks")
        .flat_map(|c| c.iter_slices::<f64>(rerun::Scalars::descriptor_scalars().component))
        .flat_map(|b| b.to_vec())
        .collect();
    let x = m.nodes["sensor"].exec.as_ref().unwrap();
    assert!(x.skipped_ticks > 0);
    assert_eq!(
        skipped.iter().copied().fold(0.0, f64::max),
        x.skipped_ticks as f64
    );
    // Trouble placed in time: the first skipped tick is a warning at the release that came
    // late, and the total a warning at the end (#54: such a run recorded none).
    let events = events_with_levels(&path);
    let warned = |needle: &str| {
        events
            .iter()
            .any(|(level, text)| text.contains(needle) && level == "WARN")
    };
    assert!(
        warned("tick(s): its timer's periods passed while its executor's thread was busy"),
        "{events:?}"
    );
    assert!(
        warned(&format!(
            "node sensor skipped {} tick(s) in all (ticked {} times at 50 Hz set)",
            x.skipped_ticks, m.nodes["sensor"].ticks
        )),
        "{events:?}"
    );
}

#[test]
fn every_view_matches_data_in_a_real_clock_run() {
    let _machine = crate::machine::alone();
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("real.rrd");
    record(
        &path,
        &RunConfig {
            clock: ClockKind::Real,
            ..RunConfig::default().with_duration_ms(1500)
        },
        None,
    );
    let views = check_views(&path);
    assert_eq!(
        views.len(),
        13,
        "the virtual run's 12 and lateness: {views:#?}"
    );
    let lateness = views
        .iter()
        .find(|v| v.name.contains("lateness"))
        .expect("a lateness view under the real clock");
    assert_eq!(lateness.queries.len(), 3, "{lateness:?}");
    // The real clock's time is wall time since the start, and the timeline says so.
    let timelines = timeline_names(&chunks(&path));
    assert!(
        timelines.contains("wall_time") && !timelines.contains("sim_time"),
        "{timelines:?}"
    );
}

#[test]
fn a_query_that_matches_nothing_is_caught() {
    // The blueprint before issue #11: `*` inside a path is not a wildcard in rerun.
    use rerun::blueprint::{Blueprint, TimeSeriesView, Vertical};
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("bad.rrd");
    let rec = rerun::RecordingStreamBuilder::new("ratelab")
        .with_blueprint(Blueprint::new(Vertical::new([
            TimeSeriesView::new("bus: dropped")
                .with_contents(["/bus/*/dropped"])
                .into(),
            TimeSeriesView::new("obs dropped")
                .with_contents(["/bus/obs/dropped"])
                .into(),
            TimeSeriesView::new("bus").with_origin("/bus").into(),
        ])))
        .save(&path)
        .unwrap();
    rec.set_time_sequence("control_step", 1);
    rec.log("bus/obs/dropped", &rerun::Scalars::single(0.0))
        .unwrap();
    rec.flush_blocking().unwrap();
    drop(rec);
    let views = blueprint_views(&path);
    assert_eq!(views.len(), 3, "{views:#?}");
    let problems = unmatched(&views, &entity_components(&path));
    assert_eq!(
        problems,
        [r#""bus: dropped": /bus/*/dropped matches nothing"#],
        "only the wildcard query fails"
    );
}

#[test]
fn mid_run_changes_are_events_graph_labels_and_marks() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("changes.rrd");
    let at = |s: u64, command| TimedCommand {
        at_ns: s * 1_000_000_000,
        command,
    };
    record_with(
        &path,
        &virtual_cfg(),
        None,
        vec![
            at(3, Command::SetQueueDepth { depth: 5 }),
            at(5, Command::SetControlHz { hz: 10.0 }),
        ],
    );
    check_views(&path);
    let all = chunks(&path);
    let of = |entity: &str| -> Vec<&Chunk> {
        all.iter()
            .filter(|c| c.entity_path().to_string() == entity)
            .collect()
    };
    let events: Vec<String> = of("/events")
        .into_iter()
        .flat_map(|c| c.iter_slices::<String>(rerun::TextLog::descriptor_text().component))
        .flatten()
        .map(|s| s.as_str().to_string())
        .collect();
    for needle in [
        "/obs depth 1 → 5; /action depth 1 → 5",
        "policy rate 50 → 10 Hz",
    ] {
        assert!(
            events.iter().any(|e| e == needle),
            "{needle} in {events:#?}"
        );
    }
    let marks: usize = of("/marks/change")
        .into_iter()
        .filter(|c| !c.is_static())
        .map(|c| c.num_rows())
        .sum();
    assert_eq!(marks, 2, "the two changes");
    let labels = graph_labels(&all);
    assert!(labels.iter().any(|l| l == "/obs · depth 5"), "{labels:?}");
    assert!(labels.iter().any(|l| l == "policy · 10 Hz"), "{labels:?}");
}

#[test]
fn spawn_with_a_viewer_that_cannot_start_still_writes_the_whole_file() {
    // A `rerun` on PATH that exits at once, as the real one does without a display. The
    // live sink used to queue at most 100 messages for it and then block the file too.
    use std::os::unix::fs::PermissionsExt;
    let dir = tempfile::tempdir().unwrap();
    let bin = dir.path().join("bin");
    std::fs::create_dir(&bin).unwrap();
    let fake = bin.join("rerun");
    std::fs::write(&fake, "#!/bin/sh\nexit 1\n").unwrap();
    std::fs::set_permissions(&fake, std::fs::Permissions::from_mode(0o755)).unwrap();
    let path = dir.path().join("spawn.rrd");
    let mut child = std::process::Command::new(env!("CARGO_BIN_EXE_ratelab"))
        .args(["run", "--clock", "virtual", "--spawn", "--record"])
        .arg(&path)
        .env("PATH", format!("{}:/usr/bin:/bin", bin.display()))
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    let deadline = std::time::Instant::now() + std::time::Duration::from_secs(60);
    while child.try_wait().unwrap().is_none() {
        if std::time::Instant::now() > deadline {
            child.kill().unwrap();
            panic!("the run hangs on a viewer that never started");
        }
        std::thread::sleep(std::time::Duration::from_millis(50));
    }
    let out = child.wait_with_output().unwrap();
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(
        out.status.success(),
        "{stdout}{}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert!(stdout.contains("BALANCED"), "{stdout}");
    assert_eq!(angle_rows(&chunks(&path)), 501);
    check_views(&path);
}

#[test]
fn a_brain_swap_is_an_event_and_a_mark() {
    // The lab session reports a brain swap (which the graph cannot see) with
    // `Recording::change`, at the instant it applied it.
    struct SwapAt(Recording, u64);
    impl ratelab::graph::StepObserver for SwapAt {
        fn on_step(&mut self, r: &ratelab::runlog::StepRecord) {
            if r.step == self.1 {
                self.0.change(r.t, "brain → scripted");
            }
        }
    }
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("swap.rrd");
    let cfg = virtual_cfg().with_duration_ms(2000);
    let (rec, _) = Recording::create(&path, &cfg, "scripted", &RecordOptions::default()).unwrap();
    let opts = RunOptions {
        observers: vec![
            Box::new(Recorded::new(&rec)),
            Box::new(SwapAt(rec.clone(), 40)),
        ],
        ..RunOptions::new()
    };
    let r = run(&cfg, Box::new(Scripted), opts).unwrap();
    rec.finish(&r.metrics, &r.end).unwrap();
    drop(rec);
    let all = chunks(&path);
    let events: Vec<String> = all
        .iter()
        .filter(|c| c.entity_path().to_string() == "/events")
        .flat_map(|c| c.iter_slices::<String>(rerun::TextLog::descriptor_text().component))
        .flatten()
        .map(|s| s.as_str().to_string())
        .collect();
    assert!(
        events.iter().any(|e| e == "brain → scripted"),
        "{events:#?}"
    );
    let marks: Vec<i64> = all
        .iter()
        .filter(|c| !c.is_static() && c.entity_path().to_string() == "/marks/change")
        .flat_map(|c| times_on(c, "control_step"))
        .collect();
    assert_eq!(marks, [40], "the swap");
    check_views(&path);
}

/// The screenshot's QoS run: the safety graph with `--link /cmd:loss=0.2 --qos
/// /cmd:deadline_ms=30,on_deadline_missed=zero --lease policy=60 --stall policy@2+0.3`.
fn qos_cfg() -> RunConfig {
    let mut graph = ratelab::graph::GraphSpec::load(
        &PathBuf::from(crate::REPO).join("graphs/cartpole-safety.toml"),
    )
    .unwrap();
    graph.set_qos("/cmd", "loss=0.2").unwrap();
    graph
        .set_qos("/cmd", "deadline_ms=30,on_deadline_missed=zero")
        .unwrap();
    graph.set_lease("policy", 60.0).unwrap();
    RunConfig {
        graph,
        faults: vec![ratelab::qos::Fault::parse("policy@2+0.3", false).unwrap()],
        ..virtual_cfg()
    }
}

/// The event lines of a recording, each with its level (`INFO`, `WARN`, …), in the order
/// they were logged.
pub(crate) fn events_with_levels(path: &Path) -> Vec<(String, String)> {
    let mut out = Vec::new();
    for c in chunks(path)
        .into_iter()
        .filter(|c| c.entity_path().to_string() == "/events")
    {
        let column = |component| -> Vec<String> {
            c.iter_slices::<String>(component)
                .map(|s| {
                    s.first()
                        .map(|x| x.as_str().to_string())
                        .unwrap_or_default()
                })
                .collect()
        };
        let texts = column(rerun::TextLog::descriptor_text().component);
        let levels = column(rerun::TextLog::descriptor_level().component);
        assert_eq!(texts.len(), levels.len(), "every event has its level");
        out.extend(levels.into_iter().zip(texts));
    }
    out
}

/// The event lines of a recording with their `sim_time` (ns) and `control_step`.
pub(crate) fn events_with_times(path: &Path) -> Vec<(i64, i64, String)> {
    events_on(path, "sim_time")
}

/// The event lines of a recording with their time on `timeline` (`sim_time`, or a real-clock
/// run's `wall_time`; ns) and `control_step`, in time order.
pub(crate) fn events_on(path: &Path, timeline: &str) -> Vec<(i64, i64, String)> {
    let mut out = Vec::new();
    for c in chunks(path)
        .into_iter()
        .filter(|c| c.entity_path().to_string() == "/events")
    {
        // A chunk not on a timeline (static) reads 0 there.
        let col = |name: &str| -> Vec<i64> {
            let times = times_on(&c, name);
            if times.is_empty() {
                vec![0; c.num_rows()]
            } else {
                times
            }
        };
        let (t, step) = (col(timeline), col("control_step"));
        let texts: Vec<String> = c
            .iter_slices::<String>(rerun::TextLog::descriptor_text().component)
            .map(|s| {
                s.first()
                    .map(|x| x.as_str().to_string())
                    .unwrap_or_default()
            })
            .collect();
        for (i, text) in texts.into_iter().enumerate() {
            out.push((t[i], step[i], text));
        }
    }
    out.sort();
    out
}

/// The run times (s) the last `when` document lists its events at, in its order.
pub(crate) fn when_times(path: &Path) -> Vec<f64> {
    let doc = chunks(path)
        .iter()
        .filter(|c| c.entity_path().to_string() == "/when")
        .flat_map(|c| {
            c.iter_slices::<String>(rerun::TextDocument::descriptor_text().component)
                .flatten()
                .map(|s| s.as_str().to_string())
                .collect::<Vec<_>>()
        })
        .last()
        .expect("a `when` document");
    doc.lines()
        .filter_map(|l| l.strip_prefix("- ")?.split_once(" s ")?.0.parse().ok())
        .collect()
}

/// The last value of a scalar series and its number of samples.
fn last_scalar(all: &[Chunk], entity: &str) -> Option<(f64, usize)> {
    let mut samples: Vec<(i64, f64)> = Vec::new();
    for c in all
        .iter()
        .filter(|c| !c.is_static() && c.entity_path().to_string() == entity)
    {
        let steps = times_on(c, "control_step");
        let values: Vec<f64> = c
            .iter_slices::<f64>(rerun::Scalars::descriptor_scalars().component)
            .flat_map(|b| b.to_vec())
            .collect();
        samples.extend(steps.into_iter().zip(values));
    }
    samples.sort_by_key(|(s, _)| *s);
    samples.last().map(|(_, v)| (*v, samples.len()))
}

#[test]
fn a_qos_run_plots_its_counters_and_logs_its_events() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("qos.rrd");
    let m = record(&path, &qos_cfg(), None);
    let cmd = &m.topics["/cmd"];
    let all = chunks(&path);
    // Each counter metrics.json reports is a series under the topic's bus entity, one sample
    // per step, ending at the run's total; no series for a counter the QoS cannot move.
    assert_eq!(
        cmd.qos_counters.keys().collect::<Vec<_>>(),
        [
            "lost",
            "offered_deadline_missed",
            "requested_deadline_missed"
        ]
    );
    for (key, total) in &cmd.qos_counters {
        let (last, n) = last_scalar(&all, &format!("/bus/cmd/{key}"))
            .unwrap_or_else(|| panic!("no /bus/cmd/{key} series"));
        assert_eq!(n as u64, m.steps, "{key}: one sample per step");
        assert_eq!(last, *total as f64, "{key}");
    }
    assert!(cmd.qos_counters["lost"] > 50, "{cmd:?}");
    assert!(
        cmd.qos_counters["requested_deadline_missed"] > 20,
        "{cmd:?}"
    );
    for absent in [
        "/bus/cmd/expired",
        "/bus/cmd/refused",
        "/bus/cmd/retransmitted",
        "/bus/obs/lost",
    ] {
        assert!(last_scalar(&all, absent).is_none(), "{absent} is logged");
    }
    let (not_alive, _) = last_scalar(&all, "/nodes/policy/not_alive").expect("policy has a lease");
    assert_eq!(not_alive, 1.0, "one stall, one loss");
    assert!(
        last_scalar(&all, "/nodes/sensor/not_alive").is_none(),
        "no lease, no series"
    );
    // Events: one per rise of the requested deadline counter, at the step that saw it; the
    // stall's loss of liveliness at the instant the lease ran out (last tick 1.98 s + 60 ms)
    // and the return at the stall's end.
    let events = events_with_times(&path);
    let missed: Vec<&(i64, i64, String)> = events
        .iter()
        .filter(|(_, _, e)| e.starts_with("deadline missed on /cmd: requested +"))
        .collect();
    assert!(
        !missed.is_empty() && missed.len() as u64 <= cmd.qos_counters["requested_deadline_missed"]
    );
    let total = format!("({} in all)", cmd.qos_counters["requested_deadline_missed"]);
    assert!(missed.last().unwrap().2.ends_with(&total), "{missed:?}");
    // A burst of misses is one line: a miss less than a second after the last line waits
    // for the next one, so the two lease events are not buried (issue 25: 84 lines).
    for pair in missed.windows(2).take(missed.len().saturating_sub(2)) {
        assert!(
            pair[1].0 - pair[0].0 >= 1_000_000_000,
            "lines under a second apart: {missed:#?}"
        );
    }
    assert!(missed.len() <= 11, "at most a line a second: {missed:#?}");
    // Trouble reads as trouble: the misses, the stall and the lost liveliness are warnings.
    let levels = events_with_levels(&path);
    let level_of = |starts: &str| -> Vec<&str> {
        levels
            .iter()
            .filter(|(_, e)| e.starts_with(starts))
            .map(|(l, _)| l.as_str())
            .collect()
    };
    for (starts, level) in [
        ("deadline missed on /cmd", "WARN"),
        ("injected stall: node policy", "WARN"),
        ("node policy not alive", "WARN"),
        ("node policy alive again", "INFO"),
        ("start: ", "INFO"),
    ] {
        let found = level_of(starts);
        assert!(
            !found.is_empty() && found.iter().all(|l| *l == level),
            "{starts:?} should be {level}: {levels:#?}"
        );
    }
    let at = |text: &str| -> (i64, i64) {
        let (t, s, _) = events
            .iter()
            .find(|(_, _, e)| e == text)
            .unwrap_or_else(|| panic!("no '{text}' in {events:#?}"));
        (*t, *s)
    };
    let (lost_t, lost_step) = at("node policy not alive (lease 60 ms)");
    assert_eq!(lost_t, 2_040_000_000);
    assert!(
        lost_step as f64 * 0.02 >= 2.04,
        "seen at or after the instant: {lost_step}"
    );
    assert_eq!(at("node policy alive again").0, 2_300_000_000);
    // The graph labels the topic with its QoS in short, a part a line (the chapter's
    // keep-last/latest goes without saying).
    let labels = graph_labels(&all);
    assert!(
        labels
            .iter()
            .any(|l| l == "/cmd · depth 1\ndl 30 ms zero\nlink 20%"),
        "{labels:?}"
    );
    assert!(labels.iter().any(|l| l == "/obs · depth 1"), "{labels:?}");
}

#[test]
fn every_view_matches_data_in_a_qos_run_and_the_counters_have_a_view() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("qos.rrd");
    record(&path, &qos_cfg(), None);
    let views = check_views(&path);
    assert_eq!(
        views.len(),
        14,
        "the chapter's 12, the QoS counters and liveliness: {views:#?}"
    );
    let qos = views
        .iter()
        .find(|v| v.name.starts_with("QoS"))
        .expect("a QoS view");
    assert_eq!(
        qos.queries,
        [
            "/bus/cmd/lost",
            "/bus/cmd/offered_deadline_missed",
            "/bus/cmd/requested_deadline_missed",
        ]
    );
    // The not-alive count has a plot (and a scale) of its own.
    let alive = views
        .iter()
        .find(|v| v.name.starts_with("liveliness"))
        .expect("a liveliness view");
    assert_eq!(alive.queries, ["/nodes/policy/not_alive"]);
    // The injected stall is an event, a warning, at its start, and its end one too.
    let events: Vec<String> = chunks(&path)
        .iter()
        .filter(|c| c.entity_path().to_string() == "/events")
        .flat_map(|c| c.iter_slices::<String>(rerun::TextLog::descriptor_text().component))
        .flatten()
        .map(|s| s.as_str().to_string())
        .collect();
    assert!(
        events
            .iter()
            .any(|e| e.starts_with("injected stall: node policy does no work")),
        "{events:?}"
    );
    assert!(events
        .iter()
        .any(|e| e == "node policy resumes after its stall"));
    // The watchdog: a stalled safety node starves /cmd past its deadline; the recording
    // says so and does not call it a fall.
    let stop = dir.path().join("stop.rrd");
    let mut cfg = qos_cfg();
    cfg.graph
        .set_qos("/cmd", "loss=0,on_deadline_missed=stop")
        .unwrap();
    cfg.faults = vec![ratelab::qos::Fault::parse("safety@2+0.3", false).unwrap()];
    let m = record(&stop, &cfg, None);
    let verdict = m
        .stopped_by_watchdog
        .clone()
        .expect("the watchdog stops it");
    check_views(&stop);
    let events = events_with_times(&stop);
    let end = events
        .iter()
        .rev()
        .find(|(_, _, e)| e.starts_with("end:"))
        .unwrap();
    assert!(end.2.starts_with("end: stopped by watchdog"), "{events:#?}");
    assert!(
        events.iter().any(|(t, _, e)| *e == verdict && *t == end.0),
        "{verdict} at the end in {events:#?}"
    );
    assert!(!events
        .iter()
        .any(|(_, _, e)| e.contains("FELL") || e.contains("fell")));
}

/// `launch --processes --record`: the launcher records what it watches of the processes:
/// every actuator step (from the robot's process), each topic's counters from the process
/// that holds them, the launcher's lines as events, the merged summary; every view of the
/// layout finds its data.
#[test]
fn a_launch_across_processes_records_every_step() {
    let _m = crate::machine::shared();
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("procs.rrd");
    let o = ratelab(
        &[
            "launch",
            "--processes",
            "--clock",
            "virtual",
            "--duration",
            "2",
            "--record",
            path.to_str().unwrap(),
            "--out",
            dir.path().to_str().unwrap(),
        ],
        dir.path(),
    );
    let out = String::from_utf8_lossy(&o.stdout);
    assert!(
        o.status.success(),
        "{out}{}",
        String::from_utf8_lossy(&o.stderr)
    );
    assert!(out.contains("recording: "), "{out}");
    let m: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.path().join("metrics.json")).unwrap())
            .unwrap();
    let all = chunks(&path);
    assert_eq!(angle_rows(&all), m["steps"].as_u64().unwrap());
    // /obs is held by the policy's process: the recording shows its counters (as that
    // process last published them), not the robot's forwarding copy.
    let (published, n) = last_scalar(&all, "/bus/obs/published").unwrap();
    assert_eq!(n as u64, m["steps"].as_u64().unwrap());
    let total = m["topics"]["/obs"]["published"].as_f64().unwrap();
    assert!(
        published > 0.0 && published <= total,
        "{published} of {total}"
    );
    let views = check_views(&path);
    // Each topic's msg/s starts at its rate: a topic counted by another process has no
    // count before that process's first figures, which read as 0 msg/s and then a jump.
    for topic in ["obs", "action"] {
        let rates = sim_series(&all, &format!("/bus/{topic}/msg_per_s"));
        let (t, first) = rates[0];
        assert!(
            (45.0..=55.0).contains(&first),
            "/{topic} starts at {first} msg/s at {t} ns: {:?}",
            &rates[..rates.len().min(5)]
        );
    }
    // What makes it a launch: each node's process in the node graph, each crossing topic's
    // time on the wire (a view of its own), the placement and the wire in the summary.
    let wire = views
        .iter()
        .find(|v| v.name.starts_with("over the wire"))
        .expect("a wire view");
    for q in [
        "/bus/obs/wire_p50_us",
        "/bus/obs/wire_p99_us",
        "/bus/action/wire_p50_us",
        "/bus/action/wire_p99_us",
    ] {
        assert!(wire.queries.contains(&q.to_string()), "{wire:?}");
    }
    let (p50, n) = last_scalar(&all, "/bus/obs/wire_p50_us").unwrap();
    assert!(p50 > 0.0 && n > 0, "{p50} µs, {n} values");
    let texts = |entity: &str, component| -> Vec<String> {
        all.iter()
            .filter(|c| c.entity_path().to_string() == entity)
            .flat_map(|c| c.iter_slices::<String>(component).collect::<Vec<_>>())
            .flat_map(|s| s.iter().map(|x| x.as_str().to_string()).collect::<Vec<_>>())
            .collect()
    };
    let labels = texts("/graph", rerun::GraphNodes::descriptor_labels().component);
    for l in [
        "sensor · 50 Hz\nprocess robot",
        "policy · 50 Hz\nprocess policy",
        "actuator · 50 Hz\nprocess robot",
    ] {
        assert!(labels.iter().any(|x| x == l), "{l:?} in {labels:?}");
    }
    let summary = texts("/summary", rerun::TextDocument::descriptor_text().component)
        .pop()
        .unwrap();
    assert!(
        summary.contains("processes: robot [sensor, actuator], policy [policy]")
            && summary.contains("wire /obs into 'policy': ")
            && summary.contains("wire /action into 'robot': "),
        "{summary}"
    );
    let events = events_with_times(&path);
    assert!(
        events.iter().any(|(_, _, e)| e.starts_with("end: ")),
        "no end event: {events:?}"
    );
    // The launcher's last word arrived before it left: its going is not taken for a death.
    assert!(
        !events
            .iter()
            .any(|(_, _, e)| e.contains("launcher is gone")),
        "{events:?}"
    );
}

/// The colour and width a series line is drawn with (`SeriesLines`), as logged for
/// `entity`: `(rgba, width px)`.
fn series_style(all: &[Chunk], entity: &str) -> Option<(u32, f32)> {
    let of = |c: &Chunk, component| -> Option<u32> {
        c.iter_slices::<u32>(component)
            .flat_map(|s| s.to_vec())
            .last()
    };
    let c = all.iter().find(|c| {
        c.entity_path().to_string() == entity && c.num_rows() > 0 && {
            of(c, rerun::SeriesLines::descriptor_colors().component).is_some()
        }
    })?;
    let color = of(c, rerun::SeriesLines::descriptor_colors().component)?;
    let width = c
        .iter_slices::<f32>(rerun::SeriesLines::descriptor_widths().component)
        .flat_map(|s| s.to_vec())
        .last()?;
    Some((color, width))
}

/// A topic has one colour in every plot, and where two topics' lines coincide (the
/// chapter's: both at 50 Hz, none dropped) the first drawn is wider, so both show (#25:
/// `/action` hid under `/obs`, and colours changed between graphs). Read from the reference
/// recording, which the code reproduces.
#[test]
fn a_topic_keeps_its_colour_in_every_plot_and_coinciding_lines_both_show() {
    let all = chunks(&reference());
    let mut colors = BTreeMap::new();
    for topic in ["obs", "action"] {
        let styles: Vec<(u32, f32)> = ["published", "dropped", "msg_per_s"]
            .iter()
            .map(|m| {
                let e = format!("/bus/{topic}/{m}");
                series_style(&all, &e).unwrap_or_else(|| panic!("no line style for {e}"))
            })
            .collect();
        assert!(
            styles.iter().all(|s| s.0 == styles[0].0),
            "/{topic}: one colour in every plot: {styles:?}"
        );
        colors.insert(topic, styles);
    }
    let (action, obs) = (&colors["action"], &colors["obs"]);
    assert_ne!(action[0].0, obs[0].0, "two topics, two colours");
    // Drawn in entity-path order, /action first: it is the wider in each plot.
    for (a, o) in action.iter().zip(obs) {
        assert!(a.1 > o.1, "/action {a:?} under /obs {o:?} would hide");
    }
}

/// The bus plots come with the actuator's steps; with the actuator killed at 1 s of a 3 s
/// run they still reach the run's end, at the totals the summary gives and the rate the
/// publishers kept (#25).
#[test]
fn the_bus_plots_reach_the_end_when_the_actuator_was_killed() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("kill.rrd");
    let mut cfg = virtual_cfg();
    cfg.duration = ratelab::Nanos(3_000_000_000);
    cfg.faults = vec![ratelab::qos::Fault::parse("actuator@1", true).unwrap()];
    let m = record(&path, &cfg, None);
    assert_eq!(m.topics["/action"].dropped, 100, "{:?}", m.topics);
    let all = chunks(&path);
    // The newest sample of a series by run time: (ns, value).
    let newest = |entity: &str| sim_series(&all, entity).last().copied();
    for (entity, topic, dropped) in [
        ("/bus/action", "/action", true),
        ("/bus/obs", "/obs", false),
    ] {
        let t = &m.topics[topic];
        assert_eq!(
            newest(&format!("{entity}/published")),
            Some((3_000_000_000, t.published as f64))
        );
        if dropped {
            assert_eq!(
                newest(&format!("{entity}/dropped")),
                Some((3_000_000_000, t.dropped as f64))
            );
        }
        // Both topics' publishers kept their 50 Hz after the kill: the msg/s plot reaches
        // the end at that rate, not at the kill.
        let (at, rate) = newest(&format!("{entity}/msg_per_s")).unwrap();
        assert_eq!(at, 3_000_000_000, "{entity}");
        assert!(
            (49.0..=51.0).contains(&rate),
            "{entity}: {rate} msg/s at the end"
        );
    }
    // Killed less than a window (1 s) before the end: no end point, whose quotient over a
    // short gap is noise; the plot ends at the last step (2.48 s).
    let path = dir.path().join("late-kill.rrd");
    cfg.faults = vec![ratelab::qos::Fault::parse("actuator@2.5", true).unwrap()];
    record(&path, &cfg, None);
    let newest_at = sim_series(&chunks(&path), "/bus/obs/msg_per_s")
        .last()
        .map(|(t, _)| *t);
    assert_eq!(newest_at, Some(2_480_000_000));
}

/// What a Python node prints goes into a recording too: one text log per node
/// (`log/<node>`), at the run time of the tick that wrote it, in a view of its own that the
/// final layout has only when something was written (the chapter's recording has none).
#[test]
fn what_a_python_node_writes_is_in_the_recording_per_node() {
    let dir = tempfile::tempdir().unwrap();
    let g = crate::loud_python_graph(dir.path(), "print('tick here')");
    let rrd = dir.path().join("loud.rrd");
    let o = std::process::Command::new(env!("CARGO_BIN_EXE_ratelab"))
        .args(["run", "--clock", "virtual", "--duration", "0.5", "--graph"])
        .arg(&g)
        .arg("--record")
        .arg(&rrd)
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let views = check_views(&rrd);
    let log = views
        .iter()
        .find(|v| v.name.starts_with("log"))
        .unwrap_or_else(|| panic!("no log view: {views:#?}"));
    assert_eq!(log.queries, ["/log/**"], "{log:?}");
    let lines: Vec<String> = chunks(&rrd)
        .iter()
        .filter(|c| c.entity_path().to_string() == "/log/policy")
        .flat_map(|c| c.iter_slices::<String>(rerun::TextLog::descriptor_text().component))
        .flat_map(|s| s.into_iter().map(|x| x.to_string()).collect::<Vec<_>>())
        .collect();
    assert_eq!(
        lines.len(),
        26,
        "a line a tick at 50 Hz over 0.5 s: {lines:?}"
    );
    assert!(lines.iter().all(|l| l == "tick here"), "{lines:?}");
}

/// A Python node says so on the node graph's label; a built-in node's label is its name and
/// rate alone.
#[test]
fn a_python_node_is_marked_as_one_in_the_node_graph() {
    ratelab::init(); // Python nodes or brains through the library, as a program runs them
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("python.rrd");
    let cfg = RunConfig {
        clock: ClockKind::Virtual,
        duration: ratelab::Nanos::SECOND,
        graph: ratelab::graph::GraphSpec::load(&crate::repo("graphs/cartpole-python.toml"))
            .unwrap(),
        ..RunConfig::default()
    };
    record(&path, &cfg, None);
    let labels = graph_labels(&chunks(&path));
    assert!(
        labels.iter().any(|l| l == "policy · 50 Hz\npython"),
        "{labels:?}"
    );
    assert!(labels.iter().any(|l| l == "sensor · 50 Hz"), "{labels:?}");
}

/// `--record-window FROM:UNTIL` (issue 51: a long run's recording bounded by what the user
/// asks): the plots hold that span of run time only, the recording says so (its settings,
/// an event at each edge, its summary), the events and the summary still cover the whole
/// run, and the file is a fraction of the whole run's.
#[test]
fn a_record_window_keeps_the_plots_of_that_span_and_says_so() {
    let dir = tempfile::tempdir().unwrap();
    let whole = dir.path().join("whole.rrd");
    let part = dir.path().join("part.rrd");
    let run = |extra: &[&str], path: &Path| {
        let mut args = vec!["run", "--clock", "virtual", "--duration", "60", "--record"];
        args.push(path.to_str().unwrap());
        args.extend_from_slice(extra);
        let o = ratelab(&args, dir.path());
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    };
    run(&[], &whole);
    run(&["--record-window", "20:25"], &part);
    let chunks = chunks(&part);
    let angle = sim_series(&chunks, "/plant/pole_angle_rad");
    let (first, last) = (angle.first().unwrap().0, angle.last().unwrap().0);
    assert!(
        (20_000_000_000..20_030_000_000).contains(&first),
        "first angle at {first} ns"
    );
    assert!(
        (24_970_000_000..=25_000_000_000).contains(&last),
        "last angle at {last} ns"
    );
    // Every step inside the window: the same rows as the whole run's there.
    let all = sim_series(&super::recording::chunks(&whole), "/plant/pole_angle_rad");
    assert!(
        all.len() > angle.len() * 10,
        "{} rows of the whole run",
        all.len()
    );
    let inside: Vec<_> = all
        .iter()
        .filter(|(t, _)| (20_000_000_000..=25_000_000_000).contains(t))
        .copied()
        .collect();
    assert_eq!(angle, inside);
    // It says so, and the events cover the whole run.
    let events = events_with_times(&part);
    let said = |needle: &str| {
        events
            .iter()
            .find(|(_, _, e)| e.contains(needle))
            .unwrap_or_else(|| panic!("no event '{needle}': {events:?}"))
            .0
    };
    assert_eq!(
        said("recording from here: the plots hold run time 20–25 s"),
        20_000_000_000
    );
    assert!(said("recording stops here") > 25_000_000_000);
    assert!(said("end:") >= 60_000_000_000, "{events:?}");
    let summary: String = chunks
        .iter()
        .filter(|c| c.entity_path().to_string() == "/summary")
        .flat_map(|c| {
            c.iter_slices::<String>(rerun::TextDocument::descriptor_text().component)
                .collect::<Vec<_>>()
        })
        .flat_map(|s| s.iter().map(|x| x.as_str().to_string()).collect::<Vec<_>>())
        .last()
        .unwrap();
    assert!(
        summary.contains("the plots hold run time 20–25 s of the run (--record-window)"),
        "{summary}"
    );
    // A twelfth of the run in about a twelfth of the bytes past what every recording
    // holds (the scene, the layout, the events: a window of no time).
    let empty = dir.path().join("empty.rrd");
    run(&["--record-window", "0:0"], &empty);
    let size = |p: &Path| std::fs::metadata(p).unwrap().len();
    let (a, b, z) = (size(&whole), size(&part), size(&empty));
    assert!(
        (b - z) * 8 < a - z,
        "windowed {b} bytes, whole {a} bytes, a window of no time {z} bytes"
    );
    // A window needs a recording, and a bad one is one line and exit 2.
    for (args, says) in [
        (vec!["run", "--smoke", "--record-window", "1:2"], "--record"),
        (
            vec![
                "run",
                "--smoke",
                "--record",
                "x.rrd",
                "--record-window",
                "5:2",
            ],
            "ends before it starts",
        ),
        (
            vec![
                "run",
                "--smoke",
                "--record",
                "x.rrd",
                "--record-window",
                "5",
            ],
            "FROM:UNTIL",
        ),
        (
            vec![
                "run",
                "--smoke",
                "--record",
                "x.rrd",
                "--record-window",
                "1e12:",
            ],
            "ratelab::limits::MAX_DURATION_S",
        ),
    ] {
        let o = ratelab(&args, dir.path());
        let err = String::from_utf8_lossy(&o.stderr);
        assert_eq!(o.status.code(), Some(2), "{args:?}: {err}");
        assert!(err.contains(says), "{args:?}: {err}");
    }
}

/// A run offered to ROS 2 (`--ros2`) and bagged (`--bag DIR`) says so in its settings
/// (#73): its recording properties name the domain and the bag's folder, and its summary,
/// in progress and at the end, has a line for each. A run offered nowhere has neither.
#[test]
fn a_run_offered_to_ros2_and_bagged_says_so_in_its_settings() {
    let dir = tempfile::tempdir().unwrap();
    let cfg = virtual_cfg().with_duration_ms(500);
    let bag = dir.path().join("bag");
    let offered = dir.path().join("offered.rrd");
    record_with_options(
        &offered,
        &cfg,
        None,
        Vec::new(),
        &RecordOptions {
            ros2_domain: Some(7),
            bag: Some(bag.clone()),
            ..RecordOptions::default()
        },
    );
    let settings_of = |path: &Path| -> BTreeMap<&'static str, Vec<String>> {
        let entity = EntityPath::properties().join(&EntityPath::from("settings"));
        let all = chunks(path);
        ["clock", "ros2", "bag"]
            .into_iter()
            .map(|key| {
                let values: Vec<String> = all
                    .iter()
                    .filter(|c| c.entity_path() == &entity)
                    .flat_map(|c| {
                        c.iter_slices::<String>(re_chunk::ComponentIdentifier::from(key))
                            .flatten()
                            .map(|s| s.as_str().to_string())
                            .collect::<Vec<_>>()
                    })
                    .collect();
                (key, values)
            })
            .collect()
    };
    let summaries = |path: &Path| -> Vec<String> {
        chunks(path)
            .iter()
            .filter(|c| c.entity_path().to_string() == "/summary")
            .flat_map(|c| {
                c.iter_slices::<String>(rerun::TextDocument::descriptor_text().component)
                    .flatten()
                    .map(|s| s.as_str().to_string())
                    .collect::<Vec<_>>()
            })
            .collect()
    };
    let settings = settings_of(&offered);
    assert_eq!(settings["clock"], ["virtual"], "{settings:?}");
    assert_eq!(settings["ros2"], ["offered on domain 7"], "{settings:?}");
    assert_eq!(settings["bag"], [bag.display().to_string()], "{settings:?}");
    let docs = summaries(&offered);
    assert_eq!(docs.len(), 2, "in progress, then at the end: {docs:?}");
    for doc in &docs {
        assert!(doc.contains("- ROS 2: offered on domain 7"), "{doc}");
        assert!(
            doc.contains(&format!(
                "- bag: what was offered to ROS 2, written as a rosbag2 bag (MCAP) in {}",
                bag.display()
            )),
            "{doc}"
        );
    }
    check_views(&offered);
    // Offered nowhere: neither, and the settings as they always were.
    let plain = dir.path().join("plain.rrd");
    record(&plain, &cfg, None);
    let settings = settings_of(&plain);
    assert_eq!(settings["clock"], ["virtual"]);
    assert!(
        settings["ros2"].is_empty() && settings["bag"].is_empty(),
        "{settings:?}"
    );
    assert!(summaries(&plain)
        .iter()
        .all(|d| !d.contains("ROS 2") && !d.contains("bag:")));
}

/// Outside a record window the events are recorded all the same (a change before the
/// window, a change inside it); the plots keep to it.
#[test]
fn a_record_window_keeps_the_events_outside_it() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("window-events.rrd");
    let at = |s: u64, command| TimedCommand {
        at_ns: s * 1_000_000_000,
        command,
    };
    record_with_options(
        &path,
        &RunConfig {
            duration: ratelab::Nanos(8_000_000_000),
            ..virtual_cfg()
        },
        None,
        vec![
            at(3, Command::SetQueueDepth { depth: 5 }),
            at(5, Command::SetQueueDepth { depth: 2 }),
        ],
        &RecordOptions {
            window: Some(ratelab::recording::RecordWindow::parse("4:6").unwrap()),
            ..RecordOptions::default()
        },
    );
    let events = events_with_times(&path);
    let when = |needle: &str| {
        events
            .iter()
            .find(|(_, _, e)| e.contains(needle))
            .unwrap_or_else(|| panic!("no event '{needle}': {events:?}"))
            .0
    };
    assert_eq!(when("/obs depth 1 → 5"), 3_000_000_000);
    assert_eq!(when("/obs depth 5 → 2"), 5_000_000_000);
    let all = chunks(&path);
    let angle = sim_series(&all, "/plant/pole_angle_rad");
    assert!(!angle.is_empty());
    assert!(angle
        .iter()
        .all(|(t, _)| (4_000_000_000..=6_000_000_000).contains(t)));
}

/// With an estimator in the graph the recording carries its estimate θ̂ beside the pole
/// angle, each where the angle's line shows the state it estimates (the step before's
/// angle), named and coloured, and in the pole-angle view; a graph without one has none.
#[test]
fn an_estimator_s_estimate_is_recorded_beside_the_pole_angle() {
    let dir = tempfile::tempdir().unwrap();
    let cfg = RunConfig {
        graph: ratelab::graph::GraphSpec::load(&crate::repo("graphs/cartpole-estimator.toml"))
            .unwrap(),
        ..virtual_cfg().with_duration_ms(2000)
    };
    let path = dir.path().join("estimator.rrd");
    record(&path, &cfg, None);
    let all = chunks(&path);
    let angle = sim_series(&all, "/plant/pole_angle_rad");
    let estimate = sim_series(&all, "/plant/pole_angle_estimate_rad");
    // Every step but the first (no estimate at t = 0), one step earlier.
    assert_eq!(estimate.len(), angle.len() - 1);
    let report = run(&cfg, Box::new(Scripted), RunOptions::new()).unwrap();
    for (s, (t, v)) in report.trace[1..].iter().zip(&estimate) {
        assert_eq!(*t, (s.t.0 - 20_000_000) as i64);
        assert_eq!(*v, s.estimate.as_ref().unwrap().estimate.unwrap()[2]);
    }
    // Named and coloured, and drawn with the angle: under it (its entity sorts first) and
    // wider, so that where it lies on its truth it shows either side of the angle's line.
    let named = all
        .iter()
        .any(|c| c.entity_path().to_string() == "/plant/pole_angle_estimate_rad" && c.is_static());
    assert!(named);
    let (estimate_color, estimate_width) =
        series_style(&all, "/plant/pole_angle_estimate_rad").unwrap();
    let (angle_color, angle_width) = series_style(&all, "/plant/pole_angle_rad").unwrap();
    assert!(
        estimate_width >= angle_width + 2.0,
        "{estimate_width} over {angle_width}"
    );
    assert_ne!(estimate_color, angle_color);
    let views = check_views(&path);
    assert!(
        views.iter().any(|v| v
            .queries
            .iter()
            .any(|q| q == "/plant/pole_angle_estimate_rad")),
        "{views:?}"
    );
    // Recorded within a window that starts after the first estimate: named all the same.
    let windowed = dir.path().join("window.rrd");
    record_with_options(
        &windowed,
        &cfg,
        None,
        Vec::new(),
        &RecordOptions {
            window: Some(ratelab::recording::RecordWindow::parse("1:2").unwrap()),
            ..RecordOptions::default()
        },
    );
    let inside = chunks(&windowed);
    assert!(!sim_series(&inside, "/plant/pole_angle_estimate_rad").is_empty());
    assert!(inside.iter().any(|c| {
        c.entity_path().to_string() == "/plant/pole_angle_estimate_rad" && c.is_static()
    }));
    let chapter = dir.path().join("chapter.rrd");
    record(&chapter, &virtual_cfg().with_duration_ms(500), None);
    assert!(sim_series(&chunks(&chapter), "/plant/pole_angle_estimate_rad").is_empty());
    assert!(!check_views(&chapter)
        .iter()
        .any(|v| v.queries.iter().any(|q| q.contains("estimate"))));
}

/// What a large graph's recording (more than `groups::GROUP_ABOVE` nodes or topics, #73)
/// must be, read from the file: its blueprint resolves (every view's queries match
/// recorded data of the view's kind), no time-series view's contents match more than
/// `groups::MAX_SERIES_PER_VIEW` series, every plot is tall enough at 1280×720, and every
/// recorded series is in a view or, a topic's or node's own, listed in the `groups`
/// document (the rule: reachable in the entity tree, drawn in no plot). The views.
fn check_grouped_views(path: &Path) -> Vec<BlueprintView> {
    use ratelab::recording::groups::{DOC_ENTITY, MAX_SERIES_PER_VIEW};
    let views = blueprint_views(path);
    let entities = entity_components(path);
    let problems = unmatched(&views, &entities);
    assert!(problems.is_empty(), "{problems:#?}");
    let scalars: Vec<&EntityPath> = entities
        .iter()
        .filter(|(_, c)| c.contains("Scalars:scalars"))
        .map(|(e, _)| e)
        .collect();
    let mut shown: BTreeSet<&EntityPath> = BTreeSet::new();
    for v in views.iter().filter(|v| v.class == "TimeSeries") {
        let origin = EntityPath::parse_forgiving(&v.origin);
        let filter = EntityPathFilter::from_query_expressions(v.queries.iter().map(String::as_str))
            .resolve_forgiving(&EntityPathSubs::new_with_origin(&origin));
        let matched: Vec<&EntityPath> = scalars
            .iter()
            .copied()
            .filter(|e| filter.matches(e))
            .collect();
        assert!(
            !matched.is_empty() && matched.len() <= MAX_SERIES_PER_VIEW,
            "{:?} draws {} series: {:?}",
            v.name,
            matched.len(),
            v.queries
        );
        shown.extend(matched);
    }
    let doc: String = chunks(path)
        .iter()
        .filter(|c| c.entity_path().to_string() == format!("/{DOC_ENTITY}"))
        .flat_map(|c| {
            c.iter_slices::<String>(rerun::TextDocument::descriptor_text().component)
                .flatten()
                .map(|s| s.as_str().to_string())
                .collect::<Vec<_>>()
        })
        .last()
        .expect("a `groups` document");
    assert!(
        views
            .iter()
            .any(|v| v.queries == [format!("/{DOC_ENTITY}")]),
        "the `groups` document has a view: {views:#?}"
    );
    for e in scalars.iter().filter(|e| !shown.contains(*e)) {
        let e = e.to_string();
        let owner = e.rsplit_once('/').map_or(e.as_str(), |(owner, _)| owner);
        assert!(
            (owner.starts_with("/bus/") || owner.starts_with("/nodes/"))
                && doc.contains(&format!("`{owner}`")),
            "{e} is in no view and not listed as reachable in `groups`"
        );
    }
    for (v, px) in crate::glance::view_heights(path) {
        if v.class == "TimeSeries" {
            assert!(
                px >= crate::glance::MIN_PLOT_PX,
                "{:?} is {px:.0} px tall at 1280x720",
                v.name
            );
        }
    }
    views
}

/// Any graph size reads (#73, item 2): a generated graph of 100 nodes and one of 1,000
/// (`ratelab graph --nodes N`) record every topic's own series as before, each bus group's
/// largest, median and smallest value beside them, plots of at most a dozen series that
/// all resolve, lines no wider than the cap (the 100-node graph's `/action` was 296 px),
/// and a node graph of a box per group (199 boxes made a microscopic strip).
#[test]
fn a_generated_graph_of_any_size_records_views_that_read() {
    use ratelab::recording::groups::MAX_GROUPS;
    let _m = crate::machine::shared();
    let dir = tempfile::tempdir().unwrap();
    for nodes in [100, 1000] {
        let g = crate::large_graphs::generated(dir.path(), &format!("g{nodes}.toml"), nodes, 1);
        let cfg = RunConfig {
            graph: ratelab::graph::GraphSpec::load(Path::new(&g)).unwrap(),
            ..virtual_cfg().with_duration_ms(2000)
        };
        let path = dir.path().join(format!("g{nodes}.rrd"));
        let m = record(&path, &cfg, None);
        let views = check_grouped_views(&path);
        let all = chunks(&path);
        let entities: BTreeSet<String> = all.iter().map(|c| c.entity_path().to_string()).collect();
        // Every topic's own series, as before.
        assert_eq!(m.topics.len(), nodes - 1);
        for topic in m.topics.keys() {
            let entity = ratelab::recording::bus_name(topic);
            for measure in ["published", "dropped", "msg_per_s"] {
                let e = format!("/bus/{entity}/{measure}");
                assert!(entities.contains(&e), "{nodes} nodes: no {e}");
            }
        }
        // A controller's position topics, a group drawn by its aggregates: in the bus's
        // msg/s plot, the group's largest the largest of its topics' at the end.
        let rates = views
            .iter()
            .find(|v| {
                v.queries
                    .contains(&"/bus_groups/c_k_pos/msg_per_s/median".to_string())
            })
            .unwrap_or_else(|| panic!("{nodes} nodes: no view of /c_*/pos's msg/s: {views:#?}"));
        assert!(rates.name.starts_with("bus: msg/s"), "{rates:?}");
        let (max, _) = last_scalar(&all, "/bus_groups/c_k_pos/published/max").unwrap();
        let (min, _) = last_scalar(&all, "/bus_groups/c_k_pos/published/min").unwrap();
        let (median, n) = last_scalar(&all, "/bus_groups/c_k_pos/published/median").unwrap();
        assert_eq!(n as u64, m.steps, "one sample a step");
        // Each position topic's own count at the last step (control_step, value).
        let mut last: BTreeMap<String, (i64, f64)> = BTreeMap::new();
        for c in all.iter().filter(|c| !c.is_static()) {
            let e = c.entity_path().to_string();
            if !(e.starts_with("/bus/c_") && e.ends_with("_pos/published")) {
                continue;
            }
            let values: Vec<f64> = c
                .iter_slices::<f64>(rerun::Scalars::descriptor_scalars().component)
                .flat_map(|b| b.to_vec())
                .collect();
            for (step, v) in times_on(c, "control_step").into_iter().zip(values) {
                let slot = last.entry(e.clone()).or_insert((step, v));
                if step >= slot.0 {
                    *slot = (step, v);
                }
            }
        }
        let controllers = (nodes - 3) / 4;
        assert_eq!(last.len(), controllers, "{nodes} nodes");
        let most = last.values().map(|(_, v)| *v).fold(f64::MIN, f64::max);
        let least = last.values().map(|(_, v)| *v).fold(f64::MAX, f64::min);
        assert_eq!((min, max), (least, most), "{nodes} nodes");
        // Controllers at 10, 20, 50 and 100 Hz in turn: the median between.
        assert!(min < median && median < max, "{min} {median} {max}");
        // The chapter's topics, groups of one, drawn each by its own series.
        assert!(
            views
                .iter()
                .any(|v| v.queries.contains(&"/bus/action/published".to_string())),
            "{views:#?}"
        );
        // The rule that widens coinciding lines, capped.
        for e in ["/bus/action/published", "/bus/c_0_pos/published"] {
            let (_, width) = series_style(&all, e).unwrap();
            assert!((2.0..=14.0).contains(&width), "{e}: {width} px");
        }
        // The node graph: a box per group, each group's count and rates.
        let labels = graph_labels(&all);
        assert!(labels.len() <= 2 * MAX_GROUPS, "{labels:?}");
        for label in [
            format!("sensor_* ×{controllers}\n10–100 Hz"),
            format!("/c_*/pos ×{controllers}\ndepth 1"),
            "policy · 50 Hz".to_string(),
            "/obs · depth 1".to_string(),
        ] {
            assert!(labels.contains(&label), "{label:?} in {labels:?}");
        }
    }
}

/// The chapter's graph is drawn as it always was (#73: the size rules act above the
/// threshold only): the fresh recording's views are the reference recording's, and none
/// is a group's.
#[test]
fn the_chapter_s_blueprint_is_the_reference_s() {
    let dir = tempfile::tempdir().unwrap();
    let fresh = dir.path().join("fresh.rrd");
    record(&fresh, &virtual_cfg(), None);
    let views = |p: &Path| format!("{:#?}", blueprint_views(p));
    assert_eq!(views(&fresh), views(&reference()));
    let fresh = views(&fresh);
    assert!(
        !fresh.contains("/bus_groups/") && !fresh.contains("\"/groups\""),
        "{fresh}"
    );
}
