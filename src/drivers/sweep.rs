//! Sweeps: run the graph over a grid of settings, and find the rate cliff.
//!
//! Runs are independent, so they are spread over the machine's cores; results come back in
//! grid order, so a sweep's table is the same however many threads ran it. Their tables as
//! CSV ([`write_csv`], [`write_cliffs_csv`]) are every front end's: `ratelab sweep --csv`
//! writes the one `ratelab.sweep` returns. What to sweep, as data, checked once in the front
//! end's words: [`crate::sweep_spec`].

use crate::run::{run, RunError, RunOptions};
use ratelab_core::metrics::Metrics;
use ratelab_core::time::Nanos;
use ratelab_runtime::config::{ClockKind, RunConfig};
use ratelab_runtime::policy::Policy;
use ratelab_runtime::scheduler::{EndReason, StopFlag};
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

    /// The run settings of `p`: the base graph with the point's chain rates and depth. The
    /// base's spin margin is capped at half the point's fastest period (a grid has no
    /// margin of its own to get wrong per point).
    ///
    /// # Errors
    /// [`SweepError::Config`] for a rate or depth the graph cannot take.
    pub fn config(&self, p: &Point) -> Result<RunConfig, SweepError> {
        let cfg = RunConfig {
            clock: p.clock,
            seed: p.seed,
            ..self.base.clone()
        };
        let cfg = cfg.with_chapter(p.sensor_hz, p.control_hz, p.queue_depth)?;
        Ok(RunConfig {
            spin_margin: cfg.spin_margin.min(Nanos(cfg.fastest_period().0 / 2)),
            ..cfg
        })
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
    Config(#[from] ratelab_runtime::config::ConfigError),
    /// A worker thread failed outside any run (a bug): its panic message.
    #[error("sweep worker failed: {0}")]
    Worker(String),
    /// A node failed in a run of the cliff's search: that run neither balanced nor fell,
    /// so no rate can be called the cliff.
    #[error("seed {seed} at control {hz} Hz: node {failed}: the cliff cannot be found past a failed node")]
    NodeFailed {
        /// The run's seed.
        seed: u64,
        /// Its control rate, Hz.
        hz: f64,
        /// The failed node and its error (`policy: …`).
        failed: String,
    },
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
    run_grid_until(grid, brain, threads, progress, &StopFlag::new())
}

/// [`run_grid`] that stops early when `stop` is set (Ctrl-C): the run in progress ends at
/// once (its partial metrics are dropped), no further point starts, and the points that
/// completed are returned, in grid order.
///
/// # Errors
/// The first [`SweepError`].
pub fn run_grid_until(
    grid: &Grid,
    brain: BrainFactory<'_>,
    threads: usize,
    progress: &(dyn Fn(usize, usize) + Sync),
    stop: &StopFlag,
) -> Result<Vec<(Point, Metrics)>, SweepError> {
    let points = grid.points();
    let total = points.len();
    let done = std::sync::atomic::AtomicUsize::new(0);
    let run_one = |p: &Point| -> Result<Option<Metrics>, SweepError> {
        if stop.is_stopped() {
            return Ok(None);
        }
        let b = brain().map_err(SweepError::Brain)?;
        // The run's own flag: a fall under the real clock sets it to stop that run's
        // threads, and must not end the points after it; Ctrl-C (`stop`) reaches it.
        let opts = RunOptions {
            keep_trace: false,
            stop: stop.child(),
            ..RunOptions::default()
        };
        let report = run(&grid.config(p)?, b, opts)?;
        if report.end.reason == EndReason::Interrupted {
            return Ok(None);
        }
        progress(
            done.fetch_add(1, std::sync::atomic::Ordering::SeqCst) + 1,
            total,
        );
        Ok(Some(report.metrics))
    };
    let (virt, real): (Vec<usize>, Vec<usize>) =
        (0..total).partition(|&i| points[i].clock == ClockKind::Virtual);
    let mut results: Vec<Option<Metrics>> = vec![None; total];
    let threads = threads.max(1);
    let chunks: Vec<Vec<usize>> = (0..threads)
        .map(|t| virt.iter().copied().skip(t).step_by(threads).collect())
        .collect();
    type Done = Vec<(usize, Option<Metrics>)>;
    let virt_results: Vec<Result<Done, SweepError>> = std::thread::scope(|s| {
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
                    Err(SweepError::Worker(
                        ratelab_runtime::scheduler::panic_message(&*p),
                    ))
                })
            })
            .collect()
    });
    for chunk in virt_results {
        for (i, m) in chunk? {
            results[i] = m;
        }
    }
    for i in real {
        results[i] = run_one(&points[i])?;
    }
    let stopped = stop.is_stopped();
    Ok(points
        .into_iter()
        .zip(results)
        .filter_map(|(p, m)| {
            assert!(stopped || m.is_some(), "every point ran");
            m.map(|m| (p, m))
        })
        .collect())
}

