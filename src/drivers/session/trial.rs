//! A reload's trial on a thread of its own: the saved code loaded (its import: a Python
//! node's or brain's module-level code, its constructor) and, for a reload judged under the
//! virtual clock, run headless. Saved code runs on the engine's thread only once it has
//! returned here, and the engine never waits on a trial: it looks each time round its loop
//! ([`Trial::poll`]), so the live run goes on, the keys act and `q` quits whatever the saved
//! code does. A trial that goes [`SAID_AFTER`] without returning (still loading, or one
//! callback of its run) is said once; a newer save supersedes it ([`Trial::cancel`]): it is
//! stopped, the call it is stuck in interrupted as Python's `KeyboardInterrupt` (a busy
//! loop ends there), and one that still does not end (a `time.sleep`, C code) is abandoned
//! and said ([`Cancelled::check`]).
//!
//! A trial's calls hold the interpreter's lock as any Python code does: a busy loop gives it
//! up every switch interval (5 ms by default) and a sleep at once, so a live run of Python
//! nodes goes on beside it, slower at worst.
//!
//! A trial that stalled and then returned (a callback that sleeps 5 s) is taken up as any
//! other, and says so ([`Tried::stall_note`]): the reload line ends `· the trial's callback
//! stalled 5.0 s at t=1.20 s`, as the run on screen will stall there too.

use super::compare::{Opening, RunFigures};
use crate::run::Command;
use crossbeam_channel::{Receiver, TryRecvError};
use ratelab_core::time::Nanos;
use ratelab_runtime::checkpoint::load_policy;
use ratelab_runtime::config::RunConfig;
use ratelab_runtime::graph::{Graph, GraphHandles, GraphSpec};
use ratelab_runtime::runcore::drive::{DrivePolicy, Turn};
use ratelab_runtime::runcore::{CoreOptions, RunCore};
use ratelab_runtime::scheduler::StopFlag;
use std::convert::Infallible;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::Arc;
use std::time::{Duration, Instant};

/// How long a reload's loading (its import), or one callback of its trial run, may go
/// without returning before the lab says so (as long as the Python layer lets a script's
/// loading run before it warns).
pub const SAID_AFTER: Duration = Duration::from_secs(2);

/// How long a superseded trial is given to end, once stopped and interrupted, before its
/// thread is said abandoned.
const ABANDONED_AFTER: Duration = Duration::from_secs(1);

/// The trial's progress while its code loads (no instant of its run has started).
const LOADING: u64 = u64::MAX;

/// A reload under way: the saved code loading (and tried) on a thread of its own
/// ([`Trial`]), and what is done once it has ([`super::reload`]). One at a time: a newer
/// save supersedes it.
pub(super) struct Pending {
    /// The file saved, as the user knows it.
    pub(super) name: String,
    /// The file saved, its path.
    pub(super) file: std::path::PathBuf,
    /// Its code, loading and tried.
    pub(super) trial: Trial,
    /// What is done once it has loaded.
    pub(super) then: Then,
}

/// What a reload does once its code has loaded (and, judged, run).
pub(super) enum Then {
    /// Run the graph again from t = 0 with `cfg` (the new code's), said against `old`, the
    /// run before's figures at the save (`None`: under the real clock, not judged).
    Reload {
        /// The next run's settings.
        cfg: Box<RunConfig>,
        /// The run before's figures at the save.
        old: Option<Box<RunFigures>>,
    },
    /// Restart nodes in place (under the real clock).
    Restart(Box<Restart>),
    /// Swap the brain in with this change (under the real clock).
    Brain(Command),
}

/// Nodes to restart in place on a save under the real clock.
pub(super) struct Restart {
    /// The file saved, as the user knows it.
    pub(super) name: String,
    /// The run's graph with the new code.
    pub(super) spec: GraphSpec,
    /// The graph as the files now give it.
    pub(super) read: GraphSpec,
    /// The nodes whose code or parameters changed, by graph index.
    pub(super) which: Vec<usize>,
    /// What the engine's thread was pinned to for the saved file until the restart took
    /// it up: pinned again if the restart fails ([`ratelab_runtime::graph::interpreter`]).
    pub(super) pinned_before: ratelab_runtime::graph::interpreter::Scripts,
}

/// What a trial does with the saved code.
pub(super) enum Job {
    /// Build `cfg`'s graph with brain `policy` (loading every node's and the brain's code)
    /// and run it headless to its duration (`cfg` under the virtual clock): its figures,
    /// its actuator's ticks among them ([`RunFigures`]).
    Judge {
        /// The run, headless, under the virtual clock.
        cfg: Box<RunConfig>,
        /// The brain's spec.
        policy: String,
    },
    /// Build nodes `which` of the running graph `handles` holds (its spec the saved code's)
    /// afresh with `seed`, and drop them: their code loads (a restart in place).
    Rebuild {
        /// The live run's handles, their spec the graph with the saved code.
        handles: GraphHandles,
        /// The run's seed.
        seed: u64,
        /// The nodes to build, by graph index.
        which: Vec<usize>,
    },
    /// Load the brain `policy` and drop it (a brain swapped in place).
    Brain {
        /// The brain's spec.
        policy: String,
    },
}

