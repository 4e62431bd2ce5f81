//! The virtual clock across processes: one order of events, replayed in every process.
//!
//! Every process (and the launcher) runs the same
//! [`VirtualScheduler`](ratelab_runtime::scheduler::VirtualScheduler) over the whole graph,
//! with the whole graph's executors, so all of them know the run's one order of events (a
//! tick's start, and when the tick computes, the instant its held outputs go out:
//! [`Event`]; by time, then the executors' order) and number them 0, 1, …. A process runs
//! an event of its own node when its turn comes and says so ([`Ticked`], on
//! `ratelab/<graph>/@ticked/<process>`, with the seq it sent, the compute time its node
//! drew at a start, and whether the node stopped the graph or failed); at another process's
//! event it waits for that report ([`check_tick_report`]) and schedules the tick's end by
//! the compute time reported. So events run one after another in the in-process order, a
//! tick sees exactly the input messages it would see in one process (it waits for the seq
//! the report names), and every process stops at the same event: the same seed gives
//! byte-identical metrics in one process and in several, executors' figures included.
//!
//! What a process must know before it runs an event is every report before it: the compute
//! times it schedules by, the seqs its inputs wait for, and whether the run stopped. The
//! reports go through the launcher, the router of the launch's star: a process sends the
//! reports of its consecutive events together, in one message, when it must next wait
//! ([`wire::encode_reports`]), to the launcher alone; the launcher follows them in the
//! run's order on the thread that receives them and, when an event is next, hands its
//! node's process every report it has not had, in one message on its own key
//! ([`crate::Keys::relayed`], [`subscribe_relayed`]); at the end it hands every process the
//! rest, and each takes them before it reports ([`wire::ToProcess::Events`]). An instant
//! in which P processes each run an event costs P messages in and P out, where sending
//! each report to every other process cost P (P − 1). A process runs its events on the
//! thread that receives what they wait for (Zenoh's receive callback; the process's
//! `stepper`): between two events of different processes there is one report message to
//! the launcher and one from it, which the launcher puts from the thread that received what
//! made it due (its outbox's direct lane; the outbox's own thread when something waits
//! there: Zenoh's one thread must never wait to send, `launcher/outbox.rs`). The launcher
//! is also the time authority: it lets the processes run up to a horizon
//! ([`wire::ToProcess::Horizon`]), [`horizon_periods`] periods of the fastest node ahead of
//! the events it has seen reported (8 when a lab paces the run; up to 256 otherwise), and
//! ends the run early by not moving it on (a Ctrl-C).
//!
//! In a launch linked directly ([`crate::open_linked_peer`]) the processes are linked to each
//! other, and a process's message of reports goes to every other process
//! ([`subscribe_reports`]): between two events of different processes there is one message
//! over their own link; between two processes the reports of ticks that published a
//! crossing sample ride on the last such sample instead ([`reports_ride_on_samples`]), so a
//! hop is one message. The launcher hears the same reports in batches
//! ([`subscribe_progress`], [`follow_at`]: once a process's run passes the time the
//! horizon names, and always before it waits for the horizon), follows them as above, and
//! moves the horizon, but hands nothing on until the end.
//! Following the reports, it knows the end (a stop, a failure, a process gone) and the
//! last seq of every topic before the processes report. Linked directly it knows them as
//! far as the batches have come: a run it ends early (a process gone, Ctrl-C, a process
//! that does not answer) ends where the furthest report it holds says, as the others may
//! have run on reports it never had.
//!
//! This is conservative parallel discrete-event simulation in the sense of Chandy and
//! Misra ("Distributed simulation: a case study in design and verification of distributed
//! programs", IEEE TSE, 1979), with the whole schedule known to every process in advance
//! (fixed rates; a compute time is known once its tick has started, before its end), so no
//! null messages are needed: the reports are the messages.

use super::wire::{self, Ticked};
use super::{DistError, Keys};
use ratelab_core::time::Nanos;
use ratelab_runtime::graph::spec::GraphSpec;
use ratelab_runtime::graph::NodeId;
use ratelab_runtime::scheduler::Event;
use std::collections::BTreeMap;
use zenoh::Wait;

