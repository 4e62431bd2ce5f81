//! `ratelab exercise ex1|ex2|ex3`: predict, run, reconcile.

use anyhow::{bail, Context};
use ratelab::exercise::{
    check_ex1, check_ex2, check_ex3, load_bands, measure_ex1, measure_ex2, measure_ex3,
    required_keys, Check, ExerciseFile, Outcome,
};
use std::path::Path;

const FILES: [(&str, &str); 3] = [
    ("ex1", "ex1_rate_cliff.toml"),
    ("ex2", "ex2_queue_trap.toml"),
    ("ex3", "ex3_jitter_phase.toml"),
];

fn print_checks(checks: &[Check]) {
    for c in checks {
        println!("  [{}] {}", if c.passed { "ok" } else { "!!" }, c.name);
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

/// Run exercise `which` from the exercise folder `dir`.
pub fn run_exercise(
    which: &str,
    dir: &Path,
    graph: &ratelab::graph::GraphSpec,
) -> anyhow::Result<()> {
    let Some((ex, file)) = FILES.iter().find(|(e, _)| *e == which) else {
        bail!("unknown exercise '{which}' (expected ex1, ex2 or ex3)");
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
            println!("(Y: balanced the whole run; n@T: fell at run time T s; one cell per seed, as in the header.)");
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
                        m.queue_depth,
                        m.obs_dropped,
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
                        .map(|(_, d)| d.obs_dropped)
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
                    m.obs_dropped,
                    m.action_dropped,
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
                    matched_obs_drops: matched.obs_dropped,
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
                matched.obs_dropped,
                offset.obs_dropped
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

/// The learner's prediction against the outcome, in words.
fn say_reconcile(f: &ExerciseFile, outcome: &Outcome) {
    println!();
    for line in f.reconcile(outcome) {
        println!("{line}");
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
