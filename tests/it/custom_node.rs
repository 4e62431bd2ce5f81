//! Node kinds written in Rust outside ratelab (`ratelab::graph::registry`): a kind
//! registered once is usable from a graph file, runs in the graph like any node, and
//! `examples/custom_node.rs` (a PD controller) runs the chapter's graph.

use ratelab::graph::registry::{register, NodeContext, RustNode};
use ratelab::graph::GraphSpec;
use ratelab::msg::{ForceMsg, PositionMsg, StateMsg};
use ratelab::policy::Scripted;
use ratelab::{run, ClockKind, Nanos, RunConfig, RunOptions};
use std::path::PathBuf;
use std::process::Command;

/// Pushes the cart with a constant force, whatever it reads (it still needs one reading).
struct Push {
    newtons: f64,
    sensed: bool,
}

impl RustNode for Push {
    type Input = StateMsg;
    type Output = ForceMsg;
    fn tick(&mut self, _now: Nanos, input: Option<&StateMsg>) -> Option<ForceMsg> {
        self.sensed |= input.is_some();
        self.sensed.then_some(ForceMsg {
            newtons: self.newtons,
        })
    }
}

/// The chapter's graph with its policy node of kind `kind` and `params`.
fn graph_with(kind: &str, params: &str) -> String {
    std::fs::read_to_string(crate::repo("graphs/cartpole.toml"))
        .unwrap()
        .replace(
            "kind = \"policy\"",
            &format!("kind = \"{kind}\"\nparams = {{ {params} }}"),
        )
}

fn virtual_run(graph: GraphSpec) -> ratelab::metrics::Metrics {
    let cfg = RunConfig {
        clock: ClockKind::Virtual,
        graph,
        ..RunConfig::default()
    };
    run(&cfg, Box::new(Scripted), RunOptions::default())
        .unwrap()
        .metrics
}

#[test]
fn a_registered_kind_is_usable_from_a_graph_file_and_runs_as_a_node() {
    register("push_it", |cx: &NodeContext<'_>| {
        Ok(Push {
            newtons: cx.param_f64("newtons", 0.0)?,
            sensed: false,
        })
    })
    .unwrap();
    let text = graph_with("push_it", "newtons = 10");
    let spec = GraphSpec::parse(&text, "push.toml").unwrap();
    assert_eq!(spec.node(spec.chain.unwrap().policy).kind_name(), "push_it");
    // The file the spec writes (session logs keep it) reads back to the same spec.
    assert_eq!(
        GraphSpec::parse(&spec.to_toml(), "again.toml").unwrap(),
        spec
    );
    let m = virtual_run(spec);
    // Pushed at full force the whole time, the pole falls, and fast; metrics name the kind.
    let fell = m.fell_at_s.expect("a constant push topples the pole");
    assert!(fell < 3.0, "fell at {fell}");
    assert_eq!(m.nodes["policy"].kind, "push_it");
    // Sense→act latency passes through it: the sensor's stamp reaches the actuator.
    assert_eq!(m.mean_latency_ms, 0.0);
    assert!(m.topics["/action"].published > 0);

    // Its parameters are checked by its maker, in one line naming the node.
    let bad = graph_with("push_it", "newtons = \"lots\"");
    let cfg = RunConfig {
        clock: ClockKind::Virtual,
        graph: GraphSpec::parse(&bad, "bad.toml").unwrap(),
        ..RunConfig::default()
    };
    let err = run(&cfg, Box::new(Scripted), RunOptions::default())
        .err()
        .expect("refused")
        .to_string();
    assert!(
        err.contains("node 'policy': params.newtons must be a number"),
        "{err}"
    );
    // Its registered types are checked against the file's topics.
    let wrong =
        graph_with("push_it", "newtons = 1").replacen("type = \"state\"", "type = \"position\"", 1);
    let err = GraphSpec::parse(&wrong, "wrong.toml")
        .unwrap_err()
        .to_string();
    assert!(err.contains("a push_it node reads state"), "{err}");
}

/// graphs/nodes/setpoint_tracker.py in Rust: two inputs (the state, the setpoint), two
/// outputs (the force, the tracking error), the same arithmetic.
struct Tracker {
    state: Option<StateMsg>,
    setpoint_m: f64,
}