/// How far ahead of the ticks it has seen reported the launcher lets the processes run, in
/// periods of the graph's fastest node (the horizon is moved on when half of it is used),
/// when it paces the run (a lab follows it), and at least ([`horizon_periods`]).
pub const HORIZON_PERIODS: u64 = 8;

/// How far ahead the horizon reaches at most, in periods of the fastest node, when nothing
/// paces the run: each move of the horizon wakes the launcher's main thread, sends every
/// process a message and, linked directly, has every process send the launcher its reports
/// ([`follow_at`]). At 8 periods the moves cost an instant of the chapter's launch about a
/// tenth of its time; from 64 to 256, with the reports sent once a move, the launcher's CPU
/// fell by 40% (BENCHMARKS.md, issue 76 item 4).
pub const HORIZON_PERIODS_UNPACED: u64 = 256;

/// The periods of the fastest node the horizon reaches ahead for the run `order` follows:
/// [`HORIZON_PERIODS`] when `paced`; else the most up to [`HORIZON_PERIODS_UNPACED`] (halving
/// from it) whose ticks, two events each, fill at most a quarter of [`MAX_AHEAD`], so that
/// what a process or the launcher keeps ahead of its turn stays far within it whatever the
/// graph's size.
pub fn horizon_periods(order: &ratelab_runtime::runcore::Follower, paced: bool) -> u64 {
    if paced {
        return HORIZON_PERIODS;
    }
    let shortest = order.shortest_period();
    let mut periods = HORIZON_PERIODS_UNPACED;
    while periods > HORIZON_PERIODS {
        let span = Nanos(shortest.0.saturating_mul(periods));
        if order.ticks_within(span).saturating_mul(2) <= (MAX_AHEAD / 4) as u64 {
            break;
        }
        periods /= 2;
    }
    periods
}

/// In a launch linked directly, the run time from which the launcher wants the tick reports
/// a process keeps for it, for a horizon at `horizon_ns` reaching `lookahead_ns` ahead: the
/// launcher moves the horizon on once its view of the run passes `horizon_ns −
/// lookahead_ns / 2` ([`horizon_low`]), so that is when it must hear from every process. A
/// process sends what it has kept once its run passes that time (it has then made every
/// report the launcher needs from it to get there), and otherwise only before it waits for
/// the horizon, before a tick that may be long, at its run's end, or after
/// [`FOLLOWED_MAX_AGE`]. The other
/// processes hear every report as it is made ([`Keys::ticked`], or on the sample it
/// published, [`reports_ride_on_samples`]): only the launcher's view, which moves the
/// horizon and counts the run, comes in batches, about one a process for each move of the
/// horizon. Every message the launcher takes wakes it: following every report cost it 77 µs
/// of CPU an instant of the chapter's launch, batches of [`FOLLOWED_BATCH`] 7–8 µs, and one
/// batch a process a move of a 256-period horizon about 4 µs (BENCHMARKS.md, issue 76 item
/// 4).
pub fn follow_at(horizon_ns: u64, lookahead_ns: u64) -> u64 {
    horizon_ns.saturating_sub(lookahead_ns / 2)
}

/// Whether the launcher moves the horizon at `horizon_ns` (reaching `lookahead_ns` ahead)
/// on, its view of the run being at an event at run time `at_ns`: once less than half the
/// lookahead is left, that is once `at_ns` is past [`follow_at`] (the time the processes
/// send their reports from).
pub fn horizon_low(horizon_ns: u64, at_ns: u64, lookahead_ns: u64) -> bool {
    at_ns.saturating_add(lookahead_ns / 2) > horizon_ns
}

/// In a launch linked directly whose launcher names no run time to send from
/// ([`follow_at`]: a launcher of an earlier ratelab, as a process on another host may
/// meet), the most of its own tick reports a process keeps before it sends them to
/// the launcher to follow ([`Keys::progress`]); it sends what it has kept before it waits
/// for the horizon, and at its run's end, whatever the count.
pub const FOLLOWED_BATCH: usize = 32;

