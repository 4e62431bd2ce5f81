"""The camera against the state sensor (graphs/cartpole-camera-beside.toml): each of the
vision node's measurements (`/meas`, the pole's angle seen in a frame) is compared with the
state sensor's newest angle (`/obs`, read from the robot's encoders at 100 Hz, so at most
10 ms older or newer than the frame on its own). Once a second the node says how far apart
they were: the camera's view is up to a frame old when
it is taken, and older by the time the render, the transfer and NumPy are done, so while
the pole swings the two disagree by its angular velocity times that age.
"""

import math

from ratelab import Position, State

EVERY = 30  # measurements between two log lines: one second of a 30 Hz camera


class CameraVsSensor:
    def __init__(self, node):
        self.logger = node.get_logger()
        self.sensor_rad = None
        self.squares = 0.0
        self.largest = 0.0
        self.count = 0
        node.create_subscription(State, "/obs", self.on_obs, 1)
        node.create_subscription(Position, "/meas", self.on_meas, 1)

    def on_obs(self, msg):
        self.sensor_rad = math.atan2(msg.sin_theta, msg.cos_theta)

    def on_meas(self, msg):
        if self.sensor_rad is None:
            return
        d = msg.pole_angle_rad - self.sensor_rad
        diff = math.atan2(math.sin(d), math.cos(d))  # the shorter way round
        self.squares += diff * diff
        self.largest = max(self.largest, abs(diff))
        self.count += 1
        if self.count == EVERY:
            rms_mrad = 1000.0 * math.sqrt(self.squares / self.count)
            self.logger.info(
                f"camera vs state sensor, pole angle over {self.count} frames: "
                f"RMS {rms_mrad:.1f} mrad, largest {1000.0 * self.largest:.1f} mrad"
            )
            self.squares, self.largest, self.count = 0.0, 0.0, 0
