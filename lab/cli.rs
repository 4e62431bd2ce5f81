//! The command line (clap): `ratelab [run|bench|...]` and the run flags shared by all.

use clap::{Args, CommandFactory, FromArgMatches, Parser, Subcommand};
use ratelab::config::{check_rate, duration_from_secs, phase_offset_from_ms, ClockKind};
use ratelab::graph::nodes::camera::{MAX_FRAME_PX, MIN_FRAME_PX};
use ratelab::outputs::{Outputs, Ros2Domain};
use ratelab::qos::Fault;
use ratelab::run_spec::{GraphSettings, RunSpec, DEFAULT_CLOCK, DEFAULT_POLICY};
use ratelab::sweep_spec::{CliffSpec, SweepSpec};
use std::path::PathBuf;

/// ratelab: a graph of nodes at fixed rates keeping a MuJoCo cartpole upright.
///
/// Without a subcommand, `ratelab` opens the terminal lab when stdout is a terminal and
/// runs headless (like `ratelab run`) otherwise, or with --headless.
#[derive(Debug, Parser)]
#[command(name = "ratelab", version, about, long_about = None)]
pub struct Cli {
    /// What to do (default: the lab on a terminal, a headless run otherwise).
    #[command(subcommand)]
    pub command: Option<Command>,
    /// Run headless even on a terminal.
    #[arg(long, global = true)]
    pub headless: bool,
    /// Run settings (for the default action).
    #[command(flatten)]
    pub run: RunArgs,
}

impl Cli {
    /// `argv` (the program's name first) read as the command line reads it: clap's parse,
    /// with one rule added, [`numbers_may_begin_with_a_hyphen`].
    ///
    /// # Errors
    /// clap's error for an unknown flag, a missing value or a value its rule refuses
    /// (`--control-hz must be in (0, 10000]`); `--help` and `--version` come back as clap's
    /// `DisplayHelp`/`DisplayVersion` errors, to be printed.
    pub fn parse_argv<I, T>(argv: I) -> Result<Cli, clap::Error>
    where
        I: IntoIterator<Item = T>,
        T: Into<std::ffi::OsString> + Clone,
    {
        let mut matches =
            numbers_may_begin_with_a_hyphen(Cli::command()).try_get_matches_from(argv)?;
        Cli::from_arg_matches_mut(&mut matches)
    }
}

/// Every option of `cmd` (and of its subcommands) whose value is a number (and not
/// optional: `--ros2 [DOMAIN]` keeps clap's reading) takes a value
/// that begins with `-` (`-inf`, `-1e3`, `-5`) as that value, to be judged by the option's
/// own rule ("--control-hz must be in (0, 10000]"), rather than as a flag: clap alone reads
/// `--control-hz -inf` as the flags `-i`, `-n`, `-f` ("unexpected argument '-i' found"),
/// naming neither the option nor its rule. Options whose value is a name or a path are left
/// as clap reads them, so `--out --force` still says that `--out` lacks its value.
pub fn numbers_may_begin_with_a_hyphen(cmd: clap::Command) -> clap::Command {
    cmd.mut_args(|arg| {
        if takes_a_number(&arg) {
            arg.allow_hyphen_values(true)
        } else {
            arg
        }
    })
    .mut_subcommands(numbers_may_begin_with_a_hyphen)
}

/// Whether `arg` takes a value parsed as a number (its value parser's type).
fn takes_a_number(arg: &clap::Arg) -> bool {
    use std::any::TypeId;
    let numbers = [
        TypeId::of::<f64>(),
        TypeId::of::<f32>(),
        TypeId::of::<u8>(),
        TypeId::of::<u16>(),
        TypeId::of::<u32>(),
        TypeId::of::<u64>(),
        TypeId::of::<usize>(),
        TypeId::of::<i32>(),
        TypeId::of::<i64>(),
    ];
    let ty = arg.get_value_parser().type_id();
    // An option whose value may be left out (`--ros2 [DOMAIN]`) keeps clap's reading, so
    // that a flag after it (`--ros2 --bag DIR`) stays a flag.
    let value_optional = arg.get_num_args().is_some_and(|n| n.min_values() == 0);
    arg.get_action().takes_values() && !value_optional && numbers.iter().any(|n| ty == *n)
}

/// Subcommands.
#[derive(Debug, Subcommand)]
pub enum Command {
    /// Run the graph once, headless, and print the chapter's summary.
    Run(RunArgs),
    /// Open the terminal lab (the default on a terminal); `--attach` watches a graph that
    /// runs across processes.
    Lab(LabArgs),
    /// Re-run a lab session's virtual-clock runs headless from its command log.
    Replay(ReplayArgs),
    /// Real-clock timing benchmark: per-node tick lateness and CPU at given rates.
    Bench(BenchArgs),
    /// Run an exercise (ex1, ex2, …): prediction first, then the measurement.
    Exercise(ExerciseArgs),
    /// Run a grid of settings; print a table and a plot, write CSV/JSON.
    Sweep(SweepArgs),
    /// Find, per seed, the highest control rate at which the pole falls.
    Cliff(CliffArgs),
    /// Run a graph with each of its processes (the nodes' `process = "…"`) in its own OS process, over Zenoh.
    Launch(LaunchArgs),
    /// Run one process of a graph, joining a launcher (`launch` starts these; `node` is its
    /// old name).
    #[command(alias = "node")]
    Process(ProcessArgs),
    /// Route a launch on another host: a Zenoh router linked to the launcher's, which this
    /// host's processes link to (`ratelab process --connect` its `--listen`).
    Router(RouterArgs),
    /// A table of a running multi-process graph: nodes, rates, topics, wire latency.
    Top(TopArgs),
    /// Write a checkpoint's tensors (.pt/.pth/.safetensors) as NumPy's .npz, for a Python
    /// node to load with `np.load` (graphs/nodes/ppo_numpy.py).
    Export(ExportArgs),
    /// Print the node kinds this program knows, built in and registered: what each reads
    /// and publishes, how it touches the plant, whose code it runs, its parameters (unit,
    /// default, range), as a Markdown table.
    Kinds,
    /// Print the message types this program knows, built in and registered: the Python
    /// class, the fields with their units, the ROS 2 type, as a Markdown table.
    Msgs,
    /// Read any rmw_zenoh graph as ros2cli does, without ROS 2: `node list|info`,
    /// `topic list|info|echo|bw|hz`, `graph`, `param list|get|set`, and rosbag2 bags with
    /// `bag info|echo` (docs/ros2.md).
    // Every verb of the subcommand tree is named here: a unit test checks it
    // (`the_ros2_summary_names_every_verb`).
    Ros2(crate::ros2::Ros2Args),
    /// Print a generated graph file of any size: the chapter's loop and, beside it,
    /// controllers of four nodes each (`ratelab graph --nodes 1000 > big.toml`).
    Graph(GenerateArgs),
    /// Serve a camera's frames rendered by MuJoCo, on stdin and stdout: a camera with
    /// `mujoco = 1` starts this in a process of its own (`ratelab_runtime::graph::nodes::
    /// camera_render`); not a person's command, so hidden from the help.
    #[command(name = "render-camera", hide = true)]
    RenderCamera(RenderCameraArgs),
}

