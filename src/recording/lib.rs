//! Recordings: a run written to a rerun `.rrd` for offline review (rerun 0.36.3).
//!
//! Timelines: the runtime clock's time as a duration, named for the clock — `sim_time` under
//! the virtual clock, `wall_time` (since the run's start) under the real one — and
//! `control_step` (a sequence). Entities, for a graph described by a [`GraphShape`] (lists of
//! nodes and topics, so nothing below names a node or a topic):
//! - `world` (z up): `world/rail` (the cart rests on it), `world/cart` (translated by the cart
//!   position) with `world/cart/body` (box 0.2 × 0.1 × 0.1 m), `world/cart/fall_limits`
//!   (two lines at ±12°, labelled by `…/labels`), `world/cart/force` (the applied force as an arrow, 0.04 m per N)
//!   and `world/cart/pole` (rotated θ about +y) with `world/cart/pole/body` (capsule 1.0 m)
//!   and, from a fall on, `world/cart/pole/fallen` (the pole drawn red, `…/label` along it, clear of the limits' labels:
//!   `FELL at 0.84 s`);
//! - `plant/pole_angle_rad`, `plant/fall_limit/{upper,lower}`, `plant/fall` (the fall, at
//!   the pole's angle), `plant/pole_angle_estimate_rad` (with an estimator in the graph: its
//!   estimate θ̂, where the angle's line shows the state it estimates,
//!   `ratelab_core::estimate`; drawn under the angle, wider and lighter, so that where it
//!   lies on its truth it shows as a band either side of the angle's line: `style`),
//!   `plant/cart_pos_m`, `plant/rail_end/{right,left}`,
//!   `plant/cart_limit/{right,left}`;
//! - `marks/{change,trouble,recovery}`: a mark at each event of that kind, in a row under
//!   the lower fall limit, each legend naming the times (`events`);
//! - `action/published_N` (the force the policy asked for, at each message it published),
//!   `action/applied_N` (the force the actuator applied at each step: the zero-order hold);
//! - `latency/sense_to_act_ms`, `latency/control_period_ms` (the controller's period);
//! - `bus/<topic>/{published,dropped,msg_per_s}` for every topic (msg/s over a 1 s sliding
//!   window, from the second actuator step: the first spans no time; and at the run's end
//!   when the actuator stopped stepping 1 s or more before it, over the time since its last
//!   step), one colour per topic, the same in every graph and apart from every other
//!   topic's, QoS counter's and node's (`style`), each topic's line narrower than the one
//!   drawn before it so that equal lines show both colours;
//! - QoS ([`ratelab_core::qos`]): `bus/<topic>/<counter>` (`expired`, `refused`, `lost`,
//!   `retransmitted`, `offered_deadline_missed`, `requested_deadline_missed`) for each counter
//!   a topic reports ([`ratelab_core::topic::TopicStats::reported`]: its QoS can make it count, or it has
//!   counted), from the first step it is reported to the end, read at each actuator step
//!   (deadline periods missed up to that step count before the next message); and
//!   `nodes/<name>/not_alive` (times the node lost its liveliness) for each node with a
//!   liveliness lease. A graph with the chapter's QoS logs none of them;
//! - `graph`: the node graph as rerun `GraphNodes`/`GraphEdges`. Rerun's edges carry no
//!   labels, so topics are drawn as nodes of their own, as ROS's rqt_graph does; each node
//!   and topic in the colour its series have in every plot (a node's: [`style`]'s
//!   `node_color`); positions run left to right from the sources (a chain longer than five
//!   columns folded into bands, the second right to left); labels show the rates and depths
//!   (a topic with QoS beyond the depth shows it in short, a part a line under its name:
//!   `dl 30 ms zero`, `link 20%`; a Python node's label says `python`) and are re-logged
//!   when they change;
//! - `nodes/<name>/lateness_ms`: per-tick lateness of each node (real clock only);
//! - across processes (a launch's recording): `bus/<topic>/wire_{p50,p99}_us` for each topic
//!   that crosses processes (its samples' time on the wire so far, as the subscriber's
//!   process measured it), and each node's process on its node-graph label;
//! - with executors or compute times: `nodes/<name>/executor_lane` (the executor timeline:
//!   the node's rank, raised by 0.8 while its tick holds a thread), `nodes/<name>/response_ms`
//!   (release → outputs published, per tick) and `nodes/<name>/skipped_ticks` (so far);
//! - `events`: text logs for the start, rate, depth and QoS changes, brain swaps, the fall and
//!   the end; and the QoS events: `deadline missed on /cmd: requested +1 (3 in all)` (WARN)
//!   when a topic's offered or requested deadline counter rises, stamped at the actuator
//!   step that sees the rise (so up to one actuator period after the deadline timer fired);
//!   `node policy not alive (lease 60 ms)` (WARN) at the instant its lease ran out (its last
//!   tick plus the lease) and `node policy alive again` (INFO) at the tick that brought it
//!   back; `stopped by watchdog at … s: no message on /cmd for more than 30 ms` (WARN) at
//!   the run's end when the actuator's deadline reaction stopped it; a launcher's lines at
//!   the run time they state, on the launcher's run clock (`killed at t=3.027s`, `rejoined
//!   at t=3.110s`: the summary's wire line gives the rejoin the same time); and a live
//!   session's own changes, each with a mark at the run time it took effect: a fault
//!   injected from the lab (its stall key, trouble, and the stall's end), a clock switch, a
//!   reload of saved code and a ROS 2 parameter set (changes). `when`: every event in time
//!   order (stable: one instant's in the order logged), the first trouble on top, as a
//!   markdown document ([`events`]). `summary`: the run's summary as a markdown document;
//!   the settings are also recording properties, with a run's ROS 2 domain and bag folder
//!   when it is offered to ROS 2 or bagged ([`settings`]).
//!
//! The blueprint ([`blueprint`], written with [`layout`]'s archetypes) lays these out as a
//! learner reads them, every plot tall enough to label its axes at 1280×720, its legend
//! where none of its series is (the final layout: [`legend`]): the cartpole,
//! the node graph and the summary; the chapter's core (the pole angle with the events'
//! marks, the action, the cart position, the latency); `when` over tabs per concern (the
//! bus; QoS and liveliness; executors; the real clock's lateness; processes; the events;
//! the nodes' log). Every view names its entities explicitly, so none matches nothing. The layout is sent twice: when
//! the graph is built (plots with no scale known up front fit themselves while the run goes)
//! and at the end, each plot's y range then padded around every value its series took. The
//! blueprint stores' ids derive from the settings too (virtual clock).
//!
//! A graph of any size reads ([`groups`]): one of more than [`groups::GROUP_ABOVE`] nodes or
//! topics (none of the shipped graphs, which are recorded as they always were) is drawn by
//! group, its names grouped with their digits read as `*` (`sensor_*`, `/c_*/pos`). Beside
//! every topic's and node's own series (recorded in full, in the entity tree), each topic
//! group of more than [`groups::SHOWN_EACH_UP_TO`] topics gets
//! `bus_groups/<group>/<measure>/{max,median,min}` (its largest, median and smallest
//! published count, drops and msg/s at every actuator step: [`grouped`]); the bus's plots
//! draw those on pages of whole groups, the topics that dropped most each by its own
//! series, and `groups`, a document, lists every group's members with the paths of their
//! own series; the node graph draws a box per group (`sensor_* ×249`, `/c_*/pos ×249`).
//! No time-series view draws more than [`groups::MAX_SERIES_PER_VIEW`] series, whatever the
//! graph: past that, a plot of per-node or per-topic series (QoS, liveliness, executors,
//! lateness, the wire) shows those that rose highest; and the rule that widens coinciding
//! lines stops at [`style`]'s `MAX_LAYERED_WIDTH_PX`.
//!
//! A graph across processes is recorded as a watcher sees it ([`watched`]): the launch's
//! merged telemetry in place of the steps.
//!
//! The rows are written by a step observer ([`observer`]); a long run's recording may keep
//! the plots of a span of run time only ([`window`]: `--record-window`). Determinism: rows are not left
//! to rerun's background batcher, whose chunk boundaries and
//! order depend on thread timing. Each entity's rows are gathered into chunks here and sent
//! every [`FLUSH_EVERY_STEPS`] actuator steps (and at the end), entities in sorted order, all
//! stamped on the runtime clock. Under the virtual clock the wall-clock `log_time` timeline
//! is off and the recording id derives from the settings, so two runs with the same settings
//! write recordings that `rerun rrd compare` finds identical. (Per-node lateness, real clock
//! only, is logged from the node threads through the ordinary batcher.)
//!
//! Files follow [`ratelab_core::output`]'s rule for recordings: a new recording is written at
//! its name from the start (created there exclusively, and reopened by rerun through its
//! descriptor, never by the name), so a run killed outright leaves what it recorded there;
//! an existing file is replaced only when the recording was opened with `force`, through a
//! temporary file beside it (`.<name>.<pid>-<n>.tmp`) moved into place when the recording
//! is finished (or dropped); a symbolic link or non-regular file at the final name is
//! refused.
#![warn(missing_docs)]
// The crate's docs map its private modules for a maintainer: links to them are meant.
#![allow(rustdoc::private_intra_doc_links)]

