//! The headless run: one graph, the chapter's summary, optional metrics.json and trace.csv.

use crate::cli::{GraphArgs, RunArgs};
use anyhow::Context;
use indicatif::{ProgressBar, ProgressStyle};
use ratelab::config::{phase_offset_from_ms, BREAK_CONTROL_HZ};
use ratelab::graph::GraphSpec;
use ratelab::metrics::StepRecord;
use ratelab::recording::{check_output_path, default_path, RecordOptions, Recording};
use ratelab::scheduler::{EndReason, StopFlag};
use ratelab::{run, ClockKind, Nanos, RunConfig, RunOptions, RunReport};
use std::io::{IsTerminal, Write};
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::time::Duration;

/// Headless runs last this long unless `--duration` says otherwise, s.
pub const DEFAULT_DURATION_S: f64 = 10.0;

/// The graph the flags name (`--graph`, default the chapter's), with `--rate` and
/// `--depth` applied.
pub fn graph_from_args(g: &GraphArgs) -> anyhow::Result<GraphSpec> {
    let mut spec = match &g.graph {
        Some(path) => GraphSpec::load(path)?,
        None => GraphSpec::chapter(),
    };
    for (node, hz) in &g.rates {
        spec.set_rate(node, *hz)
            .map_err(|e| anyhow::anyhow!("--rate {node}={hz}: {e}"))?;
    }
    for (topic, depth) in &g.depths {
        spec.set_depth(topic, *depth)
            .map_err(|e| anyhow::anyhow!("--depth {topic}={depth}: {e}"))?;
    }
    Ok(spec)
}

/// The run settings the flags describe (`--smoke` and `--break` applied).
pub fn config_from_args(a: &RunArgs) -> anyhow::Result<RunConfig> {
    let mut cfg = RunConfig {
        seed: a.seed,
        duration: ratelab::config::duration_from_secs(a.duration.unwrap_or(DEFAULT_DURATION_S))?,
        graph: graph_from_args(&a.graph)?,
        clock: a.clock,
        spin_margin: Nanos(a.spin_margin_us.saturating_mul(1_000)),
        rt_priority: a.rt_priority,
        ..RunConfig::default()
    };
    if let Some(hz) = a.sensor_hz {
        cfg.set_sensor_hz(hz)?;
    }
    match (a.break_, a.control_hz) {
        (true, _) => cfg.set_control_hz(BREAK_CONTROL_HZ)?,
        (false, Some(hz)) => cfg.set_control_hz(hz)?,
        (false, None) => {}
    }
    if let Some(depth) = a.queue_depth {
        cfg.set_queue_depth(depth)?;
    }
    if !a.phase_offset_ms.is_empty() {
        let nodes = cfg.graph.node_names();
        anyhow::ensure!(
            a.phase_offset_ms.len() == nodes.len(),
            "--phase-offset-ms takes one value per node ({} for graph '{}': {}), got {}",
            nodes.len(),
            cfg.graph.name,
            nodes.join(", "),
            a.phase_offset_ms.len()
        );
        cfg.phase_offsets = a
            .phase_offset_ms
            .iter()
            .map(|&ms| phase_offset_from_ms(ms))
            .collect::<Result<_, _>>()?;
    }
    if a.smoke {
        cfg.clock = ClockKind::Virtual;
        cfg.duration = Nanos(2 * Nanos::SECOND.0);
    }
    cfg.validate()?;
    Ok(cfg)
}

/// Run headless and print the summary. Returns the report.
pub fn run_headless(a: &RunArgs, stop: StopFlag) -> anyhow::Result<RunReport> {
    let cfg = config_from_args(a)?;
    let brain = ratelab::checkpoint::load_policy(&a.policy)?;
    if let Some(dir) = &a.out {
        std::fs::create_dir_all(dir)
            .with_context(|| format!("cannot create --out folder {}", dir.display()))?;
    }
    let bar = (cfg.clock == ClockKind::Real && std::io::stdout().is_terminal()).then(|| {
        let bar = ProgressBar::new(cfg.duration.0 / 1_000_000);
        bar.set_style(
            ProgressStyle::with_template("{spinner} real clock [{bar:40}] {pos}/{len} ms run time")
                .expect("static template")
                .progress_chars("=> "),
        );
        bar.enable_steady_tick(Duration::from_millis(100));
        bar
    });
    let ticker = bar.clone().map(|bar| {
        let stop = stop.clone();
        std::thread::spawn(move || {
            let start = std::time::Instant::now();
            while !stop.is_stopped() && !bar.is_finished() {
                bar.set_position(start.elapsed().as_millis() as u64);
                std::thread::sleep(Duration::from_millis(50));
            }
        })
    });
    let recording = open_recording(a, &cfg, &brain.label())?;
    let mut opts = RunOptions {
        stop: stop.clone(),
        ..RunOptions::new()
    };
    if let Some(r) = &recording {
        opts.observers.push(r.observer());
        let r = r.clone();
        opts.on_node_tick = Some(Arc::new(move |_, node, now, late| {
            r.node_tick(node, now, late)
        }));
    }
    let report = run(&cfg, brain, opts)?;
    if let Some(r) = &recording {
        match r.finish(&report.metrics, &report.end) {
            // With --spawn the flush also waits for the live viewer; one that could not start
            // (no display) or went away costs neither the file nor the summary.
            Err(e) if a.spawn => {
                eprintln!("[ratelab] warning: live viewer: {e} (the file is written)")
            }
            other => other?,
        }
    }
    if let Some(bar) = bar {
        bar.finish_and_clear();
    }
    if let Some(t) = ticker {
        let _ = t.join();
    }
    print_summary(&report);
    if cfg.rt_priority.is_some() && cfg.clock == ClockKind::Virtual {
        eprintln!("[ratelab] note: --rt-priority applies to the real clock only; ignored");
    }
    if let Some(w) = report.metrics.sched_warning() {
        eprintln!("[ratelab] warning: {w}");
    }
    if let Some(dir) = &a.out {
        write_outputs(dir, &report, &cfg.graph)?;
    }
    if let Some(r) = &recording {
        println!("[ratelab] recording: {}", r.path().display());
        println!("[ratelab] open it with: rerun {}", r.path().display());
    }
    Ok(report)
}

