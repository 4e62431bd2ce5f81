//! Executors and compute time, whole runs: a chain's latency is the sum of its compute times,
//! one slow callback on a single-threaded executor starves the timer beside it (identically
//! twice under the virtual clock, within bands under the real one), a second thread gives it
//! back, the defaults change nothing, and bad executors are refused in one line.

use ratelab::executor::{ComputeTime, ExecutorOverride};
use ratelab::graph::GraphSpec;
use ratelab::metrics::Metrics;
use ratelab::policy::Scripted;
use ratelab::{run, ClockKind, Nanos, RunConfig, RunOptions};

use crate::{ratelab_in_repo as ratelab, repo};

fn cfg(graph: GraphSpec, clock: ClockKind, secs: f64) -> RunConfig {
    RunConfig {
        clock,
        duration: Nanos::from_secs_f64(secs).unwrap(),
        graph,
        ..RunConfig::default()
    }
}

fn metrics(cfg: &RunConfig) -> (Metrics, String) {
    let r = run(cfg, Box::new(Scripted), RunOptions::default()).unwrap();
    let json = serde_json::to_string_pretty(&r.metrics).unwrap();
    (r.metrics, json)
}

fn compute(spec: &mut GraphSpec, node: &str, ms: &str) {
    spec.set_compute(node, ComputeTime::parse(ms).unwrap())
        .unwrap();
}

#[test]
fn every_stage_of_the_estimator_chain_adds_its_compute_time_to_the_latency() {
    let mut g = GraphSpec::load(&repo("graphs/cartpole-estimator.toml")).unwrap();
    assert_eq!(
        g.node_names(),
        vec!["sensor", "estimator", "policy", "actuator"]
    );
    compute(&mut g, "sensor", "1");
    compute(&mut g, "estimator", "2");
    compute(&mut g, "policy", "3");
    let mut c = cfg(g, ClockKind::Virtual, 5.0);
    // Each stage's tick starts as the stage before it publishes: nothing else waits.
    c.phase_offsets = [0, 1, 3, 6].map(Nanos::from_millis).to_vec();
    let (m, _) = metrics(&c);
    assert!(m.balanced, "{}", m.headline());
    for (what, v) in [
        ("mean", m.mean_latency_ms),
        ("p50", m.latency_p50_ms),
        ("max", m.latency_max_ms),
    ] {
        assert!(
            (v - 6.0).abs() < 1e-9,
            "{what} latency {v} ms, not 1 + 2 + 3"
        );
    }
    let policy = &m.nodes["policy"];
    assert_eq!(policy.compute_ms, Some(3.0));
    let x = policy.exec.as_ref().unwrap();
    assert_eq!((x.response_time_max_ms, x.skipped_ticks), (3.0, 0));
    // The same offsets without compute times: no latency at all (the chapter's instant).
    let mut zero = c.clone();
    for n in ["sensor", "estimator", "policy"] {
        compute(&mut zero.graph, n, "0");
    }
    zero.phase_offsets = vec![Nanos::ZERO; 4];
    let (m0, json0) = metrics(&zero);
    assert_eq!(m0.latency_max_ms, 0.0);
    assert!(!json0.contains("response_time"), "defaults add no key");
}

