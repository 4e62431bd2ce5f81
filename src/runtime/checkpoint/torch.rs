//! PyTorch `torch.save` archives, read as untrusted input with bounded memory and time.
//!
//! # Mechanism, and why
//!
//! A `.pt` file is a zip archive holding a pickle program (`<dir>/data.pkl`) that describes
//! the `state_dict` and one raw record per storage (`<dir>/data/<key>`). Unpickling is the
//! dangerous part: a tiny program can nest tens of thousands of levels (candle's unpickler
//! and the drop of its object tree recurse: stack overflow), clone a memoized value again
//! and again (candle clones on every memo read: gigabytes from kilobytes), or declare a
//! tensor of 10¹² elements over a 4-byte storage (an allocation abort).
//!
//! The options were (a) a bounded pre-scan of the opcode stream plus shape checks before
//! any allocation, (b) loading in a child process under `setrlimit`, (c) another reader
//! crate. (b) does not fit: the loader is a library function, called in-process by the
//! lab's brain swap and by tests; `RLIMIT_AS` is process-wide (it would also cap MuJoCo and
//! rerun), `fork` without `exec` is unsound in a multi-threaded process, and re-executing
//! needs the `ratelab` binary, which a library cannot count on. (c): no crate in the
//! dependency tree is built for untrusted pickles. So (a), in-process and deterministic:
//!
//! 1. The file is read once, from a regular file only, up to [`MAX_FILE_BYTES`]; every
//!    later step works on that buffer (no second open that could see another file).
//! 2. Zip: the end-of-directory records are checked against the file's size first (the
//!    zip crate sizes its tables by them); then the zip crate reads the central directory;
//!    every entry must be stored (not
//!    compressed), lie inside the file, have a local header that agrees with the central
//!    directory (name, method, and CRC and sizes, or a data descriptor that agrees), and
//!    match its CRC-32. Names are unique. A corrupted or lying archive is refused.
//! 3. `data.pkl` ([`MAX_PICKLE_BYTES`]) is pre-scanned ([`prescan`]): a walk of the opcode
//!    stream that models candle's unpickler with only a size and a depth per value, and
//!    refuses unknown opcodes, more than [`MAX_OPCODES`] opcodes, nesting deeper than
//!    [`MAX_DEPTH`], more than [`MAX_MODELLED_BYTES`] of live objects (memo bombs included,
//!    since each memo read is counted as the clone it is), strings longer than the rest of
//!    the stream, and any `GLOBAL` but those a `state_dict` needs (as
//!    `torch.load(weights_only=True)`): `collections.OrderedDict`,
//!    `torch._utils._rebuild_tensor_v2`, `torch._utils._rebuild_parameter`, `torch.*Storage`.
//!    This is not a second unpickler: it builds nothing, it only bounds what candle's
//!    unpickler (which then builds the object tree) can do.
//! 4. Every tensor entry's arguments are checked (count, types), its shape and strides are
//!    multiplied with overflow checks, and its span is checked against the storage's
//!    declared element count and the storage record's byte length before anything is
//!    allocated; the bytes materialized in total are capped at [`MAX_TENSOR_BYTES`].
//!    Tensors of a storage type ratelab does not represent are kept aside: harmless unless
//!    a caller asks for them.
//!
//! Every step is linear in the (capped) file, so a load ends in well under a second.

use candle_core::{DType, Device, Tensor};
use std::collections::HashMap;

/// The largest checkpoint file read, bytes (the course's 64-wide actor is 42 KB).
pub const MAX_FILE_BYTES: u64 = 16 << 20;
/// The largest `data.pkl`, bytes (the course's is 1.4 KB).
pub const MAX_PICKLE_BYTES: usize = 1 << 20;
/// The most pickle opcodes executed.
pub const MAX_OPCODES: u64 = 200_000;
/// The deepest nesting of pickled values (a `state_dict` needs about 6).
pub const MAX_DEPTH: u32 = 64;
/// The most memory the unpickler's live objects may take, as modelled by the pre-scan, bytes.
pub const MAX_MODELLED_BYTES: u64 = 32 << 20;
/// The most tensor bytes materialized from one checkpoint.
pub const MAX_TENSOR_BYTES: u64 = 32 << 20;

