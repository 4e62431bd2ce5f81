//! What a recording writes while the run goes: the step observer that turns every actuator
//! step into rows (the plant, the action, the latency, the bus counters, QoS and liveliness
//! events, the executor lanes), gathered into chunks and flushed in a fixed order
//! ([`super::FLUSH_EVERY_STEPS`]), so a virtual run's recording is the same every time.

use super::*;

/// Where the change marks sit on the pole-angle plot: just above the upper fall limit.
pub(super) const CHANGE_MARK_RAD: f64 = 0.24;

/// The constant reference series (fall limits, rail ends, cart limits) at `t`: logged at the
/// start, at every flush and at the end, so their lines span the run.
pub(super) fn reference_lines(buf: &mut ChunkBuffer, t: Nanos, step: u64) {
    for (name, sign) in [("upper", 1.0), ("lower", -1.0)] {
        buf.scalar(
            &format!("plant/fall_limit/{name}"),
            t,
            step,
            sign * THETA_LIMIT_RAD,
        );
    }
    for (name, sign) in [("right", 1.0), ("left", -1.0)] {
        buf.scalar(
            &format!("plant/rail_end/{name}"),
            t,
            step,
            sign * RAIL_HALF_LENGTH_M,
        );
        buf.scalar(
            &format!("plant/cart_limit/{name}"),
            t,
            step,
            sign * CART_LIMIT_M,
        );
    }
}

/// The entity of an estimator's estimate of the pole angle, rad.
const ESTIMATE_ENTITY: &str = "plant/pole_angle_estimate_rad";

pub(super) struct RecordingObserver {
    rec: Recording,
    shape: GraphShape,
    /// Rates, depths and QoS as last logged.
    last_state: Option<GraphState>,
    /// (t, published per topic) over the last second.
    window: VecDeque<(Nanos, Vec<u64>)>,
    /// The next command sequence number not yet logged as published.
    next_command: u64,
    /// Per topic, the QoS counters logged so far: once reported, a series goes on to the
    /// end of the run.
    qos_logged: Vec<Vec<QosCounter>>,
    /// Per topic, (offered, requested) deadline periods missed at the last step.
    deadline_seen: Vec<(u64, u64)>,
    /// Per node, its liveliness as last seen (`None` until it is logged: a node with a
    /// lease, or one that has lost its liveliness).
    live_seen: Vec<Option<LiveSeen>>,
    /// With a [`RecordWindow`]: the steps were inside it at the last step (its start and
    /// end are each marked once).
    in_window: bool,
    /// The estimate's series has its name and colour (logged with its first point).
    estimate_styled: bool,
    /// A large graph's groups ([`super::groups`]): its bus also drawn by group, its node
    /// graph a box per group. `None` for a graph drawn node by node.
    groups: Option<super::groups::Groups>,
    /// The previous step's run time, step number and whether its rows were muted (outside
    /// the recording window): an estimate is logged there, where the angle's line shows the
    /// state it estimates.
    previous: Option<(Nanos, u64, bool)>,
}

impl RecordingObserver {
    /// An observer writing `shape`'s run into `rec`, nothing logged yet.
    pub(super) fn new(rec: Recording, shape: GraphShape) -> RecordingObserver {
        RecordingObserver {
            rec,
            groups: super::groups::Groups::of(&shape),
            shape,
            last_state: None,
            window: VecDeque::new(),
            next_command: 0,
            qos_logged: Vec::new(),
            deadline_seen: Vec::new(),
            live_seen: Vec::new(),
            in_window: false,
            estimate_styled: false,
            previous: None,
        }
    }

