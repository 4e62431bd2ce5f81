//! A rerun blueprint written with the blueprint archetypes directly.
//!
//! rerun 0.36's Rust blueprint builders (`rerun::blueprint`) cannot set view properties such
//! as a 3D view's camera (`EyeControls3D`) or a plot's y range (`ScalarAxis`), and they give
//! every view and container a random id. This module logs the same archetypes the Python SDK
//! logs (`view/<id>` + `view/<id>/ViewContents` + `view/<id>/<Property>`,
//! `container/<id>`, `viewport`, the panels) into an in-memory blueprint stream, with ids
//! derived from the views' keys, and hands back the messages to send with the recording.

use rerun::external::re_log_types::{BlueprintActivationCommand, LogMsg};
use rerun::external::re_sdk_types::blueprint::archetypes as bp;
use rerun::external::re_sdk_types::blueprint::components as bpc;
use rerun::external::re_sdk_types::datatypes;
use rerun::external::re_sdk_types::SerializedComponentBatch;
use rerun::{AsComponents, RecordingStreamBuilder, RecordingStreamError};

/// A view: its class (`"TimeSeries"`, `"Spatial3D"`, …), title, origin, contents (entity
/// query expressions) and properties (archetypes logged under the view, by short name).
/// A plot's y range and legend corner are also kept as values
/// ([`ViewSpec::y_range`], [`ViewSpec::legend`]): the legend's placement reads and moves them.
pub(crate) struct ViewSpec {
    key: String,
    class: &'static str,
    name: String,
    origin: String,
    contents: Vec<String>,
    properties: Vec<(&'static str, Vec<SerializedComponentBatch>)>,
    y_range: Option<(f64, f64)>,
    legend: Option<bpc::Corner2D>,
    /// Its legend may be hidden where it would cover data ([`ViewSpec::legend_optional`]).
    legend_optional: bool,
}

impl ViewSpec {
    /// A view of `class` titled `name`; `key` (unique in the layout) seeds its id.
    pub(crate) fn new(key: &str, class: &'static str, name: impl Into<String>) -> Self {
        Self {
            key: key.to_string(),
            class,
            name: name.into(),
            origin: "/".to_string(),
            contents: vec!["$origin/**".to_string()],
            properties: Vec::new(),
            y_range: None,
            legend: None,
            legend_optional: false,
        }
    }

    /// The space origin (contents default to its subtree).
    pub(crate) fn origin(mut self, origin: &str) -> Self {
        self.origin = origin.to_string();
        self
    }

    /// Explicit contents: entity paths (exact) or `path/**` (subtree).
    pub(crate) fn contents<S: Into<String>>(
        mut self,
        queries: impl IntoIterator<Item = S>,
    ) -> Self {
        self.contents = queries.into_iter().map(Into::into).collect();
        self
    }

    /// The view's title and its contents' query expressions.
    #[cfg(test)]
    pub(crate) fn title_and_queries(&self) -> (&str, &[String]) {
        (&self.name, &self.contents)
    }

    /// A view property, e.g. `("EyeControls3D", &EyeControls3D::new()…)`; one set before
    /// under the same name is replaced (a view has one of each).
    pub(crate) fn property(mut self, name: &'static str, archetype: &dyn AsComponents) -> Self {
        self.set_property(name, archetype);
        self
    }

    fn set_property(&mut self, name: &'static str, archetype: &dyn AsComponents) {
        self.properties.retain(|(n, _)| *n != name);
        self.properties
            .push((name, archetype.as_serialized_batches()));
    }

    /// A plot's y range, `[lo, hi]` (its `ScalarAxis`).
    pub(crate) fn y_range(mut self, lo: f64, hi: f64) -> Self {
        self.set_y_range(lo, hi);
        self
    }

    /// [`ViewSpec::y_range`], in place.
    pub(crate) fn set_y_range(&mut self, lo: f64, hi: f64) {
        self.y_range = Some((lo, hi));
        let axis = bp::ScalarAxis::new().with_range(rerun::components::Range1D::new(lo, hi));
        self.set_property("ScalarAxis", &axis);
    }

