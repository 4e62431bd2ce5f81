//! External nodes (`kind = "external"`): a ROS 2 node fills a graph node. The node here is
//! `examples/ros2/zenoh_policy.py`, the chapter's scripted balancer written as a ROS 2 node
//! would be with independent implementations only (PyPI `eclipse-zenoh`, `rosbags`); the
//! stand-in (`tests/ros2/standin.py`) plays the Zenoh router and lists what ROS 2 sees.

use super::ros2::{connect_to, endpoints, oracle_python, ratelab, Oracle, StandIn};
use crate::distributed::free_port;
use crate::repo;
use serde_json::Value;
use std::path::Path;
use std::process::{Command, Stdio};

/// The external policy (`examples/ros2/zenoh_policy.py`), ready: its tokens declared.
struct External;

impl External {
    fn start(endpoint: &str, domain: u32, rate_hz: &str, extra: &[&str]) -> Oracle {
        let domain = domain.to_string();
        let args = [&[endpoint, &domain, rate_hz][..], extra].concat();
        Oracle::start(
            "examples/ros2/zenoh_policy.py",
            &args,
            "the external policy",
        )
    }
}

/// metrics.json without what names the graph, the brain and the nodes' kinds, and
/// trace.csv, of the run written to `dir`.
fn figures(dir: &Path) -> (String, Vec<u8>) {
    let trace = std::fs::read(dir.join("trace.csv")).unwrap();
    (metrics(dir), trace)
}

/// metrics.json of the run written to `dir`, without what names the graph, the brain and
/// the nodes' kinds.
fn metrics(dir: &Path) -> String {
    let text = std::fs::read_to_string(dir.join("metrics.json")).unwrap();
    crate::metrics_without_names(serde_json::from_str(&text).unwrap())
}

const GRAPH: &str = "graphs/cartpole-external.toml";

#[test]
fn an_external_ros_2_policy_in_lockstep_gives_the_builtin_policys_figures_byte_for_byte() {
    let _m = crate::machine::shared();
    let endpoint = format!("tcp/127.0.0.1:{}", free_port());
    let standin = StandIn::start("router", &endpoint, 4, &[]);
    let (a, b) = (tempfile::tempdir().unwrap(), tempfile::tempdir().unwrap());
    let cases = [("0", "50"), ("1", "50"), ("2", "50"), ("0", "5")];
    for (seed, hz) in cases {
        let common = ["--clock", "virtual", "--duration", "2", "--force"];
        let args = |dir: &Path| -> Vec<String> {
            let mut v: Vec<String> = ["run", "--seed", seed, "--control-hz", hz, "--out"]
                .map(String::from)
                .to_vec();
            v.push(dir.to_string_lossy().into_owned());
            v.extend(common.map(String::from));
            v
        };
        let builtin = args(a.path());
        let builtin: Vec<&str> = builtin.iter().map(String::as_str).collect();
        let (code, _, err) = ratelab(&builtin, &[]);
        assert_eq!(code, 0, "{err}");

        let policy = External::start(&endpoint, 4, hz, &[]);
        let mut ext = args(b.path());
        ext.extend(["--graph", GRAPH, "--ros2", "4"].map(String::from));
        let ext: Vec<&str> = ext.iter().map(String::as_str).collect();
        let (code, out, err) = ratelab(&ext, &[connect_to(&endpoint)]);
        let did = policy.report();
        assert_eq!(code, 0, "{out}{err}");
        assert!(!err.contains("missed"), "seed {seed}, {hz} Hz: {err}");
        assert!(out.contains("policy=external ROS 2 node 'policy'"), "{out}");
        let (want, got) = (figures(a.path()), figures(b.path()));
        assert!(
            want.0 == got.0,
            "seed {seed}, {hz} Hz: metrics differ\n{}\n{}",
            want.0,
            got.0
        );
        assert!(want.1 == got.1, "seed {seed}, {hz} Hz: trace differs");
        // One message per tick, each one delivered: the policy's ticks.
        let m: Value =
            serde_json::from_str(&std::fs::read_to_string(b.path().join("metrics.json")).unwrap())
                .unwrap();
        assert_eq!(did["published"], m["policy_ticks"], "{did} {m}");
    }
    // ROS 2 saw the external node's own endpoints alone for 'policy' (one MP and one MS
    // per run, with the QoS it declared): ratelab declared none for it.
    let r = standin.report();
    let e = endpoints(&r);
    let of_policy: Vec<_> = e.iter().filter(|x| x.1 == "policy").collect();
    assert_eq!(of_policy.len(), 2 * cases.len(), "{of_policy:?}");
    for qos in r["endpoints"].as_array().unwrap() {
        if qos["node"] == "policy" {
            assert_eq!(qos["qos"], "1::,1:,:,:,,", "{qos}");
        }
    }
}

