//! A ROS 2 QoS profile, and its string in an endpoint's liveliness token (rmw_zenoh's
//! `docs/design.md`, "Quality of Service"; the string's layout is rmw_zenoh_cpp's
//! `liveliness_utils.cpp`, its defaults `qos.cpp`). Six `:`-separated fields, the last four
//! with `,`-separated parts:
//!
//! `<reliability>:<durability>:<history>,<depth>:<deadline s>,<ns>:<lifespan s>,<ns>:<liveliness>,<lease s>,<ns>`
//!
//! each policy as its number in ROS 2's `rmw/types.h` (reliability 1 reliable, 2 best
//! effort; durability 1 transient local, 2 volatile; history 1 keep last, 2 keep all;
//! liveliness 1 automatic, 3 manual by topic), each number in decimal, and each part left
//! empty when it equals rmw_zenoh_cpp's default ([`QosProfile::WIRE_DEFAULT`]: reliable,
//! volatile, keep last 42, infinite durations, automatic), so that ROS 2's default profile
//! is `::,10:,:,:,,`. A duration's seconds and nanoseconds are compared with the default's
//! one by one: a 10 s lifespan is `10,0`.

use super::{bad, bounded, decimal, decimal_usize, split_exact, Error};

/// The longest QoS string read, in bytes (the longest rmw_zenoh_cpp writes is about 150:
/// seven numbers of at most 20 digits, and the separators).
pub const MAX_QOS_BYTES: usize = 256;

/// The depth rmw_zenoh_cpp gives a history whose depth is unset (0), and so the depth a QoS
/// string leaves out (rmw_zenoh_cpp's `RMW_ZENOH_DEFAULT_HISTORY_DEPTH`, design.md: "If
/// `DEPTH` is set to 0, `rmw_zenoh_cpp` will choose a depth of 42").
pub const WIRE_DEFAULT_DEPTH: usize = 42;

/// Whether delivery is retried until it succeeds.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
pub enum QosReliability {
    /// `RELIABLE` (1): rmw_zenoh_cpp's default, and ROS 2's.
    #[default]
    Reliable,
    /// `BEST_EFFORT` (2).
    BestEffort,
}

/// Whether a subscription that joins late gets the messages published before.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
pub enum QosDurability {
    /// `VOLATILE` (2): rmw_zenoh_cpp's default, and ROS 2's.
    #[default]
    Volatile,
    /// `TRANSIENT_LOCAL` (1).
    TransientLocal,
}

/// How many messages are kept, with the profile's depth (ROS 2's `history` and `depth`).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum QosHistory {
    /// `KEEP_LAST` (1): the last `depth` messages.
    KeepLast(usize),
    /// `KEEP_ALL` (2): every message. The depth is the profile's all the same, which
    /// rmw_zenoh_cpp writes too (`2,10`) and keep-all ignores.
    KeepAll(usize),
}

impl Default for QosHistory {
    /// ROS 2's default: keep the last 10 (`rmw_qos_profile_default`).
    fn default() -> QosHistory {
        QosHistory::KeepLast(10)
    }
}

/// Whether an endpoint's liveliness is asserted by the middleware or by the application.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
pub enum QosLiveliness {
    /// `AUTOMATIC` (1): rmw_zenoh_cpp's default, and ROS 2's.
    #[default]
    Automatic,
    /// `MANUAL_BY_TOPIC` (3). (`MANUAL_BY_NODE`, 2, is gone from ROS 2 and rmw_zenoh_cpp
    /// refuses it: so does [`QosProfile::decode`].)
    ManualByTopic,
}

/// A duration of a QoS policy, as ROS 2's `rmw_time_t`: seconds and nanoseconds.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct QosDuration {
    /// Whole seconds.
    pub sec: u64,
    /// Nanoseconds besides.
    pub nsec: u64,
}

impl QosDuration {
    /// ROS 2's `RMW_DURATION_INFINITE` (2^63 − 1 ns, as seconds and nanoseconds): no
    /// deadline, no lifespan, no lease.
    pub const INFINITE: QosDuration = QosDuration {
        sec: 9_223_372_036,
        nsec: 854_775_807,
    };
}

impl Default for QosDuration {
    /// [`QosDuration::INFINITE`].
    fn default() -> QosDuration {
        QosDuration::INFINITE
    }
}

