//! `ratelab top`: the processes, nodes and topics of every running graph as a refreshing
//! table, as `top` shows processes: on a terminal one page at a time (PgDn/PgUp), sorted by
//! a column (`--sort`, key `s`); `--once` prints every row for scripts.

use crate::cli::{SortBy, TopArgs};
use ratelab::distributed::credentials::Role;
use ratelab::distributed::monitor::{ask_graph, placed_processes, Carried, PlacedProcess};
use ratelab::distributed::process::LiveStats;
use ratelab::distributed::zenoh::{self, Wait};
use ratelab::distributed::{check_endpoint, live_tokens, open_client, Access};
use ratelab::scheduler::StopFlag;
use std::collections::BTreeMap;
use std::time::{Duration, Instant};

/// `ratelab top`: refresh a table of every graph reachable from `--connect`.
pub fn run_top(a: &TopArgs, stop: StopFlag) -> anyhow::Result<()> {
    for ep in &a.connect {
        check_endpoint("--connect", ep, false)?;
    }
    let crate::rendezvous::Target {
        connect,
        hint,
        credentials,
    } = crate::rendezvous::target(
        &a.connect,
        a.credentials.as_deref(),
        &crate::rendezvous::launches(),
    )?;
    let access = Access {
        credentials: &credentials,
        role: &Role::Observer,
        spec: None,
    };
    // A client of the launcher's router, as a watcher is: it hears every process through
    // the router, whether the processes are its clients (a star) or peers linked to each
    // other (a peer would be taken for one of those, and hear none of them).
    let session = open_client(&connect, access)
        .map_err(|e| anyhow::anyhow!("cannot reach {}: {e}: {hint}", connect.join(", ")))?;
    let (tx, rx) = crossbeam_channel::bounded::<LiveStats>(1024);
    // `top` shows counts: figures without the lab's batch (`Keys::stats_counts`).
    let _sub = session
        .declare_subscriber("ratelab/*/@stats/*/counts")
        .callback(move |s| {
            if let Some(mut m) = LiveStats::from_sample(&s) {
                m.steps = Vec::new();
                m.ticks = Vec::new();
                m.counters = Vec::new();
                let _ = tx.try_send(m);
            }
        })
        .wait()
        .map_err(|e| anyhow::anyhow!("zenoh: {e}"))?;
    // A launch's end (its summary on `@ended`): its graph leaves the table, and a refreshing
    // `top` with nothing left to show ends too.
    let (ended_tx, ended_rx) = crossbeam_channel::bounded::<String>(64);
    let _ended_sub = session
        .declare_subscriber("ratelab/*/@ended")
        .callback(move |s| {
            if let Some(g) = s.key_expr().as_str().split('/').nth(1) {
                let _ = ended_tx.try_send(g.to_string());
            }
        })
        .wait()
        .map_err(|e| anyhow::anyhow!("zenoh: {e}"))?;
    let mut ended: std::collections::BTreeSet<String> = std::collections::BTreeSet::new();
    // Per process: the newest figures and the ones before, for rates.
    let mut seen: BTreeMap<String, (LiveStats, Option<LiveStats>)> = BTreeMap::new();
    // Per graph: its shape (asked of its launcher once), so that a process gone before
    // `top` heard from it is listed too and a restarted one's counts go on.
    let mut graphs: BTreeMap<String, Known> = BTreeMap::new();
    let started = Instant::now();
    let mut last_print = Instant::now();
    // On a terminal (not `--once`): pages and keys.
    let keys = (!a.once).then(Keys::start).flatten();
    let mut paging = Paging {
        sort: a.sort,
        page: 0,
        redraw: false,
    };
    // A key taken while waiting for one, handled first.
    let mut held: Option<TopKey> = None;
    loop {
        if let Some(k) = &keys {
            for key in held.take().into_iter().chain(k.rx.try_iter()) {
                if paging.on_key(key) {
                    return Ok(());
                }
            }
        }
        for g in ended_rx.try_iter() {
            if !a.once {
                seen.retain(|_, (m, _)| ratelab::distributed::Keys::new(&m.graph).graph() != g);
            }
            ended.insert(g);
        }
        if !a.once && !ended.is_empty() && seen.is_empty() {
            let graphs: Vec<&str> = ended.iter().map(String::as_str).collect();
            drop(keys); // the terminal given back first: the line starts at its start
            println!(
                "ratelab top: the launch of graph '{}' ended",
                graphs.join("', '")
            );
            return Ok(());
        }
        while let Ok(m) = rx.try_recv() {
            if !a.once && ended.contains(ratelab::distributed::Keys::new(&m.graph).graph()) {
                continue; // a last figure after its launch's end
            }
            let key = format!("{}/{}", m.graph, m.process);
            // Rates over about a second: the figures before stay until the new ones are a
            // second newer (processes publish every 100 ms); none across a restart.
            let prev = match seen.remove(&key) {
                Some((_, Some(p))) if m.t_ns.saturating_sub(p.t_ns) < 1_000_000_000 => Some(p),
                Some((cur, _)) => Some(cur),
                None => None,
            }
            .filter(|p| p.pid == m.pid);
            graphs
                .entry(m.graph.clone())
                .or_insert_with(|| Known::new(ask_graph(&session, &m.graph)))
                .see(&m);
            seen.insert(key, (m, prev));
        }
        let alive = alive_nodes(&session);
        if a.once {
            // Rates over half a second at least (a process gone sends no more figures).
            let have_rates = seen.values().all(|(m, p)| {
                !alive.iter().any(|(ap, _)| *ap == m.process)
                    || p.as_ref()
                        .is_some_and(|p| m.t_ns.saturating_sub(p.t_ns) >= 500_000_000)
            });
            if (!seen.is_empty() && have_rates) || started.elapsed() > Duration::from_secs(3) {
                if seen.is_empty() {
                    anyhow::bail!(
                        "no running ratelab graph answered at {} within 3 s: {hint}",
                        connect.join(", ")
                    );
                }
                let mut t = build_table(&seen, &alive, &graphs);
                t.sort(paging.sort);
                print!("{}", t.render(paging.sort));
                return Ok(());
            }
        } else if paging.redraw || last_print.elapsed() >= Duration::from_secs(1) {
            last_print = Instant::now();
            let mut text = paging.frame(build_table(&seen, &alive, &graphs), keys.is_some());
            if seen.is_empty() {
                text.push_str(&format!(
                    "\n(waiting for a graph at {})\n",
                    a.connect.join(", ")
                ));
            }
            print_raw(&text, keys.is_some());
        }
        if stop.is_stopped() {
            return Ok(());
        }
        match &keys {
            // A key redraws at once.
            Some(k) => held = k.rx.recv_timeout(Duration::from_millis(100)).ok(),
            None => std::thread::sleep(Duration::from_millis(100)),
        }
    }
}

