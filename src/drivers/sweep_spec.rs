//! A sweep and a cliff search as data: [`SweepSpec`] (the settings every run shares, and the
//! grid's lists) and [`CliffSpec`] (the settings every run shares, the seeds, and the range
//! of control rates searched), what every front end fills in — the command line's `ratelab
//! sweep` and `ratelab cliff`, the Python package's `ratelab.sweep` and `ratelab.cliff` —
//! so that no front end builds another's argument list to reach one.
//!
//! Each checks its settings once, by [`RunSpec`]'s rules and its own, refusing a bad one in
//! one line naming it as its front end takes it ([`Speech`]: `--seeds` on the command line,
//! `seeds` from Python), then runs on every core with the brains of a factory the front end
//! gives ([`BrainFactory`]: a brain file's, [`brain_factory`], or a Python callable's), until
//! a [`StopFlag`]. Printing, progress bars and files are the front end's; the tables as CSV
//! are [`crate::sweep`]'s.

use crate::run_spec::RunSpec;
use crate::sweep::{
    find_cliff, run_grid_until, run_pool, BrainFactory, Cliff, Grid, Point, SweepError,
};
use ratelab_core::limits::MAX_SWEEP_RUNS;
use ratelab_core::metrics::Metrics;
use ratelab_core::rate::DEFAULT_SPIN_MARGIN;
use ratelab_runtime::checkpoint::load_policy;
use ratelab_runtime::config::{check_rate, ClockKind, ConfigError, RunConfig};
use ratelab_runtime::graph::{GraphSpec, NodeId};
use ratelab_runtime::policy::Policy;
use ratelab_runtime::scheduler::StopFlag;
use ratelab_runtime::setting::{Setting, Speech};

/// At most this many control rates are searched per seed (the step against the range).
pub const MAX_CLIFF_RATES: f64 = 5000.0;

/// The threads a sweep or search runs on: one per core (at least one).
pub fn threads() -> usize {
    std::thread::available_parallelism().map_or(1, |n| n.get())
}

/// A factory of fresh brains of `policy` (`scripted`, `FILE.py[:FUNCTION]` or a checkpoint
/// path), one per run (runs go on several threads): the brain is loaded once here, to refuse
/// it before any run, then again for each run.
///
/// # Errors
/// The brain cannot be loaded ([`ratelab_runtime::checkpoint::PolicyError`]: a file
/// missing, a script that does not load, …).
pub fn brain_factory(
    policy: &str,
) -> anyhow::Result<impl Fn() -> Result<Box<dyn Policy>, String> + Send + Sync + 'static> {
    load_policy(policy)?;
    let policy = policy.to_string();
    Ok(move || load_policy(&policy).map_err(|e| e.to_string()))
}

/// Refuse an empty list of `setting`: every check over it would pass without a run.
fn not_empty<T>(list: &[T], setting: Setting, speech: Speech) -> anyhow::Result<()> {
    if list.is_empty() {
        anyhow::bail!(
            "{}: an empty list runs nothing (every check over it would pass without a run); give at least one value",
            speech.name(setting)
        );
    }
    Ok(())
}

/// Refuse a rate outside (0, [`ratelab_core::rate::MAX_HZ`]] Hz or not finite, naming it by
/// `flag` (`control-hz`, `min-hz`, `step`: [`ConfigError::line`] speaks it).
fn rate(flag: &'static str, hz: f64, speech: Speech) -> anyhow::Result<f64> {
    check_rate(flag, hz).map_err(|e| anyhow::anyhow!(e.line(speech)))
}

