//! Recordings: a run written to a rerun `.rrd` for offline review (rerun 0.36.3).
//!
//! Timelines: `sim_time` (a duration on the runtime clock, virtual or real) and
//! `control_step` (a sequence). Entities:
//! - `world/rail`, `world/cart` (box, half sizes 0.1 × 0.05 × 0.05, translated by the
//!   cart position) and `world/cart/pole` (capsule, 1.0 m × 0.02 m, rotated θ about +y);
//! - `plant/pole_angle_rad`, `plant/fall_limit/{upper,lower}`, `plant/cart_pos_m`,
//!   `policy/action`, `latency/sense_to_act_ms`;
//! - `bus/<topic>/{published,dropped,msg_per_s}` per topic of the graph (`/obs` → `bus/obs`;
//!   msg/s over a 1 s sliding window);
//! - `graph`: the node graph as rerun `GraphNodes`/`GraphEdges`, built from the graph's
//!   shape. Rerun's edges carry no labels, so topics are drawn as nodes of their own, as
//!   ROS's rqt_graph does: sensor → /obs → policy → /action → actuator; labels show the
//!   rates and depths and are re-logged when they change;
//! - `nodes/<name>/lateness_us`: per-tick lateness of each node (real clock only);
//! - `events`: text logs for the start (all settings), rate and depth changes, the fall and
//!   the end (the summary); the settings are also recording properties.
//!
//! Determinism: rows are not left to rerun's background batcher, whose chunk boundaries and
//! order depend on thread timing. Each entity's rows are gathered into chunks here and sent
//! every [`FLUSH_EVERY_STEPS`] control steps (and at the end), entities in sorted order, all
//! stamped on the runtime clock. Under the virtual clock the wall-clock `log_time` timeline
//! is off and the recording id derives from the settings, so two runs with the same settings
//! write recordings that `rerun rrd compare` finds identical. (Per-node lateness, real clock
//! only, is logged from the node threads through the ordinary batcher.)
//!
//! Files follow [`crate::output`]'s rule: rerun writes a temporary file beside the final
//! name (`.<name>.<pid>-<n>.tmp`), moved into place when the recording is finished (or
//! dropped); an existing file is replaced only when the recording was opened with
//! `force`, and a symbolic link or non-regular file at the final name is refused.

use crate::config::{ClockKind, RunConfig};
use crate::graph::{GraphHandles, GraphSpec, NodeId, StepObserver};
use crate::metrics::{Metrics, StepRecord};
use crate::plant::THETA_LIMIT_RAD;
use crate::scheduler::{EndReason, RunEnd};
use crate::time::Nanos;
use re_chunk::{Chunk, ChunkBuilder, RowId, TimeColumn};
use rerun::blueprint::{
    Blueprint, GraphView, Horizontal, Spatial3DView, TextLogView, TimeSeriesView, Vertical,
};
use rerun::time::{TimePoint, Timeline};
use rerun::{RecordingStream, RecordingStreamBuilder};
use std::collections::{BTreeMap, VecDeque};
use std::path::{Path, PathBuf};
use std::sync::{Arc, Mutex};

/// The rerun application id of ratelab recordings.
pub const APP_ID: &str = "ratelab";

/// Buffered rows are sent as chunks this often (control steps), so a run cut short loses
/// at most this much even without a clean exit (a clean exit always sends everything).
pub const FLUSH_EVERY_STEPS: u64 = 250;

/// A scalar series gathered as columns: run time (ns), control step, value.
#[derive(Default)]
struct ScalarColumn {
    t_ns: Vec<i64>,
    step: Vec<i64>,
    value: Vec<f64>,
}

/// Rows gathered per entity, sent as chunks in a fixed order. Scalars are kept as plain
/// columns and serialized once per flush (one arrow array per series, not one per row).
#[derive(Default)]
struct ChunkBuffer {
    rows: BTreeMap<String, ChunkBuilder>,
    scalars: BTreeMap<String, ScalarColumn>,
}

impl ChunkBuffer {
    fn add(&mut self, entity: &str, time: &TimePoint, row: &dyn rerun::AsComponents) {
        let builder = self
            .rows
            .remove(entity)
            .unwrap_or_else(|| Chunk::builder(entity));
        self.rows.insert(
            entity.to_string(),
            builder.with_archetype(RowId::new(), time.clone(), row),
        );
    }

