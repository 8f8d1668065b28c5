"""Rasterise a world into a ground-truth occupancy grid in map_server format.

Pure numpy.  A cell is occupied when some shape whose vertical extent overlaps
the robot's height band covers the cell: each cell is tested at its centre,
at several heights inside the band, against the shape grown by half a cell
in its own x/y (so a thin wall still marks every cell it touches).

Image convention of map_server: row 0 is the top (largest y); ``origin`` is
the pose of the lower-left pixel's corner; occupied = 0 (black), free = 254.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from chefbot_common.map_io import write_map_yaml, write_pgm
from chefbot_sim.world import World

FREE = 254
OCCUPIED = 0


@dataclass
class Grid:
    """Occupancy grid: ``occupied[row, col]`` with row 0 at ``origin`` y (bottom)."""

    occupied: np.ndarray
    resolution: float
    origin: tuple[float, float]

    @property
    def shape(self) -> tuple[int, int]:
        """(rows, columns) of the grid."""
        return self.occupied.shape

    def cell_of(self, x: float, y: float) -> tuple[int, int]:
        """(row, col) of the world point (m), row counted from the bottom."""
        return (int(math.floor((y - self.origin[1]) / self.resolution)),
                int(math.floor((x - self.origin[0]) / self.resolution)))

    def image(self) -> np.ndarray:
        """uint8 PGM image, top row first: occupied 0, free 254."""
        img = np.where(self.occupied, OCCUPIED, FREE).astype(np.uint8)
        return img[::-1].copy()


def rasterise(world: World, resolution: float = 0.05, z_band: tuple[float, float] = (0.02, 0.45),
              margin: float = 0.5, bounds: tuple[float, float, float, float] | None = None) -> Grid:
    """Ground-truth occupancy of ``world``.

    ``resolution`` m/cell; ``z_band`` (low, high) m: the robot's height band (the
    default covers the ChefBot's body up to its top plate at ~0.4 m); ``margin`` m
    of free border around the shapes' extent, or explicit ``bounds``
    (xmin, ymin, xmax, ymax) in m.  Bounds snap outwards to the resolution grid
    so the origin is a round number.
    """
    if resolution <= 0:
        raise ValueError(f"resolution must be positive, got {resolution}")
    if bounds is None:
        xmin, ymin, xmax, ymax = world.bounds_xy()
        bounds = (xmin - margin, ymin - margin, xmax + margin, ymax + margin)
    xmin, ymin, xmax, ymax = bounds
    # snap to whole cells; round() first guards against 2.9999999 / 0.05 style noise
    x0 = math.floor(round(xmin / resolution, 6)) * resolution
    y0 = math.floor(round(ymin / resolution, 6)) * resolution
    ncols = max(1, math.ceil(round((xmax - x0) / resolution, 6)))
    nrows = max(1, math.ceil(round((ymax - y0) / resolution, 6)))
    occ = np.zeros((nrows, ncols), dtype=bool)
    z_lo, z_hi = z_band
    zs = np.linspace(z_lo, z_hi, max(2, int(math.ceil((z_hi - z_lo) / resolution)) + 1))
    half = resolution / 2.0
    for s in world.shapes_in_band(z_lo, z_hi):
        lo, hi = s.aabb()
        c0 = max(0, int(math.floor((lo[0] - half - x0) / resolution)))
        c1 = min(ncols, int(math.ceil((hi[0] + half - x0) / resolution)) + 1)
        r0 = max(0, int(math.floor((lo[1] - half - y0) / resolution)))
        r1 = min(nrows, int(math.ceil((hi[1] + half - y0) / resolution)) + 1)
        if c0 >= c1 or r0 >= r1:
            continue
        cx = x0 + (np.arange(c0, c1) + 0.5) * resolution
        cy = y0 + (np.arange(r0, r1) + 0.5) * resolution
        zz = zs[(zs >= lo[2]) & (zs <= hi[2])]
        if zz.size == 0:  # the band only grazes the shape between samples
            zz = np.array([min(max((z_lo + z_hi) / 2.0, lo[2]), hi[2])])
        gy, gx, gz = np.meshgrid(cy, cx, zz, indexing="ij")
        pts = np.stack([gx.ravel(), gy.ravel(), gz.ravel()], axis=1)
        inside = s.contains(pts, grow_xy=half).reshape(gy.shape).any(axis=2)
        occ[r0:r1, c0:c1] |= inside
    return Grid(occ, resolution, (x0, y0))


def write_map(grid: Grid, yaml_path: str | Path) -> tuple[Path, Path]:
    """Write ``<name>.yaml`` + ``<name>.pgm`` (binary P5) in map_server format.

    Output is byte-for-byte deterministic for the same grid (numbers rounded
    to 6 significant digits so that float noise does not reach the YAML).
    """
    yaml_path = Path(yaml_path)
    pgm_path = yaml_path.with_suffix(".pgm")
    write_pgm(pgm_path, grid.image(), f"CREATOR: chefbot_sim world_to_map {grid.resolution:.3f} m/pix")
    ox, oy = grid.origin
    write_map_yaml(yaml_path, pgm_path.name, float(f"{grid.resolution:.6g}"),
                   (float(f"{ox:.6g}"), float(f"{oy:.6g}"), 0.0))
    return yaml_path, pgm_path
