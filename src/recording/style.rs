//! How a recording names and colours what it draws: one colour per topic (the same in
//! every graph) and per QoS counter, the node graph's colours, line widths that keep equal
//! series apart, the names and entity paths of the QoS and liveliness series, and each
//! series' name, colour and width as the run starts ([`Recording::log_styles`]).
//!
//! The colours are chosen to stay apart where they meet. The shipped graphs' topics and the
//! QoS counters, twelve colours, are at least 100 apart in the "redmean" distance (a cheap
//! approximation of perceived difference in RGB: √((2 + r̄/256)·ΔR² + 4·ΔG² + (2 + (255 −
//! r̄)/256)·ΔB²), r̄ the two reds' mean, 0–765), so a counter is never taken for a topic;
//! each topic is at least 75 from every node's colour (the node graph draws both); every
//! colour is light enough to read on the viewer's dark background (luma, Rec. 709 on the
//! 0–255 values, at least 90). Two series that coincide (the chapter's `/obs` and `/action`,
//! both at 50 msg/s; the estimate on the pole angle) differ in lightness by at least 50 as
//! well as in hue: a thin line over a wide one of the same lightness blends into one colour
//! at 1280×720, whatever their hues.

use super::*;

/// Colours for per-topic series (readable on rerun's dark background), the shipped
/// graphs' topics' ([`FIXED_TOPICS`]) in order: apart from one another, from the QoS
/// counters' and from the nodes' (module docs).
pub(super) const PALETTE: [(u8, u8, u8); 6] = [
    (80, 220, 255), // light cyan (/obs)
    (220, 100, 20), // rust orange (/action): darker than /obs, where they coincide
    (145, 95, 255), // violet (/meas)
    (70, 215, 120), // emerald (/state)
    (255, 95, 170), // pink (/cmd)
    (240, 230, 90), // yellow (/force)
];

/// The shipped graphs' topics, each with its [`PALETTE`] entry in this order.
pub(super) const FIXED_TOPICS: [&str; 6] = ["/obs", "/action", "/meas", "/state", "/cmd", "/force"];

pub(super) fn palette(i: usize) -> Color {
    let (r, g, b) = PALETTE[i % PALETTE.len()];
    Color::from_rgb(r, g, b)
}

/// A topic's colour, the same in every graph: the shipped graphs' topics have one each
/// (`/obs` light cyan, `/action` rust orange, …), any other topic a palette entry chosen by
/// its name (FNV-1a), so a topic keeps its colour when the graph around it changes.
pub(super) fn topic_color(name: &str) -> Color {
    let i = FIXED_TOPICS
        .iter()
        .position(|t| *t == name)
        .unwrap_or_else(|| (fnv1a(name) % PALETTE.len() as u64) as usize);
    palette(i)
}

/// Colours for nodes (readable on rerun's dark background, apart from one another and
/// from the pole angle's blue): a node has one in every view (its executor lane, response
/// times, skipped ticks, lateness, liveliness, its box in the node graph).
pub(super) const NODE_PALETTE: [(u8, u8, u8); 8] = [
    (255, 120, 95),  // coral
    (80, 205, 175),  // teal
    (175, 140, 255), // lilac
    (235, 190, 90),  // sand
    (160, 215, 80),  // lime
    (255, 130, 200), // rose
    (120, 185, 255), // sky
    (215, 215, 215), // silver
];

/// A node's colour, the same in every graph: the shipped graphs' nodes have one each
/// (`sensor` sky, `policy` coral, `actuator` teal, …), any other node a palette entry chosen
/// by its name (FNV-1a), so a node keeps its colour when the graph around it changes.
pub(super) fn node_color(name: &str) -> Color {
    const FIXED: [&str; 7] = [
        "policy",
        "actuator",
        "estimator",
        "safety",
        "monitor",
        "controller",
        "sensor",
    ];
    let i = FIXED
        .iter()
        .position(|n| *n == name)
        .unwrap_or_else(|| (fnv1a(name) % NODE_PALETTE.len() as u64) as usize);
    let (r, g, b) = NODE_PALETTE[i];
    Color::from_rgb(r, g, b)
}

