//! The integration and end-to-end suite, as one test binary made of modules: one link of
//! rerun, candle, tract and MuJoCo instead of one per file (see BENCHMARKS.md, set-up time).
//!
//! Tests of one binary run concurrently, so the ones that measure time take the machine
//! alone ([`machine::alone`]: real-clock runs, the lab in a pseudo-terminal), and the
//! CPU-heavy ones ([`machine::shared`]: sweeps, exercise measurements, stress) never run
//! beside them. Light tests take neither.

/// The repository's top folder (this suite belongs to the `lab/` package).
pub const REPO: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/..");

/// `file`, relative to the repository's top folder.
pub fn repo(file: &str) -> std::path::PathBuf {
    std::path::Path::new(REPO).join(file)
}

/// The chapter's graph with its Python policy, `graphs/cartpole-python.toml` and its
/// `graphs/nodes/scripted_balancer.py`, copied into `dir` as `g.toml` and
/// `nodes/scripted_balancer.py` for a test to save over: the graph file, the node's file and
/// the node's text.
pub fn python_graph_copy(
    dir: &std::path::Path,
) -> (std::path::PathBuf, std::path::PathBuf, String) {
    std::fs::create_dir_all(dir.join("nodes")).unwrap();
    let graph = dir.join("g.toml");
    std::fs::copy(repo("graphs/cartpole-python.toml"), &graph).unwrap();
    let node = dir.join("nodes/scripted_balancer.py");
    let script = std::fs::read_to_string(repo("graphs/nodes/scripted_balancer.py")).unwrap();
    std::fs::write(&node, &script).unwrap();
    (graph, node, script)
}

/// The chapter's graph with a Python policy (`graphs/cartpole-python.toml`) whose timer
/// callback first runs `code` (Python statements, one per line), written in `dir` as
/// `loud.toml` and `nodes/loud.py`: a node that writes. Returns the graph file.
pub fn loud_python_graph(dir: &std::path::Path, code: &str) -> std::path::PathBuf {
    std::fs::create_dir_all(dir.join("nodes")).unwrap();
    let balancer = std::fs::read_to_string(repo("graphs/nodes/scripted_balancer.py")).unwrap();
    let timer = "    def on_timer(self):\n";
    assert!(balancer.contains(timer));
    let body: String = code.lines().map(|l| format!("        {l}\n")).collect();
    std::fs::write(
        dir.join("nodes/loud.py"),
        balancer.replace(timer, &format!("{timer}{body}")),
    )
    .unwrap();
    let graph = std::fs::read_to_string(repo("graphs/cartpole-python.toml"))
        .unwrap()
        .replace("nodes/scripted_balancer.py", "nodes/loud.py");
    let g = dir.join("loud.toml");
    std::fs::write(&g, graph).unwrap();
    g
}

/// metrics.json `m` as pretty text without what names the graph, the brain and the nodes'
/// kinds (each must be there): what two graphs of the same shape, one with a Python or an
/// external node in the built-in node's place, must then have equal.
pub fn metrics_without_names(mut m: serde_json::Value) -> String {
    let o = m.as_object_mut().unwrap();
    o.remove("graph").expect("graph");
    o.remove("policy").expect("policy");
    for n in o["nodes"].as_object_mut().unwrap().values_mut() {
        n.as_object_mut().unwrap().remove("kind").expect("kind");
    }
    serde_json::to_string_pretty(&m).unwrap()
}

/// How many samples a launch's wire line (`wire /image into 'vision': 91 samples, … | 90
/// read in place from shared memory`) says were read in place: 0 when it says none (shared
/// memory off).
pub fn read_in_place(wire_line: &str) -> u64 {
    wire_line_count(wire_line, " read in place from shared memory")
}

/// A launch's summary line for `topic`'s time on the wire into `process` (`wire /image
/// into 'vision': 91 samples, …`), out of its printed `summary`; the test fails without one.
pub fn wire_line<'s>(summary: &'s str, topic: &str, process: &str) -> &'s str {
    let head = format!("wire {topic} into '{process}'");
    summary
        .lines()
        .find(|l| l.contains(&head))
        .unwrap_or_else(|| panic!("no wire line for {topic} into {process}: {summary}"))
}

/// How many samples a launch's wire line says arrived.
pub fn wire_samples(wire_line: &str) -> u64 {
    wire_line
        .split(": ")
        .nth(1)
        .and_then(|r| r.split(' ').next())
        .and_then(|n| n.parse().ok())
        .unwrap_or_else(|| panic!("no sample count in: {wire_line}"))
}

/// Of those, how many crossed in the buffer their publishing node drew them into (a lent
/// buffer, issue 76), as a launch's wire line says it; 0 when it says none.
pub fn drawn_in_place(wire_line: &str) -> u64 {
    wire_line_count(wire_line, " as their node drew them")
}

/// The count a launch's wire line gives before `suffix` in one of its ` | ` parts; 0 when
/// no part ends so.
fn wire_line_count(wire_line: &str, suffix: &str) -> u64 {
    wire_line
        .split(" | ")
        .find_map(|part| part.strip_suffix(suffix))
        .map_or(0, |n| n.trim().parse().unwrap())
}

/// `ratelab ARGS` run in the repository's top folder: (exit code, stdout, stderr).
pub fn ratelab_in_repo(args: &[&str]) -> (i32, String, String) {
    ratelab_in_repo_with(
        args,
        &mut std::process::Command::new(env!("CARGO_BIN_EXE_ratelab")),
    )
}

/// [`ratelab_in_repo`] with `cmd` (the binary, its environment set by the caller).
pub fn ratelab_in_repo_with(
    args: &[&str],
    cmd: &mut std::process::Command,
) -> (i32, String, String) {
    let o = cmd.args(args).current_dir(REPO).output().unwrap();
    (
        o.status.code().unwrap_or(-1),
        String::from_utf8_lossy(&o.stdout).into_owned(),
        String::from_utf8_lossy(&o.stderr).into_owned(),
    )
}

mod architecture;
mod brains;
mod chapter_bands;
mod cli;
mod custom_node;
mod distributed;
mod e2e_pty;
mod executors;
mod exercises;
mod glance;
mod graphs;
mod hardening;
mod hostile;
mod hostile_readers;
mod large_graphs;
mod memory_bounds;
mod python;
mod python_env;
mod qos;
mod qos_compat;
mod realtime;
mod recording;
mod reference_runs;
mod ros2;
mod ros2_cli;
mod ros2_cli_rules;
mod ros2_cli_waits;
mod ros2_external;
mod ros2_latched;
mod ros2_params;
mod ros2_rosout;
mod runcore;
mod security;
mod session;
mod topic_stress;

pub mod machine {
    //! Turns on the machine between timing-sensitive and CPU-heavy tests.
    use std::sync::{RwLock, RwLockReadGuard, RwLockWriteGuard};

    static MACHINE: RwLock<()> = RwLock::new(());

    /// For a test that measures time (real clock, PTY): no heavy test runs meanwhile.
    pub fn alone() -> RwLockWriteGuard<'static, ()> {
        MACHINE.write().unwrap_or_else(|e| e.into_inner())
    }

    /// For a CPU-heavy test: it may run beside other heavy tests, never beside a timing one.
    pub fn shared() -> RwLockReadGuard<'static, ()> {
        MACHINE.read().unwrap_or_else(|e| e.into_inner())
    }
}
