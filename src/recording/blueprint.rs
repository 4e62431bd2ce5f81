//! The recording's blueprint: the views a recording opens with and what each shows, laid
//! out as a learner reads a run ([`layout_for`]: the cartpole, the node graph and the
//! summary; the pole angle, the action, the cart position, the latency; the bus counters,
//! QoS, executors and processes where the run has them; the events and the text logs), each
//! plot's axis and legend placed so it reads at the viewer's usual sizes. Written with
//! [`super::layout`]'s archetypes.
//!
//! Whatever the graph's size, no plot draws more than
//! [`super::groups::MAX_SERIES_PER_VIEW`] series ([`plot`]); a large graph's bus and node
//! graph are drawn by group ([`grouped_bus_tabs`], [`super::grouped`]).

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
pub(super) fn padded(lo: f64, hi: f64) -> (f64, f64) {
    let pad = if hi > lo { (hi - lo) * 0.1 } else { 1.0 };
    (lo - pad, hi + pad)
}

/// A legend in `corner` (in place of [`plot`]'s top right). The final layout may move it
/// where the plot's series are not ([`super::legend::place_legends`]).
pub(super) fn legend_at(view: ViewSpec, corner: bpc::Corner2D) -> ViewSpec {
    view.legend(corner)
}

/// Totals (counters that only grow, from 0 at the start) rise from bottom left to top
/// right: their legend sits top left, where they never are.
pub(super) fn totals(view: ViewSpec) -> ViewSpec {
    legend_at(view, bpc::Corner2D::LeftTop)
}

/// A time series view of the series `entities` (exact paths; at most
/// [`super::groups::MAX_SERIES_PER_VIEW`] of them: [`at_most_a_dozen`]), its legend top
/// right. Its y range spans `base` (a scale chosen up front) and, when the run is over,
/// every value the series took (`extents`); with neither, rerun fits the data itself.
pub(super) fn plot(
    key: &str,
    name: &str,
    entities: Vec<String>,
    base: Option<(f64, f64)>,
    extents: Option<&Extents>,
) -> ViewSpec {
    let (entities, name) = at_most_a_dozen(entities, name, extents);
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
        .legend(bpc::Corner2D::RightTop)
        .property(
            "TimeAxis",
            &bp::TimeAxis::new().with_link(bpc::LinkAxis::LinkToGlobal),
        );
    match range.map(|(lo, hi)| padded(lo, hi)) {
        Some((lo, hi)) => view.y_range(lo, hi),
        None => view,
    }
}

/// `entities` as a plot draws them, with its title: at most
/// [`super::groups::MAX_SERIES_PER_VIEW`], whatever the graph's size. Past that, those that
/// rose highest once the run is over (at the start, the first ones:
/// [`super::groups::pick`]), the title saying how many of how many; the rest are recorded
/// all the same, in the entity tree.
fn at_most_a_dozen(
    entities: Vec<String>,
    name: &str,
    extents: Option<&Extents>,
) -> (Vec<String>, String) {
    let n = entities.len();
    if n <= super::groups::MAX_SERIES_PER_VIEW {
        return (entities, name.to_string());
    }
    let largest = |i: usize| {
        let e = entities[i].trim_start_matches('/');
        extents.and_then(|x| x.get(e)).map(|&(_, hi)| hi)
    };
    let kept: Vec<String> = super::groups::pick(n, largest)
        .into_iter()
        .map(|i| entities[i].clone())
        .collect();
    let title = match extents {
        Some(_) => format!("{name} · the {} highest of {n}", kept.len()),
        None => format!("{name} · {} of {n}", kept.len()),
    };
    (kept, title)
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
    let groups = super::groups::Groups::of(shape);
    let (mut tabs, open) = concern_tabs(shape, groups.as_ref(), cfg, extents);
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
    let when =
        ViewSpec::new("when", "TextDocument", "when: the run's events in time").contents(["/when"]);
    let (world, graph) = (world_view(), graph_view(shape, groups.as_ref()));
    let summary = ViewSpec::new("summary", "TextDocument", "summary").contents(["/summary"]);
    // A large graph's node graph gets the room its boxes take to read at the chapter's
    // scale (two bands of up to four columns: `grouped`'s tests); a graph drawn node by
    // node keeps its share.
    let [world_share, graph_share, summary_share] = if groups.is_some() {
        [0.30, 0.40, 0.30]
    } else {
        [0.38, 0.24, 0.38]
    };

    Item::Horizontal(vec![
        (
            0.30,
            Item::Vertical(vec![
                (world_share, Item::View(world)),
                (graph_share, Item::View(graph)),
                (summary_share, Item::View(summary)),
            ]),
        ),
        (0.38, core),
        (
            0.32,
            Item::Vertical(vec![(0.3, Item::View(when)), (0.7, Item::Tabs(tabs, open))]),
        ),
    ])
}