mod blueprint;
mod events;
mod files;
mod grouped;
pub mod groups;
mod layout;
mod legend;
mod live;
pub use files::timeline_name;
pub use live::{open_hint, viewer_on_path, VIEWER_INSTALL, VIEWER_VERSION};
mod observer;
mod settings;
mod shape;
mod style;
pub mod watched;
mod window;

use blueprint::layout_for;
use events::{EventList, Mark};
use files::{
    chapter_settings, deterministic_id, run_name, settings_line, writing_beside_fails, Committer,
};
pub use files::{check_output_path, default_lab_path, default_path};
use observer::{reference_lines, RecordingObserver, CHANGE_MARK_RAD};
use style::*;
pub use window::RecordWindow;

use shape::GraphState;
pub use shape::{GraphShape, NodeShape, TopicShape};

use layout::{Item, ViewSpec};
use ratelab_core::metrics::Metrics;
use ratelab_core::plant::{CART_LIMIT_M, THETA_LIMIT_RAD};
use ratelab_core::qos::QosCounter;
use ratelab_core::runlog::StepRecord;
use ratelab_core::time::Nanos;
use ratelab_core::topic::TopicStats;
use ratelab_runtime::config::{ClockKind, RunConfig};
use ratelab_runtime::graph::{GraphHandles, StepObserver};
use ratelab_runtime::scheduler::{EndReason, RunEnd};
use re_chunk::{Chunk, ChunkBuilder, RowId, TimeColumn};
use rerun::external::re_sdk_types::blueprint::archetypes as bp;
use rerun::external::re_sdk_types::blueprint::components as bpc;
use rerun::external::re_sdk_types::blueprint::datatypes as bpd;
use rerun::time::{TimePoint, Timeline};
use rerun::{Color, RecordingStream, RecordingStreamBuilder};
use std::collections::{BTreeMap, VecDeque};
use std::path::{Path, PathBuf};
use std::sync::{Arc, Mutex};

/// The rerun application id of ratelab recordings.
pub const APP_ID: &str = "ratelab";

/// Buffered rows are sent as chunks this often (actuator steps), so a run cut short loses
/// at most this much even without a clean exit (a clean exit always sends everything).
pub const FLUSH_EVERY_STEPS: u64 = 250;

/// The longest a recording's last flush waits for its file to take what is left (rerun's
/// writer thread): a disk that stops taking writes without refusing them ends the run with
/// the recording cut short rather than a hang. Far above what a healthy disk needs: a
/// 1,000-node graph's 51 MB recording is written in under 5 s here.
pub const FLUSH_TIMEOUT: std::time::Duration = std::time::Duration::from_secs(120);

/// A scalar series gathered as columns: run time (ns), control step, value.
#[derive(Default)]
struct ScalarColumn {
    t_ns: Vec<i64>,
    step: Vec<i64>,
    value: Vec<f64>,
}

/// Rows gathered per entity, sent as chunks in a fixed order. Scalars are kept as plain
/// columns and serialized once per flush (one arrow array per series, not one per row).
struct ChunkBuffer {
    /// The time timeline's name ([`timeline_name`]).
    timeline: &'static str,
    rows: BTreeMap<String, ChunkBuilder>,
    scalars: BTreeMap<String, ScalarColumn>,
    /// The smallest and largest value of every scalar series so far (kept across sends):
    /// the final layout fits each plot's y range to them.
    extents: Extents,
    /// Where in time every scalar series so far took its values, coarsely, and each
    /// series' legend name (kept across sends): the final layout places each plot's legend
    /// where no series is ([`legend`]).
    seen: legend::Seen,
    /// The events so far, for the `when` document and the marks' legends.
    events: EventList,
    /// Steps outside the [`RecordWindow`]: rows (plots, the scene, the graph) are not
    /// kept, events are.
    rows_muted: bool,
}

/// (min, max) per scalar entity path.
type Extents = BTreeMap<String, (f64, f64)>;

/// The key of [`Extents`] that says the run's text log wrote lines (`log/<node>`): the final
/// layout then has a view of them.
const LOG_MARK: &str = "log";

fn widen(extents: &mut Extents, entity: &str, value: f64) {
    if !value.is_finite() {
        return;
    }
    match extents.get_mut(entity) {
        Some((lo, hi)) => {
            *lo = lo.min(value);
            *hi = hi.max(value);
        }
        None => {
            extents.insert(entity.to_string(), (value, value));
        }
    }
}

impl ChunkBuffer {
    fn new(timeline: &'static str) -> Self {
        Self {
            timeline,
            rows: BTreeMap::new(),
            scalars: BTreeMap::new(),
            extents: Extents::new(),
            seen: legend::Seen::default(),
            events: EventList::default(),
            rows_muted: false,
        }
    }

    /// The time point of control step `step` at run time `t`.
    fn at(&self, t: Nanos, step: u64) -> TimePoint {
        time_point(self.timeline, t, step)
    }

    fn add(&mut self, entity: &str, time: &TimePoint, row: &dyn rerun::AsComponents) {
        if self.rows_muted && entity != "events" {
            return;
        }
        let builder = self
            .rows
            .remove(entity)
            .unwrap_or_else(|| Chunk::builder(entity));
        self.rows.insert(
            entity.to_string(),
            builder.with_archetype(RowId::new(), time.clone(), row),
        );
    }

    /// A series' style (a static row, `row`), its legend naming it `name`: logged, and the
    /// name kept for its legend's size ([`legend`]).
    fn style(&mut self, entity: &str, name: &str, row: &dyn rerun::AsComponents) {
        self.seen.name(entity, name);
        self.add(entity, &TimePoint::default(), row);
    }

    fn scalar(&mut self, entity: &str, t: Nanos, step: u64, value: f64) {
        if self.rows_muted {
            return;
        }
        if !self.scalars.contains_key(entity) {
            self.scalars
                .insert(entity.to_string(), ScalarColumn::default());
        }
        let col = self.scalars.get_mut(entity).expect("inserted above");
        col.t_ns.push(i64::try_from(t.0).unwrap_or(i64::MAX));
        col.step.push(i64::try_from(step).unwrap_or(i64::MAX));
        col.value.push(value);
        widen(&mut self.extents, entity, value);
        self.seen.occupy(entity, t, value);
    }

    fn send(&mut self, rec: &RecordingStream) {
        for (_, builder) in std::mem::take(&mut self.rows) {
            if let Ok(chunk) = builder.build() {
                rec.send_chunk(chunk);
            }
        }
        for (entity, col) in std::mem::take(&mut self.scalars) {
            let index = [
                TimeColumn::new_duration_nanos(self.timeline, col.t_ns),
                TimeColumn::new_sequence("control_step", col.step),
            ];
            if let Ok(columns) = rerun::Scalars::new(col.value).columns_of_unit_batches() {
                let _ = rec.send_columns(entity, index, columns);
            }
        }
    }
}

