//! The processes a launch starts: each `ratelab process` with its own credentials, its stderr
//! passed on a line at a time, killed with the launch however it ends, and watched until
//! the run starts.

use super::{Launch, MAX_STDERR_LINE};
use crate::{DistError, REPLY_TIMEOUT};
use crossbeam_channel::Receiver;
use ratelab_runtime::scheduler::StopFlag;
use std::process::{Child, Stdio};
use std::time::{Duration, Instant};
use zenoh::Wait;

impl Launch<'_> {
    /// Start every process of the placement ([`Launch::start_process`]), or, when the
    /// launch starts none, say how to start them by hand.
    ///
    /// # Errors
    /// As [`Launch::start_process`].
    pub(super) fn start_processes(&self) -> Result<Children, DistError> {
        let mut children = Children(Vec::new());
        if self.opts.exe.is_none() {
            self.say(&format!(
                "waiting for {} to join: ratelab process{} --process NAME --connect {} --credentials FILE (launch --export-credentials FILE)",
                ratelab_core::text::listed(self.names.iter().map(String::as_str)),
                self.opts
                    .graph_path
                    .as_ref()
                    .map_or(String::new(), |g| format!(" --graph {}", g.display())),
                self.endpoint
            ));
        }
        for (p, _) in &self.placement {
            if let Some(child) = self.start_process(p, self.direct)? {
                children.0.push((p.clone(), child));
            }
        }
        Ok(children)
    }

    /// Start (or start again) process `p` with its own credentials: `None` when the launch
    /// starts no process (they are started by hand, [`super::LaunchOptions::exe`]).
    /// `listen`: the process listens for the launch's other processes, which link to it
    /// directly (a launch linked directly, at its start). A process started again mid-run
    /// (real clock) is a client of the router: its wait for links to every other process
    /// would fail were one of them gone, and the router brokers between it and the peers.
    ///
    /// # Errors
    /// [`DistError::Usage`] when its credentials cannot be written or the binary cannot
    /// start.
    pub(super) fn start_process(&self, p: &str, listen: bool) -> Result<Option<Child>, DistError> {
        let Some(exe) = &self.opts.exe else {
            return Ok(None);
        };
        // Read by the process at its start; a restart writes it anew.
        let own = self.private.write(
            p,
            &self
                .opts
                .credentials
                .only(&crate::credentials::Role::Process(p.to_string()))?,
        )?;
        let mut cmd = exe.command();
        cmd.arg("process").arg("--credentials").arg(&own);
        if let Some(g) = &self.opts.graph_path {
            cmd.arg("--graph").arg(g);
        }
        // Its own process group: a Ctrl-C at the terminal reaches the launcher only,
        // which then stops every process in order (their reports are merged).
        use std::os::unix::process::CommandExt as _;
        cmd.args(["--process", p, "--connect", &self.endpoint]);
        // Linked directly: the other processes link to it on a port of its own.
        if listen {
            cmd.args(["--listen", crate::LOOPBACK_ANY]);
        }
        cmd.process_group(0)
            .stdin(Stdio::null())
            .stdout(Stdio::null())
            // Piped always: its lines also go on the graph's log key, for a lab attached
            // from another terminal (`ratelab lab --attach`).
            .stderr(Stdio::piped());
        // A node dies with the launcher, however the launcher ends.
        // SAFETY: prctl is async-signal-safe and touches only this (child) process.
        unsafe {
            cmd.pre_exec(|| {
                libc::prctl(libc::PR_SET_PDEATHSIG, libc::SIGTERM);
                Ok(())
            });
        }
        let mut child = cmd
            .spawn()
            .map_err(|e| DistError::Usage(format!("cannot start {}: {e}", exe.path.display())))?;
        if let Some(relay) = pass_stderr(
            p,
            &mut child,
            self.opts.child_stderr.clone(),
            self.link.session.clone(),
            self.link.keys.log(),
        ) {
            self.relays.0.borrow_mut().push(relay);
        }
        Ok(Some(child))
    }
}

/// Pass `child`'s stderr on a line at a time (each cut at [`MAX_STDERR_LINE`] bytes, its
/// rest skipped), as `PROCESS: LINE`, on the log key (where an attached lab reads it) and
/// to `to`, or, without `to`, to the launcher's own stderr as the child wrote the line;
/// until the child closes it (a thread that ends with the child).
fn pass_stderr(
    process: &str,
    child: &mut Child,
    to: Option<crossbeam_channel::Sender<String>>,
    session: zenoh::Session,
    log_key: String,
) -> Option<std::thread::JoinHandle<()>> {
    let err = child.stderr.take()?;
    let process = process.to_string();
    std::thread::Builder::new()
        .name(format!("stderr {process}"))
        .spawn(move || {
            let mut r = std::io::BufReader::new(err);
            let mut buf = Vec::new();
            // Bounded: a line longer than the limit is cut, its rest skipped.
            while let Ok(true) =
                ratelab_core::input::read_line_bounded(&mut r, MAX_STDERR_LINE, &mut buf)
            {
                let text = String::from_utf8_lossy(&buf);
                let text = text.trim_end();
                let line = format!("{process}: {}", ratelab_core::text::printable(text));
                let _ = session.put(log_key.as_str(), line.as_str()).wait();
                match &to {
                    Some(to) => {
                        let _ = to.try_send(line);
                    }
                    None => {
                        use std::io::Write as _;
                        let _ = writeln!(std::io::stderr().lock(), "{text}");
                    }
                }
            }
        })
        .ok()
}

