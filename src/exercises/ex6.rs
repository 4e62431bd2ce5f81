//! ex6, write your own node: the learner's Python safety limiter in the safety graph's
//! place, over a ladder of clamps, beside the built-in safety node: the smallest clamp that
//! still balances, and whether the learner's node limits as the built-in one does.

use super::{check, run_virtual, seeds_header, threads, Check, Context, Exercise};
use super::{ExerciseError, Reconcile, Said, Section};
use ratelab_core::metrics::Metrics;
use ratelab_drivers::sweep::run_pool;
use ratelab_runtime::graph::GraphSpec;
use ratelab_runtime::scheduler::StopFlag;
use serde::Deserialize;
use std::path::Path;

/// ex6: write your own node.
pub struct Ex6;

/// ex6's settings: write your own node (a Python safety limiter).
#[derive(Clone, Debug, Deserialize)]
pub struct Ex6Bands {
    /// The graph (the safety graph), relative to the bands file's folder.
    pub graph: String,
    /// Its safety node, which the learner's Python node replaces.
    pub node: String,
    /// The learner's script, relative to the bands file's folder.
    pub script: String,
    /// A correct limiter, relative to the bands file's folder: the measurement checks run
    /// it in the learner's place, so that they test the runtime, not the learner.
    pub reference_script: String,
    /// Seeds.
    pub seeds: Vec<u64>,
    /// Run length, s.
    pub duration_s: f64,
    /// The clamps tried (`max_force_n`), N, largest first.
    pub clamps_n: Vec<f64>,
    /// The smallest clamp of `clamps_n` at which the built-in safety node keeps the pole up
    /// on every seed, N.
    pub smallest_balancing_clamp_n: f64,
}

impl Section for Ex6Bands {
    const NAME: &'static str = "ex6";
}

/// ex6's outcome: the smallest clamp at which the learner's node kept the pole up on every
/// seed, and whether it gave the built-in node's verdicts at every clamp.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Ex6Outcome {
    /// Clamp, N (`None`: at none).
    pub smallest_clamp_n: Option<f64>,
    /// Same balanced/fell, at the same step, as the built-in safety node, everywhere.
    pub matches_builtin: bool,
}

/// One ex6 run: a clamp and a seed, with the built-in safety node or the Python one.
#[derive(Clone, Debug)]
pub struct Ex6Run {
    /// The clamp (`max_force_n`), N.
    pub clamp_n: f64,
    /// The seed.
    pub seed: u64,
    /// The Python node ran (else the built-in safety node).
    pub python: bool,
    /// What the run measured.
    pub metrics: Metrics,
}

/// ex6's graph with node `b.node` clamping at `clamp_n`: the built-in safety node, or, with
/// `script`, a Python node running it with `params = { max_force_n = clamp_n }`.
fn ex6_graph(
    b: &Ex6Bands,
    graph: &GraphSpec,
    clamp_n: f64,
    script: Option<&Path>,
) -> Result<GraphSpec, ExerciseError> {
    let mut g = graph.clone();
    let node = g
        .nodes
        .iter_mut()
        .find(|n| n.name == b.node)
        .ok_or_else(|| ExerciseError::NoNode(b.node.clone()))?;
    node.params
        .insert("max_force_n".into(), toml::Value::Float(clamp_n));
    if let Some(script) = script {
        let absolute = std::path::absolute(script).unwrap_or_else(|_| script.to_path_buf());
        node.kind = ratelab_runtime::graph::registry::kind("python").expect("a built-in kind");
        node.python = Some(ratelab_runtime::graph::kind::PythonCode {
            script: absolute.to_string_lossy().into_owned(),
            class: None,
        });
    }
    Ok(g)
}

/// ex6's measurements: every clamp on every seed, the built-in safety node and the Python
/// node `script` in its place (clamp order, seed fastest, built-in first). The Python
/// runs go one at a time (they share the interpreter).
///
/// # Errors
/// [`ExerciseError`] when the graph has no such node, or a run cannot start (the script
/// cannot be loaded: its one-line reason).
pub fn measure_ex6(
    b: &Ex6Bands,
    graph: &GraphSpec,
    script: &Path,
    stop: &StopFlag,
) -> Result<Vec<Ex6Run>, ExerciseError> {
    let mut jobs = Vec::new();
    for &clamp_n in &b.clamps_n {
        for python in [false, true] {
            let g = ex6_graph(b, graph, clamp_n, python.then_some(script))?;
            for &seed in &b.seeds {
                jobs.push((clamp_n, seed, python, g.clone()));
            }
        }
    }
    let run = |(clamp_n, seed, python, g): &(f64, u64, bool, GraphSpec)| {
        Ok(Ex6Run {
            clamp_n: *clamp_n,
            seed: *seed,
            python: *python,
            metrics: run_virtual(g.clone(), *seed, b.duration_s, stop)?.metrics,
        })
    };
    let (builtin, python): (Vec<_>, Vec<_>) = jobs.into_iter().partition(|j| !j.2);
    let mut runs: Vec<Ex6Run> = run_pool(&builtin, threads(), run)
        .into_iter()
        .collect::<Result<_, ExerciseError>>()?;
    for j in &python {
        runs.push(run(j)?);
    }
    Ok(runs)
}

