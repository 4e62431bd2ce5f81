//! Reading a graph file into a [`GraphSpec`]: every rule of the format
//! ([`super`]'s header lists them) checked with the culprit's position, the nodes wired to
//! their topics, the tie-break order computed and the chapter's chain found.

use super::{
    check_actuator_rate, check_depth, check_rate_hz, executors, processes, requested,
    valid_node_name, valid_python_name, valid_topic_name, Chain, Ctx, GraphSpec, NodeSpec,
    RawGraph, RawNode, RawTopic, SpecError, TopicSpec, MAX_PYTHON_PARAMS, MAX_SUBSCRIBERS,
};
use super::{Code, Kind, MsgType, NodeId, Plant, PythonCode, TopicId};
use crate::graph::kind::{Params, Ports};
use ratelab_core::ids::MAX_NODES;
use ratelab_core::limits::{self, MAX_NODE_PORTS, MAX_TOPICS};
use ratelab_core::msg::{ForceMsg, Message, StateMsg};
use ratelab_core::qos::{self, TopicQos};
use std::cmp::Reverse;
use std::collections::{BinaryHeap, HashMap, HashSet};
use std::ops::Range;
use std::path::Path;
use toml::Spanned;

/// A topic's QoS from its table, each key through [`qos::apply_key`] (the `--qos` rules),
/// errors at the key's position.
fn topic_qos(cx: &Ctx<'_>, t: &RawTopic, depth: &mut usize) -> Result<TopicQos, SpecError> {
    let mut q = TopicQos::default();
    let mut set = |key: &str, value: String, span: Range<usize>| {
        qos::apply_key(&mut q, depth, key, &value).map_err(|e| cx.err(span, e))
    };
    if let Some(v) = &t.deadline_ms {
        set("deadline_ms", v.get_ref().to_string(), v.span())?;
    }
    if let Some(v) = &t.lifespan_ms {
        set("lifespan_ms", v.get_ref().to_string(), v.span())?;
    }
    if let Some(l) = &t.link {
        let l_ref = l.get_ref();
        set("loss", "0".into(), l.span())?; // a link, even if every key is left out
        let values = [
            &l_ref.loss,
            &l_ref.delay_ms,
            &l_ref.jitter_ms,
            &l_ref.retransmit_ms,
        ];
        for (key, v) in qos::LINK_KEYS.into_iter().zip(values) {
            if let Some(v) = v {
                set(key, v.get_ref().to_string(), v.span())?;
            }
        }
    }
    if let Some(v) = &t.history {
        q.history = *v.get_ref();
    }
    if let Some(v) = &t.delivery {
        q.delivery = *v.get_ref();
    }
    if let Some(v) = &t.reliability {
        q.reliability = *v.get_ref();
    }
    if let Some(v) = &t.durability {
        q.durability = *v.get_ref();
    }
    if let Some(v) = &t.on_deadline_missed {
        q.on_deadline_missed = *v.get_ref();
    }
    Ok(q)
}

/// "a sensor", "an actuator": the kind with its article, for messages.
fn a_kind(kind_name: &str) -> String {
    let an = kind_name.starts_with(['a', 'e', 'i', 'o', 'u']);
    format!("{} {kind_name}", if an { "an" } else { "a" })
}

/// A node's `subscribes` or `publishes`: one topic name, or a list of them (at most
/// [`MAX_NODE_PORTS`], each once), each spanned at the value.
fn topic_list(
    cx: &Ctx<'_>,
    key: &str,
    v: &Option<Spanned<toml::Value>>,
) -> Result<Vec<Spanned<String>>, SpecError> {
    let Some(v) = v else {
        return Ok(Vec::new());
    };
    let bad = || {
        cx.err(
            v.span(),
            format!("{key} must be a topic name or a list of topic names"),
        )
    };
    let names: Vec<String> = match v.get_ref() {
        toml::Value::String(name) => vec![name.clone()],
        toml::Value::Array(items) if items.len() > MAX_NODE_PORTS => {
            return Err(cx.err(
                v.span(),
                limits::refusal(
                    format_args!(
                        "{key} names {} topics; a node has at most {MAX_NODE_PORTS}",
                        items.len()
                    ),
                    "MAX_NODE_PORTS",
                ),
            ))
        }
        toml::Value::Array(items) if !items.is_empty() => items
            .iter()
            .map(|i| i.as_str().map(String::from).ok_or_else(bad))
            .collect::<Result<_, _>>()?,
        _ => return Err(bad()),
    };
    for (i, n) in names.iter().enumerate() {
        if names[..i].contains(n) {
            return Err(cx.err(v.span(), format!("{key} names '{n}' twice")));
        }
    }
    Ok(names
        .into_iter()
        .map(|n| Spanned::new(v.span(), n))
        .collect())
}

