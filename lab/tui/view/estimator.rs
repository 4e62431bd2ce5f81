//! The estimator in view. With an estimator in the graph (`graphs/cartpole-estimator.toml`)
//! Tab to the estimator node (or to the topic of its estimate, `/state`) swaps the
//! pole-angle chart for the estimator's: the pole's angular velocity θ̇ (the plant's, yellow)
//! and the estimator's estimate of it (magenta) over the same window — the velocity the
//! estimator differences from noisy angles, whose noise exercise ex8 is about — and its
//! error and lag as the run's summary gives them (the same fold of the same points:
//! `tui/estimates.rs`), RMS and lag in the title, every figure in the bottom border where
//! the chart has one. Paused, the title reads the tick at the scrub cursor: θ̇, its estimate
//! and their difference ([`super::Readout::estimate_line`]). Esc, or Tab on, gives the
//! pole angle back.
//!
//! An estimate drawn over its truth would hide it, and drawn under it would be hidden where
//! it lies on it (ratatui's chart draws each dataset as a layer over the ones before, a
//! cell taking the later one's dots). So an estimate is drawn after its truth in dashes
//! ([`dashes`]): in every other pair of plot columns the estimate's dots, in the others the
//! truth's, both lines readable where they coincide. The pole-angle chart draws θ̂ so too,
//! and its bottom border says θ̂'s error and lag and where the estimator's chart is.

use super::*;
use ratelab::estimate::{EstimateFigures, MAX_LAG, POLE_ANGLE, POLE_ANGVEL};

/// The estimator's chart's view model ([`View::estimator`]).
#[derive(Clone, Debug, PartialEq)]
pub struct EstimatorView {
    /// The estimator node (the publisher of [`EstimatorView::topic`]).
    pub node: String,
    /// The topic of its estimate, the policy's input (`/state`).
    pub topic: String,
    /// The estimator node or its topic is selected: its chart is in the pole angle's place.
    pub shown: bool,
    /// (t s, θ̇ rad/s): the plant's angular velocity over the charts' window, each drawn
    /// where the angle's line shows the state it is of (empty while not shown).
    pub angvel: Vec<(f64, f64)>,
    /// (t s, rad/s): the estimate of θ̇ the policy read at each actuator tick, beside it
    /// (empty while not shown).
    pub angvel_estimate: Vec<(f64, f64)>,
    /// The estimate's error and lag so far, the run's summary's figures
    /// ([`ratelab::estimate::EstimateFigures`]); `None` before the first tick.
    pub figures: Option<EstimateFigures>,
}

/// Plot columns a dash of an estimate covers, and the gap after it (the truth's).
pub const DASH: usize = 2;

/// The largest θ̇ axis bound, rad/s (a pole spinning faster is off the chart).
const MAX_BOUND: f64 = 1e4;

/// The points of an estimate, `points` over the window `(t0, t1)` of a plot `cols`
/// columns wide, cut into dashes to draw over its truth: only those in the first [`DASH`]
/// of every 2·[`DASH`] columns, consecutive ones in the same dash together (a line within
/// a dash, never across a gap).
pub(super) fn dashes(
    points: &[(f64, f64)],
    (t0, t1): (f64, f64),
    cols: u16,
) -> Vec<Vec<(f64, f64)>> {
    let span = (t1 - t0).max(f64::EPSILON);
    let cols = f64::from(cols.max(1));
    let mut runs: Vec<Vec<(f64, f64)>> = Vec::new();
    let mut last: Option<usize> = None;
    for &(t, v) in points {
        let block = ((t - t0) / span * cols).floor().max(0.0) as usize / DASH;
        if block % 2 == 1 {
            last = None;
            continue;
        }
        // A point in the dash of the one before goes on its line; else it starts a dash.
        if last == Some(block) {
            if let Some(run) = runs.last_mut() {
                run.push((t, v));
            }
        } else {
            runs.push(vec![(t, v)]);
        }
        last = Some(block);
    }
    runs
}

/// The dashes of an estimate ([`dashes`]) as a chart's datasets, in magenta, the first
/// named `name` (for the chart's legend).
pub(super) fn dash_datasets<'a>(
    runs: &'a [Vec<(f64, f64)>],
    name: &'static str,
) -> Vec<Dataset<'a>> {
    runs.iter()
        .enumerate()
        .map(|(i, run)| {
            let d = Dataset::default()
                .marker(Marker::Braille)
                .graph_type(GraphType::Line)
                .magenta()
                .data(run);
            if i == 0 {
                d.name(name)
            } else {
                d
            }
        })
        .collect()
}

