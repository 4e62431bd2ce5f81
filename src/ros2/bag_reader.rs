//! `ratelab ros2 bag info|echo DIR`: a rosbag2 bag in MCAP storage read back, whoever wrote
//! it (`--bag`, or `ros2 bag record`), as `ros2 bag info` describes one and as `ros2 topic
//! echo` would have printed its messages ([`super::echo`]).
//!
//! The MCAP file is the one `metadata.yaml` names, else the folder's only `*.mcap`; its
//! messages are read with the `mcap` crate (every message, in the file's order, so a bag cut
//! short, without its summary, still reads up to where it stops, and says so). A topic's
//! type is its channel's schema name; its RIHS01 hash is the channel's `topic_type_hash`
//! (rosbag2's MCAP metadata) or `metadata.yaml`'s `type_description_hash`; a bag that gives
//! none is decoded by the type's name alone. Bounded: the MCAP file at most
//! [`MAX_BAG_BYTES`], `metadata.yaml` at most [`MAX_METADATA_BYTES`] and
//! [`crate::yaml_depth::MAX_YAML_DEPTH`] deep, the folder's listing at most
//! [`MAX_DIR_ENTRIES`] entries, every record's length by the bytes there are, a chunk's
//! inflated size by [`MAX_CHUNK_BYTES`], by what it declares and by its codec's ratio
//! ([`max_inflation`]); Ctrl-C and SIGTERM end a read between records. The `mcap` crate's
//! own `MessageStream` is not used: it reads a record's declared length unchecked (a 64-byte
//! file claiming 2⁶⁴ − 1 bytes panics it) and loops forever on a chunk that inflates past
//! what it declares.

use std::borrow::Cow;
use std::collections::{BTreeMap, HashMap};
use std::io::Read;
use std::path::{Path, PathBuf};

/// The largest MCAP file read (bytes): it is read whole into memory.
pub const MAX_BAG_BYTES: u64 = 2 * 1024 * 1024 * 1024;
/// The largest `metadata.yaml` read (bytes): 4 MiB. rosbag2 writes under 1 KiB a topic,
/// so this holds thousands of topics; YAML's parser holds every event of a file at once
/// (16 MiB of flat entries took 530 MB and 1.6 s, 4 MiB about a quarter of that).
pub const MAX_METADATA_BYTES: u64 = 4 << 20;
/// The most entries of the bag's folder looked at for its `*.mcap`.
pub const MAX_DIR_ENTRIES: usize = 10_000;
/// The largest chunk inflated (the uncompressed size it declares, checked before a byte is
/// inflated): 128 MiB, twice the largest message ratelab takes from ROS 2
/// ([`ratelab_core::limits::MAX_ROS_MESSAGE_BYTES`]). Writers close a chunk at a target of
/// a few MiB (the `mcap` crate's 768 KiB, rosbag2's 768 KiB by default), or after the one
/// message that passes it; one chunk is held at a time.
pub const MAX_CHUNK_BYTES: u64 = 128 << 20;
/// How many times its compressed size a chunk compressed with `codec` can inflate to: the
/// most the codec itself can produce, so a chunk that claims more lies and is refused
/// before it is inflated. zstd: a 4-byte run-length block yields at most one 128 KiB
/// block (32 768:1); lz4: a match grows by at most 255 bytes per byte read (256:1, with the
/// byte itself); none: 1. `None` for a codec ratelab cannot inflate.
pub fn max_inflation(codec: &str) -> Option<u64> {
    match codec {
        "" => Some(1),
        "zstd" => Some(32_768),
        "lz4" => Some(256),
        _ => None,
    }
}

/// What a bag's `metadata.yaml` says that the MCAP file may not (every field optional: a
/// bag of another writer, or of another version, reads as far as it goes).
#[derive(Debug, Default, serde::Deserialize)]
struct Metadata {
    #[serde(default)]
    rosbag2_bagfile_information: Option<BagInformation>,
}

#[derive(Debug, Default, serde::Deserialize)]
struct BagInformation {
    #[serde(default)]
    relative_file_paths: Vec<String>,
    #[serde(default)]
    ros_distro: Option<String>,
    #[serde(default)]
    topics_with_message_count: Vec<TopicCount>,
}

#[derive(Debug, serde::Deserialize)]
struct TopicCount {
    topic_metadata: TopicMetadata,
}

#[derive(Debug, serde::Deserialize)]
struct TopicMetadata {
    name: String,
    #[serde(default)]
    type_description_hash: Option<String>,
}

