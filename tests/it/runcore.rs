//! The run core's capture and restore, whole runs: restoring what was captured at t and
//! running on gives the uninterrupted run byte for byte (`metrics.json` and every step
//! record), whatever ran or was changed in between; capturing changes nothing; a branch at
//! the capture equals `replay` of the same command; a graph with a Python node restores by
//! replaying, one with a program's own kind that says how to capture its state in place.

use proptest::prelude::*;
use ratelab::graph::registry::{Held, NodeContext, RustNode, Stamped};
use ratelab::graph::GraphSpec;
use ratelab::msg::{ForceMsg, StateMsg};
use ratelab::node::NodeState;
use ratelab::policy::Scripted;
use ratelab::qos::Fault;
use ratelab::run::{Command, TimedCommand};
use ratelab::runcore::{CoreOptions, RunCore};
use ratelab::scheduler::StopFlag;
use ratelab::{ClockKind, Nanos, RunConfig};

use crate::repo;

/// The configurations the byte-identity checks use, each `(label, settings)`.
fn configurations() -> Vec<(&'static str, RunConfig)> {
    let cfg = |graph: GraphSpec, seed: u64| RunConfig {
        clock: ClockKind::Virtual,
        duration: Nanos(6 * Nanos::SECOND.0),
        graph,
        seed,
        ..RunConfig::default()
    };
    let file = |f: &str| GraphSpec::load(&repo(f)).unwrap();
    let mut slow = GraphSpec::chapter();
    slow.set_rate("policy", 5.0).unwrap();
    let mut deep = GraphSpec::chapter();
    deep.set_rate("policy", 10.0).unwrap();
    deep.set_qos("/obs", "depth=100").unwrap();
    let mut lossy = GraphSpec::chapter();
    lossy
        .set_qos(
            "/action",
            "loss=0.2,delay_ms=5,deadline_ms=30,on_deadline_missed=zero",
        )
        .unwrap();
    let mut faulted = cfg(GraphSpec::chapter(), 1);
    faulted.graph.set_lease("policy", 100.0).unwrap();
    faulted.faults = vec![
        Fault::parse("policy@2+0.5", false).unwrap(),
        Fault::parse("sensor@5", true).unwrap(),
    ];
    vec![
        ("chapter", cfg(GraphSpec::chapter(), 0)),
        ("5 Hz", cfg(slow, 0)),
        ("10 Hz depth 100 seed 2", cfg(deep, 2)),
        ("lossy link", cfg(lossy, 3)),
        ("faults", faulted),
        ("estimator", cfg(file("graphs/cartpole-estimator.toml"), 0)),
        ("safety", cfg(file("graphs/cartpole-safety.toml"), 0)),
        ("executors", cfg(file("graphs/cartpole-executors.toml"), 0)),
        ("a program's own kind", cfg(own_kind_graph(), 4)),
    ]
}

/// A program's own kind that keeps state and says how to capture it: a PD controller on
/// the held state (`Held<StateMsg>`, the zero-order hold) whose force is low-passed, so a
/// restore that lost its state, or its input's position, would not give the same run.
struct SmoothPd {
    force_n: f64,
}

impl RustNode for SmoothPd {
    type Input = Held<StateMsg>;
    type Output = ForceMsg;

    fn tick(&mut self, _now: Nanos, state: Option<&Stamped<StateMsg>>) -> Option<ForceMsg> {
        let [x, x_dot, cos_t, sin_t, theta_dot] = state?.data.map(f64::from);
        let u = 10.0 * sin_t.atan2(cos_t) + 2.0 * theta_dot + 0.4 * x + 0.8 * x_dot;
        let target = (u.clamp(-1.0, 1.0) as f32 as f64) * ratelab::plant::GEAR_N;
        self.force_n += 0.7 * (target - self.force_n);
        Some(ForceMsg {
            newtons: self.force_n,
        })
    }

    fn save(&self) -> Option<NodeState> {
        Some(Box::new(self.force_n))
    }

    fn load(&mut self, state: &NodeState) -> bool {
        let Some(f) = state.downcast_ref::<f64>() else {
            return false;
        };
        self.force_n = *f;
        true
    }
}

/// The chapter's graph with its policy a [`SmoothPd`] (`kind = "smooth_pd"`, registered
/// once).
fn own_kind_graph() -> GraphSpec {
    static REGISTERED: std::sync::Once = std::sync::Once::new();
    REGISTERED.call_once(|| {
        ratelab::graph::registry::register("smooth_pd", |_: &NodeContext<'_>| {
            Ok(SmoothPd { force_n: 0.0 })
        })
        .unwrap();
    });
    let chapter = std::fs::read_to_string(repo("graphs/cartpole.toml")).unwrap();
    let own = chapter.replace("kind = \"policy\"", "kind = \"smooth_pd\"");
    assert_ne!(own, chapter);
    GraphSpec::parse(&own, "cartpole.toml").unwrap()
}

