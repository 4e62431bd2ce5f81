//! The readout at the scrub cursor. Paused under the virtual clock (or reviewing an ended
//! real-clock run), ← and → put the run at an instant, the cursor, and the pole-angle
//! chart's and the force band's titles read the run there: the cursor's run time, the
//! pole's angle θ and rate θ̇, the force the actuator applied and the age of the command it
//! holds (the zero-order hold re-applies a command until a newer one arrives: its age is the
//! time since it was published), and the selected topic's counters (a node's: its first
//! topic's).
//!
//! Every value is the actuator's step record at or before the cursor
//! ([`ratelab::runlog::StepRecord`]), the record `trace.csv`'s row for that tick is written
//! from, so the readout and the trace agree; θ̇ and the command's age are in the record,
//! not among the file's columns. The app builds a [`Readout`] each frame (a view model,
//! immutable once built); [`Readout::plant_line`] and [`Readout::hold_line`] give its two
//! lines, each the fullest of its forms that fits the title. With the estimator's chart
//! shown (`view/estimator.rs`), [`Readout::estimate_line`] reads the tick's estimate of θ̇
//! beside the truth it is of, the pair the run's summary folds into its error.

use ratatui::text::Span;
use ratelab::plant::GEAR_N;
use ratelab::runlog::StepRecord;
use ratelab::text::signed as s;
use ratelab::Nanos;

/// A topic's counters at the readout's tick, as the lab's arrows count them live.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct TopicCounts {
    /// The topic's name (`/obs`).
    pub topic: String,
    /// Messages published so far.
    pub msgs: u64,
    /// Messages dropped so far (evicted before any read caught up with them).
    pub dropped: u64,
    /// Reads so far that found nothing new.
    pub stale_reads: u64,
    /// Its QoS counters that counted so far, labelled as its arrow labels them (`lost`,
    /// `dl miss`, …).
    pub qos: Vec<(&'static str, u64)>,
}

/// The run at the scrub cursor, from the actuator's tick at or before it.
#[derive(Clone, Debug, PartialEq)]
pub struct Readout {
    /// The cursor's run time, s.
    pub cursor_s: f64,
    /// The run time of the actuator's tick read (the newest at or before the cursor), s
    /// (`trace.csv`'s `t_ns`).
    pub step_s: f64,
    /// The pole's angle after that tick, rad (`trace.csv`'s `pole_angle`).
    pub theta_rad: f64,
    /// The pole's angular velocity after that tick, rad/s.
    pub theta_dot_rad_s: f64,
    /// With an estimator in the graph: at that tick, the plant's θ̇ before its step and the
    /// newest estimate of it, rad/s (`None`: none yet) — the tick's
    /// [`ratelab::estimate::EstimatePoint`].
    pub angvel_pair: Option<(f64, Option<f64>)>,
    /// The force applied at that tick, N (`trace.csv`'s `action` × [`GEAR_N`]).
    pub force_n: f64,
    /// The age of the command the actuator held at that tick, ms: the time since it was
    /// published (`None`: it held none, before the first or zeroed by a missed deadline).
    pub age_ms: Option<f64>,
    /// The selected topic's counters at that tick (`None`: nothing selected).
    pub counters: Option<TopicCounts>,
}

impl Readout {
    /// The readout with the cursor at `cursor`, of `rec` (the actuator's tick at or before
    /// it) and the selected topic's `counters` at that tick.
    pub fn at(cursor: Nanos, rec: &StepRecord, counters: Option<TopicCounts>) -> Readout {
        Readout {
            cursor_s: cursor.as_secs_f64(),
            step_s: rec.t.as_secs_f64(),
            theta_rad: rec.pole_angle,
            theta_dot_rad_s: rec.pole_angvel,
            angvel_pair: rec.estimate.as_deref().map(|p| {
                let i = ratelab::estimate::POLE_ANGVEL;
                (p.truth[i], p.estimate.map(|e| e[i]))
            }),
            force_n: rec.action * GEAR_N,
            age_ms: rec
                .held_stamp
                .map(|stamp| rec.t.saturating_sub(stamp).as_millis_f64()),
            counters,
        }
    }

    /// The plant's line, for the pole-angle chart's title `room` columns wide:
    /// `t=2.340 s · θ +0.0123 rad · θ̇ -0.045 rad/s` (with `(tick 2.320 s)` after the run
    /// time when the tick read is before the cursor), or a shorter form that fits.
    pub fn plant_line(&self, room: usize) -> String {
        let t = self.when();
        let (theta, dot) = (self.theta_rad, self.theta_dot_rad_s);
        fit(
            [
                format!("{t} · θ {} rad · θ̇ {} rad/s", s(theta, 4), s(dot, 3)),
                format!("{t} θ {} rad θ̇ {} rad/s", s(theta, 4), s(dot, 3)),
                format!("{t} θ {} θ̇ {}", s(theta, 3), s(dot, 2)),
            ],
            room,
        )
    }