impl RustNode for Tracker {
    type Input = (StateMsg, PositionMsg);
    type Output = (ForceMsg, PositionMsg);
    fn tick(
        &mut self,
        _now: Nanos,
        (state, reference): (Option<&StateMsg>, Option<&PositionMsg>),
    ) -> (Option<ForceMsg>, Option<PositionMsg>) {
        if let Some(s) = state {
            self.state = Some(*s);
        }
        if let Some(r) = reference {
            self.setpoint_m = r.cart_pos_m;
        }
        let Some([x, x_dot, cos_t, sin_t, theta_dot]) = self.state.map(|s| s.map(f64::from)) else {
            return (None, None);
        };
        let theta = sin_t.atan2(cos_t);
        let error_m = x - self.setpoint_m;
        let u = 10.0 * theta + 2.0 * theta_dot + 0.4 * error_m + 0.8 * x_dot;
        let command = u.clamp(-1.0, 1.0) as f32;
        (
            Some(ForceMsg {
                newtons: f64::from(command) * 10.0,
            }),
            Some(PositionMsg {
                cart_pos_m: error_m,
                pole_angle_rad: theta,
            }),
        )
    }
}

/// graphs/cartpole-setpoint.toml, its tracker of kind `tracker` (`None`: the Python one),
/// as a spec read from a file in `dir`.
fn setpoint_graph(dir: &std::path::Path, tracker: Option<&str>) -> GraphSpec {
    let nodes = crate::repo("graphs/nodes");
    let mut text = std::fs::read_to_string(crate::repo("graphs/cartpole-setpoint.toml"))
        .unwrap()
        .replace("\"nodes/", &format!("\"{}/", nodes.display()));
    if let Some(kind) = tracker {
        let python = format!(
            "kind = \"python\"\nscript = \"{}/setpoint_tracker.py\"",
            nodes.display()
        );
        assert!(text.contains(&python));
        text = text.replace(&python, &format!("kind = \"{kind}\""));
    }
    let path = dir.join("g.toml");
    std::fs::write(&path, text).unwrap();
    GraphSpec::load(&path).unwrap()
}

#[test]
fn a_registered_kind_of_two_inputs_and_two_outputs_equals_the_python_one() {
    ratelab::init(); // Python nodes or brains through the library, as a program runs them
    register("track_rs", |_: &NodeContext<'_>| {
        Ok(Tracker {
            state: None,
            setpoint_m: 0.0,
        })
    })
    .unwrap();
    let dir = tempfile::tempdir().unwrap();
    let rust = setpoint_graph(dir.path(), Some("track_rs"));
    let tracker = rust.node_id("tracker").unwrap();
    assert_eq!(rust.node(tracker).subscribes.len(), 2);
    assert_eq!(rust.chain.unwrap().policy, tracker);
    let python = setpoint_graph(dir.path(), None);
    for seed in [0, 1] {
        let metrics = |graph: &GraphSpec| {
            let cfg = RunConfig {
                clock: ClockKind::Virtual,
                duration: Nanos(8_000_000_000),
                seed,
                graph: graph.clone(),
                ..RunConfig::default()
            };
            let m = run(&cfg, Box::new(Scripted), RunOptions::default())
                .unwrap()
                .metrics;
            crate::metrics_without_names(serde_json::to_value(&m).unwrap())
        };
        let (r, p) = (metrics(&rust), metrics(&python));
        assert!(r == p, "seed {seed}:\n{r}\n{p}");
        assert!(r.contains("\"balanced\": true"), "{r}");
    }
    // The file's topics must be the registered ones, in number and in order.
    let text = rust.to_toml();
    for (from, to, want) in [
        (
            r#"subscribes = ["/obs", "/reference"]"#,
            r#"subscribes = "/obs""#,
            "a node of kind 'track_rs' subscribes 2 topics: state, position, in that order (as registered), not 1",
        ),
        (
            r#"subscribes = ["/obs", "/reference"]"#,
            r#"subscribes = ["/reference", "/obs"]"#,
            "type mismatch: '/reference' carries position but a track_rs node reads state",
        ),
    ] {
        assert!(text.contains(from), "{text}");
        let err = GraphSpec::parse(&text.replace(from, to), "g.toml")
            .unwrap_err()
            .to_string();
        assert!(err.contains(want), "{err}");
    }
}

