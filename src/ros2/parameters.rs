//! A node's parameters as ROS 2 sees them, and the answers of its parameter services
//! (`ros2 param list`, `get`, `describe`, `set`): pure functions from a request's CDR to
//! the response's, so that every rule is tested without a network.
//!
//! A ratelab node's parameters are its graph file's:
//! - `rate_hz` (`DOUBLE`), its rate *now*: the lab's keys change it while the run goes on;
//! - each key of its `params` table (a nested table's keys joined by `.`, as ROS 2 names
//!   nested parameters): numbers, booleans, strings, and arrays of one of them;
//! - `use_sim_time` (`BOOL`), which every ROS 2 node has: `true`, since a ratelab node's
//!   time is the run's, the time `/clock` carries;
//! - `start_type_description_service` (`BOOL`, read-only), which every Jazzy-and-later node
//!   has (rclcpp's and rclpy's `TypeDescriptionService`): `true`, since every ratelab node
//!   answers `~/get_type_description` ([`super::node_api`]).
//!
//! They are read-only over ROS 2, but one: `rate_hz`, which the lab's keys change, can be
//! set where the run takes commands (the lab): a set is handed to the run as the key's
//! command would be ([`SetRate`]), so the run's session log has it and a virtual-clock run
//! still replays. `use_sim_time` is read-only everywhere because no set of it could take
//! effect: the run's clock is chosen when it starts ([`SIM_TIME_FIXED`], which its
//! descriptor and a refused set say). `set_parameters` answers each parameter, with the
//! reason when not.
//!
//! The services answer as rclcpp's `ParameterService` does in Jazzy and later (`rclcpp/src/
//! rclcpp/node_interfaces/node_parameters.cpp`, `parameter_service.cpp`; rclpy's agree):
//! `list_parameters` by its prefix and depth rule (the depth counted below the prefix,
//! rclcpp #2300); `get_parameters`, `get_parameter_types` and `describe_parameters` answer
//! nothing at all when one name is not declared (undeclared parameters are not allowed).
//! A reply is bounded before it is built ([`MAX_SERVICE_REPLY_BYTES`]): a request naming
//! one large parameter a hundred thousand times is refused, not answered with gigabytes.

use super::rcl_interfaces::{
    parameter_type as pt, DescribeParametersResponse, FloatingPointRange,
    GetParameterTypesResponse, GetParametersResponse, ListParametersRequest,
    ListParametersResponse, ListParametersResult, NamesRequest, Parameter, ParameterDescriptor,
    ParameterService, ParameterValue, SetParametersAtomicallyResponse, SetParametersResponse,
    SetParametersResult, SetRequest,
};
use ratelab_core::limits::{self, MAX_SERVICE_REPLY_BYTES, MAX_SERVICE_REQUEST_BYTES};
use ratelab_core::rate::{Rate, MAX_HZ};
use ratelab_core::ros_types::{cdr, from_cdr};
use ratelab_core::time::Nanos;
use ratelab_runtime::graph::spec::NodeSpec;
use std::collections::BTreeMap;

/// The separator of nested parameter names (ROS 2's).
const SEPARATOR: char = '.';

/// Why `use_sim_time` is read-only over ROS 2 (its descriptor's `additional_constraints`,
/// a refused set's reason): no set of it could take effect. A ratelab node's time is the
/// run's under either clock (`/clock` carries it), and the clock itself is the run's
/// `--clock`, kept while the run is offered to ROS 2 (the lab's `c` restarts such a run
/// under the other clock rather than switching it in place).
pub const SIM_TIME_FIXED: &str = "ratelab's clock is chosen when the run starts (--clock); it cannot change mid-run, and the nodes' time is the run's, on /clock, under either clock";

/// The parameter every ROS 2 node since Jazzy declares, read-only, for whether it offers
/// `~/get_type_description` (rclpy's `type_description_service.py`, rclcpp's
/// `node_type_descriptions.cpp`); real ros2cli's `param list` shows it on every node
/// (kilted-ros2cli/step2/ros2cli/param-list.txt).
const TYPE_DESCRIPTION_SERVICE: &str = "start_type_description_service";

/// How deep a `params` table may nest before its deeper keys are left out of ROS 2's view.
const MAX_NESTING: usize = 16;

/// Set a node's rate, Hz, as the lab's keys do (a command to the run); `Err`: why not.
pub type SetRate = std::sync::Arc<dyn Fn(f64) -> Result<(), String> + Send + Sync>;

