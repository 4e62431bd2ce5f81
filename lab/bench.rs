//! `ratelab bench`: the real clock's timing quality — per-node tick lateness (p50/p99/max)
//! and CPU per node — with every node of the graph at one rate; and what a call into
//! Python costs per tick. `--render` times the lab's frames, `--scrub` its time scrubbing.

use crate::cli::BenchArgs;
use ratelab::graph::nodes::GraphNode;
use ratelab::ids::NodeId;
use ratelab::metrics::NodeTiming;
use ratelab::policy::Scripted;
use ratelab::rate::Rate;
use ratelab::run_spec::{GraphSettings, RunSpec};
use ratelab::scheduler::{run_real, RealOptions, StopFlag};
use ratelab::setting::Speech;
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
        "lab frame at 120x40 (view model + draw), {frames} frames: {}",
        spread(&times)
    );
    Ok(())
}

/// `mean … | p50 … | p99 … | max …` of timings.
fn spread(t: &ratelab::metrics::LatencyStats) -> String {
    format!(
        "mean {} | p50 {} | p99 {} | max {}",
        Nanos(t.mean().unwrap_or(0.0) as u64),
        t.quantile(0.5).unwrap_or_default(),
        t.quantile(0.99).unwrap_or_default(),
        t.max().unwrap_or_default()
    )
}

/// How often, in run time, the scrub bench tells the lab the engine's status: the lab's 30 a
/// second at about ×1.7.
pub(crate) const STATUS_EVERY: Nanos = Nanos(50 * Nanos::MILLISECOND.0);

/// The engine's status at step `s` of the chapter's graph run with the scripted brain as
/// set out (every node at 50 Hz, each topic at depth 1 with the default QoS), with the
/// step's topic counters: what a lab is told beside the steps.
pub(crate) fn chapter_status(s: &ratelab::runlog::StepRecord) -> ratelab::session::Telemetry {
    ratelab::session::Telemetry::Status {
        now: s.t,
        paused: false,
        speed: ratelab::session::Speed::Times(1.0),
        rates: vec![50.0; 3],
        depths: vec![1, 1],
        qos: vec![ratelab::qos::TopicQos::default(); 2],
        alive: vec![None; 3],
        policy: "scripted".into(),
        exec: None,
        topics: Some(Box::new(s.topics.clone())),
    }
}

/// Time reaching instants of a 10-minute virtual run of the chapter's graph (a quarter of
/// them in its last minute) as the lab's time scrubbing does, in its two halves: the
/// engine's seek of the run core (restore the capture kept at or before the instant, one a
/// second as the lab keeps them, and run on to it, the step telemetry muted), and the lab's
/// fold of what the run told it up to the instant (its steps, and a status every 50 ms of
/// run time: the lab's 30 a second at about ×1.7), from the lab's nearest checkpoint of its
/// folded view (`tui/app/checkpoints.rs`).
pub fn scrub_bench(seeks: usize) -> anyhow::Result<()> {
    use crate::tui::app::App;
    use ratelab::runcore::{CoreOptions, RunCore, HISTORY_EVERY};
    use ratelab::session::{Speed, Telemetry};
    let cfg = RunConfig {
        clock: ClockKind::Virtual,
        duration: Nanos(600 * Nanos::SECOND.0),
        ..RunConfig::default()
    };
    // What the run tells the lab: its steps (a run that keeps them) …
    let trace = run(
        &cfg,
        Box::new(Scripted),
        RunOptions {
            keep_trace: true,
            ..RunOptions::default()
        },
    )?
    .trace;
    // … and the engine's core, which keeps none, as the lab's does not.
    let mut core = RunCore::new(
        &cfg,
        Box::new(Scripted),
        CoreOptions {
            history_every: Some(HISTORY_EVERY),
            ..CoreOptions::default()
        },
    )?;
    core.run_until(cfg.duration);
    let last = core.now();
    // The lab told the whole run.
    let (tx, _controls) = crossbeam_channel::unbounded();
    let mut app = App::new(tx, "scripted".into(), None, Speed::Times(1.0));
    app.on_telemetry(Telemetry::Started {
        cfg: cfg.clone(),
        policy: "scripted".into(),
        recording: None,
    });
    let mut next_status = Nanos::ZERO;
    let mut told = 1usize;
    for s in &trace {
        app.on_telemetry(Telemetry::Step(Box::new(s.clone())));
        told += 1;
        if s.t >= next_status {
            app.on_telemetry(chapter_status(s));
            told += 1;
            next_status = s.t.saturating_add(STATUS_EVERY);
        }
    }
    let (mut engine, mut lab) = (
        ratelab::metrics::LatencyStats::default(),
        ratelab::metrics::LatencyStats::default(),
    );
    let mut k = 0u64;
    for i in 0..seeks {
        // Spread over the run, none on a capture; every fourth in the last minute.
        k = (k + 7_919) % 599_000;
        let ms = if i % 4 == 3 { 540_000 + k % 59_000 } else { k } + 500;
        let at = Nanos(ms * Nanos::MILLISECOND.0).min(last);
        let start = std::time::Instant::now();
        core.seek(at)?;
        engine.record(Nanos::from(start.elapsed()));
        let start = std::time::Instant::now();
        app.on_telemetry(Telemetry::Rewound { at: core.now() });
        lab.record(Nanos::from(start.elapsed()));
        // Back to the end, as the lab would be told it again (not timed).
        core.seek(last)?;
        for s in trace.iter().filter(|s| s.t > at) {
            app.on_telemetry(Telemetry::Step(Box::new(s.clone())));
        }
    }
    let row = |what: &str, t: &ratelab::metrics::LatencyStats| println!("{what}: {}", spread(t));
    println!(
        "reaching an instant of a 10-minute virtual run ({seeks} seeks; the lab told {told} messages):"
    );
    row("  engine: restore + run on (run core)", &engine);
    row("  lab: fold the journal up to it", &lab);
    Ok(())
}

