//! Hostile bags, YAML and replies, generated here at test time: for `ratelab ros2 bag
//! info|echo`,
//! MCAP records assembled byte by byte (lengths that lie, chunks that inflate past what they
//! declare or claim more than their codec can give, schemas and channels never declared,
//! names holding escapes) and `metadata.yaml` nested past its bound. Every case runs the
//! real binary under an address-space limit (`RLIMIT_AS`, as `ulimit -v`) and a time bound,
//! and must end with exit 2 and one line naming what it refused, never a panic (101), an
//! abort or a hang. A SIGTERM ends a long read within a second; a parameter reply of 64 MiB
//! is refused before it is decoded or printed. Beside them, the other
//! classes of the same round: a number that looks like a flag (`--control-hz -inf`) judged
//! by its rule, and an empty list in the bands refused naming its key.

use std::io::Read;
use std::os::unix::process::CommandExt;
use std::path::Path;
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

/// The address space a bag read may take (`ulimit -v`), bytes: the file, one chunk at its
/// largest (128 MiB) and the binary's own mappings fit well under it.
const AS_LIMIT: u64 = 1 << 30;
/// The time any refusal may take.
const WITHIN: Duration = Duration::from_secs(5);

const MAGIC: &[u8] = b"\x89MCAP0\r\n";

/// How a child ended.
#[derive(Debug)]
pub(crate) struct Ended {
    pub(crate) code: Option<i32>,
    pub(crate) stdout: String,
    pub(crate) stderr: String,
    pub(crate) wall: Duration,
}

/// `ratelab args` under [`AS_LIMIT`], killed after `timeout`; `during(pid)` once started.
fn limited(args: &[&str], timeout: Duration, during: impl FnOnce(libc::pid_t)) -> Ended {
    limited_with(args, &[], AS_LIMIT, timeout, during)
}

/// `ratelab ros2 bag VERB DIR` under [`limited`]'s bounds, within [`WITHIN`].
fn read_bag(verb: &str, dir: &Path) -> Ended {
    limited(
        &["ros2", "bag", verb, dir.to_str().unwrap()],
        WITHIN,
        |_| {},
    )
}

/// [`limited`] with environment `env` and address-space limit `as_bytes` (bytes).
pub(crate) fn limited_with(
    args: &[&str],
    env: &[(&str, String)],
    as_bytes: u64,
    timeout: Duration,
    during: impl FnOnce(libc::pid_t),
) -> Ended {
    let start = Instant::now();
    let mut cmd = Command::new(env!("CARGO_BIN_EXE_ratelab"));
    cmd.env_remove("ROS_DOMAIN_ID")
        .env_remove("ZENOH_ROUTER_CHECK_ATTEMPTS")
        .env_remove("ZENOH_CONFIG_OVERRIDE");
    for (k, v) in env {
        cmd.env(k, v);
    }
    cmd.args(args)
        .stdin(Stdio::null())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped());
    // SAFETY: setrlimit is async-signal-safe; nothing else runs between fork and exec.
    unsafe {
        cmd.pre_exec(move || {
            let lim = libc::rlimit {
                rlim_cur: as_bytes,
                rlim_max: as_bytes,
            };
            if libc::setrlimit(libc::RLIMIT_AS, &lim) != 0 {
                return Err(std::io::Error::last_os_error());
            }
            Ok(())
        });
    }
    let mut child = cmd.spawn().expect("ratelab starts");
    let pid = libc::pid_t::try_from(child.id()).unwrap();
    let mut out = child.stdout.take().unwrap();
    let mut err = child.stderr.take().unwrap();
    let o = std::thread::spawn(move || {
        let mut s = Vec::new();
        let _ = out.read_to_end(&mut s);
        s
    });
    let e = std::thread::spawn(move || {
        let mut s = Vec::new();
        let _ = err.read_to_end(&mut s);
        s
    });
    during(pid);
    let code = loop {
        if let Some(status) = child.try_wait().unwrap() {
            break status.code();
        }
        if start.elapsed() > timeout {
            let _ = child.kill();
            let _ = child.wait();
            break None;
        }
        std::thread::sleep(Duration::from_millis(5));
    };
    Ended {
        code,
        stdout: String::from_utf8_lossy(&o.join().unwrap()).into_owned(),
        stderr: String::from_utf8_lossy(&e.join().unwrap()).into_owned(),
        wall: start.elapsed(),
    }
}

