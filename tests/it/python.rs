//! Brains written in Python (`--policy FILE.py[:FUNCTION]`, src/python): the chapter's
//! arithmetic in Python equals the built-in scripted brain in every figure; every way a
//! script can be wrong is one line and exit 2; a callback that never returns cannot hang a
//! run. The tests need NumPy in the active virtual environment (scripts/test.sh makes it).

use crate::brains::fixture;
use std::io::{BufRead, BufReader};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Output, Stdio};
use std::time::{Duration, Instant};

fn ratelab(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_ratelab"))
        .args(args)
        .output()
        .expect("runs")
}

fn stderr(o: &Output) -> String {
    String::from_utf8_lossy(&o.stderr).into_owned()
}

/// The shipped brain that does the chapter's arithmetic.
fn shipped_brain() -> String {
    Path::new(crate::REPO)
        .join("graphs/brains/scripted.py")
        .to_string_lossy()
        .into_owned()
}

/// Send `child` (stdout and stderr piped) SIGINT once its stderr has said `needle`, and
/// collect its output: the output, and how long it took to exit after the signal. Waiting
/// for what the test means to interrupt (a callback the watchdog has seen hanging), not a
/// fixed time, keeps a slow start on a loaded machine from sending it too early; the 30 s
/// only bounds a run that never says it.
fn sigint_after(mut child: Child, needle: &str) -> (Output, Duration) {
    let stderr = child.stderr.take().expect("stderr piped");
    let (tx, rx) = std::sync::mpsc::channel::<String>();
    let reader = std::thread::spawn(move || {
        for line in BufReader::new(stderr).lines().map_while(Result::ok) {
            let _ = tx.send(line);
        }
    });
    let mut err = String::new();
    let deadline = Instant::now() + Duration::from_secs(30);
    while !err.contains(needle) {
        let left = deadline.saturating_duration_since(Instant::now());
        match rx.recv_timeout(left) {
            Ok(line) => {
                err.push_str(&line);
                err.push('\n');
            }
            Err(e) => {
                let _ = child.kill();
                let _ = child.wait();
                panic!("no '{needle}' on stderr ({e:?}): {err}");
            }
        }
    }
    let sent = Instant::now();
    // SAFETY: plain kill(2) on our child.
    unsafe { libc::kill(child.id() as i32, libc::SIGINT) };
    let mut o = child.wait_with_output().unwrap();
    let took = sent.elapsed();
    reader.join().unwrap();
    for line in rx.try_iter() {
        err.push_str(&line);
        err.push('\n');
    }
    o.stderr = err.into_bytes();
    (o, took)
}

fn script(dir: &Path, name: &str, text: &str) -> PathBuf {
    let p = dir.join(name);
    std::fs::write(&p, text).unwrap();
    p
}

/// `ratelab run --clock virtual --out DIR --force ARGS`: its metrics.json and trace.csv.
fn virtual_out(dir: &Path, args: &[&str]) -> (serde_json::Value, Vec<u8>) {
    let out = dir.to_str().unwrap();
    let o = ratelab(
        &[
            &["run", "--clock", "virtual", "--out", out, "--force"][..],
            args,
        ]
        .concat(),
    );
    assert!(o.status.success(), "{args:?}: {}", stderr(&o));
    let m =
        serde_json::from_str(&std::fs::read_to_string(dir.join("metrics.json")).unwrap()).unwrap();
    (m, std::fs::read(dir.join("trace.csv")).unwrap())
}

/// metrics.json without the brain's label, and trace.csv, of one virtual run.
fn virtual_run(dir: &Path, policy: &str, seed: &str, control_hz: &str) -> (String, Vec<u8>) {
    let (mut m, trace) = virtual_out(
        dir,
        &[
            "--seed",
            seed,
            "--control-hz",
            control_hz,
            "--policy",
            policy,
        ],
    );
    let label = m
        .as_object_mut()
        .unwrap()
        .remove("policy")
        .expect("metrics.json names the brain");
    assert!(
        label.as_str().unwrap().contains(if policy == "scripted" {
            "scripted balancer"
        } else {
            "Python brain"
        }),
        "{label}"
    );
    (serde_json::to_string_pretty(&m).unwrap(), trace)
}

#[test]
fn a_python_brain_with_the_chapters_arithmetic_equals_the_builtin_one_in_every_figure() {
    let _m = crate::machine::shared();
    let (a, b) = (tempfile::tempdir().unwrap(), tempfile::tempdir().unwrap());
    let brain = shipped_brain();
    for hz in ["50", "5"] {
        for seed in ["0", "1", "2"] {
            let builtin = virtual_run(a.path(), "scripted", seed, hz);
            let python = virtual_run(b.path(), &brain, seed, hz);
            assert!(
                builtin.0 == python.0,
                "seed {seed}, {hz} Hz: metrics differ\n{}\n{}",
                builtin.0,
                python.0
            );
            assert!(builtin.1 == python.1, "seed {seed}, {hz} Hz: trace differs");
        }
    }
    // Two runs of the Python brain are byte-identical, label included.
    let c = tempfile::tempdir().unwrap();
    let first = virtual_run(b.path(), &brain, "1", "5");
    let second = virtual_run(c.path(), &brain, "1", "5");
    assert_eq!(first, second);
}

#[test]
fn a_named_function_is_run_and_its_return_value_may_be_a_float_or_an_array() {
    let dir = tempfile::tempdir().unwrap();
    // Returns a plain float, unclipped: ratelab clips it to [-1, 1].
    let p = script(
        dir.path(),
        "mine.py",
        "import math\n\
         def balance(obs):\n\
         \x20   theta = math.atan2(float(obs[3]), float(obs[2]))\n\
         \x20   return 10.0 * theta + 2.0 * float(obs[4]) + 0.4 * float(obs[0]) + 0.8 * float(obs[1])\n",
    );
    let spec = format!("{}:balance", p.display());
    let (python, trace) = virtual_run(dir.path(), &spec, "0", "50");
    let other = tempfile::tempdir().unwrap();
    let (builtin, builtin_trace) = virtual_run(other.path(), "scripted", "0", "50");
    assert_eq!(python, builtin);
    assert_eq!(trace, builtin_trace);
}

/// A brain file imports the message classes as a node's script does (`from ratelab import
/// Force`: docs/python.md), and uses them.
#[test]
fn a_brain_file_imports_the_message_classes() {
    let dir = tempfile::tempdir().unwrap();
    let p = script(
        dir.path(),
        "typed.py",
        "from ratelab import Force, State\n\
         def act(obs):\n\
         \x20   s = State(*[float(x) for x in obs])\n\
         \x20   return Force(newtons=0.0).newtons + 0.0 * s.cart_pos_m\n",
    );
    let o = ratelab(&["run", "--smoke", "--policy", p.to_str().unwrap()]);
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
}

fn assert_refused(policy: &str, needles: &[&str]) {
    let o = ratelab(&[
        "run",
        "--clock",
        "virtual",
        "--duration",
        "1",
        "--policy",
        policy,
    ]);
    let err = stderr(&o);
    assert_eq!(o.status.code(), Some(2), "{policy}: {err}");
    assert_eq!(
        err.trim_end().lines().count(),
        1,
        "{policy}: one line: {err:?}"
    );
    for n in needles {
        assert!(err.contains(n), "{policy}: {err:?} lacks {n:?}");
    }
    assert!(
        !err.contains("panicked") && !err.contains("Traceback"),
        "{err}"
    );
}

#[test]
fn every_way_a_brain_script_is_wrong_is_one_line_and_exit_2() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let missing = d.join("nothing.py");
    assert_refused(missing.to_str().unwrap(), &["nothing.py", "not found"]);
    let syntax = script(d, "syntax.py", "def act(obs):\n    return (1.0\n\n");
    assert_refused(
        syntax.to_str().unwrap(),
        &[&format!("{}:2: SyntaxError", syntax.display())],
    );
    let raises = script(
        d,
        "raises.py",
        "import math\nx = 1 / 0\ndef act(obs):\n    return 0.0\n",
    );
    assert_refused(
        raises.to_str().unwrap(),
        &[&format!(
            "{}:2: ZeroDivisionError: division by zero",
            raises.display()
        )],
    );
    let other = script(d, "other.py", "def policy(obs):\n    return 0.0\n");
    assert_refused(
        other.to_str().unwrap(),
        &["other.py", "no function 'act'", "it defines policy"],
    );
    let not_fn = script(d, "notfn.py", "act = 3\n");
    assert_refused(notfn_spec(&not_fn), &["'act' is a int, not a function"]);
    let binary = script(d, "bin.py", "");
    std::fs::write(&binary, b"x = 1\n\xff\xfe\n").unwrap();
    assert_refused(binary.to_str().unwrap(), &["bin.py:2: not UTF-8"]);
    let folder = d.join("folder.py");
    std::fs::create_dir(&folder).unwrap();
    assert_refused(
        folder.to_str().unwrap(),
        &["folder.py", "not a regular file"],
    );
}