#[test]
fn a_kind_nobody_registered_is_refused_by_the_file_and_the_binary() {
    let text = graph_with("nobody_registered", "");
    let err = GraphSpec::parse(&text, "g.toml").unwrap_err().to_string();
    assert!(
        err.contains("unknown kind `nobody_registered`: expected one of sensor"),
        "{err}"
    );
    let dir = tempfile::tempdir().unwrap();
    let g = dir.path().join("g.toml");
    std::fs::write(&g, text).unwrap();
    let o = Command::new(env!("CARGO_BIN_EXE_ratelab"))
        .args(["run", "--clock", "virtual", "--graph"])
        .arg(&g)
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(2), "{err}");
    assert_eq!(err.trim().lines().count(), 1, "{err}");
    assert!(err.contains("unknown kind `nobody_registered`"), "{err}");
}

/// `target/<profile>/examples/custom_node`, built by `cargo test` beside this test binary
/// (`target/<profile>/deps/it-…`).
fn example_binary() -> PathBuf {
    example("custom_node")
}

/// `target/<profile>/examples/NAME`.
fn example(name: &str) -> PathBuf {
    let exe = std::env::current_exe().unwrap();
    let profile = exe.parent().and_then(|deps| deps.parent()).unwrap();
    let p = profile.join("examples").join(name);
    assert!(
        p.is_file(),
        "{} is missing: `cargo test` builds the examples",
        p.display()
    );
    p
}

#[test]
fn the_custom_node_example_runs_the_chapters_graph_with_a_pd_node() {
    let _m = crate::machine::shared();
    for (hz, seed, verdict) in [("50", "0", "BALANCED"), ("5", "1", "FELL at t=")] {
        let o = Command::new(example_binary())
            .args([hz, seed])
            .output()
            .unwrap();
        let out = String::from_utf8_lossy(&o.stdout);
        assert!(
            o.status.success(),
            "{out}{}",
            String::from_utf8_lossy(&o.stderr)
        );
        assert!(
            out.contains(&format!("pd node at {hz} Hz, seed {seed}: {verdict}")),
            "{out}"
        );
        assert!(
            out.contains(
                "equal to the built-in policy node (scripted balancer) in every figure: yes"
            ),
            "{out}"
        );
    }
    let o = Command::new(example_binary()).arg("fast").output().unwrap();
    assert_eq!(o.status.code(), Some(2));
}

/// A program that registers a kind gets ratelab's whole command line with it
/// (`ratelab_lab::main_with`, `examples/custom_node_processes.rs`): `kinds` lists it, a sweep
/// runs it, and a launch across processes — each process the program started again — gives
/// the one-process run byte for byte under the virtual clock. The `ratelab` binary, which
/// does not know the kind, refuses the graph in one line.
#[test]
fn a_program_s_own_kind_is_in_every_front_end_of_its_command_line() {
    let _m = crate::machine::shared();
    let program = example("custom_node_processes");
    let graph = crate::repo("examples/cartpole-pd.toml");
    let graph = graph.to_str().unwrap();
    let run = |args: &[&str]| {
        let o = Command::new(&program).args(args).output().unwrap();
        let out = String::from_utf8_lossy(&o.stdout).into_owned();
        let err = String::from_utf8_lossy(&o.stderr).into_owned();
        assert!(o.status.success(), "{args:?}: {out}{err}");
        out
    };
    let kinds = run(&["kinds"]);
    assert!(
        kinds.contains("| `pd` | `state` → `force` |") && kinds.contains("| `sensor` |"),
        "{kinds}"
    );
    let dir = tempfile::tempdir().unwrap();
    for seed in ["0", "2"] {
        let one = dir.path().join(format!("one-{seed}"));
        let many = dir.path().join(format!("many-{seed}"));
        let common = ["--clock", "virtual", "--seed", seed, "--graph", graph];
        run(&[&["run"], &common[..], &["--out", one.to_str().unwrap()]].concat());
        let launched = run(&[
            &["launch", "--processes", "--headless"],
            &common[..],
            &["--out", many.to_str().unwrap()],
        ]
        .concat());
        assert!(
            launched.contains(
                "graph 'cartpole-pd' in 2 processes: robot [sensor, actuator], policy [policy]"
            ),
            "{launched}"
        );
        let a = std::fs::read(one.join("metrics.json")).unwrap();
        let b = std::fs::read(many.join("metrics.json")).unwrap();
        assert!(
            a == b,
            "seed {seed}: the launch differs from the one-process run"
        );
    }
    let json = dir.path().join("sweep.json");
    run(&[
        "sweep",
        "--graph",
        graph,
        "--control-hz",
        "50,5",
        "--seeds",
        "1",
        "--json",
        json.to_str().unwrap(),
    ]);
    let rows: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&json).unwrap()).unwrap();
    let rows = rows.as_array().expect("a table of runs");
    assert_eq!(rows.len(), 2, "{rows:?}");
    // The ratelab binary, which does not know the kind, refuses the graph in one line.
    let o = Command::new(env!("CARGO_BIN_EXE_ratelab"))
        .args(["launch", "--processes", "--graph", graph])
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(2), "{err}");
    assert!(err.contains("unknown kind `pd`"), "{err}");
}

