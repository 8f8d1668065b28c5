"""Pure helpers of the GUI demo world (``nodes/gui_demo_world``): a stand-in for the
map server and move_base so the GUI can be tried, screenshotted and demonstrated
without the simulator.  No ROS, no Qt.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

from chefbot_common import map_io
from chefbot_gui.geometry import Point, distance


@dataclass(frozen=True)
class MapFile:
    """A ``map_server`` map: cells row-major from the *bottom* row, values -1/0/100."""

    resolution: float
    origin: tuple[float, float, float]
    width: int
    height: int
    data: list[int]


def load_map(yaml_path: str | Path) -> MapFile:
    """Read a map_server YAML + image (the map server's reader) into occupancy values.

    Raises :class:`chefbot_common.map_io.MapError` (a ValueError) naming the file and field.
    """
    occ = map_io.load_map(yaml_path)
    info = occ.info
    return MapFile(info.resolution, (info.origin_x, info.origin_y, info.origin_yaw), info.width, info.height,
                   occ.data.ravel().tolist())


def aisle_route(start: Point, goal: Point, aisle_offset: float = 1.5) -> list[Point]:
    """A plausible route in the hotel's table grid: up/down to the aisle beside the
    goal's row, along it, then into the goal.  Good enough to draw; not a planner."""
    sign = -1.0 if goal[1] > start[1] else 1.0
    aisle_y = goal[1] + sign * aisle_offset if abs(goal[1] - start[1]) > 1e-6 else goal[1]
    pts = [start, (start[0], aisle_y), (goal[0], aisle_y), goal]
    out: list[Point] = [pts[0]]
    for p in pts[1:]:
        if distance(out[-1], p) > 1e-6:
            out.append(p)
    return out


def point_along(route: list[Point], s: float) -> tuple[float, float, float]:
    """Pose (x, y, heading) at arc length ``s`` (m) along a polyline, clamped to its ends."""
    for a, b in zip(route, route[1:], strict=False):
        seg = distance(a, b)
        heading = math.atan2(b[1] - a[1], b[0] - a[0])
        if s <= seg:
            t = s / seg if seg else 1.0
            return a[0] + t * (b[0] - a[0]), a[1] + t * (b[1] - a[1]), heading
        s -= seg
    if len(route) >= 2:
        a, b = route[-2], route[-1]
        return b[0], b[1], math.atan2(b[1] - a[1], b[0] - a[0])
    return route[0][0], route[0][1], 0.0
