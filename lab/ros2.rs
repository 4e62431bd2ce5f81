//! `ratelab ros2`: ros2cli's verbs on any rmw_zenoh graph (ratelab's own `--ros2` runs, or
//! ROS 2 nodes with `RMW_IMPLEMENTATION=rmw_zenoh_cpp`), without a ROS 2 installation. The
//! graph and its output are `ratelab::ros2::inspect`'s and `::echo`'s; this module parses
//! the command line, waits for what it asks for, and prints.

use anyhow::{anyhow, Result};
use clap::{Args, Subcommand};
use ratelab::ros2::{echo, inspect, subscription, type_description};
use ratelab::scheduler::StopFlag;
use std::io::Write;
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

/// `ratelab ros2`.
#[derive(Debug, Clone, Args)]
pub struct Ros2Args {
    /// The ROS 2 domain, 0-232 (default: ROS_DOMAIN_ID, else 0).
    #[arg(long, global = true, value_name = "ID")]
    pub domain: Option<String>,
    /// The Zenoh router to read the graph through (default tcp/localhost:7447, where
    /// rmw_zenoh's nodes find theirs).
    #[arg(long, global = true, value_name = "ENDPOINT")]
    pub connect: Option<String>,
    /// How long to wait for the graph's liveliness tokens, seconds.
    #[arg(long, global = true, default_value_t = 1.0, value_name = "S")]
    pub wait: f64,
    /// What to read.
    #[command(subcommand)]
    pub what: Ros2Command,
}

/// `ratelab ros2 …`.
#[derive(Debug, Clone, Subcommand)]
pub enum Ros2Command {
    /// Nodes: `node list`, `node info NODE`.
    #[command(subcommand)]
    Node(NodeVerb),
    /// Topics: `topic list [-t]`, `topic info TOPIC [-v]`, `topic echo|hz|bw TOPIC`.
    #[command(subcommand)]
    Topic(TopicVerb),
    /// The graph: a line per topic, publisher ──▶ topic [type] msg/s ──▶ subscribers, every
    /// second until Ctrl-C (`--once`: one measured second, then exit).
    Graph {
        /// Print once, after one second of measuring.
        #[arg(long)]
        once: bool,
        /// Stop after this many seconds (default: at Ctrl-C).
        #[arg(long, value_name = "S")]
        duration: Option<f64>,
    },
    /// Bags (rosbag2, MCAP storage): `bag info DIR`, `bag echo DIR`.
    #[command(subcommand)]
    Bag(BagVerb),
    /// Parameters: `param list [NODE]`, `param get NODE NAME`, `param set NODE NAME VALUE`
    /// (the nodes' parameter services, as `ros2 param` asks them).
    #[command(subcommand)]
    Param(ParamVerb),
}

/// `ratelab ros2 param …`.
#[derive(Debug, Clone, Subcommand)]
pub enum ParamVerb {
    /// The parameters' names of one node, or of every node (each under its name).
    List {
        /// The node (`/policy` or `policy`); none: every node.
        node: Option<String>,
        /// Hidden nodes too (a name beginning with `_`), as ros2cli's.
        #[arg(long = "include-hidden-nodes")]
        include_hidden_nodes: bool,
    },
    /// Set one parameter, as `ros2 param set` does (the value read as YAML: `20.0`); a set
    /// the node refuses is said on stderr, exit 0, as ros2cli's.
    Set {
        /// The node (`/policy` or `policy`).
        node: String,
        /// The parameter (`rate_hz`).
        name: String,
        /// Its new value (`20.0`, `true`, `[1, 2]`, `text`).
        value: String,
        /// A hidden node too (a name beginning with `_`), as ros2cli's.
        #[arg(long = "include-hidden-nodes")]
        include_hidden_nodes: bool,
    },
    /// One parameter's value, as `ros2 param get` prints it (`Double value is: 50.0`).
    Get {
        /// The node (`/policy` or `policy`).
        node: String,
        /// The parameter (`rate_hz`).
        name: String,
        /// A hidden node too (a name beginning with `_`), as ros2cli's.
        #[arg(long = "include-hidden-nodes")]
        include_hidden_nodes: bool,
    },
}

/// How long a node's parameter service is waited for.
const PARAM_TIMEOUT: Duration = Duration::from_secs(5);

