//! The recording's blueprint: the views a recording opens with and what each shows, laid
//! out as a learner reads a run ([`layout_for`]: the cartpole, the node graph and the
//! summary; the pole angle, the action, the cart position, the latency; the bus counters,
//! QoS, executors and processes where the run has them; the events and the text logs), each
//! plot's axis and legend placed so it reads at the viewer's usual sizes. Written with
//! [`super::layout`]'s archetypes.

use super::*;

/// The top of a y range from 0 that gets a label above 0 in the stock viewer: its grid
/// labels steps of a power of ten at least about 16 px apart, which a plot of the 1600×900
/// layout (about 110 px, the range padded by a tenth either side) gives up to about 5.5 of,
/// so a top over 5.5 × 10^k (a latency of 80 ms: eight steps of 10, too dense, and no step
/// of 100 under it) shows "0" alone. Such a top is raised to 10^(k+1) (100: "0" and "100");
/// a lower one stays (msg/s at 52: "0" to "50"; 300: "0" to "300"). Measured in the
/// viewer's pictures: 5.2 steps labelled, 6.96 steps of a symmetric range not.
pub(super) fn label_top(hi: f64) -> f64 {
    if !(hi.is_finite() && hi > 0.0) {
        return hi;
    }
    let step = 10f64.powf(hi.log10().floor());
    if hi / step > 5.5 {
        step * 10.0
    } else {
        hi
    }
}

/// A y range with a margin around `[lo, hi]`, so no line sits on the plot's edge.
pub(super) fn axis(lo: f64, hi: f64) -> bp::ScalarAxis {
    let pad = if hi > lo { (hi - lo) * 0.1 } else { 1.0 };
    bp::ScalarAxis::new().with_range(rerun::components::Range1D::new(lo - pad, hi + pad))
}

/// A legend in `corner` (in place of [`plot`]'s top right).
pub(super) fn legend_at(view: ViewSpec, corner: bpc::Corner2D) -> ViewSpec {
    view.property("PlotLegend", &bp::PlotLegend::new().with_corner(corner))
}

/// Totals (counters that only grow, from 0 at the start) rise from bottom left to top
/// right: their legend sits top left, where they never are.
pub(super) fn totals(view: ViewSpec) -> ViewSpec {
    legend_at(view, bpc::Corner2D::LeftTop)
}

/// A time series view of the series `entities` (exact paths), its legend top right. Its y
/// range spans `base` (a scale chosen up front) and, when the run is over, every value the
/// series took (`extents`); with neither, rerun fits the data itself.
pub(super) fn plot(
    key: &str,
    name: &str,
    entities: Vec<String>,
    base: Option<(f64, f64)>,
    extents: Option<&Extents>,
) -> ViewSpec {
    let seen = extents.map(|ext| {
        entities
            .iter()
            .filter_map(|e| ext.get(e.trim_start_matches('/')))
            .fold(None, |acc: Option<(f64, f64)>, &(lo, hi)| {
                Some(acc.map_or((lo, hi), |(a, b)| (a.min(lo), b.max(hi))))
            })
    });
    let range = match (base, seen.flatten()) {
        (Some((a, b)), Some((lo, hi))) => Some((a.min(lo), b.max(hi))),
        (Some(r), None) | (None, Some(r)) => Some(r),
        (None, None) => None,
    }
    // Only a range fitted to the data from 0 (a latency, a count): a scale chosen up front
    // (an executor's lanes, a liveliness count) stays as chosen.
    .map(|(lo, hi)| {
        if base == Some((0.0, 0.0)) && lo >= 0.0 {
            (lo, label_top(hi))
        } else {
            (lo, hi)
        }
    });
    // The legend sits top right (the start and change markers are on the left; other
    // corners: `legend_at`); the time axes are linked: zoom or pan one plot and every plot
    // follows.
    let view = ViewSpec::new(key, "TimeSeries", name)
        .contents(entities)
        .property(
            "PlotLegend",
            &bp::PlotLegend::new().with_corner(bpc::Corner2D::RightTop),
        )
        .property(
            "TimeAxis",
            &bp::TimeAxis::new().with_link(bpc::LinkAxis::LinkToGlobal),
        );
    match range {
        Some((lo, hi)) => view.property("ScalarAxis", &axis(lo, hi)),
        None => view,
    }
}

