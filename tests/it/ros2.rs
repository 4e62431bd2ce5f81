//! `--ros2`: the graph as ROS 2's tools see it, checked by a stand-in written with
//! independent implementations only (`tests/ros2/standin.py`: PyPI `eclipse-zenoh` for the
//! wire, `rosbags` for RIHS01 hashes and CDR), in the oracle environment `scripts/test.sh`
//! makes (`RATELAB_ORACLE_PYTHON`).

use crate::distributed::free_port;
use crate::repo;
use serde_json::Value;
use std::io::{BufRead, BufReader, Read};
use std::process::{Child, Command, Stdio};

pub(crate) fn oracle_python() -> String {
    std::env::var("RATELAB_ORACLE_PYTHON").expect(
        "RATELAB_ORACLE_PYTHON is not set: run the tests with scripts/test.sh (it makes the oracle environment)",
    )
}

/// What the oracle's Python script `script` (run as `python -c script args…`) prints on
/// stdout, read as JSON; the script must succeed (its stderr is the failure's message).
pub(crate) fn oracle_json(script: &str, args: &[&str]) -> Value {
    let o = Command::new(oracle_python())
        .arg("-c")
        .arg(script)
        .args(args)
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    serde_json::from_slice(&o.stdout).unwrap()
}

/// A test oracle's Python script (`tests/ros2/*.py`), running and ready: it printed
/// `ready` on stdout; closing its stdin tells it to finish and print one JSON report.
pub(crate) struct Oracle {
    child: Child,
    what: &'static str,
}

impl Oracle {
    /// Start `script` with `args` and wait for its `ready` (`what` names it in failures).
    pub(crate) fn start(script: &str, args: &[&str], what: &'static str) -> Oracle {
        let mut child = Command::new(oracle_python())
            .arg(repo(script))
            .args(args)
            .stdin(Stdio::piped())
            .stdout(Stdio::piped())
            .stderr(Stdio::inherit())
            .spawn()
            .unwrap();
        let mut line = String::new();
        BufReader::new(child.stdout.as_mut().unwrap())
            .read_line(&mut line)
            .unwrap();
        assert_eq!(line.trim(), "ready", "{what} did not start");
        Oracle { child, what }
    }

    /// Tell it ratelab is done; its report.
    pub(crate) fn report(mut self) -> Value {
        drop(self.child.stdin.take());
        let mut out = String::new();
        self.child
            .stdout
            .take()
            .unwrap()
            .read_to_string(&mut out)
            .unwrap();
        assert!(self.child.wait().unwrap().success(), "{} failed", self.what);
        serde_json::from_str(out.trim()).unwrap_or_else(|e| panic!("{e}: {out}"))
    }
}