    fn scalar(&mut self, entity: &str, t: Nanos, step: u64, value: f64) {
        if !self.scalars.contains_key(entity) {
            self.scalars
                .insert(entity.to_string(), ScalarColumn::default());
        }
        let col = self.scalars.get_mut(entity).expect("inserted above");
        col.t_ns.push(i64::try_from(t.0).unwrap_or(i64::MAX));
        col.step.push(i64::try_from(step).unwrap_or(i64::MAX));
        col.value.push(value);
    }

    fn send(&mut self, rec: &RecordingStream) {
        for (_, builder) in std::mem::take(&mut self.rows) {
            if let Ok(chunk) = builder.build() {
                rec.send_chunk(chunk);
            }
        }
        for (entity, col) in std::mem::take(&mut self.scalars) {
            let index = [
                TimeColumn::new_duration_nanos("sim_time", col.t_ns),
                TimeColumn::new_sequence("control_step", col.step),
            ];
            if let Ok(columns) = rerun::Scalars::new(col.value).columns_of_unit_batches() {
                let _ = rec.send_columns(entity, index, columns);
            }
        }
    }
}

/// The runtime-clock time point of control step `step` at run time `t`.
fn time_point(t: Nanos, step: u64) -> TimePoint {
    TimePoint::default()
        .with(
            Timeline::new_duration("sim_time"),
            i64::try_from(t.0).unwrap_or(i64::MAX),
        )
        .with(
            Timeline::new_sequence("control_step"),
            i64::try_from(step).unwrap_or(i64::MAX),
        )
}

/// Why a recording cannot be written. One line each, naming the file.
#[derive(Debug, thiserror::Error)]
pub enum RecordingError {
    /// A symbolic link or a non-regular file at the path, or a move into place that failed.
    #[error("--record {0}")]
    Output(crate::output::OutputError),
    /// The path is a folder.
    #[error("--record path is a directory: {0}")]
    IsDirectory(PathBuf),
    /// The file exists and `--force` was not given.
    #[error("--record file exists: {0} (pass --force to overwrite)")]
    Exists(PathBuf),
    /// The file cannot be created.
    #[error("cannot write recording {path}: {detail}")]
    Unwritable {
        /// The path.
        path: PathBuf,
        /// The OS's reason.
        detail: String,
    },
    /// rerun refused or failed to write.
    #[error("recording {path}: {detail}")]
    Rerun {
        /// The recording's final path.
        path: PathBuf,
        /// rerun's reason.
        detail: String,
    },
}

impl From<crate::output::OutputError> for RecordingError {
    fn from(e: crate::output::OutputError) -> Self {
        use crate::output::OutputError;
        match e {
            OutputError::Exists(p) => RecordingError::Exists(p),
            OutputError::NotRegular {
                path,
                kind: "a folder",
            } => RecordingError::IsDirectory(path),
            OutputError::Io { path, detail } => RecordingError::Unwritable { path, detail },
            other => RecordingError::Output(other),
        }
    }
}

/// Format a rate for a file name: `50`, `7.5`.
fn hz_label(hz: f64) -> String {
    let s = format!("{hz:.3}");
    s.trim_end_matches('0').trim_end_matches('.').to_string()
}

/// `<graph>-` for any graph but the chapter's (`cartpole`), which keeps the names it had.
fn graph_prefix(cfg: &RunConfig) -> String {
    if cfg.graph.name == "cartpole" {
        String::new()
    } else {
        format!("{}-", cfg.graph.name)
    }
}

/// `recordings/[<graph>-]<clock>-control<hz>-q<depth>-seed<seed>[-<n>].rrd` under `dir`: the first
/// name not already taken (`-2`, `-3`, … are appended), so nothing is overwritten.
pub fn default_path(dir: &Path, cfg: &RunConfig) -> PathBuf {
    let stem = format!(
        "{}{}-control{}-q{}-seed{}",
        graph_prefix(cfg),
        cfg.clock,
        hz_label(cfg.control_hz()),
        cfg.queue_depth(),
        cfg.seed
    );
    let first = dir.join(format!("{stem}.rrd"));
    if !first.exists() {
        return first;
    }
    (2..)
        .map(|n| dir.join(format!("{stem}-{n}.rrd")))
        .find(|p| !p.exists())
        .expect("unbounded")
}

