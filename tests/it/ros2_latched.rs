//! `ratelab ros2 topic echo|bw` on a transient-local ("latched") topic (#74 item 1): the
//! subscription takes the durability and reliability its publishers offer, as ros2cli's
//! `choose_qos` does, so the publishers' stored messages print at once, and `--qos-*` flags
//! replace that choice as ros2cli's do. Checked against the real `ros2` command's output on
//! a real rclpy latcher over real rmw_zenoh_cpp (`../shared/fixtures/ros2-real/
//! kilted-ros2cli/step2`), the latcher played by `tests/ros2/latcher.py` (eclipse-zenoh and
//! rosbags, nothing of ratelab's) as that capture shows it: the same type, QoS and messages.

use crate::distributed::free_port;
use crate::ros2::Oracle;
use std::io::Read;
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

/// `ratelab ARGS`, to be spawned in the repository without the ROS 2 environment variables
/// a developer's shell may hold (`ROS_DOMAIN_ID`, `ZENOH_ROUTER_CHECK_ATTEMPTS`,
/// `ZENOH_CONFIG_OVERRIDE`).
pub(crate) fn ratelab_command<S: AsRef<std::ffi::OsStr>>(args: &[S]) -> Command {
    let mut c = Command::new(env!("CARGO_BIN_EXE_ratelab"));
    c.args(args)
        .current_dir(crate::REPO)
        .env_remove("ROS_DOMAIN_ID")
        .env_remove("ZENOH_ROUTER_CHECK_ATTEMPTS")
        .env_remove("ZENOH_CONFIG_OVERRIDE");
    c
}

/// `ratelab ARGS` (in the repository, without the ROS 2 environment variables), killed if it
/// has not ended within `limit`: its exit code (-1 when killed), stdout, stderr, and how
/// long it ran.
pub(crate) fn ratelab_within(args: &[&str], limit: Duration) -> (i32, String, String, Duration) {
    let start = Instant::now();
    let mut child = ratelab_command(args)
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    fn drain(mut from: impl Read + Send + 'static) -> std::thread::JoinHandle<String> {
        std::thread::spawn(move || {
            let mut text = String::new();
            let _ = from.read_to_string(&mut text);
            text
        })
    }
    let out = drain(child.stdout.take().unwrap());
    let err = drain(child.stderr.take().unwrap());
    let code = loop {
        if let Some(status) = child.try_wait().unwrap() {
            break status.code().unwrap_or(-1);
        }
        if start.elapsed() > limit {
            let _ = child.kill();
            let _ = child.wait();
            break -1;
        }
        std::thread::sleep(Duration::from_millis(20));
    };
    let took = start.elapsed();
    (code, out.join().unwrap(), err.join().unwrap(), took)
}

/// A capture of the real `ros2` command (`kilted-ros2cli/PATH`): its exit code and its
/// stdout, without the zenoh-c log lines ([`crate::ros2_cli_rules::capture`]).
fn ros2cli(path: &str) -> (i32, String) {
    let (rc, out, _) = crate::ros2_cli_rules::capture(path);
    (rc, out)
}

/// The first endpoint's `QoS profile:` block of a `topic info -v`, through its lease line.
fn qos_block(info: &str) -> String {
    let at = info
        .find("QoS profile:\n")
        .unwrap_or_else(|| panic!("{info}"));
    let rest = &info[at..];
    let lease = rest.find("  Liveliness lease duration: ").unwrap();
    let end = lease + rest[lease..].find('\n').unwrap() + 1;
    rest[..end].to_string()
}

/// Each of `texts` as `topic echo` prints a std_msgs/msg/String.
fn echoed(texts: &[String]) -> String {
    texts.iter().map(|t| format!("data: {t}\n---\n")).collect()
}

