//! ros2cli's rules in `ratelab ros2` (#74 item 5): hidden names (`node list -a`, `topic list
//! --include-hidden-topics`, `node info --include-hidden`), nodes that share a name (listed
//! each, warned of, never merged), a topic of two types (refused by `echo`, `hz` and `bw`),
//! the formats of `hz`, `bw`, plain `topic info` and `topic list -v` (ros2topic's
//! `verb/list.py`: no capture of it), and ros2cli's exit codes (a topic not published yet,
//! and Ctrl-C: `ros2_cli_waits.rs`). Checked against the real `ros2` command's output on a
//! real graph (`../shared/fixtures/ros2-real/kilted-ros2cli/step2`: ros2cli 0.36.1, real
//! rclpy over real rmw_zenoh_cpp 0.6.7), the
//! graph played by stand-ins written with eclipse-zenoh and rosbags only, nothing of
//! ratelab's: `tests/ros2/edges.py` (the capture's edge cases) and `tests/ros2/latcher.py`
//! (its latched topic).

use crate::distributed::free_port;
use crate::ros2::Oracle;
use crate::ros2_latched::ratelab_within;
use std::collections::BTreeSet;
use std::time::Duration;

/// A capture of a command (`kilted-ros2cli/PATH`: the command line, `# rc=…`, then its
/// stdout and stderr): its exit code, stdout and stderr, without the zenoh-c log lines that
/// reached them (each begins with an escape sequence).
pub(crate) fn capture(path: &str) -> (i32, String, String) {
    let file = crate::brains::fixture(&format!("ros2-real/kilted-ros2cli/{path}"));
    let text = std::fs::read_to_string(file).unwrap();
    let rc: i32 = text
        .lines()
        .find_map(|l| l.strip_prefix("# rc="))
        .and_then(|r| r.split_whitespace().next())
        .and_then(|r| r.parse().ok())
        .unwrap_or_else(|| panic!("no rc in {path}"));
    let (_, rest) = text.split_once("# --- stdout\n").unwrap();
    let (out, err) = rest.split_once("# --- stderr").unwrap();
    let err = err.strip_prefix('\n').unwrap_or(err);
    let clean = |s: &str| -> String {
        s.lines()
            .filter(|l| !l.starts_with('\x1b'))
            .map(|l| format!("{l}\n"))
            .collect()
    };
    (rc, clean(out), clean(err))
}

/// An edge case's capture (`kilted-ros2cli/step2/edge/NAME`): what the command printed,
/// stderr and stdout together (its warning first), and its exit code (the last line, `rc=N`).
fn edge(name: &str) -> (i32, String) {
    let file = crate::brains::fixture(&format!("ros2-real/kilted-ros2cli/step2/edge/{name}"));
    let text = std::fs::read_to_string(file).unwrap();
    let (said, rc) = text
        .trim_end()
        .rsplit_once("\nrc=")
        .unwrap_or_else(|| panic!("no rc in {name}"));
    (rc.parse().unwrap(), format!("{said}\n"))
}

/// `topic list -t`'s lines as (topic, its types as a set): rmw_zenoh_cpp gives a topic's
/// types in no fixed order (the real captures list /mixed's two both ways), ratelab sorted.
fn by_topic(listing: &str) -> Vec<(String, BTreeSet<String>)> {
    listing
        .lines()
        .map(|l| {
            let (topic, types) = l.split_once(" [").unwrap_or_else(|| panic!("{l}"));
            let types = types.strip_suffix(']').unwrap_or_else(|| panic!("{l}"));
            (topic.into(), types.split(", ").map(String::from).collect())
        })
        .collect()
}

/// `ratelab ros2 --connect ENDPOINT VERB…`: exit code, stdout, stderr.
fn ros2_at(endpoint: &str, verb: &[&str]) -> (i32, String, String) {
    let mut args = vec!["ros2", "--connect", endpoint];
    args.extend_from_slice(verb);
    let (code, out, err, _) = ratelab_within(&args, Duration::from_secs(30));
    (code, out, err)
}

