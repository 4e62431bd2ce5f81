//! What a recording writes for a graph drawn by group ([`super::groups`]), beside every
//! node's and topic's own series: each topic group's aggregates (its smallest, median and
//! largest published count, drops and msg/s) at every actuator step and at the run's end,
//! and the node graph with a box per group of nodes and per group of topics, edges between
//! them wherever a topic links them.

use super::groups::{aggregate_entity, min_median_max, Group, Groups, MEASURES, STATS};
use super::*;
use std::collections::BTreeSet;

/// A topic group's aggregates of `measure` from its members' `values` at run time `t`
/// (step `step`): nothing when none of them has a value.
fn aggregate_rows(
    buf: &mut ChunkBuffer,
    group: &Group,
    measure: &str,
    (t, step): (Nanos, u64),
    values: &[f64],
) {
    if let Some((lo, median, hi)) = min_median_max(values) {
        for (stat, value) in STATS.iter().zip([hi, median, lo]) {
            buf.scalar(&aggregate_entity(group, measure, stat), t, step, value);
        }
    }
}

/// At an actuator step (run time `t`, step `step`): each topic group drawn by its
/// aggregates, from `values` (per measure in [`MEASURES`]' order, per topic: its value at
/// this step, `None` when it has none yet, as msg/s before a topic's first message).
pub(super) fn bus_rows(
    buf: &mut ChunkBuffer,
    groups: &Groups,
    t: Nanos,
    step: u64,
    values: &[Vec<Option<f64>>; 3],
) {
    for g in groups.topics.iter().filter(|g| g.aggregated()) {
        for (measure, of) in MEASURES.iter().zip(values) {
            let v: Vec<f64> = g
                .members
                .iter()
                .filter_map(|&i| of.get(i).copied().flatten())
                .collect();
            aggregate_rows(buf, g, measure, (t, step), &v);
        }
    }
}

/// At the run's end (`end`, step `step`), after the topics' own values there
/// ([`Recording::finish`]: an actuator that stopped stepping before the end): each topic
/// group drawn by its aggregates, from the values its members were given at `end`, so its
/// lines reach the end with theirs. Nothing for a graph drawn node by node.
pub(super) fn end_rows(buf: &mut ChunkBuffer, shape: &GraphShape, end: Nanos, step: u64) {
    let Some(groups) = Groups::of(shape) else {
        return;
    };
    let at = i64::try_from(end.0).unwrap_or(i64::MAX);
    for g in groups.topics.iter().filter(|g| g.aggregated()) {
        for measure in MEASURES {
            let v: Vec<f64> = g
                .members
                .iter()
                .filter_map(|&i| {
                    let entity = format!("bus/{}/{measure}", shape.topics.get(i)?.entity());
                    let col = buf.scalars.get(&entity)?;
                    (col.t_ns.last() == Some(&at))
                        .then(|| col.value.last().copied())
                        .flatten()
                })
                .collect();
            aggregate_rows(buf, g, measure, (end, step), &v);
        }
    }
}

/// A large graph's node graph: a box per group of nodes, then per group of topics (each
/// box's id its group's label), and the edges from a group of nodes to a group of topics
/// one of its nodes publishes on, and from a group of topics to a group of nodes one of
/// whose nodes reads one of them (by index into the boxes).
struct Boxes {
    ids: Vec<String>,
    /// Groups of nodes come first: so many.
    node_boxes: usize,
    edges: BTreeSet<(usize, usize)>,
}

fn boxes(shape: &GraphShape, groups: &Groups) -> Boxes {
    let index: BTreeMap<&str, usize> = shape
        .nodes
        .iter()
        .enumerate()
        .map(|(i, n)| (n.name.as_str(), i))
        .collect();
    let node_group = groups.node_group(shape.nodes.len());
    let topic_group = groups.topic_group(shape.topics.len());
    let node_boxes = groups.nodes.len();
    let mut edges = BTreeSet::new();
    for (i, t) in shape.topics.iter().enumerate() {
        let topic = node_boxes + topic_group[i];
        if let Some(&p) = index.get(t.publisher.as_str()) {
            edges.insert((node_group[p], topic));
        }
        for s in &t.subscribers {
            if let Some(&n) = index.get(s.as_str()) {
                edges.insert((topic, node_group[n]));
            }
        }
    }
    Boxes {
        ids: groups
            .nodes
            .iter()
            .chain(&groups.topics)
            .map(|g| g.label.clone())
            .collect(),
        node_boxes,
        edges,
    }
}

