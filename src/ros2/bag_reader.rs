//! `ratelab ros2 bag info|echo DIR`: a rosbag2 bag in MCAP storage read back, whoever wrote
//! it (`--bag`, or `ros2 bag record`), as `ros2 bag info` describes one and as `ros2 topic
//! echo` would have printed its messages ([`super::echo`]).
//!
//! The MCAP file is the one `metadata.yaml` names, else the folder's only `*.mcap`; its
//! messages are read with the `mcap` crate (every message, in the file's order, so a bag cut
//! short, without its summary, still reads up to where it stops, and says so). A topic's
//! type is its channel's schema name; its RIHS01 hash is the channel's `topic_type_hash`
//! (rosbag2's MCAP metadata) or `metadata.yaml`'s `type_description_hash`. A message is
//! decoded ([`BagMessage::decode`]) by the description ratelab has of its type when the
//! name and hash are one it knows ([`super::echo::known`]; a bag that gives no hash, by the
//! name alone); else by the `ros2msg` schema the bag carries for its channel
//! ([`super::msg_schema`]), whose description must hash to the bag's hash when the bag
//! gives one. Bounded: the MCAP file at most
//! [`MAX_BAG_BYTES`], `metadata.yaml` at most [`MAX_METADATA_BYTES`] and
//! [`crate::yaml_depth::MAX_YAML_DEPTH`] deep, the folder's listing at most
//! [`MAX_DIR_ENTRIES`] entries, every record's length by the bytes there are, a chunk's
//! inflated size by [`MAX_CHUNK_BYTES`], by what it declares and by its codec's ratio
//! ([`max_inflation`]), the schemas held by [`super::msg_schema::MAX_SCHEMA_BYTES`] each
//! and [`MAX_HELD_SCHEMA_BYTES`] in all; Ctrl-C and SIGTERM end a read between records. The
//! `mcap` crate's own `MessageStream` is not used: it reads a record's declared length
//! unchecked (a 64-byte file claiming 2⁶⁴ − 1 bytes panics it) and loops forever on a chunk
//! that inflates past what it declares.

use super::echo::{self, NOT_DESCRIBED};
use super::msg_schema::{self, MAX_SCHEMA_BYTES};
use hiroz_schema::TypeDescriptionMsg;
use std::borrow::Cow;
use std::cell::OnceCell;
use std::collections::{BTreeMap, HashMap};
use std::io::Read;
use std::path::{Path, PathBuf};
use std::rc::Rc;

/// The largest MCAP file read (bytes): it is read whole into memory.
pub const MAX_BAG_BYTES: u64 = 2 * 1024 * 1024 * 1024;
/// The largest `metadata.yaml` read (bytes): 4 MiB. rosbag2 writes under 1 KiB a topic,
/// so this holds thousands of topics; YAML's parser holds every event of a file at once
/// (16 MiB of flat entries took 530 MB and 1.6 s, 4 MiB about a quarter of that).
pub const MAX_METADATA_BYTES: u64 = 4 << 20;
/// The most schema text held while a bag is read (bytes, every schema's together): 64 MiB.
/// A bag declares one schema a type, a few KiB each; a schema past this is not held, and
/// its messages are said undecoded, with the reason.
pub const MAX_HELD_SCHEMA_BYTES: usize = 64 << 20;
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
        ratelab_core::text::printable(&path.display().to_string()),
        ratelab_core::text::printable(&what.to_string())
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

    /// Every message in the file's order, to `each` ([`BagMessage`]: its topic, type, hash,
    /// log time and payload, and how to decode it); stops early when `each` returns false,
    /// or when `stop` says so (Ctrl-C, SIGTERM: checked between records and every MiB a
    /// chunk inflates). Returns a note when
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
        mut each: impl FnMut(&BagMessage<'_>) -> bool,
    ) -> Result<Option<String>, String> {
        let mut walk = Walk {
            bag: self,
            schemas: HashMap::new(),
            channels: HashMap::new(),
            held: 0,
            count: 0,
            stop,
        };
        let read = super::catching_panics(|| walk.file(&mut each));
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
        let note = self.messages(stop, |m| {
            let e = topics.entry(m.topic.to_string()).or_default();
            e.ty = m.type_name.to_string();
            e.count += 1;
            first = first.min(m.log_time);
            last = last.max(m.log_time);
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
                ratelab_core::text::printable(t),
                ratelab_core::text::printable(&x.ty),
                x.count
            )
        });
        let mut out = format!(
            "\nFiles:             {}\nBag size:          {}\nStorage id:        mcap\nROS Distro:        {}\nDuration:          {}s\nStart:             {}\nEnd:               {}\nMessages:          {total}\nTopic information: {}\n",
            ratelab_core::text::printable(&name),
            size_text(self.bytes.len() as u64),
            ratelab_core::text::printable(
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

/// One message of a bag, as [`Bag::messages`] tells it.
pub struct BagMessage<'m> {
    /// Its topic.
    pub topic: &'m str,
    /// Its type: its channel's schema name (`?` for a channel of no schema).
    pub type_name: &'m str,
    /// Its type's RIHS01 hash, when the bag gives one (else empty).
    pub hash: &'m str,
    /// Its log time, ns.
    pub log_time: u64,
    /// Its payload: CDR with its 4-byte header.
    pub data: &'m [u8],
    /// Its channel's schema, when it has one.
    schema: Option<&'m Schema>,
}

impl BagMessage<'_> {
    /// The message decoded as `ratelab ros2 bag echo` prints it ([`echo::yaml`]), with
    /// echo's bounds: by the description ratelab has of its type when the type's name and
    /// the bag's hash are one it knows (the name alone when the bag gives no hash, as
    /// [`echo::decode_named`]); else by the `ros2msg` schema the bag carries for it
    /// ([`msg_schema::describe`]), whose description must hash to the bag's hash when it
    /// gives one.
    ///
    /// # Errors
    /// One line: [`NOT_DESCRIBED`] and why the schema did not serve (none, not `ros2msg`,
    /// refused, another hash), or why the payload does not decode.
    pub fn decode(&self) -> Result<echo::Value, String> {
        let by_name = || echo::decode_named(self.type_name, self.hash, self.data);
        let and = |e: String, why: &str| {
            if e == NOT_DESCRIBED {
                format!("{e}, and {why}")
            } else {
                e
            }
        };
        let Some(schema) = self.schema else {
            return by_name().map_err(|e| and(e, "the bag carries no schema of it"));
        };
        match by_name() {
            Err(e) if e == NOT_DESCRIBED => {}
            decoded => return decoded,
        }
        let (d, hash) = schema
            .description()
            .map_err(|why| format!("{NOT_DESCRIBED}, and {why}"))?;
        if !self.hash.is_empty() && hash != self.hash {
            return Err(format!(
                "{NOT_DESCRIBED}, and the ros2msg schema describes a type of hash {hash}, not of the bag's {}",
                ratelab_core::text::printable(self.hash)
            ));
        }
        echo::decode_with(d, self.data)
    }
}

