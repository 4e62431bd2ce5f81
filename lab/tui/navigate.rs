//! Finding one's way in a graph too large for the screen: the graph panel's zoom (boxes,
//! names, a list), how far it is scrolled, and the filter (by name, by process, by
//! trouble). The lab holds a [`Navigation`]; what matches and what each key does to it are
//! pure functions here, tested without a terminal. The chapter's graph, unfiltered at the
//! first zoom, is drawn exactly as it always was.

use super::view::{NodeView, TopicView};
pub use super::zoom::{Reach, Zoom};

/// The longest filter text kept, characters (a name is matched by a part of it).
pub const MAX_FILTER_CHARS: usize = 32;

/// Which nodes and topics the graph panel shows.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct Filter {
    /// What was typed after `/`, matched without regard to case: a node whose name holds
    /// it, a topic whose name or publisher's name holds it. Starting with `@`, the rest is
    /// matched against the process a node runs in (a topic: its publisher's). Empty: all.
    pub text: String,
    /// Only what is in trouble ([`NodeView::in_trouble`], [`TopicView::in_trouble`]); key `!`.
    pub trouble: bool,
}

impl Filter {
    /// Does it leave anything out?
    pub fn is_active(&self) -> bool {
        !self.text.is_empty() || self.trouble
    }

    /// Does the name or process `(name, process)` match the text?
    fn text_matches(&self, name: &str, process: &str) -> bool {
        match self.text.strip_prefix('@') {
            Some(p) => contains_ignoring_case(process, p),
            None => contains_ignoring_case(name, &self.text),
        }
    }

    /// Is node `n`, running in `process`, shown?
    pub fn node(&self, n: &NodeView, process: &str) -> bool {
        self.text_matches(&n.name, process) && (!self.trouble || n.in_trouble())
    }

    /// Is topic `t`, published by `publisher` (running in `process`), shown?
    pub fn topic(&self, t: &TopicView, publisher: &NodeView, process: &str) -> bool {
        let text = if self.text.starts_with('@') {
            self.text_matches(&publisher.name, process)
        } else {
            self.text_matches(&t.name, process) || self.text_matches(&publisher.name, process)
        };
        text && (!self.trouble || t.in_trouble())
    }

    /// The filter in a few words for the panel's title (`/sens · trouble`), `None` when
    /// it leaves nothing out.
    pub fn label(&self) -> Option<String> {
        let parts: Vec<String> = [
            (!self.text.is_empty()).then(|| format!("/{}", self.text)),
            self.trouble.then(|| "trouble".to_string()),
        ]
        .into_iter()
        .flatten()
        .collect();
        (!parts.is_empty()).then(|| parts.join(" · "))
    }
}

/// `hay` holds `needle`, ignoring ASCII and Unicode case (an empty needle: always).
fn contains_ignoring_case(hay: &str, needle: &str) -> bool {
    needle.is_empty() || hay.to_lowercase().contains(&needle.to_lowercase())
}

/// The lab's navigation of the graph panel.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct Navigation {
    /// The zoom.
    pub zoom: Zoom,
    /// Rows scrolled down from the top (of every column, or of the list); the drawing keeps
    /// it within what there is to show.
    pub scroll: usize,
    /// The filter.
    pub filter: Filter,
    /// A filter is being typed (`/`): the text it had before, restored by Esc.
    pub typing: Option<String>,
    /// How far scrolling can go, as the last frame drew the panel.
    pub reach: Reach,
}

/// What a navigation key asks for.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum NavKey {
    /// The next zoom.
    Zoom,
    /// Rows up (toward the first nodes).
    Up(usize),
    /// Rows down.
    Down(usize),
    /// Back to the top.
    Top,
    /// Start typing a filter.
    StartFilter,
    /// Only trouble, or everything again.
    ToggleTrouble,
    /// While typing: a character.
    Input(char),
    /// While typing: delete one character.
    Backspace,
    /// While typing: keep the filter.
    Submit,
    /// While typing: the filter as it was.
    Cancel,
}

