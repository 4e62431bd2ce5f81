//! Executors: two ways to run one graph.
//!
//! - [`VirtualScheduler`]: single-threaded discrete-event executor over a virtual clock
//!   (ch2.8, `run_virtual`). A min-heap of `(due, priority, index)`: pop the earliest,
//!   stop if it is due after the run's end, tick it, stop the world on [`Flow::Stop`],
//!   push it back at `due + period` (the period read *now*, so a rate change takes effect
//!   from the node's next tick). Time is integer nanoseconds, so ties are exact and broken
//!   by priority then index: same settings → the same interleaving → byte-identical runs.
//! - [`run_real`]: one OS thread per node, each ticking against a monotonic clock at
//!   absolute deadlines (ch2.8, `run_real`). Message interleaving then depends on the OS
//!   scheduler, so two runs with the same seed are **not** reproducible: drop counts and
//!   latencies vary by a handful. That is the nature of concurrency, not a bug; use the
//!   virtual clock to compare runs.

use crate::clock::{Clock, MonotonicClock};
use crate::metrics::{LatencyStats, NodeTiming};
use crate::node::{Flow, Node};
use crate::rate::{next_deadline, DeadlineWaiter};
use crate::time::Nanos;
use std::cmp::Reverse;
use std::collections::BinaryHeap;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::Arc;

/// A shared stop request: set by a fall, Ctrl-C, the lab, or a failed node.
#[derive(Clone, Debug, Default)]
pub struct StopFlag(Arc<AtomicBool>);

impl StopFlag {
    /// A flag not yet set.
    pub fn new() -> Self {
        Self::default()
    }
    /// Ask every node loop to stop.
    pub fn stop(&self) {
        self.0.store(true, Ordering::SeqCst);
    }
    /// Has a stop been asked for?
    pub fn is_stopped(&self) -> bool {
        self.0.load(Ordering::SeqCst)
    }
}

/// Why a run ended.
#[derive(Clone, Debug, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub enum EndReason {
    /// The run reached its duration.
    Duration,
    /// A node returned [`Flow::Stop`] (the pole fell).
    NodeStopped,
    /// The stop flag was set from outside (Ctrl-C, the lab).
    Interrupted,
    /// A node panicked; its name and message.
    NodeFailed {
        /// The node.
        node: String,
        /// The panic message.
        message: String,
    },
}

impl std::fmt::Display for EndReason {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            EndReason::Duration => f.write_str("duration reached"),
            EndReason::NodeStopped => f.write_str("the pole fell"),
            EndReason::Interrupted => f.write_str("interrupted"),
            EndReason::NodeFailed { node, message } => write!(f, "node '{node}' failed: {message}"),
        }
    }
}

/// How a run ended and at what run time.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct RunEnd {
    /// Run time at the end: the stopping tick's time, or the duration.
    pub at: Nanos,
    /// Why.
    pub reason: EndReason,
}

/// What running one virtual instant did.
#[derive(Debug, PartialEq)]
pub enum InstantOutcome {
    /// Every tick due at the instant ran; bit `i` of `ticked` is set when node `i` ticked.
    Ran {
        /// The nodes that ticked, as a bit set over node indices.
        ticked: u64,
    },
    /// A node stopped the graph (the fall).
    Stopped,
    /// A node panicked: the graph stops and the run names the node.
    Failed(EndReason),
}

/// The virtual-clock executor, steppable one instant at a time (the lab paces it against
/// the wall clock for display; pacing never changes the order of ticks). Every virtual run
/// (headless, sweep, replay, exercises, the lab) goes through [`VirtualScheduler::run_instant`].
pub struct VirtualScheduler {
    heap: BinaryHeap<Reverse<(Nanos, u32, usize)>>,
    now: Nanos,
    ticks: Vec<u64>,
}

impl VirtualScheduler {
    /// Every node due at `t = 0`.
    pub fn new(nodes: &[Box<dyn Node>]) -> Self {
        Self::with_offsets(nodes, &[])
    }

