//! Keys → messages: one table of bindings ([`BINDINGS`]) from which the keymap
//! ([`map_key`]), the help overlay, the footer and the README's key list are all built
//! (gitui keeps its bindings as data the same way), and a pure mapping function, so the
//! bindings are tested without a terminal.

use crossterm::event::{KeyCode, KeyEvent, KeyEventKind, KeyModifiers};

/// How long `k` stalls a node, s ([`Msg::Stall`]).
pub const STALL_S: f64 = 0.5;

/// What a key asks for.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Msg {
    /// The selected node's rate (the policy's when no node is selected) one step down.
    RateDown,
    /// … one step up.
    RateUp,
    /// Start typing an exact rate for the selected node (or the policy).
    TypeRate,
    /// The selected node's (else the policy's) phase offset: the next of 0, 5, 10, 15 ms
    /// (`super::app::PHASES_MS`), from the next instant on (`Command::SetPhase`; virtual
    /// clock).
    CyclePhase,
    /// Sensor rate down the ladder.
    SensorDown,
    /// Sensor rate up the ladder.
    SensorUp,
    /// The selected topic's depth (every topic's when none is selected) down (1, 2, 5, 10, 100).
    DepthDown,
    /// … up.
    DepthUp,
    /// The selected topic's delivery: latest ↔ fifo.
    ToggleDelivery,
    /// The selected topic's deadline: the next of none, 25, 30, 50, 100, 200 ms
    /// (`super::app::DEADLINES_MS`).
    CycleDeadline,
    /// The selected topic's link loss: the next of 0, 1 %, 5 %, 20 %, 50 %, 80 %.
    CycleLoss,
    /// The selected topic's lifespan: the next of none, 20, 50, 100, 200 ms.
    CycleLifespan,
    /// The selected topic's reliability: best effort ↔ reliable.
    ToggleReliability,
    /// The actuator's reaction to a missed deadline on the selected topic: hold → zero →
    /// stop → hold.
    CycleOnDeadlineMissed,
    /// Select the next node or topic (nothing → nodes → topics → nothing).
    SelectNext,
    /// Select the previous one.
    SelectPrev,
    /// Control rate to 5 Hz.
    Break,
    /// Stall the selected node (else the chain's policy) for [`STALL_S`] from the instant the
    /// run takes up next (`Control::Stall`): a fault injected into the run
    /// (`Command::InjectFault`), at any speed.
    Stall,
    /// Pause / resume (virtual clock); review a real-clock run that has ended.
    TogglePause,
    /// One actuator step while paused (virtual clock).
    Step,
    /// While paused (virtual clock): back one tick of the selected node (else the
    /// actuator's); `second`: one second.
    SeekBack {
        /// One second rather than one tick.
        second: bool,
    },
    /// … forward.
    SeekForward {
        /// One second rather than one tick.
        second: bool,
    },
    /// New run, same seed.
    Reset,
    /// New run, next seed.
    NextSeed,
    /// Go on under the other clock (a run that ended: restart under it).
    SwitchClock,
    /// Slower virtual pacing.
    Slower,
    /// Faster virtual pacing.
    Faster,
    /// The charts' window one step narrower (down to 0.2 s).
    ChartsNarrower,
    /// … wider (up to the whole run).
    ChartsWider,
    /// Swap the brain (scripted ↔ the --policy file).
    SwapBrain,
    /// Run the graph on the next executors: one thread per node → one thread for all →
    /// two threads → one per node (virtual clock: at once; real clock: the next run).
    CycleExecutor,
    /// Show the executor timeline instead of the latency histogram, or back.
    ToggleTimeline,
    /// Show the log pane (what nodes' code and ratelab's warnings wrote) instead of the
    /// latency histogram, or back.
    ToggleLog,
    /// Show the graph as ROS 2 sees it (with `--ros2`: node names, topics with their ROS 2
    /// types, QoS and endpoint counts, `/clock`) instead of the node graph, or back.
    ToggleRos2,
    /// The graph panel's next zoom: boxes → names → list ([`super::navigate::Zoom`]).
    Zoom,
    /// Scroll the graph panel up a row.
    ScrollUp,
    /// … down a row.
    ScrollDown,
    /// Back to the graph panel's top.
    ScrollTop,
    /// Start typing the graph panel's filter (a name, or `@` and a process).
    Filter,
    /// Show only the nodes and topics in trouble, or everything again.
    ToggleTrouble,
    /// Scroll the log pane back (older lines).
    LogOlder,
    /// Scroll the log pane forward (newer lines).
    LogNewer,
    /// Show the log pane's selected entry whole (its text, a failure's frames and whole
    /// traceback) over the lab, or close it.
    LogEntry,
    /// Show / hide the key help.
    ToggleHelp,
    /// Close the help or the selection; when neither is open, ask, and quit on a second one.
    Back,
    /// Leave the lab.
    Quit,
    /// Ctrl-C: interrupt a callback of the run on screen that has not returned (Python's
    /// `KeyboardInterrupt`, as Ctrl-C does in a headless run), or say that a save's trial is
    /// what hangs; with nothing hung, or a second time, leave the lab.
    Interrupt,
    /// While typing a rate: a character.
    Input(char),
    /// While typing: delete one character.
    Backspace,
    /// While typing: apply.
    Submit,
    /// While typing: abandon.
    Cancel,
}

