"""The chapter's scripted balancer as a Python brain: `ratelab run --policy graphs/brains/scripted.py`.

A brain is a function from observation to action (course chapter 2.8, `load_policy`).
ratelab calls `act(obs)` on every policy tick with the observation the sensor published:

    obs: numpy float32[5] = [cart position m, cart velocity m/s, cos θ, sin θ,
                             pole angular velocity rad/s]

and applies what it returns — a float, or a one-element array — as the force command in
[-1, 1] (×10 N on the cart; ratelab converts it to float32 and clips it, as the chapter's
environment does). This file does the chapter's arithmetic, so under the virtual clock its
runs equal the built-in `--policy scripted` in every figure. Copy it and make it yours.
"""

import math

import numpy as np


def act(obs):
    theta = math.atan2(float(obs[3]), float(obs[2]))  # pole angle from upright, rad
    u = 10.0 * theta + 2.0 * float(obs[4]) + 0.4 * float(obs[0]) + 0.8 * float(obs[1])
    return np.array([np.clip(u, -1.0, 1.0)], dtype=np.float32)