/// A refreshing `top`'s sort and page.
struct Paging {
    sort: SortBy,
    /// The page shown (past the last: the last).
    page: usize,
    /// A key changed what to show: draw again now.
    redraw: bool,
}

impl Paging {
    /// Take a key; true when it asks to quit.
    fn on_key(&mut self, key: TopKey) -> bool {
        match key {
            TopKey::Quit => return true,
            TopKey::NextPage => self.page = self.page.saturating_add(1),
            TopKey::PreviousPage => self.page = self.page.saturating_sub(1),
            TopKey::First => self.page = 0,
            TopKey::Last => self.page = usize::MAX,
            TopKey::Sort => {
                self.sort = self.sort.next();
                self.page = 0;
            }
        }
        self.redraw = true;
        false
    }

    /// The text of a frame of table `t`: on a terminal (`paged`), the screen cleared and the
    /// cursor homed (like `top`), then the page that fits; to a pipe, the whole table.
    fn frame(&mut self, mut t: Table, paged: bool) -> String {
        self.redraw = false;
        t.sort(self.sort);
        if !paged {
            return t.render(self.sort);
        }
        let (cols, rows) =
            crossterm::terminal::size().map_or((80, 24), |(c, r)| (usize::from(c), usize::from(r)));
        let (text, page) = t.render_page(self.page, cols, rows, self.sort);
        self.page = page;
        format!("\x1b[2J\x1b[H{text}")
    }
}

/// Print `text` and flush; `raw`: the terminal is in raw mode, where a line feed does not
/// return the cursor, so each line ends in CR LF.
fn print_raw(text: &str, raw: bool) {
    use std::io::Write;
    let mut out = std::io::stdout().lock();
    let _ = if raw {
        out.write_all(text.replace('\n', "\r\n").as_bytes())
    } else {
        out.write_all(text.as_bytes())
    };
    let _ = out.flush();
}

/// What a key asks of a refreshing `top`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum TopKey {
    NextPage,
    PreviousPage,
    First,
    Last,
    Sort,
    Quit,
}

/// `top`'s keys as data: each key and what it asks (the page line names them).
const TOP_KEYS: &[(crossterm::event::KeyCode, TopKey)] = {
    use crossterm::event::KeyCode::{Char, Down, End, Esc, Home, PageDown, PageUp, Up};
    &[
        (PageDown, TopKey::NextPage),
        (Char(' '), TopKey::NextPage),
        (Down, TopKey::NextPage),
        (Char('j'), TopKey::NextPage),
        (PageUp, TopKey::PreviousPage),
        (Up, TopKey::PreviousPage),
        (Char('k'), TopKey::PreviousPage),
        (Home, TopKey::First),
        (End, TopKey::Last),
        (Char('s'), TopKey::Sort),
        (Char('q'), TopKey::Quit),
        (Esc, TopKey::Quit),
    ]
};

/// A key event as `top` reads it (Ctrl-C quits: in raw mode it is a key, not a signal).
fn top_key(k: crossterm::event::KeyEvent) -> Option<TopKey> {
    use crossterm::event::{KeyCode, KeyEventKind, KeyModifiers};
    if k.kind == KeyEventKind::Release {
        return None;
    }
    if k.modifiers.contains(KeyModifiers::CONTROL) && k.code == KeyCode::Char('c') {
        return Some(TopKey::Quit);
    }
    TOP_KEYS.iter().find(|(c, _)| *c == k.code).map(|(_, t)| *t)
}