fn fnv1a(name: &str) -> u64 {
    name.bytes().fold(0xcbf2_9ce4_8422_2325_u64, |h, b| {
        (h ^ u64::from(b)).wrapping_mul(0x0100_0000_01b3)
    })
}

/// A dimmer shade of `c` (two thirds of each channel): a second statistic of one topic
/// (p99 beside p50) in the topic's hue, told apart.
pub(super) fn dimmed(c: Color) -> Color {
    let [r, g, b, _] = c.to_array();
    let d = |x: u8| (u16::from(x) * 2 / 3) as u8;
    Color::from_rgb(d(r), d(g), d(b))
}

/// The widest line [`layered_widths`] draws, px: five layers of 3 px over the thinnest's 2
/// px (14, 11, 8, 5 and 2 px: the most topics a shipped graph has, drawn as they always
/// were). More series share these 12 px in thinner steps: a graph of 99 topics drew its
/// first at 296 px, flooding its plots.
pub(super) const MAX_LAYERED_WIDTH_PX: f32 = 14.0;

/// Line widths (px) for series that can coincide (every topic's published count, two
/// topics at one rate): the viewer draws a plot's series in entity-path order, each over
/// the last, so the first drawn is the widest and every later one narrower; two equal
/// lines then show as one inside the other, both colours visible. Steps of 3 px from 2 px,
/// thinner where that would pass [`MAX_LAYERED_WIDTH_PX`]. Returns one width per name, in
/// the order given.
pub(super) fn layered_widths(entities: &[String]) -> Vec<f32> {
    let mut sorted = entities.to_vec();
    sorted.sort_unstable();
    let n = sorted.len();
    let step = match n {
        0 | 1 => 3.0,
        _ => (3.0f32).min((MAX_LAYERED_WIDTH_PX - 2.0) / (n - 1) as f32),
    };
    entities
        .iter()
        .map(|e| {
            // The first of equal names, as it sorts.
            let rank = sorted.partition_point(|s| s < e);
            2.0 + step * (n - 1 - rank) as f32
        })
        .collect()
}

pub(super) const ANGLE_COLOR: (u8, u8, u8) = (90, 160, 255);
pub(super) const LIMIT_COLOR: (u8, u8, u8) = (235, 80, 80);
/// The pole angle's line width, px.
pub(super) const ANGLE_WIDTH: f32 = 2.0;
/// An estimator's estimate of the pole angle (θ̂): peach, lighter than the angle's blue.
/// Its entity (`plant/pole_angle_estimate_rad`) sorts before the angle's, so the viewer
/// draws it first, under the angle: it is wider ([`ESTIMATE_WIDTH`]), and where the estimate
/// lies on its truth it shows as a peach band either side of the blue line.
pub(super) const ESTIMATE_COLOR: (u8, u8, u8) = (255, 200, 110);
/// The estimate's line width, px: wider than [`ANGLE_WIDTH`] by a band of 1.5 px a side.
pub(super) const ESTIMATE_WIDTH: f32 = 5.0;
pub(super) const NEUTRAL_COLOR: (u8, u8, u8) = (150, 150, 150);
pub(super) const FORCE_COLOR: (u8, u8, u8) = (120, 220, 120);

/// One colour per QoS counter (in [`QosCounter::ALL`]'s order): a counter keeps its colour
/// whichever topic it is on, and none is a topic's (module docs), so the QoS plot's lines
/// are not taken for the bus plots' topics.
pub(super) const QOS_COLORS: [(u8, u8, u8); 6] = [
    (165, 140, 95),  // expired: khaki
    (90, 120, 210),  // refused: slate blue
    (250, 200, 230), // lost: pale pink
    (40, 165, 140),  // retransmitted: deep teal
    (255, 175, 120), // offered deadline missed: apricot
    (235, 60, 60),   // requested deadline missed: red
];

/// A QoS counter as a series name says it: `requested deadline missed`.
pub(super) fn counter_words(c: QosCounter) -> String {
    c.key().replace('_', " ")
}

