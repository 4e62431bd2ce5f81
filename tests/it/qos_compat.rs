//! QoS compatibility in whole runs: a subscription whose requested QoS
//! (`[topic.requested.NODE]`) its publisher does not offer receives nothing, and the summary,
//! `metrics.json`, the run's log and a launch across processes all say so; offered what it
//! requests, the pair connects and the run is the chapter's. (The table itself, row by row:
//! `src/core/qos/compat.rs`.)

use ratelab::graph::GraphSpec;
use ratelab::policy::{BrainSlot, Scripted};
use ratelab::run::build_graph;
use ratelab::{run, ClockKind, Nanos, RunConfig, RunOptions};

use crate::{ratelab_in_repo as ratelab, repo};

const GRAPH: &str = "graphs/cartpole-incompatible-qos.toml";

fn cfg(graph: GraphSpec, secs: u64) -> RunConfig {
    RunConfig {
        clock: ClockKind::Virtual,
        duration: Nanos(secs * Nanos::SECOND.0),
        graph,
        ..RunConfig::default()
    }
}

fn run_virtual(cfg: &RunConfig) -> (ratelab::metrics::Metrics, String) {
    let (m, trace, _) = run_with_physics(cfg);
    (m, trace)
}

/// The run's figures, its whole trace (counters included) and each step's pole angle and
/// action (the physics alone).
fn run_with_physics(cfg: &RunConfig) -> (ratelab::metrics::Metrics, String, Vec<(f64, f64)>) {
    let opts = RunOptions {
        keep_trace: true,
        ..RunOptions::default()
    };
    let r = run(cfg, Box::new(Scripted), opts).unwrap();
    let trace = format!("{:?}", r.trace);
    let physics = r.trace.iter().map(|s| (s.pole_angle, s.action)).collect();
    (r.metrics, trace, physics)
}

#[test]
fn an_incompatible_request_delivers_nothing_and_every_output_says_so() {
    let _machine = crate::machine::shared();
    let g = GraphSpec::load(&repo(GRAPH)).unwrap();
    let (m, _) = run_virtual(&cfg(g, 10));
    assert!(!m.balanced && m.fell_at_s.is_some(), "{m:?}");
    let action = &m.topics["/action"];
    assert!(
        action.published > 10,
        "the policy goes on publishing: {action:?}"
    );
    let i = &action.incompatible_qos["actuator"];
    assert_eq!(i.policy, "RELIABILITY");
    assert_eq!(
        i.event,
        "incompatible QoS: requested RELIABLE, offered BEST_EFFORT"
    );
    assert_eq!(i.not_delivered, action.published, "not one message crossed");
    assert!(m.topics["/obs"].incompatible_qos.is_empty());
    let lines = m.summary_lines(None).join("\n");
    assert!(
        lines.contains(&format!(
            "/action → actuator: incompatible QoS: requested RELIABLE, offered BEST_EFFORT ({} messages not delivered)",
            action.published
        )),
        "{lines}"
    );
    assert!(
        lines.contains("sense->act latency: none (the actuator's subscription was never connected: incompatible QoS)"),
        "{lines}"
    );

    // The command line: the event in the run's log (stderr), the summary, metrics.json.
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("out");
    let (code, stdout, stderr) = ratelab(&[
        "run",
        "--graph",
        GRAPH,
        "--clock",
        "virtual",
        "--out",
        out.to_str().unwrap(),
    ]);
    assert_eq!(code, 0, "{stderr}");
    assert!(
        stderr.contains("[actuator] incompatible QoS on /action: requested RELIABLE, offered BEST_EFFORT; it receives nothing"),
        "{stderr}"
    );
    assert!(
        stdout.contains("/action → actuator: incompatible QoS"),
        "{stdout}"
    );
    let json: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("metrics.json")).unwrap()).unwrap();
    assert_eq!(
        json["topics"]["/action"]["incompatible_qos"]["actuator"]["policy"],
        "RELIABILITY"
    );
    let log = std::fs::read_to_string(out.join("log.txt")).unwrap();
    assert!(log.contains("incompatible QoS on /action"), "{log}");
}

#[test]
fn offered_what_it_requests_the_pair_connects_and_the_run_is_the_chapters() {
    let _machine = crate::machine::shared();
    let mut g = GraphSpec::load(&repo(GRAPH)).unwrap();
    g.set_qos("/action", "reliability=reliable").unwrap();
    let (m, trace) = run_virtual(&cfg(g, 10));
    assert!(m.balanced, "{m:?}");
    assert!(m.topics["/action"].incompatible_qos.is_empty());
    let mut chapter = GraphSpec::chapter();
    chapter.set_qos("/action", "reliability=reliable").unwrap();
    let (c, chapter_trace) = run_virtual(&cfg(chapter, 10));
    assert_eq!(
        trace, chapter_trace,
        "the same nodes, connected: the same run"
    );
    assert_eq!(m.latency_p50_ms, c.latency_p50_ms);
}