/// Check that `path` can be written before a run starts: not a folder, a symbolic link or
/// another non-regular file, not an existing file (unless `force`), and in a folder where
/// files can be created (a temporary file is created there and removed; the final name is
/// never touched).
///
/// # Errors
/// [`RecordingError`] naming the problem.
pub fn check_output_path(path: &Path, force: bool) -> Result<(), RecordingError> {
    let (pending, _file) = crate::output::PendingFile::create(path, force)?;
    drop(pending); // removes the probe
    Ok(())
}

/// Moves a recording's temporary file into place once, when finished or dropped.
struct Committer(Mutex<Option<crate::output::PendingFile>>);

impl Committer {
    fn commit(&self) -> Result<(), crate::output::OutputError> {
        match self.0.lock().unwrap_or_else(|e| e.into_inner()).take() {
            Some(mut p) => p.commit(),
            None => Ok(()),
        }
    }
}

impl Drop for Committer {
    fn drop(&mut self) {
        // Best effort: a recording dropped unfinished keeps what it wrote.
        let _ = self.commit();
    }
}

/// How to record.
#[derive(Clone, Debug, Default)]
pub struct RecordOptions {
    /// Also stream live to a rerun viewer spawned from PATH.
    pub spawn: bool,
}

/// An open recording. Cheap to clone (the stream is a shared handle).
#[derive(Clone)]
pub struct Recording {
    rec: RecordingStream,
    path: PathBuf,
    clock: ClockKind,
    buffer: Arc<Mutex<ChunkBuffer>>,
    /// The latest control step logged (stamps events that arrive between steps).
    last_step: Arc<std::sync::atomic::AtomicU64>,
    /// The temporary file rerun writes, moved to `path` by [`Recording::finish`].
    file: Arc<Committer>,
}

fn blueprint() -> Blueprint {
    Blueprint::new(Horizontal::new([
        Vertical::new([
            Spatial3DView::new("cartpole").with_origin("/world").into(),
            GraphView::new("node graph").with_origin("/graph").into(),
            TextLogView::new("events").with_origin("/events").into(),
        ])
        .into(),
        Vertical::new([
            TimeSeriesView::new("pole angle (rad) and fall limits")
                .with_contents(["/plant/pole_angle_rad", "/plant/fall_limit/**"])
                .into(),
            TimeSeriesView::new("sense→act latency (ms)")
                .with_origin("/latency")
                .into(),
            TimeSeriesView::new("bus: dropped")
                .with_contents(["/bus/*/dropped"])
                .into(),
            TimeSeriesView::new("bus: msg/s")
                .with_contents(["/bus/*/msg_per_s"])
                .into(),
        ])
        .into(),
    ]))
}

/// A spawnable viewer on PATH?
pub fn viewer_on_path() -> bool {
    std::env::var_os("PATH")
        .map(|paths| std::env::split_paths(&paths).any(|d| d.join("rerun").is_file()))
        .unwrap_or(false)
}

impl Recording {
    /// Open a recording of a run with `cfg` and the brain `policy` at `path`, which must
    /// not exist yet ([`Recording::create_with`] without `force`).
    ///
    /// # Errors
    /// As [`Recording::create_with`].
    pub fn create(
        path: &Path,
        cfg: &RunConfig,
        policy: &str,
        opts: &RecordOptions,
    ) -> Result<(Self, Option<String>), RecordingError> {
        Self::create_with(path, cfg, policy, opts, false)
    }

