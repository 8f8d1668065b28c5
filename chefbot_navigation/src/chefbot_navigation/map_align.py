"""Rigid 2-D registration of two occupancy maps of one site, and moving poses between them (pure).

Used to re-mark delivery poses on a new map (``align_tables``): the poses known
in a *source* map's frame (e.g. the world raster) are carried into a *target*
map's frame (e.g. a SLAM map, whose frame is the robot's odometry frame at its
first scan).  The result :class:`Alignment` is the pose of the target frame in
the source frame: ``p_source = R(yaw) @ p_target + (x, y)``.

Method (numpy/scipy only):

1. Points: the centres of the target's occupied cells; score field: a
   truncated distance transform of the source's occupied cells
   (``scipy.ndimage.distance_transform_edt``).
2. Coarse, global: for every heading of a grid (``yaw_step`` over
   ``±max_yaw``) the rotated target points are binned on the source grid and
   cross-correlated with ``1 - d/trunc`` by FFT (``scipy.signal.fftconvolve``),
   which scores every integer-cell translation at once; the best
   (yaw, shift) is kept.
3. Fine: ``scipy.optimize.least_squares`` (Huber loss, scale one cell) on the
   bilinearly interpolated distance of each moved target point to the nearest
   source occupied cell, over (x, y, yaw).

Residual figures: RMS and median of those distances over the *inliers*
(points within ``inlier_m``, default 2 cells) and the inlier share; target
cells with no counterpart (SLAM false-occupied cells, furniture moved) are the
outliers.  :func:`local_alignment` refines the same transform on the target
cells within a radius of one place only, to measure how far the map is
distorted there (a rigid transform fits a SLAM map only up to its drift).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy import ndimage, optimize, signal

from chefbot_common.geometry import Pose2D
from chefbot_common.grid import OccupancyMap

OCCUPIED_MIN = 50  # OccupancyGrid value above which a cell counts as occupied (map_server's 0.65 -> 100)


class AlignError(ValueError):
    """The maps cannot be aligned; the message says why and names the map."""


@dataclass
class Alignment:
    """Pose of the target map's frame in the source map's frame, and how well the maps agree.

    x, y in m, yaw in rad; rms_m / median_m: distance (m) of the target's occupied
    cells to the nearest source occupied cell after alignment, over the inliers;
    inlier_fraction 0..1; points: number of target occupied cells used.
    """

    x: float
    y: float
    yaw: float
    rms_m: float
    median_m: float
    inlier_fraction: float
    points: int

    @property
    def pose(self) -> Pose2D:
        """The transform as a Pose2D (target frame in the source frame)."""
        return Pose2D(self.x, self.y, self.yaw)

    def to_source(self, pose: Pose2D) -> Pose2D:
        """A pose given in the target frame, expressed in the source frame."""
        return self.pose.compose(pose)

    def to_target(self, pose: Pose2D) -> Pose2D:
        """A pose given in the source frame, expressed in the target frame (inverse of :meth:`to_source`)."""
        return self.pose.inverse().compose(pose)


def occupied_points(occ: OccupancyMap, name: str = "map") -> np.ndarray:
    """(N, 2) map-frame coordinates (m) of the centres of the occupied cells (honours origin yaw)."""
    rows, cols = np.nonzero(occ.data > OCCUPIED_MIN)
    if rows.size == 0:
        raise AlignError(f"{name}: has no occupied cells to align on")
    info = occ.info
    lx, ly = (cols + 0.5) * info.resolution, (rows + 0.5) * info.resolution
    c, s = math.cos(info.origin_yaw), math.sin(info.origin_yaw)
    return np.column_stack((info.origin_x + c * lx - s * ly, info.origin_y + s * lx + c * ly))


class _Field:
    """Distance (m) to the nearest occupied cell of a map, sampled anywhere in its frame."""

    def __init__(self, occ: OccupancyMap, name: str) -> None:
        if occ.info.origin_yaw != 0.0:
            raise AlignError(f"{name}: a source map with a rotated origin is not supported")
        occupied = occ.data > OCCUPIED_MIN
        if not occupied.any():
            raise AlignError(f"{name}: has no occupied cells to align on")
        self.info = occ.info
        self.dist = ndimage.distance_transform_edt(~occupied) * occ.info.resolution

    def grid_coords(self, pts: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Continuous (row, col) of points, cell centres at integers."""
        info = self.info
        return (pts[:, 1] - info.origin_y) / info.resolution - 0.5, (pts[:, 0] - info.origin_x) / info.resolution - 0.5

    def sample(self, pts: np.ndarray, far: float) -> np.ndarray:
        """Bilinear distance (m) at points; ``far`` outside the grid."""
        r, c = self.grid_coords(pts)
        return ndimage.map_coordinates(self.dist, [r, c], order=1, mode="constant", cval=far)


def _transform(pts: np.ndarray, x: float, y: float, yaw: float) -> np.ndarray:
    c, s = math.cos(yaw), math.sin(yaw)
    return pts @ np.array([[c, s], [-s, c]]) + (x, y)


