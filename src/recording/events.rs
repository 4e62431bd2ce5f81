//! The run's events placed in time, three ways at once: a row of the `events` text log
//! (at its run time, with its level), a mark on the pole-angle plot (`marks/change` ◆,
//! `marks/trouble` ▲, `marks/recovery` ●, in a row under the lower fall limit; the fall's ×
//! is `plant/fall`, at the pole's angle) whose legend names the times, and a line of the `when` document, which lists
//! every event in time order and names the first trouble at its top. The document is what a
//! reviewer reads first: the stock viewer labels a plot's time axis only at power-of-ten
//! steps at least about 150 px apart, so a plot alone cannot say when something happened
//! ("+0s" alone under a 10 s run at 1280×720).
//!
//! Every event is stamped on the run's one clock (a launch's: the launcher's run clock, as
//! its lines state it) and listed in time order ([`in_time_order`]: stable, so events of one
//! instant keep the order they were logged in, their causal order). Besides what the graph
//! shows, a live session's own changes are events with marks ([`Recording::injected_fault`],
//! [`Recording::clock_switched`], [`Recording::reloaded`], [`Recording::parameter_set`]).

use super::*;

/// What an event is, for its mark.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord)]
pub(super) enum Mark {
    /// A change made mid-run: a rate, a depth, a QoS setting, the brain.
    Change,
    /// Trouble: an injected stall or kill, a deadline missed, a node not alive, a timer's
    /// skipped ticks, a watchdog's stop, a process gone, a node's failure.
    Trouble,
    /// A return from trouble: a stall's end, a node alive again, a process rejoined.
    Recovery,
    /// The pole past its limit.
    Fall,
}

impl Mark {
    /// Every mark, in the order legends and the document's key list them.
    pub(super) const ALL: [Mark; 4] = [Mark::Change, Mark::Trouble, Mark::Recovery, Mark::Fall];

    /// The scalar series that marks it on the pole-angle plot.
    pub(super) fn entity(self) -> &'static str {
        match self {
            Mark::Change => "marks/change",
            Mark::Trouble => "marks/trouble",
            Mark::Recovery => "marks/recovery",
            Mark::Fall => "plant/fall",
        }
    }

    fn words(self) -> &'static str {
        match self {
            Mark::Change => "change",
            Mark::Trouble => "trouble",
            Mark::Recovery => "recovered",
            Mark::Fall => "the fall",
        }
    }

    /// The marker's symbol as the document writes it (the plot's marker shape).
    pub(super) fn symbol(self) -> &'static str {
        match self {
            Mark::Change => "◆",
            Mark::Trouble => "▲",
            Mark::Recovery => "●",
            Mark::Fall => "×",
        }
    }

    /// Where the mark sits on the pole-angle plot (rad): below the lower fall limit, in a
    /// row along the time axis (the legend takes the top left; the fall: at the pole's
    /// angle).
    fn y_rad(self) -> f64 {
        -CHANGE_MARK_RAD
    }

    fn style(self) -> ((u8, u8, u8), rerun::components::MarkerShape, f32) {
        use rerun::components::MarkerShape as M;
        match self {
            Mark::Change => ((240, 240, 240), M::Diamond, 5.0),
            Mark::Trouble => ((240, 200, 60), M::Up, 6.0),
            Mark::Recovery => ((120, 210, 110), M::Circle, 4.0),
            Mark::Fall => (LIMIT_COLOR, M::Cross, 8.0),
        }
    }

    /// A legend's name for the mark, with the times it was set, to 10 ms: `▲ trouble at
    /// 2.00, 2.04, 2.30 s`; events that read as one time named once with their count
    /// (`0.08 (×2)`, two deadlines missed at one step); past three times, `… 7 in all`.
    pub(super) fn legend(self, times: &[Nanos]) -> String {
        let mut shown: Vec<(String, usize)> = Vec::new();
        for t in times {
            let at = format!("{:.2}", t.as_secs_f64());
            match shown.last_mut() {
                Some((last, n)) if *last == at => *n += 1,
                _ => shown.push((at, 1)),
            }
        }
        if shown.is_empty() {
            return format!("{} {}", self.symbol(), self.words());
        }
        let more = if shown.len() > 3 {
            format!(" … {} in all", times.len())
        } else {
            String::new()
        };
        let listed: Vec<String> = (shown.iter().take(3))
            .map(|(at, n)| match n {
                1 => at.clone(),
                n => format!("{at} (×{n})"),
            })
            .collect();
        format!(
            "{} {} at {} s{more}",
            self.symbol(),
            self.words(),
            listed.join(", ")
        )
    }
}