    /// With a [`RecordWindow`]: (does step `s` enter it, is it outside it)? A fall is
    /// recorded wherever it is. At the window's first step and the first after it, an
    /// event says so.
    fn window_edge(&mut self, buf: &mut ChunkBuffer, s: &StepRecord) -> (bool, bool) {
        let Some(w) = self.rec.window() else {
            return (false, false);
        };
        let inside = w.contains(s.t) || s.fell;
        if inside == self.in_window {
            return (false, !inside);
        }
        let text = if inside {
            format!(
                "recording from here: the plots hold {} (--record-window)",
                w.describe()
            )
        } else {
            format!("recording stops here: the plots hold {} (--record-window); the events go on to the end", w.describe())
        };
        buf.event(
            s.t,
            s.step,
            None,
            &text,
            rerun::components::TextLogLevel::INFO,
        );
        self.in_window = inside;
        (inside, !inside)
    }

    /// Each topic's counters at step `s`: into the last second's window (msg/s) and the
    /// counts [`Recording::finish`] starts from.
    fn note_published(&mut self, s: &StepRecord) -> Vec<TopicStats> {
        let stats: Vec<TopicStats> = self.shape.topics.iter().map(|t| (t.stats)()).collect();
        self.window
            .push_back((s.t, stats.iter().map(|st| st.published).collect()));
        while self
            .window
            .front()
            .is_some_and(|(t, _)| s.t.saturating_sub(*t) > Nanos::SECOND)
        {
            self.window.pop_front();
        }
        let mut last = self
            .rec
            .last_step_published
            .lock()
            .unwrap_or_else(|e| e.into_inner());
        for (topic, st) in self.shape.topics.iter().zip(&stats) {
            match last.get_mut(&topic.name) {
                Some(n) => *n = st.published,
                None => {
                    last.insert(topic.name.clone(), st.published);
                }
            }
        }
        stats
    }
}

/// A node's liveliness as the recording last saw it.
#[derive(Clone, Copy)]
struct LiveSeen {
    alive: bool,
    not_alive: u64,
    last_asserted: Nanos,
}

impl RecordingObserver {
    /// The node graph with its current labels: nodes (blue) and topics (amber) placed left
    /// to right, edges publisher → topic → subscriber.
    fn graph_rows(&self, buf: &mut ChunkBuffer, time: &TimePoint) {
        if let Some(groups) = &self.groups {
            // A large graph: a box per group ([`super::groups`]).
            super::grouped::graph_rows(buf, time, &self.shape, groups);
            return;
        }
        let shape = &self.shape;
        let (positions, _) = graph_positions(shape);
        // A node's label and a topic's (`NodeShape::label`, `TopicShape::label`): its rate
        // or depth, a Python node or a node's process, a topic's QoS in short.
        let label = |id: &str| {
            if let Some(n) = shape.nodes.iter().find(|n| n.name == id) {
                (n.label(), node_color(id))
            } else {
                let topic = shape.topics.iter().find(|t| t.name == id);
                let text = topic.map_or_else(|| format!("{id} · depth 0"), |t| t.label());
                (text, topic_color(id))
            }
        };
        let (labels, colors): (Vec<String>, Vec<Color>) =
            positions.iter().map(|(id, _)| label(id)).unzip();
        buf.add(
            "graph",
            time,
            &rerun::GraphNodes::new(positions.iter().map(|(id, _)| id.as_str()))
                .with_positions(positions.iter().map(|(_, p)| *p))
                .with_labels(labels)
                .with_colors(colors),
        );
        let mut edges = Vec::new();
        for t in &shape.topics {
            edges.push((t.publisher.clone(), t.name.clone()));
            for s in &t.subscribers {
                edges.push((t.name.clone(), s.clone()));
            }
        }
        buf.add(
            "graph",
            time,
            &rerun::GraphEdges::new(edges).with_directed_edges(),
        );
    }