/// A bag read: its MCAP file's name and bytes, and what its metadata adds.
pub struct Bag {
    file: PathBuf,
    bytes: Vec<u8>,
    distro: Option<String>,
    hashes: BTreeMap<String, String>,
}

fn err(path: &Path, what: impl std::fmt::Display) -> String {
    format!(
        "{}: {}",
        crate::text::printable(&path.display().to_string()),
        crate::text::printable(&what.to_string())
    )
}

impl Bag {
    /// Open the bag in folder `dir`.
    ///
    /// # Errors
    /// One line: not a folder, no `*.mcap` (or several and no `metadata.yaml` naming one),
    /// a file over its bound, a `metadata.yaml` that does not parse.
    pub fn open(dir: &Path) -> Result<Bag, String> {
        if !dir.is_dir() {
            return Err(err(
                dir,
                "not a folder (a bag is a folder with metadata.yaml and its .mcap)",
            ));
        }
        let meta_path = dir.join("metadata.yaml");
        let info = if meta_path.exists() {
            let text = ratelab_core::input::read_regular_file(&meta_path, MAX_METADATA_BYTES)
                .map_err(|e| e.to_string())?;
            crate::yaml_depth::check(&text).map_err(|e| err(&meta_path, e))?;
            let m: Metadata = serde_yaml::from_slice(&text).map_err(|e| err(&meta_path, e))?;
            m.rosbag2_bagfile_information.unwrap_or_default()
        } else {
            BagInformation::default()
        };
        let named = info
            .relative_file_paths
            .iter()
            .map(|p| dir.join(p))
            .find(|p| p.extension().is_some_and(|e| e == "mcap"));
        let file = match named {
            Some(f) => f,
            None => {
                let mut found = Vec::new();
                let entries = std::fs::read_dir(dir).map_err(|e| err(dir, e))?;
                for entry in entries.take(MAX_DIR_ENTRIES) {
                    let p = entry.map_err(|e| err(dir, e))?.path();
                    if p.extension().is_some_and(|e| e == "mcap") {
                        found.push(p);
                    }
                }
                match found.len() {
                    1 => found.remove(0),
                    0 => return Err(err(dir, "no .mcap file: not a bag in MCAP storage")),
                    n => {
                        return Err(err(
                            dir,
                            format!("{n} .mcap files and no metadata.yaml naming one"),
                        ))
                    }
                }
            }
        };
        let bytes = ratelab_core::input::read_regular_file(&file, MAX_BAG_BYTES)
            .map_err(|e| e.to_string())?;
        if !bytes.starts_with(mcap::MAGIC) {
            return Err(err(
                &file,
                "not an MCAP file (its first bytes are not MCAP's magic)",
            ));
        }
        let hashes = info
            .topics_with_message_count
            .into_iter()
            .filter_map(|t| {
                Some((
                    t.topic_metadata.name,
                    t.topic_metadata.type_description_hash?,
                ))
            })
            .collect();
        Ok(Bag {
            file,
            bytes,
            distro: info.ros_distro,
            hashes,
        })
    }

    /// Every message in the file's order, to `each` (topic, type, hash, log time ns,
    /// payload); stops early when `each` returns false, or when `stop` says so (Ctrl-C,
    /// SIGTERM: checked between records and every MiB a chunk inflates). Returns a note when
    /// the file stops short of its end (a bag cut short) or the read was stopped.
    ///
    /// The records are walked by the `mcap` crate's [`mcap::read::LinearReader`], which
    /// checks every record's declared length against the bytes there are; each chunk is then
    /// inflated here, under [`MAX_CHUNK_BYTES`] and its codec's largest ratio
    /// ([`max_inflation`]), its output cut at the size it declares and its checksum checked,
    /// before its records are read. A panic inside the `mcap` crate is caught here and said as
    /// a bad file.
    ///
    /// # Errors
    /// One line when the file is not MCAP at all, a chunk passes a bound (naming it), does
    /// not inflate to what it declares or fails its checksum, or a message names a channel
    /// never declared.
    pub fn messages(
        &self,
        stop: &dyn Fn() -> bool,
        mut each: impl FnMut(&str, &str, &str, u64, &[u8]) -> bool,
    ) -> Result<Option<String>, String> {
        let mut walk = Walk {
            bag: self,
            schemas: HashMap::new(),
            channels: HashMap::new(),
            count: 0,
            stop,
        };
        let read = catching_panics(|| walk.file(&mut each));
        match read {
            Ok(r) => r.map_err(|e| err(&self.file, e)),
            Err(why) => Err(err(
                &self.file,
                format!("not a readable MCAP file (its reader failed: {why})"),
            )),
        }
    }