    /// Open a recording of a run with `cfg` and the brain `policy` at `path`; an existing
    /// regular file there is replaced (when the recording is finished) only if `force`.
    /// With `opts.spawn` and a `rerun` viewer on PATH, data is also streamed live. Returns
    /// the recording and, when `spawn` was asked for but no viewer was found, a one-line
    /// notice.
    ///
    /// # Errors
    /// [`RecordingError`] when the path is refused ([`check_output_path`]'s rules), the
    /// file cannot be created, or rerun refuses.
    pub fn create_with(
        path: &Path,
        cfg: &RunConfig,
        policy: &str,
        opts: &RecordOptions,
        force: bool,
    ) -> Result<(Self, Option<String>), RecordingError> {
        let (pending, file) = crate::output::PendingFile::create(path, force)?;
        drop(file);
        let tmp = pending.temp_path().to_path_buf();
        let mut builder = RecordingStreamBuilder::new(APP_ID).with_blueprint(blueprint());
        if cfg.clock == ClockKind::Virtual {
            let id = format!(
                "ratelab-{}virtual-sensor{}-control{}-q{}-seed{}-d{}",
                graph_prefix(cfg),
                hz_label(cfg.sensor_hz()),
                hz_label(cfg.control_hz()),
                cfg.queue_depth(),
                cfg.seed,
                cfg.duration.0
            );
            builder = builder
                .recording_id(id)
                .batcher_config(rerun::log::ChunkBatcherConfig {
                    flush_tick: std::time::Duration::MAX,
                    flush_num_bytes: 256 * 1024,
                    flush_num_rows: u64::MAX,
                    ..rerun::log::ChunkBatcherConfig::DEFAULT
                });
        }
        let rec_err = |e: rerun::RecordingStreamError| RecordingError::Rerun {
            path: path.to_path_buf(),
            detail: e.to_string(),
        };
        let mut notice = None;
        let live = opts.spawn && viewer_on_path();
        if opts.spawn && !live {
            notice = Some(
                "no rerun viewer on PATH: recording to the file only (install one with `cargo install rerun-cli --locked --version 0.36.3` or `pip install rerun-sdk==0.36.3`)".to_string(),
            );
        }
        let rec = if live {
            // Start the viewer, then write to the file and stream to the viewer at once.
            rerun::spawn(&rerun::SpawnOptions::default()).map_err(|e| RecordingError::Rerun {
                path: path.to_path_buf(),
                detail: e.to_string(),
            })?;
            let file =
                rerun::sink::FileSink::new(&tmp).map_err(|e| RecordingError::Unwritable {
                    path: path.to_path_buf(),
                    detail: e.to_string(),
                })?;
            builder
                .set_sinks((file, rerun::sink::GrpcSink::default()))
                .map_err(rec_err)?
        } else {
            builder.save(&tmp).map_err(rec_err)?
        };
        if cfg.clock == ClockKind::Virtual {
            rec.set_log_time_enabled(false);
        }
        let recording = Self {
            rec,
            path: path.to_path_buf(),
            clock: cfg.clock,
            buffer: Arc::default(),
            last_step: Arc::default(),
            file: Arc::new(Committer(Mutex::new(Some(pending)))),
        };
        recording.log_settings(cfg, policy);
        Ok((recording, notice))
    }

    /// The file being written.
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// The underlying rerun stream.
    pub fn stream(&self) -> &RecordingStream {
        &self.rec
    }

    fn log_settings(&self, cfg: &RunConfig, policy: &str) {
        let settings = [
            ("clock", cfg.clock.to_string()),
            ("policy", policy.to_string()),
            ("seed", cfg.seed.to_string()),
            ("duration_s", cfg.duration.as_secs_f64().to_string()),
            ("sensor_hz", cfg.sensor_hz().to_string()),
            ("control_hz", cfg.control_hz().to_string()),
            ("actuator_hz", cfg.actuator_hz().to_string()),
            ("queue_depth", cfg.queue_depth().to_string()),
        ];
        // The chapter's graph keeps the recording it had; any other names itself.
        let graph = (cfg.graph.name != "cartpole").then(|| ("graph", cfg.graph.to_string()));
        let mut values = rerun::AnyValues::default();
        for (k, v) in settings.iter().chain(graph.iter()) {
            values = values.with_component::<rerun::components::Text>(*k, [v.as_str()]);
        }
        let name = format!(
            "{}{} clock, control {} Hz, depth {}, seed {}",
            graph_prefix(cfg),
            cfg.clock,
            hz_label(cfg.control_hz()),
            cfg.queue_depth(),
            cfg.seed
        );
        let properties = rerun::EntityPath::properties();
        let fixed = TimePoint::default();
        let mut buf = self.lock();
        buf.add(
            &properties.to_string(),
            &fixed,
            &rerun::RecordingInfo::update_fields().with_name(name),
        );
        buf.add(
            &properties
                .join(&rerun::EntityPath::from("settings"))
                .to_string(),
            &fixed,
            &values,
        );
        buf.add(
            "world/rail",
            &fixed,
            &rerun::Boxes3D::from_half_sizes([(2.9, 0.01, 0.01)])
                .with_colors([rerun::Color::from_rgb(110, 110, 110)]),
        );
        buf.add(
            "world/cart/body",
            &fixed,
            &rerun::Boxes3D::from_half_sizes([(0.1, 0.05, 0.05)])
                .with_colors([rerun::Color::from_rgb(60, 110, 200)]),
        );
        buf.add(
            "world/cart/pole/body",
            &fixed,
            &rerun::Capsules3D::from_lengths_and_radii([1.0], [0.02])
                .with_colors([rerun::Color::from_rgb(230, 150, 50)]),
        );
        let start = time_point(Nanos::ZERO, 0);
        let text = settings
            .iter()
            .map(|(k, v)| format!("{k}={v}"))
            .collect::<Vec<_>>()
            .join(" ");
        buf.add(
            "events",
            &start,
            &rerun::TextLog::new(format!("start: {text}"))
                .with_level(rerun::components::TextLogLevel::INFO),
        );
        for (name, limit) in [("upper", THETA_LIMIT_RAD), ("lower", -THETA_LIMIT_RAD)] {
            buf.scalar(&format!("plant/fall_limit/{name}"), Nanos::ZERO, 0, limit);
        }
        buf.send(&self.rec);
    }