/// Validate `raw` into a spec: its name, its topics, its nodes in file order (wired to
/// their topics), the whole (one actuator, every topic published, QoS that fit), then the
/// tie-break order, the executors and the processes, and last what its queues may hold at
/// worst (`memory.rs`).
pub(super) fn build(cx: &Ctx<'_>, raw: RawGraph) -> Result<GraphSpec, SpecError> {
    let name = graph_name(cx, &raw)?;
    if raw.nodes.len() > MAX_NODES {
        return Err(cx.err(
            raw.nodes[MAX_NODES].span(),
            limits::refusal(
                format_args!("a graph has at most {MAX_NODES} nodes"),
                "MAX_NODES",
            ),
        ));
    }
    if raw.topics.len() > MAX_TOPICS {
        return Err(cx.err(
            raw.topics[MAX_TOPICS].span(),
            limits::refusal(
                format_args!("a graph has at most {MAX_TOPICS} topics"),
                "MAX_TOPICS",
            ),
        ));
    }
    if raw.nodes.is_empty() {
        return Err(cx.err(
            0..0,
            "no [[node]]: a graph needs at least an actuator (it steps the plant), and nodes that drive it",
        ));
    }
    let (mut topics, topic_spans) = read_topics(cx, &raw)?;
    let by_name: HashMap<String, usize> = topics
        .iter()
        .enumerate()
        .map(|(i, t)| (t.name.clone(), i))
        .collect();
    let mut file_nodes: Vec<NodeSpec> = Vec::new();
    let mut node_names: HashSet<String> = HashSet::new();
    let mut node_spans = Vec::new();
    let mut actuators = Vec::new();
    for n in &raw.nodes {
        let known = Known {
            topics: &by_name,
            nodes: &node_names,
        };
        let node = read_node(cx, n.get_ref(), &mut topics, &file_nodes, known)?;
        node_names.insert(node.name.clone());
        if node.kind.is_actuator() {
            actuators.push(n.get_ref().name.span());
        }
        file_nodes.push(node);
        node_spans.push(n.get_ref().name.span());
    }
    match actuators.len() {
        1 => {}
        0 => {
            return Err(cx.err(
                0..0,
                "no actuator: a graph needs exactly one (it steps the plant)",
            ))
        }
        _ => {
            return Err(cx.err(
                actuators[1].clone(),
                "a second actuator: a graph has exactly one (it steps the plant)",
            ))
        }
    }
    check_topics(cx, &raw, &topics, &topic_spans, &file_nodes)?;
    let (nodes, order) = in_tie_break_order(cx, file_nodes, &mut topics, &node_spans)?;
    let actuator = NodeId(nodes.iter().position(|n| n.kind.is_actuator()).unwrap_or(0));
    let mut spec = GraphSpec {
        name,
        nodes,
        topics,
        actuator,
        chain: None,
        executors: Vec::new(),
        restart: std::collections::BTreeMap::new(),
    };
    let no_executors = executors::RawExecutors::new();
    spec.executors = executors::executors(
        cx,
        raw.executors.as_ref().unwrap_or(&no_executors),
        &spec,
        |j| raw.nodes[order[j]].get_ref(),
    )?;
    if let Some(p) = &raw.processes {
        spec.restart = processes::processes(cx, p, &spec)?;
    }
    // The subscriptions' requests, now that every topic knows its subscribers.
    for (i, t) in raw.topics.iter().enumerate() {
        if let Some(r) = &t.get_ref().requested {
            let got =
                requested::requested(cx, r, &spec.topics[i], |n| spec.nodes[n.0].name.clone())?;
            spec.topics[i].requested = got;
        }
    }
    spec.chain = find_chain(&spec);
    // What its queues may hold at worst, once every topic knows its publisher, subscribers
    // and QoS: at the depth of the topic that takes the most.
    if let Some((t, line)) = spec.queue_refusal() {
        let at = raw
            .topics
            .get(t.0)
            .map_or(0..0, |r| r.get_ref().depth.span());
        return Err(cx.err(at, line));
    }
    Ok(spec)
}

/// The graph's `name` (default `graph`): 1 to 64 characters, none a control character.
fn graph_name(cx: &Ctx<'_>, raw: &RawGraph) -> Result<String, SpecError> {
    let Some(n) = &raw.name else {
        return Ok("graph".to_string());
    };
    if n.get_ref().trim().is_empty() || n.get_ref().len() > 64 {
        return Err(cx.err(n.span(), "name must be 1 to 64 characters"));
    }
    // The name titles the lab, names recordings and heads a launch's credentials file:
    // a control character would repaint a terminal or break that file.
    if ratelab_core::text::has_control(n.get_ref()) {
        return Err(cx.err(
            n.span(),
            format!(
                "name '{}' holds a control character",
                ratelab_core::text::printable(n.get_ref())
            ),
        ));
    }
    Ok(n.get_ref().clone())
}