/// The smallest clamp at which every run of `python` (or the built-in node) balanced.
fn ex6_smallest(runs: &[Ex6Run], python: bool) -> Option<f64> {
    let mut clamps: Vec<f64> = runs.iter().map(|r| r.clamp_n).collect();
    clamps.sort_by(f64::total_cmp);
    clamps.dedup();
    clamps.into_iter().find(|&c| {
        let rs: Vec<&Ex6Run> = runs
            .iter()
            .filter(|r| r.python == python && r.clamp_n == c)
            .collect();
        !rs.is_empty() && rs.iter().all(|r| r.metrics.balanced)
    })
}

/// The (clamp, seed) pairs where the Python node's verdict or fall differs from the
/// built-in node's.
pub fn ex6_differences(runs: &[Ex6Run]) -> Vec<(f64, u64)> {
    runs.iter()
        .filter(|p| p.python)
        .filter(|p| {
            !runs.iter().any(|b| {
                !b.python
                    && b.clamp_n == p.clamp_n
                    && b.seed == p.seed
                    && b.metrics.balanced == p.metrics.balanced
                    && b.metrics.fell_at_s == p.metrics.fell_at_s
            })
        })
        .map(|p| (p.clamp_n, p.seed))
        .collect()
}

/// ex6's outcome in the terms of its prediction.
pub fn outcome_ex6(runs: &[Ex6Run]) -> Ex6Outcome {
    Ex6Outcome {
        smallest_clamp_n: ex6_smallest(runs, true),
        matches_builtin: ex6_differences(runs).is_empty(),
    }
}

/// ex6's checks: the built-in safety node's smallest balancing clamp is the bands', and the
/// Python node (the reference limiter in the tests, the learner's in the exercise) limits
/// as it does.
pub fn check_ex6(b: &Ex6Bands, runs: &[Ex6Run]) -> Vec<Check> {
    let builtin = ex6_smallest(runs, false);
    let above = b
        .clamps_n
        .iter()
        .copied()
        .filter(|&c| c > b.smallest_balancing_clamp_n)
        .all(|c| {
            runs.iter()
                .filter(|r| !r.python && r.clamp_n == c)
                .all(|r| r.metrics.balanced)
        });
    vec![
        check(
            format!(
                "the built-in safety node keeps the pole up on every seed down to {} N, not below",
                b.smallest_balancing_clamp_n
            ),
            builtin == Some(b.smallest_balancing_clamp_n) && above,
        ),
        check(
            "the Python node gives the built-in node's verdict, at the same step, at every clamp and seed",
            runs.iter().any(|r| r.python) && ex6_differences(runs).is_empty(),
        ),
    ]
}

impl Ex6Outcome {
    /// Whether the learner's node limits as the built-in one does, in words (a finding the
    /// checks grade, said after the prediction).
    pub fn node_sentence(&self) -> &'static str {
        if self.matches_builtin {
            "Your node limits as the built-in safety node does: the same verdict, at the same step, at every clamp and seed."
        } else {
            "Your node does not limit as the built-in safety node does: see the table for where they differ."
        }
    }
}

/// A clamp of the ladder: right when it is the smallest that kept the pole up.
impl Reconcile for Ex6Outcome {
    fn reconcile(&self, prediction: &toml::Table) -> Vec<Said> {
        let key = "smallest_clamp_n";
        let measured = self.smallest_clamp_n.map_or_else(
            || "your node kept it up at none of the clamps".to_string(),
            |c| format!("with your node it was {c} N"),
        );
        vec![match prediction.get(key).and_then(super::number) {
            Some(n) => super::graded(
                key,
                &format!(
                    "You predicted the smallest clamp that keeps the pole up is {n} N; {measured}"
                ),
                self.smallest_clamp_n.is_some_and(|c| super::same(n, c)),
                "",
            ),
            None => super::unreadable(key),
        }]
    }
}