/// The real graph's edge cases, listed as real ros2cli listed them: a hidden node and topic
/// left out unless asked for, a name two nodes share listed twice after ros2cli's warning,
/// `node info` of that name warning and showing one node (not the union of both), and a
/// topic of two types shown as a Python list and refused by `echo`, `hz` and `bw` in
/// ros2cli's words with its exit code.
#[test]
fn hidden_and_shared_names_and_a_topic_of_two_types_read_as_real_ros2cli_reads_them() {
    // Processes of its own beside the suite: never beside a timing test.
    let _m = crate::machine::shared();
    let endpoint = format!("tcp/127.0.0.1:{}", free_port());
    let talker = crate::brains::fixture("ros2-real/real-rclpy-talker.json");
    let args = [endpoint.as_str(), "0", talker.to_str().unwrap()];
    let _edges = Oracle::start("tests/ros2/edges.py", &args, "the edge graph");
    let ros2 = |verb: &[&str]| ros2_at(&endpoint, verb);
    // node list: the warning on stderr, then each /dup; /_hidden_node left out.
    let (rc, real) = edge("ros2-node-list.txt");
    let (warning, listed) = real.split_once('\n').unwrap();
    assert!(warning.starts_with("WARNING: "), "{real}");
    let (code, out, err) = ros2(&["node", "list"]);
    assert_eq!(
        (code, err, out.as_str()),
        (rc, format!("{warning}\n"), listed)
    );
    // -a: the hidden node too (ros2cli's own hidden node, /_ros2cli_…, is not ratelab's).
    let (rc, real) = edge("ros2-node-list-a.txt");
    let real: String = real
        .lines()
        .filter(|l| !l.starts_with("/_ros2cli_"))
        .map(|l| format!("{l}\n"))
        .collect();
    let (code, out, err) = ros2(&["node", "list", "-a"]);
    assert_eq!((code, format!("{err}{out}")), (rc, real));
    // -c counts what would be listed, a shared name once per node.
    assert_eq!(ros2(&["node", "list", "-c"]).1, "4\n");
    assert_eq!(ros2(&["node", "list", "-c", "-a"]).1, "5\n");
    // topic list -t: /_secret only with --include-hidden-topics.
    for (flags, file) in [
        (&["-t"][..], "ros2-topic-list-t.txt"),
        (
            &["-t", "--include-hidden-topics"][..],
            "ros2-topic-list-t-hidden.txt",
        ),
    ] {
        let (rc, real) = edge(file);
        let (code, out, err) = ros2(&[&["topic", "list"][..], flags].concat());
        assert_eq!(code, rc, "{err}");
        assert_eq!(by_topic(&out), by_topic(&real), "{file}");
    }
    assert_eq!(ros2(&["topic", "list", "-c"]).1, "5\n");
    // node info of the shared name: the warning, then the one node ros2cli showed, line
    // for line (not the /mixed and /rosout of the other /dup).
    let (rc, real) = edge("ros2-node-info-dup.txt");
    let (code, out, err) = ros2(&["node", "info", "/dup"]);
    assert!(err.starts_with("There are 2 nodes in the graph with the exact name \"/dup\"."));
    assert_eq!((code, format!("{err}{out}")), (rc, real));
    let (rc, real) = edge("ros2-node-info-nstalker.txt");
    let (code, out, err) = ros2(&["node", "info", "/ns/talker"]);
    assert_eq!((code, out), (rc, real), "{err}");
    // topic info of the two-typed topic, plain: ros2cli's lines exactly.
    let (rc, real) = edge("ros2-topic-info-mixed.txt");
    let (code, out, err) = ros2(&["topic", "info", "/mixed"]);
    assert_eq!((code, out), (rc, real), "{err}");
    // echo refuses it in ros2cli's words, on stderr, exit 1; hz and bw too, with the same
    // words (ros2topic's shared `get_msg_class`).
    let (rc, real) = edge("ros2-echo-mixed.txt");
    assert_eq!(rc, 1);
    for verb in [
        &["topic", "echo", "/mixed", "--once", "--timeout", "5"][..],
        &["topic", "hz", "/mixed", "--duration", "5"],
        &["topic", "bw", "/mixed", "--duration", "5"],
    ] {
        let (code, out, err) = ros2(verb);
        assert_eq!(
            (code, err.as_str(), out.as_str()),
            (rc, real.as_str(), ""),
            "{verb:?}"
        );
    }
    // A hidden node is found only with --include-hidden (ros2node's `get_node_names`), and
    // then its hidden topic and services are shown; a hidden topic's info is given as is.
    let (code, out, err) = ros2(&["node", "info", "/_hidden_node"]);
    assert_eq!(
        (code, out.as_str(), err.as_str()),
        (1, "", "Unable to find node '/_hidden_node'\n")
    );
    let (code, out, err) = ros2(&["node", "info", "/_hidden_node", "--include-hidden"]);
    assert_eq!(code, 0, "{err}");
    for needle in [
        "  Publishers:\n    /_secret: std_msgs/msg/String\n",
        "    /_hidden_node/list_parameters: rcl_interfaces/srv/ListParameters\n",
    ] {
        assert!(out.contains(needle), "{needle:?} in {out}");
    }
    let (code, out, err) = ros2(&["topic", "info", "/_secret"]);
    assert_eq!(
        (code, out.as_str()),
        (
            0,
            "Type: std_msgs/msg/String\nPublisher count: 1\nSubscription count: 0\n"
        ),
        "{err}"
    );
    // An unknown topic: ros2cli's words and exit code.
    let (code, _, err) = ros2(&["topic", "info", "/nothing"]);
    assert_eq!((code, err.as_str()), (1, "Unknown topic '/nothing'\n"));
}