/// `ratelab render-camera`: the frame's size, in the camera kind's bounds.
#[derive(Debug, Clone, Args)]
pub struct RenderCameraArgs {
    /// Frame width, px.
    #[arg(long, value_parser = clap::value_parser!(u32).range(MIN_FRAME_PX as i64..=MAX_FRAME_PX as i64))]
    pub width: u32,
    /// Frame height, px.
    #[arg(long, value_parser = clap::value_parser!(u32).range(MIN_FRAME_PX as i64..=MAX_FRAME_PX as i64))]
    pub height: u32,
}

/// `ratelab graph`.
#[derive(Debug, Clone, Args)]
pub struct GenerateArgs {
    /// How many nodes, from 3 (the chapter's graph) to 65536 (ratelab::limits::MAX_NODES).
    #[arg(long, value_parser = clap::value_parser!(u32).range(3..=ratelab::limits::MAX_NODES as i64))]
    pub nodes: u32,
    /// Place the nodes in this many processes for `ratelab launch --processes` (the plant's
    /// nodes in `robot`, the rest dealt out, a controller of 4 nodes or more each: P ≥ 3
    /// processes need at least 3 + 4 (P − 1) nodes); 1, the default, places none.
    #[arg(long, default_value_t = 1, value_parser = clap::value_parser!(u32).range(1..=ratelab::limits::MAX_PROCESSES as i64))]
    pub processes: u32,
    /// Every controller's rate, Hz, instead of 10, 20, 50 and 100 in turn (0.01: idle
    /// nodes, for measuring what a node costs when it is not due).
    #[arg(long, value_parser = parse_rate("controller-hz"))]
    pub controller_hz: Option<f64>,
}

/// `ratelab export`.
#[derive(Debug, Clone, Args)]
pub struct ExportArgs {
    /// The checkpoint: a PyTorch state_dict (.pt/.pth) or .safetensors.
    #[arg(value_name = "CHECKPOINT")]
    pub checkpoint: PathBuf,
    /// The archive to write (.npz).
    #[arg(long, value_name = "FILE.npz")]
    pub out: PathBuf,
    /// Overwrite an existing file.
    #[arg(long)]
    pub force: bool,
}

/// `ratelab launch`.
#[derive(Debug, Clone, Args)]
pub struct LaunchArgs {
    /// The graph file (default: the chapter's, graphs/cartpole.toml).
    #[arg(value_name = "GRAPH")]
    pub file: Option<PathBuf>,
    /// One OS process per process of the graph (the nodes' `process = "…"`; by default the
    /// plant's nodes share `robot` and every other node runs alone), connected over Zenoh.
    /// Without it the graph runs in this one process, as `ratelab run`.
    #[arg(long)]
    pub processes: bool,
    /// The Zenoh endpoint to listen on (default tls/127.0.0.1:7449, or a free port when that
    /// is taken).
    #[arg(long, value_name = "tls/HOST:PORT")]
    pub listen: Option<String>,
    /// Start no processes: wait for each group to join with `ratelab process … --connect …
    /// --credentials FILE` (needs --export-credentials).
    #[arg(long)]
    pub no_spawn: bool,
    /// Write the launch's credentials (its CA's certificate and every process's identity;
    /// a secret, mode 600) to FILE, for processes started by hand (`ratelab process
    /// --credentials FILE`, also `top`, `lab --attach` and `ratelab router` on another
    /// host). An existing FILE only with --force.
    #[arg(long, value_name = "FILE")]
    pub export_credentials: Option<PathBuf>,
    /// Kill a process of the graph at run time T, seconds, as a crash would (SIGKILL;
    /// repeatable; real clock): --kill-process policy@3. With `restart = "on-failure"` in
    /// its `[processes.NAME]` table it is started again and rejoins (not the plant's
    /// process: killing it ends the run).
    #[arg(long = "kill-process", value_name = "PROCESS@T", value_parser = parse_kill_process)]
    pub kill_processes: Vec<Fault>,
    /// Link every process to the launcher's router alone (a star), even in a launch of 10
    /// processes or fewer started here, whose processes otherwise also link to each other
    /// directly (a sample or a lockstep report then crosses one link, not two).
    #[arg(long)]
    pub star: bool,
    /// The run flags.
    #[command(flatten)]
    pub run: RunArgs,
}

