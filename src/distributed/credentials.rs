//! Who may join a graph across processes: per-launch credentials for mutual TLS.
//!
//! Every session of a graph across processes (the launcher, each `ratelab process`, and the
//! watchers `ratelab top` and `lab --attach`) speaks Zenoh over TLS 1.3 with mutual
//! authentication: both ends of every link show a certificate signed by one certificate
//! authority (CA) that exists for one launch only, so a peer without the launch's
//! credentials cannot connect, read or write anything (ROS 2's own answer for rmw_zenoh is
//! the same Zenoh mechanism, `zenoh_security_tools`). The certificate's common name is the
//! peer's identity, which Zenoh's access control ([`super::access`]) checks on every
//! message: [`Role::common_name`]. The launcher's session, the router every other session
//! links to, has an identity of its own ([`Role::Router`]) that never leaves the launcher:
//! no file holds it ([`Credentials::to_toml`]), so nobody else can speak as the router. A
//! host's router ([`Role::HostRouter`], started by hand on another host) is exported; the
//! launcher's router hears it as the processes behind it, no more ([`super::access`]).
//!
//! [`Credentials::generate`] makes the CA and one certificate per identity (ECDSA P-256,
//! by `rcgen`); the CA's private key is dropped at once, so nobody, not even the launcher,
//! can issue another identity. The launcher hands each process it starts a file holding
//! the CA's certificate and that process's identity alone, in a private folder (mode
//! `0700`, files `0600`) removed when the launch ends; `launch --export-credentials FILE`
//! writes every identity to a file for processes started by hand (`ratelab process
//! --credentials FILE`). A later launch makes a new CA: old files admit to nothing.
//!
//! A credentials file is read as untrusted input: at most [`MAX_CREDENTIALS_BYTES`], TOML
//! with known fields only, bounded counts and sizes, and refused when other users may read
//! it (as `ssh` refuses a private key anyone can read).

use super::{DistError, MAX_PROCESSES};
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;
use std::path::Path;

/// The largest credentials file read, bytes: room for every identity of the largest launch
/// ([`MAX_PROCESSES`] and four more, each a certificate and a key of at most
/// `MAX_PEM_BYTES`), and 64 KiB besides (about 4.1 MiB).
pub const MAX_CREDENTIALS_BYTES: u64 =
    (MAX_PROCESSES as u64 + MORE_IDENTITIES as u64) * 2 * MAX_PEM_BYTES as u64 + 64 * 1024;

/// The identities of a launch beside its processes': the launcher, an observer, the
/// launcher's router and a host's router.
const MORE_IDENTITIES: usize = 4;

/// The largest certificate or private key in a credentials file, bytes of PEM.
const MAX_PEM_BYTES: usize = 8 * 1024;

/// The longest graph name or common name in a credentials file, bytes.
const MAX_NAME_BYTES: usize = 128;

/// How long a launch's certificates are valid, from when they are made: a launch runs an
/// hour at most, and processes started by hand may join a launch that waited for them.
pub const VALIDITY: std::time::Duration = std::time::Duration::from_secs(7 * 24 * 3600);

/// How far before it was made a certificate is valid already: hosts' clocks disagree.
const CLOCK_SKEW: std::time::Duration = std::time::Duration::from_secs(3600);

/// Now, seconds since the Unix epoch.
fn unix_now_s() -> u64 {
    std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map_or(0, |d| d.as_secs())
}

/// Who a session is, as its certificate's common name says.
#[derive(Clone, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum Role {
    /// The launcher: the run's authority (the control keys, the run's settings, its end).
    Launcher,
    /// A process of the graph (`ratelab process --process NAME`): it publishes its own
    /// nodes' topics, reports and tokens.
    Process(String),
    /// A watcher (`ratelab top`, `lab --attach`, the lab beside its launch): it reads, and
    /// publishes nothing the graph acts on.
    Observer,
    /// The launcher's session as the router of the launch ([`super::open_router`]):
    /// it passes on what every other identity says, each message checked on arrival by the
    /// identity it came from, and what the launcher itself says. Only the launcher holds it.
    Router,
    /// A router on another host (`ratelab router`, [`super::host_router`]): the processes
    /// and watchers of its host link to it, and it links to the launcher's router, as Zenoh
    /// deploys a system across hosts. It checks what each of its clients says on arrival,
    /// as the launcher's router does, and passes on what it let in. Exported with the
    /// launch's other identities (`launch --export-credentials`), since it is started by hand.
    HostRouter,
}

