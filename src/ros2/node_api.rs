//! What every ROS 2 node declares besides its own topics, declared for each node ratelab
//! offers (a real rclpy node's tokens: `../shared/fixtures/ros2-real/real-rclpy-talker.json`):
//!
//! - **`/rosout`** (`rcl_interfaces/msg/Log`, reliable, transient local, keep last 1000,
//!   lifespan 10 s):
//!   the node's log, the lines its code writes ([`ratelab_core::textlog`]: a Python node's
//!   `print` and `get_logger()`, ratelab's warnings about it), as the lab's log pane shows
//!   them. Lines written outside any node go out on the `/clock` publisher's (`ratelab`).
//!   As a real node's, its last 1000 lines are kept for subscriptions that join later.
//! - **`/parameter_events`** (`rcl_interfaces/msg/ParameterEvent`, reliable, keep last
//!   1000): the node's parameters once, as declared, when the offer starts; then `rate_hz`
//!   each time the run's rate of the node changes (the lab's keys), seen within
//!   [`RATE_POLL`].
//! - **the six parameter services** (`/<node>/list_parameters`, `get_parameters`, …), Zenoh
//!   queryables answering from [`super::parameters`]: `ros2 param list /policy` and
//!   `ros2 param get /policy rate_hz` answer. A request's reply carries rmw_zenoh's
//!   attachment with the request's sequence number and the client's GID, as rmw_zenoh_cpp's
//!   service servers reply; a request without that attachment, too long or not the
//!   service's CDR, is not answered.
//!
//! - **`~/get_type_description`** (`type_description_interfaces/srv/GetTypeDescription`,
//!   reliable, keep last 10), answering for the types of the node's endpoints
//!   ([`super::type_description`]).
//!
//! Not declared: the logger-level services.

use super::parameters::NodeParameters;
use super::rcl_interfaces::{self as rcl, Log, ParameterService};
use super::rmw_zenoh::entity::{EndpointKind, NodeEntity};
use super::rmw_zenoh::qos::{QosDurability, QosDuration, QosHistory, QosProfile, QosReliability};
use super::type_description::Descriptions;
use super::wire::{attachment, read_attachment, wall_ns, Declarer, Outlet};
use super::{zerr, Ros2Error};
use ratelab_core::limits::MAX_SERVICE_REQUEST_BYTES;
use ratelab_core::ros_types::cdr;
use ratelab_core::textlog::{Level, LogLine};
use ratelab_core::time::Nanos;
use std::sync::Arc;
use std::time::Duration;
use zenoh::Wait;

/// How often the bridge looks whether a node's rate changed, at most, to say so on
/// `/parameter_events`.
pub const RATE_POLL: Duration = Duration::from_millis(100);

/// `/rosout`.
pub const ROSOUT: &str = "/rosout";
/// `/parameter_events`.
pub const PARAMETER_EVENTS: &str = "/parameter_events";

/// rclcpp's and rclpy's QoS for `/rosout` (`rcl_logging`'s): reliable, transient local
/// (its last 1000 lines kept for late joiners, [`super::wire`]), keep last 1000, lifespan
/// 10 s.
pub(crate) fn rosout_qos() -> QosProfile {
    QosProfile {
        reliability: QosReliability::Reliable,
        durability: QosDurability::TransientLocal,
        history: QosHistory::KeepLast(1000),
        lifespan: QosDuration { sec: 10, nsec: 0 },
        ..QosProfile::default()
    }
}

/// rclcpp's `rmw_qos_profile_parameters` and `rmw_qos_profile_parameter_events`: reliable,
/// keep last 1000, volatile.
pub(crate) fn parameters_qos() -> QosProfile {
    QosProfile {
        reliability: QosReliability::Reliable,
        history: QosHistory::KeepLast(1000),
        ..QosProfile::default()
    }
}

/// One node's `/rosout`, `/parameter_events` and parameter services, declared.
pub(crate) struct NodeApi {
    /// The node's name, its logger's (`policy`).
    pub name: String,
    params: Arc<NodeParameters>,
    rosout: Outlet,
    events: Outlet,
    rosout_seq: i64,
    events_seq: i64,
    /// The rate last said on `/parameter_events`.
    said_rate: Option<f64>,
    /// The CDR of the event that declared the parameters (put when declared), until
    /// [`NodeApi::take_declared`] takes it for the bag.
    declared: Vec<u8>,
    queryables: Vec<zenoh::query::Queryable<()>>,
}

/// `/rosout`'s level of a log line.
fn level(l: Level) -> u8 {
    match l {
        Level::Info => rcl::LOG_INFO,
        Level::Warn => rcl::LOG_WARN,
        Level::Error => rcl::LOG_ERROR,
    }
}

