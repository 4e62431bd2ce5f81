//! Quality of service: what a topic promises its subscriber beyond "the newest message".
//!
//! The names and meanings are ROS 2's ("About Quality of Service settings",
//! <https://docs.ros.org/en/rolling/Concepts/Intermediate/About-Quality-of-Service-Settings.html>):
//! history (keep last *depth* / keep all), deadline, lifespan, liveliness and reliability.
//! ratelab adds two things the chapter's topic has and DDS does not name: the *delivery*
//! to the subscriber (the chapter's latest-wins read, or a FIFO callback queue), and a
//! seeded *lossy link* a topic may cross, so that reliability has something to do
//! in-process and a virtual run stays byte-identical.
//!
//! Every setting has a graph-file key on the `[[topic]]` table and the same key in
//! `--qos TOPIC:KEY=VALUE[,KEY=VALUE…]` ([`apply_key`]):
//!
//! | key | values | default |
//! |---|---|---|
//! | `history` | `keep_last`, `keep_all` | `keep_last` |
//! | `depth` | keep-last depth or keep-all cap, ≥ 1 | 1 |
//! | `delivery` | `latest`, `fifo` | `latest` |
//! | `deadline_ms` | > 0 | none |
//! | `lifespan_ms` | > 0 | none |
//! | `reliability` | `best_effort`, `reliable` | `best_effort` |
//! | `durability` | `volatile`, `transient_local` (history for late joiners) | `volatile` |
//! | `on_deadline_missed` | `hold`, `zero`, `stop` (the actuator's input only) | `hold` |
//! | `loss`, `delay_ms`, `jitter_ms`, `retransmit_ms` | the link (`link = { … }` in a file) | no link |
//!
//! Liveliness is a node's: `liveliness_lease_ms` on a `[[node]]` (or `--lease NODE=MS`).
//! The defaults are the chapter's topic exactly, so a graph that sets none of them runs
//! byte-identically to one written before QoS existed.

pub mod compat;

use crate::time::{Nanos, MAX_DURATION_S};
use serde::{Deserialize, Serialize};

/// The longest deadline, lifespan, lease, link delay or jitter a graph may set, ms (an
/// hour: the longest run).
pub const MAX_QOS_MS: f64 = 3_600_000.0;

/// The largest history depth a graph file or flag may set (a bound on memory per topic).
pub const MAX_DEPTH: usize = 1_000_000;

/// How many times a reliable link sends one message before it gives up and counts it
/// lost (a bound on work per message; at 20% loss the chance of reaching it is 0.2¹⁶).
pub const MAX_ATTEMPTS: u32 = 16;

/// What a topic keeps for its subscriber (ROS 2 *history*).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum History {
    /// Keep the newest `depth` messages; publishing into a full queue evicts the oldest
    /// (a *drop* when it was never read). The chapter's topic.
    #[default]
    KeepLast,
    /// Keep every unread message up to a hard cap of `depth`; a publish into a cap full of
    /// unread messages is *refused* and counted, never a silent loss and never unbounded
    /// memory (ROS 2 bounds keep-all by its resource limits the same way).
    KeepAll,
}

/// Which message a subscriber's read returns.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Delivery {
    /// The newest message; everything older is read past (ch2.8's latest-wins read).
    #[default]
    Latest,
    /// The oldest unread message, one per read, as a ROS executor's callback queue hands
    /// them out: nothing is skipped, so a slow subscriber acts on ever older data.
    Fifo,
}

/// Whether a link retries a message it lost (ROS 2 *reliability*).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Reliability {
    /// A message the link loses is gone (counted `lost`).
    #[default]
    BestEffort,
    /// A lost message is sent again after the retransmit timeout until it arrives (counted
    /// `retransmitted`; gives up after [`MAX_ATTEMPTS`] sends and counts it `lost`).
    Reliable,
}

/// What the actuator does at a tick when its input's deadline has passed with no new
/// message (ROS 2 leaves the reaction to the application; these are the usual three).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum OnDeadlineMissed {
    /// Keep applying the last command: the zero-order hold (ch2.8's actuator).
    #[default]
    Hold,
    /// Apply no force until a message arrives.
    Zero,
    /// End the run, "stopped by watchdog": a verdict distinct from a fall.
    Stop,
}