/// A series' name, colour and width (a static row), for a series that appears mid-run.
fn series_style(buf: &mut ChunkBuffer, entity: &str, name: &str, color: Color) {
    buf.style(
        entity,
        name,
        &rerun::SeriesLines::new()
            .with_names([name])
            .with_colors([color])
            .with_widths([2.0])
            .with_interpolation_mode(rerun::components::InterpolationMode::StepAfter),
    );
}

/// The range the plots' linked time axes show for a run that ended at `end` (ns): the run
/// with 5 % of it (at least 100 ms) of room each side, so the labels at its ends show
/// whole.
fn time_axis_ns(end: Nanos) -> (i64, i64) {
    let end = i64::try_from(end.0).unwrap_or(i64::MAX);
    let pad = (end / 20).max(100_000_000);
    (-pad, end.saturating_add(pad))
}

/// The runtime-clock time point of control step `step` at run time `t`, on `timeline`.
fn time_point(timeline: &'static str, t: Nanos, step: u64) -> TimePoint {
    TimePoint::default()
        .with(
            Timeline::new_duration(timeline),
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
    /// A symbolic link or a non-regular file at the path, a move into place that failed, or
    /// a file written in place found replaced or removed at its name at the end.
    #[error("--record {0}")]
    Output(ratelab_core::output::OutputError),
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
        /// Its kind (a front end says it in its own terms: Python's `PermissionError`).
        kind: std::io::ErrorKind,
    },
    /// The graph cannot be drawn as a watcher sees it ([`watched::record`]): its topics
    /// cannot be made (a validated configuration has none that cannot).
    #[error("{0}")]
    Graph(String),
    /// rerun refused or failed to write.
    #[error("recording {path}: {detail}")]
    Rerun {
        /// The recording's final path.
        path: PathBuf,
        /// rerun's reason.
        detail: String,
    },
}

impl RecordingError {
    /// The refusal in `speech`'s words: the command line's as [`std::fmt::Display`] says it
    /// (`--record file exists: r.rrd (pass --force to overwrite)`), Python's naming the
    /// keyword (`record: r.rrd: file exists (pass force=True to overwrite)`).
    pub fn said(&self, speech: ratelab_runtime::setting::Speech) -> String {
        use ratelab_runtime::setting::{Setting, Speech};
        if speech == Speech::Flags {
            return self.to_string();
        }
        let record = speech.name(Setting::Record);
        match self {
            RecordingError::Output(o) => format!("{record}: {o}"),
            RecordingError::IsDirectory(p) => {
                format!("{record}: {} is a directory, not a file", p.display())
            }
            RecordingError::Exists(p) => format!(
                "{record}: {}: file exists (pass {} to overwrite)",
                p.display(),
                speech.force()
            ),
            RecordingError::Unwritable { path, detail, .. } => {
                format!("{record}: cannot write {}: {detail}", path.display())
            }
            other => other.to_string(),
        }
    }
}

impl From<ratelab_core::output::OutputError> for RecordingError {
    fn from(e: ratelab_core::output::OutputError) -> Self {
        use ratelab_core::output::OutputError;
        match e {
            OutputError::Exists(p) => RecordingError::Exists(p),
            OutputError::NotRegular {
                path,
                kind: "a folder",
            } => RecordingError::IsDirectory(path),
            OutputError::Io { path, detail, kind } => {
                RecordingError::Unwritable { path, detail, kind }
            }
            other => RecordingError::Output(other),
        }
    }
}

/// rerun's refusal to start a recording of `path`: a file it could not create is the file
/// system's refusal, [`RecordingError::Unwritable`] with its kind kept (a front end says it
/// in its own terms: Python's `PermissionError`); any other failure is rerun's.
fn stream_error(path: &Path, e: rerun::RecordingStreamError) -> RecordingError {
    match &e {
        rerun::RecordingStreamError::FileSink(rerun::sink::FileSinkError::CreateFile {
            source,
            ..
        }) => RecordingError::Unwritable {
            path: path.to_path_buf(),
            kind: source.kind(),
            detail: source.to_string(),
        },
        _ => RecordingError::Rerun {
            path: path.to_path_buf(),
            detail: e.to_string(),
        },
    }
}

/// Format a rate for a file name: `50`, `7.5`.
fn hz_label(hz: f64) -> String {
    let s = format!("{hz:.3}");
    s.trim_end_matches('0').trim_end_matches('.').to_string()
}

/// The entity name of a topic's bus series: `/obs` → `obs`, `/a/b` → `a_b`.
pub fn bus_name(topic: &str) -> String {
    topic.trim_start_matches('/').replace('/', "_")
}

/// The topics of `shape` that cross processes: a subscriber in another process than the
/// publisher's (none in one process).
fn crossing_topics(shape: &GraphShape) -> impl Iterator<Item = &TopicShape> {
    let process = |name: &str| {
        shape
            .nodes
            .iter()
            .find(|n| n.name == name)
            .and_then(|n| n.process.as_deref())
    };
    shape.topics.iter().filter(move |t| {
        let from = process(&t.publisher);
        from.is_some() && t.subscribers.iter().any(|s| process(s) != from)
    })
}

/// The force the motor applies per unit of control (the `gear` of `assets/cartpole.xml`), N:
/// the graph's [`ratelab_core::plant::GEAR_N`].
pub const FORCE_PER_CONTROL_N: f64 = ratelab_core::plant::GEAR_N;

/// Half the rail's length (the slider's range in `assets/cartpole.xml`), m.
pub const RAIL_HALF_LENGTH_M: f64 = 2.9;

/// How to record.
#[derive(Clone, Debug, Default)]
pub struct RecordOptions {
    /// Also stream live to a rerun viewer spawned from PATH.
    pub spawn: bool,
    /// Record only this span of run time (`--record-window`); `None`: all of it.
    pub window: Option<RecordWindow>,
    /// The run is offered to ROS 2 on this domain (`--ros2`): said in its settings.
    pub ros2_domain: Option<u32>,
    /// What the run offers to ROS 2 is also written as a rosbag2 bag in this folder
    /// (`--bag DIR`): said in its settings.
    pub bag: Option<PathBuf>,
}

/// An open recording. Cheap to clone (the stream is a shared handle).
#[derive(Clone)]
pub struct Recording {
    rec: RecordingStream,
    path: PathBuf,
    /// The path rerun was given to write ([`ratelab_core::output::PendingFile::write_path`]:
    /// `/proc/self/fd/N` for a file written in place), said as `path` in its errors.
    written_at: PathBuf,
    clock: ClockKind,
    /// The settings the run started with (for the blueprint's scales and ids).
    cfg: RunConfig,
    buffer: Arc<Mutex<ChunkBuffer>>,
    /// The latest actuator step logged (stamps events that arrive between steps).
    last_step: Arc<std::sync::atomic::AtomicU64>,
    /// Its run time, ns (the bus counters come with the steps: see [`Recording::finish`]).
    last_step_ns: Arc<std::sync::atomic::AtomicU64>,
    /// Each topic's messages published by then, by topic name (for the msg/s from the last
    /// step to the run's end: see [`Recording::finish`]).
    last_step_published: Arc<Mutex<BTreeMap<String, u64>>>,
    /// The graph, once the observer is attached (for the final layout).
    shape: Arc<Mutex<Option<GraphShape>>>,
    /// The file rerun writes: at `path` from the start, or (replacing a file) beside it and
    /// moved to `path` by [`Recording::finish`].
    file: Arc<Committer>,
    /// Per node (by index): the release of its last tick logged and the periods its timer
    /// skipped so far ([`Recording::node_span`]).
    lanes: Arc<Mutex<Vec<Lane>>>,
    /// Per topic (by name): the deadline misses the events have told so far (offered,
    /// requested) and when the last such event was ([`DEADLINE_EVENT_GAP`]).
    deadline_said: Arc<Mutex<BTreeMap<String, DeadlineSaid>>>,
    /// Lines the summary gains beyond the metrics' ([`Recording::summary_line`]).
    extra_summary: Arc<Mutex<Vec<String>>>,
    /// Events known before they happen (an injected fault's start and end), oldest first:
    /// each is logged once the run reaches its time, so a run that ended first (a fall, a
    /// watchdog) records none after its end.
    due_events: Arc<Mutex<VecDeque<DueEvent>>>,
    /// The span of run time whose step rows are recorded ([`RecordOptions::window`]).
    window: Option<RecordWindow>,
    /// Node rates a ROS 2 parameter set changed, (node, Hz), whose change the graph has not
    /// shown yet ([`Recording::parameter_set`]).
    announced: Arc<Mutex<Vec<(String, f64)>>>,
}

