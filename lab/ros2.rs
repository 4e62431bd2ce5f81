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
    /// How long to wait for the graph's liveliness tokens, seconds in [0, 3600] (default 1).
    #[arg(long, global = true, value_name = "S", value_parser = wait_s, allow_negative_numbers = true)]
    pub wait: Option<Duration>,
    /// ros2cli's `--no-daemon`, taken so that ros2 commands and scripts carry over as they
    /// are: ratelab never uses a daemon (each command reads the graph itself), so it changes
    /// nothing.
    #[arg(long, global = true)]
    pub no_daemon: bool,
    /// The program's global `--headless`, which means nothing here (ros2cli's verbs print
    /// as they go, with no lab to leave out): declared on `ros2` itself, hidden, so that
    /// clap neither shows it in any `ros2` help nor hands it down to the verbs, which refuse
    /// it as any flag they do not know; given before the verb (or before `ros2`), [`run`]
    /// refuses it.
    #[arg(long, hide = true)]
    pub headless: bool,
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
    /// Topics: `topic list [-t|-v]`, `topic info TOPIC [-v]`, `topic echo|hz|bw TOPIC`.
    #[command(subcommand)]
    Topic(TopicVerb),
    /// The graph: a line per topic, publisher ──▶ topic [type] msg/s ──▶ subscribers, every
    /// second until Ctrl-C (`--once`: one measured second, then exit).
    Graph {
        /// Print once, after one second of measuring.
        #[arg(long)]
        once: bool,
        /// Stop after this many seconds, in (0, 1000000] (default: at Ctrl-C).
        #[arg(long, value_name = "S", value_parser = time_limit, allow_negative_numbers = true)]
        duration: Option<Duration>,
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
    /// Its messages as YAML, in the file's order, each after a `# TOPIC at T s` line; a
    /// type ratelab has no description of is decoded by the ros2msg schema the bag carries.
    Echo {
        /// The bag's folder.
        dir: std::path::PathBuf,
        /// Only this topic's messages (a relative name, `obs`, is `/obs`).
        #[arg(long)]
        topic: Option<String>,
        /// At most this many messages.
        #[arg(short = 'n', long = "max-count", value_name = "N")]
        count: Option<u64>,
    },
    /// ros2cli's `bag record`: not here (refused in one line saying how ratelab writes a bag).
    #[command(hide = true)]
    Record {
        /// Whatever it was given.
        #[arg(trailing_var_arg = true, allow_hyphen_values = true)]
        rest: Vec<String>,
    },
    /// ros2cli's `bag play`: not here (refused in one line saying what plays one).
    #[command(hide = true)]
    Play {
        /// Whatever it was given.
        #[arg(trailing_var_arg = true, allow_hyphen_values = true)]
        rest: Vec<String>,
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
    /// Every topic (`-t`: with its type; `-v`: published and subscribed topics with their
    /// endpoint counts).
    List {
        /// Show each topic's type.
        #[arg(short = 't', long = "show-types")]
        types: bool,
        /// List full details about each topic, as ros2cli's `-v`: a `Published topics:` and
        /// a `Subscribed topics:` section, ` * /topic [type] N publisher(s)` each.
        #[arg(short = 'v', long = "verbose")]
        verbose: bool,
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
    /// topic's stored messages first, at once). A topic only subscribed to so far is
    /// listened to for publishers to come; one no node has is refused, as ros2cli's (its
    /// warning on stdout, `Could not determine the type for the passed topic`, exit 1).
    Echo {
        /// The topic.
        topic: String,
        /// Print one message and exit.
        #[arg(long)]
        once: bool,
        /// Print this many messages and exit.
        #[arg(short = 'n', long = "max-count", value_name = "N")]
        count: Option<u64>,
        /// Stop waiting after this many seconds, in (0, 1000000], as ros2cli's `--timeout`
        /// (exit 0).
        #[arg(long, value_name = "S", value_parser = time_limit, allow_negative_numbers = true)]
        timeout: Option<Duration>,
        /// The QoS to subscribe with.
        #[command(flatten)]
        qos: QosArgs,
    },
    /// Print a topic's bandwidth every second, until Ctrl-C (a topic no node has yet is
    /// waited for, after ros2cli's warning).
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
        /// Stop after this many seconds, in (0, 1000000] (default: at Ctrl-C).
        #[arg(long, value_name = "S", value_parser = time_limit, allow_negative_numbers = true)]
        duration: Option<Duration>,
        /// The QoS to subscribe with.
        #[command(flatten)]
        qos: QosArgs,
    },
    /// Print a topic's rate every second, until Ctrl-C (a topic no node has yet is
    /// waited for, after ros2cli's warning).
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
        /// Stop after this many seconds, in (0, 1000000] (default: at Ctrl-C).
        #[arg(long, value_name = "S", value_parser = time_limit, allow_negative_numbers = true)]
        duration: Option<Duration>,
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
/// `RuntimeError` (`Cannot echo topic …`, `Could not determine the type for the passed
/// topic`), which ros2cli's `main` hands to `sys.exit`: the message alone on stderr, exit 1
/// ([`EXIT_REFUSED`]). ratelab's own refusals (a bad flag, no router) stay `error: …`,
/// exit 2.
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

/// How a verb that Ctrl-C (or SIGTERM: ratelab does not tell them apart) stopped ends, as
/// ros2cli's does: its exit code, nothing said. ros2cli's `main` (`ros2cli/cli.py`) catches
/// the `KeyboardInterrupt` that reaches it and returns `signal.SIGINT`, which `sys.exit`
/// makes exit code 2 ([`EXIT_KEYBOARD_INTERRUPT`]): `echo` and `bw` let it reach `main`, and
/// so do `hz` and `bw` while they wait for the topic (`get_msg_class(blocking=True)` sleeps
/// outside any `try`); `hz` catches it around its spin once subscribed and ends 0
/// (`verb/hz.py`, `except (KeyboardInterrupt, ExternalShutdownException): pass`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Interrupted(pub u8);

impl std::fmt::Display for Interrupted {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "interrupted (exit {})", self.0)
    }
}

