//! Opt-in real-time scheduling for the real clock's node threads.
//!
//! Under the default Linux policy (`SCHED_OTHER`) a node thread shares its core with every
//! other thread on the machine: a tick that is due can wait behind a compile job, and a
//! thread spinning the last microseconds before a deadline can be preempted in the middle
//! of the spin. Robot runtimes therefore run their executor threads under a fixed-priority
//! real-time policy (ROS 2's real-time guidance, OROCOS, copper-rs): a `SCHED_FIFO` thread
//! runs as soon as it is runnable and keeps its core until it blocks or a higher priority
//! thread needs it.
//!
//! Asking for it needs `CAP_SYS_NICE` or an `RLIMIT_RTPRIO` (`ulimit -r`) at least the
//! priority asked for (and, under cgroup v1 real-time group scheduling, a non-zero
//! `cpu.rt_runtime_us` for the process's cgroup, which containers often lack). Otherwise the
//! request is refused and the node keeps `SCHED_OTHER`; ratelab reports that and runs on
//! (a lab run never fails over it).
//!
//! Two cautions, both visible in `ratelab bench`:
//! - The kernel's real-time throttle (`/proc/sys/kernel/sched_rt_runtime_us`, by default
//!   950 ms in every 1 s) stops every `SCHED_FIFO` thread of a core for the rest of a
//!   second once they have used their share. Threads that spin a large fraction of their
//!   period (a big spin margin at a high rate) hit it and then miss ticks for tens of ms.
//! - With more node threads than cores, threads due at the same instant still queue for a
//!   core; real-time priority orders them, it does not add cores.

use std::fmt;
use thread_priority::{
    NormalThreadSchedulePolicy, RealtimeThreadSchedulePolicy, ThreadPriority, ThreadPriorityValue,
    ThreadSchedulePolicy,
};

/// Lowest `SCHED_FIFO` priority Linux accepts.
pub const MIN_RT_PRIORITY: u8 = 1;
/// Highest `SCHED_FIFO` priority Linux accepts.
pub const MAX_RT_PRIORITY: u8 = 99;

/// Why a thread could not be given a real-time priority.
#[derive(Debug, thiserror::Error, PartialEq, Eq, Clone)]
pub enum RealtimeError {
    /// The priority is outside [`MIN_RT_PRIORITY`]..=[`MAX_RT_PRIORITY`].
    #[error("real-time priority must be in 1..=99, got {0}")]
    Range(u8),
    /// The kernel refused (typically `EPERM`: no `CAP_SYS_NICE` and `ulimit -r` too low, or a
    /// cgroup with no real-time budget).
    #[error(
        "SCHED_FIFO priority {priority} refused: {reason} (needs CAP_SYS_NICE or `ulimit -r` >= {priority}, and a real-time budget in a container)"
    )]
    Refused {
        /// The priority asked for.
        priority: u8,
        /// The operating system's reason.
        reason: String,
    },
}

/// The scheduling policy a thread runs under (Linux `sched(7)`), with its static priority
/// for the real-time policies.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ThreadSched {
    /// `SCHED_OTHER`, the default time-sharing policy.
    Other,
    /// `SCHED_FIFO` at this priority (1..=99).
    Fifo(u8),
    /// `SCHED_RR` at this priority (1..=99).
    RoundRobin(u8),
    /// `SCHED_BATCH`.
    Batch,
    /// `SCHED_IDLE`.
    Idle,
    /// `SCHED_DEADLINE`.
    Deadline,
    /// Could not be read.
    Unknown,
}

impl fmt::Display for ThreadSched {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            ThreadSched::Other => f.write_str("SCHED_OTHER"),
            ThreadSched::Fifo(p) => write!(f, "SCHED_FIFO {p}"),
            ThreadSched::RoundRobin(p) => write!(f, "SCHED_RR {p}"),
            ThreadSched::Batch => f.write_str("SCHED_BATCH"),
            ThreadSched::Idle => f.write_str("SCHED_IDLE"),
            ThreadSched::Deadline => f.write_str("SCHED_DEADLINE"),
            ThreadSched::Unknown => f.write_str("unknown"),
        }
    }
}

