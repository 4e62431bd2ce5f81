//! The executor timeline (key `t`, in place of the latency histogram): per executor thread,
//! which node's tick ran when over the last second of run time, ticks that started a period
//! or more late (their timer skipped periods) or ran past their period in red. Each tick
//! is its node's letter, capital where it starts.
//!
//! Its state is the ticks heard of ([`Timeline`]): under the virtual clock the scheduler's
//! [`CallbackSpan`]s, sent when the graph has executors or compute times (without them a
//! tick is an instant and there is nothing to draw); under the real clock each
//! [`Telemetry::NodeTick`](ratelab::session::Telemetry::NodeTick), start to end. Threads
//! are not named by the executors: ticks are laid on an executor's `threads` lanes first
//! come, lowest free lane first, which is what a pool of that many threads can have done.

use ratatui::buffer::Buffer;
use ratatui::layout::Rect;
use ratatui::style::{Color, Style, Stylize};
use ratatui::text::{Line, Span};
use ratatui::widgets::{Block, Paragraph, Widget};
use ratelab::executor::{CallbackSpan, ExecutionPlan};
use ratelab::graph::GraphSpec;
use ratelab::Nanos;
use std::collections::VecDeque;

/// How much run time the timeline shows, ending now.
pub const WINDOW: Nanos = Nanos::SECOND;

/// The most ticks kept (a 10 kHz node fills a second with 10 000).
const MAX_KEPT: usize = 8192;

/// The ticks heard of over the last [`WINDOW`].
#[derive(Clone, Debug, Default)]
pub struct Timeline {
    spans: VecDeque<CallbackSpan>,
}

impl Timeline {
    /// How many ticks it holds.
    pub fn kept(&self) -> usize {
        self.spans.len()
    }

    /// Forget every tick (a new run).
    pub fn clear(&mut self) {
        self.spans.clear();
    }

    /// A tick that ended; ticks that ended before `now − WINDOW` go.
    pub fn push(&mut self, span: CallbackSpan, now: Nanos) {
        if self.spans.len() == MAX_KEPT {
            self.spans.pop_front();
        }
        self.spans.push_back(span);
        let from = now.saturating_sub(WINDOW);
        while self.spans.front().is_some_and(|s| s.end < from) {
            self.spans.pop_front();
        }
    }

    /// What to draw at run time `now` for `graph` run by `plan`, each node at its rate now
    /// (`rates_hz`, by node index).
    pub fn view(
        &self,
        graph: &GraphSpec,
        plan: &ExecutionPlan,
        rates_hz: &[f64],
        now: Nanos,
    ) -> TimelineView {
        let t0 = now.saturating_sub(WINDOW);
        let mut lanes = Vec::new();
        for (e, exec) in plan.executors.iter().enumerate() {
            let threads = exec.threads.max(1);
            let first = lanes.len();
            for k in 0..threads {
                lanes.push(LaneView {
                    label: if threads == 1 {
                        exec.name.clone()
                    } else {
                        format!("{}#{}", exec.name, k + 1)
                    },
                    spans: Vec::new(),
                });
            }
            // First come, lowest free lane first.
            let mut free_at = vec![Nanos::ZERO; threads];
            let mut mine: Vec<&CallbackSpan> = self
                .spans
                .iter()
                .filter(|s| plan.node_executor.get(s.node) == Some(&e) && s.end >= t0)
                .collect();
            mine.sort_by_key(|s| (s.start, s.node));
            for s in mine {
                let lane = (0..threads)
                    .find(|&k| free_at[k] <= s.start)
                    .unwrap_or_else(|| (0..threads).min_by_key(|&k| free_at[k]).unwrap_or(0));
                free_at[lane] = s.end;
                let period = rates_hz
                    .get(s.node)
                    .and_then(|&hz| Nanos::from_secs_f64(1.0 / hz.max(1e-6)))
                    .unwrap_or(Nanos(u64::MAX));
                let late = s.start.saturating_sub(s.release) >= period
                    || s.end.saturating_sub(s.start) > period;
                lanes[first + lane].spans.push(SpanView {
                    node: s.node,
                    start: s.start,
                    end: s.end,
                    late,
                });
            }
        }
        TimelineView {
            t0,
            t1: now,
            lanes,
            letters: letters(graph),
            names: graph.nodes.iter().map(|n| n.name.clone()).collect(),
        }
    }
}