impl std::error::Error for Interrupted {}

/// ros2cli's exit code when a `KeyboardInterrupt` reaches its `main`: `signal.SIGINT`, 2.
pub const EXIT_KEYBOARD_INTERRUPT: u8 = 2;

/// `code` as an [`Interrupted`] error.
fn interrupted(code: u8) -> anyhow::Error {
    anyhow::Error::new(Interrupted(code))
}

/// What ros2cli's `get_msg_class` says on stdout when no node has the topic (ros2topic's
/// `api/__init__.py`), the topic as it was given.
fn not_published_yet(topic: &str) -> String {
    format!(
        "WARNING: topic [{}] does not appear to be published yet",
        ratelab::text::printable(topic)
    )
}

/// ros2cli's `echo` refusal when no node has the topic (`verb/echo.py`: its `RuntimeError`,
/// exit 1).
pub const NO_TYPE: &str = "Could not determine the type for the passed topic";

/// `line` on stdout at once (ros2cli's stdout is line-buffered).
fn say(line: &str) -> Result<()> {
    let mut out = std::io::stdout().lock();
    writeln!(out, "{line}")?;
    out.flush()?;
    Ok(())
}

/// `topic` as ros2cli's `get_msg_class` looks it up: rclpy's `expand_topic_name` in its
/// node's namespace, `/`, so a relative name (`chatter`) is `/chatter`. (`~` and
/// substitutions, which name ros2cli's own node, are left as given: no such topic.)
fn expanded(topic: &str) -> String {
    if topic.starts_with(['/', '~', '{']) {
        topic.to_string()
    } else {
        format!("/{topic}")
    }
}

/// `message` as a [`Refused`] error.
fn refused(message: String) -> anyhow::Error {
    anyhow::Error::new(Refused(message))
}

/// ros2cli's warning `w` on stderr, before what it warns of is printed on stdout.
fn warn(w: &str) {
    let _ = writeln!(std::io::stderr(), "{w}");
}

