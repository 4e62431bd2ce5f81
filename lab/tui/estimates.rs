//! The estimator as the lab keeps it, step by step: with an estimator in the graph each
//! actuator step's record carries the plant's state beside the newest estimate
//! ([`ratelab::estimate::EstimatePoint`], `StepRecord::estimate`), and the lab keeps three
//! lines of it for the charts — the pole angle's estimate θ̂, the pole's angular velocity θ̇
//! and its estimate — and the estimate's error and lag folded exactly as the run's summary
//! folds them ([`ratelab::estimate::EstimateError`], the fold `RunLog::push` makes): the
//! same points, in the same order, through the same function, so the figures the lab shows
//! are the summary's line's.
//!
//! Each point is drawn where the pole-angle line shows the state it is of: a point's truth
//! is the plant's state before its step, which is the state the step before reached, drawn
//! at that step's run time. The first step, with no step before it, draws nothing (its
//! point is still folded into the figures).

use super::chart_window::Series;
use ratelab::estimate::{EstimateError, EstimateFigures, EstimateReport, POLE_ANGLE, POLE_ANGVEL};
use ratelab::runlog::StepRecord;

/// What the lab keeps of a run's estimator ([`Estimates::push`] each step).
#[derive(Clone, Debug, Default)]
pub struct Estimates {
    /// (t s, θ̂ rad): the pole angle's estimate, drawn beside the angle.
    pub angle: Series,
    /// (t s, θ̇ rad/s): the plant's angular velocity the estimate is of.
    pub angvel: Series,
    /// (t s, θ̇ estimate rad/s): the estimator's angular velocity, differenced from noisy
    /// angles and smoothed (exercise ex8's noise).
    pub angvel_estimate: Series,
    /// The estimate's error and lag so far, folded as the run's summary folds them.
    error: EstimateError,
    /// The figures the run's summary gave when it ended (its `Ended` metrics), when they
    /// came: they then stand for the lab's own fold.
    ended: Option<EstimateFigures>,
    /// The run time of the step before, s.
    previous_s: Option<f64>,
}

impl Estimates {
    /// How many points its lines hold, recent and thinned (a checkpoint's size,
    /// `app/checkpoints.rs`).
    pub fn points(&self) -> usize {
        [&self.angle, &self.angvel, &self.angvel_estimate]
            .iter()
            .map(|s| s.recent.len() + s.whole.kept())
            .sum()
    }

    /// One actuator step (every step, in order): its point folded, and drawn at the step
    /// before's run time.
    pub fn push(&mut self, s: &StepRecord) {
        let at_s = self.previous_s.replace(s.t.as_secs_f64());
        let Some(p) = s.estimate.as_deref() else {
            return;
        };
        // As `RunLog::push` folds it for the summary.
        self.error.push(s.t, p);
        let Some(at_s) = at_s else {
            return;
        };
        self.angvel.push(at_s, p.truth[POLE_ANGVEL]);
        if let Some(e) = p.estimate {
            self.angle.push(at_s, e[POLE_ANGLE]);
            self.angvel_estimate.push(at_s, e[POLE_ANGVEL]);
        }
    }

    /// The run ended with `report`, its summary's estimator figures (`None` when its
    /// metrics carry none: the lab's own fold stands).
    pub fn ended(&mut self, report: Option<&EstimateReport>) {
        self.ended = report.map(|r| r.figures.clone());
    }

    /// The figures so far (the summary's once the run has ended); `None` before the first
    /// point.
    pub fn figures(&self) -> Option<EstimateFigures> {
        self.ended.clone().or_else(|| self.error.figures())
    }

    /// Forget the run (a new one starts, or a seek folds it again).
    pub fn clear(&mut self) {
        *self = Estimates::default();
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use ratelab::{run, ClockKind, RunConfig, RunOptions};

    /// Folded step by step, the lab's figures are the run's summary's, to the bit, before
    /// and after the run's end says them.
    #[test]
    fn the_figures_are_the_summary_s() {
        let cfg = RunConfig {
            clock: ClockKind::Virtual,
            duration: ratelab::Nanos(3_000_000_000),
            graph: ratelab::graph::GraphSpec::load(
                &std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
                    .join("../graphs/cartpole-estimator.toml"),
            )
            .unwrap(),
            ..RunConfig::default()
        };
        let report = run(&cfg, Box::new(ratelab::policy::Scripted), RunOptions::new()).unwrap();
        let summary = report.metrics.estimate.clone().expect("an estimator");
        let mut e = Estimates::default();
        assert_eq!(e.figures(), None);
        for s in &report.trace {
            e.push(s);
        }
        assert_eq!(e.figures(), Some(summary.figures.clone()));
        assert!(e.figures().unwrap().lag_measured);
        // Every step but the first draws a point of each line.
        let n = report.trace.len() - 1;
        assert_eq!(e.angvel.recent.len(), n);
        assert_eq!(e.angvel_estimate.recent.len(), n);
        assert_eq!(e.angle.recent.len(), n);
        e.ended(Some(&summary));
        assert_eq!(e.figures(), Some(summary.figures));
        e.clear();
        assert_eq!(e.figures(), None);
        assert!(e.angvel.recent.is_empty());
    }
}
