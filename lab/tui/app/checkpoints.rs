//! The lab's folded view, kept every so many journal messages ([`Checkpoints`]), so that a
//! seek back ([`super::journal`]) folds the journal from the nearest checkpoint at or before
//! the instant instead of from the run's start: reaching any instant of a long run then costs
//! a checkpoint's copy and at most [`Checkpoints::every`] messages, whatever the run's length
//! (issue 76 item 5: scrubbing a 10-minute run within 15 ms at p99). The run core does the
//! same for the run itself (its captures, `ratelab::runcore`); these are the screen's.
//!
//! A checkpoint holds every field the fold writes ([`Folded`]), taken right after the
//! journal's `upto`-th message was folded. The fields left out are the user's (selection,
//! panels, typing), the journal's own, what keys asked for that no status has shown yet
//! (dropped by a seek, as by a run's start), or fixed for a journal's whole life (its graph
//! but its executors: a new graph is a new run, which starts a new journal). [`App::folded`] names every field of the
//! lab's state, so a new field does not compile until it is sorted into one side or the other.

use super::{App, GhostStep, Live, StepRecord, Verdict};
use ratelab::graph::spec::ExecutorSpec;
use ratelab::graph::TopicId;
use ratelab::qos::TopicQos;
use ratelab::session::{Speed, Telemetry};
use ratelab::Nanos;
use std::collections::{BTreeMap, VecDeque};
use std::mem::size_of;

/// The most checkpoints kept: past it every other one goes and the spacing doubles, so a
/// run of any length keeps between half and all of these.
pub const MAX_CHECKPOINTS: usize = 32;
/// The most bytes the checkpoints hold together (estimated by [`Folded::approx_bytes`]);
/// past it they are thinned as past [`MAX_CHECKPOINTS`].
pub const MAX_CHECKPOINT_BYTES: usize = 32 << 20;
/// Journal messages between checkpoints at a run's start (the spacing doubles with each
/// thinning).
pub const FIRST_EVERY: usize = 256;

/// Everything the fold of a journal writes into the lab's state: see [`App::folded`].
#[derive(Clone)]
pub(super) struct Folded {
    clock: String,
    speed: Speed,
    paused: bool,
    now: Nanos,
    seed: u64,
    brain: String,
    recording: Option<String>,
    rates: Vec<f64>,
    depths: Vec<usize>,
    qos: Vec<TopicQos>,
    phases: Vec<f64>,
    explained_losses: Vec<TopicId>,
    lost_before_reliable: Vec<Option<(Nanos, u64)>>,
    lost_at_last_step: Vec<u64>,
    alive: Vec<Option<bool>>,
    faults: super::Faults,
    exec: VecDeque<(Nanos, Vec<(u64, u64)>)>,
    live: Live,
    history: VecDeque<(f64, f64)>,
    thinned: crate::tui::chart_window::Thinned,
    estimates: crate::tui::estimates::Estimates,
    applied: VecDeque<(f64, f64)>,
    published: VecDeque<(f64, f64)>,
    ticks: Vec<VecDeque<(Nanos, Nanos, Nanos)>>,
    timeline: crate::tui::timeline::Timeline,
    /// The graph's executors and its nodes' callback groups (`x` changes them under the
    /// virtual clock; the rest of the graph is fixed for a journal's life).
    executors: Vec<ExecutorSpec>,
    callback_groups: Vec<Option<String>>,
    exec_from: Option<Nanos>,
    ended_with: Option<(Vec<f64>, Vec<usize>, Vec<TopicQos>)>,
    final_topics: Option<BTreeMap<String, ratelab::metrics::TopicMetrics>>,
    last: Option<StepRecord>,
    verdict: Verdict,
    message: Option<String>,
    message_at: Option<std::time::Instant>,
    journal_bytes: usize,
    whole: Vec<GhostStep>,
    reloading: Option<String>,
    run_reload: Option<String>,
    ended_word: Option<String>,
    wire: Vec<Option<(f64, f64)>>,
}

