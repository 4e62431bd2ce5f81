//! Each node of a `--ros2` run as a ROS 2 node is besides its topics: `ros2 param list /
//! get / describe / set` answer from the graph file's parameters, and the node's log
//! reaches `/rosout`; and transient-local durability over the wire: a ROS 2 subscription
//! joining late gets the last messages of a transient-local topic, and of `/rosout`. The client is `tests/ros2/param_client.py` (PyPI `eclipse-zenoh` and
//! `rosbags`, nothing of ratelab's), calling with the service type hashes a real rclpy node
//! declared over real rmw_zenoh_cpp (`../shared/fixtures/ros2-real/`).

use crate::ros2::{connect_to, ratelab, Oracle};
use crate::ros2_cli::Offering;
use serde_json::{json, Value};

/// A Python node that prints every tenth reading it hears, with parameters of every kind
/// a graph file gives, beside the chapter's graph.
const CHATTY: &str = r#"
[[node]]
name = "chatty"
kind = "python"
script = "chatty.py"
class = "Chatty"
rate_hz = 10
subscribes = "/obs"
params = { gain = 2.5, mode = "calm", window = [1, 2, 3], on = true }
"#;

const CHATTY_PY: &str = r#"
from ratelab import State


class Chatty:
    def __init__(self, node):
        self.heard = 0
        node.create_subscription(State, "/obs", self.on_obs, 1)

    def on_obs(self, msg):
        self.heard += 1
        if self.heard % 10 == 1:
            print(f"heard {self.heard}")
"#;

/// The chapter's graph with `extra` (`[[node]]` and `[[topic]]` tables, after its own: an
/// array of tables may go on anywhere) and the Python `scripts` it runs, written in `dir`
/// as `g.toml`, `NAME.py`, …; the graph file.
fn chapter_with(
    dir: &std::path::Path,
    extra: &str,
    scripts: &[(&str, &str)],
) -> std::path::PathBuf {
    let chapter = std::fs::read_to_string(crate::repo("graphs/cartpole.toml")).unwrap();
    let graph = dir.join("g.toml");
    std::fs::write(&graph, format!("{chapter}\n{extra}")).unwrap();
    for (name, code) in scripts {
        std::fs::write(dir.join(name), code).unwrap();
    }
    graph
}

