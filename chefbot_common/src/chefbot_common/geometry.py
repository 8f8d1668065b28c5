"""Planar poses and quaternion helpers (pure, no ROS).

Angles in rad, lengths in m.  A :class:`Pose2D` is the pose of a frame in its
parent (x, y, yaw), composable like a homogeneous 2-D transform.
"""
from __future__ import annotations

import math
from dataclasses import dataclass


def wrap_angle(a: float) -> float:
    """Angle wrapped to [-pi, pi) rad."""
    return (a + math.pi) % (2.0 * math.pi) - math.pi


@dataclass(frozen=True)
class Pose2D:
    """x, y in m and yaw in rad of a child frame expressed in its parent frame."""

    x: float = 0.0
    y: float = 0.0
    yaw: float = 0.0

    def compose(self, other: Pose2D) -> Pose2D:
        """``self * other``: ``other`` (given in this pose's frame) expressed in the parent frame."""
        c, s = math.cos(self.yaw), math.sin(self.yaw)
        return Pose2D(self.x + c * other.x - s * other.y, self.y + s * other.x + c * other.y,
                      wrap_angle(self.yaw + other.yaw))

    def inverse(self) -> Pose2D:
        """The parent frame expressed in this pose's frame."""
        c, s = math.cos(self.yaw), math.sin(self.yaw)
        return Pose2D(-c * self.x - s * self.y, s * self.x - c * self.y, wrap_angle(-self.yaw))

    def distance(self, other: Pose2D) -> float:
        """Euclidean distance (m) between the two positions."""
        return math.hypot(other.x - self.x, other.y - self.y)


class QuaternionError(ValueError):
    """A quaternion that cannot be used as a planar orientation."""


def yaw_from_quaternion(x: float, y: float, z: float, w: float, zero_policy: str = "reject") -> float | None:
    """Yaw (rad) of a quaternion that need not be normalised.

    ``zero_policy`` decides what an all-zero quaternion (a client that fills no
    orientation at all) means: ``"reject"`` raises :class:`QuaternionError`, ``"identity"``
    returns 0.0 (the intended (0, 0, 0, 1)), ``"ignore_yaw"`` returns None
    (the caller then skips the final heading alignment).  NaN/inf components
    always raise.  Roll/pitch are dropped: a planar robot can only honour yaw.
    """
    comps = (x, y, z, w)
    if not all(math.isfinite(c) for c in comps):
        raise QuaternionError(f"quaternion has non-finite components {comps}")
    norm = math.sqrt(sum(c * c for c in comps))
    if norm < 1e-6:
        if zero_policy == "identity":
            return 0.0
        if zero_policy == "ignore_yaw":
            return None
        raise QuaternionError("quaternion has length zero (all components 0); no orientation given")
    x, y, z, w = (c / norm for c in comps)
    return math.atan2(2.0 * (w * z + x * y), 1.0 - 2.0 * (y * y + z * z))


def quaternion_from_yaw(yaw: float) -> tuple[float, float, float, float]:
    """(x, y, z, w) of a rotation of ``yaw`` rad about +z."""
    return (0.0, 0.0, math.sin(0.5 * yaw), math.cos(0.5 * yaw))


def map_to_odom(map_T_base: Pose2D, odom_T_base: Pose2D) -> Pose2D:
    """The map->odom transform (m, rad) that makes map->odom->base equal ``map_T_base``:
    map_T_odom = map_T_base * inverse(odom_T_base) (what every localizer publishes)."""
    return map_T_base.compose(odom_T_base.inverse())
