//! The log pane (key `v`): what nodes' code wrote and ratelab's warnings, one entry a line
//! of the run's text log, newest last, each wrapped at the pane's width (never cut), a
//! callback's failure with the learner's frames under it; and the selected entry shown
//! whole over the lab (Enter), a failure with its whole traceback.

use ratatui::buffer::Buffer;
use ratatui::layout::Rect;
use ratatui::style::Stylize;
use ratatui::text::Line;
use ratatui::widgets::{Block, Clear, Paragraph, Widget};

/// One entry of the log pane: a line a node's code wrote or ratelab's, or a callback's
/// failure with its frames and traceback.
#[derive(Clone, Debug, PartialEq, Default)]
pub struct LogEntry {
    /// A warning or an error (drawn yellow).
    pub warn: bool,
    /// Its stamp and who wrote it, `t=1.23  policy    ` (as wide for every entry of a run
    /// under 100 s).
    pub stamp: String,
    /// Its text, whole (the paths in it relative to the graph file's folder).
    pub text: String,
    /// A failure's learner's frames, outermost first: `nodes/policy.py:12 in on_timer: x =
    /// 1 / 0`.
    pub frames: Vec<String>,
    /// A failure's whole traceback, line by line (shown when the entry is opened).
    pub traceback: Vec<String>,
}

/// The entry shown whole over the lab (Enter), and how many of its rows are scrolled past.
#[derive(Clone, Debug, PartialEq, Default)]
pub struct OpenEntry {
    /// The entry.
    pub entry: LogEntry,
    /// Rows scrolled past (PgDn), at most to its last row.
    pub scroll: usize,
}

/// The log pane: what nodes' code wrote and ratelab's warnings, newest last.
#[derive(Clone, Debug, PartialEq, Default)]
pub struct LogView {
    /// Whose lines: `all nodes`, or the selected node's name.
    pub whose: String,
    /// How many lines the lab holds of it in all.
    pub total: usize,
    /// The entries up to the selected one, its last (the newest that the pane can show).
    pub entries: Vec<LogEntry>,
    /// The selected entry is this many back from the newest (PgUp / PgDn).
    pub back: usize,
    /// The entry shown whole over the lab, if one is (Enter).
    pub open: Option<OpenEntry>,
}

/// `text` wrapped into rows of `width` columns at its spaces (a word longer than a row is
/// broken where the row ends), every row after the first starting with `indent` spaces (none
/// where that would leave a row less than half of `width`). Its own leading spaces stay.
pub fn wrap(text: &str, width: usize, indent: usize) -> Vec<String> {
    let width = width.max(1);
    let indent = if indent * 2 > width { 0 } else { indent };
    let chars: Vec<char> = text.trim_end().chars().collect();
    let mut rows = Vec::new();
    let mut at = 0;
    loop {
        let lead = if rows.is_empty() { 0 } else { indent };
        let room = width - lead;
        let pad = " ".repeat(lead);
        if chars.len() - at <= room {
            rows.push(format!("{pad}{}", chars[at..].iter().collect::<String>()));
            return rows;
        }
        // The row ends at its last space (one right after it too), else where it is full.
        let end = (at + 1..=at + room)
            .rev()
            .find(|&i| chars[i] == ' ')
            .unwrap_or(at + room);
        let row: String = chars[at..end].iter().collect();
        rows.push(format!("{pad}{}", row.trim_end()));
        at = end;
        while chars.get(at) == Some(&' ') {
            at += 1;
        }
        if at == chars.len() {
            return rows;
        }
    }
}

/// `e`'s rows at `width` columns: its stamp and text wrapped (the rows after the first under
/// its text), then its frames (`↳ nodes/policy.py:12 in on_timer: …`) likewise; `whole`:
/// then a blank row and its whole traceback.
pub fn entry_rows(e: &LogEntry, width: usize, whole: bool) -> Vec<String> {
    let indent = e.stamp.chars().count();
    let mut rows = wrap(&format!("{}{}", e.stamp, e.text), width, indent);
    let under = " ".repeat(indent);
    for f in &e.frames {
        rows.extend(wrap(&format!("{under}↳ {f}"), width, indent + 2));
    }
    if whole && !e.traceback.is_empty() {
        rows.push(String::new());
        for line in &e.traceback {
            rows.extend(wrap(line, width, 6));
        }
    }
    rows
}

