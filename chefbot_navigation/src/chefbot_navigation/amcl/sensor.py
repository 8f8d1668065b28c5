"""Likelihood-field measurement model (AMCL's ``likelihood_field``), precomputed from the map.

For every map cell the distance ``d`` (m) to the nearest obstacle *surface* cell
(an occupied cell with a non-occupied 8-neighbour) comes from an exact Euclidean
distance transform (``scipy.ndimage.distance_transform_edt``), capped at
``laser_likelihood_max_dist``; points off the map count as that cap, as in ROS's
amcl.  amcl measures to any occupied cell, so a beam end point *inside* a solid
obstacle fits perfectly: on maps with filled obstacles (our hotel raster's 1 m
tables) a narrow camera facing a table face could not tell 0.3 m along its axis
(bench_amcl, first two tables: RMS tracking error 0.19 m -> 0.08 m).  On maps
with thin walls (SLAM) every occupied cell is a surface cell and nothing changes.
A beam ending at distance ``d`` from the nearest obstacle has

    pz = z_hit · exp(-d² / (2 sigma_hit²)) + z_rand / range_max

and a particle's weight is ``1 + sum(pz³)`` over the beams (amcl's ad-hoc
combination: cubing sharpens, the 1 keeps every weight positive).  The table
stores the Gaussian term ``fit = exp(-d²/2σ²)`` (0..1, float32) so that the
range-dependent z_rand term is added per scan.  One update is a gather from
the table for all N × B beam end points at once.

Ours, beyond amcl: a beam that went *through* an obstacle.  On a map with thick walls (a raster
of a building, walls 0.2-0.3 m, free space on both sides) an end point pushed 0.15-0.2 m into a
wall is as close to the wall's *far* face as the true one is to its near face, so the field fits
a pose shifted into the wall about as well as the true pose: in the bistro (walls-only map, 0.25 m
walls) the estimate sat 0.1-0.17 m inside the room's walls along a whole route.  With
``through_dist`` > 0 the point that far before each end point (towards the sensor) is looked up
too; if it lies in an obstacle's *interior* (an occupied cell whose 8 neighbours are all occupied)
the beam passed through a wall from that particle's pose, and its ``fit`` counts as 0 in the
particle's weight (the beam is then only the random term; the mean fit reported for the recovery
gate leaves the check out, see ``weights``).  Interior cells exist only in obstacles over two cells thick, so a
map with thin walls (SLAM's) is scored exactly as before.

Beams are chosen as amcl does — evenly spaced up to ``max_beams`` — but among
the *valid* ranges only (finite, within [range_min, range_max)), so a depth
camera's NaN columns do not waste beams.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy import ndimage

from chefbot_common.geometry import Pose2D
from chefbot_common.grid import OccupancyMap


class MapError(ValueError):
    """The map cannot be used for localization (the message says why)."""


@dataclass(frozen=True)
class LaserModel:
    """AMCL's ``laser_*`` parameters of the likelihood-field model."""

    z_hit: float = 0.5               # weight of the Gaussian around the nearest obstacle
    z_rand: float = 0.5              # weight of the uniform term (divided by range_max)
    sigma_hit: float = 0.2           # m, stddev of the Gaussian
    likelihood_max_dist: float = 2.0  # m, distance transform cap
    occupied_threshold: int = 65     # map values >= this are obstacles (map_saver's --occ)
    through_dist: float = 0.0        # ours: m before an end point that must not be inside an obstacle (0: off)

    def __post_init__(self) -> None:
        if not (self.z_hit >= 0 and self.z_rand >= 0 and self.z_hit + self.z_rand > 0):
            raise ValueError(f"laser_z_hit and laser_z_rand must be >= 0 and not both 0, got "
                             f"{self.z_hit}, {self.z_rand}")
        if not self.sigma_hit > 0:
            raise ValueError(f"laser_sigma_hit must be > 0 m, got {self.sigma_hit}")
        if not self.likelihood_max_dist > 0:
            raise ValueError(f"laser_likelihood_max_dist must be > 0 m, got {self.likelihood_max_dist}")
        if not 1 <= self.occupied_threshold <= 100:
            raise ValueError(f"occupied_threshold must be in 1..100, got {self.occupied_threshold}")
        if not (math.isfinite(self.through_dist) and self.through_dist >= 0):
            raise ValueError(f"laser_through_dist must be >= 0 m, got {self.through_dist}")