impl Drop for Oracle {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

/// The stand-in (`tests/ros2/standin.py`), ready: its subscriptions declared.
pub(crate) struct StandIn;

impl StandIn {
    pub(crate) fn start(mode: &str, endpoint: &str, domain: u32, extra: &[&str]) -> Oracle {
        let domain = domain.to_string();
        let args = [&[mode, endpoint, &domain][..], extra].concat();
        Oracle::start("tests/ros2/standin.py", &args, "the stand-in")
    }
}

pub(crate) fn ratelab(args: &[&str], env: &[(&str, String)]) -> (i32, String, String) {
    let mut cmd = Command::new(env!("CARGO_BIN_EXE_ratelab"));
    cmd.env_remove("ROS_DOMAIN_ID")
        .env_remove("ZENOH_ROUTER_CHECK_ATTEMPTS")
        .env_remove("ZENOH_CONFIG_OVERRIDE");
    for (k, v) in env {
        cmd.env(k, v);
    }
    crate::ratelab_in_repo_with(args, &mut cmd)
}

pub(crate) fn connect_to(endpoint: &str) -> (&'static str, String) {
    (
        "ZENOH_CONFIG_OVERRIDE",
        format!("connect/endpoints=[\"{endpoint}\"]"),
    )
}

/// The stand-in's `/clock` samples, ns.
pub(crate) fn clock_ns(r: &Value) -> Vec<u64> {
    r["clock_ns"]
        .as_array()
        .unwrap()
        .iter()
        .map(|v| v.as_u64().unwrap())
        .collect()
}

/// Assert `msgs` are numbered `first`, `first` + 1, … with none missing.
pub(crate) fn assert_every_one_from(msgs: &[Value], first: i64) {
    for (i, m) in msgs.iter().enumerate() {
        assert_eq!(m["seq"].as_i64(), Some(first + i as i64), "message {i}");
    }
}

pub(crate) fn strs(v: &Value) -> Vec<String> {
    v.as_array()
        .unwrap()
        .iter()
        .map(|s| s.as_str().unwrap().to_string())
        .collect()
}

/// What `ros2 node list` and `ros2 topic list -v` show of the chapter's graph, as the
/// stand-in `r` saw it: its three nodes and `ratelab` (the `/clock` publisher), and who
/// publishes and subscribes what, with which type.
fn assert_the_chapters_graph(r: &Value) {
    assert_eq!(
        strs(&r["nodes"]),
        ["actuator", "policy", "ratelab", "sensor"]
    );
    let e = |k: &str, n: &str, t: &str, ty: &str| (k.into(), n.into(), t.into(), ty.into());
    let (js, f64t) = ("sensor_msgs/msg/JointState", "std_msgs/msg/Float64");
    assert_eq!(
        endpoints(r),
        vec![
            e("MP", "policy", "/action", f64t),
            e("MP", "ratelab", "/clock", "rosgraph_msgs/msg/Clock"),
            e("MP", "sensor", "/obs", js),
            e("MS", "actuator", "/action", f64t),
            e("MS", "policy", "/obs", js),
        ]
    );
}

/// The topics every ROS 2 node publishes besides its own (`ratelab::ros2::node_api`).
pub(crate) const NODE_TOPICS: [&str; 2] = ["/rosout", "/parameter_events"];

/// Each of `nodes` publishes `/rosout` and `/parameter_events` and serves the six parameter
/// services and `~/get_type_description`, as the stand-in `r` saw their tokens: each token's type, type hash and QoS
/// the same as a real rclpy node's over real rmw_zenoh_cpp (`real-rclpy-talker.json`).
pub(crate) fn assert_every_node_s_own_endpoints(r: &Value, nodes: &[&str]) {
    let real = crate::ros2_cli::real_capture("real-rclpy-talker.json");
    let real: Vec<&Value> = real["tokens_parsed"].as_array().unwrap().iter().collect();
    let demangle = |s: &Value| s.as_str().unwrap().replace('%', "/");
    let real_of = |kind: &str, name: &str| -> (String, String, String) {
        let t = real
            .iter()
            .find(|t| t["kind"] == kind && demangle(&t["topic"]).ends_with(name))
            .unwrap_or_else(|| panic!("the real node has no {kind} {name}"));
        // rcl_interfaces::srv::dds_::GetParameters_ -> rcl_interfaces/srv/GetParameters
        let dds: Vec<&str> = t["type"].as_str().unwrap().split("::").collect();
        let ty = format!("{}/{}/{}", dds[0], dds[1], dds[3].trim_end_matches('_'));
        let qos = t["qos"].as_str().unwrap().to_string();
        (ty, t["type_hash"].as_str().unwrap().into(), qos)
    };
    for node in nodes {
        for topic in NODE_TOPICS {
            let e = r["endpoints"]
                .as_array()
                .unwrap()
                .iter()
                .find(|e| e["kind"] == "MP" && e["node"] == *node && e["topic"] == topic)
                .unwrap_or_else(|| panic!("{node} has no {topic} publisher: {r}"));
            let (ty, hash, qos) = real_of("MP", topic);
            assert_eq!(
                (&e["type"], &e["hash"], &e["qos"]),
                (&Value::from(ty), &Value::from(hash), &Value::from(qos)),
                "{node} {topic}"
            );
        }
        let services: Vec<&Value> = r["services"]
            .as_array()
            .unwrap()
            .iter()
            .filter(|s| s["node"] == *node)
            .collect();
        assert_eq!(services.len(), 7, "{node}: {services:?}");
        for suffix in [
            "describe_parameters",
            "get_parameters",
            "get_parameter_types",
            "list_parameters",
            "set_parameters",
            "set_parameters_atomically",
            "get_type_description",
        ] {
            let name = format!("/{node}/{suffix}");
            let s = services
                .iter()
                .find(|s| s["service"] == name.as_str())
                .unwrap_or_else(|| panic!("no {name}: {services:?}"));
            let (ty, hash, qos) = real_of("SS", &format!("/{suffix}"));
            assert_eq!(s["kind"], "SS");
            assert_eq!(
                (&s["type"], &s["hash"], &s["qos"]),
                (&Value::from(ty), &Value::from(hash), &Value::from(qos)),
                "{name}"
            );
        }
    }
}

/// `(kind, node, topic, type)` of each endpoint token of the graph's own topics (not
/// [`NODE_TOPICS`]).
pub(crate) fn endpoints(r: &Value) -> Vec<(String, String, String, String)> {
    let mut e: Vec<_> = r["endpoints"]
        .as_array()
        .unwrap()
        .iter()
        .filter(|e| !NODE_TOPICS.contains(&e["topic"].as_str().unwrap()))
        .map(|e| {
            let s = |k: &str| e[k].as_str().unwrap().to_string();
            (s("kind"), s("node"), s("topic"), s("type"))
        })
        .collect();
    e.sort();
    e
}

fn trace(dir: &std::path::Path) -> Vec<std::collections::HashMap<String, String>> {
    let text = std::fs::read_to_string(dir.join("trace.csv")).unwrap();
    let mut lines = text.lines();
    let head: Vec<&str> = lines.next().unwrap().split(',').collect();
    lines
        .map(|l| {
            head.iter()
                .zip(l.split(','))
                .map(|(k, v)| (k.to_string(), v.to_string()))
                .collect()
        })
        .collect()
}

fn f(v: &Value) -> f64 {
    v.as_f64().unwrap()
}

#[test]
fn ros_2s_tools_see_the_graph_its_types_messages_and_clock_and_the_results_do_not_change() {
    let endpoint = format!("tcp/127.0.0.1:{}", free_port());
    let standin = StandIn::start("router", &endpoint, 3, &[]);
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("ros2");
    // The run, with --ros2 and (at the end) without.
    let run = |extra: &[&str]| {
        let mut args = vec!["run", "--clock", "virtual", "--duration", "1"];
        args.extend_from_slice(&["--qos", "/action:deadline_ms=40"]);
        args.extend_from_slice(extra);
        ratelab(&args, &[connect_to(&endpoint)])
    };
    let (code, stdout, stderr) = run(&["--ros2", "3", "--out", out.to_str().unwrap()]);
    let r = standin.report();
    assert_eq!(code, 0, "{stdout}{stderr}");
    assert!(
        stderr.contains(&format!(
            "offering the graph to ROS 2 on domain 3 with /clock, through the Zenoh router at {endpoint}"
        )),
        "{stderr}"
    );
    assert!(stdout.contains("ROS 2: 102 messages offered"), "{stdout}");
    assert_eq!(r["errors"], Value::Array(vec![]), "{r}");

    // ros2 node list / ros2 topic list -v: the nodes, who publishes and subscribes what.
    assert_the_chapters_graph(&r);
    // Each node's /rosout, /parameter_events and parameter services, as a real node's.
    assert_every_node_s_own_endpoints(&r, &["actuator", "policy", "ratelab", "sensor"]);
    // Each node said its parameters on /parameter_events as the offer started: the graph
    // file's (the policy's rate), use_sim_time (ratelab's /clock node makes the time).
    let events = r["topics"]["/parameter_events"].as_array().unwrap();
    let event = |node: &str| events.iter().find(|e| e["node"] == node).unwrap();
    assert_eq!(events.len(), 4, "{events:?}");
    assert_eq!(
        event("/policy")["new"]["rate_hz"],
        serde_json::json!([3, 50.0])
    );
    assert_eq!(
        event("/policy")["new"]["use_sim_time"],
        serde_json::json!([1, true])
    );
    assert_eq!(
        event("/ratelab")["new"],
        serde_json::json!({"start_type_description_service": [1, true], "use_sim_time": [1, false]})
    );
    // Every type's hash is rosbags' hash_rihs01 of it (rcl_interfaces' Log and
    // ParameterEvent too).
    for (ty, ok) in r["hash_ok"].as_object().unwrap() {
        assert_eq!(ok, &Value::Bool(true), "{ty}");
    }
    // The QoS strings, read by rmw's enums: best effort (2), keep last 1; /action has its
    // 40 ms deadline; /clock is best effort, depth 1.
    let graph_s = |e: &&Value| !NODE_TOPICS.contains(&e["topic"].as_str().unwrap());
    for ep in r["endpoints"].as_array().unwrap().iter().filter(graph_s) {
        let qos: Vec<&str> = ep["qos"].as_str().unwrap().split(':').collect();
        assert_eq!(qos[0], "2", "{ep}");
        assert_eq!(qos[2], ",1", "{ep}");
        let deadline = if ep["topic"] == "/action" {
            "0,40000000"
        } else {
            ","
        };
        assert_eq!(qos[3], deadline, "{ep}");
    }
    // Withdrawn at the end (here with the session; a bridge's own withdrawal, its session
    // staying open as in the lab: `a_finished_bridge_withdraws_its_tokens_…`).
    assert_eq!(r["alive_at_end"], Value::Array(vec![]));

    // ros2 topic echo: every message, in order, numbered 1, 2, … by one publisher, with the
    // values ratelab ran with.
    let rows = trace(&out);
    let obs = r["topics"]["/obs"].as_array().unwrap();
    let action = r["topics"]["/action"].as_array().unwrap();
    assert_eq!((obs.len(), action.len()), (51, 51));
    for msgs in [obs, action] {
        assert_every_one_from(msgs, 1);
        assert!(msgs.iter().all(|m| m["gid"] == msgs[0]["gid"]));
    }
    assert_ne!(obs[0]["gid"], action[0]["gid"]);
    // Each sample stamped by its publisher's session (its ZID, the one in its tokens), as a
    // real rmw_zenoh_cpp node's are (the captures), not by the router.
    let zid_of = |topic: &str| -> Value {
        let mp = r["endpoints"]
            .as_array()
            .unwrap()
            .iter()
            .find(|e| e["kind"] == "MP" && e["topic"] == topic);
        mp.unwrap()["zid"].clone()
    };
    for (topic, msgs) in [("/obs", obs), ("/action", action)] {
        assert!(
            msgs.iter().all(|m| m["stamp_zid"] == zid_of(topic)),
            "{topic}: {msgs:?}"
        );
    }
    for (i, row) in rows.iter().enumerate() {
        let stamp_ns = |m: &Value| m["stamp_ns"].as_u64().unwrap();
        // The force the actuator applied at step i is /action's message i, in newtons.
        let applied = row["action"].parse::<f64>().unwrap() * 10.0;
        assert_eq!(f(&action[i]["data"]), applied, "step {i}");
        // Step i's resulting state is the sensor's next reading (float32 in the
        // observation; the angle is atan2 of its cos and sin).
        if let Some(next) = obs.get(i + 1) {
            let cart = row["cart_pos"].parse::<f64>().unwrap();
            let angle = row["pole_angle"].parse::<f64>().unwrap();
            assert!((f(&next["position"][0]) - cart).abs() < 1e-6, "step {i}");
            assert!((f(&next["position"][1]) - angle).abs() < 1e-6, "step {i}");
            assert_eq!(next["velocity"].as_array().unwrap().len(), 2);
            assert_eq!(strs(&next["name"]), ["slider", "hinge"]);
            assert_eq!(stamp_ns(next), (i as u64 + 1) * 20_000_000);
        }
    }

    // /clock: the run's time, from 0 to the end, never behind a message's stamp.
    let clock = clock_ns(&r);
    assert_eq!(clock.first(), Some(&0));
    assert_eq!(clock.last(), Some(&1_000_000_000));
    assert!(clock.windows(2).all(|w| w[0] < w[1]), "{clock:?}");

    // The same run without --ros2: the same metrics, byte for byte.
    let plain = dir.path().join("plain");
    let (code, ..) = run(&["--out", plain.to_str().unwrap()]);
    assert_eq!(code, 0);
    for file in ["metrics.json", "trace.csv"] {
        assert_eq!(
            std::fs::read(out.join(file)).unwrap(),
            std::fs::read(plain.join(file)).unwrap(),
            "{file}"
        );
    }
}

#[test]
fn with_no_router_ratelab_runs_one_and_ros_2_nodes_join_it_under_the_real_clock() {
    let _alone = crate::machine::alone();
    let endpoint = format!("tcp/127.0.0.1:{}", free_port());
    // 10 s: room for the stand-in's Python to start and join on a loaded machine before
    // the run ends, with the 80 messages asked for below still to come.
    let mut child = Command::new(env!("CARGO_BIN_EXE_ratelab"))
        .args(["run", "--clock", "real", "--duration", "10", "--ros2"])
        .current_dir(crate::REPO)
        .env_remove("ROS_DOMAIN_ID")
        .env_remove("ZENOH_ROUTER_CHECK_ATTEMPTS")
        .env(connect_to(&endpoint).0, connect_to(&endpoint).1)
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let mut err = BufReader::new(child.stderr.take().unwrap());
    let mut line = String::new();
    err.read_line(&mut line).unwrap();
    assert!(
        line.contains(&format!(
            "no Zenoh router answered at {endpoint}, so ratelab runs one there for this run"
        )),
        "{line}"
    );
    // A ROS 2 node (domain 0: ROS_DOMAIN_ID unset) connects to it while the graph runs.
    let standin = StandIn::start("client", &endpoint, 0, &[]);
    let status = child.wait().unwrap();
    let mut stdout = String::new();
    child
        .stdout
        .take()
        .unwrap()
        .read_to_string(&mut stdout)
        .unwrap();
    assert!(status.success(), "{stdout}");
    let r = standin.report();
    assert_eq!(r["errors"], Value::Array(vec![]), "{r}");
    assert_eq!(
        strs(&r["nodes"]),
        ["actuator", "policy", "ratelab", "sensor"]
    );
    // It joined late: from its first message on, it saw every one, in order, at about the
    // sensor's 50 Hz (at least 1.6 s of the 10 s run, however slowly Python starts).
    let obs = r["topics"]["/obs"].as_array().unwrap();
    assert!(obs.len() >= 80, "{} messages", obs.len());
    assert_every_one_from(obs, obs[0]["seq"].as_i64().unwrap());
    let clock = r["clock_ns"].as_array().unwrap();
    assert!(clock.len() >= 80, "{} clock messages", clock.len());
}

/// With more than one attempt allowed, the nodes' session says it waits for the router
/// after the first attempt fails, as `ratelab ros2`'s readers do, then runs one itself.
#[test]
fn the_nodes_session_says_it_waits_for_a_router_then_runs_one() {
    let endpoint = format!("tcp/127.0.0.1:{}", free_port());
    let (code, _, stderr) = ratelab(
        &["run", "--clock", "virtual", "--duration", "1", "--ros2"],
        &[
            connect_to(&endpoint),
            ("ZENOH_ROUTER_CHECK_ATTEMPTS", "2".into()),
        ],
    );
    assert_eq!(code, 0, "{stderr}");
    let lines: Vec<&str> = stderr.lines().collect();
    let waiting = format!("[ratelab] waiting for a Zenoh router at {endpoint} (ZENOH_ROUTER_CHECK_ATTEMPTS=2: up to 2 attempts a second apart) ...");
    let ran = format!("no Zenoh router answered at {endpoint}, so ratelab runs one there");
    let at = |needle: &str| lines.iter().position(|l| l.contains(needle));
    assert!(
        matches!((at(&waiting), at(&ran)), (Some(w), Some(r)) if w < r),
        "{stderr}"
    );
    assert_eq!(
        stderr.matches("waiting for a Zenoh router").count(),
        1,
        "{stderr}"
    );
}

#[test]
fn a_second_clock_a_bad_domain_and_names_ros_2_refuses_are_said_in_one_line() {
    // Another /clock publisher on the domain (a simulator): refused before the run.
    let endpoint = format!("tcp/127.0.0.1:{}", free_port());
    let standin = StandIn::start("router", &endpoint, 0, &["clock"]);
    let (code, _, stderr) = ratelab(
        &["run", "--clock", "virtual", "--duration", "1", "--ros2"],
        &[connect_to(&endpoint)],
    );
    drop(standin);
    assert_eq!(code, 2, "{stderr}");
    assert!(
        stderr.contains("node 'gazebo' already publishes /clock on domain 0"),
        "{stderr}"
    );

    let refused = |args: &[&str], env: &[(&str, String)], says: &str| {
        let (code, _, stderr) = ratelab(args, env);
        assert_eq!(code, 2, "{args:?}: {stderr}");
        assert!(stderr.contains(says), "{args:?}: {stderr}");
        assert_eq!(stderr.trim().lines().count(), 1, "{stderr}");
    };
    refused(&["run", "--ros2", "233"], &[], "outside 0–232");
    refused(
        &["run", "--ros2"],
        &[("ROS_DOMAIN_ID", "abc".into())],
        "ROS_DOMAIN_ID",
    );
    refused(
        &["run", "--ros2"],
        &[("ZENOH_ROUTER_CHECK_ATTEMPTS", "soon".into())],
        "ZENOH_ROUTER_CHECK_ATTEMPTS='soon' is not an integer",
    );
    refused(
        &["run", "--ros2"],
        &[("ZENOH_CONFIG_OVERRIDE", "mode".into())],
        "is not KEY=VALUE",
    );
    // A graph whose topic is /clock would be a second /clock publisher.
    let dir = tempfile::tempdir().unwrap();
    let graph = dir.path().join("clock.toml");
    let text = std::fs::read_to_string(repo("graphs/cartpole.toml"))
        .unwrap()
        .replace("\"/obs\"", "\"/clock\"");
    std::fs::write(&graph, text).unwrap();
    refused(
        &["lab", "--ros2", "--bag", "b"],
        &[],
        "--bag writes one run's bag",
    );
    refused(&["run", "--bag", "b"], &[], "--ros2");
    for cmd in ["run", "lab"] {
        refused(
            &[cmd, "--graph", graph.to_str().unwrap(), "--ros2"],
            &[],
            "would be a second /clock publisher",
        );
    }
}

#[test]
fn a_camera_s_frames_reach_ros_2_as_sensor_msgs_image_each_whole_as_the_vision_node_saw_it() {
    use ratelab::graph::nodes::image_estimator::measure;
    use ratelab::msg::ImageMsg;
    let endpoint = format!("tcp/127.0.0.1:{}", free_port());
    let standin = StandIn::start("router", &endpoint, 4, &[]);
    let graph = repo("graphs/cartpole-camera.toml");
    let args = [
        "run",
        "--clock",
        "virtual",
        "--duration",
        "0.2",
        "--ros2",
        "4",
    ];
    let args = [&args[..], &["--graph", graph.to_str().unwrap()]].concat();
    let (code, stdout, stderr) = ratelab(&args, &[connect_to(&endpoint)]);
    let r = standin.report();
    assert_eq!(code, 0, "{stdout}{stderr}");
    assert_eq!(r["errors"], Value::Array(vec![]), "{}", r["errors"]);
    assert_eq!(r["hash_ok"]["sensor_msgs/msg/Image"], Value::Bool(true));
    let frames = r["topics"]["/image"].as_array().unwrap();
    // 30 frames a second from t = 0: 7 in 0.2 s, every one, in order, stamped at its tick.
    let seqs: Vec<i64> = frames.iter().filter_map(|f| f["seq"].as_i64()).collect();
    assert_eq!(frames.len(), 7, "seqs {seqs:?}\n{stdout}");
    assert_every_one_from(frames, 1);
    let pixels = |f: &Value| -> Vec<u8> {
        let h = f["data_hex"].as_str().unwrap();
        (0..h.len())
            .step_by(2)
            .map(|i| u8::from_str_radix(&h[i..i + 2], 16).unwrap())
            .collect()
    };
    let image = |f: &Value| ImageMsg {
        height: f["height"].as_u64().unwrap() as u32,
        width: f["width"].as_u64().unwrap() as u32,
        encoding: f["encoding"].as_str().unwrap().into(),
        step: f["step"].as_u64().unwrap() as u32,
        data: pixels(f).into(),
    };
    for (k, f) in frames.iter().enumerate() {
        let stamp = f["stamp_ns"].as_u64().unwrap();
        // (The period is whole nanoseconds: 33 333 333 at 30 Hz.)
        assert_eq!(stamp, k as u64 * (1_000_000_000 / 30), "frame {k}");
        assert_eq!(
            (&f["height"], &f["width"], &f["step"], &f["encoding"]),
            (
                &Value::from(480),
                &Value::from(640),
                &Value::from(640),
                &Value::from("mono8")
            ),
        );
        assert_eq!(
            (f["is_bigendian"].as_u64(), f["data_len"].as_u64()),
            (Some(0), Some(640 * 480))
        );
        // The drawing's shades: the background, the cart and the pole, and the
        // anti-aliased edges between them.
        let shades = f["shades"].as_object().unwrap();
        for shade in ["64", "128", "255"] {
            assert!(shades.contains_key(shade), "frame {k}: {shades:?}");
        }
    }
    // What the vision node measured (/meas, a JointState), from each frame as ROS 2 got it:
    // the same position, to the last bit, so the pixels on the wire are the ones it read.
    let meas = r["topics"]["/meas"].as_array().unwrap();
    assert!(meas.len() >= 6, "{meas:?}");
    for m in meas {
        let stamp = m["stamp_ns"].as_u64().unwrap();
        let seen = frames
            .iter()
            .rev()
            .find(|f| f["stamp_ns"].as_u64().unwrap() <= stamp)
            .unwrap();
        let p = measure(&image(seen)).expect("the cartpole in the frame");
        let got: Vec<f64> = m["position"]
            .as_array()
            .unwrap()
            .iter()
            .map(|x| x.as_f64().unwrap())
            .collect();
        assert_eq!(got, [p.cart_pos_m, p.pole_angle_rad], "/meas at {stamp} ns");
    }
}

/// Read a bag with rosbags: each topic's type and messages (`/action`'s data, `/obs`'s
/// positions, `/clock`'s times in ns, `/rosout`'s level, name, text, file, function and
/// line, `/parameter_events`' node, stamp and declared names), and each message's log time.
fn read_bag(dir: &std::path::Path) -> Value {
    let script = r#"
import json, sys
from rosbags.rosbag2 import Reader
from rosbags.typesys import Stores, get_typestore
ts = get_typestore(Stores.LATEST)
out = {"count": 0, "topics": {}, "qos": {}}
with Reader(sys.argv[1]) as r:
    out["count"] = r.message_count
    for c in r.connections:
        out["qos"][c.topic] = [
            [q.history.name, q.depth, q.reliability.name, q.durability.name,
             q.deadline.sec, q.deadline.nsec]
            for q in c.ext.offered_qos_profiles
        ]
    for c, t, raw in r.messages():
        m = ts.deserialize_cdr(raw, c.msgtype)
        rows = out["topics"].setdefault(c.topic, {"type": c.msgtype, "t": [], "v": []})
        rows["t"].append(t)
        if c.msgtype == "std_msgs/msg/Float64":
            rows["v"].append(float(m.data))
        elif c.msgtype == "rosgraph_msgs/msg/Clock":
            rows["v"].append(m.clock.sec * 10**9 + m.clock.nanosec)
        elif c.msgtype == "rcl_interfaces/msg/Log":
            rows["v"].append([int(m.level), m.name, m.msg, m.file, m.function, int(m.line)])
        elif c.msgtype == "rcl_interfaces/msg/ParameterEvent":
            stamp = m.stamp.sec * 10**9 + m.stamp.nanosec
            rows["v"].append([m.node, stamp, [p.name for p in m.new_parameters]])
        else:
            rows["v"].append([float(x) for x in m.position])
print(json.dumps(out))
"#;
    oracle_json(script, &[dir.to_str().unwrap()])
}

/// Each MCAP channel of a bag read with Foxglove's `mcap` (nothing of rosbag2's or
/// ratelab's): by topic, its schema's name, its metadata's `topic_type_hash` and
/// `offered_qos_profiles`, and the hash rosbags computes for the schema's type.
fn read_channels(dir: &std::path::Path) -> Value {
    let script = r#"
import glob, json, sys
from mcap.reader import make_reader
from rosbags.typesys import Stores, get_typestore
ts = get_typestore(Stores.LATEST)
out = {}
with open(glob.glob(sys.argv[1] + "/*.mcap")[0], "rb") as f:
    summary = make_reader(f).get_summary()
for c in summary.channels.values():
    name = summary.schemas[c.schema_id].name
    out[c.topic] = {
        "type": name,
        "hash": c.metadata.get("topic_type_hash"),
        "qos": c.metadata.get("offered_qos_profiles"),
        "rosbags_hash": ts.hash_rihs01(name),
    }
print(json.dumps(out))
"#;
    oracle_json(script, &[dir.to_str().unwrap()])
}

#[test]
fn a_bag_of_the_run_reads_back_with_rosbags_every_message_the_same_on_every_run() {
    // No router needed to write a bag: the session is not checked for one.
    let env = [
        ("ZENOH_ROUTER_CHECK_ATTEMPTS", "-1".to_string()),
        connect_to(&format!("tcp/127.0.0.1:{}", free_port())),
    ];
    let dir = tempfile::tempdir().unwrap();
    let bag = |name: &str, extra: &[&str]| {
        let path = dir.path().join(name);
        let mut args = vec!["run", "--clock", "virtual", "--duration", "1", "--ros2"];
        args.extend_from_slice(&["--bag", path.to_str().unwrap()]);
        args.extend_from_slice(extra);
        (ratelab(&args, &env), path)
    };
    let out = dir.path().join("out");
    let deadline = ["--qos", "/action:deadline_ms=40"];
    let ((code, stdout, stderr), first) = bag(
        "first",
        &[&["--out", out.to_str().unwrap()][..], &deadline].concat(),
    );
    assert_eq!(code, 0, "{stdout}{stderr}");
    // 51 of each topic and of /clock, and each of the 4 nodes' declared parameters (the
    // graph's 3 and /ratelab) on /parameter_events; these nodes write no log line.
    assert!(
        stdout.contains("(rosbag2, MCAP): 157 messages with /clock"),
        "{stdout}"
    );
    let r = read_bag(&first);
    assert_eq!(r["count"], 157);
    let topic = |t: &str| &r["topics"][t];
    assert_eq!(topic("/obs")["type"], "sensor_msgs/msg/JointState");
    assert_eq!(topic("/action")["type"], "std_msgs/msg/Float64");
    assert_eq!(topic("/clock")["type"], "rosgraph_msgs/msg/Clock");
    // As `ros2 bag record -a` takes them: each node's parameters as declared, at run time 0.
    let events = topic("/parameter_events");
    assert_eq!(events["type"], "rcl_interfaces/msg/ParameterEvent");
    assert_eq!(events["t"], serde_json::json!([0, 0, 0, 0]));
    let declared: std::collections::BTreeMap<&str, (u64, Vec<String>)> = events["v"]
        .as_array()
        .unwrap()
        .iter()
        .map(|e| {
            (
                e[0].as_str().unwrap(),
                (e[1].as_u64().unwrap(), strs(&e[2])),
            )
        })
        .collect();
    assert_eq!(
        declared.keys().copied().collect::<Vec<&str>>(),
        ["/actuator", "/policy", "/ratelab", "/sensor"]
    );
    assert!(
        declared.values().all(|(stamp, _)| *stamp == 0),
        "{declared:?}"
    );
    assert_eq!(
        declared["/policy"].1,
        ["rate_hz", "start_type_description_service", "use_sim_time"]
    );
    assert_eq!(
        declared["/ratelab"].1,
        ["start_type_description_service", "use_sim_time"]
    );
    // Each topic's offered QoS is the one ratelab ran it with (`ros2 bag play` offers it).
    let qos = |t: &str| r["qos"][t].to_string();
    let inf = "9223372036,854775807";
    assert_eq!(
        qos("/obs"),
        format!("[[\"KEEP_LAST\",1,\"BEST_EFFORT\",\"VOLATILE\",{inf}]]")
    );
    assert_eq!(
        qos("/action"),
        "[[\"KEEP_LAST\",1,\"BEST_EFFORT\",\"VOLATILE\",0,40000000]]"
    );
    assert_eq!(
        qos("/clock"),
        format!("[[\"KEEP_LAST\",1,\"BEST_EFFORT\",\"VOLATILE\",{inf}]]")
    );
    // /rosout's: each of the 4 nodes' publisher (rcl's QoS, transient local), as rosbag2
    // lists one profile per publisher.
    let rosout = "[\"KEEP_LAST\",1000,\"RELIABLE\",\"TRANSIENT_LOCAL\",9223372036,854775807]";
    assert_eq!(qos("/rosout"), format!("[{}]", [rosout; 4].join(",")));
    // Each channel's metadata as rosbag2_storage_mcap writes it, read with Foxglove's mcap:
    // the offered profiles and the type's hash, which rosbags computes again.
    let channels = read_channels(&first);
    assert_eq!(
        channels.as_object().unwrap().keys().collect::<Vec<_>>(),
        ["/action", "/clock", "/obs", "/parameter_events", "/rosout"]
    );
    for (name, c) in channels.as_object().unwrap() {
        assert!(
            c["hash"].as_str().unwrap().starts_with("RIHS01_"),
            "{name}: {c}"
        );
        assert_eq!(c["hash"], c["rosbags_hash"], "{name}: {c}");
        assert!(
            c["qos"]
                .as_str()
                .unwrap()
                .starts_with("- history: keep_last\n"),
            "{name}: {c}"
        );
    }
    // The forces applied, in newtons, step by step; log times are run times.
    let rows = trace(&out);
    let forces = topic("/action")["v"].as_array().unwrap();
    assert_eq!(forces.len(), rows.len());
    for (i, (v, row)) in forces.iter().zip(&rows).enumerate() {
        assert_eq!(
            f(v),
            row["action"].parse::<f64>().unwrap() * 10.0,
            "step {i}"
        );
        assert_eq!(
            topic("/action")["t"][i].as_u64(),
            Some(i as u64 * 20_000_000)
        );
    }
    let clock = topic("/clock")["v"].as_array().unwrap();
    assert_eq!(clock.len(), 51);
    assert_eq!(clock.last().unwrap().as_u64(), Some(1_000_000_000));

    // The same run again: the same messages at the same times (the MCAP summary's record
    // order is the `mcap` crate's and varies between processes).
    let ((code, ..), second) = bag("second", &deadline);
    assert_eq!(code, 0);
    assert_eq!(read_bag(&second), r);
    // Never over a bag without --force; with it, replaced.
    let ((code, _, stderr), _) = bag("first", &[]);
    assert_eq!(code, 2, "{stderr}");
    assert!(stderr.contains("--force"), "{stderr}");
    let ((code, _, stderr), _) = bag("first", &["--force"]);
    assert_eq!(code, 0, "{stderr}");
    assert_eq!(read_bag(&first)["count"], 157);
    // Another bag's MCAP file in the folder is never bagged beside this one's, --force or
    // not: one line, exit 2, nothing removed.
    let stray = first.join("second_0.mcap");
    std::fs::copy(second.join("second_0.mcap"), &stray).unwrap();
    let ((code, stdout, stderr), _) = bag("first", &["--force"]);
    assert_eq!(code, 2, "{stdout}{stderr}");
    assert_eq!(
        stderr.trim_end(),
        format!(
            "error: --bag {}: an MCAP file of another bag in the folder (this one's is \
             first_0.mcap); move it away or give --bag another folder",
            stray.display()
        )
    );
    assert!(stray.exists() && first.join("metadata.yaml").exists());
}

/// A run killed outright (SIGKILL: no end, no summary, no `metadata.yaml`) leaves a bag
/// that reads up to its last second ([`ratelab::ros2::bag::FLUSH_PERIOD`]): the writer
/// closes its chunk every second, where it held every message in one chunk until the run
/// ended, and a killed run's bag held none. The reader says where the file stops.
#[test]
fn a_run_killed_outright_leaves_a_bag_that_reads_up_to_its_last_second() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("killed");
    /// The run, killed when the test ends, however it ends.
    struct Killed(Child);
    impl Drop for Killed {
        fn drop(&mut self) {
            let _ = self.0.kill();
            let _ = self.0.wait();
        }
    }
    let mut child = Killed(
        Command::new(env!("CARGO_BIN_EXE_ratelab"))
            .args([
                "run",
                "--clock",
                "real",
                "--duration",
                "60",
                "--ros2",
                "--bag",
            ])
            .arg(&path)
            .env_remove("ROS_DOMAIN_ID")
            .env("ZENOH_ROUTER_CHECK_ATTEMPTS", "-1")
            .env(
                "ZENOH_CONFIG_OVERRIDE",
                format!("connect/endpoints=[\"tcp/127.0.0.1:{}\"]", free_port()),
            )
            .current_dir(dir.path())
            .stdout(Stdio::null())
            .stderr(Stdio::null())
            .spawn()
            .unwrap(),
    );
    let mcap = path.join("killed_0.mcap");
    let start = std::time::Instant::now();
    while !mcap.exists() && start.elapsed() < std::time::Duration::from_secs(30) {
        std::thread::sleep(std::time::Duration::from_millis(50));
    }
    assert!(mcap.exists(), "the run made no bag in 30 s");
    // Three seconds of a 50 Hz run: one of them at least is in the file (a second's 50
    // /obs messages), however slow the machine.
    std::thread::sleep(std::time::Duration::from_secs(3));
    child.0.kill().unwrap();
    child.0.wait().unwrap();
    assert!(!path.join("metadata.yaml").exists());
    let (code, stdout, stderr) = ratelab(&["ros2", "bag", "info", path.to_str().unwrap()], &[]);
    assert_eq!(code, 0, "{stdout}{stderr}");
    assert!(stdout.contains("cut short?"), "{stdout}");
    let obs: u64 = stdout
        .lines()
        .find_map(|l| {
            l.contains("Topic: /obs |")
                .then(|| {
                    l.rsplit("Count: ")
                        .next()?
                        .split_whitespace()
                        .next()?
                        .parse()
                        .ok()
                })
                .flatten()
        })
        .unwrap_or_else(|| panic!("no /obs in: {stdout}"));
    assert!(
        obs >= 50,
        "{obs} /obs messages in the killed run's bag: {stdout}"
    );
}

