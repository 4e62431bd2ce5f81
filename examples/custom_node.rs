//! A node kind written outside ratelab: a PD controller, registered as `kind = "pd"`, runs
//! the chapter's graph (sensor → `/obs` → pd → `/action` → actuator) headless on the
//! virtual clock, and is compared with the built-in policy node running the chapter's
//! scripted balancer.
//!
//! ```sh
//! cargo run --release --example custom_node [CONTROL_HZ] [SEED]    # default: 50 Hz, seed 0
//! ```
//!
//! The balancer *is* a PD controller (`u = 10 θ + 2 θ̇ + 0.4 x + 0.8 ẋ`, clipped to
//! [-1, 1]); with those gains, given as the node's `params` in the graph file, the run's
//! metrics equal the built-in graph's in every figure (the graph's name, the brain's label
//! and the node's kind aside), which the example checks and prints. Exit status 0 when they
//! are equal, 1 when not, 2 for bad arguments.

#[path = "common/pd.rs"]
mod pd;

use ratelab::graph::GraphSpec;
use ratelab::policy::Scripted;
use ratelab::{run, ClockKind, RunConfig, RunOptions};

/// The chapter's graph with the policy node replaced by a `pd` node.
const GRAPH: &str = include_str!("cartpole-pd.toml");

fn main() {
    ratelab::init(); // the Python layer, for graphs with Python nodes
    let args: Vec<String> = std::env::args().skip(1).collect();
    let arg = |i: usize, default: f64| -> f64 {
        match args.get(i).map(|a| a.parse::<f64>()) {
            None => default,
            Some(Ok(v)) if v.is_finite() && v >= 0.0 => v,
            Some(_) => {
                eprintln!("usage: custom_node [CONTROL_HZ] [SEED]");
                std::process::exit(2);
            }
        }
    };
    let (control_hz, seed) = (arg(0, 50.0), arg(1, 0.0) as u64);

    pd::register_pd();

    let metrics = |graph: GraphSpec| {
        let mut cfg = RunConfig {
            clock: ClockKind::Virtual,
            seed,
            graph,
            ..RunConfig::default()
        };
        if let Err(e) = cfg.set_control_hz(control_hz) {
            eprintln!("custom_node: {e}");
            std::process::exit(2);
        }
        match run(&cfg, Box::new(Scripted), RunOptions::default()) {
            Ok(report) => report.metrics,
            Err(e) => {
                eprintln!("custom_node: {e}");
                std::process::exit(2);
            }
        }
    };
    let pd_graph = GraphSpec::parse(GRAPH, "examples/custom_node.rs").unwrap_or_else(|e| {
        eprintln!("{e}");
        std::process::exit(2);
    });
    let pd = metrics(pd_graph);
    let builtin = metrics(GraphSpec::chapter());

    println!("pd node at {control_hz} Hz, seed {seed}: {}", pd.headline());
    println!(
        "  sense->act latency mean {:.1} ms (p50 {:.1} | p99 {:.1} | max {:.1} ms); /obs {} dropped",
        pd.mean_latency_ms,
        pd.latency_p50_ms,
        pd.latency_p99_ms,
        pd.latency_max_ms,
        pd.topics.get("/obs").map_or(0, |t| t.dropped)
    );
    // Every figure but what names the graph, the brain and the node's kind.
    let figures = |m: &ratelab::metrics::Metrics| {
        let mut v = serde_json::to_value(m).expect("metrics serialize");
        let o = v.as_object_mut().expect("an object");
        o.remove("graph");
        o.remove("policy");
        if let Some(nodes) = o.get_mut("nodes").and_then(|n| n.as_object_mut()) {
            for n in nodes.values_mut() {
                if let Some(n) = n.as_object_mut() {
                    n.remove("kind");
                }
            }
        }
        v
    };
    let equal = figures(&pd) == figures(&builtin);
    println!(
        "  equal to the built-in policy node (scripted balancer) in every figure: {}",
        if equal { "yes" } else { "NO" }
    );
    std::process::exit(if equal { 0 } else { 1 });
}