/// A link a topic crosses between publisher and subscriber: seeded loss, delay and jitter.
/// In-process topics without a link are lossless, as in DDS and Zenoh.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct Link {
    /// Probability that one send is lost, in [0, 1].
    pub loss: f64,
    /// One-way delay added to every message.
    pub delay: Nanos,
    /// Each message's delay varies uniformly in `delay ± jitter` (never below zero). The
    /// link keeps order, as a TCP or Zenoh link does: a message never overtakes an earlier one.
    pub jitter: Nanos,
    /// A reliable link sends a lost message again after this long.
    pub retransmit: Nanos,
}

impl Link {
    /// The default retransmit timeout for a link: one round trip at the worst delay
    /// (`2 × (delay + jitter)`), at least 1 ms.
    pub fn default_retransmit(delay: Nanos, jitter: Nanos) -> Nanos {
        Nanos(
            (delay.0.saturating_add(jitter.0))
                .saturating_mul(2)
                .max(Nanos::MILLISECOND.0),
        )
    }
}

/// A topic's QoS apart from its history depth (which `ratelab::graph::spec::TopicSpec`
/// keeps as `depth`, as it did before QoS).
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct TopicQos {
    /// Keep last or keep all.
    pub history: History,
    /// Latest or FIFO.
    pub delivery: Delivery,
    /// The longest expected time between messages; missing it is counted per period missed,
    /// on the publisher (*offered*) and on the subscriber (*requested*).
    pub deadline: Option<Nanos>,
    /// A message older than this (since its publish stamp) when read is discarded and
    /// counted `expired`.
    pub lifespan: Option<Nanos>,
    /// Best effort or reliable (matters only across a [`Link`]).
    pub reliability: Reliability,
    /// The link the topic crosses, if any.
    pub link: Option<Link>,
    /// The subscriber's reaction to a missed deadline (the actuator's input only).
    pub on_deadline_missed: OnDeadlineMissed,
    /// Volatile, or transient local: the publisher keeps its last *depth* messages for a
    /// subscription that joins later (a node with a `start_ms`), as ROS 2's durability.
    #[serde(default, skip_serializing_if = "is_volatile")]
    pub durability: compat::Durability,
}

fn is_volatile(d: &compat::Durability) -> bool {
    *d == compat::Durability::Volatile
}

impl TopicQos {
    /// True when every setting is the chapter's (keep-last, latest, nothing else): such a
    /// topic adds no QoS counters to any output.
    pub fn is_default(&self) -> bool {
        *self == TopicQos::default()
    }

    /// The QoS in a few characters, for the lab's edges: `KL1 latest`, `KA100 fifo`, then
    /// `dl 40 ms` (`dl 40 ms stop`, `… zero`: what a missed deadline does when not the
    /// hold), `ls 60 ms`, `link 5%`, `rel` when set.
    pub fn short(&self, depth: usize) -> String {
        self.short_parts(depth).join(" ")
    }

    /// [`TopicQos::short`] in its parts (`["KL1 latest", "dl 40 ms", "link 5% rel"]`), for
    /// a view that wraps them.
    pub fn short_parts(&self, depth: usize) -> Vec<String> {
        let mut parts = vec![format!(
            "{}{depth} {}",
            match self.history {
                History::KeepLast => "KL",
                History::KeepAll => "KA",
            },
            match self.delivery {
                Delivery::Latest => "latest",
                Delivery::Fifo => "fifo",
            }
        )];
        if let Some(d) = self.deadline {
            // What a missed deadline does, when not the hold.
            parts.push(match self.on_deadline_missed {
                OnDeadlineMissed::Hold => format!("dl {d}"),
                OnDeadlineMissed::Zero => format!("dl {d} zero"),
                OnDeadlineMissed::Stop => format!("dl {d} stop"),
            });
        }
        if let Some(l) = self.lifespan {
            parts.push(format!("ls {l}"));
        }
        if self.durability == compat::Durability::TransientLocal {
            parts.push("transient".into());
        }
        let rel = self.reliability == Reliability::Reliable;
        match &self.link {
            Some(l) => parts.push(format!(
                "link {}%{}",
                fmt_percent(l.loss),
                if rel { " rel" } else { "" }
            )),
            // Reliable without a link: nothing is lost to resend, but what was set shows.
            None if rel => parts.push("rel".into()),
            None => {}
        }
        parts
    }
}

fn fmt_percent(p: f64) -> String {
    let pct = p * 100.0;
    if (pct - pct.round()).abs() < 1e-9 {
        format!("{pct:.0}")
    } else {
        format!("{pct:.1}")
    }
}

