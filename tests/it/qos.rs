//! QoS beyond depth, whole runs: every message accounted for under any QoS, virtual runs
//! with links and faults byte-identical, the lessons (the stale queue, the watchdog, a
//! stalled node) as the outputs show them, and one test per bad-QoS rule.

use proptest::prelude::*;
use ratelab::graph::GraphSpec;
use ratelab::policy::{BrainSlot, Scripted};
use ratelab::qos::Fault;
use ratelab::run::build_graph;
use ratelab::runcore::{CoreOptions, RunCore};
use ratelab::scheduler::StopFlag;
use ratelab::{run, ClockKind, Nanos, RunConfig, RunOptions};

use crate::{ratelab_in_repo as ratelab, repo};

fn graph(file: &str) -> GraphSpec {
    GraphSpec::load(&repo(file)).unwrap()
}

fn virtual_cfg(graph: GraphSpec, secs: u64) -> RunConfig {
    RunConfig {
        clock: ClockKind::Virtual,
        duration: Nanos(secs * Nanos::SECOND.0),
        graph,
        ..RunConfig::default()
    }
}

fn run_json(cfg: &RunConfig) -> (ratelab::metrics::Metrics, String, String) {
    let opts = RunOptions {
        keep_trace: true,
        ..RunOptions::default()
    };
    let r = run(cfg, Box::new(Scripted), opts).unwrap();
    let json = serde_json::to_string_pretty(&r.metrics).unwrap();
    let trace = format!("{:?}", r.trace);
    (r.metrics, json, trace)
}

#[test]
fn the_stale_queue_fifo_falls_where_latest_balances() {
    let _machine = crate::machine::shared();
    let mut g = GraphSpec::chapter();
    g.set_rate("policy", 10.0).unwrap();
    g.set_qos("/obs", "depth=100,delivery=latest").unwrap();
    let (latest, _, _) = run_json(&virtual_cfg(g.clone(), 10));
    g.set_qos("/obs", "delivery=fifo").unwrap();
    let (fifo, _, _) = run_json(&virtual_cfg(g, 10));
    assert!(latest.balanced, "{latest:?}");
    assert!(!fifo.balanced && fifo.fell_at_s.is_some(), "{fifo:?}");
    // FIFO: nothing dropped, and what the policy acts on grows older every tick.
    assert_eq!(fifo.topics["/obs"].dropped, 0);
    assert_eq!(
        latest.topics["/obs"].dropped, 0,
        "depth 100 absorbs it under latest too"
    );
    assert!(
        fifo.latency_max_ms > 2.0 * latest.latency_max_ms,
        "{} vs {}",
        fifo.latency_max_ms,
        latest.latency_max_ms
    );
    assert_eq!(fifo.topics["/obs"].qos.as_deref(), Some("KL100 fifo"));
}

#[test]
fn lifespan_expires_what_a_fifo_queue_holds_too_long() {
    let _machine = crate::machine::shared();
    let mut g = GraphSpec::chapter();
    g.set_rate("policy", 10.0).unwrap();
    g.set_qos("/obs", "depth=100,delivery=fifo,lifespan_ms=60")
        .unwrap();
    let (m, _, _) = run_json(&virtual_cfg(g, 10));
    let obs = &m.topics["/obs"];
    assert!(obs.qos_counters["expired"] > 0, "{obs:?}");
    // A reading is at most 60 ms old when read, and the action then waits for the actuator.
    assert!(m.latency_max_ms <= 60.0 + 100.0, "{m:?}");
}

