//! Where each plot's legend goes in the final layout, so that it covers none of the plot's
//! data at 1280×720 (rerun 0.36.3's `PlotLegend` has a corner and a visibility, no size and
//! no place outside the plot).
//!
//! While the run goes, every scalar series' values are kept coarsely in time ([`Seen`]: per
//! series, the smallest and largest value in each of at most [`BUCKETS`] spans of run time,
//! the spans doubled as the run outgrows them), with the name its legend row shows. When the
//! run is over, each plot's legend is sized as the viewer draws it (a row per name, as wide
//! as its longest name: [`LegendSize`]) in the plot's size at 1280×720 ([`place_legends`]
//! walks the layout's shares), and placed by [`place`]'s rules:
//! 1. in the first corner, the plot's own first, where no series has a value (a line counts
//!    over the stretch it is drawn across, from one sample to the next);
//! 2. else with the y range widened at the top or the bottom so that the legend sits in a
//!    band past every value under it, the least widening first, as long as the range still
//!    labels its axis at that size (a step of a power of ten at least 18 px apart, at most 7
//!    of them across, as the viewer does and `tests/it/glance.rs` checks) and the legend
//!    takes at most [`MAX_LEGEND_SHARE`] of the height;
//! 3. else, for a plot whose legend is optional (its title names its series, and what its
//!    legend adds is written elsewhere: the pole angle's marks, in `when`), hidden; for
//!    any other, in the corner its data enter least.
//!
//! Reference lines (the fall limits, the rail's ends, the run's ends: constants drawn across
//! the plot, each named in the legend) are not data a legend can hide: a stretch of one
//! passes behind it.

use super::layout::{Item, ViewSpec};
use super::*;

/// The most spans of run time a series' values are kept in.
pub(super) const BUCKETS: usize = 64;

/// The first span's length: 64 of them cover 6.4 s; a longer run doubles it as needed.
const FIRST_WIDTH_NS: u64 = 100_000_000;

/// Where one series' values lay in run time: per span of `width_ns` from t = 0, the
/// smallest and largest value (an empty span: `lo > hi`).
#[derive(Clone, Debug, PartialEq)]
pub(super) struct Occupancy {
    width_ns: u64,
    spans: Vec<(f64, f64)>,
}

const EMPTY: (f64, f64) = (f64::INFINITY, f64::NEG_INFINITY);

fn merge(a: (f64, f64), b: (f64, f64)) -> (f64, f64) {
    (a.0.min(b.0), a.1.max(b.1))
}

/// Whether a span holds a value (an empty one is [`EMPTY`]).
fn filled(s: &(f64, f64)) -> bool {
    s.0 <= s.1
}

impl Default for Occupancy {
    fn default() -> Self {
        Occupancy {
            width_ns: FIRST_WIDTH_NS,
            spans: Vec::new(),
        }
    }
}

impl Occupancy {
    /// A series known only by its extent, `[lo, hi]` over the whole run (one logged outside
    /// the gathered rows: the real clock's lateness).
    pub(super) fn whole(lo: f64, hi: f64) -> Occupancy {
        Occupancy {
            width_ns: u64::MAX,
            spans: vec![(lo, hi)],
        }
    }

    /// Value `v` at run time `t` (a value that is not finite is drawn nowhere).
    pub(super) fn add(&mut self, t: Nanos, v: f64) {
        if !v.is_finite() {
            return;
        }
        let mut i = t.0 / self.width_ns;
        while i >= BUCKETS as u64 {
            self.spans = self
                .spans
                .chunks(2)
                .map(|p| p.iter().copied().fold(EMPTY, merge))
                .collect();
            self.width_ns = self.width_ns.saturating_mul(2);
            i = t.0 / self.width_ns;
        }
        let i = i as usize;
        if self.spans.len() <= i {
            self.spans.resize(i + 1, EMPTY);
        }
        self.spans[i] = merge(self.spans[i], (v, v));
    }