/// Modelled cost of one unpickled value (enum, vector slot with growth slack, box), bytes.
const NODE_BYTES: u64 = 128;

/// The tensors of a checkpoint.
#[derive(Debug, Default)]
pub struct TorchTensors {
    /// Tensors ratelab can represent, by key.
    pub tensors: HashMap<String, Tensor>,
    /// Tensors of a storage type ratelab does not represent: key → storage type.
    pub unsupported: HashMap<String, String>,
}

/// Read the tensors of a `torch.save` archive held in `bytes`. With `only`, just those keys
/// are materialized (the others are still validated).
///
/// # Errors
/// A one-line reason (the caller adds the file's name).
pub fn read(bytes: &[u8], only: Option<&[&str]>) -> Result<TorchTensors, String> {
    let entries = zip_entries(bytes)?;
    let pkl_names: Vec<&String> = entries.keys().filter(|n| n.ends_with("data.pkl")).collect();
    let pkl_name = match pkl_names.as_slice() {
        [one] => (*one).clone(),
        [] => return Err("no data.pkl in the archive".into()),
        _ => return Err("more than one data.pkl in the archive".into()),
    };
    let dir = pkl_name.strip_suffix("data.pkl").unwrap_or_default();
    let pkl = entries[&pkl_name];
    if pkl.len() > MAX_PICKLE_BYTES {
        return Err(format!(
            "data.pkl is {} bytes, more than the {MAX_PICKLE_BYTES} a state_dict needs",
            pkl.len()
        ));
    }
    prescan(pkl)?;
    let mut stack = candle_core::pickle::Stack::empty();
    stack
        .read_loop(&mut &pkl[..])
        .map_err(|e| format!("data.pkl: {}", first_line(&e.to_string())))?;
    let root = stack
        .finalize()
        .map_err(|e| format!("data.pkl: {}", first_line(&e.to_string())))?;
    let candle_core::pickle::Object::Dict(items) = root else {
        return Err("data.pkl does not hold a state_dict (a dict of tensors)".into());
    };
    let mut out = TorchTensors::default();
    let mut budget = MAX_TENSOR_BYTES;
    for (key, value) in items {
        let candle_core::pickle::Object::Unicode(key) = key else {
            continue;
        };
        let Some(spec) = tensor_spec(&key, value)? else {
            continue; // not a tensor (e.g. `_metadata`): nothing to check
        };
        let record = entries
            .get(&format!("{dir}data/{}", spec.storage_key))
            .copied()
            .ok_or_else(|| {
                format!(
                    "tensor '{key}': storage record data/{} is missing",
                    spec.storage_key
                )
            })?;
        let span = spec.check(&key, record)?;
        let wanted = only.is_none_or(|keys| keys.contains(&key.as_str()));
        match (spec.dtype, wanted) {
            (_, false) => {}
            (None, true) => {
                out.unsupported.insert(key, spec.storage_type);
            }
            (Some((dtype, elem)), true) => {
                let bytes = span.numel * elem;
                budget = budget.checked_sub(bytes).ok_or_else(|| {
                    format!("tensors take more than {MAX_TENSOR_BYTES} bytes in memory")
                })?;
                let raw = gather(record, &spec, elem);
                let t = Tensor::from_raw_buffer(&raw, dtype, &spec.size_usize(), &Device::Cpu)
                    .map_err(|e| format!("tensor '{key}': {}", first_line(&e.to_string())))?;
                out.tensors.insert(key, t);
            }
        }
    }
    Ok(out)
}

fn first_line(s: &str) -> &str {
    s.lines().next().unwrap_or("unreadable")
}

// ---------------------------------------------------------------------------------------
// Zip

const LOCAL_SIG: u32 = 0x0403_4b50;
const DESCRIPTOR_SIG: u32 = 0x0807_4b50;

fn le16(b: &[u8], at: usize) -> Option<u64> {
    b.get(at..at + 2)
        .map(|s| u64::from(u16::from_le_bytes([s[0], s[1]])))
}

