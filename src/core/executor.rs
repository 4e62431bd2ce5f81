//! Executors and compute time: which thread runs a node's tick, when, and for how long.
//!
//! ROS 2 runs callbacks on **executors** ("About Executors", ROS 2 documentation): a
//! *single-threaded* executor runs the ready callbacks of its nodes one at a time on one
//! thread; a *multi-threaded* one runs them on a pool of threads, limited by **callback
//! groups** (callbacks of a *mutually exclusive* group never overlap; those of a *reentrant*
//! group may). ratelab's historical model, one thread per node, is the executor kind
//! [`ExecutorKind::PerNode`] (the default). This module holds the rules as data and pure
//! functions; `ratelab::scheduler` applies them under both clocks.
//!
//! - **Timers** follow rcl's `rcl_timer_call` (rcl/src/rcl/timer.c): a call moves the next
//!   call time one period on from the previous *scheduled* time, and a timer that missed
//!   whole periods skips them and stays phase-aligned ([`crate::rate::next_deadline`]): no
//!   burst of catch-up ticks. Those skipped periods are the node's `skipped_ticks`.
//! - **Order**: an executor takes a snapshot of its ready callbacks when it has nothing left
//!   to run (a *polling point*) and runs the snapshot in registration order (here the node
//!   order of the graph file, its tie-break rank) before it looks again: round-robin over
//!   ready entities, not first-come first-served (Casini, Blaß, Lütkebohle, Brandenburg,
//!   "Response-Time Analysis of ROS 2 Processing Chains Under Reservation-Based
//!   Scheduling", ECRTS 2019, §3). A callback released meanwhile waits for the next poll.
//! - **Compute time**: a tick reads its inputs when it starts and its outputs are published
//!   when its compute time has elapsed ([`ComputeTime`]); its thread is busy meanwhile.
//! - A node never overlaps itself (its state is one value), whatever its group: in a
//!   reentrant group, *different* nodes of the group may run at once.

use crate::time::Nanos;
use rand_distr::{Distribution, Uniform};

/// What a node's tick costs: `mean ± jitter`, uniform, drawn per tick from a generator
/// seeded by the run's seed and the node's rank (so virtual runs stay byte-identical).
/// Graph file: `compute_ms = 3` or `compute_ms = { mean = 3, jitter = 1 }`; command line:
/// `--compute NODE=MS` or `--compute NODE=MEAN±JITTER` (also `MEAN+-JITTER`).
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct ComputeTime {
    /// Mean compute time of a tick.
    pub mean: Nanos,
    /// Half-width of the uniform spread around the mean (≤ `mean`).
    pub jitter: Nanos,
}

/// Largest compute time a node may declare: 10 s.
pub const MAX_COMPUTE: Nanos = Nanos(10_000_000_000);

impl ComputeTime {
    /// `mean_ms ± jitter_ms`.
    ///
    /// # Errors
    /// One line when either is negative or not finite, the jitter exceeds the mean, or the
    /// mean exceeds [`MAX_COMPUTE`].
    pub fn from_ms(mean_ms: f64, jitter_ms: f64) -> Result<ComputeTime, String> {
        if !(mean_ms.is_finite() && mean_ms >= 0.0) {
            return Err(format!("compute time must be ≥ 0 ms, got {mean_ms}"));
        }
        if !(jitter_ms.is_finite() && jitter_ms >= 0.0) {
            return Err(format!("compute jitter must be ≥ 0 ms, got {jitter_ms}"));
        }
        if jitter_ms > mean_ms {
            return Err(format!(
                "compute jitter ({jitter_ms} ms) must not exceed its mean ({mean_ms} ms)"
            ));
        }
        if mean_ms > MAX_COMPUTE.as_millis_f64() {
            return Err(format!(
                "compute time must be at most 10000 ms, got {mean_ms}"
            ));
        }
        let ns = |ms: f64| Nanos((ms * 1e6).round() as u64);
        Ok(ComputeTime {
            mean: ns(mean_ms),
            jitter: ns(jitter_ms),
        })
    }

    /// Parse `MS`, `MEAN±JITTER` or `MEAN+-JITTER` (milliseconds).
    ///
    /// # Errors
    /// One line naming what is wrong.
    pub fn parse(text: &str) -> Result<ComputeTime, String> {
        let num = |s: &str| {
            s.trim()
                .parse::<f64>()
                .map_err(|_| format!("'{s}' is not a number of milliseconds"))
        };
        match text.split_once('±').or_else(|| text.split_once("+-")) {
            Some((m, j)) => Self::from_ms(num(m)?, num(j)?),
            None => Self::from_ms(num(text)?, 0.0),
        }
    }