#[test]
fn the_watchdog_stops_the_run_with_its_own_verdict() {
    let _machine = crate::machine::shared();
    let mut g = graph("graphs/cartpole-safety.toml");
    g.set_qos("/cmd", "loss=0.2,deadline_ms=30,on_deadline_missed=stop")
        .unwrap();
    let (m, json, _) = run_json(&virtual_cfg(g, 10));
    assert!(!m.balanced);
    assert_eq!(m.fell_at_s, None, "a watchdog stop is not a fall");
    let w = m.stopped_by_watchdog.as_deref().unwrap();
    assert!(w.contains("no message on /cmd for more than 30 ms"), "{w}");
    assert!(json.contains("\"stopped_by_watchdog\""));
    // With zero instead, the run goes on; the misses are counted.
    let mut g = graph("graphs/cartpole-safety.toml");
    g.set_qos("/cmd", "loss=0.2,deadline_ms=30,on_deadline_missed=zero")
        .unwrap();
    let (m, _, _) = run_json(&virtual_cfg(g, 10));
    assert_eq!(m.stopped_by_watchdog, None);
    let cmd = &m.topics["/cmd"];
    assert!(cmd.qos_counters["requested_deadline_missed"] > 0);
    assert_eq!(
        cmd.qos_counters["offered_deadline_missed"], 0,
        "the safety node kept its rate"
    );
    assert!(cmd.qos_counters["lost"] > 0);
}

#[test]
fn reliable_delivery_loses_nothing_and_pays_in_latency() {
    let _machine = crate::machine::shared();
    let mut g = graph("graphs/cartpole-safety.toml");
    g.set_qos("/cmd", "loss=0,delay_ms=5").unwrap();
    let (lossless, _, _) = run_json(&virtual_cfg(g.clone(), 10));
    g.set_qos("/cmd", "loss=0.2").unwrap();
    let (best, _, _) = run_json(&virtual_cfg(g.clone(), 10));
    g.set_qos("/cmd", "reliability=reliable").unwrap();
    let (rel, _, _) = run_json(&virtual_cfg(g, 10));
    assert!(best.topics["/cmd"].qos_counters["lost"] > 50);
    assert_eq!(rel.topics["/cmd"].qos_counters["lost"], 0);
    assert!(rel.topics["/cmd"].qos_counters["retransmitted"] > 50);
    // A retransmission arrives a timeout (2 × 5 ms) later: some commands miss the
    // actuator's tick they would have made over a lossless link.
    assert!(
        rel.mean_latency_ms > lossless.mean_latency_ms,
        "reliable {} ms vs lossless {} ms",
        rel.mean_latency_ms,
        lossless.mean_latency_ms
    );
    assert!(rel.latency_max_ms > lossless.latency_max_ms);
}

#[test]
fn a_stalled_node_is_reported_not_alive_and_a_killed_one_stays_so() {
    let _machine = crate::machine::shared();
    let mut g = GraphSpec::chapter();
    g.set_lease("policy", 100.0).unwrap();
    g.set_lease("sensor", 100.0).unwrap();
    let mut cfg = virtual_cfg(g, 5);
    cfg.faults = vec![
        Fault::parse("policy@2+0.5", false).unwrap(),
        Fault::parse("sensor@4", true).unwrap(),
    ];
    let (m, a, ta) = run_json(&cfg);
    let policy = &m.nodes["policy"];
    assert_eq!(policy.not_alive, Some(1));
    assert_eq!(policy.faulted_ticks, Some(25), "0.5 s at 50 Hz");
    let sensor = &m.nodes["sensor"];
    assert_eq!(
        sensor.not_alive,
        Some(1),
        "killed at 4 s: not alive by 4.1 s, never back"
    );
    assert_eq!(sensor.faulted_ticks, Some(51), "4.00 s to 5.00 s inclusive");
    assert_eq!(
        m.nodes["actuator"].not_alive, None,
        "no lease, not monitored"
    );
    // Faults are deterministic: the same run twice is the same, byte for byte.
    let (_, b, tb) = run_json(&cfg);
    assert_eq!((a, ta), (b, tb));
}

