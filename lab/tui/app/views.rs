//! From the lab's state to the [`View`] a frame draws: each node's box, each topic's
//! arrow, the latency and the segment's counters, built from the one graph spec and what the
//! telemetry told (the log pane's in `app/log.rs`).

use super::*;

impl App {
    pub(super) fn topic_view(&self, id: TopicId) -> TopicView {
        let spec = self.graph.topic(id);
        // After the run ended: the QoS it ran with (keys set the next run's).
        let qos = self
            .ended_with
            .as_ref()
            .and_then(|(_, _, q)| q.get(id.0).copied())
            .unwrap_or_else(|| self.qos_of(id));
        // The depth it ran with, and as set for the next run.
        let (ran_depth, next_depth) = match &self.ended_with {
            Some((_, d, _)) => {
                let next = self.depth_of(id);
                (
                    d.get(id.0).copied().unwrap_or(next),
                    (d.get(id.0) != Some(&next)).then_some(next),
                )
            }
            None => (self.depth_of(id), None),
        };
        let window = self.live.window_topic(id);
        let segment = self.live.segment_topic(id);
        // An attached lab's totals, once the launch ended: its summary's.
        let ended = self.final_topics.as_ref().and_then(|m| m.get(&spec.name));
        let dead = |n: NodeId| {
            self.alive.get(n.0).copied().flatten() == Some(false) || self.fault_of(n).is_some()
        };
        let incompatible: Vec<_> = self
            .graph
            .incompatible(id, &qos)
            .into_iter()
            .map(|(_, node, m)| (node, m))
            .collect();
        let unhealthy = !incompatible.is_empty()
            || dead(spec.publisher)
            || spec.subscribers.iter().any(|&n| dead(n))
            || self.live.window_counter(id, QosCounter::Lost) > 0
            || self
                .live
                .window_counter(id, QosCounter::RequestedDeadlineMissed)
                > 0;
        let uncounted = self.attached.is_some() && dead(spec.holder());
        TopicView {
            name: spec.name.clone(),
            // The filter decides ([`App::graph_views`]).
            shown: true,
            publisher: spec.publisher.0,
            subscriber: spec.subscriber().map(|n| n.0),
            fan_out: (spec.subscribers.len() > 1).then(|| {
                spec.subscribers
                    .iter()
                    .map(|n| self.graph.node(*n).name.as_str())
                    .collect::<Vec<_>>()
                    .join(", ")
            }),
            depth: ran_depth,
            next_depth,
            msg_per_s: window.msg_per_s,
            dropped: window.dropped,
            // A topic nobody reads evicts every message unread: not a drop anyone suffers.
            dropping: spec.subscriber().is_some() && window.dropped > 0,
            unhealthy,
            uncounted,
            measuring: !unhealthy
                && !uncounted
                && window.published < 2
                && !self.live.window_span().1,
            stale_reads: window.stale_reads,
            staling: window.stale_reads > 0,
            segment_dropped: ended.map_or(segment.dropped, |t| t.dropped),
            segment_stale_reads: ended.map_or(segment.stale_reads, |t| t.stale_reads),
            segment_lost: ended.map_or(segment.lost, |t| {
                t.qos_counters
                    .get(QosCounter::Lost.key())
                    .copied()
                    .unwrap_or(0)
            }),
            segment_expired: ended.map_or(segment.expired, |t| {
                t.qos_counters
                    .get(QosCounter::Expired.key())
                    .copied()
                    .unwrap_or(0)
            }),
            qos: (!(qos.is_default() && spec.qos.is_default())).then(|| qos.short_parts(ran_depth)),
            // Over the window, as its drops and stale reads (totals counted from the start
            // read as 40 % loss on a 20 % link under an arrow saying "last 5 s").
            qos_counts: self.last.as_ref().map_or_else(Vec::new, |l| {
                l.topics
                    .get(id)
                    .reported(&[spec.qos, qos])
                    .into_iter()
                    .filter(|c| *c != QosCounter::OfferedDeadlineMissed)
                    .map(|c| (short_counter(c), self.live.window_counter(id, c)))
                    .collect()
            }),
            selected: self.selected == Some(Selected::Topic(id)),
            wire_us: self.wire.get(id.0).copied().flatten(),
            incompatible,
        }
    }

