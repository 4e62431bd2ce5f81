//! `ratelab sweep` (a parameter grid to CSV/JSON with a plot) and `ratelab cliff`: their
//! flags read as the library's [`SweepSpec`] and [`CliffSpec`] (whose rules and runs these
//! are, as `ratelab.sweep` and `ratelab.cliff`'s in Python), and here what the terminal shows
//! and the files written: tables, progress bars, plots.

use crate::cli::{CliffArgs, SweepArgs};
use indicatif::{ProgressBar, ProgressStyle};
use ratelab::metrics::Metrics;
use ratelab::scheduler::StopFlag;
use ratelab::setting::Speech;
use ratelab::sweep::{run_grid, run_grid_until, write_csv, BrainFactory, Cliff, Grid, Point};
use ratelab::sweep_spec::{brain_factory, threads, CliffSpec, SweepSpec};
use ratelab::{ClockKind, RunConfig};
use std::io::IsTerminal;

/// A progress bar on stderr (when it is a terminal), redrawn every 200 ms so that even a
/// run of many seconds shows the time going by.
pub fn progress_bar(total: usize, unit: &str) -> Option<ProgressBar> {
    std::io::stderr().is_terminal().then(|| {
        let bar = ProgressBar::new(total as u64);
        bar.set_style(
            ProgressStyle::with_template(&format!(
                "{{spinner}} [{{bar:40}}] {{pos}}/{{len}} {unit}, {{elapsed}} (about {{eta}} left)"
            ))
            .expect("static template")
            .progress_chars("=> "),
        );
        bar.enable_steady_tick(std::time::Duration::from_millis(200));
        bar
    })
}

/// Run a sweep and print/write its table.
/// Ctrl-C (`stop`) ends the run in progress at once and prints what completed.
pub fn run_sweep(a: &SweepArgs, stop: &StopFlag) -> anyhow::Result<()> {
    for p in [&a.csv, &a.json].into_iter().flatten() {
        ratelab::output::check_writable(p, a.force)?; // refuse before hours of runs, not after
    }
    let rows = sweep_rows(a, stop)?;
    print_table(&rows);
    println!();
    if std::io::stdout().is_terminal() {
        draw_chart(&rows)?;
    } else {
        print_plot(&rows);
    }
    if let Some(p) = &a.csv {
        ratelab::output::write_with(p, a.force, |w| {
            write_csv(w, &rows).map_err(std::io::Error::other)
        })?;
        println!("wrote {}", p.display());
    }
    if let Some(p) = &a.json {
        let items: Vec<_> = rows
            .iter()
            .map(|(p, m)| serde_json::json!({ "point": p, "metrics": m }))
            .collect();
        let json = serde_json::to_string_pretty(&items)? + "\n";
        ratelab::output::write_file(p, a.force, json.as_bytes())?;
        println!("wrote {}", p.display());
    }
    // A sweep whose runs failed a node is no success.
    match ratelab::sweep::failed_line(&rows) {
        Some(line) => Err(anyhow::anyhow!(line)),
        None => Ok(()),
    }
}

/// The sweep `a` asks for ([`SweepSpec`]), run on every core until `stop`, a progress bar on
/// a terminal: one row per point of its grid that ran.
///
/// # Errors
/// Bad settings, a brain that cannot be loaded, a run that cannot start.
fn sweep_rows(a: &SweepArgs, stop: &StopFlag) -> anyhow::Result<Vec<(Point, Metrics)>> {
    let spec = SweepSpec::from(a);
    let brain = brain_factory(&spec.base.policy)?;
    let grid = spec.grid(Speech::Flags)?;
    crate::headless::warn_qos(&grid.base.graph);
    let total = grid.points().len();
    let bar = progress_bar(total, "runs");
    let rows = run_grid_until(
        &grid,
        &brain,
        threads(),
        &|done, _| {
            if let Some(b) = &bar {
                b.set_position(done as u64);
            }
        },
        stop,
    )?;
    if let Some(b) = bar {
        b.finish_and_clear();
    }
    if stop.is_stopped() {
        println!("interrupted: {} of {total} runs completed", rows.len());
    }
    Ok(rows)
}

fn print_table(rows: &[(Point, Metrics)]) {
    println!(
        "{:<7} {:>9} {:>10} {:>5} {:>4} | {:>8} {:>6} {:>9} {:>11} {:>14}",
        "clock",
        "sensor Hz",
        "control Hz",
        "depth",
        "seed",
        "balanced",
        "steps",
        "fell at s",
        "obs dropped",
        "mean lat (ms)"
    );
    for (p, m) in rows {
        println!(
            "{:<7} {:>9} {:>10} {:>5} {:>4} | {:>8} {:>6} {:>9} {:>11} {:>14.2}",
            p.clock.as_str(),
            p.sensor_hz,
            p.control_hz,
            p.queue_depth,
            p.seed,
            if m.balanced { "Y" } else { "n" },
            m.steps,
            m.fell_at_s.map_or("-".into(), |t| format!("{t:.2}")),
            m.obs_dropped.map_or("-".into(), |d| d.to_string()),
            m.mean_latency_ms
        );
        if let Some(failed) = &m.node_failed {
            println!("        ↳ node failed: {failed}");
        }
    }
}