#[test]
fn an_external_ros_2_policy_keeps_the_pole_up_under_the_real_clock() {
    let _m = crate::machine::alone();
    let endpoint = format!("tcp/127.0.0.1:{}", free_port());
    let _standin = StandIn::start("router", &endpoint, 5, &[]);
    let policy = External::start(&endpoint, 5, "50", &[]);
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path().to_str().unwrap();
    let args = [
        "run",
        "--clock",
        "real",
        "--duration",
        "3",
        "--graph",
        GRAPH,
        "--ros2",
        "5",
        "--out",
        d,
    ];
    let (code, out, err) = ratelab(&args, &[connect_to(&endpoint)]);
    let did = policy.report();
    assert_eq!(code, 0, "{out}{err}");
    let m: Value =
        serde_json::from_str(&std::fs::read_to_string(dir.path().join("metrics.json")).unwrap())
            .unwrap();
    assert_eq!(m["balanced"], true, "{out}{err}");
    // It published about 50 a second, and what it published drove the actuator.
    let sent = did["published"].as_u64().unwrap();
    assert!((100..=200).contains(&sent), "{did}");
    let action = m["action_published"].as_u64().unwrap();
    assert!(action >= sent - 5 && action <= sent, "{action} of {sent}");
}

#[test]
fn an_external_node_missing_of_another_type_or_silent_is_said_in_one_line() {
    let _m = crate::machine::shared();
    let dir = tempfile::tempdir().unwrap();
    let text = std::fs::read_to_string(repo(GRAPH)).unwrap();
    let graph = |from: &str, to: &str| {
        let p = dir.path().join(format!("g{}.toml", to.len()));
        std::fs::write(&p, text.replace(from, to)).unwrap();
        p.to_string_lossy().into_owned()
    };
    // Short waits, and a liveliness lease: a node that stops delivering is not alive.
    let quick = graph(
        "appear_timeout_s = 10, tick_timeout_ms = 2000 }",
        "appear_timeout_s = 1, tick_timeout_ms = 50 }\nliveliness_lease_ms = 100",
    );
    let one_line = |err: &str| {
        assert_eq!(err.trim_end().lines().count(), 1, "{err}");
    };
    // A refusal: exit 2, saying each of `wants`; its stderr.
    let refused = |args: &[&str], env: &[(&str, String)], wants: &[&str]| -> String {
        let (code, _, err) = ratelab(args, env);
        assert_eq!(code, 2, "{err}");
        for want in wants {
            assert!(err.contains(want), "{want}: {err}");
        }
        err
    };

    // Without --ros2 nothing can fill it.
    let err = refused(
        &["run", "--graph", GRAPH],
        &[],
        &["node 'policy' is external", "--ros2"],
    );
    one_line(&err);
    // Graph files: an external node must publish, and takes only its two params.
    for (from, to, want) in [
        (
            "publishes = \"/action\"\nparams",
            "params",
            "an external node must publish a topic",
        ),
        (
            "tick_timeout_ms = 2000",
            "tick_timeout_ms = 0",
            "params.tick_timeout_ms must be a number in 1..=60000",
        ),
        (
            "tick_timeout_ms = 2000",
            "script = 2",
            "appear_timeout_s and tick_timeout_ms, not 'script'",
        ),
    ] {
        refused(&["run", "--graph", &graph(from, to)], &[], &[want]);
    }

    let endpoint = format!("tcp/127.0.0.1:{}", free_port());
    let _standin = StandIn::start("router", &endpoint, 6, &[]);
    let env = [connect_to(&endpoint)];
    let quick_run = ["run", "--graph", &quick, "--ros2", "6", "--duration", "1"];
    let run = |extra: &[&str]| ratelab(&[&quick_run[..], extra].concat(), &env);
    // Never appears: named, with what is missing, after its bounded wait.
    let err = refused(
        &quick_run,
        &env,
        &[
            "external node 'policy' did not appear on ROS 2 domain 6 within 1.0 s",
            "an NN token named 'policy'",
            "publishes /action (std_msgs/msg/Float64)",
        ],
    );
    one_line(&err);
    // The wrong type: said from its token, before the run.
    let wrong = External::start(&endpoint, 6, "50", &["--type", "float32"]);
    let err = refused(
        &quick_run,
        &env,
        &["external node 'policy' publishes /action as std_msgs/msg/Float32, but the graph's /action is std_msgs/msg/Float64"],
    );
    drop(wrong);
    one_line(&err);
    // There but silent: each tick waits its timeout, and the misses are reported.
    let mute = External::start(&endpoint, 6, "50", &["--mute"]);
    let (code, out, err) = run(&["--clock", "virtual"]);
    drop(mute);
    assert_eq!(code, 0, "{out}{err}");
    assert!(
        err.contains("external node 'policy' missed") && err.contains("tick(s)"),
        "{err}"
    );
    assert!(
        format!("{out}{err}").contains("policy not alive 1× (lease 100 ms)"),
        "{out}{err}"
    );
    // Two external nodes under the virtual clock would share each /clock tick: refused.
    let two = dir.path().join("two.toml");
    std::fs::write(
        &two,
        text.replace("publishes = \"/action\"\nparams", "publishes = \"/mid\"\nparams")
            + "\n[[node]]\nname = \"limiter\"\nkind = \"external\"\nrate_hz = 50\nsubscribes = \"/mid\"\npublishes = \"/action\"\n\n[[topic]]\nname = \"/mid\"\ntype = \"force\"\ndepth = 1\n",
    )
    .unwrap();
    let err = refused(
        &[
            "run",
            "--graph",
            two.to_str().unwrap(),
            "--ros2",
            "6",
            "--clock",
            "virtual",
        ],
        &env,
        &["has 2 external nodes: under the virtual clock the lockstep takes one"],
    );
    one_line(&err);
    // Two messages a tick: the second is dropped and counted, and every tick still takes
    // its own (the pole stays up, no tick missed).
    // (The shipped graph's 2 s tick timeout: a first tick may take longer than 50 ms while
    // the node's Python warms up, and would be missed.)
    let double = External::start(&endpoint, 6, "50", &["--double"]);
    let (code, out, err) = ratelab(
        &[
            "run",
            "--graph",
            GRAPH,
            "--ros2",
            "6",
            "--duration",
            "1",
            "--clock",
            "virtual",
        ],
        &env,
    );
    drop(double);
    assert_eq!(code, 0, "{out}{err}");
    assert!(
        err.contains("came outside their tick") && !err.contains("missed"),
        "{err}"
    );
    assert!(out.contains("BALANCED"), "{out}");
    // A hostile peer beside the node: a token whose type name holds an escape sequence,
    // and one of another type for the same node and topic. Neither stops the run: the
    // first is ignored with a note (written out, never raw), the second does not matter
    // while a token of the right type is there.
    let forged = External::start(&endpoint, 6, "50", &["--forge"]);
    let (code, out, err) = ratelab(
        &[
            "run",
            "--graph",
            GRAPH,
            "--ros2",
            "6",
            "--duration",
            "1",
            "--clock",
            "virtual",
        ],
        &env,
    );
    drop(forged);
    assert_eq!(code, 0, "{out}{err}");
    assert!(out.contains("BALANCED"), "{out}");
    assert!(
        err.contains("ignored 1 malformed ROS 2 liveliness token(s) on domain 6")
            && err.contains("Float64\\u{1b}[2J\\u{1b}]0;pwned\\u{7}_"),
        "{err}"
    );
    assert!(
        !format!("{out}{err}").contains('\u{1b}'),
        "raw ESC: {err:?}"
    );
}