#[test]
fn a_live_qos_change_connects_and_disconnects_the_subscription() {
    let _machine = crate::machine::shared();
    let c = cfg(GraphSpec::load(&repo(GRAPH)).unwrap(), 1);
    let built = build_graph(&c, BrainSlot::new(Box::new(Scripted)), false, Vec::new()).unwrap();
    let h = &built.handles;
    let action = h.topic(c.graph.topic_id("/action").unwrap());
    assert!(!action.matched(), "best effort offered, reliable requested");
    let set = |pairs: &str| {
        ratelab::command::Command::SetTopicQos {
            topic: "/action".into(),
            pairs: pairs.into(),
        }
        .apply(h, ratelab::Nanos::ZERO)
        .unwrap();
    };
    set("reliability=reliable");
    assert!(action.matched(), "now offered what it requests");
    set("reliability=best_effort");
    assert!(!action.matched());
    action
        .publish(
            None,
            &ratelab::msg::ForceMsg { newtons: 1.0 }.into(),
            Nanos(0),
            None,
        )
        .unwrap();
    assert_eq!(action.stats().unmatched, 1);
    assert_eq!(action.read(Nanos(1)), None, "nothing reached it");
}

/// One topic, two subscribers: only the one whose request is not met is cut off; the other
/// reads on, and the pole balances.
#[test]
fn a_request_concerns_its_own_subscription_only() {
    let _machine = crate::machine::shared();
    // The request goes under /obs's table (a `[topic.requested.…]` belongs to the
    // `[[topic]]` above it).
    let text = std::fs::read_to_string(repo("graphs/cartpole-monitor.toml"))
        .unwrap()
        .replace(
            "[[topic]]\nname = \"/action\"",
            "[topic.requested.monitor]\ndeadline_ms = 10\n\n[[topic]]\nname = \"/action\"",
        );
    assert!(text.contains("[topic.requested.monitor]"));
    let dir = tempfile::tempdir().unwrap();
    let file = dir.path().join("g.toml");
    std::fs::write(&file, text).unwrap();
    // The monitor is a Python node: its script is found beside the graph file.
    std::fs::create_dir(dir.path().join("nodes")).unwrap();
    std::fs::copy(
        repo("graphs/nodes/obs_monitor.py"),
        dir.path().join("nodes/obs_monitor.py"),
    )
    .unwrap();
    let g = GraphSpec::load(&file).unwrap();
    ratelab::init(); // Python nodes through the library, as a program runs them
    let (m, _) = run_virtual(&cfg(g, 5));
    assert!(m.balanced, "{m:?}");
    let obs = &m.topics["/obs"];
    let i = &obs.incompatible_qos["monitor"];
    assert_eq!(i.policy, "DEADLINE");
    assert_eq!(
        i.event,
        "incompatible QoS: requested deadline 10 ms, offered no deadline"
    );
    assert_eq!(i.not_delivered, obs.published);
    assert!(!obs.incompatible_qos.contains_key("policy"));
}

/// Across processes the subscriber's process judges its own request: a lockstep launch
/// writes the in-process run's `metrics.json` byte for byte, incompatible subscription and
/// all.
#[test]
fn a_launch_across_processes_cuts_off_the_same_subscription() {
    let _machine = crate::machine::shared();
    let dir = tempfile::tempdir().unwrap();
    let (one, many) = (dir.path().join("one"), dir.path().join("many"));
    let common = ["--graph", GRAPH, "--clock", "virtual", "--duration", "3"];
    let (code, _, err) =
        ratelab(&[&["run"][..], &common, &["--out", one.to_str().unwrap()]].concat());
    assert_eq!(code, 0, "{err}");
    let (code, out, err) = ratelab(
        &[
            &["launch", "--processes"][..],
            &common,
            &["--out", many.to_str().unwrap()],
        ]
        .concat(),
    );
    assert_eq!(code, 0, "{out}{err}");
    let a = std::fs::read_to_string(one.join("metrics.json")).unwrap();
    let b = std::fs::read_to_string(many.join("metrics.json")).unwrap();
    assert!(a.contains("\"incompatible_qos\""), "{a}");
    assert_eq!(a, b);
}

