//! Build script:
//! 1. embeds MuJoCo's and libpython's library folders as rpaths, so binaries run without
//!    LD_LIBRARY_PATH (libpython: the one PyO3 links, of the `python3` found at build time);
//! 2. tells the tests which exercise predictions are still empty, so each exercise's
//!    prediction check is reported as *ignored* (not passed) until the learner writes one.

fn main() {
    // Every package of the workspace but the core builds with this script; the exercise
    // files are at the repository's top, the nearest folder up that has them (by a file of
    // theirs: `src/` has an `exercises` folder too, the crate's, and a path that names no
    // file is never fresh, so every build would run this script and rebuild every crate
    // above it).
    let manifest =
        std::path::PathBuf::from(std::env::var("CARGO_MANIFEST_DIR").unwrap_or_default());
    let root = manifest
        .ancestors()
        .find(|d| d.join("exercises").join("bands.toml").is_file())
        .unwrap_or(&manifest)
        .to_path_buf();
    println!("cargo:rerun-if-env-changed=MUJOCO_DYNAMIC_LINK_DIR");
    if let Ok(dir) = std::env::var("MUJOCO_DYNAMIC_LINK_DIR") {
        println!("cargo:rustc-link-arg=-Wl,-rpath,{dir}");
    }
    // Only a package that links libpython (a direct dependent of PyO3, which then gives its
    // build configuration) needs its folder: the Python layer, the facade and the lab.
    if std::env::var_os("DEP_PYTHON_PYO3_CONFIG").is_some()
        || std::env::var_os("DEP_PYO3_PYTHON_PYO3_CONFIG").is_some()
    {
        pyo3_build_config::add_libpython_rpath_link_args();
    }
    for (ex, file, keys) in [
        ("ex1", "exercises/ex1_rate_cliff.toml", &["fails_at_hz"][..]),
        (
            "ex2",
            "exercises/ex2_queue_trap.toml",
            &["deep_queue_obs_drops", "deep_queue_balances"][..],
        ),
        (
            "ex3",
            "exercises/ex3_jitter_phase.toml",
            &["matched_obs_drops"][..],
        ),
        (
            "ex4",
            "exercises/ex4_stale_queue.toml",
            &[
                "latest_balances",
                "fifo_balances",
                "fifo_latency_at_fall_ms",
                "lifespan_balances",
            ][..],
        ),
        (
            "ex5",
            "exercises/ex5_watchdog.toml",
            &[
                "survives_low_loss",
                "survives_high_loss",
                "keeps_it_up",
                "reliable_latency_ms",
            ][..],
        ),
        (
            "ex6",
            "exercises/ex6_own_node.toml",
            &["smallest_clamp_n"][..],
        ),
        (
            "ex7",
            "exercises/ex7_slow_callback.toml",
            &[
                "sensor_hz_single_threaded",
                "skipped_ticks_single_threaded",
                "balances_single_threaded",
                "sensor_hz_shared_group",
                "sensor_hz_own_group",
            ][..],
        ),
        (
            "ex8",
            "exercises/ex8_noisy_sensor.toml",
            &["fails_at_noise_rad", "lower_cutoff_tolerates_more"][..],
        ),
        (
            "ex9",
            "exercises/ex9_crossing.toml",
            &["p50_latency_across_ms", "p50_latency_across_offsets_ms"][..],
        ),
        (
            "ex10",
            "exercises/ex10_held_force.toml",
            &["stays_up_s"][..],
        ),
        (
            "ex11",
            "exercises/ex11_my_brain.toml",
            &["my_cliff_hz", "lower_than_scripted"][..],
        ),
        (
            "ex12",
            "exercises/ex12_restart.toml",
            &["readings_lost", "latency_max_ms"][..],
        ),
        (
            "ex13",
            "exercises/ex13_what_ros2_sees.toml",
            &["nodes", "obs_type", "action_type", "clock_hz"][..],
        ),
        (
            "ex14",
            "exercises/ex14_incompatible_qos.toml",
            &[
                "reliable_from_best_effort",
                "best_effort_from_reliable",
                "deadline_20_from_40",
                "deadline_40_from_20",
                "late_joiner_volatile",
                "late_joiner_transient_local",
            ][..],
        ),
    ] {
        let file = root.join(file);
        println!("cargo:rerun-if-changed={}", file.display());
        println!("cargo::rustc-check-cfg=cfg({ex}_prediction_empty)");
        let filled = std::fs::read_to_string(file)
            .ok()
            .and_then(|text| text.parse::<toml::Table>().ok())
            .and_then(|t| t.get("prediction").and_then(|p| p.as_table()).cloned())
            .is_some_and(|p| {
                let why = p
                    .get("why")
                    .and_then(|w| w.as_str())
                    .is_some_and(|w| !w.trim().is_empty());
                why && keys.iter().all(|k| p.contains_key(*k))
            });
        if !filled {
            println!("cargo:rustc-cfg={ex}_prediction_empty");
        }
    }
}