fn le32(b: &[u8], at: usize) -> Option<u64> {
    b.get(at..at + 4)
        .map(|s| u64::from(u32::from_le_bytes([s[0], s[1], s[2], s[3]])))
}

fn le64(b: &[u8], at: usize) -> Option<u64> {
    b.get(at..at + 8)
        .map(|s| u64::from_le_bytes(s.try_into().expect("8 bytes")))
}

/// Check every end-of-central-directory record in the archive's tail (and the zip64 one
/// each points to) before the zip crate sizes anything by them: the entry count must fit
/// the file (46 bytes at least per entry) and the directory must lie inside the file.
fn check_directory_records(bytes: &[u8]) -> Result<(), String> {
    let len = bytes.len() as u64;
    let lie = || "the zip directory's end record does not fit the file".to_string();
    let fits = |entries: u64, size: u64, offset: u64| {
        entries <= len / 46 && offset.checked_add(size).is_some_and(|end| end <= len)
    };
    let tail = bytes.len().saturating_sub(22 + 0xffff);
    let mut found = false;
    for at in (tail..bytes.len().saturating_sub(21)).rev() {
        if le32(bytes, at) != Some(0x0605_4b50) {
            continue;
        }
        found = true;
        let (entries, size, offset) = (
            le16(bytes, at + 10).ok_or_else(lie)?,
            le32(bytes, at + 12).ok_or_else(lie)?,
            le32(bytes, at + 16).ok_or_else(lie)?,
        );
        let zip64 = at >= 20 && le32(bytes, at - 20) == Some(0x0706_4b50);
        if zip64 {
            let rec = le64(bytes, at - 20 + 8)
                .and_then(|o| usize::try_from(o).ok())
                .ok_or_else(lie)?;
            if le32(bytes, rec) != Some(0x0606_4b50) {
                return Err(lie());
            }
            let (e, sz, off) = (
                le64(bytes, rec + 32).ok_or_else(lie)?,
                le64(bytes, rec + 40).ok_or_else(lie)?,
                le64(bytes, rec + 48).ok_or_else(lie)?,
            );
            if !fits(e, sz, off) {
                return Err(lie());
            }
        }
        // With a zip64 record, the classic fields may hold placeholders instead of values.
        let placeholder = entries == 0xffff || size == 0xffff_ffff || offset == 0xffff_ffff;
        let deferred = zip64 && placeholder;
        if !deferred && !fits(entries, size, offset) {
            return Err(lie());
        }
    }
    if found {
        Ok(())
    } else {
        Err("not a zip archive (no end of central directory)".into())
    }
}

