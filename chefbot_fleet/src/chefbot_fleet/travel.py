"""Seconds and metres between the places of a site, over planned paths (pure; no rospy).

The dispatcher plans with :class:`Places`: named poses (tables, the kitchen, each robot's parking
pose and charger, and each robot's last known pose), and a ``route(a, b)`` function giving
(seconds, metres) from one pose to another.  :func:`map_route` makes that function from a map: the
global planner's path on the inflated costmap, timed by the time-optimal profile of the robot's
limits (``chefbot_navigation.time_limit.profile_limit``, the profile a delivery leg is judged by).
Routes between fixed places are computed once; a place that moves (a robot's pose) forgets its own.
A pair with no path costs :data:`UNREACHABLE` seconds, so the planner sends nothing there while a
reachable choice exists.
"""
from __future__ import annotations

import math
from collections.abc import Callable

from chefbot_common.geometry import Pose2D, wrap_angle

UNREACHABLE = 1.0e6     # s (and m) between places with no path: larger than any real trip, still finite


class Places:
    """Named poses and the (seconds, metres) between them, remembered (module docstring)."""

    def __init__(self, poses: dict[str, Pose2D], route: Callable[[Pose2D, Pose2D], tuple[float, float]]) -> None:
        self._poses = dict(poses)
        self._route = route
        self._memo: dict[tuple[str, str], tuple[float, float]] = {}

    def __contains__(self, name: str) -> bool:
        return name in self._poses

    def pose(self, name: str) -> Pose2D:
        """The pose of ``name`` (KeyError names the known places)."""
        try:
            return self._poses[name]
        except KeyError:
            raise KeyError(f"no place {name!r} (places: {', '.join(sorted(self._poses))})") from None

    def set(self, name: str, pose: Pose2D) -> None:
        """Add or move the place ``name``; the routes from and to it are planned again when asked."""
        old = self._poses.get(name)
        if old == pose:
            return
        self._poses[name] = pose
        if old is not None:
            self._memo = {k: v for k, v in self._memo.items() if name not in k}

    def _get(self, a: str, b: str) -> tuple[float, float]:
        if a == b:
            return 0.0, 0.0
        if (a, b) not in self._memo:
            s, m = self._route(self.pose(a), self.pose(b))
            if not (math.isfinite(s) and math.isfinite(m)):
                s, m = UNREACHABLE, UNREACHABLE
            self._memo[a, b] = (float(s), float(m))
        return self._memo[a, b]

    def travel(self, a: str, b: str) -> float:
        """Seconds from place ``a`` to place ``b``."""
        return self._get(a, b)[0]

    def distance(self, a: str, b: str) -> float:
        """Metres from place ``a`` to place ``b`` along the route."""
        return self._get(a, b)[1]


def straight_route(speed: float, turn_rate: float = 0.0) -> Callable[[Pose2D, Pose2D], tuple[float, float]]:
    """Straight lines at ``speed`` m/s (plus turning on the spot at ``turn_rate`` rad/s when > 0):
    for tests and for a site without a map."""
    if not speed > 0:
        raise ValueError(f"speed must be > 0, got {speed}")

    def route(a: Pose2D, b: Pose2D) -> tuple[float, float]:
        d = math.hypot(b.x - a.x, b.y - a.y)
        turn = 0.0
        if turn_rate > 0:
            heading = math.atan2(b.y - a.y, b.x - a.x) if d > 1e-9 else a.yaw
            turn = (abs(wrap_angle(heading - a.yaw)) + abs(wrap_angle(b.yaw - heading))) / turn_rate
        return d / speed + turn, d
    return route


def map_route(grid, planner_name: str = "dijkstra", robot_radius: float = 0.2,
              limits=None) -> Callable[[Pose2D, Pose2D], tuple[float, float]]:
    """(seconds, metres) over the global planner's path on ``grid`` (a ``chefbot_common.map_io``
    occupancy grid) inflated as move_base's costmap with default parameters; seconds by the
    time-optimal profile of ``limits`` (default: the robot's).  A pair with no path gives ``inf``."""
    import numpy as np

    from chefbot_navigation.costmap import CostmapParams, LayeredCostmap
    from chefbot_navigation.planners import PlannerParams, PlanningError, make_planner
    from chefbot_navigation.time_limit import MotionLimits, path_length, profile_limit

    costmap = LayeredCostmap(grid, CostmapParams()).master()
    planner = make_planner(planner_name, PlannerParams(), robot_radius)
    lim = limits or MotionLimits()

    def route(a: Pose2D, b: Pose2D) -> tuple[float, float]:
        try:
            pts = np.asarray(planner.plan(costmap, (a.x, a.y), (b.x, b.y)).points, dtype=float)
        except PlanningError:
            return math.inf, math.inf
        if len(pts) < 2:
            pts = np.array([[a.x, a.y], [b.x, b.y]])
        return float(profile_limit(pts, lim, a.yaw, b.yaw)), float(path_length(pts))
    return route