def obstacle_surface(occupied: np.ndarray) -> np.ndarray:
    """Occupied cells with at least one non-occupied 8-neighbour (or on the map's edge)."""
    inner = ndimage.binary_erosion(occupied, structure=np.ones((3, 3), bool), border_value=0)
    return occupied & ~inner


def distance_to_obstacles(occupied: np.ndarray, resolution: float, cap: float) -> np.ndarray:
    """Euclidean distance (m) from each cell centre to the nearest obstacle-surface cell centre, capped."""
    surface = obstacle_surface(occupied)
    if not surface.any():
        return np.full(occupied.shape, cap)
    return np.minimum(ndimage.distance_transform_edt(~surface) * resolution, cap)


class LikelihoodField:
    """The map's likelihood field: ``fit`` table, free cells, and the per-scan weight function."""

    def __init__(self, occ: OccupancyMap, model: LaserModel) -> None:
        info = occ.info
        if info.width < 1 or info.height < 1:
            raise MapError(f"map is empty ({info.width} x {info.height} cells)")
        if not (math.isfinite(info.resolution) and info.resolution > 0):
            raise MapError(f"map resolution must be > 0 m, got {info.resolution}")
        if abs(info.origin_yaw) > 1e-6:
            raise MapError(f"map origin yaw must be 0 (as for costmap_2d), got {info.origin_yaw} rad")
        data = occ.data
        occupied = data >= model.occupied_threshold
        free = data == 0
        if not occupied.any():
            raise MapError("map has no occupied cells: nothing to localize against")
        if not free.any():
            raise MapError("map has no free cells: nowhere the robot could be")
        self.info, self.model = info, model
        d = distance_to_obstacles(occupied, info.resolution, model.likelihood_max_dist)
        far = np.float32(math.exp(-model.likelihood_max_dist ** 2 / (2.0 * model.sigma_hit ** 2)))
        # a one-cell border holding the off-map value: lookups clip into it instead of testing bounds
        fit = np.full((info.height + 2, info.width + 2), far, dtype=np.float32)
        fit[1:-1, 1:-1] = np.exp(-(d * d) / (2.0 * model.sigma_hit ** 2))
        self.fit_flat = fit.ravel()
        # 1.0 in an obstacle's interior (no non-occupied 8-neighbour), same border layout as ``fit``
        interior = np.zeros_like(fit)
        interior[1:-1, 1:-1] = occupied & ~obstacle_surface(occupied)
        self.interior_flat = interior.ravel()
        self.distance = d
        self.free_cells = np.flatnonzero(free.ravel())
        self.free_mask = free

    def fit_at(self, x: np.ndarray, y: np.ndarray) -> np.ndarray:
        """``exp(-d²/2σ²)`` at map points (any shape; off the map -> the capped value)."""
        return self._lookup(self.fit_flat, x, y)

    def interior_at(self, x: np.ndarray, y: np.ndarray) -> np.ndarray:
        """1.0 where a map point lies in an obstacle's interior, else 0.0 (off the map: 0)."""
        return self._lookup(self.interior_flat, x, y)

    def _lookup(self, table: np.ndarray, x: np.ndarray, y: np.ndarray) -> np.ndarray:
        info = self.info
        inv = np.float32(1.0 / info.resolution)
        # cell index + 1, clipped into the border; non-negative, so truncation = floor
        fc = np.clip((np.asarray(x, np.float32) - np.float32(info.origin_x)) * inv + np.float32(1.0),
                     0.0, info.width + 1.0).astype(np.int32)
        fr = np.clip((np.asarray(y, np.float32) - np.float32(info.origin_y)) * inv + np.float32(1.0),
                     0.0, info.height + 1.0).astype(np.int32)
        fr *= info.width + 2
        fr += fc
        return table[fr]

    @staticmethod
    def _frames(particles: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Particles (N, 3) as float32 columns (x, y) and their cos, sin (N, 1 each)."""
        p = particles.astype(np.float32)   # float32 halves the memory traffic; 1e-5 m at 100 m
        return p, np.cos(p[:, 2:3]), np.sin(p[:, 2:3])

    @staticmethod
    def _in_map(frames: tuple[np.ndarray, np.ndarray, np.ndarray], points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(N, B) map x and y of points (B, 2, m, base frame) seen from each particle."""
        p, c, s = frames
        bx, by = points[None, :, 0], points[None, :, 1]
        return p[:, 0:1] + c * bx - s * by, p[:, 1:2] + s * bx + c * by

    def beam_fits(self, particles: np.ndarray, endpoints: np.ndarray) -> np.ndarray:
        """(N, B) ``fit`` of beam end points (B, 2, m, base frame) seen from each particle (N, 3)."""
        return self.fit_at(*self._in_map(self._frames(particles), endpoints))

    def weights(self, particles: np.ndarray, endpoints: np.ndarray, range_max: float,
                before: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
        """(weight ``1 + sum pz³`` per particle, mean ``fit`` per particle in 0..1).

        ``before``: for each end point, the point ``through_dist`` before it on its beam (B, 2, base
        frame, see ``points_before``); a beam whose point lies in an obstacle's interior from a
        particle's pose fits 0 in the weight.  The mean ``fit`` (the recovery gate's and the
        diagnostics' measure of how well the map explains the scan) is the end points' alone: at the
        true pose a beam grazing a table that stands against a wall ends at the wall with its point
        inside the table, and counting those dropped the cafe's fit from ~0.75 to 0.6-0.66, below
        ``recovery_max_fit``: look-alike particles were injected while tracking within 2 cm, and took
        over (cafe_aisles' home leg, 2026-11-24).
        """
        frames = self._frames(particles)
        fits = self.fit_at(*self._in_map(frames, endpoints))
        mean_fit = fits.mean(axis=1, dtype=np.float64)
        if before is not None:
            fits *= np.float32(1.0) - self.interior_at(*self._in_map(frames, before))
        m = self.model
        pz = np.float32(m.z_hit) * fits + np.float32(m.z_rand / range_max)
        w = 1.0 + np.einsum("ij,ij,ij->i", pz, pz, pz, dtype=np.float64)
        return w, mean_fit

    def sample_free(self, n: int, rng: np.random.Generator) -> np.ndarray:
        """``n`` poses (N, 3) uniform over the free cells, uniform yaw."""
        info = self.info
        cells = rng.choice(self.free_cells, size=n)
        row, col = np.divmod(cells, info.width)
        u = rng.random((3, n))
        return np.stack([info.origin_x + (col + u[0]) * info.resolution,
                         info.origin_y + (row + u[1]) * info.resolution,
                         (u[2] * 2.0 - 1.0) * math.pi], axis=1)

    def is_free(self, x: float, y: float) -> bool | None:
        """True in a free cell, False in an occupied/unknown one, None off the map."""
        info = self.info
        col = math.floor((x - info.origin_x) / info.resolution)
        row = math.floor((y - info.origin_y) / info.resolution)
        if not (0 <= col < info.width and 0 <= row < info.height):
            return None
        return bool(self.free_mask[row, col])


def select_beams(ranges: np.ndarray, angles: np.ndarray, range_min: float, range_max: float,
                 max_beams: int, laser_pose: Pose2D) -> np.ndarray:
    """End points (B, 2) in the base frame of at most ``max_beams`` valid beams, evenly spaced.

    Valid: finite and within [range_min, range_max) (REP 117: NaN, ±inf and
    out-of-range readings carry no hit).  ``laser_pose`` is the scan frame in
    the base frame (m, rad).
    """
    r = np.asarray(ranges, dtype=np.float64)
    with np.errstate(invalid="ignore"):
        valid = np.flatnonzero(np.isfinite(r) & (r >= range_min) & (r < range_max))
    if len(valid) > max_beams:
        valid = valid[np.round(np.linspace(0, len(valid) - 1, max_beams)).astype(np.int64)]
    a = np.asarray(angles, dtype=np.float64)[valid] + laser_pose.yaw
    rv = r[valid]
    return np.stack([laser_pose.x + rv * np.cos(a), laser_pose.y + rv * np.sin(a)], axis=1).astype(np.float32)


def points_before(endpoints: np.ndarray, laser_pose: Pose2D, dist: float) -> np.ndarray:
    """For each end point (B, 2, base frame), the point ``dist`` m before it on its beam from the
    sensor at ``laser_pose`` (at most back to the sensor)."""
    e = np.asarray(endpoints, dtype=np.float32)
    v = e - np.array([laser_pose.x, laser_pose.y], dtype=np.float32)
    n = np.linalg.norm(v, axis=1, keepdims=True)
    back = np.minimum(np.float32(dist), n) / np.maximum(n, np.float32(1e-9))
    return (e - v * back).astype(np.float32)
