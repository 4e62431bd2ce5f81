//! Hostile input, generated here at test time (raw pickle bytes, zips written with the zip
//! crate, hand-encoded ONNX, FIFOs, symbolic links, sparse files): for every case the
//! `ratelab` binary must refuse with exit code 2 and exactly one line on stderr, print no
//! panic, stay under the memory cap (the child's peak resident set: `ru_maxrss` from
//! `wait4`, or `VmHWM` sampled while it runs — see [`run_child`]) and end within the time
//! bound. Clobber cases check
//! that a canary file is unchanged; the signal cases that a slow real-clock run ends within
//! a second of its duration and of SIGINT.

use prost::Message;
use std::io::{Read, Write};
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

/// The memory cap for loading any file, MiB (issue #14).
const CAP_MIB: f64 = 256.0;
/// The time bound for refusing any hostile file, s.
const REFUSE_WITHIN: Duration = Duration::from_secs(5);

/// How a child process ended.
#[derive(Debug)]
pub(crate) struct Outcome {
    pub(crate) code: Option<i32>,
    pub(crate) stdout: String,
    pub(crate) stderr: String,
    /// Peak resident set size, MiB.
    pub(crate) peak_mib: f64,
    /// Whether `peak_mib` is the child's own: false when the child ended before its first
    /// sample and its `ru_maxrss` may be this test binary's peak (see [`run_child`]); then
    /// `peak_mib` is only an upper bound, and [`measure_child`] runs the child again.
    pub(crate) peak_is_the_child_s: bool,
    /// Voluntary context switches (`ru_nvcsw`) of the child and the children it reaped.
    pub(crate) voluntary_switches: i64,
    pub(crate) wall: Duration,
    pub(crate) timed_out: bool,
}

/// Run `ratelab args` in `cwd`, killing it after `timeout`; `during(pid)` runs once the
/// child has started (e.g. to send it a signal).
///
/// Peak memory: a child's `ru_maxrss` (from `wait4`) also holds the peak of the memory it
/// was spawned from, this test binary's, which Linux counts at its `exec` (the spawn shares
/// the parent's pages until then). So when this binary's own peak (`VmHWM`) is not below
/// the child's `ru_maxrss`, that figure says nothing of the child, and its peak is taken
/// from its own `VmHWM` (`/proc/PID/status`), sampled every millisecond while it runs:
/// its high-water mark since its `exec`, as of the last sample.
#[allow(
    clippy::zombie_processes,
    reason = "the child is reaped by wait4, which also reports its peak memory"
)]
pub(crate) fn run_child(
    args: &[&str],
    cwd: &Path,
    timeout: Duration,
    during: impl FnOnce(libc::pid_t),
) -> Outcome {
    let start = Instant::now();
    let mut child = Command::new(env!("CARGO_BIN_EXE_ratelab"))
        .args(args)
        .current_dir(cwd)
        .stdin(Stdio::null())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("ratelab starts");
    let pid = child.id() as libc::pid_t;
    let mut out = child.stdout.take().unwrap();
    let mut err = child.stderr.take().unwrap();
    let out_t = std::thread::spawn(move || {
        let mut s = String::new();
        let _ = out.read_to_string(&mut s);
        s
    });
    let err_t = std::thread::spawn(move || {
        let mut s = String::new();
        let _ = err.read_to_string(&mut s);
        s
    });
    during(pid);
    let mut status = 0;
    // SAFETY: rusage is plain data; wait4 fills it.
    let mut usage: libc::rusage = unsafe { std::mem::zeroed() };
    let mut timed_out = false;
    let mut sampled_kib = 0u64;
    loop {
        sampled_kib = sampled_kib.max(vm_hwm_kib(&format!("/proc/{pid}/status")));
        // SAFETY: waiting for our own child, with valid out-pointers.
        let r = unsafe { libc::wait4(pid, &mut status, libc::WNOHANG, &mut usage) };
        if r == pid {
            break;
        }
        assert!(r == 0, "wait4 failed");
        if start.elapsed() > timeout {
            timed_out = true;
            // SAFETY: killing our own child.
            unsafe { libc::kill(pid, libc::SIGKILL) };
            // SAFETY: as above, blocking.
            unsafe { libc::wait4(pid, &mut status, 0, &mut usage) };
            break;
        }
        std::thread::sleep(Duration::from_millis(1));
    }
    let wall = start.elapsed();
    let maxrss_kib = u64::try_from(usage.ru_maxrss).unwrap_or(0);
    // `ru_maxrss` is the child's own when this binary's peak is below it. Otherwise the
    // samples are; without one (the child ended before it, as a quick refusal on a loaded
    // machine may), `ru_maxrss` is only an upper bound.
    let maxrss_is_the_child_s = vm_hwm_kib("/proc/self/status") < maxrss_kib;
    let (peak_kib, peak_is_the_child_s) = if !maxrss_is_the_child_s && sampled_kib > 0 {
        (sampled_kib, true)
    } else {
        (maxrss_kib, maxrss_is_the_child_s)
    };
    let code = libc::WIFEXITED(status).then(|| libc::WEXITSTATUS(status));
    Outcome {
        code,
        stdout: out_t.join().unwrap(),
        stderr: err_t.join().unwrap(),
        peak_mib: peak_kib as f64 / 1024.0,
        peak_is_the_child_s,
        voluntary_switches: usage.ru_nvcsw,
        wall,
        timed_out,
    }
}

/// [`run_child`] for its peak memory: run again (at most 5 times in all) while that peak is
/// not the child's own (it ended before its first sample, its `ru_maxrss` this binary's
/// peak). Only for a child whose run may be repeated (no side effects asserted between).
pub(crate) fn measure_child(args: &[&str], cwd: &Path, timeout: Duration) -> Outcome {
    let mut o = run_child(args, cwd, timeout, |_| {});
    for _ in 1..5 {
        if o.peak_is_the_child_s {
            break;
        }
        o = run_child(args, cwd, timeout, |_| {});
    }
    o
}

/// `VmHWM` of the `/proc/PID/status` file `path`, KiB (0 when it cannot be read: the
/// process has ended).
pub(crate) fn vm_hwm_kib(path: &str) -> u64 {
    std::fs::read_to_string(path)
        .ok()
        .and_then(|s| {
            s.lines()
                .find_map(|l| l.strip_prefix("VmHWM:"))
                .and_then(|v| v.trim().trim_end_matches("kB").trim().parse().ok())
        })
        .unwrap_or(0)
}

/// Run and assert the refusal contract; returns the one stderr line.
fn assert_refused(args: &[&str], cwd: &Path, needle: &str) -> String {
    let o = measure_child(args, cwd, REFUSE_WITHIN * 3);
    // The measurements, for `--nocapture` (BENCHMARKS-style figures for the worst cases).
    println!(
        "{:>7.1} MiB {:>6} ms  {}",
        o.peak_mib,
        o.wall.as_millis(),
        args.join(" ")
    );
    let what = format!("{args:?}: {o:?}");
    assert!(!o.timed_out, "hung: {what}");
    assert_eq!(o.code, Some(2), "exit code: {what}");
    let lines: Vec<&str> = o.stderr.trim_end().lines().collect();
    assert_eq!(lines.len(), 1, "exactly one line on stderr: {what}");
    assert!(!o.stderr.contains("panicked"), "panic text: {what}");
    assert!(o.stderr.contains(needle), "{needle:?} not in: {what}");
    assert!(o.peak_mib < CAP_MIB, "peak {:.0} MiB: {what}", o.peak_mib);
    assert!(o.wall < REFUSE_WITHIN, "took {:?}: {what}", o.wall);
    lines[0].to_string()
}