/// One letter per node, distinct: the first of its name not taken by an earlier node.
fn letters(graph: &GraphSpec) -> Vec<char> {
    let mut taken: Vec<char> = Vec::new();
    for n in &graph.nodes {
        let c = n
            .name
            .chars()
            .filter(|c| c.is_alphanumeric())
            .map(|c| c.to_ascii_lowercase())
            .find(|c| !taken.contains(c))
            .or_else(|| ('a'..='z').find(|c| !taken.contains(c)))
            .unwrap_or('?');
        taken.push(c);
    }
    taken
}

/// The executor timeline as drawn.
#[derive(Clone, Debug, PartialEq)]
pub struct TimelineView {
    /// Run time at the left edge.
    pub t0: Nanos,
    /// Run time at the right edge (now).
    pub t1: Nanos,
    /// One per executor thread, executors in the plan's order.
    pub lanes: Vec<LaneView>,
    /// Each node's letter, by node index.
    pub letters: Vec<char>,
    /// Each node's name, by node index.
    pub names: Vec<String>,
}

/// One executor thread's row.
#[derive(Clone, Debug, PartialEq)]
pub struct LaneView {
    /// The executor's name (a per-node executor is named after its node), `#k` for its
    /// k-th thread.
    pub label: String,
    /// The ticks on it, by start.
    pub spans: Vec<SpanView>,
}

/// One tick on a lane.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SpanView {
    /// The node.
    pub node: usize,
    /// Start and end, run time.
    pub start: Nanos,
    /// End (equal to the start for a tick that took no time).
    pub end: Nanos,
    /// Started a period or more after its timer was due, or ran past its period.
    pub late: bool,
}

const PALETTE: [Color; 6] = [
    Color::Cyan,
    Color::Green,
    Color::Magenta,
    Color::Blue,
    Color::Yellow,
    Color::LightCyan,
];

