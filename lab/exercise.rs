//! `ratelab exercise ex1|…|ex8`: predict, run, reconcile.

use anyhow::{bail, Context};
use ratelab::exercise::{
    check_ex1, check_ex2, check_ex3, check_ex4, check_ex5, check_ex6, ex6_differences, load_bands,
    measure_ex1, measure_ex2, measure_ex3, measure_ex4, measure_ex5, measure_ex6, outcome_ex4,
    outcome_ex5, outcome_ex6, required_keys, Check, Ex4Bands, Ex4Run, Ex5Bands, Ex5Case, Ex5Run,
    Ex6Bands, Ex6Run, ExerciseFile, Outcome,
};
use ratelab::exercise::{check_ex7, measure_ex7, outcome_ex7, Ex7Bands, Ex7Case, Ex7Run};
use ratelab::exercise::{check_ex8, measure_ex8, outcome_ex8, Ex8Bands, Ex8Run};
use ratelab::exercise::{check_ex9, measure_ex9, outcome_ex9, Ex9Bands, Ex9Case, Ex9Run};
use ratelab::metrics::Metrics;
use std::path::Path;
use std::sync::atomic::{AtomicUsize, Ordering};

/// Every exercise and its file, in order.
const FILES: [(&str, &str); 9] = [
    ("ex1", "ex1_rate_cliff.toml"),
    ("ex2", "ex2_queue_trap.toml"),
    ("ex3", "ex3_jitter_phase.toml"),
    ("ex4", "ex4_stale_queue.toml"),
    ("ex5", "ex5_watchdog.toml"),
    ("ex6", "ex6_own_node.toml"),
    ("ex7", "ex7_slow_callback.toml"),
    ("ex8", "ex8_noisy_sensor.toml"),
    ("ex9", "ex9_crossing.toml"),
];

/// What did not pass in this process's exercise: checks marked `[!!]` and predictions
/// that could not be read. One exercise runs per process.
static NOT_PASSED: AtomicUsize = AtomicUsize::new(0);

/// An exercise that ran to its end but did not pass: a check failed or a prediction could
/// not be read. `ratelab exercise` then exits 1 (2 is for what kept it from running).
#[derive(Debug)]
pub struct NotPassed(pub usize);

impl std::fmt::Display for NotPassed {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "{} check(s) or prediction(s) did not pass (marked above): the exercise is not passed",
            self.0
        )
    }
}

impl std::error::Error for NotPassed {}

fn print_checks(checks: &[Check]) {
    for c in checks {
        println!("  [{}] {}", if c.passed { "ok" } else { "!!" }, c.name);
        if !c.passed {
            NOT_PASSED.fetch_add(1, Ordering::Relaxed);
        }
    }
}

/// Run `f` with a spinner and the elapsed time on stderr (when it is a terminal): the
/// measurements take from seconds to a minute.
fn with_spinner<T>(what: &str, f: impl FnOnce() -> T) -> T {
    use std::io::IsTerminal;
    let bar = std::io::stderr().is_terminal().then(|| {
        let bar = indicatif::ProgressBar::new_spinner();
        bar.set_style(
            indicatif::ProgressStyle::with_template("{spinner} {msg} ({elapsed})")
                .expect("static template"),
        );
        bar.set_message(what.to_string());
        bar.enable_steady_tick(std::time::Duration::from_millis(200));
        bar
    });
    let out = f();
    if let Some(b) = bar {
        b.finish_and_clear();
    }
    out
}

/// `ratelab exercise`: the graph (the chapter's, or the one the exercise's bands name, with
/// the command line's overrides), then [`run_exercise`].
pub fn run_from_args(args: &crate::cli::ExerciseArgs) -> anyhow::Result<()> {
    let mut graph = args.graph.clone();
    if graph.graph.is_none() {
        graph.graph = ratelab::exercise::default_graph(&args.which, &args.dir)?;
    }
    let g = crate::headless::graph_from_args(&graph)?;
    if !crate::headless::faults_from_args(&graph).is_empty() {
        bail!("--stall/--kill: the exercises inject no faults; use `ratelab run` or `ratelab lab` with them");
    }
    run_exercise(&args.which, &args.dir, &g, graph.graph.as_deref())
}

