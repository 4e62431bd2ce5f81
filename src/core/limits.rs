//! Every bound ratelab puts on what it is given, in one place: how large a graph, a graph
//! file, a message, a launch and a run may be.
//!
//! The bounds are there for hostile or mistaken input (a graph file from the network, a
//! sample from another process), not to keep graphs small: each is sized for real robot
//! software (ROS 2 systems run dozens to hundreds of nodes; a camera image is megabytes) and
//! checked as early as the input allows (a file's or a message's size before it is read or
//! decoded; a graph's counts once its file, at most 16 MiB, is parsed). A refusal names the
//! bound ([`refusal`]); where raising it is safe, the bound's documentation says how.
//!
//! | bound | value | what it protects |
//! | --- | --- | --- |
//! | [`MAX_NODES`] | 65 536 | a graph's nodes |
//! | [`MAX_TOPICS`] | 65 536 | a graph's topics |
//! | [`MAX_SUBSCRIBERS`] | 65 535 | one topic's subscribers (every node but its publisher) |
//! | [`MAX_NODE_PORTS`] | 256 | the topics one Python node reads, and those it publishes |
//! | [`MAX_GRAPH_FILE_BYTES`] | 16 MiB | a graph file, read before it is parsed |
//! | [`MAX_PROCESSES`] | 256 | the processes of one launch |
//! | [`MAX_SAMPLE_BYTES`] | 64 MiB | one message between processes, encoded |
//! | [`MAX_CONTROL_BYTES`] | 64 MiB | one control message between a launch's processes |
//! | [`MAX_ROS_MESSAGE_BYTES`] | 64 MiB | one message from ROS 2 (CDR), before it is decoded (4 KiB for the cartpole's types) |
//! | [`MAX_SERVICE_REQUEST_BYTES`] | 1 MiB | one request to a node's ROS 2 parameter services (CDR), before it is decoded |
//! | [`MAX_SERVICE_REPLY_BYTES`] | 16 MiB | one reply of a node's ROS 2 parameter services, before it is built; one reply read from a ROS 2 service, before it is decoded |
//! | [`MAX_DESCRIBED_TYPES`] | 1024 | the types one ROS 2 type description (`get_type_description`) refers to |
//! | [`MAX_DURATION_S`] | 10 years | a run's length, in whole nanoseconds |
//! | [`MAX_MSG_TYPES`] | 1024 | the message types one process registers, the built-in ones included |
//! | [`MAX_MSG_FIELDS`] | 64 | one message type's fields |
//! | [`MAX_NODE_KINDS`] | 1024 | the node kinds one process registers, the built-in ones included |
//! | [`MAX_NODE_PARAMS`] | 1024 | one node's parameters in a graph file |
//! | [`MAX_SCRIPT_BYTES`] | 16 MiB | a Python script (a node's or a brain's), read before it runs |
//! | [`MAX_FAULTS`] | 64 | the faults one run holds (`--stall`, `--kill` and those injected while it runs) |
//! | [`MAX_GRAPH_QUEUE_BYTES`] | 4 GiB | what a graph's queues may hold at worst (every subscription's depth × its type's largest message), computed when the file is read and at every change of a depth, QoS or rate |
//! | [`MAX_HELD_TRACE_VALUES`] | 64 Mi | the trace a run returns in memory (`ratelab.run`): rows × columns, checked before it starts |
//! | [`MAX_REAL_CLOCK_THREADS`] | 1024 | the threads a real-clock run starts (one per node on a thread of its own, and the shared executors'), checked before any starts |
//! | [`MAX_SWEEP_RUNS`] | 100 000 | the runs of one sweep (the product of its lists' lengths), checked before any starts |

/// The most commands a run takes scheduled at run times (`ratelab::run_spec::RunSpec`'s
/// `commands`: a session log's run).
pub const MAX_COMMANDS: usize = 10_000;

/// The most nodes a graph may have: 65 536. A node costs its scheduler entry, its queues
/// and its counters (about a kilobyte), so the bound keeps a hostile graph file's graph
/// under a few hundred MB; a program that needs larger graphs raises it and rebuilds.
pub const MAX_NODES: usize = 1 << 16;