fn notfn_spec(p: &Path) -> &str {
    p.to_str().unwrap()
}

/// A run whose brain fails mid-run: the node fails at that tick, in one line naming the
/// file and line of the raising frame and the exception; the summary is still printed.
fn assert_fails_mid_run(body: &str, needles: &[&str]) {
    let dir = tempfile::tempdir().unwrap();
    let p = script(dir.path(), "brain.py", body);
    let o = ratelab(&["run", "--clock", "virtual", "--policy", p.to_str().unwrap()]);
    let err = stderr(&o);
    assert_eq!(o.status.code(), Some(2), "{err}");
    let last = err.trim_end().lines().last().unwrap_or("");
    assert!(
        last.starts_with("error: node 'policy' failed at t="),
        "{err}"
    );
    for n in needles {
        let n = n.replace("FILE", p.to_str().unwrap());
        assert!(last.contains(&n), "{last:?} lacks {n:?}");
    }
    assert!(
        !err.contains("panicked") && !err.contains("Traceback"),
        "{err}"
    );
    assert!(
        String::from_utf8_lossy(&o.stdout).contains("NODE FAILED"),
        "the summary says so"
    );
}

#[test]
fn a_brain_that_raises_or_returns_nonsense_fails_the_policy_node_at_that_tick() {
    assert_fails_mid_run(
        "calls = 0\n\
         def act(obs):\n\
         \x20   global calls\n\
         \x20   calls += 1\n\
         \x20   if calls == 10:\n\
         \x20       raise RuntimeError('gave up')\n\
         \x20   return 0.0\n",
        &["t=0.18s", "FILE:6: RuntimeError: gave up"],
    );
    // The raising frame in the learner's helper, not in NumPy.
    assert_fails_mid_run(
        "import numpy as np\n\
         def helper(obs):\n\
         \x20   return np.linalg.inv(np.zeros((2, 2)))\n\
         def act(obs):\n\
         \x20   return helper(obs)\n",
        &["t=0.00s", "FILE:3: LinAlgError: Singular matrix"],
    );
    assert_fails_mid_run(
        "def act(obs):\n    return 'left'\n",
        &["FILE:1: act() returned 'left'; expected a float or a one-element array"],
    );
    assert_fails_mid_run(
        "def act(obs):\n    return [0.1, 0.2]\n",
        &["FILE:1: act() returned [0.1, 0.2]; expected a float"],
    );
    // A brain that forgot to return: None is not a number (NumPy would read it as NaN).
    assert_fails_mid_run(
        "def act(obs):\n    obs * 2\n",
        &["t=0.00s", "FILE:1: act() returned None; expected a float"],
    );
    // An exception's message reaches the terminal with its control characters written out.
    assert_fails_mid_run(
        "def act(obs):\n    raise RuntimeError('\\x1b[2J\\x1b]0;pwned\\x07 gone')\n",
        &["FILE:2: RuntimeError: \\u{1b}[2J\\u{1b}]0;pwned\\u{7} gone"],
    );
}

/// A brain whose every action is NaN applies nothing: the summary says there is no
/// latency to give rather than a mean of 0.0 ms.
#[test]
fn a_brain_that_never_gives_a_finite_action_has_no_latency_said() {
    let dir = tempfile::tempdir().unwrap();
    let p = script(
        dir.path(),
        "nan.py",
        "def act(obs):\n    return float('nan')\n",
    );
    let spec = format!("{}:act", p.display());
    let o = ratelab(&[
        "run",
        "--clock",
        "virtual",
        "--duration",
        "2",
        "--policy",
        &spec,
    ]);
    let out = String::from_utf8_lossy(&o.stdout);
    assert!(
        out.contains("sense->act latency: none (no finite command was applied)"),
        "{out}"
    );
    assert!(!out.contains("mean sense->act latency"), "{out}");
    assert!(
        out.contains(
            "non-finite actions held over: 32 (no good action came, so no force was applied)"
        ),
        "{out}"
    );
}

/// ±inf from a brain is refused as NaN is: counted, said, and never applied (the actuator
/// holds its last good force), not clipped to a full push.
#[test]
fn an_infinite_action_is_refused_and_counted_as_nan_is() {
    let dir = tempfile::tempdir().unwrap();
    for (name, bad) in [
        ("inf", "float('inf')"),
        ("ninf", "-float('inf')"),
        ("nan", "float('nan')"),
    ] {
        // The shipped scripted brain, but every third action non-finite (holding the one
        // before still balances at 50 Hz).
        let p = script(
            dir.path(),
            &format!("{name}.py"),
            &format!(
                "import importlib.util\n\
                 spec = importlib.util.spec_from_file_location('scripted', {:?})\n\
                 scripted = importlib.util.module_from_spec(spec)\n\
                 spec.loader.exec_module(scripted)\n\
                 calls = 0\n\
                 def act(obs):\n\
                 \x20   global calls\n\
                 \x20   calls += 1\n\
                 \x20   return {bad} if calls % 3 == 0 else scripted.act(obs)\n",
                shipped_brain()
            ),
        );
        let out = dir.path().join(name);
        let (m, trace) = virtual_out(&out, &["--policy", p.to_str().unwrap(), "--duration", "2"]);
        assert_eq!(
            m["nonfinite_actions"].as_u64(),
            Some(33),
            "{name}: one in three of 101 ticks"
        );
        // No applied force is a full push that the brain did not ask for: every force in the
        // trace is finite, and the first refused tick re-applies the force before it.
        let text = String::from_utf8_lossy(&trace);
        let header: Vec<&str> = text.lines().next().unwrap().split(',').collect();
        let col = header
            .iter()
            .position(|c| *c == "action")
            .expect("an action column");
        let actions: Vec<f64> = text
            .lines()
            .skip(1)
            .map(|l| l.split(',').nth(col).unwrap().parse().unwrap())
            .collect();
        assert!(actions.iter().all(|a| a.is_finite()), "{name}");
        assert_eq!(
            actions[2], actions[1],
            "{name}: the third tick holds the second's force"
        );
    }
}

/// A callback asleep in `time.sleep` or `threading.Event.wait` (one C call) is interrupted
/// by the first Ctrl-C too: the run ends at once (well before the 60 s sleep), with its
/// summary, whose headline names the hang and where the callback was.
#[test]
fn a_brain_asleep_in_a_c_call_is_interrupted_by_the_first_ctrl_c() {
    let _m = crate::machine::alone();
    let dir = tempfile::tempdir().unwrap();
    for (name, body) in [
        (
            "sleep",
            "import time\ndef act(obs):\n    time.sleep(60)\n    return 0.0\n",
        ),
        (
            "wait",
            "import threading\ndef act(obs):\n    threading.Event().wait()\n    return 0.0\n",
        ),
    ] {
        let p = script(dir.path(), &format!("{name}.py"), body);
        let child = Command::new(env!("CARGO_BIN_EXE_ratelab"))
            .args(["run", "--clock", "real", "--policy", p.to_str().unwrap()])
            .stdout(Stdio::piped())
            .stderr(Stdio::piped())
            .spawn()
            .unwrap();
        // Ctrl-C once the watchdog has seen the callback hang (2 s into it): by then it is
        // surely inside the sleep or the wait, however slowly Python started.
        let (o, took) = sigint_after(child, "has not returned after");
        let err = stderr(&o);
        // At once, with room for a loaded machine: what this guards against is the 60 s
        // sleep (or the endless wait) running out.
        assert!(
            took < Duration::from_secs(5),
            "{name}: took {took:?}: {err}"
        );
        assert!(
            err.contains(&format!("Ctrl-C interrupted it at {}:3", p.display())),
            "{name}: {err}"
        );
        assert!(
            String::from_utf8_lossy(&o.stdout).contains("HUNG in policy's callback at t="),
            "{name}: the summary is printed, naming the hang"
        );
        assert_eq!(o.status.code(), Some(130), "{name}: {err}");
    }
}

