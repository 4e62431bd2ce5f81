//! The run's text log: every line a node's code writes (a Python node's or brain's `print`,
//! `get_logger()`, a Python warning) and ratelab's own warnings about them (a callback that
//! has not returned), each stamped with the run time and the node it came from.
//!
//! Where a line goes is the program's choice, made once ([`set_sink`]): the terminal lab
//! takes them into its log pane (nothing is ever written over its screen); without a sink
//! (a headless run) each goes to stderr as one line, `[t=1.234 s policy] text`.
//!
//! The run time and node of a line are those of the tick the calling thread is in
//! ([`enter`], set by the node around its tick): a line written outside any tick (a script's
//! loading) has neither. Text is made safe to show ([`crate::text::printable`]).
//!
//! A line a node's logger wrote ([`emit_logged`]: a Python node's `get_logger().info(…)`)
//! keeps its message apart from the level word it is shown with (`info: text`), and where
//! the logger was called ([`Logged`]): `/rosout` carries them as rcl does (the message
//! alone in `msg`; `file`, `function`, `line`).
//!
//! A callback's failure, when the program asks for it (the terminal lab, through the Python
//! layer), is one line too ([`emit_failure`]): its one-line description, carrying the
//! learner's frames and the whole traceback ([`Traceback`]), which the lab's log pane shows
//! under it and on demand.

use crate::time::Nanos;
use std::cell::RefCell;
use std::sync::{Arc, Mutex};

/// How much a line matters.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Level {
    /// What a node's code printed on stdout, or logged as info.
    Info,
    /// A warning: what the code wrote on stderr or logged as one, ratelab's own.
    Warn,
    /// An error the code logged.
    Error,
}

impl Level {
    /// The word a logger's line is shown with (`info: text`): `info`, `warning`, `error`,
    /// as the Python logger's methods name them.
    pub fn word(self) -> &'static str {
        match self {
            Level::Info => "info",
            Level::Warn => "warning",
            Level::Error => "error",
        }
    }
}

/// What a node's logger logged, as rcl puts it on `/rosout` (`rcl_interfaces/msg/Log`'s
/// `msg`, `file`, `function`, `line`): the message without the level word, and the call
/// that logged it. For a Python node the frame that called `get_logger().info(…)`, as
/// rclpy takes it (`rclpy/impl/rcutils_logger.py`: the caller's `co_filename`, `co_name`,
/// `f_lineno`).
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct Logged {
    /// The message, one line, control characters written out.
    pub msg: String,
    /// The source file, as the interpreter names it (a Python node's script: its absolute
    /// path); empty when not known.
    pub file: String,
    /// The function that called the logger (`__init__`, `on_obs`); empty when not known.
    pub function: String,
    /// The line of that call, from 1; 0 when not known.
    pub line: u32,
}

/// A Python exception's traceback, as a callback's failure carries it ([`emit_failure`]).
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct Traceback {
    /// The learner's own frames (those in the failed script's folder), outermost first.
    pub frames: Vec<Frame>,
    /// The whole traceback as Python prints it, line by line.
    pub lines: Vec<String>,
}

/// One frame of a traceback: where the code was, and its line of code.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct Frame {
    /// The source file, as the interpreter names it (a script's absolute path).
    pub file: String,
    /// The line, from 1; 0 when not known.
    pub line: u32,
    /// The function it was in.
    pub function: String,
    /// Its line of code, stripped; empty when not known.
    pub code: String,
}

/// One line of the log.
#[derive(Clone, Debug, PartialEq)]
pub struct LogLine {
    /// The run time of the tick it was written in; `None` outside any tick.
    pub t: Option<Nanos>,
    /// The node whose code wrote it (or whom ratelab's warning is about).
    pub node: Option<String>,
    /// How much it matters.
    pub level: Level,
    /// The text, one line, control characters written out: as shown (a logger's line with
    /// its level word first, `info: text`).
    pub text: String,
    /// For a line a node's logger wrote: its message alone and where it was logged
    /// ([`emit_logged`]); `None` for what code printed and ratelab's own lines.
    pub logged: Option<Logged>,
    /// For a callback's failure ([`emit_failure`]): its traceback; `None` for every other
    /// line.
    pub traceback: Option<Box<Traceback>>,
}

impl LogLine {
    /// `[t=1.234 s policy] text`: the line as headless runs print it (the stamp's parts
    /// that are known).
    pub fn prefixed(&self) -> String {
        let stamp = match (self.t, &self.node) {
            (Some(t), Some(n)) => format!("[t={:.3} s {n}] ", t.as_secs_f64()),
            (Some(t), None) => format!("[t={:.3} s] ", t.as_secs_f64()),
            (None, Some(n)) => format!("[{n}] "),
            (None, None) => String::new(),
        };
        format!("{stamp}{}", self.text)
    }

