//! Connections a graph's session refused: a peer without the launch's credentials
//! ([`super::credentials`]) fails the TLS handshake, which Zenoh reports only as a warning
//! of its TLS link (`zenoh_link_tls`, through the `tracing` crate). [`watch`] installs a
//! `tracing` subscriber that passes those warnings on, and nothing else (every other
//! callsite is disabled once, at registration, so it costs nothing after: a test holds
//! it); [`Refusals`]
//! turns them into the launcher's progress lines, rate-limited. With `RUST_LOG` set (Zenoh's
//! own convention, `RUST_LOG=zenoh=debug`), the same subscriber also writes what it selects
//! to stderr, as a Zenoh program would: ratelab's subscriber is the process's one.

use crossbeam_channel::{Receiver, Sender};
use std::sync::{Mutex, OnceLock};
use std::time::{Duration, Instant};
use tracing::{Event, Metadata, Subscriber};
use tracing_subscriber::layer::{Context, Layer};
use tracing_subscriber::prelude::*;

/// The most refusals waiting to be said (more are counted, not kept).
const MAX_WAITING: usize = 256;

/// The longest refusal reason kept, bytes.
const MAX_REASON_BYTES: usize = 200;

/// How Zenoh's TLS listener ends its warning of a failed accept (zenoh-link-tls 1.10,
/// `accept_task`): what follows is Zenoh's hint, what precedes it the reason.
const ACCEPT_FAILED: &str = ". Hint: increase the system open file limit";

/// Where refusals go: the receivers [`watch`] handed out.
static SINKS: OnceLock<Mutex<Vec<Sender<String>>>> = OnceLock::new();

/// Whether a callsite is one of Zenoh's TLS link warnings (and errors).
fn is_refusal(meta: &Metadata<'_>) -> bool {
    meta.target().starts_with("zenoh_link_tls") && *meta.level() <= tracing::Level::WARN
}

struct RefusalLayer;

impl<S: Subscriber> Layer<S> for RefusalLayer {
    fn on_event(&self, event: &Event<'_>, _: Context<'_, S>) {
        struct Message(String);
        impl tracing::field::Visit for Message {
            fn record_debug(&mut self, field: &tracing::field::Field, v: &dyn std::fmt::Debug) {
                if field.name() == "message" {
                    self.0 = format!("{v:?}");
                }
            }
        }
        let mut m = Message(String::new());
        event.record(&mut m);
        // Only a failed accept (a handshake refused, or one that timed out) is a refusal:
        // Zenoh's TLS link warns of other things too (it skips checking a server's name on
        // every link this session opens, as ratelab asks). Zenoh's own hint after a failed
        // accept is about file limits: not this case.
        let Some((reason, _)) = m.0.split_once(ACCEPT_FAILED) else {
            return;
        };
        let reason = reason.trim().to_string();
        let reason = super::wire::cut_to_bytes(
            ratelab_core::text::printable(&reason).into_owned(),
            MAX_REASON_BYTES,
        );
        if let Some(sinks) = SINKS.get() {
            ratelab_runtime::graph::lock(sinks).retain(|s| match s.try_send(reason.clone()) {
                Ok(()) | Err(crossbeam_channel::TrySendError::Full(_)) => true,
                Err(crossbeam_channel::TrySendError::Disconnected(_)) => false,
            });
        }
    }
}

/// Start passing on this process's refused connections, and return where they come (one
/// reason per refused connection, printable, at most `MAX_WAITING` waiting). Installs the
/// process's global `tracing` subscriber ([`install`]) if no call did yet; when another
/// program's is installed already, nothing comes (the run goes on).
pub fn watch() -> Receiver<String> {
    let (tx, rx) = crossbeam_channel::bounded(MAX_WAITING);
    ratelab_runtime::graph::lock(sinks()).push(tx);
    rx
}

/// Install the process's global `tracing` subscriber, once: refused connections for
/// [`watch`], and what `RUST_LOG` selects on stderr (a process of a launch calls it at its
/// start, so `RUST_LOG=zenoh=warn ratelab launch …` shows every process's Zenoh warnings).
/// Does nothing after the first call, or when another subscriber is installed already.
pub fn install() {
    sinks();
}