impl Navigation {
    /// Take a key. Returns the notice the footer should give, if any.
    pub fn on_key(&mut self, k: NavKey) -> Option<String> {
        match k {
            NavKey::Zoom => {
                self.zoom = self.zoom.next();
                self.scroll = 0;
                Some(format!(
                    "graph: {} (z: {} next)",
                    self.zoom.word(),
                    self.zoom.next().word()
                ))
            }
            NavKey::Up(n) => {
                self.scroll = self.scroll.min(self.reach.get()).saturating_sub(n);
                None
            }
            NavKey::Down(n) => {
                // Never past the last window drawn: the ↑ that follows moves at once.
                self.scroll = self.scroll.saturating_add(n).min(self.reach.get());
                None
            }
            NavKey::Top => {
                self.scroll = 0;
                None
            }
            NavKey::StartFilter => {
                self.typing = Some(self.filter.text.clone());
                self.filter.text.clear();
                self.scroll = 0;
                None
            }
            NavKey::ToggleTrouble => {
                self.filter.trouble = !self.filter.trouble;
                self.scroll = 0;
                Some(if self.filter.trouble {
                    "graph: only trouble (drops, stale reads, losses, missed deadlines, not alive)"
                        .into()
                } else {
                    "graph: everything again".into()
                })
            }
            NavKey::Input(c) => {
                if self.typing.is_some() && self.filter.text.chars().count() < MAX_FILTER_CHARS {
                    self.filter.text.push(c);
                    self.scroll = 0;
                }
                None
            }
            NavKey::Backspace => {
                self.filter.text.pop();
                None
            }
            NavKey::Submit => {
                self.typing = None;
                None
            }
            NavKey::Cancel => {
                if let Some(before) = self.typing.take() {
                    self.filter.text = before;
                }
                None
            }
        }
    }

