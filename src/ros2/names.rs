//! ROS 2's rules for what a graph offers under its own names: the domain id, topic names
//! and node names. Pure functions, so a graph is refused before any session opens.
//!
//! The rules are rmw's (`rmw/validate_full_topic_name.h`, `rmw/validate_node_name.h`,
//! REP 144 "ROS Package Naming" for tokens) and ROS 2's domain range (`ROS_DOMAIN_ID`,
//! 0–232 so that the DDS port formula stays below 65535; rmw_zenoh keeps the same range).
//! Which names ros2cli hides is rclpy's rule ([`is_hidden_name`], [`is_hidden_node`]).

/// The largest domain id ROS 2 accepts (`ROS_DOMAIN_ID`, "0–232" in ROS 2's docs).
pub const MAX_DOMAIN_ID: u32 = 232;

/// The longest fully qualified topic name, characters (`RMW_TOPIC_MAX_NAME_LENGTH`:
/// 255 less the 8 a DDS prefix such as `rt/` may take).
pub const MAX_TOPIC_NAME_LEN: usize = 247;

/// The longest node name, characters (`RMW_NODE_NAME_MAX_NAME_LENGTH`).
pub const MAX_NODE_NAME_LEN: usize = 255;

/// A domain id from the command line or `ROS_DOMAIN_ID`.
///
/// # Errors
/// Not an integer, or above [`MAX_DOMAIN_ID`]: the reason, in one line.
pub fn parse_domain(s: &str) -> Result<u32, String> {
    let t = s.trim();
    let d: u32 = t
        .parse()
        .map_err(|_| format!("ROS 2 domain '{s}' is not a whole number in 0–{MAX_DOMAIN_ID}"))?;
    if d > MAX_DOMAIN_ID {
        return Err(format!(
            "ROS 2 domain {d} is outside 0–{MAX_DOMAIN_ID} (ROS_DOMAIN_ID's range)"
        ));
    }
    Ok(d)
}

/// Check a fully qualified topic name (`/cart/state`) by rmw's rules.
///
/// # Errors
/// The rule it breaks, in words: empty, not absolute, ends with `/`, a character other than
/// `A–Z a–z 0–9 _ /`, `//`, a token starting with a digit, or longer than
/// [`MAX_TOPIC_NAME_LEN`].
pub fn check_topic_name(name: &str) -> Result<(), String> {
    let bad = |rule: &str| Err(format!("'{name}' is not a valid ROS 2 topic name: {rule}"));
    if name.is_empty() {
        return bad("it is empty");
    }
    if !name.starts_with('/') {
        return bad("it must start with '/' (fully qualified)");
    }
    if name.ends_with('/') {
        return bad("it must not end with '/'");
    }
    if let Some(c) = name
        .chars()
        .find(|c| !(c.is_ascii_alphanumeric() || *c == '_' || *c == '/'))
    {
        return bad(&format!(
            "'{}' is not allowed (only A-Z a-z 0-9 _ /)",
            c.escape_default()
        ));
    }
    if name.contains("//") {
        return bad("it must not contain '//'");
    }
    if name
        .split('/')
        .any(|t| t.starts_with(|c: char| c.is_ascii_digit()))
    {
        return bad("a name token must not start with a digit");
    }
    if name.len() > MAX_TOPIC_NAME_LEN {
        return bad(&format!(
            "it is longer than {MAX_TOPIC_NAME_LEN} characters"
        ));
    }
    Ok(())
}

/// Check a node name (`policy`, no namespace) by rmw's rules.
///
/// # Errors
/// The rule it breaks: empty, a character other than `A–Z a–z 0–9 _`, starting with a
/// digit, or longer than [`MAX_NODE_NAME_LEN`].
pub fn check_node_name(name: &str) -> Result<(), String> {
    let bad = |rule: &str| Err(format!("'{name}' is not a valid ROS 2 node name: {rule}"));
    if name.is_empty() {
        return bad("it is empty");
    }
    if let Some(c) = name
        .chars()
        .find(|c| !(c.is_ascii_alphanumeric() || *c == '_'))
    {
        return bad(&format!(
            "'{}' is not allowed (only A-Z a-z 0-9 _)",
            c.escape_default()
        ));
    }
    if name.starts_with(|c: char| c.is_ascii_digit()) {
        return bad("it must not start with a digit");
    }
    if name.len() > MAX_NODE_NAME_LEN {
        return bad(&format!("it is longer than {MAX_NODE_NAME_LEN} characters"));
    }
    Ok(())
}