/// A node that fails (an exception, `sys.exit`) fails the run in every layout: `run`, a
/// launch in one process and a launch across processes, under either clock, exit 2 with
/// one line naming the node, after the summary.
#[test]
fn a_failed_node_exits_2_in_every_layout() {
    let _m = crate::machine::shared();
    let dir = tempfile::tempdir().unwrap();
    for (body, needle) in [
        ("raise RuntimeError('gave up')", "RuntimeError: gave up"),
        ("import sys; sys.exit(3)", "SystemExit: 3"),
    ] {
        let (graph, _) = python_graph(
            dir.path(),
            &format!(
                "{HEAD}\
                 class Mine:\n\
                 \x20   def __init__(self, node):\n\
                 \x20       self.n = 0\n\
                 \x20       self.pub = node.create_publisher(Force, '/action', 1)\n\
                 \x20       node.create_subscription(State, '/obs', lambda m: None, 1)\n\
                 \x20       node.create_timer(node.get_period(), self.tick)\n\
                 \x20   def tick(self):\n\
                 \x20       self.n += 1\n\
                 \x20       if self.n == 5:\n\
                 \x20           {body}\n\
                 \x20       self.pub.publish(Force(newtons=0.0))\n"
            ),
            "class = \"Mine\"\nprocess = \"policy\"",
        );
        let g = graph.to_str().unwrap();
        for clock in ["virtual", "real"] {
            for args in [
                vec!["run", "--graph", g],
                vec!["launch", g],
                vec!["launch", g, "--processes"],
            ] {
                let o = ratelab(&[&args[..], &["--clock", clock, "--duration", "1"]].concat());
                let err = stderr(&o);
                let what = format!("{args:?} under the {clock} clock");
                assert_eq!(o.status.code(), Some(2), "{what}: {err}");
                let last = err.trim_end().lines().last().unwrap_or("");
                assert!(
                    last.starts_with("error: node 'policy' failed at t=") && last.contains(needle),
                    "{what}: {err}"
                );
                let out = String::from_utf8_lossy(&o.stdout);
                assert!(
                    out.contains("NODE FAILED"),
                    "{what}: the summary says so\n{out}\n{err}"
                );
            }
        }
    }
}

/// A brain that loops forever (under the virtual clock it holds the clock) is reported after
/// 2 s, Ctrl-C ends the run at once (within 5 s on a loaded machine), and the headline says
/// it hung (not that the node failed), when, for how long and where; so does
/// `metrics.json`'s `node_failed`.
#[test]
fn a_brain_that_never_returns_is_reported_and_ctrl_c_ends_the_run_within_a_second() {
    let _m = crate::machine::alone();
    let dir = tempfile::tempdir().unwrap();
    let p = script(
        dir.path(),
        "hang.py",
        "def act(obs):\n    while True:\n        pass\n",
    );
    for clock in ["real", "virtual"] {
        let out = dir.path().join(clock);
        let child = Command::new(env!("CARGO_BIN_EXE_ratelab"))
            .args(["run", "--clock", clock, "--policy", p.to_str().unwrap()])
            .arg("--out")
            .arg(&out)
            .stdout(Stdio::piped())
            .stderr(Stdio::piped())
            .spawn()
            .unwrap();
        // The watchdog reports the callback after 2 s; Ctrl-C once it has.
        let (o, took) = sigint_after(child, "has not returned after");
        let err = stderr(&o);
        // The loop never ends by itself: anything short of hanging passes, with room for a
        // loaded machine.
        assert!(
            took < Duration::from_secs(5),
            "{clock}: took {took:?}: {err}"
        );
        assert!(
            err.contains(&format!(
                "the brain {}:act() has not returned after 2 s",
                p.display()
            )),
            "{clock}: {err}"
        );
        assert!(
            err.contains(&format!("Ctrl-C interrupted it at {}:", p.display())),
            "{clock}: {err}"
        );
        let stdout = String::from_utf8_lossy(&o.stdout);
        let headline = stdout
            .lines()
            .find(|l| l.contains("HUNG"))
            .unwrap_or_else(|| panic!("{clock}: no HUNG headline: {stdout}"));
        assert!(
            headline.contains("HUNG in policy's callback at t=")
                && headline.contains(&format!(
                    "s without returning; Ctrl-C interrupted it at {}:",
                    p.display()
                )),
            "{clock}: {headline}"
        );
        if clock == "virtual" {
            // The clock held at the first tick.
            assert!(headline.contains("at t=0.00s (ran "), "{headline}");
        }
        assert!(!stdout.contains("NODE FAILED"), "{clock}: {stdout}");
        let metrics = std::fs::read_to_string(out.join("metrics.json")).unwrap();
        assert!(
            metrics.contains("\"node_failed\": \"policy: hung: ran "),
            "{clock}: {metrics}"
        );
        assert_eq!(o.status.code(), Some(130), "{clock}: {err}");
    }
}

/// A Python node's tick that never returns is reported after 100 of the node's periods
/// (0.5 s at 200 Hz, not the brain's fixed 2 s), and Ctrl-C still ends the run at once.
#[test]
fn a_python_node_that_never_returns_is_reported_after_100_periods_and_ctrl_c_ends_it() {
    let _m = crate::machine::alone();
    let dir = tempfile::tempdir().unwrap();
    script(
        dir.path(),
        "hang.py",
        "from ratelab import Force\n\
         class Hang:\n\
         \x20   def __init__(self, node):\n\
         \x20       node.create_publisher(Force, '/action', 1)\n\
         \x20       node.create_timer(node.get_period(), self.on_timer)\n\
         \x20   def on_timer(self):\n\
         \x20       while True:\n\
         \x20           pass\n",
    );
    let graph = std::fs::read_to_string(crate::repo("graphs/cartpole-python.toml"))
        .unwrap()
        .replace("nodes/scripted_balancer.py", "hang.py")
        .replace("ScriptedBalancer", "Hang");
    let g = dir.path().join("graph.toml");
    std::fs::write(&g, graph).unwrap();
    let child = Command::new(env!("CARGO_BIN_EXE_ratelab"))
        .args(["run", "--clock", "real", "--control-hz", "200", "--graph"])
        .arg(&g)
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    // Ctrl-C once the watchdog has reported the tick (0.5 s into it).
    let (o, took) = sigint_after(child, "has not returned after");
    let err = stderr(&o);
    // At once, with room for a loaded machine: the tick never returns by itself.
    assert!(took < Duration::from_secs(5), "took {took:?}: {err}");
    assert!(
        err.contains("node 'policy'")
            && err.contains("has not returned after 0.5 s, 100 of its 5 ms periods"),
        "{err}"
    );
    assert!(
        err.contains("node 'policy' failed at t=") && err.contains(": hung: ran "),
        "{err}"
    );
    assert!(
        String::from_utf8_lossy(&o.stdout).contains("HUNG in policy's callback at t="),
        "the headline names the hang"
    );
    assert_eq!(o.status.code(), Some(130), "{err}");
}

// ---- Python nodes (kind = "python") ----------------------------------------------------

/// [`crate::repo`] as text, for command lines.
fn repo(file: &str) -> String {
    crate::repo(file).to_string_lossy().into_owned()
}

/// metrics.json of one virtual run of `graph` without what names the graph, the brain and
/// the nodes' kinds, and trace.csv.
fn graph_run(dir: &Path, graph: &str, seed: &str, extra: &[&str]) -> (String, Vec<u8>) {
    let (m, trace) = virtual_out(
        dir,
        &[&["--seed", seed, "--graph", graph][..], extra].concat(),
    );
    (crate::metrics_without_names(m), trace)
}

#[test]
fn the_python_policy_node_graph_equals_the_builtin_graph_in_every_figure() {
    let _m = crate::machine::shared();
    let (a, b) = (tempfile::tempdir().unwrap(), tempfile::tempdir().unwrap());
    let python = repo("graphs/cartpole-python.toml");
    let builtin = repo("graphs/cartpole.toml");
    for hz in ["50", "5"] {
        for seed in ["0", "1", "2"] {
            let extra = ["--control-hz", hz];
            let want = graph_run(a.path(), &builtin, seed, &extra);
            let got = graph_run(b.path(), &python, seed, &extra);
            assert!(
                want.0 == got.0,
                "seed {seed}, {hz} Hz: metrics differ\n{}\n{}",
                want.0,
                got.0
            );
            assert!(want.1 == got.1, "seed {seed}, {hz} Hz: trace differs");
        }
    }
    // The label names the node's script and class; the node's kind is python.
    let o = ratelab(&[
        "run",
        "--clock",
        "virtual",
        "--graph",
        &python,
        "--duration",
        "1",
    ]);
    let out = String::from_utf8_lossy(&o.stdout);
    assert!(
        out.contains("policy=Python node 'policy' (")
            && out.contains("scripted_balancer.py:ScriptedBalancer)"),
        "{out}"
    );
}

#[test]
fn a_python_safety_node_equals_the_builtin_safety_node_at_its_rates() {
    let _m = crate::machine::shared();
    let (a, b) = (tempfile::tempdir().unwrap(), tempfile::tempdir().unwrap());
    for seed in ["0", "1"] {
        let want = graph_run(a.path(), &repo("graphs/cartpole-safety.toml"), seed, &[]);
        let got = graph_run(
            b.path(),
            &repo("graphs/cartpole-safety-python.toml"),
            seed,
            &[],
        );
        assert!(want == got, "seed {seed}:\n{}\n{}", want.0, got.0);
    }
}

