//! Reload on save, the engine's side: when a file the run's code comes from is saved (the
//! graph file, a Python node's script, a Python brain; the lab watches them), the graph is
//! read and built again from what the files hold now. Code that no longer loads (a syntax
//! error, a missing class, a bad parameter) leaves the run going, and its one line
//! (`FILE:LINE: …`) goes to the log pane. Code that loads is first run headless under the
//! virtual clock, its lines muted, over the span the run before reached (at least 10 s, at
//! most [`super::engine::JUDGE_FOR`]), so that one line can say what changed — `reloaded
//! FILE: fell at 0.84 s → balanced (10.0 s) · over the first 0.84 s of each: latency p50 40
//! → 40 ms, /obs dropped 9 → 0`, both runs' figures over the run time both ran
//! ([`super::compare`]) — and then the lab runs it again from t = 0 with the run before
//! drawn as a ghost.
//!
//! Under the real clock a run cannot start again alike, so the saved code takes effect in
//! place ([`Engine::reload_in_place`]): the nodes whose code or parameters changed (a Python
//! node's script, `params` in the graph file) are restarted in place, fresh, while every
//! other node, topic and the pole go on; a saved brain is swapped in. The real clock stands
//! still while they load. A save that changes more of the graph (its nodes, rates, topics)
//! starts the run again from t = 0 with the new code, as does a save after the run ended
//! (a real-clock run cannot be judged exactly: the line says so).
//!
//! No saved code runs on the engine's thread until it has returned once: it loads (a
//! restart's nodes, a brain) or loads and is judged on a thread of its own ([`Trial`]),
//! which the engine looks at each time round its loop ([`Engine::reload_ready`]) while the
//! run on screen goes on and the keys act. One that has not returned after [`super::trial::SAID_AFTER`]
//! is said (`loading FILE has not returned after 2 s; the run on screen is the code
//! before`, or which instant of its trial its callback is stuck in); a newer save
//! supersedes it, and a new run (`r`, `R`, `c` after the end) or quitting drops it: it is
//! stopped and interrupted ([`super::trial::Cancelled`]). Once it has returned, the code
//! is loaded again for the run on screen (a restart in place, the next run), as long as it
//! took the first time. A judged trial that stalled on its way (a callback that sleeps 5 s)
//! says so at the end of its reload line (`· the trial's callback stalled 5.0 s at t=1.20
//! s`: [`super::trial::Tried::stall_note`]).

use super::compare::{changes, RunFigures};
use super::engine::{Engine, Next, JUDGE_FOR};
use super::trial::{Job, Pending, Poll, Restart, Then, Trial};
use crate::run::Command;
use ratelab_core::textlog::Level;
use ratelab_core::time::Nanos;
use ratelab_runtime::config::{ClockKind, RunConfig};
use ratelab_runtime::graph::interpreter::Scripts;
use ratelab_runtime::graph::{GraphHandles, GraphSpec};
use ratelab_runtime::runcore::RunCore;
use ratelab_runtime::telemetry::Telemetry;
use std::path::Path;

/// The shortest span a reloaded graph is judged over.
const JUDGE_AT_LEAST: Nanos = Nanos(10 * Nanos::SECOND.0);

/// A reload whose code has loaded, for the run going on to take up
/// ([`Engine::reload_ready`]).
pub(super) enum Ready {
    /// The next run is the new code's ([`Next::Reload`]); said already.
    Next(Next),
    /// Restart these nodes in place (a real-clock run going on).
    Restart(Box<Restart>),
    /// Apply `swap` (a live brain change, logged as one) and, when it loads, say `reloaded
    /// NAME` ([`Engine::brain_reloaded`]) (a real-clock run going on).
    Brain {
        /// The file as the user knows it.
        name: String,
        /// The brain change.
        swap: Command,
        /// What the engine's thread was pinned to for the file: pinned again if the swap
        /// fails.
        pinned_before: Scripts,
    },
}