/// Plain `topic info` is a line each, as real ros2cli printed it on the real graph, where
/// ratelab printed an empty line after each (step2/ratelab/topic-info_chatter.txt).
#[test]
fn plain_topic_info_is_a_line_each_as_real_ros2cli_prints_it() {
    // Processes of its own beside the suite: never beside a timing test.
    let _m = crate::machine::shared();
    let (rc, real, _) = capture("step2/ros2cli/topic-info_chatter.txt");
    assert_eq!(
        (rc, real.as_str()),
        (
            0,
            "Type: std_msgs/msg/String\nPublisher count: 1\nSubscription count: 1\n"
        )
    );
    let (_, before, _) = capture("step2/ratelab/topic-info_chatter.txt");
    assert_ne!(
        before, real,
        "the capture shows the difference this test is about"
    );
    let endpoint = format!("tcp/127.0.0.1:{}", free_port());
    let _talker = Oracle::start("tests/ros2/talker.py", &[&endpoint, "0"], "the talker");
    // The talker's /chatter: one publisher (/demo/talker), one subscription (/listener).
    let (code, out, err) = ros2_at(&endpoint, &["topic", "info", "/chatter"]);
    assert_eq!((code, out), (0, real), "{err}");
}

/// `hz` counts the intervals between messages (real ros2cli's first report at 20 Hz said
/// `window: 19`, ratelab's said 20) and prints nothing when no message is new; `bw` gives
/// every figure in the rate's unit, whole bytes below 1000 B/s (`524 B/s`, `mean: 26 B`,
/// where ratelab said `524.15 B/s`, `26.00 B`). Checked on the latched topic: its 5 stored
/// messages arrive at once, then nothing.
#[test]
fn hz_counts_intervals_and_bw_keeps_one_unit_as_real_ros2cli_does() {
    // Processes of its own beside the suite: never beside a timing test.
    let _m = crate::machine::shared();
    let (_, real_hz, _) = capture("step2/ros2cli/topic-hz_chatter.txt");
    assert!(real_hz.starts_with(
        "average rate: 19.995\n\tmin: 0.045s max: 0.053s std dev: 0.00174s window: 19\n"
    ));
    let (_, real_bw, _) = capture("step2/ros2cli/topic-bw_chatter.txt");
    assert!(real_bw
        .contains("\n524 B/s from 20 messages\n\tMessage size mean: 26 B min: 26 B max: 26 B\n"));
    let endpoint = format!("tcp/127.0.0.1:{}", free_port());
    let published = crate::brains::fixture("ros2-real/kilted-ros2cli/step2/real-other.json");
    let args = [endpoint.as_str(), "0", published.to_str().unwrap()];
    let _latcher = Oracle::start("tests/ros2/latcher.py", &args, "the latcher");
    // The 5 stored messages (keep last 5, as ros2cli's `info -v /latched` says).
    let (_, info, _) = capture("step2/ros2cli/topic-info-v_latched.txt");
    assert!(
        info.contains("  History (Depth): KEEP_LAST (5)\n"),
        "{info}"
    );
    let sent: serde_json::Value =
        serde_json::from_slice(&std::fs::read(&published).unwrap()).unwrap();
    let sent: Vec<&str> = sent["published"]["/latched"]
        .as_array()
        .unwrap()
        .iter()
        .map(|t| t.as_str().unwrap())
        .collect();
    let stored = &sent[sent.len() - 5..];
    // hz: 5 messages are 4 intervals; a second and third second with nothing new print
    // nothing (at most one more report, if the history came in two parts).
    let (code, out, err) = ros2_at(&endpoint, &["topic", "hz", "/latched", "--duration", "4.5"]);
    assert_eq!(code, 0, "{err}");
    let lines: Vec<&str> = out.lines().collect();
    assert!(matches!(lines.len(), 2 | 4), "{out}");
    for pair in lines.chunks(2) {
        assert!(pair[0].starts_with("average rate: "), "{out}");
        assert!(pair[1].starts_with("\tmin: "), "{out}");
    }
    assert!(out.ends_with(" window: 4\n"), "{out}");
    // bw: each stored message is a std_msgs/msg/String in CDR, 4 bytes of encapsulation, 4
    // of length, the text and its NUL (so real ros2cli's 26 B for "Hello World: 3435").
    // Every figure is in the rate's unit: whole bytes below 1000 B/s (5 messages over a
    // second), KB with two decimals above (should the history come late in a second).
    let sizes: BTreeSet<usize> = stored.iter().map(|t| 4 + 4 + t.len() + 1).collect();
    assert_eq!(sizes.len(), 1, "{stored:?}");
    let size = sizes.into_iter().next().unwrap();
    let (code, out, err) = ros2_at(&endpoint, &["topic", "bw", "/latched", "--duration", "2.5"]);
    assert_eq!(code, 0, "{err}");
    let mut lines = out.lines();
    assert_eq!(lines.next(), Some("Subscribed to [/latched]"), "{out}");
    let rest: Vec<&str> = lines.collect();
    assert!(!rest.is_empty(), "{out}");
    for pair in rest.chunks(2) {
        let (rate, unit) = pair[0]
            .strip_suffix("/s from 5 messages")
            .and_then(|r| r.split_once(' '))
            .unwrap_or_else(|| panic!("{out}"));
        let each = match unit {
            "B" => {
                assert!(rate.parse::<u32>().is_ok_and(|r| r < 1000), "{out}");
                format!("{size} B")
            }
            "KB" => {
                assert!(
                    rate.split_once('.').is_some_and(|(_, d)| d.len() == 2),
                    "{out}"
                );
                format!("{:.2} KB", size as f64 / 1000.0)
            }
            _ => panic!("{out}"),
        };
        let said = format!("\tMessage size mean: {each} min: {each} max: {each}");
        assert_eq!(pair.get(1).copied(), Some(said.as_str()), "{out}");
    }
}

