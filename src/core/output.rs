//! Writing output files (`--out` metrics and trace, `--record` recordings, sweep CSV/JSON,
//! the lab's session log): one rule for every writer.
//!
//! - Never overwrite an existing file unless the user passed `--force`.
//! - Never write through a symbolic link at the final name, and never write to anything that
//!   is not a regular file (a FIFO would block the run forever, a device would swallow it),
//!   `--force` or not.
//! - Write to a temporary file in the same folder, then move it into place in one step: a
//!   reader never sees half a file, and an interrupted write never destroys the old one.
//!   Without `--force` the move is a hard link, which the kernel refuses atomically when the
//!   name is taken meanwhile; with `--force` it is a `rename`, which replaces the directory
//!   entry (a symbolic link put there meanwhile is replaced, not followed).
//! - A recording, written over a whole run, is the exception where nothing is at its name
//!   yet ([`PendingFile::create_in_place`]): it is created there at once, exclusively, and
//!   written in place, so a run killed midway (`SIGKILL`, the out-of-memory killer) leaves
//!   what it recorded under the name the user gave, as rosbag2 and rerun's own `--save` do.
//!   The file is held open and reopened only through its descriptor (`/proc/self/fd/N`),
//!   never by its name, so a link or FIFO put at the name meanwhile is never written
//!   through; a file found replaced at the end is said so. Replacing a file (`--force`)
//!   still goes through a temporary file.
//!
//! Every error is one line naming the file, with the OS's reason where there is one.

use std::io::Write;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU64, Ordering};

/// Why an output file cannot be written. One line each, naming the file.
#[derive(Debug, thiserror::Error)]
pub enum OutputError {
    /// The file exists and overwriting was not allowed.
    #[error("{0}: file exists (pass --force to overwrite)")]
    Exists(PathBuf),
    /// A symbolic link sits at the final name.
    #[error("{0}: is a symbolic link; refusing to write through it")]
    Symlink(PathBuf),
    /// Something other than a regular file sits at the final name.
    #[error("{path}: exists and is not a regular file ({kind}); refusing to write to it")]
    NotRegular {
        /// The path.
        path: PathBuf,
        /// What it is.
        kind: &'static str,
    },
    /// A file written in place ([`PendingFile::create_in_place`]) was replaced at its name
    /// (moved over, or removed) while it was written: what was written is not there.
    #[error("{0}: moved, replaced or removed by something else while it was written: the recording is not at that name")]
    Replaced(PathBuf),
    /// An I/O error while creating, writing or moving the file.
    #[error("cannot write {path}: {detail}")]
    Io {
        /// The final path.
        path: PathBuf,
        /// The OS's reason.
        detail: String,
        /// Its kind (a front end says it in its own terms: Python's `PermissionError`).
        kind: std::io::ErrorKind,
    },
}

impl OutputError {
    /// [`OutputError::Io`] for `e`, met writing `path`.
    pub fn io(path: &Path, e: &std::io::Error) -> OutputError {
        OutputError::Io {
            path: path.to_path_buf(),
            detail: e.to_string(),
            kind: e.kind(),
        }
    }
}

/// Check that `path` may be written: nothing there, or (with `force`) a regular file.
/// A symbolic link or a non-regular file is refused whatever `force` says.
///
/// # Errors
/// [`OutputError`] naming the problem.
pub fn check_target(path: &Path, force: bool) -> Result<(), OutputError> {
    match std::fs::symlink_metadata(path) {
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => Ok(()),
        Err(e) => Err(OutputError::io(path, &e)),
        Ok(m) if m.file_type().is_symlink() => Err(OutputError::Symlink(path.to_path_buf())),
        Ok(m) if !m.file_type().is_file() => Err(OutputError::NotRegular {
            path: path.to_path_buf(),
            kind: crate::input::file_kind(m.file_type()),
        }),
        Ok(_) if !force => Err(OutputError::Exists(path.to_path_buf())),
        Ok(_) => Ok(()),
    }
}

/// Check that `path` can be written now, before a long run rather than after it:
/// [`check_target`], then a temporary file created beside it (its folder made if missing,
/// as writing it will) and removed at once. The final name is never touched. A folder that
/// takes no files (`/proc`, one read-only or full of inodes) is refused here, not when the
/// run's figures are to be written.
///
/// # Errors
/// [`OutputError`] from the check or the creation.
pub fn check_writable(path: &Path, force: bool) -> Result<(), OutputError> {
    let (pending, _file) = PendingFile::create(path, force)?;
    drop(pending); // removes the probe
    Ok(())
}

