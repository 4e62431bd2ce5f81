//! The `ratelab` binary's command line: headless runs, outputs, and bad input.

use std::path::Path;
use std::process::{Command, Output};

fn ratelab(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_ratelab"))
        .args(args)
        .output()
        .expect("runs")
}

fn stderr(o: &Output) -> String {
    String::from_utf8_lossy(&o.stderr).into_owned()
}

fn assert_usage_error(args: &[&str], needle: &str) {
    let o = ratelab(args);
    assert_eq!(o.status.code(), Some(2), "{args:?}: {}", stderr(&o));
    let err = stderr(&o);
    assert_eq!(
        err.trim_end().lines().count(),
        1,
        "{args:?}: one line, got {err:?}"
    );
    assert!(err.contains(needle), "{args:?}: {err:?} lacks {needle:?}");
    assert!(!err.contains("panicked"), "{err}");
}

#[test]
fn the_lab_refuses_headless_with_a_pointer_to_run() {
    // `--headless` is a global flag, so `lab --help` lists it; it cannot mean the lab.
    assert_usage_error(
        &["lab", "--headless", "--clock", "virtual"],
        "`lab` is the terminal lab and cannot run --headless: `ratelab run` runs the graph headless",
    );
}

#[test]
fn bad_rates_are_refused() {
    for bad in ["0", "-5", "nan", "inf", "10001", "fast"] {
        assert_usage_error(&["run", "--control-hz", bad], "--control-hz");
        assert_usage_error(&["run", "--sensor-hz", bad], "--sensor-hz");
    }
}

#[test]
fn bad_depth_duration_clock_are_refused() {
    assert_usage_error(&["run", "--queue-depth", "0"], "--queue-depth");
    assert_usage_error(&["run", "--duration", "0"], "--duration");
    assert_usage_error(&["run", "--duration", "-1"], "--duration");
    assert_usage_error(&["run", "--duration", "inf"], "--duration");
    assert_usage_error(&["run", "--clock", "wall"], "--clock");
    // A topic's depth is named by its own flag, not by --queue-depth's.
    let o = ratelab(&["run", "--depth", "/obs=0"]);
    assert_eq!(o.status.code(), Some(2));
    assert_eq!(
        stderr(&o).trim_end(),
        "error: invalid value '/obs=0' for '--depth <TOPIC=N>': a history depth is at least 1, got 0"
    );
}

#[test]
fn smoke_is_refused_beside_a_clock_or_a_duration_it_would_override() {
    assert_usage_error(
        &["run", "--smoke", "--clock", "real"],
        "error: the argument '--smoke' cannot be used with '--clock <CLOCK>'",
    );
    assert_usage_error(
        &["run", "--smoke", "--duration", "5"],
        "error: the argument '--smoke' cannot be used with '--duration <DURATION>'",
    );
}

#[test]
fn a_headless_run_refuses_the_lab_s_session_log_it_would_not_write() {
    let dir = tempfile::tempdir().unwrap();
    let file = dir.path().join("s.json");
    assert_usage_error(
        &["run", "--smoke", "--session", file.to_str().unwrap()],
        "error: --session is the lab's log of the keys pressed in it; a headless run takes none",
    );
    assert!(!file.exists());
}

#[test]
fn flags_that_would_write_nothing_are_refused_not_ignored() {
    // trace.csv is written by --out alone, and never by the lab or a launch across processes.
    assert_usage_error(
        &["run", "--smoke", "--trace-every", "2"],
        "error: --trace-every thins trace.csv, which only --out writes: add --out DIR",
    );
    assert_usage_error(
        &["launch", "--smoke", "--trace-every", "2"],
        "which only --out writes",
    );
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("o");
    let out = out.to_str().unwrap();
    assert_usage_error(
        &[
            "launch",
            "--processes",
            "--headless",
            "--smoke",
            "--out",
            out,
            "--trace-every",
            "2",
        ],
        "error: --trace-every thins trace.csv, which a launch across processes does not write",
    );
    // The lab refuses before its screen opens (here without a terminal, as in a pipe).
    assert_usage_error(
        &["lab", "--out", out],
        "error: --out writes one headless run's files",
    );
    assert_usage_error(
        &["lab", "--trace-every", "3"],
        "error: --trace-every thins trace.csv, which the lab does not write",
    );
    assert!(!Path::new(out).exists());
    // With --out it thins the file.
    let o = ratelab(&["run", "--smoke", "--out", out, "--trace-every", "10"]);
    assert!(o.status.success(), "{}", stderr(&o));
    let rows = std::fs::read_to_string(Path::new(out).join("trace.csv")).unwrap();
    assert!(rows.lines().count() < 20, "{} rows", rows.lines().count());
}

#[test]
fn an_exercise_without_its_folder_says_where_to_run_it_or_what_to_give() {
    assert_usage_error(
        &["exercise", "ex1", "--dir", "/nonexistent/exercises"],
        "error: the exercises folder /nonexistent/exercises is not there: run from the ratelab repository (its exercises/ folder), or give the folder with --dir FOLDER",
    );
}

#[test]
fn a_misspelled_flag_or_command_is_told_the_near_name_in_its_one_line() {
    assert_usage_error(
        &["run", "--contol-hz", "5"],
        "error: unexpected argument '--contol-hz' found (a similar argument exists: '--control-hz')",
    );
    assert_usage_error(
        &["runn"],
        "error: unrecognized subcommand 'runn' (a similar subcommand exists: 'run')",
    );
    // Nothing near: the line alone.
    let o = ratelab(&["run", "--zzzzzz"]);
    assert_eq!(
        stderr(&o).trim_end(),
        "error: unexpected argument '--zzzzzz' found"
    );
}

