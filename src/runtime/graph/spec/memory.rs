//! What a graph's queues may hold at worst, and its bound
//! ([`ratelab_core::limits::MAX_GRAPH_QUEUE_BYTES`], whose documentation states the rule): every
//! subscription's queue of its topic's depth (and what is in flight on a link), times the
//! largest message of the topic's type — a camera's frame at the size its node gives.
//! Computed when a graph file is read ([`super::build`]) and again at every change of a
//! depth, QoS or rate ([`GraphSpec::set_depth`] and the others), so that a graph that would
//! fill the machine is refused before it runs, in one line naming the topics that take the
//! most.

use super::{GraphSpec, OverrideError, TopicId, TopicSpec};
use crate::graph::kind::Code;
use crate::graph::nodes::camera;
use ratelab_core::limits::{self, MAX_GRAPH_QUEUE_BYTES, MAX_SAMPLE_BYTES};
use ratelab_core::msg::{FieldKind, ImageMsg, Message};
use ratelab_core::qos::{Reliability, MAX_ATTEMPTS};

/// What a queued message holds beside its fields, bytes: its publish stamp, sequence
/// number and origin stamp, and on a link its arrival time.
const MESSAGE_STAMPS_BYTES: u64 = 40;

/// The most topics a refusal names: the largest, until they make 90% of the whole (the
/// rest are counted).
const NAMED_TOPICS: usize = 3;

/// The bytes a field of `kind` takes in the message itself: a number's 8, a text's or a
/// bytes field's handle (their contents are counted apart, [`GraphSpec::largest_message_bytes`]).
fn field_slot_bytes(kind: FieldKind) -> u64 {
    match kind {
        FieldKind::Number | FieldKind::Integer => 8,
        // A `String`: pointer, capacity, length.
        FieldKind::Text => 24,
        // An `ImageData` (a `bytes::Bytes`): pointer, length, owner, vtable.
        FieldKind::Bytes => std::mem::size_of::<ratelab_core::msg::ImageData>() as u64,
    }
}

/// `bytes` for people: `16 MiB`, `15.6 GiB`, `300 KiB`, `72 B`.
pub(super) fn bytes_text(bytes: u64) -> String {
    const UNITS: [&str; 4] = ["KiB", "MiB", "GiB", "TiB"];
    if bytes < 1024 {
        return format!("{bytes} B");
    }
    let mut value = bytes as f64 / 1024.0;
    let mut unit = 0;
    while value >= 1024.0 && unit + 1 < UNITS.len() {
        value /= 1024.0;
        unit += 1;
    }
    let shown = format!("{value:.1}");
    format!(
        "{} {}",
        shown.strip_suffix(".0").unwrap_or(&shown),
        UNITS[unit]
    )
}

impl GraphSpec {
    /// The most bytes one message on topic `t` may take in a queue: its fields (8 bytes a
    /// number, a text or bytes field's handle) and stamps, doubled (a queue's slots grow by
    /// doubling), plus, for a type with text or bytes fields, their contents: a `camera`'s
    /// frame (`width_px` × `height_px` bytes, `mono8`, and its encoding's name) when a camera
    /// publishes the topic, else the bound on one message,
    /// [`ratelab_core::limits::MAX_SAMPLE_BYTES`].
    pub fn largest_message_bytes(&self, t: TopicId) -> u64 {
        let topic = self.topic(t);
        let fields = topic.msg.fields();
        let slots: u64 = fields.iter().map(|f| field_slot_bytes(f.kind)).sum();
        let unbounded = fields
            .iter()
            .any(|f| matches!(f.kind, FieldKind::Text | FieldKind::Bytes));
        let contents = if unbounded {
            self.implied_contents(topic)
                .unwrap_or(MAX_SAMPLE_BYTES as u64)
        } else {
            0
        };
        (slots + MESSAGE_STAMPS_BYTES)
            .saturating_mul(2)
            .saturating_add(contents)
    }

