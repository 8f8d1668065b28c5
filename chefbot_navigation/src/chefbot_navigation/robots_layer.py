"""The other robots of a fleet as costs (pure numpy/OpenCV): footprints lethal, their path ahead a cost.

Every robot of a site publishes its own ``chefbot_msgs/RobotState`` (pose, footprint, velocity,
remaining global plan) on the site's shared topic ``/fleet/robots``; move_base keeps the latest
state of every *other* robot and this layer turns them into cells of its costmap:

* **footprint**: the robot's polygon at its pose, moved along its velocity for the age of the
  state (at most ``max_extrapolation`` s) and grown by ``footprint_padding``: *lethal*, so the
  inflation keeps our robot clear of it as of any obstacle, and the planner routes around a robot
  that no sensor of ours sees yet (round a corner, nearer than the camera's 0.45 m minimum range,
  below the scan's slice);
* **path**: the first ``path_horizon`` m of its remaining global plan, as wide as its footprint's
  circumscribed circle: cost ``path_cost`` (below inscribed), so the planner prefers another way
  but may still cross it;
* **stale**: a robot not heard from for ``timeout`` s is dropped, so a robot whose stack died leaves
  no ghost behind (its body is still seen by our sensors, as any obstacle).

The layer is rebuilt from the current states at every :meth:`RobotsLayer.refresh` (nothing
accumulates); the costmap (:class:`chefbot_navigation.costmap.LayeredCostmap`) adds :attr:`grid` to
its lethal cells and :attr:`cost` after the inflation.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import cv2
import numpy as np

from chefbot_common.grid import GridInfo
from chefbot_navigation.footprint import Footprint, circle_footprint, polygon_footprint

#: sub-cell precision of OpenCV's path drawing (coordinates in 1/16 cell)
_SHIFT = 4


@dataclass(frozen=True)
class RobotsLayerParams:
    """Settings of the other-robots source; ``move_base`` reads them from ``~robots_layer/<name>``."""

    enabled: bool = True                # read the other robots' states (harmless alone: nobody publishes)
    topic: str = "/fleet/robots"        # chefbot_msgs/RobotState, one publisher per robot, shared by the site
    own_name: str = ""                  # this robot's name on that topic ('' = move_base's namespace)
    timeout: float = 2.0                # s without a state after which a robot is dropped
    footprint_padding: float = 0.05     # m around another robot's footprint (both robots' localization error)
    max_extrapolation: float = 0.5      # s: a state's pose is moved along its velocity for at most this long
    path_horizon: float = 2.0           # m of another robot's remaining path that get path_cost (0 = none)
    path_cost: int = 100                # cost (1..252) of a cell on another robot's path ahead

    def __post_init__(self) -> None:
        if not self.topic:
            raise ValueError("topic must not be empty")
        if not self.timeout > 0.0:
            raise ValueError(f"timeout must be > 0 s, got {self.timeout}")
        if not self.footprint_padding >= 0.0:
            raise ValueError(f"footprint_padding must be >= 0 m, got {self.footprint_padding}")
        if not self.max_extrapolation >= 0.0:
            raise ValueError(f"max_extrapolation must be >= 0 s, got {self.max_extrapolation}")
        if not self.path_horizon >= 0.0:
            raise ValueError(f"path_horizon must be >= 0 m, got {self.path_horizon}")
        if not 1 <= self.path_cost <= 252:
            raise ValueError(f"path_cost must be in 1..252, got {self.path_cost}")


@dataclass
class OtherRobot:
    """One robot's latest state (map frame, m, rad, s): what the layer draws."""

    name: str
    stamp: float                        # time the pose holds
    x: float
    y: float
    yaw: float
    v: float = 0.0                      # m/s forward
    w: float = 0.0                      # rad/s
    footprint: np.ndarray = field(default_factory=lambda: np.zeros((0, 2)))   # (K, 2) base frame; K = 0: circle
    radius: float = 0.0                 # m, circumscribed radius (the circle when there is no polygon)
    path: np.ndarray = field(default_factory=lambda: np.zeros((0, 2)))        # (M, 2) remaining plan, nearest first

    def check(self) -> None:
        """ValueError naming what is unusable (non-finite values, a footprint of 1-2 points, no shape)."""
        if not self.name:
            raise ValueError("a robot state without a name")
        vals = (self.stamp, self.x, self.y, self.yaw, self.v, self.w, self.radius)
        if not all(math.isfinite(v) for v in vals):
            raise ValueError(f"robot '{self.name}': non-finite pose, velocity, stamp or radius")
        fp = np.asarray(self.footprint, dtype=float).reshape(-1, 2)
        if fp.shape[0] == 0 and not self.radius > 0.0:
            raise ValueError(f"robot '{self.name}': neither a footprint polygon nor a footprint_radius > 0")
        if 0 < fp.shape[0] < 3 or not np.isfinite(fp).all():
            raise ValueError(f"robot '{self.name}': footprint needs >= 3 finite points, got {fp.shape[0]}")
        if not np.isfinite(np.asarray(self.path, dtype=float)).all():
            raise ValueError(f"robot '{self.name}': non-finite path point")

    def pose_at(self, t: float, max_extrapolation: float) -> tuple[float, float, float]:
        """The pose at time ``t``: moved along (v, w) for the state's age, at most ``max_extrapolation`` s
        (never backwards)."""
        dt = min(max(t - self.stamp, 0.0), max_extrapolation)
        if abs(self.w) < 1e-6:
            return (self.x + self.v * dt * math.cos(self.yaw), self.y + self.v * dt * math.sin(self.yaw), self.yaw)
        yaw = self.yaw + self.w * dt
        r = self.v / self.w
        return (self.x + r * (math.sin(yaw) - math.sin(self.yaw)),
                self.y - r * (math.cos(yaw) - math.cos(self.yaw)), yaw)