/// A policy file refused by `run --smoke --policy FILE`, and the reason in its one line.
fn assert_policy_refused(file: &Path, needle: &str) -> String {
    let dir = file.parent().unwrap();
    let line = assert_refused(
        &["run", "--smoke", "--policy", file.to_str().unwrap()],
        dir,
        needle,
    );
    let name = file.file_name().unwrap().to_str().unwrap();
    assert!(line.contains(name), "the line names the file: {line}");
    line
}

fn fixture(name: &str) -> PathBuf {
    let p = Path::new(crate::REPO).join("../shared/fixtures").join(name);
    assert!(p.is_file(), "fixture missing: {}", p.display());
    p
}

fn mkfifo(p: &Path) {
    let c = std::ffi::CString::new(p.to_str().unwrap()).unwrap();
    // SAFETY: a valid NUL-terminated path.
    assert_eq!(unsafe { libc::mkfifo(c.as_ptr(), 0o600) }, 0);
}

// ---------------------------------------------------------------------------------------
// Pickles and torch.save archives, byte by byte

/// A pickle program, written opcode by opcode.
#[derive(Default)]
struct Pickle(Vec<u8>);

impl Pickle {
    fn new() -> Self {
        Self(vec![0x80, 2])
    }
    fn op(&mut self, b: &[u8]) -> &mut Self {
        self.0.extend_from_slice(b);
        self
    }
    fn global(&mut self, module: &str, name: &str) -> &mut Self {
        self.op(b"c")
            .op(module.as_bytes())
            .op(b"\n")
            .op(name.as_bytes())
            .op(b"\n")
    }
    fn str(&mut self, s: &str) -> &mut Self {
        self.op(b"X")
            .op(&(s.len() as u32).to_le_bytes())
            .op(s.as_bytes())
    }
    fn int(&mut self, i: i64) -> &mut Self {
        match i32::try_from(i) {
            Ok(v) => self.op(b"J").op(&v.to_le_bytes()),
            Err(_) => self.op(&[0x8a, 8]).op(&i.to_le_bytes()),
        }
    }
    fn ints(&mut self, v: &[i64]) -> &mut Self {
        self.op(b"(");
        for &i in v {
            self.int(i);
        }
        self.op(b"t")
    }
    fn empty_ordered_dict(&mut self) -> &mut Self {
        self.global("collections", "OrderedDict").op(b")R")
    }
    /// `_rebuild_tensor_v2((storage, type, key, 'cpu', numel), offset, size, stride, False,
    /// OrderedDict())`, with `n_args` of those six arguments.
    fn tensor(&mut self, t: &TensorDecl, n_args: usize) -> &mut Self {
        self.global("torch._utils", "_rebuild_tensor_v2").op(b"(");
        let parts: [&dyn Fn(&mut Pickle); 6] = [
            &|p| {
                p.op(b"(")
                    .str("storage")
                    .global("torch", &t.storage)
                    .str(&t.key)
                    .str("cpu")
                    .int(t.numel)
                    .op(b"tQ");
            },
            &|p| {
                p.int(t.offset);
            },
            &|p| {
                p.ints(&t.size);
            },
            &|p| {
                p.ints(&t.stride);
            },
            &|p| {
                p.op(&[0x89]);
            },
            &|p| {
                p.empty_ordered_dict();
            },
        ];
        for part in parts.iter().take(n_args) {
            part(self);
        }
        self.op(b"tR")
    }
    fn stop(&mut self) -> Vec<u8> {
        self.op(b".");
        std::mem::take(&mut self.0)
    }
}

/// One tensor entry of a state_dict.
#[derive(Clone)]
struct TensorDecl {
    name: String,
    storage: String,
    key: String,
    numel: i64,
    offset: i64,
    size: Vec<i64>,
    stride: Vec<i64>,
    /// The storage record's bytes.
    data: Vec<u8>,
}

fn row_major(size: &[i64]) -> Vec<i64> {
    let mut stride = vec![1; size.len()];
    for i in (0..size.len().saturating_sub(1)).rev() {
        stride[i] = stride[i + 1] * size[i + 1];
    }
    stride
}

fn float_tensor(name: &str, key: usize, size: &[i64], value: f32) -> TensorDecl {
    let numel: i64 = size.iter().product();
    TensorDecl {
        name: name.into(),
        storage: "FloatStorage".into(),
        key: key.to_string(),
        numel,
        offset: 0,
        size: size.to_vec(),
        stride: row_major(size),
        data: std::iter::repeat_n(value.to_le_bytes(), numel as usize)
            .flatten()
            .collect(),
    }
}

/// The six actor tensors of hidden width `h`.
fn actor(h: i64) -> Vec<TensorDecl> {
    let keys = ratelab::checkpoint::ACTOR_KEYS;
    let shapes: [Vec<i64>; 6] = [
        vec![h, 5],
        vec![h],
        vec![h, h],
        vec![h],
        vec![1, h],
        vec![1],
    ];
    keys.iter()
        .zip(shapes)
        .enumerate()
        .map(|(i, (k, s))| float_tensor(k, i, &s, 0.01))
        .collect()
}

/// `OrderedDict` of `tensors` (each with `n_args` rebuild arguments) as data.pkl.
fn state_dict_pickle(tensors: &[TensorDecl], n_args: usize) -> Vec<u8> {
    let mut p = Pickle::new();
    p.empty_ordered_dict().op(b"(");
    for t in tensors {
        p.str(&t.name).tensor(t, n_args);
    }
    p.op(b"u").stop()
}

/// A `torch.save`-style archive: `archive/data.pkl` and one record per storage.
fn torch_zip(pkl: &[u8], records: &[(String, Vec<u8>)]) -> Vec<u8> {
    let mut w = zip::ZipWriter::new(std::io::Cursor::new(Vec::new()));
    let opts =
        zip::write::SimpleFileOptions::default().compression_method(zip::CompressionMethod::Stored);
    w.start_file("archive/data.pkl", opts).unwrap();
    w.write_all(pkl).unwrap();
    for (key, data) in records {
        w.start_file(format!("archive/data/{key}"), opts).unwrap();
        w.write_all(data).unwrap();
    }
    w.start_file("archive/version", opts).unwrap();
    w.write_all(b"3\n").unwrap();
    w.finish().unwrap().into_inner()
}

fn write_pt(dir: &Path, name: &str, tensors: &[TensorDecl], n_args: usize) -> PathBuf {
    let mut records: Vec<(String, Vec<u8>)> = Vec::new();
    for t in tensors {
        if !records.iter().any(|(k, _)| *k == t.key) {
            records.push((t.key.clone(), t.data.clone()));
        }
    }
    let p = dir.join(name);
    std::fs::write(&p, torch_zip(&state_dict_pickle(tensors, n_args), &records)).unwrap();
    p
}

fn write_raw_pt(dir: &Path, name: &str, pkl: &[u8]) -> PathBuf {
    let p = dir.join(name);
    std::fs::write(&p, torch_zip(pkl, &[])).unwrap();
    p
}

