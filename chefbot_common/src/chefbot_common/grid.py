"""A 2-D grid georeferenced like ``nav_msgs/OccupancyGrid`` (pure numpy).

Row 0 of ``data`` is the row with the smallest y (OccupancyGrid order, the
reverse of image order); column 0 the smallest x.  Cell (row, col) covers
x in [ox + col*res, ox + (col+1)*res) in the grid's frame, whose origin is
``origin`` (x, y in m, yaw in rad) in the map frame.  Only yaw = 0 origins
are used for planning (as in ROS's costmap_2d, which ignores the yaw).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

# OccupancyGrid values
FREE = 0
OCCUPIED = 100
UNKNOWN = -1


@dataclass
class GridInfo:
    """Geometry of a grid: resolution (m/cell), size (cells), origin (m, m, rad)."""

    resolution: float
    width: int
    height: int
    origin_x: float = 0.0
    origin_y: float = 0.0
    origin_yaw: float = 0.0

    def world_to_cell(self, x: np.ndarray | float, y: np.ndarray | float) -> tuple[np.ndarray, np.ndarray]:
        """(row, col) integer indices of world points (may lie outside the grid)."""
        col = np.floor((np.asarray(x, dtype=float) - self.origin_x) / self.resolution).astype(np.int64)
        row = np.floor((np.asarray(y, dtype=float) - self.origin_y) / self.resolution).astype(np.int64)
        return row, col

    def cell_to_world(self, row: np.ndarray | float, col: np.ndarray | float) -> tuple[np.ndarray, np.ndarray]:
        """World coordinates (m) of cell centres."""
        x = self.origin_x + (np.asarray(col, dtype=float) + 0.5) * self.resolution
        y = self.origin_y + (np.asarray(row, dtype=float) + 0.5) * self.resolution
        return x, y

    def inside(self, row: np.ndarray, col: np.ndarray) -> np.ndarray:
        """Boolean mask: which cells lie inside the grid."""
        return (row >= 0) & (row < self.height) & (col >= 0) & (col < self.width)

    # Continuous coordinates honouring ``origin_yaw`` (for display: the GUI draws rotated maps).
    def world_to_grid(self, x: float, y: float) -> tuple[float, float]:
        """Continuous grid coordinates (column, row from the grid's bottom) of a map point."""
        dx, dy = x - self.origin_x, y - self.origin_y
        c, s = math.cos(self.origin_yaw), math.sin(self.origin_yaw)
        return (c * dx + s * dy) / self.resolution, (-s * dx + c * dy) / self.resolution

    def grid_to_world(self, col: float, row: float) -> tuple[float, float]:
        """Map point (m) of continuous grid coordinates (inverse of :meth:`world_to_grid`)."""
        lx, ly = col * self.resolution, row * self.resolution
        c, s = math.cos(self.origin_yaw), math.sin(self.origin_yaw)
        return self.origin_x + c * lx - s * ly, self.origin_y + s * lx + c * ly

    def world_to_image(self, x: float, y: float) -> tuple[float, float]:
        """Image pixel (u right, v down) of a map point in an image of the grid whose
        first row is the grid's *top* row (images grow downwards, grids upwards)."""
        col, row = self.world_to_grid(x, y)
        return col, self.height - row

    def image_to_world(self, u: float, v: float) -> tuple[float, float]:
        """Map point of an image pixel (inverse of :meth:`world_to_image`)."""
        return self.grid_to_world(u, self.height - v)


@dataclass
class OccupancyMap:
    """An occupancy grid: ``data`` int8 (height, width) with values -1, 0..100."""

    info: GridInfo
    data: np.ndarray

    def __post_init__(self) -> None:
        if self.data.shape != (self.info.height, self.info.width):
            raise ValueError(f"data shape {self.data.shape} != (height, width) "
                             f"({self.info.height}, {self.info.width})")
