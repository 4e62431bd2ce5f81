//! A process's share of a real-clock run: its nodes on their own threads from the run's
//! shared start instant, its figures' run time kept short of a tick in progress, and the
//! launcher's stop watched.

use super::stats::{held_topics, read_counters};
use super::{wire, DistError, GraphState, NodeId, Share, StopFlag, ToLauncher, ToProcess};
use crate::liveliness::TokenWatch;
use crossbeam_channel::{Receiver, RecvTimeoutError};
use ratelab_core::metrics::NodeTiming;
use ratelab_core::time::Nanos;
use ratelab_runtime::runcore::drive::{watch_real, Intake, RealPolicy};
use ratelab_runtime::runcore::{RealEnd, RunCore};
use ratelab_runtime::scheduler::RealOptions;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::Arc;
use std::time::Duration;

/// The real clock: run the local nodes of `core`'s graph on their own threads
/// ([`RunCore::run_real`]) from the shared start instant
/// (a process that joined late starts each node at its next tick on the run's grid), until
/// the duration, a local stop (the fall) or the launcher's stop.
pub(super) fn real_clock(
    mut core: RunCore,
    share: &Share,
    start: u64,
    ctl_rx: &Receiver<ToProcess>,
    stop: &StopFlag,
    launcher_gone: &TokenWatch,
    send: super::SendUp<'_>,
) -> Result<GraphState, DistError> {
    let cfg = &share.cfg;
    let local = share.local();
    let spec = &cfg.graph;
    // Joined late (a restart): the first tick of each node is its next one on the grid.
    let late = Nanos(wire::mono_now_ns().saturating_sub(start));
    share.joined_at.store(late.0, Ordering::Relaxed);
    let index: Vec<usize> = (0..spec.nodes.len())
        .filter(|i| local.contains(i))
        .collect();
    let phase_offsets = first_ticks(share, &index, late);
    // Per local node, the deadline of its next tick, ns: no tick of it not yet sampled is
    // earlier (see `figures_time`).
    let next_due: Arc<Vec<AtomicU64>> =
        Arc::new(phase_offsets.iter().map(|d| AtomicU64::new(d.0)).collect());
    let real = RealOptions {
        spin_margin: cfg.spin_margin,
        phase_offsets,
        rt_priority: cfg.rt_priority,
        on_tick: Some(tick_hook(share, &index, &next_due, start)),
        pause: None,
        start: Some(wire::instant_at_mono(start)),
        from: Nanos::ZERO,
        // This process's executors (an executor never spans processes: `launch` checks).
        plan: Some(spec.execution_plan().restricted(&index)),
        track: spec.has_executors_or_compute(),
    };
    // The launcher's stop (another process ended the run, or Ctrl-C there), watched on
    // this thread while the nodes run on theirs.
    let mut watch = Watch {
        rx: Some(ctl_rx),
        outer: stop,
        gone: launcher_gone,
        launcher_at: None,
        left: false,
        run_time: &share.run_time,
        next_due: &next_due,
        start,
        end: share.cfg.duration.0,
    };
    let Some(r) = watch_real(&mut core, Some(&index), &real, &mut watch, &StopFlag::new()) else {
        return Err(DistError::Peer(format!(
            "process '{}': the real clock's runner failed; its nodes are gone",
            share.process
        )));
    };
    let stopped_by_launcher =
        watch.left && r.end.reason == ratelab_runtime::scheduler::EndReason::Interrupted;
    if !stopped_by_launcher {
        send(&ToLauncher::Ended {
            process: share.process.clone(),
            end: r.end.clone(),
        })?;
    }
    // Report at the run's end as the launcher saw it (its stop), else our own.
    let at = match watch.launcher_at {
        Some(at) if stopped_by_launcher => at,
        _ => r.end.at,
    };
    // Every node thread has ended: the figures are final up to the run's end.
    share.run_time.fetch_max(at.0, Ordering::SeqCst);
    Ok(local_state(share, &index, at, r))
}

/// Each local node's first tick (`index`: their graph indices): its phase offset, or for
/// a process that joined `late` into the run, its next tick on the run's grid.
fn first_ticks(share: &Share, index: &[usize], late: Nanos) -> Vec<Nanos> {
    let firsts = share.cfg.first_deadlines();
    index
        .iter()
        .map(|&i| {
            let first = firsts.get(i).copied().unwrap_or(Nanos::ZERO);
            ratelab_core::rate::first_on_grid(first, share.handles.rates[i].period(), late)
        })
        .collect()
}