#[test]
fn a_generated_checkpoint_loads_so_the_refusals_below_are_meaningful() {
    let dir = tempfile::tempdir().unwrap();
    let p = write_pt(dir.path(), "ok.pt", &actor(8), 6);
    let mut brain = ratelab::checkpoint::load_policy(p.to_str().unwrap()).unwrap();
    assert!(brain.label().contains("hidden 8"));
    // tanh(5·0.05 + …): all weights 0.01, so the output is small and finite.
    assert!(brain.act(&[1.0; 5])[0].is_finite());
    // An extra step counter in an IntStorage (as real checkpoints carry) and a bool mask:
    // loaded silently, and the run is clean.
    let mut extra = actor(8);
    let mut step = float_tensor("global_step", 6, &[], 0.0);
    step.storage = "IntStorage".into();
    step.data = 12345i32.to_le_bytes().to_vec();
    let mut mask = float_tensor("mask", 7, &[3], 0.0);
    mask.storage = "BoolStorage".into();
    mask.data = vec![1, 0, 1];
    extra.push(step);
    extra.push(mask);
    let p = write_pt(dir.path(), "extra.pt", &extra, 6);
    let o = run_child(
        &["run", "--smoke", "--policy", p.to_str().unwrap()],
        dir.path(),
        Duration::from_secs(30),
        |_| {},
    );
    assert_eq!(o.code, Some(0), "{o:?}");
    assert_eq!(o.stderr, "", "unused tensors must not matter: {o:?}");
    // _rebuild_parameter around the tensors loads too.
    let mut p = Pickle::new();
    p.empty_ordered_dict().op(b"(");
    for t in &actor(8) {
        p.str(&t.name)
            .global("torch._utils", "_rebuild_parameter")
            .op(b"(")
            .tensor(t, 6)
            .op(&[0x88])
            .empty_ordered_dict()
            .op(b"tR");
    }
    let pkl = p.op(b"u").stop();
    let records: Vec<_> = actor(8).into_iter().map(|t| (t.key, t.data)).collect();
    let path = dir.path().join("param.pt");
    std::fs::write(&path, torch_zip(&pkl, &records)).unwrap();
    assert!(ratelab::checkpoint::load_policy(path.to_str().unwrap()).is_ok());
}

#[test]
fn tensors_larger_than_their_storage_are_refused_before_allocating() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    // 10¹² elements over a 4-element storage.
    let mut t = actor(8);
    t[0].size = vec![1_000_000, 1_000_000];
    t[0].stride = vec![1_000_000, 1];
    t[0].numel = 4;
    t[0].data = vec![0; 16];
    assert_policy_refused(&write_pt(d, "huge.pt", &t, 6), "reaches past its storage");
    // A shape whose element count overflows 64 bits.
    let mut t = actor(8);
    t[2].size = vec![1 << 40, 1 << 40];
    t[2].stride = vec![0, 0];
    assert_policy_refused(&write_pt(d, "overflow.pt", &t, 6), "overflows");
    // Broadcast strides: a declared 2¹⁴ × 2¹⁴ view of one element (1 GiB if materialized).
    let mut t = actor(8);
    t[2].size = vec![1 << 14, 1 << 14];
    t[2].stride = vec![0, 0];
    assert_policy_refused(&write_pt(d, "broadcast.pt", &t, 6), "more than");
    // A storage that declares more elements than its record holds.
    let mut t = actor(8);
    t[1].numel = 1 << 30;
    assert_policy_refused(&write_pt(d, "short-record.pt", &t, 6), "record holds");
    // A negative offset.
    let mut t = actor(8);
    t[1].offset = -1;
    assert_policy_refused(&write_pt(d, "negative.pt", &t, 6), "offset");
    // An offset past the end.
    let mut t = actor(8);
    t[1].offset = 5;
    assert_policy_refused(&write_pt(d, "offset.pt", &t, 6), "reaches past its storage");
}

#[test]
fn the_largest_checkpoint_the_limits_accept_stays_under_the_cap() {
    let _machine = crate::machine::shared();
    // Just under the tensor budget: a 2800-wide actor whose 2800×2800 weight is one float
    // broadcast (stride 0), so the file is tiny and all the memory is ratelab's.
    let dir = tempfile::tempdir().unwrap();
    let mut t = actor(2800);
    t[2].stride = vec![0, 0];
    t[2].numel = 1;
    t[2].data = 0.001f32.to_le_bytes().to_vec();
    let p = write_pt(dir.path(), "wide.pt", &t, 6);
    let o = measure_child(
        &["run", "--smoke", "--policy", p.to_str().unwrap()],
        dir.path(),
        Duration::from_secs(60),
    );
    println!(
        "{:>7.1} MiB {:>6} ms  wide.pt (accepted)",
        o.peak_mib,
        o.wall.as_millis()
    );
    assert_eq!(o.code, Some(0), "{o:?}");
    assert!(o.stdout.contains("hidden 2800"), "{o:?}");
    assert!(o.peak_mib < CAP_MIB, "{o:?}");
    // Just under the pickle's object budget: a 500 KB string cloned 60 times (30 MB built
    // by the unpickler), then refused for not being a state_dict.
    let mut p = Pickle::new();
    p.str(&"x".repeat(500_000)).op(b"q\x00");
    for _ in 0..60 {
        p.op(b"h\x00");
    }
    let pkl = p.op(b"t").stop();
    let mut pkl = pkl;
    pkl.insert(2, b'(');
    assert_policy_refused(&write_raw_pt(dir.path(), "clones.pt", &pkl), "state_dict");
}

#[test]
fn malformed_rebuild_calls_and_storages_are_refused_in_one_line() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    for n in [0, 1, 2, 3] {
        assert_policy_refused(
            &write_pt(d, &format!("args{n}.pt"), &actor(4), n),
            "_rebuild_tensor_v2",
        );
    }
    // _rebuild_parameter with nothing to rebuild.
    let mut p = Pickle::new();
    p.empty_ordered_dict()
        .str("actor_mean.0.weight")
        .global("torch._utils", "_rebuild_parameter")
        .op(b")R")
        .op(b"s");
    assert_policy_refused(
        &write_raw_pt(d, "param.pt", &p.stop()),
        "_rebuild_parameter",
    );
    // An actor tensor in a storage type that cannot become float32.
    let mut t = actor(4);
    t[0].storage = "FancyStorage".into();
    let fancy = write_pt(d, "fancy.pt", &t, 6);
    assert_policy_refused(&fancy, "torch.FancyStorage");
    // `export` refuses it as `run --policy` does: no tensor is left out without a word.
    let npz = d.join("fancy.npz");
    let (fancy, npz) = (fancy.to_str().unwrap(), npz.to_str().unwrap());
    assert_refused(&["export", fancy, "--out", npz], d, "torch.FancyStorage");
    assert!(!d.join("fancy.npz").exists());
    let mut t = actor(4);
    t[1].storage = "BoolStorage".into();
    t[1].data = vec![1; 4];
    assert_policy_refused(&write_pt(d, "bool.pt", &t, 6), "torch.BoolStorage");
    // A missing storage record.
    let mut t = actor(4);
    t[3].key = "missing".into();
    let records: Vec<_> = actor(4).into_iter().map(|t| (t.key, t.data)).collect();
    let p = d.join("norecord.pt");
    std::fs::write(&p, torch_zip(&state_dict_pickle(&t, 6), &records)).unwrap();
    assert_policy_refused(&p, "missing");
    // Not a dict at the top.
    let p = write_raw_pt(d, "list.pt", &Pickle::new().op(b"]").stop());
    assert_policy_refused(&p, "state_dict");
}

#[test]
fn width_zero_layers_are_refused_at_validation() {
    let dir = tempfile::tempdir().unwrap();
    let line = assert_policy_refused(&write_pt(dir.path(), "w0.pt", &actor(0), 6), "width is 0");
    assert!(line.contains("actor_mean.0.weight"), "{line}");
    // Through every command that loads a brain.
    let p = dir.path().join("w0.pt");
    let p = p.to_str().unwrap();
    assert_refused(
        &["sweep", "--policy", p, "--duration", "0.1"],
        dir.path(),
        "width is 0",
    );
    assert_refused(
        &["cliff", "--policy", p, "--duration", "0.1"],
        dir.path(),
        "width is 0",
    );
    assert_refused(
        &["run", "--clock", "real", "--duration", "1", "--policy", p],
        dir.path(),
        "width is 0",
    );
    // The same actor as safetensors.
    let tensors: std::collections::HashMap<String, candle_core::Tensor> = actor(0)
        .iter()
        .map(|t| {
            let shape: Vec<usize> = t.size.iter().map(|&d| d as usize).collect();
            (
                t.name.clone(),
                candle_core::Tensor::zeros(
                    shape,
                    candle_core::DType::F32,
                    &candle_core::Device::Cpu,
                )
                .unwrap(),
            )
        })
        .collect();
    let st = dir.path().join("w0.safetensors");
    candle_core::safetensors::save(&tensors, &st).unwrap();
    assert_policy_refused(&st, "width is 0");
}