/// Check a real-time priority.
///
/// # Errors
/// [`RealtimeError::Range`] outside 1..=99.
pub fn check_priority(priority: u8) -> Result<(), RealtimeError> {
    if (MIN_RT_PRIORITY..=MAX_RT_PRIORITY).contains(&priority) {
        Ok(())
    } else {
        Err(RealtimeError::Range(priority))
    }
}

/// Put the calling thread under `SCHED_FIFO` at `priority` (1..=99; higher runs first).
///
/// # Errors
/// [`RealtimeError::Range`] for a priority outside 1..=99; [`RealtimeError::Refused`] when
/// the kernel says no (the thread's policy is then unchanged).
pub fn set_current_thread_fifo(priority: u8) -> Result<(), RealtimeError> {
    check_priority(priority)?;
    let value =
        ThreadPriorityValue::try_from(priority).map_err(|_| RealtimeError::Range(priority))?;
    thread_priority::set_thread_priority_and_policy(
        thread_priority::thread_native_id(),
        ThreadPriority::Crossplatform(value),
        ThreadSchedulePolicy::Realtime(RealtimeThreadSchedulePolicy::Fifo),
    )
    .map_err(|e| RealtimeError::Refused {
        priority,
        reason: match e {
            thread_priority::Error::OS(code) => {
                // "Operation not permitted (os error 1)" → "Operation not permitted".
                let text = std::io::Error::from_raw_os_error(code).to_string();
                text.split(" (os error")
                    .next()
                    .unwrap_or_default()
                    .to_string()
            }
            other => other.to_string(),
        },
    })
}

/// Whether a thread started now by the calling thread would be granted `SCHED_FIFO` at
/// `priority`: asks on a throwaway thread (threads inherit their creator's privileges), so
/// the caller's own policy is untouched.
///
/// # Errors
/// As [`set_current_thread_fifo`].
pub fn probe_fifo(priority: u8) -> Result<(), RealtimeError> {
    std::thread::spawn(move || set_current_thread_fifo(priority))
        .join()
        .unwrap_or(Err(RealtimeError::Refused {
            priority,
            reason: "the probe thread panicked".into(),
        }))
}

/// The calling thread's scheduling policy.
pub fn current_thread_sched() -> ThreadSched {
    let Ok((policy, params)) =
        thread_priority::thread_schedule_policy_param(thread_priority::thread_native_id())
    else {
        return ThreadSched::Unknown;
    };
    let prio = u8::try_from(params.sched_priority).unwrap_or(0);
    match policy {
        ThreadSchedulePolicy::Realtime(RealtimeThreadSchedulePolicy::Fifo) => {
            ThreadSched::Fifo(prio)
        }
        ThreadSchedulePolicy::Realtime(RealtimeThreadSchedulePolicy::RoundRobin) => {
            ThreadSched::RoundRobin(prio)
        }
        ThreadSchedulePolicy::Realtime(RealtimeThreadSchedulePolicy::Deadline) => {
            ThreadSched::Deadline
        }
        ThreadSchedulePolicy::Normal(NormalThreadSchedulePolicy::Batch) => ThreadSched::Batch,
        ThreadSchedulePolicy::Normal(NormalThreadSchedulePolicy::Idle) => ThreadSched::Idle,
        ThreadSchedulePolicy::Normal(_) => ThreadSched::Other,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn priorities_outside_1_to_99_are_rejected_before_asking_the_kernel() {
        assert_eq!(set_current_thread_fifo(0), Err(RealtimeError::Range(0)));
        assert_eq!(set_current_thread_fifo(100), Err(RealtimeError::Range(100)));
        assert!(check_priority(1).is_ok() && check_priority(99).is_ok());
    }

    #[test]
    fn policies_print_as_sched7_names() {
        assert_eq!(ThreadSched::Fifo(50).to_string(), "SCHED_FIFO 50");
        assert_eq!(ThreadSched::Other.to_string(), "SCHED_OTHER");
    }
}