/// Milliseconds from a file or flag as [`Nanos`]: finite, `> 0` (or `≥ 0` when
/// `zero_ok`), at most [`MAX_QOS_MS`]. Time is whole nanoseconds, so a duration where 0
/// has no meaning (a deadline, a lifespan, a lease, a retransmission) must also be at
/// least 1 ns once rounded: `deadline_ms = 1e-300` would otherwise be a deadline of 0,
/// which no period can miss.
///
/// # Errors
/// A one-line reason naming `key`.
pub fn ms_to_nanos(key: &str, ms: f64, zero_ok: bool) -> Result<Nanos, String> {
    let ok = ms.is_finite() && ms <= MAX_QOS_MS && if zero_ok { ms >= 0.0 } else { ms > 0.0 };
    if !ok {
        let lo = if zero_ok { "≥ 0" } else { "> 0" };
        return Err(format!(
            "{key} must be {lo} and at most {MAX_QOS_MS} ms, got {ms}"
        ));
    }
    let n =
        Nanos::from_secs_f64(ms / 1e3).ok_or_else(|| format!("{key}: {ms} ms is out of range"))?;
    if !zero_ok && n == Nanos::ZERO {
        return Err(format!(
            "{key} = {ms:e} ms rounds to 0 ns (time is whole nanoseconds): give at least 0.000001 ms"
        ));
    }
    Ok(n)
}

/// A link's loss probability: in [0, 1].
///
/// # Errors
/// A one-line reason.
pub fn check_loss(loss: f64) -> Result<f64, String> {
    if (0.0..=1.0).contains(&loss) {
        Ok(loss)
    } else {
        Err(format!("loss must be a probability in [0, 1], got {loss}"))
    }
}

/// The rules that concern more than one key, checked once every key is set.
///
/// # Errors
/// A one-line reason.
pub fn check_combination(q: &TopicQos, subscriber_is_actuator: bool) -> Result<(), String> {
    if q.on_deadline_missed != OnDeadlineMissed::Hold {
        if !subscriber_is_actuator {
            return Err(
                "on_deadline_missed is the actuator's reaction: set it on the topic the actuator subscribes to"
                    .into(),
            );
        }
        if q.deadline.is_none() {
            return Err("on_deadline_missed needs a deadline_ms on the same topic".into());
        }
    }
    if let Some(l) = &q.link {
        if q.reliability == Reliability::Reliable && l.loss >= 1.0 {
            return Err(
                "a reliable link that loses every send never delivers: loss must be below 1".into(),
            );
        }
    }
    Ok(())
}

/// The keys of a link (a graph file's `link = { … }` table, `--link`), in that table's order.
pub const LINK_KEYS: [&str; 4] = ["loss", "delay_ms", "jitter_ms", "retransmit_ms"];

/// Names of the keys [`apply_key`] knows, for messages.
pub const KEYS: &str = "history, depth, delivery, deadline_ms, lifespan_ms, reliability, durability, on_deadline_missed, loss, delay_ms, jitter_ms, retransmit_ms";

/// Set one key (a `--qos` pair) on `qos` and `depth`, with the graph file's names and
/// values (`deadline_ms=none` and `lifespan_ms=none` turn them off). A link key on a topic without a link starts one (no loss, no delay). Keys are
/// set one at a time; call [`check_combination`] after the last.
///
/// # Errors
/// A one-line reason for an unknown key or a bad value.
pub fn apply_key(
    qos: &mut TopicQos,
    depth: &mut usize,
    key: &str,
    value: &str,
) -> Result<(), String> {
    let num = |v: &str| -> Result<f64, String> {
        v.trim()
            .parse::<f64>()
            .map_err(|_| format!("{key}: not a number: '{v}'"))
    };
    let link = |q: &mut TopicQos| -> Link {
        q.link.unwrap_or(Link {
            retransmit: Link::default_retransmit(Nanos::ZERO, Nanos::ZERO),
            ..Link::default()
        })
    };
    match key.trim() {
        "history" => {
            qos.history = word(key, value)?;
        }
        "depth" => {
            let d = value
                .trim()
                .parse::<usize>()
                .map_err(|_| format!("depth: not a whole number: '{value}'"))?;
            if d == 0 || d > MAX_DEPTH {
                return Err(format!("depth must be in 1..={}, got {d}", MAX_DEPTH));
            }
            *depth = d;
        }
        "delivery" => qos.delivery = word(key, value)?,
        "deadline_ms" | "lifespan_ms" => {
            let v = match value.trim() {
                "none" => None,
                v => Some(ms_to_nanos(key, num(v)?, false)?),
            };
            if key == "deadline_ms" {
                qos.deadline = v;
            } else {
                qos.lifespan = v;
            }
        }
        "reliability" => {
            qos.reliability = word(key, value)?;
        }
        "on_deadline_missed" => {
            qos.on_deadline_missed = word(key, value)?;
        }
        "durability" => qos.durability = word(key, value)?,
        "loss" => {
            let mut l = link(qos);
            l.loss = check_loss(num(value)?)?;
            qos.link = Some(l);
        }
        "delay_ms" | "jitter_ms" => {
            let mut l = link(qos);
            let v = ms_to_nanos(key, num(value)?, true)?;
            let auto = l.retransmit == Link::default_retransmit(l.delay, l.jitter);
            if key == "delay_ms" {
                l.delay = v;
            } else {
                l.jitter = v;
            }
            if auto {
                l.retransmit = Link::default_retransmit(l.delay, l.jitter);
            }
            qos.link = Some(l);
        }
        "retransmit_ms" => {
            let mut l = link(qos);
            l.retransmit = ms_to_nanos("retransmit_ms", num(value)?, false)?;
            qos.link = Some(l);
        }
        other => return Err(format!("unknown QoS key '{other}' (known: {KEYS})")),
    }
    Ok(())
}

