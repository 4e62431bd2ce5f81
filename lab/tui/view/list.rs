//! The graph panel zoomed out ([`Zoom::Names`]: a row per node and per topic in the
//! layered columns) and as a list ([`Zoom::List`]: the nodes, then the topics, a row each
//! with its figures), for graphs too large for boxes; and the line that counts what a
//! scrolled window leaves out.

use super::graph::{alarm, layout_columns, Column};
use super::*;
use crate::tui::zoom::window_start;

/// What a scrolled column or list leaves out, in `w` columns: `above` rows above it and
/// `below` under it (`+47 more ↓`, `↑ 12 more`, `↑12 ↓35 more`; narrower, `+47↓`, `↑12↓35`).
pub(super) fn more_line(above: usize, below: usize, w: usize) -> String {
    let forms = match (above, below) {
        (0, b) => [
            format!("+{b} more ↓"),
            format!("+{b} more"),
            format!("+{b}↓"),
        ],
        (a, 0) => [format!("↑ {a} more"), format!("↑{a} more"), format!("↑{a}")],
        (a, b) => [
            format!("↑{a} ↓{b} more"),
            format!("↑{a} ↓{b}"),
            format!("↑{a}↓{b}"),
        ],
    };
    first_that_fits(forms, w)
}

/// A node's rate in a few characters (`200 Hz`, `199.8 meas`, `50 Hz sent`).
fn node_rate(n: &NodeView, room: usize) -> String {
    let set = hz(n.set_hz);
    match (n.published_hz, n.measured_hz, n.ran) {
        (Some(p), ..) => first_that_fits([format!("{p:.0} Hz sent"), format!("{p:.0}")], room),
        (None, Some(m), _) => first_that_fits(
            [
                format!("{set} Hz · {m:.1} meas"),
                format!("{m:.1} meas"),
                format!("{m:.0}"),
            ],
            room,
        ),
        (None, None, Some((r, skipped))) if skipped > 0 => first_that_fits(
            [
                format!("{set} Hz · {r:.1} ran · {skipped} skip"),
                format!("{r:.0} Hz·{skipped} skip"),
                format!("{skipped} skip"),
            ],
            room,
        ),
        _ => first_that_fits([format!("{set} Hz"), set], room),
    }
}

/// What is wrong with a node, in a word or two (`NOT ALIVE`, `in callback 3.2 s`).
fn node_trouble(n: &NodeView) -> Option<String> {
    alarm(n).map(str::to_string).or_else(|| {
        n.held
            .map(|(held_in, s)| format!("{} {s:.1} s", held_in.words()))
    })
}

/// What is wrong with a topic, in a few words (`3 drop`, `41 lost ✗`, `incompatible QoS`).
fn topic_trouble(t: &TopicView) -> Option<String> {
    let mut parts = Vec::new();
    if !t.incompatible.is_empty() {
        parts.push("incompatible QoS".to_string());
    }
    if t.dropping {
        parts.push(format!("{} drop", t.dropped));
    }
    if t.staling {
        parts.push(format!("{}↺", t.stale_reads));
    }
    for (label, count) in &t.qos_counts {
        if *count > 0 && matches!(*label, "lost" | "missed") {
            parts.push(format!("{count} {label}"));
        }
    }
    if t.unhealthy && parts.is_empty() {
        parts.push("✗".to_string());
    }
    (!parts.is_empty()).then(|| parts.join(" "))
}

/// The style of a row: the selection's black on yellow, trouble in red, else plain.
fn row_style(selected: bool, trouble: bool) -> Style {
    match (selected, trouble) {
        (true, _) => Style::new().black().on_yellow().bold(),
        (false, true) => Style::new().red().bold(),
        _ => Style::new(),
    }
}

/// What the graph panel says when its filter shows nothing.
pub(super) fn render_nothing_shown(v: &View, area: Rect, buf: &mut Buffer) {
    let what = match &v.nav.filter {
        Some(f) => format!("nothing matches {f} (Esc clears the filter)"),
        None => "no nodes".to_string(),
    };
    Paragraph::new(Line::from(what).dim())
        .alignment(Alignment::Center)
        .render(area, buf);
}

