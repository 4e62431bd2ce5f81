//! What watches a run as it goes: [`RunObserver`], one trait with a method for each thing a
//! run tells (its graph built, an actuator step's record, a node's tick under the real
//! clock, a tick as its executor ran it under the virtual clock, a line of its text log, its
//! end), each a no-op unless implemented. A recording ([`Recorded`]), `trace.csv`'s writer
//! ([`steps`] of [`crate::trace_csv`]'s observer), the command line's progress bar and any
//! step observer of the run core's ([`StepObserver`], told of its graph and steps only) are
//! run observers; a run takes any number of them ([`crate::run::RunOptions::observers`]).
//!
//! The run core calls hooks of three kinds (step observers, the real clock's tick hook, the
//! virtual scheduler's span hook); within this crate the run's observers stand behind one
//! adapter for each (`Observers`), so that neither the run core nor the scheduler knows
//! this trait, and their hook types stay theirs.

use ratelab_core::executor::{CallbackSpan, SpanHook};
use ratelab_core::metrics::Metrics;
use ratelab_core::runlog::StepRecord;
use ratelab_core::textlog::LogLine;
use ratelab_recording::Recording;
use ratelab_runtime::graph::{GraphHandles, StepObserver};
use ratelab_runtime::scheduler::{RunEnd, TickHook, TickReport};
use std::sync::{Arc, Mutex};

/// Something told about a run as it goes. Every method does nothing unless implemented.
///
/// A run calls them on its own threads: the steps on the actuator's, a real-clock tick on
/// its node's (or executor's) thread, a line on the thread that wrote it. Each observer is
/// called by one thread at a time (it is behind a lock of its own), so a method must not
/// block for long. Node ticks, spans and lines reach only an observer that says it hears
/// them ([`RunObserver::hears`]), so that an observer of steps costs a node's tick nothing;
/// one that hears lines must not write to the text log ([`ratelab_core::textlog`]) from
/// its methods (what it writes while told a line is dropped).
pub trait RunObserver: Send {
    /// What it is told besides its graph, its steps and the end (none by default): asked
    /// once, when the run starts.
    fn hears(&self) -> Hears {
        Hears::default()
    }

    /// The graph was built, before its first instant: a chance to keep handles (rates,
    /// topics) for later steps ([`StepObserver::attach`]).
    fn on_start(&mut self, _handles: &GraphHandles) {}

    /// One actuator step happened ([`StepObserver::on_step`]).
    fn on_step_record(&mut self, _rec: &StepRecord) {}

    /// Real clock: a node ticked (its run time, lateness and wall time taken).
    fn on_node_tick(&mut self, _tick: &TickReport<'_>) {}

    /// Virtual clock, when executors or compute times apply: a tick as its executor ran it
    /// (release, start, end; run time).
    fn on_span(&mut self, _span: &CallbackSpan) {}

    /// A line of the run's text log: what a node's code wrote, or a notice of ratelab's own
    /// (no node). Told in a run started by `RunSpec::start`, which takes the process's text
    /// log for its run ([`crate::run::run`] alone does not).
    fn on_line(&mut self, _line: &LogLine) {}

    /// The run has ended, summarized (`metrics`) and how (`end`), its threads joined.
    fn on_end(&mut self, _metrics: &Metrics, _end: &RunEnd) {}
}

/// What a run observer is told besides its graph, its steps and the end
/// ([`RunObserver::hears`]).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Hears {
    /// Real clock: every node tick ([`RunObserver::on_node_tick`]).
    pub node_ticks: bool,
    /// Virtual clock: every tick as its executor ran it ([`RunObserver::on_span`]).
    pub spans: bool,
    /// Every line of the text log ([`RunObserver::on_line`]).
    pub lines: bool,
}

/// Every step observer of the run core's is a run observer told of its graph and its steps.
impl<T: StepObserver> RunObserver for T {
    fn on_start(&mut self, handles: &GraphHandles) {
        StepObserver::attach(self, handles);
    }

    fn on_step_record(&mut self, rec: &StepRecord) {
        StepObserver::on_step(self, rec);
    }
}

/// A boxed step observer (what `Recording::observer` and `trace.csv`'s writers give) as a
/// run observer ([`steps`]).
pub struct Steps(pub Box<dyn StepObserver>);

impl StepObserver for Steps {
    fn attach(&mut self, handles: &GraphHandles) {
        self.0.attach(handles);
    }

    fn on_step(&mut self, rec: &StepRecord) {
        self.0.on_step(rec);
    }
}

/// `observer` (a boxed step observer) as a run observer, told of its graph and steps.
pub fn steps(observer: Box<dyn StepObserver>) -> Box<dyn RunObserver> {
    Box::new(Steps(observer))
}

/// A recording as a run observer, as `ratelab run` attaches it: every step (the recording's
/// step observer), every real-clock tick (its lateness, and its span when the run measures
/// its executors: [`Recording::real_tick`]), every virtual-clock span when the run measures
/// its executors ([`Recording::span_hook`]), every line of the text log (`log/<node>`).
/// It does not finish the recording: its opener does, after the run
/// (`crate::outputs::finish_recording`).
pub struct Recorded {
    recording: Recording,
    steps: Box<dyn StepObserver>,
    spans: Option<SpanHook>,
}

impl Recorded {
    /// Attach `recording` (a clone of it is kept: it is a shared handle).
    pub fn new(recording: &Recording) -> Self {
        Self {
            recording: recording.clone(),
            steps: recording.observer(),
            spans: recording.span_hook(),
        }
    }
}

impl RunObserver for Recorded {
    fn hears(&self) -> Hears {
        Hears {
            node_ticks: true,
            spans: self.spans.is_some(),
            lines: true,
        }
    }

