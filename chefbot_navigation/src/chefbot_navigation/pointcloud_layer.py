"""Obstacles from a depth camera's point cloud in a height band (pure numpy; costmap_2d's voxel layer idea).

The laser scan from ``depth_to_scan`` is a thin slice at the camera's height
(0.26 m): a table top, a chair seat or a tray overhanging above or below that
slice is invisible to it, and the robot clips it.  This layer marks every
cloud point whose height is inside ``[min_obstacle_height, max_obstacle_height]``
(floor + 0.03 m ... robot top + 0.05 m) and clears along the rays to all points
in **3-D**: it keeps a coarse voxel column per map cell, so a ray passing
*under* a table top (the scan's own rays do exactly that) does not erase the
top.  The 2-D projection (:attr:`PointCloudLayer.grid`: any marked voxel in
the column) is what the costmap adds as lethal cells.

Cost control: the cloud is voxel-filtered first (one ray per occupied voxel,
``np.unique`` on integer voxel keys), voxels need ``min_voxel_points`` points
to mark (speckle), rays are sampled every ``voxel_size`` / 2 and only within
``raytrace_range``.  Figures: chefbot_vision/bench (cost per cloud).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from chefbot_common.grid import GridInfo


@dataclass(frozen=True)
class CloudLayerParams:
    """Point-cloud obstacle source settings (m unless stated); ``move_base`` reads them from
    ``~pointcloud_layer/<name>``."""

    enabled: bool = True
    topic: str = "camera/depth/points"   # sensor_msgs/PointCloud2 (XYZ in any frame tf knows)
    min_obstacle_height: float = 0.03    # m above the floor: lower points are floor (clear only)
    max_obstacle_height: float = 0.43    # m: robot top (0.38) + 0.05; higher points pass over the robot
    voxel_size: float = 0.05             # m, vertical voxel size (horizontal: the map resolution)
    obstacle_range: float = 2.5          # m, horizontal distance up to which points mark
    raytrace_range: float = 3.0          # m, rays clear up to this horizontal distance
    min_voxel_points: int = 2            # points a voxel needs to be marked (depth speckle)
    decimation: int = 2                  # keep every n-th row and column of an organised cloud
    transform_tolerance: float = 0.3     # s to wait for the cloud's tf

    def __post_init__(self) -> None:
        if not 0.0 <= self.min_obstacle_height < self.max_obstacle_height:
            raise ValueError(f"need 0 <= min_obstacle_height ({self.min_obstacle_height}) < "
                             f"max_obstacle_height ({self.max_obstacle_height})")
        if not self.voxel_size > 0:
            raise ValueError(f"voxel_size must be > 0 m, got {self.voxel_size}")
        if not (self.obstacle_range > 0 and self.raytrace_range > 0):
            raise ValueError("obstacle_range and raytrace_range must be > 0 m")
        if self.min_voxel_points < 1 or self.decimation < 1:
            raise ValueError("min_voxel_points and decimation must be >= 1")
        if not self.topic:
            raise ValueError("topic must not be empty")
        if not self.transform_tolerance >= 0:
            raise ValueError(f"transform_tolerance must be >= 0 s, got {self.transform_tolerance}")


class PointCloudLayer:
    """Voxel columns over a map's grid; :meth:`update` with map-frame points, :attr:`grid` the 2-D marks."""

    def __init__(self, info: GridInfo, params: CloudLayerParams) -> None:
        self.info, self.params = info, params
        self.levels = max(1, math.ceil((params.max_obstacle_height - params.min_obstacle_height)
                                       / params.voxel_size - 1e-9))
        # the voxels plus one dump slot at the end (ray samples off the grid are written there)
        self._dump = info.height * info.width * self.levels
        self._flat = np.zeros(self._dump + 1, dtype=bool)
        self.voxels = self._flat[:-1].reshape(info.height, info.width, self.levels)
        self.grid = np.zeros((info.height, info.width), dtype=bool)

    def clear(self) -> None:
        """Forget everything (recovery's clear costmaps)."""
        self.voxels[:] = False
        self.grid[:] = False

    def _keys(self, pts: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(row, col, level) of points (N, 3) in the map frame; level may be outside 0..levels-1."""
        p = self.params
        row, col = self.info.world_to_cell(pts[:, 0], pts[:, 1])
        lev = np.floor((pts[:, 2] - p.min_obstacle_height) / p.voxel_size).astype(np.int64)
        return np.asarray(row, np.int64), np.asarray(col, np.int64), lev

    def update(self, points: np.ndarray, origin: np.ndarray) -> tuple[int, int]:
        """Clear along the rays from ``origin`` (the sensor, map frame, m) to ``points`` (N, 3) in the
        map frame (NaN rows ignored), then mark in-band points.  Returns (rays cast, voxels marked)."""
        p = self.params
        pts = np.asarray(points, dtype=np.float64).reshape(-1, 3)
        pts = pts[np.isfinite(pts).all(axis=1)]
        o = np.asarray(origin, dtype=np.float64).reshape(3)
        if not np.isfinite(o).all():
            raise ValueError(f"sensor origin must be finite, got {o.tolist()}")
        if pts.shape[0] == 0:
            return 0, 0
        # voxel filter: one representative (the mean) per occupied voxel, with its point count
        row, col, lev = self._keys(pts)
        key = (row * (self.info.width + 1) + col) * 4096 + np.clip(lev + 2048, 0, 4095)
        uniq, inverse, counts = np.unique(key, return_inverse=True, return_counts=True)
        inverse = inverse.ravel()
        centres = np.stack([np.bincount(inverse, weights=pts[:, k], minlength=uniq.size) for k in range(3)],
                           axis=1) / counts[:, None]
        self._clear_rays(o, centres)
        # mark: in the band, close enough, enough points
        crow, ccol, clev = self._keys(centres)
        horiz = np.hypot(centres[:, 0] - o[0], centres[:, 1] - o[1])
        mark = ((clev >= 0) & (clev < self.levels) & (horiz <= p.obstacle_range) & (counts >= p.min_voxel_points)
                & self.info.inside(crow, ccol))
        self.voxels[crow[mark], ccol[mark], clev[mark]] = True
        # re-project only the cells rays can have reached (the raytrace square around the sensor)
        reach = int(math.ceil(max(p.raytrace_range, p.obstacle_range) / self.info.resolution)) + 2
        orow, ocol = self._keys(o[None, :])[:2]
        r0, r1 = max(int(orow[0]) - reach, 0), min(int(orow[0]) + reach + 1, self.info.height)
        c0, c1 = max(int(ocol[0]) - reach, 0), min(int(ocol[0]) + reach + 1, self.info.width)
        if r0 < r1 and c0 < c1:
            np.any(self.voxels[r0:r1, c0:c1], axis=2, out=self.grid[r0:r1, c0:c1])
        return int(uniq.size), int(mark.sum())

    def _clear_rays(self, o: np.ndarray, ends: np.ndarray) -> None:
        """Free the voxels that the segments origin -> end pass through, stopping half a step short of
        each end (its own voxel is not cleared), only within raytrace_range (horizontal).

        Samples every min(resolution, voxel_size) along each ray, all rays at once in float32; samples
        that are past their end or off the grid go to a dump slot of the flat voxel array, so no
        boolean gathering is needed (measured: 3x faster than filtering the samples).
        """
        p, info = self.params, self.info
        d = ends - o
        horiz = np.hypot(d[:, 0], d[:, 1])
        scale = np.minimum(1.0, p.raytrace_range / np.maximum(horiz, 1e-9))
        norm = np.maximum(np.linalg.norm(d, axis=1), 1e-12)
        length = norm * scale
        step = min(info.resolution, p.voxel_size)
        n = int(math.ceil(float(length.max(initial=0.0)) / step))
        if n <= 0:
            return
        t = (np.arange(1, n + 1, dtype=np.float32) * np.float32(step))[None, :]      # (1, S) m along each ray
        unit = (d / norm[:, None]).astype(np.float32)
        # cell / level coordinates (float) of the origin and their change per metre along each ray
        c0 = np.float32((o[0] - info.origin_x) / info.resolution)
        r0 = np.float32((o[1] - info.origin_y) / info.resolution)
        l0 = np.float32((o[2] - p.min_obstacle_height) / p.voxel_size)
        col = np.floor(c0 + unit[:, 0:1] / np.float32(info.resolution) * t).astype(np.int32)
        row = np.floor(r0 + unit[:, 1:2] / np.float32(info.resolution) * t).astype(np.int32)
        lev = np.floor(l0 + unit[:, 2:3] / np.float32(p.voxel_size) * t).astype(np.int32)
        ok = ((t < (length[:, None] - 0.5 * step)) & (lev >= 0) & (lev < self.levels)
              & (row >= 0) & (row < info.height) & (col >= 0) & (col < info.width))
        flat = (row * info.width + col) * self.levels + lev
        self._flat[np.where(ok, flat, self._dump)] = False
