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

/// Set `key` of `config` to the JSON5 `value`.
///
/// # Errors
/// [`Ros2Error::Usage`]: Zenoh refused it (named, with Zenoh's reason).
pub(crate) fn set(config: &mut zenoh::Config, key: &str, value: &str) -> Result<(), Ros2Error> {
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

/// How often the nodes' session asks whether a router has answered, within each of
/// `ZENOH_ROUTER_CHECK_ATTEMPTS`' seconds.
const PROBE_EVERY: Duration = Duration::from_millis(20);

/// One of `ZENOH_ROUTER_CHECK_ATTEMPTS`' attempts.
const ATTEMPT: Duration = Duration::from_secs(1);

/// Look for a router as `ZENOH_ROUTER_CHECK_ATTEMPTS` says (`check`): its attempts of one
/// second each (one for [`RouterCheck::Skip`]: a caller that may go on without a router
/// does not call this), `probe` tried at the start of each and again `every` after each
/// failed try within it. After the first attempt fails, when more are allowed, one line on
/// stderr says it waits and where (`endpoint`, printable). `stop` (Ctrl-C) is heard between
/// tries, every 20 ms. The nodes' session ([`open`]) and `ratelab ros2`'s readers
/// ([`super::inspect::open`]) both look so.
///
/// Returns `Ok(Ok(found))` for the first `probe` that finds it, `Ok(Err(last))` with the
/// last failure when every attempt has failed.
///
/// # Errors
/// [`Ros2Error::Usage`]: stopped while waiting.
pub(crate) fn look_for_router<T, E>(
    check: RouterCheck,
    endpoint: &str,
    stop: &StopFlag,
    every: Duration,
    probe: impl FnMut() -> Result<T, E>,
) -> Result<Result<T, E>, Ros2Error> {
    let attempts = match check {
        RouterCheck::Attempts(n) => n,
        RouterCheck::Forever => u32::MAX,
        RouterCheck::Skip => 1,
    };
    let waiting = || {
        let how_long = match check {
            RouterCheck::Forever => "0: until one answers".to_string(),
            _ => format!("{attempts}: up to {attempts} attempts a second apart"),
        };
        eprintln!(
            "[ratelab] waiting for a Zenoh router at {endpoint} (ZENOH_ROUTER_CHECK_ATTEMPTS={how_long}) ..."
        );
    };
    look_in_windows(attempts, ATTEMPT, every, stop, waiting, probe).map_err(|Stopped| {
        Ros2Error::Usage(format!(
            "stopped while waiting for a Zenoh router at {endpoint}"
        ))
    })
}

/// A wait ended by its stop flag.
#[derive(Debug, PartialEq, Eq)]
struct Stopped;

/// [`look_for_router`]'s loop, its attempt's length given (tests use milliseconds):
/// `waiting` is called once, after the first attempt fails, when more are allowed; the last
/// attempt ends at its last `probe`, without waiting out its window.
fn look_in_windows<T, E>(
    attempts: u32,
    window: Duration,
    every: Duration,
    stop: &StopFlag,
    waiting: impl FnOnce(),
    mut probe: impl FnMut() -> Result<T, E>,
) -> Result<Result<T, E>, Stopped> {
    let mut waiting = Some(waiting);
    let mut attempt = 0;
    loop {
        attempt += 1;
        let window_end = Instant::now() + window;
        let failed = loop {
            let failed = match probe() {
                Ok(found) => return Ok(Ok(found)),
                Err(e) => e,
            };
            if stop.is_stopped() {
                return Err(Stopped);
            }
            let next = Instant::now() + every;
            if next >= window_end {
                break failed;
            }
            sleep_until(next, stop)?;
        };
        if attempt >= attempts.max(1) {
            return Ok(Err(failed));
        }
        if let Some(say) = waiting.take() {
            say();
        }
        sleep_until(window_end, stop)?;
    }
}

/// Sleep until `until`, hearing `stop` every 20 ms.
fn sleep_until(until: Instant, stop: &StopFlag) -> Result<(), Stopped> {
    loop {
        if stop.is_stopped() {
            return Err(Stopped);
        }
        let left = until.saturating_duration_since(Instant::now());
        if left.is_zero() {
            return Ok(());
        }
        std::thread::sleep(left.min(Duration::from_millis(20)));
    }
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
    if check == RouterCheck::Skip {
        return Ok(Ros2Session::new(session, Router::Unchecked));
    }
    let shown = ratelab_core::text::printable(&endpoint).into_owned();
    let probe = || has_router(&session).then_some(()).ok_or(());
    let looked = look_for_router(check, &shown, stop, PROBE_EVERY, probe)?;
    if looked.is_ok() {
        return Ok(Ros2Session::new(session, Router::Found(endpoint)));
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

    /// A probe that fails `fails` times, then finds the router; it counts its calls.
    fn probe_failing(
        fails: usize,
        calls: &std::cell::Cell<usize>,
    ) -> impl FnMut() -> Result<(), usize> + '_ {
        move || {
            calls.set(calls.get() + 1);
            if calls.get() > fails {
                Ok(())
            } else {
                Err(calls.get())
            }
        }
    }

    #[test]
    fn a_router_is_looked_for_in_attempts_each_a_window_long() {
        let stop = StopFlag::default();
        let ms = Duration::from_millis;
        let said = std::cell::Cell::new(0);
        let say = || said.set(said.get() + 1);
        // One attempt, probed once a window: one probe, no waiting line, the failure kept.
        let calls = std::cell::Cell::new(0);
        let began = Instant::now();
        let r = look_in_windows(1, ms(5000), ms(5000), &stop, say, probe_failing(9, &calls));
        assert_eq!((r, calls.get(), said.get()), (Ok(Err(1)), 1, 0));
        assert!(
            began.elapsed() < ms(2500),
            "the last attempt does not wait out its window"
        );
        // Three attempts: three probes a window apart, the waiting line once, the last
        // failure returned.
        let calls = std::cell::Cell::new(0);
        let began = Instant::now();
        let r = look_in_windows(3, ms(30), ms(30), &stop, say, probe_failing(9, &calls));
        assert_eq!((r, calls.get(), said.get()), (Ok(Err(3)), 3, 1));
        assert!(began.elapsed() >= ms(60));
        // Found at the third probe of the first window (seconds long: long before it ends,
        // however loaded the machine): no waiting line.
        let calls = std::cell::Cell::new(0);
        let r = look_in_windows(2, ms(10_000), ms(5), &stop, say, probe_failing(2, &calls));
        assert_eq!((r, calls.get(), said.get()), (Ok(Ok(())), 3, 1));
        // Probed every 10 ms in a 100 ms window: at most ten probes, the last failure kept.
        let calls = std::cell::Cell::new(0);
        let r = look_in_windows(1, ms(100), ms(10), &stop, || {}, probe_failing(99, &calls));
        assert!(
            r == Ok(Err(calls.get())) && (1..=10).contains(&calls.get()),
            "{}",
            calls.get()
        );
        // Stopped: heard after the probe that failed, however many attempts are allowed.
        stop.stop();
        let calls = std::cell::Cell::new(0);
        let r = look_in_windows(
            u32::MAX,
            ms(1000),
            ms(1000),
            &stop,
            || {},
            probe_failing(9, &calls),
        );
        assert_eq!((r, calls.get()), (Err(Stopped), 1));
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
