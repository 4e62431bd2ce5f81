//! `ratelab bench`: the real clock's timing quality — per-node tick lateness (p50/p99/max)
//! and CPU per node — with every node of the graph at one rate; and what a call into
//! Python costs per tick.

use crate::cli::BenchArgs;
use ratelab::config::duration_from_secs;
use ratelab::metrics::NodeTiming;
use ratelab::node::{Flow, Node};
use ratelab::policy::Scripted;
use ratelab::rate::Rate;
use ratelab::scheduler::{run_real, RealOptions, StopFlag};
use ratelab::{run, ClockKind, Nanos, RunConfig, RunOptions};
use std::time::Duration;

/// Time `frames` renders of the lab at 120×40 fed with a 5 Hz virtual run (a dropping
/// /obs, a full histogram and chart): building the view model and drawing it.
pub fn render_bench(frames: usize) -> anyhow::Result<()> {
    use crate::tui::app::App;
    use ratatui::backend::TestBackend;
    use ratatui::Terminal;
    let mut cfg = RunConfig {
        clock: ClockKind::Virtual,
        ..RunConfig::default()
    };
    cfg.set_control_hz(8.0)?;
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

/// The bare wait: a node with no work, so that [`run_real`] alone, with the same waiter,
/// margin and policy as the graph's nodes, measures the machine's own floor.
struct BareWait(Rate);

impl Node for BareWait {
    fn name(&self) -> &str {
        "bare wait"
    }
    fn priority(&self) -> u32 {
        0
    }
    fn rate(&self) -> &Rate {
        &self.0
    }
    fn tick(&mut self, _now: Nanos) -> Flow {
        Flow::Continue
    }
}

/// One table row: a node's tick timing at `hz`, CPU as a share of `wall`.
fn print_row(hz: f64, t: &NodeTiming, wall: Duration) {
    println!(
        "{:>8}  {:<10} {:>7} {:>9.1} {:>9.1} {:>9.1} {:>9.2} {:>8}  {}",
        hz,
        t.node,
        t.ticks,
        t.lateness_p50_us,
        t.lateness_p99_us,
        t.lateness_max_us,
        100.0 * t.cpu_ms / (wall.as_secs_f64() * 1e3),
        t.skipped,
        t.sched
    );
}

/// Run the benchmark and print one table row per node and rate, after a row for the bare
/// wait (the machine's floor, measured just before the graph in the same run).
pub fn run_bench(a: &BenchArgs, stop: StopFlag) -> anyhow::Result<()> {
    if a.render {
        return render_bench(2000);
    }
    let duration = duration_from_secs(a.duration)?;
    let graph = crate::headless::graph_from_args(&a.graph)?;
    if let Some(us) = a.spin_margin_us {
        for &hz in &a.hz {
            let period = Rate::new(hz)?.period();
            if Nanos(us.saturating_mul(1_000)) >= period {
                anyhow::bail!(
                    "--spin-margin-us must be below every node's period (here {} µs, at --hz {hz}), got {us}",
                    period.0 / 1_000
                );
            }
        }
    }
    // Asked for, or the default capped at half the period (never a whole period spun).
    let margin_for = |period: Nanos| match a.spin_margin_us {
        Some(us) => Nanos(us.saturating_mul(1_000)),
        None => ratelab::rate::DEFAULT_SPIN_MARGIN.min(Nanos(period.0 / 2)),
    };
    println!(
        "real-clock timing: every node at one rate{}, {} s each, spin margin {} µs, {} cores",
        if a.stagger { ", staggered by P/n" } else { "" },
        a.duration,
        a.spin_margin_us.map_or_else(
            || format!(
                "{} (at most P/2)",
                ratelab::rate::DEFAULT_SPIN_MARGIN.0 / 1_000
            ),
            |us| us.to_string()
        ),
        std::thread::available_parallelism().map_or(1, |n| n.get())
    );
    println!(
        "{:>8}  {:<10} {:>7} {:>9} {:>9} {:>9} {:>9} {:>8}  policy",
        "rate Hz", "node", "ticks", "p50 µs", "p99 µs", "max µs", "cpu %", "skipped"
    );
    // What a Python brain or node adds to a tick (docs/python.md): its call, measured here.
    match ratelab::python::brain::call_cost(20_000) {
        Ok((p50, p99)) => println!(
            "Python: an empty brain's call (obs to NumPy, act(obs), the float back) costs p50 {:.1} µs, p99 {:.1} µs over 20000 calls; Python nodes share one interpreter lock",
            p50 as f64 / 1e3,
            p99 as f64 / 1e3
        ),
        Err(e) => println!("Python: not measured ({e})"),
    }
    for &hz in &a.hz {
        let rate = Rate::new(hz)?;
        let period = rate.period();
        let spin_margin = margin_for(period);
        let floor = run_real(
            vec![Box::new(BareWait(rate))],
            duration,
            &stop,
            &RealOptions {
                spin_margin,
                rt_priority: a.rt_priority,
                ..RealOptions::default()
            },
        );
        for t in &floor.timing {
            print_row(hz, t, Duration::from_nanos(duration.0));
        }
        // Every node at `hz`, the actuator too: a timing run, not a physical one (the
        // plant still steps 20 ms per actuator tick), so the graph file's 50 Hz rule for
        // the actuator is deliberately set aside here.
        let mut graph = graph.clone();
        for n in &mut graph.nodes {
            n.rate_hz = hz;
        }
        let count = graph.nodes.len() as u64;
        let cfg = RunConfig {
            clock: ClockKind::Real,
            duration,
            graph,
            spin_margin,
            rt_priority: a.rt_priority,
            phase_offsets: if a.stagger {
                (0..count).map(|i| Nanos(i * period.0 / count)).collect()
            } else {
                Vec::new()
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
            print_row(hz, t, report.wall);
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
