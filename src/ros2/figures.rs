//! What `ratelab ros2 topic hz` and `topic bw` count of a topic's messages, and the lines
//! they print of it every second, as ros2cli's (ros2topic's `verb/hz.py` and `verb/bw.py`,
//! ros2cli 0.36.1; checked against the real command's captures in
//! `../shared/fixtures/ros2-real/kilted-ros2cli/step2/ros2cli/topic-{hz,bw}_*.txt`): `hz`
//! over the intervals between arrivals ([`Rate`]), `bw` over the messages' sizes, every
//! figure in one unit ([`Bandwidth`], [`bw_figures`]). Pure: the caller gives the arrival
//! times (s, from any fixed start) and sizes (bytes, the serialized message as it came).

/// `ros2 topic hz`'s figures (ros2topic's `verb/hz.py`, `ROSTopicHz`): over the newest
/// `window` intervals between arrivals (s), messages a second and the intervals' min, max
/// and standard deviation (over the population, as ros2cli's).
#[derive(Debug, Default)]
pub struct Rate {
    /// Arrival times (s), the newest last: at most `window` + 1, so at most `window`
    /// intervals.
    times: std::collections::VecDeque<f64>,
    /// The most intervals kept (ros2cli's `--window`, default 10000).
    window: usize,
    /// Messages arrived so far, and how many had when the last report was made.
    arrived: u64,
    reported: u64,
}

impl Rate {
    /// A window of `window` intervals (ros2cli's default: 10000; at least 1).
    pub fn new(window: usize) -> Rate {
        Rate {
            window: window.max(1),
            ..Rate::default()
        }
    }

    /// A message arrived at `t_s`.
    pub fn arrived(&mut self, t_s: f64) {
        self.times.push_back(t_s);
        if self.times.len() > self.window + 1 {
            self.times.pop_front();
        }
        self.arrived += 1;
    }

    /// ros2cli's two lines, `window` the intervals they are over:
    /// `average rate: 20.000\n\tmin: 0.050s max: 0.050s std dev: 0.00010s window: 20\n`;
    /// `None` before two messages, and when none arrived since the last report (ros2cli
    /// then prints nothing). The rate is 0 when the intervals' mean is not above 0.
    pub fn report(&mut self) -> Option<String> {
        if self.times.len() < 2 || self.arrived == self.reported {
            return None;
        }
        self.reported = self.arrived;
        let periods: Vec<f64> = self
            .times
            .iter()
            .zip(self.times.iter().skip(1))
            .map(|(a, b)| b - a)
            .collect();
        let n = periods.len();
        let mean = periods.iter().sum::<f64>() / n as f64;
        let rate = if mean > 0.0 { 1.0 / mean } else { 0.0 };
        let var = periods.iter().map(|p| (p - mean).powi(2)).sum::<f64>() / n as f64;
        let min = periods.iter().copied().fold(f64::INFINITY, f64::min);
        let max = periods.iter().copied().fold(f64::NEG_INFINITY, f64::max);
        Some(format!(
            "average rate: {rate:.3}\n\tmin: {min:.3}s max: {max:.3}s std dev: {:.5}s window: {n}\n",
            var.sqrt()
        ))
    }
}

/// `ros2 topic bw`'s figures (ros2topic's `verb/bw.py`, `ROSTopicBandwidth`): over the
/// newest `window` messages, bytes a second (their sizes' sum over the time from the oldest
/// to now) and their mean, min and max size, all in one unit.
#[derive(Debug, Default)]
pub struct Bandwidth {
    /// (arrival time s, size bytes), the newest last, at most `window`.
    seen: std::collections::VecDeque<(f64, usize)>,
    window: usize,
}

/// `ros2 topic bw`'s figures `[rate, mean, min, max]` (bytes) in ros2cli's one unit, the
/// rate's (`verb/bw.py`, "for now I prefer unit consistency"): below 1000 B/s all as whole
/// bytes (`524 B`), below 1,000,000 as KB with two decimals (`1.05 KB`, `0.05 KB`), else
/// MB (powers of 1000).
pub fn bw_figures(figures: [f64; 4]) -> [String; 4] {
    let rate = figures[0];
    figures.map(|n| {
        if rate < 1000.0 {
            format!("{n:.0} B")
        } else if rate < 1_000_000.0 {
            format!("{:.2} KB", n / 1000.0)
        } else {
            format!("{:.2} MB", n / 1000.0 / 1000.0)
        }
    })
}

impl Bandwidth {
    /// A window of `window` messages (ros2cli's default: 100; at least 1).
    pub fn new(window: usize) -> Bandwidth {
        Bandwidth {
            seen: Default::default(),
            window: window.max(1),
        }
    }

    /// A message of `bytes` arrived at `t_s`.
    pub fn arrived(&mut self, t_s: f64, bytes: usize) {
        self.seen.push_back((t_s, bytes));
        if self.seen.len() > self.window {
            self.seen.pop_front();
        }
    }