impl Boxes {
    /// Left-to-right columns, as the node graph's ([`GraphShape::columns`]): groups of
    /// nodes from column 0, of topics from 1, each box one right of the furthest box with
    /// an edge into it (a cycle stops growing after as many rounds as there are boxes, and
    /// the columns no box took are closed up: groups that feed one another, as `other
    /// nodes` and `other topics` may, do not stretch the graph).
    fn columns(&self) -> Vec<(String, usize)> {
        let mut col: Vec<usize> = (0..self.ids.len())
            .map(|i| usize::from(i >= self.node_boxes))
            .collect();
        for _ in 0..self.ids.len() {
            let mut changed = false;
            for &(from, to) in &self.edges {
                if col[from] + 1 > col[to] {
                    col[to] = col[from] + 1;
                    changed = true;
                }
            }
            if !changed {
                break;
            }
        }
        let taken: BTreeSet<usize> = col.iter().copied().collect();
        let closed: BTreeMap<usize, usize> =
            taken.into_iter().enumerate().map(|(r, c)| (c, r)).collect();
        self.ids
            .iter()
            .cloned()
            .zip(col.iter().map(|c| closed[c]))
            .collect()
    }
}

/// The grouped node graph's positions (box id → x, y) and the bounds that frame them,
/// laid out as a node graph is (a chain longer than five columns folded into bands).
pub(super) fn graph_positions(
    shape: &GraphShape,
    groups: &Groups,
) -> (Vec<(String, [f32; 2])>, bpc::VisualBounds2D) {
    super::positions_of(boxes(shape, groups).columns())
}

/// A group of nodes' label: a single node's own ([`NodeShape::label`]); a group's name and
/// count, its rates, whether its nodes are Python's and the processes they run in:
/// `sensor_* ×249`, `10–100 Hz`, `process robot` (`7 processes`).
fn node_group_label(shape: &GraphShape, g: &Group) -> String {
    if let [only] = g.members.as_slice() {
        return shape.nodes[*only].label();
    }
    let members: Vec<&NodeShape> = g
        .members
        .iter()
        .filter_map(|&i| shape.nodes.get(i))
        .collect();
    let rates: Vec<f64> = members.iter().map(|n| n.rate.hz()).collect();
    let (lo, _, hi) = min_median_max(&rates).unwrap_or_default();
    let mut lines = vec![
        format!("{} ×{}", g.label, members.len()),
        if lo == hi {
            format!("{} Hz", hz_label(lo))
        } else {
            format!("{}–{} Hz", hz_label(lo), hz_label(hi))
        },
    ];
    let python = members.iter().filter(|n| n.python).count();
    if python == members.len() {
        lines.push("python".to_string());
    } else if python > 0 {
        lines.push(format!("python ×{python}"));
    }
    let processes: BTreeSet<&str> = members
        .iter()
        .filter_map(|n| n.process.as_deref())
        .collect();
    match processes.iter().collect::<Vec<_>>().as_slice() {
        [] => {}
        [one] => lines.push(format!("process {one}")),
        many => lines.push(format!("{} processes", many.len())),
    }
    lines.join("\n")
}

/// A group of topics' label: a single topic's own ([`TopicShape::label`]); a group's name
/// and count (the topics its edges carry), their depths now and how many have QoS beyond
/// the depth: `/c_*/pos ×249`, `depth 1`.
fn topic_group_label(shape: &GraphShape, g: &Group) -> String {
    if let [only] = g.members.as_slice() {
        return shape.topics[*only].label();
    }
    let members: Vec<&TopicShape> = g
        .members
        .iter()
        .filter_map(|&i| shape.topics.get(i))
        .collect();
    let depths: Vec<usize> = members.iter().map(|t| (t.stats)().depth).collect();
    let (lo, hi) = (
        depths.iter().copied().min().unwrap_or(0),
        depths.iter().copied().max().unwrap_or(0),
    );
    let mut lines = vec![
        format!("{} ×{}", g.label, members.len()),
        if lo == hi {
            format!("depth {lo}")
        } else {
            format!("depth {lo}–{hi}")
        },
    ];
    let qos = members
        .iter()
        .filter(|t| !(t.live_qos)().is_default())
        .count();
    if qos > 0 {
        lines.push(format!("QoS set on {qos}"));
    }
    lines.join("\n")
}