    /// The smallest and largest value drawn over run times `[from, to]` (ns), if any: the
    /// spans that meet it, and where a line passes through it from a sample before to one
    /// after (or inside), the spans of those samples.
    pub(super) fn within(&self, from: i64, to: i64) -> Option<(f64, f64)> {
        let w = i128::from(self.width_ns);
        let first = (i128::from(from).max(0) / w) as usize;
        let last = (i128::from(to).max(0) / w) as usize;
        if to < 0 || self.spans.is_empty() {
            return None;
        }
        let inside = self
            .spans
            .iter()
            .enumerate()
            .filter(|(i, s)| (first..=last).contains(i) && filled(s))
            .fold(EMPTY, |acc, (_, s)| merge(acc, *s));
        let before = self.spans[..first.min(self.spans.len())]
            .iter()
            .rev()
            .find(|s| filled(s));
        let after = self
            .spans
            .get(last + 1..)
            .and_then(|rest| rest.iter().find(|s| filled(s)));
        let any_inside = filled(&inside);
        let mut out = inside;
        if let Some(b) = before.filter(|_| any_inside || after.is_some()) {
            out = merge(out, *b);
        }
        if let Some(a) = after.filter(|_| any_inside || before.is_some()) {
            out = merge(out, *a);
        }
        filled(&out).then_some(out)
    }
}

/// What the legends' placement knows of the series so far: where each took its values
/// ([`Occupancy`]) and the name its legend row shows, by entity path (no leading `/`).
#[derive(Clone, Debug, Default)]
pub(super) struct Seen {
    occupancy: BTreeMap<String, Occupancy>,
    names: BTreeMap<String, String>,
}

impl Seen {
    /// Series `entity` took `value` at run time `t`.
    pub(super) fn occupy(&mut self, entity: &str, t: Nanos, value: f64) {
        match self.occupancy.get_mut(entity) {
            Some(o) => o.add(t, value),
            None => {
                let mut o = Occupancy::default();
                o.add(t, value);
                self.occupancy.insert(entity.to_string(), o);
            }
        }
    }

    /// Series `entity` is named `name` in its plot's legend.
    pub(super) fn name(&mut self, entity: &str, name: &str) {
        if self.names.get(entity).is_none_or(|n| n != name) {
            self.names.insert(entity.to_string(), name.to_string());
        }
    }
}

/// A legend's size as the viewer draws it at 1280×720: a row of [`ROW_PX`] per name and
/// [`FRAME_PX`] around, [`CHAR_PX`] per character of its longest name and [`SWATCH_PX`]
/// beside it. Estimated from the stock viewer's default text (about 12.5 points).
#[derive(Clone, Copy, Debug, PartialEq)]
pub(super) struct LegendSize {
    /// Its rows (distinct names).
    pub rows: usize,
    /// The characters of its longest name.
    pub chars: usize,
}

/// A legend row's height, px.
const ROW_PX: f32 = 18.0;
/// The legend's frame, top and bottom together (and its gap to the plot's edge), px.
const FRAME_PX: f32 = 12.0;
/// A character of a legend's text, px (on average).
const CHAR_PX: f32 = 7.0;
/// A row's swatch, its gap to the text, and the frame left and right, px.
const SWATCH_PX: f32 = 34.0;

impl LegendSize {
    fn px(self) -> (f32, f32) {
        (
            self.chars as f32 * CHAR_PX + SWATCH_PX,
            self.rows as f32 * ROW_PX + FRAME_PX,
        )
    }
}

/// The most of a plot's height a legend may take in a band of its own (step 2 of the
/// module's rules): the data keep the rest.
pub(super) const MAX_LEGEND_SHARE: f64 = 0.45;

/// A plot as the rules see it: its drawing area at 1280×720 (px, without its title and
/// its axes' labels), its time range (ns) and its y range.
#[derive(Clone, Copy, Debug)]
pub(super) struct PlotArea {
    /// Width and height, px.
    pub px: (f32, f32),
    /// The time range shown, ns.
    pub x: (i64, i64),
    /// The y range shown.
    pub y: (f64, f64),
}