/// Run exercise `which` from the exercise folder `dir` on `graph` (read from `graph_path`,
/// `None` for the chapter's: ex9's processes load it too).
///
/// # Errors
/// What kept it from running (exit 2), or [`NotPassed`] after it ran when a check failed or
/// a prediction could not be read (exit 1).
pub fn run_exercise(
    which: &str,
    dir: &Path,
    graph: &ratelab::graph::GraphSpec,
    graph_path: Option<&Path>,
) -> anyhow::Result<()> {
    NOT_PASSED.store(0, Ordering::Relaxed);
    run_one(which, dir, graph, graph_path)?;
    match NOT_PASSED.load(Ordering::Relaxed) {
        0 => Ok(()),
        n => Err(NotPassed(n).into()),
    }
}

fn run_one(
    which: &str,
    dir: &Path,
    graph: &ratelab::graph::GraphSpec,
    graph_path: Option<&Path>,
) -> anyhow::Result<()> {
    let Some((ex, file)) = FILES.iter().find(|(e, _)| *e == which) else {
        bail!(
            "unknown exercise '{which}' (expected ex1, ex2, ex3, ex4, ex5, ex6, ex7, ex8 or ex9)"
        );
    };
    let path = dir.join(file);
    let f = ExerciseFile::load(&path)?;
    if !f.has_prediction(required_keys(ex)) {
        bail!(
            "{} has no prediction yet: fill in [prediction] ({} and why) first — predicting is the exercise",
            path.display(),
            required_keys(ex).join(", ")
        );
    }
    let bands = load_bands(&dir.join("bands.toml")).context("reading the bands")?;
    println!(
        "== {ex}: {} (about {} min)\n{}\n",
        f.title,
        f.estimated_minutes,
        f.objective.trim()
    );
    println!("Your prediction:\n{}\n", indent(&f.prediction_text()));
    match *ex {
        "ex1" => {
            let b = &bands.ex1;
            let runs = with_spinner("measuring ex1", || measure_ex1(b, graph))?;
            println!(
                "{:>9} | {} | mean sense->act latency",
                "control",
                seeds_header(&b.seeds)
            );
            for (i, hz) in b.control_hz.iter().enumerate() {
                let row = &runs[i * b.seeds.len()..(i + 1) * b.seeds.len()];
                let cells: Vec<String> = row
                    .iter()
                    .map(|m| {
                        if m.balanced {
                            "   Y   ".into()
                        } else {
                            format!("n@{:>4.2}s", m.fell_at_s.unwrap_or(0.0))
                        }
                    })
                    .collect();
                let lat = row.iter().map(|m| m.mean_latency_ms).sum::<f64>() / row.len() as f64;
                println!("{:>6} Hz | {} | {:>6.1} ms", hz, cells.join(" "), lat);
            }
            let first_fall = b.control_hz.iter().enumerate().find(|(i, _)| {
                runs[i * b.seeds.len()..(i + 1) * b.seeds.len()]
                    .iter()
                    .any(|m| !m.balanced)
            });
            println!(
                "(Y: balanced the whole {} s run, which a longer run may not; n@T: fell at run time T s; one cell per seed, as in the header.)",
                b.duration_s
            );
            println!(
                "\nOutcome: the pole first fails at {} Hz.",
                first_fall.map_or("no rate".into(), |(_, hz)| hz.to_string())
            );
            say_reconcile(
                &f,
                &Outcome::Ex1 {
                    fails_at_hz: first_fall.map(|(_, hz)| *hz),
                },
            );
            print_checks(&check_ex1(b, &runs));
            println!("\nReconcile: latency grows as the rate drops (the actuator holds each action longer), but");
            println!("not strictly: a 15 Hz policy ticks between sensor readings and acts on readings up to 20 ms");
            println!("older than a 10 Hz policy, whose ticks coincide with the sensor's. Phase matters, not only");
            println!("rate. The pole survives until the held action is so old that the correction arrives after");
            println!(
                "the pole is past saving. A good controller is robust until, suddenly, it is not."
            );
            println!("Near the edge a seed can fall at one rate and balance just below it: the cliff is ragged.");
            println!(
                "Find it to 0.1 Hz, with the balanced fraction per rate around it: ratelab cliff --seeds {}",
                join(&b.seeds)
            );
        }
        "ex2" => {
            let b = &bands.ex2;
            let pairs = with_spinner("measuring ex2", || measure_ex2(b, graph))?;
            println!("control {} Hz | seed | depth | /obs dropped | balanced | fell at step | mean latency", b.control_hz);
            for (seed, (s, d)) in b.seeds.iter().zip(&pairs) {
                for m in [s, d] {
                    println!(
                        "{:>13} | {:>4} | {:>5} | {:>12} | {:>8} | {:>12} | {:>7.1} ms",
                        "",
                        seed,
                        dash(m.queue_depth),
                        dash(m.obs_dropped),
                        if m.balanced { "Y" } else { "n" },
                        m.steps,
                        m.mean_latency_ms
                    );
                }
            }
            say_reconcile(
                &f,
                &Outcome::Ex2 {
                    deep_queue_obs_drops: pairs
                        .iter()
                        .filter_map(|(_, d)| d.obs_dropped)
                        .max()
                        .unwrap_or(0),
                    deep_queue_balances: pairs.iter().all(|(_, d)| d.balanced),
                },
            );
            print_checks(&check_ex2(b, &pairs));
            println!("\nReconcile: the deep queue stops the drop counter — nothing is evicted before the next");
            println!("read — but the policy still reads only the LATEST message, every 200 ms. The backlog it");
            println!("buffers is never used, the decisions are exactly as old, and the pole falls at the same");
            println!("step. Drops were the symptom of a rate mismatch; the disease is latency. Throughput is not control.");
        }
        "ex4" => {
            let b = &bands.ex4;
            let runs = with_spinner("measuring ex4", || measure_ex4(b, graph))?;
            print_ex4(b, &f, &runs);
        }
        "ex5" => {
            let b = &bands.ex5;
            let runs = with_spinner("measuring ex5", || measure_ex5(b, graph))?;
            print_ex5(b, &f, &runs);
        }
        "ex6" => {
            let b = &bands.ex6;
            let script = dir.join(&b.script);
            refuse_the_template(&script)?;
            let runs = with_spinner("measuring ex6", || measure_ex6(b, graph, &script))?;
            print_ex6(b, &f, &runs, dir);
        }
        "ex7" => {
            let b = &bands.ex7;
            let runs = with_spinner("measuring ex7", || measure_ex7(b, graph))?;
            print_ex7(b, &f, &runs);
        }
        "ex8" => {
            let b = &bands.ex8;
            let runs = with_spinner("measuring ex8", || measure_ex8(b, graph))?;
            print_ex8(b, &f, &runs);
        }
        "ex9" => {
            let b = &bands.ex9;
            println!(
                "Running {} s on the real clock three times, twice across two processes (this takes real time)...",
                b.duration_s
            );
            let exe = std::env::current_exe()?;
            let runs = with_spinner("measuring ex9", || measure_ex9(b, graph, graph_path, &exe))?;
            print_ex9(b, &f, &runs);
        }
        _ => {
            let b = &bands.ex3;
            println!(
                "Running {} s on the real clock twice (this takes real time)...",
                b.duration_s
            );
            let (matched, offset) = with_spinner("measuring ex3", || measure_ex3(b, graph))?;
            println!("offsets (ms)     | /obs dropped | /action dropped | balanced | latency mean |    p50 |    p99");
            for (label, m) in [
                ("none".to_string(), &matched),
                (format!("{:?}", b.phase_offset_ms), &offset),
            ] {
                println!(
                    "{:<16} | {:>12} | {:>15} | {:>8} | {:>9.1} ms | {:>6.1} | {:>6.1}",
                    label,
                    dash(m.obs_dropped),
                    dash(m.action_dropped),
                    if m.balanced { "Y" } else { "n" },
                    m.mean_latency_ms,
                    m.latency_p50_ms,
                    m.latency_p99_ms
                );
            }
            println!("(latency in ms, sense->act: from the reading to the step that applied the action derived from it)");
            say_reconcile(
                &f,
                &Outcome::Ex3 {
                    matched_obs_drops: matched.obs_dropped.unwrap_or(0),
                },
            );
            print_checks(&check_ex3(b, &matched, &offset));
            println!("\nReconcile: with matched rates all three threads wake at the same instant and race.");
            println!("Each time the sensor publishes twice before the policy reads, a reading is dropped. And");
            println!("each time the policy reads a moment before the sensor publishes, it acts on the previous");
            println!("tick's reading, 20 ms old (40 ms when the actuator is late too): the latency here was");
            println!(
                "{:.1} ms on average, p99 {:.1} ms, where the virtual clock gives 0 ms, because its fixed",
                matched.mean_latency_ms, matched.latency_p99_ms
            );
            println!("tie-break puts the sensor first at every shared instant. The offsets make that order real:");
            println!(
                "sense, then {} ms later think, then {} ms later act. They remove the drops ({} -> {}) and fix",
                b.phase_offset_ms[1] - b.phase_offset_ms[0],
                b.phase_offset_ms[2] - b.phase_offset_ms[1],
                dash(matched.obs_dropped),
                dash(offset.obs_dropped)
            );
            println!(
                "the latency at the sensor-to-actuator offset: {:.1} ms on average, {:.1} ms at the median,",
                offset.mean_latency_ms, offset.latency_p50_ms
            );
            println!("the same at almost every tick (only a host stall longer than an offset moves one).");
            println!("Nothing was buffered: the race was removed by design.");
        }
    }
    Ok(())
}

