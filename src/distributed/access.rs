//! What each identity of a graph across processes may say: Zenoh's access control (ACL),
//! built from the graph as data.
//!
//! Every session of the graph enforces it on what it receives (the ingress flow), by the
//! authenticated identity of the link it came on (the TLS certificate's common name,
//! [`super::credentials::Role::common_name`]); anything not allowed is dropped by Zenoh
//! before it reaches ratelab, so a sample from the wrong identity never reaches a topic's
//! buffer. The default is to deny:
//!
//! | who | may publish (`put`) | may declare |
//! |---|---|---|
//! | everyone | nothing | subscribers, queries, liveliness subscribers and queries on the graph's topics, tokens (`@node`, `@pub`, `@sub`, `@launcher`), figures (`@stats`), settings (`@setup`), log and end |
//! | the launcher | control (`@ctl/*`), the end (`@ended`), progress lines (`@log`) | its token `@launcher`, the settings' queryable `@setup` (and its replies); subscribers to the launch's own traffic: reports (`@up`), ticks (`@ticked`; linked directly, the processes' batches of them, `@progress`), the samples it passes on (`@via`), control and relayed reports |
//! | process `P` | the topics its nodes publish, on `@via/<topic>` for the launcher to pass on (in a launch linked directly, on the topic's own key), its reports `@up/P`, ticks `@ticked/P` (linked directly, also in batches for the launcher, `@progress/P`), counters `@stats/P` (and its counts alone, `@stats/P/counts`, for the launcher and `ratelab top`) | its nodes' tokens `@node/P/*`, their endpoints' `@pub`/`@sub` tokens; subscribers to its own control `@ctl/P` and relayed reports `@relayed/P` (linked directly, also to the other processes' ticks `@ticked/*`) |
//! | an observer | nothing | nothing more |
//! | the launcher's router | anything on the graph's keys | anything on the graph's keys |
//! | a host's router, heard by the launcher's router | the processes' kinds of keys (`@up`, `@ticked`, `@via`, `@stats`) | node and endpoint tokens; reads of any key |
//! | a host's router, heard by its clients | anything on the graph's keys | anything on the graph's keys |
//!
//! The launch's own traffic is the launcher's to hear: the router passes it on from the
//! one thread Zenoh runs it on, waiting for room in every subscriber's link, so a
//! subscriber that stops reading it (a frozen watcher) would hold the whole star. The
//! topics' own keys stay readable by everyone: under the real clock the launcher puts them
//! from a thread per receiving process (its outbox), so a frozen watcher subscribed to a
//! topic holds only that topic's process's outbox. Under the virtual clock a small sample
//! is put from Zenoh's thread (the outbox's direct lane, `launcher/outbox.rs`), so a
//! frozen watcher subscribed to it holds the whole star, as it held the lockstep before,
//! until Zenoh closes its link (5 s). Between two processes linked directly a sample
//! carries its tick's reports ([`crate::lockstep::reports_ride_on_samples`]), so whoever
//! may read a topic reads those too (compute times, a failure's text: what the run's
//! summary prints).
//!
//! A large launch is a star ([`super::open_router`]): every process and watcher links to the
//! launcher's router alone, so the check that matters is the router's, on each message
//! as it arrives from the identity that sent it; what the router then passes on arrives
//! at the others under the router's identity, which may say anything (the launcher
//! itself speaks through it, and it passes on only what it let in). A process therefore
//! still cannot publish another's topic, report or token, nor control anybody: the router
//! drops it before any other process sees it. Nobody but the launcher holds the router's
//! identity ([`super::credentials::Role::Router`]). Two sessions linked directly (a test,
//! the transport-floor examples) check each other by the same rules, and so do the
//! processes of a launch linked directly ([`super::open_linked_peer`]; `direct` below):
//! each process checks what every other sends it over their link, so a process still
//! cannot publish another's topic or report to it. There, and only there, a process may
//! put its own topics on their own keys (which every process and the router, for its
//! watchers, then accept from it) and hear the other processes' reports: in a star the
//! topic's key stays the router's, so that what it passes on to a process goes through
//! that process's outbox, never straight from Zenoh's one thread.
//!
//! Across hosts, a router on each other host ([`super::host_router`]) is the one link its
//! host's processes have: it checks each of them on arrival by these same rules, and
//! passes on to the launcher's router, under its own identity
//! ([`super::credentials::Role::HostRouter`]), only what their identities allowed. The
//! launcher's router hears that identity as the processes behind it (their kinds of keys,
//! never a topic's own key, a relayed report, control, the end or the settings), so its
//! certificate, exported with the processes', adds no power to theirs there; its clients
//! hear it as their router ([`acl`]'s `hearer`).
//!
//! A session that does not know the graph's shape (a watcher, before it asks the settings)
//! lets every process publish on any topic and declare any endpoint token: what it
//! receives moves nothing. Zenoh's own ACL semantics: a rule's key expression must
//! include the message's (`**` never matches a chunk starting with `@`, so each `@` key is
//! named), a deny wins, and with a default of deny both flows are filtered (so every
//! session may send anything on the graph's keys: the check is where it is received).