/// The most topics a graph may have: 65 536 (each has exactly one publisher, and a Python
/// node may publish up to [`MAX_NODE_PORTS`]).
pub const MAX_TOPICS: usize = 1 << 16;

/// The most subscribers one topic may have: every node of the largest graph but the
/// topic's publisher. Each subscription has its own queue (ROS 2's rule), of the topic's
/// history depth.
pub const MAX_SUBSCRIBERS: usize = MAX_NODES - 1;

/// The most topics one Python node reads, and the most it publishes: 256 each (a node
/// with more is better split; the bound keeps one node's per-tick work bounded).
pub const MAX_NODE_PORTS: usize = 256;

/// A graph file larger than this is refused before it is parsed: 16 MiB (a 10 000-node
/// graph written out in full is about 1.5 MiB).
pub const MAX_GRAPH_FILE_BYTES: u64 = 16 << 20;

/// The most processes one launch may start (`ratelab launch`): 256. Each is an operating
/// system process with its own Zenoh session and identity; the launcher's lockstep waits
/// on every one at every instant, so its cost grows with this number (`BENCHMARKS.md`).
/// Under the virtual clock every process links to every other (P (P − 1) / 2 links): on a
/// 2-core machine 64 processes start (in about 25 s), 96 did not.
pub const MAX_PROCESSES: usize = 256;

/// The largest message one process sends another, encoded: 64 MiB (a 4K RGB image is
/// 25 MB). A larger sample is refused by the receiver before it is decoded.
pub const MAX_SAMPLE_BYTES: usize = 64 << 20;

/// The largest message accepted from ROS 2 (CDR with its encapsulation header), checked
/// before it is decoded: 64 MiB, as [`MAX_SAMPLE_BYTES`], for a type that needs it (a
/// camera's `sensor_msgs/msg/Image`); each type sets its own bound under this one
/// (`ratelab::msg::RosMapped::MAX_ROS_BYTES`: 4 KiB for the cartpole's, whose messages are
/// under 200 bytes and whose decoded form, a `JointState`'s names, can be several times its
/// bytes). A sequence inside a message is read only as far as its bytes go.
pub const MAX_ROS_MESSAGE_BYTES: usize = MAX_SAMPLE_BYTES;

/// The largest request a node's ROS 2 parameter services read (CDR with its header),
/// checked before it is decoded: 1 MiB. A request names parameters (the largest real one,
/// `set_parameters` with a long array, is far smaller); a larger one is answered with nothing.
pub const MAX_SERVICE_REQUEST_BYTES: usize = 1 << 20;

/// The largest reply a node's ROS 2 parameter services build, bounded before it is built:
/// 16 MiB. A request naming one large parameter many times would otherwise make a reply
/// thousands of times its own size; it is refused (not answered).
pub const MAX_SERVICE_REPLY_BYTES: usize = 16 << 20;

/// The most types one ROS 2 type description read from the network may refer to
/// (`~/get_type_description`'s `referenced_type_descriptions`): 1024 (a real message refers
/// to tens). Each is walked when a message is decoded by it.
pub const MAX_DESCRIBED_TYPES: usize = 1024;

/// The largest control message between a launch's processes, encoded: 64 MiB. Control
/// messages are JSON; the largest carry a graph file (at most [`MAX_GRAPH_FILE_BYTES`],
/// escaped) or every topic's counters of a large graph (about 150 bytes a topic).
pub const MAX_CONTROL_BYTES: usize = 64 << 20;

/// The longest run accepted, seconds (`--duration`, an exercise's bands, `bench`, a session
/// log's run, a fault's time): ten years of 365 days, 315 360 000 s (run time is whole
/// nanoseconds in a `u64`, good for 584 years). A run's memory does not grow with its length
/// (the latency's percentiles are exact over the first hour's samples, from a streaming
/// histogram past it), nor does its trace's: `ratelab run --out` writes `trace.csv` a row at
/// a time as the run goes, and a run that returns its trace in memory (`ratelab.run`) is
/// refused past [`MAX_HELD_TRACE_VALUES`] before it starts. A lab run ends here, so its log
/// replays.
pub const MAX_DURATION_S: f64 = 315_360_000.0;