/// What a trial came to ([`Tried`]), or why the code does not load.
pub(super) type Outcome = Result<Tried, String>;

/// A trial that returned: a judged run's figures, and where it stalled.
pub(super) struct Tried {
    /// The judged run's figures (`None` for a load only).
    pub(super) figures: Option<Box<RunFigures>>,
    /// How long its code took to load (its import, its constructor, the graph's building).
    pub(super) loading: Duration,
    /// Its longest instant, when it was one of a judged run: its run time, and how long it
    /// took (wall time).
    pub(super) longest: Option<(Nanos, Duration)>,
}

/// A judged run's instant (its callbacks) that took this long (wall time) is said in the
/// reload line ([`Tried::stall_note`]): the run on screen will stall there too. Far past
/// what an instant of a graph that balances takes (its period is 20 ms).
pub(super) const STALL_SAID: Duration = Duration::from_secs(1);

impl Tried {
    /// A trial that only loaded code, in `loading`.
    fn loaded(loading: Duration) -> Tried {
        Tried {
            figures: None,
            loading,
            longest: None,
        }
    }

    /// What the reload line adds of where the trial stalled, if it did: its longest instant
    /// when that took [`STALL_SAID`] or longer (`the trial's callback stalled 5.0 s at
    /// t=1.20 s`), its loading when that took [`SAID_AFTER`] or longer (`loading it took
    /// 3.0 s`); `None` when it did neither.
    pub(super) fn stall_note(&self) -> Option<String> {
        let mut notes = Vec::new();
        if self.loading >= SAID_AFTER {
            notes.push(format!(
                "loading it took {:.1} s",
                self.loading.as_secs_f64()
            ));
        }
        if let Some((at, took)) = self.longest.filter(|(_, took)| *took >= STALL_SAID) {
            notes.push(format!(
                "the trial's callback stalled {:.1} s at t={:.2} s",
                took.as_secs_f64(),
                at.as_secs_f64()
            ));
        }
        (!notes.is_empty()).then(|| notes.join(" · "))
    }
}

/// Times a judged run's instants as it runs them ([`Judged`] calls [`Stopwatch::next`]
/// before each): its longest, and how long it took to come to its first
/// (its loading, from when the stopwatch was made).
struct Stopwatch {
    /// When the stretch under way began: the trial's start, then each instant's.
    from: Instant,
    /// The instant under way (`None`: still loading).
    at: Option<Nanos>,
    loading: Duration,
    longest: Option<(Nanos, Duration)>,
}

impl Stopwatch {
    fn new() -> Stopwatch {
        Stopwatch {
            from: Instant::now(),
            at: None,
            loading: Duration::ZERO,
            longest: None,
        }
    }

    /// The run comes to its instant at `next` (`None`: it has ended): the stretch before
    /// (its loading, or the instant before) is timed.
    fn next(&mut self, next: Option<Nanos>) {
        let took = self.from.elapsed();
        match self.at {
            None => self.loading = took,
            Some(at) => {
                if self.longest.is_none_or(|(_, most)| took > most) {
                    self.longest = Some((at, took));
                }
            }
        }
        self.from = Instant::now();
        self.at = next;
    }
}

/// A judged run's drive policy: each instant, as it comes, is the trial's progress (run time,
/// ns, for the lab's bar) and starts the stopwatch's next stretch; nothing is paced.
struct Judged<'a> {
    progress: &'a AtomicU64,
    watch: &'a mut Stopwatch,
}

impl DrivePolicy<Nanos, RunCore> for Judged<'_> {
    type Error = Infallible;

    fn turn(&mut self, _index: u64, t: Nanos) -> Result<Turn, Infallible> {
        self.progress.store(t.0, Ordering::Relaxed);
        self.watch.next(Some(t));
        Ok(Turn::Go)
    }
}

