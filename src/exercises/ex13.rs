//! ex13, what ROS 2 sees: the chapter's graph offered with `--ros2`, its policy at another
//! rate than the sensor's. The learner predicts what `ros2 node list` prints, the ROS 2 types
//! of `/obs` and `/action`, and how many `/clock` messages a second of run time carries;
//! ratelab answers from the mapping its bridge declares the graph with
//! ([`ratelab_ros2::offered`]) and from the run's own instants (`/clock` is published before
//! each virtual instant, docs/ros2.md), and prints the `ratelab ros2` commands that read the
//! same from the wire (a test reads them there and finds the same).

use super::{check, Check, Context, Exercise, ExerciseError, Reconcile, Said, Section};
use ratelab_core::time::Nanos;
use ratelab_runtime::config::{duration_from_secs, ClockKind, RunConfig};
use ratelab_runtime::policy::Scripted;
use ratelab_runtime::runcore::drive::{ClockOut, Unpaced};
use ratelab_runtime::runcore::{CoreOptions, RunCore};
use ratelab_runtime::scheduler::StopFlag;
use serde::Deserialize;
use std::cell::Cell;
use std::collections::BTreeSet;

/// ex13: what ROS 2 sees.
pub struct Ex13;

/// ex13's settings.
#[derive(Clone, Debug, Deserialize)]
pub struct Ex13Bands {
    /// The policy's rate, Hz (the sensor and actuator keep the graph's).
    pub control_hz: f64,
    /// Run time over which `/clock` is counted, s.
    pub duration_s: f64,
}

impl Section for Ex13Bands {
    const NAME: &'static str = "ex13";
}

/// ex13's outcome: what ROS 2 sees.
#[derive(Clone, Debug, PartialEq)]
pub struct Ex13Outcome {
    /// The nodes ROS 2 sees, in the graph's order (`/ratelab` last); `ros2 node list` prints
    /// them sorted ([`node_set`]).
    pub nodes: Vec<String>,
    /// `/obs`'s ROS 2 type.
    pub obs_type: String,
    /// `/action`'s.
    pub action_type: String,
    /// `/clock` messages per second of run time.
    pub clock_hz: f64,
}

/// ex13's measurement on the run `cfg` (virtual clock): the graph as offered, and its
/// instants per second of run time (each one a `/clock` message).
///
/// # Errors
/// [`ExerciseError`] when the run cannot start.
pub fn measure_ex13(cfg: &RunConfig, stop: &StopFlag) -> Result<Ex13Outcome, ExerciseError> {
    let offered = ratelab_ros2::offered::offered(&cfg.graph);
    let type_of = |name: &str| {
        offered
            .topics
            .iter()
            .find(|t| t.name == name)
            .map_or_else(|| "?".to_string(), |t| t.ros_type.clone())
    };
    let mut core = RunCore::new(cfg, Box::new(Scripted), CoreOptions::default()).map_err(|e| {
        ratelab_drivers::sweep::SweepError::from(ratelab_drivers::run::RunError::from(e))
    })?;
    // Driven as `ratelab run --ros2` drives it, /clock counted where it is told: one
    // message per instant in [0, duration).
    let clock = ClockCount {
        before: cfg.duration,
        told: Cell::new(0),
    };
    core.run_to_end_with(&mut Unpaced, stop, Some(&clock));
    super::interrupted(stop)?;
    let instants = clock.told.get();
    Ok(Ex13Outcome {
        nodes: offered.nodes.clone(),
        obs_type: type_of("/obs"),
        action_type: type_of("/action"),
        clock_hz: instants as f64 / cfg.duration.as_secs_f64(),
    })
}

/// Counts the `/clock` messages a run tells before run time `before` (ns).
struct ClockCount {
    before: Nanos,
    told: Cell<u64>,
}

impl ClockOut for ClockCount {
    fn clock(&self, t: Nanos) {
        if t < self.before {
            self.told.set(self.told.get() + 1);
        }
    }
}

/// ex13's checks: the facts the lesson rests on.
pub fn check_ex13(b: &Ex13Bands, o: &Ex13Outcome) -> Vec<Check> {
    vec![
        check(
            "ROS 2 sees every node of the graph, and ratelab's own /ratelab (which publishes /clock)",
            o.nodes.first().is_some_and(|n| n == "/sensor") && o.nodes.last().is_some_and(|n| n == "/ratelab"),
        ),
        check(
            "/obs is a sensor_msgs/msg/JointState, /action a std_msgs/msg/Float64 (newtons)",
            o.obs_type == "sensor_msgs/msg/JointState" && o.action_type == "std_msgs/msg/Float64",
        ),
        check(
            format!(
                "/clock ticks at every instant any node ticks: more often than any one node ({} Hz policy, 50 Hz sensor)",
                b.control_hz
            ),
            o.clock_hz > b.control_hz.max(50.0),
        ),
    ]
}

/// Node names as `ros2 node list` prints them: each fully qualified (a name without a
/// namespace is in the root one, `sensor` is `/sensor`, as ros2cli's `node info` takes it),
/// each once, sorted as ros2cli sorts them (and `ratelab ros2 node list`).
pub fn node_set<'a>(names: impl IntoIterator<Item = &'a str>) -> BTreeSet<String> {
    names
        .into_iter()
        .map(|n| {
            if n.starts_with('/') {
                n.to_string()
            } else {
                format!("/{n}")
            }
        })
        .collect()
}