/// The entity of a topic's QoS counter: `bus/<topic>/<counter key>`.
pub(super) fn qos_entity(topic: &TopicShape, c: QosCounter) -> String {
    format!("bus/{}/{}", topic.entity(), c.key())
}

/// `deadline missed on /cmd: requested +3 (84 in all)`: the misses since `before`,
/// (offered, requested), to `now`, and `tail` after the counts.
pub(super) fn deadline_line(
    topic: &str,
    before: (u64, u64),
    now: (u64, u64),
    tail: &str,
) -> String {
    let mut sides = Vec::new();
    if now.0 > before.0 {
        sides.push(format!("offered +{} ({} in all)", now.0 - before.0, now.0));
    }
    if now.1 > before.1 {
        sides.push(format!(
            "requested +{} ({} in all)",
            now.1 - before.1,
            now.1
        ));
    }
    format!("deadline missed on {topic}: {}{tail}", sides.join(", "))
}

/// The entity of a node's not-alive count: `nodes/<name>/not_alive`.
pub(super) fn not_alive_entity(node: &str) -> String {
    format!("nodes/{node}/not_alive")
}

/// The QoS series a layout shows (exact paths, `/`-rooted), topics in order then nodes:
/// when the run is over, every QoS series that was logged (`extents` holds every scalar
/// series); at the start, the counters the topics' QoS enables and the not-alive count of
/// every node with a lease. Empty for the chapter's QoS (the layout then has no QoS view).
pub(super) fn qos_series(shape: &GraphShape, extents: Option<&Extents>) -> Vec<String> {
    let mut out = Vec::new();
    for t in &shape.topics {
        for c in QosCounter::ALL {
            let e = qos_entity(t, c);
            let shown = match extents {
                Some(ext) => ext.contains_key(&e),
                None => c.enabled_by(&t.qos),
            };
            if shown {
                out.push(format!("/{e}"));
            }
        }
    }
    out
}

/// The liveliness series a layout shows (`nodes/<name>/not_alive`, `/`-rooted): when the
/// run is over, every one that was logged; at the start, every node with a lease. A plot of
/// their own, so that a count of 1 is not a flat line under counters of hundreds.
pub(super) fn liveliness_series(shape: &GraphShape, extents: Option<&Extents>) -> Vec<String> {
    shape
        .nodes
        .iter()
        .map(|n| not_alive_entity(&n.name))
        .zip(&shape.nodes)
        .filter(|(e, n)| match extents {
            Some(ext) => ext.contains_key(e),
            None => n.lease().is_some(),
        })
        .map(|(e, _)| format!("/{e}"))
        .collect()
}

/// A large graph's bus lines ([`super::groups::bus_lines`]: a topic's own, or a topic
/// group's aggregates') with their layered widths: only these coincide in a plot.
fn bus_line_widths(groups: &super::groups::Groups, entities: &[String]) -> BTreeMap<String, f32> {
    let lines = super::groups::bus_lines(groups, entities);
    let widths = layered_widths(&lines);
    lines.into_iter().zip(widths).collect()
}

/// A large graph's topic groups drawn by their aggregates: each measure's median in the
/// group's colour (named `/c_*/pos ×249 median`, layered with the topics drawn each by its
/// own), its smallest and largest dimmer and thin, under one name (`… min, max`), so the
/// legend has a row for each; and the `groups` document ([`super::groups::document`]).
fn group_styles(
    buf: &mut ChunkBuffer,
    shape: &GraphShape,
    groups: &super::groups::Groups,
    entities: &[String],
) {
    let widths = bus_line_widths(groups, entities);
    for g in groups.topics.iter().filter(|g| g.aggregated()) {
        let hue = topic_color(&g.label);
        let median = widths
            .get(&format!("bus_groups/{}", g.key))
            .copied()
            .unwrap_or(2.0);
        let n = g.members.len();
        for measure in super::groups::MEASURES {
            for stat in super::groups::STATS {
                let (name, color, width) = match stat {
                    "median" => (format!("{} ×{n} median", g.label), hue, median),
                    _ => (format!("{} ×{n} min, max", g.label), dimmed(hue), 1.5),
                };
                buf.style(
                    &super::groups::aggregate_entity(g, measure, stat),
                    &name,
                    &rerun::SeriesLines::new()
                        .with_names([name.as_str()])
                        .with_colors([color])
                        .with_widths([width]),
                );
            }
        }
    }
    buf.add(
        super::groups::DOC_ENTITY,
        &TimePoint::default(),
        &rerun::TextDocument::from_markdown(super::groups::document(shape, groups)),
    );
}

