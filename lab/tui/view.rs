//! The view model (an immutable snapshot the app builds each frame) and its rendering:
//! pure functions from a [`View`] to a buffer, one `render_*` helper per panel: the graph
//! panel in `view/graph.rs`, the plant and the figures in `view/charts.rs` (paused, their
//! titles read the run at the scrub cursor: `view/readout.rs`), the estimator's chart in
//! `view/estimator.rs`, the log pane and an entry of it opened in `view/log.rs`, the
//! status, footer and help here.

use super::keymap::{BINDINGS, HELP_NOTES};
use ratatui::buffer::Buffer;
use ratatui::layout::{Alignment, Constraint, Layout, Rect};
use ratatui::style::{Color, Modifier, Style, Stylize};
use ratatui::symbols::Marker;
use ratatui::text::{Line, Span};
use ratatui::widgets::canvas::{Canvas, Line as CanvasLine, Rectangle};
use ratatui::widgets::{
    Axis, Bar, BarChart, BarGroup, Block, Chart, Clear, Dataset, GraphType, Paragraph, Widget,
};
use ratelab::graph::{NodeId, TopicId};

mod axis;
mod charts;
mod estimator;
mod graph;
mod list;
mod log;
mod readout;

pub use self::log::{entry_rows, LogEntry, LogView, OpenEntry};
pub use estimator::EstimatorView;
pub use readout::{Readout, TopicCounts};

pub(super) use super::fit::first_that_fits;
use super::zoom::{window_start, Zoom};
use charts::{
    render_angle_chart, render_cartpole, render_hold_chart, render_latency, render_segment,
};
use graph::{graph_height, render_graph};
use list::{more_line, name_columns, render_list, render_names, render_nothing_shown};

/// The smallest terminal the lab lays out in.
pub const MIN_SIZE: (u16, u16) = (80, 24);
/// Fall limit shown on the drawings, rad (±12°).
pub const LIMIT_RAD: f64 = ratelab::plant::THETA_LIMIT_RAD;

/// What Tab selected: the target of the rate and depth keys.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Selected {
    /// A node.
    Node(NodeId),
    /// A topic.
    Topic(TopicId),
}

/// One node box.
#[derive(Clone, Debug, PartialEq, Default)]
pub struct NodeView {
    /// Name.
    pub name: String,
    /// Shown: the graph panel's filter lets it through ([`super::navigate::Filter`]).
    pub shown: bool,
    /// Column of the layout, left to right (publisher before subscriber).
    pub layer: usize,
    /// Selected with Tab?
    pub selected: bool,
    /// Rate as set, Hz (after the run ended: the rate it ran at).
    pub set_hz: f64,
    /// Its phase offset, ms: its ticks fall on `phase + k·period` (`--phase-offset-ms`, the
    /// key `P`).
    pub phase_ms: f64,
    /// After the run ended: the next run's rate, Hz, when a key changed it.
    pub next_hz: Option<f64>,
    /// Real clock: measured rate over the last second, Hz.
    pub measured_hz: Option<f64>,
    /// An external node (run by a ROS 2 program): the rate of what it publishes, msg/s
    /// over the arrows' window, shown instead of its proxy's ticks (`50.0 Hz sent`).
    pub published_hz: Option<f64>,
    /// Real clock: p99 tick lateness over recent ticks, µs.
    pub lateness_p99_us: Option<f64>,
    /// Real clock: the median wall time of its recent ticks, start to end, µs (what a
    /// Python callback, a brain or a compute time costs each tick).
    pub tick_p50_us: Option<f64>,
    /// Virtual clock with executors ([`ratelab::executor`]): the rate it achieved over the
    /// run, Hz, and the timer periods it skipped waiting for a thread.
    pub ran: Option<(f64, u64)>,
    /// Its compute time per tick (`30 ms`, `3±1 ms`), when it has one.
    pub compute: Option<String>,
    /// Liveliness with a lease: `Some(false)` when not heard from within it; `None`
    /// without a lease. Attached to a graph across processes: its liveliness token.
    pub alive: Option<bool>,
    /// An injected fault in force now (`--stall`, `--kill`): `STALLED` or `KILLED`. Its box
    /// says so until its lease (if it has one) says `NOT ALIVE`.
    pub fault: Option<&'static str>,
    /// Attached to a graph across processes: the process it runs in (the box's title
    /// reads `policy@policy`).
    pub process: Option<String>,
    /// What its box says under its rate about who runs it: `python` for a learner's node
    /// (`kind = "python"`), `ROS 2` for an external node (`kind = "external"`, run by a ROS 2
    /// program); `None` for the built-in kinds.
    pub badge: Option<Badge>,
    /// A call into the node's code (a Python tick, the brain's call, its script's loading)
    /// that has not returned for a while, and how long, s: its box says `in callback 3.2 s`
    /// (`loading 3.2 s`) instead of its timing.
    pub held: Option<(HeldIn, f64)>,
}

impl NodeView {
    /// In trouble: its liveliness lease ran out, a fault is injected into it, or a callback
    /// of it has not returned (the graph panel's `!` filter, and the list's alarm colour).
    pub fn in_trouble(&self) -> bool {
        self.alive == Some(false) || self.fault.is_some() || self.held.is_some()
    }
}

/// What of a node's code holds the run ([`NodeView::held`], [`Verdict::Hung`]).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum HeldIn {
    /// A tick's callback, or the brain's call.
    #[default]
    Callback,
    /// Its script's loading: the module's top level (a sleep or a loop at module level).
    Loading,
}

impl HeldIn {
    /// How a node's box and the list say it, before the time (`in callback`, `loading`).
    pub fn words(self) -> &'static str {
        match self {
            HeldIn::Callback => "in callback",
            HeldIn::Loading => "loading",
        }
    }

    /// What holds the run, as the verdict says it after `HUNG` (`in policy's callback`,
    /// `loading policy's script`).
    pub fn holding(self, node: &str) -> String {
        match self {
            HeldIn::Callback => format!("in {node}'s callback"),
            HeldIn::Loading => format!("loading {node}'s script"),
        }
    }
}

/// Who runs a node that ratelab's built-in kinds do not: [`NodeView::badge`].
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Badge {
    /// A Python node.
    Python,
    /// An external node, filled by a ROS 2 program.
    Ros2,
}

impl Badge {
    /// Under the rate, and (when the box has no room below) after the name in its title.
    fn words(self) -> (&'static str, &'static str) {
        match self {
            Badge::Python => ("python", "py"),
            Badge::Ros2 => ("ROS 2 node", "ros"),
        }
    }
}