/// A run's verdict in a table cell: `Y`, `n@0.34s` (fell at run time 0.34 s), or
/// `W@0.34s` (stopped by the watchdog).
fn verdict(m: &Metrics) -> String {
    match (m.balanced, m.fell_at_s) {
        (true, _) => "Y".into(),
        (false, Some(t)) => format!("n@{t:.2}s"),
        (false, None) if m.stopped_by_watchdog.is_some() => format!("W@{:.2}s", m.sim_time_s),
        (false, None) => "n".into(),
    }
}

fn print_ex4(b: &Ex4Bands, f: &ExerciseFile, runs: &[Ex4Run]) {
    let head = format!(
        "{} keep-last {}, policy {} Hz",
        b.topic, b.depth, b.control_hz
    );
    let w = head.len().max(22);
    println!(
        "{head:<w$} | seed | {:>7} | expired | balanced | latency mean |   max | at the fall",
        "dropped"
    );
    let mut last = String::new();
    for r in runs {
        let label = r.label();
        let shown = if label == last {
            String::new()
        } else {
            label.clone()
        };
        last = label;
        let m = &r.metrics;
        println!(
            "{shown:<w$} | {:>4} | {:>7} | {:>7} | {:>8} | {:>9.1} ms | {:>5.1} | {:>11}",
            r.seed,
            m.topics.get(&b.topic).map_or(0, |t| t.dropped),
            if r.lifespan_ms.is_some() {
                r.expired(&b.topic).to_string()
            } else {
                "-".into()
            },
            verdict(m),
            m.mean_latency_ms,
            m.latency_max_ms,
            r.latency_at_fall_ms
                .map_or("-".into(), |l| format!("{l:.1} ms")),
        );
    }
    println!("(latency: sense->act, ms; at the fall: the latency of the action applied at the step the pole fell;");
    println!(" dropped: readings evicted unread; expired: readings the lifespan discarded unread; n@T: fell at T s)");
    let outcome = outcome_ex4(b, runs);
    say_reconcile(f, &outcome);
    print_checks(&check_ex4(b, runs));
    // The explanation, with its numbers from the bands and the runs, and each claim about a
    // verdict said only when the runs bear it out.
    let per_tick = b.sensor_hz / b.control_hz;
    let aging_ms = (per_tick - 1.0) * 1e3 / b.sensor_hz;
    let of = |label: &str| -> Vec<&Ex4Run> { runs.iter().filter(|r| r.label() == label).collect() };
    let latest_max = of("latest")
        .iter()
        .map(|r| r.metrics.latency_max_ms)
        .fold(0.0, f64::max);
    let mut text = format!(
        "Reconcile: under latest the policy reads the newest reading and reads past the rest; the deep \
         queue holds them, nothing is dropped, and no action is older than {latest_max:.0} ms. Under fifo \
         the policy takes the OLDEST unread reading, one per tick, while {per_tick} arrive: the backlog \
         grows by {} a tick, and each reading acted on is {aging_ms:.0} ms older than the one before. \
         Nothing is dropped, so the drop counter says all is well",
        per_tick - 1.0
    );
    let fifo_falls: Vec<f64> = of("fifo")
        .iter()
        .filter_map(|r| r.metrics.fell_at_s)
        .collect();
    match outcome {
        Outcome::Ex4 {
            fifo_latency_at_fall_ms: Some((lo, hi)),
            ..
        } if fifo_falls.len() == of("fifo").len() => {
            let t = fifo_falls.iter().copied().fold(0.0, f64::max);
            text += &format!(
                ", while the pole is down by {t:.2} s on every seed, acting on readings {lo:.0} to {hi:.0} ms old."
            );
        }
        _ => text += ", while the decisions age.",
    }
    if let Some((&first, longer)) = b.lifespan_ms.split_first() {
        text += &format!(
            " A lifespan discards a reading older than it before a read can return it: at {first} ms \
             fifo acts at worst on a reading {first} ms old when read"
        );
        text += if of(&format!("fifo, lifespan {first} ms"))
            .iter()
            .all(|r| r.metrics.balanced)
        {
            ", and the pole stays up."
        } else {
            "."
        };
        text += " The readings latest reads past are discarded again, and counted as expired: the drops \
                 are back, under another name.";
        for &l in longer {
            let rs = of(&format!("fifo, lifespan {l} ms"));
            if rs.iter().all(|r| !r.metrics.balanced) {
                text += &format!(
                    " At {l} ms the bound is too loose: the pole falls later ({}), but it falls.",
                    rs.iter()
                        .filter_map(|r| r.metrics.fell_at_s)
                        .map(|t| format!("{t:.2} s"))
                        .collect::<Vec<_>>()
                        .join(", ")
                );
            }
        }
    }
    text += " A slow subscriber of a fast sensor wants the newest reading, not a queue of old ones: \
             ROS 2's sensor-data QoS profile keeps only the last few, best effort, for this reason.";
    println!();
    paragraph(&text);
}