/// The most events listed one by one (the document, the legends' times); past it, events
/// are counted. Bounds a long run's memory: deadline misses are said at most once a second
/// per topic, so an hour with a lossy topic stays under it only for a few topics.
pub(super) const MAX_LISTED: usize = 500;

/// One event as logged.
#[derive(Clone, Debug)]
pub(super) struct Logged {
    t: Nanos,
    mark: Option<Mark>,
    warn: bool,
    text: String,
}

/// The events so far: the first [`MAX_LISTED`], then a count.
#[derive(Default)]
pub(super) struct EventList {
    rows: Vec<Logged>,
    more: usize,
    /// Each mark's legend as last logged: past [`MAX_LISTED`] it no longer changes, and is
    /// not logged again.
    legends: BTreeMap<Mark, String>,
}

/// Sort `rows` by their run time (`t` of each), stably: rows of one instant keep the order
/// they came in (a process gone before its rejoin, both at one step's time).
pub(super) fn in_time_order<T>(rows: &mut [T], t: impl Fn(&T) -> Nanos) {
    rows.sort_by_key(t);
}

impl EventList {
    /// Add `row` in time order: after every row at or before its time (a launcher's line can
    /// state a time before the newest step's), so that the list stays as
    /// [`in_time_order`] sorts it.
    fn push(&mut self, row: Logged) {
        if self.rows.len() < MAX_LISTED {
            let at = self.rows.partition_point(|r| r.t <= row.t);
            self.rows.insert(at, row);
        } else {
            self.more += 1;
        }
    }

    /// The times of the listed events marked `mark`, in time order.
    pub(super) fn times(&self, mark: Mark) -> Vec<Nanos> {
        let mut t: Vec<Nanos> = self
            .rows
            .iter()
            .filter(|r| r.mark == Some(mark))
            .map(|r| r.t)
            .collect();
        t.sort();
        t
    }

    /// The `when` document: the first trouble (or the fall) at the top, then every event in
    /// time order, `2.000 s ▲ text`. `ended`: the run is over (else it says so).
    pub(super) fn document(&self, ended: bool) -> String {
        let mut rows: Vec<&Logged> = self.rows.iter().collect();
        in_time_order(&mut rows, |r| r.t);
        let line = |r: &Logged| {
            let symbol = r.mark.map_or(if r.warn { "!" } else { "·" }, Mark::symbol);
            format!("{:.3} s {symbol} {}", r.t.as_secs_f64(), escape(&r.text))
        };
        let mut doc = String::new();
        let first = rows
            .iter()
            .find(|r| matches!(r.mark, Some(Mark::Trouble | Mark::Fall)));
        match first {
            Some(r) => doc.push_str(&format!("**First trouble: {}**\n\n", line(r))),
            None if ended => doc.push_str("No trouble: no fault, miss, loss or fall.\n\n"),
            None => {}
        }
        for r in rows {
            doc.push_str(&format!("- {}\n", line(r)));
        }
        if self.more > 0 {
            doc.push_str(&format!(
                "- … and {} more (the events tab lists them all)\n",
                self.more
            ));
        }
        if !ended {
            doc.push_str("\nThe run is still going: more come as it runs.\n");
        }
        doc.push_str(&format!(
            "\nMarks on the pole-angle plot: {}.\n",
            Mark::ALL
                .iter()
                .map(|m| format!("{} {}", m.symbol(), m.words()))
                .collect::<Vec<_>>()
                .join(", ")
        ));
        doc
    }
}

/// `text` with markdown's active characters escaped, so a name cannot format the document.
fn escape(text: &str) -> String {
    let mut out = String::with_capacity(text.len());
    for c in text.chars() {
        if matches!(
            c,
            '\\' | '*' | '_' | '`' | '[' | ']' | '<' | '>' | '#' | '|'
        ) {
            out.push('\\');
        }
        out.push(c);
    }
    out
}

