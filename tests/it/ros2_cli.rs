//! `ratelab ros2` (#52): ros2cli's verbs on an rmw_zenoh graph, read from the other side: a
//! `ratelab run --ros2` (which runs its own router) read by the real binary, and every type
//! `echo` decodes hashed as rosbags (an independent implementation) hashes it.

use crate::distributed::free_port;
use crate::ros2::{connect_to, oracle_python, ratelab, Oracle};
use std::io::{BufRead, BufReader};
use std::process::{Command, Stdio};

/// `ratelab run ARGS` offering its graph to ROS 2 through its own router at a free port,
/// once its first lines said so (it runs the router and offers the graph); its stderr
/// drained from then on; killed when dropped.
pub(crate) struct Offering {
    child: std::process::Child,
    pub(crate) endpoint: String,
}

impl Offering {
    pub(crate) fn start(args: &[&str]) -> Offering {
        Offering::start_at(&format!("tcp/127.0.0.1:{}", free_port()), args)
    }

    /// As [`Offering::start`], its router at `endpoint`.
    pub(crate) fn start_at(endpoint: &str, args: &[&str]) -> Offering {
        let endpoint = endpoint.to_string();
        let mut child = Command::new(env!("CARGO_BIN_EXE_ratelab"))
            .arg("run")
            .args(args)
            .current_dir(crate::REPO)
            .env_remove("ROS_DOMAIN_ID")
            .env_remove("ZENOH_ROUTER_CHECK_ATTEMPTS")
            .env(connect_to(&endpoint).0, connect_to(&endpoint).1)
            .stdout(Stdio::null())
            .stderr(Stdio::piped())
            .spawn()
            .unwrap();
        let mut err = BufReader::new(child.stderr.take().unwrap());
        let mut said = String::new();
        while !said.contains("offering the graph to ROS 2") {
            let mut line = String::new();
            if err.read_line(&mut line).unwrap() == 0 {
                break;
            }
            said.push_str(&line);
        }
        assert!(said.contains("offering the graph to ROS 2"), "{said}");
        // A node's prints go on stderr too (headless): never let the pipe fill.
        std::thread::spawn(move || std::io::copy(&mut err, &mut std::io::sink()));
        Offering { child, endpoint }
    }
}

