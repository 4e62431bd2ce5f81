//! The `ratelab` binary: ratelab's command line with the built-in node kinds and message
//! types ([`ratelab_lab::main_with`]).

fn main() -> std::process::ExitCode {
    ratelab_lab::main_with(|| {})
}