#[test]
fn one_slow_callback_on_a_single_threaded_executor_starves_the_sensor_the_same_way_twice() {
    let _machine = crate::machine::shared();
    let mut g = GraphSpec::chapter();
    compute(&mut g, "policy", "30");
    g.set_executor(ExecutorOverride::parse("single_threaded").unwrap());
    let c = cfg(g.clone(), ClockKind::Virtual, 10.0);
    let (m, json) = metrics(&c);
    let (_, again) = metrics(&c);
    assert_eq!(json, again, "byte-identical");
    let sensor = &m.nodes["sensor"];
    let x = sensor.exec.as_ref().unwrap();
    // The sensor runs only between the policy's 30 ms callbacks: about 1 / 30 ms, not 50 Hz.
    let hz = sensor.ticks as f64 / m.sim_time_s;
    assert!((30.0..=36.0).contains(&hz), "sensor at {hz} Hz");
    assert!(x.skipped_ticks > 0, "{x:?}");
    assert!(x.response_time_max_ms >= 19.9, "{x:?}");
    assert_eq!(m.executors.len(), 1);
    assert!(m.executors[0].utilization > 0.85, "{:?}", m.executors);
    // A second thread: the sensor keeps its 50 Hz grid.
    g.set_executor(ExecutorOverride::parse("multi_threaded:2").unwrap());
    let (m2, _) = metrics(&cfg(g, ClockKind::Virtual, m.sim_time_s.max(1.0)));
    let s2 = &m2.nodes["sensor"];
    assert_eq!(s2.exec.as_ref().unwrap().skipped_ticks, 0);
    let hz2 = s2.ticks as f64 / m2.sim_time_s;
    assert!((49.0..=51.0).contains(&hz2), "sensor at {hz2} Hz");
}

#[test]
fn the_defaults_said_out_loud_change_nothing() {
    let base = cfg(GraphSpec::chapter(), ClockKind::Virtual, 5.0);
    let (_, json) = metrics(&base);
    let mut g = GraphSpec::chapter();
    g.set_executor(ExecutorOverride::parse("per_node").unwrap());
    compute(&mut g, "policy", "0");
    let (_, same) = metrics(&cfg(g, ClockKind::Virtual, 5.0));
    assert_eq!(json, same);
}

/// The measured rate of `node` in a real-clock run's metrics, Hz.
fn measured_hz(m: &Metrics, node: &str) -> f64 {
    m.node_timing
        .as_ref()
        .unwrap()
        .iter()
        .find(|t| t.node == node)
        .unwrap()
        .measured_hz
}

#[test]
fn the_real_clock_shows_the_same_starvation_within_bands() {
    // Judged against this machine as it is now (a learner's busy laptop, CI's shared
    // cores): the sensor's rate with a thread of its own and no compute time, measured in
    // the same test, is the floor; the claims are relative to it.
    let _machine = crate::machine::alone();
    let floor_hz = measured_hz(
        &metrics(&cfg(GraphSpec::chapter(), ClockKind::Real, 2.0)).0,
        "sensor",
    );
    assert!(
        floor_hz > 25.0,
        "the machine cannot hold even 50 Hz: {floor_hz} Hz"
    );
    let mut g = GraphSpec::chapter();
    compute(&mut g, "policy", "30");
    g.set_executor(ExecutorOverride::parse("single_threaded").unwrap());
    let (m, _) = metrics(&cfg(g.clone(), ClockKind::Real, 2.0));
    let starved_hz = measured_hz(&m, "sensor");
    // One thread: the policy's 30 ms holds the sensor's timer past its 20 ms period (about
    // 33 Hz on an idle machine, less on a loaded one), and periods are skipped.
    assert!(
        starved_hz <= 0.8 * floor_hz,
        "sensor at {starved_hz} Hz on one thread beside a 30 ms policy, {floor_hz} Hz alone"
    );
    assert!(m.nodes["sensor"].exec.as_ref().unwrap().skipped_ticks > 0);
    // A second thread gives the sensor its grid back: the floor's rate, within a few ticks.
    g.set_executor(ExecutorOverride::parse("multi_threaded:2").unwrap());
    let freed_hz = measured_hz(&metrics(&cfg(g, ClockKind::Real, 2.0)).0, "sensor");
    assert!(
        freed_hz >= 0.9 * floor_hz && freed_hz > starved_hz,
        "sensor at {freed_hz} Hz with its own thread, {floor_hz} Hz alone, {starved_hz} Hz starved"
    );
}