/// The monitor graph with the monitor joining at 2 s and `/obs` of depth 5 and durability
/// `durability`, written beside a copy of its script.
fn late_monitor(dir: &std::path::Path, durability: &str) -> GraphSpec {
    let text = std::fs::read_to_string(repo("graphs/cartpole-monitor.toml"))
        .unwrap()
        .replace(
            "script = \"nodes/obs_monitor.py\"",
            "script = \"nodes/obs_monitor.py\"\nstart_ms = 2000\nliveliness_lease_ms = 300",
        )
        .replace(
            "name = \"/obs\"\ntype = \"state\"\ndepth = 1",
            &format!("name = \"/obs\"\ntype = \"state\"\ndepth = 5\ndurability = \"{durability}\""),
        );
    assert!(text.contains("start_ms = 2000") && text.contains("durability"));
    std::fs::create_dir_all(dir.join("nodes")).unwrap();
    std::fs::copy(
        repo("graphs/nodes/obs_monitor.py"),
        dir.join("nodes/obs_monitor.py"),
    )
    .unwrap();
    let file = dir.join(format!("{durability}.toml"));
    std::fs::write(&file, text).unwrap();
    GraphSpec::load(&file).unwrap()
}

/// A node that joins late (`start_ms`) receives what was published before it only from a
/// transient-local topic, the last `depth` messages; from a volatile one, nothing. The
/// others' subscriptions, there from the start, are untouched.
#[test]
fn a_late_joiner_gets_the_last_depth_messages_only_under_transient_local() {
    let _machine = crate::machine::shared();
    ratelab::init(); // Python nodes through the library, as a program runs them
    let dir = tempfile::tempdir().unwrap();
    let mut traces = Vec::new();
    for (durability, history) in [("volatile", 0), ("transient_local", 5)] {
        let g = late_monitor(dir.path(), durability);
        assert_eq!(
            g.node(g.node_id("monitor").unwrap()).start,
            Some(Nanos(2 * Nanos::SECOND.0))
        );
        let (m, _, physics) = run_with_physics(&cfg(g, 5));
        assert!(m.balanced, "{durability}: {m:?}");
        let j = &m.topics["/obs"].late_joiners["monitor"];
        assert_eq!((j.start_s, j.history), (2.0, history), "{durability}");
        assert_eq!(j.durability, durability);
        // 100 readings before 2 s (0, 20, … 1980 ms): what it did not get, it missed.
        assert_eq!(j.missed, 100 - history, "{durability}");
        assert!(
            m.topics["/obs"].incompatible_qos.is_empty(),
            "late is not incompatible"
        );
        // It ticks from its start: 2.0, 2.1, … 5.0 s at 10 Hz (the run's last instant
        // included, as every node's).
        assert_eq!(m.nodes["monitor"].ticks, 31, "{durability}");
        assert_eq!(m.nodes["sensor"].ticks, 251, "{durability}");
        let lines = m.summary_lines(None).join("\n");
        let said = format!(
            "/obs → monitor joined at 2.00 s and received {history} messages from before ({})",
            durability.replace('_', "-")
        );
        assert!(lines.contains(&said), "{lines}");
        traces.push(physics);
    }
    assert_eq!(
        traces[0], traces[1],
        "the policy's own queue is not the monitor's"
    );
}

#[test]
fn bad_durabilities_and_start_times_are_refused_at_their_place() {
    let chapter = std::fs::read_to_string(repo("graphs/cartpole.toml")).unwrap();
    let refused = |from: &str, to: &str, says: &str| {
        assert!(chapter.contains(from), "{from}");
        let e = GraphSpec::parse(&chapter.replacen(from, to, 1), "g.toml")
            .unwrap_err()
            .to_string();
        assert!(e.starts_with("g.toml:") && e.contains(says), "{e}");
    };
    refused(
        "subscribes = \"/action\"",
        "subscribes = \"/action\"\nstart_ms = 500",
        "the actuator steps the plant from t = 0: it cannot join late (start_ms)",
    );
    refused(
        "name = \"policy\"",
        "name = \"policy\"\nstart_ms = -3",
        "start_ms must be > 0",
    );
    refused(
        "depth = 1             # history depth",
        "durability = \"persistent\"\ndepth = 1             # history depth",
        "unknown variant `persistent`",
    );
    // `--qos` takes the key too.
    let mut g = GraphSpec::chapter();
    g.set_qos("/obs", "durability=transient_local").unwrap();
    assert!(g.set_qos("/obs", "durability=forever").is_err());
    assert_eq!(
        g.topic(g.topic_id("/obs").unwrap()).qos.short(1),
        "KL1 latest transient"
    );
}
