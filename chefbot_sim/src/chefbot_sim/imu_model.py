"""What the real MPU6050 (DMP) reports about heading: yaw relative to power-on, and gyro drift.

The DMP's quaternion starts at yaw 0 wherever the robot stands when the board
powers up, and its yaw integrates the gyro, so an uncorrected z-gyro bias
makes the heading drift.  The simulator's ideal IMU would give the world-frame
orientation with no drift, which no odometry fusion ever gets on the robot.

Model (planar robot, z axis up): the z-gyro bias ``b`` starts at
``gyro_bias`` (rad/s) and does a random walk with density ``gyro_bias_drift``
(rad/s per sqrt(s)); the heading error is the integral of ``b``.  The
reported orientation is ``Rz(err - yaw0) * R_world`` and the reported z rate
is ``w_z + b``.  Roll and pitch stay absolute (the DMP levels them with the
accelerometer).

No pybullet, no rospy.  The state is a small tuple the simulator keeps in its
snapshot state; the random walk's steps come from a generator seeded by
(seed, sample index), so a run is repeatable and a restored snapshot continues
exactly as the original run did, without touching the simulator's noise
generator.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

# MPU6050 after the DMP's start-up calibration: about 1 deg/min heading drift at rest
# (InvenSense application notes; hobby reports 0.5-3 deg/min), and a bias that wanders.
DEFAULT_GYRO_BIAS = 0.0003          # rad/s  (~1 deg/min)
DEFAULT_GYRO_BIAS_DRIFT = 0.0001    # rad/s/sqrt(s)


@dataclass(frozen=True)
class ImuDriftConfig:
    """Heading model of the simulated MPU6050."""

    relative_yaw: bool = True                       # yaw 0 at the start pose, as the real DMP
    gyro_bias: float = DEFAULT_GYRO_BIAS            # rad/s, z-gyro bias at power-on
    gyro_bias_drift: float = DEFAULT_GYRO_BIAS_DRIFT  # rad/s/sqrt(s), random walk of the bias

    def __post_init__(self) -> None:
        if not math.isfinite(self.gyro_bias):
            raise ValueError(f"imu_gyro_bias must be finite (rad/s), got {self.gyro_bias!r}")
        if not (math.isfinite(self.gyro_bias_drift) and self.gyro_bias_drift >= 0):
            raise ValueError(f"imu_gyro_bias_drift must be >= 0 (rad/s/sqrt(s)), got {self.gyro_bias_drift!r}")


# (bias rad/s, heading error rad, time of the last sample s or None, sample index)
DriftState = tuple[float, float, float | None, int]


def initial_state(cfg: ImuDriftConfig) -> DriftState:
    """The drift model's state at start: power-on gyro bias, no heading error, no sample yet."""
    return (cfg.gyro_bias, 0.0, None, 0)


def advance(state: DriftState, t: float, cfg: ImuDriftConfig, seed: int) -> DriftState:
    """State at sim time ``t`` (s): the bias walks, the heading error integrates it."""
    bias, err, t_last, k = state
    if t_last is None or t <= t_last:
        return (bias, err, t, k)
    dt = t - t_last
    new_bias = bias
    if cfg.gyro_bias_drift > 0:
        step = np.random.default_rng([int(seed) & 0xFFFFFFFF, 0x1A0, k]).standard_normal()
        new_bias = bias + cfg.gyro_bias_drift * math.sqrt(dt) * float(step)
    return (new_bias, err + 0.5 * (bias + new_bias) * dt, t, k + 1)


def _yaw_quat(angle: float) -> np.ndarray:
    return np.array([0.0, 0.0, math.sin(0.5 * angle), math.cos(0.5 * angle)])


def _quat_mul(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Hamilton product of (x, y, z, w) quaternions."""
    ax, ay, az, aw = a
    bx, by, bz, bw = b
    return np.array([aw * bx + ax * bw + ay * bz - az * by,
                     aw * by - ax * bz + ay * bw + az * bx,
                     aw * bz + ax * by - ay * bx + az * bw,
                     aw * bw - ax * bx - ay * by - az * bz])


def apply(quat_world: np.ndarray, gyro: np.ndarray, start_yaw: float, state: DriftState,
          cfg: ImuDriftConfig) -> tuple[np.ndarray, np.ndarray]:
    """Reported (orientation x, y, z, w; angular velocity rad/s) for the ideal ones."""
    bias, err, _, _ = state
    offset = err - (start_yaw if cfg.relative_yaw else 0.0)
    q = _quat_mul(_yaw_quat(offset), np.asarray(quat_world, dtype=float)) if offset else np.asarray(quat_world)
    g = np.array(gyro, dtype=float)
    g[2] += bias
    return q, g
