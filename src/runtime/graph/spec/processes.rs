//! The graph file's `[processes.NAME]` tables: what `ratelab launch --processes` does with
//! a process of a launch (today: whether it starts it again when it fails).
//!
//! ```toml
//! [processes.policy]
//! restart = "on-failure"      # never (the default) | on-failure
//! ```
//!
//! `on-failure` starts the process again when it exits with an error or is killed by a
//! signal while the run goes on, at most [`MAX_RESTARTS`] times per run (as systemd's
//! `Restart=on-failure` with a start limit, or dora-rs's `restart_policy`); it rejoins the
//! run on the same clock. Under the virtual clock a process cannot rejoin a lockstep, so
//! the run ends as without it (the launcher says so). Rules (a [`SpecError`] at the
//! culprit): the table's name is a process of the graph's placement, and the plant's
//! process (the actuator's) is never started again: its state goes with it.

use super::{Ctx, GraphSpec, SpecError};
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;
use toml::Spanned;

/// The most times one process is started again in one run.
pub const MAX_RESTARTS: u32 = 3;

/// When the launcher starts a process again.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum RestartPolicy {
    /// Never: a process gone is gone (its nodes' figures missing from the summary).
    #[default]
    Never,
    /// When it exits with an error or a signal while the run goes on.
    OnFailure,
}

#[derive(Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub(super) struct RawProcess {
    #[serde(default, skip_serializing_if = "Option::is_none")]
    restart: Option<Spanned<RestartPolicy>>,
}

/// The processes of a graph file, as serde reads them.
pub(super) type RawProcesses = BTreeMap<String, Spanned<RawProcess>>;

/// Check the `[processes]` tables of `spec` (its nodes placed): each names a process of
/// the placement. Returns each process's restart policy that is not the default.
pub(super) fn processes(
    cx: &Ctx<'_>,
    raw: &RawProcesses,
    spec: &GraphSpec,
) -> Result<BTreeMap<String, RestartPolicy>, SpecError> {
    let placed: Vec<String> = spec.placement().into_iter().map(|(p, _)| p).collect();
    let mut out = BTreeMap::new();
    for (name, p) in raw {
        if !placed.contains(name) {
            return Err(cx.err(
                p.span(),
                format!(
                    "[processes.{name:?}]: no node is placed in a process of that name (the graph's processes: {})",
                    placed.join(", ")
                ),
            ));
        }
        if let Some(r) = &p.get_ref().restart {
            if *r.get_ref() != RestartPolicy::Never {
                // The plant's state lives in its process: gone, the run ends with it.
                if *name == spec.process_of(spec.actuator) {
                    return Err(cx.err(
                        r.span(),
                        format!(
                            "[processes.{name:?}]: restart = \"on-failure\" cannot be: '{name}' runs the plant (the actuator), whose state goes with its process; when it goes the run ends"
                        ),
                    ));
                }
                out.insert(name.clone(), *r.get_ref());
            }
        }
    }
    Ok(out)
}

/// The `[processes]` tables as the graph file writes them back ([`GraphSpec::to_toml`]).
pub(super) fn to_raw(spec: &GraphSpec) -> Option<RawProcesses> {
    (!spec.restart.is_empty()).then(|| {
        spec.restart
            .iter()
            .map(|(name, r)| {
                (
                    name.clone(),
                    Spanned::new(
                        0..0,
                        RawProcess {
                            restart: Some(Spanned::new(0..0, *r)),
                        },
                    ),
                )
            })
            .collect()
    })
}

#[cfg(test)]
mod tests {
    use super::super::{GraphSpec, DEFAULT_GRAPH_TOML};
    use super::RestartPolicy;

    fn with(tail: &str) -> Result<GraphSpec, String> {
        GraphSpec::parse(&format!("{DEFAULT_GRAPH_TOML}\n{tail}\n"), "g.toml")
            .map_err(|e| e.to_string())
    }

    #[test]
    fn a_process_restarts_on_failure_only_when_its_table_says_so() {
        assert!(with("").unwrap().restart.is_empty());
        let spec = with("[processes.policy]\nrestart = \"on-failure\"").unwrap();
        assert_eq!(spec.restart.get("policy"), Some(&RestartPolicy::OnFailure));
        // Written back and read again alike (a launch sends the graph to its processes so).
        let again = GraphSpec::parse(&spec.to_toml(), "again").unwrap();
        assert_eq!(again.restart, spec.restart);
        assert!(with("[processes.robot]\nrestart = \"never\"")
            .unwrap()
            .restart
            .is_empty());
    }

    #[test]
    fn unknown_processes_and_policies_are_refused_at_their_place() {
        let e = with("[processes.camera]\nrestart = \"on-failure\"").unwrap_err();
        assert!(
            e.contains("[processes.\"camera\"]: no node is placed in a process of that name (the graph's processes: robot, policy)"),
            "{e}"
        );
        assert!(e.starts_with("g.toml:"), "{e}");
        let e = with("[processes.policy]\nrestart = \"always\"").unwrap_err();
        assert!(e.contains("unknown variant `always`"), "{e}");
        // The plant's process cannot be started again: refused at its value.
        let e = with("[processes.robot]\nrestart = \"on-failure\"").unwrap_err();
        assert!(
            e.contains(
                "[processes.\"robot\"]: restart = \"on-failure\" cannot be: 'robot' runs the plant"
            ),
            "{e}"
        );
        assert!(e.starts_with("g.toml:"), "{e}");
        let e = with("[processes.policy]\nretry = 3").unwrap_err();
        assert!(e.contains("unknown field `retry`"), "{e}");
    }
}