/// What ros2cli takes as a window is a positive whole number (ros2topic's `positive_int`):
/// another is refused before any session opens, in one line, exit 2 (bad input).
#[test]
fn a_window_below_one_is_refused_in_one_line() {
    // Processes of its own beside the suite: never beside a timing test.
    let _m = crate::machine::shared();
    for verb in ["hz", "bw"] {
        let args = ["ros2", "topic", verb, "/obs", "--window", "0"];
        let (code, out, err, _) = ratelab_within(&args, Duration::from_secs(30));
        assert_eq!((code, out.as_str()), (2, ""), "{err}");
        assert_eq!(err.trim_end().lines().count(), 1, "{err}");
        assert!(err.contains("--window"), "{err}");
    }
}

/// A time limit out of range (`--timeout`, `--duration`, `--wait`) is refused as the
/// window is: before any session opens (no router runs here), in one short line quoting the
/// value as typed (`1e300`, not its 301 digits), exit 2.
#[test]
fn a_time_limit_out_of_range_is_refused_before_connecting_in_one_short_line() {
    let _m = crate::machine::shared();
    for (args, flag) in [
        (
            &["topic", "echo", "/obs", "--timeout", "1e300"][..],
            "--timeout",
        ),
        (
            &["topic", "echo", "/obs", "--timeout", "0"][..],
            "--timeout",
        ),
        (
            &["topic", "hz", "/obs", "--duration", "NaN"][..],
            "--duration",
        ),
        (&["graph", "--duration", "-1"][..], "--duration"),
        (&["node", "list", "--wait", "inf"][..], "--wait"),
    ] {
        let args: Vec<&str> = ["ros2"].iter().chain(args).copied().collect();
        let (code, out, err, _) = ratelab_within(&args, Duration::from_secs(30));
        assert_eq!((code, out.as_str()), (2, ""), "{args:?}: {err}");
        assert_eq!(err.trim_end().lines().count(), 1, "{err}");
        assert!(
            err.contains(flag) && err.contains("must be a number of seconds"),
            "{err}"
        );
        assert!(err.len() < 160, "{err}");
    }
}