/// What every run of a sweep or search shares: `base` by [`RunSpec::config`]'s rules under
/// the virtual clock (the real one is checked where a sweep asks for it), the settings the
/// sweep or search gives each run left out (its seed, clock and control rate; with
/// `varies_sensor`, the sensor rate and queue depth too), its `break_` and `smoke` unused.
/// A spin margin not asked for is the default, capped per run ([`Grid::config`]). The graph
/// must have the chapter's chain, and no `rate` of `base` may name a node whose rate the
/// sweep or search varies (one of the two would be ignored; a `rate` beside `base`'s own
/// `sensor_hz` is [`RunSpec::config`]'s to judge).
///
/// # Errors
/// The first setting that cannot be used, in one line naming it in `speech`'s words.
fn shared_config(
    base: &RunSpec,
    speech: Speech,
    what: &str,
    varies_sensor: bool,
) -> anyhow::Result<RunConfig> {
    let spec = RunSpec {
        seed: 0,
        clock: ClockKind::Virtual,
        control_hz: None,
        sensor_hz: base.sensor_hz.filter(|_| !varies_sensor),
        queue_depth: base.queue_depth.filter(|_| !varies_sensor),
        break_: false,
        smoke: false,
        ..base.clone()
    };
    let mut cfg = spec.config(speech)?;
    if base.spin_margin_us.is_none() {
        cfg.spin_margin = DEFAULT_SPIN_MARGIN;
    }
    let chain = cfg.graph.chain_for(what, speech)?;
    let mut varied = vec![(Setting::ControlHz, chain.policy)];
    if varies_sensor {
        varied.push((Setting::SensorHz, chain.sensor));
    }
    refuse_rates_of(base, &cfg.graph, &varied, speech)?;
    Ok(cfg)
}

/// Refuse a `rate` of `base` naming one of the `varied` nodes, whose rate the setting beside
/// it sets: both are named.
fn refuse_rates_of(
    base: &RunSpec,
    graph: &GraphSpec,
    varied: &[(Setting, NodeId)],
    speech: Speech,
) -> anyhow::Result<()> {
    for &(setting, node) in varied {
        let node = &graph.node(node).name;
        if let Some((_, hz)) = base.graph.rates.iter().find(|(n, _)| n == node) {
            anyhow::bail!(
                "{} and {} both set the rate of node '{node}'; give one",
                speech.entry(Setting::Rate, node, hz),
                speech.name(setting)
            );
        }
    }
    Ok(())
}

/// A sweep's settings, as data: every combination of the grid's lists is run once, with the
/// settings of `base` (seed fastest, then queue depth, control rate, sensor rate, clock:
/// [`Grid::points`]). Fill in the fields and call [`SweepSpec::grid`] or [`SweepSpec::run`].
#[derive(Clone, Debug, PartialEq)]
pub struct SweepSpec {
    /// What every run shares: the graph and its overrides (faults too), the duration, the
    /// brain (`policy`, unless the front end gives a brain factory of its own), phase
    /// offsets, spin margin, priority. Its seed, clock, `sensor_hz`, `control_hz` and
    /// `queue_depth` are the grid's (not used here), as are `break_` and `smoke`; its
    /// `outputs` are not used (a sweep's table is its front end's to write).
    pub base: RunSpec,
    /// The clocks (virtual runs go in parallel; real ones one at a time, in real time).
    pub clocks: Vec<ClockKind>,
    /// The chain sensor's rates, Hz, each in (0, 10000].
    pub sensor_hz: Vec<f64>,
    /// The chain policy's (control) rates, Hz, each in (0, 10000].
    pub control_hz: Vec<f64>,
    /// Every topic's history depth, messages, each ≥ 1.
    pub queue_depth: Vec<usize>,
    /// The reset seeds.
    pub seeds: Vec<u64>,
}

impl Default for SweepSpec {
    /// `ratelab sweep`'s defaults: control 50, 25, 20, 15, 10 and 5 Hz, sensor 50 Hz, depth 1,
    /// seeds 0, 1 and 2, the virtual clock, the chapter's graph, 10 s, the scripted balancer.
    fn default() -> Self {
        Self {
            base: RunSpec {
                clock: ClockKind::Virtual,
                ..RunSpec::default()
            },
            clocks: vec![ClockKind::Virtual],
            sensor_hz: vec![50.0],
            control_hz: vec![50.0, 25.0, 20.0, 15.0, 10.0, 5.0],
            queue_depth: vec![1],
            seeds: vec![0, 1, 2],
        }
    }
}