class RobotsLayer:
    """The other robots' cells over a map's grid: :meth:`update` with states, :meth:`refresh` to draw.

    :attr:`grid` (bool) marks the padded footprints (lethal), :attr:`cost` (uint8, 0 = nothing) the
    path costs; both in the map's row order.
    """

    def __init__(self, info: GridInfo, params: RobotsLayerParams, own_name: str = "") -> None:
        self.info, self.params, self.own_name = info, params, own_name
        self.robots: dict[str, OtherRobot] = {}
        self.grid = np.zeros((info.height, info.width), dtype=bool)
        self.cost = np.zeros((info.height, info.width), dtype=np.uint8)
        self._shapes: dict[str, Footprint] = {}     # padded footprint per robot (it changes rarely)

    def update(self, robot: OtherRobot) -> bool:
        """Keep ``robot``'s state (the newest per name); False for this robot's own state or an older
        one.  ValueError (naming the robot) for an unusable state, which is not kept."""
        if robot.name == self.own_name:
            return False
        robot.check()
        old = self.robots.get(robot.name)
        if old is not None and robot.stamp < old.stamp:
            return False
        fp = np.asarray(robot.footprint, dtype=float).reshape(-1, 2)
        same_shape = old is not None and old.radius == robot.radius and np.array_equal(old.footprint, fp)
        if not same_shape or robot.name not in self._shapes:
            pad = self.params.footprint_padding
            self._shapes[robot.name] = polygon_footprint(fp, pad) if fp.shape[0] else \
                circle_footprint(robot.radius + pad)
        robot.footprint = fp
        self.robots[robot.name] = robot
        return True

    def forget(self, name: str) -> None:
        """Drop one robot (e.g. its publisher went away)."""
        self.robots.pop(name, None)
        self._shapes.pop(name, None)

    def refresh(self, now: float) -> list[str]:
        """Drop the robots not heard from for ``timeout`` s (returns their names) and redraw the others
        at their poses extrapolated to ``now``."""
        p = self.params
        stale = [n for n, r in self.robots.items() if now - r.stamp > p.timeout]
        for name in stale:
            self.forget(name)
        self.grid[:] = False
        self.cost[:] = 0
        if not self.robots:
            return stale
        path = np.zeros(self.grid.shape, dtype=np.uint8)
        for name, r in self.robots.items():
            x, y, yaw = r.pose_at(now, p.max_extrapolation)
            shape = self._shapes[name]
            self._fill(shape, x, y, yaw)
            ahead = clip_length(np.vstack(([[x, y]], np.asarray(r.path, dtype=float).reshape(-1, 2))),
                                 p.path_horizon)
            if len(ahead) >= 2:
                width = 2.0 * max(r.radius, shape.circumscribed_radius - p.footprint_padding)
                thick = max(1, int(round(width / self.info.resolution)))
                cv2.polylines(path, [self._pixels(ahead)], False, 1, thickness=thick, lineType=cv2.LINE_8,
                              shift=_SHIFT)
        self.cost[(path != 0) & ~self.grid] = p.path_cost
        return stale

    def _fill(self, shape: Footprint, x: float, y: float, yaw: float) -> None:
        """Mark the cells whose centre lies inside ``shape`` placed at (x, y, yaw)."""
        info, rad = self.info, shape.circumscribed_radius
        r0, c0 = (int(v) for v in info.world_to_cell(x - rad, y - rad))
        r1, c1 = (int(v) + 1 for v in info.world_to_cell(x + rad, y + rad))
        r0, c0, r1, c1 = max(r0, 0), max(c0, 0), min(r1, info.height), min(c1, info.width)
        if r0 >= r1 or c0 >= c1:
            return
        rows, cols = np.mgrid[r0:r1, c0:c1]
        cx, cy = info.cell_to_world(rows.ravel(), cols.ravel())
        c, s = math.cos(yaw), math.sin(yaw)
        dx, dy = cx - x, cy - y
        inside = shape.contains(np.column_stack((c * dx + s * dy, -s * dx + c * dy)))
        self.grid[r0:r1, c0:c1] |= inside.reshape(rows.shape)

    def _pixels(self, pts: np.ndarray) -> np.ndarray:
        """World points (K, 2) m as OpenCV's fixed-point pixel coordinates (pixel centre = cell centre)."""
        res = self.info.resolution
        u = (pts[:, 0] - self.info.origin_x) / res - 0.5
        v = (pts[:, 1] - self.info.origin_y) / res - 0.5
        # far-off points would overflow OpenCV's int32 fixed-point coordinates
        lim = 4.0 * (max(self.info.width, self.info.height) + 16)
        uv = np.clip(np.column_stack((u, v)), -lim, lim)
        return np.round(uv * (1 << _SHIFT)).astype(np.int32).reshape(-1, 1, 2)