/// `ratelab ros2` is ros2cli's command set: the program's `--headless` is neither in its
/// help nor taken by it, wherever it is put (it used to be listed and silently taken).
#[test]
fn ros2_neither_lists_nor_takes_headless() {
    for help in [
        &["ros2", "--help"][..],
        &["ros2", "topic", "--help"],
        &["ros2", "topic", "list", "--help"],
        &["ros2", "bag", "info", "--help"],
    ] {
        let o = ratelab(help);
        assert!(o.status.success(), "{help:?}");
        let text = String::from_utf8_lossy(&o.stdout);
        assert!(!text.contains("--headless"), "{help:?}: {text}");
        assert!(
            text.contains("--domain"),
            "{help:?}: its own flags still shown"
        );
    }
    let run = ratelab(&["run", "--help"]);
    assert!(String::from_utf8_lossy(&run.stdout).contains("--headless"));
    assert_usage_error(
        &["ros2", "topic", "list", "--headless"],
        "error: unexpected argument '--headless' found",
    );
    for before in [&["ros2", "--headless"][..], &["--headless", "ros2"]] {
        let args: Vec<&str> = before.iter().chain(&["topic", "list"]).copied().collect();
        assert_usage_error(
            &args,
            "error: --headless: `ratelab ros2` prints as ros2cli does, with no lab to run headless",
        );
    }
}

#[test]
fn bad_rt_priorities_are_refused() {
    for bad in ["0", "100", "-1", "256", "high"] {
        assert_usage_error(
            &["run", "--rt-priority", bad],
            "--rt-priority must be in 1..=99",
        );
        assert_usage_error(
            &["bench", "--rt-priority", bad],
            "--rt-priority must be in 1..=99",
        );
    }
}

#[test]
fn bad_policies_are_refused() {
    assert_usage_error(
        &["run", "--smoke", "--policy", "/no/such/ppo.pt"],
        "/no/such/ppo.pt",
    );
    let dir = tempfile::tempdir().unwrap();
    let p = dir.path().join("junk.pt");
    std::fs::write(&p, b"not a zip").unwrap();
    assert_usage_error(
        &["run", "--smoke", "--policy", p.to_str().unwrap()],
        "junk.pt",
    );
}

#[test]
fn smoke_run_prints_the_summary_and_writes_metrics() {
    let dir = tempfile::tempdir().unwrap();
    let o = ratelab(&["run", "--smoke", "--out", dir.path().to_str().unwrap()]);
    assert!(o.status.success(), "{}", stderr(&o));
    let out = String::from_utf8_lossy(&o.stdout);
    assert!(out.contains("clock=virtual"), "{out}");
    assert!(out.contains("BALANCED"), "{out}");
    assert!(out.contains("/obs 50.5 msg/s (0 dropped)"), "{out}");
    // Under a second of run time the summary counts: 18 messages in 0.34 s are a 50 Hz
    // sensor, though published / run time reads 52.9 (metrics.json keeps that figure).
    let short = ratelab(&["run", "--clock", "virtual", "--duration", "0.34"]);
    let text = String::from_utf8_lossy(&short.stdout);
    assert!(
        text.contains("/obs 18 msgs in 0.34 s (0 dropped)"),
        "{text}"
    );
    assert!(!text.contains("52.9"), "{text}");
    let m: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.path().join("metrics.json")).unwrap())
            .unwrap();
    for key in [
        "balanced",
        "clock",
        "control_hz",
        "sensor_hz",
        "queue_depth",
        "seed",
        "steps",
        "sim_time_s",
        "final_pole_angle",
        "mean_latency_ms",
        "obs_published",
        "obs_dropped",
        "action_published",
        "action_dropped",
        "latency_p50_ms",
        "latency_p99_ms",
        "latency_max_ms",
        "fell_at_s",
        "policy",
    ] {
        assert!(m.get(key).is_some(), "metrics.json lacks {key}");
    }
    assert_eq!(m["steps"], 101);
    assert_eq!(m["balanced"], true);
    assert!(dir.path().join("trace.csv").is_file());
}

fn run_to(dir: &Path, extra: &[&str]) -> (Vec<u8>, Vec<u8>) {
    let mut args = vec![
        "run",
        "--clock",
        "virtual",
        "--seed",
        "2",
        "--out",
        dir.to_str().unwrap(),
        "--force", // each folder is written twice (plain, then --break)
    ];
    args.extend_from_slice(extra);
    let o = ratelab(&args);
    assert!(o.status.success(), "{}", stderr(&o));
    (
        std::fs::read(dir.join("metrics.json")).unwrap(),
        std::fs::read(dir.join("trace.csv")).unwrap(),
    )
}

#[test]
fn two_virtual_runs_write_byte_identical_files() {
    let (a, b) = (tempfile::tempdir().unwrap(), tempfile::tempdir().unwrap());
    for extra in [&[][..], &["--break"][..]] {
        let first = run_to(a.path(), extra);
        let second = run_to(b.path(), extra);
        assert_eq!(first, second, "{extra:?}");
    }
}

#[test]
fn break_flag_falls_headless_when_piped() {
    // No subcommand + piped stdout = the headless run.
    let o = ratelab(&["--clock", "virtual", "--break"]);
    assert!(o.status.success(), "{}", stderr(&o));
    let out = String::from_utf8_lossy(&o.stdout);
    assert!(
        out.contains("control 5 Hz") && out.contains("FELL at t="),
        "{out}"
    );
}