    /// `t=2.340 s`, or `t=2.350 s (tick 2.340 s)` when the tick read is before the cursor.
    fn when(&self) -> String {
        if (self.cursor_s - self.step_s).abs() < 5e-7 {
            format!("t={:.3} s", self.cursor_s)
        } else {
            format!("t={:.3} s (tick {:.3} s)", self.cursor_s, self.step_s)
        }
    }

    /// The estimator's line, for its chart's title `room` columns wide: the tick's θ̇ (the
    /// plant's, before the step) and its estimate, `t=2.340 s · θ̇ -0.045 · est -0.051
    /// rad/s · error -6.0 mrad/s`, or a shorter form that fits; [`Readout::plant_line`]
    /// without an estimator.
    pub fn estimate_line(&self, room: usize) -> String {
        let Some((truth, estimate)) = self.angvel_pair else {
            return self.plant_line(room);
        };
        let t = self.when();
        match estimate {
            Some(e) => fit(
                [
                    format!(
                        "{t} · θ̇ {} · est {} rad/s · error {} mrad/s",
                        s(truth, 3),
                        s(e, 3),
                        s((e - truth) * 1e3, 1)
                    ),
                    format!("{t} · θ̇ {} · est {} rad/s", s(truth, 3), s(e, 3)),
                    format!("{t} θ̇ {} est {}", s(truth, 2), s(e, 2)),
                ],
                room,
            ),
            None => fit(
                [
                    format!("{t} · θ̇ {} rad/s · no estimate yet", s(truth, 3)),
                    format!("{t} θ̇ {} no est", s(truth, 2)),
                ],
                room,
            ),
        }
    }

    /// The hold's line, for the force band's title `room` columns wide: the force applied,
    /// the held command's age and the selected topic's counters, `F +3.20 N · cmd 40 ms old
    /// · /obs 151 msgs, 37 dropped, 38 stale`, or a shorter form that fits (the counters'
    /// words shortened first, then the topic's name, then the counters left out).
    pub fn hold_line(&self, room: usize) -> String {
        let force = format!("F {} N", s(self.force_n, 2));
        let (age, age_short) = match self.age_ms {
            Some(a) => (format!("cmd {} ms old", ms(a)), format!("{} ms old", ms(a))),
            None => ("no cmd yet".to_string(), "no cmd".to_string()),
        };
        let Some(c) = &self.counters else {
            return fit(
                [format!("{force} · {age}"), format!("{force}, {age_short}")],
                room,
            );
        };
        let mut long = format!("{} {} msgs, {} dropped", c.topic, c.msgs, c.dropped);
        let mut medium = format!("{} {} msg {} drop", c.topic, c.msgs, c.dropped);
        if c.stale_reads > 0 {
            long.push_str(&format!(", {} stale", c.stale_reads));
            medium.push_str(&format!(" {}↺", c.stale_reads));
        }
        for (label, n) in c.qos.iter().filter(|(_, n)| *n > 0) {
            long.push_str(&format!(", {n} {label}"));
            medium.push_str(&format!(" {n} {label}"));
        }
        let short = format!("{} {} msg {} drop", c.topic, c.msgs, c.dropped);
        let nameless = format!("{} msg {} drop", c.msgs, c.dropped);
        fit(
            [
                format!("{force} · {age} · {long}"),
                format!("{force} · {age} · {medium}"),
                format!("{force}, {age_short} · {medium}"),
                format!("{force}, {age_short} · {short}"),
                format!("{force}, {age_short} · {nameless}"),
                format!("{force}, {age_short}"),
            ],
            room,
        )
    }
}

/// A time in ms as the readout says it: whole, or to the tenth (`40`, `12.5`).
fn ms(x: f64) -> String {
    let tenths = (x * 10.0).round() / 10.0;
    if tenths.fract() == 0.0 {
        format!("{tenths:.0}")
    } else {
        format!("{tenths:.1}")
    }
}

/// The first of `forms` (fullest first) whose width on screen fits `room` columns, else
/// the last.
fn fit<const N: usize>(forms: [String; N], room: usize) -> String {
    let mut last = String::new();
    for f in forms {
        if Span::raw(f.as_str()).width() <= room {
            return f;
        }
        last = f;
    }
    last
}

