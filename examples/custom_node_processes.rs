//! A node kind written outside ratelab, run across processes: this program registers the
//! PD controller of `examples/custom_node.rs` as `kind = "pd"` and launches
//! `examples/cartpole-pd.toml` split over OS processes (`robot` [sensor, actuator] and
//! `policy` [policy]), each process **this program started again** as a node — a
//! `ratelab` binary would not know the kind. Under the virtual clock (the lockstep) the
//! launch's metrics equal the same graph's run in one process, which it checks and prints.
//!
//! ```sh
//! cargo run --release --example custom_node_processes [-- --seed N]
//! ```
//!
//! How a program of its own joins a launch: the launcher starts `LaunchOptions::exe` with
//! `node --credentials FILE --graph FILE --process NAME --connect ENDPOINT`; the program
//! registers its kinds, then serves that command with [`run_member`] (here parsed with
//! clap, as the `ratelab` binary does). Exit status 0 when the two runs are equal, 1 when
//! not, 2 for bad arguments or a failed launch.

#[path = "common/pd.rs"]
mod pd;

use clap::{Parser, Subcommand};
use ratelab::distributed::credentials::Credentials;
use ratelab::distributed::launcher::{launch, LaunchOptions};
use ratelab::distributed::member::{run_member, MemberOptions};
use ratelab::graph::GraphSpec;
use ratelab::policy::Scripted;
use ratelab::scheduler::StopFlag;
use ratelab::{run, ClockKind, Nanos, RunConfig, RunOptions};
use std::path::PathBuf;

/// The graph, as a file: the launcher hands its path to every process it starts.
fn graph_path() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("examples/cartpole-pd.toml")
}

#[derive(Parser)]
#[command(about = "A registered node kind across processes")]
struct Cli {
    /// The run's seed.
    #[arg(long, default_value_t = 0)]
    seed: u64,
    #[command(subcommand)]
    command: Option<Command>,
}

#[derive(Subcommand)]
enum Command {
    /// One process of a launch (the launcher starts it): the `ratelab node` arguments.
    Node {
        #[arg(long)]
        graph: PathBuf,
        #[arg(long)]
        process: String,
        #[arg(long, required = true)]
        connect: Vec<String>,
        #[arg(long)]
        listen: Vec<String>,
        #[arg(long)]
        credentials: PathBuf,
    },
}

fn main() {
    // Zenoh's threads as ratelab sets them, before any thread starts (launcher and nodes).
    if let Err(e) = ratelab::distributed::set_zenoh_runtime() {
        eprintln!("custom_node_processes: {e}");
        std::process::exit(2);
    }
    pd::register_pd();
    let cli = Cli::parse();
    let fail = |e: &dyn std::fmt::Display| -> ! {
        eprintln!("custom_node_processes: {e}");
        std::process::exit(2)
    };
    if let Some(Command::Node {
        graph,
        process,
        connect,
        listen,
        credentials,
    }) = cli.command
    {
        let opts = MemberOptions {
            graph_bytes: std::fs::read(&graph).unwrap_or_else(|e| fail(&e)),
            graph_origin: graph.display().to_string(),
            process: process.clone(),
            connect,
            listen,
            credentials: Credentials::load(&credentials).unwrap_or_else(|e| fail(&e)),
            say: None,
        };
        if let Err(e) = run_member(&opts, &StopFlag::new()) {
            fail(&format!("node '{process}': {e}"));
        }
        return;
    }

    let path = graph_path();
    let bytes = std::fs::read(&path).unwrap_or_else(|e| fail(&e));
    let graph = GraphSpec::load(&path).unwrap_or_else(|e| fail(&e));
    let cfg = RunConfig {
        clock: ClockKind::Virtual,
        seed: cli.seed,
        duration: Nanos(10 * Nanos::SECOND.0),
        graph: graph.clone(),
        ..RunConfig::default()
    };
    let one = run(&cfg, Box::new(Scripted), RunOptions::default())
        .unwrap_or_else(|e| fail(&e))
        .metrics;
    let placement = graph.placement();
    let names: Vec<String> = placement.iter().map(|(p, _)| p.clone()).collect();
    let groups: Vec<String> = placement
        .iter()
        .map(|(p, ids)| {
            let nodes: Vec<&str> = ids.iter().map(|i| graph.node(*i).name.as_str()).collect();
            format!("{p} [{}]", nodes.join(", "))
        })
        .collect();
    println!(
        "launch: graph '{}' in {} processes: {}",
        graph.name,
        names.len(),
        groups.join(", ")
    );
    let opts = LaunchOptions {
        graph_bytes: bytes,
        graph_path: Some(path),
        // Any free port on loopback (the processes it starts are told which).
        listen: Some(ratelab::distributed::LOOPBACK_ANY.to_string()),
        policy: "scripted".into(),
        exe: Some(std::env::current_exe().unwrap_or_else(|e| fail(&e))),
        child_stderr: None,
        start_gate: None,
        listening: None,
        pace: None,
        credentials: Credentials::generate(&graph.name, &names).unwrap_or_else(|e| fail(&e)),
        ros2_domain: None,
    };
    let report = launch(&cfg, &opts, &StopFlag::new(), &|line| {
        println!("launch: {line}")
    })
    .unwrap_or_else(|e| fail(&e));
    let many = report.metrics;
    println!(
        "pd node across {} processes, seed {}: {}",
        names.len(),
        cli.seed,
        many.headline()
    );
    let json = |m: &ratelab::metrics::Metrics| serde_json::to_string(m).expect("serializes");
    let equal = json(&one) == json(&many);
    println!(
        "  equal to the same graph in one process in every figure: {}",
        if equal { "yes" } else { "NO" }
    );
    std::process::exit(if equal { 0 } else { 1 });
}
