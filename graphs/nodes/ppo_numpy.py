"""The course's ch2.1 PPO actor, run with NumPy alone, as a policy node
(graphs/cartpole-ppo-numpy.toml).

The actor is Linear(5, h) -> tanh -> Linear(h, h) -> tanh -> Linear(h, 1) on the chapter's
observation [cart_pos, cart_vel, cos(theta), sin(theta), pole_angvel] (float32), acting
with its mean. Its weights are the checkpoint's tensors in NumPy's .npz, written by ratelab
(no PyTorch needed):

    ratelab export ../shared/fixtures/ppo_ch2.1_seed0.pt --out graphs/nodes/ppo_ch2.1_seed0.npz

The `weights` parameter is that file, relative to this script's folder (or absolute).
`PpoActor` is the network alone, usable outside a graph: `PpoActor(path)(obs) -> float`.
"""

import os

import numpy as np
from ratelab import Force, State

MOTOR_N = 10.0  # newtons per unit of command: the cart's motor (gear 10 on a control in [-1, 1])


class PpoActor:
    """The actor's mean, float32 throughout, from the `actor_mean.{0,2,4}.{weight,bias}`
    arrays of an .npz (PyTorch's layout: weight [out, in])."""

    def __init__(self, npz_path):
        with np.load(npz_path) as z:
            self.layers = [
                (z[f"actor_mean.{i}.weight"].astype(np.float32), z[f"actor_mean.{i}.bias"].astype(np.float32))
                for i in (0, 2, 4)
            ]

    def __call__(self, obs):
        x = np.asarray(obs, dtype=np.float32)
        last = len(self.layers) - 1
        for i, (w, b) in enumerate(self.layers):
            x = w @ x + b
            if i < last:
                x = np.tanh(x)
        return float(x[0])  # the raw mean; the env clips it to [-1, 1]


class PpoNumpy:
    def __init__(self, node):
        weights = str(node.get_parameter("weights").value)
        path = os.path.join(os.path.dirname(os.path.abspath(__file__)), weights)
        if not os.path.isfile(path):
            raise FileNotFoundError(
                f"no weights at {path}; write them with `ratelab export "
                f"../shared/fixtures/ppo_ch2.1_seed0.pt --out {path}`"
            )
        self.actor = PpoActor(path)
        self.obs = None
        self.pub = node.create_publisher(Force, "/action", 1)
        node.create_subscription(State, "/obs", self.on_obs, 1)
        node.create_timer(node.get_period(), self.on_timer)

    def on_obs(self, msg):
        self.obs = msg

    def on_timer(self):
        if self.obs is None:
            return  # nothing sensed yet
        s = self.obs
        obs = [s.cart_pos_m, s.cart_vel_m_s, s.cos_theta, s.sin_theta, s.pole_angvel_rad_s]
        command = np.float32(np.clip(self.actor(obs), -1.0, 1.0))  # the env's clip, float32
        self.pub.publish(Force(newtons=float(command) * MOTOR_N))
