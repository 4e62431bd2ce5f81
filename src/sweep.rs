//! Sweeps: run the graph over a grid of settings, and find the rate cliff.
//!
//! Runs are independent, so they are spread over the machine's cores; results come back in
//! grid order, so a sweep's table is the same however many threads ran it.

use crate::config::{ClockKind, RunConfig};
use crate::metrics::Metrics;
use crate::policy::Policy;
use crate::run::{run, RunError, RunOptions};
use serde::Serialize;

/// Builds a fresh brain for each run (runs may be on different threads).
pub type BrainFactory<'a> = &'a (dyn Fn() -> Result<Box<dyn Policy>, String> + Sync);

/// One point of a sweep grid.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct Point {
    /// Clock.
    pub clock: ClockKind,
    /// Sensor rate, Hz.
    pub sensor_hz: f64,
    /// Control rate, Hz.
    pub control_hz: f64,
    /// Queue depth.
    pub queue_depth: usize,
    /// Seed.
    pub seed: u64,
}

/// A parameter grid: every combination is run (seed varies fastest).
#[derive(Clone, Debug)]
pub struct Grid {
    /// Clocks.
    pub clocks: Vec<ClockKind>,
    /// Sensor rates, Hz.
    pub sensor_hz: Vec<f64>,
    /// Control rates, Hz.
    pub control_hz: Vec<f64>,
    /// Queue depths.
    pub queue_depth: Vec<usize>,
    /// Seeds.
    pub seeds: Vec<u64>,
    /// Settings not on the grid (duration, actuator rate, spin margin).
    pub base: RunConfig,
}

impl Grid {
    /// Every point, in order: clock, sensor rate, control rate, depth, then seed.
    pub fn points(&self) -> Vec<Point> {
        let mut out = Vec::new();
        for &clock in &self.clocks {
            for &sensor_hz in &self.sensor_hz {
                for &control_hz in &self.control_hz {
                    for &queue_depth in &self.queue_depth {
                        for &seed in &self.seeds {
                            out.push(Point {
                                clock,
                                sensor_hz,
                                control_hz,
                                queue_depth,
                                seed,
                            });
                        }
                    }
                }
            }
        }
        out
    }

    /// The run settings of `p`: the base graph with the point's chain rates and depth.
    ///
    /// # Errors
    /// [`SweepError::Config`] for a rate or depth the graph cannot take.
    pub fn config(&self, p: &Point) -> Result<RunConfig, SweepError> {
        let cfg = RunConfig {
            clock: p.clock,
            seed: p.seed,
            ..self.base.clone()
        };
        Ok(cfg.with_chapter(p.sensor_hz, p.control_hz, p.queue_depth)?)
    }
}