def _coarse(field: _Field, pts: np.ndarray, yaws: np.ndarray, trunc: float) -> tuple[float, float, float]:
    """Best (x, y, yaw) over the heading grid, integer-cell translations scored by FFT correlation."""
    res = field.info.resolution
    score = np.clip(1.0 - field.dist / trunc, 0.0, None)
    best = (-np.inf, 0.0, 0.0, 0.0)
    for yaw in yaws:
        r, c = field.grid_coords(_transform(pts, 0.0, 0.0, float(yaw)))
        ri, ci = np.rint(r).astype(np.int64), np.rint(c).astype(np.int64)
        r0, c0 = ri.min(), ci.min()
        img = np.zeros((ri.max() - r0 + 1, ci.max() - c0 + 1))
        np.add.at(img, (ri - r0, ci - c0), 1.0)
        # corr[i, j] = sum score[i + a, j + b] * img[a, b]: the score of shifting img's (0, 0) to (i, j)
        corr = signal.fftconvolve(score, img[::-1, ::-1], mode="full")
        k = int(np.argmax(corr))
        i, j = np.unravel_index(k, corr.shape)
        if corr[i, j] > best[0]:
            dr, dc = i - (img.shape[0] - 1) - r0, j - (img.shape[1] - 1) - c0
            best = (float(corr[i, j]), float(dc) * res, float(dr) * res, float(yaw))
    return best[1], best[2], best[3]


def _refine(field: _Field, pts: np.ndarray, start: tuple[float, float, float], trunc: float) -> np.ndarray:
    res = field.info.resolution

    def residuals(p: np.ndarray) -> np.ndarray:
        return field.sample(_transform(pts, *p), far=trunc)

    sol = optimize.least_squares(residuals, np.asarray(start, dtype=float), loss="huber", f_scale=res,
                                 x_scale=[res, res, res / 5.0], diff_step=[1e-3, 1e-3, 1e-3])
    return sol.x


def _result(field: _Field, pts: np.ndarray, p: np.ndarray, inlier_m: float) -> Alignment:
    d = field.sample(_transform(pts, *p), far=np.inf)
    inl = d[d <= inlier_m]
    if inl.size == 0:
        raise AlignError("no target cell lies near a source cell after alignment: the maps do not overlap")
    return Alignment(x=float(p[0]), y=float(p[1]), yaw=math.remainder(float(p[2]), math.tau),
                     rms_m=float(np.sqrt(np.mean(inl ** 2))), median_m=float(np.median(inl)),
                     inlier_fraction=float(inl.size / d.size), points=int(d.size))


def align_maps(source: OccupancyMap, target: OccupancyMap, max_yaw: float = math.pi,
               yaw_step: float = math.radians(1.0), trunc: float = 0.3, inlier_m: float | None = None,
               source_name: str = "source map", target_name: str = "target map") -> Alignment:
    """Pose of ``target``'s frame in ``source``'s frame (see the module doc).

    max_yaw: heading search half-width (rad, ≤ π); yaw_step: coarse heading step (rad);
    trunc: distance (m) beyond which a cell scores nothing; inlier_m: inlier distance
    for the residual figures (m, default two cells of the source).
    """
    for name, value in (("max_yaw", max_yaw), ("yaw_step", yaw_step), ("trunc", trunc)):
        if not math.isfinite(value) or value < 0 or (name != "max_yaw" and value == 0):
            raise AlignError(f"{name} must be a finite positive number, got {value!r}")
    field = _Field(source, source_name)
    pts = occupied_points(target, target_name)
    inlier_m = 2.0 * source.info.resolution if inlier_m is None else inlier_m
    n = int(math.floor(min(max_yaw, math.pi) / yaw_step))
    yaws = np.arange(-n, n + 1) * yaw_step
    yaws = yaws[yaws > -math.pi + 1e-9]  # -pi is +pi
    start = _coarse(field, pts, yaws, trunc)
    # two rounds: wide basin first, then tight (a coarse heading can be one step off)
    p = _refine(field, pts, start, trunc)
    p = _refine(field, pts, tuple(p), 2.0 * source.info.resolution)
    return _result(field, pts, p, inlier_m)


def local_alignment(source: OccupancyMap, target: OccupancyMap, initial: Alignment, centre: Pose2D,
                    radius: float, inlier_m: float | None = None) -> Alignment:
    """``initial`` refined on the target's occupied cells within ``radius`` (m) of ``centre`` (target frame)."""
    field = _Field(source, "source map")
    pts = occupied_points(target, "target map")
    near = np.hypot(pts[:, 0] - centre.x, pts[:, 1] - centre.y) <= radius
    if near.sum() < 10:
        raise AlignError(f"fewer than 10 occupied target cells within {radius} m of ({centre.x:.2f}, "
                         f"{centre.y:.2f}): nothing to align on there")
    pts = pts[near]
    p = _refine(field, pts, (initial.x, initial.y, initial.yaw), 2.0 * source.info.resolution)
    return _result(field, pts, p, 2.0 * source.info.resolution if inlier_m is None else inlier_m)