impl Folded {
    /// About how many bytes a copy holds of its own, an estimate for the budget
    /// ([`MAX_CHECKPOINT_BYTES`]): its series and queues, and each kept step record's fixed
    /// part. Topic counters are not counted: a copied record or count shares its counters'
    /// blocks with the journal's message it came from (`TopicCounters` clones share them),
    /// and the journal is budgeted on its own ([`super::MAX_JOURNAL_BYTES`]).
    fn approx_bytes(&self) -> usize {
        let pairs = self.history.len()
            + self.applied.len()
            + self.published.len()
            + self.estimates.points();
        size_of::<Self>()
            + pairs * size_of::<(f64, f64)>()
            + self.thinned.kept() * size_of::<(f64, f64, f64)>()
            + self.whole.len() * size_of::<GhostStep>()
            + self.live.records() * size_of::<StepRecord>()
            + self.ticks.iter().map(VecDeque::len).sum::<usize>() * size_of::<[Nanos; 3]>()
            + self.timeline.kept() * size_of::<ratelab::executor::CallbackSpan>()
            + self.exec.iter().map(|(_, e)| e.len()).sum::<usize>() * size_of::<(u64, u64)>()
    }
}

/// One checkpoint: the fold of the journal's first `upto` messages.
struct Checkpoint {
    /// Journal messages folded into it.
    upto: usize,
    /// The latest instant a clock switch among them happened at: a seek to that instant or
    /// before cannot start here (a switch at the seek's instant came after it, and is not
    /// folded).
    switched_at: Option<Nanos>,
    /// [`Folded::approx_bytes`].
    bytes: usize,
    state: Box<Folded>,
}

/// The checkpoints of the journal on screen, oldest first.
pub(super) struct Checkpoints {
    kept: Vec<Checkpoint>,
    /// Journal messages between two checkpoints.
    every: usize,
    /// Their [`Folded::approx_bytes`], added.
    bytes: usize,
    /// The journal's length at which the next is due (`usize::MAX`: none for this journal).
    next_at: usize,
    /// None is taken while set: a seek's fold that left out a clock switch (the journal
    /// folded again is then not the one a review puts back, past the switch).
    held: bool,
    /// None is ever due (a test's lab that folds every seek from the run's start).
    #[cfg(test)]
    never: bool,
    /// The messages of the checkpoint the last seek started from (`Some(0)`: none).
    #[cfg(test)]
    started_from: Option<usize>,
}

impl Default for Checkpoints {
    fn default() -> Self {
        Self {
            kept: Vec::new(),
            every: FIRST_EVERY,
            bytes: 0,
            next_at: FIRST_EVERY,
            held: false,
            #[cfg(test)]
            never: false,
            #[cfg(test)]
            started_from: None,
        }
    }
}

impl Checkpoints {
    /// Forget them all (a new journal: a new run).
    pub(super) fn clear(&mut self) {
        self.kept.clear();
        self.every = FIRST_EVERY;
        self.bytes = 0;
        self.next_at = FIRST_EVERY;
    }

    /// Take none while `held` ([`Checkpoints::held`]).
    pub(super) fn hold(&mut self, held: bool) {
        self.held = held;
    }

    /// Journal messages between two checkpoints now.
    #[cfg(test)]
    pub(super) fn every(&self) -> usize {
        self.every
    }

    /// How many are kept.
    #[cfg(test)]
    pub(super) fn len(&self) -> usize {
        self.kept.len()
    }

    /// Is one due, the journal holding `len` messages?
    fn due(&self, len: usize) -> bool {
        #[cfg(test)]
        if self.never {
            return false;
        }
        !self.held && len >= self.next_at
    }

    /// The next is due `every` messages after the last kept.
    fn due_after_the_last(&mut self) {
        let last = self.kept.last().map_or(0, |c| c.upto);
        self.next_at = last.saturating_add(self.every);
    }

    /// Keep `state`, the fold of `journal` (the whole journal so far).
    fn keep(&mut self, journal: &[(Nanos, Telemetry)], state: Folded) {
        let upto = journal.len();
        let (from, before) = self
            .kept
            .last()
            .map_or((0, None), |c| (c.upto, c.switched_at));
        let switched_at = journal[from..]
            .iter()
            .filter_map(|(_, t)| match t {
                Telemetry::ClockSwitched { at, .. } => Some(*at),
                _ => None,
            })
            .chain(before)
            .max();
        let bytes = state.approx_bytes();
        if bytes > MAX_CHECKPOINT_BYTES / 4 {
            // Too large to keep even a few: this journal's seeks fold from the run's start
            // (and no copy is made again).
            self.next_at = usize::MAX;
            return;
        }
        self.bytes += bytes;
        self.kept.push(Checkpoint {
            upto,
            switched_at,
            bytes,
            state: Box::new(state),
        });
        while self.kept.len() > MAX_CHECKPOINTS || self.bytes > MAX_CHECKPOINT_BYTES {
            self.thin();
        }
        self.due_after_the_last();
    }