/// Whether the stock viewer labels a y axis `[lo, hi]` drawn `px` tall past "0": a step of
/// a power of ten within the range, at least 18 px apart and at most 7 across.
pub(super) fn labelled(px: f32, (lo, hi): (f64, f64)) -> bool {
    let span = hi - lo;
    span > 0.0
        && (-12..=12).any(|k| {
            let step = 10f64.powi(k);
            step <= hi.max(-lo) && span / step <= 7.0 && f64::from(px) * step / span >= 18.0
        })
}

const CORNERS: [bpc::Corner2D; 4] = [
    bpc::Corner2D::LeftTop,
    bpc::Corner2D::RightTop,
    bpc::Corner2D::RightBottom,
    bpc::Corner2D::LeftBottom,
];

fn is_top(c: bpc::Corner2D) -> bool {
    matches!(c, bpc::Corner2D::LeftTop | bpc::Corner2D::RightTop)
}

fn is_left(c: bpc::Corner2D) -> bool {
    matches!(c, bpc::Corner2D::LeftTop | bpc::Corner2D::LeftBottom)
}

/// The run times a legend in `corner` spans, its width being `share` of the plot's.
fn time_span(area: &PlotArea, corner: bpc::Corner2D, share: f64) -> (i64, i64) {
    let (x0, x1) = area.x;
    let w = ((x1 - x0) as f64 * share.min(1.0)) as i64;
    if is_left(corner) {
        (x0, x0.saturating_add(w))
    } else {
        (x1.saturating_sub(w), x1)
    }
}

/// The values a legend in `corner` spans in `y`, its height being `share` of the plot's.
fn value_span(y: (f64, f64), corner: bpc::Corner2D, share: f64) -> (f64, f64) {
    let h = (y.1 - y.0) * share.min(1.0);
    if is_top(corner) {
        (y.1 - h, y.1)
    } else {
        (y.0, y.0 + h)
    }
}

/// Where a legend goes ([`place`]).
#[derive(Clone, Copy, Debug, PartialEq)]
pub(super) struct Placed {
    /// Its corner.
    pub corner: bpc::Corner2D,
    /// The y range the plot then shows: widened for a band of its own, or as it was.
    pub y: (f64, f64),
    /// Whether it is shown (an optional legend with no place off the data is not).
    pub shown: bool,
}

/// Where the legend goes (module docs). `series`: the plot's data, each as
/// [`Occupancy`]; `prefer`: the plot's own corner, tried first; `optional`: it may be
/// hidden.
pub(super) fn place(
    area: &PlotArea,
    size: LegendSize,
    series: &[&Occupancy],
    prefer: bpc::Corner2D,
    optional: bool,
) -> Placed {
    let placed = |corner, y, shown| Placed { corner, y, shown };
    let (w_px, h_px) = size.px();
    let (w_share, h_share) = (
        f64::from(w_px / area.px.0.max(1.0)),
        f64::from(h_px / area.px.1.max(1.0)),
    );
    let order: Vec<bpc::Corner2D> = std::iter::once(prefer)
        .chain(CORNERS.iter().copied().filter(|c| *c != prefer))
        .collect();
    // The values drawn under a legend in each corner (over its stretch of time).
    let under = |c: bpc::Corner2D| -> Option<(f64, f64)> {
        let (from, to) = time_span(area, c, w_share);
        series
            .iter()
            .filter_map(|o| o.within(from, to))
            .reduce(merge)
    };
    let meets = |c: bpc::Corner2D, y: (f64, f64)| -> bool {
        let (lo, hi) = value_span(y, c, h_share);
        under(c).is_some_and(|(a, b)| a <= hi && b >= lo)
    };
    // 1. A corner where nothing is.
    if h_share < 1.0 {
        if let Some(c) = order.iter().find(|c| !meets(**c, area.y)) {
            return placed(*c, area.y, true);
        }
    }
    // 2. A band of its own, past the values under it.
    let (y0, y1) = area.y;
    let margin = (y1 - y0) * 0.02;
    let band = |c: bpc::Corner2D| -> Option<(f64, f64)> {
        let (lo_d, hi_d) = under(c)?;
        let y = if is_top(c) {
            (y0, ((hi_d + margin) - h_share * y0) / (1.0 - h_share))
        } else {
            (((lo_d - margin) - h_share * y1) / (1.0 - h_share), y1)
        };
        (y.0 <= y0 && y.1 >= y1 && labelled(area.px.1, y)).then_some(y)
    };
    if h_share <= MAX_LEGEND_SHARE {
        let widened = order
            .iter()
            .filter_map(|c| band(*c).map(|y| (*c, y)))
            .min_by(|a, b| (a.1 .1 - a.1 .0).total_cmp(&(b.1 .1 - b.1 .0)));
        if let Some((c, y)) = widened {
            return placed(c, y, true);
        }
    }
    // 3. Hidden, where it may be; else the corner its data enter least (as a share of the
    // legend's height).
    if optional {
        return placed(prefer, area.y, false);
    }
    let depth = |c: bpc::Corner2D| -> f64 {
        let (lo, hi) = value_span(area.y, c, h_share);
        match under(c) {
            Some((a, b)) if a <= hi && b >= lo && hi > lo => {
                let d = if is_top(c) {
                    b.min(hi) - lo
                } else {
                    hi - a.max(lo)
                };
                d / (hi - lo)
            }
            _ => 0.0,
        }
    };
    let best = order
        .iter()
        .copied()
        .min_by(|a, b| depth(*a).total_cmp(&depth(*b)))
        .unwrap_or(prefer);
    placed(best, area.y, true)
}