#[test]
fn exercise_refuses_without_a_prediction_then_runs_with_one() {
    let repo = Path::new(crate::REPO).join("exercises");
    let o = ratelab(&["exercise", "ex2", "--dir", repo.to_str().unwrap()]);
    assert_eq!(o.status.code(), Some(2));
    assert!(
        stderr(&o).contains("has no prediction yet"),
        "{}",
        stderr(&o)
    );

    let dir = tempfile::tempdir().unwrap();
    for f in ["bands.toml", "ex2_queue_trap.toml"] {
        std::fs::copy(repo.join(f), dir.path().join(f)).unwrap();
    }
    let file = dir.path().join("ex2_queue_trap.toml");
    let shipped = std::fs::read_to_string(&file).unwrap();
    // Part of a prediction: refused, naming what is left out (it said the whole prediction
    // was missing, a blank `why` beside two keys filled in).
    let keys = shipped
        .replace("# deep_queue_obs_drops =\n", "deep_queue_obs_drops = 0\n")
        .replace("# deep_queue_balances =\n", "deep_queue_balances = false\n");
    let why = "why = \"the policy still reads only the newest reading\"";
    for (text, lacks) in [
        (
            keys.clone(),
            "lacks why (a sentence: what you expect and why): ",
        ),
        (
            shipped
                .replace("# deep_queue_obs_drops =\n", "deep_queue_obs_drops = 0\n")
                .replace("why = \"\"", why),
            "lacks deep_queue_balances: ",
        ),
    ] {
        std::fs::write(&file, text).unwrap();
        let o = ratelab(&["exercise", "ex2", "--dir", dir.path().to_str().unwrap()]);
        assert_eq!(o.status.code(), Some(2), "{}", stderr(&o));
        assert_eq!(
            stderr(&o).trim_end(),
            format!(
                "error: {}: [prediction] {lacks}fill it in first — predicting is the exercise",
                file.display()
            )
        );
    }
    std::fs::write(&file, keys.replace("why = \"\"", why)).unwrap();
    let o = ratelab(&["exercise", "ex2", "--dir", dir.path().to_str().unwrap()]);
    let out = String::from_utf8_lossy(&o.stdout);
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(
        out.contains("deep_queue_obs_drops = 0"),
        "the prediction is shown beside the outcome:\n{out}"
    );
    assert!(
        out.contains("[ok] depth 100 drops 0 /obs on every seed"),
        "{out}"
    );
    assert!(out.contains("Reconcile:"), "{out}");
    assert!(
        out.contains("You predicted 0 /obs drops with the deep queue; there were 0: right.")
            && out
                .contains("You predicted the pole falls even with the deep queue; it fell: right.")
            && out.contains("Your prediction: 2 of 2 right."),
        "the prediction is compared with the outcome in words, and graded:\n{out}"
    );
}

#[test]
fn sweep_writes_csv_and_json_and_plots_as_text_when_piped() {
    let dir = tempfile::tempdir().unwrap();
    let (csv, json) = (dir.path().join("s.csv"), dir.path().join("s.json"));
    let o = ratelab(&[
        "sweep",
        "--control-hz",
        "50,5",
        "--queue-depth",
        "1,100",
        "--seeds",
        "0,1",
        "--duration",
        "3",
        "--csv",
        csv.to_str().unwrap(),
        "--json",
        json.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let out = String::from_utf8_lossy(&o.stdout);
    assert!(
        out.contains("control Hz | balanced | mean sense->act latency"),
        "{out}"
    );
    let rows = std::fs::read_to_string(&csv).unwrap();
    assert_eq!(rows.lines().count(), 1 + 2 * 2 * 2, "{rows}");
    assert!(rows
        .lines()
        .next()
        .unwrap()
        .starts_with("clock,sensor_hz,control_hz,queue_depth,seed,balanced"));
    let items: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&json).unwrap()).unwrap();
    assert_eq!(items.as_array().unwrap().len(), 8);
    assert_eq!(items[0]["point"]["control_hz"], 50.0);
    assert_eq!(items[0]["metrics"]["balanced"], true);
    assert_usage_error(&["sweep", "--control-hz", "50,0"], "--control-hz");
}

#[test]
fn cliff_prints_one_rate_per_seed_with_one_decimal() {
    // A narrow search band keeps the test quick; the full search is `ratelab cliff`.
    let o = ratelab(&["cliff", "--seeds", "0,1", "--min-hz", "7", "--max-hz", "9"]);
    assert!(o.status.success(), "{}", stderr(&o));
    let out = String::from_utf8_lossy(&o.stdout);
    let lines: Vec<&str> = out.lines().filter(|l| l.starts_with("seed ")).collect();
    assert_eq!(lines.len(), 2, "{out}");
    // The run's length it judged by: balanced means up that long.
    assert!(
        out.contains("highest control rate at which the pole falls within a 10 s run (virtual clock, 7–9 Hz by 0.1 Hz):"),
        "{out}"
    );
    // Then the ragged edge: every rate around the cliff, the fraction of seeds that balanced.
    assert!(out.contains("The edge is ragged"), "{out}");
    let plot: Vec<&str> = out.lines().filter(|l| l.contains(" Hz |")).collect();
    assert!(plot.len() >= 5, "{out}");
    assert!(
        plot.iter().all(|l| l.ends_with("/2")),
        "two seeds per rate:\n{out}"
    );
    for (seed, line) in lines.iter().enumerate() {
        let rate = line
            .strip_prefix(&format!("seed {seed}: "))
            .and_then(|rest| rest.split(" Hz").next())
            .unwrap_or_else(|| panic!("{line}"));
        let hz: f64 = rate.parse().unwrap();
        assert_eq!(
            rate.split('.').nth(1).map(str::len),
            Some(1),
            "one decimal: {line}"
        );
        // Measured with integer-nanosecond time: between 7 and 8 Hz for seeds 0-2.
        assert!((7.0..8.0).contains(&hz), "{line}");
    }
}

