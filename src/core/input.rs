//! Reading input files the user names (checkpoints, exercise files): regular files only,
//! with a size cap, and one-line errors that name the path and keep the OS's reason.
//!
//! A FIFO, a device (`/dev/zero`) or a folder is refused before a single byte is read: the
//! file is opened with `O_NONBLOCK` (so opening a FIFO with no writer cannot hang) and
//! checked with `fstat` on the open descriptor (so a swap between check and read cannot
//! slip a FIFO in). The read itself stops one byte past the cap, whatever the file claims.
//!
//! A stream read a line at a time (another process's stderr) is read in bounded lines:
//! [`read_line_bounded`]. A file that must be text and is not says where it stops being
//! UTF-8 ([`utf8_text`]), so a stray byte can be found in a long file.

use std::io::Read;
use std::os::unix::fs::OpenOptionsExt;
use std::path::{Path, PathBuf};

/// Why an input file cannot be read. One line each, naming the file.
#[derive(Debug, thiserror::Error, PartialEq, Eq)]
pub enum InputError {
    /// The path does not exist.
    #[error("{0}: not found")]
    NotFound(PathBuf),
    /// The OS refused access (permissions), as opposed to a missing file.
    #[error("{0}: permission denied")]
    PermissionDenied(PathBuf),
    /// The path exists but is not a regular file (folder, FIFO, device, socket).
    #[error("{path}: not a regular file ({kind})")]
    NotRegular {
        /// The path.
        path: PathBuf,
        /// What it is instead.
        kind: &'static str,
    },
    /// The file is larger than the cap for its kind.
    #[error("{path}: too large ({size} bytes; at most {max} bytes are read)")]
    TooLarge {
        /// The path.
        path: PathBuf,
        /// Its size in bytes (at least `max + 1`).
        size: u64,
        /// The cap in bytes.
        max: u64,
    },
    /// Any other I/O error, with the OS's reason.
    #[error("{path}: {detail}")]
    Io {
        /// The path.
        path: PathBuf,
        /// The OS's reason.
        detail: String,
    },
}

/// A one-line description of a file type that is not a regular file.
pub fn file_kind(ft: std::fs::FileType) -> &'static str {
    use std::os::unix::fs::FileTypeExt;
    if ft.is_dir() {
        "a folder"
    } else if ft.is_fifo() {
        "a FIFO"
    } else if ft.is_char_device() {
        "a character device"
    } else if ft.is_block_device() {
        "a block device"
    } else if ft.is_socket() {
        "a socket"
    } else if ft.is_symlink() {
        "a symbolic link"
    } else if ft.is_file() {
        "a regular file"
    } else {
        "not a regular file"
    }
}

/// Map an I/O error on `path` to an [`InputError`] that keeps its point (missing versus
/// forbidden versus anything else).
pub fn io_error(path: &Path, e: &std::io::Error) -> InputError {
    match e.kind() {
        std::io::ErrorKind::NotFound => InputError::NotFound(path.to_path_buf()),
        std::io::ErrorKind::PermissionDenied => InputError::PermissionDenied(path.to_path_buf()),
        _ => InputError::Io {
            path: path.to_path_buf(),
            detail: e.to_string(),
        },
    }
}

/// Read all of `path`, which must be a regular file of at most `max_bytes` bytes.
///
/// # Errors
/// [`InputError`]: missing, not permitted, not a regular file, larger than `max_bytes`
/// (checked on the descriptor and again while reading, so a growing file is caught too),
/// or another I/O error.
pub fn read_regular_file(path: &Path, max_bytes: u64) -> Result<Vec<u8>, InputError> {
    let file = std::fs::OpenOptions::new()
        .read(true)
        .custom_flags(libc::O_NONBLOCK | libc::O_NOCTTY)
        .open(path)
        .map_err(|e| io_error(path, &e))?;
    let meta = file.metadata().map_err(|e| io_error(path, &e))?;
    if !meta.file_type().is_file() {
        return Err(InputError::NotRegular {
            path: path.to_path_buf(),
            kind: file_kind(meta.file_type()),
        });
    }
    if meta.len() > max_bytes {
        return Err(InputError::TooLarge {
            path: path.to_path_buf(),
            size: meta.len(),
            max: max_bytes,
        });
    }
    let mut bytes = Vec::with_capacity(usize::try_from(meta.len()).unwrap_or(0));
    file.take(max_bytes.saturating_add(1))
        .read_to_end(&mut bytes)
        .map_err(|e| io_error(path, &e))?;
    if bytes.len() as u64 > max_bytes {
        return Err(InputError::TooLarge {
            path: path.to_path_buf(),
            size: bytes.len() as u64,
            max: max_bytes,
        });
    }
    Ok(bytes)
}

/// Where a file's bytes stop being UTF-8 text: the first byte that is not, its 1-based line
/// and its 1-based column (characters of valid text before it on its line, plus one).
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
#[error("not UTF-8 text (byte {byte:#04x} at line {line}, column {col})")]
pub struct NotUtf8 {
    /// The first byte that is not UTF-8 (of a sequence cut short or broken: its first).
    pub byte: u8,
    /// Its line, from 1.
    pub line: usize,
    /// Its column on that line, in characters, from 1.
    pub col: usize,
}

/// `bytes` as text, or where they stop being UTF-8.
///
/// # Errors
/// [`NotUtf8`] at the first byte that is not.
pub fn utf8_text(bytes: Vec<u8>) -> Result<String, NotUtf8> {
    String::from_utf8(bytes).map_err(|e| {
        let at = e.utf8_error().valid_up_to();
        not_utf8(e.as_bytes(), at)
    })
}