/// A temporary file beside its final name, moved into place by [`PendingFile::commit`]
/// and removed if dropped uncommitted; or a new file written at its final name
/// ([`PendingFile::create_in_place`]).
#[derive(Debug)]
pub struct PendingFile {
    /// Where the file is written: beside `dest`, or `dest` itself when written in place.
    tmp: PathBuf,
    dest: PathBuf,
    force: bool,
    done: bool,
    /// Written at `dest` from the start: the file, held open (what is at `dest` is checked
    /// against it, and a writer reopens it by its descriptor); committing moves nothing.
    in_place: Option<std::fs::File>,
}

impl PendingFile {
    /// Check `dest` ([`check_target`]), create its folder, and create a new, empty
    /// temporary file beside it (`.<name>.<pid>-<n>.tmp`, created exclusively).
    ///
    /// # Errors
    /// [`OutputError`] from the check or the creation.
    pub fn create(dest: &Path, force: bool) -> Result<(Self, std::fs::File), OutputError> {
        Self::create_with_mode(dest, force, 0o666)
    }

    /// [`PendingFile::create`], the temporary file created with permission bits `mode`
    /// (less the process's umask): `0o600` for a secret, which no other user may read at
    /// any moment.
    ///
    /// # Errors
    /// [`OutputError`] from the check or the creation.
    pub fn create_with_mode(
        dest: &Path,
        force: bool,
        mode: u32,
    ) -> Result<(Self, std::fs::File), OutputError> {
        use std::os::unix::fs::OpenOptionsExt as _;
        static COUNTER: AtomicU64 = AtomicU64::new(0);
        check_target(dest, force)?;
        let (name, dir) = name_and_folder(dest)?;
        std::fs::create_dir_all(&dir).map_err(|e| OutputError::io(dest, &e))?;
        let tmp = dir.join(format!(
            ".{name}.{}-{}.tmp",
            std::process::id(),
            COUNTER.fetch_add(1, Ordering::Relaxed)
        ));
        let file = std::fs::OpenOptions::new()
            .write(true)
            .create_new(true)
            .mode(mode)
            .open(&tmp)
            .map_err(|e| OutputError::io(dest, &e))?;
        Ok((
            Self {
                tmp,
                dest: dest.to_path_buf(),
                force,
                done: false,
                in_place: None,
            },
            file,
        ))
    }

    /// [`PendingFile::create`] for a file written over a long time that should outlive a
    /// writer killed midway (a recording). Where nothing is at `dest`, the file is created
    /// there at once, exclusively, and written in place: whatever was written before a
    /// `SIGKILL` is at the name the user gave, and [`PendingFile::commit`] moves nothing (it
    /// checks that the name is still this file's). A writer that opens the file itself
    /// opens [`PendingFile::write_path`], never the name. Where a regular file is there
    /// (`force`), or one appears there meanwhile (`force`), it is written beside and moved
    /// into place, as [`PendingFile::create`] does, so the old file stays whole until the
    /// new one is.
    ///
    /// # Errors
    /// [`OutputError`] from the check or the creation ([`OutputError::Exists`] when the name
    /// is taken between the two without `force`).
    pub fn create_in_place(dest: &Path, force: bool) -> Result<(Self, std::fs::File), OutputError> {
        check_target(dest, force)?;
        let (_, dir) = name_and_folder(dest)?;
        std::fs::create_dir_all(&dir).map_err(|e| OutputError::io(dest, &e))?;
        // create_new: never through a link or FIFO, nor over a file, put there since the check.
        let file = match std::fs::OpenOptions::new()
            .write(true)
            .create_new(true)
            .open(dest)
        {
            Ok(f) => f,
            Err(e) if e.kind() == std::io::ErrorKind::AlreadyExists && force => {
                // A file there (found by the check, or put there since): replaced, written
                // beside and moved into place.
                return Self::create(dest, force);
            }
            Err(e) if e.kind() == std::io::ErrorKind::AlreadyExists => {
                return Err(OutputError::Exists(dest.to_path_buf()));
            }
            Err(e) => return Err(OutputError::io(dest, &e)),
        };
        let held = file.try_clone().map_err(|e| OutputError::io(dest, &e))?;
        Ok((
            Self {
                tmp: dest.to_path_buf(),
                dest: dest.to_path_buf(),
                force,
                done: false,
                in_place: Some(held),
            },
            file,
        ))
    }