    /// Esc with nothing else open: clear the filter. Did it have one to clear?
    pub fn clear_filter(&mut self) -> bool {
        let had = self.filter.is_active();
        self.filter = Filter::default();
        had
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::tui::zoom::window_start;

    fn node(name: &str) -> NodeView {
        NodeView {
            name: name.into(),
            ..NodeView::default()
        }
    }

    fn topic(name: &str) -> TopicView {
        TopicView {
            name: name.into(),
            ..TopicView::default()
        }
    }

    #[test]
    fn zoom_cycles_boxes_names_list() {
        let mut nav = Navigation::default();
        assert_eq!(nav.zoom, Zoom::Boxes);
        nav.scroll = 7;
        let said = nav.on_key(NavKey::Zoom).unwrap();
        assert_eq!((nav.zoom, nav.scroll), (Zoom::Names, 0));
        assert!(said.contains("names"), "{said}");
        nav.on_key(NavKey::Zoom);
        assert_eq!(nav.zoom, Zoom::List);
        nav.on_key(NavKey::Zoom);
        assert_eq!(nav.zoom, Zoom::Boxes);
    }

    #[test]
    fn the_filter_matches_names_processes_and_trouble() {
        let f = |text: &str, trouble| Filter {
            text: text.into(),
            trouble,
        };
        let sensor = node("sensor_3");
        assert!(Filter::default().node(&sensor, "robot"));
        assert!(f("SENS", false).node(&sensor, "robot"));
        assert!(!f("policy", false).node(&sensor, "robot"));
        assert!(f("@rob", false).node(&sensor, "robot"));
        assert!(!f("@rob", false).node(&sensor, "brain"));
        // Trouble: only what is.
        assert!(!f("", true).node(&sensor, "robot"));
        let dead = NodeView {
            alive: Some(false),
            ..node("policy")
        };
        assert!(f("", true).node(&dead, "robot"));
        assert!(f("pol", true).node(&dead, "robot"));
        assert!(!f("sens", true).node(&dead, "robot"));
        // A topic by its name or its publisher's; by process, its publisher's.
        let obs = topic("/obs_3");
        assert!(f("obs", false).topic(&obs, &sensor, "robot"));
        assert!(f("sensor_3", false).topic(&obs, &sensor, "robot"));
        assert!(!f("policy", false).topic(&obs, &sensor, "robot"));
        assert!(f("@robot", false).topic(&obs, &sensor, "robot"));
        assert!(!f("@obs", false).topic(&obs, &sensor, "robot"));
        let dropping = TopicView {
            dropping: true,
            ..topic("/obs")
        };
        assert!(!f("", true).topic(&obs, &sensor, "robot"));
        assert!(f("", true).topic(&dropping, &sensor, "robot"));
    }

    #[test]
    fn typing_a_filter_applies_as_typed_and_esc_restores_it() {
        let mut nav = Navigation::default();
        nav.on_key(NavKey::StartFilter);
        for c in "pol".chars() {
            nav.on_key(NavKey::Input(c));
        }
        assert_eq!(nav.filter.text, "pol");
        nav.on_key(NavKey::Submit);
        assert_eq!(
            (nav.typing.as_deref(), nav.filter.label()),
            (None, Some("/pol".into()))
        );
        // A new filter typed and abandoned: the one before stays.
        nav.on_key(NavKey::StartFilter);
        nav.on_key(NavKey::Input('x'));
        assert_eq!(nav.filter.text, "x");
        nav.on_key(NavKey::Cancel);
        assert_eq!(nav.filter.text, "pol");
        nav.on_key(NavKey::ToggleTrouble);
        assert_eq!(nav.filter.label().as_deref(), Some("/pol · trouble"));
        assert!(nav.clear_filter());
        assert!(!nav.clear_filter());
        // Bounded.
        nav.on_key(NavKey::StartFilter);
        for _ in 0..100 {
            nav.on_key(NavKey::Input('a'));
        }
        assert_eq!(nav.filter.text.len(), MAX_FILTER_CHARS);
    }

    #[test]
    fn scrolling_stops_at_the_last_window_drawn_so_up_moves_at_once() {
        let mut nav = Navigation::default();
        // Nothing drawn that scrolls: ↓ does nothing.
        nav.on_key(NavKey::Down(1));
        assert_eq!(nav.scroll, 0);
        // A column of 100 rows in a window of 10, and a shorter one: 90 is as far as it goes.
        let view_side = nav.reach.clone();
        view_side.clear();
        view_side.note(100, 10);
        view_side.note(30, 10);
        for _ in 0..120 {
            nav.on_key(NavKey::Down(1));
        }
        assert_eq!(nav.scroll, 90);
        nav.on_key(NavKey::Up(1));
        assert_eq!(nav.scroll, 89);
        // The terminal grew: the next frame draws 100 rows in 40, and ↑ starts from 60.
        view_side.clear();
        view_side.note(100, 40);
        nav.on_key(NavKey::Up(1));
        assert_eq!(nav.scroll, 59);
    }

    #[test]
    fn the_window_follows_the_selection_and_stops_at_the_end() {
        // 100 rows, 10 fit.
        assert_eq!(window_start(100, 10, 0, None), 0);
        assert_eq!(window_start(100, 10, 35, None), 35);
        assert_eq!(window_start(100, 10, 500, None), 90);
        assert_eq!(window_start(100, 10, 0, Some(9)), 0);
        assert_eq!(window_start(100, 10, 0, Some(10)), 1);
        assert_eq!(window_start(100, 10, 0, Some(99)), 90);
        assert_eq!(window_start(100, 10, 50, Some(3)), 3);
        // Everything fits: no scrolling.
        assert_eq!(window_start(5, 10, 3, Some(4)), 0);
        assert_eq!(window_start(0, 0, 3, None), 0);
    }
}
