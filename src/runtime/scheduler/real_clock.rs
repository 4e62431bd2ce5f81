//! The real clock ([`run_real`]): by default one OS thread per node, each ticking against
//! the monotonic clock at absolute deadlines (ch2.8, `run_real`); a single- or
//! multi-threaded executor's nodes share its threads ([`shared`]); the threads a plan
//! starts are counted and bounded first ([`threads`]).

use super::*;

mod shared;
mod threads;
pub use threads::{check_real_clock_threads, plan_threads};
use threads::{none_started, not_started};

/// One tick under the real clock, as a [`TickHook`] is told of it.
#[derive(Clone, Copy, Debug)]
pub struct TickReport<'a> {
    /// The node's index (its tie-break rank).
    pub node: usize,
    /// The node's name.
    pub name: &'a str,
    /// Run time the tick started.
    pub now: Nanos,
    /// Its lateness: actual start − scheduled.
    pub lateness: Nanos,
    /// Wall time the tick took, start to end (its compute time burned included; zero for
    /// a tick that panicked).
    pub took: Nanos,
}

/// Called on the node's thread after each tick under the real clock ([`TickReport`]).
pub type TickHook = Arc<dyn Fn(&TickReport<'_>) + Send + Sync>;

/// Options of the real-clock executor.
#[derive(Clone)]
pub struct RealOptions {
    /// Spin (rather than sleep) this long before each deadline.
    pub spin_margin: Nanos,
    /// First deadline of node `i` (missing = 0): phase offsets between nodes.
    pub phase_offsets: Vec<Nanos>,
    /// Told about every tick (e.g. a recorder logging lateness).
    pub on_tick: Option<TickHook>,
    /// While set, no node ticks (the lab's pause); deadlines missed meanwhile are skipped.
    pub pause: Option<Arc<AtomicBool>>,
    /// Run every node thread under `SCHED_FIFO` at this priority (1..=99), if the kernel
    /// allows; a refusal is reported in [`NodeTiming::sched_error`] and the node runs on
    /// under its default policy. See [`ratelab_core::realtime`].
    ///
    /// One priority for all nodes, on purpose: ordering them by tie-break priority (sensor
    /// highest) was measured (BENCHMARKS.md) and moved all waiting for a core onto the
    /// actuator, whose spinning peers never yield to a lower priority.
    pub rt_priority: Option<u8>,
    /// The instant the run's time is zero (`None`: when [`run_real`] starts). Processes of
    /// one graph share it, so their stamps share one clock (`ratelab::distributed`).
    pub start: Option<std::time::Instant>,
    /// The run time the run starts at: 0, or the instant another clock reached when the run
    /// goes on from there (`ratelab::runcore::RunCore::run_real`). The executors' figures
    /// span from here to the end.
    pub from: Nanos,
    /// The executors ([`ratelab_core::executor`]); `None`: one thread per node.
    pub plan: Option<ExecutionPlan>,
    /// Measure response times, skipped ticks and busy time ([`RealRun::exec`]).
    pub track: bool,
}

impl Default for RealOptions {
    fn default() -> Self {
        Self {
            spin_margin: ratelab_core::rate::DEFAULT_SPIN_MARGIN,
            phase_offsets: Vec::new(),
            on_tick: None,
            pause: None,
            rt_priority: None,
            start: None,
            from: Nanos::ZERO,
            plan: None,
            track: false,
        }
    }
}

/// What [`run_real`] hands back.
pub struct RealRun {
    /// How it ended.
    pub end: RunEnd,
    /// Per-node tick timing, one per node run, in their order (a node whose thread died,
    /// panicking, has an empty one).
    pub timing: Vec<NodeTiming>,
    /// The nodes, returned for reuse or inspection (a node whose thread died is not).
    pub nodes: Vec<GraphNode>,
    /// What the executors measured, when [`RealOptions::track`] (and no node thread died).
    pub exec: Option<ExecFigures>,
}

/// This thread's CPU time (Linux `CLOCK_THREAD_CPUTIME_ID`).
fn thread_cpu_time() -> Nanos {
    let mut ts = libc::timespec {
        tv_sec: 0,
        tv_nsec: 0,
    };
    // SAFETY: `ts` is a valid, writable timespec; the clock id is a constant.
    let rc = unsafe { libc::clock_gettime(libc::CLOCK_THREAD_CPUTIME_ID, &mut ts) };
    if rc != 0 {
        return Nanos::ZERO;
    }
    Nanos(ts.tv_sec as u64 * 1_000_000_000 + ts.tv_nsec as u64)
}

/// A node's figures at the end of a real-clock run: `ticks` ticked and `skipped` deadlines
/// skipped over `elapsed`, with their `lateness` and `cpu` of thread CPU time (the
/// scheduling policy left for the caller to fill in).
fn node_timing(
    node: String,
    ticks: u64,
    skipped: u64,
    lateness: &LatencyStats,
    cpu: Nanos,
    elapsed: Nanos,
) -> NodeTiming {
    let us = |n: Option<Nanos>| n.map_or(0.0, Nanos::as_micros_f64);
    NodeTiming {
        node,
        ticks,
        skipped,
        lateness_p50_us: us(lateness.quantile(0.5)),
        lateness_p99_us: us(lateness.quantile(0.99)),
        lateness_max_us: us(lateness.max()),
        cpu_ms: cpu.as_millis_f64(),
        measured_hz: if elapsed.0 > 0 {
            ticks as f64 / elapsed.as_secs_f64()
        } else {
            0.0
        },
        sched: String::new(),
        sched_error: None,
    }
}

/// Burn `cpu` of this thread's CPU time in a busy loop (`CLOCK_THREAD_CPUTIME_ID`): a tick's
/// declared compute time under the real clock. On a loaded machine it takes longer than
/// `cpu` of wall time, as real computation does. Stops early on `stop`.
fn burn(cpu: Nanos, stop: &StopFlag) {
    let wall = std::time::Instant::now();
    let t0 = thread_cpu_time();
    let mut x = 0u64;
    loop {
        for _ in 0..512 {
            x = std::hint::black_box(x.wrapping_mul(6_364_136_223_846_793_005).wrapping_add(1));
        }
        // Without a thread CPU clock (it read 0), the wall clock measures.
        let spent = if t0.0 == 0 {
            Nanos(wall.elapsed().as_nanos() as u64)
        } else {
            thread_cpu_time().saturating_sub(t0)
        };
        if spent >= cpu || stop.is_stopped() {
            return;
        }
    }
}

/// One tick of `node` at `now` under the real clock, with its compute time: its outputs are
/// held while it burns that much CPU, then published at the clock's time. Returns the flow
/// and the time its outputs went out.
fn real_tick(
    node: &mut GraphNode,
    now: Nanos,
    clock: &MonotonicClock,
    stop: &StopFlag,
) -> (Flow, Nanos) {
    let compute = node.compute_time();
    if compute.0 == 0 {
        return (node.tick(now), clock.now());
    }
    node.hold_outputs();
    let flow = node.tick(now);
    burn(compute, stop);
    let done = clock.now();
    node.publish_held(done);
    (flow, done)
}

/// What a node's own thread gives back when it ends: the node, its timing, its executor
/// figures, and its panic's message if it panicked.
type OwnThreadEnd = (GraphNode, NodeTiming, NodeExecStats, Option<String>);

/// A node [`spawn_own_thread`] could not start: the node back (when it could be taken
/// back), and the machine's refusal.
type NotStarted = (Option<Box<GraphNode>>, std::io::Error);

/// Start node `i` on a thread of its own (a per-node executor): it ticks on its grid from
/// its phase offset until the run's end or `stop` (a pause holds it; a tick that says stop
/// records when in `stop_at` and stops the run; a panic stops the run). The thread keeps
/// Rust's default stack (2 MiB, or `RUST_MIN_STACK`): a Python callback or a brain may
/// need it.
///
/// # Errors
/// The node back with the machine's refusal, when the thread cannot be started (no more
/// threads, no memory for its stack).
fn spawn_own_thread(
    i: usize,
    node: GraphNode,
    opts: &RealOptions,
    (clock, waiter, duration): (MonotonicClock, DeadlineWaiter, Nanos),
    (stop, stop_at): (&StopFlag, &Arc<AtomicU64>),
) -> Result<std::thread::JoinHandle<OwnThreadEnd>, NotStarted> {
    let track = opts.track;
    let stop = stop.clone();
    let stop_at = stop_at.clone();
    let first = opts.phase_offsets.get(i).copied().unwrap_or(Nanos::ZERO);
    let name = node.name().to_string();
    let on_tick = opts.on_tick.clone();
    let pause = opts.pause.clone();
    let rt_priority = opts.rt_priority;
    // Handed over through a cell, so that a thread that cannot start gives the node back.
    let cell: Arc<std::sync::Mutex<Option<GraphNode>>> =
        Arc::new(std::sync::Mutex::new(Some(node)));
    let handed = cell.clone();
    let spawned = std::thread::Builder::new()
        .name(name.clone())
        .spawn(move || {
            let mut node = handed
                .lock()
                .unwrap_or_else(|e| e.into_inner())
                .take()
                .expect("a node is handed to its thread once");
            drop(handed);
            let sched_error = rt_priority
                .and_then(|p| ratelab_core::realtime::set_current_thread_fifo(p).err())
                .map(|e| e.to_string());
            let sched = ratelab_core::realtime::current_thread_sched().to_string();
            let cpu0 = thread_cpu_time();
            let mut lateness = LatencyStats::default();
            let mut exec = NodeExecStats::default();
            let (mut ticks, mut skipped) = (0u64, 0u64);
            let mut deadline = first;
            let result = catch_quietly(|| loop {
                // Wake for the deadline, the run's end or a stop, whichever is
                // first: a slow node must not sleep past either.
                waiter.wait_until_or(clock.instant_at(deadline.min(duration)), &|| {
                    stop.is_stopped()
                });
                let mut was_paused = false;
                while pause.as_ref().is_some_and(|p| p.load(Ordering::SeqCst)) && !stop.is_stopped()
                {
                    was_paused = true;
                    std::thread::sleep(std::time::Duration::from_millis(5));
                }
                let now = clock.now();
                if now >= duration || stop.is_stopped() {
                    break;
                }
                if was_paused {
                    // Back on the grid after a pause: the ticks missed are not late ticks.
                    let (next, _) = next_deadline(deadline, now, node.rate().period());
                    deadline = next;
                    continue;
                }
                let late = now.saturating_sub(deadline);
                lateness.record(late);
                ticks += 1;
                let (flow, done) = real_tick(&mut node, now, &clock, &stop);
                if track {
                    exec.record(deadline, done, done.saturating_sub(now));
                }
                if let Some(hook) = &on_tick {
                    hook(&TickReport {
                        node: i,
                        name: &name,
                        now,
                        lateness: late,
                        took: done.saturating_sub(now),
                    });
                }
                if flow == Flow::Stop {
                    stop_at.fetch_min(now.0, Ordering::SeqCst);
                    stop.stop();
                    break;
                }
                let (next, missed) = next_deadline(deadline, clock.now(), node.rate().period());
                deadline = next;
                skipped += missed;
            });
            if result.is_err() {
                stop.stop();
            }
            exec.skipped_ticks = skipped;
            let elapsed = clock.now().min(duration).saturating_sub(first);
            let cpu = thread_cpu_time().saturating_sub(cpu0);
            let timing = NodeTiming {
                sched,
                sched_error,
                ..node_timing(name, ticks, skipped, &lateness, cpu, elapsed)
            };
            (node, timing, exec, result.err().map(|p| panic_message(&*p)))
        });
    spawned.map_err(|e| {
        let node = cell.lock().unwrap_or_else(|p| p.into_inner()).take();
        (node.map(Box::new), e)
    })
}

/// Run `nodes` against a monotonic clock until `duration`, a node's [`Flow::Stop`] (which
/// stops every thread), or `stop`, on the executors of [`RealOptions::plan`]: by default one
/// OS thread per node, sleeping to absolute deadlines; a single- or multi-threaded executor's
/// nodes share its threads by [`ratelab_core::executor`]'s rules. Each tick's lateness (actual −
/// scheduled) is recorded for jitter statistics. A panicking node stops the graph and is
/// reported in [`EndReason::NodeFailed`].
///
/// Never more than [`ratelab_core::limits::MAX_REAL_CLOCK_THREADS`] threads ([`plan_threads`]): a
/// plan that needs more starts none and ends at once as the failure of the first node past
/// the bound ([`check_real_clock_threads`]'s line; a run's settings refuse such a graph
/// before it is built, `ratelab::config::RunConfig::validate`). A thread the machine will
/// not start (no more threads, no memory for its stack) stops the threads started, which
/// are joined, and ends the run as that node's failure: every node that did not run comes
/// back untouched.
pub fn run_real(
    nodes: Vec<GraphNode>,
    duration: Nanos,
    stop: &StopFlag,
    opts: &RealOptions,
) -> RealRun {
    let clock = opts
        .start
        .map_or_else(MonotonicClock::start, MonotonicClock::starting_at);
    let waiter = DeadlineWaiter::new(opts.spin_margin);
    let stop_at = Arc::new(AtomicU64::new(u64::MAX));
    let names: Vec<String> = nodes.iter().map(|n| n.name().to_string()).collect();
    let plan = opts.plan.clone().unwrap_or_else(|| {
        ExecutionPlan::per_node(&names.iter().map(String::as_str).collect::<Vec<_>>())
    });
    let track = opts.track;
    let own_thread: Vec<bool> = (0..nodes.len())
        .map(|i| plan.executors[plan.node_executor[i]].kind == ExecutorKind::PerNode)
        .collect();
    // More threads than the bound (a graph the run's settings did not check for the real
    // clock: the lab's switch of clocks): none starts, every node back.
    if let Err(line) = check_real_clock_threads(&plan) {
        return none_started(nodes, &names, &own_thread, line, clock.now().min(duration));
    }
    let mut slots: Vec<Option<shared::Finished>> = (0..names.len()).map(|_| None).collect();
    // A node that did not run comes back as it was, with no ticks.
    let unrun = |i: usize, node: GraphNode| -> shared::Finished {
        let timing = NodeTiming {
            node: names[i].clone(),
            ..NodeTiming::default()
        };
        (node, timing, NodeExecStats::default())
    };
    let mut shared_nodes: Vec<Option<GraphNode>> = Vec::new();
    let mut handles = Vec::new();
    // The first node whose thread the machine would not start, and why: the run stops
    // there (the threads started are stopped and joined), and ends as that node's failure.
    let mut refused: Option<(usize, String)> = None;
    for (i, node) in nodes.into_iter().enumerate() {
        if refused.is_some() {
            slots[i] = Some(unrun(i, node));
            shared_nodes.push(None);
            continue;
        }
        if !own_thread[i] {
            shared_nodes.push(Some(node));
            continue;
        }
        shared_nodes.push(None);
        match spawn_own_thread(i, node, opts, (clock, waiter, duration), (stop, &stop_at)) {
            Ok(handle) => handles.push((i, handle)),
            Err((node, e)) => {
                stop.stop();
                if let Some(node) = node {
                    slots[i] = Some(unrun(i, *node));
                }
                refused = Some((i, not_started("its thread", &e)));
            }
        }
    }
    // Only when an executor shares threads (its bookkeeping holds a histogram per node),
    // and every node's own thread started.
    let shared = if refused.is_none() && own_thread.contains(&false) {
        Some(shared::SharedExecutors::start(
            shared_nodes,
            &plan,
            shared::Context {
                clock,
                duration,
                stop: stop.clone(),
                stop_at: stop_at.clone(),
                opts: opts.clone(),
            },
        ))
    } else {
        for (i, node) in shared_nodes.into_iter().enumerate() {
            if let Some(node) = node {
                slots[i] = Some(unrun(i, node));
            }
        }
        None
    };
    let mut failed = refused.map(|(i, message)| EndReason::NodeFailed {
        node: names[i].clone(),
        message,
    });
    for (i, h) in handles {
        match h.join() {
            Ok((node, t, exec, panic)) => {
                if let (Some(message), None) = (panic, &failed) {
                    failed = Some(EndReason::NodeFailed {
                        node: t.node.clone(),
                        message,
                    });
                }
                slots[i] = Some((node, t, exec));
            }
            Err(p) => {
                failed.get_or_insert(EndReason::NodeFailed {
                    node: names[i].clone(),
                    message: panic_message(&*p),
                });
            }
        }
    }
    if let Some(shared) = shared {
        let shared_end = shared.join();
        if let (Some((node, message)), None) = (shared_end.failed, &failed) {
            failed = Some(EndReason::NodeFailed { node, message });
        }
        for (i, s) in shared_end.nodes.into_iter().enumerate() {
            if let Some(s) = s {
                slots[i] = Some(s);
            }
        }
    }
    let (nodes, timing, stats) = gather(slots, &names);
    let end = real_end(
        failed,
        stop_at.load(Ordering::SeqCst),
        stop,
        clock.now().min(duration),
        duration,
    );
    let span = end.at.saturating_sub(opts.from);
    let exec = (track && stats.len() == names.len()).then(|| figures(&plan, &stats, span));
    RealRun {
        end,
        timing,
        nodes,
        exec,
    }
}

/// Every node's slot after a real-clock run, in the graph's order: the nodes that came
/// back, every node's timing and the figures of those that came back.
fn gather(
    slots: Vec<Option<shared::Finished>>,
    names: &[String],
) -> (Vec<GraphNode>, Vec<NodeTiming>, Vec<NodeExecStats>) {
    let mut nodes = Vec::new();
    let mut timing = Vec::new();
    let mut stats = Vec::new();
    for (i, slot) in slots.into_iter().enumerate() {
        match slot {
            Some((node, t, exec)) => {
                nodes.push(node);
                timing.push(t);
                stats.push(exec);
            }
            // Its thread died (the node panicked): no timing, but its place kept, so that
            // every later node's timing stays its own.
            None => timing.push(NodeTiming {
                node: names[i].clone(),
                ..NodeTiming::default()
            }),
        }
    }
    (nodes, timing, stats)
}

/// How a real-clock run ended: a node's failure first, then a node's stop at `stopped_at`
/// (`u64::MAX`: none), then `stop` (an interruption) at `now`, else its `duration`.
fn real_end(
    failed: Option<EndReason>,
    stopped_at: u64,
    stop: &StopFlag,
    now: Nanos,
    duration: Nanos,
) -> RunEnd {
    if let Some(reason) = failed {
        RunEnd { at: now, reason }
    } else if stopped_at != u64::MAX {
        RunEnd {
            at: Nanos(stopped_at),
            reason: EndReason::NodeStopped,
        }
    } else if stop.is_stopped() {
        RunEnd {
            at: now,
            reason: EndReason::Interrupted,
        }
    } else {
        RunEnd {
            at: duration,
            reason: EndReason::Duration,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::graph::kind::NodeOf;
    use crate::scheduler::probes::probes;
    use ratelab_core::ids::NodeId;
    use ratelab_core::limits::MAX_REAL_CLOCK_THREADS;
    use ratelab_core::ports::RustNode;
    use ratelab_core::rate::Rate;
    use std::sync::Mutex;

    #[test]
    fn real_clock_runs_every_node_and_reports_panics() {
        let log = Arc::new(Mutex::new(Vec::new()));
        let nodes = probes(&log, [100.0, 100.0, 100.0]);
        let run = run_real(
            nodes,
            Nanos::from_millis(100),
            &StopFlag::new(),
            &RealOptions::default(),
        );
        assert_eq!(run.end.reason, EndReason::Duration);
        assert_eq!(run.timing.len(), 3);
        assert!(run.timing.iter().all(|t| t.ticks >= 5), "{:?}", run.timing);

        /// Its tick panics.
        struct Boom;
        impl RustNode for Boom {
            type Input = ();
            type Output = ();
            fn tick(&mut self, _: Nanos, _: ()) {
                panic!("sensor cable unplugged")
            }
        }
        // The failed node first: the nodes after it keep their own timing.
        let rate = Rate::new(50.0).unwrap();
        let boom = GraphNode::alone("boom", NodeId(0), rate, |_| NodeOf::unbound(Boom));
        let mut nodes: Vec<GraphNode> = vec![boom];
        nodes.extend(probes(&log, [100.0, 100.0, 100.0]));
        let run = run_real(
            nodes,
            Nanos::SECOND,
            &StopFlag::new(),
            &RealOptions::default(),
        );
        assert_eq!(
            run.end.reason,
            EndReason::NodeFailed {
                node: "boom".into(),
                message: "sensor cable unplugged".into()
            }
        );
        let named: Vec<&str> = run.timing.iter().map(|t| t.node.as_str()).collect();
        assert_eq!(named, ["boom", "actuator", "sensor", "policy"]);
    }

    #[test]
    fn the_threads_a_plan_starts_are_counted_before_any_starts() {
        let names: Vec<String> = (0..10).map(|i| format!("n{i}")).collect();
        let names: Vec<&str> = names.iter().map(String::as_str).collect();
        assert_eq!(plan_threads(&ExecutionPlan::per_node(&names)), 10);
        let single = ExecutionPlan::one_executor(&names, ExecutorKind::SingleThreaded, 1);
        assert_eq!(plan_threads(&single), 1);
        let pool = ExecutionPlan::one_executor(&names, ExecutorKind::MultiThreaded, 4);
        assert_eq!(plan_threads(&pool), 4);
        assert_eq!(check_real_clock_threads(&pool), Ok(()));
        // One past the bound, one thread per node: refused in one line naming it.
        let many: Vec<String> = (0..=MAX_REAL_CLOCK_THREADS)
            .map(|i| format!("n{i}"))
            .collect();
        let many: Vec<&str> = many.iter().map(String::as_str).collect();
        let line = check_real_clock_threads(&ExecutionPlan::per_node(&many)).unwrap_err();
        assert_eq!(line.lines().count(), 1);
        assert!(
            line.starts_with("the real clock would start 1025 threads (one per node on a thread of its own, and each shared executor's), at most 1024: run it under the virtual clock (--clock virtual), or share threads among its nodes (--executor single_threaded"),
            "{line}"
        );
        assert!(
            line.ends_with("(ratelab::limits::MAX_REAL_CLOCK_THREADS)"),
            "{line}"
        );
        // The same nodes on one shared thread are well within it.
        let shared = ExecutionPlan::one_executor(&many, ExecutorKind::SingleThreaded, 1);
        assert_eq!(check_real_clock_threads(&shared), Ok(()));
    }

    #[test]
    fn a_real_clock_run_past_the_thread_bound_starts_none_and_gives_every_node_back() {
        let nodes: Vec<GraphNode> = (0..=MAX_REAL_CLOCK_THREADS)
            .map(|i| GraphNode::idle(&format!("n{i}"), NodeId(i), Rate::new(10.0).unwrap()))
            .collect();
        let stop = StopFlag::new();
        let run = run_real(nodes, Nanos::SECOND, &stop, &RealOptions::default());
        match &run.end.reason {
            EndReason::NodeFailed { node, message } => {
                assert_eq!(node, &format!("n{MAX_REAL_CLOCK_THREADS}"));
                assert!(message.contains("MAX_REAL_CLOCK_THREADS"), "{message}");
            }
            other => panic!("ended as {other:?}"),
        }
        assert!(run.end.at < Nanos::SECOND, "{:?}", run.end);
        assert_eq!(run.nodes.len(), MAX_REAL_CLOCK_THREADS + 1);
        assert_eq!(run.timing.len(), MAX_REAL_CLOCK_THREADS + 1);
        assert!(run.timing.iter().all(|t| t.ticks == 0));
        assert!(!stop.is_stopped(), "nothing started, nothing to stop");
    }

    #[test]
    fn a_thread_the_machine_refuses_reads_as_one_line() {
        let e = std::io::Error::from_raw_os_error(libc::EAGAIN);
        let line = not_started("its thread", &e);
        assert_eq!(line.lines().count(), 1);
        assert!(
            line.starts_with("its thread could not be started ("),
            "{line}"
        );
        assert!(line.contains("--clock virtual"), "{line}");
        assert!(
            line.ends_with("ratelab::limits::MAX_REAL_CLOCK_THREADS)"),
            "{line}"
        );
    }
}