/// Every entry of the archive, checked (see the module docs), by name.
fn zip_entries(bytes: &[u8]) -> Result<HashMap<String, &[u8]>, String> {
    check_directory_records(bytes)?;
    let mut zip = zip::ZipArchive::new(std::io::Cursor::new(bytes))
        .map_err(|e| format!("not a zip archive ({})", first_line(&e.to_string())))?;
    let mut out = HashMap::new();
    for i in 0..zip.len() {
        let f = zip
            .by_index_raw(i)
            .map_err(|e| format!("zip entry {i}: {}", first_line(&e.to_string())))?;
        let name = f
            .name()
            .map_err(|e| format!("zip entry {i}: {}", first_line(&e.to_string())))?
            .into_owned();
        let bad = |what: &str| format!("zip entry {name}: {what}");
        if f.compression() != zip::CompressionMethod::Stored {
            return Err(bad("compressed (torch.save stores entries uncompressed)"));
        }
        let (size, csize, crc) = (f.size(), f.compressed_size(), u64::from(f.crc32()));
        if size != csize {
            return Err(bad("stored entry whose sizes disagree"));
        }
        let h = usize::try_from(f.header_start()).map_err(|_| bad("header out of range"))?;
        if le32(bytes, h) != Some(u64::from(LOCAL_SIG)) {
            return Err(bad("no local header where the central directory points"));
        }
        let field = |at: usize| le16(bytes, h + at).ok_or_else(|| bad("truncated local header"));
        let field32 = |at: usize| le32(bytes, h + at).ok_or_else(|| bad("truncated local header"));
        let (flags, method) = (field(6)?, field(8)?);
        let (l_crc, l_csize, l_size) = (field32(14)?, field32(18)?, field32(22)?);
        let (name_len, extra_len) = (field(26)? as usize, field(28)? as usize);
        if bytes.get(h + 30..h + 30 + name_len) != Some(f.name_raw()) {
            return Err(bad("local header names another file"));
        }
        if method != 0 {
            return Err(bad("local header says compressed"));
        }
        let start = h + 30 + name_len + extra_len;
        let end = usize::try_from(size)
            .ok()
            .and_then(|s| start.checked_add(s))
            .filter(|&e| e <= bytes.len())
            .ok_or_else(|| bad("data runs past the end of the file"))?;
        let described = flags & 0x8 != 0;
        let local_agrees = (l_crc, l_csize, l_size) == (crc, size, size);
        let local_deferred = described && (l_crc, l_csize, l_size) == (0, 0, 0);
        if !local_agrees && !local_deferred {
            return Err(bad("local header disagrees with the central directory"));
        }
        if described {
            // CRC and sizes follow the data, with or without a signature.
            let at = if le32(bytes, end) == Some(u64::from(DESCRIPTOR_SIG)) {
                end + 4
            } else {
                end
            };
            if (le32(bytes, at), le32(bytes, at + 4), le32(bytes, at + 8))
                != (Some(crc), Some(size), Some(size))
            {
                return Err(bad("data descriptor disagrees with the central directory"));
            }
        }
        let data = &bytes[start..end];
        if u64::from(crc32fast::hash(data)) != crc {
            return Err(bad("CRC mismatch (the file is corrupted)"));
        }
        if out.insert(name.clone(), data).is_some() {
            return Err(bad("appears twice"));
        }
    }
    Ok(out)
}

// ---------------------------------------------------------------------------------------
// Pickle pre-scan

/// A modelled value: what it would cost candle's unpickler and how deep it nests.
#[derive(Clone, Copy, Debug)]
struct Shadow {
    bytes: u64,
    depth: u32,
    mark: bool,
}

impl Shadow {
    fn leaf(extra: u64) -> Self {
        Self {
            bytes: NODE_BYTES + extra,
            depth: 1,
            mark: false,
        }
    }
}

/// Is `module.name` a global a `state_dict` needs?
fn allowed_global(module: &[u8], name: &[u8]) -> bool {
    match module {
        b"collections" => name == b"OrderedDict",
        b"torch._utils" => name == b"_rebuild_tensor_v2" || name == b"_rebuild_parameter",
        b"torch" => {
            name.ends_with(b"Storage")
                && name.len() > b"Storage".len()
                && name.iter().all(u8::is_ascii_alphanumeric)
        }
        _ => false,
    }
}

struct Scan<'a> {
    data: &'a [u8],
    pos: usize,
    stack: Vec<Shadow>,
    memo: HashMap<u32, Shadow>,
    live: u64,
}