#[test]
fn pickle_bombs_and_foreign_code_are_refused() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    // Deep nesting: 50 000 MARKs closed by 50 000 TUPLEs.
    let mut p = Pickle::new();
    p.op(&vec![b'('; 50_000]).op(&vec![b't'; 50_000]);
    assert_policy_refused(&write_raw_pt(d, "deep.pt", &p.stop()), "deeper");
    // Deep lists by APPEND: [[[…]]].
    let mut p = Pickle::new();
    for _ in 0..50_000 {
        p.op(b"]");
    }
    for _ in 0..49_999 {
        p.op(b"a");
    }
    assert_policy_refused(&write_raw_pt(d, "deeplist.pt", &p.stop()), "deeper");
    // Memo bomb: x = []; 60 times x = (x, x), through BINPUT/BINGET.
    let mut p = Pickle::new();
    p.op(b"]q\x00");
    for _ in 0..60 {
        p.op(b"h\x00h\x00\x86q\x00");
    }
    assert_policy_refused(&write_raw_pt(d, "memo.pt", &p.stop()), "bomb");
    // Memo bomb with a long string cloned again and again.
    let mut p = Pickle::new();
    p.str(&"x".repeat(500_000)).op(b"q\x00");
    for _ in 0..200 {
        p.op(b"h\x00");
    }
    assert_policy_refused(&write_raw_pt(d, "strings.pt", &p.stop()), "bomb");
    // A string longer than the file.
    let p = write_raw_pt(d, "longstr.pt", b"\x80\x02X\xff\xff\xff\xff.");
    assert_policy_refused(&p, "longer than the file");
    // Many opcodes.
    let mut p = Pickle::new();
    p.op(&vec![b'N'; 300_000]);
    assert_policy_refused(&write_raw_pt(d, "ops.pt", &p.stop()), "opcodes");
    // Globals a state_dict does not need, however they are spelled.
    for (m, n) in [
        ("os", "system"),
        ("builtins", "eval"),
        ("__torch__", "Module"),
        ("torch._tensor", "_rebuild_from_type_v2"),
        ("torch", "load"),
        ("torch", "Storage\nos"),
        ("collections", "defaultdict"),
    ] {
        let mut p = Pickle::new();
        p.global(m, n).op(b")R");
        assert_policy_refused(&write_raw_pt(d, "global.pt", &p.stop()), "only OrderedDict");
    }
    // Opcodes candle does not know (STACK_GLOBAL, INST, OBJ).
    for op in [0x93u8, b'i', b'o'] {
        let p = write_raw_pt(d, "opcode.pt", &[0x80, 2, op, b'.']);
        assert_policy_refused(&p, "opcode");
    }
    // A pickle with no STOP, and one that pops an empty stack.
    assert_policy_refused(&write_raw_pt(d, "nostop.pt", b"\x80\x02N"), "STOP");
    assert_policy_refused(&write_raw_pt(d, "pop.pt", b"\x80\x02t."), "MARK");
}

/// `(offset, length)` of the stored data of `name` in the zip `bytes`.
fn entry_span(bytes: &[u8], name: &str) -> (usize, usize) {
    let mut z = zip::ZipArchive::new(std::io::Cursor::new(bytes)).unwrap();
    let f = z.by_name(name).unwrap();
    let h = f.header_start() as usize;
    let n = u16::from_le_bytes([bytes[h + 26], bytes[h + 27]]) as usize;
    let e = u16::from_le_bytes([bytes[h + 28], bytes[h + 29]]) as usize;
    (h + 30 + n + e, f.size() as usize)
}

#[test]
fn corrupted_and_lying_archives_are_refused() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let real = std::fs::read(fixture("ppo_ch2.1_seed0.pt")).unwrap();
    // One flipped byte in the actor's weights (the issue's 4.10 s instead of 5.84 s).
    let (at, len) = entry_span(&real, "ppo_agent/data/3");
    assert_eq!(len, 16384, "actor_mean.2.weight, 64×64 float32");
    let mut bad = real.clone();
    bad[at + len / 2] ^= 0x01;
    let p = d.join("flipped.pt");
    std::fs::write(&p, &bad).unwrap();
    assert_policy_refused(&p, "CRC mismatch");
    // A flipped byte in an entry the actor does not use is still corruption.
    let (at, _) = entry_span(&real, "ppo_agent/version");
    let mut bad = real.clone();
    bad[at] ^= 0x01;
    let p = d.join("flipped-version.pt");
    std::fs::write(&p, &bad).unwrap();
    assert_policy_refused(&p, "CRC mismatch");
    // The fixture defers sizes to data descriptors; one that lies about the size.
    let (at, len) = entry_span(&real, "ppo_agent/data.pkl");
    let mut bad = real.clone();
    bad[at + len + 8] ^= 0x10; // the descriptor's compressed size
    let p = d.join("descriptor.pt");
    std::fs::write(&p, &bad).unwrap();
    assert_policy_refused(&p, "data descriptor");
    // A local header that lies about the size (a generated archive, sizes in the header).
    let good = torch_zip(
        &state_dict_pickle(&actor(4), 6),
        &actor(4)
            .into_iter()
            .map(|t| (t.key, t.data))
            .collect::<Vec<_>>(),
    );
    let (at, _) = entry_span(&good, "archive/data/2");
    let name_len = "archive/data/2".len();
    let h = at - 30 - name_len;
    let mut bad = good.clone();
    bad[h + 22..h + 26].copy_from_slice(&1_000_000u32.to_le_bytes());
    let p = d.join("local.pt");
    std::fs::write(&p, &bad).unwrap();
    assert_policy_refused(&p, "zip entry");
    // A local header naming another file.
    let mut bad = good.clone();
    bad[h + 30] = b'X';
    let p = d.join("name.pt");
    std::fs::write(&p, &bad).unwrap();
    assert_policy_refused(&p, "zip entry");
    // A compressed entry, declared so in both headers.
    let mut w = zip::ZipWriter::new(std::io::Cursor::new(Vec::new()));
    let opts =
        zip::write::SimpleFileOptions::default().compression_method(zip::CompressionMethod::Stored);
    w.start_file("archive/data.pkl", opts).unwrap();
    w.write_all(&state_dict_pickle(&actor(4), 6)).unwrap();
    let mut bytes = w.finish().unwrap().into_inner();
    let cd = bytes
        .windows(4)
        .position(|w| w == [0x50, 0x4b, 0x01, 0x02])
        .unwrap();
    bytes[8] = 8; // local: deflate
    bytes[cd + 10] = 8; // central: deflate
    let p = d.join("deflated.pt");
    std::fs::write(&p, &bytes).unwrap();
    assert_policy_refused(&p, "compress");
    // No data.pkl at all; two of them.
    let p = d.join("nopkl.pt");
    let mut w = zip::ZipWriter::new(std::io::Cursor::new(Vec::new()));
    w.start_file("archive/version", opts).unwrap();
    w.write_all(b"3").unwrap();
    std::fs::write(&p, w.finish().unwrap().into_inner()).unwrap();
    assert_policy_refused(&p, "data.pkl");
    // The real checkpoint, untouched, still loads (the checks refuse only what is wrong).
    assert!(
        ratelab::checkpoint::load_policy(fixture("ppo_ch2.1_seed0.pt").to_str().unwrap()).is_ok()
    );
}