/// A message type of the program's own (`examples/common/setpoint.rs`): registered once,
/// a graph file's topic carries it, a Rust kind publishes it typed, a Python node reads it
/// as a class made from its fields, and the run equals the same graph with the setpoint as
/// a built-in `position` message in every figure. The `ratelab` binary, which does not know
/// the type, refuses the graph in one line naming it.
#[test]
fn a_message_type_of_the_programs_own_is_one_definition_and_one_line() {
    let _m = crate::machine::shared();
    for seed in ["0", "1"] {
        let o = Command::new(example("custom_message"))
            .arg(seed)
            .output()
            .unwrap();
        let out = String::from_utf8_lossy(&o.stdout);
        assert!(
            o.status.success(),
            "{out}{}",
            String::from_utf8_lossy(&o.stderr)
        );
        assert!(
            out.contains(&format!("setpoint message, seed {seed}: BALANCED")),
            "{out}"
        );
        assert!(
            out.contains("/reference carries setpoint (501 published)"),
            "{out}"
        );
        assert!(
            out.contains(
                "equal to graphs/cartpole-setpoint.toml (a position message) in every figure: yes"
            ),
            "{out}"
        );
    }
    let o = Command::new(env!("CARGO_BIN_EXE_ratelab"))
        .args(["run", "--clock", "virtual", "--graph"])
        .arg(crate::repo("examples/cartpole-setpoint-msg.toml"))
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(2), "{err}");
    assert_eq!(err.trim().lines().count(), 1, "{err}");
    assert!(err.contains("unknown message type `setpoint`"), "{err}");
}

/// The one definition of a message type drives what a Python node sees: a type registered
/// in Rust becomes a `ratelab` class with its fields, and a Python node publishes it typed
/// onto a topic a Rust node reads.
#[test]
fn a_registered_message_type_crosses_between_rust_and_python_nodes() {
    ratelab::init(); // Python nodes or brains through the library, as a program runs them
    #[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
    struct Gain {
        scale: f64,
    }
    impl ratelab::msg::Message for Gain {
        const NAME: &'static str = "gain_it";
        const CLASS: &'static str = "GainIt";
        const DOC: &'static str = "A scale for the force.";
        const FIELDS: &'static [ratelab::msg::Field] =
            &[ratelab::msg::Field::new("scale", "1", "force multiplier")];
        fn to_fields(&self) -> Vec<f64> {
            vec![self.scale]
        }
        fn from_fields(f: &[f64]) -> Self {
            Gain { scale: f[0] }
        }
    }
    /// The chapter's balancer, its force scaled by the newest gain (1 before the first).
    struct Scaled {
        gain: f64,
        state: Option<StateMsg>,
    }
    impl RustNode for Scaled {
        type Input = (StateMsg, Gain);
        type Output = ForceMsg;
        fn tick(
            &mut self,
            _now: Nanos,
            (state, gain): (Option<&StateMsg>, Option<&Gain>),
        ) -> Option<ForceMsg> {
            if let Some(g) = gain {
                self.gain = g.scale;
            }
            if let Some(s) = state {
                self.state = Some(*s);
            }
            use ratelab::policy::Policy;
            let u = Scripted.act(self.state.as_ref()?)[0];
            Some(ForceMsg {
                newtons: f64::from(u) * 10.0 * self.gain,
            })
        }
    }
    register("scaled_it", |_: &NodeContext<'_>| {
        Ok(Scaled {
            gain: 1.0,
            state: None,
        })
    })
    .unwrap();
    assert!(
        ratelab::msg::MsgType::named("gain_it").is_some(),
        "registered with its kind"
    );
    let dir = tempfile::tempdir().unwrap();
    std::fs::write(
        dir.path().join("gain.py"),
        "from ratelab import GainIt\n\n\
         class Gain:\n    \
             def __init__(self, node):\n        \
                 assert GainIt.FIELDS == ('scale',), GainIt.FIELDS\n        \
                 self.pub = node.create_publisher(GainIt, '/gain', 1)\n        \
                 node.create_timer(node.get_period(), self.tick)\n\n    \
             def tick(self):\n        \
                 self.pub.publish(GainIt(scale=0.0))\n",
    )
    .unwrap();
    let text = "name = \"gain\"\n\
         [[node]]\nname = \"sensor\"\nkind = \"sensor\"\nrate_hz = 50\npublishes = \"/obs\"\n\
         [[node]]\nname = \"gain\"\nkind = \"python\"\nscript = \"gain.py\"\nrate_hz = 50\npublishes = \"/gain\"\n\
         [[node]]\nname = \"policy\"\nkind = \"scaled_it\"\nrate_hz = 50\nsubscribes = [\"/obs\", \"/gain\"]\npublishes = \"/action\"\n\
         [[node]]\nname = \"actuator\"\nkind = \"actuator\"\nrate_hz = 50\nsubscribes = \"/action\"\n\
         [[topic]]\nname = \"/obs\"\ntype = \"state\"\ndepth = 1\n\
         [[topic]]\nname = \"/gain\"\ntype = \"gain_it\"\ndepth = 1\n\
         [[topic]]\nname = \"/action\"\ntype = \"force\"\ndepth = 1\n";
    let path = dir.path().join("g.toml");
    std::fs::write(&path, text).unwrap();
    let spec = GraphSpec::load(&path).unwrap();
    // A gain of 0 from the first tick: the motor never pushes, and the pole falls.
    let m = virtual_run(spec);
    assert!(!m.balanced, "{m:?}");
    assert_eq!(m.topics["/gain"].msg, "gain_it");
    assert!(m.topics["/gain"].published > 0);
}