/// `ratelab ros2 bag …`.
#[derive(Debug, Clone, Subcommand)]
pub enum BagVerb {
    /// What the bag holds, as `ros2 bag info` says it (times in UTC).
    Info {
        /// The bag's folder.
        dir: std::path::PathBuf,
    },
    /// Its messages as YAML, in the file's order, each after a `# TOPIC at T s` line.
    Echo {
        /// The bag's folder.
        dir: std::path::PathBuf,
        /// Only this topic's messages.
        #[arg(long)]
        topic: Option<String>,
        /// At most this many messages.
        #[arg(short = 'n', long = "max-count", value_name = "N")]
        count: Option<u64>,
    },
}

/// `ratelab ros2 node …`.
#[derive(Debug, Clone, Subcommand)]
pub enum NodeVerb {
    /// Every node's name (`/talker`), sorted; a name nodes share is listed for each, after a
    /// warning on stderr, as ros2cli's.
    List {
        /// Hidden nodes too (a name beginning with `_`), as ros2cli's `-a`.
        #[arg(short = 'a', long = "all")]
        all: bool,
        /// Only the number of nodes.
        #[arg(short = 'c', long = "count-nodes")]
        count: bool,
    },
    /// A node's publishers, subscribers, services and clients with their types (nodes that
    /// share the name: a warning on stderr, and one of them, as ros2cli's).
    Info {
        /// The node (`/talker` or `talker`).
        node: String,
        /// A hidden node, and hidden topics and services (a name part beginning with `_`).
        #[arg(long = "include-hidden")]
        include_hidden: bool,
    },
}

/// `ratelab ros2 topic …`.
#[derive(Debug, Clone, Subcommand)]
pub enum TopicVerb {
    /// Every topic (`-t`: with its type).
    List {
        /// Show each topic's type.
        #[arg(short = 't', long = "show-types")]
        types: bool,
        /// Only the number of topics.
        #[arg(short = 'c', long = "count-topics")]
        count: bool,
        /// Hidden topics too (a name part beginning with `_`), as ros2cli's.
        #[arg(long = "include-hidden-topics")]
        include_hidden: bool,
    },
    /// A topic's type and endpoint counts (`-v`: each endpoint with its node and QoS).
    Info {
        /// The topic (`/obs`).
        topic: String,
        /// Each endpoint with its node, type hash and QoS.
        #[arg(short, long)]
        verbose: bool,
    },
    /// Print a topic's messages as YAML, `---` between them, until Ctrl-C (a latched
    /// topic's stored messages first, at once).
    Echo {
        /// The topic.
        topic: String,
        /// Print one message and exit.
        #[arg(long)]
        once: bool,
        /// Print this many messages and exit.
        #[arg(short = 'n', long = "max-count", value_name = "N")]
        count: Option<u64>,
        /// Stop waiting after this many seconds, as ros2cli's `--timeout` (exit 0).
        #[arg(long, value_name = "S")]
        timeout: Option<f64>,
        /// The QoS to subscribe with.
        #[command(flatten)]
        qos: QosArgs,
    },
    /// Print a topic's bandwidth every second, until Ctrl-C.
    Bw {
        /// The topic.
        topic: String,
        /// Messages the figures are taken over (the newest).
        #[arg(
            short,
            long,
            default_value_t = 100,
            value_parser = clap::builder::RangedU64ValueParser::<usize>::new().range(1..)
        )]
        window: usize,
        /// Stop after this many seconds (default: at Ctrl-C).
        #[arg(long, value_name = "S")]
        duration: Option<f64>,
        /// The QoS to subscribe with.
        #[command(flatten)]
        qos: QosArgs,
    },
    /// Print a topic's rate every second, until Ctrl-C.
    Hz {
        /// The topic.
        topic: String,
        /// Intervals between messages the figures are taken over (the newest), as
        /// ros2cli's window.
        #[arg(
            short,
            long,
            default_value_t = 10_000,
            value_parser = clap::builder::RangedU64ValueParser::<usize>::new().range(1..)
        )]
        window: usize,
        /// Stop after this many seconds (default: at Ctrl-C).
        #[arg(long, value_name = "S")]
        duration: Option<f64>,
        /// The QoS to subscribe with.
        #[command(flatten)]
        qos: QosArgs,
    },
}

