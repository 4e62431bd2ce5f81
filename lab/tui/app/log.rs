//! The log pane's side of the lab's state: its entries, each a line of the run's text log
//! as the pane shows it (a callback's failure with the learner's frames, every path
//! relative to the graph file's folder), the one selected (PgUp / PgDn) and the one opened
//! whole over the lab (Enter).

use super::super::view::{entry_rows, LogEntry, OpenEntry, MIN_SIZE};
use super::*;
use ratelab::textlog::{Level, LogLine};

/// How many entries before the selected one the pane is given at most (more than any pane
/// shows).
const SHOWN: usize = 64;

/// How many rows PgUp / PgDn scroll an opened entry.
const ENTRY_PAGE: usize = 5;

/// `text` with `folder/` taken off every path in it that starts there: `nodes/policy.py:12`
/// for `/home/me/lab/nodes/policy.py:12`, with the graph file in `/home/me/lab`. A path
/// elsewhere, and `text` with no folder (`""`, or the root), stay as they are.
pub fn relative_to(text: &str, folder: &str) -> String {
    let folder = folder.trim_end_matches('/');
    if folder.is_empty() {
        return text.to_string();
    }
    text.replace(&format!("{folder}/"), "")
}

/// The log pane's entry for `line`, its paths relative to `folder` ([`relative_to`]): its
/// stamp (`t=1.23  policy    `), its text whole, and a failure's frames (`nodes/policy.py:12
/// in on_timer: x = 1 / 0`) and whole traceback.
pub fn entry_of(line: &LogLine, folder: &str) -> LogEntry {
    let t = line.t.map_or_else(
        || "      ".to_string(),
        |t| format!("t={:<5.2}", t.as_secs_f64()),
    );
    let who = line.node.as_deref().unwrap_or("ratelab");
    let rel = |s: &str| relative_to(s, folder);
    let (frames, traceback) = match &line.traceback {
        Some(tb) => (
            tb.frames
                .iter()
                .map(|f| {
                    let at = format!("{}:{} in {}", rel(&f.file), f.line, f.function);
                    if f.code.is_empty() {
                        at
                    } else {
                        format!("{at}: {}", f.code)
                    }
                })
                .collect(),
            tb.lines.iter().map(|l| rel(l)).collect(),
        ),
        None => (Vec::new(), Vec::new()),
    };
    LogEntry {
        warn: line.level != Level::Info,
        stamp: format!("{t} {who:<9} "),
        text: rel(&line.text),
        frames,
        traceback,
    }
}

impl App {
    /// Paths in the log pane are shown relative to `folder` (the graph file's, else the
    /// folder the lab runs in), as the reload line names files.
    pub fn set_code_folder(&mut self, folder: &std::path::Path) {
        self.code_folder = Some(folder.display().to_string());
    }

    /// The node whose lines the pane shows (the selected node's), `None`: every line.
    fn log_node(&self) -> Option<String> {
        match self.selected {
            Some(Selected::Node(id)) => Some(self.graph.node(id).name.clone()),
            _ => None,
        }
    }

    /// The indices in [`App::log`] of the lines the pane shows, oldest first.
    fn log_shown(&self) -> Vec<usize> {
        let node = self.log_node();
        self.log
            .iter()
            .enumerate()
            .filter(|(_, l)| node.is_none() || l.node == node)
            .map(|(i, _)| i)
            .collect()
    }

    /// The log pane's view: the selected node's lines (all nodes' when none is selected), up
    /// to the selected entry, and the entry opened whole, if one is.
    pub(super) fn log_view(&self) -> LogView {
        let folder = self.code_folder.as_deref().unwrap_or("");
        let shown = self.log_shown();
        let back = self.log_back.min(shown.len().saturating_sub(1));
        let upto = shown.len() - back.min(shown.len());
        let entries = shown[upto.saturating_sub(SHOWN)..upto]
            .iter()
            .map(|&i| entry_of(&self.log[i], folder))
            .collect();
        LogView {
            whose: self.log_node().unwrap_or_else(|| "all nodes".to_string()),
            total: if self.selected.is_some() {
                shown.len()
            } else {
                self.log_total
            },
            entries,
            back,
            open: self.opened().map(|line| OpenEntry {
                entry: entry_of(line, folder),
                scroll: self.log_scroll,
            }),
        }
    }

    /// The line opened whole (Enter), while the lab still holds it.
    fn opened(&self) -> Option<&LogLine> {
        let first = self.log_total - self.log.len();
        self.log.get(self.log_open?.checked_sub(first)?)
    }