/// One parameter's value: fixed (the graph file's), or the node's rate as it is now.
#[derive(Clone, Debug)]
enum Value {
    Fixed(ParameterValue),
    Rate(Rate),
}

impl Value {
    fn now(&self) -> ParameterValue {
        match self {
            Value::Fixed(v) => v.clone(),
            Value::Rate(r) => double(r.hz()),
        }
    }
}

/// A node's parameters (module header), by name.
#[derive(Clone)]
pub struct NodeParameters {
    /// The node's fully qualified name (`/policy`).
    pub node: String,
    params: BTreeMap<String, Value>,
    /// How its rate is set (`None`: the run takes no commands).
    set_rate: Option<SetRate>,
    /// What the node's `params` held that ROS 2 has no type for (`key: why`), one each.
    pub left_out: Vec<String>,
}

impl std::fmt::Debug for NodeParameters {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("NodeParameters")
            .field("node", &self.node)
            .field("params", &self.params.keys().collect::<Vec<_>>())
            .field("rate_settable", &self.set_rate.is_some())
            .finish()
    }
}

fn double(x: f64) -> ParameterValue {
    ParameterValue {
        type_: pt::DOUBLE,
        double_value: x,
        ..ParameterValue::default()
    }
}

fn boolean(b: bool) -> ParameterValue {
    ParameterValue {
        type_: pt::BOOL,
        bool_value: b,
        ..ParameterValue::default()
    }
}

/// At most the bytes `v` takes in CDR (every field, its padding and lengths).
fn value_bytes(v: &ParameterValue) -> usize {
    let strings = |s: &[String]| s.iter().map(|x| x.len() + 8).sum::<usize>();
    64 + v.string_value.len()
        + v.byte_array_value.len()
        + v.bool_array_value.len()
        + 8 * (v.integer_array_value.len() + v.double_array_value.len())
        + strings(&v.string_array_value)
}

/// A TOML value as a ROS 2 parameter value; `Err` says why it has none (a mixed or nested
/// array, an empty one, whose type ROS 2 could not tell).
fn from_toml(v: &toml::Value) -> Result<ParameterValue, &'static str> {
    use toml::Value as T;
    let mut p = ParameterValue::default();
    match v {
        T::Boolean(b) => return Ok(boolean(*b)),
        T::Integer(i) => (p.type_, p.integer_value) = (pt::INTEGER, *i),
        T::Float(x) => return Ok(double(*x)),
        T::String(s) => (p.type_, p.string_value) = (pt::STRING, s.clone()),
        T::Datetime(d) => (p.type_, p.string_value) = (pt::STRING, d.to_string()),
        T::Array(a) if a.iter().all(T::is_bool) => {
            p.type_ = pt::BOOL_ARRAY;
            p.bool_array_value = a.iter().filter_map(T::as_bool).collect();
        }
        T::Array(a) if a.iter().all(T::is_integer) => {
            p.type_ = pt::INTEGER_ARRAY;
            p.integer_array_value = a.iter().filter_map(T::as_integer).collect();
        }
        // Numbers, some written without a point: all doubles, as a YAML loader would.
        T::Array(a) if a.iter().all(|x| x.is_float() || x.is_integer()) => {
            p.type_ = pt::DOUBLE_ARRAY;
            p.double_array_value = a
                .iter()
                .filter_map(|x| x.as_float().or(x.as_integer().map(|i| i as f64)))
                .collect();
        }
        T::Array(a) if a.iter().all(T::is_str) => {
            p.type_ = pt::STRING_ARRAY;
            p.string_array_value = a
                .iter()
                .filter_map(|s| s.as_str().map(String::from))
                .collect();
        }
        T::Array(_) => return Err("an array of mixed or nested values has no ROS 2 type"),
        T::Table(_) => return Err("a table is a prefix, not a value"),
    }
    if matches!(v, T::Array(a) if a.is_empty()) {
        return Err("an empty array has no ROS 2 type");
    }
    Ok(p)
}

