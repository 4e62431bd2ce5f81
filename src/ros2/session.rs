//! The Zenoh session that offers a graph to ROS 2, opened as rmw_zenoh's nodes open theirs
//! by default: peer mode, multicast scouting off, listening on a free local port, connected
//! to a Zenoh router at [`DEFAULT_ROUTER`] (`ros2 run rmw_zenoh_cpp rmw_zenohd`, `zenohd`,
//! or any Zenoh 1.x router), with rmw_zenoh's two environment variables:
//!
//! - `ZENOH_CONFIG_OVERRIDE`: `key=value` pairs separated by `;`, each a Zenoh config path
//!   and a JSON5 value (`connect/endpoints=["tcp/192.168.1.2:7447"];mode="client"`);
//! - `ZENOH_ROUTER_CHECK_ATTEMPTS`: how many times (one second each) to look for the router
//!   before going on; unset means 1, `0` waits until one answers, a negative number skips
//!   the check.
//!
//! When the check finds no router, ratelab runs one itself, listening where the session
//! would have connected (the first `connect/endpoints`), and says so: ROS 2 nodes started
//! afterwards connect to it as they would to `rmw_zenohd`. ratelab's own processes never
//! use this session: it carries the ROS 2 view only (docs/ros2.md).

use super::Ros2Error;
use ratelab_runtime::scheduler::StopFlag;
use std::time::{Duration, Instant};
use zenoh::Wait;

/// Where rmw_zenoh's nodes look for their router by default.
pub const DEFAULT_ROUTER: &str = "tcp/localhost:7447";

/// The longest `ZENOH_CONFIG_OVERRIDE` accepted, bytes (it comes from the environment).
pub const MAX_OVERRIDE_BYTES: usize = 64 * 1024;

/// The environment the session honours, read once ([`SessionEnv::from_process`]) so that
/// tests can pass their own.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct SessionEnv {
    /// `ZENOH_ROUTER_CHECK_ATTEMPTS`, if set.
    pub router_check_attempts: Option<String>,
    /// `ZENOH_CONFIG_OVERRIDE`, if set.
    pub config_override: Option<String>,
}

impl SessionEnv {
    /// The process's environment.
    pub fn from_process() -> SessionEnv {
        SessionEnv {
            router_check_attempts: std::env::var("ZENOH_ROUTER_CHECK_ATTEMPTS").ok(),
            config_override: std::env::var("ZENOH_CONFIG_OVERRIDE").ok(),
        }
    }
}

/// How long to look for a router.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum RouterCheck {
    /// This many attempts of one second.
    Attempts(u32),
    /// Until one answers.
    Forever,
    /// Not at all (and no embedded router).
    Skip,
}

/// `ZENOH_ROUTER_CHECK_ATTEMPTS` read as rmw_zenoh reads it (unset: one attempt).
///
/// # Errors
/// Not an integer: the reason, in one line.
pub fn router_check(value: Option<&str>) -> Result<RouterCheck, String> {
    // Set but empty reads as unset, as rmw_zenoh reads it.
    let Some(v) = value.filter(|v| !v.trim().is_empty()) else {
        return Ok(RouterCheck::Attempts(1));
    };
    let n: i64 = v.trim().parse().map_err(|_| {
        format!("ZENOH_ROUTER_CHECK_ATTEMPTS='{v}' is not an integer (0: wait for a router, <0: do not check)")
    })?;
    Ok(match n {
        0 => RouterCheck::Forever,
        n if n < 0 => RouterCheck::Skip,
        n => RouterCheck::Attempts(u32::try_from(n).unwrap_or(u32::MAX)),
    })
}