/// A schema the bag declares: its type's name and text, described (with its RIHS01 hash)
/// when a message of it is first decoded.
struct Schema {
    name: String,
    encoding: String,
    /// The text's length, whether held or not.
    len: usize,
    /// The text, or why it is not held (not `ros2msg`, too long, past what a bag may hold).
    text: Result<Vec<u8>, String>,
    described: OnceCell<Result<(TypeDescriptionMsg, String), String>>,
}

impl Schema {
    /// The description the schema gives its type, and that description's RIHS01 hash.
    fn description(&self) -> Result<&(TypeDescriptionMsg, String), String> {
        self.described
            .get_or_init(|| {
                let text = self.text.as_ref().map_err(Clone::clone)?;
                let d = msg_schema::describe(&self.name, text)?;
                let hash = hiroz_schema::calculate_hash(&d).to_rihs_string();
                Ok((d, hash))
            })
            .as_ref()
            .map_err(Clone::clone)
    }
}

/// A channel the bag declares.
struct Channel {
    topic: String,
    /// Its type: its schema's name, or `?`.
    ty: String,
    /// Its type's RIHS01 hash, or empty.
    hash: String,
    schema: Option<Rc<Schema>>,
}

/// What is told of each message ([`BagMessage`]) → go on.
type Each<'e> = dyn FnMut(&BagMessage<'_>) -> bool + 'e;

/// A walk through a bag's records: the schemas and channels declared so far.
struct Walk<'b, 's> {
    bag: &'b Bag,
    /// Schema id → the schema.
    schemas: HashMap<u16, Rc<Schema>>,
    /// Channel id → the channel.
    channels: HashMap<u16, Channel>,
    /// The schema text held, bytes ([`MAX_HELD_SCHEMA_BYTES`] at most).
    held: usize,
    /// Messages given to `each` so far.
    count: u64,
    stop: &'s dyn Fn() -> bool,
}