impl SweepSpec {
    /// The grid these settings describe, every rule checked once: no list empty, every rate
    /// and depth of the lists, [`RunSpec::config`]'s rules for `base`, a graph with the
    /// chapter's chain and no `rate` of its sensor or policy beside the grid's, and with the
    /// real clock among the clocks, a real-clock run of the graph. The graph's QoS warnings
    /// are the caller's to show (`grid.base.graph`).
    ///
    /// # Errors
    /// The first setting that cannot be used, in one line naming it in `speech`'s words
    /// (`--seeds: an empty list runs nothing …`, `seeds: …`).
    pub fn grid(&self, speech: Speech) -> anyhow::Result<Grid> {
        not_empty(&self.control_hz, Setting::ControlHz, speech)?;
        not_empty(&self.sensor_hz, Setting::SensorHz, speech)?;
        not_empty(&self.queue_depth, Setting::QueueDepth, speech)?;
        not_empty(&self.seeds, Setting::Seeds, speech)?;
        not_empty(&self.clocks, Setting::Clock, speech)?;
        let lists = [
            (Setting::Clock, self.clocks.len()),
            (Setting::SensorHz, self.sensor_hz.len()),
            (Setting::ControlHz, self.control_hz.len()),
            (Setting::QueueDepth, self.queue_depth.len()),
            (Setting::Seeds, self.seeds.len()),
        ];
        let runs = (lists.iter()).try_fold(1usize, |runs, &(_, n)| runs.checked_mul(n));
        if runs.is_none_or(|runs| runs > MAX_SWEEP_RUNS) {
            let names: Vec<&str> = lists.iter().map(|&(s, _)| speech.name(s)).collect();
            let sizes: Vec<String> = lists.iter().map(|&(_, n)| n.to_string()).collect();
            anyhow::bail!(ratelab_core::limits::refusal(
                format_args!(
                    "{}: a sweep of {} runs is too many; a sweep makes at most {MAX_SWEEP_RUNS}",
                    names.join(" × "),
                    sizes.join(" × ")
                ),
                "MAX_SWEEP_RUNS"
            ));
        }
        for &hz in &self.sensor_hz {
            rate("sensor-hz", hz, speech)?;
        }
        for &hz in &self.control_hz {
            rate("control-hz", hz, speech)?;
        }
        if self.queue_depth.contains(&0) {
            anyhow::bail!(ConfigError::Depth(0).line(speech));
        }
        let what = "a sweep (it varies the chain's sensor and control rates)";
        let grid = Grid {
            clocks: self.clocks.clone(),
            sensor_hz: self.sensor_hz.clone(),
            control_hz: self.control_hz.clone(),
            queue_depth: self.queue_depth.clone(),
            seeds: self.seeds.clone(),
            base: shared_config(&self.base, speech, what, true)?,
        };
        // What the real clock alone refuses (too many threads), once: it does not depend
        // on the point.
        if self.clocks.contains(&ClockKind::Real) {
            let point = Point {
                clock: ClockKind::Real,
                sensor_hz: self.sensor_hz[0],
                control_hz: self.control_hz[0],
                queue_depth: self.queue_depth[0],
                seed: self.seeds[0],
            };
            let said = |e: ConfigError| anyhow::anyhow!(e.line(speech));
            match grid.config(&point) {
                Ok(cfg) => cfg.validate().map_err(said)?,
                Err(SweepError::Config(e)) => return Err(said(e)),
                Err(e) => return Err(e.into()),
            }
        }
        Ok(grid)
    }

    /// Run the sweep ([`SweepSpec::grid`]) on every core with the brains of `brain`, until
    /// `stop` (the run in progress ends at once, no further one starts); `progress(done,
    /// total)` after each run. Returns a row per run that completed, in grid order: its
    /// point and its figures. A run whose node failed is a row like any other
    /// ([`crate::sweep::failed_line`] says it).
    ///
    /// # Errors
    /// Bad settings, in `speech`'s words; a brain that cannot be built; a run that cannot
    /// start.
    pub fn run(
        &self,
        speech: Speech,
        brain: BrainFactory<'_>,
        progress: &(dyn Fn(usize, usize) + Sync),
        stop: &StopFlag,
    ) -> anyhow::Result<Vec<(Point, Metrics)>> {
        let grid = self.grid(speech)?;
        Ok(run_grid_until(&grid, brain, threads(), progress, stop)?)
    }
}

