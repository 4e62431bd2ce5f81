//! Liveliness tokens watched for their withdrawal, riding out Zenoh's brief withdrawals of a
//! token that is still there.
//!
//! A launch reads a process's end, or its launcher's, from the withdrawal of a liveliness
//! token (a `Delete` sample on a liveliness subscriber). Zenoh withdraws a token when the
//! link it was heard over closes, and declares it again when it is heard over another: a
//! link that fails while its peer lives is read as that peer's end. Seen here as the two
//! processes of a launch linked to each other at startup: a process heard the launcher's
//! token withdrawn, then declared again 4.5–6 ms later, while the launcher ran on, and
//! ended with "the launcher went away" (6 launches in 138 with Zenoh's receive and send on
//! pools of two workers each, as a user's `ZENOH_RUNTIME` could set it then). That setting
//! was later found to corrupt Zenoh's TLS links (eclipse-zenoh/zenoh#2557) and is refused
//! since ([`crate::set_zenoh_runtime`]); with ratelab's runtime, and with one whose receive
//! and send share one thread beside other pools of two, no withdrawal of a live token was
//! seen in 100 launches each. So a token counts as withdrawn only once it has stayed
//! withdrawn for [`WITHDRAWN_FOR`], and a `Put` within that time takes the withdrawal
//! back: a guard against a link lost while another path remains, whose cost is a real end
//! noticed 0.75 s later.
//!
//! Times are the host's `CLOCK_MONOTONIC` in ns ([`crate::wire::mono_now_ns`]); each type
//! also takes them as arguments (`*_at`), so its rule is tested without waiting.

use std::collections::BTreeMap;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, Mutex};
use std::time::Duration;
use zenoh::sample::SampleKind;

/// How long a token must stay withdrawn before it counts as gone: far beyond the few
/// milliseconds between Zenoh's withdrawal of a live token and its declaration again, and
/// short beside how a launch notices a process frozen (its link's lease, seconds).
pub const WITHDRAWN_FOR: Duration = Duration::from_millis(750);

/// [`WITHDRAWN_FOR`] in ns.
const WITHDRAWN_FOR_NS: u64 = WITHDRAWN_FOR.as_nanos() as u64;

/// One liveliness token (the launcher's, as a process or a host's router watches it):
/// gone once withdrawn for [`WITHDRAWN_FOR`] without being declared again. Clones share
/// the state: the subscriber's callback notes, the run's loop asks.
#[derive(Clone, Debug, Default)]
pub struct TokenWatch {
    /// When the token was withdrawn (ns, at least 1), or 0 while it is declared (or was
    /// never seen).
    withdrawn_at_ns: Arc<AtomicU64>,
}

impl TokenWatch {
    /// A token not yet seen withdrawn.
    pub fn new() -> Self {
        Self::default()
    }

    /// Note a sample of the token, now.
    pub fn note(&self, kind: SampleKind) {
        self.note_at(kind, crate::wire::mono_now_ns());
    }

    /// Note a sample of the token at `now_ns`: a `Delete` starts its withdrawal (a second
    /// one does not move its start), a `Put` takes it back.
    pub fn note_at(&self, kind: SampleKind, now_ns: u64) {
        match kind {
            SampleKind::Put => self.withdrawn_at_ns.store(0, Ordering::SeqCst),
            SampleKind::Delete => {
                let _ = self.withdrawn_at_ns.compare_exchange(
                    0,
                    now_ns.max(1),
                    Ordering::SeqCst,
                    Ordering::SeqCst,
                );
            }
        }
    }

    /// Whether the token is gone now: withdrawn for [`WITHDRAWN_FOR`] or longer.
    pub fn is_gone(&self) -> bool {
        self.is_gone_at(crate::wire::mono_now_ns())
    }

    /// Whether the token is gone at `now_ns`.
    pub fn is_gone_at(&self, now_ns: u64) -> bool {
        match self.withdrawn_at_ns.load(Ordering::SeqCst) {
            0 => false,
            at => now_ns.saturating_sub(at) >= WITHDRAWN_FOR_NS,
        }
    }
}

/// Liveliness tokens by key (the launcher's watch on every process's node tokens): each
/// withdrawal counts once it has held for [`WITHDRAWN_FOR`], and is handed out once
/// ([`Withdrawals::take_settled`]); the token declared again before then takes it back.
/// At most one pending withdrawal per key: the keys are the launch's own tokens, which
/// the access rules let only its processes declare.
#[derive(Debug, Default)]
pub struct Withdrawals {
    /// Key → when its token was withdrawn (ns), while that has not settled.
    pending: Mutex<BTreeMap<String, u64>>,
}

impl Withdrawals {
    /// No withdrawal yet.
    pub fn new() -> Self {
        Self::default()
    }