#[test]
fn a_python_node_balances_under_the_real_clock() {
    let _m = crate::machine::alone();
    let dir = tempfile::tempdir().unwrap();
    let o = ratelab(&[
        "run",
        "--clock",
        "real",
        "--duration",
        "3",
        "--graph",
        &repo("graphs/cartpole-python.toml"),
        "--out",
        dir.path().to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let m: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.path().join("metrics.json")).unwrap())
            .unwrap();
    assert_eq!(m["balanced"], true, "{m}");
    let ticks = m["nodes"]["policy"]["ticks"].as_u64().unwrap();
    assert!((140..=152).contains(&ticks), "policy ticks {ticks}");
    assert_eq!(m["nodes"]["policy"]["kind"], "python");
}

/// A graph in `dir` whose policy is the Python node `body` (class `Mine`), with `node`
/// lines added to its table.
fn python_graph(dir: &Path, body: &str, node: &str) -> (PathBuf, PathBuf) {
    let script = script(dir, "mine.py", body);
    let graph = dir.join("g.toml");
    std::fs::write(
        &graph,
        format!(
            "name = \"g\"\n\
             [[node]]\nname = \"sensor\"\nkind = \"sensor\"\nrate_hz = 50\npublishes = \"/obs\"\n\
             [[node]]\nname = \"policy\"\nkind = \"python\"\nscript = \"mine.py\"\nrate_hz = 50\n\
             subscribes = \"/obs\"\npublishes = \"/action\"\n{node}\n\
             [[node]]\nname = \"actuator\"\nkind = \"actuator\"\nrate_hz = 50\nsubscribes = \"/action\"\n\
             [[topic]]\nname = \"/obs\"\ntype = \"state\"\ndepth = 1\n\
             [[topic]]\nname = \"/action\"\ntype = \"force\"\ndepth = 1\n"
        ),
    )
    .unwrap();
    (graph, script)
}

const HEAD: &str = "from ratelab import State, Force, Position\n";

fn node_refused(body: &str, node: &str, needles: &[&str]) {
    let dir = tempfile::tempdir().unwrap();
    let (graph, script) = python_graph(dir.path(), &format!("{HEAD}{body}"), node);
    let o = ratelab(
        &["run", "--clock", "virtual", "--duration", "1", "--graph"]
            .iter()
            .copied()
            .chain([graph.to_str().unwrap()])
            .collect::<Vec<_>>(),
    );
    let err = stderr(&o);
    assert_eq!(o.status.code(), Some(2), "{err}");
    assert_eq!(err.trim_end().lines().count(), 1, "one line: {err:?}");
    for n in needles {
        let n = n.replace("FILE", script.to_str().unwrap());
        assert!(err.contains(&n), "{err:?} lacks {n:?}");
    }
    assert!(
        !err.contains("panicked") && !err.contains("Traceback"),
        "{err}"
    );
}

