//! Text from outside made safe to show: the one rule every terminal line, log line and
//! recording event follows for strings that came from a file, a flag, a peer or a learner's
//! code.
//!
//! A control character (ESC, carriage return, newline, DEL, the C1 controls) never reaches
//! a terminal raw: an escape sequence would repaint the screen, a carriage return would
//! overwrite the line, a newline would split a one-line error in two. Each is written out
//! as Rust writes it (`\u{1b}`, `\r`, `\n`), so what the user sees names the byte that was
//! there.

use std::borrow::Cow;

/// `text` with every control character written out (`\u{1b}`, `\r`, `\n`, `\t`,
/// `\u{7f}`), everything else (any printable Unicode) as it is. Borrowed when there is
/// nothing to escape (the common case costs no allocation).
pub fn printable(text: &str) -> Cow<'_, str> {
    if !text.chars().any(char::is_control) {
        return Cow::Borrowed(text);
    }
    Cow::Owned(
        text.chars()
            .map(|c| {
                if c.is_control() {
                    c.escape_default().to_string()
                } else {
                    c.to_string()
                }
            })
            .collect(),
    )
}

/// A library's error message as one line a user can read: its first line, the places in
/// the library's source it names removed (`… at /root/.cargo/registry/src/…/tcp.rs:61.`),
/// and a message wrapped in its error's debug form (`Json5Err(Message { msg: "…", location:
/// … })`, as Zenoh's configuration errors are) unwrapped to the message.
pub fn library_message(msg: &str) -> String {
    let mut line = msg.lines().next().unwrap_or("error").to_string();
    if let Some(inner) = line.split_once("msg: \"").and_then(|(_, rest)| {
        let mut end = None;
        let mut escaped = false;
        for (i, c) in rest.char_indices() {
            match c {
                '\\' if !escaped => escaped = true,
                '"' if !escaped => {
                    end = Some(i);
                    break;
                }
                _ => escaped = false,
            }
        }
        end.map(|e| rest[..e].replace("\\\"", "\""))
    }) {
        line = inner;
    }
    let mut from = 0;
    while let Some(k) = line[from..].find(" at ").map(|k| k + from) {
        let rest = &line[k + 4..];
        let token_end = rest
            .find(|c: char| c.is_whitespace() || c == ']')
            .unwrap_or(rest.len());
        if rest[..token_end].contains(".rs:") {
            line.replace_range(k..k + 4 + token_end, "");
        } else {
            from = k + 4;
        }
    }
    line
}

/// A number as a refusal quotes it, short: Rust's own form up to 15 digits either side of
/// the point, scientific past them (`1e300`, not its 301 digits; `1e-12`).
pub fn number(x: f64) -> String {
    let a = x.abs();
    if a != 0.0 && a.is_finite() && !(1e-6..1e15).contains(&a) {
        format!("{x:e}")
    } else {
        format!("{x}")
    }
}

/// `x` to `places` decimals with its sign, `+` for a value that reads as zero: `+0.0`, never
/// the `-0.0` Rust writes for -0.04 (a sign on a readout says a direction; a zero has none).
pub fn signed(x: f64, places: usize) -> String {
    let text = format!("{x:+.places$}");
    if text.starts_with('-') && text[1..].chars().all(|c| c == '0' || c == '.') {
        format!("+{}", &text[1..])
    } else {
        text
    }
}

/// Does `text` hold a control character (what [`printable`] would write out)?
pub fn has_control(text: &str) -> bool {
    text.chars().any(char::is_control)
}

/// The most names [`listed`] writes before saying how many more there are.
pub const LISTED_NAMES: usize = 12;

/// `names` for a one-line message: comma-separated, the first [`LISTED_NAMES`] of them,
/// then `and N more` (a program may register a thousand kinds or message types, and a
/// refusal stays one readable line). Each name is made [`printable`].
pub fn listed<'a>(names: impl IntoIterator<Item = &'a str>) -> String {
    listed_at_most(names, LISTED_NAMES)
}