/// `ratelab lab`.
#[derive(Debug, Clone, Args)]
pub struct LabArgs {
    /// Watch a graph already running across processes (`ratelab launch --processes`)
    /// instead of running one here: nodes alive, rates, topics, latency, the plant. Read-only;
    /// the run flags do not apply.
    #[arg(long)]
    pub attach: bool,
    /// With --attach: the launcher's endpoint (repeatable; default: this user's running
    /// launch, recorded when it started, else tls/127.0.0.1:7449).
    #[arg(long, value_name = "tls/HOST:PORT", requires = "attach")]
    pub connect: Vec<String>,
    /// With --attach: the launch's credentials (`launch --export-credentials FILE`;
    /// default: those this user's running launch keeps for its watchers).
    #[arg(long, value_name = "FILE", requires = "attach")]
    pub credentials: Option<PathBuf>,
    /// The run flags.
    #[command(flatten)]
    pub run: RunArgs,
}

/// `ratelab process`.
#[derive(Debug, Clone, Args)]
pub struct ProcessArgs {
    /// The graph file (default: the chapter's); it must be the launcher's, byte for byte.
    #[arg(long, value_name = "FILE")]
    pub graph: Option<PathBuf>,
    /// The process to run (its name in the graph file).
    #[arg(long, value_name = "NAME")]
    pub process: String,
    /// The launcher's endpoint (repeatable).
    #[arg(long, value_name = "tls/HOST:PORT", required = true)]
    pub connect: Vec<String>,
    /// Listen here for the launch's other processes, which then link to this one directly
    /// (a launch linked directly: its launcher gives the processes it starts
    /// tls/127.0.0.1:0, any free port). Without it, this process links to the router at
    /// --connect alone.
    #[arg(long, value_name = "tls/HOST:PORT")]
    pub listen: Vec<String>,
    /// The launch's credentials, holding this process's identity (`launch
    /// --export-credentials FILE`; the launcher gives the processes it starts their own).
    #[arg(long, value_name = "FILE")]
    pub credentials: Option<PathBuf>,
}

/// `ratelab router`.
#[derive(Debug, Clone, Args)]
pub struct RouterArgs {
    /// The graph file (default: the chapter's): the launcher's, whose access rules the
    /// router enforces on this host's processes (refused when its nodes' processes or its
    /// topics' publishers differ from the launcher's graph).
    #[arg(long, value_name = "FILE")]
    pub graph: Option<PathBuf>,
    /// The launcher's endpoint (repeatable): the router's one link off this host.
    #[arg(long, value_name = "tls/HOST:PORT", required = true)]
    pub connect: Vec<String>,
    /// Where this host's processes and watchers link to the router (repeatable).
    #[arg(long, value_name = "tls/HOST:PORT", default_value = ratelab::distributed::DEFAULT_ENDPOINT)]
    pub listen: Vec<String>,
    /// The launch's credentials (`launch --export-credentials FILE`), holding a host
    /// router's identity.
    #[arg(long, value_name = "FILE", required = true)]
    pub credentials: PathBuf,
}

/// `ratelab top`.
#[derive(Debug, Clone, Args)]
pub struct TopArgs {
    /// The endpoint of a running launcher or node (repeatable; default: this user's running
    /// launch, recorded when it started, else tls/127.0.0.1:7449).
    #[arg(long, value_name = "tls/HOST:PORT")]
    pub connect: Vec<String>,
    /// Print one table, every row, and exit (for scripts). On a terminal `top` otherwise
    /// shows a page at a time (PgDn/PgUp or space, Home/End) and `s` sorts by the next
    /// column; `q` quits.
    #[arg(long)]
    pub once: bool,
    /// Sort the rows by: name (nodes by process, topics by name), rate (measured Hz and
    /// msg/s, highest first), count (ticks and published messages, most first), trouble
    /// (nodes not alive and topics' dropped + lost messages first).
    #[arg(long, value_enum, default_value_t = SortBy::Name)]
    pub sort: SortBy,
    /// The launch's credentials (`launch --export-credentials FILE`; default: those this
    /// user's running launch keeps for its watchers).
    #[arg(long, value_name = "FILE")]
    pub credentials: Option<PathBuf>,
}

/// `ratelab replay`.
#[derive(Debug, Clone, Args)]
pub struct ReplayArgs {
    /// The session log (JSON) the lab saved.
    pub file: PathBuf,
    /// Write metrics-<n>.json for each replayed run into this folder.
    #[arg(long, value_name = "DIR")]
    pub out: Option<PathBuf>,
    /// Overwrite existing metrics-<n>.json files.
    #[arg(long)]
    pub force: bool,
}