/// The most message types one process may have registered, the built-in ones included:
/// 1024. Each is a few hundred bytes in a list looked up by name when a graph is built; a
/// program with more raises it and rebuilds.
pub const MAX_MSG_TYPES: usize = 1024;

/// The most fields one message type may have: 64 (ROS 2's common messages have a few
/// dozen at most; an array of values is one bytes field).
pub const MAX_MSG_FIELDS: usize = 64;

/// The most node kinds one process may have, the built-in ones included: 1024. A list
/// looked up by name when a graph is built; a program with more raises it and rebuilds.
pub const MAX_NODE_KINDS: usize = 1024;

/// The most parameters one node may be given in a graph file: 1024 (a table read into a
/// node's Python dict, or its kind's checks).
pub const MAX_NODE_PARAMS: usize = 1024;

/// The largest Python script read, a node's or a brain's: 16 MiB, as a graph file (a
/// learner's node is a few KiB; a generated one may be larger).
pub const MAX_SCRIPT_BYTES: u64 = 16 << 20;

/// The most faults one run may hold: its settings' (`--stall`, `--kill`) and those
/// injected by command while it runs: 64. Each is checked at every tick of its node.
pub const MAX_FAULTS: usize = 64;

/// The most bytes a graph's queues may hold at worst: 4 GiB. Each topic's worst case is
/// the messages its queues may hold at once times the largest such message, and the graph's
/// is the sum over its topics (`ratelab::graph::GraphSpec::queue_bytes`):
///
/// - **messages**: each subscription has a queue of its own (ROS 2's rule), of the topic's
///   history depth (keep-last, or keep-all's cap), and on a link (`link = { … }`) also the
///   messages in flight, at most the publisher's rate × the longest transit (delay +
///   jitter, and 15 retransmissions on a reliable link), rounded up, plus one; a topic
///   nobody reads keeps one queue; and the publisher holds one message more (the frame it is
///   sending). The pixels of a frame are shared by the queues of one process, but a keep-all
///   queue read slowly keeps frames the others have let go, so each queue is counted whole;
/// - **the largest message** of the topic's type: 8 bytes a number, the slot of a text or
///   bytes field, and the message's stamps, doubled (a queue grows by doubling); for a type
///   with text or bytes fields (unbounded in themselves) their contents are the size the
///   graph implies — a `camera`'s frame, `width_px` × `height_px` bytes (`mono8`) — or, with
///   no size implied (a Python or external node's image), the bound on one message between
///   processes, [`MAX_SAMPLE_BYTES`].
///
/// Why 4 GiB: a 4096 × 4096 frame (16 MiB, the camera's largest) fits 256 times, more than
/// any robot's image pipeline keeps (ROS 2's default depth is 10, its sensor-data profile's
/// 5), and half of an 8 GiB machine is left to the process itself, its Python nodes and
/// brains, and the run's trace. A graph past it (a 4096 × 4096 camera at 100 Hz on a topic of
/// depth 1000: 15.6 GiB) would fill the machine in seconds and abort; it is refused when read,
/// in one line naming the topics that take the most. Lower their depth (or the frame); a
/// machine with more memory may raise this and rebuild. Not counted here: the copies of
/// the queues the lab keeps for seeking back (`ratelab::runcore::max_history`) and the
/// run's trace.
pub const MAX_GRAPH_QUEUE_BYTES: u64 = 4 << 30;