#[test]
fn bench_scrub_times_both_halves_of_reaching_an_instant() {
    let _m = crate::machine::shared();
    // Shape only: timings on a shared machine are not asserted anywhere.
    let o = ratelab(&["bench", "--scrub"]);
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    let out = String::from_utf8_lossy(&o.stdout);
    assert!(
        out.contains("10-minute virtual run (100 seeks; the lab told 40003 messages)"),
        "{out}"
    );
    for half in [
        "engine: restore + run on (run core): mean ",
        "lab: fold the journal up to it: mean ",
    ] {
        assert!(out.contains(half), "{half}: {out}");
    }
}

#[test]
fn bench_takes_a_run_s_settings_by_its_rules_and_refuses_faults_it_would_not_show() {
    assert_usage_error(
        &["bench", "--stall", "policy@1+0.5"],
        "error: --stall/--kill: the bench times every tick",
    );
    // The graph's overrides are a run's, checked as `run` checks them.
    assert_usage_error(&["bench", "--rate", "nobody=10"], "--rate nobody=10: ");
    // A node's own rate would not be timed (every node runs at each --hz): refused, not
    // ignored.
    assert_usage_error(
        &["bench", "--rate", "policy=10"],
        "error: --rate policy=…: the bench runs every node at each --hz",
    );
    // The frame and scrub timings take none of the real-clock timing's settings: refused
    // beside them, not ignored.
    assert_usage_error(
        &["bench", "--render", "--hz", "50"],
        "error: the argument '--render' cannot be used with '--hz <HZ>'",
    );
    assert_usage_error(
        &["bench", "--scrub", "--duration", "3"],
        "error: the argument '--scrub' cannot be used with '--duration <DURATION>'",
    );
    // Every override of the graph too, not only the file.
    assert_usage_error(
        &["bench", "--render", "--rate", "policy=5"],
        "error: the argument '--render' cannot be used with: --graph <FILE>, --rate <NODE=HZ>",
    );
}

#[test]
fn bench_prints_the_bare_wait_floor_then_each_node() {
    // Shape only: timings on a shared machine are not asserted anywhere.
    let o = ratelab(&["bench", "--hz", "200", "--duration", "0.5", "--stagger"]);
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    let out = String::from_utf8_lossy(&o.stdout);
    assert!(out.contains("staggered by P/n"), "{out}");
    // The margin the rate is timed with, as used: the default, below half of 5 ms.
    assert!(
        out.contains("spin margin 300 µs at 200 Hz (300 µs, at most P/2)"),
        "{out}"
    );
    // Python's line (measured or not) comes before the table, not among its rows.
    let python = out.lines().position(|l| l.starts_with("Python: "));
    let header = out
        .lines()
        .position(|l| l.trim_start().starts_with("rate Hz"));
    assert!(python.is_some() && python < header, "{out}");
    let rows: Vec<Vec<&str>> = out
        .lines()
        .filter(|l| l.trim_start().starts_with("200 "))
        .map(|l| l.split_whitespace().collect())
        .collect();
    assert_eq!(rows.len(), 4, "{out}");
    assert_eq!(&rows[0][1..3], ["bare", "wait"], "{out}");
    for (row, node) in rows[1..].iter().zip(["sensor", "policy", "actuator"]) {
        assert_eq!(row[1], node, "{out}");
        // 0.5 s at 200 Hz: 100 deadlines, each either ticked or skipped.
        let ticks: u64 = row[2].parse().unwrap();
        let skipped: u64 = row[7].parse().unwrap();
        assert!((98..=101).contains(&(ticks + skipped)), "{out}");
        assert!(row[8].starts_with("SCHED_"), "{out}");
    }
}

/// An exercise folder in `root`: `exercises/` with the bands and `files`, and `graphs/` (ex5
/// names its graph relative to the bands).
fn exercise_copy(root: &Path, files: &[&str]) -> std::path::PathBuf {
    let repo = Path::new(crate::REPO);
    let dir = root.join("exercises");
    std::fs::create_dir_all(&dir).unwrap();
    std::fs::create_dir_all(root.join("graphs")).unwrap();
    for f in files.iter().chain(&["bands.toml"]) {
        std::fs::copy(repo.join("exercises").join(f), dir.join(f)).unwrap();
    }
    for g in [
        "graphs/cartpole-safety.toml",
        "graphs/cartpole-executors.toml",
    ] {
        std::fs::copy(repo.join(g), root.join(g)).unwrap();
    }
    dir
}