    /// A line as [`LogLine::prefixed`] wrote it, read back at `level` (the prefix does not
    /// say it): `[t=1.234 s policy] text`, `[t=1.234 s] text`, `[policy] text` or `text`
    /// (what another process of a graph wrote on its stderr). A bracket that is not a stamp
    /// is the text's own.
    pub fn parse_prefixed(line: &str, level: Level) -> LogLine {
        let plain = LogLine {
            t: None,
            node: None,
            level,
            text: line.to_string(),
            logged: None,
            traceback: None,
        };
        let Some((stamp, text)) = line
            .strip_prefix('[')
            .and_then(|rest| rest.split_once("] "))
        else {
            return plain;
        };
        let (t, node) = match stamp.strip_prefix("t=") {
            Some(timed) => {
                let (secs, node) = match timed.split_once(" s") {
                    Some((secs, rest)) => (secs, rest.strip_prefix(' ')),
                    None => return plain,
                };
                match secs.parse::<f64>() {
                    Ok(s) if (0.0..1e9).contains(&s) => {
                        (Some(Nanos((s * 1e9).round() as u64)), node)
                    }
                    _ => return plain,
                }
            }
            None if !stamp.is_empty() && !stamp.contains(' ') => (None, Some(stamp)),
            None => return plain,
        };
        if node.is_some_and(|n| n.is_empty() || n.contains(' ')) {
            return plain;
        }
        LogLine {
            t,
            node: node.map(str::to_string),
            level,
            text: text.to_string(),
            logged: None,
            traceback: None,
        }
    }
}

/// Where lines go, when a program took them.
type Sink = Box<dyn Fn(LogLine) + Send + Sync>;

fn sink() -> &'static Mutex<Option<Sink>> {
    static SINK: Mutex<Option<Sink>> = Mutex::new(None);
    &SINK
}

/// Send every line to `to` from now on (`None`: back to stderr). The terminal lab takes
/// them while its screen is up, and gives them back when it closes.
pub fn set_sink(to: Option<Sink>) {
    *sink().lock().unwrap_or_else(|e| e.into_inner()) = to;
}

/// The recorders ([`add_recorder`]), each with its number.
fn recorders() -> &'static Mutex<Vec<(u64, Sink)>> {
    static RECORDERS: Mutex<Vec<(u64, Sink)>> = Mutex::new(Vec::new());
    &RECORDERS
}

/// Also give every line to `to`, wherever the sink sends it, while the returned guard
/// lives: a recording of the run the lines come from (the lab records each run it records
/// with its lines, while its sink is the log pane). Every recorder added takes every line
/// written in the process meanwhile.
pub fn add_recorder(to: Sink) -> Recorder {
    static NEXT: std::sync::atomic::AtomicU64 = std::sync::atomic::AtomicU64::new(0);
    let id = NEXT.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
    recorders()
        .lock()
        .unwrap_or_else(|e| e.into_inner())
        .push((id, to));
    Recorder(id)
}

/// A recorder added by [`add_recorder`]; dropped, it takes no more lines.
#[must_use = "the recorder takes lines only while this lives"]
pub struct Recorder(u64);

impl Drop for Recorder {
    fn drop(&mut self) {
        recorders()
            .lock()
            .unwrap_or_else(|e| e.into_inner())
            .retain(|(id, _)| *id != self.0);
    }
}

thread_local! {
    /// The tick the calling thread is in: its run time and node.
    static TICK: RefCell<Option<(Nanos, Arc<str>)>> = const { RefCell::new(None) };
    /// Lines written on this thread are dropped ([`muted`]).
    static MUTED: std::cell::Cell<bool> = const { std::cell::Cell::new(false) };
}

/// Run `f` with every line the calling thread writes meanwhile dropped: a run made only to
/// be measured (the lab judging a reloaded node's code before it runs it for the screen)
/// does not say twice what the node says.
pub fn muted<T>(f: impl FnOnce() -> T) -> T {
    let before = MUTED.with(|m| m.replace(true));
    let out = f();
    MUTED.with(|m| m.set(before));
    out
}

/// The calling thread is in node `node`'s tick at run time `now` until the returned scope
/// is dropped: lines it writes meanwhile carry both. Cheap (no allocation): a node's ticks
/// call it each time.
pub fn enter(node: &Arc<str>, now: Nanos) -> Scope {
    let before = TICK.with(|t| t.replace(Some((now, node.clone()))));
    Scope { before }
}

/// A tick's stamp on the calling thread, restored to what it was when dropped.
pub struct Scope {
    before: Option<(Nanos, Arc<str>)>,
}

impl Drop for Scope {
    fn drop(&mut self) {
        let before = self.before.take();
        TICK.with(|t| *t.borrow_mut() = before);
    }
}

