//! The recording's blueprint: the views a recording opens with and what each shows, laid
//! out as a learner reads a run ([`layout_for`]: the cartpole, the node graph and the
//! summary; the pole angle, the action, the cart position, the latency; the bus counters,
//! QoS, executors and processes where the run has them; the events and the text logs), each
//! plot's axis and legend placed so it reads at the viewer's usual sizes. Written with
//! [`super::layout`]'s archetypes.

use super::*;

/// The top of a y range from 0 that gets a label above 0 in the stock viewer: its grid
/// labels steps of a power of ten only when they are at least about 18 points apart. The
/// smallest plot of the layout is about 100 points tall at 1280×720 (its range padded by a
/// tenth either side), which labels up to about 5.2 steps: a top over 4.4 × 10^k (a
/// latency of 50 ms, padded to six steps of 10: "0" alone) is raised to 10^(k+1) (100: "0"
/// and "100"); a lower one stays (43 messages: "0" to "40"; 300: "0" to "300"). Measured in
/// the viewer's pictures at 1280×720: 5.16 steps in 95 points labelled, 6 in 100 not.
pub(super) fn label_top(hi: f64) -> f64 {
    if !(hi.is_finite() && hi > 0.0) {
        return hi;
    }
    let step = 10f64.powf(hi.log10().floor());
    if hi / step > 4.4 {
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
    // Only a range from 0 (a latency, a count, the executors' lanes): a range about 0
    // (the pole angle, the force) is labelled by its own steps.
    .map(|(lo, hi)| {
        if base.is_some_and(|(from, _)| from == 0.0) && lo >= 0.0 {
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

/// The share of the middle column's height the pole-angle plot takes beside the latency's
/// (1): room for its legend, which names the marks' times. The force (0.9) needs least: its
/// ±12 N range labels in any plot.
const ANGLE_SHARE: f32 = 1.3;
/// The cart's share: tall enough (about 140 points at 1280×720) that the six steps of 1 m
/// between the rail's ends (±3.0 m) get their labels.
const CART_SHARE: f32 = 1.3;

/// The viewer layout for a run of `shape` with the settings `cfg`; `extents` (the values
/// every series took) once the run is over.
///
/// Three columns, each plot tall enough to label its axes at 1280×720:
/// - the cartpole, the node graph and the summary;
/// - the chapter's core, always four plots: the pole angle (with the events' marks), the
///   force, the cart (with the rail's ends) and the sense→act latency;
/// - `when` (every event at its run time, the first trouble on top) over tabs, one per
///   concern the run has: the bus, QoS and liveliness, executors, the real clock's
///   lateness, processes, the events' log and what the nodes' code wrote. The tab of the
///   run's own concern is open (executors, else QoS, else processes, else the bus).
pub(super) fn layout_for(shape: &GraphShape, cfg: &RunConfig, extents: Option<&Extents>) -> Item {
    let core = Item::Vertical(
        [
            (ANGLE_SHARE, angle_view(extents)),
            (0.9, action_view(extents)),
            (CART_SHARE, cart_view(extents)),
            (1.0, latency_view(extents)),
        ]
        .into_iter()
        .map(|(share, v)| (share, Item::View(v)))
        .collect(),
    );
    let column = |views: Vec<ViewSpec>| {
        Item::Vertical(views.into_iter().map(|v| (1.0, Item::View(v))).collect())
    };
    let mut tabs: Vec<(String, Item)> = Vec::new();
    let [published, msg_per_s, dropped] = bus_views(shape, extents);
    tabs.push(("bus".into(), column(vec![published, dropped, msg_per_s])));
    // QoS counters only where a topic's QoS can make them count (or they did), and the
    // leased nodes' liveliness: the chapter's graph has neither.
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
    let alive = liveliness_series(shape, extents);
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
    let qos: Vec<ViewSpec> = qos.into_iter().chain(alive).collect();
    let qos_tab = (!qos.is_empty()).then(|| {
        tabs.push(("QoS, liveliness".into(), column(qos)));
        tabs.len() - 1
    });
    let executors_tab = measures_executors(cfg).then(|| {
        tabs.push((
            "executors".into(),
            column(executor_views(shape, extents).into()),
        ));
        tabs.len() - 1
    });
    if cfg.clock == ClockKind::Real {
        let lateness = plot(
            "lateness",
            "node tick lateness (ms, real clock)",
            shape
                .nodes
                .iter()
                .map(|n| format!("/nodes/{}/lateness_ms", n.name))
                .collect(),
            extents.map(|_| (0.0, 0.0)),
            extents,
        );
        tabs.push(("real clock".into(), column(vec![lateness])));
    }
    let processes_tab = wire_view(shape, extents).map(|wire| {
        tabs.push(("processes".into(), column(vec![wire])));
        tabs.len() - 1
    });
    let events = ViewSpec::new("events", "TextLog", "events")
        .contents(["/events"])
        .property("TextLogColumns", &text_log_columns(cfg.clock, false));
    tabs.push(("events".into(), Item::View(events)));
    // What the nodes' code wrote (`log/<node>`), when it wrote anything: the final layout
    // knows (a run whose nodes wrote nothing, as the chapter's, has no such view). The
    // entity column names the node.
    if extents.is_some_and(|e| e.contains_key(LOG_MARK)) {
        let log = ViewSpec::new("log", "TextLog", "log: what the nodes' code wrote")
            .contents(["/log/**"])
            .property("TextLogColumns", &text_log_columns(cfg.clock, true));
        tabs.push(("log".into(), Item::View(log)));
    }
    let open = executors_tab.or(qos_tab).or(processes_tab).unwrap_or(0);
    let when =
        ViewSpec::new("when", "TextDocument", "when: the run's events in time").contents(["/when"]);
    let (world, graph) = (world_view(), graph_view(shape));
    let summary = ViewSpec::new("summary", "TextDocument", "summary").contents(["/summary"]);

    Item::Horizontal(vec![
        (
            0.30,
            Item::Vertical(vec![
                (0.38, Item::View(world)),
                (0.24, Item::View(graph)),
                (0.38, Item::View(summary)),
            ]),
        ),
        (0.38, core),
        (
            0.32,
            Item::Vertical(vec![(0.3, Item::View(when)), (0.7, Item::Tabs(tabs, open))]),
        ),
    ])
}

/// The pole angle against its fall limits, with the events' marks (changes above the
/// limits, trouble and recoveries below, the fall at the pole's angle): at the start every
/// mark (a live viewer shows them as they come), at the end those the run set.
fn angle_view(extents: Option<&Extents>) -> ViewSpec {
    let deg = THETA_LIMIT_RAD.to_degrees();
    let mut p: Vec<String> = [
        "/plant/pole_angle_rad",
        "/plant/fall_limit/upper",
        "/plant/fall_limit/lower",
    ]
    .iter()
    .map(|p| p.to_string())
    .collect();
    // An estimator's estimate, where the run has one.
    p.extend(recorded(&["/plant/pole_angle_estimate_rad"], extents));
    let marks: Vec<String> = Mark::ALL
        .iter()
        .map(|m| format!("/{}", m.entity()))
        .collect();
    p.extend(recorded(
        &marks.iter().map(String::as_str).collect::<Vec<_>>(),
        extents,
    ));
    // The legend top left: the marks run along the bottom, a fall ends the line at the
    // right, and the pole starts near 0.
    legend_at(
        plot(
            "angle",
            &format!("pole angle θ (rad), fall limits ±{deg:.0}°, events marked"),
            p,
            Some((-CHANGE_MARK_RAD, CHANGE_MARK_RAD)),
            extents,
        ),
        bpc::Corner2D::LeftTop,
    )
}

/// Of `paths`, those the run recorded (every one at the start, when nothing is known yet):
/// a graph without the chapter's policy publishes no `/action` of its own, one without a
/// controller has no control period.
fn recorded(paths: &[&str], extents: Option<&Extents>) -> Vec<String> {
    paths
        .iter()
        .filter(|p| extents.is_none_or(|e| e.contains_key(p.trim_start_matches('/'))))
        .map(|p| p.to_string())
        .collect()
}

/// The force the policy published against the force the actuator applied.
fn action_view(extents: Option<&Extents>) -> ViewSpec {
    let force = FORCE_PER_CONTROL_N;
    plot(
        "action",
        "force on the cart (N): published vs applied",
        recorded(&["/action/published_N", "/action/applied_N"], extents),
        Some((-force, force)),
        extents,
    )
}

/// The sense→act latency against the controller's period. No scale is known up front (a
/// lab session may change rates mid-run): rerun fits it while the run goes, the final layout
/// pads it.
fn latency_view(extents: Option<&Extents>) -> ViewSpec {
    plot(
        "latency",
        "sense→act latency (ms)",
        recorded(
            &["/latency/sense_to_act_ms", "/latency/control_period_ms"],
            extents,
        ),
        extents.map(|_| (0.0, 0.0)),
        extents,
    )
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
    // A drop is a message a full queue let go for a newer one: by design where a topic
    // of depth 1 is read slower than it is written (the freshest wins), not an alarm.
    let dropped = totals(bus(
        "dropped",
        "bus: dropped (total): older messages a full queue let go",
    ));
    [published, msg_per_s, dropped]
}

/// The cart's position against the rail's ends and the run's ends (past which a run stops),
/// on a range just past the rail's ends (a cart past them, at the run's end, widens it):
/// the usual tenth of padding made seven steps of 1 m, too many to label.
fn cart_view(extents: Option<&Extents>) -> ViewSpec {
    let reach = extents
        .and_then(|e| e.get("plant/cart_pos_m"))
        .map_or(0.0, |&(lo, hi)| lo.abs().max(hi.abs()));
    let half = (RAIL_HALF_LENGTH_M + 0.1).max(reach * 1.05);
    plot(
        "cart",
        "cart position (m)",
        [
            "/plant/cart_pos_m",
            "/plant/rail_end/right",
            "/plant/rail_end/left",
            "/plant/cart_limit/right",
            "/plant/cart_limit/left",
        ]
        .iter()
        .map(|p| p.to_string())
        .collect(),
        Some((-RAIL_HALF_LENGTH_M, RAIL_HALF_LENGTH_M)),
        extents,
    )
    .property(
        "ScalarAxis",
        &bp::ScalarAxis::new().with_range(rerun::components::Range1D::new(-half, half)),
    )
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
    // The lanes' own range, never raised to a labelled step: their numbers are ranks, the
    // legend names the nodes.
    let timeline = plot(
        "executor-timeline",
        "executor timeline: a lane per node, raised while its tick holds a thread",
        each("executor_lane"),
        None,
        None,
    )
    .property("ScalarAxis", &axis(0.0, lanes - 1.0 + LANE_BUSY));
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
/// out), each node and topic in its colour.
fn graph_view(shape: &GraphShape) -> ViewSpec {
    let (_, bounds) = graph_positions(shape);
    ViewSpec::new(
        "graph",
        "Graph",
        "node graph: node → /topic → node, coloured as in the plots",
    )
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