    fn lock(&self) -> std::sync::MutexGuard<'_, ChunkBuffer> {
        self.buffer.lock().unwrap_or_else(|e| e.into_inner())
    }

    /// Log an event line at run time `t` (and the latest control step).
    pub fn event(&self, t: Nanos, text: &str, level: &str) {
        let step = self.last_step.load(std::sync::atomic::Ordering::Relaxed);
        self.lock().add(
            "events",
            &time_point(t, step),
            &rerun::TextLog::new(text).with_level(level),
        );
    }

    /// An observer to hand to the graph: logs every actuator tick.
    pub fn observer(&self) -> Box<dyn StepObserver> {
        Box::new(RecordingObserver {
            rec: self.clone(),
            handles: None,
            last_labels: None,
            window: VecDeque::new(),
        })
    }

    /// Log one node tick's lateness (real clock), on the node's own thread.
    pub fn node_tick(&self, node: &str, now: Nanos, lateness: Nanos) {
        self.rec
            .set_time("sim_time", std::time::Duration::from_nanos(now.0));
        let _ = self.rec.log(
            format!("nodes/{node}/lateness_us"),
            &rerun::Scalars::single(lateness.as_micros_f64()),
        );
    }

    /// Log the end of the run (the summary) at its end time, flush the file and move it
    /// into place, so the recording is complete whichever way the run ended.
    ///
    /// # Errors
    /// [`RecordingError::Rerun`] when the flush fails, [`RecordingError`] when the file
    /// cannot be moved into place (e.g. its name was taken meanwhile, without `force`).
    pub fn finish(&self, metrics: &Metrics, end: &RunEnd) -> Result<(), RecordingError> {
        let summary = metrics.summary_lines(None);
        let level = match end.reason {
            EndReason::NodeFailed { .. } => rerun::components::TextLogLevel::ERROR,
            _ => rerun::components::TextLogLevel::INFO,
        };
        self.event(
            end.at,
            &format!("end ({}): {}", end.reason, summary[2..].join(" | ")),
            level,
        );
        {
            let mut buf = self.lock();
            for (name, limit) in [("upper", THETA_LIMIT_RAD), ("lower", -THETA_LIMIT_RAD)] {
                buf.scalar(
                    &format!("plant/fall_limit/{name}"),
                    end.at,
                    metrics.steps,
                    limit,
                );
            }
        }
        self.flush()?;
        Ok(self.file.commit()?)
    }

    /// Send every buffered row and flush the file.
    ///
    /// # Errors
    /// [`RecordingError::Rerun`] when the sink fails.
    pub fn flush(&self) -> Result<(), RecordingError> {
        self.lock().send(&self.rec);
        self.rec
            .flush_blocking()
            .map_err(|e| RecordingError::Rerun {
                path: self.path.clone(),
                detail: e.to_string(),
            })
    }

    /// The clock this recording was stamped with.
    pub fn clock(&self) -> ClockKind {
        self.clock
    }
}