/// The pane's rows at `width` columns, `rows` of them at most, the selected entry (the last
/// of `entries`) at the bottom and those before it above, each with whether it is the
/// selected entry's and a warning's. A selected entry taller than the pane shows its first
/// rows and `… ↵ shows it whole`.
fn pane_rows(l: &LogView, width: usize, rows: usize) -> Vec<(String, bool, bool)> {
    let Some((selected, before)) = l.entries.split_last() else {
        return Vec::new();
    };
    let mine = entry_rows(selected, width, false);
    if mine.len() > rows {
        let mut shown: Vec<(String, bool, bool)> = mine
            .into_iter()
            .take(rows.saturating_sub(1))
            .map(|r| (r, true, selected.warn))
            .collect();
        shown.push(("  … ↵ shows it whole".to_string(), true, false));
        return shown;
    }
    let mut shown: Vec<(String, bool, bool)> =
        mine.into_iter().map(|r| (r, true, selected.warn)).collect();
    for e in before.iter().rev() {
        if shown.len() >= rows {
            break;
        }
        let theirs = entry_rows(e, width, false);
        let room = rows - shown.len();
        let from = theirs.len().saturating_sub(room);
        let mut above: Vec<(String, bool, bool)> = theirs[from..]
            .iter()
            .map(|r| (r.clone(), false, e.warn))
            .collect();
        above.append(&mut shown);
        shown = above;
    }
    shown
}

/// `1 line`, `40 lines`: the pane's count of entries as its title says it.
fn lines(n: usize) -> String {
    ratelab::metrics::counted(n as u64, "line")
}

/// The log pane in `area`: its entries wrapped, the selected one at the bottom (bold while
/// scrolled back), and in its title what the keys do.
pub fn render_log(l: &LogView, area: Rect, buf: &mut Buffer) {
    let whole = if l.entries.last().is_some_and(|e| !e.traceback.is_empty()) {
        " · ↵ traceback"
    } else {
        ""
    };
    let title = if l.back > 0 {
        format!(
            " log: {} ({}, {} back) · PgDn newer{whole} · v hides ",
            l.whose,
            lines(l.total),
            l.back
        )
    } else {
        format!(" log: {} ({}){whole} · v hides ", l.whose, lines(l.total))
    };
    let block = Block::bordered().title(title);
    let inner = block.inner(area);
    block.render(area, buf);
    let rows = usize::from(inner.height);
    let width = usize::from(inner.width);
    let shown: Vec<Line> = if l.entries.is_empty() {
        vec![Line::from("nothing written yet (print, get_logger, warnings)").dim()]
    } else {
        pane_rows(l, width, rows)
            .into_iter()
            .map(|(text, selected, warn)| {
                let line = Line::from(text);
                let line = if warn { line.yellow() } else { line };
                if selected && l.back > 0 {
                    line.bold()
                } else {
                    line
                }
            })
            .collect()
    };
    Paragraph::new(shown).render(inner, buf);
}