impl Engine {
    /// `file` was saved while the run of `cfg` had reached `old` (its figures so far, its
    /// ticks among them; `None` under the real clock): the graph read again now, then built
    /// and judged on a thread of its own ([`Trial`]), superseding a reload under way;
    /// [`Engine::reload_ready`] takes up what it comes to. A graph that cannot be read again
    /// is said at once, and the run goes on.
    pub(super) fn reload(&mut self, cfg: &RunConfig, file: &Path, old: Option<RunFigures>) {
        self.drop_reload(false);
        let name = shown_name(file);
        let new_cfg = match self.reloaded_config(cfg) {
            Ok(c) => c,
            Err(e) => {
                self.not_reloaded(&name, &e);
                return;
            }
        };
        let policy = self.current_policy_spec(&self.run_policy);
        let reached = old.as_ref().map_or(Nanos::ZERO, |o| o.span);
        let job = Job::Judge {
            cfg: Box::new(judged(&new_cfg, reached)),
            policy,
        };
        let then = Then::Reload {
            cfg: Box::new(new_cfg),
            old: old.map(Box::new),
        };
        self.start_reload((name, file), job, then);
    }

    /// Start `job`'s trial of the code saved in `file` (`name` as the user knows it),
    /// superseding a reload under way. From the save on, the engine's thread reads the
    /// code of the run on screen, not the saved files ([`pin_code_before`]), until a save
    /// is taken up.
    fn start_reload(&mut self, (name, file): (String, &Path), job: Job, then: Then) {
        self.drop_reload(false);
        pin_code_before();
        self.reloading = Some(Pending {
            name,
            file: file.to_path_buf(),
            trial: Trial::start(job),
            then,
        });
    }

    /// Stop the reload under way, if any (a newer save supersedes it, or the run it was
    /// saved in ends: `say` it in the log then): its trial is stopped, and the call it is
    /// stuck in interrupted; what it comes to is ignored.
    pub(super) fn drop_reload(&mut self, say: bool) {
        let Some(pending) = self.reloading.take() else {
            return;
        };
        if say {
            // The files hold the saved code: the next run reads the code before, pinned
            // since the save (`start_reload`).
            ratelab_core::textlog::emit_for(
                None,
                None,
                Level::Warn,
                &format!(
                    "reload of {} dropped: a new run starts with the code before (save again to reload it)",
                    pending.name
                ),
            );
        }
        self.cancelled.push(pending.trial.cancel(pending.name));
    }

    /// The reload under way, looked at without waiting for it: `Some` once its code has
    /// loaded (and been judged), for the run going on to take up. A trial that has not
    /// returned for [`super::trial::SAID_AFTER`] is said where it is (loading, or which instant of its
    /// run): once in the log, and in the footer counting up each second; code that does not load is said, and the run goes on with the code before.
    /// Trials superseded are watched too ([`super::trial::Cancelled::check`]).
    pub(super) fn reload_ready(&mut self) -> Option<Ready> {
        self.watch_cancelled();
        let pending = self.reloading.as_mut()?;
        let outcome = match pending.trial.poll() {
            Poll::Going => return None,
            Poll::Stuck { at, after, first } => {
                let line = stuck_after(&pending.name, at, after);
                if first {
                    self.warn(line);
                } else {
                    // The count goes up in the footer; the log keeps the first line.
                    let _ = self.tx.send(Telemetry::Recount(line));
                }
                return None;
            }
            Poll::Done(outcome) => *outcome,
        };
        let Pending {
            name, then, file, ..
        } = self.reloading.take()?;
        let tried = match outcome {
            Ok(tried) => tried,
            Err(e) => {
                self.not_reloaded(&name, &e);
                return None;
            }
        };
        let stalled = tried.stall_note();
        Some(match then {
            Then::Reload { cfg, old } => {
                let mut line = match (tried.figures, old) {
                    (Some(new), Some(old)) => format!("reloaded {name}: {}", changes(&old, &new)),
                    _ => format!(
                        "reloaded {name}: the run starts again with the new code (real clock: not judged)"
                    ),
                };
                // Where the trial stalled, the run on screen will too: said last, which a
                // narrow footer keeps.
                if let Some(note) = stalled {
                    line = format!("{line} · {note}");
                }
                self.said_reloaded(line);
                // Taken up, every file judged: the runs from here read the files as saved.
                ratelab_runtime::graph::interpreter::pin_scripts(None);
                Ready::Next(Next::Reload(cfg))
            }
            // The saved file alone is read as saved from here; any other file whose save
            // was not taken up stays as it was.
            Then::Restart(mut r) => {
                r.pinned_before = unpin_file(&file);
                Ready::Restart(r)
            }
            Then::Brain(swap) => Ready::Brain {
                name,
                swap,
                pinned_before: unpin_file(&file),
            },
        })
    }

