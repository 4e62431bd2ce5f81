//! `ratelab ros2 topic echo|hz|bw` on a topic that is not published yet, and how the three
//! end on Ctrl-C (#74 item 5), as ros2cli 0.36.1 (Kilted's) does. Read in its source
//! (ros2/ros2cli at 0.36.1) and checked against the real command's captures where they exist
//! (`../shared/fixtures/ros2-real/kilted-ros2cli/step3/ros2cli`: real ros2cli over real
//! rmw_zenoh_cpp 0.6.7):
//! - `echo` of a topic no node has: ros2topic's `api/__init__.py` `get_msg_class` warns on
//!   stdout (`WARNING: topic [/x] does not appear to be published yet`) and `verb/echo.py`
//!   raises `RuntimeError('Could not determine the type for the passed topic')`, which
//!   `ros2cli/cli.py`'s `main` returns to `sys.exit`: the words on stderr, exit 1 (captured:
//!   `echo-action-real.txt`);
//! - a topic only subscribed to so far has a type (`get_topic_names_and_types` lists every
//!   endpoint's): `echo` subscribes and waits for publishers (`--timeout`: exit 0); a
//!   relative name is looked up expanded (rclpy's `expand_topic_name`, `chatter` is
//!   `/chatter`) and said as given;
//! - `hz` and `bw` wait for a topic no node has (`get_msg_class(blocking=True)`: the warning
//!   once, then a look every 0.1 s; captured: `hz-obs-real.txt`, whose later lines are
//!   ros2cli's own failure under SIGTERM), and measure once it comes;
//! - Ctrl-C: the `KeyboardInterrupt` that reaches `cli.py`'s `main` is `rc = signal.SIGINT`,
//!   exit 2, nothing said (`echo`, `bw`, and `hz` or `bw` still waiting); `verb/hz.py`
//!   catches it around its spin (`except (KeyboardInterrupt, ExternalShutdownException):
//!   pass`) and ends 0.
//!
//! The graph is played by `tests/ros2/late_talker.py` (eclipse-zenoh and rosbags only,
//! nothing of ratelab's): a subscription on `/late` at once, publishers on `/late` and
//! `/later` once the test says so.

use crate::distributed::free_port;
use crate::ros2::Oracle;
use crate::ros2_cli_rules::capture;
use crate::ros2_latched::ratelab_within;
use std::io::{BufRead, BufReader, Read};
use std::process::{Child, Stdio};
use std::sync::mpsc;
use std::time::{Duration, Instant};

/// `ratelab ros2 --connect ENDPOINT VERB…` running, its stdout read line by line as it comes;
/// killed when dropped.
struct Running {
    child: Child,
    lines: mpsc::Receiver<String>,
    out: String,
    err: Option<std::thread::JoinHandle<String>>,
}

impl Running {
    fn start(endpoint: &str, verb: &[&str]) -> Running {
        let mut child = crate::ros2_latched::ratelab_command(&["ros2", "--connect", endpoint])
            .args(verb)
            .stdout(Stdio::piped())
            .stderr(Stdio::piped())
            .spawn()
            .unwrap();
        let (tx, lines) = mpsc::channel();
        let stdout = child.stdout.take().unwrap();
        std::thread::spawn(move || {
            for line in BufReader::new(stdout).lines().map_while(Result::ok) {
                if tx.send(line).is_err() {
                    break;
                }
            }
        });
        let mut stderr = child.stderr.take().unwrap();
        let err = std::thread::spawn(move || {
            let mut text = String::new();
            let _ = stderr.read_to_string(&mut text);
            text
        });
        Running {
            child,
            lines,
            out: String::new(),
            err: Some(err),
        }
    }

    /// Read its stdout up to a line that starts with `prefix` (within 30 s: waiting for what
    /// the test means to interrupt, not a fixed time, so a slow start on a loaded machine
    /// does not send Ctrl-C too early).
    fn until(&mut self, prefix: &str) {
        let deadline = Instant::now() + Duration::from_secs(30);
        loop {
            let left = deadline.saturating_duration_since(Instant::now());
            match self.lines.recv_timeout(left) {
                Ok(line) => {
                    let found = line.starts_with(prefix);
                    self.out.push_str(&line);
                    self.out.push('\n');
                    if found {
                        return;
                    }
                }
                Err(e) => panic!("no line starting {prefix:?} ({e:?}) in: {}", self.out),
            }
        }
    }

    /// Ctrl-C (SIGINT); then its exit code (-1 when a signal ended it, or when it had not
    /// ended 30 s later and was killed), everything it wrote on stdout, and its stderr.
    fn interrupt(mut self) -> (i32, String, String) {
        // SAFETY: plain kill(2) on our own child.
        unsafe { libc::kill(self.child.id() as i32, libc::SIGINT) };
        let deadline = Instant::now() + Duration::from_secs(30);
        let code = loop {
            if let Some(status) = self.child.try_wait().unwrap() {
                break status.code().unwrap_or(-1);
            }
            if Instant::now() > deadline {
                let _ = self.child.kill();
                let _ = self.child.wait();
                break -1;
            }
            std::thread::sleep(Duration::from_millis(20));
        };
        // The rest of its stdout: the reader ends with it.
        while let Ok(line) = self.lines.recv_timeout(Duration::from_secs(10)) {
            self.out.push_str(&line);
            self.out.push('\n');
        }
        let err = self
            .err
            .take()
            .map(|e| e.join().unwrap())
            .unwrap_or_default();
        (code, std::mem::take(&mut self.out), err)
    }
}