use super::credentials::Role;
use super::Keys;
use ratelab_runtime::graph::spec::GraphSpec;
use ratelab_runtime::graph::NodeId;
use serde_json::{json, Value};

/// The `@` keys of a graph (each must be named: `**` does not match them).
const AT_KEYS: [&str; 14] = [
    "@node/**",
    "@pub/**",
    "@sub/**",
    "@ctl/**",
    "@up/**",
    "@ticked/**",
    "@progress/**",
    "@relayed/**",
    "@via/**",
    "@stats/**",
    "@setup",
    "@ended",
    "@log",
    "@launcher",
];

/// The `@` keys everyone may read: all but the launch's own traffic (`@ctl`, `@up`,
/// `@ticked`, `@progress`, `@relayed`, `@via`), which only the launcher hears (a process its own control
/// and relayed reports, and linked directly the other processes' ticks).
const LAUNCH_TRAFFIC_FREE: [&str; 8] = [
    "@node/**",
    "@pub/**",
    "@sub/**",
    "@stats/**",
    "@setup",
    "@ended",
    "@log",
    "@launcher",
];

/// Every message kind Zenoh's access control knows.
const ALL_MESSAGES: [&str; 9] = [
    "put",
    "delete",
    "declare_subscriber",
    "query",
    "declare_queryable",
    "reply",
    "liveliness_token",
    "declare_liveliness_subscriber",
    "liveliness_query",
];