    /// Is it zero (outputs published at once)?
    pub fn is_zero(&self) -> bool {
        self.mean.0 == 0
    }

    /// In short: `3 ms`, `3±1 ms`.
    pub fn label(&self) -> String {
        if self.jitter.0 == 0 {
            format!("{} ms", trim_ms(self.mean))
        } else {
            format!("{}±{} ms", trim_ms(self.mean), trim_ms(self.jitter))
        }
    }
}

fn trim_ms(n: Nanos) -> String {
    let s = format!("{:.3}", n.as_millis_f64());
    s.trim_end_matches('0').trim_end_matches('.').to_string()
}

/// Where a command leaves a plan for the virtual scheduler to take at its next instant
/// (`ratelab::scheduler::VirtualScheduler::take_plans_from`): the graph's handles hold it.
pub type PlanRequest = std::sync::Arc<std::sync::Mutex<Option<ExecutionPlan>>>;

/// A node's compute-time generator: [`ComputeTime`] with its seeded draws.
#[derive(Clone, Debug)]
pub struct ComputeDraw {
    time: ComputeTime,
    rng: rand_pcg::Pcg64,
}

impl ComputeDraw {
    /// Draws for node rank `rank` of a run seeded `seed`.
    pub fn new(time: ComputeTime, seed: u64, rank: usize) -> ComputeDraw {
        ComputeDraw {
            time,
            // "compute" in the stream constant, the rank apart: one stream per node.
            rng: rand_pcg::Pcg64::new(u128::from(seed), 0x0063_6f6d_7075_7465 ^ rank as u128),
        }
    }

    /// The next tick's compute time.
    pub fn draw(&mut self) -> Nanos {
        let ComputeTime { mean, jitter } = self.time;
        if jitter.0 == 0 {
            return mean;
        }
        let lo = mean.0 - jitter.0;
        let hi = mean.0.saturating_add(jitter.0);
        Uniform::new_inclusive(lo, hi).map_or(mean, |u| Nanos(u.sample(&mut self.rng)))
    }
}

/// The kinds of executor, with ROS 2's names.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum ExecutorKind {
    /// One thread per node (ratelab's default; the chapter's `run_real`).
    PerNode,
    /// One thread for all its nodes (rclcpp's `SingleThreadedExecutor`).
    SingleThreaded,
    /// A pool of threads (rclcpp's `MultiThreadedExecutor`), limited by callback groups.
    MultiThreaded,
}

impl ExecutorKind {
    /// Its name in graph files and on the command line.
    pub fn name(self) -> &'static str {
        match self {
            ExecutorKind::PerNode => "per_node",
            ExecutorKind::SingleThreaded => "single_threaded",
            ExecutorKind::MultiThreaded => "multi_threaded",
        }
    }
}

/// The kinds of callback group, with ROS 2's names.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum GroupKind {
    /// Its nodes' ticks never overlap (ROS 2's default group kind).
    MutuallyExclusive,
    /// Its nodes' ticks may overlap (a node never overlaps itself).
    Reentrant,
}

/// Largest thread count of a multi-threaded executor.
pub const MAX_THREADS: usize = 64;

/// `--executor single_threaded|multi_threaded:N|per_node`: one executor for the whole graph
/// (per_node: today's one thread per node), replacing the graph file's `[executors]`.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub struct ExecutorOverride {
    /// The kind.
    pub kind: ExecutorKind,
    /// Threads (1 for single_threaded; ignored for per_node).
    pub threads: usize,
}

impl ExecutorOverride {
    /// Parse the command line's value.
    ///
    /// # Errors
    /// One line naming the accepted forms.
    pub fn parse(text: &str) -> Result<ExecutorOverride, String> {
        let bad = || {
            format!(
                "unknown executor '{text}': use per_node, single_threaded or multi_threaded:N \
                 (N threads, 1..={MAX_THREADS})"
            )
        };
        match text {
            "per_node" => Ok(ExecutorOverride {
                kind: ExecutorKind::PerNode,
                threads: 1,
            }),
            "single_threaded" => Ok(ExecutorOverride {
                kind: ExecutorKind::SingleThreaded,
                threads: 1,
            }),
            _ => {
                let n = text.strip_prefix("multi_threaded:").ok_or_else(bad)?;
                let threads: usize = n.parse().map_err(|_| bad())?;
                if threads == 0 || threads > MAX_THREADS {
                    return Err(bad());
                }
                Ok(ExecutorOverride {
                    kind: ExecutorKind::MultiThreaded,
                    threads,
                })
            }
        }
    }
}

