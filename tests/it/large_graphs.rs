//! Graphs at the size of real robot software: a generated graph of 1,000 nodes runs byte
//! for byte the same twice in one process and across 8 processes, and every bound of
//! `ratelab::limits` refuses in one line that names it.

use crate::distributed::{assert_one_line_exit_2, ratelab, text};
use std::path::Path;
use std::time::Duration;

/// `ratelab graph --nodes N --processes P` written to `dir/name`.
pub(crate) fn generated(dir: &Path, name: &str, nodes: usize, processes: usize) -> String {
    let o = ratelab(&[
        "graph",
        "--nodes",
        &nodes.to_string(),
        "--processes",
        &processes.to_string(),
    ]);
    assert!(o.status.success(), "{}", text(&o.stderr));
    let path = dir.join(name);
    std::fs::write(&path, &o.stdout).unwrap();
    path.to_str().unwrap().to_string()
}

/// `ratelab launch GRAPH --processes ARGS --out DIR` succeeded in `processes` processes:
/// its metrics.json.
fn launched(graph: &str, args: &[&str], dir: &Path, processes: usize) -> String {
    let o = ratelab(
        &[
            &["launch", graph, "--processes"][..],
            args,
            &["--out", dir.to_str().unwrap()],
        ]
        .concat(),
    );
    let out = text(&o.stdout);
    assert!(o.status.success(), "{out}{}", text(&o.stderr));
    let placed = format!("in {processes} processes: robot [");
    assert!(out.contains(&placed), "{out:.2000}");
    // The placement line names each process's first nodes and counts the rest (it was
    // every name: 1,000 of them on one line).
    let line = out.lines().find(|l| l.contains(&placed)).unwrap();
    assert!(line.len() < 1000 && line.contains(" more]"), "{line:.2000}");
    std::fs::read_to_string(dir.join("metrics.json")).unwrap()
}

/// `ratelab ARGS --out DIR` succeeded: (metrics.json, trace.csv).
fn outputs(args: &[&str], dir: &Path) -> (String, String) {
    let o = ratelab(&[args, &["--out", dir.to_str().unwrap()]].concat());
    assert!(o.status.success(), "{}{}", text(&o.stdout), text(&o.stderr));
    let read = |f: &str| std::fs::read_to_string(dir.join(f)).unwrap();
    (read("metrics.json"), read("trace.csv"))
}

#[test]
fn a_thousand_node_graph_runs_byte_identically_twice_in_one_process() {
    let _m = crate::machine::shared();
    let dir = tempfile::tempdir().unwrap();
    let g = generated(dir.path(), "g.toml", 1000, 1);
    let run = [
        "run",
        "--graph",
        &g,
        "--clock",
        "virtual",
        "--duration",
        "3",
    ];
    let first = outputs(&run, &dir.path().join("a"));
    let second = outputs(&run, &dir.path().join("b"));
    assert!(first == second, "two runs of one generated graph differ");
    // Every node ran, and every topic is in the metrics and the trace.
    let m: serde_json::Value = serde_json::from_str(&first.0).unwrap();
    assert_eq!(m["nodes"].as_object().unwrap().len(), 1000);
    let topics = m["topics"].as_object().unwrap();
    assert_eq!(topics.len(), 999);
    assert!(
        topics.values().all(|t| t["published"].as_u64() > Some(0)),
        "every topic published"
    );
    let header = first.1.lines().next().unwrap();
    assert_eq!(header.split(',').count(), 8 + 2 * 999, "{header:.200}");
    // The summary names the first nodes and sums up the rest, on one line each.
    let o = ratelab(&run);
    let out = text(&o.stdout);
    assert!(
        out.contains("992 more nodes: 10 Hz ×249, 20 Hz ×247, 50 Hz ×248, 100 Hz ×248"),
        "{out:.2000}"
    );
    assert!(out.contains("991 more topics: "), "{out:.2000}");
    assert!(out.lines().all(|l| l.len() < 1000), "{out:.2000}");
    // Topics of different depths: the first few named, the rest counted.
    let o = ratelab(&[&run[..], &["--depth", "/c_0/pos=4"]].concat());
    let out = text(&o.stdout);
    assert!(
        out.contains("depths /obs 1, /action 1, /c_0/pos 4, ") && out.contains(", and 991 more\n"),
        "{out:.2000}"
    );
}

