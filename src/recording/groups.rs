//! Graphs of any size: how a recording groups a large graph's nodes and topics, so that no
//! view draws more than it can show at 1280×720 ([`MAX_SERIES_PER_VIEW`] series a plot).
//!
//! A graph with at most [`GROUP_ABOVE`] nodes and at most [`GROUP_ABOVE`] topics (every
//! shipped graph, the chapter's three nodes and two topics among them) is drawn node by node
//! and topic by topic, as it always was ([`Groups::of`] is `None` for it). A larger one is
//! drawn by group:
//! - nodes and topics are grouped by name, every run of digits read as `*` (`sensor_12` →
//!   `sensor_*`, `/c_12/pos` → `/c_*/pos`: [`pattern`]), so a generated graph's
//!   controllers fall into one group per role and the chapter's loop keeps its own names;
//!   at most [`MAX_GROUPS`] groups of each, the smallest merged into `other nodes` or
//!   `other topics`;
//! - on the bus's plots a group of at most [`SHOWN_EACH_UP_TO`] topics is drawn topic by
//!   topic, a larger one by its smallest, median and largest value at each actuator step
//!   ([`min_median_max`]), each group whole on one page of at most
//!   [`MAX_SERIES_PER_VIEW`] series ([`bus_pages`]); the topics that dropped most are
//!   drawn each by its own series ([`worst`]);
//! - the node graph draws a box per group (`sensor_* ×249`), and a box per group of
//!   topics carrying its count (rerun's edges carry no labels);
//! - every node's and topic's own series is recorded in full (`bus/<topic>/…`,
//!   `nodes/<name>/…`), reachable in the viewer's entity tree and listed in the `groups`
//!   document by group, not drawn in a plot: pages of twelve would be 250 pages a measure for
//!   a graph of 1,000 nodes.
//!
//! Any plot of per-node or per-topic series with more than [`MAX_SERIES_PER_VIEW`] of them
//! (QoS counters, liveliness, executors, lateness, the wire, whatever the graph's size)
//! shows the ones that rose highest ([`pick`]; at the start, before anything is known, the
//! first ones).

use super::GraphShape;
use std::collections::{BTreeMap, BTreeSet};

/// A graph with more nodes than this, or more topics, is drawn by group (module docs). The
/// shipped graphs have at most 7 nodes and 5 topics; the chapter's, 3 and 2.
pub const GROUP_ABOVE: usize = 8;

/// The most series a time-series view draws, for any graph (a legend row each fits a plot
/// of the usual height at 1280×720; 99 lines drawn at once stalled the viewer's GPU).
pub const MAX_SERIES_PER_VIEW: usize = 12;

/// The most groups of nodes, and of topics, a grouped graph has: the smallest groups past
/// that are merged into one (`other nodes`, `other topics`).
pub const MAX_GROUPS: usize = 8;

/// A group of this many members or fewer is drawn member by member (its own series, no
/// more lines than its aggregates would take); a larger one by its aggregates.
pub const SHOWN_EACH_UP_TO: usize = 3;

/// How many of the topics that dropped most a large graph's bus draws, each by its own
/// series, once the run is over.
pub const WORST_K: usize = 6;

/// The bus's measures, each a plot: the leaf of a topic's entity (`bus/<topic>/<measure>`).
pub const MEASURES: [&str; 3] = ["published", "dropped", "msg_per_s"];

/// A group's aggregates at a sample, in the order their entities sort (and are drawn).
pub const STATS: [&str; 3] = ["max", "median", "min"];

/// The name a merged group of nodes has.
const OTHER_NODES: &str = "other nodes";
/// The name a merged group of topics has.
const OTHER_TOPICS: &str = "other topics";

/// `name` with every run of ASCII digits read as `*`: `sensor_12` → `sensor_*`, `/c_3/pos`
/// → `/c_*/pos`, `policy` → `policy`.
pub fn pattern(name: &str) -> String {
    let mut out = String::with_capacity(name.len());
    let mut in_digits = false;
    for c in name.chars() {
        if c.is_ascii_digit() {
            if !in_digits {
                out.push('*');
            }
            in_digits = true;
        } else {
            out.push(c);
            in_digits = false;
        }
    }
    out
}