#[test]
fn special_and_oversized_files_are_refused_without_reading_them() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    for ext in ["pt", "safetensors", "onnx"] {
        let fifo = d.join(format!("fifo.{ext}"));
        mkfifo(&fifo);
        assert_policy_refused(&fifo, "not a file");
        let zero = d.join(format!("zero.{ext}"));
        std::os::unix::fs::symlink("/dev/zero", &zero).unwrap();
        assert_policy_refused(&zero, "not a file");
        // A 2 GiB sparse file: refused by its size, never read.
        let big = d.join(format!("big.{ext}"));
        std::fs::File::create(&big)
            .unwrap()
            .set_len(2 << 30)
            .unwrap();
        assert_policy_refused(&big, "too large");
    }
    assert_policy_refused(&d.join("missing.pt"), "not found");
    assert_policy_refused(&d.join("missing.h5"), "not found");
}

// ---------------------------------------------------------------------------------------
// ONNX

mod onnx {
    use super::*;
    use tract_onnx::pb::{
        GraphProto, ModelProto, NodeProto, OperatorSetIdProto, StringStringEntryProto, TensorProto,
        ValueInfoProto,
    };

    /// A float tensor's declaration (the ONNX contract tests' builder).
    fn value_info(name: &str, dims: &[i64]) -> ValueInfoProto {
        crate::brains::onnx_contract::value_info(name, 1, dims)
    }

    /// `action = obs @ W` at operator set `opset`, with an extra initializer `extra`.
    fn model(opset: i64, extra: Option<TensorProto>) -> ModelProto {
        let mut initializer = vec![TensorProto {
            name: "W".into(),
            dims: vec![5, 1],
            data_type: 1,
            float_data: vec![0.5; 5],
            ..Default::default()
        }];
        initializer.extend(extra);
        ModelProto {
            ir_version: 8,
            opset_import: vec![OperatorSetIdProto {
                domain: String::new(),
                version: opset,
            }],
            graph: Some(GraphProto {
                name: "g".into(),
                node: vec![NodeProto {
                    input: vec!["obs".into(), "W".into()],
                    output: vec!["action".into()],
                    op_type: "MatMul".into(),
                    name: "mm".into(),
                    ..Default::default()
                }],
                initializer,
                input: vec![value_info("obs", &[1, 5])],
                output: vec![value_info("action", &[1, 1])],
                ..Default::default()
            }),
            ..Default::default()
        }
    }

    fn write(dir: &Path, name: &str, m: &ModelProto) -> PathBuf {
        let p = dir.join(name);
        std::fs::write(&p, m.encode_to_vec()).unwrap();
        p
    }

    #[test]
    fn operator_sets_at_the_ends_of_the_range_load_and_outside_are_refused() {
        let dir = tempfile::tempdir().unwrap();
        let range = ratelab::checkpoint::ONNX_OPSETS;
        for opset in [*range.start(), *range.end()] {
            let p = write(dir.path(), &format!("ok{opset}.onnx"), &model(opset, None));
            let mut brain = ratelab::checkpoint::load_policy(p.to_str().unwrap())
                .unwrap_or_else(|e| panic!("opset {opset}: {e}"));
            assert_eq!(brain.act(&[1.0, 2.0, 3.0, 4.0, 0.0]), [5.0]);
        }
        for opset in [1, range.start() - 1, range.end() + 1, 9999] {
            let p = write(dir.path(), &format!("op{opset}.onnx"), &model(opset, None));
            assert_policy_refused(&p, "operator set");
        }
    }

    #[test]
    fn string_external_and_oversized_tensors_are_refused() {
        let dir = tempfile::tempdir().unwrap();
        let d = dir.path();
        let strings = TensorProto {
            name: "labels".into(),
            dims: vec![2],
            data_type: 8,
            string_data: vec![b"left".to_vec(), b"right".to_vec()],
            ..Default::default()
        };
        assert_policy_refused(
            &write(d, "strings.onnx", &model(13, Some(strings))),
            "strings",
        );
        // External data pointing at a FIFO beside the model (once: a load that hangs).
        mkfifo(&d.join("weights.bin"));
        let external = TensorProto {
            name: "E".into(),
            dims: vec![4],
            data_type: 1,
            data_location: Some(1),
            external_data: vec![StringStringEntryProto {
                key: "location".into(),
                value: "weights.bin".into(),
            }],
            ..Default::default()
        };
        assert_policy_refused(
            &write(d, "fifo.onnx", &model(13, Some(external))),
            "external data",
        );
        // External data pointing at a 2 GiB sparse file.
        std::fs::File::create(d.join("sparse.bin"))
            .unwrap()
            .set_len(2 << 30)
            .unwrap();
        let sparse = TensorProto {
            name: "S".into(),
            dims: vec![1 << 29],
            data_type: 1,
            external_data: vec![StringStringEntryProto {
                key: "location".into(),
                value: "sparse.bin".into(),
            }],
            ..Default::default()
        };
        assert_policy_refused(
            &write(d, "sparse.onnx", &model(13, Some(sparse))),
            "external data",
        );
        // A tensor declaring 10¹² elements with no data; a negative dimension.
        for (name, dims) in [("huge", vec![1_000_000, 1_000_000]), ("neg", vec![-1])] {
            let t = TensorProto {
                name: name.into(),
                dims,
                data_type: 1,
                ..Default::default()
            };
            assert_policy_refused(
                &write(d, &format!("{name}.onnx"), &model(13, Some(t))),
                "declares shape",
            );
        }
    }

    #[test]
    fn a_protobuf_of_empty_nodes_stays_under_the_memory_cap() {
        // The worst decoding ratio: every 2 bytes on disk are one empty NodeProto. The file
        // is filled to just under the ONNX size cap.
        let dir = tempfile::tempdir().unwrap();
        let cap = ratelab::checkpoint::MAX_ONNX_BYTES as usize;
        let nodes = (cap - model(13, None).encoded_len() - 8) / 2;
        let mut graph = Vec::with_capacity(nodes * 2);
        for _ in 0..nodes {
            graph.extend([0x0a, 0x00]); // GraphProto.node = {}
        }
        let mut m = model(13, None).encode_to_vec();
        m.push(0x3a); // ModelProto.graph (field 7), merged into the graph above
        let mut len = graph.len();
        while len >= 0x80 {
            m.push((len as u8 & 0x7f) | 0x80);
            len >>= 7;
        }
        m.push(len as u8);
        m.extend(graph);
        assert!(
            m.len() as u64 <= ratelab::checkpoint::MAX_ONNX_BYTES,
            "{}",
            m.len()
        );
        let p = dir.path().join("nodes.onnx");
        std::fs::write(&p, m).unwrap();
        assert_policy_refused(&p, "more than");
    }

    #[test]
    fn garbage_and_truncated_protobuf_are_refused() {
        let dir = tempfile::tempdir().unwrap();
        let full = std::fs::read(fixture("ppo_ch2.1_seed0.onnx")).unwrap();
        let p = dir.path().join("cut.onnx");
        std::fs::write(&p, &full[..full.len() * 2 / 3]).unwrap();
        assert_policy_refused(&p, "ONNX");
        let p = dir.path().join("varint.onnx");
        std::fs::write(
            &p,
            [
                0x3a, 0xff, 0xff, 0xff, 0xff, 0xff, 0xff, 0xff, 0xff, 0xff, 0x01,
            ],
        )
        .unwrap();
        assert_policy_refused(&p, "ONNX");
    }
}

#[test]
fn safetensors_headers_that_lie_are_refused() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    // A header length far past the file.
    let p = d.join("len.safetensors");
    let mut b = (1u64 << 60).to_le_bytes().to_vec();
    b.extend(b"{}");
    std::fs::write(&p, b).unwrap();
    assert_policy_refused(&p, "safetensors");
    // A tensor whose shape does not match its byte range.
    let header = br#"{"actor_mean.0.weight":{"dtype":"F32","shape":[1000000,1000000],"data_offsets":[0,16]}}"#;
    let mut b = (header.len() as u64).to_le_bytes().to_vec();
    b.extend(header);
    b.extend([0u8; 16]);
    let p = d.join("shape.safetensors");
    std::fs::write(&p, b).unwrap();
    assert_policy_refused(&p, "safetensors");
}