#[test]
fn links_and_faults_repeat_byte_for_byte_and_seeds_differ() {
    let _machine = crate::machine::shared();
    let mut g = graph("graphs/cartpole-safety.toml");
    g.set_qos("/cmd", "loss=0.2,delay_ms=10,jitter_ms=3,deadline_ms=40")
        .unwrap();
    g.set_qos("/obs", "lifespan_ms=30").unwrap();
    let mut cfg = virtual_cfg(g, 5);
    cfg.faults = vec![Fault::parse("safety@1+0.2", false).unwrap()];
    let (_, a, ta) = run_json(&cfg);
    let (_, b, tb) = run_json(&cfg);
    assert_eq!(a, b);
    assert_eq!(ta, tb);
    cfg.seed = 1;
    let (m, c, _) = run_json(&cfg);
    assert_ne!(a, c, "another seed, other losses");
    assert!(m.topics["/cmd"].qos_counters["lost"] > 0);
}

#[test]
fn default_qos_written_out_changes_nothing() {
    let _machine = crate::machine::shared();
    let text = include_str!("../../graphs/cartpole.toml").replace(
        "depth = 1",
        "depth = 1\nhistory = \"keep_last\"\ndelivery = \"latest\"\nreliability = \"best_effort\"",
    );
    let explicit = GraphSpec::parse(&text, "explicit.toml").unwrap();
    assert_eq!(explicit, GraphSpec::chapter());
    let (_, a, ta) = run_json(&virtual_cfg(GraphSpec::chapter(), 10));
    let (_, b, tb) = run_json(&virtual_cfg(explicit, 10));
    assert_eq!((a.clone(), ta), (b, tb));
    assert!(
        !a.contains("qos"),
        "no QoS key for the chapter's topics: {a}"
    );
}

#[test]
fn qos_round_trips_through_a_graph_file() {
    let mut g = graph("graphs/cartpole-safety.toml");
    g.set_qos(
        "/obs",
        "history=keep_all,depth=50,delivery=fifo,lifespan_ms=30.5",
    )
    .unwrap();
    g.set_qos("/cmd", "loss=0.05,delay_ms=10,jitter_ms=3,reliability=reliable,deadline_ms=40,on_deadline_missed=zero").unwrap();
    g.set_lease("policy", 120.0).unwrap();
    let back = GraphSpec::parse(&g.to_toml(), "back.toml").unwrap();
    assert_eq!(back, g);
}

fn refused(text: &str, line: usize, col: usize, reason: &str) {
    let e = GraphSpec::parse(text, "g.toml").unwrap_err().to_string();
    let want = format!("g.toml:{line}:{col}: ");
    assert!(e.starts_with(&want), "want {want}…, got {e}");
    assert!(e.contains(reason), "want '{reason}' in {e}");
}

const SAFETY: &str = include_str!("../../graphs/cartpole-safety.toml");

/// The safety graph with `/cmd`'s table extended by `extra` lines; returns the text and
/// the line number of the first extra line.
fn cmd_with(extra: &str) -> (String, usize) {
    let anchor = "name = \"/cmd\"\ntype = \"force\"\ndepth = 1\n";
    assert!(SAFETY.contains(anchor));
    let text = SAFETY.replacen(anchor, &format!("{anchor}{extra}\n"), 1);
    let line = text[..text.find(extra).unwrap()].matches('\n').count() + 1;
    (text, line)
}