/// One group of nodes or of topics.
#[derive(Clone, Debug, PartialEq)]
pub struct Group {
    /// What it is called: its members' [`pattern`] (`/c_*/pos`), the name of its only
    /// member, or `other nodes` / `other topics` for the merged smallest groups.
    pub label: String,
    /// Its entity path part (`c_k_pos`: the label's `*` as `k`, its `/` as `_`), unique
    /// among the graph's groups of its kind.
    pub key: String,
    /// Its members: indices into the shape's nodes or topics, in the shape's order.
    pub members: Vec<usize>,
}

impl Group {
    /// Whether the group is drawn by its aggregates rather than member by member (more than
    /// [`SHOWN_EACH_UP_TO`] members).
    pub fn aggregated(&self) -> bool {
        self.members.len() > SHOWN_EACH_UP_TO
    }

    /// The series its lines take on one bus plot: its members' one each, or its three
    /// aggregates ([`STATS`]).
    pub fn lines(&self) -> usize {
        if self.aggregated() {
            STATS.len()
        } else {
            self.members.len()
        }
    }
}

/// A large graph's groups of nodes and of topics, each group's members in the shape's
/// order, the groups in the order of their first member (a merged group last).
#[derive(Clone, Debug, PartialEq)]
pub struct Groups {
    /// The groups of nodes.
    pub nodes: Vec<Group>,
    /// The groups of topics.
    pub topics: Vec<Group>,
}

/// Whether a graph of `nodes` nodes and `topics` topics is drawn by group.
pub fn is_large(nodes: usize, topics: usize) -> bool {
    nodes > GROUP_ABOVE || topics > GROUP_ABOVE
}

impl Groups {
    /// The groups of `shape`, when it is large enough to be drawn by group ([`is_large`]);
    /// `None` for a graph drawn node by node, as every shipped graph is.
    pub fn of(shape: &GraphShape) -> Option<Groups> {
        if !is_large(shape.nodes.len(), shape.topics.len()) {
            return None;
        }
        let nodes: Vec<&str> = shape.nodes.iter().map(|n| n.name.as_str()).collect();
        let topics: Vec<&str> = shape.topics.iter().map(|t| t.name.as_str()).collect();
        Some(Groups::of_names(&nodes, &topics))
    }

    /// The groups of nodes named `nodes` and topics named `topics` (module docs), whatever
    /// their number.
    pub fn of_names(nodes: &[&str], topics: &[&str]) -> Groups {
        Groups {
            nodes: group_names(nodes, OTHER_NODES),
            topics: group_names(topics, OTHER_TOPICS),
        }
    }

    /// Per node (by index), the index of its group.
    pub fn node_group(&self, nodes: usize) -> Vec<usize> {
        group_of(&self.nodes, nodes)
    }

    /// Per topic (by index), the index of its group.
    pub fn topic_group(&self, topics: usize) -> Vec<usize> {
        group_of(&self.topics, topics)
    }
}

/// Per member (of `n`), the index of its group in `groups`.
fn group_of(groups: &[Group], n: usize) -> Vec<usize> {
    let mut out = vec![0; n];
    for (g, group) in groups.iter().enumerate() {
        for &m in &group.members {
            if let Some(slot) = out.get_mut(m) {
                *slot = g;
            }
        }
    }
    out
}