    /// What changed between two states, as one event line.
    fn describe_change(&self, old: &GraphState, new: &GraphState) -> String {
        let mut parts = Vec::new();
        for (i, node) in self.shape.nodes.iter().enumerate() {
            if old.rates.get(i) != new.rates.get(i) {
                parts.push(format!(
                    "{} rate {} → {} Hz",
                    node.name,
                    old.rates.get(i).map_or("?".into(), |h| hz_label(*h)),
                    new.rates.get(i).map_or("?".into(), |h| hz_label(*h))
                ));
            }
        }
        for (i, topic) in self.shape.topics.iter().enumerate() {
            let (d0, d1) = (
                old.depths.get(i).copied().unwrap_or_default(),
                new.depths.get(i).copied().unwrap_or_default(),
            );
            if d0 != d1 {
                parts.push(format!("{} depth {d0} → {d1}", topic.name));
            }
            if let (Some(q0), Some(q1)) = (old.qos.get(i), new.qos.get(i)) {
                if q0 != q1 {
                    parts.push(format!(
                        "{} QoS {} → {}",
                        topic.name,
                        q0.short(d1),
                        q1.short(d1)
                    ));
                }
            }
        }
        parts.join("; ")
    }

    /// Whether every change from `old` to `new` is a node's rate that a ROS 2 parameter set
    /// announced ([`Recording::parameter_set`], whose own event marks it). The announcements
    /// about the nodes whose rate changed are used up either way.
    fn announced(&self, old: &GraphState, new: &GraphState) -> bool {
        let rates: Vec<(&str, f64)> = self
            .shape
            .nodes
            .iter()
            .zip(old.rates.iter().zip(&new.rates))
            .filter(|(_, (a, b))| a != b)
            .map(|(n, (_, b))| (n.name.as_str(), *b))
            .collect();
        let mut said = self.rec.announced.lock().unwrap_or_else(|e| e.into_inner());
        let all = !rates.is_empty()
            && old.depths == new.depths
            && old.qos == new.qos
            && rates.iter().all(|(n, hz)| {
                said.iter()
                    .any(|(m, h)| m.as_str() == *n && (h - hz).abs() < 1e-9)
            });
        said.retain(|(m, _)| !rates.iter().any(|(n, _)| m.as_str() == *n));
        all
    }

    /// The topics' counters at step `s`, with msg/s over the last second of run time, and
    /// the counts the recording's summary reads.
    fn bus_rows(&mut self, buf: &mut ChunkBuffer, s: &StepRecord) {
        // Bus counters and msg/s over the last second of run time.
        let stats = self.note_published(s);
        // A large graph's groups take each topic's values too (published, dropped, msg/s).
        let mut values: Option<[Vec<Option<f64>>; 3]> = self.groups.as_ref().map(|_| {
            let n = stats.len();
            [
                Vec::with_capacity(n),
                Vec::with_capacity(n),
                Vec::with_capacity(n),
            ]
        });
        for (i, (topic, st)) in self.shape.topics.iter().zip(&stats).enumerate() {
            let entity = topic.entity();
            buf.scalar(
                &format!("bus/{entity}/published"),
                s.t,
                s.step,
                st.published as f64,
            );
            buf.scalar(
                &format!("bus/{entity}/dropped"),
                s.t,
                s.step,
                st.dropped as f64,
            );
            // The window from the topic's first counted message: the first step spans no
            // time, and a topic counted by another process has no count before that
            // process's first figures; either way no rate yet (not 0 msg/s, then a jump).
            // Saturating: a topic's counters from another process may start over (it was
            // restarted) or arrive from a peer that misbehaves.
            let from = self
                .window
                .iter()
                .find(|(_, counts)| counts.get(i).is_some_and(|n| *n > 0));
            let mut rate = None;
            if let Some((t0, counts)) = from {
                let span = s.t.saturating_sub(*t0).as_secs_f64();
                if span > 0.0 {
                    let r = st.published.saturating_sub(counts[i]) as f64 / span;
                    buf.scalar(&format!("bus/{entity}/msg_per_s"), s.t, s.step, r);
                    rate = Some(r);
                }
            }
            if let Some([published, dropped, msg_per_s]) = &mut values {
                published.push(Some(st.published as f64));
                dropped.push(Some(st.dropped as f64));
                msg_per_s.push(rate);
            }
        }
        if let (Some(groups), Some(values)) = (&self.groups, &values) {
            super::grouped::bus_rows(buf, groups, s.t, s.step, values);
        }
    }