#[test]
fn every_way_a_python_node_is_wrong_is_one_line_and_exit_2() {
    const OK: &str = "class Mine:\n\
        \x20   def __init__(self, node):\n\
        \x20       self.pub = node.create_publisher(Force, '/action', 1)\n\
        \x20       node.create_subscription(State, '/obs', self.on_obs, 1)\n\
        \x20   def on_obs(self, msg):\n\
        \x20       self.pub.publish(Force(newtons=0.0))\n";
    // The script is fine: the run goes through (the pole falls, force 0).
    let dir = tempfile::tempdir().unwrap();
    let (graph, _) = python_graph(dir.path(), &format!("{HEAD}{OK}"), "");
    let o = ratelab(&[
        "run",
        "--clock",
        "virtual",
        "--graph",
        graph.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(String::from_utf8_lossy(&o.stdout).contains("FELL"));
    // A missing class; two classes and none named.
    node_refused(OK, "class = \"Other\"", &["FILE: no class 'Other'"]);
    // A script over MAX_SCRIPT_BYTES.
    node_refused(
        &format!("{OK}{}", "#".repeat(16 << 20)),
        "",
        &["FILE: too large", "ratelab::limits::MAX_SCRIPT_BYTES"],
    );
    node_refused(
        &format!("{OK}class Two:\n    pass\n"),
        "",
        &["FILE: name the node's class", "Mine, Two"],
    );
    // A topic or a type the graph file does not give the node.
    node_refused(
        &OK.replace("'/obs', self.on_obs", "'/state', self.on_obs"),
        "",
        &["FILE:5: node 'policy' subscribes '/state', but the graph file gives it subscribes = \"/obs\""],
    );
    node_refused(
        &OK.replace("create_subscription(State", "create_subscription(Position"),
        "",
        &["FILE:5: '/obs' carries State (type = \"state\"), not Position"],
    );
    // A timer that is not a whole number of ticks; a parameter that does not exist.
    node_refused(
        &OK.replace(
            "self.on_obs, 1)",
            "self.on_obs, 1)\n        node.create_timer(0.03, self.on_obs)",
        ),
        "",
        &["FILE:6: create_timer(0.03): node 'policy' ticks every 20 ms"],
    );
    node_refused(
        &OK.replace(
            "self.on_obs, 1)",
            "self.on_obs, 1)\n        node.get_parameter('gain')",
        ),
        "params = { k = 1 }",
        &["FILE:6: node 'policy' has no parameter 'gain' (ParameterNotDeclaredException; declared: none; the graph file's params: k)"],
    );
    // A missing script.
    let dir = tempfile::tempdir().unwrap();
    let (graph, script) = python_graph(dir.path(), OK, "");
    std::fs::remove_file(&script).unwrap();
    let o = ratelab(&["run", "--graph", graph.to_str().unwrap()]);
    assert_eq!(o.status.code(), Some(2));
    assert!(stderr(&o).contains("mine.py: not found"), "{}", stderr(&o));
}

#[test]
fn a_python_node_that_publishes_the_wrong_type_fails_at_that_tick() {
    let dir = tempfile::tempdir().unwrap();
    let body = "class Mine:\n\
        \x20   def __init__(self, node):\n\
        \x20       self.pub = node.create_publisher(Force, '/action', 1)\n\
        \x20       node.create_subscription(State, '/obs', self.on_obs, 1)\n\
        \x20       self.n = 0\n\
        \x20   def on_obs(self, msg):\n\
        \x20       self.n += 1\n\
        \x20       self.pub.publish(Force(newtons=0.0) if self.n < 5 else msg)\n";
    let (graph, script) = python_graph(dir.path(), &format!("{HEAD}{body}"), "");
    let o = ratelab(&[
        "run",
        "--clock",
        "virtual",
        "--graph",
        graph.to_str().unwrap(),
    ]);
    let err = stderr(&o);
    assert_eq!(o.status.code(), Some(2), "{err}");
    let want = format!(
        "node 'policy' failed at t=0.08s: {}:9: TypeError: publish on '/action' takes a Force, got State",
        script.display()
    );
    assert!(err.contains(&want), "{err:?}");
}

#[test]
fn the_graph_file_keeps_python_keys_for_python_nodes() {
    let dir = tempfile::tempdir().unwrap();
    let (graph, _) = python_graph(dir.path(), "", "");
    let text = std::fs::read_to_string(&graph).unwrap().replace(
        "name = \"sensor\"\n",
        "name = \"sensor\"\nscript = \"x.py\"\n",
    );
    std::fs::write(&graph, text).unwrap();
    let o = ratelab(&["run", "--graph", graph.to_str().unwrap()]);
    let err = stderr(&o);
    assert_eq!(o.status.code(), Some(2), "{err}");
    assert!(
        err.contains("'script' is for python nodes, not for a sensor node"),
        "{err}"
    );
    let text = std::fs::read_to_string(&graph)
        .unwrap()
        .replace("script = \"x.py\"\n", "")
        .replace("script = \"mine.py\"\n", "");
    std::fs::write(&graph, text).unwrap();
    let o = ratelab(&["run", "--graph", graph.to_str().unwrap()]);
    assert!(
        stderr(&o).contains("a python node needs `script"),
        "{}",
        stderr(&o)
    );
}

#[test]
fn a_python_node_in_its_own_process_gives_the_in_process_run_byte_for_byte() {
    let graph = ["--graph", "graphs/cartpole-python.toml"];
    crate::distributed::assert_lockstep_equals_in_process(&graph, &graph);
}

/// A node that publishes twice in a tick sends both messages to the process that
/// subscribes, as one process delivers both (only the newest crossed, and the rest were
/// counted lost on the wire, until the report was refused as impossible).
#[test]
fn a_node_that_publishes_twice_a_tick_sends_both_across_processes() {
    publishes_across_processes(2);
}

/// A node that publishes 201 messages a tick (about 9 KiB of samples) goes past what a
/// tick run on Zenoh's receive thread may put itself: the rest are held back and put by the
/// process's main thread, in order, before the tick's report; the run is the one process's
/// byte for byte.
#[test]
fn a_node_that_publishes_a_burst_a_tick_sends_all_of_it_across_processes() {
    publishes_across_processes(201);
}

/// The chapter's Python graph with the policy publishing `n` forces a tick (n − 1 of 0 N,
/// then its own), run in one process and in two under the virtual clock: the same
/// metrics, `n` messages a tick published, none lost.
fn publishes_across_processes(n: usize) {
    let _m = crate::machine::shared();
    let dir = tempfile::tempdir().unwrap();
    std::fs::create_dir(dir.path().join("nodes")).unwrap();
    let script = std::fs::read_to_string(repo("graphs/nodes/scripted_balancer.py")).unwrap();
    let last = "        self.pub.publish(Force(newtons=float(command) * MOTOR_N))";
    assert!(script.contains(last));
    let burst = script.replace(
        last,
        &format!(
            "        for _ in range({}):\n            self.pub.publish(Force(newtons=0.0))\n{last}",
            n - 1
        ),
    );
    std::fs::write(dir.path().join("nodes/burst.py"), burst).unwrap();
    let graph = std::fs::read_to_string(repo("graphs/cartpole-python.toml"))
        .unwrap()
        .replace("nodes/scripted_balancer.py", "nodes/burst.py");
    // The actuator's queue keeps the last four: depth 4 on /action.
    let at = graph.rfind("depth = 1").unwrap();
    let graph = format!("{}depth = 4{}", &graph[..at], &graph[at + 9..]);
    let file = dir.path().join("burst.toml");
    std::fs::write(&file, graph).unwrap();
    let (_, m) = one_and_many(dir.path(), &file);
    let ticks = m["nodes"]["policy"]["ticks"].as_u64().unwrap();
    assert_eq!(
        m["topics"]["/action"]["published"].as_u64(),
        Some(n as u64 * ticks)
    );
    assert_eq!(m["topics"]["/action"].get("lost"), None, "{m}");
}

/// A process that runs many events before it next waits sends their reports in messages
/// of at most 64 (a message of more is refused whole): the robot's process holds the whole
/// chain and four monitors at 50 Hz that compute for 1 ms (a tick is then two events, its
/// start and its end), so before the first horizon it runs 8 instants of 11 events, while a
/// reference at 1 Hz in a process of its own waits on them. The run is the one process's
/// byte for byte.
#[test]
fn a_process_with_many_events_between_its_waits_reports_them_all() {
    let _m = crate::machine::shared();
    let dir = tempfile::tempdir().unwrap();
    std::fs::create_dir(dir.path().join("nodes")).unwrap();
    for script in [
        "obs_monitor.py",
        "square_reference.py",
        "scripted_balancer.py",
    ] {
        std::fs::copy(
            repo(&format!("graphs/nodes/{script}")),
            dir.path().join("nodes").join(script),
        )
        .unwrap();
    }
    let node = |name: &str, kind: &str, extra: &str| {
        format!("[[node]]\nname = \"{name}\"\nkind = \"{kind}\"\n{extra}\n")
    };
    let mut graph = String::from("name = \"many-events\"\n\n");
    graph += &node("sensor", "sensor", "rate_hz = 50\npublishes = \"/obs\"");
    graph += &node(
        "policy",
        "python",
        "script = \"nodes/scripted_balancer.py\"\nrate_hz = 50\nsubscribes = \"/obs\"\npublishes = \"/action\"\nprocess = \"robot\"",
    );
    graph += &node(
        "actuator",
        "actuator",
        "rate_hz = 50\nsubscribes = \"/action\"",
    );
    for k in 1..=4 {
        graph += &node(
            &format!("monitor{k}"),
            "python",
            "script = \"nodes/obs_monitor.py\"\nrate_hz = 50\ncompute_ms = 1\nsubscribes = \"/obs\"\nprocess = \"robot\"",
        );
    }
    graph += &node(
        "reference",
        "python",
        "script = \"nodes/square_reference.py\"\nrate_hz = 1\npublishes = \"/reference\"\nprocess = \"watch\"\nparams = { amplitude_m = 0.3, period_s = 8.0 }",
    );
    graph += "[[topic]]\nname = \"/obs\"\ntype = \"state\"\ndepth = 1\n\n";
    graph += "[[topic]]\nname = \"/action\"\ntype = \"force\"\ndepth = 1\n\n";
    graph += "[[topic]]\nname = \"/reference\"\ntype = \"position\"\ndepth = 1\n";
    let file = dir.path().join("many.toml");
    std::fs::write(&file, graph).unwrap();
    let (out, m) = one_and_many(dir.path(), &file);
    assert!(
        out.contains("in 2 processes: robot [sensor, policy, actuator, monitor1, monitor2, monitor3, monitor4], watch [reference]"),
        "{out}"
    );
    assert_eq!(m["nodes"]["monitor4"]["ticks"].as_u64(), Some(151), "{m}");
}

/// Run graph `file` for 3 s under the virtual clock in one process and launched across
/// processes (outputs under `dir`), assert the two metrics.json byte-identical and return
/// the launch's stdout and the metrics.
fn one_and_many(dir: &Path, file: &Path) -> (String, serde_json::Value) {
    let file = file.to_str().unwrap();
    let (one, many) = (dir.join("one"), dir.join("many"));
    let common = ["--clock", "virtual", "--duration", "3"];
    let o = ratelab(
        &[
            &["run", "--graph", file][..],
            &common,
            &["--out", one.to_str().unwrap()],
        ]
        .concat(),
    );
    assert!(o.status.success(), "{}", stderr(&o));
    let o = ratelab(
        &[
            &["launch", file, "--processes"][..],
            &common,
            &["--out", many.to_str().unwrap()],
        ]
        .concat(),
    );
    let out = String::from_utf8_lossy(&o.stdout).into_owned();
    assert!(o.status.success(), "{out}{}", stderr(&o));
    let a = std::fs::read_to_string(one.join("metrics.json")).unwrap();
    let b = std::fs::read_to_string(many.join("metrics.json")).unwrap();
    assert_eq!(a, b, "one process and two differ");
    (out, serde_json::from_str(&b).unwrap())
}

// ---- Several inputs and outputs (graphs/cartpole-setpoint.toml) ------------------------

/// The mean cart position, m, over trace rows with `from_s <= t < to_s`.
fn mean_cart_pos(trace: &[u8], from_s: f64, to_s: f64) -> f64 {
    let text = String::from_utf8_lossy(trace);
    let mut rows = text.lines();
    let head: Vec<&str> = rows.next().unwrap().split(',').collect();
    let col = |name: &str| head.iter().position(|h| *h == name).unwrap();
    let (t, x) = (col("t_ns"), col("cart_pos"));
    let xs: Vec<f64> = rows
        .map(|r| r.split(',').collect::<Vec<_>>())
        .filter(|r| (from_s..to_s).contains(&(r[t].parse::<f64>().unwrap() / 1e9)))
        .map(|r| r[x].parse().unwrap())
        .collect();
    xs.iter().sum::<f64>() / xs.len() as f64
}

/// A node with two subscriptions and two publishers: the tracker holds the cart at the
/// reference node's setpoint (+0.3 m, then −0.3 m after 4 s) while balancing, publishes
/// its error on a topic nobody reads (the summary says so), and the run is byte-identical
/// run to run.
#[test]
fn a_python_node_with_two_inputs_and_two_outputs_tracks_a_setpoint_and_balances() {
    let _m = crate::machine::shared();
    let (a, b) = (tempfile::tempdir().unwrap(), tempfile::tempdir().unwrap());
    let graph = repo("graphs/cartpole-setpoint.toml");
    let args = ["--graph", graph.as_str(), "--duration", "12"];
    let (m, trace) = virtual_out(a.path(), &args);
    assert_eq!(m["balanced"], true, "{m}");
    let label = format!(
        "Python node 'tracker' ({})",
        repo("graphs/nodes/setpoint_tracker.py")
    );
    assert_eq!(m["policy"], label.as_str());
    let before = mean_cart_pos(&trace, 3.5, 4.0);
    let after = mean_cart_pos(&trace, 7.5, 8.0);
    assert!(
        before > 0.2 && after < -0.2,
        "cart at {before} m, then {after} m"
    );
    // Each output got one message per tick (the timer publishes both).
    let ticks = m["nodes"]["tracker"]["ticks"].as_u64().unwrap();
    assert_eq!(m["topics"]["/action"]["published"], ticks);
    assert_eq!(m["topics"]["/error"]["published"], ticks);
    assert_eq!(m["topics"]["/error"].get("subscriber"), None);
    let (m2, trace2) = virtual_out(b.path(), &args);
    assert!(m == m2 && trace == trace2, "two runs differ");
    let o = ratelab(&[&["run", "--clock", "virtual"][..], &args].concat());
    let out = String::from_utf8_lossy(&o.stdout);
    assert!(out.contains("/error 50.1 msg/s (no subscriber)"), "{out}");
}

/// What a node with several inputs publishes carries the oldest origin among its inputs'
/// newest messages: with the setpoint published at 5 Hz (at 0, 200, … ms) and the sensor at
/// 50 Hz, the tracker's command at `t` rests on the setpoint of the last multiple of 200 ms,
/// so the actuator measures `t mod 200 ms`: 0, 20, …, 180 ms, mean 90. At 50 Hz both
/// inputs are of the same instant: 0 under the virtual clock.
#[test]
fn a_node_with_several_inputs_passes_on_the_oldest_origin() {
    let dir = tempfile::tempdir().unwrap();
    let graph = repo("graphs/cartpole-setpoint.toml");
    let latency = |rate: &str| {
        let (m, _) = virtual_out(
            dir.path(),
            &["--graph", &graph, "--duration", "4", "--rate", rate],
        );
        assert_eq!(m["balanced"], true, "{rate}: {m}");
        (
            m["mean_latency_ms"].as_f64().unwrap(),
            m["latency_max_ms"].as_f64().unwrap(),
        )
    };
    assert_eq!(latency("reference=50"), (0.0, 0.0));
    let (mean, max) = latency("reference=5");
    assert_eq!(max, 180.0);
    assert!((mean - 90.0).abs() < 1.0, "mean {mean} ms");
}

#[test]
fn a_node_with_several_inputs_in_its_own_process_gives_the_in_process_run() {
    let _m = crate::machine::shared();
    let dir = tempfile::tempdir().unwrap();
    let graph = repo("graphs/cartpole-setpoint.toml");
    for seed in ["0", "1"] {
        let (one, many) = (dir.path().join("one"), dir.path().join("many"));
        let common = [
            "--clock",
            "virtual",
            "--seed",
            seed,
            "--duration",
            "6",
            "--graph",
            &graph,
        ];
        let o = ratelab(
            &[
                &["run"][..],
                &common,
                &["--out", one.to_str().unwrap(), "--force"],
            ]
            .concat(),
        );
        assert!(o.status.success(), "{}", stderr(&o));
        let o = ratelab(
            &[
                &["launch", "--processes"][..],
                &common,
                &["--out", many.to_str().unwrap(), "--force"],
            ]
            .concat(),
        );
        let out = String::from_utf8_lossy(&o.stdout);
        assert!(o.status.success(), "{out}{}", stderr(&o));
        assert!(
            out.contains("in 3 processes: robot [sensor, actuator], reference [reference], tracker [tracker]"),
            "{out}"
        );
        let a = std::fs::read_to_string(one.join("metrics.json")).unwrap();
        let b = std::fs::read_to_string(many.join("metrics.json")).unwrap();
        assert_eq!(a, b, "seed {seed}: metrics differ");
    }
}

#[test]
fn a_python_node_subscribes_and_publishes_only_what_its_list_gives_it() {
    let dir = tempfile::tempdir().unwrap();
    let refused = |node: &str, needle: &str| {
        let graph = dir.path().join("g.toml");
        let text = std::fs::read_to_string(repo("graphs/cartpole-setpoint.toml"))
            .unwrap()
            .replace(
                "script = \"nodes/setpoint_tracker.py\"",
                "script = \"tracker.py\"",
            )
            .replace(
                "nodes/square_reference.py",
                &repo("graphs/nodes/square_reference.py"),
            );
        std::fs::write(&graph, text).unwrap();
        let tracker = std::fs::read_to_string(repo("graphs/nodes/setpoint_tracker.py")).unwrap();
        let changed = tracker.replace(
            "        node.create_timer(node.get_period(), self.on_timer)",
            &format!("        node.create_timer(node.get_period(), self.on_timer)\n{node}"),
        );
        assert_ne!(changed, tracker);
        std::fs::write(dir.path().join("tracker.py"), changed).unwrap();
        let o = ratelab(&[
            "run",
            "--clock",
            "virtual",
            "--graph",
            graph.to_str().unwrap(),
        ]);
        let err = stderr(&o);
        assert_eq!(o.status.code(), Some(2), "{err}");
        assert_eq!(err.trim_end().lines().count(), 1, "{err:?}");
        assert!(err.contains(needle), "{err:?} lacks {needle:?}");
    };
    refused(
        "        node.create_subscription(State, '/state', self.on_obs, 1)",
        "node 'tracker' subscribes '/state', but the graph file gives it subscribes = [\"/obs\", \"/reference\"]",
    );
    refused(
        "        node.create_subscription(State, '/obs', self.on_obs, 1)",
        "a second subscription to '/obs' (one per topic)",
    );
    refused(
        "        node.create_publisher(State, '/error', 1)",
        "'/error' carries Position (type = \"position\"), not State",
    );
}

// ---- The ch2.1 actor in NumPy (`ratelab export` + graphs/nodes/ppo_numpy.py) -----------

/// `ratelab export` writes the checkpoint's tensors as .npz; `PpoActor` of the shipped node,
/// run by the embedded interpreter on those weights, gives PyTorch's reference actions
/// within 1e-5; the shipped graph runs with it. Bad exports are one line and exit 2.
#[test]
fn the_ppo_actor_in_numpy_matches_pytorch_from_exported_weights() {
    let dir = tempfile::tempdir().unwrap();
    let npz = dir.path().join("ppo.npz");
    let pt = fixture("ppo_ch2.1_seed0.pt");
    let o = ratelab(&[
        "export",
        pt.to_str().unwrap(),
        "--out",
        npz.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let out = String::from_utf8_lossy(&o.stdout);
    assert!(
        out.lines()
            .any(|l| l.starts_with("actor_mean.0.weight ") && l.ends_with(" [64, 5]")),
        "{out}"
    );
    assert!(
        out.contains("wrote") && out.contains("(13 tensors, float32)"),
        "{out}"
    );

    // Nothing clobbered, and what cannot be exported says why.
    for (args, needle) in [
        (
            vec![pt.to_str().unwrap(), "--out", npz.to_str().unwrap()],
            "--force",
        ),
        (
            vec![
                fixture("ppo_ch2.1_seed0.onnx").to_str().unwrap(),
                "--out",
                dir.path().join("x.npz").to_str().unwrap(),
            ],
            "ppo_ch2.1_seed0.onnx",
        ),
        (
            vec![
                pt.to_str().unwrap(),
                "--out",
                dir.path().join("x.npy").to_str().unwrap(),
            ],
            "must end in .npz",
        ),
    ] {
        let mut a = vec!["export"];
        a.extend(args);
        let o = ratelab(&a);
        let err = stderr(&o);
        assert_eq!(o.status.code(), Some(2), "{a:?}: {err}");
        assert_eq!(err.trim_end().lines().count(), 1, "{err}");
        assert!(err.contains(needle), "{err} lacks {needle}");
    }

    // The shipped node's network, on the reference observations.
    let reference: serde_json::Value = serde_json::from_slice(
        &std::fs::read(fixture("ppo_ch2.1_seed0.reference_actions.json")).unwrap(),
    )
    .unwrap();
    let obs: Vec<Vec<f64>> = serde_json::from_value(reference["obs"].clone()).unwrap();
    let want: Vec<Vec<f64>> = serde_json::from_value(reference["action"].clone()).unwrap();
    assert_eq!((obs.len(), want.len()), (32, 32));
    ratelab::python::start().unwrap();
    let got: Vec<f64> = pyo3::Python::attach(|py| {
        use pyo3::types::PyAnyMethods;
        // As for a node: `from ratelab import Force, State` works.
        ratelab::python::install_messages(py).unwrap();
        let sys = py.import("sys").unwrap();
        sys.getattr("path")
            .unwrap()
            .call_method1("insert", (0, repo("graphs/nodes")))
            .unwrap();
        let actor = py
            .import("ppo_numpy")
            .unwrap()
            .getattr("PpoActor")
            .unwrap()
            .call1((npz.to_str().unwrap(),))
            .unwrap();
        obs.iter()
            .map(|o| actor.call1((o.clone(),)).unwrap().extract::<f64>().unwrap())
            .collect()
    });
    for (i, (g, w)) in got.iter().zip(&want).enumerate() {
        assert!(
            (g - w[0]).abs() < 1e-5,
            "obs {i}: numpy {g}, pytorch {}",
            w[0]
        );
    }

    // The shipped graph, its weights beside a copy of its script.
    let graphs = dir.path().join("graphs");
    std::fs::create_dir_all(graphs.join("nodes")).unwrap();
    std::fs::copy(
        repo("graphs/cartpole-ppo-numpy.toml"),
        graphs.join("cartpole-ppo-numpy.toml"),
    )
    .unwrap();
    std::fs::copy(
        repo("graphs/nodes/ppo_numpy.py"),
        graphs.join("nodes/ppo_numpy.py"),
    )
    .unwrap();
    std::fs::copy(&npz, graphs.join("nodes/ppo_ch2.1_seed0.npz")).unwrap();
    let run = |args: &[&str]| {
        let mut a = vec!["run", "--clock", "virtual", "--duration", "10"];
        a.extend_from_slice(args);
        let o = ratelab(&a);
        assert!(o.status.success(), "{a:?}: {}", stderr(&o));
        String::from_utf8_lossy(&o.stdout).into_owned()
    };
    let numpy = run(&[
        "--graph",
        graphs.join("cartpole-ppo-numpy.toml").to_str().unwrap(),
    ]);
    let torch = run(&["--policy", pt.to_str().unwrap()]);
    let headline = |s: &str| {
        s.lines()
            .find(|l| l.contains("actuator steps"))
            // Without the wall time, which varies.
            .and_then(|l| l.trim_start_matches("[ratelab] ").rsplit_once(" ("))
            .map(|(head, _)| head.to_string())
            .unwrap_or_default()
    };
    // The chapter's measured behaviour of this checkpoint at 50 Hz: it falls at 5.84 s.
    assert!(headline(&torch).starts_with("FELL at t=5.84s"), "{torch}");
    assert_eq!(headline(&numpy), headline(&torch), "{numpy}");

    // Without its weights the node says how to make them.
    std::fs::remove_file(graphs.join("nodes/ppo_ch2.1_seed0.npz")).unwrap();
    let o = ratelab(&[
        "run",
        "--smoke",
        "--graph",
        graphs.join("cartpole-ppo-numpy.toml").to_str().unwrap(),
    ]);
    let err = stderr(&o);
    assert_eq!(o.status.code(), Some(2), "{err}");
    assert!(
        err.contains("FileNotFoundError: no weights at") && err.contains("ratelab export"),
        "{err}"
    );
}

/// Headless, what a Python node writes (print, stderr, a warning, its logger) goes to
/// stderr one line each, stamped `[t=… s NODE]`, and with `--out` to `log.txt` as well.
#[test]
fn what_a_python_node_writes_is_stamped_on_stderr_and_kept_in_log_txt() {
    let dir = tempfile::tempdir().unwrap();
    std::fs::create_dir(dir.path().join("nodes")).unwrap();
    let balancer = std::fs::read_to_string(repo("graphs/nodes/scripted_balancer.py")).unwrap();
    let timer = "    def on_timer(self):\n";
    assert!(balancer.contains(timer));
    let loud = balancer.replace(
        timer,
        &format!(
            "{timer}        import sys, warnings\n        print('tick', 7)\n        print('to stderr', file=sys.stderr)\n        warnings.warn('careful')\n"
        ),
    );
    std::fs::write(dir.path().join("nodes/loud.py"), loud).unwrap();
    let graph = std::fs::read_to_string(repo("graphs/cartpole-python.toml"))
        .unwrap()
        .replace("nodes/scripted_balancer.py", "nodes/loud.py");
    let g = dir.path().join("loud.toml");
    std::fs::write(&g, graph).unwrap();
    let out = dir.path().join("out");
    let o = ratelab(&[
        "run",
        "--clock",
        "virtual",
        "--duration",
        "0.1",
        "--graph",
        g.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
    ]);
    let err = stderr(&o);
    assert!(o.status.success(), "{err}");
    for needle in [
        "[t=0.000 s policy] tick 7",
        "[t=0.020 s policy] to stderr",
        "[t=0.000 s policy] ",
        "UserWarning: careful",
    ] {
        assert!(err.contains(needle), "{needle}: {err}");
    }
    let log = std::fs::read_to_string(out.join("log.txt")).unwrap();
    let on_stderr: Vec<&str> = err.lines().filter(|l| l.starts_with("[t=")).collect();
    let in_log: Vec<&str> = log.lines().collect();
    assert_eq!(
        in_log, on_stderr,
        "log.txt holds what stderr showed of the nodes"
    );
    assert_eq!(
        in_log.iter().filter(|l| l.ends_with("] tick 7")).count(),
        6,
        "one a tick at 50 Hz over 0.1 s: {log}"
    );
    // Nothing is printed raw on stdout: the summary is all there is.
    assert!(!String::from_utf8_lossy(&o.stdout).contains("tick 7"));
}

/// A Python node whose constructor never declares a publisher (or subscription) for a topic
/// its graph file gives it is warned about, once, before the run (nothing would come of
/// the topic); the shipped graphs' nodes declare all of theirs.
#[test]
fn a_python_node_that_never_declares_a_topic_its_file_gives_it_is_warned_about() {
    let dir = tempfile::tempdir().unwrap();
    let (graph, _) = python_graph(
        dir.path(),
        &format!(
            "{HEAD}\
             class Mine:\n\
             \x20   def __init__(self, node):\n\
             \x20       pass\n"
        ),
        "",
    );
    let o = ratelab(&[
        "run",
        "--clock",
        "virtual",
        "--duration",
        "0.2",
        "--graph",
        graph.to_str().unwrap(),
    ]);
    let err = stderr(&o);
    assert!(
        err.contains("[policy] [ratelab] warning: node 'policy' declares no publisher for '/action', which its graph file gives it: nothing is published there"),
        "{err}"
    );
    assert!(
        err.contains("node 'policy' declares no subscription to '/obs'"),
        "{err}"
    );
    for shipped in std::fs::read_dir(repo("graphs")).unwrap() {
        let path = shipped.unwrap().path();
        let text = std::fs::read_to_string(&path).unwrap_or_default();
        if path.extension().is_none_or(|e| e != "toml") || !text.contains("kind = \"python\"") {
            continue;
        }
        let o = ratelab(&[
            "run",
            "--clock",
            "virtual",
            "--duration",
            "0.1",
            "--graph",
            path.to_str().unwrap(),
        ]);
        assert!(
            !stderr(&o).contains("declares no"),
            "{}: {}",
            path.display(),
            stderr(&o)
        );
    }
}

/// A graph of a Python `Painter` (script `painter`, in `dir`) publishing `/img` from a
/// process of its own (`paint`), a Python `Reader` (`reader.py`) that answers each frame
/// on `/action`, and the actuator; written to `dir/bytes.toml`, whose path it returns.
fn painter_reader_graph(dir: &Path, painter: &str) -> PathBuf {
    let g = dir.join("bytes.toml");
    std::fs::write(
        &g,
        format!(
            "name = \"py-bytes\"\n\
             [[node]]\nname = \"painter\"\nkind = \"python\"\nscript = \"{painter}\"\n\
             class = \"Painter\"\nrate_hz = 10\npublishes = \"/img\"\nprocess = \"paint\"\n\
             [[node]]\nname = \"reader\"\nkind = \"python\"\nscript = \"reader.py\"\n\
             class = \"Reader\"\nrate_hz = 10\nsubscribes = \"/img\"\npublishes = \"/action\"\n\
             [[node]]\nname = \"actuator\"\nkind = \"actuator\"\nrate_hz = 50\nsubscribes = \"/action\"\n\
             [[topic]]\nname = \"/img\"\ntype = \"image\"\ndepth = 1\n\
             [[topic]]\nname = \"/action\"\ntype = \"force\"\ndepth = 1\n"
        ),
    )
    .unwrap();
    g
}

/// Bytes cross into and out of Python nodes (issue 51 item 2): a Python node publishes a
/// NumPy array as an `Image`'s pixels, another reads them back (a read-only view) with `np.frombuffer`, in one
/// process and across processes (a node that finds a pixel wrong raises, and the run exits
/// 2); a field of the wrong kind fails the node naming the field.
#[test]
fn a_python_node_publishes_and_reads_an_image_s_bytes_in_one_process_and_across() {
    let _m = crate::machine::shared();
    let dir = tempfile::tempdir().unwrap();
    script(
        dir.path(),
        "painter.py",
        "import numpy as np\n\
         from ratelab import Image\n\
         class Painter:\n\
         \x20   def __init__(self, node):\n\
         \x20       self.k = 0\n\
         \x20       self.pub = node.create_publisher(Image, '/img', 1)\n\
         \x20       node.create_timer(node.get_period(), self.tick)\n\
         \x20   def tick(self):\n\
         \x20       self.k += 1\n\
         \x20       frame = (np.arange(12, dtype=np.uint8) * self.k) % 251\n\
         \x20       self.pub.publish(Image(height=3, width=4, encoding='mono8', step=4, data=PIXELS))\n",
    );
    script(
        dir.path(),
        "reader.py",
        "import numpy as np\n\
         from ratelab import Force, Image\n\
         class Reader:\n\
         \x20   def __init__(self, node):\n\
         \x20       self.pub = node.create_publisher(Force, '/action', 1)\n\
         \x20       node.create_subscription(Image, '/img', self.on_img, 1)\n\
         \x20   def on_img(self, img):\n\
         \x20       assert isinstance(img.data, memoryview) and img.data.readonly, repr(img)\n\
         \x20       assert img.encoding == 'mono8', repr(img)\n\
         \x20       assert (img.height, img.width, img.step) == (3, 4, 4), repr(img)\n\
         \x20       px = np.frombuffer(img.data, np.uint8).reshape(img.height, img.step)\n\
         \x20       k = int(px[0, 1])\n\
         \x20       want = (np.arange(12, dtype=np.uint8) * k) % 251\n\
         \x20       assert (px.ravel() == want).all(), (k, px)\n\
         \x20       self.pub.publish(Force(newtons=0.0))\n",
    );
    let graph = |pixels: &str| {
        let painter = std::fs::read_to_string(dir.path().join("painter.py"))
            .unwrap()
            .replace("PIXELS", pixels);
        std::fs::write(dir.path().join("painter_now.py"), painter).unwrap();
        painter_reader_graph(dir.path(), "painter_now.py")
    };
    let g = graph("frame");
    let g = g.to_str().unwrap();
    for (how, args) in [
        ("in one process", vec!["run", "--graph", g]),
        ("across processes", vec!["launch", g, "--processes"]),
    ] {
        let out = dir.path().join(how.replace(' ', "-"));
        let o = ratelab(
            &[
                &args[..],
                &["--clock", "virtual", "--duration", "1"],
                &["--out", out.to_str().unwrap()],
            ]
            .concat(),
        );
        assert!(o.status.success(), "{how}: {}", stderr(&o));
        let m: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(out.join("metrics.json")).unwrap())
                .unwrap();
        // (Pushed by nothing, the pole falls within a second: what counts is that every
        // frame painted was read whole.)
        let painted = &m["nodes"]["painter"]["ticks"];
        assert!(painted.as_u64().unwrap() >= 5, "{how}: {m}");
        assert_eq!(&m["topics"]["/img"]["published"], painted, "{how}: {m}");
        assert_eq!(&m["topics"]["/action"]["published"], painted, "{how}: {m}");
    }
    // Pixels that are not bytes: the painter fails at its first tick, naming the field.
    let g = graph("3.5");
    let o = ratelab(&[
        "run",
        "--graph",
        g.to_str().unwrap(),
        "--clock",
        "virtual",
        "--duration",
        "1",
    ]);
    let err = stderr(&o);
    assert_eq!(o.status.code(), Some(2), "{err}");
    assert!(
        err.contains("node 'painter' failed") && err.contains("field 'data' takes bytes"),
        "{err}"
    );
}

/// A Python node's frame crosses to another process in the buffer its topic lent (issue 76
/// item 1): the NumPy array it publishes is copied once, into the publishing process's
/// shared-memory pool, and the reading process's pixels are a view of that buffer. The
/// launch's wire line counts every frame so; the reader checks every pixel.
#[test]
fn a_python_node_s_large_frame_crosses_in_the_buffer_its_topic_lent() {
    let _m = crate::machine::shared();
    let dir = tempfile::tempdir().unwrap();
    script(
        dir.path(),
        "painter.py",
        "import numpy as np\n\
         from ratelab import Image\n\
         class Painter:\n\
         \x20   def __init__(self, node):\n\
         \x20       self.k = 0\n\
         \x20       self.pub = node.create_publisher(Image, '/img', 1)\n\
         \x20       node.create_timer(node.get_period(), self.tick)\n\
         \x20   def tick(self):\n\
         \x20       self.k += 1\n\
         \x20       frame = np.full((300, 300), self.k % 251, dtype=np.uint8)\n\
         \x20       self.pub.publish(Image(height=300, width=300, encoding='mono8', step=300, data=frame))\n",
    );
    script(
        dir.path(),
        "reader.py",
        "import numpy as np\n\
         from ratelab import Force, Image\n\
         class Reader:\n\
         \x20   def __init__(self, node):\n\
         \x20       self.pub = node.create_publisher(Force, '/action', 1)\n\
         \x20       node.create_subscription(Image, '/img', self.on_img, 1)\n\
         \x20   def on_img(self, img):\n\
         \x20       px = np.frombuffer(img.data, np.uint8)\n\
         \x20       assert px.size == 90000 and (px == px[0]).all() and px[0] > 0, px[:4]\n\
         \x20       self.pub.publish(Force(newtons=0.0))\n",
    );
    let g = painter_reader_graph(dir.path(), "painter.py");
    let o = ratelab(&[
        "launch",
        g.to_str().unwrap(),
        "--processes",
        "--clock",
        "virtual",
        "--duration",
        "1",
    ]);
    let out = String::from_utf8_lossy(&o.stdout).into_owned();
    assert!(o.status.success(), "{out}{}", stderr(&o));
    let line = crate::wire_line(&out, "/img", "reader");
    let samples = crate::wire_samples(line);
    assert!(samples >= 5, "{line}");
    assert_eq!(crate::read_in_place(line), samples, "{line}");
    assert_eq!(crate::drawn_in_place(line), samples, "{line}");
}

/// Under the real clock each node runs on its own thread, and `print` writes a line in
/// pieces: one node's line stays whole while another prints between its pieces (each
/// thread has its own partial line).
#[test]
fn lines_printed_at_once_by_two_nodes_stay_whole() {
    let _m = crate::machine::shared();
    let dir = tempfile::tempdir().unwrap();
    // `slow` writes half a line, sleeps (the GIL let go) and ends it; `fast` prints whole
    // lines meanwhile, at a rate that puts several of them inside each sleep.
    script(
        dir.path(),
        "slow.py",
        "import sys, time\n\
         class Slow:\n\
         \x20   def __init__(self, node):\n\
         \x20       node.create_timer(node.get_period(), self.tick)\n\
         \x20   def tick(self):\n\
         \x20       sys.stdout.write('slow begins')\n\
         \x20       time.sleep(0.03)\n\
         \x20       sys.stdout.write(' and ends\\n')\n",
    );
    script(
        dir.path(),
        "fast.py",
        "class Fast:\n\
         \x20   def __init__(self, node):\n\
         \x20       node.create_timer(node.get_period(), self.tick)\n\
         \x20   def tick(self):\n\
         \x20       print('fast', 'line')\n",
    );
    let graph = dir.path().join("g.toml");
    std::fs::write(
        &graph,
        "name = \"g\"\n\
         [[node]]\nname = \"sensor\"\nkind = \"sensor\"\nrate_hz = 50\npublishes = \"/obs\"\n\
         [[node]]\nname = \"policy\"\nkind = \"policy\"\nrate_hz = 50\nsubscribes = \"/obs\"\npublishes = \"/action\"\n\
         [[node]]\nname = \"actuator\"\nkind = \"actuator\"\nrate_hz = 50\nsubscribes = \"/action\"\n\
         [[node]]\nname = \"slow\"\nkind = \"python\"\nscript = \"slow.py\"\nrate_hz = 10\n\
         [[node]]\nname = \"fast\"\nkind = \"python\"\nscript = \"fast.py\"\nrate_hz = 200\n\
         [[topic]]\nname = \"/obs\"\ntype = \"state\"\ndepth = 1\n\
         [[topic]]\nname = \"/action\"\ntype = \"force\"\ndepth = 1\n",
    )
    .unwrap();
    let o = ratelab(&[
        "run",
        "--clock",
        "real",
        "--duration",
        "1",
        "--graph",
        graph.to_str().unwrap(),
    ]);
    let err = stderr(&o);
    assert!(o.status.success(), "{err}");
    let lines: Vec<&str> = err.lines().filter(|l| l.starts_with("[t=")).collect();
    let said = |node: &str, text: &str| {
        lines
            .iter()
            .filter(|l| l.contains(&format!(" {node}] ")) && l.ends_with(text))
            .count()
    };
    let (slow, fast) = (
        said("slow", "] slow begins and ends"),
        said("fast", "] fast line"),
    );
    assert!(slow >= 3 && fast >= 20, "{slow} slow, {fast} fast: {err}");
    // Every line is one of the two the nodes wrote, whole: nothing spliced.
    for l in &lines {
        let whole = l.ends_with(" slow] slow begins and ends") || l.ends_with(" fast] fast line");
        assert!(whole, "a spliced line: {l:?}\n{err}");
    }
}
