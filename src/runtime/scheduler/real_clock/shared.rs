//! The real clock's shared executors: the threads of single- and multi-threaded executors
//! ([`ratelab_core::executor`]), which take their nodes' ticks by the same rules the virtual clock
//! models (timers released when due, snapshots polled when done, callback groups), with
//! the monotonic clock's instants. One lock guards the executors' bookkeeping; a tick runs
//! outside it, and its end wakes the executors' waiting threads.

use super::{
    catch_quietly, next_deadline, node_timing, panic_message, real_tick, thread_cpu_time,
    LatencyStats, NodeExecStats, RealOptions, StopFlag,
};
use crate::graph::nodes::GraphNode;
use ratelab_core::clock::{Clock, MonotonicClock};
use ratelab_core::executor::{Dispatch, ExecutionPlan, ExecutorKind};
use ratelab_core::metrics::NodeTiming;
use ratelab_core::node::Flow;
use ratelab_core::time::Nanos;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, Condvar, Mutex, MutexGuard};
use std::thread::JoinHandle;
use std::time::Duration;

/// What every shared executor thread needs of the run.
pub(super) struct Context {
    pub clock: MonotonicClock,
    pub duration: Nanos,
    pub stop: StopFlag,
    pub stop_at: Arc<AtomicU64>,
    pub opts: RealOptions,
}

struct State {
    dispatch: Dispatch,
    next_call: Vec<Nanos>,
    /// Released to the dispatcher and not started since.
    released: Vec<bool>,
    /// The nodes of shared executors, `None` while a thread runs its tick (and for nodes on
    /// threads of their own).
    slots: Vec<Option<GraphNode>>,
    stats: Vec<NodeExecStats>,
    lateness: Vec<LatencyStats>,
    ticks: Vec<u64>,
    /// Thread CPU time spent in each node's ticks.
    cpu: Vec<Nanos>,
    first: Vec<Nanos>,
    sched: String,
    sched_error: Option<String>,
    failed: Option<(String, String)>,
}

struct Inner {
    state: Mutex<State>,
    wake: Condvar,
    cx: Context,
    plan: ExecutionPlan,
}

impl Inner {
    fn lock(&self) -> MutexGuard<'_, State> {
        self.state.lock().unwrap_or_else(|e| e.into_inner())
    }
}

/// The running shared executors.
pub(super) struct SharedExecutors {
    inner: Arc<Inner>,
    threads: Vec<JoinHandle<()>>,
    names: Vec<String>,
}

/// A node handed back at the end, with its timing and figures.
pub(super) type Finished = (GraphNode, NodeTiming, NodeExecStats);

/// What the shared executors hand back: by node index, the nodes they ran with their timing
/// and figures (`None` for nodes on threads of their own), and the node that failed.
pub(super) struct SharedEnd {
    pub nodes: Vec<Option<Finished>>,
    pub failed: Option<(String, String)>,
}

impl SharedExecutors {
    /// Start the threads of `plan`'s shared executors over `nodes` (by node index, `Some`
    /// for the nodes they hold). A thread the machine will not start stops the run: the
    /// threads started end, and [`SharedExecutors::join`] gives it as the failure of the
    /// executor's first node.
    pub(super) fn start(
        nodes: Vec<Option<GraphNode>>,
        plan: &ExecutionPlan,
        cx: Context,
    ) -> SharedExecutors {
        let n = nodes.len();
        let names: Vec<String> = nodes
            .iter()
            .map(|s| s.as_ref().map(|n| n.name().to_string()).unwrap_or_default())
            .collect();
        let ranks: Vec<u32> = nodes
            .iter()
            .enumerate()
            .map(|(i, s)| s.as_ref().map_or(i as u32, |n| n.priority()))
            .collect();
        let first: Vec<Nanos> = (0..n)
            .map(|i| cx.opts.phase_offsets.get(i).copied().unwrap_or(Nanos::ZERO))
            .collect();
        let inner = Arc::new(Inner {
            state: Mutex::new(State {
                dispatch: Dispatch::new(plan.clone(), &ranks),
                next_call: first.clone(),
                released: vec![false; n],
                slots: nodes,
                stats: vec![NodeExecStats::default(); n],
                lateness: vec![LatencyStats::default(); n],
                ticks: vec![0; n],
                cpu: vec![Nanos::ZERO; n],
                first,
                sched: String::new(),
                sched_error: None,
                failed: None,
            }),
            wake: Condvar::new(),
            cx,
            plan: plan.clone(),
        });
        let mut threads = Vec::new();
        'start: for (e, x) in plan.executors.iter().enumerate() {
            if x.kind == ExecutorKind::PerNode {
                continue;
            }
            for k in 0..x.threads {
                let worker_inner = inner.clone();
                let name = format!("{}-{k}", x.name);
                match std::thread::Builder::new()
                    .name(name.clone())
                    .spawn(move || worker(&worker_inner, e))
                {
                    Ok(t) => threads.push(t),
                    Err(why) => {
                        // The machine starts no more threads: the run stops (the threads
                        // started see it and end), as the failure of the executor's first
                        // node.
                        inner.cx.stop.stop();
                        let node = (0..plan.node_executor.len())
                            .find(|&i| plan.node_executor[i] == e)
                            .and_then(|i| names.get(i).cloned())
                            .unwrap_or_else(|| x.name.clone());
                        let line =
                            super::not_started(&format!("its executor's thread '{name}'"), &why);
                        inner.lock().failed.get_or_insert((node, line));
                        inner.wake.notify_all();
                        break 'start;
                    }
                }
            }
        }
        SharedExecutors {
            inner,
            threads,
            names,
        }
    }

    /// Wait for the threads to end; hand back the nodes with their timing.
    pub(super) fn join(self) -> SharedEnd {
        for t in self.threads {
            let _ = t.join();
        }
        let mut guard = self.inner.lock();
        let st = &mut *guard;
        let cx = &self.inner.cx;
        let end = cx.clock.now().min(cx.duration);
        let mut nodes = Vec::new();
        for i in 0..st.slots.len() {
            let Some(node) = st.slots[i].take() else {
                nodes.push(None);
                continue;
            };
            let lateness = &st.lateness[i];
            let ticks = st.ticks[i];
            let elapsed = end.saturating_sub(st.first[i]);
            let stats = std::mem::take(&mut st.stats[i]);
            let timing = NodeTiming {
                sched: st.sched.clone(),
                sched_error: st.sched_error.clone(),
                ..node_timing(
                    self.names[i].clone(),
                    ticks,
                    stats.skipped_ticks,
                    lateness,
                    st.cpu[i],
                    elapsed,
                )
            };
            nodes.push(Some((node, timing, stats)));
        }
        SharedEnd {
            nodes,
            failed: st.failed.take(),
        }
    }
}

