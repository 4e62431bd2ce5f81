//! End to end, code that hangs (issue 72, item 1): a saved node whose callback never returns
//! hangs its reload's trial, not the run on screen, and a newer save supersedes it; a
//! trial that stalled and returned says so in its reload line; and in the run on screen a
//! hung callback is interrupted by the first Ctrl-C, the second quitting the lab, as is a
//! script's loading that never returns at the lab's start.

use super::{shown_run_time, Lab};
use std::time::Duration;

/// A node saved with a timer callback that loops forever, under the virtual clock: the run
/// on screen goes on with the code before (its run time advances, nothing is called hung)
/// and the footer names the file whose trial is stuck; Ctrl-C says the trial hangs, not the
/// run on screen, and does not quit; a newer save (the callback sleeping 1.5 s once)
/// supersedes it, is taken up, and its reload line says where its trial stalled. `q` then
/// quits with exit 0.
#[test]
fn a_saved_callback_that_never_returns_hangs_its_trial_never_the_run_on_screen() {
    let _machine = crate::machine::alone();
    let dir = tempfile::tempdir().unwrap();
    let (graph, node, script) = crate::python_graph_copy(dir.path());
    let timer = "    def on_timer(self):\n";
    assert!(script.contains(timer));
    let with = |body: &str| script.replace(timer, &format!("{timer}{body}"));
    let mut lab = Lab::start_sized(
        &["--clock", "virtual", "--graph", graph.to_str().unwrap()],
        &[],
        120,
        40,
    );
    lab.wait_for_the_run();
    std::fs::write(&node, with("        while True:\n            pass\n")).unwrap();
    // Said once the trial's callback has run 2 s (the wait leaves a loaded machine room).
    let screen = lab.wait_for(
        "scripted_balancer.py: its callback has not returned after 2 s",
        Duration::from_secs(15),
    );
    assert!(screen.contains("reload of "), "{screen}");
    assert!(
        !screen.contains("HUNG"),
        "the stuck trial is not the run on screen's:\n{screen}"
    );
    let t0 = shown_run_time(&screen).unwrap_or_else(|| panic!("{screen}"));
    lab.wait_until("the run time advancing", Duration::from_secs(10), |s| {
        shown_run_time(s).is_some_and(|t| t >= t0 + 0.5)
    });
    // Ctrl-C says the run on screen is not what hangs, and does not quit.
    lab.keys("\x03");
    let screen = lab.wait_for(
        "the run on screen is not hung, a reload's trial is",
        Duration::from_secs(5),
    );
    assert!(
        lab.child.try_wait().unwrap().is_none(),
        "Ctrl-C quit:\n{screen}"
    );
    // A newer save supersedes the stuck trial: its callback sleeps 1.5 s once, then
    // balances; the reload line says where its trial stalled.
    std::fs::write(
        &node,
        with("        if not hasattr(self, 'slept'):\n            self.slept = True\n            import time\n            time.sleep(1.5)\n"),
    )
    .unwrap();
    let screen = lab.wait_until("the newer save taken up", Duration::from_secs(20), |s| {
        s.contains("reloaded ") && s.contains("the trial's callback stalled 1.")
    });
    assert!(!screen.contains("not reloaded"), "{screen}");
    assert!(screen.contains("at t=0.00 s"), "{screen}");
    // The run on screen stalls there too (its first tick sleeps 1.5 s), then balances.
    std::thread::sleep(Duration::from_millis(2500));
    lab.wait_for("BALANCED", Duration::from_secs(20));
    lab.quit();
}

/// A Python brain whose call never returns holds the run on screen (`HUNG`): the first
/// Ctrl-C interrupts it (its node fails, the lab goes on, and the log pane says where it
/// was), the second quits the lab, restoring the terminal.
#[test]
fn the_first_ctrl_c_interrupts_a_hung_callback_and_the_second_quits() {
    let _machine = crate::machine::alone();
    let dir = tempfile::tempdir().unwrap();
    let hang = dir.path().join("hang.py");
    std::fs::write(
        &hang,
        "calls = 0\ndef act(obs):\n    global calls\n    calls += 1\n    while calls > 25:\n        pass\n    return 0.0\n",
    )
    .unwrap();
    let mut lab = Lab::start_sized(
        &["--clock", "virtual", "--policy", hang.to_str().unwrap()],
        &[],
        120,
        40,
    );
    lab.wait_for("HUNG in policy's callback", Duration::from_secs(60));
    lab.keys("\x03");
    let screen = lab.wait_for("NODE FAILED", Duration::from_secs(10));
    assert!(
        lab.child.try_wait().unwrap().is_none(),
        "the first Ctrl-C quit:\n{screen}"
    );
    lab.keys("v");
    let screen = lab.wait_for("log: all nodes", Duration::from_secs(5));
    assert!(
        screen.contains("hung: ran") && screen.contains("Ctrl-C interrupted it at"),
        "{screen}"
    );
    lab.keys("\x03");
    let status = lab.exit_status("the second Ctrl-C");
    // The run's node failed: the lab says so in its exit status.
    assert!(!status.success(), "{status:?}");
    std::thread::sleep(Duration::from_millis(200));
    let parser = lab.parser.lock().unwrap();
    assert!(
        !parser.screen().alternate_screen(),
        "still on the alternate screen"
    );
}