/// One topic arrow.
#[derive(Clone, Debug, PartialEq, Default)]
pub struct TopicView {
    /// Its name (`/obs`).
    pub name: String,
    /// Shown: the graph panel's filter lets it through ([`super::navigate::Filter`]).
    pub shown: bool,
    /// The publishing node's index.
    pub publisher: usize,
    /// The subscribing node's index, if any (the first of several).
    pub subscriber: Option<usize>,
    /// With several subscribers, their names (each has a queue of its own; the arrow's
    /// drops and stale reads are their sums).
    pub fan_out: Option<String>,
    /// History depth now (after the run ended: the depth it ran with).
    pub depth: usize,
    /// After the run ended: the next run's depth, when a key changed it.
    pub next_depth: Option<usize>,
    /// Selected with Tab?
    pub selected: bool,
    /// Messages per second over the window (the last 5 s, never across a change): the
    /// count over the span of their publish stamps.
    pub msg_per_s: f64,
    /// Dropped within the window.
    pub dropped: u64,
    /// Any dropped within the window (the arrow is "dropping").
    pub dropping: bool,
    /// Not healthy though nothing was dropped: its publisher or its subscriber is not
    /// alive, its link lost messages, or its subscriber missed a deadline on it. Its drop
    /// count gets no ✓ (a green tick never stands on a dead, lossy or late topic).
    pub unhealthy: bool,
    /// Attached to a graph across processes, its counters come from a process that is not
    /// alive (its subscriber's): they stopped with it, so its msg/s is not known (`? msg/s`,
    /// not a 0.0 that says nothing was published).
    pub uncounted: bool,
    /// Its rate is not known: a healthy topic with fewer than two messages published in a
    /// window shorter than [`super::live::WINDOW`] (the run's start, or right after a
    /// change: a 3 Hz topic's first third of a second; or a run that ended that soon, as a
    /// 2 Hz policy's falls). Its arrow says `measuring`, as a node's box does, not a 0.0
    /// that says nothing was published.
    pub measuring: bool,
    /// Reads within the window that found nothing new (the mirror of a drop).
    pub stale_reads: u64,
    /// Any stale reads within the window (the subscriber is re-reading old data).
    pub staling: bool,
    /// Its QoS in short, in parts (`KA100 fifo`, `dl 40 ms`), when not the chapter's.
    pub qos: Option<Vec<String>>,
    /// The QoS counters it reports, over the window (as `dropped`), labelled for the edge
    /// (`lost`, `dl miss`, …).
    pub qos_counts: Vec<(&'static str, u64)>,
    /// Dropped since the last change of settings (or the run's start).
    pub segment_dropped: u64,
    /// Stale reads since the last change of settings (or the run's start).
    pub segment_stale_reads: u64,
    /// Messages its link lost since then (QoS counter `lost`), in the segment line when any.
    pub segment_lost: u64,
    /// Unread messages that outlived its lifespan since then (QoS counter `expired`), in the
    /// segment line when any.
    pub segment_expired: u64,
    /// Attached to a graph across processes, a topic that crosses them: its over-the-wire
    /// latency so far, (p50, p99) µs.
    pub wire_us: Option<(f64, f64)>,
    /// The subscribers its publisher does not connect, their requested QoS not offered:
    /// each subscriber's name with the policies that failed.
    pub incompatible: Vec<(String, Vec<ratelab::qos::compat::Mismatch>)>,
}

/// What the lab says of a rate not measured yet: a node's under the real clock before it
/// ticked twice, a topic's ([`TopicView::measuring`]).
pub const MEASURING: &str = "measuring";

impl TopicView {
    /// Its rate per second to `decimals` places (`50/s`, `50.0/s`), or [`MEASURING`] while it
    /// is not known.
    pub fn per_s(&self, decimals: usize) -> String {
        if self.measuring {
            MEASURING.to_string()
        } else {
            format!("{:.*}/s", decimals, self.msg_per_s)
        }
    }

    /// In trouble: it drops messages a subscriber misses or is read stale over the window,
    /// loses messages or misses deadlines (its ✗), or offers a QoS a subscriber cannot take
    /// (the graph panel's `!` filter, and the list's alarm colour).
    pub fn in_trouble(&self) -> bool {
        self.dropping || self.staling || self.unhealthy || !self.incompatible.is_empty()
    }
}

/// The window and the segment: what the live numbers count over.
#[derive(Clone, Debug, PartialEq, Default)]
pub struct SegmentView {
    /// 1 for the run's start, then one more per change of rate, depth or brain.
    pub index: u32,
    /// Run time the segment started, s.
    pub start_s: f64,
    /// The change that started it (`None`: the run's start).
    pub cause: Option<String>,
    /// The window's span, s: 5, or less right after the start or a change.
    pub window_s: f64,
    /// The window spans its whole 5 s.
    pub window_full: bool,
    /// The latency window's span, s: as `window_s`, but from the first step a lab attached
    /// mid-run saw.
    pub latency_window_s: f64,
    /// Run times of the changes over the last ~10 s, s (marks on the angle chart).
    pub marks_s: Vec<f64>,
    /// When the lab saw its first step well after the run's start (attached mid-run), its
    /// run time, s: the latency counts from there.
    pub joined_s: Option<f64>,
}

/// `last 5 s` for a whole window of `span_s`, else `last 2.3 s`.
fn last(span_s: f64, full: bool) -> String {
    if full {
        format!("last {} s", hz(span_s))
    } else {
        format!("last {span_s:.1} s")
    }
}

impl SegmentView {
    /// `last 5 s` or, while the window is shorter, `last 2.3 s`.
    pub fn window_label(&self) -> String {
        last(self.window_s, self.window_full)
    }

    /// The latency window's label: as [`SegmentView::window_label`], over
    /// [`SegmentView::latency_window_s`] (shorter only while the window is).
    pub fn latency_window_label(&self) -> String {
        last(self.latency_window_s, self.window_full)
    }