/// One tick as an executor ran it: for the lab's executor timeline.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct CallbackSpan {
    /// The node (index in the graph).
    pub node: usize,
    /// When its timer was due (the tick's release).
    pub release: Nanos,
    /// When the tick started on a thread.
    pub start: Nanos,
    /// When it ended (its outputs published).
    pub end: Nanos,
}

/// Told of every tick as an executor ran it ([`CallbackSpan`]; a recording's timeline).
pub type SpanHook = std::sync::Arc<dyn Fn(&CallbackSpan) + Send + Sync>;

/// The most [`CallbackSpan`]s a virtual scheduler keeps between two reads (the oldest go).
pub const MAX_SPANS: usize = 4096;

/// One executor of a plan.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct PlanExecutor {
    /// Its name (a per-node executor is named after its node).
    pub name: String,
    /// Its kind.
    pub kind: ExecutorKind,
    /// Its threads.
    pub threads: usize,
}

/// Which executor and callback group each node belongs to: the graph's execution plan,
/// built from the graph file (`ratelab::graph::spec`) and `--executor`.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct ExecutionPlan {
    /// The executors.
    pub executors: Vec<PlanExecutor>,
    /// The callback groups' kinds.
    pub groups: Vec<GroupKind>,
    /// Each node's executor (index into `executors`), by node index.
    pub node_executor: Vec<usize>,
    /// Each node's callback group (index into `groups`), by node index.
    pub node_group: Vec<usize>,
}

impl ExecutionPlan {
    /// One thread per node, each node its own mutually exclusive group: ratelab's default.
    pub fn per_node(names: &[&str]) -> ExecutionPlan {
        ExecutionPlan {
            executors: names
                .iter()
                .map(|n| PlanExecutor {
                    name: (*n).to_string(),
                    kind: ExecutorKind::PerNode,
                    threads: 1,
                })
                .collect(),
            groups: vec![GroupKind::MutuallyExclusive; names.len()],
            node_executor: (0..names.len()).collect(),
            node_group: (0..names.len()).collect(),
        }
    }

    /// Every node on one executor of `kind` with `threads`, each node its own mutually
    /// exclusive group (a plan made by hand, as the tests do; `--executor` goes through
    /// `ratelab::graph::GraphSpec::set_executor`, which keeps the actuator on a thread of its
    /// own). `per_node` gives [`ExecutionPlan::per_node`].
    pub fn one_executor(names: &[&str], kind: ExecutorKind, threads: usize) -> ExecutionPlan {
        if kind == ExecutorKind::PerNode {
            return Self::per_node(names);
        }
        ExecutionPlan {
            executors: vec![PlanExecutor {
                name: "main".into(),
                kind,
                threads: if kind == ExecutorKind::SingleThreaded {
                    1
                } else {
                    threads
                },
            }],
            groups: vec![GroupKind::MutuallyExclusive; names.len()],
            node_executor: vec![0; names.len()],
            node_group: (0..names.len()).collect(),
        }
    }

    /// The plan of the nodes `keep` (indices into this plan's nodes, in the order the new
    /// plan indexes them): the executors and callback groups that hold any of them, in this
    /// plan's order. What one process of a launch runs (`ratelab::distributed`: its nodes
    /// only; an executor never spans processes).
    pub fn restricted(&self, keep: &[usize]) -> ExecutionPlan {
        let mut executors: Vec<usize> = keep.iter().map(|&n| self.node_executor[n]).collect();
        let mut groups: Vec<usize> = keep.iter().map(|&n| self.node_group[n]).collect();
        executors.sort_unstable();
        executors.dedup();
        groups.sort_unstable();
        groups.dedup();
        let at = |v: &[usize], x: usize| v.iter().position(|&y| y == x).unwrap_or(0);
        ExecutionPlan {
            executors: executors
                .iter()
                .map(|&e| self.executors[e].clone())
                .collect(),
            groups: groups.iter().map(|&g| self.groups[g]).collect(),
            node_executor: keep
                .iter()
                .map(|&n| at(&executors, self.node_executor[n]))
                .collect(),
            node_group: keep
                .iter()
                .map(|&n| at(&groups, self.node_group[n]))
                .collect(),
        }
    }

    /// Is every node on a thread of its own (nothing shared, nothing to wait for)?
    pub fn is_per_node(&self) -> bool {
        self.executors
            .iter()
            .all(|e| e.kind == ExecutorKind::PerNode)
    }

