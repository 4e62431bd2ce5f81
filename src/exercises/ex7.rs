//! ex7, the slow callback ([`ratelab_core::executor`]): the policy's tick computes for 30 ms, the
//! sensor beside it at 50 Hz, on one executor three ways: a single-threaded executor; a
//! multi-threaded one of two threads with both in one mutually exclusive callback group (two
//! timers of one rclpy node, its default group); the same with the sensor in a group of its
//! own. Virtual clock: each case is exact.

use super::{
    check, run_virtual, Check, Context, Exercise, ExerciseError, Reconcile, Said, Section,
};
use ratelab_core::executor::ExecutorOverride;
use ratelab_core::metrics::Metrics;
use ratelab_runtime::graph::GraphSpec;
use ratelab_runtime::scheduler::StopFlag;
use serde::Deserialize;

/// ex7: the slow callback.
pub struct Ex7;

/// ex7's settings and the bands its checks assert.
#[derive(Clone, Debug, Deserialize)]
pub struct Ex7Bands {
    /// The graph (sensor and policy on a two-thread executor in one group), relative to the
    /// bands file's folder.
    pub graph: String,
    /// The node whose rate suffers.
    pub sensor: String,
    /// Seeds.
    pub seeds: Vec<u64>,
    /// Run length, s.
    pub duration_s: f64,
    /// The sensor's achieved rate, single-threaded, Hz: within this `[low, high]`.
    pub single_threaded_sensor_hz: [f64; 2],
    /// The sensor's rate with a group of its own: its set rate within this, Hz.
    pub own_group_tolerance_hz: f64,
}

impl Section for Ex7Bands {
    const NAME: &'static str = "ex7";
}

/// ex7's outcome: the sensor's achieved rate in each case (the lowest over the seeds), its
/// skipped ticks single-threaded (the most over the seeds), and the single-threaded verdict.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Ex7Outcome {
    /// Single-threaded, Hz.
    pub sensor_hz_single_threaded: f64,
    /// Single-threaded.
    pub skipped_ticks_single_threaded: u64,
    /// Single-threaded, on every seed.
    pub balances_single_threaded: bool,
    /// Two threads, one mutually exclusive group, Hz.
    pub sensor_hz_shared_group: f64,
    /// Two threads, the sensor in its own group, Hz.
    pub sensor_hz_own_group: f64,
}

/// The three ways ex7 runs its graph.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Ex7Case {
    /// `--executor single_threaded`.
    SingleThreaded,
    /// The graph as shipped: two threads, sensor and policy in one mutually exclusive group.
    SharedGroup,
    /// Two threads, the sensor in a group of its own.
    OwnGroup,
}

impl Ex7Case {
    /// Every case, in the order the exercise shows them.
    pub const ALL: [Ex7Case; 3] = [
        Ex7Case::SingleThreaded,
        Ex7Case::SharedGroup,
        Ex7Case::OwnGroup,
    ];

    /// The case as the table names it.
    pub fn label(self) -> &'static str {
        match self {
            Ex7Case::SingleThreaded => "single_threaded",
            Ex7Case::SharedGroup => "2 threads, one group",
            Ex7Case::OwnGroup => "2 threads, own group",
        }
    }
}

/// One ex7 run.
#[derive(Clone, Debug)]
pub struct Ex7Run {
    /// Which case.
    pub case: Ex7Case,
    /// The seed.
    pub seed: u64,
    /// What it measured.
    pub metrics: Metrics,
}

impl Ex7Run {
    /// The sensor's achieved rate, Hz: its ticks after the first over the run time (the
    /// rate of its intervals: a 50 Hz node ticks 501 times in 10 s, at 0 and at 10 s too).
    pub fn sensor_hz(&self, b: &Ex7Bands) -> f64 {
        let ticks = self.metrics.nodes.get(&b.sensor).map_or(0, |n| n.ticks);
        if self.metrics.sim_time_s > 0.0 {
            ticks.saturating_sub(1) as f64 / self.metrics.sim_time_s
        } else {
            0.0
        }
    }

    /// The sensor's skipped ticks.
    pub fn sensor_skipped(&self, b: &Ex7Bands) -> u64 {
        self.metrics
            .nodes
            .get(&b.sensor)
            .and_then(|n| n.exec.as_ref())
            .map_or(0, |x| x.skipped_ticks)
    }
}

/// `graph` run as `case`.
fn case_graph(b: &Ex7Bands, graph: &GraphSpec, case: Ex7Case) -> Result<GraphSpec, ExerciseError> {
    let mut g = graph.clone();
    let sensor = g
        .node_id(&b.sensor)
        .ok_or_else(|| ExerciseError::NoNode(b.sensor.clone()))?;
    match case {
        Ex7Case::SingleThreaded => {
            g.set_executor(ExecutorOverride::parse("single_threaded").map_err(|e| {
                ExerciseError::Setting(ratelab_runtime::graph::spec::OverrideError(e))
            })?)
        }
        Ex7Case::SharedGroup => {}
        Ex7Case::OwnGroup => g.nodes[sensor.0].callback_group = None,
    }
    Ok(g)
}