/// Both verbs on bag folder `dir` refused: exit 2, one line holding `needle`, in time.
fn assert_bag_refused(dir: &Path, needle: &str) {
    for verb in ["info", "echo"] {
        let o = limited(
            &["ros2", "bag", verb, dir.to_str().unwrap()],
            WITHIN * 2,
            |_| {},
        );
        let what = format!("bag {verb} ({needle}): {o:?}");
        assert_eq!(o.code, Some(2), "exit code: {what}");
        let lines: Vec<&str> = o.stderr.trim_end().lines().collect();
        assert_eq!(lines.len(), 1, "exactly one line on stderr: {what}");
        assert!(!o.stderr.contains("panicked"), "panic text: {what}");
        assert!(o.stderr.contains(needle), "{needle:?} not in: {what}");
        assert!(o.wall < WITHIN, "took {:?}: {what}", o.wall);
    }
}

/// One MCAP record: opcode, length (u64), body.
fn record(op: u8, body: &[u8]) -> Vec<u8> {
    let mut r = vec![op];
    r.extend_from_slice(&(body.len() as u64).to_le_bytes());
    r.extend_from_slice(body);
    r
}

/// An MCAP string or byte array: u32 length, bytes.
fn prefixed(b: &[u8]) -> Vec<u8> {
    let mut r = (b.len() as u32).to_le_bytes().to_vec();
    r.extend_from_slice(b);
    r
}

fn header() -> Vec<u8> {
    record(0x01, &[prefixed(b"ros2"), prefixed(b"hostile")].concat())
}

fn schema(id: u16, name: &str) -> Vec<u8> {
    let body = [
        id.to_le_bytes().to_vec(),
        prefixed(name.as_bytes()),
        prefixed(b"ros2msg"),
        prefixed(b"float64 data"),
    ]
    .concat();
    record(0x03, &body)
}

fn channel(id: u16, schema_id: u16, topic: &str) -> Vec<u8> {
    let body = [
        id.to_le_bytes().to_vec(),
        schema_id.to_le_bytes().to_vec(),
        prefixed(topic.as_bytes()),
        prefixed(b"cdr"),
        0u32.to_le_bytes().to_vec(), // no metadata
    ]
    .concat();
    record(0x04, &body)
}

fn message(channel_id: u16, t_ns: u64, data: &[u8]) -> Vec<u8> {
    let body = [
        channel_id.to_le_bytes().to_vec(),
        0u32.to_le_bytes().to_vec(),
        t_ns.to_le_bytes().to_vec(),
        t_ns.to_le_bytes().to_vec(),
        data.to_vec(),
    ]
    .concat();
    record(0x05, &body)
}

/// A chunk of `records` as `compression` gives them (`""` or `"zstd"`), declaring
/// `declared` bytes uncompressed (the true size when `None`) and no checksum.
fn chunk(records: &[u8], compression: &str, declared: Option<u64>) -> Vec<u8> {
    let data = match compression {
        "" => records.to_vec(),
        "zstd" => zstd::bulk::compress(records, 1).unwrap(),
        _ => records.to_vec(),
    };
    chunk_of(&data, compression, declared.unwrap_or(records.len() as u64))
}

fn chunk_of(data: &[u8], compression: &str, declared: u64) -> Vec<u8> {
    let body = [
        0u64.to_le_bytes().to_vec(),
        0u64.to_le_bytes().to_vec(),
        declared.to_le_bytes().to_vec(),
        0u32.to_le_bytes().to_vec(),
        prefixed(compression.as_bytes()),
        (data.len() as u64).to_le_bytes().to_vec(),
        data.to_vec(),
    ]
    .concat();
    record(0x06, &body)
}