/// What each tick of a local node does besides the node's own work: count it, forward
/// what it published to other processes, sample the counters this process holds into the
/// batch, move its next deadline on and the figures' run time with it.
fn tick_hook(
    share: &Share,
    index: &[usize],
    next_due: &Arc<Vec<AtomicU64>>,
    start: u64,
) -> ratelab_runtime::scheduler::TickHook {
    let (hook_ticks, hook_time) = (share.ticks.clone(), share.run_time.clone());
    let hook_batch = share.batch.clone();
    let hook_index = index.to_vec();
    let fwd = share.bridge.clone();
    let mine: Vec<NodeId> = share.local().iter().map(|&i| NodeId(i)).collect();
    let hook_held = held_topics(&share.cfg.graph, &mine);
    let hook_handles = share.handles.clone();
    let (hook_due, end) = (next_due.clone(), share.cfg.duration.0);
    Arc::new(move |t: &ratelab_runtime::scheduler::TickReport<'_>| {
        let (k, now, late) = (t.node, t.now, t.lateness);
        let i = hook_index[k];
        hook_ticks[i].fetch_add(1, Ordering::Relaxed);
        fwd.forward_after(i);
        // The sample is in the batch before the run time says this tick is done.
        let read = read_counters(&hook_held, &hook_handles);
        {
            let mut b = ratelab_runtime::graph::lock(&hook_batch);
            b.push_tick((i, now.0, late.0, t.took.0));
            b.keep(now.0, &read);
        }
        // Its next tick is due a period after this one's deadline, at the earliest.
        let period = hook_handles.rates[i].period().0.max(1);
        let deadline = now.0.saturating_sub(late.0);
        hook_due[k].store(deadline.saturating_add(period), Ordering::SeqCst);
        let wall = wire::mono_now_ns().saturating_sub(start);
        hook_time.fetch_max(
            figures_time(wall, end, due_now(&hook_due)),
            Ordering::SeqCst,
        );
    })
}

/// Watches the launcher while the nodes run ([`watch_real`]'s policy): its stop (another
/// process ended the run, or Ctrl-C there) stops the run, with its run time kept
/// (`launcher_at`); so does a local stop or the launcher going away (without a time). It
/// keeps the figures' run time at now, short of a tick that may be in progress.
struct Watch<'a> {
    /// The launcher's messages (`None` once its channel has closed).
    rx: Option<&'a Receiver<ToProcess>>,
    outer: &'a StopFlag,
    gone: &'a TokenWatch,
    /// The launcher's stop's run time, once it has come.
    launcher_at: Option<Nanos>,
    /// The watch stopped the run.
    left: bool,
    run_time: &'a AtomicU64,
    next_due: &'a [AtomicU64],
    /// The run's start, on the monotonic clock (ns).
    start: u64,
    /// The run's duration, ns.
    end: u64,
}

impl RealPolicy for Watch<'_> {
    fn intake(&mut self, _ended: bool) -> Intake {
        // The figures' run time is now, not the last tick (a slow node ticks seldom), short
        // of a tick that may be in progress.
        let wall = wire::mono_now_ns().saturating_sub(self.start);
        let at = figures_time(wall, self.end, due_now(self.next_due));
        self.run_time.fetch_max(at, Ordering::SeqCst);
        let wait = Duration::from_millis(50);
        let got = match self.rx {
            Some(rx) => rx.recv_timeout(wait),
            None => {
                std::thread::sleep(wait);
                Err(RecvTimeoutError::Timeout)
            }
        };
        match got {
            Ok(ToProcess::Stop { at_ns, .. }) => {
                self.launcher_at = Some(Nanos(at_ns));
                self.left = true;
                return Intake::Leave;
            }
            Ok(_) => {}
            // Its stop cannot come now; a local stop or its going away still can.
            Err(RecvTimeoutError::Disconnected) => self.rx = None,
            Err(RecvTimeoutError::Timeout) if self.outer.is_stopped() || self.gone.is_gone() => {
                self.left = true;
                return Intake::Leave;
            }
            Err(RecvTimeoutError::Timeout) => {}
        }
        Intake::Go
    }
}

/// This process's view of the run at `at`: the graph's state, with its own nodes' timing
/// and executor figures (`r`, in local order; `index`: their graph indices) by graph index
/// (the others' are their processes' to report).
fn local_state(share: &Share, index: &[usize], at: Nanos, r: RealEnd) -> GraphState {
    let spec = &share.cfg.graph;
    let mut timing: Vec<NodeTiming> = spec
        .nodes
        .iter()
        .map(|n| NodeTiming {
            node: n.name.clone(),
            ..NodeTiming::default()
        })
        .collect();
    for (k, t) in r.timing.into_iter().enumerate() {
        timing[index[k]] = t;
    }
    let ticks_now: Vec<u64> = share
        .ticks
        .iter()
        .map(|t| t.load(Ordering::Relaxed))
        .collect();
    let mut state = GraphState::capture(&share.handles, at, &ticks_now, Some(timing));
    state.exec = r.exec.map(|x| {
        let mut nodes = vec![ratelab_core::executor::NodeExecFigures::default(); spec.nodes.len()];
        for (k, f) in x.nodes.into_iter().enumerate() {
            nodes[index[k]] = f;
        }
        ratelab_core::executor::ExecFigures {
            nodes,
            executors: x.executors,
        }
    });
    state
}

/// The deadlines in `next_due`, ns, as they are now (read on every tick: no allocation).
fn due_now(next_due: &[AtomicU64]) -> impl Iterator<Item = u64> + '_ {
    next_due.iter().map(|d| d.load(Ordering::SeqCst))
}

/// The run time up to which a real-clock process's figures are final, ns: now (`wall_ns`,
/// at most the run's `end_ns`), but short of the earliest next deadline of its nodes
/// (`next_due_ns`). A node's tick due by now may be in progress, its counters not yet
/// sampled; its sample will carry its start time, which is at or after its deadline. So a
/// watcher that releases a step of run time `t` once the figures cover `t` has every sample
/// up to `t` ([`LiveStats::t_ns`]).
pub(super) fn figures_time(
    wall_ns: u64,
    end_ns: u64,
    next_due_ns: impl IntoIterator<Item = u64>,
) -> u64 {
    let due = next_due_ns.into_iter().min().unwrap_or(u64::MAX);
    wall_ns.min(end_ns).min(due.saturating_sub(1))
}