def from_nearest(pts: np.ndarray, x: float, y: float) -> np.ndarray:
    """The polyline ``pts`` (K, 2) from its point nearest to (x, y) on: what a robot there still has to
    drive.  The whole line is searched, so a path that passes the robot twice (a loop) is cut at the
    nearer pass."""
    pts = np.asarray(pts, dtype=float).reshape(-1, 2)
    if len(pts) == 0:
        return pts
    return pts[int(np.argmin(np.hypot(pts[:, 0] - x, pts[:, 1] - y))):]


def clip_length(pts: np.ndarray, length: float) -> np.ndarray:
    """The first ``length`` m of the polyline ``pts`` (K, 2), the last segment cut where it reaches it."""
    if len(pts) < 2 or length <= 0.0:
        return pts[:1] if length <= 0.0 else pts
    seg = np.hypot(*np.diff(pts, axis=0).T)
    cum = np.concatenate(([0.0], np.cumsum(seg)))
    if cum[-1] <= length:
        return pts
    k = int(np.searchsorted(cum, length, side="right"))   # cum[k-1] <= length < cum[k]
    f = (length - cum[k - 1]) / seg[k - 1] if seg[k - 1] > 0 else 0.0
    end = pts[k - 1] + f * (pts[k] - pts[k - 1])
    return np.vstack((pts[:k], end[None, :]))