/// Print `text` wrapped at 96 columns.
fn paragraph(text: &str) {
    let mut line = String::new();
    for word in text.split_whitespace() {
        if !line.is_empty() && line.len() + 1 + word.len() > 96 {
            println!("{line}");
            line.clear();
        }
        if !line.is_empty() {
            line.push(' ');
        }
        line.push_str(word);
    }
    if !line.is_empty() {
        println!("{line}");
    }
}

fn print_ex5(b: &Ex5Bands, f: &ExerciseFile, runs: &[Ex5Run]) {
    let w = Ex5Case::ALL
        .iter()
        .map(|c| c.label(b).len())
        .max()
        .unwrap_or(0)
        .max(b.topic.len() + 20);
    println!(
        "{:<w$} | {} | latency mean |   max | lost |  retx | dl missed | no cmd",
        format!("{} (safety -> actuator)", b.topic),
        seeds_header(&b.seeds)
    );
    for case in Ex5Case::ALL {
        let rs: Vec<&Ex5Run> = runs.iter().filter(|r| r.case == case).collect();
        let cells: Vec<String> = rs
            .iter()
            .map(|r| format!("{:^7}", verdict(&r.metrics)))
            .collect();
        let mean =
            rs.iter().map(|r| r.metrics.mean_latency_ms).sum::<f64>() / rs.len().max(1) as f64;
        let max = rs
            .iter()
            .map(|r| r.metrics.latency_max_ms)
            .fold(0.0, f64::max);
        let sum = |key: &str| rs.iter().map(|r| r.counter(b, key)).sum::<u64>();
        println!(
            "{:<w$} | {} | {:>9.1} ms | {:>5.1} | {:>4} | {:>5} | {:>9} | {:>6}",
            case.label(b),
            cells.join(" "),
            mean,
            max,
            sum("lost"),
            sum("retransmitted"),
            if matches!(case, Ex5Case::DeadlineHold | Ex5Case::DeadlineZero) {
                sum("requested_deadline_missed").to_string()
            } else {
                "-".into()
            },
            rs.iter().map(|r| r.steps_without_command).sum::<u64>(),
        );
    }
    println!("(latency: sense->act, ms, the mean of the seeds' means and the largest; lost, retx (retransmitted),");
    println!(" dl missed (deadline periods with no command arriving; -: no deadline) and no cmd (actuator steps");
    println!(" that applied no command: no latency) are summed over the seeds; Y: balanced; n@T: fell at T s)");
    let outcome = outcome_ex5(b, runs);
    say_reconcile(f, &outcome);
    print_checks(&check_ex5(b, runs));
    let of = |c: Ex5Case| -> Vec<&Ex5Run> { runs.iter().filter(|r| r.case == c).collect() };
    let max_of = |c: Ex5Case| {
        of(c)
            .iter()
            .map(|r| r.metrics.latency_max_ms)
            .fold(0.0, f64::max)
    };
    let up = |c: Ex5Case| of(c).iter().all(|r| r.metrics.balanced);
    let pct = |p: f64| format!("{}%", p * 100.0);
    let (low, high) = (pct(b.low_loss), pct(b.high_loss));
    let mut text = format!(
        "Reconcile: a lost command is a held command. At {low} loss the actuator re-applies the \
         previous command for a tick or a few (the oldest command applied was {:.0} ms old)",
        max_of(Ex5Case::LowLoss)
    );
    text += if up(Ex5Case::LowLoss) {
        ", within what ex1's rate cliff allows, and the pole stays up: the zero-order hold already \
         is a loss strategy."
    } else {
        "."
    };
    text += &format!(
        " At {high} the holds run to {:.0} ms{}",
        max_of(Ex5Case::HighLoss),
        if up(Ex5Case::HighLoss) {
            "."
        } else {
            " and the pole falls."
        }
    );
    text += &format!(
        " A deadline alone changes only the counters: hold is the default reaction. With zero the \
         actuator stops pushing once its command is older than the deadline ({} ms: a command lost \
         once is held, the next tick still without one applies no force).",
        b.deadline_ms
    );
    if up(Ex5Case::DeadlineZero) && !up(Ex5Case::HighLoss) {
        text += " Here a stale push is worse than none, and the pole stays up.";
    }
    text +=
        " Motor drivers do the same with a command timeout (ROS 2's diff_drive_controller stops \
             the wheels after cmd_vel_timeout).";
    let timeout =
        ratelab::qos::Link::default_retransmit(ratelab::Nanos::ZERO, ratelab::Nanos::ZERO);
    let attempts = ratelab::qos::MAX_ATTEMPTS;
    text += &format!(
        " Reliable delivery sends a lost command again, up to {attempts} times (at {high} loss all \
         {attempts} sends fail for {:.1}% of commands), and a retransmission comes a timeout later \
         ({timeout} here: the link has no delay), too late for its tick, which applies an older \
         command.",
        b.high_loss.powi(i32::try_from(attempts).unwrap_or(i32::MAX)) * 100.0
    );
    if let Outcome::Ex5 {
        reliable_latency_ms,
        lossless_latency_ms,
        ..
    } = outcome
    {
        text += &format!(
            " That is its latency cost: {reliable_latency_ms:.1} ms on average, against \
             {lossless_latency_ms:.1} ms without the link."
        );
    }
    text += " On a slow link the timeout is a round trip, and a reliable link keeps order, so one \
             loss delays every command behind it. Try it:";
    println!();
    paragraph(&text);
    println!(
        "  ratelab run --clock virtual --graph graphs/cartpole-safety.toml --link {}:loss={},delay_ms=30,jitter_ms=10",
        b.topic, b.low_loss
    );
    println!("and the same with --qos {}:reliability=reliable.", b.topic);
}

