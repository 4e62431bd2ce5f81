//! The graph file's executors and compute times ([`ratelab_core::executor`]): a node's
//! `compute_ms` and `callback_group`, and `[executors.NAME]` tables.
//!
//! ```toml
//! [[node]]
//! name = "policy"
//! # …
//! compute_ms = 30                      # or { mean = 30, jitter = 5 }, ms
//! callback_group = "control"           # a group of the executor that holds the node
//!
//! [executors.main]
//! kind = "multi_threaded"              # per_node | single_threaded | multi_threaded
//! threads = 2                          # multi_threaded only, 1..=64
//! nodes = ["sensor", "policy"]
//! callback_groups = { control = "mutually_exclusive", io = "reentrant" }
//! ```
//!
//! Rules (each a [`SpecError`] at the culprit): a node is in at most one executor; an
//! executor names at least one node, every one of them declared; `threads` only on (and
//! required by) a multi-threaded executor; a node's `callback_group` names a group of the
//! executor holding it. A node in no
//! `[executors]` table runs on a thread of its own (`per_node`), in a group of its own.

use super::{Ctx, GraphSpec, NodeId, OverrideError, RawNode, SpecError};
use ratelab_core::executor::{
    ComputeTime, ExecutionPlan, ExecutorKind, ExecutorOverride, GroupKind, PlanExecutor,
    MAX_THREADS,
};
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;
use toml::Spanned;

/// One `[executors.NAME]` table of a validated graph.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ExecutorSpec {
    /// Its name (the table's key).
    pub name: String,
    /// Its kind.
    pub kind: ExecutorKind,
    /// Its threads: 1 unless multi-threaded.
    pub threads: usize,
    /// Its nodes, in tie-break order.
    pub nodes: Vec<NodeId>,
    /// Its callback groups by name.
    pub callback_groups: BTreeMap<String, GroupKind>,
}

#[derive(Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub(super) struct RawExecutor {
    kind: Spanned<ExecutorKind>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    threads: Option<Spanned<i64>>,
    nodes: Spanned<Vec<Spanned<String>>>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    callback_groups: Option<BTreeMap<String, Spanned<GroupKind>>>,
}

/// Why the actuator takes no compute time.
pub(super) const ACTUATOR_NO_COMPUTE: &str = "the actuator applies the command and steps the plant at its tick: it takes no compute time (give it to the node before it)";

/// The executors of a graph file, as serde reads them.
pub(super) type RawExecutors = BTreeMap<String, Spanned<RawExecutor>>;

/// A node's `compute_ms`: a number of milliseconds or `{ mean = MS, jitter = MS }`.
pub(super) fn compute(cx: &Ctx<'_>, raw: &Spanned<toml::Value>) -> Result<ComputeTime, SpecError> {
    let num = |v: &toml::Value| match v {
        toml::Value::Integer(i) => Some(*i as f64),
        toml::Value::Float(f) => Some(*f),
        _ => None,
    };
    let shape = "compute_ms must be a number of milliseconds or { mean = MS, jitter = MS }";
    let (mean, jitter) = match raw.get_ref() {
        toml::Value::Table(t) => {
            if t.keys().any(|k| k != "mean" && k != "jitter") {
                return Err(cx.err(raw.span(), shape));
            }
            let mean = t.get("mean").and_then(num);
            let jitter = t.get("jitter").map_or(Some(0.0), num);
            match (mean, jitter) {
                (Some(m), Some(j)) => (m, j),
                _ => return Err(cx.err(raw.span(), shape)),
            }
        }
        v => match num(v) {
            Some(m) => (m, 0.0),
            None => return Err(cx.err(raw.span(), shape)),
        },
    };
    ComputeTime::from_ms(mean, jitter).map_err(|e| cx.err(raw.span(), e))
}

/// `compute_ms` as the graph file writes it back ([`GraphSpec::to_toml`]).
pub(super) fn compute_value(c: &ComputeTime) -> toml::Value {
    let ms = |n: ratelab_core::time::Nanos| toml::Value::Float(n.as_millis_f64());
    if c.jitter.0 == 0 {
        ms(c.mean)
    } else {
        let mut t = toml::Table::new();
        t.insert("mean".into(), ms(c.mean));
        t.insert("jitter".into(), ms(c.jitter));
        toml::Value::Table(t)
    }
}

