"""Synthetic scenes for the AMCL unit tests: maps and ray-cast scans on the grid (test helper)."""
from __future__ import annotations

import math

import numpy as np

from chefbot_common.geometry import Pose2D
from chefbot_common.grid import GridInfo, OccupancyMap


def room_map(width_m: float = 8.0, height_m: float = 6.0, res: float = 0.05) -> OccupancyMap:
    """A walled room with a few asymmetric boxes (so the pose is globally unique)."""
    w, h = int(round(width_m / res)), int(round(height_m / res))
    data = np.zeros((h, w), dtype=np.int8)
    data[:2, :] = data[-2:, :] = data[:, :2] = data[:, -2:] = 100
    for (x0, y0, x1, y1) in ((1.0, 1.0, 1.6, 1.4), (5.0, 3.5, 5.4, 4.8), (3.0, 4.6, 3.3, 6.0), (6.5, 0.0, 8.0, 1.2)):
        data[int(y0 / res):int(y1 / res), int(x0 / res):int(x1 / res)] = 100
    return OccupancyMap(GridInfo(res, w, h, 0.0, 0.0, 0.0), data)


def symmetric_room(res: float = 0.05) -> OccupancyMap:
    """An 8 m x 6 m walled room whose boxes come in pairs turned 180 deg about its centre (4, 3): the
    pose (x, y, a) and its look-alike (8 - x, 6 - y, a + pi) see the same scans."""
    w, h = int(round(8.0 / res)), int(round(6.0 / res))
    data = np.zeros((h, w), dtype=np.int8)
    data[:2, :] = data[-2:, :] = data[:, :2] = data[:, -2:] = 100
    for (x0, y0, x1, y1) in ((1.0, 1.0, 1.6, 1.4), (3.0, 4.4, 3.4, 6.0)):
        data[int(y0 / res):int(y1 / res), int(x0 / res):int(x1 / res)] = 100
    data[:] = np.maximum(data, data[::-1, ::-1])
    return OccupancyMap(GridInfo(res, w, h, 0.0, 0.0, 0.0), data)


def cast(occ: OccupancyMap, pose: Pose2D, angles: np.ndarray, range_max: float) -> np.ndarray:
    """Ranges (m) from ``pose`` along ``angles`` (rad, in the pose's frame) to the first
    occupied cell, marching at a quarter cell; +inf when nothing within ``range_max``."""
    info = occ.info
    step = info.resolution / 4.0
    t = np.arange(step, range_max, step)
    a = pose.yaw + np.asarray(angles)
    x = pose.x + np.cos(a)[:, None] * t[None, :]
    y = pose.y + np.sin(a)[:, None] * t[None, :]
    row, col = info.world_to_cell(x, y)
    inside = info.inside(row, col)
    hit = np.zeros_like(inside)
    hit[inside] = occ.data[row[inside], col[inside]] >= 65
    hit |= ~inside
    first = np.where(hit.any(axis=1), hit.argmax(axis=1), -1)
    return np.where(first >= 0, t[np.maximum(first, 0)], math.inf)


def drifting_odometry(truth: list[Pose2D], scale: float = 1.02, yaw_bias: float = 0.02,
                      seed: int = 0) -> list[Pose2D]:
    """Odometry poses along a true path: distances scaled by ``scale``, a heading bias of
    ``yaw_bias`` rad per m driven, plus small random noise (fixed seed)."""
    rng = np.random.default_rng(seed)
    odom = [Pose2D(0.3, -0.2, 0.5)]      # odometry frame unrelated to the map
    for a, b in zip(truth[:-1], truth[1:], strict=True):
        d = a.inverse().compose(b)
        dist = math.hypot(d.x, d.y)
        step = Pose2D(d.x * scale + rng.normal(0, 0.002), d.y * scale + rng.normal(0, 0.002),
                      d.yaw + yaw_bias * dist + rng.normal(0, 0.002))
        odom.append(odom[-1].compose(step))
    return odom


def lawnmower(room: OccupancyMap, step: float = 0.05) -> list[Pose2D]:
    """A closed route through the test room (m, rad), sampled every ``step`` m, turning in place at corners."""
    corners = [(0.8, 2.2), (4.2, 2.2), (4.2, 3.8), (1.5, 3.6), (1.5, 5.2), (6.5, 5.2), (6.6, 2.4), (2.2, 2.0)]
    poses: list[Pose2D] = []
    yaw = 0.0
    for (x0, y0), (x1, y1) in zip(corners[:-1], corners[1:], strict=True):
        new_yaw = math.atan2(y1 - y0, x1 - x0)
        turn = math.remainder(new_yaw - yaw, 2 * math.pi)
        for k in range(int(abs(turn) / 0.05) + 1):
            poses.append(Pose2D(x0, y0, yaw + turn * k / max(int(abs(turn) / 0.05), 1)))
        yaw = new_yaw
        n = int(math.hypot(x1 - x0, y1 - y0) / step)
        poses.extend(Pose2D(x0 + (x1 - x0) * k / n, y0 + (y1 - y0) * k / n, yaw) for k in range(1, n + 1))
    return poses