fn core(cfg: &RunConfig, commands: Vec<TimedCommand>) -> RunCore {
    RunCore::new(
        cfg,
        Box::new(Scripted),
        CoreOptions {
            keep_trace: true,
            commands,
            remake_brain: Some(Box::new(|| Ok(Box::new(Scripted)))),
            ..CoreOptions::default()
        },
    )
    .unwrap()
}

/// `metrics.json` and the trace of the rest of `core`'s run.
fn finish(mut core: RunCore) -> (String, String) {
    core.run_to_end(&StopFlag::new());
    let metrics = serde_json::to_string_pretty(&core.metrics()).unwrap();
    (metrics, format!("{:?}", core.take_trace()))
}

/// Something that changes the run: a rate, a depth, a QoS, a fault, a phase.
fn divergence(cfg: &RunConfig, k: usize) -> Command {
    let topic = cfg.graph.topics[0].name.clone();
    match k % 5 {
        // The middle node's ticks on another grid.
        4 => Command::SetPhase {
            node: cfg.graph.nodes[cfg.graph.nodes.len() / 2].name.clone(),
            phase_ms: 3.0,
        },
        // A kill of the first node from t = 0: from now on.
        3 => Command::InjectFault {
            fault: format!("{}@0", cfg.graph.nodes[0].name),
        },
        0 => Command::SetNodeHz {
            node: cfg.graph.nodes[cfg.graph.nodes.len() / 2].name.clone(),
            hz: 7.0,
        },
        1 => Command::SetTopicDepth { topic, depth: 3 },
        _ => Command::SetTopicQos {
            topic,
            pairs: "loss=0.5".into(),
        },
    }
}

/// Capture at `t_ms`, change the run and run it on, restore, finish: the uninterrupted
/// run. And a capture that is never restored changes nothing.
fn check_restore(label: &str, cfg: &RunConfig, t_ms: u64, k: usize) {
    let whole = finish(core(cfg, Vec::new()));
    let t = Nanos(t_ms * Nanos::MILLISECOND.0);

    let mut c = core(cfg, Vec::new());
    c.run_until(t);
    let cap = c.capture();
    let python = cfg.graph.nodes.iter().any(|n| n.python.is_some());
    assert_eq!(
        cap.is_replay(),
        python,
        "{label}: only Python nodes make a replay"
    );
    assert_eq!(
        finish(c),
        whole,
        "{label}: a capture at {t} changed the run"
    );

    let mut c = core(cfg, Vec::new());
    c.run_until(t);
    let cap = c.capture();
    // The command may be refused (a rule of the graph): the run goes on regardless.
    let _ = c.apply(divergence(cfg, k));
    c.run_until(t.saturating_add(Nanos(1_500 * Nanos::MILLISECOND.0)));
    c.restore(&cap).unwrap();
    assert_eq!(c.now(), cap.at());
    assert_eq!(finish(c), whole, "{label}: restored at {t}, continued");
}

#[test]
fn a_restored_run_continues_as_the_uninterrupted_run_in_every_configuration() {
    ratelab::init(); // Python nodes or brains through the library, as a program runs them
    let _machine = crate::machine::shared();
    for (i, (label, cfg)) in configurations().iter().enumerate() {
        check_restore(label, cfg, 1_000 + 450 * i as u64, i);
    }
    // Python nodes (two, with parameters): a replay, to the same continuation.
    let mut setpoint = configurations()[0].1.clone();
    setpoint.graph = GraphSpec::load(&repo("graphs/cartpole-setpoint.toml")).unwrap();
    check_restore("setpoint", &setpoint, 2_345, 1);
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 24, ..ProptestConfig::default() })]

    /// Over random instants, configurations and changes in between.
    #[test]
    fn capture_restore_continue_is_the_uninterrupted_run(
        which in 0usize..8,
        t_ms in 0u64..6_000,
        k in 0usize..5,
    ) {
        let _machine = crate::machine::shared();
        let all = configurations();
        let (label, cfg) = &all[which % all.len()];
        check_restore(label, cfg, t_ms, k);
    }
}

#[test]
fn a_branch_at_the_capture_equals_replay_of_the_same_command() {
    let _machine = crate::machine::shared();
    let cfg = &configurations()[0].1;
    let t = Nanos(2_010 * Nanos::MILLISECOND.0);
    let change = Command::SetControlHz { hz: 6.0 };
    let mut c = core(cfg, Vec::new());
    c.run_until(t);
    let cap = c.capture();
    c.run_until(Nanos(4 * Nanos::SECOND.0));
    c.restore(&cap).unwrap();
    c.apply(change.clone()).unwrap();
    let logged = c.applied().to_vec();
    assert_eq!(logged.len(), 1);
    assert!(logged[0].at_ns > t.0, "taking effect at the next instant");
    let branched = finish(c);
    let replayed = finish(core(cfg, logged));
    assert_eq!(branched, replayed);
    assert_ne!(
        branched,
        finish(core(cfg, Vec::new())),
        "6 Hz changes the run"
    );
}