#[test]
fn a_finished_bridge_withdraws_its_tokens_and_the_next_takes_fresh_ids_on_the_same_session() {
    use ratelab::ros2::session::{open, SessionEnv};
    use ratelab::ros2::{Bridge, Ros2Options};
    use zenoh::Wait;
    let env = SessionEnv {
        router_check_attempts: Some("-1".into()),
        config_override: Some(connect_to(&format!("tcp/127.0.0.1:{}", free_port())).1),
    };
    let link = open(&env, &ratelab::scheduler::StopFlag::new()).unwrap();
    let tokens = || -> Vec<String> {
        let replies = link
            .session
            .liveliness()
            .get("@ros2_lv/9/**")
            .timeout(std::time::Duration::from_millis(300))
            .wait()
            .unwrap();
        let mut keys = Vec::new();
        while let Ok(r) = replies.recv() {
            if let Ok(s) = r.result() {
                keys.push(s.key_expr().to_string());
            }
        }
        keys.sort();
        keys
    };
    let opts = Ros2Options {
        domain: 9,
        bag: None,
        force: false,
    };
    let cfg = ratelab::RunConfig::default();
    let bridge = || {
        let brain = ratelab::checkpoint::load_policy("scripted").unwrap();
        let slot = ratelab::policy::BrainSlot::new(brain);
        let graph = ratelab::run::build_graph(&cfg, slot, false, Vec::new()).unwrap();
        let h = &graph.handles;
        let g = ratelab::ros2::bridge::Offer::whole(h);
        Bridge::start(
            &link,
            &g,
            &opts,
            cfg.clock,
            &ratelab::scheduler::StopFlag::new(),
        )
        .unwrap()
    };
    let first = bridge();
    let during = tokens();
    // 4 nodes (the graph's 3 and /clock's), 5 endpoints of the graph, and each node's
    // /rosout, /parameter_events, 6 parameter services and ~/get_type_description.
    assert_eq!(during.len(), 4 + 5 + 4 * 9, "{during:?}");
    first.finish();
    assert_eq!(
        tokens(),
        Vec::<String>::new(),
        "withdrawn, the session still open"
    );
    // The lab's next run: the same graph on the same session, fresh ids, so none of the
    // first run's tokens (nor its GIDs) comes back.
    let second = bridge();
    let again = tokens();
    assert_eq!(again.len(), 4 + 5 + 4 * 9);
    assert!(again.iter().all(|k| !during.contains(k)), "{again:?}");
    second.finish();
    link.close();
}

