//! The view model (an immutable snapshot the app builds each frame) and its rendering:
//! pure functions from a [`View`] to a buffer, one `render_*` helper per panel.

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
#[derive(Clone, Debug, PartialEq)]
pub struct NodeView {
    /// Name.
    pub name: String,
    /// Column of the layout, left to right (publisher before subscriber).
    pub layer: usize,
    /// Selected with Tab?
    pub selected: bool,
    /// Rate as set, Hz (after the run ended: the rate it ran at).
    pub set_hz: f64,
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
    /// A callback of the node (a Python tick, the brain's call) that has not returned for
    /// this long, s: its box says `in callback 3.2 s` instead of its timing.
    pub in_callback_s: Option<f64>,
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
#[derive(Clone, Debug, PartialEq)]
pub struct TopicView {
    /// Its name (`/obs`).
    pub name: String,
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
    /// Attached to a graph across processes, a topic that crosses them: its over-the-wire
    /// latency so far, (p50, p99) µs.
    pub wire_us: Option<(f64, f64)>,
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
        /// The node whose callback it is.
        node: String,
        /// The run time it has held since, s.
        since_s: f64,
    },
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
    /// (t s, θ rad) over the last ~10 s.
    pub angle_history: Vec<(f64, f64)>,
    /// The force the actuator applied, N, as a staircase over the last ~10 s (each step's
    /// force held until the next: the zero-order hold).
    pub applied_force: Vec<(f64, f64)>,
    /// (t s, N) of each force the policy published over the last ~10 s.
    pub published_force: Vec<(f64, f64)>,
    /// Latency since the last change, and over the window.
    pub latency: LatencyView,
    /// The executor timeline, shown in place of the latency histogram (key `t`).
    pub timeline: Option<super::timeline::TimelineView>,
    /// The log pane, shown in place of the latency histogram (key `v`).
    pub log: Option<LogView>,
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
}

/// The log pane: what nodes' code wrote and ratelab's warnings, newest last.
#[derive(Clone, Debug, PartialEq, Default)]
pub struct LogView {
    /// Whose lines: `all nodes`, or the selected node's name.
    pub whose: String,
    /// How many lines the lab holds of it in all.
    pub total: usize,
    /// The newest lines: (is it a warning or an error, `t=1.23 policy  text`).
    pub lines: Vec<(bool, String)>,
    /// Scrolled back this many lines from the newest (PgUp / PgDn).
    pub back: usize,
}

fn render_log(l: &LogView, area: Rect, buf: &mut Buffer) {
    let title = if l.back > 0 {
        format!(
            " log: {} ({} lines, {} back) · PgDn newer · v hides ",
            l.whose, l.total, l.back
        )
    } else {
        format!(" log: {} ({} lines) · v hides ", l.whose, l.total)
    };
    let block = Block::bordered().title(title);
    let inner = block.inner(area);
    block.render(area, buf);
    let rows = usize::from(inner.height);
    let width = usize::from(inner.width);
    let shown: Vec<Line> = if l.lines.is_empty() {
        vec![Line::from("nothing written yet (print, get_logger, warnings)").dim()]
    } else {
        let end = l.lines.len().saturating_sub(l.back);
        l.lines[end.saturating_sub(rows)..end]
            .iter()
            .map(|(warn, text)| {
                let cut: String = text.chars().take(width).collect();
                if *warn {
                    Line::from(cut).yellow()
                } else {
                    Line::from(cut)
                }
            })
            .collect()
    };
    ratatui::widgets::Paragraph::new(shown).render(inner, buf);
}

fn hz(x: f64) -> String {
    let s = format!("{x:.2}");
    s.trim_end_matches('0').trim_end_matches('.').to_string()
}

