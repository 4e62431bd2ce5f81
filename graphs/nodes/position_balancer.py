"""A controller with its own estimator: it reads the position sensor alone (cart position,
pole angle: no velocities), estimates the velocities by differencing the two newest
readings, and commands the force (graphs/cartpole-position-python.toml).

In the chapter's graph an estimator node and the policy do this as two nodes; here one node
does both, as a learner's first controller often does. It drives the actuator, so ratelab
takes it as the graph's policy; /meas, the topic it reads, is the policy's input.

A Python node gets a message without its stamp, so the velocities divide by the time
between the callbacks that delivered the two readings (the node's clock), which is the
sensor's interval when both run at the same rate, as here.
"""

import math

import numpy as np
from ratelab import Force, Position

MOTOR_N = 10.0  # newtons per unit of command (gear 10 on a control in [-1, 1])


class PositionBalancer:
    def __init__(self, node):
        self.clock = node.get_clock()
        self.last = None  # (t_s, cart_pos_m, pole_angle_rad) of the previous reading
        self.vel = (0.0, 0.0)  # cart m/s, pole rad/s
        self.pub = node.create_publisher(Force, "/action", 1)
        node.create_subscription(Position, "/meas", self.on_meas, 1)

    def on_meas(self, msg):
        t = self.clock.now().nanoseconds / 1e9
        x, theta = msg.cart_pos_m, msg.pole_angle_rad
        if self.last is not None and t > self.last[0]:
            dt = t - self.last[0]
            dtheta = math.remainder(theta - self.last[2], 2 * math.pi)  # across ±π
            self.vel = ((x - self.last[1]) / dt, dtheta / dt)
        self.last = (t, x, theta)
        x_dot, theta_dot = self.vel
        u = 10.0 * theta + 2.0 * theta_dot + 0.4 * x + 0.8 * x_dot
        command = np.float32(np.clip(u, -1.0, 1.0))
        self.pub.publish(Force(newtons=float(command) * MOTOR_N))