impl NodeParameters {
    /// The parameters of node `spec`, whose rate is `rate` (shared with the running
    /// graph: read when asked) and set by `set_rate` (`None`: read-only).
    pub fn of(spec: &NodeSpec, rate: Option<&Rate>, set_rate: Option<SetRate>) -> NodeParameters {
        let mut p = NodeParameters {
            node: format!("/{}", spec.name),
            params: BTreeMap::new(),
            set_rate,
            left_out: Vec::new(),
        };
        p.add_table("", &spec.params, 0);
        let rate = rate
            .cloned()
            .map_or(Value::Fixed(double(spec.rate_hz)), Value::Rate);
        for (name, value) in [
            ("rate_hz", rate),
            ("use_sim_time", Value::Fixed(boolean(true))),
            (TYPE_DESCRIPTION_SERVICE, Value::Fixed(boolean(true))),
        ] {
            if p.params.insert(name.into(), value).is_some() {
                p.left_out.push(format!(
                    "{name}: a params key of that name is shadowed by the node's own {name}"
                ));
            }
        }
        p
    }

    /// The parameters of a node with no graph file behind it (ratelab's `/clock`
    /// publisher): `use_sim_time` alone, `false` (it makes the time).
    pub fn clock_node(name: &str) -> NodeParameters {
        let mut params = BTreeMap::new();
        params.insert("use_sim_time".into(), Value::Fixed(boolean(false)));
        params.insert(TYPE_DESCRIPTION_SERVICE.into(), Value::Fixed(boolean(true)));
        NodeParameters {
            node: format!("/{name}"),
            params,
            set_rate: None,
            left_out: Vec::new(),
        }
    }

    fn add_table(&mut self, prefix: &str, table: &toml::Table, depth: usize) {
        for (k, v) in table {
            let name = format!("{prefix}{k}");
            match v {
                toml::Value::Table(t) if depth < MAX_NESTING => {
                    self.add_table(&format!("{name}{SEPARATOR}"), t, depth + 1);
                }
                toml::Value::Table(_) => self
                    .left_out
                    .push(format!("{name}: nested more than {MAX_NESTING} deep")),
                v => match from_toml(v) {
                    Ok(_) if self.params.contains_key(&name) => self
                        .left_out
                        .push(format!("{name}: given twice (a dotted key and a table)")),
                    Ok(p) => {
                        self.params.insert(name, Value::Fixed(p));
                    }
                    Err(why) => self.left_out.push(format!("{name}: {why}")),
                },
            }
        }
    }

    /// Every parameter and its value now, by name.
    pub fn all(&self) -> Vec<Parameter> {
        self.params
            .iter()
            .map(|(name, v)| Parameter {
                name: name.clone(),
                value: v.now(),
            })
            .collect()
    }

    /// The node's rate now, Hz, when it has one.
    pub fn rate_hz(&self) -> Option<f64> {
        self.params.get("rate_hz").map(|v| v.now().double_value)
    }

    fn descriptor(&self, name: &str, v: &Value) -> ParameterDescriptor {
        let value = v.now();
        let (description, range) = match name {
            "rate_hz" => (
                "the node's rate, Hz (the graph file's rate_hz; the lab's keys change it)",
                vec![FloatingPointRange {
                    from_value: 0.0,
                    to_value: MAX_HZ,
                    step: 0.0,
                }],
            ),
            "use_sim_time" if self.makes_time() => (
                "false: this node publishes /clock, the run's time, rather than following it",
                vec![],
            ),
            "use_sim_time" => ("the node's time is the run's, which /clock carries", vec![]),
            // rclpy's descriptor, word for word.
            TYPE_DESCRIPTION_SERVICE => (
                "If enabled, start the ~/get_type_description service.",
                vec![],
            ),
            _ => ("the graph file's params", vec![]),
        };
        let settable = name == "rate_hz" && self.set_rate.is_some();
        let constraints = if settable {
            "set as the lab's rate keys set it: a command to the run, in its session log".into()
        } else if name == TYPE_DESCRIPTION_SERVICE {
            String::new()
        } else if name == "use_sim_time" {
            format!("read-only: {SIM_TIME_FIXED}")
        } else {
            "read-only over ROS 2: set it in the graph file (rate_hz: in the lab)".into()
        };
        ParameterDescriptor {
            name: name.to_string(),
            type_: value.type_,
            description: description.into(),
            additional_constraints: constraints,
            read_only: !settable,
            dynamic_typing: false,
            floating_point_range: range,
            integer_range: vec![],
        }
    }