/// Run `ratelab ros2 …` until done or `stop` (Ctrl-C); `headless`: the program's
/// `--headless` was given before `ros2`.
///
/// # Errors
/// One line: `--headless` given, a bad domain or wait, no router; what ros2cli refuses
/// with exit 1 as [`Refused`] (an unknown node or topic, a parameter not set, a topic of two types to
/// `echo`, `hz` or `bw`, a topic no node has to `echo`); `echo`, `hz` or `bw` stopped by
/// Ctrl-C as [`Interrupted`], with ros2cli's exit code.
pub fn run(args: &Ros2Args, headless: bool, stop: StopFlag) -> Result<()> {
    if headless || args.headless {
        anyhow::bail!(
            "--headless: `ratelab ros2` prints as ros2cli does, with no lab to run headless"
        );
    }
    if let Ros2Command::Bag(verb) = &args.what {
        // A bag is read from its files: the graph's settings would change nothing (record
        // and play are refused for what they are first).
        let given = [
            ("--domain", args.domain.is_some()),
            ("--connect", args.connect.is_some()),
            ("--wait", args.wait.is_some()),
        ];
        let reads = !matches!(verb, BagVerb::Record { .. } | BagVerb::Play { .. });
        if let Some((flag, _)) = given.iter().find(|(_, given)| *given && reads) {
            anyhow::bail!("{flag}: `ros2 bag` reads the bag's files, not a graph, so it takes no graph settings");
        }
        return bag(verb, &stop);
    }
    let domain = domain(args)?;
    let wait = args.wait.unwrap_or(DEFAULT_WAIT);
    let env = ratelab::ros2::session::SessionEnv::from_process();
    let session = inspect::open(args.connect.as_deref(), &env, &stop)?;
    let g = inspect::seen(&session, domain, wait)?;
    let mut out = std::io::stdout().lock();
    match &args.what {
        Ros2Command::Node(verb) => node(&g, verb, &mut out)?,
        Ros2Command::Topic(TopicVerb::List {
            types,
            count,
            include_hidden,
            verbose,
        }) => {
            // ros2cli: `-c` first, then `-v` (whatever `-t` says), then the plain list.
            if *count {
                writeln!(out, "{}", inspect::topic_count(&g, *include_hidden))?
            } else if *verbose {
                write!(out, "{}", inspect::topic_list_verbose(&g, *include_hidden))?
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
            let timeout = *timeout;
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
            let graph = (&g, domain, wait);
            every_second(&session, graph, (topic.as_str(), qos), hz, *duration, &stop)?;
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
            let graph = (&g, domain, wait);
            every_second(&session, graph, (topic.as_str(), qos), bw, *duration, &stop)?;
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

/// The endpoint of topic `name` (expanded) a subscriber takes its type, hash and data key
/// from: its first publisher, else its first subscription, for a topic only subscribed to so
/// far (ros2cli's `get_msg_class` takes the type of any endpoint: `get_topic_names_and_types`
/// lists both), whose publishers to come put on the same key.
fn source<'a>(g: &'a inspect::Seen, name: &str) -> Option<&'a inspect::EndpointEntity> {
    inspect::publishers(g, name).into_iter().next().or_else(|| {
        g.endpoints
            .iter()
            .find(|e| e.kind == inspect::EndpointKind::Subscription && e.topic == name)
    })
}

/// Subscribe to `topic` as ros2cli subscribes (`ratelab::ros2::subscription`): the QoS
/// chosen from what its publishers offer and the `qos` flags, ros2cli's lines about that
/// choice printed first on stdout (`echo`'s `choose_qos` comes before its
/// `get_msg_class`). `on` gets each payload; the subscription (held while listening) and the
/// endpoint whose key, type and hash it took ([`source`]). [`Refused`] in ros2cli's words,
/// whichever verb asked: a topic of two types; a topic no node has, after ros2cli's warning
/// on stdout (`echo`'s words: `hz` and `bw` wait for the topic first, [`wait_for_topic`]).
fn listen<'a>(
    session: &inspect::Session,
    g: &'a inspect::Seen,
    topic: &str,
    qos: &QosArgs,
    on: impl Fn(Vec<u8>) + Send + Sync + 'static,
) -> Result<(subscription::Subscription, &'a inspect::EndpointEntity)> {
    let name = expanded(topic);
    let offered: Vec<subscription::QosProfile> = inspect::publishers(g, &name)
        .iter()
        .map(|e| e.qos)
        .collect();
    let choice = subscription::choose_qos(&offered, qos.flags()?);
    for note in &choice.notes {
        say(note)?;
    }
    // A topic of two types is refused, as ros2cli's `get_msg_class` refuses it.
    inspect::one_type_as(g, &name, topic).map_err(refused)?;
    let Some(p) = source(g, &name) else {
        say(&not_published_yet(topic))?;
        return Err(refused(NO_TYPE.into()));
    };
    let sub = subscription::subscribe(session, p, &choice.qos, on)?;
    Ok((sub, p))
}

/// ros2cli's `get_msg_class(…, blocking=True)` (`hz`, `bw`): the graph once some node has
/// `topic` (a publisher or a subscription); until then, ros2cli's warning once on stdout and
/// the graph read again every 0.1 s, as ros2cli's loop sleeps. `None` when `stopped` (Ctrl-C,
/// `--duration`) first.
///
/// # Errors
/// [`Refused`]: the topic has two types (ros2cli's words); the graph could not be read.
fn wait_for_topic<'a>(
    session: &inspect::Session,
    (g, domain, wait): (&'a inspect::Seen, u32, Duration),
    topic: &str,
    stopped: &dyn Fn() -> bool,
) -> Result<Option<std::borrow::Cow<'a, inspect::Seen>>> {
    let name = expanded(topic);
    let mut g = std::borrow::Cow::Borrowed(g);
    let mut warned = false;
    loop {
        if inspect::one_type_as(&g, &name, topic)
            .map_err(refused)?
            .is_some()
        {
            return Ok(Some(g));
        }
        if !warned {
            say(&not_published_yet(topic))?;
            warned = true;
        }
        if stopped() {
            return Ok(None);
        }
        std::thread::sleep(Duration::from_millis(100));
        if stopped() {
            return Ok(None);
        }
        g = std::borrow::Cow::Owned(inspect::seen(session, domain, wait)?);
    }
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
    // ros2cli's `echo` lets Ctrl-C's KeyboardInterrupt reach its `main` ([`Interrupted`]).
    if stop.is_stopped() {
        return Err(interrupted(EXIT_KEYBOARD_INTERRUPT));
    }
    Ok(())
}