impl Msg {
    /// Does it move through the run ([`Msg::SeekBack`], [`Msg::SeekForward`])?
    pub fn is_seek(self) -> bool {
        matches!(self, Msg::SeekBack { .. } | Msg::SeekForward { .. })
    }

    /// Does it only change what the lab shows (a selection, the help, leaving)? Those are the
    /// keys an attached lab, which watches a graph across processes, acts on.
    pub fn only_views(self) -> bool {
        matches!(
            self,
            Msg::SelectNext
                | Msg::SelectPrev
                | Msg::Zoom
                | Msg::ScrollUp
                | Msg::ScrollDown
                | Msg::ScrollTop
                | Msg::Filter
                | Msg::ToggleTrouble
                | Msg::ToggleHelp
                | Msg::ToggleTimeline
                | Msg::ToggleLog
                | Msg::ToggleRos2
                | Msg::LogOlder
                | Msg::LogNewer
                | Msg::LogEntry
                | Msg::ChartsNarrower
                | Msg::ChartsWider
                | Msg::Back
                | Msg::Quit
                | Msg::Interrupt
        )
    }
}

/// One row of the key table: the keys, how the help and README name them, what they do,
/// and the word the footer shows (if the footer shows them).
pub struct Binding {
    /// Each key and the message it sends.
    pub keys: &'static [(KeyCode, Msg)],
    /// The keys as the help overlay and the README write them.
    pub label: &'static str,
    /// What they do.
    pub help: &'static str,
    /// The footer's compact form: (keys, word), or `None` when the footer leaves it out.
    pub footer: Option<(&'static str, &'static str)>,
}

impl Binding {
    /// Do all its keys only change what the lab shows ([`Msg::only_views`])?
    pub fn only_views(&self) -> bool {
        self.keys.iter().all(|(_, m)| m.only_views())
    }

    /// Does this binding pause the run (space)?
    pub fn pauses(&self) -> bool {
        self.keys.iter().any(|(_, m)| *m == Msg::TogglePause)
    }
}

use KeyCode::{BackTab, Char, Down, Esc, Home, Left, Right, Tab, Up};

