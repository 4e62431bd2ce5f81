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
//! [`MAX_BAG_BYTES`], `metadata.yaml` at most [`MAX_METADATA_BYTES`], the folder's listing at
//! most [`MAX_DIR_ENTRIES`] entries.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

/// The largest MCAP file read (bytes): it is read whole into memory.
pub const MAX_BAG_BYTES: u64 = 2 * 1024 * 1024 * 1024;
/// The largest `metadata.yaml` read (bytes).
pub const MAX_METADATA_BYTES: u64 = 16 * 1024 * 1024;
/// The most entries of the bag's folder looked at for its `*.mcap`.
pub const MAX_DIR_ENTRIES: usize = 10_000;

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
    /// payload); stops early when `each` returns false. Returns a note when the file
    /// stops short of its end (a bag cut short).
    ///
    /// # Errors
    /// One line when the file is not MCAP at all.
    pub fn messages(
        &self,
        mut each: impl FnMut(&str, &str, &str, u64, &[u8]) -> bool,
    ) -> Result<Option<String>, String> {
        let stream = mcap::MessageStream::new(&self.bytes).map_err(|e| err(&self.file, e))?;
        for (n, m) in stream.enumerate() {
            let m = match m {
                Ok(m) => m,
                Err(e) => {
                    return Ok(Some(format!(
                        "the bag stops short after {n} messages ({}): cut short?",
                        crate::text::printable(&e.to_string())
                    )))
                }
            };
            let ty = m.channel.schema.as_ref().map_or("?", |s| s.name.as_str());
            let hash = m
                .channel
                .metadata
                .get("topic_type_hash")
                .or_else(|| self.hashes.get(&m.channel.topic))
                .map_or("", String::as_str);
            if !each(&m.channel.topic, ty, hash, m.log_time, &m.data) {
                break;
            }
        }
        Ok(None)
    }

    /// `ros2 bag info`'s description (times in UTC).
    ///
    /// # Errors
    /// As [`Bag::messages`].
    pub fn info(&self) -> Result<String, String> {
        #[derive(Default)]
        struct Topic {
            ty: String,
            count: u64,
        }
        let mut topics: BTreeMap<String, Topic> = BTreeMap::new();
        let (mut first, mut last, mut total) = (u64::MAX, 0u64, 0u64);
        let note = self.messages(|topic, ty, _, t, _| {
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
        let info = Bag::open(dir.path()).unwrap().info().unwrap();
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