    /// Node `i` first due at `offsets[i]` (missing offsets are 0).
    pub fn with_offsets(nodes: &[Box<dyn Node>], offsets: &[Nanos]) -> Self {
        let heap = nodes
            .iter()
            .enumerate()
            .map(|(i, n)| {
                Reverse((
                    offsets.get(i).copied().unwrap_or(Nanos::ZERO),
                    n.priority(),
                    i,
                ))
            })
            .collect();
        Self {
            heap,
            now: Nanos::ZERO,
            ticks: vec![0; nodes.len()],
        }
    }

    /// The due time of the next tick.
    pub fn next_due(&self) -> Option<Nanos> {
        self.heap.peek().map(|Reverse((due, _, _))| *due)
    }

    /// The due time of node `node`'s next tick (index in the graph), if it is scheduled.
    pub fn next_due_of(&self, node: usize) -> Option<Nanos> {
        self.heap
            .iter()
            .find(|Reverse((_, _, i))| *i == node)
            .map(|Reverse((due, _, _))| *due)
    }

    /// The virtual time of the latest tick.
    pub fn now(&self) -> Nanos {
        self.now
    }

    /// Ticks run so far, per node index.
    pub fn ticks(&self) -> &[u64] {
        &self.ticks
    }

    /// Run the next tick. Returns its time, the node's index and the node's [`Flow`].
    /// A panic in the node propagates; [`VirtualScheduler::run_instant`] catches it.
    pub fn tick_next(&mut self, nodes: &mut [Box<dyn Node>]) -> Option<(Nanos, usize, Flow)> {
        let Reverse((due, prio, i)) = self.heap.pop()?;
        self.now = due;
        self.ticks[i] += 1;
        let flow = nodes[i].tick(due);
        self.heap.push(Reverse((
            due.saturating_add(nodes[i].rate().period()),
            prio,
            i,
        )));
        Some((due, i, flow))
    }

    /// Take the next tick off the schedule without running it (it runs in another process,
    /// [`crate::distributed`]): sets [`VirtualScheduler::now`] to its time, schedules the
    /// node's next tick one period on, and returns the tick's time and node index. Not
    /// counted in [`VirtualScheduler::ticks`].
    pub fn skip_next(&mut self, nodes: &[Box<dyn Node>]) -> Option<(Nanos, usize)> {
        let Reverse((due, prio, i)) = self.heap.pop()?;
        self.now = due;
        self.heap.push(Reverse((
            due.saturating_add(nodes[i].rate().period()),
            prio,
            i,
        )));
        Some((due, i))
    }

    /// Run every tick due at the next instant, in tie-break order. A node that panics is
    /// caught, named, and ends the graph ([`InstantOutcome::Failed`]).
    pub fn run_instant(&mut self, nodes: &mut [Box<dyn Node>]) -> InstantOutcome {
        let Some(t) = self.next_due() else {
            return InstantOutcome::Ran { ticked: 0 };
        };
        let mut ticked = 0u64;
        while self.next_due() == Some(t) {
            let next = self.next_node().unwrap_or(0);
            match catch_quietly(|| self.tick_next(nodes)) {
                Err(p) => {
                    return InstantOutcome::Failed(EndReason::NodeFailed {
                        node: nodes[next].name().to_string(),
                        message: panic_message(&*p),
                    })
                }
                Ok(None) => break,
                Ok(Some((_, i, flow))) => {
                    ticked |= 1 << (i % 64);
                    if flow == Flow::Stop {
                        return InstantOutcome::Stopped;
                    }
                }
            }
        }
        InstantOutcome::Ran { ticked }
    }

    /// The index of the node that ticks next.
    pub fn next_node(&self) -> Option<usize> {
        self.heap.peek().map(|Reverse((_, _, i))| *i)
    }