/// ex6's table (per clamp: the built-in node's verdict per seed, then the learner's), the
/// reconcile and the checks.
fn print_ex6(b: &Ex6Bands, f: &ExerciseFile, runs: &[Ex6Run], dir: &Path) {
    let cell = |r: Option<&Ex6Run>| match r {
        Some(r) if r.metrics.balanced => "Y".to_string(),
        Some(r) => r
            .metrics
            .fell_at_s
            .map_or("n".into(), |t| format!("n@{t:.2}")),
        None => "-".into(),
    };
    let row = |clamp: f64, python: bool| -> Vec<String> {
        b.seeds
            .iter()
            .map(|&seed| {
                cell(
                    runs.iter()
                        .find(|r| r.clamp_n == clamp && r.seed == seed && r.python == python),
                )
            })
            .map(|c| format!("{c:<7}"))
            .collect()
    };
    println!(
        "{:>9} | built-in safety node: {} | your node ({}): {}",
        "max force",
        seeds_header(&b.seeds),
        b.script,
        seeds_header(&b.seeds)
    );
    let differ = ex6_differences(runs);
    for &clamp in &b.clamps_n {
        let mark = if differ.iter().any(|(c, _)| *c == clamp) {
            "  <- differs"
        } else {
            ""
        };
        println!(
            "{:>7} N | {:>21} {} | {:>w$} {}{mark}",
            clamp,
            "",
            row(clamp, false).join(" "),
            "",
            row(clamp, true).join(" "),
            w = 11 + b.script.len()
        );
    }
    println!("(Y: balanced the whole run; n@T: fell at T s)");
    say_reconcile(f, &outcome_ex6(runs));
    print_checks(&check_ex6(b, runs));
    println!();
    paragraph(&format!(
        "Reconcile: the balancer's commands are large only in the first second, while it \
         catches the pole from the reset's tilt; once the pole is up, a few newtons' worth of \
         command is plenty. Clamped at {} N the pole still comes up on every seed; below it, \
         a seed whose first pushes need more falls in the first seconds. A limiter is a node \
         like any other: here it ticks at the same instants as the policy, just after it, so \
         it adds no sense->act latency. Try your node in the lab, and change its rate (Tab to \
         select it, then - and +):",
        b.smallest_balancing_clamp_n
    ));
    // The learner's node, not the shipped solution: the graph beside the exercise's files.
    println!(
        "  ./scripts/lab.sh --clock virtual --graph {}",
        dir.join("ex6_my_limiter.toml").display()
    );
}