#[test]
fn the_command_line_prints_the_executor_lines_and_refuses_bad_executors() {
    let (code, out, err) = ratelab(&[
        "run",
        "--clock",
        "virtual",
        "--duration",
        "2",
        "--compute",
        "policy=30",
        "--executor",
        "single_threaded",
    ]);
    assert_eq!(code, 0, "{err}");
    assert!(
        out.contains("executor main: single_threaded, 1 thread,"),
        "{out}"
    );
    assert!(
        out.contains("node policy   compute 30 ms | response p50"),
        "{out}"
    );
    for (args, want) in [
        (vec!["--executor", "fifo"], "unknown executor 'fifo'"),
        (vec!["--compute", "policy=-1"], "compute time must be"),
        (vec!["--compute", "nobody=3"], "unknown node 'nobody'"),
    ] {
        let mut all = vec!["run", "--clock", "virtual", "--duration", "1"];
        all.extend(args);
        let (code, _, err) = ratelab(&all);
        assert_eq!(code, 2, "{all:?}: {err}");
        assert!(err.contains(want), "{all:?}: {err}");
        assert!(!err.contains("panicked"), "{err}");
    }
    let dir = tempfile::tempdir().unwrap();
    let file = dir.path().join("two.toml");
    let text = std::fs::read_to_string(repo("graphs/cartpole.toml")).unwrap()
        + "\n[executors.a]\nkind = \"single_threaded\"\nnodes = [\"policy\"]\n\n[executors.b]\nkind = \"single_threaded\"\nnodes = [\"policy\"]\n";
    std::fs::write(&file, text).unwrap();
    let (code, _, err) = ratelab(&[
        "run",
        "--clock",
        "virtual",
        "--graph",
        file.to_str().unwrap(),
    ]);
    assert_eq!(code, 2, "{err}");
    assert!(
        err.contains("two.toml:") && err.contains("already in executor 'a'"),
        "{err}"
    );
    assert_eq!(err.trim().lines().count(), 1, "{err}");
}

/// The estimator graph teaches what its comment says: with its compute times (the estimate
/// 1 ms, the brain 2 ms) each stage's output waits for the next stage's tick, 10 + 20 = 30 ms
/// of sense→act latency every step; 13 ms with the actuator just after the policy; none
/// with the compute times at 0 (the chapter's instant).
#[test]
fn the_estimator_graph_adds_each_stages_delay_as_its_comment_says() {
    ratelab::init(); // Python nodes or brains through the library, as a program runs them
    for file in [
        "graphs/cartpole-estimator.toml",
        "graphs/cartpole-estimator-python.toml",
    ] {
        let g = GraphSpec::load(&repo(file)).unwrap();
        let node = |n: &str| g.node(g.node_id(n).unwrap()).compute.map(|c| c.mean);
        assert_eq!(
            (node("estimator"), node("policy")),
            (Some(Nanos::from_millis(1)), Some(Nanos::from_millis(2))),
            "{file}"
        );
        let c = cfg(g.clone(), ClockKind::Virtual, 10.0);
        let (m, _) = metrics(&c);
        assert!(m.balanced, "{file}: {}", m.headline());
        assert_eq!((m.latency_p50_ms, m.latency_max_ms), (30.0, 30.0), "{file}");
        let mut shifted = c.clone();
        shifted.phase_offsets = [0, 0, 0, 3].map(Nanos::from_millis).to_vec();
        let (m, _) = metrics(&shifted);
        assert_eq!((m.latency_p50_ms, m.latency_max_ms), (13.0, 13.0), "{file}");
        let mut instant = c;
        for n in ["estimator", "policy"] {
            compute(&mut instant.graph, n, "0");
        }
        assert_eq!(metrics(&instant).0.latency_max_ms, 0.0, "{file}");
    }
}

