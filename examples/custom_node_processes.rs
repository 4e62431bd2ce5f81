//! A program with a node kind of its own gets ratelab's whole command line with it: this one
//! registers the PD controller of `examples/custom_node.rs` as `kind = "pd"` and hands over
//! to [`ratelab_lab::main_with`]. Every front end then knows the kind — the lab, `run`,
//! `sweep`, `cliff`, `exercise`, `bench`, `replay`, `kinds` — and `launch --processes` starts
//! each process as **this program** again (a `ratelab` binary would not know the kind):
//!
//! ```sh
//! cargo run --release --example custom_node_processes -- lab --graph examples/cartpole-pd.toml
//! cargo run --release --example custom_node_processes -- \
//!     launch --processes --clock virtual --graph examples/cartpole-pd.toml
//! cargo run --release --example custom_node_processes -- kinds
//! ```
//!
//! Under the virtual clock the launch across processes (`robot` [sensor, actuator] and
//! `policy` [policy], the graph file's placement) gives the same graph's one-process run byte
//! for byte (`tests/it/custom_node.rs` checks it).

#[path = "common/pd.rs"]
mod pd;

fn main() -> std::process::ExitCode {
    ratelab_lab::main_with(pd::register_pd)
}
