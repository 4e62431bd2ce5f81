"""graphs/nodes/setpoint_tracker.py reading its setpoint as a message type a Rust program
registered (examples/custom_message.rs): `ratelab.Setpoint`, one field, cart_pos_m. The
class is made from the type's one definition in Rust; nothing here declares it.
"""

import math

import numpy as np
from ratelab import Force, Position, Setpoint, State

MOTOR_N = 10.0  # newtons per unit of command (gear 10 on a control in [-1, 1])


class SetpointTracker:
    def __init__(self, node):
        self.obs, self.setpoint_m = None, 0.0
        self.action = node.create_publisher(Force, "/action", 1)
        self.error = node.create_publisher(Position, "/error", 1)
        node.create_subscription(State, "/obs", self.on_obs, 1)
        node.create_subscription(Setpoint, "/reference", self.on_reference, 1)
        node.create_timer(node.get_period(), self.on_timer)

    def on_obs(self, msg):
        self.obs = msg

    def on_reference(self, msg):
        self.setpoint_m = msg.cart_pos_m

    def on_timer(self):
        if self.obs is None:
            return  # nothing sensed yet
        s = self.obs
        theta = math.atan2(s.sin_theta, s.cos_theta)
        error_m = s.cart_pos_m - self.setpoint_m
        u = 10.0 * theta + 2.0 * s.pole_angvel_rad_s + 0.4 * error_m + 0.8 * s.cart_vel_m_s
        command = np.float32(np.clip(u, -1.0, 1.0))
        self.action.publish(Force(newtons=float(command) * MOTOR_N))
        self.error.publish(Position(cart_pos_m=error_m, pole_angle_rad=theta))
