//! Only the graph's own processes (issue 27): a peer without the launch's credentials
//! cannot connect, and an authenticated process cannot say what its identity may not
//! (Zenoh's mutual TLS and access control as `ratelab::distributed` configures them).

use crate::distributed::{bin, free_port};
use ratelab::distributed::credentials::{Credentials, Role};
use ratelab::distributed::wire::{encode_json, SampleHead, ToProcess, WireSample};
use ratelab::distributed::zenoh::{self, Wait};
use ratelab::distributed::{open_session, Access, Keys};
use ratelab::graph::spec::{GraphSpec, DEFAULT_GRAPH_TOML};
use ratelab::msg::{ForceMsg, MsgData};
use std::path::Path;
use std::process::{Child, Stdio};
use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};
use std::sync::Arc;
use std::time::{Duration, Instant};

fn chapter_processes() -> Vec<String> {
    vec!["robot".into(), "policy".into()]
}

/// A session of `role` with `creds`, listening on `listen`, connecting to `connect`.
fn session(
    creds: &Credentials,
    role: Role,
    spec: Option<&GraphSpec>,
    listen: &[String],
    connect: &[String],
) -> Result<zenoh::Session, String> {
    let access = Access {
        credentials: creds,
        role: &role,
        spec,
    };
    open_session(listen, connect, access).map_err(|e| e.to_string())
}

/// A plain Zenoh peer (no credentials) connecting to `connect`, with extra settings.
fn plain_peer(connect: &str, extra: &[(&str, String)]) -> Result<zenoh::Session, String> {
    let mut c = zenoh::Config::default();
    for (k, v) in [
        ("mode", "\"peer\"".to_string()),
        ("scouting/multicast/enabled", "false".into()),
        ("listen/endpoints", "[]".into()),
        ("connect/endpoints", format!("[\"{connect}\"]")),
        ("connect/exit_on_failure", "true".into()),
        ("connect/timeout_ms", "3000".into()),
    ]
    .into_iter()
    .chain(extra.iter().map(|(k, v)| (*k, v.clone())))
    {
        c.insert_json5(k, &v).unwrap();
    }
    zenoh::open(c).wait().map_err(|e| e.to_string())
}

#[test]
fn a_peer_without_the_launch_s_credentials_cannot_connect() {
    let _m = crate::machine::shared();
    let creds = Credentials::generate("cartpole", &chapter_processes()).unwrap();
    let port = free_port();
    let ep = format!("tls/127.0.0.1:{port}");
    let _launcher = session(&creds, Role::Launcher, None, std::slice::from_ref(&ep), &[]).unwrap();
    // The launch's own process connects.
    let ok = session(
        &creds,
        Role::Process("policy".into()),
        None,
        &[],
        std::slice::from_ref(&ep),
    );
    assert!(ok.is_ok(), "{:?}", ok.err());
    // Another launch's credentials (another CA): refused.
    let other = Credentials::generate("cartpole", &chapter_processes()).unwrap();
    let e = session(
        &other,
        Role::Process("policy".into()),
        None,
        &[],
        std::slice::from_ref(&ep),
    )
    .expect_err("another launch's identity is refused");
    assert!(e.contains("cannot open a Zenoh session"), "{e}");
    // Plain Zenoh over TCP to the port: refused.
    assert!(plain_peer(&format!("tcp/127.0.0.1:{port}"), &[]).is_err());
    // TLS trusting the launch's CA but showing no certificate of its own: refused.
    let dir = tempfile::tempdir().unwrap();
    let ca = dir.path().join("ca.pem");
    std::fs::write(&ca, &creds.ca).unwrap();
    let e = plain_peer(
        &ep,
        &[
            (
                "transport/link/tls/root_ca_certificate",
                serde_json::to_string(&ca).unwrap(),
            ),
            ("transport/link/tls/verify_name_on_connect", "false".into()),
        ],
    );
    assert!(e.is_err(), "a TLS peer without a certificate connected");
}

