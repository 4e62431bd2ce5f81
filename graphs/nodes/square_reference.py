"""A setpoint source: a node with no input that publishes, on a timer, where the cart
should be: a square wave between -amplitude_m and +amplitude_m, switching every half
period_s (graphs/cartpole-setpoint.toml). Its messages carry its own tick time as their
origin: it is where their data begins.
"""

from ratelab import Position


class SquareReference:
    def __init__(self, node):
        self.amplitude_m = float(node.get_parameter("amplitude_m").value)
        self.half_period_ns = int(float(node.get_parameter("period_s").value) * 1e9 / 2)
        self.clock = node.get_clock()
        self.pub = node.create_publisher(Position, "/reference", 1)
        node.create_timer(node.get_period(), self.on_timer)

    def on_timer(self):
        half = self.clock.now().nanoseconds // self.half_period_ns
        setpoint = self.amplitude_m if half % 2 == 0 else -self.amplitude_m
        self.pub.publish(Position(cart_pos_m=setpoint, pole_angle_rad=0.0))
