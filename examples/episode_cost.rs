//! Instruction counts for BENCHMARKS.md (the host's timings are too noisy for a 10% claim):
//!
//! ```sh
//! valgrind --tool=callgrind --callgrind-out-file=cg.out target/release/examples/episode_cost graph 20
//! ```
//!
//! `episode_cost bare|graph N` runs N ten-second episodes: `bare` steps a fresh plant with the
//! scripted brain inline (501 control steps, 1002 `mj_step`); `graph` runs the same episode
//! through ratelab's graph on the virtual clock. Per-episode cost = (count(N) − count(0)) / N.

use ratelab::plant::CartPole;
use ratelab::policy::{Policy, Scripted};
use ratelab::{run, ClockKind, RunConfig, RunOptions};
use std::hint::black_box;

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let (mode, n) = match (
        args.get(1).map(String::as_str),
        args.get(2).and_then(|n| n.parse::<u32>().ok()),
    ) {
        (Some(m @ ("bare" | "graph")), Some(n)) => (m.to_string(), n),
        _ => {
            eprintln!("usage: episode_cost bare|graph N");
            std::process::exit(2);
        }
    };
    // Warm the process-wide model cache in both modes, so N = 0 is the fixed cost.
    black_box(CartPole::new().expect("the cartpole model loads"));
    let cfg = RunConfig {
        clock: ClockKind::Virtual,
        ..RunConfig::default()
    };
    for _ in 0..n {
        if mode == "bare" {
            let mut plant = CartPole::new().expect("the cartpole model loads");
            plant.reset(0);
            let mut brain = Scripted;
            for _ in 0..501 {
                let a = brain.act(&plant.observe());
                black_box(plant.step(a[0]));
            }
        } else {
            let opts = RunOptions {
                keep_trace: false,
                ..RunOptions::default()
            };
            black_box(run(&cfg, Box::new(Scripted), opts).expect("the run starts"));
        }
    }
}
