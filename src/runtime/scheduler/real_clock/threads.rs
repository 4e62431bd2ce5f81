//! How many threads a real-clock run starts, and the bound on them
//! ([`MAX_REAL_CLOCK_THREADS`]): counted from the execution plan before any starts, and the
//! one line that refuses a plan past it or a thread the machine would not start.

use super::{EndReason, RealRun, RunEnd};
use crate::graph::nodes::GraphNode;
use ratelab_core::executor::{ExecutionPlan, ExecutorKind};
use ratelab_core::limits::MAX_REAL_CLOCK_THREADS;
use ratelab_core::metrics::NodeTiming;
use ratelab_core::time::Nanos;

/// The threads [`run_real`](super::run_real) starts for `plan`: one per node on a per-node executor, and
/// each shared executor's threads (which start whether or not their nodes are due).
pub fn plan_threads(plan: &ExecutionPlan) -> usize {
    let per_node = plan
        .node_executor
        .iter()
        .filter(|&&e| {
            plan.executors
                .get(e)
                .is_some_and(|x| x.kind == ExecutorKind::PerNode)
        })
        .count();
    let shared: usize = plan
        .executors
        .iter()
        .filter(|x| x.kind != ExecutorKind::PerNode)
        .map(|x| x.threads)
        .fold(0, usize::saturating_add);
    per_node.saturating_add(shared)
}

/// Check that a real-clock run of `plan` starts at most
/// [`ratelab_core::limits::MAX_REAL_CLOCK_THREADS`] threads ([`plan_threads`]).
///
/// # Errors
/// One line: the threads it would start, the bound, and the ways to fewer threads (the
/// virtual clock; executors that share threads).
pub fn check_real_clock_threads(plan: &ExecutionPlan) -> Result<(), String> {
    let threads = plan_threads(plan);
    if threads <= MAX_REAL_CLOCK_THREADS {
        return Ok(());
    }
    Err(ratelab_core::limits::refusal(
        format_args!(
            "the real clock would start {threads} threads (one per node on a thread of its own, and each shared executor's), at most {MAX_REAL_CLOCK_THREADS}: run it under the virtual clock (--clock virtual), or share threads among its nodes (--executor single_threaded or multi_threaded:N, or [executors] tables in the graph file)"
        ),
        "MAX_REAL_CLOCK_THREADS",
    ))
}

/// Why `what` (a node's own thread, an executor's thread) did not start: the machine's
/// refusal `e`, and what to do, in one line.
pub(super) fn not_started(what: &str, e: &std::io::Error) -> String {
    format!(
        "{what} could not be started ({e}): the machine gives no more threads; run it under the virtual clock (--clock virtual), or share threads among the graph's nodes (--executor single_threaded) (the real clock starts at most {MAX_REAL_CLOCK_THREADS}: ratelab::limits::MAX_REAL_CLOCK_THREADS)"
    )
}

/// A real-clock run that started no thread (its plan needs more than
/// [`MAX_REAL_CLOCK_THREADS`]): it ends at `at` as the failure of the first node past the
/// bound, with `line` ([`check_real_clock_threads`]'s), every node back untouched.
pub(super) fn none_started(
    nodes: Vec<GraphNode>,
    names: &[String],
    own_thread: &[bool],
    line: String,
    at: Nanos,
) -> RealRun {
    let beyond = own_thread
        .iter()
        .enumerate()
        .filter(|(_, own)| **own)
        .map(|(i, _)| i)
        .nth(MAX_REAL_CLOCK_THREADS)
        .unwrap_or(names.len().saturating_sub(1));
    let timing = names
        .iter()
        .map(|n| NodeTiming {
            node: n.clone(),
            ..NodeTiming::default()
        })
        .collect();
    RealRun {
        end: RunEnd {
            at,
            reason: EndReason::NodeFailed {
                node: names.get(beyond).cloned().unwrap_or_default(),
                message: line,
            },
        },
        timing,
        nodes,
        exec: None,
    }
}
