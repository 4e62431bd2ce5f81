//! End to end, a lab attached from another terminal (`ratelab lab --attach`) to a launch
//! running headless: what the launched processes print reaches its log pane.

use super::{press, Lab};
use std::time::{Duration, Instant};

/// A headless launch across processes of a graph whose Python policy prints: the launcher
/// still writes each print on its own stderr as the process wrote it, and a lab attached
/// from another terminal shows it in its log pane (`v`), stamped with the node.
#[test]
fn a_launched_process_s_print_reaches_a_lab_attached_from_elsewhere() {
    let _machine = crate::machine::alone();
    let dir = tempfile::tempdir().unwrap();
    let (graph, node, script) = crate::python_graph_copy(dir.path());
    let script = script.replace(
        "        s = self.obs\n",
        "        s = self.obs\n        print('policy says cos', round(s.cos_theta, 1))\n",
    );
    assert!(script.contains("policy says"), "the script's line moved");
    std::fs::write(node, script).unwrap();
    let port = crate::distributed::free_port();
    let ep = format!("tls/127.0.0.1:{port}");
    let creds = dir.path().join("creds.toml");
    let stderr = dir.path().join("launcher.err");
    let mut launcher = crate::distributed::bin()
        .args([
            "launch",
            "--processes",
            "--clock",
            "real",
            "--duration",
            "40",
        ])
        .args(["--listen", &ep, "--export-credentials"])
        .arg(&creds)
        .arg(&graph)
        .stdout(std::process::Stdio::null())
        .stderr(std::fs::File::create(&stderr).unwrap())
        .spawn()
        .unwrap();
    let until = Instant::now() + Duration::from_secs(30);
    while !creds.exists() && Instant::now() < until {
        std::thread::sleep(Duration::from_millis(50));
    }
    let mut lab = Lab::start(&[
        "lab",
        "--attach",
        "--connect",
        &ep,
        "--credentials",
        creds.to_str().unwrap(),
    ]);
    lab.wait_for("policy@policy", Duration::from_secs(60));
    press(&mut lab, &["v"]);
    let screen = lab.wait_until("the print in the log pane", Duration::from_secs(20), |s| {
        s.contains("log:") && s.contains("policy says cos 1.0")
    });
    assert!(
        screen
            .lines()
            .any(|l| l.contains("policy ") && l.contains("policy says cos")),
        "the print is stamped with its node:\n{screen}"
    );
    lab.quit();
    // SAFETY: plain kill(2) on our child: SIGTERM ends the launch cleanly.
    unsafe { libc::kill(launcher.id() as i32, libc::SIGTERM) };
    let _ = launcher.wait();
    // The launcher's own stderr has the line as the process wrote it (its stamp, no prefix).
    let err = std::fs::read_to_string(&stderr).unwrap();
    assert!(
        err.lines()
            .any(|l| l.starts_with("[t=") && l.ends_with("policy] policy says cos 1.0")),
        "{err}"
    );
    crate::distributed::assert_none_left(port, Duration::ZERO);
}
