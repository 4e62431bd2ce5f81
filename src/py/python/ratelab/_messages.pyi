"""Stubs of ratelab's message classes for Python nodes (made at run time from ratelab's
message registry: src/core/msg; docs/python.md). Fields are floats in SI units; a message is
made positionally or by keyword (`Force(newtons=2.0)`)."""

from typing import Any, Dict

class State:
    """The full state, the chapter's observation. ROS 2: sensor_msgs/msg/JointState."""

    cart_pos_m: float
    cart_vel_m_s: float
    cos_theta: float
    sin_theta: float
    pole_angvel_rad_s: float
    def __init__(
        self,
        cart_pos_m: float = 0.0,
        cart_vel_m_s: float = 0.0,
        cos_theta: float = 0.0,
        sin_theta: float = 0.0,
        pole_angvel_rad_s: float = 0.0,
    ) -> None: ...
    def to_ros(self) -> Dict[str, Any]: ...
    @classmethod
    def from_ros(cls, msg: Any) -> "State": ...

class Position:
    """A position measurement. ROS 2: sensor_msgs/msg/JointState without velocities."""

    cart_pos_m: float
    pole_angle_rad: float
    def __init__(self, cart_pos_m: float = 0.0, pole_angle_rad: float = 0.0) -> None: ...
    def to_ros(self) -> Dict[str, Any]: ...
    @classmethod
    def from_ros(cls, msg: Any) -> "Position": ...

class Force:
    """A force on the cart, N. ROS 2: std_msgs/msg/Float64."""

    newtons: float
    def __init__(self, newtons: float = 0.0) -> None: ...
    def to_ros(self) -> Dict[str, Any]: ...
    @classmethod
    def from_ros(cls, msg: Any) -> "Force": ...

class Time:
    """A run time, as rclpy's Time: nanoseconds since the run's start."""

    nanoseconds: int
    def __init__(self, nanoseconds: int) -> None: ...
    @property
    def seconds(self) -> float: ...