/// `names` grouped by [`pattern`], in the order of each group's first member; past
/// [`MAX_GROUPS`] groups the largest `MAX_GROUPS − 1` are kept (the first listed among
/// equals) and the rest merged into one called `other`.
fn group_names(names: &[&str], other: &str) -> Vec<Group> {
    let mut index: BTreeMap<String, usize> = BTreeMap::new();
    let mut found: Vec<(String, Vec<usize>)> = Vec::new();
    for (i, name) in names.iter().enumerate() {
        let p = pattern(name);
        match index.get(&p) {
            Some(&g) => found[g].1.push(i),
            None => {
                index.insert(p.clone(), found.len());
                found.push((p, vec![i]));
            }
        }
    }
    if found.len() > MAX_GROUPS {
        // Groups are in the order of their first member: the index breaks ties.
        let mut by_size: Vec<usize> = (0..found.len()).collect();
        by_size.sort_by_key(|&g| (std::cmp::Reverse(found[g].1.len()), g));
        let keep: BTreeSet<usize> = by_size[..MAX_GROUPS - 1].iter().copied().collect();
        let mut kept = Vec::new();
        let mut rest = Vec::new();
        for (g, group) in found.into_iter().enumerate() {
            if keep.contains(&g) {
                kept.push(group);
            } else {
                rest.extend(group.1);
            }
        }
        rest.sort_unstable();
        kept.push((other.to_string(), rest));
        found = kept;
    }
    let mut used: BTreeSet<String> = BTreeSet::new();
    found
        .into_iter()
        .map(|(label, members)| {
            // A group of one is called by its member's own name.
            let label = match members.as_slice() {
                [only] if label != other => names[*only].to_string(),
                _ => label,
            };
            let base = key_of(&label);
            let mut key = base.clone();
            let mut n = 2;
            while !used.insert(key.clone()) {
                key = format!("{base}.{n}");
                n += 1;
            }
            Group {
                label,
                key,
                members,
            }
        })
        .collect()
}

/// A group's entity path part: its label without the leading `/`, `/` and spaces as `_`,
/// `*` as `k` (`/c_*/pos` → `c_k_pos`).
fn key_of(label: &str) -> String {
    label
        .trim_start_matches('/')
        .replace(['/', ' '], "_")
        .replace('*', "k")
}

/// The smallest, the median (of an even count, the mean of the two middle values) and the
/// largest of `values`, those that are not a number left out; `None` when none is left.
pub fn min_median_max(values: &[f64]) -> Option<(f64, f64, f64)> {
    let mut v: Vec<f64> = values.iter().copied().filter(|x| !x.is_nan()).collect();
    if v.is_empty() {
        return None;
    }
    v.sort_unstable_by(f64::total_cmp);
    let n = v.len();
    let median = if n % 2 == 1 {
        v[n / 2]
    } else {
        (v[n / 2 - 1] + v[n / 2]) / 2.0
    };
    Some((v[0], median, v[n - 1]))
}

/// The members (of `values`: member, value) with the `k` largest values above 0, largest
/// first, the first listed among equals: the topics that dropped most, by their drops.
pub fn worst(values: &[(usize, f64)], k: usize) -> Vec<usize> {
    let mut v: Vec<(usize, usize, f64)> = values
        .iter()
        .enumerate()
        .filter(|(_, (_, x))| *x > 0.0)
        .map(|(order, &(m, x))| (order, m, x))
        .collect();
    v.sort_by(|a, b| b.2.total_cmp(&a.2).then(a.0.cmp(&b.0)));
    v.into_iter().take(k).map(|(_, m, _)| m).collect()
}

/// Of `n` series, the indices of at most [`MAX_SERIES_PER_VIEW`], in order: every one when
/// there are that many or fewer; else those whose `largest` value is highest (a series not
/// known yet, `None`, counts lowest; the first listed among equals), so that at the start,
/// when nothing is known, the first ones.
pub fn pick(n: usize, largest: impl Fn(usize) -> Option<f64>) -> Vec<usize> {
    if n <= MAX_SERIES_PER_VIEW {
        return (0..n).collect();
    }
    let mut ranked: Vec<(usize, Option<f64>)> = (0..n).map(|i| (i, largest(i))).collect();
    ranked.sort_by(|a, b| match (a.1, b.1) {
        (Some(x), Some(y)) => y.total_cmp(&x).then(a.0.cmp(&b.0)),
        (Some(_), None) => std::cmp::Ordering::Less,
        (None, Some(_)) => std::cmp::Ordering::Greater,
        (None, None) => a.0.cmp(&b.0),
    });
    let mut chosen: Vec<usize> = ranked
        .into_iter()
        .take(MAX_SERIES_PER_VIEW)
        .map(|(i, _)| i)
        .collect();
    chosen.sort_unstable();
    chosen
}

