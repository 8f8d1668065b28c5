"""Layered 2-D costmap: static map + scan obstacles (ray-traced) + inflation (pure numpy/OpenCV).

Cost values follow ROS costmap_2d: 0 free, 1..252 inflated (decaying with
distance), 253 inscribed (the robot's centre here means a collision), 254
lethal (an obstacle cell), 255 unknown.  The published OccupancyGrid uses
costmap_2d's translation (0 -> 0, 1..252 -> 1..98, 253 -> 99, 254 -> 100,
255 -> -1).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import cv2
import numpy as np

from chefbot_common.geometry import Pose2D
from chefbot_common.grid import GridInfo, OccupancyMap

FREE_SPACE = 0
INSCRIBED = 253
LETHAL = 254
NO_INFORMATION = 255
#: another robot's cells when the planner may plan through it (:meth:`LayeredCostmap.master`)
ROBOT_COST = 252


@dataclass(frozen=True)
class CostmapParams:
    """Costmap tunables (names as costmap_2d's where the meaning matches)."""

    robot_radius: float = 0.20          # m, inscribed radius; replaced by the footprint's when there is one
    circumscribed_radius: float = 0.0   # m, 0 = robot_radius (round robot); set from the footprint
    footprint: str = "urdf"             # urdf (robot_description) | radius (round, robot_radius) | [[x, y], ...]
    footprint_padding: float = 0.01     # m added around the footprint polygon
    inflation_radius: float = 0.55      # m, cost decays to 0 beyond this distance from an obstacle
    cost_scaling_factor: float = 5.0    # 1/m, exponential decay rate of the inflated cost
    obstacle_range: float = 2.5         # m, scan returns farther than this are not marked
    raytrace_range: float = 3.0         # m, free space is cleared up to this range
    lethal_threshold: int = 65          # static map value (0..100) at or above which a cell is lethal
    track_unknown_space: bool = True    # unknown static cells stay unknown (else free)
    nan_is_free: bool = False           # treat NaN ranges as "nothing within raytrace_range"

    def __post_init__(self) -> None:
        if not self.robot_radius > 0.0:
            raise ValueError(f"robot_radius must be > 0 m, got {self.robot_radius}")
        if self.circumscribed_radius and self.circumscribed_radius < self.robot_radius:
            raise ValueError(f"circumscribed_radius ({self.circumscribed_radius}) must be >= robot_radius "
                             f"({self.robot_radius})")
        if self.footprint_padding < 0.0:
            raise ValueError(f"footprint_padding must be >= 0 m, got {self.footprint_padding}")
        if not self.inflation_radius >= self.robot_radius:
            raise ValueError(f"inflation_radius ({self.inflation_radius}) must be >= robot_radius "
                             f"({self.robot_radius})")
        if not self.cost_scaling_factor > 0.0:
            raise ValueError(f"cost_scaling_factor must be > 0, got {self.cost_scaling_factor}")
        if not (self.obstacle_range > 0.0 and self.raytrace_range > 0.0):
            raise ValueError("obstacle_range and raytrace_range must be > 0 m")
        if not 1 <= self.lethal_threshold <= 100:
            raise ValueError(f"lethal_threshold must be in 1..100, got {self.lethal_threshold}")


@dataclass
class Costmap:
    """A grid of costmap_2d costs (uint8, OccupancyGrid row order) with its geometry."""

    info: GridInfo
    cost: np.ndarray

    def cost_at(self, x: np.ndarray | float, y: np.ndarray | float, outside: int = NO_INFORMATION) -> np.ndarray:
        """Costs at world points (m); ``outside`` for points off the grid."""
        row, col = self.info.world_to_cell(x, y)
        inside = self.info.inside(row, col)
        out = np.full(np.shape(row), outside, dtype=np.uint8)
        out[inside] = self.cost[row[inside], col[inside]]
        return out

    def to_occupancy(self) -> OccupancyMap:
        """OccupancyGrid values (costmap_2d's translation table)."""
        return OccupancyMap(self.info, _TRANSLATION[self.cost])


def _translation_table() -> np.ndarray:
    table = np.zeros(256, dtype=np.int8)
    i = np.arange(1, 253)
    table[1:253] = 1 + (97 * (i - 1)) // 251
    table[INSCRIBED], table[LETHAL], table[NO_INFORMATION] = 99, 100, -1
    return table


_TRANSLATION = _translation_table()


def inflate(base: np.ndarray, resolution: float, params: CostmapParams) -> np.ndarray:
    """Inflate lethal cells of ``base`` (uint8 costs) by the robot radius with exponential decay.

    Cost at distance d (m) from the nearest lethal cell centre: 253 for
    d <= robot_radius, 252 * exp(-cost_scaling_factor * (d - robot_radius))
    up to inflation_radius, else unchanged.  Unknown cells become 253 only
    when within the robot radius (as costmap_2d with inflate_unknown off).
    """
    lethal = base == LETHAL
    if not lethal.any():
        return base.copy()
    # distance of every cell to the nearest lethal cell, exact Euclidean (OpenCV, vectorised)
    dist = cv2.distanceTransform((~lethal).astype(np.uint8), cv2.DIST_L2, cv2.DIST_MASK_PRECISE) * resolution
    inflated = np.zeros(base.shape, dtype=np.uint8)
    decay = dist <= params.inflation_radius
    vals = 252.0 * np.exp(-params.cost_scaling_factor * (dist[decay] - params.robot_radius))
    inflated[decay] = np.minimum(vals, 252.0).astype(np.uint8)
    inflated[dist <= params.robot_radius] = INSCRIBED
    out = base.copy()
    unknown = base == NO_INFORMATION
    known = ~unknown & ~lethal
    out[known] = np.maximum(base[known], inflated[known])
    out[unknown & (inflated == INSCRIBED)] = INSCRIBED
    return out


class LayeredCostmap:
    """Static layer from a map, an obstacle layer from scans, inflation on demand.

    Not thread-safe: the node serialises access.
    """

    def __init__(self, occ: OccupancyMap, params: CostmapParams) -> None:
        self.params = params
        self.info = occ.info
        static = np.zeros(occ.data.shape, dtype=np.uint8)
        data = occ.data.astype(np.int16)
        static[data >= params.lethal_threshold] = LETHAL
        if params.track_unknown_space:
            static[data < 0] = NO_INFORMATION
        self.static = static
        self.obstacles = np.zeros(occ.data.shape, dtype=bool)
        # cells a scan ray has passed through: an unknown static cell among them counts as free (as
        # costmap_2d's obstacle layer writes FREE over the static layer's unknown; a SLAM map's small
        # unseen holes in an aisle would otherwise block the footprint check for good)
        self.seen_free = np.zeros(occ.data.shape, dtype=bool)
        # 3-D obstacles of the point-cloud source (pointcloud_layer.PointCloudLayer, set by move_base):
        # kept apart from the scan's marks so that scan rays passing under a table top do not clear it
        self.cloud_layer = None
        # the other robots of a fleet (robots_layer.RobotsLayer, set by move_base): footprints lethal,
        # their paths ahead a cost added after the inflation; rebuilt from their states, never cleared here
        self.robots_layer = None
        self._master: np.ndarray | None = None

    def _marks(self) -> np.ndarray:
        """What the sensors marked (scan and point cloud)."""
        return self.obstacles if self.cloud_layer is None else self.obstacles | self.cloud_layer.grid

    def _all_obstacles(self) -> np.ndarray:
        marks = self._marks()
        return marks if self.robots_layer is None else marks | self.robots_layer.grid

    def has_marks(self) -> bool:
        """Has any sensor (scan or point cloud) marked an obstacle?"""
        return bool(self._marks().any())

    def robots_in_view(self) -> bool:
        """Does the robots layer mark any other robot?"""
        return self.robots_layer is not None and bool(self.robots_layer.grid.any())

    def robot_near(self, x: float, y: float, radius: float) -> bool:
        """Does the robots layer mark another robot's footprint within ``radius`` m of (x, y)?"""
        if self.robots_layer is None:
            return False
        info = self.info
        r, c = (int(v) for v in info.world_to_cell(x, y))
        n = int(math.ceil(radius / info.resolution))
        r0, r1, c0, c1 = max(r - n, 0), min(r + n + 1, info.height), max(c - n, 0), min(c + n + 1, info.width)
        if r0 >= r1 or c0 >= c1:
            return False
        rows, cols = np.nonzero(self.robots_layer.grid[r0:r1, c0:c1])
        return bool(len(rows)) and bool(np.any(np.hypot(rows + r0 - r, cols + c0 - c) * info.resolution <= radius))

    def _with_paths(self, cost: np.ndarray, rows: slice, cols: slice) -> np.ndarray:
        """``cost`` (inflated, the grid's ``[rows, cols]``) raised to the other robots' path costs where
        it is below inscribed."""
        if self.robots_layer is not None:
            paths = self.robots_layer.cost[rows, cols]
            raise_ = (paths > cost) & (cost < INSCRIBED)
            cost[raise_] = paths[raise_]
        return cost

    def layers_changed(self) -> None:
        """An obstacle source changed its marks outside update_scan (the point-cloud layer)."""
        self._master = None

    # --- obstacle layer -------------------------------------------------------------------------
    def clear_obstacles(self) -> None:
        """Forget every scan obstacle and every cell seen free (recovery 'clear costmaps'; the other
        robots' layer stays: it is rebuilt from their states)."""
        self.obstacles[:] = False
        self.seen_free[:] = False
        if self.cloud_layer is not None:
            self.cloud_layer.clear()
        self._master = None

    def update_scan(self, sensor: Pose2D, ranges: np.ndarray, angle_min: float, angle_increment: float,
                    range_min: float, range_max: float) -> None:
        """Clear along every ray and mark its end point (sensor pose in the map frame, m/rad).

        REP 117: +inf = nothing within range_max (clear up to
        min(range_max, raytrace_range), no mark); NaN and values below range_min
        are ignored (unless ``nan_is_free``); finite values beyond range_max are
        treated like +inf.
        """
        p = self.params
        r = np.asarray(ranges, dtype=float).ravel()
        angles = sensor.yaw + angle_min + angle_increment * np.arange(r.size)
        nan = np.isnan(r)
        no_return = np.isposinf(r) | (np.isfinite(r) & (r > range_max)) | (nan & p.nan_is_free)
        valid = np.isfinite(r) & (r >= range_min) & (r <= range_max)
        clear_len = np.where(no_return, min(range_max, p.raytrace_range),
                             np.where(valid, np.minimum(r, p.raytrace_range), 0.0))
        res = self.info.resolution
        step = 0.5 * res
        n = int(math.ceil(float(clear_len.max(initial=0.0)) / step))
        if n > 0:
            t = np.arange(n) * step
            # stop half a cell short of the hit so the end point's own cell is not cleared
            keep = t[None, :] < (clear_len[:, None] - step)
            xs = sensor.x + np.cos(angles)[:, None] * t[None, :]
            ys = sensor.y + np.sin(angles)[:, None] * t[None, :]
            row, col = self.info.world_to_cell(xs[keep], ys[keep])
            inside = self.info.inside(row, col)
            self.obstacles[row[inside], col[inside]] = False
            self.seen_free[row[inside], col[inside]] = True
        mark = valid & (r <= p.obstacle_range)
        if mark.any():
            hx = sensor.x + np.cos(angles[mark]) * r[mark]
            hy = sensor.y + np.sin(angles[mark]) * r[mark]
            row, col = self.info.world_to_cell(hx, hy)
            inside = self.info.inside(row, col)
            self.obstacles[row[inside], col[inside]] = True
        self._master = None

    def mark_points(self, xs: np.ndarray, ys: np.ndarray) -> None:
        """Mark world points (m) as obstacles (tests and external sensors)."""
        row, col = self.info.world_to_cell(xs, ys)
        inside = self.info.inside(row, col)
        self.obstacles[row[inside], col[inside]] = True
        self._master = None

    # --- combined -------------------------------------------------------------------------------
    def base(self) -> np.ndarray:
        """Static layer with scan obstacles and the unknown cells scans saw free, before inflation."""
        return self._sensed(self.static.copy(), slice(None), slice(None))

    def _sensed(self, static: np.ndarray, rows: slice, cols: slice) -> np.ndarray:
        """``static`` (the static layer's ``[rows, cols]``) with what the sensors saw: unknown cells a
        ray passed through become free, obstacle cells lethal."""
        static[(static == NO_INFORMATION) & self.seen_free[rows, cols]] = FREE_SPACE
        static[self._all_obstacles()[rows, cols]] = LETHAL
        return static

    def master(self, robots_as_cost: bool = False) -> Costmap:
        """The inflated global costmap (cached until the layers change).

        ``robots_as_cost``: the other robots (the robots layer's footprints, and what the sensors
        marked on and right around them) are not obstacles but cells of cost :data:`ROBOT_COST`: the
        way *through* a robot, for when it is the only way (the robot will drive on, or the traffic
        rule make it give way); not cached."""
        if robots_as_cost and self.robots_in_view():
            robots = cv2.dilate(self.robots_layer.grid.astype(np.uint8), np.ones((3, 3), np.uint8)) != 0
            base = self.static.copy()
            base[(base == NO_INFORMATION) & self.seen_free] = FREE_SPACE
            base[self._marks() & ~robots] = LETHAL
            cost = self._with_paths(inflate(base, self.info.resolution, self.params), slice(None), slice(None))
            cost[robots & (cost < ROBOT_COST)] = ROBOT_COST
            return Costmap(self.info, cost)
        if self._master is None:
            self._master = self._with_paths(inflate(self.base(), self.info.resolution, self.params),
                                            slice(None), slice(None))
        return Costmap(self.info, self._master)

    def window(self, cx: float, cy: float, width: float, height: float, static_only: bool = False) -> Costmap:
        """Rolling window (m) centred at (cx, cy), inflated locally (cells off the map are unknown).

        Only a window plus the inflation radius is inflated, so the cost per
        controller cycle does not grow with the map.  ``static_only``: the map
        alone, without what the sensors marked.
        """
        res = self.info.resolution
        w, h = int(round(width / res)), int(round(height / res))
        margin = int(math.ceil(self.params.inflation_radius / res)) + 1
        r0, c0 = self.info.world_to_cell(cx - 0.5 * width, cy - 0.5 * height)
        r0, c0 = int(r0), int(c0)
        # padded window, filled from the map where they overlap
        pr0, pc0 = r0 - margin, c0 - margin
        ph, pw = h + 2 * margin, w + 2 * margin
        pad = np.full((ph, pw), NO_INFORMATION, dtype=np.uint8)
        sr0, sr1 = max(pr0, 0), min(pr0 + ph, self.info.height)
        sc0, sc1 = max(pc0, 0), min(pc0 + pw, self.info.width)
        if sr0 < sr1 and sc0 < sc1:
            static = self.static[sr0:sr1, sc0:sc1].copy()
            if not static_only:
                static = self._sensed(static, slice(sr0, sr1), slice(sc0, sc1))
            pad[sr0 - pr0:sr1 - pr0, sc0 - pc0:sc1 - pc0] = static
        cost = inflate(pad, res, self.params)
        if not static_only and sr0 < sr1 and sc0 < sc1:
            cost[sr0 - pr0:sr1 - pr0, sc0 - pc0:sc1 - pc0] = self._with_paths(
                cost[sr0 - pr0:sr1 - pr0, sc0 - pc0:sc1 - pc0], slice(sr0, sr1), slice(sc0, sc1))
        cost = cost[margin:margin + h, margin:margin + w]
        ox = self.info.origin_x + c0 * res
        oy = self.info.origin_y + r0 * res
        return Costmap(GridInfo(res, w, h, ox, oy, 0.0), np.ascontiguousarray(cost))