    /// The QoS counters and events of this step (nothing for the chapter's QoS): each topic's
    /// reported counters as series under its `bus/<topic>/` entity, an event when a deadline
    /// counter rose, each leased node's not-alive count, and an event when a node's
    /// liveliness changed.
    fn qos_rows(&mut self, buf: &mut ChunkBuffer, s: &StepRecord) {
        let n = self.shape.topics.len();
        self.qos_logged.resize(n, Vec::new());
        self.deadline_seen.resize(n, (0, 0));
        for (i, topic) in self.shape.topics.iter().enumerate() {
            // The actuator's counters at this step (deadline periods missed up to now
            // count before the next message); the topic's own as a fallback.
            let st = if i < s.topics.len() {
                s.topics.get(ratelab_core::ids::TopicId(i))
            } else {
                (topic.stats)()
            };
            let logged = &mut self.qos_logged[i];
            for c in st.reported(&[topic.qos, (topic.live_qos)()]) {
                if !logged.contains(&c) {
                    logged.push(c);
                    let color =
                        QOS_COLORS[QosCounter::ALL.iter().position(|a| *a == c).unwrap_or(0)];
                    series_style(
                        buf,
                        &qos_entity(topic, c),
                        &format!("{} {}", topic.name, counter_words(c)),
                        rgb(color),
                    );
                }
            }
            logged.sort_by_key(|c| QosCounter::ALL.iter().position(|a| a == c));
            for c in logged.iter() {
                buf.scalar(&qos_entity(topic, *c), s.t, s.step, st.counter(*c) as f64);
            }
            let (offered, requested) = (st.offered_deadline_missed, st.requested_deadline_missed);
            let (o0, r0) = self.deadline_seen[i];
            if offered > o0 || requested > r0 {
                // A burst's first miss is said; misses within DEADLINE_EVENT_GAP of the last
                // line are counted, and said with the next line or at the end.
                let mut said = self
                    .rec
                    .deadline_said
                    .lock()
                    .unwrap_or_else(|e| e.into_inner());
                let (so, sr, last) = match said.get(&topic.name) {
                    Some(&(o, r, at)) => (o, r, Some(at)),
                    None => (0, 0, None),
                };
                let quiet = last.is_none_or(|at| s.t.saturating_sub(at) > DEADLINE_EVENT_GAP);
                if quiet {
                    buf.event(
                        s.t,
                        s.step,
                        Some(Mark::Trouble),
                        &deadline_line(&topic.name, (so, sr), (offered, requested), ""),
                        rerun::components::TextLogLevel::WARN,
                    );
                    said.insert(topic.name.clone(), (offered, requested, s.t));
                }
            }
            self.deadline_seen[i] = (offered.max(o0), requested.max(r0));
        }
        self.live_seen.resize(self.shape.nodes.len(), None);
        for (i, node) in self.shape.nodes.iter().enumerate() {
            let Some(live) = &node.liveliness else {
                continue;
            };
            let status = live.status_at(s.t);
            let lease = live.lease();
            let seen = match self.live_seen[i] {
                Some(seen) => seen,
                None if lease.is_some() || status.not_alive > 0 => {
                    let entity = not_alive_entity(&node.name);
                    series_style(
                        buf,
                        &entity,
                        &format!("{} not alive (times)", node.name),
                        node_color(&node.name),
                    );
                    LiveSeen {
                        alive: true,
                        not_alive: 0,
                        last_asserted: Nanos::ZERO,
                    }
                }
                None => continue,
            };
            buf.scalar(
                &not_alive_entity(&node.name),
                s.t,
                s.step,
                status.not_alive as f64,
            );
            // Each loss at the instant its lease ran out (the node's last tick before it
            // plus the lease), each return at the tick that brought the node back. A node
            // still not alive has not ticked since its last assertion, so that instant is
            // exact; one that lapsed and came back between two steps is dated from the
            // tick seen at the step before.
            if status.not_alive > seen.not_alive {
                let before = if status.alive {
                    seen.last_asserted
                } else {
                    status.last_asserted
                };
                let lapsed_at = before.saturating_add(lease.unwrap_or(Nanos::ZERO)).min(s.t);
                let lease_text = lease.map_or(String::new(), |l| format!(" (lease {l})"));
                buf.event(
                    lapsed_at,
                    s.step,
                    Some(Mark::Trouble),
                    &format!("node {} not alive{lease_text}", node.name),
                    rerun::components::TextLogLevel::WARN,
                );
            }
            let came_back = status.alive && (!seen.alive || status.not_alive > seen.not_alive);
            if came_back {
                buf.event(
                    status.last_asserted,
                    s.step,
                    Some(Mark::Recovery),
                    &format!("node {} alive again", node.name),
                    rerun::components::TextLogLevel::INFO,
                );
            }
            self.live_seen[i] = Some(LiveSeen {
                alive: status.alive,
                not_alive: status.not_alive,
                last_asserted: status.last_asserted,
            });
        }
    }
}