/// The keys of a refreshing `top` on a terminal: raw mode while it runs (restored when
/// dropped), and a thread that reads keys.
struct Keys {
    rx: crossbeam_channel::Receiver<TopKey>,
}

impl Keys {
    /// Raw mode and a reader of keys, when both stdin and stdout are terminals.
    fn start() -> Option<Keys> {
        use std::io::IsTerminal;
        if !(std::io::stdin().is_terminal() && std::io::stdout().is_terminal()) {
            return None;
        }
        crossterm::terminal::enable_raw_mode().ok()?;
        let (send, rx) = crossbeam_channel::bounded(64);
        std::thread::spawn(move || {
            while let Ok(ev) = crossterm::event::read() {
                if let Some(k) = match ev {
                    crossterm::event::Event::Key(k) => top_key(k),
                    _ => None,
                } {
                    if send.send(k).is_err() {
                        break;
                    }
                }
            }
        });
        Some(Keys { rx })
    }
}

impl Drop for Keys {
    fn drop(&mut self) {
        let _ = crossterm::terminal::disable_raw_mode();
        print_raw("\n", false);
    }
}

/// The nodes whose liveliness tokens are alive now: `(process, node)`.
fn alive_nodes(session: &zenoh::Session) -> Vec<(String, String)> {
    // At most every node of 4 graphs of the largest size (a few hundred MB of names at
    // most from whatever answers).
    let max = 4 * ratelab::ids::MAX_NODES;
    live_tokens(
        session,
        "ratelab/*/@node/*/*",
        Duration::from_millis(300),
        max,
    )
    .iter()
    .filter_map(|key| match key.split('/').collect::<Vec<_>>().as_slice() {
        [_, _, _, p, n] => Some(((*p).to_string(), (*n).to_string())),
        _ => None,
    })
    .collect()
}

/// What `top` knows of a running graph beyond its processes' figures: its shape, as its
/// launcher answered (none when it did not), and the counts of its restarted processes.
struct Known {
    /// Its processes as placed.
    placed: Vec<PlacedProcess>,
    /// The graph, with the counts its restarted processes carry over.
    carried: Option<(ratelab::graph::spec::GraphSpec, Carried)>,
}

impl Known {
    fn new(spec: Option<ratelab::graph::spec::GraphSpec>) -> Known {
        match spec {
            Some(spec) => Known {
                placed: placed_processes(&spec),
                carried: Some((spec.clone(), Carried::new(&spec))),
            },
            None => Known {
                placed: Vec::new(),
                carried: None,
            },
        }
    }

    /// Take in a process's figures.
    fn see(&mut self, m: &LiveStats) {
        if let Some((spec, carried)) = &mut self.carried {
            carried.see(spec, m);
        }
    }

    /// Node `name`'s ticks `now` (its process's count), continued from the processes
    /// before it that `top` heard.
    fn ticks(&self, name: &str, now: u64) -> u64 {
        self.carried
            .as_ref()
            .and_then(|(spec, c)| {
                let i = spec.nodes.iter().position(|n| n.name == name)?;
                Some(c.node_ticks(i, now))
            })
            .unwrap_or(now)
    }

    /// Topic `name`'s counters `now` (its holder's), continued likewise.
    fn counters(&self, name: &str, now: &ratelab::topic::TopicStats) -> ratelab::topic::TopicStats {
        self.carried
            .as_ref()
            .and_then(|(spec, c)| {
                let i = spec.topics.iter().position(|t| t.name == name)?;
                Some(c.continued(i, now))
            })
            .unwrap_or(*now)
    }

    /// What the counts of process `m.process` leave out, said after them: its runs before
    /// a rejoin that `top` did not hear (empty when they cover the whole run).
    fn since(&self, m: &LiveStats) -> String {
        let carried = self
            .carried
            .as_ref()
            .is_some_and(|(_, c)| c.saw_restart(&m.process));
        match m.since_ns {
            Some(t) if !carried => format!("since it rejoined at {:.2} s", t as f64 / 1e9),
            _ => String::new(),
        }
    }
}

/// A node's row of `top`'s table: what it is sorted by, and the line.
struct NodeRow {
    /// Its place in the table as built (processes in order, each one's nodes in order).
    order: usize,
    /// Measured rate, Hz.
    meas_hz: Option<f64>,
    ticks: Option<u64>,
    alive: bool,
    line: String,
}

/// A topic's row of `top`'s table: what it is sorted by, and the line.
struct TopicLine {
    name: String,
    msg_per_s: Option<f64>,
    published: Option<u64>,
    /// Dropped and lost.
    trouble: Option<u64>,
    line: String,
}

/// `top`'s table: its first line, then every process's nodes and every topic with its
/// counters (continued across a restart `top` heard; a note where they leave something
/// out), each row with the figures it can be sorted by.
struct Table {
    head: String,
    nodes: Vec<NodeRow>,
    topics: Vec<TopicLine>,
}

