//! rmw_zenoh's names for a ROS 2 graph: ratelab's own encoder and decoder of its key
//! expressions, liveliness tokens and QoS strings, written from rmw_zenoh's `docs/design.md`
//! ("Graph Cache", "Namespaces", "Quality of Service") and, for the details design.md leaves
//! to the code, rmw_zenoh_cpp's `liveliness_utils.cpp` (field order, `/` mangled as `%`, the
//! QoS string) and `qos.cpp` (the defaults a QoS string leaves out). Only what ratelab
//! offers and reads is here:
//! - [`entity`]: what a token names — a node, or an endpoint (publisher, subscription,
//!   service server or client) of a node, with its topic, its type (DDS name and RIHS01
//!   hash) and its QoS;
//! - [`qos`]: a QoS profile and its string in a token (`2::,1:,:,:,,`);
//! - [`key_expr`]: an endpoint's data key (`<domain>/<topic>/<dds type>/<RIHS01>`), the
//!   liveliness tokens of nodes and endpoints (`@ros2_lv/<domain>/<zid>/<node id>/<id>/…`),
//!   and a token read back into what it names.
//!
//! Reading a token is reading what any peer on the network declared: every input is
//! bounded ([`MAX_KEY_EXPR_BYTES`], [`qos::MAX_QOS_BYTES`]), every field is checked (its
//! count, its numbers, its words), and what does not fit the format is an [`Error`], never
//! a panic. What is read is what was written: a token as rmw_zenoh_cpp writes one, read and
//! written again, gives the same bytes (the tests check every token and data key a real
//! rclpy node over rmw_zenoh_cpp 0.6.7 declared, `../shared/fixtures/ros2-real/`).

pub mod entity;
pub mod key_expr;
pub mod qos;

/// The longest key expression (liveliness token) read, in bytes. A real token is a few
/// hundred bytes: ROS 2 names are at most 255 characters each, and a token holds four
/// (namespace, node, topic, type) besides its numbers, hash and QoS.
pub const MAX_KEY_EXPR_BYTES: usize = 4096;

/// What the format refuses, reading or writing. A value quoted from the input is cut to its
/// first [`QUOTED_CHARS`] characters.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
pub enum Error {
    /// The input is longer than the bound for what it is.
    #[error("{what} of {len} bytes, over the {max}-byte bound")]
    TooLong {
        /// What was read (`liveliness token`, `QoS string`).
        what: &'static str,
        /// Its length, bytes.
        len: usize,
        /// The bound, bytes.
        max: usize,
    },
    /// The input does not have as many fields as the format gives it.
    #[error("{what} with {got} fields, not {want}")]
    FieldCount {
        /// What was split (`liveliness token`, `QoS history`).
        what: &'static str,
        /// How many fields it has (counted up to one more than `want`).
        got: usize,
        /// How many the format has.
        want: usize,
    },
    /// A field whose value the format does not have (a word, a number, a hash, a name).
    #[error("bad {what}: {value:?}")]
    Bad {
        /// The field.
        what: &'static str,
        /// Its value, cut to [`QUOTED_CHARS`] characters.
        value: String,
    },
    /// What cannot be written in the format (an endpoint with no node or no type, an empty
    /// name, a name that makes no Zenoh key expression).
    #[error("cannot write {0}")]
    Unwritable(String),
}

/// How many characters of a bad value an [`Error::Bad`] quotes.
pub const QUOTED_CHARS: usize = 64;

/// [`Error::Bad`] for field `what` holding `value`.
fn bad(what: &'static str, value: &str) -> Error {
    Error::Bad {
        what,
        value: value.chars().take(QUOTED_CHARS).collect(),
    }
}

/// `s` if it is at most `max` bytes long.
fn bounded<'a>(what: &'static str, s: &'a str, max: usize) -> Result<&'a str, Error> {
    if s.len() > max {
        return Err(Error::TooLong {
            what,
            len: s.len(),
            max,
        });
    }
    Ok(s)
}

/// `s` split at each `sep` into exactly `N` fields (empty ones included).
///
/// # Errors
/// [`Error::FieldCount`] when it has fewer or more.
fn split_exact<'a, const N: usize>(
    what: &'static str,
    s: &'a str,
    sep: char,
) -> Result<[&'a str; N], Error> {
    let mut out = [""; N];
    let mut got = 0;
    for field in s.split(sep) {
        if got == N {
            return Err(Error::FieldCount {
                what,
                got: N + 1,
                want: N,
            });
        }
        out[got] = field;
        got += 1;
    }
    if got != N {
        return Err(Error::FieldCount { what, got, want: N });
    }
    Ok(out)
}

/// The decimal number `s`, as C++'s `std::to_string` writes one: ASCII digits only (no sign,
/// no space), no leading zero but in `0` itself, at most `u64::MAX`.
///
/// # Errors
/// [`Error::Bad`] for anything else (empty included).
fn decimal(what: &'static str, s: &str) -> Result<u64, Error> {
    let canonical = !s.is_empty()
        && s.len() <= 20
        && s.bytes().all(|b| b.is_ascii_digit())
        && (s == "0" || !s.starts_with('0'));
    if !canonical {
        return Err(bad(what, s));
    }
    s.parse::<u64>().map_err(|_| bad(what, s))
}

/// [`decimal`], as a `usize`.
fn decimal_usize(what: &'static str, s: &str) -> Result<usize, Error> {
    usize::try_from(decimal(what, s)?).map_err(|_| bad(what, s))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn numbers_are_read_only_as_std_to_string_writes_them() {
        assert_eq!(decimal("n", "0"), Ok(0));
        assert_eq!(decimal("n", "42"), Ok(42));
        assert_eq!(decimal("n", "18446744073709551615"), Ok(u64::MAX));
        for no in [
            "",
            "+1",
            "-1",
            " 1",
            "1 ",
            "01",
            "00",
            "1e3",
            "0x10",
            "18446744073709551616",
            "999999999999999999999",
            "٣",
        ] {
            assert!(decimal("n", no).is_err(), "{no:?}");
        }
    }

    #[test]
    fn fields_are_exactly_as_many_as_the_format_has() {
        assert_eq!(split_exact::<3>("f", "a::c", ':'), Ok(["a", "", "c"]));
        assert_eq!(
            split_exact::<3>("f", "a:b", ':'),
            Err(Error::FieldCount {
                what: "f",
                got: 2,
                want: 3
            })
        );
        assert_eq!(
            split_exact::<2>("f", "a:b:c:d", ':'),
            Err(Error::FieldCount {
                what: "f",
                got: 3,
                want: 2
            })
        );
        assert_eq!(split_exact::<1>("f", "", ':'), Ok([""]));
    }

    #[test]
    fn a_bad_value_is_quoted_short_and_whole_characters() {
        let long = "é".repeat(1000);
        let Error::Bad { value, .. } = bad("name", &long) else {
            panic!("not Bad")
        };
        assert_eq!(value.chars().count(), QUOTED_CHARS);
        assert!(bounded("x", &long, 10).is_err());
        assert_eq!(bounded("x", "abc", 3), Ok("abc"));
    }
}