/// The node graph of a large graph with its current labels, a box per group (module
/// docs): each in its group's colour (a single node's or topic's own), edges group →
/// group of topics → group.
pub(super) fn graph_rows(
    buf: &mut ChunkBuffer,
    time: &TimePoint,
    shape: &GraphShape,
    groups: &Groups,
) {
    let b = boxes(shape, groups);
    let (positions, _) = super::positions_of(b.columns());
    let mut labels = Vec::with_capacity(b.ids.len());
    let mut colors = Vec::with_capacity(b.ids.len());
    for g in &groups.nodes {
        labels.push(node_group_label(shape, g));
        colors.push(node_color(&g.label));
    }
    for g in &groups.topics {
        labels.push(topic_group_label(shape, g));
        colors.push(topic_color(&g.label));
    }
    buf.add(
        "graph",
        time,
        &rerun::GraphNodes::new(positions.iter().map(|(id, _)| id.as_str()))
            .with_positions(positions.iter().map(|(_, p)| *p))
            .with_labels(labels)
            .with_colors(colors),
    );
    let edges: Vec<(String, String)> = b
        .edges
        .iter()
        .map(|&(from, to)| (b.ids[from].clone(), b.ids[to].clone()))
        .collect();
    buf.add(
        "graph",
        time,
        &rerun::GraphEdges::new(edges).with_directed_edges(),
    );
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The shape of `ratelab graph --nodes n --processes p` (the runtime's generator),
    /// counters at zero.
    fn placed(n: usize, p: usize) -> GraphShape {
        let toml = ratelab_runtime::graph::synthetic::graph_toml(n, p);
        let spec = ratelab_runtime::graph::GraphSpec::parse(&toml, "synthetic").unwrap();
        let each = TopicStats {
            depth: 1,
            ..TopicStats::default()
        };
        let stats = Arc::new(Mutex::new(vec![each; spec.topics.len()]));
        GraphShape::from_spec(&spec, stats, None).unwrap()
    }

    /// [`placed`] in one process, as a graph run in one process draws it (no process).
    fn generated(n: usize) -> GraphShape {
        let mut shape = placed(n, 1);
        for node in &mut shape.nodes {
            node.process = None;
        }
        shape
    }

    #[test]
    fn a_thousand_node_graph_is_a_box_per_group_folded_to_read() {
        let shape = generated(1000);
        let groups = Groups::of(&shape).expect("a large graph");
        let b = boxes(&shape, &groups);
        assert_eq!(b.ids.len(), 15, "{:?}", b.ids);
        // The controllers' chain, group to group, with the chapter's loop beside it.
        for (from, to) in [
            ("sensor_*", "/c_*/pos"),
            ("/c_*/pos", "estimator_*"),
            ("safety_*", "/c_*/cmd"),
            ("sensor", "/obs"),
            ("/action", "actuator"),
        ] {
            let at = |id: &str| b.ids.iter().position(|x| x == id).unwrap();
            assert!(b.edges.contains(&(at(from), at(to))), "{from} → {to}");
        }
        assert_eq!(b.edges.len(), 12, "{:?}", b.edges);
        let columns: BTreeMap<String, usize> = b.columns().into_iter().collect();
        assert_eq!(columns["sensor_*"], 0);
        assert_eq!(columns["/c_*/cmd"], 7);
        assert_eq!(columns["actuator"], 4);
        // Eight columns fold into two bands of four: about the chapter's size in graph
        // units, so its labels read at the chapter's scale in a panel twice its height.
        let (positions, bounds) = graph_positions(&shape, &groups);
        assert_eq!(positions.len(), 15);
        let r = bounds.0;
        let (w, h) = (
            r.x_range.0[1] - r.x_range.0[0],
            r.y_range.0[1] - r.y_range.0[0],
        );
        assert!(w <= 800.0 && h <= 600.0, "{w} × {h}");
        let distinct: BTreeSet<String> = positions.iter().map(|(_, p)| format!("{p:?}")).collect();
        assert_eq!(distinct.len(), positions.len(), "no two boxes at one place");
        // Labels: a group's count and rates, a single node's own.
        let sensors = &groups.nodes[3];
        assert_eq!(
            node_group_label(&shape, sensors),
            "sensor_* ×249\n10–100 Hz"
        );
        assert_eq!(node_group_label(&shape, &groups.nodes[0]), "sensor · 50 Hz");
        assert_eq!(
            topic_group_label(&shape, &groups.topics[2]),
            "/c_*/pos ×249\ndepth 1"
        );
    }

    #[test]
    fn no_view_of_a_large_graph_s_layout_draws_more_than_a_dozen_series() {
        use crate::groups::MAX_SERIES_PER_VIEW;
        for n in [9, 100, 1000] {
            let shape = generated(n);
            let toml = ratelab_runtime::graph::synthetic::graph_toml(n, 1);
            let mut graph = ratelab_runtime::graph::GraphSpec::parse(&toml, "synthetic").unwrap();
            // Executors too: three plots of a lane, a response time, skipped ticks a node.
            graph.set_executor(
                ratelab_core::executor::ExecutorOverride::parse("single_threaded").unwrap(),
            );
            for clock in [ClockKind::Virtual, ClockKind::Real] {
                let cfg = RunConfig {
                    clock,
                    graph: graph.clone(),
                    ..RunConfig::default()
                };
                let mut root = crate::blueprint::layout_for(&shape, &cfg, None);
                // Every view's title reads whole at 1280×720.
                let cut = crate::legend::cut_titles(&mut root);
                assert!(cut.is_empty(), "{n} nodes, {clock:?}: cut titles {cut:?}");
                let views = root.views();
                for v in &views {
                    let (title, queries) = v.title_and_queries();
                    assert!(
                        queries.len() <= MAX_SERIES_PER_VIEW,
                        "{n} nodes: {title:?} draws {}",
                        queries.len()
                    );
                }
                let titles: Vec<&str> = views.iter().map(|v| v.title_and_queries().0).collect();
                for start in ["groups:", "node graph by group", "executor timeline"] {
                    assert!(
                        titles.iter().any(|t| t.starts_with(start)),
                        "{n}: {titles:?}"
                    );
                }
                if n > MAX_SERIES_PER_VIEW {
                    let of = format!("{MAX_SERIES_PER_VIEW} of {n}");
                    let capped = |start: &str| {
                        titles
                            .iter()
                            .any(|t| t.starts_with(start) && t.contains(&of))
                    };
                    assert!(capped("executor timeline"), "{titles:?}");
                    assert_eq!(capped("node tick lateness"), clock == ClockKind::Real);
                }
            }
        }
    }

    #[test]
    fn groups_that_feed_one_another_do_not_stretch_the_graph() {
        // Nine nodes of no common pattern in a ring: the smallest merged into `other
        // nodes`, whose topics (`other topics`) it reads itself.
        let nodes: Vec<String> = (b'a'..=b'i').map(|c| format!("n{}", c as char)).collect();
        let topics: Vec<(String, String, String)> = (0..9)
            .map(|i| {
                let t = format!("/t{}", (b'a' + i as u8) as char);
                (t, nodes[i].clone(), nodes[(i + 1) % 9].clone())
            })
            .collect();
        let spec: Vec<(&str, &str, Vec<&str>)> = topics
            .iter()
            .map(|(t, p, s)| (t.as_str(), p.as_str(), vec![s.as_str()]))
            .collect();
        let listed: Vec<(&str, &str, &[&str])> = spec
            .iter()
            .map(|(t, p, s)| (*t, *p, s.as_slice()))
            .collect();
        let names: Vec<&str> = nodes.iter().map(String::as_str).collect();
        let shape = crate::shape::tests::shape(&listed, &names);
        let groups = Groups::of(&shape).unwrap();
        let columns = boxes(&shape, &groups).columns();
        let widest = columns.iter().map(|(_, c)| *c).max().unwrap();
        assert!(widest < columns.len(), "{columns:?}");
    }

    #[test]
    fn a_placed_group_names_its_process_or_counts_them() {
        let shape = placed(1000, 8);
        let groups = Groups::of(&shape).unwrap();
        let label = |name: &str| {
            let g = groups.nodes.iter().find(|g| g.label == name).unwrap();
            node_group_label(&shape, g)
        };
        assert!(
            label("sensor_*").ends_with("\nprocess robot"),
            "{}",
            label("sensor_*")
        );
        assert!(
            label("estimator_*").ends_with("\n7 processes"),
            "{}",
            label("estimator_*")
        );
    }
}