/// What begins a hidden name's token: rclpy's `HIDDEN_TOPIC_PREFIX` and
/// `HIDDEN_NODE_PREFIX` (`rclpy/topic_or_service_is_hidden.py`, `rclpy/node.py`), `_`.
pub const HIDDEN_PREFIX: char = '_';

/// Whether ros2cli hides a topic or service name (`/_secret`, `/a/_b/c`,
/// `/talker/_action/status`; not `/a_b`): rclpy's `topic_or_service_is_hidden`, "any of the
/// name tokens begins with an underscore", which `ros2 topic list` applies unless
/// `--include-hidden-topics` (ros2topic's `api.get_topic_names_and_types`) and `ros2 node
/// info` to each endpoint unless `--include-hidden` (ros2node's `api._is_hidden_name`).
pub fn is_hidden_name(name: &str) -> bool {
    name.split('/').any(|t| t.starts_with(HIDDEN_PREFIX))
}

/// Whether ros2cli hides a node, given its base name (`_ros2cli_123`, no namespace): the
/// name is empty or begins with `_` (ros2node's `api.get_node_names`, which `ros2 node list`
/// applies unless `-a`, `node info` unless `--include-hidden` and `ros2 param` unless
/// `--include-hidden-nodes`). The namespace does not count: `/_ns/talker` is shown.
pub fn is_hidden_node(base_name: &str) -> bool {
    base_name.is_empty() || base_name.starts_with(HIDDEN_PREFIX)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn domains_are_0_to_232() {
        assert_eq!(parse_domain("0"), Ok(0));
        assert_eq!(parse_domain(" 232 "), Ok(232));
        assert!(parse_domain("233").unwrap_err().contains("outside 0–232"));
        assert!(parse_domain("-1").unwrap_err().contains("whole number"));
        assert!(parse_domain("x").is_err());
    }

    #[test]
    fn topic_names_follow_rmw() {
        for ok in ["/obs", "/action", "/cart/state", "/a_1/b2"] {
            assert_eq!(check_topic_name(ok), Ok(()), "{ok}");
        }
        let why = |n: &str| check_topic_name(n).unwrap_err();
        assert!(why("").contains("empty"));
        assert!(why("obs").contains("start with '/'"));
        assert!(why("/obs/").contains("end with '/'"));
        assert!(why("/").contains("end with '/'"));
        assert!(why("/ob-s").contains("'-' is not allowed"));
        assert!(why("/a//b").contains("'//'"));
        assert!(why("/2d/pose").contains("digit"));
        assert!(why(&format!("/{}", "a".repeat(300))).contains("longer than 247"));
    }

    #[test]
    fn node_names_follow_rmw() {
        assert_eq!(check_node_name("policy_2"), Ok(()));
        assert!(check_node_name("2policy").unwrap_err().contains("digit"));
        assert!(check_node_name("po-licy").unwrap_err().contains("'-'"));
        assert!(check_node_name("").is_err());
    }

    #[test]
    fn hidden_names_are_rclpy_s() {
        for hidden in [
            "/_secret",
            "/a/_b/c",
            "/talker/_action/status",
            "_x",
            "/ns/_",
        ] {
            assert!(is_hidden_name(hidden), "{hidden}");
        }
        for shown in ["/secret", "/a_b", "/a/b_/c", "/", ""] {
            assert!(!is_hidden_name(shown), "{shown}");
        }
    }

    #[test]
    fn hidden_nodes_are_ros2node_s() {
        assert!(is_hidden_node("_hidden_node"));
        assert!(is_hidden_node("_ros2cli_28379"));
        assert!(is_hidden_node(""), "an empty name is not listed either");
        assert!(!is_hidden_node("talker"));
        assert!(!is_hidden_node("dup_"));
    }
}