impl Role {
    /// The certificate's common name: `ratelab-launcher`, `ratelab-process-<NAME>`,
    /// `ratelab-observer`, `ratelab-router`, `ratelab-host-router`.
    pub fn common_name(&self) -> String {
        match self {
            Role::Launcher => "ratelab-launcher".into(),
            Role::Process(p) => format!("ratelab-process-{p}"),
            Role::Observer => "ratelab-observer".into(),
            Role::Router => "ratelab-router".into(),
            Role::HostRouter => "ratelab-host-router".into(),
        }
    }

    /// How a line names it: `the launcher`, `process 'robot'`, `an observer`.
    pub fn describe(&self) -> String {
        match self {
            Role::Launcher => "the launcher".into(),
            Role::Process(p) => format!("process '{p}'"),
            Role::Observer => "an observer".into(),
            Role::Router => "the launcher's router".into(),
            Role::HostRouter => "a host's router".into(),
        }
    }
}

/// One identity: its certificate (signed by the launch's CA) and private key, PEM.
#[derive(Clone, PartialEq, Eq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Identity {
    /// The certificate, PEM.
    pub cert: String,
    /// Its private key (PKCS#8), PEM.
    pub key: String,
}

impl std::fmt::Debug for Identity {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str("Identity { cert, key: *** }")
    }
}

/// A launch's credentials: its CA's certificate and some of its identities.
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Credentials {
    /// The graph they admit to (its name).
    pub graph: String,
    /// The graph's processes, in placement order.
    pub processes: Vec<String>,
    /// When the certificates stop being valid, seconds since the Unix epoch ([`VALIDITY`]
    /// after they were made; TLS refuses them after it, whatever the file says).
    pub valid_until_unix_s: u64,
    /// The launch's CA certificate, PEM: the only issuer a session trusts.
    pub ca: String,
    /// Identities by common name ([`Role::common_name`]).
    pub identities: BTreeMap<String, Identity>,
}

fn tls_error(e: rcgen::Error) -> DistError {
    DistError::Usage(format!("cannot make the launch's certificates: {e}"))
}

/// Is `pem` exactly one X.509 certificate, in PEM whose DER parses? (Checked when a file
/// is read, so a bad one is named there; Zenoh's TLS would say it at the handshake, in
/// rustls' terms.)
///
/// # Errors
/// What is wrong, to follow "its certificate …".
fn check_certificate(pem: &str) -> Result<(), String> {
    use rustls_pki_types::{pem::PemObject, CertificateDer};
    let certs = CertificateDer::pem_slice_iter(pem.as_bytes())
        .collect::<Result<Vec<_>, _>>()
        .map_err(|e| {
            format!(
                "is not valid PEM ({})",
                ratelab_core::text::printable(&e.to_string())
            )
        })?;
    let [cert] = certs.as_slice() else {
        return Err(format!("holds {} certificates, not one", certs.len()));
    };
    webpki::EndEntityCert::try_from(cert)
        .map(drop)
        .map_err(|e| format!("is not an X.509 certificate ({e:?})"))
}