// ---------------------------------------------------------------------------------------
// Paths: nothing is clobbered

#[test]
fn outputs_never_write_through_links_into_fifos_or_over_files() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let canary = d.join("canary.txt");
    std::fs::write(&canary, b"precious").unwrap();
    let out = d.join("out");
    std::fs::create_dir(&out).unwrap();
    let outs = out.to_str().unwrap();
    // --out DIR/metrics.json is a link to the canary.
    std::os::unix::fs::symlink(&canary, out.join("metrics.json")).unwrap();
    for force in [false, true] {
        let mut args = vec!["run", "--smoke", "--out", outs];
        if force {
            args.push("--force");
        }
        assert_refused(&args, d, "symbolic link");
    }
    std::fs::remove_file(out.join("metrics.json")).unwrap();
    // --out DIR/trace.csv is a FIFO: refused at once, not a hang.
    mkfifo(&out.join("trace.csv"));
    assert_refused(&["run", "--smoke", "--out", outs], d, "not a regular file");
    std::fs::remove_file(out.join("trace.csv")).unwrap();
    // --record to a FIFO, and through a link.
    let fifo = d.join("rec.rrd");
    mkfifo(&fifo);
    assert_refused(
        &[
            "run",
            "--smoke",
            "--record",
            fifo.to_str().unwrap(),
            "--force",
        ],
        d,
        "not a regular file",
    );
    let link = d.join("link.rrd");
    std::os::unix::fs::symlink(&canary, &link).unwrap();
    assert_refused(
        &[
            "run",
            "--smoke",
            "--record",
            link.to_str().unwrap(),
            "--force",
        ],
        d,
        "symbolic link",
    );
    // An existing metrics.json without --force: refused before the run; with it, replaced.
    std::fs::write(out.join("metrics.json"), b"precious").unwrap();
    assert_refused(&["run", "--smoke", "--out", outs], d, "--force");
    assert_eq!(
        std::fs::read(out.join("metrics.json")).unwrap(),
        b"precious"
    );
    let o = run_child(
        &["run", "--smoke", "--out", outs, "--force"],
        d,
        Duration::from_secs(30),
        |_| {},
    );
    assert_eq!(o.code, Some(0), "{o:?}");
    assert!(std::fs::read_to_string(out.join("metrics.json"))
        .unwrap()
        .contains("\"steps\""));
    // An existing log.txt alone, too: refused before the run (it was refused only after
    // it, and the run's figures were lost), nothing written.
    let logged = d.join("logged");
    std::fs::create_dir(&logged).unwrap();
    std::fs::write(logged.join("log.txt"), b"precious").unwrap();
    let o = run_child(
        &["run", "--smoke", "--out", logged.to_str().unwrap()],
        d,
        Duration::from_secs(30),
        |_| {},
    );
    assert_eq!(o.code, Some(2), "{o:?}");
    assert!(
        o.stderr.contains("log.txt") && o.stderr.contains("--force"),
        "{o:?}"
    );
    assert!(!o.stdout.contains("BALANCED"), "the run went ahead: {o:?}");
    assert!(!logged.join("metrics.json").exists());
    assert_eq!(std::fs::read(logged.join("log.txt")).unwrap(), b"precious");
    // A folder that takes no files (root is not stopped by permission bits; /proc is):
    // refused before the run, not once its figures are to be written.
    let o = run_child(
        &["run", "--smoke", "--out", "/proc"],
        d,
        Duration::from_secs(30),
        |_| {},
    );
    assert_eq!(o.code, Some(2), "{o:?}");
    assert!(
        o.stderr.contains("cannot write /proc/metrics.json"),
        "{o:?}"
    );
    assert!(!o.stdout.contains("BALANCED"), "the run went ahead: {o:?}");
    let o = run_child(
        &[
            "sweep",
            "--control-hz",
            "50",
            "--seeds",
            "0",
            "--duration",
            "0.1",
            "--csv",
            "/proc/ratelab-sweep.csv",
        ],
        d,
        Duration::from_secs(30),
        |_| {},
    );
    assert_eq!(o.code, Some(2), "{o:?}");
    assert!(
        o.stderr.contains("cannot write /proc/ratelab-sweep.csv"),
        "{o:?}"
    );
    assert!(!o.stdout.contains("balanced"), "the sweep ran: {o:?}");
    // sweep --csv over an existing file.
    assert_refused(
        &[
            "sweep",
            "--control-hz",
            "50",
            "--seeds",
            "0",
            "--duration",
            "0.1",
            "--csv",
            canary.to_str().unwrap(),
        ],
        d,
        "--force",
    );
    // The lab's --session over an existing file (refused before the screen opens).
    assert_refused(
        &[
            "lab",
            "--clock",
            "virtual",
            "--session",
            canary.to_str().unwrap(),
        ],
        d,
        "--force",
    );
    assert_eq!(std::fs::read(&canary).unwrap(), b"precious");
    // No temporary file is left behind.
    for entry in std::fs::read_dir(d)
        .unwrap()
        .chain(std::fs::read_dir(&out).unwrap())
    {
        let name = entry.unwrap().file_name();
        assert!(!name.to_string_lossy().ends_with(".tmp"), "{name:?}");
    }
}

#[test]
fn a_recording_never_replaces_an_existing_file_unless_forced() {
    // The lab's second run (rec-2.rrd) opens its recording with Recording::create.
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("rec-2.rrd");
    std::fs::write(&path, b"an older session's recording").unwrap();
    let cfg = ratelab::RunConfig {
        clock: ratelab::ClockKind::Virtual,
        ..ratelab::RunConfig::default()
    };
    let opts = ratelab::recording::RecordOptions::default();
    let Err(e) = ratelab::recording::Recording::create(&path, &cfg, "scripted", &opts) else {
        panic!("an existing recording was opened for writing");
    };
    assert!(e.to_string().contains("--force"), "{e}");
    assert_eq!(
        std::fs::read(&path).unwrap(),
        b"an older session's recording"
    );
    let (rec, _) =
        ratelab::recording::Recording::create_with(&path, &cfg, "scripted", &opts, true).unwrap();
    assert_eq!(
        std::fs::read(&path).unwrap(),
        b"an older session's recording",
        "replaced only when finished"
    );
    drop(rec);
    assert_ne!(
        std::fs::read(&path).unwrap(),
        b"an older session's recording"
    );
}

/// A tmpfs of `size` mounted at a new folder `small` in `dir`, unmounted when dropped;
/// `None` where this user cannot mount one (not root), which `RATELAB_REQUIRE_TMPFS` (set
/// by CI where it can) turns into a failure.
fn small_disk(dir: &Path, size: &str) -> Option<impl Drop + AsRef<Path>> {
    struct Mounted(PathBuf);
    impl Drop for Mounted {
        fn drop(&mut self) {
            let _ = Command::new("umount").arg(&self.0).status();
        }
    }
    impl AsRef<Path> for Mounted {
        fn as_ref(&self) -> &Path {
            &self.0
        }
    }
    let small = dir.join("small");
    std::fs::create_dir(&small).unwrap();
    let mounted = Command::new("mount")
        .args(["-t", "tmpfs", "-o", &format!("size={size}"), "tmpfs"])
        .arg(&small)
        .stderr(Stdio::null())
        .status()
        .is_ok_and(|s| s.success());
    assert!(
        mounted || std::env::var_os("RATELAB_REQUIRE_TMPFS").is_none(),
        "RATELAB_REQUIRE_TMPFS is set but a tmpfs cannot be mounted"
    );
    mounted.then_some(Mounted(small))
}