    /// Run instant by instant until `duration` (ticks due at exactly `duration` run), a
    /// stop, a failed node, or the flag. `before_instant(t)` runs before every instant with
    /// its time (the place to apply commands scheduled at virtual instants).
    pub fn run(
        &mut self,
        nodes: &mut [Box<dyn Node>],
        duration: Nanos,
        stop: &StopFlag,
        before_instant: &mut dyn FnMut(Nanos),
    ) -> RunEnd {
        loop {
            if stop.is_stopped() {
                return RunEnd {
                    at: self.now,
                    reason: EndReason::Interrupted,
                };
            }
            match self.next_due() {
                Some(due) if due <= duration => before_instant(due),
                _ => {
                    return RunEnd {
                        at: duration,
                        reason: EndReason::Duration,
                    }
                }
            }
            match self.run_instant(nodes) {
                InstantOutcome::Ran { .. } => {}
                InstantOutcome::Stopped => {
                    return RunEnd {
                        at: self.now,
                        reason: EndReason::NodeStopped,
                    }
                }
                InstantOutcome::Failed(reason) => {
                    return RunEnd {
                        at: self.now,
                        reason,
                    }
                }
            }
        }
    }
}

/// Called on a node's own thread after each tick under the real clock, with the node's
/// index and name, the tick's run time and its lateness (actual − scheduled).
pub type TickHook = Arc<dyn Fn(usize, &str, Nanos, Nanos) + Send + Sync>;

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
    /// under its default policy. See [`crate::realtime`].
    ///
    /// One priority for all nodes, on purpose: ordering them by tie-break priority (sensor
    /// highest) was measured (BENCHMARKS.md) and moved all waiting for a core onto the
    /// actuator, whose spinning peers never yield to a lower priority.
    pub rt_priority: Option<u8>,
    /// The instant the run's time is zero (`None`: when [`run_real`] starts). Processes of
    /// one graph share it, so their stamps share one clock ([`crate::distributed`]).
    pub start: Option<std::time::Instant>,
}

impl Default for RealOptions {
    fn default() -> Self {
        Self {
            spin_margin: crate::rate::DEFAULT_SPIN_MARGIN,
            phase_offsets: Vec::new(),
            on_tick: None,
            pause: None,
            rt_priority: None,
            start: None,
        }
    }
}

