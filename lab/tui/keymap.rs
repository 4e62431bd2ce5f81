//! Keys → messages: a pure function, so the bindings are tested without a terminal.

use crossterm::event::{KeyCode, KeyEvent, KeyEventKind, KeyModifiers};

/// What a key asks for.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Msg {
    /// Control rate one step down the ladder.
    ControlDown,
    /// Control rate one step up the ladder.
    ControlUp,
    /// Start typing an exact control rate.
    TypeRate,
    /// Sensor rate down the ladder.
    SensorDown,
    /// Sensor rate up the ladder.
    SensorUp,
    /// Queue depth down (1, 2, 5, 10, 100).
    DepthDown,
    /// Queue depth up.
    DepthUp,
    /// Control rate to 5 Hz.
    Break,
    /// Pause / resume.
    TogglePause,
    /// One control step while paused (virtual clock).
    Step,
    /// New run, same seed.
    Reset,
    /// New run, next seed.
    NextSeed,
    /// Restart under the other clock.
    SwitchClock,
    /// Slower virtual pacing.
    Slower,
    /// Faster virtual pacing.
    Faster,
    /// Swap the brain (scripted ↔ the --policy file).
    SwapBrain,
    /// Show / hide the key help.
    ToggleHelp,
    /// Leave the lab.
    Quit,
    /// While typing a rate: a character.
    Input(char),
    /// While typing: delete one character.
    Backspace,
    /// While typing: apply.
    Submit,
    /// While typing: abandon.
    Cancel,
}

/// Map a key event. `typing` is true while an exact rate is being typed.
pub fn map_key(key: KeyEvent, typing: bool) -> Option<Msg> {
    if key.kind == KeyEventKind::Release {
        return None;
    }
    if key.modifiers.contains(KeyModifiers::CONTROL) && key.code == KeyCode::Char('c') {
        return Some(Msg::Quit);
    }
    if typing {
        return match key.code {
            KeyCode::Char(c) if c.is_ascii_digit() || c == '.' => Some(Msg::Input(c)),
            KeyCode::Backspace => Some(Msg::Backspace),
            KeyCode::Enter => Some(Msg::Submit),
            KeyCode::Esc => Some(Msg::Cancel),
            _ => None,
        };
    }
    Some(match key.code {
        KeyCode::Char('-') | KeyCode::Left => Msg::ControlDown,
        KeyCode::Char('+') | KeyCode::Right => Msg::ControlUp,
        KeyCode::Char('=') => Msg::TypeRate,
        KeyCode::Char('s') => Msg::SensorDown,
        KeyCode::Char('S') => Msg::SensorUp,
        KeyCode::Char('[') => Msg::DepthDown,
        KeyCode::Char(']') => Msg::DepthUp,
        KeyCode::Char('b') => Msg::Break,
        KeyCode::Char(' ') => Msg::TogglePause,
        KeyCode::Char('.') => Msg::Step,
        KeyCode::Char('r') => Msg::Reset,
        KeyCode::Char('R') => Msg::NextSeed,
        KeyCode::Char('c') => Msg::SwitchClock,
        KeyCode::Char('<') => Msg::Slower,
        KeyCode::Char('>') => Msg::Faster,
        KeyCode::Char('p') => Msg::SwapBrain,
        KeyCode::Char('?') => Msg::ToggleHelp,
        KeyCode::Char('q') | KeyCode::Esc => Msg::Quit,
        _ => return None,
    })
}

/// The key help: (keys, what they do), in the order the overlay lists them.
pub const HELP: [(&str, &str); 16] = [
    ("- / + (← / →)", "control rate down / up the ladder"),
    (
        "=",
        "type an exact control rate (Enter applies, Esc cancels)",
    ),
    ("s / S", "sensor rate down / up"),
    ("[ / ]", "queue depth down / up (1, 2, 5, 10, 100)"),
    ("b", "break: control rate to 5 Hz"),
    ("space", "pause / resume"),
    (".", "one control step while paused (virtual clock)"),
    ("r / R", "reset (same seed) / next seed"),
    ("c", "switch clock (restart under the other one)"),
    ("< / >", "slower / faster (virtual clock; ×0.25 … ×8, max)"),
    ("p", "swap brain: scripted ↔ the --policy file"),
    ("?", "this help"),
    ("q / Esc / Ctrl-C", "quit"),
    ("", ""),
    ("ladder (Hz)", "50 40 30 25 20 15 12 10 8 7 6 5 4 3 2 1"),
    ("after a fall", "the lab freezes; r, R, c or q"),
];

/// The control/sensor rate ladder, Hz, high to low.
pub const RATE_LADDER: [f64; 16] = [
    50.0, 40.0, 30.0, 25.0, 20.0, 15.0, 12.0, 10.0, 8.0, 7.0, 6.0, 5.0, 4.0, 3.0, 2.0, 1.0,
];
/// The queue-depth ladder.
pub const DEPTH_LADDER: [usize; 5] = [1, 2, 5, 10, 100];

/// The next rate down the ladder from `hz` (off-ladder rates go to the next lower rung).
pub fn rate_down(hz: f64) -> f64 {
    RATE_LADDER
        .iter()
        .copied()
        .find(|&r| r < hz)
        .unwrap_or(RATE_LADDER[RATE_LADDER.len() - 1])
}

