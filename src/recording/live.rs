//! The live half of a `--spawn` recording: a gRPC sink to the spawned viewer that can never
//! hold up the file (and whether there is a viewer on PATH to spawn, and how to get one).
//!
//! rerun's `GrpcSink` keeps retrying to connect for as long as it takes and queues at most
//! 100 messages meanwhile; the 101st `send` then blocks. Beside a `FileSink` in one
//! `MultiSink`, that block stops the file as well, and the final flush waits forever, when
//! the viewer cannot start (no display: it exits before it ever connects). Here the gRPC
//! sink runs on a thread of its own behind an unbounded queue; messages are dropped once the
//! viewer process is gone without having connected, and a flush waits at most
//! [`LIVE_FLUSH_LIMIT`].

use crossbeam_channel::{unbounded, Sender};
use rerun::log::{ChunkBatcherConfig, LogMsg};
use rerun::sink::{GrpcSink, GrpcSinkConnectionState, LogSink, SinkFlushError};
use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};
use std::sync::Arc;
use std::time::{Duration, Instant};

/// The longest a flush waits for the live viewer (the file is flushed regardless).
pub(crate) const LIVE_FLUSH_LIMIT: Duration = Duration::from_secs(10);

struct Shared {
    grpc: GrpcSink,
    /// The spawned viewer's process id (`None`: an already running viewer was reused).
    viewer: Option<u32>,
    /// Messages queued and not yet handed to the gRPC sink.
    pending: AtomicUsize,
    /// Set once the viewer is known never to connect: later messages are dropped.
    gave_up: AtomicBool,
}

impl Shared {
    /// Whether the viewer can still receive: connected, or connecting while its process
    /// lives. Gives up for good otherwise.
    fn reachable(&self) -> bool {
        if self.gave_up.load(Ordering::Relaxed) {
            return false;
        }
        let hopeless = match self.grpc.status() {
            GrpcSinkConnectionState::Connected => false,
            GrpcSinkConnectionState::Connecting { .. } => {
                !self.viewer.is_none_or(ratelab_core::procs::process_alive)
            }
            GrpcSinkConnectionState::Disconnected(_) => true,
        };
        if hopeless {
            self.gave_up.store(true, Ordering::Relaxed);
        }
        !hopeless
    }
}

/// A [`LogSink`] to a live viewer that never blocks its caller.
pub(crate) struct LiveSink {
    tx: Sender<LogMsg>,
    shared: Arc<Shared>,
}

impl LiveSink {
    /// A sink to the viewer at rerun's default address, spawned as process `viewer`.
    pub(crate) fn new(viewer: Option<u32>) -> Self {
        let shared = Arc::new(Shared {
            grpc: GrpcSink::default(),
            viewer,
            pending: AtomicUsize::new(0),
            gave_up: AtomicBool::new(false),
        });
        let (tx, rx) = unbounded::<LogMsg>();
        let forward = shared.clone();
        // Not joined: when the viewer never comes, this thread may stay blocked in the gRPC
        // sink until the process exits.
        let _ = std::thread::Builder::new()
            .name("live-viewer".into())
            .spawn(move || {
                for msg in rx {
                    if forward.reachable() {
                        forward.grpc.send(msg);
                    }
                    forward.pending.fetch_sub(1, Ordering::Relaxed);
                }
            });
        Self { tx, shared }
    }
}

impl LogSink for LiveSink {
    fn send(&self, msg: LogMsg) {
        if !self.shared.reachable() {
            return;
        }
        self.shared.pending.fetch_add(1, Ordering::Relaxed);
        if self.tx.send(msg).is_err() {
            self.shared.pending.fetch_sub(1, Ordering::Relaxed);
        }
    }

    fn flush_blocking(&self, timeout: Duration) -> Result<(), SinkFlushError> {
        let limit = timeout.min(LIVE_FLUSH_LIMIT);
        let start = Instant::now();
        while self.shared.pending.load(Ordering::Relaxed) > 0 {
            if !self.shared.reachable() {
                break;
            }
            if start.elapsed() >= limit {
                return Err(SinkFlushError::Timeout);
            }
            std::thread::sleep(Duration::from_millis(20));
        }
        if !self.shared.reachable() {
            return Err(SinkFlushError::failed(
                "the viewer exited before it connected",
            ));
        }
        self.shared
            .grpc
            .flush_blocking(limit.saturating_sub(start.elapsed()))
    }

    fn default_batcher_config(&self) -> ChunkBatcherConfig {
        self.shared.grpc.default_batcher_config()
    }
}

/// The version of the stock rerun viewer ratelab's recordings are drawn with and checked
/// against: what `pip install rerun-sdk` gives today (docs/recordings.md says why ratelab
/// writes with the crate 0.36.3, which that viewer reads and takes a live stream from).
macro_rules! viewer_version {
    () => {
        "0.41.0"
    };
}

/// [`VIEWER_INSTALL`]'s version, for the other ways to get that viewer (`cargo install
/// rerun-cli --version …`).
pub const VIEWER_VERSION: &str = viewer_version!();

/// How a user gets the stock rerun viewer that opens ratelab's recordings
/// ([`VIEWER_VERSION`]).
pub const VIEWER_INSTALL: &str = concat!("pip install rerun-sdk==", viewer_version!());

/// The line that tells a user how to open the recording at `path`: `open it with: rerun
/// PATH`, and where no `rerun` is on PATH, how to get one ([`VIEWER_INSTALL`]).
pub fn open_hint(path: &std::path::Path) -> String {
    let open = format!("open it with: rerun {}", path.display());
    if viewer_on_path() {
        open
    } else {
        format!("{open} (no rerun on PATH: {VIEWER_INSTALL})")
    }
}

/// A spawnable viewer on PATH?
pub fn viewer_on_path() -> bool {
    std::env::var_os("PATH")
        .map(|paths| std::env::split_paths(&paths).any(|d| d.join("rerun").is_file()))
        .unwrap_or(false)
}