#[test]
fn a_thousand_node_graph_across_eight_processes_equals_the_in_process_run() {
    let _m = crate::machine::shared();
    let dir = tempfile::tempdir().unwrap();
    let g = generated(dir.path(), "g.toml", 1000, 8);
    let common = ["--clock", "virtual", "--duration", "1", "--seed", "3"];
    let one = outputs(
        &[&["run", "--graph", &g][..], &common].concat(),
        &dir.path().join("one"),
    );
    // Twice across the processes: each launch equals the run in one process, byte for byte
    // (a launch writes metrics.json; the trace is one process's).
    for out_dir in ["many", "again"] {
        let many = launched(&g, &common, &dir.path().join(out_dir), 8);
        assert!(
            one.0 == many,
            "the launch's metrics.json ({out_dir}) differs from one process's"
        );
    }
}

/// Watchers attached to a large launch under the virtual clock (`ratelab top` polled, as a
/// learner opens one beside it, and a subscriber to the whole figures, as `lab --attach`
/// is) never break the run. Each of the 8 processes' whole figures is hundreds of KB every
/// 100 ms; sent at Zenoh's default priority they filled the queue of the process's link
/// that its ticks' own puts needed, on the one Zenoh thread that empties it, and after 5 s
/// Zenoh closed the link: the processes read their launcher gone and the run failed
/// ("process 'ctl_2': the launcher went away", observed with `top` polled, when `top` read
/// the whole figures; it reads the counts alone now, so the subscriber is what sends them).
#[test]
fn a_watcher_never_breaks_a_large_launch_under_the_virtual_clock() {
    use crate::distributed::{bin, exit_within, free_port};
    use ratelab::distributed::zenoh::Wait;
    let _m = crate::machine::shared();
    let dir = tempfile::tempdir().unwrap();
    let g = generated(dir.path(), "g.toml", 1000, 8);
    let ep = format!("tls/127.0.0.1:{}", free_port());
    let creds = dir.path().join("creds.toml");
    let log = dir.path().join("launch.log");
    let mut launch = bin()
        .args(["launch", &g, "--processes", "--clock", "virtual"])
        .args(["--duration", "3", "--seed", "3", "--listen", &ep])
        .arg("--export-credentials")
        .arg(&creds)
        .arg("--out")
        .arg(dir.path().join("out"))
        .stdout(std::fs::File::create(&log).unwrap())
        .stderr(std::fs::File::create(dir.path().join("launch.err")).unwrap())
        .spawn()
        .unwrap();
    let started = std::time::Instant::now();
    let session = crate::distributed::observer_of(&ep, &creds, Duration::from_secs(60));
    let batches = std::sync::Arc::new(std::sync::atomic::AtomicUsize::new(0));
    let counted = batches.clone();
    let _whole = session
        .declare_subscriber("ratelab/*/@stats/*")
        .callback(move |s| {
            let m = ratelab::distributed::process::LiveStats::from_sample(&s);
            if m.is_some_and(|m| !m.steps.is_empty() || !m.counters.is_empty()) {
                counted.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
            }
        })
        .wait()
        .unwrap();
    let mut watched = 0;
    while launch.try_wait().unwrap().is_none() && started.elapsed() < Duration::from_secs(240) {
        let top = bin()
            .args(["top", "--once", "--connect", &ep, "--credentials"])
            .arg(&creds)
            .output()
            .unwrap();
        watched += usize::from(top.status.success() && text(&top.stdout).contains("8 processes"));
        std::thread::sleep(Duration::from_millis(200));
    }
    let status = exit_within(&mut launch, 60);
    let said = std::fs::read_to_string(dir.path().join("launch.err")).unwrap();
    assert!(status.success(), "{said}");
    assert!(!said.contains("went away"), "{said}");
    // Watched through much of the run, not only its last moments, the whole figures with
    // their batches too.
    assert!(watched >= 5, "watched {watched} times");
    let batches = batches.load(std::sync::atomic::Ordering::Relaxed);
    assert!(batches >= 5, "{batches} whole figures with a batch");
}