#[test]
fn a_launch_across_processes_offers_each_processs_own_nodes_and_the_plants_clock() {
    let _m = crate::machine::shared();
    let endpoint = format!("tcp/127.0.0.1:{}", free_port());
    let standin = StandIn::start("router", &endpoint, 7, &[]);
    let dir = tempfile::tempdir().unwrap();
    let plain = dir.path().join("plain");
    let launched = dir.path().join("launched");
    let args = ["--clock", "virtual", "--duration", "1", "--force"];
    let (code, out, err) = ratelab(
        &[
            &["launch", "--processes", "--ros2", "7", "--out"][..],
            &[launched.to_str().unwrap()],
            &args,
        ]
        .concat(),
        &[connect_to(&endpoint)],
    );
    let r = standin.report();
    assert_eq!(code, 0, "{out}{err}");
    assert!(
        out.contains("offering the graph to ROS 2 on domain 7: each process its own nodes, the plant's process /clock"),
        "{out}"
    );
    assert_eq!(r["errors"], Value::Array(vec![]), "{r}");
    // One NN per node and one MP/MS per endpoint, whichever process declared it (each
    // process offers its own nodes; a copy of another's topic is not offered again).
    assert_the_chapters_graph(&r);
    // Every message once, numbered from 1, with the in-process run's values (the lockstep
    // is byte-identical to it).
    let (code, ..) = ratelab(
        &[&["run", "--out", plain.to_str().unwrap()][..], &args].concat(),
        &[],
    );
    assert_eq!(code, 0);
    let rows = trace(&plain);
    let action = r["topics"]["/action"].as_array().unwrap();
    let obs = r["topics"]["/obs"].as_array().unwrap();
    assert_eq!((obs.len(), action.len()), (51, 51));
    assert_every_one_from(obs, 1);
    assert_every_one_from(action, 1);
    for (i, row) in rows.iter().enumerate() {
        let applied = row["action"].parse::<f64>().unwrap() * 10.0;
        assert_eq!(f(&action[i]["data"]), applied, "step {i}");
    }
    // /clock from the plant's process alone: the run's time, 0 to the end.
    let clock = clock_ns(&r);
    assert_eq!(clock.first(), Some(&0));
    assert_eq!(clock.last(), Some(&1_000_000_000));
    assert!(clock.windows(2).all(|w| w[0] < w[1]), "{clock:?}");
}

