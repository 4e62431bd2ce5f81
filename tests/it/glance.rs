//! The recording reads at a glance (#54): each recording's blueprint read as the viewer lays
//! it out, and its data, checked for what a reviewer needs at once:
//! - every recorded series is in some view;
//! - no plot is shorter than [`MIN_PLOT_PX`] in a 1280×720 window (heights from the
//!   layout's shares, tab bars and title bars), and each labels its y axis there;
//! - every node and topic has one colour in every view (its series and its box in the node
//!   graph; nodes told apart), and every legend names its series in words, not paths;
//! - every event is listed in the `when` document at its run time, and every mark on the
//!   pole-angle plot is an event, every warning marked.
//!
//! [`check_at_a_glance`] runs from `recording::check_views`, so every recording test (the
//! chapter's, a fall, QoS, executors, the real clock, mid-run changes and brain swaps as a
//! lab session makes them, a launch across processes) checks it; the test here adds every
//! shipped graph.

use crate::recording::{active_blueprint, chunks};
use re_chunk::Chunk;
use rerun::external::re_sdk_types::blueprint::archetypes as bp;
use rerun::external::re_sdk_types::blueprint::components as bpc;
use std::collections::{BTreeMap, BTreeSet};
use std::path::Path;

/// Height of the viewer's area for views in a 1280×720 window: the window less the top bar
/// (about 34 px) and the collapsed time panel (about 40 px), as the pictures show them.
const VIEWS_PX: f32 = 720.0 - 34.0 - 40.0;
/// A view's title bar, and a tab container's bar of tabs.
const BAR_PX: f32 = 24.0;
/// The least height of a plot (below its title bar) that labels its y axis past "0" and
/// keeps its legend off most of its data.
pub(crate) const MIN_PLOT_PX: f32 = 100.0;

/// A container of the blueprint: its kind (`Horizontal`, `Vertical`, `Tabs`), its contents
/// (`view/<id>` or `container/<id>` paths) and their shares.
#[derive(Debug, Default)]
struct Container {
    kind: String,
    contents: Vec<String>,
    shares: Vec<f32>,
}

/// A view of the blueprint: class, name and y range (a time series' `ScalarAxis`).
#[derive(Debug, Default, Clone)]
pub(crate) struct View {
    pub class: String,
    pub name: String,
    pub y_range: Option<[f64; 2]>,
}

/// The active blueprint's containers and views (by path).
fn tree(path: &Path) -> (BTreeMap<String, Container>, BTreeMap<String, View>) {
    let mut containers: BTreeMap<String, Container> = BTreeMap::new();
    let mut views: BTreeMap<String, View> = BTreeMap::new();
    let strings = |c: &Chunk, component| -> Vec<String> {
        c.iter_slices::<String>(component)
            .flatten()
            .map(|s| s.as_str().to_string())
            .collect()
    };
    for c in active_blueprint(path) {
        let entity = c.entity_path().to_string();
        let key = entity.trim_start_matches('/').to_string();
        let parts: Vec<&str> = key.split('/').collect();
        match parts.as_slice() {
            ["container", _] => {
                let k = containers.entry(key.clone()).or_default();
                let kind = bp::ContainerBlueprint::descriptor_container_kind().component;
                if let Some(kind) = c
                    .iter_component::<bpc::ContainerKind>(kind)
                    .flat_map(|b| b.to_vec())
                    .last()
                {
                    k.kind = format!("{kind:?}");
                }
                let contents = bp::ContainerBlueprint::descriptor_contents().component;
                let found = strings(&c, contents);
                if !found.is_empty() {
                    k.contents = found
                        .iter()
                        .map(|p| p.trim_start_matches('/').to_string())
                        .collect();
                }
                for shares in [
                    bp::ContainerBlueprint::descriptor_row_shares().component,
                    bp::ContainerBlueprint::descriptor_col_shares().component,
                ] {
                    let s: Vec<f32> = c.iter_slices::<f32>(shares).flatten().copied().collect();
                    if !s.is_empty() {
                        k.shares = s;
                    }
                }
            }
            ["view", _] => {
                let class = strings(
                    &c,
                    bp::ViewBlueprint::descriptor_class_identifier().component,
                );
                let name = strings(&c, bp::ViewBlueprint::descriptor_display_name().component);
                let v = views.entry(key.clone()).or_default();
                if let Some(class) = class.last() {
                    v.class = class.clone();
                }
                if let Some(name) = name.last() {
                    v.name = name.clone();
                }
            }
            ["view", id, "ScalarAxis"] => {
                let range = bp::ScalarAxis::descriptor_range().component;
                if let Some(r) = c
                    .iter_component::<rerun::components::Range1D>(range)
                    .flat_map(|b| b.to_vec())
                    .last()
                {
                    views.entry(format!("view/{id}")).or_default().y_range = Some(r.0 .0);
                }
            }
            _ => {}
        }
    }
    (containers, views)
}