/// The graph to run and overrides of its rates and depths (every command that runs one).
#[derive(Debug, Clone, Default, Args)]
pub struct GraphArgs {
    /// The node graph (TOML; see graphs/). Default: the chapter's, graphs/cartpole.toml.
    #[arg(long, value_name = "FILE")]
    pub graph: Option<PathBuf>,
    /// Set a node's rate, Hz (repeatable): --rate estimator=10.
    #[arg(long = "rate", value_name = "NODE=HZ", value_parser = parse_node_rate)]
    pub rates: Vec<(String, f64)>,
    /// Set a topic's history depth (repeatable): --depth /obs=100.
    #[arg(long = "depth", value_name = "TOPIC=N", value_parser = parse_topic_depth)]
    pub depths: Vec<(String, usize)>,
    /// Set a topic's QoS with the graph file's keys (repeatable):
    /// --qos /obs:history=keep_last,depth=100,delivery=fifo  --qos /action:deadline_ms=40,lifespan_ms=60.
    /// Keys: history, depth, delivery, deadline_ms, lifespan_ms, reliability, durability,
    /// on_deadline_missed.
    #[arg(long = "qos", value_name = "TOPIC:KEY=VALUE,…", value_parser = parse_topic_pairs)]
    pub qos: Vec<(String, String)>,
    /// Put a topic on a seeded lossy link (repeatable): --link /cmd:loss=0.2,delay_ms=10,jitter_ms=3
    /// (keys: loss, delay_ms, jitter_ms, retransmit_ms).
    #[arg(long = "link", value_name = "TOPIC:KEY=VALUE,…", value_parser = parse_topic_pairs)]
    pub links: Vec<(String, String)>,
    /// Set a node's liveliness lease, ms (repeatable): --lease policy=100.
    #[arg(long = "lease", value_name = "NODE=MS", value_parser = parse_node_ms)]
    pub leases: Vec<(String, f64)>,
    /// Stall a node at run time T for D, seconds (repeatable): --stall policy@2+0.5.
    #[arg(long = "stall", value_name = "NODE@T+D", value_parser = parse_stall)]
    pub stalls: Vec<Fault>,
    /// Kill a node at run time T, seconds (repeatable): --kill policy@3.
    #[arg(long = "kill", value_name = "NODE@T", value_parser = parse_kill)]
    pub kills: Vec<Fault>,
    /// Give a node's ticks a compute time, ms (repeatable): --compute policy=30, or
    /// --compute policy=30±5 (uniform jitter, seeded). Its outputs go out that long after
    /// its tick starts; its executor's thread is busy meanwhile.
    #[arg(long = "compute", value_name = "NODE=MS", value_parser = parse_compute)]
    pub computes: Vec<(String, ratelab::executor::ComputeTime)>,
    /// Run every node but the actuator (it steps the plant, on a thread of its own) on one
    /// executor: single_threaded, multi_threaded:N (N threads) or per_node (a thread each,
    /// the default); replaces the graph file's [executors].
    #[arg(long, value_name = "KIND", value_parser = ratelab::executor::ExecutorOverride::parse)]
    pub executor: Option<ratelab::executor::ExecutorOverride>,
}

fn parse_compute(s: &str) -> Result<(String, ratelab::executor::ComputeTime), String> {
    let (node, ms) = split_assignment(s, "NODE=MS")?;
    Ok((node.to_string(), ratelab::executor::ComputeTime::parse(ms)?))
}

fn parse_topic_pairs(s: &str) -> Result<(String, String), String> {
    let (topic, pairs) = s
        .split_once(':')
        .map(|(t, p)| (t.trim(), p.trim()))
        .filter(|(t, p)| !t.is_empty() && !p.is_empty())
        .ok_or_else(|| format!("expected TOPIC:KEY=VALUE[,KEY=VALUE…], got '{s}'"))?;
    ratelab::qos::split_pairs(pairs)?;
    Ok((topic.to_string(), pairs.to_string()))
}

fn parse_node_ms(s: &str) -> Result<(String, f64), String> {
    let (node, ms) = split_assignment(s, "NODE=MS")?;
    let ms: f64 = ms
        .parse()
        .map_err(|_| format!("not a time in ms: '{ms}'"))?;
    ratelab::qos::ms_to_nanos("lease", ms, false)?;
    Ok((node.to_string(), ms))
}

fn parse_stall(s: &str) -> Result<Fault, String> {
    Fault::parse(s, false)
}

fn parse_kill(s: &str) -> Result<Fault, String> {
    Fault::parse(s, true)
}

fn parse_kill_process(s: &str) -> Result<Fault, String> {
    Fault::parse(s, true).map_err(|e| e.replace("NODE@T", "PROCESS@T"))
}

fn split_assignment<'a>(s: &'a str, what: &str) -> Result<(&'a str, &'a str), String> {
    s.split_once('=')
        .map(|(k, v)| (k.trim(), v.trim()))
        .filter(|(k, _)| !k.is_empty())
        .ok_or_else(|| format!("expected {what}, got '{s}'"))
}

fn parse_node_rate(s: &str) -> Result<(String, f64), String> {
    let (node, hz) = split_assignment(s, "NODE=HZ")?;
    let hz: f64 = hz
        .parse()
        .map_err(|_| format!("not a rate in Hz: '{hz}'"))?;
    check_rate("rate", hz).map_err(|e| e.to_string())?;
    Ok((node.to_string(), hz))
}

fn parse_topic_depth(s: &str) -> Result<(String, usize), String> {
    let (topic, depth) = split_assignment(s, "TOPIC=N")?;
    let depth = parse_depth(depth)?;
    Ok((topic.to_string(), depth))
}

/// `ratelab exercise`.
#[derive(Debug, Clone, Args)]
pub struct ExerciseArgs {
    /// The exercise: one of the registry's (`ratelab exercise --help` lists them).
    #[arg(help = ratelab_exercises::menu())]
    pub which: String,
    /// The folder holding the exercise files and bands.toml.
    #[arg(long, default_value = "exercises")]
    pub dir: PathBuf,
    /// The graph the exercise runs on (its bands were measured on the default: the chapter's,
    /// or for ex5 to ex8 the one their bands name; ex9's processes load it too).
    #[command(flatten)]
    pub graph: GraphArgs,
}

fn parse_seed(s: &str) -> Result<u64, String> {
    s.trim()
        .parse()
        .map_err(|_| format!("a seed is a whole number in 0..={}, got '{s}'", u64::MAX))
}

fn parse_spin_margin(s: &str) -> Result<u64, String> {
    let max = ratelab::rate::MAX_SPIN_MARGIN.0 / 1_000;
    s.trim()
        .parse()
        .ok()
        .filter(|&us| us <= max)
        .ok_or_else(|| {
            format!("--spin-margin-us must be a whole number of µs in 0..={max}, below every node's period; got '{s}'")
        })
}