/// ros2cli's QoS flags of `echo`, `hz` and `bw` (`add_qos_arguments`): with neither, the
/// subscription takes what every publisher of the topic offers, as ros2cli's `choose_qos`
/// (`ratelab::ros2::subscription`).
#[derive(Debug, Clone, Default, Args)]
pub struct QosArgs {
    /// Quality of service reliability setting to subscribe with (overrides the
    /// sensor_data profile's best_effort; default: reliable when every publisher offers
    /// it, and any --qos-* flag turns that adaptation off, as ros2cli's).
    #[arg(
        long = "qos-reliability",
        value_name = "POLICY",
        value_parser = clap::builder::PossibleValuesParser::new(subscription::RELIABILITY_KEYS)
    )]
    pub reliability: Option<String>,
    /// Quality of service durability setting to subscribe with (overrides the sensor_data
    /// profile's volatile; default: transient_local when every publisher offers it, so a
    /// latched topic's stored messages print at once).
    #[arg(
        long = "qos-durability",
        value_name = "POLICY",
        value_parser = clap::builder::PossibleValuesParser::new(subscription::DURABILITY_KEYS)
    )]
    pub durability: Option<String>,
}

impl QosArgs {
    /// The flags, read.
    ///
    /// # Errors
    /// A value that is not one of the keys (clap refuses those first).
    fn flags(&self) -> Result<subscription::QosFlags> {
        let reliability = self.reliability.as_deref();
        let durability = self.durability.as_deref();
        Ok(subscription::QosFlags {
            reliability: reliability
                .map(subscription::reliability_from_key)
                .transpose()
                .map_err(|e| anyhow!(e))?,
            durability: durability
                .map(subscription::durability_from_key)
                .transpose()
                .map_err(|e| anyhow!(e))?,
        })
    }
}

/// The domain: `--domain`, else `ROS_DOMAIN_ID`, else 0.
fn domain(args: &Ros2Args) -> Result<u32> {
    let parse = |s: &str, what: &str| {
        ratelab::ros2::names::parse_domain(s).map_err(|e| anyhow!("{what}: {e}"))
    };
    match (&args.domain, std::env::var("ROS_DOMAIN_ID")) {
        (Some(d), _) => parse(d, "--domain"),
        (None, Ok(d)) if !d.is_empty() => parse(&d, "ROS_DOMAIN_ID"),
        _ => Ok(0),
    }
}

/// A refusal ros2cli makes by a verb's returned message (`return 'Node not found'`) or its
/// `RuntimeError` (`Cannot echo topic …`), which ros2cli's `main` hands to `sys.exit`: the
/// message alone on stderr, exit 1 ([`EXIT_REFUSED`]). ratelab's own refusals (a bad flag,
/// no router, a topic nobody publishes) stay `error: …`, exit 2.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Refused(pub String);

impl std::fmt::Display for Refused {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(&self.0)
    }
}

impl std::error::Error for Refused {}

/// The exit code of a [`Refused`] verb: ros2cli's, 1 (`sys.exit` of a message).
pub const EXIT_REFUSED: u8 = 1;

/// `message` as a [`Refused`] error.
fn refused(message: String) -> anyhow::Error {
    anyhow::Error::new(Refused(message))
}

/// ros2cli's warning `w` on stderr, before what it warns of is printed on stdout.
fn warn(w: &str) {
    let _ = writeln!(std::io::stderr(), "{w}");
}