/// Counts of what a subscriber received.
fn counting(
    session: &zenoh::Session,
    key: &str,
) -> (Arc<AtomicUsize>, zenoh::pubsub::Subscriber<()>) {
    let n = Arc::new(AtomicUsize::new(0));
    let c = n.clone();
    let sub = session
        .declare_subscriber(key.to_string())
        .callback(move |_| {
            c.fetch_add(1, Ordering::SeqCst);
        })
        .wait()
        .unwrap();
    (n, sub)
}

/// In a star, a process's topic is put on `@via` for the launcher to pass on, never on its
/// own key.
#[test]
fn an_identity_publishes_only_what_the_graph_gives_it() {
    identity_publishes(false);
}

/// Linked directly, the process that publishes a topic may also put it on its own key
/// (the other processes hear it there), and still nobody else may: a session checking by
/// the rules of a launch linked directly ([`ratelab::distributed::open_linked_peer`]).
#[test]
fn linked_directly_an_identity_publishes_its_own_topics_on_their_keys_and_nothing_more() {
    identity_publishes(true);
}

/// Each identity's puts, tokens and control as the launcher's session receives them, the
/// session checking by the rules of a star or, `direct`, of a launch linked directly.
fn identity_publishes(direct: bool) {
    let _m = crate::machine::shared();
    let spec = GraphSpec::parse(DEFAULT_GRAPH_TOML, "chapter").unwrap();
    let keys = Keys::new(&spec.name);
    let creds = Credentials::generate(&spec.name, &chapter_processes()).unwrap();
    let ep = format!("tls/127.0.0.1:{}", free_port());
    // The launcher's session, which hears what processes publish for it to pass on
    // (`@via/action`), and here also the topic's own key and the robot's control key.
    let launcher = match direct {
        false => session(
            &creds,
            Role::Launcher,
            Some(&spec),
            std::slice::from_ref(&ep),
            &[],
        )
        .unwrap(),
        true => {
            let access = Access {
                credentials: &creds,
                role: &Role::Launcher,
                spec: Some(&spec),
            };
            ratelab::distributed::open_linked_peer(std::slice::from_ref(&ep), &[], access).unwrap()
        }
    };
    let (via, _v) = counting(&launcher, &keys.via("/action"));
    let (topic, _t) = counting(&launcher, &keys.topic("/action"));
    let (control, _c) = counting(&launcher, &keys.control("robot"));
    let tokens = Arc::new(AtomicUsize::new(0));
    let t = tokens.clone();
    let _live = launcher
        .liveliness()
        .declare_subscriber(format!("{}/@node/**", keys.prefix()))
        .callback(move |_| {
            t.fetch_add(1, Ordering::SeqCst);
        })
        .wait()
        .unwrap();
    let force = WireSample {
        head: SampleHead {
            seq: 0,
            stamp_ns: 0,
            origin_ns: None,
            sent_mono_ns: 0,
        },
        data: MsgData::new(ForceMsg { newtons: 10.0 }).to_bytes(),
    }
    .encode();
    let start = encode_json(&ToProcess::Start { start_mono_ns: 0 });
    type Counts = (usize, usize, usize, usize);
    // Publishes `n` forces on `@via/action` and on `/action`'s own key and `n` starts on
    // robot's control key as `role`, and declares a token for the policy's node; returns
    // how many of each arrived. It waits (at most 10 s each) for the counts `want` says
    // should arrive, not a fixed time a loaded machine may not fill, then 300 ms more in
    // which nothing else may arrive.
    let attempt = |role: Role, want: Counts| -> Counts {
        let before = [&via, &topic, &control, &tokens].map(|c| c.load(Ordering::SeqCst));
        let counts = || -> Counts {
            let now = [&via, &topic, &control, &tokens].map(|n| n.load(Ordering::SeqCst));
            (
                now[0] - before[0],
                now[1] - before[1],
                now[2] - before[2],
                now[3] - before[3],
            )
        };
        let wait_for = |ok: &dyn Fn(Counts) -> bool| {
            let until = Instant::now() + Duration::from_secs(10);
            while !ok(counts()) && Instant::now() < until {
                std::thread::sleep(Duration::from_millis(20));
            }
        };
        let s = session(&creds, role, None, &[], std::slice::from_ref(&ep)).unwrap();
        let token = s
            .liveliness()
            .declare_token(keys.node_token("policy", "policy"))
            .wait()
            .unwrap();
        // Declarations travel first: wait until the launcher's subscriptions reach this
        // session.
        let p = s.declare_publisher(keys.via("/action")).wait().unwrap();
        let direct = s.declare_publisher(keys.topic("/action")).wait().unwrap();
        let until = Instant::now() + Duration::from_secs(5);
        while !(p.matching_status().wait().unwrap().matching()
            && direct.matching_status().wait().unwrap().matching())
            && Instant::now() < until
        {
            std::thread::sleep(Duration::from_millis(20));
        }
        for _ in 0..20 {
            p.put(force.clone()).wait().unwrap();
            direct.put(force.clone()).wait().unwrap();
            s.put(keys.control("robot"), start.clone()).wait().unwrap();
        }
        // What should arrive while the token is declared (its declaration, if allowed), then
        // time for anything refused to arrive after all, the session still open.
        wait_for(&|(v, t, c, k): Counts| {
            v >= want.0 && t >= want.1 && c >= want.2 && k >= want.3.min(1)
        });
        std::thread::sleep(Duration::from_millis(300));
        drop(token);
        // The token's withdrawal, if its declaration arrived.
        wait_for(&|(_, _, _, k): Counts| k >= want.3);
        drop(s);
        std::thread::sleep(Duration::from_millis(300));
        counts()
    };
    // The robot's own identity (or an observer's) may not command the actuator, control a
    // process nor declare another process's node: nothing reaches the launcher's session.
    assert_eq!(
        attempt(Role::Process("robot".into()), (0, 0, 0, 0)),
        (0, 0, 0, 0)
    );
    assert_eq!(attempt(Role::Observer, (0, 0, 0, 0)), (0, 0, 0, 0));
    // The policy's identity may publish the force for the launcher to pass on, not on the
    // topic's own key (the router's) but linked directly, nor control; its own node's token
    // (`@node/policy/policy`) arrives declared, then withdrawn.
    let own_key = if direct { 20 } else { 0 };
    assert_eq!(
        attempt(Role::Process("policy".into()), (20, own_key, 0, 2)),
        (20, own_key, 0, 2)
    );
    // The launcher may control.
    assert_eq!(attempt(Role::Launcher, (0, 0, 20, 0)), (0, 0, 20, 0));
}

