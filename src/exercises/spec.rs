//! An exercise's run as data: [`ExerciseSpec`], what `ratelab exercise`'s flags and
//! `ratelab.exercise(…)`'s keywords both fill in, and [`ExerciseSpec::report`], which runs
//! it. So the Python package reaches an exercise without building the command line's
//! argument list, and each front end's refusals speak its own words ([`Speech`]).

use crate::{default_graph, run_report, Progress, Report, Setup};
use ratelab_drivers::run_spec::GraphSettings;
use ratelab_runtime::scheduler::StopFlag;
use ratelab_runtime::setting::{Setting, Speech};
use std::path::PathBuf;

/// One exercise to run: which, where its files are, on what graph, with what prediction.
#[derive(Clone, Debug, PartialEq)]
pub struct ExerciseSpec {
    /// The exercise's id (`ex1`, …; [`crate::EXERCISES`]).
    pub which: String,
    /// The folder holding the exercise files and `bands.toml`.
    pub dir: PathBuf,
    /// The graph and its overrides. No file: the exercise's own default (the graph its
    /// bands name, for ex5 to ex8; else the chapter's). Injected faults are refused: the
    /// exercises inject their own.
    pub graph: GraphSettings,
    /// The prediction, in place of the learner's file's (`None`: the file's): the keys the
    /// exercise's file asks for, and `why`.
    pub prediction: Option<toml::Table>,
}

impl ExerciseSpec {
    /// Run it as `ratelab exercise` does ([`run_report`]): its report's lines through `out`,
    /// its progress through `progress`, its findings returned. The graph's QoS warnings go
    /// to stderr, a `[ratelab]` line each. `stop` (Ctrl-C) ends the run in progress and
    /// the exercise, ungraded.
    ///
    /// # Errors
    /// What kept it from running, in one line in `speech`'s words: an injected fault, a
    /// graph or override that does not fit, an unknown exercise, no prediction, unreadable
    /// files or bands ([`crate::ExerciseError`], kept as the error's source), a run that
    /// cannot start, [`crate::ExerciseError::Interrupted`] once `stop` is set.
    pub fn report(
        &self,
        speech: Speech,
        out: &mut dyn FnMut(&str),
        progress: &dyn Progress,
        stop: &StopFlag,
    ) -> anyhow::Result<Report> {
        if !self.dir.is_dir() {
            // Said before any of its files is looked for: the folder is what is missing.
            let dir = match speech {
                Speech::Flags => "--dir FOLDER",
                Speech::Keywords => "dir=FOLDER",
            };
            let why = format!(
                "the exercises folder {} is not there: run from the ratelab repository (its exercises/ folder), or give the folder with {dir}",
                self.dir.display()
            );
            return Err(std::io::Error::new(std::io::ErrorKind::NotFound, why).into());
        }
        let mut graph = self.graph.clone();
        if graph.file.is_none() {
            graph.file = default_graph(&self.which, &self.dir)?;
        }
        let spec = graph.graph(speech)?;
        for w in spec.qos_warnings() {
            eprintln!("[ratelab] {w}");
        }
        if !graph.faults().is_empty() {
            anyhow::bail!(
                "{}/{}: the exercises inject no faults; use `ratelab run` or `ratelab lab` with them",
                speech.name(Setting::Stall),
                speech.name(Setting::Kill)
            );
        }
        let exe = ratelab_runtime::program::Program::this()?;
        let setup = Setup {
            dir: &self.dir,
            graph: &spec,
            graph_path: graph.file.as_deref(),
            exe: &exe,
            prediction: self.prediction.as_ref(),
            stop,
        };
        Ok(run_report(&self.which, setup, out, progress)?)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::ExerciseError;
    use ratelab_core::qos::Fault;
    use ratelab_core::time::Nanos;

    fn spec(which: &str) -> ExerciseSpec {
        ExerciseSpec {
            which: which.into(),
            dir: PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../exercises"),
            graph: GraphSettings::default(),
            prediction: None,
        }
    }

    fn refusal(spec: &ExerciseSpec, speech: Speech) -> anyhow::Error {
        let mut out = |_: &str| {};
        spec.report(speech, &mut out, &(), &StopFlag::new())
            .unwrap_err()
    }

    #[test]
    fn an_injected_fault_is_refused_in_each_front_end_s_words() {
        let mut s = spec("ex1");
        s.graph.stalls.push(Fault {
            node: "policy".into(),
            at: Nanos(1_000_000_000),
            duration: Some(Nanos(500_000_000)),
        });
        let flags = refusal(&s, Speech::Flags).to_string();
        assert!(flags.starts_with("--stall/--kill: "), "{flags}");
        let keywords = refusal(&s, Speech::Keywords).to_string();
        assert!(keywords.starts_with("stall/kill: "), "{keywords}");
        assert!(keywords.contains("inject no faults"), "{keywords}");
    }

    #[test]
    fn a_bad_override_speaks_the_front_end_s_words_and_an_unknown_exercise_is_named() {
        let mut s = spec("ex1");
        s.graph.rates.push(("nobody".into(), 10.0));
        let keywords = refusal(&s, Speech::Keywords).to_string();
        assert!(
            keywords.contains("rate")
                && keywords.contains("nobody")
                && !keywords.contains("--rate"),
            "{keywords}"
        );
        let flags = refusal(&s, Speech::Flags).to_string();
        assert!(flags.contains("--rate"), "{flags}");
        let unknown = refusal(&spec("ex99"), Speech::Keywords);
        assert!(matches!(
            unknown.downcast_ref::<ExerciseError>(),
            Some(ExerciseError::Unknown(id)) if id == "ex99"
        ));
    }

    #[test]
    fn a_missing_folder_and_no_prediction_are_refused_before_anything_runs() {
        let s = ExerciseSpec {
            dir: std::env::temp_dir().join("ratelab-no-such-exercises-folder"),
            ..spec("ex1")
        };
        // A folder that is not there: said as the folder, with where to run or what to give
        // (a missing file for Python), nothing run.
        let e = refusal(&s, Speech::Keywords);
        let io = e
            .downcast_ref::<std::io::Error>()
            .expect("a missing folder");
        assert_eq!(io.kind(), std::io::ErrorKind::NotFound);
        assert!(
            e.to_string().contains("give the folder with dir=FOLDER"),
            "{e}"
        );
        assert!(
            refusal(&s, Speech::Flags)
                .to_string()
                .contains("--dir FOLDER"),
            "{e}"
        );
        // The repository's exercise file holds no prediction yet: refused, naming it.
        let e = refusal(&spec("ex1"), Speech::Keywords);
        assert!(
            matches!(
                e.downcast_ref::<ExerciseError>(),
                Some(ExerciseError::NoPrediction { .. })
            ),
            "{e:#}"
        );
        // One given in its place that lacks its keys: refused, naming what is missing.
        let mut s = spec("ex1");
        s.prediction = Some(toml::Table::new());
        let e = refusal(&s, Speech::Keywords);
        assert!(
            matches!(
                e.downcast_ref::<ExerciseError>(),
                Some(ExerciseError::GivenPrediction(why)) if why == "missing fails_at_hz, why (ex1 asks for fails_at_hz and why)"
            ),
            "{e:#}"
        );
    }
}