impl ChunkBuffer {
    /// Log an event at run time `t` (control step `step`): a row of `events` at level
    /// `level`, a mark (`mark`; the fall's is logged with the fall), and a line of the `when`
    /// document.
    pub(super) fn event(
        &mut self,
        t: Nanos,
        step: u64,
        mark: Option<Mark>,
        text: &str,
        level: &str,
    ) {
        let time = self.at(t, step);
        self.add(
            "events",
            &time,
            &rerun::TextLog::new(text).with_level(level),
        );
        if let Some(m) = mark.filter(|m| *m != Mark::Fall) {
            self.scalar(m.entity(), t, step, m.y_rad());
        }
        self.events.push(Logged {
            t,
            mark,
            warn: level != rerun::components::TextLogLevel::INFO,
            text: text.to_string(),
        });
        if let Some(m) = mark {
            self.mark_style(m);
        }
    }

    /// A mark's style (a static row), its legend naming the times it was set so far.
    fn mark_style(&mut self, m: Mark) {
        let (color, shape, size) = m.style();
        let name = m.legend(&self.events.times(m));
        if self.events.legends.get(&m) == Some(&name) {
            return;
        }
        self.events.legends.insert(m, name.clone());
        self.style(
            m.entity(),
            &name,
            &rerun::SeriesPoints::new()
                .with_names([name.as_str()])
                .with_colors([rgb(color)])
                .with_markers([shape])
                .with_marker_sizes([size]),
        );
    }

    /// The `when` document (`ended`: the run is over).
    pub(super) fn when_document(&mut self, ended: bool) {
        let doc = self.events.document(ended);
        self.add(
            "when",
            &TimePoint::default(),
            &rerun::TextDocument::from_markdown(doc),
        );
    }
}

/// The mark of a line a launch's launcher or a watcher says: a warning is trouble, a
/// process's or node's return a recovery.
pub(super) fn mark_of_line(text: &str, level: &str) -> Option<Mark> {
    if level != rerun::components::TextLogLevel::INFO {
        Some(Mark::Trouble)
    } else if ["rejoined", "heard again", "alive again"]
        .iter()
        .any(|w| text.contains(w))
    {
        Some(Mark::Recovery)
    } else {
        None
    }
}

/// The run time a launcher's line states (`… at t=5.57s …`), when it states one: its event
/// is placed there rather than at the newest step the watcher had, which can lag behind.
pub(super) fn stated_time(text: &str) -> Option<Nanos> {
    let rest = &text[text.find("t=")? + 2..];
    let end = rest
        .find(|c: char| !(c.is_ascii_digit() || c == '.'))
        .unwrap_or(rest.len());
    let s: f64 = rest[..end].parse().ok()?;
    (s.is_finite() && (0.0..1e9).contains(&s)).then(|| Nanos((s * 1e9).round() as u64))
}

/// The events of fault `f`: a stall's start (trouble) and end (a recovery), a kill's start
/// (trouble), from run time `from` on: a fault injected while the run goes on (`live`, said
/// so) covers the ticks from when it was applied, its own time being past. A stall over
/// before `from` is listed, unmarked, as having done nothing.
pub(super) fn fault_events(f: &ratelab_core::qos::Fault, from: Nanos, live: bool) -> Vec<DueEvent> {
    let (warn, info) = (
        rerun::components::TextLogLevel::WARN,
        rerun::components::TextLogLevel::INFO,
    );
    let how = if live { " (live)" } else { "" };
    let start = f.at.max(from);
    let Some(d) = f.duration else {
        let text = format!("injected kill{how}: node {} stops for good", f.node);
        return vec![(start, text, warn, Some(Mark::Trouble))];
    };
    let end = f.at.saturating_add(d);
    if end <= start {
        let text = format!(
            "injected stall{how}: node {} from {:.2} s to {:.2} s, over before it was injected: no effect",
            f.node,
            f.at.as_secs_f64(),
            end.as_secs_f64()
        );
        return vec![(start, text, info, None)];
    }
    vec![
        (
            start,
            format!(
                "injected stall{how}: node {} does no work and asserts no liveliness for {:.2} s (until {:.2} s)",
                f.node,
                end.saturating_sub(start).as_secs_f64(),
                end.as_secs_f64()
            ),
            warn,
            Some(Mark::Trouble),
        ),
        (
            end,
            format!("node {} resumes after its stall", f.node),
            info,
            Some(Mark::Recovery),
        ),
    ]
}

/// A ROS 2 parameter set's event line: `ROS 2 parameter set: policy rate_hz = 10 Hz (ros2
/// param set)`.
fn parameter_line(node: &str, hz: f64) -> String {
    format!(
        "ROS 2 parameter set: {node} rate_hz = {} Hz (ros2 param set)",
        hz_label(hz)
    )
}