impl StepObserver for RecordingObserver {
    fn attach(&mut self, h: &GraphHandles) {
        self.shape = GraphShape::from_handles(h);
        self.groups = super::groups::Groups::of(&self.shape);
        self.rec.attach(&self.shape);
    }

    fn on_step(&mut self, s: &StepRecord) {
        self.rec
            .last_step
            .store(s.step, std::sync::atomic::Ordering::Relaxed);
        self.rec
            .last_step_ns
            .store(s.t.0, std::sync::atomic::Ordering::Relaxed);
        let rec = self.rec.clone();
        let mut buf = rec.lock();
        rec.log_due_events(&mut buf, s.t, s.step);
        // Outside the window the step goes through as any other, its rows muted: the
        // events (changes, deadlines, liveliness) are recorded all the same.
        let (entering, outside) = self.window_edge(&mut buf, s);
        buf.rows_muted = outside;
        let time = buf.at(s.t, s.step);
        let state = self.shape.state();
        let changed = self.last_state.as_ref() != Some(&state);
        // Entering the window: the graph as it is now, whether or not it changed.
        if changed || entering {
            // A change mid-run (the first state is the start's, an event of its own). A rate
            // set from ROS 2 is marked at the parameter set's own event: listed here only.
            if let (Some(old), true) = (&self.last_state, changed) {
                let text = self.describe_change(old, &state);
                let mark = (!self.announced(old, &state)).then_some(Mark::Change);
                buf.event(
                    s.t,
                    s.step,
                    mark,
                    &text,
                    rerun::components::TextLogLevel::INFO,
                );
            }
            self.graph_rows(&mut buf, &time);
            self.last_state = Some(state);
        }
        let theta = s.pole_angle;
        let force = s.action * FORCE_PER_CONTROL_N;
        world_rows(&mut buf, &time, s, force);
        buf.scalar("plant/pole_angle_rad", s.t, s.step, theta);
        // With an estimator: its estimate where the angle's line shows the state it
        // estimates (each angle is the one its step reached, the state the next step's
        // sensors read): at the previous step's time and number, muted as its rows were;
        // as the lab draws it.
        let estimate = s.estimate.as_ref().and_then(|e| e.estimate);
        let previous = self.previous.replace((s.t, s.step, outside));
        if let (Some(est), Some((t, step, muted_then))) = (estimate, previous) {
            if !std::mem::replace(&mut self.estimate_styled, true) {
                // Drawn before the angle (its entity sorts first) and wider: where the
                // estimate lies on its truth, a band either side of the angle's line.
                let name = "pole angle estimate θ̂";
                let style = rerun::SeriesLines::new()
                    .with_names([name])
                    .with_colors([rgb(ESTIMATE_COLOR)])
                    .with_widths([ESTIMATE_WIDTH]);
                // A static row, written whether or not this step is inside a recording
                // window (the series keeps its name whenever its points start).
                let muted = std::mem::replace(&mut buf.rows_muted, false);
                buf.style(ESTIMATE_ENTITY, name, &style);
                buf.rows_muted = muted;
            }
            let angle = est[ratelab_core::estimate::POLE_ANGLE];
            let muted_now = std::mem::replace(&mut buf.rows_muted, muted_then);
            buf.scalar(ESTIMATE_ENTITY, t, step, angle);
            buf.rows_muted = muted_now;
        }
        buf.scalar("plant/cart_pos_m", s.t, s.step, s.cart_pos);
        buf.scalar("action/applied_N", s.t, s.step, force);
        if let Some(commands) = &self.shape.commands {
            for msg in commands.peek_from(self.next_command) {
                self.next_command = msg.seq + 1;
                let asked = msg.data.newtons;
                if asked.is_finite() {
                    buf.scalar("action/published_N", msg.stamp, s.step, asked);
                }
            }
        }
        if let Some(lat) = s.latency {
            buf.scalar("latency/sense_to_act_ms", s.t, s.step, lat.as_millis_f64());
        }
        if let Some(period) = self.shape.controller_period_ms() {
            buf.scalar("latency/control_period_ms", s.t, s.step, period);
        }
        self.bus_rows(&mut buf, s);
        self.qos_rows(&mut buf, s);
        if s.fell {
            fall_rows(&mut buf, &time, s);
        }
        if s.step % FLUSH_EVERY_STEPS == 0 || s.fell {
            reference_lines(&mut buf, s.t, s.step);
            buf.send(&rec.rec);
        }
        buf.rows_muted = false;
    }
}

