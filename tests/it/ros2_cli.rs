//! `ratelab ros2` (#52): ros2cli's verbs on an rmw_zenoh graph, read from the other side: a
//! `ratelab run --ros2` (which runs its own router) read by the real binary, and every type
//! `echo` decodes hashed as rosbags (an independent implementation) hashes it.

use crate::distributed::free_port;
use crate::ros2::{connect_to, oracle_python, ratelab};
use std::io::{BufRead, BufReader};
use std::process::{Command, Stdio};

/// A graph offered to ROS 2 under the real clock, through a router at a free port (the
/// run's own), read with `ratelab ros2 --connect` while it runs.
#[test]
fn ros2_verbs_read_a_running_graph_as_ros2cli_prints_it() {
    let _alone = crate::machine::alone();
    let endpoint = format!("tcp/127.0.0.1:{}", free_port());
    let mut run = Command::new(env!("CARGO_BIN_EXE_ratelab"))
        .args(["run", "--clock", "real", "--duration", "12", "--ros2", "4"])
        .current_dir(crate::REPO)
        .env_remove("ROS_DOMAIN_ID")
        .env_remove("ZENOH_ROUTER_CHECK_ATTEMPTS")
        .env(connect_to(&endpoint).0, connect_to(&endpoint).1)
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    // Its first lines say it runs the router and offers the graph.
    let mut err = BufReader::new(run.stderr.take().unwrap());
    let mut said = String::new();
    while !said.contains("offering the graph to ROS 2") {
        let mut line = String::new();
        if err.read_line(&mut line).unwrap() == 0 {
            break;
        }
        said.push_str(&line);
    }
    assert!(said.contains("offering the graph to ROS 2"), "{said}");
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
        "/action [std_msgs/msg/Float64]\n/clock [rosgraph_msgs/msg/Clock]\n/obs [sensor_msgs/msg/JointState]\n"
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
        "Endpoint type: PUBLISHER\nQoS profile:\n  Reliability: BEST_EFFORT\n  History (Depth): KEEP_LAST (1)\n",
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
    // What is not there is said in one line, exit 2.
    let (code, _, err) = ros2(&["topic", "echo", "/nothing", "--once"]);
    assert_eq!(code, 2);
    assert!(err.contains("no publisher of '/nothing'"), "{err}");
    let (code, _, err) = ros2(&["node", "info", "/nobody"]);
    assert_eq!(
        (code, err.trim()),
        (2, "error: Unable to find node '/nobody'")
    );
    let _ = run.kill();
    let _ = run.wait();
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
    let (code, _, err) = ratelab(&["ros2", "--domain", "999", "node", "list"], &[]);
    assert_eq!(code, 2);
    assert!(err.contains("--domain"), "{err}");
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
    let o = Command::new(oracle_python())
        .args(["-c", &script])
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let theirs: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    assert!(names.len() >= 15, "{names:?}");
    for (name, d) in known {
        assert_eq!(
            theirs[name.as_str()].as_str(),
            Some(d.hash.to_rihs_string().as_str()),
            "{name}"
        );
    }
}