/// A clock switch's event line, the recording's time axis named by `timeline`.
fn clock_line(to: ClockKind, timeline: &str) -> String {
    format!("clock switched: the run goes on under the {to} clock, its state carried across (the time axis stays {timeline})")
}

/// A live session's own changes, each an event with a mark at the run time it took effect.
impl Recording {
    /// A fault injected while the run goes on (the lab's stall key `k`, a session log's
    /// `inject_fault` replayed), applied at run time `at`: its start is marked as trouble at
    /// the run time it took effect (its own time, or `at` when that had passed) and a
    /// stall's end as a recovery, each logged once the run reaches it (a run that ended
    /// first records none after its end), as `--stall` and `--kill` are.
    pub fn injected_fault(&self, at: Nanos, fault: &ratelab_core::qos::Fault) {
        let mut due = self.due_events.lock().unwrap_or_else(|e| e.into_inner());
        for e in fault_events(fault, at, true) {
            // After every event due at or before it: one instant's in the order known.
            let i = due.partition_point(|d| d.0 <= e.0);
            due.insert(i, e);
        }
    }

    /// The run went on under the clock `to` at run time `at` (the lab's `c` on a run going
    /// on, its state carried across): an event with a change mark. The recording's time
    /// axis keeps the name of the clock the run started under.
    pub fn clock_switched(&self, at: Nanos, to: ClockKind) {
        let text = clock_line(to, timeline_name(self.clock));
        let info = rerun::components::TextLogLevel::INFO;
        self.event_marked(at, Some(Mark::Change), &text, info);
    }

    /// Saved code taken up at run time `at` (a Python node's script restarted in place; a
    /// run that starts again from t = 0 with the new code, in the next recording): `text` as
    /// an event with a change mark.
    pub fn reloaded(&self, at: Nanos, text: &str) {
        let info = rerun::components::TextLogLevel::INFO;
        self.event_marked(at, Some(Mark::Change), text, info);
    }