/// A row of the names zoom: a node, or a topic it publishes (under it).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) enum NameRow {
    Node(usize),
    Topic(usize),
}

/// The names zoom's columns, one per layer (sensors on the left): each shown node, and
/// under it the shown topics it publishes; a shown topic whose publisher the filter hides
/// goes at the end of its publisher's layer. One pass over the nodes and one over the
/// topics.
pub(super) fn name_columns(v: &View) -> Vec<Vec<NameRow>> {
    let layers = v.nodes.iter().map(|n| n.layer).max().map_or(0, |l| l + 1);
    let mut published: Vec<Vec<usize>> = vec![Vec::new(); v.nodes.len()];
    let mut orphans: Vec<Vec<usize>> = vec![Vec::new(); layers];
    for (i, t) in v.topics.iter().enumerate() {
        match v.nodes.get(t.publisher) {
            Some(p) if t.shown && p.shown => published[t.publisher].push(i),
            Some(p) if t.shown => orphans[p.layer].push(i),
            _ => {}
        }
    }
    let mut cols: Vec<Vec<NameRow>> = vec![Vec::new(); layers];
    for (i, n) in v.nodes.iter().enumerate() {
        if n.shown {
            cols[n.layer].push(NameRow::Node(i));
            cols[n.layer].extend(published[i].iter().map(|&t| NameRow::Topic(t)));
        }
    }
    for (col, o) in cols.iter_mut().zip(orphans) {
        col.extend(o.into_iter().map(NameRow::Topic));
    }
    cols.retain(|c| !c.is_empty());
    cols
}

/// The names zoom: a column per layer, a row per node (`sensor_3 10 Hz`) and under it a row
/// per topic it publishes (` ▶ /c_3/pos 10/s`), trouble in red and the selection in
/// yellow; each column scrolled (and moved to the selection), counting what it leaves out.
pub(super) fn render_names(v: &View, area: Rect, buf: &mut Buffer) {
    let cols = name_columns(v);
    if cols.is_empty() {
        render_nothing_shown(v, area, buf);
        return;
    }
    let n = cols.len() as u32;
    let areas = Layout::horizontal((0..n).map(|_| Constraint::Ratio(1, n))).split(area);
    for (col, rect) in cols.iter().zip(areas.iter()) {
        let w = usize::from(rect.width.saturating_sub(1));
        let fit = usize::from(rect.height).max(1);
        let selected = col.iter().position(|r| match *r {
            NameRow::Node(i) => v.nodes[i].selected,
            NameRow::Topic(i) => v.topics[i].selected,
        });
        let (start, body) = if col.len() > fit {
            let body = fit - 1;
            v.nav.reach.note(col.len(), body);
            (window_start(col.len(), body, v.nav.scroll, selected), body)
        } else {
            (0, col.len())
        };
        let mut lines: Vec<Line> = col[start..start + body]
            .iter()
            .map(|r| match *r {
                NameRow::Node(i) => {
                    let n = &v.nodes[i];
                    let figure = node_trouble(n).unwrap_or_else(|| node_rate(n, w / 2));
                    let name_w = w.saturating_sub(figure.chars().count() + 1).max(w / 2);
                    let text = format!("{} {figure}", cut(&n.name, name_w));
                    Line::from(cut(&text, w)).style(row_style(n.selected, n.in_trouble()))
                }
                NameRow::Topic(i) => {
                    let t = &v.topics[i];
                    let figure = topic_trouble(t).unwrap_or_else(|| t.per_s(0));
                    let name_w = w.saturating_sub(figure.chars().count() + 4).max(w / 2);
                    let text = format!(" ▶ {} {figure}", cut(&t.name, name_w));
                    Line::from(cut(&text, w)).style(row_style(t.selected, t.in_trouble()))
                }
            })
            .collect();
        if col.len() > fit {
            lines.push(Line::from(more_line(start, col.len() - start - body, w)).dim());
        }
        Paragraph::new(lines).render(*rect, buf);
    }
}