/// The next rate up the ladder from `hz`.
pub fn rate_up(hz: f64) -> f64 {
    RATE_LADDER
        .iter()
        .rev()
        .copied()
        .find(|&r| r > hz)
        .unwrap_or(RATE_LADDER[0])
}

/// The next depth down.
pub fn depth_down(d: usize) -> usize {
    DEPTH_LADDER
        .iter()
        .rev()
        .copied()
        .find(|&x| x < d)
        .unwrap_or(1)
}

/// The next depth up.
pub fn depth_up(d: usize) -> usize {
    DEPTH_LADDER.iter().copied().find(|&x| x > d).unwrap_or(100)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn key(c: KeyCode) -> KeyEvent {
        KeyEvent::new(c, KeyModifiers::NONE)
    }

    #[test]
    fn default_bindings() {
        assert_eq!(
            map_key(key(KeyCode::Char('-')), false),
            Some(Msg::ControlDown)
        );
        assert_eq!(map_key(key(KeyCode::Left), false), Some(Msg::ControlDown));
        assert_eq!(
            map_key(key(KeyCode::Char('+')), false),
            Some(Msg::ControlUp)
        );
        assert_eq!(map_key(key(KeyCode::Right), false), Some(Msg::ControlUp));
        assert_eq!(map_key(key(KeyCode::Char('=')), false), Some(Msg::TypeRate));
        assert_eq!(
            map_key(key(KeyCode::Char('s')), false),
            Some(Msg::SensorDown)
        );
        assert_eq!(map_key(key(KeyCode::Char('S')), false), Some(Msg::SensorUp));
        assert_eq!(
            map_key(key(KeyCode::Char('[')), false),
            Some(Msg::DepthDown)
        );
        assert_eq!(map_key(key(KeyCode::Char(']')), false), Some(Msg::DepthUp));
        assert_eq!(map_key(key(KeyCode::Char('b')), false), Some(Msg::Break));
        assert_eq!(
            map_key(key(KeyCode::Char(' ')), false),
            Some(Msg::TogglePause)
        );
        assert_eq!(map_key(key(KeyCode::Char('.')), false), Some(Msg::Step));
        assert_eq!(map_key(key(KeyCode::Char('r')), false), Some(Msg::Reset));
        assert_eq!(map_key(key(KeyCode::Char('R')), false), Some(Msg::NextSeed));
        assert_eq!(
            map_key(key(KeyCode::Char('c')), false),
            Some(Msg::SwitchClock)
        );
        assert_eq!(map_key(key(KeyCode::Char('<')), false), Some(Msg::Slower));
        assert_eq!(map_key(key(KeyCode::Char('>')), false), Some(Msg::Faster));
        assert_eq!(
            map_key(key(KeyCode::Char('p')), false),
            Some(Msg::SwapBrain)
        );
        assert_eq!(
            map_key(key(KeyCode::Char('?')), false),
            Some(Msg::ToggleHelp)
        );
        assert_eq!(map_key(key(KeyCode::Char('q')), false), Some(Msg::Quit));
        assert_eq!(map_key(key(KeyCode::Esc), false), Some(Msg::Quit));
        assert_eq!(
            map_key(
                KeyEvent::new(KeyCode::Char('c'), KeyModifiers::CONTROL),
                false
            ),
            Some(Msg::Quit)
        );
        assert_eq!(map_key(key(KeyCode::Char('x')), false), None);
    }

    #[test]
    fn typing_mode_takes_digits_only() {
        assert_eq!(
            map_key(key(KeyCode::Char('7')), true),
            Some(Msg::Input('7'))
        );
        assert_eq!(
            map_key(key(KeyCode::Char('.')), true),
            Some(Msg::Input('.'))
        );
        assert_eq!(map_key(key(KeyCode::Char('q')), true), None);
        assert_eq!(map_key(key(KeyCode::Enter), true), Some(Msg::Submit));
        assert_eq!(map_key(key(KeyCode::Esc), true), Some(Msg::Cancel));
        assert_eq!(map_key(key(KeyCode::Backspace), true), Some(Msg::Backspace));
        // Ctrl-C always quits.
        assert_eq!(
            map_key(
                KeyEvent::new(KeyCode::Char('c'), KeyModifiers::CONTROL),
                true
            ),
            Some(Msg::Quit)
        );
    }

    #[test]
    fn key_releases_are_ignored() {
        let mut k = key(KeyCode::Char('-'));
        k.kind = KeyEventKind::Release;
        assert_eq!(map_key(k, false), None);
    }

    #[test]
    fn ladders() {
        assert_eq!(rate_down(50.0), 40.0);
        assert_eq!(rate_down(5.0), 4.0);
        assert_eq!(rate_down(1.0), 1.0);
        assert_eq!(rate_down(7.5), 7.0);
        assert_eq!(rate_up(7.5), 8.0);
        assert_eq!(rate_up(50.0), 50.0);
        assert_eq!(rate_up(100.0), 50.0);
        assert_eq!(depth_up(1), 2);
        assert_eq!(depth_up(100), 100);
        assert_eq!(depth_down(10), 5);
        assert_eq!(depth_down(1), 1);
        assert_eq!(depth_down(3), 2);
        // 11 presses of `-` take 50 Hz to 5 Hz.
        let mut hz = 50.0;
        for _ in 0..11 {
            hz = rate_down(hz);
        }
        assert_eq!(hz, 5.0);
    }
}