pub(super) fn rgb((r, g, b): (u8, u8, u8)) -> Color {
    Color::from_rgb(r, g, b)
}

impl Recording {
    /// Per-series names and colours, the node graph's first drawing and the reference lines
    /// at the start, for a graph of `shape`.
    pub(super) fn log_styles(&self, shape: &GraphShape) {
        let lines = |name: &str, color: (u8, u8, u8), width: f32| {
            rerun::SeriesLines::new()
                .with_names([name])
                .with_colors([rgb(color)])
                .with_widths([width])
        };
        let step = rerun::components::InterpolationMode::StepAfter;
        let mut buf = self.lock();
        let angle = "pole angle";
        buf.style(
            "plant/pole_angle_rad",
            angle,
            &lines(angle, ANGLE_COLOR, ANGLE_WIDTH),
        );
        // Both sides of a limit share one name, so the legend shows it once.
        let limits = format!("fall limits ±{THETA_LIMIT_RAD} rad");
        for side in ["upper", "lower"] {
            let entity = format!("plant/fall_limit/{side}");
            buf.style(&entity, &limits, &lines(&limits, LIMIT_COLOR, 1.5));
        }
        buf.style("plant/cart_pos_m", "cart", &lines("cart", ANGLE_COLOR, 2.0));
        let (rail, run) = (
            format!("rail ends ±{RAIL_HALF_LENGTH_M} m"),
            format!("run ends ±{CART_LIMIT_M} m"),
        );
        for side in ["right", "left"] {
            let entity = format!("plant/rail_end/{side}");
            buf.style(&entity, &rail, &lines(&rail, NEUTRAL_COLOR, 1.5));
            let entity = format!("plant/cart_limit/{side}");
            buf.style(&entity, &run, &lines(&run, LIMIT_COLOR, 1.5));
        }
        let published = "published (policy)";
        buf.style(
            "action/published_N",
            published,
            &rerun::SeriesPoints::new()
                .with_names([published])
                .with_colors([rgb(ANGLE_COLOR)])
                .with_markers([rerun::components::MarkerShape::Circle])
                .with_marker_sizes([2.5]),
        );
        // Wider than the published points drawn over it (where the actuator applies what
        // was just published, both show).
        let applied = "applied (actuator, held)";
        buf.style(
            "action/applied_N",
            applied,
            &lines(applied, FORCE_COLOR, 5.0).with_interpolation_mode(step),
        );
        // A latency holds from one actuator step to the next: steps, not slopes.
        buf.style(
            "latency/sense_to_act_ms",
            "latency",
            &lines("latency", ANGLE_COLOR, 2.0).with_interpolation_mode(step),
        );
        let period = format!("{} period", shape.controller.clone().unwrap_or_default());
        buf.style(
            "latency/control_period_ms",
            &period,
            &lines(&period, NEUTRAL_COLOR, 1.5).with_interpolation_mode(step),
        );
        // A large graph layers only the lines its bus plots draw ([`super::groups`]).
        let groups = super::groups::Groups::of(shape);
        let entities: Vec<String> = shape.topics.iter().map(|t| t.entity()).collect();
        let widths = match &groups {
            Some(groups) => {
                let lines = bus_line_widths(groups, &entities);
                entities
                    .iter()
                    .map(|e| lines.get(&format!("bus/{e}")).copied().unwrap_or(2.0))
                    .collect()
            }
            None => layered_widths(&entities),
        };
        for (topic, width) in shape.topics.iter().zip(widths) {
            for measure in ["published", "dropped", "msg_per_s"] {
                buf.style(
                    &format!("bus/{}/{measure}", topic.entity()),
                    &topic.name,
                    &rerun::SeriesLines::new()
                        .with_names([topic.name.as_str()])
                        .with_colors([topic_color(&topic.name)])
                        .with_widths([width]),
                );
            }
        }
        if self.clock == ClockKind::Real {
            // Noisy series that seldom coincide: one width (layered, the spikes hid all).
            for node in &shape.nodes {
                buf.style(
                    &format!("nodes/{}/lateness_ms", node.name),
                    &node.name,
                    &rerun::SeriesLines::new()
                        .with_names([node.name.as_str()])
                        .with_colors([node_color(&node.name)])
                        .with_widths([1.5]),
                );
            }
        }
        if measures_executors(&self.cfg) {
            // A node's executor series in its colour, named by it; steps, as they hold.
            // Skipped-tick totals of two nodes often coincide (one thread held both): each
            // narrower than the one drawn before it, so both colours show.
            let names: Vec<String> = shape.nodes.iter().map(|n| n.name.clone()).collect();
            for (node, layered) in shape.nodes.iter().zip(layered_widths(&names)) {
                for (series, width) in [
                    ("executor_lane", 2.0),
                    ("response_ms", 1.5),
                    ("skipped_ticks", layered),
                ] {
                    buf.style(
                        &format!("nodes/{}/{series}", node.name),
                        &node.name,
                        &rerun::SeriesLines::new()
                            .with_names([node.name.as_str()])
                            .with_colors([node_color(&node.name)])
                            .with_widths([width])
                            .with_interpolation_mode(step),
                    );
                }
            }
        }
        if let Some(groups) = &groups {
            group_styles(&mut buf, shape, groups, &entities);
        }
        buf.send(&self.rec);
        reference_lines(&mut buf, Nanos::ZERO, 0);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The least "redmean" distance between two of the shipped topics' and the QoS counters'
    /// colours (module docs).
    const MIN_DISTANCE: f64 = 100.0;
    /// The least distance between a topic's colour and a node's (the node graph draws both,
    /// and names each).
    const MIN_TOPIC_NODE_DISTANCE: f64 = 75.0;
    /// The least luma of a series' colour: readable on the viewer's dark background.
    const MIN_LUMA: f64 = 90.0;
    /// The least difference in luma between two series drawn one over the other.
    const MIN_LUMA_APART: f64 = 50.0;

    /// The "redmean" distance between two colours: √((2 + r̄/256)·ΔR² + 4·ΔG² + (2 + (255 −
    /// r̄)/256)·ΔB²), r̄ the mean of their reds.
    fn distance(a: (u8, u8, u8), b: (u8, u8, u8)) -> f64 {
        let (r, g, b2) = (
            f64::from(a.0) - f64::from(b.0),
            f64::from(a.1) - f64::from(b.1),
            f64::from(a.2) - f64::from(b.2),
        );
        let mean_r = (f64::from(a.0) + f64::from(b.0)) / 2.0;
        ((2.0 + mean_r / 256.0) * r * r + 4.0 * g * g + (2.0 + (255.0 - mean_r) / 256.0) * b2 * b2)
            .sqrt()
    }

    /// Luma (Rec. 709 weights on the 0–255 values).
    fn luma(c: (u8, u8, u8)) -> f64 {
        0.2126 * f64::from(c.0) + 0.7152 * f64::from(c.1) + 0.0722 * f64::from(c.2)
    }

    fn rgb_of(c: Color) -> (u8, u8, u8) {
        let [r, g, b, _] = c.to_array();
        (r, g, b)
    }

    /// Every shipped topic's colour and every QoS counter's, named.
    fn series_colors() -> Vec<(String, (u8, u8, u8))> {
        let topics = FIXED_TOPICS
            .iter()
            .map(|t| (t.to_string(), rgb_of(topic_color(t))));
        let counters = QosCounter::ALL
            .iter()
            .zip(QOS_COLORS)
            .map(|(c, rgb)| (counter_words(*c), rgb));
        topics.chain(counters).collect()
    }

    #[test]
    fn topics_and_qos_counters_have_colours_of_their_own_far_apart() {
        let all = series_colors();
        assert_eq!(all.len(), 12);
        for (i, (a, ca)) in all.iter().enumerate() {
            assert!(luma(*ca) >= MIN_LUMA, "{a} {ca:?} is too dark to read");
            for (b, cb) in &all[i + 1..] {
                let d = distance(*ca, *cb);
                assert!(d >= MIN_DISTANCE, "{a} {ca:?} and {b} {cb:?}: {d:.0} apart");
            }
        }
        // A counter never wears a topic's colour, whatever the topic's name hashes to.
        for rgb in QOS_COLORS {
            assert!(!PALETTE.contains(&rgb), "{rgb:?}");
        }
    }

    #[test]
    fn a_topic_stands_apart_from_every_node_in_the_node_graph() {
        for t in FIXED_TOPICS {
            for n in NODE_PALETTE {
                let d = distance(rgb_of(topic_color(t)), n);
                assert!(d >= MIN_TOPIC_NODE_DISTANCE, "{t} and node {n:?}: {d:.0}");
            }
        }
    }

    #[test]
    fn series_drawn_one_over_the_other_differ_in_lightness_too() {
        // The chapter's two topics coincide in every bus plot (both at 50 msg/s): the
        // one drawn over the other is told apart by its lightness, not by its hue alone.
        let (obs, action) = (rgb_of(topic_color("/obs")), rgb_of(topic_color("/action")));
        assert!((luma(obs) - luma(action)).abs() >= MIN_LUMA_APART);
        assert!(distance(obs, action) >= MIN_DISTANCE);
        // The estimate, drawn under the pole angle: wider, and lighter than its blue.
        assert!((luma(ESTIMATE_COLOR) - luma(ANGLE_COLOR)).abs() >= MIN_LUMA_APART);
        assert!(distance(ESTIMATE_COLOR, ANGLE_COLOR) >= MIN_DISTANCE);
        // Drawn first (the viewer draws a plot's series in entity-path order), under the
        // angle: wider (tests/it/recording.rs reads the widths logged).
        let (estimate, angle) = (
            rerun::EntityPath::from("plant/pole_angle_estimate_rad"),
            rerun::EntityPath::from("plant/pole_angle_rad"),
        );
        assert!(estimate < angle);
    }

    #[test]
    fn layered_widths_are_capped_and_the_shipped_graphs_keep_theirs() {
        let names = |n: usize| (0..n).map(|i| format!("t{i:04}")).collect::<Vec<_>>();
        // Five topics (the most a shipped graph has): 3 px apart, as they always were.
        assert_eq!(layered_widths(&names(5)), [14.0, 11.0, 8.0, 5.0, 2.0]);
        assert_eq!(layered_widths(&names(2)), [5.0, 2.0]);
        // 99 topics drew the first at 296 px: now every line within the cap, each still
        // narrower than the one drawn before it.
        for n in [6, 99, 999] {
            let w = layered_widths(&names(n));
            assert!(
                w.iter()
                    .all(|x| (2.0..=MAX_LAYERED_WIDTH_PX + 1e-3).contains(x)),
                "{n}: {w:?}"
            );
            assert!(w.windows(2).all(|p| p[0] > p[1]), "{n}");
            assert!((w[0] - MAX_LAYERED_WIDTH_PX).abs() < 1e-3, "{n}: {}", w[0]);
        }
    }

    #[test]
    fn the_distance_is_the_redmean_one() {
        assert_eq!(distance((0, 0, 0), (0, 0, 0)), 0.0);
        // Pure green weighs most: 4·255² under the root.
        assert_eq!(distance((0, 0, 0), (0, 255, 0)), 510.0);
        assert!((distance((0, 0, 0), (255, 255, 255)) - 764.83).abs() < 0.01);
    }
}