    /// `the start` or `12.30 s`.
    pub fn since(&self) -> String {
        match self.cause {
            None => "the start".to_string(),
            Some(_) => format!("{:.2} s", self.start_s),
        }
    }
}

/// The run's verdict badge.
#[derive(Clone, Debug, PartialEq)]
pub enum Verdict {
    /// Pole up so far.
    Balanced,
    /// The pole fell at this run time, s.
    Fell(f64),
    /// The run reached its duration with the pole up.
    Done,
    /// A node failed.
    Failed(String),
    /// A node's callback (a Python tick or brain call) has not returned for a while: under
    /// the virtual clock it holds the run's clock, so the pole is not "balanced" meanwhile.
    Hung {
        /// The node whose callback (or script's loading) it is.
        node: String,
        /// A callback, or its script's loading.
        held_in: HeldIn,
        /// The run time it has held since, s.
        since_s: f64,
    },
    /// The run could not start ([`ratelab::session::Telemetry::NotStarted`]): no run is
    /// going; the footer says why, until a save, `r` or `c` starts one.
    NotStarted,
    /// The run goes on with its actuator killed or stalled now: the plant stands still, the
    /// pole neither balanced nor fallen (`ACTUATOR KILLED at t=1.00s`, `ACTUATOR STALLED at
    /// t=1.00s`).
    Still(String),
    /// The run ended neither fallen nor balanced the whole run: the summary's headline
    /// ([`ratelab::metrics::Metrics::headline`], e.g. `STOPPED BY WATCHDOG at t=2.04s (…)`).
    Stopped(String),
}

/// Sense→act latency over the window, ms to the tenth rounded down (exact order statistics).
#[derive(Clone, Debug, PartialEq, Default)]
pub struct WindowLatency {
    /// Samples.
    pub count: u64,
    /// Steps that applied no command (a deadline's `zero`): no latency, said beside `count`.
    pub no_command: u64,
    /// p50, ms.
    pub p50_ms: f64,
    /// p99, ms.
    pub p99_ms: f64,
    /// max, ms.
    pub max_ms: f64,
}

/// Latency panel: the histogram and percentiles since the last change (exact order
/// statistics), and the window's percentiles.
#[derive(Clone, Debug, PartialEq, Default)]
pub struct LatencyView {
    /// (label, count) per bucket, since the last change: `<20` for [0, 20) ms, …, `≥200`.
    pub buckets: Vec<(String, u64)>,
    /// Samples since the last change.
    pub count: u64,
    /// Steps since the last change that applied no command (no latency: not in the bars).
    pub no_command: u64,
    /// p50, ms, to the tenth rounded down (as the bar it is counted in says).
    pub p50_ms: f64,
    /// p99, ms, to the tenth rounded down.
    pub p99_ms: f64,
    /// max, ms, to the tenth rounded down.
    pub max_ms: f64,
    /// The same over the window.
    pub window: WindowLatency,
    /// After a reload, the run before's count per bucket over the same span of run time
    /// (drawn dim beside each bar); empty without one.
    pub ghost: Vec<u64>,
}

/// Everything one frame shows.
#[derive(Clone, Debug, PartialEq)]
pub struct View {
    /// `virtual` / `real`.
    pub clock: String,
    /// Virtual pacing (`×1`, `max`), empty under the real clock.
    pub speed: String,
    /// Paused?
    pub paused: bool,
    /// Reviewing an ended real-clock run (space; ← → move through it)?
    pub review: bool,
    /// Run time, s.
    pub sim_time_s: f64,
    /// Seed.
    pub seed: u64,
    /// Brain label.
    pub brain: String,
    /// What the brain is, when its checkpoint is known (a caption; see
    /// `ratelab::checkpoint::caption`).
    pub brain_caption: Option<String>,
    /// Recording path, if recording.
    pub recording: Option<String>,
    /// The graph's nodes, in tie-break order.
    pub nodes: Vec<NodeView>,
    /// The graph's topics.
    pub topics: Vec<TopicView>,
    /// Pole angle, rad.
    pub pole_angle: f64,
    /// Cart position, m.
    pub cart_pos: f64,
    /// Badge.
    pub verdict: Verdict,
    /// The charts' window, run time s, `(from, to)` (`(` / `)` zoom it:
    /// [`super::chart_window`]).
    pub chart_s: (f64, f64),
    /// The window in words for the charts' titles (`last 10 s`, `whole run`).
    pub chart_label: String,
    /// (t s, θ rad) over the charts' window.
    pub angle_history: Vec<(f64, f64)>,
    /// With an estimator in the graph: (t s, θ̂ rad), the newest estimate at each actuator
    /// step, over the same window (drawn beside θ, the truth); empty without one.
    pub angle_estimate: Vec<(f64, f64)>,
    /// With an estimator in the graph: its chart (θ̇ and its estimate, the error and lag
    /// as the run's summary gives them), drawn in the pole-angle chart's place while the
    /// estimator is selected; `None` without one.
    pub estimator: Option<EstimatorView>,
    /// The force the actuator applied, N, as a staircase over the charts' window (each
    /// step's force held until the next: the zero-order hold).
    pub applied_force: Vec<(f64, f64)>,
    /// (t s, N) of each force the policy published over the charts' window (none over the
    /// whole run).
    pub published_force: Vec<(f64, f64)>,
    /// The run before a reload (a saved file): its (t s, θ rad) over the same window, drawn
    /// dim beside this run's; empty without one.
    pub ghost_angle: Vec<(f64, f64)>,
    /// The run before a reload: its applied force, N, as a staircase over the window.
    pub ghost_force: Vec<(f64, f64)>,
    /// Latency since the last change, and over the window.
    pub latency: LatencyView,
    /// Paused under the virtual clock, or reviewing: the run at the scrub cursor, read in
    /// the pole-angle chart's and the force band's titles (`None` otherwise, or before the
    /// actuator's first tick).
    pub readout: Option<Readout>,
    /// The executor timeline, shown in place of the latency histogram (key `t`).
    pub timeline: Option<super::timeline::TimelineView>,
    /// The log pane, shown in place of the latency histogram (key `v`).
    pub log: Option<LogView>,
    /// The run has ended and its reload line holds the footer (a run of code just saved that
    /// fell or failed): how it ended, for the status bar (`the pole fell — r/R reset · …`),
    /// so that both read whole at 80×24. `None` otherwise (the footer says how it ended).
    pub ended: Option<String>,
    /// The graph as ROS 2 sees it, shown in place of the node graph (key `g`, `--ros2`).
    pub ros2: Option<Ros2View>,
    /// The window and the segment the numbers count over.
    pub segment: SegmentView,
    /// Help overlay shown?
    pub help: bool,
    /// An exact rate being typed.
    pub typing: Option<String>,
    /// The latest notice (a command applied, an error).
    pub message: Option<String>,
    /// The notice is new: it leads the footer, so it is read even at 80 columns.
    pub message_fresh: bool,
    /// Watching a graph across processes: the header's note (`2 processes`).
    pub attached: Option<String>,
    /// Attached: where the launch listens (the header's note where it fits, and the
    /// footer's).
    pub endpoint: Option<String>,
    /// The graph panel's zoom, scroll and filter.
    pub nav: NavView,
}

/// What the graph panel shows of a large graph ([`super::navigate`]).
#[derive(Clone, Debug, PartialEq, Default)]
pub struct NavView {
    /// The zoom.
    pub zoom: super::zoom::Zoom,
    /// Rows scrolled down from the top.
    pub scroll: usize,
    /// The filter in a few words (`/sens · trouble`), when one leaves something out.
    pub filter: Option<String>,
    /// The filter's text as typed (the footer's prompt shows it while it is typed).
    pub text: String,
    /// A filter is being typed.
    pub typing: bool,
    /// Where the drawing says how far scrolling can go ([`super::navigate::Reach`]).
    pub reach: super::zoom::Reach,
}

/// The graph as ROS 2 sees it (`--ros2`): the domain and what `ros2 node list` and `ros2
/// topic info -v` would show ([`ratelab::ros2::offered`]).
#[derive(Clone, Debug, PartialEq)]
pub struct Ros2View {
    /// The ROS 2 domain.
    pub domain: u32,
    /// What is offered.
    pub offered: ratelab::ros2::offered::Offered,
}

fn hz(x: f64) -> String {
    let s = format!("{x:.2}");
    s.trim_end_matches('0').trim_end_matches('.').to_string()
}

impl Widget for &View {
    fn render(self, area: Rect, buf: &mut Buffer) {
        // The windows drawn below say how far scrolling can go (none: nowhere).
        self.nav.reach.clear();
        if area.width < MIN_SIZE.0 || area.height < MIN_SIZE.1 {
            render_too_small(area, buf);
            return;
        }
        // A notice that needs two rows takes the second from the latency panel while it leads.
        let foot_h = footer_rows(self, area.width);
        let hist_h: u16 = (if area.height >= 34 { 10 } else { 5 }) - (foot_h - 1);
        if self.nav.zoom == Zoom::List && self.ros2.is_none() {
            // The list takes the plant's rows too: a large graph's figures at 80×24.
            let [status, list, segment, latency, footer] = Layout::vertical([
                Constraint::Length(1),
                Constraint::Fill(1),
                Constraint::Length(1),
                Constraint::Length(hist_h),
                Constraint::Length(foot_h),
            ])
            .areas(area);
            render_status(self, status, buf);
            render_list(self, list, buf);
            render_segment(self, segment, buf);
            self.render_bottom(latency, buf);
            render_footer(self, footer, buf);
            self.render_overlays(area, buf);
            return;
        }
        let graph_h = graph_height(
            self,
            area.width,
            area.height,
            area.height.saturating_sub(hist_h + foot_h + 10),
        );
        let [status, graph, segment, middle, latency, footer] = Layout::vertical([
            Constraint::Length(1),
            Constraint::Length(graph_h),
            Constraint::Length(1),
            Constraint::Min(8),
            Constraint::Length(hist_h),
            Constraint::Length(foot_h),
        ])
        .areas(area);
        render_status(self, status, buf);
        match &self.ros2 {
            Some(r) => render_ros2(r, graph, buf),
            None => render_graph(self, graph, buf),
        }
        render_segment(self, segment, buf);
        let [cart, chart] =
            Layout::horizontal([Constraint::Percentage(40), Constraint::Percentage(60)])
                .areas(middle);
        render_cartpole(self, cart, buf);
        let (angle, hold, shared) = chart_areas(chart);
        // Tab to the estimator: its chart takes the pole angle's place.
        match self.estimator.as_ref().filter(|e| e.shown) {
            Some(e) => estimator::render_estimator_chart(self, e, angle, buf, shared),
            None => render_angle_chart(self, angle, buf, shared),
        }
        render_hold_chart(self, hold, buf, shared);
        self.render_bottom(latency, buf);
        render_footer(self, footer, buf);
        self.render_overlays(area, buf);
    }
}

/// The rows of the force band (the zero-order hold's chart) at least, borders included:
/// three rows of plot, one each for ≥ 10 N, 0 N and ≤ −10 N (two could only tell the force's
/// sign).
pub const HOLD_ROWS: u16 = 5;

/// The angle chart's and the force band's areas in `chart`, and whether they share a border:
/// 56 % and 44 % of it, unless that leaves the force band under [`HOLD_ROWS`] (80×24): then
/// it takes [`HOLD_ROWS`] and the angle chart the rest, drawn without its bottom border,
/// which the force band's top border (its title) serves for both.
fn chart_areas(chart: Rect) -> (Rect, Rect, bool) {
    let [angle, hold] =
        Layout::vertical([Constraint::Percentage(56), Constraint::Percentage(44)]).areas(chart);
    if hold.height >= HOLD_ROWS || chart.height < HOLD_ROWS + 3 {
        return (angle, hold, false);
    }
    let [angle, hold] =
        Layout::vertical([Constraint::Fill(1), Constraint::Length(HOLD_ROWS)]).areas(chart);
    (angle, hold, true)
}

impl View {
    /// What is drawn over the lab: a log entry opened (Enter), then the help (`?`).
    fn render_overlays(&self, area: Rect, buf: &mut Buffer) {
        if let Some(open) = self.log.as_ref().and_then(|l| l.open.as_ref()) {
            log::render_entry(open, area, buf);
        }
        if self.help {
            render_help(area, buf, self.attached.is_some());
        }
    }

