//! `--bag DIR`: what a run offered to ROS 2, written as a rosbag2 bag with MCAP storage
//! (the format `ros2 bag record` writes since Iron, and `ros2 bag play` reads): a folder
//! with `metadata.yaml` and one `<folder name>_0.mcap`.
//!
//! The MCAP file has the `ros2` profile; one schema per type (encoding `ros2msg`: the `.msg`
//! text with its dependencies after rosbag2's `====…` / `MSG: pkg/Type` separators), one
//! channel per topic (CDR): the graph's, `/clock`, and what every ROS 2 node publishes
//! besides, `/rosout` and `/parameter_events` (which `ros2 bag record -a` takes too); each
//! message's log and publish times are its run time, ns (a log line's: the run time it was
//! written at, or the latest seen), so a bag of a virtual run holds the same topic messages
//! at the same times on every run of it (the MCAP summary's record order is the `mcap`
//! crate's and varies; a `/rosout` line is stamped with the wall clock, as rcl stamps it),
//! and its starting time reads 1970-01-01 (run time starts at 0). `metadata.yaml` is
//! rosbag2's version 9 with each topic's type, RIHS01 hash, message count and offered QoS
//! profiles (one per publisher, the QoS ratelab ran it with, as its publisher's token says).
//! Each MCAP channel's metadata holds the same two as rosbag2_storage_mcap writes them
//! (`mcap_storage.cpp`, `create_topic`): `offered_qos_profiles` (that YAML) and
//! `topic_type_hash` (`RIHS01_<64 hex>`), where `ros2 bag play` and `ros2 bag info` read
//! them. MCAP is written by the `mcap` crate,
//! the YAML by `serde_yaml`; a bag cut short (killed run) has its MCAP data, all but the
//! last [`FLUSH_PERIOD`] of it at most, but no `metadata.yaml`, which `ros2 bag reindex`
//! rebuilds. A bag that could not be written
//! whole (a full disk) is not left under its name: its MCAP file is removed, and the run
//! says so and fails ([`Bag::finish`]), as `--out` and `--record` do.

use super::rmw_zenoh::qos::{QosDurability, QosDuration, QosHistory, QosProfile, QosReliability};
use super::types::RosType;
use super::Ros2Error;
use hiroz_schema::TypeDescriptionMsg;
use serde::Serialize;
use std::collections::BTreeMap;
use std::io::BufWriter;
use std::path::{Path, PathBuf};

/// The `.msg` text of each type the bags carry, as ROS 2 Jazzy ships it (comments dropped;
/// `rcl_interfaces`' from ros2/rcl_interfaces 2.2.0, the same in Kilted); empty for a type
/// of no text here. Also the sources `~/get_type_description` gives when asked
/// ([`super::type_description`]).
pub(crate) fn msg_text(name: &str) -> &'static str {
    match name {
        "rcl_interfaces/msg/Log" => {
            "uint8 DEBUG=10\nuint8 INFO=20\nuint8 WARN=30\nuint8 ERROR=40\nuint8 FATAL=50\n\
             builtin_interfaces/Time stamp\nuint8 level\nstring name\nstring msg\nstring file\n\
             string function\nuint32 line\n"
        }
        "rcl_interfaces/msg/ParameterEvent" => {
            "builtin_interfaces/Time stamp\nstring node\nParameter[] new_parameters\n\
             Parameter[] changed_parameters\nParameter[] deleted_parameters\n"
        }
        "rcl_interfaces/msg/Parameter" => "string name\nParameterValue value\n",
        "rcl_interfaces/msg/ParameterValue" => {
            "uint8 type\nbool bool_value\nint64 integer_value\nfloat64 double_value\n\
             string string_value\nbyte[] byte_array_value\nbool[] bool_array_value\n\
             int64[] integer_array_value\nfloat64[] double_array_value\n\
             string[] string_array_value\n"
        }
        "builtin_interfaces/msg/Time" => "int32 sec\nuint32 nanosec\n",
        "std_msgs/msg/Header" => "builtin_interfaces/Time stamp\nstring frame_id\n",
        "sensor_msgs/msg/JointState" => {
            "std_msgs/Header header\nstring[] name\nfloat64[] position\nfloat64[] velocity\nfloat64[] effort\n"
        }
        "sensor_msgs/msg/Image" => {
            "std_msgs/Header header\nuint32 height\nuint32 width\nstring encoding\n\
             uint8 is_bigendian\nuint32 step\nuint8[] data\n"
        }
        "std_msgs/msg/Float64" => "float64 data\n",
        "rosgraph_msgs/msg/Clock" => "builtin_interfaces/Time clock\n",
        _ => "",
    }
}