/// The `[[topic]]` tables: names, types, depths and QoS, each with its name's span; no
/// publisher or subscriber yet.
fn read_topics(
    cx: &Ctx<'_>,
    raw: &RawGraph,
) -> Result<(Vec<TopicSpec>, Vec<Range<usize>>), SpecError> {
    let mut topics: Vec<TopicSpec> = Vec::with_capacity(raw.topics.len());
    let mut topic_spans = Vec::with_capacity(raw.topics.len());
    let mut seen: HashSet<&str> = HashSet::with_capacity(raw.topics.len());
    for t in &raw.topics {
        let t_ref = t.get_ref();
        let tname = t_ref.name.get_ref();
        if !valid_topic_name(tname) {
            return Err(cx.err(
                t_ref.name.span(),
                format!("topic name '{tname}' must be '/' then names of letters, digits and '_' separated by single '/', with no '/' at the end (at most 64 characters)"),
            ));
        }
        if !seen.insert(tname.as_str()) {
            return Err(cx.err(t_ref.name.span(), format!("duplicate topic '{tname}'")));
        }
        let mut depth =
            check_depth(*t_ref.depth.get_ref()).map_err(|e| cx.err(t_ref.depth.span(), e))?;
        let qos = topic_qos(cx, t_ref, &mut depth)?;
        topics.push(TopicSpec {
            name: tname.clone(),
            msg: *t_ref.msg.get_ref(),
            depth,
            qos,
            publisher: NodeId(usize::MAX),
            subscribers: Vec::new(),
            requested: std::collections::BTreeMap::new(),
        });
        topic_spans.push(t_ref.name.span());
    }
    Ok((topics, topic_spans))
}

/// What a node table is checked against: the topics by name, and the names of the nodes
/// before it (hashed: a graph may have tens of thousands of each).
#[derive(Clone, Copy)]
struct Known<'a> {
    topics: &'a HashMap<String, usize>,
    nodes: &'a HashSet<String>,
}

/// The index of the topic `r` names, or an error at `r`.
fn find_topic(
    cx: &Ctx<'_>,
    topics: &HashMap<String, usize>,
    r: &Spanned<String>,
) -> Result<usize, SpecError> {
    topics.get(r.get_ref()).copied().ok_or_else(|| {
        cx.err(
            r.span(),
            format!(
                "unknown topic '{}': declare it in a [[topic]] table",
                r.get_ref()
            ),
        )
    })
}

