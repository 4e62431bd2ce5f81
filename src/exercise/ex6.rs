//! ex6, write your own node: the learner's Python safety limiter in the safety graph's
//! place, over a ladder of clamps, beside the built-in safety node: the smallest clamp that
//! still balances, and whether the learner's node limits as the built-in one does.

use super::*;

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
        node.kind = crate::graph::registry::kind("python").expect("a built-in kind");
        node.python = Some(crate::graph::kind::PythonCode {
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
            metrics: run_virtual(g.clone(), *seed, b.duration_s)?.metrics,
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
pub fn outcome_ex6(runs: &[Ex6Run]) -> Outcome {
    Outcome::Ex6 {
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