    /// `ready` as the next run, where it cannot be taken up in place (the run has ended, or
    /// went on under the virtual clock since the save): a restart in place or a brain swap
    /// starts the run again with the new code, not judged. `cfg`: the run's settings, under
    /// the clock it goes on under.
    pub(super) fn as_next(&self, cfg: &RunConfig, ready: Ready) -> Next {
        let (name, graph) = match ready {
            Ready::Next(Next::Reload(mut new)) => {
                new.clock = cfg.clock;
                return Next::Reload(new);
            }
            Ready::Next(next) => return next,
            Ready::Restart(r) => (r.name, r.read),
            Ready::Brain { name, .. } => (name, self.file_graph.clone()),
        };
        self.said_reloaded(format!(
            "reloaded {name}: the run starts again with the new code (real clock: not judged)"
        ));
        Next::Reload(Box::new(RunConfig {
            graph,
            ..cfg.clone()
        }))
    }

    /// Say (log pane and footer) that a reload loaded, in `line`: the ghost of the run before
    /// is drawn beside the next.
    fn said_reloaded(&self, line: String) {
        ratelab_core::textlog::emit_for(None, None, Level::Info, &line);
        let _ = self.tx.send(Telemetry::Reloaded { line });
    }

    /// Say `line` in the log pane and the footer, as a warning.
    fn warn(&self, line: String) {
        ratelab_core::textlog::emit_for(None, None, Level::Warn, &line);
        let _ = self.tx.send(Telemetry::Error(line));
    }

    /// Watch the trials superseded until they end, saying those interrupted and those
    /// abandoned (in the log pane: the footer is the reload's that superseded them).
    fn watch_cancelled(&mut self) {
        let mut said = Vec::new();
        self.cancelled.retain_mut(|c| {
            let (keep, line) = c.check();
            said.extend(line);
            keep
        });
        for line in said {
            ratelab_core::textlog::emit_for(None, None, Level::Warn, &line);
        }
    }

    /// `cfg` with its graph read again ([`super::GraphSource`]; the compiled-in chapter's graph
    /// stays as it is).
    pub(super) fn reloaded_config(&self, cfg: &RunConfig) -> Result<RunConfig, String> {
        let mut new = cfg.clone();
        if let Some(source) = &self.settings.graph_source {
            new.graph = (source.0)()?;
        }
        new.validate().map_err(|e| e.to_string())?;
        Ok(new)
    }

    /// Say that `file` did not load: the run goes on with the code it had. The reason first
    /// (it names the file and line: `brain.py:2: SyntaxError: …`), as it must fit 80 columns.
    fn not_reloaded(&self, file: &str, why: &str) {
        let why = if why.contains(file) || why.starts_with('/') {
            why.to_string()
        } else {
            format!("{file}: {why}")
        };
        let line = format!("not reloaded: {why} (the run goes on with the code before)");
        // And so does the next run (`r`, a fall): its files hold code that did not load.
        pin_code_before();
        ratelab_core::textlog::emit_for(None, None, Level::Error, &line);
        let _ = self.tx.send(Telemetry::Error(line));
    }
}

/// Pin the engine's thread to the code of the run on screen, unless it is pinned already
/// (to the code before an earlier save not taken up): what it read since the run started
/// ([`ratelab_runtime::graph::interpreter::scripts_read`]). What it builds from here (a seek's
/// replay, the next run) reads that code rather than the files' saved code, until a save is
/// taken up.
fn pin_code_before() {
    use ratelab_runtime::graph::interpreter::{pin_scripts, pinned_scripts, scripts_read};
    if pinned_scripts().is_none() {
        pin_scripts(Some(scripts_read()));
    }
}

