//! `ratelab bench`: the real clock's timing quality — per-node tick lateness (p50/p99/max)
//! and CPU per node — with every node of the graph at one rate.

use crate::cli::BenchArgs;
use ratelab::config::duration_from_secs;
use ratelab::policy::Scripted;
use ratelab::scheduler::StopFlag;
use ratelab::{run, ClockKind, Nanos, RunConfig, RunOptions};

/// Run the benchmark and print one table row per node and rate.
pub fn run_bench(a: &BenchArgs, stop: StopFlag) -> anyhow::Result<()> {
    println!(
        "real-clock timing: every node at one rate, {} s each, spin margin {} µs, {} cores",
        a.duration,
        a.spin_margin_us,
        std::thread::available_parallelism().map_or(1, |n| n.get())
    );
    println!(
        "{:>8}  {:<8} {:>7} {:>9} {:>9} {:>9} {:>9} {:>8}",
        "rate Hz", "node", "ticks", "p50 µs", "p99 µs", "max µs", "cpu %", "skipped"
    );
    for &hz in &a.hz {
        let cfg = RunConfig {
            clock: ClockKind::Real,
            duration: duration_from_secs(a.duration)?,
            sensor_hz: hz,
            control_hz: hz,
            actuator_hz: hz,
            spin_margin: Nanos(a.spin_margin_us * 1_000),
            ..RunConfig::default()
        };
        let opts = RunOptions {
            stop: stop.clone(),
            keep_trace: false,
            ..RunOptions::default()
        };
        let report = run(&cfg, Box::new(Scripted), opts)?;
        for t in report.metrics.node_timing.iter().flatten() {
            let cpu_pct = 100.0 * t.cpu_ms / (report.wall.as_secs_f64() * 1e3);
            println!(
                "{:>8}  {:<8} {:>7} {:>9.1} {:>9.1} {:>9.1} {:>9.2} {:>8}",
                hz,
                t.node,
                t.ticks,
                t.lateness_p50_us,
                t.lateness_p99_us,
                t.lateness_max_us,
                cpu_pct,
                t.skipped
            );
        }
        if !report.metrics.balanced {
            println!(
                "          (the pole fell at t={:?} s; timing covers the run until then)",
                report.metrics.fell_at_s
            );
        }
        if stop.is_stopped() {
            break;
        }
    }
    Ok(())
}
