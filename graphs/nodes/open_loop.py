"""An open-loop driver (graphs/cartpole-open-loop.toml): a node with no input that
publishes a force on a timer, a sine of amplitude_n newtons and period period_s, whatever
the pole does. Without feedback nothing catches the pole.
"""

import math

from ratelab import Force


class OpenLoop:
    def __init__(self, node):
        self.amplitude_n = float(node.get_parameter("amplitude_n").value)
        self.period_s = float(node.get_parameter("period_s").value)
        self.clock = node.get_clock()
        self.pub = node.create_publisher(Force, "/force", 1)
        node.create_timer(node.get_period(), self.on_timer)

    def on_timer(self):
        t_s = self.clock.now().nanoseconds / 1e9
        newtons = self.amplitude_n * math.sin(2.0 * math.pi * t_s / self.period_s)
        self.pub.publish(Force(newtons=newtons))