/// `ratelab sweep`.
#[derive(Debug, Clone, Args)]
pub struct SweepArgs {
    /// Control rates, Hz (comma-separated).
    #[arg(long, value_delimiter = ',', default_value = "50,25,20,15,10,5", value_parser = parse_rate("control-hz"))]
    pub control_hz: Vec<f64>,
    /// Sensor rates, Hz.
    #[arg(long, value_delimiter = ',', default_value = "50", value_parser = parse_rate("sensor-hz"))]
    pub sensor_hz: Vec<f64>,
    /// Queue depths.
    #[arg(long, value_delimiter = ',', default_value = "1", value_parser = parse_depth)]
    pub queue_depth: Vec<usize>,
    /// Seeds.
    #[arg(long, value_delimiter = ',', default_value = "0,1,2", value_parser = parse_seed)]
    pub seeds: Vec<u64>,
    /// Clocks (virtual runs in parallel; real runs one at a time, in real time).
    #[arg(long, value_delimiter = ',', default_value = "virtual", value_parser = parse_clock)]
    pub clock: Vec<ClockKind>,
    /// The brain for every run.
    #[arg(long, default_value = "scripted")]
    pub policy: String,
    /// Seconds per run, in (0, 315360000] (ten years).
    #[arg(long, default_value = "10", value_parser = parse_duration)]
    pub duration: f64,
    /// Write the table as CSV.
    #[arg(long, value_name = "FILE")]
    pub csv: Option<PathBuf>,
    /// Write the table as JSON.
    #[arg(long, value_name = "FILE")]
    pub json: Option<PathBuf>,
    /// The graph (the grid's rates are its chain sensor's and policy's).
    #[command(flatten)]
    pub graph: GraphArgs,
    /// Overwrite existing --csv/--json files.
    #[arg(long)]
    pub force: bool,
}

/// `ratelab cliff`.
#[derive(Debug, Clone, Args)]
pub struct CliffArgs {
    /// Seeds (one line of output each).
    #[arg(long, value_delimiter = ',', default_value = "0,1,2", value_parser = parse_seed)]
    pub seeds: Vec<u64>,
    /// Sensor rate, Hz.
    #[arg(long, default_value = "50", value_parser = parse_rate("sensor-hz"))]
    pub sensor_hz: f64,
    /// Queue depth.
    #[arg(long, default_value = "1", value_parser = parse_depth)]
    pub queue_depth: usize,
    /// The brain.
    #[arg(long, default_value = "scripted")]
    pub policy: String,
    /// Seconds per run, in (0, 315360000] (ten years).
    #[arg(long, default_value = "10", value_parser = parse_duration)]
    pub duration: f64,
    /// Lowest rate searched, Hz.
    #[arg(long, default_value = "1", value_parser = parse_rate("min-hz"))]
    pub min_hz: f64,
    /// Highest rate searched, Hz.
    #[arg(long, default_value = "50", value_parser = parse_rate("max-hz"))]
    pub max_hz: f64,
    /// Resolution, Hz (at most 5000 rates between --min-hz and --max-hz).
    #[arg(long, default_value = "0.1", value_parser = parse_rate("step"))]
    pub step: f64,
    /// The graph (the searched rate is its chain policy's).
    #[command(flatten)]
    pub graph: GraphArgs,
}

fn parse_rate(flag: &'static str) -> impl Fn(&str) -> Result<f64, String> + Clone {
    move |s: &str| {
        let hz: f64 = s
            .trim()
            .parse()
            .map_err(|_| format!("not a number: '{s}'"))?;
        check_rate(flag, hz).map_err(|e| e.to_string())
    }
}

fn parse_duration(s: &str) -> Result<f64, String> {
    let secs: f64 = s
        .trim()
        .parse()
        .map_err(|_| format!("not a number of seconds: '{s}'"))?;
    duration_from_secs(secs)
        .map(|_| secs)
        .map_err(|e| e.to_string())
}

fn parse_depth(s: &str) -> Result<usize, String> {
    let d: usize = s
        .trim()
        .parse()
        .map_err(|_| format!("not a whole number: '{s}'"))?;
    if d == 0 {
        // Clap names the flag ("invalid value '0' for '--depth <TOPIC=N>'"): not this line.
        return Err("a history depth is at least 1, got 0".into());
    }
    Ok(d)
}

fn parse_rt_priority(s: &str) -> Result<u8, String> {
    let out_of_range = || format!("--rt-priority must be in 1..=99, got {s}");
    let p: u8 = s.trim().parse().map_err(|_| out_of_range())?;
    ratelab::realtime::check_priority(p).map_err(|_| out_of_range())?;
    Ok(p)
}

fn parse_clock(s: &str) -> Result<ClockKind, String> {
    s.parse()
        .map_err(|e: ratelab::clock::UnknownClock| e.to_string())
}

fn parse_offset(s: &str) -> Result<f64, String> {
    let ms: f64 = s
        .trim()
        .parse()
        .map_err(|_| format!("not a number of ms: '{s}'"))?;
    phase_offset_from_ms(ms)
        .map(|_| ms)
        .map_err(|e| e.to_string())
}