/// What a record tells the walk: go on, or stop there (`each` asked to: `Done`; the data
/// section ended: `End`).
enum Flow {
    Go,
    Done,
    End,
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
                // A record longer than the whole file: every record before it was read
                // whole, so the file stops inside this one, as a bag cut short does (a
                // writer killed inside a chunk leaves the chunk's length unwritten,
                // 2^64 − 1; a file cut inside a record leaves one longer than what is
                // left of it). Read as far as it goes, and said; nothing is held for the
                // length. But a file that ends in MCAP's closing magic was not cut, and no
                // writer leaves another record's length unwritten: a lie, refused.
                Err(mcap::McapError::RecordTooLarge { opcode, len })
                    if self.bag.bytes.ends_with(mcap::MAGIC)
                        || (len == u64::MAX && opcode != mcap::records::op::CHUNK) =>
                {
                    return Err(format!(
                        "a record (opcode {opcode:#04x}) declares {len} bytes, more than the whole file holds ({}): a damaged or hostile bag",
                        self.bag.bytes.len()
                    ))
                }
                Err(mcap::McapError::RecordTooLarge { opcode, len }) => {
                    let what = if opcode == mcap::records::op::CHUNK && len == u64::MAX {
                        "a chunk its writer never finished".to_string()
                    } else {
                        format!(
                            "a record (opcode {opcode:#04x}) of {len} bytes where the file holds {}",
                            self.bag.bytes.len()
                        )
                    };
                    return Ok(Some(format!(
                        "the bag stops short after {} messages, inside {what}: cut short?",
                        self.count
                    )));
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
                        ratelab_core::text::printable(&e.to_string())
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
                    if let Some(ended) = self.step(inner, each)? {
                        return Ok(ended);
                    }
                }
            } else if let Some(ended) = self.step(record, each)? {
                return Ok(ended);
            }
        }
        // Records ran out at a record's end, before the data section's end: the file stops
        // where a writer that was cut off stopped.
        Ok(Some(format!(
            "the bag stops short after {} messages (its data section has no end): cut short?",
            self.count
        )))
    }

    /// [`Walk::take`] `record`, and where that ends the walk, what [`Walk::file`] returns: no
    /// note when `each` asked to stop; when the data section ended, none for a whole file
    /// (it ends in MCAP's closing magic), else that every message was read but the summary
    /// after them is cut short (a file cut after its data, or a writer stopped while
    /// writing its summary).
    ///
    /// # Errors
    /// [`Walk::take`]'s.
    fn step(
        &mut self,
        record: mcap::records::Record<'_>,
        each: &mut Each<'_>,
    ) -> Result<Option<Option<String>>, String> {
        Ok(match self.take(record, each)? {
            Flow::Go => None,
            Flow::Done => Some(None),
            Flow::End => Some((!self.bag.bytes.ends_with(mcap::MAGIC)).then(|| {
                format!(
                    "the bag's data is whole ({} read) but its summary stops short: cut short?",
                    ratelab_core::metrics::counted(self.count, "message")
                )
            })),
        })
    }

    /// One record outside a chunk or inside one.
    fn take(
        &mut self,
        record: mcap::records::Record<'_>,
        each: &mut Each<'_>,
    ) -> Result<Flow, String> {
        use mcap::records::Record;
        match record {
            Record::Schema { header, data } => self.schema(header, &data),
            Record::Channel(c) => {
                let schema = match c.schema_id {
                    0 => None,
                    id => Some(self.schemas.get(&id).cloned().ok_or_else(|| {
                        format!(
                            "channel {} names schema {id}, never declared",
                            ratelab_core::text::printable(&c.topic)
                        )
                    })?),
                };
                let ty = schema
                    .as_ref()
                    .map_or_else(|| "?".to_string(), |s| s.name.clone());
                let hash = c
                    .metadata
                    .get("topic_type_hash")
                    .or_else(|| self.bag.hashes.get(&c.topic))
                    .cloned()
                    .unwrap_or_default();
                let channel = Channel {
                    topic: c.topic,
                    ty,
                    hash,
                    schema,
                };
                self.channels.insert(c.id, channel);
            }
            Record::Message { header, data } => {
                let c = self.channels.get(&header.channel_id).ok_or_else(|| {
                    format!("a message on channel {}, never declared", header.channel_id)
                })?;
                self.count += 1;
                let m = BagMessage {
                    topic: &c.topic,
                    type_name: &c.ty,
                    hash: &c.hash,
                    log_time: header.log_time,
                    data: &data,
                    schema: c.schema.as_deref(),
                };
                if !each(&m) {
                    return Ok(Flow::Done);
                }
            }
            // The data section ends here (a footer, where a writer wrote no data end); the
            // summary repeats what it declared.
            Record::DataEnd(_) | Record::Footer(_) => return Ok(Flow::End),
            _ => {}
        }
        Ok(Flow::Go)
    }

    /// A schema record: kept (a copy of one already declared is not kept twice), its text
    /// held when it is `ros2msg` and within [`MAX_SCHEMA_BYTES`] and [`MAX_HELD_SCHEMA_BYTES`].
    fn schema(&mut self, header: mcap::records::SchemaHeader, data: &[u8]) {
        let same = self.schemas.get(&header.id).is_some_and(|s| {
            s.name == header.name
                && s.encoding == header.encoding
                && s.len == data.len()
                && s.text.as_deref().map_or(true, |t| t == data)
        });
        if same {
            return;
        }
        let text = if header.encoding != "ros2msg" {
            Err(format!(
                "its schema is encoded '{}', not ros2msg, which ratelab does not read",
                ratelab_core::text::printable(&header.encoding)
            ))
        } else if data.len() > MAX_SCHEMA_BYTES {
            Err(msg_schema::too_long(data.len()))
        } else if data.iter().all(u8::is_ascii_whitespace) {
            // What a writer with no definition of the type writes (a bag converted from
            // one that carried none): no definition, rather than one of no fields.
            Err("its ros2msg schema is empty (its writer had no definition of it)".into())
        } else if self.held + data.len() > MAX_HELD_SCHEMA_BYTES {
            Err(format!(
                "the bag's schemas pass {MAX_HELD_SCHEMA_BYTES} bytes, more than ratelab holds (ratelab::ros2::bag_reader::MAX_HELD_SCHEMA_BYTES)"
            ))
        } else {
            self.held += data.len();
            Ok(data.to_vec())
        };
        let schema = Schema {
            name: header.name,
            encoding: header.encoding,
            len: data.len(),
            text,
            described: OnceCell::new(),
        };
        self.schemas.insert(header.id, Rc::new(schema));
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
                ratelab_core::text::printable(codec)
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

/// `9.980000000` (s, nine decimals).
fn seconds(ns: u64) -> String {
    ratelab_core::time::Nanos(ns).secs_exact()
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

    /// A message of a type ratelab has no description of decodes by its channel's `ros2msg`
    /// schema when the schema describes a type of the bag's hash (or the bag gives none);
    /// else it is said, in one line, why not.
    #[test]
    fn a_type_ratelab_does_not_know_decodes_by_the_bag_s_schema() {
        let dir = tempfile::tempdir().unwrap();
        let text = b"# a made-up type\nuint8 KIND=1\nfloat64 x\nstring s\n";
        let d = msg_schema::describe("my_pkg/msg/Small", text).unwrap();
        let hash = hiroz_schema::calculate_hash(&d).to_rihs_string();
        let file = std::fs::File::create(dir.path().join("b.mcap")).unwrap();
        let mut w = mcap::WriteOptions::new()
            .profile("ros2")
            .create(std::io::BufWriter::new(file))
            .unwrap();
        let small = w.add_schema("my_pkg/msg/Small", "ros2msg", text).unwrap();
        let idl = w
            .add_schema("my_pkg/msg/Idl", "ros2idl", b"module my_pkg {};")
            .unwrap();
        let meta = |h: &str| BTreeMap::from([("topic_type_hash".to_string(), h.to_string())]);
        let liar = format!("RIHS01_{}", "0".repeat(64));
        let channels = [
            w.add_channel(small, "/small", "cdr", &meta(&hash)).unwrap(),
            w.add_channel(small, "/nohash", "cdr", &BTreeMap::new())
                .unwrap(),
            w.add_channel(small, "/liar", "cdr", &meta(&liar)).unwrap(),
            w.add_channel(idl, "/idl", "cdr", &BTreeMap::new()).unwrap(),
        ];
        // x = 1.5, s = "hi"
        let mut cdr = vec![0, 1, 0, 0];
        cdr.extend_from_slice(&1.5f64.to_le_bytes());
        cdr.extend_from_slice(&3u32.to_le_bytes());
        cdr.extend_from_slice(b"hi\0");
        for (t, channel_id) in (0u64..).zip(channels) {
            let header = mcap::records::MessageHeader {
                channel_id,
                sequence: 0,
                log_time: t,
                publish_time: t,
            };
            w.write_to_known_channel(&header, &cdr).unwrap();
        }
        w.finish().unwrap();
        drop(w);
        let bag = Bag::open(dir.path()).unwrap();
        let mut got = Vec::new();
        let note = bag
            .messages(&|| false, |m| {
                got.push((m.topic.to_string(), m.decode().map(|v| echo::yaml(&v))));
                true
            })
            .unwrap();
        assert_eq!(note, None);
        let decoded = Ok("x: 1.5\ns: hi\n".to_string());
        assert_eq!(got[0], ("/small".to_string(), decoded.clone()));
        assert_eq!(got[1], ("/nohash".to_string(), decoded));
        let why = |i: usize| got[i].1.clone().unwrap_err();
        assert!(
            why(2).starts_with(&format!(
                "a type not described here, and the ros2msg schema describes a type of hash {hash}, not of the bag's {liar}"
            )),
            "{}",
            why(2)
        );
        assert!(
            why(3).contains("encoded 'ros2idl', not ros2msg"),
            "{}",
            why(3)
        );
        assert!(!why(2).contains('\n') && !why(3).contains('\n'));
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