/// A launch of 64 processes (issue 51: "launches of 64+ processes"): a 256-node graph dealt
/// out to 64 processes runs the run of one process, byte for byte. `ratelab graph` refuses
/// 64 processes of fewer than 255 nodes, rather than fill fewer without a word.
#[test]
fn a_launch_of_sixty_four_processes_equals_the_in_process_run() {
    // 64 processes starting on the machine's cores: nothing else beside them.
    let _m = crate::machine::alone();
    let dir = tempfile::tempdir().unwrap();
    let g = generated(dir.path(), "g.toml", 256, 64);
    let o = ratelab(&["graph", "--nodes", "100", "--processes", "64"]);
    assert_one_line_exit_2(&o, "--nodes 100 fills at most 25 processes");
    assert_one_line_exit_2(&o, "--processes 64 needs --nodes 255 or more");
    let common = ["--clock", "virtual", "--duration", "0.2", "--seed", "5"];
    let one = outputs(
        &[&["run", "--graph", &g][..], &common].concat(),
        &dir.path().join("one"),
    );
    let many = launched(&g, &common, &dir.path().join("many"), 64);
    assert!(
        one.0 == many,
        "the 64-process launch's metrics.json differs from one process's"
    );
}

#[test]
fn every_bound_refuses_in_one_line_naming_it() {
    let dir = tempfile::tempdir().unwrap();
    let path = |name: &str| dir.path().join(name).to_str().unwrap().to_string();
    let chapter = std::fs::read_to_string(crate::repo("graphs/cartpole.toml")).unwrap();
    // A graph file over 16 MiB, refused before it is parsed.
    let big = path("big.toml");
    let mut text_over = chapter.clone();
    text_over.push_str(&"#".repeat(16 << 20));
    std::fs::write(&big, text_over).unwrap();
    let o = ratelab(&["run", "--graph", &big, "--clock", "virtual"]);
    for needle in ["big.toml", "16777216"] {
        assert_one_line_exit_2(&o, needle);
    }
    // More nodes than MAX_NODES: the 65,537th is the culprit.
    let many = path("many.toml");
    let mut nodes = chapter.clone();
    for i in 0..ratelab::limits::MAX_NODES {
        nodes.push_str(&format!(
            "[[node]]\nname = \"n{i}\"\nkind = \"sensor\"\nrate_hz = 1\n"
        ));
    }
    std::fs::write(&many, nodes).unwrap();
    let o = ratelab(&["run", "--graph", &many, "--clock", "virtual"]);
    for needle in [
        "a graph has at most 65536 nodes",
        "ratelab::limits::MAX_NODES",
    ] {
        assert_one_line_exit_2(&o, needle);
    }
    // More topics than MAX_TOPICS: the 65,537th is the culprit, wherever the tables are.
    let wide = path("wide.toml");
    let mut topics = chapter.clone();
    for i in 2..=ratelab::limits::MAX_TOPICS {
        topics.push_str(&format!(
            "[[topic]]\nname = \"/t{i}\"\ntype = \"state\"\ndepth = 1\n"
        ));
    }
    // The culprit's table starts on the line above its name (lines count from 1).
    let culprit = topics
        .lines()
        .position(|l| l == "name = \"/t65536\"")
        .unwrap();
    std::fs::write(&wide, topics).unwrap();
    let o = ratelab(&["run", "--graph", &wide, "--clock", "virtual"]);
    for needle in [
        &format!("wide.toml:{culprit}:1: error: "),
        "a graph has at most 65536 topics",
        "ratelab::limits::MAX_TOPICS",
    ] {
        assert_one_line_exit_2(&o, needle);
    }
    // A run longer than MAX_DURATION_S (ten years of run time).
    let o = ratelab(&["run", "--clock", "virtual", "--duration", "1e9"]);
    assert_one_line_exit_2(&o, "ratelab::limits::MAX_DURATION_S");
    // A Python node reading more than MAX_NODE_PORTS topics.
    let ports = path("ports.toml");
    let list: Vec<String> = (0..257).map(|i| format!("\"/t{i}\"")).collect();
    std::fs::write(
        &ports,
        format!(
            "{chapter}\n[[node]]\nname = \"wide\"\nkind = \"python\"\nscript = \"w.py\"\nrate_hz = 1\nsubscribes = [{}]\n",
            list.join(", ")
        ),
    )
    .unwrap();
    let o = ratelab(&["run", "--graph", &ports, "--clock", "virtual"]);
    for needle in [
        "subscribes names 257 topics; a node has at most 256",
        "ratelab::limits::MAX_NODE_PORTS",
    ] {
        assert_one_line_exit_2(&o, needle);
    }
    // A launch of more than MAX_PROCESSES processes: a node without a `process` is its own.
    let g = generated(dir.path(), "unplaced.toml", 1003, 1);
    let o = ratelab(&["launch", &g, "--processes", "--clock", "virtual"]);
    for needle in [
        "places its nodes in 752 processes; a launch has at most 256",
        "ratelab::limits::MAX_PROCESSES",
    ] {
        assert_one_line_exit_2(&o, needle);
    }
    // Refused before the placement is said (a line naming all 752 processes came first).
    assert!(
        o.stdout.is_empty(),
        "{}",
        String::from_utf8_lossy(&o.stdout)
    );
    // A node given more than MAX_NODE_PARAMS parameters.
    let params = path("params.toml");
    let table: Vec<String> = (0..=ratelab::limits::MAX_NODE_PARAMS)
        .map(|i| format!("p{i} = {i}"))
        .collect();
    std::fs::write(
        &params,
        format!(
            "{chapter}\n[[node]]\nname = \"tuned\"\nkind = \"python\"\nscript = \"w.py\"\nrate_hz = 1\nparams = {{ {} }}\n",
            table.join(", ")
        ),
    )
    .unwrap();
    let o = ratelab(&["run", "--graph", &params, "--clock", "virtual"]);
    for needle in [
        "a node has at most 1024 params",
        "ratelab::limits::MAX_NODE_PARAMS",
    ] {
        assert_one_line_exit_2(&o, needle);
    }
    // More faults than MAX_FAULTS.
    let mut args = vec!["run".to_string(), "--clock".into(), "virtual".into()];
    for i in 0..=ratelab::limits::MAX_FAULTS {
        args.extend(["--stall".into(), format!("policy@{i}+0.001")]);
    }
    let args: Vec<&str> = args.iter().map(String::as_str).collect();
    let o = ratelab(&args);
    for needle in ["at most 64 faults, got 65", "ratelab::limits::MAX_FAULTS"] {
        assert_one_line_exit_2(&o, needle);
    }
    // `ratelab graph` itself keeps to the bounds.
    let o = ratelab(&["graph", "--nodes", "65537"]);
    assert_eq!(o.status.code(), Some(2), "{}", text(&o.stderr));
    // A rate refused by its flag's name, written once (it came with four dashes).
    let o = ratelab(&["graph", "--nodes", "10", "--controller-hz", "0"]);
    let err = text(&o.stderr);
    assert_eq!(o.status.code(), Some(2), "{err}");
    assert!(
        err.contains("--controller-hz must be") && !err.contains("---"),
        "{err}"
    );
}