#[test]
fn python_message_classes_convert_to_and_from_ros_2_as_the_bridge_does() {
    use ratelab::msg::{ForceMsg, ImageMsg, Message, MsgData, MsgType, PositionMsg, StateMsg};
    let encode = |d: &MsgData, stamp, out: &mut Vec<u8>| {
        assert!((d.msg_type().ros2().unwrap().encode)(d, stamp, out))
    };
    let decode = |t: MsgType, bytes: &[u8]| (t.ros2().unwrap().decode)(bytes);
    let position = |cart_pos_m, pole_angle_rad| {
        MsgData::new(PositionMsg {
            cart_pos_m,
            pole_angle_rad,
        })
    };
    use std::io::Write;
    // A 4 × 3 mono8 image whose rows are padded to 5 bytes.
    let pixels: Vec<u8> = (0..15u8).map(|i| i * 17).collect();
    let pixels_hex: String = pixels.iter().map(|x| format!("{x:02x}")).collect();
    let image = |data: &[u8]| ImageMsg {
        height: 3,
        width: 4,
        encoding: "mono8".into(),
        step: 5,
        data: data.to_vec().into(),
    };
    let th = 0.125f64;
    let obs = [0.5f32, -1.0, th.cos() as f32, th.sin() as f32, 2.0];
    let hex = |d: MsgData| {
        let mut b = Vec::new();
        encode(&d, ratelab::Nanos(7), &mut b);
        b.iter().map(|x| format!("{x:02x}")).collect::<String>()
    };
    let input = serde_json::json!({
        "state": hex(MsgData::new(obs)),
        "position": hex(position(0.25, -0.5)),
        "force": hex(MsgData::new(ForceMsg { newtons: -3.5 })),
        "image": hex(MsgData::new(image(&pixels))),
        "values": {
            "state": obs.map(f64::from),
            "position": [0.25, -0.5],
            "force": [-3.5],
            "image": [3, 4, "mono8", 5, pixels_hex],
        },
    });
    let mut child = Command::new(oracle_python())
        .arg(repo("tests/ros2/message_classes.py"))
        .stdin(Stdio::piped())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    child
        .stdin
        .take()
        .unwrap()
        .write_all(input.to_string().as_bytes())
        .unwrap();
    let o = child.wait_with_output().unwrap();
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(o.status.success(), "{err}");
    let r: Value = serde_json::from_slice(&o.stdout).unwrap();
    let floats = |v: &Value| -> Vec<f64> {
        v.as_array()
            .unwrap()
            .iter()
            .map(|x| x.as_f64().unwrap())
            .collect()
    };
    // ratelab's CDR read by rosbags, then by the Python classes: the same values (the
    // state's cos θ and sin θ through the angle, equal as float32, as on the topic).
    let state: Vec<f32> = floats(&r["from_ros"]["state"])
        .iter()
        .map(|&x| x as f32)
        .collect();
    assert_eq!(state, obs);
    assert_eq!(floats(&r["from_ros"]["position"]), [0.25, -0.5]);
    assert_eq!(floats(&r["from_ros"]["force"]), [-3.5]);
    // The classes' to_ros() serialized by rosbags, read by ratelab's decoder: the same.
    let bytes = |k: &str| -> Vec<u8> {
        let h = r["to_ros"][k].as_str().unwrap();
        (0..h.len())
            .step_by(2)
            .map(|i| u8::from_str_radix(&h[i..i + 2], 16).unwrap())
            .collect()
    };
    assert_eq!(
        decode(StateMsg::TYPE, &bytes("state")),
        Ok(MsgData::new(obs))
    );
    assert_eq!(
        decode(PositionMsg::TYPE, &bytes("position")),
        Ok(position(0.25, -0.5))
    );
    assert_eq!(
        decode(ForceMsg::TYPE, &bytes("force")),
        Ok(MsgData::new(ForceMsg { newtons: -3.5 }))
    );
    assert_eq!(
        r["from_ros"]["image"],
        serde_json::json!([3, 4, "mono8", 5, pixels_hex])
    );
    assert_eq!(
        decode(ImageMsg::TYPE, &bytes("image")),
        Ok(MsgData::new(image(&pixels)))
    );
    assert_eq!(r["ros_type"]["image"], "sensor_msgs/msg/Image");
    assert_eq!(r["ros_type"]["state"], "sensor_msgs/msg/JointState");
    assert_eq!(r["ros_type"]["force"], "std_msgs/msg/Float64");
}