    /// The path a writer that opens the file itself (rerun's file sink) should open: the
    /// temporary file; for a file written in place, the open file through its descriptor
    /// (`/proc/self/fd/N`, Linux's name for exactly that file), so that whatever is put at
    /// the final name meanwhile (a link, a FIFO, another file) is never opened. Without
    /// `/proc`, the final name itself.
    pub fn write_path(&self) -> PathBuf {
        use std::os::fd::AsRawFd as _;
        match &self.in_place {
            Some(f) => {
                let by_fd = PathBuf::from(format!("/proc/self/fd/{}", f.as_raw_fd()));
                if by_fd.exists() {
                    by_fd
                } else {
                    self.dest.clone()
                }
            }
            None => self.tmp.clone(),
        }
    }

    /// Written in place: whether the final name still holds this file (the same device and
    /// inode, not through a link); `Ok(false)` when nothing is there.
    ///
    /// # Errors
    /// The OS's, when what is at the name cannot be looked at (a folder made unreadable).
    fn still_ours(&self) -> std::io::Result<bool> {
        use std::os::unix::fs::MetadataExt as _;
        let Some(f) = &self.in_place else {
            return Ok(false);
        };
        let ours = f.metadata()?;
        match std::fs::symlink_metadata(&self.dest) {
            Ok(there) => Ok(ours.dev() == there.dev() && ours.ino() == there.ino()),
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => Ok(false),
            Err(e) => Err(e),
        }
    }

    /// The file's path while it is written (for writers that open the file themselves): a
    /// temporary name beside the final one, or the final one when written in place.
    pub fn temp_path(&self) -> &Path {
        &self.tmp
    }

    /// The final path.
    pub fn path(&self) -> &Path {
        &self.dest
    }

    /// Move the temporary file to its final name (see the module's rule); a file written in
    /// place is where it belongs, and only checked. Committing twice does nothing.
    ///
    /// # Errors
    /// [`OutputError`]: the name was taken meanwhile (without `force`), a link or
    /// non-regular file appeared there, or the move failed; the temporary file is removed.
    /// Written in place: [`OutputError::Replaced`] when the name no longer holds the file.
    pub fn commit(&mut self) -> Result<(), OutputError> {
        if self.done {
            return Ok(());
        }
        self.done = true;
        if self.in_place.is_some() {
            return match self.still_ours() {
                Ok(true) => Ok(()),
                Ok(false) => Err(OutputError::Replaced(self.dest.clone())),
                Err(e) => Err(OutputError::io(&self.dest, &e)),
            };
        }
        let result = self.move_into_place();
        let _ = std::fs::remove_file(&self.tmp);
        result
    }

    fn move_into_place(&self) -> Result<(), OutputError> {
        check_target(&self.dest, self.force)?;
        if self.force {
            return std::fs::rename(&self.tmp, &self.dest)
                .map_err(|e| OutputError::io(&self.dest, &e));
        }
        match std::fs::hard_link(&self.tmp, &self.dest) {
            Ok(()) => Ok(()),
            Err(e) if e.kind() == std::io::ErrorKind::AlreadyExists => {
                Err(OutputError::Exists(self.dest.clone()))
            }
            // A file system without hard links: checked just above, rename.
            Err(e) if matches!(e.raw_os_error(), Some(libc::EPERM | libc::EOPNOTSUPP)) => {
                std::fs::rename(&self.tmp, &self.dest).map_err(|e| OutputError::io(&self.dest, &e))
            }
            Err(e) => Err(OutputError::io(&self.dest, &e)),
        }
    }
}

/// `dest`'s file name and its folder (`.` for a bare name).
///
/// # Errors
/// [`OutputError::Io`] when `dest` names no file (`/`, `..`).
fn name_and_folder(dest: &Path) -> Result<(String, PathBuf), OutputError> {
    let name = dest
        .file_name()
        .ok_or_else(|| OutputError::Io {
            path: dest.to_path_buf(),
            detail: "not a file name".into(),
            kind: std::io::ErrorKind::InvalidInput,
        })?
        .to_string_lossy()
        .into_owned();
    let dir = match dest.parent() {
        Some(p) if !p.as_os_str().is_empty() => p.to_path_buf(),
        _ => PathBuf::from("."),
    };
    Ok((name, dir))
}

impl Drop for PendingFile {
    fn drop(&mut self) {
        // Written in place: removed only while the name still holds this file, never
        // whatever was put there since.
        if !self.done && (self.in_place.is_none() || self.still_ours().unwrap_or(false)) {
            let _ = std::fs::remove_file(&self.tmp);
        }
    }
}

/// Write `path` through a temporary file by calling `fill` on a buffered writer, then move
/// it into place (the module's rule; `force` allows replacing an existing regular file).
///
/// # Errors
/// [`OutputError`] naming `path`; an error from `fill` is reported with the path too.
pub fn write_with(
    path: &Path,
    force: bool,
    fill: impl FnOnce(&mut dyn Write) -> std::io::Result<()>,
) -> Result<(), OutputError> {
    write_with_mode(path, force, 0o666, fill)
}