/// Let the engine's thread read `file` as saved again (its code is taken up: a restart in
/// place, a brain swapped), every other pinned script staying pinned; returns what was
/// pinned for it ([`repin`] it if taking it up fails).
fn unpin_file(file: &Path) -> Scripts {
    use ratelab_runtime::graph::interpreter::{pin_scripts, pinned_scripts};
    let Some(pinned) = pinned_scripts() else {
        return Scripts::new();
    };
    let target = std::path::absolute(file).ok();
    let (gone, kept): (Scripts, Scripts) = pinned
        .into_iter()
        .partition(|(k, _)| std::path::absolute(k).ok() == target);
    pin_scripts(Some(kept));
    gone
}

/// Pin `before` again (what [`unpin_file`] returned): its saved code was not taken up.
pub(super) fn repin(before: Scripts) {
    use ratelab_runtime::graph::interpreter::{pin_scripts, pinned_scripts};
    let mut pinned = pinned_scripts().unwrap_or_default();
    pinned.extend(before);
    pin_scripts(Some(pinned));
}

/// How a stretch of the real clock ended ([`Engine::real_run`]).
pub(super) enum RealExit {
    /// The user moved on.
    Done(super::engine::Segment),
    /// A save restarts nodes in place; the real clock goes on after.
    Restart(Box<Restart>),
}

impl Engine {
    /// `file` was saved while the real clock runs `running` (the run's graph as its nodes
    /// were built; `handles`, its handles): the nodes whose code or parameters changed, to
    /// restart in place once their code has loaded on a thread of its own; a brain file,
    /// swapped in once it has loaded (a live brain change, logged as one); or, when the
    /// graph changed beyond its nodes' code, the run started again with the new code
    /// ([`Engine::reload`]). [`Engine::reload_ready`] takes up what the trial comes to;
    /// what needs no trial is said at once.
    pub(super) fn reload_in_place(
        &mut self,
        cfg: &RunConfig,
        running: &GraphSpec,
        handles: &GraphHandles,
        file: &Path,
    ) {
        let name = shown_name(file);
        let new_cfg = match self.reloaded_config(cfg) {
            Ok(c) => c,
            Err(e) => {
                self.drop_reload(false);
                self.not_reloaded(&name, &e);
                return;
            }
        };
        // What the save changed, against the files as last read (the run's graph may hold
        // rates and depths the keys set since, which stay).
        let old = &self.file_graph;
        let moved = old.nodes.iter().zip(&new_cfg.graph.nodes).find(|(o, n)| {
            o.python.as_ref().map(|p| &p.script) != n.python.as_ref().map(|p| &p.script)
        });
        let why = match old.same_shape(&new_cfg.graph) {
            Err(why) => Some(why),
            // A node's script moved: its new file is watched from the next run's start.
            Ok(()) => moved.map(|(o, _)| format!("node '{}' runs another script", o.name)),
        };
        if let Some(why) = why {
            let _ = self
                .tx
                .send(Telemetry::Applied(format!("{why}: the run starts again")));
            return self.reload(cfg, file, None);
        }
        // A restart under way whose code has not loaded yet: its nodes restart with these.
        let earlier: Vec<usize> = match &self.reloading {
            Some(Pending {
                then: Then::Restart(r),
                ..
            }) => r.which.clone(),
            _ => Vec::new(),
        };
        let saved = std::path::absolute(file).unwrap_or_else(|_| file.to_path_buf());
        let which: Vec<usize> = old
            .nodes
            .iter()
            .zip(&new_cfg.graph.nodes)
            .enumerate()
            .filter(|(i, (o, n))| {
                earlier.contains(i)
                    || o.params != n.params
                    || o.python != n.python
                    || n.python
                        .as_ref()
                        .is_some_and(|p| std::path::absolute(&p.script).is_ok_and(|s| s == saved))
            })
            .map(|(i, _)| i)
            .collect();
        if which.contains(&running.actuator.0) {
            // It steps the plant and tells the run's observers: not restarted alone.
            let _ = self.tx.send(Telemetry::Applied(
                "the actuator changed: the run starts again".into(),
            ));
            return self.reload(cfg, file, None);
        }
        let policy = self.current_policy_spec(&self.run_policy);
        let brain = ratelab_runtime::graph::interpreter::parse_spec(&policy)
            .and_then(|(script, _)| std::path::absolute(script).ok());
        if which.is_empty() && brain.is_some_and(|b| b == saved) {
            // The brain: loaded again from the file and swapped in, as `p` swaps brains.
            let job = Job::Brain {
                policy: policy.clone(),
            };
            let then = Then::Brain(Command::SetPolicy { spec: policy });
            return self.start_reload((name, file), job, then);
        }
        if which.is_empty() {
            let _ = self.tx.send(Telemetry::Applied(format!(
                "reloaded {name}: no node's code or parameters changed (the run goes on)"
            )));
            return;
        }
        // The run's graph, its rates and depths as they are, with the saved code.
        let mut spec = running.clone();
        for &i in &which {
            spec.nodes[i].params = new_cfg.graph.nodes[i].params.clone();
            spec.nodes[i].python = new_cfg.graph.nodes[i].python.clone();
        }
        // Only a Python node's code can fail to return: those load in the trial, built on
        // the live run's handles as the restart builds them (and dropped).
        let python: Vec<usize> = which
            .iter()
            .copied()
            .filter(|&i| spec.nodes[i].python.is_some())
            .collect();
        let mut trial = handles.clone();
        trial.spec = std::sync::Arc::new(spec.clone());
        let job = Job::Rebuild {
            handles: trial,
            seed: cfg.seed,
            which: python,
        };
        let then = Then::Restart(Box::new(Restart {
            name: name.clone(),
            spec,
            read: new_cfg.graph,
            which,
            pinned_before: Scripts::new(),
        }));
        self.start_reload((name, file), job, then);
    }