    fn on_start(&mut self, handles: &GraphHandles) {
        self.steps.attach(handles);
    }

    fn on_step_record(&mut self, rec: &StepRecord) {
        self.steps.on_step(rec);
    }

    fn on_node_tick(&mut self, tick: &TickReport<'_>) {
        self.recording.real_tick(tick);
    }

    fn on_span(&mut self, span: &CallbackSpan) {
        if let Some(hook) = &self.spans {
            hook(span);
        }
    }

    fn on_line(&mut self, line: &LogLine) {
        self.recording.log_line(line);
    }
}

/// A run's observers, in the order given, each behind a lock of its own, shared by the
/// adapters the run core calls ([`Observers::step_observers`], [`Observers::span_hook`],
/// [`Observers::tick_hook`]) and by the text log's sink. Cheap to clone.
#[derive(Clone)]
pub(crate) struct Observers(Arc<Vec<Slot>>);

/// One observer of a run, and what it hears.
type Slot = (Hears, Mutex<Box<dyn RunObserver>>);

impl Observers {
    /// `list`, told in this order.
    pub(crate) fn new(list: Vec<Box<dyn RunObserver>>) -> Self {
        Self(Arc::new(
            list.into_iter()
                .map(|o| (o.hears(), Mutex::new(o)))
                .collect(),
        ))
    }

    /// Some observer hears what `what` picks.
    fn any(&self, what: fn(&Hears) -> bool) -> bool {
        self.0.iter().any(|(h, _)| what(h))
    }

    /// Call `f` with each observer that hears what `what` picks, in order, each locked
    /// meanwhile.
    fn each(&self, what: fn(&Hears) -> bool, mut f: impl FnMut(&mut Box<dyn RunObserver>)) {
        for (_, o) in self.0.iter().filter(|(h, _)| what(h)) {
            let mut guard = o.lock().unwrap_or_else(std::sync::PoisonError::into_inner);
            f(&mut guard);
        }
    }

    /// For the run core's graph: one step observer telling each of them (none without
    /// observers).
    pub(crate) fn step_observers(&self) -> Vec<Box<dyn StepObserver>> {
        if self.0.is_empty() {
            return Vec::new();
        }
        vec![Box::new(StepsOf(self.clone()))]
    }

    /// For the virtual scheduler: a hook telling each observer that hears spans of every
    /// span (none when none does).
    pub(crate) fn span_hook(&self) -> Option<SpanHook> {
        let spans = |h: &Hears| h.spans;
        if !self.any(spans) {
            return None;
        }
        let me = self.clone();
        let hook: SpanHook =
            Arc::new(move |span: &CallbackSpan| me.each(spans, |o| o.on_span(span)));
        Some(hook)
    }

    /// For the real clock: a hook telling each observer that hears node ticks of every one
    /// (none when none does).
    pub(crate) fn tick_hook(&self) -> Option<TickHook> {
        let ticks = |h: &Hears| h.node_ticks;
        if !self.any(ticks) {
            return None;
        }
        let me = self.clone();
        let hook: TickHook =
            Arc::new(move |tick: &TickReport<'_>| me.each(ticks, |o| o.on_node_tick(tick)));
        Some(hook)
    }

    /// Tell each observer that hears lines of a line of the text log; what they write
    /// meanwhile is dropped (it would come back here).
    pub(crate) fn line(&self, line: &LogLine) {
        ratelab_core::textlog::muted(|| self.each(|h| h.lines, |o| o.on_line(line)));
    }

    /// Tell each of them the run has ended.
    pub(crate) fn end(&self, metrics: &Metrics, end: &RunEnd) {
        self.each(|_| true, |o| o.on_end(metrics, end));
    }
}

/// The run's observers as the one step observer the run core's graph is given.
struct StepsOf(Observers);

impl StepObserver for StepsOf {
    fn attach(&mut self, handles: &GraphHandles) {
        self.0.each(|_| true, |o| o.on_start(handles));
    }

    fn on_step(&mut self, rec: &StepRecord) {
        self.0.each(|_| true, |o| o.on_step_record(rec));
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Told of steps, and does nothing with them.
    struct Nothing;

    impl StepObserver for Nothing {
        fn on_step(&mut self, _rec: &StepRecord) {}
    }

    /// Counts what it is told.
    struct Count(Arc<Mutex<Vec<&'static str>>>);

    impl RunObserver for Count {
        fn hears(&self) -> Hears {
            Hears {
                spans: true,
                ..Hears::default()
            }
        }

        fn on_span(&mut self, _span: &CallbackSpan) {
            self.0.lock().unwrap().push("span");
        }
    }

    #[test]
    fn the_hooks_tell_every_observer_in_order_and_none_exist_without_observers() {
        let none = Observers::new(Vec::new());
        assert!(none.step_observers().is_empty());
        assert!(none.span_hook().is_none() && none.tick_hook().is_none());
        let told = Arc::new(Mutex::new(Vec::new()));
        let count = || -> Box<dyn RunObserver> { Box::new(Count(told.clone())) };
        // An observer of steps alone adds no hook.
        let steps_only = Observers::new(vec![Box::new(Steps(Box::new(Nothing)))]);
        assert!(steps_only.span_hook().is_none() && steps_only.tick_hook().is_none());
        let all = Observers::new(vec![count(), Box::new(Nothing), count()]);
        assert_eq!(all.step_observers().len(), 1);
        let hook = all.span_hook().expect("a span hook");
        let zero = ratelab_core::time::Nanos::ZERO;
        hook(&CallbackSpan {
            node: 0,
            release: zero,
            start: zero,
            end: zero,
        });
        assert_eq!(*told.lock().unwrap(), ["span", "span"]);
    }
}