    /// The contents of a message on `topic` as its publisher implies them: a built-in
    /// camera's frame and its encoding's name; `None` when nothing bounds them.
    fn implied_contents(&self, topic: &TopicSpec) -> Option<u64> {
        let p = self.nodes.get(topic.publisher.0)?;
        let is_camera = p.kind.as_str() == camera::NAME && p.kind.code() == Code::BuiltIn;
        // The encoding's name (`mono8`), with room to spare.
        const ENCODING_BYTES: u64 = 16;
        (is_camera && topic.msg == ImageMsg::TYPE)
            .then(|| camera::frame_bytes(&p.params).saturating_add(ENCODING_BYTES))
    }

    /// The most messages one subscription's queue of `topic` may hold at once: its depth,
    /// and on a link those in flight (published within the longest transit, at the
    /// publisher's rate now: delay + jitter, and [`MAX_ATTEMPTS`] − 1 retransmissions on a
    /// reliable link).
    pub fn queued_per_subscription(&self, t: TopicId) -> u64 {
        let topic = self.topic(t);
        let depth = topic.depth as u64;
        let Some(link) = topic.qos.link else {
            return depth;
        };
        let retries = match topic.qos.reliability {
            Reliability::Reliable => u64::from(MAX_ATTEMPTS.saturating_sub(1)),
            Reliability::BestEffort => 0,
        };
        let transit_ns = link
            .delay
            .0
            .saturating_add(link.jitter.0)
            .saturating_add(link.retransmit.0.saturating_mul(retries));
        let hz = self.nodes.get(topic.publisher.0).map_or(0.0, |n| n.rate_hz);
        // Published within one transit: the rate × the transit, rounded up, and one more.
        // (`as` saturates: an absurd product is u64::MAX, refused.)
        let in_flight = (hz * transit_ns as f64 / 1e9).ceil() as u64;
        depth.saturating_add(in_flight).saturating_add(1)
    }

    /// What topic `t`'s queues may hold at worst, bytes: each subscription's queue (one when
    /// nobody subscribes) of [`GraphSpec::queued_per_subscription`] messages, and the one
    /// message its publisher holds, each of [`GraphSpec::largest_message_bytes`].
    pub fn topic_queue_bytes(&self, t: TopicId) -> u64 {
        let queues = self.topic(t).subscribers.len().max(1) as u64;
        queues
            .saturating_mul(self.queued_per_subscription(t))
            .saturating_add(1)
            .saturating_mul(self.largest_message_bytes(t))
    }

    /// What the graph's queues may hold at worst, bytes: the sum of its topics'
    /// ([`GraphSpec::topic_queue_bytes`]), bounded by
    /// [`ratelab_core::limits::MAX_GRAPH_QUEUE_BYTES`].
    pub fn queue_bytes(&self) -> u64 {
        (0..self.topics.len())
            .map(|i| self.topic_queue_bytes(TopicId(i)))
            .fold(0, u64::saturating_add)
    }

    /// Check the graph's worst case against [`ratelab_core::limits::MAX_GRAPH_QUEUE_BYTES`].
    ///
    /// # Errors
    /// One line: the graph's worst case, the topics that take the most (each with its
    /// queues, depth and largest message), and the bound.
    pub fn check_queue_bytes(&self) -> Result<(), OverrideError> {
        match self.queue_refusal() {
            Some((_, line)) => Err(OverrideError(line)),
            None => Ok(()),
        }
    }