/// In a launch linked directly, how long a process keeps a report for the launcher at most
/// (sent when the process next looks: at once while it runs, within 100 ms when it waits
/// on a process that is gone), so that the launcher's view of a run that stalls catches up
/// with the processes'. A process also sends what it holds before a tick that may be long,
/// and before it waits for the horizon.
pub const FOLLOWED_MAX_AGE: std::time::Duration = std::time::Duration::from_millis(50);

/// Whether a process's tick reports ride on its samples in a run of `spec` under the
/// virtual clock (`direct`: linked directly): the reports of the ticks that published
/// samples crossing to another process go as the last such sample's attachment, not on
/// their own key ([`Keys::ticked`]), so a hop costs one message where a sample and its report
/// made two. (Samples a Zenoh callback holds back past its send budget go later, from the
/// main thread, with their reports on their own key.) Whoever may read a topic may then read
/// the reports its samples carry: the ticks' compute times and a failure's text, which the
/// run's summary prints anyway. Only where the one process that reads a sample is every
/// process that needs the reports: a launch of two processes linked directly (in a star the
/// launcher hands the reports on; with three or more, a sample reaches one process of
/// several). A process reading a topic takes the reports its sample carries only from the
/// process that publishes the topic ([`decode_carried`]; the access rules let no other put
/// on its key).
pub fn reports_ride_on_samples(spec: &GraphSpec, direct: bool) -> bool {
    direct && spec.placement().len() == 2
}

/// The tick reports a sample carries ([`reports_ride_on_samples`]), as its attachment
/// `bytes` says, from process `from`, the process that publishes the sample's topic: `None`
/// for bytes that are not a message of reports, or one with a report of another process's.
pub fn decode_carried(bytes: &[u8], from: &str) -> Option<Vec<Ticked>> {
    let ms = wire::decode_reports(bytes).ok()?;
    ms.iter().all(|m| m.process == from).then_some(ms)
}

/// The most reports of other processes' ticks one process (or the launcher) keeps ahead of
/// their turn (each process runs at most to the horizon, so a run holds at most the other
/// processes' ticks of one horizon, [`horizon_periods`]).
pub const MAX_AHEAD: usize = 65_536;

/// The other processes' tick reports, handed out in the run's order.
#[derive(Debug, Default)]
pub struct TickInbox {
    ahead: BTreeMap<u64, Ticked>,
    /// Every index below this was taken or given up.
    next: u64,
}

impl TickInbox {
    /// An empty inbox, at tick 0.
    pub fn new() -> Self {
        Self::default()
    }

    /// Keep `m` until its turn. Ignored: a report for a tick already taken, a second report
    /// for one tick (the first stands), or one whose node is not in the graph or not in the
    /// process the report names (the access control lets only that process's identity put
    /// on its key, [`crate::access`]; a holder of its credentials could still
    /// send a well-formed report that disturbs the run).
    ///
    /// # Errors
    /// [`DistError::Peer`] when [`MAX_AHEAD`] reports are already waiting.
    pub fn accept(&mut self, m: Ticked, spec: &GraphSpec) -> Result<(), DistError> {
        let genuine = m.node < spec.nodes.len() && spec.process_name(NodeId(m.node)) == m.process;
        if !genuine || m.index < self.next || self.ahead.contains_key(&m.index) {
            return Ok(());
        }
        if self.ahead.len() >= MAX_AHEAD {
            return Err(DistError::Peer(format!(
                "more than {MAX_AHEAD} tick reports arrived ahead of their turn"
            )));
        }
        self.ahead.insert(m.index, m);
        Ok(())
    }

    /// The latest run time of a report kept ahead of its turn, ns (`None`: none is).
    pub fn newest_ns(&self) -> Option<u64> {
        self.ahead.values().map(|m| m.t_ns).max()
    }

    /// The report of tick `index`, if it is in (the reports before it are then given up).
    pub fn take(&mut self, index: u64) -> Option<Ticked> {
        let m = self.ahead.remove(&index)?;
        self.next = index + 1;
        // Those before it given up where they are, at the map's front: splitting the map
        // there moved every report kept after it into a new map, at every take (the
        // launcher follows a batch of hundreds at a time, [`follow_at`]).
        while let Some(first) = self.ahead.first_entry() {
            if *first.key() >= self.next {
                break;
            }
            first.remove();
        }
        Some(m)
    }
}