    /// A plot's legend, aligned to `corner` (its `PlotLegend`).
    pub(crate) fn legend(mut self, corner: bpc::Corner2D) -> Self {
        self.set_legend(corner);
        self
    }

    /// [`ViewSpec::legend`], in place.
    pub(crate) fn set_legend(&mut self, corner: bpc::Corner2D) {
        self.legend = Some(corner);
        self.set_property("PlotLegend", &bp::PlotLegend::new().with_corner(corner));
    }

    /// A plot whose legend may be hidden where no place keeps it off the data: its title
    /// names its series, and what its legend adds is written elsewhere (the pole angle's
    /// marks: in `when`).
    pub(crate) fn legend_optional(mut self) -> Self {
        self.legend_optional = true;
        self
    }

    /// Whether its legend may be hidden ([`ViewSpec::legend_optional`]).
    pub(crate) fn is_legend_optional(&self) -> bool {
        self.legend_optional
    }

    /// Hide its legend (kept aligned to its corner, should the viewer show it).
    pub(crate) fn hide_legend(&mut self) {
        let corner = self.legend.unwrap_or_default();
        let legend = bp::PlotLegend::new()
            .with_corner(corner)
            .with_visible(false);
        self.set_property("PlotLegend", &legend);
    }

    /// What a plot's legend placement reads of the view, as set.
    pub(crate) fn plot_parts(&self) -> PlotParts<'_> {
        PlotParts {
            class: self.class,
            contents: &self.contents,
            y_range: self.y_range,
            legend: self.legend,
        }
    }
}

/// A view as legend placement reads it ([`ViewSpec::plot_parts`]).
pub(crate) struct PlotParts<'a> {
    /// The view's class.
    pub class: &'a str,
    /// Its contents' query expressions.
    pub contents: &'a [String],
    /// Its y range, when set.
    pub y_range: Option<(f64, f64)>,
    /// Its legend's corner, when set.
    pub legend: Option<bpc::Corner2D>,
}

/// A node of the layout tree.
pub(crate) enum Item {
    /// A view.
    View(ViewSpec),
    /// Children side by side, with relative widths.
    Horizontal(Vec<(f32, Item)>),
    /// Children stacked, with relative heights.
    Vertical(Vec<(f32, Item)>),
    /// Children as tabs, one shown at a time: each with its tab's title (a container's
    /// display name; a view's tab shows the view's own), and the index of the one open.
    Tabs(Vec<(String, Item)>, usize),
}

impl Item {
    /// The views in the tree, depth first.
    #[cfg(test)]
    pub(crate) fn views(&self) -> Vec<&ViewSpec> {
        match self {
            Item::View(v) => vec![v],
            Item::Horizontal(c) | Item::Vertical(c) => {
                c.iter().flat_map(|(_, i)| i.views()).collect()
            }
            Item::Tabs(c, _) => c.iter().flat_map(|(_, i)| i.views()).collect(),
        }
    }

    fn key(&self) -> String {
        let join = |keys: Vec<String>| keys.join(",");
        match self {
            Item::View(v) => format!("view:{}", v.key),
            Item::Horizontal(c) | Item::Vertical(c) => {
                format!(
                    "container:{}",
                    join(c.iter().map(|(_, i)| i.key()).collect())
                )
            }
            Item::Tabs(c, _) => {
                format!("tabs:{}", join(c.iter().map(|(_, i)| i.key()).collect()))
            }
        }
    }

    fn path(&self) -> String {
        match self {
            Item::View(_) => format!("view/{}", uuid_string(&self.key())),
            _ => format!("container/{}", uuid_string(&self.key())),
        }
    }
}

/// 16 bytes derived from `key` (two FNV-1a hashes), with the version-4/variant bits set so
/// that they read as an ordinary UUID.
fn uuid_bytes(key: &str) -> [u8; 16] {
    let fnv = |seed: u64| {
        key.bytes().fold(seed, |h, b| {
            (h ^ u64::from(b)).wrapping_mul(0x0000_0100_0000_01b3)
        })
    };
    let mut bytes = [0u8; 16];
    bytes[..8].copy_from_slice(&fnv(0xcbf2_9ce4_8422_2325).to_be_bytes());
    bytes[8..].copy_from_slice(&fnv(0x84222325_cbf29ce4).to_be_bytes());
    bytes[6] = (bytes[6] & 0x0f) | 0x40;
    bytes[8] = (bytes[8] & 0x3f) | 0x80;
    bytes
}