impl Widget for &View {
    fn render(self, area: Rect, buf: &mut Buffer) {
        if area.width < MIN_SIZE.0 || area.height < MIN_SIZE.1 {
            render_too_small(area, buf);
            return;
        }
        let hist_h = if area.height >= 34 { 10 } else { 5 };
        let graph_h = graph_height(
            self,
            area.width,
            area.height,
            area.height.saturating_sub(hist_h + 11),
        );
        let [status, graph, segment, middle, latency, footer] = Layout::vertical([
            Constraint::Length(1),
            Constraint::Length(graph_h),
            Constraint::Length(1),
            Constraint::Min(8),
            Constraint::Length(hist_h),
            Constraint::Length(1),
        ])
        .areas(area);
        render_status(self, status, buf);
        render_graph(self, graph, buf);
        render_segment(self, segment, buf);
        let [cart, chart] =
            Layout::horizontal([Constraint::Percentage(40), Constraint::Percentage(60)])
                .areas(middle);
        render_cartpole(self, cart, buf);
        let [angle, hold] =
            Layout::vertical([Constraint::Percentage(56), Constraint::Percentage(44)]).areas(chart);
        render_angle_chart(self, angle, buf);
        render_hold_chart(self, hold, buf);
        match (&self.log, &self.timeline) {
            (Some(l), _) => render_log(l, latency, buf),
            (None, Some(t)) => super::timeline::render(t, self.clock == "virtual", latency, buf),
            (None, None) => render_latency(self, latency, buf),
        }
        render_footer(self, footer, buf);
        if self.help {
            render_help(area, buf, self.attached.is_some());
        }
    }
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

fn render_status(v: &View, area: Rect, buf: &mut Buffer) {
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
    if v.paused {
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
fn selection_title(v: &View) -> Option<String> {
    if v.attached.is_some() {
        let name = v
            .nodes
            .iter()
            .find(|n| n.selected)
            .map(|n| n.name.clone())
            .or_else(|| v.topics.iter().find(|t| t.selected).map(|t| t.name.clone()))?;
        return Some(format!(
            " {name} selected (read-only) · Tab next · Esc clears "
        ));
    }
    if let Some(n) = v.nodes.iter().find(|n| n.selected) {
        return Some(format!(
            " {} selected: -/+ its rate · Tab next · Esc clears ",
            n.name
        ));
    }
    // With QoS set, the selection names it first: at 80×24 the arrow has no row left for it.
    v.topics.iter().find(|t| t.selected).map(|t| match &t.qos {
        Some(parts) => format!(
            " {} selected: {} · [/] depth · f d L l e o QoS · Esc clears ",
            t.name,
            parts.join(" ")
        ),
        None => format!(
            " {} selected: [/] its depth ({}) · f/d/L/l/e/o its QoS · Tab next · Esc clears ",
            t.name, t.depth
        ),
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

/// The graph panel's title: the nodes and topics in layout order.
fn graph_title(v: &View) -> String {
    // Columns joined by arrows; what shares a column, by commas.
    let names: Vec<String> = layout_columns(v)
        .iter()
        .map(|c| match c {
            Column::Nodes(ns) => ns
                .iter()
                .map(|&i| v.nodes[i].name.as_str())
                .collect::<Vec<_>>()
                .join(", "),
            Column::Topics(ts) => ts
                .iter()
                .map(|&i| v.topics[i].name.as_str())
                .collect::<Vec<_>>()
                .join(", "),
        })
        .collect();
    format!(" graph: {} ", names.join(" → "))
}

/// A column of the graph panel: the nodes of one layer, or the topics they publish.
enum Column {
    Nodes(Vec<usize>),
    Topics(Vec<usize>),
}

/// Left to right: each layer's nodes, then the topics they publish.
fn layout_columns(v: &View) -> Vec<Column> {
    let layers = v.nodes.iter().map(|n| n.layer).max().map_or(0, |l| l + 1);
    let mut cols = Vec::new();
    for l in 0..layers {
        let nodes: Vec<usize> = (0..v.nodes.len())
            .filter(|&i| v.nodes[i].layer == l)
            .collect();
        if nodes.is_empty() {
            continue;
        }
        let topics: Vec<usize> = (0..v.topics.len())
            .filter(|&t| nodes.contains(&v.topics[t].publisher))
            .collect();
        cols.push(Column::Nodes(nodes));
        if !topics.is_empty() {
            cols.push(Column::Topics(topics));
        }
    }
    cols
}

fn render_graph(v: &View, area: Rect, buf: &mut Buffer) {
    let mut block = match selection_title(v) {
        Some(t) => Block::bordered().title(Line::from(t).black().on_yellow().bold()),
        None => Block::bordered().title(graph_title(v)),
    };
    // What the brain is, when known: a fall with no drops is then no mystery.
    if let Some(caption) = &v.brain_caption {
        block = block.title_bottom(Line::from(format!(" brain: {caption} ")).dim());
    }
    let inner = block.inner(area);
    block.render(area, buf);
    let cols = layout_columns(v);
    let n = cols.len().max(1) as u32;
    let areas = Layout::horizontal((0..n).map(|_| Constraint::Ratio(1, n))).split(inner);
    for (col, rect) in cols.iter().zip(areas.iter()) {
        let count = match col {
            Column::Nodes(x) | Column::Topics(x) => x.len().max(1) as u32,
        };
        // Node boxes each as tall as they need when the column has room for all of them
        // (the last takes the rest); else, and for arrows, evenly.
        let needs: Vec<u16> = match col {
            Column::Nodes(ns) => ns
                .iter()
                .map(|&i| node_rows(&v.nodes[i]) as u16 + 2)
                .collect(),
            Column::Topics(_) => Vec::new(),
        };
        let cells = if !needs.is_empty() && needs.iter().sum::<u16>() <= rect.height {
            let last = needs.len() - 1;
            Layout::vertical(needs.iter().enumerate().map(|(k, &h)| {
                if k == last {
                    Constraint::Fill(1)
                } else {
                    Constraint::Length(h)
                }
            }))
            .split(*rect)
        } else {
            Layout::vertical((0..count).map(|_| Constraint::Ratio(1, count))).split(*rect)
        };
        match col {
            Column::Nodes(ns) => {
                for (&i, cell) in ns.iter().zip(cells.iter()) {
                    render_node(&v.nodes[i], *cell, buf, v.clock == "real");
                }
            }
            Column::Topics(ts) => {
                for (&i, cell) in ts.iter().zip(cells.iter()) {
                    render_arrow(&v.topics[i], *cell, buf);
                }
            }
        }
    }
}

/// A node's box; `real`: under the real clock (a node with no measured rate yet, as one
/// just started again, is being measured, not on virtual time).
fn render_node(n: &NodeView, area: Rect, buf: &mut Buffer, real: bool) {
    let wide = area.width >= 14;
    // Each figure in the first of its forms that fits the box whole (at 80 columns a box is
    // 9 wide: `200 meas`, `p99 3.5ms`, never `200.0 mea` or `p99 3506 `).
    let room = usize::from(area.width.saturating_sub(2));
    let fit = |forms: Vec<String>| first_that_fits(forms, room);
    let set = match (n.next_hz, wide) {
        // After the run ended, the rate it ran at beside the next run's.
        (Some(next), _) => {
            let (ran, next) = (hz(n.set_hz), hz(next));
            fit(vec![
                format!("{ran}→{next} Hz next"),
                format!("{ran}→{next} Hz"),
                format!("{ran}→{next}"),
                format!("→{next} Hz"),
            ])
        }
        (None, true) => format!("{} Hz set", hz(n.set_hz)),
        (None, false) => format!("{} Hz", hz(n.set_hz)),
    };
    let mut lines = vec![Line::from(set)];
    if let Some(s) = n.in_callback_s {
        lines.push(
            Line::from(fit(vec![
                format!("in callback {s:.1} s"),
                format!("in callback {s:.0}s"),
                format!("in cb {s:.1}s"),
                format!("cb {s:.0}s"),
            ]))
            .red()
            .bold(),
        );
    }
    match (n.published_hz, n.measured_hz, n.lateness_p99_us) {
        _ if n.in_callback_s.is_some() => {}
        (Some(p), ..) => lines.push(Line::from(fit(vec![
            format!("{p:.1} Hz sent"),
            format!("{p:.0} Hz sent"),
            format!("{p:.0} sent"),
        ]))),
        (None, Some(m), Some(l)) => {
            let mut meas = vec![format!("{m:.1} meas"), format!("{m:.0} meas")];
            if wide {
                meas.insert(0, format!("{m:.1} Hz meas"));
            }
            lines.push(Line::from(fit(meas)));
            // What the figure is ("late") goes only after the spaces and digits that can
            // go (past 999 µs in milliseconds), so that boxes of one width read alike:
            // a 14-wide box keeps "late" up to 999 ms.
            let ms = l / 1000.0;
            lines.push(
                Line::from(fit(vec![
                    format!("p99 {l:.0} µs late"),
                    format!("p99 {l:.0}µs late"),
                    format!("p99 {ms:.1} ms late"),
                    format!("p99 {ms:.1}ms late"),
                    format!("p99 {ms:.0}ms late"),
                    format!("p99 {l:.0}µs"),
                    format!("p99 {ms:.1}ms"),
                    format!("p99 {ms:.0}ms"),
                ]))
                .dim(),
            );
        }
        _ => match n.ran {
            // Executors under the virtual clock: what the timer achieved, and what it skipped.
            Some((hz, skipped)) => {
                let text = match (skipped > 0, wide && area.width >= 22) {
                    (true, true) => format!("{hz:.1} Hz · {skipped} skip"),
                    (true, false) => fit(vec![
                        format!("{hz:.0} Hz·{skipped} skip"),
                        format!("{hz:.0}Hz {skipped}skip"),
                        format!("{skipped} skip"),
                    ]),
                    (false, _) => fit(vec![
                        format!("{hz:.1} Hz ran"),
                        format!("{hz:.0} Hz ran"),
                        format!("{hz:.1} ran"),
                    ]),
                };
                let line = Line::from(text);
                lines.push(if skipped > 0 { line.yellow() } else { line });
            }
            None if real => lines.push(Line::from("measuring").dim()),
            None => lines.push(Line::from(if wide { "virtual time" } else { "virtual" }).dim()),
        },
    }
    if let Some(c) = &n.compute {
        lines.push(
            Line::from(if wide {
                format!("{c} compute")
            } else {
                c.clone()
            })
            .dim(),
        );
    }
    // A Python or ROS 2 node says so under its rate, or in its title when the box has no
    // room left.
    let badge_in_title =
        n.badge.is_some() && lines.len() + 1 > usize::from(area.height.saturating_sub(2));
    if let (Some(b), false) = (n.badge, badge_in_title) {
        lines.insert(1, Line::from(b.words().0).cyan());
    }
    // What a tick costs, last: only where the box has a row left for it.
    if let Some(t) = n.tick_p50_us {
        if lines.len() < usize::from(area.height.saturating_sub(2)) {
            // Whole, in ms past 999 µs where µs would not fit (a 2 ms compute time).
            let ms = t / 1000.0;
            let text = fit(vec![
                format!("tick p50 {t:.0} µs"),
                format!("tick p50 {ms:.1} ms"),
                format!("tick {t:.0} µs"),
                format!("tick {ms:.1} ms"),
                format!("tick {ms:.0}ms"),
            ]);
            lines.push(Line::from(text).dim());
        }
    }
    if let Some(words) = alarm(n) {
        // The mark gives way in a narrow box (80 columns): the words must read whole.
        let full = format!("✗ {words}");
        let text = if full.chars().count() <= usize::from(area.width.saturating_sub(2)) {
            full
        } else {
            words.to_string()
        };
        lines.insert(0, Line::from(text).white().on_red().bold());
    }
    let mut name = match &n.process {
        Some(p) => format!("{}@{p}", n.name),
        None => n.name.clone(),
    };
    // Only where the name still fits whole (a centred title too long loses both ends).
    if let (Some(b), true) = (n.badge, badge_in_title) {
        let short = b.words().1;
        if name.chars().count() + short.len() < usize::from(area.width.saturating_sub(2)) {
            name.push(' ');
            name.push_str(short);
        }
    }
    let (title, border) = if n.selected {
        (
            Line::from(name).black().on_yellow().bold().centered(),
            Style::new().fg(Color::Yellow),
        )
    } else {
        (Line::from(name).bold().centered(), Style::new())
    };
    Paragraph::new(lines)
        .alignment(Alignment::Center)
        .block(Block::bordered().border_style(border).title(title))
        .render(area, buf);
}

/// `parts` packed greedily into lines of at most `w` characters.
fn pack(parts: impl IntoIterator<Item = String>, sep: &str, w: usize) -> Vec<String> {
    let mut packed: Vec<String> = Vec::new();
    for p in parts {
        match packed.last_mut() {
            Some(l) if l.chars().count() + sep.chars().count() + p.chars().count() <= w => {
                l.push_str(sep);
                l.push_str(&p);
            }
            _ => packed.push(p),
        }
    }
    packed
}

/// An arrow's lines at width `w`, for a panel `rows` high: name, shaft, msg/s, dropped (and
/// stale reads, and the wire latency across processes). When those do not fit in `rows`
/// (at 80×24), the drops and stale reads share a line (`3 drop ⚠ 126↺`) if it fits `w`, so
/// the wire line still shows; a wire line wider than `w` shows its p50 only. With QoS set:
/// name, shaft, drops, msg/s, the QoS counters, the QoS in short, stale reads, packed to the
/// width, most telling first (a short panel cuts from the end).
fn arrow_lines(t: &TopicView, w: usize, rows: usize) -> Vec<Line<'static>> {
    if t.subscriber.is_none() {
        // Published, read by no node (a diagnostic output): a dashed arrow to nobody, and
        // no drop count (every message it evicts is unread, and no one misses it).
        let grey = Style::new().fg(Color::DarkGray);
        return vec![
            Line::from(t.name.clone().bold()).centered(),
            Line::from(Span::styled(
                format!("{}▷", "╌".repeat(w.saturating_sub(1))),
                grey,
            )),
            Line::from(format!("{:.1} msg/s", t.msg_per_s)).centered(),
            Line::from(Span::styled("no subscriber", grey)).centered(),
        ];
    }
    let (shaft, style, mark) = if t.dropping {
        (
            "═",
            Style::new().fg(Color::Yellow).add_modifier(Modifier::BOLD),
            "⚠",
        )
    } else if t.unhealthy {
        ("─", Style::new().fg(Color::Red), "✗")
    } else {
        ("─", Style::new().fg(Color::Green), "✓")
    };
    let name = if t.selected {
        Line::from(
            format!("{} d{}", t.name, t.depth)
                .black()
                .on_yellow()
                .bold(),
        )
        .centered()
    } else {
        Line::from(t.name.clone().bold()).centered()
    };
    let shaft = Line::from(Span::styled(
        format!("{}▶", shaft.repeat(w.saturating_sub(1))),
        style,
    ));
    // The ✗ of an unhealthy topic stands by what went wrong, never by a count of 0 drops:
    // by its losses or missed deadlines where its QoS counters show (`53 lost ✗`), else by
    // its rate (a dead node starves it; a default-QoS topic's losses on the wire).
    let faulty = |label: &str| label == "lost" || label == "dl miss";
    let fault_counted = t.qos.is_some()
        && t.qos_counts
            .iter()
            .any(|(label, n)| *n > 0 && faulty(label));
    let fault_on_rate = t.unhealthy && !t.dropping && !fault_counted;
    let rate = if t.uncounted {
        Line::from("? msg/s".red()).centered()
    } else if fault_on_rate {
        // Room for the rate and " ✗".
        let text = first_that_fits(
            [
                format!("{:.1} msg/s", t.msg_per_s),
                format!("{:.0} msg/s", t.msg_per_s),
                format!("{:.0}/s", t.msg_per_s),
                format!("{:.0}", t.msg_per_s),
            ],
            (w + 1).saturating_sub(2),
        );
        Line::from(vec![
            Span::raw(format!("{text} ")),
            Span::styled("✗", style),
        ])
        .centered()
    } else {
        Line::from(format!("{:.1} msg/s", t.msg_per_s)).centered()
    };
    // Several subscribers: who reads it, under its name.
    let name = match &t.fan_out {
        Some(to) => {
            let to: String = format!("→ {to}").chars().take(w).collect();
            Line::from(vec![name.spans[0].clone(), Span::raw(" "), to.dim()]).centered()
        }
        None => name,
    };
    // The mark stays when the words do not fit (`25 drop ⚠` at 80 columns; the line may
    // take the column before the next box too).
    let drop_mark = if t.unhealthy && !t.dropping {
        String::new()
    } else {
        format!(" {mark}")
    };
    let dropped = first_that_fits(
        [
            format!("{} dropped{drop_mark}", t.dropped),
            format!("{} drop{drop_mark}", t.dropped),
            format!("{}{drop_mark}", t.dropped),
        ],
        w + 1,
    );
    let dropped = Line::from(Span::styled(dropped, style)).centered();
    // The mirror image of a drop, with a symbol of its own: old data read again.
    let stale_style = if t.staling {
        Style::new().fg(Color::Magenta).add_modifier(Modifier::BOLD)
    } else {
        Style::new().fg(Color::DarkGray)
    };
    let stale = (t.segment_stale_reads > 0).then(|| {
        Line::from(Span::styled(
            format!("{} stale ↺", t.stale_reads),
            stale_style,
        ))
        .centered()
    });
    let wire = t.wire_us.map(|(p50, p99)| {
        let full = format!("wire {p50:.0}/{p99:.0} µs");
        let text = if full.chars().count() <= w {
            full
        } else {
            format!("wire {p50:.0} µs")
        };
        Line::from(text.dim()).centered()
    });
    let Some(parts) = &t.qos else {
        let mut lines = vec![name, shaft, rate];
        let (drop_text, stale_text) = (
            format!("{} drop{drop_mark} ", t.dropped),
            format!("{}↺", t.stale_reads),
        );
        let short =
            lines.len() + 1 + usize::from(stale.is_some()) + usize::from(wire.is_some()) > rows;
        if short
            && stale.is_some()
            && wire.is_some()
            && (drop_text.chars().count() + stale_text.chars().count()) <= w
        {
            lines.push(
                Line::from(vec![
                    Span::styled(drop_text, style),
                    Span::styled(stale_text, stale_style),
                ])
                .centered(),
            );
        } else {
            lines.push(dropped);
            lines.extend(stale);
        }
        lines.extend(wire);
        return lines;
    };
    // The QoS on the shaft itself (`── dl 40 ms stop ──▶`), as many parts as fit, most
    // telling first: at 80×24 the panel's rows are the drops', the rate's and the counters'.
    // On a shaft too short for all, the chapter's keep-last/latest rule gives way first
    // (the depth shows in the header and on the selected arrow); the parts left go below.
    let room = w.saturating_sub(3); // the head and a space either side
    let all = parts.join(" ");
    let (on_shaft, below): (Vec<String>, Vec<String>) = if all.chars().count() <= room {
        (parts.clone(), Vec::new())
    } else {
        let mut fit: Vec<String> = Vec::new();
        let mut rest: Vec<String> = Vec::new();
        let latest_rule = |p: &str| p.starts_with("KL") && p.ends_with(" latest");
        for p in parts.iter().filter(|p| !latest_rule(p)) {
            let used = fit.iter().map(|f| f.chars().count() + 1).sum::<usize>();
            // Its compact form when it is too long (`dl 40 stop`: milliseconds, as every
            // QoS time is), then its first two words (`dl 30`: the deadline without what a
            // miss does, which goes below with the whole part).
            let compact = p.replace(" ms", "");
            let words: Vec<&str> = compact.split(' ').collect();
            let head = (words.len() > 2).then(|| words[..2].join(" "));
            let whole = [p.clone(), compact.clone()]
                .into_iter()
                .find(|c| rest.is_empty() && used + c.chars().count() <= room);
            match (whole, head) {
                (Some(c), _) => fit.push(c),
                (None, Some(h)) if rest.is_empty() && used + h.chars().count() <= room => {
                    fit.push(h);
                    rest.push(p.clone());
                }
                _ => rest.push(p.clone()),
            }
        }
        rest.extend(parts.iter().filter(|p| latest_rule(p)).cloned());
        (fit, rest)
    };
    let shaft = if on_shaft.is_empty() {
        shaft
    } else {
        let label = on_shaft.join(" ");
        let run = w
            .saturating_sub(1)
            .saturating_sub(label.chars().count() + 2);
        let (left, right) = (run / 2, run - run / 2);
        let shaft_style = shaft.spans.first().map_or(Style::new(), |s| s.style);
        let bar = if t.dropping { "═" } else { "─" };
        Line::from(vec![
            Span::styled(format!("{} ", bar.repeat(left)), shaft_style),
            Span::raw(label).dim(),
            Span::styled(format!(" {}▶", bar.repeat(right)), shaft_style),
        ])
    };
    // msg/s right after the drops: at 80×24 a panel of five rows still shows it.
    let mut lines = vec![name, shaft, dropped, rate];
    let counting = t.qos_counts.iter().any(|(_, n)| *n > 0);
    // The counters that counted first (a short panel cuts from the end: at 80×24 "41 lost"
    // must not give way to "0 expired").
    let mut counted: Vec<&(&'static str, u64)> = t.qos_counts.iter().collect();
    counted.sort_by_key(|(_, n)| *n == 0);
    // The unhealthy topic's ✗ by the first of its losses or missed deadlines that counted.
    let marked = counted
        .iter()
        .position(|(label, n)| *n > 0 && faulty(label))
        .filter(|_| t.unhealthy && !t.dropping);
    let counts = pack(
        counted.iter().enumerate().map(|(i, (label, n))| {
            format!("{n} {label}{}", if Some(i) == marked { " ✗" } else { "" })
        }),
        " · ",
        w,
    );
    let style = if counting {
        Style::new().fg(Color::Red).add_modifier(Modifier::BOLD)
    } else {
        Style::new().fg(Color::DarkGray)
    };
    lines.extend(
        counts
            .into_iter()
            .map(|l| Line::from(Span::styled(l, style)).centered()),
    );
    lines.extend(
        pack(below, " ", w)
            .into_iter()
            .map(|l| Line::from(l).dim().centered()),
    );
    lines.extend(stale);
    lines.extend(wire);
    lines
}

fn render_arrow(t: &TopicView, area: Rect, buf: &mut Buffer) {
    let w = area.width.saturating_sub(1) as usize;
    Paragraph::new(arrow_lines(t, w, usize::from(area.height))).render(area, buf);
}

/// What a node's box raises in red: its lease ran out (`NOT ALIVE`), or, until then, the
/// fault injected into it (`STALLED`, `KILLED`).
fn alarm(n: &NodeView) -> Option<&'static str> {
    if n.alive == Some(false) {
        Some("NOT ALIVE")
    } else {
        n.fault
    }
}

/// The rows a node's box would fill inside its border: its rate, what it measured (or ran,
/// or sent), its compute time, badge, tick time and liveliness.
fn node_rows(n: &NodeView) -> usize {
    let status = match (n.published_hz, n.measured_hz, n.lateness_p99_us) {
        (None, Some(_), Some(_)) => 2,
        _ => 1,
    };
    1 + status
        + usize::from(n.compute.is_some())
        + usize::from(n.badge.is_some())
        + usize::from(n.tick_p50_us.is_some())
        + usize::from(alarm(n).is_some())
}

/// The graph panel's height: 7 rows, more when an arrow's QoS lines or a column of node
/// boxes need them and the terminal is tall enough (30 rows) to spare them, within `max`.
fn graph_height(v: &View, width: u16, height: u16, max: u16) -> u16 {
    if height < 30 {
        return 7;
    }
    let cols = layout_columns(v);
    let n = cols.len().max(1) as u16;
    let w = (width.saturating_sub(2) / n).saturating_sub(1) as usize;
    let tallest = cols
        .iter()
        .map(|c| match c {
            Column::Topics(ts) => ts
                .iter()
                .map(|&i| arrow_lines(&v.topics[i], w, usize::MAX).len())
                .sum::<usize>(),
            Column::Nodes(ns) => ns.iter().map(|&i| node_rows(&v.nodes[i]) + 2).sum(),
        })
        .max()
        .unwrap_or(0) as u16;
    (tallest + 2).clamp(7, max.max(7))
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
        Verdict::Hung { node, since_s } => Span::from(format!(
            " HUNG in {node}'s callback since t={since_s:.2}s ✗ "
        ))
        .white()
        .on_red()
        .bold(),
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

fn render_cartpole(v: &View, area: Rect, buf: &mut Buffer) {
    let x = v.cart_pos;
    let theta = v.pole_angle;
    // The verdict reads whole: in a narrow panel (80 columns) the panel's name gives way,
    // then the badge's padding ("BALANCED while the plant ran" is no plain BALANCED).
    let room = usize::from(area.width.saturating_sub(2));
    let verdict = match &v.verdict {
        // The hang's verdict in the first of its forms that fits the panel whole.
        Verdict::Hung { node, since_s } => {
            let forms = vec![
                format!(" HUNG in {node}'s callback since t={since_s:.2}s ✗ "),
                format!(" HUNG in {node}'s callback t={since_s:.2}s "),
                format!(" HUNG: {node} since t={since_s:.2}s "),
                format!(" HUNG: {node} t={since_s:.2}s "),
            ];
            Span::from(first_that_fits(forms, room))
                .white()
                .on_red()
                .bold()
        }
        _ => badge(v),
    };
    let words = verdict.content.chars().count();
    let name = " cartpole ";
    let title = if name.len() + words <= room {
        Line::from(vec![name.into(), verdict])
    } else if words <= room {
        Line::from(verdict)
    } else {
        Line::from(Span::styled(
            verdict.content.trim().to_string(),
            verdict.style,
        ))
    };
    Canvas::default()
        .block(Block::bordered().title(title))
        .marker(Marker::Braille)
        .x_bounds([-2.6, 2.6])
        .y_bounds([-0.3, 1.2])
        .paint(move |ctx| {
            ctx.draw(&CanvasLine {
                x1: -2.4,
                y1: -0.05,
                x2: 2.4,
                y2: -0.05,
                color: Color::Gray,
            });
            // Fall limits: ±12° from the pivot.
            for sign in [-1.0, 1.0] {
                let a = sign * LIMIT_RAD;
                ctx.draw(&CanvasLine {
                    x1: x,
                    y1: 0.05,
                    x2: x + a.sin(),
                    y2: 0.05 + a.cos(),
                    color: Color::DarkGray,
                });
            }
            ctx.draw(&Rectangle {
                x: x - 0.2,
                y: -0.05,
                width: 0.4,
                height: 0.15,
                color: Color::Blue,
            });
            let color = if theta.abs() > LIMIT_RAD {
                Color::Red
            } else {
                Color::Yellow
            };
            ctx.draw(&CanvasLine {
                x1: x,
                y1: 0.05,
                x2: x + theta.sin(),
                y2: 0.05 + theta.cos(),
                color,
            });
        })
        .render(area, buf);
}

fn render_angle_chart(v: &View, area: Rect, buf: &mut Buffer) {
    let t1 = v.sim_time_s.max(10.0);
    let t0 = t1 - 10.0;
    let upper = [(t0, LIMIT_RAD), (t1, LIMIT_RAD)];
    let lower = [(t0, -LIMIT_RAD), (t1, -LIMIT_RAD)];
    let data: Vec<(f64, f64)> = v
        .angle_history
        .iter()
        .map(|&(t, a)| (t, a.clamp(-0.3, 0.3)))
        .collect();
    // A vertical mark at each change of settings: a new segment starts there.
    let marks: Vec<[(f64, f64); 2]> = v
        .segment
        .marks_s
        .iter()
        .filter(|&&t| t >= t0 && t <= t1)
        // A tick at the top edge, not a line across: a line read as a ±0.3 rad spike.
        .map(|&t| [(t, 0.26), (t, 0.3)])
        .collect();
    let mut datasets = vec![
        Dataset::default()
            .name("θ")
            .marker(Marker::Braille)
            .graph_type(GraphType::Line)
            .yellow()
            .data(&data),
        Dataset::default()
            .name("±12°")
            .marker(Marker::Braille)
            .graph_type(GraphType::Line)
            .red()
            .data(&upper),
        Dataset::default()
            .marker(Marker::Braille)
            .graph_type(GraphType::Line)
            .red()
            .data(&lower),
    ];
    for (i, m) in marks.iter().enumerate() {
        let d = Dataset::default()
            .marker(Marker::Braille)
            .graph_type(GraphType::Line)
            .cyan()
            .data(m);
        datasets.push(if i == 0 { d.name("change") } else { d });
    }
    // The lines' key in the title (the chart's own legend hides when the chart is small):
    // the fall limits (±0.2095 rad, drawn between the axis's ±0.3 labels), the changes'
    // marks, then the window, each as long as the title has room.
    let room = usize::from(area.width.saturating_sub(2));
    let mut title = vec![Span::raw(" pole angle (rad) ")];
    let mut used = 18;
    let limits = format!("── ±{LIMIT_RAD:.2} fall ");
    let mut add = |title: &mut Vec<Span<'static>>, text: String, style: Style| {
        let n = text.chars().count() + 2;
        if used + n <= room {
            used += n;
            title.push(Span::raw("· "));
            title.push(Span::styled(text, style));
        }
    };
    add(&mut title, limits, Style::new().fg(Color::Red));
    if !marks.is_empty() {
        add(&mut title, "⡇ change ".into(), Style::new().fg(Color::Cyan));
    }
    add(&mut title, "last 10 s ".into(), Style::new());
    Chart::new(datasets)
        .block(Block::bordered().title(Line::from(title)))
        .x_axis(time_axis(t0, t1, area))
        .y_axis(
            Axis::default()
                .bounds([-0.3, 0.3])
                .labels(["-0.3", "0", "0.3"]),
        )
        .render(area, buf);
}

/// The last 10 s; labelled only where the chart has room for the axis (two rows).
fn time_axis(t0: f64, t1: f64, area: Rect) -> Axis<'static> {
    let axis = Axis::default().bounds([t0, t1]);
    if area.height >= 8 {
        axis.labels([format!("{t0:.0}s"), format!("{t1:.0}s")])
    } else {
        axis
    }
}

/// The zero-order hold, live: the force the policy published (dots, at its ticks) and the
/// force the actuator applied (a staircase: each step's force held until the next).
fn render_hold_chart(v: &View, area: Rect, buf: &mut Buffer) {
    let t1 = v.sim_time_s.max(10.0);
    let t0 = t1 - 10.0;
    let limit = ratelab::plant::GEAR_N;
    let clamp = |pts: &[(f64, f64)]| -> Vec<(f64, f64)> {
        pts.iter()
            .map(|&(t, f)| (t, f.clamp(-limit, limit)))
            .collect()
    };
    let (applied, published) = (clamp(&v.applied_force), clamp(&v.published_force));
    let datasets = vec![
        Dataset::default()
            .name("applied")
            .marker(Marker::Braille)
            .graph_type(GraphType::Line)
            .green()
            .data(&applied),
        Dataset::default()
            .name("published")
            .marker(Marker::Braille)
            .graph_type(GraphType::Scatter)
            .magenta()
            .data(&published),
    ];
    // Three labels need three rows of plot. A band of two rows (80×24) cannot put a label
    // on 0 N: the braille grid draws 0 N in the upper row (at its lowest dot), so its rows
    // are labelled by what they hold, ≥ 0 above and < 0 below, not by ±10 at their ends,
    // which read as if 0 N were 10 N.
    let labels: &[&str] = if area.height >= 5 {
        &["-10", "0", "10"]
    } else {
        &["<0", "≥0"]
    };
    let title = Line::from(vec![
        " force (N): ".into(),
        "published".magenta(),
        " · ".into(),
        "applied".green(),
        " — the hold ".into(),
    ]);
    Chart::new(datasets)
        .block(Block::bordered().title(title))
        .hidden_legend_constraints((Constraint::Length(0), Constraint::Length(0)))
        .x_axis(time_axis(t0, t1, area))
        .y_axis(
            Axis::default()
                .bounds([-limit, limit])
                .labels(labels.iter().copied()),
        )
        .render(area, buf);
}

/// The segment line: what the arrows count over (the window), then each topic's totals since
/// the last change of settings (or the start), saying since when, with the change when the
/// width allows.
fn render_segment(v: &View, area: Rect, buf: &mut Buffer) {
    let seg = &v.segment;
    // `short`: 0 says it in words, 1 shortens "dropped", 2 also writes stale reads as `N↺`
    // (the arrows' symbol), so that no number is cut at 80 columns.
    let topics = |short: u8| -> Vec<Span<'static>> {
        let mut spans: Vec<Span> = Vec::new();
        // A topic nobody reads has no drops to total (the arrow says "no subscriber").
        for (i, t) in v
            .topics
            .iter()
            .filter(|t| t.subscriber.is_some())
            .enumerate()
        {
            if i > 0 {
                spans.push(" · ".dim());
            }
            spans.push(format!("{} ", t.name).into());
            let dropped = if short > 0 {
                format!("{} drop", t.segment_dropped)
            } else {
                format!("{} dropped", t.segment_dropped)
            };
            spans.push(if t.segment_dropped > 0 {
                dropped.yellow().bold()
            } else {
                dropped.into()
            });
            if t.segment_stale_reads > 0 {
                spans.push(if short > 1 {
                    format!(" {}↺", t.segment_stale_reads).magenta()
                } else {
                    format!(", {} stale", t.segment_stale_reads).magenta()
                });
            }
            if t.segment_lost > 0 {
                spans.push(if short > 1 {
                    format!(" {} lost", t.segment_lost).red()
                } else {
                    format!(", {} lost", t.segment_lost).red()
                });
            }
        }
        spans
    };
    let since = seg.since();
    let mut heads: Vec<String> = Vec::new();
    if let Some(cause) = &seg.cause {
        heads.push(format!(" totals since the change at {since} ({cause}): "));
        heads.push(format!(" totals since the change at {since}: "));
    }
    heads.push(format!(" totals since {since}: "));
    // From the most to the least said, the first that fits.
    let mut candidates: Vec<Vec<Span>> = Vec::new();
    for head in &heads {
        let mut line = vec![
            " arrows: ".dim(),
            seg.window_label().bold(),
            " │".dim(),
            Span::from(head.clone()).dim(),
        ];
        line.extend(topics(0));
        candidates.push(line);
    }
    for short in [0, 1, 2] {
        let mut line = vec![
            " ".into(),
            seg.window_label().bold(),
            " │".dim(),
            Span::from(format!(" since {since}: ")).dim(),
        ];
        line.extend(topics(short));
        candidates.push(line);
    }
    // Narrower: the totals without their "since" (the latency panel's title says it), but
    // still called totals (after "last 5 s" alone they read as the window's).
    let mut line = vec![
        " ".into(),
        seg.window_label().bold(),
        " │".dim(),
        " totals: ".dim(),
    ];
    line.extend(topics(2));
    candidates.push(line);
    // The narrowest: the totals alone (the arrows' window is in the latency panel's foot).
    let mut line = vec![" totals: ".dim()];
    line.extend(topics(2));
    candidates.push(line);
    let width = |l: &Vec<Span>| l.iter().map(|s| s.content.chars().count()).sum::<usize>();
    let last = candidates.len() - 1;
    let line = candidates
        .iter()
        .position(|l| width(l) <= area.width as usize)
        .map_or_else(|| candidates[last].clone(), |i| candidates[i].clone());
    Paragraph::new(Line::from(line)).render(area, buf);
}

/// `n=81 (+19 no cmd) │ p50 20.0 │ p99 220.0 │ max 220.0 ms `: a latency panel's figures.
/// Steps that applied no command have no latency: said beside n, not silently left out.
fn latency_figures(count: u64, no_command: u64, p50_ms: f64, p99_ms: f64, max_ms: f64) -> String {
    let no_cmd = if no_command > 0 {
        format!(" (+{no_command} no cmd)")
    } else {
        String::new()
    };
    format!("n={count}{no_cmd} │ p50 {p50_ms:.1} │ p99 {p99_ms:.1} │ max {max_ms:.1} ms ")
}

fn render_latency(v: &View, area: Rect, buf: &mut Buffer) {
    let l = &v.latency;
    let since = match v.segment.joined_s {
        Some(t) => format!("{t:.2} s (joined)"),
        None => v.segment.since(),
    };
    let figures = latency_figures(l.count, l.no_command, l.p50_ms, l.p99_ms, l.max_ms);
    // "sense→act" and "since …" when the width allows them; the figures whole always.
    let title = first_that_fits(
        [
            format!(" sense→act latency since {since}: {figures}"),
            format!(" latency since {since}: {figures}"),
            format!(" latency {figures}"),
        ],
        usize::from(area.width).saturating_sub(2),
    );
    let w = &l.window;
    let window = Line::from(vec![
        " ".into(),
        v.segment.latency_window_label().bold(),
        format!(
            ": {}",
            latency_figures(w.count, w.no_command, w.p50_ms, w.p99_ms, w.max_ms)
        )
        .into(),
    ]);
    let bars: Vec<Bar> = l
        .buckets
        .iter()
        .map(|(label, n)| Bar::default().value(*n).label(Line::from(label.clone())))
        .collect();
    let inner_w = area.width.saturating_sub(2);
    let n = l.buckets.len().max(1) as u16;
    let bar_w = (inner_w / n).saturating_sub(1).clamp(1, 12);
    BarChart::default()
        .block(Block::bordered().title(title).title_bottom(window))
        .data(BarGroup::default().bars(&bars))
        .bar_width(bar_w)
        .bar_gap(1)
        .bar_style(Style::new().fg(Color::Cyan))
        .value_style(Style::new().fg(Color::Black).bg(Color::Cyan))
        .render(area, buf);
}

/// The first of `forms` (longest first) that fits `room` columns whole, else the last: a
/// figure or title never cut mid-word.
pub(super) fn first_that_fits(forms: impl IntoIterator<Item = String>, room: usize) -> String {
    let mut last = String::new();
    for f in forms {
        if f.chars().count() <= room {
            return f;
        }
        last = f;
    }
    last
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

fn render_footer(v: &View, area: Rect, buf: &mut Buffer) {
    // A hung callback is no end: the run goes on once it returns.
    let ended = !matches!(v.verdict, Verdict::Balanced | Verdict::Hung { .. });
    // Typing a rate shows its prompt even after a fall, where the verdict leads otherwise.
    let line = if let Some(t) = &v.typing {
        Line::from(vec![
            " rate (Hz): ".bold(),
            format!("{t}▏").into(),
            "  Enter apply · Esc cancel".dim(),
        ])
    } else if let (true, Some(m)) = (ended, &v.message) {
        let m = fit_message(m, usize::from(area.width).saturating_sub(1));
        Line::from(Span::from(format!(" {m}")).bold())
    } else if let (true, Some(m)) = (v.message_fresh, &v.message) {
        let width = usize::from(area.width);
        let m = fit_message(m, width.saturating_sub(3));
        let keys = (m.chars().count() + 3 + 10 <= width).then(|| "  (? keys)".dim());
        Line::from(
            std::iter::once(Span::from(format!(" ● {m}")).bold())
                .chain(keys)
                .collect::<Vec<_>>(),
        )
    } else {
        // Attached to a graph across processes, only the keys that change the view act.
        let mut spans: Vec<Span> = match v.attached {
            Some(_) => match &v.endpoint {
                Some(ep) => vec![format!(" read-only · {ep} │ ").dim()],
                None => vec![" read-only │ ".dim()],
            },
            None => vec![" ".into()],
        };
        let shown = BINDINGS
            .iter()
            .filter(|b| v.attached.is_none() || b.only_views());
        for (keys, word) in shown.filter_map(|b| b.footer) {
            spans.push(format!("{keys} ").bold());
            spans.push(format!("{word} ").into());
        }
        // The last message after the keys, made to fit what is left (its verdict kept),
        // or left out where too little is (never a cut word or a bare `│`).
        let used: usize = spans.iter().map(|s| s.content.chars().count()).sum();
        let left = usize::from(area.width).saturating_sub(used + 4);
        if let (Some(m), true) = (&v.message, left >= 12) {
            spans.push(Span::from(format!("  │ {}", fit_message(m, left))).italic());
        }
        Line::from(spans)
    };
    Paragraph::new(line).render(area, buf);
}

/// The key help over the lab; `attached`: only the keys that act in a lab that watches a
/// graph across processes (the others would be refused).
fn render_help(area: Rect, buf: &mut Buffer, attached: bool) {
    let mut lines: Vec<Line> = BINDINGS
        .iter()
        .filter(|b| !attached || b.only_views())
        .map(|b| Line::from(vec![format!("{:>16}  ", b.label).bold(), b.help.into()]))
        .collect();
    let notes: Vec<Line> = HELP_NOTES
        .iter()
        // Attached, the ladders and the fall's keys do not apply; the wire's note does.
        .filter(|(k, _)| !attached || k.starts_with("wire"))
        .map(|(k, d)| Line::from(vec![format!("{k:>16}  ").bold(), (*d).into()]))
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
    use super::fit_message;

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
