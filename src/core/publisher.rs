//! Publishers: a node's handle to publish on a topic, which can hold what a tick publishes
//! until the tick's compute time has elapsed ([`crate::executor`]).
//!
//! A node with a compute time reads its inputs when its tick starts and publishes when it
//! ends. The scheduler asks the node's [`Outbox`] to *hold* before such a tick; every
//! [`Publisher::publish`] during it is kept, in order, and goes out when the scheduler
//! releases the outbox at the tick's end, stamped with that time, through the topic's normal
//! path (drop rule, QoS, link). With a zero compute time nothing is held: a publish is the
//! topic's publish, as it always was.

use crate::time::Nanos;
use crate::topic::Subscription;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex};

/// One publish a held tick made, to go out at the tick's end. `Fn` (each call publishes a
/// copy of the value), so a capture can keep what is held ([`Outbox::save`]).
type Held = Arc<dyn Fn(Nanos) + Send + Sync>;

#[derive(Default)]
struct Inner {
    holding: AtomicBool,
    held: Mutex<Vec<Held>>,
}

/// One node's outbox, shared by its publishers. Cheap to clone.
#[derive(Clone, Default)]
pub struct Outbox(Arc<Inner>);

/// What an [`Outbox`] holds at an instant ([`Outbox::save`]).
#[derive(Clone)]
pub struct OutboxState {
    holding: bool,
    held: Vec<Held>,
}

impl Outbox {
    /// An outbox that holds nothing.
    pub fn new() -> Outbox {
        Outbox::default()
    }

    /// From now on, keep what is published (the tick that follows has a compute time).
    pub fn hold(&self) {
        self.0.holding.store(true, Ordering::Release);
    }

    /// Is it holding?
    pub fn is_holding(&self) -> bool {
        self.0.holding.load(Ordering::Acquire)
    }

    /// Stop holding and publish everything held, in order, stamped `at` (the tick's end).
    /// Returns how many messages went out.
    pub fn release(&self, at: Nanos) -> usize {
        self.0.holding.store(false, Ordering::Release);
        let held = std::mem::take(&mut *self.0.held.lock().unwrap_or_else(|e| e.into_inner()));
        let n = held.len();
        for publish in held {
            publish(at);
        }
        n
    }

    /// What the outbox holds now (whether it is holding, and the publishes held), for a
    /// capture of the run (`ratelab::runcore`).
    pub fn save(&self) -> OutboxState {
        OutboxState {
            holding: self.is_holding(),
            held: self
                .0
                .held
                .lock()
                .unwrap_or_else(|e| e.into_inner())
                .clone(),
        }
    }

    /// Hold again what [`Outbox::save`] gave.
    pub fn load(&self, state: &OutboxState) {
        self.0.holding.store(state.holding, Ordering::Release);
        *self.0.held.lock().unwrap_or_else(|e| e.into_inner()) = state.held.clone();
    }

    fn keep(&self, publish: Held) {
        self.0
            .held
            .lock()
            .unwrap_or_else(|e| e.into_inner())
            .push(publish);
    }

    /// Publish `data` on `topic` through this outbox: at once (stamped `now`) unless it is
    /// holding, else when it is released.
    pub fn publish<T: Clone + Send + Sync + 'static>(
        &self,
        topic: &Arc<Subscription<T>>,
        data: T,
        now: Nanos,
        origin_stamp: Option<Nanos>,
    ) {
        if self.is_holding() {
            let topic = topic.clone();
            self.keep(Arc::new(move |at| {
                topic.publish(data.clone(), at, origin_stamp);
            }));
        } else {
            topic.publish(data, now, origin_stamp);
        }
    }
}

/// A node's publisher on one topic of `T` messages: it publishes into the queue of every
/// subscription (one queue for a topic with at most one subscriber).
#[derive(Clone)]
pub struct Publisher<T> {
    queues: Queues<T>,
    outbox: Outbox,
}

/// The queues a publish goes into.
#[derive(Clone)]
enum Queues<T> {
    One(Arc<Subscription<T>>),
    Many(Arc<[Arc<Subscription<T>>]>),
}

impl<T: Clone + Send + Sync + 'static> Publisher<T> {
    /// A publisher on `topic` through the node's `outbox`.
    pub fn new(topic: Arc<Subscription<T>>, outbox: Outbox) -> Publisher<T> {
        Publisher {
            queues: Queues::One(topic),
            outbox,
        }
    }

    /// A publisher on a topic of several subscriptions, one queue each (at least one).
    ///
    /// # Panics
    /// For no queue.
    pub fn fan_out(queues: Vec<Arc<Subscription<T>>>, outbox: Outbox) -> Publisher<T> {
        assert!(!queues.is_empty(), "a topic has at least one queue");
        Publisher {
            queues: if queues.len() == 1 {
                Queues::One(queues[0].clone())
            } else {
                Queues::Many(queues.into())
            },
            outbox,
        }
    }

    /// Publish `data` at run time `now` with the origin stamp of what it was derived from
    /// (sense→act latency is measured from it), into every subscription's queue. Held
    /// until the tick's end when the tick has a compute time.
    pub fn publish(&self, data: T, now: Nanos, origin_stamp: Option<Nanos>) {
        match &self.queues {
            Queues::One(t) => self.outbox.publish(t, data, now, origin_stamp),
            Queues::Many(ts) => {
                for t in ts.iter() {
                    self.outbox.publish(t, data.clone(), now, origin_stamp);
                }
            }
        }
    }

    /// The (first subscription's) queue.
    pub fn topic(&self) -> &Arc<Subscription<T>> {
        match &self.queues {
            Queues::One(t) => t,
            Queues::Many(ts) => &ts[0],
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_held_publish_goes_out_at_the_release_stamped_then() {
        let topic = Arc::new(Subscription::<u32>::new("/t", 4).unwrap());
        let outbox = Outbox::new();
        let p = Publisher::new(topic.clone(), outbox.clone());
        p.publish(1, Nanos(10), Some(Nanos(9)));
        assert_eq!(topic.stats().published, 1, "not holding: at once");
        outbox.hold();
        p.publish(2, Nanos(20), Some(Nanos(19)));
        p.publish(3, Nanos(20), Some(Nanos(18)));
        assert_eq!(topic.stats().published, 1, "held");
        assert_eq!(outbox.release(Nanos(23)), 2);
        let newest = topic.read(Nanos(23)).unwrap();
        assert_eq!(
            (newest.data, newest.stamp, newest.origin_stamp),
            (3, Nanos(23), Some(Nanos(18)))
        );
        assert_eq!(topic.stats().published, 3);
        p.publish(4, Nanos(30), None);
        assert_eq!(topic.stats().published, 4, "released: at once again");
    }
}