#[test]
fn every_type_hash_is_the_one_a_second_independent_implementation_computes() {
    use ratelab::msg::{ForceMsg, ImageMsg, Message, MsgType, PositionMsg, StateMsg};
    use ratelab::ros2::types::clock_type;
    let ros_type_of = |t: MsgType| (t.ros2().expect("a ROS 2 mapping").ros_type)();
    // ros2-pyterfaces (pure-Python core, its schemas rewritten from ROS 2's interfaces),
    // beside rosbags which the other tests use.
    let script = r#"
import json
from ros2_pyterfaces import core
from ros2_pyterfaces.core.sensor_msgs.msg import JointState
from ros2_pyterfaces.core.std_msgs.msg import Float64
from ros2_pyterfaces.core.rosgraph_msgs.msg import Clock
from ros2_pyterfaces.core.sensor_msgs.msg import Image
print(json.dumps({t["__typename"]: core.hash_rihs01(t) for t in (JointState, Float64, Clock, Image)}))
"#;
    let theirs = oracle_json(script, &[]);
    for ty in [
        ros_type_of(StateMsg::TYPE),
        ros_type_of(PositionMsg::TYPE),
        ros_type_of(ForceMsg::TYPE),
        ros_type_of(ImageMsg::TYPE),
        clock_type(),
    ] {
        assert_eq!(
            theirs[ty.name].as_str(),
            Some(ty.hash.to_rihs_string().as_str()),
            "{}",
            ty.name
        );
    }
}