/// A thinned trace says so where the files are said to be written, and only then.
#[test]
fn a_thinned_trace_says_so() {
    let dir = tempfile::tempdir().unwrap();
    let said = |every: &str, out: &str| {
        let out = dir.path().join(out);
        let o = ratelab(&[
            "run",
            "--clock",
            "virtual",
            "--duration",
            "2",
            "--trace-every",
            every,
            "--out",
            out.to_str().unwrap(),
        ]);
        assert_eq!(o.status.code(), Some(0), "{}", text(&o.stderr));
        let rows = std::fs::read_to_string(out.join("trace.csv"))
            .unwrap()
            .lines()
            .count();
        (text(&o.stdout), rows - 1)
    };
    let (thinned, rows) = said("10", "thin");
    assert!(
        thinned.contains("trace.csv keeps one actuator step in 10 (--trace-every 10: steps 1, 11, … and the last); the metrics count every step"),
        "{thinned}"
    );
    assert_eq!(rows, 11, "steps 1, 11, …, 91 and the last, 101");
    let (whole, rows) = said("1", "whole");
    assert!(!whole.contains("trace.csv keeps one"), "{whole}");
    assert_eq!(rows, 101);
}

#[test]
fn a_day_of_virtual_run_time_takes_no_more_memory_than_ten_minutes() {
    let _m = crate::machine::shared();
    let dir = tempfile::tempdir().unwrap();
    let run = |secs: &str| {
        let args = ["run", "--clock", "virtual", "--duration", secs];
        let o = crate::hostile::measure_child(&args, dir.path(), Duration::from_secs(600));
        assert_eq!(o.code, Some(0), "a {secs} s run: {o:?}");
        o.peak_mib
    };
    let ten_minutes = run("600");
    let day = run("86400");
    assert!(
        day * 2.0 <= ten_minutes * 3.0,
        "a day's run peaked at {day} MiB, ten minutes' at {ten_minutes} MiB"
    );
    // The trace of a long run is what the user asks for: every 50th step of ten minutes,
    // and the last.
    let (metrics, trace) = outputs(
        &[
            "run",
            "--clock",
            "virtual",
            "--duration",
            "600.5",
            "--trace-every",
            "50",
        ],
        &dir.path().join("thin"),
    );
    let rows: Vec<&str> = trace.lines().skip(1).collect();
    // Steps 1, 51, …, 30001, and the last, 30026.
    assert_eq!(rows.len(), 601 + 1, "{:?}", &rows[..3]);
    assert!(rows[1].starts_with("51,"), "{}", rows[1]);
    assert!(rows[600].starts_with("30001,"), "{}", rows[600]);
    assert!(rows[601].starts_with("30026,"), "{}", rows[601]);
    let m: serde_json::Value = serde_json::from_str(&metrics).unwrap();
    assert_eq!(
        m["steps"].as_u64(),
        Some(30026),
        "the metrics count every step"
    );
}

