"""A safety limiter written as a learner would, in Python: clamps every force command to
±max_force_n and passes it on to the motor (graphs/cartpole-safety-python.toml).

It reacts to each new command (a subscription callback) rather than on a timer: when the
policy is slower than this node, nothing is republished between commands, and the actuator
holds the last one (the zero-order hold).
"""

from ratelab import Force


class ForceLimiter:
    def __init__(self, node):
        self.max_force_n = float(node.get_parameter("max_force_n").value)
        self.pub = node.create_publisher(Force, "/cmd", 1)
        node.create_subscription(Force, "/action", self.on_action, 1)

    def on_action(self, msg):
        limited = min(max(msg.newtons, -self.max_force_n), self.max_force_n)
        self.pub.publish(Force(newtons=limited))
