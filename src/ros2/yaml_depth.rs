//! YAML read from outside (a bag's `metadata.yaml`, a parameter's value on the command
//! line) is checked here for how deeply it nests before a parser sees it: YAML's parser
//! (libyaml, under `serde_yaml`) takes time quadratic in the depth of `[` and `{` (a 200 KB
//! file of `[` took 123 s to refuse), and an event per level of block nesting (16 MiB of
//! `- - - …` took 6 s and 2.4 GB), where this check takes a pass over the bytes.

/// The deepest nesting read, as [`check_within`] counts it: 64. A rosbag2 `metadata.yaml`
/// counts at most about 14 (8 columns of indentation, 2 indicators, 4 `[`), a parameter's
/// value (an array) one.
pub const MAX_YAML_DEPTH: usize = 64;

/// [`check_within`] at [`MAX_YAML_DEPTH`].
///
/// # Errors
/// As [`check_within`].
pub fn check(text: &[u8]) -> Result<(), String> {
    check_within(text, MAX_YAML_DEPTH)
}

/// Refuse YAML `text` that nests deeper than `max_depth`, before a parser sees it.
///
/// A line's depth is counted as the `[`/`{` open at it, plus its indentation in columns,
/// plus its block indicators (`- `, `? `, `: `: each a level where block collections
/// start on one line, as `- - - x`). The count can only overstate the depth, never
/// understate it, whatever the text: every `[` and `{` opens a level wherever it stands (in
/// a quoted string or a comment too), and a `]` or `}` closes one only outside what could
/// be a quoted string or a comment (any `'` or `"` is taken to open one, `\"` escaped). A
/// real file (rosbag2's metadata, a parameter's value) nests a few levels and passes.
///
/// # Errors
/// One line naming the bound.
pub fn check_within(text: &[u8], max_depth: usize) -> Result<(), String> {
    let (mut flow, mut quote, mut comment, mut escaped) = (0usize, None::<u8>, false, false);
    let (mut indent, mut at_line_start, mut indicators) = (0usize, true, 0usize);
    let mut prev = b'\n';
    for (i, &b) in text.iter().enumerate() {
        if b == b'\n' {
            (indent, at_line_start, indicators) = (0, true, 0);
        } else if at_line_start && b == b' ' {
            indent += 1;
        } else {
            at_line_start = false;
        }
        if b == b'[' || b == b'{' {
            flow += 1;
        }
        if comment {
            comment = b != b'\n';
        } else if let Some(q) = quote {
            if b == q && !escaped {
                quote = None;
            }
            escaped = q == b'"' && b == b'\\' && !escaped;
        } else {
            let next_is_blank = text.get(i + 1).is_none_or(|n| n.is_ascii_whitespace());
            match b {
                b'#' if prev.is_ascii_whitespace() => comment = true,
                b'"' | b'\'' => quote = Some(b),
                b']' | b'}' => flow = flow.saturating_sub(1),
                b'-' | b'?' | b':' if next_is_blank => indicators += 1,
                _ => {}
            }
        }
        if flow + indent + indicators > max_depth {
            return Err(format!(
                "YAML nested deeper than {max_depth} levels ([ and {{, indentation and - ? : on a line) (ratelab::ros2::yaml_depth::MAX_YAML_DEPTH)"
            ));
        }
        prev = b;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn nesting_is_overstated_never_understated() {
        assert!(check_within(b"a: [[1, 2], {b: [3]}]", 5).is_ok());
        assert!(check_within(b"a: [[1, 2], {b: [3]}]", 4).is_err());
        // Openers count wherever they stand; closers only outside strings and comments;
        // `a:` and `b:` are a level each.
        assert!(check_within(b"a: '[['\nb: \"[\\\"[\" # [\n", 6).is_ok());
        assert!(check_within(b"a: '[['\nb: \"[\\\"[\" # [\n", 5).is_err());
        assert!(check_within(b"[ ']' [ \"]\" [ # ]\n [", 3).is_err());
        assert!(check_within(b"a: 'it''s ]' [x]", 2).is_ok());
        let deep = "[".repeat(200_000);
        let e = check(deep.as_bytes()).unwrap_err();
        assert!(
            e.contains("deeper than 64") && e.contains("MAX_YAML_DEPTH"),
            "{e}"
        );
        // Block collections nest too: on one line, or by indentation.
        assert!(check("- ".repeat(100).as_bytes()).is_err());
        assert!(check_within(b"- - - x\n", 3).is_ok());
        assert!(check_within(b"- - - x\n", 2).is_err());
        let stairs: String = (0..100).map(|i| format!("{}a:\n", " ".repeat(i))).collect();
        assert!(check(stairs.as_bytes()).is_err());
        // A real rosbag2 metadata.yaml (its QoS profiles are YAML in a string).
        let meta = "rosbag2_bagfile_information:\n  version: 9\n  topics_with_message_count:\n    - topic_metadata:\n        name: /obs\n        offered_qos_profiles: \"- history: 3\\n  depth: 0\\n\"\n      message_count: 500\n  relative_file_paths: [b_0.mcap]\n";
        assert!(check(meta.as_bytes()).is_ok());
    }
}
