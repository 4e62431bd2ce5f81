//! Topics: named, thread-safe, bounded message buses with a latest-wins subscriber.
//!
//! The drop rule is the chapter's (ch2.8, `Topic`): a topic buffers at most `depth`
//! messages (its history depth, in QoS terms). Publishing into a full buffer evicts the
//! oldest message; that eviction is a **drop** exactly when the evicted message was never
//! read, i.e. its `seq` is above the read high-water mark. Reading with
//! [`Topic::latest`] returns the newest message and moves the high-water mark past
//! everything buffered: a latest-wins subscriber that caught up skips the backlog.
//! The drop counter is how a rate mismatch becomes visible.

use crate::time::Nanos;
use std::collections::VecDeque;
use std::sync::{Mutex, MutexGuard};

/// One published value.
#[derive(Clone, Debug, PartialEq)]
pub struct Message<T> {
    /// The payload.
    pub data: T,
    /// Run time at which the message was published.
    pub stamp: Nanos,
    /// Per-topic sequence number, from 0, in publish order.
    pub seq: u64,
    /// The stamp of the sensor reading this value was derived from, when there is one;
    /// a downstream node measures sense→act latency as `now - origin_stamp`.
    pub origin_stamp: Option<Nanos>,
}

/// A topic's counters at one instant.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Serialize)]
pub struct TopicStats {
    /// Messages published so far.
    pub published: u64,
    /// Messages evicted from a full buffer before any read caught up with them.
    pub dropped: u64,
    /// Messages a subscriber has read or read past (a latest-wins read marks everything
    /// buffered as seen). Every message is seen, dropped, or still buffered unseen.
    pub seen: u64,
    /// Reads that returned a message the subscriber had already read: nothing new arrived
    /// since its last read (a publisher slower than its subscriber). The mirror image of a
    /// drop: there a message is never read, here one is read again.
    pub stale_reads: u64,
    /// Stamp of the newest message published (zero before the first). With
    /// [`TopicStats::published`] at two instants it gives the exact rate of the messages
    /// published between them: `Δpublished / Δlast_stamp`.
    pub last_stamp: Nanos,
    /// The current history depth (buffer bound), ≥ 1.
    pub depth: usize,
}

/// Why a depth cannot be set.
#[derive(Debug, thiserror::Error, PartialEq, Eq)]
#[error("queue depth must be at least 1")]
pub struct ZeroDepth;

struct Inner<T> {
    buf: VecDeque<Message<T>>,
    depth: usize,
    next_seq: u64,
    /// Newest `seq` a subscriber has seen; `None` before the first read.
    read_high_water: Option<u64>,
    published: u64,
    dropped: u64,
    seen: u64,
    stale_reads: u64,
    last_stamp: Nanos,
}

impl<T> Inner<T> {
    fn evict_oldest(&mut self) {
        if let Some(old) = self.buf.pop_front() {
            if self.read_high_water.is_none_or(|hw| old.seq > hw) {
                self.dropped += 1;
            }
        }
    }
}

/// A named bus of `T` messages bounded to `depth` buffered messages. Publishers and
/// subscribers may live on different threads; every operation takes one short lock.
pub struct Topic<T> {
    name: String,
    inner: Mutex<Inner<T>>,
}

impl<T: Clone> Topic<T> {
    /// A topic named `name` (by convention `/obs`, `/action`) holding at most `depth` messages.
    ///
    /// # Errors
    /// [`ZeroDepth`] when `depth` is 0.
    pub fn new(name: impl Into<String>, depth: usize) -> Result<Self, ZeroDepth> {
        if depth == 0 {
            return Err(ZeroDepth);
        }
        Ok(Self {
            name: name.into(),
            inner: Mutex::new(Inner {
                buf: VecDeque::with_capacity(depth.min(1024)),
                depth,
                next_seq: 0,
                read_high_water: None,
                published: 0,
                dropped: 0,
                seen: 0,
                stale_reads: 0,
                last_stamp: Nanos::ZERO,
            }),
        })
    }

    /// The topic's name.
    pub fn name(&self) -> &str {
        &self.name
    }