/// Each view's height below its title bar (px) in a 1280×720 window.
pub(crate) fn view_heights(path: &Path) -> Vec<(View, f32)> {
    let (containers, views) = tree(path);
    let inside: BTreeSet<&String> = containers.values().flat_map(|c| &c.contents).collect();
    let roots: Vec<&String> = containers.keys().filter(|k| !inside.contains(k)).collect();
    assert_eq!(roots.len(), 1, "one root container: {roots:?}");
    let mut out = Vec::new();
    let mut stack = vec![(roots[0].clone(), VIEWS_PX)];
    while let Some((key, px)) = stack.pop() {
        if let Some(view) = views.get(&key) {
            out.push((view.clone(), px - BAR_PX));
            continue;
        }
        let c = containers
            .get(&key)
            .unwrap_or_else(|| panic!("{key} is neither a view nor a container"));
        let total: f32 = c.shares.iter().sum();
        for (i, child) in c.contents.iter().enumerate() {
            let h = match c.kind.as_str() {
                "Vertical" => px * c.shares.get(i).copied().unwrap_or(1.0) / total.max(1e-6),
                "Tabs" => px - BAR_PX,
                _ => px,
            };
            stack.push((child.clone(), h));
        }
    }
    out
}

/// Whether a plot `px` tall (below its title) with the y range `[lo, hi]` gets a label
/// other than "0" in the stock viewer: some power of ten inside the range, its steps at
/// least [`LABEL_STEP_PX`] apart in the plot's area (its height less the time axis's labels,
/// about 20 px).
fn y_labelled(px: f32, [lo, hi]: [f64; 2]) -> bool {
    let area = f64::from(px - 20.0);
    let span = hi - lo;
    (-12..=12).any(|k| {
        let step = 10f64.powi(k);
        step <= hi.max(-lo) && area * step / span >= LABEL_STEP_PX
    })
}

/// The spacing of a power-of-ten step the stock viewer labels: 5.16 steps in a plot of 95
/// points were labelled, 6 in 100 were not (pictures at 1280×720).
const LABEL_STEP_PX: f64 = 18.0;

/// The last static colour of `entity`'s series style (lines or points), and its name.
fn style(all: &[Chunk], entity: &str) -> Option<(u32, String)> {
    let mut found = None;
    for c in all.iter().filter(|c| c.entity_path().to_string() == entity) {
        for (colors, names) in [
            (
                rerun::SeriesLines::descriptor_colors().component,
                rerun::SeriesLines::descriptor_names().component,
            ),
            (
                rerun::SeriesPoints::descriptor_colors().component,
                rerun::SeriesPoints::descriptor_names().component,
            ),
        ] {
            let color = c.iter_slices::<u32>(colors).flat_map(|s| s.to_vec()).last();
            let name = c
                .iter_slices::<String>(names)
                .flatten()
                .map(|s| s.as_str().to_string())
                .last();
            if let (Some(color), Some(name)) = (color, name) {
                found = Some((color, name));
            }
        }
    }
    found
}