/// An event known in advance: its run time, text, level and mark (none: listed only).
type DueEvent = (Nanos, String, &'static str, Option<Mark>);

/// A topic's deadline misses as the events told them: (offered, requested) and the time
/// of the last event.
type DeadlineSaid = (u64, u64, Nanos);

/// Deadline misses closer than this to the last event about them are counted, not listed:
/// a lossy link misses a deadline every few steps, and a line for each buried everything
/// else in the event list. A burst's first miss gets a line; the end of the run says how
/// many there were in all.
const DEADLINE_EVENT_GAP: Nanos = Nanos(1_000_000_000);

/// A node's lane in the executor timeline: the release of its last tick logged, and the
/// periods its timer skipped so far.
type Lane = (Option<Nanos>, u64);

/// Does a run of `cfg` measure its executors (compute times, or executors that share
/// threads)? Its recording then has the executor timeline, response times and skipped
/// ticks.
fn measures_executors(cfg: &RunConfig) -> bool {
    cfg.graph.nodes.iter().any(|n| n.compute.is_some()) || !cfg.graph.execution_plan().is_per_node()
}

/// How high a node's lane sits in the executor timeline: its tie-break rank, the lane at
/// `rank` while idle and `rank + LANE_BUSY` while its tick holds a thread.
const LANE_BUSY: f64 = 0.8;

/// Where the ground grid lies: just under the rail (the rail's top is the cart's bottom).
const GROUND_Z_M: f64 = -0.08;
/// The cart body's half height; the pole's hinge is at the body's centre, as in MuJoCo.
const CART_HALF_HEIGHT_M: f64 = 0.05;
/// The rail's half thickness.
const RAIL_HALF_THICKNESS_M: f64 = 0.01;

/// Node-graph positions (id → x, y) in graph units, and the bounds that frame them.
fn graph_positions(shape: &GraphShape) -> (Vec<(String, [f32; 2])>, bpc::VisualBounds2D) {
    positions_of(shape.columns())
}

/// Positions (id → x, y) in graph units for boxes in left-to-right `columns` (id, column),
/// and the bounds that frame them: a node graph's, or a large graph's groups'
/// ([`grouped`]).
fn positions_of(columns: Vec<(String, usize)>) -> (Vec<(String, [f32; 2])>, bpc::VisualBounds2D) {
    const DX: f32 = 150.0;
    const DY: f32 = 70.0;
    let n_cols = columns.iter().map(|(_, c)| c + 1).max().unwrap_or(1);
    let mut rows: BTreeMap<usize, usize> = BTreeMap::new();
    for (_, col) in &columns {
        *rows.entry(*col).or_insert(0) += 1;
    }
    let band_rows = rows.values().copied().max().unwrap_or(1);
    // The chapter's five columns fit the panel in one band; a longer chain is folded into
    // two or more bands, the second running right to left (its arrows stay short), so that
    // its labels keep a readable size in the panel (seven boxes in a row made them tiny).
    let wrap = if n_cols > 5 {
        n_cols.div_ceil(2).max(4)
    } else {
        n_cols
    };
    let mut row_of: BTreeMap<usize, usize> = BTreeMap::new();
    let mut out = Vec::new();
    for (id, col) in columns {
        let row = row_of.entry(col).or_insert(0);
        let (band, at) = (col / wrap, col % wrap);
        let x = if band % 2 == 1 { wrap - 1 - at } else { at };
        let y = (band * (band_rows + 1) + *row) as f32 * DY;
        out.push((id, [x as f32 * DX, y]));
        *row += 1;
    }
    let max_x = out.iter().map(|(_, p)| p[0]).fold(0.0, f32::max);
    let max_y = out.iter().map(|(_, p)| p[1]).fold(0.0, f32::max);
    let range = |lo: f32, hi: f32| rerun::datatypes::Range1D([f64::from(lo), f64::from(hi)]);
    let bounds = bpc::VisualBounds2D(rerun::datatypes::Range2D {
        x_range: range(-0.45 * DX, max_x + 0.45 * DX),
        y_range: range(-0.6 * DY, max_y + 0.6 * DY),
    });
    (out, bounds)
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
    /// notice. The viewer layout is sent when the graph is known (the
    /// [`Recording::observer`] is attached to it).
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
        // Written at its name from the start where nothing is there: a run killed midway
        // leaves what it recorded where the user asked (the module's rule).
        let (pending, file) = ratelab_core::output::PendingFile::create_in_place(path, force)?;
        drop(file);
        // Rerun opens the file itself: by its descriptor where it is written in place.
        let tmp = pending.write_path();
        let mut builder = RecordingStreamBuilder::new(APP_ID);
        if let Some(id) = deterministic_id(cfg) {
            builder = builder
                .recording_id(id)
                .batcher_config(rerun::log::ChunkBatcherConfig {
                    flush_tick: std::time::Duration::MAX,
                    flush_num_bytes: 256 * 1024,
                    flush_num_rows: u64::MAX,
                    ..rerun::log::ChunkBatcherConfig::DEFAULT
                });
        }
        let rec_err = |e: rerun::RecordingStreamError| stream_error(path, e);
        let mut notice = None;
        let live = opts.spawn && viewer_on_path();
        if opts.spawn && !live {
            notice = Some(
                format!("no rerun viewer on PATH: recording to the file only (install one: {VIEWER_INSTALL}, or cargo install rerun-cli --locked --version {VIEWER_VERSION})"),
            );
        }
        let rec = if live {
            // Start the viewer, then write to the file and stream to the viewer at once.
            let viewer = rerun::spawn(&rerun::SpawnOptions::default()).map_err(|e| {
                RecordingError::Rerun {
                    path: path.to_path_buf(),
                    detail: e.to_string(),
                }
            })?;
            let file = rerun::sink::FileSink::new(&tmp)
                .map_err(|e| rec_err(rerun::RecordingStreamError::FileSink(e)))?;
            // The live sink never holds up the file, even when the viewer cannot start.
            let sinks: Vec<Box<dyn rerun::sink::LogSink>> = vec![
                Box::new(file),
                Box::new(live::LiveSink::new(viewer.child_pid)),
            ];
            builder.set_sinks(sinks).map_err(rec_err)?
        } else {
            builder.save(&tmp).map_err(rec_err)?
        };
        if cfg.clock == ClockKind::Virtual {
            rec.set_log_time_enabled(false);
        }
        let recording = Self {
            rec,
            path: path.to_path_buf(),
            written_at: tmp.clone(),
            clock: cfg.clock,
            cfg: cfg.clone(),
            buffer: Arc::new(Mutex::new(ChunkBuffer::new(timeline_name(cfg.clock)))),
            file: Arc::new(Committer(Mutex::new(Some(pending)))),
            last_step: Arc::default(),
            last_step_ns: Arc::default(),
            last_step_published: Arc::default(),
            shape: Arc::default(),
            lanes: Arc::default(),
            deadline_said: Arc::default(),
            extra_summary: Arc::new(Mutex::new(
                opts.window
                    .iter()
                    .map(|w| {
                        format!(
                            "recorded: the plots hold {} of the run (--record-window); the events and this summary cover all of it",
                            w.describe()
                        )
                    })
                    .collect(),
            )),
            due_events: Arc::default(),
            window: opts.window,
            announced: Arc::default(),
        };
        recording.log_settings(cfg, policy, opts);
        Ok((recording, notice))
    }

    /// The file being written.
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// Are the rows of run time `t` recorded (inside the [`RecordWindow`], if any)?
    pub fn records(&self, t: Nanos) -> bool {
        self.window.is_none_or(|w| w.contains(t))
    }

    /// The span of run time recorded, if not all of it.
    pub fn window(&self) -> Option<RecordWindow> {
        self.window
    }

    /// The underlying rerun stream.
    pub fn stream(&self) -> &RecordingStream {
        &self.rec
    }

    /// Send the viewer layout for a graph of `shape`: when the graph is built (`over` none:
    /// plots without a scale known up front fit themselves while the run goes), and again
    /// when the run is over (`over`: the values every series took, where in time, and the
    /// run's end), every plot's y range then padded around what its series took, so nothing
    /// sits on a plot's edge, and its legend placed where none of its series is
    /// ([`legend::place_legends`]). The second layout is a blueprint of its own, activated
    /// after the first.
    fn send_layout(
        &self,
        shape: &GraphShape,
        over: Option<(&Extents, &legend::Seen, Nanos)>,
    ) -> Result<(), RecordingError> {
        let mut root = layout_for(shape, &self.cfg, over.map(|(e, _, _)| e));
        let axis = over.map(|(_, _, end)| time_axis_ns(end));
        if let (Some((extents, seen, _)), Some(x)) = (over, axis) {
            legend::place_legends(&mut root, seen, extents, x);
        }
        let stage = if over.is_some() { "final" } else { "start" };
        let id = deterministic_id(&self.cfg).map(|id| format!("{id}-blueprint-{stage}"));
        let timeline = timeline_name(self.cfg.clock);
        let (msgs, activate) = layout::blueprint_messages(APP_ID, id, &root, timeline, axis)
            .map_err(|detail| RecordingError::Rerun {
                path: self.path.clone(),
                detail,
            })?;
        self.rec.send_blueprint(msgs, activate);
        Ok(())
    }

    /// The graph is built: keep its shape, name and colour its series, send the layout.
    fn attach(&self, shape: &GraphShape) {
        *self.shape.lock().unwrap_or_else(|e| e.into_inner()) = Some(shape.clone());
        self.log_styles(shape);
        if let Err(e) = self.send_layout(shape, None) {
            // The data is still recorded; the viewer falls back to its own layout.
            self.event(Nanos::ZERO, &format!("no viewer layout: {e}"), "WARN");
        }
    }

    /// Log the events known in advance that are due by run time `now` (at their own times,
    /// on control step `step`, the step that reached them).
    fn log_due_events(&self, buf: &mut ChunkBuffer, now: Nanos, step: u64) {
        let mut due = self.due_events.lock().unwrap_or_else(|e| e.into_inner());
        while due.front().is_some_and(|(t, _, _, _)| *t <= now) {
            if let Some((t, text, level, mark)) = due.pop_front() {
                buf.event(t, step, mark, &text, level);
            }
        }
    }

    fn lock(&self) -> std::sync::MutexGuard<'_, ChunkBuffer> {
        self.buffer.lock().unwrap_or_else(|e| e.into_inner())
    }

    /// Log a line of the run's text log ([`ratelab_core::textlog`]) under `log/<node>` (`log/ratelab`
    /// for ratelab's own), at its run time (the latest step's when it has none), with its
    /// level: the final layout shows them in a view of their own.
    pub fn log_line(&self, line: &ratelab_core::textlog::LogLine) {
        let step = self.last_step.load(std::sync::atomic::Ordering::Relaxed);
        let mut buf = self.lock();
        // Outside any tick (a script's loading): at the latest actuator step's time.
        let t = line.t.unwrap_or_else(|| {
            Nanos((step as f64 * 1e9 / ratelab_core::plant::ACTUATOR_HZ).round() as u64)
        });
        let time = buf.at(t, step);
        let level = match line.level {
            ratelab_core::textlog::Level::Info => rerun::components::TextLogLevel::INFO,
            ratelab_core::textlog::Level::Warn => rerun::components::TextLogLevel::WARN,
            ratelab_core::textlog::Level::Error => rerun::components::TextLogLevel::ERROR,
        };
        let who = line.node.as_deref().unwrap_or("ratelab");
        buf.add(
            &format!("log/{who}"),
            &time,
            &rerun::TextLog::new(line.text.as_str()).with_level(level),
        );
        buf.extents.insert(LOG_MARK.to_string(), (0.0, 0.0));
    }

    /// Log an event line at run time `t` (and the latest control step), at `level`
    /// (`"INFO"`, `"WARN"`, `"ERROR"`): a warning or an error is marked as trouble on the
    /// pole-angle plot; a return (`rejoined`, `heard again`, `alive again`) as a recovery.
    pub fn event(&self, t: Nanos, text: &str, level: &str) {
        self.event_marked(t, events::mark_of_line(text, level), text, level);
    }

    /// Log an event line with its mark (none: listed, not marked).
    fn event_marked(&self, t: Nanos, mark: Option<Mark>, text: &str, level: &str) {
        let step = self.last_step.load(std::sync::atomic::Ordering::Relaxed);
        self.lock().event(t, step, mark, text, level);
    }

    /// Log a mid-run change made from outside the graph (a brain swap) at run time `t`: an
    /// event, and a mark on the pole-angle plot.
    pub fn change(&self, t: Nanos, text: &str) {
        self.event_marked(
            t,
            Some(Mark::Change),
            text,
            rerun::components::TextLogLevel::INFO,
        );
    }

    /// An observer to hand to the graph: logs every actuator tick. When it is attached to
    /// the graph, the viewer layout for that graph is sent.
    pub fn observer(&self) -> Box<dyn StepObserver> {
        Box::new(self.new_observer(GraphShape::default()))
    }

    /// An observer of a graph known as data rather than by its handles: one that runs in
    /// other processes, whose figures arrive over the network
    /// ([`watched::record`]). The viewer layout for `shape` is sent now;
    /// [`StepObserver::attach`] is not needed (and would replace `shape`).
    pub fn observer_for(&self, shape: GraphShape) -> Box<dyn StepObserver> {
        self.attach(&shape);
        Box::new(self.new_observer(shape))
    }

    fn new_observer(&self, shape: GraphShape) -> RecordingObserver {
        RecordingObserver::new(self.clone(), shape)
    }

    /// Log a real-clock tick: its lateness ([`Recording::node_tick`]) and, when the run
    /// measures its executors, its span for the executor timeline ([`Recording::node_span`]:
    /// released at its deadline, started `lateness` after it, ended when it had taken `took`).
    pub fn real_tick(&self, t: &ratelab_runtime::scheduler::TickReport<'_>) {
        self.node_tick(t.name, t.now, t.lateness);
        if measures_executors(&self.cfg) {
            self.node_span(&ratelab_core::executor::CallbackSpan {
                node: t.node,
                release: t.now.saturating_sub(t.lateness),
                start: t.now,
                end: t.now.saturating_add(t.took),
            });
        }
    }

    /// A hook that logs every span of a virtual run ([`Recording::node_span`]), when the
    /// run measures its executors (`None` else: nothing to draw).
    pub fn span_hook(&self) -> Option<ratelab_core::executor::SpanHook> {
        let me = self.clone();
        measures_executors(&self.cfg)
            .then(|| Arc::new(move |s: &ratelab_core::executor::CallbackSpan| me.node_span(s)) as _)
    }

    /// Add `line` to the summary written at [`Recording::finish`], after the metrics' lines
    /// (a launch's processes and wire latencies).
    pub fn summary_line(&self, line: impl Into<String>) {
        self.extra_summary
            .lock()
            .unwrap_or_else(|e| e.into_inner())
            .push(line.into());
    }

    /// Log the over-the-wire latency of topic `topic` (a graph across processes) at run time
    /// `t`: the median and the 99th percentile, µs, of the samples its subscriber's process
    /// received so far, as `bus/<topic>/wire_p50_us` and `bus/<topic>/wire_p99_us` (named
    /// and coloured as the topic at their first value).
    pub fn wire(&self, t: Nanos, topic: &str, p50_us: f64, p99_us: f64) {
        let step = self.last_step.load(std::sync::atomic::Ordering::Relaxed);
        let entity = bus_name(topic);
        let mut buf = self.lock();
        let hue = topic_color(topic);
        for (stat, value, width, color) in
            [("p50", p50_us, 2.5, hue), ("p99", p99_us, 1.5, dimmed(hue))]
        {
            let path = format!("bus/{entity}/wire_{stat}_us");
            if !buf.extents.contains_key(&path) {
                let name = format!("{topic} {stat}");
                buf.style(
                    &path,
                    &name,
                    &rerun::SeriesLines::new()
                        .with_names([name.as_str()])
                        .with_colors([color])
                        .with_widths([width]),
                );
            }
            buf.scalar(&path, t, step, value);
        }
    }

    /// Log one node tick's lateness (real clock), on the node's own thread.
    pub fn node_tick(&self, node: &str, now: Nanos, lateness: Nanos) {
        if !self.records(now) {
            return;
        }
        let entity = format!("nodes/{node}/lateness_ms");
        let ms = lateness.as_millis_f64();
        widen(&mut self.lock().extents, &entity, ms);
        self.rec.set_time(
            timeline_name(self.clock),
            std::time::Duration::from_nanos(now.0),
        );
        let _ = self.rec.log(entity, &rerun::Scalars::single(ms));
    }

    /// Log one tick as its executor ran it (virtual clock: the scheduler's span; real clock:
    /// the tick's start, lateness and time taken) for the executor timeline: node `node`'s
    /// lane (`nodes/<name>/executor_lane`, its rank, `LANE_BUSY` higher from the tick's start
    /// to its end), its response time (`nodes/<name>/response_ms`: release → outputs
    /// published, at the end) and the periods its timer skipped so far
    /// (`nodes/<name>/skipped_ticks`: a release more than a period after the last, at the
    /// node's starting rate). Only for runs that measure executors.
    pub fn node_span(&self, span: &ratelab_core::executor::CallbackSpan) {
        let Some(n) = self.cfg.graph.nodes.get(span.node) else {
            return;
        };
        if !self.records(span.release) {
            return;
        }
        let base = span.node as f64;
        let lane = format!("nodes/{}/executor_lane", n.name);
        let period = ratelab_core::rate::period_for_hz(n.rate_hz).map_or(0, |p| p.0.max(1));
        let (skipped, first_skip) = {
            let mut lanes = self.lanes.lock().unwrap_or_else(|e| e.into_inner());
            if lanes.len() <= span.node {
                lanes.resize(span.node + 1, (None, 0));
            }
            let (last, total) = &mut lanes[span.node];
            let before = *total;
            if let (Some(l), true) = (*last, period > 0) {
                let gap = span.release.saturating_sub(l).0;
                *total += (gap / period).saturating_sub(1);
            }
            *last = Some(span.release);
            (*total, before == 0 && *total > 0)
        };
        if first_skip {
            // The moment a timer first lost periods to a busy thread is trouble to find in
            // time: a warning, at the release that came late (the total is at the end).
            self.event(
                span.release,
                &format!(
                    "node {} skipped {} tick(s): its timer's periods passed while its executor's thread was busy",
                    n.name, skipped
                ),
                rerun::components::TextLogLevel::WARN,
            );
        }
        let step = self.last_step.load(std::sync::atomic::Ordering::Relaxed);
        let mut buf = self.lock();
        let (start, end) = (span.start, span.end.max(span.start));
        buf.scalar(&lane, start, step, base + LANE_BUSY);
        buf.scalar(&lane, end, step, base);
        buf.scalar(
            &format!("nodes/{}/response_ms", n.name),
            end,
            step,
            end.saturating_sub(span.release).as_millis_f64(),
        );
        buf.scalar(
            &format!("nodes/{}/skipped_ticks", n.name),
            end,
            step,
            skipped as f64,
        );
    }

    /// At the end: for each topic whose deadline misses grew since its last event, one line
    /// with how many more and how many in all.
    fn deadline_totals(&self, buf: &mut ChunkBuffer, metrics: &Metrics, end: Nanos) {
        let said = self.deadline_said.lock().unwrap_or_else(|e| e.into_inner());
        for (name, t) in &metrics.topics {
            let total = |k: &str| t.qos_counters.get(k).copied().unwrap_or(0);
            let now = (
                total("offered_deadline_missed"),
                total("requested_deadline_missed"),
            );
            let Some(&(so, sr, _)) = said.get(name) else {
                continue;
            };
            if now.0 > so || now.1 > sr {
                buf.event(
                    end,
                    metrics.steps,
                    Some(Mark::Trouble),
                    &deadline_line(name, (so, sr), now, ""),
                    rerun::components::TextLogLevel::WARN,
                );
            }
        }
    }

    /// Log the end of the run (an event and the summary document) at its end time, flush
    /// and close the file and (replacing a file) move it into place, so the recording is
    /// complete whichever way the run ended. Nothing is logged to it after this.
    ///
    /// # Errors
    /// [`RecordingError::Rerun`] when the flush fails or the file's end could not be
    /// written ([`Recording::close`]), [`RecordingError`] when the file cannot be moved into
    /// place (e.g. its name was taken meanwhile, without `force`) or, written in place, was
    /// replaced at its name meanwhile.
    pub fn finish(&self, metrics: &Metrics, end: &RunEnd) -> Result<(), RecordingError> {
        let summary = metrics.summary_lines(None);
        let level = match end.reason {
            EndReason::NodeFailed { .. } => rerun::components::TextLogLevel::ERROR,
            _ => rerun::components::TextLogLevel::INFO,
        };
        let verdict = summary.get(2).cloned().unwrap_or_default();
        let reason = end.reason.words(metrics.stopped_by_watchdog.is_some());
        // The known events the run reached after its last step (an actuator killed or
        // stalled takes no step at them); none past the end.
        {
            let mut buf = self.lock();
            let step = self.last_step.load(std::sync::atomic::Ordering::Relaxed);
            self.log_due_events(&mut buf, end.at, step);
        }
        if let Some(watchdog) = &metrics.stopped_by_watchdog {
            self.event(end.at, watchdog, rerun::components::TextLogLevel::WARN);
        }
        // Each node whose timer skipped periods, in all: the rate it achieved of its own.
        for (name, n) in &metrics.nodes {
            if let Some(x) = n.exec.as_ref().filter(|x| x.skipped_ticks > 0) {
                // A total (its first skip was marked where it happened).
                self.event_marked(
                    end.at,
                    None,
                    &format!(
                        "node {name} skipped {} tick(s) in all (ticked {} times at {} Hz set): its executor's thread was busy",
                        x.skipped_ticks, n.ticks, n.rate_hz
                    ),
                    rerun::components::TextLogLevel::WARN,
                );
            }
        }
        self.event_marked(
            end.at,
            (level == rerun::components::TextLogLevel::ERROR).then_some(Mark::Trouble),
            &format!(
                "end: {reason}, {}",
                ratelab_core::metrics::counted(metrics.steps, "actuator step")
            ),
            level,
        );
        let mut doc = format!("**{verdict}** ({reason}).\n\n");
        for (i, line) in summary.iter().enumerate() {
            if i != 2 {
                doc.push_str(&format!("- {line}\n"));
            }
        }
        for line in self
            .extra_summary
            .lock()
            .unwrap_or_else(|e| e.into_inner())
            .iter()
        {
            doc.push_str(&format!("- {line}\n"));
        }
        {
            let mut buf = self.lock();
            self.deadline_totals(&mut buf, metrics, end.at);
            // The bus counters come with the actuator's steps: an actuator killed (or stalled
            // past the end) left them short of the run's end, where the summary counts on.
            // Its totals at the end, so that the bus plots reach them, and, when the steps
            // stopped a whole window (1 s) or more before the end, its msg/s there: the
            // messages published from the last step to the end over that time (a publisher
            // that kept its rate keeps its line level). Over a shorter gap (a real-clock
            // run's last step a few ms before its end) that quotient is noise: a launch's
            // merged totals against its last step's counters read as a 500 msg/s spike.
            let last_ns = self.last_step_ns.load(std::sync::atomic::Ordering::Relaxed);
            if metrics.steps > 0 && last_ns < end.at.0 {
                let since_s = end.at.saturating_sub(Nanos(last_ns)).as_secs_f64();
                let then = self
                    .last_step_published
                    .lock()
                    .unwrap_or_else(|e| e.into_inner())
                    .clone();
                for (name, t) in &metrics.topics {
                    let entity = bus_name(name);
                    let at = |m: &str| format!("bus/{entity}/{m}");
                    buf.scalar(&at("published"), end.at, metrics.steps, t.published as f64);
                    buf.scalar(&at("dropped"), end.at, metrics.steps, t.dropped as f64);
                    if let (Some(&before), true) = (then.get(name), since_s >= 1.0) {
                        let rate = t.published.saturating_sub(before) as f64 / since_s;
                        buf.scalar(&at("msg_per_s"), end.at, metrics.steps, rate);
                    }
                }
                // A large graph's groups reach the end with their topics.
                let shape = self.shape.lock().unwrap_or_else(|e| e.into_inner());
                if let Some(shape) = shape.as_ref() {
                    grouped::end_rows(&mut buf, shape, end.at, metrics.steps);
                }
            }
            // The skipped ticks end where metrics.json ends them (a tick still computing
            // at the end counted its skipped periods when it started, and no span ended).
            let logged = self.lanes.lock().unwrap_or_else(|e| e.into_inner()).clone();
            for (name, n) in &metrics.nodes {
                let spans = logged.get(n.rank).is_some_and(|(last, _)| last.is_some());
                if let (Some(x), true) = (&n.exec, spans) {
                    let entity = format!("nodes/{name}/skipped_ticks");
                    buf.scalar(&entity, end.at, metrics.steps, x.skipped_ticks as f64);
                }
            }
            buf.add(
                "summary",
                &TimePoint::default(),
                &rerun::TextDocument::from_markdown(doc),
            );
            buf.when_document(true);
            // A run whose control rate changed (a lab session) says so in its name.
            if let (Some(a), Some(b)) = (metrics.control_hz, metrics.control_hz_end) {
                if a != b {
                    buf.add(
                        &rerun::EntityPath::properties().to_string(),
                        &TimePoint::default(),
                        &rerun::RecordingInfo::update_fields().with_name(run_name(
                            &self.cfg,
                            Some(format!("{} → {}", hz_label(a), hz_label(b))),
                        )),
                    );
                }
            }
            reference_lines(&mut buf, end.at, metrics.steps);
        }
        let shape = self.shape.lock().unwrap_or_else(|e| e.into_inner()).clone();
        if let Some(shape) = shape {
            let (extents, seen) = {
                let buf = self.lock();
                (buf.extents.clone(), buf.seen.clone())
            };
            self.send_layout(&shape, Some((&extents, &seen, end.at)))?;
        }
        self.flush()?;
        self.close()?;
        Ok(self.file.commit()?)
    }

    /// Close the file's sink: rerun writes the file's end (its footer) then, and only logs a
    /// failure there, so its folder is tried after (a disk that filled cut the end short,
    /// and the recording must not be said written whole).
    ///
    /// # Errors
    /// [`RecordingError::Rerun`] when the folder takes no more writes.
    fn close(&self) -> Result<(), RecordingError> {
        self.rec.disconnect();
        match self.path.parent().and_then(writing_beside_fails) {
            Some(why) => Err(RecordingError::Rerun {
                path: self.path.clone(),
                detail: format!(
                    "its end could not be written ({why}): cut short, what was written is kept and opens as a recording cut short"
                ),
            }),
            None => Ok(()),
        }
    }

    /// Send every buffered row and flush the file, waiting [`FLUSH_TIMEOUT`] at most.
    ///
    /// # Errors
    /// [`RecordingError::Rerun`] when the sink fails or takes longer than [`FLUSH_TIMEOUT`].
    pub fn flush(&self) -> Result<(), RecordingError> {
        self.lock().send(&self.rec);
        self.rec.flush_with_timeout(FLUSH_TIMEOUT).map_err(|e| {
            if matches!(e, rerun::sink::SinkFlushError::Timeout) {
                // A disk that takes no writes and refuses none: writing beside it would
                // wait too, and so would the stream's own end (its drop flushes without a
                // limit and joins its writer). The stream is left, never dropped.
                std::mem::forget(self.rec.clone());
                return RecordingError::Rerun {
                    path: self.path.clone(),
                    detail: format!(
                        "the disk took no writes for {} s: cut short, what was written is kept and opens as a recording cut short",
                        FLUSH_TIMEOUT.as_secs()
                    ),
                };
            }
            // rerun's file writer says only that it stopped: the OS's reason is found by
            // writing beside the file (a full disk refuses that too).
            let why = self
                .path
                .parent()
                .and_then(writing_beside_fails)
                .map_or_else(String::new, |e| format!(" ({e})"));
            // rerun names the path it was given: the user's, not a descriptor's.
            let e = (e.to_string()).replace(
                &self.written_at.display().to_string(),
                &self.path.display().to_string(),
            );
            RecordingError::Rerun {
                path: self.path.clone(),
                detail: format!(
                    "{e}{why}: cut short, what was written is kept and opens as a recording cut short"
                ),
            }
        })
    }

    /// The clock this recording was stamped with.
    pub fn clock(&self) -> ClockKind {
        self.clock
    }
}