/// One `[[node]]` table, the next of `file_nodes` (which are the ones before it): its kind,
/// rate, parameters and settings, its topics checked against the kind's ports and wired
/// (it becomes their subscriber or publisher in `topics`).
fn read_node(
    cx: &Ctx<'_>,
    r: &RawNode,
    topics: &mut [TopicSpec],
    file_nodes: &[NodeSpec],
    known: Known<'_>,
) -> Result<NodeSpec, SpecError> {
    let nname = r.name.get_ref();
    if !valid_node_name(nname) {
        return Err(cx.err(
            r.name.span(),
            format!("node name '{nname}' must be 1 to 32 letters, digits, '_' or '-'"),
        ));
    }
    if known.nodes.contains(nname) {
        return Err(cx.err(r.name.span(), format!("duplicate node '{nname}'")));
    }
    let kind_name = r.kind.get_ref().as_str();
    let kind = crate::graph::registry::kind(kind_name).ok_or_else(|| {
        let kinds = crate::graph::registry::kinds();
        cx.err(
            r.kind.span(),
            format!(
                "unknown kind `{}`: expected one of {} (or a kind a Rust program \
                 registers: ratelab::graph::registry)",
                ratelab_core::text::printable(kind_name),
                ratelab_core::text::listed(kinds.iter().map(|k| k.as_str()))
            ),
        )
    })?;
    let hz = *r.rate_hz.get_ref();
    check_rate_hz(hz).map_err(|e| cx.err(r.rate_hz.span(), e))?;
    if kind.is_actuator() {
        check_actuator_rate(hz).map_err(|e| cx.err(r.rate_hz.span(), e))?;
    }
    let id = NodeId(file_nodes.len());
    let sub_names = topic_list(cx, "subscribes", &r.subscribes)?;
    let pub_names = topic_list(cx, "publishes", &r.publishes)?;
    // What the kind reads and publishes: per topic, the types it takes (`None`: any).
    let (reads, writes) = check_ports(cx, kind, r, &sub_names, &pub_names)?;
    let wiring = Wiring {
        cx,
        id,
        kind_name,
        node_name: nname,
        file_nodes,
        topic_index: known.topics,
    };
    let subscribes = wiring.subscribe(topics, &sub_names, &reads)?;
    let publishes = wiring.publish(topics, &pub_names, &writes)?;
    let params = node_params(cx, kind, r)?;
    let python = python_code(cx, kind, r)?;
    let liveliness_lease = r
        .liveliness_lease_ms
        .as_ref()
        .map(|v| {
            qos::ms_to_nanos("liveliness_lease_ms", *v.get_ref(), false)
                .map_err(|e| cx.err(v.span(), e))
        })
        .transpose()?;
    let start = r
        .start_ms
        .as_ref()
        .map(|v| {
            requested::start_at(*v.get_ref(), kind.is_actuator()).map_err(|e| cx.err(v.span(), e))
        })
        .transpose()?;
    let process = match &r.process {
        Some(p) if !valid_node_name(p.get_ref()) => {
            return Err(cx.err(
                p.span(),
                format!(
                    "process name '{}' must be 1 to 32 letters, digits, '_' or '-'",
                    p.get_ref()
                ),
            ))
        }
        p => p.as_ref().map(|p| p.get_ref().clone()),
    };
    let compute = r
        .compute_ms
        .as_ref()
        .map(|c| executors::compute(cx, c))
        .transpose()?
        .filter(|c| !c.is_zero());
    if let (Some(_), Some(c)) = (compute, &r.compute_ms) {
        if kind.is_actuator() {
            return Err(cx.err(c.span(), executors::ACTUATOR_NO_COMPUTE));
        }
    }
    Ok(NodeSpec {
        name: nname.clone(),
        kind,
        rate_hz: hz,
        priority: r.priority.as_ref().map(|p| *p.get_ref()),
        subscribes,
        publishes,
        params,
        liveliness_lease,
        process,
        python,
        compute,
        callback_group: r.callback_group.as_ref().map(|g| g.get_ref().clone()),
        start,
    })
}

/// One node being wired to its topics.
struct Wiring<'a> {
    cx: &'a Ctx<'a>,
    id: NodeId,
    kind_name: &'a str,
    node_name: &'a str,
    /// The nodes before it, in file order.
    file_nodes: &'a [NodeSpec],
    /// Every topic's index by name.
    topic_index: &'a HashMap<String, usize>,
}

impl Wiring<'_> {
    /// `want` (`None`: any type) against topic `t`'s type, else an error at `at` saying
    /// the node `verb`s (reads, publishes) another.
    fn check_type(
        &self,
        t: &TopicSpec,
        want: Option<&[MsgType]>,
        at: &Spanned<String>,
        verb: &str,
    ) -> Result<(), SpecError> {
        match want {
            Some(want) if !want.contains(&t.msg) => Err(self.cx.err(
                at.span(),
                format!(
                    "type mismatch: '{}' carries {} but {} node {verb} {}",
                    t.name,
                    t.msg.as_str(),
                    a_kind(self.kind_name),
                    type_names(want)
                ),
            )),
            _ => Ok(()),
        }
    }

    /// Subscribe the node to the topics `names` (each of the types `reads` gives it, if
    /// any): at most [`MAX_SUBSCRIBERS`] per topic.
    fn subscribe(
        &self,
        topics: &mut [TopicSpec],
        names: &[Spanned<String>],
        reads: &[Option<&[MsgType]>],
    ) -> Result<Vec<TopicId>, SpecError> {
        let mut subscribes = Vec::with_capacity(names.len());
        for (k, s) in names.iter().enumerate() {
            let ti = find_topic(self.cx, self.topic_index, s)?;
            let t = &mut topics[ti];
            self.check_type(t, reads.get(k).copied().flatten(), s, "reads")?;
            if t.subscribers.len() >= MAX_SUBSCRIBERS {
                return Err(self.cx.err(
                    s.span(),
                    limits::refusal(
                        format_args!(
                            "topic '{}' has {MAX_SUBSCRIBERS} subscribers already (at most {MAX_SUBSCRIBERS})",
                            t.name
                        ),
                        "MAX_SUBSCRIBERS",
                    ),
                ));
            }
            t.subscribers.push(self.id);
            subscribes.push(TopicId(ti));
        }
        Ok(subscribes)
    }

    /// Make the node the publisher of the topics `names` (each of the types `writes` gives
    /// it, if any): one publisher per topic.
    fn publish(
        &self,
        topics: &mut [TopicSpec],
        names: &[Spanned<String>],
        writes: &[Option<&[MsgType]>],
    ) -> Result<Vec<TopicId>, SpecError> {
        let mut publishes = Vec::with_capacity(names.len());
        for (k, p) in names.iter().enumerate() {
            let ti = find_topic(self.cx, self.topic_index, p)?;
            let t = &mut topics[ti];
            self.check_type(t, writes.get(k).copied().flatten(), p, "publishes")?;
            if t.publisher.0 != usize::MAX {
                let who = self
                    .file_nodes
                    .get(t.publisher.0)
                    .map_or(self.node_name, |n| &n.name);
                return Err(self.cx.err(
                    p.span(),
                    format!(
                        "topic '{}' already has a publisher ('{who}'): one publisher per topic",
                        t.name
                    ),
                ));
            }
            t.publisher = self.id;
            publishes.push(TopicId(ti));
        }
        Ok(publishes)
    }
}