/// Check another process's report `m` of event `index` against the event this process
/// expects there (`event`: every process replays the same order), and return the compute
/// time it reports for a start.
///
/// # Errors
/// One line when the report is for another node, another run time, the other kind of
/// event, or claims a compute time over [`ratelab_core::executor::MAX_COMPUTE`] (or any at the
/// end of a compute time): the processes are out of step, and the run cannot go on.
pub fn check_tick_report(
    m: &Ticked,
    index: u64,
    event: Event,
    spec: &GraphSpec,
) -> Result<Nanos, String> {
    let (node, at) = event.node_at();
    let publish = matches!(event, Event::Publish { .. });
    let name = |i: usize| spec.nodes.get(i).map_or("?", |n| n.name.as_str());
    let what = |p: bool| if p { "the outputs" } else { "the tick" };
    if m.node != node || m.t_ns != at.0 || m.publish != publish {
        return Err(format!(
            "process '{}' is out of step at event {index}: it reported {} of {} at {} ns, where this run has {} of {} at {} ns",
            m.process,
            what(m.publish),
            name(m.node),
            m.t_ns,
            what(publish),
            name(node),
            at.0
        ));
    }
    let compute = Nanos(m.compute_ns);
    if compute > ratelab_core::executor::MAX_COMPUTE || (publish && compute.0 > 0) {
        return Err(format!(
            "process '{}' reported a compute time of {} ns for {} at event {index} (at most {} ns at a start, none when outputs go out)",
            m.process,
            m.compute_ns,
            name(node),
            ratelab_core::executor::MAX_COMPUTE.0
        ));
    }
    Ok(compute)
}

/// Decode a message of tick reports that came on `key` (`ratelab/<graph>/@ticked/<process>`,
/// [`wire::decode_reports`]): `None` for bytes that are not one, for a message with a report
/// whose process is not the key's, and for this process's own (`own`: Zenoh hands a session
/// its own puts too).
pub fn decode_report(key: &str, bytes: &[u8], own: Option<&str>) -> Option<Vec<Ticked>> {
    let from = key.rsplit('/').next()?;
    if own == Some(from) {
        return None;
    }
    let ms = wire::decode_reports(bytes).ok()?;
    ms.iter().all(|m| m.process == from).then_some(ms)
}

/// Subscribe to the tick reports ([`Keys::ticked`]) of every process of `processes` but
/// `own` (`None` for the launcher, which takes them all), as [`decode_report`] lets them
/// through: each message's reports go to `take`, on Zenoh's receive thread.
///
/// One subscriber per process, each on its process's key, not one on `@ticked/*`: Zenoh
/// keeps the routes of a key that has subscribers and no wildcard, and routes a sample on
/// any other key by searching its key tree, which grows with the graph's topics
/// (`BENCHMARKS.md`, "Graphs of any size").
///
/// # Errors
/// [`DistError::Zenoh`] when a subscriber cannot be declared.
pub fn subscribe_reports(
    session: &zenoh::Session,
    keys: &Keys,
    processes: &[String],
    own: Option<&str>,
    take: impl Fn(Vec<Ticked>) + Send + Sync + 'static,
) -> Result<Vec<zenoh::pubsub::Subscriber<()>>, DistError> {
    subscribe_reports_on(session, |p| keys.ticked(p), processes, own, take)
}

/// The launcher of a launch linked directly: [`subscribe_reports`] on the batches each
/// process sends it to follow ([`Keys::progress`]).
///
/// # Errors
/// [`DistError::Zenoh`] when a subscriber cannot be declared.
pub fn subscribe_progress(
    session: &zenoh::Session,
    keys: &Keys,
    processes: &[String],
    take: impl Fn(Vec<Ticked>) + Send + Sync + 'static,
) -> Result<Vec<zenoh::pubsub::Subscriber<()>>, DistError> {
    subscribe_reports_on(session, |p| keys.progress(p), processes, None, take)
}

