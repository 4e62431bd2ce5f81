"""Exercise ex6: your safety limiter, a Python node in the safety graph's place
(safety: /action -> /cmd; see exercises/ex6_own_node.toml and docs/python.md).

`ratelab exercise ex6` runs this node with params = { max_force_n = C } for every clamp C of
the exercise, beside the built-in safety node, and compares them. As shipped it passes every
command through unchanged: make it clamp each force to [-max_force_n, +max_force_n].
"""

from ratelab import Force


class MyLimiter:
    def __init__(self, node):
        self.max_force_n = float(node.get_parameter("max_force_n").value)
        self.pub = node.create_publisher(Force, "/cmd", 1)
        node.create_subscription(Force, "/action", self.on_action, 1)

    def on_action(self, msg):
        # TODO: clamp msg.newtons to [-self.max_force_n, +self.max_force_n] before passing it on.
        self.pub.publish(Force(newtons=msg.newtons))
