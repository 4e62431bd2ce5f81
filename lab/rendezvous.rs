//! Where this user's launches listen: `ratelab launch --processes` records its endpoint in a
//! file of the user's own (`$XDG_RUNTIME_DIR/ratelab/launch.<pid>`, else
//! `~/.cache/ratelab/launch.<pid>`), and `ratelab lab --attach` and `ratelab top` look there
//! when no `--connect` is given, so they find this user's launch on whatever port it got
//! (7449 when free, another when not), and not another user's on 7449. With two launches of
//! the user running, neither is guessed: both are listed, and `--connect` chooses.
//!
//! Each record is one line, `ENDPOINT PID`. It is read as untrusted input: at most 256 bytes,
//! the endpoint checked as `--connect` checks it, at most [`MAX_RECORDS`] records looked at,
//! and a record whose process is gone (a launch killed before it could remove it) is
//! ignored.
//!
//! Beside each, `launch-credentials.<pid>.toml` (mode 600) holds that launch's observer
//! identity ([`ratelab::distributed::credentials`]), so that this user's watchers join the
//! launch's authenticated graph without `--credentials`; it goes with the record. The
//! credentials a watcher uses are always those of the launch it connects to.

use ratelab::distributed::check_endpoint;
use ratelab::distributed::credentials::Credentials;
use ratelab::text::printable;
use std::path::{Path, PathBuf};

/// The largest record read, bytes.
const MAX_RECORD_BYTES: u64 = 256;

/// The most entries of the records' folder looked at (a user runs a few launches at once).
pub const MAX_RECORDS: usize = 256;

/// The folder of this user's records, if the user has a runtime or home folder.
pub fn records_dir() -> Option<PathBuf> {
    let dir = std::env::var_os("XDG_RUNTIME_DIR")
        .filter(|d| !d.is_empty())
        .map(PathBuf::from)
        .or_else(|| {
            std::env::var_os("HOME")
                .filter(|d| !d.is_empty())
                .map(|h| PathBuf::from(h).join(".cache"))
        })?;
    Some(dir.join("ratelab"))
}

/// The record of the launch of process `pid` in `dir`.
fn record_path(dir: &Path, pid: u32) -> PathBuf {
    dir.join(format!("launch.{pid}"))
}

/// The observer credentials' path of the launch of process `pid` in `dir`.
fn credentials_path(dir: &Path, pid: u32) -> PathBuf {
    dir.join(format!("launch-credentials.{pid}.toml"))
}

/// This process's launch, recorded while it lives: dropping it removes the record and its
/// credentials.
pub struct Recorded {
    dir: PathBuf,
    pid: u32,
}