/// Run `ratelab ros2 …` until done or `stop` (Ctrl-C).
///
/// # Errors
/// One line: a bad domain or wait, no router, a topic nobody publishes within the wait;
/// what ros2cli refuses with exit 1 as [`Refused`] (an unknown node or topic, a parameter
/// not set, a topic of two types to `echo`, `hz` or `bw`).
pub fn run(args: &Ros2Args, stop: StopFlag) -> Result<()> {
    if let Ros2Command::Bag(verb) = &args.what {
        return bag(verb, &stop);
    }
    let domain = domain(args)?;
    if !(args.wait.is_finite() && (0.0..=3600.0).contains(&args.wait)) {
        return Err(anyhow!(
            "--wait must be in [0, 3600] seconds, got {}",
            args.wait
        ));
    }
    let wait = Duration::from_secs_f64(args.wait);
    let env = ratelab::ros2::session::SessionEnv::from_process();
    let session = inspect::open(args.connect.as_deref(), &env)?;
    let g = inspect::seen(&session, domain, wait)?;
    let mut out = std::io::stdout().lock();
    match &args.what {
        Ros2Command::Node(verb) => node(&g, verb, &mut out)?,
        Ros2Command::Topic(TopicVerb::List {
            types,
            count,
            include_hidden,
        }) => {
            if *count {
                writeln!(out, "{}", inspect::topic_count(&g, *include_hidden))?
            } else {
                write!(out, "{}", inspect::topic_list(&g, *types, *include_hidden))?
            }
        }
        Ros2Command::Topic(TopicVerb::Info { topic, verbose }) => write!(
            out,
            "{}",
            inspect::topic_info(&g, topic, *verbose).map_err(refused)?
        )?,
        Ros2Command::Topic(TopicVerb::Echo {
            topic,
            once,
            count,
            timeout,
            qos,
        }) => {
            let limit = if *once { Some(1) } else { *count };
            let timeout = until("--timeout", *timeout)?;
            drop(out);
            echo_topic(
                &session,
                (&g, domain),
                (topic.as_str(), qos),
                (limit, timeout),
                &stop,
            )?;
        }
        Ros2Command::Topic(TopicVerb::Hz {
            topic,
            window,
            duration,
            qos,
        }) => {
            drop(out);
            let hz = Figures::Hz(inspect::Rate::new(*window));
            every_second(&session, &g, (topic.as_str(), qos), hz, *duration, &stop)?;
        }
        Ros2Command::Bag(_) => {}
        Ros2Command::Param(verb) => write!(out, "{}", param(&session, &g, domain, verb)?)?,
        Ros2Command::Graph { once, duration } => {
            drop(out);
            graph(&session, &g, *once, *duration, &stop)?;
        }
        Ros2Command::Topic(TopicVerb::Bw {
            topic,
            window,
            duration,
            qos,
        }) => {
            drop(out);
            let bw = Figures::Bw(inspect::Bandwidth::new(*window));
            every_second(&session, &g, (topic.as_str(), qos), bw, *duration, &stop)?;
        }
    }
    drop(session);
    Ok(())
}

/// `ratelab ros2 node …`: what ros2cli prints on `out`, its warning first on stderr.
///
/// # Errors
/// [`Refused`]: no node of that name (`node info`); `out` failed.
fn node(g: &inspect::Seen, verb: &NodeVerb, out: &mut impl Write) -> Result<()> {
    match verb {
        NodeVerb::List { all, count: true } => writeln!(out, "{}", inspect::node_count(g, *all))?,
        NodeVerb::List { all, count: false } => {
            let list = inspect::node_list(g, *all);
            if let Some(w) = list.warning {
                warn(w);
            }
            write!(out, "{}", list.names)?;
        }
        NodeVerb::Info {
            node,
            include_hidden,
        } => {
            let info = inspect::node_info(g, node, *include_hidden).map_err(refused)?;
            if let Some(w) = &info.warning {
                warn(w);
            }
            write!(out, "{}", info.text)?;
        }
    }
    Ok(())
}