/// Check the `[executors]` tables of a graph whose nodes are in tie-break order; `raw_node`
/// gives node `j`'s table as the file wrote it.
pub(super) fn executors<'r>(
    cx: &Ctx<'_>,
    raw: &RawExecutors,
    spec: &GraphSpec,
    raw_node: impl Fn(usize) -> &'r RawNode,
) -> Result<Vec<ExecutorSpec>, SpecError> {
    let mut holder: Vec<Option<usize>> = vec![None; spec.nodes.len()];
    let mut out: Vec<ExecutorSpec> = Vec::new();
    // Node ids by name, once (an executor may list tens of thousands).
    let ids: std::collections::HashMap<&str, NodeId> = spec
        .nodes
        .iter()
        .enumerate()
        .map(|(i, n)| (n.name.as_str(), NodeId(i)))
        .collect();
    for (name, e) in raw {
        let r = e.get_ref();
        if !super::valid_node_name(name) {
            return Err(cx.err(
                e.span(),
                format!("executor name '{name}' must be 1 to 32 letters, digits, '_' or '-'"),
            ));
        }
        let kind = *r.kind.get_ref();
        let threads = match (kind, &r.threads) {
            (ExecutorKind::MultiThreaded, None) => {
                return Err(cx.err(
                    r.kind.span(),
                    format!("executor '{name}': a multi_threaded executor needs `threads` (1..={MAX_THREADS})"),
                ))
            }
            (ExecutorKind::MultiThreaded, Some(t)) => {
                let n = *t.get_ref();
                if !(1..=MAX_THREADS as i64).contains(&n) {
                    return Err(cx.err(
                        t.span(),
                        format!("executor '{name}': threads must be in 1..={MAX_THREADS}, got {n}"),
                    ));
                }
                n as usize
            }
            (_, Some(t)) => {
                return Err(cx.err(
                    t.span(),
                    format!(
                        "executor '{name}': `threads` is for multi_threaded executors (a {} one has {})",
                        kind.name(),
                        if kind == ExecutorKind::PerNode { "one per node" } else { "one" }
                    ),
                ))
            }
            (_, None) => 1,
        };
        if r.nodes.get_ref().is_empty() {
            return Err(cx.err(r.nodes.span(), format!("executor '{name}' holds no node")));
        }
        let index = out.len();
        let mut nodes = Vec::new();
        for n in r.nodes.get_ref() {
            let id = ids.get(n.get_ref().as_str()).copied().ok_or_else(|| {
                cx.err(
                    n.span(),
                    format!("executor '{name}': unknown node '{}'", n.get_ref()),
                )
            })?;
            if spec.node(id).kind.is_actuator() {
                return Err(cx.err(
                    n.span(),
                    format!(
                        "executor '{name}': the actuator '{}' steps the plant (20 ms of physics per tick) and keeps a thread of its own: run time must not wait for a thread",
                        n.get_ref()
                    ),
                ));
            }
            if let Some(other) = holder[id.0] {
                return Err(cx.err(
                    n.span(),
                    format!(
                        "node '{}' is already in executor '{}': a node runs on one executor",
                        n.get_ref(),
                        out.get(other).map_or(name.as_str(), |o| o.name.as_str())
                    ),
                ));
            }
            holder[id.0] = Some(index);
            nodes.push(id);
        }
        nodes.sort();
        let mut callback_groups = BTreeMap::new();
        for (g, k) in r.callback_groups.iter().flatten() {
            if !super::valid_node_name(g) {
                return Err(cx.err(
                    k.span(),
                    format!(
                        "callback group name '{g}' must be 1 to 32 letters, digits, '_' or '-'"
                    ),
                ));
            }
            callback_groups.insert(g.clone(), *k.get_ref());
        }
        out.push(ExecutorSpec {
            name: name.clone(),
            kind,
            threads,
            nodes,
            callback_groups,
        });
    }
    for (j, n) in spec.nodes.iter().enumerate() {
        let Some(g) = &raw_node(j).callback_group else {
            continue;
        };
        let known = holder[j].is_some_and(|e| out[e].callback_groups.contains_key(g.get_ref()));
        if !known {
            let reason = match holder[j] {
                None => format!(
                    "node '{}': callback_group '{}' but no [executors] table holds the node",
                    n.name,
                    g.get_ref()
                ),
                Some(e) => format!(
                    "node '{}': executor '{}' has no callback group '{}' (declare it in its callback_groups)",
                    n.name,
                    out[e].name,
                    g.get_ref()
                ),
            };
            return Err(cx.err(g.span(), reason));
        }
    }
    Ok(out)
}