/// About how many plot columns a chart in `area` has, its y labels `label_w` wide: the
/// width within its borders, less the labels and the axis.
pub(super) fn plot_cols(area: Rect, label_w: usize) -> u16 {
    let label_w = u16::try_from(label_w).unwrap_or(u16::MAX);
    area.width.saturating_sub(3).saturating_sub(label_w).max(1)
}

/// The θ̇ axis's bound, rad/s: the first of 0.5, 1, 2, 5, 10, 20, 50, … that holds every
/// finite point of `lines` (0.5 for none).
pub(super) fn angvel_bound(lines: &[&[(f64, f64)]]) -> f64 {
    let top = lines
        .iter()
        .flat_map(|l| l.iter())
        .map(|&(_, v)| v.abs())
        .filter(|v| v.is_finite())
        .fold(0.0, f64::max);
    let mut scale = 1.0;
    loop {
        for m in [0.5, 1.0, 2.0] {
            let b = m * scale;
            if top <= b || b >= MAX_BOUND {
                return b;
            }
        }
        scale *= 10.0;
    }
}

/// An axis bound as its label reads: `0.5`, `2`, `20`.
fn bound_label(b: f64) -> String {
    if b < 1.0 {
        format!("{b:.1}")
    } else {
        format!("{b:.0}")
    }
}

/// A lag as the summary says it (`7 ms`, `250 ms or more`, `not measured …`), `short` for a
/// title (`≥250 ms`, `not yet`).
fn lag_words(ms: Option<f64>, measured: bool, short: bool) -> String {
    let max_ms = MAX_LAG.as_secs_f64() * 1e3;
    match (ms, measured, short) {
        (Some(ms), ..) => format!("{ms:.0} ms"),
        (None, true, false) => format!("{max_ms:.0} ms or more"),
        (None, true, true) => format!("≥{max_ms:.0} ms"),
        (None, false, false) => "not measured (under 250 ms of estimates)".to_string(),
        (None, false, true) => "not yet".to_string(),
    }
}

/// The width of `text` on screen (combining marks take none: `θ̇` is one column).
fn width(text: &str) -> usize {
    Span::raw(text).width()
}

/// The first of `forms` whose width on screen fits `room` columns, if any.
fn fitting(forms: Vec<String>, room: usize) -> Option<String> {
    forms.into_iter().find(|f| width(f) <= room)
}

/// A chart's title built piece by piece: each piece after the lead whole, after `· `, or
/// left out when it does not fit.
struct Title {
    spans: Vec<Span<'static>>,
    used: usize,
    room: usize,
}

impl Title {
    /// A title of `room` columns led by `lead` (always there).
    fn new(lead: Vec<Span<'static>>, room: usize) -> Self {
        let used = lead.iter().map(Span::width).sum();
        Title {
            spans: lead,
            used,
            room,
        }
    }

    /// `text` in `style` after `· `, where it fits.
    fn add(&mut self, text: String, style: Style) {
        let n = width(&text) + 2;
        if self.used + n <= self.room {
            self.used += n;
            self.spans.push(Span::raw("· "));
            self.spans.push(Span::styled(text, style));
        }
    }
}

