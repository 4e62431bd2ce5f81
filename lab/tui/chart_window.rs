//! The charts' time window (pole angle, force): zoomed with `(` and `)` from 0.2 s to the
//! whole run, 10 s to start with; and the whole run's angle and force, kept thinned to a
//! bounded number of points, for the widest window.
//!
//! Finer windows draw the run at full rate: the lab keeps the last [`FULL_RATE_S`] of every
//! step. The whole run is drawn from [`Thinned`]: every step at first, then every other one
//! each time it fills ([`MAX_THINNED`] points at most), so an hour's run costs what a
//! minute's does.

/// The windows, narrowest first; `None` is the whole run.
pub const WINDOWS_S: [Option<f64>; 9] = [
    Some(0.2),
    Some(0.5),
    Some(1.0),
    Some(2.0),
    Some(5.0),
    Some(10.0),
    Some(30.0),
    Some(60.0),
    None,
];

/// Seconds of run time kept at full rate: the widest finite window.
pub const FULL_RATE_S: f64 = 60.0;

/// The most points [`Thinned`] keeps.
pub const MAX_THINNED: usize = 4096;

/// Which of [`WINDOWS_S`] the charts show.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct ChartWindow(usize);

impl Default for ChartWindow {
    /// The last 10 s.
    fn default() -> Self {
        ChartWindow(5)
    }
}

impl ChartWindow {
    /// The next wider window (the whole run stays the whole run).
    pub fn wider(self) -> Self {
        ChartWindow((self.0 + 1).min(WINDOWS_S.len() - 1))
    }

    /// The next narrower window (0.2 s stays 0.2 s).
    pub fn narrower(self) -> Self {
        ChartWindow(self.0.saturating_sub(1))
    }

    /// Its span, s; `None` for the whole run.
    pub fn span_s(self) -> Option<f64> {
        WINDOWS_S[self.0]
    }

    /// The run times it shows, s, `(from, to)`, when the run is at `now_s`: the last span
    /// (the first, before the run has reached it), or from 0 to now for the whole run.
    pub fn bounds(self, now_s: f64) -> (f64, f64) {
        match self.span_s() {
            Some(w) => {
                let to = now_s.max(w);
                (to - w, to)
            }
            None => (0.0, now_s.max(WINDOWS_S[0].unwrap_or(0.2))),
        }
    }

    /// Its words in a chart's title: `last 10 s`, `last 0.2 s`, `whole run`.
    pub fn label(self) -> String {
        match self.span_s() {
            Some(w) => format!("last {w} s"),
            None => "whole run".into(),
        }
    }
}

/// The whole run's (t s, pole angle rad, applied force N), every `stride`-th step.
#[derive(Clone, Debug)]
pub struct Thinned {
    points: Vec<(f64, f64, f64)>,
    stride: usize,
    seen: usize,
}

impl Default for Thinned {
    fn default() -> Self {
        Thinned {
            points: Vec::new(),
            stride: 1,
            seen: 0,
        }
    }
}

impl Thinned {
    /// How many points it holds.
    pub fn kept(&self) -> usize {
        self.points.len()
    }

    /// One actuator step.
    pub fn push(&mut self, t_s: f64, angle_rad: f64, force_n: f64) {
        if self.seen % self.stride == 0 {
            self.points.push((t_s, angle_rad, force_n));
            if self.points.len() >= MAX_THINNED {
                // Keep every other point: those on the doubled stride.
                let mut k = 0;
                self.points.retain(|_| {
                    k += 1;
                    k % 2 == 1
                });
                self.stride *= 2;
            }
        }
        self.seen += 1;
    }

    /// The points kept, oldest first.
    pub fn points(&self) -> &[(f64, f64, f64)] {
        &self.points
    }

    /// Forget the run (a new one starts).
    pub fn clear(&mut self) {
        *self = Thinned::default();
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_window_steps_between_0_2_s_and_the_whole_run() {
        let w = ChartWindow::default();
        assert_eq!((w.span_s(), w.label()), (Some(10.0), "last 10 s".into()));
        assert_eq!(
            w.bounds(4.0),
            (0.0, 10.0),
            "the first 10 s until the run has them"
        );
        assert_eq!(w.bounds(25.0), (15.0, 25.0));
        let mut n = w;
        for _ in 0..20 {
            n = n.narrower();
        }
        assert_eq!(
            (n.label(), n.bounds(25.0)),
            ("last 0.2 s".into(), (24.8, 25.0))
        );
        let mut all = w;
        for _ in 0..20 {
            all = all.wider();
        }
        assert_eq!(
            (all.label(), all.bounds(3600.0)),
            ("whole run".into(), (0.0, 3600.0))
        );
        assert_eq!(all.narrower().span_s(), Some(FULL_RATE_S));
    }

    #[test]
    fn the_whole_run_is_kept_thinned_within_its_bound_and_spans_the_run() {
        let mut t = Thinned::default();
        // An hour at 50 Hz.
        let steps = 3600 * 50;
        for i in 0..steps {
            t.push(i as f64 / 50.0, 0.0, 0.0);
        }
        let p = t.points();
        assert!(
            p.len() < MAX_THINNED && p.len() > MAX_THINNED / 4,
            "{}",
            p.len()
        );
        assert_eq!(p[0].0, 0.0);
        assert!(p[p.len() - 1].0 > 3590.0, "{:?}", p.last());
        // Evenly spaced: every point a whole stride after the one before.
        let gap = p[1].0 - p[0].0;
        assert!(p.windows(2).all(|w| ((w[1].0 - w[0].0) - gap).abs() < 1e-9));
        t.clear();
        assert!(t.points().is_empty());
    }
}

/// One line of a chart kept as the truth's is: the last [`FULL_RATE_S`] at full rate, the
/// whole run in [`Thinned`] (the estimator's θ̂ beside the pole angle).
#[derive(Clone, Debug, Default)]
pub struct Series {
    /// (t s, value) over the last [`FULL_RATE_S`].
    pub recent: std::collections::VecDeque<(f64, f64)>,
    /// The whole run's points (the force slot unused).
    pub whole: Thinned,
}

impl Series {
    /// One point at run time `t_s`, after every earlier one.
    pub fn push(&mut self, t_s: f64, value: f64) {
        self.recent.push_back((t_s, value));
        while self
            .recent
            .front()
            .is_some_and(|(t, _)| t_s - t > FULL_RATE_S)
        {
            self.recent.pop_front();
        }
        self.whole.push(t_s, value, 0.0);
    }
}