/// The most threads a real-clock run starts: 1024 (the virtual clock starts none). The real
/// clock runs each node on a thread of its own unless an executor shares threads
/// (`[executors]` tables, `--executor single_threaded` or `multi_threaded:N`), so a run needs
/// one thread per node on a thread of its own plus each shared executor's threads (across
/// a launch's processes, together: they share the machine and the user's process limit).
/// Checked before any thread starts, so a larger graph is refused in one line that says how
/// to share threads, never a panic midway.
///
/// Why 1024: a node thread reserves the default stack of Rust's threads, 2 MiB of address
/// space (`RUST_MIN_STACK` sets it; node threads keep it, as a Python callback or a brain
/// may recurse deeply), so 1024 threads reserve 2 GiB: well inside an 8 GiB address-space
/// limit, where 5,000 threads (10 GiB) fail to start. It is also below the process limits
/// machines commonly set (a container's `pids.max`, `RLIMIT_NPROC`, the kernel's
/// `threads-max` on a small machine), and above what real robot software runs (dozens to
/// hundreds of nodes). A thread the machine still refuses ends the run cleanly, as a failed
/// node (exit 2), the threads already started stopped and joined.
pub const MAX_REAL_CLOCK_THREADS: usize = 1024;

/// The line that refuses input for passing the bound named `bound`: `what`, then the
/// constant a program can look up (`"a graph has at most 65536 nodes
/// (ratelab::limits::MAX_NODES)"`). Every bound of this module is refused so.
pub fn refusal(what: impl std::fmt::Display, bound: &str) -> String {
    format!("{what} (ratelab::limits::{bound})")
}

// A node's ports fit in a graph's topics.
const _: () = assert!(MAX_NODE_PORTS <= MAX_TOPICS);

// One message of the largest size fits the queues' budget many times over.
const _: () = assert!(MAX_SAMPLE_BYTES as u64 * 16 <= MAX_GRAPH_QUEUE_BYTES);

/// The most trace values (rows × columns of `trace.csv`: actuator steps kept, each a value
/// per column) a run returns in memory may hold: 64 Mi (67 108 864). `ratelab.run` in
/// Python returns its trace as `trace.csv`'s text and as NumPy arrays, about 10 bytes of
/// text and at most 8 of array per value (estimated from the chapter's rows, not measured),
/// so about 1.2 GB at the bound and up to twice the text while they are made. The chapter's
/// graph has 12 columns: a day of its run time (4 320 001 steps, 52 M values) fits, two do
/// not. Past it a run is refused before it starts (`ratelab.TraceTooLarge`, a
/// `MemoryError`), naming the `--trace-every` that fits. `ratelab run --out` holds no trace
/// (it writes `trace.csv` as the run goes), so its trace has no such bound.
pub const MAX_HELD_TRACE_VALUES: u64 = 1 << 26;

/// The most runs one sweep makes (`ratelab sweep`, `ratelab.sweep`): the product of its
/// lists' lengths (clocks × sensor rates × control rates × depths × seeds), 100 000. Each
/// run keeps a row of figures (about 2 KB) until the sweep ends, so the rows stay within
/// about 200 MB; at the chapter's 10 s virtual run (a few ms each on one core) such a sweep
/// takes minutes. A larger grid is refused before any run starts, as a grid of 3 000 × 3 000
/// rates asked for 20 GB at once.
pub const MAX_SWEEP_RUNS: usize = 100_000;

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn refusal_names_the_bound() {
        assert_eq!(
            refusal(
                format_args!("a graph has at most {MAX_NODES} nodes"),
                "MAX_NODES"
            ),
            "a graph has at most 65536 nodes (ratelab::limits::MAX_NODES)"
        );
    }

    #[test]
    fn the_memory_bounds_are_what_their_documentation_says() {
        // The camera's largest frame (4096 × 4096 mono8) fits the queues' budget 256 times;
        // the issue's /image at depth 1000 does not.
        let frame = 4096u64 * 4096;
        assert_eq!(MAX_GRAPH_QUEUE_BYTES / frame, 256);
        assert!(1000 * frame > MAX_GRAPH_QUEUE_BYTES);
        // The real clock's threads reserve 2 GiB of Rust's default 2 MiB stacks.
        assert_eq!(MAX_REAL_CLOCK_THREADS as u64 * (2 << 20), 2 << 30);
        assert_eq!(
            refusal("too many threads", "MAX_REAL_CLOCK_THREADS"),
            "too many threads (ratelab::limits::MAX_REAL_CLOCK_THREADS)"
        );
    }
}