#[cfg(test)]
mod tests {
    use super::blueprint::label_top;
    use super::shape::tests::shape;
    use super::*;

    #[test]
    fn a_recording_refused_speaks_the_front_ends_words() {
        use ratelab_core::output::OutputError;
        use ratelab_runtime::setting::Speech;
        let p = || PathBuf::from("r.rrd");
        let speaks = |e: &RecordingError, flags: &str, keywords: &str| {
            assert_eq!(e.said(Speech::Flags), flags);
            assert_eq!(e.said(Speech::Keywords), keywords);
        };
        speaks(
            &RecordingError::Exists(p()),
            "--record file exists: r.rrd (pass --force to overwrite)",
            "record: r.rrd: file exists (pass force=True to overwrite)",
        );
        // A symbolic link put at the final name while the run went, found as a recording
        // that replaces a file is moved into place when it ends: no flag in Python.
        let moved = RecordingError::from(OutputError::Symlink(p()));
        assert!(moved.said(Speech::Flags).starts_with("--record "));
        let said = moved.said(Speech::Keywords);
        assert_eq!(
            said,
            "record: r.rrd: is a symbolic link; refusing to write through it"
        );
        // A file written in place, moved or removed under the run: said at its end.
        speaks(
            &RecordingError::from(OutputError::Replaced(p())),
            "--record r.rrd: moved, replaced or removed by something else while it was written: the recording is not at that name",
            "record: r.rrd: moved, replaced or removed by something else while it was written: the recording is not at that name",
        );
        // A full disk: the file named, in each front end's words, its kind kept.
        let full = RecordingError::from(OutputError::Io {
            path: p(),
            detail: "No space left on device".into(),
            kind: std::io::ErrorKind::StorageFull,
        });
        speaks(
            &full,
            "cannot write recording r.rrd: No space left on device",
            "record: cannot write r.rrd: No space left on device",
        );
        assert!(matches!(
            full,
            RecordingError::Unwritable {
                kind: std::io::ErrorKind::StorageFull,
                ..
            }
        ));
        // rerun failing to create the file: the file system's refusal, its kind kept.
        let denied = std::io::Error::from(std::io::ErrorKind::PermissionDenied);
        let made = stream_error(
            &p(),
            rerun::RecordingStreamError::FileSink(rerun::sink::FileSinkError::CreateFile {
                source: denied,
                path: p(),
            }),
        );
        assert!(
            matches!(
                made,
                RecordingError::Unwritable {
                    kind: std::io::ErrorKind::PermissionDenied,
                    ..
                }
            ),
            "{made:?}"
        );
        assert!(made
            .said(Speech::Keywords)
            .starts_with("record: cannot write r.rrd: "));
        let rerun = RecordingError::Rerun {
            path: p(),
            detail: "closed".into(),
        };
        for speech in [Speech::Flags, Speech::Keywords] {
            assert!(!rerun.said(speech).contains("--"), "{}", rerun.said(speech));
            assert!(!rerun.said(speech).contains("record:"));
        }
        let dir = RecordingError::IsDirectory(p()).said(Speech::Keywords);
        assert_eq!(dir, "record: r.rrd is a directory, not a file");
    }