impl Credentials {
    /// A new CA and an identity for the launcher, an observer, the launcher's router, a
    /// host's router and each of `processes`, for graph `graph`. The CA's private key is not kept.
    ///
    /// # Errors
    /// [`DistError::Usage`] when a key or certificate cannot be made (the system's
    /// random source failed).
    pub fn generate(graph: &str, processes: &[String]) -> Result<Credentials, DistError> {
        use rcgen::{
            BasicConstraints, CertificateParams, DnType, ExtendedKeyUsagePurpose, IsCa, Issuer,
            KeyPair, KeyUsagePurpose,
        };
        let now = unix_now_s();
        let valid_until_unix_s = now + VALIDITY.as_secs();
        let at = |s: u64| {
            time::OffsetDateTime::from_unix_timestamp(i64::try_from(s).unwrap_or(i64::MAX))
                .map_err(|e| DistError::Usage(format!("cannot date the certificates: {e}")))
        };
        let (not_before, not_after) = (
            at(now.saturating_sub(CLOCK_SKEW.as_secs()))?,
            at(valid_until_unix_s)?,
        );
        let mut ca_params = CertificateParams::new(Vec::<String>::new()).map_err(tls_error)?;
        ca_params.not_before = not_before;
        ca_params.not_after = not_after;
        ca_params
            .distinguished_name
            .push(DnType::CommonName, format!("ratelab launch CA ({graph})"));
        ca_params.is_ca = IsCa::Ca(BasicConstraints::Constrained(0));
        ca_params.key_usages = vec![
            KeyUsagePurpose::KeyCertSign,
            KeyUsagePurpose::CrlSign,
            KeyUsagePurpose::DigitalSignature,
        ];
        let ca_key = KeyPair::generate().map_err(tls_error)?;
        let ca_cert = ca_params.self_signed(&ca_key).map_err(tls_error)?;
        let issuer = Issuer::new(ca_params, ca_key);
        let mut roles = vec![
            Role::Launcher,
            Role::Observer,
            Role::Router,
            Role::HostRouter,
        ];
        roles.extend(processes.iter().cloned().map(Role::Process));
        let mut identities = BTreeMap::new();
        for role in roles {
            let cn = role.common_name();
            let mut params =
                CertificateParams::new(vec!["localhost".to_string()]).map_err(tls_error)?;
            params
                .distinguished_name
                .push(DnType::CommonName, cn.clone());
            params.not_before = not_before;
            params.not_after = not_after;
            params.extended_key_usages = vec![
                ExtendedKeyUsagePurpose::ServerAuth,
                ExtendedKeyUsagePurpose::ClientAuth,
            ];
            params.key_usages = vec![KeyUsagePurpose::DigitalSignature];
            let key = KeyPair::generate().map_err(tls_error)?;
            let cert = params.signed_by(&key, &issuer).map_err(tls_error)?;
            identities.insert(
                cn,
                Identity {
                    cert: cert.pem(),
                    key: key.serialize_pem(),
                },
            );
        }
        Ok(Credentials {
            graph: graph.to_string(),
            processes: processes.to_vec(),
            valid_until_unix_s,
            ca: ca_cert.pem(),
            identities,
        })
    }

    /// The same credentials holding `role`'s identity alone (what a started process is
    /// given).
    ///
    /// # Errors
    /// [`DistError::Usage`] when they hold no identity for `role`.
    pub fn only(&self, role: &Role) -> Result<Credentials, DistError> {
        let id = self.identity(role)?.clone();
        Ok(Credentials {
            identities: BTreeMap::from([(role.common_name(), id)]),
            ..self.clone()
        })
    }

    /// `role`'s identity.
    ///
    /// # Errors
    /// [`DistError::Usage`] naming the identities they hold.
    pub fn identity(&self, role: &Role) -> Result<&Identity, DistError> {
        self.identities.get(&role.common_name()).ok_or_else(|| {
            DistError::Usage(format!(
                "these credentials (graph '{}') hold no identity for {} (they hold: {})",
                self.graph,
                role.describe(),
                self.identities
                    .keys()
                    .map(String::as_str)
                    .collect::<Vec<_>>()
                    .join(", ")
            ))
        })
    }

    /// The file's text (TOML, with a first line saying it is a secret), without the
    /// router's identity ([`Role::Router`]): it never leaves the launcher, whatever file is
    /// written (an export, a started process's own).
    pub fn to_toml(&self) -> String {
        let mut written = self.clone();
        written.identities.remove(&Role::Router.common_name());
        let body = toml::to_string(&written).unwrap_or_default();
        format!(
            "# ratelab credentials for graph '{}': a secret. Whoever holds this file can join \
             the graph's launch as the identities below.\n{body}",
            // A comment holds no control character (TOML), whatever the graph is called.
            ratelab_core::text::printable(&self.graph)
        )
    }