/// A ROS 2 QoS profile, as an endpoint's token carries it (ROS 2's `rmw_qos_profile_t`, its
/// depth in [`QosHistory`]).
///
/// Its default is ROS 2's default profile (`rmw_qos_profile_default`, rclcpp's and
/// rclpy's `QoS(10)`) as rmw_zenoh_cpp completes it: reliable, volatile, keep last 10,
/// infinite deadline, lifespan and lease, automatic liveliness.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
pub struct QosProfile {
    /// Reliability.
    pub reliability: QosReliability,
    /// Durability.
    pub durability: QosDurability,
    /// History, with the depth.
    pub history: QosHistory,
    /// The longest time expected between messages.
    pub deadline: QosDuration,
    /// How long a message stays valid after it was published.
    pub lifespan: QosDuration,
    /// Who asserts liveliness.
    pub liveliness: QosLiveliness,
    /// How long an endpoint is alive after its last assertion.
    pub liveliness_lease_duration: QosDuration,
}

impl QosProfile {
    /// rmw_zenoh_cpp's defaults (`qos.cpp`): what an empty part of a QoS string stands for,
    /// and what is left out when written.
    pub const WIRE_DEFAULT: QosProfile = QosProfile {
        reliability: QosReliability::Reliable,
        durability: QosDurability::Volatile,
        history: QosHistory::KeepLast(WIRE_DEFAULT_DEPTH),
        deadline: QosDuration::INFINITE,
        lifespan: QosDuration::INFINITE,
        liveliness: QosLiveliness::Automatic,
        liveliness_lease_duration: QosDuration::INFINITE,
    };

    /// The profile as a token's QoS string (module header): `2::,1:,:,:,,` for best effort,
    /// keep last 1.
    pub fn encode(&self) -> String {
        let d = QosProfile::WIRE_DEFAULT;
        let reliability = match self.reliability {
            QosReliability::Reliable => "",
            QosReliability::BestEffort => "2",
        };
        let durability = match self.durability {
            QosDurability::Volatile => "",
            QosDurability::TransientLocal => "1",
        };
        let (kind, depth) = match self.history {
            QosHistory::KeepLast(n) => ("", n),
            QosHistory::KeepAll(n) => ("2", n),
        };
        let depth = unless_default(depth, WIRE_DEFAULT_DEPTH);
        let liveliness = match self.liveliness {
            QosLiveliness::Automatic => "",
            QosLiveliness::ManualByTopic => "3",
        };
        let lease = duration(self.liveliness_lease_duration, d.liveliness_lease_duration);
        format!(
            "{reliability}:{durability}:{kind},{depth}:{}:{}:{liveliness},{lease}",
            duration(self.deadline, d.deadline),
            duration(self.lifespan, d.lifespan),
        )
    }

    /// The profile QoS string `s` writes (module header), an empty part standing for
    /// [`QosProfile::WIRE_DEFAULT`]'s, a `0` policy (ROS 2's `SYSTEM_DEFAULT`) too.
    ///
    /// # Errors
    /// [`Error::TooLong`] over [`MAX_QOS_BYTES`]; [`Error::FieldCount`] when it has not six
    /// fields, or a field not its number of parts; [`Error::Bad`] for a policy number the
    /// profile does not have (`UNKNOWN`, `BEST_AVAILABLE`, `MANUAL_BY_NODE`, anything
    /// else) or a number not in decimal.
    pub fn decode(s: &str) -> Result<QosProfile, Error> {
        let s = bounded("QoS string", s, MAX_QOS_BYTES)?;
        let d = QosProfile::WIRE_DEFAULT;
        let [reliability, durability, history, deadline, lifespan, liveliness] =
            split_exact::<6>("QoS string", s, ':')?;
        let reliability = match reliability {
            "" | "0" => d.reliability,
            "1" => QosReliability::Reliable,
            "2" => QosReliability::BestEffort,
            other => return Err(bad("QoS reliability", other)),
        };
        let durability = match durability {
            "" | "0" => d.durability,
            "1" => QosDurability::TransientLocal,
            "2" => QosDurability::Volatile,
            other => return Err(bad("QoS durability", other)),
        };
        let [kind, depth] = split_exact::<2>("QoS history", history, ',')?;
        let depth = match depth {
            "" => WIRE_DEFAULT_DEPTH,
            n => decimal_usize("QoS depth", n)?,
        };
        let history = match kind {
            "" | "0" | "1" => QosHistory::KeepLast(depth),
            "2" => QosHistory::KeepAll(depth),
            other => return Err(bad("QoS history", other)),
        };
        let [kind, lease_sec, lease_nsec] = split_exact::<3>("QoS liveliness", liveliness, ',')?;
        let liveliness = match kind {
            "" | "0" | "1" => QosLiveliness::Automatic,
            "3" => QosLiveliness::ManualByTopic,
            other => return Err(bad("QoS liveliness", other)),
        };
        let [deadline_sec, deadline_nsec] = split_exact::<2>("QoS deadline", deadline, ',')?;
        let [lifespan_sec, lifespan_nsec] = split_exact::<2>("QoS lifespan", lifespan, ',')?;
        Ok(QosProfile {
            reliability,
            durability,
            history,
            deadline: read_duration("QoS deadline", [deadline_sec, deadline_nsec], d.deadline)?,
            lifespan: read_duration("QoS lifespan", [lifespan_sec, lifespan_nsec], d.lifespan)?,
            liveliness,
            liveliness_lease_duration: read_duration(
                "QoS liveliness lease",
                [lease_sec, lease_nsec],
                d.liveliness_lease_duration,
            )?,
        })
    }
}