/// rosbag2's `ros2msg` schema of the type `description` describes: its text, then each
/// type it refers to.
fn schema(description: &TypeDescriptionMsg) -> String {
    let mut s = msg_text(&description.type_description.type_name).to_string();
    for r in &description.referenced_type_descriptions {
        let short = r.type_name.replacen("/msg/", "/", 1);
        s.push_str(&format!("{}\nMSG: {short}\n", "=".repeat(80)));
        s.push_str(msg_text(&r.type_name));
    }
    s
}

/// One topic of the bag.
pub struct BagTopic<'a> {
    /// Its name (`/obs`).
    pub name: &'a str,
    /// Its ROS 2 type's description (its name, `sensor_msgs/msg/JointState`, and the types
    /// it refers to): the channel's schema.
    pub description: &'a TypeDescriptionMsg,
    /// Its type's RIHS01 hash, `RIHS01_<64 hex>`.
    pub hash: String,
    /// The QoS each of its publishers offered, one profile per publisher (rosbag2 lists
    /// them so).
    pub qos: Vec<QosProfile>,
}

impl<'a> BagTopic<'a> {
    /// Topic `name` of type `ty`, with one publisher offering `qos`.
    pub fn of(name: &'a str, ty: &'a RosType, qos: QosProfile) -> BagTopic<'a> {
        BagTopic {
            name,
            description: &ty.description,
            hash: ty.hash.to_rihs_string(),
            qos: vec![qos],
        }
    }
}

/// A QoS profile as rosbag2's metadata (version 9) writes it.
#[derive(Clone, Debug, PartialEq, Serialize)]
struct QosYaml {
    history: &'static str,
    depth: usize,
    reliability: &'static str,
    durability: &'static str,
    deadline: SecNsec,
    lifespan: SecNsec,
    liveliness: &'static str,
    liveliness_lease_duration: SecNsec,
    avoid_ros_namespace_conventions: bool,
}

#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
struct SecNsec {
    sec: u64,
    nsec: u64,
}

impl QosYaml {
    fn of(q: &QosProfile) -> QosYaml {
        let d = |d: QosDuration| SecNsec {
            sec: d.sec,
            nsec: d.nsec,
        };
        let (history, depth) = match q.history {
            QosHistory::KeepLast(n) => ("keep_last", n),
            QosHistory::KeepAll(_) => ("keep_all", 0),
        };
        QosYaml {
            history,
            depth,
            reliability: match q.reliability {
                QosReliability::Reliable => "reliable",
                QosReliability::BestEffort => "best_effort",
            },
            durability: match q.durability {
                QosDurability::Volatile => "volatile",
                QosDurability::TransientLocal => "transient_local",
            },
            deadline: d(q.deadline),
            lifespan: d(q.lifespan),
            liveliness: "automatic",
            liveliness_lease_duration: d(q.liveliness_lease_duration),
            avoid_ros_namespace_conventions: false,
        }
    }
}

/// An MCAP channel's metadata as rosbag2_storage_mcap writes it (`create_topic`): its
/// publishers' offered QoS profiles (`offered_qos_profiles`, the YAML of `metadata.yaml`'s
/// version 9) and its type's hash (`topic_type_hash`, `RIHS01_<64 hex>`).
fn channel_metadata(qos: &[QosYaml], hash: &str) -> BTreeMap<String, String> {
    let offered = serde_yaml::to_string(qos).unwrap_or_default();
    BTreeMap::from([
        ("offered_qos_profiles".to_string(), offered),
        ("topic_type_hash".to_string(), hash.to_string()),
    ])
}