    /// `list_parameters` (rclcpp's rule since #2300): with no prefixes, every name with fewer
    /// than `depth` separators (all, for depth 0); else every name equal to a prefix, or under
    /// one (`prefix.`) with fewer than `depth` separators in what follows `prefix.`. `prefixes` lists each listed
    /// name's part before its last separator, once.
    pub fn list(&self, req: &ListParametersRequest) -> ListParametersResult {
        // Separators below the name's prefix (the whole name: below the root).
        let within = |s: &str| req.depth == 0 || (s.matches(SEPARATOR).count() as u64) < req.depth;
        let mut out = ListParametersResult::default();
        for name in self.params.keys() {
            let all = req.prefixes.is_empty() && within(name);
            let under = req.prefixes.iter().any(|p| {
                name == p
                    || name
                        .strip_prefix(p.as_str())
                        .and_then(|rest| rest.strip_prefix(SEPARATOR))
                        .is_some_and(within)
            });
            if all || under {
                out.names.push(name.clone());
                if let Some((prefix, _)) = name.rsplit_once(SEPARATOR) {
                    if !out.prefixes.iter().any(|p| p == prefix) {
                        out.prefixes.push(prefix.to_string());
                    }
                }
            }
        }
        out
    }

    /// Refuse a request naming `names` whose reply could pass [`MAX_SERVICE_REPLY_BYTES`]
    /// (each name's value, or its descriptor, at most: its value's bytes and 512 more).
    fn check_reply(&self, names: &[String]) -> Result<(), String> {
        let mut bytes = 0usize;
        for n in names {
            let value = self.params.get(n).map_or(0, |v| value_bytes(&v.now()));
            bytes = bytes.saturating_add(value + n.len() + 512);
            if bytes > MAX_SERVICE_REPLY_BYTES {
                return Err(limits::refusal(
                    format_args!(
                        "a reply to {} names would pass {MAX_SERVICE_REPLY_BYTES} bytes",
                        names.len()
                    ),
                    "MAX_SERVICE_REPLY_BYTES",
                ));
            }
        }
        Ok(())
    }

    /// The rate parameter `p` sets, if it can be set: checked, not yet set.
    fn check_set(&self, p: &Parameter) -> Result<f64, String> {
        if p.name != "rate_hz" || self.set_rate.is_none() {
            return Err(self.refusal(&p.name));
        }
        // Its type is fixed (dynamic_typing false): as rclcpp, an INTEGER is refused.
        if p.value.type_ != pt::DOUBLE {
            return Err(format!(
                "Wrong parameter type, parameter {{rate_hz}} is of type {{double}}, setting it to a value of type {} is not allowed.",
                p.value.type_
            ));
        }
        let hz = p.value.double_value;
        ratelab_core::rate::period_for_hz(hz)
            .map(|_| hz)
            .map_err(|e| format!("{}: rate_hz: {e}", self.node))
    }

    /// Set the rate checked by [`NodeParameters::check_set`]: its result.
    fn apply_set(&self, hz: f64) -> SetParametersResult {
        let done = self
            .set_rate
            .as_ref()
            .map_or(Err("read-only".to_string()), |set| set(hz));
        match done {
            Ok(()) => SetParametersResult {
                successful: true,
                reason: String::new(),
            },
            Err(e) => SetParametersResult {
                successful: false,
                reason: format!("{}: rate_hz: {e}", self.node),
            },
        }
    }

    /// Set parameter `p`, if it can be: its result.
    fn set(&self, p: &Parameter) -> SetParametersResult {
        match self.check_set(p) {
            Ok(hz) => self.apply_set(hz),
            Err(reason) => SetParametersResult {
                successful: false,
                reason,
            },
        }
    }

    /// Whether this node makes the run's time (ratelab's `/clock` publisher, whose
    /// `use_sim_time` is `false`) rather than following it.
    fn makes_time(&self) -> bool {
        matches!(self.params.get("use_sim_time"), Some(Value::Fixed(v)) if !v.bool_value)
    }

    /// The reason `name` cannot be set over ROS 2.
    fn refusal(&self, name: &str) -> String {
        match name {
            "rate_hz" => format!(
                "{}: rate_hz is read-only in a run that takes no commands (in the lab, setting it changes the node's rate as its keys do)",
                self.node
            ),
            "use_sim_time" if self.params.contains_key(name) => format!(
                "{}: parameter 'use_sim_time' is read-only: {SIM_TIME_FIXED}",
                self.node
            ),
            // rclcpp's words for any read-only parameter (param-set-ro.txt).
            TYPE_DESCRIPTION_SERVICE if self.params.contains_key(name) => {
                format!("Trying to set a read-only parameter: {name}.")
            }
            _ if self.params.contains_key(name) => format!(
                "{}: parameter '{name}' is read-only (it is the graph file's)",
                self.node
            ),
            _ => format!("{}: parameter '{name}' is not declared", self.node),
        }
    }

