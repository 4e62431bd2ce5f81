//! The topic under contention: counts that must add up exactly whatever the interleaving.

use ratelab::topic::Subscription;
use ratelab::Nanos;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;

const PUBLISHERS: u64 = 4;
const EACH: u64 = 20_000;

fn publish_all(topic: &Arc<Subscription<u64>>) -> Vec<u64> {
    let handles: Vec<_> = (0..PUBLISHERS)
        .map(|p| {
            let t = topic.clone();
            std::thread::spawn(move || {
                (0..EACH)
                    .map(|i| t.publish(p * EACH + i, Nanos(i), None))
                    .collect::<Vec<u64>>()
            })
        })
        .collect();
    let mut seqs: Vec<u64> = handles
        .into_iter()
        .flat_map(|h| h.join().unwrap())
        .collect();
    seqs.sort_unstable();
    seqs
}

#[test]
fn unread_topic_drops_all_but_depth_exactly() {
    let _machine = crate::machine::shared();
    for depth in [1usize, 3, 64] {
        let topic = Arc::new(Subscription::new("/stress", depth).unwrap());
        let seqs = publish_all(&topic);
        let n = PUBLISHERS * EACH;
        // Every publish got its own sequence number: no lost or duplicated update.
        assert_eq!(seqs, (0..n).collect::<Vec<u64>>());
        let stats = topic.stats();
        assert_eq!(stats.published, n);
        // Nothing was ever read, so every evicted message was dropped: all but the last `depth`.
        assert_eq!(stats.dropped, n - depth as u64, "depth {depth}");
        assert_eq!(topic.buffered(), depth);
        assert_eq!(topic.read(Nanos(u64::MAX)).unwrap().seq, n - 1);
    }
}

#[test]
fn concurrent_reader_sees_time_move_forward_and_counts_stay_bounded() {
    let _machine = crate::machine::shared();
    let depth = 4;
    let topic = Arc::new(Subscription::new("/stress", depth).unwrap());
    let done = Arc::new(AtomicBool::new(false));
    let reader = {
        let (t, done) = (topic.clone(), done.clone());
        std::thread::spawn(move || {
            let mut seen = Vec::new();
            while !done.load(Ordering::Relaxed) {
                if let Some(m) = t.read(Nanos(u64::MAX)) {
                    seen.push(m.seq);
                }
            }
            seen
        })
    };
    let seqs = publish_all(&topic);
    done.store(true, Ordering::Relaxed);
    let seen = reader.join().unwrap();
    let n = PUBLISHERS * EACH;
    assert_eq!(seqs.len() as u64, n);
    let stats = topic.stats();
    assert_eq!(stats.published, n);
    // latest() never goes back in time.
    assert!(seen.windows(2).all(|w| w[0] <= w[1]));
    // Reads can only save messages from being counted as drops.
    assert!(stats.dropped <= n - depth as u64);
    // A final read marks everything buffered as seen: publishing `depth` more then drops nothing.
    topic.read(Nanos(u64::MAX));
    let before = topic.stats().dropped;
    for i in 0..depth as u64 {
        topic.publish(i, Nanos(0), None);
    }
    assert_eq!(topic.stats().dropped, before);
}

#[test]
fn under_every_qos_four_publishers_and_a_reader_account_for_every_message() {
    use ratelab::qos::{apply_key, split_pairs, TopicQos};
    use std::sync::atomic::AtomicU64;
    let _machine = crate::machine::shared();
    for pairs in [
        "history=keep_all,depth=64,delivery=fifo,lifespan_ms=0.05",
        "history=keep_last,depth=8,delivery=latest,deadline_ms=0.01,loss=0.1,delay_ms=0.02,jitter_ms=0.01",
        "history=keep_all,depth=16,delivery=fifo,loss=0.2,reliability=reliable,delay_ms=0.01,lifespan_ms=0.2",
    ] {
        let (mut qos, mut depth) = (TopicQos::default(), 1);
        for (k, v) in split_pairs(pairs).unwrap() {
            apply_key(&mut qos, &mut depth, k, v).unwrap();
        }
        let topic = Arc::new(Subscription::with_qos("/stress", depth, qos, 3).unwrap());
        // One clock for every thread, ticking 1 µs per operation.
        let clock = Arc::new(AtomicU64::new(0));
        let now = |c: &AtomicU64| Nanos(c.fetch_add(1_000, Ordering::Relaxed));
        let done = Arc::new(AtomicBool::new(false));
        let reader = {
            let (t, c, done) = (topic.clone(), clock.clone(), done.clone());
            std::thread::spawn(move || {
                // At least one read, however the threads are scheduled on a busy machine.
                let mut reads = 0u64;
                loop {
                    t.read(now(&c));
                    reads += 1;
                    if done.load(Ordering::Relaxed) {
                        break reads;
                    }
                }
            })
        };
        let publishers: Vec<_> = (0..PUBLISHERS)
            .map(|_| {
                let (t, c) = (topic.clone(), clock.clone());
                std::thread::spawn(move || {
                    for i in 0..EACH / 4 {
                        t.publish(i, now(&c), None);
                    }
                })
            })
            .collect();
        for p in publishers {
            p.join().unwrap();
        }
        done.store(true, Ordering::Relaxed);
        assert!(reader.join().unwrap() > 0);
        let s = topic.stats();
        let accounted = s.seen
            + s.dropped
            + s.expired
            + s.lost
            + s.refused
            + topic.unseen_buffered() as u64
            + s.in_flight;
        assert_eq!(s.published, PUBLISHERS * (EACH / 4), "{pairs}");
        assert_eq!(s.published, accounted, "{pairs}: {s:?}");
    }
}