impl Drop for Running {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

/// The whole of #74 item 5's waiting rules on one graph, in order: first what holds while
/// `/later` has no node and `/late` only a subscription, then, once their publisher comes,
/// what `hz`, `bw` and `echo` (started before it) measure and print, and their exit codes
/// on Ctrl-C.
#[test]
fn a_topic_not_published_yet_is_refused_or_waited_for_and_ctrl_c_ends_as_ros2cli_ends() {
    // Processes of its own beside the suite: never beside a timing test.
    let _m = crate::machine::shared();
    let dir = tempfile::tempdir().unwrap();
    let trigger = dir.path().join("publish");
    let endpoint = format!("tcp/127.0.0.1:{}", free_port());
    let args = [endpoint.as_str(), "0", trigger.to_str().unwrap()];
    let _graph = Oracle::start("tests/ros2/late_talker.py", &args, "the late talker");
    let ros2 = |verb: &[&str]| {
        let mut args = vec!["ros2", "--connect", endpoint.as_str()];
        args.extend_from_slice(verb);
        let (code, out, err, _) = ratelab_within(&args, Duration::from_secs(30));
        (code, out, err)
    };
    // `echo` of a topic no node has: real ros2cli's lines and exit code, for the same
    // command line (without its `--no-daemon`, which ratelab has no use for).
    let (rc, real_out, real_err) = capture("step3/ros2cli/echo-action-real.txt");
    assert_eq!(
        (rc, real_out.as_str(), real_err.as_str()),
        (
            1,
            "WARNING: topic [/action] does not appear to be published yet\n",
            "Could not determine the type for the passed topic\n"
        )
    );
    assert_eq!(
        ros2(&["topic", "echo", "--once", "/action"]),
        (rc, real_out, real_err)
    );
    // The name as it was given.
    let (code, out, _) = ros2(&["topic", "echo", "--once", "action"]);
    assert_eq!(
        (code, out.as_str()),
        (
            1,
            "WARNING: topic [action] does not appear to be published yet\n"
        )
    );
    // `hz`'s warning, real ros2cli's first line (then it waits); the rest of that capture
    // is ros2cli failing under the SIGTERM that ended it.
    let (_, real_hz, _) = capture("step3/ros2cli/hz-obs-real.txt");
    let first = real_hz.lines().next().unwrap();
    assert_eq!(
        first,
        "WARNING: topic [/obs] does not appear to be published yet"
    );
    let warning = |topic: &str| format!("{}\n", first.replace("/obs", topic));
    // `--duration` (ratelab's) ends the wait: the warning and nothing more, exit 0.
    let (code, out, err) = ros2(&["topic", "hz", "/later", "--duration", "1.5"]);
    assert_eq!((code, out, err), (0, warning("/later"), String::new()));
    // /late has only a subscription: its type is known, so `echo` subscribes and waits
    // (`--timeout`: exit 0, nothing printed); a relative name is looked up as `/late`.
    for topic in ["/late", "late"] {
        let (code, out, err) = ros2(&["topic", "echo", topic, "--timeout", "1.5"]);
        assert_eq!((code, out.as_str(), err.as_str()), (0, "", ""), "{topic}");
    }
    // Ctrl-C while `hz` waits: the KeyboardInterrupt reaches ros2cli's `main`, exit 2,
    // nothing said.
    let mut waiting = Running::start(&endpoint, &["topic", "hz", "/later"]);
    waiting.until("WARNING: ");
    assert_eq!(waiting.interrupt(), (2, warning("/later"), String::new()));
    // Waiting, then the publisher comes: each measures or prints it.
    let mut hz = Running::start(&endpoint, &["topic", "hz", "/later"]);
    let mut bw = Running::start(&endpoint, &["topic", "bw", "/later"]);
    let mut echo = Running::start(&endpoint, &["topic", "echo", "/late"]);
    hz.until("WARNING: ");
    bw.until("WARNING: ");
    std::fs::write(&trigger, b"").unwrap();
    hz.until("average rate: ");
    bw.until("\tMessage size mean: ");
    echo.until("data: late ");
    // Ctrl-C: `hz` once subscribed ends 0; `bw` and `echo` 2. Nothing on stderr.
    let (code, out, err) = hz.interrupt();
    assert_eq!((code, err.as_str()), (0, ""), "{out}");
    assert!(
        out.starts_with(&format!("{}average rate: ", warning("/later"))),
        "{out}"
    );
    let (code, out, err) = bw.interrupt();
    assert_eq!((code, err.as_str()), (2, ""), "{out}");
    assert!(
        out.starts_with(&format!("{}Subscribed to [/later]\n", warning("/later"))),
        "{out}"
    );
    let (code, out, err) = echo.interrupt();
    assert_eq!((code, err.as_str()), (2, ""), "{out}");
    assert!(
        out.starts_with("data: late ") && out.ends_with("\n---\n"),
        "{out}"
    );
}