/// The run time of the tick the calling thread is in, if any.
pub fn now() -> Option<Nanos> {
    TICK.with(|t| t.borrow().as_ref().map(|(now, _)| *now))
}

/// Write `text` (one line or several: each its own line) at `level`, stamped with the
/// calling thread's tick ([`enter`]).
pub fn emit(level: Level, text: &str) {
    let (t, node) = TICK.with(|t| t.borrow().clone()).unzip();
    emit_for(node.as_deref(), t, level, text);
}

/// Write `text` about node `node` at run time `t` (either unknown: `None`).
pub fn emit_for(node: Option<&str>, t: Option<Nanos>, level: Level, text: &str) {
    deliver(
        text.lines()
            .filter(|l| !l.trim().is_empty())
            .map(|line| LogLine {
                t,
                node: node.map(str::to_string),
                level,
                text: crate::text::printable(line.trim_end()).into_owned(),
                logged: None,
                traceback: None,
            }),
    );
}

/// Write what node `node`'s logger logged at `level`, stamped with the calling thread's
/// tick's run time ([`enter`]): one line, `logged.msg` (its control characters, a newline
/// too, written out, as are the file's and function's), shown as `info: msg` (the level's
/// [`Level::word`]) and kept apart with where it was logged ([`LogLine::logged`]).
pub fn emit_logged(node: Option<&str>, level: Level, logged: Logged) {
    let safe = |s: &str| crate::text::printable(s).into_owned();
    let logged = Logged {
        msg: safe(logged.msg.trim_end()),
        file: safe(&logged.file),
        function: safe(&logged.function),
        line: logged.line,
    };
    deliver(std::iter::once(LogLine {
        t: now(),
        node: node.map(str::to_string),
        level,
        text: format!("{}: {}", level.word(), logged.msg)
            .trim_end()
            .to_string(),
        logged: Some(logged),
        traceback: None,
    }));
}

/// Write a callback's failure at [`Level::Error`], stamped with the calling thread's tick
/// ([`enter`]): one line, `text` (its one-line description, `FILE:LINE: Type: message`),
/// carrying `traceback` ([`LogLine::traceback`]), every part made safe to show. Only a
/// program that asks for failures in its log writes them (the terminal lab, through the
/// Python layer's `log_failures`): a headless run says a failure once, in its summary.
pub fn emit_failure(text: &str, traceback: Traceback) {
    let safe = |s: &str| crate::text::printable(s).into_owned();
    let (t, node) = TICK.with(|t| t.borrow().clone()).unzip();
    let traceback = Traceback {
        frames: traceback
            .frames
            .iter()
            .map(|f| Frame {
                file: safe(&f.file),
                line: f.line,
                function: safe(&f.function),
                code: safe(f.code.trim()),
            })
            .collect(),
        lines: traceback.lines.iter().map(|l| safe(l.trim_end())).collect(),
    };
    deliver(std::iter::once(LogLine {
        t,
        node: node.as_deref().map(str::to_string),
        level: Level::Error,
        text: safe(text.trim()),
        logged: None,
        traceback: Some(Box::new(traceback)),
    }));
}

