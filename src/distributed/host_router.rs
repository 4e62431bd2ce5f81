//! A router on another host (`ratelab router`): how a launch spans hosts as Zenoh deploys a
//! system, with a router on each host that its processes link to, and the routers linked to
//! each other.
//!
//! On the launcher's host every process links to the launcher's router ([`super::open_router`]).
//! On another host, `ratelab router --connect <the launcher's endpoint>` opens a Zenoh router
//! there, linked to the launcher's router and listening on the host (by default
//! [`super::DEFAULT_ENDPOINT`]); that host's processes (`ratelab process --connect
//! tls/127.0.0.1:7449`) and watchers link to it alone. So each host has one link across the
//! network, whatever its number of processes (a full mesh across two hosts of P and Q
//! processes would cross P·Q links, the star alone P + Q), and a host's processes reach each
//! other and the launcher through their own router, which Zenoh routes between.
//!
//! - **The same authentication and access control.** The router speaks TLS 1.3 with the
//!   launch's credentials as [`Role::HostRouter`] and checks every message its clients send
//!   on arrival, by the identity of the link it came on, with the graph's rules
//!   ([`super::access`]): a process behind it can publish only its own topics, as behind the
//!   launcher's router. It passes on to the launcher's router only what it let in.
//! - **Its lifetime is the launch's.** It waits for the launcher's liveliness token
//!   ([`LAUNCHER_WAIT`]), routes while the token lives, and returns once it is withdrawn
//!   (the launcher ended, or its host went away) or on a stop (Ctrl-C).
//!
//! Under the virtual clock a launch across hosts equals one process's run byte for byte;
//! under the real clock the processes must share the launcher's host (its monotonic clock),
//! as without a router.

use super::credentials::{Credentials, Role};
use super::liveliness::TokenWatch;
use super::{check_endpoint, open_as, Access, DistError, Keys, Mode};
use ratelab_runtime::graph::spec::GraphSpec;
use ratelab_runtime::scheduler::StopFlag;
use std::time::{Duration, Instant};
use zenoh::Wait;

/// How long the router waits, once linked to the launcher's router, for the launcher's
/// liveliness token: the launcher declares it as it starts, a moment after it listens, so
/// past this the endpoint is not a launch of this graph.
pub const LAUNCHER_WAIT: Duration = Duration::from_secs(10);

/// What `ratelab router` was given.
#[derive(Clone, Debug)]
pub struct HostRouterOptions {
    /// The graph file's bytes: its name names the keys routed, and its shape the access
    /// rules the router enforces ([`super::access::acl`]).
    pub graph_bytes: Vec<u8>,
    /// The graph file's name, for messages.
    pub graph_origin: String,
    /// The launcher's endpoints (`tls/HOST:PORT`): the router's one link off the host.
    pub connect: Vec<String>,
    /// Where the host's processes and watchers link to it (`tls/HOST:PORT`).
    pub listen: Vec<String>,
    /// The launch's credentials, holding [`Role::HostRouter`]'s identity (`launch
    /// --export-credentials FILE`).
    pub credentials: Credentials,
    /// Where the router says what happens to it (linked, the launch ended), one line each;
    /// `None`: nothing said.
    pub say: Option<fn(&str)>,
}

/// Check `opts` before anything opens: the graph parses, the credentials are this graph's
/// and hold a host router's identity, the endpoints are well formed.
///
/// # Errors
/// [`DistError::Usage`], one line naming what is wrong.
fn check_options(opts: &HostRouterOptions) -> Result<GraphSpec, DistError> {
    let spec = super::graph_file(&opts.graph_bytes, &opts.graph_origin)?;
    super::credentials_fit(&opts.credentials, &spec)?;
    opts.credentials.identity(&Role::HostRouter)?;
    if opts.connect.is_empty() {
        return Err(DistError::Usage(
            "--connect tls/HOST:PORT is required: the launcher's endpoint".into(),
        ));
    }
    if opts.listen.is_empty() {
        return Err(DistError::Usage(
            "--listen tls/HOST:PORT is required: where this host's processes link to the router"
                .into(),
        ));
    }
    for ep in &opts.connect {
        check_endpoint("--connect", ep, false)?;
    }
    for ep in &opts.listen {
        check_endpoint("--listen", ep, true)?;
        if ep.ends_with(":0") {
            return Err(DistError::Usage(format!(
                "--listen {ep}: port 0 means any port, and this host's processes must know the router's: give one"
            )));
        }
    }
    Ok(spec)
}