/// The column headings of `top`'s two tables.
fn node_heading() -> String {
    format!(
        "{:<10} {:>7} {:<10} {:<9} {:>8} {:>8} {:>10} {:<6}",
        "PROCESS", "PID", "NODE", "KIND", "RATE_HZ", "TICKS", "MEAS_HZ", "ALIVE"
    )
}

fn topic_heading() -> String {
    format!(
        "{:<10} {:>8} {:>10} {:>8} {:>6} {:>9} {:>9}",
        "TOPIC", "MSG/S", "PUBLISHED", "DROPPED", "LOST", "WIRE_P50", "WIRE_P99"
    )
}

/// A window of `top`'s table on a terminal: which page, of how many rows.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
struct Page {
    /// The page, from 0 (past the last: the last).
    index: usize,
    /// Rows the terminal has for the table (headings and the page line included).
    rows: usize,
}

impl Table {
    /// Sort the rows by `by`. By name: the nodes in the table's order (each process's in
    /// its order), the topics by name; ties of the others keep that order.
    fn sort(&mut self, by: SortBy) {
        let desc = |a: Option<f64>, b: Option<f64>| {
            b.unwrap_or(f64::NEG_INFINITY)
                .total_cmp(&a.unwrap_or(f64::NEG_INFINITY))
        };
        // Stable: ties keep the table's order (processes, then each one's nodes).
        self.nodes.sort_by(|a, b| match by {
            SortBy::Name => a.order.cmp(&b.order),
            SortBy::Rate => desc(a.meas_hz, b.meas_hz),
            SortBy::Count => b.ticks.cmp(&a.ticks),
            SortBy::Trouble => a.alive.cmp(&b.alive),
        });
        self.topics.sort_by(|a, b| {
            match by {
                SortBy::Name => std::cmp::Ordering::Equal,
                SortBy::Rate => desc(a.msg_per_s, b.msg_per_s),
                SortBy::Count => b.published.cmp(&a.published),
                SortBy::Trouble => b.trouble.cmp(&a.trouble),
            }
            .then_with(|| a.name.cmp(&b.name))
        });
    }

    /// Page `index` (past the last: the last) for a terminal `cols` × `rows`, and the page it
    /// is: `rows` lines at most, none wider than `cols` (a wrapped line would scroll the
    /// title away), the last with no line feed after it.
    fn render_page(&self, index: usize, cols: usize, rows: usize, by: SortBy) -> (String, usize) {
        let (text, page) = self.render_with(Some(Page { index, rows }), by);
        let lines: Vec<String> = text
            .lines()
            .take(rows.max(1))
            .map(|l| {
                if l.chars().count() <= cols {
                    return l.to_string();
                }
                // The page line gives up its keys before its page; a row is cut.
                let short = l.split(" · ").next().unwrap_or(l);
                if l.starts_with("page ") && short.chars().count() <= cols {
                    short.to_string()
                } else {
                    l.chars().take(cols).collect()
                }
            })
            .collect();
        (lines.join("\n"), page)
    }

    /// The table as text, every row.
    fn render(&self, by: SortBy) -> String {
        self.render_with(None, by).0
    }

    /// The table as text: every row, or (`page`) one page of each table that fits the
    /// terminal, with a line that says which page and the keys; and the page shown.
    fn render_with(&self, page: Option<Page>, by: SortBy) -> (String, usize) {
        use std::fmt::Write;
        let (nodes, topics, footer, shown) = match page {
            None => (&self.nodes[..], &self.topics[..], None, 0),
            Some(p) => {
                // Title, two headings, the blank line between and the page line.
                let room = p.rows.saturating_sub(5).max(2);
                let (n, t) = (self.nodes.len(), self.topics.len());
                // Each table half the rows, the other's share where one needs less.
                let mut for_nodes = (room / 2).max(1);
                if t < room - for_nodes {
                    for_nodes = room - t;
                }
                let for_nodes = for_nodes.min(n).max(1);
                let for_topics = room.saturating_sub(for_nodes).max(1);
                let pages = n.div_ceil(for_nodes).max(t.div_ceil(for_topics)).max(1);
                let index = p.index.min(pages - 1);
                let window = |len: usize, per: usize| {
                    let from = (index * per).min(len);
                    from..(from + per).min(len)
                };
                (
                    &self.nodes[window(n, for_nodes)],
                    &self.topics[window(t, for_topics)],
                    Some(format!(
                        "page {}/{pages} · sorted by {} · {}, {} · PgDn/PgUp s q",
                        index + 1,
                        by.word(),
                        ratelab::metrics::counted(n as u64, "node"),
                        ratelab::metrics::counted(t as u64, "topic")
                    )),
                    index,
                )
            }
        };
        let mut s = String::new();
        let _ = writeln!(s, "{}", self.head);
        // Columns are padded to line up; a row ends at its last character.
        let _ = writeln!(s, "{}", node_heading().trim_end());
        for r in nodes {
            let _ = writeln!(s, "{}", r.line.trim_end());
        }
        let _ = writeln!(s, "\n{}", topic_heading().trim_end());
        for r in topics {
            let _ = writeln!(s, "{}", r.line.trim_end());
        }
        if let Some(f) = footer {
            let _ = writeln!(s, "{f}");
        }
        (s, shown)
    }
}