/// A cliff search's settings, as data: for each seed, the highest control rate from
/// `min_hz` to `max_hz` at which the pole falls, to `step_hz`, under the virtual clock
/// ([`find_cliff`]). Fill in the fields and call [`CliffSpec::config`] or [`CliffSpec::run`].
#[derive(Clone, Debug, PartialEq)]
pub struct CliffSpec {
    /// What every run shares: the graph and its overrides (faults too), the duration, the
    /// brain (`policy`, unless the front end gives a brain factory of its own), the chain
    /// sensor's rate and the queue depth (`sensor_hz`, `queue_depth`; `None`: the graph's),
    /// phase offsets. Its seed, clock (always the virtual one) and `control_hz` are the
    /// search's (not used here), as are `break_` and `smoke`; its `outputs` are not used.
    pub base: RunSpec,
    /// The seeds, one search each.
    pub seeds: Vec<u64>,
    /// The lowest control rate searched, Hz, in (0, 10000].
    pub min_hz: f64,
    /// The highest control rate searched, Hz, in (0, 10000], not below `min_hz`.
    pub max_hz: f64,
    /// The resolution, Hz: at most [`MAX_CLIFF_RATES`] rates from `min_hz` to `max_hz`.
    pub step_hz: f64,
}

impl Default for CliffSpec {
    /// `ratelab cliff`'s defaults: seeds 0, 1 and 2, sensor 50 Hz, depth 1, 1 to 50 Hz by
    /// 0.1 Hz, the chapter's graph, 10 s, the scripted balancer.
    fn default() -> Self {
        Self {
            base: RunSpec {
                clock: ClockKind::Virtual,
                sensor_hz: Some(50.0),
                queue_depth: Some(1),
                ..RunSpec::default()
            },
            seeds: vec![0, 1, 2],
            min_hz: 1.0,
            max_hz: 50.0,
            step_hz: 0.1,
        }
    }
}

impl CliffSpec {
    /// The settings every run of the search shares (seed 0: each search sets its own; the
    /// virtual clock), every rule checked once: seeds not empty, the range's rates, the
    /// range not upside down nor stepped finer than [`MAX_CLIFF_RATES`] rates,
    /// [`RunSpec::config`]'s rules for `base`, a graph with the chapter's chain and no `rate`
    /// of its policy (nor, with `sensor_hz`, of its sensor) beside the search's. The graph's
    /// QoS warnings are the caller's to show.
    ///
    /// # Errors
    /// The first setting that cannot be used, in one line naming it in `speech`'s words
    /// (`--min-hz (20) must not be above --max-hz (10)`, `min_hz (20) …`).
    pub fn config(&self, speech: Speech) -> anyhow::Result<RunConfig> {
        not_empty(&self.seeds, Setting::Seeds, speech)?;
        let min = rate("min-hz", self.min_hz, speech)?;
        let max = rate("max-hz", self.max_hz, speech)?;
        let step = rate("step", self.step_hz, speech)?;
        let name = |s: Setting| speech.name(s);
        if min > max {
            anyhow::bail!(
                "{} ({min}) must not be above {} ({max})",
                name(Setting::MinHz),
                name(Setting::MaxHz)
            );
        }
        let rates = ((max - min) / step).floor() + 1.0;
        if rates.is_nan() || rates > MAX_CLIFF_RATES {
            anyhow::bail!(
                "{} is too fine for {} to {}: at most {MAX_CLIFF_RATES} rates are searched (use {} ≥ {:.4})",
                speech.value(Setting::Step, &step),
                speech.value(Setting::MinHz, &min),
                speech.value(Setting::MaxHz, &max),
                name(Setting::Step),
                (max - min) / (MAX_CLIFF_RATES - 1.0)
            );
        }
        let what = "a cliff search (it varies the chain's control rate)";
        shared_config(&self.base, speech, what, false)
    }