/// How far the predicted `/clock` rate may be from the measured one, messages a second:
/// the rate is exact (the instants of the grids' union), so only a rounding.
const CLOCK_HZ_TOLERANCE: f64 = 0.5;

/// The node list: right when the names are the same set (in any order, `/` or not before a
/// name in the root namespace). The types: right when the same. `/clock`'s rate: right
/// within `CLOCK_HZ_TOLERANCE`.
impl Reconcile for Ex13Outcome {
    fn reconcile(&self, prediction: &toml::Table) -> Vec<Said> {
        let key = "nodes";
        let names: Option<Vec<&str>> = prediction
            .get(key)
            .and_then(toml::Value::as_array)
            .and_then(|a| a.iter().map(toml::Value::as_str).collect());
        let words = |set: &BTreeSet<String>| -> String {
            if set.is_empty() {
                return "none".into();
            }
            set.iter()
                .map(|n| ratelab_core::text::printable(n).into_owned())
                .collect::<Vec<_>>()
                .join(" ")
        };
        let mut out = vec![match names {
            Some(names) => {
                let said = node_set(names);
                let seen = node_set(self.nodes.iter().map(String::as_str));
                super::graded(
                    key,
                    &format!(
                        "You predicted the node list {}; ros2 node list prints {}",
                        words(&said),
                        words(&seen)
                    ),
                    said == seen,
                    " (ROS 2 sees every node of the graph, and ratelab's own, which publishes /clock)",
                )
            }
            None => super::unreadable(key),
        }];
        for (key, seen) in [
            ("obs_type", &self.obs_type),
            ("action_type", &self.action_type),
        ] {
            out.push(match prediction.get(key).and_then(toml::Value::as_str) {
                Some(t) => super::graded(
                    key,
                    &format!(
                        "You predicted {key} = {}; it is {seen}",
                        ratelab_core::text::printable(t)
                    ),
                    t == seen.as_str(),
                    "",
                ),
                None => super::unreadable(key),
            });
        }
        let key = "clock_hz";
        out.push(match prediction.get(key).and_then(super::number) {
            Some(n) => super::graded(
                key,
                &format!(
                    "You predicted {n} /clock messages a second; there were {:.1}",
                    self.clock_hz
                ),
                (n - self.clock_hz).abs() <= CLOCK_HZ_TOLERANCE,
                &format!(": off by more than {CLOCK_HZ_TOLERANCE}"),
            ),
            None => super::unreadable(key),
        });
        out
    }
}

impl Exercise for Ex13 {
    fn id(&self) -> &'static str {
        "ex13"
    }

    fn title(&self) -> &'static str {
        "what ROS 2 sees"
    }

    fn file(&self) -> &'static str {
        "ex13_what_ros2_sees.toml"
    }

    fn required_keys(&self) -> &'static [&'static str] {
        &["nodes", "obs_type", "action_type", "clock_hz"]
    }

    fn run(&self, cx: &mut Context<'_>) -> Result<(), ExerciseError> {
        let b: Ex13Bands = cx.bands()?;
        let mut cfg = RunConfig {
            clock: ClockKind::Virtual,
            duration: duration_from_secs(b.duration_s)?,
            graph: cx.graph.clone(),
            ..RunConfig::default()
        };
        cfg.set_control_hz(b.control_hz)?;
        let o = cx.measure(|stop| measure_ex13(&cfg, stop))?;
        say!(
            cx,
            "what ROS 2 sees of the chapter's graph, policy at {} Hz:",
            b.control_hz
        );
        // As `ros2 node list` prints them (and `ratelab ros2 node list`): sorted, one a line.
        say!(cx, "  ros2 node list");
        for n in node_set(o.nodes.iter().map(String::as_str)) {
            say!(cx, "    {}", ratelab_core::text::printable(&n));
        }
        say!(cx, "  /obs                  {}", o.obs_type);
        say!(cx, "  /action               {}", o.action_type);
        say!(
            cx,
            "  /clock                {:.1} messages per second of run time",
            o.clock_hz
        );
        cx.reconcile(&o);
        cx.checks(&check_ex13(&b, &o));
        say!(cx);
        cx.paragraph(
            "Reconcile: ROS 2 sees the graph's nodes by name, with the root namespace's `/`, and \
             one more: ratelab's own `/ratelab`, which publishes /clock. Each topic is offered \
             as the ROS 2 type its message maps to: the state as a sensor_msgs/msg/JointState \
             (the cart's slider and the pole's hinge), the force as a std_msgs/msg/Float64 in \
             newtons. /clock is the virtual clock itself: it is published before every instant \
             at which any node ticks, so with the sensor at 50 Hz and the policy at 40 Hz it \
             ticks at the union of both grids (every 20 ms and every 25 ms, together every \
             100 ms): 50 + 40 - 10 = 80 times a second, more often than any node. A ROS 2 node \
             with use_sim_time sees time jump from instant to instant. Like any ROS 2 node, \
             each also publishes its log on /rosout and its parameters' changes on \
             /parameter_events (so `topic list` shows both), and answers `ros2 param list` \
             and `ros2 param get` from the graph file. Check it from the other side, in two \
             terminals:",
        );
        say!(
            cx,
            "  ./scripts/lab.sh run --clock virtual --control-hz {} --duration 60 --ros2",
            b.control_hz
        );
        say!(cx, "  ./scripts/lab.sh ros2 node list; ./scripts/lab.sh ros2 topic list -t; ./scripts/lab.sh ros2 topic hz /clock");
        Ok(())
    }
}
