"""Log-odds occupancy grid that grows as needed, updated by vectorised ray casting.

Each scan updates a cell at most once: cells crossed by a beam before its end
get ``l_free``, cells holding a beam's obstacle end get ``l_occ`` (and are not
also cleared by the same scan).  A beam is traced by sampling it every
``resolution / 3`` m (all beams of a scan at once, numpy), which visits every
cell the segment passes through except cells it only grazes at a corner.

Output is map_server's trinary convention: p = 1 - 1 / (1 + e^l);
p > occupied_thresh (0.65) -> 100, p < free_thresh (0.196) -> 0, else -1,
so ``map_saver`` -> ``map_server`` returns exactly the published grid.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from chefbot_common.grid import FREE, OCCUPIED, UNKNOWN, GridInfo, OccupancyMap


def logit(p: float) -> float:
    """log(p / (1 - p)) of a probability in (0, 1)."""
    return math.log(p / (1.0 - p))


@dataclass
class LogOddsParams:
    """Sensor model in log-odds and the output thresholds (probabilities)."""

    l_occ: float = 0.9           # added to a cell holding a beam end (p 0.71 per hit)
    l_free: float = -0.7         # added to a cell a beam passes through (p 0.33 per pass)
    l_min: float = -4.0          # clamp, so a cell can change its mind after ~6 readings
    l_max: float = 4.0
    occupied_thresh: float = 0.65
    free_thresh: float = 0.196


class LogOddsGrid:
    """Growing log-odds grid; world coordinates in m, origin snapped to the resolution."""

    def __init__(self, resolution: float, bounds: tuple[float, float, float, float] = (-5.0, -5.0, 5.0, 5.0),
                 params: LogOddsParams | None = None, grow_margin: float = 2.0) -> None:
        if not resolution > 0:
            raise ValueError(f"resolution must be > 0 m, got {resolution}")
        self.res = float(resolution)
        self.params = params or LogOddsParams()
        self.grow_margin = grow_margin
        xmin, ymin, xmax, ymax = bounds
        if not (xmax > xmin and ymax > ymin):
            raise ValueError(f"map bounds must have xmax > xmin and ymax > ymin, got {bounds}")
        self.ox = math.floor(round(xmin / self.res, 6)) * self.res
        self.oy = math.floor(round(ymin / self.res, 6)) * self.res
        w = max(1, math.ceil(round((xmax - self.ox) / self.res, 6)))
        h = max(1, math.ceil(round((ymax - self.oy) / self.res, 6)))
        self.l = np.zeros((h, w), dtype=np.float32)
        self._mark: np.ndarray | None = None     # scratch for _unique_cells, all False between calls

    # -- geometry ---------------------------------------------------------------------------
    @property
    def info(self) -> GridInfo:
        """Geometry of the grid as it is now (it grows as the robot explores)."""
        h, w = self.l.shape
        return GridInfo(self.res, w, h, self.ox, self.oy, 0.0)

    def ensure(self, xmin: float, ymin: float, xmax: float, ymax: float) -> bool:
        """Grow the grid (by whole cells, plus ``grow_margin`` m) to cover the box; True if it grew."""
        h, w = self.l.shape
        x1, y1 = self.ox + w * self.res, self.oy + h * self.res
        if xmin >= self.ox and ymin >= self.oy and xmax < x1 and ymax < y1:
            return False
        m = self.grow_margin
        add_left = math.ceil((self.ox - xmin + m) / self.res) if xmin < self.ox else 0
        add_bottom = math.ceil((self.oy - ymin + m) / self.res) if ymin < self.oy else 0
        add_right = math.ceil((xmax - x1 + m) / self.res) if xmax >= x1 else 0
        add_top = math.ceil((ymax - y1 + m) / self.res) if ymax >= y1 else 0
        self.l = np.pad(self.l, ((add_bottom, add_top), (add_left, add_right)))
        self.ox -= add_left * self.res
        self.oy -= add_bottom * self.res
        return True

    # -- update -----------------------------------------------------------------------------
    def trace(self, origin: np.ndarray, ends: np.ndarray, hit: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Flat indices (free cells, occupied cells) of one scan, each cell once.

        ``origin`` (2,) m sensor position, ``ends`` (N, 2) m beam ends, ``hit``
        (N,) bool whether the end is an obstacle, all in the grid's frame.
        The grid is grown first so every index is valid.
        """
        ends = np.asarray(ends, dtype=float).reshape(-1, 2)
        hit = np.asarray(hit, dtype=bool)
        if len(ends) == 0:
            return np.zeros(0, np.int64), np.zeros(0, np.int64)
        allx = np.append(ends[:, 0], origin[0])
        ally = np.append(ends[:, 1], origin[1])
        self.ensure(allx.min(), ally.min(), allx.max(), ally.max())
        h, w = self.l.shape
        d = ends - origin
        length = np.hypot(d[:, 0], d[:, 1])
        step = self.res / 3.0
        n = int(math.ceil(length.max() / step)) + 1
        t = np.arange(n) * step
        frac = t[None, :] / np.maximum(length[:, None], 1e-9)
        inside = t[None, :] < length[:, None]
        xs = origin[0] + frac * d[:, 0:1]
        ys = origin[1] + frac * d[:, 1:2]
        col = np.floor((xs[inside] - self.ox) / self.res).astype(np.int64)
        row = np.floor((ys[inside] - self.oy) / self.res).astype(np.int64)
        free = self._unique_cells(row * w + col)
        ec = np.floor((ends[:, 0] - self.ox) / self.res).astype(np.int64)
        er = np.floor((ends[:, 1] - self.oy) / self.res).astype(np.int64)
        occ = np.unique(er[hit] * w + ec[hit])
        free_end = np.unique(er[~hit] * w + ec[~hit])
        free = np.union1d(free, free_end)
        free = np.setdiff1d(free, occ, assume_unique=True)
        return free, occ

    def _unique_cells(self, cells: np.ndarray) -> np.ndarray:
        """``np.unique(cells)`` (flat indices of this grid).  A beam is sampled three times per cell, so a
        scan gives ~10^4-10^5 samples: marking them in a scratch mask of the grid and reading it back
        is ~6x faster than sorting them, unless the grid is much larger than the samples."""
        size = self.l.size
        if size > 64 * len(cells):
            return np.unique(cells)
        if self._mark is None or self._mark.size != size:
            self._mark = np.zeros(size, dtype=bool)
        self._mark[cells] = True
        out = np.flatnonzero(self._mark)
        self._mark[out] = False
        return out

    def integrate(self, origin: np.ndarray, ends: np.ndarray, hit: np.ndarray) -> None:
        """Update the log-odds with one scan given in the grid's frame (see :meth:`trace`)."""
        free, occ = self.trace(origin, ends, hit)
        flat = self.l.reshape(-1)
        p = self.params
        flat[free] = np.clip(flat[free] + p.l_free, p.l_min, p.l_max)
        flat[occ] = np.clip(flat[occ] + p.l_occ, p.l_min, p.l_max)

    def clear(self) -> None:
        """Forget everything (all cells unknown), keeping the geometry."""
        self.l[:] = 0.0

    # -- output -----------------------------------------------------------------------------
    def occupied_mask(self) -> np.ndarray:
        """Boolean (H, W): cells whose probability exceeds occupied_thresh."""
        return self.l > logit(self.params.occupied_thresh)

    def to_occupancy(self) -> OccupancyMap:
        """Trinary :class:`OccupancyMap` (100 / 0 / -1), row 0 = smallest y."""
        data = np.full(self.l.shape, UNKNOWN, dtype=np.int8)
        data[self.l < logit(self.params.free_thresh)] = FREE
        data[self.occupied_mask()] = OCCUPIED
        return OccupancyMap(self.info, data)