/// The estimator's chart in the pole-angle chart's `area`; `open`: without a bottom border,
/// the force band's top one below serving for both (as the angle chart's).
pub(super) fn render_estimator_chart(
    v: &View,
    e: &EstimatorView,
    area: Rect,
    buf: &mut Buffer,
    open: bool,
) {
    let (t0, t1) = v.chart_s;
    let b = angvel_bound(&[e.angvel.as_slice(), e.angvel_estimate.as_slice()]);
    let clamp = |pts: &[(f64, f64)]| -> Vec<(f64, f64)> {
        pts.iter().map(|&(t, w)| (t, w.clamp(-b, b))).collect()
    };
    let (truth, estimate) = (clamp(&e.angvel), clamp(&e.angvel_estimate));
    let labels = [format!("-{}", bound_label(b)), "0".into(), bound_label(b)];
    let label_w = labels.iter().map(|l| width(l)).max().unwrap_or(0);
    let runs = dashes(&estimate, (t0, t1), plot_cols(area, label_w));
    // The truth first, the estimate over it in dashes.
    let mut datasets = vec![Dataset::default()
        .name("θ̇")
        .marker(Marker::Braille)
        .graph_type(GraphType::Line)
        .yellow()
        .data(&truth)];
    datasets.extend(dash_datasets(&runs, "θ̇ estimate"));
    let room = usize::from(area.width.saturating_sub(2));
    let block = if open {
        use ratatui::widgets::Borders;
        Block::new().borders(Borders::TOP | Borders::LEFT | Borders::RIGHT)
    } else {
        let foot = e
            .figures
            .as_ref()
            .and_then(|f| figures_foot(f, &e.topic, room));
        match foot {
            Some(foot) if area.height >= 3 => Block::bordered().title_bottom(foot),
            _ => Block::bordered(),
        }
    };
    Chart::new(datasets)
        .block(block.title(Line::from(title(v, e, room))))
        .x_axis(super::axis::time_axis(t0, t1, area))
        .y_axis(Axis::default().bounds([-b, b]).labels(labels))
        .render(area, buf);
}

/// The estimator's chart's title, `room` columns: what it draws in whose colour (paused:
/// the tick at the cursor), then θ̇'s RMS error and lag, then the window, each where it
/// fits.
fn title(v: &View, e: &EstimatorView, room: usize) -> Vec<Span<'static>> {
    let lead: Vec<Span<'static>> = match &v.readout {
        Some(r) => vec![Span::styled(
            format!(" {} ", r.estimate_line(room.saturating_sub(2))),
            Style::new().bold(),
        )],
        None if room >= 60 => vec![
            " θ̇ (rad/s): ".into(),
            "true".yellow(),
            " · ".into(),
            "estimate".magenta(),
            " ".into(),
        ],
        None => vec![
            " θ̇".yellow(),
            " vs ".into(),
            "est".magenta(),
            " rad/s ".into(),
        ],
    };
    let mut title = Title::new(lead, room);
    if let Some(f) = &e.figures {
        match f.rms {
            Some(rms) => {
                let bold = Style::new().bold();
                title.add(format!("RMS {:.1} mrad/s ", rms[POLE_ANGVEL] * 1e3), bold);
                let lag = lag_words(f.pole_angvel_lag_ms, f.lag_measured, true);
                title.add(format!("lag {lag} "), bold);
            }
            None => title.add("no estimate yet ".into(), Style::new()),
        }
    }
    title.add(format!("{} ", v.chart_label), Style::new());
    title.spans
}

/// The estimator's figures for its chart's bottom border, `room` columns: the summary's
/// own line where it fits, else the error of θ and θ̇ and their lags, else θ̇'s alone.
fn figures_foot(f: &EstimateFigures, topic: &str, room: usize) -> Option<String> {
    let Some(rms) = f.rms else {
        return fitting(
            vec![format!(" {} ", f.line(topic)), " no estimate yet ".into()],
            room,
        );
    };
    let (a, w) = (rms[POLE_ANGLE] * 1e3, rms[POLE_ANGVEL] * 1e3);
    let lag = |ms, short| lag_words(ms, f.lag_measured, short);
    let both = |short| {
        format!(
            "RMS error θ {a:.2} mrad · θ̇ {w:.1} mrad/s · lag θ {}, θ̇ {}",
            lag(f.pole_angle_lag_ms, short),
            lag(f.pole_angvel_lag_ms, short)
        )
    };
    fitting(
        vec![
            format!(" {} ", f.line(topic)),
            format!(" {} ticks: {} ", f.samples, both(false)),
            format!(" {} ", both(false)),
            format!(" {} ", both(true)),
            format!(
                " θ̇ RMS error {w:.1} mrad/s · lag {} ",
                lag(f.pole_angvel_lag_ms, true)
            ),
        ],
        room,
    )
}