/// The table `top` prints, every row, sorted by name.
#[cfg(test)]
fn table(
    seen: &BTreeMap<String, (LiveStats, Option<LiveStats>)>,
    alive: &[(String, String)],
    graphs: &BTreeMap<String, Known>,
) -> String {
    let mut t = build_table(seen, alive, graphs);
    t.sort(SortBy::Name);
    t.render(SortBy::Name)
}

/// `top`'s table from what it heard: `seen`, each process's newest figures and the ones
/// about a second before; `alive`, the (process, node) liveliness tokens; `graphs`, each
/// graph's shape.
fn build_table(
    seen: &BTreeMap<String, (LiveStats, Option<LiveStats>)>,
    alive: &[(String, String)],
    graphs: &BTreeMap<String, Known>,
) -> Table {
    let t = seen.values().map(|(m, _)| m.t_ns).max().unwrap_or(0);
    let alive_set: std::collections::HashSet<(&str, &str)> = alive
        .iter()
        .map(|(p, n)| (p.as_str(), n.as_str()))
        .collect();
    let alive_processes: std::collections::HashSet<&str> =
        alive.iter().map(|(p, _)| p.as_str()).collect();
    // The placed processes `top` has no figures from (gone before it heard them, or not
    // yet started).
    let unheard: Vec<(&String, &PlacedProcess)> = graphs
        .iter()
        .flat_map(|(g, k)| k.placed.iter().map(move |p| (g, p)))
        .filter(|(g, p)| !seen.contains_key(&format!("{g}/{}", p.name)))
        .collect();
    let unknown = Known::new(None);
    let head = match seen.len() + unheard.len() {
        1 => format!("ratelab top: 1 process, run time {:.2} s", t as f64 / 1e9),
        n => format!(
            "ratelab top: {n} processes, run time {:.2} s",
            t as f64 / 1e9
        ),
    };
    let mut nodes = unheard_node_rows(&unheard, &alive_set);
    let mut wire: BTreeMap<String, (f64, f64)> = BTreeMap::new();
    let mut topics: Vec<TopicRow> = Vec::new();
    for (m, prev) in seen.values() {
        let p = &m.process;
        let known = graphs.get(&m.graph).unwrap_or(&unknown);
        let since = known.since(m);
        let dt = prev
            .as_ref()
            .map(|q| m.t_ns.saturating_sub(q.t_ns) as f64 / 1e9)
            .filter(|d| *d > 0.0);
        let before_ticks: std::collections::HashMap<&str, u64> = prev
            .iter()
            .flat_map(|q| q.nodes.iter().map(|n| (n.0.as_str(), n.3)))
            .collect();
        for (name, kind, hz, ticks) in &m.nodes {
            let is_alive = alive_set.contains(&(p.as_str(), name.as_str()));
            // A node gone has no rate now (its last figures would show its old one).
            let meas_hz = match (dt, before_ticks.get(name.as_str()), is_alive) {
                (Some(dt), Some(b), true) => Some(ticks.saturating_sub(*b) as f64 / dt),
                _ => None,
            };
            let ticks = known.ticks(name, *ticks);
            let line = format!(
                "{:<10} {:>7} {:<10} {:<9} {:>8.1} {:>8} {:>10} {:<6} {since}",
                p,
                m.pid,
                name,
                kind,
                hz,
                ticks,
                meas_hz.map_or_else(|| "-".to_string(), |h| format!("{h:.1}")),
                if is_alive { "yes" } else { "GONE" }
            );
            nodes.push(NodeRow {
                order: nodes.len(),
                meas_hz,
                ticks: Some(ticks),
                alive: is_alive,
                line: line.trim_end().to_string(),
            });
        }
        let process_alive = alive_processes.contains(p.as_str());
        // A holder gone took its counting with it: its last counts stand, and say so.
        let why = if !process_alive && !m.done {
            format!("counted by '{p}' until it went")
        } else if since.is_empty() {
            String::new()
        } else {
            format!("counted by '{p}' {since}")
        };
        let before_published: std::collections::HashMap<&str, u64> = prev
            .iter()
            .flat_map(|q| q.topics.iter().map(|x| (x.0.as_str(), x.1.published)))
            .collect();
        for (name, st) in &m.topics {
            let before = before_published
                .get(name.as_str())
                .copied()
                .filter(|_| process_alive);
            let rate = match (dt, before) {
                (Some(dt), Some(b)) => Some(st.published.saturating_sub(b) as f64 / dt),
                _ => None,
            };
            let st = known.counters(name, st);
            topics.push((
                name.clone(),
                rate,
                Some([st.published, st.dropped, st.lost]),
                why.clone(),
            ));
        }
        for w in &m.wire {
            wire.insert(w.topic.clone(), (w.p50_us, w.p99_us));
        }
    }
    unheard_topic_rows(&mut topics, &unheard, &alive_processes);
    let topics = topics
        .into_iter()
        .map(|(name, rate, counts, why)| {
            let (p50, p99) = match wire.get(&name) {
                // No figures from its counting process: nothing to show of its wire either.
                _ if counts.is_none() => ("-".to_string(), "-".to_string()),
                Some((a, b)) => (format!("{a:.0} µs"), format!("{b:.0} µs")),
                None => ("in-proc".to_string(), "-".to_string()),
            };
            let [published, dropped, lost] =
                counts.map_or(["-".to_string(), "-".into(), "-".into()], |c| {
                    c.map(|n| n.to_string())
                });
            let shown_rate = rate.map_or_else(|| "-".to_string(), |r| format!("{r:.1}"));
            let line = format!(
                "{name:<10} {shown_rate:>8} {published:>10} {dropped:>8} {lost:>6} {p50:>9} {p99:>9}  {why}"
            );
            TopicLine {
                msg_per_s: rate,
                published: counts.map(|c| c[0]),
                trouble: counts.map(|c| c[1].saturating_add(c[2])),
                line: line.trim_end().to_string(),
                name,
            }
        })
        .collect();
    Table {
        head,
        nodes,
        topics,
    }
}