impl Exercise for Ex6 {
    fn id(&self) -> &'static str {
        "ex6"
    }

    fn title(&self) -> &'static str {
        "write your own node"
    }

    fn file(&self) -> &'static str {
        "ex6_own_node.toml"
    }

    fn required_keys(&self) -> &'static [&'static str] {
        &["smallest_clamp_n"]
    }

    fn default_graph(&self, bands: &super::Bands) -> Result<Option<String>, ExerciseError> {
        Ok(Some(bands.of::<Ex6Bands>()?.graph))
    }

    fn run(&self, cx: &mut Context<'_>) -> Result<(), ExerciseError> {
        let b: Ex6Bands = cx.bands()?;
        let script = cx.dir.join(&b.script);
        refuse_the_template(&script)?;
        let runs = cx.measure(|stop| measure_ex6(&b, cx.graph, &script, stop))?;
        table(cx, &b, &runs);
        let outcome = outcome_ex6(&runs);
        cx.reconcile(&outcome);
        cx.say(outcome.node_sentence());
        cx.checks(&check_ex6(&b, &runs));
        say!(cx);
        cx.paragraph(&format!(
            "Reconcile: the balancer's commands are large only in the first second, while it \
             catches the pole from the reset's tilt; once the pole is up, a few newtons' worth of \
             command is plenty. Clamped at {} N the pole still comes up on every seed; below it, \
             a seed whose first pushes need more falls in the first seconds. A limiter is a node \
             like any other: here it ticks at the same instants as the policy, just after it, so \
             it adds no sense->act latency. Try your node in the lab, and change its rate (Tab to \
             select it, then - and +):",
            b.smallest_balancing_clamp_n
        ));
        // The learner's node, not the shipped solution: the graph beside the exercise's files.
        let graph = cx.dir.join("ex6_my_limiter.toml");
        say!(
            cx,
            "  ./scripts/lab.sh --clock virtual --graph {}",
            graph.display()
        );
        Ok(())
    }
}

/// ex6's table: per clamp, the built-in node's verdict per seed, then the learner's.
fn table(cx: &mut Context<'_>, b: &Ex6Bands, runs: &[Ex6Run]) {
    let cell = |r: Option<&Ex6Run>| r.map_or("-".into(), |r| super::fell_cell(&r.metrics));
    let row = |clamp: f64, python: bool| -> Vec<String> {
        b.seeds
            .iter()
            .map(|&seed| {
                cell(
                    runs.iter()
                        .find(|r| r.clamp_n == clamp && r.seed == seed && r.python == python),
                )
            })
            .map(|c| format!("{c:<7}"))
            .collect()
    };
    say!(
        cx,
        "{:>9} | built-in safety node: {} | your node ({}): {}",
        "max force",
        seeds_header(&b.seeds),
        b.script,
        seeds_header(&b.seeds)
    );
    let differ = ex6_differences(runs);
    for &clamp in &b.clamps_n {
        let mark = if differ.iter().any(|(c, _)| *c == clamp) {
            "  <- differs"
        } else {
            ""
        };
        say!(
            cx,
            "{:>7} N | {:>21} {} | {:>w$} {}{mark}",
            clamp,
            "",
            row(clamp, false).join(" "),
            "",
            row(clamp, true).join(" "),
            w = 11 + b.script.len()
        );
    }
    say!(cx, "(Y: balanced the whole run; n@T: fell at T s)");
}

/// ex6's node as shipped, to tell the learner's from it: running the untouched template
/// would measure ratelab's pass-through, not the learner's node.
const EX6_TEMPLATE: &str = include_str!("../../exercises/ex6_my_limiter.py");

/// Refuse ex6's node file when it is still the template as shipped (line endings and
/// trailing blanks aside).
///
/// # Errors
/// [`ExerciseError::NotReady`]: the file is the untouched template.
fn refuse_the_template(script: &Path) -> Result<(), ExerciseError> {
    let normal = |t: &str| t.lines().map(str::trim_end).collect::<Vec<_>>().join("\n");
    let mine = std::fs::read(script).unwrap_or_default();
    if normal(&String::from_utf8_lossy(&mine)) == normal(EX6_TEMPLATE).as_str() {
        return Err(ExerciseError::NotReady(format!(
            "{} is the template as shipped: make on_action clamp msg.newtons to ±max_force_n (its TODO) first; writing the node is the exercise",
            script.display()
        )));
    }
    Ok(())
}