    /// Every other checkpoint goes (the first, the third, …: those kept stay on multiples of
    /// the new spacing), and the spacing doubles.
    fn thin(&mut self) {
        let mut i = 0;
        self.kept.retain(|_| {
            i += 1;
            i % 2 == 0
        });
        self.bytes = self.kept.iter().map(|c| c.bytes).sum();
        self.every = self.every.saturating_mul(2);
    }

    /// The last message of the journal's first `len` was replaced (a status repeating its
    /// instant): a checkpoint that folded the message replaced goes.
    fn replaced_last(&mut self, len: usize) {
        if self.kept.last().is_some_and(|c| c.upto >= len) {
            if let Some(c) = self.kept.pop() {
                self.bytes -= c.bytes;
            }
        }
    }

    /// The latest checkpoint a seek to `at` can start from, folding the journal's first
    /// `upto` messages: its messages' count and its state. Those after it go (the journal
    /// is folded again from it, and is not what it was after it).
    fn start_for(&mut self, upto: usize, at: Nanos) -> Option<(usize, Folded)> {
        let usable = |c: &Checkpoint| c.upto <= upto && c.switched_at.is_none_or(|s| s < at);
        let i = self.kept.iter().rposition(usable);
        #[cfg(test)]
        {
            self.started_from = Some(i.map_or(0, |i| self.kept[i].upto));
        }
        let i = i?;
        for c in self.kept.drain(i + 1..) {
            self.bytes -= c.bytes;
        }
        self.due_after_the_last();
        let c = &self.kept[i];
        Some((c.upto, (*c.state).clone()))
    }
}

impl App {
    /// After a message was added to the journal: a checkpoint, when one is due.
    pub(super) fn checkpoint_if_due(&mut self) {
        if self.journal_full || !self.checkpoints.due(self.journal.len()) {
            return;
        }
        let state = self.folded();
        self.checkpoints.keep(&self.journal, state);
    }

    /// The journal's last message was replaced by `len`'s last (see
    /// [`Checkpoints::replaced_last`]).
    pub(super) fn journal_replaced_last(&mut self) {
        self.checkpoints.replaced_last(self.journal.len());
    }

    /// Put the lab's state back to the latest checkpoint a seek to `at` can start from, and
    /// cut the journal there: what it held from there up to `upto` (its messages at or before
    /// `at`) is returned, to fold again. With no such checkpoint, the whole journal up to
    /// `upto` is returned and the journal is left empty (folding it from its start resets
    /// the state).
    pub(super) fn restore_for(&mut self, upto: usize, at: Nanos) -> Vec<(Nanos, Telemetry)> {
        let mut journal = std::mem::take(&mut self.journal);
        journal.truncate(upto);
        let Some((from, state)) = self.checkpoints.start_for(upto, at) else {
            self.checkpoints.clear();
            return journal;
        };
        let tail = journal.split_off(from);
        self.journal = journal;
        self.restore_folded(state);
        tail
    }

