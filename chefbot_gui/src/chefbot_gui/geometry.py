"""Planar geometry for the delivery GUI: route progress, map pixels.

Quaternions: :mod:`chefbot_common.geometry`; grid placement: :class:`chefbot_common.grid.GridInfo`.

Pure Python (no ROS, no Qt) so it is unit-tested without a master or a display.
Units: metres, radians, seconds.  All poses are in the ``map`` frame.
"""
from __future__ import annotations

import math
from collections.abc import Sequence

Point = tuple[float, float]


def distance(a: Point, b: Point) -> float:
    """Euclidean distance (m) between two points."""
    return math.hypot(a[0] - b[0], a[1] - b[1])


def path_length(points: Sequence[Point]) -> float:
    """Length (m) of a polyline."""
    return sum(distance(points[i], points[i + 1]) for i in range(len(points) - 1))


def _project(p: Point, a: Point, b: Point) -> tuple[float, Point]:
    """Parameter t in [0, 1] and the closest point of segment ab to p."""
    dx, dy = b[0] - a[0], b[1] - a[1]
    seg2 = dx * dx + dy * dy
    if seg2 == 0.0:
        return 0.0, a
    t = max(0.0, min(1.0, ((p[0] - a[0]) * dx + (p[1] - a[1]) * dy) / seg2))
    return t, (a[0] + t * dx, a[1] + t * dy)


def remaining_distance(robot: Point, goal: Point, plan: Sequence[Point] | None = None) -> float:
    """Distance (m) the robot still has to drive to reach ``goal``.

    With a global plan: the gap from the robot to the closest point of the plan
    plus the plan's length from there to its end, plus the gap from the plan's
    end to the goal (planners may stop a cell short).  Without a plan (or a
    one-point plan) the straight line, which is the best lower bound we have.
    """
    if not plan or len(plan) < 2:
        return distance(robot, goal)
    best_i, best_pt, best_d = 0, plan[0], math.inf
    for i in range(len(plan) - 1):
        _, pt = _project(robot, plan[i], plan[i + 1])
        d = distance(robot, pt)
        if d < best_d:
            best_i, best_pt, best_d = i, pt, d
    rest = distance(best_pt, plan[best_i + 1]) + path_length(plan[best_i + 1:])
    return best_d + rest + distance(plan[-1], goal)


def eta_seconds(remaining_m: float, speed_mps: float) -> float:
    """Time (s) to drive ``remaining_m`` at ``speed_mps``; infinite when not moving."""
    if speed_mps <= 0.0:
        return math.inf
    return remaining_m / speed_mps


def nearest_index(origin: Point, candidates: Sequence[Point]) -> int:
    """Index of the candidate closest to ``origin`` (first one on ties); -1 when empty."""
    best, best_d = -1, math.inf
    for i, c in enumerate(candidates):
        d = distance(origin, c)
        if d < best_d:
            best, best_d = i, d
    return best


def grid_to_grey(data: Sequence[int], width: int, height: int) -> bytes:
    """Grey-level image bytes (row-major, top row first) of OccupancyGrid ``data``.

    Free (0) is white, occupied (100) black, unknown (-1) mid grey, values in
    between shaded linearly, like RViz's "map" colour scheme.
    """
    if len(data) != width * height:
        raise ValueError(f"grid data has {len(data)} cells, expected {width}×{height}")
    lut = bytearray(256)
    for v in range(256):
        signed = v - 256 if v > 127 else v
        if signed < 0 or signed > 100:
            lut[v] = 160
        else:
            lut[v] = 255 - round(signed * 255 / 100)
    raw = bytes(b & 0xFF for b in data) if not isinstance(data, (bytes, bytearray)) else bytes(data)
    grey = raw.translate(bytes(lut))
    # flip rows: the grid's row 0 is at the bottom (lowest y)
    return b"".join(grey[r * width:(r + 1) * width] for r in range(height - 1, -1, -1))