/// ex6's node as shipped, to tell the learner's from it: running the untouched template
/// would measure ratelab's pass-through, not the learner's node.
const EX6_TEMPLATE: &str = include_str!("../exercises/ex6_my_limiter.py");

/// Refuse ex6's node file when it is still the template as shipped (line endings and
/// trailing blanks aside).
///
/// # Errors
/// One line: the file is the untouched template.
fn refuse_the_template(script: &Path) -> anyhow::Result<()> {
    let normal = |t: &str| t.lines().map(str::trim_end).collect::<Vec<_>>().join("\n");
    let mine = std::fs::read(script).unwrap_or_default();
    if normal(&String::from_utf8_lossy(&mine)) == normal(EX6_TEMPLATE).as_str() {
        bail!(
            "{} is the template as shipped: make on_action clamp msg.newtons to ±max_force_n (its TODO) first; writing the node is the exercise",
            script.display()
        );
    }
    Ok(())
}

/// ex7's table (per case and seed: the sensor's rate and skipped ticks, the policy's
/// response time, the executor's utilization, the verdict), the reconcile and the checks.
fn print_ex7(b: &Ex7Bands, f: &ExerciseFile, runs: &[Ex7Run]) {
    println!(
        "{:<21} | seed | sensor Hz | skipped | policy response p50/max | executor busy | balanced",
        "executor"
    );
    for case in Ex7Case::ALL {
        for r in runs.iter().filter(|r| r.case == case) {
            let m = &r.metrics;
            let policy = m
                .nodes
                .values()
                .find(|n| n.kind == "policy")
                .and_then(|n| n.exec.clone())
                .unwrap_or_default();
            let busy = m.executors.first().map_or(0.0, |e| e.utilization * 100.0);
            println!(
                "{:<21} | {:>4} | {:>9.1} | {:>7} | {:>10.1} / {:>5.1} ms | {:>12.0}% | {}",
                case.label(),
                r.seed,
                r.sensor_hz(b),
                r.sensor_skipped(b),
                policy.response_time_p50_ms,
                policy.response_time_max_ms,
                busy,
                if m.balanced {
                    "Y".to_string()
                } else {
                    m.fell_at_s.map_or("n".into(), |t| format!("n@{t:.2}"))
                }
            );
        }
    }
    say_reconcile(f, &outcome_ex7(b, runs));
    print_checks(&check_ex7(b, runs));
    println!();
    paragraph(
        "Reconcile: an executor runs one callback per thread at a time, and a callback is not          interrupted. Single-threaded, each 30 ms policy tick holds the only thread, so the          sensor's timer fires late, and the periods that pass meanwhile are skipped, not          made up (ROS 2's timers stay on their grid). A second thread does nothing while          both callbacks are in one mutually exclusive group: the group, not the thread count,          decides what may run together, and a node's callbacks share its default group. In a          group of its own the sensor gets the second thread and its rate back. The pole          hardly notices either way: the policy reads the newest reading when it starts, and          the action's age is the policy's own 30 ms plus the wait for the actuator's tick.          What the starved sensor costs is every other subscriber of /obs (a logger, an          estimator), which would see a third of its readings missing. Try it with the          policy's compute time changed:",
    );
    println!("  ./scripts/lab.sh run --clock virtual --graph graphs/cartpole-executors.toml --executor single_threaded --compute policy=60");
}