/// A long run's trace goes to trace.csv as the run goes, never into memory (issue 75: a
/// day-long run with `--out` aborted at 4.3 GB, its step records kept for the file, 1 064
/// bytes each, 50 a second of run time). With `--out`, two hours of run time (360 001
/// steps: 365 MiB of records before) peak within 1.5× of a minute's, and under 128 MiB;
/// the files are whole, and no temporary file is left.
#[test]
fn a_long_run_with_out_writes_its_trace_as_it_goes_in_flat_memory() {
    let _m = crate::machine::shared();
    let dir = tempfile::tempdir().unwrap();
    let run = |secs: &str| {
        let out = dir.path().join(format!("out-{secs}"));
        let args = [
            "run",
            "--clock",
            "virtual",
            "--duration",
            secs,
            "--out",
            out.to_str().unwrap(),
        ];
        let o = crate::hostile::measure_child(&args, dir.path(), Duration::from_secs(600));
        assert_eq!(o.code, Some(0), "a {secs} s run: {o:?}");
        (o.peak_mib, out)
    };
    let (minute, _) = run("60");
    let (hours, out) = run("7200");
    assert!(
        hours * 2.0 <= minute * 3.0 && hours < 128.0,
        "two hours' run with --out peaked at {hours} MiB, a minute's at {minute} MiB"
    );
    let m: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("metrics.json")).unwrap()).unwrap();
    assert_eq!(
        m["steps"].as_u64(),
        Some(360_001),
        "the pole is up the whole run"
    );
    let trace = std::fs::read_to_string(out.join("trace.csv")).unwrap();
    assert!(trace.ends_with('\n'));
    assert_eq!(trace.lines().count(), 1 + 360_001);
    let last = trace.lines().last().unwrap();
    assert!(last.starts_with("360001,7200000000000,"), "{last}");
    let mut names: Vec<String> = std::fs::read_dir(&out)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    names.sort();
    assert_eq!(names, ["log.txt", "metrics.json", "trace.csv"]);
}