    /// Parse a credentials file's text; `origin` names it in errors.
    ///
    /// # Errors
    /// [`DistError::Usage`], one line: not TOML of this shape, or counts and sizes over
    /// their bounds.
    pub fn parse(text: &str, origin: &str) -> Result<Credentials, DistError> {
        let bad = |why: String| DistError::Usage(format!("{origin}: {why}"));
        let c: Credentials = toml::from_str(text).map_err(|e| {
            bad(format!(
                "not a ratelab credentials file ({})",
                e.message().lines().next().unwrap_or("malformed")
            ))
        })?;
        if c.graph.is_empty() || c.graph.len() > MAX_NAME_BYTES {
            return Err(bad("the graph's name is empty or too long".into()));
        }
        if c.processes.len() > MAX_PROCESSES || c.identities.len() > MAX_PROCESSES + MORE_IDENTITIES
        {
            return Err(bad(format!(
                "more than {MAX_PROCESSES} processes or {} identities",
                MAX_PROCESSES + MORE_IDENTITIES
            )));
        }
        if let Some(p) = c
            .processes
            .iter()
            .find(|p| !ratelab_runtime::graph::spec::valid_node_name(p))
        {
            return Err(bad(format!(
                "'{}' is not a process name",
                ratelab_core::text::printable(p)
            )));
        }
        let pem_ok = |s: &str| s.len() <= MAX_PEM_BYTES && s.starts_with("-----BEGIN ");
        if !pem_ok(&c.ca) {
            return Err(bad("the CA certificate is not a PEM certificate".into()));
        }
        check_certificate(&c.ca).map_err(|why| bad(format!("the CA certificate {why}")))?;
        for (cn, id) in &c.identities {
            let who = ratelab_core::text::printable(cn);
            if cn.len() > MAX_NAME_BYTES || !pem_ok(&id.cert) || !pem_ok(&id.key) {
                return Err(bad(format!(
                    "identity '{who}' is not a PEM certificate and key"
                )));
            }
            check_certificate(&id.cert)
                .map_err(|why| bad(format!("identity '{who}': its certificate {why}")))?;
            rcgen::KeyPair::from_pem(&id.key).map_err(|e| {
                bad(format!(
                    "identity '{who}': its key is not a valid PEM private key ({})",
                    ratelab_core::text::printable(&e.to_string())
                ))
            })?;
        }
        Ok(c)
    }

    /// Read a credentials file ([`Credentials::parse`]), refusing one that other users may
    /// read or write.
    ///
    /// # Errors
    /// [`DistError::Usage`], one line naming the file.
    pub fn load(path: &Path) -> Result<Credentials, DistError> {
        use std::os::unix::fs::PermissionsExt as _;
        let shown = path.display();
        let bytes = ratelab_core::input::read_regular_file(path, MAX_CREDENTIALS_BYTES)
            .map_err(|e| DistError::Usage(format!("--credentials: {e}")))?;
        if let Ok(m) = std::fs::metadata(path) {
            if m.permissions().mode() & 0o077 != 0 {
                return Err(DistError::Usage(format!(
                    "--credentials {shown}: other users may read it (mode {:o}); it is a secret: chmod 600 {shown}",
                    m.permissions().mode() & 0o777
                )));
            }
        }
        let text = ratelab_core::input::utf8_text(bytes)
            .map_err(|e| DistError::Usage(format!("--credentials {shown}: {e}")))?;
        let c = Credentials::parse(&text, &format!("--credentials {shown}"))?;
        let now = unix_now_s();
        if now > c.valid_until_unix_s {
            return Err(DistError::Usage(format!(
                "--credentials {shown}: expired {} h ago (a launch's credentials are valid {} days): export this launch's with `launch --export-credentials FILE`",
                (now - c.valid_until_unix_s) / 3600,
                VALIDITY.as_secs() / 86_400
            )));
        }
        Ok(c)
    }

    /// Write them to `path`, readable by its owner alone; an existing file only with
    /// `force` ([`ratelab_core::output`]'s rule).
    ///
    /// # Errors
    /// [`DistError::Usage`], one line naming the file.
    pub fn write(&self, path: &Path, force: bool) -> Result<(), DistError> {
        ratelab_core::output::write_private(path, force, self.to_toml().as_bytes())
            .map_err(|e| DistError::Usage(e.to_string()))
    }