impl Drop for Offering {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

/// A subscription announces its own requested QoS (`[topic.requested.NODE]`) beside its
/// publisher's offer, so `topic info -v` lists both ends as ros2cli does: here a compatible
/// pair, the policy offering a 40 ms deadline on /action and the actuator accepting 100 ms.
/// The policy's lifespan (60 ms) and lease (100 ms) are its publisher's alone: the
/// actuator's subscription announces neither, as a real rclpy subscription that sets none
/// announces `Infinite` (the probe's in `real-rclpy-graph-view-qos.json`), where the
/// captured run (the same flags) showed the actuator's with the policy's (#74 item 4).
#[test]
fn topic_info_lists_the_offer_and_the_subscriptions_own_request() {
    let _alone = crate::machine::alone();
    let dir = tempfile::tempdir().unwrap();
    let graph = dir.path().join("g.toml");
    // The chapter's file ends with /action's table: the request goes under it.
    let text = std::fs::read_to_string(crate::repo("graphs/cartpole.toml")).unwrap()
        + "\n[topic.requested.actuator]\ndeadline_ms = 100\n";
    std::fs::write(&graph, text).unwrap();
    let run = Offering::start(&[
        "--clock",
        "real",
        "--duration",
        "12",
        "--ros2",
        "6",
        "--graph",
        graph.to_str().unwrap(),
        "--qos",
        "/action:deadline_ms=40,lifespan_ms=60",
        "--lease",
        "policy=100",
    ]);
    let (code, out, err) = ratelab(
        &[
            "ros2",
            "--connect",
            run.endpoint.as_str(),
            "--domain",
            "6",
            "topic",
            "info",
            "/action",
            "-v",
        ],
        &[],
    );
    assert_eq!(code, 0, "{err}");
    let (publisher, subscription) = out
        .split_once("Endpoint type: SUBSCRIPTION")
        .unwrap_or_else(|| panic!("{out}"));
    assert!(publisher.contains("Node name: policy"), "{out}");
    assert!(
        publisher.contains("Deadline: 40000000 nanoseconds"),
        "{out}"
    );
    assert!(
        subscription.contains("Deadline: 100000000 nanoseconds"),
        "{out}"
    );
    assert!(subscription.contains("Reliability: BEST_EFFORT"), "{out}");
    // Lifespan and lease: the publisher's on the publisher, the real subscription's way on
    // the subscription.
    for needle in [
        "Lifespan: 60000000 nanoseconds\n",
        "Liveliness lease duration: 100000000 nanoseconds\n",
    ] {
        assert!(publisher.contains(needle), "{needle:?} in {out}");
        assert!(!subscription.contains(needle), "{needle:?} in {out}");
    }
    let real = real_capture("real-rclpy-graph-view-qos.json");
    let subs = &real["snapshots"][0]["endpoints"]["/action"]["subscriptions"];
    let of = |node: &str| {
        subs.as_array()
            .unwrap()
            .iter()
            .find(|s| s["node"] == node)
            .unwrap_or_else(|| panic!("no {node} in {subs}"))["qos"]
            .clone()
    };
    let (probe, captured) = (of("probe"), of("actuator"));
    assert_eq!(
        (
            &captured["lifespan"],
            &captured["liveliness_lease_duration"]
        ),
        (
            &serde_json::json!("60000000 nanoseconds"),
            &serde_json::json!("100000000 nanoseconds")
        ),
        "the capture shows the difference this test is about"
    );
    for (field, line) in [
        ("lifespan", "Lifespan"),
        ("liveliness_lease_duration", "Liveliness lease duration"),
    ] {
        let said = format!("  {line}: {}\n", probe[field].as_str().unwrap());
        assert!(subscription.contains(&said), "{said:?} in {out}");
    }
}

/// A graph offered to ROS 2 under the real clock, through a router at a free port (the
/// run's own), read with `ratelab ros2 --connect` while it runs.
#[test]
fn ros2_verbs_read_a_running_graph_as_ros2cli_prints_it() {
    let _alone = crate::machine::alone();
    let run = Offering::start(&["--clock", "real", "--duration", "12", "--ros2", "4"]);
    let endpoint = run.endpoint.clone();
    let ros2 = |verb: &[&str]| {
        let mut args = vec!["ros2", "--connect", endpoint.as_str(), "--domain", "4"];
        args.extend_from_slice(verb);
        ratelab(&args, &[])
    };
    let (code, out, err) = ros2(&["node", "list"]);
    assert_eq!(code, 0, "{err}");
    assert_eq!(out, "/actuator\n/policy\n/ratelab\n/sensor\n");
    let (_, out, _) = ros2(&["topic", "list", "-t"]);
    assert_eq!(
        out,
        "/action [std_msgs/msg/Float64]\n/clock [rosgraph_msgs/msg/Clock]\n/obs [sensor_msgs/msg/JointState]\n/parameter_events [rcl_interfaces/msg/ParameterEvent]\n/rosout [rcl_interfaces/msg/Log]\n"
    );
    let (_, out, _) = ros2(&["node", "info", "policy"]);
    assert!(
        out.starts_with("/policy\n  Subscribers:\n    /obs: sensor_msgs/msg/JointState\n  Publishers:\n    /action: std_msgs/msg/Float64\n"),
        "{out}"
    );
    let (_, out, _) = ros2(&["topic", "info", "/obs", "-v"]);
    for needle in [
        "Type: sensor_msgs/msg/JointState\n\nPublisher count: 1\n",
        "Node name: sensor\nNode namespace: /\n",
        "Endpoint type: PUBLISHER\nGID: ",
        "QoS profile:\n  Reliability: BEST_EFFORT\n  History (Depth): KEEP_LAST (1)\n",
        "Subscription count: 1\n",
        "Node name: policy\n",
    ] {
        assert!(out.contains(needle), "{needle:?} in {out}");
    }
    // echo: YAML, `---` after each message, the joints by their MuJoCo names.
    let (code, out, err) = ros2(&["topic", "echo", "/obs", "--once"]);
    assert_eq!(code, 0, "{err}");
    assert!(out.starts_with("header:\n  stamp:\n    sec: "), "{out}");
    assert!(
        out.contains("  frame_id: ''\nname:\n- slider\n- hinge\nposition:\n- "),
        "{out}"
    );
    assert!(out.ends_with("effort: []\n---\n"), "{out}");
    let (_, out, _) = ros2(&["topic", "echo", "/action", "-n", "3"]);
    assert_eq!(out.matches("---\n").count(), 3, "{out}");
    assert!(out.starts_with("data: "), "{out}");
    // hz: the sensor's 50 Hz, said as ros2cli says it.
    let (code, out, err) = ros2(&["topic", "hz", "/obs", "--duration", "2.5"]);
    assert_eq!(code, 0, "{err}");
    let rate: f64 = out
        .lines()
        .rev()
        .find_map(|l| l.strip_prefix("average rate: "))
        .unwrap_or_else(|| panic!("{out}"))
        .parse()
        .unwrap();
    assert!((45.0..55.0).contains(&rate), "{out}");
    assert!(out.contains("\tmin: 0.0"), "{out}");
    // A topic nobody has: ros2cli's warning on stdout, its refusal on stderr, exit 1
    // (ros2topic's `api.get_msg_class`, `verb/echo.py`; `ros2_cli_rules.rs` checks it
    // against the real command's capture).
    let (code, out, err) = ros2(&["topic", "echo", "/nothing", "--once"]);
    assert_eq!(
        (code, out.as_str(), err.as_str()),
        (
            1,
            "WARNING: topic [/nothing] does not appear to be published yet\n",
            "Could not determine the type for the passed topic\n"
        )
    );
    // What ros2cli refuses with its message, it ends with 1 (`sys.exit` of the message).
    let (code, _, err) = ros2(&["node", "info", "/nobody"]);
    assert_eq!((code, err.trim()), (1, "Unable to find node '/nobody'"));
    drop(run);
}

/// A graph that is not ratelab's (`tests/ros2/talker.py`: eclipse-zenoh and rosbags playing
/// ROS 2 nodes): a namespaced node, a type ratelab does not describe, payloads that do not
/// decode, a node name holding an escape sequence and a newline. Every verb answers as
/// ros2cli would; what cannot be decoded is one line, and the echo goes on.
#[test]
fn ros2_verbs_read_another_graph_and_survive_hostile_tokens_and_payloads() {
    let endpoint = format!("tcp/127.0.0.1:{}", free_port());
    let _talker = Oracle::start("tests/ros2/talker.py", &[&endpoint, "0"], "the talker");
    let ros2 = |verb: &[&str]| {
        let mut args = vec!["ros2", "--connect", endpoint.as_str()];
        args.extend_from_slice(verb);
        ratelab(&args, &[])
    };
    let (code, out, err) = ros2(&["node", "list"]);
    assert_eq!(code, 0, "{err}");
    assert_eq!(
        out, "/demo/talker\n/evil\\u{1b}[2J\\nnode\n/gizmo\n/hostile\n/liar\n/listener\n/mystery\n",
        "the escape and the newline written out"
    );
    let (_, out, _) = ros2(&["topic", "list", "-t"]);
    assert_eq!(
        out,
        "/broken [sensor_msgs/msg/JointState]\n/chatter [std_msgs/msg/String]\n/cmd_vel [geometry_msgs/msg/Twist]\n/fib [my_pkg/msg/Fib]\n/gadget [my_pkg/msg/Gadget]\n/thing [my_pkg/msg/Thing]\n"
    );
    let (_, out, _) = ros2(&["node", "info", "/demo/talker"]);
    assert_eq!(
        out,
        "/demo/talker\n  Subscribers:\n\n  Publishers:\n    /chatter: std_msgs/msg/String\n    /cmd_vel: geometry_msgs/msg/Twist\n  Service Servers:\n\n  Service Clients:\n\n  Action Servers:\n\n  Action Clients:\n\n"
    );
    let (_, out, _) = ros2(&["topic", "info", "/chatter", "-v"]);
    for needle in [
        "Node name: talker\nNode namespace: /demo\n",
        "Endpoint type: PUBLISHER\nGID: ",
        "QoS profile:\n  Reliability: RELIABLE\n  History (Depth): KEEP_LAST (7)\n",
        "Node name: listener\n",
        "Endpoint type: SUBSCRIPTION\nGID: ",
        "QoS profile:\n  Reliability: BEST_EFFORT\n  History (Depth): KEEP_LAST (1)\n  Durability: VOLATILE\n  Lifespan: Infinite\n  Deadline: 100000000 nanoseconds\n",
    ] {
        assert!(out.contains(needle), "{needle:?} in {out}");
    }
    let (_, out, _) = ros2(&["topic", "echo", "/cmd_vel", "--once"]);
    assert_eq!(
        out,
        "linear:\n  x: 0.5\n  y: 0.0\n  z: 0.0\nangular:\n  x: 0.0\n  y: 0.0\n  z: -0.25\n---\n"
    );
    let (_, out, _) = ros2(&["topic", "echo", "/chatter", "-n", "2"]);
    let lines: Vec<&str> = out.lines().collect();
    assert_eq!(lines.len(), 4, "{out}");
    assert!(lines[0].starts_with("data: hello world "), "{out}");
    let (_, out, _) = ros2(&["topic", "echo", "/thing", "--once"]);
    assert_eq!(
        out,
        format!(
            "<my_pkg/msg/Thing RIHS01_{}: 12 bytes, not decoded: a type not described here, and node /mystery did not answer its get_type_description within 5.0 s>\n---\n",
            "ab".repeat(32)
        )
    );
    // A type ratelab carries no description of, decoded by the one its publisher's node
    // gives (~/get_type_description), checked against the hash in its key...
    let (code, out, err) = ros2(&["topic", "echo", "/gadget", "--once"]);
    assert_eq!(code, 0, "{err}");
    assert_eq!(
        out,
        "label: left arm\nreadings:\n- 0.5\n- -1.25\noffset:\n  x: 1.0\n  y: 2.0\n  z: 3.0\ncounts:\n- 1\n- 2\n- 3\n---\n"
    );
    // ...and one whose node describes it falsely is not decoded by that description.
    let (_, out, _) = ros2(&["topic", "echo", "/fib", "--once"]);
    assert!(
        out.starts_with("<my_pkg/msg/Fib RIHS01_") && out.contains(": 20 bytes, not decoded: a type not described here, and its node's description hashes to RIHS01_"),
        "{out}"
    );
    assert!(out.contains(", not to the topic's RIHS01_"), "{out}");
    // Both hostile payloads, one line each, and the echo goes on to the next.
    let (code, out, _) = ros2(&["topic", "echo", "/broken", "-n", "2"]);
    assert_eq!(code, 0);
    let notes: Vec<&str> = out.lines().filter(|l| l.starts_with('<')).collect();
    assert_eq!(notes.len(), 2, "{out}");
    assert!(notes.iter().all(|l| l.contains("not decoded")), "{out}");
    let (_, out, _) = ros2(&["topic", "hz", "/cmd_vel", "--duration", "2.2"]);
    // The talker publishes about 20 Hz, but it sleeps 50 ms after its work rather than to a
    // deadline, so on a loaded machine it runs a little slower: a band, not the digits.
    let rate: f64 = out
        .lines()
        .rev()
        .find_map(|l| l.strip_prefix("average rate: "))
        .unwrap_or_else(|| panic!("{out}"))
        .parse()
        .unwrap();
    assert!((15.0..=21.0).contains(&rate), "{out}");
    // graph: publisher ──▶ topic [type] msg/s ──▶ subscribers, as the lab draws it.
    let (code, out, err) = ros2(&["graph", "--once"]);
    assert_eq!(code, 0, "{err}");
    let line = |topic: &str| {
        out.lines()
            .find(|l| l.contains(&format!(" ──▶ {topic} [")))
            .unwrap_or_else(|| panic!("{topic} in {out}"))
            .to_string()
    };
    assert!(
        line("/chatter").starts_with("/demo/talker ──▶ /chatter [std_msgs/msg/String] "),
        "{out}"
    );
    assert!(line("/chatter").ends_with(" msg/s ──▶ /listener"), "{out}");
    let cmd_vel = line("/cmd_vel");
    let hz: f64 = cmd_vel
        .split(" msg/s")
        .next()
        .and_then(|l| l.rsplit(' ').next())
        .and_then(|r| r.parse().ok())
        .unwrap_or_else(|| panic!("{cmd_vel}"));
    assert!((15.0..25.0).contains(&hz), "{cmd_vel}");
    assert!(
        out.contains("nodes with no topic: /evil\\u{1b}[2J\\nnode"),
        "{out}"
    );
    let (_, out, _) = ros2(&["topic", "bw", "/chatter", "--duration", "2.2"]);
    assert!(out.starts_with("Subscribed to [/chatter]\n"), "{out}");
    assert!(out.contains("\tMessage size mean: 2"), "{out}");
    assert!(out.contains(" B/s from "), "{out}");
}

/// With no router, the reader says where it looked and how to start one; a bad domain is
/// refused before anything is opened.
#[test]
fn no_router_or_a_bad_domain_is_said_in_one_line() {
    let endpoint = format!("tcp/127.0.0.1:{}", free_port());
    let (code, _, err) = ratelab(&["ros2", "--connect", &endpoint, "node", "list"], &[]);
    assert_eq!(code, 2, "{err}");
    assert!(
        err.contains(&format!("no Zenoh router answered at {endpoint}")),
        "{err}"
    );
    assert_eq!(err.trim().lines().count(), 1, "{err}");
    // ros2cli's --no-daemon (in every ros2 script) is taken, after the verb as ros2 takes it.
    let (code, _, err) = ratelab(
        &[
            "ros2",
            "--connect",
            &endpoint,
            "node",
            "list",
            "--no-daemon",
        ],
        &[],
    );
    assert_eq!(code, 2, "{err}");
    assert!(err.contains("no Zenoh router answered"), "{err}");
    let (code, _, err) = ratelab(&["ros2", "--domain", "999", "node", "list"], &[]);
    assert_eq!(code, 2);
    assert!(err.contains("--domain"), "{err}");
    // An endpoint Zenoh cannot read: Zenoh's own reason, in one line, without its error's
    // debug form or the places in its source.
    for endpoint in ["garbage", ""] {
        let (code, _, err) = ratelab(&["ros2", "--connect", endpoint, "node", "list"], &[]);
        assert_eq!(code, 2, "{err}");
        assert_eq!(err.trim().lines().count(), 1, "{err}");
        assert!(
            err.contains("Endpoints must be of the form <protocol>/<address>"),
            "{err}"
        );
        assert!(!err.contains(".rs:") && !err.contains("Json5Err"), "{err}");
    }
}

/// The readers look for the router as rmw_zenoh's nodes do, `ZENOH_ROUTER_CHECK_ATTEMPTS`
/// one second apart (it was ignored: one attempt whatever it said); `0` waits, saying so,
/// until a router answers. An endpoint whose port is no port is refused before any session.
#[test]
fn the_readers_look_for_the_router_as_zenoh_router_check_attempts_says() {
    let endpoint = format!("tcp/127.0.0.1:{}", free_port());
    let attempts = |n: &str| [("ZENOH_ROUTER_CHECK_ATTEMPTS", n.to_string())];
    let began = std::time::Instant::now();
    let (code, _, err) = ratelab(
        &["ros2", "--connect", &endpoint, "node", "list"],
        &attempts("3"),
    );
    assert_eq!(code, 2, "{err}");
    assert!(err.contains("no Zenoh router answered"), "{err}");
    assert!(
        err.contains(&format!("waiting for a Zenoh router at {endpoint} (ZENOH_ROUTER_CHECK_ATTEMPTS=3: up to 3 attempts a second apart)")),
        "{err}"
    );
    // Three attempts, a second apart: two seconds of waiting at least, and not many more.
    let waited = began.elapsed().as_secs_f64();
    assert!((2.0..15.0).contains(&waited), "{waited} s");
    // The router it looks for is the one the override names, as it says.
    let (code, _, err) = ratelab(&["ros2", "node", "list"], &[connect_to(&endpoint)]);
    assert_eq!(code, 2, "{err}");
    assert!(
        err.contains(&format!("no Zenoh router answered at {endpoint} (")),
        "{err}"
    );
    assert!(!err.contains("waiting"), "one attempt when unset: {err}");
    let (code, _, err) = ratelab(
        &["ros2", "--connect", &endpoint, "node", "list"],
        &attempts("x"),
    );
    assert_eq!(code, 2);
    assert!(
        err.contains("ZENOH_ROUTER_CHECK_ATTEMPTS='x' is not an integer"),
        "{err}"
    );
    for (bad, why) in [
        (
            "tcp/127.0.0.1:99999",
            "the port must be a number in 1..=65535",
        ),
        ("tcp/127.0.0.1:0", "port 0 means any port"),
        ("tcp/127.0.0.1", "expected tcp/HOST:PORT"),
        ("tls/:7447", "no host"),
    ] {
        let (code, _, err) = ratelab(&["ros2", "--connect", bad, "node", "list"], &[]);
        assert_eq!(code, 2, "{bad}: {err}");
        assert!(
            err.contains(&format!("--connect {bad}: {why}")),
            "{bad}: {err}"
        );
        assert!(!err.contains("no Zenoh router answered"), "{err}");
    }
    // 0: waits for the router, and reads the graph through it once it runs: an independent
    // one (PyPI's eclipse-zenoh), declaring a node as it starts to listen.
    let mut reader = Command::new(env!("CARGO_BIN_EXE_ratelab"))
        .args([
            "ros2",
            "--connect",
            &endpoint,
            "--domain",
            "5",
            "node",
            "list",
        ])
        .env("ZENOH_ROUTER_CHECK_ATTEMPTS", "0")
        .env_remove("ZENOH_CONFIG_OVERRIDE")
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    std::thread::sleep(std::time::Duration::from_millis(2500));
    let trigger = tempfile::tempdir().unwrap();
    let trigger = trigger.path().join("never");
    let args = [endpoint.as_str(), "5", trigger.to_str().unwrap()];
    let _router = Oracle::start("tests/ros2/late_talker.py", &args, "the late talker");
    let status = crate::distributed::exit_within(&mut reader, 60);
    let read = |p: &mut dyn std::io::Read| {
        let mut s = String::new();
        p.read_to_string(&mut s).unwrap();
        s
    };
    let out = read(reader.stdout.as_mut().unwrap());
    let err = read(reader.stderr.as_mut().unwrap());
    assert!(status.success(), "{err}");
    assert!(
        err.contains(&format!(
            "waiting for a Zenoh router at {endpoint} (ZENOH_ROUTER_CHECK_ATTEMPTS=0: until one answers)"
        )),
        "{err}"
    );
    // Exit 0 is the check that it waited and then read through the router (one attempt
    // fails with exit 2; waiting for ever would not end). What it reads is what the router
    // held as the reader's retry linked to it, which is as the router starts to listen:
    // the node it declares at once may not be there yet, as for ros2cli on rmw_zenoh.
    assert!(["", "/late_listener\n"].contains(&out.as_str()), "{out}");
}

/// Every type `echo` decodes has the RIHS01 hash rosbags computes from ROS 2's own
/// definitions: a message of that type from a real ROS 2 node is decoded, never one of a
/// type that only shares its name.
#[test]
fn every_type_echo_decodes_is_hashed_as_rosbags_hashes_it() {
    let known = ratelab::ros2::echo::known();
    let names: Vec<&str> = known.keys().map(String::as_str).collect();
    let script = format!(
        "import json\nfrom rosbags.typesys import Stores, get_typestore\nts = get_typestore(Stores.LATEST)\nprint(json.dumps({{t: ts.hash_rihs01(t) for t in {names:?}}}))"
    );
    let theirs = crate::ros2::oracle_json(&script, &[]);
    assert!(names.len() >= 15, "{names:?}");
    for (name, d) in known {
        assert_eq!(
            theirs[name.as_str()].as_str(),
            Some(d.hash.to_rihs_string().as_str()),
            "{name}"
        );
    }
}

/// `bag info` and `bag echo` read a bag `--bag` wrote, one rosbags wrote (another writer:
/// its times since 1970, no type hashes), and a bag cut short (up to where it stops, said).
#[test]
fn bag_info_and_echo_read_ratelab_s_bags_rosbags_bags_and_bags_cut_short() {
    let dir = tempfile::tempdir().unwrap();
    let ours = dir.path().join("ours");
    let endpoint = format!("tcp/127.0.0.1:{}", free_port());
    let (code, _, err) = ratelab(
        &[
            "run",
            "--clock",
            "virtual",
            "--duration",
            "1",
            "--ros2",
            "--bag",
            ours.to_str().unwrap(),
        ],
        &[connect_to(&endpoint)],
    );
    assert_eq!(code, 0, "{err}");
    let (code, out, err) = ratelab(&["ros2", "bag", "info", ours.to_str().unwrap()], &[]);
    assert_eq!(code, 0, "{err}");
    for needle in [
        "Files:             ours_0.mcap\n",
        "Storage id:        mcap\n",
        "Duration:          1.000000000s\n",
        "Start:             Jan  1 1970 00:00:00.000000000 (0.000000000)\n",
        // /obs, /action and /clock, 51 each, and each node's declared parameters (4).
        "Messages:          157\n",
        "Topic information: Topic: /action | Type: std_msgs/msg/Float64 | Count: 51 | Serialization Format: cdr\n",
        "                   Topic: /obs | Type: sensor_msgs/msg/JointState | Count: 51 | Serialization Format: cdr\n",
        "                   Topic: /parameter_events | Type: rcl_interfaces/msg/ParameterEvent | Count: 4 | Serialization Format: cdr\n",
    ] {
        assert!(out.contains(needle), "{needle:?} in {out}");
    }
    // `ratelab ros2 bag echo` of our bag, with `args` after it.
    let echo_ours = |args: &[&str]| {
        let bag = ours.to_str().unwrap();
        ratelab(&[&["ros2", "bag", "echo", bag][..], args].concat(), &[])
    };
    let (_, out, _) = echo_ours(&["--topic", "/obs", "-n", "2"]);
    assert!(
        out.starts_with("# /obs at 0.000000000 s\nheader:\n"),
        "{out}"
    );
    assert!(out.contains("# /obs at 0.020000000 s\n"), "{out}");
    assert_eq!(out.matches("---\n").count(), 2, "{out}");
    // A relative name is the root namespace's, as `topic echo` takes it.
    let (code, relative, err) = echo_ours(&["--topic", "obs", "-n", "2"]);
    assert_eq!((code, relative), (0, out), "{err}");
    // A bag is read from its files: a graph's setting is refused, not ignored; ros2cli's
    // `bag record` and `bag play` say what does their work.
    for (args, said) in [
        (
            &["info", "--domain", "999"][..],
            "error: --domain: `ros2 bag` reads the bag's files, not a graph",
        ),
        (
            &["echo", "--wait", "2"][..],
            "error: --wait: `ros2 bag` reads the bag's files",
        ),
        (&["record", "-a"][..], "`ratelab run --ros2 --bag DIR`"),
        (&["play"][..], "ROS 2's own `ros2 bag play DIR`"),
    ] {
        let bag = ours.to_str().unwrap();
        let args = [&["ros2", "bag"][..], &args[..1], &[bag], &args[1..]].concat();
        let (code, out, err) = ratelab(&args, &[]);
        assert_eq!((code, out.as_str()), (2, ""), "{args:?}: {err}");
        assert!(
            err.contains(said) && err.trim_end().lines().count() == 1,
            "{args:?}: {err}"
        );
    }
    // A topic with no messages in the bag (a typo) is said, with the topics it has.
    let (code, out, err) = echo_ours(&["--topic", "/ob"]);
    assert_eq!((code, out.as_str()), (2, ""), "{err}");
    assert_eq!(
        err.trim_end(),
        "error: no messages on /ob in this bag (its topics: /action, /clock, /obs, /parameter_events)"
    );
    // A topic it has, with no message asked for (`-n 0`): nothing, and no refusal.
    let (code, out, err) = echo_ours(&["--topic", "/obs", "-n", "0"]);
    assert_eq!((code, out.as_str(), err.as_str()), (0, "", ""));

    // rosbags' writer: MCAP storage, times since 1970, no hashes.
    let theirs = dir.path().join("theirs");
    let script = format!(
        r#"
from rosbags.rosbag2 import Writer, StoragePlugin
from rosbags.typesys import Stores, get_typestore
store = get_typestore(Stores.LATEST)
V, T = store.types['geometry_msgs/msg/Vector3'], store.types['geometry_msgs/msg/Twist']
with Writer({path:?}, version=9, storage_plugin=StoragePlugin.MCAP) as w:
    c = w.add_connection('/cmd_vel', 'geometry_msgs/msg/Twist', typestore=store)
    for i in range(3):
        msg = T(linear=V(x=0.5, y=0.0, z=0.0), angular=V(x=0.0, y=0.0, z=float(i)))
        w.write(c, 1_700_000_000_000_000_000 + i * 50_000_000, store.serialize_cdr(msg, 'geometry_msgs/msg/Twist'))
"#,
        path = theirs.to_str().unwrap()
    );
    let o = Command::new(oracle_python())
        .args(["-c", &script])
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let (code, out, err) = ratelab(&["ros2", "bag", "info", theirs.to_str().unwrap()], &[]);
    assert_eq!(code, 0, "{err}");
    assert!(out.contains("ROS Distro:        rosbags\n"), "{out}");
    assert!(
        out.contains("Start:             Nov 14 2023 22:13:20.000000000 (1700000000.000000000)\n"),
        "{out}"
    );
    assert!(
        out.contains("Topic: /cmd_vel | Type: geometry_msgs/msg/Twist | Count: 3 |"),
        "{out}"
    );
    let (_, out, _) = ratelab(&["ros2", "bag", "echo", theirs.to_str().unwrap()], &[]);
    assert!(
        out.ends_with("# /cmd_vel at 1700000000.100000000 s\nlinear:\n  x: 0.5\n  y: 0.0\n  z: 0.0\nangular:\n  x: 0.0\n  y: 0.0\n  z: 2.0\n---\n"),
        "{out}"
    );

    // Cut short, one byte before its summary (the footer's summary_start): every message and
    // no summary, read up to the cut, and said. (The bag is one chunk; a cut inside it leaves
    // a chunk that declares more than the file holds, which the reader refuses as damaged.)
    let mcap = ours.join("ours_0.mcap");
    let bytes = std::fs::read(&mcap).unwrap();
    let footer = &bytes[bytes.len() - 8 - 29..bytes.len() - 8];
    assert_eq!(footer[0], 0x02, "the footer record");
    let summary_start = u64::from_le_bytes(footer[9..17].try_into().unwrap()) as usize;
    assert!(
        summary_start > 0 && summary_start < bytes.len(),
        "{summary_start}"
    );
    std::fs::write(&mcap, &bytes[..summary_start - 1]).unwrap();
    let (code, out, err) = ratelab(&["ros2", "bag", "echo", ours.to_str().unwrap()], &[]);
    assert_eq!(code, 0, "{err}");
    assert!(out.matches("---\n").count() > 10, "{out}");
    assert!(err.contains("stops short after"), "{err}");
    assert_eq!(err.lines().count(), 1, "{err}");
    let (code, _, err) = ratelab(
        &[
            "ros2",
            "bag",
            "info",
            dir.path().join("none").to_str().unwrap(),
        ],
        &[],
    );
    assert_eq!(code, 2);
    assert!(err.contains("not a folder"), "{err}");
}

/// Where ratelab differed from a real rmw_zenoh_cpp 0.6.7 node (the captures in
/// `../shared/fixtures/ros2-real/`): a publisher's GID is its MP token's XXH3-128, as in the
/// real node's attachments, and a keep-all history carries its depth (`2,10`).
#[test]
fn gids_and_keep_all_depths_are_rmw_zenoh_cpp_s() {
    let talker: serde_json::Value = serde_json::from_slice(
        &std::fs::read(crate::brains::fixture("ros2-real/real-rclpy-talker.json")).unwrap(),
    )
    .unwrap();
    let tokens: Vec<&str> = talker["token_events"]
        .as_array()
        .unwrap()
        .iter()
        .filter_map(|e| e["key"].as_str())
        .filter(|k| k.contains("/MP/"))
        .collect();
    let mut checked = 0;
    for (key, samples) in talker["samples"].as_object().unwrap() {
        // The data key is `<domain>/<topic>/<type>/<hash>`; the MP token names the same
        // topic (mangled `%topic`), type and hash.
        let parts: Vec<&str> = key.splitn(2, '/').collect();
        let (topic_and_type, _) = (parts[1], parts[0]);
        let (topic, rest) = topic_and_type.split_once('/').unwrap();
        let token = tokens
            .iter()
            .find(|t| t.contains(&format!("/%{topic}/{rest}/")))
            .unwrap_or_else(|| panic!("no MP token for {key}"));
        let real = samples[0]["attachment"]["gid"].as_str().unwrap();
        let ours: String = ratelab::ros2::bridge::gid(token)
            .iter()
            .map(|b| format!("{b:02x}"))
            .collect();
        assert_eq!(ours, real, "{token}");
        checked += 1;
    }
    assert!(checked >= 2, "{checked}");
    // The real node's keep-all probe: `::2,10:` (reliability default, keep all, depth 10).
    assert!(
        tokens.iter().any(|t| t.ends_with("/::2,10:,:,:,,")),
        "{tokens:?}"
    );
    // ratelab's keep-all /obs (the fixture's `--qos /obs:history=keep_all,…` run), today:
    // its depth written out, where the capture (before the fix) had `2,`.
    let endpoint = format!("tcp/127.0.0.1:{}", free_port());
    let standin = crate::ros2::StandIn::start("router", &endpoint, 0, &[]);
    let (code, _, err) = ratelab(
        &[
            "run",
            "--clock",
            "virtual",
            "--duration",
            "0.2",
            "--ros2",
            "--qos",
            "/obs:history=keep_all,reliability=reliable,depth=10",
        ],
        &[connect_to(&endpoint)],
    );
    assert_eq!(code, 0, "{err}");
    let r = standin.report();
    let obs: Vec<String> = r["endpoints"]
        .as_array()
        .unwrap()
        .iter()
        .filter(|e| e["topic"] == "/obs")
        .map(|e| e["qos"].as_str().unwrap().to_string())
        .collect();
    assert!(!obs.is_empty());
    for q in &obs {
        assert_eq!(q.split(':').nth(2), Some("2,10"), "{obs:?}");
    }
}

/// ex13's answers (what ROS 2 sees of the chapter's graph, its policy at 40 Hz) are what
/// `ratelab ros2` reads from the wire of such a run: the node list, the topics' types, and
/// /clock's rate (the run is paced to the wall clock with --ros2, so run time is wall time).
#[test]
fn ex13_s_answers_are_what_the_wire_shows() {
    let _alone = crate::machine::alone();
    let mut cfg = ratelab::RunConfig {
        clock: ratelab::ClockKind::Virtual,
        duration: ratelab::config::duration_from_secs(2.0).unwrap(),
        ..ratelab::RunConfig::default()
    };
    cfg.set_control_hz(40.0).unwrap();
    let o = ratelab_exercises::measure_ex13(&cfg, &ratelab::scheduler::StopFlag::new()).unwrap();
    assert_eq!(o.clock_hz, 80.0);
    let run = Offering::start(&[
        "--clock",
        "virtual",
        "--control-hz",
        "40",
        "--duration",
        "10",
        "--ros2",
    ]);
    let endpoint = run.endpoint.clone();
    let ros2 = |verb: &[&str]| {
        let mut args = vec!["ros2", "--connect", endpoint.as_str()];
        args.extend_from_slice(verb);
        ratelab(&args, &[])
    };
    let (_, out, _) = ros2(&["node", "list"]);
    let mut nodes = o.nodes.clone();
    nodes.sort();
    assert_eq!(
        out,
        nodes.iter().map(|n| format!("{n}\n")).collect::<String>()
    );
    let (_, out, _) = ros2(&["topic", "list", "-t"]);
    assert!(out.contains(&format!("/obs [{}]", o.obs_type)), "{out}");
    assert!(
        out.contains(&format!("/action [{}]", o.action_type)),
        "{out}"
    );
    let (_, out, _) = ros2(&["topic", "hz", "/clock", "--duration", "3.2"]);
    let rate: f64 = out
        .lines()
        .rev()
        .find_map(|l| l.strip_prefix("average rate: "))
        .unwrap_or_else(|| panic!("{out}"))
        .parse()
        .unwrap();
    assert!(
        (rate - o.clock_hz).abs() < 4.0,
        "{rate} vs {}: {out}",
        o.clock_hz
    );
    drop(run);
}

/// A capture of `../shared/fixtures/ros2-real/` (real rmw_zenoh_cpp 0.6.7 and real rclpy).
pub(crate) fn real_capture(file: &str) -> serde_json::Value {
    let path = crate::brains::fixture(&format!("ros2-real/{file}"));
    serde_json::from_slice(&std::fs::read(&path).unwrap()).unwrap()
}

/// What `ratelab ros2` reads of a graph is what real ROS 2 read of it, field by field. The
/// liveliness tokens captured in one run beside a real rclpy probe over real rmw_zenoh_cpp
/// (`real-probe-and-ratelab-real-clock.json`: the probe's own, with its /rosout and
/// /parameter_events, and ratelab's) are parsed here; every endpoint real rclpy's graph API
/// gave in that run (`real-rclpy-graph-view-real-clock.json`) is found by its GID in
/// `topic info -v`, with its node, namespace, type, type hash and every QoS field as the
/// graph API gave them, and `node list` names the nodes it named.
#[test]
fn topic_info_reads_a_real_graph_as_real_ros2_s_graph_api_does() {
    use ratelab::ros2::inspect::{node_list, topic_info, Seen};
    let capture = real_capture("real-probe-and-ratelab-real-clock.json");
    let view = real_capture("real-rclpy-graph-view-real-clock.json");
    let mut g = Seen::default();
    let mut keys = std::collections::BTreeSet::new();
    for e in capture["token_events"].as_array().unwrap() {
        let key = e["key"].as_str().unwrap();
        if e["kind"] == "SampleKind.PUT" && keys.insert(key) {
            assert!(g.take(key), "a ROS 2 token: {key}");
        }
    }
    let word = |q: &serde_json::Value, what: &str, words: &[(&str, &str)]| -> String {
        let code = q[what].as_str().unwrap();
        let w = words.iter().find(|(c, _)| *c == code);
        w.unwrap_or_else(|| panic!("{what} {code}")).1.to_string()
    };
    let (mut checked, mut nodes) = (
        std::collections::BTreeSet::new(),
        std::collections::BTreeSet::new(),
    );
    for snap in view["snapshots"].as_array().unwrap() {
        for n in snap["nodes"].as_array().unwrap() {
            let ns = n[1].as_str().unwrap().trim_end_matches('/');
            nodes.insert(format!("{ns}/{}", n[0].as_str().unwrap()));
        }
        for (topic, ends) in snap["endpoints"].as_object().unwrap() {
            let info = topic_info(&g, topic, true).unwrap();
            for (side, what) in [
                ("publishers", "PUBLISHER"),
                ("subscriptions", "SUBSCRIPTION"),
            ] {
                for x in ends[side].as_array().unwrap() {
                    let q = &x["qos"];
                    let gid: Vec<String> = (0..16)
                        .map(|i| x["gid"].as_str().unwrap()[2 * i..2 * i + 2].to_string())
                        .collect();
                    let history = match q["history"].as_str().unwrap() {
                        "1" => format!("KEEP_LAST ({})", q["depth"].as_str().unwrap()),
                        // rclpy's TopicEndpointInfo.__str__ (Jazzy and later): no depth.
                        "2" => "KEEP_ALL".to_string(),
                        h => panic!("history {h}"),
                    };
                    let block = format!(
                        "Node name: {}\nNode namespace: {}\nTopic type: {}\nTopic type hash: {}\nEndpoint type: {what}\nGID: {}\nQoS profile:\n  Reliability: {}\n  History (Depth): {history}\n  Durability: {}\n  Lifespan: {}\n  Deadline: {}\n  Liveliness: {}\n  Liveliness lease duration: {}\n",
                        x["node"].as_str().unwrap(),
                        x["ns"].as_str().unwrap(),
                        x["type"].as_str().unwrap(),
                        x["type_hash"].as_str().unwrap(),
                        gid.join("."),
                        word(q, "reliability", &[("1", "RELIABLE"), ("2", "BEST_EFFORT")]),
                        word(q, "durability", &[("1", "TRANSIENT_LOCAL"), ("2", "VOLATILE")]),
                        q["lifespan"].as_str().unwrap(),
                        q["deadline"].as_str().unwrap(),
                        word(q, "liveliness", &[("1", "AUTOMATIC"), ("3", "MANUAL_BY_TOPIC")]),
                        q["liveliness_lease_duration"].as_str().unwrap(),
                    );
                    assert!(info.contains(&block), "{block}\nis not in\n{info}");
                    checked.insert(x["gid"].as_str().unwrap().to_string());
                }
            }
        }
    }
    // Every endpoint of the run, each once by its GID: the probe's (its subscriptions,
    // /rosout and /parameter_events) and ratelab's (its publishers and subscriptions).
    assert!(checked.len() >= 13, "{checked:?}");
    let theirs = |node: &str| {
        g.endpoints
            .iter()
            .zip(&g.gids)
            .filter(|(e, _)| e.node.as_ref().is_some_and(|n| n.name == node))
            .count()
    };
    assert!(theirs("sensor") >= 1 && theirs("probe") >= 1);
    let listed: std::collections::BTreeSet<String> = node_list(&g, false)
        .names
        .lines()
        .map(String::from)
        .collect();
    assert_eq!(listed, nodes);
}

/// Every sample captured on the wire, from a real rclpy node (`std_msgs/String`,
/// `sensor_msgs/JointState`) and from ratelab as a real subscriber saw it (`/obs`, `/action`,
/// `/clock`), decodes here (`ratelab ros2 topic echo`'s decoder, from the types'
/// descriptions) to the values real rclpy's `deserialize_message` gave, field by field.
#[test]
fn the_captured_samples_decode_as_real_rclpy_decoded_them() {
    fn json(v: &ratelab::ros2::echo::Value) -> serde_json::Value {
        use ratelab::ros2::echo::Value as V;
        match v {
            V::Bool(b) => (*b).into(),
            V::Int(i) => (*i).into(),
            V::UInt(u) => (*u).into(),
            V::Float(f) => (*f).into(),
            V::Str(s) => s.clone().into(),
            V::List(l) => l.iter().map(json).collect(),
            V::Struct(fields) => fields
                .iter()
                .map(|(k, v)| (k.clone(), json(v)))
                .collect::<serde_json::Map<_, _>>()
                .into(),
        }
    }
    let mut decoded = 0;
    for file in [
        "real-rclpy-talker.json",
        "ratelab-default.json",
        "ratelab-qos.json",
        "real-probe-and-ratelab-real-clock.json",
    ] {
        let capture = real_capture(file);
        for (key, samples) in capture["samples"].as_object().unwrap() {
            // `<domain>/<topic>/<pkg>::msg::dds_::<Type>_/<hash>`
            let parts: Vec<&str> = key.rsplitn(3, '/').collect();
            let (hash, dds) = (parts[0], parts[1]);
            let (pkg, ty) = dds.split_once("::msg::dds_::").unwrap();
            let name = format!("{pkg}/msg/{}", ty.trim_end_matches('_'));
            for s in samples.as_array().unwrap() {
                let hex = s["payload_hex"].as_str().unwrap();
                let payload: Vec<u8> = (0..hex.len() / 2)
                    .map(|i| u8::from_str_radix(&hex[2 * i..2 * i + 2], 16).unwrap())
                    .collect();
                let v = ratelab::ros2::echo::decode(&name, hash, &payload)
                    .unwrap_or_else(|e| panic!("{file} {key}: {e}"));
                assert_eq!(json(&v), s["decoded_with_real_rclpy"], "{file} {key}");
                decoded += 1;
            }
        }
    }
    assert!(decoded >= 40, "{decoded}");
}

/// `bag echo` decodes a type ratelab has no description of by the `ros2msg` schema the bag
/// carries (#74): a bag of a made-up `my_pkg/msg/Reading` (constants and comments, a nested
/// `geometry_msgs/Vector3`, a package-relative type in a bounded sequence, arrays, a bounded
/// string) written by rosbags alone (tests/ros2/custom_bag.py: the types registered from
/// their .msg text, the CDR serialized by rosbags, the hash rosbags' RIHS01) prints as
/// ros2cli prints those values (written out by hand below). The description ratelab makes
/// of the schema must hash to the bag's hash: a bag whose hash is another type's is said,
/// message by message, in one line.
#[test]
fn bag_echo_decodes_a_type_from_the_schema_the_bag_carries() {
    let dir = tempfile::tempdir().unwrap();
    let bag = dir.path().join("custom");
    let o = Command::new(oracle_python())
        .arg(crate::repo("tests/ros2/custom_bag.py"))
        .arg(&bag)
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let written: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    let hash = written["hash"].as_str().unwrap();
    // A type ratelab does not describe: only the bag's schema can decode it.
    assert!(!ratelab::ros2::echo::known().contains_key("my_pkg/msg/Reading"));
    let echo = || {
        ratelab(
            &[
                "ros2",
                "bag",
                "echo",
                bag.to_str().unwrap(),
                "--topic",
                "/reading",
            ],
            &[],
        )
    };
    let (code, out, err) = echo();
    assert_eq!(code, 0, "{err}");
    assert_eq!(
        out,
        concat!(
            "# /reading at 1.000000000 s\n",
            "x: 1.5\n",
            "label: first\n",
            "counts:\n- 1\n- -2\n- 3\n",
            "v:\n  x: 0.25\n  y: -0.5\n  z: 1.0e-05\n",
            "parts:\n- name: a\n  w: 0.5\n- name: b c\n  w: -2.0\n",
            "flags:\n- true\n- false\n",
            "tag: none\n",
            "kind: 1\n",
            "---\n",
            "# /reading at 1.500000000 s\n",
            "x: -0.0\n",
            "label: 'true'\n",
            "counts: []\n",
            "v:\n  x: 0.0\n  y: 0.0\n  z: 100.0\n",
            "parts: []\n",
            "flags:\n- false\n- true\n",
            "tag: ''\n",
            "kind: 0\n",
            "---\n",
        )
    );
    assert_eq!(err, "");

    // The bag's hash made another type's: the schema no longer describes the type it names.
    let meta = bag.join("metadata.yaml");
    let text = std::fs::read_to_string(&meta).unwrap();
    assert!(text.contains(hash), "{text}");
    let other = format!("RIHS01_{}", "0".repeat(64));
    std::fs::write(&meta, text.replace(hash, &other)).unwrap();
    let (code, out, err) = echo();
    assert_eq!(code, 0, "{err}");
    let line = format!(
        "<my_pkg/msg/Reading: {{}} bytes, not decoded: a type not described here, and the ros2msg schema describes a type of hash {hash}, not of the bag's {other}>"
    );
    let said: Vec<&str> = out.lines().filter(|l| l.starts_with('<')).collect();
    assert_eq!(said.len(), 2, "{out}");
    for l in said {
        let (head, tail) = line.split_once("{}").unwrap();
        assert!(l.starts_with(head) && l.ends_with(tail), "{l}\nnot {line}");
    }
}