    /// The executors that are not per-node, with their nodes (by index): what a summary
    /// lists.
    pub fn shared(&self) -> Vec<(usize, Vec<usize>)> {
        self.executors
            .iter()
            .enumerate()
            .filter(|(_, e)| e.kind != ExecutorKind::PerNode)
            .map(|(i, _)| {
                let nodes = (0..self.node_executor.len())
                    .filter(|&n| self.node_executor[n] == i)
                    .collect();
                (i, nodes)
            })
            .collect()
    }
}

/// An executor's bookkeeping while a graph runs: which nodes are ready, in its snapshot,
/// running; which threads and groups are busy. Pure state, advanced by the scheduler under
/// either clock (the virtual one calls it with virtual instants, the real one with the
/// monotonic clock's), so both apply the same rules.
#[derive(Clone, Debug)]
pub struct Dispatch {
    plan: ExecutionPlan,
    /// Node indices by tie-break rank (lower first, then index): the registration order.
    order: Vec<usize>,
    /// Each node's place in `order`.
    place: Vec<usize>,
    /// Each executor's nodes, by node index.
    members: Vec<Vec<usize>>,
    ready: Vec<bool>,
    /// Ready nodes per executor (only an executor with some polls to any effect).
    ready_in: Vec<usize>,
    in_snapshot: Vec<bool>,
    /// The places in `order` of the nodes in a snapshot: the candidates of
    /// [`Dispatch::pick`], lowest rank first (a graph of thousands of nodes has few ready at
    /// once).
    snapshot: std::collections::BTreeSet<usize>,
    running: Vec<bool>,
    busy_threads: Vec<usize>,
    busy_groups: Vec<usize>,
    /// Each group's executors (those with a node in it), by index.
    group_executors: Vec<Vec<usize>>,
    /// The executors whose poll may change something: something it reads changed since it
    /// last polled (a node of its own released, started or finished; a group of one of its
    /// nodes taken or let go; a new plan). A poll is idempotent while what it reads stays
    /// the same, so [`Dispatch::pick`] polls only these, each at most once, instead of
    /// every executor with a ready node at every pick.
    stale: Vec<usize>,
    /// `is_stale[e]`: `e` is in `stale`.
    is_stale: Vec<bool>,
}

/// Each executor of `plan`'s nodes, by node index.
fn members_of(plan: &ExecutionPlan) -> Vec<Vec<usize>> {
    let mut members = vec![Vec::new(); plan.executors.len()];
    for (i, &e) in plan.node_executor.iter().enumerate() {
        if let Some(m) = members.get_mut(e) {
            m.push(i);
        }
    }
    members
}

/// Each group of `plan`'s executors with a node in it, by executor index, once each.
fn group_executors_of(plan: &ExecutionPlan) -> Vec<Vec<usize>> {
    let mut of = vec![Vec::new(); plan.groups.len()];
    for (&e, &g) in plan.node_executor.iter().zip(&plan.node_group) {
        if let Some(list) = of.get_mut(g) {
            list.push(e);
        }
    }
    for list in &mut of {
        list.sort_unstable();
        list.dedup();
    }
    of
}

impl Dispatch {
    /// Nothing ready, nothing running; node `i` has tie-break rank `ranks[i]` (missing: its
    /// index).
    pub fn new(plan: ExecutionPlan, ranks: &[u32]) -> Dispatch {
        let n = plan.node_executor.len();
        let mut order: Vec<usize> = (0..n).collect();
        order.sort_by_key(|&i| (ranks.get(i).copied().unwrap_or(i as u32), i));
        let mut place = vec![0; n];
        for (p, &i) in order.iter().enumerate() {
            place[i] = p;
        }
        Dispatch {
            order,
            place,
            members: members_of(&plan),
            ready: vec![false; n],
            ready_in: vec![0; plan.executors.len()],
            in_snapshot: vec![false; n],
            snapshot: Default::default(),
            running: vec![false; n],
            busy_threads: vec![0; plan.executors.len()],
            busy_groups: vec![0; plan.groups.len()],
            group_executors: group_executors_of(&plan),
            stale: Vec::new(),
            is_stale: vec![false; plan.executors.len()],
            plan,
        }
    }

    /// Executor `e` must poll again at the next [`Dispatch::pick`].
    fn mark_stale(&mut self, e: usize) {
        if let Some(s) = self.is_stale.get_mut(e) {
            if !std::mem::replace(s, true) {
                self.stale.push(e);
            }
        }
    }

    /// Node `node`'s thread and group changed hands: its executor, and every executor with
    /// a node in its group, must poll again.
    fn mark_stale_around(&mut self, node: usize) {
        self.mark_stale(self.plan.node_executor[node]);
        let g = self.plan.node_group[node];
        for k in 0..self.group_executors.get(g).map_or(0, Vec::len) {
            self.mark_stale(self.group_executors[g][k]);
        }
    }

