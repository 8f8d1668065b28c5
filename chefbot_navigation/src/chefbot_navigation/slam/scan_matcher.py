"""Correlative scan matcher on a blurred likelihood field (pure numpy/scipy).

The field is built from obstacle points: exact Euclidean distance to the
nearest obstacle cell (``scipy.ndimage.distance_transform_edt``) turned into a
Gaussian likelihood ``exp(-d^2 / 2 sigma^2)`` (Thrun's likelihood field).  A
scan pose is scored by the mean likelihood at its beam ends.

Search (Olson's correlative matching, two levels): every cell-sized offset in
the x/y window at every angle step (all at once: one index array of shape
(angles, dy, dx, beams)), then a sub-cell refinement around the best pose with
bilinear interpolation (``scipy.ndimage.map_coordinates``) at a quarter cell
and a tenth of the angle step, then once more four times finer.  A Gaussian prior around the odometry
prediction (its std-devs grow with the motion, gmapping's srr/srt/str/stt)
makes the matcher keep the prediction along directions the scan does not
constrain (a single flat wall seen by a narrow depth camera), where the bare
score would slide new wall points onto the part of the wall already mapped.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy import ndimage

from chefbot_common.geometry import Pose2D, wrap_angle


@dataclass
class MatchResult:
    """Best pose, its score (mean likelihood of the beam ends, 0..1), the number of beams used,
    ``spread`` (m): the largest standard deviation of the positions scoring within 5 % of
    the best (large along a corridor, where the scan cannot fix the position), and ``on_border``:
    the coarse best lies on the edge of the search window (x, y or yaw), so it may be no maximum
    at all - the score may still rise outside the window."""

    pose: Pose2D
    score: float
    beams: int
    spread: float = 0.0
    on_border: bool = False


class LikelihoodField:
    """Gaussian likelihood of the distance to the nearest obstacle point, on a grid.

    ``points`` (N, 2) m obstacle points; the field covers their bounding box
    plus ``margin`` m; ``sigma`` m is the standard deviation of the blur.
    """

    def __init__(self, points: np.ndarray, resolution: float, sigma: float = 0.05, margin: float = 1.0,
                 occupied_mask: np.ndarray | None = None, origin: tuple[float, float] | None = None) -> None:
        self.res = float(resolution)
        if occupied_mask is not None:
            # an existing grid: occupied cells are the obstacles
            if origin is None:
                raise ValueError("origin is required with occupied_mask")
            occ = occupied_mask.astype(bool)
            self.ox, self.oy = origin
        else:
            pts = np.asarray(points, dtype=float).reshape(-1, 2)
            if len(pts) == 0:
                raise ValueError("likelihood field needs at least one obstacle point")
            lo = pts.min(axis=0) - margin
            hi = pts.max(axis=0) + margin
            self.ox = math.floor(lo[0] / self.res) * self.res
            self.oy = math.floor(lo[1] / self.res) * self.res
            w = int(math.ceil((hi[0] - self.ox) / self.res)) + 1
            h = int(math.ceil((hi[1] - self.oy) / self.res)) + 1
            occ = np.zeros((h, w), dtype=bool)
            c = np.floor((pts[:, 0] - self.ox) / self.res).astype(np.int64)
            r = np.floor((pts[:, 1] - self.oy) / self.res).astype(np.int64)
            occ[r, c] = True
        if not occ.any():
            raise ValueError("likelihood field needs at least one obstacle cell")
        dist = ndimage.distance_transform_edt(~occ) * self.res
        field = np.exp(-0.5 * (dist / sigma) ** 2).astype(np.float32)
        # one zero cell of border: clipped indices of beams outside the field land there
        self.field = np.pad(field, 1)
        self.ox -= self.res
        self.oy -= self.res

    def score_points(self, pts: np.ndarray) -> np.ndarray:
        """Bilinear likelihood at (..., 2) world points (0 outside the field)."""
        fc = (pts[..., 0] - self.ox) / self.res - 0.5
        fr = (pts[..., 1] - self.oy) / self.res - 0.5
        return ndimage.map_coordinates(self.field, [fr.ravel(), fc.ravel()], order=1, mode="constant",
                                       cval=0.0).reshape(fc.shape)


@dataclass
class SearchWindow:
    """Half-widths of the search: ``xy`` m, ``yaw`` rad, angle step ``yaw_step`` rad."""

    xy: float = 0.2
    yaw: float = math.radians(10.0)
    yaw_step: float = math.radians(1.0)


def match(field: LikelihoodField, points: np.ndarray, prior: Pose2D, window: SearchWindow,
          prior_sigma: tuple[float, float] | None = None, beams_per_dof: float = 10.0) -> MatchResult:
    """Pose of the robot that best explains ``points`` (N, 2) m given in its base frame.

    Searches ``window`` around ``prior`` (pose of the base in the field's frame).
    ``prior_sigma`` (m, rad): std-devs of the prior (the odometry's error since
    the last scan); candidates are ranked by the log-posterior
    ``(beams / beams_per_dof) * log(score) - mahalanobis^2 / 2`` (neighbouring
    beams are far from independent: ``beams_per_dof`` of them count as one
    measurement), so a scan that cannot tell along a wall keeps the odometry
    there.  None: a flat prior with a 5 % tie-break towards it.
    """
    pts = np.asarray(points, dtype=float).reshape(-1, 2)
    if len(pts) == 0:
        return MatchResult(prior, 0.0, 0)
    res = field.res
    n_xy = max(0, int(round(window.xy / res)))
    n_th = max(0, int(round(window.yaw / window.yaw_step)))
    dths = np.arange(-n_th, n_th + 1) * window.yaw_step
    offs = np.arange(-n_xy, n_xy + 1)
    th = prior.yaw + dths                                        # (T,)
    c, s = np.cos(th)[:, None], np.sin(th)[:, None]
    wx = prior.x + c * pts[None, :, 0] - s * pts[None, :, 1]     # (T, N)
    wy = prior.y + s * pts[None, :, 0] + c * pts[None, :, 1]
    col = np.floor((wx - field.ox) / res).astype(np.int64)
    row = np.floor((wy - field.oy) / res).astype(np.int64)
    h, w = field.field.shape
    rr = np.clip(row[:, None, None, :] + offs[None, :, None, None], 0, h - 1)   # (T, Dy, 1, N)
    cc = np.clip(col[:, None, None, :] + offs[None, None, :, None], 0, w - 1)   # (T, 1, Dx, N)
    score = field.field[rr, cc].mean(axis=3)                     # (T, Dy, Dx)
    spread = _spread(score, offs * res)                          # before the prior penalty
    d2 = (offs[None, :, None] ** 2 + offs[None, None, :] ** 2) * res ** 2       # (1, Dy, Dx) m^2
    if prior_sigma is not None:
        sxy, sth = prior_sigma
        score = _posterior(score, len(pts), d2 / sxy ** 2 + (dths[:, None, None] / sth) ** 2, beams_per_dof)
    else:
        flat = d2 / max(window.xy, res) ** 2 + (dths[:, None, None] / max(window.yaw, 1e-9)) ** 2
        score = score * (1.0 - 0.05 * flat)
    t, iy, ix = np.unravel_index(int(np.argmax(score)), score.shape)
    best = Pose2D(prior.x + offs[ix] * res, prior.y + offs[iy] * res, wrap_angle(th[t]))
    fine = refine(field, pts, best, res / 2.0, window.yaw_step / 2.0, prior, prior_sigma, beams_per_dof)
    fine = refine(field, pts, fine.pose, res / 8.0, window.yaw_step / 8.0, prior, prior_sigma, beams_per_dof)
    fine.spread = spread
    fine.on_border = bool((n_th > 0 and t in (0, len(dths) - 1))
                          or (n_xy > 0 and (ix in (0, len(offs) - 1) or iy in (0, len(offs) - 1))))
    return fine


def _posterior(score: np.ndarray, beams: int, mahalanobis2: np.ndarray, beams_per_dof: float) -> np.ndarray:
    """Log-posterior of candidate poses: independent-measurement count * log(score) - m^2 / 2."""
    return (beams / beams_per_dof) * np.log(np.maximum(score, 1e-4)) - 0.5 * mahalanobis2


def _spread(score: np.ndarray, offs: np.ndarray) -> float:
    """Largest std-dev (m) of the x/y offsets whose score is within 5 % of the best."""
    good = score >= 0.95 * score.max()
    _, iy, ix = np.nonzero(good)
    if len(ix) < 2:
        return 0.0
    cov = np.cov(np.vstack((offs[ix], offs[iy])), bias=True)
    return float(np.sqrt(max(np.linalg.eigvalsh(cov).max(), 0.0)))


def refine(field: LikelihoodField, pts: np.ndarray, start: Pose2D, xy: float, yaw: float,
           prior: Pose2D | None = None, prior_sigma: tuple[float, float] | None = None,
           beams_per_dof: float = 10.0) -> MatchResult:
    """Search of +-``xy`` m (5 steps) and +-``yaw`` rad (11 steps) around ``start``, bilinear scores,
    times the Gaussian prior around ``prior`` if ``prior_sigma`` is given."""
    offs = np.linspace(-xy, xy, 5)
    dths = np.linspace(-yaw, yaw, 11)
    th = start.yaw + dths
    c, s = np.cos(th)[:, None], np.sin(th)[:, None]
    wx = c * pts[None, :, 0] - s * pts[None, :, 1]               # (T, N)
    wy = s * pts[None, :, 0] + c * pts[None, :, 1]
    X = start.x + wx[:, None, None, :] + offs[None, None, :, None]
    Y = start.y + wy[:, None, None, :] + offs[None, :, None, None]
    sc = field.score_points(np.stack(np.broadcast_arrays(X, Y), axis=-1)).mean(axis=3)
    raw = sc
    if prior is not None and prior_sigma is not None:
        sxy, sth = prior_sigma
        ex = start.x + offs - prior.x
        ey = start.y + offs - prior.y
        eth = np.angle(np.exp(1j * (th - prior.yaw)))
        m2 = (ex[None, None, :] ** 2 + ey[None, :, None] ** 2) / sxy ** 2 + (eth[:, None, None] / sth) ** 2
        sc = _posterior(sc, len(pts), m2, beams_per_dof)
    t, iy, ix = np.unravel_index(int(np.argmax(sc)), sc.shape)
    pose = Pose2D(start.x + offs[ix], start.y + offs[iy], wrap_angle(th[t]))
    return MatchResult(pose, float(raw[t, iy, ix]), len(pts))