/// What the launch's own traffic is, only the launcher hears: a session of an observer's or
/// of a process's identity that subscribes to the samples passed on (`@via`), the reports
/// (`@up`, `@ticked`) or another process's control and relayed reports receives none, while
/// the launcher's own subscriber (and the process's to its own control) does.
#[test]
fn only_the_launcher_hears_the_launch_s_own_traffic() {
    let _m = crate::machine::shared();
    let spec = GraphSpec::parse(DEFAULT_GRAPH_TOML, "chapter").unwrap();
    let keys = Keys::new(&spec.name);
    let creds = Credentials::generate(&spec.name, &chapter_processes()).unwrap();
    let ep = format!("tls/127.0.0.1:{}", free_port());
    // The router's identity speaks for the launch, as the launcher's router does.
    let router = session(
        &creds,
        Role::Router,
        Some(&spec),
        std::slice::from_ref(&ep),
        &[],
    )
    .unwrap();
    let traffic = [
        keys.via("/obs"),
        keys.up_from("policy"),
        keys.ticked("policy"),
        keys.control("policy"),
        keys.relayed("policy"),
    ];
    let hear = |role: Role| -> Vec<usize> {
        let s = session(&creds, role, None, &[], std::slice::from_ref(&ep)).unwrap();
        let counters: Vec<_> = traffic.iter().map(|k| counting(&s, k)).collect();
        // Room for the subscriptions to reach the router (or be refused there).
        std::thread::sleep(Duration::from_millis(500));
        for _ in 0..10 {
            for k in &traffic {
                router.put(k.as_str(), b"x".to_vec()).wait().unwrap();
            }
        }
        let until = Instant::now() + Duration::from_secs(3);
        while Instant::now() < until {
            std::thread::sleep(Duration::from_millis(50));
        }
        counters
            .iter()
            .map(|(n, _)| n.load(Ordering::SeqCst))
            .collect()
    };
    assert_eq!(hear(Role::Launcher), vec![10; 5]);
    assert_eq!(hear(Role::Observer), vec![0; 5]);
    // The policy's process hears its own control and relayed reports, nothing else of it.
    assert_eq!(hear(Role::Process("policy".into())), vec![0, 0, 0, 10, 10]);
    assert_eq!(hear(Role::Process("robot".into())), vec![0; 5]);
}