/// One of an enum's words, by its serde name (the graph file's spelling): one source of names.
fn word<E: serde::de::DeserializeOwned>(key: &str, value: &str) -> Result<E, String> {
    use serde::de::IntoDeserializer;
    E::deserialize(value.trim().into_deserializer())
        .map_err(|e: serde::de::value::Error| format!("{key}: {e}"))
}

/// A `KEY=VALUE[,KEY=VALUE…]` list, split (the values are numbers or words; none holds a
/// comma or an equals sign).
///
/// # Errors
/// A one-line reason for a pair without `=`, a key given twice, or an empty list.
pub fn split_pairs(list: &str) -> Result<Vec<(&str, &str)>, String> {
    let pairs = list
        .split(',')
        .map(|p| {
            p.split_once('=')
                .map(|(k, v)| (k.trim(), v.trim()))
                .filter(|(k, v)| !k.is_empty() && !v.is_empty())
                .ok_or_else(|| format!("expected KEY=VALUE, got '{p}'"))
        })
        .collect::<Result<Vec<_>, _>>()?;
    if pairs.is_empty() {
        return Err("expected KEY=VALUE[,KEY=VALUE…]".into());
    }
    // A key twice would have the last win unseen (`depth=3,depth=5`): refused, naming it.
    let mut seen = std::collections::HashSet::with_capacity(pairs.len());
    if let Some((k, _)) = pairs.iter().find(|(k, _)| !seen.insert(*k)) {
        return Err(format!("'{}' is given twice", crate::text::printable(k)));
    }
    Ok(pairs)
}

/// A QoS counter a topic reports (see `TopicStats` in [`crate::topic`] for each one's
/// meaning; `TopicStats::counter` reads one, `TopicStats::reported` lists a topic's).
/// Outputs (metrics.json, trace.csv, the lab, recordings) show a counter when the QoS that
/// can make it count is on, or when it has counted (a live change may have turned it off
/// since): a topic with the chapter's QoS adds nothing, so its outputs are unchanged.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum QosCounter {
    /// Unread messages that outlived the lifespan.
    Expired,
    /// Publishes a full keep-all queue refused.
    Refused,
    /// Messages the link lost.
    Lost,
    /// A reliable link's extra sends.
    Retransmitted,
    /// Deadline periods the publisher missed.
    OfferedDeadlineMissed,
    /// Deadline periods with nothing arriving at the subscriber.
    RequestedDeadlineMissed,
}

impl QosCounter {
    /// Every counter, in output order.
    pub const ALL: [QosCounter; 6] = [
        QosCounter::Expired,
        QosCounter::Refused,
        QosCounter::Lost,
        QosCounter::Retransmitted,
        QosCounter::OfferedDeadlineMissed,
        QosCounter::RequestedDeadlineMissed,
    ];

    /// Its key in metrics.json and (after the topic's prefix) its trace.csv column.
    pub fn key(self) -> &'static str {
        match self {
            QosCounter::Expired => "expired",
            QosCounter::Refused => "refused",
            QosCounter::Lost => "lost",
            QosCounter::Retransmitted => "retransmitted",
            QosCounter::OfferedDeadlineMissed => "offered_deadline_missed",
            QosCounter::RequestedDeadlineMissed => "requested_deadline_missed",
        }
    }

    /// True when `q` can make it count.
    pub fn enabled_by(self, q: &TopicQos) -> bool {
        match self {
            QosCounter::Expired => q.lifespan.is_some(),
            QosCounter::Refused => q.history == History::KeepAll,
            QosCounter::Lost => q.link.is_some(),
            QosCounter::Retransmitted => q.link.is_some() && q.reliability == Reliability::Reliable,
            QosCounter::OfferedDeadlineMissed | QosCounter::RequestedDeadlineMissed => {
                q.deadline.is_some()
            }
        }
    }
}