#[test]
fn ros2_param_answers_from_the_graph_file_and_the_log_reaches_rosout() {
    let _alone = crate::machine::alone();
    let dir = tempfile::tempdir().unwrap();
    // And a twin that says one line only, at its first reading: two /rosout publishers.
    let twin = CHATTY
        .replace("name = \"chatty\"", "name = \"twin\"")
        .replace("chatty.py", "twin.py")
        .replace(
            "params = { gain = 2.5, mode = \"calm\", window = [1, 2, 3], on = true }",
            "",
        );
    let once = CHATTY_PY.replace("self.heard % 10 == 1", "self.heard == 1");
    let graph = chapter_with(
        dir.path(),
        &format!("{CHATTY}\n{twin}"),
        &[("chatty.py", CHATTY_PY), ("twin.py", &once)],
    );
    let run = Offering::start(&[
        "--graph",
        graph.to_str().unwrap(),
        "--ros2",
        "6",
        "--clock",
        "real",
        "--duration",
        "30",
    ]);
    let endpoint = run.endpoint.clone();
    let talker = crate::brains::fixture("ros2-real/real-rclpy-talker.json");
    let client = Oracle::start(
        "tests/ros2/param_client.py",
        &[
            &endpoint,
            "6",
            talker.to_str().unwrap(),
            "chatty",
            "policy",
            "ratelab",
        ],
        "the parameter client",
    );
    let r = client.report();
    // `ratelab ros2 node info` lists the services as ros2cli does, while the run goes on.
    let (code, info, e) = ratelab(
        &[
            "ros2",
            "--connect",
            &endpoint,
            "--domain",
            "6",
            "node",
            "info",
            "/chatty",
        ],
        &[],
    );
    // ratelab's own `ros2 param` and `topic echo /rosout`, as ros2cli prints them.
    let ros2 = |verb: &[&str]| {
        let mut args = vec!["ros2", "--connect", endpoint.as_str(), "--domain", "6"];
        args.extend_from_slice(verb);
        ratelab(&args, &[])
    };
    let listed = ros2(&["param", "list", "chatty"]);
    let got = ros2(&["param", "get", "/chatty", "window"]);
    let all = ros2(&["param", "list"]);
    let missing = ros2(&["param", "get", "/nobody", "x"]);
    let unset = ros2(&["param", "get", "/policy", "no_such_parameter"]);
    let refused = ros2(&["param", "set", "/policy", "rate_hz", "20.0"]);
    let log = ros2(&["topic", "echo", "/rosout", "--once"]);
    // A subscription joining now, transient local as a ROS 2 one to /rosout is: the node's
    // first line, written seconds ago, is in its history.
    let args = [endpoint.as_str(), "6/rosout/**", "1000", "1.5"];
    let kept = Oracle::start("tests/ros2/late_joiner.py", &args, "the late joiner").report();
    // With a history of one per publisher, each node's newest line: the twin's only line,
    // seconds old, though chatty has written since (every /rosout publisher has a numbered
    // history of its own, as rmw_zenoh_cpp's reliable ones have; one shared history of
    // one would hold chatty's newest alone).
    let args = [endpoint.as_str(), "6/rosout/**", "1", "1.5"];
    let newest = Oracle::start("tests/ros2/late_joiner.py", &args, "the late joiner").report();
    drop(run);
    assert_eq!(
        listed,
        (
            0,
            "  gain\n  mode\n  on\n  rate_hz\n  start_type_description_service\n  use_sim_time\n  window\n".into(),
            String::new()
        )
    );
    assert_eq!(got.1, "Integer values are: [1, 2, 3]\n", "{got:?}");
    assert!(
        all.1
            .contains("/policy:\n  rate_hz\n  start_type_description_service\n  use_sim_time\n/ratelab:\n  start_type_description_service\n  use_sim_time\n"),
        "{all:?}"
    );
    // As real ros2cli said them (kilted-ros2cli/step2/ros2cli): its words alone on stderr,
    // exit 1.
    let capture = crate::ros2_cli_rules::capture;
    let (rc, _, said) = capture("step2/ros2cli/param-get-nonode.txt");
    assert_eq!((missing.0, missing.2.trim()), (rc, said.trim()));
    assert_eq!((rc, said.as_str()), (1, "Node not found\n"));
    let (rc, _, said) = capture("step2/ros2cli/param-get-no_such.txt");
    assert_eq!((unset.0, unset.2.trim()), (rc, said.trim()));
    assert_eq!((rc, said.as_str()), (1, "Parameter not set\n"));
    // A headless run takes no commands: its rates are read-only over ROS 2. The node's
    // refusal is said on stderr, nothing on stdout, exit 0, as real ros2cli's
    // (param-set-ro.txt: `Setting parameter failed: Trying to set a read-only parameter: ro.`).
    let (rc, out, said) = capture("step2/ros2cli/param-set-ro.txt");
    assert_eq!((rc, out.as_str()), (0, ""));
    assert!(said.starts_with("Setting parameter failed: "), "{said}");
    assert_eq!(
        (refused.0, refused.1.as_str()),
        (rc, out.as_str()),
        "{refused:?}"
    );
    assert!(
        refused.2.starts_with("Setting parameter failed: /policy: rate_hz is read-only in a run that takes no commands"),
        "{refused:?}"
    );
    assert_eq!(refused.2.lines().count(), 1, "{refused:?}");
    // Every /rosout publisher is transient local, so `echo --once` prints the oldest line a
    // node still keeps (as ros2cli's does), which may be one of ratelab's own warnings.
    assert_eq!(log.0, 0, "{log:?}");
    assert!(log.1.starts_with("stamp:\n  sec: "), "{log:?}");
    let level = log.1.lines().find_map(|l| l.strip_prefix("level: "));
    assert!(matches!(level, Some("20" | "30" | "40")), "{log:?}");
    assert!(log.1.contains("\nname: "), "{log:?}");
    assert_eq!(r["errors"], json!([]), "{r}");
    let chatty = &r["nodes"]["chatty"];
    assert_eq!(
        chatty["names"],
        json!([
            "gain",
            "mode",
            "on",
            "rate_hz",
            "start_type_description_service",
            "use_sim_time",
            "window"
        ]),
        "{r}"
    );
    assert_eq!(chatty["prefixes"], json!([]));
    assert_eq!(
        chatty["values"],
        json!({
            "gain": [3, 2.5], "mode": [4, "calm"], "on": [1, true],
            "rate_hz": [3, 10.0], "start_type_description_service": [1, true], "use_sim_time": [1, true],
            "window": [7, [1, 2, 3]],
        })
    );
    assert_eq!(chatty["types"], json!([3, 4, 1, 3, 1, 1, 7]));
    // An undeclared name among them: no types at all (rclcpp and rclpy).
    assert_eq!(chatty["types_with_undeclared"], json!([]));
    assert_eq!(chatty["described"]["name"], "gain");
    assert_eq!(chatty["described"]["read_only"], true);
    // Every set refused, each with its reason.
    let set = chatty["set"].as_array().unwrap();
    assert_eq!(set.len(), 8);
    assert!(set.iter().all(|s| s["successful"] == false), "{set:?}");
    let reason = |i: usize| set[i]["reason"].as_str().unwrap();
    assert!(reason(0).contains("'gain' is read-only"), "{}", reason(0));
    assert!(
        reason(3).contains("rate_hz is read-only in a run that takes no commands"),
        "{}",
        reason(3)
    );
    // rclcpp's words for the parameter every node since Jazzy has (param-set-ro.txt).
    assert_eq!(
        reason(4),
        "Trying to set a read-only parameter: start_type_description_service."
    );
    assert!(reason(7).contains("is not declared"), "{}", reason(7));
    // Each reply carried the request's sequence number and the client's GID.
    for node in ["chatty", "policy", "ratelab"] {
        assert_eq!(r["nodes"][node]["attachments_ok"], true, "{node}: {r}");
    }
    assert_eq!(r["nodes"]["policy"]["values"]["rate_hz"], json!([3, 50.0]));
    assert_eq!(
        r["nodes"]["ratelab"]["values"],
        json!({"start_type_description_service": [1, true], "use_sim_time": [1, false]})
    );
    // The node's prints, on /rosout as its log (INFO, named for it).
    let heard: Vec<&Value> = r["rosout"]
        .as_array()
        .unwrap()
        .iter()
        .filter(|l| l["node"] == "chatty")
        .collect();
    assert!(!heard.is_empty(), "{r}");
    assert!(heard.iter().all(|l| l["level"] == 20), "{heard:?}");
    assert!(
        heard
            .iter()
            .all(|l| l["msg"].as_str().unwrap().starts_with("heard ")),
        "{heard:?}"
    );
    let heard_first = |r: &Value| {
        r["samples"]
            .as_array()
            .unwrap()
            .iter()
            .any(|s| s["name"] == "chatty" && s["msg"] == "heard 1")
    };
    assert!(heard_first(&kept), "{kept}");
    assert_eq!(kept["errors"], json!([]));
    let from = |node: &str| {
        newest["samples"]
            .as_array()
            .unwrap()
            .iter()
            .any(|s| s["name"] == node)
    };
    assert!(from("twin"), "{newest}");
    assert_eq!(code, 0, "{e}");
    for line in [
        "  Publishers:\n    /parameter_events: rcl_interfaces/msg/ParameterEvent\n    /rosout: rcl_interfaces/msg/Log\n",
        "  Service Servers:\n    /chatty/describe_parameters: rcl_interfaces/srv/DescribeParameters\n    /chatty/get_parameter_types: rcl_interfaces/srv/GetParameterTypes\n",
    ] {
        assert!(info.contains(line), "{line:?} in {info}");
    }
}