/// No shape is privileged: an open-loop driver with no chain runs, its metrics say why the
/// chapter's keys are missing, and the chapter's shorthands refuse in one line.
#[test]
fn a_graph_without_the_chapters_chain_runs_and_says_so() {
    let _m = crate::machine::shared();
    let dir = tempfile::tempdir().unwrap();
    let graph = crate::repo("graphs/cartpole-open-loop.toml");
    let o = Command::new(env!("CARGO_BIN_EXE_ratelab"))
        .args(["run", "--clock", "virtual", "--out"])
        .arg(dir.path())
        .arg("--graph")
        .arg(&graph)
        .output()
        .unwrap();
    let out = String::from_utf8_lossy(&o.stdout);
    assert!(
        o.status.success(),
        "{out}{}",
        String::from_utf8_lossy(&o.stderr)
    );
    assert!(out.contains("FELL at t="), "{out}");
    assert!(
        out.contains("has no sensor → policy → actuator chain"),
        "{out}"
    );
    let m: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.path().join("metrics.json")).unwrap())
            .unwrap();
    for key in [
        "control_hz",
        "sensor_hz",
        "queue_depth",
        "policy_ticks",
        "obs_published",
        "action_dropped",
    ] {
        assert!(m.get(key).is_none(), "{key}: {m}");
    }
    assert!(m["without_chain"]
        .as_str()
        .unwrap()
        .contains("cartpole-open-loop"));
    assert_eq!(
        m["policy"],
        "none (the graph has no policy driving the actuator)"
    );
    assert!(m["topics"]["/force"]["published"].as_u64().unwrap() > 0);
    // Twice the same: deterministic like any graph.
    let again = tempfile::tempdir().unwrap();
    let o2 = Command::new(env!("CARGO_BIN_EXE_ratelab"))
        .args(["run", "--clock", "virtual", "--out"])
        .arg(again.path())
        .arg("--graph")
        .arg(&graph)
        .output()
        .unwrap();
    assert!(o2.status.success());
    for f in ["metrics.json", "trace.csv"] {
        assert_eq!(
            std::fs::read(dir.path().join(f)).unwrap(),
            std::fs::read(again.path().join(f)).unwrap(),
            "{f}"
        );
    }
    for flag in ["--control-hz", "--sensor-hz"] {
        let o = Command::new(env!("CARGO_BIN_EXE_ratelab"))
            .args(["run", "--clock", "virtual", flag, "5", "--graph"])
            .arg(&graph)
            .output()
            .unwrap();
        let err = String::from_utf8_lossy(&o.stderr);
        assert_eq!(o.status.code(), Some(2), "{flag}: {err}");
        assert_eq!(err.trim().lines().count(), 1, "{err}");
        assert!(
            err.contains(&format!("{flag} speaks of the chapter's chain")),
            "{err}"
        );
    }
}