    #[test]
    fn a_plot_from_zero_reaches_a_labelled_step() {
        // A real-clock latency of 80 ms: 0–100, so "100" is labelled, not "0" alone.
        assert_eq!(label_top(80.0), 100.0);
        assert_eq!(label_top(0.8), 1.0);
        assert_eq!(label_top(2400.0), 2400.0);
        assert_eq!(label_top(60.0), 100.0);
        // A latency of 50 ms padded is six steps of 10, "0" alone at 1280x720: 0–100.
        assert_eq!(label_top(50.0), 100.0);
        // Steps of the power of ten already label it: kept.
        for hi in [300.0, 43.0, 44.0, 400.0, 1.0, 100.0, 4.0] {
            assert_eq!(label_top(hi), hi);
        }
        // Nothing to label: as is.
        assert_eq!(label_top(0.0), 0.0);
        assert!(label_top(f64::NAN).is_nan());
    }

    #[test]
    fn a_topic_keeps_its_colour_in_every_graph_and_equal_lines_stay_visible() {
        // The shipped graphs' topics have a colour each, whatever graph they are in.
        let shipped = ["/obs", "/action", "/meas", "/state", "/cmd", "/force"];
        let colours: std::collections::BTreeSet<[u8; 4]> =
            shipped.iter().map(|t| topic_color(t).to_array()).collect();
        assert_eq!(colours.len(), shipped.len());
        assert_eq!(topic_color("/reference"), topic_color("/reference"));
        assert!(PALETTE.contains(&{
            let [r, g, b, _] = topic_color("/reference").to_array();
            (r, g, b)
        }));
        // Drawn in entity-path order, each over the last: the first drawn is the widest.
        let w = layered_widths(&["obs".to_string(), "action".to_string(), "cmd".to_string()]);
        assert!(w[1] > w[2] && w[2] > w[0], "{w:?}");
        assert_eq!(layered_widths(&["obs".to_string()]), [2.0]);
    }

