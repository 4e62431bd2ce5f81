//! Who joins a launch: each process joins with the graph file's hash and is welcomed with
//! the run's settings, or refused and told why; before the run the launcher waits until
//! every process of the placement is ready. Nothing a joiner sends can end the run: a bad
//! join is refused to that joiner alone.

use super::processes::{before_the_run, Children};
use super::Launch;
use crate::wire::{self, ToLauncher, ToProcess};
use crate::DistError;
use ratelab_runtime::config::ClockKind;
use std::time::{Duration, Instant};

/// What the launcher made of a join.
pub(super) enum Admission {
    /// Welcomed: it gets the settings.
    Welcomed,
    /// Refused, and told why.
    Refused(String),
    /// Refused: a process of this graph with another graph file (told why).
    OtherGraph(String),
    /// Not yet: a process of that name still runs (its liveliness token has not gone), so
    /// the joining one, started again at once after the last was killed, asks again for a
    /// while (told why; a second copy gives up).
    Busy(String),
    /// Not a join, or from a name no key can answer.
    Ignored,
}

impl Launch<'_> {
    /// What to make of `m` (a join, or anything else): before the run (`running` false)
    /// a process joins once (`joined`: those already welcomed); during it, under the real
    /// clock, a process other than the plant's may rejoin once its last run is `gone`.
    /// A welcome carries the run's settings; a refusal is told to the joiner.
    pub(super) fn admit(
        &self,
        m: &ToLauncher,
        running: bool,
        gone: &[String],
        joined: &[String],
    ) -> Admission {
        let ToLauncher::Join {
            process,
            graph_sha256,
            ..
        } = m
        else {
            return Admission::Ignored;
        };
        if !ratelab_runtime::graph::spec::valid_node_name(process) {
            return Admission::Ignored; // no key to answer on
        }
        let (spec, names, hash) = (self.spec, &self.names, &self.hash);
        let tell_refusal = |reason: String, busy: bool| {
            let _ = self.link.tell(
                process,
                &ToProcess::Reject {
                    reason: reason.clone(),
                    busy,
                },
            );
            Admission::Refused(reason)
        };
        let refuse = |reason: String| tell_refusal(reason, false);
        if !names.contains(process) {
            return refuse(format!(
                "graph '{}' has no process '{process}' (its processes: {})",
                spec.name,
                ratelab_core::text::listed(names.iter().map(String::as_str))
            ));
        }
        let well_formed =
            graph_sha256.len() == 64 && graph_sha256.bytes().all(|b| b.is_ascii_hexdigit());
        if !well_formed {
            return refuse(format!("process '{process}' sent a malformed join"));
        }
        if graph_sha256 != hash {
            let theirs: String = graph_sha256.chars().take(12).collect();
            let reason = format!(
                "process '{process}' was given a different graph file than the launcher (SHA-256 {theirs}… against {}…)",
                &hash[..12]
            );
            let _ = refuse(reason.clone());
            return Admission::OtherGraph(reason);
        }
        if running {
            if self.cfg.clock == ClockKind::Virtual {
                return refuse(format!("process '{process}' cannot rejoin: under the virtual clock the run is in lockstep (rejoining works under the real clock)"));
            }
            if *process == self.robot {
                return refuse(format!("process '{process}' cannot rejoin: it holds the plant, whose state died with it"));
            }
            if !gone.contains(process) {
                let reason = format!("process '{process}' is already running in this graph");
                let _ = tell_refusal(reason.clone(), true);
                return Admission::Busy(reason);
            }
        } else if joined.contains(process) {
            return refuse(format!("process '{process}' has already joined this graph"));
        }
        let _ = self.link.tell(
            process,
            &ToProcess::Welcome {
                setup: Box::new(self.setup.clone()),
                launcher_mono_ns: wire::mono_now_ns(),
            },
        );
        Admission::Welcomed
    }

    /// Admit joins until every process of the placement is ready (within
    /// [`crate::ready_wait`] of the start when the launch started them, an hour when they
    /// are started by hand).
    ///
    /// # Errors
    /// [`DistError::Peer`]: Ctrl-C, a started process that exited, or one not ready in
    /// time; [`DistError::Usage`]: a process of this graph joined with another graph file.
    pub(super) fn admit_until_ready(&self, children: &mut Children) -> Result<(), DistError> {
        let names = &self.names;
        let mut joined = Vec::new();
        let mut ready = Vec::new();
        let wait = crate::ready_wait(names.len());
        let deadline = Instant::now()
            + if self.opts.exe.is_some() {
                wait
            } else {
                Duration::from_secs(3600)
            };
        while ready.len() < names.len() {
            before_the_run(self.stop, children)?;
            if Instant::now() >= deadline {
                let missing: Vec<&str> = names
                    .iter()
                    .filter(|p| !ready.contains(*p))
                    .map(String::as_str)
                    .collect();
                return Err(DistError::Peer(format!(
                    "process(es) {} did not become ready within {:.1} s",
                    ratelab_core::text::listed(missing),
                    wait.as_secs_f64()
                )));
            }
            self.say_refusals_due();
            match self.link.recv(Duration::from_millis(50)) {
                Some(m @ ToLauncher::Join { .. }) => match self.admit(&m, false, &[], &joined) {
                    Admission::Welcomed => joined.push(m.process().to_string()),
                    // Before the run, a process with another graph file is the user's mistake.
                    Admission::OtherGraph(r) => {
                        std::thread::sleep(Duration::from_millis(300)); // let the refusal reach it
                        return Err(DistError::Usage(r));
                    }
                    Admission::Refused(r) | Admission::Busy(r) => self.say_refused(&r),
                    Admission::Ignored => {}
                },
                Some(ToLauncher::Ready { process })
                    if joined.contains(&process) && !ready.contains(&process) =>
                {
                    self.say(&format!("process '{process}' ready"));
                    ready.push(process);
                }
                _ => {}
            }
        }
        Ok(())
    }
}