    fn pending(&self) -> std::sync::MutexGuard<'_, BTreeMap<String, u64>> {
        self.pending.lock().unwrap_or_else(|e| e.into_inner())
    }

    /// Note a sample of the token at `key`, now.
    pub fn note(&self, key: &str, kind: SampleKind) {
        self.note_at(key, kind, crate::wire::mono_now_ns());
    }

    /// Note a sample of the token at `key` at `now_ns`: a `Delete` starts its withdrawal (a
    /// second one does not move its start), a `Put` takes it back.
    pub fn note_at(&self, key: &str, kind: SampleKind, now_ns: u64) {
        let mut pending = self.pending();
        match kind {
            SampleKind::Put => {
                pending.remove(key);
            }
            SampleKind::Delete => {
                pending.entry(key.to_string()).or_insert(now_ns);
            }
        }
    }

    /// The keys whose withdrawals have settled by now, each once, in key order.
    pub fn take_settled(&self) -> Vec<String> {
        self.take_settled_at(crate::wire::mono_now_ns())
    }

    /// The keys whose withdrawals have settled by `now_ns` (withdrawn [`WITHDRAWN_FOR`] or
    /// longer before it), each once, in key order. Those taken are forgotten: the same key
    /// withdrawn again later (a process restarted, then gone again) is handed out again.
    pub fn take_settled_at(&self, now_ns: u64) -> Vec<String> {
        let mut pending = self.pending();
        let settled: Vec<String> = pending
            .iter()
            .filter(|(_, at)| now_ns.saturating_sub(**at) >= WITHDRAWN_FOR_NS)
            .map(|(k, _)| k.clone())
            .collect();
        for k in &settled {
            pending.remove(k);
        }
        settled
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const MS: u64 = 1_000_000;

    #[test]
    fn a_token_withdrawn_and_declared_again_within_the_grace_is_never_gone() {
        let w = TokenWatch::new();
        let t0 = 5_000 * MS;
        assert!(!w.is_gone_at(t0), "never seen");
        w.note_at(SampleKind::Put, t0);
        // What was seen here: withdrawn, then declared again 5 ms later.
        w.note_at(SampleKind::Delete, t0 + MS);
        assert!(!w.is_gone_at(t0 + 5 * MS));
        w.note_at(SampleKind::Put, t0 + 6 * MS);
        assert!(
            !w.is_gone_at(t0 + 10_000 * MS),
            "declared again: never gone"
        );
    }

    #[test]
    fn a_token_withdrawn_for_the_grace_is_gone_from_its_first_withdrawal() {
        let w = TokenWatch::new();
        let t0 = 5_000 * MS;
        w.note_at(SampleKind::Put, t0);
        w.note_at(SampleKind::Delete, t0 + MS);
        // A second withdrawal (sent twice) does not restart the wait.
        w.note_at(SampleKind::Delete, t0 + 500 * MS);
        assert!(!w.is_gone_at(t0 + MS + WITHDRAWN_FOR_NS - 1));
        assert!(w.is_gone_at(t0 + MS + WITHDRAWN_FOR_NS));
        // A clone shares it (the callback notes, the run's loop asks).
        assert!(w.clone().is_gone_at(t0 + 2 * WITHDRAWN_FOR_NS));
        // At time 0 of the clock too: a withdrawal is never read as "declared".
        let w0 = TokenWatch::new();
        w0.note_at(SampleKind::Delete, 0);
        assert!(w0.is_gone_at(WITHDRAWN_FOR_NS + 1));
    }

    #[test]
    fn withdrawals_are_handed_out_once_when_settled_and_taken_back_by_a_put() {
        let w = Withdrawals::new();
        let t0 = 5_000 * MS;
        w.note_at("a/1", SampleKind::Delete, t0);
        w.note_at("b/1", SampleKind::Delete, t0 + 100 * MS);
        w.note_at("c/1", SampleKind::Delete, t0 + 200 * MS);
        w.note_at("c/1", SampleKind::Put, t0 + 205 * MS);
        assert!(w.take_settled_at(t0 + WITHDRAWN_FOR_NS - 1).is_empty());
        assert_eq!(
            w.take_settled_at(t0 + WITHDRAWN_FOR_NS),
            vec!["a/1".to_string()]
        );
        assert_eq!(
            w.take_settled_at(t0 + 10 * WITHDRAWN_FOR_NS),
            vec!["b/1".to_string()],
            "each once; c/1 was declared again"
        );
        assert!(w.take_settled_at(t0 + 20 * WITHDRAWN_FOR_NS).is_empty());
        // The same key withdrawn again later (its process restarted, then gone again).
        w.note_at("a/1", SampleKind::Delete, t0 + 30 * WITHDRAWN_FOR_NS);
        assert_eq!(
            w.take_settled_at(t0 + 31 * WITHDRAWN_FOR_NS).len(),
            1,
            "handed out again"
        );
    }
}