#[test]
fn exercise_ex7_runs_its_three_executors_and_reconciles() {
    let _machine = crate::machine::shared();
    let tmp = tempfile::tempdir().unwrap();
    let dir = exercise_copy(tmp.path(), &["ex7_slow_callback.toml"]);
    let d = dir.to_str().unwrap();
    let o = ratelab(&["exercise", "ex7", "--dir", d]);
    assert_eq!(o.status.code(), Some(2));
    assert!(
        stderr(&o).contains("has no prediction yet"),
        "{}",
        stderr(&o)
    );
    let file = dir.join("ex7_slow_callback.toml");
    let text = std::fs::read_to_string(&file)
        .unwrap()
        .replace(
            "# sensor_hz_single_threaded =\n",
            "sensor_hz_single_threaded = 25\n",
        )
        .replace(
            "# skipped_ticks_single_threaded =\n",
            "skipped_ticks_single_threaded = 250\n",
        )
        .replace(
            "# balances_single_threaded =\n",
            "balances_single_threaded = false\n",
        )
        .replace(
            "# sensor_hz_shared_group =\n",
            "sensor_hz_shared_group = 50\n",
        )
        .replace("# sensor_hz_own_group =\n", "sensor_hz_own_group = 50\n")
        .replace("why = \"\"", "why = \"one thread, one callback at a time\"");
    std::fs::write(&file, text).unwrap();
    // Every check passes; four of the five predictions miss, so the exercise is not passed.
    let o = ratelab(&["exercise", "ex7", "--dir", d]);
    let out = String::from_utf8_lossy(&o.stdout);
    assert_eq!(o.status.code(), Some(1), "{}", stderr(&o));
    assert!(
        stderr(&o).contains("4 predictions missed or could not be read (see above)")
            && !stderr(&o).contains("check"),
        "{}",
        stderr(&o)
    );
    for row in [
        "single_threaded       |    0 |      33.3 |     166 |",
        "2 threads, one group  |    2 |      33.3 |     166 |",
        "2 threads, own group  |    1 |      50.0 |       0 |",
    ] {
        assert!(out.contains(row), "{row}: {out}");
    }
    assert!(out.contains("[ok]") && !out.contains("[!!]"), "{out}");
    assert!(
        out.contains("You predicted the sensor achieves 50 Hz on two threads, in the policy's group; it achieved 33.3 Hz: more than 20% off.")
            && out.contains("You predicted the pole falls single-threaded; it stayed up on every seed.")
            && out.contains("You predicted the sensor achieves 50 Hz on two threads, in a group of its own; it achieved 50.0 Hz: right."),
        "{out}"
    );
    assert!(
        out.contains("Reconcile: an executor runs one callback per thread"),
        "{out}"
    );
}

#[test]
fn exercise_ex5_runs_on_the_graph_its_bands_name_and_reconciles() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = exercise_copy(tmp.path(), &["ex5_watchdog.toml"]);
    let d = dir.to_str().unwrap();
    let o = ratelab(&["exercise", "ex5", "--dir", d]);
    assert_eq!(o.status.code(), Some(2));
    assert!(
        stderr(&o).contains("has no prediction yet"),
        "{}",
        stderr(&o)
    );
    let file = dir.join("ex5_watchdog.toml");
    let text = std::fs::read_to_string(&file)
        .unwrap()
        .replace("# survives_low_loss =\n", "survives_low_loss = false\n")
        .replace("# survives_high_loss =\n", "survives_high_loss = false\n")
        .replace(
            "# keeps_it_up =\n",
            "keeps_it_up = [\"hold\", \"reliable\"]\n",
        )
        .replace("# reliable_latency_ms =\n", "reliable_latency_ms = 20\n")
        .replace("why = \"\"", "why = \"a lost command is an old command\"");
    std::fs::write(&file, text).unwrap();
    // Every check passes; the predictions that miss leave the exercise not passed.
    let o = ratelab(&["exercise", "ex5", "--dir", d]);
    let out = String::from_utf8_lossy(&o.stdout);
    assert_eq!(o.status.code(), Some(1), "{}", stderr(&o));
    assert!(out.contains("80%, deadline 30 ms + zero |"), "{out}");
    assert!(out.contains("[ok]") && !out.contains("[!!]"), "{out}");
    assert!(
        out.contains("You predicted the pole falls at 20% loss, best effort; it stayed up on every seed.")
            && out.contains("You predicted these keep the pole up at 80% loss: hold, reliable; what did: zero, reliable.")
            && out.contains("You predicted the pole falls at 80% loss, best effort; it fell: right.")
            && out.contains("; missed: survives_low_loss, keeps_it_up"),
        "{out}"
    );
    assert!(out.contains("Reconcile:"), "{out}");
    // Overrides apply to that graph; faults are refused as for every exercise.
    let o = ratelab(&["exercise", "ex5", "--dir", d, "--stall", "safety@1+1"]);
    assert_eq!(o.status.code(), Some(2));
    assert!(stderr(&o).contains("inject no faults"), "{}", stderr(&o));
    // Without its graph beside the bands, a one-line error naming it.
    std::fs::remove_file(tmp.path().join("graphs/cartpole-safety.toml")).unwrap();
    let o = ratelab(&["exercise", "ex5", "--dir", d]);
    assert_eq!(o.status.code(), Some(2), "{}", stderr(&o));
    assert!(
        stderr(&o).contains("cartpole-safety.toml"),
        "{}",
        stderr(&o)
    );
    let o = ratelab(&["exercise", "ex15", "--dir", d]);
    assert!(
        o.status.code() == Some(2)
            && stderr(&o).contains(
                "expected ex1, ex2, ex3, ex4, ex5, ex6, ex7, ex8, ex9, ex10, ex11, ex12, ex13 or ex14"
            ),
        "{}",
        stderr(&o)
    );
}