    /// The plan.
    pub fn plan(&self) -> &ExecutionPlan {
        &self.plan
    }

    /// Run on `plan` from now on (the lab's executor key, at an instant of the virtual
    /// clock): what is ready stays ready, what runs keeps its thread — a thread of its
    /// executor under the new plan, even past that executor's threads (nothing new starts
    /// there until enough have finished) — and every executor polls afresh.
    ///
    /// # Panics
    /// When `plan` is for another number of nodes.
    pub fn replan(&mut self, plan: ExecutionPlan) {
        assert_eq!(
            plan.node_executor.len(),
            self.ready.len(),
            "a plan for these nodes"
        );
        self.busy_threads = vec![0; plan.executors.len()];
        self.busy_groups = vec![0; plan.groups.len()];
        for (i, &running) in self.running.iter().enumerate() {
            if running {
                self.busy_threads[plan.node_executor[i]] += 1;
                self.busy_groups[plan.node_group[i]] += 1;
            }
        }
        self.in_snapshot.iter_mut().for_each(|s| *s = false);
        self.snapshot.clear();
        self.members = members_of(&plan);
        self.group_executors = group_executors_of(&plan);
        self.stale = (0..plan.executors.len()).collect();
        self.is_stale = vec![true; plan.executors.len()];
        self.ready_in = vec![0; plan.executors.len()];
        for (i, &ready) in self.ready.iter().enumerate() {
            if ready {
                self.ready_in[plan.node_executor[i]] += 1;
            }
        }
        self.plan = plan;
    }

    /// Node `node`'s timer is due: it waits for a thread (and for its executor's next poll).
    pub fn release(&mut self, node: usize) {
        if !std::mem::replace(&mut self.ready[node], true) {
            let e = self.plan.node_executor[node];
            self.ready_in[e] += 1;
            self.mark_stale(e);
        }
    }

    /// Is node `node` running (started, outputs not yet published)?
    pub fn is_running(&self, node: usize) -> bool {
        self.running[node]
    }

    fn startable(&self, node: usize) -> bool {
        let e = self.plan.node_executor[node];
        let g = self.plan.node_group[node];
        self.ready[node]
            && !self.running[node]
            && self.busy_threads[e] < self.plan.executors[e].threads
            && (self.busy_groups[g] == 0 || self.plan.groups[g] == GroupKind::Reentrant)
    }

    /// Executor `e`'s polling point: when it has a free thread and nothing in its snapshot can
    /// start, its snapshot becomes every ready node of its own not running. Returns whether it
    /// has a free thread (`false` too for an executor index out of range).
    fn poll_if_idle(&mut self, e: usize) -> bool {
        if self
            .busy_threads
            .get(e)
            .is_none_or(|&b| b >= self.plan.executors[e].threads)
        {
            return false;
        }
        let members = &self.members[e];
        if !members
            .iter()
            .any(|&i| self.in_snapshot[i] && self.startable(i))
        {
            for &i in members {
                let now = self.ready[i] && !self.running[i];
                self.in_snapshot[i] = now;
                if now {
                    self.snapshot.insert(self.place[i]);
                } else {
                    self.snapshot.remove(&self.place[i]);
                }
            }
        }
        true
    }

    /// Executor `e`'s next node to start now (a thread of `e` asks), polling `e` first when
    /// nothing in its snapshot can start; `None` when every ready node of `e` waits.
    pub fn pick_for(&mut self, e: usize) -> Option<usize> {
        if !self.poll_if_idle(e) {
            return None;
        }
        self.members[e]
            .iter()
            .copied()
            .filter(|&i| self.in_snapshot[i] && self.startable(i))
            .min_by_key(|&i| self.place[i])
    }

    /// The next node to start now, by the rules above, or `None` when every ready node waits
    /// (for a thread, its group, or its executor's next poll). An executor with a free thread
    /// and nothing startable in its snapshot polls first (takes every ready node of its own
    /// as its new snapshot); then the lowest-ranked startable node of any snapshot starts.
    /// Call [`Dispatch::start`] with it.
    pub fn pick(&mut self) -> Option<usize> {
        // Polling every executor with a ready node, as the rule says, is polling the stale
        // ones: the others' polls would change nothing (see `stale`). Polls of different
        // executors touch only their own nodes' snapshots, so their order does not matter.
        // An executor with no ready node has an empty snapshot (a node leaves its snapshot
        // only by starting, which is the only way it stops being ready), so its poll would
        // change nothing either.
        for e in std::mem::take(&mut self.stale) {
            self.is_stale[e] = false;
            if self.ready_in[e] > 0 {
                self.poll_if_idle(e);
            }
        }
        self.snapshot
            .iter()
            .map(|&p| self.order[p])
            .find(|&i| self.startable(i))
    }