fn write_with_mode(
    path: &Path,
    force: bool,
    mode: u32,
    fill: impl FnOnce(&mut dyn Write) -> std::io::Result<()>,
) -> Result<(), OutputError> {
    let (mut pending, file) = PendingFile::create_with_mode(path, force, mode)?;
    let mut w = std::io::BufWriter::new(file);
    fill(&mut w)
        .and_then(|()| w.flush())
        .map_err(|e| OutputError::io(path, &e))?;
    let file = w
        .into_inner()
        .map_err(|e| OutputError::io(path, e.error()))?;
    file.sync_all().map_err(|e| OutputError::io(path, &e))?;
    drop(file);
    pending.commit()
}

/// Write `bytes` to `path` by [`write_with`].
///
/// # Errors
/// As [`write_with`].
pub fn write_file(path: &Path, force: bool, bytes: &[u8]) -> Result<(), OutputError> {
    write_with(path, force, |w| w.write_all(bytes))
}

/// Write a secret (a private key, credentials) to `path` by [`write_with`]'s rule, readable
/// and writable by its owner alone (mode `0o600` from the moment it exists).
///
/// # Errors
/// As [`write_with`].
pub fn write_private(path: &Path, force: bool, bytes: &[u8]) -> Result<(), OutputError> {
    write_with_mode(path, force, 0o600, |w| w.write_all(bytes))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn scratch(name: &str) -> PathBuf {
        let d = std::env::temp_dir().join(format!("ratelab-output-{name}-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&d);
        std::fs::create_dir_all(&d).unwrap();
        d
    }

    #[test]
    fn never_overwrites_without_force_and_never_follows_links() {
        let d = scratch("rule");
        let f = d.join("out.json");
        write_file(&f, false, b"one").unwrap();
        assert!(matches!(
            write_file(&f, false, b"two"),
            Err(OutputError::Exists(_))
        ));
        assert_eq!(std::fs::read(&f).unwrap(), b"one");
        write_file(&f, true, b"three").unwrap();
        assert_eq!(std::fs::read(&f).unwrap(), b"three");
        let victim = d.join("victim");
        std::fs::write(&victim, b"canary").unwrap();
        let link = d.join("link.json");
        std::os::unix::fs::symlink(&victim, &link).unwrap();
        for force in [false, true] {
            assert!(matches!(
                write_file(&link, force, b"x"),
                Err(OutputError::Symlink(_))
            ));
        }
        assert_eq!(std::fs::read(&victim).unwrap(), b"canary");
        assert!(matches!(
            write_file(&d, true, b"x"),
            Err(OutputError::NotRegular { .. })
        ));
        // No temporary file is left behind by any of it.
        let left: Vec<_> = std::fs::read_dir(&d)
            .unwrap()
            .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
            .filter(|n| n.ends_with(".tmp"))
            .collect();
        assert!(left.is_empty(), "{left:?}");
        std::fs::remove_dir_all(&d).unwrap();
    }

    #[test]
    fn write_errors_name_the_file_and_leave_nothing() {
        let d = scratch("fail");
        let f = d.join("table.csv");
        let e = write_with(&f, false, |_| {
            Err(std::io::Error::from_raw_os_error(libc::ENOSPC))
        })
        .unwrap_err()
        .to_string();
        assert!(
            e.contains("table.csv") && e.contains("No space left on device"),
            "{e}"
        );
        assert_eq!(std::fs::read_dir(&d).unwrap().count(), 0);
        let e = write_file(Path::new("/proc/ratelab-denied/x.json"), false, b"x")
            .unwrap_err()
            .to_string();
        assert!(
            e.starts_with("cannot write /proc/ratelab-denied/x.json: "),
            "{e}"
        );
        std::fs::remove_dir_all(&d).unwrap();
    }

    #[test]
    fn a_name_taken_meanwhile_is_not_replaced() {
        let d = scratch("race");
        let f = d.join("rec.rrd");
        let (mut pending, _file) = PendingFile::create(&f, false).unwrap();
        std::fs::write(&f, b"someone else's").unwrap();
        assert!(matches!(pending.commit(), Err(OutputError::Exists(_))));
        assert_eq!(std::fs::read(&f).unwrap(), b"someone else's");
        assert!(!pending.temp_path().exists());
        std::fs::remove_dir_all(&d).unwrap();
    }

    /// A recording where nothing is at its name is written there from the start (a writer
    /// killed midway leaves it under that name) and is never moved; a second writer of
    /// the same name is refused; a file replaced (`--force`) is written beside and the old
    /// one stays whole until the new one is committed; links and folders are refused.
    #[test]
    fn a_new_recording_is_written_in_place_and_a_replaced_one_beside() {
        let d = scratch("in-place");
        let f = d.join("sub").join("rec.rrd");
        let (mut pending, mut file) = PendingFile::create_in_place(&f, false).unwrap();
        assert_eq!(pending.temp_path(), f, "written at its name");
        file.write_all(b"part").unwrap();
        assert_eq!(
            std::fs::read(&f).unwrap(),
            b"part",
            "there before it is finished"
        );
        for force in [false, true] {
            // The name is taken now (by the file being written): without --force refused;
            // with it, beside.
            let other = PendingFile::create_in_place(&f, force);
            if force {
                let (p, _) = other.unwrap();
                assert_ne!(p.temp_path(), f);
            } else {
                assert!(matches!(other, Err(OutputError::Exists(_))));
            }
        }
        drop(file);
        pending.commit().unwrap();
        pending.commit().unwrap();
        assert_eq!(std::fs::read(&f).unwrap(), b"part");
        // Replaced with --force: the old file is whole until the new one is moved there.
        let (mut pending, mut file) = PendingFile::create_in_place(&f, true).unwrap();
        file.write_all(b"new").unwrap();
        assert_eq!(std::fs::read(&f).unwrap(), b"part");
        drop(file);
        pending.commit().unwrap();
        assert_eq!(std::fs::read(&f).unwrap(), b"new");
        let link = d.join("link.rrd");
        std::os::unix::fs::symlink(&f, &link).unwrap();
        for force in [false, true] {
            assert!(matches!(
                PendingFile::create_in_place(&link, force),
                Err(OutputError::Symlink(_))
            ));
            assert!(matches!(
                PendingFile::create_in_place(&d, force),
                Err(OutputError::NotRegular { .. })
            ));
        }
        assert_eq!(std::fs::read(&f).unwrap(), b"new");
        let left: Vec<_> = std::fs::read_dir(d.join("sub"))
            .unwrap()
            .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
            .collect();
        assert_eq!(left, ["rec.rrd"], "no temporary file left");
        std::fs::remove_dir_all(&d).unwrap();
    }

    /// A file written in place is reopened by its descriptor, never by its name: a link
    /// put at the name while it is written is not written through, and the end says the
    /// file was replaced (and removes nothing that is not the file). Moved over by another
    /// file: said at the end, the other file kept.
    #[test]
    fn a_file_written_in_place_is_never_reopened_by_its_name() {
        let d = scratch("by-fd");
        let f = d.join("rec.rrd");
        let victim = d.join("victim");
        std::fs::write(&victim, b"canary").unwrap();
        let (mut pending, _file) = PendingFile::create_in_place(&f, false).unwrap();
        let by = pending.write_path();
        assert!(by.starts_with("/proc/self/fd/"), "{}", by.display());
        // Someone puts a link at the name; the writer then opens its path (as rerun does,
        // `File::create`: truncating, following links).
        std::fs::rename(&f, d.join("moved-away.rrd")).unwrap();
        std::os::unix::fs::symlink(&victim, &f).unwrap();
        std::fs::File::create(&by)
            .unwrap()
            .write_all(b"rows")
            .unwrap();
        assert_eq!(
            std::fs::read(&victim).unwrap(),
            b"canary",
            "never through the link"
        );
        assert_eq!(std::fs::read(d.join("moved-away.rrd")).unwrap(), b"rows");
        assert!(matches!(pending.commit(), Err(OutputError::Replaced(_))));
        assert!(std::fs::symlink_metadata(&f)
            .unwrap()
            .file_type()
            .is_symlink());
        // Dropped uncommitted with another file at its name: that file is left alone.
        std::fs::remove_file(&f).unwrap();
        let (pending, _file) = PendingFile::create_in_place(&f, false).unwrap();
        std::fs::write(d.join("other"), b"theirs").unwrap();
        std::fs::rename(d.join("other"), &f).unwrap();
        drop(pending);
        assert_eq!(std::fs::read(&f).unwrap(), b"theirs");
        // Dropped uncommitted while the name still holds it: removed, as a temporary file is.
        std::fs::remove_file(&f).unwrap();
        let (pending, _file) = PendingFile::create_in_place(&f, false).unwrap();
        drop(pending);
        assert!(!f.exists());
        std::fs::remove_dir_all(&d).unwrap();
    }
}