/// `f` applied to every item on a pool of `threads` workers (at least one, at most one per
/// item), each taking the next item as it finishes the last; results in item order. A
/// panic in `f` is re-raised here.
pub fn run_pool<T: Sync, R: Send>(
    items: &[T],
    threads: usize,
    f: impl Fn(&T) -> R + Sync,
) -> Vec<R> {
    let next = std::sync::atomic::AtomicUsize::new(0);
    let workers = threads.clamp(1, items.len().max(1));
    let mut done: Vec<(usize, R)> = std::thread::scope(|s| {
        let handles: Vec<_> = (0..workers)
            .map(|_| {
                s.spawn(|| {
                    let mut out = Vec::new();
                    loop {
                        let i = next.fetch_add(1, std::sync::atomic::Ordering::SeqCst);
                        let Some(item) = items.get(i) else { break };
                        out.push((i, f(item)));
                    }
                    out
                })
            })
            .collect();
        handles
            .into_iter()
            .flat_map(|h| h.join().unwrap_or_else(|p| std::panic::resume_unwind(p)))
            .collect()
    });
    done.sort_by_key(|(i, _)| *i);
    done.into_iter().map(|(_, r)| r).collect()
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
/// [`SweepError`] when a run cannot start, or [`SweepError::NodeFailed`] when a node of a
/// run failed (a run that did not balance because its brain raised is no fall).
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
        if let Some(failed) = m.node_failed {
            return Err(SweepError::NodeFailed {
                seed: base.seed,
                hz,
                failed,
            });
        }
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

/// The line of a sweep whose runs failed a node: how many of all, and the first (its control
/// rate, seed and failure); `None` when none did. A sweep that has it is no success.
pub fn failed_line(rows: &[(Point, Metrics)]) -> Option<String> {
    let failed: Vec<&(Point, Metrics)> = rows
        .iter()
        .filter(|(_, m)| m.node_failed.is_some())
        .collect();
    let (p, m) = failed.first()?;
    Some(format!(
        "{} of {} runs failed a node (the first, control {} Hz seed {}: {})",
        failed.len(),
        rows.len(),
        p.control_hz,
        p.seed,
        m.node_failed.as_deref().unwrap_or("?")
    ))
}

/// A sweep's rows as CSV into `out`, as `ratelab sweep --csv` writes them: a header, then a
/// row per run, its point (`clock`, `sensor_hz`, `control_hz` in Hz, `queue_depth` in
/// messages, `seed`) and figures (`balanced`, `steps`, `fell_at_s` in s, the `/obs` and
/// `/action` counts, `mean_latency_ms`, `latency_p99_ms`, `policy`); a figure the run has
/// none of is an empty cell.
///
/// # Errors
/// What writing to `out` gives.
pub fn write_csv(out: &mut dyn std::io::Write, rows: &[(Point, Metrics)]) -> anyhow::Result<()> {
    let mut w = csv::Writer::from_writer(out);
    w.write_record([
        "clock",
        "sensor_hz",
        "control_hz",
        "queue_depth",
        "seed",
        "balanced",
        "steps",
        "fell_at_s",
        "obs_published",
        "obs_dropped",
        "action_published",
        "action_dropped",
        "mean_latency_ms",
        "latency_p99_ms",
        "policy",
    ])?;
    let opt = |x: Option<u64>| x.map_or(String::new(), |x| x.to_string());
    for (p, m) in rows {
        w.write_record([
            p.clock.as_str().to_string(),
            p.sensor_hz.to_string(),
            p.control_hz.to_string(),
            p.queue_depth.to_string(),
            p.seed.to_string(),
            m.balanced.to_string(),
            m.steps.to_string(),
            m.fell_at_s.map_or(String::new(), |t| t.to_string()),
            opt(m.obs_published),
            opt(m.obs_dropped),
            opt(m.action_published),
            opt(m.action_dropped),
            m.mean_latency_ms.to_string(),
            m.latency_p99_ms.to_string(),
            m.policy.clone(),
        ])?;
    }
    w.flush()?;
    Ok(())
}

/// A cliff search's results as CSV into `out`: `seed,falls_at_hz,balances_at_hz,runs`, a row
/// per seed (rates in Hz; a rate is an empty cell when there is none).
///
/// # Errors
/// What writing to `out` gives.
pub fn write_cliffs_csv(out: &mut dyn std::io::Write, cliffs: &[Cliff]) -> anyhow::Result<()> {
    let mut w = csv::Writer::from_writer(out);
    w.write_record(["seed", "falls_at_hz", "balances_at_hz", "runs"])?;
    let hz = |x: Option<f64>| x.map_or_else(String::new, |x| x.to_string());
    for c in cliffs {
        w.write_record([
            c.seed.to_string(),
            hz(c.falls_at_hz),
            hz(c.balances_at_hz),
            c.runs.to_string(),
        ])?;
    }
    w.flush()?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use ratelab_runtime::policy::Scripted;

    #[test]
    fn the_pool_keeps_order_and_uses_at_most_its_workers() {
        let live = std::sync::atomic::AtomicUsize::new(0);
        let peak = std::sync::atomic::AtomicUsize::new(0);
        let items: Vec<u64> = (0..200).collect();
        let out = run_pool(&items, 3, |&x| {
            use std::sync::atomic::Ordering::SeqCst;
            let now = live.fetch_add(1, SeqCst) + 1;
            peak.fetch_max(now, SeqCst);
            std::thread::yield_now();
            live.fetch_sub(1, SeqCst);
            x * 2
        });
        assert_eq!(out, items.iter().map(|x| x * 2).collect::<Vec<_>>());
        assert!(peak.load(std::sync::atomic::Ordering::SeqCst) <= 3);
        assert!(run_pool(&[] as &[u8], 4, |_| 0).is_empty());
    }

    #[test]
    fn a_stopped_sweep_returns_only_what_completed() {
        let g = Grid {
            clocks: vec![ClockKind::Virtual],
            sensor_hz: vec![50.0],
            control_hz: vec![50.0, 20.0, 10.0, 5.0],
            queue_depth: vec![1],
            seeds: vec![0],
            base: RunConfig {
                duration: Nanos(Nanos::SECOND.0),
                ..RunConfig::default()
            },
        };
        let brain = || Ok(Box::new(Scripted) as Box<dyn Policy>);
        let stop = StopFlag::new();
        // Stop after the second run completes: one thread, so runs go in grid order.
        let rows = run_grid_until(
            &g,
            &brain,
            1,
            &|done, _| {
                if done == 2 {
                    stop.stop();
                }
            },
            &stop,
        )
        .unwrap();
        let hz: Vec<f64> = rows.iter().map(|(p, _)| p.control_hz).collect();
        assert_eq!(hz, vec![50.0, 20.0]);
        assert_eq!(rows, run_grid(&g, &brain, 1, &|_, _| {}).unwrap()[..2]);
    }

    #[test]
    fn the_tables_are_the_command_line_s() {
        struct Exploding;
        impl Policy for Exploding {
            fn act(&mut self, _: &ratelab_core::plant::Observation) -> ratelab_core::plant::Action {
                panic!("boom")
            }
            fn label(&self) -> String {
                "exploding".into()
            }
        }
        let g = Grid {
            clocks: vec![ClockKind::Virtual],
            sensor_hz: vec![50.0],
            control_hz: vec![5.0],
            queue_depth: vec![1],
            seeds: vec![2],
            base: RunConfig {
                duration: Nanos(Nanos::SECOND.0),
                ..RunConfig::default()
            },
        };
        let scripted = || Ok(Box::new(Scripted) as Box<dyn Policy>);
        let exploding = || Ok(Box::new(Exploding) as Box<dyn Policy>);
        let mut rows = run_grid(&g, &scripted, 1, &|_, _| {}).unwrap();
        assert_eq!(failed_line(&rows), None);
        rows.extend(run_grid(&g, &exploding, 1, &|_, _| {}).unwrap());
        assert_eq!(
            failed_line(&rows).as_deref(),
            Some("1 of 2 runs failed a node (the first, control 5 Hz seed 2: policy: boom)")
        );
        let mut csv = Vec::new();
        write_csv(&mut csv, &rows).unwrap();
        let text = String::from_utf8(csv).unwrap();
        assert!(
            text.starts_with("clock,sensor_hz,control_hz,queue_depth,seed,balanced,"),
            "{text}"
        );
        assert_eq!(text.lines().count(), 3);
        assert!(text
            .lines()
            .nth(1)
            .unwrap()
            .starts_with("virtual,50,5,1,2,"));
        let cliffs = [Cliff {
            seed: 0,
            falls_at_hz: Some(7.5),
            balances_at_hz: None,
            runs: 3,
        }];
        let mut csv = Vec::new();
        write_cliffs_csv(&mut csv, &cliffs).unwrap();
        assert_eq!(
            String::from_utf8(csv).unwrap(),
            "seed,falls_at_hz,balances_at_hz,runs\n0,7.5,,3\n"
        );
    }

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
            fn act(&mut self, _: &ratelab_core::plant::Observation) -> ratelab_core::plant::Action {
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