#[test]
fn each_bad_qos_rule_is_refused_at_its_position() {
    // A keep-all cap of 0 (the depth is the cap).
    let (t, _) = cmd_with("history = \"keep_all\"");
    let t = t.replacen("depth = 1\nhistory", "depth = 0\nhistory", 1);
    let line = t.lines().position(|l| l == "depth = 0").unwrap() + 1;
    refused(&t, line, 9, "depth must be in 1..=");
    // A lifespan ≤ 0, a deadline ≤ 0.
    let (t, l) = cmd_with("lifespan_ms = 0");
    refused(&t, l, 15, "lifespan_ms must be > 0");
    let (t, l) = cmd_with("deadline_ms = -40");
    refused(&t, l, 15, "deadline_ms must be > 0");
    // An unknown field, an unknown value, an unknown link key.
    let (t, l) = cmd_with("deadline = 40");
    refused(&t, l, 1, "unknown field `deadline`");
    let (t, l) = cmd_with("delivery = \"newest\"");
    refused(&t, l, 12, "unknown variant `newest`");
    let (t, l) = cmd_with("link = { loss = 0.2, drop = 1 }");
    refused(&t, l, 22, "unknown field `drop`");
    // Out of range link values.
    let (t, l) = cmd_with("link = { loss = 1.5 }");
    refused(&t, l, 17, "loss must be a probability");
    let (t, l) = cmd_with("link = { jitter_ms = -3 }");
    refused(&t, l, 22, "jitter_ms must be ≥ 0");
    // Combinations.
    let (t, l) = cmd_with("on_deadline_missed = \"zero\"");
    refused(&t, l, 22, "needs a deadline_ms");
    let (t, l) = cmd_with("link = { loss = 1 }\nreliability = \"reliable\"");
    refused(&t, l, 8, "never delivers");
    let t = SAFETY.replacen(
        "name = \"/obs\"\ntype = \"state\"\ndepth = 1\n",
        "name = \"/obs\"\ntype = \"state\"\ndepth = 1\ndeadline_ms = 40\non_deadline_missed = \"stop\"\n",
        1,
    );
    let l = t
        .lines()
        .position(|l| l.starts_with("on_deadline_missed"))
        .unwrap()
        + 1;
    refused(&t, l, 22, "the actuator's reaction");
    // A lease ≤ 0.
    let t = SAFETY.replacen(
        "rate_hz = 50\nsubscribes = \"/obs\"",
        "rate_hz = 50\nliveliness_lease_ms = 0\nsubscribes = \"/obs\"",
        1,
    );
    let l = t
        .lines()
        .position(|l| l.starts_with("liveliness_lease_ms"))
        .unwrap()
        + 1;
    refused(&t, l, 23, "liveliness_lease_ms must be > 0");
}

#[test]
fn a_deadline_shorter_than_the_period_is_a_warning_not_an_error() {
    let (t, _) = cmd_with("deadline_ms = 10");
    let g = GraphSpec::parse(&t, "g.toml").unwrap();
    let w = g.qos_warnings();
    assert_eq!(w.len(), 1);
    assert!(w[0].contains("topic '/cmd': deadline 10 ms is shorter than the period of its publisher 'safety' (20 ms"), "{w:?}");
    let (code, _, err) = ratelab(&["run", "--smoke", "--qos", "/obs:deadline_ms=5"]);
    assert_eq!(code, 0, "{err}");
    assert!(
        err.contains("warning: topic '/obs': deadline 5 ms"),
        "{err}"
    );
}

#[test]
fn bad_qos_flags_exit_2_with_one_line() {
    for (args, needle) in [
        (vec!["--qos", "/obs:colour=red"], "unknown QoS key 'colour'"),
        (vec!["--qos", "/nope:depth=2"], "has no topic '/nope'"),
        (vec!["--qos", "/obs"], "expected TOPIC:KEY=VALUE"),
        (
            vec!["--qos", "/obs:lifespan_ms=0"],
            "lifespan_ms must be > 0",
        ),
        (
            vec!["--qos", "/action:on_deadline_missed=stop"],
            "needs a deadline_ms",
        ),
        (vec!["--link", "/obs:loss=2"], "loss must be a probability"),
        (vec!["--link", "/obs:delivery=fifo"], "not a link key"),
        (vec!["--lease", "policy=0"], "must be > 0"),
        (vec!["--lease", "nobody=10"], "has no node 'nobody'"),
        (vec!["--stall", "policy@1"], "expected NODE@T+D"),
        (vec!["--stall", "nobody@1+1"], "unknown node 'nobody'"),
        (vec!["--kill", "policy@-1"], "must be in [0, 315360000] s"),
    ] {
        let mut all = vec!["run", "--smoke"];
        all.extend(&args);
        let (code, _, err) = ratelab(&all);
        assert_eq!(code, 2, "{args:?}: {err}");
        assert!(err.contains(needle), "{args:?}: want '{needle}' in {err}");
        assert!(!err.contains("panicked"), "{err}");
        assert_eq!(err.trim().lines().count(), 1, "{args:?}: {err}");
    }
}