struct Counted {
    name: String,
    type_name: String,
    hash: String,
    qos: Vec<QosYaml>,
    channel: u16,
    count: u64,
}

/// A bag being written.
pub struct Bag {
    writer: mcap::Writer<BufWriter<std::fs::File>>,
    dir: PathBuf,
    mcap_path: PathBuf,
    topics: Vec<Counted>,
    first_ns: Option<u64>,
    last_ns: u64,
    /// The first write that failed (a full disk): later messages are not written, and
    /// [`Bag::finish`] removes the file.
    failed: Option<String>,
    /// When the MCAP data was last put in the file whole ([`FLUSH_PERIOD`]).
    flushed: std::time::Instant,
}

/// How long, in wall time, a message may wait in the MCAP writer's open chunk before the
/// chunk is closed and written to the file: what a run killed outright (SIGKILL, the OOM
/// killer) loses of its bag at most, a second of wall time (under the virtual clock, that
/// may be many seconds of run time). The `mcap` crate writes a chunk only when it holds
/// 1 MiB of records (95 s of the chapter's run: 11 kB of records a second), so a run killed
/// before then kept no message at all, and a longer one lost up to its last 95 s. Closing
/// a chunk is `mcap::Writer::flush`, which leaves the file readable up to there.
pub const FLUSH_PERIOD: std::time::Duration = std::time::Duration::from_secs(1);

fn io(what: &Path, e: impl std::fmt::Display) -> Ros2Error {
    Ros2Error::Usage(format!("--bag {}: {e}", what.display()))
}

/// An output check's refusal, which names its file itself.
fn out(e: ratelab_core::output::OutputError) -> Ros2Error {
    Ros2Error::Usage(format!("--bag: {e}"))
}

impl Bag {
    /// The bag's two files in `dir`: the MCAP file (named for the folder, as rosbag2
    /// names it) and `metadata.yaml`.
    fn files(dir: &Path) -> (PathBuf, PathBuf) {
        (
            dir.join(format!("{}_0.mcap", Bag::stem(dir))),
            dir.join("metadata.yaml"),
        )
    }

    /// What the bag's MCAP files in `dir` are named for: the folder's name (`bag` when it
    /// has none, as `/`).
    fn stem(dir: &Path) -> String {
        std::path::absolute(dir)
            .ok()
            .and_then(|d| d.file_name().map(|n| n.to_string_lossy().into_owned()))
            .unwrap_or_else(|| "bag".into())
    }

    /// Every MCAP file in `dir` (a folder that exists), each once, with whether it is a
    /// file of this folder's bag: `<stem>_<N>.mcap`, as rosbag2 names the files of a bag
    /// split in several (`<stem>` the folder's name as [`Bag::files`] writes it, `N` decimal
    /// digits). Names are compared as bytes: a name that is not UTF-8 is never this bag's.
    /// Read lazily: `each` may stop the walk with an error.
    ///
    /// # Errors
    /// The folder cannot be read, or `each`'s error.
    fn each_mcap(
        dir: &Path,
        mut each: impl FnMut(&Path, bool) -> Result<(), Ros2Error>,
    ) -> Result<(), Ros2Error> {
        use std::os::unix::ffi::OsStrExt as _;
        let prefix = format!("{}_", Bag::stem(dir));
        for entry in std::fs::read_dir(dir).map_err(|e| io(dir, e))? {
            let entry = entry.map_err(|e| io(dir, e))?;
            let name = entry.file_name();
            let Some(base) = name.as_bytes().strip_suffix(b".mcap") else {
                continue;
            };
            let ours = base
                .strip_prefix(prefix.as_bytes())
                .is_some_and(|n| !n.is_empty() && n.iter().all(u8::is_ascii_digit));
            each(&entry.path(), ours)?;
        }
        Ok(())
    }