/// Per control rate (over every other grid dimension): the fraction of runs that balanced
/// and the mean sense→act latency, ms.
fn by_rate(rows: &[(Point, Metrics)]) -> Vec<(f64, f64, f64)> {
    let mut rates: Vec<f64> = rows.iter().map(|(p, _)| p.control_hz).collect();
    rates.sort_by(f64::total_cmp);
    rates.dedup();
    rates
        .into_iter()
        .map(|hz| {
            let at: Vec<&Metrics> = rows
                .iter()
                .filter(|(p, _)| p.control_hz == hz)
                .map(|(_, m)| m)
                .collect();
            let ok = at.iter().filter(|m| m.balanced).count() as f64 / at.len() as f64;
            let lat = at.iter().map(|m| m.mean_latency_ms).sum::<f64>() / at.len() as f64;
            (hz, ok, lat)
        })
        .collect()
}

/// Outcome and latency against the control rate as two ratatui charts, drawn inline
/// below the table (the terminal is left in its normal mode afterwards).
fn draw_chart(rows: &[(Point, Metrics)]) -> anyhow::Result<()> {
    use ratatui::layout::{Constraint, Layout};
    use ratatui::style::Color;
    use ratatui::widgets::Axis;
    use ratatui::{TerminalOptions, Viewport};
    let points = by_rate(rows);
    let ok: Vec<(f64, f64)> = points.iter().map(|&(hz, ok, _)| (hz, ok)).collect();
    let lat: Vec<(f64, f64)> = points.iter().map(|&(hz, _, l)| (hz, l)).collect();
    let x_max = points.iter().map(|p| p.0).fold(1.0, f64::max);
    let lat_max = points.iter().map(|p| p.2).fold(1.0, f64::max) * 1.1;
    let x_axis = || {
        Axis::default()
            .title("control Hz")
            .bounds([0.0, x_max])
            .labels(["0".to_string(), format!("{x_max}")])
    };
    let mut terminal = ratatui::try_init_with_options(TerminalOptions {
        viewport: Viewport::Inline(14),
    })?;
    let drawn = terminal.draw(|f| {
        let [left, right] = Layout::horizontal([Constraint::Percentage(50); 2]).areas(f.area());
        let balanced = line_chart(
            " fraction of runs balanced ",
            "balanced",
            Color::Green,
            &ok,
            x_axis(),
            [0.0, 1.05],
        );
        let latency = line_chart(
            " mean sense→act latency (ms) ",
            "mean latency",
            Color::Cyan,
            &lat,
            x_axis(),
            [0.0, lat_max],
        );
        f.render_widget(balanced, left);
        f.render_widget(latency, right);
    });
    ratatui::restore();
    drawn?;
    println!();
    Ok(())
}

/// One titled line chart of `data` with a y axis over `y` (labelled at its ends).
fn line_chart<'a>(
    title: &'a str,
    name: &'a str,
    color: ratatui::style::Color,
    data: &'a [(f64, f64)],
    x_axis: ratatui::widgets::Axis<'a>,
    y: [f64; 2],
) -> ratatui::widgets::Chart<'a> {
    use ratatui::widgets::{Axis, Block, Chart, Dataset, GraphType};
    let dataset = Dataset::default()
        .name(name)
        .marker(ratatui::symbols::Marker::Braille)
        .graph_type(GraphType::Line)
        .style(color)
        .data(data);
    Chart::new(vec![dataset])
        .block(Block::bordered().title(title))
        .x_axis(x_axis)
        .y_axis(
            Axis::default()
                .bounds(y)
                .labels([format!("{:.0}", y[0]), format!("{:.1}", y[1])]),
        )
}

/// Outcome and latency against the control rate, as text: one line per rate (over every
/// other grid dimension), with a bar for the mean latency.
fn print_plot(rows: &[(Point, Metrics)]) {
    let points = by_rate(rows);
    let max_lat = points.iter().map(|p| p.2).fold(1e-9, f64::max);
    println!("control Hz | balanced | mean sense->act latency");
    for &(hz, ok, lat) in points.iter().rev() {
        let bar = "#".repeat(((lat / max_lat) * 40.0).round() as usize);
        println!(
            "{:>10} | {:>7.0}% | {:<40} {:.1} ms",
            hz,
            ok * 100.0,
            bar,
            lat
        );
    }
}