#[test]
fn exercise_ex6_runs_the_learners_node_and_says_whether_it_limits() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = exercise_copy(tmp.path(), &["ex6_own_node.toml", "ex6_my_limiter.py"]);
    let d = dir.to_str().unwrap();
    let file = dir.join("ex6_own_node.toml");
    let text = std::fs::read_to_string(&file)
        .unwrap()
        .replace("# smallest_clamp_n =\n", "smallest_clamp_n = 2\n")
        .replace("why = \"\"", "why = \"catching the pole takes newtons\"");
    std::fs::write(&file, text).unwrap();
    // The template as shipped is refused: measuring it would say nothing of the learner's.
    let o = ratelab(&["exercise", "ex6", "--dir", d]);
    assert_eq!(o.status.code(), Some(2), "{}", stderr(&o));
    assert_eq!(stderr(&o).trim_end().lines().count(), 1, "{}", stderr(&o));
    assert!(
        stderr(&o).contains("ex6_my_limiter.py is the template as shipped"),
        "{}",
        stderr(&o)
    );
    // Touched but still passing commands through: not the built-in limiter, a check fails,
    // and the exercise exits 1 (not passed; 2 is for what kept it from running).
    let script = dir.join("ex6_my_limiter.py");
    let touched = std::fs::read_to_string(&script)
        .unwrap()
        .replace("# TODO: clamp", "# not yet: clamp");
    std::fs::write(&script, touched).unwrap();
    let o = ratelab(&["exercise", "ex6", "--dir", d]);
    let out = String::from_utf8_lossy(&o.stdout);
    assert_eq!(o.status.code(), Some(1), "{}", stderr(&o));
    assert!(
        stderr(&o).contains("1 check failed (see above): the exercise is not passed"),
        "{}",
        stderr(&o)
    );
    assert!(out.contains("your node (ex6_my_limiter.py)"), "{out}");
    assert!(out.contains("<- differs"), "{out}");
    assert!(
        out.contains("Your node does not limit as the built-in safety node does"),
        "{out}"
    );
    assert!(out.contains("[!!]"), "{out}");
    // Try it in the lab: the learner's node, beside the exercise's files.
    assert!(
        out.contains(&format!(
            "./scripts/lab.sh --clock virtual --graph {}",
            dir.join("ex6_my_limiter.toml").display()
        )),
        "{out}"
    );
    // Written, it limits as the built-in node does, and the prediction is reconciled.
    let written = std::fs::read_to_string(&script).unwrap().replace(
        "Force(newtons=msg.newtons)",
        "Force(newtons=min(max(msg.newtons, -self.max_force_n), self.max_force_n))",
    );
    // Every check passes now, but the prediction (2 N) missed: exit 1, and it says so.
    std::fs::write(&script, written).unwrap();
    let o = ratelab(&["exercise", "ex6", "--dir", d]);
    let out = String::from_utf8_lossy(&o.stdout);
    assert_eq!(o.status.code(), Some(1), "{}", stderr(&o));
    assert!(
        stderr(&o).contains(
            "1 prediction missed or could not be read (see above): the exercise is not passed"
        ),
        "{}",
        stderr(&o)
    );
    assert!(out.contains("[ok]") && !out.contains("[!!]"), "{out}");
    assert!(
        out.contains("You predicted the smallest clamp that keeps the pole up is 2 N; with your node it was 0.75 N.")
            && out.contains("Your prediction: 0 of 1 right; missed: smallest_clamp_n."),
        "{out}"
    );
    assert!(
        out.contains("Your node limits as the built-in safety node does"),
        "{out}"
    );
    // A script that does not load: one line naming FILE:LINE, exit 2.
    std::fs::write(&script, "x = (\n").unwrap();
    let o = ratelab(&["exercise", "ex6", "--dir", d]);
    assert_eq!(o.status.code(), Some(2));
    assert!(
        stderr(&o).contains("ex6_my_limiter.py:1: SyntaxError"),
        "{}",
        stderr(&o)
    );
}

#[test]
fn exercise_ex4_shows_the_stale_queue_and_reconciles() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = exercise_copy(tmp.path(), &["ex4_stale_queue.toml"]);
    let file = dir.join("ex4_stale_queue.toml");
    let text = std::fs::read_to_string(&file)
        .unwrap()
        .replace("# latest_balances =\n", "latest_balances = true\n")
        .replace("# fifo_balances =\n", "fifo_balances = true\n")
        .replace(
            "# fifo_latency_at_fall_ms =\n",
            "fifo_latency_at_fall_ms = 100\n",
        )
        .replace("# lifespan_balances =\n", "lifespan_balances = true\n")
        .replace("why = \"\"", "why = \"nothing is dropped\"");
    std::fs::write(&file, text).unwrap();
    // Every check passes; the fifo predictions miss, so the exercise is not passed.
    let o = ratelab(&["exercise", "ex4", "--dir", dir.to_str().unwrap()]);
    let out = String::from_utf8_lossy(&o.stdout);
    assert_eq!(o.status.code(), Some(1), "{}", stderr(&o));
    assert!(out.contains("fifo, lifespan 20 ms"), "{out}");
    assert!(out.contains("[ok]") && !out.contains("[!!]"), "{out}");
    assert!(
        out.contains("You predicted the pole stays up with fifo; it fell.")
            && out.contains("You predicted 100 ms of sense->act latency at the FIFO fall; it was ")
            && out.contains("over the seeds: more than 20% off.")
            && out.contains(
                "Your prediction: 2 of 4 right; missed: fifo_balances, fifo_latency_at_fall_ms."
            ),
        "{out}"
    );
}