/// A sweep failure.
#[derive(Debug, thiserror::Error)]
pub enum SweepError {
    /// A run could not start.
    #[error(transparent)]
    Run(#[from] RunError),
    /// The brain could not be built.
    #[error("{0}")]
    Brain(String),
    /// A point's settings do not fit the graph.
    #[error(transparent)]
    Config(#[from] crate::config::ConfigError),
    /// A worker thread failed outside any run (a bug): its panic message.
    #[error("sweep worker failed: {0}")]
    Worker(String),
}

/// Run every point of `grid`, `threads` at a time (real-clock points run one at a time so
/// they do not disturb each other's timing). `progress(done, total)` is called after each.
///
/// # Errors
/// The first [`SweepError`].
pub fn run_grid(
    grid: &Grid,
    brain: BrainFactory<'_>,
    threads: usize,
    progress: &(dyn Fn(usize, usize) + Sync),
) -> Result<Vec<(Point, Metrics)>, SweepError> {
    let points = grid.points();
    let total = points.len();
    let done = std::sync::atomic::AtomicUsize::new(0);
    let run_one = |p: &Point| -> Result<Metrics, SweepError> {
        let b = brain().map_err(SweepError::Brain)?;
        let opts = RunOptions {
            keep_trace: false,
            ..RunOptions::default()
        };
        let m = run(&grid.config(p)?, b, opts)?.metrics;
        progress(
            done.fetch_add(1, std::sync::atomic::Ordering::SeqCst) + 1,
            total,
        );
        Ok(m)
    };
    let (virt, real): (Vec<usize>, Vec<usize>) =
        (0..total).partition(|&i| points[i].clock == ClockKind::Virtual);
    let mut results: Vec<Option<Metrics>> = vec![None; total];
    let threads = threads.max(1);
    let chunks: Vec<Vec<usize>> = (0..threads)
        .map(|t| virt.iter().copied().skip(t).step_by(threads).collect())
        .collect();
    let virt_results: Vec<Result<Vec<(usize, Metrics)>, SweepError>> = std::thread::scope(|s| {
        let handles: Vec<_> = chunks
            .iter()
            .map(|idx| {
                s.spawn(|| {
                    idx.iter()
                        .map(|&i| run_one(&points[i]).map(|m| (i, m)))
                        .collect()
                })
            })
            .collect();
        handles
            .into_iter()
            .map(|h| {
                h.join().unwrap_or_else(|p| {
                    Err(SweepError::Worker(crate::scheduler::panic_message(&*p)))
                })
            })
            .collect()
    });
    for chunk in virt_results {
        for (i, m) in chunk? {
            results[i] = Some(m);
        }
    }
    for i in real {
        results[i] = Some(run_one(&points[i])?);
    }
    Ok(points
        .into_iter()
        .zip(results.into_iter().map(|m| m.expect("every point ran")))
        .collect())
}

/// The cliff of one seed: the highest control rate at which the pole falls.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct Cliff {
    /// Seed.
    pub seed: u64,
    /// Highest falling control rate on the search grid, Hz (`None`: never fell).
    pub falls_at_hz: Option<f64>,
    /// The next rate up on the grid, which balanced, Hz.
    pub balances_at_hz: Option<f64>,
    /// Runs made.
    pub runs: usize,
}

/// Find, for `base.seed`, the highest control rate in `[lo_hz, hi_hz]` at which the pole
/// falls, to `step_hz`: every rate on the grid `hi, hi − step, …` is run from the top down
/// until the first fall. No monotonicity is assumed (a scan, not a bisection), so a
/// falling rate above a balancing one cannot be missed. Rates are computed as integer
/// multiples of the step (no float accumulation).
///
/// # Errors
/// [`SweepError`] when a run cannot start.
pub fn find_cliff(
    base: &RunConfig,
    brain: BrainFactory<'_>,
    lo_hz: f64,
    hi_hz: f64,
    step_hz: f64,
) -> Result<Cliff, SweepError> {
    let top = (hi_hz / step_hz).round() as i64;
    let bottom = (lo_hz / step_hz).round() as i64;
    let mut runs = 0;
    for k in (bottom..=top).rev() {
        let hz = (k as f64 * step_hz * 1e6).round() / 1e6;
        let mut cfg = base.clone();
        cfg.set_control_hz(hz)?;
        let opts = RunOptions {
            keep_trace: false,
            ..RunOptions::default()
        };
        let m = run(&cfg, brain().map_err(SweepError::Brain)?, opts)?.metrics;
        runs += 1;
        if !m.balanced {
            let above = (k < top).then(|| ((k + 1) as f64 * step_hz * 1e6).round() / 1e6);
            return Ok(Cliff {
                seed: base.seed,
                falls_at_hz: Some(hz),
                balances_at_hz: above,
                runs,
            });
        }
    }
    Ok(Cliff {
        seed: base.seed,
        falls_at_hz: None,
        balances_at_hz: None,
        runs,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::policy::Scripted;
    use crate::time::Nanos;

    #[test]
    fn grid_order_is_seed_fastest() {
        let g = Grid {
            clocks: vec![ClockKind::Virtual],
            sensor_hz: vec![50.0],
            control_hz: vec![50.0, 5.0],
            queue_depth: vec![1],
            seeds: vec![0, 1],
            base: RunConfig::default(),
        };
        let p = g.points();
        assert_eq!(p.len(), 4);
        assert_eq!((p[1].control_hz, p[1].seed), (50.0, 1));
        assert_eq!((p[2].control_hz, p[2].seed), (5.0, 0));
    }

    #[test]
    fn a_node_that_panics_is_reported_not_fatal() {
        struct Exploding;
        impl Policy for Exploding {
            fn act(&mut self, _: &crate::plant::Observation) -> crate::plant::Action {
                panic!("weights on fire")
            }
            fn label(&self) -> String {
                "exploding".into()
            }
        }
        let g = Grid {
            clocks: vec![ClockKind::Virtual],
            sensor_hz: vec![50.0],
            control_hz: vec![50.0],
            queue_depth: vec![1],
            seeds: vec![0, 1],
            base: RunConfig::default(),
        };
        let brain = || Ok(Box::new(Exploding) as Box<dyn Policy>);
        let rows = run_grid(&g, &brain, 2, &|_, _| {}).unwrap();
        for (_, m) in rows {
            assert!(!m.balanced);
            assert_eq!(m.node_failed.as_deref(), Some("policy: weights on fire"));
            assert!(m.summary_lines(None)[2].starts_with("NODE FAILED (policy: weights on fire)"));
        }
    }

    #[test]
    fn sweep_results_do_not_depend_on_thread_count() {
        let g = Grid {
            clocks: vec![ClockKind::Virtual],
            sensor_hz: vec![50.0],
            control_hz: vec![20.0, 5.0],
            queue_depth: vec![1, 100],
            seeds: vec![0, 1],
            base: RunConfig {
                duration: Nanos(2 * Nanos::SECOND.0),
                ..RunConfig::default()
            },
        };
        let brain = || Ok(Box::new(Scripted) as Box<dyn Policy>);
        let one = run_grid(&g, &brain, 1, &|_, _| {}).unwrap();
        let three = run_grid(&g, &brain, 3, &|_, _| {}).unwrap();
        assert_eq!(one, three);
        assert_eq!(one.len(), 8);
    }
}