    /// The bottom panel: the log pane, the executor timeline, or the latency histogram.
    fn render_bottom(&self, area: Rect, buf: &mut Buffer) {
        match (&self.log, &self.timeline) {
            (Some(l), _) => log::render_log(l, area, buf),
            (None, Some(t)) => super::timeline::render(t, self.clock == "virtual", area, buf),
            (None, None) => render_latency(self, area, buf),
        }
    }
}

/// The graph panel as ROS 2 sees the graph: its node names on one line, then a row per
/// topic (`/obs  sensor_msgs/msg/JointState  1 pub 1 sub  BEST_EFFORT · KEEP_LAST (1)`),
/// `/clock` last, then what every node offers besides (`/rosout`, …); a row too long for
/// the panel is cut with `…`.
fn render_ros2(r: &Ros2View, area: Rect, buf: &mut Buffer) {
    let block = Block::bordered().title(Line::from(format!(
        " as ROS 2 sees it · domain {} · g: back ",
        r.domain
    )));
    let inner = block.inner(area);
    block.render(area, buf);
    let width = usize::from(inner.width);
    let name_w = r
        .offered
        .topics
        .iter()
        .map(|t| t.name.chars().count())
        .max()
        .unwrap_or(0);
    let type_w = r
        .offered
        .topics
        .iter()
        .map(|t| t.ros_type.chars().count())
        .max()
        .unwrap_or(0);
    let mut lines = vec![Line::from(cut(
        &format!("nodes  {}", r.offered.nodes.join("  ")),
        width,
    ))];
    for t in &r.offered.topics {
        lines.push(Line::from(cut(
            &format!(
                "{:name_w$}  {:type_w$}  {} pub {} sub  {}",
                t.name, t.ros_type, t.publishers, t.subscriptions, t.qos
            ),
            width,
        )));
    }
    lines.push(Line::from(cut(&r.offered.every_node, width)).dim());
    Paragraph::new(lines).render(inner, buf);
}

fn render_too_small(area: Rect, buf: &mut Buffer) {
    let text = vec![
        Line::from("ratelab".bold()),
        Line::from(format!("resize to at least {}×{}", MIN_SIZE.0, MIN_SIZE.1)),
        Line::from(format!("(now {}×{})", area.width, area.height)),
    ];
    let h = 3.min(area.height);
    let y = area.y + area.height.saturating_sub(h) / 2;
    Paragraph::new(text).alignment(Alignment::Center).render(
        Rect {
            y,
            height: h,
            ..area
        },
        buf,
    );
}

/// The status bar of a run that ended while its reload line holds the footer
/// ([`View::ended`]): the clock and run time, then how it ended, made to fit.
fn render_ended_status(v: &View, ended: &str, area: Rect, buf: &mut Buffer) {
    let speed = if v.speed.is_empty() {
        String::new()
    } else {
        format!(" {}", v.speed)
    };
    let head = format!(" {} clock{speed} │ t {:.2} s │ ", v.clock, v.sim_time_s);
    let badge = " ratelab ";
    let room = usize::from(area.width).saturating_sub(badge.chars().count() + head.chars().count());
    let spans = vec![
        badge.black().on_cyan().bold(),
        head.into(),
        Span::from(fit_message(ended, room)).red().bold(),
    ];
    Paragraph::new(Line::from(spans)).render(area, buf);
}

fn render_status(v: &View, area: Rect, buf: &mut Buffer) {
    if let Some(ended) = &v.ended {
        return render_ended_status(v, ended, area, buf);
    }
    let mut spans = vec![
        " ratelab ".black().on_cyan().bold(),
        format!(" {} clock", v.clock).into(),
    ];
    let fixed = format!(
        " │ t {:.2} s │ seed {} │ {} │ ",
        v.sim_time_s,
        v.seed,
        depth_summary(&v.topics)
    );
    let recording = recording_room(v);
    if let Some(a) = &v.attached {
        // Where the launch listens, at once (it may not be 7449): whole where the line has
        // room beside the run's figures, else its port (at 80 columns; the brain's label
        // and "rec off" give way first, and the footer says it whole when no news is).
        let head: usize = spans.iter().map(|s| s.content.chars().count()).sum();
        let note = format!(" · {a}");
        let room = usize::from(area.width)
            .saturating_sub(head + note.chars().count() + fixed.chars().count() + recording);
        let at = v.endpoint.as_ref().and_then(|ep| {
            let port = ep.rsplit_once(':').map(|(_, p)| format!(" at :{p}"));
            std::iter::once(format!(" at {ep}"))
                .chain(port)
                .find(|at| at.chars().count() <= room)
        });
        spans.push(format!("{note}{}", at.unwrap_or_default()).bold());
    }
    if !v.speed.is_empty() {
        spans.push(format!(" {}", v.speed).into());
    }
    if v.review {
        spans.push(" REVIEW".yellow().bold());
    } else if v.paused {
        spans.push(" PAUSED".yellow().bold());
    }
    // The brain's label in what is left (cut at a word's end, or left out), so the line
    // never runs off the screen mid-word.
    let head: usize = spans.iter().map(|s| s.content.chars().count()).sum();
    let room = usize::from(area.width).saturating_sub(head + fixed.chars().count() + 3 + recording);
    let brain = if v.brain.chars().count() <= room {
        v.brain.clone()
    } else if room >= 8 {
        fit_message(&v.brain, room)
    } else {
        String::new()
    };
    spans.push(if brain.is_empty() {
        fixed.into()
    } else {
        format!("{fixed}{brain} │ ").into()
    });
    let used: usize = spans.iter().map(|s| s.content.chars().count()).sum();
    match &v.recording {
        Some(p) => spans.push(
            Span::from(format!(
                "rec ● {}",
                shorten_left(p, (area.width as usize).saturating_sub(used + 6))
            ))
            .red(),
        ),
        // Whole or not at all (at 80 columns "rec " alone read as a cut word).
        None if used + "rec off".len() <= area.width as usize => {
            spans.push(Span::from("rec off").dim());
        }
        None => {
            if let Some(last) = spans.pop() {
                let kept = last.content.trim_end_matches(" │ ").to_string();
                spans.push(Span::styled(kept, last.style));
            }
        }
    }
    Paragraph::new(Line::from(spans)).render(area, buf);
}

/// The header's room a recording keeps for its file's name (`rec ● …/run.rrd`): what the
/// brain's label and an attached lab's endpoint give way to. 0 without a recording.
fn recording_room(v: &View) -> usize {
    v.recording.as_deref().map_or(0, |p| {
        let name = std::path::Path::new(p)
            .file_name()
            .map_or(p.chars().count(), |n| n.to_string_lossy().chars().count());
        "rec ● …/".chars().count() + name
    })
}

/// `depth 1` when every topic has one depth, else each: `depths 1/5/1`; after the run
/// ended with a key changing one, the next run's too: `depth 1→2 next`.
fn depth_summary(topics: &[TopicView]) -> String {
    let ran = depths_of(topics.iter().map(|t| t.depth));
    if topics.iter().all(|t| t.next_depth.is_none()) {
        return ran;
    }
    let next = depths_of(topics.iter().map(|t| t.next_depth.unwrap_or(t.depth)));
    let next = next
        .trim_start_matches("depths ")
        .trim_start_matches("depth ");
    format!("{ran}→{next} next")
}

fn depths_of(depths: impl Iterator<Item = usize>) -> String {
    let depths: Vec<usize> = depths.collect();
    match depths.first() {
        Some(first) if depths.iter().all(|d| d == first) => format!("depth {first}"),
        Some(_) => format!(
            "depths {}",
            depths
                .iter()
                .map(|d| d.to_string())
                .collect::<Vec<_>>()
                .join("/")
        ),
        None => "no topics".to_string(),
    }
}

/// With a selection: what is selected and what the keys now do to it (in an attached lab,
/// which only watches, nothing: the selection only shows it).
/// The graph panel's title while a node or a topic is selected, in the first of its forms
/// that fits `room` columns: what is selected, what its keys change, how to move on.
fn selection_title(v: &View, room: usize) -> Option<String> {
    let fit = |forms: Vec<String>| first_that_fits(forms, room);
    if v.attached.is_some() {
        let name = v
            .nodes
            .iter()
            .find(|n| n.selected)
            .map(|n| n.name.clone())
            .or_else(|| v.topics.iter().find(|t| t.selected).map(|t| t.name.clone()))?;
        return Some(fit(vec![
            format!(" {name} selected (read-only) · Tab next · Esc clears "),
            format!(" {name} selected (read-only) · Esc clears "),
        ]));
    }
    if let Some(n) = v.nodes.iter().find(|n| n.selected) {
        let name = &n.name;
        return Some(fit(vec![
            format!(
                " {name} selected: -/+ its rate · P its phase ({} ms) · Tab next · Esc clears ",
                hz(n.phase_ms)
            ),
            format!(" {name} selected: -/+ its rate · Tab next · Esc clears "),
            format!(" {name} selected: -/+ its rate · Esc clears "),
            format!(" {name}: -/+ rate · Esc "),
        ]));
    }
    // With QoS set, the selection names it first: at 80×24 the arrow has no row left for it.
    v.topics.iter().find(|t| t.selected).map(|t| {
        let (name, depth) = (&t.name, t.depth);
        fit(match &t.qos {
            Some(parts) => {
                let qos = parts.join(" ");
                vec![
                    format!(" {name} selected: {qos} · [/] depth · f d L l e o QoS · Esc clears "),
                    format!(" {name}: {qos} · [/] depth · f d L l e o QoS · Esc "),
                    format!(" {name}: {qos} · Esc "),
                ]
            }
            None => vec![
                format!(" {name} selected: [/] its depth ({depth}) · f/d/L/l/e/o its QoS · Tab next · Esc clears "),
                format!(" {name} selected: [/] its depth ({depth}) · f/d/L/l/e/o its QoS · Esc clears "),
                format!(" {name}: [/] depth ({depth}) · f d L l e o QoS · Esc "),
            ],
        })
    })
}

/// `s` cut from the left to at most `max` characters (`…ings/run.rrd`), so the end of a
/// path, its file name, stays readable.
pub fn shorten_left(s: &str, max: usize) -> String {
    let n = s.chars().count();
    if n <= max {
        return s.to_string();
    }
    let keep = max.saturating_sub(1);
    let tail: String = s.chars().skip(n - keep).collect();
    format!("…{tail}")
}

fn badge(v: &View) -> Span<'static> {
    match &v.verdict {
        Verdict::Balanced => " BALANCED ✓ ".black().on_green().bold(),
        Verdict::Done => " BALANCED ✓ (run complete) ".black().on_green().bold(),
        Verdict::Fell(t) => Span::from(format!(" FELL at t={t:.2}s ✗ "))
            .white()
            .on_red()
            .bold(),
        Verdict::Failed(_) => " NODE FAILED ✗ ".white().on_red().bold(),
        Verdict::NotStarted => " NOT STARTED ✗ ".white().on_red().bold(),
        Verdict::Hung {
            node,
            since_s,
            held_in,
        } => Span::from(format!(
            " HUNG {} since t={since_s:.2}s ✗ ",
            held_in.holding(node)
        ))
        .white()
        .on_red()
        .bold(),
        Verdict::Still(what) => Span::from(format!(" {what} ")).black().on_yellow().bold(),
        // The headline up to its parenthesis: "STOPPED BY WATCHDOG at t=2.04s".
        Verdict::Stopped(headline) => Span::from(format!(
            " {} ",
            headline.split(" (").next().unwrap_or(headline)
        ))
        .black()
        .on_yellow()
        .bold(),
    }
}