/// The viewer layout for a run of `shape` with the settings `cfg`; `extents` (the values
/// every series took) once the run is over.
pub(super) fn layout_for(shape: &GraphShape, cfg: &RunConfig, extents: Option<&Extents>) -> Item {
    let paths = |list: &[&str]| list.iter().map(|p| p.to_string()).collect::<Vec<_>>();
    let deg = THETA_LIMIT_RAD.to_degrees();
    let angle = plot(
        "angle",
        &format!("pole angle θ (rad), fall limits ±{deg:.0}°"),
        {
            let mut p = paths(&[
                "/plant/pole_angle_rad",
                "/plant/fall_limit/upper",
                "/plant/fall_limit/lower",
                "/plant/changes",
            ]);
            // The fall's marker, in the final layout of a run that fell.
            if extents.is_some_and(|e| e.contains_key("plant/fall")) {
                p.push("/plant/fall".to_string());
            }
            p
        },
        Some((-CHANGE_MARK_RAD, CHANGE_MARK_RAD)),
        extents,
    );
    let force = FORCE_PER_CONTROL_N;
    let action = plot(
        "action",
        "force on the cart (N): published vs applied",
        paths(&["/action/published_N", "/action/applied_N"]),
        Some((-force, force)),
        extents,
    );
    // The middle column's plots: these four, the executors' three, the real clock's
    // lateness, the liveliness totals.
    let alive = liveliness_series(shape, extents);
    let column = 4
        + if measures_executors(cfg) { 3 } else { 0 }
        + usize::from(cfg.clock == ClockKind::Real)
        + usize::from(!alive.is_empty());
    // With four, the rails' ends and the run's; in a shorter plot the rails' ends padded
    // (6.96 m) are too many metres for the viewer to label one (it showed "0" alone): the
    // run's ends alone, within ±2.5 m, get "-2" to "2" (a cart past them, at the run's end,
    // widens the range).
    let tall = column <= 4;
    let cart = cart_view(tall, extents);
    // Latency, lateness and the bus series have no scale known up front (a lab session may
    // change rates mid-run): rerun fits them while the run goes, the final layout pads them.
    let latency = plot(
        "latency",
        "sense→act latency (ms)",
        paths(&["/latency/sense_to_act_ms", "/latency/control_period_ms"]),
        extents.map(|_| (0.0, 0.0)),
        extents,
    );
    let mut signals: Vec<(f32, Item)> = [angle, action, cart, latency]
        .into_iter()
        .map(|v| (1.0, Item::View(v)))
        .collect();
    if measures_executors(cfg) {
        let [timeline, response, skipped] = executor_views(shape, extents);
        for v in [timeline, response, skipped] {
            signals.push((1.0, Item::View(v)));
        }
    }
    if cfg.clock == ClockKind::Real {
        let lateness = plot(
            "lateness",
            "node tick lateness (µs, real clock)",
            shape
                .nodes
                .iter()
                .map(|n| format!("/nodes/{}/lateness_us", n.name))
                .collect(),
            extents.map(|_| (0.0, 0.0)),
            extents,
        );
        signals.push((1.0, Item::View(lateness)));
    }
    let wire = wire_view(shape, extents);
    let [published, msg_per_s, dropped] = bus_views(shape, extents);
    // QoS counters only where a topic's QoS can make them count (or they did): the
    // chapter's graph has no such view.
    let qos = qos_series(shape, extents);
    let qos = (!qos.is_empty()).then(|| {
        totals(plot(
            "bus-qos",
            "QoS: counters (total)",
            qos,
            extents.map(|_| (0.0, 0.0)),
            extents,
        ))
    });
    let alive = (!alive.is_empty()).then(|| {
        totals(plot(
            "liveliness",
            "liveliness: times a node went not alive (total)",
            alive,
            // Room above a single loss, under the legend top left.
            extents.map(|_| (0.0, 2.0)),
            extents,
        ))
    });
    // A node's liveliness sits with the node's other plots (the middle column).
    if let Some(v) = alive {
        signals.push((1.0, Item::View(v)));
    }
    let events = ViewSpec::new("events", "TextLog", "events")
        .contents(["/events"])
        .property("TextLogColumns", &text_log_columns(cfg.clock, false));
    // What the nodes' code wrote (`log/<node>`), when it wrote anything: the final layout
    // knows (a run whose nodes wrote nothing, as the chapter's, has no such view). The
    // entity column names the node.
    let log = extents.filter(|e| e.contains_key(LOG_MARK)).map(|_| {
        ViewSpec::new("log", "TextLog", "log: what the nodes' code wrote")
            .contents(["/log/**"])
            .property("TextLogColumns", &text_log_columns(cfg.clock, true))
    });
    let (world, graph) = (world_view(), graph_view(shape));
    let summary = ViewSpec::new("summary", "TextDocument", "summary").contents(["/summary"]);

    Item::Horizontal(vec![
        (
            0.36,
            Item::Vertical(vec![
                (0.42, Item::View(world)),
                (0.2, Item::View(graph)),
                (0.38, Item::View(summary)),
            ]),
        ),
        (0.34, Item::Vertical(signals)),
        (
            0.30,
            Item::Vertical(
                [
                    Some(published),
                    Some(dropped),
                    qos,
                    Some(msg_per_s),
                    wire,
                    Some(events),
                    log,
                ]
                .into_iter()
                .flatten()
                .map(|v| (1.0, Item::View(v)))
                .collect(),
            ),
        ),
    ])
}