/// The executors as the graph file writes them back.
pub(super) fn to_raw(spec: &GraphSpec) -> Option<RawExecutors> {
    fn s<T>(v: T) -> Spanned<T> {
        Spanned::new(0..0, v)
    }
    (!spec.executors.is_empty()).then(|| {
        spec.executors
            .iter()
            .map(|e| {
                let raw = RawExecutor {
                    kind: s(e.kind),
                    threads: (e.kind == ExecutorKind::MultiThreaded).then(|| s(e.threads as i64)),
                    nodes: s(e
                        .nodes
                        .iter()
                        .map(|&n| s(spec.node(n).name.clone()))
                        .collect()),
                    callback_groups: (!e.callback_groups.is_empty()).then(|| {
                        e.callback_groups
                            .iter()
                            .map(|(g, k)| (g.clone(), s(*k)))
                            .collect()
                    }),
                };
                (e.name.clone(), s(raw))
            })
            .collect()
    })
}

impl GraphSpec {
    /// Which executor and callback group each node runs in: the `[executors]` tables, every
    /// other node on a thread of its own in a group of its own.
    pub fn execution_plan(&self) -> ExecutionPlan {
        let n_nodes = self.nodes.len();
        let mut plan = ExecutionPlan {
            executors: Vec::new(),
            groups: Vec::new(),
            node_executor: vec![0; n_nodes],
            node_group: vec![0; n_nodes],
        };
        // Per-node executors first (one per node not held), then the declared ones.
        let mut held = vec![false; n_nodes];
        for n in self.executors.iter().flat_map(|e| &e.nodes) {
            if let Some(h) = held.get_mut(n.0) {
                *h = true;
            }
        }
        for (i, n) in self.nodes.iter().enumerate() {
            if !held[i] {
                plan.node_executor[i] = plan.executors.len();
                plan.executors.push(PlanExecutor {
                    name: n.name.clone(),
                    kind: ExecutorKind::PerNode,
                    threads: 1,
                });
                plan.node_group[i] = plan.groups.len();
                plan.groups.push(GroupKind::MutuallyExclusive);
            }
        }
        for e in &self.executors {
            let index = plan.executors.len();
            plan.executors.push(PlanExecutor {
                name: e.name.clone(),
                kind: e.kind,
                threads: e.threads,
            });
            let first_group = plan.groups.len();
            plan.groups.extend(e.callback_groups.values().copied());
            for &n in &e.nodes {
                plan.node_executor[n.0] = index;
                plan.node_group[n.0] = match &self.nodes[n.0].callback_group {
                    Some(g) => {
                        first_group + e.callback_groups.keys().position(|k| k == g).unwrap_or(0)
                    }
                    None => {
                        // The node's default group: mutually exclusive, its own.
                        plan.groups.push(GroupKind::MutuallyExclusive);
                        plan.groups.len() - 1
                    }
                };
            }
        }
        plan
    }

    /// Do any executors or compute times differ from ratelab's default (one thread per node,
    /// ticks that take no time)? Then metrics report response times and skipped ticks.
    pub fn has_executors_or_compute(&self) -> bool {
        self.executors
            .iter()
            .any(|e| e.kind != ExecutorKind::PerNode)
            || self
                .nodes
                .iter()
                .any(|n| n.compute.is_some_and(|c| !c.is_zero()))
    }

    /// `--executor`: one executor of that kind for every node but the actuator (per_node:
    /// none), replacing the file's `[executors]` and every node's `callback_group`. The
    /// actuator steps the plant and keeps a thread of its own.
    pub fn set_executor(&mut self, over: ExecutorOverride) {
        for n in &mut self.nodes {
            n.callback_group = None;
        }
        self.executors = match over.kind {
            ExecutorKind::PerNode => Vec::new(),
            kind => vec![ExecutorSpec {
                name: "main".into(),
                kind,
                threads: over.threads,
                nodes: (0..self.nodes.len())
                    .map(NodeId)
                    .filter(|&n| !self.node(n).kind.is_actuator())
                    .collect(),
                callback_groups: BTreeMap::new(),
            }],
        };
    }

    /// `--executor` on a launch across processes (`ratelab::distributed`): one executor of
    /// that kind per process, named after it, holding its nodes but the actuator (per_node:
    /// none), replacing the file's `[executors]` and every node's `callback_group`. Across
    /// processes each process has its own executors, as each ROS 2 process spins its own.
    pub fn set_executor_per_process(&mut self, over: ExecutorOverride) {
        self.set_executor(over);
        // `--executor`'s one executor (none for per_node), split by process.
        let Some(all) = self.executors.pop() else {
            return;
        };
        self.executors = self
            .placement()
            .into_iter()
            .filter_map(|(process, ids)| {
                let nodes: Vec<NodeId> = all
                    .nodes
                    .iter()
                    .copied()
                    .filter(|n| ids.contains(n))
                    .collect();
                (!nodes.is_empty()).then(|| ExecutorSpec {
                    name: process,
                    nodes,
                    ..all.clone()
                })
            })
            .collect();
        // By name, as a graph file's tables are: the same executors written in a file give
        // the same plan.
        self.executors.sort_by(|a, b| a.name.cmp(&b.name));
    }