/// `line` as node `name`'s `/rosout` message at wall time `now` (ns since the Unix epoch),
/// as rcl writes one ([`NodeApi::log`]).
fn log_message(name: &str, line: &LogLine, now: u64) -> Log {
    let (msg, file, function, at) = match &line.logged {
        Some(l) => (l.msg.clone(), l.file.clone(), l.function.clone(), l.line),
        None => (line.text.clone(), String::new(), String::new(), 0),
    };
    Log {
        stamp: rcl::Time {
            sec: i32::try_from(now / 1_000_000_000).unwrap_or(i32::MAX),
            nanosec: (now % 1_000_000_000) as u32,
        },
        level: level(line.level),
        name: name.to_string(),
        msg,
        file,
        function,
        line: at,
    }
}

/// A service's answer to a request's CDR: the reply's CDR, or why it is not answered.
type Answer = dyn Fn(&[u8]) -> Result<Vec<u8>, String> + Send + Sync;

/// Answer `query` with `answer`'s reply to its payload, on the service's own key `key` as
/// rmw_zenoh_cpp's servers reply (a query on a wildcard is answered so too), with the
/// request's sequence number and the client's GID. A request without that attachment, or
/// longer than [`MAX_SERVICE_REQUEST_BYTES`] (checked before it is copied), or that
/// `answer` refuses, is not answered (module header).
fn reply(query: &zenoh::query::Query, key: &zenoh::key_expr::KeyExpr<'static>, answer: &Answer) {
    let Some((seq, client)) = query
        .attachment()
        .and_then(|a| read_attachment(&a.to_bytes()))
    else {
        return;
    };
    let Some(payload) = query
        .payload()
        .filter(|p| p.len() <= MAX_SERVICE_REQUEST_BYTES)
    else {
        return;
    };
    if let Ok(bytes) = answer(&payload.to_bytes()) {
        let _ = query
            .reply(key.clone(), bytes)
            .attachment(attachment(seq, wall_ns(), &client).to_vec())
            .wait();
    }
}

/// Declare service `s` of `node` (its queryable, then its SS token, with `qos` and its
/// depth), answering with `answer` ([`reply`]).
fn serve(
    d: &mut Declarer<'_>,
    node: &NodeEntity,
    (s, qos, depth): (rcl::ServiceType, QosProfile, usize),
    answer: impl Fn(&[u8]) -> Result<Vec<u8>, String> + Send + Sync + 'static,
) -> Result<zenoh::query::Queryable<()>, Ros2Error> {
    let name = format!("/{}/{}", node.name, s.suffix);
    let ty = rcl::type_info(s.type_name, s.hash);
    let ss = d.endpoint(node, EndpointKind::Service, &name, ty, qos);
    let key = zenoh::key_expr::KeyExpr::try_from(d.key(&ss)?).map_err(zerr)?;
    let reply_on = key.clone();
    let q = d
        .session()
        .declare_queryable(key)
        .complete(true)
        .callback(move |query| reply(&query, &reply_on, &answer))
        .wait()
        .map_err(zerr)?;
    d.token_of(&ss, depth)?;
    Ok(q)
}

impl NodeApi {
    /// Declare `node`'s `/rosout`, `/parameter_events` and parameter services with `d`,
    /// answering from `params`; its parameters are said declared at run time `t`.
    ///
    /// # Errors
    /// [`Ros2Error::Zenoh`]: a declaration failed.
    pub fn declare(
        d: &mut Declarer<'_>,
        node: &NodeEntity,
        (params, types): (NodeParameters, Descriptions),
        t: Nanos,
    ) -> Result<NodeApi, Ros2Error> {
        let log_type = rcl::type_info("rcl_interfaces/msg/Log", rcl::LOG_HASH);
        let rosout = d.endpoint(
            node,
            EndpointKind::Publisher,
            ROSOUT,
            log_type,
            rosout_qos(),
        );
        let rosout = d.publisher(&rosout, 1000)?;
        let event_type = rcl::type_info(
            "rcl_interfaces/msg/ParameterEvent",
            rcl::PARAMETER_EVENT_HASH,
        );
        let kind = EndpointKind::Publisher;
        let events = d.endpoint(node, kind, PARAMETER_EVENTS, event_type, parameters_qos());
        let events = d.publisher(&events, 1000)?;
        let params = Arc::new(params);
        let mut queryables = Vec::new();
        for service in ParameterService::ALL {
            let p = Arc::clone(&params);
            let s = (service.service_type(), parameters_qos(), 1000);
            queryables.push(serve(d, node, s, move |req| p.answer(service, req))?);
        }
        // rclcpp's `~/get_type_description` QoS: reliable, keep last 10.
        let qos = QosProfile {
            reliability: QosReliability::Reliable,
            history: QosHistory::KeepLast(10),
            ..QosProfile::default()
        };
        let s = (rcl::GET_TYPE_DESCRIPTION, qos, 10);
        queryables.push(serve(d, node, s, move |req| types.answer(req))?);
        let mut api = NodeApi {
            name: node.name.clone(),
            said_rate: params.rate_hz(),
            params,
            rosout,
            events,
            rosout_seq: 0,
            events_seq: 0,
            declared: Vec::new(),
            queryables,
        };
        let declared = api.params.declared_event(t);
        let mut buf = Vec::new();
        api.put_event(&declared, &mut buf)
            .map_err(Ros2Error::Zenoh)?;
        api.declared = buf;
        Ok(api)
    }