    /// The answer of service `service` to `request` (CDR with its header): the response's
    /// CDR with its header.
    ///
    /// # Errors
    /// One line when the request is too long ([`MAX_SERVICE_REQUEST_BYTES`]) or not that service's
    /// CDR: it is then answered with nothing (a ROS 2 client times out, as it would with a
    /// server that could not read it).
    pub fn answer(&self, service: ParameterService, request: &[u8]) -> Result<Vec<u8>, String> {
        if request.len() > MAX_SERVICE_REQUEST_BYTES {
            return Err(limits::refusal(
                format_args!(
                    "a request of {} bytes, at most {MAX_SERVICE_REQUEST_BYTES}",
                    request.len()
                ),
                "MAX_SERVICE_REQUEST_BYTES",
            ));
        }
        let mut out = Vec::new();
        let names = |r: &[u8]| {
            let names = from_cdr::<NamesRequest>(r, MAX_SERVICE_REQUEST_BYTES)?.names;
            self.check_reply(&names)?;
            Ok::<_, String>(names)
        };
        match service {
            ParameterService::List => {
                let req = from_cdr::<ListParametersRequest>(request, MAX_SERVICE_REQUEST_BYTES)?;
                let result = self.list(&req);
                cdr(&ListParametersResponse { result }, &mut out);
            }
            ParameterService::Get => {
                let names = names(request)?;
                // rclcpp: one name not declared, no values at all.
                let values = names
                    .iter()
                    .map(|n| self.params.get(n).map(Value::now))
                    .collect::<Option<Vec<_>>>()
                    .unwrap_or_default();
                cdr(&GetParametersResponse { values }, &mut out);
            }
            ParameterService::GetTypes => {
                // rclcpp and rclpy: one name not declared, no types at all.
                let types = names(request)?
                    .iter()
                    .map(|n| self.params.get(n).map(|v| v.now().type_))
                    .collect::<Option<Vec<_>>>()
                    .unwrap_or_default();
                cdr(&GetParameterTypesResponse { types }, &mut out);
            }
            ParameterService::Describe => {
                let descriptors = names(request)?
                    .iter()
                    .map(|n| self.params.get(n).map(|v| self.descriptor(n, v)))
                    .collect::<Option<Vec<_>>>()
                    .unwrap_or_default();
                cdr(&DescribeParametersResponse { descriptors }, &mut out);
            }
            ParameterService::Set => {
                let req = from_cdr::<SetRequest>(request, MAX_SERVICE_REQUEST_BYTES)?;
                let results = req.parameters.iter().map(|p| self.set(p)).collect();
                cdr(&SetParametersResponse { results }, &mut out);
            }
            ParameterService::SetAtomically => {
                let req = from_cdr::<SetRequest>(request, MAX_SERVICE_REQUEST_BYTES)?;
                // All or none: every one checked before any is set.
                let checked: Result<Vec<f64>, String> =
                    req.parameters.iter().map(|p| self.check_set(p)).collect();
                let result = match checked {
                    Err(reason) => SetParametersResult {
                        successful: false,
                        reason,
                    },
                    Ok(rates) if rates.is_empty() => SetParametersResult {
                        successful: false,
                        reason: "no parameters given".into(),
                    },
                    Ok(rates) => rates
                        .iter()
                        .map(|hz| self.apply_set(*hz))
                        .find(|r| !r.successful)
                        .unwrap_or(SetParametersResult {
                            successful: true,
                            reason: String::new(),
                        }),
                };
                cdr(&SetParametersAtomicallyResponse { result }, &mut out);
            }
        }
        Ok(out)
    }

    /// The event a node publishes on `/parameter_events` when its parameters are declared:
    /// all of them, new, at run time `t`.
    pub fn declared_event(&self, t: Nanos) -> super::rcl_interfaces::ParameterEvent {
        super::rcl_interfaces::ParameterEvent {
            stamp: super::rcl_interfaces::Time::of(t),
            node: self.node.clone(),
            new_parameters: self.all(),
            ..Default::default()
        }
    }