/// ex7's measurements: every case on every seed (case order, seed fastest).
///
/// # Errors
/// [`ExerciseError`] when the graph has no such sensor, or a run cannot start.
pub fn measure_ex7(
    b: &Ex7Bands,
    graph: &GraphSpec,
    stop: &StopFlag,
) -> Result<Vec<Ex7Run>, ExerciseError> {
    let mut runs = Vec::new();
    for case in Ex7Case::ALL {
        let g = case_graph(b, graph, case)?;
        for &seed in &b.seeds {
            runs.push(Ex7Run {
                case,
                seed,
                metrics: run_virtual(g.clone(), seed, b.duration_s, stop)?.metrics,
            });
        }
    }
    Ok(runs)
}

fn of(runs: &[Ex7Run], case: Ex7Case) -> impl Iterator<Item = &Ex7Run> {
    runs.iter().filter(move |r| r.case == case)
}

/// The lowest sensor rate of a case over the seeds, Hz.
fn sensor_hz(b: &Ex7Bands, runs: &[Ex7Run], case: Ex7Case) -> f64 {
    of(runs, case)
        .map(|r| r.sensor_hz(b))
        .fold(f64::INFINITY, f64::min)
}

/// ex7's outcome in the terms of its prediction.
pub fn outcome_ex7(b: &Ex7Bands, runs: &[Ex7Run]) -> Ex7Outcome {
    Ex7Outcome {
        sensor_hz_single_threaded: sensor_hz(b, runs, Ex7Case::SingleThreaded),
        skipped_ticks_single_threaded: of(runs, Ex7Case::SingleThreaded)
            .map(|r| r.sensor_skipped(b))
            .max()
            .unwrap_or(0),
        balances_single_threaded: of(runs, Ex7Case::SingleThreaded).all(|r| r.metrics.balanced),
        sensor_hz_shared_group: sensor_hz(b, runs, Ex7Case::SharedGroup),
        sensor_hz_own_group: sensor_hz(b, runs, Ex7Case::OwnGroup),
    }
}

/// ex7's checks: single-threaded, the sensor runs only between the slow callbacks (its rate
/// in the bands, periods skipped); a second thread changes nothing while both share a
/// mutually exclusive group; a group of its own gives the sensor its rate back.
pub fn check_ex7(b: &Ex7Bands, runs: &[Ex7Run]) -> Vec<Check> {
    let [lo, hi] = b.single_threaded_sensor_hz;
    let set_hz = runs
        .first()
        .and_then(|r| r.metrics.nodes.get(&b.sensor))
        .map_or(0.0, |n| n.rate_hz);
    let single = sensor_hz(b, runs, Ex7Case::SingleThreaded);
    let same = of(runs, Ex7Case::SharedGroup).all(|r| {
        of(runs, Ex7Case::SingleThreaded)
            .find(|s| s.seed == r.seed)
            .is_some_and(|s| {
                s.metrics.nodes.get(&b.sensor).map(|n| n.ticks)
                    == r.metrics.nodes.get(&b.sensor).map(|n| n.ticks)
                    && s.sensor_skipped(b) == r.sensor_skipped(b)
            })
    });
    let own = of(runs, Ex7Case::OwnGroup).all(|r| {
        (r.sensor_hz(b) - set_hz).abs() <= b.own_group_tolerance_hz && r.sensor_skipped(b) == 0
    });
    vec![
        check(
            format!("single-threaded, the sensor achieves {lo}-{hi} Hz and skips ticks"),
            (lo..=hi).contains(&single)
                && of(runs, Ex7Case::SingleThreaded).all(|r| r.sensor_skipped(b) > 0),
        ),
        check(
            "two threads with sensor and policy in one mutually exclusive group: the sensor ticks exactly as single-threaded",
            of(runs, Ex7Case::SharedGroup).count() > 0 && same,
        ),
        check(
            format!(
                "with a group of its own the sensor keeps its {set_hz} Hz (within {} Hz) and skips nothing",
                b.own_group_tolerance_hz
            ),
            of(runs, Ex7Case::OwnGroup).count() > 0 && own,
        ),
    ]
}

/// The learner's ex7 `prediction` beside the outcome, one sentence per key. The rates and the
/// skipped ticks: right within [`super::NEAR`]. The survival: right when it agrees.
impl Reconcile for Ex7Outcome {
    fn reconcile(&self, prediction: &toml::Table) -> Vec<Said> {
        reconcile(prediction, self)
    }
}