/// [`utf8_text`] for borrowed bytes.
///
/// # Errors
/// As [`utf8_text`].
pub fn utf8_str(bytes: &[u8]) -> Result<&str, NotUtf8> {
    std::str::from_utf8(bytes).map_err(|e| not_utf8(bytes, e.valid_up_to()))
}

/// The place of `bytes[at]`, the first byte that is not UTF-8 (`bytes[..at]` is).
fn not_utf8(bytes: &[u8], at: usize) -> NotUtf8 {
    let valid = std::str::from_utf8(&bytes[..at]).unwrap_or_default();
    let line_start = valid.rfind('\n').map_or(0, |i| i + 1);
    NotUtf8 {
        byte: bytes.get(at).copied().unwrap_or_default(),
        line: valid.matches('\n').count() + 1,
        col: valid[line_start..].chars().count() + 1,
    }
}

/// Read the next line of `r` into `buf` (cleared first), at most `max` bytes of it with
/// its `\n` when that fits; the rest of a longer line is skipped without being held. So a
/// stream that never ends a line costs `max` bytes, not all it sends. `Ok(false)` at the
/// end of the stream; a last line without `\n` is a line.
///
/// # Errors
/// The stream's, reading the line (an error while skipping a long line's rest is left to
/// the next read).
pub fn read_line_bounded(
    r: &mut impl std::io::BufRead,
    max: usize,
    buf: &mut Vec<u8>,
) -> std::io::Result<bool> {
    use std::io::BufRead;
    buf.clear();
    if std::io::Read::take(&mut *r, max as u64).read_until(b'\n', buf)? == 0 {
        return Ok(false);
    }
    if buf.last() != Some(&b'\n') {
        let _ = r.skip_until(b'\n');
    }
    Ok(true)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A file that stops being UTF-8 says where: the byte, its line and its column in
    /// characters (a multi-byte character before it on its line counts once).
    #[test]
    fn text_that_is_not_utf8_says_where() {
        assert_eq!(utf8_text(b"a\nb".to_vec()).unwrap(), "a\nb");
        let e = utf8_text(b"name = \"\xff\"\n".to_vec()).unwrap_err();
        assert_eq!((e.byte, e.line, e.col), (0xff, 1, 9));
        assert_eq!(
            e.to_string(),
            "not UTF-8 text (byte 0xff at line 1, column 9)"
        );
        let e = utf8_str(
            "one\ntwo\nθ = "
                .as_bytes()
                .iter()
                .chain(b"\xfe")
                .copied()
                .collect::<Vec<_>>()
                .as_slice(),
        )
        .unwrap_err();
        assert_eq!((e.byte, e.line, e.col), (0xfe, 3, 5));
        // A sequence cut short by the end of the file: where it starts.
        let e = utf8_str(b"ok\n\xe2\x82").unwrap_err();
        assert_eq!((e.byte, e.line, e.col), (0xe2, 2, 1));
        assert_eq!(utf8_str(b"\x80").unwrap_err().col, 1);
    }

    #[test]
    fn a_line_is_read_to_its_bound_and_its_rest_skipped() {
        let text = format!("one\n{}\nthree", "y".repeat(100));
        let mut r = std::io::BufReader::with_capacity(8, text.as_bytes());
        let mut buf = Vec::new();
        let mut lines = Vec::new();
        while read_line_bounded(&mut r, 10, &mut buf).unwrap() {
            lines.push(String::from_utf8(buf.clone()).unwrap());
        }
        assert_eq!(lines, ["one\n", &"y".repeat(10), "three"]);
    }

    #[test]
    fn refuses_what_is_not_a_small_regular_file() {
        let dir = std::env::temp_dir().join(format!("ratelab-input-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let f = dir.join("f.bin");
        std::fs::write(&f, [7u8; 10]).unwrap();
        assert_eq!(read_regular_file(&f, 10).unwrap(), vec![7u8; 10]);
        assert!(matches!(
            read_regular_file(&f, 9),
            Err(InputError::TooLarge {
                size: 10,
                max: 9,
                ..
            })
        ));
        assert!(matches!(
            read_regular_file(&dir, 9),
            Err(InputError::NotRegular {
                kind: "a folder",
                ..
            })
        ));
        assert!(matches!(
            read_regular_file(Path::new("/dev/zero"), 1 << 20),
            Err(InputError::NotRegular {
                kind: "a character device",
                ..
            })
        ));
        let fifo = dir.join("fifo");
        let c = std::ffi::CString::new(fifo.to_str().unwrap()).unwrap();
        // SAFETY: a valid NUL-terminated path.
        assert_eq!(unsafe { libc::mkfifo(c.as_ptr(), 0o600) }, 0);
        assert!(matches!(
            read_regular_file(&fifo, 10),
            Err(InputError::NotRegular { kind: "a FIFO", .. })
        ));
        assert_eq!(
            read_regular_file(&dir.join("missing"), 10),
            Err(InputError::NotFound(dir.join("missing")))
        );
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn forbidden_is_not_reported_as_missing() {
        // Built from the error kind: a test run as root could not be denied a real file.
        let p = Path::new("/x/brain.pt");
        let denied = std::io::Error::from(std::io::ErrorKind::PermissionDenied);
        assert_eq!(
            io_error(p, &denied).to_string(),
            "/x/brain.pt: permission denied"
        );
        let missing = std::io::Error::from(std::io::ErrorKind::NotFound);
        assert_eq!(io_error(p, &missing).to_string(), "/x/brain.pt: not found");
        let other = std::io::Error::from_raw_os_error(libc::EIO);
        let text = io_error(p, &other).to_string();
        assert!(
            text.starts_with("/x/brain.pt: ") && text.contains("os error 5"),
            "{text}"
        );
    }
}