/// Every binding of the lab (Ctrl-C, always: [`Msg::Interrupt`]).
pub const BINDINGS: &[Binding] = &[
    Binding {
        keys: &[
            (Char('-'), Msg::RateDown),
            (Left, Msg::RateDown),
            (Char('+'), Msg::RateUp),
            (Right, Msg::RateUp),
        ],
        label: "- / + (← / →)",
        help: "rate down / up: the selected node's, else the policy's",
        footer: Some(("-/+", "rate")),
    },
    Binding {
        keys: &[(Char('='), Msg::TypeRate)],
        label: "=",
        help: "type an exact rate for it (Enter applies, Esc cancels)",
        footer: None,
    },
    Binding {
        keys: &[(Char('P'), Msg::CyclePhase)],
        label: "P",
        help: "its phase offset: the next of 0, 5, 10, 15 ms (virtual)",
        footer: None,
    },
    Binding {
        keys: &[
            (Char('s'), Msg::SensorDown),
            (Char('S'), Msg::SensorUp),
            (Char('p'), Msg::SwapBrain),
        ],
        label: "s / S / p",
        help: "sensor rate down / up / brain: scripted ↔ --policy file",
        footer: None,
    },
    Binding {
        keys: &[(Char('['), Msg::DepthDown), (Char(']'), Msg::DepthUp)],
        label: "[ / ]",
        help: "depth down / up: the selected topic's, else every topic's",
        footer: Some(("[/]", "depth")),
    },
    Binding {
        keys: &[
            (Char('f'), Msg::ToggleDelivery),
            (Char('d'), Msg::CycleDeadline),
            (Char('L'), Msg::CycleLoss),
        ],
        label: "f / d / L",
        help: "QoS of the selected topic: fifo ↔ latest / deadline / loss",
        footer: None,
    },
    Binding {
        keys: &[
            (Char('l'), Msg::CycleLifespan),
            (Char('e'), Msg::ToggleReliability),
            (Char('o'), Msg::CycleOnDeadlineMissed),
        ],
        label: "l / e / o",
        help: "… lifespan / reliability / on_deadline_missed",
        footer: None,
    },
    Binding {
        keys: &[(Tab, Msg::SelectNext), (BackTab, Msg::SelectPrev)],
        label: "Tab / Shift-Tab",
        help: "select the next / previous node or topic",
        footer: Some(("Tab", "select")),
    },
    Binding {
        keys: &[
            (Char('z'), Msg::Zoom),
            (Up, Msg::ScrollUp),
            (Down, Msg::ScrollDown),
            (Home, Msg::ScrollTop),
            (Char('/'), Msg::Filter),
            (Char('!'), Msg::ToggleTrouble),
        ],
        label: "z ↑↓ / !",
        help: "graph: zoom boxes→names→list · scroll · filter · trouble",
        footer: None,
    },
    Binding {
        keys: &[
            (Char('t'), Msg::ToggleTimeline),
            (Char('x'), Msg::CycleExecutor),
        ],
        label: "t / x",
        help: "timeline ↔ latency / executors per node → single → multi:2",
        footer: None,
    },
    Binding {
        keys: &[(Char('b'), Msg::Break), (Char('k'), Msg::Stall)],
        label: "b / k",
        help: "break: control to 5 Hz / stall the selected node 0.5 s",
        footer: Some(("b", "break")),
    },
    Binding {
        keys: &[(Char(' '), Msg::TogglePause)],
        label: "space",
        help: "pause / resume · an ended real-clock run: review it",
        footer: Some(("␣", "pause")),
    },
    Binding {
        keys: &[
            (Char('.'), Msg::Step),
            (Left, Msg::SeekBack { second: false }),
            (Right, Msg::SeekForward { second: false }),
        ],
        label: ". / ← →",
        help: "paused: one step / ← → a tick back · forward (Shift: 1 s)",
        footer: None,
    },
    Binding {
        keys: &[(Char('r'), Msg::Reset), (Char('R'), Msg::NextSeed)],
        label: "r / R",
        help: "reset (same seed) / next seed",
        footer: Some(("r", "reset")),
    },
    Binding {
        keys: &[(Char('c'), Msg::SwitchClock)],
        label: "c",
        help: "switch clock in place (a run that ended restarts)",
        footer: Some(("c", "clock")),
    },
    Binding {
        keys: &[
            (Char('<'), Msg::Slower),
            (Char('>'), Msg::Faster),
            (Char('('), Msg::ChartsNarrower),
            (Char(')'), Msg::ChartsWider),
        ],
        label: "< > / ( )",
        help: "slower / faster (virtual) / chart window 0.2 s … whole run",
        footer: None,
    },
    Binding {
        keys: &[
            (Char('?'), Msg::ToggleHelp),
            (Char('v'), Msg::ToggleLog),
            (KeyCode::PageUp, Msg::LogOlder),
            (KeyCode::PageDown, Msg::LogNewer),
            (KeyCode::Enter, Msg::LogEntry),
            (Char('g'), Msg::ToggleRos2),
        ],
        label: "? / v / ↵ / g",
        help: "help / log pane (PgUp PgDn, ↵ an entry whole) / ROS 2 view",
        footer: Some(("?", "help")),
    },
    Binding {
        keys: &[(Esc, Msg::Back), (Char('q'), Msg::Quit)],
        label: "Esc / q / Ctrl-C",
        help: "close help, selection, filter / quit / stop a hang or quit",
        footer: Some(("q", "quit")),
    },
];