/// A node's liveliness as ROS 2 defines it for automatic liveliness: the node asserts it by
/// running (every tick), and with a lease it is *not alive* once it has not ticked for
/// longer than the lease. Counted once per loss (alive → not alive), observed at any
/// instant without waiting for the next tick. Also counts the ticks a fault
/// (`--stall`, `--kill`) swallowed.
#[derive(Debug)]
pub struct Liveliness {
    inner: std::sync::Mutex<LiveInner>,
}

#[derive(Debug, Clone, Copy)]
struct LiveInner {
    lease: Option<Nanos>,
    last: Nanos,
    lost: u64,
    faulted_ticks: u64,
}

/// A [`Liveliness`]'s state at an instant ([`Liveliness::save`]).
#[derive(Clone, Copy, Debug)]
pub struct LivelinessState(LiveInner);

/// A node's liveliness at one instant.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct LivelinessStatus {
    /// False when a lease is set and the node has not ticked within it.
    pub alive: bool,
    /// Times the node went from alive to not alive (the current loss included).
    pub not_alive: u64,
    /// The node's last tick (its last assertion).
    pub last_asserted: Nanos,
    /// Ticks a fault swallowed.
    pub faulted_ticks: u64,
}

impl Liveliness {
    /// Alive at the start, with `lease` (`None`: never reported not alive).
    pub fn new(lease: Option<Nanos>) -> Self {
        Self {
            inner: std::sync::Mutex::new(LiveInner {
                lease,
                last: Nanos::ZERO,
                lost: 0,
                faulted_ticks: 0,
            }),
        }
    }

    /// Its lease, last assertion and counters now, for a capture of the run
    /// (`ratelab::runcore`).
    pub fn save(&self) -> LivelinessState {
        LivelinessState(*self.lock())
    }

    /// Put back what [`Liveliness::save`] gave.
    pub fn load(&self, state: LivelinessState) {
        *self.lock() = state.0;
    }

    fn lock(&self) -> std::sync::MutexGuard<'_, LiveInner> {
        self.inner.lock().unwrap_or_else(|e| e.into_inner())
    }

    /// The node ticked at `now`.
    pub fn assert_at(&self, now: Nanos) {
        let mut l = self.lock();
        if l.lease
            .is_some_and(|lease| now.saturating_sub(l.last) > lease)
        {
            l.lost += 1;
        }
        l.last = l.last.max(now);
    }

    /// The node comes into being at `at` (it joins the graph late): its lease runs from
    /// then, not from t = 0. Set before the run starts.
    pub fn starts_at(&self, at: Nanos) {
        let mut l = self.lock();
        l.last = l.last.max(at);
    }

    /// A fault swallowed the node's tick at `now`: no assertion.
    pub fn fault_tick(&self) {
        self.lock().faulted_ticks += 1;
    }

    /// Change the lease while running.
    pub fn set_lease(&self, lease: Option<Nanos>) {
        self.lock().lease = lease;
    }

    /// The lease in force.
    pub fn lease(&self) -> Option<Nanos> {
        self.lock().lease
    }

    /// The status at run time `now`.
    pub fn status_at(&self, now: Nanos) -> LivelinessStatus {
        let l = *self.lock();
        let lapsed = l
            .lease
            .is_some_and(|lease| now.saturating_sub(l.last) > lease);
        LivelinessStatus {
            alive: !lapsed,
            not_alive: l.lost + u64::from(lapsed),
            last_asserted: l.last,
            faulted_ticks: l.faulted_ticks,
        }
    }
}

pub use crate::limits::MAX_FAULTS;

/// A fault injected into one node (`--stall NODE@T+D`, `--kill NODE@T`): from run time
/// `at` (for `duration`, or for good when `None`) the node's ticks do nothing and assert no
/// liveliness, as a node blocked in a callback or a crashed process would.
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Fault {
    /// The node's name.
    pub node: String,
    /// When it starts, run time.
    pub at: Nanos,
    /// How long it lasts; `None` for a kill.
    pub duration: Option<Nanos>,
}