/// The threads passing the started processes' stderr on. Dropped (with the launch, after
/// its processes: their pipes are closed then), each is waited for until it has passed its
/// last line, for up to [`RELAY_GRACE`] in all: a grandchild that holds a pipe open (a
/// node's own subprocess) does not hold the launcher.
#[derive(Default)]
pub(super) struct Relays(std::cell::RefCell<Vec<std::thread::JoinHandle<()>>>);

/// How long a launch that ends waits, in all, for its processes' last stderr lines.
const RELAY_GRACE: Duration = Duration::from_secs(1);

impl Drop for Relays {
    fn drop(&mut self) {
        let deadline = Instant::now() + RELAY_GRACE;
        for relay in self.0.get_mut().drain(..) {
            while !relay.is_finished() && Instant::now() < deadline {
                std::thread::sleep(Duration::from_millis(5));
            }
            if relay.is_finished() {
                let _ = relay.join();
            }
        }
    }
}

/// The child processes; every one still running is killed when this is dropped.
pub(super) struct Children(pub(super) Vec<(String, Child)>);

impl Children {
    /// Wait up to `grace` for each to exit, then kill the rest; those for which `given_up`
    /// holds (the launcher has stopped waiting for their reports: a frozen process never
    /// exits on its own) are killed at once.
    pub(super) fn reap(&mut self, grace: Duration, given_up: impl Fn(&str) -> bool) {
        let deadline = Instant::now() + grace;
        for (p, c) in &mut self.0 {
            while !given_up(p) && Instant::now() < deadline {
                if let Ok(Some(_)) = c.try_wait() {
                    break;
                }
                std::thread::sleep(Duration::from_millis(20));
            }
            if let Ok(None) = c.try_wait() {
                let _ = c.kill();
            }
            let _ = c.wait();
        }
        self.0.clear();
    }

    /// A child that exited: its process name and status.
    fn exited(&mut self) -> Option<(String, String)> {
        for (p, c) in &mut self.0 {
            if let Ok(Some(status)) = c.try_wait() {
                return Some((p.clone(), status.to_string()));
            }
        }
        None
    }
}

impl Drop for Children {
    fn drop(&mut self) {
        for (_, c) in &mut self.0 {
            let _ = c.kill();
            let _ = c.wait();
        }
    }
}

/// Wait for the start gate ([`LaunchOptions::start_gate`]), for up to [`REPLY_TIMEOUT`].
pub(super) fn wait_gate(
    gate: &Receiver<()>,
    stop: &StopFlag,
    children: &mut Children,
) -> Result<(), DistError> {
    let deadline = Instant::now() + REPLY_TIMEOUT;
    loop {
        match gate.recv_timeout(Duration::from_millis(50)) {
            Ok(()) => return Ok(()),
            Err(crossbeam_channel::RecvTimeoutError::Disconnected) => {
                return Err(DistError::Peer(
                    "the run's watcher stopped before the run started".into(),
                ))
            }
            Err(crossbeam_channel::RecvTimeoutError::Timeout) => {}
        }
        before_the_run(stop, children)?;
        if Instant::now() >= deadline {
            return Err(DistError::Peer(format!(
                "the run's watcher did not hear from every process within {} s",
                REPLY_TIMEOUT.as_secs()
            )));
        }
    }
}

/// Nothing has ended the launch before its run: not Ctrl-C, not a started process that
/// exited.
pub(super) fn before_the_run(stop: &StopFlag, children: &mut Children) -> Result<(), DistError> {
    if stop.is_stopped() {
        return Err(DistError::Peer("interrupted before the run started".into()));
    }
    if let Some((p, status)) = children.exited() {
        return Err(DistError::Peer(format!(
            "process '{p}' exited ({status}) before the run started"
        )));
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::credentials::{Credentials, Role};
    use crate::{Access, Keys};

    #[test]
    fn a_child_s_stderr_comes_as_bounded_lines_named_by_its_process() {
        let mut child = std::process::Command::new("sh")
            .args([
                "-c",
                "echo 'first line' >&2; head -c 10000 /dev/zero | tr '\\0' x >&2; echo >&2; printf 'last, no newline' >&2",
            ])
            .stdout(Stdio::null())
            .stderr(Stdio::piped())
            .spawn()
            .expect("sh runs");
        let creds = Credentials::generate("g", &[]).expect("credentials");
        let access = Access {
            credentials: &creds,
            role: &Role::Launcher,
            spec: None,
        };
        let session =
            crate::open_session(&[crate::LOOPBACK_ANY.into()], &[], access).expect("a session");
        let (tx, rx) = crossbeam_channel::unbounded();
        pass_stderr(
            "policy",
            &mut child,
            Some(tx),
            session,
            Keys::new("g").log(),
        );
        let _ = child.wait();
        let lines: Vec<String> =
            std::iter::from_fn(|| rx.recv_timeout(Duration::from_secs(5)).ok()).collect();
        assert_eq!(lines.len(), 3, "{lines:?}");
        assert_eq!(lines[0], "policy: first line");
        assert_eq!(lines[1], format!("policy: {}", "x".repeat(MAX_STDERR_LINE)));
        assert_eq!(lines[2], "policy: last, no newline");
    }
}
