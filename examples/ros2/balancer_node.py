"""The chapter's scripted balancer as an rclpy node: the external `policy` of
graphs/cartpole-external.toml.

On a ROS 2 machine (Jazzy or later) with rmw_zenoh:

    export RMW_IMPLEMENTATION=rmw_zenoh_cpp
    ros2 run rmw_zenoh_cpp rmw_zenohd &            # or let ratelab run its own router
    python3 examples/ros2/balancer_node.py &
    ratelab run --graph graphs/cartpole-external.toml --ros2 --clock virtual

It keeps the newest /obs and follows ratelab's /clock: at each /clock that reaches its next
tick (every 1/RATE_HZ from 0) it publishes one /action, the contract of an external node under
the virtual clock (one message per output per tick; docs/ros2.md). Its rate must be the graph
node's rate_hz. It ticks from a /clock subscription rather than create_timer: a timer made
under sim time is first due one period after its creation, so it would skip the tick at 0
(which ratelab would wait for and count as missed), and it may run before an /obs callback
that arrived first. It starts again from 0 when /clock jumps back (each run starts at 0).
Run once under real rclpy and rmw_zenoh_cpp 0.6.7 (Kilted), it gave metrics.json and
trace.csv byte-identical to the built-in policy's under the virtual clock on seeds 0-2
(../shared/fixtures/ros2-real/external-policy-runs.json).

Untested here: the machines that build ratelab have no ROS 2. The same node written with
Zenoh's Python API and rosbags (examples/ros2/zenoh_policy.py) is what the tests run.
"""


import rclpy
from rclpy.node import Node
from rclpy.parameter import Parameter
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import JointState
from std_msgs.msg import Float64

try:  # what `spin` raises when the context is shut down under it (Kilted: at Ctrl-C)
    from rclpy.executors import ExternalShutdownException
except ImportError:  # an older rclpy, which does not have it: Ctrl-C alone ends `spin`

    class ExternalShutdownException(Exception):
        """Stands in for rclpy's, which this rclpy never raises."""


RATE_HZ = 50.0  # the graph file's rate_hz for `policy`
GEAR_N = 10.0  # the cartpole's motor: newtons per unit of action


class Balancer(Node):
    def __init__(self):
        super().__init__(
            "policy", parameter_overrides=[Parameter("use_sim_time", value=True)]
        )
        self.obs = None
        self.period_ns = round(1e9 / RATE_HZ)
        self.next_ns = 0
        self.last_ns = 0
        self.create_subscription(JointState, "/obs", self.on_obs, 1)
        self.create_subscription(Clock, "/clock", self.on_clock, 10)
        self.pub = self.create_publisher(Float64, "/action", 1)

    def on_obs(self, msg):
        self.obs = msg

    def on_clock(self, msg):
        t = msg.clock.sec * 1_000_000_000 + msg.clock.nanosec
        if t < self.last_ns:
            self.next_ns = t  # a new run: time jumped back
        self.last_ns = t
        if t < self.next_ns:
            return
        while self.next_ns <= t:
            self.next_ns += self.period_ns
        if self.obs is None:
            return
        x, theta = self.obs.position
        x_dot, theta_dot = self.obs.velocity
        u = 10.0 * theta + 2.0 * theta_dot + 0.4 * x + 0.8 * x_dot
        u = max(-1.0, min(1.0, u))
        self.pub.publish(Float64(data=u * GEAR_N))


def main():
    rclpy.init()
    node = Balancer()
    try:
        rclpy.spin(node)
    except (KeyboardInterrupt, ExternalShutdownException):
        # Ctrl-C: Kilted's rclpy shuts the context down on SIGINT and `spin` raises
        # ExternalShutdownException (older ones raise KeyboardInterrupt); either ends here
        # quietly, as ROS 2's demos end.
        pass
    finally:
        node.destroy_node()
        rclpy.try_shutdown()


if __name__ == "__main__":
    main()