    /// `ros2 bag info`'s description (times in UTC), read until `stop` says so.
    ///
    /// # Errors
    /// As [`Bag::messages`].
    pub fn info(&self, stop: &dyn Fn() -> bool) -> Result<String, String> {
        #[derive(Default)]
        struct Topic {
            ty: String,
            count: u64,
        }
        let mut topics: BTreeMap<String, Topic> = BTreeMap::new();
        let (mut first, mut last, mut total) = (u64::MAX, 0u64, 0u64);
        let note = self.messages(stop, |topic, ty, _, t, _| {
            let e = topics.entry(topic.to_string()).or_default();
            e.ty = ty.to_string();
            e.count += 1;
            first = first.min(t);
            last = last.max(t);
            total += 1;
            true
        })?;
        if total == 0 {
            first = 0;
        }
        let name = self
            .file
            .file_name()
            .map_or_else(String::new, |f| f.to_string_lossy().into_owned());
        let mut rows = topics.iter().map(|(t, x)| {
            format!(
                "Topic: {} | Type: {} | Count: {} | Serialization Format: cdr",
                crate::text::printable(t),
                crate::text::printable(&x.ty),
                x.count
            )
        });
        let mut out = format!(
            "\nFiles:             {}\nBag size:          {}\nStorage id:        mcap\nROS Distro:        {}\nDuration:          {}s\nStart:             {}\nEnd:               {}\nMessages:          {total}\nTopic information: {}\n",
            crate::text::printable(&name),
            size_text(self.bytes.len() as u64),
            crate::text::printable(
                self.distro
                    .as_deref()
                    .filter(|d| !d.is_empty())
                    .unwrap_or("unknown")
            ),
            seconds(last.saturating_sub(first)),
            stamp(first),
            stamp(last),
            rows.next().unwrap_or_default(),
        );
        for r in rows {
            out.push_str(&format!("                   {r}\n"));
        }
        out.push_str("Service:           0\nService information: \n");
        if let Some(n) = note {
            out.push_str(&format!("Note: {n}\n"));
        }
        Ok(out)
    }
}

/// What is told of each message: (topic, type, RIHS01 hash, log time ns, payload) → go on.
type Each<'e> = dyn FnMut(&str, &str, &str, u64, &[u8]) -> bool + 'e;

/// A walk through a bag's records: the schemas and channels declared so far.
struct Walk<'b, 's> {
    bag: &'b Bag,
    /// Schema id → the type's name.
    schemas: HashMap<u16, String>,
    /// Channel id → (topic, type, RIHS01 hash).
    channels: HashMap<u16, (String, String, String)>,
    /// Messages given to `each` so far.
    count: u64,
    stop: &'s dyn Fn() -> bool,
}

/// What a record tells the walk: go on, or stop there (`each` asked to, or the data
/// section ended).
enum Flow {
    Go,
    Done,
}

impl Walk<'_, '_> {
    /// The whole file; a note when it stops short or is stopped.
    fn file(&mut self, each: &mut Each<'_>) -> Result<Option<String>, String> {
        let records = mcap::read::LinearReader::new_with_options(
            &self.bag.bytes,
            [mcap::read::Options::IgnoreEndMagic].into(),
        )
        .map_err(|e| e.to_string())?;
        for record in records {
            if (self.stop)() {
                return Ok(Some(format!("stopped after {} messages", self.count)));
            }
            let record = match record {
                Ok(r) => r,
                // A length past the whole file is a lie, not a bag cut short (whose last
                // record runs past where the file stops, but not past its size).
                Err(mcap::McapError::RecordTooLarge { opcode, len }) => {
                    return Err(format!(
                        "a record (opcode {opcode:#04x}) declares {len} bytes, more than the whole file holds ({}): a damaged or hostile bag",
                        self.bag.bytes.len()
                    ))
                }
                Err(mcap::McapError::ChunkTooLarge(len)) => {
                    return Err(format!(
                        "a chunk declares {len} bytes, more than the whole file holds ({}): a damaged or hostile bag",
                        self.bag.bytes.len()
                    ))
                }
                Err(e) => {
                    return Ok(Some(format!(
                        "the bag stops short after {} messages ({}): cut short?",
                        self.count,
                        crate::text::printable(&e.to_string())
                    )))
                }
            };
            if let mcap::records::Record::Chunk { header, data } = record {
                let inflated = self.inflate(&header, &data)?;
                let Some(inflated) = inflated else {
                    return Ok(Some(format!("stopped after {} messages", self.count)));
                };
                for inner in mcap::read::LinearReader::sans_magic(&inflated) {
                    if (self.stop)() {
                        return Ok(Some(format!("stopped after {} messages", self.count)));
                    }
                    let inner = inner.map_err(|e| format!("a chunk's records do not read: {e}"))?;
                    if let Flow::Done = self.take(inner, each)? {
                        return Ok(None);
                    }
                }
            } else if let Flow::Done = self.take(record, each)? {
                return Ok(None);
            }
        }
        // Records ran out at a record's end, before the data section's end: the file stops
        // where a writer that was cut off stopped.
        Ok(Some(format!(
            "the bag stops short after {} messages (its data section has no end): cut short?",
            self.count
        )))
    }