    /// The Zenoh configuration a session of `role` needs, as `(key, JSON5 value)` pairs
    /// for [`zenoh::Config::insert_json5`]: the CA as the only custom root, `role`'s
    /// certificate and key on both listening and connecting links, mutual TLS. The peer's
    /// host name is not checked against its certificate (a launch's CA issues nothing
    /// else, and every peer is checked by its identity, [`super::access`]).
    ///
    /// # Errors
    /// [`DistError::Usage`] when they hold no identity for `role`.
    pub fn zenoh_tls(&self, role: &Role) -> Result<Vec<(&'static str, String)>, DistError> {
        use base64::Engine as _;
        let id = self.identity(role)?;
        let b64 = |s: &str| {
            serde_json::to_string(&base64::engine::general_purpose::STANDARD.encode(s))
                .unwrap_or_default()
        };
        Ok(vec![
            (
                "transport/link/tls/root_ca_certificate_base64",
                b64(&self.ca),
            ),
            (
                "transport/link/tls/listen_certificate_base64",
                b64(&id.cert),
            ),
            ("transport/link/tls/listen_private_key_base64", b64(&id.key)),
            (
                "transport/link/tls/connect_certificate_base64",
                b64(&id.cert),
            ),
            (
                "transport/link/tls/connect_private_key_base64",
                b64(&id.key),
            ),
            ("transport/link/tls/enable_mtls", "true".into()),
            ("transport/link/tls/verify_name_on_connect", "false".into()),
        ])
    }
}

/// A folder of this user's alone (mode `0700`) for a launch's credentials files, removed
/// with everything in it when dropped.
pub struct PrivateDir(tempfile::TempDir);

/// How a launch's private folder's name begins, before its launcher's process id.
const PRIVATE_PREFIX: &str = "ratelab-launch-";

/// The most entries of the temporary folder looked through for folders left behind.
const MAX_SWEPT_ENTRIES: usize = 100_000;

impl PrivateDir {
    /// A new one under the system's temporary folder (`ratelab-launch-<PID>-XXXXXX`, PID
    /// this process's), after removing those of this user whose launcher is no longer
    /// running ([`PrivateDir::sweep`]).
    ///
    /// # Errors
    /// [`DistError::Usage`] when it cannot be made.
    pub fn new() -> Result<PrivateDir, DistError> {
        use std::os::unix::fs::PermissionsExt as _;
        PrivateDir::sweep(&std::env::temp_dir());
        tempfile::Builder::new()
            .prefix(&format!("{PRIVATE_PREFIX}{}-", std::process::id()))
            .permissions(std::fs::Permissions::from_mode(0o700))
            .tempdir()
            .map(PrivateDir)
            .map_err(|e| DistError::Usage(format!("cannot make a private folder: {e}")))
    }

    /// Its path.
    pub fn path(&self) -> &Path {
        self.0.path()
    }

    /// Remove from `tmp` the private folders of this user's launches whose launcher is gone
    /// (a SIGKILL leaves its folder, with the launch's keys, behind): each a folder, not a
    /// link, owned by this user, named for a process id that no process has now. Best
    /// effort, bounded ([`MAX_SWEPT_ENTRIES`]); returns how many were removed.
    pub fn sweep(tmp: &Path) -> usize {
        use std::os::unix::fs::MetadataExt as _;
        let Ok(entries) = std::fs::read_dir(tmp) else {
            return 0;
        };
        // SAFETY: geteuid has no preconditions.
        let me = unsafe { libc::geteuid() };
        let mut removed = 0;
        for entry in entries.take(MAX_SWEPT_ENTRIES).flatten() {
            let name = entry.file_name();
            let Some(pid) = (name.to_str())
                .and_then(|n| n.strip_prefix(PRIVATE_PREFIX))
                .and_then(|rest| rest.split_once('-'))
                .and_then(|(pid, _)| pid.parse::<i32>().ok())
                .filter(|pid| *pid > 0)
            else {
                continue;
            };
            let Ok(meta) = std::fs::symlink_metadata(entry.path()) else {
                continue;
            };
            // SAFETY: kill with signal 0 only asks whether the process exists.
            let gone = unsafe { libc::kill(pid, 0) } != 0
                && std::io::Error::last_os_error().raw_os_error() == Some(libc::ESRCH);
            if meta.is_dir() && meta.uid() == me && gone {
                removed += usize::from(std::fs::remove_dir_all(entry.path()).is_ok());
            }
        }
        removed
    }