/// One thread of executor `e`: take the next tick by the rules, run it, repeat.
fn worker(inner: &Inner, e: usize) {
    let cx = &inner.cx;
    let sched_error = cx
        .opts
        .rt_priority
        .and_then(|p| ratelab_core::realtime::set_current_thread_fifo(p).err())
        .map(|e| e.to_string());
    {
        let mut st = inner.lock();
        if st.sched.is_empty() {
            st.sched = ratelab_core::realtime::current_thread_sched().to_string();
            st.sched_error = sched_error;
        }
    }
    let members: Vec<usize> = (0..inner.plan.node_executor.len())
        .filter(|&i| inner.plan.node_executor[i] == e)
        .collect();
    let mut st = inner.lock();
    loop {
        if cx.stop.is_stopped() {
            break;
        }
        if cx
            .opts
            .pause
            .as_ref()
            .is_some_and(|p| p.load(Ordering::SeqCst))
        {
            drop(st);
            std::thread::sleep(Duration::from_millis(5));
            st = inner.lock();
            // Back on the grid after a pause: the ticks missed are not late ticks.
            let now = cx.clock.now();
            for &i in &members {
                if let Some(node) = &st.slots[i] {
                    if !st.released[i] && st.next_call[i] < now {
                        st.next_call[i] =
                            next_deadline(st.next_call[i], now, node.rate().period()).0;
                    }
                }
            }
            continue;
        }
        let now = cx.clock.now();
        if now >= cx.duration {
            break;
        }
        for &i in &members {
            if !st.released[i] && st.next_call[i] <= now {
                st.released[i] = true;
                st.dispatch.release(i);
            }
        }
        let Some(i) = st.dispatch.pick_for(e) else {
            // Nothing to start: sleep until this executor's next timer, a tick's end
            // elsewhere (notified), the run's end, or at most 20 ms (to see a stop).
            let next = members
                .iter()
                .filter(|&&i| !st.released[i])
                .map(|&i| st.next_call[i])
                .min()
                .unwrap_or(cx.duration)
                .min(cx.duration);
            let wait = next
                .saturating_sub(now)
                .to_duration()
                .min(Duration::from_millis(20));
            st = inner
                .wake
                .wait_timeout(st, wait)
                .unwrap_or_else(|e| e.into_inner())
                .0;
            continue;
        };
        st.dispatch.start(i);
        st.released[i] = false;
        let Some(mut node) = st.slots[i].take() else {
            // A node this executor holds is always in its slot when it can start.
            st.dispatch.finish(i);
            continue;
        };
        let release = st.next_call[i];
        let (next, skipped) = next_deadline(release, now, node.rate().period());
        st.next_call[i] = next;
        st.ticks[i] += 1;
        st.stats[i].skipped_ticks += skipped;
        let late = now.saturating_sub(release);
        st.lateness[i].record(late);
        drop(st);
        let cpu0 = thread_cpu_time();
        let result = catch_quietly(|| real_tick(&mut node, now, &cx.clock, &cx.stop));
        let cpu = thread_cpu_time().saturating_sub(cpu0);
        if let Some(hook) = &cx.opts.on_tick {
            hook(&super::TickReport {
                node: i,
                name: node.name(),
                now,
                lateness: late,
                took: result
                    .as_ref()
                    .map_or(Nanos::ZERO, |(_, done)| done.saturating_sub(now)),
            });
        }
        st = inner.lock();
        let name = node.name().to_string();
        st.slots[i] = Some(node);
        st.dispatch.finish(i);
        st.cpu[i] = st.cpu[i].saturating_add(cpu);
        match result {
            Ok((flow, done)) => {
                if cx.opts.track {
                    st.stats[i].record(release, done, done.saturating_sub(now));
                }
                if flow == Flow::Stop {
                    cx.stop_at.fetch_min(now.0, Ordering::SeqCst);
                    cx.stop.stop();
                }
            }
            Err(p) => {
                st.failed.get_or_insert((name, panic_message(&*p)));
                cx.stop.stop();
            }
        }
        inner.wake.notify_all();
    }
    drop(st);
    inner.wake.notify_all();
}