    /// A copy of every field the fold writes. Every field of the lab's state is named here:
    /// those not copied are the user's, the journal's, or fixed for a journal's life.
    fn folded(&self) -> Folded {
        let App {
            // The engine's channel, the brains `p` swaps, the user's view and panels.
            tx: _,
            policy_spec: _,
            alt_policy: _,
            selected: _,
            nav: _,
            chart_window: _,
            review: _,
            on_graph: _,
            show_timeline: _,
            log: _,
            log_rx: _,
            log_total: _,
            show_log: _,
            log_back: _,
            log_open: _,
            log_scroll: _,
            code_folder: _,
            interrupted_at: _,
            ros2_domain: _,
            show_ros2: _,
            help: _,
            // Said by the seek back that folds the journal, after it.
            back_at: _,
            confirm_quit: _,
            typing: _,
            attached: _,
            endpoint: _,
            quit: _,
            // The journal and its checkpoints; a seek's own flag.
            journal: _,
            journal_full: _,
            checkpoints: _,
            rewinding: _,
            seek_target: _,
            // What keys asked for and no status has shown yet: a seek back drops it, as a
            // run's start does (the engine's run core is put back before it too).
            pending_rates: _,
            pending_executor: _,
            // The run before a reload, fixed for a journal's life; of the run's graph, fixed
            // too, only the executors are copied (below).
            ghost: _,
            graph,
            clock,
            speed,
            paused,
            now,
            seed,
            brain,
            recording,
            rates,
            depths,
            qos,
            phases,
            explained_losses,
            lost_before_reliable,
            lost_at_last_step,
            alive,
            faults,
            exec,
            live,
            history,
            thinned,
            estimates,
            applied,
            published,
            ticks,
            timeline,
            exec_from,
            ended_with,
            final_topics,
            last,
            verdict,
            message,
            message_at,
            journal_bytes,
            whole,
            reloading,
            run_reload,
            ended_word,
            wire,
        } = self;
        Folded {
            clock: clock.clone(),
            speed: *speed,
            paused: *paused,
            now: *now,
            seed: *seed,
            brain: brain.clone(),
            recording: recording.clone(),
            rates: rates.clone(),
            depths: depths.clone(),
            qos: qos.clone(),
            phases: phases.clone(),
            explained_losses: explained_losses.clone(),
            lost_before_reliable: lost_before_reliable.clone(),
            lost_at_last_step: lost_at_last_step.clone(),
            alive: alive.clone(),
            faults: faults.clone(),
            exec: exec.clone(),
            live: live.clone(),
            history: history.clone(),
            thinned: thinned.clone(),
            estimates: estimates.clone(),
            applied: applied.clone(),
            published: published.clone(),
            ticks: ticks.clone(),
            timeline: timeline.clone(),
            executors: graph.executors.clone(),
            callback_groups: graph
                .nodes
                .iter()
                .map(|n| n.callback_group.clone())
                .collect(),
            exec_from: *exec_from,
            ended_with: ended_with.clone(),
            final_topics: final_topics.clone(),
            last: last.clone(),
            verdict: verdict.clone(),
            message: message.clone(),
            message_at: *message_at,
            journal_bytes: *journal_bytes,
            whole: whole.clone(),
            reloading: reloading.clone(),
            run_reload: run_reload.clone(),
            ended_word: ended_word.clone(),
            wire: wire.clone(),
        }
    }

    /// Put back what [`App::folded`] copied.
    fn restore_folded(&mut self, f: Folded) {
        let Folded {
            clock,
            speed,
            paused,
            now,
            seed,
            brain,
            recording,
            rates,
            depths,
            qos,
            phases,
            explained_losses,
            lost_before_reliable,
            lost_at_last_step,
            alive,
            faults,
            exec,
            live,
            history,
            thinned,
            estimates,
            applied,
            published,
            ticks,
            timeline,
            executors,
            callback_groups,
            exec_from,
            ended_with,
            final_topics,
            last,
            verdict,
            message,
            message_at,
            journal_bytes,
            whole,
            reloading,
            run_reload,
            ended_word,
            wire,
        } = f;
        self.clock = clock;
        self.speed = speed;
        self.paused = paused;
        self.now = now;
        self.seed = seed;
        self.brain = brain;
        self.recording = recording;
        self.rates = rates;
        self.pending_rates.clear();
        self.depths = depths;
        self.qos = qos;
        self.phases = phases;
        self.explained_losses = explained_losses;
        self.lost_before_reliable = lost_before_reliable;
        self.lost_at_last_step = lost_at_last_step;
        self.alive = alive;
        self.faults = faults;
        self.exec = exec;
        self.live = live;
        self.history = history;
        self.thinned = thinned;
        self.estimates = estimates;
        self.applied = applied;
        self.published = published;
        self.ticks = ticks;
        self.timeline = timeline;
        self.pending_executor = None;
        self.graph.executors = executors;
        for (n, group) in self.graph.nodes.iter_mut().zip(callback_groups) {
            n.callback_group = group;
        }
        self.exec_from = exec_from;
        self.ended_with = ended_with;
        self.final_topics = final_topics;
        self.last = last;
        self.verdict = verdict;
        self.message = message;
        self.message_at = message_at;
        self.journal_bytes = journal_bytes;
        self.whole = whole;
        self.reloading = reloading;
        self.run_reload = run_reload;
        self.ended_word = ended_word;
        self.wire = wire;
    }
}

#[cfg(test)]
mod tests {
    use super::{App, Checkpoints, FIRST_EVERY, MAX_CHECKPOINTS, MAX_CHECKPOINT_BYTES};
    use crate::bench::{chapter_status, STATUS_EVERY};
    use crate::tui::keymap::Msg;
    use ratelab::policy::Scripted;
    use ratelab::runlog::StepRecord;
    use ratelab::session::{Speed, Telemetry};
    use ratelab::{run, ClockKind, Nanos, RunConfig, RunOptions};