    /// Write `creds` there as `NAME.toml` (mode `0600`; anew, for a process started again)
    /// and return its path.
    ///
    /// # Errors
    /// [`DistError::Usage`] when it cannot be written.
    pub fn write(&self, name: &str, creds: &Credentials) -> Result<std::path::PathBuf, DistError> {
        let path = self.0.path().join(format!("{name}.toml"));
        creds.write(&path, true)?;
        Ok(path)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn procs() -> Vec<String> {
        vec!["robot".into(), "policy".into()]
    }

    #[test]
    fn a_private_folder_left_by_a_launcher_that_is_gone_is_swept() {
        let tmp = tempfile::tempdir().unwrap();
        let mine = std::process::id();
        // A process id no process has (past the kernel's pid_max).
        let gone = 0x3fff_fff0;
        let left = tmp.path().join(format!("ratelab-launch-{gone}-abc123"));
        let alive = tmp.path().join(format!("ratelab-launch-{mine}-def456"));
        let older = tmp.path().join("ratelab-launch-XyZ123"); // no process id: kept
        let other = tmp.path().join(format!("not-ratelab-{gone}-x"));
        for d in [&left, &alive, &older, &other] {
            std::fs::create_dir(d).unwrap();
            std::fs::write(d.join("policy.toml"), "secret").unwrap();
        }
        // A link of that name is not followed or removed.
        let target = tmp.path().join("target");
        std::fs::create_dir(&target).unwrap();
        let link = tmp.path().join(format!("ratelab-launch-{gone}-link"));
        std::os::unix::fs::symlink(&target, &link).unwrap();
        assert_eq!(PrivateDir::sweep(tmp.path()), 1);
        assert!(!left.exists());
        assert!(alive.exists() && older.exists() && other.exists() && target.exists());
        assert!(std::fs::symlink_metadata(&link).is_ok());
        // A new one is named for this process.
        let dir = PrivateDir::new().unwrap();
        let name = dir
            .path()
            .file_name()
            .unwrap()
            .to_str()
            .unwrap()
            .to_string();
        assert!(
            name.starts_with(&format!("ratelab-launch-{mine}-")),
            "{name}"
        );
    }

    #[test]
    fn generated_credentials_round_trip_through_their_file_and_keep_one_identity_per_role() {
        let c = Credentials::generate("cartpole", &procs()).unwrap();
        assert_eq!(
            c.identities.keys().cloned().collect::<Vec<_>>(),
            [
                "ratelab-host-router",
                "ratelab-launcher",
                "ratelab-observer",
                "ratelab-process-policy",
                "ratelab-process-robot",
                "ratelab-router"
            ]
        );
        // Every identity but the launcher's router's, which never leaves the launcher; a
        // host's router's is exported, since it is started by hand.
        let back = Credentials::parse(&c.to_toml(), "x").unwrap();
        assert!(back.identity(&Role::Router).is_err());
        assert!(back.identity(&Role::HostRouter).is_ok());
        let mut all_but_router = c.clone();
        all_but_router
            .identities
            .remove(&Role::Router.common_name());
        assert_eq!(back, all_but_router);
        assert!(c.zenoh_tls(&Role::Router).is_ok());
        let one = c.only(&Role::Process("robot".into())).unwrap();
        assert_eq!(one.identities.len(), 1);
        assert!(one.identity(&Role::Launcher).is_err());
        let err = c
            .only(&Role::Process("camera".into()))
            .unwrap_err()
            .to_string();
        assert!(err.contains("no identity for process 'camera'"), "{err}");
        // The key never shows in a debug print.
        assert!(!format!("{one:?}").contains("PRIVATE KEY"));
    }

    #[test]
    fn two_launches_have_different_authorities() {
        let a = Credentials::generate("g", &procs()).unwrap();
        let b = Credentials::generate("g", &procs()).unwrap();
        assert_ne!(a.ca, b.ca);
    }

    #[test]
    fn hostile_files_are_refused_in_one_line() {
        let c = Credentials::generate("g", &procs()).unwrap();
        for (text, says) in [
            ("", "not a ratelab credentials file"),
            ("graph = 1", "not a ratelab credentials file"),
            (
                &c.to_toml()
                    .replace("graph = \"g\"", "graph = \"g\"\nextra = 1"),
                "not a ratelab credentials file",
            ),
            (
                &c.to_toml().replace("-----BEGIN CERTIFICATE", "BEGIN"),
                "not a PEM certificate",
            ),
        ] {
            let e = Credentials::parse(text, "F").unwrap_err().to_string();
            assert!(e.starts_with("F: ") && e.contains(says), "{e}");
            assert!(!e.contains('\n'), "{e}");
        }
        // Certificates and keys whose PEM, DER or count is wrong: each named in one line.
        let cert = |f: &dyn Fn(&mut Identity)| {
            let mut bad = c.clone();
            f(bad.identities.values_mut().next().unwrap());
            Credentials::parse(&bad.to_toml(), "F")
                .unwrap_err()
                .to_string()
        };
        let e = cert(&|id| id.cert = id.cert.replacen("-----\nM", "-----\n!", 1));
        assert!(e.contains("its certificate is not valid PEM"), "{e}");
        let e = cert(&|id| {
            id.cert = "-----BEGIN CERTIFICATE-----\nAAAA\n-----END CERTIFICATE-----\n".into()
        });
        assert!(
            e.contains("its certificate is not an X.509 certificate"),
            "{e}"
        );
        let e = cert(&|id| id.cert = format!("{}{}", id.cert, id.cert));
        assert!(e.contains("holds 2 certificates, not one"), "{e}");
        let e = cert(&|id| id.key = id.key.replacen("-----\nM", "-----\n!", 1));
        assert!(e.contains("its key is not a valid PEM private key"), "{e}");
        let mut bad = c.clone();
        bad.ca = bad.ca.replacen("-----\nM", "-----\n!", 1);
        let e = Credentials::parse(&bad.to_toml(), "F")
            .unwrap_err()
            .to_string();
        assert!(
            e.starts_with("F: the CA certificate is not valid PEM"),
            "{e}"
        );
        // A graph name with control characters still makes a file that reads back.
        let mut odd = c.clone();
        odd.graph = "g\n\u{1b}[2J".into();
        assert_eq!(
            Credentials::parse(&odd.to_toml(), "F").unwrap().graph,
            odd.graph
        );
        let many = (0..=MAX_PROCESSES)
            .map(|i| format!("p{i}"))
            .collect::<Vec<_>>();
        let mut big = c.clone();
        big.processes = many;
        let e = Credentials::parse(&big.to_toml(), "F")
            .unwrap_err()
            .to_string();
        assert!(e.contains("more than"), "{e}");
    }

    #[test]
    fn files_are_private_never_overwritten_without_force_and_refused_when_others_can_read() {
        use std::os::unix::fs::PermissionsExt as _;
        let dir = PrivateDir::new().unwrap();
        assert_eq!(
            std::fs::metadata(dir.path()).unwrap().permissions().mode() & 0o777,
            0o700
        );
        let c = Credentials::generate("g", &procs()).unwrap();
        let f = dir.write("all", &c).unwrap();
        let mut written = c.clone();
        written.identities.remove(&Role::Router.common_name());
        assert_eq!(
            std::fs::metadata(&f).unwrap().permissions().mode() & 0o777,
            0o600
        );
        assert_eq!(Credentials::load(&f).unwrap(), written);
        let e = c.write(&f, false).unwrap_err().to_string();
        assert!(e.contains("--force"), "{e}");
        c.write(&f, true).unwrap();
        let mut old = c.clone();
        old.valid_until_unix_s = unix_now_s() - 7200;
        old.write(&f, true).unwrap();
        let e = Credentials::load(&f).unwrap_err().to_string();
        assert!(e.contains("expired 2 h ago"), "{e}");
        c.write(&f, true).unwrap();
        std::fs::set_permissions(&f, std::fs::Permissions::from_mode(0o644)).unwrap();
        let e = Credentials::load(&f).unwrap_err().to_string();
        assert!(e.contains("other users may read it"), "{e}");
        let kept = dir.path().to_path_buf();
        drop(dir);
        assert!(
            !kept.exists(),
            "the private folder is removed with its files"
        );
    }
}