/// A 1 MiB camera frame crosses processes whole (issue 51 item 2): the camera's graph at
/// 1024×1024 px, launched with the camera in `robot` and the image estimator in a process
/// of its own, writes byte for byte the metrics of the run in one process; every
/// frame published was measured (a frame cut or garbled measures nothing), and the counts
/// of `/image` are the in-process run's.
#[test]
fn a_megabyte_frame_crosses_processes_whole_with_its_counters_right() {
    let _m = crate::machine::shared();
    let dir = tempfile::tempdir().unwrap();
    let graph = std::fs::read_to_string(Path::new(crate::REPO).join("graphs/cartpole-camera.toml"))
        .unwrap()
        .replace(
            "params = { width_px = 640, height_px = 480 }",
            "params = { width_px = 1024, height_px = 1024 }",
        );
    let file = dir.path().join("camera-1mib.toml");
    std::fs::write(&file, graph).unwrap();
    let file = file.to_str().unwrap();
    let common = ["--clock", "virtual", "--duration", "3", "--seed", "1"];
    let one = dir.path().join("one");
    let (m1, t1) = outputs(&[&["run", "--graph", file][..], &common].concat(), &one);
    // Across processes, with Zenoh's shared memory (the default) and without it: the
    // frames go through a shared segment or through the socket, the run is the same.
    for shm in ["on", "off"] {
        let many = dir.path().join(format!("many-{shm}"));
        let o = crate::distributed::bin()
            .env(ratelab::distributed::SHARED_MEMORY_ENV, shm)
            .args(
                [
                    &["launch", file, "--processes"][..],
                    &common,
                    &["--out", many.to_str().unwrap()],
                ]
                .concat(),
            )
            .output()
            .unwrap();
        let out = text(&o.stdout);
        assert!(o.status.success(), "{out}{}", text(&o.stderr));
        assert!(out.contains("robot [camera, actuator]"), "{out}");
        assert!(out.contains("vision [vision]"), "{out}");
        let m2 = std::fs::read_to_string(many.join("metrics.json")).unwrap();
        assert_eq!(m1, m2, "metrics differ with shared memory {shm}");
        // With shared memory the vision process reads every frame in place (issue 76): its
        // pixels a view of the camera process's buffer, not a copy. The camera process made
        // its pool before it said it was ready, so even its first frame goes through it
        // (when the pool was made at the first frame, a loaded machine's full test suite
        // once sent all 91 frames of this short lockstep run through the socket); without
        // shared memory, none is read in place.
        let line = crate::wire_line(&out, "/image", "vision");
        let in_place = crate::read_in_place(line);
        let samples = crate::wire_samples(line);
        // And the camera drew every frame straight into a buffer of that pool, which its
        // topic lent it: the frame crossed without a copy between the drawing and the
        // vision node's pixels.
        let drawn = crate::drawn_in_place(line);
        if shm == "on" {
            assert_eq!(in_place, samples, "{line}\n{}", text(&o.stderr));
            assert_eq!(drawn, samples, "{line}\n{}", text(&o.stderr));
        } else {
            assert_eq!((in_place, drawn), (0, 0), "{line}");
        }
    }
    assert!(t1.lines().count() > 30, "{t1:.300}");
    let m: serde_json::Value = serde_json::from_str(&m1).unwrap();
    let published = |t: &str| m["topics"][t]["published"].as_u64().unwrap();
    // 30 frames a second (for as long as the pole stays up), each measured once.
    assert!(published("/image") >= 30, "{m1}");
    assert_eq!(published("/meas"), published("/image"), "{m1}");
    // A setting that is neither on nor off is refused in one line.
    let o = crate::distributed::bin()
        .env(ratelab::distributed::SHARED_MEMORY_ENV, "maybe")
        .args([
            "launch",
            file,
            "--processes",
            "--clock",
            "virtual",
            "--duration",
            "1",
        ])
        .output()
        .unwrap();
    assert_one_line_exit_2(&o, "RATELAB_SHARED_MEMORY is 'maybe': on or off");
}