impl<'a> Scan<'a> {
    fn take(&mut self, n: usize) -> Result<&'a [u8], String> {
        let end = self
            .pos
            .checked_add(n)
            .filter(|&e| e <= self.data.len())
            .ok_or("data.pkl ends in the middle of an opcode")?;
        let s = &self.data[self.pos..end];
        self.pos = end;
        Ok(s)
    }

    fn u32(&mut self) -> Result<u32, String> {
        let b = self.take(4)?;
        Ok(u32::from_le_bytes([b[0], b[1], b[2], b[3]]))
    }

    /// As candle's `read_to_newline`: up to and including `\n`, or to the end.
    fn line(&mut self) -> &'a [u8] {
        let rest = &self.data[self.pos..];
        let n = rest
            .iter()
            .position(|&b| b == b'\n')
            .map_or(rest.len(), |i| i + 1);
        self.pos += n;
        let line = &rest[..n];
        let line = line.strip_suffix(b"\n").unwrap_or(line);
        line.strip_suffix(b"\r").unwrap_or(line)
    }

    fn grow(&mut self, bytes: u64) -> Result<(), String> {
        self.live = self.live.saturating_add(bytes);
        if self.live > MAX_MODELLED_BYTES {
            return Err(format!(
                "data.pkl would build more than {} MiB of objects (a memo or nesting bomb)",
                MAX_MODELLED_BYTES >> 20
            ));
        }
        Ok(())
    }

    fn push(&mut self, s: Shadow, new_bytes: u64) -> Result<(), String> {
        if s.depth > MAX_DEPTH {
            return Err(format!("data.pkl nests deeper than {MAX_DEPTH} levels"));
        }
        self.grow(new_bytes)?;
        self.stack.push(s);
        Ok(())
    }

    fn pop(&mut self) -> Result<Shadow, String> {
        match self.stack.pop() {
            Some(s) if !s.mark => Ok(s),
            _ => Err("data.pkl pops an empty stack".into()),
        }
    }

    fn pop_to_mark(&mut self) -> Result<Vec<Shadow>, String> {
        let at = self
            .stack
            .iter()
            .rposition(|s| s.mark)
            .ok_or("data.pkl: no MARK before a collection")?;
        let items = self.stack.split_off(at + 1);
        self.stack.pop();
        Ok(items)
    }

    /// A new container holding `items`.
    fn contain(&mut self, items: &[Shadow]) -> Result<(), String> {
        let c = Shadow {
            bytes: NODE_BYTES + items.iter().map(|s| s.bytes).sum::<u64>(),
            depth: 1 + items.iter().map(|s| s.depth).max().unwrap_or(0),
            mark: false,
        };
        self.push(c, NODE_BYTES)
    }

    /// Add `items` into the value on top of the stack (APPEND, SETITEM and friends).
    fn add_to_top(&mut self, items: &[Shadow]) -> Result<(), String> {
        let top = self
            .stack
            .last_mut()
            .filter(|s| !s.mark)
            .ok_or("data.pkl adds to an empty stack")?;
        top.bytes += items.iter().map(|s| s.bytes).sum::<u64>();
        top.depth = top
            .depth
            .max(1 + items.iter().map(|s| s.depth).max().unwrap_or(0));
        if top.depth > MAX_DEPTH {
            return Err(format!("data.pkl nests deeper than {MAX_DEPTH} levels"));
        }
        Ok(())
    }

    fn memo_get(&mut self, id: u32) -> Result<(), String> {
        let s = *self
            .memo
            .get(&id)
            .ok_or_else(|| format!("data.pkl reads memo {id} before writing it"))?;
        self.push(s, s.bytes) // candle clones the memoized value
    }

    fn memo_put(&mut self, id: u32) -> Result<(), String> {
        let top = *self
            .stack
            .last()
            .filter(|s| !s.mark)
            .ok_or("data.pkl memoizes an empty stack")?;
        self.grow(top.bytes)?; // cloned into the memo
        if let Some(old) = self.memo.insert(id, top) {
            self.live -= old.bytes.min(self.live);
        }
        Ok(())
    }
}