/// The series of a plot that are reference lines: constants across it (module docs).
fn is_reference(entity: &str) -> bool {
    ["plant/fall_limit/", "plant/rail_end/", "plant/cart_limit/"]
        .iter()
        .any(|r| entity.starts_with(r))
}

/// The width of the area the views share in a 1280×720 window, px.
const VIEWS_W_PX: f32 = 1270.0;
/// Its height: the window less the viewer's top bar and its collapsed time panel, as
/// `tests/it/glance.rs` measures them.
const VIEWS_H_PX: f32 = 720.0 - 34.0 - 40.0;
/// A view's title bar, and a tab container's bar of tabs, px.
const BAR_PX: f32 = 24.0;
/// A plot's time axis labels (under it), px.
const X_LABELS_PX: f32 = 20.0;
/// A plot's y axis labels (left of it), px.
const Y_LABELS_PX: f32 = 45.0;

/// Place every plot's legend in the final layout `root` (module docs): each plot's drawing
/// area at 1280×720 from the layout's shares, its data from `seen` (and, for series logged
/// outside it, `extents`), its time range `x` (ns).
pub(super) fn place_legends(root: &mut Item, seen: &Seen, extents: &Extents, x: (i64, i64)) {
    walk(root, (VIEWS_W_PX, VIEWS_H_PX), &mut |view, (w, h)| {
        let optional = view.is_legend_optional();
        let parts = view.plot_parts();
        let (class, contents, y, corner) =
            (parts.class, parts.contents, parts.y_range, parts.legend);
        let (Some(y), true) = (y, class == "TimeSeries") else {
            return;
        };
        let area = PlotArea {
            px: (w - Y_LABELS_PX, h - BAR_PX - X_LABELS_PX),
            x,
            y,
        };
        let drawn: Vec<&str> = contents
            .iter()
            .map(|q| q.trim_start_matches('/'))
            .filter(|e| extents.contains_key(*e))
            .collect();
        let mut names: Vec<&str> = drawn
            .iter()
            .map(|e| seen.names.get(*e).map_or(*e, String::as_str))
            .collect();
        names.sort_unstable();
        names.dedup();
        let size = LegendSize {
            rows: names.len(),
            chars: names.iter().map(|n| n.chars().count()).max().unwrap_or(0),
        };
        let whole: Vec<Occupancy> = drawn
            .iter()
            .filter(|e| !is_reference(e) && !seen.occupancy.contains_key(**e))
            .filter_map(|e| extents.get(*e).map(|&(lo, hi)| Occupancy::whole(lo, hi)))
            .collect();
        let series: Vec<&Occupancy> = drawn
            .iter()
            .filter(|e| !is_reference(e))
            .filter_map(|e| seen.occupancy.get(*e))
            .chain(whole.iter())
            .collect();
        if size.rows == 0 {
            return;
        }
        let prefer = corner.unwrap_or(bpc::Corner2D::RightTop);
        let placed = place(&area, size, &series, prefer, optional);
        view.set_legend(placed.corner);
        if !placed.shown {
            view.hide_legend();
        }
        if placed.y != y {
            view.set_y_range(placed.y.0, placed.y.1);
        }
    });
}

