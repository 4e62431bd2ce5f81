//! The graph panel: the nodes as boxes in columns by layer (name, kind, rate, ticks and
//! what is wrong with them), the topics as arrows between them (name, type, QoS, msg/s,
//! drops), and how tall the panel is at a terminal's size.

use super::*;

/// The graph panel's title in `room` columns: its columns joined by arrows (what shares a
/// column, by commas); where that does not fit (a wide graph at 80 columns), its nodes'
/// columns alone, then its counts.
fn graph_title(v: &View, room: usize, hidden: bool) -> String {
    if let Some(f) = &v.nav.filter {
        let (n, t) = (
            v.nodes.iter().filter(|n| n.shown).count(),
            v.topics.iter().filter(|t| t.shown).count(),
        );
        let (all_n, all_t) = (v.nodes.len(), v.topics.len());
        return first_that_fits(
            [
                format!(" graph {f}: {n} of {all_n} nodes, {t} of {all_t} topics · Esc clears "),
                format!(" {f}: {n}/{all_n} nodes, {t}/{all_t} topics "),
            ],
            room,
        );
    }
    let columns = layout_columns(v);
    let names = |with_topics: bool| -> String {
        columns
            .iter()
            .filter_map(|c| match c {
                Column::Nodes(ns) => Some(
                    ns.iter()
                        .map(|&i| v.nodes[i].name.as_str())
                        .collect::<Vec<_>>()
                        .join(", "),
                ),
                Column::Topics(ts) if with_topics => Some(
                    ts.iter()
                        .map(|&i| v.topics[i].name.as_str())
                        .collect::<Vec<_>>()
                        .join(", "),
                ),
                Column::Topics(_) => None,
            })
            .collect::<Vec<_>>()
            .join(" → ")
    };
    let counts = format!(
        " graph: {} nodes, {} topics ",
        v.nodes.len(),
        v.topics.len()
    );
    // A graph larger than the panel says how to find one's way in it.
    if hidden {
        return first_that_fits(
            [
                format!("{counts}· ↑↓ scroll · z zoom · / filter "),
                format!("{counts}· z zoom · / filter "),
                counts,
            ],
            room,
        );
    }
    first_that_fits(
        [
            format!(" graph: {} ", names(true)),
            format!(" graph: {} ", names(false)),
            counts,
        ],
        room,
    )
}

/// Does the graph panel in `area` leave nodes or topics out (a column longer than it is
/// high)?
fn overflows(v: &View, area: Rect) -> bool {
    let rows = usize::from(area.height.saturating_sub(2) / MIN_ITEM_ROWS);
    match v.nav.zoom {
        Zoom::Names => name_columns(v).iter().any(|c| c.len() > rows),
        _ => layout_columns(v).iter().any(|c| c.items().len() > rows),
    }
}

/// The fewest rows a node's box or a topic's arrow is drawn in (its name's): a column of
/// more than fit (a large graph's) shows the first ones and counts the rest.
const MIN_ITEM_ROWS: u16 = 1;

/// A column of the graph panel: the nodes of one layer, or the topics they publish.
pub(super) enum Column {
    Nodes(Vec<usize>),
    Topics(Vec<usize>),
}

impl Column {
    /// Its nodes' or topics' indices, top to bottom.
    pub(super) fn items(&self) -> &[usize] {
        match self {
            Column::Nodes(x) | Column::Topics(x) => x,
        }
    }

    /// The row of the selected node or topic in it, if it holds it.
    fn selected_row(&self, v: &View) -> Option<usize> {
        match self {
            Column::Nodes(ns) => ns.iter().position(|&i| v.nodes[i].selected),
            Column::Topics(ts) => ts.iter().position(|&i| v.topics[i].selected),
        }
    }
}