#[test]
fn qos_counters_reach_metrics_json_and_trace_csv() {
    let _machine = crate::machine::shared();
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().to_str().unwrap();
    let (code, stdout, err) = ratelab(&[
        "run",
        "--clock",
        "virtual",
        "--duration",
        "3",
        "--graph",
        "graphs/cartpole-safety.toml",
        "--link",
        "/cmd:loss=0.2,delay_ms=5",
        "--qos",
        "/cmd:reliability=reliable,deadline_ms=30",
        "--qos",
        "/obs:lifespan_ms=30,history=keep_all,depth=4",
        "--lease",
        "policy=50",
        "--stall",
        "policy@1+0.2",
        "--out",
        out,
    ]);
    assert_eq!(code, 0, "{err}");
    assert!(stdout.contains("qos: /obs KA4 latest ls 30 ms"), "{stdout}");
    assert!(
        stdout.contains(
            "liveliness: policy not alive 1× (lease 50 ms), stalled at 1.00 s for 0.20 s: 10 ticks lost"
        ),
        "{stdout}"
    );
    let m: serde_json::Value =
        serde_json::from_slice(&std::fs::read(dir.path().join("metrics.json")).unwrap()).unwrap();
    let cmd = &m["topics"]["/cmd"];
    for key in [
        "lost",
        "retransmitted",
        "offered_deadline_missed",
        "requested_deadline_missed",
    ] {
        assert!(cmd[key].is_u64(), "{key} in {cmd}");
    }
    assert!(m["topics"]["/obs"]["expired"].is_u64());
    assert!(m["topics"]["/obs"]["refused"].is_u64());
    assert!(
        m["topics"]["/action"].get("expired").is_none(),
        "no lifespan, no column"
    );
    assert_eq!(m["nodes"]["policy"]["not_alive"], 1);
    let trace = std::fs::read_to_string(dir.path().join("trace.csv")).unwrap();
    let header = trace.lines().next().unwrap();
    assert!(header.ends_with(",obs_expired,obs_refused,cmd_lost,cmd_retransmitted,cmd_offered_deadline_missed,cmd_requested_deadline_missed,fell"), "{header}");
}

fn random_qos() -> impl Strategy<Value = String> {
    (
        prop_oneof![Just("keep_last"), Just("keep_all")],
        1usize..6,
        prop_oneof![Just("latest"), Just("fifo")],
        prop::option::of(5u32..80),
        prop::option::of(5u32..80),
        prop::option::of((0u32..60, 0u32..15, 0u32..4)),
        any::<bool>(),
    )
        .prop_map(
            |(history, depth, delivery, deadline, lifespan, link, reliable)| {
                let mut s = format!("history={history},depth={depth},delivery={delivery}");
                if let Some(d) = deadline {
                    s += &format!(",deadline_ms={d}");
                }
                if let Some(l) = lifespan {
                    s += &format!(",lifespan_ms={l}");
                }
                if let Some((loss, delay, jitter)) = link {
                    s += &format!(
                        ",loss={},delay_ms={delay},jitter_ms={jitter}",
                        f64::from(loss) / 100.0
                    );
                    if reliable {
                        s += ",reliability=reliable";
                    }
                }
                s
            },
        )
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 24, ..ProptestConfig::default() })]

    /// published = seen + dropped + expired + lost + refused + unseen buffered + in flight,
    /// on every topic of a whole run under random QoS, and the run repeats exactly.
    #[test]
    fn any_qos_accounts_for_every_message_and_repeats(obs in random_qos(), action in random_qos(), cmd in random_qos(), seed in 0u64..3) {
        let _machine = crate::machine::shared();
        let mut g = graph("graphs/cartpole-safety.toml");
        g.set_qos("/obs", &obs).unwrap();
        g.set_qos("/action", &action).unwrap();
        g.set_qos("/cmd", &cmd).unwrap();
        let cfg = RunConfig { seed, ..virtual_cfg(g, 2) };
        let once = || {
            let built = build_graph(&cfg, BrainSlot::new(Box::new(Scripted)), true, Vec::new()).unwrap();
            let mut core = RunCore::with_graph(&cfg, built, CoreOptions::default());
            let end = core.run_to_end(&StopFlag::new());
            for t in &core.handles().topics {
                let s = t.stats_at(end.at);
                let total = s.seen + s.dropped + s.expired + s.lost + s.refused + s.unmatched + s.before_join + t.unseen_buffered() as u64 + s.in_flight;
                assert_eq!(s.published, total, "{}: {s:?}", t.name());
            }
            serde_json::to_string(&core.metrics()).unwrap()
        };
        prop_assert_eq!(once(), once());
    }
}