#[test]
fn a_capture_restores_only_into_the_graph_it_was_taken_of() {
    let cfg = &configurations()[0].1;
    let mut a = core(cfg, Vec::new());
    a.run_until(Nanos::SECOND);
    let mut b = core(cfg, Vec::new());
    let e = b.restore(&a.capture()).unwrap_err();
    assert_eq!(e.to_string(), "this capture is of another graph");
    assert_eq!(b.now(), Nanos::ZERO, "unchanged");
}

#[test]
fn a_python_node_makes_the_capture_a_replay_that_gives_the_same_continuation() {
    ratelab::init(); // Python nodes or brains through the library, as a program runs them
    let _machine = crate::machine::shared();
    let cfg = RunConfig {
        clock: ClockKind::Virtual,
        duration: Nanos(4 * Nanos::SECOND.0),
        graph: GraphSpec::load(&repo("graphs/cartpole-python.toml")).unwrap(),
        ..RunConfig::default()
    };
    let whole = finish(core(&cfg, Vec::new()));
    let mut c = core(&cfg, Vec::new());
    c.run_until(Nanos(1_500 * Nanos::MILLISECOND.0));
    c.apply(Command::SetQueueDepth { depth: 2 }).unwrap();
    let cap = c.capture();
    assert!(cap.is_replay(), "a Python node's objects cannot be copied");
    c.run_until(Nanos(3 * Nanos::SECOND.0));
    c.restore(&cap).unwrap();
    assert_eq!(c.now(), cap.at());
    let restored = finish(c);
    let mut straight = core(&cfg, Vec::new());
    straight.run_until(Nanos(1_500 * Nanos::MILLISECOND.0));
    straight.apply(Command::SetQueueDepth { depth: 2 }).unwrap();
    assert_eq!(restored, finish(straight));
    assert_ne!(restored, whole, "depth 2 from 1.5 s is another run");

    // Without a way to make the brain again, a replay is refused and nothing changes.
    let mut c = RunCore::new(&cfg, Box::new(Scripted), CoreOptions::default()).unwrap();
    c.run_until(Nanos::SECOND);
    let cap = c.capture();
    c.run_until(Nanos(2 * Nanos::SECOND.0));
    assert!(c.restore(&cap).is_err());
    assert_eq!(c.now(), Nanos(2 * Nanos::SECOND.0));
}

/// A core keeping captures every `every` for seeking.
fn seeking(cfg: &RunConfig, every: Nanos) -> RunCore {
    RunCore::new(
        cfg,
        Box::new(Scripted),
        CoreOptions {
            keep_trace: true,
            history_every: Some(every),
            ..CoreOptions::default()
        },
    )
    .unwrap()
}

/// `metrics.json` (as of now) and the trace so far.
fn so_far(core: &mut RunCore) -> (String, String) {
    let metrics = serde_json::to_string_pretty(&core.metrics()).unwrap();
    (metrics, format!("{:?}", core.take_trace()))
}

#[test]
fn seeking_back_shows_the_run_as_it_was_and_a_branch_there_equals_replay() {
    let _machine = crate::machine::shared();
    for (label, cfg) in configurations() {
        let ms = |v: u64| Nanos(v * Nanos::MILLISECOND.0);
        // The run to 8 s with commands by hand at 3 s and 7 s, then back to 5.5 s …
        let mut c = seeking(&cfg, Nanos::SECOND);
        c.run_until(ms(3_000));
        let early = divergence(&cfg, 1);
        let early_ok = c.apply(early.clone()).is_ok();
        c.run_until(ms(7_000));
        let _ = c.apply(divergence(&cfg, 0));
        c.run_until(ms(8_000));
        c.seek(ms(5_500)).unwrap();
        // … is the run to 5.5 s with the 3 s command only (its counters, every record).
        let mut fresh = seeking(&cfg, Nanos::SECOND);
        fresh.run_until(ms(3_000));
        if early_ok {
            fresh.apply(early).unwrap();
        }
        fresh.run_until(ms(5_500));
        assert_eq!(c.now(), fresh.now(), "{label}");
        assert_eq!(c.applied(), fresh.applied(), "{label}");
        let (trace_at, trace_fresh) = (so_far(&mut c), so_far(&mut fresh));
        assert_eq!(trace_at, trace_fresh, "{label}: seeking back to 5.5 s");
        // A branch there: a change, then on to the end, is what replay of the log gives.
        let _ = c.apply(Command::SetQueueDepth { depth: 4 });
        let logged = c.applied().to_vec();
        let branched = finish(c);
        assert_eq!(branched.0, finish(core(&cfg, logged)).0, "{label}: branch");
    }
}