#[test]
fn a_recording_whose_disk_fills_at_its_end_is_said_cut_short_not_written() {
    let dir = tempfile::tempdir().unwrap();
    // 300 KiB: a 2 s recording's 540 KB does not fit, most of it does.
    let Some(small) = small_disk(dir.path(), "300k") else {
        eprintln!("not checked: a tmpfs cannot be mounted here (root only)");
        return;
    };
    let rrd = small.as_ref().join("r.rrd");
    let o = run_child(
        &[
            "run",
            "--clock",
            "virtual",
            "--duration",
            "2",
            "--record",
            rrd.to_str().unwrap(),
        ],
        dir.path(),
        Duration::from_secs(60),
        |_| {},
    );
    assert!(!o.timed_out, "{o:?}");
    assert_eq!(o.code, Some(2), "said written whole: {o:?}");
    assert!(
        o.stderr.contains("No space left on device") && o.stderr.contains("cut short"),
        "{o:?}"
    );
    assert!(!o.stdout.contains("open it with"), "{o:?}");
    assert_eq!(o.stderr.trim().lines().count(), 1, "{o:?}");
}

#[test]
fn a_bag_on_a_full_disk_is_one_line_and_leaves_no_file() {
    let dir = tempfile::tempdir().unwrap();
    let Some(small) = small_disk(dir.path(), "64k") else {
        eprintln!("not checked: a tmpfs cannot be mounted here (root only)");
        return;
    };
    std::fs::write(small.as_ref().join("fill"), vec![0u8; 64 * 1024]).ok();
    let bag = small.as_ref().join("b");
    let o = run_child(
        &[
            "run",
            "--clock",
            "virtual",
            "--duration",
            "2",
            "--ros2",
            "87",
            "--bag",
            bag.to_str().unwrap(),
        ],
        dir.path(),
        Duration::from_secs(60),
        |_| {},
    );
    assert_eq!(o.code, Some(2), "{o:?}");
    assert!(!o.stderr.contains("panicked"), "{o:?}");
    assert_eq!(o.stderr.trim().lines().count(), 1, "{o:?}");
    assert!(o.stderr.contains("--bag"), "{o:?}");
    assert!(!bag.join("b_0.mcap").exists(), "an empty bag file left");
}

// ---------------------------------------------------------------------------------------
// Rates, durations, signals, error lines

#[test]
fn slow_real_clock_nodes_stop_at_the_duration() {
    let _machine = crate::machine::alone();
    let dir = tempfile::tempdir().unwrap();
    for slow in [
        &["--control-hz", "0.01"][..],
        &["--sensor-hz", "0.02"][..],
        // Near the slowest a run takes (one tick in ten years; slower is refused).
        &["--control-hz", "3.2e-9"][..],
    ] {
        let mut args = vec!["run", "--clock", "real", "--duration", "1"];
        args.extend_from_slice(slow);
        let o = run_child(&args, dir.path(), Duration::from_secs(20), |_| {});
        assert!(!o.timed_out && o.code.is_some(), "{args:?}: {o:?}");
        // A loose bound: a loaded machine may start the process slowly, and what this
        // guards against is waiting a slow node's period (50 s, 100 s, forever).
        assert!(
            o.wall < Duration::from_secs(10),
            "{args:?}: a 1 s run took {:?}",
            o.wall
        );
    }
    // bench has no plant to fall: its bare wait and its graph (every node at the rate)
    // each last exactly the duration.
    for hz in ["0.01", "3.2e-9"] {
        let o = run_child(
            &["bench", "--hz", hz, "--duration", "1"],
            dir.path(),
            Duration::from_secs(20),
            |_| {},
        );
        assert_eq!(o.code, Some(0), "{o:?}");
        // Loose, as above: the bug is waiting the 100 s period (or forever).
        assert!(
            o.wall < Duration::from_secs(10),
            "--hz {hz}: two 1 s runs took {:?}",
            o.wall
        );
    }
}

#[test]
fn sigint_stops_a_slow_real_clock_run_within_a_second() {
    let _machine = crate::machine::alone();
    let dir = tempfile::tempdir().unwrap();
    let mut sent = None;
    let o = run_child(
        // Every node at 0.01 Hz for 60 s (no plant to fall): each thread waits 100 s.
        &["bench", "--hz", "0.01", "--duration", "60"],
        dir.path(),
        Duration::from_secs(30),
        |pid| {
            std::thread::sleep(Duration::from_millis(1500));
            sent = Some(Instant::now());
            // SAFETY: signalling our own child.
            unsafe { libc::kill(pid, libc::SIGINT) };
        },
    );
    let after = sent.unwrap().elapsed();
    assert_eq!(o.code, Some(130), "{o:?}");
    // `after` is measured once the child is reaped, so it bounds the stop from above.
    // Loose for a loaded machine: the bug is waiting out the 100 s period or the 60 s run.
    assert!(
        after < Duration::from_secs(10),
        "stopped {after:?} after SIGINT"
    );
}

#[test]
fn sigint_stops_a_real_clock_sweep_within_a_second_and_keeps_what_completed() {
    let _machine = crate::machine::alone();
    let dir = tempfile::tempdir().unwrap();
    let mut sent = None;
    let o = run_child(
        &[
            "sweep",
            "--clock",
            "real",
            "--control-hz",
            "50",
            "--seeds",
            "0,1,2",
            "--duration",
            "2",
        ],
        dir.path(),
        Duration::from_secs(30),
        |pid| {
            // The first run (2 s) completes, the second is cut short.
            std::thread::sleep(Duration::from_millis(3000));
            sent = Some(Instant::now());
            // SAFETY: signalling our own child.
            unsafe { libc::kill(pid, libc::SIGINT) };
        },
    );
    let after = sent.unwrap().elapsed();
    assert_eq!(o.code, Some(130), "{o:?}");
    // Normally 1 of 3 (the first 2 s run completed); a slow start may make it 0.
    let done: usize = o
        .stdout
        .lines()
        .find_map(|l| l.strip_prefix("interrupted: "))
        .and_then(|l| l.split(' ').next())
        .and_then(|n| n.parse().ok())
        .unwrap_or_else(|| panic!("no 'interrupted' line: {o:?}"));
    assert!(done < 3, "{o:?}");
    let rows = o.stdout.lines().filter(|l| l.starts_with("real ")).count();
    assert_eq!(rows, done, "the completed runs are in the table: {o:?}");
    // Room for a loaded machine, yet short of going on with the sweep (its next run alone
    // is 2 s).
    assert!(
        after < Duration::from_millis(1800),
        "stopped {after:?} after SIGINT"
    );
}

/// A fall under the real clock stops that run's threads through the run's own stop flag:
/// the points after it still run (a sweep used to end at the first fall, as if Ctrl-C).
#[test]
fn a_fall_in_a_real_clock_sweep_ends_that_run_alone() {
    let _machine = crate::machine::alone();
    let dir = tempfile::tempdir().unwrap();
    let o = run_child(
        &[
            "sweep",
            "--clock",
            "real",
            "--control-hz",
            "2,50",
            "--seeds",
            "0",
            "--duration",
            "2",
        ],
        dir.path(),
        Duration::from_secs(60),
        |_| {},
    );
    assert_eq!(o.code, Some(0), "{o:?}");
    assert!(!o.stdout.contains("interrupted"), "{o:?}");
    let rows: Vec<&str> = o
        .stdout
        .lines()
        .filter(|l| l.starts_with("real "))
        .collect();
    assert_eq!(rows.len(), 2, "both points ran: {o:?}");
    let fell = |r: &str| {
        r.split('|')
            .nth(1)
            .is_some_and(|v| v.trim_start().starts_with('n'))
    };
    assert!(rows.iter().any(|r| fell(r)), "the 2 Hz point falls: {o:?}");
}