    #[test]
    fn views_list_every_topic_and_use_only_trailing_subtree_queries() {
        let s = shape(
            &[
                ("/obs", "sensor", &["policy"]),
                ("/action", "policy", &["actuator"]),
                ("/debug", "policy", &[]),
            ],
            &["sensor", "policy", "actuator"],
        );
        for clock in [ClockKind::Virtual, ClockKind::Real] {
            let cfg = RunConfig {
                clock,
                ..RunConfig::default()
            };
            let mut root = layout_for(&s, &cfg, None);
            // Every view's title reads whole at 1280×720, across processes too (the wire's).
            let cut = legend::cut_titles(&mut root);
            assert!(cut.is_empty(), "{clock:?}: cut titles {cut:?}");
            let mut placed = s.clone();
            for (n, p) in placed.nodes.iter_mut().zip(["robot", "policy", "robot"]) {
                n.process = Some(p.to_string());
            }
            let mut across = layout_for(&placed, &cfg, None);
            assert!(across
                .views()
                .iter()
                .any(|v| v.title_and_queries().0.starts_with("over the wire")));
            let cut = legend::cut_titles(&mut across);
            assert!(
                cut.is_empty(),
                "{clock:?}, across processes: cut titles {cut:?}"
            );
            let views = root.views();
            for v in &views {
                let (title, queries) = v.title_and_queries();
                assert!(!queries.is_empty(), "{title}");
                for q in queries {
                    let body = q.strip_suffix("/**").unwrap_or(q);
                    assert!(!body.contains('*'), "{title}: {q}");
                }
            }
            let dropped = views
                .iter()
                .map(|v| v.title_and_queries())
                .find(|(t, _)| t.contains("dropped"))
                .unwrap();
            assert_eq!(
                dropped.1,
                [
                    "/bus/obs/dropped",
                    "/bus/action/dropped",
                    "/bus/debug/dropped"
                ]
            );
            let lateness = views
                .iter()
                .map(|v| v.title_and_queries())
                .find(|(t, _)| t.contains("lateness"));
            assert_eq!(lateness.is_some(), clock == ClockKind::Real);
            // The middle column is always the chapter's four plots (the lateness has a
            // tab of its own): the cart's plot has room for the rails' ends under both
            // clocks, so they are never recorded unseen.
            let cart = views
                .iter()
                .map(|v| v.title_and_queries())
                .find(|(t, _)| t.starts_with("cart position"))
                .unwrap();
            let rails = cart.1.iter().filter(|q| q.contains("rail_end")).count();
            assert_eq!(rails, 2, "{:?}", cart.1);
            assert!(cart.1.iter().any(|q| q == "/plant/cart_limit/right"));
        }
    }