/// Settings of one run.
#[derive(Debug, Clone, Args)]
pub struct RunArgs {
    /// Reset seed (the course env's numpy draws).
    #[arg(long, default_value = "0", value_parser = parse_seed)]
    pub seed: u64,
    /// Run length in seconds of run time, in (0, 315360000] (ten years; headless default 10; the lab runs
    /// until you stop it).
    #[arg(long, value_parser = parse_duration)]
    pub duration: Option<f64>,
    /// The graph and overrides of its rates and depths.
    #[command(flatten)]
    pub graph: GraphArgs,
    /// Sensor rate, Hz, in (0, 10000]: the chain's sensor (default: the graph's).
    #[arg(long, value_parser = parse_rate("sensor-hz"))]
    pub sensor_hz: Option<f64>,
    /// Policy (control) rate, Hz, in (0, 10000]: the chain's policy (default: the graph's).
    #[arg(long, value_parser = parse_rate("control-hz"))]
    pub control_hz: Option<f64>,
    /// History depth of every topic, ≥ 1 (default: the graph's).
    #[arg(long, value_parser = parse_depth)]
    pub queue_depth: Option<usize>,
    /// Clock: real (node threads against the monotonic clock, by the executors' rules) or
    /// virtual (deterministic).
    #[arg(long, default_value_t = DEFAULT_CLOCK, value_parser = parse_clock)]
    pub clock: ClockKind,
    /// The brain: `scripted`, a Python function (`FILE.py[:FUNCTION]`, default `act`), or a
    /// checkpoint (.pt/.pth, .safetensors, .onnx).
    #[arg(long, default_value = DEFAULT_POLICY)]
    pub policy: String,
    /// Break the controller: control rate 5 Hz (the chapter's cliff demo).
    #[arg(long = "break")]
    pub break_: bool,
    /// Quick deterministic check: virtual clock, 2 s (so not with --clock or --duration).
    #[arg(long, conflicts_with_all = ["duration", "clock"])]
    pub smoke: bool,
    /// Write metrics.json (and trace.csv and log.txt in one process, and estimator.json
    /// with an estimator in the graph) into this folder.
    #[arg(long, value_name = "DIR")]
    pub out: Option<PathBuf>,
    /// trace.csv keeps every N-th actuator step (steps 1, 1+N, …) and the last: a long
    /// run's trace (its file, written as the run goes) in proportion to what you ask. The
    /// metrics count every step.
    #[arg(long, value_name = "N", default_value_t = 1, value_parser = clap::value_parser!(u64).range(1..))]
    pub trace_every: u64,
    /// Record the run to a rerun .rrd (default: recordings/<clock>-control<hz>-q<depth>-seed<seed>.rrd).
    #[arg(long, value_name = "PATH", num_args = 0..=1)]
    pub record: Option<Option<PathBuf>>,
    /// Overwrite existing output files (--record, --out's files, --session); without it
    /// nothing is ever overwritten. Links and non-regular files are refused either way.
    #[arg(long)]
    pub force: bool,
    /// Stream live to a rerun viewer on PATH as well (implies --record).
    #[arg(long)]
    pub spawn: bool,
    /// Record only this span of run time, FROM:UNTIL in seconds (3600:3660, :60, 600:): a
    /// long run's recording as large as you ask. The events and the summary still cover the
    /// whole run, and the recording says which span its plots hold. Needs --record.
    #[arg(long, value_name = "FROM:UNTIL", value_parser = ratelab::recording::RecordWindow::parse, requires = "record")]
    pub record_window: Option<ratelab::recording::RecordWindow>,
    /// Lab: save the session's command log here (default: beside the recording); a
    /// headless run refuses it (it takes no keys to log).
    #[arg(long, value_name = "FILE")]
    pub session: Option<PathBuf>,
    /// Real clock: spin this many µs before each deadline instead of sleeping (below every
    /// node's period, at most 1000000; default 300, or half the fastest period if shorter).
    #[arg(long, value_name = "US", value_parser = parse_spin_margin)]
    pub spin_margin_us: Option<u64>,
    /// First-tick offsets in ms, exactly one per node, in tie-break order (the chapter's
    /// sensor,policy,actuator: e.g. 0,5,10), each in [0, 1000); both clocks.
    #[arg(long, value_delimiter = ',', value_parser = parse_offset, value_name = "MS,…")]
    pub phase_offset_ms: Vec<f64>,
    /// Real clock: run node threads under SCHED_FIFO at this priority, 1..=99 (needs
    /// CAP_SYS_NICE or `ulimit -r`; refused → a warning, default policy).
    #[arg(long, value_parser = parse_rt_priority, value_name = "PRIO")]
    pub rt_priority: Option<u8>,
    /// Offer the graph to ROS 2 while it runs (rmw_zenoh's format: ros2 topic list/echo/hz
    /// see it), on this domain, 0-232 (default: ROS_DOMAIN_ID, else 0), with the run time
    /// on /clock; the virtual clock then keeps pace with the wall clock (docs/ros2.md).
    #[arg(long, value_name = "DOMAIN", num_args = 0..=1, value_parser = parse_ros2_domain)]
    pub ros2: Option<Option<u32>>,
    /// With --ros2 (`run`): also write what is offered as a rosbag2 bag (MCAP storage) in
    /// this folder: every topic and /clock, stamped with run time (docs/ros2.md).
    #[arg(long, value_name = "DIR", requires = "ros2")]
    pub bag: Option<PathBuf>,
}

fn parse_ros2_domain(s: &str) -> Result<u32, String> {
    ratelab::ros2::names::parse_domain(s)
}

impl RunArgs {
    /// The ROS 2 domain with `--ros2` (its value, else `ROS_DOMAIN_ID`, else 0).
    ///
    /// # Errors
    /// `ROS_DOMAIN_ID` is set to something that is not a domain.
    pub fn ros2_domain(&self) -> Result<Option<u32>, String> {
        RunSpec::from(self).outputs.ros2_domain()
    }
}

impl From<&GraphArgs> for GraphSettings {
    /// The graph flags as the library's settings, in the order given.
    fn from(g: &GraphArgs) -> GraphSettings {
        GraphSettings {
            file: g.graph.clone(),
            inline: None,
            rates: g.rates.clone(),
            depths: g.depths.clone(),
            qos: g.qos.clone(),
            links: g.links.clone(),
            leases_ms: g.leases.clone(),
            stalls: g.stalls.clone(),
            kills: g.kills.clone(),
            computes: g.computes.clone(),
            executor: g.executor,
        }
    }
}

