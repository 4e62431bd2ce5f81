//! How much of a large graph the graph panel draws and where its windows stand: the zoom
//! (boxes, names, a list), how far scrolling can go, and the first row of a scrolled
//! window. Beneath both the view ([`super::view`]), which draws with them, and the
//! navigation ([`super::navigate`]), which the keys change.

/// How much of each node and topic the graph panel draws (key `z` cycles).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Zoom {
    /// A box per node and an arrow per topic with all their figures.
    #[default]
    Boxes,
    /// One row per node and per topic in the same layered columns (sensors on the left,
    /// actuators on the right): a large graph's shape at a glance.
    Names,
    /// A list of the nodes and then the topics, a row each with its figures, over the
    /// plant's rows as well: what reads at 80×24.
    List,
}

impl Zoom {
    /// The next zoom: boxes → names → list → boxes.
    pub fn next(self) -> Zoom {
        match self {
            Zoom::Boxes => Zoom::Names,
            Zoom::Names => Zoom::List,
            Zoom::List => Zoom::Boxes,
        }
    }

    /// Its name, as the footer's notice says it.
    pub fn word(self) -> &'static str {
        match self {
            Zoom::Boxes => "boxes",
            Zoom::Names => "names",
            Zoom::List => "list",
        }
    }
}

/// How far scrolling can move the graph panel's windows, as the last frame drew them: the
/// drawing writes it (the largest first row any window can have), the keys read it, so a ↓
/// past the end is not counted and the ↑ after it moves at once. Shared between the lab and
/// the view it draws (clones are one value).
#[derive(Clone, Debug, Default)]
pub struct Reach(std::sync::Arc<std::sync::atomic::AtomicUsize>);

impl Reach {
    /// A new frame: nothing drawn yet.
    pub fn clear(&self) {
        self.0.store(0, std::sync::atomic::Ordering::Relaxed);
    }
    /// A window `fit` rows high over `len` rows was drawn.
    pub fn note(&self, len: usize, fit: usize) {
        self.0.fetch_max(
            len.saturating_sub(fit.max(1)),
            std::sync::atomic::Ordering::Relaxed,
        );
    }
    /// The largest useful scroll, rows.
    pub fn get(&self) -> usize {
        self.0.load(std::sync::atomic::Ordering::Relaxed)
    }
}

impl PartialEq for Reach {
    fn eq(&self, other: &Reach) -> bool {
        self.get() == other.get()
    }
}

impl Eq for Reach {}

/// The first row of a window `fit` rows high over `len` rows, scrolled `scroll` rows down
/// and moved, if need be, so that row `keep` (a selection) is inside it. Never past the
/// last full window.
pub fn window_start(len: usize, fit: usize, scroll: usize, keep: Option<usize>) -> usize {
    let last = len.saturating_sub(fit.max(1));
    let start = scroll.min(last);
    match keep {
        Some(k) if k < start => k,
        Some(k) if fit > 0 && k >= start + fit => (k + 1 - fit).min(last),
        _ => start,
    }
}