    /// One record outside a chunk or inside one.
    fn take(
        &mut self,
        record: mcap::records::Record<'_>,
        each: &mut Each<'_>,
    ) -> Result<Flow, String> {
        use mcap::records::Record;
        match record {
            Record::Schema { header, .. } => {
                self.schemas.insert(header.id, header.name);
            }
            Record::Channel(c) => {
                let ty = match c.schema_id {
                    0 => "?".to_string(),
                    id => self.schemas.get(&id).cloned().ok_or_else(|| {
                        format!(
                            "channel {} names schema {id}, never declared",
                            crate::text::printable(&c.topic)
                        )
                    })?,
                };
                let hash = c
                    .metadata
                    .get("topic_type_hash")
                    .or_else(|| self.bag.hashes.get(&c.topic))
                    .cloned()
                    .unwrap_or_default();
                self.channels.insert(c.id, (c.topic, ty, hash));
            }
            Record::Message { header, data } => {
                let (topic, ty, hash) = self.channels.get(&header.channel_id).ok_or_else(|| {
                    format!("a message on channel {}, never declared", header.channel_id)
                })?;
                self.count += 1;
                if !each(topic, ty, hash, header.log_time, &data) {
                    return Ok(Flow::Done);
                }
            }
            // The data section ends here (a footer, where a writer wrote no data end); the
            // summary repeats what it declared.
            Record::DataEnd(_) | Record::Footer(_) => return Ok(Flow::Done),
            _ => {}
        }
        Ok(Flow::Go)
    }

    /// A chunk's records, inflated under the bounds; `None` when stopped while inflating.
    fn inflate<'d>(
        &self,
        header: &mcap::records::ChunkHeader,
        data: &'d [u8],
    ) -> Result<Option<Cow<'d, [u8]>>, String> {
        let declared = header.uncompressed_size;
        let codec = header.compression.as_str();
        let ratio = max_inflation(codec).ok_or_else(|| {
            format!(
                "a chunk compressed with '{}', which ratelab cannot read (zstd, lz4 or none)",
                crate::text::printable(codec)
            )
        })?;
        if declared > MAX_CHUNK_BYTES {
            return Err(ratelab_core::limits::refusal(
                format_args!(
                    "a chunk declares {declared} bytes uncompressed; ratelab inflates at most {MAX_CHUNK_BYTES}"
                ),
                "MAX_CHUNK_BYTES (ratelab::ros2::bag_reader)",
            ));
        }
        if declared > (data.len() as u64).saturating_mul(ratio) {
            return Err(format!(
                "a chunk of {} bytes declares {declared} bytes uncompressed, more than {} can yield ({ratio}:1 at most): a damaged or hostile bag",
                data.len(),
                if codec.is_empty() { "an uncompressed chunk" } else { codec }
            ));
        }
        let inflated: Cow<'d, [u8]> = match codec {
            "" => Cow::Borrowed(data),
            "zstd" => {
                let d = zstd::stream::read::Decoder::with_buffer(data)
                    .map_err(|e| format!("a zstd chunk does not read: {e}"))?;
                match self.read_bounded(d, declared)? {
                    Some(v) => Cow::Owned(v),
                    None => return Ok(None),
                }
            }
            _ => {
                let d = lz4::Decoder::new(data)
                    .map_err(|e| format!("an lz4 chunk does not read: {e}"))?;
                match self.read_bounded(d, declared)? {
                    Some(v) => Cow::Owned(v),
                    None => return Ok(None),
                }
            }
        };
        if inflated.len() as u64 != declared {
            return Err(format!(
                "a chunk inflates to {}{} bytes where it declares {declared}: a damaged or hostile bag",
                if inflated.len() as u64 > declared { "more than " } else { "" },
                inflated.len().min(usize::try_from(declared).unwrap_or(usize::MAX))
            ));
        }
        if header.uncompressed_crc != 0 && crc32fast::hash(&inflated) != header.uncompressed_crc {
            return Err("a chunk's checksum does not match its records: a damaged bag".into());
        }
        Ok(Some(inflated))
    }

    /// At most `declared + 1` bytes of `r`, a MiB at a time, `stop` checked between them;
    /// `None` when stopped.
    fn read_bounded(&self, r: impl Read, declared: u64) -> Result<Option<Vec<u8>>, String> {
        const STEP: u64 = 1 << 20;
        // `declared` is at most MAX_CHUNK_BYTES here: reserved, not touched, until inflated.
        let mut out = Vec::with_capacity(usize::try_from(declared + 1).unwrap_or(usize::MAX));
        let mut r = r.take(declared + 1);
        loop {
            if (self.stop)() {
                return Ok(None);
            }
            let n = (&mut r)
                .take(STEP)
                .read_to_end(&mut out)
                .map_err(|e| format!("a chunk does not inflate: {e}"))?;
            if n == 0 {
                return Ok(Some(out));
            }
        }
    }
}