/// `ZENOH_CONFIG_OVERRIDE` as `(path, JSON5 value)` pairs, in order (empty pairs skipped).
///
/// # Errors
/// Longer than [`MAX_OVERRIDE_BYTES`], or a pair without `=`: the reason, in one line.
pub fn parse_override(s: &str) -> Result<Vec<(String, String)>, String> {
    if s.len() > MAX_OVERRIDE_BYTES {
        return Err(format!(
            "ZENOH_CONFIG_OVERRIDE is longer than {MAX_OVERRIDE_BYTES} bytes"
        ));
    }
    s.split(';')
        .map(str::trim)
        .filter(|p| !p.is_empty())
        .map(|p| {
            p.split_once('=')
                .map(|(k, v)| (k.trim().to_string(), v.trim().to_string()))
                .ok_or_else(|| {
                    format!(
                        "ZENOH_CONFIG_OVERRIDE: '{p}' is not KEY=VALUE (pairs separated by ';')"
                    )
                })
        })
        .collect()
}

/// What the session found.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum Router {
    /// A router answered at this endpoint.
    Found(String),
    /// None answered: ratelab runs one, listening here.
    Embedded(String),
    /// Not checked (`ZENOH_ROUTER_CHECK_ATTEMPTS` < 0).
    Unchecked,
}

impl Router {
    /// Where the session's messages go, for a person: `through the Zenoh router at …`.
    pub fn via(&self) -> String {
        match self {
            Router::Found(e) => format!("through the Zenoh router at {e}"),
            Router::Embedded(e) => format!(
                "no Zenoh router answered at {e}, so ratelab runs one there for this run (ROS 2 nodes connect to it as to rmw_zenohd)"
            ),
            Router::Unchecked => {
                "without looking for a router (ZENOH_ROUTER_CHECK_ATTEMPTS < 0)".into()
            }
        }
    }
}

/// An open session and what it found. Cloning it gives another handle to the same session.
#[derive(Clone)]
pub struct Ros2Session {
    /// The session.
    pub session: zenoh::Session,
    /// The router it uses.
    pub router: Router,
    /// The next node or endpoint id (rmw_zenoh numbers them per context): every bridge on
    /// this session takes fresh ones, so successive runs of a lab never share a token, a
    /// GID or a sequence.
    next_id: std::sync::Arc<std::sync::atomic::AtomicUsize>,
}

impl std::fmt::Debug for Ros2Session {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Ros2Session")
            .field("zid", &self.session.zid())
            .field("router", &self.router)
            .finish()
    }
}

impl Ros2Session {
    fn new(session: zenoh::Session, router: Router) -> Ros2Session {
        Ros2Session {
            session,
            router,
            next_id: std::sync::Arc::default(),
        }
    }

    /// A fresh node or endpoint id.
    pub fn take_id(&self) -> usize {
        self.next_id
            .fetch_add(1, std::sync::atomic::Ordering::Relaxed)
    }

    /// Close the session (and the embedded router, if it is one).
    pub fn close(self) {
        let _ = self.session.close().wait();
    }
}

fn set(config: &mut zenoh::Config, key: &str, value: &str) -> Result<(), Ros2Error> {
    config.insert_json5(key, value).map_err(|e| {
        let why = ratelab_core::text::library_message(&e.to_string());
        Ros2Error::Usage(format!("Zenoh config {key}={value}: {why}"))
    })
}

fn open_with(config: zenoh::Config, what: &str) -> Result<zenoh::Session, Ros2Error> {
    zenoh::open(config).wait().map_err(|e| {
        let first = e.to_string().lines().next().unwrap_or_default().to_string();
        Ros2Error::Usage(format!("cannot open the ROS 2 session ({what}): {first}"))
    })
}

/// The endpoints `config` connects to (`connect/endpoints`, as an override may have set
/// them); empty when it names none or cannot be read.
pub(crate) fn connect_endpoints(config: &zenoh::Config) -> Vec<String> {
    config
        .get_json("connect/endpoints")
        .ok()
        .and_then(|j| serde_json::from_str(&j).ok())
        .unwrap_or_default()
}

fn has_router(session: &zenoh::Session) -> bool {
    session.info().routers_zid().wait().next().is_some()
}

