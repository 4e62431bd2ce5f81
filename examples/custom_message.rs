//! A message type written outside ratelab: a cart position `Setpoint` (one field,
//! `cart_pos_m`), registered with `ratelab::msg::register`, published by a Rust node kind
//! (`square_setpoint`) and read by a Python node as `ratelab.Setpoint`
//! (`examples/cartpole-setpoint-msg.toml`). The graph runs headless on the virtual clock
//! and is compared with `graphs/cartpole-setpoint.toml`, where the same square wave travels
//! as a built-in `position` message from a Python node.
//!
//! ```sh
//! cargo run --release --example custom_message [SEED]    # default: seed 0
//! ```
//!
//! The setpoint changes type, not value: the run's metrics equal the built-in graph's in
//! every figure (the graph's name, the nodes' kinds and `/reference`'s type aside), which
//! the example checks and prints. Exit status 0 when they are equal, 1 when not, 2 for bad
//! arguments or a graph that does not run.

#[path = "common/setpoint.rs"]
mod setpoint;

use ratelab::graph::GraphSpec;
use ratelab::policy::Scripted;
use ratelab::{run, ClockKind, RunConfig, RunOptions};
use std::path::Path;

fn main() {
    ratelab::init(); // the Python layer, for graphs with Python nodes
    let seed = match std::env::args().nth(1).map(|a| a.parse::<u64>()) {
        None => 0,
        Some(Ok(s)) => s,
        Some(Err(_)) => {
            eprintln!("usage: custom_message [SEED]");
            std::process::exit(2);
        }
    };
    setpoint::register_setpoint();

    let repo = Path::new(env!("CARGO_MANIFEST_DIR"));
    let load = |file: &str| {
        GraphSpec::load(&repo.join(file)).unwrap_or_else(|e| {
            eprintln!("custom_message: {e}");
            std::process::exit(2);
        })
    };
    let metrics = |graph: GraphSpec| {
        let cfg = RunConfig {
            clock: ClockKind::Virtual,
            seed,
            graph,
            ..RunConfig::default()
        };
        match run(&cfg, Box::new(Scripted), RunOptions::default()) {
            Ok(report) => report.metrics,
            Err(e) => {
                eprintln!("custom_message: {e}");
                std::process::exit(2);
            }
        }
    };
    let own = metrics(load("examples/cartpole-setpoint-msg.toml"));
    let built_in = metrics(load("graphs/cartpole-setpoint.toml"));

    println!("setpoint message, seed {seed}: {}", own.headline());
    let reference = own.topics.get("/reference");
    println!(
        "  /reference carries {} ({} published); sense->act latency mean {:.1} ms",
        reference.map_or("?", |t| t.msg.as_str()),
        reference.map_or(0, |t| t.published),
        own.mean_latency_ms
    );
    // Every figure but what names the graph, the brain, the nodes' kinds and the type.
    let figures = |m: &ratelab::metrics::Metrics| {
        let mut v = serde_json::to_value(m).expect("metrics serialize");
        let o = v.as_object_mut().expect("an object");
        o.remove("graph");
        o.remove("policy");
        for key in ["nodes", "topics"] {
            if let Some(items) = o.get_mut(key).and_then(|n| n.as_object_mut()) {
                for item in items.values_mut() {
                    if let Some(item) = item.as_object_mut() {
                        item.remove("kind");
                        item.remove("type");
                    }
                }
            }
        }
        v
    };
    let equal = figures(&own) == figures(&built_in);
    println!(
        "  equal to graphs/cartpole-setpoint.toml (a position message) in every figure: {}",
        if equal { "yes" } else { "NO" }
    );
    std::process::exit(if equal { 0 } else { 1 });
}
