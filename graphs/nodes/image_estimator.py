"""A learner's vision node in NumPy: the cart's position and the pole's angle from a
camera's frame (graphs/cartpole-camera-python.toml), what the built-in `image_estimator`
kind does in Rust.

The camera (kind `camera`) sees the world as a calibrated camera would: 6 m of rail across
the frame's width (or less, where its height is the limit), the hinge 85 % of the way down,
the cart a 0.2 × 0.1 m box of shade 128, the 1 m pole in shade 255 with soft edges. That
calibration, like a real camera's intrinsics, is what turns pixels into metres and radians.
The cart's column comes from its box's lower half (which the pole never covers); the pole's
angle from the principal axis of the bright pixels above the cart, each weighted by its
brightness: a fraction of a pixel at the pole's tip.
"""

import numpy as np

from ratelab import Image, Position

CART_SHADE = 128


class ImageEstimator:
    def __init__(self, node):
        self.pub = node.create_publisher(Position, "/meas", 1)
        node.create_subscription(Image, "/image", self.on_image, 1)

    def on_image(self, img):
        if img.encoding != "mono8" or img.width == 0 or img.height == 0:
            return
        h, w, step = int(img.height), int(img.width), int(img.step)
        if len(img.data) != step * h:
            return  # not a whole frame
        px = np.frombuffer(img.data, dtype=np.uint8).reshape(h, step)[:, :w]
        # The camera's calibration.
        scale = min(w / 6.0, 0.7 * h / 1.1)  # px per metre
        hinge_row = 0.85 * h
        radius = max(0.02 * scale, 1.0)  # the pole's, px
        half = max(0.05 * scale, radius + 2.0)  # the cart's half height, px
        # (Rounded half away from zero, as the camera draws: Python's round() goes to even.)
        top = int(np.floor(hinge_row - half + 0.5))
        bottom = min(int(np.floor(hinge_row + half + 0.5)), h)
        below_pole = int(np.floor(hinge_row + radius)) + 1
        # The cart: its shade's columns in the rows the pole's round end does not reach.
        cols = np.nonzero(px[max(below_pole, top):bottom] == CART_SHADE)[1]
        if cols.size == 0:
            return
        hinge_col = cols.mean() + 0.5
        # The pole: the brightness above the cart, right and up from the hinge.
        rows, cols = np.nonzero(px[:top])
        if rows.size == 0:
            return
        weight = px[rows, cols].astype(np.float64)
        u = cols + 0.5 - hinge_col
        v = hinge_row - (rows + 0.5)
        mu, mv = np.average(u, weights=weight), np.average(v, weights=weight)
        cuu = np.average((u - mu) ** 2, weights=weight)
        cvv = np.average((v - mv) ** 2, weights=weight)
        cuv = np.average((u - mu) * (v - mv), weights=weight)
        # Along (sin θ, cos θ): c_uv = σ² sin θ cos θ, c_vv − c_uu = σ² cos 2θ.
        theta = 0.5 * np.arctan2(2.0 * cuv, cvv - cuu)
        self.pub.publish(Position(cart_pos_m=(hinge_col - w / 2.0) / scale,
                                  pole_angle_rad=float(theta)))