    /// Check that a bag may be written in `dir` (before a run starts).
    ///
    /// # Errors
    /// [`Ros2Error::Usage`]: `dir` exists and is not a folder, or holds a bag (its
    /// `metadata.yaml` or any of its `<folder>_<N>.mcap` files) and `force` is false, `dir`
    /// or one of them is a link, one of them is not a regular file, `dir` holds an MCAP file
    /// of another name (another bag's, `--force` or not: a folder is one bag, and
    /// `ros2 bag reindex` would take `old_0.mcap` for part of this one), or no file can be
    /// created there
    /// ([`ratelab_core::output::check_writable`]; the folder is made).
    pub fn check(dir: &Path, force: bool) -> Result<(), Ros2Error> {
        // Never written through a link, as an output file never is (`--force` or not): the
        // bag's files would be another folder's, named for the link.
        if std::fs::symlink_metadata(dir).is_ok_and(|m| m.file_type().is_symlink()) {
            return Err(io(dir, "is a symbolic link; refusing to write through it"));
        }
        if dir.exists() && !dir.is_dir() {
            return Err(io(dir, "exists and is not a folder"));
        }
        let (mcap, meta) = Bag::files(dir);
        if dir.is_dir() {
            // No other bag's MCAP file: a folder is one bag (`ros2 bag reindex` takes each
            // `<name>_<N>.<ext>` file in it as its own), and another's beside this one would
            // be taken for part of it. Said first, as `--force` does not mend it. This
            // bag's other files (a bag rosbag2 split) are replaced as its first is.
            let this_bag = mcap.file_name().unwrap_or_default().to_string_lossy();
            // The one named when refused: the first of the split files (a folder lists its
            // files in no set order).
            let mut ours: Option<PathBuf> = None;
            Bag::each_mcap(dir, |p, own| match own {
                true => {
                    let first =
                        |a: &Path, b: &Path| (a.as_os_str().len(), a) < (b.as_os_str().len(), b);
                    if ours.as_deref().is_none_or(|o| first(p, o)) {
                        ours = Some(p.to_path_buf());
                    }
                    // A link or a folder is refused, --force or not.
                    ratelab_core::output::check_target(p, true).map_err(out)
                }
                false => Err(io(
                    p,
                    format!(
                        "an MCAP file of another bag in the folder (this one's is {this_bag}); \
                         move it away or give --bag another folder"
                    ),
                )),
            })?;
            if let Some(p) = ours.filter(|_| !force) {
                return Err(out(ratelab_core::output::OutputError::Exists(p)));
            }
        }
        for p in [&mcap, &meta] {
            ratelab_core::output::check_writable(p, force).map_err(out)?;
        }
        Ok(())
    }