    /// Search every seed ([`CliffSpec::config`]) on every core with the brains of `brain`,
    /// until `stop`; `progress(done, total)` after each seed. Returns the cliff of each seed
    /// searched, in seed order.
    ///
    /// # Errors
    /// Bad settings, in `speech`'s words; a brain that cannot be built; a run that cannot
    /// start, or whose node failed ([`SweepError::NodeFailed`]: such a run neither balanced
    /// nor fell).
    pub fn run(
        &self,
        speech: Speech,
        brain: BrainFactory<'_>,
        progress: &(dyn Fn(usize, usize) + Sync),
        stop: &StopFlag,
    ) -> anyhow::Result<Vec<Cliff>> {
        let base = self.config(speech)?;
        Ok(self.search(&base, brain, progress, stop)?)
    }

    /// [`CliffSpec::run`] from `base`, what [`CliffSpec::config`] returned (for a front end
    /// that uses it too: the lab's plot of the edge). A seed not started when `stop` is set
    /// is left out; the one in progress finishes.
    ///
    /// # Errors
    /// As [`CliffSpec::run`], but for the settings.
    pub fn search(
        &self,
        base: &RunConfig,
        brain: BrainFactory<'_>,
        progress: &(dyn Fn(usize, usize) + Sync),
        stop: &StopFlag,
    ) -> Result<Vec<Cliff>, SweepError> {
        let total = self.seeds.len();
        let done = std::sync::atomic::AtomicUsize::new(0);
        let results = run_pool(&self.seeds, threads(), |&seed| {
            if stop.is_stopped() {
                return None;
            }
            let cfg = RunConfig {
                seed,
                ..base.clone()
            };
            let found = find_cliff(&cfg, brain, self.min_hz, self.max_hz, self.step_hz);
            progress(
                done.fetch_add(1, std::sync::atomic::Ordering::SeqCst) + 1,
                total,
            );
            Some(found)
        });
        results.into_iter().flatten().collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use ratelab_runtime::policy::Scripted;

    fn scripted() -> Result<Box<dyn Policy>, String> {
        Ok(Box::new(Scripted))
    }

    /// `spec`'s refusal in both speeches: (flags, keywords).
    fn refused(check: impl Fn(Speech) -> anyhow::Result<()>) -> (String, String) {
        let line = |speech| check(speech).unwrap_err().to_string();
        (line(Speech::Flags), line(Speech::Keywords))
    }

    fn sweep_refused(spec: &SweepSpec) -> (String, String) {
        refused(|speech| spec.grid(speech).map(drop))
    }

    fn cliff_refused(spec: &CliffSpec) -> (String, String) {
        refused(|speech| spec.config(speech).map(drop))
    }

    #[test]
    fn an_empty_list_is_refused_naming_it() {
        let spec = SweepSpec {
            seeds: Vec::new(),
            ..SweepSpec::default()
        };
        let (flags, words) = sweep_refused(&spec);
        assert!(
            flags.starts_with("--seeds: an empty list runs nothing"),
            "{flags}"
        );
        assert!(
            words.starts_with("seeds: an empty list runs nothing"),
            "{words}"
        );
        assert!(!words.contains('\n'));
        let spec = SweepSpec {
            control_hz: Vec::new(),
            ..SweepSpec::default()
        };
        let (flags, words) = sweep_refused(&spec);
        assert!(flags.starts_with("--control-hz: "), "{flags}");
        assert!(words.starts_with("control_hz: "), "{words}");
        let spec = CliffSpec {
            seeds: Vec::new(),
            ..CliffSpec::default()
        };
        let (flags, words) = cliff_refused(&spec);
        assert!(
            flags.starts_with("--seeds: an empty list runs nothing"),
            "{flags}"
        );
        assert!(
            words.starts_with("seeds: an empty list runs nothing"),
            "{words}"
        );
    }

    /// A grid of more runs than a sweep makes is refused before any run, in one line naming
    /// the lists and the bound (a grid of 3 000 × 3 000 rates asked for 20 GB at once). At
    /// the bound it is a grid.
    #[test]
    fn a_grid_of_too_many_runs_is_refused_before_any_starts() {
        let rates = |n: usize| (1..=n).map(|i| i as f64).collect::<Vec<f64>>();
        let spec = SweepSpec {
            control_hz: rates(3_000),
            sensor_hz: rates(3_000),
            seeds: vec![0],
            ..SweepSpec::default()
        };
        let (flags, words) = sweep_refused(&spec);
        assert!(
            flags.starts_with("--clock × --sensor-hz × --control-hz × --queue-depth × --seeds: a sweep of 1 × 3000 × 3000 × 1 × 1 runs is too many; a sweep makes at most 100000"),
            "{flags}"
        );
        assert!(
            flags.ends_with("(ratelab::limits::MAX_SWEEP_RUNS)"),
            "{flags}"
        );
        assert!(
            words.starts_with("clock × sensor_hz × control_hz × queue_depth × seeds: "),
            "{words}"
        );
        assert!(!words.contains('\n'));
        // A product past usize is refused too, not wrapped round.
        let spec = SweepSpec {
            seeds: vec![0; 1 << 16],
            queue_depth: vec![1; 1 << 16],
            control_hz: vec![50.0; 1 << 16],
            sensor_hz: vec![50.0; 1 << 16],
            ..SweepSpec::default()
        };
        assert!(sweep_refused(&spec).0.contains("is too many"));
        // At the bound: a grid.
        let spec = SweepSpec {
            control_hz: rates(400),
            sensor_hz: rates(250),
            seeds: vec![0],
            ..SweepSpec::default()
        };
        assert_eq!(spec.clocks.len() * spec.queue_depth.len(), 1);
        assert!(spec.grid(Speech::Flags).is_ok());
        let spec = SweepSpec {
            seeds: vec![0, 1],
            ..spec
        };
        assert!(sweep_refused(&spec)
            .0
            .contains("1 × 250 × 400 × 1 × 2 runs is too many"));
    }

    #[test]
    fn a_bad_value_of_a_list_is_refused_by_run_spec_s_rule() {
        let spec = SweepSpec {
            control_hz: vec![10.0, 0.0],
            ..SweepSpec::default()
        };
        assert_eq!(
            sweep_refused(&spec),
            (
                "--control-hz must be a finite rate in (0, 10000] Hz, got 0".to_string(),
                "control_hz must be a finite rate in (0, 10000] Hz, got 0".to_string()
            )
        );
        let spec = SweepSpec {
            sensor_hz: vec![f64::NAN],
            ..SweepSpec::default()
        };
        assert!(sweep_refused(&spec)
            .1
            .starts_with("sensor_hz must be a finite rate"));
        let spec = SweepSpec {
            queue_depth: vec![1, 0],
            ..SweepSpec::default()
        };
        assert_eq!(
            sweep_refused(&spec).1,
            "queue_depth must be at least 1, got 0"
        );
        let mut spec = SweepSpec::default();
        spec.base.duration_s = Some(-1.0);
        let (flags, words) = sweep_refused(&spec);
        assert!(flags.starts_with("--duration must be in (0, "), "{flags}");
        assert!(words.starts_with("duration_s must be in (0, "), "{words}");
    }

    #[test]
    fn a_rate_beside_the_grid_s_is_refused_naming_both() {
        let mut spec = SweepSpec::default();
        spec.base.graph.rates.push(("policy".into(), 20.0));
        assert_eq!(
            sweep_refused(&spec),
            (
                "--rate policy=20 and --control-hz both set the rate of node 'policy'; give one"
                    .to_string(),
                "rate[\"policy\"]=20 and control_hz both set the rate of node 'policy'; give one"
                    .to_string()
            )
        );
        let mut spec = CliffSpec::default();
        spec.base.graph.rates.push(("policy".into(), 20.0));
        let (flags, words) = cliff_refused(&spec);
        assert!(
            flags.starts_with("--rate policy=20 and --control-hz "),
            "{flags}"
        );
        assert!(
            words.starts_with("rate[\"policy\"]=20 and control_hz "),
            "{words}"
        );
        // Beside the search's sensor rate, RunSpec's rule: the two rates named.
        let mut spec = CliffSpec::default();
        spec.base.graph.rates.push(("sensor".into(), 20.0));
        let (_, words) = cliff_refused(&spec);
        assert!(
            words.contains("rate[\"sensor\"]=20 and sensor_hz"),
            "{words}"
        );
        // Another node's rate is the run's own.
        let mut spec = SweepSpec::default();
        spec.base.graph.rates.push(("actuator".into(), 50.0));
        assert!(spec.grid(Speech::Keywords).is_ok());
    }

    #[test]
    fn a_range_upside_down_or_too_fine_is_refused_in_the_front_end_s_words() {
        let spec = CliffSpec {
            min_hz: 20.0,
            max_hz: 10.0,
            ..CliffSpec::default()
        };
        assert_eq!(
            cliff_refused(&spec),
            (
                "--min-hz (20) must not be above --max-hz (10)".to_string(),
                "min_hz (20) must not be above max_hz (10)".to_string()
            )
        );
        let spec = CliffSpec {
            step_hz: 0.001,
            ..CliffSpec::default()
        };
        let (flags, words) = cliff_refused(&spec);
        assert!(
            flags.starts_with("--step 0.001 is too fine for --min-hz 1 to --max-hz 50: "),
            "{flags}"
        );
        assert!(flags.ends_with("(use --step ≥ 0.0098)"), "{flags}");
        assert!(
            words.starts_with("step_hz=0.001 is too fine for min_hz=1 to max_hz=50: "),
            "{words}"
        );
        let spec = CliffSpec {
            step_hz: 0.0,
            ..CliffSpec::default()
        };
        assert_eq!(
            cliff_refused(&spec).1,
            "step_hz must be a finite rate in (0, 10000] Hz, got 0"
        );
        let spec = CliffSpec {
            min_hz: -1.0,
            ..CliffSpec::default()
        };
        assert!(cliff_refused(&spec)
            .0
            .starts_with("--min-hz must be a finite rate"));
    }

    #[test]
    fn the_defaults_are_the_command_line_s() {
        let grid = SweepSpec::default().grid(Speech::Flags).unwrap();
        assert_eq!(grid.points().len(), 6 * 3);
        assert_eq!(grid.base.duration.as_secs_f64(), 10.0);
        assert_eq!(grid.base.spin_margin, DEFAULT_SPIN_MARGIN);
        let cfg = CliffSpec::default().config(Speech::Keywords).unwrap();
        assert_eq!(cfg.clock, ClockKind::Virtual);
        assert_eq!((cfg.sensor_hz(), cfg.queue_depth()), (Some(50.0), Some(1)));
    }

    #[test]
    fn a_sweep_runs_its_grid_and_a_search_finds_the_cliff() {
        let mut spec = SweepSpec {
            control_hz: vec![50.0, 5.0],
            seeds: vec![0],
            ..SweepSpec::default()
        };
        spec.base.duration_s = Some(2.0);
        let stop = StopFlag::new();
        let rows = spec
            .run(Speech::Keywords, &scripted, &|_, _| {}, &stop)
            .unwrap();
        let seen: Vec<(f64, bool)> = rows
            .iter()
            .map(|(p, m)| (p.control_hz, m.balanced))
            .collect();
        assert_eq!(seen, vec![(50.0, true), (5.0, false)]);
        let cliff = CliffSpec {
            seeds: vec![0],
            min_hz: 4.0,
            max_hz: 12.0,
            step_hz: 0.5,
            ..CliffSpec::default()
        };
        let found = cliff
            .run(Speech::Flags, &scripted, &|_, _| {}, &stop)
            .unwrap();
        let [c] = found.as_slice() else {
            panic!("{found:?}")
        };
        let (falls, balances) = (c.falls_at_hz.unwrap(), c.balances_at_hz.unwrap());
        assert_eq!(balances - falls, 0.5);
        // Stopped before it starts: nothing searched.
        stop.stop();
        let base = cliff.config(Speech::Flags).unwrap();
        let none = cliff.search(&base, &scripted, &|_, _| {}, &stop).unwrap();
        assert!(none.is_empty());
    }
}
