"""The chapter's scripted balancer as a Python node, written as an rclpy node is.

Run it: `ratelab run --graph graphs/cartpole-python.toml`. Under the virtual clock its runs
equal the built-in graph's (graphs/cartpole.toml) in every figure.

The constructor declares what the node does, as in rclpy: one subscription (the state the
sensor publishes), one publisher (the force for the actuator), one timer at the node's rate.
ratelab ticks the node at its `rate_hz`: first the subscription callback for what arrived
(the newest /obs: the topic delivers latest-wins), then the timer.
"""

import math

import numpy as np
from ratelab import Force, State

MOTOR_N = 10.0  # newtons per unit of command: the cart's motor (gear 10 on a control in [-1, 1])


class ScriptedBalancer:
    def __init__(self, node):
        self.obs = None
        self.pub = node.create_publisher(Force, "/action", 1)
        node.create_subscription(State, "/obs", self.on_obs, 1)
        node.create_timer(node.get_period(), self.on_timer)  # every tick, at the node's rate_hz

    def on_obs(self, msg):
        self.obs = msg  # the newest state: cart_pos_m, cart_vel_m_s, cos_theta, sin_theta, pole_angvel_rad_s

    def on_timer(self):
        if self.obs is None:
            return  # nothing sensed yet
        s = self.obs
        theta = math.atan2(s.sin_theta, s.cos_theta)
        u = 10.0 * theta + 2.0 * s.pole_angvel_rad_s + 0.4 * s.cart_pos_m + 0.8 * s.cart_vel_m_s
        command = np.float32(np.clip(u, -1.0, 1.0))  # the chapter's action: float32 in [-1, 1]
        self.pub.publish(Force(newtons=float(command) * MOTOR_N))