/// The summary's headline names the run's real end: a watchdog stop is not "the whole run",
/// and a plant whose actuator was stalled or killed did not balance anything (#25).
#[test]
fn the_headline_names_how_the_run_really_ended() {
    let headline = |extra: &[&str]| {
        let dir = tempfile::tempdir().unwrap();
        let out = dir.path().to_str().unwrap();
        let mut args = vec!["run", "--clock", "virtual", "--duration", "3", "--out", out];
        args.extend_from_slice(extra);
        let (code, stdout, err) = ratelab(&args);
        let m: serde_json::Value =
            serde_json::from_slice(&std::fs::read(dir.path().join("metrics.json")).unwrap())
                .unwrap();
        let line = stdout
            .lines()
            .find(|l| l.contains(" — ") && l.contains("actuator steps"))
            .unwrap_or_else(|| panic!("no headline in {stdout}"))
            .trim_start_matches("[ratelab] ")
            .to_string();
        // A watchdog's stop is an early end, and an actuator killed within the run left the
        // plant standing still: after the summary and files, exit 2 and one line (#27: a
        // lying report never reads as success); every other end here is a success.
        let killed = extra
            .windows(2)
            .find(|w| w[0] == "--kill" && w[1].starts_with("actuator@"))
            .map(|w| w[1].trim_start_matches("actuator@").parse::<f64>().unwrap())
            .filter(|&t| t <= 3.0);
        match (
            m.get("stopped_by_watchdog").and_then(|w| w.as_str()),
            killed,
        ) {
            (Some(w), _) => {
                assert_eq!(code, 2, "{err}");
                let lines: Vec<&str> = err.lines().collect();
                assert_eq!(lines, [format!("error: the run ended early: {w}")], "{err}");
            }
            (None, Some(t)) => {
                assert_eq!(code, 2, "{err}");
                let lines: Vec<&str> = err.lines().collect();
                assert_eq!(
                    lines,
                    [format!(
                        "error: the actuator was killed at t={t:.2}s (--kill): the plant stood still from then, so the run balanced nothing after"
                    )],
                    "{err}"
                );
            }
            (None, None) => assert_eq!(code, 0, "{err}"),
        }
        (
            line,
            m["balanced"].as_bool().unwrap(),
            m["policy_ticks"].as_u64().unwrap(),
            stdout,
        )
    };
    let (line, balanced, policy_ticks, _) = headline(&[
        "--qos",
        "/action:deadline_ms=40,on_deadline_missed=stop",
        "--stall",
        "policy@2+0.5",
    ]);
    // The brain ran at t = 0, 0.02, …, 1.98 s; the stall swallowed the ticks from 2 s.
    assert_eq!(policy_ticks, 100, "{line}");
    assert!(
        line.starts_with("STOPPED BY WATCHDOG at t=2.04s (pole up until then; not balanced)"),
        "{line}"
    );
    assert!(!line.contains("whole run") && !balanced, "{line}");

    let (line, balanced, _, out) = headline(&["--kill", "actuator@0"]);
    assert!(line.starts_with("PLANT NEVER STEPPED"), "{line}");
    assert!(line.contains("0 actuator steps") && !balanced, "{line}");
    // Commands were published, none applied: no latency to give, not one of 0.0 ms.
    assert!(
        out.contains("sense->act latency: none (the actuator applied no command)"),
        "{out}"
    );
    assert!(!out.contains("latency: 0.0 ms"), "{out}");

    // Killed mid-run: the plant stood still from then, and the summary says what was done.
    let (line, balanced, _, out) = headline(&["--kill", "actuator@1"]);
    assert!(
        line.starts_with(
            "ACTUATOR KILLED at t=1.00s (pole up until then; the plant stood still after) — 50 actuator steps"
        ),
        "{line}"
    );
    assert!(!balanced, "{line}");
    assert!(
        out.contains("liveliness: actuator killed at 1.00 s: 101 ticks lost"),
        "{out}"
    );

    // A kill set after the end does nothing (it is warned about): the headline agrees with
    // `balanced`.
    let (line, balanced, _, _) = headline(&["--kill", "actuator@12"]);
    assert!(
        line.starts_with("BALANCED (pole up the whole run) — 151 actuator steps"),
        "{line}"
    );
    assert!(balanced, "{line}");

    let (line, balanced, _, out) = headline(&["--stall", "actuator@1+0.5"]);
    assert!(
        out.contains("liveliness: actuator stalled at 1.00 s for 0.50 s: 25 ticks lost"),
        "{out}"
    );
    assert!(
        line.starts_with("BALANCED while the plant ran (the actuator lost 25 ticks to a fault"),
        "{line}"
    );
    assert!(balanced, "the pole did stay up whenever the plant stepped");

    let (line, balanced, _, _) = headline(&[]);
    assert!(
        line.starts_with("BALANCED (pole up the whole run) — 151 actuator steps"),
        "{line}"
    );
    assert!(balanced);
}