/// The bus's pages: the indices of the topic groups each page's plots draw, whole groups
/// in order, each page at most [`MAX_SERIES_PER_VIEW`] series ([`Group::lines`]).
pub fn bus_pages(groups: &Groups) -> Vec<Vec<usize>> {
    let mut pages: Vec<Vec<usize>> = Vec::new();
    let mut lines = 0;
    for (g, group) in groups.topics.iter().enumerate() {
        let n = group.lines();
        match pages.last_mut() {
            Some(page) if lines + n <= MAX_SERIES_PER_VIEW => page.push(g),
            _ => {
                pages.push(vec![g]);
                lines = 0;
            }
        }
        lines += n;
    }
    pages
}

/// The entity of a topic group's aggregate `stat` ([`STATS`]) of `measure` ([`MEASURES`]):
/// `bus_groups/<key>/<measure>/<stat>`.
pub fn aggregate_entity(group: &Group, measure: &str, stat: &str) -> String {
    format!("bus_groups/{}/{measure}/{stat}", group.key)
}

/// The lines a large graph's bus plots draw, as their entities start, each topic group's in
/// turn: its members' own (`bus/<topic>`, `topic_entities` by topic) or its aggregates'
/// (`bus_groups/<key>`). Each plot draws these lines of its page; the rule that widens
/// coinciding lines layers them, and only them.
pub fn bus_lines(groups: &Groups, topic_entities: &[String]) -> Vec<String> {
    groups
        .topics
        .iter()
        .flat_map(|g| {
            if g.aggregated() {
                vec![format!("bus_groups/{}", g.key)]
            } else {
                g.members
                    .iter()
                    .filter_map(|&i| topic_entities.get(i))
                    .map(|e| format!("bus/{e}"))
                    .collect()
            }
        })
        .collect()
}

/// The entity of the `groups` document ([`document`]).
pub const DOC_ENTITY: &str = "groups";