/// Left to right: each layer's nodes, then the topics they publish, those the filter shows
/// (in one pass over each: a graph of thousands).
pub(super) fn layout_columns(v: &View) -> Vec<Column> {
    let layers = v.nodes.iter().map(|n| n.layer).max().map_or(0, |l| l + 1);
    let mut nodes: Vec<Vec<usize>> = vec![Vec::new(); layers];
    for (i, n) in v.nodes.iter().enumerate() {
        if n.shown {
            nodes[n.layer].push(i);
        }
    }
    let mut topics: Vec<Vec<usize>> = vec![Vec::new(); layers];
    for (i, t) in v.topics.iter().enumerate() {
        if let (true, Some(p)) = (t.shown, v.nodes.get(t.publisher)) {
            topics[p.layer].push(i);
        }
    }
    let mut cols = Vec::new();
    for (ns, ts) in nodes.into_iter().zip(topics) {
        if !ns.is_empty() {
            cols.push(Column::Nodes(ns));
        }
        if !ts.is_empty() {
            cols.push(Column::Topics(ts));
        }
    }
    cols
}

pub(super) fn render_graph(v: &View, area: Rect, buf: &mut Buffer) {
    // The title's room: the panel's width less its corners.
    let room = usize::from(area.width.saturating_sub(2));
    let mut block = match selection_title(v, room) {
        Some(t) => Block::bordered().title(Line::from(t).black().on_yellow().bold()),
        None => Block::bordered().title(graph_title(v, room, overflows(v, area))),
    };
    // What the brain is, when known: a fall with no drops is then no mystery.
    if let Some(caption) = &v.brain_caption {
        block = block.title_bottom(Line::from(format!(" brain: {caption} ")).dim());
    }
    let inner = block.inner(area);
    block.render(area, buf);
    if v.nav.zoom == Zoom::Names {
        render_names(v, inner, buf);
        return;
    }
    let mut cols = layout_columns(v);
    if cols.is_empty() {
        render_nothing_shown(v, inner, buf);
        return;
    }
    let n = cols.len().max(1) as u32;
    let areas = Layout::horizontal((0..n).map(|_| Constraint::Ratio(1, n))).split(inner);
    for (col, rect) in cols.iter_mut().zip(areas.iter()) {
        // A column of more than fit (a large graph): the window scrolled to (and moved to
        // the selection), and a line that counts the rest.
        let fit = usize::from(rect.height / MIN_ITEM_ROWS).max(1);
        let len = col.items().len();
        let (above, below) = if len > fit {
            let rows = fit - 1;
            let start = window_start(len, rows, v.nav.scroll, col.selected_row(v));
            v.nav.reach.note(len, rows);
            match col {
                Column::Nodes(x) | Column::Topics(x) => {
                    x.drain(..start);
                    x.truncate(rows);
                }
            }
            (start, len - start - rows)
        } else {
            (0, 0)
        };
        let rect = &if above + below > 0 {
            let last = Rect {
                y: rect.y + rect.height - 1,
                height: 1,
                ..*rect
            };
            Paragraph::new(Line::from(more_line(above, below, usize::from(rect.width))).dim())
                .render(last, buf);
            Rect {
                height: rect.height - 1,
                ..*rect
            }
        } else {
            *rect
        };
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
pub(super) fn render_node(n: &NodeView, area: Rect, buf: &mut Buffer, real: bool) {
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
    if let Some((held_in, s)) = n.held {
        let words = held_in.words();
        let short = match held_in {
            HeldIn::Callback => "cb",
            HeldIn::Loading => "load",
        };
        lines.push(
            Line::from(fit(vec![
                format!("{words} {s:.1} s"),
                format!("{words} {s:.0}s"),
                format!("{short} {s:.1}s"),
                format!("{short} {s:.0}s"),
            ]))
            .red()
            .bold(),
        );
    }
    if n.held.is_none() {
        lines.extend(rate_figures(n, area.width, real));
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
    // What a tick costs, last: only where the box has a row left for it, and not while an
    // alarm is raised, whose row it gives up (so the box keeps its height: the graph panel
    // does not grow for the half second of a stall, [`node_rows`]).
    if let (Some(t), None) = (n.tick_p50_us, alarm(n)) {
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
    let mut name = node_title(
        &n.name,
        n.process.as_deref(),
        usize::from(area.width.saturating_sub(2)),
    );
    // Only where the name still fits whole (a centred title too long loses both ends).
    if let (Some(b), true) = (n.badge, badge_in_title) {
        let short = b.words().1;
        if name.chars().count() + short.len() < usize::from(area.width.saturating_sub(2)) {
            name.push(' ');
            name.push_str(short);
        }
    }
    // Whatever is still too long (a badge added) is cut at its end, marked.
    let name = cut_with_ellipsis(name, usize::from(area.width.saturating_sub(2)));
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

/// A node box's title in `room` columns: `name@process` (attached to a launch) when it fits,
/// else the name, cut ([`cut_with_ellipsis`]) to no fewer than 7 columns, before a cut
/// `@process` (`estima…_0@c…`), else the name alone, cut (`esti…_0`): the node's own number
/// is kept, never the process's taken for it.
fn node_title(name: &str, process: Option<&str>, room: usize) -> String {
    let Some(p) = process else {
        return cut_with_ellipsis(name.to_string(), room);
    };
    let whole = format!("{name}@{p}");
    if whole.chars().count() <= room {
        return whole;
    }
    // The name in all but three columns (`@c…`), when that leaves it 7 or whole.
    let at = format!("@{p}");
    let name_len = name.chars().count();
    let name_room = room.saturating_sub(3).min(name_len);
    if name_room >= name_len.min(7) {
        let name = cut_with_ellipsis(name.to_string(), name_room);
        let left = room - name.chars().count();
        return format!("{name}{}", cut_with_ellipsis(at, left));
    }
    cut_with_ellipsis(name.to_string(), room)
}

/// `text` whole when it has at most `room` characters; else cut and marked `…`: in the
/// middle when it ends in a number (`esti…_12`: a generated graph's nodes differ there),
/// else at its end (`estim…`). Characters, not display columns: node and process names
/// are ASCII (`valid_node_name`), badges too.
fn cut_with_ellipsis(text: String, room: usize) -> String {
    let chars: Vec<char> = text.chars().collect();
    if chars.len() <= room {
        return text;
    }
    if room == 0 {
        return String::new();
    }
    // The number it ends in, with the `_` before it.
    let digits = chars
        .iter()
        .rev()
        .take_while(|c| c.is_ascii_digit())
        .count();
    let underscore =
        usize::from(digits > 0 && chars.len() > digits && chars[chars.len() - digits - 1] == '_');
    let suffix = digits + underscore;
    // At least two characters of the start before the mark, or the number is not kept.
    let keep_suffix = suffix > 0 && suffix + 3 <= room;
    if !keep_suffix {
        return cut(&text, room);
    }
    let (head, tail) = chars.split_at(chars.len() - suffix);
    head[..room - 1 - suffix]
        .iter()
        .chain(['…'].iter())
        .chain(tail)
        .collect()
}

/// What a node's box says of its rate under the rate it is set to: what it sent, what the
/// real clock measured and how late its ticks were (p99), or under the virtual clock what
/// its timer achieved and skipped (executors). Each in the first of its forms that fits a
/// box `width` wide.
fn rate_figures(n: &NodeView, width: u16, real: bool) -> Vec<Line<'static>> {
    let wide = width >= 14;
    let room = usize::from(width.saturating_sub(2));
    let fit = |forms: Vec<String>| first_that_fits(forms, room);
    let mut lines = Vec::new();
    match (n.published_hz, n.measured_hz, n.lateness_p99_us) {
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
                let text = match (skipped > 0, wide && width >= 22) {
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
            None if real => lines.push(Line::from(MEASURING).dim()),
            None => lines.push(Line::from(if wide { "virtual time" } else { "virtual" }).dim()),
        },
    }
    lines
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

/// An arrow's first line, `w` (+ 1) wide: its name (with its depth when selected) and,
/// with several subscribers, who reads it (`/meas → estimator, compare`), else how many
/// (`/meas → 2 subs`, `/meas →2`), else the name alone.
fn arrow_title(t: &TopicView, w: usize) -> Line<'static> {
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
    match &t.fan_out {
        Some(to) => {
            // The arrow's lines may take the column before the next box (w + 1).
            let room = w.saturating_sub(name.width());
            // Node names hold no ", " (letters, digits, `_` and `-`).
            let n = to.matches(", ").count() + 1;
            let to = first_that_fits(
                [format!("→ {to}"), format!("→ {n} subs"), format!("→{n}")],
                room,
            );
            if to.chars().count() <= room {
                Line::from(vec![name.spans[0].clone(), Span::raw(" "), to.dim()]).centered()
            } else {
                name
            }
        }
        None => name,
    }
}

/// An arrow's lines at width `w`, for a panel `rows` high: name, shaft, msg/s, dropped (and
/// stale reads, and the wire latency across processes). When those do not fit in `rows`
/// (at 80×24), the drops and stale reads share a line (`3 drop ⚠ 126↺`) if it fits `w`, so
/// the wire line still shows; a wire line wider than `w` shows its p50 only. With QoS set:
/// name, shaft, drops, msg/s, the QoS counters, the QoS in short, stale reads, packed to the
/// width, most telling first (a short panel cuts from the end).
pub(super) fn arrow_lines(t: &TopicView, w: usize, rows: usize) -> Vec<Line<'static>> {
    if t.subscriber.is_none() {
        return unsubscribed_arrow(t, w, rows);
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
    let shaft = Line::from(Span::styled(
        format!("{}▶", shaft.repeat(w.saturating_sub(1))),
        style,
    ));
    let rate = arrow_rate(t, w, style);
    let name = arrow_title(t, w);
    if !t.incompatible.is_empty() {
        return incompatible_arrow(t, name, w, rows);
    }
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
    // A cell too short for every line (an arrow of a two-row layout at 80×24): the rate
    // goes on the shaft, so the name, the rate and the drops still show in three rows.
    // (Name, shaft, rate, the drops with any stale reads beside them, the wire line.)
    let plain = t.qos.is_none() && 4 + usize::from(wire.is_some()) > rows;
    let rate_on_shaft = (plain && !t.uncounted && !t.unhealthy)
        .then(|| {
            let bar = if t.dropping { "═" } else { "─" };
            labelled_shaft(bar, "▶", &shaft_rate(t, w)?, w, style, Style::new())
        })
        .flatten();
    let Some(parts) = &t.qos else {
        let mut lines = match rate_on_shaft {
            Some(shaft) => vec![name, shaft],
            None => vec![name, shaft, rate],
        };
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
    let (on_shaft, below) = qos_on_shaft(parts, w);
    let bar = if t.dropping { "═" } else { "─" };
    let shaft = if on_shaft.is_empty() {
        shaft
    } else {
        let dim = Style::new().add_modifier(Modifier::DIM);
        labelled_shaft(bar, "▶", &on_shaft.join(" "), w, style, dim).unwrap_or(shaft)
    };
    let mut lines = vec![name, shaft];
    lines.extend(qos_figures(t, w, rows, &drop_mark, style, [dropped, rate]));
    lines.extend(
        pack(below, " ", w)
            .into_iter()
            .map(|l| Line::from(l).dim().centered()),
    );
    lines.extend(stale);
    lines.extend(wire);
    lines
}

/// A QoS arrow's figures under its shaft: its drops and rate (`drop_rate`, two lines),
/// then its QoS counters. msg/s right after the drops: at 80×24 a panel of five rows still
/// shows it. A cell shorter than its lines (a two-row layout) takes the drops and the rate
/// in one line, so the QoS counters (expired, deadline misses, losses) still show; in three
/// rows or fewer, trouble first: counters that counted before the drops and the rate, which
/// the line under the panel totals too.
fn qos_figures(
    t: &TopicView,
    w: usize,
    rows: usize,
    drop_mark: &str,
    style: Style,
    drop_rate: [Line<'static>; 2],
) -> Vec<Line<'static>> {
    let counters = qos_counters(t, w);
    let one_line = (4 + counters.len() > rows && !t.uncounted)
        .then(|| {
            let rate = t.per_s(0);
            [
                format!("{} drop{drop_mark} {rate}", t.dropped),
                format!("{}{drop_mark} {rate}", t.dropped),
            ]
            .into_iter()
            .find(|l| l.chars().count() <= w + 1)
        })
        .flatten();
    let figures = match one_line {
        Some(l) => vec![Line::from(Span::styled(l, style)).centered()],
        None => drop_rate.to_vec(),
    };
    if rows <= 3 && t.qos_counts.iter().any(|(_, n)| *n > 0) {
        [counters, figures].concat()
    } else {
        [figures, counters].concat()
    }
}

/// A subscription its publisher does not connect (what it requested is not offered,
/// ROS 2's incompatible QoS): a broken red arrow, `incompatible QoS`, then who requested
/// what as far as the rows go, and the publisher's rate (it goes on publishing).
fn incompatible_arrow(
    t: &TopicView,
    name: Line<'static>,
    w: usize,
    rows: usize,
) -> Vec<Line<'static>> {
    let red = Style::new().fg(Color::Red).add_modifier(Modifier::BOLD);
    let run = w.saturating_sub(2);
    let mut lines = vec![
        name,
        Line::from(Span::styled(
            format!("{}✗{}▷", "╌".repeat(run / 2), "╌".repeat(run - run / 2)),
            red,
        )),
        Line::from(Span::styled(
            first_that_fits(
                ["incompatible QoS".to_string(), "incompatible".to_string()],
                w + 1,
            ),
            red,
        ))
        .centered(),
    ];
    // `actuator: requested RELIABLE, offered BEST_EFFORT` where the rows allow, else what
    // the first subscriber wanted (`wants RELIABLE`); the log pane has the whole event.
    let words = t.incompatible.iter().flat_map(|(node, m)| {
        let each: Vec<String> = m.iter().map(ToString::to_string).collect();
        format!("{node}: {}", each.join("; "))
            .split(' ')
            .map(String::from)
            .collect::<Vec<_>>()
    });
    let why = pack(words, " ", w);
    let room = rows.saturating_sub(lines.len() + 1);
    let why = if why.len() <= room {
        why
    } else {
        let wanted = t
            .incompatible
            .first()
            .and_then(|(_, m)| m.first())
            .map_or_else(String::new, |m| m.requested.clone());
        vec![first_that_fits([format!("wants {wanted}"), wanted], w + 1)]
    };
    lines.extend(
        why.into_iter()
            .take(room)
            .map(|l| Line::from(Span::styled(l, Style::new().fg(Color::Red))).centered()),
    );
    lines.push(Line::from(rate_text(t).dim()).centered());
    lines
}

/// Published, read by no node (a diagnostic output): a dashed arrow to nobody, and no drop
/// count (every message it evicts is unread, and no one misses it). In fewer than four
/// rows the rate goes on the arrow.
fn unsubscribed_arrow(t: &TopicView, w: usize, rows: usize) -> Vec<Line<'static>> {
    let grey = Style::new().fg(Color::DarkGray);
    let name = Line::from(t.name.clone().bold()).centered();
    let rate = rate_text(t);
    if rows < 4 {
        let on_shaft =
            shaft_rate(t, w).and_then(|r| labelled_shaft("╌", "▷", &r, w, grey, Style::new()));
        if let Some(shaft) = on_shaft {
            return vec![
                name,
                shaft,
                Line::from(Span::styled("no subscriber", grey)).centered(),
            ];
        }
    }
    vec![
        name,
        Line::from(Span::styled(
            format!("{}▷", "╌".repeat(w.saturating_sub(1))),
            grey,
        )),
        Line::from(rate).centered(),
        Line::from(Span::styled("no subscriber", grey)).centered(),
    ]
}

/// A topic's rate as its arrow gives it: `50.0 msg/s` (or `measuring`).
fn rate_text(t: &TopicView) -> String {
    rate_forms(t)[0].clone()
}

/// A topic's rate, longest form first: `50.0 msg/s`, `50 msg/s`, `50/s` (or `measuring`
/// alone).
fn rate_forms(t: &TopicView) -> Vec<String> {
    if t.measuring {
        return vec![MEASURING.to_string()];
    }
    vec![
        format!("{:.1} msg/s", t.msg_per_s),
        format!("{:.0} msg/s", t.msg_per_s),
        format!("{:.0}/s", t.msg_per_s),
    ]
}

/// The rate in the first form that fits on a shaft `w` wide with a bar either side
/// (`─ 50.0 msg/s ─▶`, `─ 50 msg/s ─▶`, `─ 50/s ─▶`); `None` when none does.
fn shaft_rate(t: &TopicView, w: usize) -> Option<String> {
    rate_forms(t)
        .into_iter()
        .find(|r| r.chars().count() + 5 <= w)
}

/// An arrow's shaft `w` wide with `label` on it (`── dl 40 ms ──▶`, `╌ 50.0 msg/s ╌▷`):
/// `bar`s either side in `style`, the label in `label_style`, then `head`. `None` when
/// the label does not fit.
fn labelled_shaft(
    bar: &str,
    head: &str,
    label: &str,
    w: usize,
    style: Style,
    label_style: Style,
) -> Option<Line<'static>> {
    let run = w.checked_sub(1 + label.chars().count() + 2)?;
    let (left, right) = (run / 2, run - run / 2);
    Some(Line::from(vec![
        Span::styled(format!("{} ", bar.repeat(left)), style),
        Span::styled(label.to_string(), label_style),
        Span::styled(format!(" {}{head}", bar.repeat(right)), style),
    ]))
}

/// A QoS counter that says the topic is unhealthy.
fn faulty(label: &str) -> bool {
    label == "lost" || label == "dl miss"
}

/// The arrow's msg/s line. The ✗ of an unhealthy topic stands by what went wrong, never by
/// a count of 0 drops: by its losses or missed deadlines where its QoS counters show
/// (`53 lost ✗`), else by its rate (a dead node starves it; a default-QoS topic's losses
/// on the wire), in `style`.
fn arrow_rate(t: &TopicView, w: usize, style: Style) -> Line<'static> {
    let fault_counted = t.qos.is_some()
        && t.qos_counts
            .iter()
            .any(|(label, n)| *n > 0 && faulty(label));
    let fault_on_rate = t.unhealthy && !t.dropping && !fault_counted;
    if t.uncounted {
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
    } else if t.measuring {
        Line::from(MEASURING.dim()).centered()
    } else {
        Line::from(format!("{:.1} msg/s", t.msg_per_s)).centered()
    }
}

/// The QoS parts that go on the shaft itself (`── dl 40 ms stop ──▶`), as many as fit in
/// `w`, most telling first, and those that go below it. At 80×24 the panel's rows are the
/// drops', the rate's and the counters'. On a shaft too short for all, the chapter's
/// keep-last/latest rule gives way first (the depth shows in the header and on the
/// selected arrow).
fn qos_on_shaft(parts: &[String], w: usize) -> (Vec<String>, Vec<String>) {
    let room = w.saturating_sub(3); // the head and a space either side
    let all = parts.join(" ");
    if all.chars().count() <= room {
        return (parts.to_vec(), Vec::new());
    }
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
}

/// The topic's QoS counters under its arrow, packed into lines of `w`: those that counted
/// first (a short panel cuts from the end: at 80×24 "41 lost" must not give way to
/// "0 expired"), the unhealthy topic's ✗ by the first of its losses or missed deadlines
/// that counted.
fn qos_counters(t: &TopicView, w: usize) -> Vec<Line<'static>> {
    let counting = t.qos_counts.iter().any(|(_, n)| *n > 0);
    let mut counted: Vec<&(&'static str, u64)> = t.qos_counts.iter().collect();
    counted.sort_by_key(|(_, n)| *n == 0);
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
    counts
        .into_iter()
        .map(|l| Line::from(Span::styled(l, style)).centered())
        .collect()
}

fn render_arrow(t: &TopicView, area: Rect, buf: &mut Buffer) {
    let w = area.width.saturating_sub(1) as usize;
    Paragraph::new(arrow_lines(t, w, usize::from(area.height))).render(area, buf);
}

/// What a node's box raises in red: its lease ran out (`NOT ALIVE`), or, until then, the
/// fault injected into it (`STALLED`, `KILLED`).
pub(super) fn alarm(n: &NodeView) -> Option<&'static str> {
    if n.alive == Some(false) {
        Some("NOT ALIVE")
    } else {
        n.fault
    }
}