    /// Node `node` starts (it was [`Dispatch::pick`]ed): it holds a thread of its executor and
    /// its group until [`Dispatch::finish`] (at once for a zero compute time).
    pub fn start(&mut self, node: usize) {
        if std::mem::take(&mut self.ready[node]) {
            self.ready_in[self.plan.node_executor[node]] -= 1;
        }
        self.in_snapshot[node] = false;
        self.snapshot.remove(&self.place[node]);
        self.running[node] = true;
        self.busy_threads[self.plan.node_executor[node]] += 1;
        self.busy_groups[self.plan.node_group[node]] += 1;
        self.mark_stale_around(node);
    }

    /// Node `node`'s tick is done: its outputs are published, its thread and group free.
    pub fn finish(&mut self, node: usize) {
        if std::mem::take(&mut self.running[node]) {
            self.busy_threads[self.plan.node_executor[node]] -= 1;
            self.busy_groups[self.plan.node_group[node]] -= 1;
            self.mark_stale_around(node);
        }
    }
}

/// One node's figures under its executor: what `metrics.json` reports as
/// `nodes.<name>.response_time_p50_ms` … and `skipped_ticks` (docs/metrics.md).
#[derive(Clone, Debug, Default, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct NodeExecFigures {
    /// Response time (release, when its timer was due → outputs published), median, ms.
    pub response_time_p50_ms: f64,
    /// 99th percentile, ms.
    pub response_time_p99_ms: f64,
    /// Largest, ms.
    pub response_time_max_ms: f64,
    /// Periods its timer skipped because the previous tick or another callback held the
    /// thread ([`crate::rate::next_deadline`]).
    pub skipped_ticks: u64,
    /// Time its ticks held a thread (the sum of their compute times), ms.
    pub busy_ms: f64,
}

/// One executor's figures: its threads' utilization.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct ExecutorFigures {
    /// Its name.
    pub name: String,
    /// Its kind.
    pub kind: ExecutorKind,
    /// Its threads.
    pub threads: usize,
    /// Busy time over available thread time (`threads ×` run time), in [0, 1].
    pub utilization: f64,
}