impl Drop for Recorded {
    fn drop(&mut self) {
        let _ = std::fs::remove_file(record_path(&self.dir, self.pid));
        let _ = std::fs::remove_file(credentials_path(&self.dir, self.pid));
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
    let dir = records_dir()?;
    let pid = std::process::id();
    let path = record_path(&dir, pid);
    prune(&dir);
    let write = || -> std::io::Result<()> {
        std::fs::create_dir_all(&dir)?;
        // The credentials first: a watcher that finds the record finds them too.
        observer
            .write(&credentials_path(&dir, pid), true)
            .map_err(std::io::Error::other)?;
        // Written beside and moved into place: a reader never sees half a line.
        let tmp = dir.join(format!(".launch.{pid}"));
        std::fs::write(&tmp, format!("{endpoint} {pid}\n"))?;
        std::fs::rename(&tmp, &path)
    };
    match write() {
        Ok(()) => Some(Recorded { dir, pid }),
        Err(e) => {
            warn(format!(
                "cannot record this launch in {} ({e}): `lab --attach` and `top` need --connect {endpoint}",
                path.display()
            ));
            None
        }
    }
}

/// Remove the records (and credentials) in `dir` of launches that are gone: a launch killed
/// before it could remove its own (SIGKILL, a second Ctrl-C) leaves them.
fn prune(dir: &Path) {
    for pid in recorded_pids(dir) {
        if !is_launch(pid) {
            let _ = std::fs::remove_file(record_path(dir, pid));
            let _ = std::fs::remove_file(credentials_path(dir, pid));
        }
    }
}

/// The process ids of the records (`launch.<pid>`) in `dir`, at most [`MAX_RECORDS`].
fn recorded_pids(dir: &Path) -> Vec<u32> {
    let Ok(entries) = std::fs::read_dir(dir) else {
        return Vec::new();
    };
    entries
        .filter_map(Result::ok)
        .filter_map(|e| {
            e.file_name()
                .to_str()?
                .strip_prefix("launch.")?
                .parse()
                .ok()
        })
        .take(MAX_RECORDS)
        .collect()
}

/// Is process `pid` a ratelab launch? It lives and its command line says `launch` (a pid
/// reused by another program since the record was written is no launch).
fn is_launch(pid: u32) -> bool {
    std::fs::read(format!("/proc/{pid}/cmdline"))
        .is_ok_and(|c| c.split(|&b| b == 0).any(|arg| arg == b"launch"))
}

/// A running launch of this user's, as its record gives it.
#[derive(Clone, Debug, PartialEq)]
pub struct Launch {
    /// Where it listens.
    pub endpoint: String,
    /// Its launcher's process id.
    pub pid: u32,
    /// Its observer credentials' file.
    pub credentials: PathBuf,
}

impl Launch {
    /// `tls/127.0.0.1:7449 (graph 'cartpole', pid 123)`, for a list of launches.
    fn describe(&self) -> String {
        let graph = Credentials::load(&self.credentials)
            .map(|c| format!("graph '{}', ", printable(&c.graph)))
            .unwrap_or_default();
        format!("{} ({graph}pid {})", self.endpoint, self.pid)
    }
}

/// This user's running launches (their records whose process lives), by process id.
pub fn launches() -> Vec<Launch> {
    let Some(dir) = records_dir() else {
        return Vec::new();
    };
    let mut found: Vec<Launch> = recorded_pids(&dir)
        .into_iter()
        .filter_map(|pid| {
            let bytes =
                ratelab::input::read_regular_file(&record_path(&dir, pid), MAX_RECORD_BYTES)
                    .ok()?;
            let (endpoint, said) = parse(&String::from_utf8(bytes).ok()?)?;
            (said == pid && is_launch(pid)).then(|| Launch {
                endpoint,
                pid,
                credentials: credentials_path(&dir, pid),
            })
        })
        .collect();
    found.sort_by_key(|l| l.pid);
    found
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

/// What `lab --attach` and `top` watch: where they connect, what to say when nothing answers
/// there, and the credentials they join with.
pub struct Target {
    /// The endpoints to connect to.
    pub connect: Vec<String>,
    /// The hint for when nothing answers.
    pub hint: String,
    /// The credentials to join with.
    pub credentials: Credentials,
}

/// Choose what `lab --attach` and `top` watch, from `--connect` (`connect`),
/// `--credentials` (`given`) and `launches` (this user's running launches):
///
/// - endpoints: `connect` when given, else the one running launch's, else the default;
/// - credentials: `given`, else those of the launch connected to (the one whose endpoint
///   `connect` names, or the one running).
///
/// # Errors
/// One line: several launches running and nothing to choose one by (they are listed);
/// no credentials to be had; a credentials file that is bad.
pub fn target(
    connect: &[String],
    given: Option<&Path>,
    launches: &[Launch],
) -> anyhow::Result<Target> {
    let chosen: Option<&Launch> = if connect.is_empty() {
        match launches {
            [] => None,
            [one] => Some(one),
            several => anyhow::bail!(
                "{} launches of yours are running: {}; choose one with --connect",
                several.len(),
                several
                    .iter()
                    .map(Launch::describe)
                    .collect::<Vec<_>>()
                    .join(", ")
            ),
        }
    } else {
        let port = |ep: &str| ep.rsplit_once(':').map(|(_, p)| p.to_string());
        let local = |ep: &str| {
            ["127.0.0.1", "localhost", "[::1]"]
                .iter()
                .any(|h| ep.contains(h))
        };
        match launches
            .iter()
            .find(|l| connect.contains(&l.endpoint))
            // Named otherwise (localhost for 127.0.0.1): a launch of this host on that port.
            .or_else(|| {
                launches.iter().find(|l| {
                    connect
                        .iter()
                        .any(|c| local(c) && port(c).is_some() && port(c) == port(&l.endpoint))
                })
            }) {
            Some(l) => Some(l),
            None if given.is_some() || launches.is_empty() => None,
            None => anyhow::bail!(
                "none of the {} launches of yours listens on {}: {}; give its --connect, or --credentials FILE",
                launches.len(),
                connect.join(", "),
                launches
                    .iter()
                    .map(Launch::describe)
                    .collect::<Vec<_>>()
                    .join(", ")
            ),
        }
    };
    let credentials = match (given, chosen) {
        (Some(f), _) => Credentials::load(f)?,
        (None, Some(l)) => Credentials::load(&l.credentials)?,
        (None, None) => anyhow::bail!(
            "no launch of yours is running on this host to watch: give --credentials FILE (written by `ratelab launch --processes --export-credentials FILE`)"
        ),
    };
    let (connect, hint) = match (connect.is_empty(), chosen) {
        (false, _) => (connect.to_vec(), "check the endpoint".to_string()),
        (true, Some(l)) => (
            vec![l.endpoint.clone()],
            "this user's launch was recorded there; is it still starting?".to_string(),
        ),
        (true, None) => (
            vec![ratelab::distributed::DEFAULT_ENDPOINT.to_string()],
            "no launch of yours is recorded: start one with `ratelab launch --processes`, or \
             give --connect tls/HOST:PORT"
                .to_string(),
        ),
    };
    Ok(Target {
        connect,
        hint,
        credentials,
    })
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

    #[test]
    fn two_running_launches_are_listed_never_guessed() {
        let l = |port: u16, pid: u32| Launch {
            endpoint: format!("tls/127.0.0.1:{port}"),
            pid,
            credentials: PathBuf::from(format!("/nonexistent/launch-credentials.{pid}.toml")),
        };
        let two = [l(7449, 10), l(7450, 11)];
        let e = target(&[], None, &two).err().unwrap().to_string();
        assert!(
            e.starts_with("2 launches of yours are running: tls/127.0.0.1:7449 (pid 10), tls/127.0.0.1:7450 (pid 11)")
                && e.ends_with("choose one with --connect"),
            "{e}"
        );
        assert_eq!(e.lines().count(), 1);
        // --connect chooses, and the credentials looked for are that launch's.
        let e = target(&["tls/127.0.0.1:7450".into()], None, &two)
            .err()
            .unwrap()
            .to_string();
        assert!(e.contains("launch-credentials.11.toml"), "{e}");
        // An endpoint neither listens on: listed, with what to do.
        let e = target(&["tls/127.0.0.1:9".into()], None, &two)
            .err()
            .unwrap()
            .to_string();
        assert!(
            e.starts_with("none of the 2 launches of yours listens on tls/127.0.0.1:9"),
            "{e}"
        );
        // None running and no credentials: one line saying what to give.
        let e = target(&[], None, &[]).err().unwrap().to_string();
        assert!(e.contains("give --credentials FILE"), "{e}");
    }
}