impl Job {
    fn run(self, progress: &AtomicU64, stop: &StopFlag) -> Outcome {
        let started = Instant::now();
        match self {
            Job::Judge { cfg, policy } => {
                let mut watch = Stopwatch::new();
                let brain = load_policy(&policy).map_err(|e| e.to_string())?;
                let opening = Opening::upto(cfg.duration);
                let opts = CoreOptions {
                    observers: vec![opening.observer()],
                    ..CoreOptions::default()
                };
                let mut core = RunCore::new(&cfg, brain, opts).map_err(|e| e.to_string())?;
                let mut judged = Judged {
                    progress,
                    watch: &mut watch,
                };
                core.run_to_end_with(&mut judged, stop, None);
                watch.next(None);
                let topics = core.handles().spec.topics.iter();
                let topics = topics.map(|t| t.name.clone()).collect();
                let figures = RunFigures::of(&core.metrics(), topics, opening.ticks());
                Ok(Tried {
                    figures: Some(Box::new(figures)),
                    loading: watch.loading,
                    longest: watch.longest,
                })
            }
            Job::Rebuild {
                handles,
                seed,
                which,
            } => {
                for i in which {
                    drop(Graph::rebuild_node(&handles, seed, i).map_err(|e| e.to_string())?);
                }
                Ok(Tried::loaded(started.elapsed()))
            }
            Job::Brain { policy } => load_policy(&policy)
                .map(|_brain| Tried::loaded(started.elapsed()))
                .map_err(|e| e.to_string()),
        }
    }
}

/// A trial on its thread, as the engine sees it.
pub(super) struct Trial {
    result: Receiver<Outcome>,
    /// The run time of the instant its run is in (ns), or [`LOADING`].
    progress: Arc<AtomicU64>,
    stop: StopFlag,
    /// Its thread's id for the interpreter ([`ratelab_runtime::graph::interpreter::Interpreter::enter_trial`];
    /// 0: not known yet, or no interpreter).
    thread: Arc<AtomicU64>,
    /// Set when its thread is done.
    done: Arc<AtomicBool>,
    /// The progress last seen, and since when.
    seen: (u64, Instant),
    /// The progress at which it was last said not to return, and the whole seconds said.
    said: Option<(u64, u64)>,
}

/// What a look at a trial finds ([`Trial::poll`]).
pub(super) enum Poll {
    /// It has come to this.
    Done(Box<Outcome>),
    /// It has not returned for [`SAID_AFTER`] or longer (`after`, whole seconds: found so
    /// again at each further second), where it is: loading (`at` `None`), or in an instant
    /// of its run (`Some(t)`). `first`: the first time it is found so at this place.
    Stuck {
        /// Where it is.
        at: Option<Nanos>,
        /// How long it has not returned, whole seconds.
        after: Duration,
        /// First found so here.
        first: bool,
    },
    /// It goes on.
    Going,
}

/// Sets its flag when dropped: the trial's thread is done (returned or unwound).
struct Done(Arc<AtomicBool>);

impl Drop for Done {
    fn drop(&mut self) {
        self.0.store(true, Ordering::SeqCst);
    }
}

impl Trial {
    /// Start `job` on a thread of its own, its lines muted (what the code prints is said
    /// when the run on screen runs it).
    pub(super) fn start(job: Job) -> Trial {
        let (tx, result) = crossbeam_channel::bounded(1);
        let progress = Arc::new(AtomicU64::new(LOADING));
        let stop = StopFlag::new();
        let thread = Arc::new(AtomicU64::new(0));
        let done = Arc::new(AtomicBool::new(false));
        let (p, s, t, d) = (progress.clone(), stop.clone(), thread.clone(), done.clone());
        // Not joined: a trial that never returns is left behind (a thread that cannot start
        // drops `tx`, which the poll finds).
        let _ = std::thread::Builder::new()
            .name("reload-trial".into())
            .spawn(move || {
                let _done = Done(d);
                if let Ok(interpreter) = ratelab_runtime::graph::interpreter::installed() {
                    t.store(interpreter.enter_trial(), Ordering::SeqCst);
                }
                let outcome = ratelab_core::textlog::muted(|| job.run(&p, &s));
                let _ = tx.send(outcome);
            });
        Trial {
            result,
            progress,
            stop,
            thread,
            done,
            seen: (LOADING, Instant::now()),
            said: None,
        }
    }

    /// Look at the trial without waiting for it.
    pub(super) fn poll(&mut self) -> Poll {
        match self.result.try_recv() {
            Ok(outcome) => return Poll::Done(Box::new(outcome)),
            Err(TryRecvError::Disconnected) => {
                return Poll::Done(Box::new(Err(
                    "its trial ended without an outcome (its thread could not start, or failed)"
                        .into(),
                )))
            }
            Err(TryRecvError::Empty) => {}
        }
        let at = self.progress.load(Ordering::Relaxed);
        if at != self.seen.0 {
            self.seen = (at, Instant::now());
        }
        let secs = self.seen.1.elapsed().as_secs();
        if secs < SAID_AFTER.as_secs() || self.said == Some((at, secs)) {
            return Poll::Going;
        }
        let first = self.said.is_none_or(|(said_at, _)| said_at != at);
        self.said = Some((at, secs));
        Poll::Stuck {
            at: (at != LOADING).then_some(Nanos(at)),
            after: Duration::from_secs(secs),
            first,
        }
    }