#[cfg(test)]
mod tests {
    use super::*;
    use ratelab::runlog::TopicCounters;

    #[test]
    fn a_zero_reads_plus_zero_and_other_numbers_keep_their_sign() {
        let mut r = Readout::at(Nanos(2_340_000_000), &tick(), Some(obs()));
        r.theta_rad = -0.000_01;
        r.force_n = -0.001;
        assert!(
            r.plant_line(80).contains("θ +0.0000 rad · θ̇ -0.045 rad/s"),
            "{}",
            r.plant_line(80)
        );
        assert!(
            r.hold_line(80).starts_with("F +0.00 N"),
            "{}",
            r.hold_line(80)
        );
    }

    /// The actuator's tick at 2.34 s: θ 0.0123 rad, θ̇ −0.045 rad/s, action 0.32 (3.2 N),
    /// holding a command published at 2.30 s.
    fn tick() -> StepRecord {
        StepRecord {
            step: 118,
            t: Nanos(2_340_000_000),
            pole_angle: 0.0123,
            pole_angvel: -0.045,
            cart_pos: 0.1,
            action: 0.32,
            latency: Some(Nanos(60_000_000)),
            held_stamp: Some(Nanos(2_300_000_000)),
            nonfinite: false,
            topics: TopicCounters::default(),
            published: None,
            fell: false,
            estimate: None,
        }
    }

    fn obs() -> TopicCounts {
        TopicCounts {
            topic: "/obs".into(),
            msgs: 118,
            dropped: 37,
            stale_reads: 0,
            qos: Vec::new(),
        }
    }

    #[test]
    fn the_readout_reads_the_tick_at_the_cursor() {
        let r = Readout::at(Nanos(2_340_000_000), &tick(), Some(obs()));
        assert_eq!(r.step_s, 2.34);
        assert_eq!(r.force_n, 0.32 * GEAR_N);
        assert_eq!(r.age_ms, Some(40.0));
        // Wide (120 columns: the chart's title has 70).
        assert_eq!(
            r.plant_line(70),
            "t=2.340 s · θ +0.0123 rad · θ̇ -0.045 rad/s"
        );
        assert_eq!(
            r.hold_line(70),
            "F +3.20 N · cmd 40 ms old · /obs 118 msgs, 37 dropped"
        );
        // At 80 columns the chart's title has 46, less its padding.
        assert_eq!(
            r.plant_line(44),
            "t=2.340 s · θ +0.0123 rad · θ̇ -0.045 rad/s"
        );
        assert_eq!(
            r.hold_line(44),
            "F +3.20 N, 40 ms old · /obs 118 msg 37 drop"
        );
        // Narrower still: the topic's name, then its counters give way.
        assert_eq!(r.hold_line(38), "F +3.20 N, 40 ms old · 118 msg 37 drop");
        assert_eq!(r.hold_line(20), "F +3.20 N, 40 ms old");
        assert_eq!(r.plant_line(30), "t=2.340 s θ +0.012 θ̇ -0.04");
    }

    #[test]
    fn the_readout_says_stale_reads_qos_counts_and_no_command() {
        let mut rec = tick();
        rec.held_stamp = None;
        rec.action = 0.0;
        let counts = TopicCounts {
            topic: "/action".into(),
            msgs: 30,
            dropped: 0,
            stale_reads: 87,
            qos: vec![("lost", 3), ("expired", 0)],
        };
        let r = Readout::at(Nanos(2_340_000_000), &rec, Some(counts));
        assert_eq!(r.age_ms, None);
        assert_eq!(
            r.hold_line(80),
            "F +0.00 N · no cmd yet · /action 30 msgs, 0 dropped, 87 stale, 3 lost"
        );
        assert_eq!(
            r.hold_line(60),
            "F +0.00 N · no cmd yet · /action 30 msg 0 drop 87↺ 3 lost"
        );
        // Nothing selected: the force and the command alone.
        let r = Readout::at(Nanos(2_340_000_000), &tick(), None);
        assert_eq!(r.hold_line(44), "F +3.20 N · cmd 40 ms old");
    }

