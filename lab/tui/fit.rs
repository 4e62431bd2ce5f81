//! Text made to fit a width: the first of several forms of a figure or title that fits
//! whole, so nothing is cut mid-word. Used by the views and the executor timeline.

/// The first of `forms` (longest first) that fits `room` columns whole, else the last: a
/// figure or title never cut mid-word.
pub fn first_that_fits(forms: impl IntoIterator<Item = String>, room: usize) -> String {
    let mut last = String::new();
    for f in forms {
        if f.chars().count() <= room {
            return f;
        }
        last = f;
    }
    last
}
