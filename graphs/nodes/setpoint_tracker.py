"""A policy with two inputs and two outputs: the chapter's balancer, made to hold the cart at
a setpoint that another node publishes (graphs/cartpole-setpoint.toml).

Inputs: /obs (the sensor's state) and /reference (the setpoint: a Position whose
cart_pos_m is where the cart should be). Outputs: /action (the force for the motor) and
/error (a Position: how far the cart is from the setpoint, and the pole's angle), for a
learner to watch or a node to use.

Each subscription keeps its input's newest message (a zero-order hold); the timer computes.
ratelab runs the callbacks of one tick in the order they were created (here /obs, then
/reference), then the timer. What it publishes carries the oldest origin of the inputs'
newest messages, so a setpoint published rarely would stretch the sense→act latency the
actuator measures (the command rests on a value that old): the reference node publishes at
the control rate.
"""

import math

import numpy as np
from ratelab import Force, Position, State

MOTOR_N = 10.0  # newtons per unit of command (gear 10 on a control in [-1, 1])


class SetpointTracker:
    def __init__(self, node):
        self.obs, self.setpoint_m = None, 0.0
        self.action = node.create_publisher(Force, "/action", 1)
        self.error = node.create_publisher(Position, "/error", 1)
        node.create_subscription(State, "/obs", self.on_obs, 1)
        node.create_subscription(Position, "/reference", self.on_reference, 1)
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
        # The chapter's gains, with the cart's position measured from the setpoint.
        u = 10.0 * theta + 2.0 * s.pole_angvel_rad_s + 0.4 * error_m + 0.8 * s.cart_vel_m_s
        command = np.float32(np.clip(u, -1.0, 1.0))
        self.action.publish(Force(newtons=float(command) * MOTOR_N))
        self.error.publish(Position(cart_pos_m=error_m, pole_angle_rad=theta))