    /// The refusal line when the graph's worst case is past the bound, with the topic that
    /// takes the most (where a graph file's error points); `None` within it.
    pub(super) fn queue_refusal(&self) -> Option<(TopicId, String)> {
        let per_topic: Vec<u64> = (0..self.topics.len())
            .map(|i| self.topic_queue_bytes(TopicId(i)))
            .collect();
        let total = per_topic.iter().copied().fold(0, u64::saturating_add);
        if total <= MAX_GRAPH_QUEUE_BYTES {
            return None;
        }
        let mut order: Vec<usize> = (0..per_topic.len()).collect();
        // The largest first; ties in file order.
        order.sort_by(|&a, &b| per_topic[b].cmp(&per_topic[a]).then(a.cmp(&b)));
        // The topics that dominate: the largest, until they make 90% of the whole.
        let mut covered = 0u64;
        let count = order
            .iter()
            .take(NAMED_TOPICS)
            .take_while(|&&i| {
                let more = (covered as f64) < 0.9 * total as f64;
                covered = covered.saturating_add(per_topic[i]);
                more
            })
            .count()
            .max(1);
        let named: Vec<String> = order
            .iter()
            .take(count)
            .map(|&i| {
                let t = &self.topics[i];
                let queues = t.subscribers.len().max(1);
                let id = TopicId(i);
                format!(
                    "{} {} ({queues} queue{} × {} message{} of up to {})",
                    t.name,
                    bytes_text(per_topic[i]),
                    if queues == 1 { "" } else { "s" },
                    self.queued_per_subscription(id),
                    if self.queued_per_subscription(id) == 1 {
                        ""
                    } else {
                        "s"
                    },
                    bytes_text(self.largest_message_bytes(id))
                )
            })
            .collect();
        let rest = order.len().saturating_sub(count);
        let rest_bytes = order
            .iter()
            .skip(count)
            .map(|&i| per_topic[i])
            .fold(0, u64::saturating_add);
        let more = match rest {
            0 => String::new(),
            1 => format!(", and 1 topic more ({})", bytes_text(rest_bytes)),
            n => format!(", and {n} topics more ({})", bytes_text(rest_bytes)),
        };
        let line = limits::refusal(
            format_args!(
                "graph '{}': its queues may hold {} at worst, past the budget of {}: {}{more}; lower the depth of the topics that take the most (or a camera's frame, or a link's delay)",
                self.name,
                bytes_text(total),
                bytes_text(MAX_GRAPH_QUEUE_BYTES),
                named.join(", ")
            ),
            "MAX_GRAPH_QUEUE_BYTES",
        );
        Some((TopicId(order[0]), line))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A camera of `w` × `h` px on `/image` at `depth`, read by an image estimator, with
    /// the chapter's loop behind it.
    fn camera_graph(w: u32, h: u32, depth: usize) -> String {
        include_str!("../../../../graphs/cartpole-camera.toml")
            .replace(
                "params = { width_px = 640, height_px = 480 }",
                &format!("params = {{ width_px = {w}, height_px = {h} }}"),
            )
            .replace(
                "name = \"/image\"\ntype = \"image\"            # sensor_msgs/Image fields: height, width, encoding, step, data\ndepth = 1",
                &format!("name = \"/image\"\ntype = \"image\"\ndepth = {depth}"),
            )
    }

    #[test]
    fn sizes_read_as_people_write_them() {
        assert_eq!(bytes_text(72), "72 B");
        assert_eq!(bytes_text(300 << 10), "300 KiB");
        assert_eq!(bytes_text(16 << 20), "16 MiB");
        assert_eq!(bytes_text(4 << 30), "4 GiB");
        assert_eq!(bytes_text(16_000 << 20), "15.6 GiB");
        assert_eq!(bytes_text(1536), "1.5 KiB");
    }

    #[test]
    fn a_numeric_message_is_its_fields_and_stamps_doubled() {
        let g = GraphSpec::chapter();
        let obs = g.topic_id("/obs").unwrap();
        let fields = g.topic(obs).msg.fields().len() as u64;
        assert!(fields > 0);
        let one = 2 * (8 * fields + MESSAGE_STAMPS_BYTES);
        assert_eq!(g.largest_message_bytes(obs), one);
        // Depth 1, one subscriber, and the publisher's own: two messages.
        assert_eq!(g.queued_per_subscription(obs), 1);
        assert_eq!(g.topic_queue_bytes(obs), 2 * one);
        // The chapter's graph takes a few hundred bytes at worst.
        assert!(g.queue_bytes() < 4096, "{}", g.queue_bytes());
        assert_eq!(g.check_queue_bytes(), Ok(()));
    }

    #[test]
    fn a_cameras_frame_is_the_size_its_node_gives() {
        let g = GraphSpec::parse(&camera_graph(640, 480, 1), "cam.toml").unwrap();
        let image = g.topic_id("/image").unwrap();
        let pixels = std::mem::size_of::<ratelab_core::msg::ImageData>() as u64;
        let slots = 2 * (8 + 8 + 24 + 8 + pixels + MESSAGE_STAMPS_BYTES);
        assert_eq!(g.largest_message_bytes(image), slots + 640 * 480 + 16);
        // One queue (the vision node's) of depth 1, and the frame the camera holds.
        assert_eq!(g.topic_queue_bytes(image), 2 * (slots + 640 * 480 + 16));
        // Every shipped camera graph is far below the budget.
        assert!(g.queue_bytes() < 1 << 20, "{}", g.queue_bytes());
        // A frame left to its defaults is 640 × 480; one out of range is clamped.
        assert_eq!(camera::frame_bytes(&toml::Table::new()), 640 * 480);
        let mut big = toml::Table::new();
        big.insert("width_px".into(), toml::Value::Integer(1 << 20));
        big.insert("height_px".into(), toml::Value::Float(4095.6));
        assert_eq!(camera::frame_bytes(&big), 4096 * 4096);
    }

    #[test]
    fn a_deep_queue_of_large_frames_is_refused_in_one_line_naming_the_topic() {
        // Issue 75: a 4096 × 4096 camera at 100 Hz, /image at depth 1000 (read at 0.1 Hz):
        // 15.6 GiB of frames at worst.
        let text = camera_graph(4096, 4096, 1000).replace(
            "rate_hz = 30\npublishes = \"/image\"",
            "rate_hz = 100\npublishes = \"/image\"",
        );
        let e = GraphSpec::parse(&text, "cam.toml").unwrap_err();
        let line = e.to_string();
        assert_eq!(line.lines().count(), 1, "{line}");
        assert!(
            line.contains("graph 'cartpole-camera': its queues may hold 15.6 GiB at worst, past the budget of 4 GiB: /image 15.6 GiB (1 queue × 1000 messages of up to 16 MiB)"),
            "{line}"
        );
        assert!(line.contains(", and 3 topics more ("), "{line}");
        assert!(
            line.ends_with("(ratelab::limits::MAX_GRAPH_QUEUE_BYTES)"),
            "{line}"
        );
        // It points at the culprit's depth.
        let depth_line = text.lines().position(|l| l == "depth = 1000").unwrap() + 1;
        assert_eq!((e.line, e.col), (depth_line, 9), "{line}");
        // At depth 100 it fits (1.6 GiB).
        let g = GraphSpec::parse(&camera_graph(4096, 4096, 100), "cam.toml").unwrap();
        let bytes = g.queue_bytes();
        assert!(bytes > 100 * (16 << 20) && bytes < 2 << 30, "{bytes}");
    }

    #[test]
    fn every_subscription_has_a_queue_of_its_own() {
        // A second reader of /image doubles its queues.
        let text = format!(
            "{}\n[[node]]\nname = \"look\"\nkind = \"python\"\nscript = \"l.py\"\nrate_hz = 1\nsubscribes = \"/image\"\n",
            camera_graph(4096, 4096, 10)
        );
        let one = GraphSpec::parse(&camera_graph(4096, 4096, 10), "a.toml").unwrap();
        let two = GraphSpec::parse(&text, "b.toml").unwrap();
        let image = one.topic_id("/image").unwrap();
        let frame = one.largest_message_bytes(image);
        assert_eq!(one.topic_queue_bytes(image), (10 + 1) * frame);
        assert_eq!(two.topic_queue_bytes(image), (2 * 10 + 1) * frame);
    }

    #[test]
    fn an_image_of_no_implied_size_counts_the_largest_message() {
        // A Python node's image: nothing says its size, so one message's bound.
        let text = format!(
            "{}\n[[node]]\nname = \"painter\"\nkind = \"python\"\nscript = \"p.py\"\nrate_hz = 1\npublishes = \"/painted\"\n\
             [[topic]]\nname = \"/painted\"\ntype = \"image\"\ndepth = 1\n",
            include_str!("../../../../graphs/cartpole.toml")
        );
        let g = GraphSpec::parse(&text, "p.toml").unwrap();
        let painted = g.topic_id("/painted").unwrap();
        assert!(g.largest_message_bytes(painted) > MAX_SAMPLE_BYTES as u64);
        // At depth 64 with its one queue and the publisher's message: past 4 GiB.
        let deep = text.replace(
            "name = \"/painted\"\ntype = \"image\"\ndepth = 1",
            "name = \"/painted\"\ntype = \"image\"\ndepth = 64",
        );
        let e = GraphSpec::parse(&deep, "p.toml").unwrap_err();
        assert!(
            e.reason
                .contains("/painted 4.1 GiB (1 queue × 64 messages of up to 64 MiB)"),
            "{e}"
        );
    }

    #[test]
    fn a_link_counts_what_is_in_flight() {
        let mut g = GraphSpec::chapter();
        let obs = g.topic_id("/obs").unwrap();
        // 50 Hz over 100 ms ± 20 ms: 6 in flight, and one more.
        g.set_qos("/obs", "delay_ms=100,jitter_ms=20").unwrap();
        assert_eq!(g.queued_per_subscription(obs), 1 + 6 + 1);
        // Reliable: 15 retransmissions of 10 ms each on top.
        g.set_qos("/obs", "reliability=reliable,retransmit_ms=10")
            .unwrap();
        assert_eq!(g.queued_per_subscription(obs), 1 + 6 + 8 + 1);
    }

    #[test]
    fn changes_past_the_budget_are_refused_and_change_nothing() {
        let mut g = GraphSpec::parse(&camera_graph(4096, 4096, 1), "cam.toml").unwrap();
        let before = g.clone();
        let e = g.set_depth("/image", 1000).unwrap_err();
        assert!(e.0.contains("MAX_GRAPH_QUEUE_BYTES"), "{e}");
        assert!(e.0.contains("/image 15.6 GiB"), "{e}");
        assert_eq!(g, before);
        let e = g.set_all_depths(1000).unwrap_err();
        assert!(e.0.contains("MAX_GRAPH_QUEUE_BYTES"), "{e}");
        assert_eq!(g, before);
        let e = g.set_qos("/image", "depth=1000").unwrap_err();
        assert!(e.0.contains("MAX_GRAPH_QUEUE_BYTES"), "{e}");
        assert_eq!(g, before);
        // A link's in-flight frames grow with its publisher's rate: 1 s of delay at 30 Hz
        // fits, at 1000 Hz it does not.
        g.set_qos("/image", "delay_ms=1000").unwrap();
        let with_link = g.clone();
        let e = g.set_rate("camera", 1000.0).unwrap_err();
        assert!(e.0.contains("MAX_GRAPH_QUEUE_BYTES"), "{e}");
        assert_eq!(g, with_link);
        // Within the budget, changes are made.
        let mut g = before;
        g.set_depth("/image", 100).unwrap();
        assert_eq!(g.topic(g.topic_id("/image").unwrap()).depth, 100);
        g.set_all_depths(50).unwrap();
        assert!(g.topics.iter().all(|t| t.depth == 50));
    }
}