/// The learner's prediction against the outcome, in words.
fn say_reconcile(f: &ExerciseFile, outcome: &Outcome) {
    println!();
    for line in f.reconcile(outcome) {
        println!("{line}");
        if ratelab::exercise::says_unreadable(&line) {
            NOT_PASSED.fetch_add(1, Ordering::Relaxed);
        }
    }
}

fn indent(s: &str) -> String {
    s.lines()
        .map(|l| format!("  {l}"))
        .collect::<Vec<_>>()
        .join("\n")
}

fn seeds_header(seeds: &[u64]) -> String {
    seeds
        .iter()
        .map(|s| format!("seed {s:<2}"))
        .collect::<Vec<_>>()
        .join(" ")
}

fn join(seeds: &[u64]) -> String {
    seeds
        .iter()
        .map(u64::to_string)
        .collect::<Vec<_>>()
        .join(",")
}

/// A figure of the chapter's chain, or `-` for a graph without it (the exercises' graphs
/// all have it).
fn dash<T: std::fmt::Display>(x: Option<T>) -> String {
    x.map_or_else(|| "-".to_string(), |v| v.to_string())
}

/// ex8's table (per cut-off and noise: each seed's verdict and the mean sense→act latency),
/// the reconcile and the checks.
fn print_ex8(b: &Ex8Bands, f: &ExerciseFile, runs: &[Ex8Run]) {
    println!("cut-off | angle noise | seeds: balanced (n@t: fell at t s) | latency mean");
    for cutoff in b.cutoffs_hz {
        for &noise in &b.noise_grid_rad {
            let row: Vec<&Ex8Run> = runs
                .iter()
                .filter(|r| r.cutoff_hz == cutoff && r.noise_rad == noise)
                .collect();
            let verdicts: Vec<String> = row
                .iter()
                .map(|r| {
                    if r.metrics.balanced {
                        "Y".to_string()
                    } else {
                        r.metrics
                            .fell_at_s
                            .map_or("n".into(), |t| format!("n@{t:.2}"))
                    }
                })
                .collect();
            let mean = row.iter().map(|r| r.metrics.mean_latency_ms).sum::<f64>()
                / row.len().max(1) as f64;
            println!(
                "{:>4} Hz | {:>7.3} rad | {:<34} | {:>7.1} ms",
                cutoff,
                noise,
                verdicts.join(" "),
                mean
            );
        }
    }
    say_reconcile(f, &outcome_ex8(b, runs));
    print_checks(&check_ex8(b, runs));
    println!();
    paragraph(
        "Reconcile: the estimator ticks at 100 Hz and reads the newest of the two measurements \
         the 200 Hz sensor published since its last tick, so its velocity is the difference of \
         two noisy angles 10 ms apart: its noise is about 141 times the angle's \
         (sqrt(2) / 0.010 s) before the filter. A pole-angle noise of a hundredth of a radian, \
         half a degree, is a velocity noise of about 1.4 rad/s, and the policy pushes on it. The low-pass filter trades that noise for \
         lag (about 1 / (2 pi cut-off): 8 ms at 20 Hz, 16 ms at 10 Hz); here the noise is the \
         larger harm, so the smoother estimate holds on to a higher noise. How far does the \
         trade go? Copy the graph, lower cutoff_hz to 5 and 2 Hz, raise noise_angle_rad, and \
         look. The latency column stays at the estimator's and the policy's compute times \
         plus the waits for the next tick: noise does not delay messages, it corrupts them.",
    );
    println!("  ./scripts/lab.sh run --clock virtual --graph graphs/cartpole-estimator.toml");
}