/// The `groups` document (markdown): how a large graph is drawn, and every group with its
/// members' entity paths, where their own series are (`/bus/<topic>`, `/nodes/<name>`):
/// recorded in full, reachable in the viewer's entity tree, drawn in no plot.
pub fn document(shape: &GraphShape, groups: &Groups) -> String {
    let mut doc = format!(
        "**{} nodes and {} topics, drawn by group** (a graph of more than {GROUP_ABOVE} nodes \
         or topics; names grouped with their digits read as `*`).\n\n\
         The bus's plots draw a group of up to {SHOWN_EACH_UP_TO} topics topic by topic, a \
         larger one by its smallest, median and largest value at each actuator step \
         (`/bus_groups/<group>/<measure>/max`, `…/median`, `…/min`), at most \
         {MAX_SERIES_PER_VIEW} series a plot; the node graph draws a box per group. Every \
         topic's and node's own series is recorded in full under the paths listed below: \
         open the time panel (bottom) to find them in the entity tree, and right-click one to \
         add it to a view.\n\n## Topics\n\n",
        shape.nodes.len(),
        shape.topics.len(),
    );
    let list = |g: &Group, what: &str, paths: Vec<String>| {
        format!(
            "- `{}`, {} {what}: {}\n",
            g.label,
            g.members.len(),
            paths
                .iter()
                .map(|p| format!("`{p}`"))
                .collect::<Vec<_>>()
                .join(", ")
        )
    };
    for g in &groups.topics {
        let paths = g
            .members
            .iter()
            .filter_map(|&i| shape.topics.get(i))
            .map(|t| format!("/bus/{}", t.entity()))
            .collect();
        doc.push_str(&list(g, "topic(s)", paths));
    }
    doc.push_str("\n## Nodes\n\n");
    for g in &groups.nodes {
        let paths = g
            .members
            .iter()
            .filter_map(|&i| shape.nodes.get(i))
            .map(|n| format!("/nodes/{}", n.name))
            .collect();
        doc.push_str(&list(g, "node(s)", paths));
    }
    doc
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The node and topic names of `ratelab graph --nodes n` (the runtime's generator).
    fn generated(n: usize) -> (Vec<String>, Vec<String>) {
        let toml = ratelab_runtime::graph::synthetic::graph_toml(n, 1);
        let spec = ratelab_runtime::graph::GraphSpec::parse(&toml, "synthetic").unwrap();
        (
            spec.nodes.iter().map(|n| n.name.clone()).collect(),
            spec.topics.iter().map(|t| t.name.clone()).collect(),
        )
    }

    fn of(nodes: &[String], topics: &[String]) -> Groups {
        let n: Vec<&str> = nodes.iter().map(String::as_str).collect();
        let t: Vec<&str> = topics.iter().map(String::as_str).collect();
        Groups::of_names(&n, &t)
    }

    fn labels(groups: &[Group]) -> Vec<(&str, usize)> {
        groups
            .iter()
            .map(|g| (g.label.as_str(), g.members.len()))
            .collect()
    }

    #[test]
    fn digits_are_read_as_a_wildcard() {
        assert_eq!(pattern("sensor_12"), "sensor_*");
        assert_eq!(pattern("/c_3/pos"), "/c_*/pos");
        assert_eq!(pattern("/c_310/state2"), "/c_*/state*");
        assert_eq!(pattern("policy"), "policy");
        assert_eq!(key_of("/c_*/pos"), "c_k_pos");
        assert_eq!(key_of("other topics"), "other_topics");
    }

    #[test]
    fn a_generated_graph_falls_into_its_roles_and_keeps_the_chapter_s_names() {
        let (nodes, topics) = generated(1000);
        assert!(is_large(nodes.len(), topics.len()));
        let g = of(&nodes, &topics);
        assert_eq!(
            labels(&g.nodes),
            [
                ("sensor", 1),
                ("policy", 1),
                ("actuator", 1),
                ("sensor_*", 249),
                ("estimator_*", 249),
                ("policy_*", 249),
                ("safety_*", 249),
                ("extra_0", 1),
            ]
        );
        assert_eq!(
            labels(&g.topics),
            [
                ("/obs", 1),
                ("/action", 1),
                ("/c_*/pos", 249),
                ("/c_*/state", 249),
                ("/c_*/force", 249),
                ("/c_*/cmd", 249),
                ("/extra_0", 1),
            ]
        );
        assert_eq!(g.topics[2].key, "c_k_pos");
        assert_eq!(g.topics[2].members[..2], [2, 6]);
        // Every member in exactly one group.
        let of_topic = g.topic_group(topics.len());
        assert_eq!(of_topic[0], 0);
        assert_eq!(of_topic[6], 2);
        assert_eq!(of_topic[998], 6);
        let all: usize = g.nodes.iter().map(|g| g.members.len()).sum();
        assert_eq!(all, nodes.len());
    }

    #[test]
    fn small_graphs_are_not_grouped_and_many_groups_are_merged() {
        assert!(!is_large(3, 2));
        assert!(!is_large(GROUP_ABOVE, GROUP_ABOVE));
        assert!(is_large(GROUP_ABOVE + 1, 2));
        assert!(is_large(3, GROUP_ABOVE + 1));
        // Twenty names of no common pattern: the first seven kept, the rest merged.
        let names: Vec<String> = (b'a'..=b't')
            .map(|c| format!("node{}", c as char))
            .collect();
        let g = of(&names, &[]);
        assert_eq!(g.nodes.len(), MAX_GROUPS);
        let last = g.nodes.last().unwrap();
        assert_eq!(last.label, "other nodes");
        assert_eq!(last.key, "other_nodes");
        assert_eq!(last.members, (7..20).collect::<Vec<_>>());
        assert_eq!(g.nodes[0].label, "nodea");
        // The larger groups are kept before the first listed.
        let mut names: Vec<String> = (0..9)
            .map(|i| format!("solo{}x", (b'a' + i) as char))
            .collect();
        names.extend((0..5).map(|i| format!("many_{i}")));
        let g = of(&names, &[]);
        assert!(g.nodes.iter().any(|g| g.label == "many_*"), "{g:?}");
    }

    #[test]
    fn keys_stay_unique() {
        let g = of(&["a-1".into(), "a-2".into(), "a_k".into()], &[]);
        let keys: Vec<&str> = g.nodes.iter().map(|g| g.key.as_str()).collect();
        assert_eq!(keys, ["a-k", "a_k"]);
        let g = of(&["x_1".into(), "x_2".into(), "x_k".into()], &[]);
        let keys: Vec<&str> = g.nodes.iter().map(|g| g.key.as_str()).collect();
        assert_eq!(keys, ["x_k", "x_k.2"]);
    }

    #[test]
    fn a_group_s_min_median_and_max_at_a_sample() {
        assert_eq!(min_median_max(&[3.0, 1.0, 2.0]), Some((1.0, 2.0, 3.0)));
        assert_eq!(min_median_max(&[4.0, 1.0, 2.0, 3.0]), Some((1.0, 2.5, 4.0)));
        assert_eq!(min_median_max(&[7.0]), Some((7.0, 7.0, 7.0)));
        assert_eq!(min_median_max(&[f64::NAN, 5.0, 1.0]), Some((1.0, 3.0, 5.0)));
        assert_eq!(min_median_max(&[]), None);
        assert_eq!(min_median_max(&[f64::NAN]), None);
        // The published totals of a generated group at 10, 20, 50 and 100 Hz after 1 s.
        let totals = [10.0, 20.0, 50.0, 100.0, 10.0, 20.0, 50.0, 100.0, 10.0];
        assert_eq!(min_median_max(&totals), Some((10.0, 20.0, 100.0)));
    }

    #[test]
    fn the_worst_by_drops_are_the_k_largest_above_zero() {
        let drops = [
            (10, 0.0),
            (11, 5.0),
            (12, 9.0),
            (13, 5.0),
            (14, 1.0),
            (15, 0.0),
        ];
        assert_eq!(worst(&drops, 3), [12, 11, 13]);
        assert_eq!(worst(&drops, 10), [12, 11, 13, 14]);
        assert_eq!(worst(&[(0, 0.0), (1, 0.0)], 3), Vec::<usize>::new());
        assert_eq!(worst(&drops, 0), Vec::<usize>::new());
    }

    #[test]
    fn a_view_picks_at_most_a_dozen_the_highest_in_order() {
        assert_eq!(pick(3, |_| None), [0, 1, 2]);
        let n = 40;
        let first = pick(n, |_| None);
        assert_eq!(first, (0..MAX_SERIES_PER_VIEW).collect::<Vec<_>>());
        // The highest: the last twelve by value, listed in their order.
        let highest = pick(n, |i| Some(i as f64));
        assert_eq!(highest, (n - MAX_SERIES_PER_VIEW..n).collect::<Vec<_>>());
        // Known beats unknown.
        let some = pick(n, |i| (i % 10 == 0).then_some(0.0));
        for known in [0, 10, 20, 30] {
            assert!(some.contains(&known), "{some:?}");
        }
        assert_eq!(some.len(), MAX_SERIES_PER_VIEW);
        assert_eq!(some[..9], [0, 1, 2, 3, 4, 5, 6, 7, 8]);
    }

    #[test]
    fn the_bus_pages_hold_whole_groups_and_at_most_a_dozen_series() {
        for n in [9, 20, 35, 100, 1000] {
            let (nodes, topics) = generated(n);
            let g = of(&nodes, &topics);
            let pages = bus_pages(&g);
            let listed: Vec<usize> = pages.iter().flatten().copied().collect();
            assert_eq!(listed, (0..g.topics.len()).collect::<Vec<_>>(), "{n}");
            for page in &pages {
                let lines: usize = page.iter().map(|&i| g.topics[i].lines()).sum();
                assert!(lines <= MAX_SERIES_PER_VIEW, "{n}: {lines}");
            }
            assert!(pages.len() <= 2, "{n}: {pages:?}");
        }
    }
}
