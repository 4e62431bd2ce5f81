//! ex11, your own brain: the learner's Python brain (`ex11_my_brain.py`, a function from
//! observation to action) against the scripted balancer, each slowed down the same ladder
//! of policy rates until the pole falls: whose rate cliff is lower? Virtual clock: exact.

use super::{check, threads, Check, Context, Exercise, ExerciseError, Reconcile, Said, Section};
use ratelab_drivers::sweep::{find_cliff, run_pool, Cliff};
use ratelab_runtime::config::{duration_from_secs, ClockKind, RunConfig};
use ratelab_runtime::graph::GraphSpec;
use ratelab_runtime::scheduler::StopFlag;
use serde::Deserialize;
use std::path::Path;

/// ex11: your own brain.
pub struct Ex11;

/// The learner's brain, in the exercises folder.
pub const BRAIN_FILE: &str = "ex11_my_brain.py";

/// ex11's search and bands (`bands.toml`'s `[ex11]`).
#[derive(Clone, Debug, Deserialize)]
pub struct Ex11Bands {
    /// Seeds.
    pub seeds: Vec<u64>,
    /// The slowest policy rate searched, Hz.
    pub min_hz: f64,
    /// The fastest, Hz (every brain is run down from here).
    pub max_hz: f64,
    /// The search's step, Hz.
    pub step_hz: f64,
    /// Run length, s.
    pub duration_s: f64,
    /// The scripted balancer's cliff lies in this band on every seed, Hz (measured).
    pub scripted_cliff_hz: [f64; 2],
}

impl Section for Ex11Bands {
    const NAME: &'static str = "ex11";
}

/// ex11's outcome: each brain's cliff, the highest rate at which it dropped the pole on any
/// seed (`None`: it balanced at every rate searched).
#[derive(Clone, Debug, PartialEq)]
pub struct Ex11Outcome {
    /// The learner's brain's, Hz.
    pub mine_hz: Option<f64>,
    /// The scripted balancer's, Hz.
    pub scripted_hz: Option<f64>,
}

/// Both brains' cliffs, per seed, in the bands' seed order: `(mine, scripted)`.
pub type Ex11Runs = (Vec<Cliff>, Vec<Cliff>);

/// ex11's measurements: each brain's cliff on every seed, the seeds on every core.
///
/// # Errors
/// [`ExerciseError`] when the learner's brain cannot be loaded, one of its runs fails (it
/// raised), or a run cannot start.
pub fn measure_ex11(
    b: &Ex11Bands,
    graph: &GraphSpec,
    brain: &Path,
    stop: &StopFlag,
) -> Result<Ex11Runs, ExerciseError> {
    let spec = brain.display().to_string();
    ratelab_runtime::checkpoint::load_policy(&spec)
        .map_err(|e| ExerciseError::NotReady(e.to_string()))?;
    let mine = move || ratelab_runtime::checkpoint::load_policy(&spec).map_err(|e| e.to_string());
    let scripted = super::scripted;
    let cliffs =
        |brain: ratelab_drivers::sweep::BrainFactory<'_>| -> Result<Vec<Cliff>, ExerciseError> {
            let base = RunConfig {
                clock: ClockKind::Virtual,
                duration: duration_from_secs(b.duration_s)?,
                graph: graph.clone(),
                ..RunConfig::default()
            };
            // A seed's search not begun when `stop` is set is not begun; one under way
            // finishes its scan (virtual runs of a few seconds each).
            let found = run_pool(&b.seeds, threads(), |&seed| {
                super::interrupted(stop)?;
                let cfg = RunConfig {
                    seed,
                    ..base.clone()
                };
                Ok(find_cliff(&cfg, brain, b.min_hz, b.max_hz, b.step_hz)?)
            })
            .into_iter()
            .collect::<Result<Vec<Cliff>, ExerciseError>>()?;
            super::interrupted(stop)?;
            Ok(found)
        };
    Ok((cliffs(&mine)?, cliffs(&scripted)?))
}

/// The highest falling rate over the seeds.
fn highest(cliffs: &[Cliff]) -> Option<f64> {
    cliffs
        .iter()
        .filter_map(|c| c.falls_at_hz)
        .fold(None, |top, hz| Some(top.map_or(hz, |t: f64| t.max(hz))))
}

/// ex11's outcome from its runs.
pub fn outcome_ex11(runs: &Ex11Runs) -> Ex11Outcome {
    Ex11Outcome {
        mine_hz: highest(&runs.0),
        scripted_hz: highest(&runs.1),
    }
}