    const S: u64 = 1_000_000_000;

    /// A lab told nothing yet.
    fn lab() -> App {
        let (tx, _) = crossbeam_channel::unbounded();
        App::new(tx, "scripted".into(), None, Speed::Times(1.0))
    }

    /// What a virtual run of `cfg` whose steps are `trace` tells the lab: its start, every
    /// step, a status every 50 ms of run time (with the counters), a change of rate at 30 s
    /// and a switch to the real clock at 40 s, as the engine tells them.
    fn telemetry(cfg: &RunConfig, trace: &[StepRecord]) -> Vec<Telemetry> {
        let mut told = vec![Telemetry::Started {
            cfg: cfg.clone(),
            policy: "scripted".into(),
            recording: None,
        }];
        let mut next_status = Nanos::ZERO;
        for s in trace {
            told.push(Telemetry::Step(Box::new(s.clone())));
            if s.t == Nanos(30 * S) {
                told.push(Telemetry::Changed {
                    at: s.t,
                    text: "policy → 40 Hz at t=30.00 s".into(),
                });
            }
            if s.t == Nanos(40 * S) {
                told.push(Telemetry::ClockSwitched {
                    at: s.t,
                    clock: ClockKind::Real,
                });
            }
            if s.t >= next_status {
                told.push(chapter_status(s));
                next_status = s.t.saturating_add(STATUS_EVERY);
            }
        }
        told
    }

    /// A seek back from a checkpoint shows what folding the journal from the run's start
    /// shows: before the first checkpoint, between checkpoints, on a clock switch's instant
    /// and just after it, at the end; with a rate asked for by a key and not yet seen; and
    /// the run told on after the seek shows the same. Each seek is from a lab told the whole
    /// run.
    #[test]
    fn a_seek_from_a_checkpoint_shows_what_a_fold_from_the_start_shows() {
        let cfg = RunConfig {
            clock: ClockKind::Virtual,
            duration: Nanos(60 * S),
            ..RunConfig::default()
        };
        let report = run(&cfg, Box::new(Scripted), RunOptions::new()).unwrap();
        let told = telemetry(&cfg, &report.trace);
        let ms = |ms: u64| Nanos(ms * 1_000_000);
        let key_at = told
            .iter()
            .position(|t| matches!(t, Telemetry::Step(s) if s.t == ms(25_000)))
            .unwrap();
        for at in [
            ms(1_500),
            ms(5_120),
            ms(20_000),
            ms(25_010),
            ms(31_000),
            ms(40_000),
            ms(40_020),
            ms(45_300),
            ms(59_990),
        ] {
            let (mut kept, mut none) = (lab(), lab());
            // Never due: every seek folds from the run's start, as before checkpoints.
            none.checkpoints.never = true;
            for (i, t) in told.iter().enumerate() {
                kept.on_telemetry(t.clone());
                none.on_telemetry(t.clone());
                if i == key_at {
                    // The policy's rate, asked for at 25 s (its status comes later).
                    kept.on_msg(Msg::RateUp);
                    none.on_msg(Msg::RateUp);
                }
            }
            assert!(kept.checkpoints.len() >= 4, "{}", kept.checkpoints.len());
            assert_eq!(none.checkpoints.len(), 0);
            kept.on_telemetry(Telemetry::Rewound { at });
            none.on_telemetry(Telemetry::Rewound { at });
            assert_eq!(kept.view(), none.view(), "back at {at:?}");
            assert_eq!(kept.pending_rates, none.pending_rates, "back at {at:?}");
            let from = kept.checkpoints.started_from.unwrap();
            if at < ms(3_000) {
                assert_eq!(from, 0, "back at {at:?}: no checkpoint so early");
            } else {
                assert!(from > 0, "back at {at:?}: folded from the run's start");
            }
            // Told on from `at`: the run goes on as the engine runs it again.
            for t in told
                .iter()
                .skip_while(|t| !matches!(t, Telemetry::Step(s) if s.t > at))
            {
                kept.on_telemetry(t.clone());
                none.on_telemetry(t.clone());
            }
            assert_eq!(kept.view(), none.view(), "told on from {at:?}");
        }
    }