#[test]
fn a_long_run_keeps_a_bounded_history_and_still_seeks_exactly() {
    let _machine = crate::machine::shared();
    let cfg = RunConfig {
        duration: Nanos(120 * Nanos::SECOND.0),
        ..configurations()[0].1.clone()
    };
    let mut c = seeking(&cfg, Nanos(100 * Nanos::MILLISECOND.0));
    c.run_until(cfg.duration);
    let kept: Vec<Nanos> = c.history().collect();
    assert!(
        kept.len() <= ratelab::runcore::MAX_HISTORY,
        "{}",
        kept.len()
    );
    assert!(kept.len() > 32, "{}", kept.len());
    assert_eq!(kept[0], Nanos::ZERO);
    let t = Nanos(77_777 * Nanos::MILLISECOND.0);
    c.seek(t).unwrap();
    let mut fresh = core(&cfg, Vec::new());
    fresh.run_until(t);
    assert_eq!(
        serde_json::to_string(&c.metrics()).unwrap(),
        serde_json::to_string(&fresh.metrics()).unwrap()
    );
    // Without a history, seeking back is refused and nothing changes.
    let e = fresh.seek(Nanos::SECOND).unwrap_err();
    assert_eq!(e.to_string(), "no capture kept to seek back to 1 s");
    assert_eq!(fresh.now(), Nanos(77_760 * Nanos::MILLISECOND.0));
}

/// The run drawn event by event (as each process of a launch draws it), every event run
/// here: `metrics.json` and the trace equal those of the run stepped instant by instant,
/// with commands at run times too; and a follower (the launcher's view) draws the same
/// events in the same order.
fn check_events(label: &str, cfg: &RunConfig, commands: Vec<TimedCommand>) {
    let whole = finish(core(cfg, commands.clone()));
    let mut c = core(cfg, commands.clone());
    let mut order = Vec::new();
    while let Some(event) = c.next_event() {
        let compute = c
            .run_event(event)
            .map_or(Nanos::ZERO, |(_, compute)| compute);
        order.push((event, compute));
    }
    // A node that stopped the run (the fall) ended it; else it ends at its duration, as
    // a stepped run does.
    let stopped = c.end().is_some();
    assert_eq!(finish(c), whole, "{label}: event by event");
    if commands.is_empty() {
        let mut follower = ratelab::runcore::Follower::new(cfg).unwrap();
        for &(event, compute) in &order {
            assert_eq!(
                follower.next_event(),
                Some(event),
                "{label}: the follower's order"
            );
            follower.ran_elsewhere(event, compute);
        }
        if !stopped {
            assert_eq!(follower.next_event(), None, "{label}: the follower's end");
        }
    }
}

#[test]
fn a_run_drawn_event_by_event_is_the_run_stepped_instant_by_instant() {
    let _machine = crate::machine::shared();
    for (label, cfg) in configurations() {
        check_events(label, &cfg, Vec::new());
        let at = |ms: u64| ms * Nanos::MILLISECOND.0;
        let commands = vec![
            TimedCommand {
                at_ns: at(1_250),
                command: divergence(&cfg, 0),
            },
            TimedCommand {
                at_ns: at(2_500),
                command: divergence(&cfg, 1),
            },
            TimedCommand {
                at_ns: at(3_005),
                command: divergence(&cfg, 4),
            },
            TimedCommand {
                at_ns: at(3_500),
                command: Command::InjectFault {
                    fault: format!("{}@3.6+0.2", cfg.graph.nodes[0].name),
                },
            },
            TimedCommand {
                at_ns: at(4_000),
                command: Command::SetExecutor {
                    executor: "single".into(),
                },
            },
        ];
        check_events(label, &cfg, commands);
    }
}

#[test]
fn a_real_clock_run_gives_its_nodes_back_to_the_core_and_ends_it() {
    let _machine = crate::machine::shared();
    let cfg = RunConfig {
        clock: ClockKind::Real,
        duration: Nanos(300 * Nanos::MILLISECOND.0),
        ..RunConfig::default()
    };
    let mut c = core(&cfg, Vec::new());
    let before = c.capture();
    let opts = ratelab::run::real_options(&cfg);
    // Only the sensor and the policy (a process's share): the actuator never ticks.
    let r = c.run_real(Some(&[0, 1]), &StopFlag::new(), &opts);
    assert_eq!(r.end.reason, ratelab::scheduler::EndReason::Duration);
    assert_eq!(r.timing.len(), 2);
    assert!(r.timing.iter().all(|t| t.ticks > 0), "{:?}", r.timing);
    assert_eq!(c.end(), Some(&r.end));
    // Run once: a second call gives the end back and runs nothing.
    let again = c.run_real(None, &StopFlag::new(), &opts);
    assert_eq!((again.end, again.timing.len()), (r.end, 0));
    // Every node is back in its place: the capture taken before the run (every node's
    // state, by position) restores into it, and the run goes on from t = 0 under the
    // virtual clock.
    assert!(!before.is_replay());
    c.restore(&before).unwrap();
    assert_eq!(c.now(), Nanos::ZERO);
    assert!(c.end().is_none());
    c.run_until(Nanos(200 * Nanos::MILLISECOND.0));
    assert_eq!(c.now(), Nanos(200 * Nanos::MILLISECOND.0));
}