/// [`subscribe_reports`] on the key `key_of` gives each process (its last chunk the
/// process's name, as [`decode_report`] checks).
fn subscribe_reports_on(
    session: &zenoh::Session,
    key_of: impl Fn(&str) -> String,
    processes: &[String],
    own: Option<&str>,
    take: impl Fn(Vec<Ticked>) + Send + Sync + 'static,
) -> Result<Vec<zenoh::pubsub::Subscriber<()>>, DistError> {
    let take = std::sync::Arc::new(take);
    let mut subs = Vec::with_capacity(processes.len());
    for p in processes.iter().filter(|p| Some(p.as_str()) != own) {
        let (take, own) = (take.clone(), own.map(str::to_string));
        let sub = session
            .declare_subscriber(key_of(p))
            .callback(move |s| {
                let bytes = s.payload().to_bytes();
                if let Some(ms) = decode_report(s.key_expr().as_str(), &bytes, own.as_deref()) {
                    take(ms);
                }
            })
            .wait()?;
        subs.push(sub);
    }
    Ok(subs)
}

/// Decode a message of tick reports the launcher handed process `own` ([`Keys::relayed`],
/// [`wire::decode_relayed`]): `None` for bytes that are not one; `own`'s own reports are left
/// out (it ran those events). Only the launcher's router may put on the key ([`crate::access`]).
pub fn decode_relayed(bytes: &[u8], own: &str) -> Option<Vec<Ticked>> {
    let mut ms = wire::decode_relayed(bytes).ok()?;
    ms.retain(|m| m.process != own);
    Some(ms)
}

