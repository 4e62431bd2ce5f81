//! End to end, a callback's exception (issue 72, item 2): one entry of the log pane, its
//! message whole and the learner's frames, paths relative to the graph file; Enter shows
//! its whole traceback over the lab, at 80×24.

use super::Lab;
use std::time::Duration;

/// A Python node whose timer callback calls a helper that divides by zero at its 25th tick:
/// the node fails; in the log pane (`v`) its exception is one entry naming
/// `nodes/loud.py:LINE` (relative to the graph file's folder), its title offers the
/// traceback, and Enter shows it whole (both frames, the exception); Esc closes it.
#[test]
fn a_callback_s_exception_is_one_entry_and_enter_shows_its_traceback() {
    let _machine = crate::machine::alone();
    let dir = tempfile::tempdir().unwrap();
    let graph = crate::loud_python_graph(
        dir.path(),
        "self.n = getattr(self, 'n', 0) + 1\ndef gain(n):\n    return 1 / (25 - n)\ngain(self.n)",
    );
    let mut lab = Lab::start_sized(
        &["--clock", "virtual", "--graph", graph.to_str().unwrap()],
        &[],
        80,
        24,
    );
    lab.wait_for("NODE FAILED", Duration::from_secs(60));
    lab.keys("v");
    let screen = lab.wait_for("log: all nodes", Duration::from_secs(5));
    assert!(
        screen.contains("nodes/loud.py:") && screen.contains("ZeroDivisionError"),
        "{screen}"
    );
    assert!(
        !screen.contains(&dir.path().display().to_string()),
        "a path not relative to the graph file:\n{screen}"
    );
    assert!(screen.contains("↵ traceback"), "{screen}");
    // Enter (a carriage return, as a terminal sends it).
    lab.keys("\r");
    let screen = lab.wait_for("Traceback (most recent call last):", Duration::from_secs(5));
    assert!(screen.contains("log entry"), "{screen}");
    assert!(
        screen.contains("in on_timer") && screen.contains("in gain"),
        "{screen}"
    );
    assert!(screen.contains("return 1 / (25 - n)"), "{screen}");
    lab.keys("\x1b");
    lab.wait_until("the entry closed", Duration::from_secs(5), |s| {
        !s.contains("Traceback (most recent")
    });
    lab.keys("q");
    let status = lab.exit_status("q");
    // The run's node failed: the lab says so in its exit status.
    assert!(!status.success(), "{status:?}");
}

/// A long exception message (three lines' worth at 80 columns) reads whole at 80×24 and
/// 120×40: the log pane's entry begins with the file and line and the exception, and Enter
/// shows the message entire, wrapped, its last word included.
#[test]
fn a_long_exception_message_reads_whole_at_both_sizes() {
    let _machine = crate::machine::alone();
    for (cols, rows) in [(80, 24), (120, 40)] {
        long_exception_at(cols, rows);
    }
}

/// The test above at `cols`×`rows`.
fn long_exception_at(cols: u16, rows: u16) {
    let dir = tempfile::tempdir().unwrap();
    let words: Vec<String> = (1..=30).map(|i| format!("word{i:02}")).collect();
    let message = words.join(" ");
    let graph = crate::loud_python_graph(
        dir.path(),
        &format!("raise ValueError('the gain is wrong: {message} END')"),
    );
    let mut lab = Lab::start_sized(
        &["--clock", "virtual", "--graph", graph.to_str().unwrap()],
        &[],
        cols,
        rows,
    );
    lab.wait_for("NODE FAILED", Duration::from_secs(60));
    lab.keys("v");
    let screen = lab.wait_for("log: all nodes", Duration::from_secs(5));
    assert!(
        screen.contains("nodes/loud.py:") && screen.contains("ValueError: the gain is wrong"),
        "{screen}"
    );
    lab.keys("\r");
    let screen = lab.wait_for("Traceback (most recent call last):", Duration::from_secs(5));
    // Every word of the message, in order, across the wrapped rows.
    let text: String = screen.split_whitespace().collect::<Vec<_>>().join(" ");
    let mut at = 0;
    for w in words.iter().map(String::as_str).chain(["END"]) {
        let found = text[at..]
            .find(w)
            .unwrap_or_else(|| panic!("'{w}' missing or out of order:\n{screen}"));
        at += found + w.len();
    }
    lab.keys("\x1b");
    lab.keys("q");
    let _ = lab.exit_status("q");
}