/// The faults configuration, and the same without its faults.
fn faults_and_bare() -> (RunConfig, RunConfig) {
    let (_, given) = configurations()
        .into_iter()
        .find(|(label, _)| *label == "faults")
        .unwrap();
    let bare = RunConfig {
        faults: Vec::new(),
        ..given.clone()
    };
    (given, bare)
}

/// The faults configuration's faults (a policy stall, a sensor kill) injected by command
/// as the run goes on, instead of given at the start: the same run, byte for byte. And a
/// fault that names no node, or one past the run's bound, is refused in one line.
#[test]
fn a_fault_injected_by_command_is_the_fault_given_at_the_start() {
    let _machine = crate::machine::shared();
    let (given, bare) = faults_and_bare();
    let inject = |at_ms: u64, fault: &str| TimedCommand {
        at_ns: at_ms * Nanos::MILLISECOND.0,
        command: Command::InjectFault {
            fault: fault.into(),
        },
    };
    let by_command = core(
        &bare,
        vec![inject(1_000, "policy@2+0.5"), inject(4_000, "sensor@5s")],
    );
    let (metrics, trace) = finish(by_command);
    assert_eq!((metrics.clone(), trace), finish(core(&given, Vec::new())));
    assert!(metrics.contains("\"faulted_ticks\": 25"), "{metrics}");

    let mut c = core(&bare, Vec::new());
    let refused = |c: &mut RunCore, fault: &str| {
        c.apply(Command::InjectFault {
            fault: fault.into(),
        })
        .unwrap_err()
    };
    assert!(refused(&mut c, "nobody@1").contains("unknown node 'nobody'"));
    assert!(refused(&mut c, "policy").contains("NODE@T"));
    for _ in 0..ratelab::config::MAX_FAULTS {
        c.apply(Command::InjectFault {
            fault: "policy@9+0.1".into(),
        })
        .unwrap();
    }
    assert!(refused(&mut c, "policy@9+0.1").contains("at most"));
}

/// A fault injected with a time already past is booked from the instant it takes effect (a
/// stall still ending when it was set to): the run, its summary too, is that of the fault
/// given at the start from that instant; the summary never names a start it did not have.
#[test]
fn a_fault_given_a_past_time_is_booked_from_the_instant_it_takes_effect() {
    let _machine = crate::machine::shared();
    let (_, bare) = faults_and_bare();
    let late = TimedCommand {
        at_ns: 2_200 * Nanos::MILLISECOND.0,
        command: Command::InjectFault {
            fault: "policy@2+0.5".into(),
        },
    };
    let from_its_instant = RunConfig {
        faults: vec![ratelab::qos::Fault::parse("policy@2.2+0.3", false).unwrap()],
        ..bare.clone()
    };
    let mut c = core(&bare, vec![late.clone()]);
    c.run_to_end(&StopFlag::new());
    let summary = c.metrics().summary_lines(None).join("\n");
    assert!(
        summary.contains("stalled at 2.20 s for 0.30 s"),
        "{summary}"
    );
    assert_eq!(
        finish(core(&bare, vec![late])),
        finish(core(&from_its_instant, Vec::new()))
    );
    // A stall over before the instant it would take effect is refused: it would name a
    // stall that never was.
    let mut c = core(&bare, Vec::new());
    c.run_until(Nanos(3 * Nanos::SECOND.0));
    let err = c
        .apply(Command::InjectFault {
            fault: "sensor@0.5+0.2".into(),
        })
        .unwrap_err();
    assert!(err.contains("over at 0.7 s, before the instant"), "{err}");
    assert!(c.applied().is_empty(), "not logged");
    // As a session log of version 2 or before holds it: booked at its given time, as those
    // runs booked it.
    let legacy = TimedCommand {
        at_ns: 2_200 * Nanos::MILLISECOND.0,
        command: Command::InjectFaultAsGiven {
            fault: "policy@2+0.5".into(),
        },
    };
    let mut c = core(&bare, vec![legacy]);
    c.run_to_end(&StopFlag::new());
    let summary = c.metrics().summary_lines(None).join("\n");
    assert!(
        summary.contains("stalled at 2.00 s for 0.50 s"),
        "{summary}"
    );
}

