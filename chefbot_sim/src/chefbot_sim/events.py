"""Typed readings of the simulator (pure): what :meth:`chefbot_sim.sim.Simulator.step` returns.

An :class:`Event` is a sensor ``kind``, the sim time ``stamp`` (s) and a payload
whose shape depends on the kind (TypedDicts below; arrays are numpy).  The ROS
node turns them into messages (``chefbot_sim.ros_io``), the benchmark and the
unit tests read them directly.
"""
from __future__ import annotations

from typing import Literal, NamedTuple, TypedDict, Union

import numpy as np

SensorKind = Literal["clock", "joint_states", "ground_truth", "odom", "imu", "ultrasonic", "cliff", "depth", "rgb",
                     "bumper", "lidar"]


class JointStatesData(TypedDict):
    """Joint names, positions (rad) and velocities (rad/s)."""

    name: list[str]
    position: np.ndarray
    velocity: np.ndarray


class GroundTruthData(TypedDict):
    """True base pose in the world frame (position m, orientation quaternion xyzw) and twist in the base frame."""

    position: np.ndarray
    orientation: np.ndarray
    linear: np.ndarray
    angular: np.ndarray
    x: float
    y: float
    yaw: float


class OdomData(TypedDict):
    """Wheel odometry: pose (m, m, rad) in the odom frame, forward speed (m/s) and turn rate (rad/s)."""

    x: float
    y: float
    yaw: float
    v: float
    w: float


class ImuData(TypedDict):
    """IMU frame orientation (quaternion xyzw), gyro (rad/s), accelerometer (m/s^2) and their variances."""

    orientation: np.ndarray
    angular_velocity: np.ndarray
    linear_acceleration: np.ndarray
    gyro_variance: float
    accel_variance: float


class UltrasonicData(TypedDict):
    """Sonar cone (rad), limits and reading (m; +inf without an echo, REP 117)."""

    field_of_view: float
    min_range: float
    max_range: float
    range: float


class CliffData(TypedDict):
    """The cliff sensors, one entry per sensor in URDF order: names, URDF frames, beam cone (rad), limits and
    readings (m; +inf = no floor within max_range, i.e. a drop; -inf = closer than min_range; REP 117)."""

    names: list[str]
    frames: list[str]
    field_of_view: np.ndarray
    min_range: np.ndarray
    max_range: np.ndarray
    range: np.ndarray


class LidarData(TypedDict):
    """One 2-D lidar scan: beam i at angle_min + i * angle_increment (rad, about the frame's +z), ranges (m,
    float32; +inf = no return within range_max, -inf = closer than range_min; REP 117), period (s), frame."""

    ranges: np.ndarray
    angle_min: float
    angle_increment: float
    angle_max: float
    range_min: float
    range_max: float
    scan_time: float
    frame: str


class BumperData(TypedDict):
    """Whether the robot touches anything, and the names of the bodies it touches."""

    pressed: bool
    bodies: list[str]


# clock: sim time (s); depth: float32 (H, W) m; rgb: uint8 (H, W, 3)
EventData = Union[float, np.ndarray, JointStatesData, GroundTruthData, OdomData, ImuData, UltrasonicData,
                  CliffData, BumperData, LidarData]


class Event(NamedTuple):
    """A reading: ``kind``, sim time ``stamp`` (s) and ``data`` (the payload type of that kind)."""

    kind: SensorKind
    stamp: float
    data: EventData