    /// Stop the trial (a newer save supersedes it, or the run it was saved in ended): its
    /// run stops at its next instant and the call it is in, if any, is interrupted. What it
    /// comes to is ignored; [`Cancelled::check`] watches that it ends. `name`: the file
    /// saved, as the user knows it.
    pub(super) fn cancel(self, name: String) -> Cancelled {
        self.stop.stop();
        let mut cancelled = Cancelled {
            name,
            since: Instant::now(),
            thread: self.thread,
            done: self.done,
            interrupted: false,
            stuck: self.said.is_some(),
        };
        cancelled.interrupt();
        cancelled
    }
}

/// A trial stopped, until its thread is done or abandoned ([`Cancelled::check`]).
pub(super) struct Cancelled {
    name: String,
    since: Instant,
    thread: Arc<AtomicU64>,
    done: Arc<AtomicBool>,
    /// A `KeyboardInterrupt` was raised in the call it was in.
    interrupted: bool,
    /// It had been said not to return.
    stuck: bool,
}

impl Cancelled {
    /// Interrupt the call the trial is in, if it is in one (and not interrupted already).
    fn interrupt(&mut self) {
        let thread = self.thread.load(Ordering::SeqCst);
        if self.interrupted || thread == 0 {
            return;
        }
        self.interrupted = ratelab_runtime::graph::interpreter::installed()
            .is_ok_and(|interpreter| interpreter.interrupt_trial(thread));
    }

    /// Whether to go on watching it, and what to say of it: a stuck trial that the
    /// interrupt ended, or one not done [`ABANDONED_AFTER`] it was stopped (a `time.sleep`,
    /// C code, or Python that catches `KeyboardInterrupt`: its thread is left to end when
    /// it returns, and what it comes to is ignored).
    pub(super) fn check(&mut self) -> (bool, Option<String>) {
        if self.done.load(Ordering::SeqCst) {
            let said = (self.stuck && self.interrupted).then(|| {
                format!(
                    "reload of {}: the code saved before, which had not returned, was interrupted (KeyboardInterrupt)",
                    self.name
                )
            });
            return (false, said);
        }
        if self.since.elapsed() >= ABANDONED_AFTER {
            return (
                false,
                Some(format!(
                    "reload of {}: the code saved before has not returned {} s after it was interrupted (a sleep or C code cannot be): its thread is abandoned",
                    self.name,
                    ABANDONED_AFTER.as_secs()
                )),
            );
        }
        // A call it entered after it was stopped (it was between two).
        self.interrupt();
        (true, None)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn tried(loading_ms: u64, longest: Option<(u64, u64)>) -> Tried {
        Tried {
            figures: None,
            loading: Duration::from_millis(loading_ms),
            longest: longest
                .map(|(at_ms, took_ms)| (Nanos(at_ms * 1_000_000), Duration::from_millis(took_ms))),
        }
    }

    /// A trial whose callback slept 5 s says where and how long, as the reload line ends;
    /// one that went at its pace says nothing; a long loading is said apart.
    #[test]
    fn a_trial_that_stalled_and_returned_says_where() {
        assert_eq!(
            tried(40, Some((1_200, 5_000))).stall_note().as_deref(),
            Some("the trial's callback stalled 5.0 s at t=1.20 s")
        );
        assert_eq!(tried(40, Some((20, 3))).stall_note(), None);
        assert_eq!(tried(40, Some((20, 999))).stall_note(), None);
        assert_eq!(tried(40, None).stall_note(), None);
        assert_eq!(
            tried(3_000, Some((0, 1_000))).stall_note().as_deref(),
            Some("loading it took 3.0 s · the trial's callback stalled 1.0 s at t=0.00 s")
        );
        assert_eq!(
            Tried::loaded(Duration::from_millis(2_500))
                .stall_note()
                .as_deref(),
            Some("loading it took 2.5 s")
        );
    }

    /// The stopwatch times the loading up to the first instant, then each instant up to the
    /// next (the last up to the run's end), keeping the longest and its run time.
    #[test]
    fn the_stopwatch_keeps_the_loading_and_the_longest_instant() {
        let mut watch = Stopwatch::new();
        std::thread::sleep(Duration::from_millis(30));
        watch.next(Some(Nanos::ZERO));
        watch.next(Some(Nanos(20_000_000)));
        std::thread::sleep(Duration::from_millis(60));
        watch.next(Some(Nanos(40_000_000)));
        watch.next(None);
        assert!(
            watch.loading >= Duration::from_millis(30),
            "{:?}",
            watch.loading
        );
        let (at, took) = watch.longest.expect("instants ran");
        assert_eq!(at, Nanos(20_000_000));
        assert!(took >= Duration::from_millis(60), "{took:?}");
    }
}