/// `ratelab ros2 param …`'s output (a refused `set`: ros2cli's line on stderr, and none).
fn param(
    session: &inspect::Session,
    g: &inspect::Seen,
    domain: u32,
    verb: &ParamVerb,
) -> Result<String> {
    use ratelab::ros2::param_cli;
    // As ros2cli says a node the graph does not have, or hides.
    let known = |n: &str, hidden: bool| {
        inspect::known_node(g, n, hidden).ok_or_else(|| refused("Node not found".into()))
    };
    match verb {
        ParamVerb::List {
            node: Some(node),
            include_hidden_nodes,
        } => {
            let node = known(node, *include_hidden_nodes)?;
            let names = param_cli::list(session, domain, &node, PARAM_TIMEOUT)?;
            Ok(param_cli::list_text(&node, &names, false))
        }
        ParamVerb::List {
            node: None,
            include_hidden_nodes,
        } => {
            // Every node that serves its parameters, by name; a hidden one when asked.
            let mut nodes: Vec<String> = g
                .endpoints
                .iter()
                .filter(|e| e.kind == inspect::EndpointKind::Service)
                .filter_map(|e| e.topic.strip_suffix("/list_parameters").map(str::to_string))
                .filter(|n| {
                    let base = n.rsplit('/').next().unwrap_or_default();
                    *include_hidden_nodes || !ratelab::ros2::names::is_hidden_node(base)
                })
                .collect();
            nodes.sort();
            nodes.dedup();
            // A node that does not answer is said on stderr, and the others listed (ros2cli).
            let mut out = String::new();
            for node in nodes {
                match param_cli::list(session, domain, &node, PARAM_TIMEOUT) {
                    Ok(names) => out.push_str(&param_cli::list_text(&node, &names, true)),
                    Err(e) => eprintln!("{e}"),
                }
            }
            Ok(out)
        }
        ParamVerb::Set {
            node,
            name,
            value,
            include_hidden_nodes,
        } => {
            let node = known(node, *include_hidden_nodes)?;
            let value = param_cli::value_from_text(value).map_err(|e| anyhow!(e))?;
            let asked = (node.as_str(), name.as_str());
            match param_cli::set(session, domain, asked, value, PARAM_TIMEOUT)? {
                param_cli::SetAnswer::Set(said) => Ok(said + "\n"),
                // ros2cli prints a refusal on stderr and exits 0.
                param_cli::SetAnswer::Refused(said) => {
                    warn(&said);
                    Ok(String::new())
                }
            }
        }
        ParamVerb::Get {
            node,
            name,
            include_hidden_nodes,
        } => {
            let node = known(node, *include_hidden_nodes)?;
            let value = param_cli::get(session, domain, &node, name, PARAM_TIMEOUT)?;
            param_cli::get_text(value.as_ref()).map_err(refused)
        }
    }
}

/// The publisher of `topic` a subscriber takes its type and key from.
fn publisher<'a>(g: &'a inspect::Seen, topic: &str) -> Result<&'a inspect::EndpointEntity> {
    inspect::publishers(g, topic)
        .into_iter()
        .next()
        .ok_or_else(|| {
            anyhow!(
                "no publisher of '{}' on the domain (`ratelab ros2 topic list` lists the topics)",
                ratelab::text::printable(topic)
            )
        })
}

/// Subscribe to `topic` as ros2cli subscribes (`ratelab::ros2::subscription`): the QoS
/// chosen from what its publishers offer and the `qos` flags, ros2cli's lines about that
/// choice printed first on stdout. `on` gets each payload; the subscription (held while
/// listening) and the publisher whose key, type and hash it took. A topic of two types is
/// [`Refused`] first, in ros2cli's words, whichever verb asked.
fn listen<'a>(
    session: &inspect::Session,
    g: &'a inspect::Seen,
    topic: &str,
    qos: &QosArgs,
    on: impl Fn(Vec<u8>) + Send + Sync + 'static,
) -> Result<(subscription::Subscription, &'a inspect::EndpointEntity)> {
    // A topic of two types is refused, as ros2cli's `get_msg_class` refuses it.
    inspect::one_type(g, topic).map_err(refused)?;
    let p = publisher(g, topic)?;
    let offered: Vec<subscription::QosProfile> = inspect::publishers(g, topic)
        .iter()
        .map(|e| e.qos)
        .collect();
    let choice = subscription::choose_qos(&offered, qos.flags()?);
    if !choice.notes.is_empty() {
        let mut out = std::io::stdout().lock();
        for note in &choice.notes {
            writeln!(out, "{note}")?;
        }
        out.flush()?;
    }
    let sub = subscription::subscribe(session, p, &choice.qos, on)?;
    Ok((sub, p))
}

