//! A node's log on `/rosout` as rcl writes it (issue #74, item 3), and in the bag as
//! `ros2 bag record -a` records it (item 6): a Python node's `get_logger()` line is its
//! text alone (the `info: ` the log pane shows is not part of it), with the file, function
//! and line of the Python frame that logged it, as a real rclpy node's line is
//! (`../shared/fixtures/ros2-real/kilted-ros2cli/step2/ros2cli/topic-echo-rosout-n.txt`:
//! `file: <scratch>/thermo.py`, `function: tick`, `line: 20`); a print's has none; the lines
//! its constructor writes go out first, and a transient-local subscription joining later
//! gets them. Read back with independent implementations only: Foxglove's `mcap` and
//! `mcap-ros2-support` (decoding with the schema the bag carries), PyPI `eclipse-zenoh` and
//! `rosbags` (`tests/ros2/late_joiner.py`).

use crate::distributed::free_port;
use crate::ros2::{connect_to, oracle_json, ratelab, Oracle};
use crate::ros2_cli::Offering;
use serde_json::{json, Value};
use std::path::{Path, PathBuf};

/// A Python node that logs in its constructor, and at its first reading logs a warning and
/// prints a line.
const TELLER_PY: &str = r#"from ratelab import State


class Teller:
    def __init__(self, node):
        self.log = node.get_logger()
        self.log.info("ready to tell")
        self.heard = 0
        node.create_subscription(State, "/obs", self.on_obs, 1)

    def on_obs(self, msg):
        self.heard += 1
        if self.heard == 1:
            self.log.warning(f"heard {self.heard}")
            print("printed once")
"#;

const TELLER: &str = r#"
[[node]]
name = "teller"
kind = "python"
script = "teller.py"
class = "Teller"
rate_hz = 10
subscribes = "/obs"
"#;

/// The chapter's graph with the teller, written in `dir` (`g.toml`, `teller.py`).
fn teller_graph(dir: &Path) -> PathBuf {
    let chapter = std::fs::read_to_string(crate::repo("graphs/cartpole.toml")).unwrap();
    let graph = dir.join("g.toml");
    std::fs::write(&graph, format!("{chapter}\n{TELLER}")).unwrap();
    std::fs::write(dir.join("teller.py"), TELLER_PY).unwrap();
    graph
}

/// The line of `TELLER_PY` (from 1) that holds `text`.
fn line_of(text: &str) -> u64 {
    let i = TELLER_PY.lines().position(|l| l.contains(text)).unwrap();
    i as u64 + 1
}

/// `r`'s text, level, function and line (a `/rosout` message's).
fn said(r: &Value) -> Value {
    json!([r["msg"], r["level"], r["function"], r["line"]])
}

/// The script `file` names is the teller's, in `dir`.
fn is_the_tellers(file: &Value, dir: &Path) -> bool {
    let named = Path::new(file.as_str().unwrap());
    named.is_absolute() && named.canonicalize().ok() == dir.join("teller.py").canonicalize().ok()
}

/// Every `/rosout` message of the bag in `dir`, in the file's order, decoded by Foxglove's
/// `mcap-ros2-support` from the schema the bag carries: its log time and fields.
fn rosout_of_bag(dir: &Path) -> Vec<Value> {
    let script = r#"
import glob, json, sys
from mcap.reader import make_reader
from mcap_ros2.decoder import DecoderFactory
rows = []
with open(glob.glob(sys.argv[1] + "/*.mcap")[0], "rb") as f:
    reader = make_reader(f, decoder_factories=[DecoderFactory()])
    for _, _, message, m in reader.iter_decoded_messages(topics=["/rosout"], log_time_order=False):
        rows.append({"t": message.log_time, "level": m.level, "name": m.name, "msg": m.msg,
                     "file": m.file, "function": m.function, "line": m.line})
print(json.dumps(rows))
"#;
    serde_json::from_value(oracle_json(script, &[dir.to_str().unwrap()])).unwrap()
}