    /// With an estimator, the estimator's line reads the tick's θ̇ beside its estimate and
    /// their difference; without one it is the plant's line.
    #[test]
    fn the_estimate_line_reads_the_tick_s_estimate_beside_its_truth() {
        let r = Readout::at(Nanos(2_340_000_000), &tick(), None);
        assert_eq!(r.angvel_pair, None);
        assert_eq!(r.estimate_line(70), r.plant_line(70));
        let mut rec = tick();
        rec.estimate = Some(Box::new(ratelab::estimate::EstimatePoint {
            truth: [0.1, 0.0, 0.0123, -0.045],
            estimate: Some([0.1, 0.0, 0.0121, -0.051]),
            nonfinite: false,
        }));
        let r = Readout::at(Nanos(2_340_000_000), &rec, None);
        assert_eq!(r.angvel_pair, Some((-0.045, Some(-0.051))));
        assert_eq!(
            r.estimate_line(70),
            "t=2.340 s · θ̇ -0.045 · est -0.051 rad/s · error -6.0 mrad/s"
        );
        // At 80 columns the chart's title has 46, less its padding.
        assert_eq!(
            r.estimate_line(44),
            "t=2.340 s · θ̇ -0.045 · est -0.051 rad/s"
        );
        assert_eq!(r.estimate_line(30), "t=2.340 s θ̇ -0.04 est -0.05");
        rec.estimate.as_mut().unwrap().estimate = None;
        let r = Readout::at(Nanos(2_340_000_000), &rec, None);
        assert_eq!(
            r.estimate_line(70),
            "t=2.340 s · θ̇ -0.045 rad/s · no estimate yet"
        );
    }

    #[test]
    fn a_cursor_between_ticks_says_which_tick_it_reads() {
        // A 40 Hz node's tick at 2.35 s: the actuator's last was at 2.34 s.
        let r = Readout::at(Nanos(2_350_000_000), &tick(), None);
        assert_eq!(
            r.plant_line(70),
            "t=2.350 s (tick 2.340 s) · θ +0.0123 rad · θ̇ -0.045 rad/s"
        );
        assert_eq!(ms(12.5), "12.5");
        assert_eq!(ms(40.000_000_1), "40");
    }

    /// The readout's values are `trace.csv`'s at the tick: both are written from the same
    /// step record (a run's own trace, written as `ratelab run --out` writes it).
    #[test]
    fn the_readout_equals_the_trace_at_its_tick() {
        use ratelab::trace_csv::{qos_columns, TraceWriter};
        let mut cfg = ratelab::RunConfig {
            clock: ratelab::ClockKind::Virtual,
            duration: Nanos(2_000_000_000),
            ..ratelab::RunConfig::default()
        };
        cfg.set_control_hz(8.0).unwrap();
        let report = ratelab::run(
            &cfg,
            Box::new(ratelab::policy::Scripted),
            ratelab::RunOptions::new(),
        )
        .unwrap();
        let mut csv = TraceWriter::new(
            Vec::new(),
            &cfg.graph,
            qos_columns(&cfg.graph, report.trace.last().map(|r| &r.topics)),
        )
        .unwrap();
        for r in &report.trace {
            csv.row(r).unwrap();
        }
        let csv = String::from_utf8(csv.finish().unwrap()).unwrap();
        let header: Vec<&str> = csv.lines().next().unwrap().split(',').collect();
        let col = |name: &str| header.iter().position(|h| *h == name).unwrap();
        let rec = &report.trace[61]; // t = 1.22 s (the actuator ticks from 0)
        let t_ns = rec.t.0.to_string();
        let row: Vec<&str> = csv
            .lines()
            .find(|l| l.split(',').nth(col("t_ns")) == Some(t_ns.as_str()))
            .unwrap()
            .split(',')
            .collect();
        let cell = |name: &str| -> f64 { row[col(name)].parse().unwrap() };
        let obs = rec.topics.get(ratelab::graph::TopicId(0));
        let counts = TopicCounts {
            topic: "/obs".into(),
            msgs: obs.published,
            dropped: obs.dropped,
            stale_reads: obs.stale_reads,
            qos: Vec::new(),
        };
        let r = Readout::at(rec.t, rec, Some(counts));
        assert_eq!(r.step_s, cell("t_ns") / 1e9);
        assert_eq!(r.theta_rad, cell("pole_angle"));
        assert_eq!(r.force_n, cell("action") * GEAR_N);
        assert_eq!(
            r.counters.as_ref().unwrap().msgs as f64,
            cell("obs_published")
        );
        assert_eq!(
            r.counters.as_ref().unwrap().dropped as f64,
            cell("obs_dropped")
        );
        assert!(r.counters.as_ref().unwrap().dropped > 0, "8 Hz drops /obs");
        // The held command's age: an 8 Hz policy's command is at most 125 ms old.
        let age = r.age_ms.unwrap();
        assert!((0.0..=125.0).contains(&age), "{age}");
    }
}