/// A phase change by command at the start is the run started at that phase offset, byte
/// for byte; mid-run it puts the node's ticks on the new grid from the next instant on,
/// rate unchanged; a bad node or offset is refused in one line.
#[test]
fn a_phase_change_puts_a_node_s_ticks_on_a_new_grid() {
    let _machine = crate::machine::shared();
    let base = configurations()[0].1.clone();
    let ms = |m: u64| Nanos(m * Nanos::MILLISECOND.0);
    let mut offset = base.clone();
    offset.phase_offsets = vec![Nanos::ZERO, ms(10), Nanos::ZERO];
    let at = |at_ms: u64, phase_ms: f64| TimedCommand {
        at_ns: ms(at_ms).0,
        command: Command::SetPhase {
            node: "policy".into(),
            phase_ms,
        },
    };
    assert_eq!(
        finish(core(&base, vec![at(0, 10.0)])),
        finish(core(&offset, Vec::new()))
    );

    // Mid-run, at 2.005 s (so before the instant at 2.020 s, the first at or after it): the
    // policy's ticks were on 0 + k·20 ms, then on 7 + k·20 ms.
    let mut c = core(&base, vec![at(2_005, 7.0)]);
    let mut starts = Vec::new();
    while let Some(e) = c.next_event() {
        if let ratelab::scheduler::Event::Start { node: 1, at } = e {
            starts.push(at);
        }
        let _ = c.run_event(e);
    }
    let (before, after): (Vec<Nanos>, Vec<Nanos>) = starts.iter().partition(|t| **t < ms(2_005));
    assert!(before.iter().all(|t| t.0 % ms(20).0 == 0), "{before:?}");
    assert_eq!(before.last(), Some(&ms(2_000)));
    assert_eq!(after.first(), Some(&ms(2_027)));
    assert!(after.iter().all(|t| (t.0 - ms(7).0) % ms(20).0 == 0));
    // One tick a period, the grid 7 ms later: 0…2000 ms and 2027…5987 ms.
    assert_eq!((before.len(), after.len()), (101, 199));

    let mut c = core(&base, Vec::new());
    let set = |node: &str, phase_ms: f64| Command::SetPhase {
        node: node.into(),
        phase_ms,
    };
    assert!(c
        .apply(set("nobody", 5.0))
        .unwrap_err()
        .contains("no node 'nobody'"));
    assert!(c
        .apply(set("policy", 1000.0))
        .unwrap_err()
        .contains("[0, 1000)"));
    assert!(c.apply(set("policy", f64::NAN)).is_err());
}

/// Every node moved to another grid at once: the instant due next no longer runs, and a
/// command between it and the new one takes effect before the new one, stepped or drawn
/// event by event alike.
#[test]
fn a_phase_change_that_moves_the_next_instant_applies_the_commands_up_to_the_new_one() {
    let _machine = crate::machine::shared();
    let cfg = configurations()[0].1.clone();
    let ms = |m: u64| m * Nanos::MILLISECOND.0;
    let mut commands: Vec<TimedCommand> = cfg
        .graph
        .nodes
        .iter()
        .map(|n| TimedCommand {
            at_ns: ms(2_005),
            command: Command::SetPhase {
                node: n.name.clone(),
                phase_ms: 7.0,
            },
        })
        .collect();
    commands.push(TimedCommand {
        at_ns: ms(2_025),
        command: Command::SetQueueDepth { depth: 3 },
    });
    check_events("every node's phase", &cfg, commands.clone());
    let mut c = core(&cfg, commands);
    c.run_until(Nanos(ms(2_020)));
    assert_eq!(c.now(), Nanos(ms(2_000)), "no instant at 2.020 s");
    c.step();
    assert_eq!(c.now(), Nanos(ms(2_027)));
    assert_eq!(c.applied().len(), 4, "the depth too, before 2.027 s");
}

/// The scripted balancer, but a brain that cannot be copied: its captures replay.
struct Uncopied;

impl ratelab::policy::Policy for Uncopied {
    fn act(&mut self, obs: &ratelab::plant::Observation) -> ratelab::plant::Action {
        Scripted.act(obs)
    }
    fn label(&self) -> String {
        "uncopied".into()
    }
}

/// What a real-clock part of a run did ([`real_for`]).
struct RealPart {
    end: ratelab::scheduler::RunEnd,
    /// Per node, the run times of its first and last deadlines there.
    deadlines: Vec<Option<(Nanos, Nanos)>>,
    /// Per node, its ticks there.
    ticks: Vec<u64>,
}

/// Switch `core` to the real clock in place for `wall` of wall time, and back.
fn real_for(core: &mut RunCore, wall: std::time::Duration) -> RealPart {
    real_for_with(core, wall, || {})
}