#[test]
fn a_second_sigterm_exits_at_once_and_says_so() {
    let _m = crate::machine::shared();
    let dir = tempfile::tempdir().unwrap();
    // A launch across processes: its clean stop (each process's report) takes long
    // enough for the second signal to find it still stopping.
    let port = crate::distributed::free_port();
    let child = Command::new(env!("CARGO_BIN_EXE_ratelab"))
        .args([
            "launch",
            "--processes",
            "--clock",
            "real",
            "--duration",
            "60",
        ])
        .args(["--listen", &format!("tls/127.0.0.1:{port}"), "--out"])
        .arg(dir.path())
        .stdout(std::process::Stdio::null())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    std::thread::sleep(std::time::Duration::from_millis(3000));
    for _ in 0..2 {
        // SAFETY: plain kill(2) on our child.
        unsafe { libc::kill(child.id() as i32, libc::SIGTERM) };
        std::thread::sleep(std::time::Duration::from_millis(50));
    }
    let o = child.wait_with_output().unwrap();
    let err = stderr(&o);
    assert_eq!(o.status.code(), Some(130), "{err}");
    assert!(
        err.contains("interrupted again: exiting at once, without a summary or files"),
        "{err}"
    );
    assert!(!dir.path().join("metrics.json").exists());
    crate::distributed::assert_none_left(port, std::time::Duration::from_millis(500));
}

/// `lab --attach` without a terminal points to `top`, which finds the launch the same way:
/// no made-up endpoint (it once named 7449 whatever port the launch had).
#[test]
fn attach_without_a_terminal_points_to_top() {
    assert_usage_error(
        &["lab", "--attach"],
        "without one, `ratelab top` prints the same figures as text",
    );
    assert_usage_error(
        &["lab", "--attach", "--connect", "tls/127.0.0.1:7500"],
        "`ratelab top --connect tls/127.0.0.1:7500` prints",
    );
}

/// Two flags that set the same rate differently are refused, not silently resolved; a fault
/// that starts after the run ends is warned about (#25).
#[test]
fn conflicting_rates_are_refused_and_a_fault_after_the_end_is_warned_about() {
    assert_usage_error(
        &["run", "--smoke", "--rate", "policy=5", "--control-hz", "10"],
        "--rate policy=5 and --control-hz (10 Hz) both set the rate of node 'policy'; give one",
    );
    assert_usage_error(
        &["run", "--smoke", "--rate", "sensor=20", "--sensor-hz", "50"],
        "both set the rate of node 'sensor'",
    );
    assert_usage_error(
        &["run", "--smoke", "--rate", "policy=50", "--break"],
        "--rate policy=50 and --break (5 Hz) both set",
    );
    assert_usage_error(
        &["run", "--smoke", "--control-hz", "10", "--break"],
        "--break sets the policy to 5 Hz and --control-hz to 10 Hz; give one",
    );
    // One flag given twice with two values: neither wins unseen.
    assert_usage_error(
        &["run", "--smoke", "--rate", "policy=5", "--rate", "policy=8"],
        "--rate policy=5 and --rate policy=8 both set the rate of node 'policy'; give one",
    );
    assert_usage_error(
        &["run", "--smoke", "--qos", "/obs:depth=3", "--qos", "/obs:depth=5"],
        "--qos /obs:depth=3 and --qos /obs:depth=5 both set the history depth of topic '/obs'; give one",
    );
    // The same value twice is no conflict.
    let o = ratelab(&[
        "run",
        "--smoke",
        "--rate",
        "policy=10",
        "--rate",
        "policy=10",
        "--control-hz",
        "10",
    ]);
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    let o = ratelab(&[
        "run",
        "--clock",
        "virtual",
        "--duration",
        "2",
        "--stall",
        "policy@20+1",
    ]);
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    assert!(
        stderr(&o).contains("warning: the --stall of 'policy' at 20 s starts after the run ends (2 s): it does nothing"),
        "{}",
        stderr(&o)
    );
    // Nor does the summary list it as if it had happened; one that did is listed.
    let summary = String::from_utf8_lossy(&o.stdout);
    assert!(!summary.contains("liveliness:"), "{summary}");
    let o = ratelab(&[
        "run",
        "--clock",
        "virtual",
        "--duration",
        "2",
        "--stall",
        "policy@1+0.2",
        "--kill",
        "sensor@20",
    ]);
    let summary = String::from_utf8_lossy(&o.stdout);
    assert!(
        summary.contains("liveliness: policy stalled at 1.00 s for 0.20 s: ")
            && !summary.contains("sensor killed"),
        "{summary}"
    );
    // A launch says it too (one process, as `run`; the warning is given once the run's
    // duration is final: the lab and a launch on a terminal run until quit, and give none).
    let o = ratelab(&[
        "launch",
        "--clock",
        "virtual",
        "--duration",
        "2",
        "--kill",
        "policy@5",
    ]);
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    assert_eq!(
        stderr(&o)
            .matches("warning: the --kill of 'policy' at 5 s starts after the run ends (2 s)")
            .count(),
        1,
        "{}",
        stderr(&o)
    );
}

/// `docs/graphs.md`'s section between `<!-- generated: ratelab WHAT -->` and
/// `<!-- end: ratelab WHAT -->`, without the markers' lines (the README sends the reader
/// there for the tables).
fn readme_section(what: &str) -> String {
    let readme = std::fs::read_to_string(crate::repo("docs/graphs.md")).unwrap();
    let start = format!("<!-- generated: ratelab {what} -->\n");
    let end = format!("<!-- end: ratelab {what} -->");
    let from = readme
        .find(&start)
        .unwrap_or_else(|| panic!("docs/graphs.md has no {start:?}"))
        + start.len();
    let to = from + readme[from..].find(&end).expect("the section's end");
    readme[from..to].to_string()
}