/// The cart, the pole at its angle and the applied `force` (N) as an arrow, in 3D.
fn world_rows(buf: &mut ChunkBuffer, time: &TimePoint, s: &StepRecord, force: f64) {
    buf.add(
        "world/cart",
        time,
        &rerun::Transform3D::from_translation([s.cart_pos as f32, 0.0, 0.0]),
    );
    buf.add(
        "world/cart/pole",
        time,
        &rerun::Transform3D::from_rotation(rerun::RotationAxisAngle::new(
            [0.0, 1.0, 0.0],
            rerun::Angle::from_radians(s.pole_angle as f32),
        )),
    );
    buf.add(
        "world/cart/force",
        time,
        &rerun::Arrows3D::from_vectors([[(force * 0.04) as f32, 0.0, 0.0]])
            .with_origins([[0.0, -0.06, 0.0]])
            .with_colors([rgb(FORCE_COLOR)])
            .with_radii([0.012])
            .with_labels([format!("{} N", ratelab_core::text::signed(force, 1))]),
    );
}

/// The fall at step `s`: a marker on the angle plot, the pole drawn red and labelled in 3D
/// from then on, and a warning among the events.
fn fall_rows(buf: &mut ChunkBuffer, time: &TimePoint, s: &StepRecord) {
    // A marker on the angle plot where the pole went past its limit.
    buf.scalar(Mark::Fall.entity(), s.t, s.step, s.pole_angle);
    // …and in 3D: from the fall on, the pole is drawn red and labelled.
    buf.add(
        "world/cart/pole/fallen",
        time,
        &rerun::Capsules3D::from_lengths_and_radii([1.0], [0.032]).with_colors([rgb(LIMIT_COLOR)]),
    );
    buf.add(
        "world/cart/pole/fallen/label",
        time,
        &rerun::Points3D::new([[0.0, 0.0, 0.6]])
            .with_colors([rgb(LIMIT_COLOR)])
            .with_radii([0.02])
            .with_labels([format!("FELL at {:.2} s", s.t.as_secs_f64())]),
    );
    let text = format!(
        "FELL at t={:.2}s, θ = {:.3} rad",
        s.t.as_secs_f64(),
        s.pole_angle
    );
    buf.event(
        s.t,
        s.step,
        Some(Mark::Fall),
        &text,
        rerun::components::TextLogLevel::WARN,
    );
}