/// A character of a view's title at 1280×720, px (on average: the stock viewer drew 45
/// characters of a title in 262 px).
#[cfg(test)]
const TITLE_CHAR_PX: f32 = 5.9;
/// What a view's title bar holds beside its title at 1280×720, px: the view kind's icon on
/// the left; on the right its help, visibility and maximize buttons, and the arrow the
/// viewer adds to a title it cuts.
#[cfg(test)]
const TITLE_BAR_ICONS_PX: f32 = 136.0;

/// The views of the layout `root` whose title is cut at 1280×720, each `(title, the
/// title's width, the view's, px)`. A title's detail after ` · ` (how many of a large
/// graph's nodes a plot shows, and which) may be cut; its head may not.
#[cfg(test)]
pub(super) fn cut_titles(root: &mut Item) -> Vec<(String, f32, f32)> {
    let mut cut = Vec::new();
    walk(root, (VIEWS_W_PX, VIEWS_H_PX), &mut |view, (w, _)| {
        let title = view.title_and_queries().0;
        let head = title.split(" · ").next().unwrap_or(title);
        let needs = head.chars().count() as f32 * TITLE_CHAR_PX + TITLE_BAR_ICONS_PX;
        if needs > w {
            cut.push((head.to_string(), needs, w));
        }
    });
    cut
}