fn uuid_string(key: &str) -> String {
    let b = uuid_bytes(key);
    let hex: String = b.iter().map(|x| format!("{x:02x}")).collect();
    format!(
        "{}-{}-{}-{}-{}",
        &hex[0..8],
        &hex[8..12],
        &hex[12..16],
        &hex[16..20],
        &hex[20..32]
    )
}

/// Log `item` (and its children); `name`, a container's display name (a tab's title).
fn log_item(
    stream: &rerun::RecordingStream,
    item: &Item,
    name: Option<&str>,
) -> Result<(), RecordingStreamError> {
    match item {
        Item::View(v) => {
            let path = item.path();
            stream.log(
                format!("{path}/ViewContents"),
                &bp::ViewContents::new(
                    v.contents
                        .iter()
                        .map(|q| bpc::QueryExpression(q.as_str().into())),
                ),
            )?;
            stream.log(
                path.as_str(),
                &bp::ViewBlueprint::new(bpc::ViewClass(v.class.into()))
                    .with_display_name(v.name.as_str())
                    .with_space_origin(v.origin.as_str()),
            )?;
            for (name, batches) in &v.properties {
                stream.log_serialized_batches(
                    format!("{path}/{name}"),
                    false,
                    batches.iter().cloned(),
                )?;
            }
            Ok(())
        }
        Item::Tabs(children, active) => {
            for (title, child) in children {
                log_item(stream, child, Some(title))?;
            }
            let mut arch = bp::ContainerBlueprint::new(bpc::ContainerKind::Tabs).with_contents(
                children
                    .iter()
                    .map(|(_, c)| bpc::IncludedContent(c.path().as_str().into())),
            );
            if let Some((_, open)) = children.get(*active) {
                arch = arch.with_active_tab(open.path().as_str());
            }
            if let Some(name) = name {
                arch = arch.with_display_name(name);
            }
            stream.log(item.path(), &arch)
        }
        Item::Horizontal(children) | Item::Vertical(children) => {
            for (_, child) in children {
                log_item(stream, child, None)?;
            }
            let (kind, shares) = match item {
                Item::Horizontal(_) => (bpc::ContainerKind::Horizontal, true),
                _ => (bpc::ContainerKind::Vertical, false),
            };
            let mut arch = bp::ContainerBlueprint::new(kind).with_contents(
                children
                    .iter()
                    .map(|(_, c)| bpc::IncludedContent(c.path().as_str().into())),
            );
            let share_values = children.iter().map(|(s, _)| datatypes::Float32(*s));
            arch = if shares {
                arch.with_col_shares(share_values.map(bpc::ColumnShare))
            } else {
                arch.with_row_shares(share_values.map(bpc::RowShare))
            };
            if let Some(name) = name {
                arch = arch.with_display_name(name);
            }
            stream.log(item.path(), &arch)
        }
    }
}

/// The viewer's id for the hidden view whose time axis every plot linked with
/// `LinkAxis::LinkToGlobal` reads (`re_viewer_context::GLOBAL_VIEW_ID` in rerun 0.36, not
/// exposed by the SDK: `re_view_time_series`'s `view_class.rs` reads that view's `TimeAxis`
/// for a linked plot, ignoring the plot's own range). Pinned with rerun itself.
const GLOBAL_VIEW_UUID: &str = "5c0dca6a-e63f-9cf7-f657-2602590474cc";