/// `--duration S` or `--timeout S` read as a time limit: seconds in (0, 1000000], refused
/// by clap before anything is opened, the value quoted as it was typed.
///
/// # Errors
/// One line when `S` is not a number or not in the range.
fn time_limit(s: &str) -> Result<Duration, String> {
    seconds_in(s, (false, 1e6))
}

/// How long a verb waits for the graph's liveliness tokens when `--wait` is not given.
const DEFAULT_WAIT: Duration = Duration::from_secs(1);

/// `--wait S`: seconds in [0, 3600], as [`time_limit`].
///
/// # Errors
/// One line when `S` is not a number or not in the range.
fn wait_s(s: &str) -> Result<Duration, String> {
    seconds_in(s, (true, 3600.0))
}

/// `s` as seconds from 0 (taken when `zero`, else excluded) up to `max`, inclusive.
fn seconds_in(s: &str, (zero, max): (bool, f64)) -> Result<Duration, String> {
    match s.trim().parse::<f64>() {
        Ok(x) if (x > 0.0 || (zero && x == 0.0)) && x <= max => Ok(Duration::from_secs_f64(x)),
        _ => Err(format!(
            "must be a number of seconds in {}0, {}]",
            if zero { "[" } else { "(" },
            ratelab::text::number(max)
        )),
    }
}

/// What `hz` or `bw` keeps of the messages.
enum Figures {
    Hz(inspect::Rate),
    Bw(inspect::Bandwidth),
}