/// Ctrl-C during an exercise ends the run in progress and the exercise, ungraded, exit 130:
/// ex3's two real-clock runs take 10 s, and the exercise used to run them out.
#[test]
fn sigint_stops_an_exercise_within_a_second_and_grades_nothing() {
    let _machine = crate::machine::alone();
    let dir = tempfile::tempdir().unwrap();
    let repo = Path::new(crate::REPO).join("exercises");
    let file = "ex3_jitter_phase.toml";
    for f in ["bands.toml", file] {
        std::fs::copy(repo.join(f), dir.path().join(f)).unwrap();
    }
    let learner = dir.path().join(file);
    let text = std::fs::read_to_string(&learner)
        .unwrap()
        .replace("# matched_obs_drops =\n", "matched_obs_drops = 100\n")
        .replace(
            "why = \"\"",
            "why = \"each reading comes just after the last was taken\"",
        );
    std::fs::write(&learner, text).unwrap();
    let mut sent = None;
    let o = run_child(
        &["exercise", "ex3", "--dir", dir.path().to_str().unwrap()],
        dir.path(),
        Duration::from_secs(30),
        |pid| {
            std::thread::sleep(Duration::from_millis(1500));
            sent = Some(Instant::now());
            // SAFETY: signalling our own child.
            unsafe { libc::kill(pid, libc::SIGINT) };
        },
    );
    let after = sent.unwrap().elapsed();
    assert_eq!(o.code, Some(130), "{o:?}");
    assert!(o.stderr.contains("interrupted"), "{o:?}");
    assert!(
        !o.stdout.contains("[ok]") && !o.stdout.contains("[!!]"),
        "{o:?}"
    );
    // The rest of the first 5 s run and the second one would be 8.5 s more.
    assert!(
        after < Duration::from_secs(3),
        "stopped {after:?} after SIGINT"
    );
}

#[test]
fn durations_counts_and_margins_out_of_range_are_refused_with_the_range() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    for bad in ["1e10", "18446744073", "1e20", "315360000.5"] {
        let line = assert_refused(
            &["run", "--clock", "virtual", "--duration", bad],
            d,
            "--duration",
        );
        assert!(line.contains("(0, 315360000]"), "{line}");
    }
    assert_refused(&["sweep", "--duration", "1e10"], d, "(0, 315360000]");
    assert_refused(&["bench", "--duration", "1e10"], d, "(0, 315360000]");
    for bad in ["0,1,2,3", "0,1,2,3,4", "0,1"] {
        assert_refused(
            &["run", "--smoke", "--phase-offset-ms", bad],
            d,
            "exactly 3 values",
        );
    }
    assert_refused(
        &["run", "--smoke", "--phase-offset-ms", "0,-1,2"],
        d,
        "[0, 1000)",
    );
    for bad in ["18446744073709551615", "1000001", "-1"] {
        assert_refused(
            &["run", "--smoke", "--spin-margin-us", bad],
            d,
            "--spin-margin-us",
        );
    }
    // Not below the fastest node's period (50 Hz → 20 000 µs).
    assert_refused(
        &[
            "run",
            "--clock",
            "real",
            "--duration",
            "1",
            "--spin-margin-us",
            "20000",
        ],
        d,
        "20000 µs",
    );
    // Unasked for, the margin never reaches a period: a 10 kHz real run is accepted.
    let o = run_child(
        &[
            "run",
            "--clock",
            "real",
            "--duration",
            "0.2",
            "--control-hz",
            "10000",
        ],
        d,
        Duration::from_secs(20),
        |_| {},
    );
    assert!(!o.stderr.contains("--spin-margin-us"), "{o:?}");
    assert_refused(
        &["bench", "--hz", "1000", "--spin-margin-us", "1000"],
        d,
        "--spin-margin-us",
    );
    for step in ["1e-300", "0.0001"] {
        let line = assert_refused(&["cliff", "--step", step], d, "--step");
        assert!(!line.contains("--control-hz"), "{line}");
    }
    assert_refused(
        &["cliff", "--min-hz", "40", "--max-hz", "10"],
        d,
        "--min-hz",
    );
}

#[test]
fn error_lines_keep_their_point() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let line = assert_refused(&["run", "--seed", "-1"], d, "--seed");
    assert!(
        line.contains("-1") && !line.contains("unexpected argument"),
        "{line}"
    );
    assert_refused(&["sweep", "--seeds", "0,-1"], d, "--seeds");
    let line = assert_refused(&["replay"], d, "<FILE>");
    assert!(line.contains("required"), "{line}");
    assert_refused(
        &["run", "--clock", "real", "--clock", "virtual"],
        d,
        "--clock",
    );
    assert_refused(&["run", "--control-hz", "-5"], d, "--control-hz");
    // A folder where a file is expected.
    assert_refused(
        &["run", "--smoke", "--policy", d.to_str().unwrap()],
        d,
        "not a file",
    );
}

#[test]
fn cliff_runs_many_seeds_on_a_pool_not_a_thread_each() {
    let _machine = crate::machine::shared();
    let dir = tempfile::tempdir().unwrap();
    let seeds: Vec<String> = (0..400).map(|s| s.to_string()).collect();
    let seeds = seeds.join(",");
    let cores = std::thread::available_parallelism().map_or(1, |n| n.get());
    let peak = std::sync::Arc::new(std::sync::atomic::AtomicUsize::new(0));
    let watch = peak.clone();
    let o = run_child(
        &[
            "cliff",
            "--seeds",
            &seeds,
            "--min-hz",
            "49",
            "--max-hz",
            "50",
            "--step",
            "1",
            "--duration",
            "0.05",
        ],
        dir.path(),
        Duration::from_secs(120),
        move |pid| {
            std::thread::spawn(move || {
                let status = format!("/proc/{pid}/status");
                while let Ok(text) = std::fs::read_to_string(&status) {
                    if let Some(n) = text
                        .lines()
                        .find_map(|l| l.strip_prefix("Threads:"))
                        .and_then(|n| n.trim().parse::<usize>().ok())
                    {
                        watch.fetch_max(n, std::sync::atomic::Ordering::SeqCst);
                    }
                    std::thread::sleep(Duration::from_millis(2));
                }
            });
        },
    );
    assert_eq!(o.code, Some(0), "{o:?}");
    assert_eq!(
        o.stdout.lines().filter(|l| l.starts_with("seed ")).count(),
        400,
        "{o:?}"
    );
    let peak = peak.load(std::sync::atomic::Ordering::SeqCst);
    assert!(peak > 0, "the thread count was never read");
    assert!(
        peak <= cores + 4,
        "{peak} threads at once for {cores} cores"
    );
}

#[test]
fn an_exercise_bands_file_with_an_endless_duration_is_refused() {
    let dir = tempfile::tempdir().unwrap();
    let bands =
        std::fs::read_to_string(Path::new(crate::REPO).join("exercises/bands.toml")).unwrap();
    let mut changed = 0;
    let edited: String = bands
        .lines()
        .map(|l| {
            if l.trim_start().starts_with("duration_s") {
                changed += 1;
                "duration_s = 1e10".to_string()
            } else {
                l.to_string()
            }
        })
        .collect::<Vec<_>>()
        .join("\n");
    assert!(changed > 0, "bands.toml has no duration_s");
    let p = dir.path().join("bands.toml");
    std::fs::write(&p, edited).unwrap();
    let b = ratelab_exercises::load_bands(&p).unwrap();
    let start = Instant::now();
    let e = ratelab_exercises::measure_ex1(
        &b.of().unwrap(),
        &ratelab::graph::GraphSpec::chapter(),
        &ratelab::scheduler::StopFlag::new(),
    )
    .unwrap_err();
    assert!(e.to_string().contains("(0, 315360000]"), "{e}");
    assert!(start.elapsed() < Duration::from_secs(1));
}