/// `text` cut to `w` characters (the last one `…` when cut).
pub(super) fn cut(text: &str, w: usize) -> String {
    if text.chars().count() <= w {
        return text.to_string();
    }
    let mut t: String = text.chars().take(w.saturating_sub(1)).collect();
    t.push('…');
    t
}

/// A status message made to fit `width` columns: whole when it fits; else its parts
/// (separated by ` · `) from the middle out, keeping the first (what changed) and the last
/// (the verdict: `a fresh run falls at 4.06 s: judge no sooner`); else cut with `…`, at a
/// word's end where one is near.
fn fit_message(m: &str, width: usize) -> String {
    let len = |s: &str| s.chars().count();
    if len(m) <= width {
        return m.to_string();
    }
    // Too long: what changed and the verdict (the first and last parts) stay, and the
    // middle parts go from the first (a phase note's offset from a fresh run before where
    // its ticks fall against the sensor's).
    let parts: Vec<&str> = m.split(" · ").collect();
    if parts.len() >= 3 {
        let (first, last) = (parts[0], parts[parts.len() - 1]);
        for drop in 1..parts.len() - 1 {
            let kept: Vec<&str> = std::iter::once(first)
                .chain(parts[1 + drop..parts.len() - 1].iter().copied())
                .chain(std::iter::once(last))
                .collect();
            let short = kept.join(" · ");
            if len(&short) <= width {
                return short;
            }
        }
    }
    // Cut at a word's end where one is near, so no word is left half.
    let cut: String = m.chars().take(width.saturating_sub(1)).collect();
    let cut = match cut.rfind(' ') {
        Some(i) if cut[i..].chars().count() <= 16 && i > 0 => {
            cut[..i].trim_end_matches([' ', '·']).to_string()
        }
        _ => cut,
    };
    format!("{cut}…")
}