/// The entity name of a topic's bus series: `/obs` → `obs`, `/a/b` → `a_b`.
pub fn bus_name(topic: &str) -> String {
    topic.trim_start_matches('/').replace('/', "_")
}

struct RecordingObserver {
    rec: Recording,
    handles: Option<GraphHandles>,
    /// Node rates and topic depths as last logged in the graph's labels.
    last_labels: Option<(Vec<f64>, Vec<usize>)>,
    /// (t, published per topic) over the last second.
    window: VecDeque<(Nanos, Vec<u64>)>,
}

impl RecordingObserver {
    /// The node graph, from the graph's shape: nodes and topics as rerun graph nodes (rerun's
    /// edges carry no labels), publisher → topic → subscriber.
    fn graph_rows(
        &self,
        buf: &mut ChunkBuffer,
        time: &TimePoint,
        spec: &GraphSpec,
        rates: &[f64],
        depths: &[usize],
    ) {
        let mut ids = Vec::new();
        let mut labels = Vec::new();
        let mut edges = Vec::new();
        for (i, n) in spec.nodes.iter().enumerate() {
            ids.push(n.name.clone());
            labels.push(format!("{} {} Hz", n.name, hz_label(rates[i])));
            if let Some(t) = n.publishes {
                let topic = &spec.topics[t.0];
                ids.push(topic.name.clone());
                labels.push(format!("{} (depth {})", topic.name, depths[t.0]));
                edges.push((n.name.clone(), topic.name.clone()));
                if let Some(sub) = topic.subscriber {
                    edges.push((topic.name.clone(), spec.node(sub).name.clone()));
                }
            }
        }
        buf.add(
            "graph",
            time,
            &rerun::GraphNodes::new(ids).with_labels(labels),
        );
        buf.add(
            "graph",
            time,
            &rerun::GraphEdges::new(edges).with_directed_edges(),
        );
    }
}

/// What changed between two sets of labels, in words.
fn describe_change(
    spec: &GraphSpec,
    old: &(Vec<f64>, Vec<usize>),
    new: &(Vec<f64>, Vec<usize>),
) -> String {
    if let Some(i) = (0..old.0.len()).find(|&i| old.0[i] != new.0[i]) {
        let who = if NodeId(i) == spec.chain.policy {
            "control".to_string()
        } else {
            spec.nodes[i].name.clone()
        };
        return format!(
            "{who} rate {} → {} Hz",
            hz_label(old.0[i]),
            hz_label(new.0[i])
        );
    }
    let changed: Vec<usize> = (0..old.1.len()).filter(|&i| old.1[i] != new.1[i]).collect();
    match changed.as_slice() {
        [one] if spec.topics.len() > 1 => format!(
            "{} depth {} → {}",
            spec.topics[*one].name, old.1[*one], new.1[*one]
        ),
        [first, ..] => format!("queue depth {} → {}", old.1[*first], new.1[*first]),
        [] => "graph changed".to_string(),
    }
}

impl StepObserver for RecordingObserver {
    fn attach(&mut self, h: &GraphHandles) {
        self.handles = Some(h.clone());
    }