/// Views stacked in a column, each an equal share.
fn column(views: Vec<ViewSpec>) -> Item {
    Item::Vertical(views.into_iter().map(|v| (1.0, Item::View(v))).collect())
}

/// The right column's tabs, one per concern the run has (the bus; QoS and liveliness;
/// executors; the real clock's lateness; processes), and the index of the one open: the
/// run's own concern's (executors, else QoS, else processes, else the bus). A large graph's
/// bus is drawn by group ([`grouped_bus_tabs`]), with its groups listed in a tab.
fn concern_tabs(
    shape: &GraphShape,
    groups: Option<&super::groups::Groups>,
    cfg: &RunConfig,
    extents: Option<&Extents>,
) -> (Vec<(String, Item)>, usize) {
    let mut tabs: Vec<(String, Item)> = match groups {
        None => {
            let [published, msg_per_s, dropped] = bus_views(shape, extents);
            vec![("bus".into(), column(vec![published, dropped, msg_per_s]))]
        }
        Some(groups) => grouped_bus_tabs(shape, groups, extents),
    };
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
    if groups.is_some() {
        let doc = ViewSpec::new(
            "groups",
            "TextDocument",
            "groups: nodes, topics, their series",
        )
        .contents([format!("/{}", super::groups::DOC_ENTITY)]);
        tabs.push(("groups".into(), Item::View(doc)));
    }
    (
        tabs,
        executors_tab.or(qos_tab).or(processes_tab).unwrap_or(0),
    )
}

/// A large graph's bus ([`super::groups`]): a tab per page of topic groups, each with the
/// three plots of the chapter's bus (published and dropped in all, msg/s), a group of a few
/// topics drawn topic by topic and a larger one by its largest, median and smallest value;
/// and once the run is over, the topics that dropped most, each by its own series, in a
/// tab of their own.
fn grouped_bus_tabs(
    shape: &GraphShape,
    groups: &super::groups::Groups,
    extents: Option<&Extents>,
) -> Vec<(String, Item)> {
    use super::groups::{aggregate_entity, bus_pages, STATS};
    let recorded = |q: &String| extents.is_none_or(|e| e.contains_key(&q[1..]));
    let pages = bus_pages(groups);
    let mut tabs = Vec::new();
    for (p, page) in pages.iter().enumerate() {
        let series = |measure: &str| -> Vec<String> {
            page.iter()
                .flat_map(|&g| {
                    let group = &groups.topics[g];
                    if group.aggregated() {
                        STATS
                            .iter()
                            .map(|stat| format!("/{}", aggregate_entity(group, measure, stat)))
                            .collect::<Vec<_>>()
                    } else {
                        group
                            .members
                            .iter()
                            .map(|&i| format!("/bus/{}/{measure}", shape.topics[i].entity()))
                            .collect()
                    }
                })
                .filter(|q| recorded(q))
                .collect()
        };
        let (key, of) = match (p, pages.len()) {
            (_, 1) => (String::new(), String::new()),
            (p, n) => (format!("-{}", p + 1), format!(" ({}/{n})", p + 1)),
        };
        let bus = |measure: &str, title: &str| {
            let list = series(measure);
            (!list.is_empty()).then(|| {
                plot(
                    &format!("bus-{measure}{key}"),
                    &format!("{title}{of}"),
                    list,
                    extents.map(|_| (0.0, 0.0)),
                    extents,
                )
            })
        };
        let views: Vec<ViewSpec> = [
            bus("published", "bus: published (total)").map(totals),
            bus("dropped", "bus: dropped by a full queue (total)").map(totals),
            bus("msg_per_s", "bus: msg/s (1 s window)")
                .map(|v| legend_at(v, bpc::Corner2D::RightBottom)),
        ]
        .into_iter()
        .flatten()
        .collect();
        if !views.is_empty() {
            let title = if p == 0 {
                "bus".to_string()
            } else {
                format!("bus {}", p + 1)
            };
            tabs.push((title, column(views)));
        }
    }
    if let Some(views) = most_dropped_views(shape, extents) {
        tabs.push(("bus: most drops".into(), column(views)));
    }
    tabs
}

