//! Where this user's launch listens: `ratelab launch --processes` records its endpoint in a
//! file of the user's own (`$XDG_RUNTIME_DIR/ratelab/launch`, else
//! `~/.cache/ratelab/launch`), and `ratelab lab --attach` and `ratelab top` look there when
//! no `--connect` is given, so they find this user's launch on whatever port it got (7449
//! when free, another when not), and not another user's on 7449.
//!
//! The file is one line, `ENDPOINT PID`. It is read as untrusted input: at most 256 bytes,
//! the endpoint checked as `--connect` checks it, and a record whose process is gone (a
//! launch killed before it could remove it) is ignored.
//!
//! Beside it, `launch-credentials.toml` (mode 600) holds the launch's observer identity
//! ([`ratelab::distributed::credentials`]), so that this user's watchers join the launch's
//! authenticated graph without `--credentials`; it goes with the record.

use ratelab::distributed::check_endpoint;
use ratelab::distributed::credentials::Credentials;
use std::path::{Path, PathBuf};

/// The largest record read, bytes.
const MAX_RECORD_BYTES: u64 = 256;

/// The record's path, if the user has a runtime or home folder.
pub fn record_path() -> Option<PathBuf> {
    let dir = std::env::var_os("XDG_RUNTIME_DIR")
        .filter(|d| !d.is_empty())
        .map(PathBuf::from)
        .or_else(|| {
            std::env::var_os("HOME")
                .filter(|d| !d.is_empty())
                .map(|h| PathBuf::from(h).join(".cache"))
        })?;
    Some(dir.join("ratelab").join("launch"))
}

/// The observer credentials' path beside `record`.
fn credentials_path(record: &Path) -> PathBuf {
    record.with_file_name("launch-credentials.toml")
}

/// This process's launch, recorded while it lives: dropping it removes the record and its
/// credentials (unless a later launch has replaced them).
pub struct Recorded {
    path: PathBuf,
    line: String,
}

impl Drop for Recorded {
    fn drop(&mut self) {
        if std::fs::read_to_string(&self.path).is_ok_and(|l| l == self.line) {
            let _ = std::fs::remove_file(&self.path);
            let _ = std::fs::remove_file(credentials_path(&self.path));
        }
    }
}

/// Record that this process's launch listens on `endpoint`, with `observer` (the launch's
/// credentials holding the observer's identity alone). Best effort: a launch runs without
/// the record (say so in `warn`) when the folder cannot be written.
pub fn record(
    endpoint: &str,
    observer: &Credentials,
    warn: &mut dyn FnMut(String),
) -> Option<Recorded> {
    let path = record_path()?;
    let line = format!("{endpoint} {}\n", std::process::id());
    let write = || -> std::io::Result<()> {
        let dir = path.parent().expect("a file in a folder");
        std::fs::create_dir_all(dir)?;
        // The credentials first: a watcher that finds the record finds them too.
        observer
            .write(&credentials_path(&path), true)
            .map_err(std::io::Error::other)?;
        // Written beside and moved into place: a reader never sees half a line.
        let tmp = dir.join(format!(".launch.{}", std::process::id()));
        std::fs::write(&tmp, &line)?;
        std::fs::rename(&tmp, &path)
    };
    match write() {
        Ok(()) => Some(Recorded { path, line }),
        Err(e) => {
            warn(format!(
                "cannot record this launch in {} ({e}): `lab --attach` and `top` need --connect {endpoint}",
                path.display()
            ));
            None
        }
    }
}

/// The endpoint of this user's running launch, if one is recorded and its process lives.
pub fn find() -> Option<String> {
    let path = record_path()?;
    let bytes = ratelab::input::read_regular_file(&path, MAX_RECORD_BYTES).ok()?;
    parse(&String::from_utf8(bytes).ok()?)
        .filter(|(_, pid)| std::path::Path::new(&format!("/proc/{pid}")).exists())
        .map(|(ep, _)| ep)
}

/// A record's endpoint and process id, if it is one well-formed line.
fn parse(text: &str) -> Option<(String, u32)> {
    let mut parts = text.trim_end_matches('\n').split(' ');
    let (ep, pid) = (parts.next()?, parts.next()?.parse::<u32>().ok()?);
    if parts.next().is_some() || check_endpoint("--connect", ep, false).is_err() {
        return None;
    }
    Some((ep.to_string(), pid))
}

/// The credentials `lab --attach` and `top` join with: `given` (`--credentials FILE`), else
/// those of this user's recorded launch.
///
/// # Errors
/// One line: the file is bad, or none is given and no launch of this user's is recorded.
pub fn credentials(given: Option<&Path>) -> anyhow::Result<Credentials> {
    if let Some(f) = given {
        return Ok(Credentials::load(f)?);
    }
    let recorded = record_path()
        .filter(|_| find().is_some())
        .map(|p| credentials_path(&p))
        .filter(|p| p.exists());
    match recorded {
        Some(p) => Ok(Credentials::load(&p)?),
        None => anyhow::bail!(
            "no launch of yours is running on this host to watch: give --credentials FILE (written by `ratelab launch --processes --export-credentials FILE`)"
        ),
    }
}

/// Where `lab --attach` and `top` connect: `connect` when given, else this user's recorded
/// launch, else the default endpoint; with what to say when nothing answers there.
pub fn endpoints(connect: &[String]) -> (Vec<String>, String) {
    if !connect.is_empty() {
        return (connect.to_vec(), "check the endpoint".to_string());
    }
    match find() {
        Some(ep) => (
            vec![ep],
            "this user's launch was recorded there; is it still starting?".to_string(),
        ),
        None => (
            vec![ratelab::distributed::DEFAULT_ENDPOINT.to_string()],
            "no launch of yours is recorded: start one with `ratelab launch --processes`, or \
             give --connect tls/HOST:PORT"
                .to_string(),
        ),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn records_are_one_checked_line() {
        assert_eq!(
            parse("tls/127.0.0.1:7449 42\n"),
            Some(("tls/127.0.0.1:7449".into(), 42))
        );
        for bad in [
            "",
            "tls/127.0.0.1:7449",
            "tls/127.0.0.1:7449 x",
            "tls/127.0.0.1:7449 42 43",
            "udp/127.0.0.1:7449 42",
            "tcp/127.0.0.1:7449 42",
            "tls/127.0.0.1:99999 42",
        ] {
            assert_eq!(parse(bad), None, "{bad:?}");
        }
    }
}