impl From<&RunArgs> for RunSpec {
    /// `ratelab run`'s flags as the library's settings: the command line's whole share of a
    /// run's set-up (every rule is [`RunSpec::config`]'s).
    fn from(a: &RunArgs) -> RunSpec {
        RunSpec {
            graph: GraphSettings::from(&a.graph),
            seed: a.seed,
            duration_s: a.duration,
            duration_ns: None,
            clock: a.clock,
            sensor_hz: a.sensor_hz,
            control_hz: a.control_hz,
            break_: a.break_,
            queue_depth: a.queue_depth,
            phase_offset_ms: a.phase_offset_ms.clone(),
            smoke: a.smoke,
            spin_margin_us: a.spin_margin_us,
            rt_priority: a.rt_priority,
            policy: a.policy.clone(),
            // Scheduled changes are the lab's (its keys) and a replay's (its session log).
            commands: Vec::new(),
            outputs: Outputs {
                out: a.out.clone(),
                trace_every: a.trace_every,
                record: a.record.clone(),
                spawn: a.spawn,
                record_window: a.record_window,
                force: a.force,
                ros2: a
                    .ros2
                    .map(|d| d.map_or(Ros2Domain::FromEnvironment, Ros2Domain::Given)),
                bag: a.bag.clone(),
            },
        }
    }
}

impl From<&SweepArgs> for SweepSpec {
    /// `ratelab sweep`'s flags as the library's sweep: the grid's lists, and the settings
    /// every run shares (every rule is [`SweepSpec::grid`]'s).
    fn from(a: &SweepArgs) -> SweepSpec {
        SweepSpec {
            base: RunSpec {
                graph: GraphSettings::from(&a.graph),
                duration_s: Some(a.duration),
                clock: ClockKind::Virtual,
                policy: a.policy.clone(),
                ..RunSpec::default()
            },
            clocks: a.clock.clone(),
            sensor_hz: a.sensor_hz.clone(),
            control_hz: a.control_hz.clone(),
            queue_depth: a.queue_depth.clone(),
            seeds: a.seeds.clone(),
        }
    }
}

impl From<&CliffArgs> for CliffSpec {
    /// `ratelab cliff`'s flags as the library's search (every rule is
    /// [`CliffSpec::config`]'s).
    fn from(a: &CliffArgs) -> CliffSpec {
        CliffSpec {
            base: RunSpec {
                graph: GraphSettings::from(&a.graph),
                duration_s: Some(a.duration),
                clock: ClockKind::Virtual,
                sensor_hz: Some(a.sensor_hz),
                queue_depth: Some(a.queue_depth),
                policy: a.policy.clone(),
                ..RunSpec::default()
            },
            seeds: a.seeds.clone(),
            min_hz: a.min_hz,
            max_hz: a.max_hz,
            step_hz: a.step,
        }
    }
}

/// `ratelab bench`'s settings of its real-clock timing, which `--render` and `--scrub` do not
/// take (refused beside them, not ignored).
const REAL_CLOCK_TIMING: [&str; 6] = [
    "hz",
    "duration",
    "spin_margin_us",
    "rt_priority",
    "stagger",
    "GraphArgs", // the graph and every override of it
];

/// Settings of the real-clock timing benchmark.
#[derive(Debug, Clone, Args)]
pub struct BenchArgs {
    /// Rates to measure, Hz (every node at the same rate).
    #[arg(long, value_delimiter = ',', default_value = "50,1000", value_parser = parse_rate("hz"))]
    pub hz: Vec<f64>,
    /// Seconds per rate, in (0, 315360000] (ten years).
    #[arg(long, default_value = "5", value_parser = parse_duration)]
    pub duration: f64,
    /// Spin margin, µs (below the period of every rate measured, at most 1000000; default
    /// 300, or half the period if shorter).
    #[arg(long, value_parser = parse_spin_margin)]
    pub spin_margin_us: Option<u64>,
    /// Run node threads (and the bare wait) under SCHED_FIFO at this priority, 1..=99.
    #[arg(long, value_parser = parse_rt_priority, value_name = "PRIO")]
    pub rt_priority: Option<u8>,
    /// Stagger the nodes' first deadlines by P/n each (n nodes; the chapter's three: sensor
    /// 0, policy P/3, actuator 2P/3) so that no two are due at once.
    #[arg(long)]
    pub stagger: bool,
    /// Instead: time the lab's frame rendering at 120×40 (view model + draw). Takes none of
    /// the real-clock timing's settings.
    #[arg(long, conflicts_with_all = REAL_CLOCK_TIMING)]
    pub render: bool,
    /// Instead: time reaching instants of a 10-minute virtual run as the lab's scrubbing
    /// does (the engine's seek and the lab's fold of what it was told). Takes none of the
    /// real-clock timing's settings.
    #[arg(long, conflicts_with = "render", conflicts_with_all = REAL_CLOCK_TIMING)]
    pub scrub: bool,
    /// The graph whose nodes are timed (every node at each --hz).
    #[command(flatten)]
    pub graph: GraphArgs,
}

/// What `top`'s rows are sorted by (`--sort`, key `s` cycles).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, clap::ValueEnum)]
pub enum SortBy {
    /// Nodes by process then name, topics by name.
    #[default]
    Name,
    /// The measured rate (nodes' Hz, topics' msg/s), highest first.
    Rate,
    /// Nodes' ticks, topics' published messages, most first.
    Count,
    /// Topics' dropped and lost messages, most first (nodes: not alive first).
    Trouble,
}

impl SortBy {
    /// The next sort key: name → rate → count → trouble → name.
    pub fn next(self) -> SortBy {
        match self {
            SortBy::Name => SortBy::Rate,
            SortBy::Rate => SortBy::Count,
            SortBy::Count => SortBy::Trouble,
            SortBy::Trouble => SortBy::Name,
        }
    }