/// A notice made to fit `rows` rows of `width` columns: whole where it fits; else its parts
/// (separated by ` · `) packed into the rows, the middle ones dropped from the first as
/// [`fit_message`] drops them until the rest fit (a row the next goes on from ends in ` ·`);
/// else its words wrapped, the last row cut as [`fit_message`] cuts. In one row it is
/// [`fit_message`]'s.
fn fit_rows(m: &str, width: usize, rows: usize) -> Vec<String> {
    if rows <= 1 || m.chars().count() <= width {
        return vec![fit_message(m, width)];
    }
    let parts: Vec<&str> = m.split(" · ").collect();
    let n = parts.len();
    for drop in 0..=n.saturating_sub(2) {
        let kept: Vec<&str> = if drop == 0 {
            parts.clone()
        } else {
            std::iter::once(parts[0])
                .chain(parts[1 + drop..n - 1].iter().copied())
                .chain(std::iter::once(parts[n - 1]))
                .collect()
        };
        if let Some(packed) = pack_parts(&kept, width, rows) {
            return packed;
        }
    }
    wrap_words(m, width, rows)
}

/// `parts` in at most `rows` rows of `width` columns, as many whole parts a row as fit,
/// joined by ` · ` (a row the next goes on from ends in ` ·` where it has room); `None` when
/// they do not fit.
fn pack_parts(parts: &[&str], width: usize, rows: usize) -> Option<Vec<String>> {
    let len = |s: &str| s.chars().count();
    let mut out: Vec<String> = Vec::new();
    let mut row = String::new();
    for part in parts {
        if len(part) > width {
            return None;
        }
        if row.is_empty() {
            row.push_str(part);
        } else if len(&row) + 3 + len(part) <= width {
            row.push_str(" · ");
            row.push_str(part);
        } else {
            if len(&row) + 2 <= width {
                row.push_str(" ·");
            }
            out.push(std::mem::take(&mut row));
            row.push_str(part);
        }
    }
    out.push(row);
    (out.len() <= rows).then_some(out)
}