/// A rate changed while the run goes on (the lab's keys) is said on `/parameter_events`,
/// as ROS 2 says a changed parameter, and `get_parameters` answers the new rate.
#[test]
fn a_changed_rate_is_a_parameter_event() {
    use ratelab::ros2::session::{open, SessionEnv};
    use ratelab::ros2::{echo, Bridge, Ros2Options};
    use zenoh::Wait;
    let env = SessionEnv {
        router_check_attempts: Some("-1".into()),
        config_override: Some(
            connect_to(&format!(
                "tcp/127.0.0.1:{}",
                crate::distributed::free_port()
            ))
            .1,
        ),
    };
    let link = open(&env, &ratelab::scheduler::StopFlag::new()).unwrap();
    let (tx, rx) = std::sync::mpsc::channel();
    let sub = link
        .session
        .declare_subscriber("8/parameter_events/**")
        .callback(move |s| {
            let _ = tx.send(s.payload().to_bytes().into_owned());
        })
        .wait()
        .unwrap();
    let cfg = ratelab::RunConfig::default();
    let brain = ratelab::checkpoint::load_policy("scripted").unwrap();
    let slot = ratelab::policy::BrainSlot::new(brain);
    let graph = ratelab::run::build_graph(&cfg, slot, false, Vec::new()).unwrap();
    let h = &graph.handles;
    let opts = Ros2Options {
        domain: 8,
        bag: None,
        force: false,
    };
    let stop = ratelab::scheduler::StopFlag::new();
    let bridge = Bridge::start(
        &link,
        &ratelab::ros2::bridge::Offer::whole(h),
        &opts,
        cfg.clock,
        &stop,
    )
    .unwrap();
    let policy = h.spec.node_id("policy").unwrap();
    h.rates[policy.0].set_hz(20.0).unwrap();
    let (name, hash) = (
        "rcl_interfaces/msg/ParameterEvent",
        ratelab::ros2::rcl_interfaces::PARAMETER_EVENT_HASH,
    );
    let mut changed = None;
    let deadline = std::time::Instant::now() + std::time::Duration::from_secs(5);
    while changed.is_none() && std::time::Instant::now() < deadline {
        let Ok(bytes) = rx.recv_timeout(std::time::Duration::from_millis(200)) else {
            continue;
        };
        let yaml = echo::yaml(&echo::decode(name, hash, &bytes).unwrap());
        if yaml.contains("changed_parameters:\n- name: rate_hz") {
            changed = Some(yaml);
        }
    }
    let changed = changed.expect("no event for the changed rate within 5 s");
    assert!(changed.contains("node: /policy\n"), "{changed}");
    assert!(changed.contains("    double_value: 20.0\n"), "{changed}");
    let value = ratelab::ros2::param_cli::get(
        &link.session,
        8,
        "/policy",
        "rate_hz",
        std::time::Duration::from_secs(5),
    )
    .unwrap();
    assert_eq!(value.map(|v| v.double_value), Some(20.0));
    // Each node describes the types it uses (~/get_type_description): what it gives hashes
    // to the hash a real rclpy node declared for the same type (the fixture's talker).
    let real = crate::ros2_cli::real_capture("real-rclpy-talker.json");
    let real_hash = |dds: &str| {
        let t = real["tokens_parsed"].as_array().unwrap().iter();
        t.clone()
            .find(|t| t["type"] == dds)
            .map(|t| t["type_hash"].as_str().unwrap().to_string())
            .unwrap()
    };
    let fetch = |node: &str, ty: &str, dds: &str| {
        let hash = real_hash(dds);
        let wait = std::time::Duration::from_secs(5);
        ratelab::ros2::type_description::fetch(&link.session, 8, node, (ty, hash.as_str()), wait)
    };
    let js = fetch(
        "/policy",
        "sensor_msgs/msg/JointState",
        "sensor_msgs::msg::dds_::JointState_",
    )
    .unwrap();
    assert_eq!(js.type_description.fields[0].name, "header");
    fetch(
        "/sensor",
        "rcl_interfaces/msg/Log",
        "rcl_interfaces::msg::dds_::Log_",
    )
    .unwrap();
    let not_its = fetch(
        "/sensor",
        "std_msgs/msg/Float64",
        "std_msgs::msg::dds_::Float64_",
    )
    .unwrap_err();
    assert!(
        not_its.ends_with("Type not currently in use by this node"),
        "{not_its}"
    );
    bridge.finish();
    let _ = sub.undeclare().wait();
    link.close();
}