/// The rows a node's box would fill inside its border: its rate, what it measured (or ran,
/// or sent), its compute time, badge, and its tick time or, in its place, its alarm
/// ([`alarm`]: a node that has a tick time keeps its height when one is raised).
pub(super) fn node_rows(n: &NodeView) -> usize {
    let status = match (n.published_hz, n.measured_hz, n.lateness_p99_us) {
        (None, Some(_), Some(_)) => 2,
        _ => 1,
    };
    1 + status
        + usize::from(n.compute.is_some())
        + usize::from(n.badge.is_some())
        + usize::from(n.tick_p50_us.is_some() || alarm(n).is_some())
}

/// The graph panel's height: 7 rows, more when an arrow's QoS lines or a column of node
/// boxes need them and the terminal is tall enough (30 rows) to spare them, within `max`.
pub(super) fn graph_height(v: &View, width: u16, height: u16, max: u16) -> u16 {
    if height < 30 {
        return 7;
    }
    let cols = layout_columns(v);
    let n = cols.len().max(1) as u16;
    let w = (width.saturating_sub(2) / n).saturating_sub(1) as usize;
    // A column's rows, counted only as far as the panel could grow (a large graph's).
    let limit = usize::from(max);
    let rows = |each: &mut dyn FnMut(usize) -> usize, items: &[usize]| {
        let mut sum = 0;
        for &i in items {
            sum += each(i);
            if sum > limit {
                break;
            }
        }
        sum
    };
    let tallest = cols
        .iter()
        .map(|c| match (v.nav.zoom, c) {
            (Zoom::Names, _) => name_columns(v)
                .iter()
                .map(Vec::len)
                .max()
                .unwrap_or(0)
                .min(limit + 1),
            (Zoom::List, c) => c.items().len().min(limit + 1),
            (Zoom::Boxes, Column::Topics(ts)) => {
                rows(&mut |i| arrow_lines(&v.topics[i], w, usize::MAX).len(), ts)
            }
            (Zoom::Boxes, Column::Nodes(ns)) => rows(&mut |i| node_rows(&v.nodes[i]) + 2, ns),
        })
        .max()
        .unwrap_or(0)
        .min(usize::from(u16::MAX - 2)) as u16;
    (tallest + 2).clamp(7, max.max(7))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn texts(lines: &[Line<'_>]) -> Vec<String> {
        lines.iter().map(ToString::to_string).collect()
    }

    fn topic(qos: Option<Vec<String>>, counts: Vec<(&'static str, u64)>) -> TopicView {
        TopicView {
            name: "/reference".into(),
            subscriber: Some(1),
            depth: 1,
            msg_per_s: 50.0,
            qos,
            qos_counts: counts,
            ..TopicView::default()
        }
    }

    #[test]
    fn a_fanned_out_topic_names_its_subscribers_or_counts_them_as_room_allows() {
        let t = TopicView {
            name: "/meas".into(),
            fan_out: Some("estimator, compare".into()),
            ..topic(None, Vec::new())
        };
        let first = |w: usize| texts(&arrow_lines(&t, w, 3))[0].trim().to_string();
        assert_eq!(first(40), "/meas → estimator, compare");
        assert_eq!(first(14), "/meas → 2 subs");
        // Exactly as wide as the cell (w + 1 columns).
        assert_eq!(first(13), "/meas → 2 subs");
        assert_eq!(first(12), "/meas →2");
        // At 80 columns with 9 columns of boxes and arrows (an arrow 9 wide).
        assert_eq!(first(8), "/meas →2");
        assert_eq!(first(5), "/meas");
    }

    /// Under the real clock a node's box ends with its tick time; a stall raised on it takes
    /// that row, so the box (and the graph panel sized from it) keeps its height: a user saw
    /// the whole screen below the graph jump a row for the stall's half second.
    #[test]
    fn an_alarm_takes_the_tick_time_s_row_and_the_box_keeps_its_height() {
        let ticking = NodeView {
            name: "policy".into(),
            set_hz: 50.0,
            measured_hz: Some(50.0),
            lateness_p99_us: Some(51.0),
            tick_p50_us: Some(11.0),
            ..NodeView::default()
        };
        let stalled = NodeView {
            fault: Some("STALLED"),
            ..ticking.clone()
        };
        assert_eq!(node_rows(&ticking), node_rows(&stalled));
        let area = Rect::new(0, 0, 24, 2 + node_rows(&ticking) as u16);
        let drawn = |n: &NodeView| {
            let mut buf = Buffer::empty(area);
            render_node(n, area, &mut buf, true);
            crate::tui::buffer_text(&buf)
        };
        let (before, during) = (drawn(&ticking), drawn(&stalled));
        assert!(before.contains("tick p50 11 µs"), "{before}");
        assert!(during.contains("✗ STALLED"), "{during}");
        assert!(!during.contains("tick p50"), "{during}");
        // Every row of the box as before is still there, but the tick time's.
        for row in ["50 Hz set", "50.0 Hz meas", "p99 51 µs late"] {
            assert!(during.contains(row), "{row}: {during}");
        }
        // A node without a tick time (the virtual clock) gains the alarm's row.
        let plain = NodeView {
            tick_p50_us: None,
            ..ticking.clone()
        };
        let plain_stalled = NodeView {
            fault: Some("STALLED"),
            ..plain.clone()
        };
        assert_eq!(node_rows(&plain_stalled), node_rows(&plain) + 1);
    }

    #[test]
    fn a_name_longer_than_its_box_is_cut_at_its_end_and_marked() {
        assert_eq!(cut_with_ellipsis("policy".into(), 6), "policy");
        assert_eq!(cut_with_ellipsis("estimator".into(), 6), "estim…");
        // A number at the end is what tells a generated graph's nodes apart: kept.
        assert_eq!(cut_with_ellipsis("estimator_12".into(), 8), "esti…_12");
        assert_eq!(cut_with_ellipsis("safety_0".into(), 7), "safe…_0");
        assert_eq!(cut_with_ellipsis("node1234".into(), 7), "no…1234");
        // Too little room for the number and a start: cut at the end.
        assert_eq!(cut_with_ellipsis("estimator_12".into(), 5), "esti…");
        assert_eq!(cut_with_ellipsis("_1234".into(), 4), "_12…");
        assert_eq!(cut_with_ellipsis("θ̂ node".into(), 3), "θ\u{302}…");
        assert_eq!(cut_with_ellipsis("x".into(), 0), "");
        // Attached to a launch: the node's number, not the process's.
        assert_eq!(
            node_title("estimator_0", Some("ctl_3"), 30),
            "estimator_0@ctl_3"
        );
        assert_eq!(node_title("estimator_0", Some("ctl_3"), 12), "estima…_0@c…");
        assert_eq!(node_title("policy", Some("ctl_3"), 10), "policy@ct…");
        assert_eq!(node_title("estimator_0", Some("ctl_3"), 7), "esti…_0");
        assert_eq!(node_title("estimator_0", None, 7), "esti…_0");
    }

    /// An arrow in a cell of two or three rows (a two-row layout at 80×24) keeps its rate
    /// on the shaft, and its QoS counters before its drops when they counted; in a cell
    /// with room, the lines are as they were.
    #[test]
    fn a_short_arrow_keeps_its_rate_and_its_trouble() {
        let plain = topic(None, Vec::new());
        assert_eq!(
            texts(&arrow_lines(&plain, 14, 3)),
            ["/reference", "─ 50 msg/s ──▶", "0 dropped ✓"]
        );
        assert_eq!(texts(&arrow_lines(&plain, 15, 2))[1], "─ 50.0 msg/s ─▶");
        assert_eq!(
            texts(&arrow_lines(&plain, 14, 5)),
            ["/reference", "─────────────▶", "50.0 msg/s", "0 dropped ✓"]
        );
        let late = topic(
            Some(vec!["dl 30 ms".into()]),
            vec![("dl miss", 17), ("expired", 3)],
        );
        let short = texts(&arrow_lines(&late, 14, 3));
        assert_eq!(short[2], "17 dl miss", "{short:?}");
        assert_eq!(short[3], "3 expired", "{short:?}");
        let tall = texts(&arrow_lines(&late, 14, 6));
        assert_eq!(tall[2..4], ["0 dropped ✓", "50.0 msg/s"], "{tall:?}");
        let mut idle = topic(None, Vec::new());
        idle.subscriber = None;
        assert_eq!(
            texts(&arrow_lines(&idle, 14, 3)),
            ["/reference", "╌ 50 msg/s ╌╌▷", "no subscriber"]
        );
    }
}