/// The real latcher published 7 messages, keep last 5, then nothing; real `ros2 topic echo
/// --once /latched` printed the oldest of the 5 it stores, at once. `ratelab ros2` on the
/// same topic prints the same, at once, and `-n 5` all five; a volatile subscription (a
/// `--qos-*` flag turns ros2cli's adaptation off) gets none of them.
#[test]
fn a_latched_topic_is_echoed_at_once_as_real_ros2cli_echoes_it() {
    // Processes of its own beside the suite: never beside a timing test.
    let _m = crate::machine::shared();
    let endpoint = format!("tcp/127.0.0.1:{}", free_port());
    let published = crate::brains::fixture("ros2-real/kilted-ros2cli/step2/real-other.json");
    let args = [endpoint.as_str(), "0", published.to_str().unwrap()];
    let _latcher = Oracle::start("tests/ros2/latcher.py", &args, "the latcher");
    let ros2 = |verb: &[&str]| {
        let mut args = vec!["ros2", "--connect", endpoint.as_str()];
        args.extend_from_slice(verb);
        ratelab_within(&args, Duration::from_secs(30))
    };
    // The stand-in offers /latched as the real node did: its QoS as real ros2cli printed it.
    let (real_rc, real_info) = ros2cli("step2/ros2cli/topic-info-v_latched.txt");
    let (code, info, err, _) = ros2(&["topic", "info", "-v", "/latched"]);
    assert_eq!((code, real_rc), (0, 0), "{err}");
    assert_eq!(qos_block(&info), qos_block(&real_info));
    assert!(real_info.contains("  Durability: TRANSIENT_LOCAL\n"));
    // Line for line, but the GIDs (each run's own): to its last line, the empty one after
    // the last endpoint (ratelab left it out).
    let gids = |s: &str| -> String {
        (s.lines())
            .map(|l| {
                if l.starts_with("GID: ") {
                    "GID: …\n".to_string()
                } else {
                    format!("{l}\n")
                }
            })
            .collect()
    };
    assert!(real_info.ends_with("\n\n"), "{real_info:?}");
    assert_eq!(gids(&info), gids(&real_info));
    // What the real node published; what its publisher stores (its depth, from ros2cli).
    let sent: serde_json::Value =
        serde_json::from_slice(&std::fs::read(&published).unwrap()).unwrap();
    let sent: Vec<String> = sent["published"]["/latched"]
        .as_array()
        .unwrap()
        .iter()
        .map(|t| t.as_str().unwrap().to_string())
        .collect();
    let depth: usize = real_info
        .lines()
        .find_map(|l| l.strip_prefix("  History (Depth): KEEP_LAST ("))
        .and_then(|d| d.strip_suffix(')'))
        .and_then(|d| d.parse().ok())
        .unwrap();
    let stored = &sent[sent.len() - depth..];
    // Real ros2cli printed the oldest stored message, and ratelab prints exactly that.
    let (real_rc, real_out) = ros2cli("step2/ros2cli/topic-echo-once_latched.txt");
    assert_eq!(real_out, echoed(&stored[..1]));
    let (code, out, err, took) = ros2(&["topic", "echo", "--once", "/latched"]);
    assert_eq!((code, out.as_str()), (real_rc, real_out.as_str()), "{err}");
    // At once: the graph's wait (1 s) and the history's query, not a publication.
    assert!(took < Duration::from_secs(10), "{took:?}");
    let (code, out, err, took) = ros2(&["topic", "echo", "/latched", "-n", &depth.to_string()]);
    assert_eq!((code, out), (0, echoed(stored)), "{err}");
    assert!(took < Duration::from_secs(10), "{took:?}");
    // ros2cli's rule: any --qos-* flag turns the adaptation off, the policy not given is
    // sensor_data's (volatile), so a volatile subscription hears none of the stored ones.
    let (code, out, err, took) = ros2(&[
        "topic",
        "echo",
        "/latched",
        "--once",
        "--qos-reliability",
        "reliable",
        "--timeout",
        "2",
    ]);
    assert_eq!((code, out.as_str()), (0, ""), "{err}");
    assert!(took >= Duration::from_secs(2), "{took:?}");
    // bw hears the stored messages too (rolling ros2cli's bw chooses its QoS as echo does).
    let (code, out, err, _) = ros2(&["topic", "bw", "/latched", "--duration", "1.5"]);
    assert_eq!(code, 0, "{err}");
    assert!(out.starts_with("Subscribed to [/latched]\n"), "{out}");
    assert!(out.contains(&format!(" from {depth} messages\n")), "{out}");
}

/// A topic one of whose publishers is transient local and the other volatile: ros2cli says
/// so and subscribes volatile (which connects to both), so the stored message is not
/// printed; `--qos-durability transient_local` asks for it, and gets it at once.
#[test]
fn a_topic_of_mixed_durability_falls_back_to_volatile_as_ros2cli_says() {
    // Processes of its own beside the suite: never beside a timing test.
    let _m = crate::machine::shared();
    let endpoint = format!("tcp/127.0.0.1:{}", free_port());
    let published = crate::brains::fixture("ros2-real/kilted-ros2cli/step2/real-other.json");
    let args = [endpoint.as_str(), "0", published.to_str().unwrap()];
    let _latcher = Oracle::start("tests/ros2/latcher.py", &args, "the latcher");
    let ros2 = |verb: &[&str]| {
        let mut args = vec!["ros2", "--connect", endpoint.as_str(), "topic", "echo"];
        args.extend_from_slice(verb);
        ratelab_within(&args, Duration::from_secs(30))
    };
    // ros2cli's words (ros2topic's verb/echo.py, `choose_qos`), on stdout.
    let said = "Some, but not all, publishers are offering QoSDurabilityPolicy.TRANSIENT_LOCAL. Falling back to QoSDurabilityPolicy.VOLATILE as it will connect to all publishers\n";
    let (code, out, err, _) = ros2(&["/mixed", "--once", "--timeout", "2"]);
    assert_eq!((code, out.as_str()), (0, said), "{err}");
    let (code, out, err, took) = ros2(&["/mixed", "--once", "--qos-durability", "transient_local"]);
    assert_eq!((code, out.as_str()), (0, "data: kept\n---\n"), "{err}");
    assert!(took < Duration::from_secs(10), "{took:?}");
    // A value rclpy has but no subscription here can take: refused by name, in one line.
    let (code, _, err, _) = ros2(&["/mixed", "--qos-durability", "best_available"]);
    assert_eq!(code, 2, "{err}");
    assert_eq!(err.trim().lines().count(), 1, "{err}");
    assert!(err.contains("--qos-durability"), "{err}");
    let (code, _, err, _) = ros2(&["/mixed", "--timeout", "0"]);
    assert_eq!(code, 2, "{err}");
    assert!(
        err.contains("'0' for '--timeout <S>': must be a number of seconds in (0, 1000000]"),
        "{err}"
    );
}