/// A file: magic, header, `body`, data end, footer, magic.
fn file(body: &[u8]) -> Vec<u8> {
    let footer = [0u64.to_le_bytes(), 0u64.to_le_bytes()].concat();
    let footer = [footer, 0u32.to_le_bytes().to_vec()].concat();
    [
        MAGIC.to_vec(),
        header(),
        body.to_vec(),
        record(0x0F, &0u32.to_le_bytes()),
        record(0x02, &footer),
        MAGIC.to_vec(),
    ]
    .concat()
}

/// A CDR `std_msgs/msg/Float64` of `x`.
fn float64(x: f64) -> Vec<u8> {
    [vec![0, 1, 0, 0], x.to_le_bytes().to_vec()].concat()
}

/// Type, topic and one message, declared in order.
fn declared_message(topic: &str) -> Vec<u8> {
    [
        schema(1, "std_msgs/msg/Float64"),
        channel(1, 1, topic),
        message(1, 20_000_000, &float64(1.5)),
    ]
    .concat()
}

/// A bag folder holding `bytes` as its only `.mcap`.
fn bag(bytes: &[u8]) -> tempfile::TempDir {
    let dir = tempfile::tempdir().unwrap();
    std::fs::write(dir.path().join("b_0.mcap"), bytes).unwrap();
    dir
}

#[test]
fn hand_made_bags_read_so_the_refusals_below_mean_something() {
    // Many short processes (and a 64 MiB compression): never beside a timed test.
    let _m = crate::machine::shared();
    let plain = file(&declared_message("/x"));
    let chunked = file(&chunk(&declared_message("/x"), "", None));
    let zstd = file(&chunk(&declared_message("/x"), "zstd", None));
    for (what, bytes) in [("plain", plain), ("chunked", chunked), ("zstd", zstd)] {
        let d = bag(&bytes);
        let o = read_bag("info", d.path());
        assert_eq!(o.code, Some(0), "{what}: {o:?}");
        assert!(
            o.stdout
                .contains("Topic: /x | Type: std_msgs/msg/Float64 | Count: 1"),
            "{what}: {o:?}"
        );
        let o = read_bag("echo", d.path());
        assert_eq!(o.code, Some(0), "{what}: {o:?}");
        assert!(
            o.stdout.starts_with("# /x at 0.020000000 s\n"),
            "{what}: {o:?}"
        );
    }
    // Cut short inside its one message: read as far as it goes, said, exit 0.
    let mut cut = file(&declared_message("/x"));
    cut.truncate(cut.len() - 60);
    let d = bag(&cut);
    let o = read_bag("info", d.path());
    assert_eq!(o.code, Some(0), "{o:?}");
    assert!(o.stdout.contains("cut short?"), "{o:?}");
    // Cut after its data, inside its summary (here: its closing magic): every message is
    // read, and the summary's loss said (nothing was said).
    let mut summary_cut = file(&declared_message("/x"));
    summary_cut.truncate(summary_cut.len() - 4);
    let d = bag(&summary_cut);
    let o = read_bag("info", d.path());
    assert_eq!(o.code, Some(0), "{o:?}");
    assert!(
        o.stdout.contains("Count: 1 ")
            && o.stdout
                .contains("the bag's data is whole (1 message read) but its summary stops short"),
        "{o:?}"
    );
    // A record longer than the whole file is the file's last (every one before it was
    // read whole): the file stops inside it, as one cut short does. Read as far as it
    // goes, said, and nothing held for the length (the reader's address space is bound):
    // a chunk of a writer that was killed (its length never written), and a bag cut
    // inside a chunk whose length is more than the cut file holds.
    let start = [MAGIC.to_vec(), header()].concat();
    let mut unfinished = start.clone();
    unfinished.push(0x06);
    unfinished.extend_from_slice(&u64::MAX.to_le_bytes());
    unfinished.extend_from_slice(&[0u8; 40]);
    let mut cut_chunk = file(&chunk(&declared_message("/x"), "", None));
    cut_chunk.truncate(start.len() + 40);
    for (what, bytes, said) in [
        (
            "unfinished",
            unfinished,
            "inside a chunk its writer never finished",
        ),
        ("cut chunk", cut_chunk, "inside a record (opcode 0x06)"),
    ] {
        let d = bag(&bytes);
        let o = read_bag("info", d.path());
        assert_eq!(o.code, Some(0), "{what}: {o:?}");
        assert!(
            o.stdout.contains("stops short after 0 messages") && o.stdout.contains(said),
            "{what}: {o:?}"
        );
    }
}