/// Bound what candle's unpickler may do with `data` (see the module docs). Mirrors the
/// opcodes candle implements, and how it implements them (`d` is read as an empty dict).
///
/// # Errors
/// A one-line reason.
pub fn prescan(data: &[u8]) -> Result<(), String> {
    let mut s = Scan {
        data,
        pos: 0,
        stack: Vec::new(),
        memo: HashMap::new(),
        live: 0,
    };
    let mut ops = 0u64;
    loop {
        ops += 1;
        if ops > MAX_OPCODES {
            return Err(format!("data.pkl runs more than {MAX_OPCODES} opcodes"));
        }
        let op = s.take(1).map_err(|_| "data.pkl ends without STOP")?[0];
        match op {
            0x80 => {
                s.take(1)?;
            }
            b'c' => {
                let module = s.line();
                let name = s.line();
                if !allowed_global(module, name) {
                    return Err(format!(
                        "data.pkl refers to {}.{}, which a state_dict does not need (only OrderedDict, _rebuild_tensor_v2, _rebuild_parameter and torch storages are allowed)",
                        String::from_utf8_lossy(module),
                        String::from_utf8_lossy(name)
                    ));
                }
                let extra = (module.len() + name.len()) as u64;
                s.push(Shadow::leaf(extra), NODE_BYTES + extra)?;
            }
            b'K' | b'M' | b'J' | b'G' | b'N' | 0x88 | 0x89 | b'}' | b'd' | b')' | b']' => {
                let n = match op {
                    b'K' => 1,
                    b'M' => 2,
                    b'J' => 4,
                    b'G' => 8,
                    _ => 0,
                };
                s.take(n)?;
                s.push(Shadow::leaf(0), NODE_BYTES)?;
            }
            0x8a => {
                let n = usize::from(s.take(1)?[0]);
                if n > 8 {
                    return Err(format!("data.pkl has a {n}-byte integer (at most 8)"));
                }
                s.take(n)?;
                s.push(Shadow::leaf(0), NODE_BYTES)?;
            }
            b'X' => {
                let len = s.u32()? as usize;
                if len > s.data.len() - s.pos {
                    return Err("data.pkl declares a string longer than the file".into());
                }
                s.take(len)?;
                s.push(Shadow::leaf(len as u64), NODE_BYTES + len as u64)?;
            }
            b'(' => s.push(
                Shadow {
                    bytes: NODE_BYTES,
                    depth: 0,
                    mark: true,
                },
                NODE_BYTES,
            )?,
            b'Q' => {
                let id = s.pop()?;
                s.contain(&[id])?;
            }
            b't' => {
                let items = s.pop_to_mark()?;
                s.contain(&items)?;
            }
            0x85..=0x87 => {
                let n = usize::from(op - 0x84);
                let mut items = Vec::with_capacity(n);
                for _ in 0..n {
                    items.push(s.pop()?);
                }
                s.contain(&items)?;
            }
            b'R' | b'b' | 0x81 => {
                let a = s.pop()?;
                let b = s.pop()?;
                s.contain(&[a, b])?;
            }
            b'a' => {
                let v = s.pop()?;
                s.add_to_top(&[v])?;
            }
            b's' => {
                let v = s.pop()?;
                let k = s.pop()?;
                s.add_to_top(&[k, v])?;
            }
            b'e' | b'u' => {
                let items = s.pop_to_mark()?;
                s.add_to_top(&items)?;
            }
            b'h' => {
                let id = u32::from(s.take(1)?[0]);
                s.memo_get(id)?;
            }
            b'j' => {
                let id = s.u32()?;
                s.memo_get(id)?;
            }
            b'q' => {
                let id = u32::from(s.take(1)?[0]);
                s.memo_put(id)?;
            }
            b'r' => {
                let id = s.u32()?;
                s.memo_put(id)?;
            }
            b'.' => return Ok(()),
            other => {
                return Err(format!(
                    "data.pkl uses pickle opcode 0x{other:02x}, which a state_dict does not need"
                ))
            }
        }
    }
}

// ---------------------------------------------------------------------------------------
// Tensor entries

use candle_core::pickle::Object;

/// A tensor entry's declaration, checked for form.
struct Spec {
    storage_type: String,
    storage_key: String,
    /// Declared element count of the storage.
    storage_numel: u64,
    /// The candle dtype and element size, when ratelab represents the storage type.
    dtype: Option<(DType, u64)>,
    /// Element size in bytes when known (also for types ratelab does not represent).
    elem_bytes: Option<u64>,
    offset: u64,
    size: Vec<u64>,
    stride: Vec<u64>,
}

/// The checked extent of a tensor.
struct Span {
    numel: u64,
}

fn int(o: &Object) -> Option<i64> {
    match o {
        Object::Int(i) => Some(i64::from(*i)),
        Object::Long(l) => Some(*l),
        _ => None,
    }
}

fn uint_tuple(o: &Object) -> Option<Vec<u64>> {
    match o {
        Object::Tuple(v) => v
            .iter()
            .map(|x| int(x).and_then(|i| u64::try_from(i).ok()))
            .collect(),
        _ => None,
    }
}

fn is_class(o: &Object, module: &str, name: &str) -> bool {
    matches!(o, Object::Class { module_name, class_name } if module_name == module && class_name == name)
}