/// One table row: a node's tick timing at `hz`, CPU as a share of `wall`, its name in a
/// column `name_w` characters wide (the longest name's).
fn print_row(hz: f64, t: &NodeTiming, wall: Duration, name_w: usize) {
    println!(
        "{:>8}  {:<name_w$} {:>7} {:>9.1} {:>9.1} {:>9.1} {:>9.2} {:>8}  {}",
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
    if a.scrub {
        return scrub_bench(100);
    }
    // What every timing run shares, by a run's own rules (RunSpec): the graph and its
    // overrides, the real clock, the duration and the priority. Faults are refused: a
    // stalled tick still counts as a tick here, so the table would not show them.
    let base = RunSpec {
        graph: GraphSettings::from(&a.graph),
        clock: ClockKind::Real,
        duration_s: Some(a.duration),
        rt_priority: a.rt_priority,
        ..RunSpec::default()
    }
    .config(Speech::Flags)?;
    crate::headless::warn_qos(&base.graph);
    if !base.faults.is_empty() {
        anyhow::bail!(
            "--stall/--kill: the bench times every tick, a faulted one too, so its table would not show them; use `ratelab run` or `ratelab lab` with them"
        );
    }
    if let Some((node, _)) = a.graph.rates.first() {
        anyhow::bail!(
            "--rate {node}=…: the bench runs every node at each --hz, so a node's own rate would not be timed; give the rates to time with --hz"
        );
    }
    let duration = base.duration;
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
    // What a Python brain or node adds to a tick (docs/python.md): its call, measured here.
    match ratelab::python::brain::call_cost(20_000) {
        Ok((p50, p99)) => println!(
            "Python: an empty brain's call (obs to NumPy, act(obs), the float back) costs p50 {:.1} µs, p99 {:.1} µs over 20000 calls; Python nodes share one interpreter lock",
            p50 as f64 / 1e3,
            p99 as f64 / 1e3
        ),
        Err(e) => println!("Python: not measured ({e})"),
    }
    // The margin each rate is timed with, as used.
    let margins: Vec<String> = (a.hz.iter())
        .map(|&hz| {
            let us = Rate::new(hz).map_or(0, |r| margin_for(r.period()).0 / 1_000);
            format!("{us} µs at {hz} Hz")
        })
        .collect();
    println!(
        "real-clock timing (p50/p99/max: how late each tick started past its deadline): every node at one rate{}, {} s each, spin margin {}{}, {} cores",
        if a.stagger { ", staggered by P/n" } else { "" },
        a.duration,
        margins.join(", "),
        match a.spin_margin_us {
            None => format!(
                " ({} µs, at most P/2)",
                ratelab::rate::DEFAULT_SPIN_MARGIN.0 / 1_000
            ),
            Some(_) => String::new(),
        },
        ratelab::sweep_spec::threads()
    );
    // The node column as wide as the longest name (the bare wait's, 9, at least 10).
    let name_w = (base.graph.nodes.iter())
        .map(|n| n.name.chars().count())
        .max()
        .unwrap_or(0)
        .max(10);
    println!(
        "{:>8}  {:<name_w$} {:>7} {:>9} {:>9} {:>9} {:>9} {:>8}  policy",
        "rate Hz", "node", "ticks", "p50 µs", "p99 µs", "max µs", "cpu %", "skipped"
    );
    for &hz in &a.hz {
        let rate = Rate::new(hz)?;
        let period = rate.period();
        let spin_margin = margin_for(period);
        let floor = run_real(
            // The bare wait: a node with no work, so that `run_real` alone, with the same
            // waiter, margin and policy as the graph's nodes, measures the machine's floor.
            vec![GraphNode::idle("bare wait", NodeId(0), rate)],
            duration,
            &stop,
            &RealOptions {
                spin_margin,
                rt_priority: a.rt_priority,
                ..RealOptions::default()
            },
        );
        for t in &floor.timing {
            print_row(hz, t, Duration::from_nanos(duration.0), name_w);
        }
        // Every node at `hz`, the actuator too: a timing run, not a physical one (the
        // plant still steps 20 ms per actuator tick), so the graph file's 50 Hz rule for
        // the actuator is deliberately set aside here, after the settings' rules.
        let mut cfg = base.clone();
        for n in &mut cfg.graph.nodes {
            n.rate_hz = hz;
        }
        let count = cfg.graph.nodes.len() as u64;
        cfg.spin_margin = spin_margin;
        cfg.phase_offsets = if a.stagger {
            (0..count).map(|i| Nanos(i * period.0 / count)).collect()
        } else {
            Vec::new()
        };
        let opts = RunOptions {
            stop: stop.clone(),
            keep_trace: false,
            ..RunOptions::default()
        };
        let report = run(&cfg, Box::new(Scripted), opts)?;
        for t in report.metrics.node_timing.iter().flatten() {
            print_row(hz, t, report.wall, name_w);
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