/// Every topic has a publisher, and its QoS fit together (some keys only toward the
/// actuator: [`qos::check_combination`]).
fn check_topics(
    cx: &Ctx<'_>,
    raw: &RawGraph,
    topics: &[TopicSpec],
    topic_spans: &[Range<usize>],
    file_nodes: &[NodeSpec],
) -> Result<(), SpecError> {
    for (i, t) in topics.iter().enumerate() {
        if t.publisher.0 == usize::MAX {
            let why = if !t.subscribers.is_empty() {
                "has a subscriber but no publisher"
            } else {
                "is declared but no node publishes it"
            };
            return Err(cx.err(topic_spans[i].clone(), format!("topic '{}' {why}", t.name)));
        }
        let to_actuator = t
            .subscribers
            .iter()
            .any(|n| file_nodes[n.0].kind.is_actuator());
        qos::check_combination(&t.qos, to_actuator).map_err(|e| {
            let raw = raw.topics[i].get_ref();
            let at = raw
                .on_deadline_missed
                .as_ref()
                .map(Spanned::span)
                .or_else(|| raw.link.as_ref().map(Spanned::span))
                .unwrap_or_else(|| topic_spans[i].clone());
            cx.err(at, format!("topic '{}': {e}", t.name))
        })?;
    }
    Ok(())
}

/// The nodes in tie-break order (topological, explicit priorities override), the topics'
/// ends renumbered to match, and the order itself (new index → file index).
fn in_tie_break_order(
    cx: &Ctx<'_>,
    file_nodes: Vec<NodeSpec>,
    topics: &mut [TopicSpec],
    node_spans: &[Range<usize>],
) -> Result<(Vec<NodeSpec>, Vec<usize>), SpecError> {
    let order = tie_break_order(&file_nodes, topics).map_err(|cycle| {
        let first = cycle[0];
        let path: Vec<String> = cycle
            .iter()
            .chain(std::iter::once(&first))
            .map(|&i| file_nodes[i].name.clone())
            .collect();
        cx.err(
            node_spans[first].clone(),
            format!(
                "cycle {}: give one of its nodes an explicit `priority`",
                path.join(" → ")
            ),
        )
    })?;
    let mut new_index = vec![0usize; file_nodes.len()];
    for (new, &old) in order.iter().enumerate() {
        new_index[old] = new;
    }
    let nodes: Vec<NodeSpec> = order.iter().map(|&i| file_nodes[i].clone()).collect();
    for t in topics.iter_mut() {
        t.publisher = NodeId(new_index[t.publisher.0]);
        for s in &mut t.subscribers {
            *s = NodeId(new_index[s.0]);
        }
        t.subscribers.sort();
    }
    Ok((nodes, order))
}