/// A node that publishes a count on /beat, a transient-local topic nobody subscribes to.
const BEAT: &str = r#"
[[node]]
name = "beat"
kind = "python"
script = "beat.py"
class = "Beat"
rate_hz = 10
publishes = "/beat"

[[topic]]
name = "/beat"
type = "force"
depth = 5
durability = "transient_local"
"#;

const BEAT_PY: &str = r#"
from ratelab import Force


class Beat:
    def __init__(self, node):
        self.n = 0
        self.pub = node.create_publisher(Force, "/beat", 5)
        node.create_timer(node.get_period(), self.on_timer)

    def on_timer(self):
        self.n += 1
        self.pub.publish(Force(newtons=float(self.n)))
"#;

/// A transient-local topic keeps its last `depth` messages for a ROS 2 subscription that
/// joins late (`tests/ros2/late_joiner.py`, rmw_zenoh_cpp's transient-local subscription
/// played with eclipse-zenoh's advanced subscriber): /beat's publisher stalls after its
/// 15th message, and a subscription joining seconds later gets its last 5, numbered as they
/// were published (from the publisher's cache: it publishes nothing after them). So does
/// `ratelab ros2 topic echo`, at once (#74 item 1).
#[test]
fn a_late_ros_2_subscription_gets_a_transient_local_topic_s_last_messages() {
    let _alone = crate::machine::alone();
    let dir = tempfile::tempdir().unwrap();
    let graph = chapter_with(dir.path(), BEAT, &[("beat.py", BEAT_PY)]);
    // Ticks at 0, 0.1, …, 1.4 s publish messages 1 to 15; from 1.45 s it is stalled.
    let run = Offering::start(&[
        "--graph",
        graph.to_str().unwrap(),
        "--ros2",
        "5",
        "--clock",
        "real",
        "--duration",
        "30",
        "--stall",
        "beat@1.45+60",
    ]);
    std::thread::sleep(std::time::Duration::from_secs(3));
    let args = [run.endpoint.as_str(), "5/beat/**", "5", "1.5"];
    let kept = Oracle::start("tests/ros2/late_joiner.py", &args, "the late joiner").report();
    let (code, info, err) = ratelab(
        &[
            "ros2",
            "--connect",
            &run.endpoint,
            "--domain",
            "5",
            "topic",
            "info",
            "/beat",
            "-v",
        ],
        &[],
    );
    // `ratelab ros2 topic echo` subscribes transient local, as the publisher offers (ros2cli's
    // rule): the stored five at once; made volatile (`--qos-durability`), none.
    let echo = |extra: &[&str]| {
        let mut args = vec!["ros2", "--connect", run.endpoint.as_str(), "--domain", "5"];
        args.extend_from_slice(&["topic", "echo", "/beat"]);
        args.extend_from_slice(extra);
        crate::ros2_latched::ratelab_within(&args, std::time::Duration::from_secs(30))
    };
    let stored = echo(&["-n", "5"]);
    let volatile = echo(&["--once", "--qos-durability", "volatile", "--timeout", "2"]);
    drop(run);
    let (echo_code, out, echo_err, took) = stored;
    assert_eq!(echo_code, 0, "{echo_err}");
    let beats: String = (11..=15).map(|n| format!("data: {n}.0\n---\n")).collect();
    assert_eq!(out, beats);
    assert!(took < std::time::Duration::from_secs(10), "{took:?}");
    assert_eq!((volatile.0, volatile.1.as_str()), (0, ""), "{}", volatile.2);
    let seqs: Vec<i64> = kept["samples"]
        .as_array()
        .unwrap()
        .iter()
        .map(|s| s["seq"].as_i64().unwrap())
        .collect();
    assert_eq!(seqs, [11, 12, 13, 14, 15], "{kept}");
    assert_eq!(code, 0, "{err}");
    assert!(info.contains("  Durability: TRANSIENT_LOCAL\n"), "{info}");
}