/// The lab's executor key as a command: at 2 s the chapter's graph (its policy computing
/// 30 ms) moves to one thread for all; from that instant the sensor waits for the policy's
/// callbacks (skipped ticks), before it none. Applied at an instant, it replays the same.
#[test]
fn an_executor_switched_live_applies_from_its_instant_and_replays_the_same() {
    use ratelab::run::{Command, TimedCommand};
    let mut g = GraphSpec::chapter();
    compute(&mut g, "policy", "30");
    let c = cfg(g, ClockKind::Virtual, 4.0);
    let switched = || {
        let opts = RunOptions {
            commands: vec![TimedCommand {
                at_ns: 2_000_000_000,
                command: Command::SetExecutor {
                    executor: "single_threaded".into(),
                },
            }],
            ..RunOptions::new()
        };
        let r = run(&c, Box::new(Scripted), opts).unwrap();
        (
            r.metrics.clone(),
            serde_json::to_string_pretty(&r.metrics).unwrap(),
            r.trace,
        )
    };
    let (m, json, trace) = switched();
    let (_, again, _) = switched();
    assert_eq!(json, again, "byte-identical");
    // Before the switch the sensor ticked at 50 Hz: 100 ticks in the first 2 s, one per
    // 20 ms; after it, about one per 30 ms.
    let sensor = &m.nodes["sensor"];
    let x = sensor.exec.as_ref().unwrap();
    assert!(x.skipped_ticks > 20, "{x:?}");
    let hz = sensor.ticks as f64 / m.sim_time_s;
    assert!((40.0..48.0).contains(&hz), "sensor at {hz} Hz over the run");
    assert_eq!(m.executors.len(), 1, "{:?}", m.executors);
    // The obs rate the actuator saw before the switch is the chapter's 50 per second.
    let published_at = |t_ns: u64| {
        trace
            .iter()
            .find(|s| s.t.0 >= t_ns)
            .map(|s| s.topics.get(ratelab::ids::TopicId(0)).published)
            .unwrap()
    };
    assert_eq!(published_at(1_000_000_000), 51, "50 Hz before the switch");
    let after = published_at(3_980_000_000) - published_at(2_000_000_000);
    assert!(
        (60..=70).contains(&after),
        "{after} in the 2 s after the switch"
    );
    // A bad executor is refused in one line, as --executor refuses it.
    let bad = Command::SetExecutor {
        executor: "two_threads".into(),
    };
    assert!(bad
        .validate(&GraphSpec::chapter())
        .unwrap_err()
        .contains("unknown executor 'two_threads'"));
}

/// The estimator graph with its estimator (1 ms) and its policy (12 ± 4 ms) in one process,
/// 'brain', on one single-threaded executor, the sensor and the actuator in 'robot': written
/// to `dir/brain.toml`.
fn brain_graph(dir: &std::path::Path) -> std::path::PathBuf {
    let mut g = GraphSpec::load(&repo("graphs/cartpole-estimator.toml")).unwrap();
    g.name = "estimator-brain".into();
    compute(&mut g, "policy", "12±4");
    for n in ["estimator", "policy"] {
        let id = g.node_id(n).unwrap();
        g.nodes[id.0].process = Some("brain".into());
    }
    g.executors = vec![ratelab::graph::spec::ExecutorSpec {
        name: "brain".into(),
        kind: ratelab::executor::ExecutorKind::SingleThreaded,
        threads: 1,
        nodes: ["estimator", "policy"]
            .iter()
            .map(|n| g.node_id(n).unwrap())
            .collect(),
        callback_groups: Default::default(),
    }];
    let f = dir.join("brain.toml");
    std::fs::write(&f, g.to_toml()).unwrap();
    f
}

fn json(path: &std::path::Path) -> serde_json::Value {
    serde_json::from_str(&std::fs::read_to_string(path).unwrap()).unwrap()
}