/// `topic list -v`'s lines (` * /topic [a, b] N publishers`) as (topic, its types as a set),
/// each section's.
fn verbose_topics(section: &str) -> Vec<(String, BTreeSet<String>)> {
    section
        .lines()
        .skip(1)
        .map(|l| {
            let l = l.strip_prefix(" * ").unwrap_or_else(|| panic!("{l}"));
            let (listed, _count) = l.rsplit_once("] ").unwrap_or_else(|| panic!("{l}"));
            format!("{listed}]")
        })
        .flat_map(|l| by_topic(&l))
        .collect()
}

/// `topic list -v` as ros2topic's `verb/list.py` prints it (ros2cli 0.36.1; no capture of
/// `-v` exists, so the format is the source's, `show_topic_info`, each section `print`ed
/// and so followed by an empty line): ` * /topic [types] N publisher(s)` under `Published
/// topics:` for each topic with a publisher, ` * … N subscriber(s)` under `Subscribed
/// topics:`, a hidden node's endpoints counted too (rclpy's `count_publishers`), a hidden
/// topic only with `--include-hidden-topics`, and `-c` first. On the real graph's edge
/// cases (`tests/ros2/edges.py`), whose topics and types are those real ros2cli's `topic list
/// -t` listed (`step2/edge/ros2-topic-list-t*.txt`; a two-typed topic's types sorted here,
/// where rmw_zenoh_cpp gives no fixed order). Real ros2cli would count its own node's
/// /rosout and /parameter_events publishers too; ratelab reads the graph without a node.
#[test]
fn the_verbose_topic_list_reads_as_ros2cli_s_list_py_writes_it() {
    // Processes of its own beside the suite: never beside a timing test.
    let _m = crate::machine::shared();
    let endpoint = format!("tcp/127.0.0.1:{}", free_port());
    let talker = crate::brains::fixture("ros2-real/real-rclpy-talker.json");
    let args = [endpoint.as_str(), "0", talker.to_str().unwrap()];
    let _edges = Oracle::start("tests/ros2/edges.py", &args, "the edge graph");
    let ros2 = |verb: &[&str]| ros2_at(&endpoint, verb);
    let (code, out, err) = ros2(&["topic", "list", "-v"]);
    assert_eq!(code, 0, "{err}");
    assert_eq!(
        out,
        "Published topics:\n \
         * /dup/private [std_msgs/msg/String] 1 publisher\n \
         * /mixed [std_msgs/msg/Int32, std_msgs/msg/String] 2 publishers\n \
         * /ns/chatter [std_msgs/msg/String] 1 publisher\n \
         * /parameter_events [rcl_interfaces/msg/ParameterEvent] 4 publishers\n \
         * /rosout [rcl_interfaces/msg/Log] 4 publishers\n\
         \n\
         Subscribed topics:\n \
         * /ns/chatter [std_msgs/msg/String] 1 subscriber\n\
         \n"
    );
    // `-t` changes nothing under `-v`; `-c` counts instead, as ros2cli's.
    assert_eq!(ros2(&["topic", "list", "-v", "-t"]).1, out);
    assert_eq!(ros2(&["topic", "list", "-v", "-c"]).1, "5\n");
    for (flags, file) in [
        (&["-v"][..], "ros2-topic-list-t.txt"),
        (
            &["-v", "--include-hidden-topics"][..],
            "ros2-topic-list-t-hidden.txt",
        ),
    ] {
        let (rc, real) = edge(file);
        let (code, out, err) = ros2(&[&["topic", "list"][..], flags].concat());
        assert_eq!(code, rc, "{err}");
        let (published, subscribed) = out
            .trim_end()
            .split_once("\n\n")
            .unwrap_or_else(|| panic!("{out}"));
        assert!(published.starts_with("Published topics:\n"), "{out}");
        assert!(subscribed.starts_with("Subscribed topics:\n"), "{out}");
        let mut listed = verbose_topics(published);
        listed.extend(verbose_topics(subscribed));
        listed.sort();
        listed.dedup();
        assert_eq!(listed, by_topic(&real), "{file}: {out}");
    }
    let (_, hidden, _) = ros2(&["topic", "list", "-v", "--include-hidden-topics"]);
    assert!(
        hidden.starts_with(
            "Published topics:\n * /_secret [std_msgs/msg/String] 1 publisher\n * /dup/private "
        ),
        "{hidden}"
    );
}