#[test]
fn a_loggers_line_is_on_rosout_and_in_the_bag_as_rcl_writes_it_the_constructors_first() {
    // Processes of its own beside the suite: never beside a timing test.
    let _m = crate::machine::shared();
    // No router needed to write a bag: the session is not checked for one.
    let env = [
        ("ZENOH_ROUTER_CHECK_ATTEMPTS", "-1".to_string()),
        connect_to(&format!("tcp/127.0.0.1:{}", free_port())),
    ];
    let dir = tempfile::tempdir().unwrap();
    let graph = teller_graph(dir.path());
    let bag = dir.path().join("bag");
    let (code, out, err) = ratelab(
        &[
            "run",
            "--graph",
            graph.to_str().unwrap(),
            "--clock",
            "virtual",
            "--duration",
            "1",
            "--ros2",
            "--bag",
            bag.to_str().unwrap(),
        ],
        &env,
    );
    assert_eq!(code, 0, "{out}{err}");
    // The log itself is unchanged: a logger's line with its level word.
    assert!(err.contains("[teller] info: ready to tell\n"), "{err}");
    assert!(err.contains(" teller] warning: heard 1\n"), "{err}");
    let rows = rosout_of_bag(&bag);
    let teller: Vec<&Value> = rows.iter().filter(|r| r["name"] == "teller").collect();
    assert_eq!(teller.len(), 3, "{rows:?}");
    // The constructor's line first, at run time 0.
    let (ready, heard, printed) = (teller[0], teller[1], teller[2]);
    let at = line_of("\"ready to tell\"");
    assert_eq!(
        said(ready),
        json!(["ready to tell", 20, "__init__", at]),
        "{ready}"
    );
    assert_eq!(ready["t"], 0, "{ready}");
    assert!(is_the_tellers(&ready["file"], dir.path()), "{ready}");
    let at = line_of("self.log.warning(");
    assert_eq!(said(heard), json!(["heard 1", 30, "on_obs", at]), "{heard}");
    assert!(is_the_tellers(&heard["file"], dir.path()), "{heard}");
    // A print is no logger's call: no file, function or line, as ratelab has none to give.
    assert_eq!(
        said(printed),
        json!(["printed once", 20, "", 0]),
        "{printed}"
    );
    assert_eq!(printed["file"], "", "{printed}");
    // No line of any node carries a level word in its text.
    for r in &rows {
        let msg = r["msg"].as_str().unwrap();
        assert!(
            !["info: ", "warning: ", "error: "]
                .iter()
                .any(|w| msg.starts_with(w)),
            "{r}"
        );
    }
}

#[test]
fn a_transient_local_joiner_gets_the_constructors_line_with_its_caller() {
    let _alone = crate::machine::alone();
    let dir = tempfile::tempdir().unwrap();
    let graph = teller_graph(dir.path());
    let run = Offering::start(&[
        "--graph",
        graph.to_str().unwrap(),
        "--ros2",
        "8",
        "--clock",
        "real",
        "--duration",
        "30",
    ]);
    // Joining well after the constructor's line went out (the bridge puts it first, as it
    // starts): it can only come from the publisher's history.
    std::thread::sleep(std::time::Duration::from_secs(2));
    let args = [run.endpoint.as_str(), "8/rosout/**", "1000", "1.5"];
    let kept = Oracle::start("tests/ros2/late_joiner.py", &args, "the late joiner").report();
    drop(run);
    assert_eq!(kept["errors"], json!([]), "{kept}");
    let samples = kept["samples"].as_array().unwrap();
    let ready = samples
        .iter()
        .find(|s| s["name"] == "teller" && s["msg"] == "ready to tell")
        .unwrap_or_else(|| panic!("no constructor line in {kept}"));
    let at = line_of("\"ready to tell\"");
    assert_eq!(
        said(ready),
        json!(["ready to tell", 20, "__init__", at]),
        "{ready}"
    );
    assert!(is_the_tellers(&ready["file"], dir.path()), "{ready}");
    assert!(
        samples
            .iter()
            .any(|s| s["name"] == "teller" && s["msg"] == "heard 1" && s["function"] == "on_obs"),
        "{kept}"
    );
}