/// Draw `v` in `area`; `virtual_clock` without ticks says why there are none.
pub fn render(v: &TimelineView, virtual_clock: bool, area: Rect, buf: &mut Buffer) {
    let legend: Vec<String> = v
        .names
        .iter()
        .zip(&v.letters)
        .map(|(n, c)| format!("{c} {n}"))
        .collect();
    // The first title that fits whole, the letters' legend kept the longest.
    let secs = WINDOW.as_secs_f64();
    let legend = legend.join(" · ");
    let titles = [
        format!(
            " executor timeline, last {secs:.0} s (t: latency) │ {legend} │ red: a period late or over "
        ),
        format!(" executor timeline, last {secs:.0} s │ {legend} │ red: late "),
        format!(" timeline │ {legend} │ red: late "),
        format!(" {legend} │ red: late "),
        format!(" {legend} "),
    ];
    let title = super::fit::first_that_fits(titles, usize::from(area.width.saturating_sub(2)));
    let block = Block::bordered().title(title);
    let inner = block.inner(area);
    block.render(area, buf);
    if v.lanes.iter().all(|l| l.spans.is_empty()) {
        let why = if virtual_clock {
            "Under the virtual clock a tick takes no time unless it declares one: give nodes compute_ms or an executor (graphs/cartpole-executors.toml) to see them."
        } else {
            "No ticks yet."
        };
        Paragraph::new(why)
            .dim()
            .wrap(ratatui::widgets::Wrap { trim: true })
            .render(inner, buf);
        return;
    }
    let label_w = v
        .lanes
        .iter()
        .map(|l| l.label.chars().count())
        .max()
        .unwrap_or(0)
        .min(usize::from(inner.width / 4)) as u16;
    let cols = inner.width.saturating_sub(label_w + 1);
    if cols == 0 {
        return;
    }
    let span_ns = v.t1.saturating_sub(v.t0).0.max(1);
    let col_of = |t: Nanos| -> u16 {
        let x = t.saturating_sub(v.t0).0 as u128 * u128::from(cols) / u128::from(span_ns);
        (x as u16).min(cols - 1)
    };
    // The last row is the time axis, when there is room for it and a lane.
    let axis = inner.height >= 2;
    let rows = inner.height.saturating_sub(u16::from(axis));
    for (r, lane) in v.lanes.iter().take(usize::from(rows)).enumerate() {
        let y = inner.y + r as u16;
        let label: String = lane.label.chars().take(usize::from(label_w)).collect();
        buf.set_string(inner.x, y, &label, Style::new().dim());
        let x0 = inner.x + label_w + 1;
        // Ticks that fill cells first, then those within one cell on top (a short tick
        // beside a long one stays visible); each tick's first cell in capitals.
        let mut order: Vec<&SpanView> = lane.spans.iter().collect();
        order.sort_by_key(|s| (col_of(s.end) == col_of(s.start), s.start));
        // Whose short tick each cell shows: one run back to back with another node's in
        // the same cell (a single-threaded executor's ticks due at one instant) goes in
        // the next cell when that is free, in the order they ran, rather than under it.
        let mut shown: Vec<Option<usize>> = vec![None; usize::from(cols)];
        for s in order {
            if s.end < v.t0 {
                continue;
            }
            let (mut a, mut b) = (col_of(s.start.max(v.t0)), col_of(s.end));
            if a == b {
                let taken = |x: u16| shown[usize::from(x)].is_some_and(|n| n != s.node);
                if taken(a) && a + 1 < cols && !taken(a + 1) {
                    (a, b) = (a + 1, a + 1);
                }
                shown[usize::from(a)] = Some(s.node);
            }
            let color = PALETTE[s.node % PALETTE.len()];
            let style = if s.late {
                Style::new().fg(Color::White).bg(Color::Red)
            } else {
                Style::new().fg(Color::Black).bg(color)
            };
            let c = v.letters.get(s.node).copied().unwrap_or('?');
            for x in a..=b {
                let c = if x == a && s.start >= v.t0 {
                    c.to_ascii_uppercase()
                } else {
                    c
                };
                buf.set_string(x0 + x, y, c.to_string(), style);
            }
        }
    }
    if v.lanes.len() > usize::from(rows) {
        let hidden = v.lanes.len() - usize::from(rows);
        let more = format!(" +{hidden} lane{} ", if hidden == 1 { "" } else { "s" });
        let x = inner.right().saturating_sub(more.len() as u16);
        buf.set_string(x, inner.y, more, Style::new().reversed());
    }
    if axis {
        let y = inner.bottom() - 1;
        let left = format!("{:.2} s", v.t0.as_secs_f64());
        let right = format!("{:.2} s", v.t1.as_secs_f64());
        let x0 = inner.x + label_w + 1;
        Line::from(vec![Span::from(left).dim()]).render(Rect::new(x0, y, cols, 1), buf);
        let rx = (x0 + cols).saturating_sub(right.len() as u16);
        buf.set_string(rx, y, right, Style::new().dim());
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const MS: u64 = 1_000_000;

    fn span(node: usize, release_ms: u64, start_ms: u64, end_ms: u64) -> CallbackSpan {
        CallbackSpan {
            node,
            release: Nanos(release_ms * MS),
            start: Nanos(start_ms * MS),
            end: Nanos(end_ms * MS),
        }
    }

    /// The executors graph with its two nodes in reentrant groups, or in one exclusive one.
    fn graph(reentrant: bool) -> GraphSpec {
        let text = std::fs::read_to_string(
            std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
                .join("../graphs/cartpole-executors.toml"),
        )
        .unwrap();
        let text = if reentrant {
            text.replace(
                "{ node = \"mutually_exclusive\" }",
                "{ node = \"reentrant\" }",
            )
        } else {
            text
        };
        GraphSpec::parse(&text, "g.toml").unwrap()
    }

    #[test]
    fn ticks_are_laid_on_an_executors_threads_first_come_lowest_lane_first() {
        let now = Nanos(1500 * MS);
        let rates = [50.0, 50.0, 50.0];
        for (reentrant, second_lane) in [(true, true), (false, false)] {
            let g = graph(reentrant);
            let plan = g.execution_plan();
            let (sensor, policy) = (
                g.node_id("sensor").unwrap().0,
                g.node_id("policy").unwrap().0,
            );
            let mut t = Timeline::default();
            // The policy computes 30 ms from 900 ms; the sensor ticks at 920 ms: with a
            // reentrant group it runs beside it, with an exclusive one after it (930 ms).
            t.push(span(policy, 900, 900, 930), now);
            let s = if reentrant {
                span(sensor, 920, 920, 920)
            } else {
                span(sensor, 920, 930, 930)
            };
            t.push(s, now);
            // Too old to draw (before 500 ms).
            t.push(span(sensor, 100, 100, 100), now);
            let v = t.view(&g, &plan, &rates, now);
            let main: Vec<&LaneView> = v
                .lanes
                .iter()
                .filter(|l| l.label.starts_with("main#"))
                .collect();
            assert_eq!(main.len(), 2, "two threads, two lanes");
            assert_eq!(main[0].spans[0].node, policy);
            assert_eq!(!main[1].spans.is_empty(), second_lane, "{v:?}");
            let all: usize = v.lanes.iter().map(|l| l.spans.len()).sum();
            assert_eq!(all, 2, "the tick before the window is not drawn");
            // 30 ms at 50 Hz runs past its period: late.
            assert!(main[0].spans[0].late);
        }
    }

    #[test]
    fn a_tick_a_period_late_is_marked_and_letters_are_distinct() {
        let g = graph(false);
        let plan = g.execution_plan();
        let sensor = g.node_id("sensor").unwrap().0;
        let mut t = Timeline::default();
        let now = Nanos(1000 * MS);
        t.push(span(sensor, 900, 919, 919), now); // 19 ms late: in time
        t.push(span(sensor, 940, 960, 960), now); // 20 ms late: a period
        let v = t.view(&g, &plan, &[50.0; 3], now);
        let lane = v.lanes.iter().find(|l| !l.spans.is_empty()).unwrap();
        assert_eq!(
            lane.spans.iter().map(|s| s.late).collect::<Vec<_>>(),
            [false, true]
        );
        assert_eq!(v.letters, ['s', 'p', 'a']);
    }

    #[test]
    fn the_timeline_draws_each_tick_as_its_letter_capital_where_it_starts() {
        let g = graph(false);
        let plan = g.execution_plan();
        let policy = g.node_id("policy").unwrap().0;
        let mut t = Timeline::default();
        let now = Nanos(1000 * MS);
        t.push(span(policy, 500, 500, 600), now);
        let v = t.view(&g, &plan, &[50.0; 3], now);
        let mut buf = Buffer::empty(Rect::new(0, 0, 60, 8));
        render(&v, true, buf.area, &mut buf);
        let text = crate::tui::buffer_text(&buf);
        // At 60 columns the title is the short one, whole: every node's letter and "red".
        assert!(
            text.contains("┌ timeline │ s sensor · p policy · a actuator │ red: late ─┐"),
            "{text}"
        );
        assert!(text.contains("main#1"), "{text}");
        assert!(text.contains("Ppppp"), "{text}");
        assert!(text.contains("0.00 s") && text.contains("1.00 s"), "{text}");
        // Ticks that take no time, due at one instant on a single thread (the virtual
        // clock without compute times): each node's letter is seen, side by side in the
        // order they ran, not the last over the first.
        let sensor = g.node_id("sensor").unwrap().0;
        let mut t = Timeline::default();
        for k in 0..50 {
            let at = k * 20;
            t.push(span(sensor, at, at, at), now);
            t.push(span(policy, at, at, at), now);
        }
        let v = t.view(&g, &plan, &[50.0; 3], now);
        let mut buf = Buffer::empty(Rect::new(0, 0, 120, 8));
        render(&v, true, buf.area, &mut buf);
        let text = crate::tui::buffer_text(&buf);
        let row = text.lines().find(|l| l.contains("main#1")).unwrap();
        assert!(row.contains("SP"), "{text}");
        assert_eq!(
            row.matches('S').count(),
            row.matches('P').count(),
            "as many of each: {row}"
        );
        // Nothing heard of under the virtual clock: why.
        let empty = Timeline::default().view(&g, &plan, &[50.0; 3], now);
        let mut buf = Buffer::empty(Rect::new(0, 0, 60, 8));
        render(&empty, true, buf.area, &mut buf);
        let text = crate::tui::buffer_text(&buf);
        assert!(text.contains("compute_ms"), "{text}");
    }
}