/// The pole-angle chart's bottom border in a graph with an estimator, `room` columns: θ̂'s
/// RMS error and lag (the summary's) and where the estimator's chart is, or as much of it
/// as fits.
pub(super) fn angle_foot(e: &EstimatorView, room: usize) -> Option<String> {
    let hint = format!("Tab to {}: θ̇ and its estimate", e.node);
    let figures = e.figures.as_ref().and_then(|f| {
        let rms = f.rms?;
        Some(format!(
            "θ̂ RMS error {:.2} mrad · lag {}",
            rms[POLE_ANGLE] * 1e3,
            lag_words(f.pole_angle_lag_ms, f.lag_measured, true)
        ))
    });
    let mut forms = Vec::new();
    if let Some(figures) = figures {
        forms.push(format!(" {figures} · {hint} "));
        forms.push(format!(" {figures} · Tab to {} ", e.node));
    }
    forms.push(format!(" {hint} "));
    forms.push(format!(" Tab to {} ", e.node));
    fitting(forms, room)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Dashes take every other pair of columns, a line within a dash, never across a gap.
    #[test]
    fn an_estimate_is_cut_into_dashes_on_every_other_pair_of_columns() {
        // 8 columns over 0–8 s, a point every half second: columns 0–1 and 4–5 are dashes.
        let points: Vec<(f64, f64)> = (0..16).map(|i| (f64::from(i) * 0.5, 1.0)).collect();
        let runs = dashes(&points, (0.0, 8.0), 8);
        let times: Vec<Vec<f64>> = runs
            .iter()
            .map(|r| r.iter().map(|p| p.0).collect())
            .collect();
        assert_eq!(
            times,
            vec![vec![0.0, 0.5, 1.0, 1.5], vec![4.0, 4.5, 5.0, 5.5]]
        );
        // Sparse points (one every 4 columns) are dots, never joined across a gap.
        let sparse = [(0.0, 0.0), (4.0, 0.0), (8.0, 0.0)];
        assert_eq!(dashes(&sparse, (0.0, 12.0), 12).len(), 3);
        assert!(dashes(&[], (0.0, 1.0), 10).is_empty());
    }

    #[test]
    fn the_angular_velocity_axis_holds_every_point_on_a_round_bound() {
        let at = |v: f64| vec![(0.0, v)];
        assert_eq!(angvel_bound(&[]), 0.5);
        assert_eq!(
            angvel_bound(&[at(0.3).as_slice(), at(-0.7).as_slice()]),
            1.0
        );
        assert_eq!(angvel_bound(&[at(2.5).as_slice()]), 5.0);
        let nan = vec![(0.0, -12.0), (1.0, f64::NAN)];
        assert_eq!(angvel_bound(&[nan.as_slice()]), 20.0);
        assert_eq!(angvel_bound(&[at(1e9).as_slice()]), 1e4);
        assert_eq!(bound_label(0.5), "0.5");
        assert_eq!(bound_label(20.0), "20");
    }

    /// The figures read as the summary's line reads them, the fullest form that fits.
    #[test]
    fn the_figures_read_as_the_summary_s() {
        let f = EstimateFigures {
            ticks: 500,
            samples: 499,
            nonfinite: 0,
            rms: Some([0.00102, 0.0735, 0.00099, 0.074]),
            pole_angle_lag_ms: Some(0.0),
            pole_angvel_lag_ms: Some(7.0),
            lag_measured: true,
        };
        let line = format!(" {} ", f.line("/state"));
        assert_eq!(figures_foot(&f, "/state", 200), Some(line));
        assert_eq!(
            figures_foot(&f, "/state", 70).as_deref(),
            Some(" RMS error θ 0.99 mrad · θ̇ 74.0 mrad/s · lag θ 0 ms, θ̇ 7 ms ")
        );
        assert_eq!(
            figures_foot(&f, "/state", 40).as_deref(),
            Some(" θ̇ RMS error 74.0 mrad/s · lag 7 ms ")
        );
        assert_eq!(figures_foot(&f, "/state", 10), None);
        let e = EstimatorView {
            node: "estimator".into(),
            topic: "/state".into(),
            shown: false,
            angvel: Vec::new(),
            angvel_estimate: Vec::new(),
            figures: Some(f),
        };
        assert_eq!(
            angle_foot(&e, 70).as_deref(),
            Some(" θ̂ RMS error 0.99 mrad · lag 0 ms · Tab to estimator ")
        );
        let unmeasured = EstimateFigures {
            pole_angle_lag_ms: None,
            lag_measured: false,
            ..e.figures.clone().unwrap()
        };
        assert_eq!(lag_words(None, false, true), "not yet");
        assert_eq!(lag_words(None, true, false), "250 ms or more");
        assert!(figures_foot(&unmeasured, "/state", 70)
            .unwrap()
            .contains("lag θ not yet, θ̇ 7 ms"));
    }
}