/// The node graph's boxes: id → colour (the last drawing).
fn graph_colors(all: &[Chunk]) -> BTreeMap<String, u32> {
    let mut out = BTreeMap::new();
    for c in all
        .iter()
        .filter(|c| c.entity_path().to_string() == "/graph")
    {
        let ids: Vec<Vec<String>> = c
            .iter_slices::<String>(rerun::GraphNodes::descriptor_node_ids().component)
            .map(|s| s.into_iter().map(|x| x.as_str().to_string()).collect())
            .collect();
        let colors: Vec<Vec<u32>> = c
            .iter_slices::<u32>(rerun::GraphNodes::descriptor_colors().component)
            .map(|s| s.to_vec())
            .collect();
        for (ids, colors) in ids.iter().zip(&colors) {
            for (id, color) in ids.iter().zip(colors) {
                out.insert(id.clone(), *color);
            }
        }
    }
    out
}

/// Every row of the `events` log: (run time ns, level, text).
fn event_rows(all: &[Chunk]) -> Vec<(i64, String, String)> {
    let mut out = Vec::new();
    for c in all
        .iter()
        .filter(|c| c.entity_path().to_string() == "/events")
    {
        let times = run_times(c);
        // One string per row.
        let per_row = |component| -> Vec<String> {
            c.iter_slices::<String>(component)
                .map(|s| s.iter().map(|x| x.as_str()).collect::<String>())
                .collect()
        };
        let texts = per_row(rerun::TextLog::descriptor_text().component);
        let levels = per_row(rerun::TextLog::descriptor_level().component);
        for ((t, text), level) in times.iter().zip(texts).zip(levels) {
            out.push((*t, level, text));
        }
    }
    out
}

/// A chunk's times on the run's timeline (`sim_time` or `wall_time`).
fn run_times(c: &Chunk) -> Vec<i64> {
    c.timelines()
        .iter()
        .find(|(name, _)| ["sim_time", "wall_time"].contains(&name.as_str()))
        .map(|(_, t)| t.times_raw().to_vec())
        .unwrap_or_default()
}

/// The times (ns) a mark series was set.
fn mark_times(all: &[Chunk], entity: &str) -> BTreeSet<i64> {
    all.iter()
        .filter(|c| !c.is_static() && c.entity_path().to_string() == entity)
        .flat_map(run_times)
        .collect()
}

/// The last `when` document, its markdown escapes removed.
fn when_document(all: &[Chunk]) -> String {
    all.iter()
        .filter(|c| c.entity_path().to_string() == "/when")
        .flat_map(|c| {
            c.iter_slices::<String>(rerun::TextDocument::descriptor_text().component)
                .flatten()
                .map(|s| s.as_str().to_string())
                .collect::<Vec<_>>()
        })
        .last()
        .expect("a `when` document")
        .replace('\\', "")
}