#[test]
fn bags_whose_lengths_and_chunks_lie_are_refused_in_one_line() {
    // Many short processes (and a 64 MiB compression): never beside a timed test.
    let _m = crate::machine::shared();
    let msg = declared_message("/x");
    // A 64-byte file whose first record claims 2^64 - 1 bytes: no writer leaves a length
    // unwritten but a chunk's, so a lie, not a file cut short.
    let mut huge = MAGIC.to_vec();
    huge.push(0x01);
    huge.extend_from_slice(&u64::MAX.to_le_bytes());
    huge.resize(64, 0);
    assert_bag_refused(bag(&huge).path(), "more than the whole file holds");
    // A whole file (it ends in MCAP's closing magic) with a chunk longer than the file:
    // damaged, not cut short.
    let mut lying = file(&chunk(&msg, "", None));
    let at = MAGIC.len() + header().len() + 1;
    assert_eq!(lying[at - 1], 0x06);
    lying[at..at + 8].copy_from_slice(&(1u64 << 20).to_le_bytes());
    assert_bag_refused(bag(&lying).path(), "more than the whole file holds");
    // A chunk claiming 100 bytes whose zstd data inflates to 64 MiB of records.
    let bomb = {
        let mut records = message(1, 0, &vec![0u8; 64 << 20]);
        records.splice(0..0, [schema(1, "t/msg/T"), channel(1, 1, "/x")].concat());
        zstd::bulk::compress(&records, 1).unwrap()
    };
    assert!(bomb.len() < 64 << 10, "{}", bomb.len());
    let d = bag(&file(&chunk_of(&bomb, "zstd", 100)));
    assert_bag_refused(d.path(), "inflates to more than 100 bytes");
    // Chunks that declare more than the bound, or than their codec can yield.
    let d = bag(&file(&chunk_of(&bomb, "zstd", 1 << 40)));
    assert_bag_refused(d.path(), "MAX_CHUNK_BYTES");
    let d = bag(&file(&chunk_of(&[0u8; 16], "zstd", 100 << 20)));
    assert_bag_refused(d.path(), "more than zstd can yield");
    let d = bag(&file(&chunk_of(&msg, "", msg.len() as u64 + 1)));
    assert_bag_refused(d.path(), "more than an uncompressed chunk can yield");
    let d = bag(&file(&chunk_of(&[0u8; 64], "brotli", 64)));
    assert_bag_refused(d.path(), "cannot read");
    // Garbage where zstd data should be.
    let d = bag(&file(&chunk_of(&[0x55u8; 64], "zstd", 64)));
    assert_bag_refused(d.path(), "chunk");
    // A channel naming a schema never declared; a message on a channel never declared.
    let d = bag(&file(
        &[channel(1, 7, "/x"), message(1, 0, &float64(0.0))].concat(),
    ));
    assert_bag_refused(d.path(), "never declared");
    let d = bag(&file(
        &[schema(1, "t/msg/T"), message(3, 0, &float64(0.0))].concat(),
    ));
    assert_bag_refused(d.path(), "never declared");
    // Inside a chunk, a record longer than the chunk.
    let mut inner = declared_message("/x");
    let n = inner.len();
    // The message record is the last: opcode, length, then 34 bytes of body.
    let last = n - (1 + 8 + 2 + 4 + 8 + 8 + 12);
    inner[last + 1..last + 9].copy_from_slice(&(u64::MAX / 2).to_le_bytes());
    let d = bag(&file(&chunk(&inner, "", None)));
    assert_bag_refused(d.path(), "chunk");
}