/// Lines the help overlay adds after the bindings: (label, text). The last, the wire's, only
/// in a lab attached to a graph across processes (the only one to show it); the others only
/// in the lab's own session.
pub const HELP_NOTES: [(&str, &str); 5] = [
    (
        "rate ladder (Hz)",
        "1000 500 200 100 60 50 40 30 25 20 15 12 10 8 7 6 5 4 3 2 1",
    ),
    ("depth ladder", "1 2 5 10 100"),
    (
        "after a fall",
        "the lab freezes; keys set the next run, r/R/c start it",
    ),
    (
        // What `N lost` means under reliable delivery ([`ratelab::qos::MAX_ATTEMPTS`]).
        "reliable, N lost",
        "given up after 16 sends, each one lost (retx: the resends)",
    ),
    (
        "wire p50/p99 µs",
        "across processes: latency over the wire (narrow: p50)",
    ),
];

/// What is being typed, if anything: keys then edit it instead of acting.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Typing {
    /// Nothing: keys act.
    No,
    /// An exact rate: every character is typed, and Enter judges the whole (`-5` is refused,
    /// not read as 5).
    Rate,
    /// The graph panel's filter: any printable character.
    Filter,
}

/// Map a key event. `typing` says what is being typed; `scrubbing` is true while the run
/// is paused under the virtual clock, when ← and → move through the run (Shift: by a
/// second) instead of changing a rate.
pub fn map_key(key: KeyEvent, typing: Typing, scrubbing: bool) -> Option<Msg> {
    if key.kind == KeyEventKind::Release {
        return None;
    }
    if key.modifiers.contains(KeyModifiers::CONTROL) && key.code == Char('c') {
        return Some(Msg::Interrupt);
    }
    if typing != Typing::No {
        return match key.code {
            // Every character typed is kept, a rate's too: `-5` or `x1` is refused whole on
            // Enter, never read as the digits left (`5`, `1`).
            Char(c) if !c.is_control() => Some(Msg::Input(c)),
            KeyCode::Backspace => Some(Msg::Backspace),
            KeyCode::Enter => Some(Msg::Submit),
            Esc => Some(Msg::Cancel),
            _ => None,
        };
    }
    let second = key.modifiers.contains(KeyModifiers::SHIFT);
    BINDINGS
        .iter()
        .flat_map(|b| b.keys.iter())
        .filter(|(_, msg)| msg.is_seek() == scrubbing || !key_seeks(key.code))
        .find(|(code, _)| *code == key.code)
        .map(|(_, msg)| match *msg {
            Msg::SeekBack { .. } => Msg::SeekBack { second },
            Msg::SeekForward { .. } => Msg::SeekForward { second },
            m => m,
        })
}

/// Is `code` one of the keys that move through the run while paused?
fn key_seeks(code: KeyCode) -> bool {
    BINDINGS
        .iter()
        .flat_map(|b| b.keys.iter())
        .any(|(c, m)| *c == code && m.is_seek())
}

