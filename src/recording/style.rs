//! How a recording names and colours what it draws: one colour per topic (the same in
//! every graph) and per QoS counter, the node graph's colours, line widths that keep equal
//! series apart, and the names and entity paths of the QoS and liveliness series.

use super::*;

/// Colours for per-topic and per-node series (readable on rerun's dark background).
pub(super) const PALETTE: [(u8, u8, u8); 6] = [
    (64, 196, 220),
    (245, 150, 50),
    (190, 120, 240),
    (120, 210, 110),
    (240, 100, 150),
    (230, 210, 80),
];

pub(super) fn palette(i: usize) -> Color {
    let (r, g, b) = PALETTE[i % PALETTE.len()];
    Color::from_rgb(r, g, b)
}

/// A topic's colour, the same in every graph: the shipped graphs' topics have one each
/// (`/obs` cyan, `/action` orange, …), any other topic a palette entry chosen by its name
/// (FNV-1a), so a topic keeps its colour when the graph around it changes.
pub(super) fn topic_color(name: &str) -> Color {
    const FIXED: [&str; 6] = ["/obs", "/action", "/meas", "/state", "/cmd", "/force"];
    let i = FIXED
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

/// Line widths (px) for series that can coincide (every topic's published count, two
/// topics at one rate): the viewer draws a plot's series in entity-path order, each over
/// the last, so the first drawn is the widest and every later one narrower; two equal
/// lines then show as one inside the other, both colours visible. Returns one width per
/// name, in the order given.
pub(super) fn layered_widths(entities: &[String]) -> Vec<f32> {
    let mut sorted = entities.to_vec();
    sorted.sort_unstable();
    let n = sorted.len();
    entities
        .iter()
        .map(|e| {
            let rank = sorted.iter().position(|s| s == e).unwrap_or(0);
            2.0 + 3.0 * (n - 1 - rank) as f32
        })
        .collect()
}

pub(super) const ANGLE_COLOR: (u8, u8, u8) = (90, 160, 255);
pub(super) const LIMIT_COLOR: (u8, u8, u8) = (235, 80, 80);
/// An estimator's estimate of the pole angle (θ̂), beside the angle's own colour.
pub(super) const ESTIMATE_COLOR: (u8, u8, u8) = (220, 120, 230);
pub(super) const NEUTRAL_COLOR: (u8, u8, u8) = (150, 150, 150);
pub(super) const FORCE_COLOR: (u8, u8, u8) = (120, 220, 120);

/// One colour per QoS counter (in [`QosCounter::ALL`]'s order), and for a node's
/// not-alive count: a counter keeps its colour whichever topic it is on.
pub(super) const QOS_COLORS: [(u8, u8, u8); 6] = [
    (230, 210, 80),  // expired
    (190, 120, 240), // refused
    (64, 196, 220),  // lost
    (120, 210, 110), // retransmitted
    (245, 150, 50),  // offered deadline missed
    (235, 80, 80),   // requested deadline missed
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

pub(super) fn rgb((r, g, b): (u8, u8, u8)) -> Color {
    Color::from_rgb(r, g, b)
}