    /// A ROS 2 parameter set (`ros2 param set NODE rate_hz HZ`) that set node `node`'s rate
    /// to `hz` at run time `at`: an event with a change mark. The graph's own line for that
    /// rate change (`policy rate 50 → 10 Hz`, at the next step) is then listed unmarked, so
    /// one change has one mark.
    pub fn parameter_set(&self, at: Nanos, node: &str, hz: f64) {
        self.announced
            .lock()
            .unwrap_or_else(|e| e.into_inner())
            .push((node.to_string(), hz));
        let info = rerun::components::TextLogLevel::INFO;
        self.event_marked(at, Some(Mark::Change), &parameter_line(node, hz), info);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_legend_names_the_first_times_and_counts_the_rest() {
        let t = |ms: u64| Nanos(ms * 1_000_000);
        assert_eq!(Mark::Change.legend(&[]), "◆ change");
        assert_eq!(
            Mark::Trouble.legend(&[t(2000), t(2040), t(2300)]),
            "▲ trouble at 2.00, 2.04, 2.30 s"
        );
        assert_eq!(
            Mark::Recovery.legend(&[t(1), t(2), t(3), t(4)]),
            "● recovered at 0.00 (×4) s",
            "times that read alike are named once"
        );
        assert_eq!(
            Mark::Trouble.legend(&[t(80), t(80), t(100), t(2000), t(2300)]),
            "▲ trouble at 0.08 (×2), 0.10, 2.00 s … 5 in all"
        );
    }

    #[test]
    fn the_document_lists_events_in_time_order_and_opens_at_the_first_trouble() {
        let mut list = EventList::default();
        let row = |ms: u64, mark, text: &str| Logged {
            t: Nanos(ms * 1_000_000),
            mark,
            warn: mark == Some(Mark::Trouble),
            text: text.to_string(),
        };
        list.push(row(2300, Some(Mark::Recovery), "node policy alive again"));
        list.push(row(0, None, "start"));
        list.push(row(2000, Some(Mark::Trouble), "injected stall *policy*"));
        let doc = list.document(true);
        let first = doc.find("First trouble: 2.000 s ▲ injected stall").unwrap();
        let start = doc.find("- 0.000 s · start").unwrap();
        let stall = doc.find("- 2.000 s ▲").unwrap();
        let back = doc.find("- 2.300 s ● node policy alive again").unwrap();
        assert!(first < start && start < stall && stall < back, "{doc}");
        assert!(doc.contains(r"\*policy\*"), "markdown escaped: {doc}");
        let calm = EventList::default().document(true);
        assert!(calm.contains("No trouble"), "{calm}");
    }

    #[test]
    fn a_long_run_s_events_are_counted_past_the_bound() {
        let mut list = EventList::default();
        for i in 0..(MAX_LISTED + 7) {
            list.push(Logged {
                t: Nanos(i as u64),
                mark: Some(Mark::Trouble),
                warn: true,
                text: "x".into(),
            });
        }
        assert_eq!(list.rows.len(), MAX_LISTED);
        assert!(list.document(true).contains("… and 7 more"));
    }

    #[test]
    fn launcher_lines_are_marked_and_placed_at_their_stated_time() {
        let gone =
            "launch: process 'policy' is gone at t=5.57s (its liveliness token was withdrawn)";
        assert_eq!(mark_of_line(gone, "WARN"), Some(Mark::Trouble));
        assert_eq!(stated_time(gone), Some(Nanos(5_570_000_000)));
        let back = "launch: process 'policy' rejoined the run at t=5.59s";
        assert_eq!(mark_of_line(back, "INFO"), Some(Mark::Recovery));
        assert_eq!(mark_of_line("launch: listening on tls/x", "INFO"), None);
        for hostile in ["t=", "t=.", "t=1.2.3s", "at t=-3s", "t=99999999999s"] {
            assert_eq!(stated_time(hostile), None, "{hostile}");
        }
    }

    /// A recording of the chapter's graph (virtual clock) in a folder of its own.
    fn recording() -> (tempfile::TempDir, Recording) {
        let dir = tempfile::tempdir().unwrap();
        let cfg = RunConfig {
            clock: ClockKind::Virtual,
            ..RunConfig::default()
        };
        let path = dir.path().join("r.rrd");
        let (rec, _) =
            Recording::create(&path, &cfg, "scripted", &RecordOptions::default()).unwrap();
        (dir, rec)
    }

    /// The events listed so far: (run time, mark, text), in the list's order.
    fn listed(rec: &Recording) -> Vec<(Nanos, Option<Mark>, String)> {
        rec.lock()
            .events
            .rows
            .iter()
            .map(|r| (r.t, r.mark, r.text.clone()))
            .collect()
    }

    #[test]
    fn events_come_out_in_time_order_and_one_instant_s_in_the_order_logged() {
        let ms = |ms: u64| Nanos(ms * 1_000_000);
        let row = |t: Nanos, text: &str| Logged {
            t,
            mark: None,
            warn: false,
            text: text.to_string(),
        };
        // As a launch's events came before (#73): a rejoin stamped before the kill it
        // follows; and two events of one instant, the process gone before its node.
        let mut list = EventList::default();
        for (t, text) in [
            (ms(3110), "process 'policy' rejoined at t=3.110s"),
            (ms(3027), "process 'policy' killed at t=3.027s"),
            (ms(3080), "process 'policy' failed at t=3.080s"),
            (ms(3080), "node policy not alive"),
            (ms(0), "start"),
        ] {
            list.push(row(t, text));
        }
        let texts: Vec<&str> = list.rows.iter().map(|r| r.text.as_str()).collect();
        assert_eq!(
            texts,
            [
                "start",
                "process 'policy' killed at t=3.027s",
                "process 'policy' failed at t=3.080s",
                "node policy not alive",
                "process 'policy' rejoined at t=3.110s",
            ]
        );
        let doc = list.document(true);
        let at = |needle: &str| {
            doc.find(needle)
                .unwrap_or_else(|| panic!("{needle}: {doc}"))
        };
        assert!(at("- 3.027 s") < at("- 3.080 s · process") && at("not alive") < at("- 3.110 s"));
        // The sort itself: by time, stable.
        let mut v = vec![(ms(5), 'a'), (ms(1), 'b'), (ms(5), 'c'), (ms(1), 'd')];
        in_time_order(&mut v, |r| r.0);
        assert_eq!(
            v.iter().map(|r| r.1).collect::<String>(),
            "bdac",
            "equal stamps keep their order"
        );
    }

    #[test]
    fn a_fault_s_events_start_where_it_took_effect() {
        let s = |ms: u64| Nanos(ms * 1_000_000);
        let stall = ratelab_core::qos::Fault::parse("policy@2+0.5", false).unwrap();
        // From the settings: at its time, as `--stall` always said it.
        let set = fault_events(&stall, Nanos::ZERO, false);
        assert_eq!(set[0].0, s(2000));
        assert_eq!(
            set[0].1,
            "injected stall: node policy does no work and asserts no liveliness for 0.50 s (until 2.50 s)"
        );
        assert_eq!((set[1].0, set[1].3), (s(2500), Some(Mark::Recovery)));
        // Injected live at 2.3 s, its time past: from 2.3 s to its end.
        let live = fault_events(&stall, s(2300), true);
        assert_eq!(
            (live[0].0, live[0].2, live[0].3),
            (s(2300), "WARN", Some(Mark::Trouble))
        );
        assert!(
            live[0].1.starts_with("injected stall (live): node policy"),
            "{}",
            live[0].1
        );
        assert!(
            live[0].1.contains("for 0.20 s (until 2.50 s)"),
            "{}",
            live[0].1
        );
        // Injected after its end: listed, unmarked.
        let late = fault_events(&stall, s(3000), true);
        assert_eq!(late.len(), 1);
        assert_eq!((late[0].2, late[0].3), ("INFO", None));
        let kill = ratelab_core::qos::Fault::parse("policy@1", true).unwrap();
        let killed = fault_events(&kill, s(1500), true);
        assert_eq!(killed.len(), 1);
        assert_eq!((killed[0].0, killed[0].3), (s(1500), Some(Mark::Trouble)));
        assert_eq!(
            killed[0].1,
            "injected kill (live): node policy stops for good"
        );
    }

    #[test]
    fn the_lab_s_stall_key_is_trouble_at_the_run_time_it_took_effect() {
        let (_dir, rec) = recording();
        let stall = ratelab_core::qos::Fault::parse("policy@2.3+2", false).unwrap();
        rec.injected_fault(Nanos(2_300_000_000), &stall);
        // Logged once the run reaches it, at its own time.
        assert!(!listed(&rec).iter().any(|r| r.2.contains("stall")));
        {
            let mut buf = rec.lock();
            rec.log_due_events(&mut buf, Nanos(3_000_000_000), 150);
        }
        let rows = listed(&rec);
        let stalled = rows
            .iter()
            .find(|r| r.2.contains("injected stall (live)"))
            .unwrap();
        assert_eq!(
            (stalled.0, stalled.1),
            (Nanos(2_300_000_000), Some(Mark::Trouble))
        );
        assert!(
            !rows.iter().any(|r| r.2.contains("resumes")),
            "not yet: {rows:?}"
        );
        {
            let mut buf = rec.lock();
            rec.log_due_events(&mut buf, Nanos(5_000_000_000), 250);
        }
        let back = listed(&rec);
        let resumed = back.iter().find(|r| r.2.contains("resumes")).unwrap();
        assert_eq!(
            (resumed.0, resumed.1),
            (Nanos(4_300_000_000), Some(Mark::Recovery))
        );
        assert_eq!(
            rec.lock()
                .events
                .legends
                .get(&Mark::Trouble)
                .map(String::as_str),
            Some("▲ trouble at 2.30 s")
        );
    }

    #[test]
    fn a_clock_switch_a_reload_and_a_ros2_parameter_set_are_marked_changes() {
        let (_dir, rec) = recording();
        let ms = |ms: u64| Nanos(ms * 1_000_000);
        rec.parameter_set(ms(3000), "policy", 10.0);
        rec.clock_switched(ms(1500), ClockKind::Real);
        let reload = "reloaded nodes/x.py: 'policy' restarted in place at t=2.50 s";
        rec.reloaded(ms(2500), reload);
        let rows = listed(&rec);
        let changes: Vec<(Nanos, &str)> = rows
            .iter()
            .filter(|r| r.1 == Some(Mark::Change))
            .map(|r| (r.0, r.2.as_str()))
            .collect();
        assert_eq!(
            changes,
            [
                (
                    ms(1500),
                    "clock switched: the run goes on under the real clock, its state carried across (the time axis stays sim_time)"
                ),
                (ms(2500), reload),
                (
                    ms(3000),
                    "ROS 2 parameter set: policy rate_hz = 10 Hz (ros2 param set)"
                ),
            ],
            "in time order, each marked"
        );
        assert_eq!(
            rec.lock()
                .events
                .legends
                .get(&Mark::Change)
                .map(String::as_str),
            Some("◆ change at 1.50, 2.50, 3.00 s")
        );
        // The graph's own line for that rate is then listed unmarked (its observer).
        assert_eq!(
            *rec.announced.lock().unwrap(),
            [("policy".to_string(), 10.0)]
        );
    }
}