#[test]
fn across_processes_each_process_runs_its_executors_byte_for_byte_under_the_virtual_clock() {
    let _m = crate::machine::shared();
    let dir = tempfile::tempdir().unwrap();
    let brain = brain_graph(dir.path());
    let brain = brain.to_str().unwrap();
    // An executor shared by two nodes of one process, with jittered compute times; and the
    // shipped estimator graph, whose compute times cross three processes.
    for (graph, seed) in [
        (brain, "0"),
        (brain, "1"),
        ("graphs/cartpole-estimator.toml", "0"),
    ] {
        let one = dir.path().join(format!("one-{seed}"));
        let many = dir.path().join(format!("many-{seed}"));
        let _ = std::fs::remove_dir_all(&one);
        let _ = std::fs::remove_dir_all(&many);
        let common = ["--clock", "virtual", "--duration", "5", "--seed", seed];
        let (code, _, err) = ratelab(
            &[
                &["run", "--graph", graph][..],
                &common,
                &["--out", one.to_str().unwrap()],
            ]
            .concat(),
        );
        assert_eq!(code, 0, "{err}");
        let (code, out, err) = ratelab(
            &[
                &["launch", graph, "--processes"][..],
                &common,
                &["--out", many.to_str().unwrap()],
            ]
            .concat(),
        );
        assert_eq!(code, 0, "{out}{err}");
        if graph == brain {
            assert!(
                out.contains("robot [sensor, actuator], brain [estimator, policy]"),
                "{out}"
            );
            assert!(
                out.contains("executor brain: single_threaded, 1 thread"),
                "{out}"
            );
        }
        let a = std::fs::read_to_string(one.join("metrics.json")).unwrap();
        let b = std::fs::read_to_string(many.join("metrics.json")).unwrap();
        assert_eq!(a, b, "{graph}, seed {seed}: metrics differ");
        let m = json(&many.join("metrics.json"));
        assert!(
            m["nodes"]["policy"]["response_time_p50_ms"]
                .as_f64()
                .unwrap()
                > 0.0,
            "{graph}: compute times ran"
        );
    }
}

#[test]
fn an_executor_across_processes_is_refused_and_executor_makes_one_per_process() {
    let _m = crate::machine::shared();
    // The file's executor holds the sensor ('robot') and the policy ('policy').
    let (code, out, err) = ratelab(&[
        "launch",
        "graphs/cartpole-executors.toml",
        "--processes",
        "--clock",
        "virtual",
    ]);
    assert_eq!(code, 2, "{out}{err}");
    assert_eq!(err.trim().lines().count(), 1, "{err}");
    assert!(
        err.contains(
            "executor 'main' holds 'sensor' (process 'robot') and 'policy' (process 'policy')"
        ),
        "{err}"
    );
    assert!(
        !out.contains("launch:"),
        "refused before any process starts: {out}"
    );
    // --executor on a launch: one executor per process.
    let dir = tempfile::tempdir().unwrap();
    let (code, out, err) = ratelab(&[
        "launch",
        "graphs/cartpole-executors.toml",
        "--processes",
        "--clock",
        "virtual",
        "--duration",
        "3",
        "--executor",
        "single_threaded",
        "--out",
        dir.path().to_str().unwrap(),
    ]);
    assert_eq!(code, 0, "{out}{err}");
    for line in [
        "executor robot: single_threaded, 1 thread",
        "executor policy: single_threaded, 1 thread",
    ] {
        assert!(out.contains(line), "{line}: {out}");
    }
    // The same executors written in a file give the same bytes in one process.
    let mut g = GraphSpec::load(&repo("graphs/cartpole-executors.toml")).unwrap();
    g.set_executor_per_process(ExecutorOverride::parse("single_threaded").unwrap());
    let file = dir.path().join("per-process.toml");
    std::fs::write(&file, g.to_toml()).unwrap();
    let one = dir.path().join("one");
    let (code, _, err) = ratelab(&[
        "run",
        "--graph",
        file.to_str().unwrap(),
        "--clock",
        "virtual",
        "--duration",
        "3",
        "--out",
        one.to_str().unwrap(),
    ]);
    assert_eq!(code, 0, "{err}");
    assert_eq!(
        std::fs::read_to_string(one.join("metrics.json")).unwrap(),
        std::fs::read_to_string(dir.path().join("metrics.json")).unwrap(),
        "launch --executor = its executors written in a file, run in one process"
    );
    let m = json(&dir.path().join("metrics.json"));
    // The policy's 30 ms tick on its process's one thread skips every other 20 ms period.
    let policy = &m["nodes"]["policy"];
    let p50 = policy["response_time_p50_ms"].as_f64().unwrap();
    assert!((p50 - 40.0).abs() < 0.1, "{policy}"); // a histogram's bucket of 40 ms
    assert!(policy["skipped_ticks"].as_u64().unwrap() > 0, "{policy}");
    assert_eq!(m["nodes"]["sensor"]["skipped_ticks"].as_u64(), Some(0));
}

