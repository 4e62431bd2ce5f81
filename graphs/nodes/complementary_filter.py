"""A learner-style estimator in Python: from position measurements (cart m, pole angle rad)
to the full state the policy needs (graphs/cartpole-estimator-python.toml).

Velocities are not measured, so they are estimated: the finite difference of two readings is
noisy (it amplifies the sensor's noise by 1/dt), the previous estimate is smooth but lags; a
complementary filter blends them, trusting the smooth estimate at high frequencies and the
measurement at low ones. `cutoff_hz` is where the trust crosses over: the estimate lags the
true velocity by about 1/(2π·cutoff_hz) seconds.
"""

import math

from ratelab import Position, State


class ComplementaryFilter:
    def __init__(self, node):
        cutoff_hz = float(node.get_parameter("cutoff_hz").value)
        self.tau_s = 1.0 / (2.0 * math.pi * cutoff_hz)
        self.clock = node.get_clock()
        self.last = None  # (time s, cart m, angle rad) of the previous reading
        self.vel = (0.0, 0.0)  # estimated cart m/s, pole rad/s
        self.pub = node.create_publisher(State, "/state", 1)
        node.create_subscription(Position, "/meas", self.on_meas, 1)
        node.create_timer(node.get_period(), self.on_timer)

    def on_meas(self, msg):
        t = self.clock.now().seconds
        if self.last is not None and t > self.last[0]:
            dt = t - self.last[0]
            raw = ((msg.cart_pos_m - self.last[1]) / dt, (msg.pole_angle_rad - self.last[2]) / dt)
            a = self.tau_s / (self.tau_s + dt)  # how much of the old estimate to keep
            self.vel = tuple(a * v + (1.0 - a) * r for v, r in zip(self.vel, raw))
        self.last = (t, msg.cart_pos_m, msg.pole_angle_rad)

    def on_timer(self):
        if self.last is None:
            return  # nothing measured yet
        _, x, theta = self.last
        self.pub.publish(State(cart_pos_m=x, cart_vel_m_s=self.vel[0], cos_theta=math.cos(theta),
                               sin_theta=math.sin(theta), pole_angvel_rad_s=self.vel[1]))