    /// The verdict while the run goes on with its actuator under a fault (killed, or stalled
    /// now): the plant stands still, so the pole is neither balanced nor fallen. `None` when
    /// no actuator is under a fault now.
    fn actuator_still(&self) -> Option<Verdict> {
        let f = self.faults.iter().find(|f| {
            f.covers(self.now)
                && (self.graph.node_id(&f.node))
                    .is_some_and(|id| self.graph.node(id).kind.is_actuator())
        })?;
        let at_s = f.at.as_secs_f64();
        Some(Verdict::Still(match f.duration {
            None => format!("ACTUATOR KILLED at t={at_s:.2}s"),
            Some(_) => format!("ACTUATOR STALLED at t={at_s:.2}s"),
        }))
    }

    /// The injected fault node `id` is under now: `STALLED` or `KILLED`.
    pub(super) fn fault_of(&self, id: NodeId) -> Option<&'static str> {
        let name = &self.graph.node(id).name;
        self.faults
            .iter()
            .find(|f| &f.node == name && f.covers(self.now))
            .map(|f| {
                if f.duration.is_some() {
                    "STALLED"
                } else {
                    "KILLED"
                }
            })
    }

    /// `hung`: the callback held now, if any ([`App::hung_callback`], asked once a frame).
    pub(super) fn node_view(
        &self,
        id: NodeId,
        layer: usize,
        hung: Option<&hang::HungCall>,
    ) -> NodeView {
        let empty = VecDeque::new();
        let q = self.ticks.get(id.0).unwrap_or(&empty);
        // No tick for a second or two periods (a node whose process died): 0 Hz now.
        let quiet = Nanos::from_secs_f64(2.0 / self.rate_of(id).max(1e-3))
            .unwrap_or(TICK_WINDOW)
            .max(TICK_WINDOW);
        let silent = q
            .back()
            .is_some_and(|(t, ..)| self.now.saturating_sub(*t) > quiet);
        let (measured_hz, lateness_p99_us, tick_p50_us) = if self.clock == "real" && q.len() >= 2 {
            let span = (q.back().expect("len ≥ 2").0)
                .saturating_sub(q.front().expect("len ≥ 2").0)
                .as_secs_f64();
            let mut late: Vec<u64> = q.iter().map(|(_, l, _)| l.0).collect();
            late.sort_unstable();
            let p99 = late[((late.len() as f64 * 0.99).ceil() as usize).clamp(1, late.len()) - 1];
            let mut took: Vec<u64> = q.iter().map(|(.., d)| d.0).collect();
            took.sort_unstable();
            let p50 = took[(took.len() - 1) / 2];
            let hz = if silent {
                0.0
            } else {
                (q.len() - 1) as f64 / span.max(1e-9)
            };
            (Some(hz), Some(p99 as f64 / 1e3), Some(p50 as f64 / 1e3))
        } else {
            (None, None, None)
        };
        // After the run ended: the rate it ran at, and the next run's when a key changed it.
        let ran_hz = self
            .ended_with
            .as_ref()
            .and_then(|(r, _, _)| r.get(id.0).copied());
        // Virtual clock with executors: the rate the node achieved and the periods its timer
        // skipped waiting for a thread, over the arrows' window (since the start until the
        // run is that long: its tick intervals). Each period of a timer either ticks or is
        // skipped (rcl's timers, `ratelab::rate::next_deadline`), so the rate achieved is the
        // set rate times the share of periods that ticked: exactly the set rate for a node
        // that skipped none, where ticks over the span between two status messages (which
        // fall between ticks) read a tick off (200.3 Hz for 200).
        let ran = self.exec.back().and_then(|(at, x)| {
            let &(ticks, skipped) = x.get(id.0)?;
            let base = match self.exec.front() {
                Some((t0, b)) if t0 < at => b.get(id.0).copied(),
                // One count since a change: nothing to rate yet.
                _ if self.exec_from.is_some() => return None,
                _ => None,
            };
            let (ticks0, skipped0) = base.unwrap_or((1, 0));
            let (ticked, missed) = (
                ticks.saturating_sub(ticks0),
                skipped.saturating_sub(skipped0),
            );
            let hz = if ticked + missed > 0 {
                ran_hz.unwrap_or_else(|| self.rate_of(id)) * ticked as f64
                    / (ticked + missed) as f64
            } else {
                0.0
            };
            Some((hz, missed))
        });
        NodeView {
            name: self.graph.node(id).name.clone(),
            // The filter decides ([`App::graph_views`]).
            shown: true,
            layer,
            set_hz: ran_hz.unwrap_or_else(|| self.rate_of(id)),
            phase_ms: self.phases.get(id.0).copied().unwrap_or(0.0),
            next_hz: ran_hz
                .map(|_| self.rate_of(id))
                .filter(|&next| Some(next) != ran_hz),
            measured_hz,
            published_hz: match (
                self.graph.node(id).kind.code(),
                self.graph.node(id).publishes.first(),
            ) {
                (Code::Ros2, Some(&t)) => Some(self.live.window_topic(t).msg_per_s),
                _ => None,
            },
            lateness_p99_us,
            tick_p50_us,
            ran,
            compute: self.graph.node(id).compute.map(|c| c.label()),
            selected: self.selected == Some(Selected::Node(id)),
            alive: self.alive.get(id.0).copied().flatten(),
            fault: self.fault_of(id),
            process: self.attached.as_ref().map(|_| self.graph.process_of(id)),
            badge: match self.graph.node(id).kind.code() {
                Code::Python => Some(Badge::Python),
                Code::Ros2 => Some(Badge::Ros2),
                Code::BuiltIn | Code::Rust => None,
            },
            held: hung
                .filter(|h| h.node == self.graph.node(id).name)
                .map(|h| (h.held_in, h.running_s)),
        }
    }

    /// The latency panel: the segment's histogram and percentiles, and the window's.
    /// The ghost's points over the charts' window ([`super::super::chart_window`]), as
    /// `pick` takes them.
    fn ghost_in_window(&self, pick: impl Fn(&super::GhostStep) -> (f64, f64)) -> Vec<(f64, f64)> {
        let (t0, t1) = self.chart_bounds();
        self.ghost
            .iter()
            .filter(|(t, ..)| *t >= t0 && *t <= t1)
            .map(pick)
            .collect()
    }

    /// The charts' window now, run time s, `(from, to)`.
    fn chart_bounds(&self) -> (f64, f64) {
        self.chart_window.bounds(self.now.as_secs_f64())
    }

    /// A chart's points over its window: from the full-rate history `full` (t s, value)
    /// for a finite window, from the whole run's thinned points as `thinned` takes
    /// them for the whole run.
    fn in_chart_window(
        &self,
        full: &std::collections::VecDeque<(f64, f64)>,
        thinned: impl Fn(&(f64, f64, f64)) -> (f64, f64),
    ) -> Vec<(f64, f64)> {
        self.in_window_of(full, &self.thinned, thinned)
    }

    /// [`App::in_chart_window`] with the whole run's points taken from `whole`.
    fn in_window_of(
        &self,
        full: &std::collections::VecDeque<(f64, f64)>,
        whole: &crate::tui::chart_window::Thinned,
        thinned: impl Fn(&(f64, f64, f64)) -> (f64, f64),
    ) -> Vec<(f64, f64)> {
        let (t0, t1) = self.chart_bounds();
        match self.chart_window.span_s() {
            Some(_) => full
                .iter()
                .copied()
                .filter(|(t, _)| *t >= t0 && *t <= t1)
                .collect(),
            None => whole.points().iter().map(thinned).collect(),
        }
    }

    pub(super) fn latency_view(&self) -> LatencyView {
        let latency = &self.live.segment().latency;
        let mut buckets: Vec<(String, u64)> = (0..BUCKETS)
            .map(|i| {
                // Each bar holds [i·20, (i+1)·20) ms, the last [200, ∞): labelled by the bound a
                // sample is below ("<20": a fixed 10 ms, or 19.99 ms, is read right).
                let label = if i + 1 == BUCKETS {
                    format!("≥{}", i as u64 * BUCKET.0 / 1_000_000)
                } else {
                    format!("<{}", (i as u64 + 1) * BUCKET.0 / 1_000_000)
                };
                (label, 0)
            })
            .collect();
        // Exact counts per bar (the samples themselves, not the histogram's rounding: a
        // sample of exactly 200 ms is in the last bar, one of 19.99 ms in the first).
        let mut below_prev = 0;
        for (i, b) in buckets.iter_mut().enumerate() {
            let below = if i + 1 == BUCKETS {
                latency.count()
            } else {
                latency.count_below(Nanos((i as u64 + 1) * BUCKET.0))
            };
            b.1 = below.saturating_sub(below_prev);
            below_prev = below;
        }
        // The run before a reload over the same span of run time (this segment's start to
        // now), in the same bars.
        let (from, to) = (
            self.live.segment().start.as_secs_f64(),
            self.now.as_secs_f64(),
        );
        let mut ghost = vec![0u64; if self.ghost.is_empty() { 0 } else { BUCKETS }];
        let spanned = (self.ghost.iter()).filter(|(t, ..)| *t >= from && *t <= to);
        for latency in spanned.filter_map(|g| g.3) {
            let i =
                usize::try_from(latency.0 / BUCKET.0).map_or(BUCKETS - 1, |i| i.min(BUCKETS - 1));
            if let Some(b) = ghost.get_mut(i) {
                *b += 1;
            }
        }
        let (n, stats) = self.live.window_latency();
        let down = |n: Option<Nanos>| n.map_or(0.0, tenth_ms_down);
        LatencyView {
            buckets,
            ghost,
            count: latency.count(),
            no_command: self.live.segment().no_command,
            p50_ms: down(latency.quantile(0.5)),
            p99_ms: down(latency.quantile(0.99)),
            max_ms: down(latency.max()),
            window: WindowLatency {
                count: n as u64,
                no_command: self.live.window_no_command(),
                p50_ms: down(stats.map(|s| s.0)),
                p99_ms: down(stats.map(|s| s.1)),
                max_ms: down(stats.map(|s| s.2)),
            },
        }
    }

    /// Paused under the virtual clock, or reviewing: the run at the scrub cursor (`now`),
    /// from the actuator's tick at or before it — the step record its `trace.csv` row is
    /// written from — with the selected topic's counters at that tick (a node's: the first
    /// topic it publishes, else the first it reads). `None` otherwise, or before the first
    /// tick.
    pub(super) fn readout(&self) -> Option<super::super::view::Readout> {
        let paused = self.paused && self.clock == "virtual" && self.attached.is_none();
        let rec = self.last.as_ref().filter(|_| paused || self.reviewing())?;
        let topic = match self.selected {
            Some(Selected::Topic(t)) => Some(t),
            Some(Selected::Node(n)) => {
                let node = self.graph.node(n);
                node.publishes.first().or(node.subscribes.first()).copied()
            }
            None => None,
        };
        let counters = topic.map(|id| {
            let stats = rec.topics.get(id);
            let spec = self.graph.topic(id);
            super::super::view::TopicCounts {
                topic: spec.name.clone(),
                msgs: stats.published,
                dropped: stats.dropped,
                stale_reads: stats.stale_reads,
                // Those its arrow labels (the publisher's deadline misses it leaves out).
                qos: stats
                    .reported(&[spec.qos, self.qos_of(id)])
                    .into_iter()
                    .filter(|c| *c != QosCounter::OfferedDeadlineMissed)
                    .map(|c| (short_counter(c), stats.counter(c)))
                    .collect(),
            }
        });
        Some(super::super::view::Readout::at(self.now, rec, counters))
    }

    /// With an estimator in the graph, its chart's view: shown in the pole-angle chart's
    /// place while the estimator node or the topic of its estimate is selected (Tab), its
    /// lines taken over the charts' window only then; the figures always (the summary's).
    pub(super) fn estimator_view(&self) -> Option<super::super::view::EstimatorView> {
        let topic = self.graph.estimate_topic()?;
        let node = self.graph.topic(topic).publisher;
        let shown = self.selected == Some(Selected::Node(node))
            || self.selected == Some(Selected::Topic(topic));
        let line = |s: &crate::tui::chart_window::Series| -> Vec<(f64, f64)> {
            if shown {
                self.in_window_of(&s.recent, &s.whole, |&(t, v, _)| (t, v))
            } else {
                Vec::new()
            }
        };
        Some(super::super::view::EstimatorView {
            node: self.graph.node(node).name.clone(),
            topic: self.graph.topic(topic).name.clone(),
            shown,
            angvel: line(&self.estimates.angvel),
            angvel_estimate: line(&self.estimates.angvel_estimate),
            figures: self.estimates.figures(),
        })
    }

    /// The segment since the last change, for the segment line and the angle chart.
    pub(super) fn segment_view(&self) -> SegmentView {
        let seg = self.live.segment();
        let (span, full) = self.live.window_span();
        SegmentView {
            index: seg.index,
            start_s: seg.start.as_secs_f64(),
            cause: seg.cause.clone(),
            // Both spans are at most the window's.
            window_s: span.as_secs_f64(),
            window_full: full,
            latency_window_s: self.live.latency_span().0.as_secs_f64(),
            marks_s: self
                .live
                .marks()
                .map(Nanos::as_secs_f64)
                .filter(|&t| t > 0.0)
                .collect(),
            joined_s: seg.joined().map(Nanos::as_secs_f64),
        }
    }

    /// The frame's view model.
    pub fn view(&self) -> View {
        // Asked once a frame: the verdict and the nodes' boxes read the same answer.
        let hung = self.hung_callback();
        let (nodes, topics) = self.graph_views(hung.as_ref());
        View {
            clock: self.clock.clone(),
            // An attached lab's graph runs at the lockstep's pace, not the lab's.
            speed: if self.clock == "virtual" && self.attached.is_none() {
                self.speed.to_string()
            } else {
                String::new()
            },
            paused: self.paused,
            review: self.reviewing(),
            sim_time_s: self.now.as_secs_f64(),
            seed: self.seed,
            // A Python or external policy node is its own brain (`--policy` does not apply).
            brain: match self.graph.chain.map(|c| self.graph.node(c.policy).kind) {
                None => "no policy".into(),
                Some(k) => match k.code() {
                    Code::Python => "py node".into(),
                    Code::Ros2 => "ROS 2 node".into(),
                    Code::Rust => format!("{k} node"),
                    Code::BuiltIn if k.def().uses_brain => short_brain(&self.policy_spec),
                    Code::BuiltIn => format!("{k} node"),
                },
            },
            brain_caption: self
                .brain
                .split_once(" — ")
                .map(|(_, caption)| caption.to_string()),
            recording: self.recording.clone(),
            nodes,
            topics,
            pole_angle: self.last.as_ref().map_or(0.0, |s| s.pole_angle),
            cart_pos: self.last.as_ref().map_or(0.0, |s| s.cart_pos),
            // While a callback holds the run, the run is not "balanced": it is hung, since the
            // run time it holds (the virtual clock stands there; under the real clock, from
            // when it started).
            verdict: match (&self.verdict, hung) {
                (Verdict::Balanced, Some(h)) => Verdict::Hung {
                    node: h.node,
                    held_in: h.held_in,
                    since_s: if self.clock == "real" {
                        (self.now.as_secs_f64() - h.running_s).max(0.0)
                    } else {
                        self.now.as_secs_f64()
                    },
                },
                (Verdict::Balanced, None) => self.actuator_still().unwrap_or(Verdict::Balanced),
                (v, _) => v.clone(),
            },
            angle_history: self.in_chart_window(&self.history, |&(t, a, _)| (t, a)),
            angle_estimate: self.in_window_of(
                &self.estimates.angle.recent,
                &self.estimates.angle.whole,
                |&(t, a, _)| (t, a),
            ),
            estimator: self.estimator_view(),
            // Each applied force holds until the next step: a staircase.
            applied_force: staircase(&self.in_chart_window(&self.applied, |&(t, _, f)| (t, f))),
            // The whole run draws no dots: thinned, they would not be the policy's ticks.
            published_force: match self.chart_window.span_s() {
                Some(_) => self.in_chart_window(&self.published, |_| (0.0, 0.0)),
                None => Vec::new(),
            },
            chart_s: self.chart_bounds(),
            chart_label: self.chart_window.label(),
            ghost_angle: self.ghost_in_window(|&(t, a, ..)| (t, a)),
            // The run before's applied force, as a staircase too.
            ghost_force: staircase(&self.ghost_in_window(|&(t, _, f, _)| (t, f))),
            latency: self.latency_view(),
            readout: self.readout(),
            log: self.show_log.then(|| self.log_view()),
            ended: self.ended_word.clone(),
            ros2: match (self.show_ros2, self.ros2_domain) {
                (true, Some(domain)) => Some(Ros2View {
                    domain,
                    offered: ratelab::ros2::offered::offered(&self.graph),
                }),
                _ => None,
            },
            timeline: self.show_timeline.then(|| {
                self.timeline.view(
                    &self.graph,
                    &self.graph.execution_plan(),
                    // The rates the ticks ran at (after a fall, not the next run's).
                    &match &self.ended_with {
                        Some((r, ..)) => r.clone(),
                        None => (0..self.graph.nodes.len())
                            .map(|i| self.rate_of(NodeId(i)))
                            .collect::<Vec<_>>(),
                    },
                    self.now,
                )
            }),
            segment: self.segment_view(),
            help: self.help,
            typing: self.typing.clone(),
            message: self.shown_message(),
            message_fresh: self.message_at.is_some_and(|at| at.elapsed() < FRESH),
            attached: self.attached.clone(),
            endpoint: self.endpoint.clone(),
            nav: NavView {
                zoom: self.nav.zoom,
                scroll: self.nav.scroll,
                filter: self.nav.filter.label(),
                text: self.nav.filter.text.clone(),
                typing: self.nav.typing.is_some(),
                reach: self.nav.reach.clone(),
            },
        }
    }

    /// Each node's box and each topic's arrow, marked shown where the graph panel's filter
    /// lets them through (`hung`: as for [`App::node_view`]).
    pub(super) fn graph_views(
        &self,
        hung: Option<&hang::HungCall>,
    ) -> (Vec<NodeView>, Vec<TopicView>) {
        let filter = &self.nav.filter;
        // Processes only where the filter asks for one (a frame of a large graph).
        let process_of = |id: NodeId| {
            if filter.text.starts_with('@') {
                self.graph.process_of(id)
            } else {
                String::new()
            }
        };
        let mut nodes: Vec<NodeView> = self
            .graph
            .layers()
            .into_iter()
            .enumerate()
            .map(|(i, layer)| self.node_view(NodeId(i), layer, hung))
            .collect();
        for (i, n) in nodes.iter_mut().enumerate() {
            n.shown = filter.node(n, &process_of(NodeId(i)));
        }
        let mut topics: Vec<TopicView> = (0..self.graph.topics.len())
            .map(|i| self.topic_view(TopicId(i)))
            .collect();
        for t in &mut topics {
            let p = NodeId(t.publisher);
            t.shown = filter.topic(t, &nodes[p.0], &process_of(p));
        }
        (nodes, topics)
    }
}

/// Each force held until the next point's time: a staircase, as the zero-order hold applies
/// it.
fn staircase(points: &[(f64, f64)]) -> Vec<(f64, f64)> {
    points
        .windows(2)
        .flat_map(|w| [(w[0].0, w[0].1), (w[1].0, w[0].1)])
        .collect()
}

/// A run's faults as the lab shows them on their nodes.
#[derive(Clone, Debug, Default)]
pub(super) struct Faults {
    /// Given at the start (`--stall`, `--kill`): the run's from its first instant.
    pub(super) given: Vec<ratelab::qos::Fault>,
    /// Injected while the run went (`k`, a session log's `inject_fault`), each from the
    /// instant it took effect ([`ratelab::session::Telemetry::Faulted`]): a seek back before that drops it.
    pub(super) injected: Vec<ratelab::qos::Fault>,
}

impl Faults {
    /// Every fault, given first.
    pub(super) fn iter(&self) -> impl Iterator<Item = &ratelab::qos::Fault> {
        self.given.iter().chain(&self.injected)
    }
}