    /// The event saying `rate_hz` is now `hz`, at run time `t`.
    pub fn rate_event(&self, hz: f64, t: Nanos) -> super::rcl_interfaces::ParameterEvent {
        super::rcl_interfaces::ParameterEvent {
            stamp: super::rcl_interfaces::Time::of(t),
            node: self.node.clone(),
            changed_parameters: vec![Parameter {
                name: "rate_hz".into(),
                value: double(hz),
            }],
            ..Default::default()
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use ratelab_runtime::graph::GraphSpec;

    fn policy_with(params: &str) -> NodeParameters {
        let text = std::fs::read_to_string(concat!(
            env!("CARGO_MANIFEST_DIR"),
            "/../../graphs/cartpole.toml"
        ))
        .unwrap();
        let spec = GraphSpec::parse(&text, "g.toml").unwrap();
        let mut node = spec.node(spec.node_id("policy").unwrap()).clone();
        node.params = toml::from_str(params).unwrap();
        NodeParameters::of(&node, Some(&Rate::new(50.0).unwrap()), None)
    }

    fn decode<'de, T: serde::Deserialize<'de>>(b: &'de [u8]) -> T {
        from_cdr(b, usize::MAX).unwrap()
    }

    fn ask<T: serde::Serialize>(p: &NodeParameters, s: ParameterService, req: &T) -> Vec<u8> {
        let mut b = Vec::new();
        cdr(req, &mut b);
        p.answer(s, &b).unwrap()
    }

    #[test]
    fn the_graph_files_parameters_with_their_ros_2_types() {
        let p = policy_with(
            "gain = 2.5\nsteps = 3\nname = \"lqr\"\non = true\nk = [1, 2.5]\nids = [1, 2]\n[gains]\nkp = 1.0\n[gains.inner]\nkd = 0.5\n",
        );
        let all: BTreeMap<String, ParameterValue> =
            p.all().into_iter().map(|q| (q.name, q.value)).collect();
        let ty = |n: &str| all[n].type_;
        assert_eq!(ty("gain"), pt::DOUBLE);
        assert_eq!(ty("steps"), pt::INTEGER);
        assert_eq!(ty("name"), pt::STRING);
        assert_eq!(ty("on"), pt::BOOL);
        assert_eq!(all["k"].double_array_value, vec![1.0, 2.5]);
        assert_eq!(all["ids"].integer_array_value, vec![1, 2]);
        assert_eq!(all["gains.inner.kd"].double_value, 0.5);
        assert_eq!(all["rate_hz"].double_value, 50.0);
        assert!(all["use_sim_time"].bool_value);
        assert!(p.left_out.is_empty());
        let odd =
            policy_with("mixed = [1, \"a\"]\nnone = []\nrate_hz = 3\n\"x.y\" = 1\n[x]\ny = 2\n");
        assert_eq!(odd.left_out.len(), 4, "{:?}", odd.left_out);
        let all: BTreeMap<String, ParameterValue> =
            odd.all().into_iter().map(|q| (q.name, q.value)).collect();
        assert_eq!(all["rate_hz"].double_value, 50.0, "the node's own rate");
    }

    #[test]
    fn rate_hz_is_the_rate_now() {
        let rate = Rate::new(50.0).unwrap();
        let spec = GraphSpec::chapter();
        let p = NodeParameters::of(&spec.nodes[1], Some(&rate), None);
        rate.set_hz(20.0).unwrap();
        let got: GetParametersResponse = decode(&ask(
            &p,
            ParameterService::Get,
            &NamesRequest {
                names: vec!["rate_hz".into()],
            },
        ));
        assert_eq!(got.values, vec![double(20.0)]);
    }

    /// rclcpp's `list_parameters` rule, case by case.
    #[test]
    fn list_follows_rclcpp_s_prefix_and_depth_rule() {
        let p = policy_with("a = 1\n[b]\nc = 1\n[b.d]\ne = 1\n");
        let list = |prefixes: &[&str], depth: u64| {
            p.list(&ListParametersRequest {
                prefixes: prefixes.iter().map(|s| s.to_string()).collect(),
                depth,
            })
        };
        let all = list(&[], 0);
        assert_eq!(
            all.names,
            [
                "a",
                "b.c",
                "b.d.e",
                "rate_hz",
                "start_type_description_service",
                "use_sim_time"
            ]
        );
        assert_eq!(all.prefixes, ["b", "b.d"]);
        assert_eq!(
            list(&[], 1).names,
            [
                "a",
                "rate_hz",
                "start_type_description_service",
                "use_sim_time"
            ]
        );
        assert_eq!(
            list(&[], 2).names,
            [
                "a",
                "b.c",
                "rate_hz",
                "start_type_description_service",
                "use_sim_time"
            ]
        );
        assert_eq!(list(&["b"], 0).names, ["b.c", "b.d.e"]);
        // The depth below the prefix (rclcpp #2300, Jazzy and later).
        assert_eq!(list(&["b"], 1).names, ["b.c"]);
        assert_eq!(list(&["b"], 2).names, ["b.c", "b.d.e"]);
        assert_eq!(list(&["b.d"], 1).names, ["b.d.e"]);
        assert_eq!(list(&["a"], 1).names, ["a"]);
        assert!(list(&["x"], 0).names.is_empty());
    }

    #[test]
    fn get_types_and_describe_answer_nothing_for_an_undeclared_name() {
        let p = policy_with("");
        let names = |n: &[&str]| NamesRequest {
            names: n.iter().map(|s| s.to_string()).collect(),
        };
        let got: GetParametersResponse = decode(&ask(
            &p,
            ParameterService::Get,
            &names(&["rate_hz", "nope"]),
        ));
        assert!(got.values.is_empty());
        let types: GetParameterTypesResponse = decode(&ask(
            &p,
            ParameterService::GetTypes,
            &names(&["rate_hz", "nope"]),
        ));
        assert!(types.types.is_empty());
        let types: GetParameterTypesResponse = decode(&ask(
            &p,
            ParameterService::GetTypes,
            &names(&["rate_hz", "use_sim_time"]),
        ));
        assert_eq!(types.types, vec![pt::DOUBLE, pt::BOOL]);
        let d: DescribeParametersResponse =
            decode(&ask(&p, ParameterService::Describe, &names(&["rate_hz"])));
        assert!(d.descriptors[0].read_only);
        assert_eq!(d.descriptors[0].floating_point_range[0].to_value, MAX_HZ);
        let d: DescribeParametersResponse =
            decode(&ask(&p, ParameterService::Describe, &names(&["nope"])));
        assert!(d.descriptors.is_empty());
    }

    #[test]
    fn every_set_is_refused_with_its_reason() {
        let p = policy_with("gain = 1.0\n");
        let set = |n: &str| SetRequest {
            parameters: vec![Parameter {
                name: n.into(),
                value: double(1.0),
            }],
        };
        let r: SetParametersResponse = decode(&ask(&p, ParameterService::Set, &set("rate_hz")));
        assert!(!r.results[0].successful);
        assert!(
            r.results[0].reason.contains("takes no commands"),
            "{:?}",
            r.results
        );
        let r: SetParametersResponse = decode(&ask(&p, ParameterService::Set, &set("gain")));
        assert!(r.results[0].reason.contains("read-only"));
        let r: SetParametersAtomicallyResponse =
            decode(&ask(&p, ParameterService::SetAtomically, &set("nope")));
        assert!(r.result.reason.contains("not declared"));
    }

    /// `use_sim_time` cannot take effect when set (the run's clock is its `--clock`): it is
    /// read-only on every node, and its descriptor and a refused set say why.
    #[test]
    fn use_sim_time_is_read_only_and_says_why() {
        let flag = |b: bool| SetRequest {
            parameters: vec![Parameter {
                name: "use_sim_time".into(),
                value: boolean(b),
            }],
        };
        let describe = NamesRequest {
            names: vec!["use_sim_time".into()],
        };
        // A graph node (one whose run takes commands too) and ratelab's /clock publisher.
        let set: SetRate = std::sync::Arc::new(|_hz: f64| -> Result<(), String> { Ok(()) });
        let spec = GraphSpec::chapter();
        let nodes = [
            (policy_with(""), true),
            (NodeParameters::of(&spec.nodes[1], None, Some(set)), true),
            (NodeParameters::clock_node("ratelab"), false),
        ];
        for (p, value) in nodes {
            for b in [false, true] {
                let r: SetParametersResponse = decode(&ask(&p, ParameterService::Set, &flag(b)));
                assert!(!r.results[0].successful, "{:?}", r.results);
                assert_eq!(
                    r.results[0].reason,
                    format!(
                        "{}: parameter 'use_sim_time' is read-only: {SIM_TIME_FIXED}",
                        p.node
                    )
                );
                assert!(!r.results[0].reason.contains('\n'));
            }
            let d: DescribeParametersResponse =
                decode(&ask(&p, ParameterService::Describe, &describe));
            let d = &d.descriptors[0];
            assert!(d.read_only, "{}", p.node);
            assert_eq!(d.type_, pt::BOOL);
            assert_eq!(
                d.additional_constraints,
                "read-only: ratelab's clock is chosen when the run starts (--clock); it cannot change mid-run, and the nodes' time is the run's, on /clock, under either clock"
            );
            assert_eq!(
                d.description.starts_with("false:"),
                !value,
                "{}",
                d.description
            );
            let got: GetParametersResponse = decode(&ask(&p, ParameterService::Get, &describe));
            assert_eq!(got.values, vec![boolean(value)]);
        }
    }

    /// Where the run takes commands, rate_hz is set through them, checked first; every
    /// other parameter stays read-only, and an atomic set of both sets neither.
    #[test]
    fn rate_hz_is_set_through_the_run_s_commands() {
        let asked = std::sync::Arc::new(std::sync::Mutex::new(Vec::new()));
        let log = asked.clone();
        let spec = GraphSpec::chapter();
        let set: SetRate = std::sync::Arc::new(move |hz| {
            log.lock().unwrap().push(hz);
            Ok(())
        });
        let p = NodeParameters::of(&spec.nodes[1], None, Some(set));
        let param = |name: &str, v: ParameterValue| Parameter {
            name: name.into(),
            value: v,
        };
        let int = |i: i64| ParameterValue {
            type_: pt::INTEGER,
            integer_value: i,
            ..ParameterValue::default()
        };
        let req = SetRequest {
            parameters: vec![
                param("rate_hz", double(20.0)),
                param("rate_hz", int(25)),
                param("rate_hz", double(-1.0)),
                param("rate_hz", boolean(true)),
                param("use_sim_time", boolean(false)),
            ],
        };
        let r: SetParametersResponse = decode(&ask(&p, ParameterService::Set, &req));
        let ok: Vec<bool> = r.results.iter().map(|r| r.successful).collect();
        assert_eq!(ok, [true, false, false, false, false], "{:?}", r.results);
        // A DOUBLE's type is fixed: an INTEGER is refused, as rclcpp refuses it.
        let reason = |i: usize| r.results[i].reason.as_str();
        assert!(
            reason(1).starts_with("Wrong parameter type"),
            "{:?}",
            r.results
        );
        assert!(reason(2).contains("rate must be"), "{:?}", r.results);
        assert!(
            reason(3).starts_with("Wrong parameter type"),
            "{:?}",
            r.results
        );
        assert_eq!(*asked.lock().unwrap(), [20.0]);
        let both = SetRequest {
            parameters: vec![
                param("rate_hz", double(30.0)),
                param("use_sim_time", boolean(true)),
            ],
        };
        let r: SetParametersAtomicallyResponse =
            decode(&ask(&p, ParameterService::SetAtomically, &both));
        assert!(!r.result.successful && r.result.reason.contains("'use_sim_time' is read-only"));
        // A good rate, then a bad one: neither set.
        let bad_second = SetRequest {
            parameters: vec![
                param("rate_hz", double(30.0)),
                param("rate_hz", double(-1.0)),
            ],
        };
        let r: SetParametersAtomicallyResponse =
            decode(&ask(&p, ParameterService::SetAtomically, &bad_second));
        assert!(!r.result.successful && r.result.reason.contains("rate must be"));
        assert_eq!(asked.lock().unwrap().len(), 1, "nothing set");
    }

    #[test]
    fn a_bad_request_is_one_line_and_no_answer() {
        let p = policy_with("");
        for bad in [
            &b""[..],
            &[0, 1, 0, 0, 0xff, 0xff, 0xff, 0xff][..],
            &[0, 0, 0, 0, 1, 0, 0, 0][..],
        ] {
            for s in ParameterService::ALL {
                let e = p.answer(s, bad).unwrap_err();
                assert!(!e.contains('\n'), "{e}");
            }
        }
        // One large parameter named over and over: refused before the reply is built.
        let big = policy_with(&format!("s = \"{}\"\n", "x".repeat(100_000)));
        let mut req = Vec::new();
        cdr(
            &NamesRequest {
                names: vec!["s".into(); 1000],
            },
            &mut req,
        );
        let e = big.answer(ParameterService::Get, &req).unwrap_err();
        assert!(
            e.ends_with("(ratelab::limits::MAX_SERVICE_REPLY_BYTES)"),
            "{e}"
        );
        let long = vec![0u8; MAX_SERVICE_REQUEST_BYTES + 1];
        let e = p.answer(ParameterService::List, &long).unwrap_err();
        assert!(
            e.ends_with("(ratelab::limits::MAX_SERVICE_REQUEST_BYTES)"),
            "{e}"
        );
    }
}