/// The chapter's chain, if the graph has it: walk upstream from the actuator's `force`
/// input. A node that reads `state` (its first such input) is the policy; else one that
/// reads `force` passes it on (a safety limiter), and the walk goes on up it; else the
/// node drives the actuator from what it reads (a controller with its own estimator may
/// read `position` alone) and is the policy, its first input its observation. Up from the
/// policy, the walk follows first inputs (through estimators) to a node that reads the
/// plant (a sensor). Any other shape — the actuator fed by a node that reads nothing (an
/// open-loop source), a policy fed by no sensor — has no chain.
fn find_chain(spec: &GraphSpec) -> Option<Chain> {
    let actuator = spec.actuator;
    // Node `n`'s first input of type `m` (any type: `None`), with its publisher.
    let input = |n: NodeId, m: Option<MsgType>| -> Option<(TopicId, NodeId)> {
        let t = *spec.nodes[n.0]
            .subscribes
            .iter()
            .find(|t| m.is_none_or(|m| spec.topics[t.0].msg == m))?;
        Some((t, spec.topics[t.0].publisher))
    };
    let mut cur = actuator;
    let mut seen = 0;
    let (policy, action) = loop {
        let Some((t, p)) = input(cur, Some(ForceMsg::TYPE)) else {
            return None; // the actuator reads nothing
        };
        seen += 1;
        if seen > MAX_NODES {
            return None; // pass-through nodes in a loop
        }
        let reads = |m: MsgType| input(p, Some(m)).is_some();
        if reads(StateMsg::TYPE) || !reads(ForceMsg::TYPE) {
            break (p, t);
        }
        cur = p;
    };
    // Its `state` input, else its first.
    let Some((obs, mut src)) = input(policy, Some(StateMsg::TYPE)).or_else(|| input(policy, None))
    else {
        return None; // an open-loop source drives the actuator
    };
    // Up through the nodes before it to the plant's sensor.
    for _ in 0..MAX_NODES {
        if spec.nodes[src.0].kind.plant() == Plant::Reads {
            return Some(Chain {
                sensor: src,
                policy,
                obs,
                action,
            });
        }
        match input(src, None) {
            Some((_, up)) => src = up,
            None => return None, // fed by a source that is not a sensor
        }
    }
    None
}

/// A topological order (Kahn; of the nodes ready, the first in the file), with explicit
/// priorities overriding. Err: the nodes left in a cycle. O((nodes + edges) log nodes).
fn tie_break_order(nodes: &[NodeSpec], topics: &[TopicSpec]) -> Result<Vec<usize>, Vec<usize>> {
    let n = nodes.len();
    let mut indegree = vec![0usize; n];
    // Edges publisher → subscriber, out of and into each node, in topic then subscriber order.
    let mut downstream: Vec<Vec<usize>> = vec![Vec::new(); n];
    let mut upstream: Vec<Vec<usize>> = vec![Vec::new(); n];
    for t in topics {
        for &s in &t.subscribers {
            if nodes[s.0].priority.is_none() {
                downstream[t.publisher.0].push(s.0);
                upstream[s.0].push(t.publisher.0);
                indegree[s.0] += 1;
            }
        }
    }
    let mut placed = vec![false; n];
    let mut topo = Vec::with_capacity(n);
    let mut ready: BinaryHeap<Reverse<usize>> =
        (0..n).filter(|&i| indegree[i] == 0).map(Reverse).collect();
    while topo.len() < n {
        let Some(Reverse(next)) = ready.pop() else {
            // Every unplaced node waits on another: report a cycle through the first.
            let start = (0..n).find(|&i| !placed[i]).expect("some node is unplaced");
            let mut cycle = vec![start];
            // Each node's place in `cycle`, so that closing the loop is no scan of it.
            let mut at = vec![usize::MAX; n];
            at[start] = 0;
            let mut cur = start;
            loop {
                let prev = upstream[cur]
                    .iter()
                    .copied()
                    .find(|&from| !placed[from])
                    .expect("an unplaced node with indegree > 0 has an unplaced publisher");
                if let Some(pos) = Some(at[prev]).filter(|&p| p != usize::MAX) {
                    // Collected against the flow (subscriber ← publisher): reverse it, and
                    // start at the node that comes first in the file.
                    let mut c = cycle.split_off(pos);
                    c.reverse();
                    let first = (0..c.len()).min_by_key(|&i| c[i]).unwrap_or(0);
                    c.rotate_left(first);
                    return Err(c);
                }
                at[prev] = cycle.len();
                cycle.push(prev);
                cur = prev;
            }
        };
        placed[next] = true;
        topo.push(next);
        for &to in &downstream[next] {
            indegree[to] -= 1;
            if indegree[to] == 0 {
                ready.push(Reverse(to));
            }
        }
    }
    let mut pos = vec![0usize; n];
    for (p, &i) in topo.iter().enumerate() {
        pos[i] = p;
    }
    let mut order = topo.clone();
    order.sort_by_key(|&i| (nodes[i].priority.unwrap_or(pos[i] as i64), pos[i]));
    Ok(order)
}

/// Per topic of a node's `subscribes` or `publishes`, the types its kind takes there
/// (`None`: any).
type PortTypes = Vec<Option<&'static [MsgType]>>;

