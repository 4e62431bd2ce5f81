"""A monitor (graphs/cartpole-monitor.toml): it reads the sensor's state beside the policy
and keeps the largest pole angle it has seen, saying it when it grows past a threshold. It
ticks at its own rate; the topic gives it a queue of its own, so what it misses is its
drop, not the policy's.
"""

import math

from ratelab import State


class ObsMonitor:
    def __init__(self, node):
        self.logger = node.get_logger()
        self.worst_rad = 0.0
        self.warn_rad = 0.2
        node.create_subscription(State, "/obs", self.on_obs, 1)

    def on_obs(self, msg):
        angle = abs(math.atan2(msg.sin_theta, msg.cos_theta))
        if angle > self.worst_rad:
            self.worst_rad = angle
            if angle > self.warn_rad:
                self.logger.warn(f"pole at {angle:.2f} rad")