#[cfg(test)]
/// The README's key list, as a markdown table built from [`BINDINGS`] (a test checks that
/// README.md holds exactly this).
#[cfg(test)]
pub fn readme_key_table() -> String {
    let mut out = String::from("| keys | what they do |\n| --- | --- |\n");
    for b in BINDINGS {
        let label = b.label.replace('|', "\\|");
        out.push_str(&format!("| `{label}` | {} |\n", b.help));
    }
    for (label, text) in HELP_NOTES {
        out.push_str(&format!("| {label} | {text} |\n"));
    }
    out
}

/// The rate ladder, Hz, high to low: the chapter's control rates (50 … 1 Hz) and, above
/// them, rungs back to a fast estimator's or sensor's rate (100, 200 Hz) once lowered.
pub const RATE_LADDER: [f64; 21] = [
    1000.0, 500.0, 200.0, 100.0, 60.0, 50.0, 40.0, 30.0, 25.0, 20.0, 15.0, 12.0, 10.0, 8.0, 7.0,
    6.0, 5.0, 4.0, 3.0, 2.0, 1.0,
];
/// The queue-depth ladder.
pub const DEPTH_LADDER: [usize; 5] = [1, 2, 5, 10, 100];

/// The next rate down the ladder from `hz` (off-ladder rates go to the next lower rung).
pub fn rate_down(hz: f64) -> f64 {
    RATE_LADDER
        .iter()
        .copied()
        .find(|&r| r < hz)
        .unwrap_or(RATE_LADDER[RATE_LADDER.len() - 1])
}

/// The next rate up the ladder from `hz` (a rate at or above the top rung stays: `+`
/// never lowers a rate).
pub fn rate_up(hz: f64) -> f64 {
    RATE_LADDER
        .iter()
        .rev()
        .copied()
        .find(|&r| r > hz)
        .unwrap_or(hz)
}

/// The next depth down.
pub fn depth_down(d: usize) -> usize {
    DEPTH_LADDER
        .iter()
        .rev()
        .copied()
        .find(|&x| x < d)
        .unwrap_or(1)
}