/// Check a node's topics against its kind's ports: how many it reads and publishes. Per
/// topic, the types it takes (reads, publishes).
fn check_ports(
    cx: &Ctx<'_>,
    kind: Kind,
    r: &RawNode,
    sub_names: &[Spanned<String>],
    pub_names: &[Spanned<String>],
) -> Result<(PortTypes, PortTypes), SpecError> {
    let kind_name = kind.as_str();
    match &kind.def().ports {
        Ports::Fixed { inputs, outputs } => {
            for (key, names, want) in [
                ("subscribes", sub_names, inputs),
                ("publishes", pub_names, outputs),
            ] {
                if names.len() == want.len() {
                    continue;
                }
                let a = a_kind(kind_name);
                let (at, reason) = match (names.len(), want.as_slice()) {
                    // The chapter's kinds read and publish one topic or none.
                    (0, [t]) if kind.code() == Code::BuiltIn && key == "subscribes" => (
                        r.name.span(),
                        format!("{a} node must subscribe to a {} topic", type_names(t)),
                    ),
                    (0, [_]) if kind.code() == Code::BuiltIn => {
                        (r.name.span(), format!("{a} node must publish a topic"))
                    }
                    (_, []) if kind.code() == Code::BuiltIn => {
                        let what = if key == "subscribes" {
                            "subscribes to"
                        } else {
                            "publishes"
                        };
                        (names[0].span(), format!("{a} node {what} nothing"))
                    }
                    (_, [_]) if kind.code() == Code::BuiltIn => (
                        names[1].span(),
                        format!("{a} node {key} one topic (a python node, or a kind registered with several, may have more)"),
                    ),
                    _ => {
                        let list: Vec<String> = want.iter().map(|t| type_names(t)).collect();
                        let wanted = match list.len() {
                            0 => "no topic".to_string(),
                            1 => format!("one {} topic", list[0]),
                            n => format!("{n} topics: {}", list.join(", ")),
                        };
                        (
                            names.first().map_or_else(|| r.name.span(), |n| n.span()),
                            format!(
                                "a node of kind '{kind_name}' {key} {wanted}, in that order (as registered), not {}",
                                names.len()
                            ),
                        )
                    }
                };
                return Err(cx.err(at, reason));
            }
            Ok((
                inputs.iter().map(|t| Some(*t)).collect(),
                outputs.iter().map(|t| Some(*t)).collect(),
            ))
        }
        &Ports::Open {
            max_inputs,
            min_outputs,
            max_outputs,
        } => {
            for (key, names, max) in [
                ("subscribes", sub_names, max_inputs),
                ("publishes", pub_names, max_outputs),
            ] {
                if let Some(extra) = names.get(max) {
                    let most = match max {
                        0 => "nothing".to_string(),
                        1 => "one topic".to_string(),
                        n => format!("at most {n} topics"),
                    };
                    return Err(cx.err(
                        extra.span(),
                        format!("{} node {key} {most}", a_kind(kind_name)),
                    ));
                }
            }
            if pub_names.len() < min_outputs {
                let why = if kind.code() == Code::Ros2 {
                    ": what it publishes is how ratelab hears it"
                } else {
                    ""
                };
                return Err(cx.err(
                    r.name.span(),
                    format!("{} node must publish a topic{why}", a_kind(kind_name)),
                ));
            }
            Ok((vec![None; sub_names.len()], vec![None; pub_names.len()]))
        }
    }
}

/// Message types as a file names them: `state`, or `state or position`.
fn type_names(types: &[MsgType]) -> String {
    types
        .iter()
        .map(|t| t.as_str())
        .collect::<Vec<_>>()
        .join(" or ")
}

/// The built-in kinds' parameters the file may also give as keys of the node's table, as
/// the chapter's graphs do (`max_force_n = 8`), not only in `params = { … }`.
const PARAM_KEYS: [&str; 4] = ["noise_pos_m", "noise_angle_rad", "cutoff_hz", "max_force_n"];

