"""Sample motion model of a differential drive from odometry (AMCL's ``diff`` model).

Between two odometry poses the robot is said to have turned ``rot1``, driven
``trans`` and turned ``rot2`` (Thrun, Burgard, Fox, *Probabilistic Robotics*,
table 5.6).  Each particle draws its own noisy version of the three, with
variances (rad², m²)

    var(rot1)  = alpha1 · rot1²  + alpha2 · trans²
    var(trans) = alpha3 · trans² + alpha4 · (rot1² + rot2²)
    var(rot2)  = alpha1 · rot2²  + alpha2 · trans²

As in ROS's amcl, the rotations entering the noise are folded to
min(|rot|, |pi - rot|) so that driving backwards is not taken for a half turn,
and rot1 is 0 for translations under 1 cm (its direction is then undefined).
All particles are moved at once (vectorised).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from chefbot_common.geometry import Pose2D, wrap_angle

MIN_TRANS_FOR_ROT1 = 0.01  # m: below this the heading of the translation is noise


@dataclass(frozen=True)
class DiffMotionNoise:
    """AMCL's ``odom_alpha1..4`` (dimensionless variance ratios, see the module docstring)."""

    alpha1: float = 0.2   # rotation noise from rotation
    alpha2: float = 0.2   # rotation noise from translation (rad²/m²)
    alpha3: float = 0.2   # translation noise from translation
    alpha4: float = 0.2   # translation noise from rotation (m²/rad²)

    def __post_init__(self) -> None:
        for name in ("alpha1", "alpha2", "alpha3", "alpha4"):
            v = getattr(self, name)
            if not (math.isfinite(v) and v >= 0.0):
                raise ValueError(f"odom_{name} must be a finite number >= 0, got {v}")


def odometry_deltas(old: Pose2D, new: Pose2D) -> tuple[float, float, float]:
    """(rot1 rad, trans m, rot2 rad) taking the odometry pose ``old`` to ``new``."""
    dx, dy = new.x - old.x, new.y - old.y
    trans = math.hypot(dx, dy)
    rot1 = wrap_angle(math.atan2(dy, dx) - old.yaw) if trans >= MIN_TRANS_FOR_ROT1 else 0.0
    rot2 = wrap_angle(new.yaw - old.yaw - rot1)
    return rot1, trans, rot2


def _fold(rot: float) -> float:
    """|rot| or |pi - |rot||, whichever is smaller: driving backwards is not a half turn."""
    return min(abs(rot), abs(wrap_angle(rot - math.pi)))


def deltas_stddev(rot1: float, trans: float, rot2: float, noise: DiffMotionNoise) -> tuple[float, float, float]:
    """Standard deviations (rad, m, rad) of the sampled (rot1, trans, rot2)."""
    r1, r2 = _fold(rot1), _fold(rot2)
    s_rot1 = math.sqrt(noise.alpha1 * r1 * r1 + noise.alpha2 * trans * trans)
    s_trans = math.sqrt(noise.alpha3 * trans * trans + noise.alpha4 * (r1 * r1 + r2 * r2))
    s_rot2 = math.sqrt(noise.alpha1 * r2 * r2 + noise.alpha2 * trans * trans)
    return s_rot1, s_trans, s_rot2


def sample_deltas(rot1: float, trans: float, rot2: float, noise: DiffMotionNoise, n: int,
                  rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``n`` noisy copies of (rot1, trans, rot2), each an (n,) array."""
    s1, st, s2 = deltas_stddev(rot1, trans, rot2, noise)
    z = rng.standard_normal((3, n))
    return rot1 - s1 * z[0], trans - st * z[1], rot2 - s2 * z[2]


def apply_deltas(particles: np.ndarray, rot1: np.ndarray, trans: np.ndarray, rot2: np.ndarray) -> np.ndarray:
    """Particles (N, 3) moved by per-particle (rot1, trans, rot2); yaw wrapped to [-pi, pi)."""
    out = np.empty_like(particles)
    heading = particles[:, 2] + rot1
    out[:, 0] = particles[:, 0] + trans * np.cos(heading)
    out[:, 1] = particles[:, 1] + trans * np.sin(heading)
    out[:, 2] = np.mod(heading + rot2 + math.pi, 2.0 * math.pi) - math.pi
    return out


def sample_motion(particles: np.ndarray, old: Pose2D, new: Pose2D, noise: DiffMotionNoise,
                  rng: np.random.Generator) -> np.ndarray:
    """Particles moved by the odometry change ``old`` -> ``new`` with sampled noise."""
    rot1, trans, rot2 = odometry_deltas(old, new)
    return apply_deltas(particles, *sample_deltas(rot1, trans, rot2, noise, len(particles), rng))