/// The reference's tables of node kinds and message types (`docs/graphs.md`) are the registry's, as `ratelab
/// kinds` and `ratelab msgs` print them: a kind or a type added, or a parameter's range
/// changed, without the README following fails here (paste the command's output there).
#[test]
fn the_readme_tables_of_kinds_and_messages_are_the_registrys() {
    for what in ["kinds", "msgs"] {
        let o = ratelab(&[what]);
        assert!(o.status.success(), "{}", stderr(&o));
        let printed = String::from_utf8(o.stdout).unwrap();
        assert_eq!(
            readme_section(what),
            printed,
            "docs/graphs.md's table differs from `ratelab {what}`: paste its output between the markers"
        );
    }
    // What the tables must show: every built-in kind and type, parameters with units and
    // ranges, ROS 2 types.
    // (Which kinds it lists is the registry's: `ratelab kinds` prints them, and a unit test
    // keeps the registry's built-in kinds those of `graph/nodes/`.)
    let kinds = readme_section("kinds");
    for needle in ["`max_force_n` N (default", "`cutoff_hz` Hz"] {
        assert!(kinds.contains(needle), "{needle} missing:\n{kinds}");
    }
    let msgs = readme_section("msgs");
    for needle in [
        "| `state` | `State` |",
        "| `force` | `Force` | `newtons` (N) | `std_msgs/msg/Float64` |",
        "`sensor_msgs/msg/JointState`",
    ] {
        assert!(msgs.contains(needle), "{needle} missing:\n{msgs}");
    }
}

/// A prediction that cannot be read (of another type than its key asks) is said in the
/// reconcile, and the exercise exits 1: it ran, but is not passed.
#[test]
fn an_exercise_whose_prediction_cannot_be_read_exits_1() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = exercise_copy(tmp.path(), &["ex2_queue_trap.toml"]);
    let file = dir.join("ex2_queue_trap.toml");
    let text = std::fs::read_to_string(&file)
        .unwrap()
        .replace(
            "# deep_queue_obs_drops =\n",
            "deep_queue_obs_drops = \"none\"\n",
        )
        .replace("# deep_queue_balances =\n", "deep_queue_balances = false\n")
        .replace("why = \"\"", "why = \"the newest only\"");
    std::fs::write(&file, text).unwrap();
    let o = ratelab(&["exercise", "ex2", "--dir", dir.to_str().unwrap()]);
    let out = String::from_utf8_lossy(&o.stdout);
    assert_eq!(o.status.code(), Some(1), "{out}{}", stderr(&o));
    assert!(
        out.contains(
            "Your prediction `deep_queue_obs_drops` is not of the type this exercise reads (the comment above it in the file gives an example)."
        ),
        "{out}"
    );
    assert!(!out.contains("[!!]"), "the checks pass: {out}");
    assert!(
        stderr(&o).starts_with(
            "error: 1 prediction missed or could not be read (see above): the exercise is not passed"
        ),
        "{}",
        stderr(&o)
    );
    assert!(
        out.contains("Your prediction: 1 of 2 right; not read: deep_queue_obs_drops."),
        "{out}"
    );
}

/// The README's 80×24 screen is the lab's snapshot test's (`dropping_80x24`), line for line
/// (trailing blanks aside): a change to the lab that moves it fails here, not silently.
#[test]
fn the_readme_s_lab_screen_is_the_snapshot_s() {
    let snap = std::fs::read_to_string(crate::repo(
        "lab/tui/snapshots/ratelab_lab__tui__tests__dropping_80x24.snap",
    ))
    .unwrap();
    let screen: Vec<String> = snap
        .lines()
        .filter_map(|l| l.strip_prefix('"').and_then(|l| l.strip_suffix('"')))
        .map(|l| {
            l.replace("\\\"", "\"")
                .replace("\\\\", "\\")
                .trim_end()
                .to_string()
        })
        .collect();
    assert_eq!(screen.len(), 24, "{snap}");
    let readme = std::fs::read_to_string(crate::repo("README.md")).unwrap();
    let start = readme
        .find("```text\n ratelab  virtual clock")
        .expect("the screen")
        + 8;
    let shown: Vec<&str> = readme[start..].lines().take(24).collect();
    assert_eq!(
        shown, screen,
        "README.md's 80x24 screen differs from the snapshot"
    );
}

/// `ratelab process` runs one process of a launch; `node`, its old name, is the same
/// command (scripts and processes started by hand keep working), and the help lists the
/// process under its one name.
#[test]
fn a_process_of_a_launch_is_ratelab_process_and_node_is_its_old_name() {
    let new = ratelab(&["process", "--help"]);
    let old = ratelab(&["node", "--help"]);
    assert!(new.status.success(), "{}", stderr(&new));
    assert!(old.status.success(), "{}", stderr(&old));
    let text =
        |o: &Output| String::from_utf8_lossy(&o.stdout).replace("ratelab node", "ratelab process");
    assert_eq!(text(&new), text(&old));
    assert!(text(&new).contains("--process <NAME>"), "{}", text(&new));
    let help = String::from_utf8_lossy(&ratelab(&["--help"]).stdout).to_string();
    assert!(help.contains("\n  process "), "{help}");
    assert!(!help.contains("\n  node "), "{help}");
    assert!(!help.contains("placement group"), "{help}");
}