    /// Enter: show the selected entry of the log pane whole over the lab, or close the one
    /// shown. The entry stays the one opened as lines come in.
    pub(super) fn toggle_entry(&mut self) {
        if self.log_open.take().is_some() {
            return;
        }
        if !self.show_log {
            self.say("Enter shows the log pane's selected entry whole: v opens the pane".into());
            return;
        }
        let shown = self.log_shown();
        let back = self.log_back.min(shown.len().saturating_sub(1));
        match shown.len().checked_sub(back + 1).map(|k| shown[k]) {
            Some(i) => {
                self.log_open = Some(self.log_total - self.log.len() + i);
                self.log_scroll = 0;
            }
            None => self.say("nothing in the log yet".into()),
        }
    }

    /// PgUp (`up`) / PgDn on an opened entry: its rows scrolled, up to its last row at the
    /// narrowest the lab draws it.
    pub(super) fn scroll_entry(&mut self, up: bool) {
        let folder = self.code_folder.as_deref().unwrap_or("");
        let Some(entry) = self.opened().map(|l| entry_of(l, folder)) else {
            self.log_open = None;
            return;
        };
        let most = entry_rows(&entry, usize::from(MIN_SIZE.0) - 2, true).len();
        self.log_scroll = if up {
            self.log_scroll.saturating_sub(ENTRY_PAGE)
        } else {
            (self.log_scroll + ENTRY_PAGE).min(most)
        };
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use ratelab::textlog::{Frame, Traceback};

    #[test]
    fn paths_read_relative_to_the_graph_file_s_folder() {
        let folder = "/home/me/lab";
        assert_eq!(
            relative_to(
                "/home/me/lab/nodes/p.py:12: ZeroDivisionError: division by zero",
                folder
            ),
            "nodes/p.py:12: ZeroDivisionError: division by zero"
        );
        assert_eq!(
            relative_to(
                "  File \"/home/me/lab/p.py\", line 3, in act",
                "/home/me/lab/"
            ),
            "  File \"p.py\", line 3, in act"
        );
        // Elsewhere, or with no folder (the root's would take every slash), as it is.
        assert_eq!(relative_to("/usr/lib/x.py:1", folder), "/usr/lib/x.py:1");
        assert_eq!(relative_to("/a/b.py:1", "/"), "/a/b.py:1");
        assert_eq!(relative_to("/a/b.py:1", ""), "/a/b.py:1");
    }

    /// A callback's failure is one entry: its stamp, its message whole, its learner's frames
    /// and its traceback, every path relative to the graph file's folder.
    #[test]
    fn a_failure_is_one_entry_with_its_frames_and_traceback() {
        let line = LogLine {
            t: Some(ratelab::Nanos(1_200_000_000)),
            node: Some("policy".into()),
            level: Level::Error,
            text: "/g/nodes/p.py:12: ZeroDivisionError: division by zero".into(),
            logged: None,
            traceback: Some(Box::new(Traceback {
                frames: vec![
                    Frame {
                        file: "/g/nodes/p.py".into(),
                        line: 9,
                        function: "on_timer".into(),
                        code: "u = self.gain(s)".into(),
                    },
                    Frame {
                        file: "/g/nodes/p.py".into(),
                        line: 12,
                        function: "gain".into(),
                        code: String::new(),
                    },
                ],
                lines: vec![
                    "Traceback (most recent call last):".into(),
                    "  File \"/g/nodes/p.py\", line 12, in gain".into(),
                    "ZeroDivisionError: division by zero".into(),
                ],
            })),
        };
        let e = entry_of(&line, "/g");
        assert!(e.warn);
        assert_eq!(e.stamp, "t=1.20  policy    ");
        assert_eq!(e.text, "nodes/p.py:12: ZeroDivisionError: division by zero");
        assert_eq!(
            e.frames,
            [
                "nodes/p.py:9 in on_timer: u = self.gain(s)",
                "nodes/p.py:12 in gain"
            ]
        );
        assert_eq!(e.traceback[1], "  File \"nodes/p.py\", line 12, in gain");
        // A line outside any tick, of ratelab's own, without a traceback.
        let plain = LogLine {
            t: None,
            node: None,
            level: Level::Info,
            text: "reloaded /g/nodes/p.py: …".into(),
            logged: None,
            traceback: None,
        };
        let e = entry_of(&plain, "/g");
        assert_eq!(
            (e.stamp.as_str(), e.text.as_str()),
            ("       ratelab   ", "reloaded nodes/p.py: …")
        );
        assert!(!e.warn && e.frames.is_empty() && e.traceback.is_empty());
    }
}