/// What ended a router's service.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Served {
    /// The launcher's token was withdrawn: the launch ended (or its host went away).
    LaunchEnded,
    /// Stopped (Ctrl-C, a signal).
    Stopped,
}

/// Serve as the router of this host for a launch until it ends: open a Zenoh router
/// listening on `opts.listen` and linked to the launcher's router at `opts.connect`,
/// wait for the launcher's token ([`LAUNCHER_WAIT`]), and route until it is withdrawn or
/// `stop` is set.
///
/// # Errors
/// [`DistError::Usage`], one line: bad options (the graph does not parse, the credentials
/// are not a host router's of this graph, an endpoint is malformed), an endpoint that
/// cannot be listened on, nobody (or another launch) at `connect`, no launcher of this
/// graph there within [`LAUNCHER_WAIT`]; else [`DistError::Zenoh`].
pub fn serve(opts: &HostRouterOptions, stop: &StopFlag) -> Result<Served, DistError> {
    let spec = check_options(opts)?;
    super::refusals::install();
    let access = Access {
        credentials: &opts.credentials,
        role: &Role::HostRouter,
        spec: Some(&spec),
    };
    let session = open_as((Mode::Router, false), &opts.listen, &opts.connect, access)?;
    let keys = Keys::new(&spec.name);
    // Seen once, then gone once withdrawn for good (Zenoh may withdraw it for a moment as
    // routes change: [`crate::liveliness`]).
    let (present, gone) = (StopFlag::new(), TokenWatch::new());
    let _launcher_watch = {
        let (present, gone) = (present.clone(), gone.clone());
        session
            .liveliness()
            .declare_subscriber(keys.launcher_token())
            .history(true)
            .callback(move |s| {
                if s.kind() == zenoh::sample::SampleKind::Put {
                    present.stop();
                }
                gone.note(s.kind());
            })
            .wait()?
    };
    let say = |line: String| {
        if let Some(say) = opts.say {
            say(&line);
        }
    };
    let since = Instant::now();
    while !present.is_stopped() {
        if stop.is_stopped() {
            return Ok(Served::Stopped);
        }
        if since.elapsed() > LAUNCHER_WAIT {
            return Err(DistError::Usage(format!(
                "no launcher of graph '{}' answered at {} within {} s (is the launch running there?)",
                spec.name,
                opts.connect.join(", "),
                LAUNCHER_WAIT.as_secs()
            )));
        }
        std::thread::sleep(Duration::from_millis(20));
    }
    same_rules(&session, &keys, &spec, opts)?;
    say(format!(
        "router for graph '{}' linked to the launcher at {}, listening on {}",
        spec.name,
        opts.connect.join(", "),
        opts.listen.join(", ")
    ));
    loop {
        if gone.is_gone() {
            say("the launch ended (or its host can no longer be reached): routing no more".into());
            return Ok(Served::LaunchEnded);
        }
        if stop.is_stopped() {
            return Ok(Served::Stopped);
        }
        std::thread::sleep(Duration::from_millis(50));
    }
}

/// Are the access rules this router enforces, from its graph file, the launcher's? The
/// rules follow the graph's shape (which process owns each node and publishes each topic);
/// the launcher's graph comes from its settings (`@setup`), asked for up to
/// [`LAUNCHER_WAIT`].
///
/// # Errors
/// [`DistError::Usage`], one line: the launcher never said its settings, or its graph
/// places nodes or topics otherwise than the router's file.
fn same_rules(
    session: &zenoh::Session,
    keys: &Keys,
    spec: &GraphSpec,
    opts: &HostRouterOptions,
) -> Result<(), DistError> {
    let since = Instant::now();
    let setup = loop {
        if let Some(setup) = super::monitor::ask_setup(session, &keys.setup()) {
            break setup;
        }
        if since.elapsed() > LAUNCHER_WAIT {
            return Err(DistError::Usage(format!(
                "the launcher at {} did not say its settings within {} s",
                opts.connect.join(", "),
                LAUNCHER_WAIT.as_secs()
            )));
        }
    };
    let theirs = GraphSpec::parse(&setup.graph_toml, "the launcher's graph")
        .map_err(|e| DistError::Usage(e.to_string()))?;
    let processes = &opts.credentials.processes;
    let rules =
        |g: &GraphSpec| super::access::acl(keys, processes, (Some(g), false), &Role::HostRouter);
    if rules(spec) != rules(&theirs) {
        return Err(DistError::Usage(format!(
            "{}: its nodes' processes or its topics' publishers differ from the launcher's graph '{}': give the router the launcher's graph file",
            opts.graph_origin, theirs.name
        )));
    }
    Ok(())
}