/// Subscribe process `own` to the tick reports the launcher hands it ([`Keys::relayed`]),
/// as [`decode_relayed`] lets them through: each message's reports go to `take`, on
/// Zenoh's receive thread. Declared before the process says it is ready: Zenoh sends a
/// declaration ahead of the messages after it on the same link, so the launcher, which
/// starts the run once every process is ready, never hands on a report before its
/// subscription is in place.
///
/// # Errors
/// [`DistError::Zenoh`] when the subscriber cannot be declared.
pub fn subscribe_relayed(
    session: &zenoh::Session,
    keys: &Keys,
    own: &str,
    take: impl Fn(Vec<Ticked>) + Send + Sync + 'static,
) -> Result<zenoh::pubsub::Subscriber<()>, DistError> {
    let own = own.to_string();
    let sub = session
        .declare_subscriber(keys.relayed(&own))
        .callback(move |s| {
            if let Some(ms) = decode_relayed(&s.payload().to_bytes(), &own) {
                if !ms.is_empty() {
                    take(ms);
                }
            }
        })
        .wait()?;
    Ok(sub)
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;
    use ratelab_runtime::graph::spec::DEFAULT_GRAPH_TOML;

    /// Process `process`'s report of event `index`, a tick of `node` that published nothing
    /// (also the relay's tests').
    pub(crate) fn report(process: &str, index: u64, node: usize) -> Ticked {
        Ticked {
            process: process.into(),
            index,
            node,
            t_ns: 0,
            stop: false,
            published: Vec::new(),
            failed: None,
            publish: false,
            compute_ns: 0,
        }
    }

    /// The reports ride on the samples only between two processes linked directly, and a
    /// process takes the reports a sample carries only when every one is its publisher's.
    #[test]
    fn reports_ride_on_samples_only_between_two_processes_linked_directly() {
        use ratelab_runtime::graph::synthetic::graph_toml;
        let chapter = GraphSpec::chapter();
        assert_eq!(chapter.placement().len(), 2);
        assert!(reports_ride_on_samples(&chapter, true));
        assert!(!reports_ride_on_samples(&chapter, false), "a star");
        let three = GraphSpec::parse(&graph_toml(12, 3), "three").unwrap();
        assert_eq!(three.placement().len(), 3);
        assert!(!reports_ride_on_samples(&three, true));
        let bytes = wire::encode_reports(&[report("robot", 0, 0), report("robot", 1, 2)]);
        let carried = decode_carried(&bytes, "robot").expect("the publisher's reports");
        assert_eq!(carried.len(), 2);
        assert_eq!(
            decode_carried(&bytes, "policy"),
            None,
            "not the publisher's"
        );
        let mixed = wire::encode_reports(&[report("robot", 0, 0), report("policy", 1, 1)]);
        assert_eq!(
            decode_carried(&mixed, "robot"),
            None,
            "one not the publisher's"
        );
        assert_eq!(decode_carried(b"not reports", "robot"), None);
    }

    /// The launcher, linked directly, ends a run whose process is gone where the furthest
    /// of the others got: the latest run time among the reports kept ahead of their turn.
    #[test]
    fn the_newest_report_kept_ahead_is_the_furthest_a_process_got() {
        let spec = GraphSpec::chapter();
        let mut inbox = TickInbox::new();
        assert_eq!(inbox.newest_ns(), None);
        let sensor = spec.node_id("sensor").unwrap().0;
        for (index, t_ns) in [(5, 100), (9, 300), (7, 200)] {
            let m = Ticked {
                t_ns,
                ..report(&spec.process_of(NodeId(sensor)), index, sensor)
            };
            inbox.accept(m, &spec).unwrap();
        }
        assert_eq!(inbox.newest_ns(), Some(300));
        // Taken in turn, a report is no longer ahead.
        inbox.take(9).unwrap();
        assert_eq!(inbox.newest_ns(), None);
    }

    /// The processes send the launcher their reports from the last run time at which it
    /// does not yet move the horizon on: past it, it does, for even and odd lookaheads and
    /// horizons at or near the run's start.
    #[test]
    fn the_processes_send_from_where_the_launcher_moves_the_horizon_on() {
        for lookahead in [1, 2, 7, 8, 20_000_000, 5_120_000_001] {
            for horizon in [0, 1, lookahead / 2, lookahead, 3 * lookahead + 5] {
                let at = follow_at(horizon, lookahead);
                assert!(at <= horizon, "{lookahead} {horizon}");
                if horizon >= lookahead / 2 {
                    assert!(
                        !horizon_low(horizon, at, lookahead),
                        "{lookahead} {horizon}"
                    );
                }
                assert!(
                    horizon_low(horizon, at + 1, lookahead),
                    "{lookahead} {horizon}"
                );
            }
        }
    }

    /// The horizon reaches 256 periods ahead for the chapter's graph, 8 when paced, and
    /// fewer for a graph whose ticks in 256 periods would fill more than a quarter of what a
    /// process keeps ahead ([`MAX_AHEAD`]), never fewer than 8.
    #[test]
    fn the_horizon_reaches_as_far_as_the_graph_s_size_allows() {
        use ratelab_runtime::config::RunConfig;
        use ratelab_runtime::graph::synthetic::graph_toml;
        use ratelab_runtime::runcore::Follower;
        let periods = |toml: &str, paced: bool| {
            let cfg = RunConfig {
                graph: GraphSpec::parse(toml, "t").expect("a graph"),
                ..RunConfig::default()
            };
            let order = Follower::new(&cfg).expect("its rates");
            let p = horizon_periods(&order, paced);
            let span = Nanos(order.shortest_period().0 * p);
            (p, order.ticks_within(span))
        };
        assert_eq!(
            periods(DEFAULT_GRAPH_TOML, false).0,
            HORIZON_PERIODS_UNPACED
        );
        assert_eq!(periods(DEFAULT_GRAPH_TOML, true).0, HORIZON_PERIODS);
        // The chapter's three nodes at 50 Hz: 257 ticks each in 256 periods.
        assert_eq!(periods(DEFAULT_GRAPH_TOML, false).1, 3 * 257);
        for nodes in [1_000, 10_000] {
            let (p, ticks) = periods(&graph_toml(nodes, 2), false);
            assert!(p < HORIZON_PERIODS_UNPACED, "{nodes} nodes: {p}");
            assert!(p >= HORIZON_PERIODS, "{nodes} nodes: {p}");
            assert!(
                p == HORIZON_PERIODS || ticks * 2 <= (MAX_AHEAD / 4) as u64,
                "{nodes} nodes: {p} periods, {ticks} ticks"
            );
        }
    }

    #[test]
    fn a_report_of_another_event_or_an_impossible_compute_time_is_out_of_step() {
        let spec = GraphSpec::parse(DEFAULT_GRAPH_TOML, "t").expect("the chapter's graph");
        let policy = spec.chain.unwrap().policy.0;
        let start = Event::Start {
            node: policy,
            at: Nanos(20_000_000),
        };
        let mut m = report("policy", 5, policy);
        m.t_ns = 20_000_000;
        m.compute_ns = 30_000_000;
        assert_eq!(
            check_tick_report(&m, 5, start, &spec),
            Ok(Nanos(30_000_000))
        );
        // Another node, another time, the other kind of event.
        let mut other = m.clone();
        other.node = spec.chain.unwrap().sensor.0;
        let e = check_tick_report(&other, 5, start, &spec).unwrap_err();
        assert!(
            e.contains("out of step at event 5") && e.contains("the tick of sensor"),
            "{e}"
        );
        other = m.clone();
        other.t_ns += 1;
        assert!(check_tick_report(&other, 5, start, &spec).is_err());
        other = m.clone();
        other.publish = true;
        let e = check_tick_report(&other, 5, start, &spec).unwrap_err();
        assert!(e.contains("the outputs of policy"), "{e}");
        // A compute time no node may declare, or one claimed when outputs go out.
        other = m.clone();
        other.compute_ns = ratelab_core::executor::MAX_COMPUTE.0 + 1;
        assert!(check_tick_report(&other, 5, start, &spec).is_err());
        let publish = Event::Publish {
            node: policy,
            at: Nanos(20_000_000),
        };
        other = m.clone();
        other.publish = true;
        assert!(check_tick_report(&other, 5, publish, &spec).is_err());
        other.compute_ns = 0;
        assert_eq!(
            check_tick_report(&other, 5, publish, &spec),
            Ok(Nanos::ZERO)
        );
    }

    #[test]
    fn reports_are_handed_out_in_the_run_s_order_whatever_order_they_come_in() {
        let spec = GraphSpec::parse(DEFAULT_GRAPH_TOML, "t").expect("the chapter's graph");
        let policy = spec.chain.unwrap().policy.0;
        let sensor = spec.chain.unwrap().sensor.0;
        let mut inbox = TickInbox::new();
        inbox.accept(report("policy", 4, policy), &spec).unwrap();
        inbox.accept(report("robot", 1, sensor), &spec).unwrap();
        assert_eq!(inbox.take(0), None, "tick 0 has not come");
        assert_eq!(inbox.take(1).map(|m| m.index), Some(1));
        assert_eq!(inbox.take(4).map(|m| m.index), Some(4));
        // Late and repeated reports, and ones for ticks given up, are ignored.
        inbox.accept(report("robot", 2, sensor), &spec).unwrap();
        inbox.accept(report("robot", 4, sensor), &spec).unwrap();
        assert_eq!(inbox.take(2), None);
        assert!(inbox.ahead.is_empty());
        // Taking a tick gives up those kept before it, and keeps those after it.
        for i in [5, 6, 8] {
            inbox.accept(report("robot", i, sensor), &spec).unwrap();
        }
        assert_eq!(inbox.take(6).map(|m| m.index), Some(6));
        assert_eq!(inbox.ahead.keys().copied().collect::<Vec<_>>(), [8]);
        assert_eq!(inbox.take(5), None, "given up");
        assert_eq!(inbox.take(8).map(|m| m.index), Some(8));
    }

    #[test]
    fn a_report_for_a_node_its_sender_does_not_hold_is_ignored() {
        let spec = GraphSpec::parse(DEFAULT_GRAPH_TOML, "t").expect("the chapter's graph");
        let mut inbox = TickInbox::new();
        // The policy runs in 'policy', not in 'robot'; node 99 does not exist.
        inbox
            .accept(report("robot", 0, spec.chain.unwrap().policy.0), &spec)
            .unwrap();
        inbox.accept(report("policy", 1, 99), &spec).unwrap();
        assert_eq!(inbox.take(0), None);
        assert_eq!(inbox.take(1), None);
        // A second report for one tick does not replace the first.
        let mut first = report("policy", 2, spec.chain.unwrap().policy.0);
        first.published = vec![(1, 7)];
        inbox.accept(first.clone(), &spec).unwrap();
        inbox
            .accept(report("policy", 2, spec.chain.unwrap().policy.0), &spec)
            .unwrap();
        assert_eq!(inbox.take(2), Some(first));
    }

    #[test]
    fn a_report_counts_only_from_its_own_process_s_key_and_never_one_s_own() {
        let bytes = wire::encode_reports(&[report("policy", 3, 1), report("policy", 4, 1)]);
        let key = |p: &str| format!("ratelab/cartpole/@ticked/{p}");
        let got = decode_report(&key("policy"), &bytes, Some("robot")).unwrap();
        assert_eq!(got, vec![report("policy", 3, 1), report("policy", 4, 1)]);
        assert!(decode_report(&key("policy"), &bytes, None).is_some());
        assert_eq!(decode_report(&key("policy"), &bytes, Some("policy")), None);
        assert_eq!(decode_report(&key("robot"), &bytes, Some("x")), None);
        assert_eq!(decode_report(&key("policy"), b"\xff{", None), None);
        // One report of another process refuses the whole message.
        let mixed = wire::encode_reports(&[report("policy", 3, 1), report("robot", 4, 0)]);
        assert_eq!(decode_report(&key("policy"), &mixed, None), None);
        // Exactly: a byte after its end, a message over the bound, none or too many
        // reports are refused.
        let mut longer = bytes.clone();
        longer.push(0);
        assert_eq!(decode_report(&key("policy"), &longer, None), None);
        let mut failed = report("policy", 3, 1);
        failed.failed = Some("x".repeat(wire::MAX_TICKS_PER_MESSAGE * wire::MAX_TICK_BYTES));
        let over = wire::encode_reports(std::slice::from_ref(&failed));
        assert_eq!(decode_report(&key("policy"), &over, None), None);
        assert_eq!(
            decode_report(&key("policy"), &wire::encode_reports(&[]), None),
            None
        );
        let many = vec![report("policy", 3, 1); wire::MAX_TICKS_PER_MESSAGE + 1];
        assert_eq!(
            decode_report(&key("policy"), &wire::encode_reports(&many), None),
            None
        );
        // Its text arrives printable.
        failed.failed = Some("boom \u{1b}[2J".into());
        let got = decode_report(&key("policy"), &wire::encode_reports(&[failed]), None).unwrap();
        assert_eq!(got[0].failed.as_deref(), Some("boom \\u{1b}[2J"));
    }

    #[test]
    fn relayed_reports_are_any_process_s_but_one_s_own() {
        let (a, b) = (report("policy", 3, 1), report("robot", 4, 0));
        let bytes = wire::encode_relayed(&[&a, &b]);
        assert_eq!(
            decode_relayed(&bytes, "ctl_0"),
            Some(vec![a.clone(), b.clone()])
        );
        assert_eq!(decode_relayed(&bytes, "robot"), Some(vec![a.clone()]));
        assert_eq!(decode_relayed(b"\xff{", "robot"), None);
        let mut longer = bytes.clone();
        longer.push(0);
        assert_eq!(decode_relayed(&longer, "robot"), None);
        assert_eq!(decode_relayed(&wire::encode_relayed(&[]), "robot"), None);
        let many = vec![&a; wire::MAX_RELAYED + 1];
        assert_eq!(decode_relayed(&wire::encode_relayed(&many), "robot"), None);
        // A process's own message of reports has the same form.
        assert_eq!(
            wire::decode_relayed(&wire::encode_reports(std::slice::from_ref(&a))),
            Ok(vec![a])
        );
    }

    #[test]
    fn the_inbox_is_bounded() {
        let spec = GraphSpec::parse(DEFAULT_GRAPH_TOML, "t").expect("the chapter's graph");
        let mut inbox = TickInbox::new();
        for i in 0..MAX_AHEAD as u64 {
            inbox
                .accept(report("policy", i + 1, spec.chain.unwrap().policy.0), &spec)
                .unwrap();
        }
        let over = inbox.accept(
            report("policy", u64::MAX, spec.chain.unwrap().policy.0),
            &spec,
        );
        assert!(matches!(over, Err(DistError::Peer(_))), "{over:?}");
    }
}