/// ex11's checks: the scripted balancer's cliff where it was measured, and every cliff
/// found a real edge (it fell there and balanced one step up).
pub fn check_ex11(b: &Ex11Bands, runs: &Ex11Runs) -> Vec<Check> {
    let [lo, hi] = b.scripted_cliff_hz;
    let edge = |c: &Cliff| match (c.falls_at_hz, c.balances_at_hz) {
        (Some(f), Some(up)) => ((up - f) - b.step_hz).abs() < 1e-9,
        (Some(_), None) => true, // fell even at the top: no step up to balance at
        (None, _) => true,       // balanced at every rate searched
    };
    vec![
        check(
            format!("the scripted balancer's cliff is {lo}–{hi} Hz on every seed"),
            runs.1
                .iter()
                .all(|c| c.falls_at_hz.is_some_and(|f| (lo..=hi).contains(&f))),
        ),
        check(
            format!(
                "every cliff found is an edge: a fall, and a balance {} Hz above it",
                b.step_hz
            ),
            runs.0.iter().chain(&runs.1).all(edge),
        ),
        check(
            format!("your brain balances at {} Hz on every seed", b.max_hz),
            runs.0.iter().all(|c| c.falls_at_hz != Some(b.max_hz)),
        ),
    ]
}

/// A rate of the search (a multiple of its step): right when it is the brain's cliff. Lower
/// or not: right when it agrees; not graded when neither brain fell in the range.
impl Reconcile for Ex11Outcome {
    fn reconcile(&self, prediction: &toml::Table) -> Vec<Said> {
        let hz = |x: Option<f64>| x.map_or("none in the range".into(), |hz| format!("{hz} Hz"));
        // A brain that never fell in the range has its cliff below it: lower than one that did.
        let lower = match (self.mine_hz, self.scripted_hz) {
            (Some(m), Some(s)) => Some(m < s),
            (None, Some(_)) => Some(true),
            (Some(_), None) => Some(false),
            (None, None) => None,
        };
        let key = "my_cliff_hz";
        let cliff = match prediction.get(key).and_then(super::number) {
            Some(p) => super::graded(
                key,
                &format!(
                    "You predicted your brain's cliff at {p} Hz; it was {} (the scripted balancer's {})",
                    hz(self.mine_hz),
                    hz(self.scripted_hz)
                ),
                self.mine_hz.is_some_and(|m| super::same(p, m)),
                "",
            ),
            None => super::unreadable(key),
        };
        let key = "lower_than_scripted";
        let lower = match (prediction.get(key).and_then(toml::Value::as_bool), lower) {
            (Some(p), Some(l)) => super::graded(
                key,
                &format!(
                    "You predicted your brain's cliff is {} than the scripted one's; it is {}",
                    if p { "lower" } else { "not lower" },
                    if l { "lower" } else { "not lower" }
                ),
                p == l,
                "",
            ),
            (Some(_), None) => super::open(
                key,
                "Neither brain fell in the range: there is no cliff to compare.".into(),
            ),
            (None, _) => super::unreadable(key),
        };
        vec![cliff, lower]
    }
}

impl Exercise for Ex11 {
    fn id(&self) -> &'static str {
        "ex11"
    }

    fn title(&self) -> &'static str {
        "your own brain"
    }

    fn file(&self) -> &'static str {
        "ex11_my_brain.toml"
    }

    fn required_keys(&self) -> &'static [&'static str] {
        &["my_cliff_hz", "lower_than_scripted"]
    }

    fn run(&self, cx: &mut Context<'_>) -> Result<(), ExerciseError> {
        let b: Ex11Bands = cx.bands()?;
        let brain = cx.dir.join(BRAIN_FILE);
        let runs = cx.measure(|stop| measure_ex11(&b, cx.graph, &brain, stop))?;
        say!(
            cx,
            "{:>6} | {:>22} | {:>22}",
            "seed",
            "your brain falls at",
            "scripted falls at"
        );
        let cell = |c: &Cliff| match (c.falls_at_hz, c.balances_at_hz) {
            (Some(f), Some(up)) => format!("{f} Hz (up at {up})"),
            (Some(f), None) => format!("{f} Hz (the top)"),
            (None, _) => "never".into(),
        };
        for ((seed, mine), scripted) in b.seeds.iter().zip(&runs.0).zip(&runs.1) {
            say!(
                cx,
                "{:>6} | {:>22} | {:>22}",
                seed,
                cell(mine),
                cell(scripted)
            );
        }
        say!(
            cx,
            "(Each brain run down from {} Hz by {} Hz until the pole falls within {} s.)",
            b.max_hz,
            b.step_hz,
            b.duration_s
        );
        let outcome = outcome_ex11(&runs);
        cx.reconcile(&outcome);
        cx.checks(&check_ex11(&b, &runs));
        say!(cx);
        cx.paragraph(
            "Reconcile: a slower policy acts on older states and holds each action longer. A brain \
             with high gains corrects hard on a state that has moved on: at a slow rate its held \
             pushes overshoot, and the pole is lost sooner. Gentler gains react less to each \
             reading, and so suffer less from its age: the rate a brain tolerates is part of its \
             design. Watch yours at its cliff in the lab, then save it changed and see the lab \
             run it again beside the run before: ratelab --clock virtual --policy \
             exercises/ex11_my_brain.py --rate policy=8",
        );
        Ok(())
    }
}