/// `m` wrapped at its spaces into at most `rows` rows of `width` columns (a word longer
/// than a row is cut where the row ends), the last row cut as [`fit_message`] cuts.
fn wrap_words(m: &str, width: usize, rows: usize) -> Vec<String> {
    let mut out = Vec::new();
    let mut rest = m.trim();
    while out.len() + 1 < rows && rest.chars().count() > width {
        // The row's end: at a space within it (or right after it), else at its width.
        let end = rest
            .char_indices()
            .nth(width)
            .map_or(rest.len(), |(i, _)| i);
        let at = if rest[end..].starts_with(' ') {
            Some(end)
        } else {
            rest[..end].rfind(' ').filter(|&i| i > 0)
        };
        let (row, next) = rest.split_at(at.unwrap_or(end));
        out.push(row.trim_end().to_string());
        rest = next.trim_start();
    }
    out.push(fit_message(rest, width));
    out
}

/// The notice that leads the footer, if one does, with its prefix's width: after a run's end
/// its last word (` `), else a fresh notice (` ● `); none while something is typed.
fn leading_notice(v: &View) -> Option<(&str, usize)> {
    if v.typing.is_some() || v.nav.typing {
        return None;
    }
    let m = v.message.as_deref()?;
    // A hung callback is no end: the run goes on once it returns.
    let ended = !matches!(
        v.verdict,
        Verdict::Balanced | Verdict::Hung { .. } | Verdict::Still(_)
    );
    if ended {
        Some((m, 1))
    } else if v.message_fresh {
        Some((m, 3))
    } else {
        None
    }
}

/// The footer's rows at `width` columns: two while the notice that leads it does not fit in
/// one (at 80 columns a live rate change's notice: what changed, where the node's ticks now
/// fall against the sensor's, and a fresh run's verdict), else one.
pub(super) fn footer_rows(v: &View, width: u16) -> u16 {
    match leading_notice(v) {
        Some((m, prefix)) if m.chars().count() + prefix > usize::from(width) => 2,
        _ => 1,
    }
}

fn render_footer(v: &View, area: Rect, buf: &mut Buffer) {
    let width = usize::from(area.width);
    // Typing a rate shows its prompt even after a fall, where the verdict leads otherwise.
    let lines: Vec<Line> = if let Some(t) = &v.typing {
        vec![Line::from(vec![
            " rate (Hz): ".bold(),
            format!("{t}▏").into(),
            "  Enter apply · Esc cancel".dim(),
        ])]
    } else if v.nav.typing {
        vec![Line::from(vec![
            " filter: ".bold(),
            format!("{}▏", v.nav.text).into(),
            "  name, @process · Enter keep · Esc as before".dim(),
        ])]
    } else if let Some((m, prefix)) = leading_notice(v) {
        // In as many rows as the footer has (two when it does not fit one: footer_rows).
        let rows = fit_rows(m, width.saturating_sub(prefix), usize::from(area.height));
        let last = rows.len().saturating_sub(1);
        rows.into_iter()
            .enumerate()
            .map(|(i, row)| match (prefix, i) {
                (1, _) => Line::from(Span::from(format!(" {row}")).bold()),
                _ => {
                    let lead = if i == 0 { " ● " } else { "   " };
                    let keys = (i == last && row.chars().count() + 3 + 10 <= width)
                        .then(|| "  (? keys)".dim());
                    Line::from(
                        std::iter::once(Span::from(format!("{lead}{row}")).bold())
                            .chain(keys)
                            .collect::<Vec<_>>(),
                    )
                }
            })
            .collect()
    } else {
        // Attached to a graph across processes, only the keys that change the view act.
        let mut spans: Vec<Span> = match v.attached {
            Some(_) => match &v.endpoint {
                Some(ep) => vec![format!(" read-only · {ep} │ ").dim()],
                None => vec![" read-only │ ".dim()],
            },
            None => vec![" ".into()],
        };
        // Under the real clock time does not stop: space only reviews a run that ended
        // (the help says so), so the footer does not offer a pause.
        let shown = BINDINGS
            .iter()
            .filter(|b| v.attached.is_none() || b.only_views())
            .filter(|b| v.clock != "real" || !b.pauses());
        for b in shown {
            let Some((keys, word)) = b.footer else {
                continue;
            };
            // Paused, space resumes.
            let word = if b.pauses() && v.paused {
                "resume"
            } else {
                word
            };
            spans.push(format!("{keys} ").bold());
            spans.push(format!("{word} ").into());
        }
        // The last message after the keys, made to fit what is left (its verdict kept),
        // or left out where too little is (never a cut word or a bare `│`).
        let used: usize = spans.iter().map(|s| s.content.chars().count()).sum();
        let left = width.saturating_sub(used + 4);
        if let (Some(m), true) = (&v.message, left >= 12) {
            spans.push(Span::from(format!("  │ {}", fit_message(m, left))).italic());
        }
        vec![Line::from(spans)]
    };
    Paragraph::new(lines).render(area, buf);
}