/// Storage type → (candle dtype if represented, element size if known).
fn storage_dtype(name: &str) -> (Option<DType>, Option<u64>) {
    match name {
        "FloatStorage" => (Some(DType::F32), Some(4)),
        "DoubleStorage" => (Some(DType::F64), Some(8)),
        "HalfStorage" => (Some(DType::F16), Some(2)),
        "BFloat16Storage" => (Some(DType::BF16), Some(2)),
        "ByteStorage" => (Some(DType::U8), Some(1)),
        "ShortStorage" => (Some(DType::I16), Some(2)),
        "IntStorage" => (Some(DType::I32), Some(4)),
        "LongStorage" => (Some(DType::I64), Some(8)),
        "CharStorage" | "BoolStorage" => (None, Some(1)),
        "ComplexFloatStorage" => (None, Some(8)),
        "ComplexDoubleStorage" => (None, Some(16)),
        _ => (None, None),
    }
}

/// The declaration of `value` if it is a tensor (`_rebuild_tensor_v2`, possibly wrapped
/// in `_rebuild_parameter`); `None` for anything else.
fn tensor_spec(key: &str, value: Object) -> Result<Option<Spec>, String> {
    let bad = |what: &str| format!("tensor '{key}': {what}");
    let Object::Reduce { callable, args } = value else {
        return Ok(None);
    };
    let (callable, args) = if is_class(&callable, "torch._utils", "_rebuild_parameter") {
        match *args {
            Object::Tuple(mut a) if !a.is_empty() => match a.swap_remove(0) {
                Object::Reduce { callable, args } => (callable, args),
                _ => return Err(bad("_rebuild_parameter without a tensor")),
            },
            _ => return Err(bad("_rebuild_parameter without arguments")),
        }
    } else {
        (callable, args)
    };
    if !is_class(&callable, "torch._utils", "_rebuild_tensor_v2") {
        return Ok(None);
    }
    let Object::Tuple(a) = *args else {
        return Err(bad("_rebuild_tensor_v2 without an argument tuple"));
    };
    if a.len() < 4 {
        return Err(bad(&format!(
            "_rebuild_tensor_v2 with {} arguments (storage, offset, size and stride are needed)",
            a.len()
        )));
    }
    let Object::PersistentLoad(pid) = &a[0] else {
        return Err(bad("no storage reference"));
    };
    let Object::Tuple(pid) = pid.as_ref() else {
        return Err(bad("malformed storage reference"));
    };
    let [Object::Unicode(tag), Object::Class {
        module_name,
        class_name,
    }, Object::Unicode(storage_key), _location, numel] = pid.as_slice()
    else {
        return Err(bad("malformed storage reference"));
    };
    if tag != "storage" || module_name != "torch" {
        return Err(bad("malformed storage reference"));
    }
    let storage_numel = int(numel)
        .and_then(|n| u64::try_from(n).ok())
        .ok_or_else(|| bad("negative or missing storage size"))?;
    let offset = int(&a[1])
        .and_then(|n| u64::try_from(n).ok())
        .ok_or_else(|| bad("negative or missing storage offset"))?;
    let size = uint_tuple(&a[2]).ok_or_else(|| bad("size is not a tuple of sizes ≥ 0"))?;
    let stride = uint_tuple(&a[3]).ok_or_else(|| bad("stride is not a tuple of strides ≥ 0"))?;
    if size.len() != stride.len() {
        return Err(bad("size and stride have different lengths"));
    }
    let (dtype, elem_bytes) = storage_dtype(class_name);
    Ok(Some(Spec {
        storage_type: format!("torch.{class_name}"),
        storage_key: storage_key.clone(),
        storage_numel,
        dtype: dtype.zip(elem_bytes),
        elem_bytes,
        offset,
        size,
        stride,
    }))
}