/// Zenoh's `access_control` configuration (JSON) for a session of the graph whose keys are
/// `keys`, placed in `processes`; `spec` gives which process publishes which topic and
/// owns which node (`None`: a watcher that does not know yet, see the module's header).
/// `hearer` is the session's own identity: the launcher's router ([`Role::Router`]) hears a
/// host's router as the processes behind it, every other session as its router. `direct`:
/// the launch's processes are linked directly ([`super::open_linked_peer`]), and each may
/// also put its topics on their own keys and hear the others' reports.
pub fn acl(
    keys: &Keys,
    processes: &[String],
    (spec, direct): (Option<&GraphSpec>, bool),
    hearer: &Role,
) -> Value {
    let p = keys.prefix();
    let at = |k: &str| format!("{p}/{k}");
    let mut rules = Vec::new();
    let mut policies = Vec::new();
    let mut rule_on = |flow: &str, id: String, messages: &[&str], key_exprs: Vec<String>| {
        rules.push(json!({
            "id": id,
            "messages": messages,
            "flows": [flow],
            "permission": "allow",
            "key_exprs": key_exprs,
        }));
        id
    };
    let mut all_keys = vec![format!("{p}/**")];
    all_keys.extend(AT_KEYS.iter().map(|k| at(k)));
    // `ratelab top` and the processes look for any graph's launcher, settings, figures,
    // nodes and end (what they find is this launch's: no other peer can connect).
    let discovery = [
        "@launcher",
        "@setup",
        "@stats/*",
        "@stats/*/counts",
        "@ended",
        "@node/*/*",
    ]
    .map(|k| format!("ratelab/*/{k}"));
    all_keys.extend(discovery.iter().cloned());
    // What everyone may read: the graph's topics, tokens, figures, settings, log and end;
    // not the launch's own traffic (see the module's header).
    let mut shared_reads = vec![format!("{p}/**")];
    shared_reads.extend(LAUNCH_TRAFFIC_FREE.iter().map(|k| at(k)));
    shared_reads.extend(discovery.iter().cloned());
    // With a default of deny, Zenoh filters what a session sends too: it sends anything
    // on the graph's keys (what it may send is bounded where it is received).
    let send = rule_on("egress", "send".into(), &ALL_MESSAGES, all_keys.clone());
    let mut rule = |id: String, messages: &[&str], key_exprs: Vec<String>| {
        rule_on("ingress", id, messages, key_exprs)
    };
    const READS: [&str; 4] = [
        "declare_subscriber",
        "query",
        "declare_liveliness_subscriber",
        "liveliness_query",
    ];
    let read = rule("read".into(), &READS, shared_reads);
    let read_all = rule("launcher-read".into(), &READS, all_keys.clone());
    let all_keys_for_reads = all_keys.clone();
    // The router passes on what it let in, and says what the launcher says.
    let routed = rule("router-routes".into(), &ALL_MESSAGES, all_keys);
    let mut roles = vec![
        Role::Launcher,
        Role::Observer,
        Role::Router,
        Role::HostRouter,
    ];
    roles.extend(processes.iter().cloned().map(Role::Process));
    let subjects: Vec<Value> = roles
        .iter()
        .map(|r| json!({ "id": subject_id(r), "cert_common_names": [r.common_name()] }))
        .collect();
    policies.push(json!({
        "rules": [send, read],
        "subjects": roles.iter().map(subject_id).collect::<Vec<_>>(),
    }));
    let mut own = |role: &Role, rules: Vec<String>| {
        policies.push(json!({ "rules": rules, "subjects": [subject_id(role)] }));
    };
    let launcher = vec![
        read_all,
        rule(
            "launcher-put".into(),
            &["put"],
            vec![at("@ctl/**"), at("@ended"), at("@log")],
        ),
        rule(
            "launcher-token".into(),
            &["liveliness_token"],
            vec![at("@launcher")],
        ),
        rule(
            "launcher-setup".into(),
            &["declare_queryable", "reply"],
            vec![at("@setup")],
        ),
    ];
    own(&Role::Launcher, launcher);
    if *hearer != Role::Router && !direct {
        // Its clients, and any session linked to it, hear it as their router; a process
        // linked directly is never behind one (it listens: anyone holding that certificate
        // could link to it).
        own(&Role::HostRouter, vec![routed.clone()]);
    }
    own(&Role::Router, vec![routed]);
    // What the launcher's router hears from a host's router: what its processes and
    // watchers may say (it checked each message by its sender's rules on arrival), by kind
    // of key, each with its bare prefix (a router forwards under declared prefixes), and
    // reads of any key. Never a topic's own key, a relayed report, control, the end, the
    // settings or the log: the host router's certificate, exported with the processes',
    // adds nothing to theirs there.
    let (puts, tokens, reads) = hosted_keys(keys, &all_keys_for_reads);
    let hosted = vec![
        rule("host-router-put".into(), &["put"], puts),
        rule("host-router-token".into(), &["liveliness_token"], tokens),
        rule("host-router-read".into(), &READS, reads),
    ];
    if *hearer == Role::Router {
        own(&Role::HostRouter, hosted);
    }
    for proc_name in processes {
        let (puts, tokens) = process_keys(keys, (spec, direct), proc_name);
        let role = Role::Process(proc_name.clone());
        let id = subject_id(&role);
        let mut reads = vec![keys.control(proc_name), keys.relayed(proc_name)];
        if direct {
            reads.push(keys.ticked("*"));
        }
        let mine = vec![
            rule(format!("{id}-put"), &["put"], puts),
            rule(format!("{id}-token"), &["liveliness_token"], tokens),
            rule(format!("{id}-read"), &READS, reads),
        ];
        own(&role, mine);
    }
    json!({
        "enabled": true,
        "default_permission": "deny",
        "rules": rules,
        "subjects": subjects,
        "policies": policies,
    })
}