/// `n` in decimal, or nothing when it is `default`.
fn unless_default<T: PartialEq + std::fmt::Display>(n: T, default: T) -> String {
    if n == default {
        String::new()
    } else {
        n.to_string()
    }
}

/// `d` as `<s>,<ns>`, each part left out when it is `default`'s.
fn duration(d: QosDuration, default: QosDuration) -> String {
    format!(
        "{},{}",
        unless_default(d.sec, default.sec),
        unless_default(d.nsec, default.nsec)
    )
}

/// The duration of parts `[<s>, <ns>]`, an empty part being `default`'s.
fn read_duration(
    what: &'static str,
    [sec, nsec]: [&str; 2],
    default: QosDuration,
) -> Result<QosDuration, Error> {
    let part = |p: &str, default: u64| {
        if p.is_empty() {
            Ok(default)
        } else {
            decimal(what, p)
        }
    };
    Ok(QosDuration {
        sec: part(sec, default.sec)?,
        nsec: part(nsec, default.nsec)?,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn ms(n: u64) -> QosDuration {
        QosDuration {
            sec: n / 1000,
            nsec: n % 1000 * 1_000_000,
        }
    }

    /// ROS 2's default profile is rmw_qos_profile_default as rmw_zenoh_cpp completes it, and
    /// its string is a real rclpy publisher's with default QoS (`/chatter` in the fixture).
    #[test]
    fn the_default_is_ros2_s_and_writes_as_a_real_default_publisher_s() {
        let q = QosProfile::default();
        assert_eq!(q.reliability, QosReliability::Reliable);
        assert_eq!(q.durability, QosDurability::Volatile);
        assert_eq!(q.history, QosHistory::KeepLast(10));
        assert_eq!(q.deadline, QosDuration::INFINITE);
        assert_eq!(q.lifespan, QosDuration::INFINITE);
        assert_eq!(q.liveliness, QosLiveliness::Automatic);
        assert_eq!(q.liveliness_lease_duration, QosDuration::INFINITE);
        assert_eq!(q.encode(), "::,10:,:,:,,");
        assert_eq!(QosProfile::WIRE_DEFAULT.encode(), "::,:,:,:,,");
        assert_eq!(
            QosProfile::decode("::,:,:,:,,"),
            Ok(QosProfile::WIRE_DEFAULT)
        );
    }

    /// Each string a real rmw_zenoh_cpp 0.6.7 node wrote (`real-rclpy-talker.json`), read
    /// and written again.
    #[test]
    fn real_qos_strings_read_as_their_profiles_and_write_back_the_same() {
        let cases = [
            // /rosout: transient local, keep last 1000, lifespan 10 s.
            (
                ":1:,1000:,:10,0:,,",
                QosProfile {
                    durability: QosDurability::TransientLocal,
                    history: QosHistory::KeepLast(1000),
                    lifespan: QosDuration { sec: 10, nsec: 0 },
                    ..QosProfile::default()
                },
            ),
            // Sensor data: best effort, keep last 5.
            (
                "2::,5:,:,:,,",
                QosProfile {
                    reliability: QosReliability::BestEffort,
                    history: QosHistory::KeepLast(5),
                    ..QosProfile::default()
                },
            ),
            // Keep all, reliable, depth 10.
            (
                "::2,10:,:,:,,",
                QosProfile {
                    history: QosHistory::KeepAll(10),
                    ..QosProfile::default()
                },
            ),
            // Best effort, depth 1, deadline 40 ms, lifespan 60 ms, lease 100 ms.
            (
                "2::,1:0,40000000:0,60000000:,0,100000000",
                QosProfile {
                    reliability: QosReliability::BestEffort,
                    history: QosHistory::KeepLast(1),
                    deadline: ms(40),
                    lifespan: ms(60),
                    liveliness_lease_duration: ms(100),
                    ..QosProfile::default()
                },
            ),
        ];
        for (s, q) in cases {
            assert_eq!(QosProfile::decode(s), Ok(q), "{s}");
            assert_eq!(q.encode(), s);
        }
    }

    #[test]
    fn every_policy_round_trips() {
        let durations = [
            QosDuration::INFINITE,
            QosDuration { sec: 0, nsec: 0 },
            ms(25),
            QosDuration {
                sec: QosDuration::INFINITE.sec,
                nsec: 0,
            },
            QosDuration {
                sec: u64::MAX,
                nsec: u64::MAX,
            },
        ];
        for reliability in [QosReliability::Reliable, QosReliability::BestEffort] {
            for durability in [QosDurability::Volatile, QosDurability::TransientLocal] {
                for history in [
                    QosHistory::KeepLast(1),
                    QosHistory::KeepLast(0),
                    QosHistory::KeepLast(WIRE_DEFAULT_DEPTH),
                    QosHistory::KeepAll(WIRE_DEFAULT_DEPTH),
                    QosHistory::KeepAll(usize::MAX),
                ] {
                    for liveliness in [QosLiveliness::Automatic, QosLiveliness::ManualByTopic] {
                        for d in durations {
                            let q = QosProfile {
                                reliability,
                                durability,
                                history,
                                deadline: d,
                                lifespan: d,
                                liveliness,
                                liveliness_lease_duration: d,
                            };
                            let s = q.encode();
                            assert!(s.len() <= MAX_QOS_BYTES, "{s}");
                            assert_eq!(QosProfile::decode(&s), Ok(q), "{s}");
                        }
                    }
                }
            }
        }
    }

    /// A keep-all history's depth is written as rmw_zenoh_cpp writes it (`2,10`), and left
    /// out only when it is rmw_zenoh_cpp's default, 42, which an empty depth stands for.
    #[test]
    fn a_keep_all_history_carries_its_depth() {
        let all = |n| QosProfile {
            history: QosHistory::KeepAll(n),
            ..QosProfile::default()
        };
        assert_eq!(all(10).encode(), "::2,10:,:,:,,");
        assert_eq!(all(42).encode(), "::2,:,:,:,,");
        assert_eq!(QosProfile::decode("::2,:,:,:,,"), Ok(all(42)));
    }

    /// `0` is ROS 2's `SYSTEM_DEFAULT`, which rmw_zenoh_cpp's defaults stand for.
    #[test]
    fn system_default_reads_as_rmw_zenoh_s_default() {
        assert_eq!(
            QosProfile::decode("0:0:0,:,:,:0,,"),
            Ok(QosProfile::WIRE_DEFAULT)
        );
    }

    #[test]
    fn what_is_not_a_qos_string_is_refused() {
        let long = format!("::,{}:,:,:,,", "1".repeat(MAX_QOS_BYTES));
        for no in [
            "",
            ":",
            "::,",
            "::,10",
            "::,10:,:,",
            "::,10:,:,:,",
            "::,10:,:,:,,:",
            "::,10:,:,:,,,",
            "::,10,1:,:,:,,",
            "::,10:,,:,:,,",
            "::,10:,:,:,,:extra",
            "3::,10:,:,:,,",
            "4::,10:,:,:,,",
            ":3:,10:,:,:,,",
            ":4:,10:,:,:,,",
            "::3,10:,:,:,,",
            "::1,-1:,:,:,,",
            "::1,+1:,:,:,,",
            "::1,010:,:,:,,",
            "::1,1x:,:,:,,",
            "::,10:,:,:2,,",
            "::,10:,:,:4,,",
            "::,10:,:,:5,,",
            "::,10:1.5,:,:,,",
            "::,10:,:,:,99999999999999999999,",
            "::,10:,:,:,,18446744073709551616",
            "r::,10:,:,:,,",
            "1 ::,10:,:,:,,",
            "\u{0}::,10:,:,:,,",
            long.as_str(),
        ] {
            assert!(QosProfile::decode(no).is_err(), "{no:?}");
        }
        assert!(matches!(
            QosProfile::decode(&long),
            Err(Error::TooLong { .. })
        ));
    }
}