impl Spec {
    /// Check the declared extent against the storage and its record, with overflow checks,
    /// before anything is allocated.
    fn check(&self, key: &str, record: &[u8]) -> Result<Span, String> {
        let bad = |what: String| format!("tensor '{key}': {what}");
        let numel = self
            .size
            .iter()
            .try_fold(1u64, |n, &d| n.checked_mul(d))
            .ok_or_else(|| bad(format!("shape {:?} overflows", self.size)))?;
        if let Some(elem) = self.elem_bytes {
            let want = self.storage_numel.checked_mul(elem);
            if want != Some(record.len() as u64) {
                return Err(bad(format!(
                    "storage declares {} elements of {elem} bytes but its record holds {} bytes",
                    self.storage_numel,
                    record.len()
                )));
            }
        }
        if numel > 0 {
            let last = self
                .size
                .iter()
                .zip(&self.stride)
                .try_fold(self.offset, |acc, (&d, &s)| {
                    (d - 1).checked_mul(s).and_then(|x| acc.checked_add(x))
                });
            match last {
                Some(last) if last < self.storage_numel => {}
                _ => {
                    return Err(bad(format!(
                    "shape {:?} (offset {}, stride {:?}) reaches past its storage of {} elements",
                    self.size, self.offset, self.stride, self.storage_numel
                )))
                }
            }
        }
        if let Some(elem) = self.elem_bytes {
            numel
                .checked_mul(elem)
                .filter(|&b| b <= MAX_TENSOR_BYTES)
                .ok_or_else(|| {
                    bad(format!(
                        "shape {:?} takes more than {MAX_TENSOR_BYTES} bytes",
                        self.size
                    ))
                })?;
        }
        Ok(Span { numel })
    }

    fn size_usize(&self) -> Vec<usize> {
        // Checked in `check`: every dimension's product fits the byte cap, hence usize.
        self.size.iter().map(|&d| d as usize).collect()
    }
}

/// The tensor's elements in row-major order, as raw bytes (any strides, checked before).
fn gather(record: &[u8], spec: &Spec, elem: u64) -> Vec<u8> {
    let elem = elem as usize;
    let size: Vec<usize> = spec.size_usize();
    let stride: Vec<usize> = spec.stride.iter().map(|&s| s as usize).collect();
    let numel: usize = size.iter().product();
    if numel == 0 {
        return Vec::new(); // the offset of an empty tensor is not checked, nor needed
    }
    let offset = spec.offset as usize;
    let contiguous = {
        let mut expect = 1usize;
        let mut ok = true;
        for (&d, &s) in size.iter().zip(&stride).rev() {
            if d > 1 && s != expect {
                ok = false;
            }
            expect *= d;
        }
        ok
    };
    if contiguous {
        return record[offset * elem..(offset + numel) * elem].to_vec();
    }
    let mut out = Vec::with_capacity(numel * elem);
    let mut index = vec![0usize; size.len()];
    for _ in 0..numel {
        let at = offset + index.iter().zip(&stride).map(|(i, s)| i * s).sum::<usize>();
        out.extend_from_slice(&record[at * elem..(at + 1) * elem]);
        for axis in (0..size.len()).rev() {
            index[axis] += 1;
            if index[axis] < size[axis] {
                break;
            }
            index[axis] = 0;
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn prescan_bounds_depth_memo_and_globals() {
        // 100 nested empty lists: EMPTY_LIST, then (EMPTY_LIST, APPEND)… is flat; nesting
        // needs MARK … TUPLE.
        let mut deep = vec![0x80, 2];
        deep.extend(std::iter::repeat_n(b'(', 100));
        deep.extend(std::iter::repeat_n(b't', 100));
        deep.push(b'.');
        assert!(prescan(&deep).unwrap_err().contains("deeper"));
        // Memo bomb: x = []; repeat { x = (x, x) } via BINPUT/BINGET.
        let mut bomb = vec![0x80, 2, b']', b'q', 0];
        for _ in 0..40 {
            bomb.extend([b'h', 0, b'h', 0, 0x86, b'q', 0]);
        }
        bomb.push(b'.');
        assert!(prescan(&bomb).unwrap_err().contains("bomb"));
        let evil = b"\x80\x02cos\nsystem\n.";
        assert!(prescan(evil).unwrap_err().contains("os.system"));
        let ok = b"\x80\x02ccollections\nOrderedDict\n)R.";
        prescan(ok).unwrap();
        assert!(prescan(b"\x80\x02X\xff\xff\xff\x7f").is_err());
        assert!(prescan(b"\x80\x02").unwrap_err().contains("STOP"));
    }
}
