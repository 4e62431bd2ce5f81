//! A FROZEN COPY of the pre-QoS topic, for comparison only: `src/topic.rs` at commit
//! e7a8428 (the last commit before QoS), cut down to what the topic benchmark calls
//! (`new`, `publish`, `latest`). The bodies are unchanged; only `stats`, `set_depth` and the
//! onlookers' methods were left out, and `Nanos` comes from the library. Never edit it to
//! follow `src/topic.rs`: it is the "costs what it costs today" baseline of issue 12's
//! benchmark goal (BENCHMARKS.md, "Topics with QoS").

// The copy keeps every counter the original kept, written as the original wrote them, though
// the benchmark never reads them back.
#![allow(dead_code)]

use ratelab::Nanos;
use std::collections::VecDeque;
use std::sync::{Mutex, MutexGuard};

/// One published value (as at e7a8428).
#[derive(Clone, Debug, PartialEq)]
pub struct Message<T> {
    /// The payload.
    pub data: T,
    /// Run time at which the message was published.
    pub stamp: Nanos,
    /// Per-topic sequence number, from 0, in publish order.
    pub seq: u64,
    /// The stamp of the sensor reading this value was derived from.
    pub origin_stamp: Option<Nanos>,
}

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

/// The pre-QoS topic: keep-last `depth`, latest-wins reads.
pub struct Topic<T> {
    name: String,
    inner: Mutex<Inner<T>>,
}

impl<T: Clone> Topic<T> {
    /// A topic holding at most `depth` messages (`None` for 0, where e7a8428 returned an
    /// error type this copy leaves out).
    pub fn new(name: impl Into<String>, depth: usize) -> Option<Self> {
        if depth == 0 {
            return None;
        }
        Some(Self {
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

    fn lock(&self) -> MutexGuard<'_, Inner<T>> {
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
}