/// At 80×24: a saved node whose callback loops forever is named as the reload's trial, the
/// run on screen advancing; `r` then drops the stuck trial and starts the run again with the
/// code before, as it says — the new run advances and nothing is called hung — and quits
/// with `q`.
#[test]
fn at_80x24_r_drops_a_stuck_trial_and_the_run_starts_again_with_the_code_before() {
    let _machine = crate::machine::alone();
    let dir = tempfile::tempdir().unwrap();
    let (graph, node, script) = crate::python_graph_copy(dir.path());
    let timer = "    def on_timer(self):\n";
    assert!(script.contains(timer));
    let mut lab = Lab::start_sized(
        &["--clock", "virtual", "--graph", graph.to_str().unwrap()],
        &[],
        80,
        24,
    );
    lab.wait_for_the_run();
    std::fs::write(
        &node,
        script.replace(
            timer,
            &format!("{timer}        while True:\n            pass\n"),
        ),
    )
    .unwrap();
    // Wrapped on two rows at 80 columns.
    let screen = lab.wait_until("the stuck trial said", Duration::from_secs(15), |s| {
        s.contains("its callback has not") && s.contains("of the trial run (t=0.00 s)")
    });
    assert!(!screen.contains("HUNG"), "{screen}");
    let t0 = shown_run_time(&screen).unwrap_or_else(|| panic!("{screen}"));
    lab.wait_until("the run time advancing", Duration::from_secs(10), |s| {
        shown_run_time(s).is_some_and(|t| t >= t0 + 0.5)
    });
    lab.keys("r");
    // The new run, with the code before: it starts from t = 0 and gets past 1.5 s.
    lab.wait_until("the new run from t = 0", Duration::from_secs(10), |s| {
        shown_run_time(s).is_some_and(|t| t < t0)
    });
    let screen = lab.wait_until("the new run advancing", Duration::from_secs(20), |s| {
        shown_run_time(s).is_some_and(|t| t >= 1.5)
    });
    assert!(!screen.contains("HUNG"), "{screen}");
    assert!(screen.contains("BALANCED"), "{screen}");
    lab.quit();
}

/// A node whose script's loading never returns at the lab's start (a sleep at module level)
/// holds the run before its first step: the lab says so (`HUNG loading policy's script`,
/// the node's box `loading`, the header naming the clock the run starts under), the first
/// Ctrl-C interrupts the loading and the footer says where it was, and a save of the fixed
/// script starts the run, which balances; `q` then quits with exit 0.
#[test]
fn a_script_whose_loading_never_returns_at_the_start_is_said_and_a_save_starts_the_run() {
    let _machine = crate::machine::alone();
    let dir = tempfile::tempdir().unwrap();
    let (graph, node, script) = crate::python_graph_copy(dir.path());
    std::fs::write(&node, format!("import time\ntime.sleep(10**6)\n{script}")).unwrap();
    let mut lab = Lab::start_sized(
        &["--clock", "virtual", "--graph", graph.to_str().unwrap()],
        &[],
        120,
        40,
    );
    let screen = lab.wait_for("HUNG loading policy's script", Duration::from_secs(30));
    assert!(
        screen.contains("virtual clock") && screen.contains("│ t 0.00 s"),
        "{screen}"
    );
    assert!(screen.contains("loading "), "the policy's box:\n{screen}");
    lab.keys("\x03");
    let screen = lab.wait_for("Ctrl-C interrupted it at", Duration::from_secs(10));
    assert!(screen.contains("scripted_balancer.py:2"), "{screen}");
    assert!(!screen.contains("HUNG"), "{screen}");
    // No run is going: not the BALANCED of a run that never stepped.
    assert!(
        screen.contains("NOT STARTED") && !screen.contains("BALANCED"),
        "{screen}"
    );
    assert!(
        lab.child.try_wait().unwrap().is_none(),
        "the first Ctrl-C quit:\n{screen}"
    );
    std::fs::write(&node, &script).unwrap();
    lab.wait_until("the fixed run stepping", Duration::from_secs(30), |s| {
        s.contains("BALANCED") && shown_run_time(s).is_some_and(|t| t > 1.0)
    });
    lab.keys("q");
    let status = lab.exit_status("q");
    assert!(status.success(), "{status:?}");
}
