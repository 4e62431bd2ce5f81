"""Your own brain for exercise 11: a function from observation to action (docs/python.md).

    obs: numpy float32[5] = [cart position m, cart velocity m/s, cos θ, sin θ,
                             pole angular velocity rad/s]

Return the force command in [-1, 1] (×10 N on the cart). This one is a start: it pushes
against the pole's angle and its angular velocity, more gently than the scripted balancer
(graphs/brains/scripted.py: 10·θ + 2·ω + 0.4·x + 0.8·ẋ), and ignores the cart. Make it
yours, then run `./scripts/lab.sh exercise ex11`.
"""

import math


def act(obs):
    theta = math.atan2(float(obs[3]), float(obs[2]))  # pole angle from upright, rad
    u = 6.0 * theta + 1.2 * float(obs[4])
    return max(-1.0, min(1.0, u))