/// [`listed`] with the first `most` names written (at least one).
pub fn listed_at_most<'a>(names: impl IntoIterator<Item = &'a str>, most: usize) -> String {
    let most = most.max(1);
    let mut shown = Vec::with_capacity(most.min(LISTED_NAMES));
    let mut more = 0usize;
    for name in names {
        if shown.len() < most {
            shown.push(printable(name));
        } else {
            more += 1;
        }
    }
    let mut out = shown.join(", ");
    if more > 0 {
        out.push_str(&format!(" and {more} more"));
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_signed_zero_reads_plus_zero() {
        assert_eq!(signed(-0.04, 1), "+0.0");
        assert_eq!(signed(-0.0, 2), "+0.00");
        assert_eq!(signed(0.0, 1), "+0.0");
        assert_eq!(signed(-0.05, 1), "-0.1");
        assert_eq!(signed(3.25, 2), "+3.25");
        assert_eq!(signed(-12.0, 0), "-12");
        assert_eq!(signed(f64::NAN, 1), "NaN");
    }

    #[test]
    fn a_list_names_its_first_few_and_counts_the_rest() {
        let names = ["a", "b", "c", "d"];
        assert_eq!(listed_at_most(names, 2), "a, b and 2 more");
        assert_eq!(listed_at_most(names, 4), "a, b, c, d");
        assert_eq!(listed_at_most(names, 0), "a and 3 more");
        assert_eq!(listed(names), "a, b, c, d");
    }

    #[test]
    fn a_library_message_is_one_line_without_its_source_places() {
        let raw = "Can not create a new TCP listener bound to 127.0.0.1:7449: [Address already in use (os error 98) at /root/.cargo/registry/src/index.crates.io-1949cf8c6b5b557f/zenoh-link-commons-1.10.2/src/tcp.rs:61.] at /root/.cargo/registry/src/x/zenoh-transport-1.10.2/src/unicast.rs:338.\nmore";
        assert_eq!(
            library_message(raw),
            "Can not create a new TCP listener bound to 127.0.0.1:7449: [Address already in use (os error 98)]"
        );
        assert_eq!(
            library_message("Timeout! at src/orchestrator.rs:388."),
            "Timeout!"
        );
        assert_eq!(library_message("look at me"), "look at me");
        // Zenoh's configuration error, in its debug form: the message inside.
        let config = r#"Json5Err(Message { msg: "Endpoints must be of the form <protocol>/<address>[?<metadata>][#<config>]: garbage at /root/.cargo/registry/src/index.crates.io-1949cf8c6b5b557f/zenoh-protocol-1.10.2/src/core/endpoint.rs:615.", location: Some(Location { line: 1, column: 2 }) }) at /root/.cargo/registry/src/index.crates.io-1949cf8c6b5b557f/zenoh-1.10.2/src/api/config.rs:86."#;
        assert_eq!(
            library_message(config),
            "Endpoints must be of the form <protocol>/<address>[?<metadata>][#<config>]: garbage"
        );
        assert_eq!(
            library_message(r#"Json5Err(Message { msg: "a \"quoted\" word", location: None })"#),
            "a \"quoted\" word"
        );
    }

    #[test]
    fn a_long_list_of_names_is_cut_saying_how_many_more() {
        assert_eq!(listed(["a", "b"]), "a, b");
        assert_eq!(listed([]), "");
        let many: Vec<String> = (0..1000).map(|i| format!("kind_{i}")).collect();
        let line = listed(many.iter().map(String::as_str));
        assert!(line.starts_with("kind_0, kind_1, "), "{line}");
        assert!(line.ends_with("kind_11 and 988 more"), "{line}");
        assert_eq!(listed(["x\ny", "z"]), "x\\ny, z");
    }

    #[test]
    fn control_characters_are_written_out_and_the_rest_kept() {
        assert_eq!(printable("plain · ✓ é"), "plain · ✓ é");
        assert!(matches!(printable("plain"), Cow::Borrowed(_)));
        assert_eq!(printable("\u{1b}[2Jx"), "\\u{1b}[2Jx");
        assert_eq!(printable("a\nb\rc\td"), "a\\nb\\rc\\td");
        assert_eq!(printable("\u{7f}\u{85}\u{9b}"), "\\u{7f}\\u{85}\\u{9b}");
        assert!(!printable("\u{1b}\u{9b}\n\r\u{7f}")
            .chars()
            .any(char::is_control));
        assert!(has_control("x\u{1b}"));
        assert!(!has_control("x y"));
    }

    #[test]
    fn a_number_is_quoted_short() {
        assert_eq!(number(1e300), "1e300");
        assert_eq!(number(-2.5e-9), "-2.5e-9");
        assert_eq!(number(0.0), "0");
        assert_eq!(number(12.5), "12.5");
        assert_eq!(number(10000.0), "10000");
        assert_eq!(number(f64::NAN), "NaN");
        assert_eq!(number(f64::INFINITY), "inf");
    }
}
