//! The run's events placed in time, three ways at once: a row of the `events` text log
//! (at its run time, with its level), a mark on the pole-angle plot (`marks/change` ◆,
//! `marks/trouble` ▲, `marks/recovery` ●, in a row under the lower fall limit; the fall's ×
//! is `plant/fall`, at the pole's angle) whose legend names the times, and a line of the `when` document, which lists
//! every event in time order and names the first trouble at its top. The document is what a
//! reviewer reads first: the stock viewer labels a plot's time axis only at power-of-ten
//! steps at least about 150 px apart, so a plot alone cannot say when something happened
//! ("+0s" alone under a 10 s run at 1280×720).

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

    /// A legend's name for the mark, with the times it was set: `▲ trouble at 2.00, 2.04,
    /// 2.30 s`, and past three `… (7 in all)`.
    pub(super) fn legend(self, times: &[Nanos]) -> String {
        let shown: Vec<String> = times
            .iter()
            .take(3)
            .map(|t| format!("{:.2}", t.as_secs_f64()))
            .collect();
        let more = if times.len() > 3 {
            format!(", … ({} in all)", times.len())
        } else {
            String::new()
        };
        if shown.is_empty() {
            format!("{} {}", self.symbol(), self.words())
        } else {
            format!(
                "{} {} at {}{more} s",
                self.symbol(),
                self.words(),
                shown.join(", ")
            )
        }
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

impl EventList {
    fn push(&mut self, row: Logged) {
        if self.rows.len() < MAX_LISTED {
            self.rows.push(row);
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
        rows.sort_by_key(|r| r.t);
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
        self.add(
            m.entity(),
            &TimePoint::default(),
            &rerun::SeriesPoints::new()
                .with_names([name])
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
            "● recovered at 0.00, 0.00, 0.00, … (4 in all) s"
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
}