    #[test]
    fn qos_counters_get_a_view_only_where_qos_can_move_them() {
        let mut s = shape(
            &[
                ("/obs", "sensor", &["policy"]),
                ("/action", "policy", &["actuator"]),
            ],
            &["sensor", "policy", "actuator"],
        );
        let cfg = RunConfig::default();
        let qos_view = |s: &GraphShape, extents: Option<&Extents>| {
            layout_for(s, &cfg, extents)
                .views()
                .iter()
                .map(|v| v.title_and_queries())
                .find(|(t, _)| t.starts_with("QoS"))
                .map(|(_, q)| q.to_vec())
        };
        assert_eq!(qos_view(&s, None), None, "the chapter's QoS adds no view");
        let mut qos = ratelab_core::qos::TopicQos {
            deadline: Some(Nanos::from_millis(40)),
            ..Default::default()
        };
        qos.history = ratelab_core::qos::History::KeepAll;
        s.topics[1].qos = qos;
        s.nodes[1].liveliness = Some(Arc::new(ratelab_core::qos::Liveliness::new(Some(
            Nanos::from_millis(60),
        ))));
        s.nodes[2].liveliness = Some(Arc::new(ratelab_core::qos::Liveliness::new(None)));
        assert_eq!(
            qos_view(&s, None).unwrap(),
            [
                "/bus/action/refused",
                "/bus/action/offered_deadline_missed",
                "/bus/action/requested_deadline_missed",
            ]
        );
        // A leased node's not-alive count: a view (and a scale) of its own.
        let alive = layout_for(&s, &cfg, None)
            .views()
            .iter()
            .map(|v| v.title_and_queries())
            .find(|(t, _)| t.starts_with("liveliness"))
            .map(|(_, q)| q.to_vec());
        assert_eq!(alive.unwrap(), ["/nodes/policy/not_alive"]);
        // At the end: what was logged, whatever the QoS says now.
        let mut ext = Extents::new();
        widen(&mut ext, "bus/obs/lost", 3.0);
        widen(&mut ext, "bus/obs/published", 3.0);
        assert_eq!(qos_view(&s, Some(&ext)).unwrap(), ["/bus/obs/lost"]);
        assert_eq!(qos_view(&s, Some(&Extents::new())), None);
    }

    #[test]
    fn force_and_rail_scales_are_the_model_s() {
        let mjcf = include_str!("../runtime/assets/cartpole.xml");
        assert!(mjcf.contains(&format!("gear=\"{FORCE_PER_CONTROL_N}\"")));
        assert!(mjcf.contains(&format!(
            "range=\"-{RAIL_HALF_LENGTH_M} {RAIL_HALF_LENGTH_M}\""
        )));
    }

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
        // A lab session's name claims no rate: the learner changes them as it runs.
        let lab = default_lab_path(dir.path(), &cfg);
        assert_eq!(lab.file_name().unwrap(), "lab-virtual-seed0.rrd");
        std::fs::write(&lab, b"").unwrap();
        let lab2 = default_lab_path(dir.path(), &cfg);
        assert_eq!(lab2.file_name().unwrap(), "lab-virtual-seed0-2.rrd");
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
            Err(RecordingError::Unwritable {
                kind: std::io::ErrorKind::NotFound,
                ..
            })
        ));
    }
}