/// A run's executor figures, by node and by executor.
#[derive(Clone, Debug, Default, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct ExecFigures {
    /// By node index.
    pub nodes: Vec<NodeExecFigures>,
    /// By executor index of the [`ExecutionPlan`].
    pub executors: Vec<ExecutorFigures>,
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_restricted_plan_keeps_the_executors_and_groups_of_its_nodes_renumbered() {
        // a, b, c on one multi-threaded executor with a shared reentrant group for b and c;
        // d on a thread of its own.
        let plan = ExecutionPlan {
            executors: vec![
                PlanExecutor {
                    name: "d".into(),
                    kind: ExecutorKind::PerNode,
                    threads: 1,
                },
                PlanExecutor {
                    name: "main".into(),
                    kind: ExecutorKind::MultiThreaded,
                    threads: 2,
                },
            ],
            groups: vec![
                GroupKind::MutuallyExclusive,
                GroupKind::Reentrant,
                GroupKind::MutuallyExclusive,
            ],
            node_executor: vec![1, 1, 1, 0],
            node_group: vec![2, 1, 1, 0],
        };
        let bc = plan.restricted(&[1, 2]);
        assert_eq!(bc.executors, vec![plan.executors[1].clone()]);
        assert_eq!(bc.groups, vec![GroupKind::Reentrant]);
        assert_eq!((bc.node_executor, bc.node_group), (vec![0, 0], vec![0, 0]));
        let da = plan.restricted(&[3, 0]);
        assert_eq!(da.executors, plan.executors);
        assert_eq!(
            da.groups,
            vec![GroupKind::MutuallyExclusive, GroupKind::MutuallyExclusive]
        );
        assert_eq!((da.node_executor, da.node_group), (vec![0, 1], vec![0, 1]));
        assert_eq!(plan.restricted(&[0, 1, 2, 3]), plan);
    }

    #[test]
    fn a_new_plan_keeps_what_runs_on_its_thread_and_what_is_ready() {
        // Two nodes on threads of their own; node 0 runs, node 1 is ready.
        let mut d = Dispatch::new(ExecutionPlan::per_node(&["a", "b"]), &[0, 1]);
        d.release(0);
        assert_eq!(d.pick(), Some(0));
        d.start(0);
        d.release(1);
        // One thread for both: node 0 keeps it, node 1 waits for it.
        d.replan(ExecutionPlan::one_executor(
            &["a", "b"],
            ExecutorKind::SingleThreaded,
            1,
        ));
        assert!(d.is_running(0));
        assert_eq!(d.pick(), None, "the one thread is held");
        d.finish(0);
        assert_eq!(d.pick(), Some(1));
    }

    #[test]
    fn compute_times_parse_and_draw_within_their_spread() {
        assert_eq!(ComputeTime::parse("3").unwrap().mean, Nanos(3_000_000));
        let c = ComputeTime::parse("3±1").unwrap();
        assert_eq!((c.mean, c.jitter), (Nanos(3_000_000), Nanos(1_000_000)));
        assert_eq!(ComputeTime::parse("3+-1").unwrap(), c);
        assert_eq!(c.label(), "3±1 ms");
        assert_eq!(ComputeTime::parse("2.5").unwrap().label(), "2.5 ms");
        for bad in ["", "-1", "nan", "1±2", "x", "20000", "3±"] {
            assert!(ComputeTime::parse(bad).is_err(), "{bad}");
        }
        let mut a = ComputeDraw::new(c, 7, 1);
        let mut b = ComputeDraw::new(c, 7, 1);
        let draws: Vec<_> = (0..200).map(|_| a.draw()).collect();
        assert!(draws.iter().all(|d| (2_000_000..=4_000_000).contains(&d.0)));
        assert!(draws.iter().any(|d| *d != draws[0]), "it varies");
        assert_eq!(draws, (0..200).map(|_| b.draw()).collect::<Vec<_>>());
        let mut other = ComputeDraw::new(c, 7, 2);
        assert_ne!(draws, (0..200).map(|_| other.draw()).collect::<Vec<_>>());
    }

    #[test]
    fn executor_overrides_parse() {
        assert_eq!(
            ExecutorOverride::parse("multi_threaded:2").unwrap(),
            ExecutorOverride {
                kind: ExecutorKind::MultiThreaded,
                threads: 2
            }
        );
        assert_eq!(
            ExecutorOverride::parse("single_threaded").unwrap().kind,
            ExecutorKind::SingleThreaded
        );
        for bad in [
            "",
            "multi_threaded",
            "multi_threaded:0",
            "multi_threaded:65",
            "fifo",
        ] {
            assert!(ExecutorOverride::parse(bad).is_err(), "{bad}");
        }
    }

    fn drain(d: &mut Dispatch) -> Vec<usize> {
        let mut started = Vec::new();
        while let Some(i) = d.pick() {
            d.start(i);
            started.push(i);
        }
        started
    }

    #[test]
    fn per_node_starts_every_ready_node_in_rank_order() {
        let mut d = Dispatch::new(ExecutionPlan::per_node(&["a", "b", "c"]), &[]);
        for i in [2, 0, 1] {
            d.release(i);
        }
        assert_eq!(drain(&mut d), vec![0, 1, 2]);
    }

    #[test]
    fn a_single_thread_runs_one_at_a_time_and_polls_only_when_its_snapshot_is_done() {
        let mut d = Dispatch::new(
            ExecutionPlan::one_executor(&["a", "b", "c"], ExecutorKind::SingleThreaded, 1),
            &[],
        );
        d.release(1);
        d.release(2);
        assert_eq!(drain(&mut d), vec![1], "one thread: one at a time");
        // `a` (rank 0) becomes ready while `b` runs: it is not in the snapshot {b, c}.
        d.release(0);
        d.finish(1);
        assert_eq!(
            drain(&mut d),
            vec![2],
            "round-robin: c, from the old snapshot, first"
        );
        d.finish(2);
        assert_eq!(drain(&mut d), vec![0], "then a poll finds a");
    }

    #[test]
    fn callback_groups_limit_a_multi_threaded_executor() {
        let mut plan =
            ExecutionPlan::one_executor(&["a", "b", "c"], ExecutorKind::MultiThreaded, 3);
        // a and b in one mutually exclusive group.
        plan.node_group = vec![0, 0, 1];
        plan.groups = vec![GroupKind::MutuallyExclusive, GroupKind::MutuallyExclusive];
        let mut d = Dispatch::new(plan.clone(), &[]);
        (0..3).for_each(|i| d.release(i));
        assert_eq!(drain(&mut d), vec![0, 2], "b waits for a, its group");
        d.finish(0);
        assert_eq!(drain(&mut d), vec![1]);
        // The same group reentrant: all three at once.
        plan.groups[0] = GroupKind::Reentrant;
        let mut d = Dispatch::new(plan.clone(), &[]);
        (0..3).for_each(|i| d.release(i));
        assert_eq!(drain(&mut d), vec![0, 1, 2]);
        // Two threads: the third waits for a thread whatever its group.
        plan.executors[0].threads = 2;
        let mut d = Dispatch::new(plan, &[]);
        (0..3).for_each(|i| d.release(i));
        assert_eq!(drain(&mut d), vec![0, 1]);
        d.finish(1);
        assert_eq!(drain(&mut d), vec![2]);
    }

    #[test]
    fn a_node_never_overlaps_itself() {
        let mut plan = ExecutionPlan::one_executor(&["a"], ExecutorKind::MultiThreaded, 2);
        plan.groups = vec![GroupKind::Reentrant];
        let mut d = Dispatch::new(plan, &[]);
        d.release(0);
        assert_eq!(drain(&mut d), vec![0]);
        d.release(0);
        assert_eq!(drain(&mut d), Vec::<usize>::new(), "still running");
        d.finish(0);
        assert_eq!(drain(&mut d), vec![0]);
    }

    /// [`Dispatch::pick`] as the rule reads: every executor with a ready node polls, then
    /// the lowest-ranked startable node of any snapshot starts.
    fn pick_polling_all(d: &mut Dispatch) -> Option<usize> {
        for e in 0..d.ready_in.len() {
            if d.ready_in[e] > 0 {
                d.poll_if_idle(e);
            }
        }
        d.snapshot
            .iter()
            .map(|&p| d.order[p])
            .find(|&i| d.startable(i))
    }

    /// A plan of `n` nodes over executors of every kind and groups that span executors.
    fn mixed_plan(n: usize, next: &mut impl FnMut(u64) -> u64) -> ExecutionPlan {
        let kinds = [
            ExecutorKind::PerNode,
            ExecutorKind::SingleThreaded,
            ExecutorKind::MultiThreaded,
        ];
        let executors: Vec<PlanExecutor> = (0..4)
            .map(|e| PlanExecutor {
                name: format!("e{e}"),
                kind: kinds[e % 3],
                threads: 1 + next(3) as usize,
            })
            .collect();
        ExecutionPlan {
            executors,
            groups: vec![
                GroupKind::MutuallyExclusive,
                GroupKind::Reentrant,
                GroupKind::MutuallyExclusive,
            ],
            node_executor: (0..n).map(|_| next(4) as usize).collect(),
            node_group: (0..n).map(|_| next(3) as usize).collect(),
        }
    }

    #[test]
    fn polling_only_stale_executors_picks_as_polling_every_executor() {
        // A fixed sequence of operations, the same on every machine.
        let mut rng = rand_pcg::Pcg64::new(0x9e37_79b9_7f4a_7c15, 0);
        let mut next = move |n: u64| rand_pcg::rand_core::Rng::next_u64(&mut rng) % n;
        let n = 24;
        let ranks: Vec<u32> = (0..n).map(|_| next(8) as u32).collect();
        let plan = mixed_plan(n, &mut next);
        let (mut fast, mut rule) = (
            Dispatch::new(plan.clone(), &ranks),
            Dispatch::new(plan, &ranks),
        );
        let (mut picks, mut waits) = (0, 0);
        for round in 0..20_000 {
            if round % 500 == 499 {
                // A new plan mid-run (the lab's executor key): every executor polls afresh.
                let plan = mixed_plan(n, &mut next);
                fast.replan(plan.clone());
                rule.replan(plan);
            }
            match next(10) {
                0..=3 => {
                    let i = next(n as u64) as usize;
                    fast.release(i);
                    rule.release(i);
                }
                4..=6 => {
                    let got = fast.pick();
                    assert_eq!(got, pick_polling_all(&mut rule), "round {round}");
                    assert_eq!(fast.snapshot, rule.snapshot, "round {round}");
                    if let Some(i) = got {
                        fast.start(i);
                        rule.start(i);
                        picks += 1;
                    } else {
                        waits += 1;
                    }
                }
                7 | 8 => {
                    // A running node finishes (one that is not: nothing happens).
                    let running: Vec<usize> = (0..n).filter(|&i| fast.is_running(i)).collect();
                    let i = match running.len() {
                        0 => next(n as u64) as usize,
                        k => running[next(k as u64) as usize],
                    };
                    fast.finish(i);
                    rule.finish(i);
                }
                _ => {}
            }
        }
        assert!(picks > 3000 && waits > 1000, "{picks} picks, {waits} waits");
    }
}