/// Check everything the module's header lists for the recording at `path`; `queries`, the
/// views' entity queries (exact paths and `…/**`).
pub(crate) fn check_at_a_glance(path: &Path, queries: &[String]) {
    let all = chunks(path);
    // Every recorded series is in some view.
    let scalars: BTreeSet<String> = all
        .iter()
        .filter(|c| {
            c.component_descriptors()
                .any(|d| d.component.as_str() == "Scalars:scalars")
        })
        .map(|c| c.entity_path().to_string())
        .collect();
    let unseen: Vec<&String> = scalars.iter().filter(|e| !queries.contains(e)).collect();
    assert!(unseen.is_empty(), "recorded but in no view: {unseen:?}");
    // Every plot tall enough at 1280×720.
    for (v, px) in view_heights(path) {
        if v.class == "TimeSeries" {
            assert!(
                px >= MIN_PLOT_PX,
                "{:?} is {px:.0} px tall at 1280x720 (< {MIN_PLOT_PX})",
                v.name
            );
            let range = v
                .y_range
                .unwrap_or_else(|| panic!("{:?}: no y range", v.name));
            assert!(
                y_labelled(px, range),
                "{:?}: {range:?} in {px:.0} px labels \"0\" alone at 1280x720",
                v.name
            );
        }
    }
    // One colour per node and per topic, in every view; legends in words.
    let boxes = graph_colors(&all);
    let mut node_colors: BTreeMap<String, u32> = BTreeMap::new();
    for e in &scalars {
        let (color, name) = style(&all, e).unwrap_or_else(|| panic!("{e} has no style"));
        assert!(
            !name.contains('_') && !name.is_empty(),
            "{e}: its legend reads {name:?}, a path rather than words"
        );
        let parts: Vec<&str> = e.trim_start_matches('/').split('/').collect();
        let owner = match parts.as_slice() {
            ["nodes", node, _] => Some((node.to_string(), true)),
            ["bus", topic, series]
                if ["published", "dropped", "msg_per_s", "wire_p50_us"].contains(series) =>
            {
                Some((format!("/{topic}"), false))
            }
            _ => None,
        };
        if let Some((id, is_node)) = owner {
            // A topic's entity flattens its name (`/a/b` → `a_b`): its box is found by it.
            let shown = boxes
                .iter()
                .find(|(b, _)| *b == &id || b.trim_start_matches('/').replace('/', "_") == id[1..])
                .map(|(_, c)| *c);
            assert_eq!(shown, Some(color), "{e}: not the colour of {id}'s box");
            if is_node {
                node_colors.insert(id, color);
            }
        }
    }
    let mut distinct: Vec<u32> = node_colors.values().copied().collect();
    distinct.sort_unstable();
    distinct.dedup();
    assert_eq!(
        distinct.len(),
        node_colors.len(),
        "nodes share a colour: {node_colors:?}"
    );
    // Every event at its time in `when`; every mark an event; every warning marked.
    let doc = when_document(&all);
    let rows = event_rows(&all);
    for (t, _, text) in &rows {
        let line = format!("{:.3} s", *t as f64 / 1e9);
        assert!(
            doc.lines()
                .any(|l| l.contains(&line) && l.contains(text.as_str())),
            "{text:?} at {line} is not in `when`:\n{doc}"
        );
    }
    let marks: Vec<(&str, BTreeSet<i64>)> = [
        "/marks/change",
        "/marks/trouble",
        "/marks/recovery",
        "/plant/fall",
    ]
    .iter()
    .map(|m| (*m, mark_times(&all, m)))
    .collect();
    for (entity, times) in &marks {
        for t in times {
            assert!(
                rows.iter().any(|(at, _, _)| at == t),
                "{entity} at {t} ns has no event"
            );
        }
        if !times.is_empty() {
            assert!(
                queries.contains(&entity.to_string()),
                "{entity} is in no view"
            );
        }
    }
    let marked: BTreeSet<i64> = marks.iter().flat_map(|(_, t)| t.iter().copied()).collect();
    for (t, level, text) in &rows {
        // A total said at the end counts what was marked where it happened.
        let total = text.contains("in all") && !text.starts_with("deadline");
        if level != "INFO" && !total && !text.starts_with("end:") {
            assert!(
                marked.contains(t),
                "the warning {text:?} at {t} ns is not marked"
            );
        }
    }
}

/// Every shipped graph's recording reads at a glance (the checks above), 3 s of each under
/// the virtual clock.
#[test]
fn every_shipped_graph_s_recording_reads_at_a_glance() {
    ratelab::init(); // the Python graphs' nodes, as the command line runs them
    let dir = tempfile::tempdir().unwrap();
    let mut seen = 0;
    for entry in std::fs::read_dir(crate::repo("graphs")).unwrap() {
        let file = entry.unwrap().path();
        if file.extension().is_none_or(|e| e != "toml") {
            continue;
        }
        let graph = ratelab::graph::GraphSpec::load(&file).unwrap();
        // A graph whose nodes run in another program (ROS 2) records no steps here; the
        // PPO graph needs weights exported from the course's checkpoint first (its own
        // tests do that).
        let name = file.file_stem().unwrap().to_string_lossy().to_string();
        if graph.first_external().is_some() || name == "cartpole-ppo-numpy" {
            continue;
        }
        let cfg = ratelab::RunConfig {
            graph,
            ..crate::recording::virtual_cfg().with_duration_ms(3000)
        };
        let path = dir.path().join(format!("{name}.rrd"));
        crate::recording::record(&path, &cfg, None);
        eprintln!("checking {name}");
        crate::recording::check_views(&path);
        seen += 1;
    }
    assert!(seen >= 10, "{seen} graphs");
}