/// A topic of `top`'s table before it is written: name, msg/s, (published, dropped,
/// lost) where its counting process told them, and who counted.
type TopicRow = (String, Option<f64>, Option<[u64; 3]>, String);

/// `top`'s node rows of the placed processes it has no figures from: alive or gone, no
/// counts.
fn unheard_node_rows(
    unheard: &[(&String, &PlacedProcess)],
    alive: &std::collections::HashSet<(&str, &str)>,
) -> Vec<NodeRow> {
    let mut rows = Vec::new();
    for (_, placed) in unheard {
        let p = &placed.name;
        for (name, kind, hz) in &placed.nodes {
            let is_alive = alive.contains(&(p.as_str(), name.as_str()));
            let line = format!(
                "{:<10} {:>7} {:<10} {:<9} {:>8.1} {:>8} {:>10} {:<6}",
                p,
                "-",
                name,
                kind,
                hz,
                "-",
                "-",
                if is_alive { "yes" } else { "GONE" }
            );
            rows.push(NodeRow {
                order: rows.len(),
                meas_hz: None,
                ticks: None,
                alive: is_alive,
                line,
            });
        }
    }
    rows
}

/// A topic held by a process with no figures here still has its row: its counters live
/// there, so none can be shown, and the row says why.
fn unheard_topic_rows(
    topics: &mut Vec<TopicRow>,
    unheard: &[(&String, &PlacedProcess)],
    alive_processes: &std::collections::HashSet<&str>,
) {
    let listed: std::collections::HashSet<String> = topics.iter().map(|t| t.0.clone()).collect();
    for (_, placed) in unheard {
        let gone = !alive_processes.contains(placed.name.as_str());
        for name in &placed.holds {
            if listed.contains(name) {
                continue;
            }
            let why = if gone {
                format!("counted by '{}', which is gone", placed.name)
            } else {
                format!("counted by '{}': no figures yet", placed.name)
            };
            topics.push((name.clone(), None, None, why));
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn stats(process: &str, t_ns: u64, sensor_ticks: u64) -> LiveStats {
        LiveStats {
            graph: "cartpole".into(),
            process: process.into(),
            pid: 42,
            t_ns,
            nodes: vec![("sensor".into(), "sensor".into(), 50.0, sensor_ticks)],
            topics: vec![(
                "/action".into(),
                ratelab::topic::TopicStats {
                    published: 40,
                    ..Default::default()
                },
            )],
            wire: Vec::new(),
            steps: Vec::new(),
            ticks: Vec::new(),
            counters: Vec::new(),
            done: false,
            since_ns: None,
        }
    }

    /// The policy's process's figures: its pid, the counts of `/obs` (which it holds) and
    /// of its node's ticks, and the run time it joined at when it rejoined.
    fn policy_stats(pid: u32, counted: u64, since_ns: Option<u64>) -> LiveStats {
        LiveStats {
            process: "policy".into(),
            pid,
            t_ns: 3_000_000_000,
            nodes: vec![("policy".into(), "policy".into(), 50.0, counted)],
            topics: vec![(
                "/obs".into(),
                ratelab::topic::TopicStats {
                    published: counted,
                    dropped: 2,
                    ..Default::default()
                },
            )],
            since_ns,
            ..stats("policy", 0, 0)
        }
    }

    fn row<'a>(t: &'a str, starts: &str) -> &'a str {
        t.lines()
            .find(|l| l.starts_with(starts))
            .unwrap_or_else(|| panic!("no row {starts}: {t}"))
    }

    #[test]
    fn a_restarted_process_counts_on_or_says_what_its_counts_leave_out() {
        let spec = ratelab::graph::GraphSpec::chapter();
        let alive = vec![
            ("robot".to_string(), "sensor".to_string()),
            ("policy".to_string(), "policy".to_string()),
        ];
        let (first, again) = (
            policy_stats(7, 100, None),
            policy_stats(8, 30, Some(2_000_000_000)),
        );
        let seen = BTreeMap::from([("cartpole/policy".to_string(), (again.clone(), None))]);
        // Heard before and after its restart: the counts go on.
        let mut known = Known::new(Some(spec.clone()));
        known.see(&first);
        known.see(&again);
        let graphs = BTreeMap::from([("cartpole".to_string(), known)]);
        let t = table(&seen, &alive, &graphs);
        let obs = row(&t, "/obs");
        let cols: Vec<&str> = obs.split_whitespace().collect();
        assert_eq!(
            cols[2..4],
            ["130", "4"],
            "published and dropped carried over: {t}"
        );
        assert!(!obs.contains("since") && !obs.contains("counted by"), "{t}");
        let node = row(&t, "policy ");
        assert!(node.contains(" 130 ") && node.ends_with("yes"), "{t}");
        // Heard only after it: its own counts, and what they leave out.
        let mut known = Known::new(Some(spec.clone()));
        known.see(&again);
        let graphs = BTreeMap::from([("cartpole".to_string(), known)]);
        let t = table(&seen, &alive, &graphs);
        let obs = row(&t, "/obs");
        assert!(obs.contains(" 30 "), "{t}");
        assert!(
            obs.ends_with("counted by 'policy' since it rejoined at 2.00 s"),
            "{t}"
        );
        assert!(
            row(&t, "policy ").ends_with("yes    since it rejoined at 2.00 s"),
            "{t}"
        );
        // Gone: its last counts stand, and say so.
        let robot_only = vec![("robot".to_string(), "sensor".to_string())];
        let t = table(&seen, &robot_only, &graphs);
        let obs = row(&t, "/obs");
        assert!(
            obs.contains(" 30 ") && obs.contains(" - "),
            "no rate for a gone holder: {t}"
        );
        assert!(obs.ends_with("counted by 'policy' until it went"), "{t}");
        assert!(row(&t, "policy ").contains("GONE"), "{t}");
    }

    /// A process of `n` nodes and topics: node `node_k` ticked `k` times, topic `/t_k`
    /// published `k` times and dropped `n - k`.
    fn big(n: u64) -> BTreeMap<String, (LiveStats, Option<LiveStats>)> {
        let at = |t_ns: u64, scale: u64| LiveStats {
            nodes: (0..n)
                .map(|k| (format!("node_{k}"), "sensor".into(), 50.0, k * scale))
                .collect(),
            topics: (0..n)
                .map(|k| {
                    (
                        format!("/t_{k}"),
                        ratelab::topic::TopicStats {
                            published: k * scale,
                            dropped: n - k,
                            ..Default::default()
                        },
                    )
                })
                .collect(),
            ..stats("robot", t_ns, 0)
        };
        BTreeMap::from([(
            "cartpole/robot".to_string(),
            (at(2_000_000_000, 2), Some(at(1_000_000_000, 1))),
        )])
    }

    #[test]
    fn top_sorts_by_each_column() {
        let seen = big(5);
        let alive: Vec<(String, String)> = (0..5)
            .filter(|k| *k != 2)
            .map(|k| ("robot".to_string(), format!("node_{k}")))
            .collect();
        let graphs = BTreeMap::new();
        let order = |by: SortBy| {
            let mut t = build_table(&seen, &alive, &graphs);
            t.sort(by);
            let text = t.render(by);
            let names = |prefix: &str| -> Vec<String> {
                text.lines()
                    .flat_map(|l| l.split_whitespace())
                    .filter(|w| w.starts_with(prefix))
                    .map(String::from)
                    .collect()
            };
            (names("node_"), names("/t_"))
        };
        let (nodes, topics) = order(SortBy::Name);
        assert_eq!(nodes, ["node_0", "node_1", "node_2", "node_3", "node_4"]);
        assert_eq!(topics, ["/t_0", "/t_1", "/t_2", "/t_3", "/t_4"]);
        // Rate: ticks and messages over the second between the two figures, highest
        // first; node_2 is gone and has no rate.
        let (nodes, topics) = order(SortBy::Rate);
        assert_eq!(nodes, ["node_4", "node_3", "node_1", "node_0", "node_2"]);
        assert_eq!(topics, ["/t_4", "/t_3", "/t_2", "/t_1", "/t_0"]);
        let (nodes, topics) = order(SortBy::Count);
        assert_eq!(nodes, ["node_4", "node_3", "node_2", "node_1", "node_0"]);
        assert_eq!(topics[0], "/t_4");
        // Trouble: the gone node first; the topic that dropped most first.
        let (nodes, topics) = order(SortBy::Trouble);
        assert_eq!(nodes[0], "node_2");
        assert_eq!(topics, ["/t_0", "/t_1", "/t_2", "/t_3", "/t_4"]);
        let mut by = SortBy::Name;
        for _ in 0..4 {
            by = by.next();
        }
        assert_eq!(by, SortBy::Name);
    }

    #[test]
    fn on_a_terminal_top_shows_a_page_that_fits_and_the_last_at_most() {
        let seen = big(1000);
        let alive = Vec::new();
        let graphs = BTreeMap::new();
        let t = build_table(&seen, &alive, &graphs);
        // 24 rows: 19 for rows, 9 nodes and 10 topics a page.
        let (first, page) = t.render_page(0, 80, 24, SortBy::Name);
        assert_eq!(page, 0);
        // Every line within the terminal, and none after the last (it would scroll).
        assert_eq!(first.lines().count(), 24, "{first}");
        assert!(!first.ends_with('\n'));
        assert!(first.lines().all(|l| l.chars().count() <= 80), "{first}");
        let (narrow, _) = t.render_page(0, 40, 24, SortBy::Name);
        assert!(narrow.lines().all(|l| l.chars().count() <= 40), "{narrow}");
        assert_eq!(narrow.lines().last(), Some("page 1/112"), "{narrow}");
        assert!(
            first.contains("node_0 ") && first.contains("node_8 "),
            "{first}"
        );
        assert!(!first.contains("node_9 "), "{first}");
        assert!(
            first.contains("/t_9 ") && !first.contains("/t_10 "),
            "{first}"
        );
        let last = first.lines().last().unwrap();
        assert!(
            last.starts_with("page 1/112 · sorted by name · 1000 nodes, 1000 topics"),
            "{last}"
        );
        let (second, _) = t.render_page(1, 80, 24, SortBy::Name);
        assert!(
            second.contains("node_9 ") && second.contains("/t_10 "),
            "{second}"
        );
        // Past the last: the last.
        let (end, page) = t.render_page(usize::MAX, 80, 24, SortBy::Name);
        assert_eq!(page, 111);
        assert!(
            end.contains("node_999 ") && end.contains("page 112/112"),
            "{end}"
        );
        // A tiny terminal still shows a row of each.
        let (tiny, _) = t.render_page(0, 80, 7, SortBy::Name);
        assert_eq!(tiny.lines().count(), 7, "{tiny}");
        assert!(tiny.contains("node_0 ") && tiny.contains("/t_0 "), "{tiny}");
        // Few topics: the nodes take the rows they leave.
        let few = Table {
            topics: Vec::new(),
            ..build_table(&seen, &alive, &graphs)
        };
        let (text, _) = few.render_page(0, 80, 24, SortBy::Name);
        assert!(
            text.contains("node_18 ") && !text.contains("node_19 "),
            "{text}"
        );
    }

    #[test]
    fn top_s_keys() {
        use crossterm::event::{KeyCode, KeyEvent, KeyModifiers};
        let key = |c| top_key(KeyEvent::new(c, KeyModifiers::NONE));
        assert_eq!(key(KeyCode::PageDown), Some(TopKey::NextPage));
        assert_eq!(key(KeyCode::Char(' ')), Some(TopKey::NextPage));
        assert_eq!(key(KeyCode::PageUp), Some(TopKey::PreviousPage));
        assert_eq!(key(KeyCode::Home), Some(TopKey::First));
        assert_eq!(key(KeyCode::End), Some(TopKey::Last));
        assert_eq!(key(KeyCode::Char('s')), Some(TopKey::Sort));
        assert_eq!(key(KeyCode::Char('q')), Some(TopKey::Quit));
        assert_eq!(key(KeyCode::Char('x')), None);
        assert_eq!(
            top_key(KeyEvent::new(KeyCode::Char('c'), KeyModifiers::CONTROL)),
            Some(TopKey::Quit)
        );
    }

    #[test]
    fn a_topic_counted_by_a_process_gone_keeps_its_row_and_says_why() {
        let spec = ratelab::graph::GraphSpec::chapter();
        let placed = placed_processes(&spec);
        assert_eq!(placed[0].name, "robot");
        assert_eq!(placed[0].holds, vec!["/action"]);
        assert_eq!(
            placed[1].holds,
            vec!["/obs"],
            "the policy subscribes to /obs"
        );
        let mut seen = BTreeMap::new();
        seen.insert(
            "cartpole/robot".to_string(),
            (
                stats("robot", 2_000_000_000, 100),
                Some(stats("robot", 1_000_000_000, 50)),
            ),
        );
        let graphs = BTreeMap::from([("cartpole".to_string(), Known::new(Some(spec.clone())))]);
        let alive = vec![("robot".to_string(), "sensor".to_string())];
        let t = table(&seen, &alive, &graphs);
        let obs = t
            .lines()
            .find(|l| l.starts_with("/obs"))
            .unwrap_or_else(|| panic!("{t}"));
        assert!(obs.contains("counted by 'policy', which is gone"), "{t}");
        assert!(!obs.contains(" 0 "), "no counts made up: {t}");
        let policy = t.lines().find(|l| l.contains(" policy ")).unwrap();
        assert!(policy.trim_end().ends_with("GONE"), "{t}");
        let sensor = t.lines().find(|l| l.contains(" sensor ")).unwrap();
        assert!(sensor.contains("50.0") && sensor.contains("yes"), "{t}");
        // Still starting: no figures yet, not gone.
        let alive = vec![
            ("robot".to_string(), "sensor".to_string()),
            ("policy".to_string(), "policy".to_string()),
        ];
        let t = table(&seen, &alive, &graphs);
        assert!(t.contains("counted by 'policy': no figures yet"), "{t}");
    }
}