#[test]
fn an_external_policy_in_a_launch_across_processes_runs_beside_its_input_and_equals_the_builtin() {
    let _m = crate::machine::shared();
    let endpoint = format!("tcp/127.0.0.1:{}", free_port());
    let _standin = StandIn::start("router", &endpoint, 8, &[]);
    let (a, b) = (tempfile::tempdir().unwrap(), tempfile::tempdir().unwrap());
    let common = ["--clock", "virtual", "--duration", "2", "--force", "--out"];
    let (code, _, err) = ratelab(
        &[&["run"][..], &common, &[a.path().to_str().unwrap()]].concat(),
        &[],
    );
    assert_eq!(code, 0, "{err}");
    let policy = External::start(&endpoint, 8, "50", &[]);
    let (code, out, err) = ratelab(
        &[
            &["launch", "--processes", "--graph", GRAPH, "--ros2", "8"][..],
            &common,
            &[b.path().to_str().unwrap()],
        ]
        .concat(),
        &[connect_to(&endpoint)],
    );
    let did = policy.report();
    assert_eq!(code, 0, "{out}{err}");
    // Its proxy runs beside its input's publisher, the plant's process.
    assert!(out.contains("robot [sensor, policy, actuator]"), "{out}");
    assert_eq!(metrics(a.path()), metrics(b.path()));
    assert_eq!(did["published"], 101, "{did}");

    // Placed away from its input, it is refused in one line.
    let dir = tempfile::tempdir().unwrap();
    let g = dir.path().join("g.toml");
    let text = std::fs::read_to_string(repo(GRAPH)).unwrap();
    std::fs::write(
        &g,
        text.replace(
            "kind = \"external\"",
            "kind = \"external\"\nprocess = \"brain\"",
        ),
    )
    .unwrap();
    let (code, _, err) = ratelab(
        &[
            "launch",
            "--processes",
            "--ros2",
            "8",
            "--graph",
            g.to_str().unwrap(),
        ],
        &[connect_to(&endpoint)],
    );
    assert_eq!(code, 2, "{err}");
    assert!(
        err.contains("external node 'policy' is placed in process 'brain', but its input /obs comes from process 'robot'"),
        "{err}"
    );
}