/// The bus's views: each topic's messages published (total), its msg/s over a 1 s window
/// (legend bottom right: rates run along the top once they settle) and its drops (total).
fn bus_views(shape: &GraphShape, extents: Option<&Extents>) -> [ViewSpec; 3] {
    let bus = |measure: &str, title: &str| {
        plot(
            &format!("bus-{measure}"),
            title,
            shape
                .topics
                .iter()
                .map(|t| format!("/bus/{}/{measure}", t.entity()))
                .collect(),
            extents.map(|_| (0.0, 0.0)),
            extents,
        )
    };
    let published = totals(bus("published", "bus: published (total)"));
    // Rates run along the top once they settle: their legend bottom right.
    let msg_per_s = legend_at(
        bus("msg_per_s", "bus: msg/s (1 s window)"),
        bpc::Corner2D::RightBottom,
    );
    let dropped = totals(bus("dropped", "bus: dropped (total)"));
    [published, msg_per_s, dropped]
}

/// The cart's position against the rail's ends and the run's. `tall`: in a column of four
/// plots, the rails' ends too; in a shorter plot the rails' ends padded (6.96 m) are too
/// many metres for the viewer to label one (it showed "0" alone): the run's ends alone,
/// within ±2.5 m, get "-2" to "2" (a cart past them, at the run's end, widens the range).
fn cart_view(tall: bool, extents: Option<&Extents>) -> ViewSpec {
    let paths = |list: &[&str]| list.iter().map(|p| p.to_string()).collect::<Vec<_>>();
    let mut cart_paths = vec!["/plant/cart_pos_m"];
    if tall {
        cart_paths.extend(["/plant/rail_end/right", "/plant/rail_end/left"]);
    }
    cart_paths.extend(["/plant/cart_limit/right", "/plant/cart_limit/left"]);
    let cart = plot(
        "cart",
        "cart position (m)",
        paths(&cart_paths),
        Some((-RAIL_HALF_LENGTH_M, RAIL_HALF_LENGTH_M)),
        extents,
    );
    if tall {
        cart
    } else {
        let reach = extents
            .and_then(|e| e.get("plant/cart_pos_m"))
            .map_or(0.0, |&(lo, hi)| lo.abs().max(hi.abs()));
        let half = (CART_LIMIT_M + 0.1).max(reach * 1.05);
        cart.property(
            "ScalarAxis",
            &bp::ScalarAxis::new().with_range(rerun::components::Range1D::new(-half, half)),
        )
    }
}