/// Open the session (see the module's header). `stop` (Ctrl-C) ends a wait for a router.
///
/// # Errors
/// [`Ros2Error::Usage`] for a bad `ZENOH_*` variable or config value, a router that
/// cannot listen (its port taken by something that is not a Zenoh router), or a wait for a
/// router stopped.
pub fn open(env: &SessionEnv, stop: &StopFlag) -> Result<Ros2Session, Ros2Error> {
    let check = router_check(env.router_check_attempts.as_deref()).map_err(Ros2Error::Usage)?;
    let overrides = match env.config_override.as_deref() {
        Some(s) => parse_override(s).map_err(Ros2Error::Usage)?,
        None => Vec::new(),
    };
    let mut config = zenoh::Config::default();
    set(&mut config, "mode", "\"peer\"")?;
    set(&mut config, "scouting/multicast/enabled", "false")?;
    // A clock of the session's own (a hybrid logical clock: unique, increasing stamps) for
    // every sample it puts, as rmw_zenoh_cpp's default session config enables in every mode.
    set(
        &mut config,
        "timestamping/enabled",
        "{ router: true, peer: true, client: true }",
    )?;
    set(&mut config, "listen/endpoints", "[\"tcp/localhost:0\"]")?;
    set(
        &mut config,
        "connect/endpoints",
        &format!("[\"{DEFAULT_ROUTER}\"]"),
    )?;
    for (k, v) in &overrides {
        set(&mut config, k, v)?;
    }
    let endpoint = connect_endpoints(&config)
        .first()
        .cloned()
        .unwrap_or_else(|| DEFAULT_ROUTER.to_string());
    let session = open_with(config, "peer")?;
    let attempts = match check {
        RouterCheck::Skip => return Ok(Ros2Session::new(session, Router::Unchecked)),
        RouterCheck::Forever => u32::MAX,
        RouterCheck::Attempts(n) => n,
    };
    for attempt in 0..attempts {
        if attempt == 1 && check == RouterCheck::Forever {
            eprintln!(
                "[ratelab] waiting for a Zenoh router at {} (ZENOH_ROUTER_CHECK_ATTEMPTS=0) ...",
                ratelab_core::text::printable(&endpoint.to_string())
            );
        }
        let until = Instant::now() + Duration::from_secs(1);
        while Instant::now() < until {
            if stop.is_stopped() {
                return Err(Ros2Error::Usage(format!(
                    "stopped while waiting for a Zenoh router at {endpoint}"
                )));
            }
            if has_router(&session) {
                return Ok(Ros2Session::new(session, Router::Found(endpoint)));
            }
            std::thread::sleep(Duration::from_millis(20));
        }
    }
    // No router: be one, where ROS 2 nodes look for it.
    let _ = session.close().wait();
    let mut config = zenoh::Config::default();
    set(&mut config, "mode", "\"router\"")?;
    set(&mut config, "scouting/multicast/enabled", "false")?;
    set(
        &mut config,
        "listen/endpoints",
        &serde_json::to_string(&[&endpoint]).unwrap_or_default(),
    )?;
    set(&mut config, "listen/exit_on_failure", "true")?;
    set(&mut config, "connect/endpoints", "[]")?;
    let session = open_with(config, &format!("a Zenoh router on {endpoint}"))?;
    Ok(Ros2Session::new(session, Router::Embedded(endpoint)))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn router_check_attempts_read_as_rmw_zenoh_reads_them() {
        assert_eq!(router_check(None), Ok(RouterCheck::Attempts(1)));
        assert_eq!(router_check(Some(" ")), Ok(RouterCheck::Attempts(1)));
        assert_eq!(router_check(Some("3")), Ok(RouterCheck::Attempts(3)));
        assert_eq!(router_check(Some("0")), Ok(RouterCheck::Forever));
        assert_eq!(router_check(Some("-1")), Ok(RouterCheck::Skip));
        assert!(router_check(Some("x"))
            .unwrap_err()
            .contains("not an integer"));
    }

    #[test]
    fn overrides_are_key_value_pairs() {
        assert_eq!(
            parse_override(r#"mode="client"; connect/endpoints=["tcp/a:1"];"#),
            Ok(vec![
                ("mode".into(), "\"client\"".into()),
                ("connect/endpoints".into(), "[\"tcp/a:1\"]".into())
            ])
        );
        assert!(parse_override("mode").unwrap_err().contains("KEY=VALUE"));
        assert!(parse_override(&"a=1;".repeat(20_000)).is_err());
    }
}