/// A launch under attack by a holder of the credentials who forges as the wrong identity,
/// and by peers without them: the run is the undisturbed one, byte for byte, and the
/// launcher says it refused connections.
#[test]
fn forgeries_change_nothing_in_a_launch_and_refused_peers_are_said() {
    forgeries_change_nothing(false);
}

/// The same forgeries, and the processes, through a host's router (`ratelab router`,
/// issue 76 item 2) linked to the launcher's: the router checks its clients by the graph's
/// rules, so what it passes on under its own identity (which may say anything) is only
/// what theirs allowed, and the run is still the undisturbed one, byte for byte.
#[test]
fn forgeries_through_a_host_s_router_change_nothing() {
    forgeries_change_nothing(true);
}

/// A launch attacked as [`forgeries_change_nothing_in_a_launch_and_refused_peers_are_said`]
/// says; `via_router`: the forger and the processes link to a host's router linked to the
/// launcher's, not to the launcher's.
fn forgeries_change_nothing(via_router: bool) {
    let _m = crate::machine::alone();
    let dir = tempfile::tempdir().unwrap();
    let creds_file = dir.path().join("creds.toml");
    let port = free_port();
    let ep = format!("tls/127.0.0.1:{port}");
    let mut launcher = bin()
        .args(["launch", "--processes", "--no-spawn", "--clock", "virtual"])
        .args(["--duration", "10", "--listen", &ep, "--out"])
        .arg(dir.path())
        .arg("--export-credentials")
        .arg(&creds_file)
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let (rx, mut lines) = crate::distributed::listening(&mut launcher);
    // Peers without the launch's credentials.
    assert!(plain_peer(&format!("tcp/127.0.0.1:{port}"), &[]).is_err());
    let creds = Credentials::load(&creds_file).unwrap();
    let router = via_router.then(|| {
        let rep = format!("tls/127.0.0.1:{}", free_port());
        let mut router = bin()
            .args([
                "router",
                "--connect",
                &ep,
                "--listen",
                &rep,
                "--credentials",
            ])
            .arg(&creds_file)
            .stdout(Stdio::piped())
            .stderr(Stdio::null())
            .spawn()
            .unwrap();
        let rx = crate::distributed::stdout_lines(&mut router);
        let mut said = Vec::new();
        let linked = crate::distributed::wait_line(&rx, &mut said, "linked to the launcher", 30);
        assert!(linked, "{said:?}");
        (router, rep)
    });
    // Where the forger and the processes link: the launcher's router, or the host's.
    let ep = router.as_ref().map_or(ep, |(_, rep)| rep.clone());
    let spec = GraphSpec::parse(DEFAULT_GRAPH_TOML, "chapter").unwrap();
    let keys = Keys::new(&spec.name);
    // A holder of the file forging, as the robot's identity, what the policy and the
    // launcher say, for the whole run; and, at the launcher's router, as a host's router
    // (whose certificate the file holds too) what no process may say.
    let done = Arc::new(AtomicBool::new(false));
    let mut forgers = vec![(Role::Process("robot".into()), ep.clone())];
    if !via_router {
        forgers.push((Role::HostRouter, ep.clone()));
    }
    let forging: Vec<_> = forgers
        .into_iter()
        .map(|(role, at)| {
            let forger = session(&creds, role.clone(), None, &[], &[at]).unwrap();
            let (done, keys) = (done.clone(), keys.clone());
            std::thread::spawn(move || forge(&forger, &keys, &role, &done))
        })
        .collect();
    std::thread::sleep(Duration::from_millis(300));
    let nodes = crate::distributed::hand_started(&ep, &creds_file, Stdio::null);
    let status = launcher.wait().unwrap();
    done.store(true, Ordering::SeqCst);
    for f in forging {
        f.join().unwrap();
    }
    lines.extend(rx.try_iter());
    assert!(status.success(), "{lines:?}");
    for mut n in nodes {
        assert!(n.wait().unwrap().success());
    }
    if let Some((mut router, _)) = router {
        let ended = crate::distributed::exit_within(&mut router, 15);
        assert!(ended.success(), "the router ends with the launch");
    }
    // The refused peer is said (at once, then at most every 5 s, counted), with TLS's
    // reason; the launch's own processes and the forger (who holds the credentials) are
    // not refused: the peer's attempts (Zenoh retries for 3 s) are all there is.
    let refused: Vec<&String> = lines
        .iter()
        .filter(|l| l.contains("without this launch's credentials"))
        .collect();
    assert!((1..=2).contains(&refused.len()), "{lines:?}");
    let counted: u32 = refused
        .iter()
        .filter_map(|l| {
            l.split("refused ")
                .nth(1)?
                .split(' ')
                .next()?
                .parse::<u32>()
                .ok()
        })
        .sum();
    assert!((1..=5).contains(&counted), "{lines:?}");
    crate::distributed::assert_in_process_run_equals(
        "10",
        dir.path(),
        "the forged run differs from the undisturbed one",
    );
}