impl Fault {
    /// This fault as it takes effect when applied before the instant at `from` (run time),
    /// while the run goes on: from its own time when that is later, else from `from`, a
    /// stall still ending when it was set to (a time already past covers the ticks from
    /// `from` on that it would have covered; one whose end has passed covers none). What
    /// a run's fault book holds, so its summary and its telemetry give the same start.
    pub fn from_instant(&self, from: Nanos) -> Fault {
        let at = self.at.max(from);
        Fault {
            node: self.node.clone(),
            at,
            duration: self
                .duration
                .map(|d| self.at.saturating_add(d).saturating_sub(at)),
        }
    }

    /// True when a tick at `now` is swallowed.
    pub fn covers(&self, now: Nanos) -> bool {
        now >= self.at
            && self
                .duration
                .is_none_or(|d| now < self.at.saturating_add(d))
    }

    /// Parse `NODE@T+D` (a stall) or, with `kill`, `NODE@T`. Times are seconds of run time,
    /// with an optional `s` or `ms` suffix (`policy@2+0.5`, `policy@2s+500ms`).
    ///
    /// # Errors
    /// A one-line reason.
    pub fn parse(s: &str, kill: bool) -> Result<Fault, String> {
        let form = if kill { "NODE@T" } else { "NODE@T+D" };
        let (node, when) = s
            .split_once('@')
            .ok_or_else(|| format!("expected {form}, got '{s}'"))?;
        let time = |t: &str| -> Result<Nanos, String> {
            let t = t.trim();
            let (num, scale) = if let Some(v) = t.strip_suffix("ms") {
                (v, 1e-3)
            } else if let Some(v) = t.strip_suffix('s') {
                (v, 1.0)
            } else {
                (t, 1.0)
            };
            // Plain decimals to the nanosecond are read exactly (a booked `k`'s
            // `9.380000000`): through an `f64`, a time past 2^51 ns could land 1 ns off.
            let (unit_ns, decimals) = if scale == 1.0 {
                (1_000_000_000, 9)
            } else {
                (1_000_000, 6)
            };
            if let Some(ns) = exact_ns(num.trim(), unit_ns, decimals) {
                if ns > crate::time::MAX_DURATION.0 {
                    return Err(format!("time '{t}' must be in [0, {}] s", MAX_DURATION_S));
                }
                return Ok(Nanos(ns));
            }
            let secs = num
                .trim()
                .parse::<f64>()
                .map_err(|_| format!("not a time: '{t}' (seconds, or with s/ms)"))?
                * scale;
            if !(secs.is_finite() && (0.0..=MAX_DURATION_S).contains(&secs)) {
                return Err(format!("time '{t}' must be in [0, {}] s", MAX_DURATION_S));
            }
            Nanos::from_secs_f64(secs).ok_or_else(|| format!("time '{t}' is out of range"))
        };
        let (at, duration) = if kill {
            (time(when)?, None)
        } else {
            let (at, d) = when
                .split_once('+')
                .ok_or_else(|| format!("expected {form}, got '{s}'"))?;
            let d = time(d)?;
            if d == Nanos::ZERO {
                return Err(format!("a stall of 0 s does nothing: '{s}'"));
            }
            (time(at)?, Some(d))
        };
        if node.trim().is_empty() {
            return Err(format!("expected {form}, got '{s}'"));
        }
        Ok(Fault {
            node: node.trim().to_string(),
            at,
            duration,
        })
    }
}

/// `num` in units of `unit_ns` nanoseconds, exactly, when it is plain decimal digits with at
/// most `decimals` of them after the point (`9.380000000` seconds: `unit_ns` 10^9, 9
/// decimals); `None` for any other form (an exponent, a sign, more decimals), which the
/// caller reads as an `f64`, or on overflow.
fn exact_ns(num: &str, unit_ns: u64, decimals: u32) -> Option<u64> {
    let (whole, frac) = num.split_once('.').unwrap_or((num, ""));
    let digits = |d: &str| d.bytes().all(|b| b.is_ascii_digit());
    if whole.is_empty() || !digits(whole) || !digits(frac) || frac.len() > decimals as usize {
        return None;
    }
    let part = match frac {
        "" => 0,
        f => f.parse::<u64>().ok()? * 10u64.pow(decimals - f.len() as u32),
    };
    whole
        .parse::<u64>()
        .ok()?
        .checked_mul(unit_ns)?
        .checked_add(part)
}