/// The built-in kinds are made of the registry's public parts only: each `def()` registered
/// again under another name through `register_kind`, as a program registers its own, runs
/// the chapter's, a safety node's and a camera's graphs exactly as the built-in kinds do; and a kind of a program's own with
/// docs and a parameter with its unit and range (`rust_kind`) is printed and checked like a
/// built-in one.
#[test]
fn the_built_in_kinds_are_registered_through_the_public_api_and_are_its_examples() {
    use ratelab::graph::kind::{KindDef, ParamDef, Params};
    use ratelab::graph::nodes;
    use ratelab::graph::registry::{kinds_table, register_kind, rust_kind};
    // Every built-in kind of fixed ports (all but the Python and ROS 2 adapters), again.
    let again: Vec<&str> = ratelab::graph::registry::kinds()
        .into_iter()
        .filter(|k| k.code() == ratelab::graph::kind::Code::BuiltIn)
        .map(|k| k.as_str())
        .collect();
    assert!(again.len() >= 7, "{again:?}");
    for (name, def) in [
        ("sensor_again", nodes::sensor::def()),
        ("camera_again", nodes::camera::def()),
        ("image_estimator_again", nodes::image_estimator::def()),
        ("estimator_again", nodes::estimator::def()),
        ("policy_again", nodes::policy::def()),
        ("safety_again", nodes::safety::def()),
        ("actuator_again", nodes::actuator::def()),
    ] {
        assert!(again.contains(&def.name), "{} is built in", def.name);
        register_kind(KindDef { name, ..def }).unwrap();
    }
    // The chapter's graph, a safety node's, and a camera's (camera, image estimator,
    // estimator): every one of them.
    for file in [
        "graphs/cartpole.toml",
        "graphs/cartpole-safety.toml",
        "graphs/cartpole-camera.toml",
    ] {
        let text = std::fs::read_to_string(crate::repo(file)).unwrap();
        let mut registered = text.clone();
        for kind in &again {
            registered = registered.replace(
                &format!("kind = \"{kind}\""),
                &format!("kind = \"{kind}_again\""),
            );
        }
        assert_ne!(registered, text);
        let built_in = virtual_run(GraphSpec::parse(&text, file).unwrap());
        let registered = virtual_run(GraphSpec::parse(&registered, file).unwrap());
        // Every figure the same; only the kinds' names differ.
        assert_eq!(
            serde_json::to_string(&registered)
                .unwrap()
                .replace("_again\"", "\""),
            serde_json::to_string(&built_in).unwrap(),
            "{file}"
        );
    }
    // A program's own kind, with what a built-in one carries: docs, a parameter with its
    // unit, default and range, checked when the graph file is read.
    static PUSH: [ParamDef; 1] = [ParamDef {
        name: "newtons",
        unit: "N",
        doc: "the force it pushes with",
        default: 1.0,
        min: -10.0,
        max: 10.0,
    }];
    let mut def = rust_kind("push_documented", |cx: &NodeContext<'_>| {
        Ok(Push {
            newtons: cx.param_f64("newtons", 0.0)?,
            sensed: false,
        })
    });
    def.doc = "pushes the cart with a constant force once it has sensed";
    def.params = Params::Numbers(&PUSH);
    register_kind(def).unwrap();
    let table = kinds_table();
    let row = table
        .lines()
        .find(|l| l.starts_with("| `push_documented` |"))
        .unwrap();
    assert!(row.contains("`newtons` N (default 1, -10…10)"), "{row}");
    assert!(row.contains("pushes the cart"), "{row}");
    let too_hard = graph_with("push_documented", "newtons = 50");
    let err = GraphSpec::parse(&too_hard, "g.toml")
        .unwrap_err()
        .to_string();
    assert!(err.contains("newtons"), "{err}");
    assert!(
        register_kind(nodes::sensor::def()).is_err(),
        "sensor is taken"
    );
}