/// The summary's rates line says when the depth at the end is not the one the run started
/// with (a live change, as `replay` re-runs them), and a topic with the default QoS beside
/// one with QoS set is named with its depth (#25).
#[test]
fn the_summary_names_depths_at_the_start_and_the_end_and_default_qos_with_its_depth() {
    let mut cfg = RunConfig {
        clock: ClockKind::Virtual,
        duration: Nanos::from_millis(400),
        ..RunConfig::default()
    };
    let (m, _, _) = run_json(&cfg);
    assert!(
        m.summary_lines(None)[1].ends_with("| queue_depth 1"),
        "{:?}",
        m.summary_lines(None)
    );
    // As a live change to depth 2 leaves it: the topics at 2, the run's setting 1.
    let mut moved = m.clone();
    for t in moved.topics.values_mut() {
        t.depth = 2;
    }
    assert!(
        moved.summary_lines(None)[1].ends_with("| queue_depth 2 at the end, 1 at the start"),
        "{:?}",
        moved.summary_lines(None)
    );
    cfg.graph.set_qos("/action", "deadline_ms=40").unwrap();
    cfg.graph.set_depth("/obs", 3).unwrap();
    let (mut m, _, _) = run_json(&cfg);
    // As a launch across processes reports a default-QoS topic: counters, no QoS string.
    let obs = m.topics.get_mut("/obs").unwrap();
    assert_eq!(obs.qos, None);
    obs.qos_counters.insert("lost".into(), 3);
    let qos = m
        .summary_lines(None)
        .into_iter()
        .find(|l| l.starts_with("qos: "))
        .expect("a qos line");
    assert!(qos.contains("/obs KL3 latest: 3 lost"), "{qos}");
    assert!(qos.contains("/action KL1 latest dl 40 ms"), "{qos}");
}
