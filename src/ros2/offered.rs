//! A graph as ROS 2 sees it when it is offered (`--ros2`): the node names, each topic with
//! its ROS 2 type, QoS and endpoint counts, and `/clock`: what `ros2 node list` and `ros2
//! topic info -v` would show, made from the same mapping the bridge declares its tokens
//! with ([`super::bridge`]), for the lab's "as ROS 2 sees it" panel.

use super::bridge::{clock_qos, qos_of, CLOCK_NODE, CLOCK_TOPIC};
use super::inspect::qos_short;
use super::ros_type_of;
use super::types::clock_type;
use ratelab_runtime::graph::GraphSpec;

/// One topic as ROS 2 sees it.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct OfferedTopic {
    /// `/obs`.
    pub name: String,
    /// `sensor_msgs/msg/JointState`.
    pub ros_type: String,
    /// `BEST_EFFORT · KEEP_LAST (1)` ([`qos_short`]).
    pub qos: String,
    /// Publishers.
    pub publishers: usize,
    /// Subscriptions.
    pub subscriptions: usize,
}

/// The graph as ROS 2 sees it.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Offered {
    /// The nodes' names, as `ros2 node list` prints them (`/sensor`), ratelab's own
    /// (`/ratelab`, which publishes `/clock`) last.
    pub nodes: Vec<String>,
    /// The topics in the graph's order, then `/clock`.
    pub topics: Vec<OfferedTopic>,
    /// What every node offers besides ([`super::node_api`]), in one line.
    pub every_node: String,
}

/// `spec` as ROS 2 sees it when offered (a graph with a type ROS 2 has no mapping for is
/// refused before it is offered: such a topic shows `?`).
pub fn offered(spec: &GraphSpec) -> Offered {
    let mut nodes: Vec<String> = spec.nodes.iter().map(|n| format!("/{}", n.name)).collect();
    nodes.push(format!("/{CLOCK_NODE}"));
    let mut topics: Vec<OfferedTopic> = spec
        .topics
        .iter()
        .enumerate()
        .map(|(i, t)| OfferedTopic {
            name: t.name.clone(),
            ros_type: t
                .msg
                .ros2()
                .map_or_else(|| "?".to_string(), |_| ros_type_of(t.msg).name.to_string()),
            qos: qos_short(&qos_of(spec, i)),
            publishers: 1,
            subscriptions: t.subscribers.len(),
        })
        .collect();
    topics.push(OfferedTopic {
        name: CLOCK_TOPIC.to_string(),
        ros_type: clock_type().name.to_string(),
        qos: qos_short(&clock_qos()),
        publishers: 1,
        subscriptions: 0,
    });
    let every_node = format!(
        "every node also: {} · {} · parameter and type services",
        super::node_api::ROSOUT,
        super::node_api::PARAMETER_EVENTS
    );
    Offered {
        nodes,
        topics,
        every_node,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_chapter_s_graph_as_ros_2_sees_it() {
        let path = concat!(env!("CARGO_MANIFEST_DIR"), "/../../graphs/cartpole.toml");
        let spec = GraphSpec::load(std::path::Path::new(path)).unwrap();
        let o = offered(&spec);
        assert_eq!(o.nodes, ["/sensor", "/policy", "/actuator", "/ratelab"]);
        let row = |t: &OfferedTopic| {
            format!(
                "{} {} {} {}/{}",
                t.name, t.ros_type, t.qos, t.publishers, t.subscriptions
            )
        };
        let rows: Vec<String> = o.topics.iter().map(row).collect();
        assert_eq!(
            rows,
            [
                "/obs sensor_msgs/msg/JointState BEST_EFFORT · KEEP_LAST (1) 1/1",
                "/action std_msgs/msg/Float64 BEST_EFFORT · KEEP_LAST (1) 1/1",
                "/clock rosgraph_msgs/msg/Clock BEST_EFFORT · KEEP_LAST (1) 1/0",
            ]
        );
        assert!(o.every_node.contains("/rosout") && o.every_node.contains("/parameter_events"));
    }
}