    /// The brain's file `name` was loaded again and swapped in, under the real clock.
    pub(super) fn brain_reloaded(&self, name: &str) {
        let line = format!("reloaded {name}: the brain swapped in place (real clock: not judged)");
        ratelab_core::textlog::emit_for(None, None, Level::Info, &line);
        let _ = self.tx.send(Telemetry::Applied(line));
    }

    /// Restart `r`'s nodes in `core` (stopped between two stretches of the real clock),
    /// and say what was done, or why not (the run goes on with the code before). Their code
    /// has loaded in a trial already ([`Engine::reload_in_place`]): it loads again here, for
    /// as long as it took there.
    /// Returns the line said when the nodes restarted (for the recording), `None` when not.
    pub(super) fn restart_in_place(
        &mut self,
        core: &mut RunCore,
        r: Box<Restart>,
    ) -> Option<String> {
        let at = core.now();
        match core.restart_nodes(&r.spec, &r.which) {
            Ok(()) => {
                self.file_graph = r.read;
                let names: Vec<String> = r
                    .which
                    .iter()
                    .map(|&i| format!("'{}'", r.spec.nodes[i].name))
                    .collect();
                let line = format!(
                    "reloaded {}: {} restarted in place at t={:.2} s (real clock: not judged)",
                    r.name,
                    names.join(", "),
                    at.as_secs_f64()
                );
                ratelab_core::textlog::emit_for(None, None, Level::Info, &line);
                let _ = self.tx.send(Telemetry::Applied(line.clone()));
                Some(line)
            }
            Err(e) => {
                repin(r.pinned_before);
                self.not_reloaded(&r.name, &e);
                None
            }
        }
    }
}

/// What the lab says of a reload's trial that has not returned for `after` (whole seconds
/// are said): still loading (`at` is `None`), or in the instant at `at` of its run.
fn stuck_after(name: &str, at: Option<Nanos>, after: std::time::Duration) -> String {
    let secs = after.as_secs();
    match at {
        None => format!(
            "loading {name} has not returned after {secs} s; the run on screen is the code before"
        ),
        Some(t) => format!(
            "reload of {name}: its callback has not returned after {secs} s of the trial run (t={:.2} s); the run on screen is the code before",
            t.as_secs_f64()
        ),
    }
}

/// `cfg` as a reload's trial runs it: headless under the virtual clock, over the span the
/// run before `reached` (at least [`JUDGE_AT_LEAST`], at most [`JUDGE_FOR`] and the run's
/// duration).
fn judged(cfg: &RunConfig, reached: Nanos) -> RunConfig {
    let mut fresh = cfg.clone();
    fresh.clock = ClockKind::Virtual;
    fresh.duration = reached.max(JUDGE_AT_LEAST).min(JUDGE_FOR).min(cfg.duration);
    fresh
}

