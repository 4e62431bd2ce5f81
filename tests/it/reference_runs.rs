//! The eighteen reference runs of `../shared/fixtures/reference-runs/` (its README): each
//! configuration's `metrics.json` and `trace.csv`, made by the binary at adf3e66, must come
//! out of this binary byte for byte, so no change moves a result a learner has seen without
//! saying so.

use std::path::Path;

#[test]
fn the_reference_runs_come_out_byte_for_byte() {
    let _m = crate::machine::shared();
    let fixtures = Path::new(crate::REPO).join("../shared/fixtures/reference-runs");
    let commands = std::fs::read_to_string(fixtures.join("commands.txt"))
        .expect("../shared/fixtures/reference-runs/commands.txt");
    let checkout = std::fs::canonicalize(crate::REPO).unwrap();
    let out = tempfile::tempdir().unwrap();
    let mut compared = 0;
    for line in commands.lines().filter(|l| !l.trim().is_empty()) {
        let (name, args) = line.split_once('|').expect("name|arguments");
        let dir = out.path().join(name);
        let o = std::process::Command::new(env!("CARGO_BIN_EXE_ratelab"))
            .args(args.split_whitespace())
            .arg("--out")
            .arg(&dir)
            .current_dir(&checkout)
            .output()
            .unwrap();
        for file in ["metrics.json", "trace.csv"] {
            let Ok(want) = std::fs::read_to_string(fixtures.join(name).join(file)) else {
                continue; // not written for this run (a launch writes metrics.json only)
            };
            let got = std::fs::read_to_string(dir.join(file)).unwrap_or_else(|e| {
                panic!(
                    "{name}: no {file} ({e}): {}",
                    String::from_utf8_lossy(&o.stderr)
                )
            });
            // A Python node's script is named by its absolute path: the checkout's part is
            // `<checkout>` in the fixtures.
            let got = got.replace(checkout.to_str().unwrap(), "<checkout>");
            assert!(got == want, "{name}/{file} differs from the reference run");
            compared += 1;
        }
    }
    assert_eq!(
        compared, 35,
        "18 runs, every one with metrics.json, all but one with trace.csv"
    );
}