/// What the launcher's router hears from a host's router ([`acl`]): (puts, tokens, reads).
/// The processes' kinds of keys, each with its bare prefix (a router forwards under
/// declared prefixes), and reads of `all_keys` and the bare `@` prefixes.
fn hosted_keys(keys: &Keys, all_keys: &[String]) -> (Vec<String>, Vec<String>, Vec<String>) {
    let p = keys.prefix();
    let both = |k: &&str| [format!("{p}/{k}/**"), format!("{p}/{k}")];
    let puts = ["@up", "@ticked", "@via", "@stats"]
        .iter()
        .flat_map(both)
        .collect();
    let tokens = ["@node", "@pub", "@sub"].iter().flat_map(both).collect();
    let mut reads = all_keys.to_vec();
    reads.extend(
        AT_KEYS
            .iter()
            .map(|k| format!("{p}/{}", k.trim_end_matches("/**"))),
    );
    (puts, tokens, reads)
}

/// Process `proc_name`'s own keys ([`acl`]): (puts, liveliness tokens). With the graph's
/// shape, its reports, ticks, figures and its topics on `@via` (and, `direct`, on their
/// own keys), its nodes' tokens; without (a watcher that does not know yet), any topic and
/// endpoint token.
fn process_keys(
    keys: &Keys,
    (spec, direct): (Option<&GraphSpec>, bool),
    proc_name: &str,
) -> (Vec<String>, Vec<String>) {
    let p = keys.prefix();
    let mut puts = vec![
        keys.up_from(proc_name),
        keys.ticked(proc_name),
        keys.stats(proc_name),
        keys.stats_counts(proc_name),
    ];
    if direct {
        // Its reports in batches, for the launcher to follow.
        puts.push(keys.progress(proc_name));
    }
    let mut tokens = vec![format!("{p}/@node/{proc_name}/**")];
    match spec {
        Some(spec) => {
            // On `@via`, for the router to pass on through its outbox
            // (`launcher/outbox.rs`); linked directly, on the topic's own key.
            for t in &spec.topics {
                if spec.process_of(t.publisher) == *proc_name {
                    puts.push(keys.via(&t.name));
                    if direct {
                        puts.push(keys.topic(&t.name));
                    }
                }
            }
            for (i, n) in spec.nodes.iter().enumerate() {
                if spec.process_of(NodeId(i)) == *proc_name {
                    tokens.push(format!("{p}/@pub/**/{}", n.name));
                    tokens.push(format!("{p}/@sub/**/{}", n.name));
                }
            }
        }
        None => {
            puts.push(format!("{p}/**"));
            puts.push(format!("{p}/@via/**"));
            tokens.push(format!("{p}/@pub/**"));
            tokens.push(format!("{p}/@sub/**"));
        }
    }
    (puts, tokens)
}