    fn lock(&self) -> MutexGuard<'_, Inner<T>> {
        // A panic elsewhere cannot leave the buffer half-updated (every update is a
        // single push/pop plus counters), so a poisoned lock is still consistent.
        self.inner.lock().unwrap_or_else(|e| e.into_inner())
    }

    /// Append a message stamped `stamp`, evicting (and maybe dropping) the oldest when full.
    /// Returns the new message's `seq`.
    pub fn publish(&self, data: T, stamp: Nanos, origin_stamp: Option<Nanos>) -> u64 {
        let mut inner = self.lock();
        if inner.buf.len() >= inner.depth {
            inner.evict_oldest();
        }
        let seq = inner.next_seq;
        inner.next_seq += 1;
        inner.buf.push_back(Message {
            data,
            stamp,
            seq,
            origin_stamp,
        });
        inner.published += 1;
        inner.last_stamp = stamp;
        seq
    }

    /// The newest message, or `None` if nothing has been published yet. Advances the
    /// read high-water mark past everything buffered.
    pub fn latest(&self) -> Option<Message<T>> {
        let mut inner = self.lock();
        let newest = inner.buf.back()?.clone();
        let hw = inner.read_high_water;
        if hw.is_some_and(|hw| newest.seq <= hw) {
            inner.stale_reads += 1;
        }
        // Seqs are consecutive in the buffer: the unseen ones are the newest `newest − hw`.
        let unseen = hw
            .map_or(inner.buf.len() as u64, |hw| newest.seq.saturating_sub(hw))
            .min(inner.buf.len() as u64);
        inner.seen += unseen;
        inner.read_high_water = Some(
            inner
                .read_high_water
                .map_or(newest.seq, |hw| hw.max(newest.seq)),
        );
        Some(newest)
    }

    /// Change the history depth while running. Shrinking keeps the newest messages and
    /// evicts the oldest under the same drop rule as [`Topic::publish`].
    ///
    /// # Errors
    /// [`ZeroDepth`] when `depth` is 0 (the topic is unchanged).
    pub fn set_depth(&self, depth: usize) -> Result<(), ZeroDepth> {
        if depth == 0 {
            return Err(ZeroDepth);
        }
        let mut inner = self.lock();
        inner.depth = depth;
        while inner.buf.len() > depth {
            inner.evict_oldest();
        }
        Ok(())
    }

    /// Counters and depth, read together under one lock.
    pub fn stats(&self) -> TopicStats {
        let inner = self.lock();
        TopicStats {
            published: inner.published,
            dropped: inner.dropped,
            seen: inner.seen,
            stale_reads: inner.stale_reads,
            last_stamp: inner.last_stamp,
            depth: inner.depth,
        }
    }

    /// Buffered messages no subscriber has seen yet.
    pub fn unseen_buffered(&self) -> usize {
        let inner = self.lock();
        inner
            .buf
            .iter()
            .filter(|m| inner.read_high_water.is_none_or(|hw| m.seq > hw))
            .count()
    }

    /// Messages currently buffered (≤ depth).
    pub fn buffered(&self) -> usize {
        self.lock().buf.len()
    }

    /// The newest buffered message, without reading it (the read high-water mark, and so
    /// the drop count, is unchanged). For onlookers.
    pub fn peek_newest(&self) -> Option<Message<T>> {
        self.lock().buf.back().cloned()
    }

    /// The buffered messages with `seq >= from`, oldest first, without reading them: the read
    /// high-water mark, and so the drop count, is unchanged. For onlookers such as a recorder.
    pub fn peek_from(&self, from: u64) -> Vec<Message<T>> {
        self.lock()
            .buf
            .iter()
            .filter(|m| m.seq >= from)
            .cloned()
            .collect()
    }
}

