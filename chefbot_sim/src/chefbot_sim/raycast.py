"""Vectorised ray casting against the world's primitive shapes and the floor.

Pure numpy.  The depth camera and the sonar cast many rays from ONE origin per
frame; exploiting that (one shape-local origin per shape, one matrix product
for all directions) makes this several times cheaper than pybullet's
``rayTestBatch`` (~4 µs/ray on this machine) or TinyRenderer
(160×120 ≈ 8 ms): see the package README for measured figures.

The caster sees exactly the static shapes it is given (the world plus spawned
obstacles) and the floor plane z = 0, never the robot itself.
"""
from __future__ import annotations

import numpy as np

from chefbot_sim.world import Shape


class RayCaster:
    """Ray caster over a fixed set of shapes; rebuild it when shapes change."""

    def __init__(self, shapes: list[Shape], floor: bool = True) -> None:
        self.floor = floor
        self.shapes = list(shapes)
        boxes = [s for s in shapes if s.kind == "box"]
        cyls = [s for s in shapes if s.kind == "cylinder"]
        sphs = [s for s in shapes if s.kind == "sphere"]
        self._box_c = np.array([s.position for s in boxes], float).reshape(-1, 3)
        self._box_r = np.array([s.rotation() for s in boxes], float).reshape(-1, 3, 3)
        self._box_h = np.array([s.half_extents() for s in boxes], float).reshape(-1, 3)
        self._cyl_c = np.array([s.position for s in cyls], float).reshape(-1, 3)
        self._cyl_r = np.array([s.rotation() for s in cyls], float).reshape(-1, 3, 3)
        self._cyl_rad = np.array([s.size[0] for s in cyls], float)
        self._cyl_hh = np.array([s.size[1] / 2.0 for s in cyls], float)
        self._sph_c = np.array([s.position for s in sphs], float).reshape(-1, 3)
        self._sph_rad = np.array([s.size[0] for s in sphs], float)
        # bounding-sphere radii for culling
        self._box_bound = np.linalg.norm(self._box_h, axis=1)
        self._cyl_bound = np.hypot(self._cyl_rad, self._cyl_hh)

    def cast(self, origin: np.ndarray, dirs: np.ndarray, max_t: float, floor: bool | None = None) -> np.ndarray:
        """Distance parameter ``t`` of the first hit of each ray ``origin + t·dir``.

        ``dirs`` (N, 3) need not be unit vectors: ``t`` is in units of each
        direction's length (so directions with optical z = 1 give depth directly).
        Returns ``inf`` where nothing is hit with ``t <= max_t``.  A ray starting
        inside a shape hits it at t = 0.  ``floor`` overrides whether the floor
        plane counts (default: as constructed).
        """
        o = np.asarray(origin, float)
        d = np.asarray(dirs, float)
        best = np.full(d.shape[0], np.inf)
        if self.floor if floor is None else floor:
            with np.errstate(divide="ignore", invalid="ignore"):
                t = -o[2] / d[:, 2]
            t[(d[:, 2] >= 0) | (t < 0)] = np.inf
            best = np.minimum(best, t)
        if d.shape[0] == 0:
            return best
        norms = np.linalg.norm(d, axis=1)
        reach = max_t * float(np.max(norms))
        # cone around the mean direction containing every ray: shapes whose
        # bounding sphere lies outside it, or beyond reach, cannot be hit
        unit = d / norms[:, None]
        axis = unit.sum(axis=0)
        axis_n = np.linalg.norm(axis)
        cos_half = float(np.min(unit @ (axis / axis_n))) if axis_n > 1e-9 else -1.0
        half = np.arccos(np.clip(cos_half, -1.0, 1.0))
        axis = axis / axis_n if axis_n > 1e-9 else np.array([1.0, 0.0, 0.0])

        def visible(centres: np.ndarray, bounds: np.ndarray) -> np.ndarray:
            v = centres - o
            dist = np.linalg.norm(v, axis=1)
            inside = dist <= bounds
            with np.errstate(divide="ignore", invalid="ignore"):
                ang = np.arccos(np.clip((v @ axis) / dist, -1.0, 1.0))
                margin = np.arcsin(np.clip(bounds / dist, 0.0, 1.0))
            return inside | ((dist <= reach + bounds) & (ang - margin <= half))

        if len(self._box_c):
            keep = visible(self._box_c, self._box_bound)
            if keep.any():
                best = np.minimum(best, self._boxes(o, d, keep))
        if len(self._cyl_c):
            keep = visible(self._cyl_c, self._cyl_bound)
            if keep.any():
                best = np.minimum(best, self._cylinders(o, d, keep))
        if len(self._sph_c):
            keep = visible(self._sph_c, self._sph_rad)
            if keep.any():
                best = np.minimum(best, self._spheres(o, d, keep))
        best[best > max_t] = np.inf
        return best

    def _boxes(self, o: np.ndarray, d: np.ndarray, keep: np.ndarray) -> np.ndarray:
        rot, c, h = self._box_r[keep], self._box_c[keep], self._box_h[keep]
        lo = np.einsum("sji,sj->si", rot, o - c)        # (S, 3) origin in box frames
        # float32 planes: half the memory traffic of float64 (the cost here is
        # memory, not arithmetic); ~1 µm error at 8 m.  Origins stay float64
        # (shape-local, so world coordinates far from 0 lose nothing).
        dt = np.ascontiguousarray(d.T, dtype=np.float32)  # (3, N)
        rot32 = rot.astype(np.float32)
        lo32, h32 = lo.astype(np.float32), h.astype(np.float32)
        tmin = np.zeros((rot.shape[0], d.shape[0]), np.float32)
        tmax = np.full_like(tmin, np.inf)
        # slab test one axis at a time on contiguous (S, N) planes: much faster
        # in numpy than reducing over a trailing axis of length 3
        for k in range(3):
            ld = rot32[:, :, k] @ dt                     # (S, N) direction component
            ld[ld == 0.0] = 1e-12                        # avoid 0 * inf = nan
            inv = np.reciprocal(ld, out=ld)
            t1 = (-h32[:, k:k + 1] - lo32[:, k:k + 1]) * inv
            t2 = (h32[:, k:k + 1] - lo32[:, k:k + 1]) * inv
            np.maximum(tmin, np.minimum(t1, t2), out=tmin)
            np.minimum(tmax, np.maximum(t1, t2), out=tmax)
        tmin[tmax < tmin] = np.inf
        return tmin.min(axis=0).astype(float)

    def _cylinders(self, o: np.ndarray, d: np.ndarray, keep: np.ndarray) -> np.ndarray:
        rot, c = self._cyl_r[keep], self._cyl_c[keep]
        rad, hh = self._cyl_rad[keep][:, None], self._cyl_hh[keep][:, None]
        lo = np.einsum("sji,sj->si", rot, o - c)
        ld = np.matmul(d[None, :, :], rot)
        ox, oy, oz = lo[:, 0:1], lo[:, 1:2], lo[:, 2:3]
        dx, dy, dz = ld[..., 0], ld[..., 1], ld[..., 2]
        a = dx * dx + dy * dy
        b = 2.0 * (ox * dx + oy * dy)
        cc = ox * ox + oy * oy - rad * rad
        disc = b * b - 4.0 * a * cc
        with np.errstate(divide="ignore", invalid="ignore"):
            sq = np.sqrt(np.maximum(disc, 0.0))
            r_in = np.where(a > 0, (-b - sq) / (2.0 * a), np.where(cc <= 0, -np.inf, np.inf))
            r_out = np.where(a > 0, (-b + sq) / (2.0 * a), np.where(cc <= 0, np.inf, -np.inf))
            r_in = np.where((a > 0) & (disc < 0), np.inf, r_in)
            r_out = np.where((a > 0) & (disc < 0), -np.inf, r_out)
            z1 = (-hh - oz) / dz
            z2 = (hh - oz) / dz
        inside_z = np.abs(oz) <= hh
        z_in = np.where(dz != 0, np.minimum(z1, z2), np.where(inside_z, -np.inf, np.inf))
        z_out = np.where(dz != 0, np.maximum(z1, z2), np.where(inside_z, np.inf, -np.inf))
        tmin = np.maximum(r_in, z_in)
        tmax = np.minimum(r_out, z_out)
        hit = tmax >= np.maximum(tmin, 0.0)
        return np.where(hit, np.maximum(tmin, 0.0), np.inf).min(axis=0)

    def _spheres(self, o: np.ndarray, d: np.ndarray, keep: np.ndarray) -> np.ndarray:
        c, rad = self._sph_c[keep], self._sph_rad[keep][:, None]
        oc = o - c                                         # (S, 3)
        a = np.einsum("ni,ni->n", d, d)[None, :]
        b = 2.0 * (oc @ d.T)                               # (S, N)
        cc = np.einsum("si,si->s", oc, oc)[:, None] - rad * rad
        disc = b * b - 4.0 * a * cc
        sq = np.sqrt(np.maximum(disc, 0.0))
        t0 = (-b - sq) / (2.0 * a)
        t1 = (-b + sq) / (2.0 * a)
        hit = (disc >= 0) & (t1 >= 0)
        return np.where(hit, np.maximum(t0, 0.0), np.inf).min(axis=0)
