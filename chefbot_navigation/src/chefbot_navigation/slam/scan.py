"""A laser scan reduced to what mapping needs (pure numpy), REP 117 aware.

REP 117 reading classes: a finite range in [range_min, range_max] is a hit;
``+inf`` means "nothing within range_max" (free space up to the usable range,
no obstacle); ``-inf`` means "too close" and NaN "no valid measurement": both
say nothing about free space and are dropped.  Finite readings outside
[range_min, range_max] (drivers that predate REP 117) are treated like their
REP 117 class: above range_max as ``+inf``, below range_min dropped.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from chefbot_common.geometry import Pose2D


class ScanError(ValueError):
    """A scan that cannot be used; the message names what is wrong."""


@dataclass
class Scan:
    """Beams of one scan in the robot base frame.

    ``origin`` (2,) m: sensor position in the base frame; ``ends`` (N, 2) m:
    end of each usable beam in the base frame (at the hit, or at the usable
    range for a no-return beam); ``hit`` (N,) bool: the end is an obstacle.
    """

    origin: np.ndarray
    ends: np.ndarray
    hit: np.ndarray

    @property
    def hits(self) -> np.ndarray:
        """(M, 2) m obstacle points in the base frame."""
        return self.ends[self.hit]


def scan_from_ranges(ranges: np.ndarray, angle_min: float, angle_increment: float, range_min: float,
                     range_max: float, sensor_in_base: Pose2D, max_usable_range: float,
                     max_range: float | None = None) -> Scan:
    """Convert raw ranges (m) to a :class:`Scan` in the base frame.

    ``max_usable_range`` (gmapping's ``maxUrange``, m): longer readings and
    ``+inf`` clear free space only up to this distance and mark nothing.
    ``max_range`` (gmapping's ``maxRange``, m; default the sensor's
    ``range_max``): readings at or beyond it count as "no return".
    Raises :class:`ScanError` for a scan with zero beams or a non-finite or
    non-positive angle increment.
    """
    r = np.asarray(ranges, dtype=float).ravel()
    if r.size == 0:
        raise ScanError("scan has zero beams (empty ranges)")
    if not math.isfinite(angle_increment) or angle_increment == 0.0 or not math.isfinite(angle_min):
        raise ScanError(f"scan has invalid angles: angle_min {angle_min}, angle_increment {angle_increment}")
    if not (math.isfinite(range_max) and range_max > 0):
        raise ScanError(f"scan has invalid range_max {range_max}")
    no_return_at = min(range_max, max_range) if max_range else range_max
    angles = angle_min + angle_increment * np.arange(r.size)
    with np.errstate(invalid="ignore"):
        no_return = (r == np.inf) | (np.isfinite(r) & (r >= no_return_at))
        hit = np.isfinite(r) & (r >= range_min) & (r < no_return_at) & (r <= max_usable_range)
        far_hit = np.isfinite(r) & (r >= range_min) & (r < no_return_at) & (r > max_usable_range)
    use = hit | no_return | far_hit
    length = np.where(hit, r, max_usable_range)[use]
    a = angles[use] + sensor_in_base.yaw
    ends = np.column_stack((sensor_in_base.x + length * np.cos(a), sensor_in_base.y + length * np.sin(a)))
    return Scan(np.array([sensor_in_base.x, sensor_in_base.y]), ends, hit[use])


def transform_points(pose: Pose2D, pts: np.ndarray) -> np.ndarray:
    """(N, 2) points given in ``pose``'s frame, expressed in its parent frame."""
    c, s = math.cos(pose.yaw), math.sin(pose.yaw)
    pts = np.asarray(pts, dtype=float).reshape(-1, 2)
    return np.column_stack((pose.x + c * pts[:, 0] - s * pts[:, 1], pose.y + s * pts[:, 0] + c * pts[:, 1]))