    fn on_step(&mut self, s: &StepRecord) {
        self.rec
            .last_step
            .store(s.step, std::sync::atomic::Ordering::Relaxed);
        let time = time_point(s.t, s.step);
        let rec = self.rec.clone();
        let mut buf = rec.lock();
        let topics = s.topics.as_slice();
        if let Some(h) = &self.handles {
            let now = (
                h.rates_hz(),
                topics.iter().map(|t| t.depth).collect::<Vec<_>>(),
            );
            if self.last_labels.as_ref() != Some(&now) {
                if let Some(old) = &self.last_labels {
                    buf.add(
                        "events",
                        &time,
                        &rerun::TextLog::new(describe_change(&h.spec, old, &now))
                            .with_level(rerun::components::TextLogLevel::INFO),
                    );
                }
                self.graph_rows(&mut buf, &time, &h.spec, &now.0, &now.1);
                self.last_labels = Some(now);
            }
        }
        let theta = s.pole_angle;
        buf.add(
            "world/cart",
            &time,
            &rerun::Transform3D::from_translation([s.cart_pos as f32, 0.0, 0.0]),
        );
        buf.add(
            "world/cart/pole",
            &time,
            &rerun::Transform3D::from_rotation(rerun::RotationAxisAngle::new(
                [0.0, 1.0, 0.0],
                rerun::Angle::from_radians(theta as f32),
            )),
        );
        buf.scalar("plant/pole_angle_rad", s.t, s.step, theta);
        buf.scalar("plant/cart_pos_m", s.t, s.step, s.cart_pos);
        buf.scalar("policy/action", s.t, s.step, s.action);
        if let Some(lat) = s.latency {
            buf.scalar("latency/sense_to_act_ms", s.t, s.step, lat.as_millis_f64());
        }
        // Bus counters and msg/s over the last second of run time.
        self.window
            .push_back((s.t, topics.iter().map(|t| t.published).collect()));
        while self
            .window
            .front()
            .is_some_and(|(t, _)| s.t.saturating_sub(*t) > Nanos::SECOND)
        {
            self.window.pop_front();
        }
        let (t0, then) = self.window.front().cloned().unwrap_or((s.t, Vec::new()));
        let span = s.t.saturating_sub(t0).as_secs_f64();
        let rate = |now: u64, then: u64| {
            if span > 0.0 {
                (now - then) as f64 / span
            } else {
                0.0
            }
        };
        let names: Vec<String> = self.handles.as_ref().map_or_else(Vec::new, |h| {
            h.spec.topics.iter().map(|t| bus_name(&t.name)).collect()
        });
        for ((topic, stats), then) in names
            .iter()
            .zip(topics)
            .zip(then.iter().copied().chain(std::iter::repeat(0)))
        {
            buf.scalar(
                &format!("bus/{topic}/published"),
                s.t,
                s.step,
                stats.published as f64,
            );
            buf.scalar(
                &format!("bus/{topic}/dropped"),
                s.t,
                s.step,
                stats.dropped as f64,
            );
            buf.scalar(
                &format!("bus/{topic}/msg_per_s"),
                s.t,
                s.step,
                rate(stats.published, then),
            );
        }
        if s.fell {
            let text = format!(
                "FELL at t={:.2}s (step {}, θ = {:.3} rad)",
                s.t.as_secs_f64(),
                s.step,
                theta
            );
            buf.add(
                "events",
                &time,
                &rerun::TextLog::new(text).with_level(rerun::components::TextLogLevel::WARN),
            );
        }
        if s.step % FLUSH_EVERY_STEPS == 0 || s.fell {
            buf.send(&rec.rec);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn default_paths_never_collide() {
        let dir = tempfile::tempdir().unwrap();
        let mut cfg = RunConfig {
            clock: ClockKind::Virtual,
            ..RunConfig::default()
        };
        cfg.set_control_hz(7.5).unwrap();
        let first = default_path(dir.path(), &cfg);
        assert_eq!(
            first.file_name().unwrap(),
            "virtual-control7.5-q1-seed0.rrd"
        );
        std::fs::write(&first, b"").unwrap();
        let second = default_path(dir.path(), &cfg);
        assert_eq!(
            second.file_name().unwrap(),
            "virtual-control7.5-q1-seed0-2.rrd"
        );
    }

    #[test]
    fn output_path_checks() {
        let dir = tempfile::tempdir().unwrap();
        assert!(matches!(
            check_output_path(dir.path(), false),
            Err(RecordingError::IsDirectory(_))
        ));
        let f = dir.path().join("x.rrd");
        std::fs::write(&f, b"old").unwrap();
        assert!(matches!(
            check_output_path(&f, false),
            Err(RecordingError::Exists(_))
        ));
        assert!(check_output_path(&f, true).is_ok());
        assert_eq!(
            std::fs::read(&f).unwrap(),
            b"old",
            "a check never touches the file"
        );
        let link = dir.path().join("link.rrd");
        std::os::unix::fs::symlink(&f, &link).unwrap();
        assert!(matches!(
            check_output_path(&link, true),
            Err(RecordingError::Output(_))
        ));
        assert!(matches!(
            check_output_path(Path::new("/proc/ratelab/x.rrd"), false),
            Err(RecordingError::Unwritable { .. })
        ));
    }
}