#[test]
fn names_with_escapes_come_out_printable() {
    // Many short processes (and a 64 MiB compression): never beside a timed test.
    let _m = crate::machine::shared();
    let topic = "/x\u{1b}[2J\u{7}\nspoof";
    let d = bag(&file(&declared_message(topic)));
    for verb in ["info", "echo"] {
        let o = limited(
            &["ros2", "bag", verb, d.path().to_str().unwrap()],
            WITHIN,
            |_| {},
        );
        assert_eq!(o.code, Some(0), "{o:?}");
        assert!(
            !o.stdout.contains('\u{1b}') && !o.stdout.contains('\u{7}'),
            "{o:?}"
        );
        assert!(!o.stdout.contains("\nspoof"), "{o:?}");
    }
}

#[test]
fn metadata_nested_past_its_bound_is_refused_before_it_is_parsed() {
    // Many short processes (and a 64 MiB compression): never beside a timed test.
    let _m = crate::machine::shared();
    let d = bag(&file(&declared_message("/x")));
    // 200 KB of `[`: YAML's parser took 123 s on it.
    std::fs::write(d.path().join("metadata.yaml"), "[".repeat(200_000)).unwrap();
    assert_bag_refused(d.path(), "MAX_YAML_DEPTH");
    // Brackets hidden in strings that close nothing still count.
    let sneaky = "[ ']' ".repeat(100);
    std::fs::write(d.path().join("metadata.yaml"), sneaky).unwrap();
    assert_bag_refused(d.path(), "MAX_YAML_DEPTH");
    // At the bound it is the parser's to judge: it answers at once.
    let at = format!("{}{}", "[".repeat(64), "]".repeat(64));
    std::fs::write(d.path().join("metadata.yaml"), at).unwrap();
    let o = read_bag("info", d.path());
    assert!(o.wall < WITHIN, "{o:?}");
    assert!(o.code == Some(0) || o.code == Some(2), "{o:?}");
}

#[test]
fn sigterm_ends_a_long_bag_read_within_a_second() {
    // 200 chunks of one 128 MiB message of zeros each, about 4 KB apiece compressed: 25 GiB
    // to inflate, far more than a second's work.
    let records = [
        schema(1, "t/msg/T"),
        channel(1, 1, "/x"),
        message(1, 0, &vec![0u8; (128 << 20) - 256]),
    ]
    .concat();
    assert!(records.len() as u64 <= 128 << 20);
    let one = chunk(&records, "zstd", None);
    let body: Vec<u8> = std::iter::repeat_n(one, 200).flatten().collect();
    let d = bag(&file(&body));
    let _alone = crate::machine::alone();
    let mut signalled = None;
    let o = limited(
        &["ros2", "bag", "info", d.path().to_str().unwrap()],
        Duration::from_secs(60),
        |pid| {
            std::thread::sleep(Duration::from_millis(1500));
            signalled = Some(Instant::now());
            // SAFETY: kill(2) on our own child.
            unsafe { libc::kill(pid, libc::SIGTERM) };
        },
    );
    let after = signalled.unwrap().elapsed();
    assert!(
        after < Duration::from_secs(1),
        "ended {after:?} after SIGTERM: {o:?}"
    );
    assert!(!o.stderr.contains("panicked"), "{o:?}");
    assert_ne!(o.code, Some(0), "a stopped read is no success: {o:?}");
}