/// The next depth up.
pub fn depth_up(d: usize) -> usize {
    DEPTH_LADDER.iter().copied().find(|&x| x > d).unwrap_or(100)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn key(c: KeyCode) -> KeyEvent {
        KeyEvent::new(c, KeyModifiers::NONE)
    }

    #[test]
    fn no_key_is_bound_twice() {
        // Once while running and once while scrubbing (paused, virtual clock) at most.
        for scrubbing in [false, true] {
            let mut seen = Vec::new();
            for (code, msg) in BINDINGS.iter().flat_map(|b| b.keys.iter()) {
                if msg.is_seek() != scrubbing && (scrubbing && key_seeks(*code)) {
                    continue; // the running binding, shadowed while scrubbing
                }
                if msg.is_seek() && !scrubbing {
                    continue;
                }
                assert!(!seen.contains(code), "{code:?} bound twice");
                seen.push(*code);
            }
        }
    }

    /// Every row of the key help fits the 78 columns inside its box at 80 columns: a margin,
    /// the label column, two spaces, the text (`view::help_row`), none cut.
    #[test]
    fn every_help_row_fits_eighty_columns() {
        let w = crate::tui::view::HELP_LABEL_CHARS;
        let rows = BINDINGS
            .iter()
            .map(|b| (b.label, b.help))
            .chain(HELP_NOTES.iter().copied());
        for (label, text) in rows {
            assert!(
                label.chars().count() <= w,
                "label {label:?} is wider than {w}"
            );
            let row = 1 + w + 2 + text.chars().count();
            assert!(row <= 78, "{label:?}: {row} columns: {text:?}");
        }
    }

    #[test]
    fn the_readme_lists_every_binding() {
        let readme = std::fs::read_to_string(concat!(env!("CARGO_MANIFEST_DIR"), "/../README.md"))
            .expect("README.md");
        let table = readme_key_table();
        assert!(
            readme.contains(&table),
            "README.md's key list is out of date; it should read:\n{table}"
        );
    }

    #[test]
    fn default_bindings() {
        assert_eq!(
            map_key(key(KeyCode::Char('-')), Typing::No, false),
            Some(Msg::RateDown)
        );
        assert_eq!(
            map_key(key(KeyCode::Left), Typing::No, false),
            Some(Msg::RateDown)
        );
        assert_eq!(
            map_key(key(KeyCode::Char('+')), Typing::No, false),
            Some(Msg::RateUp)
        );
        assert_eq!(
            map_key(key(KeyCode::Right), Typing::No, false),
            Some(Msg::RateUp)
        );
        assert_eq!(
            map_key(key(KeyCode::Tab), Typing::No, false),
            Some(Msg::SelectNext)
        );
        assert_eq!(
            map_key(key(KeyCode::BackTab), Typing::No, false),
            Some(Msg::SelectPrev)
        );
        assert_eq!(
            map_key(key(KeyCode::Char('=')), Typing::No, false),
            Some(Msg::TypeRate)
        );
        assert_eq!(
            map_key(key(KeyCode::Char('s')), Typing::No, false),
            Some(Msg::SensorDown)
        );
        assert_eq!(
            map_key(key(KeyCode::Char('S')), Typing::No, false),
            Some(Msg::SensorUp)
        );
        assert_eq!(
            map_key(key(KeyCode::Char('[')), Typing::No, false),
            Some(Msg::DepthDown)
        );
        assert_eq!(
            map_key(key(KeyCode::Char(']')), Typing::No, false),
            Some(Msg::DepthUp)
        );
        assert_eq!(
            map_key(key(KeyCode::Char('b')), Typing::No, false),
            Some(Msg::Break)
        );
        assert_eq!(
            map_key(key(KeyCode::Char(' ')), Typing::No, false),
            Some(Msg::TogglePause)
        );
        assert_eq!(
            map_key(key(KeyCode::Char('.')), Typing::No, false),
            Some(Msg::Step)
        );
        assert_eq!(
            map_key(key(KeyCode::Char('r')), Typing::No, false),
            Some(Msg::Reset)
        );
        assert_eq!(
            map_key(key(KeyCode::Char('R')), Typing::No, false),
            Some(Msg::NextSeed)
        );
        assert_eq!(
            map_key(key(KeyCode::Char('c')), Typing::No, false),
            Some(Msg::SwitchClock)
        );
        assert_eq!(
            map_key(key(KeyCode::Char('<')), Typing::No, false),
            Some(Msg::Slower)
        );
        assert_eq!(
            map_key(key(KeyCode::Char('>')), Typing::No, false),
            Some(Msg::Faster)
        );
        assert_eq!(
            map_key(key(KeyCode::Char('(')), Typing::No, false),
            Some(Msg::ChartsNarrower)
        );
        assert_eq!(
            map_key(key(KeyCode::Char(')')), Typing::No, false),
            Some(Msg::ChartsWider)
        );
        assert_eq!(
            map_key(key(KeyCode::Char('p')), Typing::No, false),
            Some(Msg::SwapBrain)
        );
        assert_eq!(
            map_key(key(KeyCode::Char('?')), Typing::No, false),
            Some(Msg::ToggleHelp)
        );
        assert_eq!(
            map_key(key(KeyCode::Char('q')), Typing::No, false),
            Some(Msg::Quit)
        );
        assert_eq!(
            map_key(key(KeyCode::Esc), Typing::No, false),
            Some(Msg::Back)
        );
        assert_eq!(
            map_key(
                KeyEvent::new(KeyCode::Char('c'), KeyModifiers::CONTROL),
                Typing::No,
                false
            ),
            Some(Msg::Interrupt)
        );
        assert_eq!(
            map_key(key(KeyCode::Enter), Typing::No, false),
            Some(Msg::LogEntry)
        );
        assert_eq!(
            map_key(key(KeyCode::Char('x')), Typing::No, false),
            Some(Msg::CycleExecutor)
        );
        assert_eq!(map_key(key(KeyCode::Char('y')), Typing::No, false), None);
    }

    /// `P` steps the selected node's phase offset (ex3's subject), a change of the run (an
    /// attached lab refuses it); `p` still swaps the brain, on the sensor's row of the help.
    #[test]
    fn shift_p_sets_a_phase_offset_and_p_still_swaps_the_brain() {
        assert_eq!(
            map_key(key(KeyCode::Char('P')), Typing::No, false),
            Some(Msg::CyclePhase)
        );
        assert_eq!(
            map_key(
                KeyEvent::new(KeyCode::Char('P'), KeyModifiers::SHIFT),
                Typing::No,
                true
            ),
            Some(Msg::CyclePhase)
        );
        assert!(!Msg::CyclePhase.only_views());
        assert_eq!(
            map_key(key(KeyCode::Char('p')), Typing::No, false),
            Some(Msg::SwapBrain)
        );
        let row = |m: Msg| {
            BINDINGS
                .iter()
                .find(|b| b.keys.iter().any(|(_, x)| *x == m))
                .map(|b| (b.label, b.help))
        };
        assert_eq!(
            row(Msg::CyclePhase),
            Some((
                "P",
                "its phase offset: the next of 0, 5, 10, 15 ms (virtual)"
            ))
        );
        assert_eq!(row(Msg::SwapBrain).map(|r| r.0), Some("s / S / p"));
    }

    /// The help explains what `N lost` means on a reliable topic: messages given up after
    /// the reliable link's every send (its retransmit budget) was lost.
    #[test]
    fn the_help_says_what_lost_means_under_reliable_delivery() {
        let (label, text) = HELP_NOTES
            .iter()
            .find(|(label, _)| label.starts_with("reliable"))
            .expect("a note on reliable losses");
        assert_eq!(*label, "reliable, N lost");
        assert!(
            text.contains(&format!("after {} sends", ratelab::qos::MAX_ATTEMPTS)),
            "{text}"
        );
        // Every help row fits the 80-column overlay: 16 for the label, 2, then the text.
        for b in BINDINGS {
            assert!(b.label.chars().count() <= 16, "{}", b.label);
            assert!(b.help.chars().count() <= 60, "{}", b.help);
        }
        for (label, text) in HELP_NOTES {
            assert!(
                label.chars().count() <= 16 && text.chars().count() <= 60,
                "{label}"
            );
        }
    }

    #[test]
    fn the_graph_panel_s_keys_and_its_filter_takes_any_character() {
        for (code, msg) in [
            (KeyCode::Char('z'), Msg::Zoom),
            (KeyCode::Up, Msg::ScrollUp),
            (KeyCode::Down, Msg::ScrollDown),
            (KeyCode::Home, Msg::ScrollTop),
            (KeyCode::Char('/'), Msg::Filter),
            (KeyCode::Char('!'), Msg::ToggleTrouble),
        ] {
            assert_eq!(map_key(key(code), Typing::No, false), Some(msg));
            // They only change what the lab shows: an attached lab takes them.
            assert!(msg.only_views(), "{msg:?}");
        }
        // Typing a filter, the lab's keys are letters of it.
        for c in ['q', 'z', '@', '_', '/', '-'] {
            assert_eq!(
                map_key(key(KeyCode::Char(c)), Typing::Filter, false),
                Some(Msg::Input(c))
            );
        }
        assert_eq!(
            map_key(key(KeyCode::Enter), Typing::Filter, false),
            Some(Msg::Submit)
        );
        assert_eq!(
            map_key(key(KeyCode::Esc), Typing::Filter, false),
            Some(Msg::Cancel)
        );
        assert_eq!(map_key(key(KeyCode::Up), Typing::Filter, false), None);
    }

    #[test]
    fn typing_mode_takes_every_character_for_enter_to_judge() {
        assert_eq!(
            map_key(key(KeyCode::Char('7')), Typing::Rate, false),
            Some(Msg::Input('7'))
        );
        assert_eq!(
            map_key(key(KeyCode::Char('.')), Typing::Rate, false),
            Some(Msg::Input('.'))
        );
        // Not a digit: typed too (Enter refuses `-5` whole), not dropped nor a lab key.
        for c in ['q', '-', 'x', 'e'] {
            assert_eq!(
                map_key(key(KeyCode::Char(c)), Typing::Rate, false),
                Some(Msg::Input(c))
            );
        }
        assert_eq!(map_key(key(KeyCode::Up), Typing::Rate, false), None);
        assert_eq!(
            map_key(key(KeyCode::Enter), Typing::Rate, false),
            Some(Msg::Submit)
        );
        assert_eq!(
            map_key(key(KeyCode::Esc), Typing::Rate, false),
            Some(Msg::Cancel)
        );
        assert_eq!(
            map_key(key(KeyCode::Backspace), Typing::Rate, false),
            Some(Msg::Backspace)
        );
        // Ctrl-C always interrupts (a hung callback first, else it quits).
        assert_eq!(
            map_key(
                KeyEvent::new(KeyCode::Char('c'), KeyModifiers::CONTROL),
                Typing::Rate,
                false
            ),
            Some(Msg::Interrupt)
        );
    }

    #[test]
    fn paused_the_arrows_move_through_the_run_and_shift_by_a_second() {
        let shifted = |c| KeyEvent::new(c, KeyModifiers::SHIFT);
        assert_eq!(
            map_key(key(KeyCode::Left), Typing::No, true),
            Some(Msg::SeekBack { second: false })
        );
        assert_eq!(
            map_key(key(KeyCode::Right), Typing::No, true),
            Some(Msg::SeekForward { second: false })
        );
        assert_eq!(
            map_key(shifted(KeyCode::Left), Typing::No, true),
            Some(Msg::SeekBack { second: true })
        );
        assert_eq!(
            map_key(shifted(KeyCode::Right), Typing::No, true),
            Some(Msg::SeekForward { second: true })
        );
        // The rate keys stay rate keys; running, the arrows are rates again.
        assert_eq!(
            map_key(key(KeyCode::Char('-')), Typing::No, true),
            Some(Msg::RateDown)
        );
        assert_eq!(
            map_key(key(KeyCode::Char('.')), Typing::No, true),
            Some(Msg::Step)
        );
        assert_eq!(
            map_key(shifted(KeyCode::Left), Typing::No, false),
            Some(Msg::RateDown)
        );
    }

    #[test]
    fn key_releases_are_ignored() {
        let mut k = key(KeyCode::Char('-'));
        k.kind = KeyEventKind::Release;
        assert_eq!(map_key(k, Typing::No, false), None);
    }

    #[test]
    fn ladders() {
        assert_eq!(rate_down(50.0), 40.0);
        assert_eq!(rate_down(5.0), 4.0);
        assert_eq!(rate_down(1.0), 1.0);
        assert_eq!(rate_down(7.5), 7.0);
        assert_eq!(rate_up(7.5), 8.0);
        assert_eq!(rate_up(50.0), 60.0);
        // A 100 Hz estimator or a 200 Hz sensor lowered once comes back with `+`.
        assert_eq!(rate_up(rate_down(100.0)), 100.0);
        assert_eq!(rate_up(rate_down(200.0)), 200.0);
        assert_eq!(rate_up(1000.0), 1000.0);
        assert_eq!(rate_up(2000.0), 2000.0);
        assert_eq!(rate_down(2000.0), 1000.0);
        assert_eq!(depth_up(1), 2);
        assert_eq!(depth_up(100), 100);
        assert_eq!(depth_down(10), 5);
        assert_eq!(depth_down(1), 1);
        assert_eq!(depth_down(3), 2);
        // 11 presses of `-` take 50 Hz to 5 Hz.
        let mut hz = 50.0;
        for _ in 0..11 {
            hz = rate_down(hz);
        }
        assert_eq!(hz, 5.0);
    }
}