/// The blueprint messages for `root` (a container) and the command that activates them.
/// `blueprint_id`, when given, makes the blueprint store's id deterministic. The panels
/// around the views are folded away (blueprint and selection hidden, time panel collapsed on
/// `timeline`, following the newest data), so the views get the window. `time_axis_ns`, when
/// given, is the range `[start, end]` (ns on `timeline`) the linked time axes show: the
/// viewer centres each tick's label on its tick, so a range ending at the run's last instant
/// cuts the last label in half ("+1" for "+10s"); a little room each side shows it whole.
pub(crate) fn blueprint_messages(
    app_id: &'static str,
    blueprint_id: Option<String>,
    root: &Item,
    timeline: &str,
    time_axis_ns: Option<(i64, i64)>,
) -> Result<(Vec<LogMsg>, BlueprintActivationCommand), String> {
    let msgs = blueprint_stream(app_id, blueprint_id, root, timeline, time_axis_ns)
        .map_err(|e| e.to_string())?;
    let blueprint_id = msgs
        .iter()
        .find_map(|m| match m {
            LogMsg::SetStoreInfo(info) => Some(info.info.store_id.clone()),
            _ => None,
        })
        .ok_or_else(|| "the blueprint stream wrote no store info".to_string())?;
    let activate = BlueprintActivationCommand {
        blueprint_id,
        make_active: true,
        make_default: true,
    };
    Ok((msgs, activate))
}

fn blueprint_stream(
    app_id: &'static str,
    blueprint_id: Option<String>,
    root: &Item,
    timeline: &str,
    time_axis_ns: Option<(i64, i64)>,
) -> Result<Vec<LogMsg>, RecordingStreamError> {
    let mut builder = RecordingStreamBuilder::new(app_id).blueprint();
    if let Some(id) = blueprint_id {
        builder = builder.recording_id(id);
    }
    let (stream, storage) = builder.memory()?;
    // The viewer identifies blueprint data by this timeline.
    stream.set_time_sequence("blueprint", 0);
    log_item(&stream, root, None)?;
    if let Some((start, end)) = time_axis_ns {
        stream.log(
            format!("view/{GLOBAL_VIEW_UUID}/TimeAxis"),
            &bp::TimeAxis::new().with_view_range(bpc::TimeRange(datatypes::TimeRange {
                start: datatypes::TimeRangeBoundary::Absolute(datatypes::TimeInt(start)),
                end: datatypes::TimeRangeBoundary::Absolute(datatypes::TimeInt(end)),
            })),
        )?;
    }
    stream.log(
        "viewport",
        &bp::ViewportBlueprint::new()
            .with_root_container(bpc::RootContainer(datatypes::Uuid {
                bytes: uuid_bytes(&root.key()),
            }))
            .with_auto_layout(false)
            .with_auto_views(false),
    )?;
    stream.log(
        "blueprint_panel",
        &bp::PanelBlueprint::new().with_state(bpc::PanelState::Hidden),
    )?;
    stream.log(
        "selection_panel",
        &bp::PanelBlueprint::new().with_state(bpc::PanelState::Hidden),
    )?;
    stream.log(
        "time_panel",
        &bp::TimePanelBlueprint::new()
            .with_state(bpc::PanelState::Collapsed)
            .with_timeline(timeline),
    )?;
    stream.log_static(
        "time_panel",
        &bp::TimePanelBlueprint::new().with_play_state(bpc::PlayState::Following),
    )?;
    Ok(storage.take())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ids_are_stable_distinct_uuids() {
        let a = uuid_string("view:pole angle");
        assert_eq!(a, uuid_string("view:pole angle"));
        assert_ne!(a, uuid_string("view:latency"));
        assert_eq!(a.len(), 36);
        assert_eq!(&a[14..15], "4", "{a}");
    }

    #[test]
    fn a_property_set_again_replaces_the_first() {
        use rerun::external::re_sdk_types::blueprint::{
            archetypes::PlotLegend, components::Corner2D,
        };
        let v = ViewSpec::new("k", "TimeSeries", "plot")
            .property(
                "PlotLegend",
                &PlotLegend::new().with_corner(Corner2D::RightTop),
            )
            .property(
                "PlotLegend",
                &PlotLegend::new().with_corner(Corner2D::LeftTop),
            );
        let legends: Vec<_> = v
            .properties
            .iter()
            .filter(|(n, _)| *n == "PlotLegend")
            .collect();
        assert_eq!(legends.len(), 1, "one legend per view");
        let left = PlotLegend::new()
            .with_corner(Corner2D::LeftTop)
            .as_serialized_batches();
        assert_eq!(
            format!("{:?}", legends[0].1),
            format!("{left:?}"),
            "the later one"
        );
    }
}