/// Forge, as `role`, until `done`: a force on `/action`'s own key, a stop of the policy's
/// process, the launch's end and a relayed report; as a process also the policy's tick and
/// a node token under the policy's name (what a host's router may pass on for a process,
/// so not forged as one).
fn forge(forger: &zenoh::Session, keys: &Keys, role: &Role, done: &AtomicBool) {
    let mut seq = 0;
    while !done.load(Ordering::SeqCst) {
        let force = WireSample {
            head: SampleHead {
                seq,
                stamp_ns: 0,
                origin_ns: None,
                sent_mono_ns: 0,
            },
            data: MsgData::new(ForceMsg { newtons: 10.0 }).to_bytes(),
        };
        let _ = forger.put(keys.topic("/action"), force.encode()).wait();
        let stop = ToProcess::Stop {
            at_ns: 0,
            need: Vec::new(),
        };
        let _ = forger
            .put(keys.control("policy"), encode_json(&stop))
            .wait();
        let _ = forger.put(keys.ended(), b"{}".to_vec()).wait();
        let _ = forger.put(keys.relayed("robot"), vec![0u8; 16]).wait();
        if matches!(role, Role::Process(_)) {
            let _ = forger
                .put(keys.ticked("policy"), br#"{"process":"policy","index":0,"node":1,"t_ns":0,"stop":true,"published":null,"failed":null}"#.to_vec())
                .wait();
            // A node token under the policy's name, declared and withdrawn.
            if let Ok(t) = forger
                .liveliness()
                .declare_token(keys.node_token("policy", "policy"))
                .wait()
            {
                std::thread::sleep(Duration::from_millis(5));
                drop(t);
            }
        }
        seq += 1;
        std::thread::sleep(Duration::from_millis(5));
    }
}

#[test]
fn bad_credentials_files_exit_2_in_one_line() {
    use std::os::unix::fs::PermissionsExt as _;
    let _m = crate::machine::shared();
    let dir = tempfile::tempdir().unwrap();
    let node = |creds: &std::path::Path, ep: &str| {
        bin()
            .args([
                "node",
                "--process",
                "policy",
                "--connect",
                ep,
                "--credentials",
            ])
            .arg(creds)
            .output()
            .unwrap()
    };
    let one_line = |o: &std::process::Output, needle: &str| {
        let err = String::from_utf8_lossy(&o.stderr);
        assert_eq!(o.status.code(), Some(2), "{err}");
        assert_eq!(err.trim_end().lines().count(), 1, "one line: {err}");
        assert!(err.contains(needle), "{err} lacks {needle:?}");
    };
    let ep = format!("tls/127.0.0.1:{}", free_port());
    one_line(&node(&dir.path().join("none.toml"), &ep), "--credentials");
    // Readable by others.
    let loose = crate::distributed::chapter_credentials(dir.path());
    std::fs::set_permissions(&loose, std::fs::Permissions::from_mode(0o644)).unwrap();
    one_line(&node(&loose, &ep), "other users may read it");
    // Expired.
    let mut c = Credentials::generate("cartpole", &chapter_processes()).unwrap();
    c.valid_until_unix_s = 1;
    let expired = dir.path().join("expired.toml");
    c.write(&expired, false).unwrap();
    one_line(&node(&expired, &ep), "expired");
    // Not credentials at all.
    let junk = dir.path().join("junk.toml");
    std::fs::write(&junk, "graph = [").unwrap();
    std::fs::set_permissions(&junk, std::fs::Permissions::from_mode(0o600)).unwrap();
    one_line(&node(&junk, &ep), "not a ratelab credentials file");
    // A malformed certificate: the file and the identity named, not rustls' internals.
    let mut c = Credentials::generate("cartpole", &chapter_processes()).unwrap();
    let id = c.identities.values_mut().next().unwrap();
    id.cert = id.cert.replacen("-----\nM", "-----\n!", 1);
    let bad_pem = dir.path().join("bad-pem.toml");
    c.write(&bad_pem, false).unwrap();
    let o = node(&bad_pem, &ep);
    one_line(&o, "bad-pem.toml");
    one_line(&o, "its certificate is not valid PEM");
    // Another launch's, at a running launch: its TLS handshake is refused.
    let port = free_port();
    let ep = format!("tls/127.0.0.1:{port}");
    let mut launcher = bin()
        .args(["launch", "--processes", "--no-spawn", "--clock", "virtual"])
        .args(["--listen", &ep, "--export-credentials"])
        .arg(dir.path().join("this.toml"))
        .stdout(Stdio::piped())
        .stderr(Stdio::null())
        .spawn()
        .unwrap();
    let (_rx, _lines) = crate::distributed::listening(&mut launcher);
    let other = dir.path().join("other");
    std::fs::create_dir_all(&other).unwrap();
    one_line(
        &node(&crate::distributed::chapter_credentials(&other), &ep),
        "were these credentials made by it?",
    );
    let _ = launcher.kill();
    let _ = launcher.wait();
}

/// Two network namespaces joined by a veth pair with `tc netem` delay on one end: two
/// "hosts" on one machine (removed when dropped).
struct TwoHosts {
    a: String,
    b: String,
}

impl TwoHosts {
    /// Make them, with addresses 10.77.0.1 (`a`) and 10.77.0.2 (`b`) and `delay_ms` on
    /// `b`'s end when the kernel has netem; `None` when this machine does not let the test
    /// make them (not root, no `ip`, no network namespaces).
    fn new(delay_ms: u32) -> Option<TwoHosts> {
        let tag = std::process::id();
        let hosts = TwoHosts {
            a: format!("rla{tag}"),
            b: format!("rlb{tag}"),
        };
        let ip = |args: &[&str]| {
            std::process::Command::new("ip")
                .args(args)
                .stdout(Stdio::null())
                .stderr(Stdio::null())
                .status()
                .is_ok_and(|s| s.success())
        };
        let (va, vb) = (format!("va{tag}"), format!("vb{tag}"));
        let delay = format!("{delay_ms}ms");
        let ok = ip(&["netns", "add", &hosts.a])
            && ip(&["netns", "add", &hosts.b])
            && ip(&["link", "add", &va, "type", "veth", "peer", "name", &vb])
            && ip(&["link", "set", &va, "netns", &hosts.a])
            && ip(&["link", "set", &vb, "netns", &hosts.b])
            && ip(&["-n", &hosts.a, "addr", "add", "10.77.0.1/24", "dev", &va])
            && ip(&["-n", &hosts.b, "addr", "add", "10.77.0.2/24", "dev", &vb])
            && ip(&["-n", &hosts.a, "link", "set", &va, "up"])
            && ip(&["-n", &hosts.b, "link", "set", &vb, "up"])
            && ip(&["-n", &hosts.a, "link", "set", "lo", "up"])
            && ip(&["-n", &hosts.b, "link", "set", "lo", "up"])
            // A program runs inside each (some containers make the namespaces but cannot
            // enter them).
            && ip(&["netns", "exec", &hosts.a, env!("CARGO_BIN_EXE_ratelab"), "--version"])
            && ip(&["netns", "exec", &hosts.b, env!("CARGO_BIN_EXE_ratelab"), "--version"]);
        if !ok {
            return None;
        }
        // The delay when the kernel has netem (not every one does).
        let delayed = std::process::Command::new("ip")
            .args(["netns", "exec", &hosts.b, "tc", "qdisc", "add", "dev", &vb])
            .args(["root", "netem", "delay", &delay])
            .stderr(Stdio::null())
            .status()
            .is_ok_and(|s| s.success());
        if !delayed {
            eprintln!("note: no tc netem on this kernel: the two hosts are joined without delay");
        }
        Some(hosts)
    }

    /// `ratelab ARGS` on host `ns`.
    fn ratelab(&self, ns: &str, args: &[&str]) -> std::process::Command {
        let mut c = std::process::Command::new("ip");
        c.args(["netns", "exec", ns, env!("CARGO_BIN_EXE_ratelab")])
            .args(args)
            .current_dir(crate::REPO);
        c
    }

    /// A launch on host `a` under `clock` for `secs`, listening on [`TWO_HOSTS_EP`], its
    /// processes started by hand, its credentials and metrics in `out`; its lines once it
    /// listens.
    fn launch(
        &self,
        clock: &str,
        secs: &str,
        out: &Path,
    ) -> (Child, std::sync::mpsc::Receiver<String>, Vec<String>) {
        let mut launcher = self
            .ratelab(
                &self.a,
                &["launch", "--processes", "--no-spawn", "--clock", clock],
            )
            .args(["--duration", secs, "--listen", TWO_HOSTS_EP, "--out"])
            .arg(out)
            .arg("--export-credentials")
            .arg(out.join("creds.toml"))
            .stdout(Stdio::piped())
            .stderr(Stdio::null())
            .spawn()
            .unwrap();
        let (rx, lines) = crate::distributed::listening(&mut launcher);
        (launcher, rx, lines)
    }

    /// `ratelab process --process PROCESS` on host `ns`, listening on `listen`, joining the
    /// launch with `creds`.
    fn node(&self, ns: &str, process: &str, listen: &str, creds: &Path) -> Child {
        self.ratelab(
            ns,
            &["process", "--process", process, "--connect", TWO_HOSTS_EP],
        )
        .args(["--listen", listen, "--credentials"])
        .arg(creds)
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .spawn()
        .unwrap()
    }
}

/// Where [`TwoHosts::launch`] listens (host `a`).
const TWO_HOSTS_EP: &str = "tls/10.77.0.1:7449";

/// Wait (at most 120 s) for `launcher` and then for its `nodes`, which must succeed; its
/// status, `lines` with every line it printed.
fn launch_ends(
    launcher: &mut Child,
    nodes: Vec<Child>,
    rx: &std::sync::mpsc::Receiver<String>,
    lines: &mut Vec<String>,
) -> std::process::ExitStatus {
    let until = Instant::now() + Duration::from_secs(120);
    let status = loop {
        if let Some(s) = launcher.try_wait().unwrap() {
            break s;
        }
        assert!(Instant::now() < until, "the launch did not end: {lines:?}");
        std::thread::sleep(Duration::from_millis(100));
    };
    lines.extend(rx.try_iter());
    for mut n in nodes {
        assert!(n.wait().unwrap().success());
    }
    status
}

impl Drop for TwoHosts {
    fn drop(&mut self) {
        for ns in [&self.a, &self.b] {
            let _ = std::process::Command::new("ip")
                .args(["netns", "del", ns])
                .status();
        }
    }
}

/// Across two "hosts" (network namespaces; 5 ms on one end where the kernel has netem): a
/// node on the other host joins with the launch's credentials and the lockstep run is the
/// in-process run, byte for byte; with another launch's it is refused.
#[test]
fn a_node_on_another_host_joins_with_the_credentials_and_only_with_them() {
    let _m = crate::machine::alone();
    let Some(hosts) = TwoHosts::new(5) else {
        eprintln!(
            "note: two-host test skipped: this machine does not let it make network namespaces (needs root and iproute2)"
        );
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let creds = dir.path().join("creds.toml");
    let (mut launcher, rx, mut lines) = hosts.launch("virtual", "5", dir.path());
    // Another launch's credentials, from the other host: refused.
    let other = dir.path().join("other");
    std::fs::create_dir_all(&other).unwrap();
    let other = crate::distributed::chapter_credentials(&other);
    let o = hosts
        .ratelab(
            &hosts.b,
            &["process", "--process", "policy", "--connect", TWO_HOSTS_EP],
        )
        .args(["--listen", "tls/10.77.0.2:0", "--credentials"])
        .arg(&other)
        .output()
        .unwrap();
    assert_eq!(
        o.status.code(),
        Some(2),
        "{}",
        String::from_utf8_lossy(&o.stderr)
    );
    // The launch's own: the robot beside the launcher, the policy on the other host.
    let nodes = vec![
        hosts.node(&hosts.a, "robot", "tls/10.77.0.1:0", &creds),
        hosts.node(&hosts.b, "policy", "tls/10.77.0.2:0", &creds),
    ];
    let status = launch_ends(&mut launcher, nodes, &rx, &mut lines);
    assert!(status.success(), "{lines:?}");
    assert!(
        lines
            .iter()
            .any(|l| l.contains("refused 1 connection without this launch's credentials")),
        "{lines:?}"
    );
    crate::distributed::assert_in_process_run_equals(
        "5",
        dir.path(),
        "the run across two hosts differs from the one in one process",
    );
    drop(hosts);
}

/// The real clock across two "hosts" (network namespaces on one machine: one
/// `CLOCK_MONOTONIC`, so the launcher's start instant and every stamp are shared, as
/// docs/distributed.md says they must be): the policy on the other host, 5 ms away where
/// the kernel has netem (on what that host sends: the force back). The run balances, and
/// every command crosses the link twice (the reading out, the force back), so the mean
/// sense→act latency is at least the delay.
#[test]
fn the_real_clock_across_two_hosts_balances_and_its_latency_carries_the_link() {
    let _m = crate::machine::alone();
    let Some(hosts) = TwoHosts::new(5) else {
        eprintln!(
            "note: two-host test skipped: this machine does not let it make network namespaces (needs root and iproute2)"
        );
        return;
    };
    let netem = std::process::Command::new("ip")
        .args(["netns", "exec", &hosts.b, "tc", "qdisc", "show"])
        .output()
        .is_ok_and(|o| String::from_utf8_lossy(&o.stdout).contains("netem"));
    let dir = tempfile::tempdir().unwrap();
    let creds = dir.path().join("creds.toml");
    let (mut launcher, rx, mut lines) = hosts.launch("real", "3", dir.path());
    let nodes = vec![
        hosts.node(&hosts.a, "robot", "tls/10.77.0.1:0", &creds),
        hosts.node(&hosts.b, "policy", "tls/10.77.0.2:0", &creds),
    ];
    let status = launch_ends(&mut launcher, nodes, &rx, &mut lines);
    assert!(status.success(), "{lines:?}");
    let m: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.path().join("metrics.json")).unwrap())
            .unwrap();
    assert_eq!(m["balanced"], true, "{m}");
    assert_eq!(m["clock"], "real");
    let mean = m["mean_latency_ms"].as_f64().unwrap();
    if netem {
        // The force comes back 5 ms late at least, on top of the sampling.
        assert!(mean >= 5.0, "mean sense→act {mean} ms across a 5 ms link");
    }
    assert!(mean > 0.0, "{m}");
    drop(hosts);
}