#[test]
fn across_processes_the_real_clock_runs_each_process_s_executor() {
    let _m = crate::machine::alone();
    let dir = tempfile::tempdir().unwrap();
    let brain = brain_graph(dir.path());
    let out_dir = dir.path().join("real");
    let (code, out, err) = ratelab(&[
        "launch",
        brain.to_str().unwrap(),
        "--processes",
        "--clock",
        "real",
        "--duration",
        "3",
        "--out",
        out_dir.to_str().unwrap(),
    ]);
    assert_eq!(code, 0, "{out}{err}");
    let m = json(&out_dir.join("metrics.json"));
    let e = &m["executors"][0];
    assert_eq!(e["name"], "brain", "{m}");
    assert_eq!(e["kind"], "single_threaded");
    // Busy 1 ms per 10 ms and 12 ms per 20 ms: 70 % of one thread (the virtual clock's
    // figure). A compute time is CPU burnt: on a loaded machine it takes longer in wall
    // time, by the stretch measured here (the policy's wall time per tick over its 12 ms of
    // CPU), and the upper bounds stretch with it; load never lowers these figures.
    let node = |n: &str, k: &str| m["nodes"][n][k].as_f64().unwrap();
    let stretch = (node("policy", "busy_ms") / (12.0 * node("policy", "ticks"))).max(1.0);
    let u = e["utilization"].as_f64().unwrap();
    assert!(
        u >= 0.55 && u <= (0.9 * stretch).min(1.0),
        "utilization {u} (stretch {stretch})"
    );
    let p50 = node("policy", "response_time_p50_ms");
    assert!(
        (12.0..=20.0 * stretch).contains(&p50),
        "policy response p50 {p50} ms (stretch {stretch})"
    );
    // The estimator's 1 ms update waits behind the policy's tick on the one thread: its
    // worst response is several ms (about 1 ms on a thread of its own).
    let p99 = node("estimator", "response_time_p99_ms");
    assert!(p99 >= 4.0, "estimator response p99 {p99} ms");
}

#[test]
fn a_tick_that_never_finishes_is_said_so_not_shown_as_zero() {
    // The policy's first tick computes for 10 s: nothing reaches the actuator in 2 s.
    let dir = tempfile::tempdir().unwrap();
    let (code, out, err) = ratelab(&[
        "run",
        "--clock",
        "virtual",
        "--duration",
        "2",
        "--compute",
        "policy=9999±1",
        "--out",
        dir.path().to_str().unwrap(),
    ]);
    assert_eq!(code, 0, "{err}");
    assert!(
        out.contains("sense->act latency: none (no command was published to the actuator)"),
        "{out}"
    );
    assert!(
        out.contains("node policy   compute 9999±1 ms | no tick finished its compute time |"),
        "{out}"
    );
    assert!(!out.contains("latency: 0.0 ms"), "{out}");
    let m = json(&dir.path().join("metrics.json"));
    assert_eq!(
        m["nodes"]["policy"]["compute_jitter_ms"].as_f64(),
        Some(1.0)
    );
    assert_eq!(m["action_published"].as_u64(), Some(0));
}