/// Once the run is over, the [`super::groups::WORST_K`] topics that dropped most (none when
/// none dropped), each by its own series: its drops, and its msg/s.
fn most_dropped_views(shape: &GraphShape, extents: Option<&Extents>) -> Option<Vec<ViewSpec>> {
    let ext = extents?;
    let drops: Vec<(usize, f64)> = shape
        .topics
        .iter()
        .enumerate()
        .filter_map(|(i, t)| {
            ext.get(&format!("bus/{}/dropped", t.entity()))
                .map(|&(_, hi)| (i, hi))
        })
        .collect();
    let worst = super::groups::worst(&drops, super::groups::WORST_K);
    if worst.is_empty() {
        return None;
    }
    let each = |measure: &str| -> Vec<String> {
        worst
            .iter()
            .map(|&i| format!("/bus/{}/{measure}", shape.topics[i].entity()))
            .filter(|q| ext.contains_key(&q[1..]))
            .collect()
    };
    let mut views = vec![totals(plot(
        "bus-worst-dropped",
        &format!("bus: the {} topics that dropped most (total)", worst.len()),
        each("dropped"),
        Some((0.0, 0.0)),
        extents,
    ))];
    let rates = each("msg_per_s");
    if !rates.is_empty() {
        views.push(legend_at(
            plot(
                "bus-worst-msg_per_s",
                "bus: msg/s of the topics that dropped most",
                rates,
                Some((0.0, 0.0)),
                extents,
            ),
            bpc::Corner2D::RightBottom,
        ));
    }
    Some(views)
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
    // right, and the pole starts near 0. Where the final layout finds no place off the
    // pole's line for it (a run with many marks), it is hidden: the title names the
    // series, and `when` the marks and their times.
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
    .legend_optional()
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
    let dropped = totals(bus("dropped", "bus: dropped by a full queue (total)"));
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
    .y_range(-half, half)
}

/// The executors' views: a lane per node raised while its tick holds a thread, each
/// tick's response time, and the ticks its timer skipped.
fn executor_views(shape: &GraphShape, extents: Option<&Extents>) -> [ViewSpec; 3] {
    // At most a dozen nodes, the same in the three plots: once the run is over, those whose
    // timers skipped most (`groups::pick`); every node of a graph of a dozen or fewer.
    let chosen = super::groups::pick(shape.nodes.len(), |i| {
        let e = format!("nodes/{}/skipped_ticks", shape.nodes[i].name);
        extents.and_then(|x| x.get(&e)).map(|&(_, hi)| hi)
    });
    let of = if chosen.len() == shape.nodes.len() {
        String::new()
    } else {
        let why = if extents.is_some() {
            ", those that skipped most"
        } else {
            ""
        };
        format!(" · {} of {} nodes{why}", chosen.len(), shape.nodes.len())
    };
    let each = |series: &str| -> Vec<String> {
        chosen
            .iter()
            .map(|&i| format!("/nodes/{}/{series}", shape.nodes[i].name))
            .collect()
    };
    // The lanes' own range, never raised to a labelled step: their numbers are ranks, the
    // legend names the nodes.
    let first = chosen.first().copied().unwrap_or(0) as f64;
    let last = chosen.last().copied().unwrap_or(0) as f64;
    let (lo, hi) = padded(first, last + LANE_BUSY);
    let timeline = plot(
        "executor-timeline",
        &format!("executor timeline: up while a tick runs{of}"),
        each("executor_lane"),
        None,
        None,
    )
    .y_range(lo, hi);
    let response = plot(
        "response",
        &format!("response time (ms): release → publish{of}"),
        each("response_ms"),
        extents.map(|_| (0.0, 0.0)),
        extents,
    );
    let skipped = totals(plot(
        "skipped",
        &format!("skipped ticks (total): thread busy{of}"),
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
            "over the wire (µs): p50, p99 so far",
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
/// out), each node and topic in its colour; a large graph's a box per group of nodes and
/// of topics ([`super::groups`]).
fn graph_view(shape: &GraphShape, groups: Option<&super::groups::Groups>) -> ViewSpec {
    let (bounds, title) = match groups {
        None => (graph_positions(shape).1, "node graph: node → /topic → node"),
        Some(groups) => (
            super::grouped::graph_positions(shape, groups).1,
            "node graph by group (×count)",
        ),
    };
    ViewSpec::new("graph", "Graph", title)
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