    /// A launch across processes (`ratelab::distributed`) runs each process's executors in
    /// that process: no executor may hold nodes of two processes.
    ///
    /// # Errors
    /// One line naming the executor, two of its nodes and their processes.
    pub fn check_executors_per_process(&self) -> Result<(), String> {
        for e in &self.executors {
            let Some(&first) = e.nodes.first() else {
                continue;
            };
            let home = self.process_of(first);
            if let Some(&other) = e.nodes.iter().find(|&&n| self.process_of(n) != home) {
                return Err(format!(
                    "graph '{}': executor '{}' holds '{}' (process '{home}') and '{}' (process '{}'): across processes each process has its own executors, as each ROS 2 process spins its own; give each process its own [executors] table (or use --executor, which makes one per process), or run in one process (without --processes)",
                    self.name,
                    e.name,
                    self.node(first).name,
                    self.node(other).name,
                    self.process_of(other)
                ));
            }
        }
        Ok(())
    }

    /// `--compute NODE=MS`: node `name`'s compute time.
    ///
    /// # Errors
    /// [`OverrideError`] naming an unknown node, or the actuator (which applies the command
    /// and steps the plant at its tick).
    pub fn set_compute(&mut self, name: &str, c: ComputeTime) -> Result<(), OverrideError> {
        let id = self.node_id(name).ok_or_else(|| {
            OverrideError(format!(
                "--compute: unknown node '{name}' (nodes: {})",
                self.node_names().join(", ")
            ))
        })?;
        if self.nodes[id.0].kind.is_actuator() && !c.is_zero() {
            return Err(OverrideError(format!("--compute: {ACTUATOR_NO_COMPUTE}")));
        }
        self.nodes[id.0].compute = (!c.is_zero()).then_some(c);
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use ratelab_core::time::Nanos;

    const CHAIN: &str = r#"
name = "g"
[[node]]
name = "sensor"
kind = "sensor"
rate_hz = 50
publishes = "/obs"
compute_ms = { mean = 2, jitter = 0.5 }
[[node]]
name = "policy"
kind = "policy"
rate_hz = 50
subscribes = "/obs"
publishes = "/action"
compute_ms = 30
callback_group = "control"
[[node]]
name = "actuator"
kind = "actuator"
rate_hz = 50
subscribes = "/action"
[[topic]]
name = "/obs"
type = "state"
depth = 1
[[topic]]
name = "/action"
type = "force"
depth = 1
"#;

    fn with(extra: &str) -> Result<GraphSpec, SpecError> {
        GraphSpec::parse(&format!("{CHAIN}{extra}"), "g.toml")
    }

    const MAIN: &str = r#"
[executors.main]
kind = "multi_threaded"
threads = 2
nodes = ["sensor", "policy"]
callback_groups = { control = "mutually_exclusive" }
"#;

    #[test]
    fn executors_and_compute_times_read_and_round_trip() {
        let spec = with(MAIN).unwrap();
        let s = spec.node(spec.node_id("sensor").unwrap());
        assert_eq!(
            s.compute,
            Some(ComputeTime {
                mean: Nanos(2_000_000),
                jitter: Nanos(500_000)
            })
        );
        assert_eq!(spec.executors.len(), 1);
        assert_eq!(spec.executors[0].threads, 2);
        let plan = spec.execution_plan();
        // actuator per-node (executor 0), sensor and policy on "main" (executor 1).
        assert_eq!(plan.node_executor, vec![1, 1, 0]);
        assert_eq!(plan.executors[1].kind, ExecutorKind::MultiThreaded);
        assert_ne!(plan.node_group[0], plan.node_group[1]);
        assert!(spec.has_executors_or_compute());
        let back = GraphSpec::parse(&spec.to_toml(), "log").unwrap();
        assert_eq!(back, spec);
    }

    #[test]
    fn across_processes_an_executor_stays_in_its_process() {
        // The chapter's graph: sensor and actuator in 'robot', the policy in 'policy'.
        let mut spec = GraphSpec::chapter();
        spec.set_executor(ExecutorOverride::parse("single_threaded").unwrap());
        let e = spec.check_executors_per_process().unwrap_err();
        assert!(
            e.contains(
                "executor 'main' holds 'sensor' (process 'robot') and 'policy' (process 'policy')"
            ),
            "{e}"
        );
        spec.set_executor_per_process(ExecutorOverride::parse("multi_threaded:2").unwrap());
        spec.check_executors_per_process().unwrap();
        let names: Vec<(&str, usize)> = spec
            .executors
            .iter()
            .map(|e| (e.name.as_str(), e.nodes.len()))
            .collect();
        assert_eq!(
            names,
            vec![("policy", 1), ("robot", 1)],
            "by name, as a file's tables; the actuator keeps its thread"
        );
        assert!(spec.executors.iter().all(|e| e.threads == 2));
        spec.set_executor_per_process(ExecutorOverride::parse("per_node").unwrap());
        assert!(spec.executors.is_empty());
    }

    #[test]
    fn the_default_graph_has_no_executor_and_no_compute_time() {
        let spec = GraphSpec::chapter();
        assert!(!spec.has_executors_or_compute());
        assert!(spec.execution_plan().is_per_node());
    }

    #[test]
    fn bad_executors_are_refused_at_their_position() {
        let cases = [
            ("[executors.e]\nkind = \"multi_threaded\"\nnodes = [\"sensor\"]\n", "needs `threads`"),
            ("[executors.e]\nkind = \"multi_threaded\"\nthreads = 0\nnodes = [\"sensor\"]\n", "threads must be in"),
            ("[executors.e]\nkind = \"single_threaded\"\nthreads = 2\nnodes = [\"sensor\"]\n", "is for multi_threaded"),
            ("[executors.e]\nkind = \"single_threaded\"\nnodes = []\n", "holds no node"),
            ("[executors.e]\nkind = \"single_threaded\"\nnodes = [\"nobody\"]\n", "unknown node 'nobody'"),
            ("[executors.a]\nkind = \"single_threaded\"\nnodes = [\"sensor\"]\n[executors.b]\nkind = \"single_threaded\"\nnodes = [\"sensor\"]\n", "already in executor 'a'"),
            ("[executors.e]\nkind = \"single_threaded\"\nnodes = [\"sensor\", \"policy\"]\n", "has no callback group 'control'"),
            ("[executors.e]\nkind = \"fifo\"\nnodes = [\"sensor\"]\n", "unknown variant"),
            ("[executors.e]\nkind = \"single_threaded\"\nnodes = [\"actuator\"]\n", "keeps a thread of its own"),
            ("", "no [executors] table holds"),
        ];
        for (extra, want) in cases {
            let e = with(extra).expect_err(extra).to_string();
            assert!(e.contains(want), "{extra}: {e}");
            assert!(e.starts_with("g.toml:"), "{e}");
            assert!(!e.starts_with("g.toml:0"), "with a position: {e}");
        }
        let bad_compute = CHAIN.replace("compute_ms = 30", "compute_ms = { mean = 1, jitter = 2 }");
        let e = GraphSpec::parse(&bad_compute, "g.toml")
            .unwrap_err()
            .to_string();
        assert!(e.contains("must not exceed its mean"), "{e}");
        let bad_compute = CHAIN.replace("compute_ms = 30", "compute_ms = \"slow\"");
        let e = GraphSpec::parse(&bad_compute, "g.toml")
            .unwrap_err()
            .to_string();
        assert!(e.contains("compute_ms must be a number"), "{e}");
    }

    #[test]
    fn the_command_line_overrides_the_executors_and_compute_times() {
        let mut spec = with(MAIN).unwrap();
        spec.set_executor(ExecutorOverride::parse("single_threaded").unwrap());
        let plan = spec.execution_plan();
        // The actuator keeps a thread of its own (executor 0); the rest share "main".
        assert_eq!(plan.executors.len(), 2);
        assert_eq!(plan.node_executor, vec![1, 1, 0]);
        assert_eq!(plan.executors[1].threads, 1);
        assert_eq!(plan.executors[0].kind, ExecutorKind::PerNode);
        let e = spec
            .set_compute("actuator", ComputeTime::parse("1").unwrap())
            .unwrap_err();
        assert!(e.0.contains("steps the plant"), "{e}");
        spec.set_executor(ExecutorOverride::parse("per_node").unwrap());
        assert!(spec.execution_plan().is_per_node());
        spec.set_compute("policy", ComputeTime::parse("0").unwrap())
            .unwrap();
        spec.set_compute("sensor", ComputeTime::parse("0").unwrap())
            .unwrap();
        assert!(!spec.has_executors_or_compute());
        assert!(spec
            .set_compute("nobody", ComputeTime::parse("1").unwrap())
            .is_err());
        assert_eq!(GraphSpec::parse(&spec.to_toml(), "log").unwrap(), spec);
    }
}