/// `ratelab ros2 topic echo`: at most `limit` messages, for at most `timeout`.
fn echo_topic(
    session: &inspect::Session,
    (g, domain): (&inspect::Seen, u32),
    (topic, qos): (&str, &QosArgs),
    (limit, timeout): (Option<u64>, Option<Duration>),
    stop: &StopFlag,
) -> Result<()> {
    let start = Instant::now();
    let (tx, rx) = crossbeam_channel::bounded::<Vec<u8>>(1024);
    let (_sub, p) = listen(session, g, topic, qos, move |bytes| {
        let _ = tx.try_send(bytes);
    })?;
    let (name, hash) = inspect::type_and_hash(p);
    let node = p.node.as_ref().map(inspect::fq_name);
    // A type not described here: its publisher's node is asked once for its description.
    let mut fetched: Option<Result<ratelab::ros2::type_description::TypeDescriptionMsg, String>> =
        None;
    let mut printed = 0u64;
    while !stop.is_stopped()
        && limit.is_none_or(|n| printed < n)
        && timeout.is_none_or(|t| start.elapsed() < t)
    {
        let Ok(bytes) = rx.recv_timeout(Duration::from_millis(100)) else {
            continue;
        };
        let decoded = match echo::decode(&name, &hash, &bytes) {
            Err(e) if e == echo::NOT_DESCRIBED => {
                let d = fetched.get_or_insert_with(|| {
                    let node = node.as_deref().ok_or("its publisher names no node")?;
                    let asked = (name.as_str(), hash.as_str());
                    let d = type_description::fetch(session, domain, node, asked, PARAM_TIMEOUT);
                    d.map_err(|why| format!("{e}, and {why}"))
                });
                d.as_ref()
                    .map_err(Clone::clone)
                    .and_then(|d| echo::decode_with(d, &bytes))
            }
            other => other,
        };
        let text = match decoded {
            Ok(v) => echo::yaml(&v),
            Err(why) => format!(
                "<{} {}: {} bytes, not decoded: {why}>\n",
                ratelab::text::printable(&name),
                hash,
                bytes.len()
            ),
        };
        let mut out = std::io::stdout().lock();
        writeln!(out, "{text}---")?;
        out.flush()?;
        printed += 1;
    }
    Ok(())
}

/// `FLAG S` (`--duration`, `--timeout`) as a time limit (`None`: until Ctrl-C).
///
/// # Errors
/// One line when `S` is not in (0, 1000000].
fn until(flag: &str, duration: Option<f64>) -> Result<Option<Duration>> {
    match duration {
        Some(s) if s.is_finite() && s > 0.0 && s <= 1e6 => Ok(Some(Duration::from_secs_f64(s))),
        Some(s) => Err(anyhow!("{flag} must be in (0, 1000000] seconds, got {s}")),
        None => Ok(None),
    }
}

/// What `hz` or `bw` keeps of the messages.
enum Figures {
    Hz(inspect::Rate),
    Bw(inspect::Bandwidth),
}

/// Subscribe to `topic` (with the QoS ros2cli chooses, [`listen`]) and print `figures`
/// every second, when they have something to say ([`inspect::Rate::report`],
/// [`inspect::Bandwidth::report`]), until `duration` or Ctrl-C; `bw` says first that it
/// subscribed, as ros2cli's.
fn every_second(
    session: &inspect::Session,
    g: &inspect::Seen,
    (topic, qos): (&str, &QosArgs),
    figures: Figures,
    duration: Option<f64>,
    stop: &StopFlag,
) -> Result<()> {
    let until = until("--duration", duration)?;
    let start = Instant::now();
    let bw = matches!(figures, Figures::Bw(_));
    let figures = Arc::new(Mutex::new(figures));
    let seen = figures.clone();
    let _sub = listen(session, g, topic, qos, move |bytes| {
        let t = start.elapsed().as_secs_f64();
        match &mut *seen.lock().unwrap_or_else(|e| e.into_inner()) {
            Figures::Hz(r) => r.arrived(t),
            Figures::Bw(b) => b.arrived(t, bytes.len()),
        }
    })?;
    if bw {
        let mut out = std::io::stdout().lock();
        writeln!(out, "Subscribed to [{}]", ratelab::text::printable(topic))?;
        out.flush()?;
    }
    let mut next = start + Duration::from_secs(1);
    while !stop.is_stopped() && until.is_none_or(|u| start.elapsed() < u) {
        std::thread::sleep(Duration::from_millis(20));
        if Instant::now() >= next {
            next += Duration::from_secs(1);
            let now = start.elapsed().as_secs_f64();
            let report = match &mut *figures.lock().unwrap_or_else(|e| e.into_inner()) {
                Figures::Hz(r) => r.report(),
                Figures::Bw(b) => b.report(now),
            };
            // Nothing to report (too few messages; for hz, none new): nothing printed, as
            // ros2cli prints nothing then.
            if let Some(r) = report {
                let mut out = std::io::stdout().lock();
                write!(out, "{r}")?;
                out.flush()?;
            }
        }
    }
    Ok(())
}