    /// Its name, as `--sort` takes it.
    pub fn word(self) -> &'static str {
        match self {
            SortBy::Name => "name",
            SortBy::Rate => "rate",
            SortBy::Count => "count",
            SortBy::Trouble => "trouble",
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use clap::error::ErrorKind;

    /// Every (subcommand path, `--long`) of an option that takes a number.
    fn numeric_options(cmd: &clap::Command, path: &[String], out: &mut Vec<(Vec<String>, String)>) {
        for arg in cmd.get_arguments() {
            if let (true, Some(long)) = (takes_a_number(arg), arg.get_long()) {
                out.push((path.to_vec(), format!("--{long}")));
            }
        }
        for sub in cmd.get_subcommands() {
            let mut p = path.to_vec();
            p.push(sub.get_name().to_string());
            numeric_options(sub, &p, out);
        }
    }

    /// `ratelab ros2`'s summary (its about, the line `ratelab --help` lists it by and the
    /// first of `ratelab ros2 --help`) names every verb of its subcommand tree, a group's
    /// verbs as `` `topic list|info|echo|bw|hz` ``, a verb of none as `` `graph` ``: a verb
    /// added to the tree and not to the summary fails here.
    #[test]
    fn the_ros2_summary_names_every_verb() {
        let cli = Cli::command();
        let ros2 = cli.find_subcommand("ros2").expect("ratelab ros2");
        let about = [ros2.get_about(), ros2.get_long_about()]
            .into_iter()
            .flatten()
            .map(|t| t.to_string())
            .collect::<Vec<_>>()
            .join("\n");
        // The verbs the summary lists after `` `NAME``, up to the closing backtick.
        let listed = |name: &str| -> Option<Vec<String>> {
            let at = about.find(&format!("`{name}"))? + 1 + name.len();
            let rest = &about[at..];
            let group = rest[..rest.find('`')?].trim();
            let mut verbs: Vec<String> = group
                .split('|')
                .filter(|v| !v.is_empty())
                .map(String::from)
                .collect();
            verbs.sort();
            Some(verbs)
        };
        let shown = |c: &&clap::Command| !c.is_hide_set() && c.get_name() != "help";
        let groups: Vec<&clap::Command> = ros2.get_subcommands().filter(shown).collect();
        assert!(groups.len() >= 5, "{groups:?}");
        for group in groups {
            let mut verbs: Vec<String> = group
                .get_subcommands()
                .filter(shown)
                .map(|v| v.get_name().to_string())
                .collect();
            verbs.sort();
            assert_eq!(
                listed(group.get_name()).as_ref(),
                Some(&verbs),
                "`ratelab ros2`'s summary does not list `{}`'s verbs {verbs:?}: {about}",
                group.get_name()
            );
        }
    }

    #[test]
    fn a_negative_infinity_is_a_value_judged_by_its_rule() {
        let e = Cli::parse_argv(["ratelab", "run", "--control-hz", "-inf"]).unwrap_err();
        assert_eq!(e.kind(), ErrorKind::ValueValidation, "{e}");
        let text = e.to_string();
        assert!(
            text.contains("--control-hz") && text.contains("(0, 10000]"),
            "{text}"
        );
        let e = Cli::parse_argv(["ratelab", "run", "--duration", "-1e3"]).unwrap_err();
        assert_eq!(e.kind(), ErrorKind::ValueValidation, "{e}");
        // A negative value where one is due, and a flag after it, still read as meant.
        let cli = Cli::parse_argv(["ratelab", "run", "--phase-offset-ms", "-0", "--headless"]);
        assert!(cli.is_ok(), "{:?}", cli.err());
        // A path is no number: a flag in its place is still the flag.
        let e = Cli::parse_argv(["ratelab", "run", "--out", "--force"]).unwrap_err();
        assert_ne!(e.kind(), ErrorKind::ValueValidation, "{e}");
        // Nor is a number whose value may be left out: the flag after it is a flag.
        let cli = Cli::parse_argv([
            "ratelab",
            "run",
            "--ros2",
            "--bag",
            "b",
            "--qos",
            "/obs:depth=2",
        ]);
        assert!(cli.is_ok(), "{:?}", cli.err());
    }

    #[test]
    fn sweep_and_cliff_flags_default_to_the_library_s_specs() {
        use ratelab::setting::Speech;
        let Some(Command::Sweep(a)) = Cli::parse_argv(["ratelab", "sweep"]).unwrap().command else {
            panic!("not a sweep")
        };
        let flags = SweepSpec::from(&a).grid(Speech::Flags).unwrap();
        let library = SweepSpec::default().grid(Speech::Flags).unwrap();
        assert_eq!(flags.points(), library.points());
        assert_eq!(flags.base, library.base);
        let Some(Command::Cliff(a)) = Cli::parse_argv(["ratelab", "cliff"]).unwrap().command else {
            panic!("not a cliff search")
        };
        let (flags, library) = (CliffSpec::from(&a), CliffSpec::default());
        assert_eq!(
            (&flags.seeds, flags.min_hz, flags.max_hz, flags.step_hz),
            (
                &library.seeds,
                library.min_hz,
                library.max_hz,
                library.step_hz
            )
        );
        assert_eq!(
            flags.config(Speech::Flags).unwrap(),
            library.config(Speech::Flags).unwrap()
        );
    }

    #[test]
    fn no_numeric_option_reads_a_number_with_a_hyphen_as_a_flag() {
        let mut found = Vec::new();
        numeric_options(&Cli::command(), &[], &mut found);
        assert!(found.len() > 20, "{found:?}");
        for (path, long) in found {
            for value in ["-inf", "-1e3", "-5"] {
                let argv = std::iter::once("ratelab".to_string())
                    .chain(path.iter().cloned())
                    .chain([long.clone(), value.to_string()]);
                if let Err(e) = Cli::parse_argv(argv) {
                    assert!(
                        !matches!(e.kind(), ErrorKind::UnknownArgument | ErrorKind::NoEquals),
                        "{path:?} {long} {value}: {e}"
                    );
                }
            }
        }
    }
}