/// For each seed, the highest control rate at which the pole falls, to `--step` Hz
/// ([`CliffSpec`]). Seeds run on a pool of workers sized to the machine's cores (as `sweep`
/// does), results in seed order, a progress bar on a terminal. After Ctrl-C (`stop`) no
/// further seed starts.
pub fn run_cliff(a: &CliffArgs, stop: &StopFlag) -> anyhow::Result<()> {
    let spec = CliffSpec::from(a);
    let brain = brain_factory(&spec.base.policy)?;
    let base = spec.config(Speech::Flags)?;
    crate::headless::warn_qos(&base.graph);
    let bar = progress_bar(spec.seeds.len(), "seeds");
    let searched = spec.search(
        &base,
        &brain,
        &|done, _| {
            if let Some(b) = &bar {
                b.set_position(done as u64);
            }
        },
        stop,
    );
    if let Some(b) = bar {
        b.finish_and_clear();
    }
    let cliffs = searched?;
    if cliffs.len() < spec.seeds.len() {
        println!(
            "interrupted: {} of {} seeds searched",
            cliffs.len(),
            spec.seeds.len()
        );
    }
    // "Balanced" means up for the whole run: a longer run can fall at a rate this one
    // balances at (8 Hz falls at 22.5 s of a 30 s run).
    println!(
        "highest control rate at which the pole falls within a {} s run (virtual clock, {}–{} Hz by {} Hz):",
        a.duration, a.min_hz, a.max_hz, a.step
    );
    for c in &cliffs {
        match (c.falls_at_hz, c.balances_at_hz) {
            (Some(f), Some(b)) => println!(
                "seed {}: {:.1} Hz (falls there; balances at {:.1} Hz; {} runs)",
                c.seed, f, b, c.runs
            ),
            (Some(f), None) => println!(
                "seed {}: {:.1} Hz (falls even at the top of the range)",
                c.seed, f
            ),
            (None, _) => println!(
                "seed {}: none (balances at every rate in [{}, {}] Hz)",
                c.seed, a.min_hz, a.max_hz
            ),
        }
    }
    if !stop.is_stopped() {
        print_edge(a, &base, &brain, &cliffs)?;
    }
    Ok(())
}

/// The most rows the edge plot shows.
const EDGE_ROWS: usize = 41;

/// Around the cliff, every rate on the search grid for every seed: the balanced fraction
/// per rate, as a text plot. The edge is ragged, not a line: phase decides too.
fn print_edge(
    a: &CliffArgs,
    base: &RunConfig,
    brain: BrainFactory<'_>,
    cliffs: &[Cliff],
) -> anyhow::Result<()> {
    let falls: Vec<f64> = cliffs.iter().filter_map(|c| c.falls_at_hz).collect();
    let (Some(lowest), Some(highest)) = (
        falls.iter().copied().reduce(f64::min),
        falls.iter().copied().reduce(f64::max),
    ) else {
        return Ok(());
    };
    let lo = (lowest - 0.5).max(a.min_hz);
    let hi = (highest + 0.5).min(a.max_hz);
    // Rates are whole multiples of the step (as the search's), at most EDGE_ROWS of them.
    let step = a.step.max((hi - lo) / (EDGE_ROWS - 1) as f64);
    let (k0, k1) = ((lo / step).ceil() as i64, (hi / step).floor() as i64);
    let rates: Vec<f64> = (k0..=k1)
        .rev()
        .map(|k| (k as f64 * step * 1e6).round() / 1e6)
        .filter(|&hz| ratelab::config::check_rate("control-hz", hz).is_ok())
        .collect();
    let grid = Grid {
        clocks: vec![ClockKind::Virtual],
        sensor_hz: vec![a.sensor_hz],
        control_hz: rates.clone(),
        queue_depth: vec![a.queue_depth],
        seeds: a.seeds.clone(),
        base: base.clone(),
    };
    let rows = run_grid(&grid, brain, threads(), &|_, _| {})?;
    println!(
        "\nThe edge is ragged, not a line: whether a seed survives depends on the phase between the\n\
         policy's ticks and the sensor's readings as much as on the rate, so a seed can fall at one\n\
         rate and balance just below it. Balanced fraction per rate (seeds {}):",
        a.seeds
            .iter()
            .map(u64::to_string)
            .collect::<Vec<_>>()
            .join(",")
    );
    for hz in rates {
        let at: Vec<bool> = rows
            .iter()
            .filter(|(p, _)| p.control_hz == hz)
            .map(|(_, m)| m.balanced)
            .collect();
        let ok = at.iter().filter(|b| **b).count();
        let bar = (ok * 10).div_ceil(at.len().max(1));
        println!("{hz:>8.2} Hz |{:<10}| {ok}/{}", "█".repeat(bar), at.len());
    }
    Ok(())
}
