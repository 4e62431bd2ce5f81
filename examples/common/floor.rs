//! What the transport-floor examples (`zenoh_floor.rs`, `image_floor.rs`) share: a Zenoh
//! session opened as ratelab opens its own, a publisher's wait for its subscriber, and a
//! process's CPU time.

use ratelab::distributed::credentials::{Credentials, Role};
use ratelab::distributed::{open_session, zenoh, zenoh::Wait, Access};
use std::time::Duration;

/// A Zenoh session as ratelab opens one (TLS, access control) for process `who` of the
/// graph the credentials at `creds` were made for, listening on `listen` and connecting to
/// `connect`.
///
/// # Panics
/// When the credentials cannot be read or the session cannot open (an example's failure).
pub fn tls_session(
    listen: &[String],
    connect: &[String],
    creds: &str,
    who: &str,
) -> zenoh::Session {
    let credentials = Credentials::load(std::path::Path::new(creds)).expect("credentials");
    let access = Access {
        credentials: &credentials,
        role: &Role::Process(who.into()),
        spec: None,
    };
    open_session(listen, connect, access).expect("a session")
}

/// Wait until `publisher` has a matching subscriber, so that no first sample is put to
/// nobody.
pub fn wait_matched(publisher: &zenoh::pubsub::Publisher<'_>) {
    while !publisher
        .matching_status()
        .wait()
        .map(|m| m.matching())
        .unwrap_or(false)
    {
        std::thread::sleep(Duration::from_millis(10));
    }
}

/// CPU time (user and system) process `pid` has used so far, ns; `None` off Linux (it
/// reads `/proc/PID/stat`).
pub fn cpu_ns(pid: u32) -> Option<u64> {
    let stat = std::fs::read_to_string(format!("/proc/{pid}/stat")).ok()?;
    // The fields after the command's closing parenthesis; utime and stime are 14 and 15.
    let f: Vec<&str> = stat.rsplit_once(')')?.1.split_whitespace().collect();
    let ticks = f.get(11)?.parse::<u64>().ok()? + f.get(12)?.parse::<u64>().ok()?;
    // The kernel's USER_HZ is 100 on every Linux this runs on.
    Some(ticks * 10_000_000)
}