    /// Start a bag in folder `dir` (made if missing) with these topics, in order. With
    /// `force`, a bag there is removed first (`metadata.yaml` and every one of its MCAP
    /// files: a run cut short then leaves no `metadata.yaml` of the old bag beside the new
    /// data, and no file of the old bag's is taken for the new one's).
    ///
    /// # Errors
    /// What [`Bag::check`] refuses, or the folder or file cannot be made.
    pub fn create(dir: &Path, force: bool, topics: &[BagTopic<'_>]) -> Result<Bag, Ros2Error> {
        Bag::check(dir, force)?;
        std::fs::create_dir_all(dir).map_err(|e| io(dir, e))?;
        let (mcap_path, meta) = Bag::files(dir);
        let remove = |p: &Path| match std::fs::remove_file(p) {
            Err(e) if e.kind() != std::io::ErrorKind::NotFound => Err(io(p, e)),
            _ => Ok(()),
        };
        remove(&meta)?;
        Bag::each_mcap(dir, |p, ours| if ours { remove(p) } else { Ok(()) })?;
        // create_new: never through a link made since the check.
        let file = std::fs::OpenOptions::new()
            .write(true)
            .create_new(true)
            .open(&mcap_path)
            .map_err(|e| io(&mcap_path, e))?;
        // mcap 0.25's writer panics when dropped after a failed write (its `finish` expects
        // the chunk the failed write took): until the bag is made, a writer that failed is
        // not dropped but forgotten (its file, and the rest of this process's life, hold
        // one descriptor), and its file removed: one line, nothing left.
        let made = mcap::WriteOptions::new()
            .profile("ros2")
            .library("ratelab")
            .create(BufWriter::new(file))
            .map_err(|e| io(&mcap_path, e))
            .map(std::mem::ManuallyDrop::new)
            .and_then(
                |mut writer| match Bag::declare(&mut writer, topics, &mcap_path) {
                    Ok(counted) => Ok((std::mem::ManuallyDrop::into_inner(writer), counted)),
                    Err(e) => Err(e),
                },
            );
        let (writer, counted) = match made {
            Ok(made) => made,
            Err(e) => {
                let _ = std::fs::remove_file(&mcap_path);
                return Err(e);
            }
        };
        Ok(Bag {
            writer,
            dir: dir.to_path_buf(),
            mcap_path,
            topics: counted,
            first_ns: None,
            last_ns: 0,
            failed: None,
            flushed: std::time::Instant::now(),
        })
    }

    /// Declare `topics` in `writer` (a schema per type, a channel per topic, with its QoS
    /// and type hash): what each is counted as.
    ///
    /// # Errors
    /// [`Ros2Error`] naming `mcap_path` when a record cannot be written.
    fn declare(
        writer: &mut mcap::Writer<BufWriter<std::fs::File>>,
        topics: &[BagTopic<'_>],
        mcap_path: &Path,
    ) -> Result<Vec<Counted>, Ros2Error> {
        let mut counted = Vec::new();
        let mut schemas: BTreeMap<&str, u16> = BTreeMap::new();
        for t in topics {
            let type_name = t.description.type_description.type_name.as_str();
            let schema_id = match schemas.get(type_name) {
                Some(id) => *id,
                None => {
                    let id = writer
                        .add_schema(type_name, "ros2msg", schema(t.description).as_bytes())
                        .map_err(|e| io(mcap_path, e))?;
                    schemas.insert(type_name, id);
                    id
                }
            };
            let qos: Vec<QosYaml> = t.qos.iter().map(QosYaml::of).collect();
            let channel = writer
                .add_channel(schema_id, t.name, "cdr", &channel_metadata(&qos, &t.hash))
                .map_err(|e| io(mcap_path, e))?;
            counted.push(Counted {
                name: t.name.to_string(),
                type_name: type_name.to_string(),
                hash: t.hash.clone(),
                qos,
                channel,
                count: 0,
            });
        }
        Ok(counted)
    }

    /// Write message `data` (CDR with its header) of topic number `topic` at run time
    /// `t_ns`.
    ///
    /// A write that fails (a full disk) is kept for [`Bag::finish`], which fails with it;
    /// nothing is written after it.
    pub fn write(&mut self, topic: usize, t_ns: u64, data: &[u8]) {
        if self.failed.is_some() {
            return;
        }
        if let Err(e) = self.write_one(topic, t_ns, data) {
            self.failed = Some(e);
        }
    }

    fn write_one(&mut self, topic: usize, t_ns: u64, data: &[u8]) -> Result<(), String> {
        let t = &mut self.topics[topic];
        let header = mcap::records::MessageHeader {
            channel_id: t.channel,
            sequence: u32::try_from(t.count).unwrap_or(u32::MAX),
            log_time: t_ns,
            publish_time: t_ns,
        };
        self.writer
            .write_to_known_channel(&header, data)
            .map_err(|e| e.to_string())?;
        t.count += 1;
        self.first_ns.get_or_insert(t_ns);
        self.last_ns = self.last_ns.max(t_ns);
        self.flush_if_due();
        Ok(())
    }

    /// Close the open chunk and write it to the file when [`FLUSH_PERIOD`] has passed since
    /// the last time: after each message, and from the bridge's loop while none comes (a
    /// run that stalls). A flush that fails is kept for [`Bag::finish`], as a write's is.
    pub fn flush_if_due(&mut self) {
        if self.failed.is_some() || self.flushed.elapsed() < FLUSH_PERIOD {
            return;
        }
        self.flushed = std::time::Instant::now();
        if let Err(e) = self.writer.flush() {
            self.failed = Some(e.to_string());
        }
    }

    /// Finish the MCAP file and write `metadata.yaml`. Returns the messages written.
    ///
    /// # Errors
    /// A write failed (here or in [`Bag::write`]): the reason, and the bag is not left under
    /// its name (its MCAP file is removed, no `metadata.yaml` is written): a bag is whole or
    /// not there.
    pub fn finish(mut self) -> Result<u64, String> {
        let finished = match self.failed.take() {
            Some(e) => Err(e),
            None => self.writer.finish().map(drop).map_err(|e| e.to_string()),
        };
        if let Err(e) = finished.and_then(|()| self.write_metadata()) {
            let _ = std::fs::remove_file(&self.mcap_path);
            return Err(format!(
                "{}: cut short ({e}); the bag was removed",
                self.dir.display()
            ));
        }
        Ok(self.topics.iter().map(|t| t.count).sum())
    }

    /// `metadata.yaml`, rosbag2's description of the bag, once the MCAP file is whole.
    fn write_metadata(&self) -> Result<(), String> {
        let start = self.first_ns.unwrap_or(0);
        let duration = self.last_ns.saturating_sub(start);
        let total: u64 = self.topics.iter().map(|t| t.count).sum();
        let file = self
            .mcap_path
            .file_name()
            .map(|n| n.to_string_lossy().into_owned())
            .unwrap_or_default();
        let meta = MetadataFile {
            rosbag2_bagfile_information: Info {
                version: 9,
                storage_identifier: "mcap",
                duration: Duration {
                    nanoseconds: duration,
                },
                starting_time: Starting {
                    nanoseconds_since_epoch: start,
                },
                message_count: total,
                topics_with_message_count: self
                    .topics
                    .iter()
                    .map(|t| TopicCount {
                        topic_metadata: TopicMeta {
                            name: t.name.clone(),
                            r#type: t.type_name.clone(),
                            serialization_format: "cdr",
                            offered_qos_profiles: t.qos.clone(),
                            type_description_hash: t.hash.clone(),
                        },
                        message_count: t.count,
                    })
                    .collect(),
                compression_format: "",
                compression_mode: "",
                relative_file_paths: vec![file.clone()],
                files: vec![FileInfo {
                    path: file,
                    starting_time: Starting {
                        nanoseconds_since_epoch: start,
                    },
                    duration: Duration {
                        nanoseconds: duration,
                    },
                    message_count: total,
                }],
                custom_data: BTreeMap::new(),
                ros_distro: "",
            },
        };
        let yaml = serde_yaml::to_string(&meta).map_err(|e| e.to_string())?;
        ratelab_core::output::write_file(&self.dir.join("metadata.yaml"), true, yaml.as_bytes())
            .map_err(|e| e.to_string())
    }
}

#[derive(Serialize)]
struct MetadataFile {
    rosbag2_bagfile_information: Info,
}

#[derive(Serialize)]
struct Info {
    version: u32,
    storage_identifier: &'static str,
    duration: Duration,
    starting_time: Starting,
    message_count: u64,
    topics_with_message_count: Vec<TopicCount>,
    compression_format: &'static str,
    compression_mode: &'static str,
    relative_file_paths: Vec<String>,
    files: Vec<FileInfo>,
    custom_data: BTreeMap<String, String>,
    ros_distro: &'static str,
}

#[derive(Serialize)]
struct Duration {
    nanoseconds: u64,
}

#[derive(Serialize)]
struct Starting {
    nanoseconds_since_epoch: u64,
}

#[derive(Serialize)]
struct TopicCount {
    topic_metadata: TopicMeta,
    message_count: u64,
}

#[derive(Serialize)]
struct TopicMeta {
    name: String,
    r#type: String,
    serialization_format: &'static str,
    offered_qos_profiles: Vec<QosYaml>,
    type_description_hash: String,
}

#[derive(Serialize)]
struct FileInfo {
    path: String,
    starting_time: Starting,
    duration: Duration,
    message_count: u64,
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_bag_is_never_written_through_a_linked_folder() {
        let tmp = tempfile::tempdir().unwrap();
        let real = tmp.path().join("bag1");
        std::fs::create_dir(&real).unwrap();
        let link = tmp.path().join("linkbag");
        std::os::unix::fs::symlink(&real, &link).unwrap();
        for force in [false, true] {
            let e = Bag::check(&link, force).unwrap_err().to_string();
            assert!(
                e.contains("linkbag: is a symbolic link; refusing to write through it"),
                "{e}"
            );
        }
        assert_eq!(
            std::fs::read_dir(&real).unwrap().count(),
            0,
            "nothing written"
        );
        Bag::check(&real, false).unwrap();
    }

    #[test]
    fn a_folder_holds_one_bag_its_split_files_replaced_with_force_and_another_bags_refused() {
        use std::os::unix::ffi::OsStrExt as _;
        let tmp = tempfile::tempdir().unwrap();
        let dir = tmp.path().join("run1");
        std::fs::create_dir(&dir).unwrap();
        let put = |name: &str| std::fs::write(dir.join(name), "old").unwrap();
        let names = || {
            let mut n: Vec<String> = std::fs::read_dir(&dir)
                .unwrap()
                .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
                .collect();
            n.sort();
            n
        };
        // A bag split in two files by rosbag2 (run1_0.mcap, run1_1.mcap), and a file of
        // the user's.
        for f in ["run1_0.mcap", "run1_1.mcap", "metadata.yaml", "notes.txt"] {
            put(f);
        }
        let e = Bag::check(&dir, false).unwrap_err().to_string();
        assert!(e.contains("run1_0.mcap") && e.contains("--force"), "{e}");
        // Its second file alone is a bag too.
        std::fs::remove_file(dir.join("run1_0.mcap")).unwrap();
        std::fs::remove_file(dir.join("metadata.yaml")).unwrap();
        let e = Bag::check(&dir, false).unwrap_err().to_string();
        assert!(e.contains("run1_1.mcap") && e.contains("--force"), "{e}");
        // With --force, every file of the old bag goes; the user's file stays.
        put("run1_0.mcap");
        put("metadata.yaml");
        Bag::create(&dir, true, &[]).unwrap().finish().unwrap();
        assert_eq!(names(), ["metadata.yaml", "notes.txt", "run1_0.mcap"]);
        assert_ne!(std::fs::read(dir.join("run1_0.mcap")).unwrap(), b"old");
        // Another bag's file (a folder renamed, names close to this bag's) is refused,
        // --force or not, and nothing is removed.
        for other in ["old_0.mcap", "run1_.mcap", "run1_x.mcap", "run10.mcap"] {
            put(other);
            for force in [false, true] {
                let e = Bag::check(&dir, force).unwrap_err().to_string();
                assert!(
                    e.ends_with(&format!(
                        "{other}: an MCAP file of another bag in the folder (this one's is \
                         run1_0.mcap); move it away or give --bag another folder"
                    )),
                    "{e}"
                );
            }
            // Nor when the bag is started: nothing of the folder's is removed.
            let before = names();
            assert!(Bag::create(&dir, true, &[]).is_err());
            assert_eq!(names(), before);
            assert!(names().contains(&other.to_string()));
            std::fs::remove_file(dir.join(other)).unwrap();
        }
        // A name that is not UTF-8 is never this bag's.
        let raw = std::ffi::OsStr::from_bytes(b"run1_\xff1.mcap");
        std::fs::write(dir.join(raw), "old").unwrap();
        let e = Bag::check(&dir, true).unwrap_err().to_string();
        assert!(e.contains("an MCAP file of another bag"), "{e}");
        std::fs::remove_file(dir.join(raw)).unwrap();
        // A folder named as this bag's file is not a file to replace.
        std::fs::create_dir(dir.join("run1_2.mcap")).unwrap();
        let e = Bag::check(&dir, true).unwrap_err().to_string();
        assert!(
            e.contains("run1_2.mcap: exists and is not a regular file"),
            "{e}"
        );
        std::fs::remove_dir(dir.join("run1_2.mcap")).unwrap();
        // A link named as this bag's file is never followed, --force or not.
        std::os::unix::fs::symlink(dir.join("notes.txt"), dir.join("run1_3.mcap")).unwrap();
        let e = Bag::check(&dir, true).unwrap_err().to_string();
        assert!(e.contains("run1_3.mcap: is a symbolic link"), "{e}");
        assert_eq!(std::fs::read(dir.join("notes.txt")).unwrap(), b"old");
    }

    #[test]
    fn a_schema_carries_the_types_it_refers_to() {
        let s = schema(&super::super::types::joint_state_type().description);
        assert!(s.starts_with("std_msgs/Header header\n"), "{s}");
        assert!(s.contains("\nMSG: std_msgs/Header\nbuiltin_interfaces/Time stamp\n"));
        assert!(s.contains("\nMSG: builtin_interfaces/Time\nint32 sec\n"));
    }

    /// Every type a bag carries has its text: the graph's types, `/clock`'s, and those of
    /// `/rosout` and `/parameter_events` with each type they refer to.
    #[test]
    fn every_bagged_type_has_its_msg_text() {
        use super::super::types::{clock_type, float64_type, image_type};
        let known = super::super::echo::known();
        let node_types = [
            "rcl_interfaces/msg/Log",
            "rcl_interfaces/msg/ParameterEvent",
        ]
        .map(|n| &known[n].description);
        let own = [
            super::super::types::joint_state_type(),
            float64_type(),
            clock_type(),
            image_type(),
        ]
        .map(|t| &t.description);
        for d in own.into_iter().chain(node_types) {
            let names = std::iter::once(&d.type_description)
                .chain(&d.referenced_type_descriptions)
                .map(|t| t.type_name.as_str());
            for name in names {
                assert!(!msg_text(name).is_empty(), "{name}");
            }
        }
        let log = schema(node_types[0]);
        assert!(log.starts_with("uint8 DEBUG=10\n"), "{log}");
        assert!(log.ends_with("\nMSG: builtin_interfaces/Time\nint32 sec\nuint32 nanosec\n"));
        let events = schema(node_types[1]);
        assert!(
            events.contains("\nMSG: rcl_interfaces/Parameter\nstring name\n"),
            "{events}"
        );
        assert!(events.contains("\nMSG: rcl_interfaces/ParameterValue\nuint8 type\n"));
    }

    /// A channel's metadata as rosbag2_storage_mcap writes it: both keys, the hash as
    /// `RIHS01_<64 hex>` (a real rosbag2 bag's `/rosout` channel: `topic_type_hash:
    /// RIHS01_e28c…8eac`, rosbag2's `rosbag2_cpp/test/rosbag2_cpp/bags/only_topics.mcap`).
    #[test]
    fn a_channel_carries_its_offered_qos_and_its_type_hash() {
        let qos = QosYaml::of(&super::super::node_api::rosout_qos());
        let meta = channel_metadata(&[qos.clone(), qos], super::super::rcl_interfaces::LOG_HASH);
        assert_eq!(
            meta.keys().collect::<Vec<_>>(),
            ["offered_qos_profiles", "topic_type_hash"]
        );
        assert_eq!(
            meta["topic_type_hash"],
            "RIHS01_e28ce254ca8abc06abf92773b74602cdbf116ed34fbaf294fb9f81da9f318eac"
        );
        let offered = &meta["offered_qos_profiles"];
        assert_eq!(
            offered.matches("- history: keep_last\n").count(),
            2,
            "{offered}"
        );
        assert!(
            offered.contains("  durability: transient_local\n"),
            "{offered}"
        );
        assert!(
            offered.contains("  lifespan:\n    sec: 10\n    nsec: 0\n"),
            "{offered}"
        );
    }
}