impl std::fmt::Display for Fault {
    /// `stall policy@2 s+500 ms` or `kill policy@2 s`.
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self.duration {
            Some(d) => write!(f, "stall {}@{}+{}", self.node, self.at, d),
            None => write!(f, "kill {}@{}", self.node, self.at),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn set(pairs: &str) -> Result<(TopicQos, usize), String> {
        let mut q = TopicQos::default();
        let mut d = 1;
        for (k, v) in split_pairs(pairs)? {
            apply_key(&mut q, &mut d, k, v)?;
        }
        Ok((q, d))
    }

    #[test]
    fn a_key_given_twice_is_refused_naming_it() {
        assert_eq!(
            set("depth=3,depth=5").unwrap_err(),
            "'depth' is given twice"
        );
        assert_eq!(set("depth=3, reliability=reliable").unwrap().1, 3);
    }

    #[test]
    fn a_fault_takes_effect_from_its_instant_a_stall_ending_when_set_to() {
        let ms = |m: u64| Nanos(m * 1_000_000);
        let stall = Fault::parse("policy@2+0.5", false).unwrap();
        let later = stall.from_instant(ms(2_200));
        assert_eq!((later.at, later.duration), (ms(2_200), Some(ms(300))));
        assert_eq!(
            stall.from_instant(ms(1_000)),
            stall,
            "its own time, when later"
        );
        let over = stall.from_instant(ms(3_000));
        assert_eq!(over.duration, Some(Nanos::ZERO));
        assert!(
            !(over.covers(ms(3_000))),
            "a stall whose end has passed covers nothing"
        );
        let kill = Fault::parse("sensor@1", true)
            .unwrap()
            .from_instant(ms(4_000));
        assert_eq!((kill.at, kill.duration), (ms(4_000), None));
    }

    #[test]
    fn the_issue_examples_parse() {
        let (q, d) = set("history=keep_last,depth=100,delivery=fifo").unwrap();
        assert_eq!(
            (q.history, q.delivery, d),
            (History::KeepLast, Delivery::Fifo, 100)
        );
        let (q, _) = set("deadline_ms=40,lifespan_ms=60").unwrap();
        assert_eq!(q.deadline, Some(Nanos::from_millis(40)));
        assert_eq!(q.lifespan, Some(Nanos::from_millis(60)));
        let (q, _) = set("loss=0.2,delay_ms=10,jitter_ms=3").unwrap();
        let l = q.link.unwrap();
        assert_eq!(
            (l.loss, l.delay, l.jitter),
            (0.2, Nanos::from_millis(10), Nanos::from_millis(3))
        );
        assert_eq!(l.retransmit, Nanos::from_millis(26), "2 × (10 + 3) ms");
        let (q, _) = set("delay_ms=10,retransmit_ms=5,jitter_ms=3").unwrap();
        assert_eq!(
            q.link.unwrap().retransmit,
            Nanos::from_millis(5),
            "an explicit timeout stays"
        );
        assert_eq!(q.short(1), "KL1 latest link 0%");
        // `none` turns them off (a later `--qos` on a topic whose graph file set them).
        let (mut q, mut d) = set("deadline_ms=40,lifespan_ms=50").unwrap();
        for (k, v) in split_pairs("deadline_ms=none,lifespan_ms=none").unwrap() {
            apply_key(&mut q, &mut d, k, v).unwrap();
        }
        assert_eq!((q.deadline, q.lifespan), (None, None));
    }

    #[test]
    fn each_bad_value_is_one_line() {
        for (pairs, needle) in [
            ("depth=0", "depth must be in 1..="),
            ("lifespan_ms=0", "lifespan_ms must be > 0"),
            ("deadline_ms=-5", "deadline_ms must be > 0"),
            ("deadline_ms=nan", "deadline_ms must be > 0"),
            ("loss=1.5", "loss must be a probability"),
            ("delay_ms=-1", "delay_ms must be ≥ 0"),
            (
                "delivery=newest",
                "delivery: unknown variant `newest`, expected `latest` or `fifo`",
            ),
            ("colour=red", "unknown QoS key 'colour'"),
            ("depth", "expected KEY=VALUE"),
        ] {
            let e = set(pairs).unwrap_err();
            assert!(e.contains(needle), "{pairs}: {e}");
            assert!(!e.contains('\n'));
        }
    }

    #[test]
    fn combinations() {
        let (q, _) = set("on_deadline_missed=zero").unwrap();
        assert!(check_combination(&q, true)
            .unwrap_err()
            .contains("needs a deadline_ms"));
        let (q, _) = set("on_deadline_missed=zero,deadline_ms=40").unwrap();
        assert!(check_combination(&q, true).is_ok());
        assert!(check_combination(&q, false)
            .unwrap_err()
            .contains("actuator"));
        let (q, _) = set("reliability=reliable,loss=1").unwrap();
        assert!(check_combination(&q, false)
            .unwrap_err()
            .contains("never delivers"));
        let (q, _) = set("reliability=best_effort,loss=1").unwrap();
        assert!(check_combination(&q, false).is_ok());
    }

    #[test]
    fn short_labels() {
        assert_eq!(TopicQos::default().short(1), "KL1 latest");
        let (q, d) = set("history=keep_all,depth=100,delivery=fifo,deadline_ms=40,loss=0.05,reliability=reliable").unwrap();
        assert_eq!(q.short(d), "KA100 fifo dl 40 ms link 5% rel");
        // Nothing set is hidden: what a missed deadline does, reliability without a link.
        let (q, d) = set("deadline_ms=40,on_deadline_missed=stop,reliability=reliable").unwrap();
        assert_eq!(q.short(d), "KL1 latest dl 40 ms stop rel");
        let (q, d) = set("deadline_ms=40,on_deadline_missed=zero,lifespan_ms=60").unwrap();
        assert_eq!(q.short(d), "KL1 latest dl 40 ms zero ls 60 ms");
    }

    #[test]
    fn liveliness_is_lost_once_per_lapse_and_seen_before_the_next_tick() {
        let l = Liveliness::new(Some(Nanos::from_millis(50)));
        l.assert_at(Nanos::from_millis(20));
        assert!(
            l.status_at(Nanos::from_millis(70)).alive,
            "50 ms since: within the lease"
        );
        let s = l.status_at(Nanos::from_millis(71));
        assert_eq!((s.alive, s.not_alive), (false, 1));
        l.assert_at(Nanos::from_millis(200)); // back
        let s = l.status_at(Nanos::from_millis(200));
        assert_eq!(
            (s.alive, s.not_alive),
            (true, 1),
            "the same loss, now committed"
        );
        assert!(Liveliness::new(None).status_at(Nanos::SECOND).alive);
    }

    #[test]
    fn faults_parse_and_cover_their_interval() {
        let f = Fault::parse("policy@2+0.5", false).unwrap();
        assert_eq!(
            (f.at, f.duration),
            (Nanos::from_millis(2000), Some(Nanos::from_millis(500)))
        );
        assert!(!f.covers(Nanos::from_millis(1999)));
        assert!(f.covers(Nanos::from_millis(2000)));
        assert!(f.covers(Nanos::from_millis(2499)));
        assert!(!f.covers(Nanos::from_millis(2500)));
        assert_eq!(Fault::parse("policy@2s+500ms", false).unwrap(), f);
        let k = Fault::parse("sensor@1.5", true).unwrap();
        assert!(k.covers(Nanos::from_millis(100_000)) && !k.covers(Nanos::SECOND));
        assert_eq!(k.to_string(), "kill sensor@1.5 s");
        for bad in [
            "policy",
            "policy@x+1",
            "@1+1",
            "policy@1+0",
            "policy@-1+1",
            "policy@1e9+1",
            "policy@315360000.000000001+1",
        ] {
            assert!(Fault::parse(bad, false).is_err(), "{bad}");
        }
    }

    #[test]
    fn plain_decimal_times_are_read_to_the_nanosecond() {
        let at = |t: &str| Fault::parse(&format!("p@{t}"), true).unwrap().at.0;
        // 48.5 days of 20 ms instants: through an f64, this one came back 1 ns late.
        assert_eq!(at("4194304.280000000"), 4_194_304_280_000_000);
        assert_eq!(at("12.5ms"), 12_500_000);
        assert_eq!(at("0.000000001"), 1);
        assert_eq!(at("315360000"), crate::time::MAX_DURATION.0);
        // Other forms still read as f64: an exponent, more decimals than a nanosecond.
        assert_eq!(at("1e-3"), 1_000_000);
        assert_eq!(at("0.0000000014"), 1);
        // Every nanosecond of [2^51, 2^53) sampled, written as `stall_from` writes it.
        let mut x = 0x9E37_79B9_7F4A_7C15_u64;
        for _ in 0..10_000 {
            x ^= x << 13;
            x ^= x >> 7;
            x ^= x << 17;
            let ns = (1u64 << 51) + x % (3u64 << 51);
            let t = Nanos(ns).secs_exact();
            assert_eq!(at(&t), ns, "{t}");
        }
    }
}