/// The rows of the list: a heading, then a row per shown node (sensors first, as the layers
/// go), then a heading and a row per shown topic, each with its style and whether it is
/// the selection.
fn list_rows(v: &View, w: usize) -> Vec<(String, Style, bool)> {
    let cols = layout_columns(v);
    let nodes: Vec<usize> = cols
        .iter()
        .filter(|c| matches!(c, Column::Nodes(_)))
        .flat_map(|c| c.items().iter().copied())
        .collect();
    let topics: Vec<usize> = cols
        .iter()
        .filter(|c| matches!(c, Column::Topics(_)))
        .flat_map(|c| c.items().iter().copied())
        .collect();
    let name_w = nodes
        .iter()
        .map(|&i| v.nodes[i].name.chars().count())
        .chain(topics.iter().map(|&i| v.topics[i].name.chars().count()))
        .max()
        .unwrap_or(0)
        // As wide as the headings (`TOPICS 199`), as a long name at most.
        .clamp(10, 24);
    let heading = Style::new().bold().underlined();
    let mut rows = vec![(
        format!(
            "{:<name_w$} {}",
            format!("NODES {}", nodes.len()),
            "RATE · TROUBLE"
        ),
        heading,
        false,
    )];
    for &i in &nodes {
        let n = &v.nodes[i];
        let name = match &n.process {
            Some(p) => format!("{}@{p}", n.name),
            None => n.name.clone(),
        };
        let rate = node_rate(n, 40);
        let text = match node_trouble(n) {
            Some(t) => format!("{:<name_w$} {rate} · ✗ {t}", cut(&name, name_w)),
            None => format!("{:<name_w$} {rate}", cut(&name, name_w)),
        };
        let style = row_style(n.selected, n.in_trouble());
        rows.push((cut(&text, w), style, n.selected));
    }
    rows.push((
        format!(
            "{:<name_w$} {}",
            format!("TOPICS {}", topics.len()),
            "PUBLISHER→SUBSCRIBERS MSG/S DEPTH · TROUBLE"
        ),
        heading,
        false,
    ));
    for &i in &topics {
        let t = &v.topics[i];
        let to = match (&t.fan_out, t.subscriber) {
            (Some(all), _) => all.clone(),
            (None, Some(s)) => v.nodes.get(s).map_or(String::new(), |n| n.name.clone()),
            (None, None) => "nobody".to_string(),
        };
        let from = v.nodes.get(t.publisher).map_or("", |n| n.name.as_str());
        let mut text = format!(
            "{:<name_w$} {from}→{to} {} depth {}",
            cut(&t.name, name_w),
            t.per_s(1),
            t.depth
        );
        if let Some(trouble) = topic_trouble(t) {
            text.push_str(&format!(" · {trouble}"));
        }
        let style = row_style(t.selected, t.in_trouble());
        rows.push((cut(&text, w), style, t.selected));
    }
    rows
}

/// The list zoom: a heading and the nodes, then a heading and the topics, a row each with
/// its figures, scrolled as one list (and moved to the selection).
pub(super) fn render_list(v: &View, area: Rect, buf: &mut Buffer) {
    let room = usize::from(area.width.saturating_sub(2));
    let title = match &v.nav.filter {
        Some(f) => format!(" graph as a list · {f} · z boxes "),
        None => " graph as a list · ↑↓ scroll · / filter · z boxes ".to_string(),
    };
    // The selection names itself and its keys, as over the boxes.
    let block = match selection_title(v, room) {
        Some(t) => Block::bordered().title(Line::from(t).black().on_yellow().bold()),
        None => Block::bordered().title(Line::from(first_that_fits(
            [title, " list · z ".to_string()],
            room,
        ))),
    };
    let inner = block.inner(area);
    block.render(area, buf);
    let w = usize::from(inner.width);
    let rows = list_rows(v, w);
    let fit = usize::from(inner.height).max(1);
    let (start, body) = if rows.len() > fit {
        let keep = rows.iter().position(|r| r.2);
        let body = fit - 1;
        v.nav.reach.note(rows.len(), body);
        (window_start(rows.len(), body, v.nav.scroll, keep), body)
    } else {
        (0, rows.len())
    };
    let mut lines: Vec<Line> = rows[start..start + body]
        .iter()
        .map(|(text, style, _)| Line::from(text.clone()).style(*style))
        .collect();
    if rows.len() > fit {
        lines.push(Line::from(more_line(start, rows.len() - start - body, w)).dim());
    }
    Paragraph::new(lines).render(inner, buf);
}