/// `file` as the user named it: relative to the folder the lab runs in, when it is inside.
fn shown_name(file: &Path) -> String {
    let here = std::env::current_dir().unwrap_or_default();
    file.strip_prefix(&here)
        .unwrap_or(file)
        .display()
        .to_string()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::session::trial::SAID_AFTER;

    /// A trial stuck in a callback names the file saved, how long, the run time of the
    /// trial's instant, and that the run on screen is the code before; one stuck loading
    /// says so.
    #[test]
    fn a_stuck_trial_is_said_with_its_file_and_where_it_is() {
        assert_eq!(
            stuck_after("nodes/policy.py", Some(Nanos(1_200_000_000)), SAID_AFTER),
            "reload of nodes/policy.py: its callback has not returned after 2 s of the trial run (t=1.20 s); the run on screen is the code before"
        );
        assert_eq!(
            stuck_after("nodes/policy.py", Some(Nanos::ZERO), std::time::Duration::from_secs(5)),
            "reload of nodes/policy.py: its callback has not returned after 5 s of the trial run (t=0.00 s); the run on screen is the code before"
        );
        assert_eq!(
            stuck_after("brain.py", None, SAID_AFTER),
            "loading brain.py has not returned after 2 s; the run on screen is the code before"
        );
    }

    /// A trial is judged over the span the run before reached, at least 10 s, at most 30 s
    /// and the run's duration, headless under the virtual clock.
    #[test]
    fn a_trial_runs_over_the_span_the_run_before_reached() {
        let cfg = RunConfig {
            clock: ClockKind::Real,
            duration: Nanos(20 * Nanos::SECOND.0),
            ..RunConfig::default()
        };
        let secs = |reached: u64| judged(&cfg, Nanos(reached * Nanos::SECOND.0)).duration;
        assert_eq!(secs(2), JUDGE_AT_LEAST);
        assert_eq!(secs(15), Nanos(15 * Nanos::SECOND.0));
        assert_eq!(secs(25), cfg.duration);
        assert_eq!(judged(&cfg, Nanos::ZERO).clock, ClockKind::Virtual);
    }

    /// From a save on, the engine's thread reads the code of the run on screen (pinned
    /// once: a later save keeps the first pin); a file taken up is unpinned alone, and
    /// pinned again when taking it up fails.
    #[test]
    fn a_save_pins_the_code_before_and_a_file_taken_up_is_unpinned_alone() {
        use ratelab_runtime::graph::interpreter::{
            forget_scripts_read, pinned_scripts, script_text,
        };
        // A thread of its own: pins are the calling thread's.
        std::thread::spawn(|| {
            forget_scripts_read();
            let dir = std::env::temp_dir();
            let (a, b) = (dir.join("ratelab-pin-a.py"), dir.join("ratelab-pin-b.py"));
            let (a, b) = (a.to_str().unwrap(), b.to_str().unwrap());
            let read = |path: &str, text: &str| {
                let text = text.to_string();
                script_text(path, move || Ok::<_, String>(text))
                    .unwrap()
                    .to_string()
            };
            assert_eq!(read(a, "a1"), "a1");
            assert_eq!(read(b, "b1"), "b1");
            pin_code_before();
            // The files hold the saved code; the engine reads the code before.
            assert_eq!(read(a, "a2"), "a1");
            assert_eq!(read(b, "b2"), "b1");
            pin_code_before();
            let pinned = || {
                pinned_scripts()
                    .unwrap()
                    .into_iter()
                    .map(|(k, v)| (k, v.to_string()))
                    .collect::<Vec<_>>()
            };
            assert_eq!(pinned(), [(a.into(), "a1".into()), (b.into(), "b1".into())]);
            // a.py taken up (a restart in place): read as saved; b.py still pinned.
            let before = unpin_file(Path::new(a));
            assert_eq!(read(a, "a2"), "a2");
            assert_eq!(read(b, "b2"), "b1");
            // Its restart failed: pinned again.
            repin(before);
            assert_eq!(read(a, "a2"), "a1");
            assert_eq!(pinned(), [(a.into(), "a1".into()), (b.into(), "b1".into())]);
        })
        .join()
        .unwrap();
    }
}
