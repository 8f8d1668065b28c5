"""Correlative scan matcher on a blurred likelihood field (pure numpy/scipy).

The field is built from obstacle points: exact Euclidean distance to the
nearest obstacle cell (``scipy.ndimage.distance_transform_edt``) turned into a
Gaussian likelihood ``exp(-d^2 / 2 sigma^2)`` (Thrun's likelihood field).  A
scan pose is scored by the mean likelihood at its beam ends.

Search (Olson's correlative matching, two levels): every cell-sized offset in
the x/y window at every angle step, then a sub-cell refinement around the best
pose with bilinear interpolation (``scipy.ndimage.map_coordinates``) at a
quarter cell and a tenth of the angle step, then once more four times finer.

The coarse level is a branch and bound over max-pooled fields (Hess, Kohler,
Rapp, Andor: "Real-Time Loop Closure in 2D LIDAR SLAM", ICRA 2016, section V;
Cartographer's real-time correlative matcher).  ``LikelihoodField.max_pooled(h)``
holds at (r, c) the largest value of the 2^h x 2^h cells from (r, c); a node is
an angle and a 2^h x 2^h block of offsets, bounded by the mean pooled value at
the beam cells of its lowest offsets (then by the prior penalty of its offset
nearest the prior).  Levels are evaluated whole in numpy; a node is split in
four while its bound can beat the best candidate found so far (greedy descents
from each level's best nodes find it early).  The result is exactly the
exhaustive one (``match_exhaustive``, one index array of shape (angles, dy, dx,
beams)): the same candidate, np.argmax's tie rule (the lowest (angle, dy, dx)
index), the same ``spread`` and ``on_border``; small windows use the exhaustive
search, faster there.  A Gaussian prior around the odometry
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
        self._pooled: dict[int, np.ndarray] = {0: self.field}

    def max_pooled(self, depth: int) -> np.ndarray:
        """Grid of the field's shape whose cell (r, c) is the largest field value of the 2^depth x 2^depth
        cells starting at (r, c) (those inside the field); computed once per depth, then cached.

        Built by doubling (the max of two shifted grids of depth - 1 along rows, then along columns).
        A block of indices clipped into the field the way :func:`match` clips them lies inside the
        pooled window of its clipped lowest corner, so the pooled value bounds every cell of the block.
        """
        if depth < 0:
            raise ValueError(f"depth must be >= 0, got {depth}")
        grid = self._pooled.get(depth)
        if grid is None:
            prev = self.max_pooled(depth - 1)
            s = 1 << (depth - 1)
            rows = prev.copy()
            rows[:-s] = np.maximum(prev[:-s], prev[s:])
            grid = rows.copy()
            grid[:, :-s] = np.maximum(rows[:, :-s], rows[:, s:])
            self._pooled[depth] = grid
        return grid

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


# the root blocks of the branch and bound are at most 2^MAX_DEPTH cells wide (bigger windows: several roots)
MAX_DEPTH = 7
# fewer coarse candidates x beams than this: the exhaustive search (the same result) is faster (measured on
# a room scan, 160 and 360 beams: 325 x 360 and 931 x 160 faster exhaustive, 931 x 360 and 3509 x 160 slower)
EXHAUSTIVE_BELOW = 250_000
# beam cells gathered per numpy pass (bounds the memory of the index arrays)
_CHUNK = 1 << 21
# greedy descents per level (from the nodes of the best rank bounds, and of the best raw bounds) for the incumbent
_GREEDY = 8


@dataclass
class _Coarse:
    """The coarse candidates of one match: angle ``t`` x cell offsets ``offs`` (iy, ix), the beam cells per angle."""

    n_xy: int
    n_th: int
    dths: np.ndarray                                             # (T,) rad, angle offsets
    offs: np.ndarray                                             # (D,) cell offsets -n_xy..n_xy
    th: np.ndarray                                               # (T,) rad, candidate yaws
    row: np.ndarray                                              # (T, N) beam cell rows at offset 0
    col: np.ndarray                                              # (T, N) beam cell columns at offset 0


def _coarse(field: LikelihoodField, pts: np.ndarray, prior: Pose2D, window: SearchWindow) -> _Coarse:
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
    return _Coarse(n_xy, n_th, dths, offs, th, row, col)


def match(field: LikelihoodField, points: np.ndarray, prior: Pose2D, window: SearchWindow,
          prior_sigma: tuple[float, float] | None = None, beams_per_dof: float = 10.0,
          prior_cap: float = math.inf) -> MatchResult:
    """Pose of the robot that best explains ``points`` (N, 2) m given in its base frame.

    Searches ``window`` around ``prior`` (pose of the base in the field's frame).
    ``prior_sigma`` (m, rad): std-devs of the prior (the odometry's error since
    the last scan); candidates are ranked by the log-posterior
    ``(beams / beams_per_dof) * log(score) - mahalanobis^2 / 2`` (neighbouring
    beams are far from independent: ``beams_per_dof`` of them count as one
    measurement), so a scan that cannot tell along a wall keeps the odometry
    there.  None: a flat prior with a 5 % tie-break towards it.  ``prior_cap``: the
    prior's penalty stops growing at this many nats (a robust, truncated
    quadratic): a scan that fits clearly better far from the odometry -- after
    the wheels slipped in a turn -- is believed, while near the prediction the
    prior is the Gaussian one.

    The coarse search is a branch and bound (see the module docstring); its result is the
    exhaustive one of :func:`match_exhaustive`, which it falls back to for small windows.
    """
    return _match(field, points, prior, window, prior_sigma, beams_per_dof, prior_cap, exhaustive=False)


def match_exhaustive(field: LikelihoodField, points: np.ndarray, prior: Pose2D, window: SearchWindow,
                     prior_sigma: tuple[float, float] | None = None, beams_per_dof: float = 10.0,
                     prior_cap: float = math.inf) -> MatchResult:
    """:func:`match` scoring every coarse candidate at once: one index array of shape (angles, dy, dx, beams).

    The reference for the branch and bound (tests, benchmark); its memory grows with the window.
    """
    return _match(field, points, prior, window, prior_sigma, beams_per_dof, prior_cap, exhaustive=True)


def _match(field: LikelihoodField, points: np.ndarray, prior: Pose2D, window: SearchWindow,
           prior_sigma: tuple[float, float] | None, beams_per_dof: float, prior_cap: float,
           exhaustive: bool) -> MatchResult:
    """:func:`match` (``exhaustive``: always the exhaustive coarse search, else the faster of the two)."""
    pts = np.asarray(points, dtype=float).reshape(-1, 2)
    if len(pts) == 0:
        return MatchResult(prior, 0.0, 0)
    co = _coarse(field, pts, prior, window)
    small = len(co.dths) * len(co.offs) ** 2 * len(pts) < EXHAUSTIVE_BELOW
    search = _search_exhaustive if exhaustive or small else _search_bnb
    rank = _Ranking(field.res, co.dths, window, len(pts), prior_sigma, beams_per_dof, prior_cap)
    t, iy, ix, spread = search(field, co, rank)
    return _finish(field, pts, prior, window, co, (t, iy, ix), spread, prior_sigma, beams_per_dof, prior_cap)


def _finish(field: LikelihoodField, pts: np.ndarray, prior: Pose2D, window: SearchWindow, co: _Coarse,
            best: tuple[int, int, int], spread: float, prior_sigma: tuple[float, float] | None,
            beams_per_dof: float, prior_cap: float) -> MatchResult:
    """Two sub-cell refinements around the coarse best (angle index, row offset index, column offset index)."""
    res = field.res
    t, iy, ix = best
    pose = Pose2D(prior.x + co.offs[ix] * res, prior.y + co.offs[iy] * res, wrap_angle(co.th[t]))
    fine = refine(field, pts, pose, res / 2.0, window.yaw_step / 2.0, prior, prior_sigma, beams_per_dof, prior_cap)
    fine = refine(field, pts, fine.pose, res / 8.0, window.yaw_step / 8.0, prior, prior_sigma, beams_per_dof,
                  prior_cap)
    fine.spread = spread
    last = len(co.offs) - 1
    fine.on_border = bool((co.n_th > 0 and t in (0, len(co.dths) - 1))
                          or (co.n_xy > 0 and (ix in (0, last) or iy in (0, last))))
    return fine


class _Ranking:
    """How :func:`match` ranks coarse candidates, from their raw score (mean likelihood, float32), and an
    upper bound of that rank over a block of offsets at one angle from an upper bound of the raw score.

    The rank of a single candidate is computed element by element with the same float operations as
    over the exhaustive (angles, dy, dx) array, so both searches see bit-identical values.
    """

    def __init__(self, res: float, dths: np.ndarray, window: SearchWindow, beams: int,
                 prior_sigma: tuple[float, float] | None, beams_per_dof: float, prior_cap: float = math.inf) -> None:
        self.res, self.dths, self.beams, self.bpd, self.cap = res, dths, beams, beams_per_dof, prior_cap
        self.xy, self.yaw = window.xy, window.yaw
        self.prior_sigma = prior_sigma
        # float32 log is not guaranteed monotonic to the last bit: the log-posterior bound gets a margin
        # (1e-4 per counted measurement ~ a 0.01 % higher score; far above float32 rounding of log <= 9.3)
        self.slack = 1e-4 * beams / beams_per_dof + 1e-9

    def leaf(self, t: np.ndarray, oy: np.ndarray, ox: np.ndarray, raw: np.ndarray) -> np.ndarray:
        """Rank of candidates: angle indices ``t``, cell offsets ``oy``/``ox``, raw scores (float32)."""
        d2 = (oy ** 2 + ox ** 2) * self.res ** 2                 # m^2
        if self.prior_sigma is not None:
            sxy, sth = self.prior_sigma
            return _posterior(raw, self.beams, d2 / sxy ** 2 + (self.dths[t] / sth) ** 2, self.bpd, self.cap)
        flat = d2 / max(self.xy, self.res) ** 2 + (self.dths[t] / max(self.yaw, 1e-9)) ** 2
        return raw * (1.0 - 0.05 * flat)

    def bound(self, t: np.ndarray, oy0: np.ndarray, oy1: np.ndarray, ox0: np.ndarray, ox1: np.ndarray,
              ub: np.ndarray) -> np.ndarray:
        """Upper bound of the rank over offsets oy0..oy1 x ox0..ox1 (inclusive) at angles ``t``, given
        ``ub`` >= the raw score of each of them."""
        # the offset of the block nearest the prior: the least penalty (mahalanobis or flat distance)
        ny = np.where(oy0 > 0, oy0, np.where(oy1 < 0, oy1, 0))
        nx = np.where(ox0 > 0, ox0, np.where(ox1 < 0, ox1, 0))
        if self.prior_sigma is not None:
            # log is increasing: k log(max(ub, 1e-4)) >= k log(max(score, 1e-4)) for every candidate, and the
            # (capped) penalty never falls with the mahalanobis distance: the nearest offset has the least
            return self.leaf(t, ny, nx, ub) + self.slack
        d2 = (ny ** 2 + nx ** 2) * self.res ** 2
        factor = 1.0 - 0.05 * (d2 / max(self.xy, self.res) ** 2 + (self.dths[t] / max(self.yaw, 1e-9)) ** 2)
        return _flat_bound(ub, factor)


def _flat_bound(ub: np.ndarray, factor: np.ndarray) -> np.ndarray:
    """Upper bound of ``score * f`` over candidates with 0 <= score <= ``ub`` and f <= ``factor``.

    factor >= 0: ub * factor (a candidate with f < 0 scores <= 0 anyway).  factor < 0: every f is
    negative and score >= 0, so every product is <= 0 (the score may be 0: no tighter bound).
    (:func:`match`'s windows keep the factor >= 0.57: the offsets reach at most 1.5 half-windows.)
    """
    return np.where(factor >= 0.0, ub * np.maximum(factor, 0.0), 0.0)


def _search_exhaustive(field: LikelihoodField, co: _Coarse, rank: _Ranking) -> tuple[int, int, int, float]:
    """Coarse best (angle index, row offset index, column offset index) and spread over every candidate."""
    h, w = field.field.shape
    offs = co.offs
    rr = np.clip(co.row[:, None, None, :] + offs[None, :, None, None], 0, h - 1)   # (T, Dy, 1, N)
    cc = np.clip(co.col[:, None, None, :] + offs[None, None, :, None], 0, w - 1)   # (T, 1, Dx, N)
    score = field.field[rr, cc].mean(axis=3)                     # (T, Dy, Dx)
    spread = _spread(score, offs * field.res)                    # before the prior penalty
    t = np.arange(len(co.dths))[:, None, None]
    ranked = rank.leaf(t, offs[None, :, None], offs[None, None, :], score)
    t, iy, ix = np.unravel_index(int(np.argmax(ranked)), ranked.shape)
    return int(t), int(iy), int(ix), spread


def _block_raw(field: LikelihoodField, depth: int, co: _Coarse, t: np.ndarray, oy: np.ndarray,
               ox: np.ndarray) -> np.ndarray:
    """Mean over the beams of the depth-``depth`` max-pooled field at the beam cells of angle ``t`` shifted by
    cell offsets ``oy``/``ox`` (clipped into the field as in :func:`match_exhaustive`): float32 (M,).

    Depth 0 is the exact raw score; the mean runs over the contiguous last axis as in the exhaustive
    search, so the float32 sums are the same and, summation being monotonic, the pooled bound is >= it.
    """
    grid = field.max_pooled(depth)
    h, w = grid.shape
    n = co.row.shape[1]
    out = np.empty(len(t), dtype=np.float32)
    step = max(1, _CHUNK // n)
    for i in range(0, len(t), step):
        sl = slice(i, i + step)
        rr = np.clip(co.row[t[sl]] + oy[sl, None], 0, h - 1)
        cc = np.clip(co.col[t[sl]] + ox[sl, None], 0, w - 1)
        out[sl] = grid[rr, cc].mean(axis=1)
    return out


class _Incumbent:
    """Best candidate so far (rank, then the lowest flat index (t, iy, ix) in C order: np.argmax's tie rule)
    and the highest raw score seen."""

    def __init__(self) -> None:
        self.value = -math.inf
        self.flat = np.iinfo(np.int64).max
        self.raw = -math.inf

    def offer(self, values: np.ndarray, flats: np.ndarray, raws: np.ndarray) -> None:
        if len(values) == 0:
            return
        top = values.max()
        f = int(flats[values == top].min())
        if top > self.value or (top == self.value and f < self.flat):
            self.value, self.flat = float(top), f
        self.raw = max(self.raw, float(raws.max()))

    def spread_floor(self) -> float:
        """Raw scores below this can be in no spread set (0.95 x the final best raw >= 0.95 x this one)."""
        return 0.95 * self.raw * (1.0 - 1e-6) if self.raw > 0 else -math.inf


def _search_bnb(field: LikelihoodField, co: _Coarse, rank: _Ranking) -> tuple[int, int, int, float]:
    """:func:`_search_exhaustive` by branch and bound over max-pooled fields (Hess et al. 2016, section V).

    A node is an angle and a block of 2^h x 2^h cell offsets; its raw bound is the mean of the depth-h
    pooled field at the beam cells of the block's lowest offsets.  Levels are processed whole (all
    surviving nodes of all angles in one numpy gather); a node survives if its rank bound can still beat
    (or tie with a lower flat index) the incumbent, or its raw bound can reach 0.95 x the best raw score
    (the candidates of the spread).  Greedy descents from the best roots give the first incumbent.
    """
    n, d, nt = co.n_xy, len(co.offs), len(co.dths)
    depth = min(max(0, math.ceil(math.log2(d))), MAX_DEPTH)
    starts = np.arange(0, d, 1 << depth)
    t, y0, x0 = (a.ravel() for a in np.meshgrid(np.arange(nt), starts, starts, indexing="ij"))
    ub = _block_raw(field, depth, co, t, y0 - n, x0 - n)
    best = _Incumbent()

    def bounds(h: int, t: np.ndarray, y0: np.ndarray, x0: np.ndarray, ub: np.ndarray) -> np.ndarray:
        y1 = np.minimum(y0 + (1 << h), d) - 1
        x1 = np.minimum(x0 + (1 << h), d) - 1
        return rank.bound(t, y0 - n, y1 - n, x0 - n, x1 - n, ub)

    def children(h: int, t: np.ndarray, y0: np.ndarray, x0: np.ndarray):
        half = 1 << (h - 1)
        ct = np.repeat(t, 4)
        cy = (y0[:, None] + np.array([0, 0, half, half])).ravel()
        cx = (x0[:, None] + np.array([0, half, 0, half])).ravel()
        return ct, cy, cx

    def leaves(t: np.ndarray, y: np.ndarray, x: np.ndarray, raw: np.ndarray) -> np.ndarray:
        values = rank.leaf(t, y - n, x - n, raw)
        best.offer(values, (t * d + y) * d + x, raw)
        return values

    def descend(h: int, t: np.ndarray, y0: np.ndarray, x0: np.ndarray, ub: np.ndarray) -> None:
        """Greedy descents (into the child with the highest rank bound) from the _GREEDY nodes of the
        highest rank bounds and those of the highest raw bounds: leaves for the incumbent."""
        g = np.union1d(np.argsort(-bounds(h, t, y0, x0, ub), kind="stable")[:_GREEDY],
                       np.argsort(-ub, kind="stable")[:_GREEDY])
        gt, gy, gx = t[g], y0[g], x0[g]
        for level in range(h, 0, -1):
            ct, cy, cx = children(level, gt, gy, gx)
            inside = (cy < d) & (cx < d)                         # outside: a copy of the first child
            cy, cx = np.where(inside, cy, np.repeat(gy, 4)), np.where(inside, cx, np.repeat(gx, 4))
            cub = _block_raw(field, level - 1, co, ct, cy - n, cx - n)
            cb = leaves(ct, cy, cx, cub) if level == 1 else bounds(level - 1, ct, cy, cx, cub)
            pick = np.arange(len(gt)) * 4 + np.argmax(cb.reshape(-1, 4), axis=1)
            gt, gy, gx = ct[pick], cy[pick], cx[pick]

    # level by level; at each, greedy descents from its best nodes first raise the incumbent
    h = depth
    while h > 0:
        descend(h, t, y0, x0, ub)
        b = bounds(h, t, y0, x0, ub)
        lowest = (t * d + y0) * d + x0
        keep = (b > best.value) | ((b == best.value) & (lowest < best.flat)) | (ub >= best.spread_floor())
        t, y0, x0 = children(h, t[keep], y0[keep], x0[keep])
        inside = (y0 < d) & (x0 < d)
        t, y0, x0 = t[inside], y0[inside], x0[inside]
        h -= 1
        ub = _block_raw(field, h, co, t, y0 - n, x0 - n)
    leaves(t, y0, x0, ub)
    # the spread: every candidate within 5 % of the best raw score, in C order as np.nonzero gives them
    good = ub >= 0.95 * ub.max()
    flat = np.sort(((t * d + y0) * d + x0)[good])
    offs = co.offs * field.res
    spread = _spread_of(offs[flat % d], offs[(flat // d) % d])
    bt, rest = divmod(best.flat, d * d)
    return bt, rest // d, rest % d, spread


def _posterior(score: np.ndarray, beams: int, mahalanobis2: np.ndarray, beams_per_dof: float,
               prior_cap: float = math.inf) -> np.ndarray:
    """Log-posterior of candidate poses: independent-measurement count * log(score) - min(m^2 / 2, cap)."""
    return (beams / beams_per_dof) * np.log(np.maximum(score, 1e-4)) - np.minimum(0.5 * mahalanobis2, prior_cap)


def _spread(score: np.ndarray, offs: np.ndarray) -> float:
    """Largest std-dev (m) of the x/y offsets whose score is within 5 % of the best."""
    good = score >= 0.95 * score.max()
    _, iy, ix = np.nonzero(good)
    return _spread_of(offs[ix], offs[iy])


def _spread_of(x: np.ndarray, y: np.ndarray) -> float:
    """Largest std-dev (m) of the offsets (x, y) m (one per candidate)."""
    if len(x) < 2:
        return 0.0
    cov = np.cov(np.vstack((x, y)), bias=True)
    return float(np.sqrt(max(np.linalg.eigvalsh(cov).max(), 0.0)))


def refine(field: LikelihoodField, pts: np.ndarray, start: Pose2D, xy: float, yaw: float,
           prior: Pose2D | None = None, prior_sigma: tuple[float, float] | None = None,
           beams_per_dof: float = 10.0, prior_cap: float = math.inf) -> MatchResult:
    """Search of +-``xy`` m (5 steps) and +-``yaw`` rad (11 steps) around ``start``, bilinear scores,
    times the Gaussian prior (capped at ``prior_cap`` nats) around ``prior`` if ``prior_sigma`` is given."""
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
        sc = _posterior(sc, len(pts), m2, beams_per_dof, prior_cap)
    t, iy, ix = np.unravel_index(int(np.argmax(sc)), sc.shape)
    pose = Pose2D(start.x + offs[ix], start.y + offs[iy], wrap_angle(th[t]))
    return MatchResult(pose, float(raw[t, iy, ix]), len(pts))