/// Call `f` on every view of `item` with its size (width, height, px) in a `px` space,
/// as the viewer lays the shares out (a tab container's bar of tabs taken off its
/// children's height; each view's title bar is the caller's).
fn walk(item: &mut Item, px: (f32, f32), f: &mut dyn FnMut(&mut ViewSpec, (f32, f32))) {
    match item {
        Item::View(v) => f(v, px),
        Item::Horizontal(children) => {
            let total: f32 = children.iter().map(|(s, _)| *s).sum::<f32>().max(1e-6);
            for (share, child) in children.iter_mut() {
                walk(child, (px.0 * *share / total, px.1), f);
            }
        }
        Item::Vertical(children) => {
            let total: f32 = children.iter().map(|(s, _)| *s).sum::<f32>().max(1e-6);
            for (share, child) in children.iter_mut() {
                walk(child, (px.0, px.1 * *share / total), f);
            }
        }
        Item::Tabs(children, _) => {
            for (_, child) in children.iter_mut() {
                walk(child, (px.0, px.1 - BAR_PX), f);
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const S: i64 = 1_000_000_000;

    /// A series through `(t s, value)` points, a sample every 20 ms between them (linear).
    fn series(points: &[(f64, f64)]) -> Occupancy {
        let mut o = Occupancy::default();
        for w in points.windows(2) {
            let ((t0, v0), (t1, v1)) = (w[0], w[1]);
            let n = ((t1 - t0) / 0.02).round() as usize;
            for k in 0..n {
                let f = k as f64 / n as f64;
                o.add(
                    Nanos(((t0 + f * (t1 - t0)) * 1e9) as u64),
                    v0 + f * (v1 - v0),
                );
            }
        }
        if let Some(&(t, v)) = points.last() {
            o.add(Nanos((t * 1e9) as u64), v);
        }
        o
    }

    /// A 10 s run's plot in the middle column (about 440 × 140 px), its time axis padded.
    fn area(y: (f64, f64)) -> PlotArea {
        PlotArea {
            px: (440.0, 140.0),
            x: (-S / 2, 10 * S + S / 2),
            y,
        }
    }

    const TWO_ROWS: LegendSize = LegendSize { rows: 2, chars: 20 };

    #[test]
    fn an_occupancy_keeps_a_run_of_any_length_in_its_buckets() {
        let o = series(&[(0.0, 0.0), (10.0, 1.0)]);
        assert!(o.spans.len() <= BUCKETS);
        assert_eq!(o.width_ns, 200_000_000, "64 × 100 ms doubled once for 10 s");
        let (lo, hi) = o.within(0, S).unwrap();
        assert!(lo >= 0.0 && hi <= 0.15, "{lo}..{hi}");
        // Before the first sample and after the last, nothing is drawn.
        assert_eq!(o.within(-S, -1), None);
        assert_eq!(o.within(11 * S, 12 * S), None);
        // An hour: the buckets grow, never their number.
        let mut long = Occupancy::default();
        for s in 0..3600 {
            long.add(Nanos(s * S as u64), s as f64);
        }
        assert!(long.spans.len() <= BUCKETS);
        assert_eq!(long.within(0, 3600 * S).unwrap(), (0.0, 3599.0));
        // Not finite: drawn nowhere.
        let mut nan = Occupancy::default();
        nan.add(Nanos(0), f64::NAN);
        assert_eq!(nan.within(0, S), None);
    }

    #[test]
    fn a_line_counts_where_it_is_drawn_between_samples() {
        // Two samples 6 s apart (a gap with none): the line between them crosses 2..4 s.
        let mut o = Occupancy::default();
        o.add(Nanos(S as u64), 1.0);
        o.add(Nanos(7 * S as u64), 3.0);
        assert_eq!(o.within(2 * S, 4 * S), Some((1.0, 3.0)));
        // After the last sample: no line.
        assert_eq!(o.within(8 * S, 9 * S), None);
    }

    #[test]
    fn a_total_s_legend_goes_top_left_where_the_line_has_not_risen_yet() {
        // A counter rising from 0 to 500 over the run: top left is empty.
        let total = series(&[(0.0, 0.0), (10.0, 500.0)]);
        let p = place(
            &area((-50.0, 550.0)),
            TWO_ROWS,
            &[&total],
            bpc::Corner2D::LeftTop,
            false,
        );
        assert_eq!(p.corner, bpc::Corner2D::LeftTop);
        assert_eq!(p.y, (-50.0, 550.0), "no band needed");
        assert!(p.shown);
        // Asked for top right, where the line ends: another corner is chosen.
        let p = place(
            &area((-50.0, 550.0)),
            TWO_ROWS,
            &[&total],
            bpc::Corner2D::RightTop,
            false,
        );
        assert!(matches!(
            p.corner,
            bpc::Corner2D::LeftTop | bpc::Corner2D::RightBottom
        ));
    }

    #[test]
    fn the_pole_angle_s_legend_goes_where_the_pole_line_is_not() {
        let y = (-0.288, 0.288);
        // Calm at first, then falling forward (to +0.25 rad) at the end: the top right is
        // where the pole is, so the legend goes top left.
        let pole = series(&[(0.0, 0.01), (7.0, -0.02), (9.5, 0.25)]);
        let marks = series(&[(2.0, -0.24), (2.02, -0.24)]);
        let p = place(
            &area(y),
            TWO_ROWS,
            &[&pole, &marks],
            bpc::Corner2D::RightTop,
            true,
        );
        assert_eq!((p.corner, p.y, p.shown), (bpc::Corner2D::LeftTop, y, true));
        // Falling backwards from the start (to −0.25 rad in 2 s, then lying there): the
        // bottom is taken all along, the top is free.
        let fallen = series(&[(0.0, 0.0), (2.0, -0.25), (10.0, -0.25)]);
        let p = place(
            &area(y),
            TWO_ROWS,
            &[&fallen],
            bpc::Corner2D::LeftBottom,
            true,
        );
        assert!(is_top(p.corner) && p.shown, "{p:?}");
        // Five rows (three marks with their times) over a pole swinging through the whole
        // run: no corner, no band keeps them off its line; the title and `when` name what
        // the legend would, so it is hidden.
        let tall = LegendSize { rows: 5, chars: 45 };
        let swinging = series(&[(0.0, 0.1), (5.0, -0.1), (10.0, 0.1)]);
        let p = place(
            &area(y),
            tall,
            &[&swinging, &marks],
            bpc::Corner2D::LeftTop,
            true,
        );
        assert_eq!((p.shown, p.y), (false, y), "{p:?}");
    }

    #[test]
    fn a_legend_with_no_free_corner_gets_a_band_of_its_own() {
        // Lines across the whole plot, top and bottom: no corner is free.
        let y = (-1.2, 1.2);
        let high = series(&[(0.0, 0.9), (10.0, 0.9)]);
        let low = series(&[(0.0, -0.9), (10.0, -0.9)]);
        let p = place(
            &area(y),
            TWO_ROWS,
            &[&high, &low],
            bpc::Corner2D::LeftTop,
            false,
        );
        let (lo, hi) = p.y;
        assert!(p.shown && (hi > 1.2 || lo < -1.2), "widened: {p:?}");
        // The legend's band is past every value, and the axis still labels.
        let share = f64::from(TWO_ROWS.px().1 / 140.0);
        let (band_lo, band_hi) = value_span((lo, hi), p.corner, share);
        assert!(band_lo > 0.9 || band_hi < -0.9, "{band_lo}..{band_hi}");
        assert!(labelled(140.0, (lo, hi)));
    }

    #[test]
    fn a_legend_too_tall_for_a_band_goes_where_its_data_enter_least() {
        // Eight rows in 140 px: no band; the data fill the top and reach into the bottom
        // only a little.
        let tall = LegendSize { rows: 8, chars: 30 };
        let y = (-1.1, 1.1);
        let high = series(&[(0.0, 1.0), (10.0, 1.0)]);
        let dip = series(&[(0.0, -0.2), (10.0, -0.2)]);
        let p = place(
            &area(y),
            tall,
            &[&high, &dip],
            bpc::Corner2D::LeftTop,
            false,
        );
        assert!(!is_top(p.corner) && p.shown, "{p:?}");
        assert_eq!(p.y, y, "the range as it was");
    }

    #[test]
    fn reference_lines_are_not_data_a_legend_hides() {
        assert!(is_reference("plant/fall_limit/upper"));
        assert!(is_reference("plant/rail_end/left"));
        assert!(!is_reference("plant/pole_angle_rad"));
        assert!(!is_reference("marks/trouble"));
    }

    #[test]
    fn an_axis_is_labelled_as_the_viewer_labels_it() {
        // The pole angle's ±0.288 rad in 140 px: steps of 0.1, 5.8 across, 24 px apart.
        assert!(labelled(140.0, (-0.288, 0.288)));
        // Widened to 0.9 rad across: 9 steps of 0.1 are too many, 1 rad is past the range.
        assert!(!labelled(140.0, (-0.288, 0.62)));
        assert!(!labelled(140.0, (1.0, 1.0)));
    }

    #[test]
    fn the_layout_s_shares_give_each_plot_its_size() {
        let mut root = Item::Horizontal(vec![
            (0.5, Item::View(ViewSpec::new("a", "TimeSeries", "a"))),
            (
                0.5,
                Item::Vertical(vec![
                    (1.0, Item::View(ViewSpec::new("b", "TimeSeries", "b"))),
                    (
                        3.0,
                        Item::Tabs(
                            vec![("t".into(), Item::View(ViewSpec::new("c", "TextLog", "c")))],
                            0,
                        ),
                    ),
                ]),
            ),
        ]);
        let mut sizes = Vec::new();
        walk(&mut root, (1000.0, 800.0), &mut |v, px| {
            sizes.push((v.plot_parts().class.to_string(), px));
        });
        assert_eq!(
            sizes,
            [
                ("TimeSeries".to_string(), (500.0, 800.0)),
                ("TimeSeries".to_string(), (500.0, 200.0)),
                ("TextLog".to_string(), (500.0, 576.0)),
            ]
        );
    }
}