/// Where refusals go ([`SINKS`]), the subscriber installed at the first call ([`install`]).
fn sinks() -> &'static Mutex<Vec<Sender<String>>> {
    SINKS.get_or_init(|| {
        // Each layer its own filter: a callsite neither selects is disabled at registration.
        // No layer may be an absent `Option` layer: one says it wants every callsite
        // (`tracing-subscriber`'s `Option<L>` with `None`), which turns the refusals'
        // `never` into `sometimes`, and every span Zenoh opens on its hot path is then
        // made and kept in the registry (about 4% of a launch's process, 2026-12-01).
        let refusals = RefusalLayer.with_filter(tracing_subscriber::filter::filter_fn(is_refusal));
        let registry = tracing_subscriber::registry().with(refusals);
        let _ = match log_to_stderr() {
            Some(log) => tracing::subscriber::set_global_default(registry.with(log)),
            None => tracing::subscriber::set_global_default(registry),
        };
        Mutex::new(Vec::new())
    })
}

/// What `RUST_LOG` selects, written to stderr; `None` when it is unset or not a filter
/// `tracing_subscriber::EnvFilter` can read (then nothing is logged, as in Zenoh's own
/// `init_log_from_env`).
///
/// A filter with span or field directives (`zenoh[route_data]=debug`) makes `EnvFilter`
/// want every callsite some of the time, so every span Zenoh opens is made again, as it
/// would be in any Zenoh program: a cost of debugging with such a filter, not of a run.
fn log_to_stderr<S>() -> Option<impl Layer<S>>
where
    S: Subscriber + for<'a> tracing_subscriber::registry::LookupSpan<'a>,
{
    let filter = tracing_subscriber::EnvFilter::try_from_default_env().ok()?;
    Some(
        tracing_subscriber::fmt::layer()
            .with_writer(std::io::stderr)
            .with_ansi(false)
            .with_filter(filter),
    )
}

/// The launcher's account of refused connections: the first said at once, then at most
/// one line per [`Refusals::EVERY`], counting the rest.
pub struct Refusals {
    rx: Receiver<String>,
    last_said: Option<Instant>,
    unsaid: u64,
    last_reason: String,
}

impl Refusals {
    /// The least time between two lines.
    pub const EVERY: Duration = Duration::from_secs(5);

    /// Start watching ([`watch`]).
    pub fn new() -> Refusals {
        Refusals {
            rx: watch(),
            last_said: None,
            unsaid: 0,
            last_reason: String::new(),
        }
    }

    /// Take what came, and say a line when one is due.
    pub fn say_due(&mut self, say: &dyn Fn(&str)) {
        for r in self.rx.try_iter() {
            self.unsaid += 1;
            self.last_reason = r;
        }
        if self.unsaid == 0 || self.last_said.is_some_and(|t| t.elapsed() < Self::EVERY) {
            return;
        }
        let n = self.unsaid;
        say(&format!(
            "refused {n} connection{} without this launch's credentials ({})",
            if n == 1 { "" } else { "s" },
            self.last_reason
        ));
        self.unsaid = 0;
        self.last_said = Some(Instant::now());
    }
}

impl Default for Refusals {
    fn default() -> Self {
        Refusals::new()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Zenoh opens spans and says events on its hot path (a put, a route): once the
    /// subscriber is installed, all but its TLS link's warnings must be off at the
    /// callsite, never made and then dropped.
    #[test]
    fn once_installed_only_zenohs_tls_warnings_are_enabled() {
        if std::env::var_os("RUST_LOG").is_some() {
            eprintln!("skipped: RUST_LOG asks for more than refusals");
            return;
        }
        install();
        let span = tracing::info_span!(target: "zenoh::net::routing", "route_data");
        assert!(span.is_disabled(), "a span of Zenoh's routing was made");
        let span = tracing::trace_span!(target: "zenoh_transport", "schedule");
        assert!(span.is_disabled(), "a span of Zenoh's transport was made");
        assert!(!tracing::enabled!(target: "zenoh_transport", tracing::Level::WARN));
        assert!(!tracing::enabled!(target: "zenoh_link_tls", tracing::Level::INFO));
        assert!(tracing::enabled!(target: "zenoh_link_tls", tracing::Level::WARN));
    }
}