/// What [`run_real`] hands back.
pub struct RealRun {
    /// How it ended.
    pub end: RunEnd,
    /// Per-node tick timing (in node order).
    pub timing: Vec<NodeTiming>,
    /// The nodes, returned for reuse or inspection.
    pub nodes: Vec<Box<dyn Node>>,
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

thread_local! {
    /// Set while [`catch_quietly`] runs on this thread: its panics are caught, not printed.
    static QUIET_PANICS: std::cell::Cell<bool> = const { std::cell::Cell::new(false) };
}

/// Run `f`, catching a panic inside it without printing it: the caller reports it (a node
/// that failed, a checkpoint reader that choked) in one line of its own. A wrapper around
/// the process's panic hook (installed once) stays silent while this thread is inside
/// `catch_quietly`, and defers to the previous hook everywhere else.
///
/// # Errors
/// The panic's payload (see [`panic_message`]).
pub fn catch_quietly<T>(f: impl FnOnce() -> T) -> std::thread::Result<T> {
    static HOOK: std::sync::Once = std::sync::Once::new();
    HOOK.call_once(|| {
        let previous = std::panic::take_hook();
        std::panic::set_hook(Box::new(move |info| {
            if !QUIET_PANICS.with(std::cell::Cell::get) {
                previous(info);
            }
        }));
    });
    let was = QUIET_PANICS.with(|q| q.replace(true));
    let result = std::panic::catch_unwind(std::panic::AssertUnwindSafe(f));
    QUIET_PANICS.with(|q| q.set(was));
    result
}

/// The message of a caught panic.
pub fn panic_message(p: &(dyn std::any::Any + Send)) -> String {
    p.downcast_ref::<&str>()
        .map(|s| s.to_string())
        .or_else(|| p.downcast_ref::<String>().cloned())
        .unwrap_or_else(|| "panic".to_string())
}

/// Run `nodes` on one OS thread each against a monotonic clock until `duration`, a node's
/// [`Flow::Stop`] (which stops every thread), or `stop`. Each thread sleeps to absolute
/// deadlines and records its lateness (actual − scheduled) for jitter statistics.
/// A panicking node stops the graph and is reported in [`EndReason::NodeFailed`].
pub fn run_real(
    nodes: Vec<Box<dyn Node>>,
    duration: Nanos,
    stop: &StopFlag,
    opts: &RealOptions,
) -> RealRun {
    let clock = opts
        .start
        .map_or_else(MonotonicClock::start, MonotonicClock::starting_at);
    let waiter = DeadlineWaiter::new(opts.spin_margin);
    let stop_at = Arc::new(AtomicU64::new(u64::MAX));
    let handles: Vec<_> = nodes
        .into_iter()
        .enumerate()
        .map(|(i, mut node)| {
            let stop = stop.clone();
            let stop_at = stop_at.clone();
            let first = opts.phase_offsets.get(i).copied().unwrap_or(Nanos::ZERO);
            let name = node.name().to_string();
            let on_tick = opts.on_tick.clone();
            let pause = opts.pause.clone();
            let rt_priority = opts.rt_priority;
            std::thread::Builder::new()
                .name(name.clone())
                .spawn(move || {
                    let sched_error = rt_priority
                        .and_then(|p| crate::realtime::set_current_thread_fifo(p).err())
                        .map(|e| e.to_string());
                    let sched = crate::realtime::current_thread_sched().to_string();
                    let cpu0 = thread_cpu_time();
                    let mut lateness = LatencyStats::default();
                    let (mut ticks, mut skipped) = (0u64, 0u64);
                    let mut deadline = first;
                    let result = catch_quietly(|| loop {
                        // Wake for the deadline, the run's end or a stop, whichever is
                        // first: a slow node must not sleep past either.
                        waiter.wait_until_or(clock.instant_at(deadline.min(duration)), &|| {
                            stop.is_stopped()
                        });
                        let mut was_paused = false;
                        while pause.as_ref().is_some_and(|p| p.load(Ordering::SeqCst))
                            && !stop.is_stopped()
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
                        let flow = node.tick(now);
                        if let Some(hook) = &on_tick {
                            hook(i, &name, now, late);
                        }
                        if flow == Flow::Stop {
                            stop_at.fetch_min(now.0, Ordering::SeqCst);
                            stop.stop();
                            break;
                        }
                        let (next, missed) =
                            next_deadline(deadline, clock.now(), node.rate().period());
                        deadline = next;
                        skipped += missed;
                    });
                    if result.is_err() {
                        stop.stop();
                    }
                    let elapsed = clock.now().min(duration).saturating_sub(first);
                    let timing = NodeTiming {
                        node: name,
                        ticks,
                        skipped,
                        lateness_p50_us: lateness.quantile(0.5).map_or(0.0, |n| n.as_micros_f64()),
                        lateness_p99_us: lateness.quantile(0.99).map_or(0.0, |n| n.as_micros_f64()),
                        lateness_max_us: lateness.max().map_or(0.0, |n| n.as_micros_f64()),
                        cpu_ms: (thread_cpu_time().saturating_sub(cpu0)).as_millis_f64(),
                        measured_hz: if elapsed.0 > 0 {
                            ticks as f64 / elapsed.as_secs_f64()
                        } else {
                            0.0
                        },
                        sched,
                        sched_error,
                    };
                    (node, timing, result.err().map(|p| panic_message(&*p)))
                })
                .expect("spawning a node thread")
        })
        .collect();
    let mut nodes = Vec::new();
    let mut timing = Vec::new();
    let mut failed = None;
    for h in handles {
        match h.join() {
            Ok((node, t, panic)) => {
                if let (Some(message), None) = (panic, &failed) {
                    failed = Some(EndReason::NodeFailed {
                        node: t.node.clone(),
                        message,
                    });
                }
                nodes.push(node);
                timing.push(t);
            }
            Err(p) => {
                failed.get_or_insert(EndReason::NodeFailed {
                    node: "?".into(),
                    message: panic_message(&*p),
                });
            }
        }
    }
    let stopped_at = stop_at.load(Ordering::SeqCst);
    let end = if let Some(reason) = failed {
        RunEnd {
            at: clock.now().min(duration),
            reason,
        }
    } else if stopped_at != u64::MAX {
        RunEnd {
            at: Nanos(stopped_at),
            reason: EndReason::NodeStopped,
        }
    } else if stop.is_stopped() {
        RunEnd {
            at: clock.now().min(duration),
            reason: EndReason::Interrupted,
        }
    } else {
        RunEnd {
            at: duration,
            reason: EndReason::Duration,
        }
    };
    RealRun { end, timing, nodes }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::rate::Rate;
    use std::sync::Mutex;

    struct Probe {
        name: &'static str,
        prio: u32,
        rate: Rate,
        log: Arc<Mutex<Vec<(u64, &'static str)>>>,
        stop_at: Option<Nanos>,
    }

    impl Node for Probe {
        fn name(&self) -> &str {
            self.name
        }
        fn priority(&self) -> u32 {
            self.prio
        }
        fn rate(&self) -> &Rate {
            &self.rate
        }
        fn tick(&mut self, now: Nanos) -> Flow {
            self.log.lock().unwrap().push((now.0, self.name));
            if self.stop_at.is_some_and(|t| now >= t) {
                Flow::Stop
            } else {
                Flow::Continue
            }
        }
    }

    fn probes(log: &Arc<Mutex<Vec<(u64, &'static str)>>>, hz: [f64; 3]) -> Vec<Box<dyn Node>> {
        // Deliberately listed out of priority order: the heap must sort by (due, priority).
        [
            ("actuator", 2, hz[2]),
            ("sensor", 0, hz[0]),
            ("policy", 1, hz[1]),
        ]
        .into_iter()
        .map(|(name, prio, hz)| {
            Box::new(Probe {
                name,
                prio,
                rate: Rate::new(hz).unwrap(),
                log: log.clone(),
                stop_at: None,
            }) as Box<dyn Node>
        })
        .collect()
    }

    #[test]
    fn ties_break_by_priority_and_duration_is_inclusive() {
        let log = Arc::new(Mutex::new(Vec::new()));
        let mut nodes = probes(&log, [50.0, 10.0, 50.0]);
        let end = VirtualScheduler::new(&nodes).run(
            &mut nodes,
            Nanos::SECOND,
            &StopFlag::new(),
            &mut |_| {},
        );
        assert_eq!(end.reason, EndReason::Duration);
        let log = log.lock().unwrap();
        assert_eq!(&log[..3], &[(0, "sensor"), (0, "policy"), (0, "actuator")]);
        // At t = 100 ms both the 50 Hz sensor and the 10 Hz policy are due: exact tie.
        let at_100: Vec<_> = log
            .iter()
            .filter(|(t, _)| *t == 100_000_000)
            .map(|(_, n)| *n)
            .collect();
        assert_eq!(at_100, vec!["sensor", "policy", "actuator"]);
        assert_eq!(log.iter().filter(|(_, n)| *n == "actuator").count(), 51);
        assert_eq!(log.last().unwrap().0, 1_000_000_000);
    }

    #[test]
    fn a_stop_halts_the_world() {
        let log = Arc::new(Mutex::new(Vec::new()));
        let mut nodes = probes(&log, [50.0, 50.0, 50.0]);
        let sensor = Box::new(Probe {
            name: "sensor",
            prio: 0,
            rate: Rate::new(50.0).unwrap(),
            log: log.clone(),
            stop_at: Some(Nanos(40_000_000)),
        });
        nodes[1] = sensor;
        let end = VirtualScheduler::new(&nodes).run(
            &mut nodes,
            Nanos::SECOND,
            &StopFlag::new(),
            &mut |_| {},
        );
        assert_eq!(
            end,
            RunEnd {
                at: Nanos(40_000_000),
                reason: EndReason::NodeStopped
            }
        );
        assert_eq!(log.lock().unwrap().last(), Some(&(40_000_000, "sensor")));
    }

    #[test]
    fn a_panicking_node_under_the_virtual_clock_is_named_not_fatal() {
        struct Flaky(Rate, &'static str, bool);
        impl Node for Flaky {
            fn name(&self) -> &str {
                self.1
            }
            fn priority(&self) -> u32 {
                u32::from(self.2)
            }
            fn rate(&self) -> &Rate {
                &self.0
            }
            fn tick(&mut self, now: Nanos) -> Flow {
                assert!(!(self.2 && now > Nanos::ZERO), "policy exploded");
                Flow::Continue
            }
        }
        let nodes = || -> Vec<Box<dyn Node>> {
            vec![
                Box::new(Flaky(Rate::new(50.0).unwrap(), "sensor", false)),
                Box::new(Flaky(Rate::new(50.0).unwrap(), "policy", true)),
            ]
        };
        let mut n = nodes();
        let mut sched = VirtualScheduler::new(&n);
        assert_eq!(
            sched.run_instant(&mut n),
            InstantOutcome::Ran { ticked: 0b11 }
        );
        match sched.run_instant(&mut n) {
            InstantOutcome::Failed(EndReason::NodeFailed { node, message }) => {
                assert_eq!(node, "policy");
                assert!(message.contains("policy exploded"), "{message}");
            }
            other => panic!("{other:?}"),
        }
        // The whole-run path reports the same instead of unwinding through the caller.
        let mut n = nodes();
        let end =
            VirtualScheduler::new(&n).run(&mut n, Nanos::SECOND, &StopFlag::new(), &mut |_| {});
        assert_eq!(end.at, Nanos(20_000_000));
        assert!(matches!(end.reason, EndReason::NodeFailed { ref node, .. } if node == "policy"));
    }

    #[test]
    fn the_slowest_rate_never_overflows_run_time() {
        // 1e-300 Hz: a period past u64 nanoseconds, saturated to "never".
        let log = Arc::new(Mutex::new(Vec::new()));
        let mut nodes = probes(&log, [50.0, 1e-300, 50.0]);
        let mut sched = VirtualScheduler::new(&nodes);
        let end = sched.run(&mut nodes, Nanos::SECOND, &StopFlag::new(), &mut |_| {});
        assert_eq!(end.reason, EndReason::Duration);
        let policy_ticks = log
            .lock()
            .unwrap()
            .iter()
            .filter(|(_, n)| *n == "policy")
            .count();
        assert_eq!(policy_ticks, 1, "ticks once at 0, next due never");
    }

    #[test]
    fn rate_change_applies_from_next_tick() {
        let log = Arc::new(Mutex::new(Vec::new()));
        let mut nodes = probes(&log, [50.0, 50.0, 50.0]);
        let policy_rate = nodes[2].rate().clone();
        let mut sched = VirtualScheduler::new(&nodes);
        let end = sched.run(&mut nodes, Nanos(300_000_000), &StopFlag::new(), &mut |t| {
            if t == Nanos(40_000_000) {
                policy_rate.set_hz(10.0).unwrap();
            }
        });
        assert_eq!(end.reason, EndReason::Duration);
        let policy: Vec<u64> = log
            .lock()
            .unwrap()
            .iter()
            .filter(|(_, n)| *n == "policy")
            .map(|(t, _)| t / 1_000_000)
            .collect();
        // Ticks at 0, 20, then 40 (already scheduled) runs and schedules 40 + 100 = 140.
        assert_eq!(policy, vec![0, 20, 40, 140, 240]);
    }

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

        struct Boom(Rate);
        impl Node for Boom {
            fn name(&self) -> &str {
                "boom"
            }
            fn priority(&self) -> u32 {
                0
            }
            fn rate(&self) -> &Rate {
                &self.0
            }
            fn tick(&mut self, _: Nanos) -> Flow {
                panic!("sensor cable unplugged")
            }
        }
        let run = run_real(
            vec![Box::new(Boom(Rate::new(50.0).unwrap()))],
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
    }
}