impl<T> std::fmt::Debug for Topic<T> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Topic")
            .field("name", &self.name)
            .finish_non_exhaustive()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn t(depth: usize) -> Topic<u32> {
        Topic::new("/t", depth).unwrap()
    }

    #[test]
    fn depth_one_drops_every_unread_superseded_message() {
        let topic = t(1);
        topic.publish(0, Nanos(0), None);
        topic.publish(1, Nanos(1), None); // 0 evicted unread
        topic.publish(2, Nanos(2), None); // 1 evicted unread
        assert_eq!(topic.stats().dropped, 2);
        assert_eq!(topic.latest().unwrap().data, 2);
        topic.publish(3, Nanos(3), None); // 2 was read: not a drop
        assert_eq!(topic.stats().dropped, 2);
        assert_eq!(topic.stats().published, 4);
    }

    #[test]
    fn peeking_is_not_reading() {
        let topic = t(2);
        topic.publish(0, Nanos(0), None);
        topic.publish(1, Nanos(1), None);
        let seen: Vec<u32> = topic.peek_from(1).into_iter().map(|m| m.data).collect();
        assert_eq!(seen, [1]);
        assert_eq!(topic.peek_from(0).len(), 2);
        topic.publish(2, Nanos(2), None); // 0 evicted: never read, peeking does not count
        assert_eq!(topic.stats().dropped, 1);
        assert!(topic.peek_from(3).is_empty());
    }

    #[test]
    fn nothing_published_reads_none() {
        assert!(t(3).latest().is_none());
        assert_eq!(t(3).stats().dropped, 0);
    }

    #[test]
    fn deep_queue_absorbs_until_full() {
        let topic = t(3);
        for i in 0..3 {
            topic.publish(i, Nanos(i as u64), None);
        }
        assert_eq!(topic.stats().dropped, 0);
        topic.publish(3, Nanos(3), None); // evicts 0, unread
        assert_eq!(topic.stats().dropped, 1);
        // Reading the newest marks everything buffered as seen.
        assert_eq!(topic.latest().unwrap().seq, 3);
        for i in 4..7 {
            topic.publish(i, Nanos(i as u64), None); // evicts 1, 2, 3: all seen
        }
        assert_eq!(topic.stats().dropped, 1);
        topic.publish(7, Nanos(7), None); // evicts 4: unread
        assert_eq!(topic.stats().dropped, 2);
    }

    #[test]
    fn reading_between_publishes_prevents_all_drops() {
        let topic = t(1);
        for i in 0..100 {
            topic.publish(i, Nanos(i as u64), None);
            assert_eq!(topic.latest().unwrap().data, i);
        }
        assert_eq!(
            topic.stats(),
            TopicStats {
                published: 100,
                dropped: 0,
                seen: 100,
                stale_reads: 0,
                last_stamp: Nanos(99),
                depth: 1
            }
        );
    }

    #[test]
    fn shrinking_depth_keeps_newest_and_counts_unread_evictions() {
        let topic = t(5);
        for i in 0..5 {
            topic.publish(i, Nanos(i as u64), None);
        }
        topic.set_depth(2).unwrap(); // evicts 0, 1, 2 unread
        assert_eq!(topic.stats().dropped, 3);
        assert_eq!(topic.buffered(), 2);
        assert_eq!(topic.latest().unwrap().data, 4);
        topic.set_depth(1).unwrap(); // evicts 3: it was below the high-water mark (read past)
        assert_eq!(topic.stats().dropped, 3);
        // Growing keeps everything and the rule stays exact.
        topic.set_depth(3).unwrap();
        topic.publish(5, Nanos(5), None);
        topic.publish(6, Nanos(6), None);
        assert_eq!(topic.stats().dropped, 3);
        topic.publish(7, Nanos(7), None); // evicts 4 (read)
        assert_eq!(topic.stats().dropped, 3);
        topic.publish(8, Nanos(8), None); // evicts 5 (unread)
        assert_eq!(topic.stats().dropped, 4);
        assert_eq!(topic.set_depth(0), Err(ZeroDepth));
        assert!(Topic::<u8>::new("/z", 0).is_err());
    }

    #[test]
    fn stale_reads_are_the_mirror_of_drops() {
        // A publisher at a fifth of the subscriber's rate: each message is read five times.
        let topic = t(1);
        assert!(topic.latest().is_none());
        assert_eq!(
            topic.stats().stale_reads,
            0,
            "nothing to read is not a stale read"
        );
        for i in 0..3 {
            topic.publish(i, Nanos(u64::from(i) * 5), None);
            for _ in 0..5 {
                assert_eq!(topic.latest().unwrap().data, i);
            }
        }
        let s = topic.stats();
        assert_eq!((s.stale_reads, s.dropped, s.seen), (12, 0, 3));
        assert_eq!(s.last_stamp, Nanos(10));
    }

    #[test]
    fn every_message_is_seen_dropped_or_waiting() {
        let topic = t(3);
        let account = |t: &Topic<u32>| {
            let s = t.stats();
            assert_eq!(
                s.published,
                s.seen + s.dropped + t.unseen_buffered() as u64,
                "{s:?}"
            );
        };
        for i in 0..5 {
            topic.publish(i, Nanos(u64::from(i)), None);
            account(&topic);
        }
        topic.latest(); // sees 2, 3, 4
        assert_eq!(topic.stats().seen, 3);
        account(&topic);
        topic.publish(5, Nanos(5), None);
        topic.set_depth(1).unwrap(); // evicts 3, 4 (seen)
        account(&topic);
        topic.latest();
        topic.latest(); // nothing new to see
        assert_eq!(topic.stats().seen, 4);
        account(&topic);
    }

    #[test]
    fn messages_carry_stamps_and_origin() {
        let topic = t(2);
        topic.publish(9, Nanos(40), Some(Nanos(20)));
        let m = topic.latest().unwrap();
        assert_eq!(
            (m.stamp, m.seq, m.origin_stamp),
            (Nanos(40), 0, Some(Nanos(20)))
        );
    }
}