/// A node's parameters, checked against its kind's ([`Params`]): `params = { … }` and the
/// keys of [`PARAM_KEYS`]. A kind of numeric parameters gets every one it declares (the
/// file's value, else its default) as a float; a Python or Rust kind its table as given
/// (numbers, strings, booleans and arrays of them, under Python names).
fn node_params(cx: &Ctx<'_>, kind: Kind, r: &RawNode) -> Result<toml::Table, SpecError> {
    let a = a_kind(kind.as_str());
    // (name, value, where, given as a key of the node's table)
    let mut given: Vec<(String, toml::Value, Range<usize>, bool)> = Vec::new();
    if let Some(p) = &r.params {
        if p.get_ref().len() > MAX_PYTHON_PARAMS {
            return Err(cx.err(
                p.span(),
                ratelab_core::limits::refusal(
                    format_args!("a node has at most {MAX_PYTHON_PARAMS} params"),
                    "MAX_NODE_PARAMS",
                ),
            ));
        }
        for (k, v) in p.get_ref() {
            given.push((k.clone(), v.get_ref().clone(), v.span(), false));
        }
    }
    let keys = [
        &r.noise_pos_m,
        &r.noise_angle_rad,
        &r.cutoff_hz,
        &r.max_force_n,
    ];
    for (key, field) in PARAM_KEYS.iter().zip(keys) {
        if let Some(v) = field {
            if given.iter().any(|g| g.0 == *key) {
                return Err(cx.err(
                    v.span(),
                    format!("'{key}' is given twice: as a key and in params"),
                ));
            }
            given.push((
                key.to_string(),
                toml::Value::Float(*v.get_ref()),
                v.span(),
                true,
            ));
        }
    }
    match kind.def().params {
        Params::Numbers(defs) => {
            let mut out = toml::Table::new();
            for (k, v, span, as_key) in given {
                let Some(d) = defs.iter().find(|d| d.name == k) else {
                    let names: Vec<&str> = defs.iter().map(|d| d.name).collect();
                    let takes = match names.as_slice() {
                        [] => "takes no parameters".to_string(),
                        [one] => format!("'s parameter is {one}"),
                        [init @ .., last] => {
                            format!("'s parameters are {} and {last}", init.join(", "))
                        }
                    };
                    let sep = if takes.starts_with('\'') { "" } else { " " };
                    return Err(cx.err(span, format!("{a} node{sep}{takes}, not '{k}'")));
                };
                let x = match v {
                    toml::Value::Float(x) => x,
                    toml::Value::Integer(i) => i as f64,
                    _ => f64::NAN,
                };
                if !(x.is_finite() && x >= d.min && x <= d.max) {
                    let name = if as_key { k } else { format!("params.{k}") };
                    let unit = match d.unit {
                        "" => String::new(),
                        u => format!(" ({u})"),
                    };
                    return Err(cx.err(
                        span,
                        format!(
                            "{name} must be a number in {}..={}{unit}, got {v}",
                            d.min, d.max
                        ),
                    ));
                }
                out.insert(d.name.to_string(), toml::Value::Float(x));
            }
            for d in defs {
                out.entry(d.name).or_insert(toml::Value::Float(d.default));
            }
            Ok(out)
        }
        Params::Free => {
            let mut out = toml::Table::new();
            for (k, v, span, as_key) in given {
                if as_key {
                    return Err(cx.err(
                        span,
                        format!("'{k}' is a built-in kind's parameter, not one of {a} node (give a node's own in params = {{ … }})"),
                    ));
                }
                let scalar = |v: &toml::Value| {
                    matches!(
                        v,
                        toml::Value::Integer(_)
                            | toml::Value::Float(_)
                            | toml::Value::Boolean(_)
                            | toml::Value::String(_)
                    )
                };
                let ok = match &v {
                    toml::Value::Array(a) => a.len() <= 4096 && a.iter().all(scalar),
                    v => scalar(v),
                };
                if !valid_python_name(&k) || !ok {
                    return Err(cx.err(
                        span,
                        format!("params.{k}: a parameter is a number, a string, a boolean or an array of them, under a Python name"),
                    ));
                }
                out.insert(k, v);
            }
            Ok(out)
        }
    }
}

/// A Python node's script and class: required and allowed only on a kind whose code is
/// Python. The script is resolved against the graph file's folder.
fn python_code(cx: &Ctx<'_>, kind: Kind, r: &RawNode) -> Result<Option<PythonCode>, SpecError> {
    if kind.code() != Code::Python {
        let stray = [
            r.script.as_ref().map(|v| ("script", v.span())),
            r.class.as_ref().map(|v| ("class", v.span())),
        ];
        if let Some((key, span)) = stray.into_iter().flatten().next() {
            return Err(cx.err(
                span,
                format!(
                    "'{key}' is for python nodes, not for {} node",
                    a_kind(kind.as_str())
                ),
            ));
        }
        return Ok(None);
    }
    let script = r.script.as_ref().ok_or_else(|| {
        cx.err(
            r.name.span(),
            "a python node needs `script = \"nodes/NAME.py\"` (relative to the graph file)",
        )
    })?;
    let text = script.get_ref();
    if !text.ends_with(".py") || text.len() > 4096 || text.contains('\0') {
        return Err(cx.err(script.span(), "script must name a .py file"));
    }
    let folder = Path::new(cx.origin).parent().unwrap_or(Path::new(""));
    let joined = folder.join(text);
    let resolved = std::path::absolute(&joined).unwrap_or(joined);
    let class = match &r.class {
        Some(c) if !valid_python_name(c.get_ref()) => {
            return Err(cx.err(
                c.span(),
                format!("class '{}' is not a Python class name", c.get_ref()),
            ))
        }
        c => c.as_ref().map(|c| c.get_ref().clone()),
    };
    Ok(Some(PythonCode {
        script: resolved.to_string_lossy().into_owned(),
        class,
    }))
}
