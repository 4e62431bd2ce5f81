//! Reload on save, the engine's side: when a file the run's code comes from is saved (the
//! graph file, a Python node's script, a Python brain; the lab watches them), the graph is
//! read and built again from what the files hold now. Code that no longer loads (a syntax
//! error, a missing class, a bad parameter) leaves the run going, and its one line
//! (`FILE:LINE: …`) goes to the log pane. Code that loads is first run headless under the
//! virtual clock, its lines muted, over the span the run before reached (at least 10 s, at
//! most [`super::engine::JUDGE_FOR`]), so that one line can say what changed — `reloaded
//! FILE: fell at 0.84 s → balanced (10.0 s) · latency p50 40 → 40 ms · /obs dropped 400 →
//! 0` — and then the lab runs it again from t = 0 with the run before drawn as a ghost.
//!
//! Under the real clock a run cannot start again alike, so the saved code takes effect in
//! place ([`Engine::reload_in_place`]): the nodes whose code or parameters changed (a Python
//! node's script, `params` in the graph file) are restarted in place, fresh, while every
//! other node, topic and the pole go on; a saved brain is swapped in. The real clock stands
//! still while they load. A save that changes more of the graph (its nodes, rates, topics)
//! starts the run again from t = 0 with the new code, as does a save after the run ended
//! (a real-clock run cannot be judged exactly: the line says so).

use super::engine::{Engine, Next, Segment, JUDGE_FOR};
use crate::checkpoint::load_policy;
use crate::config::{ClockKind, RunConfig};
use crate::graph::GraphSpec;
use crate::metrics::Metrics;
use crate::run::Command;
use crate::runcore::{CoreOptions, RunCore};
use crate::scheduler::StopFlag;
use crate::telemetry::Telemetry;
use crate::textlog::Level;
use crate::time::Nanos;
use std::path::Path;

/// The shortest span a reloaded graph is judged over.
const JUDGE_AT_LEAST: Nanos = Nanos(10 * Nanos::SECOND.0);

impl Engine {
    /// `file` was saved while the run of `cfg` had reached `old` (its figures so far; `None`
    /// under the real clock): the graph read and built again, judged, and said.
    /// `Some(next)`: the next run is the new code's; `None`: it did not load, and the run
    /// goes on (what failed has been said).
    pub(super) fn reload(
        &self,
        cfg: &RunConfig,
        file: &Path,
        old: Option<&Metrics>,
    ) -> Option<Next> {
        let name = shown_name(file);
        let new_cfg = match self.reloaded_config(cfg) {
            Ok(c) => c,
            Err(e) => {
                self.not_reloaded(&name, &e);
                return None;
            }
        };
        let policy = self.current_policy_spec(&self.run_policy);
        let reached = old.map_or(Nanos::ZERO, |m| Nanos((m.sim_time_s * 1e9) as u64));
        let line = match (judge(&new_cfg, &policy, reached), old) {
            (Ok(new), Some(old)) => format!("reloaded {name}: {}", changes(old, &new)),
            (Ok(_), None) => format!(
                "reloaded {name}: the run starts again with the new code (real clock: not judged)"
            ),
            (Err(e), _) => {
                self.not_reloaded(&name, &e);
                return None;
            }
        };
        crate::textlog::emit_for(None, None, Level::Info, &line);
        let _ = self.tx.send(Telemetry::Reloaded { line });
        Some(Next::Reload(Box::new(new_cfg)))
    }

    /// `cfg` with its graph read again ([`super::GraphSource`]; the compiled-in chapter's graph
    /// stays as it is).
    fn reloaded_config(&self, cfg: &RunConfig) -> Result<RunConfig, String> {
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
        crate::textlog::emit_for(None, None, Level::Error, &line);
        let _ = self.tx.send(Telemetry::Error(line));
    }
}

/// How a stretch of the real clock ended ([`Engine::real_run`]).
pub(super) enum RealExit {
    /// The user moved on.
    Done(Segment),
    /// A save restarts nodes in place; the real clock goes on after.
    Restart(Box<Restart>),
}

/// Nodes to restart in place on a save under the real clock.
pub(super) struct Restart {
    /// The file saved.
    pub(super) file: std::path::PathBuf,
    /// Its name as the user knows it.
    name: String,
    /// The run's graph with the new code.
    spec: GraphSpec,
    /// The graph as the files now give it.
    read: GraphSpec,
    /// The nodes whose code or parameters changed, by graph index.
    which: Vec<usize>,
}

/// What a save under the real clock does ([`Engine::reload_in_place`]).
pub(super) enum InPlace {
    /// Restart these nodes in place.
    Restart(Box<Restart>),
    /// As [`Engine::reload`]: the next run (`Some`), or nothing (`None`: it was said).
    Next(Option<Next>),
    /// The brain's file: apply `swap` (a live brain change, logged as one) and, when it
    /// loads, say `reloaded NAME` ([`Engine::brain_reloaded`]).
    Brain {
        /// The file as the user knows it.
        name: String,
        /// The brain change.
        swap: Command,
    },
}