/// [`real_for`], calling `midway` halfway through (on another thread).
fn real_for_with(
    core: &mut RunCore,
    wall: std::time::Duration,
    midway: impl FnOnce() + Send + 'static,
) -> RealPart {
    let deadlines = std::sync::Arc::new(std::sync::Mutex::new(vec![
        None;
        core.config().graph.nodes.len()
    ]));
    let seen = deadlines.clone();
    let opts = ratelab::scheduler::RealOptions {
        on_tick: Some(std::sync::Arc::new(
            move |t: &ratelab::scheduler::TickReport<'_>| {
                let mut d = seen.lock().unwrap();
                // Scheduled = actual start − lateness, exactly.
                let at = t.now.saturating_sub(t.lateness);
                let (first, _) = d[t.node].unwrap_or((at, at));
                d[t.node] = Some((first, at));
            },
        )),
        ..ratelab::run::real_options(core.config())
    };
    let stop = StopFlag::new();
    let stopper = {
        let stop = stop.clone();
        std::thread::spawn(move || {
            std::thread::sleep(wall / 2);
            midway();
            std::thread::sleep(wall / 2);
            stop.stop();
        })
    };
    let r = core.run_real(None, &stop, &opts);
    stopper.join().unwrap();
    let deadlines = deadlines.lock().unwrap().clone();
    RealPart {
        end: r.end,
        deadlines,
        ticks: r.timing.iter().map(|t| t.ticks).collect(),
    }
}

/// The lab's `c` on a running core: virtual → real → virtual → real → virtual, one run.
/// Each node's first real-clock deadline is its next tick as the virtual clock had it; the
/// virtual clock takes the graph back at the time the real one stopped, each node's next
/// tick on the grid it ran on; the counters, the run log and the plant go on through every
/// switch, and the run reaches its end. Seeking back to before the first switch gives the
/// all-virtual run byte for byte; a capture that replays is refused after a real part.
#[test]
fn a_clock_switch_in_place_carries_the_run_across_both_ways() {
    let _machine = crate::machine::shared();
    let cfg = RunConfig {
        clock: ClockKind::Virtual,
        duration: Nanos(5 * Nanos::SECOND.0),
        ..RunConfig::default()
    };
    let ms = |n: u64| Nanos(n * Nanos::MILLISECOND.0);
    let all_virtual = finish(seeking(&cfg, Nanos::SECOND));
    let mut c = seeking(&cfg, Nanos::SECOND);
    c.run_until(ms(1_250));
    let t0 = c.now();
    let n = cfg.graph.nodes.len();
    let due: Vec<Nanos> = (0..n)
        .map(|i| c.scheduler().next_due_of(i).unwrap())
        .collect();
    let ticks0 = c.scheduler().ticks().to_vec();
    let before = c.metrics();

    let RealPart {
        end,
        deadlines,
        ticks: real_ticks,
    } = real_for(&mut c, std::time::Duration::from_millis(400));
    let firsts: Vec<Option<Nanos>> = deadlines.iter().map(|d| d.map(|(f, _)| f)).collect();
    assert_eq!(end.reason, ratelab::scheduler::EndReason::Interrupted);
    assert!(c.end().is_none(), "a switch does not end the run");
    assert!(
        end.at > t0,
        "the real clock went on from {t0}: stopped at {}",
        end.at
    );
    assert_eq!(c.now(), end.at);
    for (i, (first, due)) in firsts.iter().zip(&due).enumerate() {
        if let Some(first) = first {
            assert_eq!(first, due, "node {i} starts on its virtual next tick");
        }
    }
    assert!(
        real_ticks.iter().all(|&t| t > 0),
        "every node ticked: {real_ticks:?}"
    );
    let ticks1: Vec<u64> = ticks0.iter().zip(&real_ticks).map(|(a, b)| a + b).collect();
    assert_eq!(c.scheduler().ticks(), &ticks1[..]);
    let during = c.metrics();
    assert!(during.steps > before.steps, "the run log went on");
    for (name, t) in &during.topics {
        assert!(
            t.published > before.topics[name].published,
            "{name} went on"
        );
    }
    for (i, first) in due.iter().enumerate() {
        let next = c.scheduler().next_due_of(i).unwrap();
        let period = c.handles().rates[i].period();
        assert!(next > end.at, "node {i}: {next} after {}", end.at);
        assert_eq!((next.0 - first.0) % period.0, 0, "node {i} keeps its grid");
    }

    // Back under the virtual clock: its instants go on from there.
    c.run_until(ms(2_500).max(end.at + ms(500)));
    assert!(c.end().is_none());
    assert!(c.metrics().steps > during.steps);
    // And again both ways.
    let end2 = real_for(&mut c, std::time::Duration::from_millis(200)).end;
    assert_eq!(end2.reason, ratelab::scheduler::EndReason::Interrupted);
    assert!(end2.at >= c.now());
    c.run_to_end(&StopFlag::new());
    assert_eq!(
        c.end().map(|e| e.reason.clone()),
        Some(ratelab::scheduler::EndReason::Duration)
    );
    let ticks: u64 = c.metrics().nodes.values().map(|m| m.ticks).sum();
    assert!(ticks > ticks1.iter().sum::<u64>());

    // Not into a part the real clock ran: it cannot be run again.
    let err = c.seek(t0 + ms(1)).unwrap_err();
    assert!(
        matches!(err, ratelab::runcore::RestoreError::RealPart { from, .. } if from == t0),
        "{err}"
    );
    // Back to before the first switch: the run as it was then, and on from there the
    // all-virtual run.
    c.seek(Nanos::SECOND).unwrap();
    assert_eq!(finish(c), all_virtual);

    // A capture that replays cannot give a run with a real-clock part.
    let mut c = RunCore::new(
        &cfg,
        Box::new(Uncopied),
        CoreOptions {
            keep_trace: true,
            remake_brain: Some(Box::new(|| Ok(Box::new(Uncopied)))),
            history_every: Some(Nanos::SECOND),
            ..CoreOptions::default()
        },
    )
    .unwrap();
    c.run_until(ms(1_100));
    real_for(&mut c, std::time::Duration::from_millis(150));
    let cap = c.capture();
    assert!(cap.is_replay());
    let at = c.now();
    c.run_until(at + ms(300));
    let err = c.restore(&cap).unwrap_err().to_string();
    assert!(err.contains("real clock"), "{err}");
    // Before the switch a replay still gives the run as it was.
    c.seek(ms(500)).unwrap();
    assert_eq!(c.now(), ms(500));
}