/// A role's subject id in the ACL: `launcher`, `observer`, `process-<NAME>`, `router`,
/// `host-router`.
fn subject_id(role: &Role) -> String {
    match role {
        Role::Launcher => "launcher".into(),
        Role::Observer => "observer".into(),
        Role::Process(p) => format!("process-{p}"),
        Role::Router => "router".into(),
        Role::HostRouter => "host-router".into(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn chapter() -> GraphSpec {
        GraphSpec::parse(ratelab_runtime::graph::spec::DEFAULT_GRAPH_TOML, "chapter").unwrap()
    }

    /// The key expressions `role` may `message` on (what a session receives from it).
    fn allowed(acl: &Value, role: &Role, message: &str) -> Vec<String> {
        let sid = subject_id(role);
        let rules: Vec<&str> = acl["policies"]
            .as_array()
            .unwrap()
            .iter()
            .filter(|p| p["subjects"].as_array().unwrap().iter().any(|s| s == &sid))
            .flat_map(|p| p["rules"].as_array().unwrap().iter())
            .map(|r| r.as_str().unwrap())
            .collect();
        acl["rules"]
            .as_array()
            .unwrap()
            .iter()
            .filter(|r| rules.contains(&r["id"].as_str().unwrap()))
            .filter(|r| {
                r["flows"]
                    .as_array()
                    .unwrap()
                    .iter()
                    .any(|f| f == "ingress")
            })
            .filter(|r| {
                r["messages"]
                    .as_array()
                    .unwrap()
                    .iter()
                    .any(|m| m == message)
            })
            .flat_map(|r| r["key_exprs"].as_array().unwrap().iter())
            .map(|k| k.as_str().unwrap().to_string())
            .collect()
    }

    #[test]
    fn each_process_publishes_only_its_own_topics_and_only_the_launcher_controls() {
        let spec = chapter();
        let keys = Keys::new(&spec.name);
        let procs: Vec<String> = spec.placement().into_iter().map(|(p, _)| p).collect();
        let acl = acl(&keys, &procs, (Some(&spec), false), &Role::Router);
        let p = keys.prefix();
        let robot = allowed(&acl, &Role::Process("robot".into()), "put");
        assert!(robot.contains(&format!("{p}/@via/obs")), "{robot:?}");
        // In a star a topic's own key is the router's (passed on from `@via`).
        assert!(!robot.contains(&format!("{p}/obs")), "{robot:?}");
        assert!(!robot.contains(&format!("{p}/action")), "{robot:?}");
        assert!(!robot.contains(&format!("{p}/@via/action")), "{robot:?}");
        let policy = allowed(&acl, &Role::Process("policy".into()), "put");
        assert!(policy.contains(&format!("{p}/@via/action")), "{policy:?}");
        assert!(!policy.contains(&format!("{p}/action")), "{policy:?}");
        assert!(
            !policy.iter().any(|k| k.contains("@ticked/robot")),
            "{policy:?}"
        );
        // Linked directly, a process also puts its own topics on their own keys, and
        // still never another's.
        let direct = super::acl(&keys, &procs, (Some(&spec), true), &Role::Router);
        let robot = allowed(&direct, &Role::Process("robot".into()), "put");
        for k in ["obs", "@via/obs"] {
            assert!(robot.contains(&format!("{p}/{k}")), "{k}: {robot:?}");
        }
        for k in ["action", "@via/action"] {
            assert!(!robot.contains(&format!("{p}/{k}")), "{k}: {robot:?}");
        }
        // And its own reports in batches for the launcher to follow: only linked
        // directly, and never another's.
        assert!(robot.contains(&keys.progress("robot")), "{robot:?}");
        assert!(!robot.contains(&keys.progress("policy")), "{robot:?}");
        let star_robot = allowed(&acl, &Role::Process("robot".into()), "put");
        assert!(
            !star_robot.iter().any(|k| k.contains("@progress")),
            "{star_robot:?}"
        );
        assert!(!policy.iter().any(|k| k.ends_with("obs")), "{policy:?}");
        assert!(!policy.iter().any(|k| k.contains("@ctl")), "{policy:?}");
        // Its figures, whole and its counts alone (for the launcher), never another's.
        for k in [keys.stats("policy"), keys.stats_counts("policy")] {
            assert!(policy.contains(&k), "{k}: {policy:?}");
        }
        for k in [keys.stats("robot"), keys.stats_counts("robot")] {
            assert!(!policy.contains(&k), "{k}: {policy:?}");
        }
        assert_eq!(
            allowed(&acl, &Role::Launcher, "put"),
            [
                format!("{p}/@ctl/**"),
                format!("{p}/@ended"),
                format!("{p}/@log")
            ]
        );
        assert!(allowed(&acl, &Role::Observer, "put").is_empty());
        assert!(allowed(&acl, &Role::Observer, "liveliness_token").is_empty());
        // Only the router hands on the lockstep's reports; it may say anything on the
        // graph's keys (it passes on what it let in).
        let relayed = format!("{p}/@relayed/**");
        let router_puts = allowed(&acl, &Role::Router, "put");
        assert!(router_puts.contains(&relayed), "{router_puts:?}");
        assert!(router_puts.contains(&format!("{p}/**")), "{router_puts:?}");
        // The launcher's router hears a host's router as the processes behind it: their
        // kinds of keys, never a topic's own key, a relayed report, control or the end.
        let hosted = allowed(&acl, &Role::HostRouter, "put");
        for k in ["@up/**", "@ticked/**", "@via/**", "@stats/**"] {
            assert!(hosted.contains(&format!("{p}/{k}")), "{k}: {hosted:?}");
        }
        for never in [
            "**",
            "obs",
            "action",
            "@relayed/**",
            "@ctl/**",
            "@ended",
            "@setup",
        ] {
            let key = format!("{p}/{never}");
            assert!(!hosted.contains(&key), "{key}: {hosted:?}");
        }
        // Its own clients hear it as their router.
        let client = super::acl(
            &keys,
            &procs,
            (Some(&spec), false),
            &Role::Process("robot".into()),
        );
        let from_it = allowed(&client, &Role::HostRouter, "put");
        assert!(from_it.contains(&format!("{p}/**")), "{from_it:?}");
        for role in [
            Role::Launcher,
            Role::Observer,
            Role::HostRouter,
            Role::Process("robot".into()),
            Role::Process("policy".into()),
        ] {
            let puts = allowed(&acl, &role, "put");
            assert!(!puts.iter().any(|k| k.contains("@relayed")), "{role:?}");
        }
        // A process's node tokens are under its own name only.
        let tokens = allowed(&acl, &Role::Process("policy".into()), "liveliness_token");
        assert!(
            tokens.contains(&format!("{p}/@node/policy/**")),
            "{tokens:?}"
        );
        assert!(
            !tokens.iter().any(|k| k.contains("@node/robot")),
            "{tokens:?}"
        );
    }

    #[test]
    fn only_the_launcher_subscribes_to_the_launch_s_own_traffic() {
        let spec = chapter();
        let keys = Keys::new(&spec.name);
        let procs: Vec<String> = spec.placement().into_iter().map(|(p, _)| p).collect();
        let p = keys.prefix();
        for (shape, direct) in [(Some(&spec), false), (None, false), (Some(&spec), true)] {
            let acl = acl(&keys, &procs, (shape, direct), &Role::Router);
            let subs = |role: &Role| allowed(&acl, role, "declare_subscriber");
            let launcher = subs(&Role::Launcher);
            let traffic = ["@via", "@up", "@ticked", "@progress", "@ctl", "@relayed"];
            for k in traffic {
                assert!(
                    launcher.contains(&format!("{p}/{k}/**")),
                    "{k}: {launcher:?}"
                );
            }
            let observer = subs(&Role::Observer);
            assert!(observer.contains(&format!("{p}/**")), "{observer:?}");
            assert!(observer.contains(&format!("{p}/@stats/**")), "{observer:?}");
            // An observer may hear any graph's figures, whole or its counts alone (`top`).
            for k in ["ratelab/*/@stats/*", "ratelab/*/@stats/*/counts"] {
                assert!(observer.contains(&k.to_string()), "{k}: {observer:?}");
            }
            assert!(
                !observer
                    .iter()
                    .any(|k| traffic.iter().any(|t| k.contains(t))),
                "{observer:?}"
            );
            let policy = subs(&Role::Process("policy".into()));
            let own: Vec<&String> = policy
                .iter()
                .filter(|k| traffic.iter().any(|t| k.contains(t)))
                .collect();
            // Its own control and relayed reports, and, linked directly, the others'
            // reports (it hears them itself); never `@via` or `@up`.
            let mut expected = vec![keys.control("policy"), keys.relayed("policy")];
            if direct {
                expected.push(keys.ticked("*"));
            }
            assert_eq!(own, expected.iter().collect::<Vec<_>>(), "{policy:?}");
        }
    }

    #[test]
    fn zenoh_accepts_the_configuration_with_and_without_the_graphs_shape() {
        let spec = chapter();
        let keys = Keys::new(&spec.name);
        let procs: Vec<String> = spec.placement().into_iter().map(|(p, _)| p).collect();
        for (shape, direct) in [(Some(&spec), false), (None, false), (Some(&spec), true)] {
            let mut c = zenoh::Config::default();
            c.insert_json5(
                "access_control",
                &acl(&keys, &procs, (shape, direct), &Role::Router).to_string(),
            )
            .unwrap();
        }
    }
}