/// The executors' views: a lane per node raised while its tick holds a thread, each
/// tick's response time, and the ticks its timer skipped.
fn executor_views(shape: &GraphShape, extents: Option<&Extents>) -> [ViewSpec; 3] {
    let lanes = shape.nodes.len().max(1) as f64;
    let each = |series: &str| -> Vec<String> {
        shape
            .nodes
            .iter()
            .map(|n| format!("/nodes/{}/{series}", n.name))
            .collect()
    };
    let timeline = plot(
        "executor-timeline",
        "executor timeline: a lane per node (by rank), raised while its tick holds a thread",
        each("executor_lane"),
        Some((0.0, lanes - 1.0 + LANE_BUSY)),
        extents,
    );
    let response = plot(
        "response",
        "response time (ms): a tick's release → its outputs published",
        each("response_ms"),
        extents.map(|_| (0.0, 0.0)),
        extents,
    );
    let skipped = totals(plot(
        "skipped",
        "skipped ticks (total): periods a node's timer let pass, its thread held",
        each("skipped_ticks"),
        extents.map(|_| (0.0, 1.0)),
        extents,
    ));
    [timeline, response, skipped]
}

/// Across processes: each crossing topic's time on the wire (what its subscriber's process
/// measured), where there is any. With the bus's views (the right column), so that neither
/// column gets too many plots to label their axes.
fn wire_view(shape: &GraphShape, extents: Option<&Extents>) -> Option<ViewSpec> {
    let wire: Vec<String> = crossing_topics(shape)
        .flat_map(|t| ["p50", "p99"].map(|stat| format!("/bus/{}/wire_{stat}_us", t.entity())))
        .filter(|q| extents.is_none_or(|e| e.contains_key(&q[1..])))
        .collect();
    (!wire.is_empty()).then(|| {
        plot(
            "wire",
            "over the wire (µs): each crossing topic's p50, p99 so far",
            wire,
            extents.map(|_| (0.0, 0.0)),
            extents,
        )
    })
}

/// The cart-pole in 3D, seen from the front and above, on the ground's grid.
fn world_view() -> ViewSpec {
    ViewSpec::new("cartpole", "3D", "cartpole")
        .origin("/world")
        .property(
            "EyeControls3D",
            &bp::EyeControls3D::new()
                .with_kind(bpc::Eye3DKind::Orbital)
                .with_position([0.0, -2.1, 1.1])
                .with_look_target([0.0, 0.0, 0.35])
                .with_eye_up([0.0, 0.0, 1.0]),
        )
        .property(
            "LineGrid3D",
            &bp::LineGrid3D::new()
                .with_plane(rerun::components::Plane3D::new(
                    [0.0, 0.0, 1.0],
                    GROUND_Z_M as f32,
                ))
                .with_spacing(0.25),
        )
}

/// The node graph at the positions the recording gives it (no forces: it stays as laid
/// out), nodes blue and topics amber.
fn graph_view(shape: &GraphShape) -> ViewSpec {
    let (_, bounds) = graph_positions(shape);
    ViewSpec::new("graph", "Graph", "node graph: nodes blue, topics amber")
        .origin("/graph")
        .property("VisualBounds2D", &bp::VisualBounds2D::new(bounds))
        .property("ForceLink", &bp::ForceLink::new().with_enabled(false))
        .property(
            "ForceManyBody",
            &bp::ForceManyBody::new().with_enabled(false),
        )
        .property(
            "ForcePosition",
            &bp::ForcePosition::new().with_enabled(false),
        )
        .property(
            "ForceCollisionRadius",
            &bp::ForceCollisionRadius::new().with_enabled(false),
        )
        .property("ForceCenter", &bp::ForceCenter::new().with_enabled(false))
}

/// A text log view's columns: the run's timeline, then (when `entity` is shown) the entity,
/// the level and the text.
pub(super) fn text_log_columns(clock: ClockKind, entity: bool) -> bp::TextLogColumns {
    let column = |visible: bool, kind| bpd::TextLogColumn {
        visible: visible.into(),
        kind,
    };
    bp::TextLogColumns::new()
        .with_timeline_columns([bpd::TimelineColumn {
            visible: true.into(),
            timeline: timeline_name(clock).into(),
        }])
        .with_text_log_columns([
            column(entity, bpd::TextLogColumnKind::EntityPath),
            column(true, bpd::TextLogColumnKind::LogLevel),
            column(true, bpd::TextLogColumnKind::Body),
        ])
}