    /// ros2cli's two lines at `now_s`, or `None` before two messages (ros2cli then prints
    /// nothing; after, it reports every second, new messages or not):
    /// `1.05 KB/s from 20 messages\n\tMessage size mean: 0.05 KB min: 0.05 KB max: 0.05 KB\n`.
    pub fn report(&self, now_s: f64) -> Option<String> {
        let (first, _) = *self.seen.front()?;
        let n = self.seen.len();
        if n < 2 {
            return None;
        }
        let total: usize = self.seen.iter().map(|(_, b)| b).sum();
        let span = (now_s - first).max(1e-9);
        let min = self.seen.iter().map(|(_, b)| *b).min().unwrap_or(0);
        let max = self.seen.iter().map(|(_, b)| *b).max().unwrap_or(0);
        let [rate, mean, min, max] = bw_figures([
            total as f64 / span,
            total as f64 / n as f64,
            min as f64,
            max as f64,
        ]);
        Some(format!(
            "{rate}/s from {n} messages\n\tMessage size mean: {mean} min: {min} max: {max}\n"
        ))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn bw_uses_one_unit_as_ros2cli_does() {
        let mut b = Bandwidth::new(100);
        assert!(b.report(0.0).is_none());
        b.arrived(0.0, 26);
        // One message: ros2cli prints nothing yet.
        assert!(b.report(0.5).is_none());
        for i in 1..20 {
            b.arrived(f64::from(i) * 0.05, 26);
        }
        // Real ros2cli's `topic bw /chatter` (step2/ros2cli/topic-bw_chatter.txt): 20
        // messages of 26 bytes in 0.9922 s since the oldest.
        assert_eq!(
            b.report(0.9922).unwrap(),
            "524 B/s from 20 messages\n\tMessage size mean: 26 B min: 26 B max: 26 B\n"
        );
        // topic-bw_cmd_vel.txt: 52-byte messages at 1.05 KB/s, every figure in KB.
        let mut k = Bandwidth::new(100);
        for i in 0..20 {
            k.arrived(f64::from(i) * 0.05, 52);
        }
        assert_eq!(
            k.report(0.99).unwrap(),
            "1.05 KB/s from 20 messages\n\tMessage size mean: 0.05 KB min: 0.05 KB max: 0.05 KB\n"
        );
        assert_eq!(
            bw_figures([2.5e6, 24_000.0, 1_000.0, 50_000.0]),
            ["2.50 MB", "0.02 MB", "0.00 MB", "0.05 MB"].map(String::from)
        );
        assert_eq!(
            bw_figures([999.0, 10.2, 3.0, 20.0]),
            ["999 B", "10 B", "3 B", "20 B"].map(String::from)
        );
        // The newest `window` messages only.
        let mut w = Bandwidth::new(2);
        for (i, size) in [1000, 10, 20].into_iter().enumerate() {
            w.arrived(i as f64, size);
        }
        assert_eq!(
            w.report(3.0).unwrap(),
            "15 B/s from 2 messages\n\tMessage size mean: 15 B min: 10 B max: 20 B\n"
        );
    }

    #[test]
    fn hz_counts_intervals_as_ros2cli_does() {
        let mut r = Rate::new(10_000);
        assert!(r.report().is_none());
        r.arrived(0.0);
        assert!(r.report().is_none(), "one message is no interval");
        // 20 messages in the first second at 20 Hz: 19 intervals, as real ros2cli's first
        // report said (step2/ros2cli/topic-hz_chatter.txt: `window: 19`).
        for i in 1..20 {
            r.arrived(f64::from(i) * 0.05);
        }
        assert_eq!(
            r.report().unwrap(),
            "average rate: 20.000\n\tmin: 0.050s max: 0.050s std dev: 0.00000s window: 19\n"
        );
        // Nothing new: nothing printed (ros2cli's `get_hz` returns None).
        assert!(r.report().is_none());
        r.arrived(1.0);
        assert!(r.report().unwrap().ends_with("window: 20\n"));
        // A window of 3 keeps the newest 3 intervals (4 arrivals): 1, 2 and 4 s apart.
        let mut small = Rate::new(3);
        for t in [0.0, 10.0, 11.0, 13.0, 17.0] {
            small.arrived(t);
        }
        assert_eq!(
            small.report().unwrap(),
            "average rate: 0.429\n\tmin: 1.000s max: 4.000s std dev: 1.24722s window: 3\n"
        );
        // Messages at one instant: a rate of 0, as ros2cli's `1. / mean if mean > 0. else 0`.
        let mut burst = Rate::new(10);
        for _ in 0..3 {
            burst.arrived(5.0);
        }
        assert!(burst.report().unwrap().starts_with("average rate: 0.000\n"));
    }
}