    /// However long the journal, at most [`MAX_CHECKPOINTS`] are kept: every other goes
    /// and the spacing doubles; the one a seek starts from is the latest at or before it.
    #[test]
    fn checkpoints_thin_to_at_most_their_count_and_a_seek_starts_from_the_latest_before() {
        let state = lab().folded();
        let mut c = Checkpoints::default();
        let journal: Vec<(Nanos, Telemetry)> = (0..FIRST_EVERY * MAX_CHECKPOINTS * 8)
            .map(|i| (Nanos(i as u64 * 1_000_000), Telemetry::Error(String::new())))
            .collect();
        for len in 1..=journal.len() {
            if c.due(len) {
                c.keep(&journal[..len], state.clone());
            }
            assert!(c.len() <= MAX_CHECKPOINTS);
        }
        assert_eq!(c.every(), FIRST_EVERY * 8);
        assert!(c.len() >= MAX_CHECKPOINTS / 2, "{}", c.len());
        let spaced: Vec<usize> = c.kept.iter().map(|k| k.upto).collect();
        assert!(
            spaced.windows(2).all(|w| w[1] - w[0] == c.every()),
            "{spaced:?}"
        );
        // The latest at or before message 10 000, and those after it go.
        let (from, _) = c.start_for(10_000, Nanos(9_999_000_000)).unwrap();
        assert_eq!(from, 10_000 / c.every() * c.every());
        assert_eq!(c.kept.last().map(|k| k.upto), Some(from));
        // Before the first: none.
        assert!(c.start_for(c.every() - 1, Nanos::SECOND).is_none());
    }

    /// A checkpoint that folded a clock switch is no start for a seek to the switch's
    /// instant or before it (the switch at the instant came after it, and is not folded).
    #[test]
    fn a_seek_to_a_clock_switch_starts_before_it() {
        let state = lab().folded();
        let mut c = Checkpoints::default();
        let at = |i: usize| Nanos(i as u64 * 1_000_000);
        let mut journal: Vec<(Nanos, Telemetry)> = (0..FIRST_EVERY * 3)
            .map(|i| (at(i), Telemetry::Error(String::new())))
            .collect();
        let switch = FIRST_EVERY + FIRST_EVERY / 2;
        journal[switch].1 = Telemetry::ClockSwitched {
            at: at(switch),
            clock: ClockKind::Virtual,
        };
        for len in [FIRST_EVERY, FIRST_EVERY * 2, FIRST_EVERY * 3] {
            c.keep(&journal[..len], state.clone());
        }
        let every = FIRST_EVERY * 3;
        assert_eq!(
            c.start_for(every, at(switch)).map(|s| s.0),
            Some(FIRST_EVERY)
        );
        // Once the switch is over, the latest.
        c.keep(&journal[..FIRST_EVERY * 2], state.clone());
        c.keep(&journal[..FIRST_EVERY * 3], state);
        assert_eq!(c.start_for(every, at(switch + 1)).map(|s| s.0), Some(every));
    }

    /// A view too large to keep a few of is not kept, nor copied again for its journal; the
    /// checkpoints kept hold at most [`MAX_CHECKPOINT_BYTES`] together.
    #[test]
    fn the_checkpoints_hold_their_byte_budget_and_refuse_a_view_too_large() {
        let each = |bytes: usize| {
            let mut state = lab().folded();
            state.whole =
                vec![(0.0, 0.0, 0.0, None); bytes / std::mem::size_of::<super::GhostStep>()];
            state
        };
        let journal: Vec<(Nanos, Telemetry)> = (0..FIRST_EVERY * 16)
            .map(|i| (Nanos(i as u64 * 1_000_000), Telemetry::Error(String::new())))
            .collect();
        let mut c = Checkpoints::default();
        c.keep(
            &journal[..FIRST_EVERY],
            each(MAX_CHECKPOINT_BYTES / 4 + 1024),
        );
        assert_eq!(c.len(), 0);
        assert!(!c.due(journal.len()), "copied again");
        let mut c = Checkpoints::default();
        let fifth = each(MAX_CHECKPOINT_BYTES / 5);
        for len in 1..=journal.len() {
            if c.due(len) {
                c.keep(&journal[..len], fifth.clone());
                assert!(c.bytes <= MAX_CHECKPOINT_BYTES, "{} bytes", c.bytes);
            }
        }
        assert!((2..=4).contains(&c.len()), "{}", c.len());
    }
}