fn reconcile(prediction: &toml::Table, outcome: &Ex7Outcome) -> Vec<Said> {
    let p = |k: &str| prediction.get(k);
    let Ex7Outcome {
        sensor_hz_single_threaded,
        skipped_ticks_single_threaded,
        balances_single_threaded,
        sensor_hz_shared_group,
        sensor_hz_own_group,
    } = *outcome;
    let hz = |key: &str, what: &str, measured: f64| match p(key).and_then(super::number) {
        Some(n) => super::graded(
            key,
            &format!(
                "You predicted the sensor achieves {n} Hz {what}; it achieved {measured:.1} Hz"
            ),
            super::near(n, measured, 0.0),
            &super::more_than_near(),
        ),
        None => super::unreadable(key),
    };
    let key = "skipped_ticks_single_threaded";
    let skipped = match p(key).and_then(super::number) {
        Some(n) => super::graded(
            key,
            &format!(
                "You predicted {n} skipped sensor ticks single-threaded; there were {skipped_ticks_single_threaded}"
            ),
            super::near(n, skipped_ticks_single_threaded as f64, 1.0),
            &super::more_than_near(),
        ),
        None => super::unreadable(key),
    };
    let balances = super::predicted_survival(
        prediction,
        "balances_single_threaded",
        "single-threaded",
        balances_single_threaded,
    );
    vec![
        hz(
            "sensor_hz_single_threaded",
            "single-threaded",
            sensor_hz_single_threaded,
        ),
        skipped,
        balances,
        hz(
            "sensor_hz_shared_group",
            "on two threads, in the policy's group",
            sensor_hz_shared_group,
        ),
        hz(
            "sensor_hz_own_group",
            "on two threads, in a group of its own",
            sensor_hz_own_group,
        ),
    ]
}

impl Exercise for Ex7 {
    fn id(&self) -> &'static str {
        "ex7"
    }

    fn title(&self) -> &'static str {
        "the slow callback"
    }

    fn file(&self) -> &'static str {
        "ex7_slow_callback.toml"
    }

    fn required_keys(&self) -> &'static [&'static str] {
        &[
            "sensor_hz_single_threaded",
            "skipped_ticks_single_threaded",
            "balances_single_threaded",
            "sensor_hz_shared_group",
            "sensor_hz_own_group",
        ]
    }

    fn default_graph(&self, bands: &super::Bands) -> Result<Option<String>, ExerciseError> {
        Ok(Some(bands.of::<Ex7Bands>()?.graph))
    }

    /// The table (per case and seed: the sensor's rate and skipped ticks, the policy's
    /// response time, the executor's utilization, the verdict), the reconcile and the
    /// checks.
    fn run(&self, cx: &mut Context<'_>) -> Result<(), ExerciseError> {
        let b: Ex7Bands = cx.bands()?;
        let runs = cx.measure(|stop| measure_ex7(&b, cx.graph, stop))?;
        say!(
            cx,
            "{:<21} | seed | sensor Hz | skipped | policy response p50/max | executor busy | balanced",
            "executor"
        );
        for case in Ex7Case::ALL {
            for r in of(&runs, case) {
                let m = &r.metrics;
                let policy = m
                    .nodes
                    .values()
                    .find(|n| n.kind == "policy")
                    .and_then(|n| n.exec.clone())
                    .unwrap_or_default();
                let busy = m.executors.first().map_or(0.0, |e| e.utilization * 100.0);
                say!(
                    cx,
                    "{:<21} | {:>4} | {:>9.1} | {:>7} | {:>10.1} / {:>5.1} ms | {:>12.0}% | {}",
                    case.label(),
                    r.seed,
                    r.sensor_hz(&b),
                    r.sensor_skipped(&b),
                    policy.response_time_p50_ms,
                    policy.response_time_max_ms,
                    busy,
                    super::fell_cell(m)
                );
            }
        }
        cx.reconcile(&outcome_ex7(&b, &runs));
        cx.checks(&check_ex7(&b, &runs));
        say!(cx);
        cx.paragraph(
            "Reconcile: an executor runs one callback per thread at a time, and a callback is not \
             interrupted. Single-threaded, each 30 ms policy tick holds the only thread, so the \
             sensor's timer fires late, and the periods that pass meanwhile are skipped, not \
             made up (ROS 2's timers stay on their grid). A second thread does nothing while \
             both callbacks are in one mutually exclusive group: the group, not the thread count, \
             decides what may run together, and a node's callbacks share its default group. In a \
             group of its own the sensor gets the second thread and its rate back. The pole \
             hardly notices either way: the policy reads the newest reading when it starts, and \
             the action's age is the policy's own 30 ms plus the wait for the actuator's tick. \
             What the starved sensor costs is every other subscriber of /obs (a logger, an \
             estimator), which would see a third of its readings missing. Try it with the \
             policy's compute time changed:",
        );
        say!(cx, "  ./scripts/lab.sh run --clock virtual --graph graphs/cartpole-executors.toml --executor single_threaded --compute policy=60");
        Ok(())
    }
}