/// `ratelab ros2 bag …`: no session, the bag alone, read until done or `stop` (Ctrl-C,
/// SIGTERM).
fn bag(verb: &BagVerb, stop: &StopFlag) -> Result<()> {
    let stopped = || stop.is_stopped();
    use ratelab::ros2::bag_reader::Bag;
    let mut out = std::io::stdout().lock();
    match verb {
        BagVerb::Info { dir } => {
            let b = Bag::open(dir).map_err(|e| anyhow!(e))?;
            write!(out, "{}", b.info(&stopped).map_err(|e| anyhow!(e))?)?;
        }
        BagVerb::Echo { dir, topic, count } => {
            let b = Bag::open(dir).map_err(|e| anyhow!(e))?;
            let mut printed = 0u64;
            let mut failed = None;
            let note = b
                .messages(&stopped, |t, ty, hash, at_ns, bytes| {
                    if topic.as_deref().is_some_and(|want| want != t) {
                        return true;
                    }
                    if count.is_some_and(|n| printed >= n) {
                        return false;
                    }
                    let text = match echo::decode_named(ty, hash, bytes) {
                        Ok(v) => echo::yaml(&v),
                        Err(why) => format!(
                            "<{}: {} bytes, not decoded: {why}>\n",
                            ratelab::text::printable(ty),
                            bytes.len()
                        ),
                    };
                    let head = format!(
                        "# {} at {}.{:09} s\n",
                        ratelab::text::printable(t),
                        at_ns / 1_000_000_000,
                        at_ns % 1_000_000_000
                    );
                    if let Err(e) = writeln!(out, "{head}{text}---") {
                        failed = Some(e);
                        return false;
                    }
                    printed += 1;
                    true
                })
                .map_err(|e| anyhow!(e))?;
            if let Some(e) = failed {
                return Err(e.into());
            }
            if let Some(n) = note {
                eprintln!("ratelab: {n}");
            }
        }
    }
    Ok(())
}

/// `ratelab ros2 graph`: subscribe to every published topic, count its messages each second,
/// and print the graph with each topic's msg/s.
fn graph(
    session: &inspect::Session,
    g: &inspect::Seen,
    once: bool,
    duration: Option<f64>,
    stop: &StopFlag,
) -> Result<()> {
    let until = until("--duration", duration)?;
    let counts: Arc<Mutex<std::collections::BTreeMap<String, u64>>> = Arc::default();
    let mut subs = Vec::new();
    let mut topics: Vec<&str> = Vec::new();
    for e in &g.endpoints {
        if e.kind == inspect::EndpointKind::Publisher && !topics.contains(&e.topic.as_str()) {
            topics.push(&e.topic);
            let (counted, topic) = (counts.clone(), e.topic.clone());
            subs.push(inspect::subscribe(session, e, move |_| {
                *counted
                    .lock()
                    .unwrap_or_else(|e| e.into_inner())
                    .entry(topic.clone())
                    .or_default() += 1;
            })?);
        }
    }
    let start = Instant::now();
    let mut last = start;
    loop {
        std::thread::sleep(Duration::from_secs(1));
        let now = Instant::now();
        let secs = now.duration_since(last).as_secs_f64().max(1e-9);
        last = now;
        let counted = std::mem::take(&mut *counts.lock().unwrap_or_else(|e| e.into_inner()));
        // Every topic listened to has a rate, 0 when nothing came this second.
        let rates: std::collections::BTreeMap<String, f64> = topics
            .iter()
            .map(|t| {
                (
                    t.to_string(),
                    counted.get(*t).copied().unwrap_or(0) as f64 / secs,
                )
            })
            .collect();
        let mut out = std::io::stdout().lock();
        write!(out, "{}", inspect::graph_lines(g, &rates))?;
        if once || stop.is_stopped() || until.is_some_and(|u| start.elapsed() >= u) {
            break;
        }
        writeln!(out, "---")?;
        out.flush()?;
    }
    drop(subs);
    Ok(())
}
