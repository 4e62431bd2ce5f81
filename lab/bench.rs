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

/// The machine's own floor at `hz`: one thread, no node and no other thread of ours, waiting
/// for the same absolute deadlines with the same waiter (spin margin, policy) for `duration`.
/// Returns (p50, p99, max) lateness, the thread's CPU share in % and its policy.
fn bare_wait(
    hz: f64,
    duration: Nanos,
    spin_margin: Nanos,
    rt_priority: Option<u8>,
    stop: &StopFlag,
) -> anyhow::Result<(Nanos, Nanos, Nanos, f64, String)> {
    use ratelab::clock::{Clock, MonotonicClock};
    use ratelab::rate::{next_deadline, period_for_hz, DeadlineWaiter};
    let period = period_for_hz(hz)?;
    let stop = stop.clone();
    let handle = std::thread::spawn(move || {
        if let Some(p) = rt_priority {
            // A refusal shows in the policy printed beside the row.
            let _ = ratelab::realtime::set_current_thread_fifo(p);
        }
        let sched = ratelab::realtime::current_thread_sched().to_string();
        let waiter = DeadlineWaiter::new(spin_margin);
        let cpu0 = ratelab::scheduler::thread_cpu_time();
        let clock = MonotonicClock::start();
        let mut lateness = ratelab::metrics::LatencyStats::default();
        let mut deadline = Nanos::ZERO;
        while !stop.is_stopped() {
            waiter.wait_until(clock.instant_at(deadline));
            let now = clock.now();
            if now >= duration {
                break;
            }
            lateness.record(now.saturating_sub(deadline));
            deadline = next_deadline(deadline, now, period).0;
        }
        let cpu = ratelab::scheduler::thread_cpu_time().saturating_sub(cpu0);
        let cpu_pct = 100.0 * cpu.as_secs_f64() / duration.as_secs_f64();
        (lateness, cpu_pct, sched)
    });
    let (lateness, cpu_pct, sched) = handle
        .join()
        .map_err(|_| anyhow::anyhow!("the bare-wait thread panicked"))?;
    Ok((
        lateness.quantile(0.5).unwrap_or_default(),
        lateness.quantile(0.99).unwrap_or_default(),
        lateness.max().unwrap_or_default(),
        cpu_pct,
        sched,
    ))
}

/// Run the benchmark and print one table row per node and rate, after a row for the bare
/// wait (the machine's floor, measured just before the graph in the same run).
pub fn run_bench(a: &BenchArgs, stop: StopFlag) -> anyhow::Result<()> {
    if a.render {
        return render_bench(2000);
    }
    let spin_margin = Nanos(a.spin_margin_us * 1_000);
    let duration = duration_from_secs(a.duration)?;
    println!(
        "real-clock timing: every node at one rate{}, {} s each, spin margin {} µs, {} cores",
        if a.stagger { ", staggered by P/3" } else { "" },
        a.duration,
        a.spin_margin_us,
        std::thread::available_parallelism().map_or(1, |n| n.get())
    );
    println!(
        "{:>8}  {:<10} {:>7} {:>9} {:>9} {:>9} {:>9} {:>8}  policy",
        "rate Hz", "node", "ticks", "p50 µs", "p99 µs", "max µs", "cpu %", "skipped"
    );
    for &hz in &a.hz {
        let (p50, p99, max, cpu_pct, sched) =
            bare_wait(hz, duration, spin_margin, a.rt_priority, &stop)?;
        println!(
            "{:>8}  {:<10} {:>7} {:>9.1} {:>9.1} {:>9.1} {:>9.2} {:>8}  {}",
            hz,
            "bare wait",
            "",
            p50.as_micros_f64(),
            p99.as_micros_f64(),
            max.as_micros_f64(),
            cpu_pct,
            "",
            sched
        );
        let cfg = RunConfig {
            clock: ClockKind::Real,
            duration,
            sensor_hz: hz,
            control_hz: hz,
            actuator_hz: hz,
            spin_margin,
            rt_priority: a.rt_priority,
            phase_offsets: if a.stagger {
                let p = ratelab::rate::period_for_hz(hz)?;
                [Nanos::ZERO, Nanos(p.0 / 3), Nanos(2 * p.0 / 3)]
            } else {
                [Nanos::ZERO; 3]
            },
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
                "{:>8}  {:<10} {:>7} {:>9.1} {:>9.1} {:>9.1} {:>9.2} {:>8}  {}",
                hz,
                t.node,
                t.ticks,
                t.lateness_p50_us,
                t.lateness_p99_us,
                t.lateness_max_us,
                cpu_pct,
                t.skipped,
                t.sched
            );
        }
        if let Some(w) = report.metrics.sched_warning() {
            eprintln!("[ratelab] warning: {w}");
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