/// The widest label of the key help's left column, characters ([`help_row`]).
pub(crate) const HELP_LABEL_CHARS: usize = 16;

/// One row of the key help: a margin, `label` bold and right-aligned in a column of
/// [`HELP_LABEL_CHARS`], two spaces, `text`; whole at 80 columns (a test holds every row to
/// the box's 78 inner columns: the widest, the rate ladder, reaches its right edge).
fn help_row<'a>(label: &str, text: &'a str) -> Line<'a> {
    Line::from(vec![
        format!(" {label:>w$}  ", w = HELP_LABEL_CHARS).bold(),
        text.into(),
    ])
}

/// The key help over the lab; `attached`: only the keys that act in a lab that watches a
/// graph across processes (the others would be refused).
fn render_help(area: Rect, buf: &mut Buffer, attached: bool) {
    let mut lines: Vec<Line> = BINDINGS
        .iter()
        .filter(|b| !attached || b.only_views())
        .map(|b| help_row(b.label, b.help))
        .collect();
    let notes: Vec<Line> = HELP_NOTES
        .iter()
        // Attached, the ladders, the fall's keys and reliable delivery's losses do not apply;
        // the wire's note does, and only there.
        .filter(|(k, _)| attached == k.starts_with("wire"))
        .map(|(k, d)| help_row(k, d))
        .collect();
    // A blank line between keys and notes where it fits with the footer's row left free
    // (at 80×24 every line is needed).
    if lines.len() + notes.len() + 4 <= usize::from(area.height) {
        lines.push(Line::from(""));
    }
    lines.extend(notes);
    let w = 90.min(area.width);
    let h = (lines.len() as u16 + 2).min(area.height);
    let popup = Rect {
        x: area.x + (area.width - w) / 2,
        y: area.y + (area.height - h) / 2,
        width: w,
        height: h,
    };
    Clear.render(popup, buf);
    let title = if attached {
        " keys: this lab only watches (? or Esc to close) "
    } else {
        " keys (? or Esc to close) "
    };
    Paragraph::new(lines)
        .block(Block::bordered().title(title))
        .render(popup, buf);
}

#[cfg(test)]
mod tests {
    use super::{chart_areas, fit_message, fit_rows, HOLD_ROWS};
    use ratatui::layout::Rect;

    /// In two rows a live rate change's notice keeps where the node's ticks now fall against
    /// the sensor's beside the fresh run's verdict at 80 columns (one row dropped it, #72),
    /// and reads whole at 120.
    #[test]
    fn a_long_notice_in_two_rows_keeps_the_phase_against_the_sensor() {
        let m = "control rate → 7 Hz · 142.857 ms off a fresh run's phase · ticks 2.857 ms after the sensor's (r realigns) · a fresh run falls at 4.06 s: judge no sooner";
        assert_eq!(
            fit_rows(m, 77, 2),
            [
                "control rate → 7 Hz · ticks 2.857 ms after the sensor's (r realigns) ·",
                "a fresh run falls at 4.06 s: judge no sooner",
            ]
        );
        assert_eq!(
            fit_rows(m, 117, 2),
            [
                "control rate → 7 Hz · 142.857 ms off a fresh run's phase · ticks 2.857 ms after the sensor's (r realigns) ·",
                "a fresh run falls at 4.06 s: judge no sooner",
            ]
        );
        // One row is fit_message's; a short notice keeps one row.
        assert_eq!(fit_rows(m, 77, 1), [fit_message(m, 77)]);
        assert_eq!(fit_rows("short", 77, 2), ["short"]);
        // One long part: its words wrapped, the last row cut at a word's end.
        let long = "policy: my_balancer.py:41: ValueError: the gain must be positive and below the limit the plant can take without tipping over";
        assert_eq!(
            fit_rows(long, 40, 2),
            [
                "policy: my_balancer.py:41: ValueError:",
                "the gain must be positive and below…"
            ]
        );
        // A word longer than a row is cut where the row ends.
        let word = "x".repeat(50);
        assert_eq!(fit_rows(&word, 40, 2)[0], "x".repeat(40));
    }

    /// At 80×24 the charts' column has 9 rows: the force band takes [`HOLD_ROWS`] (three rows
    /// of plot: ≥ 10, 0 and ≤ −10 N, not only the force's sign), the angle chart the other 4
    /// (three rows of plot, its bottom border the band's top one). Taller, 56 % and 44 %.
    #[test]
    fn at_80x24_the_force_band_has_three_rows_of_plot() {
        let at = |height| Rect::new(32, 10, 48, height);
        let (angle, hold, shared) = chart_areas(at(9));
        assert!(shared);
        assert_eq!((angle.y, angle.height), (10, 4));
        assert_eq!((hold.y, hold.height), (14, HOLD_ROWS));
        let (angle, hold, shared) = chart_areas(at(21));
        assert!(!shared);
        assert!(hold.height >= HOLD_ROWS && angle.height > hold.height);
    }

    #[test]
    fn a_long_status_keeps_what_changed_and_the_verdict() {
        let m = "control rate → 7 Hz · 142.857 ms off a fresh run's phase · ticks 2.857 ms after the sensor's (r realigns) · a fresh run falls at 4.06 s: judge no sooner";
        assert_eq!(fit_message(m, 200), m);
        // 120 columns: where the ticks fall against the sensor's stays.
        assert_eq!(
            fit_message(m, 117),
            "control rate → 7 Hz · ticks 2.857 ms after the sensor's (r realigns) · a fresh run falls at 4.06 s: judge no sooner"
        );
        assert_eq!(
            fit_message(m, 77),
            "control rate → 7 Hz · a fresh run falls at 4.06 s: judge no sooner"
        );
        // Cut at a word's end, never mid-word ("142.857" would have been "142.85").
        assert_eq!(fit_message(m, 30), "control rate → 7 Hz…");
        assert_eq!(fit_message("short", 3), "sh…");
    }
}
