//! The time axis every chart of the lab shares (the pole angle, the hold, the estimator's
//! velocity), so that their windows line up.

use ratatui::layout::Rect;
use ratatui::widgets::Axis;

/// The charts' window, `t0` to `t1` s; labelled only where the chart has room for the axis
/// (two rows), in tenths of a second for a window under 2 s.
pub(super) fn time_axis(t0: f64, t1: f64, area: Rect) -> Axis<'static> {
    let axis = Axis::default().bounds([t0, t1]);
    if area.height >= 8 {
        let digits = usize::from(t1 - t0 < 2.0);
        axis.labels([format!("{t0:.digits$}s"), format!("{t1:.digits$}s")])
    } else {
        axis
    }
}