#[test]
fn a_number_that_looks_like_a_flag_is_judged_by_its_rule() {
    for (flag, value, rule) in [
        (
            "--control-hz",
            "-inf",
            "--control-hz must be a finite rate in (0, 10000]",
        ),
        (
            "--sensor-hz",
            "-1e3",
            "--sensor-hz must be a finite rate in (0, 10000]",
        ),
        ("--duration", "-inf", "-inf"),
        // Too slow to tick in any run, and too long to echo in full.
        (
            "--control-hz",
            "1e-300",
            "--control-hz must be at least 3.171e-9 Hz, one tick in the longest run (315360000 s, ratelab::limits::MAX_DURATION_S), got 1e-300",
        ),
        (
            "--duration",
            "1e300",
            "--duration must be in (0, 315360000] seconds (ten years), got 1e300 (ratelab::limits::MAX_DURATION_S)",
        ),
    ] {
        let o = limited(&["run", flag, value], WITHIN, |_| {});
        let lines: Vec<&str> = o.stderr.trim_end().lines().collect();
        assert_eq!(o.code, Some(2), "{o:?}");
        assert_eq!(lines.len(), 1, "{o:?}");
        assert!(lines[0].contains(rule), "{rule:?} not in {o:?}");
        assert!(!lines[0].contains("unexpected argument"), "{o:?}");
    }
}

#[test]
fn an_empty_list_in_the_bands_is_refused_naming_its_key() {
    let bands =
        std::fs::read_to_string(Path::new(crate::REPO).join("exercises/bands.toml")).unwrap();
    let at = bands.find("[ex1]\nseeds = [0, 1, 2]").expect("ex1's seeds");
    let mut edited = bands.clone();
    edited.replace_range(
        at..at + "[ex1]\nseeds = [0, 1, 2]".len(),
        "[ex1]\nseeds = []",
    );
    let dir = tempfile::tempdir().unwrap();
    let p = dir.path().join("bands.toml");
    std::fs::write(&p, edited).unwrap();
    let b = ratelab_exercises::load_bands(&p).unwrap();
    let e = b
        .of::<ratelab_exercises::ex1::Ex1Bands>()
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("`seeds` is an empty list") && e.contains("[ex1]"),
        "{e}"
    );
    assert!(!e.contains('\n'), "{e}");
}

#[test]
fn a_parameter_reply_past_its_bound_is_refused_before_it_is_decoded() {
    use zenoh::Wait;
    let _m = crate::machine::shared();
    let endpoint = format!("tcp/127.0.0.1:{}", crate::distributed::free_port());
    let mut c = zenoh::Config::default();
    for (k, v) in [
        ("mode", "\"router\"".to_string()),
        ("scouting/multicast/enabled", "false".into()),
        ("listen/endpoints", format!("[\"{endpoint}\"]")),
    ] {
        c.insert_json5(k, &v).unwrap();
    }
    let peer = zenoh::open(c).wait().unwrap();
    // A node `/evil` (rmw_zenoh's node token) whose services answer 64 MiB: a byte array
    // parameter as large as a message may be, four times a reply's bound.
    let _token = peer
        .liveliness()
        .declare_token(format!("@ros2_lv/0/{}/0/0/NN/%/%/evil", peer.zid()))
        .wait()
        .unwrap();
    let reply = zenoh::bytes::ZBytes::from(vec![0u8; 64 << 20]);
    let _services = peer
        .declare_queryable("0/evil/**")
        .callback(move |q| {
            // Answered from a thread of its own: the tests run Zenoh on one thread
            // (`.cargo/config.toml`), which must not wait to send 64 MiB itself.
            let reply = reply.clone();
            std::thread::spawn(move || {
                let _ = q.reply(q.key_expr().clone(), reply).wait();
            });
        })
        .wait()
        .unwrap();
    let env = [crate::ros2::connect_to(&endpoint)];
    for verb in [
        &["param", "get", "/evil", "x"][..],
        &["param", "list", "/evil"],
    ] {
        let args: Vec<&str> = std::iter::once("ros2")
            .chain(verb.iter().copied())
            .collect();
        let o = limited_with(&args, &env, 3 << 30, Duration::from_secs(30), |_| {});
        let what = format!("{verb:?}: {o:?}");
        assert_eq!(o.code, Some(2), "{what}");
        assert_eq!(o.stderr.trim_end().lines().count(), 1, "{what}");
        assert!(o.stderr.contains("MAX_SERVICE_REPLY_BYTES"), "{what}");
        assert!(o.stdout.len() < 1024, "{what}");
    }
}