impl Engine {
    /// `file` was saved while the real clock runs `running` (the run's graph as its nodes
    /// were built): the nodes whose code or parameters changed, to restart in place; a
    /// brain file swapped in at once (a live brain change, logged as one); or, when the
    /// graph changed beyond its nodes' code, the run started again with the new code
    /// ([`Engine::reload`]). Code that does not load is said, and the run goes on.
    pub(super) fn reload_in_place(
        &mut self,
        cfg: &RunConfig,
        running: &GraphSpec,
        file: &Path,
    ) -> InPlace {
        let name = shown_name(file);
        let new_cfg = match self.reloaded_config(cfg) {
            Ok(c) => c,
            Err(e) => {
                self.not_reloaded(&name, &e);
                return InPlace::Next(None);
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
            return InPlace::Next(self.reload(cfg, file, None));
        }
        let saved = std::path::absolute(file).unwrap_or_else(|_| file.to_path_buf());
        let which: Vec<usize> = old
            .nodes
            .iter()
            .zip(&new_cfg.graph.nodes)
            .enumerate()
            .filter(|(_, (o, n))| {
                o.params != n.params
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
            return InPlace::Next(self.reload(cfg, file, None));
        }
        let policy = self.current_policy_spec(&self.run_policy);
        let brain = ratelab_runtime::interpreter::parse_spec(&policy)
            .and_then(|(script, _)| std::path::absolute(script).ok());
        if which.is_empty() && brain.is_some_and(|b| b == saved) {
            // The brain: loaded again from the file and swapped in, as `p` swaps brains.
            return InPlace::Brain {
                name,
                swap: Command::SetPolicy { spec: policy },
            };
        }
        if which.is_empty() {
            let _ = self.tx.send(Telemetry::Applied(format!(
                "reloaded {name}: no node's code or parameters changed (the run goes on)"
            )));
            return InPlace::Next(None);
        }
        // The run's graph, its rates and depths as they are, with the saved code.
        let mut spec = running.clone();
        for &i in &which {
            spec.nodes[i].params = new_cfg.graph.nodes[i].params.clone();
            spec.nodes[i].python = new_cfg.graph.nodes[i].python.clone();
        }
        InPlace::Restart(Box::new(Restart {
            file: file.to_path_buf(),
            name,
            spec,
            read: new_cfg.graph,
            which,
        }))
    }

    /// The brain's file `name` was loaded again and swapped in, under the real clock.
    pub(super) fn brain_reloaded(&self, name: &str) {
        let line = format!("reloaded {name}: the brain swapped in place (real clock: not judged)");
        crate::textlog::emit_for(None, None, Level::Info, &line);
        let _ = self.tx.send(Telemetry::Applied(line));
    }

    /// Restart `r`'s nodes in `core` (stopped between two stretches of the real clock),
    /// and say what was done, or why not (the run goes on with the code before).
    pub(super) fn restart_in_place(&mut self, core: &mut RunCore, r: Box<Restart>) {
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
                crate::textlog::emit_for(None, None, Level::Info, &line);
                let _ = self.tx.send(Telemetry::Applied(line));
            }
            Err(e) => self.not_reloaded(&r.name, &e),
        }
    }
}

/// `file` as the user named it: relative to the folder the lab runs in, when it is inside.
fn shown_name(file: &Path) -> String {
    let here = std::env::current_dir().unwrap_or_default();
    file.strip_prefix(&here)
        .unwrap_or(file)
        .display()
        .to_string()
}

/// Run `cfg`'s graph with brain `policy` headless under the virtual clock, its lines
/// muted, over the span the run before `reached` (at least [`JUDGE_AT_LEAST`], at most
/// [`JUDGE_FOR`] and the run's duration): its figures, or why it does not load.
fn judge(cfg: &RunConfig, policy: &str, reached: Nanos) -> Result<Metrics, String> {
    let mut fresh = cfg.clone();
    fresh.clock = ClockKind::Virtual;
    fresh.duration = reached.max(JUDGE_AT_LEAST).min(JUDGE_FOR).min(cfg.duration);
    crate::textlog::muted(|| {
        let brain = load_policy(policy).map_err(|e| e.to_string())?;
        let mut core =
            RunCore::new(&fresh, brain, CoreOptions::default()).map_err(|e| e.to_string())?;
        core.run_to_end(&StopFlag::new());
        Ok(core.metrics())
    })
}

/// What changed from `old` to `new`, in one line: how each run went, the sense→act latency
/// p50, and each topic's drops (those that dropped anything).
fn changes(old: &Metrics, new: &Metrics) -> String {
    let outcome = |m: &Metrics| match (&m.node_failed, m.fell_at_s) {
        (Some(_), _) => format!("failed at {:.2} s", m.sim_time_s),
        (None, Some(t)) => format!("fell at {t:.2} s"),
        (None, None) => format!("balanced ({:.1} s)", m.sim_time_s),
    };
    let mut parts = vec![format!("{} → {}", outcome(old), outcome(new))];
    parts.push(format!(
        "latency p50 {:.0} → {:.0} ms",
        old.latency_p50_ms, new.latency_p50_ms
    ));
    for (topic, o) in &old.topics {
        let n = new.topics.get(topic).map_or(0, |t| t.dropped);
        if o.dropped > 0 || n > 0 {
            parts.push(format!("{topic} dropped {} → {n}", o.dropped));
        }
    }
    parts.join(" · ")
}