/// `f()`, with a panic inside it (in a dependency reading outside bytes) caught and given
/// back as its message, printed by nobody: one line is said of it by the caller.
fn catching_panics<T>(f: impl FnOnce() -> T) -> Result<T, String> {
    let hook = std::panic::take_hook();
    std::panic::set_hook(Box::new(|_| {}));
    let r = std::panic::catch_unwind(std::panic::AssertUnwindSafe(f));
    std::panic::set_hook(hook);
    r.map_err(|p| {
        p.downcast_ref::<&str>()
            .map(|s| (*s).to_string())
            .or_else(|| p.downcast_ref::<String>().cloned())
            .unwrap_or_else(|| "a panic".into())
    })
}

/// `9.980000000` (s, nine decimals).
fn seconds(ns: u64) -> String {
    format!("{}.{:09}", ns / 1_000_000_000, ns % 1_000_000_000)
}

/// `Jan  1 1970 00:00:00.020000000 (0.020000000)`, in UTC.
fn stamp(ns: u64) -> String {
    let secs = i64::try_from(ns / 1_000_000_000).unwrap_or(i64::MAX);
    let date = chrono::DateTime::from_timestamp(secs, 0).map_or_else(
        || "?".to_string(),
        |d| d.format("%b %e %Y %H:%M:%S").to_string(),
    );
    format!("{date}.{:09} ({})", ns % 1_000_000_000, seconds(ns))
}

/// `36.6 KiB`, as rosbag2 gives a size.
fn size_text(bytes: u64) -> String {
    let units = ["B", "KiB", "MiB", "GiB", "TiB"];
    let mut v = bytes as f64;
    let mut i = 0;
    while v >= 1024.0 && i + 1 < units.len() {
        v /= 1024.0;
        i += 1;
    }
    if i == 0 {
        format!("{bytes} B")
    } else {
        format!("{v:.1} {}", units[i])
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn times_and_sizes_read_as_ros2_bag_info_gives_them() {
        assert_eq!(seconds(9_980_000_000), "9.980000000");
        assert_eq!(
            stamp(20_000_000),
            "Jan  1 1970 00:00:00.020000000 (0.020000000)"
        );
        assert_eq!(size_text(512), "512 B");
        assert_eq!(size_text(37_478), "36.6 KiB");
    }

    #[test]
    fn what_is_not_a_bag_is_said_in_one_line() {
        let dir = tempfile::tempdir().unwrap();
        let e = Bag::open(dir.path()).err().unwrap();
        assert!(e.contains("no .mcap file"), "{e}");
        std::fs::write(dir.path().join("x.mcap"), b"not mcap at all").unwrap();
        let e = Bag::open(dir.path()).err().unwrap();
        assert!(e.contains("not an MCAP file") && !e.contains('\n'), "{e}");
        // MCAP's magic and nothing after it: read as a bag cut short at once.
        std::fs::write(dir.path().join("x.mcap"), mcap::MAGIC).unwrap();
        let info = Bag::open(dir.path()).unwrap().info(&|| false).unwrap();
        assert!(info.contains("Messages:          0\n"), "{info}");
        assert!(info.contains("stops short after 0 messages"), "{info}");
        std::fs::write(
            dir.path().join("metadata.yaml"),
            b"rosbag2_bagfile_information: [",
        )
        .unwrap();
        assert!(Bag::open(dir.path()).is_err());
        let file = dir.path().join("x.mcap");
        assert!(Bag::open(&file).err().unwrap().contains("not a folder"));
    }
}