/// The entry opened (Enter) over the lab in `area`: whole, its text, frames and traceback
/// wrapped to the box, scrolled by its rows (PgUp / PgDn).
pub fn render_entry(open: &OpenEntry, area: Rect, buf: &mut Buffer) {
    let w = 100.min(area.width);
    let width = usize::from(w.saturating_sub(2));
    let rows = entry_rows(&open.entry, width, true);
    let tall = u16::try_from(rows.len())
        .unwrap_or(u16::MAX)
        .saturating_add(2);
    let h = tall.min(area.height.saturating_sub(2)).max(3);
    let room = usize::from(h - 2);
    let scroll = open.scroll.min(rows.len().saturating_sub(room));
    let title = if rows.len() > room {
        format!(
            " log entry, rows {}–{} of {} · PgUp PgDn · ↵ or Esc closes ",
            scroll + 1,
            (scroll + room).min(rows.len()),
            rows.len()
        )
    } else {
        " log entry · ↵ or Esc closes ".to_string()
    };
    let popup = Rect {
        x: area.x + (area.width - w) / 2,
        y: area.y + area.height.saturating_sub(h) / 2,
        width: w,
        height: h,
    };
    Clear.render(popup, buf);
    let lines: Vec<Line> = rows
        .into_iter()
        .skip(scroll)
        .take(room)
        .map(Line::from)
        .collect();
    let lines: Vec<Line> = if open.entry.warn {
        lines.into_iter().map(|l| l.yellow()).collect()
    } else {
        lines
    };
    Paragraph::new(lines)
        .block(Block::bordered().title(title))
        .render(popup, buf);
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn long_lines_wrap_at_spaces_under_their_text() {
        assert_eq!(wrap("abc def ghi", 7, 2), ["abc def", "  ghi"]);
        assert_eq!(wrap("abcdefghij", 4, 0), ["abcd", "efgh", "ij"]);
        // A word longer than a row is broken where the row ends.
        assert_eq!(wrap("ab cdefghij", 5, 1), ["ab", " cdef", " ghij"]);
        assert_eq!(wrap("", 10, 2), [""]);
        assert_eq!(wrap("fits as it is", 13, 4), ["fits as it is"]);
        // Its own leading spaces stay; an indent of more than half a row is dropped.
        assert_eq!(wrap("  File x", 80, 6), ["  File x"]);
        assert_eq!(wrap("aaaa bbbb", 6, 4), ["aaaa", "bbbb"]);
        // Nothing is lost: every character but the spaces a row ends at is shown.
        let text = "reloaded nodes/policy.py: balanced (5.5 s) → balanced (10.0 s) · over the first 5.50 s of each: latency p50 40 → 40 ms";
        let rows = wrap(text, 30, 0);
        assert!(rows.iter().all(|r| r.chars().count() <= 30), "{rows:?}");
        assert_eq!(rows.join(" "), text);
    }

    fn failure() -> LogEntry {
        LogEntry {
            warn: true,
            stamp: "t=1.20  policy    ".into(),
            text: "nodes/policy.py:12: ZeroDivisionError: division by zero".into(),
            frames: vec![
                "nodes/policy.py:9 in on_timer: u = self.gain(s)".into(),
                "nodes/policy.py:12 in gain: return 1 / 0".into(),
            ],
            traceback: vec![
                "Traceback (most recent call last):".into(),
                "  File \"nodes/policy.py\", line 12, in gain".into(),
                "    return 1 / 0".into(),
                "ZeroDivisionError: division by zero".into(),
            ],
        }
    }

    /// A failure reads whole: its message wrapped under its stamp, its frames under it; its
    /// traceback only opened.
    #[test]
    fn a_failure_shows_its_message_and_frames_and_opened_its_traceback() {
        let rows = entry_rows(&failure(), 60, false);
        assert_eq!(
            rows,
            [
                "t=1.20  policy    nodes/policy.py:12: ZeroDivisionError:",
                "                  division by zero",
                "                  ↳ nodes/policy.py:9 in on_timer: u =",
                "                    self.gain(s)",
                "                  ↳ nodes/policy.py:12 in gain: return 1 / 0",
            ]
        );
        let whole = entry_rows(&failure(), 78, true);
        assert_eq!(whole.len(), 3 + 1 + 4, "{whole:#?}");
        assert_eq!(whole[4], "Traceback (most recent call last):");
        assert_eq!(whole[7], "ZeroDivisionError: division by zero");
    }

    /// The pane shows the selected entry at its bottom and what fits of those before it; a
    /// selected entry taller than the pane, its first rows and how to see it whole.
    #[test]
    fn the_pane_fills_up_from_the_selected_entry() {
        let line = |text: &str| LogEntry {
            stamp: "t=1.00  sensor    ".into(),
            text: text.into(),
            ..LogEntry::default()
        };
        let view = LogView {
            entries: vec![line("one"), line("two"), failure()],
            ..LogView::default()
        };
        let rows: Vec<String> = pane_rows(&view, 60, 3).into_iter().map(|r| r.0).collect();
        assert_eq!(rows.len(), 3);
        assert!(rows[0].ends_with("ZeroDivisionError:"), "{rows:?}");
        assert_eq!(rows[2], "  … ↵ shows it whole");
        let rows: Vec<String> = pane_rows(&view, 60, 6).into_iter().map(|r| r.0).collect();
        assert_eq!(rows[0], "t=1.00  sensor    two");
        assert!(rows[5].ends_with("return 1 / 0"), "{rows:?}");
    }
}
