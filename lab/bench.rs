//! `ratelab bench`: the real clock's timing quality — per-node tick lateness (p50/p99/max)
//! and CPU per node — with every node of the graph at one rate.

use crate::cli::BenchArgs;
use ratelab::config::duration_from_secs;
use ratelab::policy::Scripted;
use ratelab::scheduler::StopFlag;
use ratelab::{run, ClockKind, Nanos, RunConfig, RunOptions};

/// Time `frames` renders of the lab at 120×40 fed with a 5 Hz virtual run (a dropping
/// /obs, a full histogram and chart): building the view model and drawing it.
pub fn render_bench(frames: usize) -> anyhow::Result<()> {
    use crate::tui::app::App;
    use ratatui::backend::TestBackend;
    use ratatui::Terminal;
    let cfg = RunConfig {
        clock: ClockKind::Virtual,
        control_hz: 8.0,
        ..RunConfig::default()
    };
    let (app, _controls) = App::after_virtual_run(cfg, false)?;
    let mut terminal = Terminal::new(TestBackend::new(120, 40))?;
    let mut times = ratelab::metrics::LatencyStats::default();
    for _ in 0..frames {
        let start = std::time::Instant::now();
        let view = app.view();
        terminal.draw(|f| f.render_widget(&view, f.area()))?;
        times.record(Nanos::from(start.elapsed()));
    }
    println!(
        "lab frame at 120x40 (view model + draw), {frames} frames: mean {} | p50 {} | p99 {} | max {}",
        Nanos(times.mean().unwrap_or(0.0) as u64),
        times.quantile(0.5).unwrap_or_default(),
        times.quantile(0.99).unwrap_or_default(),
        times.max().unwrap_or_default()
    );
    Ok(())
}

/// Run the benchmark and print one table row per node and rate.
pub fn run_bench(a: &BenchArgs, stop: StopFlag) -> anyhow::Result<()> {
    if a.render {
        return render_bench(2000);
    }
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