/// Subscribe to `topic` (with the QoS ros2cli chooses, [`listen`]; a topic no node has yet
/// waited for first, [`wait_for_topic`]) and print `figures` every second from then, when
/// they have something to say ([`inspect::Rate::report`], [`inspect::Bandwidth::report`]),
/// until `duration` (counted from the start, the wait included) or Ctrl-C ([`Interrupted`]:
/// 2 while waiting and for `bw`, 0 for `hz` once subscribed, as ros2cli's); `bw` says first
/// that it subscribed, as ros2cli's.
fn every_second(
    session: &inspect::Session,
    graph: (&inspect::Seen, u32, Duration),
    (topic, qos): (&str, &QosArgs),
    figures: Figures,
    until: Option<Duration>,
    stop: &StopFlag,
) -> Result<()> {
    let begun = Instant::now();
    let over = || until.is_some_and(|u| begun.elapsed() >= u);
    let bw = matches!(figures, Figures::Bw(_));
    let stopped = || stop.is_stopped() || over();
    let Some(g) = wait_for_topic(session, graph, topic, &stopped)? else {
        // Ctrl-C: its KeyboardInterrupt reaches ros2cli's `main`; `--duration`: done.
        if stop.is_stopped() {
            return Err(interrupted(EXIT_KEYBOARD_INTERRUPT));
        }
        return Ok(());
    };
    let start = Instant::now();
    let figures = Arc::new(Mutex::new(figures));
    let seen = figures.clone();
    let _sub = listen(session, &g, topic, qos, move |bytes| {
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
    while !stop.is_stopped() && !over() {
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
    if stop.is_stopped() {
        // `hz` catches Ctrl-C's KeyboardInterrupt around its spin; `bw` does not.
        return Err(interrupted(if bw { EXIT_KEYBOARD_INTERRUPT } else { 0 }));
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
        BagVerb::Record { .. } => anyhow::bail!(
            "`ros2 bag record` is not ratelab's: a run writes its own bag with `ratelab run --ros2 --bag DIR` (every topic, as `ros2 bag record -a`)"
        ),
        BagVerb::Play { .. } => anyhow::bail!(
            "`ros2 bag play` is not ratelab's: play a bag with ROS 2's own `ros2 bag play DIR`; `ratelab ros2 bag echo DIR` prints its messages"
        ),
        BagVerb::Info { dir } => {
            let b = Bag::open(dir).map_err(|e| anyhow!(e))?;
            write!(out, "{}", b.info(&stopped).map_err(|e| anyhow!(e))?)?;
        }
        BagVerb::Echo { dir, topic, count } => {
            // A relative name is the root namespace's, as `topic echo` takes it.
            let topic = topic.as_deref().map(expanded);
            let b = Bag::open(dir).map_err(|e| anyhow!(e))?;
            let mut printed = 0u64;
            let mut failed = None;
            // The topics of the messages passed over, to name when `--topic` matched none
            // (as many as the bag's channels, each read once), and whether it matched any.
            let (mut others, mut matched) = (std::collections::BTreeSet::new(), false);
            let note = b
                .messages(&stopped, |m| {
                    if topic.as_deref().is_some_and(|want| want != m.topic) {
                        if !others.contains(m.topic) {
                            others.insert(m.topic.to_string());
                        }
                        return true;
                    }
                    matched = true;
                    if count.is_some_and(|n| printed >= n) {
                        return false;
                    }
                    // By ratelab's description of the type, else by the bag's ros2msg schema.
                    let text = match m.decode() {
                        Ok(v) => echo::yaml(&v),
                        Err(why) => format!(
                            "<{}: {} bytes, not decoded: {why}>\n",
                            ratelab::text::printable(m.type_name),
                            m.data.len()
                        ),
                    };
                    let head = format!(
                        "# {} at {} s\n",
                        ratelab::text::printable(m.topic),
                        ratelab::Nanos(m.log_time).secs_exact()
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
            if let Some(n) = &note {
                eprintln!("ratelab: {n}");
            }
            if let (Some(want), false, None) = (topic, matched, note) {
                let named = ratelab::text::listed(others.iter().map(String::as_str));
                return Err(anyhow!(
                    "no messages on {} in this bag (its topics: {})",
                    ratelab::text::printable(&want),
                    if others.is_empty() { "none" } else { &named },
                ));
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
    until: Option<Duration>,
    stop: &StopFlag,
) -> Result<()> {
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