/// The `--record`/`--spawn` recording, checked and opened before the run starts.
pub fn open_recording(
    a: &RunArgs,
    cfg: &RunConfig,
    policy: &str,
) -> anyhow::Result<Option<Recording>> {
    if a.record.is_none() && !a.spawn {
        return Ok(None);
    }
    let path: PathBuf = match a.record.clone().flatten() {
        Some(p) => p,
        None => default_path(Path::new("recordings"), cfg),
    };
    check_output_path(&path, a.force)?;
    let (recording, notice) =
        Recording::create(&path, cfg, policy, &RecordOptions { spawn: a.spawn })?;
    if let Some(n) = notice {
        eprintln!("[ratelab] {n}");
    }
    Ok(Some(recording))
}

/// The chapter's summary, one `[ratelab]` line each, on stdout.
pub fn print_summary(report: &RunReport) {
    let mut out = std::io::stdout().lock();
    for line in report
        .metrics
        .summary_lines(Some(report.wall.as_secs_f64()))
    {
        let _ = writeln!(out, "[ratelab] {line}");
    }
    match &report.end.reason {
        EndReason::Interrupted => {
            let _ = writeln!(
                out,
                "[ratelab] interrupted at t={:.2}s",
                report.end.at.as_secs_f64()
            );
        }
        reason @ EndReason::NodeFailed { .. } => {
            let _ = writeln!(out, "[ratelab] {reason}");
        }
        _ => {}
    }
}

/// `metrics.json` (pretty, stable key order) and `trace.csv` (one row per actuator tick).
pub fn write_outputs(dir: &Path, report: &RunReport, graph: &GraphSpec) -> anyhow::Result<()> {
    let json = serde_json::to_string_pretty(&report.metrics)? + "\n";
    let path = dir.join("metrics.json");
    std::fs::write(&path, json).with_context(|| format!("cannot write {}", path.display()))?;
    write_trace(&dir.join("trace.csv"), &report.trace, graph)
}

/// One row per actuator tick; per topic (in the graph's topic order) a `<topic>_published`
/// and `<topic>_dropped` column (`/obs` → `obs_published`), as the chapter's trace has.
fn write_trace(path: &Path, trace: &[StepRecord], graph: &GraphSpec) -> anyhow::Result<()> {
    let mut w =
        csv::Writer::from_path(path).with_context(|| format!("cannot write {}", path.display()))?;
    let mut header: Vec<String> = [
        "step",
        "t_ns",
        "pole_angle",
        "cart_pos",
        "action",
        "latency_ns",
        "nonfinite",
    ]
    .map(String::from)
    .to_vec();
    for t in &graph.topics {
        let name = ratelab::recording::bus_name(&t.name);
        header.push(format!("{name}_published"));
        header.push(format!("{name}_dropped"));
    }
    header.push("fell".into());
    w.write_record(&header)?;
    for r in trace {
        let mut row = vec![
            r.step.to_string(),
            r.t.0.to_string(),
            format!("{:e}", r.pole_angle),
            format!("{:e}", r.cart_pos),
            format!("{:e}", r.action),
            r.latency.map_or_else(String::new, |l| l.0.to_string()),
            r.nonfinite.to_string(),
        ];
        for t in r.topics.as_slice() {
            row.push(t.published.to_string());
            row.push(t.dropped.to_string());
        }
        row.push(r.fell.to_string());
        w.write_record(&row)?;
    }
    w.flush()?;
    Ok(())
}