/// Give `lines` to every recorder and to the sink (stderr without one), all of them
/// together (no other thread's line comes between them); none on a muted thread.
fn deliver(lines: impl Iterator<Item = LogLine>) {
    if MUTED.with(std::cell::Cell::get) {
        return;
    }
    let guard = sink().lock().unwrap_or_else(|e| e.into_inner());
    let recording = recorders().lock().unwrap_or_else(|e| e.into_inner());
    for line in lines {
        for (_, r) in recording.iter() {
            r(line.clone());
        }
        match guard.as_ref() {
            Some(to) => to(line),
            // Not `eprintln!`: a closed stderr must not end the run from a node's print.
            None => {
                use std::io::Write as _;
                let _ = writeln!(std::io::stderr(), "{}", line.prefixed());
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_prefixed_line_reads_back_as_it_was_written() {
        let lines = [
            (Some(Nanos(1_234_000_000)), Some("policy")),
            (Some(Nanos(0)), None),
            (None, Some("sensor")),
            (None, None),
        ];
        for (t, node) in lines {
            let line = LogLine {
                t,
                node: node.map(str::to_string),
                level: Level::Warn,
                text: "x = [1, 2] ok".into(),
                logged: None,
                traceback: None,
            };
            assert_eq!(LogLine::parse_prefixed(&line.prefixed(), Level::Warn), line);
        }
        // Brackets that are not a stamp are the text's.
        for text in [
            "[1, 2] ok",
            "[t=x s p] y",
            "[a b] c",
            "[] d",
            "[t=1e300 s] e",
        ] {
            let read = LogLine::parse_prefixed(text, Level::Info);
            assert_eq!((read.t, read.node, read.text.as_str()), (None, None, text));
        }
    }

    #[test]
    fn lines_carry_their_tick_and_go_where_the_program_says() {
        let got = Arc::new(Mutex::new(Vec::new()));
        let keep = got.clone();
        set_sink(Some(Box::new(move |l| keep.lock().unwrap().push(l))));
        emit(Level::Info, "zqx before any tick");
        {
            let _tick = enter(&Arc::from("policy"), Nanos(1_234_000_000));
            emit(Level::Warn, "zqx two\nzqx lines \u{1b}[2J");
        }
        emit(Level::Info, "zqx after");
        set_sink(None);
        // Only this test's lines (others may write meanwhile).
        let got: Vec<LogLine> = got
            .lock()
            .unwrap()
            .iter()
            .filter(|l| l.text.starts_with("zqx "))
            .cloned()
            .collect();
        let shown: Vec<String> = got
            .iter()
            .map(|l| l.prefixed().replace("zqx ", ""))
            .collect();
        assert_eq!(
            shown,
            [
                "before any tick",
                "[t=1.234 s policy] two",
                "[t=1.234 s policy] lines \\u{1b}[2J",
                "after"
            ]
        );
        assert_eq!(got[1].level, Level::Warn);
    }

    /// A logger's line is shown with its level word, as before, and keeps its message
    /// alone and its caller for `/rosout`, each made safe to show.
    #[test]
    fn a_loggers_line_keeps_its_message_apart_from_its_level_word() {
        let got = Arc::new(Mutex::new(Vec::new()));
        let keep = got.clone();
        let _recorder = add_recorder(Box::new(move |l| keep.lock().unwrap().push(l)));
        {
            let _tick = enter(&Arc::from("policy"), Nanos(20_000_000));
            let logged = Logged {
                msg: "qzx heard 3 \u{1b}[2J".into(),
                file: "/tmp/p.py".into(),
                function: "on_obs".into(),
                line: 12,
            };
            emit_logged(Some("policy"), Level::Warn, logged);
        }
        emit_logged(
            Some("sensor"),
            Level::Info,
            Logged {
                msg: "qzx\nbuilt".into(),
                ..Logged::default()
            },
        );
        let got: Vec<LogLine> = got
            .lock()
            .unwrap()
            .iter()
            .filter(|l| l.logged.as_ref().is_some_and(|g| g.msg.starts_with("qzx")))
            .cloned()
            .collect();
        assert_eq!(got.len(), 2, "{got:?}");
        assert_eq!(
            got[0].prefixed(),
            "[t=0.020 s policy] warning: qzx heard 3 \\u{1b}[2J"
        );
        assert_eq!(
            got[0].logged,
            Some(Logged {
                msg: "qzx heard 3 \\u{1b}[2J".into(),
                file: "/tmp/p.py".into(),
                function: "on_obs".into(),
                line: 12,
            })
        );
        // Outside any tick: no run time; a newline written out, the line stays one.
        assert_eq!(got[1].prefixed(), "[sensor] info: qzx\\nbuilt");
        assert_eq!(got[1].logged.as_ref().map(|l| l.line), Some(0));
    }

    /// A callback's failure is one line at the error level, stamped with its tick, carrying
    /// its frames and traceback, every part made safe to show.
    #[test]
    fn a_failure_is_one_line_carrying_its_traceback() {
        let got = Arc::new(Mutex::new(Vec::new()));
        let keep = got.clone();
        let _recorder = add_recorder(Box::new(move |l| keep.lock().unwrap().push(l)));
        {
            let _tick = enter(&Arc::from("policy"), Nanos(480_000_000));
            emit_failure(
                "zqf p.py:3: ZeroDivisionError: division by zero\n",
                Traceback {
                    frames: vec![Frame {
                        file: "/g/p.py".into(),
                        line: 3,
                        function: "on_timer".into(),
                        code: "  x = 1 / 0 \u{1b}[2J ".into(),
                    }],
                    lines: vec!["Traceback (most recent call last):".into(), "x\t".into()],
                },
            );
        }
        let got: Vec<LogLine> = got
            .lock()
            .unwrap()
            .iter()
            .filter(|l| l.text.starts_with("zqf "))
            .cloned()
            .collect();
        assert_eq!(got.len(), 1, "{got:?}");
        assert_eq!(
            got[0].prefixed(),
            "[t=0.480 s policy] zqf p.py:3: ZeroDivisionError: division by zero"
        );
        assert_eq!(got[0].level, Level::Error);
        let tb = got[0].traceback.as_deref().expect("its traceback");
        assert_eq!(tb.frames[0].code, "x = 1 / 0 \\u{1b}[2J");
        assert_eq!(tb.lines, ["Traceback (most recent call last):", "x"]);
    }
}