/// A switch in place in each byte-identity configuration (QoS, faults, executors with
/// compute times whose ticks may be computing at the switch): the run goes on under the
/// real clock and back, every node's count only grows, and the run reaches its end.
#[test]
fn every_configuration_goes_on_through_a_clock_switch_in_place() {
    let _machine = crate::machine::shared();
    for (label, cfg) in configurations() {
        let mut c = core(&cfg, Vec::new());
        // Before the 5 Hz run falls (0.84 s).
        c.run_until(Nanos(330 * Nanos::MILLISECOND.0));
        assert!(c.end().is_none(), "{label}");
        let before = c.scheduler().ticks().to_vec();
        let RealPart {
            end,
            ticks: real_ticks,
            ..
        } = real_for(&mut c, std::time::Duration::from_millis(150));
        assert_eq!(
            end.reason,
            ratelab::scheduler::EndReason::Interrupted,
            "{label}"
        );
        let after: Vec<u64> = before.iter().zip(&real_ticks).map(|(a, b)| a + b).collect();
        assert_eq!(c.scheduler().ticks(), &after[..], "{label}");
        c.run_to_end(&StopFlag::new());
        let end = c.end().cloned().unwrap();
        assert!(
            !matches!(end.reason, ratelab::scheduler::EndReason::NodeFailed { .. }),
            "{label}: {end:?}"
        );
        assert!(
            c.scheduler()
                .ticks()
                .iter()
                .zip(&after)
                .all(|(n, a)| n >= a),
            "{label}"
        );
    }
}

/// A rate changed while the real clock runs moves the node's grid there (its next deadline
/// the last plus the new period): the virtual clock takes the node back on that grid, not
/// on the one it handed over.
#[test]
fn the_virtual_clock_takes_a_node_back_on_the_grid_the_real_clock_left_it() {
    let _machine = crate::machine::shared();
    let cfg = RunConfig {
        clock: ClockKind::Virtual,
        duration: Nanos(5 * Nanos::SECOND.0),
        ..RunConfig::default()
    };
    let mut c = core(&cfg, Vec::new());
    c.run_until(Nanos(1_010 * Nanos::MILLISECOND.0));
    let policy = 1;
    let handed = c.scheduler().next_due_of(policy).unwrap();
    let rate = c.handles().rates[policy].clone();
    let part = real_for_with(&mut c, std::time::Duration::from_millis(400), move || {
        let _ = rate.set_hz(30.0);
    });
    assert_eq!(part.end.reason, ratelab::scheduler::EndReason::Interrupted);
    let (_, last) = part.deadlines[policy].expect("the policy ticked");
    let period = c.handles().rates[policy].period();
    let next = c.scheduler().next_due_of(policy).unwrap();
    assert!(next > part.end.at && next <= part.end.at + period, "{next}");
    assert_eq!(
        (next.0 - last.0) % period.0,
        0,
        "on the grid through its last deadline"
    );
    assert_ne!(
        (next.0 - handed.0) % period.0,
        0,
        "not on the grid it was handed at (20 ms steps, then 33.3 ms)"
    );
    c.run_to_end(&StopFlag::new());
    assert!(c.end().is_some());
}