    /// Put `e` on `/parameter_events`, its CDR left in `buf`.
    fn put_event(&mut self, e: &rcl::ParameterEvent, buf: &mut Vec<u8>) -> Result<(), String> {
        cdr(e, buf);
        self.events_seq += 1;
        self.events.put(self.events_seq, buf)
    }

    /// The CDR of the `/parameter_events` message that declared the node's parameters, once
    /// (empty after): for the bag, which records what was put.
    pub fn take_declared(&mut self) -> Vec<u8> {
        std::mem::take(&mut self.declared)
    }

    /// Put `line` on this node's `/rosout`, stamped with the wall clock as rcl stamps it:
    /// a logger's line as its message alone with the file, function and line that logged
    /// it ([`ratelab_core::textlog::Logged`]), any other as its text with those empty (line 0).
    /// The message's CDR is left in `buf` (for the bag).
    ///
    /// # Errors
    /// The put's, in one line.
    pub fn log(&mut self, line: &LogLine, buf: &mut Vec<u8>) -> Result<(), String> {
        cdr(&log_message(&self.name, line, wall_ns().max(0) as u64), buf);
        self.rosout_seq += 1;
        self.rosout.put(self.rosout_seq, buf)
    }

    /// Say on `/parameter_events` that the node's rate changed, if it did since last said
    /// (`t`: the run time to stamp it with). True when it did, the message's CDR left in
    /// `buf` (for the bag).
    ///
    /// # Errors
    /// The put's, in one line.
    pub fn poll_rate(&mut self, t: Nanos, buf: &mut Vec<u8>) -> Result<bool, String> {
        let now = self.params.rate_hz();
        match (now, self.said_rate) {
            (Some(hz), Some(said)) if hz.to_bits() != said.to_bits() => {
                self.said_rate = Some(hz);
                let e = self.params.rate_event(hz, t);
                self.put_event(&e, buf).map(|()| true)
            }
            _ => Ok(false),
        }
    }

    /// Withdraw the services and publishers (the tokens go with the bridge's).
    pub fn undeclare(self) {
        for q in self.queryables {
            let _ = q.undeclare().wait();
        }
        self.rosout.undeclare();
        self.events.undeclare();
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The QoS strings a real rclpy node's tokens carry for these endpoints (the fixture).
    #[test]
    fn the_qos_strings_are_a_real_node_s() {
        let enc = |q: &QosProfile| q.encode();
        assert_eq!(enc(&parameters_qos()), "::,1000:,:,:,,");
        assert_eq!(enc(&rosout_qos()), ":1:,1000:,:10,0:,,");
    }

    /// A logger's line goes out as rcl writes it (a real rclpy node's line, the fixture's
    /// `kilted-ros2cli/step2/ros2cli/topic-echo-rosout-n.txt`: `msg: published temperature
    /// 45.0`, `file: <scratch>/thermo.py`, `function: tick`, `line: 20`): its message without
    /// the level word the log pane shows, and its caller; a print's has none.
    #[test]
    fn a_loggers_line_is_its_message_and_its_caller_as_rcl_writes_it() {
        use ratelab_core::textlog::Logged;
        let logged = LogLine {
            t: Some(Nanos(200_000_000)),
            node: Some("thermo".into()),
            level: Level::Info,
            text: "info: published temperature 45.0".into(),
            logged: Some(Logged {
                msg: "published temperature 45.0".into(),
                file: "/scratch/thermo.py".into(),
                function: "tick".into(),
                line: 20,
            }),
            traceback: None,
        };
        let now = 1_795_822_167_937_444_103;
        let m = log_message("thermo", &logged, now);
        assert_eq!(
            (m.msg.as_str(), m.file.as_str(), m.function.as_str(), m.line),
            (
                "published temperature 45.0",
                "/scratch/thermo.py",
                "tick",
                20
            )
        );
        assert_eq!((m.level, m.name.as_str()), (rcl::LOG_INFO, "thermo"));
        assert_eq!((m.stamp.sec, m.stamp.nanosec), (1_795_822_167, 937_444_103));
        let printed = LogLine {
            level: Level::Warn,
            text: "heard 3".into(),
            logged: None,
            ..logged
        };
        let m = log_message("thermo", &printed, now);
        assert_eq!(
            (m.msg.as_str(), m.file.as_str(), m.function.as_str(), m.line),
            ("heard 3", "", "", 0)
        );
        assert_eq!(m.level, rcl::LOG_WARN);
    }
}