/// ex9's table (per case: the latency's mean, median and 99th percentile, the drops, the
/// wire's median per crossing topic), the reconcile and the checks.
fn print_ex9(b: &Ex9Bands, f: &ExerciseFile, runs: &[Ex9Run]) {
    println!("case                   | latency mean |    p50 |    p99 | /obs dropped | /action dropped | wire p50");
    for case in Ex9Case::ALL {
        for r in runs.iter().filter(|r| r.case == case) {
            let m = &r.metrics;
            let wire: Vec<String> = r
                .wire_p50_us
                .iter()
                .map(|(t, us)| format!("{t} {us:.0} µs"))
                .collect();
            println!(
                "{:<22} | {:>9.1} ms | {:>6.1} | {:>6.1} | {:>12} | {:>15} | {}",
                case.label(),
                m.mean_latency_ms,
                m.latency_p50_ms,
                m.latency_p99_ms,
                m.obs_dropped.unwrap_or(0),
                m.action_dropped.unwrap_or(0),
                if wire.is_empty() {
                    "-".to_string()
                } else {
                    wire.join(", ")
                }
            );
        }
    }
    say_reconcile(f, &outcome_ex9(runs));
    print_checks(&check_ex9(b, runs));
    println!();
    paragraph(
        "Reconcile: in one process, the policy waking at the sensor's instant races the \
         sensor's thread for the fresh reading, and wins it sometimes (ex3). Across \
         processes it never does: the reading is still on the wire (a fraction of a \
         millisecond), so the policy acts on the one before, a period older (+20 ms); the \
         force crosses back the same way and the actuator, waking at the policy's instant, \
         applies the force before (+20 ms). Each crossing hop at a shared instant costs a \
         full period. Offsets give each hop time to arrive: the sensor at 0, the policy 5 ms \
         later, the actuator 5 ms after that, and the latency is the 10 ms between sensor and \
         actuator. An offset of 1 ms is longer than the wire but not than every stall of a \
         busy machine: then misses come back, some of the time.",
    );
    println!(
        "  ./scripts/lab.sh launch --processes --clock real --duration 5 --phase-offset-ms 0,1,2"
    );
}
